//! Transmission: is the gear where the shift schedule puts it, without hunting?
//!
//! - **Schedule.** In automatic (TransMsg shift mode), not braking, in a forward gear, the
//!   road speed (VehicleSpeedMsg) must lie inside the gear's band of the schedule of the
//!   engine mode in force (EngineMsg; economy while it is missing, as the ECU does):
//!   not above the upshift speed out of the gear, not below the downshift speed out of it,
//!   each widened by [`BAND_MARGIN_KMH`] for the bus's 1 km/h steps and the time a shift
//!   takes. The gearbox shifts one gear per `autoplug_ecu_params::trans::SHIFT_TIMEOUT_US` (0.8 s), so a
//!   mode change or a return to automatic may leave it out of band for a few shifts:
//!   suspect above [`BAND_SUSPECT_S`], faulty above [`BAND_FAULTY_S`]. Under braking the
//!   gearbox steps down behind the speed by design and is not judged.
//! - **Shifts.** A change of engaged gear (the pass through neutral is not a shift) less
//!   than 3/4 of the shift timeout after the previous one, or a reversal (up then down or
//!   down then up) within [`HUNTING_S`] in automatic with no paddle request, no braking
//!   and no change of engine or shift mode in between, is counted. A gearbox with hysteresis never hunts: one is
//!   suspect, more than [`SHIFTS_FAULTY`] faulty.

use autoplug_can::{
    EngineMode, EngineMsg, Gear, Node, PedalBrake, ShiftMode, ShiftMsg, ShiftRequest, TransMsg,
    VehicleSpeedMsg, MESSAGES,
};
use autoplug_ecu_params::trans::SHIFT_TIMEOUT_US;
use autoplug_gateway::{CarState, SignalName, Update};
use autoplug_logs::LogFrame;

use crate::span::{LongestSpan, SpanRule};
use crate::{Finding, Routine, Verdict, Window};

/// The signals this routine reads on every relevant frame.
static ENGINE_MODE: SignalName = SignalName::new("EngineMsg.EngineMode");
static BRAKE_CMD: SignalName = SignalName::new("PedalBrake.BrakeCmd");
static GEAR: SignalName = SignalName::new("TransMsg.Gear");
static VEHICLE_SPEED: SignalName = SignalName::new("VehicleSpeedMsg.VehicleSpeed");

/// Widening of each gear's band, km/h.
pub const BAND_MARGIN_KMH: f32 = 3.0;
/// Longest stretch out of band above which the ECU is suspect, s.
pub const BAND_SUSPECT_S: f64 = 3.0;
/// Longest stretch out of band above which the ECU is faulty, s.
pub const BAND_FAULTY_S: f64 = 6.0;
/// A reversal within this time is hunting, s.
pub const HUNTING_S: f64 = 3.0;
/// Bad shifts above which the ECU is faulty.
pub const SHIFTS_FAULTY: f64 = 2.0;
/// How long before a shift begins on the bus the ECU decided it: its inputs' period and
/// its own step, µs.
const STEP_LEAD_US: u64 = 40_000;
/// Brake command above which the driver is braking, %.
const BRAKING_PCT: f32 = 5.0;

fn forward(gear: Gear) -> Option<i32> {
    match gear {
        Gear::Reverse | Gear::Neutral => None,
        g => Some(g.raw() as i32 - 1),
    }
}

