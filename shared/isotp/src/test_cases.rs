//! Test cases shared by the host test suite and the on-target (defmt-test) suite. Each case
//! panics on failure.
//!
//! The channel under test is an ECU's UDS channel: it receives requests on 0x701 (and
//! functional ones on 0x7DF) and sends on 0x781. The tester's frames are built by hand,
//! so every byte on the bus is checked against ISO 15765-2, not against this crate.

use crate::*;
use autoplug_can::Frame;
use autoplug_ecu::Instant;

const ECU_RX: u16 = 0x701;
const ECU_TX: u16 = 0x781;
const FUNCTIONAL: u16 = 0x7DF;
const CC: u8 = DEFAULT_PADDING;
const SECOND: u64 = 1_000_000;

fn us(t: u64) -> Instant {
    Instant::from_micros(t)
}

fn ms(t: u64) -> Instant {
    Instant::from_millis(t)
}

fn unpadded() -> Config {
    Config {
        padding: None,
        ..Config::default_for(ECU_TX, ECU_RX)
    }
}

fn padded() -> Config {
    Config::default_for(ECU_TX, ECU_RX)
}

/// A recognisable payload: byte `i` is not `i`, so offset errors show.
fn pattern<const L: usize>() -> [u8; L] {
    core::array::from_fn(|i| (i as u8).wrapping_mul(31).wrapping_add(7))
}

/// Bytes 0, 1, 2, ...: frames whose content is easy to write down.
fn counting<const L: usize>() -> [u8; L] {
    core::array::from_fn(|i| i as u8)
}

fn frame(id: u16, data: &[u8]) -> Frame {
    Frame::new(u32::from(id), data).expect("a test frame fits a CAN frame")
}

/// A frame from the tester on the physical request identifier.
fn feed<const N: usize, const T: usize>(
    channel: &mut Channel<N, T>,
    now: Instant,
    data: &[u8],
) -> Option<Event> {
    channel.on_frame(now, &frame(ECU_RX, data))
}

/// The tester's first frame of `payload`.
fn feed_first<const N: usize, const T: usize>(
    channel: &mut Channel<N, T>,
    now: Instant,
    payload: &[u8],
) -> Option<Event> {
    let len = payload.len();
    let mut bytes = [0u8; 8];
    bytes[0] = 0x10 | (len >> 8) as u8;
    bytes[1] = len as u8;
    bytes[2..].copy_from_slice(&payload[..6]);
    feed(channel, now, &bytes)
}

/// The tester's consecutive frame `sequence_number` carrying `payload[offset..]` (up to 7
/// bytes, unpadded); returns the event and the next offset.
fn feed_consecutive<const N: usize, const T: usize>(
    channel: &mut Channel<N, T>,
    now: Instant,
    sequence_number: u8,
    payload: &[u8],
    offset: usize,
) -> (Option<Event>, usize) {
    let end = (offset + 7).min(payload.len());
    let mut bytes = [0u8; 8];
    bytes[0] = 0x20 | (sequence_number & 0x0F);
    bytes[1..1 + end - offset].copy_from_slice(&payload[offset..end]);
    let event = feed(channel, now, &bytes[..1 + end - offset]);
    (event, end)
}

/// Hands out the next frame, checks its identifier and bytes, and confirms it at once.
fn expect_frame<const N: usize, const T: usize>(
    channel: &mut Channel<N, T>,
    now: Instant,
    bytes: &[u8],
) {
    let frame = channel.poll_transmit(now).expect("a frame is due");
    assert_eq!(
        frame.id(),
        ECU_TX,
        "frames go out on the transmit identifier"
    );
    assert_eq!(frame.data(), bytes);
    channel.confirm_transmit(now);
}

fn expect_no_frame<const N: usize, const T: usize>(channel: &mut Channel<N, T>, now: Instant) {
    assert_eq!(channel.poll_transmit(now), None, "no frame is due");
}

/// Sends a segmented `payload` up to the flow control: the FF is handed out at `now`
/// and confirmed at once.
fn start_segmented<const N: usize, const T: usize>(
    channel: &mut Channel<N, T>,
    now: Instant,
    payload: &[u8],
) {
    channel.send(now, payload).expect("the channel is free");
    let first = channel
        .poll_transmit(now)
        .expect("the first frame is due at once");
    assert_eq!(first.data()[0] >> 4, 1, "a first frame");
    channel.confirm_transmit(now);
    assert_eq!(
        channel.poll_transmit(now),
        None,
        "no CF before the flow control"
    );
}

/// Receives a segmented `payload` completely (tester's frames unpadded, no STmin) and
/// checks the flow control frames' statuses and the result.
fn receive_segmented<const N: usize, const T: usize>(
    channel: &mut Channel<N, T>,
    now: Instant,
    payload: &[u8],
) {
    assert_eq!(feed_first(channel, now, payload), None);
    let mut offset = 6;
    let mut sequence_number = 1u8;
    let mut frames_since_flow_control = 0u32;
    let block_size = u32::from(channel.config().block_size);
    let flow_control = channel.poll_transmit(now).expect("a CTS after the FF");
    assert_eq!(flow_control.data()[0], 0x30);
    channel.confirm_transmit(now);
    loop {
        let (event, next) = feed_consecutive(channel, now, sequence_number, payload, offset);
        offset = next;
        sequence_number = (sequence_number + 1) & 0x0F;
        frames_since_flow_control += 1;
        if offset == payload.len() {
            assert_eq!(
                event,
                Some(Event::Received {
                    len: payload.len(),
                    functional: false
                })
            );
            assert_eq!(channel.received(), payload);
            return;
        }
        assert_eq!(event, None);
        if block_size != 0 && frames_since_flow_control == block_size {
            let flow_control = channel.poll_transmit(now).expect("a CTS after each block");
            assert_eq!(flow_control.data()[0], 0x30);
            channel.confirm_transmit(now);
            frames_since_flow_control = 0;
        } else {
            expect_no_frame(channel, now);
        }
    }
}

