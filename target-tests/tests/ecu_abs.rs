//! `autoplug_ecus::abs::test_cases` on the Cortex-M4F: the ABS logic (slip control, faulty build, traction control), as on the host.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_ecus::abs::test_cases;
    use autoplug_target_tests as _;

    #[test]
    fn publishes_its_messages_every_10_ms() {
        test_cases::publishes_its_messages_every_10_ms();
    }

    #[test]
    fn light_braking_passes_the_command_through() {
        test_cases::light_braking_passes_the_command_through();
    }

    #[test]
    fn slipping_wheel_is_released() {
        test_cases::slipping_wheel_is_released();
    }

    #[test]
    fn a_wheel_locking_while_the_pressure_builds_holds_it() {
        test_cases::a_wheel_locking_while_the_pressure_builds_holds_it();
    }

    #[test]
    fn full_braking_stops_short_without_locking() {
        test_cases::full_braking_stops_short_without_locking();
    }

    #[test]
    fn full_braking_on_low_friction() {
        test_cases::full_braking_on_low_friction();
    }

    #[test]
    fn faulty_build_locks_the_wheels() {
        test_cases::faulty_build_locks_the_wheels();
    }

    #[test]
    fn rear_axle_is_select_low() {
        test_cases::rear_axle_is_select_low();
    }

    #[test]
    fn front_axle_yaw_moment_builds_up_slowly() {
        test_cases::front_axle_yaw_moment_builds_up_slowly();
    }

    #[test]
    fn saturated_brake_resets_the_controller() {
        test_cases::saturated_brake_resets_the_controller();
    }

    #[test]
    fn abs_inactive_below_the_minimum_speed() {
        test_cases::abs_inactive_below_the_minimum_speed();
    }

    #[test]
    fn abs_times_out_after_it_stops_acting() {
        test_cases::abs_times_out_after_it_stops_acting();
    }

    #[test]
    fn traction_control_cuts_on_a_spinning_wheel() {
        test_cases::traction_control_cuts_on_a_spinning_wheel();
    }

    #[test]
    fn friction_change_during_a_stop() {
        test_cases::friction_change_during_a_stop();
    }

    #[test]
    fn stale_vehicle_speed_passes_the_brake_through() {
        test_cases::stale_vehicle_speed_passes_the_brake_through();
    }

    #[test]
    fn stale_pedal_brake_holds_then_stops_the_car() {
        test_cases::stale_pedal_brake_holds_then_stops_the_car();
    }

    #[test]
    fn invalid_frames_record_invalid_data() {
        test_cases::invalid_frames_record_invalid_data();
    }

    #[test]
    fn implausible_wheel_speed_disables_abs() {
        test_cases::implausible_wheel_speed_disables_abs();
    }

    #[test]
    fn outputs_stay_within_limits() {
        test_cases::outputs_stay_within_limits();
    }

    #[test]
    fn released_wheel_teaches_the_friction_peak() {
        test_cases::released_wheel_teaches_the_friction_peak();
    }

    #[test]
    fn peak_seeking_follows_the_tyre_either_side_of_the_fixed_target() {
        test_cases::peak_seeking_follows_the_tyre_either_side_of_the_fixed_target();
    }

    #[test]
    fn pressing_the_brake_asks_for_a_step_at_once() {
        test_cases::pressing_the_brake_asks_for_a_step_at_once();
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
