//! `autoplug_ecus::steering::test_cases` on the Cortex-M4F: the steering logic (buttons, shift pulses, cancel adoption), as on the host.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_ecus::steering::test_cases;
    use autoplug_target_tests as _;

    #[test]
    fn reports_the_wheel_angle() {
        test_cases::reports_the_wheel_angle();
    }

    #[test]
    fn buttons_are_debounced() {
        test_cases::buttons_are_debounced();
    }

    #[test]
    fn shift_paddle_sends_a_pulse() {
        test_cases::shift_paddle_sends_a_pulse();
    }

    #[test]
    fn a_press_during_a_pulse_is_ignored() {
        test_cases::a_press_during_a_pulse_is_ignored();
    }

    #[test]
    fn both_paddles_mean_no_request() {
        test_cases::both_paddles_mean_no_request();
    }

    #[test]
    fn cruise_buttons_set_the_state() {
        test_cases::cruise_buttons_set_the_state();
    }

    #[test]
    fn adopts_a_cancel_from_the_pedals() {
        test_cases::adopts_a_cancel_from_the_pedals();
    }

    #[test]
    fn cruise_mode_input_is_not_supervised() {
        test_cases::cruise_mode_input_is_not_supervised();
    }

    #[test]
    fn invalid_cancel_records_a_dtc() {
        test_cases::invalid_cancel_records_a_dtc();
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
