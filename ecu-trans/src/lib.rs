//! Transmission ECU (node 0x06), spec section 2 and report section 5.2.1.9.
//!
//! Reads the gear actually engaged from the gearbox's gear lines, decides the gear to
//! command and publishes the engaged gear and the shift mode (TransMsg, 20 ms).
//!
//! - **Shift mode** (automatic / manual) comes from the console switch, AccMsg bit 3.
//! - **Automatic**: the gear follows the vehicle speed (VehicleSpeedMsg) and the shift
//!   schedule of the engine mode (EngineMsg byte 2): [`SPORT`] shifts later than
//!   [`ECONOMY`]. Each gear's downshift speed lies well below the upshift speed into it
//!   (hysteresis), so the gearbox never hunts. Shifts go one gear at a time, never skipping.
//!   From Neutral at standstill, automatic engages 1st by itself (like a "D" position),
//!   unless the driver selected Neutral with a shift request: then it stays in Neutral until
//!   the driver asks for a gear. Reverse is only ever left by a request.
//! - **Shift requests** (ShiftMsg, from the steering paddles, a ~100 ms pulse): only the
//!   edge from "none" to "up" or "down" counts, and only after "none" has been seen (a
//!   paddle held at power-up or while ShiftMsg was lost does nothing). A request changes
//!   the gear in manual mode, and in automatic mode when in Neutral or Reverse or for a
//!   downshift from 1st (to Neutral). The sequence is R - N - 1st - ... - 6th.
//! - **Shift timeout**: at most one shift per [`SHIFT_TIMEOUT_US`]. A request arriving
//!   during the timeout waits for its end (as the report's "wait for timeout, then look for
//!   a shift message"); a later request replaces it.
//! - **Over-rev protection**: a downshift between forward gears is refused (logged, gear
//!   kept) when the engine speed it would give, engine RPM × ratio(target) / ratio(engaged),
//!   exceeds [`OVER_REV_LIMIT_RPM`]. Engaging 1st from Neutral checks the engine speed the
//!   road speed would give in 1st. Reverse is only engaged at standstill
//!   ([`STANDSTILL_KMH`]).
//!
//! Safe states per stale input (3 periods without a valid frame; "lost communication with"
//! the sender is recorded, and cleared when frames return):
//!
//! | input | sender | safe state |
//! |---|---|---|
//! | VehicleSpeedMsg | cruise | hold the current gear: no automatic shift; requests that need the speed (Neutral to 1st or Reverse) are refused |
//! | ShiftMsg | steering | requests ignored; a new request needs "none" seen again first |
//! | EngineMsg | engine | economy schedule; every downshift between forward gears is refused (engine speed unknown) |
//! | AccMsg | console | keep the last shift mode (automatic before the first frame) |
//!
//! Before the first valid frame an input counts as unknown in the same way (the start
//! values of the catalogue, 0 km/h and 0 rpm, are not taken as measurements).
//!
//! The gearbox should engage each commanded gear quickly; when the engaged gear still
//! differs from the command [`GEAR_ENGAGE_TIMEOUT_US`] after it, [`GEAR_NOT_ENGAGED`]
//! (P0730, incorrect gear ratio) is recorded. Decisions are based on the commanded gear;
//! at power-up the ECU adopts the engaged gear as its command, so it never shifts on its
//! own at start except for the automatic engagement of 1st from Neutral at standstill.
#![no_std]
#![deny(missing_docs)]

pub mod pins;

use autoplug_can::{
    AccMsg, EngineMode, EngineMsg, Frame, Gear, Node, ShiftMode, ShiftMsg, ShiftRequest, TransMsg,
    VehicleSpeedMsg,
};
use autoplug_ecu::{receive, supervise, Dtcs, EcuLogic, Input, Instant, PeriodicTx};

// The published parameters (calibration, thresholds, trouble codes) live with the
// other ECUs' in `autoplug-ecu-params`, where the gateway's diagnostics read them.
pub use autoplug_ecu_params::trans::*;

/// The part number of this ECU's software (UDS 0xF187), as the virtual car's ECUs answer
/// it.
pub const PART_NUMBER: &str = "AP-TRANS-0001";

/// Control period, µs: twice the rate of ShiftMsg, the speed's own period.
pub const STEP_PERIOD_US: u64 = 10_000;

/// Sensor readings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Sensors {
    /// The gear engaged, from the gearbox's gear lines.
    pub current_gear: Gear,
}

impl Default for Sensors {
    fn default() -> Self {
        Self {
            current_gear: Gear::Neutral,
        }
    }
}

/// Actuator commands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Actuators {
    /// The gear to engage, to the gearbox's gear command lines.
    pub gear_cmd: Gear,
}

impl Default for Actuators {
    fn default() -> Self {
        Self {
            gear_cmd: Gear::Neutral,
        }
    }
}

