//! Behaviour of the bus engine: timing, arbitration, delivery, faults, error confinement,
//! statistics, determinism.

use autoplug_can::Frame;
use autoplug_virtual_bus::{
    frame_bits, AcceptanceFilter, BusConfig, BusEvent, BusOffRecovery, Delivered, ErrorState,
    FaultRule, MaskFilter, NodeConfig, NodeId, Outcome, TxError, VirtualBus,
};

const BIT_NS: u64 = 2_000;
const MS: u64 = 1_000_000;

fn frame(id: u32, data: &[u8]) -> Frame {
    Frame::new(id, data).unwrap()
}

/// SOF to end of EOF, in bits.
fn len(f: &Frame) -> u64 {
    u64::from(frame_bits(f).frame_len)
}

/// Bus occupancy including intermission, in bits.
fn total(f: &Frame) -> u64 {
    u64::from(frame_bits(f).total_with_ifs)
}

/// Stuffed SOF..CRC, in bits.
fn region(f: &Frame) -> u64 {
    u64::from(frame_bits(f).stuffed_region())
}

/// Bus time of an error frame after a CRC error: the frame to the ACK delimiter (region
/// + 3), 7 dominant flag bits, 8 delimiter bits, 3 intermission bits.
fn crc_error_total(f: &Frame) -> u64 {
    region(f) + 3 + 7 + 8 + 3
}

fn logging_bus() -> VirtualBus {
    VirtualBus::new(BusConfig {
        event_log_capacity: 10_000,
        ..BusConfig::default()
    })
}

fn drain_rx(bus: &mut VirtualBus, node: NodeId) -> Vec<Delivered> {
    std::iter::from_fn(|| bus.recv(node)).collect()
}

fn events(bus: &mut VirtualBus) -> Vec<BusEvent> {
    bus.drain_events().collect()
}

#[test]
fn lowest_identifier_wins_and_frames_follow_back_to_back() {
    let mut bus = logging_bus();
    let a = bus.attach("A", AcceptanceFilter::none());
    let b = bus.attach("B", AcceptanceFilter::none());
    let c = bus.attach("C", AcceptanceFilter::none());
    let monitor = bus.attach("monitor", AcceptanceFilter::All);
    let fa = frame(0x300, &[1, 2, 3]);
    let fb = frame(0x100, &[0xFF; 8]);
    let fc = frame(0x200, &[]);
    bus.send(a, fa, 0).unwrap();
    bus.send(b, fb, 0).unwrap();
    bus.send(c, fc, 0).unwrap();
    bus.run_until(10 * MS);

    let got = drain_rx(&mut bus, monitor);
    let start_c = total(&fb);
    let start_a = start_c + total(&fc);
    assert_eq!(
        got,
        [
            Delivered {
                t_ns: len(&fb) * BIT_NS,
                frame: fb,
                from: b
            },
            Delivered {
                t_ns: (start_c + len(&fc)) * BIT_NS,
                frame: fc,
                from: c
            },
            Delivered {
                t_ns: (start_a + len(&fa)) * BIT_NS,
                frame: fa,
                from: a
            },
        ]
    );
    let starts: Vec<u64> = events(&mut bus).iter().map(|e| e.start_ns).collect();
    assert_eq!(starts, [0, start_c * BIT_NS, start_a * BIT_NS]);
    assert_eq!(bus.id_stats(0x300).latency_max_ns, start_a * BIT_NS);
}

#[test]
fn a_node_offers_its_lowest_identifier_and_keeps_fifo_order_per_identifier() {
    let mut bus = VirtualBus::new(BusConfig::default());
    let a = bus.attach("A", AcceptanceFilter::none());
    let rx = bus.attach("rx", AcceptanceFilter::All);
    for f in [
        frame(0x300, &[1]),
        frame(0x100, &[1]),
        frame(0x300, &[2]),
        frame(0x100, &[2]),
    ] {
        bus.send(a, f, 0).unwrap();
    }
    bus.run_until(10 * MS);
    let order: Vec<(u16, u8)> = drain_rx(&mut bus, rx)
        .iter()
        .map(|d| (d.frame.id(), d.frame.data()[0]))
        .collect();
    assert_eq!(order, [(0x100, 1), (0x100, 2), (0x300, 1), (0x300, 2)]);
}

