//! The transmission ECU's board: a Nucleo-F446RE wired to the bench, its pins and scales (declared in
//! `ecu_trans::pins`, which the virtual car drives too) taken from the HAL.
//!
//! | Arduino | Morpho | MCU pin | signal | direction | electrical range |
//! |---|---|---|---|---|---|
//! | D15 | CN10-3 | PB8 | CAN1 RX (AF9) from the transceiver's RXD | in | 3.3 V logic |
//! | D14 | CN10-5 | PB9 | CAN1 TX (AF9) to the transceiver's TXD | out | 3.3 V logic |
//! | D2 | CN10-33 | PA10 | gear engaged, bit 0 | in | 3.3 V logic (internal pull-down) |
//! | D3 | CN10-31 | PB3 | gear engaged, bit 1 | in | 3.3 V logic (internal pull-down) |
//! | D6 | CN10-25 | PB10 | gear engaged, bit 2 | in | 3.3 V logic (internal pull-down) |
//! | D7 | CN10-23 | PA8 | gear command, bit 0 | out | 3.3 V push-pull |
//! | D8 | CN10-21 | PA9 | gear command, bit 1 | out | 3.3 V push-pull |
//! | D10 | CN10-17 | PB6 | gear command, bit 2 | out | 3.3 V push-pull |
//!
//! Both sets of lines carry the gear as the catalogue's 3-bit code (0 reverse, 1 neutral,
//! 2–7 first to sixth). An unplugged gearbox reads 0 (reverse); as it never follows a
//! command, the logic records "gear not engaged" (P0730). PB3 is also the SWO trace pin:
//! leave SWO off. Safe state at power-up: neutral commanded.

use autoplug_can::Gear;
use autoplug_firmware::runtime::{Io, Platform};
use ecu_trans::{Actuators, Sensors, TransEcu};
use embassy_stm32::gpio::{Input, Level, Output, Pull, Speed};

/// The transmission ECU's gear lines.
pub struct Board {
    /// Gear engaged, bits 0, 1, 2.
    gear_engaged: [Input<'static>; 3],
    /// Gear command, bits 0, 1, 2.
    gear_cmd: [Output<'static>; 3],
}

/// Brings up the clocks, CAN1 and the I/O; neutral is commanded.
pub fn init() -> (Platform, Board) {
    autoplug_firmware::board_init!(p, platform);
    let mut board = Board {
        gear_engaged: [
            Input::new(p.PA10, Pull::Down),
            Input::new(p.PB3, Pull::Down),
            Input::new(p.PB10, Pull::Down),
        ],
        gear_cmd: [
            Output::new(p.PA8, Level::Low, Speed::Low),
            Output::new(p.PA9, Level::Low, Speed::Low),
            Output::new(p.PB6, Level::Low, Speed::Low),
        ],
    };
    <Board as Io<TransEcu>>::write(&mut board, &Actuators::default());
    (platform, board)
}

impl Io<TransEcu> for Board {
    fn read(&mut self) -> Sensors {
        let code = self
            .gear_engaged
            .iter()
            .enumerate()
            .fold(0, |code, (bit, line)| {
                code | (i64::from(line.is_high()) << bit)
            });
        Sensors {
            // Every 3-bit code is a gear.
            current_gear: Gear::from_raw(code).unwrap_or(Gear::Neutral),
        }
    }

    fn write(&mut self, actuators: &Actuators) {
        let code = actuators.gear_cmd.raw();
        for (bit, line) in self.gear_cmd.iter_mut().enumerate() {
            line.set_level(Level::from(code >> bit & 1 == 1));
        }
    }
}
