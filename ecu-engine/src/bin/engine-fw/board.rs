//! The engine ECU's board: a Nucleo-F446RE wired to the bench, its pins and scales (declared in
//! `ecu_engine::pins`, which the virtual car drives too) taken from the HAL.
//!
//! | Arduino | Morpho | MCU pin | signal | direction | electrical range |
//! |---|---|---|---|---|---|
//! | D15 | CN10-3 | PB8 | CAN1 RX (AF9) from the transceiver's RXD | in | 3.3 V logic |
//! | D14 | CN10-5 | PB9 | CAN1 TX (AF9) to the transceiver's TXD | out | 3.3 V logic |
//! | A0 | CN7-28 | PA0 | engine speed (ADC1_IN0) | in | 0–3.3 V = 0–9000 rpm |
//! | A1 | CN7-30 | PA1 | fuel level (ADC1_IN1) | in | 0–3.3 V = 0–63.75 L |
//! | A2 | CN7-32 | PA4 | fuel flow (ADC1_IN4) | in | 0–3.3 V = 0–150 L/h |
//!
//! The engine ECU drives nothing: it reports on EngineMsg.

use autoplug_firmware::analog::LinearInput;
use autoplug_firmware::io::{read_analog, AnalogPin};
use autoplug_firmware::runtime::{Io, Platform};
use ecu_engine::{pins, EngineEcu, Sensors, Status};
use embassy_stm32::adc::{Adc, AdcChannel};
use embassy_stm32::peripherals::ADC1;

/// Engine speed: 0–3.3 V is 0–9000 rpm.
const ENGINE_SPEED: LinearInput = pins::ENGINE_SPEED.scale;
/// Fuel level: 0–3.3 V is an empty to a full tank.
const FUEL_LEVEL: LinearInput = pins::FUEL_LEVEL.scale;
/// Fuel flow: 0–3.3 V is no flow to the input's maximum (a flow meter's analog output).
const FUEL_FLOW: LinearInput = pins::FUEL_FLOW.scale;

/// The engine ECU's sensors.
pub struct Board {
    adc: Adc<'static, ADC1>,
    engine_speed: AnalogPin,
    fuel_level: AnalogPin,
    fuel_flow: AnalogPin,
}

/// Brings up the clocks, CAN1 and the sensor inputs.
pub fn init() -> (Platform, Board) {
    autoplug_firmware::board_init!(p, platform);
    let board = Board {
        adc: Adc::new(p.ADC1),
        engine_speed: p.PA0.degrade_adc(),
        fuel_level: p.PA1.degrade_adc(),
        fuel_flow: p.PA4.degrade_adc(),
    };
    (platform, board)
}

impl Io<EngineEcu> for Board {
    fn read(&mut self) -> Sensors {
        Sensors {
            engine_rpm: read_analog(&mut self.adc, &mut self.engine_speed, &ENGINE_SPEED),
            fuel_level_l: read_analog(&mut self.adc, &mut self.fuel_level, &FUEL_LEVEL),
            fuel_flow_l_per_h: read_analog(&mut self.adc, &mut self.fuel_flow, &FUEL_FLOW),
        }
    }

    fn write(&mut self, _status: &Status) {
        // Nothing to drive: the status goes out on EngineMsg.
    }
}
