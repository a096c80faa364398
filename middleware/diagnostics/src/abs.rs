//! ABS (report scenario 2): do the wheels keep turning under hard braking?
//!
//! While the driver brakes (PedalBrake above [`BRAKING_PCT`]) above [`MIN_SPEED_KMH`], a
//! wheel whose speed (WheelSpeedMsg) falls below [`LOCK_FRACTION`] of the vehicle speed is
//! locked. The vehicle speed is VehicleSpeedMsg while it is fresh, else the fastest wheel
//! (what an ABS itself falls back to), so a silent cruise ECU does not blind the routine.
//! The number is the longest time one wheel stayed locked. The evidence also tells whether
//! the ABS released the locked wheel's brake (AbsMsg: applied brake below the driver's
//! command) and the largest yaw-rate error while braking (YawErrorMsg), the spin the
//! report's demonstration shows.
//!
//! Thresholds: a working ABS lets a wheel dip deep only for the tens of milliseconds of a
//! control cycle; 0.2 s is the longest lock allowed in the project's ABS sweep (`virtual-car abs-sweep`),
//! so a longer lock is suspect; [`FAULTY_S`] of lock is far beyond any control cycle (the
//! faulty software of the report never releases: its wheels stay locked to standstill).

use autoplug_can::{AbsMsg, Node, PedalBrake, WheelSpeedMsg, YawErrorMsg, MESSAGES};
use autoplug_gateway::{CarState, SignalName, Update};
use autoplug_logs::LogFrame;

use crate::{Finding, Routine, Verdict, Window};

/// The signals this routine reads on every relevant frame.
static BRAKE_CMD: SignalName = SignalName::new("PedalBrake.BrakeCmd");
static VEHICLE_SPEED: SignalName = SignalName::new("VehicleSpeedMsg.VehicleSpeed");

/// Brake command above which the driver is braking, %.
pub const BRAKING_PCT: f32 = 10.0;
/// Vehicle speed above which locks count, km/h.
pub const MIN_SPEED_KMH: f64 = 20.0;
/// A wheel below this fraction of the vehicle speed is locked.
pub const LOCK_FRACTION: f64 = 0.3;
/// Longest lock above which the ECU is suspect, s.
pub const SUSPECT_S: f64 = 0.2;
/// Longest lock above which the ECU is faulty, s.
pub const FAULTY_S: f64 = 0.5;

const WHEELS: [&str; 4] = ["front left", "front right", "rear left", "rear right"];

/// The ABS routine.
#[derive(Default)]
pub struct Abs {
    lock_since: [Option<u64>; 4],
    never_released: [bool; 4],
    longest: Option<(usize, Window, bool)>,
    braking_s: f64,
    last_braking_us: Option<u64>,
    peak_yaw_error: f64,
}

impl Abs {
    fn vehicle_speed(state: &CarState, t: u64, wheels: &[f64; 4]) -> f64 {
        match state.signal_named(&VEHICLE_SPEED) {
            Some(s) if s.is_fresh(t) => s.value,
            _ => wheels.iter().copied().fold(0.0, f64::max),
        }
    }

    fn end_lock(&mut self, wheel: usize, t: u64) {
        if let Some(since) = self.lock_since[wheel].take() {
            let len = t.saturating_sub(since);
            let longest = self.longest.map_or(0, |(_, w, _)| w.to_us - w.from_us);
            if len > longest {
                self.longest = Some((
                    wheel,
                    Window {
                        from_us: since,
                        to_us: t,
                    },
                    self.never_released[wheel],
                ));
            }
        }
    }
}

impl Routine for Abs {
    fn ecu(&self) -> Node {
        Node::ABS
    }

    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState) {
        let Update::Message { index, .. } = update else {
            return;
        };
        let t = frame.t_us;
        let id = MESSAGES[index].id;
        if id != WheelSpeedMsg::ID && id != AbsMsg::ID && id != YawErrorMsg::ID {
            return;
        }
        let brake = state.signal_named(&BRAKE_CMD);
        let braking_cmd = state.get::<PedalBrake>().brake_cmd;
        let w = state.get::<WheelSpeedMsg>();
        let wheels = [
            w.wheel_speed_fl,
            w.wheel_speed_fr,
            w.wheel_speed_rl,
            w.wheel_speed_rr,
        ]
        .map(f64::from);
        let v = Self::vehicle_speed(state, t, &wheels);
        let braking =
            brake.is_some_and(|b| b.is_fresh(t)) && braking_cmd > BRAKING_PCT && v > MIN_SPEED_KMH;
        match id {
            WheelSpeedMsg::ID => {
                if braking {
                    if let Some(last) = self.last_braking_us {
                        self.braking_s += t.saturating_sub(last).min(20_000) as f64 * 1e-6;
                    }
                    self.last_braking_us = Some(t);
                } else {
                    self.last_braking_us = None;
                }
                for (i, speed) in wheels.iter().enumerate() {
                    let locked = braking && *speed < LOCK_FRACTION * v;
                    match (locked, self.lock_since[i]) {
                        (true, None) => {
                            self.lock_since[i] = Some(t);
                            self.never_released[i] = true;
                        }
                        (false, Some(_)) => self.end_lock(i, t),
                        _ => {}
                    }
                }
            }
            AbsMsg::ID => {
                let a = state.get::<AbsMsg>();
                let applied = [a.brake_fl, a.brake_fr, a.brake_rl, a.brake_rr];
                for (i, b) in applied.iter().enumerate() {
                    if self.lock_since[i].is_some() && *b < braking_cmd {
                        self.never_released[i] = false;
                    }
                }
            }
            YawErrorMsg::ID if braking => {
                let e = f64::from(state.get::<YawErrorMsg>().yaw_rate_error).abs();
                self.peak_yaw_error = self.peak_yaw_error.max(e);
            }
            _ => {}
        }
    }

    fn findings(&self, state: &CarState) -> Vec<Finding> {
        let mut me = Abs {
            lock_since: self.lock_since,
            never_released: self.never_released,
            longest: self.longest,
            ..Abs::default()
        };
        for wheel in 0..4 {
            me.end_lock(wheel, state.now_us());
        }
        let finding = |verdict, value, window, evidence| Finding {
            routine: "longest wheel lock while braking",
            verdict,
            value,
            unit: "s",
            suspect_above: SUSPECT_S,
            faulty_above: FAULTY_S,
            window,
            evidence,
        };
        if self.braking_s == 0.0 {
            return vec![finding(
                Verdict::NotExercised,
                None,
                None,
                format!("not exercised: no braking above {BRAKING_PCT:.0} % from over {MIN_SPEED_KMH:.0} km/h"),
            )];
        }
        match me.longest {
            None => vec![finding(
                Verdict::Ok,
                Some(0.0),
                None,
                format!(
                    "no wheel locked in {:.1} s of braking; peak yaw-rate error while braking {:.2} rad/s",
                    self.braking_s, self.peak_yaw_error
                ),
            )],
            Some((wheel, window, never_released)) => {
                let s = (window.to_us - window.from_us) as f64 * 1e-6;
                vec![finding(
                    Verdict::of(s, SUSPECT_S, FAULTY_S),
                    Some(s),
                    Some(window),
                    format!(
                        "{} wheel below {:.0} % of the vehicle speed for {s:.2} s{}; peak yaw-rate error while braking {:.2} rad/s",
                        WHEELS[wheel],
                        LOCK_FRACTION * 100.0,
                        if never_released { ", its brake never released" } else { "" },
                        self.peak_yaw_error
                    ),
                )]
            }
        }
    }
}
