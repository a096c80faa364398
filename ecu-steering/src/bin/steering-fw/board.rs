//! The steering ECU's board: a Nucleo-F446RE wired to the bench, its pins and scales (declared in
//! `ecu_steering::pins`, which the virtual car drives too) taken from the HAL.
//!
//! | Arduino | Morpho | MCU pin | signal | direction | electrical range |
//! |---|---|---|---|---|---|
//! | D15 | CN10-3 | PB8 | CAN1 RX (AF9) from the transceiver's RXD | in | 3.3 V logic |
//! | D14 | CN10-5 | PB9 | CAN1 TX (AF9) to the transceiver's TXD | out | 3.3 V logic |
//! | A0 | CN7-28 | PA0 | steering-wheel angle (ADC1_IN0) | in | 0–3.3 V = 135° right to 135° left, 1.65 V = straight |
//! | D2 | CN10-33 | PA10 | shift-up paddle | in | to GND when pressed (internal pull-up) |
//! | D3 | CN10-31 | PB3 | shift-down paddle | in | to GND when pressed (internal pull-up) |
//! | D6 | CN10-25 | PB10 | cruise-on button | in | to GND when pressed (internal pull-up) |
//! | D7 | CN10-23 | PA8 | cruise-off button | in | to GND when pressed (internal pull-up) |
//! | D5 | CN10-27 | PB4 | steering command (TIM3_CH1 PWM) | out | 0–100 % duty = 135° right to 135° left, 50 % = straight |
//!
//! The wheel angle is a potentiometer on the column, read by the ADC: 12 bits over 270°
//! is 0.066° a count, with no timer to set up. (In 2011 the wheel's angle went through a
//! 555 timer as a frequency; a timer input capture would do that job here, for nothing
//! the ADC does not already give.) PB3 is also the SWO trace pin: leave SWO off, as
//! probe-rs's RTT logging does. The buttons are debounced by the logic. Safe state at
//! power-up: command straight ahead.

use autoplug_firmware::analog::{LinearInput, LinearOutput};
use autoplug_firmware::io::{read_analog, AnalogPin, PwmOutput};
use autoplug_firmware::runtime::{Io, Platform};
use ecu_steering::{pins, Actuators, Sensors, SteeringEcu};
use embassy_stm32::adc::{Adc, AdcChannel};
use embassy_stm32::gpio::{Input, Pull};
use embassy_stm32::peripherals::{ADC1, TIM3};

/// The wheel angle: 0–3.3 V is the full lock-to-lock range, positive (left) at 3.3 V.
const WHEEL_ANGLE: LinearInput = pins::WHEEL_ANGLE.scale;
/// The steering command: 0–100 % duty is the same range.
const STEERING_CMD: LinearOutput = pins::STEERING_CMD.scale;

/// The steering ECU's wheel, buttons and steering command.
pub struct Board {
    adc: Adc<'static, ADC1>,
    wheel_angle: AnalogPin,
    shift_up: Input<'static>,
    shift_down: Input<'static>,
    cruise_on: Input<'static>,
    cruise_off: Input<'static>,
    steering_cmd: PwmOutput<TIM3>,
}

/// Brings up the clocks, CAN1 and the I/O; the command starts straight ahead.
pub fn init() -> (Platform, Board) {
    autoplug_firmware::board_init!(p, platform);
    let pwm = autoplug_firmware::pwm_channels!(p.TIM3, ch1 = p.PB4);
    let board = Board {
        adc: Adc::new(p.ADC1),
        wheel_angle: p.PA0.degrade_adc(),
        shift_up: Input::new(p.PA10, Pull::Up),
        shift_down: Input::new(p.PB3, Pull::Up),
        cruise_on: Input::new(p.PB10, Pull::Up),
        cruise_off: Input::new(p.PA8, Pull::Up),
        steering_cmd: PwmOutput::new(pwm.ch1, STEERING_CMD, 0.0),
    };
    (platform, board)
}

impl Io<SteeringEcu> for Board {
    fn read(&mut self) -> Sensors {
        Sensors {
            wheel_angle_deg: read_analog(&mut self.adc, &mut self.wheel_angle, &WHEEL_ANGLE),
            shift_up_button: self.shift_up.is_low(),
            shift_down_button: self.shift_down.is_low(),
            cruise_on_button: self.cruise_on.is_low(),
            cruise_off_button: self.cruise_off.is_low(),
        }
    }

    fn write(&mut self, actuators: &Actuators) {
        self.steering_cmd.set(actuators.steering_cmd_deg);
    }
}
