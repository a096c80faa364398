//! Recall management on a simulated fleet, end to end on the real servers (Mosquitto and
//! PostgreSQL at `AUTOPLUG_TEST_MQTT` / `AUTOPLUG_TEST_POSTGRES`, SQLite in a temporary
//! file): virtual cars with their gateways report through the broker to a fleet service;
//! the recall queries are checked against what the simulation knows; a campaign goes to
//! exactly the cars the evidence names, each installs the fix over CAN after its driver's
//! consent while parked, and drives with a cruise control judged ok afterwards.

use std::collections::BTreeSet;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use autoplug_can::Node;
use autoplug_fleet::campaign::{now_ms, sha256_hex, VehicleState};
use autoplug_fleet::campaigns::{CampaignSpec, CampaignState, Target};
use autoplug_fleet::db::Value;
use autoplug_fleet::ingest::Ingest;
use autoplug_fleet::mqtt::{Broker, LinkOptions, MqttLink};
use autoplug_fleet::service::FleetService;
use autoplug_fleet::testing::{broker_url, PgSchema};
use autoplug_fleet::{topics, EvidenceQuery, Finding, FleetStore, InventoryQuery};
use autoplug_fleet_agent::link::FleetConfig;
use autoplug_fleet_sim::{FleetPlan, Order, SimFleet, VehicleStatus};
use autoplug_image::{SigningKey, SoftwareVariant, Version};
use autoplug_virtual_car::diag::{build_image, FACTORY_PAYLOAD_LEN};

/// Cars in the acceptance fleet (`AUTOPLUG_TEST_FLEET` to try another size).
fn fleet_size() -> usize {
    std::env::var("AUTOPLUG_TEST_FLEET")
        .ok()
        .and_then(|n| n.parse().ok())
        .unwrap_or(200)
}

fn fleet_key() -> SigningKey {
    SigningKey::from_seed([77; 32])
}