/// Single frames: PCI 0x0L then the payload, padded to 8 bytes only if configured;
/// `Sent` only once confirmed.
pub fn single_frame_bytes() {
    let mut channel: Channel<16> = Channel::new(unpadded());
    channel.send(ms(0), &[0x3E, 0x00]).unwrap();
    let frame = channel.poll_transmit(ms(0)).expect("the SF is due at once");
    assert_eq!(frame.id(), ECU_TX);
    assert_eq!(frame.data(), &[0x02, 0x3E, 0x00]);
    assert_eq!(
        channel.poll(ms(0)),
        None,
        "not sent before its confirmation"
    );
    assert!(channel.is_transmitting());
    channel.confirm_transmit(ms(1));
    assert_eq!(channel.poll(ms(1)), Some(Event::Sent));
    assert_eq!(channel.poll(ms(1)), None, "Sent comes once");
    assert!(channel.is_idle());

    channel.send(ms(2), &[1, 2, 3, 4, 5, 6, 7]).unwrap();
    expect_frame(&mut channel, ms(2), &[0x07, 1, 2, 3, 4, 5, 6, 7]);
    assert_eq!(channel.poll(ms(2)), Some(Event::Sent));

    let mut channel: Channel<16> = Channel::new(padded());
    channel.send(ms(0), &[0x3E, 0x00]).unwrap();
    expect_frame(&mut channel, ms(0), &[0x02, 0x3E, 0x00, CC, CC, CC, CC, CC]);
    let mut channel: Channel<16> = Channel::new(Config {
        padding: Some(0x55),
        ..padded()
    });
    channel.send(ms(0), &[0x11]).unwrap();
    expect_frame(
        &mut channel,
        ms(0),
        &[0x01, 0x11, 0x55, 0x55, 0x55, 0x55, 0x55, 0x55],
    );
}

/// Segmented transmission: FF 0x1LLL with 6 bytes, CFs 0x2N with 7, the last one short
/// unless padded.
pub fn segmented_frame_bytes() {
    let payload: [u8; 17] = counting();
    for padding in [None, Some(CC)] {
        let mut channel: Channel<32> = Channel::new(Config {
            padding,
            ..padded()
        });
        channel.send(ms(0), &payload).unwrap();
        expect_frame(&mut channel, ms(0), &[0x10, 0x11, 0, 1, 2, 3, 4, 5]);
        expect_no_frame(&mut channel, ms(0));
        assert_eq!(feed(&mut channel, ms(1), &[0x30, 0x00, 0x00]), None);
        expect_frame(&mut channel, ms(1), &[0x21, 6, 7, 8, 9, 10, 11, 12]);
        assert_eq!(channel.poll(ms(1)), None, "not done after the first CF");
        match padding {
            None => expect_frame(&mut channel, ms(1), &[0x22, 13, 14, 15, 16]),
            Some(_) => expect_frame(&mut channel, ms(1), &[0x22, 13, 14, 15, 16, CC, CC, CC]),
        }
        assert_eq!(channel.poll(ms(1)), Some(Event::Sent));
    }

    // The 12-bit length: high nibble in the PCI byte.
    let long: [u8; 4095] = pattern();
    let mut channel: Channel<8, 4095> = Channel::new(unpadded());
    channel.send(ms(0), &long).unwrap();
    let first = channel.poll_transmit(ms(0)).unwrap();
    assert_eq!(first.data()[..2], [0x1F, 0xFF]);
    assert_eq!(first.data()[2..], long[..6]);
    let mut channel: Channel<8, 4095> = Channel::new(unpadded());
    channel.send(ms(0), &long[..0x123]).unwrap();
    assert_eq!(
        channel.poll_transmit(ms(0)).unwrap().data()[..2],
        [0x11, 0x23]
    );
}

/// Flow control frames: 0x30 BS STmin with this side's values, 0x31 (WAIT) and 0x32
/// (OVFLW) with zeros; padded only if configured.
pub fn flow_control_bytes() {
    let payload: [u8; 20] = pattern();
    let config = Config {
        block_size: 4,
        st_min: StMin::Millis(10),
        ..unpadded()
    };
    let mut channel: Channel<64> = Channel::new(config);
    feed_first(&mut channel, ms(0), &payload);
    expect_frame(&mut channel, ms(0), &[0x30, 0x04, 0x0A]);

    let mut channel: Channel<64> = Channel::new(Config {
        padding: Some(CC),
        st_min: StMin::Micros100(5),
        ..config
    });
    feed_first(&mut channel, ms(0), &payload);
    expect_frame(&mut channel, ms(0), &[0x30, 0x04, 0xF5, CC, CC, CC, CC, CC]);

    let mut channel: Channel<64> = Channel::new(config);
    channel.set_rx_ready(false);
    feed_first(&mut channel, ms(0), &payload);
    expect_frame(&mut channel, ms(0), &[0x31, 0x00, 0x00]);

    let mut channel: Channel<16> = Channel::new(config);
    feed_first(&mut channel, ms(0), &payload);
    expect_frame(&mut channel, ms(0), &[0x32, 0x00, 0x00]);
}

/// STmin bytes: 0x00..=0x7F are ms, 0xF1..=0xF9 are 100..900 µs, the rest reads as 127 ms;
/// values the byte cannot carry are encoded rounded up.
pub fn st_min_bytes() {
    for byte in 0..=255u8 {
        let st_min = StMin::from_byte(byte);
        match byte {
            0x00..=0x7F => {
                assert_eq!(st_min, StMin::Millis(byte));
                assert_eq!(st_min.as_micros(), u64::from(byte) * 1000);
                assert_eq!(st_min.to_byte(), byte);
            }
            0xF1..=0xF9 => {
                assert_eq!(st_min, StMin::Micros100(byte - 0xF0));
                assert_eq!(st_min.as_micros(), u64::from(byte - 0xF0) * 100);
                assert_eq!(st_min.to_byte(), byte);
            }
            _ => {
                assert_eq!(st_min, StMin::Millis(127), "reserved values read as 127 ms");
                assert_eq!(st_min.as_micros(), 127_000);
            }
        }
    }
    assert_eq!(StMin::Millis(200).to_byte(), 0x7F);
    assert_eq!(StMin::Millis(200).as_micros(), 127_000);
    assert_eq!(StMin::Micros100(0).to_byte(), 0x00);
    assert_eq!(StMin::Micros100(10).to_byte(), 1, "1000 µs is 1 ms");
    assert_eq!(
        StMin::Micros100(11).to_byte(),
        2,
        "rounded up, never faster"
    );
    assert_eq!(StMin::Micros100(255).to_byte(), 26);
}

