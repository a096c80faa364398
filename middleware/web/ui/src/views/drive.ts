// Drive: a person drives the virtual car from the page — keyboard, touch, or a game
// controller or steering wheel through the browser's Gamepad API. What is sent are the
// car's sensor inputs (pedals, wheel, switches, buttons); the dashboard then shows only
// what the ECUs put on the bus.
import { post, setToken, token } from '../api';
import type { DriveState } from '../live';
import type { Ctx, View } from '../view';
import { h, num, setText } from '../util';
import { worldView } from '../world';

/** How often the controls are sent while the view is open (the gateway's dead man's
 *  release comes after 1 s without them). */
const SEND_MS = 50;
/** Pedal travel per second under the keyboard, %. */
const PEDAL_RATE = 250;
/** Steering wheel travel per second under the keyboard, degrees. */
const STEER_RATE = 180;
const STEER_MAX = 135;

type Button = 'cruise_on' | 'cruise_off' | 'shift_up' | 'shift_down';

export function driveView(ctx: Ctx): View {
  const { live } = ctx;
  const state: DriveState = { accelerator: 0, brake: 0, steering_deg: 0, headlights: false, economy_mode: false, manual_mode: false, set_temp_f: 72 };
  let engaged = false;
  let authorized = false;
  const keys = new Set<string>();
  let touch = { accelerator: 0, brake: 0 };

  const authState = h('div', { class: 'muted small', 'data-testid': 'drive-auth' });
  const tokenInput = h('input', { type: 'password', placeholder: 'token printed by autoplug dashboard', 'aria-label': 'write token' });
  const tokenBox = h('div', { class: 'form', hidden: true }, tokenInput, h('button', { class: 'btn', onclick: () => { setToken(tokenInput.value.trim()); authorize(); } }, 'Use token'));

  const pedal = (name: 'accelerator' | 'brake', label: string) => {
    const input = h('input', { type: 'range', min: 0, max: 100, value: 0, class: `pedal ${name}`, orient: 'vertical', 'aria-label': label, 'data-testid': `pedal-${name}` });
    const release = () => { input.value = '0'; touch[name] = 0; };
    input.addEventListener('input', () => { touch[name] = Number(input.value); engaged = true; });
    input.addEventListener('pointerup', release);
    input.addEventListener('pointercancel', release);
    input.addEventListener('touchend', release);
    return h('label', { class: 'pedal-box' }, input, h('span', { text: label }));
  };
  const steer = h('input', { type: 'range', min: -STEER_MAX, max: STEER_MAX, value: 0, step: 1, class: 'steer', 'aria-label': 'steering wheel', 'data-testid': 'steer' });
  steer.addEventListener('input', () => { state.steering_deg = -Number(steer.value); engaged = true; });
  steer.addEventListener('dblclick', () => { steer.value = '0'; state.steering_deg = 0; });

  const press = (button: Button) => {
    engaged = true;
    if (!live.send({ type: 'press', button })) ctx.toast('not connected', 'error');
  };
  const btn = (text: string, button: Button, key: string) =>
    h('button', { class: 'btn', 'data-testid': `press-${button}`, title: `key ${key}`, onclick: () => press(button) }, text, h('kbd', { text: key }));
  const toggle = (text: string, field: 'headlights' | 'economy_mode' | 'manual_mode', key: string) => {
    const b = h('button', { class: 'btn toggle', 'data-testid': `switch-${field}`, title: `key ${key}` }, text, h('kbd', { text: key }));
    b.addEventListener('click', () => { state[field] = !state[field]; engaged = true; });
    return b;
  };
  const switches = [toggle('Headlights', 'headlights', 'L'), toggle('Economy', 'economy_mode', 'M'), toggle('Manual shift', 'manual_mode', 'T')];
  const knob = h('input', { type: 'range', min: 60, max: 85, step: 0.5, value: 72, 'aria-label': 'cabin set temperature', 'data-testid': 'cabin-knob' });
  const knobText = h('span');
  knob.addEventListener('input', () => { state.set_temp_f = Number(knob.value); engaged = true; });

  const road = (label: string, id: string, left: number, right: number) => h('button', { class: 'btn', 'data-testid': `road-${id}`, onclick: async () => {
    try { await post('/api/road', { mu_left: left, mu_right: right }); ctx.toast(`Road: ${label}`); } catch (e: any) { ctx.toast(e.message, 'error'); }
  } }, label);

  const toStart = h('button', { class: 'btn', 'data-testid': 'road-start', onclick: async () => {
    try { await post('/api/road/start', {}); ctx.toast('Back at the start'); } catch (e: any) { ctx.toast(e.message, 'error'); }
  } }, 'Back to the start');

  // The simulator's lane keeping: it steers along the track while the person drives the
  // rest (the session says whether it is on; a car on the endless plane has no road).
  let alongRoad = false;
  const setAlongRoad = async (on: boolean) => {
    try { await post('/api/road/steering', { along_road: on }); ctx.toast(on ? 'The simulator steers along the road' : 'You steer'); } catch (e: any) { ctx.toast(e.message, 'error'); }
  };
  const alongRoadButton = h('button', { class: 'btn toggle', 'data-testid': 'steer-along-road', title: 'key R', disabled: true, onclick: () => setAlongRoad(!alongRoad) },
    'Steer along the road', h('kbd', { text: 'R' }));

  const readout = h('div', { class: 'readout' });
  const speedBig = h('div', { class: 'big-speed', 'data-testid': 'drive-speed' });
  const pad = h('div', { class: 'muted small' });
  const world = worldView(live);
  // Hidden on a bus that cannot be driven (a replay, a real bus): the world view stays.
  let controlsCard: HTMLElement;
  let roadCard: HTMLElement;
  let keysHelp: HTMLElement;
  const el = h('section', { class: 'drive' },
    world.el,
    h('div', { class: 'card' }, h('div', { class: 'toolbar' }, speedBig, readout), authState, tokenBox,
      keysHelp = h('p', { class: 'muted small', text: 'Keys: ↑/W accelerator · ↓/S brake · ←→/A D steer · R steer along the road (the simulator steers) · C cruise on · X cruise off · E/Q shift up/down · L lights · M economy · T manual. A game controller or wheel works too (right trigger accelerator, left trigger brake, stick or wheel steers, bumpers shift, A/B cruise).' }), pad),
    controlsCard = h('div', { class: 'card controls' },
      h('div', { class: 'pedals' }, pedal('brake', 'Brake'), pedal('accelerator', 'Accelerator')),
      h('div', { class: 'wheel-col' }, h('div', { class: 'muted small', text: 'Steering wheel' }), steer, alongRoadButton,
        h('div', { class: 'buttons' }, btn('Cruise on / set', 'cruise_on', 'C'), btn('Cruise off', 'cruise_off', 'X'), btn('Shift down', 'shift_down', 'Q'), btn('Shift up', 'shift_up', 'E')),
        h('div', { class: 'buttons' }, ...switches),
        h('label', { class: 'knob' }, 'Cabin set point ', knob, knobText))),
    roadCard = h('div', { class: 'card' }, h('h3', { text: 'Road (the simulator, not the car)' }), h('div', { class: 'buttons' }, road('Dry', 'dry', 1.0, 1.0), road('Wet', 'wet', 0.5, 0.5), road('Split µ (right icy)', 'split', 1.0, 0.2), toStart),
      h('p', { class: 'muted small', text: 'Dry, wet and split set the friction under the left and right wheels (on a track: of the road’s left and right halves; patches and the verge keep their own). Back to the start takes the standing car back to where it started.' })),
  );

  /** The session's source takes a person's inputs (until the session is known: yes). */
  function drivable(): boolean {
    return !live.session || live.session.source.drive;
  }

  function authorize(): void {
    const t = token();
    if (!t) {
      authorized = false;
      tokenBox.hidden = false;
      setText(authState, 'Driving needs the token printed by autoplug dashboard (open the address it printed, or paste the token).');
      return;
    }
    live.send({ type: 'auth', token: t });
  }
  const unlisten = live.listen((m) => {
    if (m.type === 'catalog') authorize();
    if (m.type === 'auth') {
      authorized = m.ok;
      tokenBox.hidden = m.ok;
      if (drivable()) setText(authState, m.ok ? 'You have the wheel: the controls below are the car\'s sensor inputs.' : 'The token was refused.');
      authState.dataset.ok = String(m.ok);
    }
    if (m.type === 'error') ctx.toast(m.error, 'error');
  });
  authorize();

  const KEYMAP: Record<string, Button> = { c: 'cruise_on', x: 'cruise_off', e: 'shift_up', q: 'shift_down' };
  const onKey = (e: KeyboardEvent) => {
    if ((e.target as HTMLElement)?.tagName === 'INPUT' && (e.target as HTMLInputElement).type !== 'range') return;
    const k = e.key.length === 1 ? e.key.toLowerCase() : e.key;
    if (e.type === 'keydown') {
      if (['ArrowUp', 'ArrowDown', 'ArrowLeft', 'ArrowRight', ' '].includes(k)) e.preventDefault();
      if (!e.repeat) {
        if (KEYMAP[k]) press(KEYMAP[k]);
        if (k === 'l') { state.headlights = !state.headlights; engaged = true; }
        if (k === 'm') { state.economy_mode = !state.economy_mode; engaged = true; }
        if (k === 't') { state.manual_mode = !state.manual_mode; engaged = true; }
        if (k === 'r' && !alongRoadButton.disabled) setAlongRoad(!alongRoad);
      }
      keys.add(k);
      engaged = true;
    } else {
      keys.delete(k);
    }
  };
  window.addEventListener('keydown', onKey);
  window.addEventListener('keyup', onKey);
  const onBlur = () => keys.clear();
  window.addEventListener('blur', onBlur);

  const padButtons: boolean[] = [];
  let keyPedal = { accelerator: 0, brake: 0 };
  let last = performance.now();
  const timer = window.setInterval(() => {
    const now = performance.now();
    const dt = Math.min(0.2, (now - last) / 1000);
    last = now;
    const held = (...names: string[]) => names.some((n) => keys.has(n));
    const ramp = (v: number, up: boolean) => Math.max(0, Math.min(100, v + (up ? 1 : -1.5) * PEDAL_RATE * dt));
    keyPedal = { accelerator: ramp(keyPedal.accelerator, held('ArrowUp', 'w')), brake: ramp(keyPedal.brake, held('ArrowDown', 's')) };
    let accelerator = Math.max(keyPedal.accelerator, touch.accelerator);
    let brake = Math.max(keyPedal.brake, touch.brake);
    if (held('ArrowLeft', 'a')) state.steering_deg = Math.min(STEER_MAX, state.steering_deg + STEER_RATE * dt);
    else if (held('ArrowRight', 'd')) state.steering_deg = Math.max(-STEER_MAX, state.steering_deg - STEER_RATE * dt);
    // Gamepad API: the standard mapping (triggers 6/7, bumpers 4/5, A/B 0/1, stick 0).
    const gp = (navigator.getGamepads?.() ?? []).find((g) => g && g.connected);
    if (gp) {
      setText(pad, `Controller: ${gp.id}`);
      const axis = gp.axes[0] ?? 0;
      if (Math.abs(axis) > 0.05) { state.steering_deg = -axis * STEER_MAX; engaged = true; }
      const trigger = (i: number) => gp.buttons[i]?.value ?? 0;
      if (trigger(7) > 0.02 || trigger(6) > 0.02) engaged = true;
      accelerator = Math.max(accelerator, 100 * trigger(7));
      brake = Math.max(brake, 100 * trigger(6));
      const edges: [number, Button][] = [[5, 'shift_up'], [4, 'shift_down'], [0, 'cruise_on'], [1, 'cruise_off']];
      for (const [i, button] of edges) {
        const down = gp.buttons[i]?.pressed ?? false;
        if (down && !padButtons[i]) press(button);
        padButtons[i] = down;
      }
    }
    state.accelerator = accelerator;
    state.brake = brake;
    steer.value = String(-state.steering_deg);
    switches[0].classList.toggle('active', state.headlights);
    switches[1].classList.toggle('active', state.economy_mode);
    switches[2].classList.toggle('active', state.manual_mode);
    setText(knobText, `${num(state.set_temp_f, 1)} °F`);
    if (engaged && authorized) live.send({ type: 'drive', ...state });
    setText(readout, `accelerator ${num(accelerator)} % · brake ${num(brake)} % · wheel ${alongRoad ? 'the simulator’s' : `${num(state.steering_deg)}°`}`);
  }, SEND_MS);

  function update(): void {
    setText(speedBig, `${num(live.value('Vehicle.Speed'))} km/h`);
    const d = live.session?.driver;
    if (!drivable()) {
      setText(authState, live.session?.source.replay
        ? 'A replay: it cannot be driven; the world view shows the recording\'s.'
        : 'This bus is not the virtual car: it cannot be driven from here.');
    }
    controlsCard.hidden = roadCard.hidden = keysHelp.hidden = readout.hidden = !drivable();
    alongRoad = d?.steers_along_road ?? false;
    alongRoadButton.disabled = !d?.on_track;
    alongRoadButton.classList.toggle('active', alongRoad);
    alongRoadButton.dataset.on = String(alongRoad);
    steer.disabled = alongRoad;
    if (d && !engaged && d.held) {
      // Start from what the car's driver holds (another tab may have driven).
      Object.assign(state, d.held);
      knob.value = String(d.held.set_temp_f);
    }
  }
  return {
    el,
    update,
    destroy() {
      window.clearInterval(timer);
      window.removeEventListener('keydown', onKey);
      window.removeEventListener('keyup', onKey);
      window.removeEventListener('blur', onBlur);
      unlisten();
      world.destroy();
    },
  };
}
