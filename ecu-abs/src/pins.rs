//! The ABS ECU board's signals (the pins `src/bin/abs-fw/board.rs` wires to the HAL, and
//! the virtual car drives from the vehicle model): pin, channel and scaling, named once.

use autoplug_ecu::pins::{AnalogIn, LinearInput, LinearOutput, Pin, PwmOut, Signal};

const fn wheel_speed(pin: Pin, adc_channel: u8) -> AnalogIn {
    AnalogIn {
        pin,
        adc_channel,
        scale: LinearInput::new(0.0, 255.0),
    }
}

const fn brake(pin: Pin, tim3_channel: u8) -> PwmOut {
    PwmOut {
        pin,
        tim3_channel,
        scale: LinearOutput::new(0.0, 100.0),
    }
}

/// Wheel speeds FL, FR, RL, RR: 0–3.3 V is 0–255 km/h (VehicleSpeedMsg's range).
pub const WHEEL_SPEEDS: [AnalogIn; 4] = [
    wheel_speed(Pin::a(0), 0),
    wheel_speed(Pin::a(1), 1),
    wheel_speed(Pin::a(4), 4),
    wheel_speed(Pin::b(0), 8),
];

/// Brakes FL, FR, RL, RR: 0–100 % duty is 0–100 % of full brake torque.
pub const BRAKES: [PwmOut; 4] = [
    brake(Pin::b(4), 1),
    brake(Pin::b(5), 2),
    brake(Pin::c(8), 3),
    brake(Pin::c(9), 4),
];

/// Every signal of the board (the CAN pins aside), for checking the board as a whole.
pub const SIGNALS: &[Signal] = &[
    Signal::Analog(WHEEL_SPEEDS[0]),
    Signal::Analog(WHEEL_SPEEDS[1]),
    Signal::Analog(WHEEL_SPEEDS[2]),
    Signal::Analog(WHEEL_SPEEDS[3]),
    Signal::Pwm(BRAKES[0]),
    Signal::Pwm(BRAKES[1]),
    Signal::Pwm(BRAKES[2]),
    Signal::Pwm(BRAKES[3]),
];
