//! A gateway that dies during a trip: the file stays consistent, the trip becomes
//! interrupted with its last checkpoint, and a live gateway's trip is never taken for a
//! dead one's.

mod common;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use autoplug_store::{SqliteStore, StoreErrorKind, TripId, TripStatus, TripStore};
use autoplug_trips::TripStats;
use common::*;
use tempfile::TempDir;

#[test]
fn an_open_trip_becomes_interrupted_on_reopen() {
    let dir = TempDir::new().unwrap();
    let path = dir.path().join("trips.db");
    let (open, closed) = {
        let mut store = SqliteStore::open(&path).unwrap();
        let closed = store.begin_trip(&new_trip("car", 1)).unwrap();
        store
            .finish_trip(closed, &finished(4), &points(0, 2))
            .unwrap();
        let open = store.begin_trip(&new_trip("car", 2)).unwrap();
        store
            .checkpoint_trip(open, &stats(1), &points(0, 3))
            .unwrap();
        store
            .checkpoint_trip(open, &stats(2), &points(3, 5))
            .unwrap();
        (open, closed)
        // Dropped without finishing: the gateway died.
    };

    let mut store = SqliteStore::open(&path).unwrap();
    assert_eq!(store.interrupted_on_open(), &[open]);
    let trip = store.trip(open).unwrap().unwrap();
    assert_eq!(trip.row.status, TripStatus::Interrupted);
    assert_eq!(trip.row.end, None);
    assert_eq!(trip.row.stats, stats(2));
    assert!(trip.verdicts.is_empty() && trip.dtcs.is_empty());
    assert_eq!(store.series(open, SPEED).unwrap().len(), 5);
    // The closed trip is as it was.
    let done = store.trip(closed).unwrap().unwrap();
    assert_eq!(
        (done.row.status, done.row.stats),
        (TripStatus::Closed, stats(4))
    );

    let err = store.checkpoint_trip(open, &stats(3), &[]).unwrap_err();
    assert_eq!(
        err.kind(),
        &StoreErrorKind::TripNotOpen(open, TripStatus::Interrupted)
    );
    assert_eq!(
        err.to_string(),
        format!(
            "{}: trip {open} was interrupted (the gateway stopped during it) and cannot be written",
            path.display()
        )
    );
    drop(store);
    assert_eq!(SqliteStore::open(&path).unwrap().interrupted_on_open(), &[]);
}

#[test]
fn a_trip_of_a_store_still_open_is_not_taken_for_abandoned() {
    let dir = TempDir::new().unwrap();
    let path = dir.path().join("trips.db");
    let status = |store: &SqliteStore, id| store.trip(id).unwrap().unwrap().row.status;

    let mut gateway = SqliteStore::open(&path).unwrap();
    let live = gateway.begin_trip(&new_trip("car", 1)).unwrap();
    // A second store (a trip list, a replay) opens the file while the gateway runs.
    let mut viewer = SqliteStore::open(&path).unwrap();
    assert_eq!(viewer.interrupted_on_open(), &[]);
    assert_eq!(status(&viewer, live), TripStatus::Open);
    gateway
        .checkpoint_trip(live, &stats(1), &points(0, 1))
        .unwrap();
    assert_eq!(viewer.trip(live).unwrap().unwrap().row.stats, stats(1));

    // The gateway dies during a second trip; the viewer is still open, so a third store
    // cannot tell the trip is abandoned, and leaves it.
    gateway.finish_trip(live, &finished(1), &[]).unwrap();
    let abandoned = gateway.begin_trip(&new_trip("car", 2)).unwrap();
    drop(gateway);
    let third = SqliteStore::open(&path).unwrap();
    assert_eq!(third.interrupted_on_open(), &[]);
    assert_eq!(status(&third, abandoned), TripStatus::Open);
    drop(third);
    // The viewer's own writes still work; once it is closed too, the next store is alone
    // and marks the trip interrupted.
    let own = viewer.begin_trip(&new_trip("bench", 3)).unwrap();
    viewer.finish_trip(own, &finished(2), &[]).unwrap();
    drop(viewer);
    let last = SqliteStore::open(&path).unwrap();
    assert_eq!(last.interrupted_on_open(), &[abandoned]);
    assert_eq!(status(&last, abandoned), TripStatus::Interrupted);
    assert_eq!(status(&last, live), TripStatus::Closed);
}

/// Set by [`kill_9_leaves_a_consistent_database`] for the child it starts: the database to
/// write to.
const CHILD_DB: &str = "AUTOPLUG_STORE_KILL_TEST_DB";
/// Points per signal in each checkpoint of the child (enough that a checkpoint takes a
/// millisecond or two, most of it inside its transaction).
const POINTS_PER_CHECKPOINT: u32 = 200;

