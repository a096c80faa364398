//! For tests of the fleet against the real servers, here and in the crates that use it:
//! where the PostgreSQL server and the broker are (`AUTOPLUG_TEST_POSTGRES`,
//! `AUTOPLUG_TEST_MQTT`; defaults: the local servers on their standard ports), and a
//! throwaway schema per test on the server, so tests running at once never see each
//! other's rows.

use std::sync::atomic::{AtomicU32, Ordering};

/// The broker the tests use: `AUTOPLUG_TEST_MQTT`, default the local Mosquitto.
pub fn broker_url() -> String {
    std::env::var("AUTOPLUG_TEST_MQTT").unwrap_or_else(|_| "mqtt://127.0.0.1:1883".to_string())
}

/// The PostgreSQL server the tests use.
pub fn postgres_url() -> String {
    std::env::var("AUTOPLUG_TEST_POSTGRES")
        .unwrap_or_else(|_| "postgresql://postgres@127.0.0.1:5432/test".to_string())
}

/// A schema on the test server, dropped with everything in it when this is dropped.
pub struct PgSchema {
    /// The address of the server with this schema first in the search path.
    pub url: String,
    name: String,
}

impl PgSchema {
    /// Creates a fresh schema; panics naming the server when it cannot (a test helper).
    #[allow(clippy::new_without_default)]
    pub fn new() -> Self {
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let name = format!(
            "fleet_test_{}_{}_{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed),
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.subsec_nanos())
        );
        let base = postgres_url();
        let mut admin = postgres::Client::connect(&base, postgres::NoTls).unwrap_or_else(|e| {
            panic!(
                "PostgreSQL at {base} (AUTOPLUG_TEST_POSTGRES): {e}; scripts/setup-tests installs and starts one"
            )
        });
        admin
            .batch_execute(&format!("CREATE SCHEMA {name}"))
            .unwrap_or_else(|e| panic!("cannot create schema {name} at {base}: {e}"));
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
