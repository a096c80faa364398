//! The store in an SQLite file: the gateway's own database.

mod columns;
mod files;
mod inventory;
mod trips;

use std::path::Path;
use std::time::Duration;

use rusqlite::{Connection, OpenFlags, Transaction, TransactionBehavior};

use crate::error::{StoreError, StoreErrorKind};
use crate::model::TripId;
use crate::schema;
use files::{CreateError, Found, WriterLock};

/// How long a statement waits for another connection's lock before giving up
/// ([`StoreErrorKind::Busy`]). A checkpoint takes milliseconds.
pub const BUSY_TIMEOUT: Duration = Duration::from_secs(5);

/// A [`TripStore`](crate::TripStore) in an SQLite database file (see the crate's
/// documentation for the schema, the journal mode and what happens after a crash).
///
/// One value per connection; it is `Send`, not `Sync`. Several stores, in one process or
/// several, may have the same file open: they read concurrently, and their writes take
/// turns (each waits up to [`BUSY_TIMEOUT`]).
pub struct SqliteStore {
    // Dropped first, so the connection is closed before the lock is released.
    conn: Connection,
    /// The path as given, or `:memory:`: what errors name.
    name: String,
    /// Trips found open, and marked interrupted, by `open`.
    interrupted: Vec<TripId>,
    /// Held (shared) while the store is open; `None` in memory.
    _lock: Option<WriterLock>,
}

/// A failure inside the store, before it is given the database's name.
#[derive(Debug)]
enum Fail {
    Sql(rusqlite::Error),
    Kind(StoreErrorKind),
}

impl From<rusqlite::Error> for Fail {
    fn from(e: rusqlite::Error) -> Self {
        Fail::Sql(e)
    }
}

impl From<StoreErrorKind> for Fail {
    fn from(k: StoreErrorKind) -> Self {
        Fail::Kind(k)
    }
}

impl Fail {
    fn named(self, db: &str) -> StoreError {
        match self {
            Fail::Sql(e) => StoreError::sqlite(db, e),
            Fail::Kind(k) => StoreError::new(db, k),
        }
    }
}

impl SqliteStore {
    /// Opens the database at `path`, creating it if there is no file there.
    ///
    /// Refuses, with a [`StoreError`] naming the file: an empty file, a file that is not an
    /// SQLite database, another program's database, a database of a newer schema than this
    /// program knows, a location it cannot write. Otherwise runs the migrations the
    /// database lacks, and sets write-ahead logging (`journal_mode=WAL`),
    /// `synchronous=NORMAL`, foreign keys on and a busy timeout of [`BUSY_TIMEOUT`].
    ///
    /// Then, if no other store has the file open, every trip still open was left by a
    /// gateway that died during it (power cut, crash, kill -9): it becomes
    /// [`Interrupted`](crate::TripStatus::Interrupted), with the statistics and series of
    /// its last checkpoint ([`SqliteStore::interrupted_on_open`] lists them). If other
    /// stores have it open, open trips may be theirs and are left alone.
    pub fn open(path: &Path) -> Result<SqliteStore, StoreError> {
        let name = path.display().to_string();
        let fail = |kind| StoreError::new(&name, kind);
        let cannot_open = |why: String| fail(StoreErrorKind::CannotOpen(why));
        match files::look(path) {
            Ok(Found::File) => {}
            Ok(Found::Nothing) => files::create(path, build_new).map_err(|e| match e {
                CreateError::Build(f) => f.named(&name),
                CreateError::Files(e) => cannot_open(e.to_string()),
            })?,
            Ok(Found::EmptyFile) => return Err(fail(StoreErrorKind::EmptyFile)),
            Ok(Found::Directory) => return Err(cannot_open("it is a directory".into())),
            Err(e) => return Err(cannot_open(e.to_string())),
        }
        // Not SQLITE_OPEN_CREATE: the file exists (if it vanished meanwhile, fail rather
        // than create an empty one outside `files::create`).
        let flags = OpenFlags::SQLITE_OPEN_READ_WRITE | OpenFlags::SQLITE_OPEN_NO_MUTEX;
        let mut conn =
            Connection::open_with_flags(path, flags).map_err(|e| StoreError::sqlite(&name, e))?;
        prepare(&mut conn, true).map_err(|f| f.named(&name))?;
        let (lock, alone) =
            WriterLock::take(path).map_err(|e| cannot_open(format!("its lock file: {e}")))?;
        let mut store = SqliteStore {
            conn,
            name: name.clone(),
            interrupted: Vec::new(),
            _lock: None,
        };
        if alone {
            store.interrupt_open_trips()?;
            lock.share()
                .map_err(|e| cannot_open(format!("its lock file: {e}")))?;
        }
        store._lock = Some(lock);
        Ok(store)
    }

