//! `autoplug_isotp::test_cases` on the Cortex-M4F: frame layouts, flow control, timing
//! and every error path of the ISO-TP channel, the same cases as the host tests.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_isotp::test_cases;
    use autoplug_target_tests as _;

    #[test]
    fn single_frame_bytes() {
        test_cases::single_frame_bytes();
    }

    #[test]
    fn segmented_frame_bytes() {
        test_cases::segmented_frame_bytes();
    }

    #[test]
    fn flow_control_bytes() {
        test_cases::flow_control_bytes();
    }

    #[test]
    fn st_min_bytes() {
        test_cases::st_min_bytes();
    }

    #[test]
    fn sender_honours_st_min_in_milliseconds() {
        test_cases::sender_honours_st_min_in_milliseconds();
    }

    #[test]
    fn sender_honours_st_min_in_microseconds() {
        test_cases::sender_honours_st_min_in_microseconds();
    }

    #[test]
    fn sender_treats_reserved_st_min_as_127_ms() {
        test_cases::sender_treats_reserved_st_min_as_127_ms();
    }

    #[test]
    fn sender_waits_for_flow_control_after_each_block() {
        test_cases::sender_waits_for_flow_control_after_each_block();
    }

    #[test]
    fn sequence_numbers_wrap_after_15() {
        test_cases::sequence_numbers_wrap_after_15();
    }

    #[test]
    fn receiver_sends_flow_control_after_each_block() {
        test_cases::receiver_sends_flow_control_after_each_block();
    }

    #[test]
    fn wrong_sequence_number_aborts_reception() {
        test_cases::wrong_sequence_number_aborts_reception();
    }

    #[test]
    fn sender_times_out_without_flow_control() {
        test_cases::sender_times_out_without_flow_control();
    }

    #[test]
    fn receiver_times_out_without_consecutive_frame() {
        test_cases::receiver_times_out_without_consecutive_frame();
    }

    #[test]
    fn sender_times_out_without_confirmation() {
        test_cases::sender_times_out_without_confirmation();
    }

    #[test]
    fn receiver_times_out_without_confirmation() {
        test_cases::receiver_times_out_without_confirmation();
    }

    #[test]
    fn sender_handles_wait_frames() {
        test_cases::sender_handles_wait_frames();
    }

    #[test]
    fn sender_aborts_on_overflow_and_invalid_flow_status() {
        test_cases::sender_aborts_on_overflow_and_invalid_flow_status();
    }

    #[test]
    fn send_refusals() {
        test_cases::send_refusals();
    }

    #[test]
    fn receiver_not_ready_waits_then_refuses() {
        test_cases::receiver_not_ready_waits_then_refuses();
    }

    #[test]
    fn receiver_ready_again_sends_clear_to_send() {
        test_cases::receiver_ready_again_sends_clear_to_send();
    }

    #[test]
    fn unreleased_buffer_holds_off_new_pdus() {
        test_cases::unreleased_buffer_holds_off_new_pdus();
    }

    #[test]
    fn first_frame_longer_than_buffer_is_refused() {
        test_cases::first_frame_longer_than_buffer_is_refused();
    }

    #[test]
    fn functional_addressing() {
        test_cases::functional_addressing();
    }

    #[test]
    fn new_pdu_interrupts_reception() {
        test_cases::new_pdu_interrupts_reception();
    }

    #[test]
    fn malformed_and_unexpected_frames_are_ignored() {
        test_cases::malformed_and_unexpected_frames_are_ignored();
    }

    #[test]
    fn other_identifiers_are_ignored() {
        test_cases::other_identifiers_are_ignored();
    }

    #[test]
    fn padded_and_unpadded_peer_frames() {
        test_cases::padded_and_unpadded_peer_frames();
    }

    #[test]
    fn flow_control_goes_before_consecutive_frames() {
        test_cases::flow_control_goes_before_consecutive_frames();
    }

    #[test]
    fn next_deadline_follows_the_state() {
        test_cases::next_deadline_follows_the_state();
    }

    #[test]
    fn abort_returns_to_idle() {
        test_cases::abort_returns_to_idle();
    }

    #[test]
    fn stray_confirmation_is_ignored() {
        test_cases::stray_confirmation_is_ignored();
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
