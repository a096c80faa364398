//! The store's interface, whatever database is behind it.

use autoplug_trips::{SeriesPoint, TripStats};

use crate::error::StoreError;
use crate::model::{EcuIdentity, FinishedTrip, NewTrip, TripDetail, TripId, TripRow};

/// A persistent store of trips and of vehicles' ECU inventory.
///
/// Object-safe (`Box<dyn TripStore>`): the gateway's SQLite file is one implementation
/// ([`crate::SqliteStore`]), a fleet server's database can be another.
///
/// A trip is written in three steps: [`begin_trip`](TripStore::begin_trip), then a
/// [`checkpoint_trip`](TripStore::checkpoint_trip) every few seconds while it is under way,
/// then [`finish_trip`](TripStore::finish_trip). Each step is one transaction, so a gateway
/// killed at any moment loses at most the checkpoint it was writing.
pub trait TripStore {
    /// Records a trip that has just started, [`Open`](crate::TripStatus::Open), with
    /// statistics all zero but its start (`start_us`).
    fn begin_trip(&mut self, trip: &NewTrip) -> Result<TripId, StoreError>;

    /// Replaces the statistics of an open trip and adds series points, in one transaction;
    /// the trip stays open.
    ///
    /// `series` is the points not stored yet. A point of a signal and `t_s` already stored
    /// replaces it (the bucket that was still filling at the previous checkpoint may be
    /// sent again, complete).
    ///
    /// Fails if the trip does not exist or is not open.
    fn checkpoint_trip(
        &mut self,
        id: TripId,
        stats: &TripStats,
        series: &[SeriesPoint],
    ) -> Result<(), StoreError>;

    /// Closes an open trip: its final statistics, why it ended, its verdicts and trouble
    /// codes, and its last series points (as in
    /// [`checkpoint_trip`](TripStore::checkpoint_trip)), in one transaction.
    ///
    /// Fails if the trip does not exist or is not open.
    fn finish_trip(
        &mut self,
        id: TripId,
        trip: &FinishedTrip,
        series: &[SeriesPoint],
    ) -> Result<(), StoreError>;

    /// Records the ECUs of `vehicle` read at `seen_at_unix_ms` (wall clock, ms), keeping
    /// history: an ECU whose identity changed since the last one recorded for it gets a new
    /// row (a reflash shows as a new software version, first seen then); an unchanged one
    /// only has its last-seen time moved on.
    ///
    /// An identifier the ECU did not answer (`None`) is not a change: the identity is not
    /// known to differ. If the stored identity lacks it and the ECU now answers, the stored
    /// identity is completed. ECUs not in `ecus` are left as they are.
    fn record_inventory(
        &mut self,
        vehicle: &str,
        seen_at_unix_ms: i64,
        ecus: &[EcuIdentity],
    ) -> Result<(), StoreError>;

    /// The current identity of each ECU of `vehicle`, with when that identity was first
    /// and last seen (ms since the Unix epoch), sorted by ECU. Empty for an unknown vehicle.
    fn inventory(&self, vehicle: &str) -> Result<Vec<(EcuIdentity, i64, i64)>, StoreError>;

    /// The trips, of one vehicle or of all, newest first.
    fn trips(&self, vehicle: Option<&str>) -> Result<Vec<TripRow>, StoreError>;

    /// One trip with its verdicts, trouble codes and the signals it has series of; `None`
    /// if there is no such trip.
    fn trip(&self, id: TripId) -> Result<Option<TripDetail>, StoreError>;

    /// The series points of one signal of a trip, by time. Empty if the trip has none of
    /// that signal; an error if there is no such trip.
    fn series(&self, id: TripId, signal: &str) -> Result<Vec<SeriesPoint>, StoreError>;
}