    /// A store in memory, empty, gone when dropped (for tests).
    pub fn open_in_memory() -> Result<SqliteStore, StoreError> {
        let name = ":memory:";
        let mut conn = Connection::open_in_memory().map_err(|e| StoreError::sqlite(name, e))?;
        prepare(&mut conn, false).map_err(|f| f.named(name))?;
        Ok(SqliteStore {
            conn,
            name: name.to_owned(),
            interrupted: Vec::new(),
            _lock: None,
        })
    }

    /// The trips `open` found still open and marked
    /// [`Interrupted`](crate::TripStatus::Interrupted), oldest first: a previous gateway
    /// died during them.
    pub fn interrupted_on_open(&self) -> &[TripId] {
        &self.interrupted
    }

    /// Marks every open trip interrupted (see [`SqliteStore::open`]).
    fn interrupt_open_trips(&mut self) -> Result<(), StoreError> {
        let result = (|| -> Result<Vec<TripId>, Fail> {
            // Read first: no write lock (nor wait for one) when there is nothing to mark.
            if open_trips(&self.conn)?.is_empty() {
                return Ok(Vec::new());
            }
            let tx = self
                .conn
                .transaction_with_behavior(TransactionBehavior::Immediate)?;
            let ids = open_trips(&tx)?;
            tx.execute(
                "UPDATE trips SET status = 'interrupted' WHERE status = 'open'",
                [],
            )?;
            tx.commit()?;
            Ok(ids)
        })();
        self.interrupted = self.named(result)?;
        Ok(())
    }

    fn named<T>(&self, result: Result<T, Fail>) -> Result<T, StoreError> {
        result.map_err(|f| f.named(&self.name))
    }

    /// A write transaction: IMMEDIATE takes the write lock at once (waiting up to the busy
    /// timeout), rather than failing at the first write when another connection wrote
    /// since this one's read began.
    fn write(&mut self) -> Result<Transaction<'_>, Fail> {
        Ok(self
            .conn
            .transaction_with_behavior(TransactionBehavior::Immediate)?)
    }

    /// A read transaction: one snapshot for several queries.
    fn read(&self) -> Result<Transaction<'_>, Fail> {
        Ok(Transaction::new_unchecked(
            &self.conn,
            TransactionBehavior::Deferred,
        )?)
    }
}

/// Fills a new database file (see `files::create`): the schema, in WAL mode, then closes it
/// (which moves the log into the file).
fn build_new(path: &Path) -> Result<(), Fail> {
    let flags = OpenFlags::SQLITE_OPEN_READ_WRITE
        | OpenFlags::SQLITE_OPEN_CREATE
        | OpenFlags::SQLITE_OPEN_NO_MUTEX;
    let mut conn = Connection::open_with_flags(path, flags)?;
    prepare(&mut conn, true)?;
    conn.close().map_err(|(_, e)| Fail::Sql(e))
}

/// Checks that `conn` is on an AutoPlug database (or an empty one), sets it up and
/// migrates it. `file`: on a file (not in memory), which gets WAL.
fn prepare(conn: &mut Connection, file: bool) -> Result<(), Fail> {
    conn.busy_timeout(BUSY_TIMEOUT)?;
    // Room for every statement of the store (the default, 16, would evict some).
    conn.set_prepared_statement_cache_capacity(64);
    // Before anything writes: another program's database must be left untouched.
    check_identity(conn)?;
    // SQLite opens a write-protected file read-only rather than fail.
    if conn.is_readonly(rusqlite::MAIN_DB)? {
        return Err(StoreErrorKind::ReadOnly.into());
    }
    if file {
        // Readers no longer block the writer nor the writer the readers, and a commit is
        // one append to the log: a checkpoint every few seconds costs little.
        let mode: String = conn.query_row("PRAGMA journal_mode = WAL", [], |r| r.get(0))?;
        if !mode.eq_ignore_ascii_case("wal") {
            return Err(StoreErrorKind::CannotOpen(format!(
                "no write-ahead log on this file system (journal mode stays {mode})"
            ))
            .into());
        }
    }
    // In WAL mode NORMAL syncs at checkpoints of the log, not at every commit: a crash of
    // the gateway loses nothing committed, a power cut at most the last commits.
    conn.execute_batch("PRAGMA synchronous = NORMAL; PRAGMA foreign_keys = ON;")?;
    // The migrations run in one IMMEDIATE transaction.
    conn.set_transaction_behavior(TransactionBehavior::Immediate);
    let migrated = schema::migrations().to_latest(conn);
    conn.set_transaction_behavior(TransactionBehavior::Deferred);
    migrated.map_err(|e| match e {
        rusqlite_migration::Error::RusqliteError { err, .. } => Fail::Sql(err),
        rusqlite_migration::Error::MigrationDefinition(
            rusqlite_migration::MigrationDefinitionError::DatabaseTooFarAhead,
        ) => Fail::Kind(StoreErrorKind::NewerSchema {
            found: user_version(conn).ok().flatten().unwrap_or(0),
            known: schema::SCHEMA_VERSION,
        }),
        other => Fail::Kind(StoreErrorKind::Database(other.to_string())),
    })
}

