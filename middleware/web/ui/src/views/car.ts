// Car: everything of the car at a glance, as the ECUs put it on the bus.
import { Gauge } from '../gauge';
import type { Ctx, View } from '../view';
import { fToC, h, num, setText } from '../util';

const P = {
  speed: 'Vehicle.Speed',
  rpm: 'Vehicle.Powertrain.CombustionEngine.Speed',
  fuel: 'Vehicle.Powertrain.FuelSystem.AbsoluteLevel',
  gear: 'Vehicle.Powertrain.Transmission.CurrentGear',
  shiftMode: 'Vehicle.Powertrain.Transmission.GearChangeMode',
  engineMode: 'Vehicle.Powertrain.Transmission.PerformanceMode',
  headlights: 'Vehicle.Body.Lights.Beam.Low.IsOn',
  brakeLights: 'Vehicle.Body.Lights.Brake.IsActive',
  cruise: 'Vehicle.ADAS.CruiseControl.IsActive',
  cruiseCmd: 'Vehicle.Private.AutoPlug.CruiseControl.Command',
  accel: 'Vehicle.Chassis.Accelerator.PedalPosition',
  brake: 'Vehicle.Chassis.Brake.PedalPosition',
  steering: 'Vehicle.Chassis.SteeringWheel.Angle',
  yaw: 'Vehicle.Private.AutoPlug.ActiveDifferential.YawRateError',
  split: 'Vehicle.Private.AutoPlug.ActiveDifferential.TorqueSplit',
  cabin: 'Vehicle.Cabin.HVAC.AmbientAirTemperature',
  setTemp: 'Vehicle.Cabin.HVAC.Station.Row1.Driver.Temperature',
  fan: 'Vehicle.Cabin.HVAC.Station.Row1.Driver.FanSpeed',
  traction: 'Vehicle.Private.AutoPlug.TractionControl.Cut',
};

const WHEELS = [
  ['FL', 'Row1.Wheel.Left', 'Row1.Left'],
  ['FR', 'Row1.Wheel.Right', 'Row1.Right'],
  ['RL', 'Row2.Wheel.Left', 'Row2.Left'],
  ['RR', 'Row2.Wheel.Right', 'Row2.Right'],
] as const;

const GEAR_SHORT: Record<string, string> = {
  Reverse: 'R', Neutral: 'N', First: '1', Second: '2', Third: '3', Fourth: '4', Fifth: '5', Sixth: '6',
};

/** The EVO VI's tank, L. */
const TANK_L = 55;

function bar(label: string, testid: string): { el: HTMLElement; set(v: number | null, text: string): void } {
  const fill = h('div', { class: 'bar-fill' });
  const value = h('span', { class: 'bar-value' });
  const el = h('div', { class: 'bar', 'data-testid': testid }, h('span', { class: 'bar-label', text: label }), h('div', { class: 'bar-track' }, fill), value);
  return {
    el,
    set(v, text) {
      fill.style.width = `${Math.max(0, Math.min(100, v ?? 0))}%`;
      setText(value, text);
      el.dataset.value = v === null ? '' : String(v);
    },
  };
}

