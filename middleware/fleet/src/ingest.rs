//! The fleet service's intake: vehicles' reports from the broker into the store.
//!
//! Every report is checked before anything is written: its topic names a vehicle and a
//! kind, the payload is at most [`MAX_REPORT_BYTES`], parses, and names the same VIN as
//! the topic (the broker's ACL lets a vehicle publish only under its own VIN, so a payload
//! naming another is refused rather than trusted). A report is acknowledged to the broker
//! only once it is stored (manual acks): a service that dies mid-way leaves it with the
//! broker for the next one. A bad report is acknowledged too, counted and kept among the
//! last rejections, so it cannot come back for ever.
//!
//! After the commit (or the refusal) the vehicle gets a [`Receipt`] on its receipt topic:
//! it keeps the report until then and publishes it again meanwhile ([`crate::outbox`]), so
//! a report the broker acknowledged and then lost still arrives. Each refusal is also a
//! notice for the operator as it happens, [`REFUSALS_SHOWN`] per [`REFUSAL_WINDOW`] at most
//! and the rest counted, so a car whose reports are refused is seen at once.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use crate::mqtt::{Message, MqttLink};
use crate::nats::WorkQueue;
use crate::report::{InventoryReport, Receipt, TripReport, MAX_REPORT_BYTES};
use crate::store::{FleetStore, StoreError, Stored};
use crate::topics::{self, ReportKind};

/// Rejections kept for the report.
pub const KEPT_REJECTIONS: usize = 20;

/// Refusals shown as notices per [`REFUSAL_WINDOW`]; the rest are counted in one notice.
pub const REFUSALS_SHOWN: u32 = 5;
/// See [`REFUSALS_SHOWN`].
pub const REFUSAL_WINDOW: Duration = Duration::from_secs(10);

/// What the intake did so far.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct IngestStats {
    /// Inventories stored.
    pub inventories: u64,
    /// Trips stored.
    pub trips: u64,
    /// Trips that were there already (a redelivery).
    pub duplicates: u64,
    /// Campaign reports stored.
    pub campaign_reports: u64,
    /// Reports refused.
    pub rejected: u64,
    /// The last refusals, newest last.
    pub last_rejections: VecDeque<String>,
    /// Database errors retried.
    pub db_retries: u64,
    /// Transactions committed (a batch of reports each).
    pub commits: u64,
}

/// What a report came to.
#[derive(Clone, Debug, PartialEq)]
pub enum Handled {
    /// An inventory; the ECUs whose identity changed.
    Inventory(Vec<String>),
    /// A trip, new or a duplicate.
    Trip(Stored),
    /// A campaign report.
    Campaign,
}

/// Why a report was not stored.
#[derive(Clone, Debug, PartialEq)]
pub enum Refused {
    /// The report is bad: it will never be stored.
    Invalid(String),
    /// The database failed: the same report may be stored later.
    Db(String),
}

impl std::fmt::Display for Refused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Refused::Invalid(e) | Refused::Db(e) => f.write_str(e),
        }
    }
}

fn from_store(e: StoreError) -> Refused {
    match e {
        StoreError::Db(e) => Refused::Db(e.to_string()),
        StoreError::Invalid(e) => Refused::Invalid(e),
    }
}

/// A report read and checked, not yet stored.
#[derive(Debug)]
pub enum Parsed {
    /// An inventory.
    Inventory(InventoryReport),
    /// A trip (its figures checked).
    Trip(TripReport),
    /// A report on a campaign.
    Campaign(crate::campaign::CampaignReport),
}

/// Reads and checks one report without writing anything (see the module docs).
pub fn parse(topic: &str, payload: &[u8]) -> Result<Parsed, Refused> {
    let (vin, kind) = topics::parse_report(topic).map_err(Refused::Invalid)?;
    if payload.len() > MAX_REPORT_BYTES {
        return Err(Refused::Invalid(format!(
            "{vin}: a {} report of {} bytes (at most {MAX_REPORT_BYTES})",
            kind.name(),
            payload.len()
        )));
    }
    let same_vin = |named: &str| {
        if named == vin.as_str() {
            Ok(())
        } else {
            Err(Refused::Invalid(format!(
                "a {} report naming VIN \"{}\" on {vin}'s topic",
                kind.name(),
                named.chars().take(40).collect::<String>()
            )))
        }
    };
    let parse_error = |e: serde_json::Error| {
        Refused::Invalid(format!(
            "{vin}: a {} report that is not valid: {e}",
            kind.name()
        ))
    };
    match kind {
        ReportKind::Inventory => {
            let report: InventoryReport = serde_json::from_slice(payload).map_err(parse_error)?;
            same_vin(&report.vin)?;
            Ok(Parsed::Inventory(report))
        }
        ReportKind::Trip => {
            let report: TripReport = serde_json::from_slice(payload).map_err(parse_error)?;
            same_vin(&report.vin)?;
            report
                .check()
                .map_err(|e| from_store(StoreError::from(e)))?;
            Ok(Parsed::Trip(report))
        }
        ReportKind::Campaign => {
            let report: crate::campaign::CampaignReport =
                serde_json::from_slice(payload).map_err(parse_error)?;
            same_vin(&report.vin)?;
            Ok(Parsed::Campaign(report))
        }
    }
}

