//! Time as the ECU logic sees it: microseconds since the ECU started, passed in by the
//! caller (an Embassy timer on the target, simulated time in the virtual car), so the
//! logic never reads a clock and every run can be replayed.

/// A point in time, in microseconds since start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Instant(u64);

impl Instant {
    /// Start of time.
    pub const ZERO: Instant = Instant(0);

    /// From microseconds.
    pub const fn from_micros(us: u64) -> Self {
        Self(us)
    }

    /// From milliseconds.
    pub const fn from_millis(ms: u64) -> Self {
        Self(ms * 1000)
    }

    /// Microseconds since start.
    pub const fn as_micros(self) -> u64 {
        self.0
    }

    /// Seconds since start, for logs and plots.
    pub fn as_secs_f32(self) -> f32 {
        self.0 as f32 * 1e-6
    }

    /// Microseconds from `earlier` to `self`; 0 if `earlier` is later.
    pub const fn micros_since(self, earlier: Instant) -> u64 {
        self.0.saturating_sub(earlier.0)
    }

    /// `self` plus some microseconds (saturating).
    pub const fn plus_micros(self, us: u64) -> Instant {
        Instant(self.0.saturating_add(us))
    }
}
