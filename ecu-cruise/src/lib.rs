//! Cruise control ECU (node 0x0D), spec section 2.
//!
//! Reads the vehicle speed and publishes it (VehicleSpeedMsg). When cruise is enabled
//! (CruiseModeMsg from the steering buttons; the pedals ECU cancels it) for two steps in a
//! row, it latches the current speed as the set speed and runs PI feedback on the speed error; the command in
//! [-100, 100] goes out as CruiseAccelMsg (positive accelerates, negative brakes).
//! Disabled: command 0 and the integrator reset.
//!
//! Safe state: when CruiseModeMsg goes stale (3 periods, 60 ms), cruise disengages as if
//! switched off and "lost communication with the steering ECU" is recorded. When the
//! frames return it stays off until the request goes off and on again: a comms glitch
//! never re-engages cruise by itself.
//!
//! [`Variant::Faulty`] is the "faulty software" of the report's first demonstration: a
//! bang-bang controller that slams between full throttle and hard braking, so the speed
//! oscillates erratically around the set speed. Firmware selects it with the `faulty`
//! feature; the virtual car picks it per scenario.
#![no_std]
#![deny(missing_docs)]

pub mod pins;

use autoplug_can::{CruiseAccelMsg, CruiseMode, CruiseModeMsg, Frame, Node, VehicleSpeedMsg};
use autoplug_ecu::{receive, supervise, Dtcs, EcuLogic, Input, Instant, PeriodicTx};
use autoplug_pid::{Pid, PidConfig};

pub use autoplug_ecu::Variant;

/// The variant this build runs: [`Variant::Faulty`] with the `faulty` cargo feature (the
/// demonstration's broken firmware), [`Variant::Correct`] otherwise. The virtual car
/// chooses per scenario instead.
pub const BUILD_VARIANT: Variant = if cfg!(feature = "faulty") {
    Variant::Faulty
} else {
    Variant::Correct
};

/// PI tuning: command in % (of full throttle or full braking) per km/h of error.
pub const TUNING: PidConfig = PidConfig {
    kp: 10.0,
    ki: 2.0,
    kd: 0.0,
    derivative_filter_tau_s: 0.0,
    output_min: -100.0,
    output_max: 100.0,
};

/// The controller, built at compile time: an invalid `TUNING` fails the build.
const SPEED_PID: Pid = Pid::from_tuning(TUNING);

/// The faulty software's dead band around the set speed, km/h.
pub const FAULTY_DEAD_BAND_KMH: f32 = 1.0;

/// Steps the request must read "on" in a row before cruise engages. CruiseModeMsg has two
/// senders: a steering "on" frame already queued when the pedals' cancel goes out can
/// reach the bus just after it; requiring the request to persist filters that frame out.
pub const ENGAGE_CONFIRM_STEPS: u8 = 2;

/// The part number of this ECU's software (UDS 0xF187), as the virtual car's ECUs answer
/// it.
pub const PART_NUMBER: &str = "AP-CRUISE-0001";

/// Control period: the rate VehicleSpeedMsg is published at.
pub const STEP_PERIOD_US: u64 = 10_000;

/// Sensor readings.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Sensors {
    /// Vehicle speed, km/h.
    pub vehicle_speed_kmh: f32,
}

/// The cruise ECU has no actuator of its own: its command reaches the pedals over CAN.
/// This reports what it decided, for logs and the virtual car's trace.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Status {
    /// Cruise holding a set speed.
    pub engaged: bool,
    /// The latched set speed, km/h (0 when disengaged).
    pub set_speed_kmh: f32,
    /// The command sent, -100..=100.
    pub command: f32,
}

/// The cruise control ECU's logic.
#[derive(Clone, Debug)]
pub struct CruiseEcu {
    variant: Variant,
    cruise_mode: Input<CruiseModeMsg>,
    pid: Pid,
    status: Status,
    /// An "off" has been seen since cruise last disengaged or lost its input: only then
    /// may an "on" engage it.
    armed: bool,
    /// Consecutive steps the request has read "on".
    on_steps: u8,
    last_step: Option<Instant>,
    tx_speed: PeriodicTx,
    tx_command: PeriodicTx,
    dtcs: Dtcs,
}

