//! The scenario's driver: turns the timeline of `[[at]]` events into the controls at any
//! moment (pedals and steering ramp linearly, switches latch, buttons are held briefly).

use crate::scenario::{Button, Event, Scenario, BUTTON_PRESS_S};

/// The steering-wheel buttons held at a moment.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Buttons {
    /// Cruise on.
    pub cruise_on: bool,
    /// Cruise off.
    pub cruise_off: bool,
    /// Shift up.
    pub shift_up: bool,
    /// Shift down.
    pub shift_down: bool,
}

/// Everything the driver operates, at one moment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriverControls {
    /// Accelerator pedal, % (0..100).
    pub accelerator: f64,
    /// Brake pedal, % (0..100).
    pub brake: f64,
    /// Steering wheel angle, degrees, positive to the left.
    pub steering_deg: f64,
    /// Headlight switch.
    pub headlights: bool,
    /// Engine-mode switch (true: economy).
    pub economy_mode: bool,
    /// Transmission-mode switch (true: manual).
    pub manual_mode: bool,
    /// Cabin set-temperature knob, °F.
    pub set_temp_f: f64,
    /// Steering-wheel buttons held.
    pub buttons: Buttons,
}

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
                accelerator: d.accelerator.unwrap_or(0.0),
                brake: d.brake.unwrap_or(0.0),
                steering_deg: d.steering_deg.unwrap_or(0.0),
                headlights: d.headlights.unwrap_or(false),
                economy_mode: d.economy_mode.unwrap_or(false),
                manual_mode: d.manual_mode.unwrap_or(false),
                set_temp_f: d.set_temp_f.unwrap_or(72.0),
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
        let c = &mut self.controls;
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
        c.buttons = Buttons {
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
            self.controls.accelerator,
            self.controls.brake,
            self.controls.steering_deg,
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
        let c = &mut self.controls;
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
            let index = match button {
                Button::CruiseOn => 0,
                Button::CruiseOff => 1,
                Button::ShiftUp => 2,
                Button::ShiftDown => 3,
            };
            self.pressed_at[index] = Some(event.t_s);
        }
    }
}
