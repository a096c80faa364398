//! Steering ECU (node 0x05), spec section 2 and the report's pseudocode 5.2.1.8.
//!
//! Reads the steering wheel angle and drives the steering actuator with it, clamped to the
//! catalogue's ±135° (SteeringMsg). Parses the buttons on the wheel:
//!
//! - **Debouncing**: every button is debounced both ways: a change of a button's state is
//!   taken once the new level has been seen on [`DEBOUNCE_STEPS`] consecutive steps. Only
//!   press edges (released → pressed) act; holding a button does nothing more.
//! - **Shift paddles → ShiftMsg**: normally None. A shift-up (down) press edge makes it Up
//!   (Down) for [`SHIFT_PULSE_MS`], then None again: the transmission acts on the
//!   None → Up/Down edge, and the pulse lasts several of ShiftMsg's 20 ms frames so that a
//!   lost frame does not lose the shift. A press edge while a pulse is running (its last
//!   step included) is ignored: one shift per pulse, two requests always separated by
//!   None, and the transmission's shift timeout would refuse it anyway. Both paddles held
//!   at once mean None, ending any pulse.
//! - **Cruise buttons → CruiseModeMsg**: the steering ECU owns the cruise state. A
//!   cruise-on press edge turns it On, a cruise-off press edge Off (both in the same step:
//!   Off). The state is sent every 20 ms and at once on a change.
//! - **Cruise cancel from the pedals**: the pedals ECU cancels cruise on a pedal press by
//!   sending CruiseModeMsg Off (it never sends On). When the steering ECU receives a valid
//!   Off while its state is On, its state becomes Off at once, so that its next frame
//!   confirms the cancel instead of undoing it. A received On is ignored: only the driver's
//!   button turns cruise on.
//!
//! Inputs and safe states: the only CAN input is CruiseModeMsg, and it is deliberately
//! **not** supervised for staleness. The steering ECU does not receive its own frames (no
//! loopback), so the only CruiseModeMsg it hears are the pedals' cancels, sent only while
//! cancelling: the input is normally silent, silence is not a fault, and there is neither
//! a safe state nor a "lost communication" DTC for it. A CruiseModeMsg with an invalid
//! value records "invalid data received from the pedals ECU" (charged to the pedals, the
//! only other sender, rather than to the message's first sender, which is this ECU) and
//! changes nothing.
#![no_std]
#![deny(missing_docs)]

pub mod pins;

use autoplug_can::{CruiseMode, CruiseModeMsg, Frame, Node, ShiftMsg, ShiftRequest, SteeringMsg};
use autoplug_ecu::{invalid_data, receive_from, Dtc, Dtcs, EcuLogic, Input, Instant, PeriodicTx};

// The published parameters (calibration, thresholds, trouble codes) live with the
// other ECUs' in `autoplug-ecu-params`, where the gateway's diagnostics read them.
pub use autoplug_ecu_params::steering::*;

/// The steering range, degrees either side of straight ahead: the catalogue's SteeringMsg
/// range (raw 10..90), and what the steering actuator accepts.
pub const STEERING_LIMIT_DEG: f32 = 135.0;

/// A button's new level must be seen on this many consecutive steps before it counts:
/// 20 ms at the 10 ms step, longer than contact bounce, far shorter than a deliberate press.
pub const DEBOUNCE_STEPS: u8 = 2;

/// The part number of this ECU's software (UDS 0xF187), as the virtual car's ECUs answer
/// it.
pub const PART_NUMBER: &str = "AP-STEER-0001";

/// Control period: the rate SteeringMsg is published at.
pub const STEP_PERIOD_US: u64 = 10_000;

/// "Invalid data received from the pedals ECU": a cancel frame with an invalid value.
pub const INVALID_CANCEL_DTC: Dtc = invalid_data(Node::Pedals);

/// Readings from the steering wheel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Sensors {
    /// Steering wheel angle, degrees, positive = left (ISO 8855); clamped to ±135°.
    pub wheel_angle_deg: f32,
    /// Shift-up paddle held (momentary).
    pub shift_up_button: bool,
    /// Shift-down paddle held (momentary).
    pub shift_down_button: bool,
    /// Cruise-on button held (momentary).
    pub cruise_on_button: bool,
    /// Cruise-off button held (momentary).
    pub cruise_off_button: bool,
}

/// Commands to the vehicle.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Actuators {
    /// Steering command: the wheel angle passed to the steering actuator, degrees,
    /// positive = left, within ±135°.
    pub steering_cmd_deg: f32,
}

/// A debounced momentary button.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
struct Button {
    pressed: bool,
    /// Consecutive steps the raw level has differed from `pressed`.
    differing: u8,
}

impl Button {
    /// Takes this step's raw level; returns true on a debounced press edge.
    fn update(&mut self, raw: bool) -> bool {
        if raw == self.pressed {
            self.differing = 0;
            return false;
        }
        self.differing = self.differing.saturating_add(1);
        if self.differing < DEBOUNCE_STEPS {
            return false;
        }
        self.pressed = raw;
        self.differing = 0;
        raw
    }
}

