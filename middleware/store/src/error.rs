//! What can go wrong, said in one short sentence that names the database.

use std::fmt;

use crate::model::{TripId, TripStatus};

/// An error of a [`crate::TripStore`]: the database it concerns and what went wrong.
///
/// Its `Display` is one short sentence, `"<database>: <what went wrong>"`, e.g.
/// `trips.db: file is not a database` or `trips.db: trip 12 does not exist`.
#[derive(Debug)]
pub struct StoreError {
    db: String,
    kind: StoreErrorKind,
}

/// What went wrong (see [`StoreError`]).
#[derive(Clone, Debug, PartialEq)]
#[non_exhaustive]
pub enum StoreErrorKind {
    /// The file could not be opened or created (the reason from the operating system or
    /// SQLite).
    CannotOpen(String),
    /// The file exists but is empty: not a database, and not one this program created.
    EmptyFile,
    /// The file is not an SQLite database (random bytes, a text file, ...).
    NotADatabase,
    /// An SQLite database, but another program's (the reason says how we can tell).
    ForeignDatabase(String),
    /// An AutoPlug database whose schema is newer than this program knows.
    NewerSchema {
        /// The database's schema version.
        found: usize,
        /// The newest version this program knows.
        known: usize,
    },
    /// The database can only be read (a read-only file, directory or file system).
    ReadOnly,
    /// Another program kept the database locked for longer than the busy timeout.
    Busy,
    /// The database file is damaged.
    Corrupt,
    /// The disk is full.
    DiskFull,
    /// The trip does not exist.
    NoSuchTrip(TripId),
    /// The trip can no longer be written: it is closed, or was interrupted.
    TripNotOpen(TripId, TripStatus),
    /// A value given to the store cannot be stored (the text says which).
    InvalidArgument(String),
    /// A value read from the database is not one this program writes (the text says which).
    UnexpectedValue(String),
    /// Any other database error (SQLite's message).
    Database(String),
}

impl StoreError {
    pub(crate) fn new(db: &str, kind: StoreErrorKind) -> Self {
        StoreError {
            db: db.to_owned(),
            kind,
        }
    }

    /// The database the error concerns: its path as given to `open`, or `:memory:`.
    pub fn db(&self) -> &str {
        &self.db
    }

    /// What went wrong.
    pub fn kind(&self) -> &StoreErrorKind {
        &self.kind
    }

    /// An error of SQLite on database `db`, sorted into a kind.
    pub(crate) fn sqlite(db: &str, err: rusqlite::Error) -> Self {
        use rusqlite::ErrorCode as C;
        let kind = match &err {
            rusqlite::Error::SqliteFailure(e, msg) => match e.code {
                C::NotADatabase => StoreErrorKind::NotADatabase,
                C::DatabaseCorrupt => StoreErrorKind::Corrupt,
                C::DatabaseBusy | C::DatabaseLocked => StoreErrorKind::Busy,
                C::ReadOnly => StoreErrorKind::ReadOnly,
                C::DiskFull => StoreErrorKind::DiskFull,
                C::CannotOpen => StoreErrorKind::CannotOpen(
                    msg.clone()
                        .unwrap_or_else(|| "unable to open database file".into()),
                ),
                _ => StoreErrorKind::Database(err.to_string()),
            },
            rusqlite::Error::FromSqlConversionFailure(..)
            | rusqlite::Error::IntegralValueOutOfRange(..)
            | rusqlite::Error::InvalidColumnType(..) => {
                StoreErrorKind::UnexpectedValue(err.to_string())
            }
            _ => StoreErrorKind::Database(err.to_string()),
        };
        StoreError::new(db, kind)
    }
}

impl fmt::Display for StoreError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.db, self.kind)
    }
}

impl fmt::Display for StoreErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StoreErrorKind::CannotOpen(why) => write!(f, "cannot open ({why})"),
            StoreErrorKind::EmptyFile => write!(
                f,
                "file is empty, not a database (delete it to start a new one)"
            ),
            StoreErrorKind::NotADatabase => write!(f, "file is not a database"),
            StoreErrorKind::ForeignDatabase(why) => {
                write!(f, "not an AutoPlug database ({why})")
            }
            StoreErrorKind::NewerSchema { found, known } => write!(
                f,
                "written by a newer AutoPlug (schema version {found} is newer than this program's {known})"
            ),
            StoreErrorKind::ReadOnly => write!(f, "cannot write (read-only file or location)"),
            StoreErrorKind::Busy => write!(f, "locked by another program for too long"),
            StoreErrorKind::Corrupt => write!(f, "database file is damaged"),
            StoreErrorKind::DiskFull => write!(f, "disk full"),
            StoreErrorKind::NoSuchTrip(id) => write!(f, "trip {id} does not exist"),
            StoreErrorKind::TripNotOpen(id, TripStatus::Interrupted) => write!(
                f,
                "trip {id} was interrupted (the gateway stopped during it) and cannot be written"
            ),
            StoreErrorKind::TripNotOpen(id, status) => {
                write!(f, "trip {id} is {} and cannot be written", status.name())
            }
            StoreErrorKind::InvalidArgument(why) => write!(f, "cannot store {why}"),
            StoreErrorKind::UnexpectedValue(why) => write!(f, "unexpected value ({why})"),
            StoreErrorKind::Database(why) => write!(f, "database error ({why})"),
        }
    }
}

impl std::error::Error for StoreError {}
