//! AutoPlug's fleet service, the manufacturer's side of recall management: what each
//! vehicle carries (its VIN and every ECU's identity), what its drives showed (trips,
//! diagnostic verdicts, trouble codes), and the recall queries that find exactly the
//! affected vehicles with the evidence for each.
//!
//! The data lives in PostgreSQL (a server any number of stateless fleet services share)
//! or, on one machine, in an SQLite file: one schema, one set of statements, versioned
//! migrations for both ([`migrations`]).
//!
//! The vehicle's side is here too: the campaign agent ([`vehicle`], sans-IO), its outbox
//! ([`outbox`]) and the gateway's link that runs them against MQTT and the car's tester
//! ([`link`]).

pub mod broker;
pub mod campaign;
pub mod campaigns;
pub mod db;
pub mod ingest;
pub mod link;
pub mod migrations;
pub mod mqtt;
pub mod outbox;
pub mod report;
pub mod service;
pub mod store;
pub mod testing;
pub mod topics;
pub mod vehicle;

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
