//! The longest stretch of bus time a condition held: what most routines measure.

use crate::{Finding, Verdict, Window};

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

/// How a rule measured as a [`LongestSpan`] reads in a finding.
pub struct SpanRule {
    /// What was measured ("fan against the temperature error").
    pub routine: &'static str,
    /// Above this many seconds: suspect.
    pub suspect_s: f64,
    /// Above this many seconds: faulty.
    pub faulty_s: f64,
    /// What breaking the rule looks like ("the fan worked against the error").
    pub broken: &'static str,
    /// Why it could not be judged ("TempMsg and FanMsg never fresh together").
    pub unexercised: &'static str,
}

impl SpanRule {
    /// The finding for `span`, its running stretch ended at `now`.
    pub fn finding(&self, span: &LongestSpan, now: u64) -> Finding {
        let span = span.until(now);
        let value = span.seconds();
        Finding {
            routine: self.routine,
            verdict: if span.judged == 0 {
                Verdict::NotExercised
            } else {
                Verdict::of(value, self.suspect_s, self.faulty_s)
            },
            value: (span.judged > 0).then_some(value),
            unit: "s",
            suspect_above: self.suspect_s,
            faulty_above: self.faulty_s,
            window: span.longest,
            evidence: match span.longest {
                _ if span.judged == 0 => format!("not exercised: {}", self.unexercised),
                None => format!("held in all {} comparisons", span.judged),
                Some(w) => format!(
                    "{} for {value:.3} s from {:.2} s",
                    self.broken,
                    w.from_us as f64 * 1e-6
                ),
            },
        }
    }
}
