//! The cruise control ECU in the car: its logic as the image's software builds it, its sensors
//! from the vehicle model and the driver's controls, and its board's pins.

use autoplug_ecu::Instant;
use autoplug_image::SoftwareVariant;
use autoplug_ecus::cruise::{CruiseEcu, Sensors, Status};

use super::{Bench, Wiring, variant};
use crate::driver::DriverControls;
use autoplug_vehicle::VehicleState;

impl Wiring for CruiseEcu {
    fn make(software: SoftwareVariant, now: Instant) -> Self {
        Self::new(variant(software), now)
    }

    fn sensors(s: &VehicleState, _: &DriverControls) -> Sensors {
        Sensors {
            vehicle_speed_kmh: s.speed_kmh(),
        }
    }

    fn drive(s: &Sensors, bench: &mut Bench<'_>) {
        bench.analog(&autoplug_ecus::cruise::pins::VEHICLE_SPEED, s.vehicle_speed_kmh);
    }
    fn read(bench: &Bench<'_>) -> Option<Status> {
        // The lamp is the board's one output; the command goes out on CAN, and the set
        // speed stays inside the ECU (0 here: what the bench cannot see).
        Some(Status {
            engaged: bench.output(&autoplug_ecus::cruise::pins::ENGAGED_LAMP)?,
            set_speed_kmh: 0.0,
            command: 0.0,
        })
    }
}
