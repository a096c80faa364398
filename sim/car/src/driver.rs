//! The scenario's driver: turns the timeline of `[[at]]` events into the controls at any
//! moment (pedals and steering ramp linearly, switches latch, buttons are held briefly).

use crate::scenario::{Button, Event, Scenario, BUTTON_PRESS_S};

pub use autoplug_vehicle::controls::{Buttons, DriverControls, HeldControls};

/// A control moving linearly from one value to another.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Ramp {
    from: f64,
    to: f64,
    start_s: f64,
    duration_s: f64,
}

impl Ramp {
    fn at(&self, t_s: f64) -> f64 {
        if self.duration_s <= 0.0 || t_s >= self.start_s + self.duration_s {
            self.to
        } else {
            let k = ((t_s - self.start_s) / self.duration_s).clamp(0.0, 1.0);
            self.from + (self.to - self.from) * k
        }
    }
}

/// Plays a scenario's timeline.
#[derive(Clone, Debug)]
pub struct Timeline {
    events: Vec<Event>,
    next: usize,
    controls: DriverControls,
    /// Accelerator, brake, steering.
    ramps: [Option<Ramp>; 3],
    /// Press start times per button, in `Button` order.
    pressed_at: [Option<f64>; 4],
    /// Whether the driver steers along the track.
    follow_road: bool,
    /// The speed the driver holds with the pedals, km/h, when holding one.
    speed_kmh: Option<f64>,
}

impl Timeline {
    /// The driver of a scenario, at t = 0 before any event.
    pub fn new(scenario: &Scenario) -> Self {
        let d = &scenario.driver;
        Self {
            events: scenario.at.clone(),
            next: 0,
            controls: DriverControls {
                held: HeldControls {
                    accelerator: d.accelerator.unwrap_or(0.0),
                    brake: d.brake.unwrap_or(0.0),
                    steering_deg: d.steering_deg.unwrap_or(0.0),
                    headlights: d.headlights.unwrap_or(false),
                    economy_mode: d.economy_mode.unwrap_or(false),
                    manual_mode: d.manual_mode.unwrap_or(false),
                    set_temp_f: d.set_temp_f.unwrap_or(72.0),
                },
                buttons: Buttons::default(),
            },
            ramps: [None; 3],
            pressed_at: [None; 4],
            follow_road: d.follow_road.unwrap_or(false),
            speed_kmh: d.speed_kmh,
        }
    }

    /// Whether the driver steers along the track now.
    pub fn follows_road(&self) -> bool {
        self.follow_road
    }

    /// The speed the driver holds with the pedals now, km/h; `None`: the pedals are the
    /// timeline's.
    pub fn speed_target_kmh(&self) -> Option<f64> {
        self.speed_kmh
    }

    /// The controls before any event.
    pub fn initial_controls(&self) -> &DriverControls {
        &self.controls
    }

    /// The controls at `t_s` (call with non-decreasing times). Each event whose time has
    /// come is applied once, and handed to `on_event` for what is not a driver control
    /// (road changes, faults).
    pub fn advance(&mut self, t_s: f64, mut on_event: impl FnMut(&Event)) -> DriverControls {
        while let Some(event) = self.events.get(self.next) {
            if event.t_s > t_s {
                break;
            }
            let event = event.clone();
            self.apply(&event);
            on_event(&event);
            self.next += 1;
        }
        let c = &mut self.controls.held;
        for (ramp, value) in
            self.ramps
                .iter()
                .zip([&mut c.accelerator, &mut c.brake, &mut c.steering_deg])
        {
            if let Some(r) = ramp {
                *value = r.at(t_s);
            }
        }
        let held = |start: Option<f64>| start.is_some_and(|s| t_s >= s && t_s < s + BUTTON_PRESS_S);
        self.controls.buttons = Buttons {
            cruise_on: held(self.pressed_at[0]),
            cruise_off: held(self.pressed_at[1]),
            shift_up: held(self.pressed_at[2]),
            shift_down: held(self.pressed_at[3]),
        };
        self.controls
    }