/// The sender waits STmin (ms) after the confirmation of each CF before the next one.
pub fn sender_honours_st_min_in_milliseconds() {
    let payload: [u8; 30] = pattern(); // FF + 4 CFs
    let mut channel: Channel<8, 64> = Channel::new(unpadded());
    start_segmented(&mut channel, ms(0), &payload);
    feed(&mut channel, ms(10), &[0x30, 0x00, 0x05]);
    let mut confirmed = ms(10);
    assert!(
        channel.poll_transmit(confirmed).is_some(),
        "first CF at once"
    );
    for _ in 0..3 {
        confirmed = confirmed.plus_micros(150); // time on the bus
        channel.confirm_transmit(confirmed);
        let due = confirmed.plus_micros(5_000);
        assert_eq!(channel.next_deadline(), Some(due));
        assert_eq!(
            channel.poll_transmit(us(due.as_micros() - 1)),
            None,
            "before STmin"
        );
        assert!(channel.poll_transmit(due).is_some(), "at STmin");
        confirmed = due;
    }
    channel.confirm_transmit(confirmed);
    assert_eq!(channel.poll(confirmed), Some(Event::Sent));
}

/// STmin 0xF1..=0xF9: 100 to 900 µs between confirmation and the next CF.
pub fn sender_honours_st_min_in_microseconds() {
    let payload: [u8; 20] = pattern(); // FF + 2 CFs
    for step in 1..=9u8 {
        let mut channel: Channel<8, 64> = Channel::new(unpadded());
        start_segmented(&mut channel, ms(0), &payload);
        feed(&mut channel, ms(1), &[0x30, 0x00, 0xF0 + step]);
        assert!(channel.poll_transmit(ms(1)).is_some());
        channel.confirm_transmit(ms(2));
        let gap = u64::from(step) * 100;
        assert_eq!(channel.poll_transmit(ms(2).plus_micros(gap - 1)), None);
        assert!(channel.poll_transmit(ms(2).plus_micros(gap)).is_some());
    }
}

/// A reserved STmin in the peer's flow control means 127 ms.
pub fn sender_treats_reserved_st_min_as_127_ms() {
    let payload: [u8; 20] = pattern();
    for reserved in [0x80, 0xF0, 0xFA, 0xFF] {
        let mut channel: Channel<8, 64> = Channel::new(unpadded());
        start_segmented(&mut channel, ms(0), &payload);
        feed(&mut channel, ms(1), &[0x30, 0x00, reserved]);
        assert!(channel.poll_transmit(ms(1)).is_some());
        channel.confirm_transmit(ms(1));
        assert_eq!(channel.poll_transmit(us(128_000 - 1)), None);
        assert!(channel.poll_transmit(ms(128)).is_some());
    }
}

/// With BS n the sender stops after every n CFs until the next flow control.
pub fn sender_waits_for_flow_control_after_each_block() {
    let payload: [u8; 76] = pattern(); // FF + 10 CFs
    let mut channel: Channel<8, 128> = Channel::new(unpadded());
    start_segmented(&mut channel, ms(0), &payload);
    let mut now = ms(0);
    let mut sequence_number = 1u8;
    for block in [3, 3, 3, 1] {
        now = now.plus_micros(1000);
        feed(&mut channel, now, &[0x30, 0x03, 0x00]);
        for _ in 0..block {
            let frame = channel.poll_transmit(now).expect("a CF within the block");
            assert_eq!(frame.data()[0], 0x20 | sequence_number);
            sequence_number += 1;
            channel.confirm_transmit(now);
        }
        if block == 3 {
            assert_eq!(
                channel.poll_transmit(now.plus_micros(SECOND - 1)),
                None,
                "the block is over: wait for the next flow control"
            );
            assert_eq!(channel.poll(now.plus_micros(SECOND - 1)), None);
        }
    }
    assert_eq!(channel.poll(now), Some(Event::Sent));
}

/// Sequence numbers run 1..=15, then 0, 1, ... on both sides.
pub fn sequence_numbers_wrap_after_15() {
    let payload: [u8; 146] = pattern(); // FF + 20 CFs
    let mut sender: Channel<8, 256> = Channel::new(unpadded());
    start_segmented(&mut sender, ms(0), &payload);
    feed(&mut sender, ms(1), &[0x30, 0x00, 0x00]);
    let mut pcis = [0u8; 20];
    for pci in pcis.iter_mut() {
        let frame = sender.poll_transmit(ms(1)).expect("BS 0: all CFs");
        *pci = frame.data()[0];
        sender.confirm_transmit(ms(1));
    }
    assert_eq!(
        pcis,
        [
            0x21, 0x22, 0x23, 0x24, 0x25, 0x26, 0x27, 0x28, 0x29, 0x2A, 0x2B, 0x2C, 0x2D, 0x2E,
            0x2F, 0x20, 0x21, 0x22, 0x23, 0x24
        ]
    );
    assert_eq!(sender.poll(ms(1)), Some(Event::Sent));

    let mut receiver: Channel<256> = Channel::new(Config {
        block_size: 0,
        ..unpadded()
    });
    receive_segmented(&mut receiver, ms(0), &payload);
}

/// The receiver sends a CTS after the FF and after every BS CFs, and ignores a CF that
/// comes before that CTS is out.
pub fn receiver_sends_flow_control_after_each_block() {
    let payload: [u8; 41] = pattern(); // FF + 5 CFs
    let mut channel: Channel<64> = Channel::new(Config {
        block_size: 2,
        ..unpadded()
    });
    feed_first(&mut channel, ms(0), &payload);
    expect_frame(&mut channel, ms(0), &[0x30, 0x02, 0x00]);
    let (_, offset) = feed_consecutive(&mut channel, ms(1), 1, &payload, 6);
    expect_no_frame(&mut channel, ms(1));
    let (_, offset) = feed_consecutive(&mut channel, ms(2), 2, &payload, offset);
    let (early, _) = feed_consecutive(&mut channel, ms(2), 3, &payload, offset);
    assert_eq!(early, None, "a CF before the CTS is out of place");
    expect_frame(&mut channel, ms(3), &[0x30, 0x02, 0x00]);
    let (_, offset) = feed_consecutive(&mut channel, ms(4), 3, &payload, offset);
    let (_, offset) = feed_consecutive(&mut channel, ms(4), 4, &payload, offset);
    expect_frame(&mut channel, ms(4), &[0x30, 0x02, 0x00]);
    let (event, _) = feed_consecutive(&mut channel, ms(5), 5, &payload, offset);
    assert_eq!(
        event,
        Some(Event::Received {
            len: 41,
            functional: false
        })
    );
    assert_eq!(channel.received(), &payload);
    expect_no_frame(&mut channel, ms(5));
    channel.release();
    assert_eq!(channel.received(), &[] as &[u8]);
    assert!(channel.is_idle());
}

