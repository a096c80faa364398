//! Vehicles' reports through the real broker into the store, on both engines: stored once,
//! acknowledged only when stored, bad ones refused with the reason.

mod common;

use std::sync::atomic::AtomicBool;
use std::time::Duration;

use autoplug_fleet::ingest::{Handled, Ingest};
use autoplug_fleet::mqtt::{Broker, LinkOptions, MqttLink};
use autoplug_fleet::topics::{self, ReportKind};
use autoplug_fleet::FleetStore;
use autoplug_fleet::{InventoryReport, Stored, TripReport};
use autoplug_store::EcuIdentity;
use autoplug_trips::{TripEnd, TripStats};
use autoplug_vin::Vin;
use common::{broker_url, engines, postgres_url, runtime, PgSchema};

fn inventory(vin: &Vin) -> InventoryReport {
    InventoryReport {
        vin: vin.to_string(),
        read_at_ms: 5,
        ecus: vec![EcuIdentity {
            ecu: "cruise".into(),
            node: 0x0D,
            part_number: Some("AP-CRUISE".into()),
            software_version: Some("1.1.0".into()),
            hardware_version: Some("NUCLEO-F446RE".into()),
            serial_number: Some("SN1".into()),
        }],
    }
}

fn trip(vin: &Vin) -> TripReport {
    TripReport {
        vin: vin.to_string(),
        trip: 1,
        started_at_ms: 10,
        ended_at_ms: 20,
        stats: TripStats::default(),
        end: TripEnd::Parked,
        verdicts: Vec::new(),
        dtcs: Vec::new(),
    }
}

/// An intake's link (manual acks) subscribed to the reports of `vins`, and a car's link
/// to publish them, both connected; `name` names the pair.
fn intake_and_car(
    rt: &tokio::runtime::Runtime,
    broker: &Broker,
    name: &str,
    vins: [&Vin; 2],
) -> (MqttLink, MqttLink) {
    let mut options = LinkOptions::new(name);
    options.manual_acks = true;
    options.subscriptions = vins
        .iter()
        .map(|v| format!("autoplug/v1/vehicles/{v}/report/#"))
        .collect();
    let link = MqttLink::connect(rt.handle(), broker, options);
    link.wait_connected(Duration::from_secs(5))
        .unwrap_or_else(|e| panic!("{e} (scripts/setup-tests installs and starts Mosquitto)"));
    while link.status().granted.len() < vins.len() {
        std::thread::sleep(Duration::from_millis(10));
    }
    let car = MqttLink::connect(rt.handle(), broker, LinkOptions::new(format!("{name}-car")));
    car.wait_connected(Duration::from_secs(5)).unwrap();
    (link, car)
}

#[test]
fn reports_through_the_broker_are_stored_once_and_bad_ones_refused() {
    let rt = runtime();
    let broker: Broker = broker_url().parse().unwrap();
    for (k, engine) in engines().into_iter().enumerate() {
        // VINs of this run only: the broker is shared with whatever else runs.
        let serial = std::process::id() % 100_000 * 10 + k as u32;
        let vin = Vin::with_check_digit(&format!("JA3AP47H0YF{serial:06}")).unwrap();
        let other = Vin::with_check_digit(&format!("JA3AP47H0YG{serial:06}")).unwrap();
        let (link, car) = intake_and_car(
            &rt,
            &broker,
            &format!("ingest-test-{serial}"),
            [&vin, &other],
        );

        let json = |v: &dyn erased::Json| v.json();
        let sends: Vec<(String, Vec<u8>)> = vec![
            (
                topics::report(&vin, ReportKind::Inventory),
                json(&inventory(&vin)),
            ),
            (topics::report(&vin, ReportKind::Trip), json(&trip(&vin))),
            // The same trip again (a redelivery): stored once.
            (topics::report(&vin, ReportKind::Trip), json(&trip(&vin))),
            // Another vehicle's report on this vehicle's topic.
            (topics::report(&vin, ReportKind::Trip), json(&trip(&other))),
            // Not JSON.
            (
                topics::report(&other, ReportKind::Inventory),
                b"{oops".to_vec(),
            ),
            // A report kind nobody defined.
            (
                format!("autoplug/v1/vehicles/{vin}/report/selfie"),
                b"{}".to_vec(),
            ),
        ];
        for (topic, payload) in &sends {
            car.publish(topic, payload.clone(), false).unwrap();
        }
        let mut ingest = Ingest::new(engine.open(), link);
        let stop = AtomicBool::new(false);
        let mut handled = Vec::new();
        for _ in 0..sends.len() {
            let message = ingest
                .link
                .recv_timeout(Duration::from_secs(5))
                .expect("every report arrives");
            handled.push(ingest.take(&message, &stop));
        }
        assert_eq!(
            handled,
            vec![
                Some(Handled::Inventory(vec!["cruise".into()])),
                Some(Handled::Trip(Stored::New)),
                Some(Handled::Trip(Stored::Duplicate)),
                None,
                None,
                None,
            ],
            "{}",
            engine.label()
        );
        let stats = &ingest.stats;
        assert_eq!(
            (
                stats.inventories,
                stats.trips,
                stats.duplicates,
                stats.rejected
            ),
            (1, 1, 1, 3)
        );
        let reasons: Vec<&String> = stats.last_rejections.iter().collect();
        assert!(
            reasons[0].contains(&format!("naming VIN \"{other}\" on {vin}'s topic")),
            "{reasons:?}"
        );
        assert!(reasons[1].contains("not valid"), "{reasons:?}");
        assert!(
            reasons[2].contains("no report kind \"selfie\""),
            "{reasons:?}"
        );
        let summary = ingest.store.summary().unwrap();
        assert_eq!(
            (summary.vehicles, summary.trips),
            (1, 1),
            "{}",
            engine.label()
        );
    }
}

