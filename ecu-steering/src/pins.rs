//! The steering ECU board's signals (the pins `src/bin/steering-fw/board.rs` wires to the HAL, and
//! the virtual car drives from the vehicle model): pin, channel and scaling, named once.

use crate::STEERING_LIMIT_DEG;
use autoplug_ecu::pins::{
    AnalogIn, DigitalIn, LinearInput, LinearOutput, Pin, Pull, PwmOut, Signal,
};

/// The wheel angle: 0–3.3 V is the full lock-to-lock range, positive (left) at 3.3 V.
pub const WHEEL_ANGLE: AnalogIn = AnalogIn {
    pin: Pin::a(0),
    adc_channel: 0,
    scale: LinearInput::new(-STEERING_LIMIT_DEG, STEERING_LIMIT_DEG),
};

/// The shift-up paddle: to GND when pressed.
pub const SHIFT_UP: DigitalIn = DigitalIn {
    pin: Pin::a(10),
    pull: Pull::Up,
};

/// The shift-down paddle: to GND when pressed.
pub const SHIFT_DOWN: DigitalIn = DigitalIn {
    pin: Pin::b(3),
    pull: Pull::Up,
};

/// The cruise-on button: to GND when pressed.
pub const CRUISE_ON: DigitalIn = DigitalIn {
    pin: Pin::b(10),
    pull: Pull::Up,
};

/// The cruise-off button: to GND when pressed.
pub const CRUISE_OFF: DigitalIn = DigitalIn {
    pin: Pin::a(8),
    pull: Pull::Up,
};

/// The steering command: 0–100 % duty is the same range as the wheel.
pub const STEERING_CMD: PwmOut = PwmOut {
    pin: Pin::b(4),
    tim3_channel: 1,
    scale: LinearOutput::new(-STEERING_LIMIT_DEG, STEERING_LIMIT_DEG),
};

/// Every signal of the board (the CAN pins aside), for checking the board as a whole.
pub const SIGNALS: &[Signal] = &[
    Signal::Analog(WHEEL_ANGLE),
    Signal::Input(SHIFT_UP),
    Signal::Input(SHIFT_DOWN),
    Signal::Input(CRUISE_ON),
    Signal::Input(CRUISE_OFF),
    Signal::Pwm(STEERING_CMD),
];