fn ecu_key() -> SigningKey {
    SigningKey::from_seed(autoplug_image::dev::SIGNING_SEED)
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

/// A fleet service on `address`, in a thread of its own, until dropped.
struct Service {
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl Service {
    fn start(address: &str, runtime: &tokio::runtime::Runtime, tag: &str) -> Self {
        let broker: Broker = broker_url().parse().unwrap();
        let mut options = LinkOptions::new(format!("fleet-service-{tag}-{}", std::process::id()));
        options.manual_acks = true;
        options.subscriptions = vec![topics::reports_shared(&format!("fleet-{tag}"))];
        let link = MqttLink::connect(runtime.handle(), &broker, options);
        link.wait_connected(Duration::from_secs(10)).unwrap();
        let store = FleetStore::open(address).unwrap();
        let mut service = FleetService::new(
            Ingest::new(store, link),
            Some(fleet_key()),
            Duration::from_millis(200),
        );
        let stop = Arc::new(AtomicBool::new(false));
        let flag = stop.clone();
        let thread = std::thread::spawn(move || service.run(&flag));
        Self {
            stop,
            thread: Some(thread),
        }
    }
}

impl Drop for Service {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::SeqCst);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn fleet_config() -> FleetConfig {
    FleetConfig {
        broker: broker_url().parse().unwrap(),
        fleet_key: fleet_key().public_key(),
        image_key: ecu_key().public_key(),
        security_secret: autoplug_tester::DEV_SECURITY_SECRET.to_vec(),
        resend_after_ms: autoplug_fleet::outbox::RESEND_AFTER_MS,
        state_file: None,
    }
}

fn count(store: &mut FleetStore, sql: &str) -> i64 {
    match store
        .db()
        .query(sql, &[])
        .unwrap()
        .first()
        .and_then(|r| r.first())
    {
        Some(Value::Int(n)) => *n,
        other => panic!("{sql}: {other:?}"),
    }
}

/// Waits until `done` holds, at most `timeout`, with a message naming what was awaited.
fn wait_for(what: &str, timeout: Duration, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + timeout;
    while !done() {
        assert!(Instant::now() < deadline, "timed out waiting for {what}");
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn vins<'a>(statuses: impl IntoIterator<Item = &'a VehicleStatus>) -> BTreeSet<String> {
    statuses.into_iter().map(|s| s.vin.clone()).collect()
}

/// The fix: cruise 1.2.0, the standard software, signed with the ECUs' key.
fn fixed_cruise() -> Vec<u8> {
    build_image(
        Node::Cruise,
        Version::new(1, 2, 0),
        SoftwareVariant::Standard,
        FACTORY_PAYLOAD_LEN,
        &ecu_key(),
    )
}

fn publish_image(runtime: &tokio::runtime::Runtime, image: &[u8]) {
    let broker: Broker = broker_url().parse().unwrap();
    let link = MqttLink::connect(
        runtime.handle(),
        &broker,
        LinkOptions::new(format!("fleet-image-{}", std::process::id())),
    );
    link.wait_connected(Duration::from_secs(10)).unwrap();
    link.publish(&topics::image(&sha256_hex(image)), image.to_vec(), true)
        .unwrap();
    link.close(Duration::from_secs(5));
}

fn recall_and_campaign(address: &str, tag: &str, first_serial: u32) {
    let runtime = runtime();
    let _service = Service::start(address, &runtime, tag);
    let mut store = FleetStore::open(address).unwrap();
    let n = fleet_size();
    let mut plan = FleetPlan::new(n, 2026);
    plan.first_serial = first_serial;
    let specs = autoplug_fleet_sim::plan(&plan);
    let (mut fleet, first) =
        SimFleet::start(specs.clone(), fleet_config(), runtime.handle().clone(), 2).unwrap();
    assert!(first.iter().all(|s| s.error.is_none()), "{first:?}");

    // Drive 1: every car reports its inventory and its trip.
    let after_drive = fleet.order(Order::Drive).unwrap();
    wait_for(
        "every car's inventory and trip",
        Duration::from_secs(120),
        || {
            // Each car's drive (its start-up, the ignition on and off, is a trip too).
            count(
                &mut store,
                "SELECT count(DISTINCT vin) FROM trips WHERE distance_m > 100",
            ) == n as i64
                && count(&mut store, "SELECT count(DISTINCT vin) FROM ecus") == n as i64
        },
    );

    // Recall by inventory: exactly the cars built with the faulty release.
    let carrying: BTreeSet<String> = specs
        .iter()
        .filter(|s| s.cruise_faulty)
        .map(|s| s.vin.clone())
        .collect();
    let by_inventory = InventoryQuery {
        ecu: Some("cruise".into()),
        part_number: Some("AP-CRUISE-0001".into()),
        software_from: Some(autoplug_fleet_sim::FAULTY_CRUISE),
        software_to: Some(autoplug_fleet_sim::FAULTY_CRUISE),
        ..InventoryQuery::default()
    };
    let found: BTreeSet<String> = store
        .recall_by_inventory(&by_inventory)
        .unwrap()
        .into_iter()
        .map(|h| h.vin)
        .collect();
    assert_eq!(
        found, carrying,
        "recall by part number and software version"
    );

    // Recall by evidence: exactly the cars whose faulty cruise showed on the drive.
    let showed = vins(
        after_drive
            .iter()
            .filter(|s| s.drives.iter().any(|d| d.showed_faulty_cruise())),
    );
    let evidence = EvidenceQuery {
        finding: Finding::Faulty,
        ecu: Some("cruise".into()),
        since_ms: 0,
        until_ms: i64::MAX,
    };
    let hits = store.recall_by_evidence(&evidence).unwrap();
    let found: BTreeSet<String> = hits.iter().map(|h| h.vin.clone()).collect();
    assert_eq!(
        found, showed,
        "recall by evidence against the simulation's truth: {hits:#?}"
    );
    assert!(!showed.is_empty() && showed.is_subset(&carrying));
    assert!(
        showed.len() < carrying.len(),
        "some carriers never engaged cruise: the evidence recalls fewer cars"
    );
    for hit in &hits {
        assert!(
            hit.evidence.iter().any(|e| e.what.starts_with("faulty")),
            "{hit:?}"
        );
    }

    // The campaign: the fix to exactly the cars the evidence names, in two stages.
    let image = fixed_cruise();
    publish_image(&runtime, &image);
    let mut spec = CampaignSpec::new(
        &format!("cruise-1.2.0-{tag}"),
        "cruise",
        image,
        Target::Evidence(evidence.clone()),
    );
    spec.message = "fixes the cruise control's speed oscillation".into();
    let created = store.create_campaign(&spec, now_ms()).unwrap();
    let targeted: BTreeSet<String> = created.vehicles.iter().map(|(v, _)| v.clone()).collect();
    assert_eq!(targeted, showed);

    let parked = Arc::new(AtomicBool::new(false));
    let statuses = std::thread::scope(|scope| {
        let flag = parked.clone();
        let address = address.to_string();
        scope.spawn(move || {
            let mut store = FleetStore::open(&address).unwrap();
            let deadline = Instant::now() + Duration::from_secs(300);
            while Instant::now() < deadline {
                let vehicles = store.campaign_vehicles(created.id).unwrap();
                if vehicles.iter().all(|v| v.state.is_final()) {
                    break;
                }
                std::thread::sleep(Duration::from_millis(200));
            }
            flag.store(true, Ordering::SeqCst);
        });
        fleet.order(Order::Park(parked.clone())).unwrap()
    });
    let vehicles = store.campaign_vehicles(created.id).unwrap();
    for v in &vehicles {
        assert_eq!(v.state, VehicleState::Installed, "{v:?}");
        assert_eq!(v.version_running.as_deref(), Some("1.2.0"), "{v:?}");
    }
    for s in &statuses {
        let fixed = targeted.contains(&s.vin);
        assert_eq!(s.cruise_version == "1.2.0", fixed, "{s:?}");
        assert_eq!(
            s.cruise_faulty,
            !fixed && specs.iter().any(|p| p.vin == s.vin && p.cruise_faulty)
        );
    }
    wait_for("the campaign to finish", Duration::from_secs(10), || {
        store.campaign(&created.id.to_string()).unwrap().state == CampaignState::Finished
    });

    // Drive 2: the fixed cars' cruise is judged ok, their inventory shows 1.2.0.
    let campaign_done_ms = now_ms();
    let after = fleet.order(Order::Drive).unwrap();
    wait_for("every car's second trip", Duration::from_secs(120), || {
        count(
            &mut store,
            &format!(
                "SELECT count(DISTINCT vin) FROM trips WHERE ended_at_ms >= {campaign_done_ms}"
            ),
        ) == n as i64
    });
    let mut judged_ok = 0;
    for s in after.iter().filter(|s| targeted.contains(&s.vin)) {
        let inventory = store.vehicle_inventory(&s.vin).unwrap();
        let cruise = inventory.iter().find(|e| e.ecu == "cruise").unwrap();
        assert_eq!(
            cruise.software_version.as_deref(),
            Some("1.2.0"),
            "{cruise:?}"
        );
        if s.drives.last().is_some_and(|d| d.cruise_engaged_s >= 15.0) {
            let rows = store
                .db()
                .query(
                    "SELECT verdict FROM verdicts v JOIN trips t ON t.vin = v.vin AND t.trip = v.trip
                     WHERE v.vin = $1 AND v.ecu = 'cruise' AND t.ended_at_ms >= $2",
                    &[Value::from(s.vin.as_str()), Value::Int(campaign_done_ms)],
                )
                .unwrap();
            let verdicts: Vec<String> = rows
                .iter()
                .filter_map(|r| match r.first() {
                    Some(Value::Text(t)) => Some(t.clone()),
                    _ => None,
                })
                .collect();
            assert!(
                !verdicts.is_empty() && verdicts.iter().all(|v| v == "ok"),
                "{}: {verdicts:?}",
                s.vin
            );
            judged_ok += 1;
        }
    }
    assert!(judged_ok > 0, "no fixed car drove with cruise afterwards");
    let since_fix = EvidenceQuery {
        since_ms: campaign_done_ms,
        ..evidence
    };
    let still: BTreeSet<String> = store
        .recall_by_evidence(&since_fix)
        .unwrap()
        .into_iter()
        .map(|h| h.vin)
        .collect();
    assert!(still.is_disjoint(&targeted), "{still:?}");
    fleet.finish();
}

/// One fleet at a time, the engines in turn: a fleet service takes every vehicle's reports
/// from the broker, so two fleets at once would each land in both stores.
static ONE_FLEET: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_fleet() -> std::sync::MutexGuard<'static, ()> {
    ONE_FLEET.lock().unwrap_or_else(|e| e.into_inner())
}

#[test]
fn a_simulated_fleet_is_recalled_exactly_and_fixed_over_the_air_on_sqlite_and_postgresql() {
    let _one = one_fleet();
    let dir = tempfile::tempdir().unwrap();
    let address = dir.path().join("fleet.db").display().to_string();
    recall_and_campaign(&address, "sqlite", 100_000);
    let schema = PgSchema::new();
    recall_and_campaign(&schema.url, "postgres", 300_000);
}

/// An instruction to install `image` as cruise 1.2.0 on `vin`, valid for an hour, made
/// outside the fleet's campaigns (number `number` of the vehicle's series).
fn cruise_instruction(
    number: u64,
    campaign: i64,
    vin: &str,
    image: &[u8],
) -> autoplug_fleet::campaign::Instruction {
    autoplug_fleet::campaign::Instruction {
        number,
        campaign,
        name: format!("campaign-{campaign}"),
        vin: vin.to_string(),
        ecu: "cruise".into(),
        image_sha256: sha256_hex(image),
        image_bytes: image.len() as u64,
        version: "1.2.0".into(),
        attempt: 1,
        issued_at_ms: now_ms(),
        expires_at_ms: now_ms() + 3_600_000,
        message: String::new(),
    }
}

/// Parks the fleet until `done` holds of the store (at most `timeout`), then returns every
/// car's status.
fn park_until(
    fleet: &mut SimFleet,
    address: &str,
    timeout: Duration,
    done: impl Fn(&mut FleetStore) -> bool + Send,
) -> Vec<VehicleStatus> {
    let parked = Arc::new(AtomicBool::new(false));
    std::thread::scope(|scope| {
        let flag = parked.clone();
        scope.spawn(move || {
            let mut store = FleetStore::open(address).unwrap();
            let deadline = Instant::now() + timeout;
            while Instant::now() < deadline && !done(&mut store) {
                std::thread::sleep(Duration::from_millis(200));
            }
            flag.store(true, Ordering::SeqCst);
        });
        fleet.order(Order::Park(parked.clone())).unwrap()
    })
}

fn status<'a>(statuses: &'a [VehicleStatus], vin: &str) -> &'a VehicleStatus {
    statuses.iter().find(|s| s.vin == vin).unwrap()
}