/// Stores one report read by [`parse`], in a transaction of its own (a savepoint inside a
/// batch's).
pub fn store(store: &mut FleetStore, parsed: &Parsed) -> Result<Handled, Refused> {
    match parsed {
        Parsed::Inventory(report) => store
            .record_inventory(report)
            .map(Handled::Inventory)
            .map_err(from_store),
        Parsed::Trip(report) => store
            .record_trip(report)
            .map(Handled::Trip)
            .map_err(from_store),
        Parsed::Campaign(report) => store
            .record_campaign_report(report)
            .map(|()| Handled::Campaign)
            .map_err(from_store),
    }
}

/// Stores one report (see the module docs for the checks).
pub fn handle(store: &mut FleetStore, topic: &str, payload: &[u8]) -> Result<Handled, Refused> {
    let parsed = parse(topic, payload)?;
    self::store(store, &parsed)
}

/// The intake: reports from `link` (subscribed to [`topics::REPORTS_SHARED`] with manual
/// acks), or from the clustered engine's work queue, into `store`.
pub struct Ingest {
    /// The store.
    pub store: FleetStore,
    /// The broker: the reports (without a work queue), the receipts.
    pub link: MqttLink,
    /// The clustered engine's work queue, where the reports come from when there is one.
    pub queue: Option<WorkQueue>,
    /// What it did.
    pub stats: IngestStats,
    /// What an operator should see now (the database failing and back), oldest first;
    /// taken by [`Ingest::take_notices`].
    notices: VecDeque<String>,
    /// Database errors in a row, since the last report stored.
    db_failures: u64,
    /// The refusal notices' window: its start, shown in it, counted and not shown.
    refusal_window: (Instant, u32, u64),
    /// Receipts the connection did not take (the vehicle sends the report again).
    pub receipts_not_sent: u64,
}

/// Most reports stored in one transaction. Mosquitto sends a client at most its
/// `max_inflight_messages` unacknowledged (the shipped configuration: 200), which bounds a
/// batch from that side.
pub const MAX_BATCH: usize = 200;

/// How long a service leaving its group waits for reports the broker sent before the
/// UNSUBSCRIBE (in order on one connection: a pause this long means none are left).
pub const DRAIN_QUIET: Duration = Duration::from_millis(500);

/// The longest a service leaving its group takes for those.
pub const DRAIN_LIMIT: Duration = Duration::from_secs(10);

/// Notices kept until taken (older ones are dropped: the last say most).
const MAX_NOTICES: usize = 64;

/// Longest wait between two tries of a database that fails.
const MAX_DB_BACKOFF: Duration = Duration::from_secs(10);

impl Ingest {
    /// Reports from `link` into `store`.
    pub fn new(store: FleetStore, link: MqttLink) -> Self {
        Self {
            store,
            link,
            queue: None,
            stats: IngestStats::default(),
            notices: VecDeque::new(),
            db_failures: 0,
            refusal_window: (Instant::now(), 0, 0),
            receipts_not_sent: 0,
        }
    }

    /// Reports from the clustered engine's `queue` into `store`; receipts over `link`.
    pub fn with_queue(store: FleetStore, link: MqttLink, queue: WorkQueue) -> Self {
        let mut ingest = Self::new(store, link);
        ingest.queue = Some(queue);
        ingest
    }

    /// Acknowledges a message where it came from.
    fn ack(&self, message: &Message) {
        match &self.queue {
            Some(queue) if matches!(message.ack, crate::mqtt::Ack::JetStream(_)) => {
                let _ = queue.ack(message);
            }
            _ => {
                let _ = self.link.ack(message);
            }
        }
    }

    /// Tells the work queue that `messages` are still being stored (a database that
    /// fails), so it does not hand them to another service meanwhile.
    fn still_at(&self, messages: &[Message]) {
        if let Some(queue) = &self.queue {
            for message in messages {
                let _ = queue.in_progress(message);
            }
        }
    }

