//! Trips: written in steps, read back whole.

mod common;

use autoplug_store::{
    SqliteStore, StoreErrorKind, TripDetail, TripId, TripRow, TripStatus, TripStore,
};
use autoplug_trips::{TripEnd, TripStats};
use common::*;

fn sorted_by_time(
    mut points: Vec<autoplug_trips::SeriesPoint>,
    signal: &str,
) -> Vec<autoplug_trips::SeriesPoint> {
    points.retain(|p| p.signal == signal);
    points.sort_by(|a, b| a.t_s.total_cmp(&b.t_s));
    points
}

#[test]
fn a_trip_round_trips_through_begin_checkpoints_and_finish() {
    let mut store = SqliteStore::open_in_memory().unwrap();
    let new = new_trip("JMYLNCP6AYJ000042", 1_700_000_000_000);
    let id = store.begin_trip(&new).unwrap();

    let begun = TripRow {
        id,
        vehicle: new.vehicle.clone(),
        source: new.source.clone(),
        started_at_unix_ms: new.started_at_unix_ms,
        status: TripStatus::Open,
        end: None,
        stats: TripStats {
            start_us: new.start_us,
            end_us: new.start_us,
            ..TripStats::default()
        },
    };
    assert_eq!(store.trips(None).unwrap(), vec![begun.clone()]);

    // Two checkpoints: the statistics are replaced, the points added.
    store.checkpoint_trip(id, &stats(1), &points(0, 4)).unwrap();
    store.checkpoint_trip(id, &stats(2), &points(4, 7)).unwrap();
    let open = store.trip(id).unwrap().unwrap();
    assert_eq!(open.row.status, TripStatus::Open);
    assert_eq!(open.row.stats, stats(2));
    assert!(open.verdicts.is_empty() && open.dtcs.is_empty());

    let done = finished(3);
    store.finish_trip(id, &done, &points(7, 9)).unwrap();
    let detail = store.trip(id).unwrap().unwrap();
    assert_eq!(
        detail,
        TripDetail {
            row: TripRow {
                status: TripStatus::Closed,
                end: Some(TripEnd::BusSilent),
                stats: stats(3),
                ..begun
            },
            verdicts: done.verdicts.clone(),
            dtcs: done.dtcs.clone(),
            series_signals: vec![RPM.to_owned(), SPEED.to_owned()],
        }
    );
    for signal in [SPEED, RPM] {
        assert_eq!(
            store.series(id, signal).unwrap(),
            sorted_by_time(points(0, 9), signal),
            "{signal}"
        );
    }
    assert_eq!(store.series(id, "Vehicle.Cabin.Fan").unwrap(), vec![]);
}

#[test]
fn a_bucket_sent_again_replaces_the_stored_one() {
    let mut store = SqliteStore::open_in_memory().unwrap();
    let id = store.begin_trip(&new_trip("car", 0)).unwrap();
    let mut filling = point(SPEED, 1.0);
    filling.max = 10.0;
    store
        .checkpoint_trip(id, &stats(1), &[point(SPEED, 0.5), filling])
        .unwrap();
    let complete = point(SPEED, 1.0);
    store
        .checkpoint_trip(id, &stats(2), std::slice::from_ref(&complete))
        .unwrap();
    assert_eq!(
        store.series(id, SPEED).unwrap(),
        vec![point(SPEED, 0.5), complete]
    );
}

#[test]
fn only_open_trips_can_be_written() {
    let mut store = SqliteStore::open_in_memory().unwrap();
    let missing = TripId(12);
    let err = store.checkpoint_trip(missing, &stats(1), &[]).unwrap_err();
    assert_eq!(err.kind(), &StoreErrorKind::NoSuchTrip(missing));
    assert_eq!(err.to_string(), ":memory:: trip 12 does not exist");
    let err = store.finish_trip(missing, &finished(1), &[]).unwrap_err();
    assert_eq!(err.kind(), &StoreErrorKind::NoSuchTrip(missing));
    assert_eq!(
        store.series(missing, SPEED).unwrap_err().kind(),
        &StoreErrorKind::NoSuchTrip(missing)
    );
    assert_eq!(store.trip(missing).unwrap(), None);

    let id = store.begin_trip(&new_trip("car", 0)).unwrap();
    store.finish_trip(id, &finished(1), &points(0, 2)).unwrap();
    let closed = store.trip(id).unwrap().unwrap();
    let err = store
        .finish_trip(id, &finished(2), &points(2, 3))
        .unwrap_err();
    assert_eq!(
        err.kind(),
        &StoreErrorKind::TripNotOpen(id, TripStatus::Closed)
    );
    assert_eq!(
        err.to_string(),
        format!(":memory:: trip {id} is closed and cannot be written")
    );
    let err = store
        .checkpoint_trip(id, &stats(5), &points(2, 3))
        .unwrap_err();
    assert_eq!(
        err.kind(),
        &StoreErrorKind::TripNotOpen(id, TripStatus::Closed)
    );
    // Nothing of the refused writes is stored: no second set of verdicts, no new points.
    assert_eq!(store.trip(id).unwrap().unwrap(), closed);
    assert_eq!(
        store.series(id, SPEED).unwrap(),
        sorted_by_time(points(0, 2), SPEED)
    );
}

