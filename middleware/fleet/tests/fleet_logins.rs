//! More than one fleet process logged in at once, as docs/src/fleet.md's "Scaling out" and
//! `fleet campaign create` have it: on a private Mosquitto run from the shipped
//! configuration (logins, ACL, persistence) and the PostgreSQL server.

mod common;

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use autoplug_fleet::broker::FLEET_USER;
use autoplug_fleet::ingest::IngestStats;
use autoplug_fleet::mqtt::{vehicle_client_id, LinkOptions, LinkStatus, MqttLink};
use autoplug_fleet::outbox::Outbox;
use autoplug_fleet::testing::{intake_thread, reporting_car, trip_report};
use autoplug_fleet::topics::{self, ReportKind};
use autoplug_fleet::FleetStore;
use autoplug_vin::Vin;
use common::{runtime, PgSchema, PrivateBroker};

/// A car as the gateway is one: its own login and persistent session, QoS 1, publishes
/// kept and sent again by the client while the broker is away. One report in flight at a
/// time, so the n-th PUBACK acknowledges the n-th report: `acked` says exactly which
/// reports the broker took responsibility for.
struct Car {
    vin: Vin,
    client: rumqttc::AsyncClient,
    acked: Arc<AtomicUsize>,
    published: usize,
    task: tokio::task::JoinHandle<()>,
}

impl Car {
    fn start(rt: &tokio::runtime::Runtime, broker: &PrivateBroker, vin: Vin) -> Self {
        let password = format!("pw-{vin}");
        let mut options = rumqttc::MqttOptions::new(
            autoplug_fleet::mqtt::vehicle_client_id(vin.as_str(), Some(&password)),
            "127.0.0.1",
            broker.port,
        );
        options
            .set_credentials(vin.to_string(), password)
            .set_clean_session(false)
            .set_keep_alive(Duration::from_secs(5))
            .set_inflight(1);
        let (client, mut eventloop) = rumqttc::AsyncClient::new(options, 1024);
        let acked = Arc::new(AtomicUsize::new(0));
        let count = acked.clone();
        let task = rt.spawn(async move {
            loop {
                match eventloop.poll().await {
                    Ok(rumqttc::Event::Incoming(rumqttc::Packet::PubAck(_))) => {
                        count.fetch_add(1, Ordering::SeqCst);
                    }
                    Ok(_) => {}
                    // The broker is away: the client reconnects on the next poll; this is
                    // its retry pace, not a synchronisation.
                    Err(_) => tokio::time::sleep(Duration::from_millis(100)).await,
                }
            }
        });
        Self {
            vin,
            client,
            acked,
            published: 0,
            task,
        }
    }

    /// Publishes its next `n` trips (numbered from 1 up).
    fn publish(&mut self, n: usize) {
        for _ in 0..n {
            self.published += 1;
            let trip = trip_report(&self.vin, self.published as i64);
            self.client
                .try_publish(
                    topics::report(&self.vin, ReportKind::Trip),
                    rumqttc::QoS::AtLeastOnce,
                    false,
                    serde_json::to_vec(&trip).unwrap(),
                )
                .unwrap();
        }
    }

    fn acked(&self) -> usize {
        self.acked.load(Ordering::SeqCst)
    }
}

impl Drop for Car {
    fn drop(&mut self) {
        self.task.abort();
    }
}

fn vins(n: u32) -> Vec<Vin> {
    (0..n)
        .map(|i| Vin::with_check_digit(&format!("JA3AP47H0YF{:06}", 100 + i)).unwrap())
        .collect()
}

/// Waits for `done`, at most `timeout`; panics with `what` and the state otherwise.
fn wait_for(what: &str, timeout: Duration, mut done: impl FnMut() -> Result<(), String>) {
    let deadline = Instant::now() + timeout;
    loop {
        match done() {
            Ok(()) => return,
            Err(state) if Instant::now() >= deadline => {
                panic!("{what} not within {timeout:?}: {state}")
            }
            Err(_) => std::thread::sleep(Duration::from_millis(20)),
        }
    }
}

