//! How the fleet's intake scales with services: cars report as the gateway does (each
//! logged in as its VIN, an outbox, receipts) through a broker run from the shipped
//! configuration to 1, 2 and 3 fleet services in one group (as `autoplug fleet serve` runs
//! them: batches, acknowledgement after the commit), into PostgreSQL
//! (`AUTOPLUG_TEST_POSTGRES`). For each count of services, on a fresh schema and broker:
//!
//! - **throughput**: every car publishes all its trips at once (a fleet coming back online),
//!   timed from the first publish until every receipt is in: reports/s;
//! - **latency**: the same cars at a steady `RATE` reports/s in all, the time from a
//!   report's publish to its receipt at the car: p50, p99, the longest.
//!
//! The trips carry the nine ECUs' verdicts (and a trouble code on one in 50), as drives
//! report them. Cars, broker, services and database share this machine's cores.
//!
//! With `--nats`, the clustered engine instead: three NATS nodes on this machine (the
//! configuration `autoplug fleet broker init --engine nats` writes), the cars spread over
//! them, the services pulling from the work queue (each on a node of its own).
//!
//! ```text
//! cargo run --release -p autoplug-fleet --example scaling_benchmark [--nats] [CARS] [TRIPS] [RATE] [SERVICES...]
//! ```
//! Defaults: 100 cars, 50 trips each, 200 reports/s, services 1 2 3.

use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::{Duration, Instant};

use autoplug_fleet::broker::FLEET_USER;
use autoplug_fleet::testing::{
    intake_thread, queue_intake_thread, reporting_car_with, trip_with_evidence, PgSchema,
    PrivateBroker, PrivateCluster,
};
use autoplug_fleet::FleetStore;
use autoplug_vin::Vin;

/// The arguments besides `--nats`.
fn args() -> Vec<String> {
    std::env::args().filter(|a| a != "--nats").collect()
}

fn nats() -> bool {
    std::env::args().any(|a| a == "--nats")
}

fn arg(n: usize, default: usize) -> usize {
    args()
        .into_iter()
        .nth(n)
        .map(|a| a.parse().expect("a number"))
        .unwrap_or(default)
}

/// CPU time so far (clock ticks), by what spends it: this process's service threads
/// ("intake"), the rest of this process (the cars and the connections), PostgreSQL, the
/// broker (Mosquitto or the NATS nodes), and the whole machine's busy and total time.
#[derive(Clone, Copy, Default)]
struct Cpu {
    services: u64,
    this_process: u64,
    postgres: u64,
    broker: u64,
    busy: u64,
    total: u64,
}

/// utime + stime of a /proc stat line, and its command name.
fn ticks(stat: &str) -> Option<(String, u64)> {
    let open = stat.find('(')?;
    let close = stat.rfind(')')?;
    let name = stat[open + 1..close].to_string();
    let fields: Vec<&str> = stat[close + 2..].split_whitespace().collect();
    let utime: u64 = fields.get(11)?.parse().ok()?;
    let stime: u64 = fields.get(12)?.parse().ok()?;
    Some((name, utime + stime))
}

fn cpu() -> Cpu {
    let mut cpu = Cpu::default();
    if let Ok(tasks) = std::fs::read_dir("/proc/self/task") {
        for task in tasks.flatten() {
            if let Some((name, t)) = std::fs::read_to_string(task.path().join("stat"))
                .ok()
                .as_deref()
                .and_then(ticks)
            {
                if name == "intake" {
                    cpu.services += t;
                }
                cpu.this_process += t;
            }
        }
    }
    if let Ok(procs) = std::fs::read_dir("/proc") {
        for p in procs.flatten() {
            if let Some((name, t)) = std::fs::read_to_string(p.path().join("stat"))
                .ok()
                .as_deref()
                .and_then(ticks)
            {
                match name.as_str() {
                    "postgres" => cpu.postgres += t,
                    "mosquitto" | "nats-server" => cpu.broker += t,
                    _ => {}
                }
            }
        }
    }
    if let Some(line) = std::fs::read_to_string("/proc/stat")
        .ok()
        .and_then(|s| s.lines().next().map(str::to_string))
    {
        let v: Vec<u64> = line
            .split_whitespace()
            .skip(1)
            .filter_map(|x| x.parse().ok())
            .collect();
        cpu.total = v.iter().take(8).sum();
        // idle and iowait are the 4th and 5th.
        cpu.busy = cpu.total - v.get(3).copied().unwrap_or(0) - v.get(4).copied().unwrap_or(0);
    }
    cpu
}

/// One phase's figures: reports, wall time, the cars' waits for their receipts (ms) and
/// the transactions the services committed.
struct Phase {
    reports: usize,
    wall_s: f64,
    waits: Vec<i64>,
    commits: u64,
    resent: u64,
    /// CPU time spent during the phase (its start to its last receipt).
    cpu: Cpu,
}

