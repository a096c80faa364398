//! The versioned schema: a list of migrations, oldest first. A database's `user_version` is
//! the number of them it has run; opening it runs the rest, in one transaction.
//!
//! To change the schema, append a migration (`M::up(include_str!("schema/v2.sql"))`); never
//! edit one that has shipped, as databases in the field have run it already.

use rusqlite_migration::{Migrations, M};

/// The migrations: version `n` of the schema is the state after the first `n`.
const MIGRATIONS: &[M<'static>] = &[
    // 1: trips, verdicts, trouble codes, series, ECU inventory.
    M::up(include_str!("schema/v1.sql")),
];

/// The newest schema version this program knows.
pub const SCHEMA_VERSION: usize = MIGRATIONS.len();

/// `PRAGMA application_id` of an AutoPlug database ("APLG"), set by migration 1.
pub const APPLICATION_ID: i64 = 0x4150_4C47;

/// The migrations, for `to_latest`.
pub(crate) fn migrations() -> Migrations<'static> {
    Migrations::from_slice(MIGRATIONS)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn migrations_are_valid_sql() {
        // Runs every migration on an empty in-memory database (rusqlite_migration's check).
        assert_eq!(migrations().validate(), Ok(()));
    }

    #[test]
    fn migration_1_sets_the_application_id() {
        let mut conn = rusqlite::Connection::open_in_memory().unwrap();
        migrations().to_latest(&mut conn).unwrap();
        let id: i64 = conn
            .query_row("PRAGMA application_id", [], |r| r.get(0))
            .unwrap();
        assert_eq!(id, APPLICATION_ID);
        let version: i64 = conn
            .query_row("PRAGMA user_version", [], |r| r.get(0))
            .unwrap();
        assert_eq!(usize::try_from(version), Ok(SCHEMA_VERSION));
    }
}
