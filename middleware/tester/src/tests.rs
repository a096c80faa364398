//! The request/response primitive against scripted ECU frames, with exact times.

use autoplug_can::{Frame, Node};
use autoplug_ecu::Instant;

use super::*;

fn ms(ms: u64) -> Instant {
    Instant::from_millis(ms)
}

/// A single frame from `ecu`'s response identifier, padded.
fn from_ecu(ecu: Node, payload: &[u8]) -> Frame {
    let mut data = [0xCC; 8];
    data[0] = payload.len() as u8;
    data[1..=payload.len()].copy_from_slice(payload);
    Frame::new(u32::from(ecu.diag_response_id().unwrap()), &data).unwrap()
}

/// Hands out and confirms every frame the tester has at `now`.
fn flush(tester: &mut Tester, now: Instant) -> Vec<Frame> {
    let mut frames = Vec::new();
    while let Some(frame) = tester.poll_transmit(now) {
        tester.confirm_transmit(now);
        frames.push(frame);
    }
    frames
}

fn started(request: &[u8]) -> Tester {
    let mut tester = Tester::new(TesterConfig::default());
    tester.request(ms(0), Node::Cruise, request).unwrap();
    let sent = flush(&mut tester, ms(0));
    assert_eq!(sent.len(), 1);
    assert_eq!(sent[0].id(), 0x70D);
    assert_eq!(&sent[0].data()[1..=request.len()], request);
    tester
}

#[test]
fn a_positive_response_ends_the_request() {
    let mut tester = started(&[0x22, 0xF1, 0x87]);
    assert!(tester.is_busy());
    tester.on_frame(ms(3), &from_ecu(Node::Cruise, &[0x62, 0xF1, 0x87, b'A']));
    assert_eq!(
        tester.take_response(),
        Some(Ok(Response::Positive(vec![0x62, 0xF1, 0x87, b'A'])))
    );
    assert!(!tester.is_busy());
    assert_eq!(tester.take_response(), None);
}

#[test]
fn p2_runs_from_the_request_on_the_bus() {
    let mut tester = started(&[0x10, 0x02]);
    assert_eq!(tester.next_deadline(), Some(ms(50)));
    tester.poll(Instant::from_micros(49_999));
    assert_eq!(tester.take_response(), None);
    tester.poll(ms(50));
    assert_eq!(
        tester.take_response(),
        Some(Err(UdsError::Timeout {
            service: 0x10,
            waited_us: 50_000,
            pending: 0
        }))
    );
}

#[test]
fn response_pending_extends_the_wait_to_p2_star() {
    let mut tester = started(&[0x31, 0x01, 0xFF, 0x00]);
    tester.on_frame(ms(10), &from_ecu(Node::Cruise, &[0x7F, 0x31, 0x78]));
    assert_eq!(tester.next_deadline(), Some(ms(5_010)));
    tester.poll(ms(3_000));
    assert_eq!(tester.take_response(), None);
    // A negative response to another service (a TesterPresent that reached the busy ECU)
    // is not the answer.
    tester.on_frame(ms(3_500), &from_ecu(Node::Cruise, &[0x7F, 0x3E, 0x22]));
    assert_eq!(tester.take_response(), None);
    tester.on_frame(ms(4_000), &from_ecu(Node::Cruise, &[0x7F, 0x31, 0x78]));
    assert_eq!(tester.next_deadline(), Some(ms(9_000)));
    tester.on_frame(
        ms(8_000),
        &from_ecu(Node::Cruise, &[0x71, 0x01, 0xFF, 0x00, 0x00]),
    );
    assert_eq!(
        tester.take_response(),
        Some(Ok(Response::Positive(vec![0x71, 0x01, 0xFF, 0x00, 0x00])))
    );
    assert_eq!(tester.last_pending_count(), 2);

    // And silence after a pending is a timeout that says so.
    let mut tester = started(&[0x31, 0x01, 0xFF, 0x01]);
    tester.on_frame(ms(10), &from_ecu(Node::Cruise, &[0x7F, 0x31, 0x78]));
    tester.poll(ms(5_010));
    let error = tester.take_response().unwrap().unwrap_err();
    assert_eq!(
        error,
        UdsError::Timeout {
            service: 0x31,
            waited_us: 5_000_000,
            pending: 1
        }
    );
    assert_eq!(
        error.to_string(),
        "no response to 0x31 RoutineControl within 5000 ms after 1 'response pending'"
    );
}