fn states_of(store: &mut FleetStore, campaign: i64) -> Vec<(String, VehicleState)> {
    store
        .campaign_vehicles(campaign)
        .unwrap()
        .into_iter()
        .map(|v| (v.vin, v.state))
        .collect()
}

fn failures_forgeries_and_an_offline_car(address: &str, tag: &str, first_serial: u32) {
    let runtime = runtime();
    let _service = Service::start(address, &runtime, tag);
    let mut store = FleetStore::open(address).unwrap();
    let mut plan = FleetPlan::new(16, 7);
    plan.first_serial = first_serial;
    let mut specs = autoplug_fleet_sim::plan(&plan);
    let vins: Vec<String> = specs.iter().map(|s| s.vin.clone()).collect();
    // Stage 1 of the staged campaign (the first 2 of 8 in VIN order) are cars a workshop
    // already gave a newer cruise release: they refuse 1.2.0 as a downgrade.
    let mut staged: Vec<String> = vins[..8].to_vec();
    // Stages are cut in VIN order.
    staged.sort();
    for spec in specs.iter_mut().filter(|s| staged[..2].contains(&s.vin)) {
        spec.factory.retain(|(ecu, _)| ecu != "cruise");
        spec.factory.push(("cruise".into(), "1.3.0".into()));
        spec.cruise_faulty = false;
    }
    let (mut fleet, _) =
        SimFleet::start(specs, fleet_config(), runtime.handle().clone(), 2).unwrap();
    fleet.order(Order::Drive).unwrap();
    wait_for("every car's inventory", Duration::from_secs(60), || {
        count(&mut store, "SELECT count(DISTINCT vin) FROM ecus") == vins.len() as i64
    });
    let before: Vec<VehicleStatus> = fleet.order(Order::Online(Vec::new())).unwrap();

    // A staged rollout pauses by itself when its first stage fails past the threshold.
    let image = fixed_cruise();
    publish_image(&runtime, &image);
    let mut spec = CampaignSpec::new(
        &format!("staged-{tag}"),
        "cruise",
        image.clone(),
        Target::Vins(staged.clone()),
    );
    spec.stages = vec![25.0, 100.0];
    spec.failure_threshold = 0.2;
    let staged_campaign = store.create_campaign(&spec, now_ms()).unwrap().id;
    let after = park_until(&mut fleet, address, Duration::from_secs(60), |store| {
        store.campaign(&staged_campaign.to_string()).unwrap().state == CampaignState::Paused
    });
    let info = store.campaign(&staged_campaign.to_string()).unwrap();
    assert_eq!(info.state, CampaignState::Paused, "{info:?}");
    assert!(info.paused_reason.is_some(), "{info:?}");
    for (vin, state) in states_of(&mut store, staged_campaign) {
        let planted = staged[..2].contains(&vin);
        let expected = if planted {
            VehicleState::Refused
        } else {
            VehicleState::Waiting
        };
        assert_eq!(state, expected, "{vin}");
        let s = status(&after, &vin);
        assert_eq!(s.cruise_version, status(&before, &vin).cruise_version);
        if planted {
            let reason = s.campaign_reports.last().unwrap().reason.clone().unwrap();
            assert!(reason.contains("no downgrade"), "{reason}");
        }
    }

    // Forged and altered instructions are refused without a trace of acting on them.
    let target = vins[8].clone();
    let vin = autoplug_vin::Vin::parse(&target).unwrap();
    let mut instruction = cruise_instruction(
        store.next_instruction_number(&target).unwrap(),
        999,
        &target,
        &image,
    );
    let forged = instruction.sign(&SigningKey::from_seed([13; 32]));
    let mut altered: autoplug_fleet::campaign::Envelope =
        serde_json::from_slice(&instruction.sign(&fleet_key())).unwrap();
    altered.instruction = altered.instruction.replace("\"1.2.0\"", "\"1.2.1\"");
    let altered = serde_json::to_vec(&altered).unwrap();
    // And a signed instruction naming an image for another ECU (a fleet-side mistake the
    // car must still catch): the ABS image under the cruise ECU.
    let abs_image = build_image(
        Node::ABS,
        Version::new(1, 2, 0),
        SoftwareVariant::Standard,
        FACTORY_PAYLOAD_LEN,
        &ecu_key(),
    );
    publish_image(&runtime, &abs_image);
    let wrong_ecu_car = vins[9].clone();
    instruction.vin = wrong_ecu_car.clone();
    instruction.number = store.next_instruction_number(&wrong_ecu_car).unwrap();
    instruction.campaign = 998;
    instruction.image_sha256 = sha256_hex(&abs_image);
    instruction.image_bytes = abs_image.len() as u64;
    let wrong_ecu = instruction.sign(&fleet_key());
    {
        let broker: Broker = broker_url().parse().unwrap();
        let link = MqttLink::connect(
            runtime.handle(),
            &broker,
            LinkOptions::new(format!("fleet-forger-{tag}-{}", std::process::id())),
        );
        link.wait_connected(Duration::from_secs(10)).unwrap();
        link.publish(&topics::command(&vin), forged, false).unwrap();
        link.publish(&topics::command(&vin), altered, false)
            .unwrap();
        let other = autoplug_vin::Vin::parse(&wrong_ecu_car).unwrap();
        link.publish(&topics::command(&other), wrong_ecu, false)
            .unwrap();
        link.close(Duration::from_secs(5));
    }

    // A bad image through the fleet itself (signed with another key than the ECUs'), and
    // a car offline while the campaign goes out.
    let bad = build_image(
        Node::Cruise,
        Version::new(1, 2, 0),
        SoftwareVariant::Standard,
        FACTORY_PAYLOAD_LEN,
        &SigningKey::from_seed([14; 32]),
    );
    publish_image(&runtime, &bad);
    let bad_car = vins[10].clone();
    let bad_campaign = store
        .create_campaign(
            &CampaignSpec::new(
                &format!("bad-{tag}"),
                "cruise",
                bad,
                Target::Vins(vec![bad_car.clone()]),
            ),
            now_ms(),
        )
        .unwrap()
        .id;
    let offline_car = vins[11].clone();
    fleet
        .order(Order::Offline(vec![offline_car.clone()]))
        .unwrap();
    let mut fix = CampaignSpec::new(
        &format!("fix-{tag}"),
        "cruise",
        image,
        Target::Vins(vec![offline_car.clone(), vins[12].clone()]),
    );
    fix.stages = vec![100.0];
    let fix_campaign = store.create_campaign(&fix, now_ms()).unwrap().id;
    let after = park_until(&mut fleet, address, Duration::from_secs(60), |store| {
        let bad = states_of(store, bad_campaign);
        let fix = states_of(store, fix_campaign);
        bad.iter().all(|(_, s)| s.is_final())
            && fix.iter().any(|(v, s)| v == &vins[12] && s.is_final())
    });

    let events = &status(&after, &target).events;
    let refusals = events
        .iter()
        .filter(|e| e.contains("instruction refused") && e.contains("signature"))
        .count();
    assert_eq!(refusals, 2, "{events:?}");
    assert!(status(&after, &target).campaign_reports.is_empty());
    assert_eq!(
        status(&after, &target).cruise_version,
        status(&before, &target).cruise_version
    );
    let wrong = status(&after, &wrong_ecu_car);
    let report = wrong
        .campaign_reports
        .last()
        .expect("a report on the wrong image");
    assert_eq!(report.state, VehicleState::Refused);
    assert!(
        report.reason.as_ref().unwrap().contains("is for abs"),
        "{report:?}"
    );
    assert_eq!(
        wrong.cruise_version,
        status(&before, &wrong_ecu_car).cruise_version
    );

    let vehicles = store.campaign_vehicles(bad_campaign).unwrap();
    assert_eq!(vehicles[0].state, VehicleState::Refused, "{vehicles:?}");
    let reason = vehicles[0].reason.clone().unwrap();
    assert!(reason.contains("does not verify"), "{reason}");
    let old = status(&before, &bad_car).cruise_version.clone();
    assert_eq!(vehicles[0].version_running.as_ref(), Some(&old));
    assert_eq!(status(&after, &bad_car).cruise_version, old);
    let inventory = store.vehicle_inventory(&bad_car).unwrap();
    let cruise = inventory.iter().find(|e| e.ecu == "cruise").unwrap();
    assert_eq!(cruise.software_version.as_ref(), Some(&old));

    // The offline car has not answered; back online, it gets the update from its session.
    let states = states_of(&mut store, fix_campaign);
    assert!(
        states.contains(&(offline_car.clone(), VehicleState::Sent)),
        "{states:?}"
    );
    assert!(
        states.contains(&(vins[12].clone(), VehicleState::Installed)),
        "{states:?}"
    );
    fleet
        .order(Order::Online(vec![offline_car.clone()]))
        .unwrap();
    let after = park_until(&mut fleet, address, Duration::from_secs(60), |store| {
        states_of(store, fix_campaign)
            .iter()
            .all(|(_, s)| *s == VehicleState::Installed)
    });
    assert!(states_of(&mut store, fix_campaign)
        .iter()
        .all(|(_, s)| *s == VehicleState::Installed));
    assert_eq!(status(&after, &offline_car).cruise_version, "1.2.0");
    fleet.finish();
}

