//! The engine ECU in the car: its logic as the image's software builds it, its sensors
//! from the vehicle model and the driver's controls, and its board's pins.

use autoplug_ecu::Instant;
use autoplug_image::SoftwareVariant;
use autoplug_ecus::engine::{EngineEcu, Sensors, Status};

use super::{Bench, Wiring};
use crate::driver::DriverControls;
use autoplug_vehicle::VehicleState;

impl Wiring for EngineEcu {
    fn make(_: SoftwareVariant, now: Instant) -> Self {
        Self::new(now)
    }

    fn sensors(s: &VehicleState, _: &DriverControls) -> Sensors {
        Sensors {
            engine_rpm: s.engine_rpm as f32,
            fuel_level_l: s.fuel_l as f32,
            fuel_flow_l_per_h: s.fuel_flow_l_per_h as f32,
        }
    }

    fn drive(s: &Sensors, bench: &mut Bench<'_>) {
        use autoplug_ecus::engine::pins::*;
        bench.analog(&ENGINE_SPEED, s.engine_rpm);
        bench.analog(&FUEL_LEVEL, s.fuel_level_l);
        bench.analog(&FUEL_FLOW, s.fuel_flow_l_per_h);
    }
    fn read(_: &Bench<'_>) -> Option<Status> {
        None // the engine ECU drives no pin: it reports on EngineMsg
    }
}
