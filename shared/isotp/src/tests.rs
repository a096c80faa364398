extern crate std;

use std::boxed::Box;
use std::string::ToString;
use std::vec::Vec;

use crate::test_cases;
use crate::*;
use autoplug_can::Frame;
use autoplug_ecu::Instant;
use proptest::prelude::*;

macro_rules! shared_cases {
    ($($name:ident),* $(,)?) => { $( #[test] fn $name() { test_cases::$name(); } )* };
}

shared_cases!(
    single_frame_bytes,
    segmented_frame_bytes,
    flow_control_bytes,
    st_min_bytes,
    sender_honours_st_min_in_milliseconds,
    sender_honours_st_min_in_microseconds,
    sender_treats_reserved_st_min_as_127_ms,
    sender_waits_for_flow_control_after_each_block,
    sequence_numbers_wrap_after_15,
    receiver_sends_flow_control_after_each_block,
    wrong_sequence_number_aborts_reception,
    sender_times_out_without_flow_control,
    receiver_times_out_without_consecutive_frame,
    sender_times_out_without_confirmation,
    receiver_times_out_without_confirmation,
    sender_handles_wait_frames,
    sender_aborts_on_overflow_and_invalid_flow_status,
    send_refusals,
    receiver_not_ready_waits_then_refuses,
    receiver_ready_again_sends_clear_to_send,
    unreleased_buffer_holds_off_new_pdus,
    first_frame_longer_than_buffer_is_refused,
    functional_addressing,
    new_pdu_interrupts_reception,
    malformed_and_unexpected_frames_are_ignored,
    other_identifiers_are_ignored,
    padded_and_unpadded_peer_frames,
    flow_control_goes_before_consecutive_frames,
    next_deadline_follows_the_state,
    abort_returns_to_idle,
    stray_confirmation_is_ignored,
);

/// Every error names what went wrong, with its numbers.
#[test]
fn errors_say_what_went_wrong() {
    let cases: [(ChannelError, &[&str]); 12] = [
        (ChannelError::TimeoutAs, &["N_As", "not confirmed"]),
        (ChannelError::TimeoutAr, &["N_Ar", "flow control"]),
        (ChannelError::TimeoutBs, &["N_Bs", "no flow control"]),
        (ChannelError::TimeoutCr, &["N_Cr", "no consecutive frame"]),
        (
            ChannelError::WrongSequenceNumber {
                expected: 4,
                got: 9,
            },
            &["sequence number 9", "4 was due"],
        ),
        (ChannelError::Overflow, &["FC.OVFLW"]),
        (
            ChannelError::TooManyWaits { max: 7 },
            &["more than 7 FC.WAIT"],
        ),
        (ChannelError::InvalidFlowStatus(5), &["flow status 5"]),
        (
            ChannelError::ReceptionInterrupted,
            &["new single or first frame"],
        ),
        (
            ChannelError::IncomingTooLong {
                announced: 5000,
                capacity: 4095,
            },
            &["5000 bytes", "4095-byte"],
        ),
        (
            ChannelError::IncomingRefused { waits: 3 },
            &["after 3 FC.WAIT"],
        ),
        (ChannelError::ReceiverBusy, &["dropped", "unreleased"]),
    ];
    for (error, needles) in cases {
        let text = error.to_string();
        for needle in needles {
            assert!(text.contains(needle), "{text:?} should mention {needle:?}");
        }
    }
    assert!(SendError::Busy.to_string().contains("already in progress"));
    assert!(SendError::Empty.to_string().contains("empty"));
    assert!(SendError::TooLong { len: 70, max: 64 }
        .to_string()
        .contains("70 bytes: this channel sends at most 64"));
}

#[test]
fn errors_name_their_direction() {
    assert_eq!(ChannelError::TimeoutBs.direction(), Direction::Transmit);
    assert_eq!(ChannelError::Overflow.direction(), Direction::Transmit);
    assert_eq!(ChannelError::TimeoutCr.direction(), Direction::Receive);
    assert_eq!(ChannelError::ReceiverBusy.direction(), Direction::Receive);
}

const A_TX: u16 = 0x701; // the tester's request identifier
const B_TX: u16 = 0x781; // the ECU's response identifier

/// Bit time on the 500 kbit/s bus.
const BIT_US: u64 = 2;

/// A deterministic jitter source, seeded by proptest.
struct Jitter(u64);

impl Jitter {
    fn next(&mut self, below: u64) -> u64 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 33) % below
    }
}

