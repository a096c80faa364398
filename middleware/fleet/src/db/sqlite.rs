//! The fleet database in an SQLite file: the embedded default for one machine.

use std::path::Path;
use std::time::Duration;

use rusqlite::types::{ToSqlOutput, ValueRef};
use rusqlite::{Connection, OpenFlags, ToSql};

use super::{sqlite_placeholders, Db, DbError, Dialect, Row, Value};

/// How long a writer waits for another connection's write to finish.
const BUSY_TIMEOUT: Duration = Duration::from_secs(10);

/// Statements kept prepared per connection (the store has a few dozen).
const STATEMENT_CACHE: usize = 64;

/// A connection to an SQLite database file (or `:memory:`).
pub struct SqliteDb {
    conn: Connection,
    name: String,
    /// Transactions open: the outer one and the savepoints inside it.
    depth: usize,
}

impl SqliteDb {
    /// Opens (creating) the database at `path`: write-ahead log, foreign keys on.
    pub fn open(path: &Path) -> Result<Self, DbError> {
        let name = path.display().to_string();
        let fail = |e: rusqlite::Error| DbError {
            database: name.clone(),
            message: e.to_string(),
        };
        let conn = Connection::open_with_flags(
            path,
            OpenFlags::SQLITE_OPEN_READ_WRITE
                | OpenFlags::SQLITE_OPEN_CREATE
                | OpenFlags::SQLITE_OPEN_NO_MUTEX,
        )
        .map_err(fail)?;
        Self::setup(conn, name)
    }

    /// A private database in memory (tests, one-off runs).
    pub fn in_memory() -> Result<Self, DbError> {
        let conn = Connection::open_in_memory().map_err(|e| DbError {
            database: ":memory:".into(),
            message: e.to_string(),
        })?;
        Self::setup(conn, ":memory:".into())
    }

    fn setup(conn: Connection, name: String) -> Result<Self, DbError> {
        conn.busy_timeout(BUSY_TIMEOUT)
            .and_then(|()| {
                conn.execute_batch(
                    "PRAGMA journal_mode = WAL; PRAGMA synchronous = NORMAL; PRAGMA foreign_keys = ON;",
                )
            })
            .map_err(|e| DbError {
                database: name.clone(),
                message: format!("not a usable SQLite database: {e}"),
            })?;
        conn.set_prepared_statement_cache_capacity(STATEMENT_CACHE);
        Ok(Self {
            conn,
            name,
            depth: 0,
        })
    }

    fn fail(&self, sql: &str, e: rusqlite::Error) -> DbError {
        DbError {
            database: self.name.clone(),
            message: format!("{e} (in: {})", first_line(sql)),
        }
    }
}

/// The first line of a statement, for error messages.
pub(crate) fn first_line(sql: &str) -> &str {
    sql.trim().lines().next().unwrap_or("")
}

impl ToSql for Value {
    fn to_sql(&self) -> rusqlite::Result<ToSqlOutput<'_>> {
        Ok(match self {
            Value::Null => ToSqlOutput::Owned(rusqlite::types::Value::Null),
            Value::Int(v) => ToSqlOutput::Owned(rusqlite::types::Value::Integer(*v)),
            Value::Float(v) => ToSqlOutput::Owned(rusqlite::types::Value::Real(*v)),
            Value::Text(v) => ToSqlOutput::Borrowed(ValueRef::Text(v.as_bytes())),
            Value::Bytes(v) => ToSqlOutput::Borrowed(ValueRef::Blob(v)),
        })
    }
}

fn value_of(v: ValueRef<'_>) -> Value {
    match v {
        ValueRef::Null => Value::Null,
        ValueRef::Integer(i) => Value::Int(i),
        ValueRef::Real(f) => Value::Float(f),
        ValueRef::Text(t) => Value::Text(String::from_utf8_lossy(t).into_owned()),
        ValueRef::Blob(b) => Value::Bytes(b.to_vec()),
    }
}

impl Db for SqliteDb {
    fn dialect(&self) -> Dialect {
        Dialect::Sqlite
    }

    fn name(&self) -> &str {
        &self.name
    }

    fn execute(&mut self, sql: &str, params: &[Value]) -> Result<u64, DbError> {
        let text = sqlite_placeholders(sql);
        let mut statement = self
            .conn
            .prepare_cached(&text)
            .map_err(|e| self.fail(sql, e))?;
        let changed = statement
            .execute(rusqlite::params_from_iter(params))
            .map_err(|e| self.fail(sql, e))?;
        Ok(changed as u64)
    }

    fn query(&mut self, sql: &str, params: &[Value]) -> Result<Vec<Row>, DbError> {
        let text = sqlite_placeholders(sql);
        let run = || -> rusqlite::Result<Vec<Row>> {
            let mut statement = self.conn.prepare_cached(&text)?;
            let columns = statement.column_count();
            let mut rows = statement.query(rusqlite::params_from_iter(params))?;
            let mut out = Vec::new();
            while let Some(row) = rows.next()? {
                let mut values = Vec::with_capacity(columns);
                for i in 0..columns {
                    values.push(value_of(row.get_ref(i)?));
                }
                out.push(values);
            }
            Ok(out)
        };
        run().map_err(|e| self.fail(sql, e))
    }

    fn batch(&mut self, sql: &str) -> Result<(), DbError> {
        self.conn.execute_batch(sql).map_err(|e| self.fail(sql, e))
    }

    fn begin(&mut self) -> Result<(), DbError> {
        // IMMEDIATE: take the write lock now, so two writers never both read then both
        // try to write (which SQLite can only resolve by failing one).
        let sql = super::begin_sql(self.depth, "BEGIN IMMEDIATE");
        self.batch(&sql)?;
        self.depth += 1;
        Ok(())
    }

    fn commit(&mut self) -> Result<(), DbError> {
        self.depth = self.depth.saturating_sub(1);
        self.batch(&super::commit_sql(self.depth))
    }

    fn rollback(&mut self) -> Result<(), DbError> {
        self.depth = self.depth.saturating_sub(1);
        self.batch(&super::rollback_sql(self.depth))
    }
}
