//! Console ECU (node 0x0B), spec section 2 and the report's pseudocode 5.2.1.4.
//!
//! Reads the headlight, engine-mode and transmission-mode switches; drives the headlights
//! (from the switch) and the brake lights (from the brake command the pedals ECU publishes
//! on PedalBrake); publishes AccMsg every 100 ms and at once on a change: bit 0 headlights,
//! bit 1 brake lights (as driven), bit 2 engine mode (1 = economy), bit 3 transmission mode
//! request (1 = manual), which reaches the engine and transmission ECUs.
//!
//! Brake lights: on once the brake command exceeds [`BRAKE_LIGHTS_ON_PCT`], off again once
//! it is back at or below [`BRAKE_LIGHTS_OFF_PCT`]. The hysteresis keeps a brake command
//! hovering at the threshold (light cruise braking, 1 % quantisation) from flickering the
//! lights and flooding the bus with AccMsg changes.
//!
//! Safe state per stale input (3 periods without a valid frame):
//!
//! | input | stale after | safe state | DTC |
//! |---|---|---|---|
//! | PedalBrake | 30 ms | brake lights **on**: when the brake state is unknown, warn the drivers behind rather than risk braking unseen | lost communication with the pedals ECU |
//!
//! For the same reason the brake lights are on from power-up until the first valid
//! PedalBrake arrives.
#![no_std]
#![deny(missing_docs)]

pub mod pins;

use autoplug_can::{AccMsg, EngineMode, Frame, Node, PedalBrake, ShiftMode};
use autoplug_ecu::{receive, supervise, Dtcs, EcuLogic, Input, Instant, PeriodicTx};

// The published parameters (calibration, thresholds, trouble codes) live with the
// other ECUs' in `autoplug-ecu-params`, where the gateway's diagnostics read them.
pub use autoplug_ecu_params::console::*;

/// The part number of this ECU's software (UDS 0xF187), as the virtual car's ECUs answer
/// it.
pub const PART_NUMBER: &str = "AP-CONSOLE-0001";

/// Control period: brake lights follow PedalBrake (10 ms) within a step.
pub const STEP_PERIOD_US: u64 = 10_000;

/// The console switches.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Sensors {
    /// Headlight switch on.
    pub headlight_switch: bool,
    /// Engine-mode switch: true = economy, false = sport.
    pub economy_mode_switch: bool,
    /// Transmission-mode switch: true = manual, false = automatic.
    pub manual_mode_switch: bool,
}

/// Commands to the vehicle's lamps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Actuators {
    /// Headlights on.
    pub headlights: bool,
    /// Brake lights on.
    pub brake_lights: bool,
}

/// The console ECU's logic.
#[derive(Clone, Debug)]
pub struct ConsoleEcu {
    brake: Input<PedalBrake>,
    brake_lights: bool,
    tx_acc: PeriodicTx,
    dtcs: Dtcs,
}

impl ConsoleEcu {
    /// The ECU at power-up (`now`).
    pub fn new(now: Instant) -> Self {
        Self {
            brake: Input::new(now),
            brake_lights: true,
            tx_acc: PeriodicTx::of::<AccMsg>(),
            dtcs: Dtcs::new(),
        }
    }
}

impl EcuLogic for ConsoleEcu {
    type Sensors = Sensors;
    type Actuators = Actuators;

    const NODE: Node = Node::Console;
    const STEP_PERIOD_US: u64 = STEP_PERIOD_US;

    fn on_frame(&mut self, now: Instant, frame: &Frame) {
        receive(&mut self.brake, &mut self.dtcs, now, frame);
    }

    fn step(&mut self, now: Instant, sensors: &Sensors) -> Actuators {
        let stale = supervise(&mut self.brake, &mut self.dtcs, now);
        let brake_lights = if stale || !self.brake.ever_received() {
            true
        } else {
            let brake = self.brake.value().brake_cmd;
            if self.brake_lights {
                brake > BRAKE_LIGHTS_OFF_PCT
            } else {
                brake > BRAKE_LIGHTS_ON_PCT
            }
        };
        if brake_lights != self.brake_lights {
            autoplug_log::debug!("console: brake lights {}", brake_lights);
        }
        self.brake_lights = brake_lights;

        let actuators = Actuators {
            headlights: sensors.headlight_switch,
            brake_lights,
        };
        self.tx_acc.set_message(&AccMsg {
            headlights: actuators.headlights,
            brake_lights: actuators.brake_lights,
            engine_mode: if sensors.economy_mode_switch {
                EngineMode::Economy
            } else {
                EngineMode::Sport
            },
            shift_mode_request: if sensors.manual_mode_switch {
                ShiftMode::Manual
            } else {
                ShiftMode::Automatic
            },
        });
        actuators
    }

    fn poll_transmit(&mut self, now: Instant) -> Option<Frame> {
        self.tx_acc.poll(now)
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
