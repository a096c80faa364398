//! The two engines every fleet test runs on: a fresh SQLite file, and a schema of its own on
//! the PostgreSQL server at `AUTOPLUG_TEST_POSTGRES` (default: the local server, database
//! `test`). The real server, never a stand-in: a test fails, naming the address, when it is
//! not there (`scripts/setup-tests` installs and starts one).

#![allow(dead_code)]

use autoplug_fleet::FleetStore;

#[allow(unused_imports)]
pub use autoplug_fleet::testing::{broker_url, postgres_url, PgSchema, PrivateBroker};

/// A fresh store on one engine, and what keeps it alive.
pub enum Engine {
    Sqlite(tempfile::TempDir),
    Postgres(PgSchema),
}

impl Engine {
    pub fn label(&self) -> &'static str {
        match self {
            Engine::Sqlite(_) => "SQLite",
            Engine::Postgres(_) => "PostgreSQL",
        }
    }

    /// The address `FleetStore::open` takes.
    pub fn address(&self) -> String {
        match self {
            Engine::Sqlite(dir) => dir.path().join("fleet.db").display().to_string(),
            Engine::Postgres(schema) => schema.url.clone(),
        }
    }

    pub fn open(&self) -> FleetStore {
        FleetStore::open(&self.address()).unwrap_or_else(|e| panic!("{}: {e}", self.label()))
    }
}

/// Both engines, fresh.
pub fn engines() -> [Engine; 2] {
    [
        Engine::Sqlite(tempfile::tempdir().unwrap()),
        Engine::Postgres(PgSchema::new()),
    ]
}

/// A runtime for the tests' MQTT connections.
pub fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}