/// What the ECU decided, for logs and the virtual car's trace.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Status {
    /// The gear commanded.
    pub gear_cmd: Gear,
    /// The gear engaged at the last step.
    pub engaged: Gear,
    /// The shift mode in effect.
    pub shift_mode: ShiftMode,
    /// The schedule in use (economy when EngineMsg is lost).
    pub schedule: EngineMode,
    /// The last shift request was refused (over-rev, or the speed needed was unknown).
    pub last_request_refused: bool,
}

/// Why a shift request was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
enum Refusal {
    /// The engine would exceed the over-rev limit.
    OverRev,
    /// The engine speed is unknown (EngineMsg lost).
    EngineSpeedUnknown,
    /// The road speed is unknown (VehicleSpeedMsg lost).
    RoadSpeedUnknown,
    /// Reverse only at standstill.
    Moving,
}

/// The transmission ECU's logic.
#[derive(Clone, Debug)]
pub struct TransEcu {
    speed: Input<VehicleSpeedMsg>,
    shift: Input<ShiftMsg>,
    acc: Input<AccMsg>,
    engine: Input<EngineMsg>,
    /// `None` until the first step adopts the engaged gear.
    gear_cmd: Option<Gear>,
    engaged: Gear,
    command_since: Instant,
    last_shift: Option<Instant>,
    /// A "none" was seen on ShiftMsg since the last request (or since start / stale).
    request_armed: bool,
    pending: Option<ShiftRequest>,
    driver_selected_neutral: bool,
    last_request_refused: bool,
    shift_mode: ShiftMode,
    schedule_mode: EngineMode,
    tx: PeriodicTx,
    dtcs: Dtcs,
}

impl TransEcu {
    /// The ECU at power-up (`now`).
    pub fn new(now: Instant) -> Self {
        Self {
            speed: Input::new(now),
            shift: Input::new(now),
            acc: Input::new(now),
            engine: Input::new(now),
            gear_cmd: None,
            engaged: Gear::Neutral,
            command_since: now,
            last_shift: None,
            request_armed: false,
            pending: None,
            driver_selected_neutral: false,
            last_request_refused: false,
            shift_mode: ShiftMode::Automatic,
            schedule_mode: EngineMode::Economy,
            tx: PeriodicTx::of::<TransMsg>(),
            dtcs: Dtcs::new(),
        }
    }

    /// What the last step decided.
    pub fn status(&self) -> Status {
        Status {
            gear_cmd: self.gear_cmd.unwrap_or(self.engaged),
            engaged: self.engaged,
            shift_mode: self.shift_mode,
            schedule: self.schedule_mode,
            last_request_refused: self.last_request_refused,
        }
    }

    /// The road speed, if known (fresh and received at least once).
    fn road_speed(&self) -> Option<f32> {
        self.speed.known().map(|m| m.vehicle_speed)
    }

    /// The engine speed, if known.
    fn engine_rpm(&self) -> Option<f32> {
        self.engine.known().map(|m| m.engine_rpm)
    }

    /// Whether a request may change the gear (report 5.2.1.9 step 5).
    fn request_applies(&self, gear: Gear, request: ShiftRequest) -> bool {
        self.shift_mode == ShiftMode::Manual
            || matches!(gear, Gear::Neutral | Gear::Reverse)
            || (gear == Gear::First && request == ShiftRequest::Down)
    }

    /// Checks a requested shift from `gear` to `target`.
    fn check_request(&self, gear: Gear, target: Gear) -> Result<(), Refusal> {
        match (gear, target) {
            (Gear::Neutral, Gear::Reverse) => match self.road_speed() {
                None => Err(Refusal::RoadSpeedUnknown),
                Some(v) if v > STANDSTILL_KMH => Err(Refusal::Moving),
                Some(_) => Ok(()),
            },
            (Gear::Neutral, Gear::First) => {
                let speed = self.road_speed().ok_or(Refusal::RoadSpeedUnknown)?;
                let [first, ..] = GEAR_RATIOS;
                if engine_rpm_at(speed, first) > OVER_REV_LIMIT_RPM {
                    Err(Refusal::OverRev)
                } else {
                    Ok(())
                }
            }
            _ => match (forward_index(gear), forward_index(target)) {
                (Some(from), Some(to)) if to < from => {
                    let rpm = self.engine_rpm().ok_or(Refusal::EngineSpeedUnknown)?;
                    // The RPM was measured in the engaged gear (the command, unless a shift
                    // is still in progress or the box is in Neutral).
                    let measured_in = if forward_index(self.engaged).is_some() {
                        self.engaged
                    } else {
                        gear
                    };
                    let reference = gear_ratio(measured_in).unwrap_or(1.0);
                    let target_ratio = gear_ratio(target).unwrap_or(reference);
                    if rpm * target_ratio / reference > OVER_REV_LIMIT_RPM {
                        Err(Refusal::OverRev)
                    } else {
                        Ok(())
                    }
                }
                // Upshifts, and leaving a forward gear or Reverse for Neutral.
                _ => Ok(()),
            },
        }
    }