#[test]
fn a_negative_response_is_named() {
    let mut tester = started(&[0x34, 0x00, 0x44]);
    tester.on_frame(ms(5), &from_ecu(Node::Cruise, &[0x7F, 0x34, 0x70]));
    let error = tester.take_response().unwrap().unwrap_err();
    assert_eq!(
        error,
        UdsError::Negative {
            service: 0x34,
            nrc: 0x70,
            name: "uploadDownloadNotAccepted"
        }
    );
    assert_eq!(
        error.to_string(),
        "negative response to 0x34 RequestDownload: NRC 0x70 uploadDownloadNotAccepted"
    );
}

#[test]
fn responses_of_other_ecus_do_not_answer_a_physical_request() {
    let mut tester = started(&[0x22, 0xF1, 0x87]);
    tester.on_frame(ms(1), &from_ecu(Node::ABS, &[0x62, 0xF1, 0x87, b'X']));
    assert_eq!(tester.take_response(), None);
    tester.on_frame(ms(2), &from_ecu(Node::Cruise, &[0x62, 0xF1, 0x87, b'C']));
    assert!(matches!(tester.take_response(), Some(Ok(Response::Positive(r))) if r[3] == b'C'));
}

#[test]
fn a_multi_frame_response_stops_p2_and_gets_flow_control() {
    let mut tester = started(&[0x22, 0xF1, 0x87]);
    let id = 0x78D;
    // First frame of a 10-byte response at 40 ms; the rest after P2 would have run out.
    let first = Frame::new(id, &[0x10, 0x0A, 0x62, 0xF1, 0x87, b'A', b'P', b'-']).unwrap();
    tester.on_frame(ms(40), &first);
    let flow_control = flush(&mut tester, ms(40));
    assert_eq!(flow_control.len(), 1);
    assert_eq!(flow_control[0].id(), 0x70D);
    assert_eq!(flow_control[0].data()[0] >> 4, 3, "a flow control frame");
    tester.poll(ms(80));
    assert_eq!(tester.take_response(), None, "P2 no longer runs");
    let consecutive = Frame::new(id, &[0x21, b'C', b'R', b'U', b'I', 0xCC, 0xCC, 0xCC]).unwrap();
    tester.on_frame(ms(90), &consecutive);
    assert_eq!(
        tester.take_response(),
        Some(Ok(Response::Positive(b"\x62\xF1\x87AP-CRUI".to_vec())))
    );
}

#[test]
fn one_request_at_a_time() {
    let mut tester = started(&[0x22, 0xF1, 0x87]);
    assert_eq!(
        tester.request(ms(1), Node::ABS, &[0x22, 0xF1, 0x87]),
        Err(UdsError::Busy)
    );
    assert_eq!(
        tester.request_functional(ms(1), &[0x3E, 0x00]),
        Err(UdsError::Busy)
    );
    let mut idle = Tester::new(TesterConfig::default());
    assert_eq!(
        idle.request(ms(0), Node::Gateway, &[0x3E, 0x00]),
        Err(UdsError::NotAnEcu(Node::Gateway))
    );
    assert!(matches!(
        idle.request_functional(ms(0), &[0x22; 8]),
        Err(UdsError::Unsendable { service: 0x22, .. })
    ));
    assert!(matches!(
        idle.request(ms(0), Node::ABS, &[]),
        Err(UdsError::Unsendable { .. })
    ));
}

#[test]
fn functional_requests_collect_answers_within_the_window() {
    let mut tester = Tester::new(TesterConfig::default());
    tester.request_functional(ms(0), &[0x10, 0x03]).unwrap();
    let sent = flush(&mut tester, ms(1));
    assert_eq!(sent.len(), 1);
    assert_eq!(sent[0].id(), 0x7DF);
    assert_eq!(
        sent[0].data(),
        [0x02, 0x10, 0x03, 0xCC, 0xCC, 0xCC, 0xCC, 0xCC]
    );
    // The window runs from the frame's confirmation.
    assert_eq!(tester.next_deadline(), Some(ms(101)));
    let positive = [0x50, 0x03, 0x00, 0x32, 0x01, 0xF4];
    tester.on_frame(ms(2), &from_ecu(Node::Engine, &positive));
    tester.on_frame(ms(3), &from_ecu(Node::ABS, &[0x7F, 0x10, 0x22]));
    // An ECU that needs longer says so; the window waits for it.
    tester.on_frame(ms(4), &from_ecu(Node::Cabin, &[0x7F, 0x10, 0x78]));
    tester.poll(ms(101));
    assert_eq!(tester.take_response(), None);
    tester.on_frame(ms(900), &from_ecu(Node::Cabin, &positive));
    tester.poll(ms(5_004));
    let Some(Ok(Response::Functional(answers))) = tester.take_response() else {
        panic!("functional answers")
    };
    assert_eq!(
        answers,
        vec![
            FunctionalResponse {
                ecu: Node::Engine,
                result: Ok(positive.to_vec())
            },
            FunctionalResponse {
                ecu: Node::ABS,
                result: Err(UdsError::negative(0x10, 0x22))
            },
            FunctionalResponse {
                ecu: Node::Cabin,
                result: Ok(positive.to_vec())
            },
        ]
    );
}

