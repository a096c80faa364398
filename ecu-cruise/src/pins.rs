//! The cruise control ECU board's signals (the pins `src/bin/cruise-fw/board.rs` wires to the HAL, and
//! the virtual car drives from the vehicle model): pin, channel and scaling, named once.

use autoplug_ecu::pins::{AnalogIn, DigitalOut, LinearInput, Pin, Signal};

/// Vehicle speed: 0–3.3 V is 0–255 km/h (VehicleSpeedMsg's range).
pub const VEHICLE_SPEED: AnalogIn = AnalogIn {
    pin: Pin::a(0),
    adc_channel: 0,
    scale: LinearInput::new(0.0, 255.0),
};

/// The cruise engaged lamp (the Nucleo's green LED): high = engaged.
pub const ENGAGED_LAMP: DigitalOut = DigitalOut { pin: Pin::a(5) };

/// Every signal of the board (the CAN pins aside), for checking the board as a whole.
pub const SIGNALS: &[Signal] = &[Signal::Analog(VEHICLE_SPEED), Signal::Output(ENGAGED_LAMP)];
