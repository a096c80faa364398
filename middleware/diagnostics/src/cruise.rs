//! Cruise control (report scenario 1): does the speed hold the set speed?
//!
//! The routine watches CruiseModeMsg: when it turns On, it latches the vehicle speed the
//! bus shows 20 ms later (the cruise ECU latches its own reading after two 10 ms steps) as
//! the set speed, as the 2011 routine "saves the reference speed". From
//! [`SETTLE_S`] after engagement until cruise ends (Off, or CruiseModeMsg gone stale, which
//! disengages the ECU), every VehicleSpeedMsg adds `speed − set` to the engagement's error.
//! The number is the root-mean-square tracking error of the worst engagement that lasted
//! long enough to judge ([`MIN_EVIDENCE_S`] after settling).
//!
//! The bus carries speed in 1 km/h steps (the DBC's factor), and the ECU latches its own,
//! finer reading: the latched bus value may sit a whole step from the speed a perfect
//! controller then holds, which would show as a constant error of up to 1 km/h. A constant
//! offset within one step is therefore not counted: the error is taken about
//! `clamp(mean error, −1 step, +1 step)`. An oscillation, or an offset beyond one step,
//! counts in full.
//!
//! Thresholds, km/h rms: a perfect controller shows up to about 0.5 km/h (the speed
//! flickering between two steps); a correct controller on a 6 % grade stays under about
//! 0.6 km/h (scenario cruise-hold). The faulty bang-bang software of the report oscillates by
//! ±2–3 km/h, about 1.5 km/h rms. Suspect above [`SUSPECT_KMH`], faulty above
//! [`FAULTY_KMH`].

use autoplug_can::{CruiseMode, CruiseModeMsg, Node, VehicleSpeedMsg, MESSAGES};
use autoplug_gateway::{CarState, SignalName, Update};
use autoplug_logs::LogFrame;

use crate::{Finding, Routine, Verdict, Window};

/// The signals this routine reads on every relevant frame.
static CRUISE_MODE: SignalName = SignalName::new("CruiseModeMsg.CruiseMode");

/// Time after engagement before the error counts, s: the speed settles within it.
pub const SETTLE_S: f64 = 8.0;
/// Time after settling needed to judge an engagement, s.
pub const MIN_EVIDENCE_S: f64 = 5.0;
/// rms tracking error above which the ECU is suspect, km/h.
pub const SUSPECT_KMH: f64 = 0.8;
/// rms tracking error above which the ECU is faulty, km/h.
pub const FAULTY_KMH: f64 = 1.1;
/// The cruise ECU latches its set speed after this long, µs (two 10 ms steps).
const LATCH_DELAY_US: u64 = 20_000;
/// One step of VehicleSpeedMsg, km/h: how far the latched bus value may lie from the set
/// speed the ECU latched.
const SPEED_STEP_KMH: f64 = VehicleSpeedMsg::VEHICLE_SPEED.factor() as f64;

#[derive(Clone, Copy)]
struct Engagement {
    start_us: u64,
    set_kmh: Option<f64>,
    sum: f64,
    sum_sq: f64,
    samples: u64,
    max_abs: f64,
    first_us: u64,
    last_us: u64,
}

impl Engagement {
    fn judged_s(&self) -> f64 {
        (self.last_us.saturating_sub(self.first_us)) as f64 * 1e-6
    }

    /// The rms error about the latch's uncertainty: a constant offset up to one speed step
    /// is taken out, anything beyond counts.
    fn rms(&self) -> f64 {
        let n = self.samples.max(1) as f64;
        let mean = self.sum / n;
        let bias = mean.clamp(-SPEED_STEP_KMH, SPEED_STEP_KMH);
        (self.sum_sq / n - 2.0 * bias * mean + bias * bias)
            .max(0.0)
            .sqrt()
    }
}

/// The cruise routine.
#[derive(Default)]
pub struct Cruise {
    current: Option<Engagement>,
    worst: Option<Engagement>,
    engagements: u32,
}

impl Cruise {
    fn close(&mut self) {
        if let Some(e) = self.current.take() {
            if e.samples > 0
                && e.judged_s() >= MIN_EVIDENCE_S
                && self.worst.is_none_or(|w| e.rms() > w.rms())
            {
                self.worst = Some(e);
            }
        }
    }
}

impl Routine for Cruise {
    fn ecu(&self) -> Node {
        Node::Cruise
    }

    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState) {
        let Update::Message { index, .. } = update else {
            return;
        };
        let t = frame.t_us;
        match MESSAGES[index].id {
            CruiseModeMsg::ID => {
                let on = state.get::<CruiseModeMsg>().cruise_mode == CruiseMode::On;
                match (on, self.current.is_some()) {
                    (true, false) => {
                        self.engagements += 1;
                        self.current = Some(Engagement {
                            start_us: t,
                            set_kmh: None,
                            sum: 0.0,
                            sum_sq: 0.0,
                            samples: 0,
                            max_abs: 0.0,
                            first_us: 0,
                            last_us: 0,
                        });
                    }
                    (false, true) => self.close(),
                    _ => {}
                }
            }
            VehicleSpeedMsg::ID => {
                let mode_fresh = state
                    .signal_named(&CRUISE_MODE)
                    .is_some_and(|s| s.is_fresh(t));
                if self.current.is_some() && !mode_fresh {
                    // The cruise ECU disengages on a stale CruiseModeMsg.
                    self.close();
                    return;
                }
                let Some(e) = self.current.as_mut() else {
                    return;
                };
                let speed = f64::from(state.get::<VehicleSpeedMsg>().vehicle_speed);
                let Some(set) = e.set_kmh else {
                    if t >= e.start_us + LATCH_DELAY_US {
                        e.set_kmh = Some(speed);
                    }
                    return;
                };
                if (t.saturating_sub(e.start_us) as f64) < SETTLE_S * 1e6 {
                    return;
                }
                let error = speed - set;
                if e.samples == 0 {
                    e.first_us = t;
                }
                e.samples += 1;
                e.sum += error;
                e.sum_sq += error * error;
                e.max_abs = e.max_abs.max(error.abs());
                e.last_us = t;
            }
            _ => {}
        }
    }

    fn findings(&self, _state: &CarState) -> Vec<Finding> {
        let mut me = Cruise {
            current: self.current,
            worst: self.worst,
            engagements: self.engagements,
        };
        me.close();
        let finding = |verdict, value, window, evidence| Finding {
            routine: "tracking error",
            verdict,
            value,
            unit: "km/h rms",
            suspect_above: SUSPECT_KMH,
            faulty_above: FAULTY_KMH,
            window,
            evidence,
        };
        match me.worst {
            None => vec![finding(
                Verdict::NotExercised,
                None,
                None,
                format!(
                    "not exercised: {} engagement(s), none held {:.0} s ({SETTLE_S:.0} s settling + {MIN_EVIDENCE_S:.0} s)",
                    me.engagements,
                    SETTLE_S + MIN_EVIDENCE_S
                ),
            )],
            Some(e) => {
                let rms = e.rms();
                vec![finding(
                    Verdict::of(rms, SUSPECT_KMH, FAULTY_KMH),
                    Some(rms),
                    Some(Window {
                        from_us: e.first_us,
                        to_us: e.last_us,
                    }),
                    format!(
                        "speed against the set speed {:.0} km/h latched at {:.2} s: {:.2} km/h rms, up to {:.0} km/h off, over {:.1} s",
                        e.set_kmh.unwrap_or(0.0),
                        e.start_us as f64 * 1e-6,
                        rms,
                        e.max_abs,
                        e.judged_s()
                    ),
                )]
            }
        }
    }
}
