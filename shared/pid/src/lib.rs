//! PID controller shared by the AutoPlug ECUs (cruise control, ABS, idle speed, ...) and
//! by their host-side twins in the vehicle simulation, so both run the same arithmetic.
//!
//! Design points, each chosen for actuators on a real car:
//!
//! - **Anti-windup, twice over.** The integral is stored as its contribution to the output
//!   and clamped to the output limits, so it can never hold more authority than the
//!   actuator has. On top of that, integration is *conditional*: when the unclamped output
//!   is already past a limit and the error pushes further that way, the integrator stops.
//!   A long saturation (hill climb at full throttle) therefore leaves no stored excess, and
//!   the controller comes off the limit as soon as the error turns.
//! - **Derivative on the measurement**, not the error: a set-point step (driver presses
//!   "+5 km/h") gives no derivative kick. It passes through a first-order low-pass filter,
//!   because a raw difference of a quantised CAN signal is mostly noise.
//! - **Integral with the past error** (forward Euler): an update outputs `P + I + D` with
//!   the integral accumulated so far, then integrates its own error. So the first update
//!   after a reset is exactly the P response, and the anti-windup decision is taken on the
//!   very output that was sent.
//! - **Total**: no panics, no allocation, no NaN. Invalid inputs leave the state untouched
//!   and repeat the last output; every stored value stays finite.
//!
//! Tuning lives in `const`s. Building the controller in a `const` too turns a bad tuning
//! into a compile error instead of a run-time `Err`:
//!
//! ```
//! use autoplug_pid::{Pid, PidConfig};
//!
//! const CRUISE_TUNING: PidConfig = PidConfig {
//!     kp: 8.0,
//!     ki: 1.5,
//!     kd: 0.0,
//!     derivative_filter_tau_s: 0.0,
//!     output_min: 0.0,
//!     output_max: 100.0,
//! };
//! const CRUISE_PID: Pid = Pid::from_tuning(CRUISE_TUNING);
//!
//! let mut pid = CRUISE_PID;
//! let throttle = pid.update(27.8, 25.0, 0.01);
//! assert!((0.0..=100.0).contains(&throttle));
//! ```
#![no_std]
#![deny(missing_docs)]

use core::fmt;

/// Gains, derivative filter and output limits of a [`Pid`].
///
/// The fields are public so that a tuning is a plain struct literal in a `const`;
/// [`PidConfig::validate`] (a `const fn`) or [`Pid::new`] checks it.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PidConfig {
    /// Proportional gain: output units per unit of error. Finite, `>= 0`.
    pub kp: f32,
    /// Integral gain: output units per unit of error per second. Finite, `>= 0`.
    pub ki: f32,
    /// Derivative gain: output units per unit of measurement change per second.
    /// Finite, `>= 0`.
    pub kd: f32,
    /// Time constant, in seconds, of the low-pass filter on the derivative; `0` leaves
    /// the derivative unfiltered. Finite, `>= 0`.
    pub derivative_filter_tau_s: f32,
    /// Lowest output the actuator accepts. Finite, below `output_max`.
    pub output_min: f32,
    /// Highest output the actuator accepts. Finite, above `output_min`.
    pub output_max: f32,
}

/// One of the three gains, to say which one a [`PidConfigError`] is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Gain {
    /// `kp`.
    Proportional,
    /// `ki`.
    Integral,
    /// `kd`.
    Derivative,
}

/// What is wrong with a [`PidConfig`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PidConfigError {
    /// A gain is NaN or infinite.
    NonFiniteGain(Gain),
    /// A gain is negative. A reverse-acting loop swaps set point and measurement instead,
    /// so that all three terms keep one sign convention.
    NegativeGain(Gain),
    /// The derivative filter time constant is NaN or infinite.
    NonFiniteFilterTau,
    /// The derivative filter time constant is negative.
    NegativeFilterTau,
    /// An output limit is NaN or infinite: the output must always be a finite command.
    NonFiniteLimit,
    /// `output_min >= output_max`: there is no room to control in.
    MinNotBelowMax,
}

impl fmt::Display for Gain {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Gain::Proportional => "proportional gain kp",
            Gain::Integral => "integral gain ki",
            Gain::Derivative => "derivative gain kd",
        })
    }
}

impl fmt::Display for PidConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PidConfigError::NonFiniteGain(gain) => write!(f, "{gain} is not finite"),
            PidConfigError::NegativeGain(gain) => write!(f, "{gain} is negative"),
            PidConfigError::NonFiniteFilterTau => {
                f.write_str("derivative filter time constant is not finite")
            }
            PidConfigError::NegativeFilterTau => {
                f.write_str("derivative filter time constant is negative")
            }
            PidConfigError::NonFiniteLimit => f.write_str("an output limit is not finite"),
            PidConfigError::MinNotBelowMax => f.write_str("output_min is not below output_max"),
        }
    }
}

impl core::error::Error for PidConfigError {}

