//! `autoplug_ecus::cruise::test_cases` on the Cortex-M4F: the cruise control logic's decisions and
//! its safe state, as on the host.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_ecus::cruise::test_cases;
    use autoplug_target_tests as _;

    #[test]
    fn publishes_speed_and_command_at_their_periods() {
        test_cases::publishes_speed_and_command_at_their_periods();
    }

    #[test]
    fn engages_on_the_edge_and_latches_the_speed() {
        test_cases::engages_on_the_edge_and_latches_the_speed();
    }

    #[test]
    fn a_stray_on_after_a_cancel_does_not_engage() {
        test_cases::a_stray_on_after_a_cancel_does_not_engage();
    }

    #[test]
    fn holds_speed_and_rejects_a_grade() {
        test_cases::holds_speed_and_rejects_a_grade();
    }

    #[test]
    fn stale_cruise_mode_disengages() {
        test_cases::stale_cruise_mode_disengages();
    }

    #[test]
    fn faulty_build_oscillates() {
        test_cases::faulty_build_oscillates();
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
