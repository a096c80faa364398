//! The cabin comfort ECU in the car: its logic as the image's software builds it, its sensors
//! from the vehicle model and the driver's controls, and its board's pins.

use autoplug_ecu::Instant;
use autoplug_image::SoftwareVariant;
use autoplug_ecus::cabin::{Actuators, CabinEcu, Sensors};

use super::{Bench, Wiring};
use crate::driver::DriverControls;
use autoplug_vehicle::VehicleState;

impl Wiring for CabinEcu {
    fn make(_: SoftwareVariant, _: Instant) -> Self {
        Self::new()
    }

    fn sensors(s: &VehicleState, c: &DriverControls) -> Sensors {
        Sensors {
            cabin_temp_f: s.cabin_temp_sensor_f(),
            set_temp_f: c.held.set_temp_f as f32,
        }
    }

    fn drive(s: &Sensors, bench: &mut Bench<'_>) {
        use autoplug_ecus::cabin::pins::*;
        bench.analog(&CABIN_TEMP, s.cabin_temp_f);
        bench.analog(&SET_TEMP, s.set_temp_f);
    }
    fn read(bench: &Bench<'_>) -> Option<Actuators> {
        Some(Actuators {
            fan: bench.pwm(&autoplug_ecus::cabin::pins::FAN)?,
        })
    }
}