/// One side of the back-to-back test: its channel, its frame in the transmitter and
/// what its upper layer saw.
struct Side {
    channel: Box<Channel<4095>>,
    /// Handed out by `poll_transmit`, waiting for the bus.
    queued: Option<Frame>,
    /// On the bus or sent: the confirmation comes at this time.
    confirm_at: Option<Instant>,
    received: Vec<Vec<u8>>,
    sent: usize,
    errors: Vec<ChannelError>,
}

impl Side {
    fn new(config: Config) -> Self {
        Side {
            channel: Box::new(Channel::new(config)),
            queued: None,
            confirm_at: None,
            received: Vec::new(),
            sent: 0,
            errors: Vec::new(),
        }
    }

    fn handle(&mut self, event: Event) {
        match event {
            Event::Received { len, functional } => {
                assert!(!functional);
                assert_eq!(self.channel.received().len(), len);
                self.received.push(self.channel.received().to_vec());
                self.channel.release();
            }
            Event::Sent => self.sent += 1,
            Event::Error(error) => self.errors.push(error),
        }
    }

    fn drain(&mut self, now: Instant) {
        while let Some(event) = self.channel.poll(now) {
            self.handle(event);
        }
    }
}

/// Runs two channels wired back to back on one simulated bus (arbitration by
/// identifier, frames taking their time on the wire, confirmations arriving after a
/// random delay) until nothing is left to do; returns the two sides.
fn back_to_back(
    a_config: Config,
    b_config: Config,
    a_payload: &[u8],
    b_payload: &[u8],
    seed: u64,
) -> (Side, Side) {
    let mut jitter = Jitter(seed);
    let mut sides = [Side::new(a_config), Side::new(b_config)];
    let mut now = Instant::ZERO;
    for (side, payload) in sides.iter_mut().zip([a_payload, b_payload]) {
        if !payload.is_empty() {
            side.channel
                .send(now, payload)
                .expect("an idle channel sends");
        }
    }
    // The frame on the wire: who sends it, the frame, when it is through.
    let mut on_wire: Option<(usize, Frame, Instant)> = None;
    for _ in 0..200_000 {
        for side in sides.iter_mut() {
            side.drain(now);
            if side.queued.is_none() && side.confirm_at.is_none() {
                side.queued = side.channel.poll_transmit(now);
            }
        }
        if on_wire.is_none() {
            // Arbitration: the lower identifier wins.
            let winner = (0..2)
                .filter(|&i| sides[i].queued.is_some())
                .min_by_key(|&i| sides[i].queued.map(|frame| frame.id()));
            if let Some(i) = winner {
                let frame = sides[i].queued.take().expect("queued");
                let bits = 47 + 8 * frame.len() as u64 + jitter.next(20);
                on_wire = Some((i, frame, now.plus_micros(bits * BIT_US)));
            }
        }
        let mut next = on_wire.map(|(_, _, end)| end);
        for side in &sides {
            for candidate in [side.confirm_at, side.channel.next_deadline()] {
                next = match (next, candidate) {
                    (Some(a), Some(b)) => Some(a.min(b)),
                    (a, b) => a.or(b),
                };
            }
        }
        let Some(next) = next else {
            let [a, b] = sides;
            return (a, b);
        };
        now = now.max(next);
        if let Some((sender, frame, end)) = on_wire {
            if end <= now {
                on_wire = None;
                let receiver = 1 - sender;
                if let Some(event) = sides[receiver].channel.on_frame(now, &frame) {
                    sides[receiver].handle(event);
                }
                // The controller's confirmation lags the end of frame by up to 300 µs,
                // so the peer's answer may come first.
                sides[sender].confirm_at = Some(now.plus_micros(jitter.next(300)));
            }
        }
        for side in sides.iter_mut() {
            if side.confirm_at.is_some_and(|at| at <= now) {
                side.confirm_at = None;
                side.channel.confirm_transmit(now);
            }
        }
    }
    panic!("the transfer did not finish");
}

