//! The bus as a transport that never sees its own frames go out (socketcand) can know it.
//!
//! socketcand's server writes a client's frames to its bus and never echoes them, so the
//! client cannot tell when one is on the bus. [`BusModel`] works it out: each frame takes
//! its exact length on the wire (stuff bits and intermission included) at the bus's bit
//! rate, behind the frames sent before it, and every frame of another node seen while
//! frames of this side wait took the bus ahead of them. A frame counts as sent (its
//! confirmation) when the model says it is through; the transport takes no more than a
//! window's worth of frames ahead of the model, so a transfer goes at the bus's pace
//! instead of piling up in the server's queue while the tester's P2 runs.
//!
//! The model can only be late by what it does not see: the link's latency and frames of
//! other nodes it has not been told of yet. The tester's ΔP2 covers that.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use autoplug_can::Frame;
use autoplug_virtual_bus::frame_bits;

/// A model of the bus's time, for the frames this side sent.
#[derive(Debug, Clone)]
pub struct BusModel {
    /// Nanoseconds per bit.
    bit_ns: u64,
    /// When each frame sent and not confirmed yet leaves the bus, oldest first.
    pending: VecDeque<Instant>,
}

impl BusModel {
    /// A bus at `bitrate` bit/s (at least 1).
    pub fn new(bitrate: u32) -> Self {
        Self {
            bit_ns: 1_000_000_000 / u64::from(bitrate.max(1)),
            pending: VecDeque::new(),
        }
    }

    /// How long `frame` keeps the bus, intermission included.
    pub fn frame_time(&self, frame: &Frame) -> Duration {
        Duration::from_nanos(u64::from(frame_bits(frame).total_with_ifs) * self.bit_ns)
    }

    /// This side handed `frame` to the bus at `now`: it goes once the frames before it
    /// have.
    pub fn sent(&mut self, now: Instant, frame: &Frame) {
        let start = self.pending.back().map_or(now, |&last| last.max(now));
        self.pending.push_back(start + self.frame_time(frame));
    }

    /// Another node's `frame` arrived while frames of this side wait: it held the bus
    /// (by its priority, or by being under way), so they all go later by its length.
    pub fn seen(&mut self, frame: &Frame) {
        if self.pending.is_empty() {
            return;
        }
        let held = self.frame_time(frame);
        for done in &mut self.pending {
            *done += held;
        }
    }

    /// Frames sent and not confirmed yet.
    pub fn in_flight(&self) -> usize {
        self.pending.len()
    }

    /// When the oldest frame in flight is through, if any.
    pub fn next_confirmation(&self) -> Option<Instant> {
        self.pending.front().copied()
    }

    /// Confirms the oldest frame in flight if it is through at `now`.
    pub fn confirm_due(&mut self, now: Instant) -> bool {
        if self.pending.front().is_some_and(|&done| done <= now) {
            self.pending.pop_front();
            true
        } else {
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn eight_bytes() -> Frame {
        Frame::new(0x70D, &[0x21, 0xAA, 0x55, 0x00, 0xFF, 0x12, 0x34, 0x56]).unwrap()
    }

    #[test]
    fn frames_follow_each_other_at_the_bit_rate() {
        let mut bus = BusModel::new(500_000);
        let frame = eight_bytes();
        let one = bus.frame_time(&frame);
        // 8 data bytes: 111 bits unstuffed with the intermission, and some stuff bits.
        let bits = one.as_nanos() / 2000;
        assert!((111..=135).contains(&bits), "{bits} bits");
        let t0 = Instant::now();
        bus.sent(t0, &frame);
        bus.sent(t0, &frame);
        assert_eq!(bus.in_flight(), 2);
        assert_eq!(bus.next_confirmation(), Some(t0 + one));
        assert!(!bus.confirm_due(t0 + one - Duration::from_nanos(1)));
        assert!(bus.confirm_due(t0 + one));
        assert_eq!(bus.next_confirmation(), Some(t0 + one * 2));
        assert!(bus.confirm_due(t0 + one * 5));
        assert!(!bus.confirm_due(t0 + one * 5));
        // The bus idle meanwhile: a new frame starts when it is sent.
        let later = t0 + one * 10;
        bus.sent(later, &frame);
        assert_eq!(bus.next_confirmation(), Some(later + one));
    }

    #[test]
    fn other_nodes_frames_delay_the_waiting_ones_only() {
        let mut bus = BusModel::new(500_000);
        let ours = eight_bytes();
        let theirs = Frame::new(0x003, &[0x00]).unwrap();
        let t0 = Instant::now();
        // Nothing waiting: another node's frame changes nothing.
        bus.seen(&theirs);
        bus.sent(t0, &ours);
        bus.sent(t0, &ours);
        bus.seen(&theirs);
        let (one, other) = (bus.frame_time(&ours), bus.frame_time(&theirs));
        assert_eq!(bus.next_confirmation(), Some(t0 + one + other));
        assert!(bus.confirm_due(t0 + one + other));
        assert!(bus.confirm_due(t0 + one * 2 + other));
        // A frame sent now queues behind nothing: it was delayed only while it waited.
        bus.sent(t0 + one * 2 + other, &ours);
        assert_eq!(
            bus.next_confirmation(),
            Some(t0 + one * 3 + other),
            "{:?}",
            bus
        );
    }
}
