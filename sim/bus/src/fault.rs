//! Deterministic fault injection: rules that drop or corrupt chosen frames, and the seeded
//! random generator behind the probabilistic ones.

use crate::node::{NodeId, NodeSet};

/// What a fault rule does to a frame it hits.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum FaultAction {
    /// The frame goes over the wire and is acknowledged (the sender counts a success),
    /// but no node's software gets it: a loss after the controller, e.g. a receiver task
    /// that missed it. Other frames are unaffected.
    Drop,
    /// Every receiver sees a CRC error: error frame after the ACK delimiter, TEC + 8 for
    /// the sender, REC + 1 for every other node on the bus, nobody gets the frame, and
    /// the sender retransmits (unless it has `auto_retransmit` off).
    Corrupt,
}

/// When a rule fires on a frame it matches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Trigger {
    /// On every matching frame.
    Always,
    /// On the n-th, 2n-th, ... matching frame (each attempt on the wire counts, so a
    /// retransmission is a new frame). `EveryNth(1)` is `Always`.
    EveryNth(u32),
    /// On each matching frame with this probability, from the bus's seeded generator.
    Probability(f64),
}

/// One fault to inject. Build with [`FaultRule::drop`] or [`FaultRule::corrupt`] and
/// narrow it with the `with_*` methods; by default it hits every frame, always, forever.
///
/// ```
/// use autoplug_virtual_bus::FaultRule;
/// // Lose one in three VehicleSpeedMsg during the first second.
/// let rule = FaultRule::drop().with_id(0x003).every_nth(3).between(0, 1_000_000_000);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FaultRule {
    /// What it does.
    pub action: FaultAction,
    /// Only frames with this identifier; `None`: any.
    pub id: Option<u16>,
    /// Only frames from this node; `None`: any.
    pub sender: Option<NodeId>,
    /// When it fires on a matching frame.
    pub trigger: Trigger,
    /// Active for frames starting at or after this time, ns.
    pub from_ns: u64,
    /// Active for frames starting before this time, ns.
    pub until_ns: u64,
    /// Fires at most this many times; `None`: unlimited.
    pub max_hits: Option<u64>,
}

impl FaultRule {
    fn new(action: FaultAction) -> Self {
        Self {
            action,
            id: None,
            sender: None,
            trigger: Trigger::Always,
            from_ns: 0,
            until_ns: u64::MAX,
            max_hits: None,
        }
    }

    /// A rule that drops frames ([`FaultAction::Drop`]).
    pub fn drop() -> Self {
        Self::new(FaultAction::Drop)
    }

    /// A rule that corrupts frames ([`FaultAction::Corrupt`]).
    pub fn corrupt() -> Self {
        Self::new(FaultAction::Corrupt)
    }

    /// Only frames with identifier `id`.
    pub fn with_id(mut self, id: u16) -> Self {
        self.id = Some(id);
        self
    }

    /// Only frames sent by `node`.
    pub fn from_sender(mut self, node: NodeId) -> Self {
        self.sender = Some(node);
        self
    }

    /// Fire on every `n`-th matching frame.
    ///
    /// # Panics
    /// If `n` is 0.
    pub fn every_nth(mut self, n: u32) -> Self {
        assert!(n > 0, "every_nth(0) would never fire");
        self.trigger = Trigger::EveryNth(n);
        self
    }

    /// Fire on each matching frame with probability `p` (clamped to 0..=1).
    pub fn with_probability(mut self, p: f64) -> Self {
        self.trigger = Trigger::Probability(p.clamp(0.0, 1.0));
        self
    }

    /// Only for frames starting in `from_ns..until_ns`.
    pub fn between(mut self, from_ns: u64, until_ns: u64) -> Self {
        self.from_ns = from_ns;
        self.until_ns = until_ns;
        self
    }

    /// Fire at most `n` times.
    pub fn max_hits(mut self, n: u64) -> Self {
        self.max_hits = Some(n);
        self
    }

    fn matches(&self, id: u16, senders: NodeSet, start_ns: u64) -> bool {
        self.id.is_none_or(|want| want == id)
            && self.sender.is_none_or(|want| senders.contains(want))
            && (self.from_ns..self.until_ns).contains(&start_ns)
    }
}

/// Handle of a rule added with [`crate::VirtualBus::add_fault`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct FaultId(pub(crate) usize);

#[derive(Clone, Debug)]
struct ActiveRule {
    rule: FaultRule,
    matched: u64,
    hits: u64,
}

