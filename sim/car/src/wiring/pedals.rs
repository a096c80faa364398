//! The pedals ECU in the car: its logic as the image's software builds it, its sensors
//! from the vehicle model and the driver's controls, and its board's pins.

use autoplug_ecu::Instant;
use autoplug_image::SoftwareVariant;
use autoplug_ecus::pedals::{Actuators, PedalsEcu, Sensors};

use super::{Bench, Wiring};
use crate::driver::DriverControls;
use autoplug_vehicle::VehicleState;

impl Wiring for PedalsEcu {
    fn make(_: SoftwareVariant, now: Instant) -> Self {
        Self::new(now)
    }

    fn sensors(_: &VehicleState, c: &DriverControls) -> Sensors {
        Sensors {
            accelerator_pedal: c.held.accelerator as f32,
            brake_pedal: c.held.brake as f32,
        }
    }

    fn drive(s: &Sensors, bench: &mut Bench<'_>) {
        use autoplug_ecus::pedals::pins::*;
        bench.analog(&ACCELERATOR_PEDAL, s.accelerator_pedal);
        bench.analog(&BRAKE_PEDAL, s.brake_pedal);
    }
    fn read(bench: &Bench<'_>) -> Option<Actuators> {
        use autoplug_ecus::pedals::pins::*;
        Some(Actuators {
            accelerator_cmd: bench.pwm(&ACCELERATOR_CMD)?,
            brake_cmd: bench.pwm(&BRAKE_CMD)?,
        })
    }
}
