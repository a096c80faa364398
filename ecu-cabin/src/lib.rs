//! Cabin comfort ECU (node 0x0A), spec section 2 and report section 5.2.1.3.
//!
//! Reads the cabin temperature and the set-temperature knob (°F), runs PID feedback on the
//! error and drives the fan, 0..100 %. The fan blows air-conditioned (cooled) air, so the
//! error is `cabin − set`: a cabin warmer than the set point raises the fan power; a cabin
//! colder than it gives fan 0 (there is no heater to drive). The PID's output limits are
//! the fan's 0..100 %, and its anti-windup keeps the integral inside them, so a cabin
//! colder than the set point for a long time leaves no negative integral behind and the fan
//! responds as soon as the cabin warms up again.
//!
//! The temperature sensor is noisy (about ±0.2 °F): the reading passes through a
//! first-order low-pass filter ([`MEASUREMENT_FILTER_TAU_S`], far faster than the cabin's
//! minutes-long response) before the PID, so the fan does not chatter. The filtered
//! temperature is what TempMsg publishes. The knob is limited to
//! [`SET_TEMP_MIN_F`]..=[`SET_TEMP_MAX_F`]; a temperature reading that is not a number or
//! outside [`CABIN_TEMP_VALID_F`] (an open or shorted sensor) is ignored: the fan power is
//! held and TempMsg keeps the last good value, until the readings are valid again.
//!
//! Published every 100 ms (and at once on a change): TempMsg (cabin temperature), TempRefMsg
//! (set temperature), FanMsg (fan power).
//!
//! The cabin ECU has no CAN input, hence no stale input and no communication DTC.
#![no_std]
#![deny(missing_docs)]

pub mod pins;

use autoplug_can::{FanMsg, Frame, Node, TempMsg, TempRefMsg};
use autoplug_ecu::{Dtcs, EcuLogic, Instant, PeriodicTx};
use autoplug_pid::{Pid, PidConfig};

/// PID tuning: fan % per °F of `cabin − set`. The cabin responds in minutes (a time
/// constant of about 4 minutes with the fan at half power), so the integral acts slowly;
/// kp gives full fan at 5 °F too warm.
pub const TUNING: PidConfig = PidConfig {
    kp: 20.0,
    ki: 0.15,
    kd: 0.0,
    derivative_filter_tau_s: 0.0,
    output_min: 0.0,
    output_max: 100.0,
};

/// The controller, built at compile time: an invalid `TUNING` fails the build.
const FAN_PID: Pid = Pid::from_tuning(TUNING);

/// Time constant of the low-pass filter on the cabin temperature, s: takes the ±0.2 °F
/// sensor noise down to a few hundredths of a degree while adding a lag that is small
/// against the cabin's minutes.
pub const MEASUREMENT_FILTER_TAU_S: f32 = 5.0;

/// Lowest set temperature the knob gives, °F (a car A/C's usual range).
pub const SET_TEMP_MIN_F: f32 = 60.0;
/// Highest set temperature the knob gives, °F.
pub const SET_TEMP_MAX_F: f32 = 85.0;

// `clamp` panics unless min <= max: checked here, at compile time.
const _: () = assert!(SET_TEMP_MIN_F < SET_TEMP_MAX_F);

/// Readings outside this range, °F, come from a broken sensor and are ignored.
pub const CABIN_TEMP_VALID_F: core::ops::RangeInclusive<f32> = -40.0..=160.0;

/// The part number of this ECU's software (UDS 0xF187), as the virtual car's ECUs answer
/// it.
pub const PART_NUMBER: &str = "AP-CABIN-0001";

/// Control period, µs: the rate of the messages published. The cabin is slow.
pub const STEP_PERIOD_US: u64 = 100_000;

/// Sensor readings.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Sensors {
    /// Cabin temperature, °F.
    pub cabin_temp_f: f32,
    /// Set temperature from the knob, °F.
    pub set_temp_f: f32,
}

/// Actuator commands.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Actuators {
    /// Fan power, 0..=100 %.
    pub fan: f32,
}

/// What the ECU works with, for logs and the virtual car's trace.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[cfg_attr(any(feature = "defmt", target_os = "none"), derive(defmt::Format))]
pub struct Status {
    /// Filtered cabin temperature, °F.
    pub cabin_temp_f: f32,
    /// Set temperature in use (knob limited), °F.
    pub set_temp_f: f32,
    /// Fan power, 0..=100 %.
    pub fan: f32,
}