/// A batch of reports in one transaction, on both engines: each comes to what it would
/// alone (a new trip, the same trip twice in the batch, a trip stored before, an inventory,
/// reports refused before and inside the transaction), and a report refused inside the
/// transaction undoes only its own writes.
#[test]
fn a_batch_in_one_transaction_settles_each_report_as_alone() {
    use autoplug_fleet::campaign::{CampaignReport, VehicleState};
    use autoplug_store::{DtcRecord, VerdictRecord};
    let rt = runtime();
    let broker: Broker = broker_url().parse().unwrap();
    for (k, engine) in engines().into_iter().enumerate() {
        let serial = std::process::id() % 100_000 * 10 + 3 + k as u32;
        let vin = Vin::with_check_digit(&format!("JA3AP47H0YK{serial:06}")).unwrap();
        let second = Vin::with_check_digit(&format!("JA3AP47H0YL{serial:06}")).unwrap();
        let (link, car) = intake_and_car(
            &rt,
            &broker,
            &format!("batch-test-{serial}"),
            [&vin, &second],
        );
        let mut ingest = Ingest::new(engine.open(), link);
        // Trip 1 of `vin` stored before the batch.
        ingest.store.record_trip(&trip(&vin)).unwrap();
        let evidence = |v: &Vin, n: i64| TripReport {
            trip: n,
            verdicts: vec![VerdictRecord {
                ecu: "cruise".into(),
                routine: "presence".into(),
                verdict: "faulty".into(),
                number: Some(30.0),
                unit: "%".into(),
                suspect_above: 5.0,
                faulty_above: 20.0,
                window_s: None,
                evidence: "frames missing".into(),
            }],
            dtcs: vec![DtcRecord {
                ecu: "cruise".into(),
                code: "U0140-87".into(),
                status: 9,
                description: "lost communication".into(),
            }],
            ..trip(v)
        };
        let stray = CampaignReport {
            vin: second.to_string(),
            campaign: 999_999,
            attempt: 1,
            state: VehicleState::Installed,
            reason: None,
            ecu: "cruise".into(),
            version_running: Some("1.2.0".into()),
            at_ms: 30,
        };
        let json = |v: &dyn erased::Json| v.json();
        let sends: Vec<(String, Vec<u8>)> = vec![
            (topics::report(&vin, ReportKind::Trip), json(&trip(&vin))),
            (
                topics::report(&second, ReportKind::Trip),
                json(&evidence(&second, 7)),
            ),
            (
                topics::report(&vin, ReportKind::Trip),
                json(&evidence(&vin, 2)),
            ),
            (topics::report(&second, ReportKind::Campaign), json(&stray)),
            (
                topics::report(&second, ReportKind::Trip),
                json(&evidence(&second, 7)),
            ),
            (
                topics::report(&second, ReportKind::Inventory),
                json(&inventory(&second)),
            ),
            (topics::report(&vin, ReportKind::Trip), b"{oops".to_vec()),
        ];
        for (topic, payload) in &sends {
            car.publish(topic, payload.clone(), false).unwrap();
        }
        let mut batch = Vec::new();
        while batch.len() < sends.len() {
            let message = ingest
                .link
                .recv_timeout(Duration::from_secs(5))
                .expect("every report arrives");
            batch.push(message);
        }
        let commits = ingest.stats.commits;
        let handled = ingest.take_batch(&batch, &AtomicBool::new(false));
        assert_eq!(
            handled,
            vec![
                Some(Handled::Trip(Stored::Duplicate)),
                Some(Handled::Trip(Stored::New)),
                Some(Handled::Trip(Stored::New)),
                None,
                Some(Handled::Trip(Stored::Duplicate)),
                Some(Handled::Inventory(vec!["cruise".into()])),
                None,
            ],
            "{}",
            engine.label()
        );
        assert_eq!(ingest.stats.commits, commits + 1, "one transaction");
        let reasons: Vec<&String> = ingest.stats.last_rejections.iter().collect();
        assert!(
            reasons[0].contains("is not a vehicle of campaign 999999"),
            "{reasons:?}"
        );
        assert!(reasons[1].contains("not valid"), "{reasons:?}");
        let count = |store: &mut FleetStore, table: &str| {
            store
                .db()
                .query(&format!("SELECT count(*) FROM {table}"), &[])
                .unwrap()[0][0]
                .int()
                .unwrap()
        };
        let store = &mut ingest.store;
        assert_eq!(
            [
                count(store, "vehicles"),
                count(store, "trips"),
                count(store, "verdicts"),
                count(store, "dtcs"),
                count(store, "ecus"),
            ],
            [2, 3, 2, 2, 1],
            "{}",
            engine.label()
        );
    }
}

