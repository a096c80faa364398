//! Engine ECU (node 0x03), spec section 2 and the report's pseudocode 5.2.1.6.
//!
//! Reads the engine speed, the fuel level and the fuel flow, and publishes them on
//! EngineMsg every 20 ms (and at once on a change), with the engine mode (sport/economy)
//! echoed from the console's AccMsg bit 2. The transmission takes its shift schedule from
//! this echo. The engine ECU drives nothing: [`EcuLogic::step`] returns a [`Status`] of
//! what it reports.
//!
//! Readings are clamped to what EngineMsg can carry: 0..[`ENGINE_RPM_MAX`] rpm and
//! 0..[`FUEL_LEVEL_MAX_L`] L (0.25 L per bit); an unreadable (NaN) sensor reports 0.
//!
//! The fuel flow (0..[`FUEL_FLOW_MAX_L_PER_H`]) is integrated over each step's measured
//! time into the fuel used since power-up, sent as a rolling 1 mL counter (EngineMsg
//! `FuelUsed`, wrapping after 65535 mL). The level's 0.25 L steps cannot tell a trip's
//! fuel to better than a step; the counter tells it to a millilitre, as a production ECU's
//! consumption signal does. The sub-millilitre remainder is carried over, so rounding never
//! accumulates.
//!
//! Safe state per stale input (3 periods without a valid frame):
//!
//! | input | stale after | safe state | DTC |
//! |---|---|---|---|
//! | AccMsg | 300 ms | report **economy** mode: the transmission then uses the gentler, earlier-shifting schedule, the conservative choice when the driver's choice is unknown | lost communication with the console ECU |
//!
//! For the same reason the engine reports economy from power-up until the first valid
//! AccMsg arrives.
#![no_std]
#![deny(missing_docs)]

pub mod pins;

use autoplug_can::{AccMsg, EngineMode, EngineMsg, Frame, Node};
use autoplug_ecu::{receive, supervise, Dtcs, EcuLogic, Input, Instant, PeriodicTx};
use autoplug_scaling::clamp_finite;

// The published parameters (calibration, thresholds, trouble codes) live with the
// other ECUs' in `autoplug-ecu-params`, where the gateway's diagnostics read them.
pub use autoplug_ecu_params::engine::*;

/// Highest engine speed at which the engine ECU lets itself be reprogrammed, rpm: engine
/// off or idling (the EVO VI idles at 850 rpm), never while driven.
pub const PROGRAMMING_MAX_RPM: f32 = 1200.0;

/// Highest engine speed EngineMsg carries, rpm (raw 255); above the EVO VI's red line.
pub const ENGINE_RPM_MAX: f32 = 9000.0;

/// Highest fuel level EngineMsg carries, litres (raw 255 at 0.25 L); the tank holds 48 L.
pub const FUEL_LEVEL_MAX_L: f32 = 63.75;

/// Longest step the fuel integration trusts, µs: a longer gap (a stalled loop, a clock
/// jump) counts as this long, so one bad timestamp cannot add litres.
pub const FUEL_MAX_STEP_US: u64 = 1_000_000;

/// Where the rolling fuel counter wraps, mL (16 bits).
pub const FUEL_USED_WRAP_ML: u32 = 1 << 16;

/// The engine mode reported while the console's choice is unknown (see the crate docs).
pub const SAFE_ENGINE_MODE: EngineMode = EngineMode::Economy;

/// The part number of this ECU's software (UDS 0xF187), as the virtual car's ECUs answer
/// it.
pub const PART_NUMBER: &str = "AP-ENGINE-0001";

/// Control period: the rate EngineMsg is published at.
pub const STEP_PERIOD_US: u64 = 20_000;

/// Engine sensor readings.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Sensors {
    /// Engine speed, rpm.
    pub engine_rpm: f32,
    /// Fuel in the tank, litres.
    pub fuel_level_l: f32,
    /// Fuel flow to the engine, litres per hour.
    pub fuel_flow_l_per_h: f32,
}

/// The engine ECU drives no actuator: this is what it reports on EngineMsg.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Status {
    /// Engine speed reported, rpm, 0..9000.
    pub engine_rpm: f32,
    /// Fuel level reported, litres, 0..63.75.
    pub fuel_level_l: f32,
    /// Engine mode echoed (economy while AccMsg is stale or not yet received).
    pub engine_mode: EngineMode,
    /// Fuel used since power-up, mL, as sent (rolling: 0..65535).
    pub fuel_used_ml: u16,
}