#[test]
fn tester_present_goes_every_two_seconds_with_the_response_suppressed() {
    let mut tester = Tester::new(TesterConfig::default());
    let mut sent_at = Vec::new();
    tester.set_tester_present(true);
    let mut now = ms(0);
    while now < ms(7_000) {
        tester.poll(now);
        for frame in flush(&mut tester, now) {
            assert_eq!(frame.id(), 0x7DF);
            assert_eq!(
                frame.data(),
                [0x02, 0x3E, 0x80, 0xCC, 0xCC, 0xCC, 0xCC, 0xCC]
            );
            sent_at.push(now);
        }
        now = tester.next_deadline().unwrap().max(now.plus_micros(1));
    }
    assert_eq!(sent_at, [ms(0), ms(2_000), ms(4_000), ms(6_000)]);
    tester.set_tester_present(false);
    assert_eq!(tester.next_deadline(), None);
}

#[test]
fn late_answers_to_earlier_requests_are_not_taken() {
    // A block whose first answer came too late was sent again; the late answer to block 7
    // must not be taken for block 8's.
    let mut tester = Tester::new(TesterConfig::default());
    tester
        .request_echoing(ms(0), Node::Cruise, &[0x36, 0x08, 0xAA, 0xBB], 1)
        .unwrap();
    flush(&mut tester, ms(0));
    tester.on_frame(ms(5), &from_ecu(Node::Cruise, &[0x76, 0x07]));
    assert_eq!(tester.take_response(), None);
    tester.on_frame(ms(6), &from_ecu(Node::Cruise, &[0x76, 0x08]));
    assert_eq!(
        tester.take_response(),
        Some(Ok(Response::Positive(vec![0x76, 0x08])))
    );
}

#[test]
fn nothing_answers_a_request_that_is_still_going_out() {
    let mut tester = Tester::new(TesterConfig::default());
    let block: Vec<u8> = [0x36, 0x01].into_iter().chain(0..40).collect();
    tester
        .request_echoing(ms(0), Node::Cruise, &block, 1)
        .unwrap();
    let first = tester.poll_transmit(ms(0)).unwrap();
    assert_eq!(first.data()[0] >> 4, 1, "a first frame");
    tester.confirm_transmit(ms(0));
    assert_eq!(tester.request_progress(), Some((6, 42)));
    let flow_control =
        Frame::new(0x78D, &[0x30, 0x00, 0x00, 0xCC, 0xCC, 0xCC, 0xCC, 0xCC]).unwrap();
    tester.on_frame(ms(1), &flow_control);
    let second = tester.poll_transmit(ms(1)).unwrap();
    tester.confirm_transmit(ms(1));
    assert_eq!(second.data()[0], 0x21);
    // The answer to an earlier transmission of the same block arrives meanwhile.
    tester.on_frame(ms(2), &from_ecu(Node::Cruise, &[0x76, 0x01]));
    assert_eq!(tester.take_response(), None);
    let rest = flush(&mut tester, ms(3));
    assert_eq!(rest.len(), 5);
    assert_eq!(tester.request_progress(), Some((42, 42)));
    tester.on_frame(ms(4), &from_ecu(Node::Cruise, &[0x76, 0x01]));
    assert_eq!(
        tester.take_response(),
        Some(Ok(Response::Positive(vec![0x76, 0x01])))
    );
}

/// A tester for a transport that queues `window` frames, with ΔP2 `delta_ms`.
fn over_a_queue(window: usize, delta_ms: u64) -> Tester {
    let mut tester = Tester::new(TesterConfig::default());
    tester.set_transport(window, delta_ms * 1000);
    tester
}

/// The ECU's flow control after a first frame: block size 0, STmin 0.
fn flow_control(ecu: Node) -> Frame {
    let mut data = [0xCC; 8];
    data[..3].copy_from_slice(&[0x30, 0x00, 0x00]);
    Frame::new(u32::from(ecu.diag_response_id().unwrap()), &data).unwrap()
}