/// The schema version (`PRAGMA user_version`, a signed 32-bit number; a negative one is
/// another program's doing and reads as `None`).
fn user_version(conn: &Connection) -> rusqlite::Result<Option<usize>> {
    let v: i64 = conn.query_row("PRAGMA user_version", [], |r| r.get(0))?;
    Ok(usize::try_from(v).ok())
}

/// Refuses a database that is not an AutoPlug one (or empty), or is of a newer schema.
fn check_identity(conn: &Connection) -> Result<(), Fail> {
    // The first read of the file: SQLITE_NOTADB here for random bytes.
    let Some(version) = user_version(conn)? else {
        return Err(
            StoreErrorKind::ForeignDatabase("its schema version is negative".into()).into(),
        );
    };
    let application_id: i64 = conn.query_row("PRAGMA application_id", [], |r| r.get(0))?;
    let tables: i64 = conn.query_row("SELECT count(*) FROM sqlite_schema", [], |r| r.get(0))?;
    if version == 0 {
        return if tables == 0 {
            Ok(()) // empty: ours to fill
        } else {
            Err(
                StoreErrorKind::ForeignDatabase("it has tables but no schema version".into())
                    .into(),
            )
        };
    }
    if application_id != schema::APPLICATION_ID {
        return Err(StoreErrorKind::ForeignDatabase(format!(
            "its application id is {application_id:#x}, not AutoPlug's"
        ))
        .into());
    }
    if version > schema::SCHEMA_VERSION {
        return Err(StoreErrorKind::NewerSchema {
            found: version,
            known: schema::SCHEMA_VERSION,
        }
        .into());
    }
    Ok(())
}

fn open_trips(conn: &Connection) -> rusqlite::Result<Vec<TripId>> {
    let mut stmt = conn.prepare_cached("SELECT id FROM trips WHERE status = 'open' ORDER BY id")?;
    let ids = stmt.query_map([], |r| r.get(0).map(TripId))?;
    ids.collect()
}

/// The id of `name` in `vehicles`, added if new.
fn vehicle_id(conn: &Connection, name: &str) -> rusqlite::Result<i64> {
    conn.prepare_cached("INSERT INTO vehicles (name) VALUES (?) ON CONFLICT (name) DO NOTHING")?
        .execute([name])?;
    conn.prepare_cached("SELECT id FROM vehicles WHERE name = ?")?
        .query_row([name], |r| r.get(0))
}

#[cfg(test)]
mod tests {
    use std::time::Instant;

    use autoplug_trips::{SeriesPoint, TripStats};
    use rusqlite::types::Value;

    use super::trips::{put_series, require_open, trip_row, trips_select, update_trip};
    use super::*;
    use crate::model::{NewTrip, TripStatus};
    use crate::store::TripStore;
    use columns::stats_values;

    fn pragma(conn: &Connection, name: &str) -> String {
        conn.query_row(&format!("PRAGMA {name}"), [], |r| {
            r.get::<_, rusqlite::types::Value>(0)
        })
        .map(|v| match v {
            Value::Integer(i) => i.to_string(),
            Value::Text(t) => t,
            other => format!("{other:?}"),
        })
        .unwrap()
    }

    fn sample_stats(k: u32) -> TripStats {
        TripStats {
            start_us: 1,
            end_us: 1 + u64::from(k),
            distance_m: f64::from(k),
            shifts: k,
            ..TripStats::default()
        }
    }

    fn sample_point(t_s: f64) -> SeriesPoint {
        SeriesPoint {
            signal: "Vehicle.Speed".into(),
            t_s,
            mean: 2.0,
            min: 1.0,
            max: 3.0,
        }
    }

