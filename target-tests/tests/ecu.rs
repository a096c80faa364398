//! `autoplug_ecu::test_cases` on the Cortex-M4F: transmit timing, stale inputs and the
//! DTC store every ECU uses.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(target_os = "none")]
#[defmt_test::tests]
mod tests {
    use autoplug_ecu::test_cases;
    use autoplug_target_tests as _;

    #[test]
    fn periodic_messages_keep_their_period() {
        test_cases::periodic_messages_keep_their_period();
    }

    #[test]
    fn changes_go_out_early_but_not_too_often() {
        test_cases::changes_go_out_early_but_not_too_often();
    }

    #[test]
    fn inputs_go_stale_after_three_periods() {
        test_cases::inputs_go_stale_after_three_periods();
    }

    #[test]
    fn invalid_frames_do_not_refresh() {
        test_cases::invalid_frames_do_not_refresh();
    }

    #[test]
    fn dtcs_encode_like_uds() {
        test_cases::dtcs_encode_like_uds();
    }

    #[test]
    fn dtc_store_keeps_iso_14229_status() {
        test_cases::dtc_store_keeps_iso_14229_status();
    }

    #[test]
    fn supervision_records_network_dtcs() {
        test_cases::supervision_records_network_dtcs();
    }
}

/// Only reached by a host build with a transport feature (`--all-features`).
#[cfg(not(target_os = "none"))]
fn main() {
    eprintln!("skipped: on-target suite, run it with scripts/target-test");
}