/// A CF with the wrong sequence number ends the reception with an error.
pub fn wrong_sequence_number_aborts_reception() {
    let payload: [u8; 30] = pattern();
    let mut channel: Channel<64> = Channel::new(unpadded());
    feed_first(&mut channel, ms(0), &payload);
    expect_frame(&mut channel, ms(0), &[0x30, 0x08, 0x00]);
    let (event, offset) = feed_consecutive(&mut channel, ms(1), 1, &payload, 6);
    assert_eq!(event, None);
    let (event, _) = feed_consecutive(&mut channel, ms(2), 3, &payload, offset);
    assert_eq!(
        event,
        Some(Event::Error(ChannelError::WrongSequenceNumber {
            expected: 2,
            got: 3
        }))
    );
    assert!(!channel.is_receiving());
    let (event, _) = feed_consecutive(&mut channel, ms(3), 2, &payload, offset);
    assert_eq!(event, None, "the rest of the PDU is ignored");
    assert_eq!(
        channel.poll(ms(3).plus_micros(10 * SECOND)),
        None,
        "no N_Cr any more"
    );
    assert_eq!(channel.received(), &[] as &[u8]);
    assert!(channel.is_idle());
}

/// N_Bs runs from the FF's confirmation (not its hand-out) and from the end of each block.
pub fn sender_times_out_without_flow_control() {
    let payload: [u8; 20] = pattern();
    let mut channel: Channel<8, 64> = Channel::new(unpadded());
    channel.send(ms(0), &payload).unwrap();
    assert!(channel.poll_transmit(ms(0)).is_some());
    channel.confirm_transmit(ms(300));
    assert_eq!(channel.next_deadline(), Some(ms(1300)));
    assert_eq!(channel.poll(us(1_300_000 - 1)), None);
    assert_eq!(
        channel.poll(ms(1300)),
        Some(Event::Error(ChannelError::TimeoutBs))
    );
    assert!(!channel.is_transmitting());
    assert_eq!(feed(&mut channel, ms(1301), &[0x30, 0x00, 0x00]), None);
    expect_no_frame(&mut channel, ms(1301));

    // After a block of 1.
    start_segmented(&mut channel, ms(2000), &payload);
    feed(&mut channel, ms(2001), &[0x30, 0x01, 0x00]);
    assert!(channel.poll_transmit(ms(2001)).is_some());
    channel.confirm_transmit(ms(2002));
    assert_eq!(channel.poll(us(3_002_000 - 1)), None);
    assert_eq!(
        channel.poll(ms(3002)),
        Some(Event::Error(ChannelError::TimeoutBs))
    );
    assert!(channel.send(ms(3003), &payload).is_ok(), "free again");
}

/// N_Cr runs from the CTS's confirmation and restarts with every CF.
pub fn receiver_times_out_without_consecutive_frame() {
    let payload: [u8; 30] = pattern();
    let mut channel: Channel<64> = Channel::new(unpadded());
    feed_first(&mut channel, ms(0), &payload);
    assert!(channel.poll_transmit(ms(0)).is_some());
    assert_eq!(
        channel.poll(ms(999)),
        None,
        "N_Ar, not N_Cr, until confirmed"
    );
    channel.confirm_transmit(ms(10));
    assert_eq!(channel.next_deadline(), Some(ms(1010)));
    let (_, offset) = feed_consecutive(&mut channel, ms(500), 1, &payload, 6);
    assert_eq!(
        channel.next_deadline(),
        Some(ms(1500)),
        "restarted by the CF"
    );
    assert_eq!(channel.poll(us(1_500_000 - 1)), None);
    assert_eq!(
        channel.poll(ms(1500)),
        Some(Event::Error(ChannelError::TimeoutCr))
    );
    assert!(!channel.is_receiving());
    let (event, _) = feed_consecutive(&mut channel, ms(1501), 2, &payload, offset);
    assert_eq!(event, None, "late CFs are ignored");
    assert_eq!(channel.received(), &[] as &[u8]);
}

/// A data frame not confirmed within N_As ends the transmission.
pub fn sender_times_out_without_confirmation() {
    let mut channel: Channel<8> = Channel::new(unpadded());
    channel.send(ms(0), &[1, 2, 3]).unwrap();
    assert!(channel.poll_transmit(ms(5)).is_some());
    assert_eq!(channel.next_deadline(), Some(ms(1005)));
    assert_eq!(channel.poll(us(1_005_000 - 1)), None);
    assert_eq!(channel.poll_transmit(ms(500)), None, "one frame at a time");
    assert_eq!(
        channel.poll(ms(1005)),
        Some(Event::Error(ChannelError::TimeoutAs))
    );
    assert!(channel.is_idle());
    channel.send(ms(1006), &[4]).expect("free again");
    expect_frame(&mut channel, ms(1006), &[0x01, 4]);
}

/// A flow control not confirmed within N_Ar ends the reception.
pub fn receiver_times_out_without_confirmation() {
    let payload: [u8; 30] = pattern();
    let mut channel: Channel<64> = Channel::new(unpadded());
    feed_first(&mut channel, ms(0), &payload);
    assert!(channel.poll_transmit(ms(0)).is_some());
    assert_eq!(channel.poll(us(SECOND - 1)), None);
    assert_eq!(
        channel.poll(ms(1000)),
        Some(Event::Error(ChannelError::TimeoutAr))
    );
    assert!(channel.is_idle());
    let (event, _) = feed_consecutive(&mut channel, ms(1001), 1, &payload, 6);
    assert_eq!(event, None);
}

