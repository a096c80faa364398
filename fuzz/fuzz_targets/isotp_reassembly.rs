//! Feeds an ISO-TP receiver arbitrary frames, time steps and upper-layer actions, and
//! checks that it never panics, reports a PDU only with the length its single or first
//! frame announced (with that many bytes in `received()`), never overwrites a PDU not
//! yet released, and sends only well-formed frames.
//!
//! Input layout: 4 header bytes (flags, block size, STmin, N_WFTmax), then operations.
//! An operation byte `op` with `op & 3` = 0, 1, 2 is a frame on the physical, functional
//! or another identifier, followed by a length byte (mod 9), the data bytes and a time
//! step byte (squared × 25 µs, up to 1.6 s, so timeouts happen). `op & 3 == 3` is an
//! upper-layer action chosen by `op >> 2` (release, ready, not ready, send, abort, a long
//! pause, confirm a pending frame).
#![no_main]

use autoplug_can::Frame;
use autoplug_ecu::Instant;
use autoplug_isotp::{Channel, ChannelError, Config, Direction, Event, StMin};
use libfuzzer_sys::fuzz_target;

const RX: u16 = 0x701;
const TX: u16 = 0x781;
const FUNCTIONAL: u16 = 0x7DF;
const OTHER: u16 = 0x123;

struct Input<'a>(&'a [u8]);

impl<'a> Input<'a> {
    fn byte(&mut self) -> Option<u8> {
        let (&first, rest) = self.0.split_first()?;
        self.0 = rest;
        Some(first)
    }

    fn bytes(&mut self, n: usize) -> Option<&'a [u8]> {
        if self.0.len() < n {
            return None;
        }
        let (taken, rest) = self.0.split_at(n);
        self.0 = rest;
        Some(taken)
    }
}

/// The segmented PDU the last valid first frame announced.
struct Announced {
    len: usize,
    first_data: [u8; 6],
}

/// What the harness knows of the channel under test.
struct Harness {
    channel: Box<Channel<4095>>,
    padded: bool,
    /// Confirmations come one operation late (so N_As / N_Ar can run out).
    confirm_late: bool,
    awaiting_confirmation: bool,
    now: Instant,
    segmented: Option<Announced>,
    holding: bool,
    sending: bool,
}

/// A single frame's announcement: length, functional, payload.
type SingleFrame<'a> = Option<(usize, bool, &'a [u8])>;

impl Harness {
    fn check_event(&mut self, event: Event, single: SingleFrame<'_>, from_frame: bool) {
        match event {
            Event::Received { len, functional } => {
                assert!(from_frame, "a PDU completed without a frame");
                assert!(!self.holding, "a PDU not released was overwritten");
                assert_eq!(
                    self.channel.received().len(),
                    len,
                    "received() has the length"
                );
                match single {
                    Some((announced, announced_functional, payload)) => {
                        assert_eq!(len, announced, "SF length");
                        assert_eq!(functional, announced_functional);
                        assert_eq!(self.channel.received(), payload);
                    }
                    None => {
                        let announced = self
                            .segmented
                            .take()
                            .expect("a segmented PDU was announced by an FF");
                        assert!(!functional, "segmented PDUs are physical");
                        assert_eq!(len, announced.len, "FF length");
                        assert_eq!(self.channel.received()[..6], announced.first_data);
                    }
                }
                self.holding = true;
            }
            Event::Sent => {
                assert!(self.sending, "Sent without a PDU being sent");
                self.sending = false;
            }
            Event::Error(error) => {
                if error.direction() == Direction::Transmit {
                    self.sending = false;
                }
                if let ChannelError::IncomingTooLong { capacity, .. } = error {
                    assert_eq!(capacity, 4095);
                }
            }
        }
    }

    fn drain(&mut self, single: SingleFrame<'_>, from_frame: bool) {
        while let Some(event) = self.channel.poll(self.now) {
            self.check_event(event, single, from_frame);
        }
        loop {
            if self.awaiting_confirmation {
                if self.confirm_late {
                    return;
                }
                self.channel.confirm_transmit(self.now);
                self.awaiting_confirmation = false;
                while let Some(event) = self.channel.poll(self.now) {
                    self.check_event(event, None, false);
                }
            }
            let Some(frame) = self.channel.poll_transmit(self.now) else {
                return;
            };
            self.awaiting_confirmation = true;
            assert_eq!(frame.id(), TX);
            let data = frame.data();
            assert!(!data.is_empty());
            if self.padded {
                assert_eq!(data.len(), 8, "padding to 8 bytes");
            }
            match data[0] >> 4 {
                0 => assert!((1..=7).contains(&(data[0] & 0x0F))),
                1 => assert_eq!(data.len(), 8),
                2 => assert!(data.len() >= 2),
                3 => assert!((data[0] & 0x0F) <= 2 && data.len() >= 3),
                _ => panic!("reserved PCI type sent: {frame:?}"),
            }
        }
    }