    #[test]
    fn a_file_connection_has_wal_normal_sync_foreign_keys_and_a_busy_timeout() {
        let dir = tempfile::TempDir::new().unwrap();
        let store = SqliteStore::open(&dir.path().join("trips.db")).unwrap();
        assert_eq!(pragma(&store.conn, "journal_mode"), "wal");
        // NORMAL
        assert_eq!(pragma(&store.conn, "synchronous"), "1");
        assert_eq!(pragma(&store.conn, "foreign_keys"), "1");
        assert_eq!(
            pragma(&store.conn, "busy_timeout"),
            BUSY_TIMEOUT.as_millis().to_string()
        );
        // Foreign keys are enforced: series points of a trip that does not exist are refused.
        let err = store
            .conn
            .execute(
                "INSERT INTO trip_series (trip_id, signal_id, t_s) VALUES (99, 99, 0.0)",
                [],
            )
            .unwrap_err();
        assert_eq!(
            err.sqlite_error_code(),
            Some(rusqlite::ErrorCode::ConstraintViolation)
        );
    }

    /// WAL: while the gateway is inside a checkpoint transaction (written, not yet
    /// committed), another store opens the file and reads, without waiting, the last
    /// committed state; after the commit it sees the new one.
    #[test]
    fn a_second_store_reads_while_a_checkpoint_transaction_is_open() {
        let dir = tempfile::TempDir::new().unwrap();
        let path = dir.path().join("trips.db");
        let mut gateway = SqliteStore::open(&path).unwrap();
        let id = gateway
            .begin_trip(&NewTrip {
                vehicle: "car".into(),
                source: "bus.log".into(),
                started_at_unix_ms: 0,
                start_us: 1,
            })
            .unwrap();
        gateway
            .checkpoint_trip(id, &sample_stats(1), &[sample_point(0.0)])
            .unwrap();

        // The checkpoint's own steps, stopped before the commit.
        let tx = gateway
            .conn
            .transaction_with_behavior(TransactionBehavior::Immediate)
            .unwrap();
        require_open(&tx, id).unwrap();
        let values = stats_values(&sample_stats(2)).unwrap();
        update_trip(&tx, id, values, TripStatus::Open, None).unwrap();
        put_series(&tx, id, &[sample_point(0.5)]).unwrap();

        let started = Instant::now();
        let reader = SqliteStore::open(&path).unwrap();
        let seen = reader.trip(id).unwrap().unwrap();
        let points = reader.series(id, "Vehicle.Speed").unwrap();
        let waited = started.elapsed();
        assert!(waited < BUSY_TIMEOUT / 2, "the reader waited {waited:?}");
        assert_eq!(seen.row.status, TripStatus::Open);
        assert_eq!(seen.row.stats, sample_stats(1));
        assert_eq!(points, vec![sample_point(0.0)]);

        tx.commit().unwrap();
        assert_eq!(reader.trip(id).unwrap().unwrap().row.stats, sample_stats(2));
        assert_eq!(reader.series(id, "Vehicle.Speed").unwrap().len(), 2);
    }

    /// WAL: a checkpoint commits, without waiting, while a reader is inside a read
    /// transaction (with a rollback journal the commit would wait for the reader, and give
    /// up after the busy timeout); the reader keeps its snapshot until it ends.
    #[test]
    fn a_checkpoint_commits_while_another_store_is_reading() {
        let dir = tempfile::TempDir::new().unwrap();
        let path = dir.path().join("trips.db");
        let mut gateway = SqliteStore::open(&path).unwrap();
        let id = gateway
            .begin_trip(&NewTrip {
                vehicle: "car".into(),
                source: "bus.log".into(),
                started_at_unix_ms: 0,
                start_us: 1,
            })
            .unwrap();
        gateway
            .checkpoint_trip(id, &sample_stats(1), &[sample_point(0.0)])
            .unwrap();

        let reader = SqliteStore::open(&path).unwrap();
        let snapshot = reader.read().unwrap();
        let read = |conn: &Connection| {
            let sql = format!("{} WHERE t.id = ?", trips_select());
            conn.query_row(&sql, [id.0], trip_row).unwrap().stats
        };
        assert_eq!(read(&snapshot), sample_stats(1));

        let started = Instant::now();
        gateway
            .checkpoint_trip(id, &sample_stats(2), &[sample_point(0.5)])
            .unwrap();
        let waited = started.elapsed();
        assert!(
            waited < BUSY_TIMEOUT / 2,
            "the checkpoint waited {waited:?}"
        );

        assert_eq!(read(&snapshot), sample_stats(1), "the snapshot changed");
        snapshot.finish().unwrap();
        assert_eq!(read(&reader.conn), sample_stats(2));
    }
}
