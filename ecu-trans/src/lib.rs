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

use autoplug_can::{
    AccMsg, EngineMode, EngineMsg, Frame, Gear, Node, ShiftMode, ShiftMsg, ShiftRequest, TransMsg,
    VehicleSpeedMsg,
};
use autoplug_ecu::{
    receive, supervise, Dtc, DtcSystem, Dtcs, EcuLogic, Input, Instant, PeriodicTx,
};

/// Ratios of 1st to 6th gear: the transmission's calibration of the gearbox it controls,
/// the six-speed box of `VehicleParams::evo_vi()` in the vehicle model (a host test in
/// `host-tests/` checks the two agree; the model documents the source).
pub const GEAR_RATIOS: [f32; 6] = [2.909, 1.944, 1.434, 1.100, 0.868, 0.693];

/// Reverse gear ratio, as a magnitude (same calibration source).
pub const REVERSE_RATIO: f32 = 3.3;

/// Final drive ratio (EVO VI).
pub const FINAL_DRIVE_RATIO: f32 = 4.529;

/// Rolling radius of the tyres (225/45 ZR17), m: converts road speed to engine speed.
pub const TYRE_RADIUS_M: f32 = 0.31;

/// Highest engine speed a driver's downshift may give, rpm: a margin under the ~7500 rpm
/// redline, for the RPM signal's 35 rpm resolution and its 20 ms age.
pub const OVER_REV_LIMIT_RPM: f32 = 7000.0;

/// At most one shift per this time, µs: lets the gearbox complete a shift and the engine
/// speed settle before the next decision. Short enough for 1st to 6th while accelerating
/// to 150 km/h in about 12 s at full throttle (the report's figure).
pub const SHIFT_TIMEOUT_US: u64 = 800_000;

/// At or below this road speed the car counts as stopped, km/h: automatic engages 1st from
/// Neutral, and Reverse may be engaged. VehicleSpeedMsg has 1 km/h resolution.
pub const STANDSTILL_KMH: f32 = 3.0;

/// Economy upshift point, rpm: upshift early, near peak torque, for low consumption.
pub const ECONOMY_UPSHIFT_RPM: f32 = 3200.0;
/// Economy downshift point, rpm in the current gear: let the engine lug down to here.
pub const ECONOMY_DOWNSHIFT_RPM: f32 = 1400.0;
/// Sport upshift point, rpm: near peak power (~6500 rpm), under the over-rev limit.
pub const SPORT_UPSHIFT_RPM: f32 = 6800.0;
/// Sport downshift point, rpm in the current gear: drop a gear to stay in the power band.
pub const SPORT_DOWNSHIFT_RPM: f32 = 3500.0;

/// Smallest gap between a gear's upshift speed and the next gear's downshift speed, km/h:
/// with less, speed noise could make the gearbox hunt. Checked at compile time.
pub const MIN_HYSTERESIS_KMH: f32 = 5.0;

/// After this time, µs, an engaged gear still different from the command is a fault.
pub const GEAR_ENGAGE_TIMEOUT_US: u64 = 1_000_000;

/// DTC P0730-00, "incorrect gear ratio": the gearbox did not engage the commanded gear.
pub const GEAR_NOT_ENGAGED: Dtc = Dtc::new(DtcSystem::P, 0x0730, 0x00);

/// Control period, µs: twice the rate of ShiftMsg, the speed's own period.
pub const STEP_PERIOD_US: u64 = 10_000;

/// Road speed, km/h, at an engine speed in a gear of `ratio`:
/// `rpm / 60 × 2π r / (ratio × final drive) × 3.6`.
pub const fn road_speed_kmh(engine_rpm: f32, ratio: f32) -> f32 {
    engine_rpm * (2.0 * core::f32::consts::PI * TYRE_RADIUS_M * 0.06) / (ratio * FINAL_DRIVE_RATIO)
}

/// Engine speed, rpm, at a road speed in a gear of `ratio` (inverse of [`road_speed_kmh`]).
pub const fn engine_rpm_at(speed_kmh: f32, ratio: f32) -> f32 {
    speed_kmh * ratio * FINAL_DRIVE_RATIO / (2.0 * core::f32::consts::PI * TYRE_RADIUS_M * 0.06)
}

/// The ratio of a gear (reverse as a magnitude); `None` for Neutral.
pub const fn gear_ratio(gear: Gear) -> Option<f32> {
    let [first, second, third, fourth, fifth, sixth] = GEAR_RATIOS;
    match gear {
        Gear::Reverse => Some(REVERSE_RATIO),
        Gear::Neutral => None,
        Gear::First => Some(first),
        Gear::Second => Some(second),
        Gear::Third => Some(third),
        Gear::Fourth => Some(fourth),
        Gear::Fifth => Some(fifth),
        Gear::Sixth => Some(sixth),
    }
}

/// 0 for 1st .. 5 for 6th; `None` for Reverse and Neutral.
const fn forward_index(gear: Gear) -> Option<usize> {
    match gear {
        Gear::First => Some(0),
        Gear::Second => Some(1),
        Gear::Third => Some(2),
        Gear::Fourth => Some(3),
        Gear::Fifth => Some(4),
        Gear::Sixth => Some(5),
        Gear::Reverse | Gear::Neutral => None,
    }
}

/// The next gear up in the sequence R - N - 1st - ... - 6th.
pub const fn gear_up(gear: Gear) -> Option<Gear> {
    match gear {
        Gear::Reverse => Some(Gear::Neutral),
        Gear::Neutral => Some(Gear::First),
        Gear::First => Some(Gear::Second),
        Gear::Second => Some(Gear::Third),
        Gear::Third => Some(Gear::Fourth),
        Gear::Fourth => Some(Gear::Fifth),
        Gear::Fifth => Some(Gear::Sixth),
        Gear::Sixth => None,
    }
}