    fn confirm_pending(&mut self) {
        if self.awaiting_confirmation {
            self.awaiting_confirmation = false;
            self.channel.confirm_transmit(self.now);
        }
    }

    fn on_frame(&mut self, id: u16, data: &[u8]) {
        let Ok(frame) = Frame::new(u32::from(id), data) else {
            return;
        };
        let pci = data.first().copied().unwrap_or(0xFF);
        let mut single = None;
        match pci >> 4 {
            0 if id == RX || id == FUNCTIONAL => {
                let len = usize::from(pci & 0x0F);
                if (1..=7).contains(&len) && len < data.len() {
                    single = Some((len, id == FUNCTIONAL, &data[1..=len]));
                    if id == RX {
                        // Ends any reception: no CF may complete the old PDU.
                        self.segmented = None;
                    }
                }
            }
            1 if id == RX && data.len() == 8 => {
                let len = usize::from(pci & 0x0F) << 8 | usize::from(data[1]);
                if len >= 8 {
                    let mut first_data = [0; 6];
                    first_data.copy_from_slice(&data[2..]);
                    self.segmented = Some(Announced { len, first_data });
                } else if len == 0 {
                    self.segmented = None;
                }
            }
            _ => {}
        }
        if let Some(event) = self.channel.on_frame(self.now, &frame) {
            self.check_event(event, single, true);
        }
        self.drain(single, true);
    }
}

fuzz_target!(|data: &[u8]| run(data));

fn run(data: &[u8]) {
    let mut input = Input(data);
    let flags = input.byte().unwrap_or(0);
    let block_size = input.byte().unwrap_or(0);
    let st_min = input.byte().unwrap_or(0);
    let max_wait_frames = input.byte().unwrap_or(0) % 4;
    let padded = flags & 1 != 0;
    let config = Config {
        functional_rx_id: Some(FUNCTIONAL),
        padding: padded.then_some(0xCC),
        block_size,
        st_min: StMin::from_byte(st_min),
        max_wait_frames,
        // Short enough that the input's time steps reach it.
        n_br_us: 50_000,
        ..Config::default_for(TX, RX)
    };
    let mut harness = Harness {
        channel: Box::new(Channel::new(config)),
        padded,
        confirm_late: flags & 2 != 0,
        awaiting_confirmation: false,
        now: Instant::ZERO,
        segmented: None,
        holding: false,
        sending: false,
    };
    while let Some(op) = input.byte() {
        // The frame to feed, if the operation is one.
        let mut frame = None;
        let mut step_us = 0;
        match op & 3 {
            target @ 0..=2 => {
                let Some(len) = input.byte() else { return };
                let Some(frame_data) = input.bytes(usize::from(len % 9)) else {
                    return;
                };
                let step = u64::from(input.byte().unwrap_or(0));
                step_us = step * step * 25;
                frame = Some(([RX, FUNCTIONAL, OTHER][usize::from(target)], frame_data));
            }
            _ if (op >> 2) % 8 == 5 => step_us = 2_000_000,
            _ => {}
        }
        // A polling loop handles the timeouts due before a late confirmation or a frame.
        harness.now = harness.now.plus_micros(step_us);
        harness.drain(None, false);
        harness.confirm_pending();
        harness.drain(None, false);
        if let Some((id, frame_data)) = frame {
            harness.on_frame(id, frame_data);
            continue;
        }
        match (op >> 2) % 8 {
            0 => {
                harness.channel.release();
                harness.holding = false;
            }
            1 => harness.channel.set_rx_ready(true),
            2 => harness.channel.set_rx_ready(false),
            3 => {
                let high = input.byte().unwrap_or(0);
                let low = input.byte().unwrap_or(0);
                let len = usize::from(u16::from_be_bytes([high, low]) % 4100);
                let payload = [0x5A; 4100];
                let busy = harness.channel.is_transmitting();
                let result = harness.channel.send(harness.now, &payload[..len]);
                assert_eq!(result.is_ok(), !busy && (1..=4095).contains(&len));
                if result.is_ok() {
                    harness.sending = true;
                }
            }
            4 => {
                harness.channel.abort();
                harness.awaiting_confirmation = false;
                harness.segmented = None;
                harness.sending = false;
                assert!(
                    harness.channel.is_idle(),
                    "abort leaves nothing in progress"
                );
            }
            _ => {}
        }
        harness.drain(None, false);
    }
}
