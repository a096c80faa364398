//! Trips from the traffic: where one begins and ends, and its statistics on the way.
//!
//! **The rule.** A trip begins at the first frame that shows the engine running (EngineMsg
//! with at least [`ENGINE_RUNNING_RPM`]) or the car moving (VehicleSpeedMsg above 0). It ends
//! - *parked*: the engine off and the car standing for [`PARKED_AFTER_US`] (a stop at a
//!   light keeps the engine running, so it never ends a trip); the trip ends at the last
//!   frame that showed it running or moving;
//! - *bus silent*: no EngineMsg or VehicleSpeedMsg for [`SILENT_AFTER_US`] (ignition off,
//!   the ECUs unpowered, the gateway unplugged); it ends at the last frame that showed it
//!   running or moving, and the next such frame begins a new trip;
//! - *end of input*: the log ends or the gateway stops; it ends at the last frame seen.
//!
//! Everything is computed from frame timestamps, so a log and the live bus give the same
//! trips. Samples further apart than 3 of their message's periods (a silent sender) are not
//! integrated across: the gateway does not invent what it did not see.

use std::collections::VecDeque;

use autoplug_can::{
    AbsMsg, CanMessage, CruiseMode, CruiseModeMsg, DiffMsg, EngineMsg, Gear, PedalBrake, TransMsg,
    VehicleSpeedMsg, MESSAGES,
};
use autoplug_ecu::STALE_AFTER_PERIODS;
use autoplug_gateway::{CarState, Observer, Update};
use autoplug_logs::LogFrame;

use crate::record::{SeriesPoint, TripEnd, TripStats};
use crate::series::Downsampler;
use crate::{
    ABS_MERGE_GAP_US, DIFF_MERGE_GAP_US, HARD_BRAKING_MPS2, PARKED_AFTER_US, SILENT_AFTER_US,
};

/// Engine speed above which the engine counts as running, rpm (cranking is about 200, idle
/// 850).
pub const ENGINE_RUNNING_RPM: f64 = 300.0;

/// Window over which the deceleration of a braking is measured, µs: the speed's 1 km/h
/// steps make a 10 ms difference meaningless; over 0.5 s one step is 0.56 m/s².
pub const DECELERATION_WINDOW_US: u64 = 500_000;

/// Highest fuel flow the engine ECU's counter can show (its input's full scale), mL/s: a
/// larger step between two readings means the ECU restarted and its counter began at 0.
const FUEL_FLOW_MAX_ML_PER_S: f64 = autoplug_ecu_params::engine::FUEL_FLOW_MAX_L_PER_H as f64 / 3.6;

/// A trip that has ended.
#[derive(Clone, Debug, PartialEq)]
pub struct CompletedTrip {
    /// Its statistics.
    pub stats: TripStats,
    /// Why it ended.
    pub end: TripEnd,
    /// The part of its series not taken while it ran.
    pub series: Vec<SeriesPoint>,
}

/// The longest a sample of a message holds: 3 of its periods.
fn hold_us<M: CanMessage>() -> u64 {
    u64::from(M::CYCLE_TIME_MS) * 1000 * STALE_AFTER_PERIODS
}

/// The interval since the previous sample, if it is short enough to integrate over.
fn held_since<M: CanMessage>(previous: Option<u64>, t_us: u64) -> Option<f64> {
    let dt = t_us.checked_sub(previous?)?;
    (dt <= hold_us::<M>()).then_some(dt as f64 * 1e-6)
}

/// Stretches of "acting" (ABS releasing, a torque split), counted once per stretch with
/// short gaps merged, and their total time.
#[derive(Debug, Default)]
struct Interventions {
    last_sample: Option<(u64, bool)>,
    last_acting_us: Option<u64>,
    count: u32,
    time_s: f64,
}

impl Interventions {
    fn sample<M: CanMessage>(&mut self, t_us: u64, acting: bool, merge_gap_us: u64) {
        if let Some((t0, was_acting)) = self.last_sample {
            if was_acting {
                self.time_s += held_since::<M>(Some(t0), t_us).unwrap_or(0.0);
            }
        }
        if acting {
            if self
                .last_acting_us
                .is_none_or(|last| t_us.saturating_sub(last) > merge_gap_us)
            {
                self.count += 1;
            }
            self.last_acting_us = Some(t_us);
        }
        self.last_sample = Some((t_us, acting));
    }
}

/// The trip in progress and what its statistics need between frames.
struct Open {
    stats: TripStats,
    series: Downsampler,
    last_active_us: u64,
    last_powertrain_us: u64,
    last_frame_us: u64,
    speed: Option<(u64, f64)>,
    recent_speeds: VecDeque<(u64, f64)>,
    fuel_counter: Option<(u64, u16)>,
    abs: Interventions,
    diff: Interventions,
    cruise: Option<(u64, bool)>,
    engaged_gear: Option<Gear>,
    braking: bool,
    braking_counted: bool,
}

