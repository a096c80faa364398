//! The vehicle's reports on their way to the fleet, kept until the fleet's receipt says
//! each is stored ([`Receipt`]), and published again while none comes.
//!
//! Why not trust the broker's acknowledgement: MQTT's PUBACK says the broker queued the
//! report, not that a service stored it. Mosquitto 2.0 does not restore a shared
//! subscription from its persistence, so after a broker restart the reports that cars
//! publish before the services have subscribed again are acknowledged and dropped (120 of
//! 300 stored in the test that found it); a client that loses its session drops its
//! unsent publishes too. An end-to-end receipt covers every such loss at once: the fleet
//! stores a report sent twice once (trips by their number, inventories and campaign
//! reports by their time), so sending again is always safe.
//!
//! Sans-IO, on a clock the caller gives: the gateway drives it from its poll, the tests
//! from plain values.

use std::collections::VecDeque;

use crate::report::Receipt;

/// First wait for a report's receipt before it is published again, ms.
pub const RESEND_AFTER_MS: i64 = 30_000;
/// Longest wait between two publishes of one report, ms (the wait doubles each time).
pub const MAX_RESEND_AFTER_MS: i64 = 10 * 60_000;

struct Pending {
    topic: String,
    payload: Vec<u8>,
    /// SHA-256 of the payload, hex: what the receipt names.
    id: String,
    /// When it is to be published (again), ms; `None`: now.
    next_ms: Option<i64>,
    /// The wait after the next publish.
    wait_ms: i64,
    /// Times published.
    sent: u32,
    /// When it was first published, ms.
    first_sent_ms: Option<i64>,
}

/// What a receipt said.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Confirmed {
    /// The report on `topic` is stored.
    Stored {
        /// Its topic.
        topic: String,
    },
    /// The fleet refused the report on `topic` for good: why.
    Refused {
        /// Its topic.
        topic: String,
        /// The fleet's reason.
        reason: String,
    },
}

/// The reports not yet confirmed, oldest first (see the module docs).
pub struct Outbox {
    pending: VecDeque<Pending>,
    capacity: usize,
    resend_after_ms: i64,
    /// Reports dropped unconfirmed because the outbox was full (the oldest go first).
    pub dropped: u64,
    /// Publishes of a report that had been published before.
    pub resent: u64,
    /// Reports the fleet confirmed stored.
    pub stored: u64,
    /// Reports the fleet refused.
    pub refused: u64,
}

impl Outbox {
    /// An outbox of at most `capacity` reports, each published again `resend_after_ms`
    /// after its last publish while no receipt came (doubling up to
    /// [`MAX_RESEND_AFTER_MS`]).
    pub fn new(capacity: usize, resend_after_ms: i64) -> Self {
        Self {
            pending: VecDeque::new(),
            capacity: capacity.max(1),
            resend_after_ms: resend_after_ms.max(1),
            dropped: 0,
            resent: 0,
            stored: 0,
            refused: 0,
        }
    }

    /// Reports waiting for their receipt (published or not yet).
    pub fn len(&self) -> usize {
        self.pending.len()
    }

    /// Whether every report is confirmed.
    pub fn is_empty(&self) -> bool {
        self.pending.is_empty()
    }

    /// Reports never published yet.
    pub fn unsent(&self) -> usize {
        self.pending.iter().filter(|p| p.sent == 0).count()
    }

    /// A report to send.
    pub fn push(&mut self, topic: String, payload: Vec<u8>) {
        if self.pending.len() >= self.capacity {
            self.pending.pop_front();
            self.dropped += 1;
        }
        let id = crate::campaign::sha256_hex(&payload);
        self.pending.push_back(Pending {
            topic,
            payload,
            id,
            next_ms: None,
            wait_ms: self.resend_after_ms,
            sent: 0,
            first_sent_ms: None,
        });
    }

    /// Publishes what is due at `now_ms`, oldest first, through `publish` (which says
    /// whether the connection took it; the first it does not take ends the round, so the
    /// order holds).
    pub fn send_due(&mut self, now_ms: i64, mut publish: impl FnMut(&str, &[u8]) -> bool) {
        for p in self.pending.iter_mut() {
            if p.next_ms.is_some_and(|t| t > now_ms) {
                continue;
            }
            if !publish(&p.topic, &p.payload) {
                return;
            }
            if p.sent > 0 {
                self.resent += 1;
            }
            p.first_sent_ms.get_or_insert(now_ms);
            p.sent += 1;
            p.next_ms = Some(now_ms.saturating_add(p.wait_ms));
            p.wait_ms = (p.wait_ms.saturating_mul(2)).min(MAX_RESEND_AFTER_MS);
        }
    }