impl CruiseEcu {
    /// The ECU at power-up (`now`), running `variant`.
    pub fn new(variant: Variant, now: Instant) -> Self {
        Self {
            variant,
            cruise_mode: Input::new(now),
            pid: SPEED_PID,
            status: Status::default(),
            armed: true,
            on_steps: 0,
            last_step: None,
            tx_speed: PeriodicTx::of::<VehicleSpeedMsg>(),
            tx_command: PeriodicTx::of::<CruiseAccelMsg>(),
            dtcs: Dtcs::new(),
        }
    }

    /// The software variant running.
    pub fn variant(&self) -> Variant {
        self.variant
    }

    /// What the last step decided.
    pub fn status(&self) -> Status {
        self.status
    }

    fn disengage(&mut self) {
        if self.status.engaged {
            autoplug_log::info!("cruise: disengaged");
        }
        self.status = Status::default();
        self.pid.reset();
    }

    fn engage(&mut self, speed_kmh: f32) {
        autoplug_log::info!("cruise: engaged at {} km/h", speed_kmh);
        self.pid.reset();
        self.status = Status {
            engaged: true,
            set_speed_kmh: speed_kmh,
            command: 0.0,
        };
    }

    fn control(&mut self, speed_kmh: f32, dt_s: f32) -> f32 {
        let set = self.status.set_speed_kmh;
        match self.variant {
            Variant::Correct => self.pid.update(set, speed_kmh, dt_s),
            Variant::Faulty => {
                // The broken build: full authority either way outside a narrow band.
                if speed_kmh < set - FAULTY_DEAD_BAND_KMH {
                    100.0
                } else if speed_kmh > set + FAULTY_DEAD_BAND_KMH {
                    -100.0
                } else {
                    self.status.command
                }
            }
        }
    }
}

impl EcuLogic for CruiseEcu {
    type Sensors = Sensors;
    type Actuators = Status;

    const NODE: Node = Node::Cruise;
    const STEP_PERIOD_US: u64 = STEP_PERIOD_US;

    fn on_frame(&mut self, now: Instant, frame: &Frame) {
        receive(&mut self.cruise_mode, &mut self.dtcs, now, frame);
    }

    fn step(&mut self, now: Instant, sensors: &Sensors) -> Status {
        let dt_s = match self.last_step {
            Some(last) => now.micros_since(last) as f32 * 1e-6,
            None => STEP_PERIOD_US as f32 * 1e-6,
        };
        self.last_step = Some(now);
        let speed = sensors.vehicle_speed_kmh;

        if supervise(&mut self.cruise_mode, &mut self.dtcs, now) {
            // Safe state. Disarm, so that when the frames return still saying "on", cruise
            // stays off until the driver switches it off and on.
            self.disengage();
            self.armed = false;
            self.on_steps = 0;
        } else {
            match self.cruise_mode.value().cruise_mode {
                CruiseMode::Off => {
                    self.disengage();
                    self.armed = true;
                    self.on_steps = 0;
                }
                CruiseMode::On => {
                    self.on_steps = self.on_steps.saturating_add(1);
                    if self.armed && !self.status.engaged && self.on_steps >= ENGAGE_CONFIRM_STEPS {
                        self.engage(speed);
                        self.armed = false;
                    }
                }
            }
        }

        if self.status.engaged {
            self.status.command = self.control(speed, dt_s);
        }
        self.tx_speed.set_message(&VehicleSpeedMsg {
            vehicle_speed: speed,
        });
        self.tx_command.set_message(&CruiseAccelMsg {
            cruise_accel: self.status.command,
        });
        self.status
    }

    fn poll_transmit(&mut self, now: Instant) -> Option<Frame> {
        self.tx_speed
            .poll(now)
            .or_else(|| self.tx_command.poll(now))
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
