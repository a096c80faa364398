// Recordings: start and stop recording all traffic (candump .log files in the data
// folder), and download them.
import { get, post, token } from '../api';
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
      // The session's event says it started or stopped, on every open page.
      await post('/api/recording', { on });
      if (!on) setTimeout(() => void load(), 300);
    } catch (e: any) {
      ctx.toast(e.message, 'error');
    }
  });
  const replayLink = h('div', { class: 'small', 'data-testid': 'replay-link' });
  function pageUrl(port: number): string {
    const t = token();
    return `${location.protocol}//${location.hostname}:${port}/car${t ? `#token=${t}` : ''}`;
  }
  async function openReplay(name: string): Promise<void> {
    // The tab opens now, while the click counts (a browser blocks one opened later).
    const tab = window.open('about:blank', '_blank');
    try {
      const answer = await post(`/api/recordings/${encodeURIComponent(name)}/replay`);
      const url = pageUrl(answer.port);
      // Its own dashboard, beside this one: wait until this gateway has seen it listen
      // (the session's state says so), rather than knock on a port nobody listens on yet.
      for (let i = 0; i < 40; i++) {
        const page = live.session?.replay_page;
        if (page && page.port === answer.port && page.listening) break;
        await new Promise((r) => setTimeout(r, 250));
      }
      if (tab) tab.location.href = url;
    } catch (e: any) {
      tab?.close();
      ctx.toast(e.message, 'error');
    }
  }
  el.append(h('div', { class: 'card' }, h('h3', { text: 'Replay' }),
    h('p', { class: 'muted small', text: 'A recording replays in a dashboard of its own (play, pause, speed, seek), beside the live car.' }), replayLink));

  async function load(): Promise<void> {
    try {
      const files: any[] = await get('/api/recordings');
      list.replaceChildren(...files.map((f) => {
        const replay = h('button', { class: 'btn small', 'data-testid': `open-replay-${f.name}`, text: 'Replay' });
        replay.addEventListener('click', () => void openReplay(f.name));
        return h('tr', {},
          h('td', { class: 'mono', text: f.name }), h('td', { text: bytes(f.bytes) }), h('td', { text: utc(f.modified_ms) }),
          h('td', {}, h('a', { href: `/api/recordings/${encodeURIComponent(f.name)}`, download: f.name, text: 'Download' }), ' ', replay));
      }));
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
    const page = live.session?.replay_page;
    const text = page ? `${page.file} replays on port ${page.port}` : 'No replay open.';
    if (replayLink.textContent !== text + (page ? 'Open' : '')) {
      replayLink.replaceChildren(text, page ? ' ' : '', page ? h('a', { href: pageUrl(page.port), target: '_blank', text: 'Open' }) : '');
    }
  }
  void load();
  return { el, update };
}