impl Open {
    fn new(t_us: u64) -> Self {
        Self {
            stats: TripStats {
                start_us: t_us,
                end_us: t_us,
                ..TripStats::default()
            },
            series: Downsampler::new(t_us),
            last_active_us: t_us,
            last_powertrain_us: t_us,
            last_frame_us: t_us,
            speed: None,
            recent_speeds: VecDeque::new(),
            fuel_counter: None,
            abs: Interventions::default(),
            diff: Interventions::default(),
            cruise: None,
            engaged_gear: None,
            braking: false,
            braking_counted: false,
        }
    }

    /// The statistics as they stand if the trip ended at `end_us`.
    fn stats_to(&self, end_us: u64) -> TripStats {
        let mut stats = self.stats.clone();
        stats.end_us = end_us.max(stats.start_us);
        stats.duration_s = (stats.end_us - stats.start_us) as f64 * 1e-6;
        stats.mean_speed_kmh = if stats.duration_s > 0.0 {
            stats.distance_m / stats.duration_s * 3.6
        } else {
            0.0
        };
        stats.abs_interventions = self.abs.count;
        stats.abs_time_s = self.abs.time_s;
        stats.diff_interventions = self.diff.count;
        stats.diff_time_s = self.diff.time_s;
        stats
    }

    fn on_speed(&mut self, t_us: u64, kmh: f64, state: &CarState) {
        if let Some(dt) = held_since::<VehicleSpeedMsg>(self.speed.map(|s| s.0), t_us) {
            let previous = self.speed.map_or(kmh, |s| s.1);
            self.stats.distance_m += (previous + kmh) / 2.0 / 3.6 * dt;
            if previous > 0.0 || kmh > 0.0 {
                self.stats.moving_time_s += dt;
            }
        }
        self.speed = Some((t_us, kmh));
        self.stats.max_speed_kmh = self.stats.max_speed_kmh.max(kmh);

        // Hard braking: the deceleration over the last half second while the brake is on.
        self.recent_speeds.push_back((t_us, kmh));
        while self
            .recent_speeds
            .get(1)
            .is_some_and(|(t, _)| t_us.saturating_sub(*t) >= DECELERATION_WINDOW_US)
        {
            self.recent_speeds.pop_front();
        }
        let brake_fresh = state
            .signal_of(PedalBrake::ID, 0)
            .is_some_and(|s| s.is_fresh(t_us));
        if self.braking && brake_fresh && !self.braking_counted {
            if let Some(&(t0, v0)) = self.recent_speeds.front() {
                let dt = t_us.saturating_sub(t0) as f64 * 1e-6;
                if t_us - t0 >= DECELERATION_WINDOW_US && (v0 - kmh) / 3.6 / dt >= HARD_BRAKING_MPS2
                {
                    self.stats.hard_brakings += 1;
                    self.braking_counted = true;
                }
            }
        }
    }

    fn on_fuel_counter(&mut self, t_us: u64, counter: u16) {
        if let Some((t0, previous)) = self.fuel_counter {
            let step = u64::from(counter.wrapping_sub(previous));
            let plausible = FUEL_FLOW_MAX_ML_PER_S * t_us.saturating_sub(t0) as f64 * 1e-6 + 50.0;
            // A step larger than the engine can burn: the ECU restarted, counting from 0.
            let ml = if step as f64 > plausible {
                u64::from(counter)
            } else {
                step
            };
            self.stats.fuel_used_l += ml as f64 * 1e-3;
        }
        self.fuel_counter = Some((t_us, counter));
    }
}

/// Finds trips in the traffic and keeps their statistics: an [`Observer`] of the pipeline.
pub struct TripTracker {
    open: Option<Open>,
    completed: Vec<CompletedTrip>,
    keep_series: bool,
}

impl Default for TripTracker {
    fn default() -> Self {
        Self::new()
    }
}

impl TripTracker {
    /// A tracker that has seen nothing, keeping each trip's series.
    pub fn new() -> Self {
        Self {
            open: None,
            completed: Vec::new(),
            keep_series: true,
        }
    }

    /// A tracker that keeps no series (nothing would store it): its memory then stays the
    /// same however long a trip lasts.
    pub fn without_series() -> Self {
        Self {
            keep_series: false,
            ..Self::new()
        }
    }

    /// The statistics of the trip in progress, up to the latest frame.
    pub fn current(&self) -> Option<TripStats> {
        self.open.as_ref().map(|o| o.stats_to(o.last_frame_us))
    }

    /// The series buckets of the trip in progress that are complete and not taken yet.
    pub fn take_series(&mut self) -> Vec<SeriesPoint> {
        self.open
            .as_mut()
            .map(|o| o.series.take_ready())
            .unwrap_or_default()
    }

    /// The trips that ended since the last call, in order.
    pub fn take_completed(&mut self) -> Vec<CompletedTrip> {
        std::mem::take(&mut self.completed)
    }