    fn apply(&mut self, event: &Event) {
        let targets = [event.accelerator, event.brake, event.steering_deg];
        let current = [
            self.controls.held.accelerator,
            self.controls.held.brake,
            self.controls.held.steering_deg,
        ];
        for ((ramp, target), from) in self.ramps.iter_mut().zip(targets).zip(current) {
            if let Some(to) = target {
                *ramp = Some(Ramp {
                    from,
                    to,
                    start_s: event.t_s,
                    duration_s: event.ramp_s,
                });
            }
        }
        let c = &mut self.controls.held;
        if let Some(v) = event.headlights {
            c.headlights = v;
        }
        if let Some(v) = event.economy_mode {
            c.economy_mode = v;
        }
        if let Some(v) = event.manual_mode {
            c.manual_mode = v;
        }
        if let Some(v) = event.set_temp_f {
            c.set_temp_f = v;
        }
        for button in &event.press {
            self.pressed_at[button_index(*button)] = Some(event.t_s);
        }
        if let Some(follow) = event.follow_road {
            self.follow_road = follow;
        }
        if event.speed_kmh.is_some() {
            self.speed_kmh = event.speed_kmh;
        } else if event.accelerator.is_some() || event.brake.is_some() {
            self.speed_kmh = None;
        }
    }
}

/// Lateral acceleration the driver allows in a bend, m/s²: brisk road driving (a racing
/// driver on this car's tyres goes to about 9).
pub const BEND_LATERAL_MPS2: f64 = 4.0;

/// Deceleration the driver plans with before a bend, m/s².
pub const PLANNED_DECELERATION_MPS2: f64 = 4.0;

/// Accelerator per m/s of speed below the target, %.
const ACCELERATOR_GAIN: f64 = 25.0;
/// Accelerator per m of speed deficit integrated over time (m/s · s), %.
const ACCELERATOR_INTEGRAL_GAIN: f64 = 4.0;
/// Brake per m/s above the target (beyond [`BRAKE_DEADBAND_MPS`]), %.
const BRAKE_GAIN: f64 = 12.0;
/// Speed above the target the driver tolerates before braking, m/s (lifting off slows
/// the car by itself).
const BRAKE_DEADBAND_MPS: f64 = 0.8;

/// What the road driver knows of the car.
#[derive(Clone, Copy, Debug)]
pub struct CarOnRoad {
    /// The middle of the rear axle, and the heading.
    pub rear_axle: autoplug_road::Pose,
    /// The rear axle's station on the road, m.
    pub station_m: f64,
    /// Speed, m/s.
    pub speed_mps: f64,
    /// Wheelbase, m.
    pub wheelbase_m: f64,
    /// Steering-wheel degrees per road-wheel degree.
    pub steering_ratio: f64,
    /// The car's understeer gradient, rad of road-wheel angle per m/s² of lateral
    /// acceleration.
    pub understeer_rad_per_mps2: f64,
}

/// The scenario's driver when it steers along the track or holds a speed: a path
/// follower and a speed keeper, the driver models of vehicle-dynamics tools (CarSim's and
/// IPG CarMaker's have the same two halves).
///
/// - Steering: pure pursuit ([`autoplug_road::follow`]) aimed at the scenario's lane,
///   looking [`autoplug_road::follow::lookahead_m`] ahead, with the car's understeer at
///   its speed added for the bend ahead.
/// - Speed: the lower of the target and what the road ahead allows: in a bend of curvature
///   κ the speed √([`BEND_LATERAL_MPS2`]/κ), and before it no faster than braking at
///   [`PLANNED_DECELERATION_MPS2`] reaches that speed at the bend. A PI controller turns
///   the shortfall into accelerator, a proportional one the excess into brake.
#[derive(Clone, Debug, Default)]
pub struct RoadDriver {
    integral: f64,
    /// The speed the road ahead allowed at the last look, m/s, and when the next look is
    /// due, µs.
    looked: Option<(f64, u64)>,
}