impl PidConfig {
    /// Checks every field; the first problem found is reported (gains in the order
    /// kp, ki, kd, then the filter, then the limits).
    ///
    /// A `const fn`, so `const _: () = assert!(TUNING.validate().is_ok());` checks a tuning
    /// at compile time.
    pub const fn validate(&self) -> Result<(), PidConfigError> {
        if let Err(e) = check_gain(self.kp, Gain::Proportional) {
            return Err(e);
        }
        if let Err(e) = check_gain(self.ki, Gain::Integral) {
            return Err(e);
        }
        if let Err(e) = check_gain(self.kd, Gain::Derivative) {
            return Err(e);
        }
        if !self.derivative_filter_tau_s.is_finite() {
            return Err(PidConfigError::NonFiniteFilterTau);
        }
        if self.derivative_filter_tau_s < 0.0 {
            return Err(PidConfigError::NegativeFilterTau);
        }
        if !self.output_min.is_finite() || !self.output_max.is_finite() {
            return Err(PidConfigError::NonFiniteLimit);
        }
        if self.output_min >= self.output_max {
            return Err(PidConfigError::MinNotBelowMax);
        }
        Ok(())
    }

    /// `x` clamped to the output limits. Relies on validated limits; never panics.
    const fn clamp_output(&self, x: f32) -> f32 {
        clamp(x, self.output_min, self.output_max)
    }
}

const fn check_gain(value: f32, gain: Gain) -> Result<(), PidConfigError> {
    if !value.is_finite() {
        Err(PidConfigError::NonFiniteGain(gain))
    } else if value < 0.0 {
        Err(PidConfigError::NegativeGain(gain))
    } else {
        Ok(())
    }
}

/// The terms that made up one output, for telemetry and diagnostics.
///
/// `output` is `proportional + integral + derivative` clamped to the output limits.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PidTerms {
    /// `kp * (setpoint - measurement)`.
    pub proportional: f32,
    /// The integral as it entered the output (accumulated before this update's error).
    pub integral: f32,
    /// `-kd * filtered d(measurement)/dt`; zero on the first update after a reset.
    pub derivative: f32,
    /// The command that was returned.
    pub output: f32,
}

/// A PID controller with anti-windup, a filtered derivative on the measurement and an
/// integrator that can be held. See the crate documentation for the design.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Pid {
    config: PidConfig,
    /// Integral contribution to the output; always within the output limits.
    integral: f32,
    /// Low-pass filtered rate of change of the measurement, per second.
    measurement_rate: f32,
    /// `None` until the first valid update: no derivative without a previous sample.
    previous_measurement: Option<f32>,
    integrator_held: bool,
    last: PidTerms,
}

impl Pid {
    /// A controller for a tuning known to be valid: meant for `const` items, where an
    /// invalid tuning stops the build (the panic happens during constant evaluation, never
    /// at run time). Use [`Pid::new`] for a configuration only known at run time.
    ///
    /// ```compile_fail
    /// use autoplug_pid::{Pid, PidConfig};
    /// // A negative gain: this does not compile.
    /// const BAD: Pid = Pid::from_tuning(PidConfig {
    ///     kp: -1.0,
    ///     ki: 0.0,
    ///     kd: 0.0,
    ///     derivative_filter_tau_s: 0.0,
    ///     output_min: 0.0,
    ///     output_max: 1.0,
    /// });
    /// fn main() {
    ///     let _ = BAD;
    /// }
    /// ```
    pub const fn from_tuning(config: PidConfig) -> Self {
        match Self::new(config) {
            Ok(pid) => pid,
            Err(_) => panic!("invalid PID tuning"),
        }
    }

    /// A controller in its reset state, or what is wrong with `config`.
    ///
    /// A `const fn`: see the crate documentation for building it in a `const`.
    pub const fn new(config: PidConfig) -> Result<Self, PidConfigError> {
        if let Err(e) = config.validate() {
            return Err(e);
        }
        let integral = config.clamp_output(0.0);
        Ok(Self {
            config,
            integral,
            measurement_rate: 0.0,
            previous_measurement: None,
            integrator_held: false,
            last: PidTerms {
                proportional: 0.0,
                integral,
                derivative: 0.0,
                output: integral,
            },
        })
    }

    /// One control step: the command for `measurement` to follow `setpoint`, `dt_s`
    /// seconds after the previous update. Always finite and within the output limits.
    ///
    /// If any input is NaN or infinite, or `dt_s <= 0`, nothing is updated and the last
    /// output is returned again: a bad sample or a stalled clock must neither corrupt the
    /// integral nor make the actuator jump.
    pub fn update(&mut self, setpoint: f32, measurement: f32, dt_s: f32) -> f32 {
        let inputs_valid =
            setpoint.is_finite() && measurement.is_finite() && dt_s.is_finite() && dt_s > 0.0;
        if !inputs_valid {
            return self.last.output;
        }
        let c = self.config;

        // Each term is kept finite, so their sum can overflow to ±inf but never be NaN.
        let error = saturate(setpoint - measurement);
        let proportional = saturate(c.kp * error);

        let derivative = match self.previous_measurement {
            None => 0.0,
            Some(previous) => {
                let raw_rate = saturate((measurement - previous) / dt_s);
                // Backward-Euler first-order lag: stable for any dt, needs no exp(), and
                // tau = 0 gives alpha = 1 (unfiltered).
                let alpha = dt_s / (c.derivative_filter_tau_s + dt_s);
                self.measurement_rate =
                    saturate((1.0 - alpha) * self.measurement_rate + alpha * raw_rate);
                saturate(-c.kd * self.measurement_rate)
            }
        };
        self.previous_measurement = Some(measurement);

        let integral_used = self.integral;
        let unclamped = proportional + integral_used + derivative;
        let output = c.clamp_output(unclamped);

        let pushes_further_into_saturation =
            (unclamped > c.output_max && error > 0.0) || (unclamped < c.output_min && error < 0.0);
        if !self.integrator_held && !pushes_further_into_saturation {
            self.integral = c.clamp_output(self.integral + c.ki * error * dt_s);
        }

        self.last = PidTerms {
            proportional,
            integral: integral_used,
            derivative,
            output,
        };
        output
    }