#[test]
fn a_queue_gets_a_windows_worth_of_frames_and_p2_starts_at_the_last_ones_confirmation() {
    let mut tester = over_a_queue(3, 20);
    // 50 bytes: a first frame and seven consecutive frames.
    let request: Vec<u8> = [0x36, 0x01].into_iter().chain(0..48).collect();
    tester.request(ms(0), Node::Cruise, &request).unwrap();
    let first = tester.poll_transmit(ms(0)).expect("the first frame");
    assert_eq!(first.data()[0] >> 4, 1);
    assert_eq!(
        tester.poll_transmit(ms(0)),
        None,
        "no more before the flow control"
    );
    tester.confirm_transmit(ms(1));
    tester.on_frame(ms(2), &flow_control(Node::Cruise));
    // Three in the queue at once, then one more per confirmation.
    let mut handed = Vec::new();
    while let Some(frame) = tester.poll_transmit(ms(2)) {
        handed.push(frame);
    }
    assert_eq!(handed.len(), 3);
    for confirmed in 0..4 {
        tester.confirm_transmit(ms(3 + confirmed));
        while let Some(frame) = tester.poll_transmit(ms(3 + confirmed)) {
            handed.push(frame);
        }
    }
    assert_eq!(handed.len(), 7, "every consecutive frame handed out");
    assert_eq!(tester.request_progress(), Some((4 * 7 + 6, 50)));
    // All handed out, three on their way: no P2 yet, whatever the time.
    tester.poll(ms(500));
    assert_eq!(tester.take_response(), None);
    tester.confirm_transmit(ms(501));
    tester.confirm_transmit(ms(502));
    tester.poll(ms(600));
    assert_eq!(tester.take_response(), None, "one frame still on its way");
    tester.confirm_transmit(ms(603));
    assert_eq!(tester.request_progress(), Some((50, 50)));
    // P2client = P2server 50 ms + ΔP2 20 ms from the last confirmation.
    assert_eq!(tester.next_deadline(), Some(ms(673)));
    tester.poll(Instant::from_micros(672_999));
    assert_eq!(tester.take_response(), None);
    tester.poll(ms(673));
    assert_eq!(
        tester.take_response(),
        Some(Err(UdsError::Timeout {
            service: 0x36,
            waited_us: 70_000,
            pending: 0
        }))
    );
}

#[test]
fn an_answer_before_the_confirmation_shows_the_request_was_on_the_bus() {
    let mut tester = over_a_queue(10, 50);
    tester.request(ms(0), Node::Cruise, &[0x10, 0x02]).unwrap();
    assert!(tester.poll_transmit(ms(0)).is_some());
    // A transport that models its confirmations may confirm after the bus did.
    tester.on_frame(
        ms(1),
        &from_ecu(Node::Cruise, &[0x50, 0x02, 0, 50, 1, 0xF4]),
    );
    assert_eq!(
        tester.take_response(),
        Some(Ok(Response::Positive(vec![0x50, 0x02, 0, 50, 1, 0xF4])))
    );
    // Its confirmation, late, belongs to that request, not to the next one.
    tester.request(ms(2), Node::Cruise, &[0x27, 0x01]).unwrap();
    assert!(tester.poll_transmit(ms(2)).is_some());
    tester.confirm_transmit(ms(3));
    assert_eq!(tester.request_progress(), Some((0, 2)));
    tester.confirm_transmit(ms(4));
    assert_eq!(tester.request_progress(), Some((2, 2)));
    assert_eq!(tester.next_deadline(), Some(ms(104)));
}

#[test]
fn a_frame_the_queue_never_confirms_ends_its_request_after_n_as() {
    let mut tester = over_a_queue(10, 0);
    tester.request(ms(0), Node::Cruise, &[0x10, 0x02]).unwrap();
    assert!(tester.poll_transmit(ms(0)).is_some());
    assert_eq!(tester.next_deadline(), Some(ms(1000)));
    tester.poll(ms(999));
    assert_eq!(tester.take_response(), None);
    tester.poll(ms(1000));
    assert_eq!(
        tester.take_response(),
        Some(Err(UdsError::Transport {
            service: 0x10,
            error: ChannelError::TimeoutAs
        }))
    );
}

#[test]
fn delta_p2_lengthens_every_wait_and_a_configured_one_stays() {
    let mut tester = over_a_queue(1, 30);
    tester.request(ms(0), Node::Cruise, &[0x10, 0x02]).unwrap();
    flush(&mut tester, ms(0));
    assert_eq!(tester.next_deadline(), Some(ms(80)));
    tester.on_frame(ms(10), &from_ecu(Node::Cruise, &[0x7F, 0x10, 0x78]));
    assert_eq!(tester.next_deadline(), Some(ms(10 + 5000 + 30)));

    let config = TesterConfig {
        network_delay_us: Some(5_000),
        ..TesterConfig::default()
    };
    let mut tester = Tester::new(config);
    tester.set_transport(10, 50_000);
    assert_eq!(
        tester.config().delta_p2_us(),
        5_000,
        "the user's ΔP2 is kept"
    );
    assert_eq!(tester.transmit_window(), 10);
}
