//! The differential ECU board's signals (the pins `src/bin/diff-fw/board.rs` wires to the HAL, and
//! the virtual car drives from the vehicle model): pin, channel and scaling, named once.

use crate::SPLIT_LIMIT_NM;
use autoplug_ecu::pins::{AnalogIn, LinearInput, LinearOutput, Pin, PwmOut, Signal};

/// The yaw-rate error, reference − actual: 0–3.3 V is −2.5–+2.5 rad/s (YawErrorMsg's range).
pub const YAW_RATE_ERROR: AnalogIn = AnalogIn {
    pin: Pin::a(0),
    adc_channel: 0,
    scale: LinearInput::new(-2.5, 2.5),
};

/// The rear torque split: 0–100 % duty spans the logic's split limits, 50 % = open.
pub const TORQUE_SPLIT: PwmOut = PwmOut {
    pin: Pin::b(4),
    tim3_channel: 1,
    scale: LinearOutput::new(-SPLIT_LIMIT_NM, SPLIT_LIMIT_NM),
};

/// Every signal of the board (the CAN pins aside), for checking the board as a whole.
pub const SIGNALS: &[Signal] = &[Signal::Analog(YAW_RATE_ERROR), Signal::Pwm(TORQUE_SPLIT)];