    /// Back to the state after [`Pid::new`]: integral zero (or the limit nearest to zero
    /// if zero is outside the output range), derivative filter cleared, no previous
    /// measurement (so the next update has no derivative term), terms zeroed.
    ///
    /// The configuration and the integrator hold are kept: a hold is a mode the caller
    /// chose, not accumulated state.
    pub fn reset(&mut self) {
        let integral = self.config.clamp_output(0.0);
        self.integral = integral;
        self.measurement_rate = 0.0;
        self.previous_measurement = None;
        self.last = PidTerms {
            proportional: 0.0,
            integral,
            derivative: 0.0,
            output: integral,
        };
    }

    /// Freezes the integral: updates keep computing P and D but leave the integral as it
    /// is. For phases where the error says nothing about the steady state (ABS pressure
    /// pulsing, cruise disengaged).
    ///
    /// Only [`Pid::update`] is affected; [`Pid::set_integral`], [`Pid::reset`] and new
    /// limits still act on the integral.
    pub fn hold_integrator(&mut self) {
        self.integrator_held = true;
    }

    /// Lets updates integrate again after [`Pid::hold_integrator`].
    pub fn release_integrator(&mut self) {
        self.integrator_held = false;
    }

    /// Whether the integrator is held.
    pub fn is_integrator_held(&self) -> bool {
        self.integrator_held
    }

    /// Sets the integral contribution, clamped to the output limits; a non-finite value is
    /// ignored. For bumpless transfer: loading the current command (e.g. the throttle when
    /// cruise engages) makes the first output continue from it instead of from zero.
    pub fn set_integral(&mut self, value: f32) {
        if value.is_finite() {
            self.integral = self.config.clamp_output(value);
        }
    }

    /// The integral contribution the next update will add to its output.
    pub fn integral(&self) -> f32 {
        self.integral
    }

    /// The terms of the last update (zeroed after construction or reset).
    pub fn terms(&self) -> PidTerms {
        self.last
    }

    /// Proportional term of the last update.
    pub fn proportional(&self) -> f32 {
        self.last.proportional
    }

    /// Derivative term of the last update.
    pub fn derivative(&self) -> f32 {
        self.last.derivative
    }

    /// The last output, within the current limits.
    pub fn output(&self) -> f32 {
        self.last.output
    }

    /// The configuration in use.
    pub fn config(&self) -> PidConfig {
        self.config
    }

    /// Retunes the controller without resetting it. An invalid `config` is rejected and
    /// changes nothing.
    ///
    /// The integral is stored as an output contribution, so a new `ki` does not bump the
    /// output; the integral and the last output are re-clamped to the new limits.
    pub fn set_config(&mut self, config: PidConfig) -> Result<(), PidConfigError> {
        config.validate()?;
        self.config = config;
        self.integral = config.clamp_output(self.integral);
        self.last.output = config.clamp_output(self.last.output);
        Ok(())
    }

    /// New gains, keeping filter, limits and state; see [`Pid::set_config`].
    pub fn set_gains(&mut self, kp: f32, ki: f32, kd: f32) -> Result<(), PidConfigError> {
        self.set_config(PidConfig {
            kp,
            ki,
            kd,
            ..self.config
        })
    }

    /// New output limits, re-clamping the integral and the last output; see
    /// [`Pid::set_config`].
    pub fn set_limits(&mut self, output_min: f32, output_max: f32) -> Result<(), PidConfigError> {
        self.set_config(PidConfig {
            output_min,
            output_max,
            ..self.config
        })
    }
}

/// Maps ±inf to ±`f32::MAX` and NaN to zero, so that intermediate terms stay finite.
fn saturate(x: f32) -> f32 {
    if x.is_nan() {
        0.0
    } else {
        clamp(x, f32::MIN, f32::MAX)
    }
}

/// `x` clamped to `[lo, hi]`, NaN to `lo`. Unlike `f32::clamp`, never panics.
const fn clamp(x: f32, lo: f32, hi: f32) -> f32 {
    if x.is_nan() || x < lo {
        lo
    } else if x > hi {
        hi
    } else {
        x
    }
}

#[cfg(any(test, feature = "test-cases"))]
pub mod test_cases;

#[cfg(test)]
mod tests;