fn any_config(tx_id: u16, rx_id: u16) -> impl Strategy<Value = Config> {
    (any::<u8>(), any::<u8>(), proptest::option::of(any::<u8>())).prop_map(
        move |(block_size, st_min, padding)| Config {
            block_size,
            st_min: StMin::from_byte(st_min),
            padding,
            ..Config::default_for(tx_id, rx_id)
        },
    )
}

fn any_payload() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        proptest::collection::vec(any::<u8>(), 1..=20),
        proptest::collection::vec(any::<u8>(), 1..=4095),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// Any payload arrives exactly, whatever block size, STmin and padding each side
    /// advertises, also with a PDU going the other way at the same time.
    #[test]
    fn back_to_back_delivers_exactly(
        a_config in any_config(A_TX, B_TX),
        b_config in any_config(B_TX, A_TX),
        a_payload in any_payload(),
        b_payload in proptest::option::of(any_payload()),
        seed in any::<u64>(),
    ) {
        let b_payload = b_payload.unwrap_or_default();
        let (a, b) = back_to_back(a_config, b_config, &a_payload, &b_payload, seed);
        prop_assert!(a.errors.is_empty(), "A errors: {:?}", a.errors);
        prop_assert!(b.errors.is_empty(), "B errors: {:?}", b.errors);
        prop_assert_eq!(b.received, std::vec![a_payload]);
        prop_assert_eq!(a.sent, 1);
        if b_payload.is_empty() {
            prop_assert!(a.received.is_empty());
            prop_assert_eq!(b.sent, 0);
        } else {
            prop_assert_eq!(a.received, std::vec![b_payload]);
            prop_assert_eq!(b.sent, 1);
        }
        prop_assert!(a.channel.is_idle() && b.channel.is_idle());
    }
}

/// What the fuzzing peer does next.
#[derive(Clone, Debug)]
enum Step {
    /// A frame on the physical (0), functional (1) or another (2) identifier.
    Frame {
        target: u8,
        data: Vec<u8>,
        after_us: u64,
    },
    /// The correct next consecutive frame of the last first frame, with random content.
    NextConsecutive { fill: u8, padded: bool },
    /// The upper layer releases the received PDU.
    Release,
    /// The upper layer becomes (not) ready.
    Ready(bool),
}

fn any_data() -> impl Strategy<Value = Vec<u8>> {
    // Mostly the PCI types that exist, with any low nibble and bytes.
    (
        0u8..5,
        any::<u8>(),
        proptest::collection::vec(any::<u8>(), 0..=7),
    )
        .prop_map(|(kind, low, mut rest)| {
            let pci = if kind < 4 {
                kind << 4 | low & 0x0F
            } else {
                low
            };
            rest.insert(0, pci);
            if kind == 1 {
                // FFs are ignored unless 8 bytes long: make most of them so, and keep
                // lengths in reach of the peer's consecutive frames.
                rest.resize(8, 0xCC);
                rest[0] &= 0xF0;
            }
            rest
        })
}

fn any_step() -> impl Strategy<Value = Step> {
    prop_oneof![
        4 => (0u8..3, any_data(), prop_oneof![Just(0u64), 0..2_000u64, 0..1_500_000u64])
            .prop_map(|(target, data, after_us)| Step::Frame { target, data, after_us }),
        6 => (any::<u8>(), any::<bool>())
            .prop_map(|(fill, padded)| Step::NextConsecutive { fill, padded }),
        1 => Just(Step::Release),
        1 => any::<bool>().prop_map(Step::Ready),
    ]
}

const RX: u16 = 0x701;
const FUNCTIONAL: u16 = 0x7DF;

