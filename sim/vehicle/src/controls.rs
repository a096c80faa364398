//! The driver's controls: what a person at the wheel operates. One definition serves the
//! scenario's timeline, the dashboard's Drive view (it arrives over the web as JSON) and
//! the virtual car, which reads them into the ECUs' sensors.

use serde::Deserialize;

/// What a person at the wheel holds at a moment (the buttons are pressed separately).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HeldControls {
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
}

/// A momentary button on the steering wheel.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Button {
    /// Cruise on / set.
    CruiseOn,
    /// Cruise off.
    CruiseOff,
    /// Shift up (manual mode, or out of neutral).
    ShiftUp,
    /// Shift down.
    ShiftDown,
}

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
    /// The pedals, the wheel, the switches and the knob.
    pub held: HeldControls,
    /// The steering-wheel buttons held.
    pub buttons: Buttons,
}
