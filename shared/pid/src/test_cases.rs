//! Test cases shared by the host test suite and the on-target (defmt-test) suite, so the
//! Cortex-M4 run checks exactly what the host run checks. Each case panics on failure.

use crate::{Gain, Pid, PidConfig, PidConfigError};

/// Control period of the ECU tasks.
const DT_S: f32 = 0.01;

/// A valid tuning that the cases vary one field at a time.
const BASE: PidConfig = PidConfig {
    kp: 1.0,
    ki: 0.5,
    kd: 0.1,
    derivative_filter_tau_s: 0.05,
    output_min: -10.0,
    output_max: 10.0,
};

/// Built at compile time: an invalid tuning here would fail the build, not the test.
const BASE_PID: Pid = match Pid::new(BASE) {
    Ok(pid) => pid,
    Err(_) => panic!("BASE is invalid"),
};

fn new_pid(config: PidConfig) -> Pid {
    Pid::new(config).expect("test tuning is valid")
}

fn config(kp: f32, ki: f32, kd: f32, tau_s: f32, min: f32, max: f32) -> PidConfig {
    PidConfig {
        kp,
        ki,
        kd,
        derivative_filter_tau_s: tau_s,
        output_min: min,
        output_max: max,
    }
}

/// `y' = (gain * u - y) / tau_s`, forward Euler.
struct FirstOrderLag {
    gain: f32,
    tau_s: f32,
    y: f32,
}

impl FirstOrderLag {
    fn step(&mut self, u: f32, dt_s: f32) -> f32 {
        self.y += dt_s * (self.gain * u - self.y) / self.tau_s;
        self.y
    }
}

/// Every stored and reported value is finite and the output and integral are within the
/// limits.
fn assert_sane(pid: &Pid) {
    let c = pid.config();
    let t = pid.terms();
    for x in [
        t.proportional,
        t.integral,
        t.derivative,
        t.output,
        pid.integral(),
    ] {
        assert!(x.is_finite(), "non-finite term {:?}", t);
    }
    assert!(
        pid.output() >= c.output_min && pid.output() <= c.output_max,
        "output {} outside [{}, {}]",
        pid.output(),
        c.output_min,
        c.output_max
    );
    assert!(
        pid.integral() >= c.output_min && pid.integral() <= c.output_max,
        "integral {} outside [{}, {}]",
        pid.integral(),
        c.output_min,
        c.output_max
    );
}

/// Each bad field is rejected with an error naming it; `validate` runs in a `const`.
pub fn config_validation_names_each_bad_field() {
    const NEGATIVE_KP: Result<(), PidConfigError> = PidConfig { kp: -1.0, ..BASE }.validate();
    assert_eq!(
        NEGATIVE_KP,
        Err(PidConfigError::NegativeGain(Gain::Proportional))
    );

    let cases = [
        (
            PidConfig {
                kp: f32::NAN,
                ..BASE
            },
            PidConfigError::NonFiniteGain(Gain::Proportional),
        ),
        (
            PidConfig {
                ki: f32::INFINITY,
                ..BASE
            },
            PidConfigError::NonFiniteGain(Gain::Integral),
        ),
        (
            PidConfig {
                kd: f32::NEG_INFINITY,
                ..BASE
            },
            PidConfigError::NonFiniteGain(Gain::Derivative),
        ),
        (
            PidConfig { ki: -0.1, ..BASE },
            PidConfigError::NegativeGain(Gain::Integral),
        ),
        (
            PidConfig { kd: -1e-9, ..BASE },
            PidConfigError::NegativeGain(Gain::Derivative),
        ),
        (
            PidConfig {
                derivative_filter_tau_s: -0.01,
                ..BASE
            },
            PidConfigError::NegativeFilterTau,
        ),
        (
            PidConfig {
                derivative_filter_tau_s: f32::NAN,
                ..BASE
            },
            PidConfigError::NonFiniteFilterTau,
        ),
        (
            PidConfig {
                derivative_filter_tau_s: f32::INFINITY,
                ..BASE
            },
            PidConfigError::NonFiniteFilterTau,
        ),
        (
            PidConfig {
                output_min: f32::NEG_INFINITY,
                ..BASE
            },
            PidConfigError::NonFiniteLimit,
        ),
        (
            PidConfig {
                output_max: f32::NAN,
                ..BASE
            },
            PidConfigError::NonFiniteLimit,
        ),
        (
            PidConfig {
                output_min: 5.0,
                output_max: 5.0,
                ..BASE
            },
            PidConfigError::MinNotBelowMax,
        ),
        (
            PidConfig {
                output_min: 6.0,
                output_max: 5.0,
                ..BASE
            },
            PidConfigError::MinNotBelowMax,
        ),
    ];
    for (bad, expected) in cases {
        assert_eq!(bad.validate(), Err(expected));
        assert_eq!(Pid::new(bad), Err(expected));
    }

    // Zero gains and an unfiltered derivative are valid.
    assert!(config(0.0, 0.0, 0.0, 0.0, -1.0, 1.0).validate().is_ok());
    assert_eq!(BASE_PID, new_pid(BASE));
    assert_eq!(BASE_PID.config(), BASE);
}

