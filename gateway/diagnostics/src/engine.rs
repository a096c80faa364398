//! Engine: does the fuel level only go down while driving?
//!
//! **Fuel never rising while driving.** The fuel level (EngineMsg, 0.25 L steps) may only
//! fall while the car moves (VehicleSpeedMsg above 5 km/h; refuelling happens at a
//! standstill). The largest rise above the lowest level seen since the car last stood is
//! reported; one step of quantisation is tolerated (suspect above [`FUEL_SUSPECT_L`],
//! faulty above [`FUEL_FAULTY_L`]).

use autoplug_can::{EngineMsg, Node, VehicleSpeedMsg, MESSAGES};
use autoplug_gateway::{CarState, SignalName, Update};
use autoplug_logs::LogFrame;

use crate::{Finding, Routine, Verdict, Window};

/// The signals this routine reads on every relevant frame.
static VEHICLE_SPEED: SignalName = SignalName::new("VehicleSpeedMsg.VehicleSpeed");

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
        if MESSAGES[index].id != EngineMsg::ID {
            return;
        }
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

    fn findings(&self, _state: &CarState) -> Vec<Finding> {
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
        vec![fuel]
    }
}
