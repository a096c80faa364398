//! The differential ECU's board: a Nucleo-F446RE wired to the bench, its pins and scales (declared in
//! `ecu_diff::pins`, which the virtual car drives too) taken from the HAL.
//!
//! | Arduino | Morpho | MCU pin | signal | direction | electrical range |
//! |---|---|---|---|---|---|
//! | D15 | CN10-3 | PB8 | CAN1 RX (AF9) from the transceiver's RXD | in | 3.3 V logic |
//! | D14 | CN10-5 | PB9 | CAN1 TX (AF9) to the transceiver's TXD | out | 3.3 V logic |
//! | A0 | CN7-28 | PA0 | yaw-rate error, reference − actual (ADC1_IN0) | in | 0–3.3 V = −2.5–+2.5 rad/s, 1.65 V = 0 |
//! | D5 | CN10-27 | PB4 | rear torque split (TIM3_CH1 PWM) | out | 0–100 % duty = −50–+50 N·m (to the right rear), 50 % = open |
//!
//! Safe state at power-up: 50 % duty, no torque moved (an open differential).

use autoplug_firmware::analog::{LinearInput, LinearOutput};
use autoplug_firmware::io::{read_analog, AnalogPin, PwmOutput};
use autoplug_firmware::runtime::{Io, Platform};
use ecu_diff::{pins, Actuators, DiffEcu, Sensors};
use embassy_stm32::adc::{Adc, AdcChannel};
use embassy_stm32::peripherals::{ADC1, TIM3};

/// The yaw-rate error signal: 0–3.3 V is −2.5–+2.5 rad/s (YawErrorMsg's range).
const YAW_RATE_ERROR: LinearInput = pins::YAW_RATE_ERROR.scale;
/// The torque split: 0–100 % duty spans the logic's split limits.
const TORQUE_SPLIT: LinearOutput = pins::TORQUE_SPLIT.scale;

/// The differential ECU's sensor and actuator.
pub struct Board {
    adc: Adc<'static, ADC1>,
    yaw_rate_error: AnalogPin,
    torque_split: PwmOutput<TIM3>,
}

/// Brings up the clocks, CAN1 and the I/O; the split starts open.
pub fn init() -> (Platform, Board) {
    autoplug_firmware::board_init!(p, platform);
    let pwm = autoplug_firmware::pwm_channels!(p.TIM3, ch1 = p.PB4);
    let board = Board {
        adc: Adc::new(p.ADC1),
        yaw_rate_error: p.PA0.degrade_adc(),
        torque_split: PwmOutput::new(pwm.ch1, TORQUE_SPLIT, 0.0),
    };
    (platform, board)
}

impl Io<DiffEcu> for Board {
    fn read(&mut self) -> Sensors {
        Sensors {
            yaw_rate_error_rad_s: read_analog(
                &mut self.adc,
                &mut self.yaw_rate_error,
                &YAW_RATE_ERROR,
            ),
        }
    }

    fn write(&mut self, actuators: &Actuators) {
        self.torque_split.set(actuators.torque_split_nm);
    }
}