/// Deterministic sweep over extreme tunings and inputs (huge gains, subnormal and huge
/// time steps, `f32::MAX` set points, NaN): the output, the integral and every reported
/// term stay finite, and output and integral stay within the limits.
pub fn output_never_leaves_limits() {
    let configs = [
        BASE,
        config(1e30, 1e30, 1e30, 0.0, -1.0, 1.0),
        config(f32::MAX, f32::MAX, f32::MAX, f32::MAX, -f32::MAX, f32::MAX),
        config(0.0, 0.0, 0.0, 0.0, 10.0, 100.0),
        config(3.0, 40.0, 0.5, 1e-6, -100.0, -99.999),
        config(1e-30, 1e-30, 1e-30, 1e30, 0.0, 1.0),
    ];
    let values = [
        0.0,
        1.0,
        -1.0,
        123.4,
        1e30,
        -1e30,
        f32::MAX,
        f32::MIN,
        f32::NAN,
        f32::INFINITY,
    ];
    let steps = [1e-45, 1e-6, DT_S, 1.0, 1e30, 0.0, -DT_S, f32::NAN];
    for c in configs {
        let mut pid = new_pid(c);
        for setpoint in values {
            for measurement in values {
                for dt_s in steps {
                    let out = pid.update(setpoint, measurement, dt_s);
                    assert_eq!(out, pid.output());
                    assert_sane(&pid);
                }
            }
        }
        // Unreachable set point for a long time, both ways, with noisy measurements.
        for sign in [1.0, -1.0] {
            for k in 0..2000 {
                let noise = if k % 2 == 0 { 1e3 } else { -1e3 };
                pid.update(sign * 1e20, noise, DT_S);
                assert_sane(&pid);
            }
        }
    }
}

/// Runs a PI loop (kp = ki = 1, zero on the plant pole) against an unreachable set point
/// of sign `sign` for 10 000 steps and returns the controller and plant. Limits +-1,
/// plant gain 1: the plant can reach at most +-1, the set point is +-1.5.
fn saturate_for_long(sign: f32) -> (Pid, FirstOrderLag) {
    let mut pid = new_pid(config(1.0, 1.0, 0.0, 0.0, -1.0, 1.0));
    let mut plant = FirstOrderLag {
        gain: 1.0,
        tau_s: 1.0,
        y: 0.0,
    };
    for _ in 0..10_000 {
        let u = pid.update(sign * 1.5, plant.y, DT_S);
        plant.step(u, DT_S);
        assert_sane(&pid);
    }
    (pid, plant)
}