    /// The notices for the operator since the last call, oldest first.
    pub fn take_notices(&mut self) -> Vec<String> {
        self.roll_refusal_window();
        self.notices.drain(..).collect()
    }

    /// A window over: the refusals it did not show, in one notice.
    fn roll_refusal_window(&mut self) {
        let (start, _, hidden) = self.refusal_window;
        if start.elapsed() < REFUSAL_WINDOW {
            return;
        }
        self.refusal_window = (Instant::now(), 0, 0);
        if hidden > 0 {
            self.notice(format!(
                "refused {hidden} more reports in the last {} s ({} refused since start)",
                REFUSAL_WINDOW.as_secs(),
                self.stats.rejected
            ));
        }
    }

    fn refusal_notice(&mut self, topic: &str, reason: &str) {
        self.roll_refusal_window();
        let (_, shown, hidden) = &mut self.refusal_window;
        if *shown < REFUSALS_SHOWN {
            *shown += 1;
            let total = self.stats.rejected;
            let what = match topics::parse_report(topic) {
                Ok((vin, kind)) => format!("a {} report of {vin}", kind.name()),
                Err(_) => "a message that is not a report".to_string(),
            };
            self.notice(format!("refused {what} ({total} since start): {reason}"));
        } else {
            *hidden += 1;
        }
    }

    /// Tells the vehicle of `message` that its report is done with (stored, or refused
    /// for `refused`); a topic that names no vehicle gets none.
    fn receipt(&mut self, message: &Message, refused: Option<String>) {
        let Ok((vin, _)) = topics::parse_report(&message.topic) else {
            return;
        };
        let receipt = Receipt::of(&message.payload, refused);
        let sent = match &self.queue {
            // On the clustered engine through NATS itself (see `WorkQueue::publish_now`).
            Some(queue) => queue
                .publish_now(&topics::receipt(&vin), receipt.to_json())
                .is_ok(),
            None => self
                .link
                .publish_waiting(&topics::receipt(&vin), receipt.to_json(), false)
                .is_ok(),
        };
        if !sent {
            self.receipts_not_sent += 1;
        }
    }

    fn notice(&mut self, text: String) {
        if self.notices.len() >= MAX_NOTICES {
            self.notices.pop_front();
        }
        self.notices.push_back(text);
    }

    /// Handles one message: stored and acknowledged, or refused and acknowledged; a
    /// database error is retried (with a backoff) until it stores or `stop` is set, and
    /// the message is then left unacknowledged for the broker to deliver again.
    pub fn take(&mut self, message: &Message, stop: &AtomicBool) -> Option<Handled> {
        let mut backoff = Duration::from_millis(50);
        loop {
            match handle(&mut self.store, &message.topic, &message.payload) {
                Ok(handled) => {
                    self.db_answers();
                    self.stats.commits += 1;
                    return self.settle(message, Ok(handled));
                }
                Err(Refused::Invalid(reason)) => return self.settle(message, Err(reason)),
                Err(Refused::Db(error)) => {
                    self.db_failed(&error);
                    if stop.load(Ordering::Relaxed) {
                        return None;
                    }
                    self.still_at(std::slice::from_ref(message));
                    std::thread::sleep(backoff);
                    backoff = (backoff * 2).min(MAX_DB_BACKOFF);
                }
            }
        }
    }

    /// The reports waiting now, at most [`MAX_BATCH`], waiting at most `wait` for the
    /// first: under load a batch fills from what the broker already sent, and a lone
    /// report is never held back for company.
    pub fn recv_batch(&mut self, wait: Duration) -> Vec<Message> {
        if let Some(queue) = &mut self.queue {
            let batch = queue.recv_batch(wait, MAX_BATCH);
            let said: Vec<String> = std::iter::from_fn(|| queue.take_notice()).collect();
            for notice in said {
                self.notice(notice);
            }
            return batch;
        }
        let Some(first) = self.link.recv_timeout(wait) else {
            return Vec::new();
        };
        let mut batch = vec![first];
        while batch.len() < MAX_BATCH {
            match self.link.try_recv() {
                Some(message) => batch.push(message),
                None => break,
            }
        }
        batch
    }

