//! How each ECU sits in the car: the software its image names built into its logic, its
//! sensors read from the vehicle model and the driver's controls, and, for an ECU that runs
//! as its firmware, the bench wiring of its board's pins (`autoplug_ecus::<name>::pins`, the
//! inverse of the firmware's board module). One module per ECU, declared from the registry
//! (`autoplug_ecus::for_each_ecu!`): a new ECU brings its own file here.

use autoplug_ecu::pins::{AnalogIn, DigitalIn, DigitalOut, Pull, PwmOut};
use autoplug_ecu::{EcuLogic, Instant, Variant};
use autoplug_image::SoftwareVariant;
use autoplug_mcu::history::Input;
use autoplug_mcu::mcu::Mcu;
use autoplug_vehicle::VehicleState;

use crate::driver::DriverControls;

macro_rules! ecu_modules {
    ($(($node:ident, $name:ident, $krate:ident, $logic:ident)),* $(,)?) => {
        $(mod $name;)*
    };
}
autoplug_ecus::for_each_ecu!(ecu_modules);

/// An ECU in the car.
pub(crate) trait Wiring: EcuLogic {
    /// Its logic for the software variant the installed image names, started at `now`.
    fn make(software: SoftwareVariant, now: Instant) -> Self;
    /// Its sensor readings: the vehicle model's state and the driver's controls.
    fn sensors(state: &VehicleState, controls: &DriverControls) -> Self::Sensors;
    /// Puts the sensor readings on the pins.
    fn drive(sensors: &Self::Sensors, bench: &mut Bench<'_>);
    /// The actuator commands the pins show; `None` until the firmware drives them all.
    fn read(bench: &Bench<'_>) -> Option<Self::Actuators>;
}

/// The demonstration variant the image's header names (the faulty software exists for
/// cruise and ABS; another ECU ignores it).
fn variant(software: SoftwareVariant) -> Variant {
    match software {
        SoftwareVariant::Standard => Variant::Correct,
        SoftwareVariant::Faulty => Variant::Faulty,
    }
}

/// The bench's side of a board's pins: what the vehicle model drives and reads. What it
/// drives reaches the MCU as an input (journaled for a reverse debugger).
pub(crate) struct Bench<'a> {
    mcu: &'a mut Mcu,
}

/// GPIO mode bits (RM0390 8.4.1).
const MODE_OUTPUT: u32 = 1;
const MODE_ALTERNATE: u32 = 2;

impl<'a> Bench<'a> {
    pub(crate) fn new(mcu: &'a mut Mcu) -> Self {
        Self { mcu }
    }

    /// Puts the voltage for `value` on an analog input.
    fn analog(&mut self, input: &AnalogIn, value: f32) {
        self.mcu.input(Input::Analog {
            channel: usize::from(input.adc_channel),
            volts: input.volts(value),
        });
    }

    /// A switch between the pin and GND (pull-up inputs): closed pulls it low, open leaves
    /// it to the pull-up.
    fn switch(&mut self, input: &DigitalIn, closed: bool) {
        debug_assert_eq!(input.pull, Pull::Up);
        let pin = input.pin;
        self.mcu.input(Input::Drive {
            port: pin.port_index(),
            pin: u32::from(pin.number),
            level: closed.then_some(false),
        });
    }

    /// A line driven high or low by the other side (pull-down inputs).
    fn level(&mut self, input: &DigitalIn, high: bool) {
        let pin = input.pin;
        self.mcu.input(Input::Drive {
            port: pin.port_index(),
            pin: u32::from(pin.number),
            level: Some(high),
        });
    }

    /// The value a PWM output stands for, once the firmware drives it (pin in its
    /// alternate function, the timer channel enabled in a PWM mode).
    fn pwm(&self, output: &PwmOut) -> Option<f32> {
        let pin = output.pin;
        if self.mcu.chip.gpio[pin.port_index()].mode(u32::from(pin.number)) != MODE_ALTERNATE {
            return None;
        }
        let duty = self
            .mcu
            .chip
            .tim3
            .pwm_duty(usize::from(output.tim3_channel) - 1)?;
        Some(output.value(duty))
    }

