//! Test cases shared by the host test suite and the on-target (defmt-test) suite. Each case
//! panics on failure.

use crate::*;
use autoplug_can::{
    CanMessage, CruiseMode, CruiseModeMsg, DecodeError, EngineMode, EngineMsg, Frame, SteeringMsg,
    VehicleSpeedMsg,
};

fn ms(t: u64) -> Instant {
    Instant::from_millis(t)
}

/// A message is sent at once, then once per period while it does not change.
pub fn periodic_messages_keep_their_period() {
    let mut tx = PeriodicTx::of::<VehicleSpeedMsg>(); // 10 ms, 5 ms gap
    assert_eq!(tx.poll(ms(0)), None, "nothing before the first value");
    tx.set_message(&VehicleSpeedMsg {
        vehicle_speed: 50.0,
    });
    let first = tx.poll(ms(0)).expect("first value goes out at once");
    assert_eq!(first.data(), &[50]);
    let mut sent = [0u64; 8];
    let mut count = 0;
    for t in 1..=70 {
        if tx.poll(ms(t)).is_some() {
            sent[count] = t;
            count += 1;
        }
    }
    assert_eq!(&sent[..count], &[10, 20, 30, 40, 50, 60, 70]);
    assert_eq!(tx.next_due(), Some(ms(80)));
}

/// A change goes out early, but not sooner than the minimum gap after the last frame.
pub fn changes_go_out_early_but_not_too_often() {
    let mut tx = PeriodicTx::of::<CruiseModeMsg>(); // 20 ms, 5 ms gap
    tx.set_message(&CruiseModeMsg {
        cruise_mode: CruiseMode::Off,
    });
    assert!(tx.poll(ms(0)).is_some());
    tx.set_message(&CruiseModeMsg {
        cruise_mode: CruiseMode::On,
    });
    assert_eq!(tx.poll(ms(2)), None, "within the 5 ms gap");
    assert_eq!(tx.poll(ms(4)), None, "still within the gap");
    let on = tx
        .poll(ms(5))
        .expect("the change goes out once the gap has passed");
    assert_eq!(on.data(), &[1]);
    assert_eq!(tx.poll(ms(6)), None, "sent already");
    assert_eq!(tx.poll(ms(24)), None, "next periodic is at 25");
    assert!(tx.poll(ms(25)).is_some());
}

fn speed_frame(kmh: u8) -> Frame {
    Frame::new(u32::from(VehicleSpeedMsg::ID), &[kmh]).unwrap()
}

/// An input goes stale after 3 periods without a valid frame, and fresh again on one.
pub fn inputs_go_stale_after_three_periods() {
    let mut input: Input<VehicleSpeedMsg> = Input::new(ms(0));
    assert_eq!(input.timeout_us(), 30_000);
    assert_eq!(input.check(ms(29)), None);
    assert!(!input.is_stale());
    assert_eq!(
        input.check(ms(30)),
        Some(Freshness::Stale),
        "never received: stale at 3 periods"
    );
    assert_eq!(input.accept(ms(31), &speed_frame(80)), Some(Ok(())));
    assert_eq!(input.check(ms(31)), Some(Freshness::Fresh));
    assert_eq!(input.value().vehicle_speed, 80.0);
    for t in (41..=91).step_by(10) {
        input.accept(ms(t), &speed_frame(81));
        assert_eq!(
            input.check(ms(t + 5)),
            None,
            "periodic frames keep it fresh"
        );
    }
    assert_eq!(input.check(ms(120)), None, "29 ms after the last frame");
    assert_eq!(input.check(ms(121)), Some(Freshness::Stale));
    assert_eq!(
        input.value().vehicle_speed,
        81.0,
        "stale input keeps its last good value"
    );
}

/// Invalid frames do not refresh an input, are counted, and do not overwrite good values.
pub fn invalid_frames_do_not_refresh() {
    let mut input: Input<SteeringMsg> = Input::new(ms(0));
    let good = Frame::new(u32::from(SteeringMsg::ID), &[60]).unwrap();
    let bad = Frame::new(u32::from(SteeringMsg::ID), &[200]).unwrap();
    let short = Frame::new(u32::from(SteeringMsg::ID), &[]).unwrap();
    assert_eq!(input.accept(ms(0), &good), Some(Ok(())));
    let angle = input.value().steering_angle;
    for t in 1..=40 {
        let frame = if t % 2 == 0 { bad } else { short };
        assert!(matches!(input.accept(ms(t), &frame), Some(Err(_))));
    }
    assert_eq!(input.invalid_frames(), 40);
    assert_eq!(input.value().steering_angle, angle);
    assert!(matches!(
        input.last_error(),
        Some(DecodeError::OutOfRange { raw: 200, .. })
    ));
    assert_eq!(
        input.check(ms(30)),
        Some(Freshness::Stale),
        "a sender of garbage is as good as silent"
    );
    assert_eq!(
        input.accept(ms(30), &speed_frame(1)),
        None,
        "other messages are not taken"
    );
}

