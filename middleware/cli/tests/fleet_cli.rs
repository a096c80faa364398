//! `autoplug fleet …` end to end on the real broker (`AUTOPLUG_TEST_MQTT`, default the
//! local Mosquitto) and an SQLite fleet database: recall, a campaign created from the
//! command line, its signed instruction and retained image reaching the vehicle, the
//! vehicle's report stored by `fleet serve`, the state on the command line.

use std::time::Duration;

use autoplug_can::Node;
use autoplug_cli::cli::{run, Cli};
use autoplug_fleet::campaign::{CampaignReport, Instruction, VehicleState};
use autoplug_fleet::mqtt::{Broker, LinkOptions, MqttLink};
use autoplug_fleet::topics::{self, ReportKind};
use autoplug_fleet::{FleetStore, InventoryReport};
use autoplug_image::{SigningKey, SoftwareVariant, Version};
use autoplug_store::EcuIdentity;
use autoplug_vin::Vin;
use clap::Parser;

fn run_args(args: &[String]) -> Result<String, String> {
    let cli =
        Cli::try_parse_from(std::iter::once("autoplug".to_string()).chain(args.iter().cloned()))
            .map_err(|e| e.to_string())?;
    let mut out = Vec::new();
    let result = run(cli, &mut out);
    let text = String::from_utf8(out).unwrap();
    result
        .map(|()| text.clone())
        .map_err(|e| format!("{text}{e}"))
}

fn args(list: &[&str]) -> Vec<String> {
    list.iter().map(|s| s.to_string()).collect()
}

fn broker_url() -> String {
    std::env::var("AUTOPLUG_TEST_MQTT").unwrap_or_else(|_| "mqtt://127.0.0.1:1883".to_string())
}

