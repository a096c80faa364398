// Recordings: start and stop recording all traffic (candump .log files in the data
// folder), and download them.
import { get, post } from '../api';
import type { Ctx, View } from '../view';
import { bytes, h, setText, utc } from '../util';

export function recordingsView(ctx: Ctx): View {
  const { live } = ctx;
  const toggle = h('button', { class: 'btn primary', 'data-testid': 'record' }, 'Start recording');
  const state = h('div', { 'data-testid': 'recording-state' });
  const list = h('tbody');
  const el = h('section', { class: 'recordings' },
    h('div', { class: 'card' }, h('h3', { text: 'Record all traffic' }), h('div', { class: 'toolbar' }, toggle, state),
      h('p', { class: 'muted small', text: 'candump .log files (one line per frame, bus time), read by candump, python-can, cantools, SavvyCAN; replay one with: autoplug replay FILE --speed 1' })),
    h('div', { class: 'card table-wrap' }, h('h3', { text: 'Recordings' }),
      h('table', { class: 'grid' }, h('thead', {}, h('tr', {}, ...['File', 'Size', 'Modified', ''].map((t) => h('th', { text: t })))), list)),
  );
  toggle.addEventListener('click', async () => {
    const on = !live.session?.recording;
    try {
      await post('/api/recording', { on });
      ctx.toast(on ? 'Recording started' : 'Recording stopped');
      if (!on) setTimeout(() => void load(), 300);
    } catch (e: any) {
      ctx.toast(e.message, 'error');
    }
  });
  async function load(): Promise<void> {
    try {
      const files: any[] = await get('/api/recordings');
      list.replaceChildren(...files.map((f) => h('tr', {},
        h('td', { class: 'mono', text: f.name }), h('td', { text: bytes(f.bytes) }), h('td', { text: utc(f.modified_ms) }),
        h('td', {}, h('a', { href: `/api/recordings/${encodeURIComponent(f.name)}`, download: f.name, text: 'Download' })))));
      if (files.length === 0) list.append(h('tr', {}, h('td', { colspan: 4, class: 'muted', text: 'No recordings yet.' })));
    } catch (e: any) {
      ctx.toast(e.message, 'error');
    }
  }
  let wasOn = false;
  function update(): void {
    const r = live.session?.recording ?? null;
    setText(toggle, r ? 'Stop recording' : 'Start recording');
    toggle.classList.toggle('danger', !!r);
    setText(state, r ? `● ${r.file ?? ''}: ${r.frames} frames, ${bytes(r.bytes)}${r.failure ? ` — ${r.failure}` : ''}` : 'not recording');
    state.classList.toggle('rec', !!r);
    if (wasOn && !r) void load();
    wasOn = !!r;
  }
  void load();
  return { el, update };
}
