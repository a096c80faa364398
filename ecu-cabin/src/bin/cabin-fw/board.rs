//! The cabin comfort ECU's board: a Nucleo-F446RE wired to the bench, its pins and scales (declared in
//! `ecu_cabin::pins`, which the virtual car drives too) taken from the HAL.
//!
//! | Arduino | Morpho | MCU pin | signal | direction | electrical range |
//! |---|---|---|---|---|---|
//! | D15 | CN10-3 | PB8 | CAN1 RX (AF9) from the transceiver's RXD | in | 3.3 V logic |
//! | D14 | CN10-5 | PB9 | CAN1 TX (AF9) to the transceiver's TXD | out | 3.3 V logic |
//! | A0 | CN7-28 | PA0 | cabin temperature (ADC1_IN0) | in | 0–3.3 V = −50–170 °F |
//! | A1 | CN7-30 | PA1 | set-temperature knob (ADC1_IN1) | in | 0–3.3 V = 60–85 °F |
//! | D5 | CN10-27 | PB4 | fan power (TIM3_CH1 PWM) | out | 0–100 % duty = 0–100 % fan |
//!
//! The temperature sensor's range is wider than the logic's plausible range (−40–160 °F):
//! a sensor stuck at a rail (open or shorted wire) reads implausible, and the logic records
//! its DTC. The knob is a potentiometer between 3.3 V and GND. Safe state at power-up: fan
//! off.

use autoplug_firmware::analog::{LinearInput, LinearOutput};
use autoplug_firmware::io::{read_analog, AnalogPin, PwmOutput};
use autoplug_firmware::runtime::{Io, Platform};
use ecu_cabin::{pins, Actuators, CabinEcu, Sensors};
use embassy_stm32::adc::{Adc, AdcChannel};
use embassy_stm32::peripherals::{ADC1, TIM3};

/// The cabin temperature sensor: 0–3.3 V is −50–170 °F.
const CABIN_TEMP: LinearInput = pins::CABIN_TEMP.scale;
/// The set-temperature knob: end to end is the logic's set range.
const SET_TEMP: LinearInput = pins::SET_TEMP.scale;
/// The fan: 0–100 % duty is 0–100 % power.
const FAN: LinearOutput = pins::FAN.scale;

/// The cabin ECU's sensors and fan.
pub struct Board {
    adc: Adc<'static, ADC1>,
    cabin_temp: AnalogPin,
    set_temp: AnalogPin,
    fan: PwmOutput<TIM3>,
}

/// Brings up the clocks, CAN1 and the I/O; the fan starts off.
pub fn init() -> (Platform, Board) {
    autoplug_firmware::board_init!(p, platform);
    let pwm = autoplug_firmware::pwm_channels!(p.TIM3, ch1 = p.PB4);
    let board = Board {
        adc: Adc::new(p.ADC1),
        cabin_temp: p.PA0.degrade_adc(),
        set_temp: p.PA1.degrade_adc(),
        fan: PwmOutput::new(pwm.ch1, FAN, 0.0),
    };
    (platform, board)
}

impl Io<CabinEcu> for Board {
    fn read(&mut self) -> Sensors {
        Sensors {
            cabin_temp_f: read_analog(&mut self.adc, &mut self.cabin_temp, &CABIN_TEMP),
            set_temp_f: read_analog(&mut self.adc, &mut self.set_temp, &SET_TEMP),
        }
    }

    fn write(&mut self, actuators: &Actuators) {
        self.fan.set(actuators.fan);
    }
}