    /// Handles a batch of messages in one transaction, each report in a savepoint of its
    /// own (a refused one undoes only its own writes); once it commits, each gets its
    /// receipt and is acknowledged, in the order received (MQTT's order for
    /// acknowledgements). A database error rolls the whole batch back and tries it again
    /// (with a backoff) until it stores or `stop` is set; it then stays unacknowledged for
    /// the broker to deliver again. The batch's trips are written first, in (VIN, trip)
    /// order, then its other reports in their vehicles' order, so two services' batches
    /// mostly take rows in one order; where they still wait on each other in a circle
    /// (an inventory and a trip of two vehicles crossing), PostgreSQL ends one
    /// transaction with a deadlock error, and that batch is tried again like any other
    /// database error.
    pub fn take_batch(&mut self, messages: &[Message], stop: &AtomicBool) -> Vec<Option<Handled>> {
        if messages.len() == 1 {
            return vec![self.take(&messages[0], stop)];
        }
        let mut order: Vec<usize> = (0..messages.len()).collect();
        order.sort_by(|&a, &b| messages[a].topic.cmp(&messages[b].topic));
        let mut backoff = Duration::from_millis(50);
        let outcomes = loop {
            match self.store_batch(messages, &order) {
                Ok(outcomes) => break outcomes,
                Err(error) => {
                    self.db_failed(&error);
                    if stop.load(Ordering::Relaxed) {
                        return vec![None; messages.len()];
                    }
                    self.still_at(messages);
                    std::thread::sleep(backoff);
                    backoff = (backoff * 2).min(MAX_DB_BACKOFF);
                }
            }
        };
        self.db_answers();
        messages
            .iter()
            .zip(outcomes)
            .map(|(message, outcome)| self.settle(message, outcome))
            .collect()
    }

    /// Writes `messages` (in `order`) in one transaction: each one's outcome, or the
    /// database's error (the transaction then rolled back).
    fn store_batch(
        &mut self,
        messages: &[Message],
        order: &[usize],
    ) -> Result<Vec<Result<Handled, String>>, String> {
        let db_error = |e: crate::db::DbError| e.to_string();
        let parsed: Vec<Result<Parsed, Refused>> = messages
            .iter()
            .map(|m| parse(&m.topic, &m.payload))
            .collect();
        let mut outcomes: Vec<Result<Handled, String>> = parsed
            .iter()
            .map(|p| match p {
                Err(refused) => Err(refused.to_string()),
                Ok(_) => Ok(Handled::Campaign),
            })
            .collect();
        self.store.db().begin().map_err(db_error)?;
        // The trips together (most of what arrives), in (VIN, trip) order.
        let mut trips: Vec<(usize, &TripReport)> = parsed
            .iter()
            .enumerate()
            .filter_map(|(i, p)| match p {
                Ok(Parsed::Trip(t)) => Some((i, t)),
                _ => None,
            })
            .collect();
        trips.sort_by(|a, b| (a.1.vin.as_str(), a.1.trip).cmp(&(b.1.vin.as_str(), b.1.trip)));
        let reports: Vec<&TripReport> = trips.iter().map(|(_, t)| *t).collect();
        match self.store.record_trips_in_batch(&reports) {
            Ok(stored) => {
                for ((i, _), stored) in trips.iter().zip(stored) {
                    outcomes[*i] = Ok(Handled::Trip(stored));
                }
            }
            Err(e) => {
                let _ = self.store.db().rollback();
                return Err(from_store(e).to_string());
            }
        }
        // The rest one by one, each in a savepoint, in their vehicles' order.
        for &i in order {
            let Ok(report) = &parsed[i] else { continue };
            if matches!(report, Parsed::Trip(_)) {
                continue;
            }
            match store(&mut self.store, report) {
                Ok(handled) => outcomes[i] = Ok(handled),
                Err(Refused::Invalid(reason)) => outcomes[i] = Err(reason),
                Err(Refused::Db(error)) => {
                    let _ = self.store.db().rollback();
                    return Err(error);
                }
            }
        }
        self.store.db().commit().map_err(db_error)?;
        self.stats.commits += 1;
        // When the batch's vehicles were last seen, outside its transaction (see
        // `FleetStore::record_trips_in_batch`); a failure here loses nothing stored (the
        // next report of the vehicle writes it).
        let vins: Vec<&str> = {
            let set: std::collections::BTreeSet<&str> =
                reports.iter().map(|r| r.vin.as_str()).collect();
            set.into_iter().collect()
        };
        let _ = self.store.touch_vehicles(&vins, crate::unix_ms());
        Ok(outcomes)
    }

    /// A database error: said once until it answers again, counted each time.
    fn db_failed(&mut self, error: &str) {
        if self.db_failures == 0 {
            self.notice(format!(
                "the database failed ({error}): reports stay unacknowledged and are tried again, at most every {} s",
                MAX_DB_BACKOFF.as_secs()
            ));
        }
        self.db_failures += 1;
        self.stats.db_retries += 1;
    }