    fn shift_to(&mut self, now: Instant, from: Gear, to: Gear, by_request: bool) {
        autoplug_log::info!(
            "trans: {:?} -> {:?} ({})",
            from,
            to,
            if by_request { "request" } else { "schedule" }
        );
        self.gear_cmd = Some(to);
        self.last_shift = Some(now);
        self.command_since = now;
        self.driver_selected_neutral = by_request && to == Gear::Neutral;
    }

    /// Tracks shift requests: the edge from "none" to up/down, once armed.
    fn track_requests(&mut self, stale: bool) {
        if stale || !self.shift.ever_received() {
            self.request_armed = false;
            self.pending = None;
            return;
        }
        match self.shift.value().shift_request {
            ShiftRequest::None => self.request_armed = true,
            request => {
                if self.request_armed {
                    self.pending = Some(request);
                }
                self.request_armed = false;
            }
        }
    }

    fn supervise_gear_engagement(&mut self, now: Instant, gear_cmd: Gear) {
        if self.engaged == gear_cmd {
            self.dtcs.report_passed(GEAR_NOT_ENGAGED);
        } else if now.micros_since(self.command_since) >= GEAR_ENGAGE_TIMEOUT_US
            && self.dtcs.report_failed(GEAR_NOT_ENGAGED, now)
        {
            autoplug_log::error!(
                "trans: {:?} commanded, {:?} engaged: DTC recorded",
                gear_cmd,
                self.engaged
            );
        }
    }
}

impl EcuLogic for TransEcu {
    type Sensors = Sensors;
    type Actuators = Actuators;

    const NODE: Node = Node::Transmission;
    const STEP_PERIOD_US: u64 = STEP_PERIOD_US;

    fn on_frame(&mut self, now: Instant, frame: &Frame) {
        let _ = receive(&mut self.speed, &mut self.dtcs, now, frame)
            || receive(&mut self.shift, &mut self.dtcs, now, frame)
            || receive(&mut self.acc, &mut self.dtcs, now, frame)
            || receive(&mut self.engine, &mut self.dtcs, now, frame);
    }

    fn step(&mut self, now: Instant, sensors: &Sensors) -> Actuators {
        self.engaged = sensors.current_gear;
        let gear = match self.gear_cmd {
            Some(gear) => gear,
            None => {
                // Power-up: continue in whatever gear the box is in.
                self.command_since = now;
                self.gear_cmd = Some(self.engaged);
                self.engaged
            }
        };

        supervise(&mut self.speed, &mut self.dtcs, now);
        let shift_stale = supervise(&mut self.shift, &mut self.dtcs, now);
        supervise(&mut self.acc, &mut self.dtcs, now);
        supervise(&mut self.engine, &mut self.dtcs, now);

        // A stale AccMsg keeps its last good value: the last shift mode.
        let mode = self.acc.value().shift_mode_request;
        if mode != self.shift_mode {
            autoplug_log::info!("trans: {:?} mode", mode);
            self.pending = None;
            self.shift_mode = mode;
        }
        self.schedule_mode = self
            .engine
            .known()
            .map(|m| m.engine_mode)
            .unwrap_or(EngineMode::Economy);
        self.track_requests(shift_stale);

        let may_shift = self
            .last_shift
            .is_none_or(|at| now.micros_since(at) >= SHIFT_TIMEOUT_US);
        if may_shift {
            let mut shifted = false;
            if let Some(request) = self.pending.take() {
                let target = match request {
                    ShiftRequest::Up => gear_up(gear),
                    ShiftRequest::Down => gear_down(gear),
                    ShiftRequest::None => None,
                };
                match target {
                    Some(target) if self.request_applies(gear, request) => {
                        match self.check_request(gear, target) {
                            Ok(()) => {
                                self.last_request_refused = false;
                                self.shift_to(now, gear, target, true);
                                shifted = true;
                            }
                            Err(why) => {
                                self.last_request_refused = true;
                                autoplug_log::warn!(
                                    "trans: {:?} -> {:?} refused ({:?})",
                                    gear,
                                    target,
                                    why
                                );
                            }
                        }
                    }
                    _ => autoplug_log::debug!("trans: {:?} request ignored in {:?}", request, gear),
                }
            }
            if !shifted && self.shift_mode == ShiftMode::Automatic {
                // Without a known road speed the gear is held.
                if let Some(speed) = self.road_speed() {
                    let target = match gear {
                        Gear::Neutral
                            if !self.driver_selected_neutral && speed <= STANDSTILL_KMH =>
                        {
                            Gear::First
                        }
                        Gear::Neutral | Gear::Reverse => gear,
                        _ => schedule(self.schedule_mode).next_gear(gear, speed),
                    };
                    if target != gear {
                        self.shift_to(now, gear, target, false);
                    }
                }
            }
        }

        let gear_cmd = self.gear_cmd.unwrap_or(gear);
        self.supervise_gear_engagement(now, gear_cmd);
        self.tx.set_message(&TransMsg {
            gear: self.engaged,
            shift_mode: self.shift_mode,
        });
        Actuators { gear_cmd }
    }

    fn poll_transmit(&mut self, now: Instant) -> Option<Frame> {
        self.tx.poll(now)
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
