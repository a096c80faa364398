//! Engine: does its RPM agree with the car's speed in the engaged gear, and does the fuel
//! level only go down while driving?
//!
//! **RPM against speed and gear.** With a forward gear engaged and the clutch closed, the
//! engine turns at the speed the road gives through the gear: vehicle speed (the cruise
//! ECU's VehicleSpeedMsg) × gear ratio (the transmission's TransMsg, with the ratios the
//! transmission ECU publishes, [`autoplug_ecu_params::trans::engine_rpm_at`]). The routine measures the
//! longest stretch the engine's RPM (EngineMsg) is more than [`RPM_TOLERANCE`] off that,
//! judged only where the automated clutch is closed: the gear engaged for
//! [`AFTER_SHIFT_US`] (it closes within 0.2 s of a shift), no braking for
//! [`AFTER_BRAKING_US`] (it opens under hard braking and closes after a hold), and the
//! road speed worth at least [`MIN_JUDGED_RPM`] in the gear (below, a launch slips the
//! clutch on purpose). On correct software the longest such stretch on the shipped
//! scenarios is under 1 s (a slow launch in 1st); an RPM sensor stuck, scaled wrong or
//! lagging shows at once and stays: suspect above [`RPM_SUSPECT_S`], faulty above
//! [`RPM_FAULTY_S`]. The tolerance covers the RPM signal's 35 rpm steps, the speed's 1 km/h
//! steps and tyre slip under full throttle.
//!
//! **Fuel never rising while driving.** The fuel level (EngineMsg, 0.25 L steps) may only
//! fall while the car moves (VehicleSpeedMsg above 5 km/h; refuelling happens at a
//! standstill). The largest rise above the lowest level seen since the car last stood is
//! reported; one step of quantisation is tolerated (suspect above [`FUEL_SUSPECT_L`],
//! faulty above [`FUEL_FAULTY_L`]).

use autoplug_can::{EngineMsg, Gear, Node, PedalBrake, TransMsg, VehicleSpeedMsg, MESSAGES};
use autoplug_gateway::{CarState, SignalName, Update};
use autoplug_logs::LogFrame;

use crate::span::{LongestSpan, SpanRule};
use crate::{Finding, Routine, Verdict, Window};

/// The signals this routine reads on every relevant frame.
static VEHICLE_SPEED: SignalName = SignalName::new("VehicleSpeedMsg.VehicleSpeed");
static GEAR: SignalName = SignalName::new("TransMsg.Gear");
static BRAKE_CMD: SignalName = SignalName::new("PedalBrake.BrakeCmd");

/// Relative difference between RPM and road speed × gear beyond which they disagree.
pub const RPM_TOLERANCE: f64 = 0.15;
/// Disagreeing longer than this: suspect, s.
pub const RPM_SUSPECT_S: f64 = 2.0;
/// Disagreeing longer than this: faulty, s.
pub const RPM_FAULTY_S: f64 = 5.0;
/// Judged from this long after a gear change on, µs.
pub const AFTER_SHIFT_US: u64 = 1_000_000;
/// Judged from this long after the brake was last pressed on, µs.
pub const AFTER_BRAKING_US: u64 = 3_000_000;
/// Judged where the road speed is worth at least this in the gear, rpm.
pub const MIN_JUDGED_RPM: f32 = 1500.0;

const RPM_RULE: SpanRule = SpanRule {
    routine: "RPM against speed and gear",
    suspect_s: RPM_SUSPECT_S,
    faulty_s: RPM_FAULTY_S,
    broken: "engine RPM more than 15 % off speed x gear ratio",
    unexercised: "never a forward gear, the clutch closed and the speed above 1500 rpm in it",
};

/// Fuel rise while driving above which the engine is suspect, L.
pub const FUEL_SUSPECT_L: f64 = 0.25;
/// Fuel rise while driving above which the engine is faulty, L.
pub const FUEL_FAULTY_L: f64 = 1.0;
/// Moving above this, km/h.
const MOVING_KMH: f32 = 5.0;