/// Under 10 000 steps of saturation the integral stops as soon as the unclamped output
/// passes the limit: `P + I` ends within one integration step (`ki * |e| * dt`) beyond
/// the limit, i.e. `|I| <= 0.505` here, where plain clamping would hold `|I| = 1` and no
/// anti-windup `|I| = 50`.
pub fn integrator_stays_bounded_under_long_saturation() {
    for sign in [1.0, -1.0] {
        let (pid, plant) = saturate_for_long(sign);
        assert_eq!(pid.output(), sign);
        let error = sign * 1.5 - plant.y;
        let one_step = 1.0 * error.abs() * DT_S;
        let excess = sign * (pid.proportional() + pid.integral()) - 1.0;
        assert!(
            excess > 0.0 && excess <= one_step + 1e-5,
            "P + I beyond the limit by {}, one step is {}",
            excess,
            one_step
        );
        assert!(
            sign * pid.integral() <= 0.505 + 1e-5,
            "integral {}",
            pid.integral()
        );
    }
}

/// After the long saturation, a reachable set point takes the output off the limit on the
/// very first update (without anti-windup the integral of 50 would need ~100 s to unwind),
/// and the plant then stays within 2 % of it from 6 s on.
pub fn leaves_saturation_promptly_when_setpoint_becomes_reachable() {
    for sign in [1.0, -1.0] {
        let (mut pid, mut plant) = saturate_for_long(sign);
        let setpoint = sign * 0.5;
        let first = pid.update(setpoint, plant.y, DT_S);
        assert!(sign * first < 1.0, "still saturated: {}", first);
        plant.step(first, DT_S);
        for k in 1..1000 {
            let u = pid.update(setpoint, plant.y, DT_S);
            let y = plant.step(u, DT_S);
            if k >= 600 {
                assert!((y - setpoint).abs() <= 0.01, "{} at step {}", y, k);
            }
        }
    }
}

/// Closed loop on `y' = u - y` (K = 1, T = 1 s) at 10 ms with PI (kp = 2, ki = 2, the
/// zero cancelling the plant pole): within 2 % of the set point from 2.5 s on, overshoot
/// at most 2 %, within 0.1 % after 10 s.
pub fn pi_first_order_plant_settles() {
    closed_loop_first_order(config(2.0, 2.0, 0.0, 0.0, -10.0, 10.0), 250);
}

/// The same loop with the actuator limited to [0, 1.2] (the plant needs 1.0): the output
/// saturates at the start; anti-windup keeps the overshoot at most 2 % and the loop
/// within 2 % from 4 s on.
pub fn pi_first_order_plant_with_saturating_actuator() {
    let c = config(2.0, 2.0, 0.0, 0.0, 0.0, 1.2);
    assert_eq!(new_pid(c).update(1.0, 0.0, DT_S), 1.2);
    closed_loop_first_order(c, 400);
}

fn closed_loop_first_order(c: PidConfig, settled_from_step: usize) {
    let mut pid = new_pid(c);
    let mut plant = FirstOrderLag {
        gain: 1.0,
        tau_s: 1.0,
        y: 0.0,
    };
    let setpoint = 1.0;
    for k in 0..1000 {
        let u = pid.update(setpoint, plant.y, DT_S);
        let y = plant.step(u, DT_S);
        assert!(y <= setpoint * 1.02, "overshoot to {} at step {}", y, k);
        if k >= settled_from_step {
            assert!((y - setpoint).abs() <= 0.02, "{} at step {}", y, k);
        }
    }
    assert!((plant.y - setpoint).abs() <= 1e-3, "final {}", plant.y);
}