/// The service's database connection ended by the server (a restart, a failover, an
/// administrator) in the middle of an intake: the next try makes it again, says so, and
/// every report is stored; none is acknowledged before it is.
#[test]
fn a_database_connection_ended_mid_intake_is_made_again_and_nothing_is_lost() {
    let rt = runtime();
    let broker: Broker = broker_url().parse().unwrap();
    let schema = PgSchema::new();
    let serial = std::process::id() % 100_000 * 10 + 7;
    let vin = Vin::with_check_digit(&format!("JA3AP47H0YH{serial:06}")).unwrap();
    let mut options = LinkOptions::new(format!("ingest-db-test-{serial}"));
    options.manual_acks = true;
    options.subscriptions = vec![format!("autoplug/v1/vehicles/{vin}/report/#")];
    let link = MqttLink::connect(rt.handle(), &broker, options);
    link.wait_connected(Duration::from_secs(5))
        .unwrap_or_else(|e| panic!("{e} (scripts/setup-tests installs and starts Mosquitto)"));
    while link.status().granted.is_empty() {
        std::thread::sleep(Duration::from_millis(10));
    }
    let car = MqttLink::connect(
        rt.handle(),
        &broker,
        LinkOptions::new(format!("db-car-{serial}")),
    );
    car.wait_connected(Duration::from_secs(5)).unwrap();
    let publish = |trips: std::ops::Range<i64>| {
        for n in trips {
            let report = TripReport {
                trip: n,
                ..trip(&vin)
            };
            let payload = serde_json::to_vec(&report).unwrap();
            car.publish(&topics::report(&vin, ReportKind::Trip), payload, false)
                .unwrap();
        }
    };
    let store = FleetStore::open(&schema.url).unwrap();
    let mut ingest = Ingest::new(store, link);
    // A database that never comes back keeps `take` retrying until `stop`: after 30 s the
    // test stops it, and fails on what was stored.
    let stop = std::sync::Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        std::thread::spawn(move || {
            std::thread::sleep(Duration::from_secs(30));
            stop.store(true, std::sync::atomic::Ordering::Relaxed);
        });
    }
    let backend = |store: &mut FleetStore| match store
        .db()
        .query("SELECT pg_backend_pid()::BIGINT", &[])
        .unwrap()[0][0]
    {
        autoplug_fleet::db::Value::Int(pid) => pid,
        ref other => panic!("{other:?}"),
    };
    let take_until = |ingest: &mut Ingest, trips: u64| {
        let give_up = std::time::Instant::now() + Duration::from_secs(25);
        while ingest.stats.trips < trips {
            assert!(
                std::time::Instant::now() < give_up,
                "{} of {trips} trips stored in 25 s: {:?}",
                ingest.stats.trips,
                ingest.stats
            );
            let batch = ingest.recv_batch(Duration::from_millis(200));
            if !batch.is_empty() {
                ingest.take_batch(&batch, &stop);
            }
        }
    };
    publish(1..21);
    take_until(&mut ingest, 20);
    let before = backend(&mut ingest.store);
    // An administrator ends the service's connection.
    let mut admin = postgres::Client::connect(&postgres_url(), postgres::NoTls).unwrap();
    let ended: bool = admin
        .query_one("SELECT pg_terminate_backend($1::INT)", &[&(before as i32)])
        .unwrap()
        .get(0);
    assert!(ended);
    publish(21..41);
    take_until(&mut ingest, 40);
    assert_ne!(backend(&mut ingest.store), before, "a new connection");
    assert_eq!(ingest.stats.duplicates, 0);
    assert_eq!(ingest.store.summary().unwrap().trips, 40);
    let notices = ingest.take_notices();
    assert!(
        notices
            .iter()
            .any(|n| n.starts_with("the database failed (")),
        "{notices:?}"
    );
    assert!(
        notices
            .iter()
            .any(|n| n.starts_with("the database answers again, after ")),
        "{notices:?}"
    );
}

/// Serialising the two report types through one closure.
mod erased {
    pub trait Json {
        fn json(&self) -> Vec<u8>;
    }
    impl<T: serde::Serialize> Json for T {
        fn json(&self) -> Vec<u8> {
            serde_json::to_vec(self).unwrap()
        }
    }
}
