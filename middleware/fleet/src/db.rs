//! One small interface over the two SQL engines the fleet runs on: PostgreSQL (the server,
//! shared by any number of fleet services) and SQLite (one machine, no server).
//!
//! The store writes each statement once, in PostgreSQL's `$1` parameter style, over plain
//! values; each engine runs it as it is (SQLite reads `$1` as `?1`). Written here rather
//! than taken from an ORM because the fleet's queries are a handful of plain SQL statements
//! whose plans the benchmark shows, and the two synchronous drivers (`postgres`,
//! `rusqlite`) are already the well-kept crates for each engine.

mod postgres;
mod sqlite;

use std::fmt;

pub use self::postgres::PostgresDb;
pub use self::sqlite::SqliteDb;

/// A value bound to a parameter or read from a column.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// SQL NULL.
    Null,
    /// BIGINT / INTEGER.
    Int(i64),
    /// DOUBLE PRECISION / REAL.
    Float(f64),
    /// TEXT.
    Text(String),
    /// BYTEA / BLOB.
    Bytes(Vec<u8>),
}

impl Value {
    /// The integer, if it is one.
    pub fn int(&self) -> Option<i64> {
        match self {
            Value::Int(v) => Some(*v),
            _ => None,
        }
    }

    /// The number, integer or not.
    pub fn float(&self) -> Option<f64> {
        match self {
            Value::Float(v) => Some(*v),
            Value::Int(v) => Some(*v as f64),
            _ => None,
        }
    }

    /// The text, if it is text.
    pub fn text(&self) -> Option<&str> {
        match self {
            Value::Text(v) => Some(v),
            _ => None,
        }
    }

    /// The bytes, if it is a blob.
    pub fn bytes(&self) -> Option<&[u8]> {
        match self {
            Value::Bytes(v) => Some(v),
            _ => None,
        }
    }
}

impl From<i64> for Value {
    fn from(v: i64) -> Self {
        Value::Int(v)
    }
}

impl From<f64> for Value {
    fn from(v: f64) -> Self {
        Value::Float(v)
    }
}

impl From<&str> for Value {
    fn from(v: &str) -> Self {
        Value::Text(v.to_string())
    }
}

impl From<String> for Value {
    fn from(v: String) -> Self {
        Value::Text(v)
    }
}

impl From<&[u8]> for Value {
    fn from(v: &[u8]) -> Self {
        Value::Bytes(v.to_vec())
    }
}

impl<T: Into<Value>> From<Option<T>> for Value {
    fn from(v: Option<T>) -> Self {
        v.map_or(Value::Null, Into::into)
    }
}

/// A row: its columns in the order selected.
pub type Row = Vec<Value>;

/// Which engine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dialect {
    /// PostgreSQL.
    Postgres,
    /// SQLite.
    Sqlite,
}

/// What went wrong in the database, in its own words, with what was being done.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DbError {
    /// The database (its address or file).
    pub database: String,
    /// What failed.
    pub message: String,
}

impl fmt::Display for DbError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.database, self.message)
    }
}

impl std::error::Error for DbError {}

/// A connection to one of the engines.
pub trait Db: Send {
    /// Which engine it is.
    fn dialect(&self) -> Dialect;
    /// Where it is (for messages): the file, or the server without credentials.
    fn name(&self) -> &str;
    /// Runs a statement; returns the rows it changed.
    fn execute(&mut self, sql: &str, params: &[Value]) -> Result<u64, DbError>;
    /// Runs a query; returns its rows.
    fn query(&mut self, sql: &str, params: &[Value]) -> Result<Vec<Row>, DbError>;
    /// Runs several statements without parameters (a migration).
    fn batch(&mut self, sql: &str) -> Result<(), DbError>;
    /// Starts a transaction (serialised against other writers as the engine does); inside
    /// one, a savepoint: a batch of reports is one transaction, each report a savepoint in
    /// it, so a refused report undoes only its own writes.
    fn begin(&mut self) -> Result<(), DbError>;
    /// Commits it (releases the savepoint).
    fn commit(&mut self) -> Result<(), DbError>;
    /// Abandons it (back to the savepoint).
    fn rollback(&mut self) -> Result<(), DbError>;
}

/// Runs `work` in a transaction: committed if it succeeds, rolled back if not.
pub fn transaction<T, E: From<DbError>>(
    db: &mut dyn Db,
    work: impl FnOnce(&mut dyn Db) -> Result<T, E>,
) -> Result<T, E> {
    db.begin()?;
    match work(db) {
        Ok(value) => {
            db.commit()?;
            Ok(value)
        }
        Err(error) => {
            // The first error is the one to report; a failed rollback ends the transaction
            // anyway (the connection drops it).
            let _ = db.rollback();
            Err(error)
        }
    }
}

/// The statement that starts a transaction at `depth` (0: the outer one, `outer`).
pub(crate) fn begin_sql(depth: usize, outer: &str) -> String {
    if depth == 0 {
        outer.to_string()
    } else {
        format!("SAVEPOINT nested_{depth}")
    }
}

/// The statement that commits the transaction at `depth` (counted after it ends).
pub(crate) fn commit_sql(depth: usize) -> String {
    if depth == 0 {
        "COMMIT".to_string()
    } else {
        format!("RELEASE SAVEPOINT nested_{depth}")
    }
}

/// The statement that abandons the transaction at `depth` (counted after it ends).
pub(crate) fn rollback_sql(depth: usize) -> String {
    if depth == 0 {
        "ROLLBACK".to_string()
    } else {
        format!("ROLLBACK TO SAVEPOINT nested_{depth}; RELEASE SAVEPOINT nested_{depth}")
    }
}

/// PostgreSQL's `$N` parameters in SQLite's numbered form `?N` (same meaning). The store's
/// statements hold no `$` in literals, so every `$` followed by digits is a parameter.
pub(crate) fn sqlite_placeholders(sql: &str) -> String {
    let mut out = String::with_capacity(sql.len());
    let mut chars = sql.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '$' && chars.peek().is_some_and(char::is_ascii_digit) {
            out.push('?');
        } else {
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn placeholders_keep_their_numbers() {
        assert_eq!(
            sqlite_placeholders("SELECT a FROM t WHERE b = $2 AND c > $1 AND d = '$x'"),
            "SELECT a FROM t WHERE b = ?2 AND c > ?1 AND d = '$x'"
        );
    }
}