    /// The input ended (end of the log, the gateway stopping): the trip in progress ends.
    pub fn finish(&mut self) {
        if let Some(open) = self.open.as_ref() {
            let end_us = open.last_frame_us;
            self.close(TripEnd::EndOfInput, end_us);
        }
    }

    /// A live bus has been silent for [`SILENT_AFTER_US`] of wall time (no frame at all, so
    /// bus time stands still): the trip in progress ends as bus silent, as it would when
    /// the next frame showed the gap.
    pub fn bus_silent(&mut self) {
        if let Some(open) = self.open.as_ref() {
            let end_us = open.last_active_us;
            self.close(TripEnd::BusSilent, end_us);
        }
    }

    fn close(&mut self, end: TripEnd, end_us: u64) {
        if let Some(mut open) = self.open.take() {
            let stats = open.stats_to(end_us);
            let series = open.series.finish();
            self.completed.push(CompletedTrip { stats, end, series });
        }
    }
}

impl Observer for TripTracker {
    /// A source with a clock of its own (the virtual car, a live bus) tells the time while
    /// no frame comes: a silence of [`SILENT_AFTER_US`] ends the trip then, the same trip
    /// the next frame's gap would have ended.
    fn on_idle(&mut self, state: &CarState) {
        if let Some(open) = self.open.as_ref() {
            if state.now_us().saturating_sub(open.last_powertrain_us) >= SILENT_AFTER_US {
                let end_us = open.last_active_us;
                self.close(TripEnd::BusSilent, end_us);
            }
        }
    }

    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState) {
        let t = frame.t_us;
        if let Some(open) = self.open.as_ref() {
            if t.saturating_sub(open.last_powertrain_us) >= SILENT_AFTER_US {
                let end_us = open.last_active_us;
                self.close(TripEnd::BusSilent, end_us);
            }
        }
        let Update::Message { index, valid: true } = update else {
            return;
        };
        let id = MESSAGES[index].id;
        // Whether this frame shows the engine running or the car moving (None: it cannot).
        let activity = match id {
            EngineMsg::ID => {
                Some(f64::from(state.get::<EngineMsg>().engine_rpm) >= ENGINE_RUNNING_RPM)
            }
            VehicleSpeedMsg::ID => Some(state.get::<VehicleSpeedMsg>().vehicle_speed > 0.0),
            _ => None,
        };
        if self.open.is_none() {
            if activity != Some(true) {
                return;
            }
            self.open = Some(Open::new(t));
        }
        let Some(open) = self.open.as_mut() else {
            return;
        };
        open.last_frame_us = open.last_frame_us.max(t);
        if let Some(active) = activity {
            open.last_powertrain_us = t;
            if active {
                open.last_active_us = t;
            } else if t.saturating_sub(open.last_active_us) >= PARKED_AFTER_US {
                let end_us = open.last_active_us;
                self.close(TripEnd::Parked, end_us);
                return;
            }
        }
        if self.keep_series {
            open.series.add(t, index, state);
        }
        match id {
            VehicleSpeedMsg::ID => {
                let kmh = f64::from(state.get::<VehicleSpeedMsg>().vehicle_speed);
                open.on_speed(t, kmh, state);
            }
            EngineMsg::ID => {
                let counter = state.get::<EngineMsg>().fuel_used;
                open.on_fuel_counter(t, counter as u16);
            }
            PedalBrake::ID => {
                open.braking = state.get::<PedalBrake>().brake_cmd > 0.0;
                if !open.braking {
                    open.braking_counted = false;
                }
            }
            AbsMsg::ID => {
                let m = state.get::<AbsMsg>();
                let releasing = [
                    m.abs_release_fl,
                    m.abs_release_fr,
                    m.abs_release_rl,
                    m.abs_release_rr,
                ]
                .iter()
                .any(|r| *r > 0.0);
                open.abs.sample::<AbsMsg>(t, releasing, ABS_MERGE_GAP_US);
            }
            DiffMsg::ID => {
                let split = state.get::<DiffMsg>().torque_split;
                open.diff
                    .sample::<DiffMsg>(t, split != 0.0, DIFF_MERGE_GAP_US);
            }
            CruiseModeMsg::ID => {
                let on = state.get::<CruiseModeMsg>().cruise_mode == CruiseMode::On;
                if let Some((t0, was_on)) = open.cruise {
                    if was_on {
                        open.stats.cruise_time_s +=
                            held_since::<CruiseModeMsg>(Some(t0), t).unwrap_or(0.0);
                    }
                }
                open.cruise = Some((t, on));
            }
            TransMsg::ID => {
                let gear = state.get::<TransMsg>().gear;
                if gear != Gear::Neutral {
                    if open.engaged_gear.is_some_and(|g| g != gear) {
                        open.stats.shifts += 1;
                    }
                    open.engaged_gear = Some(gear);
                }
            }
            _ => {}
        }
    }
}
