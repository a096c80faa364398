//! The ABS ECU in the car: its logic as the image's software builds it, its sensors
//! from the vehicle model and the driver's controls, and its board's pins.

use autoplug_ecu::Instant;
use autoplug_image::SoftwareVariant;
use autoplug_ecus::abs::{AbsEcu, Actuators, Sensors};

use super::{Bench, Wiring, variant};
use crate::driver::DriverControls;
use autoplug_vehicle::VehicleState;

impl Wiring for AbsEcu {
    fn make(software: SoftwareVariant, now: Instant) -> Self {
        Self::new(variant(software), now)
    }

    fn sensors(s: &VehicleState, _: &DriverControls) -> Sensors {
        Sensors {
            wheel_speed_kmh: s.wheel_speeds_kmh(),
        }
    }

    fn drive(s: &Sensors, bench: &mut Bench<'_>) {
        for (input, speed) in autoplug_ecus::abs::pins::WHEEL_SPEEDS.iter().zip(s.wheel_speed_kmh) {
            bench.analog(input, speed);
        }
    }
    fn read(bench: &Bench<'_>) -> Option<Actuators> {
        let mut brake = [0.0; 4];
        for (value, output) in brake.iter_mut().zip(&autoplug_ecus::abs::pins::BRAKES) {
            *value = bench.pwm(output)?;
        }
        Some(Actuators { brake })
    }
}
