//! For tests of the fleet against the real servers, here and in the crates that use it:
//! where the PostgreSQL server and the broker are (`AUTOPLUG_TEST_POSTGRES`,
//! `AUTOPLUG_TEST_MQTT`; defaults: the local servers on their standard ports), and a
//! throwaway schema per test on the server, so tests running at once never see each
//! other's rows; and a broker of a test's own, run from the shipped configuration.

use std::sync::atomic::{AtomicU32, Ordering};

/// A free loopback port for a test's own server, below the kernel's ephemeral range: a port
/// found free in that range may be taken by any outgoing connection's source port before
/// the server binds it (a cluster node failed so in CI, "address already in use"). Never
/// the same port twice in one process; spread by process id across processes.
pub fn free_port() -> u16 {
    use std::collections::BTreeSet;
    use std::sync::Mutex;
    static TAKEN: Mutex<BTreeSet<u16>> = Mutex::new(BTreeSet::new());
    let ephemeral_start = std::fs::read_to_string("/proc/sys/net/ipv4/ip_local_port_range")
        .ok()
        .and_then(|range| range.split_whitespace().next()?.parse::<u32>().ok())
        .unwrap_or(32768)
        .clamp(12_000, 65_535);
    let (low, span) = (10_000u32, ephemeral_start - 10_000);
    let mut taken = TAKEN.lock().unwrap_or_else(|e| e.into_inner());
    let start = std::process::id().wrapping_mul(2_654_435_761) % span;
    for i in 0..span {
        // A stride coprime with most spans walks the range without repeats.
        let port = (low + (start + i * 7_919) % span) as u16;
        if taken.contains(&port) {
            continue;
        }
        if std::net::TcpListener::bind(("127.0.0.1", port)).is_ok() {
            taken.insert(port);
            return port;
        }
    }
    panic!("no free loopback port between {low} and {ephemeral_start}")
}

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
        let (port, fleet_port) = (free_port(), free_port());
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

/// A NATS cluster of the test's own (the clustered engine), run from the configuration
/// `autoplug fleet broker init --engine nats` writes, on free loopback ports, each node a
/// process that can be killed and started again; killed when dropped. The binary:
/// `$NATS_SERVER`, else `/usr/sbin/nats-server`, else `nats-server` on the PATH.
pub struct PrivateCluster {
    /// Its directory (removed when dropped).
    pub dir: std::path::PathBuf,
    /// Its configuration's files.
    pub files: crate::nats_cluster::ClusterDir,
    /// The nodes' addresses.
    pub nodes: Vec<crate::nats_cluster::NodeAddress>,
    children: Vec<Option<std::process::Child>>,
}

