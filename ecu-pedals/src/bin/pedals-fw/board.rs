//! The pedals ECU's board: a Nucleo-F446RE wired to the bench, its pins and scales (declared in
//! `ecu_pedals::pins`, which the virtual car drives too) taken from the HAL.
//!
//! | Arduino | Morpho | MCU pin | signal | direction | electrical range |
//! |---|---|---|---|---|---|
//! | D15 | CN10-3 | PB8 | CAN1 RX (AF9) from the transceiver's RXD | in | 3.3 V logic |
//! | D14 | CN10-5 | PB9 | CAN1 TX (AF9) to the transceiver's TXD | out | 3.3 V logic |
//! | A0 | CN7-28 | PA0 | accelerator pedal (ADC1_IN0) | in | 0–3.3 V = 0–100 pedal units |
//! | A1 | CN7-30 | PA1 | brake pedal (ADC1_IN1) | in | 0–3.3 V = 0–100 pedal units |
//! | D5 | CN10-27 | PB4 | accelerator command (TIM3_CH1 PWM) | out | 0–100 % duty = 0–100 pedal units |
//! | D4 | CN10-29 | PB5 | brake command (TIM3_CH2 PWM) | out | 0–100 % duty = 0–100 pedal units |
//!
//! A pedal is a potentiometer between 3.3 V and GND, wiper on its pin. Safe state at
//! power-up: both commands at 0.

use autoplug_firmware::analog::{LinearInput, LinearOutput};
use autoplug_firmware::io::{read_analog, AnalogPin, PwmOutput};
use autoplug_firmware::runtime::{Io, Platform};
use ecu_pedals::{pins, Actuators, PedalsEcu, Sensors};
use embassy_stm32::adc::{Adc, AdcChannel};
use embassy_stm32::peripherals::{ADC1, TIM3};

/// A pedal: 0–3.3 V is 0–100 pedal units.
const PEDAL: LinearInput = pins::ACCELERATOR_PEDAL.scale;
/// A pedal command: 0–100 % duty is 0–100 pedal units.
const COMMAND: LinearOutput = pins::ACCELERATOR_CMD.scale;

/// The pedals ECU's sensors and actuators.
pub struct Board {
    adc: Adc<'static, ADC1>,
    accelerator_pedal: AnalogPin,
    brake_pedal: AnalogPin,
    accelerator_cmd: PwmOutput<TIM3>,
    brake_cmd: PwmOutput<TIM3>,
}

/// Brings up the clocks, CAN1 and the pedal I/O; the commands start at 0.
pub fn init() -> (Platform, Board) {
    autoplug_firmware::board_init!(p, platform);
    let pwm = autoplug_firmware::pwm_channels!(p.TIM3, ch1 = p.PB4, ch2 = p.PB5);
    let board = Board {
        adc: Adc::new(p.ADC1),
        accelerator_pedal: p.PA0.degrade_adc(),
        brake_pedal: p.PA1.degrade_adc(),
        accelerator_cmd: PwmOutput::new(pwm.ch1, COMMAND, 0.0),
        brake_cmd: PwmOutput::new(pwm.ch2, COMMAND, 0.0),
    };
    (platform, board)
}

impl Io<PedalsEcu> for Board {
    fn read(&mut self) -> Sensors {
        Sensors {
            accelerator_pedal: read_analog(&mut self.adc, &mut self.accelerator_pedal, &PEDAL),
            brake_pedal: read_analog(&mut self.adc, &mut self.brake_pedal, &PEDAL),
        }
    }

    fn write(&mut self, actuators: &Actuators) {
        self.accelerator_cmd.set(actuators.accelerator_cmd);
        self.brake_cmd.set(actuators.brake_cmd);
    }
}