#[test]
fn a_campaign_from_the_command_line_reaches_its_vehicle_and_the_report_comes_back() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("fleet.db").display().to_string();
    let pid = std::process::id() % 100_000;
    // Two vehicles with the faulty cruise software, one with the fix already.
    let vins: Vec<Vin> = (0..3)
        .map(|i| Vin::with_check_digit(&format!("JA3AP47H0YC{:06}", pid * 10 + i)).unwrap())
        .collect();
    {
        let mut store = FleetStore::open(&db).unwrap();
        for (i, vin) in vins.iter().enumerate() {
            store
                .record_inventory(&InventoryReport {
                    vin: vin.to_string(),
                    read_at_ms: 1,
                    ecus: vec![EcuIdentity {
                        ecu: "cruise".into(),
                        node: 0x0D,
                        part_number: Some("AP-CRUISE".into()),
                        software_version: Some(if i < 2 { "1.1.0" } else { "1.2.0" }.into()),
                        hardware_version: Some("NUCLEO-F446RE".into()),
                        serial_number: Some(format!("SN{i}")),
                    }],
                })
                .unwrap();
        }
    }
    let recall = run_args(&args(&[
        "fleet",
        "recall",
        "--db",
        &db,
        "--ecu",
        "cruise",
        "--software-from",
        "1.1.0",
        "--software-to",
        "1.1.9",
    ]))
    .unwrap();
    assert!(
        recall.contains(vins[0].as_str()) && recall.contains(vins[1].as_str()),
        "{recall}"
    );
    assert!(
        !recall.contains(vins[2].as_str()) && recall.contains("2 vehicle(s)"),
        "{recall}"
    );

    // The fleet's key and the fix, signed with the ECUs' key.
    let key_path = dir.path().join("fleet");
    run_args(&args(&["keygen", "--out", key_path.to_str().unwrap()])).unwrap();
    let fleet_key =
        SigningKey::parse(&std::fs::read_to_string(dir.path().join("fleet.key")).unwrap()).unwrap();
    let image = autoplug_virtual_car::diag::build_image(
        Node::Cruise,
        Version::new(1, 2, 0),
        SoftwareVariant::Standard,
        2048,
        &SigningKey::from_seed(autoplug_image::dev::SIGNING_SEED),
    );
    let image_path = dir.path().join("cruise-1.2.0.img");
    std::fs::write(&image_path, &image).unwrap();

    // The vehicle is online before the campaign: subscribed to its commands.
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let broker: Broker = broker_url().parse().unwrap();
    let mut options = LinkOptions::new(vins[0].to_string());
    options.subscriptions = vec![topics::command(&vins[0])];
    let mut car = MqttLink::connect(runtime.handle(), &broker, options);
    car.wait_connected(Duration::from_secs(5))
        .unwrap_or_else(|e| panic!("{e} (scripts/setup-tests installs and starts Mosquitto)"));
    while car.status().granted.is_empty() {
        std::thread::sleep(Duration::from_millis(10));
    }

    let name = format!("cruise-fix-{pid}");
    let created = run_args(&args(&[
        "fleet",
        "campaign",
        "create",
        "--db",
        &db,
        "--broker",
        &broker_url(),
        "--name",
        &name,
        "--for",
        "cruise",
        "--image",
        image_path.to_str().unwrap(),
        "--ecu",
        "cruise",
        "--software-from",
        "1.1.0",
        "--software-to",
        "1.1.9",
        "--stages",
        "100",
        "--message",
        "fixes the cruise control's speed oscillation",
    ]))
    .unwrap();
    assert!(created.contains("2 vehicle(s) in 1 stage(s)"), "{created}");

    // The service sends the instructions and stores what comes back.
    let group = format!("fleet-cli-test-{pid}");
    let serve_args = args(&[
        "fleet",
        "serve",
        "--db",
        &db,
        "--broker",
        &broker_url(),
        "--key",
        dir.path().join("fleet.key").to_str().unwrap(),
        "--tick",
        "0.1",
        "--duration",
        "4",
        "--client-id",
        &group,
        "--group",
        &group,
    ]);
    let service = std::thread::spawn(move || run_args(&serve_args));

    let message = car
        .recv_timeout(Duration::from_secs(5))
        .expect("the instruction arrives");
    assert_eq!(message.topic, topics::command(&vins[0]));
    let instruction = Instruction::open(
        &message.payload,
        &fleet_key.public_key(),
        vins[0].as_str(),
        autoplug_fleet::campaign::now_ms(),
    )
    .unwrap();
    assert_eq!(
        (instruction.ecu.as_str(), instruction.version.as_str()),
        ("cruise", "1.2.0")
    );
    assert_eq!(
        instruction.message,
        "fixes the cruise control's speed oscillation"
    );
    // The image it names is retained at the broker, byte for byte.
    car.subscribe(&topics::image(&instruction.image_sha256))
        .unwrap();
    let fetched = car
        .recv_timeout(Duration::from_secs(5))
        .expect("the image arrives");
    assert!(fetched.retained);
    assert_eq!(fetched.payload, image);

    let report = CampaignReport {
        vin: vins[0].to_string(),
        campaign: instruction.campaign,
        attempt: instruction.attempt,
        state: VehicleState::Installed,
        reason: None,
        ecu: "cruise".into(),
        version_running: Some("1.2.0".into()),
        at_ms: autoplug_fleet::campaign::now_ms(),
    };
    car.publish(
        &topics::report(&vins[0], ReportKind::Campaign),
        serde_json::to_vec(&report).unwrap(),
        false,
    )
    .unwrap();
    let served = service.join().unwrap().unwrap();
    assert!(served.contains("1 campaign reports"), "{served}");

    let status = run_args(&args(&["fleet", "campaign", "status", &name, "--db", &db])).unwrap();
    let line = |vin: &Vin| {
        status
            .lines()
            .find(|l| l.starts_with(vin.as_str()))
            .unwrap_or("")
            .to_string()
    };
    assert!(
        line(&vins[0]).contains("installed") && line(&vins[0]).contains("1.2.0"),
        "{status}"
    );
    assert!(line(&vins[1]).contains("sent"), "{status}");
    assert!(line(&vins[2]).is_empty(), "{status}");
    // Bad input is named.
    let e = run_args(&args(&["fleet", "campaign", "status", "nope", "--db", &db])).unwrap_err();
    assert!(e.contains("no campaign 'nope'"), "{e}");
    let e = run_args(&args(&[
        "fleet",
        "recall",
        "--db",
        &db,
        "--software-from",
        "one",
    ]))
    .unwrap_err();
    assert!(e.contains("one"), "{e}");
}

