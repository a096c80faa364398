//! The clustered engine on real servers: a NATS cluster of three nodes on loopback (the
//! configuration `autoplug fleet broker init --engine nats` writes), cars speaking MQTT to
//! it, fleet services pulling the reports from its work queue into PostgreSQL.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use autoplug_fleet::broker::FLEET_USER;
use autoplug_fleet::mqtt::{vehicle_client_id, LinkOptions, MqttLink};
use autoplug_fleet::nats::WorkQueue;
use autoplug_fleet::testing::{self, PgSchema, PrivateCluster};
use autoplug_fleet::topics::{self, ReportKind};
use autoplug_fleet::FleetStore;
use autoplug_vin::Vin;

fn vins(n: usize) -> Vec<Vin> {
    (0..n)
        .map(|i| Vin::with_check_digit(&format!("JA3AP47H0YF{:06}", 300_000 + i)).unwrap())
        .collect()
}

/// Three nodes with the fleet's login ("pw-fleet") and one for each of `cars`
/// ("pw-VIN").
fn cluster_for(cars: &[Vin]) -> PrivateCluster {
    let cluster = PrivateCluster::start(3);
    let mut logins = vec![(FLEET_USER.to_string(), "pw-fleet".to_string())];
    logins.extend(cars.iter().map(|v| (v.to_string(), format!("pw-{v}"))));
    cluster.add_logins(&logins);
    cluster
}

/// The three nodes from `n`'s on, in turn (a car's or a service's address list).
fn from(n: usize) -> [usize; 3] {
    [n % 3, (n + 1) % 3, (n + 2) % 3]
}

type Car = std::thread::JoinHandle<(
    autoplug_fleet::outbox::Outbox,
    autoplug_fleet::mqtt::LinkStatus,
    Vec<i64>,
)>;

/// `cars` reporting `trips` trips each as the gateway does, one every `pace`, sending a
/// report again after `resend_after_ms` without a receipt; car `i` starts on node `i % 3`.
fn reporting(
    runtime: &tokio::runtime::Runtime,
    cluster: &PrivateCluster,
    cars: &[Vin],
    trips: usize,
    pace: Duration,
    resend_after_ms: i64,
) -> Vec<Car> {
    cars.iter()
        .enumerate()
        .map(|(i, vin)| {
            testing::reporting_car(
                runtime.handle(),
                &cluster.mqtt_url(&from(i), vin.as_str(), &format!("pw-{vin}")),
                *vin,
                trips,
                pace,
                resend_after_ms,
                Duration::from_secs(120),
            )
        })
        .collect()
}

#[test]
fn reports_reach_the_store_through_the_cluster_once_each() {
    let cars = vins(4);
    let cluster = cluster_for(&cars);
    let runtime = autoplug_fleet::mqtt::runtime().unwrap();
    let schema = PgSchema::new();
    let stop = Arc::new(AtomicBool::new(false));
    let service = testing::queue_intake_thread(
        runtime.handle(),
        &cluster.mqtt_url(&[0, 1, 2], FLEET_USER, "pw-fleet"),
        &cluster.nats_url(&[0, 1, 2], FLEET_USER, "pw-fleet"),
        "svc-0",
        FleetStore::open(&schema.url).unwrap(),
        stop.clone(),
    );
    let drivers = reporting(
        &runtime,
        &cluster,
        &cars,
        20,
        Duration::from_millis(20),
        5_000,
    );
    for d in drivers {
        let (outbox, status, waits) = d.join().unwrap();
        assert!(outbox.is_empty(), "{status:?}");
        assert_eq!(waits.len(), 20);
    }
    stop.store(true, Ordering::Relaxed);
    let (stats, _) = service.join().unwrap();
    assert_eq!(stats.trips, 80, "{stats:?}");
    let mut store = FleetStore::open(&schema.url).unwrap();
    assert_eq!(store.summary().unwrap().trips, 80);
}

