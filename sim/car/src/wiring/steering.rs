//! The steering ECU in the car: its logic as the image's software builds it, its sensors
//! from the vehicle model and the driver's controls, and its board's pins.

use autoplug_ecu::Instant;
use autoplug_image::SoftwareVariant;
use autoplug_ecus::steering::{Actuators, Sensors, SteeringEcu};

use super::{Bench, Wiring};
use crate::driver::DriverControls;
use autoplug_vehicle::VehicleState;

impl Wiring for SteeringEcu {
    fn make(_: SoftwareVariant, now: Instant) -> Self {
        Self::new(now)
    }

    fn sensors(_: &VehicleState, c: &DriverControls) -> Sensors {
        Sensors {
            wheel_angle_deg: c.held.steering_deg as f32,
            shift_up_button: c.buttons.shift_up,
            shift_down_button: c.buttons.shift_down,
            cruise_on_button: c.buttons.cruise_on,
            cruise_off_button: c.buttons.cruise_off,
        }
    }

    fn drive(s: &Sensors, bench: &mut Bench<'_>) {
        use autoplug_ecus::steering::pins::*;
        bench.analog(&WHEEL_ANGLE, s.wheel_angle_deg);
        bench.switch(&SHIFT_UP, s.shift_up_button);
        bench.switch(&SHIFT_DOWN, s.shift_down_button);
        bench.switch(&CRUISE_ON, s.cruise_on_button);
        bench.switch(&CRUISE_OFF, s.cruise_off_button);
    }
    fn read(bench: &Bench<'_>) -> Option<Actuators> {
        Some(Actuators {
            steering_cmd_deg: bench.pwm(&autoplug_ecus::steering::pins::STEERING_CMD)?,
        })
    }
}