/// The peer's view of the PDU it is sending: its length and the next sequence number.
struct PeerTransfer {
    len: usize,
    first_data: [u8; 6],
    sent: usize,
    next_sequence_number: u8,
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    /// Whatever frames arrive, the receiver does not panic, reports a PDU only with the
    /// length its SF or FF announced, with that many bytes in `received()`, and never
    /// overwrites a PDU not yet released.
    #[test]
    fn arbitrary_frames_never_corrupt_a_reception(
        steps in proptest::collection::vec(any_step(), 1..400),
        block_size in any::<u8>(),
        padding in proptest::option::of(any::<u8>()),
    ) {
        let mut channel: Box<Channel<4095>> = Box::new(Channel::new(Config {
            functional_rx_id: Some(FUNCTIONAL),
            block_size,
            padding,
            ..Config::default_for(0x781, RX)
        }));
        let mut now = Instant::ZERO;
        let mut peer: Option<PeerTransfer> = None;
        let mut holding = false;
        for step in steps {
            // What the frame announces: (length, functional, first bytes).
            let (frame, announced): (Frame, Option<(usize, bool, Vec<u8>)>) = match step {
                Step::Release => {
                    channel.release();
                    holding = false;
                    continue;
                }
                Step::Ready(ready) => {
                    channel.set_rx_ready(ready);
                    continue;
                }
                Step::Frame { target, data, after_us } => {
                    now = now.plus_micros(after_us);
                    let id = [RX, FUNCTIONAL, 0x123][usize::from(target)];
                    let frame = Frame::new(u32::from(id), &data).unwrap();
                    let pci = data.first().copied().unwrap_or(0xFF);
                    let announced = match pci >> 4 {
                        0 if id != 0x123 => {
                            let len = usize::from(pci & 0x0F);
                            ((1..=7).contains(&len) && len < data.len())
                                .then(|| (len, id == FUNCTIONAL, data[1..=len].to_vec()))
                        }
                        1 if id == RX && data.len() == 8 => {
                            let len = usize::from(pci & 0x0F) << 8 | usize::from(data[1]);
                            if len >= 8 {
                                let mut first_data = [0; 6];
                                first_data.copy_from_slice(&data[2..]);
                                peer = Some(PeerTransfer {
                                    len,
                                    first_data,
                                    sent: 6,
                                    next_sequence_number: 1,
                                });
                            } else if len == 0 {
                                // Escape: refused, any earlier reception ended.
                                peer = None;
                            }
                            None
                        }
                        _ => None,
                    };
                    (frame, announced)
                }
                Step::NextConsecutive { fill, padded } => {
                    let Some(transfer) = peer.as_mut() else { continue };
                    if transfer.sent >= transfer.len {
                        continue;
                    }
                    let chunk = (transfer.len - transfer.sent).min(7);
                    let mut data = std::vec![0x20 | transfer.next_sequence_number];
                    data.extend((0..chunk).map(|i| fill.wrapping_add(i as u8)));
                    if padded {
                        data.resize(8, 0xCC);
                    }
                    transfer.sent += chunk;
                    transfer.next_sequence_number = (transfer.next_sequence_number + 1) & 0x0F;
                    now = now.plus_micros(200);
                    (Frame::new(u32::from(RX), &data).unwrap(), None)
                }
            };
            // A polling loop has handled the timeouts due by now before the frame.
            while let Some(event) = channel.poll(now) {
                prop_assert!(matches!(event, Event::Error(_)), "{:?} without a frame", event);
            }
            let mut events = Vec::new();
            events.extend(channel.on_frame(now, &frame));
            while let Some(event) = channel.poll(now) {
                events.push(event);
            }
            let mut received_count = 0;
            for event in events {
                if let Event::Received { len, functional } = event {
                    received_count += 1;
                    prop_assert!(!holding, "a PDU not released was overwritten");
                    prop_assert_eq!(channel.received().len(), len);
                    match &announced {
                        Some((announced_len, announced_functional, bytes)) => {
                            prop_assert_eq!(len, *announced_len);
                            prop_assert_eq!(functional, *announced_functional);
                            prop_assert_eq!(channel.received(), &bytes[..]);
                        }
                        None => {
                            let transfer = peer.as_ref().expect("a CF completes an FF's PDU");
                            prop_assert!(!functional);
                            prop_assert_eq!(len, transfer.len);
                            prop_assert_eq!(&channel.received()[..6], &transfer.first_data[..]);
                        }
                    }
                    holding = true;
                }
            }
            prop_assert!(received_count <= 1);
            // Frames the receiver sends: flow control only, on its transmit identifier.
            while let Some(out) = channel.poll_transmit(now) {
                prop_assert_eq!(out.id(), 0x781);
                prop_assert!(matches!(out.data()[0], 0x30..=0x32));
                prop_assert_eq!(out.len(), if padding.is_some() { 8 } else { 3 });
                channel.confirm_transmit(now);
            }
        }
    }
}