/// As sender, each FC.WAIT restarts N_Bs; up to `max_wait_frames` in a row are accepted
/// (counting again after a CTS), one more aborts.
pub fn sender_handles_wait_frames() {
    let payload: [u8; 20] = counting(); // FF + 2 CFs
    let config = Config {
        max_wait_frames: 2,
        ..unpadded()
    };
    let mut channel: Channel<8, 64> = Channel::new(config);
    start_segmented(&mut channel, ms(0), &payload);
    assert_eq!(feed(&mut channel, ms(900), &[0x31, 0x00, 0x00]), None);
    assert_eq!(channel.poll(ms(1000)), None, "N_Bs restarted by the WAIT");
    assert_eq!(channel.next_deadline(), Some(ms(1900)));
    assert_eq!(feed(&mut channel, ms(1800), &[0x31, 0x00, 0x00]), None);
    assert_eq!(channel.poll(ms(2700)), None);
    expect_no_frame(&mut channel, ms(2700));
    feed(&mut channel, ms(2700), &[0x30, 0x01, 0x00]);
    assert!(channel.poll_transmit(ms(2700)).is_some(), "CTS: CF");
    channel.confirm_transmit(ms(2700));
    // Two more WAITs after the CTS are fine again.
    assert_eq!(feed(&mut channel, ms(2800), &[0x31, 0x00, 0x00]), None);
    assert_eq!(feed(&mut channel, ms(2900), &[0x31, 0x00, 0x00]), None);
    feed(&mut channel, ms(3000), &[0x30, 0x00, 0x00]);
    expect_frame(&mut channel, ms(3000), &[0x22, 13, 14, 15, 16, 17, 18, 19]);
    assert_eq!(channel.poll(ms(3000)), Some(Event::Sent));

    let mut channel: Channel<8, 64> = Channel::new(config);
    start_segmented(&mut channel, ms(0), &payload);
    assert_eq!(feed(&mut channel, ms(1), &[0x31, 0x00, 0x00]), None);
    assert_eq!(feed(&mut channel, ms(2), &[0x31, 0x00, 0x00]), None);
    assert_eq!(
        feed(&mut channel, ms(3), &[0x31, 0x00, 0x00]),
        Some(Event::Error(ChannelError::TooManyWaits { max: 2 }))
    );
    assert!(!channel.is_transmitting());
    assert_eq!(channel.poll(ms(5000)), None, "no N_Bs left running");

    let mut channel: Channel<8, 64> = Channel::new(Config {
        max_wait_frames: 0,
        ..config
    });
    start_segmented(&mut channel, ms(0), &payload);
    assert_eq!(
        feed(&mut channel, ms(1), &[0x31, 0x00, 0x00]),
        Some(Event::Error(ChannelError::TooManyWaits { max: 0 }))
    );
}

/// FC.OVFLW and reserved flow statuses from the peer end the transmission.
pub fn sender_aborts_on_overflow_and_invalid_flow_status() {
    let payload: [u8; 20] = pattern();
    let mut channel: Channel<8, 64> = Channel::new(unpadded());
    start_segmented(&mut channel, ms(0), &payload);
    assert_eq!(
        feed(&mut channel, ms(1), &[0x32, 0x00, 0x00]),
        Some(Event::Error(ChannelError::Overflow))
    );
    assert!(channel.is_idle());
    expect_no_frame(&mut channel, ms(1));
    for status in 3..=15u8 {
        start_segmented(&mut channel, ms(2), &payload);
        assert_eq!(
            feed(&mut channel, ms(3), &[0x30 | status, 0x00, 0x00]),
            Some(Event::Error(ChannelError::InvalidFlowStatus(status)))
        );
        assert!(!channel.is_transmitting());
        expect_no_frame(&mut channel, ms(3));
    }
}

/// `send` refuses a second PDU, an empty one and one longer than the transmit buffer.
pub fn send_refusals() {
    let mut channel: Channel<8, 64> = Channel::new(unpadded());
    assert_eq!(channel.send(ms(0), &[]), Err(SendError::Empty));
    assert_eq!(
        channel.send(ms(0), &[0; 65]),
        Err(SendError::TooLong { len: 65, max: 64 })
    );
    channel.send(ms(0), &[1]).unwrap();
    assert_eq!(channel.send(ms(0), &[2]), Err(SendError::Busy));
    assert!(channel.poll_transmit(ms(0)).is_some());
    assert_eq!(
        channel.send(ms(0), &[2]),
        Err(SendError::Busy),
        "until confirmed"
    );
    channel.confirm_transmit(ms(0));
    assert_eq!(channel.send(ms(0), &[2]), Ok(()));
    assert_eq!(channel.poll(ms(0)), Some(Event::Sent), "for the first PDU");

    let mut channel: Channel<8, 4095> = Channel::new(unpadded());
    assert_eq!(
        channel.send(ms(0), &[0; 4096]),
        Err(SendError::TooLong {
            len: 4096,
            max: 4095
        })
    );
    assert_eq!(Channel::<8, 4095>::MAX_SEND_LEN, 4095);
}

/// While not ready, an FF gets FC.WAIT every N_Br, `max_wait_frames` of them, then
/// FC.OVFLW and an error; with 0 allowed, FC.OVFLW at once.
pub fn receiver_not_ready_waits_then_refuses() {
    let payload: [u8; 30] = pattern();
    let mut channel: Channel<64> = Channel::new(Config {
        max_wait_frames: 3,
        ..unpadded()
    });
    channel.set_rx_ready(false);
    assert_eq!(feed_first(&mut channel, ms(0), &payload), None);
    assert!(channel.is_receiving());
    expect_frame(&mut channel, ms(0), &[0x31, 0x00, 0x00]);
    for wait in 1..3u64 {
        let due = ms(wait * 500);
        assert_eq!(channel.next_deadline(), Some(due));
        expect_no_frame(&mut channel, us(due.as_micros() - 1));
        expect_frame(&mut channel, due, &[0x31, 0x00, 0x00]);
    }
    assert_eq!(channel.poll(ms(1499)), None, "no N_Cr while waiting");
    expect_frame(&mut channel, ms(1500), &[0x32, 0x00, 0x00]);
    assert_eq!(
        channel.poll(ms(1500)),
        Some(Event::Error(ChannelError::IncomingRefused { waits: 3 }))
    );
    assert!(channel.is_idle());
    let (event, _) = feed_consecutive(&mut channel, ms(1501), 1, &payload, 6);
    assert_eq!(event, None);
    expect_no_frame(&mut channel, ms(5000));

    let mut channel: Channel<64> = Channel::new(Config {
        max_wait_frames: 0,
        ..unpadded()
    });
    channel.set_rx_ready(false);
    assert_eq!(
        feed_first(&mut channel, ms(0), &payload),
        Some(Event::Error(ChannelError::IncomingRefused { waits: 0 }))
    );
    expect_frame(&mut channel, ms(0), &[0x32, 0x00, 0x00]);
}