/// How often the road driver looks down the road for bends, µs: a driver's glance, not
/// every 1 ms tick (each look queries the curvature every 2 m of braking distance: at
/// 100 km/h some 50 queries, a fifth of a lap's run time when done every tick).
const LOOK_AHEAD_PERIOD_US: u64 = 10_000;

impl RoadDriver {
    /// The steering-wheel angle, degrees (positive left), that keeps `car` (its rear
    /// axle at `car.rear_axle`, `car.station_m` along `road`) on the line `lane_m` left of
    /// the centreline: pure pursuit, plus the understeer the car needs at its speed in the
    /// bend ahead (`K_us·v²·κ`: pure pursuit alone is kinematic, and a car at speed runs
    /// wide of it by that much).
    pub fn steering_deg(road: &autoplug_road::Road, car: &CarOnRoad, lane_m: f64) -> f64 {
        let lookahead = autoplug_road::follow::lookahead_m(car.speed_mps);
        let kinematic = autoplug_road::follow::pure_pursuit(
            road,
            car.rear_axle,
            car.station_m,
            car.wheelbase_m,
            lookahead,
            lane_m,
        );
        let curvature = road.curvature_at(road.wrap(car.station_m + 0.5 * lookahead));
        let understeer = car.understeer_rad_per_mps2 * car.speed_mps * car.speed_mps * curvature;
        ((kinematic + understeer).to_degrees() * car.steering_ratio)
            .clamp(-MAX_STEERING_DEG, MAX_STEERING_DEG)
    }

    /// The speed the road allows from `station_m` on for a car at `speed_mps`, m/s: the
    /// bends within braking distance, each approached at [`PLANNED_DECELERATION_MPS2`].
    pub fn speed_allowed(road: &autoplug_road::Road, station_m: f64, speed_mps: f64) -> f64 {
        const STEP_M: f64 = 2.0;
        let reach = speed_mps * speed_mps / (2.0 * PLANNED_DECELERATION_MPS2) + 20.0;
        let mut allowed = f64::INFINITY;
        let mut ahead = 0.0;
        while ahead <= reach {
            let s = station_m + ahead;
            if !road.is_closed() && s > road.length_m() {
                break;
            }
            let curvature = road.curvature_at(road.wrap(s)).abs().max(1e-9);
            let in_bend = (BEND_LATERAL_MPS2 / curvature).sqrt();
            let from_here = (in_bend * in_bend + 2.0 * PLANNED_DECELERATION_MPS2 * ahead).sqrt();
            allowed = allowed.min(from_here);
            ahead += STEP_M;
        }
        allowed
    }

    /// [`RoadDriver::speed_allowed`], looked up again every [`LOOK_AHEAD_PERIOD_US`] of
    /// simulated time `t_us` and held between.
    pub fn speed_allowed_at(
        &mut self,
        road: &autoplug_road::Road,
        station_m: f64,
        speed_mps: f64,
        t_us: u64,
    ) -> f64 {
        match self.looked {
            Some((allowed, due_us)) if t_us < due_us => allowed,
            _ => {
                let allowed = Self::speed_allowed(road, station_m, speed_mps);
                self.looked = Some((allowed, t_us + LOOK_AHEAD_PERIOD_US));
                allowed
            }
        }
    }

    /// Accelerator and brake pedal, %, that bring `speed_mps` to `target_mps`, over a
    /// step of `dt_s`.
    pub fn pedals(&mut self, speed_mps: f64, target_mps: f64, dt_s: f64) -> (f64, f64) {
        let shortfall = target_mps - speed_mps;
        let accelerator = ACCELERATOR_GAIN * shortfall + ACCELERATOR_INTEGRAL_GAIN * self.integral;
        // Integrate only while the pedal is not pinned (no wind-up) and the car is not
        // being braked.
        if (0.0..100.0).contains(&accelerator) || (accelerator >= 100.0) != (shortfall > 0.0) {
            self.integral = (self.integral + shortfall * dt_s).max(0.0);
        }
        let brake = BRAKE_GAIN * (-shortfall - BRAKE_DEADBAND_MPS);
        if brake > 0.0 {
            self.integral = 0.0;
            (0.0, brake.min(100.0))
        } else {
            (accelerator.clamp(0.0, 100.0), 0.0)
        }
    }
}

