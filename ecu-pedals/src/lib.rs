//! Pedals ECU (node 0x04), spec section 2 and the report's pseudocode 5.2.1.7.
//!
//! Reads the accelerator and brake pedals (pedal units, 0..100) and drives the accelerator
//! and brake commands, published as PedalAccel and PedalBrake:
//!
//! - **Cruise off**: the commands are the driver's pedals.
//! - **Cruise on** (the last CruiseModeMsg said On): the accelerator command is the cruise
//!   command (CruiseAccelMsg, −100..100) when positive, the brake command its negation
//!   when negative; pedals below [`PEDAL_PRESSED_THRESHOLD`] are ignored.
//! - **Cancel**: a pedal pressed past [`PEDAL_PRESSED_THRESHOLD`] while cruise is on
//!   cancels cruise. The pedals ECU sends CruiseModeMsg Off in the same step and repeats
//!   it, never sooner than the message's minimum gap (5 ms) after the previous one and
//!   otherwise at every transmit poll, until the bus shows CruiseModeMsg Off (sending stops
//!   as soon as that frame is received, not at the next step): the steering
//!   ECU, which owns the cruise state and sends it every 20 ms, adopts the Off it hears and
//!   sends Off from then on, which is what makes the cancel stick. From the press on, the
//!   outputs are the driver's pedals. The pedals ECU never sends CruiseModeMsg otherwise.
//! - **Brake override**: a brake pedal pressed past [`PEDAL_PRESSED_THRESHOLD`] forces
//!   the accelerator command to 0, whatever the accelerator pedal or cruise says (the
//!   brake-throttle override of modern cars: the brakes never fight the engine).
//! - **Traction control**: TracMsg's cut (0..100 %) scales the accelerator command by
//!   `1 − cut/100`, in every mode. The brake command is never cut.
//!
//! Safe states per stale input (3 periods without a valid frame; each records "lost
//! communication" with the sender):
//!
//! | input | stale after | safe state | DTC |
//! |---|---|---|---|
//! | CruiseModeMsg | 60 ms | cruise treated as off: the driver's pedals pass through, no cancel is sent (none is needed) | lost communication with the steering ECU |
//! | CruiseAccelMsg | 60 ms | cruise command unknown: the outputs are the driver's pedals, as if cruise were off (a cancel is still sent on a pedal press while the bus says On) | lost communication with the cruise ECU |
//! | TracMsg | 30 ms | no traction cut | lost communication with the ABS ECU |
//!
//! A CruiseModeMsg going stale also ends a cancel in progress: the steering ECU is silent,
//! and the cruise ECU disengages on its own stale input.
#![no_std]
#![deny(missing_docs)]

pub mod pins;

use autoplug_can::{
    CanMessage, CruiseAccelMsg, CruiseMode, CruiseModeMsg, Frame, Node, PedalAccel, PedalBrake,
    TracMsg,
};
use autoplug_ecu::{receive, supervise, Dtcs, EcuLogic, Input, Instant, PeriodicTx};
use autoplug_scaling::clamp_finite;

// The published parameters (calibration, thresholds, trouble codes) live with the
// other ECUs' in `autoplug-ecu-params`, where the gateway's diagnostics read them.
pub use autoplug_ecu_params::pedals::*;

/// Full pedal travel and full command, pedal units (the catalogue's 0..100).
pub const PEDAL_FULL: f32 = 100.0;

/// Full cruise command either way, % (CruiseAccelMsg's −100..100).
pub const CRUISE_COMMAND_FULL: f32 = 100.0;

/// Full traction cut, % (TracMsg's 0..100).
pub const TRACTION_CUT_FULL: f32 = 100.0;

/// The part number of this ECU's software (UDS 0xF187), as the virtual car's ECUs answer
/// it.
pub const PART_NUMBER: &str = "AP-PEDALS-0001";

/// Control period: the rate PedalAccel and PedalBrake are published at.
pub const STEP_PERIOD_US: u64 = 10_000;

/// Pedal readings.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Sensors {
    /// Accelerator pedal, pedal units 0..100 (100 = floored).
    pub accelerator_pedal: f32,
    /// Brake pedal, pedal units 0..100 (100 = full braking).
    pub brake_pedal: f32,
}

/// Commands to the vehicle.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Actuators {
    /// Accelerator command, pedal units 0..100.
    pub accelerator_cmd: f32,
    /// Brake command, pedal units 0..100.
    pub brake_cmd: f32,
}

/// The cruise cancel: CruiseModeMsg Off, sent while a cancel is in progress, at once and
/// then never sooner than the message's minimum gap after the previous one.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
struct CancelTx {
    active: bool,
    min_gap_us: u64,
    last_sent: Option<Instant>,
}

impl CancelTx {
    const fn new() -> Self {
        Self {
            active: false,
            min_gap_us: CruiseModeMsg::MIN_GAP_MS as u64 * 1000,
            last_sent: None,
        }
    }

    fn poll(&mut self, now: Instant) -> Option<Frame> {
        if !self.active {
            return None;
        }
        let due = self
            .last_sent
            .is_none_or(|at| now.micros_since(at) >= self.min_gap_us);
        if !due {
            return None;
        }
        self.last_sent = Some(now);
        Some(
            CruiseModeMsg {
                cruise_mode: CruiseMode::Off,
            }
            .frame(),
        )
    }
}