export function carView(ctx: Ctx): View {
  const { live } = ctx;
  const speed = new Gauge('Speed', 'km/h', 260, 20, null, 0, 2);
  speed.el.dataset.testid = 'speed';
  const rpm = new Gauge('Engine', 'rpm', 8000, 1000, 7000);
  rpm.el.dataset.testid = 'rpm';

  const gear = h('div', { class: 'gear', 'data-testid': 'gear', text: '–' });
  const shiftMode = h('div', { class: 'muted small' });
  const engineMode = h('div', { class: 'muted small' });
  const headlights = h('span', { class: 'lamp', title: 'headlights', 'data-testid': 'headlights', text: 'Headlights' });
  const brakeLights = h('span', { class: 'lamp brake', title: 'brake lights', 'data-testid': 'brake-lights', text: 'Brake' });
  const cruise = h('span', { class: 'lamp cruise', 'data-testid': 'cruise', text: 'Cruise' });
  const cruiseSet = h('span', { class: 'muted small', 'data-testid': 'cruise-set' });
  const fuel = bar('Fuel', 'fuel');
  const accel = bar('Accelerator', 'accelerator');
  const brake = bar('Brake', 'brake');
  const cruiseCmd = bar('Cruise cmd', 'cruise-command');
  const traction = bar('Traction cut', 'traction');
  const wheel = h('div', { class: 'wheel-icon', 'aria-hidden': 'true' }, h('div', { class: 'wheel-spoke' }));
  const steering = h('div', { class: 'figure', 'data-testid': 'steering' });
  const yaw = h('div', { class: 'figure' });
  const split = h('div', { class: 'figure' });
  const cabin = h('div', { class: 'figure', 'data-testid': 'cabin-temp' });
  const setTemp = h('div', { class: 'figure' });
  const fan = bar('Fan', 'fan');

  const wheelCells = WHEELS.map(([name]) => {
    const v = h('div', { class: 'wheel-speed' });
    const abs = h('div', { class: 'abs-badge', text: 'ABS' });
    const applied = h('div', { class: 'muted small' });
    const cell = h('div', { class: `tyre tyre-${name}`, 'data-testid': `wheel-${name}` }, h('div', { class: 'muted small', text: name }), v, applied, abs);
    return { cell, v, abs, applied };
  });

  let setSpeed: number | null = null;
  let wasOn = false;

  const el = h(
    'section',
    { class: 'car' },
    h('div', { class: 'card gauges' }, speed.el, h('div', { class: 'gear-box' }, gear, shiftMode, engineMode), rpm.el),
    h('div', { class: 'card lamps' }, headlights, brakeLights, cruise, cruiseSet),
    h('div', { class: 'card' }, h('h3', { text: 'Pedals and fuel' }), accel.el, brake.el, cruiseCmd.el, fuel.el),
    h('div', { class: 'card' }, h('h3', { text: 'Steering and chassis' }),
      h('div', { class: 'row' }, wheel, h('div', {}, h('div', { class: 'muted small', text: 'Steering wheel' }), steering)),
      h('div', { class: 'row' }, h('div', {}, h('div', { class: 'muted small', text: 'Yaw-rate error' }), yaw), h('div', {}, h('div', { class: 'muted small', text: 'Torque split' }), split)),
      traction.el),
    h('div', { class: 'card' }, h('h3', { text: 'Wheels and ABS' }), h('div', { class: 'tyres' }, ...wheelCells.map((w) => w.cell))),
    h('div', { class: 'card' }, h('h3', { text: 'Cabin' }),
      h('div', { class: 'row' }, h('div', {}, h('div', { class: 'muted small', text: 'Cabin' }), cabin), h('div', {}, h('div', { class: 'muted small', text: 'Set point' }), setTemp)),
      fan.el),
  );

  function update(): void {
    const v = (p: string) => live.value(p);
    speed.set(v(P.speed));
    rpm.set(v(P.rpm));
    const g = live.label(P.gear);
    setText(gear, g ? GEAR_SHORT[g] ?? g : '–');
    setText(shiftMode, live.label(P.shiftMode) ?? '');
    setText(engineMode, live.label(P.engineMode) ? `${live.label(P.engineMode)} mode` : '');
    headlights.classList.toggle('on', v(P.headlights) === 1);
    brakeLights.classList.toggle('on', v(P.brakeLights) === 1);
    brakeLights.dataset.on = String(v(P.brakeLights) === 1);
    const on = v(P.cruise) === 1;
    cruise.classList.toggle('on', on);
    cruise.dataset.on = String(on);
    if (on && !wasOn) setSpeed = v(P.speed);
    if (!on) setSpeed = null;
    wasOn = on;
    setText(cruiseSet, on && setSpeed !== null ? `set ≈ ${num(setSpeed)} km/h` : 'cruise off');
    const fuelL = v(P.fuel);
    fuel.set(fuelL === null ? null : (100 * fuelL) / TANK_L, `${num(fuelL, 1)} L`);
    accel.set(v(P.accel), `${num(v(P.accel))} %`);
    brake.set(v(P.brake), `${num(v(P.brake))} %`);
    cruiseCmd.set(v(P.cruiseCmd), `${num(v(P.cruiseCmd))} %`);
    traction.set(v(P.traction), `${num(v(P.traction))} %`);
    const angle = v(P.steering);
    wheel.style.transform = `rotate(${-(angle ?? 0)}deg)`;
    setText(steering, `${num(angle)}°`);
    setText(yaw, `${num(v(P.yaw), 3)} rad/s`);
    setText(split, `${num(v(P.split))} N·m`);
    for (let i = 0; i < 4; i++) {
      const [, wheelPath, brakePath] = WHEELS[i];
      const w = wheelCells[i];
      setText(w.v, `${num(v(`Vehicle.Chassis.Axle.${wheelPath}.Speed`))} km/h`);
      const release = v(`Vehicle.Private.AutoPlug.Brakes.${brakePath}.AbsRelease`) ?? 0;
      setText(w.applied, `brake ${num(v(`Vehicle.Private.AutoPlug.Brakes.${brakePath}.Applied`))} %`);
      w.abs.classList.toggle('on', release > 0);
      w.cell.dataset.abs = String(release > 0);
    }
    const c = v(P.cabin);
    setText(cabin, `${num(c)} °F · ${num(fToC(c))} °C`);
    const s = v(P.setTemp);
    setText(setTemp, `${num(s)} °F · ${num(fToC(s))} °C`);
    fan.set(v(P.fan), `${num(v(P.fan))} %`);
  }
  return { el, update };
}