#[test]
fn a_frame_waits_for_the_frame_on_the_wire_and_its_intermission() {
    let mut bus = logging_bus();
    let a = bus.attach("A", AcceptanceFilter::none());
    let b = bus.attach("B", AcceptanceFilter::none());
    let rx = bus.attach("rx", AcceptanceFilter::All);
    let long = frame(0x400, &[0; 8]);
    let urgent = frame(0x001, &[7]);
    bus.send(a, long, 0).unwrap();
    // Higher priority, but the bus is taken: it cannot preempt.
    bus.send(b, urgent, 10_000).unwrap();
    let eof_end = (total(&long) + len(&urgent)) * BIT_NS;
    bus.run_until(eof_end);
    let got = drain_rx(&mut bus, rx);
    assert_eq!(got[1].t_ns, eof_end);
    assert_eq!(
        bus.id_stats(0x001).latency_max_ns,
        total(&long) * BIT_NS - 10_000
    );

    // Sent during the intermission: starts right after it.
    bus.send(a, long, eof_end).unwrap();
    bus.run_until(2 * MS);
    assert_eq!(events(&mut bus)[2].start_ns, eof_end + 3 * BIT_NS);

    // Sent between bit boundaries on an idle bus: starts at the next boundary.
    bus.send(a, urgent, 5 * MS + 1).unwrap();
    bus.run_until(6 * MS);
    assert_eq!(events(&mut bus)[0].start_ns, 5 * MS + BIT_NS);
}

#[test]
fn nothing_is_delivered_before_its_time() {
    let mut bus = VirtualBus::new(BusConfig::default());
    let a = bus.attach("A", AcceptanceFilter::none());
    let rx = bus.attach("rx", AcceptanceFilter::All);
    let f = frame(0x123, &[0xAA; 8]);
    bus.send(a, f, 0).unwrap();
    let end = len(&f) * BIT_NS;
    bus.run_until(end - 1);
    assert_eq!(bus.recv(rx), None);
    bus.run_until(end);
    assert_eq!(bus.recv(rx).map(|d| d.t_ns), Some(end));
}

#[test]
fn acceptance_filters_pick_what_each_node_consumes() {
    let mut bus = VirtualBus::new(BusConfig::default());
    let tx = bus.attach("tx", AcceptanceFilter::none());
    let list = bus.attach("list", AcceptanceFilter::ids(&[0x003, 0x024]));
    let mask = bus.attach(
        "mask",
        AcceptanceFilter::Masks(vec![MaskFilter {
            id: 0x020,
            mask: 0x7F8,
        }]),
    );
    let all = bus.attach("all", AcceptanceFilter::All);
    let deaf = bus.attach("deaf", AcceptanceFilter::none());
    let ids = [0x003, 0x004, 0x020, 0x024, 0x028];
    for (i, id) in ids.into_iter().enumerate() {
        bus.send(tx, frame(id, &[]), i as u64 * MS).unwrap();
    }
    bus.run_until(10 * MS);
    let ids_of = |bus: &mut VirtualBus, n| {
        drain_rx(bus, n)
            .iter()
            .map(|d| d.frame.id())
            .collect::<Vec<_>>()
    };
    assert_eq!(ids_of(&mut bus, list), [0x003, 0x024]);
    assert_eq!(ids_of(&mut bus, mask), [0x020, 0x024]);
    assert_eq!(ids_of(&mut bus, all), ids.map(|id| id as u16));
    assert!(ids_of(&mut bus, deaf).is_empty());
    // Filtering is after the controller: the deaf node still acknowledged and counted.
    assert_eq!(bus.node_stats(tx).tx_frames, 5);
}

