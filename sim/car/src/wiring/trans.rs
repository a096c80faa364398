//! The transmission ECU in the car: its logic as the image's software builds it, its sensors
//! from the vehicle model and the driver's controls, and its board's pins.

use autoplug_ecu::Instant;
use autoplug_image::SoftwareVariant;
use autoplug_can::Gear;
use autoplug_ecus::trans::{Actuators, Sensors, TransEcu};
use crate::car::can_gear;

use super::{Bench, Wiring};
use crate::driver::DriverControls;
use autoplug_vehicle::VehicleState;

impl Wiring for TransEcu {
    fn make(_: SoftwareVariant, now: Instant) -> Self {
        Self::new(now)
    }

    fn sensors(s: &VehicleState, _: &DriverControls) -> Sensors {
        Sensors {
            current_gear: can_gear(s.gear),
        }
    }

    fn drive(s: &Sensors, bench: &mut Bench<'_>) {
        let code = s.current_gear.raw();
        for (bit, line) in autoplug_ecus::trans::pins::GEAR_ENGAGED.iter().enumerate() {
            bench.level(line, code >> bit & 1 == 1);
        }
    }
    fn read(bench: &Bench<'_>) -> Option<Actuators> {
        let mut code = 0;
        for (bit, line) in autoplug_ecus::trans::pins::GEAR_CMD.iter().enumerate() {
            code |= i64::from(bench.output(line)?) << bit;
        }
        Some(Actuators {
            gear_cmd: Gear::from_raw(code)?,
        })
    }
}