/// The transmission routine.
#[derive(Default)]
pub struct Transmission {
    out_of_band: LongestSpan,
    /// The last engaged gear (reverse -1, forward 1..6) and when it engaged (`None` for
    /// the gear found engaged when the log began).
    engaged: Option<(i32, Option<u64>)>,
    /// The engine mode and shift mode last seen: a change excuses a reversal.
    modes: Option<(EngineMode, ShiftMode)>,
    /// The last shift's direction (+1 up, -1 down), when it began (the engaged gear left
    /// for neutral, or changed) and when it ended (the new gear engaged).
    last_shift: Option<(i32, u64, u64)>,
    /// When the engaged gear was last left for neutral.
    left_at: Option<u64>,
    /// When the engine or shift mode last changed.
    mode_changed_at: Option<u64>,
    /// A paddle request or braking since the last shift.
    excused: bool,
    bad_shifts: u64,
    first_bad: Option<(Window, &'static str)>,
}

impl Transmission {
    fn bad(&mut self, from_us: u64, to_us: u64, what: &'static str) {
        self.bad_shifts += 1;
        self.first_bad
            .get_or_insert((Window { from_us, to_us }, what));
    }
}

impl Routine for Transmission {
    fn ecu(&self) -> Node {
        Node::Transmission
    }

    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState) {
        let Update::Message { index, .. } = update else {
            return;
        };
        let t = frame.t_us;
        let fresh = |name: &SignalName| state.signal_named(name).is_some_and(|s| s.is_fresh(t));
        let braking = fresh(&BRAKE_CMD) && state.get::<PedalBrake>().brake_cmd > BRAKING_PCT;
        match MESSAGES[index].id {
            ShiftMsg::ID if state.get::<ShiftMsg>().shift_request != ShiftRequest::None => {
                self.excused = true;
            }
            PedalBrake::ID if braking => self.excused = true,
            TransMsg::ID => {
                let trans = state.get::<TransMsg>();
                let automatic = trans.shift_mode == ShiftMode::Automatic;
                // Shifts: changes of engaged gear.
                let gear = match trans.gear {
                    Gear::Neutral => {
                        if self.left_at.is_none() && self.engaged.is_some() {
                            self.left_at = Some(t);
                        }
                        None
                    }
                    Gear::Reverse => Some(-1),
                    g => forward(g),
                };
                if let Some(gear) = gear {
                    match self.engaged {
                        Some((last, since)) if last != gear => {
                            if let Some(since) =
                                since.filter(|s| t.saturating_sub(*s) < SHIFT_TIMEOUT_US * 3 / 4)
                            {
                                self.bad(since, t, "two shifts closer than the shift timeout");
                            }
                            let direction = (gear - last).signum();
                            let began = self.left_at.take().unwrap_or(t);
                            if let Some((previous, previous_began, at)) = self.last_shift {
                                // The ECU decided the previous shift a step before it
                                // began; a mode change since then excuses a reversal.
                                let mode_changed = self
                                    .mode_changed_at
                                    .is_some_and(|m| m + STEP_LEAD_US >= previous_began);
                                if automatic
                                    && !self.excused
                                    && !mode_changed
                                    && previous == -direction
                                    && (t.saturating_sub(at) as f64) < HUNTING_S * 1e6
                                {
                                    self.bad(at, t, "hunting: a shift reversed within 3 s");
                                }
                            }
                            self.last_shift = Some((direction, began, t));
                            self.excused = false;
                            self.engaged = Some((gear, Some(t)));
                        }
                        None => self.engaged = Some((gear, None)),
                        Some(_) => self.left_at = None,
                    }
                }
                // Schedule band.
                let judged = automatic && !braking && fresh(&GEAR) && fresh(&VEHICLE_SPEED);
                let mode = if fresh(&ENGINE_MODE) {
                    state.get::<EngineMsg>().engine_mode
                } else {
                    EngineMode::Economy
                };
                // A new schedule or a return to automatic may reverse a shift by design.
                if self.modes.is_some_and(|m| m != (mode, trans.shift_mode)) {
                    self.mode_changed_at = Some(t);
                }
                self.modes = Some((mode, trans.shift_mode));
                let schedule = autoplug_ecu_params::trans::schedule(mode);
                let speed = state.get::<VehicleSpeedMsg>().vehicle_speed;
                let out = forward(trans.gear).is_some()
                    && (schedule
                        .upshift_speed(trans.gear)
                        .is_some_and(|up| speed > up + BAND_MARGIN_KMH)
                        || schedule
                            .downshift_speed(trans.gear)
                            .is_some_and(|down| speed < down - BAND_MARGIN_KMH));
                self.out_of_band
                    .observe(t, judged && forward(trans.gear).is_some(), out);
            }
            _ => {}
        }
    }

    fn findings(&self, state: &CarState) -> Vec<Finding> {
        let schedule = SpanRule {
            routine: "gear against the shift schedule",
            suspect_s: BAND_SUSPECT_S,
            faulty_s: BAND_FAULTY_S,
            broken: "out of the schedule's band",
            unexercised: "never in automatic in a forward gear without braking",
        }
        .finding(&self.out_of_band, state.now_us());
        let shifts = Finding {
            routine: "shift rate and hunting",
            verdict: Verdict::of(self.bad_shifts as f64, 0.0, SHIFTS_FAULTY),
            value: Some(self.bad_shifts as f64),
            unit: "shifts",
            suspect_above: 0.0,
            faulty_above: SHIFTS_FAULTY,
            window: self.first_bad.map(|(w, _)| w),
            evidence: match self.first_bad {
                None => "no shift too soon after another, no hunting".into(),
                Some((w, what)) => format!(
                    "{} bad shift(s), the first at {:.2} s: {what}",
                    self.bad_shifts,
                    w.to_us as f64 * 1e-6
                ),
            },
        };
        vec![schedule, shifts]
    }
}
