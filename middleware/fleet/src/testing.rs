//! For tests of the fleet against the real servers, here and in the crates that use it:
//! where the PostgreSQL server and the broker are (`AUTOPLUG_TEST_POSTGRES`,
//! `AUTOPLUG_TEST_MQTT`; defaults: the local servers on their standard ports), and a
//! throwaway schema per test on the server, so tests running at once never see each
//! other's rows; and a broker of a test's own, run from the shipped configuration.

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

/// A Mosquitto of the test's own, run from the project's broker configuration (logins and
/// rights in the dynamic-security plugin, persistence) on free ports; killed when dropped.
/// The binary: `$MOSQUITTO`, else
/// `/usr/sbin/mosquitto`, else `mosquitto` on the PATH.
pub struct PrivateBroker {
    /// Its directory (removed when dropped).
    pub dir: std::path::PathBuf,
    /// Its configuration's files.
    pub files: crate::broker::BrokerDir,
    /// The vehicles' listener.
    pub port: u16,
    /// The fleet services' listener.
    pub fleet_port: u16,
    child: std::process::Child,
}

impl PrivateBroker {
    /// Starts one; panics naming what is missing (a test helper).
    pub fn start() -> Self {
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let dir = std::env::temp_dir().join(format!(
            "autoplug-broker-{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let free = || {
            std::net::TcpListener::bind("127.0.0.1:0")
                .unwrap()
                .local_addr()
                .unwrap()
                .port()
        };
        let (port, fleet_port) = (free(), free());
        let files = crate::broker::init(
            &dir.join("broker"),
            "127.0.0.1",
            port,
            "127.0.0.1",
            fleet_port,
        )
        .unwrap();
        let child = Self::spawn(&files);
        let broker = Self {
            dir,
            files,
            port,
            fleet_port,
            child,
        };
        broker.wait_listening();
        broker
    }

    fn spawn(files: &crate::broker::BrokerDir) -> std::process::Child {
        let binary = std::env::var("MOSQUITTO").unwrap_or_else(|_| {
            if std::path::Path::new("/usr/sbin/mosquitto").exists() {
                "/usr/sbin/mosquitto".into()
            } else {
                "mosquitto".into()
            }
        });
        std::process::Command::new(&binary)
            .arg("-c")
            .arg(&files.config)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap_or_else(|e| {
                panic!("cannot run {binary} (scripts/setup-tests installs Mosquitto): {e}")
            })
    }

    fn wait_listening(&self) {
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(10);
        for port in [self.port, self.fleet_port] {
            while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
                assert!(
                    std::time::Instant::now() < deadline,
                    "mosquitto did not listen on {port}"
                );
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
        }
    }

    /// Adds a login to the running broker (through the plugin's control topic, as
    /// `autoplug fleet broker add` does).
    pub fn add_login(&self, user: &str, password: &str) {
        crate::broker::add_login(&self.files, user, password).unwrap();
    }

    /// Adds many logins at once.
    pub fn add_logins(&self, logins: &[(String, String)]) {
        crate::broker::add_logins(&self.files, logins).unwrap();
    }

    /// The address for `user` with `password`: the fleet services' listener for the
    /// fleet's login, the vehicles' for any other.
    pub fn url(&self, user: &str, password: &str) -> crate::mqtt::Broker {
        let port = if user == crate::broker::FLEET_USER {
            self.fleet_port
        } else {
            self.port
        };
        self.url_at(port, user, password)
    }

    /// The address of the listener on `port` for `user` with `password`.
    pub fn url_at(&self, port: u16, user: &str, password: &str) -> crate::mqtt::Broker {
        format!("mqtt://{user}:{password}@127.0.0.1:{port}")
            .parse()
            .unwrap()
    }

    /// Stops the broker as a restart would (SIGTERM: it saves its persistence) and starts it
    /// again from the same directory.
    pub fn restart(&mut self) {
        let _ = std::process::Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status();
        let _ = self.child.wait();
        self.child = Self::spawn(&self.files);
        self.wait_listening();
    }
}

impl Drop for PrivateBroker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A trip report numbered `n` of `vin` (a short standing trip: every figure plausible).
pub fn trip_report(vin: &autoplug_vin::Vin, n: i64) -> crate::TripReport {
    crate::TripReport {
        vin: vin.to_string(),
        trip: n,
        started_at_ms: n * 1000,
        ended_at_ms: n * 1000 + 500,
        stats: autoplug_trips::TripStats::default(),
        end: autoplug_trips::TripEnd::Parked,
        verdicts: Vec::new(),
        dtcs: Vec::new(),
    }
}

/// A fleet service's intake as `autoplug fleet serve` runs it (a session that ends with
/// the connection, the shared subscription, manual acks, batches, receipts) as `client_id` on `broker`, storing into
/// `store`, on a thread of its own until `stop`; it returns what it did and its link's
/// state. Waits for the subscription before it returns; panics naming what failed (a
/// test and benchmark helper).
pub fn intake_thread(
    runtime: &tokio::runtime::Handle,
    broker: &crate::mqtt::Broker,
    client_id: &str,
    store: crate::FleetStore,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> std::thread::JoinHandle<(crate::ingest::IngestStats, crate::mqtt::LinkStatus)> {
    use std::time::{Duration, Instant};
    let mut options = crate::mqtt::service_options(client_id);
    options.subscriptions = vec![crate::topics::REPORTS_SHARED.to_string()];
    options.max_backoff = Duration::from_secs(1);
    let link = crate::mqtt::MqttLink::connect(runtime, broker, options);
    link.wait_connected(Duration::from_secs(10)).unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    while link.status().granted.is_empty() {
        assert!(Instant::now() < deadline, "no SUBACK: {:?}", link.status());
        std::thread::sleep(Duration::from_millis(10));
    }
    std::thread::spawn(move || {
        let mut ingest = crate::ingest::Ingest::new(store, link);
        ingest.run(&stop, Duration::from_millis(50), |_| {});
        (ingest.stats, ingest.link.status())
    })
}

/// A trip numbered `n` of `vin` as a drive reports it (statistics, the presence verdict of
/// each of the nine ECUs, the cruise control faulty with a trouble code on one trip in
/// 50): what the fleet's benchmarks store.
pub fn trip_with_evidence(vin: &autoplug_vin::Vin, n: i64) -> crate::TripReport {
    use autoplug_store::{DtcRecord, VerdictRecord};
    let ended = 1_790_000_000_000 + n * 3_600_000;
    let faulty = n % 50 == 0;
    crate::TripReport {
        vin: vin.to_string(),
        trip: n,
        started_at_ms: ended - 600_000,
        ended_at_ms: ended,
        stats: autoplug_trips::TripStats {
            duration_s: 600.0,
            distance_m: 14_000.0 + (n % 100) as f64,
            max_speed_kmh: 110.0,
            ..autoplug_trips::TripStats::default()
        },
        end: autoplug_trips::TripEnd::BusSilent,
        verdicts: ecus()
            .map(|(ecu, _)| VerdictRecord {
                ecu: ecu.to_string(),
                routine: "presence".into(),
                verdict: if faulty && ecu == "cruise" {
                    "faulty"
                } else {
                    "ok"
                }
                .into(),
                number: Some(0.2),
                unit: "%".into(),
                suspect_above: 5.0,
                faulty_above: 20.0,
                window_s: Some((0.0, 600.0)),
                evidence: "frames on time".into(),
            })
            .collect(),
        dtcs: if faulty {
            vec![DtcRecord {
                ecu: "cruise".into(),
                code: "U0140-87".into(),
                status: 0x09,
                description: "lost communication with the body control module".into(),
            }]
        } else {
            Vec::new()
        },
    }
}

/// A car as the gateway reports: its reports in an outbox until the fleet's receipt, sent
/// again while none comes (after `resend_after_ms`, doubling), over a persistent session
/// with its VIN as client id. It publishes `trips` trips one every `pace` and returns once
/// every one is confirmed (or after `deadline`), with its outbox, its link's state and
/// how long each confirmed report waited for its receipt since its first publish, ms.
pub fn reporting_car(
    runtime: &tokio::runtime::Handle,
    broker: &crate::mqtt::Broker,
    vin: autoplug_vin::Vin,
    trips: usize,
    pace: std::time::Duration,
    resend_after_ms: i64,
    deadline: std::time::Duration,
) -> std::thread::JoinHandle<(crate::outbox::Outbox, crate::mqtt::LinkStatus, Vec<i64>)> {
    reporting_car_with(
        runtime,
        broker,
        vin,
        trips,
        pace,
        resend_after_ms,
        deadline,
        trip_report,
    )
}

/// [`reporting_car`] with its trips made by `make` (the VIN and the trip's number, from 1).
#[allow(clippy::too_many_arguments)]
pub fn reporting_car_with(
    runtime: &tokio::runtime::Handle,
    broker: &crate::mqtt::Broker,
    vin: autoplug_vin::Vin,
    trips: usize,
    pace: std::time::Duration,
    resend_after_ms: i64,
    deadline: std::time::Duration,
    make: impl Fn(&autoplug_vin::Vin, i64) -> crate::TripReport + Send + 'static,
) -> std::thread::JoinHandle<(crate::outbox::Outbox, crate::mqtt::LinkStatus, Vec<i64>)> {
    use std::time::{Duration, Instant};
    let mut options = crate::mqtt::LinkOptions::new(vin.to_string());
    options.persistent_session = true;
    options.subscriptions = vec![crate::topics::receipt(&vin)];
    options.max_backoff = Duration::from_millis(500);
    let mut link = crate::mqtt::MqttLink::connect(runtime, broker, options);
    std::thread::spawn(move || {
        let mut outbox = crate::outbox::Outbox::new(4096, resend_after_ms);
        let mut waits = Vec::with_capacity(trips);
        let started = Instant::now();
        let mut pushed = 0;
        let mut next = Instant::now();
        while started.elapsed() < deadline && (pushed < trips || !outbox.is_empty()) {
            if pushed < trips && Instant::now() >= next {
                pushed += 1;
                let report = serde_json::to_vec(&make(&vin, pushed as i64)).unwrap_or_default();
                outbox.push(
                    crate::topics::report(&vin, crate::topics::ReportKind::Trip),
                    report,
                );
                next += pace;
            }
            outbox.send_due(crate::unix_ms(), |topic, payload| {
                link.publish(topic, payload.to_vec(), false).is_ok()
            });
            // Woken by a receipt at once; otherwise at the next report due (or to send
            // again), so that a hundred idle cars do not spin.
            let wait = if pushed < trips {
                next.saturating_duration_since(Instant::now())
            } else {
                Duration::from_millis(50)
            };
            if let Some(message) = link.recv_timeout(wait.min(Duration::from_millis(50))) {
                if let Ok(Some((_, waited))) =
                    outbox.on_receipt_at(&message.payload, crate::unix_ms())
                {
                    waits.push(waited);
                }
            }
        }
        let status = link.status();
        (outbox, status, waits)
    })
}

/// The nine ECUs as the fleet's reports name them: the catalogue's short name and
/// diagnostic node number (what the plausibility checks accept).
pub fn ecus() -> impl Iterator<Item = (&'static str, u8)> {
    autoplug_can::ECUS.into_iter().map(|node| {
        (
            autoplug_can::ecu_name(node),
            node.diag_node_number().unwrap_or(0),
        )
    })
}