#[test]
fn staged_pause_forged_instructions_bad_images_and_an_offline_car_on_both_engines() {
    let _one = one_fleet();
    let dir = tempfile::tempdir().unwrap();
    let address = dir.path().join("fleet.db").display().to_string();
    failures_forgeries_and_an_offline_car(&address, "sqlite-2", 500_000);
    let schema = PgSchema::new();
    failures_forgeries_and_an_offline_car(&schema.url, "postgres-2", 700_000);
}

/// A gateway's fleet link as it starts: identified as `vin`, connected, its state in
/// `state_file`.
fn started_link(
    runtime: &tokio::runtime::Runtime,
    vin: autoplug_vin::Vin,
    state_file: &std::path::Path,
) -> autoplug_fleet_agent::link::FleetLink {
    let mut config = fleet_config();
    config.state_file = Some(state_file.to_path_buf());
    let mut link = autoplug_fleet_agent::link::FleetLink::new(config, runtime.handle().clone());
    let cruise = autoplug_store::EcuIdentity {
        ecu: "cruise".into(),
        node: 0x0D,
        part_number: Some("AP-CRUISE-0001".into()),
        software_version: Some("1.1.0".into()),
        hardware_version: Some("NUCLEO-F446RE".into()),
        serial_number: Some("AP0D00000001".into()),
    };
    link.on_identification(Ok(Some(vin)), vec![cruise]);
    wait_for("the link's connection", Duration::from_secs(10), || {
        link.status()
            .is_some_and(|s| s.connected && s.granted.len() == 2)
    });
    link
}

