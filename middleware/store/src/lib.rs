//! The gateway's persistent store: its trips and the identity of each vehicle's ECUs.
//!
//! # What it stores
//!
//! - **Trips** (from `autoplug-trips`): the vehicle and where the frames came from, when the
//!   trip started, its statistics ([`TripStats`](autoplug_trips::TripStats)), why it ended
//!   ([`TripEnd`](autoplug_trips::TripEnd)), the diagnostic routines' verdicts
//!   ([`VerdictRecord`]), the trouble codes read from the ECUs ([`DtcRecord`]), and a
//!   downsampled series of every signal for plots
//!   ([`SeriesPoint`](autoplug_trips::SeriesPoint)).
//! - **ECU inventory**: each ECU's part number, software, hardware and serial number as read
//!   over UDS ([`EcuIdentity`]), with history: a reflash shows as a new software version,
//!   with the date it was first seen.
//!
//! [`TripStore`] is the interface (object-safe, for a server database later);
//! [`SqliteStore`] the gateway's SQLite file.
//!
//! # The schema
//!
//! Versioned: the file's `user_version` is the number of migrations it has run
//! ([`SCHEMA_VERSION`] is the newest this program knows), its `application_id` says it is
//! AutoPlug's. Opening a file runs the migrations it lacks; a file of a newer schema, or
//! another program's, is refused rather than used. Version 1:
//!
//! | table | holds |
//! | --- | --- |
//! | `vehicles` | one row per VIN or name |
//! | `trips` | one row per trip: vehicle, source, start, status (`open`, `closed`, `interrupted`), end, and every `TripStats` field as its own column |
//! | `trip_verdicts`, `trip_dtcs` | a closed trip's verdicts and trouble codes, in order |
//! | `signals`, `trip_series` | the VSS paths once, and the series points keyed by (trip, signal, time) |
//! | `ecu_inventory` | history: a row per identity an ECU of a vehicle has shown, first and last seen |
//! | `ecu_current` (view) | each ECU's newest row: "which vehicles carry part X / software Y" |
//!
//! A NaN is stored as NULL (SQLite has no NaN) and read back as NaN. The SQL is in
//! `src/schema/v1.sql`.
//!
//! # Why WAL
//!
//! The file is in write-ahead-log mode (`journal_mode=WAL`, `synchronous=NORMAL`): a commit
//! appends to the log instead of rewriting pages, so the checkpoint a live gateway writes
//! every few seconds is cheap, and readers (a trip list, a plot, another process) read a
//! consistent snapshot while the gateway writes, neither blocking the other. A busy timeout
//! ([`BUSY_TIMEOUT`]) makes writers of several processes take turns.
//!
//! # After a crash
//!
//! Every write ([`TripStore::begin_trip`], each [`TripStore::checkpoint_trip`],
//! [`TripStore::finish_trip`], [`TripStore::record_inventory`]) is one transaction: a
//! gateway killed at any moment (kill -9, a crash) leaves the file consistent and loses only
//! the transaction it was writing; a power cut may lose the last few commits too
//! (`synchronous=NORMAL`), never consistency.
//!
//! A trip the dead gateway was writing is still `open` in the file. The next
//! [`SqliteStore::open`] marks it [`TripStatus::Interrupted`]: its statistics and series are
//! those of its last checkpoint, and it has no end, verdicts or codes. Only if no other
//! store has the file open, though: each open store holds a shared lock on `<file>-lock`,
//! and open trips are only abandoned when nobody else holds it.
//!
//! A new file is built beside its path and linked into place complete, so a crash while
//! creating it never leaves an empty or half-built database.
#![deny(missing_docs)]
#![forbid(unsafe_code)]

mod error;
mod model;
mod schema;
mod sqlite;
mod store;

pub use error::{StoreError, StoreErrorKind};
pub use model::{
    DtcRecord, EcuIdentity, FinishedTrip, NewTrip, TripDetail, TripId, TripRow, TripStatus,
    VerdictRecord,
};
pub use schema::{APPLICATION_ID, SCHEMA_VERSION};
pub use sqlite::{SqliteStore, BUSY_TIMEOUT};
pub use store::TripStore;
