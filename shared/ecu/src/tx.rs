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
    /// When the next frame is due by the period.
    next_periodic: Instant,
}

/// How early a poll may be and still send a frame due by its period: half a millisecond,
/// under the virtual car's 1 ms tick (so there it changes nothing) and far over an MCU's
/// wake-up latency.
pub const EARLY_US: u64 = 500;

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
            next_periodic: Instant::ZERO,
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
    ///
    /// The period runs from the moment the last frame was due, not from when a poll got
    /// to it, so a caller that polls a little late (a control loop on an MCU, some µs after
    /// its ticker) does not drift a period behind; a poll up to [`EARLY_US`] before the
    /// moment counts as on time, for the same caller polling a little early. A change sent
    /// early starts the period afresh, as does a poll more than a period late.
    pub fn poll(&mut self, now: Instant) -> Option<Frame> {
        let current = self.current?;
        let (periodic, changed) = match self.last_sent {
            None => (true, false),
            Some((at, sent)) => (
                now.plus_micros(EARLY_US) >= self.next_periodic,
                sent != current && now.micros_since(at) >= self.min_gap_us,
            ),
        };
        if !(periodic || changed) {
            return None;
        }
        let on_cadence = self.last_sent.is_some()
            && periodic
            && now < self.next_periodic.plus_micros(self.period_us);
        self.next_periodic = if on_cadence {
            self.next_periodic.plus_micros(self.period_us)
        } else {
            now.plus_micros(self.period_us)
        };
        self.last_sent = Some((now, current));
        Some(current)
    }

    /// When the next transmission is due at the latest (the period), if anything was set.
    pub fn next_due(&self) -> Option<Instant> {
        self.current?;
        Some(match self.last_sent {
            None => Instant::ZERO,
            Some(_) => self.next_periodic,
        })
    }
}