#[test]
fn a_refused_checkpoint_writes_nothing() {
    let mut store = SqliteStore::open_in_memory().unwrap();
    let id = store.begin_trip(&new_trip("car", 0)).unwrap();
    store.checkpoint_trip(id, &stats(1), &points(0, 1)).unwrap();
    let mut series = points(1, 3);
    series.push(point(SPEED, f64::NAN));
    let err = store.checkpoint_trip(id, &stats(2), &series).unwrap_err();
    assert!(
        matches!(err.kind(), StoreErrorKind::InvalidArgument(_)),
        "{err}"
    );
    assert!(
        err.to_string().contains("Vehicle.Speed with time NaN"),
        "{err}"
    );
    let too_late = TripStats {
        end_us: u64::MAX,
        ..stats(2)
    };
    let err = store
        .checkpoint_trip(id, &too_late, &points(1, 3))
        .unwrap_err();
    assert!(err.to_string().contains("end_us"), "{err}");

    let row = store.trip(id).unwrap().unwrap();
    assert_eq!(row.row.stats, stats(1));
    assert_eq!(
        store.series(id, SPEED).unwrap(),
        sorted_by_time(points(0, 1), SPEED)
    );
}

#[test]
fn nan_is_kept_as_nan() {
    let mut store = SqliteStore::open_in_memory().unwrap();
    let id = store.begin_trip(&new_trip("car", 0)).unwrap();
    let nan_stats = TripStats {
        mean_speed_kmh: f64::NAN,
        ..stats(1)
    };
    let mut p = point(SPEED, 0.0);
    p.mean = f64::NAN;
    store.checkpoint_trip(id, &nan_stats, &[p]).unwrap();
    let row = store.trip(id).unwrap().unwrap().row;
    assert!(row.stats.mean_speed_kmh.is_nan());
    assert_eq!(
        TripStats {
            mean_speed_kmh: 0.0,
            ..row.stats
        },
        TripStats {
            mean_speed_kmh: 0.0,
            ..stats(1)
        }
    );
    let back = store.series(id, SPEED).unwrap();
    assert!(back[0].mean.is_nan());
    assert_eq!((back[0].min, back[0].max), (0.0, 1.25));
}

#[test]
fn trips_are_listed_newest_first_and_by_vehicle() {
    let mut store = SqliteStore::open_in_memory().unwrap();
    let a_old = store.begin_trip(&new_trip("A", 1_000)).unwrap();
    let b = store.begin_trip(&new_trip("B", 2_000)).unwrap();
    let a_new = store.begin_trip(&new_trip("A", 3_000)).unwrap();
    // Started at the same time as `a_new` but written after it: the higher id comes first.
    let a_same = store.begin_trip(&new_trip("A", 3_000)).unwrap();
    let ids = |rows: Vec<TripRow>| rows.into_iter().map(|r| r.id).collect::<Vec<_>>();
    assert_eq!(
        ids(store.trips(None).unwrap()),
        vec![a_same, a_new, b, a_old]
    );
    assert_eq!(
        ids(store.trips(Some("A")).unwrap()),
        vec![a_same, a_new, a_old]
    );
    assert_eq!(ids(store.trips(Some("B")).unwrap()), vec![b]);
    assert_eq!(ids(store.trips(Some("C")).unwrap()), vec![]);
}

#[test]
fn the_store_works_as_a_trait_object() {
    let mut store: Box<dyn TripStore + Send> = Box::new(SqliteStore::open_in_memory().unwrap());
    let id = store.begin_trip(&new_trip("car", 0)).unwrap();
    store.finish_trip(id, &finished(1), &[]).unwrap();
    assert_eq!(store.trips(None).unwrap()[0].status, TripStatus::Closed);
}