#[test]
fn fleet_simulate_runs_its_cars_reports_them_to_the_broker_and_writes_its_truth() {
    let dir = tempfile::tempdir().unwrap();
    let key_base = dir.path().join("fleet");
    run_args(&args(&["keygen", "--out", &key_base.display().to_string()])).unwrap();
    let fleet_pub = dir.path().join("fleet.pub").display().to_string();
    let truth = dir.path().join("truth.json");
    // Serials of their own (the other fleet tests use 100000 and up by hundreds).
    let first_serial = 800_000 + (std::process::id() % 1000) * 10;
    let broker: Broker = broker_url().parse().unwrap();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let mut options = LinkOptions::new(format!("simulate-test-{}", std::process::id()));
    options.subscriptions = vec![topics::REPORTS.to_string()];
    let mut listener = MqttLink::connect(runtime.handle(), &broker, options);
    listener.wait_connected(Duration::from_secs(10)).unwrap();
    // The subscription is granted before the cars start.
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while listener.status().granted.is_empty() && std::time::Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }

    let output = run_args(&args(&[
        "fleet",
        "simulate",
        "--vehicles",
        "6",
        "--drives",
        "1",
        "--seed",
        "11",
        "--first-serial",
        &first_serial.to_string(),
        "--threads",
        "2",
        "--broker",
        &broker_url(),
        "--fleet-key",
        &fleet_pub,
        "--truth",
        &truth.display().to_string(),
    ]))
    .unwrap();
    assert!(output.starts_with("6 cars ("), "{output}");
    assert!(output.contains("drive 1 ("), "{output}");
    assert!(!output.contains("errors:"), "{output}");

    let cars: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(&truth).unwrap()).unwrap();
    assert_eq!(cars.len(), 6);
    let mut vins = Vec::new();
    for car in &cars {
        let vin = car["plan"]["vin"].as_str().unwrap().to_string();
        Vin::parse(&vin).unwrap_or_else(|e| panic!("{vin}: {e}"));
        assert_eq!(car["outcome"]["vin"].as_str(), Some(vin.as_str()));
        let drives = car["outcome"]["drives"].as_array().unwrap();
        assert_eq!(drives.len(), 1, "{car}");
        assert!(drives[0]["distance_m"].as_f64().unwrap() > 100.0, "{car}");
        vins.push(vin);
    }
    vins.sort();
    vins.dedup();
    assert_eq!(vins.len(), 6, "the cars' VINs are distinct");

    // Each car reported its inventory and its drive through the broker, as itself.
    let mut inventories = std::collections::BTreeSet::new();
    let mut trips = std::collections::BTreeSet::new();
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    while (inventories.len() < 6 || trips.len() < 6) && std::time::Instant::now() < deadline {
        let Some(message) = listener.recv_timeout(Duration::from_millis(200)) else {
            continue;
        };
        let Ok((vin, kind)) = topics::parse_report(&message.topic) else {
            continue;
        };
        let vin = vin.to_string();
        if !vins.contains(&vin) {
            continue;
        }
        match kind {
            ReportKind::Inventory => {
                let report: InventoryReport = serde_json::from_slice(&message.payload).unwrap();
                assert_eq!(report.vin, vin);
                assert_eq!(
                    report.ecus.len(),
                    Node::ECUS.len(),
                    "{vin}: {:?}",
                    report.ecus
                );
                inventories.insert(vin);
            }
            ReportKind::Trip => {
                let report: autoplug_fleet::TripReport =
                    serde_json::from_slice(&message.payload).unwrap();
                assert_eq!(report.vin, vin);
                if report.stats.distance_m > 100.0 {
                    trips.insert(vin);
                }
            }
            ReportKind::Campaign => {}
        }
    }
    assert_eq!(inventories.len(), 6, "inventories from {inventories:?}");
    assert_eq!(trips.len(), 6, "drives from {trips:?}");
    listener.close(Duration::from_secs(2));
}

