//! `autoplug_ecus::trans::test_cases` on the Cortex-M4F: the transmission logic (shift schedules, manual, over-rev), as on the host.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_ecus::trans::test_cases;
    use autoplug_target_tests as _;

    #[test]
    fn publishes_gear_and_mode_every_20_ms() {
        test_cases::publishes_gear_and_mode_every_20_ms();
    }

    #[test]
    fn calibration_and_schedules_are_consistent() {
        test_cases::calibration_and_schedules_are_consistent();
    }

    #[test]
    fn automatic_steps_through_the_gears_without_hunting() {
        test_cases::automatic_steps_through_the_gears_without_hunting();
    }

    #[test]
    fn sport_shifts_later_than_economy() {
        test_cases::sport_shifts_later_than_economy();
    }

    #[test]
    fn shift_timeout_limits_the_shift_rate() {
        test_cases::shift_timeout_limits_the_shift_rate();
    }

    #[test]
    fn manual_requests_shift_one_gear_per_press() {
        test_cases::manual_requests_shift_one_gear_per_press();
    }

    #[test]
    fn neutral_and_reverse_in_automatic() {
        test_cases::neutral_and_reverse_in_automatic();
    }

    #[test]
    fn manual_downshift_that_would_over_rev_is_refused() {
        test_cases::manual_downshift_that_would_over_rev_is_refused();
    }

    #[test]
    fn stale_vehicle_speed_holds_the_gear() {
        test_cases::stale_vehicle_speed_holds_the_gear();
    }

    #[test]
    fn stale_shift_requests_are_ignored() {
        test_cases::stale_shift_requests_are_ignored();
    }

    #[test]
    fn stale_engine_selects_economy_and_refuses_downshifts() {
        test_cases::stale_engine_selects_economy_and_refuses_downshifts();
    }

    #[test]
    fn stale_console_keeps_the_shift_mode() {
        test_cases::stale_console_keeps_the_shift_mode();
    }

    #[test]
    fn invalid_frames_are_refused() {
        test_cases::invalid_frames_are_refused();
    }

    #[test]
    fn gear_not_engaged_is_recorded() {
        test_cases::gear_not_engaged_is_recorded();
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
