//! Cabin comfort: does the fan push the cabin toward its set point?
//!
//! The cabin ECU cools (its fan blows air-conditioned air; there is no heater): with the
//! cabin (TempMsg) clearly warmer than the set point (TempRefMsg) the fan (FanMsg) must
//! run, and with the cabin clearly colder it must not run hard. "Clearly" is
//! [`MARGIN_F`]: past the sensor's noise and the 0.5 °F steps of the bus. The PID's
//! integral may keep the fan turning for a while after the cabin crosses the set point,
//! and a cabin takes minutes to respond, so the rule is judged over long stretches: the
//! number is the longest time the fan worked against the error (off, below
//! [`FAN_OFF_PCT`], while too warm; or above [`FAN_HARD_PCT`] while too cold).
//! Suspect above [`SUSPECT_S`], faulty above [`FAULTY_S`].

use autoplug_can::{FanMsg, Node, TempMsg, TempRefMsg, MESSAGES};
use autoplug_gateway::{CarState, SignalName, Update};
use autoplug_logs::LogFrame;

use crate::span::{LongestSpan, SpanRule};
use crate::{Finding, Routine};

/// The signals this routine reads on every relevant frame.
static CABIN_TEMP: SignalName = SignalName::new("TempMsg.CabinTemp");
static CABIN_SET_TEMP: SignalName = SignalName::new("TempRefMsg.CabinSetTemp");

/// Temperature difference that counts as clearly warmer or colder, °F.
pub const MARGIN_F: f32 = 2.0;
/// Fan power below which the fan counts as off, %.
pub const FAN_OFF_PCT: f32 = 1.0;
/// Fan power above which the fan counts as working hard, %.
pub const FAN_HARD_PCT: f32 = 20.0;
/// Longest contrary stretch above which the cabin ECU is suspect, s.
pub const SUSPECT_S: f64 = 30.0;
/// Longest contrary stretch above which the cabin ECU is faulty, s.
pub const FAULTY_S: f64 = 120.0;

/// The cabin routine.
#[derive(Default)]
pub struct Cabin {
    contrary: LongestSpan,
}

impl Routine for Cabin {
    fn ecu(&self) -> Node {
        Node::Cabin
    }

    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState) {
        let Update::Message { index, .. } = update else {
            return;
        };
        if MESSAGES[index].id != FanMsg::ID {
            return;
        }
        let t = frame.t_us;
        let fresh = |name: &SignalName| state.signal_named(name).is_some_and(|s| s.is_fresh(t));
        let judged = fresh(&CABIN_TEMP) && fresh(&CABIN_SET_TEMP);
        let error = state.get::<TempMsg>().cabin_temp - state.get::<TempRefMsg>().cabin_set_temp;
        let fan = state.get::<FanMsg>().fan_power;
        let contrary =
            (error > MARGIN_F && fan < FAN_OFF_PCT) || (error < -MARGIN_F && fan > FAN_HARD_PCT);
        self.contrary.observe(t, judged, contrary);
    }

    fn findings(&self, state: &CarState) -> Vec<Finding> {
        vec![SpanRule {
            routine: "fan against the temperature error",
            suspect_s: SUSPECT_S,
            faulty_s: FAULTY_S,
            broken: "the fan worked against the temperature error",
            unexercised: "TempMsg, TempRefMsg and FanMsg never fresh together",
        }
        .finding(&self.contrary, state.now_us())]
    }
}
