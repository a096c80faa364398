//! `autoplug_ecus::console::test_cases` on the Cortex-M4F: the console logic (lights, AccMsg), as on the host.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_ecus::console::test_cases;
    use autoplug_target_tests as _;

    #[test]
    fn reports_the_switches() {
        test_cases::reports_the_switches();
    }

    #[test]
    fn brake_lights_follow_the_brake_command() {
        test_cases::brake_lights_follow_the_brake_command();
    }

    #[test]
    fn stale_brake_command_turns_the_brake_lights_on() {
        test_cases::stale_brake_command_turns_the_brake_lights_on();
    }

    #[test]
    fn invalid_brake_frame_records_a_dtc() {
        test_cases::invalid_brake_frame_records_a_dtc();
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