/// Closed loop on two lags (1 s and 0.2 s). With kp = 6, ki = 3 alone the response
/// overshoots by more than 5 %; adding filtered derivative action (kd = 1.2,
/// tau = 20 ms) keeps the overshoot at most 2 % and the loop within 2 % from 1.5 s on.
pub fn derivative_damps_second_order_plant() {
    fn peak(c: PidConfig) -> f32 {
        let mut pid = new_pid(c);
        let mut lag1 = FirstOrderLag {
            gain: 1.0,
            tau_s: 1.0,
            y: 0.0,
        };
        let mut lag2 = FirstOrderLag {
            gain: 1.0,
            tau_s: 0.2,
            y: 0.0,
        };
        let mut peak = f32::MIN;
        for k in 0..1000 {
            let u = pid.update(1.0, lag2.y, DT_S);
            let y = lag2.step(lag1.step(u, DT_S), DT_S);
            peak = peak.max(y);
            if c.kd > 0.0 && k >= 150 {
                assert!((y - 1.0).abs() <= 0.02, "{} at step {}", y, k);
            }
        }
        assert!((lag2.y - 1.0).abs() <= 5e-3, "final {}", lag2.y);
        peak
    }
    let with_d = peak(config(6.0, 3.0, 1.2, 0.02, -10.0, 10.0));
    let without_d = peak(config(6.0, 3.0, 0.0, 0.02, -10.0, 10.0));
    assert!(with_d <= 1.02, "PID overshoot to {}", with_d);
    assert!(without_d > 1.05, "PI overshoot only to {}", without_d);
}

/// A set-point step with the measurement steady gives no derivative kick even
/// unfiltered: the D term stays exactly zero and the output moves by `kp * step` only.
pub fn setpoint_step_causes_no_derivative_kick() {
    let mut pid = new_pid(config(1.0, 0.5, 2.0, 0.0, -10.0, 10.0));
    for _ in 0..20 {
        pid.update(0.3, 0.3, DT_S);
    }
    let before = pid.output();
    let integral = pid.integral();
    let out = pid.update(1.3, 0.3, DT_S);
    assert_eq!(pid.derivative(), 0.0);
    assert_eq!(out, pid.proportional() + integral);
    assert!((out - before - 1.0).abs() <= 1e-5, "jump {}", out - before);
}

/// A measurement step of 2 with kd = 0.5, tau = 50 ms: the D term peaks at
/// `kd * step / (tau + dt)` (bounded by `kd * step / tau`, against `kd * step / dt`
/// unfiltered), opposes the step, then decays monotonically to below 0.1 % of its peak
/// within 10 tau.
pub fn filtered_measurement_step_gives_bounded_decaying_derivative() {
    let (kd, tau, step) = (0.5, 0.05, 2.0);
    let mut pid = new_pid(config(0.0, 0.0, kd, tau, -100.0, 100.0));
    for _ in 0..10 {
        pid.update(0.0, 0.0, DT_S);
        assert_eq!(pid.derivative(), 0.0);
    }
    pid.update(0.0, step, DT_S);
    let peak = pid.derivative();
    let expected = -kd * step / (tau + DT_S);
    assert!((peak - expected).abs() <= 1e-4, "peak {}", peak);
    assert!(peak < 0.0 && -peak <= kd * step / tau);
    let mut previous = peak;
    for _ in 0..50 {
        pid.update(0.0, step, DT_S);
        let d = pid.derivative();
        assert!(d < 0.0 && d > previous, "{} after {}", d, previous);
        previous = d;
    }
    assert!(previous.abs() < 1e-3 * peak.abs(), "still {}", previous);
}

/// With tau = 0 the D term is exactly `-kd * (measurement change) / dt`.
pub fn unfiltered_derivative_is_the_measurement_slope() {
    let mut pid = new_pid(config(0.0, 0.0, 0.5, 0.0, -100.0, 100.0));
    pid.update(0.0, 1.0, DT_S);
    assert_eq!(pid.derivative(), 0.0);
    pid.update(0.0, 1.2, DT_S);
    assert!((pid.derivative() - (-0.5 * 0.2 / DT_S)).abs() <= 1e-4);
    pid.update(0.0, 1.2, DT_S);
    assert_eq!(pid.derivative(), 0.0);
}