    /// An output's level, once the firmware made the pin an output.
    fn output(&self, output: &DigitalOut) -> Option<bool> {
        let pin = output.pin;
        let port = &self.mcu.chip.gpio[pin.port_index()];
        (port.mode(u32::from(pin.number)) == MODE_OUTPUT)
            .then(|| port.output(u32::from(pin.number)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoplug_can::Gear;
    use autoplug_flash::sim::SimFlash;

    fn mcu() -> Mcu {
        Mcu::power_on(SimFlash::new(1), [0; 3]).unwrap()
    }

    #[test]
    fn sensors_reach_the_boards_pins() {
        let mut mcu = mcu();
        let sensors = autoplug_ecus::steering::Sensors {
            wheel_angle_deg: 67.5,
            shift_up_button: true,
            shift_down_button: false,
            cruise_on_button: false,
            cruise_off_button: true,
        };
        // The firmware's inputs: pull-ups on the four buttons.
        for pin in [
            &autoplug_ecus::steering::pins::SHIFT_UP,
            &autoplug_ecus::steering::pins::SHIFT_DOWN,
            &autoplug_ecus::steering::pins::CRUISE_ON,
            &autoplug_ecus::steering::pins::CRUISE_OFF,
        ] {
            let n = u32::from(pin.pin.number);
            mcu.chip.gpio[pin.pin.port_index()]
                .write(0x0C, 1 << (2 * n), 3 << (2 * n))
                .unwrap();
        }
        autoplug_ecus::steering::SteeringEcu::drive(&sensors, &mut Bench::new(&mut mcu));
        // 67.5° of ±135° is three quarters of 3.3 V.
        assert!((mcu.chip.adc.inputs()[0] - 2.475).abs() < 1e-4);
        let idr = |chip: &autoplug_mcu::chip::Chip, pin: &DigitalIn| {
            chip.gpio[pin.pin.port_index()].read(0x10).unwrap() >> pin.pin.number & 1
        };
        use autoplug_ecus::steering::pins::*;
        assert_eq!(idr(&mcu.chip, &SHIFT_UP), 0, "pressed: to GND");
        assert_eq!(idr(&mcu.chip, &SHIFT_DOWN), 1, "open: the pull-up");
        assert_eq!(idr(&mcu.chip, &CRUISE_OFF), 0);

        let mut mcu = self::mcu();
        let gear = autoplug_ecus::trans::Sensors {
            current_gear: Gear::Fifth,
        };
        autoplug_ecus::trans::TransEcu::drive(&gear, &mut Bench::new(&mut mcu));
        let code: u32 = autoplug_ecus::trans::pins::GEAR_ENGAGED
            .iter()
            .enumerate()
            .map(|(bit, line)| idr(&mcu.chip, line) << bit)
            .sum();
        assert_eq!(i64::from(code), Gear::Fifth.raw());
    }

    #[test]
    fn actuators_are_read_once_the_firmware_drives_the_pins() {
        let mut mcu = mcu();
        assert_eq!(
            autoplug_ecus::diff::DiffEcu::read(&Bench::new(&mut mcu)),
            None,
            "pins not set up"
        );
        // PB4 in its alternate function, TIM3 channel 1 in PWM mode 1 at 3/4 duty.
        let pb4 = autoplug_ecus::diff::pins::TORQUE_SPLIT.pin;
        mcu.chip.gpio[pb4.port_index()]
            .write(0x00, 2 << 8, 3 << 8)
            .unwrap();
        mcu.chip.tim3.write(0x2C, 9_999, u32::MAX, 0).unwrap(); // ARR
        mcu.chip.tim3.write(0x18, 6 << 4, u32::MAX, 0).unwrap(); // CCMR1: OC1M = PWM 1
        mcu.chip.tim3.write(0x34, 7_500, u32::MAX, 0).unwrap(); // CCR1
        mcu.chip.tim3.write(0x20, 1, u32::MAX, 0).unwrap(); // CCER: CC1E
        mcu.chip.tim3.write(0x14, 1, u32::MAX, 0).unwrap(); // EGR: UG loads ARR
        let split = autoplug_ecus::diff::DiffEcu::read(&Bench::new(&mut mcu)).expect("driven");
        assert!((split.torque_split_nm - 25.0).abs() < 0.01, "{split:?}");

        // The lamp: PA5 an output, high.
        let lamp = autoplug_ecus::cruise::pins::ENGAGED_LAMP.pin;
        mcu.chip.gpio[0].write(0x00, 1 << 10, 3 << 10).unwrap();
        mcu.chip.gpio[0]
            .write(0x14, 1 << lamp.number, 1 << lamp.number)
            .unwrap();
        let status = autoplug_ecus::cruise::CruiseEcu::read(&Bench::new(&mut mcu)).expect("driven");
        assert!(status.engaged);
    }
}
