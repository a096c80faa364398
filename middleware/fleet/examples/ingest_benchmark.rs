//! Benchmark: vehicle reports through the MQTT broker into PostgreSQL.
//!
//! `VEHICLES` vehicles each publish their inventory (nine ECUs) and `TRIPS` trip reports
//! (statistics, the verdicts of every diagnostic routine, a trouble code on a share of
//! them) with QoS 1 to their report topics, through `PUBLISHERS` connections; a fleet
//! service (the same `FleetService` as `autoplug fleet serve`: shared subscription, manual
//! acknowledgement after the commit) stores them in a throwaway schema. Measured: the
//! reports stored per second from the first publish to the last row committed.
//!
//! The publishers keep at most `WINDOW` reports beyond those stored in flight: a broker
//! queues only so many messages per subscriber and drops the rest (Debian's Mosquitto
//! 2.0.11 in its default configuration dropped 241 of 10,000 with 500 in flight, "Outgoing
//! messages are being dropped" in its log; the shipped configuration raises
//! `max_queued_messages`), so this measures what the service stores, not what the broker
//! throws away.
//!
//! ```text
//! cargo run --release -p autoplug-fleet --example ingest_benchmark [VEHICLES] [TRIPS] [PUBLISHERS]
//! ```
//! The servers: `AUTOPLUG_TEST_POSTGRES`, `AUTOPLUG_TEST_MQTT` (defaults: the local ones).

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use autoplug_fleet::ingest::Ingest;
use autoplug_fleet::mqtt::{Broker, LinkOptions, MqttLink};
use autoplug_fleet::service::FleetService;
use autoplug_fleet::testing::{broker_url, ecus, trip_with_evidence, PgSchema};
use autoplug_fleet::topics::{self, ReportKind};
use autoplug_fleet::{FleetStore, InventoryReport};
use autoplug_store::EcuIdentity;
use autoplug_vin::Vin;

/// Reports published beyond those stored, at most.
const WINDOW: usize = 400;

fn arg(n: usize, default: usize) -> usize {
    std::env::args()
        .nth(n)
        .map(|a| a.parse().expect("a number"))
        .unwrap_or(default)
}

fn inventory(vin: &Vin, i: usize) -> InventoryReport {
    InventoryReport {
        vin: vin.to_string(),
        read_at_ms: 1_790_000_000_000,
        ecus: ecus()
            .map(|(ecu, node)| EcuIdentity {
                ecu: ecu.to_string(),
                node,
                part_number: Some(format!("AP-{}-0001", ecu.to_uppercase())),
                software_version: Some(format!("1.{}.0", i % 3)),
                hardware_version: Some("NUCLEO-F446RE".into()),
                serial_number: Some(format!("{ecu}-{i:08}")),
            })
            .collect(),
    }
}

