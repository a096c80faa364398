// Drive: a person drives the virtual car from the page — keyboard, touch, or a game
// controller or steering wheel through the browser's Gamepad API. What is sent are the
// car's sensor inputs (pedals, wheel, switches, buttons); the dashboard then shows only
// what the ECUs put on the bus.
import { post, token } from '../api';
import { STEER_MAX, type Button } from '../drive-input';
import type { Ctx, View } from '../view';
import { h, num, setText } from '../util';
import { worldView } from '../world';

export function driveView(ctx: Ctx): View {
  const { live } = ctx;
  // The controls live with the page (see drive-input.ts); this view shows and works them.
  const input = ctx.drive!;
  const state = input.state;
  input.active = true;

  const authState = h('div', { class: 'muted small', 'data-testid': 'drive-auth' });
  const tokenInput = h('input', { type: 'password', placeholder: 'token printed by autoplug dashboard', 'aria-label': 'write token' });
  const tokenBox = h('div', { class: 'form', hidden: true }, tokenInput, h('button', { class: 'btn', onclick: () => { input.authorize(tokenInput.value.trim()); authorize(); } }, 'Use token'));

  const pedal = (name: 'accelerator' | 'brake', label: string) => {
    const slider = h('input', { type: 'range', min: 0, max: 100, value: 0, class: `pedal ${name}`, orient: 'vertical', 'aria-label': label, 'data-testid': `pedal-${name}` });
    const release = () => { slider.value = '0'; input.touch[name] = 0; };
    slider.addEventListener('input', () => { input.touch[name] = Number(slider.value); input.engaged = true; });
    slider.addEventListener('pointerup', release);
    slider.addEventListener('pointercancel', release);
    slider.addEventListener('touchend', release);
    return h('label', { class: 'pedal-box' }, slider, h('span', { text: label }));
  };
  const steer = h('input', { type: 'range', min: -STEER_MAX, max: STEER_MAX, value: 0, step: 1, class: 'steer', 'aria-label': 'steering wheel', 'data-testid': 'steer' });
  steer.addEventListener('input', () => { state.steering_deg = -Number(steer.value); input.engaged = true; });
  steer.addEventListener('dblclick', () => { steer.value = '0'; state.steering_deg = 0; });

  const press = (button: Button) => input.press(button);
  const btn = (text: string, button: Button, key: string) =>
    h('button', { class: 'btn', 'data-testid': `press-${button}`, title: `key ${key}`, onclick: () => press(button) }, text, h('kbd', { text: key }));
  const toggle = (text: string, field: 'headlights' | 'economy_mode' | 'manual_mode', key: string) => {
    const b = h('button', { class: 'btn toggle', 'data-testid': `switch-${field}`, title: `key ${key}` }, text, h('kbd', { text: key }));
    b.addEventListener('click', () => { state[field] = !state[field]; input.engaged = true; });
    return b;
  };
  const switches = [toggle('Headlights', 'headlights', 'L'), toggle('Economy', 'economy_mode', 'M'), toggle('Manual shift', 'manual_mode', 'T')];
  const knob = h('input', { type: 'range', min: 60, max: 85, step: 0.5, value: 72, 'aria-label': 'cabin set temperature', 'data-testid': 'cabin-knob' });
  const knobText = h('span');
  knob.addEventListener('input', () => { state.set_temp_f = Number(knob.value); input.engaged = true; });

  // The friction buttons show which is in force (the session says what the road has).
  const frictions: [HTMLElement, number, number][] = [];
  const road = (label: string, id: string, left: number, right: number) => {
    const b = h('button', { class: 'btn', 'data-testid': `road-${id}`, 'aria-pressed': 'false', onclick: async () => {
      // Said by the session's event (once, on every open page), shown by the buttons.
      try { await post('/api/road', { mu_left: left, mu_right: right }); } catch (e: any) { ctx.toast(e.message, 'error'); }
    } }, label);
    frictions.push([b, left, right]);
    return b;
  };
  const frictionNow = h('div', { class: 'muted small', 'data-testid': 'road-friction' });

  const toStart = h('button', { class: 'btn', 'data-testid': 'road-start', onclick: async () => {
    try { await post('/api/road/start', {}); } catch (e: any) { ctx.toast(e.message, 'error'); }
  } }, 'Back to the start');

  // The simulator's lane keeping: it steers along the track while the person drives the
  // rest (the session says whether it is on; a car on the endless plane has no road).
  let alongRoad = false;
  const setAlongRoad = async (on: boolean) => {
    try { await post('/api/road/steering', { along_road: on }); } catch (e: any) { ctx.toast(e.message, 'error'); }
  };
  const alongRoadButton = h('button', { class: 'btn toggle', 'data-testid': 'steer-along-road', title: 'key R', disabled: true, onclick: () => setAlongRoad(!alongRoad) },
    'Steer along the road', h('kbd', { text: 'R' }));
  input.onSteerAlongRoad = () => { if (!alongRoadButton.disabled) void setAlongRoad(!alongRoad); };

  const readout = h('div', { class: 'readout' });
  const speedBig = h('div', { class: 'big-speed', 'data-testid': 'drive-speed' });
  const pad = h('div', { class: 'muted small' });
  const released = h('div', { class: 'small warn', 'data-testid': 'drive-released', role: 'status' });
  const world = worldView(live);
  // Hidden on a bus that cannot be driven (a replay, a real bus): the world view stays.
  let controlsCard: HTMLElement;
  let roadCard: HTMLElement;
  let keysHelp: HTMLElement;
  const el = h('section', { class: 'drive' },
    world.el,
    h('div', { class: 'card' }, h('div', { class: 'toolbar' }, speedBig, readout), authState, released, tokenBox,
      keysHelp = h('p', { class: 'muted small keys-help', text: 'Keys: ↑/W accelerator · ↓/S brake · ←→/A D steer · R steer along the road (the simulator steers) · C cruise on · X cruise off · E/Q shift up/down · L lights · M economy · T manual. A game controller or wheel works too (right trigger accelerator, left trigger brake, stick or wheel steers, bumpers shift, A/B cruise).' }), pad),
    controlsCard = h('div', { class: 'card controls' },
      h('div', { class: 'pedals' }, pedal('brake', 'Brake'), pedal('accelerator', 'Accelerator')),
      h('div', { class: 'wheel-col' }, h('div', { class: 'muted small', text: 'Steering wheel' }), steer, alongRoadButton,
        h('div', { class: 'buttons' }, btn('Cruise on / set', 'cruise_on', 'C'), btn('Cruise off', 'cruise_off', 'X'), btn('Shift down', 'shift_down', 'Q'), btn('Shift up', 'shift_up', 'E')),
        h('div', { class: 'buttons' }, ...switches),
        h('label', { class: 'knob' }, 'Cabin set point ', knob, knobText))),
    roadCard = h('div', { class: 'card' }, h('h3', { text: 'Road (the simulator, not the car)' }), h('div', { class: 'buttons' }, road('Dry', 'dry', 1.0, 1.0), road('Wet', 'wet', 0.5, 0.5), road('Split µ (right icy)', 'split', 1.0, 0.2), toStart), frictionNow,
      h('p', { class: 'muted small', text: 'Dry, wet and split set the friction under the left and right wheels (on a track: of the road’s left and right halves; patches and the verge keep their own). Back to the start takes the standing car back to where it started.' })),
  );

  /** The session's source takes a person's inputs (until the session is known: yes). */
  function drivable(): boolean {
    return !live.session || live.session.source.drive;
  }

  function authorize(): void {
    if (!token()) {
      tokenBox.hidden = false;
      setText(authState, 'Driving needs the token printed by autoplug dashboard (open the address it printed, or paste the token).');
      return;
    }
    input.authorize();
  }
  const unlisten = live.listen((m) => {
    if (m.type === 'error') ctx.toast(m.error, 'error');
  });
  authorize();

  function update(): void {
    setText(speedBig, `${num(live.value('Vehicle.Speed'))} km/h`);
    const d = live.session?.driver;
    if (!drivable()) {
      setText(authState, live.session?.source.replay
        ? 'A replay: it cannot be driven; the world view shows the recording\'s.'
        : 'This bus is not the virtual car: it cannot be driven from here.');
    }
    controlsCard.hidden = roadCard.hidden = keysHelp.hidden = readout.hidden = !drivable();
    if (d) {
      for (const [b, left, right] of frictions) {
        const on = d.mu_left === left && d.mu_right === right;
        b.classList.toggle('active', on);
        b.setAttribute('aria-pressed', String(on));
      }
      setText(frictionNow, `Friction now: µ ${d.mu_left} under the left wheels, ${d.mu_right} under the right (drawn on the world view's road).`);
    }
    alongRoad = d?.steers_along_road ?? false;
    alongRoadButton.classList.toggle('active', alongRoad);
    alongRoadButton.dataset.on = String(alongRoad);
    if (d && !input.engaged && d.held) {
      // Start from what the car's driver holds (another tab may have driven).
      Object.assign(state, d.held);
      knob.value = String(d.held.set_temp_f);
    }
    if (input.authAnswer !== null) {
      tokenBox.hidden = input.authAnswer;
      if (drivable()) setText(authState, input.authAnswer ? 'You have the wheel: the controls below are the car\'s sensor inputs.' : 'The token was refused.');
      authState.dataset.ok = String(input.authAnswer);
    }
    // Without the gateway nothing here reaches the car: the controls say so by being off.
    controlsCard.classList.toggle('offline', !live.connected);
    for (const control of controlsCard.querySelectorAll<HTMLInputElement | HTMLButtonElement>('input, button')) {
      if (control === alongRoadButton) continue;
      control.disabled = !live.connected || (control === steer && alongRoad);
    }
    alongRoadButton.disabled = !live.connected || !d?.on_track;
    const pedals = input.pedals();
    setText(readout, `accelerator ${num(pedals.accelerator)} % · brake ${num(pedals.brake)} % · wheel ${alongRoad ? 'the simulator’s' : `${num(state.steering_deg)}°`}`);
    readout.dataset.accelerator = String(pedals.accelerator);
    readout.dataset.brake = String(pedals.brake);
    setText(pad, input.gamepad ? `Controller: ${input.gamepad}` : '');
    steer.value = String(-state.steering_deg);
    switches[0].classList.toggle('active', state.headlights);
    switches[1].classList.toggle('active', state.economy_mode);
    switches[2].classList.toggle('active', state.manual_mode);
    setText(knobText, `${num(state.set_temp_f, 1)} °F`);
    const why = input.released && performance.now() - input.released.at < 5000 ? `Controls released: ${input.released.why}.` : '';
    setText(released, why);
  }
  return {
    el,
    update,
    destroy() {
      // Keys held stay held until released (the brake while flashing); new presses wait
      // for the Drive view.
      input.active = false;
      input.onSteerAlongRoad = null;
      unlisten();
      world.destroy();
    },
  };
}
