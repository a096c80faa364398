//! The ABS ECU's board: a Nucleo-F446RE wired to the bench, its pins and scales (declared in
//! `ecu_abs::pins`, which the virtual car drives too) taken from the HAL.
//!
//! | Arduino | Morpho | MCU pin | signal | direction | electrical range |
//! |---|---|---|---|---|---|
//! | D15 | CN10-3 | PB8 | CAN1 RX (AF9) from the transceiver's RXD | in | 3.3 V logic |
//! | D14 | CN10-5 | PB9 | CAN1 TX (AF9) to the transceiver's TXD | out | 3.3 V logic |
//! | A0 | CN7-28 | PA0 | front-left wheel speed (ADC1_IN0) | in | 0–3.3 V = 0–255 km/h |
//! | A1 | CN7-30 | PA1 | front-right wheel speed (ADC1_IN1) | in | 0–3.3 V = 0–255 km/h |
//! | A2 | CN7-32 | PA4 | rear-left wheel speed (ADC1_IN4) | in | 0–3.3 V = 0–255 km/h |
//! | A3 | CN7-34 | PB0 | rear-right wheel speed (ADC1_IN8) | in | 0–3.3 V = 0–255 km/h |
//! | D5 | CN10-27 | PB4 | front-left brake (TIM3_CH1 PWM) | out | 0–100 % duty = 0–100 % brake |
//! | D4 | CN10-29 | PB5 | front-right brake (TIM3_CH2 PWM) | out | 0–100 % duty = 0–100 % brake |
//! | — | CN10-2 | PC8 | rear-left brake (TIM3_CH3 PWM) | out | 0–100 % duty = 0–100 % brake |
//! | — | CN10-1 | PC9 | rear-right brake (TIM3_CH4 PWM) | out | 0–100 % duty = 0–100 % brake |
//!
//! A wheel speed is the linear speed ω·r of the wheel, as a voltage (a wheel-speed sensor's
//! pulse train would be a timer input capture on real brakes; the bench, like the 2011
//! one, gets it from the simulator as a voltage). The four readings take about 30 µs of the
//! 5 ms step. Safe state at power-up: no brake applied.

use autoplug_firmware::analog::{LinearInput, LinearOutput};
use autoplug_firmware::io::{read_analog, AnalogPin, PwmOutput};
use autoplug_firmware::runtime::{Io, Platform};
use ecu_abs::{pins, AbsEcu, Actuators, Sensors};
use embassy_stm32::adc::{Adc, AdcChannel};
use embassy_stm32::peripherals::{ADC1, TIM3};

/// A wheel speed: 0–3.3 V is 0–255 km/h (VehicleSpeedMsg's range).
const WHEEL_SPEED: LinearInput = pins::WHEEL_SPEEDS[0].scale;
/// A brake: 0–100 % duty is 0–100 % of full brake torque.
const BRAKE: LinearOutput = pins::BRAKES[0].scale;

/// The ABS ECU's wheel-speed inputs and brake outputs, FL, FR, RL, RR.
pub struct Board {
    adc: Adc<'static, ADC1>,
    front_left_speed: AnalogPin,
    front_right_speed: AnalogPin,
    rear_left_speed: AnalogPin,
    rear_right_speed: AnalogPin,
    brakes: [PwmOutput<TIM3>; 4],
}

/// Brings up the clocks, CAN1 and the I/O; no brake is applied.
pub fn init() -> (Platform, Board) {
    autoplug_firmware::board_init!(p, platform);
    let pwm = autoplug_firmware::pwm_channels!(
        p.TIM3,
        ch1 = p.PB4,
        ch2 = p.PB5,
        ch3 = p.PC8,
        ch4 = p.PC9
    );
    let board = Board {
        adc: Adc::new(p.ADC1),
        front_left_speed: p.PA0.degrade_adc(),
        front_right_speed: p.PA1.degrade_adc(),
        rear_left_speed: p.PA4.degrade_adc(),
        rear_right_speed: p.PB0.degrade_adc(),
        brakes: [
            PwmOutput::new(pwm.ch1, BRAKE, 0.0),
            PwmOutput::new(pwm.ch2, BRAKE, 0.0),
            PwmOutput::new(pwm.ch3, BRAKE, 0.0),
            PwmOutput::new(pwm.ch4, BRAKE, 0.0),
        ],
    };
    (platform, board)
}

impl Io<AbsEcu> for Board {
    fn read(&mut self) -> Sensors {
        let adc = &mut self.adc;
        Sensors {
            wheel_speed_kmh: [
                read_analog(adc, &mut self.front_left_speed, &WHEEL_SPEED),
                read_analog(adc, &mut self.front_right_speed, &WHEEL_SPEED),
                read_analog(adc, &mut self.rear_left_speed, &WHEEL_SPEED),
                read_analog(adc, &mut self.rear_right_speed, &WHEEL_SPEED),
            ],
        }
    }

    fn write(&mut self, actuators: &Actuators) {
        for (output, brake) in self.brakes.iter_mut().zip(actuators.brake) {
            output.set(brake);
        }
    }
}
