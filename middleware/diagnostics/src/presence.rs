//! Every ECU: its messages present at their periods.
//!
//! For each cyclic message the ECU is the first sender of, the routine measures the longest
//! gap between two frames, in periods of that message. A gap is not held against the ECU
//! when the ECU itself answered a tester during the gap or in the second before it: a
//! tester silences normal traffic (UDS 0x28), programs and resets ECUs while flashing, and
//! the ECU's own responses show it alive and busy with the tester. Requests alone explain
//! nothing: a gateway that keeps asking a dead ECU for its trouble codes must not hide that
//! it is dead.
//!
//! Thresholds: a receiver declares an input stale after 3 periods (spec section 2), so a
//! gap over 3 periods already put the ECU's receivers into their safe states: suspect.
//! Over 10 periods the ECU is taken to have stopped: faulty. An ECU none of whose messages
//! ever arrived, or all of whose messages stopped for good, is reported as no data.

use autoplug_can::{Node, MESSAGES};
use autoplug_gateway::{CarState, Update};
use autoplug_logs::LogFrame;

use crate::{Finding, Routine, Verdict, Window};

/// The routine's name in findings.
pub const ROUTINE: &str = "messages at their periods";
/// Gaps over this many periods: suspect.
pub const GAP_SUSPECT_PERIODS: f64 = 3.0;
/// Gaps over this many periods: faulty.
pub const GAP_FAULTY_PERIODS: f64 = 10.0;
/// An answer to a tester this long before a gap still explains it, µs.
const DIAG_EXPLAINS_US: u64 = 1_000_000;
/// The whole bus silent this long is asleep (the ignition off), µs: every ECU sends
/// something at least every 100 ms while awake.
pub const BUS_ASLEEP_US: u64 = 1_000_000;

struct Tracked {
    id: u16,
    name: &'static str,
    period_us: u64,
    count: u64,
    first_us: Option<u64>,
    last_us: Option<u64>,
    longest_gap_periods: f64,
    longest_gap: Option<Window>,
    /// The bus's asleep time so far at this message's last frame.
    asleep_at_last_us: u64,
}

/// The presence routine of one ECU.
pub struct Presence {
    node: Node,
    tracked: Vec<Tracked>,
    last_response_us: Option<u64>,
    /// The last frame on the bus, anyone's.
    last_bus_us: Option<u64>,
    /// Time the whole bus was asleep so far, µs.
    asleep_us: u64,
}

impl Presence {
    /// The routine for `node`'s cyclic messages.
    pub fn new(node: Node) -> Self {
        let tracked = MESSAGES
            .iter()
            .filter(|m| m.senders.first() == Some(&node) && m.cycle_time_ms > 0)
            .map(|m| Tracked {
                id: m.id,
                name: m.name,
                period_us: u64::from(m.cycle_time_ms) * 1000,
                count: 0,
                first_us: None,
                last_us: None,
                longest_gap_periods: 0.0,
                longest_gap: None,
                asleep_at_last_us: 0,
            })
            .collect();
        Self {
            node,
            tracked,
            last_response_us: None,
            last_bus_us: None,
            asleep_us: 0,
        }
    }

    fn is_response_of_node(&self, id: u32) -> bool {
        u16::try_from(id).is_ok_and(|id| self.node.diag_response_id() == Some(id))
    }

    fn explained(&self, from_us: u64) -> bool {
        self.last_response_us
            .is_some_and(|d| d + DIAG_EXPLAINS_US >= from_us)
    }
}

impl Routine for Presence {
    fn ecu(&self) -> Node {
        self.node
    }

