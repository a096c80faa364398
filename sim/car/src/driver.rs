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
        }
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
pub const MAX_STEERING_DEG: f64 = ecu_steering::STEERING_LIMIT_DEG as f64;
/// The cabin knob's range, °F: the set-temperature sensor's.
pub const MIN_SET_TEMP_F: f64 = ecu_cabin::SET_TEMP_MIN_F as f64;
/// The cabin knob's range, °F.
pub const MAX_SET_TEMP_F: f64 = ecu_cabin::SET_TEMP_MAX_F as f64;

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