/// After a reset the controller equals a new one: the first update is exactly the P
/// response (no derivative kick, no integral) and later updates match a new controller.
/// With zero outside the output range the integral restarts at the nearest limit.
pub fn reset_restores_initial_state() {
    let c = config(1.5, 2.0, 0.3, 0.05, -5.0, 5.0);
    let mut pid = new_pid(c);
    for k in 0..100 {
        pid.update(1.0, k as f32 * 0.02, DT_S);
    }
    assert!(pid.integral() != 0.0);
    pid.reset();
    assert_eq!(pid, Pid::new(c).unwrap());

    let out = pid.update(1.0, 0.4, DT_S);
    assert_eq!(out, 1.5 * (1.0 - 0.4));
    assert_eq!(pid.derivative(), 0.0);
    assert_eq!(pid.terms().integral, 0.0);

    let mut fresh = Pid::new(c).unwrap();
    fresh.update(1.0, 0.4, DT_S);
    for k in 0..50 {
        let measurement = 0.4 + k as f32 * 0.01;
        assert_eq!(
            pid.update(1.0, measurement, DT_S),
            fresh.update(1.0, measurement, DT_S)
        );
    }

    let mut offset = new_pid(config(1.0, 1.0, 0.0, 0.0, 10.0, 100.0));
    offset.update(50.0, 0.0, DT_S);
    offset.reset();
    assert_eq!(offset.integral(), 10.0);
    assert_eq!(offset.output(), 10.0);
    assert_eq!(offset.update(20.0, 15.0, DT_S), 5.0 + 10.0);
}

/// While held the integral does not move, whatever the error, but P and D still act;
/// the hold survives a reset; after release the integral moves by `ki * e * dt` again.
pub fn held_integrator_stays_constant_until_released() {
    let mut pid = new_pid(config(1.0, 1.0, 0.2, 0.0, -10.0, 10.0));
    for _ in 0..10 {
        pid.update(1.0, 0.5, DT_S);
    }
    assert!(!pid.is_integrator_held());
    pid.hold_integrator();
    assert!(pid.is_integrator_held());
    let held = pid.integral();
    assert!(held > 0.0);
    for k in 0..100 {
        let measurement = if k % 2 == 0 { -3.0 } else { 4.0 };
        let out = pid.update(1.0, measurement, DT_S);
        assert_eq!(pid.integral(), held);
        assert_eq!(pid.proportional(), 1.0 - measurement);
        let t = pid.terms();
        assert_eq!(
            out,
            (t.proportional + t.integral + t.derivative).clamp(-10.0, 10.0)
        );
    }

    pid.reset();
    assert!(pid.is_integrator_held());
    pid.update(1.0, 0.0, DT_S);
    assert_eq!(pid.integral(), 0.0);

    pid.release_integrator();
    assert!(!pid.is_integrator_held());
    pid.update(1.0, 0.5, DT_S);
    assert!((pid.integral() - 0.5 * DT_S).abs() <= 1e-7);
}

/// Conditional integration: with the unclamped output beyond a limit the integral stops
/// if the error pushes further out, and keeps integrating if the error pulls back in.
pub fn integration_stops_only_when_pushing_further_into_saturation() {
    for sign in [1.0, -1.0] {
        let mut pid = new_pid(config(0.1, 1.0, 1.0, 0.0, -1.0, 1.0));
        pid.set_integral(sign * 1.0);
        // Error pushes out: P + I beyond the limit, integral frozen.
        pid.update(sign * 1.0, sign * 0.1, DT_S);
        assert_eq!(pid.output(), sign * 1.0);
        assert_eq!(pid.integral(), sign * 1.0);
        // Measurement overshot the set point but falls back fast: D drives the output
        // past the limit, while the error points back into the range, so the integral
        // moves inwards.
        pid.update(0.0, sign * 0.05, DT_S);
        let t = pid.terms();
        assert!(sign * (t.proportional + t.integral + t.derivative) > 1.0);
        assert_eq!(pid.output(), sign * 1.0);
        assert!(sign * pid.integral() < 1.0, "integral {}", pid.integral());
    }
}