/// The cabin comfort ECU's logic.
#[derive(Clone, Debug)]
pub struct CabinEcu {
    pid: Pid,
    /// `None` until the first valid reading.
    filtered_f: Option<f32>,
    set_f: f32,
    fan: f32,
    sensor_ok: bool,
    last_step: Option<Instant>,
    tx_temp: PeriodicTx,
    tx_ref: PeriodicTx,
    tx_fan: PeriodicTx,
    dtcs: Dtcs,
}

impl CabinEcu {
    /// The ECU at power-up.
    pub fn new() -> Self {
        Self {
            pid: FAN_PID,
            filtered_f: None,
            set_f: SET_TEMP_MAX_F,
            fan: 0.0,
            sensor_ok: true,
            last_step: None,
            tx_temp: PeriodicTx::of::<TempMsg>(),
            tx_ref: PeriodicTx::of::<TempRefMsg>(),
            tx_fan: PeriodicTx::of::<FanMsg>(),
            dtcs: Dtcs::new(),
        }
    }

    /// What the last step worked with.
    pub fn status(&self) -> Status {
        Status {
            cabin_temp_f: self.filtered_f.unwrap_or(0.0),
            set_temp_f: self.set_f,
            fan: self.fan,
        }
    }

    /// Takes a temperature reading into the filter; returns the filtered value, or `None`
    /// if the reading is invalid.
    fn filter(&mut self, reading: f32, dt_s: f32) -> Option<f32> {
        let valid = reading.is_finite() && CABIN_TEMP_VALID_F.contains(&reading);
        if valid != self.sensor_ok {
            self.sensor_ok = valid;
            if valid {
                autoplug_log::info!("cabin: temperature reading valid again");
            } else {
                autoplug_log::warn!("cabin: invalid temperature reading, last good value kept");
            }
        }
        if !valid {
            return None;
        }
        // Backward-Euler first-order lag: stable for any step.
        let alpha = dt_s / (MEASUREMENT_FILTER_TAU_S + dt_s);
        let filtered = match self.filtered_f {
            Some(previous) => previous + alpha * (reading - previous),
            None => reading,
        };
        self.filtered_f = Some(filtered);
        Some(filtered)
    }
}

impl Default for CabinEcu {
    fn default() -> Self {
        Self::new()
    }
}

impl EcuLogic for CabinEcu {
    type Sensors = Sensors;
    type Actuators = Actuators;

    const NODE: Node = Node::Cabin;
    const STEP_PERIOD_US: u64 = STEP_PERIOD_US;

    /// The cabin ECU receives nothing.
    fn on_frame(&mut self, _now: Instant, _frame: &Frame) {}

    fn step(&mut self, now: Instant, sensors: &Sensors) -> Actuators {
        let dt_s = match self.last_step {
            Some(last) => now.micros_since(last) as f32 * 1e-6,
            None => STEP_PERIOD_US as f32 * 1e-6,
        };
        self.last_step = Some(now);

        if sensors.set_temp_f.is_finite() {
            self.set_f = sensors.set_temp_f.clamp(SET_TEMP_MIN_F, SET_TEMP_MAX_F);
        }
        if let Some(cabin_f) = self.filter(sensors.cabin_temp_f, dt_s) {
            // The PID's error is setpoint − measurement: negating both gives cabin − set,
            // and keeps the derivative (if tuned in) on the cabin temperature.
            self.fan = self.pid.update(-self.set_f, -cabin_f, dt_s);
            self.tx_temp.set_message(&TempMsg {
                cabin_temp: cabin_f,
            });
        }
        self.tx_ref.set_message(&TempRefMsg {
            cabin_set_temp: self.set_f,
        });
        self.tx_fan.set_message(&FanMsg {
            fan_power: self.fan,
        });
        Actuators { fan: self.fan }
    }

    fn poll_transmit(&mut self, now: Instant) -> Option<Frame> {
        self.tx_temp
            .poll(now)
            .or_else(|| self.tx_ref.poll(now))
            .or_else(|| self.tx_fan.poll(now))
    }

    fn dtcs(&self) -> &Dtcs {
        &self.dtcs
    }

    fn dtcs_mut(&mut self) -> &mut Dtcs {
        &mut self.dtcs
    }
}

/// Test cases shared by the host and on-target suites.
#[cfg(any(test, feature = "test-cases"))]
pub mod test_cases;

#[cfg(test)]
mod tests;