#[test]
fn no_loopback_unless_configured() {
    let mut bus = logging_bus();
    let plain = bus.attach("plain", AcceptanceFilter::All);
    let echo = bus.attach_with(
        "echo",
        AcceptanceFilter::All,
        NodeConfig {
            loopback: true,
            ..NodeConfig::default()
        },
    );
    bus.send(plain, frame(0x010, &[1]), 0).unwrap();
    bus.send(echo, frame(0x011, &[2]), 0).unwrap();
    bus.run_until(MS);
    let plain_got: Vec<u16> = drain_rx(&mut bus, plain)
        .iter()
        .map(|d| d.frame.id())
        .collect();
    let echo_got: Vec<(u16, NodeId)> = drain_rx(&mut bus, echo)
        .iter()
        .map(|d| (d.frame.id(), d.from))
        .collect();
    assert_eq!(plain_got, [0x011]);
    assert_eq!(echo_got, [(0x010, plain), (0x011, echo)]);
    let receivers: Vec<_> = events(&mut bus)
        .iter()
        .map(|e| match e.outcome {
            Outcome::Received { receivers } => receivers.iter().collect::<Vec<_>>(),
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(receivers, [vec![echo], vec![plain, echo]]);
}

#[test]
fn transmit_queue_overflow_is_refused_and_counted() {
    let mut bus = VirtualBus::new(BusConfig::default());
    let small = NodeConfig {
        tx_queue_capacity: 2,
        ..NodeConfig::default()
    };
    let a = bus.attach_with("A", AcceptanceFilter::none(), small);
    let _rx = bus.attach("rx", AcceptanceFilter::All);
    let f = frame(0x100, &[0; 8]);
    assert_eq!(bus.send(a, f, 0), Ok(()));
    assert_eq!(bus.send(a, f, 0), Ok(()));
    assert_eq!(bus.send(a, f, 0), Err(TxError::QueueFull { capacity: 2 }));
    // The frame on the wire still holds its slot until it is through.
    bus.run_until(BIT_NS * 10);
    assert_eq!(bus.tx_pending(a), 2);
    assert_eq!(
        bus.send(a, f, BIT_NS * 10),
        Err(TxError::QueueFull { capacity: 2 })
    );
    let stats = bus.node_stats(a);
    assert_eq!((stats.tx_overflows, stats.tx_queue_high_water), (2, 2));
    bus.run_until(10 * MS);
    assert_eq!(bus.node_stats(a).tx_frames, 2);
}

#[test]
fn receive_queue_overrun_loses_the_new_frame_and_counts_it() {
    let mut bus = logging_bus();
    let a = bus.attach("A", AcceptanceFilter::none());
    let slow = bus.attach_with(
        "slow",
        AcceptanceFilter::All,
        NodeConfig {
            rx_queue_capacity: 2,
            ..NodeConfig::default()
        },
    );
    for i in 0..3 {
        bus.send(a, frame(0x100, &[i]), 0).unwrap();
    }
    bus.run_until(MS);
    let data: Vec<u8> = drain_rx(&mut bus, slow)
        .iter()
        .map(|d| d.frame.data()[0])
        .collect();
    assert_eq!(data, [0, 1]);
    assert_eq!(bus.node_stats(slow).rx_overruns, 1);
    assert_eq!(bus.node_stats(slow).rx_frames, 2);
    assert_eq!(
        events(&mut bus)[2].outcome,
        Outcome::Received {
            receivers: Default::default()
        }
    );
}

#[test]
fn sending_in_the_past_is_refused() {
    let mut bus = VirtualBus::new(BusConfig::default());
    let a = bus.attach("A", AcceptanceFilter::none());
    bus.run_until(5 * MS);
    assert_eq!(
        bus.send(a, frame(1, &[]), 4 * MS),
        Err(TxError::InPast {
            at_ns: 4 * MS,
            bus_now_ns: 5 * MS
        })
    );
}

#[test]
fn dropped_frames_take_the_bus_but_reach_nobody() {
    let mut bus = logging_bus();
    let a = bus.attach("A", AcceptanceFilter::none());
    let rx = bus.attach("rx", AcceptanceFilter::All);
    let rule = bus.add_fault(FaultRule::drop().with_id(0x100).every_nth(2));
    for i in 0..4u8 {
        bus.send(a, frame(0x100, &[i]), u64::from(i) * MS).unwrap();
        bus.send(a, frame(0x200, &[i]), u64::from(i) * MS).unwrap();
    }
    bus.run_until(10 * MS);
    let got: Vec<(u16, u8)> = drain_rx(&mut bus, rx)
        .iter()
        .map(|d| (d.frame.id(), d.frame.data()[0]))
        .collect();
    assert_eq!(
        got,
        [
            (0x100, 0),
            (0x200, 0),
            (0x200, 1),
            (0x100, 2),
            (0x200, 2),
            (0x200, 3)
        ]
    );
    assert_eq!(bus.fault_hits(rule), 2);
    assert_eq!(bus.node_stats(a).tx_frames, 8); // acknowledged, as far as the sender knows
    assert_eq!(
        (bus.id_stats(0x100).frames, bus.id_stats(0x100).dropped),
        (4, 2)
    );
    let log = events(&mut bus);
    assert_eq!(log[2].outcome, Outcome::Dropped);
    // The 0x200 after a dropped 0x100 still waited for it.
    assert_eq!(
        log[3].start_ns,
        log[2].start_ns + total(&log[2].frame) * BIT_NS
    );
}

#[test]
fn a_corrupted_frame_raises_an_error_frame_and_is_retransmitted() {
    let mut bus = logging_bus();
    let a = bus.attach("A", AcceptanceFilter::none());
    let rx = bus.attach("rx", AcceptanceFilter::All);
    let f = frame(0x100, &[0x12, 0x34]);
    bus.add_fault(FaultRule::corrupt().with_id(0x100).max_hits(1));
    bus.send(a, f, 0).unwrap();
    bus.run_until(BIT_NS * crc_error_total(&f) - 1);
    let status = bus.node_status(rx);
    assert_eq!((bus.node_status(a).tec, status.rec), (8, 1));
    bus.run_until(MS);

    let retry = crc_error_total(&f);
    let got = drain_rx(&mut bus, rx);
    assert_eq!(
        got,
        [Delivered {
            t_ns: (retry + len(&f)) * BIT_NS,
            frame: f,
            from: a
        }]
    );
    let log = events(&mut bus);
    assert_eq!(log[0].outcome, Outcome::CrcError);
    assert_eq!(log[0].end_ns, (retry - 3) * BIT_NS);
    assert_eq!(log[1].start_ns, retry * BIT_NS);
    assert_eq!((bus.node_status(a).tec, bus.node_status(rx).rec), (7, 0));
    assert_eq!(bus.node_stats(a).tx_errors, 1);
    assert_eq!(
        (bus.id_stats(0x100).frames, bus.id_stats(0x100).error_frames),
        (1, 1)
    );
    assert_eq!(
        bus.id_stats(0x100).bus_bits,
        crc_error_total(&f) + total(&f)
    );
    // Latency runs to the start of the transmission that went through.
    assert_eq!(bus.id_stats(0x100).latency_max_ns, retry * BIT_NS);
}

#[test]
fn without_automatic_retransmission_a_corrupted_frame_is_abandoned() {
    let mut bus = VirtualBus::new(BusConfig::default());
    let nart = NodeConfig {
        auto_retransmit: false,
        ..NodeConfig::default()
    };
    let a = bus.attach_with("A", AcceptanceFilter::none(), nart);
    let rx = bus.attach("rx", AcceptanceFilter::All);
    bus.add_fault(FaultRule::corrupt().from_sender(a).max_hits(1));
    bus.send(a, frame(0x100, &[1]), 0).unwrap();
    bus.send(a, frame(0x101, &[2]), 0).unwrap();
    bus.run_until(MS);
    assert_eq!(
        drain_rx(&mut bus, rx)
            .iter()
            .map(|d| d.frame.id())
            .collect::<Vec<_>>(),
        [0x101]
    );
    assert_eq!(bus.node_stats(a).tx_abandoned, 1);
}

#[test]
fn a_silenced_node_sends_nothing_but_still_receives_and_acknowledges() {
    let mut bus = VirtualBus::new(BusConfig::default());
    let mute = bus.attach("mute", AcceptanceFilter::All);
    let other = bus.attach("other", AcceptanceFilter::All);
    bus.send(mute, frame(0x100, &[1]), 0).unwrap();
    bus.send(mute, frame(0x101, &[1]), 0).unwrap();
    bus.set_silenced(mute, true); // before the bus got to them: both discarded
    assert_eq!(bus.send(mute, frame(0x102, &[1]), MS), Ok(()));
    bus.send(other, frame(0x200, &[2]), MS).unwrap();
    bus.run_until(2 * MS);
    assert_eq!(bus.recv(other), None);
    assert_eq!(bus.recv(mute).map(|d| d.frame.id()), Some(0x200));
    assert_eq!(bus.node_stats(mute).tx_suppressed, 3);
    assert!(bus.node_status(mute).silenced);
    assert_eq!(bus.node_status(other).tec, 0); // acknowledged by the silenced node

    bus.set_silenced(mute, false);
    bus.send(mute, frame(0x103, &[1]), 2 * MS).unwrap();
    bus.run_until(3 * MS);
    assert_eq!(bus.recv(other).map(|d| d.frame.id()), Some(0x103));
}

#[test]
fn a_node_alone_on_the_bus_gets_ack_errors_and_stays_error_passive() {
    let mut bus = logging_bus();
    let lone = bus.attach("lone", AcceptanceFilter::All);
    bus.send(lone, frame(0x100, &[1]), 0).unwrap();
    bus.run_until(100 * MS);
    let status = bus.node_status(lone);
    assert_eq!((status.state, status.tec), (ErrorState::Passive, 128));
    assert!(bus.node_stats(lone).tx_errors > 100);
    assert_eq!(bus.node_stats(lone).tx_frames, 0);
    assert!(events(&mut bus)
        .iter()
        .all(|e| e.outcome == Outcome::AckError));
}

/// 32 corrupted attempts: 16 as error-active, back to back; then error-passive, each
/// retry 8 bits later (suspend transmission); at TEC 256 bus-off; back after 128 × 11
/// recessive bits counted from the last error delimiter.
#[test]
fn repeated_corruption_drives_the_sender_bus_off_and_it_recovers_automatically() {
    let mut bus = logging_bus();
    let a = bus.attach("A", AcceptanceFilter::none());
    let rx = bus.attach("rx", AcceptanceFilter::All);
    let f = frame(0x100, &[0xC3; 4]);
    bus.add_fault(FaultRule::corrupt().from_sender(a).max_hits(32));
    bus.send(a, f, 0).unwrap();

    let mut start = 0;
    let mut expected_starts = Vec::new();
    for error in 1..=32 {
        expected_starts.push(start * BIT_NS);
        start += crc_error_total(&f) + if error >= 16 { 8 } else { 0 };
    }
    let last_start = expected_starts[31] / BIT_NS;
    let last_delimiter = last_start + region(&f) + 3 + 7;
    let recovered = last_delimiter + 128 * 11;

    bus.run_until(recovered * BIT_NS - 1);
    let status = bus.node_status(a);
    assert_eq!((status.state, status.tec), (ErrorState::BusOff, 256));
    assert_eq!(bus.node_status(rx).rec, 32);
    assert_eq!(bus.node_stats(a).bus_off_events, 1);

    bus.run_until(10 * MS);
    let log = events(&mut bus);
    assert_eq!(log.len(), 33);
    assert_eq!(
        log[..32].iter().map(|e| e.start_ns).collect::<Vec<_>>(),
        expected_starts
    );
    assert_eq!(
        (log[32].start_ns, log[32].outcome),
        (
            recovered * BIT_NS,
            Outcome::Received {
                receivers: [rx].into_iter().collect()
            }
        )
    );
    let status = bus.node_status(a);
    assert_eq!((status.state, status.tec), (ErrorState::Active, 0));
    assert_eq!(bus.node_stats(a).recoveries, 1);
    assert_eq!(bus.node_status(rx).rec, 31);
}

/// On a busy bus the 11-recessive-bit sequences come only between frames: with another
/// node sending back to back, each of its frames gives exactly one (ACK delimiter, EOF,
/// intermission), so recovery waits for 127 of them after the bus-off error frame's own.
#[test]
fn bus_off_recovery_takes_longer_on_a_busy_bus() {
    let mut bus = logging_bus();
    let a = bus.attach("A", AcceptanceFilter::none());
    let busy = bus.attach_with(
        "busy",
        AcceptanceFilter::none(),
        NodeConfig {
            tx_queue_capacity: 400,
            ..NodeConfig::default()
        },
    );
    let _rx = bus.attach("rx", AcceptanceFilter::All);
    bus.add_fault(FaultRule::corrupt().from_sender(a).max_hits(32));
    bus.send(a, frame(0x100, &[1]), 0).unwrap();
    for i in 0..400u16 {
        bus.send(busy, frame(0x200, &i.to_le_bytes()), 0).unwrap();
    }
    bus.run_until(200 * MS);
    let log = events(&mut bus);
    let last_error = log
        .iter()
        .rposition(|e| e.outcome == Outcome::CrcError)
        .unwrap();
    let success = log
        .iter()
        .position(|e| e.from == a && e.outcome != Outcome::CrcError)
        .unwrap();
    assert!(log[last_error + 1..success].iter().all(|e| e.from == busy));
    assert_eq!(success - last_error - 1, 127);
    assert_eq!(bus.node_stats(a).recoveries, 1);
}

#[test]
fn manual_recovery_waits_for_the_request() {
    let mut bus = VirtualBus::new(BusConfig::default());
    let manual = NodeConfig {
        bus_off_recovery: BusOffRecovery::Manual,
        ..NodeConfig::default()
    };
    let a = bus.attach_with("A", AcceptanceFilter::none(), manual);
    let rx = bus.attach("rx", AcceptanceFilter::All);
    bus.send(a, frame(0x100, &[1]), 0).unwrap();
    bus.force_bus_off(a);
    bus.run_until(100 * MS);
    assert_eq!(bus.node_status(a).state, ErrorState::BusOff);
    assert_eq!(bus.recv(rx), None);

    assert!(bus.request_recovery(a));
    assert!(!bus.request_recovery(a));
    bus.run_until(100 * MS + 128 * 11 * BIT_NS - 1);
    assert_eq!(bus.node_status(a).state, ErrorState::BusOff);
    bus.run_until(100 * MS + 128 * 11 * BIT_NS);
    assert_eq!(bus.node_status(a).state, ErrorState::Active);
    bus.run_until(110 * MS);
    let got = bus.recv(rx).unwrap();
    assert_eq!(got.t_ns, 100 * MS + (128 * 11 + len(&got.frame)) * BIT_NS);
}

#[test]
fn identical_frames_from_two_senders_merge_different_ones_are_serialised() {
    let mut bus = logging_bus();
    let steering = bus.attach("Steering", AcceptanceFilter::none());
    let pedals = bus.attach("Pedals", AcceptanceFilter::none());
    let cruise = bus.attach("Cruise", AcceptanceFilter::ids(&[0x008]));
    let off = frame(0x008, &[0]);
    bus.send(steering, off, 0).unwrap();
    bus.send(pedals, off, 0).unwrap();
    bus.run_until(MS);
    assert_eq!(drain_rx(&mut bus, cruise).len(), 1);
    assert_eq!(
        (
            bus.node_stats(steering).tx_frames,
            bus.node_stats(pedals).tx_frames
        ),
        (1, 1)
    );
    assert_eq!(
        events(&mut bus)[0].senders,
        [steering, pedals].into_iter().collect()
    );

    let on = frame(0x008, &[1]);
    bus.send(pedals, off, MS).unwrap();
    bus.send(steering, on, MS).unwrap();
    bus.run_until(2 * MS);
    let got: Vec<(NodeId, u8)> = drain_rx(&mut bus, cruise)
        .iter()
        .map(|d| (d.from, d.frame.data()[0]))
        .collect();
    assert_eq!(got, [(steering, 1), (pedals, 0)]); // lower NodeId first
    let stats = bus.bus_stats();
    assert_eq!(
        (stats.same_id_contentions, stats.merged_transmissions),
        (2, 1)
    );
}

/// One frame every millisecond for one second: the load is its bits × 2 µs / 1 ms.
#[test]
fn bus_load_of_a_periodic_schedule_matches_the_analytic_value() {
    for (f, bits) in [
        (frame(0x2AA, &[0x55; 8]), 111),
        (frame(0x000, &[0; 8]), 127),
    ] {
        assert_eq!(total(&f), bits);
        let mut bus = VirtualBus::new(BusConfig::default());
        let a = bus.attach("A", AcceptanceFilter::none());
        let _rx = bus.attach("rx", AcceptanceFilter::All);
        for k in 0..1000 {
            bus.send(a, f, k * MS).unwrap();
        }
        bus.run_until(1000 * MS);
        let s = bus.bus_stats();
        let expected = (bits * BIT_NS) as f64 / MS as f64;
        assert_eq!(s.busy_ns, 1000 * bits * BIT_NS);
        assert!(
            (s.load - expected).abs() < 1e-12,
            "{} vs {expected}",
            s.load
        );
        assert!((s.max_window_load.unwrap() - expected).abs() < 1e-12);
        assert_eq!(s.frames, 1000);
    }
}

#[test]
fn load_counts_only_the_time_elapsed() {
    let mut bus = VirtualBus::new(BusConfig::default());
    let a = bus.attach("A", AcceptanceFilter::none());
    let _rx = bus.attach("rx", AcceptanceFilter::All);
    bus.send(a, frame(0x2AA, &[0x55; 8]), 0).unwrap();
    bus.run_until(100 * BIT_NS); // mid-frame
    let s = bus.bus_stats();
    assert_eq!(s.busy_ns, 100 * BIT_NS);
    assert_eq!(s.load, 1.0);
    assert_eq!(s.max_window_load, None);
}

/// A small car-like schedule with random faults, stepped like the virtual car.
fn scenario(seed: u64) -> (Vec<BusEvent>, Vec<Vec<Delivered>>, String) {
    let mut bus = VirtualBus::new(BusConfig {
        seed,
        event_log_capacity: 100_000,
        ..BusConfig::default()
    });
    let nodes: Vec<NodeId> = (0..4)
        .map(|i| bus.attach(&format!("n{i}"), AcceptanceFilter::All))
        .collect();
    bus.add_fault(FaultRule::drop().with_probability(0.05));
    bus.add_fault(FaultRule::corrupt().with_id(0x010).with_probability(0.2));
    let mut received = vec![Vec::new(); nodes.len()];
    for step in 0..500u64 {
        let now = step * MS;
        for (i, &node) in nodes.iter().enumerate() {
            if step % (i as u64 + 1) == 0 {
                let id = 0x010 * (i as u32 + 1);
                bus.send(node, frame(id, &step.to_le_bytes()[..i * 2 + 1]), now)
                    .unwrap();
            }
        }
        bus.run_until(now + MS);
        for (i, &node) in nodes.iter().enumerate() {
            while let Some(d) = bus.recv(node) {
                assert!(d.t_ns <= now + MS, "delivered from the future");
                received[i].push(d);
            }
        }
    }
    (
        bus.drain_events().collect(),
        received,
        bus.report().to_string(),
    )
}

#[test]
fn same_inputs_and_seed_give_the_same_bus() {
    let first = scenario(7);
    assert_eq!(first, scenario(7));
    assert!(first.0.iter().any(|e| e.outcome == Outcome::CrcError));
    assert!(first.0.iter().any(|e| e.outcome == Outcome::Dropped));
    assert_ne!(first.0, scenario(8).0);
}

#[test]
fn a_full_event_log_counts_what_it_missed() {
    let mut bus = VirtualBus::new(BusConfig {
        event_log_capacity: 2,
        ..BusConfig::default()
    });
    let a = bus.attach("A", AcceptanceFilter::none());
    let _rx = bus.attach("rx", AcceptanceFilter::All);
    for i in 0..5 {
        bus.send(a, frame(0x100, &[i]), 0).unwrap();
    }
    bus.run_until(MS);
    assert_eq!(bus.drain_events().count(), 2);
    assert_eq!(bus.bus_stats().events_lost, 3);
}

#[test]
fn the_report_lists_ids_and_nodes() {
    let (_, _, report) = scenario(1);
    assert!(
        report.contains("0x010") && report.contains("0x040"),
        "{report}"
    );
    assert!(report.contains("n3"), "{report}");
    assert!(
        report.starts_with("CAN bus 500 kbit/s: 0.500 s simulated"),
        "{report}"
    );
}

#[test]
fn a_controller_node_learns_how_its_frames_went_and_can_take_one_back() {
    let mut bus = VirtualBus::new(BusConfig::default());
    let reporting = NodeConfig {
        report_transmissions: true,
        ..NodeConfig::default()
    };
    let ecu = bus.attach_with("emulated", AcceptanceFilter::All, reporting);
    let _listener = bus.attach("listener", AcceptanceFilter::All);
    let first = frame(0x100, &[1, 2]);
    let second = frame(0x200, &[3]);
    let third = frame(0x300, &[4]);
    bus.send(ecu, first, 0).unwrap();
    bus.send(ecu, second, 0).unwrap();
    bus.send(ecu, third, 0).unwrap();
    // The first starts at once; the others wait. Taking one back works until it starts.
    bus.run_until(BIT_NS);
    assert_eq!(bus.wire_busy_until_ns(), Some(len(&first) * BIT_NS));
    assert!(!bus.cancel(ecu, first), "on the wire: too late");
    assert!(bus.cancel(ecu, third));
    assert!(!bus.cancel(ecu, third), "taken back once");
    bus.run_until(MS);
    let outcomes: Vec<_> = std::iter::from_fn(|| bus.transmitted(ecu)).collect();
    assert_eq!(outcomes.len(), 2);
    assert_eq!(
        (outcomes[0].frame, outcomes[0].ok, outcomes[0].retrying),
        (first, true, false)
    );
    assert_eq!(outcomes[0].end_ns, len(&first) * BIT_NS);
    assert_eq!((outcomes[1].frame, outcomes[1].ok), (second, true));
    assert_eq!(bus.wire_busy_until_ns(), None);
}

#[test]
fn a_failed_transmission_is_reported_as_retrying() {
    let mut bus = VirtualBus::new(BusConfig::default());
    let reporting = NodeConfig {
        report_transmissions: true,
        ..NodeConfig::default()
    };
    // Alone on the bus: no acknowledgement, an ACK error, and the retransmission queued.
    let ecu = bus.attach_with("emulated", AcceptanceFilter::All, reporting);
    bus.send(ecu, frame(0x123, &[9]), 0).unwrap();
    bus.run_until(MS);
    let outcomes: Vec<_> = std::iter::from_fn(|| bus.transmitted(ecu)).collect();
    assert!(outcomes.len() > 1, "retried");
    assert!(outcomes.iter().all(|o| !o.ok && o.retrying));
}