/// The child of [`kill_9_leaves_a_consistent_database`] (not a test on its own: ignored,
/// and does nothing without the variable). Begins a trip and writes checkpoint `k` =
/// 1, 2, ... with `stats(k)` and the next [`POINTS_PER_CHECKPOINT`] buckets, printing
/// `@checkpoint k` after each commit, until killed (or after a minute, if the parent died).
#[test]
#[ignore = "run by kill_9_leaves_a_consistent_database in a child process"]
fn child_writing_checkpoints_until_killed() {
    let Some(path) = std::env::var_os(CHILD_DB) else {
        return;
    };
    let mut store = SqliteStore::open(Path::new(&path)).unwrap();
    let id = store.begin_trip(&new_trip("car", 1)).unwrap();
    println!("@trip {}", id.0);
    let deadline = Instant::now() + Duration::from_secs(60);
    for k in 1.. {
        let from = (k - 1) * POINTS_PER_CHECKPOINT;
        store
            .checkpoint_trip(id, &stats(k), &points(from, from + POINTS_PER_CHECKPOINT))
            .unwrap();
        println!("@checkpoint {k}");
        if Instant::now() > deadline {
            break;
        }
    }
}

/// Starts the child on `path`, kills it `delay` after it has printed `after` committed
/// checkpoints, and returns its trip and the last checkpoint it printed.
fn kill_a_writer(path: &Path, after: u32, delay: Duration) -> (TripId, u32) {
    // This test binary again, running only the child above.
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args([
            "child_writing_checkpoints_until_killed",
            "--exact",
            "--ignored",
            "--nocapture",
            "--test-threads=1",
        ])
        .env(CHILD_DB, path)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let mut trip = None;
    let mut committed = 0;
    for line in lines.by_ref() {
        // The harness may print on the same line ("test child_... ... @trip 1").
        let line = line.unwrap();
        let Some((_, said)) = line.split_once('@') else {
            continue;
        };
        if let Some(id) = said.strip_prefix("trip ") {
            trip = Some(TripId(id.parse().unwrap()));
        } else if let Some(k) = said.strip_prefix("checkpoint ") {
            committed = k.parse().unwrap();
            if committed >= after {
                break;
            }
        }
    }
    assert!(
        committed >= after,
        "the child stopped after {committed} checkpoints"
    );
    std::thread::sleep(delay);
    // std's kill is SIGKILL on Unix: no destructor, no rollback, no close.
    child.kill().unwrap();
    let status = child.wait().unwrap();
    assert!(!status.success(), "the child was not killed: {status}");
    (trip.expect("the child printed its trip"), committed)
}

#[test]
fn kill_9_leaves_a_consistent_database() {
    let dir = TempDir::new().unwrap();
    let path = dir.path().join("trips.db");
    let mut killed = Vec::new();
    // Gateways killed in turn, at different points of a checkpoint: the kill comes some
    // time after the child said it committed one, the delays spread over a few checkpoints'
    // time (the child goes on meanwhile), so that kills land inside transactions, between
    // them, and in their commit.
    for round in 0..8 {
        let delay = Duration::from_micros(1_370 * round);
        let (trip, committed) = kill_a_writer(&path, 5 + 3 * round as u32, delay);
        killed.push(trip);

        let store = SqliteStore::open(&path).unwrap();
        assert_eq!(store.interrupted_on_open(), &[trip]);
        drop(store);
        let check: String = rusqlite::Connection::open(&path)
            .unwrap()
            .query_row("PRAGMA integrity_check", [], |r| r.get(0))
            .unwrap();
        assert_eq!(check, "ok");

        let store = SqliteStore::open(&path).unwrap();
        let row = store.trip(trip).unwrap().unwrap().row;
        assert_eq!(row.status, TripStatus::Interrupted);
        // The statistics of one complete checkpoint k, no mix of two: every field agrees
        // with the k its abs_interventions says.
        let k = row.stats.abs_interventions;
        assert_eq!(row.stats, stats(k));
        assert_ne!(row.stats, TripStats::default());
        // Every checkpoint the child saw committed is there; at most the one it was
        // writing when killed is lost (it may have committed it and not printed yet).
        assert!(
            k >= committed,
            "checkpoint {k} stored, {committed} were committed"
        );
        // And the series of exactly those k checkpoints: the statistics and the points of
        // a checkpoint are one transaction.
        for signal in [SPEED, RPM] {
            let series = store.series(trip, signal).unwrap();
            assert_eq!(series.len() as u32, k * POINTS_PER_CHECKPOINT, "{signal}");
            let last = series.last().unwrap();
            assert_eq!(
                last,
                &point(signal, f64::from(k * POINTS_PER_CHECKPOINT - 1) * 0.5)
            );
        }
    }
    let store = SqliteStore::open(&path).unwrap();
    let mut interrupted: Vec<TripId> = store
        .trips(None)
        .unwrap()
        .into_iter()
        .filter(|r| r.status == TripStatus::Interrupted)
        .map(|r| r.id)
        .collect();
    interrupted.sort();
    assert_eq!(interrupted, killed);
}
