//! The console ECU's board: a Nucleo-F446RE wired to the bench, its pins and scales (declared in
//! `ecu_console::pins`, which the virtual car drives too) taken from the HAL.
//!
//! | Arduino | Morpho | MCU pin | signal | direction | electrical range |
//! |---|---|---|---|---|---|
//! | D15 | CN10-3 | PB8 | CAN1 RX (AF9) from the transceiver's RXD | in | 3.3 V logic |
//! | D14 | CN10-5 | PB9 | CAN1 TX (AF9) to the transceiver's TXD | out | 3.3 V logic |
//! | D2 | CN10-33 | PA10 | headlight switch | in | to GND = on (internal pull-up) |
//! | D3 | CN10-31 | PB3 | engine-mode switch | in | to GND = economy, open = sport (internal pull-up) |
//! | D6 | CN10-25 | PB10 | transmission-mode switch | in | to GND = manual, open = automatic (internal pull-up) |
//! | D7 | CN10-23 | PA8 | headlights | out | 3.3 V push-pull, high = on, to a lamp driver |
//! | D8 | CN10-21 | PA9 | brake lights | out | 3.3 V push-pull, high = on, to a lamp driver |
//!
//! A lamp output drives an LED through a resistor, or the gate of a logic-level MOSFET that
//! switches a real lamp. PB3 is also the SWO trace pin: leave SWO off. Safe state at
//! power-up: lamps off until the first step.

use autoplug_firmware::runtime::{Io, Platform};
use ecu_console::{Actuators, ConsoleEcu, Sensors};
use embassy_stm32::gpio::{Input, Level, Output, Pull, Speed};

/// The console ECU's switches and lamps.
pub struct Board {
    headlight_switch: Input<'static>,
    engine_mode_switch: Input<'static>,
    transmission_mode_switch: Input<'static>,
    headlights: Output<'static>,
    brake_lights: Output<'static>,
}

/// Brings up the clocks, CAN1 and the I/O; the lamps start off.
pub fn init() -> (Platform, Board) {
    autoplug_firmware::board_init!(p, platform);
    let board = Board {
        headlight_switch: Input::new(p.PA10, Pull::Up),
        engine_mode_switch: Input::new(p.PB3, Pull::Up),
        transmission_mode_switch: Input::new(p.PB10, Pull::Up),
        headlights: Output::new(p.PA8, Level::Low, Speed::Low),
        brake_lights: Output::new(p.PA9, Level::Low, Speed::Low),
    };
    (platform, board)
}

impl Io<ConsoleEcu> for Board {
    fn read(&mut self) -> Sensors {
        Sensors {
            headlight_switch: self.headlight_switch.is_low(),
            economy_mode_switch: self.engine_mode_switch.is_low(),
            manual_mode_switch: self.transmission_mode_switch.is_low(),
        }
    }

    fn write(&mut self, actuators: &Actuators) {
        self.headlights.set_level(Level::from(actuators.headlights));
        self.brake_lights
            .set_level(Level::from(actuators.brake_lights));
    }
}
