//! The pedals ECU board's signals (the pins `src/bin/pedals-fw/board.rs` wires to the HAL, and
//! the virtual car drives from the vehicle model): pin, channel and scaling, named once.

use crate::PEDAL_FULL;
use autoplug_ecu::pins::{AnalogIn, LinearInput, LinearOutput, Pin, PwmOut, Signal};

/// A pedal's scale: 0–3.3 V is 0–100 pedal units.
const PEDAL: LinearInput = LinearInput::new(0.0, PEDAL_FULL);
/// A command's scale: 0–100 % duty is 0–100 pedal units.
const COMMAND: LinearOutput = LinearOutput::new(0.0, PEDAL_FULL);

/// The accelerator pedal: 0–3.3 V is 0–100 pedal units.
pub const ACCELERATOR_PEDAL: AnalogIn = AnalogIn {
    pin: Pin::a(0),
    adc_channel: 0,
    scale: PEDAL,
};

/// The brake pedal: 0–3.3 V is 0–100 pedal units.
pub const BRAKE_PEDAL: AnalogIn = AnalogIn {
    pin: Pin::a(1),
    adc_channel: 1,
    scale: PEDAL,
};

/// The accelerator command: 0–100 % duty is 0–100 pedal units.
pub const ACCELERATOR_CMD: PwmOut = PwmOut {
    pin: Pin::b(4),
    tim3_channel: 1,
    scale: COMMAND,
};

/// The brake command: 0–100 % duty is 0–100 pedal units.
pub const BRAKE_CMD: PwmOut = PwmOut {
    pin: Pin::b(5),
    tim3_channel: 2,
    scale: COMMAND,
};

/// Every signal of the board (the CAN pins aside), for checking the board as a whole.
pub const SIGNALS: &[Signal] = &[
    Signal::Analog(ACCELERATOR_PEDAL),
    Signal::Analog(BRAKE_PEDAL),
    Signal::Pwm(ACCELERATOR_CMD),
    Signal::Pwm(BRAKE_CMD),
];
