//! Fleet services that come and go: three `autoplug fleet serve` processes share the
//! reports of cars that report as the gateway does (outbox, receipts, resends) through a
//! broker run from the shipped configuration into PostgreSQL (`AUTOPLUG_TEST_POSTGRES`).
//! One of them stops mid-stream, cleanly (SIGTERM) or killed (SIGKILL), while the other
//! two run on: every report is stored exactly once, and none waits in the stopped
//! service's session (Mosquitto's issue 1747 with kept sessions). The same on the
//! clustered engine: a NATS cluster of three nodes, the services pulling the reports from
//! its work queue.

use std::path::Path;
use std::process::{Child, Command};
use std::time::{Duration, Instant};

use autoplug_fleet::broker::FLEET_USER;
use autoplug_fleet::outbox::Outbox;
use autoplug_fleet::testing::{reporting_car, PgSchema, PrivateBroker, PrivateCluster};
use autoplug_fleet::FleetStore;
use autoplug_vin::Vin;

const CARS: usize = 6;
const PER_CAR: usize = 60;

/// The fleet's messaging under test.
enum Messaging {
    /// One Mosquitto; the services share a subscription.
    Mosquitto(PrivateBroker),
    /// Three NATS nodes; the services pull from the work queue.
    Nats(PrivateCluster),
}

impl Messaging {
    fn start(nats: bool) -> Self {
        if nats {
            Messaging::Nats(PrivateCluster::start(3))
        } else {
            Messaging::Mosquitto(PrivateBroker::start())
        }
    }

    fn add_logins(&self, logins: &[(String, String)]) {
        match self {
            Messaging::Mosquitto(broker) => broker.add_logins(logins),
            Messaging::Nats(cluster) => cluster.add_logins(logins),
        }
    }

    /// `fleet serve`'s arguments for its reports and receipts; service `n` starts on node
    /// `n` of a cluster.
    fn service_args(&self, n: usize) -> Vec<String> {
        match self {
            Messaging::Mosquitto(broker) => vec![
                "--broker".into(),
                format!(
                    "mqtt://{FLEET_USER}:pw-fleet@127.0.0.1:{}",
                    broker.fleet_port
                ),
                "--group".into(),
                "scale-in".into(),
            ],
            Messaging::Nats(cluster) => {
                let nodes = [n % 3, (n + 1) % 3, (n + 2) % 3];
                vec![
                    "--broker".into(),
                    cluster.mqtt_url(&nodes, FLEET_USER, "pw-fleet").to_string(),
                    "--broker-password-file".into(),
                    cluster.dir.join("fleet-password").display().to_string(),
                    "--queue".into(),
                    cluster.nats_url(&nodes, FLEET_USER, "pw-fleet").to_string(),
                    "--queue-password-file".into(),
                    cluster.dir.join("fleet-password").display().to_string(),
                ]
            }
        }
    }

    /// A car's address (a cluster's nodes from car `n`'s own on).
    fn car_url(&self, n: usize, vin: &Vin) -> autoplug_fleet::mqtt::Broker {
        let password = format!("pw-{vin}");
        match self {
            Messaging::Mosquitto(broker) => broker.url(vin.as_str(), &password),
            Messaging::Nats(cluster) => {
                cluster.mqtt_url(&[n % 3, (n + 1) % 3, (n + 2) % 3], vin.as_str(), &password)
            }
        }
    }
}

/// A `fleet serve` process number `n`, its output in `dir`.
fn start_service(
    messaging: &Messaging,
    schema: &PgSchema,
    n: usize,
    name: &str,
    dir: &Path,
) -> Child {
    let out = std::fs::File::create(dir.join(format!("{name}.out"))).unwrap();
    let err = std::fs::File::create(dir.join(format!("{name}.err"))).unwrap();
    Command::new(env!("CARGO_BIN_EXE_autoplug"))
        .args(["fleet", "serve", "--db", &schema.url, "--client-id", name])
        .args(messaging.service_args(n))
        .stdout(out)
        .stderr(err)
        .spawn()
        .unwrap()
}