/// A receiver that becomes ready while sending WAITs answers CTS at once and keeps the
/// FF's bytes.
pub fn receiver_ready_again_sends_clear_to_send() {
    let payload: [u8; 30] = pattern();
    let mut channel: Channel<64> = Channel::new(unpadded());
    channel.set_rx_ready(false);
    feed_first(&mut channel, ms(0), &payload);
    expect_frame(&mut channel, ms(0), &[0x31, 0x00, 0x00]);
    channel.set_rx_ready(true);
    assert_eq!(channel.next_deadline(), Some(ms(0)), "due at once");
    expect_frame(&mut channel, ms(200), &[0x30, 0x08, 0x00]);
    let mut offset = 6;
    let mut event = None;
    for sequence_number in 1..=4 {
        (event, offset) =
            feed_consecutive(&mut channel, ms(201), sequence_number, &payload, offset);
    }
    assert_eq!(
        event,
        Some(Event::Received {
            len: 30,
            functional: false
        })
    );
    assert_eq!(channel.received(), &payload);
}

/// Until `release`, a new SF is dropped with an error and an FF is held off with
/// FC.WAIT; after it, the FF gets its CTS.
pub fn unreleased_buffer_holds_off_new_pdus() {
    let payload: [u8; 30] = pattern();
    let mut channel: Channel<64> = Channel::new(unpadded());
    assert_eq!(
        feed(&mut channel, ms(0), &[0x02, 0x10, 0x03]),
        Some(Event::Received {
            len: 2,
            functional: false
        })
    );
    assert_eq!(
        feed(&mut channel, ms(1), &[0x02, 0x11, 0x01]),
        Some(Event::Error(ChannelError::ReceiverBusy))
    );
    assert_eq!(channel.received(), &[0x10, 0x03], "the first PDU is kept");
    feed_first(&mut channel, ms(2), &payload);
    expect_frame(&mut channel, ms(2), &[0x31, 0x00, 0x00]);
    assert_eq!(
        channel.received(),
        &[0x10, 0x03],
        "still kept while waiting"
    );
    channel.release();
    expect_frame(&mut channel, ms(3), &[0x30, 0x08, 0x00]);
    let mut offset = 6;
    let mut event = None;
    for sequence_number in 1..=4 {
        (event, offset) = feed_consecutive(&mut channel, ms(4), sequence_number, &payload, offset);
    }
    assert_eq!(
        event,
        Some(Event::Received {
            len: 30,
            functional: false
        })
    );
    assert_eq!(channel.received(), &payload);

    // Not ready with the buffer free: SFs are dropped too.
    channel.release();
    channel.set_rx_ready(false);
    assert_eq!(
        feed(&mut channel, ms(5), &[0x01, 0x3E]),
        Some(Event::Error(ChannelError::ReceiverBusy))
    );
    assert_eq!(channel.received(), &[] as &[u8]);
}

/// An FF announcing more than the buffer, or the 32-bit escape, gets FC.OVFLW and is
/// dropped; one that just fits is taken.
pub fn first_frame_longer_than_buffer_is_refused() {
    let payload: [u8; 65] = pattern();
    let mut channel: Channel<64> = Channel::new(unpadded());
    assert_eq!(
        feed_first(&mut channel, ms(0), &payload),
        Some(Event::Error(ChannelError::IncomingTooLong {
            announced: 65,
            capacity: 64
        }))
    );
    expect_frame(&mut channel, ms(0), &[0x32, 0x00, 0x00]);
    let (event, _) = feed_consecutive(&mut channel, ms(1), 1, &payload, 6);
    assert_eq!(event, None, "its CFs are ignored");
    assert!(channel.is_idle());

    assert_eq!(
        feed(
            &mut channel,
            ms(2),
            &[0x10, 0x00, 0x00, 0x01, 0x00, 0x00, 1, 2]
        ),
        Some(Event::Error(ChannelError::IncomingTooLong {
            announced: 0x1_0000,
            capacity: 64
        }))
    );
    expect_frame(&mut channel, ms(2), &[0x32, 0x00, 0x00]);

    let mut channel: Channel<64> = Channel::new(Config {
        block_size: 0,
        ..unpadded()
    });
    receive_segmented(&mut channel, ms(3), &payload[..64]);

    // A buffer smaller than a single frame refuses it instead of truncating.
    let mut tiny: Channel<2> = Channel::new(unpadded());
    assert_eq!(
        feed(&mut tiny, ms(0), &[0x03, 1, 2, 3]),
        Some(Event::Error(ChannelError::IncomingTooLong {
            announced: 3,
            capacity: 2
        }))
    );
    assert_eq!(
        feed(&mut tiny, ms(0), &[0x02, 1, 2]),
        Some(Event::Received {
            len: 2,
            functional: false
        })
    );
}

/// The functional identifier takes single frames only, flagged functional; a functional
/// SF does not disturb a physical reception.
pub fn functional_addressing() {
    let mut channel: Channel<64> = Channel::new(Config {
        functional_rx_id: Some(FUNCTIONAL),
        ..unpadded()
    });
    assert_eq!(
        channel.on_frame(
            ms(0),
            &frame(FUNCTIONAL, &[0x02, 0x3E, 0x80, CC, CC, CC, CC, CC])
        ),
        Some(Event::Received {
            len: 2,
            functional: true
        })
    );
    assert_eq!(channel.received(), &[0x3E, 0x80]);
    channel.release();

    let payload: [u8; 20] = pattern();
    let mut first = [0x10, 20, 0, 0, 0, 0, 0, 0];
    first[2..].copy_from_slice(&payload[..6]);
    assert_eq!(channel.on_frame(ms(1), &frame(FUNCTIONAL, &first)), None);
    expect_no_frame(&mut channel, ms(1));
    assert!(
        channel.is_idle(),
        "an FF on the functional identifier is ignored"
    );
    assert_eq!(
        channel.on_frame(ms(1), &frame(FUNCTIONAL, &[0x21, 1, 2, 3, 4, 5, 6, 7])),
        None
    );
    assert_eq!(
        channel.on_frame(ms(1), &frame(FUNCTIONAL, &[0x30, 0, 0])),
        None
    );
    assert!(channel.is_idle());

    // A functional TesterPresent in the middle of a physical transfer.
    feed_first(&mut channel, ms(2), &payload);
    expect_frame(&mut channel, ms(2), &[0x30, 0x08, 0x00]);
    let (_, offset) = feed_consecutive(&mut channel, ms(3), 1, &payload, 6);
    assert_eq!(
        channel.on_frame(ms(3), &frame(FUNCTIONAL, &[0x02, 0x3E, 0x80])),
        Some(Event::Error(ChannelError::ReceiverBusy))
    );
    let (event, _) = feed_consecutive(&mut channel, ms(4), 2, &payload, offset);
    assert_eq!(
        event,
        Some(Event::Received {
            len: 20,
            functional: false
        })
    );
    assert_eq!(channel.received(), &payload);

    // Without a functional identifier configured, 0x7DF is just another identifier.
    let mut channel: Channel<64> = Channel::new(unpadded());
    assert_eq!(
        channel.on_frame(ms(0), &frame(FUNCTIONAL, &[0x02, 0x3E, 0x80])),
        None
    );
}

