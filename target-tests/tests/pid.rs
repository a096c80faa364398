//! `autoplug_pid::test_cases` on the Cortex-M4F (hardware f32, opt-level of the profile).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_pid::test_cases;
    use autoplug_target_tests as _;

    #[test]
    fn config_validation_names_each_bad_field() {
        test_cases::config_validation_names_each_bad_field();
    }

    #[test]
    fn output_never_leaves_limits() {
        test_cases::output_never_leaves_limits();
    }

    #[test]
    fn integrator_stays_bounded_under_long_saturation() {
        test_cases::integrator_stays_bounded_under_long_saturation();
    }

    #[test]
    fn leaves_saturation_promptly_when_setpoint_becomes_reachable() {
        test_cases::leaves_saturation_promptly_when_setpoint_becomes_reachable();
    }

    #[test]
    fn pi_first_order_plant_settles() {
        test_cases::pi_first_order_plant_settles();
    }

    #[test]
    fn pi_first_order_plant_with_saturating_actuator() {
        test_cases::pi_first_order_plant_with_saturating_actuator();
    }

    #[test]
    fn derivative_damps_second_order_plant() {
        test_cases::derivative_damps_second_order_plant();
    }

    #[test]
    fn setpoint_step_causes_no_derivative_kick() {
        test_cases::setpoint_step_causes_no_derivative_kick();
    }

    #[test]
    fn filtered_measurement_step_gives_bounded_decaying_derivative() {
        test_cases::filtered_measurement_step_gives_bounded_decaying_derivative();
    }

    #[test]
    fn unfiltered_derivative_is_the_measurement_slope() {
        test_cases::unfiltered_derivative_is_the_measurement_slope();
    }

    #[test]
    fn reset_restores_initial_state() {
        test_cases::reset_restores_initial_state();
    }

    #[test]
    fn held_integrator_stays_constant_until_released() {
        test_cases::held_integrator_stays_constant_until_released();
    }

    #[test]
    fn integration_stops_only_when_pushing_further_into_saturation() {
        test_cases::integration_stops_only_when_pushing_further_into_saturation();
    }

    #[test]
    fn set_integral_gives_bumpless_transfer() {
        test_cases::set_integral_gives_bumpless_transfer();
    }

    #[test]
    fn invalid_inputs_leave_state_untouched() {
        test_cases::invalid_inputs_leave_state_untouched();
    }

    #[test]
    fn retuning_keeps_state_consistent() {
        test_cases::retuning_keeps_state_consistent();
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
