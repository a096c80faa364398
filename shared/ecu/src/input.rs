//! A received message as an ECU input: its last good value, whether it is still fresh
//! (spec section 2: stale when not received within 3 of its periods), and the faults seen.

use crate::Instant;
use autoplug_can::{CanMessage, DecodeError, Frame};

/// How many periods without a valid frame make an input stale (spec section 2).
pub const STALE_AFTER_PERIODS: u64 = 3;

/// What happened to an input's freshness at a check.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Freshness {
    /// Valid frames keep arriving.
    Fresh,
    /// No valid frame for 3 periods.
    Stale,
}

/// One consumed message.
///
/// Only a fully valid frame refreshes the input: a sender that keeps sending invalid
/// values must drive the receiver into its safe state just like a silent one, while the
/// valid signals of a partly invalid frame are still taken (`update_from`).
#[derive(Clone, Copy, Debug)]
pub struct Input<M: CanMessage> {
    value: M,
    timeout_us: u64,
    last_valid: Instant,
    freshness: Freshness,
    ever_received: bool,
    invalid_frames: u32,
    last_error: Option<DecodeError>,
    latest_frame_valid: bool,
}

impl<M: CanMessage> Input<M> {
    /// An input at the message's start values, considered fresh from `now` (so it goes
    /// stale 3 periods after start if its sender never speaks).
    pub fn new(now: Instant) -> Self {
        Self {
            value: M::default(),
            timeout_us: u64::from(M::CYCLE_TIME_MS) * 1000 * STALE_AFTER_PERIODS,
            last_valid: now,
            freshness: Freshness::Fresh,
            ever_received: false,
            invalid_frames: 0,
            last_error: None,
            latest_frame_valid: false,
        }
    }

    /// Takes a frame if it is this message: `Some(Ok(()))` when it was fully valid,
    /// `Some(Err(_))` when it was (partly) refused, `None` when it is another message.
    pub fn accept(&mut self, now: Instant, frame: &Frame) -> Option<Result<(), DecodeError>> {
        if frame.id() != M::ID {
            return None;
        }
        let result = self.value.update_from_data(frame.data());
        self.latest_frame_valid = result.is_ok();
        match result {
            Ok(()) => {
                self.last_valid = now;
                self.ever_received = true;
            }
            Err(e) => {
                self.invalid_frames = self.invalid_frames.saturating_add(1);
                self.last_error = Some(e);
            }
        }
        Some(result)
    }

    /// Re-evaluates freshness at `now`; returns the new state when it changed.
    pub fn check(&mut self, now: Instant) -> Option<Freshness> {
        let fresh = now.micros_since(self.last_valid) < self.timeout_us;
        let new = if fresh {
            Freshness::Fresh
        } else {
            Freshness::Stale
        };
        if new == self.freshness {
            None
        } else {
            self.freshness = new;
            Some(new)
        }
    }

    /// The last good value (start values before the first valid frame).
    pub fn value(&self) -> &M {
        &self.value
    }

    /// The value, if it can be trusted: received at least once and not stale.
    pub fn known(&self) -> Option<&M> {
        (self.ever_received && self.freshness == Freshness::Fresh).then_some(&self.value)
    }

    /// Whether the last check found the input stale.
    pub fn is_stale(&self) -> bool {
        self.freshness == Freshness::Stale
    }

    /// Whether a valid frame has arrived since start.
    pub fn ever_received(&self) -> bool {
        self.ever_received
    }

    /// Whether the most recent frame of this message was fully valid: act on an event
    /// carried by a frame (a cancel) only then, not on a kept last good value.
    pub fn latest_frame_valid(&self) -> bool {
        self.latest_frame_valid
    }

    /// Frames refused (wrong length or invalid values) since start.
    pub fn invalid_frames(&self) -> u32 {
        self.invalid_frames
    }

    /// Why the last refused frame was refused.
    pub fn last_error(&self) -> Option<DecodeError> {
        self.last_error
    }

    /// Time without a valid frame after which the input is stale.
    pub fn timeout_us(&self) -> u64 {
        self.timeout_us
    }
}
