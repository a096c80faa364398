//! The differential ECU in the car: its logic as the image's software builds it, its sensors
//! from the vehicle model and the driver's controls, and its board's pins.

use autoplug_ecu::Instant;
use autoplug_image::SoftwareVariant;
use autoplug_ecus::diff::{Actuators, DiffEcu, Sensors};

use super::{Bench, Wiring};
use crate::driver::DriverControls;
use autoplug_vehicle::VehicleState;

impl Wiring for DiffEcu {
    fn make(_: SoftwareVariant, now: Instant) -> Self {
        Self::new(now)
    }

    fn sensors(s: &VehicleState, _: &DriverControls) -> Sensors {
        Sensors {
            yaw_rate_error_rad_s: s.yaw_rate_error_rad_s as f32,
        }
    }

    fn drive(s: &Sensors, bench: &mut Bench<'_>) {
        bench.analog(&autoplug_ecus::diff::pins::YAW_RATE_ERROR, s.yaw_rate_error_rad_s);
    }
    fn read(bench: &Bench<'_>) -> Option<Actuators> {
        Some(Actuators {
            torque_split_nm: bench.pwm(&autoplug_ecus::diff::pins::TORQUE_SPLIT)?,
        })
    }
}
