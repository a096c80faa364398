//! The two engines every fleet test runs on: a fresh SQLite file, and a schema of its own on
//! the PostgreSQL server at `AUTOPLUG_TEST_POSTGRES` (default: the local server, database
//! `test`). The real server, never a stand-in: a test fails, naming the address, when it is
//! not there (`scripts/setup` installs and starts one).

#![allow(dead_code)]

use std::sync::atomic::{AtomicU32, Ordering};

use autoplug_fleet::FleetStore;

/// The PostgreSQL server the tests use.
pub fn postgres_url() -> String {
    std::env::var("AUTOPLUG_TEST_POSTGRES")
        .unwrap_or_else(|_| "postgresql://postgres@127.0.0.1:5432/test".to_string())
}

/// A schema on the test server, dropped with everything in it when this is dropped.
pub struct PgSchema {
    pub url: String,
    name: String,
}

impl PgSchema {
    pub fn new() -> Self {
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let name = format!(
            "fleet_test_{}_{}_{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed),
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .unwrap()
                .subsec_nanos()
        );
        let base = postgres_url();
        let mut admin = postgres::Client::connect(&base, postgres::NoTls).unwrap_or_else(|e| {
            panic!(
                "PostgreSQL at {base} (AUTOPLUG_TEST_POSTGRES): {e}; scripts/setup installs and starts one"
            )
        });
        admin
            .batch_execute(&format!("CREATE SCHEMA {name}"))
            .unwrap();
        let separator = if base.contains('?') { '&' } else { '?' };
        let url = format!("{base}{separator}options=-csearch_path%3D{name}");
        Self { url, name }
    }
}

impl Drop for PgSchema {
    fn drop(&mut self) {
        if let Ok(mut admin) = postgres::Client::connect(&postgres_url(), postgres::NoTls) {
            let _ = admin.batch_execute(&format!("DROP SCHEMA IF EXISTS {} CASCADE", self.name));
        }
    }
}

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
