import './style.css';
import { get, post, tokenFromAddress } from './api';
import { Live } from './live';
import { h, num, seconds, setText } from './util';
import type { Ctx, View } from './view';
import { carView } from './views/car';
import { plotsView } from './views/plots';
import { busView } from './views/bus';
import { diagnosticsView } from './views/diagnostics';
import { ecusView } from './views/ecus';
import { tripsView } from './views/trips';
import { recordingsView } from './views/recordings';
import { driveView } from './views/drive';
import { fleetView } from './views/fleet';
import { offerBanner } from './offer';
import { DriveInput } from './drive-input';

const VIEWS: [string, string, (ctx: Ctx) => View][] = [
  ['car', 'Car', carView],
  ['plots', 'Plots', plotsView],
  ['bus', 'Bus', busView],
  ['diagnostics', 'Diagnostics', diagnosticsView],
  ['ecus', 'ECUs', ecusView],
  ['trips', 'Trips', tripsView],
  ['recordings', 'Recordings', recordingsView],
  ['drive', 'Drive', driveView],
  ['fleet', 'Fleet', fleetView],
];
// What this server shows (`/api/info`): a fleet page alone has no live bus; the Fleet view
// shows only where there is a fleet database behind the server.
const info = await get('/api/info').catch(() => ({ live: true, fleet: false }));
const shown = VIEWS.filter(([path]) => (path === 'fleet' ? info.fleet : info.live !== false));

tokenFromAddress();

const theme = localStorage.getItem('autoplug-theme');
if (theme) document.documentElement.dataset.theme = theme;
document.getElementById('theme')!.addEventListener('click', () => {
  const dark = document.documentElement.dataset.theme
    ? document.documentElement.dataset.theme === 'dark'
    : matchMedia('(prefers-color-scheme: dark)').matches;
  const next = dark ? 'light' : 'dark';
  document.documentElement.dataset.theme = next;
  localStorage.setItem('autoplug-theme', next);
});

const live = new Live();
const events = document.getElementById('events')!;
const ctx: Ctx = {
  live,
  toast(text, kind = 'ok') {
    const t = h('div', { class: `toast ${kind}`, role: kind === 'error' ? 'alert' : 'status', text });
    events.append(t);
    setTimeout(() => t.remove(), kind === 'error' ? 8000 : 4000);
  },
};

if (info.live !== false) ctx.drive = new DriveInput(live, ctx.toast);

const nav = document.getElementById('nav')!;
for (const [path, label] of shown) {
  nav.append(h('a', { href: `/${path}`, 'data-link': true, 'data-view': path, text: label }));
}
const main = document.getElementById('view')!;
let current: View | null = null;