/// The engine routine.
#[derive(Default)]
pub struct Engine {
    lowest_fuel: Option<f64>,
    fuel_rise: f64,
    fuel_rise_at: Option<Window>,
    gear: Option<(Gear, u64)>,
    last_braking_us: Option<u64>,
    rpm: LongestSpan,
}

impl Engine {
    /// Whether RPM and road speed in the gear can be compared at `t`, and whether they
    /// disagree.
    fn rpm_against_gear(&self, t: u64, state: &CarState) -> (bool, bool) {
        let fresh = |name: &SignalName| state.signal_named(name).is_some_and(|s| s.is_fresh(t));
        if !(fresh(&VEHICLE_SPEED) && fresh(&GEAR) && fresh(&BRAKE_CMD)) {
            return (false, false);
        }
        let Some((gear, since)) = self.gear else {
            return (false, false);
        };
        let Some(ratio) =
            autoplug_ecu_params::trans::gear_ratio(gear).filter(|_| gear != Gear::Reverse)
        else {
            return (false, false);
        };
        let settled = t.saturating_sub(since) >= AFTER_SHIFT_US
            && self
                .last_braking_us
                .is_none_or(|b| t.saturating_sub(b) >= AFTER_BRAKING_US);
        let expected = autoplug_ecu_params::trans::engine_rpm_at(
            state.get::<VehicleSpeedMsg>().vehicle_speed,
            ratio,
        );
        if !settled || expected < MIN_JUDGED_RPM {
            return (false, false);
        }
        let rpm = f64::from(state.get::<EngineMsg>().engine_rpm);
        let expected = f64::from(expected);
        (true, (rpm - expected).abs() > RPM_TOLERANCE * expected)
    }
}

impl Routine for Engine {
    fn ecu(&self) -> Node {
        Node::Engine
    }

    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState) {
        let Update::Message { index, .. } = update else {
            return;
        };
        let t = frame.t_us;
        match MESSAGES[index].id {
            TransMsg::ID => {
                let gear = state.get::<TransMsg>().gear;
                if self.gear.is_none_or(|(g, _)| g != gear) {
                    self.gear = Some((gear, t));
                }
                return;
            }
            PedalBrake::ID => {
                if state.get::<PedalBrake>().brake_cmd > 0.0 {
                    self.last_braking_us = Some(t);
                }
                return;
            }
            EngineMsg::ID => {}
            _ => return,
        }
        let (judged, disagrees) = self.rpm_against_gear(t, state);
        self.rpm.observe(t, judged, disagrees);
        let fresh = |name: &SignalName| state.signal_named(name).is_some_and(|s| s.is_fresh(t));
        if !fresh(&VEHICLE_SPEED) {
            self.lowest_fuel = None;
            return;
        }
        let engine = state.get::<EngineMsg>();
        let speed = state.get::<VehicleSpeedMsg>().vehicle_speed;
        // Fuel: only while moving, from the lowest level since the last stop.
        let fuel = f64::from(engine.fuel_level);
        if speed > MOVING_KMH {
            let lowest = *self.lowest_fuel.get_or_insert(fuel);
            if fuel - lowest > self.fuel_rise {
                self.fuel_rise = fuel - lowest;
                self.fuel_rise_at = Some(Window {
                    from_us: t,
                    to_us: t,
                });
            }
            self.lowest_fuel = Some(lowest.min(fuel));
        } else {
            self.lowest_fuel = None;
        }
    }

    fn findings(&self, state: &CarState) -> Vec<Finding> {
        let fuel = Finding {
            routine: "fuel level never rising while driving",
            verdict: Verdict::of(self.fuel_rise, FUEL_SUSPECT_L, FUEL_FAULTY_L),
            value: Some(self.fuel_rise),
            unit: "L",
            suspect_above: FUEL_SUSPECT_L,
            faulty_above: FUEL_FAULTY_L,
            window: self.fuel_rise_at,
            evidence: if self.fuel_rise > 0.0 {
                format!("fuel rose {:.2} L while driving", self.fuel_rise)
            } else {
                "fuel never rose while driving".into()
            },
        };
        vec![RPM_RULE.finding(&self.rpm, state.now_us()), fuel]
    }
}
