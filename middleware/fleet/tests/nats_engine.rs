//! The clustered engine on real servers: a NATS cluster of three nodes on loopback (the
//! configuration `autoplug fleet broker init --engine nats` writes), cars speaking MQTT to
//! it, fleet services pulling the reports from its work queue into PostgreSQL.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use autoplug_fleet::broker::FLEET_USER;
use autoplug_fleet::testing::{self, PgSchema, PrivateCluster};
use autoplug_fleet::FleetStore;
use autoplug_vin::Vin;

fn vins(n: usize) -> Vec<Vin> {
    (0..n)
        .map(|i| Vin::with_check_digit(&format!("JA3AP47H0YF{:06}", 300_000 + i)).unwrap())
        .collect()
}

#[test]
fn reports_reach_the_store_through_the_cluster_once_each() {
    let cluster = PrivateCluster::start(3);
    let cars = vins(4);
    let mut logins: Vec<(String, String)> = cars
        .iter()
        .map(|v| (v.to_string(), format!("pw-{v}")))
        .collect();
    logins.push((FLEET_USER.to_string(), "fleet-pw".to_string()));
    cluster.add_logins(&logins);
    let runtime = autoplug_fleet::mqtt::runtime().unwrap();
    let schema = PgSchema::new();
    let stop = Arc::new(AtomicBool::new(false));
    let service = testing::queue_intake_thread(
        runtime.handle(),
        &cluster.mqtt_url(&[0, 1, 2], FLEET_USER, "fleet-pw"),
        &cluster.nats_url(&[0, 1, 2], FLEET_USER, "fleet-pw"),
        "svc-0",
        FleetStore::open(&schema.url).unwrap(),
        stop.clone(),
    );
    let drivers: Vec<_> = cars
        .iter()
        .enumerate()
        .map(|(i, vin)| {
            let nodes = [i % 3, (i + 1) % 3, (i + 2) % 3];
            testing::reporting_car(
                runtime.handle(),
                &cluster.mqtt_url(&nodes, vin.as_str(), &format!("pw-{vin}")),
                *vin,
                20,
                Duration::from_millis(20),
                5_000,
                Duration::from_secs(60),
            )
        })
        .collect();
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
    let mut cluster = PrivateCluster::start(3);
    let cars = vins(CARS);
    let mut logins: Vec<(String, String)> = cars
        .iter()
        .map(|v| (v.to_string(), format!("pw-{v}")))
        .collect();
    logins.push((FLEET_USER.to_string(), "fleet-pw".to_string()));
    cluster.add_logins(&logins);
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
                &cluster.mqtt_url(nodes, FLEET_USER, "fleet-pw"),
                &cluster.nats_url(nodes, FLEET_USER, "fleet-pw"),
                &format!("svc-{i}"),
                FleetStore::open(&schema.url).unwrap(),
                stop.clone(),
            )
        })
        .collect();
    // A third of the cars start on each node, the others listed after it.
    let drivers: Vec<_> = cars
        .iter()
        .enumerate()
        .map(|(i, vin)| {
            let nodes = [i % 3, (i + 1) % 3, (i + 2) % 3];
            testing::reporting_car(
                runtime.handle(),
                &cluster.mqtt_url(&nodes, vin.as_str(), &format!("pw-{vin}")),
                *vin,
                TRIPS,
                Duration::from_millis(50),
                3_000,
                Duration::from_secs(120),
            )
        })
        .collect();
    // Mid-stream (the trips take 2 s): node 0 lost, back 3 s later.
    std::thread::sleep(Duration::from_millis(800));
    cluster.kill_node(0);
    std::thread::sleep(Duration::from_secs(3));
    cluster.start_node(0);
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
            // Its node went away: it reconnected, through the next node.
            assert!(
                status.connects >= 2 && status.address != 0,
                "car {i}: {status:?}"
            );
            moved += 1;
        }
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
    assert_eq!(store.summary().unwrap().trips as usize, CARS * TRIPS);
    assert_eq!(
        stored as usize,
        CARS * TRIPS,
        "each trip stored by one service once"
    );
    all_waits.sort_unstable();
    eprintln!(
        "{} trips of {CARS} cars through a node's loss: all stored once ({duplicates} redeliveries recognised), {moved} cars moved to another node; publish to receipt p50 {} ms, p99 {} ms, longest {} ms",
        CARS * TRIPS,
        all_waits[all_waits.len() / 2],
        all_waits[all_waits.len() * 99 / 100],
        all_waits[all_waits.len() - 1],
    );
}