/// A new SF or FF on the physical identifier ends the reception in progress with an
/// error, then is taken as usual.
pub fn new_pdu_interrupts_reception() {
    let payload: [u8; 30] = pattern();
    let mut channel: Channel<64> = Channel::new(unpadded());
    feed_first(&mut channel, ms(0), &payload);
    expect_frame(&mut channel, ms(0), &[0x30, 0x08, 0x00]);
    feed_consecutive(&mut channel, ms(1), 1, &payload, 6);
    assert_eq!(
        feed(&mut channel, ms(2), &[0x03, 0x22, 0xF1, 0x90]),
        Some(Event::Error(ChannelError::ReceptionInterrupted))
    );
    assert_eq!(
        channel.next_deadline(),
        Some(ms(2)),
        "the next event is due"
    );
    assert_eq!(
        channel.poll(ms(2)),
        Some(Event::Received {
            len: 3,
            functional: false
        })
    );
    assert_eq!(channel.received(), &[0x22, 0xF1, 0x90]);
    assert_eq!(channel.poll(ms(2)), None);
    assert_eq!(channel.poll(ms(5000)), None, "the old N_Cr is gone");
    channel.release();

    // An FF interrupting: the CTS still due for the first one is replaced.
    let other: [u8; 13] = core::array::from_fn(|i| 0xA0 + i as u8);
    feed_first(&mut channel, ms(10), &payload);
    assert_eq!(
        feed_first(&mut channel, ms(11), &other),
        Some(Event::Error(ChannelError::ReceptionInterrupted))
    );
    assert_eq!(channel.poll(ms(11)), None);
    expect_frame(&mut channel, ms(11), &[0x30, 0x08, 0x00]);
    expect_no_frame(&mut channel, ms(11));
    let (event, _) = feed_consecutive(&mut channel, ms(12), 1, &other, 6);
    assert_eq!(
        event,
        Some(Event::Received {
            len: 13,
            functional: false
        })
    );
    assert_eq!(channel.received(), &other);
}

/// Frames that are no valid PDU, or come out of place, change nothing.
pub fn malformed_and_unexpected_frames_are_ignored() {
    const IGNORED: [&[u8]; 14] = [
        &[],                             // no PCI
        &[0x00, 1, 2, 3],                // SF length 0
        &[0x05, 1, 2],                   // SF longer than its frame
        &[0x08, 1, 2, 3, 4, 5, 6, 7],    // SF length 8 on classic CAN
        &[0x0F, 1, 2, 3, 4, 5, 6, 7],    // SF length 15
        &[0x10, 0x14, 1, 2, 3],          // FF shorter than 8 bytes
        &[0x10, 0x07, 1, 2, 3, 4, 5, 6], // FF announcing what fits an SF
        &[0x21, 1, 2, 3, 4, 5, 6, 7],    // CF without a reception
        &[0x20],                         // CF without data
        &[0x30, 0x00, 0x00],             // FC without a transmission
        &[0x30, 0x00],                   // FC too short
        &[0x32],                         // FC too short
        &[0x40, 1, 2, 3, 4, 5, 6, 7],    // reserved PCI type
        &[0xF3, 1, 2, 3, 4, 5, 6, 7],    // reserved PCI type
    ];
    let mut channel: Channel<64> = Channel::new(unpadded());
    for data in IGNORED {
        assert_eq!(feed(&mut channel, ms(0), data), None);
        assert_eq!(channel.poll(ms(0)), None);
        expect_no_frame(&mut channel, ms(0));
        assert!(channel.is_idle());
        assert_eq!(channel.next_deadline(), None);
    }

    // During a transmission and a reception: neither is disturbed.
    let outgoing: [u8; 20] = counting();
    let incoming: [u8; 20] = core::array::from_fn(|i| 0x40 + i as u8);
    start_segmented(&mut channel, ms(0), &outgoing);
    feed_first(&mut channel, ms(0), &incoming);
    expect_frame(&mut channel, ms(0), &[0x30, 0x08, 0x00]);
    // FC too short, SF of length 0, FF too short.
    for data in [&[0x30][..], &[0x00, 1, 2], &[0x10, 0x14, 1, 2]] {
        assert_eq!(feed(&mut channel, ms(1), data), None);
    }
    let (event, offset) = feed_consecutive(&mut channel, ms(2), 1, &incoming, 6);
    assert_eq!(event, None);
    // A CF shorter than the 7 bytes still due is ignored, the full one taken.
    assert_eq!(feed(&mut channel, ms(3), &[0x22, 1, 2, 3, 4, 5]), None);
    assert!(channel.is_receiving());
    let (event, _) = feed_consecutive(&mut channel, ms(3), 2, &incoming, offset);
    assert_eq!(
        event,
        Some(Event::Received {
            len: 20,
            functional: false
        })
    );
    assert_eq!(channel.received(), &incoming);
    assert_eq!(feed(&mut channel, ms(4), &[0x30, 0x00, 0x00]), None);
    expect_frame(&mut channel, ms(4), &[0x21, 6, 7, 8, 9, 10, 11, 12]);
}

/// Frames on other identifiers, our own transmit identifier included, are ignored.
pub fn other_identifiers_are_ignored() {
    let mut channel: Channel<64> = Channel::new(Config {
        functional_rx_id: Some(FUNCTIONAL),
        ..unpadded()
    });
    for id in [ECU_TX, 0x700, 0x702, 0x7E0, 0x000, 0x7FF] {
        assert_eq!(
            channel.on_frame(ms(0), &frame(id, &[0x02, 0x3E, 0x00])),
            None
        );
        assert_eq!(
            channel.on_frame(ms(0), &frame(id, &[0x10, 0x14, 1, 2, 3, 4, 5, 6])),
            None
        );
        assert!(channel.is_idle());
        expect_no_frame(&mut channel, ms(0));
    }
    assert_eq!(channel.received(), &[] as &[u8]);
}

