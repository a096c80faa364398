// The person's controls of the virtual car, one per page: keyboard, touch and a game
// controller, ramped and sent on the stream every 50 ms while the person drives.
//
// It lives as long as the page, not the Drive view: a key held while the person switches
// to another view (the brake, while flashing an ECU of the standing car) stays held until
// it is released, wherever the page has the keyboard. New presses drive only from the
// Drive view. Whatever takes the keyboard or the page from the person releases every held
// control at once, on the bus as well: the window losing focus, the page hidden or left,
// the stream lost (the gateway also releases the pedals when a driving stream ends).
import { setToken, token } from './api';
import type { DriveState, Live } from './live';

/** How often the controls are sent while the person drives (the gateway's dead man's
 *  release comes after 1 s without them). */
const SEND_MS = 50;
/** Pedal travel per second under the keyboard, %. */
const PEDAL_RATE = 250;
/** Steering wheel travel per second under the keyboard, degrees. */
const STEER_RATE = 180;
export const STEER_MAX = 135;

export type Button = 'cruise_on' | 'cruise_off' | 'shift_up' | 'shift_down';

/** How long after "cruise on" the bus must show cruise active, ms (the ECUs confirm
 *  within two 20 ms steps; the page's state comes at 20 Hz). */
const CRUISE_ANSWER_MS = 600;
const CRUISE_ACTIVE = 'Vehicle.ADAS.CruiseControl.IsActive';
const ACCELERATOR = 'Vehicle.Chassis.Accelerator.PedalPosition';
const BRAKE = 'Vehicle.Chassis.Brake.PedalPosition';

const KEYMAP: Record<string, Button> = { c: 'cruise_on', x: 'cruise_off', e: 'shift_up', q: 'shift_down' };

export class DriveInput {
  readonly state: DriveState = { accelerator: 0, brake: 0, steering_deg: 0, headlights: false, economy_mode: false, manual_mode: false, set_temp_f: 72 };
  /** The person has given an input: from then on the controls go on the stream. */
  engaged = false;
  /** The gateway took the token: this stream may drive. */
  authorized = false;
  /** The gateway's last answer to the token (null before one). */
  authAnswer: boolean | null = null;
  /** The Drive view is shown: new key presses drive. */
  active = false;
  /** Called for key R in the Drive view (the simulator's lane keeping). */
  onSteerAlongRoad: (() => void) | null = null;
  /** The controller in use, if any. */
  gamepad: string | null = null;
  /** Why the controls were last released by the page, and when (ms, performance.now()). */
  released: { why: string; at: number } | null = null;
  touch = { accelerator: 0, brake: 0 };

  private keys = new Set<string>();
  private keyPedal = { accelerator: 0, brake: 0 };
  private padButtons: boolean[] = [];
  /** The last tick sent something held. */
  private sentHolding = false;
  private last = performance.now();

  constructor(
    private readonly live: Live,
    private readonly toast: (text: string, kind?: 'ok' | 'error') => void,
  ) {
    window.addEventListener('keydown', this.onKey);
    window.addEventListener('keyup', this.onKey);
    window.addEventListener('blur', () => this.release('the window lost the keyboard'));
    document.addEventListener('visibilitychange', () => {
      if (document.visibilityState === 'hidden') this.release('the page was hidden');
    });
    window.addEventListener('pagehide', () => this.release('the page was left'));
    let wasConnected = false;
    live.subscribe(() => {
      if (wasConnected && !live.connected) this.release('the connection to the gateway was lost');
      wasConnected = live.connected;
    });
    live.listen((m) => {
      if (m.type === 'catalog') this.authorize();
      if (m.type === 'auth') {
        this.authorized = m.ok;
        this.authAnswer = m.ok;
      }
    });
    window.setInterval(() => this.tick(), SEND_MS);
  }

  /** Sends the token (false when this tab has none). */
  authorize(value?: string): boolean {
    if (value !== undefined) setToken(value);
    const t = token();
    if (!t) {
      this.authorized = false;
      return false;
    }
    this.live.send({ type: 'auth', token: t });
    return true;
  }

  press(button: Button): void {
    this.engaged = true;
    if (!this.live.send({ type: 'press', button })) {
      this.toast('not connected', 'error');
      return;
    }
    if (button === 'cruise_on') window.setTimeout(() => this.explainCruise(), CRUISE_ANSWER_MS);
  }

  /** Cruise pressed on and the bus does not show it active: say why, from the bus. The
   *  pedals ECU cancels cruise while a pedal is pressed (a foot still on the accelerator,
   *  or the keyboard's pedal still ramping down). */
  private explainCruise(): void {
    if (this.live.value(CRUISE_ACTIVE) === 1) return;
    const pressed = [
      ['accelerator', this.live.value(ACCELERATOR)],
      ['brake', this.live.value(BRAKE)],
    ].filter(([, v]) => typeof v === 'number' && v > 0);
    const why = pressed.length
      ? `the pedals ECU cancels cruise while a pedal is pressed (on the bus: ${pressed.map(([n, v]) => `${n} ${Math.round(v as number)} %`).join(', ')}): let go of it, then press C again`
      : 'the cruise ECU did not report it active on the bus';
    this.toast(`Cruise did not engage: ${why}.`, 'error');
  }

