// Bus: the raw view per message identifier, as cabana and SavvyCAN show it: count,
// measured period and jitter, last data with the bytes that changed highlighted, the
// decoded signals; bus load, error frames, unknown and diagnostic traffic.
import type { Ctx, View } from '../view';
import { h, num, setText } from '../util';

const BITRATE = 500_000;

/** Bits of a classic CAN data frame with an 11-bit identifier, before stuffing. */
function frameBits(dlc: number): number {
  return 47 + 8 * dlc;
}

export function busView(ctx: Ctx): View {
  const { live } = ctx;
  const load = h('div', { class: 'figure', 'data-testid': 'bus-load' });
  const frames = h('div', { class: 'figure' });
  const errors = h('div', { class: 'figure', 'data-testid': 'error-frames' });
  const unknown = h('div', { class: 'figure', 'data-testid': 'unknown-frames' });
  const diag = h('div', { class: 'figure' });
  const body = h('tbody');
  const el = h('section', { class: 'bus' },
    h('div', { class: 'card stats' },
      h('div', {}, h('div', { class: 'muted small', text: 'Bus load (500 kbit/s)' }), load),
      h('div', {}, h('div', { class: 'muted small', text: 'Frames' }), frames),
      h('div', {}, h('div', { class: 'muted small', text: 'Error frames' }), errors),
      h('div', {}, h('div', { class: 'muted small', text: 'Unknown IDs (frames)' }), unknown),
      h('div', {}, h('div', { class: 'muted small', text: 'Diagnostic frames' }), diag)),
    h('div', { class: 'card table-wrap' }, h('table', { class: 'grid' },
      h('thead', {}, h('tr', {}, ...['ID', 'Message', 'Count', 'Period', 'Jitter', 'Data', 'Signals'].map((t) => h('th', { text: t })))),
      body)),
  );
  const rows = new Map<string, { tr: HTMLElement; cells: HTMLElement[]; data: HTMLElement; last: string; lastCount: number; dlc: number; signals: HTMLElement }>();
  let sample: { t: number; bits: number } | null = null;

  function update(): void {
    if (rows.size === 0 && live.messages.size) {
      const sorted = [...live.messages.entries()].sort((a, b) => a[1].id - b[1].id);
      for (const [name, m] of sorted) {
        const cells = [0, 1, 2, 3, 4].map(() => h('td'));
        const data = h('td', { class: 'mono' });
        const signals = h('td', { class: 'small' });
        const tr = h('tr', { 'data-testid': `msg-${name}` }, ...cells, data, signals);
        setText(cells[0], `0x${m.id.toString(16).toUpperCase().padStart(3, '0')}`);
        setText(cells[1], name);
        body.append(tr);
        rows.set(name, { tr, cells, data, last: '', lastCount: 0, dlc: m.data.length / 2, signals });
      }
    }
    let bits = 0;
    for (const [name, m] of live.messages) {
      const row = rows.get(name);
      bits += m.count * frameBits(m.data.length / 2);
      if (!row) continue;
      setText(row.cells[2], String(m.count));
      setText(row.cells[3], m.period_ms === null ? '–' : `${num(m.period_ms, 1)} ms`);
      setText(row.cells[4], m.jitter_ms === null ? '–' : `${num(m.jitter_ms, 2)} ms`);
      if (m.data !== row.last) {
        row.data.replaceChildren();
        for (let i = 0; i < m.data.length; i += 2) {
          const byte = m.data.slice(i, i + 2);
          const changed = row.last && row.last.slice(i, i + 2) !== byte;
          row.data.append(h('span', { class: changed ? 'byte changed' : 'byte', text: byte }));
        }
        row.last = m.data;
      }
      const decoded = live.catalog
        .filter((s) => s.name.startsWith(`${name}.`))
        .map((s) => {
          const label = live.label(s.path);
          const v = live.value(s.path);
          const figure = v !== null && Number.isInteger(v) ? String(v) : num(v, Math.abs(v ?? 0) < 10 ? 2 : 0);
          return `${s.name.slice(name.length + 1)} ${label ?? figure}${label ? '' : s.unit ? ` ${s.unit}` : ''}`;
        })
        .join(' · ');
      setText(row.signals, decoded);
    }
    const b = live.bus;
    if (b) {
      bits += (b.unknown_frames + b.diagnostic_frames) * frameBits(8);
      setText(frames, String(b.frames));
      setText(errors, String(b.error_frames));
      errors.classList.toggle('bad', b.error_frames > 0);
      setText(unknown, String(b.unknown_frames));
      setText(diag, String(b.diagnostic_frames));
    }
    // Load from the bits of the frames counted over the last second or more of bus time.
    if (!sample) sample = { t: live.t, bits };
    const dt = live.t - sample.t;
    if (dt >= 1) {
      const percent = (100 * (bits - sample.bits)) / (dt * BITRATE);
      setText(load, `${num(percent, 1)} %`);
      sample = { t: live.t, bits };
    }
  }
  return { el, update };
}
