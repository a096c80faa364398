//! The cruise control ECU's board: a Nucleo-F446RE wired to the bench, its pins and scales (declared in
//! `ecu_cruise::pins`, which the virtual car drives too) taken from the HAL.
//!
//! | Arduino | Morpho | MCU pin | signal | direction | electrical range |
//! |---|---|---|---|---|---|
//! | D15 | CN10-3 | PB8 | CAN1 RX (AF9) from the transceiver's RXD | in | 3.3 V logic |
//! | D14 | CN10-5 | PB9 | CAN1 TX (AF9) to the transceiver's TXD | out | 3.3 V logic |
//! | A0 | CN7-28 | PA0 | vehicle speed (ADC1_IN0) | in | 0–3.3 V = 0–255 km/h |
//! | D13 (LD2) | CN10-11 | PA5 | cruise engaged lamp (the Nucleo's green LED) | out | 3.3 V push-pull, high = engaged |
//!
//! The cruise command itself has no pin: it reaches the pedals ECU over CAN. Safe state
//! at power-up: lamp off, cruise disengaged.

use autoplug_firmware::analog::LinearInput;
use autoplug_firmware::io::{read_analog, AnalogPin};
use autoplug_firmware::runtime::{Io, Platform};
use ecu_cruise::{pins, CruiseEcu, Sensors, Status};
use embassy_stm32::adc::{Adc, AdcChannel};
use embassy_stm32::gpio::{Level, Output, Speed};
use embassy_stm32::peripherals::ADC1;

/// The speed signal: 0–3.3 V is 0–255 km/h (VehicleSpeedMsg's range).
const VEHICLE_SPEED: LinearInput = pins::VEHICLE_SPEED.scale;

/// The cruise ECU's sensor and lamp.
pub struct Board {
    adc: Adc<'static, ADC1>,
    vehicle_speed: AnalogPin,
    engaged_lamp: Output<'static>,
}

/// Brings up the clocks, CAN1 and the I/O; the lamp starts off.
pub fn init() -> (Platform, Board) {
    autoplug_firmware::board_init!(p, platform);
    let board = Board {
        adc: Adc::new(p.ADC1),
        vehicle_speed: p.PA0.degrade_adc(),
        engaged_lamp: Output::new(p.PA5, Level::Low, Speed::Low),
    };
    (platform, board)
}

impl Io<CruiseEcu> for Board {
    fn read(&mut self) -> Sensors {
        Sensors {
            vehicle_speed_kmh: read_analog(&mut self.adc, &mut self.vehicle_speed, &VEHICLE_SPEED),
        }
    }

    fn write(&mut self, status: &Status) {
        self.engaged_lamp.set_level(Level::from(status.engaged));
    }
}