    /// A receipt from the fleet: the report it names is done with. `Ok(None)` for a
    /// receipt of a report no longer here (it was sent twice, and both were confirmed).
    pub fn on_receipt(&mut self, payload: &[u8]) -> Result<Option<Confirmed>, String> {
        Ok(self
            .on_receipt_at(payload, 0)?
            .map(|(confirmed, _)| confirmed))
    }

    /// [`Self::on_receipt`] at `now_ms`, with how long the report waited for its receipt
    /// since it was first published, ms (what a fleet's latency is to its cars).
    pub fn on_receipt_at(
        &mut self,
        payload: &[u8],
        now_ms: i64,
    ) -> Result<Option<(Confirmed, i64)>, String> {
        let receipt = Receipt::parse(payload)?;
        let Some(i) = self.pending.iter().position(|p| p.id == receipt.report) else {
            return Ok(None);
        };
        let Some(done) = self.pending.remove(i) else {
            return Ok(None);
        };
        let waited_ms = done.first_sent_ms.map_or(0, |t| now_ms.saturating_sub(t));
        let confirmed = match receipt.refused {
            None => {
                self.stored += 1;
                Confirmed::Stored { topic: done.topic }
            }
            Some(reason) => {
                self.refused += 1;
                Confirmed::Refused {
                    topic: done.topic,
                    reason,
                }
            }
        };
        Ok(Some((confirmed, waited_ms)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sent_at(outbox: &mut Outbox, now_ms: i64) -> Vec<String> {
        let mut out = Vec::new();
        outbox.send_due(now_ms, |topic, _| {
            out.push(topic.to_string());
            true
        });
        out
    }

    #[test]
    fn a_receipt_says_how_long_the_report_waited_since_its_first_publish() {
        let mut outbox = Outbox::new(8, 1_000);
        outbox.push("a".into(), b"report a".to_vec());
        sent_at(&mut outbox, 5_000);
        // Sent again after a second: the wait still counts from the first publish.
        sent_at(&mut outbox, 6_000);
        let stored = Receipt::of(b"report a", None).to_json();
        assert_eq!(
            outbox.on_receipt_at(&stored, 6_250),
            Ok(Some((Confirmed::Stored { topic: "a".into() }, 1_250)))
        );
    }

    #[test]
    fn a_report_goes_again_until_its_receipt_comes_and_never_after() {
        let mut outbox = Outbox::new(8, 1_000);
        outbox.push("a".into(), b"report a".to_vec());
        outbox.push("b".into(), b"report b".to_vec());
        assert_eq!(sent_at(&mut outbox, 0), ["a", "b"]);
        assert!(sent_at(&mut outbox, 999).is_empty());
        // No receipt within the wait: both again, then after twice the wait.
        assert_eq!(sent_at(&mut outbox, 1_000), ["a", "b"]);
        assert!(sent_at(&mut outbox, 2_999).is_empty());
        assert_eq!(outbox.resent, 2);
        let stored = Receipt::of(b"report a", None).to_json();
        assert_eq!(
            outbox.on_receipt(&stored),
            Ok(Some(Confirmed::Stored { topic: "a".into() }))
        );
        // A second receipt of the same report (it was stored twice over): nothing left.
        assert_eq!(outbox.on_receipt(&stored), Ok(None));
        assert_eq!(sent_at(&mut outbox, 3_000), ["b"]);
        let refused = Receipt::of(b"report b", Some("bad".into())).to_json();
        assert_eq!(
            outbox.on_receipt(&refused),
            Ok(Some(Confirmed::Refused {
                topic: "b".into(),
                reason: "bad".into()
            }))
        );
        assert!(outbox.is_empty());
        assert!(sent_at(&mut outbox, 1_000_000).is_empty());
        assert_eq!((outbox.stored, outbox.refused), (1, 1));
    }

    #[test]
    fn the_order_holds_when_the_connection_takes_no_more_and_a_full_outbox_drops_the_oldest() {
        let mut outbox = Outbox::new(2, 1_000);
        for name in ["a", "b", "c"] {
            outbox.push(name.into(), name.as_bytes().to_vec());
        }
        assert_eq!((outbox.len(), outbox.dropped), (2, 1));
        let mut taken = 0;
        outbox.send_due(0, |_, _| {
            taken += 1;
            taken == 1
        });
        assert_eq!(outbox.unsent(), 1);
        // The next round sends the one not taken, and not the one taken.
        assert_eq!(sent_at(&mut outbox, 10), ["c"]);
    }

    #[test]
    fn bad_receipts_are_named() {
        let mut outbox = Outbox::new(2, 1_000);
        for (bad, says) in [
            (&b"{"[..], "not a receipt"),
            (b"{\"report\":\"xyz\"}", "not a SHA-256"),
            (&[b' '; 5000][..], "bytes"),
        ] {
            let e = outbox.on_receipt(bad).unwrap_err();
            assert!(e.contains(says), "{e}");
        }
    }
}
