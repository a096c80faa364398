//! The console ECU board's signals (the pins `src/bin/console-fw/board.rs` wires to the HAL, and
//! the virtual car drives from the vehicle model): pin, channel and scaling, named once.

use autoplug_ecu::pins::{DigitalIn, DigitalOut, Pin, Pull, Signal};

/// The headlight switch: to GND = on.
pub const HEADLIGHT_SWITCH: DigitalIn = DigitalIn {
    pin: Pin::a(10),
    pull: Pull::Up,
};

/// The engine-mode switch: to GND = economy, open = sport.
pub const ENGINE_MODE_SWITCH: DigitalIn = DigitalIn {
    pin: Pin::b(3),
    pull: Pull::Up,
};

/// The transmission-mode switch: to GND = manual, open = automatic.
pub const TRANSMISSION_MODE_SWITCH: DigitalIn = DigitalIn {
    pin: Pin::b(10),
    pull: Pull::Up,
};

/// The headlights' lamp driver: high = on.
pub const HEADLIGHTS: DigitalOut = DigitalOut { pin: Pin::a(8) };

/// The brake lights' lamp driver: high = on.
pub const BRAKE_LIGHTS: DigitalOut = DigitalOut { pin: Pin::a(9) };

/// Every signal of the board (the CAN pins aside), for checking the board as a whole.
pub const SIGNALS: &[Signal] = &[
    Signal::Input(HEADLIGHT_SWITCH),
    Signal::Input(ENGINE_MODE_SWITCH),
    Signal::Input(TRANSMISSION_MODE_SWITCH),
    Signal::Output(HEADLIGHTS),
    Signal::Output(BRAKE_LIGHTS),
];