/// `services` services and `cars` cars of `trips` trips each, one every `pace` per car.
fn phase(
    runtime: &tokio::runtime::Runtime,
    services: usize,
    cars: usize,
    trips: usize,
    pace: Duration,
) -> Phase {
    enum Messaging {
        Mosquitto(PrivateBroker),
        Nats(PrivateCluster),
    }
    let messaging = if nats() {
        Messaging::Nats(PrivateCluster::start(3))
    } else {
        Messaging::Mosquitto(PrivateBroker::start())
    };
    let vins: Vec<Vin> = (0..cars)
        .map(|i| Vin::with_check_digit(&format!("JA3AP47H0YB{:06}", 700_000 + i)).expect("VIN"))
        .collect();
    let mut logins = vec![(FLEET_USER.to_string(), "pw-fleet".to_string())];
    logins.extend(vins.iter().map(|v| (v.to_string(), format!("pw-{v}"))));
    match &messaging {
        Messaging::Mosquitto(broker) => broker.add_logins(&logins),
        Messaging::Nats(cluster) => cluster.add_logins(&logins),
    }
    let schema = PgSchema::new();
    // The schema made once, before the services start.
    drop(FleetStore::open(&schema.url).expect("PostgreSQL"));
    let stop = Arc::new(AtomicBool::new(false));
    let intakes: Vec<_> = (0..services)
        .map(|i| {
            let store = FleetStore::open(&schema.url).expect("PostgreSQL");
            match &messaging {
                Messaging::Mosquitto(broker) => intake_thread(
                    runtime.handle(),
                    &broker.url(FLEET_USER, "pw-fleet"),
                    &format!("fleet-{i}"),
                    store,
                    stop.clone(),
                ),
                Messaging::Nats(cluster) => {
                    let nodes = [i % 3, (i + 1) % 3, (i + 2) % 3];
                    queue_intake_thread(
                        runtime.handle(),
                        &cluster.mqtt_url(&nodes, FLEET_USER, "pw-fleet"),
                        &cluster.nats_url(&nodes, FLEET_USER, "pw-fleet"),
                        &format!("fleet-{i}"),
                        store,
                        stop.clone(),
                    )
                }
            }
        })
        .collect();
    let started = Instant::now();
    let cpu_before = cpu();
    // Paced cars start one after the other, spread over one pace: a fleet's cars do not
    // report in step.
    let stagger = pace / cars as u32;
    let car_threads: Vec<_> = vins
        .iter()
        .enumerate()
        .map(|(i, v)| {
            std::thread::sleep(stagger);
            let password = format!("pw-{v}");
            let url = match &messaging {
                Messaging::Mosquitto(broker) => broker.url(v.as_str(), &password),
                Messaging::Nats(cluster) => {
                    cluster.mqtt_url(&[i % 3, (i + 1) % 3, (i + 2) % 3], v.as_str(), &password)
                }
            };
            reporting_car_with(
                runtime.handle(),
                &url,
                *v,
                trips,
                pace,
                30_000,
                Duration::from_secs(600),
                trip_with_evidence,
            )
        })
        .collect();
    let mut waits = Vec::with_capacity(cars * trips);
    let mut resent = 0;
    for car in car_threads {
        let (outbox, _, car_waits) = car.join().expect("a car");
        assert!(outbox.is_empty(), "a car's reports were not all confirmed");
        resent += outbox.resent;
        waits.extend(car_waits);
    }
    let wall_s = started.elapsed().as_secs_f64();
    let cpu_after = cpu();
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let commits = intakes
        .into_iter()
        .map(|t| t.join().expect("a service").0.commits)
        .sum();
    waits.sort_unstable();
    Phase {
        reports: cars * trips,
        wall_s,
        waits,
        commits,
        resent,
        cpu: Cpu {
            services: cpu_after.services.saturating_sub(cpu_before.services),
            this_process: cpu_after
                .this_process
                .saturating_sub(cpu_before.this_process),
            postgres: cpu_after.postgres.saturating_sub(cpu_before.postgres),
            broker: cpu_after.broker.saturating_sub(cpu_before.broker),
            busy: cpu_after.busy.saturating_sub(cpu_before.busy),
            total: cpu_after.total.saturating_sub(cpu_before.total),
        },
    }
}

fn percentile(sorted: &[i64], p: f64) -> i64 {
    if sorted.is_empty() {
        return 0;
    }
    sorted[((sorted.len() - 1) as f64 * p).round() as usize]
}

fn main() {
    let cars = arg(1, 100).max(1);
    let trips = arg(2, 50).max(1);
    let rate = arg(3, 200).max(1);
    let counts: Vec<usize> = {
        let given: Vec<usize> = args()
            .into_iter()
            .skip(4)
            .map(|a| a.parse().expect("a count of services"))
            .collect();
        if given.is_empty() {
            vec![1, 2, 3]
        } else {
            given
        }
    };
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .expect("a runtime");
    println!(
        "fleet scaling: {cars} cars x {trips} trips (9 verdicts each), {}, PostgreSQL; {} cores",
        if nats() {
            "three NATS nodes (JetStream work queue)"
        } else {
            "Mosquitto from the shipped configuration"
        },
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    for services in counts {
        let burst = phase(&runtime, services, cars, trips, Duration::ZERO);
        // The steady phase: each car one report every cars/rate seconds.
        let pace = Duration::from_secs_f64(cars as f64 / rate as f64);
        let steady_trips = (rate * 10 / cars).max(5);
        let steady = phase(&runtime, services, cars, steady_trips, pace);
        println!(
            "{services} service(s): {:.0} reports/s ({} reports in {:.2} s, {} transactions, {} sent again); at {rate} reports/s publish to receipt p50 {} ms, p99 {} ms, longest {} ms ({} reports)",
            burst.reports as f64 / burst.wall_s,
            burst.reports,
            burst.wall_s,
            burst.commits,
            burst.resent,
            percentile(&steady.waits, 0.5),
            percentile(&steady.waits, 0.99),
            steady.waits.last().copied().unwrap_or(0),
            steady.reports,
        );
        // Where the burst's CPU went, in per cent of one core (the machine has `cores`).
        let c = burst.cpu;
        let pct = |t: u64| 100.0 * t as f64 / (burst.wall_s * 100.0);
        println!(
            "    burst CPU: machine {:.0} % busy; services {:.0} % of a core, PostgreSQL {:.0} %, broker {:.0} %, cars and their links {:.0} %",
            100.0 * c.busy as f64 / c.total.max(1) as f64,
            pct(c.services),
            pct(c.postgres),
            pct(c.broker),
            pct(c.this_process.saturating_sub(c.services)),
        );
    }
}