/// Padded and unpadded frames from the peer are both taken.
pub fn padded_and_unpadded_peer_frames() {
    let mut channel: Channel<64> = Channel::new(unpadded());
    assert_eq!(
        feed(&mut channel, ms(0), &[0x02, 0x3E, 0x00, CC, CC, CC, CC, CC]),
        Some(Event::Received {
            len: 2,
            functional: false
        })
    );
    assert_eq!(channel.received(), &[0x3E, 0x00]);
    channel.release();
    assert_eq!(
        feed(&mut channel, ms(0), &[0x02, 0x3E, 0x00, 0xAA]),
        Some(Event::Received {
            len: 2,
            functional: false
        })
    );
    assert_eq!(channel.received(), &[0x3E, 0x00]);
    channel.release();

    // Last CF padded: the padding is not taken as data.
    feed(&mut channel, ms(1), &[0x10, 0x09, 1, 2, 3, 4, 5, 6]);
    expect_frame(&mut channel, ms(1), &[0x30, 0x08, 0x00]);
    assert_eq!(
        feed(&mut channel, ms(2), &[0x21, 7, 8, 9, CC, CC, CC, CC]),
        Some(Event::Received {
            len: 9,
            functional: false
        })
    );
    assert_eq!(channel.received(), &[1, 2, 3, 4, 5, 6, 7, 8, 9]);

    // A padded FC from the peer.
    let outgoing: [u8; 9] = counting();
    start_segmented(&mut channel, ms(3), &outgoing);
    feed(&mut channel, ms(3), &[0x30, 0x00, 0x00, CC, CC, CC, CC, CC]);
    expect_frame(&mut channel, ms(3), &[0x21, 6, 7, 8]);
}

/// Full duplex: a flow control this side owes goes out before its own next CF, and both
/// transfers complete.
pub fn flow_control_goes_before_consecutive_frames() {
    let outgoing: [u8; 20] = counting();
    let incoming: [u8; 13] = core::array::from_fn(|i| 0x80 + i as u8);
    let mut channel: Channel<64> = Channel::new(unpadded());
    start_segmented(&mut channel, ms(0), &outgoing);
    feed(&mut channel, ms(1), &[0x30, 0x00, 0x00]);
    feed_first(&mut channel, ms(1), &incoming);
    expect_frame(&mut channel, ms(1), &[0x30, 0x08, 0x00]);
    expect_frame(&mut channel, ms(1), &[0x21, 6, 7, 8, 9, 10, 11, 12]);
    let (event, _) = feed_consecutive(&mut channel, ms(2), 1, &incoming, 6);
    assert_eq!(
        event,
        Some(Event::Received {
            len: 13,
            functional: false
        })
    );
    expect_frame(&mut channel, ms(2), &[0x22, 13, 14, 15, 16, 17, 18, 19]);
    assert_eq!(channel.poll(ms(2)), Some(Event::Sent));
    assert_eq!(channel.received(), &incoming);
}

/// `next_deadline` names the next thing to do, or nothing.
pub fn next_deadline_follows_the_state() {
    let payload: [u8; 20] = pattern();
    let mut channel: Channel<64> = Channel::new(unpadded());
    assert_eq!(channel.next_deadline(), None);
    channel.send(ms(7), &payload).unwrap();
    assert_eq!(channel.next_deadline(), Some(ms(7)), "FF due at once");
    assert!(channel.poll_transmit(ms(8)).is_some());
    assert_eq!(channel.next_deadline(), Some(ms(1008)), "N_As");
    channel.confirm_transmit(ms(9));
    assert_eq!(channel.next_deadline(), Some(ms(1009)), "N_Bs");
    feed(&mut channel, ms(10), &[0x30, 0x00, 0x14]);
    assert_eq!(channel.next_deadline(), Some(ms(10)), "CF due at once");
    assert!(channel.poll_transmit(ms(10)).is_some());
    channel.confirm_transmit(ms(11));
    assert_eq!(channel.next_deadline(), Some(ms(31)), "STmin 20 ms");
    assert!(channel.poll_transmit(ms(31)).is_some());
    channel.confirm_transmit(ms(32));
    assert_eq!(channel.next_deadline(), Some(ms(32)), "Sent to collect");
    assert_eq!(channel.poll(ms(40)), Some(Event::Sent));
    assert_eq!(channel.next_deadline(), None);
    assert!(channel.is_idle());
}

/// `abort` ends both directions silently and forgets the unconfirmed frame; a received
/// PDU stays.
pub fn abort_returns_to_idle() {
    let outgoing: [u8; 20] = pattern();
    let incoming: [u8; 20] = pattern();
    let mut channel: Channel<64> = Channel::new(unpadded());
    feed(&mut channel, ms(0), &[0x01, 0x55]);
    channel.send(ms(0), &outgoing).unwrap();
    assert!(channel.poll_transmit(ms(0)).is_some());
    channel.set_rx_ready(false);
    feed_first(&mut channel, ms(0), &incoming);
    assert!(!channel.is_idle());
    channel.abort();
    assert!(channel.is_idle());
    assert!(!channel.is_transmitting());
    assert!(!channel.is_receiving());
    assert_eq!(channel.next_deadline(), None);
    assert_eq!(channel.poll(ms(10_000)), None, "no timeouts after abort");
    expect_no_frame(&mut channel, ms(10_000));
    assert_eq!(channel.received(), &[0x55]);
    assert_eq!(feed(&mut channel, ms(1), &[0x30, 0x00, 0x00]), None);
    channel.send(ms(2), &[1]).expect("free after abort");
    expect_frame(&mut channel, ms(2), &[0x01, 1]);
}

/// A confirmation without a frame handed out changes nothing.
pub fn stray_confirmation_is_ignored() {
    let payload: [u8; 20] = pattern();
    let mut channel: Channel<64> = Channel::new(unpadded());
    channel.confirm_transmit(ms(0));
    assert!(channel.is_idle());
    start_segmented(&mut channel, ms(0), &payload);
    channel.confirm_transmit(ms(500));
    assert_eq!(
        channel.next_deadline(),
        Some(ms(1000)),
        "N_Bs still from the real confirmation"
    );
}