    /// The database stored again after failing.
    fn db_answers(&mut self) {
        if self.db_failures > 0 {
            let tries = std::mem::take(&mut self.db_failures);
            self.notice(format!(
                "the database answers again, after {tries} failed tries: storing"
            ));
        }
    }

    /// A stored or refused report counted, its receipt sent and the message acknowledged.
    fn settle(&mut self, message: &Message, outcome: Result<Handled, String>) -> Option<Handled> {
        match outcome {
            Ok(handled) => {
                match &handled {
                    Handled::Inventory(_) => self.stats.inventories += 1,
                    Handled::Trip(Stored::New) => self.stats.trips += 1,
                    Handled::Trip(Stored::Duplicate) => self.stats.duplicates += 1,
                    Handled::Campaign => self.stats.campaign_reports += 1,
                }
                self.receipt(message, None);
                self.ack(message);
                Some(handled)
            }
            Err(reason) => {
                self.stats.rejected += 1;
                if self.stats.last_rejections.len() >= KEPT_REJECTIONS {
                    self.stats.last_rejections.pop_front();
                }
                self.stats.last_rejections.push_back(reason.clone());
                self.refusal_notice(&message.topic, &reason);
                self.receipt(message, Some(reason));
                self.ack(message);
                None
            }
        }
    }

    /// Leaves the shared group `subscription` and stores what the broker had sent before
    /// it took the UNSUBSCRIBE, until none has come for `quiet` (at most
    /// [`DRAIN_LIMIT`]): a service stopped cleanly leaves nothing for the cars to send
    /// again. Returns how many it took (a database that fails now leaves those to the
    /// cars' resends).
    pub fn leave(&mut self, subscription: &str, quiet: Duration) -> usize {
        // A service of the work queue holds nothing between batches.
        if self.queue.is_some() {
            return 0;
        }
        if subscription.is_empty() || self.link.unsubscribe(subscription).is_err() {
            return 0;
        }
        let started = Instant::now();
        // Stopping: a database that fails now is not waited for (those reports come
        // again from the cars).
        let stopping = AtomicBool::new(true);
        let mut taken = 0;
        while started.elapsed() < DRAIN_LIMIT {
            let batch = self.recv_batch(quiet);
            if batch.is_empty() {
                break;
            }
            taken += batch.len();
            self.take_batch(&batch, &stopping);
        }
        taken
    }

    /// Takes reports until `stop` is set; `wait` is the longest wait for one.
    pub fn run(&mut self, stop: &AtomicBool, wait: Duration, mut each: impl FnMut(&Self)) {
        while !stop.load(Ordering::Relaxed) {
            let batch = self.recv_batch(wait);
            if !batch.is_empty() {
                self.take_batch(&batch, stop);
            }
            each(self);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn message(topic: &str, payload: &[u8]) -> Message {
        Message::unacknowledged(topic, payload)
    }

    #[test]
    fn refusals_are_notices_as_they_happen_five_a_window_and_the_rest_counted() {
        let dir = tempfile::tempdir().unwrap();
        let store = FleetStore::open(&dir.path().join("fleet.db").display().to_string()).unwrap();
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .enable_all()
            .build()
            .unwrap();
        // Nothing listens on port 9: acknowledgements and receipts go nowhere, which the
        // intake survives.
        let link = MqttLink::connect(
            runtime.handle(),
            &"mqtt://127.0.0.1:9".parse().unwrap(),
            crate::mqtt::LinkOptions::new("refusal-test"),
        );
        let mut ingest = Ingest::new(store, link);
        let stop = AtomicBool::new(false);
        let topic = "autoplug/v1/vehicles/JA3AP47H0YF000042/report/trip";
        ingest.take(&message(topic, b"{not json"), &stop);
        // At once, naming the car, the kind and why.
        let notices = ingest.take_notices();
        assert_eq!(notices.len(), 1, "{notices:?}");
        assert!(
            notices[0].contains("refused a trip report of JA3AP47H0YF000042 (1 since start)")
                && notices[0].contains("not valid"),
            "{notices:?}"
        );
        for _ in 0..9 {
            ingest.take(&message(topic, b"[]"), &stop);
        }
        // Four more shown in this window, five counted.
        assert_eq!(ingest.take_notices().len(), 4);
        ingest.refusal_window.0 -= REFUSAL_WINDOW;
        let notices = ingest.take_notices();
        assert_eq!(notices.len(), 1, "{notices:?}");
        assert!(
            notices[0].contains("refused 5 more reports in the last 10 s (10 refused since start)"),
            "{notices:?}"
        );
        assert_eq!(ingest.stats.rejected, 10);
    }
}
