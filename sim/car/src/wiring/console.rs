//! The console ECU in the car: its logic as the image's software builds it, its sensors
//! from the vehicle model and the driver's controls, and its board's pins.

use autoplug_ecu::Instant;
use autoplug_image::SoftwareVariant;
use autoplug_ecus::console::{Actuators, ConsoleEcu, Sensors};

use super::{Bench, Wiring};
use crate::driver::DriverControls;
use autoplug_vehicle::VehicleState;

impl Wiring for ConsoleEcu {
    fn make(_: SoftwareVariant, now: Instant) -> Self {
        Self::new(now)
    }

    fn sensors(_: &VehicleState, c: &DriverControls) -> Sensors {
        Sensors {
            headlight_switch: c.held.headlights,
            economy_mode_switch: c.held.economy_mode,
            manual_mode_switch: c.held.manual_mode,
        }
    }

    fn drive(s: &Sensors, bench: &mut Bench<'_>) {
        use autoplug_ecus::console::pins::*;
        bench.switch(&HEADLIGHT_SWITCH, s.headlight_switch);
        bench.switch(&ENGINE_MODE_SWITCH, s.economy_mode_switch);
        bench.switch(&TRANSMISSION_MODE_SWITCH, s.manual_mode_switch);
    }
    fn read(bench: &Bench<'_>) -> Option<Actuators> {
        use autoplug_ecus::console::pins::*;
        Some(Actuators {
            headlights: bench.output(&HEADLIGHTS)?,
            brake_lights: bench.output(&BRAKE_LIGHTS)?,
        })
    }
}