function route(): void {
  const name = location.pathname.replace(/^\//, '') || shown[0][0];
  const found = shown.find(([path]) => path === name) ?? shown[0];
  current?.destroy?.();
  current = found[2](ctx);
  main.replaceChildren(current.el);
  main.dataset.view = found[0];
  for (const a of nav.querySelectorAll('a')) a.classList.toggle('active', a.dataset.view === found[0]);
  document.title = `AutoPlug · ${found[1]}`;
  current.update();
}

document.addEventListener('click', (e) => {
  const a = (e.target as HTMLElement).closest('a[data-link]') as HTMLAnchorElement | null;
  if (!a || e.ctrlKey || e.metaKey || e.shiftKey) return;
  e.preventDefault();
  history.pushState(null, '', a.getAttribute('href')!);
  route();
});
window.addEventListener('popstate', route);

// The replay's controls, shown on every view when the bus is a recorded log.
const player = document.getElementById('player')!;
const playButton = h('button', { class: 'btn', 'data-testid': 'replay-play' }, 'Pause');
const speedSelect = h('select', { 'aria-label': 'replay speed', 'data-testid': 'replay-speed' },
  ...[0.25, 0.5, 1, 2, 4, 10, 50].map((x) => h('option', { value: x, text: `${x}×` })));
const seek = h('input', { type: 'range', min: 0, max: 1, step: 0.1, value: 0, class: 'seek', 'aria-label': 'position in the log', 'data-testid': 'replay-seek' });
const where = h('span', { class: 'muted small', 'data-testid': 'replay-position' });
let seeking = false;
async function replay(body: object): Promise<void> {
  try {
    await post('/api/replay', body);
  } catch (e: any) {
    ctx.toast(e.message, 'error');
  }
}
playButton.addEventListener('click', () => void replay({ action: live.session?.replay?.playing ? 'pause' : 'play' }));
speedSelect.addEventListener('change', () => void replay({ action: 'speed', speed: Number(speedSelect.value) }));
seek.addEventListener('input', () => { seeking = true; });
seek.addEventListener('change', () => { seeking = false; void replay({ action: 'seek', t: Number(seek.value) }); });
player.append(h('strong', { text: 'Replay' }), playButton, speedSelect, seek, where);

function updatePlayer(): void {
  const r = live.session?.replay;
  player.hidden = !r;
  if (!r) return;
  setText(playButton, r.playing ? 'Pause' : 'Play');
  if (document.activeElement !== speedSelect) speedSelect.value = String(r.speed);
  seek.max = String(r.duration_s);
  if (!seeking) seek.value = String(r.position_s);
  setText(where, `${seconds(r.position_s)} / ${seconds(r.duration_s)}${r.at_end ? ' (end)' : ''}`);
}

// The debuggers of emulated ECUs (--gdb): a halt stops the whole car, which the page says.
const debuggerBar = document.getElementById('debugger')!;
function updateDebugger(): void {
  const ecus = live.debuggers?.ecus ?? [];
  debuggerBar.hidden = ecus.length === 0;
  const halted = ecus.filter((e) => e.halted);
  debuggerBar.classList.toggle('halted', halted.length > 0);
  if (halted.length > 0) {
    const who = halted.map((e) => `${e.ecu} (GDB from ${e.client ?? 'a client'})`).join(', ');
    setText(debuggerBar, `Halted by the debugger: ${who}. The whole car stands still at t = ${num(live.t, 3)} s: bus, vehicle and the other ECUs wait, and no diagnosis counts the pause. Continue in GDB to go on.`);
    return;
  }
  setText(debuggerBar, ecus.map((e) => e.attached
    ? `${e.ecu}: GDB attached from ${e.client ?? '?'}, running`
    : `${e.ecu}: GDB server on ${e.address} (target extended-remote ${e.address})`).join(' · '));
}

const offer = offerBanner(live, ctx.toast);
document.getElementById('offer-slot')!.append(offer.el);

const conn = document.getElementById('conn')!;
const busTime = document.getElementById('bustime')!;
// Events already shown (the page shows only those that happen while it is open).
let seenEvents: number | null = null;
let scheduled = false;
live.subscribe(() => {
  if (scheduled) return;
  scheduled = true;
  requestAnimationFrame(() => {
    scheduled = false;
    setText(conn, live.connected ? (live.session?.source.name ?? 'live') : 'offline');
    conn.className = `pill ${live.connected ? 'on' : 'off'}`;
    setText(busTime, live.connected ? `t = ${num(live.t, 1)} s` : '');
    const list = live.session?.events ?? [];
    const last = list.length ? list[list.length - 1].t : 0;
    if (live.session && seenEvents === null) seenEvents = last;
    if (seenEvents !== null && last > seenEvents) {
      for (const ev of list) if (ev.t > seenEvents) ctx.toast(ev.text, /fail|refus/i.test(ev.text) ? 'error' : 'ok');
      seenEvents = last;
    }
    updatePlayer();
    updateDebugger();
    offer.update();
    current?.update();
  });
});

route();
if (info.live !== false) live.connect();
else {
  setText(conn, 'fleet');
  conn.className = 'pill on';
}