#[test]
fn a_gateway_reports_to_a_fleet_only_when_it_may_transmit_and_knows_the_fleet_key() {
    let dir = tempfile::tempdir().unwrap();
    let scenario = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../scenarios/cruise-hold.toml"
    );
    let bus = format!("virtual:{scenario}");
    let no_key = run_args(&args(&[
        "gateway",
        "--bus",
        &bus,
        "--no-db",
        "--quiet",
        "--fast",
        "--transmit",
        "--fleet",
        "mqtt://127.0.0.1:1",
    ]))
    .unwrap_err();
    assert!(no_key.contains("--fleet needs --fleet-key"), "{no_key}");
    run_args(&args(&[
        "keygen",
        "--out",
        &dir.path().join("fleet").display().to_string(),
    ]))
    .unwrap();
    let key = dir.path().join("fleet.pub").display().to_string();
    let listening = run_args(&args(&[
        "gateway",
        "--bus",
        &bus,
        "--no-db",
        "--quiet",
        "--fast",
        "--fleet",
        "mqtt://127.0.0.1:1",
        "--fleet-key",
        &key,
    ]))
    .unwrap_err();
    assert!(
        listening.contains("--fleet needs --transmit"),
        "{listening}"
    );
    let missing = run_args(&args(&[
        "gateway",
        "--bus",
        &bus,
        "--no-db",
        "--transmit",
        "--fleet",
        "mqtt://127.0.0.1:1",
        "--fleet-key",
        &dir.path().join("nowhere.pub").display().to_string(),
    ]))
    .unwrap_err();
    assert!(missing.contains("nowhere.pub"), "{missing}");
    let bad_url = run_args(&args(&["gateway", "--bus", &bus, "--fleet", "http://x"])).unwrap_err();
    assert!(bad_url.contains("--fleet"), "{bad_url}");

    // With both, on the real broker: the gateway reads the VIN, connects as that vehicle
    // and has handed every report over when it ends.
    let reported = run_args(&args(&[
        "gateway",
        "--bus",
        &bus,
        "--no-db",
        "--quiet",
        "--fast",
        "--transmit",
        "--fleet",
        &broker_url(),
        "--fleet-key",
        &key,
    ]))
    .unwrap();
    assert!(
        reported.contains("fleet: reported as ")
            && reported.contains(" 0 not published, 0 dropped"),
        "{reported}"
    );
}

/// A raw HTTP/1.1 GET with the `Host` given: the status line's code and the body.
fn get_with_host(addr: &str, path: &str, host: &str) -> (u16, String) {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(addr).unwrap();
    stream
        .set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap();
    write!(
        stream,
        "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
    )
    .unwrap();
    let mut response = String::new();
    let _ = stream.read_to_string(&mut response);
    let code = response
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    (code, response)
}

