// ECUs: the inventory the gateway read over UDS, and flashing a signed image to one ECU
// with a progress bar and the phase timing; a refused image shows the ECU's reason.
import { get, post } from '../api';
import type { Ctx, View } from '../view';
import { bytes, h, num, seconds, setText } from '../util';

const ECUS = ['engine', 'pedals', 'steering', 'transmission', 'cabin', 'console', 'differential', 'cruise', 'abs'];
const NODE_ECU: Record<number, string> = {};

export function ecusView(ctx: Ctx): View {
  const { live } = ctx;
  const inventory = h('tbody');
  const ecu = h('select', { 'data-testid': 'flash-ecu', 'aria-label': 'ECU to flash' }, ...ECUS.map((e) => h('option', { value: e, text: e })));
  const image = h('select', { 'data-testid': 'flash-image', 'aria-label': 'image from the library' });
  const file = h('input', { type: 'file', accept: '.img', 'aria-label': 'or upload an image' });
  const start = h('button', { class: 'btn primary', 'data-testid': 'flash-start' }, 'Flash');
  const progress = h('progress', { max: 100, value: 0, 'data-testid': 'flash-progress' });
  const status = h('div', { class: 'flash-status', 'data-testid': 'flash-status' });
  const phases = h('div', { class: 'small' });
  const libraryHint = h('p', { class: 'small muted', 'data-testid': 'library-hint' });
  const el = h('section', { class: 'ecus' },
    h('div', { class: 'card table-wrap' }, h('h3', { text: 'Inventory (UDS 0x22: F187, F189, F191, F18C, F1A0)' }),
      h('table', { class: 'grid' }, h('thead', {}, h('tr', {}, ...['ECU', 'Part number', 'Software', 'Running', 'Hardware', 'Serial'].map((t) => h('th', { text: t })))), inventory)),
    h('div', { class: 'card' }, h('h3', { text: 'Flash a signed image over CAN' }),
      h('div', { class: 'form' },
        h('label', {}, 'ECU ', ecu),
        h('label', {}, 'Image ', image),
        h('label', {}, 'or upload ', file),
        start),
      libraryHint, progress, status, phases),
  );

  async function loadLibrary(): Promise<void> {
    try {
      const list: any[] = await get('/api/images');
      image.replaceChildren(h('option', { value: '', text: list.length ? '— choose —' : '(library empty)' }));
      // An empty library says how it fills: the dashboard writes the virtual car's
      // demonstration images at its start and builds the releases of ECUs it runs as
      // firmware; anything else is uploaded here or put in the data folder's images/.
      setText(libraryHint, list.length ? '' : 'The library is the data folder\'s images/ folder. The dashboard puts the demonstration images there at its start (for ECUs running their firmware it builds the signed releases, which needs this checkout and the firmware target: see its output). Upload a signed image here, or copy one there (scripts/firmware-release builds one).');
      for (const item of list) {
        const target = item.node !== null ? NODE_ECU[item.node] ?? `node ${item.node}` : '?';
        image.append(h('option', { value: item.name, 'data-ecu': target, text: `${item.name} — ${target} ${item.version ?? ''} ${item.variant ?? ''} (${bytes(item.bytes)})` }));
      }
    } catch (e: any) {
      ctx.toast(e.message, 'error');
    }
  }
  image.addEventListener('change', () => {
    const target = image.selectedOptions[0]?.dataset.ecu;
    if (target && ECUS.includes(target)) ecu.value = target;
  });

  // A refusal (the gateway's 4xx answer) stays shown until a flash starts: the session's
  // state, which says "no flash yet", must not hide it.
  let refusal: string | null = null;
  start.addEventListener('click', async () => {
    start.setAttribute('disabled', '');
    try {
      const chosen = file.files?.[0];
      if (chosen) {
        await post(`/api/ecus/${ecu.value}/flash`, await chosen.arrayBuffer(), true);
      } else if (image.value) {
        await post(`/api/ecus/${ecu.value}/flash?image=${encodeURIComponent(image.value)}`);
      } else {
        throw new Error('choose an image from the library or upload one');
      }
      // Said once, by the session's event (every open page sees it).
      refusal = null;
    } catch (e: any) {
      ctx.toast(e.message, 'error');
      refusal = e.message;
      showRefusal();
    } finally {
      start.removeAttribute('disabled');
      file.value = '';
    }
  });

  function showRefusal(): void {
    setText(status, `Refused: ${refusal}`);
    status.className = 'flash-status failed';
    status.dataset.state = 'failed';
  }

  let lastInventory = '';
  function update(): void {
    const s = live.session;
    if (!s) return;
    for (const row of s.inventory) if (row.node !== null) NODE_ECU[row.node] = row.ecu;
    const inv = JSON.stringify(s.inventory);
    if (inv !== lastInventory) {
      lastInventory = inv;
      if (image.childElementCount === 0) void loadLibrary();
      inventory.replaceChildren(...s.inventory.map((r) => h('tr', { 'data-testid': `inventory-${r.ecu}` },
        h('td', { text: r.ecu }), h('td', { text: r.part_number ?? '–' }), h('td', { class: 'sw', text: r.software_version ?? '–' }),
        h('td', { class: `slot ${r.boot_state === 'on trial' ? 'trial' : ''}`, 'data-testid': `slot-${r.ecu}`, text: r.slot ? `slot ${r.slot}, ${r.boot_state}` : '–' }),
        h('td', { text: r.hardware_version ?? '–' }), h('td', { class: 'mono', text: r.serial_number ?? '–' }))));
      if (s.inventory.length === 0) inventory.append(h('tr', {}, h('td', { colspan: 6, class: 'muted', text: s.source.transmit ? 'Reading…' : 'The gateway only listens on this bus.' })));
    }
    const f = s.flash;
    if (refusal !== null) {
      showRefusal();
      return;
    }
    if (!f) {
      setText(status, s.source.transmit ? 'No flash yet.' : 'The gateway only listens on this bus: no flashing.');
      return;
    }
    const percent = f.state === 'done' ? 100 : f.transferred !== null && f.bytes ? (100 * f.transferred) / f.bytes : 0;
    progress.value = percent;
    progress.dataset.state = f.state;
    status.className = `flash-status ${f.state}`;
    status.dataset.state = f.state;
    const what = `${f.image} (${f.version}, ${f.variant}) → ${f.ecu}`;
    if (f.state === 'running') setText(status, `${what}: ${f.phase} — ${num(percent)} % of ${bytes(f.bytes)}, ${seconds(f.elapsed_s)}`);
    else if (f.state === 'queued') setText(status, `${what}: waiting for the tester`);
    else if (f.state === 'done') setText(status, `${what}: ${bytes(f.bytes)} into slot ${f.report?.slot ?? '?'}, done in ${seconds(f.report?.total_s ?? 0)}`);
    else setText(status, `${what}: failed — ${f.error}`);
    const report = f.report;
    const text = report ? report.phases.map((p) => `${p.phase} ${num(p.s, 2)} s`).join(' · ') + (report.throughput_bps ? ` · transfer ${bytes(report.throughput_bps)}/s` : '') : '';
    setText(phases, text);
  }
  void loadLibrary();
  return { el, update };
}