impl Default for Status {
    fn default() -> Self {
        Self {
            engine_rpm: 0.0,
            fuel_level_l: 0.0,
            engine_mode: SAFE_ENGINE_MODE,
            fuel_used_ml: 0,
        }
    }
}

/// The engine ECU's logic.
#[derive(Clone, Debug)]
pub struct EngineEcu {
    /// Engine speed at the last step, rpm.
    last_rpm: f32,
    console: Input<AccMsg>,
    tx_engine: PeriodicTx,
    dtcs: Dtcs,
    fuel: FuelCounter,
}

/// The fuel used since power-up: whole microlitres and the fraction carried over.
#[derive(Clone, Debug, Default)]
struct FuelCounter {
    last_step: Option<Instant>,
    used_ul: u64,
    fraction_ul: f32,
}

impl FuelCounter {
    /// Adds the flow since the last step; returns the rolling mL counter.
    fn integrate(&mut self, now: Instant, flow_l_per_h: f32) -> u16 {
        let flow = clamp_finite(flow_l_per_h, 0.0, FUEL_FLOW_MAX_L_PER_H);
        if let Some(last) = self.last_step {
            let dt_us = now.micros_since(last).min(FUEL_MAX_STEP_US);
            // L/h over µs in µL: 1 L/h is 1e6 µL per 3.6e9 µs.
            let ul = flow * dt_us as f32 / 3600.0 + self.fraction_ul;
            let whole = ul as u64;
            self.fraction_ul = ul - whole as f32;
            self.used_ul += whole;
        }
        self.last_step = Some(now);
        ((self.used_ul / 1000) % u64::from(FUEL_USED_WRAP_ML)) as u16
    }
}

impl EngineEcu {
    /// The ECU at power-up (`now`).
    pub fn new(now: Instant) -> Self {
        Self {
            last_rpm: 0.0,
            console: Input::new(now),
            tx_engine: PeriodicTx::of::<EngineMsg>(),
            dtcs: Dtcs::new(),
            fuel: FuelCounter::default(),
        }
    }
}

impl EcuLogic for EngineEcu {
    type Sensors = Sensors;
    type Actuators = Status;

    const NODE: Node = Node::Engine;
    const STEP_PERIOD_US: u64 = STEP_PERIOD_US;

    fn on_frame(&mut self, now: Instant, frame: &Frame) {
        receive(&mut self.console, &mut self.dtcs, now, frame);
    }

    fn step(&mut self, now: Instant, sensors: &Sensors) -> Status {
        let stale = supervise(&mut self.console, &mut self.dtcs, now);
        let engine_mode = if stale || !self.console.ever_received() {
            SAFE_ENGINE_MODE
        } else {
            self.console.value().engine_mode
        };
        self.last_rpm = clamp_finite(sensors.engine_rpm, 0.0, ENGINE_RPM_MAX);
        let status = Status {
            engine_rpm: self.last_rpm,
            fuel_level_l: clamp_finite(sensors.fuel_level_l, 0.0, FUEL_LEVEL_MAX_L),
            engine_mode,
            fuel_used_ml: self.fuel.integrate(now, sensors.fuel_flow_l_per_h),
        };
        self.tx_engine.set_message(&EngineMsg {
            engine_rpm: status.engine_rpm,
            fuel_level: status.fuel_level_l,
            engine_mode: status.engine_mode,
            fuel_used: f32::from(status.fuel_used_ml),
        });
        status
    }

    fn poll_transmit(&mut self, now: Instant) -> Option<Frame> {
        self.tx_engine.poll(now)
    }

    fn dtcs(&self) -> &Dtcs {
        &self.dtcs
    }

    fn dtcs_mut(&mut self) -> &mut Dtcs {
        &mut self.dtcs
    }

    fn own_sensors_show_motion(&self) -> bool {
        self.last_rpm > PROGRAMMING_MAX_RPM
    }
}

/// Test cases shared by the host and on-target suites.
#[cfg(any(test, feature = "test-cases"))]
pub mod test_cases;

#[cfg(test)]
mod tests;
