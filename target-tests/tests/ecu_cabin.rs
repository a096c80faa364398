//! `autoplug_ecus::cabin::test_cases` on the Cortex-M4F: the cabin comfort logic (fan PID), as on the host.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_ecus::cabin::test_cases;
    use autoplug_target_tests as _;

    #[test]
    fn publishes_temperatures_and_fan_every_100_ms() {
        test_cases::publishes_temperatures_and_fan_every_100_ms();
    }

    #[test]
    fn fan_rises_when_the_cabin_is_warmer_than_set() {
        test_cases::fan_rises_when_the_cabin_is_warmer_than_set();
    }

    #[test]
    fn set_point_step_down_settles_within_one_degree() {
        test_cases::set_point_step_down_settles_within_one_degree();
    }

    #[test]
    fn integrator_stays_within_the_fan_range() {
        test_cases::integrator_stays_within_the_fan_range();
    }

    #[test]
    fn sensor_noise_is_filtered() {
        test_cases::sensor_noise_is_filtered();
    }

    #[test]
    fn knob_limits_and_invalid_readings() {
        test_cases::knob_limits_and_invalid_readings();
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