  /** Lets go of everything held (keys, touch, triggers ramp from zero) and says so on the
   *  stream at once. The switches and the wheel stay where they are. */
  release(why: string): void {
    const held = this.holding();
    this.keys.clear();
    this.touch = { accelerator: 0, brake: 0 };
    this.keyPedal = { accelerator: 0, brake: 0 };
    this.state.accelerator = 0;
    this.state.brake = 0;
    if (held) this.released = { why, at: performance.now() };
    this.send();
  }

  /** The page's pedal positions now, %. */
  pedals(): { accelerator: number; brake: number } {
    return { accelerator: this.state.accelerator, brake: this.state.brake };
  }

  /** Something is held: a key, a touch pedal, a trigger. */
  private holding(): boolean {
    return this.keys.size > 0 || this.state.accelerator > 0 || this.state.brake > 0;
  }

  private send(): void {
    if (this.engaged && this.authorized) this.live.send({ type: 'drive', ...this.state });
  }

  private onKey = (e: KeyboardEvent): void => {
    if ((e.target as HTMLElement)?.tagName === 'INPUT' && (e.target as HTMLInputElement).type !== 'range') return;
    const k = e.key.length === 1 ? e.key.toLowerCase() : e.key;
    if (e.type === 'keyup') {
      this.keys.delete(k);
      return;
    }
    if (!this.active) return;
    if (['ArrowUp', 'ArrowDown', 'ArrowLeft', 'ArrowRight', ' '].includes(k)) e.preventDefault();
    if (!e.repeat) {
      if (KEYMAP[k]) this.press(KEYMAP[k]);
      if (k === 'l') this.state.headlights = !this.state.headlights;
      if (k === 'm') this.state.economy_mode = !this.state.economy_mode;
      if (k === 't') this.state.manual_mode = !this.state.manual_mode;
      if (k === 'r') this.onSteerAlongRoad?.();
    }
    this.keys.add(k);
    this.engaged = true;
  };

  private tick(): void {
    const now = performance.now();
    const dt = Math.min(0.2, (now - this.last) / 1000);
    this.last = now;
    const state = this.state;
    const held = (...names: string[]) => names.some((n) => this.keys.has(n));
    const ramp = (v: number, up: boolean) => Math.max(0, Math.min(100, v + (up ? 1 : -1.5) * PEDAL_RATE * dt));
    this.keyPedal = { accelerator: ramp(this.keyPedal.accelerator, held('ArrowUp', 'w')), brake: ramp(this.keyPedal.brake, held('ArrowDown', 's')) };
    let accelerator = Math.max(this.keyPedal.accelerator, this.touch.accelerator);
    let brake = Math.max(this.keyPedal.brake, this.touch.brake);
    if (held('ArrowLeft', 'a')) state.steering_deg = Math.min(STEER_MAX, state.steering_deg + STEER_RATE * dt);
    else if (held('ArrowRight', 'd')) state.steering_deg = Math.max(-STEER_MAX, state.steering_deg - STEER_RATE * dt);
    // Gamepad API: the standard mapping (triggers 6/7, bumpers 4/5, A/B 0/1, stick 0).
    const gp = (navigator.getGamepads?.() ?? []).find((g) => g && g.connected);
    this.gamepad = gp ? gp.id : null;
    if (gp && document.hasFocus()) {
      const axis = gp.axes[0] ?? 0;
      if (Math.abs(axis) > 0.05) { state.steering_deg = -axis * STEER_MAX; this.engaged = true; }
      const trigger = (i: number) => gp.buttons[i]?.value ?? 0;
      if (trigger(7) > 0.02 || trigger(6) > 0.02) this.engaged = true;
      accelerator = Math.max(accelerator, 100 * trigger(7));
      brake = Math.max(brake, 100 * trigger(6));
      const edges: [number, Button][] = [[5, 'shift_up'], [4, 'shift_down'], [0, 'cruise_on'], [1, 'cruise_off']];
      for (const [i, button] of edges) {
        const down = gp.buttons[i]?.pressed ?? false;
        if (down && !this.padButtons[i]) this.press(button);
        this.padButtons[i] = down;
      }
    }
    state.accelerator = accelerator;
    state.brake = brake;
    // From the Drive view always (the dead man's release counts on it); elsewhere only
    // while something is held, so that a page in another view does not fight the person
    // driving from another page.
    // Once more after the last hold, so that the pedals' zero reaches the car.
    const holding = this.holding();
    if (this.active || holding || this.sentHolding) this.send();
    this.sentHolding = holding;
  }
}