/// A fleet service's intake as `autoplug fleet serve` runs it, on its own thread until
/// `stop`.
fn service(
    rt: &tokio::runtime::Runtime,
    broker: &PrivateBroker,
    schema: &PgSchema,
    client_id: &str,
    stop: Arc<AtomicBool>,
) -> std::thread::JoinHandle<(IngestStats, LinkStatus)> {
    let store = FleetStore::open(&schema.url).unwrap();
    intake_thread(
        rt.handle(),
        &broker.url(FLEET_USER, "pw-fleet"),
        client_id,
        store,
        stop,
    )
}

fn stored_trips(store: &mut FleetStore) -> i64 {
    store.summary().unwrap().trips
}

/// Trips stored per VIN, and the most any one (VIN, trip) is stored.
fn stored_per_vin(schema: &PgSchema) -> (Vec<(String, i64)>, i64) {
    let mut db = postgres::Client::connect(&schema.url, postgres::NoTls).unwrap();
    let per_vin = db
        .query(
            "SELECT vin, count(*) FROM trips GROUP BY vin ORDER BY vin",
            &[],
        )
        .unwrap()
        .iter()
        .map(|r| (r.get::<_, String>(0), r.get::<_, i64>(1)))
        .collect();
    let most = db
        .query_one(
            "SELECT coalesce(max(c), 0) FROM (SELECT count(*) AS c FROM trips GROUP BY vin, trip) t",
            &[],
        )
        .unwrap()
        .get::<_, i64>(0);
    (per_vin, most)
}

fn broker_with_logins(cars: &[Vin]) -> PrivateBroker {
    let broker = PrivateBroker::start();
    let mut logins = vec![(FLEET_USER.to_string(), "pw-fleet".to_string())];
    logins.extend(cars.iter().map(|v| (v.to_string(), format!("pw-{v}"))));
    broker.add_logins(&logins);
    broker
}

/// A schema of the test's own on the PostgreSQL server, a runtime for the MQTT links, and
/// the flag that stops the services.
fn servers() -> (PgSchema, tokio::runtime::Runtime, Arc<AtomicBool>) {
    (PgSchema::new(), runtime(), Arc::new(AtomicBool::new(false)))
}

#[test]
fn two_services_and_a_campaign_publisher_log_in_side_by_side_and_store_every_report_once() {
    const PER_CAR: usize = 100;
    let vins = vins(3);
    let broker = broker_with_logins(&vins);
    let (schema, rt, stop) = servers();
    // Two services of one group, as docs/src/fleet.md scales out: distinct client ids, one
    // login.
    let a = service(&rt, &broker, &schema, "fleet-a", stop.clone());
    let b = service(&rt, &broker, &schema, "fleet-b", stop.clone());
    let mut check = FleetStore::open(&schema.url).unwrap();

    let mut cars: Vec<Car> = vins.iter().map(|v| Car::start(&rt, &broker, *v)).collect();
    for car in &mut cars {
        car.publish(PER_CAR / 2);
    }
    // `fleet campaign create` meanwhile: the image published retained by a third fleet
    // process (the publisher's own client id, clean session, as the CLI's), which then
    // leaves.
    let mut options = LinkOptions::new(format!("autoplug-fleet-publisher-{}", std::process::id()));
    options.max_backoff = Duration::from_millis(200);
    let publisher = MqttLink::connect(rt.handle(), &broker.url(FLEET_USER, "pw-fleet"), options);
    publisher.wait_connected(Duration::from_secs(10)).unwrap();
    publisher
        .publish(
            &topics::image(&"ab".repeat(32)),
            vec![0x5a; 64 * 1024],
            true,
        )
        .unwrap();
    publisher.close(Duration::from_secs(10));
    for car in &mut cars {
        car.publish(PER_CAR / 2);
    }
    wait_for("every report's PUBACK", Duration::from_secs(60), || {
        let acked: Vec<usize> = cars.iter().map(Car::acked).collect();
        acked
            .iter()
            .all(|&a| a == PER_CAR)
            .then_some(())
            .ok_or(format!("{acked:?}"))
    });
    let acked: usize = cars.iter().map(Car::acked).sum();
    // What the broker acknowledged must reach the store; give it the time to.
    let deadline = Instant::now() + Duration::from_secs(30);
    while stored_trips(&mut check) < acked as i64 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    let stored = stored_trips(&mut check);
    stop.store(true, Ordering::Relaxed);
    let (stats_a, link_a) = a.join().unwrap();
    let (stats_b, link_b) = b.join().unwrap();
    let (per_vin, most) = stored_per_vin(&schema);
    eprintln!(
        "two services: {} published, {acked} acknowledged, {stored} stored ({} by fleet-a, {} by fleet-b, {} redelivered); connections: fleet-a {}, fleet-b {}",
        cars.iter().map(|c| c.published).sum::<usize>(),
        stats_a.trips,
        stats_b.trips,
        stats_a.duplicates + stats_b.duplicates,
        link_a.connects,
        link_b.connects,
    );
    // Neither service was thrown off by the other or by the publisher.
    assert_eq!(
        (link_a.connects, link_b.connects),
        (1, 1),
        "a fleet login evicted a service: {link_a:?} {link_b:?}"
    );
    assert_eq!(
        stored, acked as i64,
        "every acknowledged report is stored: {per_vin:?}"
    );
    assert_eq!(most, 1, "a report stored twice");
    assert!(
        stats_a.trips > 0 && stats_b.trips > 0,
        "both services take reports: {} and {}",
        stats_a.trips,
        stats_b.trips
    );
    assert_eq!(stats_a.trips + stats_b.trips, acked as u64);
}

