//! The fleet service's loop (`autoplug fleet serve`): reports from the broker into the
//! store ([`Ingest`]), and every `tick` the running campaigns moved on, their signed
//! instructions published to the vehicles. Stateless beyond the database: any number of
//! services may run against one PostgreSQL, splitting the reports (shared subscription)
//! and never sending one instruction twice (the campaign rows are locked while ticked).

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use autoplug_image::SigningKey;

use crate::campaign::now_ms;
use crate::ingest::Ingest;

/// The service (see the module docs).
pub struct FleetService {
    /// The intake, with its store and its link.
    pub ingest: Ingest,
    key: Option<SigningKey>,
    tick: Duration,
    last_tick: Option<Instant>,
    /// Instructions published.
    pub sent: u64,
    /// The last error of a campaign tick or a publish, if any.
    pub failure: Option<String>,
}

impl FleetService {
    /// Reports through `ingest`; campaigns signed with `key` (none: nothing is sent) every
    /// `tick`.
    pub fn new(ingest: Ingest, key: Option<SigningKey>, tick: Duration) -> Self {
        Self {
            ingest,
            key,
            tick,
            last_tick: None,
            sent: 0,
            failure: None,
        }
    }

    /// Whether it sends campaigns.
    pub fn sends_campaigns(&self) -> bool {
        self.key.is_some()
    }

    /// One turn: the reports waiting taken in one batch (waiting at most `wait` for one), the campaigns moved on if
    /// their tick is due.
    pub fn step(&mut self, stop: &AtomicBool, wait: Duration) {
        let batch = self.ingest.recv_batch(wait);
        if !batch.is_empty() {
            self.ingest.take_batch(&batch, stop);
        }
        let Some(key) = &self.key else {
            return;
        };
        if self.last_tick.is_some_and(|t| t.elapsed() < self.tick) {
            return;
        }
        self.last_tick = Some(Instant::now());
        match self.ingest.store.campaign_tick(key, now_ms()) {
            Ok(dispatches) => {
                for d in dispatches {
                    match self.ingest.link.publish(&d.topic, d.payload, false) {
                        Ok(()) => self.sent += 1,
                        // The vehicle stays 'sent': its answer time brings a retry.
                        Err(e) => self.failure = Some(e.to_string()),
                    }
                }
            }
            Err(e) => self.failure = Some(e.to_string()),
        }
    }

    /// Turns until `stop` is set.
    pub fn run(&mut self, stop: &AtomicBool) {
        while !stop.load(Ordering::Relaxed) {
            self.step(stop, Duration::from_millis(50));
        }
    }
}