fn output(dir: &Path, name: &str) -> String {
    std::fs::read_to_string(dir.join(format!("{name}.out"))).unwrap_or_default()
        + &std::fs::read_to_string(dir.join(format!("{name}.err"))).unwrap_or_default()
}

fn count(store: &mut FleetStore, sql: &str) -> i64 {
    store.db().query(sql, &[]).unwrap()[0][0].int().unwrap()
}

/// Runs the scenario with service 0 stopped by `signal` a second in; returns the
/// cars' outboxes and how long each report waited for its receipt (ms), and the stopped
/// service's output.
fn scale_in(nats: bool, signal: &str, resend_after_ms: i64) -> (Vec<Outbox>, Vec<i64>, String) {
    let broker = Messaging::start(nats);
    if let Messaging::Nats(cluster) = &broker {
        std::fs::write(cluster.dir.join("fleet-password"), "pw-fleet\n").unwrap();
    }
    let vins: Vec<Vin> = (0..CARS)
        .map(|i| {
            Vin::with_check_digit(&format!(
                "JA3AP47H0YS{:06}",
                std::process::id() % 1000 * 100 + i as u32
            ))
            .unwrap()
        })
        .collect();
    let mut logins = vec![(FLEET_USER.to_string(), "pw-fleet".to_string())];
    logins.extend(vins.iter().map(|v| (v.to_string(), format!("pw-{v}"))));
    broker.add_logins(&logins);
    let schema = PgSchema::new();
    let dir = tempfile::tempdir().unwrap();
    let names = ["fleet-0", "fleet-1", "fleet-2"];
    // Service 0 starts alone and the others join once it has stored trips: the one that
    // is stopped must have taken part. (With all three pulling from the start, the first
    // third of the stream could go to the other two, and once on the cluster it did.)
    let mut services = vec![start_service(&broker, &schema, 0, names[0], dir.path())];
    let deadline = Instant::now() + Duration::from_secs(30);
    let ready = if nats {
        "the work queue is ready"
    } else {
        "fleet service:"
    };
    while !output(dir.path(), names[0]).contains(ready) {
        assert!(
            Instant::now() < deadline,
            "{} did not start: {}",
            names[0],
            output(dir.path(), names[0])
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // Its subscription answered (the line comes once connected).
    std::thread::sleep(Duration::from_millis(500));
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let cars: Vec<_> = vins
        .iter()
        .enumerate()
        .map(|(i, v)| {
            reporting_car(
                runtime.handle(),
                &broker.car_url(i, v),
                *v,
                PER_CAR,
                Duration::from_millis(50),
                resend_after_ms,
                Duration::from_secs(60),
            )
        })
        .collect();
    // A third of the way through the stream, service 0 goes, while the database holds
    // every service up (a lock on the trips), so that reports wait in flight at each
    // service when it goes. A third counted in stored trips, not in time: on a loaded
    // machine the cars may take a second to start, and a service stopped before the
    // stream reached it has nothing to show.
    let mut watch = FleetStore::open(&schema.url).unwrap();
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut joined = false;
    loop {
        let stored = count(&mut watch, "SELECT count(*) FROM trips");
        if !joined && stored >= CARS as i64 {
            // Service 0 has stored trips of its own: the other two join, while the stream
            // goes on (they start in well under the second the stream's next third takes).
            services.extend(
                (1..names.len()).map(|i| start_service(&broker, &schema, i, names[i], dir.path())),
            );
            joined = true;
        }
        if joined && stored >= (CARS * PER_CAR) as i64 / 3 {
            break;
        }
        assert!(Instant::now() < deadline, "the stream did not get going");
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(watch);
    let mut lock = FleetStore::open(&schema.url).unwrap();
    lock.db().begin().unwrap();
    lock.db()
        .batch("LOCK TABLE trips IN EXCLUSIVE MODE")
        .unwrap();
    std::thread::sleep(Duration::from_millis(700));
    let status = Command::new("kill")
        .args([signal, &services[0].id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    std::thread::sleep(Duration::from_millis(300));
    lock.db().rollback().unwrap();
    let stopped = services[0].wait().unwrap();
    let outcomes: Vec<_> = cars.into_iter().map(|c| c.join().unwrap()).collect();
    for service in &mut services[1..] {
        let _ = Command::new("kill")
            .args(["-TERM", &service.id().to_string()])
            .status();
        let end = service.wait().unwrap();
        assert!(end.success(), "a service ended with {end}");
    }
    let mut store = FleetStore::open(&schema.url).unwrap();
    let total = (CARS * PER_CAR) as i64;
    assert_eq!(count(&mut store, "SELECT count(*) FROM trips"), total);
    assert_eq!(
        count(
            &mut store,
            "SELECT count(*) FROM (SELECT vin, trip FROM trips GROUP BY vin, trip HAVING count(*) > 1) t"
        ),
        0
    );
    let stopped_output = output(dir.path(), names[0]);
    if signal == "-TERM" {
        assert!(stopped.success(), "{stopped}: {stopped_output}");
    }
    let mut waits = Vec::new();
    let mut outboxes = Vec::new();
    for (outbox, _, car_waits) in outcomes {
        assert!(
            outbox.is_empty(),
            "a car still waits for {} receipts",
            outbox.len()
        );
        assert_eq!(outbox.stored, PER_CAR as u64);
        waits.extend(car_waits);
        outboxes.push(outbox);
    }
    (outboxes, waits, stopped_output)
}

fn stopped_cleanly(nats: bool) {
    // A resend would come after 10 s: none is needed.
    let (outboxes, waits, stopped) = scale_in(nats, "-TERM", 10_000);
    // It took part before it stopped and said what it stored; on Mosquitto it stored
    // what had arrived after leaving its group (a work queue's service holds nothing
    // between batches).
    assert!(stopped.contains("stored "), "{stopped}");
    assert!(
        nats || stopped.contains("reports that had arrived before leaving the group"),
        "{stopped}"
    );
    assert!(
        !stopped.contains("stored 0 inventories, 0 trips"),
        "{stopped}"
    );
    let resent: u64 = outboxes.iter().map(|o| o.resent).sum();
    assert_eq!(resent, 0, "reports sent again");
    let longest = waits.iter().max().copied().unwrap_or(0);
    eprintln!(
        "{}: clean stop: the longest wait for a receipt {longest} ms",
        if nats { "NATS" } else { "Mosquitto" }
    );
    assert!(longest < 10_000);
}

fn killed(nats: bool) {
    let resend_after_ms = 2_000;
    let (outboxes, waits, _) = scale_in(nats, "-KILL", resend_after_ms);
    let resent: u64 = outboxes.iter().map(|o| o.resent).sum();
    let longest = waits.iter().max().copied().unwrap_or(0);
    eprintln!(
        "{}: SIGKILL: {resent} reports sent again; the longest wait for a receipt {longest} ms (resend after {resend_after_ms} ms)",
        if nats { "NATS" } else { "Mosquitto" }
    );
    // It held reports when it was killed (the database held it up).
    assert!(resent > 0);
    // What the killed service held comes with the cars' first resend, to a live service:
    // nothing waits for a second (a kept session would have taken every other resend).
    assert!(
        longest < 2 * resend_after_ms + 1_000,
        "a report waited {longest} ms"
    );
}

#[test]
fn a_service_stopped_cleanly_leaves_its_group_and_no_report_waits_for_a_resend() {
    stopped_cleanly(false);
}

#[test]
fn a_service_killed_mid_stream_strands_nothing_its_reports_come_again_to_the_others() {
    killed(false);
}

#[test]
fn on_the_cluster_a_service_stopped_cleanly_finishes_its_batch_and_no_report_waits() {
    stopped_cleanly(true);
}

#[test]
fn on_the_cluster_a_service_killed_mid_stream_loses_nothing() {
    killed(true);
}
