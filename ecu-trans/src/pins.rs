//! The transmission ECU board's signals (the pins `src/bin/trans-fw/board.rs` wires to the
//! HAL, and the virtual car drives from the vehicle model): pin, channel and scaling, named
//! once.
//!
//! Both sets of lines carry the gear as the catalogue's 3-bit code, bit 0 first.

use autoplug_ecu::pins::{DigitalIn, DigitalOut, Pin, Pull, Signal};

/// The gear engaged, bits 0, 1, 2 (driven by the gearbox; an unplugged line reads 0).
pub const GEAR_ENGAGED: [DigitalIn; 3] = [
    DigitalIn {
        pin: Pin::a(10),
        pull: Pull::Down,
    },
    DigitalIn {
        pin: Pin::b(3),
        pull: Pull::Down,
    },
    DigitalIn {
        pin: Pin::b(10),
        pull: Pull::Down,
    },
];

/// The gear command, bits 0, 1, 2.
pub const GEAR_CMD: [DigitalOut; 3] = [
    DigitalOut { pin: Pin::a(8) },
    DigitalOut { pin: Pin::a(9) },
    DigitalOut { pin: Pin::b(6) },
];

/// Every signal of the board (the CAN pins aside), for checking the board as a whole.
pub const SIGNALS: &[Signal] = &[
    Signal::Input(GEAR_ENGAGED[0]),
    Signal::Input(GEAR_ENGAGED[1]),
    Signal::Input(GEAR_ENGAGED[2]),
    Signal::Output(GEAR_CMD[0]),
    Signal::Output(GEAR_CMD[1]),
    Signal::Output(GEAR_CMD[2]),
];