/// The steering ECU's logic.
#[derive(Clone, Debug)]
pub struct SteeringEcu {
    cancel: Input<CruiseModeMsg>,
    shift_up: Button,
    shift_down: Button,
    cruise_on: Button,
    cruise_off: Button,
    cruise: CruiseMode,
    /// The shift request being pulsed and when its pulse ends.
    pulse: Option<(ShiftRequest, Instant)>,
    shift: ShiftRequest,
    tx_steering: PeriodicTx,
    tx_shift: PeriodicTx,
    tx_cruise: PeriodicTx,
    dtcs: Dtcs,
}

impl SteeringEcu {
    /// The ECU at power-up (`now`): cruise off, no shift request.
    pub fn new(now: Instant) -> Self {
        Self {
            cancel: Input::new(now),
            shift_up: Button::default(),
            shift_down: Button::default(),
            cruise_on: Button::default(),
            cruise_off: Button::default(),
            cruise: CruiseMode::Off,
            pulse: None,
            shift: ShiftRequest::None,
            tx_steering: PeriodicTx::of::<SteeringMsg>(),
            tx_shift: PeriodicTx::of::<ShiftMsg>(),
            tx_cruise: PeriodicTx::of::<CruiseModeMsg>(),
            dtcs: Dtcs::new(),
        }
    }

    /// The cruise state this ECU sends.
    pub fn cruise_mode(&self) -> CruiseMode {
        self.cruise
    }

    /// The shift request this ECU sends.
    pub fn shift_request(&self) -> ShiftRequest {
        self.shift
    }

    fn set_cruise(&mut self, mode: CruiseMode) {
        if mode != self.cruise {
            autoplug_log::info!("steering: cruise {:?}", mode);
        }
        self.cruise = mode;
        self.tx_cruise
            .set_message(&CruiseModeMsg { cruise_mode: mode });
    }
}

impl EcuLogic for SteeringEcu {
    type Sensors = Sensors;
    type Actuators = Actuators;

    const NODE: Node = Node::Steering;
    const STEP_PERIOD_US: u64 = STEP_PERIOD_US;

    fn on_frame(&mut self, now: Instant, frame: &Frame) {
        // Charged to the pedals: CruiseModeMsg's first sender is this ECU, but the only
        // CruiseModeMsg frames it hears are the pedals' cancels (no loopback).
        if !receive_from(Node::Pedals, &mut self.cancel, &mut self.dtcs, now, frame)
            || !self.cancel.latest_frame_valid()
        {
            return;
        }
        if self.cancel.value().cruise_mode == CruiseMode::Off && self.cruise == CruiseMode::On {
            autoplug_log::info!("steering: cruise cancelled by the pedals");
            // At once, so that no transmit poll before the next step undoes it.
            self.set_cruise(CruiseMode::Off);
        }
    }

    fn step(&mut self, now: Instant, sensors: &Sensors) -> Actuators {
        // CruiseModeMsg is not supervised: see the crate docs.
        let angle = sensors.wheel_angle_deg;
        let steering_cmd_deg = if angle.is_nan() {
            0.0
        } else {
            angle.clamp(-STEERING_LIMIT_DEG, STEERING_LIMIT_DEG)
        };

        // Cruise buttons: off wins over on.
        let on_edge = self.cruise_on.update(sensors.cruise_on_button);
        let off_edge = self.cruise_off.update(sensors.cruise_off_button);
        let cruise = if off_edge {
            CruiseMode::Off
        } else if on_edge {
            CruiseMode::On
        } else {
            self.cruise
        };
        self.set_cruise(cruise);

        // Shift paddles: a pulse per press edge, None while both are held.
        let up_edge = self.shift_up.update(sensors.shift_up_button);
        let down_edge = self.shift_down.update(sensors.shift_down_button);
        // An edge during a pulse, its last step included, is ignored: two pulses always
        // have at least one step of None between them.
        let pulse_was_running = self.pulse.is_some();
        if self.pulse.is_some_and(|(_, end)| now >= end) {
            self.pulse = None;
        }
        if self.shift_up.pressed && self.shift_down.pressed {
            self.pulse = None;
        } else if !pulse_was_running {
            let end = now.plus_micros(SHIFT_PULSE_MS * 1000);
            if up_edge {
                self.pulse = Some((ShiftRequest::Up, end));
            } else if down_edge {
                self.pulse = Some((ShiftRequest::Down, end));
            }
        }
        let shift = self
            .pulse
            .map_or(ShiftRequest::None, |(request, _)| request);
        if shift != self.shift {
            autoplug_log::info!("steering: shift request {:?}", shift);
        }
        self.shift = shift;

        self.tx_steering.set_message(&SteeringMsg {
            steering_angle: steering_cmd_deg,
        });
        self.tx_shift.set_message(&ShiftMsg {
            shift_request: shift,
        });
        Actuators { steering_cmd_deg }
    }

    fn poll_transmit(&mut self, now: Instant) -> Option<Frame> {
        // Identifier order: SteeringMsg 0x005, CruiseModeMsg 0x008, ShiftMsg 0x00A.
        self.tx_steering
            .poll(now)
            .or_else(|| self.tx_cruise.poll(now))
            .or_else(|| self.tx_shift.poll(now))
    }

    fn dtcs(&self) -> &Dtcs {
        &self.dtcs
    }

    fn dtcs_mut(&mut self) -> &mut Dtcs {
        &mut self.dtcs
    }
}

/// Test cases shared by the host and on-target suites.
#[cfg(any(test, feature = "test-cases"))]
pub mod test_cases;

#[cfg(test)]
mod tests;