#[test]
fn a_vehicle_logs_in_only_with_its_own_client_id_on_either_listener() {
    let vins = vins(2);
    let broker = broker_with_logins(&vins);
    let rt = runtime();
    let (vin, other) = (vins[0].to_string(), vins[1].to_string());
    let own = vehicle_client_id(&vin, Some(&format!("pw-{vin}")));
    // With another car's client id (as it is, or its bare VIN) a car could take over that
    // car's session; with its bare VIN it would be the one another car can guess: its
    // login is refused, on the vehicles' listener and on the fleet's alike.
    let others = [
        vehicle_client_id(&other, Some(&format!("pw-{other}"))),
        other.clone(),
        vin.clone(),
    ];
    for (port, client_id) in [broker.port, broker.fleet_port]
        .into_iter()
        .flat_map(|p| others.iter().map(move |c| (p, c)))
    {
        let mut options = LinkOptions::new(client_id.clone());
        options.max_backoff = Duration::from_millis(200);
        let car = MqttLink::connect(
            rt.handle(),
            &broker.url_at(port, &vin, &format!("pw-{vin}")),
            options,
        );
        let refused = car.wait_connected(Duration::from_secs(5)).unwrap_err();
        assert!(
            refused.0.contains("refused the login"),
            "{port} {client_id}: {refused}"
        );
    }
    // With its own it is let in.
    let car = MqttLink::connect(
        rt.handle(),
        &broker.url(&vin, &format!("pw-{vin}")),
        LinkOptions::new(own),
    );
    car.wait_connected(Duration::from_secs(5)).unwrap();
}

#[test]
fn a_vehicle_cannot_join_the_services_group_and_every_report_is_stored() {
    const PER_CAR: usize = 60;
    let vins = vins(4);
    let broker = broker_with_logins(&vins);
    let (schema, rt, stop) = servers();
    let service = service(&rt, &broker, &schema, "fleet-a", stop.clone());
    // The fourth car tries to take a turn of every car's reports (the services' shared
    // group, with 3.1.1 or 5), to read them all, or another car's commands.
    let thief_vin = vins[3];
    let stolen = [
        topics::REPORTS_SHARED.to_string(),
        "$share/other-group/autoplug/v1/vehicles/+/report/#".to_string(),
        topics::REPORTS.to_string(),
        topics::command(&vins[0]),
        "#".to_string(),
    ];
    let mut options = LinkOptions::new(vehicle_client_id(
        thief_vin.as_str(),
        Some(&format!("pw-{thief_vin}")),
    ));
    options.subscriptions = stolen.to_vec();
    let mut thief = MqttLink::connect(
        rt.handle(),
        &broker.url(thief_vin.as_str(), &format!("pw-{thief_vin}")),
        options,
    );
    thief.wait_connected(Duration::from_secs(10)).unwrap();
    wait_for("the thief's SUBACK", Duration::from_secs(10), || {
        let s = thief.status();
        (s.granted.len() + s.denied.len() == stolen.len())
            .then_some(())
            .ok_or(format!("{s:?}"))
    });
    let status = thief.status();
    assert!(status.granted.is_empty(), "granted: {:?}", status.granted);
    assert_eq!(status.denied, stolen.to_vec());

    // Three cars report, with no resend: a report the thief took would be lost.
    let mut cars: Vec<Car> = vins[..3]
        .iter()
        .map(|v| Car::start(&rt, &broker, *v))
        .collect();
    for car in &mut cars {
        car.publish(PER_CAR);
    }
    wait_for("every report's PUBACK", Duration::from_secs(60), || {
        let acked: Vec<usize> = cars.iter().map(Car::acked).collect();
        acked
            .iter()
            .all(|&a| a == PER_CAR)
            .then_some(())
            .ok_or(format!("{acked:?}"))
    });
    let mut check = FleetStore::open(&schema.url).unwrap();
    let expected = (3 * PER_CAR) as i64;
    let deadline = Instant::now() + Duration::from_secs(30);
    while stored_trips(&mut check) < expected && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    stop.store(true, Ordering::Relaxed);
    service.join().unwrap();
    assert_eq!(stored_trips(&mut check), expected);
    assert_eq!(
        thief.try_recv().map(|m| m.topic),
        None,
        "the thief read something"
    );
}

