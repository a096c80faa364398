//! The longest stretch of bus time a condition held: what most routines measure.

use crate::Window;

/// Tracks a condition judged frame by frame and keeps its longest continuous stretch.
#[derive(Clone, Copy, Debug, Default)]
pub struct LongestSpan {
    since: Option<u64>,
    /// The longest stretch so far.
    pub longest: Option<Window>,
    /// Frames at which the condition could be judged (its inputs fresh).
    pub judged: u64,
}

impl LongestSpan {
    /// The condition at bus time `t`: `judged` when its inputs allow a judgement, `holds`
    /// whether it held then. A stretch ends at the first frame where it does not hold or
    /// cannot be judged.
    pub fn observe(&mut self, t: u64, judged: bool, holds: bool) {
        if judged {
            self.judged += 1;
        }
        match (judged && holds, self.since) {
            (true, None) => self.since = Some(t),
            (false, Some(_)) => self.end(t),
            _ => {}
        }
    }

    /// Ends a running stretch at `t`.
    pub fn end(&mut self, t: u64) {
        if let Some(since) = self.since.take() {
            if self
                .longest
                .is_none_or(|w| t.saturating_sub(since) > w.to_us - w.from_us)
            {
                self.longest = Some(Window {
                    from_us: since,
                    to_us: t,
                });
            }
        }
    }

    /// A copy with a running stretch ended at `now` (for a report in the middle of a run).
    pub fn until(&self, now: u64) -> Self {
        let mut copy = *self;
        copy.end(now);
        copy
    }

    /// The longest stretch, s (0 if none).
    pub fn seconds(&self) -> f64 {
        self.longest
            .map_or(0.0, |w| (w.to_us - w.from_us) as f64 * 1e-6)
    }
}