/// The bus's fault rules, evaluated in the order they were added.
#[derive(Clone, Debug, Default)]
pub(crate) struct Faults {
    rules: Vec<Option<ActiveRule>>,
}

impl Faults {
    pub(crate) fn add(&mut self, rule: FaultRule) -> FaultId {
        self.rules.push(Some(ActiveRule {
            rule,
            matched: 0,
            hits: 0,
        }));
        FaultId(self.rules.len() - 1)
    }

    pub(crate) fn remove(&mut self, id: FaultId) -> bool {
        self.rules.get_mut(id.0).and_then(Option::take).is_some()
    }

    pub(crate) fn hits(&self, id: FaultId) -> u64 {
        self.rules
            .get(id.0)
            .and_then(Option::as_ref)
            .map_or(0, |r| r.hits)
    }

    /// Decides the fate of a frame starting on the wire. Every matching rule advances its
    /// own counter (and draws from the generator if probabilistic), so one rule's
    /// behaviour does not depend on the others; the first rule that fires wins.
    pub(crate) fn evaluate(
        &mut self,
        id: u16,
        senders: NodeSet,
        start_ns: u64,
        rng: &mut XorShift64,
    ) -> Option<FaultAction> {
        let mut outcome = None;
        for active in self.rules.iter_mut().flatten() {
            let rule = &active.rule;
            if !rule.matches(id, senders, start_ns)
                || rule.max_hits.is_some_and(|max| active.hits >= max)
            {
                continue;
            }
            active.matched += 1;
            let fires = match rule.trigger {
                Trigger::Always => true,
                Trigger::EveryNth(n) => active.matched % u64::from(n) == 0,
                Trigger::Probability(p) => rng.next_f64() < p,
            };
            if fires {
                active.hits += 1;
                outcome = outcome.or(Some(rule.action));
            }
        }
        outcome
    }
}

/// xorshift64* (Vigna): tiny, fast, and the same sequence on every machine.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct XorShift64(u64);

impl XorShift64 {
    pub(crate) fn new(seed: u64) -> Self {
        // The all-zero state is a fixed point; any other seed is fine.
        Self(if seed == 0 {
            0x9E37_79B9_7F4A_7C15
        } else {
            seed
        })
    }

    pub(crate) fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in [0, 1).
    pub(crate) fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_nth_counts_matching_frames_only() {
        let mut faults = Faults::default();
        let mut rng = XorShift64::new(1);
        let rule = faults.add(FaultRule::drop().with_id(0x003).every_nth(3));
        let all = NodeSet::EMPTY;
        let hits: Vec<bool> = (0..9)
            .map(|i| {
                let id = if i % 2 == 0 { 0x003 } else { 0x004 };
                faults.evaluate(id, all, 0, &mut rng).is_some()
            })
            .collect();
        // Matching frames are i = 0, 2, 4, 6, 8; the 3rd of them is i = 4.
        assert_eq!(
            hits,
            [false, false, false, false, true, false, false, false, false]
        );
        assert_eq!(faults.hits(rule), 1);
    }

    #[test]
    fn max_hits_and_window_limit_a_rule() {
        let mut faults = Faults::default();
        let mut rng = XorShift64::new(1);
        let rule = faults.add(FaultRule::corrupt().between(100, 200).max_hits(2));
        let fired: Vec<_> = [50, 100, 150, 199, 200]
            .iter()
            .map(|&t| faults.evaluate(1, NodeSet::EMPTY, t, &mut rng))
            .collect();
        assert_eq!(
            fired,
            [
                None,
                Some(FaultAction::Corrupt),
                Some(FaultAction::Corrupt),
                None,
                None
            ]
        );
        assert_eq!(faults.hits(rule), 2);
        assert!(faults.remove(rule));
        assert!(!faults.remove(rule));
        assert_eq!(faults.evaluate(1, NodeSet::EMPTY, 150, &mut rng), None);
    }

    #[test]
    fn probability_is_roughly_right_and_reproducible() {
        let run = || {
            let mut faults = Faults::default();
            let mut rng = XorShift64::new(42);
            faults.add(FaultRule::drop().with_probability(0.1));
            (0..10_000)
                .filter(|_| faults.evaluate(1, NodeSet::EMPTY, 0, &mut rng).is_some())
                .count()
        };
        let hits = run();
        assert!((900..1100).contains(&hits), "{hits}");
        assert_eq!(hits, run());
    }
}
