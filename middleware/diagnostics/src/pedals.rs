//! Pedals: do the commands follow the rules?
//!
//! The driver's pedals are not on the bus, but two of the pedals ECU's rules can be judged
//! from what is:
//!
//! - **Brake override.** A brake command above `autoplug_ecu_params::pedals::PEDAL_PRESSED_THRESHOLD`
//!   forces the accelerator command to 0 (PedalBrake against PedalAccel).
//! - **Cruise command.** While cruise is on (CruiseModeMsg) and its command is known
//!   (CruiseAccelMsg fresh), the commands are the cruise command's: accelerator =
//!   command × (1 − traction cut) when positive, brake = −command when negative. A
//!   driver's pedal press overrides this but cancels cruise in the same step, so a
//!   disagreement that lasts while cruise stays on breaks the rule.
//!
//! Each rule is judged only while its inputs are fresh. The number is the longest
//! continuous violation. Thresholds: the commands follow their inputs within one 10 ms
//! step after the 20 ms CruiseAccelMsg arrives, and the cancel of a pedal press reaches
//! the bus within a few milliseconds; [`SUSPECT_S`] leaves room for both, several times
//! over; [`FAULTY_S`] is a rule plainly not applied. A command within [`TOLERANCE_PCT`]
//! of the expected value (rounding to the bus's 1 % steps, traction cut applied to a
//! value already rounded) agrees.

use autoplug_can::{
    CruiseAccelMsg, CruiseMode, CruiseModeMsg, Node, PedalAccel, PedalBrake, TracMsg, MESSAGES,
};
use autoplug_ecu_params::pedals::PEDAL_PRESSED_THRESHOLD;
use autoplug_gateway::{CarState, SignalName, Update};
use autoplug_logs::LogFrame;

use crate::span::{LongestSpan, SpanRule};
use crate::{Finding, Routine};

/// The signals this routine reads on every relevant frame.
static CRUISE_ACCEL: SignalName = SignalName::new("CruiseAccelMsg.CruiseAccel");
static CRUISE_MODE: SignalName = SignalName::new("CruiseModeMsg.CruiseMode");
static ACCEL_CMD: SignalName = SignalName::new("PedalAccel.AccelCmd");
static BRAKE_CMD: SignalName = SignalName::new("PedalBrake.BrakeCmd");
static TRACTION_CUT: SignalName = SignalName::new("TracMsg.TractionCut");

/// Longest violation above which the pedals ECU is suspect, s.
pub const SUSPECT_S: f64 = 0.1;
/// Longest violation above which the pedals ECU is faulty, s.
pub const FAULTY_S: f64 = 0.5;
/// Difference from the expected command still taken as agreement, %.
pub const TOLERANCE_PCT: f32 = 2.0;

/// The pedals routine.
#[derive(Default)]
pub struct Pedals {
    override_rule: LongestSpan,
    cruise_rule: LongestSpan,
}

impl Routine for Pedals {
    fn ecu(&self) -> Node {
        Node::Pedals
    }

    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState) {
        let Update::Message { index, .. } = update else {
            return;
        };
        let id = MESSAGES[index].id;
        if ![
            PedalAccel::ID,
            PedalBrake::ID,
            CruiseAccelMsg::ID,
            CruiseModeMsg::ID,
        ]
        .contains(&id)
        {
            return;
        }
        let t = frame.t_us;
        let fresh = |name: &SignalName| state.signal_named(name).is_some_and(|s| s.is_fresh(t));
        let accel = state.get::<PedalAccel>().accel_cmd;
        let brake = state.get::<PedalBrake>().brake_cmd;
        let commands_fresh = fresh(&ACCEL_CMD) && fresh(&BRAKE_CMD);
        self.override_rule.observe(
            t,
            commands_fresh,
            brake > PEDAL_PRESSED_THRESHOLD && accel > TOLERANCE_PCT,
        );
        let cruise_on =
            fresh(&CRUISE_MODE) && state.get::<CruiseModeMsg>().cruise_mode == CruiseMode::On;
        let judged = commands_fresh && cruise_on && fresh(&CRUISE_ACCEL);
        let command = state.get::<CruiseAccelMsg>().cruise_accel;
        let cut = if fresh(&TRACTION_CUT) {
            state.get::<TracMsg>().traction_cut
        } else {
            0.0
        };
        let (want_accel, want_brake) = if command >= 0.0 {
            (command * (1.0 - cut / 100.0), 0.0)
        } else {
            (0.0, -command)
        };
        let violated = (accel - want_accel).abs() > TOLERANCE_PCT
            || (brake - want_brake).abs() > TOLERANCE_PCT;
        self.cruise_rule.observe(t, judged, violated);
    }

    fn findings(&self, state: &CarState) -> Vec<Finding> {
        let now = state.now_us();
        vec![
            SpanRule {
                routine: "brake override of the accelerator",
                suspect_s: SUSPECT_S,
                faulty_s: FAULTY_S,
                broken: "accelerator command above 0 while the brake command was pressed",
                unexercised: "PedalAccel and PedalBrake never fresh together",
            }
            .finding(&self.override_rule, now),
            SpanRule {
                routine: "commands follow the cruise command",
                suspect_s: SUSPECT_S,
                faulty_s: FAULTY_S,
                broken: "commands differed from the cruise command while cruise stayed on",
                unexercised: "cruise never on with its command on the bus",
            }
            .finding(&self.cruise_rule, now),
        ]
    }
}