#[test]
fn fleet_serve_with_its_page_answers_only_its_own_names_and_ends_cleanly_on_postgresql() {
    let schema = autoplug_fleet::testing::PgSchema::new();
    let port = autoplug_fleet::testing::free_port();
    let addr = format!("127.0.0.1:{port}");
    let client_id = format!("fleet-web-test-{}", std::process::id());
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_autoplug"))
        .args([
            "fleet",
            "serve",
            "--db",
            &schema.url,
            "--broker",
            &broker_url(),
            "--client-id",
            &client_id,
            "--web",
            &addr,
            "--allowed-host",
            "fleet.example",
            "--duration",
            "4",
        ])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    while std::net::TcpStream::connect(&addr).is_err() {
        assert!(
            std::time::Instant::now() < deadline,
            "the page never listened"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    // Its own address and the allowed name are answered; a name pointed at it by a page
    // elsewhere (DNS rebinding) is refused before anything is read.
    let (own, body) = get_with_host(&addr, "/api/fleet", &addr);
    assert_eq!(own, 200, "{body}");
    assert!(body.contains("\"summary\""), "{body}");
    let (allowed, _) = get_with_host(&addr, "/api/fleet", &format!("fleet.example:{port}"));
    assert_eq!(allowed, 200);
    let (foreign, body) = get_with_host(&addr, "/api/fleet", &format!("attacker.example:{port}"));
    assert_eq!(foreign, 421, "{body}");
    assert!(!body.contains("\"summary\""), "{body}");
    // It ends by itself: status 0 and nothing panicked on the way out (the page's
    // PostgreSQL client was dropped inside the web server's runtime and panicked).
    let output = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn fleet_simulate_logs_each_car_in_as_itself_on_the_shipped_broker_and_its_drivers_decline() {
    let broker = autoplug_fleet::testing::PrivateBroker::start();
    broker.add_login(autoplug_fleet::broker::FLEET_USER, "pw-fleet");
    let dir = tempfile::tempdir().unwrap();
    let key_base = dir.path().join("fleet");
    run_args(&args(&["keygen", "--out", &key_base.display().to_string()])).unwrap();
    let fleet_pub = dir.path().join("fleet.pub").display().to_string();
    let truth = dir.path().join("truth.json");
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    // The fleet's side reads every report on its own listener.
    let mut options = LinkOptions::new("simulate-logins-test");
    options.subscriptions = vec![topics::REPORTS.to_string()];
    let mut listener = MqttLink::connect(
        runtime.handle(),
        &broker.url(autoplug_fleet::broker::FLEET_USER, "pw-fleet"),
        options,
    );
    listener.wait_connected(Duration::from_secs(10)).unwrap();
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while listener.status().granted.is_empty() && std::time::Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(20));
    }
    let vehicles = format!("mqtt://127.0.0.1:{}", broker.port);
    let simulate = |share: &str| {
        run_args(&args(&[
            "fleet",
            "simulate",
            "--vehicles",
            "4",
            "--drives",
            "1",
            "--seed",
            "12",
            "--threads",
            "2",
            "--broker",
            &vehicles,
            "--broker-dir",
            &broker.files.dir.display().to_string(),
            "--decline-share",
            share,
            "--fleet-key",
            &fleet_pub,
            "--truth",
            &truth.display().to_string(),
        ]))
    };
    let wrong = simulate("1.5").unwrap_err();
    assert!(wrong.contains("--decline-share is a fraction"), "{wrong}");
    let output = simulate("1").unwrap();
    assert!(output.contains("4 logins added"), "{output}");
    assert!(!output.contains("errors:"), "{output}");
    let cars: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(&truth).unwrap()).unwrap();
    // Every driver declines (a share of 1), and no password reached the truth.
    assert!(
        cars.iter().all(|c| c["plan"]["consents"] == false),
        "{cars:?}"
    );
    assert!(!std::fs::read_to_string(&truth)
        .unwrap()
        .contains("password"));
    // Each car reported as itself through its own login: the broker lets a login publish
    // only under its own VIN, and anonymous clients not at all.
    let vins: std::collections::BTreeSet<String> = cars
        .iter()
        .map(|c| c["plan"]["vin"].as_str().unwrap().to_string())
        .collect();
    let mut reported = std::collections::BTreeSet::new();
    let deadline = std::time::Instant::now() + Duration::from_secs(20);
    while reported.len() < vins.len() && std::time::Instant::now() < deadline {
        if let Some(message) = listener.recv_timeout(Duration::from_millis(200)) {
            if let Ok((vin, ReportKind::Inventory)) = topics::parse_report(&message.topic) {
                reported.insert(vin.to_string());
            }
        }
    }
    assert_eq!(reported, vins);
}
