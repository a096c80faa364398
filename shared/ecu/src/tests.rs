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

/// A control loop on an MCU polls right after its ticker, a few µs late and not always by
/// the same amount: the message keeps its period, neither drifting a period behind when
/// a poll is earlier than the last nor sending twice.
#[test]
fn a_period_survives_jittered_polls() {
    use crate::*;
    use autoplug_can::VehicleSpeedMsg;
    let mut tx = PeriodicTx::of::<VehicleSpeedMsg>(); // 10 ms
    tx.set_message(&VehicleSpeedMsg {
        vehicle_speed: 50.0,
    });
    let latency_us = [40, 3, 25, 1, 60, 2, 30, 7];
    let mut sent = 0;
    for (k, latency) in (0..80u64).zip(latency_us.iter().cycle()) {
        if tx
            .poll(Instant::from_micros(k * 10_000 + latency))
            .is_some()
        {
            sent += 1;
        }
        // A poll between the steps (a frame received) sends nothing new.
        assert_eq!(tx.poll(Instant::from_micros(k * 10_000 + 4_000)), None);
    }
    assert_eq!(sent, 80, "one frame per step");
    // A poll a period and more late starts the period afresh from it.
    assert!(tx.poll(Instant::from_micros(830_000)).is_some());
    assert_eq!(tx.next_due(), Some(Instant::from_micros(840_000)));
}

/// The book's table of network trouble codes says what the DBC assigns, node by node.
#[test]
fn the_docs_network_code_table_is_the_dbcs() {
    use crate::{invalid_data, lost_communication, Dtc};
    use autoplug_can::Node;
    use std::string::{String, ToString};
    use std::vec::Vec;
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../docs/src/ecus-and-bench.md"
    );
    let page = std::fs::read_to_string(path).expect("the ECUs' page");
    let rows: Vec<Vec<String>> = page
        .lines()
        .skip_while(|l| !l.starts_with("| sender | lost communication | invalid data |"))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            l.split('|')
                .map(|c| c.trim().to_string())
                .filter(|c| !c.is_empty())
                .collect()
        })
        .collect();
    let code = |dtc: Dtc| dtc.to_string().split('-').next().unwrap().to_string();
    let expected: Vec<Vec<String>> = Node::ECUS
        .iter()
        .map(|&n| {
            std::vec![
                n.name().to_string(),
                code(lost_communication(n)),
                code(invalid_data(n))
            ]
        })
        .collect();
    let mut sorted = rows.clone();
    sorted.sort();
    let mut expected_sorted = expected;
    expected_sorted.sort();
    assert_eq!(
        sorted, expected_sorted,
        "{path}: the table, against the DBC"
    );
}
