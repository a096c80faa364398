//! `autoplug_ecus::diff::test_cases` on the Cortex-M4F: the differential logic (yaw control), as on the host.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_ecus::diff::test_cases;
    use autoplug_target_tests as _;

    #[test]
    fn publishes_split_and_yaw_error_every_10_ms() {
        test_cases::publishes_split_and_yaw_error_every_10_ms();
    }

    #[test]
    fn split_sign_follows_the_yaw_error() {
        test_cases::split_sign_follows_the_yaw_error();
    }

    #[test]
    fn dead_band_with_hysteresis() {
        test_cases::dead_band_with_hysteresis();
    }

    #[test]
    fn control_only_when_fast_turning_and_not_braking() {
        test_cases::control_only_when_fast_turning_and_not_braking();
    }

    #[test]
    fn split_is_clamped_without_windup() {
        test_cases::split_is_clamped_without_windup();
    }

    #[test]
    fn closed_loop_drives_the_yaw_error_back() {
        test_cases::closed_loop_drives_the_yaw_error_back();
    }

    #[test]
    fn stale_inputs_open_the_differential() {
        test_cases::stale_inputs_open_the_differential();
    }

    #[test]
    fn invalid_inputs_are_refused() {
        test_cases::invalid_inputs_are_refused();
    }

    #[test]
    fn yaw_oscillation_is_damped() {
        test_cases::yaw_oscillation_is_damped();
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