/// DTCs encode as UDS sends them and print as J2012 codes.
pub fn dtcs_encode_like_uds() {
    let dtc = lost_communication(autoplug_can::Node::Engine);
    assert_eq!(dtc.to_bytes(), [0xC1, 0x00, 0x87]);
    assert_eq!(dtc.to_u24(), 0xC1_0087);
    assert_eq!(Dtc::from_u24(0xC1_0087), dtc);
    assert_eq!(
        Dtc::new(DtcSystem::P, 0x0301, 0x00).to_bytes(),
        [0x03, 0x01, 0x00]
    );
    assert_eq!(
        Dtc::new(DtcSystem::C, 0x0035, 0x00).to_bytes(),
        [0x40, 0x35, 0x00]
    );
    assert_eq!(
        Dtc::new(DtcSystem::B, 0x1000, 0x11).to_bytes(),
        [0x90, 0x00, 0x11]
    );
    assert_eq!(
        invalid_data(autoplug_can::Node::ABS).failure_type(),
        FTB_SIGNAL_INVALID
    );
    // Every node has its own pair of codes.
    let nodes = autoplug_can::Node::ALL;
    for (i, a) in nodes.iter().enumerate() {
        for b in &nodes[i + 1..] {
            assert_ne!(lost_communication(*a), lost_communication(*b));
            assert_ne!(invalid_data(*a), invalid_data(*b));
        }
    }
}

/// Status bits, occurrence counts, clearing, recording control and a full store.
pub fn dtc_store_keeps_iso_14229_status() {
    let mut store: DtcStore<2> = DtcStore::new();
    let a = lost_communication(autoplug_can::Node::Cruise);
    let b = invalid_data(autoplug_can::Node::Cruise);
    let c = lost_communication(autoplug_can::Node::ABS);
    assert!(store.report_failed(a, ms(10)));
    assert!(!store.report_failed(a, ms(20)), "already active");
    let record = *store.get(a).unwrap();
    assert_eq!(record.status, 0x2F);
    assert_eq!(record.status & !status::AVAILABILITY_MASK, 0);
    assert_eq!(
        (record.occurrences, record.first_failed, record.last_failed),
        (1, ms(10), ms(20))
    );
    store.report_passed(a);
    assert!(!store.is_active(a));
    assert_eq!(
        store.get(a).unwrap().status,
        0x2E,
        "stays confirmed after the fault goes"
    );
    assert!(store.report_failed(a, ms(30)));
    assert_eq!(store.get(a).unwrap().occurrences, 2);
    assert!(store.report_failed(b, ms(30)));
    assert!(!store.report_failed(c, ms(40)), "store full");
    assert_eq!(store.dropped(), 1);
    store.set_recording(false);
    store.report_passed(a);
    assert!(store.is_active(a), "0x85 off: status frozen");
    store.set_recording(true);
    store.clear();
    assert_eq!(store.records().count(), 0);
    assert_eq!(store.dropped(), 0);
}

/// `receive` and `supervise` record and clear the network DTCs against the sender.
pub fn supervision_records_network_dtcs() {
    let mut dtcs = Dtcs::new();
    let mut engine: Input<EngineMsg> = Input::new(ms(0));
    let node = autoplug_can::Node::Engine;
    let good = EngineMsg {
        engine_rpm: 3000.0,
        fuel_level: 40.0,
        engine_mode: EngineMode::Sport,
        fuel_used: 0.0,
    }
    .frame();
    let bad = Frame::new(u32::from(EngineMsg::ID), &[1, 2, 9, 0, 0]).unwrap();
    assert!(receive(&mut engine, &mut dtcs, ms(0), &good));
    assert!(!receive(&mut engine, &mut dtcs, ms(0), &speed_frame(3)));
    assert!(!supervise(&mut engine, &mut dtcs, ms(59)));
    assert!(
        supervise(&mut engine, &mut dtcs, ms(60)),
        "20 ms period: stale at 60 ms"
    );
    assert!(dtcs.is_active(lost_communication(node)));
    assert!(receive(&mut engine, &mut dtcs, ms(61), &bad));
    assert!(dtcs.is_active(invalid_data(node)));
    assert!(
        supervise(&mut engine, &mut dtcs, ms(62)),
        "an invalid frame does not revive it"
    );
    assert!(receive(&mut engine, &mut dtcs, ms(63), &good));
    assert!(!supervise(&mut engine, &mut dtcs, ms(63)));
    assert!(!dtcs.is_active(lost_communication(node)));
    assert!(!dtcs.is_active(invalid_data(node)));
    assert_eq!(dtcs.records().count(), 2, "both stay stored");
}