/// Polls `link` until an event contains `needle`.
fn wait_event(link: &mut autoplug_fleet_agent::link::FleetLink, needle: &str) {
    let state = autoplug_gateway::CarState::new();
    let deadline = Instant::now() + Duration::from_secs(10);
    while !link.events().any(|e| e.contains(needle)) {
        assert!(
            Instant::now() < deadline,
            "no event with '{needle}': {:?}",
            link.events().collect::<Vec<_>>()
        );
        link.poll(&state, None);
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn an_instruction_captured_and_played_again_after_a_restart_is_refused() {
    // Its car reports an inventory, which the other tests' services would take.
    let _one = one_fleet();
    let runtime = runtime();
    let dir = tempfile::tempdir().unwrap();
    let state_file = dir.path().join("fleet-state.json");
    let serial = std::process::id() % 100_000;
    let vin = autoplug_vin::Vin::with_check_digit(&format!("JA3AP47H0YR{serial:06}")).unwrap();
    let image = fixed_cruise();
    let instruction = cruise_instruction(5, 41, vin.as_str(), &image);
    let captured = instruction.sign(&fleet_key());
    let broker: Broker = broker_url().parse().unwrap();
    let attacker = MqttLink::connect(
        runtime.handle(),
        &broker,
        LinkOptions::new(format!("replayer-{serial}")),
    );
    attacker.wait_connected(Duration::from_secs(10)).unwrap();

    // First ignition: the instruction arrives from the fleet and is taken; its number is
    // kept on disk.
    let mut first = started_link(&runtime, vin, &state_file);
    attacker
        .publish(&topics::command(&vin), captured.clone(), false)
        .unwrap();
    wait_event(&mut first, "campaign 41 (campaign-41): fetching");
    first.close(Duration::from_secs(1));
    let kept: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&state_file).unwrap()).unwrap();
    assert_eq!(kept["newest_instruction"], 5, "{kept}");

    // Next ignition: the same bytes played to it again are refused.
    let mut second = started_link(&runtime, vin, &state_file);
    attacker
        .publish(&topics::command(&vin), captured, false)
        .unwrap();
    wait_event(&mut second, "not newer than the newest taken, 5");
    assert_eq!(second.activity(), None);
    assert!(second.offer().is_none());
}
