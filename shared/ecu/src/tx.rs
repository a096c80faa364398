//! Transmission timing of spec section 3: every message is sent at its period, and at once
//! when its value changes, but never sooner than its minimum gap after the previous
//! transmission.

use crate::Instant;
use autoplug_can::{CanMessage, Frame};

/// The transmit timing of one message.
#[derive(Clone, Copy, Debug, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PeriodicTx {
    period_us: u64,
    min_gap_us: u64,
    current: Option<Frame>,
    last_sent: Option<(Instant, Frame)>,
}

impl PeriodicTx {
    /// Timing taken from the catalogue (`GenMsgCycleTime`, `GenMsgDelayTime`).
    pub const fn of<M: CanMessage>() -> Self {
        Self::new(M::CYCLE_TIME_MS, M::MIN_GAP_MS)
    }

    /// Explicit period and minimum gap, in milliseconds.
    pub const fn new(period_ms: u32, min_gap_ms: u32) -> Self {
        Self {
            period_us: period_ms as u64 * 1000,
            min_gap_us: min_gap_ms as u64 * 1000,
            current: None,
            last_sent: None,
        }
    }

    /// The value to send from now on. Nothing is sent before the first `set`.
    pub fn set(&mut self, frame: Frame) {
        self.current = Some(frame);
    }

    /// The value to send from now on, as a message.
    pub fn set_message<M: CanMessage>(&mut self, message: &M) {
        self.set(message.frame());
    }

    /// The frame to send now, if one is due: the first one at once, then one per period,
    /// or earlier on a change once the minimum gap has passed. Marks it sent.
    pub fn poll(&mut self, now: Instant) -> Option<Frame> {
        let current = self.current?;
        let due = match self.last_sent {
            None => true,
            Some((at, sent)) => {
                let elapsed = now.micros_since(at);
                elapsed >= self.period_us || (sent != current && elapsed >= self.min_gap_us)
            }
        };
        if due {
            self.last_sent = Some((now, current));
            Some(current)
        } else {
            None
        }
    }

    /// When the next transmission is due at the latest (the period), if anything was set.
    pub fn next_due(&self) -> Option<Instant> {
        self.current?;
        Some(match self.last_sent {
            None => Instant::ZERO,
            Some((at, _)) => at.plus_micros(self.period_us),
        })
    }
}
