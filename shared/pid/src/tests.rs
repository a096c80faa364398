extern crate std;

use crate::test_cases;
use crate::{Gain, Pid, PidConfig, PidConfigError};
use proptest::prelude::*;
use std::string::ToString;
use std::vec::Vec;

macro_rules! shared_cases {
    ($($name:ident),* $(,)?) => { $( #[test] fn $name() { test_cases::$name(); } )* };
}

shared_cases!(
    config_validation_names_each_bad_field,
    output_never_leaves_limits,
    integrator_stays_bounded_under_long_saturation,
    leaves_saturation_promptly_when_setpoint_becomes_reachable,
    pi_first_order_plant_settles,
    pi_first_order_plant_with_saturating_actuator,
    derivative_damps_second_order_plant,
    setpoint_step_causes_no_derivative_kick,
    filtered_measurement_step_gives_bounded_decaying_derivative,
    unfiltered_derivative_is_the_measurement_slope,
    reset_restores_initial_state,
    held_integrator_stays_constant_until_released,
    integration_stops_only_when_pushing_further_into_saturation,
    set_integral_gives_bumpless_transfer,
    invalid_inputs_leave_state_untouched,
    retuning_keeps_state_consistent,
);

#[test]
fn errors_display_what_is_wrong() {
    assert_eq!(
        PidConfigError::NegativeGain(Gain::Integral).to_string(),
        "integral gain ki is negative"
    );
    assert_eq!(
        PidConfigError::NonFiniteGain(Gain::Derivative).to_string(),
        "derivative gain kd is not finite"
    );
    assert_eq!(
        PidConfigError::MinNotBelowMax.to_string(),
        "output_min is not below output_max"
    );
}

/// Mostly ordinary values, sometimes extreme ones.
fn any_gain() -> impl Strategy<Value = f32> {
    prop_oneof![
        4 => 0.0f32..100.0,
        1 => 0.0f32..f32::MAX,
        1 => Just(0.0f32),
    ]
}

fn any_config() -> impl Strategy<Value = PidConfig> {
    (
        any_gain(),
        any_gain(),
        any_gain(),
        prop_oneof![Just(0.0f32), 0.0f32..10.0, 0.0f32..f32::MAX],
        -1e6f32..1e6,
        prop_oneof![1e-3f32..1e6, 1e-3f32..1.0],
    )
        // At 1e6 an f32 step is 0.06: keep only spans that survive the addition.
        .prop_filter("empty range", |(.., min, span)| min + span > *min)
        .prop_map(|(kp, ki, kd, tau, min, span)| PidConfig {
            kp,
            ki,
            kd,
            derivative_filter_tau_s: tau,
            output_min: min,
            output_max: min + span,
        })
}

/// Any f32, NaN and infinities included, but mostly values a sensor could report.
fn any_signal() -> impl Strategy<Value = f32> {
    prop_oneof![4 => -1e3f32..1e3, 1 => any::<f32>()]
}

fn any_dt() -> impl Strategy<Value = f32> {
    prop_oneof![4 => 1e-4f32..0.1, 1 => any::<f32>()]
}

fn any_inputs() -> impl Strategy<Value = Vec<(f32, f32, f32)>> {
    proptest::collection::vec((any_signal(), any_signal(), any_dt()), 1..200)
}

fn within(x: f32, config: &PidConfig) -> bool {
    x.is_finite() && x >= config.output_min && x <= config.output_max
}

proptest! {
    #[test]
    fn output_and_integral_stay_within_limits(config in any_config(), inputs in any_inputs()) {
        let mut pid = Pid::new(config).unwrap();
        for (setpoint, measurement, dt_s) in inputs {
            let out = pid.update(setpoint, measurement, dt_s);
            prop_assert!(within(out, &config), "output {out} for {config:?}");
            prop_assert!(within(pid.integral(), &config), "integral {}", pid.integral());
            let t = pid.terms();
            prop_assert!(t.proportional.is_finite() && t.derivative.is_finite(), "{t:?}");
        }
    }

    #[test]
    fn invalid_inputs_change_nothing(
        config in any_config(),
        inputs in any_inputs(),
        bad in prop_oneof![
            (any::<f32>(), any::<f32>(), -1e3f32..=0.0),
            (Just(f32::NAN), any::<f32>(), any::<f32>()),
            (any::<f32>(), prop_oneof![Just(f32::INFINITY), Just(f32::NEG_INFINITY)], any::<f32>()),
            (any::<f32>(), any::<f32>(), Just(f32::NAN)),
        ],
    ) {
        let mut pid = Pid::new(config).unwrap();
        for (setpoint, measurement, dt_s) in inputs {
            pid.update(setpoint, measurement, dt_s);
        }
        let before = pid.clone();
        prop_assert_eq!(pid.update(bad.0, bad.1, bad.2), before.output());
        prop_assert_eq!(pid, before);
    }

    #[test]
    fn held_integral_never_moves(config in any_config(), inputs in any_inputs(), start in any::<f32>()) {
        let mut pid = Pid::new(config).unwrap();
        pid.set_integral(start);
        pid.hold_integrator();
        let held = pid.integral();
        for (setpoint, measurement, dt_s) in inputs {
            pid.update(setpoint, measurement, dt_s);
            prop_assert_eq!(pid.integral(), held);
        }
    }

    /// Derivative on the measurement: the set point never enters the D term.
    #[test]
    fn setpoint_never_affects_derivative(
        config in any_config(),
        measurements in proptest::collection::vec((any_signal(), 1e-4f32..0.1), 1..100),
        setpoints in proptest::collection::vec(any_signal(), 100),
    ) {
        let mut steady = Pid::new(config).unwrap();
        let mut moving = Pid::new(config).unwrap();
        for (k, (measurement, dt_s)) in measurements.into_iter().enumerate() {
            if !measurement.is_finite() || !setpoints[k].is_finite() {
                continue;
            }
            steady.update(0.0, measurement, dt_s);
            moving.update(setpoints[k], measurement, dt_s);
            prop_assert_eq!(steady.derivative(), moving.derivative());
        }
    }

    #[test]
    fn validation_accepts_exactly_the_valid_configs(
        kp in any::<f32>(), ki in any::<f32>(), kd in any::<f32>(),
        tau in any::<f32>(), min in any::<f32>(), max in any::<f32>(),
    ) {
        let gain_ok = |g: f32| g.is_finite() && g >= 0.0;
        let valid = gain_ok(kp) && gain_ok(ki) && gain_ok(kd) && gain_ok(tau)
            && min.is_finite() && max.is_finite() && min < max;
        let config = PidConfig {
            kp, ki, kd, derivative_filter_tau_s: tau, output_min: min, output_max: max,
        };
        prop_assert_eq!(Pid::new(config).is_ok(), valid);
        prop_assert_eq!(config.validate().is_ok(), valid);
    }
}
