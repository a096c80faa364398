//! The database file: created whole, reopened, and every file that is not ours refused
//! without being touched.

mod common;

use std::fs;
use std::path::{Path, PathBuf};

use autoplug_store::{
    SqliteStore, StoreError, StoreErrorKind, TripStatus, TripStore, APPLICATION_ID, SCHEMA_VERSION,
};
use common::*;
use rusqlite::Connection;
use tempfile::TempDir;

fn db_in(dir: &TempDir) -> PathBuf {
    dir.path().join("trips.db")
}

fn open_err(path: &Path) -> StoreError {
    match SqliteStore::open(path) {
        Ok(_) => panic!("{} opened", path.display()),
        Err(e) => e,
    }
}

/// The names in `dir`, sorted.
fn names(dir: &TempDir) -> Vec<String> {
    let mut names: Vec<String> = fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

fn pragma<T: rusqlite::types::FromSql>(path: &Path, pragma: &str) -> T {
    let conn = Connection::open(path).unwrap();
    conn.query_row(&format!("PRAGMA {pragma}"), [], |r| r.get(0))
        .unwrap()
}

#[test]
fn a_new_file_is_created_whole_in_wal_mode_and_reopens_with_its_data() {
    let dir = TempDir::new().unwrap();
    let path = db_in(&dir);
    let id = {
        let mut store = SqliteStore::open(&path).unwrap();
        // Only the database, its lock and SQLite's WAL companions: no temporary file left.
        assert_eq!(
            names(&dir),
            ["trips.db", "trips.db-lock", "trips.db-shm", "trips.db-wal"]
        );
        let id = store.begin_trip(&new_trip("car", 7)).unwrap();
        store.finish_trip(id, &finished(2), &points(0, 3)).unwrap();
        id
    };
    // Journal mode is a property of the file: a plain connection sees WAL.
    assert_eq!(pragma::<String>(&path, "journal_mode"), "wal");
    assert_eq!(pragma::<i64>(&path, "application_id"), APPLICATION_ID);
    assert_eq!(
        pragma::<i64>(&path, "user_version") as usize,
        SCHEMA_VERSION
    );

    let store = SqliteStore::open(&path).unwrap();
    assert_eq!(store.interrupted_on_open(), &[]);
    let detail = store.trip(id).unwrap().unwrap();
    assert_eq!(detail.row.status, TripStatus::Closed);
    assert_eq!(detail.row.stats, stats(2));
    assert_eq!(detail.verdicts, finished(2).verdicts);
    assert_eq!(store.series(id, RPM).unwrap().len(), 3);
}

#[test]
fn random_bytes_are_refused_and_left_alone() {
    let dir = TempDir::new().unwrap();
    let path = db_in(&dir);
    // A page and a bit of bytes from a linear congruential generator.
    let mut x: u32 = 12345;
    let garbage: Vec<u8> = (0..5000)
        .map(|_| {
            x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
            (x >> 16) as u8
        })
        .collect();
    fs::write(&path, &garbage).unwrap();
    let err = open_err(&path);
    assert_eq!(err.kind(), &StoreErrorKind::NotADatabase);
    assert_eq!(
        err.to_string(),
        format!("{}: file is not a database", path.display())
    );
    assert_eq!(fs::read(&path).unwrap(), garbage);
    assert_eq!(names(&dir), ["trips.db"]);

    // A short text file too.
    fs::write(&path, "hello\n").unwrap();
    assert_eq!(open_err(&path).kind(), &StoreErrorKind::NotADatabase);
    assert_eq!(fs::read(&path).unwrap(), b"hello\n");
}

#[test]
fn an_empty_file_is_refused_and_left_alone() {
    let dir = TempDir::new().unwrap();
    let path = db_in(&dir);
    fs::write(&path, "").unwrap();
    let err = open_err(&path);
    assert_eq!(err.kind(), &StoreErrorKind::EmptyFile);
    assert_eq!(
        err.to_string(),
        format!(
            "{}: file is empty, not a database (delete it to start a new one)",
            path.display()
        )
    );
    assert_eq!(fs::metadata(&path).unwrap().len(), 0);
    assert_eq!(names(&dir), ["trips.db"]);
}

#[test]
fn another_programs_database_is_refused_and_left_alone() {
    let dir = TempDir::new().unwrap();
    let path = db_in(&dir);
    {
        let conn = Connection::open(&path).unwrap();
        conn.execute_batch("CREATE TABLE notes (body TEXT); INSERT INTO notes VALUES ('hi');")
            .unwrap();
    }
    let err = open_err(&path);
    assert_eq!(
        err.to_string(),
        format!(
            "{}: not an AutoPlug database (it has tables but no schema version)",
            path.display()
        )
    );
    let conn = Connection::open(&path).unwrap();
    let tables: Vec<String> = conn
        .prepare("SELECT name FROM sqlite_schema")
        .unwrap()
        .query_map([], |r| r.get(0))
        .unwrap()
        .collect::<Result<_, _>>()
        .unwrap();
    assert_eq!(tables, ["notes"]);
    let mode: String = conn
        .query_row("PRAGMA journal_mode", [], |r| r.get(0))
        .unwrap();
    assert_eq!(mode, "delete", "its journal mode was changed");

    // One that versions its schema with user_version too, but is not ours.
    conn.execute_batch("PRAGMA user_version = 1").unwrap();
    drop(conn);
    let err = open_err(&path);
    assert_eq!(
        err.kind(),
        &StoreErrorKind::ForeignDatabase("its application id is 0x0, not AutoPlug's".into())
    );
}

#[test]
fn a_database_of_a_newer_schema_is_refused() {
    let dir = TempDir::new().unwrap();
    let path = db_in(&dir);
    drop(SqliteStore::open(&path).unwrap());
    Connection::open(&path)
        .unwrap()
        .execute_batch("PRAGMA user_version = 9")
        .unwrap();
    let err = open_err(&path);
    assert_eq!(
        err.kind(),
        &StoreErrorKind::NewerSchema {
            found: 9,
            known: SCHEMA_VERSION
        }
    );
    assert_eq!(
        err.to_string(),
        format!(
            "{}: written by a newer AutoPlug (schema version 9 is newer than this program's {SCHEMA_VERSION})",
            path.display()
        )
    );
    assert_eq!(pragma::<i64>(&path, "user_version"), 9);
}

#[test]
fn a_location_that_cannot_be_written_is_refused() {
    // A directory that does not exist.
    let dir = TempDir::new().unwrap();
    let path = dir.path().join("no-such-dir").join("trips.db");
    let err = open_err(&path);
    assert!(
        matches!(err.kind(), StoreErrorKind::CannotOpen(_)),
        "{err:?}"
    );
    assert!(
        err.to_string()
            .starts_with(&format!("{}: cannot open (", path.display())),
        "{err}"
    );
    assert!(!path.exists());

    // A directory.
    let err = open_err(dir.path());
    assert_eq!(
        err.kind(),
        &StoreErrorKind::CannotOpen("it is a directory".into())
    );
}

/// sysfs refuses new files even to root (file permissions would not stop root).
#[cfg(target_os = "linux")]
#[test]
fn a_read_only_location_is_refused() {
    let path = Path::new("/sys/autoplug-store-test.db");
    let err = open_err(path);
    assert!(
        matches!(err.kind(), StoreErrorKind::CannotOpen(_)),
        "{err:?}"
    );
    assert!(
        err.to_string()
            .starts_with("/sys/autoplug-store-test.db: cannot open ("),
        "{err}"
    );
    assert!(!path.exists());
}
