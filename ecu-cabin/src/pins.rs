//! The cabin ECU board's signals (the pins `src/bin/cabin-fw/board.rs` wires to the HAL, and
//! the virtual car drives from the vehicle model): pin, channel and scaling, named once.

use crate::{SET_TEMP_MAX_F, SET_TEMP_MIN_F};
use autoplug_ecu::pins::{AnalogIn, LinearInput, LinearOutput, Pin, PwmOut, Signal};

/// The cabin temperature sensor: 0–3.3 V is −50–170 °F.
pub const CABIN_TEMP: AnalogIn = AnalogIn {
    pin: Pin::a(0),
    adc_channel: 0,
    scale: LinearInput::new(-50.0, 170.0),
};

/// The set-temperature knob: end to end is the logic's set range.
pub const SET_TEMP: AnalogIn = AnalogIn {
    pin: Pin::a(1),
    adc_channel: 1,
    scale: LinearInput::new(SET_TEMP_MIN_F, SET_TEMP_MAX_F),
};

/// The fan: 0–100 % duty is 0–100 % power.
pub const FAN: PwmOut = PwmOut {
    pin: Pin::b(4),
    tim3_channel: 1,
    scale: LinearOutput::new(0.0, 100.0),
};

/// Every signal of the board (the CAN pins aside), for checking the board as a whole.
pub const SIGNALS: &[Signal] = &[
    Signal::Analog(CABIN_TEMP),
    Signal::Analog(SET_TEMP),
    Signal::Pwm(FAN),
];