#[test]
fn a_broker_restarted_mid_ingest_loses_no_report() {
    // 20 cars, a report every 10 ms each: more than the service takes, so its queues are
    // full when the broker goes (the load at which it once stopped for good).
    const CARS: u32 = 20;
    const PER_CAR: usize = 60;
    let vins = vins(CARS);
    let mut broker = broker_with_logins(&vins);
    let (schema, rt, stop) = servers();
    let service = service(&rt, &broker, &schema, "fleet-a", stop.clone());
    let mut check = FleetStore::open(&schema.url).unwrap();
    let cars: Vec<_> = vins
        .iter()
        .map(|v| {
            reporting_car(
                rt.handle(),
                &broker.url(v.as_str(), &format!("pw-{v}")),
                *v,
                PER_CAR,
                Duration::from_millis(10),
                1_000,
                Duration::from_secs(90),
            )
        })
        .collect();
    // A third of the reports in, the broker restarts as an upgrade would (SIGTERM: it
    // saves its persistence; the shipped configuration keeps it), while the cars go on.
    wait_for(
        "a third of the reports stored",
        Duration::from_secs(30),
        || {
            let n = stored_trips(&mut check);
            (n >= (CARS as i64 * PER_CAR as i64 / 3))
                .then_some(())
                .ok_or(format!("{n} stored"))
        },
    );
    broker.restart();
    let outcomes: Vec<(Outbox, LinkStatus, Vec<i64>)> =
        cars.into_iter().map(|c| c.join().unwrap()).collect();
    stop.store(true, Ordering::Relaxed);
    let (stats, service_link) = service.join().unwrap();
    let (per_vin, most) = stored_per_vin(&schema);
    let stored = stored_trips(&mut check);
    let acknowledged: u64 = outcomes.iter().map(|(_, s, _)| s.acknowledged).sum();
    let resent: u64 = outcomes.iter().map(|(o, _, _)| o.resent).sum();
    let confirmed: u64 = outcomes.iter().map(|(o, _, _)| o.stored).sum();
    eprintln!(
        "broker restart: {} published, {acknowledged} PUBACKs (resends included), {resent} sent again for want of a receipt, {confirmed} confirmed, {stored} stored ({} redelivered); the service connected {} times",
        vins.len() * PER_CAR,
        stats.duplicates,
        service_link.connects
    );
    assert!(
        outcomes.iter().all(|(_, s, _)| s.connects >= 2) && service_link.connects >= 2,
        "the broker did restart under every client"
    );
    for (outbox, _, _) in &outcomes {
        assert!(
            outbox.is_empty(),
            "a car still waits for {} receipts",
            outbox.len()
        );
    }
    assert_eq!(confirmed, (vins.len() * PER_CAR) as u64);
    assert_eq!(stored, (vins.len() * PER_CAR) as i64, "{per_vin:?}");
    assert_eq!(most, 1, "a report stored twice");
}