/// One node of three killed mid-stream (SIGKILL) and started again: every trip stored
/// once, the cars connected to it come back through another node, the services go on.
#[test]
fn a_node_killed_mid_stream_loses_nothing_and_its_cars_move_to_another() {
    const CARS: usize = 12;
    const TRIPS: usize = 40;
    let cars = vins(CARS);
    let mut cluster = cluster_for(&cars);
    let runtime = autoplug_fleet::mqtt::runtime().unwrap();
    let schema = PgSchema::new();
    let stop = Arc::new(AtomicBool::new(false));
    // Two services, on the nodes that stay (1) and that is killed (0), each able to move.
    let services: Vec<_> = [[1, 2, 0], [0, 1, 2]]
        .iter()
        .enumerate()
        .map(|(i, nodes)| {
            testing::queue_intake_thread(
                runtime.handle(),
                &cluster.mqtt_url(nodes, FLEET_USER, "pw-fleet"),
                &cluster.nats_url(nodes, FLEET_USER, "pw-fleet"),
                &format!("svc-{i}"),
                FleetStore::open(&schema.url).unwrap(),
                stop.clone(),
            )
        })
        .collect();
    // A third of the cars start on each node, the others listed after it.
    let drivers = reporting(
        &runtime,
        &cluster,
        &cars,
        TRIPS,
        Duration::from_millis(50),
        3_000,
    );
    // Mid-stream (the trips take 2 s): node 0 lost; it comes back once the cars are done.
    std::thread::sleep(Duration::from_millis(800));
    cluster.kill_node(0);
    let mut moved = 0;
    let mut all_waits = Vec::new();
    for (i, d) in drivers.into_iter().enumerate() {
        let (outbox, status, waits) = d.join().unwrap();
        all_waits.extend(waits.iter().copied());
        assert!(
            outbox.is_empty(),
            "car {i}: {} unconfirmed, {status:?}",
            outbox.len()
        );
        assert_eq!(waits.len(), TRIPS, "car {i}");
        if i % 3 == 0 {
            // Its node went away: it reconnected, through another node.
            assert!(
                status.connects >= 2 && status.address != 0,
                "car {i}: {status:?}"
            );
            moved += 1;
        }
    }
    // Back: it catches up from the others and serves cars again.
    cluster.start_node(0);
    let again: Vec<_> = cars[..3]
        .iter()
        .map(|vin| {
            testing::reporting_car_with(
                runtime.handle(),
                &cluster.mqtt_url(&[0], vin.as_str(), &format!("pw-{vin}")),
                *vin,
                5,
                Duration::from_millis(20),
                3_000,
                Duration::from_secs(60),
                |vin, n| testing::trip_report(vin, 1000 + n),
            )
        })
        .collect();
    for d in again {
        let (outbox, status, _) = d.join().unwrap();
        assert!(outbox.is_empty(), "through the node back: {status:?}");
    }
    stop.store(true, Ordering::Relaxed);
    let mut stored = 0;
    let mut duplicates = 0;
    for s in services {
        let (stats, _) = s.join().unwrap();
        stored += stats.trips;
        duplicates += stats.duplicates;
    }
    let mut store = FleetStore::open(&schema.url).unwrap();
    let total = CARS * TRIPS + 3 * 5;
    assert_eq!(store.summary().unwrap().trips as usize, total);
    assert_eq!(
        stored as usize, total,
        "each trip stored by one service once"
    );
    all_waits.sort_unstable();
    eprintln!(
        "{} trips of {CARS} cars through a node's loss: all stored once ({duplicates} redeliveries recognised), {moved} cars moved to another node; publish to receipt p50 {} ms, p99 {} ms, longest {} ms; 15 more through the node back",
        CARS * TRIPS,
        all_waits[all_waits.len() / 2],
        all_waits[all_waits.len() * 99 / 100],
        all_waits[all_waits.len() - 1],
    );
}

const A: &str = "JA3AP47H0YF000042";
const B: &str = "JA3AP47H2YF000043";