/// `held`, each value clamped into its control's range; `None` if one is not a number.
pub fn clamped(held: HeldControls) -> Option<HeldControls> {
    let ok = [
        held.accelerator,
        held.brake,
        held.steering_deg,
        held.set_temp_f,
    ]
    .iter()
    .all(|v| v.is_finite());
    ok.then(|| HeldControls {
        accelerator: held.accelerator.clamp(0.0, 100.0),
        brake: held.brake.clamp(0.0, 100.0),
        steering_deg: held.steering_deg.clamp(-MAX_STEERING_DEG, MAX_STEERING_DEG),
        set_temp_f: held.set_temp_f.clamp(MIN_SET_TEMP_F, MAX_SET_TEMP_F),
        ..held
    })
}

/// The steering wheel's travel either way, degrees: the steering sensor's range.
pub const MAX_STEERING_DEG: f64 = autoplug_ecus::steering::STEERING_LIMIT_DEG as f64;
/// The cabin knob's range, °F: the set-temperature sensor's.
pub const MIN_SET_TEMP_F: f64 = autoplug_ecus::cabin::SET_TEMP_MIN_F as f64;
/// The cabin knob's range, °F.
pub const MAX_SET_TEMP_F: f64 = autoplug_ecus::cabin::SET_TEMP_MAX_F as f64;

/// A person driving instead of the scenario's timeline (the dashboard's Drive view): the
/// controls they hold, and each steering-wheel button held for [`BUTTON_PRESS_S`] from
/// the moment they pressed it, as the timeline holds a scenario's presses.
#[derive(Clone, Debug, PartialEq)]
pub struct ManualDriver {
    held: HeldControls,
    /// Press times per button, in `Button` order; `None` until pressed.
    pressed_at: [Option<f64>; 4],
    /// Presses waiting for the next tick's time.
    pending: [bool; 4],
}

impl ManualDriver {
    /// Takes over from `controls` as they are.
    pub fn taking_over(controls: &DriverControls) -> Self {
        Self {
            held: controls.held,
            pressed_at: [None; 4],
            pending: [false; 4],
        }
    }

    /// What the person holds now.
    pub fn held(&self) -> &HeldControls {
        &self.held
    }

    /// The person moves the controls (values clamped to each control's range; a value
    /// that is not a number leaves the controls as they were and is refused).
    pub fn hold(&mut self, held: HeldControls) -> Result<(), &'static str> {
        self.held = clamped(held).ok_or("a driver control is not a number")?;
        Ok(())
    }

    /// The person presses a steering-wheel button (held from the next tick).
    pub fn press(&mut self, button: Button) {
        self.pending[button_index(button)] = true;
    }

    /// The controls at `t_s`.
    pub fn controls_at(&mut self, t_s: f64) -> DriverControls {
        for (pending, at) in self.pending.iter_mut().zip(&mut self.pressed_at) {
            if std::mem::take(pending) {
                *at = Some(t_s);
            }
        }
        let held = |start: Option<f64>| start.is_some_and(|s| t_s >= s && t_s < s + BUTTON_PRESS_S);
        DriverControls {
            held: self.held,
            buttons: Buttons {
                cruise_on: held(self.pressed_at[0]),
                cruise_off: held(self.pressed_at[1]),
                shift_up: held(self.pressed_at[2]),
                shift_down: held(self.pressed_at[3]),
            },
        }
    }
}

fn button_index(button: Button) -> usize {
    match button {
        Button::CruiseOn => 0,
        Button::CruiseOff => 1,
        Button::ShiftUp => 2,
        Button::ShiftDown => 3,
    }
}
