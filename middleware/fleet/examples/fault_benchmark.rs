//! The fleet's intake through the faults a deployment meets every month, on the real
//! servers: a private Mosquitto run from the shipped configuration (persistence on), the
//! PostgreSQL server (`AUTOPLUG_TEST_POSTGRES`), cars reporting as the gateway does
//! (outbox, receipts). While they report, one after the other:
//!
//! 1. the broker restarts (SIGTERM, started again from its directory);
//! 2. an administrator ends the service's database connection (`pg_terminate_backend`);
//! 3. a second service joins the group, and a third fleet process publishes a campaign's
//!    image and leaves (`fleet campaign create`).
//!
//! Then it counts: reports published, acknowledged by the broker (PUBACK, resends
//! included), confirmed stored by the fleet's receipts, stored, and stored more than once.
//! The goal: every report stored exactly once.
//!
//! `cargo run --release -p autoplug-fleet --example fault_benchmark [CARS] [TRIPS_PER_CAR]`

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use autoplug_fleet::broker::FLEET_USER;
use autoplug_fleet::mqtt::{LinkOptions, MqttLink};
use autoplug_fleet::testing::{intake_thread, reporting_car, PgSchema, PrivateBroker};
use autoplug_fleet::topics;
use autoplug_fleet::FleetStore;
use autoplug_vin::Vin;

fn arg(n: usize, default: usize) -> usize {
    std::env::args()
        .nth(n)
        .and_then(|a| a.parse().ok())
        .unwrap_or(default)
}

fn count(schema: &PgSchema, sql: &str) -> i64 {
    let mut db = postgres::Client::connect(&schema.url, postgres::NoTls).expect("PostgreSQL");
    db.query_one(sql, &[]).expect(sql).get(0)
}

fn wait_until(what: &str, timeout: Duration, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + timeout;
    while !done() {
        if Instant::now() > deadline {
            eprintln!("(went on without: {what})");
            return;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn main() {
    let cars = arg(1, 10).max(1);
    let per_car = arg(2, 200).max(10);
    let total = (cars * per_car) as i64;
    let mut broker = PrivateBroker::start();
    let vins: Vec<Vin> = (0..cars)
        .map(|i| Vin::with_check_digit(&format!("JA3AP47H0YB{:06}", 200 + i)).expect("VIN"))
        .collect();
    let mut logins = vec![(FLEET_USER.to_string(), "pw-fleet".to_string())];
    logins.extend(vins.iter().map(|v| (v.to_string(), format!("pw-{v}"))));
    broker.add_logins(&logins);
    let schema = PgSchema::new();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("runtime");
    let fleet = broker.url(FLEET_USER, "pw-fleet");
    let stop = Arc::new(AtomicBool::new(false));
    let mut store = FleetStore::open(&schema.url).expect("PostgreSQL");
    let backend: i32 = match store.db().query("SELECT pg_backend_pid()", &[]) {
        Ok(rows) => rows
            .first()
            .and_then(|r| r.first())
            .and_then(|v| v.int())
            .unwrap_or(0) as i32,
        Err(e) => panic!("{e}"),
    };
    let started = Instant::now();
    let service_a = intake_thread(runtime.handle(), &fleet, "fleet-a", store, stop.clone());
    // Each car a report every 20 ms: the faults land mid-stream.
    let car_threads: Vec<_> = vins
        .iter()
        .map(|v| {
            reporting_car(
                runtime.handle(),
                &broker.url(v.as_str(), &format!("pw-{v}")),
                *v,
                per_car,
                Duration::from_millis(20),
                2_000,
                Duration::from_secs(300),
            )
        })
        .collect();
    let stored = || count(&schema, "SELECT count(*) FROM trips");

    wait_until("a fifth stored", Duration::from_secs(60), || {
        stored() >= total / 5
    });
    let at = started.elapsed().as_secs_f64();
    broker.restart();
    eprintln!(
        "{at:.1} s: the broker restarted ({} stored before)",
        stored()
    );

    wait_until("two fifths stored", Duration::from_secs(60), || {
        stored() >= 2 * total / 5
    });
    let mut admin = postgres::Client::connect(&schema.url, postgres::NoTls).expect("PostgreSQL");
    let ended: bool = admin
        .query_one("SELECT pg_terminate_backend($1::INT)", &[&backend])
        .expect("pg_terminate_backend")
        .get(0);
    eprintln!(
        "{:.1} s: the service's database connection ended ({ended}; {} stored before)",
        started.elapsed().as_secs_f64(),
        stored()
    );

    wait_until("three fifths stored", Duration::from_secs(60), || {
        stored() >= 3 * total / 5
    });
    let store_b = FleetStore::open(&schema.url).expect("PostgreSQL");
    let service_b = intake_thread(runtime.handle(), &fleet, "fleet-b", store_b, stop.clone());
    let mut options = LinkOptions::new("fleet-campaign-publisher");
    options.max_backoff = Duration::from_millis(200);
    let publisher = MqttLink::connect(runtime.handle(), &fleet, options);
    publisher
        .wait_connected(Duration::from_secs(10))
        .expect("the publisher's login");
    publisher
        .publish(
            &topics::image(&"cd".repeat(32)),
            vec![0xa5; 64 * 1024],
            true,
        )
        .expect("publish");
    publisher.close(Duration::from_secs(5));
    eprintln!(
        "{:.1} s: a second service joined, a campaign's image was published ({} stored before)",
        started.elapsed().as_secs_f64(),
        stored()
    );

    let outcomes: Vec<_> = car_threads
        .into_iter()
        .map(|c| c.join().expect("car"))
        .collect();
    let wall = started.elapsed().as_secs_f64();
    stop.store(true, Ordering::Relaxed);
    let (a, link_a) = service_a.join().expect("service a");
    let (b, link_b) = service_b.join().expect("service b");
    let acknowledged: u64 = outcomes.iter().map(|(_, s, _)| s.acknowledged).sum();
    let resent: u64 = outcomes.iter().map(|(o, _, _)| o.resent).sum();
    let confirmed: u64 = outcomes.iter().map(|(o, _, _)| o.stored).sum();
    let unconfirmed: usize = outcomes.iter().map(|(o, _, _)| o.len()).sum();
    let stored = stored();
    let twice = count(
        &schema,
        "SELECT count(*) FROM (SELECT 1 FROM trips GROUP BY vin, trip HAVING count(*) > 1) t",
    );
    println!("fault benchmark: {cars} cars x {per_car} trips, a report every 20 ms per car; the broker restarted, the database connection ended, a second service joined");
    println!("  published                {total}");
    println!("  PUBACKs (resends incl.)  {acknowledged}");
    println!("  sent again (no receipt)  {resent}");
    println!("  confirmed by receipt     {confirmed}");
    println!("  left unconfirmed         {unconfirmed}");
    println!("  stored                   {stored}");
    println!("  stored more than once    {twice}");
    println!(
        "  by service               fleet-a {} new + {} again, fleet-b {} new + {} again; database retries {}; connections {} and {}",
        a.trips, a.duplicates, b.trips, b.duplicates, a.db_retries + b.db_retries, link_a.connects, link_b.connects
    );
    println!("  wall time                {wall:.1} s");
    let ok = stored == total && twice == 0 && confirmed == total as u64;
    println!(
        "  every report stored exactly once: {}",
        if ok { "yes" } else { "NO" }
    );
    if !ok {
        std::process::exit(1);
    }
}