    fn on_frame(&mut self, frame: &LogFrame, update: Update, _state: &CarState) {
        if let Some(last) = self.last_bus_us {
            let silence = frame.t_us.saturating_sub(last);
            if silence >= BUS_ASLEEP_US {
                self.asleep_us += silence;
            }
        }
        self.last_bus_us = Some(self.last_bus_us.map_or(frame.t_us, |l| l.max(frame.t_us)));
        match update {
            Update::Diagnostic if self.is_response_of_node(frame.id) => {
                self.last_response_us = Some(frame.t_us);
            }
            Update::Message { index, .. } => {
                // Most frames are another ECU's: one comparison turns them away.
                if MESSAGES[index].senders.first() != Some(&self.node) {
                    return;
                }
                let id = MESSAGES[index].id;
                let Some(i) = self.tracked.iter().position(|t| t.id == id) else {
                    return;
                };
                let t_us = frame.t_us;
                if let Some(last) = self.tracked[i].last_us {
                    let asleep = self.asleep_us - self.tracked[i].asleep_at_last_us;
                    let gap = t_us.saturating_sub(last).saturating_sub(asleep);
                    let periods = gap as f64 / self.tracked[i].period_us as f64;
                    let track = &self.tracked[i];
                    if periods > track.longest_gap_periods
                        && periods > GAP_SUSPECT_PERIODS
                        && !self.explained(last)
                    {
                        let track = &mut self.tracked[i];
                        track.longest_gap_periods = periods;
                        track.longest_gap = Some(Window {
                            from_us: last,
                            to_us: t_us,
                        });
                    }
                }
                let track = &mut self.tracked[i];
                track.count += 1;
                track.asleep_at_last_us = self.asleep_us;
                track.first_us.get_or_insert(t_us);
                track.last_us = Some(track.last_us.map_or(t_us, |l| l.max(t_us)));
            }
            _ => {}
        }
    }

    fn findings(&self, state: &CarState) -> Vec<Finding> {
        let now = state.now_us();
        let finding = |verdict, value, window, evidence| Finding {
            routine: ROUTINE,
            verdict,
            value,
            unit: "periods",
            suspect_above: GAP_SUSPECT_PERIODS,
            faulty_above: GAP_FAULTY_PERIODS,
            window,
            evidence,
        };
        let names = || {
            self.tracked
                .iter()
                .map(|t| t.name)
                .collect::<Vec<_>>()
                .join(", ")
        };
        if self.tracked.iter().all(|t| t.count == 0) {
            return vec![finding(
                Verdict::NoData,
                None,
                None,
                format!("none of its messages ({}) was received", names()),
            )];
        }
        let silent_since = self
            .tracked
            .iter()
            .map(|t| t.last_us.unwrap_or(0))
            .max()
            .unwrap_or(0);
        let all_silent = self.tracked.iter().all(|t| {
            t.last_us.is_none_or(|l| {
                now.saturating_sub(l) as f64 > GAP_SUSPECT_PERIODS * t.period_us as f64
            })
        });
        if all_silent && !self.explained(silent_since) {
            return vec![finding(
                Verdict::NoData,
                None,
                Some(Window {
                    from_us: silent_since,
                    to_us: now,
                }),
                format!(
                    "its messages ({}) stopped at {:.2} s",
                    names(),
                    silent_since as f64 * 1e-6
                ),
            )];
        }
        // A message absent since the ECU's first frame counts once that is longer than
        // the faulty gap; a short log cannot tell.
        let first_heard = self
            .tracked
            .iter()
            .filter_map(|t| t.first_us)
            .min()
            .unwrap_or(now);
        if let Some(missing) = self.tracked.iter().find(|t| {
            t.count == 0
                && now.saturating_sub(first_heard) as f64 > GAP_FAULTY_PERIODS * t.period_us as f64
        }) {
            return vec![finding(
                Verdict::Faulty,
                None,
                None,
                format!(
                    "{} (0x{:03X}) never received while its other messages were",
                    missing.name, missing.id
                ),
            )];
        }
        let worst = self
            .tracked
            .iter()
            .max_by(|a, b| a.longest_gap_periods.total_cmp(&b.longest_gap_periods));
        let Some(worst) = worst.filter(|w| w.longest_gap.is_some()) else {
            return vec![finding(
                Verdict::Ok,
                Some(0.0),
                None,
                format!("{} all present, no gap over 3 periods", names()),
            )];
        };
        let value = worst.longest_gap_periods;
        vec![finding(
            Verdict::of(value, GAP_SUSPECT_PERIODS, GAP_FAULTY_PERIODS),
            Some(value),
            worst.longest_gap,
            format!(
                "{} missed {:.1} periods of {} ms with no diagnostic session to explain it",
                worst.name,
                value,
                worst.period_us / 1000
            ),
        )]
    }
}