fn main() {
    let vehicles = arg(1, 2000);
    let trips = arg(2, 4);
    let publishers = arg(3, 4).max(1);
    let broker: Broker = broker_url().parse().expect("the broker's address");
    let schema = PgSchema::new();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("a runtime");
    let run = std::process::id();
    let group = format!("ingest-bench-{run}");

    // The service first: its subscription is granted before anything is published.
    let store = FleetStore::open(&schema.url).expect("the fleet schema");
    let mut options = LinkOptions::new(format!("ingest-bench-service-{run}"));
    options.manual_acks = true;
    options.subscriptions = vec![topics::reports_shared(&group)];
    let link = MqttLink::connect(runtime.handle(), &broker, options);
    link.wait_connected(Duration::from_secs(10))
        .expect("the service connects");
    while link.status().granted.is_empty() {
        std::thread::sleep(Duration::from_millis(10));
    }
    let mut service = FleetService::new(Ingest::new(store, link), None, Duration::from_secs(1));

    // The payloads, made before the clock starts.
    let vins: Vec<Vin> = (0..vehicles)
        .map(|i| Vin::with_check_digit(&format!("JA3AP47H0YB{:06}", i)).expect("a VIN"))
        .collect();
    let mut messages: Vec<(String, Vec<u8>)> = Vec::with_capacity(vehicles * (trips + 1));
    for (i, vin) in vins.iter().enumerate() {
        let body = serde_json::to_vec(&inventory(vin, i)).expect("JSON");
        messages.push((topics::report(vin, ReportKind::Inventory), body));
    }
    for n in 0..trips {
        for vin in &vins {
            let body = serde_json::to_vec(&trip_with_evidence(vin, n as i64 + 1)).expect("JSON");
            messages.push((topics::report(vin, ReportKind::Trip), body));
        }
    }
    let total = messages.len();
    let stored = Arc::new(AtomicUsize::new(0));
    let sent = Arc::new(AtomicUsize::new(0));
    let bytes: usize = messages.iter().map(|(_, b)| b.len()).sum();

    let started = Instant::now();
    let chunks: Vec<Vec<(String, Vec<u8>)>> = {
        let per = total.div_ceil(publishers);
        let mut rest = messages;
        let mut out = Vec::new();
        while !rest.is_empty() {
            let tail = rest.split_off(per.min(rest.len()));
            out.push(std::mem::replace(&mut rest, tail));
        }
        out
    };
    let handle = runtime.handle().clone();
    let broker_for = broker.clone();
    let (stored_in, sent_in) = (stored.clone(), sent.clone());
    let publishing = std::thread::spawn(move || {
        let links: Vec<MqttLink> = (0..chunks.len())
            .map(|p| {
                let link = MqttLink::connect(
                    &handle,
                    &broker_for,
                    LinkOptions::new(format!("ingest-bench-pub-{run}-{p}")),
                );
                link.wait_connected(Duration::from_secs(10))
                    .expect("a publisher connects");
                link
            })
            .collect();
        let threads: Vec<_> = chunks
            .into_iter()
            .zip(links)
            .map(|(chunk, link)| {
                let (stored, sent) = (stored_in.clone(), sent_in.clone());
                std::thread::spawn(move || {
                    let count = chunk.len() as u64;
                    for (topic, body) in chunk {
                        while sent.load(Ordering::Relaxed)
                            >= stored.load(Ordering::Relaxed) + WINDOW
                        {
                            std::thread::sleep(Duration::from_micros(200));
                        }
                        sent.fetch_add(1, Ordering::Relaxed);
                        // The link's queue is bounded: a full one is waited out.
                        while link.publish(&topic, body.clone(), false).is_err() {
                            std::thread::sleep(Duration::from_micros(200));
                        }
                    }
                    // Every publish acknowledged before the goodbye: Mosquitto 2.0.11
                    // dropped what was in flight when a client disconnected right after
                    // its last publish ("disconnected due to out of memory").
                    let deadline = Instant::now() + Duration::from_secs(60);
                    while link.status().acknowledged < count && Instant::now() < deadline {
                        std::thread::sleep(Duration::from_millis(5));
                    }
                    link.close(Duration::from_secs(60));
                })
            })
            .collect();
        for t in threads {
            t.join().expect("a publisher");
        }
        Instant::now()
    });

    let stop = AtomicBool::new(false);
    let mut progress = (0, Instant::now());
    loop {
        service.step(&stop, Duration::from_millis(20));
        let s = &service.ingest.stats;
        let done = (s.inventories + s.trips + s.duplicates + s.rejected) as usize;
        stored.store(done, Ordering::Relaxed);
        if done >= total {
            break;
        }
        if done > progress.0 {
            progress = (done, Instant::now());
        } else if progress.1.elapsed() > Duration::from_secs(20) {
            eprintln!(
                "ingest: stuck at {done} of {total} reports handled ({} published) for 20 s: lost at the broker? {:?}",
                sent.load(Ordering::Relaxed),
                service.ingest.stats
            );
            std::process::exit(1);
        }
    }
    let stored_at = Instant::now();
    let _ = publishing.join().expect("the publishers");
    let s = &service.ingest.stats;
    let elapsed = stored_at.duration_since(started).as_secs_f64();
    let rows: i64 = {
        let db = service.ingest.store.db();
        ["vehicles", "ecus", "trips", "verdicts", "dtcs"]
            .iter()
            .map(|t| {
                db.query(&format!("SELECT count(*) FROM {t}"), &[])
                    .ok()
                    .and_then(|r| r.first().and_then(|r| r.first().and_then(|v| v.int())))
                    .unwrap_or(0)
            })
            .sum()
    };
    println!(
        "ingest: {vehicles} vehicles, {total} reports ({} inventories, {} trips with 9 verdicts each), {:.1} MB of JSON, {publishers} publisher connection(s), broker {broker}, {}",
        vehicles,
        vehicles * trips,
        bytes as f64 / 1e6,
        service.ingest.store.name()
    );
    println!(
        "stored {} inventories, {} trips, {} refused, in {} transactions; {rows} rows in the tables",
        s.inventories, s.trips, s.rejected, s.commits
    );
    println!(
        "end to end (first publish to last commit): {elapsed:.2} s = {:.0} reports/s ({:.0} rows/s), at most {WINDOW} in flight",
        total as f64 / elapsed,
        rows as f64 / elapsed,
    );
    assert_eq!(s.rejected, 0, "{:?}", s.last_rejections);
    service.ingest.link.close(Duration::from_secs(2));
}
