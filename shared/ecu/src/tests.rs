extern crate std;

use crate::test_cases;

macro_rules! shared_cases {
    ($($name:ident),* $(,)?) => { $( #[test] fn $name() { test_cases::$name(); } )* };
}

shared_cases!(
    periodic_messages_keep_their_period,
    changes_go_out_early_but_not_too_often,
    inputs_go_stale_after_three_periods,
    invalid_frames_do_not_refresh,
    dtcs_encode_like_uds,
    dtc_store_keeps_iso_14229_status,
    supervision_records_network_dtcs,
);

#[test]
fn dtcs_print_as_j2012_codes() {
    use crate::*;
    assert_eq!(
        std::format!("{}", lost_communication(autoplug_can::Node::Engine)),
        "U0100-87"
    );
    assert_eq!(
        std::format!("{}", invalid_data(autoplug_can::Node::Cabin)),
        "U0424-86"
    );
    assert_eq!(
        std::format!("{}", Dtc::new(DtcSystem::C, 0x0035, 0)),
        "C0035-00"
    );
}
