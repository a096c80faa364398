//! The ECU inventory: history of identities, the current one of each ECU.

mod common;

use std::path::Path;

use autoplug_store::{EcuIdentity, SqliteStore, TripStore};
use common::*;
use rusqlite::Connection;
use tempfile::TempDir;

/// The history rows of `vehicle`'s `ecu`, oldest first: software version, first and last
/// seen.
fn history(path: &Path, vehicle: &str, ecu: &str) -> Vec<(Option<String>, i64, i64)> {
    let conn = Connection::open(path).unwrap();
    let mut stmt = conn
        .prepare(
            "SELECT i.software_version, i.first_seen_unix_ms, i.last_seen_unix_ms \
             FROM ecu_inventory AS i JOIN vehicles AS v ON v.id = i.vehicle_id \
             WHERE v.name = ? AND i.ecu = ? ORDER BY i.id",
        )
        .unwrap();
    stmt.query_map([vehicle, ecu], |r| Ok((r.get(0)?, r.get(1)?, r.get(2)?)))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap()
}

#[test]
fn a_reflash_is_a_new_row_and_the_current_identity_is_the_newest() {
    let dir = TempDir::new().unwrap();
    let path = dir.path().join("trips.db");
    let mut store = SqliteStore::open(&path).unwrap();
    let engine_v1 = identity("engine", 0x10, "1.0.0");
    let abs = identity("abs", 0x20, "3.1.0");

    store
        .record_inventory("car", 1_000, &[engine_v1.clone(), abs.clone()])
        .unwrap();
    // The same identity again: no new row, last seen moves on.
    store
        .record_inventory("car", 2_000, &[engine_v1.clone(), abs.clone()])
        .unwrap();
    assert_eq!(
        history(&path, "car", "engine"),
        vec![(Some("1.0.0".into()), 1_000, 2_000)]
    );

    // Reflashed: a second row, first seen now.
    let engine_v2 = identity("engine", 0x10, "1.1.0");
    store
        .record_inventory("car", 3_000, std::slice::from_ref(&engine_v2))
        .unwrap();
    store
        .record_inventory("car", 4_000, std::slice::from_ref(&engine_v2))
        .unwrap();
    assert_eq!(
        history(&path, "car", "engine"),
        vec![
            (Some("1.0.0".into()), 1_000, 2_000),
            (Some("1.1.0".into()), 3_000, 4_000)
        ]
    );
    // Sorted by ECU; the ABS, not read since, keeps its last seen.
    assert_eq!(
        store.inventory("car").unwrap(),
        vec![(abs, 1_000, 2_000), (engine_v2, 3_000, 4_000)]
    );
    assert_eq!(store.inventory("another car").unwrap(), vec![]);
}

#[test]
fn an_unanswered_identifier_is_not_a_change() {
    let dir = TempDir::new().unwrap();
    let path = dir.path().join("trips.db");
    let mut store = SqliteStore::open(&path).unwrap();
    let full = identity("cabin", 0x30, "2.0.0");
    let no_serial = EcuIdentity {
        serial_number: None,
        ..full.clone()
    };
    store
        .record_inventory("car", 1_000, std::slice::from_ref(&no_serial))
        .unwrap();
    assert_eq!(
        store.inventory("car").unwrap(),
        vec![(no_serial.clone(), 1_000, 1_000)]
    );
    // Now it answers: the same identity, completed.
    store
        .record_inventory("car", 2_000, std::slice::from_ref(&full))
        .unwrap();
    // And fails to answer again: still known.
    store.record_inventory("car", 3_000, &[no_serial]).unwrap();
    assert_eq!(history(&path, "car", "cabin").len(), 1);
    assert_eq!(
        store.inventory("car").unwrap(),
        vec![(full.clone(), 1_000, 3_000)]
    );

    // A different answer is a change, as is another node.
    let other_serial = EcuIdentity {
        serial_number: Some("SN-replaced".into()),
        ..full.clone()
    };
    store
        .record_inventory("car", 4_000, std::slice::from_ref(&other_serial))
        .unwrap();
    let moved = EcuIdentity {
        node: 0x31,
        ..other_serial
    };
    store
        .record_inventory("car", 5_000, std::slice::from_ref(&moved))
        .unwrap();
    assert_eq!(history(&path, "car", "cabin").len(), 3);
    assert_eq!(store.inventory("car").unwrap(), vec![(moved, 5_000, 5_000)]);
}

#[test]
fn vehicles_have_their_own_inventory_and_the_fleet_view_answers_by_version() {
    let dir = TempDir::new().unwrap();
    let path = dir.path().join("trips.db");
    let mut store = SqliteStore::open(&path).unwrap();
    let old = identity("engine", 0x10, "1.0.0");
    let new = identity("engine", 0x10, "1.1.0");
    store
        .record_inventory("A", 1_000, std::slice::from_ref(&old))
        .unwrap();
    store
        .record_inventory("B", 1_000, std::slice::from_ref(&old))
        .unwrap();
    store
        .record_inventory("C", 1_000, std::slice::from_ref(&old))
        .unwrap();
    store
        .record_inventory("B", 2_000, std::slice::from_ref(&new))
        .unwrap();
    assert_eq!(
        store.inventory("A").unwrap(),
        vec![(old.clone(), 1_000, 1_000)]
    );
    assert_eq!(store.inventory("B").unwrap(), vec![(new, 2_000, 2_000)]);

    // "Which vehicles still carry software 1.0.0 of the engine?" (B was reflashed.)
    let conn = Connection::open(&path).unwrap();
    let vehicles: Vec<String> = conn
        .prepare(
            "SELECT vehicle FROM ecu_current \
             WHERE ecu = 'engine' AND software_version = '1.0.0' ORDER BY vehicle",
        )
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(vehicles, ["A", "C"]);
}
