//! `autoplug_ecus::pedals::test_cases` on the Cortex-M4F: the pedals logic (cruise cancel, traction cut), as on the host.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_ecus::pedals::test_cases;
    use autoplug_target_tests as _;

    #[test]
    fn reports_the_driver_pedals() {
        test_cases::reports_the_driver_pedals();
    }

    #[test]
    fn cruise_command_drives_the_commands() {
        test_cases::cruise_command_drives_the_commands();
    }

    #[test]
    fn brake_press_cancels_cruise_until_off_is_seen() {
        test_cases::brake_press_cancels_cruise_until_off_is_seen();
    }

    #[test]
    fn accelerator_press_cancels_cruise() {
        test_cases::accelerator_press_cancels_cruise();
    }

    #[test]
    fn no_cancel_below_the_threshold_or_with_cruise_off() {
        test_cases::no_cancel_below_the_threshold_or_with_cruise_off();
    }

    #[test]
    fn brake_overrides_the_accelerator() {
        test_cases::brake_overrides_the_accelerator();
    }

    #[test]
    fn traction_cut_reduces_the_accelerator() {
        test_cases::traction_cut_reduces_the_accelerator();
    }

    #[test]
    fn stale_cruise_mode_passes_the_pedals_through() {
        test_cases::stale_cruise_mode_passes_the_pedals_through();
    }

    #[test]
    fn stale_cruise_command_means_no_cruise_outputs() {
        test_cases::stale_cruise_command_means_no_cruise_outputs();
    }

    #[test]
    fn invalid_frames_record_dtcs() {
        test_cases::invalid_frames_record_dtcs();
    }

    #[test]
    fn commands_stay_within_limits() {
        test_cases::commands_stay_within_limits();
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