/// The pedals ECU's logic.
#[derive(Clone, Debug)]
pub struct PedalsEcu {
    cruise_mode: Input<CruiseModeMsg>,
    cruise_accel: Input<CruiseAccelMsg>,
    traction: Input<TracMsg>,
    cancel: CancelTx,
    cruise_driving: bool,
    tx_brake: PeriodicTx,
    tx_accel: PeriodicTx,
    dtcs: Dtcs,
}

impl PedalsEcu {
    /// The ECU at power-up (`now`).
    pub fn new(now: Instant) -> Self {
        Self {
            cruise_mode: Input::new(now),
            cruise_accel: Input::new(now),
            traction: Input::new(now),
            cancel: CancelTx::new(),
            cruise_driving: false,
            tx_brake: PeriodicTx::of::<PedalBrake>(),
            tx_accel: PeriodicTx::of::<PedalAccel>(),
            dtcs: Dtcs::new(),
        }
    }

    /// Whether a cruise cancel is being sent (a pedal was pressed while cruise was on and
    /// the bus has not shown CruiseModeMsg Off yet).
    pub fn cancelling(&self) -> bool {
        self.cancel.active
    }

    /// Whether the last step's commands came from the cruise command.
    pub fn cruise_driving(&self) -> bool {
        self.cruise_driving
    }
}

impl EcuLogic for PedalsEcu {
    type Sensors = Sensors;
    type Actuators = Actuators;

    const NODE: Node = Node::Pedals;
    const STEP_PERIOD_US: u64 = STEP_PERIOD_US;

    fn on_frame(&mut self, now: Instant, frame: &Frame) {
        if receive(&mut self.cruise_mode, &mut self.dtcs, now, frame) {
            // The bus shows Off: the cancel has stuck, stop sending it at once rather than
            // at the next step. (A cancel only starts while the last value is On, so Off
            // here means an Off frame arrived.)
            if self.cancel.active && self.cruise_mode.value().cruise_mode == CruiseMode::Off {
                autoplug_log::info!("pedals: cruise cancel confirmed");
                self.cancel.active = false;
            }
            return;
        }
        let _ = receive(&mut self.cruise_accel, &mut self.dtcs, now, frame)
            || receive(&mut self.traction, &mut self.dtcs, now, frame);
    }

    fn step(&mut self, now: Instant, sensors: &Sensors) -> Actuators {
        let mode_stale = supervise(&mut self.cruise_mode, &mut self.dtcs, now);
        let command_stale = supervise(&mut self.cruise_accel, &mut self.dtcs, now);
        let traction_stale = supervise(&mut self.traction, &mut self.dtcs, now);

        let accelerator_pedal = clamp_finite(sensors.accelerator_pedal, 0.0, PEDAL_FULL);
        let brake_pedal = clamp_finite(sensors.brake_pedal, 0.0, PEDAL_FULL);
        let braking = brake_pedal > PEDAL_PRESSED_THRESHOLD;
        let pressed = braking || accelerator_pedal > PEDAL_PRESSED_THRESHOLD;

        // The cruise state as the bus last showed it; stale counts as off.
        let cruise_on = !mode_stale && self.cruise_mode.value().cruise_mode == CruiseMode::On;
        if !cruise_on {
            if self.cancel.active {
                autoplug_log::info!("pedals: cruise cancel ended (CruiseModeMsg stale)");
            }
            self.cancel.active = false;
        } else if pressed && !self.cancel.active {
            autoplug_log::info!(
                "pedals: pedal pressed (accel {}, brake {}), cancelling cruise",
                accelerator_pedal,
                brake_pedal
            );
            self.cancel.active = true;
        }

        self.cruise_driving = cruise_on && !self.cancel.active && !command_stale;
        let (mut accelerator, brake) = if self.cruise_driving {
            let command = clamp_finite(
                self.cruise_accel.value().cruise_accel,
                -CRUISE_COMMAND_FULL,
                CRUISE_COMMAND_FULL,
            );
            if command > 0.0 {
                (command, 0.0)
            } else if command < 0.0 {
                (0.0, -command)
            } else {
                (0.0, 0.0)
            }
        } else {
            (accelerator_pedal, brake_pedal)
        };
        if braking {
            accelerator = 0.0;
        }
        let cut = if traction_stale {
            0.0
        } else {
            clamp_finite(self.traction.value().traction_cut, 0.0, TRACTION_CUT_FULL)
        };
        accelerator *= 1.0 - cut / TRACTION_CUT_FULL;

        let actuators = Actuators {
            accelerator_cmd: clamp_finite(accelerator, 0.0, PEDAL_FULL),
            brake_cmd: clamp_finite(brake, 0.0, PEDAL_FULL),
        };
        self.tx_brake.set_message(&PedalBrake {
            brake_cmd: actuators.brake_cmd,
        });
        self.tx_accel.set_message(&PedalAccel {
            accel_cmd: actuators.accelerator_cmd,
        });
        actuators
    }

    fn poll_transmit(&mut self, now: Instant) -> Option<Frame> {
        // Identifier order: PedalBrake 0x004, PedalAccel 0x007, CruiseModeMsg 0x008.
        self.tx_brake
            .poll(now)
            .or_else(|| self.tx_accel.poll(now))
            .or_else(|| self.cancel.poll(now))
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
