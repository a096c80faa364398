//! AutoPlug's fleet service, the manufacturer's side of recall management: what each
//! vehicle carries (its VIN and every ECU's identity), what its drives showed (trips,
//! diagnostic verdicts, trouble codes), and the recall queries that find exactly the
//! affected vehicles with the evidence for each.
//!
//! The data lives in PostgreSQL (a server any number of stateless fleet services share)
//! or, on one machine, in an SQLite file: one schema, one set of statements, versioned
//! migrations for both ([`migrations`]).
//!
//! The protocol both sides speak is here (topics, reports, campaigns, the MQTT link and the
//! outbox that keeps a report until its receipt); the vehicle's side, the campaign agent and
//! the gateway's link, is `autoplug-fleet-agent`, so that the service links neither the
//! gateway nor the tester.

pub mod broker;
pub mod campaign;
pub mod campaigns;
pub mod db;
pub mod ingest;
pub mod migrations;
pub mod mqtt;
pub mod nats;
pub mod nats_cluster;
pub mod outbox;
pub mod report;
pub mod service;
pub mod store;
pub mod testing;
pub mod topics;

pub use report::{InventoryReport, Receipt, ReportError, TripReport};
pub use store::{
    Evidence, EvidenceHit, EvidenceQuery, Finding, FleetStore, FleetSummary, InventoryHit,
    InventoryQuery, StoreError, Stored,
};

/// Milliseconds since the Unix epoch, now (0 if the clock is before it).
pub(crate) fn unix_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}
