//! `autoplug_ecus::engine::test_cases` on the Cortex-M4F: the engine logic (RPM, fuel, engine mode), as on the host.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_ecus::engine::test_cases;
    use autoplug_target_tests as _;

    #[test]
    fn reports_rpm_and_fuel() {
        test_cases::reports_rpm_and_fuel();
    }

    #[test]
    fn echoes_the_engine_mode() {
        test_cases::echoes_the_engine_mode();
    }

    #[test]
    fn stale_console_reports_economy() {
        test_cases::stale_console_reports_economy();
    }

    #[test]
    fn invalid_console_frame_records_a_dtc() {
        test_cases::invalid_console_frame_records_a_dtc();
    }

    #[test]
    fn counts_fuel_used() {
        test_cases::counts_fuel_used();
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
