//! Differential (active yaw control): is the torque split where the rules put it?
//!
//! Two rules of the differential ECU can be judged from the bus, each while its inputs are
//! fresh:
//!
//! - **Hold.** Below `autoplug_ecu_params::diff::MIN_SPEED_KMH` (VehicleSpeedMsg), with less than
//!   `MIN_STEERING_DEG` of steering (SteeringMsg), or with any applied brake above
//!   `BRAKE_HOLD_PCT` (AbsMsg), the split must be 0: an open differential that keeps out
//!   of the way of braking and ABS. The bus quantises speed to 1 km/h, steering to
//!   3.375° and brakes to 1 %; the rule is applied one quantum inside each limit, so a
//!   value at the edge is never held against the ECU.
//! - **Direction.** A split larger than [`ACTIVE_NM`] while the yaw-rate error is beyond
//!   the ECU's dead band must push the way the error asks (a positive error, the car
//!   yawing less counter-clockwise than it should, wants a positive split: more torque to
//!   the right rear wheel).
//!
//! The number is the longest violation of either rule. Thresholds: the ECU reacts within
//! its 10 ms step and its inputs arrive every 10 ms, and its PID may lag a zero crossing
//! of the error by a few steps; [`SUSPECT_S`] is several times that, [`FAULTY_S`] a rule
//! plainly not applied.

use autoplug_can::{AbsMsg, DiffMsg, Node, SteeringMsg, VehicleSpeedMsg, YawErrorMsg, MESSAGES};
use autoplug_ecu_params::diff::{
    BRAKE_HOLD_PCT, MIN_SPEED_KMH, MIN_STEERING_DEG, YAW_DEAD_BAND_RAD_S,
};
use autoplug_gateway::{CarState, SignalName, Update};
use autoplug_logs::LogFrame;

use crate::span::{LongestSpan, SpanRule};
use crate::{Finding, Routine};

/// The signals this routine reads on every relevant frame.
static BRAKE_FL: SignalName = SignalName::new("AbsMsg.BrakeFL");
static TORQUE_SPLIT: SignalName = SignalName::new("DiffMsg.TorqueSplit");
static STEERING_ANGLE: SignalName = SignalName::new("SteeringMsg.SteeringAngle");
static VEHICLE_SPEED: SignalName = SignalName::new("VehicleSpeedMsg.VehicleSpeed");
static YAW_RATE_ERROR: SignalName = SignalName::new("YawErrorMsg.YawRateError");

/// Longest violation above which the differential ECU is suspect, s.
pub const SUSPECT_S: f64 = 0.2;
/// Longest violation above which the differential ECU is faulty, s.
pub const FAULTY_S: f64 = 1.0;
/// A split at least this large counts as active, N·m.
pub const ACTIVE_NM: f32 = 5.0;
/// One quantum of VehicleSpeedMsg, SteeringMsg and AbsMsg.
const SPEED_STEP_KMH: f32 = 1.0;
const STEERING_STEP_DEG: f32 = 3.375;
const BRAKE_STEP_PCT: f32 = 1.0;

/// The differential routine.
#[derive(Default)]
pub struct Differential {
    hold: LongestSpan,
    direction: LongestSpan,
}

impl Routine for Differential {
    fn ecu(&self) -> Node {
        Node::Differential
    }

    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState) {
        let Update::Message { index, .. } = update else {
            return;
        };
        let id = MESSAGES[index].id;
        if ![DiffMsg::ID, YawErrorMsg::ID].contains(&id) {
            return;
        }
        let t = frame.t_us;
        let fresh = |name: &SignalName| state.signal_named(name).is_some_and(|s| s.is_fresh(t));
        let split = state.get::<DiffMsg>().torque_split;
        let speed = state.get::<VehicleSpeedMsg>().vehicle_speed;
        let steering = state.get::<SteeringMsg>().steering_angle.abs();
        let a = state.get::<AbsMsg>();
        let brake = a.brake_fl.max(a.brake_fr).max(a.brake_rl).max(a.brake_rr);
        let inputs = fresh(&TORQUE_SPLIT)
            && fresh(&VEHICLE_SPEED)
            && fresh(&STEERING_ANGLE)
            && fresh(&BRAKE_FL);
        let must_hold = speed < MIN_SPEED_KMH - SPEED_STEP_KMH
            || steering < MIN_STEERING_DEG - STEERING_STEP_DEG
            || brake > BRAKE_HOLD_PCT + BRAKE_STEP_PCT;
        self.hold.observe(t, inputs && must_hold, split != 0.0);
        let error = state.get::<YawErrorMsg>().yaw_rate_error;
        let judged = fresh(&TORQUE_SPLIT)
            && fresh(&YAW_RATE_ERROR)
            && split.abs() >= ACTIVE_NM
            && error.abs() > YAW_DEAD_BAND_RAD_S;
        self.direction
            .observe(t, judged, split.signum() != error.signum());
    }

    fn findings(&self, state: &CarState) -> Vec<Finding> {
        let now = state.now_us();
        vec![
            SpanRule {
                routine: "torque split 0 when it must hold",
                suspect_s: SUSPECT_S,
                faulty_s: FAULTY_S,
                broken: "a torque split while too slow, steering too little or braking",
                unexercised: "never in a hold condition with its inputs on the bus",
            }
            .finding(&self.hold, now),
            SpanRule {
                routine: "torque split against the yaw-rate error",
                suspect_s: SUSPECT_S,
                faulty_s: FAULTY_S,
                broken: "a torque split pushing against the yaw-rate error",
                unexercised: "never an active split with a yaw-rate error beyond the dead band",
            }
            .finding(&self.direction, now),
        ]
    }
}