impl PrivateCluster {
    /// Starts `nodes` nodes and waits until every one listens and JetStream answers
    /// (a cluster: has a leader); panics naming what is missing (a test helper).
    pub fn start(nodes: usize) -> Self {
        static NEXT: AtomicU32 = AtomicU32::new(0);
        let dir = std::env::temp_dir().join(format!(
            "autoplug-nats-{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&dir);
        // Three ports a node.
        let addresses: Vec<crate::nats_cluster::NodeAddress> = (0..nodes)
            .map(|_| crate::nats_cluster::NodeAddress {
                host: "127.0.0.1".into(),
                mqtt_port: free_port(),
                client_port: free_port(),
                cluster_port: free_port(),
            })
            .collect();
        let files = crate::nats_cluster::init(&dir, &addresses).unwrap();
        let mut cluster = Self {
            dir,
            files,
            nodes: addresses,
            children: (0..nodes).map(|_| None).collect(),
        };
        // A login of its own to warm the cluster up with (a test's own logins come after).
        let warm = format!("warm-{}", std::process::id());
        crate::nats_cluster::add_logins(
            &cluster.files,
            &[(crate::broker::FLEET_USER.into(), warm.clone(), false)],
        )
        .unwrap();
        for n in 0..nodes {
            cluster.start_node(n);
        }
        cluster.warm_up(&warm);
        cluster
    }

    /// Waits until JetStream answers (the cluster elected its leader) and the MQTT side's
    /// own streams are made (the first QoS 1 subscription makes them): otherwise a test's
    /// first cars race the cluster's start, and a subscription made then times out.
    fn warm_up(&self, password: &str) {
        use std::time::{Duration, Instant};
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let servers = self.nats_url(&[0], crate::broker::FLEET_USER, password);
        let deadline = Instant::now() + Duration::from_secs(30);
        runtime.block_on(async {
            let client = async_nats::ConnectOptions::with_user_and_password(
                crate::broker::FLEET_USER.into(),
                password.into(),
            )
            .connect(format!("127.0.0.1:{}", self.nodes[0].client_port))
            .await
            .unwrap_or_else(|e| panic!("{servers}: {e}"));
            let js = async_nats::jetstream::new(client);
            // A stream that is not there: "not found" is JetStream answering.
            loop {
                match js.get_stream("AUTOPLUG_WARM_UP").await {
                    Err(e) if e.to_string().contains("not found") => break,
                    Ok(_) => break,
                    Err(e) => assert!(
                        Instant::now() < deadline,
                        "JetStream did not answer ({e}): {}",
                        self.log(0)
                    ),
                }
                tokio::time::sleep(Duration::from_millis(100)).await;
            }
        });
        let mut options = crate::mqtt::LinkOptions::new(format!("warm-{}", std::process::id()));
        options.subscriptions = vec!["autoplug/v1/warm-up".into()];
        let link = crate::mqtt::MqttLink::connect(
            runtime.handle(),
            &self.mqtt_url(&[0], crate::broker::FLEET_USER, password),
            options,
        );
        while link.status().granted.is_empty() {
            assert!(
                Instant::now() < deadline,
                "no MQTT subscription: {:?}",
                link.status()
            );
            runtime.block_on(async { tokio::time::sleep(Duration::from_millis(50)).await });
        }
    }

    /// Starts node `n` (from 0) and waits until it listens.
    pub fn start_node(&mut self, n: usize) {
        let binary = std::env::var("NATS_SERVER").unwrap_or_else(|_| {
            if std::path::Path::new("/usr/sbin/nats-server").exists() {
                "/usr/sbin/nats-server".into()
            } else {
                "nats-server".into()
            }
        });
        let log = std::fs::File::create(self.dir.join(format!("node-{}.log", n + 1))).unwrap();
        let child = std::process::Command::new(&binary)
            .arg("-c")
            .arg(self.files.node_config(n + 1))
            .stdout(std::process::Stdio::null())
            .stderr(log)
            .spawn()
            .unwrap_or_else(|e| {
                panic!("cannot run {binary} (scripts/setup-tests installs nats-server): {e}")
            });
        self.children[n] = Some(child);
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(20);
        let node = &self.nodes[n];
        for port in [node.client_port, node.mqtt_port] {
            while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
                assert!(
                    std::time::Instant::now() < deadline,
                    "nats-server node {} did not listen on {port}: {}",
                    n + 1,
                    self.log(n)
                );
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
        }
    }

    /// Kills node `n` (SIGKILL: a machine lost), waiting for it to end.
    pub fn kill_node(&mut self, n: usize) {
        if let Some(mut child) = self.children[n].take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }

    /// Node `n`'s log so far.
    pub fn log(&self, n: usize) -> String {
        std::fs::read_to_string(self.dir.join(format!("node-{}.log", n + 1))).unwrap_or_default()
    }

    /// Adds logins and has the running nodes reload them.
    pub fn add_logins(&self, logins: &[(String, String)]) {
        let logins: Vec<(String, String, bool)> = logins
            .iter()
            .map(|(u, p)| (u.clone(), p.clone(), false))
            .collect();
        crate::nats_cluster::add_logins(&self.files, &logins).unwrap();
        // A reload is asynchronous: give the nodes a moment to read the file.
        std::thread::sleep(std::time::Duration::from_millis(300));
    }

    /// The cars' MQTT address over `nodes` (from 0, in that order) as `user`.
    pub fn mqtt_url(&self, nodes: &[usize], user: &str, password: &str) -> crate::mqtt::Broker {
        let hosts: Vec<String> = nodes
            .iter()
            .map(|&n| format!("127.0.0.1:{}", self.nodes[n].mqtt_port))
            .collect();
        format!("mqtt://{user}:{password}@{}", hosts.join(","))
            .parse()
            .unwrap()
    }

    /// The services' NATS address over `nodes` as `user`.
    pub fn nats_url(
        &self,
        nodes: &[usize],
        user: &str,
        password: &str,
    ) -> crate::nats::NatsServers {
        let hosts: Vec<String> = nodes
            .iter()
            .map(|&n| format!("127.0.0.1:{}", self.nodes[n].client_port))
            .collect();
        format!("nats://{user}:{password}@{}", hosts.join(","))
            .parse()
            .unwrap()
    }
}

impl Drop for PrivateCluster {
    fn drop(&mut self) {
        for n in 0..self.children.len() {
            self.kill_node(n);
        }
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.dir);
        }
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
    run_intake(crate::ingest::Ingest::new(store, link), stop)
}

/// Runs `ingest` on a thread named "intake" (so that a benchmark can tell the services'
/// CPU time from the cars') until `stop`.
fn run_intake(
    mut ingest: crate::ingest::Ingest,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> std::thread::JoinHandle<(crate::ingest::IngestStats, crate::mqtt::LinkStatus)> {
    std::thread::Builder::new()
        .name("intake".into())
        .spawn(move || {
            ingest.run(&stop, std::time::Duration::from_millis(50), |_| {});
            (ingest.stats, ingest.link.status())
        })
        .unwrap()
}

/// A fleet service's intake on the clustered engine, as `autoplug fleet serve --queue`
/// runs it: reports pulled from the work queue at `servers`, receipts over an MQTT
/// connection to `broker`, on a thread of its own until `stop`; returns what it did.
pub fn queue_intake_thread(
    runtime: &tokio::runtime::Handle,
    broker: &crate::mqtt::Broker,
    servers: &crate::nats::NatsServers,
    client_id: &str,
    store: crate::FleetStore,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> std::thread::JoinHandle<(crate::ingest::IngestStats, crate::mqtt::LinkStatus)> {
    use std::time::Duration;
    let mut options = crate::mqtt::service_options(client_id);
    options.max_backoff = Duration::from_secs(1);
    let link = crate::mqtt::MqttLink::connect(runtime, broker, options);
    link.wait_connected(Duration::from_secs(10)).unwrap();
    let mut queue = crate::nats::WorkQueue::connect(runtime, servers, client_id).unwrap();
    queue.wait_ready(Duration::from_secs(20)).unwrap();
    run_intake(crate::ingest::Ingest::with_queue(store, link, queue), stop)
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
/// with its client id ([`crate::mqtt::vehicle_client_id`]). It publishes `trips` trips one every `pace` and returns once
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
    let mut options = crate::mqtt::LinkOptions::new(crate::mqtt::vehicle_client_id(
        vin.as_str(),
        broker.password.as_deref(),
    ));
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
            // As the gateway: not before its receipts can come.
            if link.subscribed(&crate::topics::receipt(&vin)) {
                outbox.send_due(crate::unix_ms(), |topic, payload| {
                    link.publish(topic, payload.to_vec(), false).is_ok()
                });
            }
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