fn vin(text: &str) -> Vin {
    Vin::parse(text).unwrap()
}

fn cluster_with_logins() -> PrivateCluster {
    cluster_for(&[vin(A), vin(B)])
}

/// A car's connection as `user` with `client_id` through node `node` (then the others).
fn vehicle(
    rt: &tokio::runtime::Runtime,
    cluster: &PrivateCluster,
    node: usize,
    user: &str,
    client_id: &str,
    subscriptions: Vec<String>,
) -> MqttLink {
    let mut options = LinkOptions::new(client_id);
    options.persistent_session = true;
    options.subscriptions = subscriptions;
    options.max_backoff = Duration::from_millis(500);
    let nodes = from(node);
    MqttLink::connect(
        rt.handle(),
        &cluster.mqtt_url(&nodes, user, &format!("pw-{user}")),
        options,
    )
}

fn wait_answered(link: &MqttLink, n: usize) {
    for _ in 0..1000 {
        let s = link.status();
        if s.granted.len() + s.denied.len() >= n {
            return;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    panic!("no SUBACK: {:?}", link.status());
}

fn next(link: &mut MqttLink, wait: Duration) -> Option<(String, Vec<u8>)> {
    link.recv_timeout(wait).map(|m| (m.topic, m.payload))
}

/// The reports in the work queue within `wait`, by topic and payload.
fn queued(queue: &mut WorkQueue, wait: Duration) -> Vec<(String, Vec<u8>)> {
    let deadline = std::time::Instant::now() + wait;
    let mut got = Vec::new();
    while std::time::Instant::now() < deadline {
        for m in queue.recv_batch(Duration::from_millis(100), 100) {
            queue.ack(&m).unwrap();
            got.push((m.topic, m.payload));
        }
    }
    got
}

#[test]
fn on_the_cluster_a_vehicle_publishes_only_as_itself_and_reads_only_its_own_topics() {
    let cluster = cluster_with_logins();
    let rt = testing_runtime();
    let mut queue = WorkQueue::connect(
        rt.handle(),
        &cluster.nats_url(&[1], FLEET_USER, "pw-fleet"),
        "probe",
    )
    .unwrap();
    assert!(queued(&mut queue, Duration::from_millis(500)).is_empty());
    let fleet = {
        let link = MqttLink::connect(
            rt.handle(),
            &cluster.mqtt_url(&[2], FLEET_USER, "pw-fleet"),
            LinkOptions::new("fleet-probe"),
        );
        link.wait_connected(Duration::from_secs(10)).unwrap();
        link
    };

    // A wrong password is refused at login, with the reason.
    let mut options = LinkOptions::new(A);
    options.max_backoff = Duration::from_millis(200);
    let intruder = MqttLink::connect(rt.handle(), &cluster.mqtt_url(&[0], A, "guess"), options);
    let refused = intruder.wait_connected(Duration::from_secs(5)).unwrap_err();
    assert!(refused.0.contains("refused the login"), "{refused}");
    drop(intruder);

    // Beyond its own topics every subscription is refused at SUBACK: another car's
    // commands, every car's reports, everything, the server's own delivery subjects.
    let beyond = [
        topics::command(&vin(B)),
        topics::REPORTS.to_string(),
        "#".to_string(),
        "$MQTT/sub/#".to_string(),
    ];
    let mut subscriptions = vec![topics::command(&vin(A)), topics::receipt(&vin(A))];
    subscriptions.extend(beyond.iter().cloned());
    let mut a = vehicle(&rt, &cluster, 0, A, &own(A), subscriptions);
    a.wait_connected(Duration::from_secs(10)).unwrap();
    wait_answered(&a, 6);
    let status = a.status();
    assert!(
        status.granted.contains(&topics::command(&vin(A))),
        "{status:?}"
    );
    for topic in &beyond {
        assert!(status.denied.contains(topic), "{topic}: {status:?}");
    }

    // A publishes a report as B, then one as itself: only its own reaches the queue.
    a.publish(
        &topics::report(&vin(B), ReportKind::Trip),
        b"forged".to_vec(),
        false,
    )
    .unwrap();
    a.publish(
        &topics::report(&vin(A), ReportKind::Trip),
        b"own".to_vec(),
        false,
    )
    .unwrap();
    // Nor may a car write commands (a forged instruction), to itself or another.
    a.publish(&topics::command(&vin(A)), b"self-command".to_vec(), false)
        .unwrap();
    a.publish(&topics::command(&vin(B)), b"forged-command".to_vec(), false)
        .unwrap();
    assert_eq!(
        queued(&mut queue, Duration::from_secs(2)),
        [(topics::report(&vin(A), ReportKind::Trip), b"own".to_vec())]
    );
    // B, offline with its session kept, and A taking B's client id (which only B's
    // password makes: suppose A had it): it gets B's connection but not B's commands (its
    // own rights judge the session's subscriptions).
    let b = vehicle(&rt, &cluster, 1, B, &own(B), vec![topics::command(&vin(B))]);
    b.wait_connected(Duration::from_secs(10)).unwrap();
    wait_answered(&b, 1);
    b.close(Duration::from_secs(2));
    let mut a_as_b = vehicle(&rt, &cluster, 2, A, &own(B), vec![]);
    a_as_b.wait_connected(Duration::from_secs(10)).unwrap();
    fleet
        .publish(&topics::command(&vin(B)), b"for B".to_vec(), false)
        .unwrap();
    fleet
        .publish(&topics::command(&vin(A)), b"for A".to_vec(), false)
        .unwrap();
    assert_eq!(
        next(&mut a, Duration::from_secs(5)),
        Some((topics::command(&vin(A)), b"for A".to_vec()))
    );
    assert_eq!(
        next(&mut a, Duration::from_millis(300)),
        None,
        "no forged command arrived"
    );
    assert_eq!(next(&mut a_as_b, Duration::from_millis(500)), None);
    drop(a_as_b);
    // B comes back and finds its command in its session.
    let mut b = vehicle(&rt, &cluster, 1, B, &own(B), vec![topics::command(&vin(B))]);
    b.wait_connected(Duration::from_secs(10)).unwrap();
    assert_eq!(
        next(&mut b, Duration::from_secs(10)),
        Some((topics::command(&vin(B)), b"for B".to_vec()))
    );
    // With B's VIN as client id, all another car can guess, A does not touch B's
    // connection.
    let guess = vehicle(&rt, &cluster, 0, A, B, vec![]);
    guess.wait_connected(Duration::from_secs(10)).unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let status = b.status();
    assert!(status.connected && status.connects == 1, "{status:?}");
}

/// `car`'s own client id (its VIN and password make it).
fn own(car: &str) -> String {
    vehicle_client_id(car, Some(&format!("pw-{car}")))
}

fn testing_runtime() -> tokio::runtime::Runtime {
    autoplug_fleet::mqtt::runtime().unwrap()
}

/// The receipts on `link` within `wait`: (report's SHA-256, refusal).
fn receipts(link: &mut MqttLink, wait: Duration) -> Vec<(String, Option<String>)> {
    let deadline = std::time::Instant::now() + wait;
    let mut got = Vec::new();
    while std::time::Instant::now() < deadline {
        if let Some(m) = link.recv_timeout(Duration::from_millis(100)) {
            let r: autoplug_fleet::Receipt = serde_json::from_slice(&m.payload).unwrap();
            got.push((r.report, r.refused));
        }
    }
    got
}

/// Bad reports refused with a receipt, a duplicate stored once; then, while cars report,
/// the whole cluster restarted (every node killed and started again from its store) and
/// the service's database connection ended by an administrator: every trip stored once.
#[test]
fn on_the_cluster_bad_reports_are_refused_and_restarts_lose_nothing() {
    const CARS: usize = 6;
    const TRIPS: usize = 50;
    let cars = vins(CARS);
    let mut all = cars.clone();
    all.extend([vin(A), vin(B)]);
    let mut cluster = cluster_for(&all);
    let rt = testing_runtime();
    let schema = PgSchema::new();
    let mut store = FleetStore::open(&schema.url).unwrap();
    let backend = store.db().query("SELECT pg_backend_pid()", &[]).unwrap()[0][0]
        .int()
        .unwrap();
    let stop = Arc::new(AtomicBool::new(false));
    let service = testing::queue_intake_thread(
        rt.handle(),
        &cluster.mqtt_url(&[0, 1, 2], FLEET_USER, "pw-fleet"),
        &cluster.nats_url(&[0, 1, 2], FLEET_USER, "pw-fleet"),
        "svc",
        store,
        stop.clone(),
    );

    // The hostile car: malformed, too large, naming another VIN, and one trip twice.
    let mut a = vehicle(&rt, &cluster, 0, A, &own(A), vec![topics::receipt(&vin(A))]);
    a.wait_connected(Duration::from_secs(10)).unwrap();
    wait_answered(&a, 1);
    let topic = topics::report(&vin(A), ReportKind::Trip);
    let huge = format!(
        "\"{}\"",
        "x".repeat(autoplug_fleet::report::MAX_REPORT_BYTES)
    );
    let as_b = serde_json::to_vec(&testing::trip_report(&vin(B), 1)).unwrap();
    let good = serde_json::to_vec(&testing::trip_report(&vin(A), 1)).unwrap();
    let bad: Vec<Vec<u8>> = vec![b"{not json".to_vec(), huge.into_bytes(), as_b];
    for payload in bad.iter().chain([&good, &good]) {
        a.publish(&topic, payload.clone(), false).unwrap();
    }
    let got = receipts(&mut a, Duration::from_secs(5));
    let sha = |p: &[u8]| autoplug_fleet::campaign::sha256_hex(p);
    for (payload, why) in bad
        .iter()
        .zip(["not valid", "bytes (at most", "naming VIN"])
    {
        let refused = got.iter().find(|(r, _)| *r == sha(payload));
        assert!(
            refused.is_some_and(|(_, reason)| reason.as_deref().is_some_and(|r| r.contains(why))),
            "{why}: {got:?}"
        );
    }
    assert_eq!(
        got.iter()
            .filter(|(r, f)| *r == sha(&good) && f.is_none())
            .count(),
        2
    );

    let drivers = reporting(
        &rt,
        &cluster,
        &cars,
        TRIPS,
        Duration::from_millis(40),
        2_000,
    );
    std::thread::sleep(Duration::from_millis(600));
    for n in 0..3 {
        cluster.kill_node(n);
    }
    for n in 0..3 {
        cluster.start_node(n);
    }
    std::thread::sleep(Duration::from_millis(800));
    let mut admin = FleetStore::open(&schema.url).unwrap();
    admin
        .db()
        .query(&format!("SELECT pg_terminate_backend({backend})"), &[])
        .unwrap();
    for d in drivers {
        let (outbox, status, _) = d.join().unwrap();
        assert!(
            outbox.is_empty(),
            "{} unconfirmed: {status:?}",
            outbox.len()
        );
    }
    stop.store(true, Ordering::Relaxed);
    let (stats, _) = service.join().unwrap();
    assert_eq!(stats.rejected, 3, "{stats:?}");
    assert!(
        stats.db_retries >= 1,
        "the connection's end was met: {stats:?}"
    );
    let mut store = FleetStore::open(&schema.url).unwrap();
    assert_eq!(store.summary().unwrap().trips as usize, CARS * TRIPS + 1);
    let twice = store
        .db()
        .query(
            "SELECT count(*) FROM (SELECT 1 FROM trips GROUP BY vin, trip HAVING count(*) > 1) t",
            &[],
        )
        .unwrap()[0][0]
        .int()
        .unwrap();
    assert_eq!(twice, 0);
}
