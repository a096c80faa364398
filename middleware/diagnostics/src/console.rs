//! Console: do the brake lights follow the brake?
//!
//! The console drives the brake lights from the brake command on PedalBrake, on above
//! `autoplug_ecu_params::console::BRAKE_LIGHTS_ON_PCT`, off at or below `BRAKE_LIGHTS_OFF_PCT` (in
//! between either is right), and reports them in AccMsg bit 1, sent at once on a change.
//! The routine compares AccMsg's brake lights with what PedalBrake asks for, while
//! PedalBrake is fresh (when it is stale the console's safe state is lights on, which is
//! right), and measures the longest continuous disagreement.
//!
//! Thresholds: the console steps every 10 ms and AccMsg goes out on a change no later than
//! its 5 ms minimum gap, so a working console agrees again within about 20 ms. Over
//! [`SUSPECT_S`] the drivers behind see a late light: suspect; over [`FAULTY_S`], faulty.

use autoplug_can::{AccMsg, Node, PedalBrake, MESSAGES};
use autoplug_ecu_params::console::{BRAKE_LIGHTS_OFF_PCT, BRAKE_LIGHTS_ON_PCT};
use autoplug_gateway::{CarState, SignalName, Update};
use autoplug_logs::LogFrame;

use crate::span::{LongestSpan, SpanRule};
use crate::{Finding, Routine};

/// The signals this routine reads on every relevant frame.
static BRAKE_LIGHTS: SignalName = SignalName::new("AccMsg.BrakeLights");
static BRAKE_CMD: SignalName = SignalName::new("PedalBrake.BrakeCmd");

/// Longest disagreement above which the console is suspect, s.
pub const SUSPECT_S: f64 = 0.1;
/// Longest disagreement above which the console is faulty, s.
pub const FAULTY_S: f64 = 0.3;

/// The console routine.
#[derive(Default)]
pub struct Console {
    disagreement: LongestSpan,
}

impl Routine for Console {
    fn ecu(&self) -> Node {
        Node::Console
    }

    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState) {
        let Update::Message { index, .. } = update else {
            return;
        };
        let id = MESSAGES[index].id;
        if id != PedalBrake::ID && id != AccMsg::ID {
            return;
        }
        let t = frame.t_us;
        let fresh = |name: &SignalName| state.signal_named(name).is_some_and(|s| s.is_fresh(t));
        let judged = fresh(&BRAKE_CMD) && fresh(&BRAKE_LIGHTS);
        let brake = state.get::<PedalBrake>().brake_cmd;
        let lights = state.get::<AccMsg>().brake_lights;
        let wrong =
            (brake > BRAKE_LIGHTS_ON_PCT && !lights) || (brake <= BRAKE_LIGHTS_OFF_PCT && lights);
        self.disagreement.observe(t, judged, wrong);
    }

    fn findings(&self, state: &CarState) -> Vec<Finding> {
        vec![SpanRule {
            routine: "brake lights against the brake",
            suspect_s: SUSPECT_S,
            faulty_s: FAULTY_S,
            broken: "brake lights disagreed with the brake command",
            unexercised: "PedalBrake and AccMsg never fresh together",
        }
        .finding(&self.disagreement, state.now_us())]
    }
}
