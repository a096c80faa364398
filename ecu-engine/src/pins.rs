//! The engine ECU board's signals (the pins `src/bin/engine-fw/board.rs` wires to the HAL, and
//! the virtual car drives from the vehicle model): pin, channel and scaling, named once.

use crate::{ENGINE_RPM_MAX, FUEL_FLOW_MAX_L_PER_H, FUEL_LEVEL_MAX_L};
use autoplug_ecu::pins::{AnalogIn, LinearInput, Pin, Signal};

/// Engine speed: 0–3.3 V is 0–9000 rpm.
pub const ENGINE_SPEED: AnalogIn = AnalogIn {
    pin: Pin::a(0),
    adc_channel: 0,
    scale: LinearInput::new(0.0, ENGINE_RPM_MAX),
};

/// Fuel level: 0–3.3 V is an empty to a full tank.
pub const FUEL_LEVEL: AnalogIn = AnalogIn {
    pin: Pin::a(1),
    adc_channel: 1,
    scale: LinearInput::new(0.0, FUEL_LEVEL_MAX_L),
};

/// Fuel flow: 0–3.3 V is no flow to the input's maximum (a flow meter's analog output).
pub const FUEL_FLOW: AnalogIn = AnalogIn {
    pin: Pin::a(4),
    adc_channel: 4,
    scale: LinearInput::new(0.0, FUEL_FLOW_MAX_L_PER_H),
};

/// Every signal of the board (the CAN pins aside), for checking the board as a whole.
pub const SIGNALS: &[Signal] = &[
    Signal::Analog(ENGINE_SPEED),
    Signal::Analog(FUEL_LEVEL),
    Signal::Analog(FUEL_FLOW),
];
