//! `autoplug_scaling::test_cases` on the Cortex-M4F (hardware f32, opt-level of the profile).
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_scaling::test_cases;
    use autoplug_target_tests as _;

    #[test]
    fn every_raw_value_round_trips() {
        test_cases::every_raw_value_round_trips();
    }

    #[test]
    fn out_of_range_raw_is_rejected() {
        test_cases::out_of_range_raw_is_rejected();
    }

    #[test]
    fn sending_saturates() {
        test_cases::sending_saturates();
    }

    #[test]
    fn anchor_points() {
        test_cases::anchor_points();
    }

    #[test]
    fn quantisation_error_is_half_a_step() {
        test_cases::quantisation_error_is_half_a_step();
    }

    #[test]
    fn rounding() {
        test_cases::rounding();
    }

    #[test]
    fn unit_conversions() {
        test_cases::unit_conversions();
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