/// The next gear down in the sequence R - N - 1st - ... - 6th.
pub const fn gear_down(gear: Gear) -> Option<Gear> {
    match gear {
        Gear::Reverse => None,
        Gear::Neutral => Some(Gear::Reverse),
        Gear::First => Some(Gear::Neutral),
        Gear::Second => Some(Gear::First),
        Gear::Third => Some(Gear::Second),
        Gear::Fourth => Some(Gear::Third),
        Gear::Fifth => Some(Gear::Fourth),
        Gear::Sixth => Some(Gear::Fifth),
    }
}

/// The road speeds of an automatic shift schedule.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct ShiftSchedule {
    /// `upshift_kmh[i]`: at or above this speed, shift from gear `i + 1` to `i + 2`
    /// (index 0: 1st to 2nd, ..., 4: 5th to 6th), km/h.
    pub upshift_kmh: [f32; 5],
    /// `downshift_kmh[i]`: at or below this speed, shift from gear `i + 2` to `i + 1`
    /// (index 0: 2nd to 1st, ..., 4: 6th to 5th), km/h.
    pub downshift_kmh: [f32; 5],
}

impl ShiftSchedule {
    /// Upshift where the engine reaches `upshift_rpm` in the current gear, downshift where
    /// it falls to `downshift_rpm` in the current gear.
    pub const fn from_rpm(upshift_rpm: f32, downshift_rpm: f32) -> Self {
        let mut upshift_kmh = [0.0; 5];
        let mut downshift_kmh = [0.0; 5];
        let mut i = 0;
        while i < 5 {
            upshift_kmh[i] = road_speed_kmh(upshift_rpm, GEAR_RATIOS[i]);
            downshift_kmh[i] = road_speed_kmh(downshift_rpm, GEAR_RATIOS[i + 1]);
            i += 1;
        }
        Self {
            upshift_kmh,
            downshift_kmh,
        }
    }

    /// Whether the schedule can be used: upshift speeds rising gear by gear, and each
    /// downshift at least [`MIN_HYSTERESIS_KMH`] below the upshift into that gear (and
    /// above 0, so 2nd is left before stopping).
    pub const fn is_valid(&self) -> bool {
        let mut i = 0;
        while i < 5 {
            if self.downshift_kmh[i] <= 0.0
                || self.downshift_kmh[i] > self.upshift_kmh[i] - MIN_HYSTERESIS_KMH
            {
                return false;
            }
            if i > 0 && self.upshift_kmh[i] <= self.upshift_kmh[i - 1] {
                return false;
            }
            i += 1;
        }
        true
    }

    /// The speed at or above which `gear` shifts up; `None` for 6th, Neutral, Reverse.
    pub fn upshift_speed(&self, gear: Gear) -> Option<f32> {
        forward_index(gear).and_then(|i| self.upshift_kmh.get(i).copied())
    }

    /// The speed at or below which `gear` shifts down; `None` for 1st, Neutral, Reverse.
    pub fn downshift_speed(&self, gear: Gear) -> Option<f32> {
        forward_index(gear)
            .and_then(|i| i.checked_sub(1))
            .and_then(|i| self.downshift_kmh.get(i).copied())
    }

    /// The gear the schedule wants next from `gear` at `speed_kmh`: one gear up or down,
    /// or `gear` itself. Neutral and Reverse are not the schedule's business.
    pub fn next_gear(&self, gear: Gear, speed_kmh: f32) -> Gear {
        if let Some(up) = self.upshift_speed(gear) {
            if speed_kmh >= up {
                return gear_up(gear).unwrap_or(gear);
            }
        }
        if let Some(down) = self.downshift_speed(gear) {
            if speed_kmh <= down {
                return gear_down(gear).unwrap_or(gear);
            }
        }
        gear
    }
}

/// Economy schedule (engine mode economy, and whenever EngineMsg is lost). Upshifts at
/// 30.2, 43.2, 59.8, 81.6, 110.6 km/h (1-2 .. 5-6); downshifts at 18.9, 26.2, 35.7, 48.4,
/// 61.4 km/h (2-1 .. 6-5).
pub const ECONOMY: ShiftSchedule =
    ShiftSchedule::from_rpm(ECONOMY_UPSHIFT_RPM, ECONOMY_DOWNSHIFT_RPM);

/// Sport schedule: every shift point later than economy's. Upshifts at 64.2, 91.7, 127.1,
/// 173.5, 235.0 km/h; downshifts at 47.2, 65.4, 89.3, 121.0, 153.4 km/h.
pub const SPORT: ShiftSchedule = ShiftSchedule::from_rpm(SPORT_UPSHIFT_RPM, SPORT_DOWNSHIFT_RPM);

const _: () = assert!(ECONOMY.is_valid() && SPORT.is_valid());
const _: () = assert!(SPORT_UPSHIFT_RPM <= OVER_REV_LIMIT_RPM);
const _: () =
    assert!(ECONOMY_UPSHIFT_RPM < SPORT_UPSHIFT_RPM && ECONOMY_DOWNSHIFT_RPM < SPORT_DOWNSHIFT_RPM);

/// The schedule for an engine mode.
pub const fn schedule(mode: EngineMode) -> &'static ShiftSchedule {
    match mode {
        EngineMode::Sport => &SPORT,
        EngineMode::Economy => &ECONOMY,
    }
}

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