/// `set_integral` clamps, ignores non-finite values and gives bumpless transfer: with
/// zero error the next output is the loaded value.
pub fn set_integral_gives_bumpless_transfer() {
    let mut pid = new_pid(config(8.0, 1.5, 0.0, 0.0, 0.0, 100.0));
    pid.set_integral(35.0);
    assert_eq!(pid.integral(), 35.0);
    assert_eq!(pid.update(25.0, 25.0, DT_S), 35.0);
    pid.set_integral(500.0);
    assert_eq!(pid.integral(), 100.0);
    pid.set_integral(-3.0);
    assert_eq!(pid.integral(), 0.0);
    pid.set_integral(42.0);
    pid.set_integral(f32::NAN);
    pid.set_integral(f32::INFINITY);
    assert_eq!(pid.integral(), 42.0);
}

/// NaN or infinite inputs and `dt <= 0` change nothing and return the last output.
pub fn invalid_inputs_leave_state_untouched() {
    let mut pid = BASE_PID;
    for k in 0..30 {
        pid.update(2.0, k as f32 * 0.05, DT_S);
    }
    let before = pid.clone();
    assert!(before.output() != 0.0);
    let bad = [
        (f32::NAN, 1.0, DT_S),
        (f32::INFINITY, 1.0, DT_S),
        (1.0, f32::NAN, DT_S),
        (1.0, f32::NEG_INFINITY, DT_S),
        (1.0, 1.0, f32::NAN),
        (1.0, 1.0, f32::INFINITY),
        (1.0, 1.0, 0.0),
        (1.0, 1.0, -0.0),
        (1.0, 1.0, -DT_S),
    ];
    for (setpoint, measurement, dt_s) in bad {
        assert_eq!(pid.update(setpoint, measurement, dt_s), before.output());
        assert_eq!(pid, before);
    }
}

/// Retuning keeps the state: new limits re-clamp the integral and the last output, new
/// gains do not bump the output, and invalid retunes are rejected without any change.
pub fn retuning_keeps_state_consistent() {
    let mut pid = new_pid(config(1.0, 1.0, 0.0, 0.0, -10.0, 10.0));
    pid.set_integral(4.0);
    assert_eq!(pid.update(4.0, 0.0, DT_S), 8.0);

    pid.set_limits(-2.0, 2.0).unwrap();
    assert_eq!(pid.integral(), 2.0);
    assert_eq!(pid.output(), 2.0);
    assert_eq!(pid.config().output_max, 2.0);

    let before = pid.clone();
    assert_eq!(
        pid.set_limits(2.0, 2.0),
        Err(PidConfigError::MinNotBelowMax)
    );
    assert_eq!(
        pid.set_gains(-1.0, 1.0, 0.0),
        Err(PidConfigError::NegativeGain(Gain::Proportional))
    );
    assert_eq!(
        pid.set_config(PidConfig {
            derivative_filter_tau_s: -1.0,
            ..pid.config()
        }),
        Err(PidConfigError::NegativeFilterTau)
    );
    assert_eq!(pid, before);

    // The integral is an output contribution: a tenfold ki leaves the output unchanged.
    pid.set_limits(-10.0, 10.0).unwrap();
    pid.set_integral(1.5);
    pid.set_gains(1.0, 10.0, 0.0).unwrap();
    assert_eq!(pid.config().ki, 10.0);
    assert_eq!(pid.update(0.0, 0.0, DT_S), 1.5);
    pid.update(1.0, 0.0, DT_S);
    assert!((pid.integral() - (1.5 + 10.0 * DT_S)).abs() <= 1e-6);
}
