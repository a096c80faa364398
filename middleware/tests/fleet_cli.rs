//! `autoplug fleet …` end to end on the real broker (`AUTOPLUG_TEST_MQTT`, default the
//! local Mosquitto) and an SQLite fleet database: recall, a campaign created from the
//! command line, its signed instruction and retained image reaching the vehicle, the
//! vehicle's report stored by `fleet serve`, the state on the command line.

use std::time::Duration;

use autoplug_can::Node;
use autoplug_fleet::campaign::{CampaignReport, Instruction, VehicleState};
use autoplug_fleet::mqtt::{Broker, LinkOptions, MqttLink};
use autoplug_fleet::topics::{self, ReportKind};
use autoplug_fleet::{FleetStore, InventoryReport};
use autoplug_image::{SigningKey, SoftwareVariant, Version};
use autoplug_middleware::cli::{run, Cli};
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
        .unwrap_or_else(|e| panic!("{e} (scripts/setup installs and starts Mosquitto)"));
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
        "--clean-session",
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
