//! Campaigns in the store, on both engines: the exact target, staged instructions signed
//! by the fleet, retries within bounds, no-answer, the automatic pause at the failure
//! threshold. (The vehicles' side, over the broker and the bus: the simulated fleet.)

mod common;

use autoplug_can::Node;
use autoplug_fleet::campaign::{CampaignReport, Instruction, VehicleState};
use autoplug_fleet::campaigns::{CampaignSpec, CampaignState, Target};
use autoplug_fleet::{FleetStore, InventoryQuery, InventoryReport};
use autoplug_image::{SigningKey, SoftwareVariant, Version};
use autoplug_store::EcuIdentity;
use autoplug_vin::Vin;
use common::engines;

fn vin(n: u32) -> String {
    Vin::with_check_digit(&format!("JA3AP47H0YF{n:06}"))
        .unwrap()
        .to_string()
}

/// Vehicles 0..n: odd ones carry cruise 1.1.0 (the faulty software), even ones 1.0.0.
fn fleet(store: &mut FleetStore, n: u32) {
    for i in 0..n {
        let version = if i % 2 == 1 { "1.1.0" } else { "1.0.0" };
        store
            .record_inventory(&InventoryReport {
                vin: vin(i),
                read_at_ms: 1,
                ecus: vec![EcuIdentity {
                    ecu: "cruise".into(),
                    node: 0x0D,
                    part_number: Some("AP-CRUISE".into()),
                    software_version: Some(version.into()),
                    hardware_version: Some("NUCLEO-F446RE".into()),
                    serial_number: Some(format!("SN{i:04}")),
                }],
            })
            .unwrap();
    }
}

fn spec(name: &str) -> CampaignSpec {
    let image = autoplug_virtual_car::diag::build_image(
        Node::Cruise,
        Version::new(1, 2, 0),
        SoftwareVariant::Standard,
        1024,
        &SigningKey::from_seed(autoplug_image::dev::SIGNING_SEED),
    );
    let mut spec = CampaignSpec::new(
        name,
        "cruise",
        image,
        Target::Inventory(InventoryQuery {
            ecu: Some("cruise".into()),
            software_from: Some(Version::new(1, 1, 0)),
            software_to: Some(Version::new(1, 1, 0)),
            ..InventoryQuery::default()
        }),
    );
    spec.stages = vec![20.0, 100.0];
    spec.failure_threshold = 0.25;
    spec.max_attempts = 2;
    spec.answer_within_ms = 60_000;
    spec
}

fn report(campaign: i64, vin: &str, attempt: u32, state: VehicleState) -> CampaignReport {
    CampaignReport {
        vin: vin.to_string(),
        campaign,
        attempt,
        state,
        reason: (state == VehicleState::Failed).then(|| "the ECU did not answer".into()),
        ecu: "cruise".into(),
        version_running: Some(
            if state == VehicleState::Installed {
                "1.2.0"
            } else {
                "1.1.0"
            }
            .into(),
        ),
        at_ms: 0,
    }
}

#[test]
fn a_campaign_reaches_exactly_its_vehicles_stage_by_stage_and_finishes() {
    let key = SigningKey::from_seed([3; 32]);
    for engine in engines() {
        let mut store = engine.open();
        fleet(&mut store, 20);
        let created = store.create_campaign(&spec("cruise-fix"), 0).unwrap();
        let targets: Vec<String> = (0..20).filter(|i| i % 2 == 1).map(vin).collect();
        let mut expected = targets.clone();
        expected.sort();
        assert_eq!(
            created
                .vehicles
                .iter()
                .map(|(v, _)| v.clone())
                .collect::<Vec<_>>(),
            expected,
            "{}",
            engine.label()
        );
        // The same name again is refused.
        assert!(store.create_campaign(&spec("cruise-fix"), 0).is_err());
        // A report for the campaign once it is over is refused (below, at the end).

        // Stage 1: 20 % of 10 = 2 vehicles, each with an instruction only it can open.
        let first = store.campaign_tick(&key, 1_000).unwrap();
        assert_eq!(first.len(), 2, "{}", engine.label());
        for d in &first {
            let i = Instruction::open(&d.payload, &key.public_key(), &d.vin, 1_000).unwrap();
            assert_eq!(
                (
                    i.campaign,
                    i.ecu.as_str(),
                    i.version.as_str(),
                    i.attempt,
                    i.number
                ),
                (created.id, "cruise", "1.2.0", 1, 1)
            );
            assert!(d.topic.ends_with(&format!("{}/command/campaign", d.vin)));
        }
        // Nothing more while the stage runs.
        assert!(store.campaign_tick(&key, 2_000).unwrap().is_empty());
        for d in &first {
            store
                .record_campaign_report(&report(created.id, &d.vin, 1, VehicleState::Received))
                .unwrap();
            store
                .record_campaign_report(&report(created.id, &d.vin, 1, VehicleState::Installed))
                .unwrap();
        }
        // A report from a vehicle outside the campaign is refused.
        let outsider =
            store.record_campaign_report(&report(created.id, &vin(0), 1, VehicleState::Installed));
        assert!(outsider
            .unwrap_err()
            .to_string()
            .contains("not a vehicle of campaign"));

        // Stage 2: the other 8.
        let second = store.campaign_tick(&key, 3_000).unwrap();
        assert_eq!(second.len(), 8);
        // One fails once and is retried; one never answers; the rest install.
        let (failing, silent) = (&second[0].vin, &second[1].vin);
        store
            .record_campaign_report(&report(created.id, failing, 1, VehicleState::Failed))
            .unwrap();
        for d in &second[2..] {
            store
                .record_campaign_report(&report(created.id, &d.vin, 1, VehicleState::Installed))
                .unwrap();
        }
        let retry = store.campaign_tick(&key, 4_000).unwrap();
        assert_eq!(
            retry.iter().map(|d| &d.vin).collect::<Vec<_>>(),
            vec![failing]
        );
        let opened =
            Instruction::open(&retry[0].payload, &key.public_key(), failing, 4_000).unwrap();
        // Each instruction for a vehicle is numbered after the one before (the car refuses
        // one not newer than the newest it took).
        assert_eq!((opened.attempt, opened.number), (2, 2));
        store
            .record_campaign_report(&report(created.id, failing, 2, VehicleState::Installed))
            .unwrap();
        // The silent one: sent again after its answer time, then reported as not answering.
        let again = store.campaign_tick(&key, 3_000 + 60_000).unwrap();
        assert_eq!(
            again.iter().map(|d| &d.vin).collect::<Vec<_>>(),
            vec![silent]
        );
        assert!(store
            .campaign_tick(&key, 3_000 + 60_000 + 60_000)
            .unwrap()
            .is_empty());

        let info = store.campaign(&created.id.to_string()).unwrap();
        assert_eq!(info.state, CampaignState::Finished, "{}", engine.label());
        // A report after the end (a captured instruction played to a car that then
        // installed, or declined) is refused: the campaign keeps what it ended with.
        let late = store
            .record_campaign_report(&report(created.id, silent, 2, VehicleState::Installed))
            .unwrap_err();
        assert!(late.to_string().contains("which is finished"), "{late}");
        assert_eq!(info.counts.get("installed"), Some(&9));
        assert_eq!(info.counts.get("no_answer"), Some(&1));
        let vehicles = store.campaign_vehicles(created.id).unwrap();
        let silent_row = vehicles.iter().find(|v| &v.vin == silent).unwrap();
        assert_eq!(
            (silent_row.state, silent_row.attempts),
            (VehicleState::NoAnswer, 2)
        );
        assert!(vehicles
            .iter()
            .filter(|v| v.state == VehicleState::Installed)
            .all(|v| v.version_running.as_deref() == Some("1.2.0")));
    }
}

#[test]
fn a_stage_whose_failures_pass_the_threshold_pauses_the_campaign() {
    let key = SigningKey::from_seed([3; 32]);
    for engine in engines() {
        let mut store = engine.open();
        fleet(&mut store, 40);
        let mut spec = spec("planted-failures");
        spec.max_attempts = 1;
        let created = store.create_campaign(&spec, 0).unwrap();
        // Stage 1: 20 % of 20 = 4 vehicles; two refuse the image (50 % > 25 %).
        let first = store.campaign_tick(&key, 1_000).unwrap();
        assert_eq!(first.len(), 4);
        for (k, d) in first.iter().enumerate() {
            let state = if k < 2 {
                VehicleState::Refused
            } else {
                VehicleState::Installed
            };
            store
                .record_campaign_report(&report(created.id, &d.vin, 1, state))
                .unwrap();
        }
        assert!(
            store.campaign_tick(&key, 2_000).unwrap().is_empty(),
            "{}",
            engine.label()
        );
        let info = store.campaign(&created.id.to_string()).unwrap();
        assert_eq!(info.state, CampaignState::Paused);
        assert_eq!(info.stage, 0);
        assert!(
            info.paused_reason
                .as_deref()
                .unwrap()
                .contains("2 of 4 vehicles failed"),
            "{:?}",
            info.paused_reason
        );
        // The rest got nothing; resumed by hand, the next stage goes out.
        assert_eq!(info.counts.get("waiting"), Some(&16));
        store.resume_campaign(created.id).unwrap();
        // Still above the threshold: it pauses again at once rather than go on.
        assert!(store.campaign_tick(&key, 3_000).unwrap().is_empty());
        assert_eq!(
            store.campaign(&created.id.to_string()).unwrap().state,
            CampaignState::Paused
        );
    }
}

#[test]
fn bad_campaigns_are_refused_with_the_reason() {
    for engine in engines() {
        let mut store = engine.open();
        fleet(&mut store, 4);
        let mut wrong_ecu = spec("wrong-ecu");
        wrong_ecu.ecu = "abs".into();
        assert!(store
            .create_campaign(&wrong_ecu, 0)
            .unwrap_err()
            .to_string()
            .contains("not for abs"));
        let mut stages = spec("stages");
        stages.stages = vec![50.0, 40.0];
        assert!(store
            .create_campaign(&stages, 0)
            .unwrap_err()
            .to_string()
            .contains("stages"));
        let mut nobody = spec("nobody");
        nobody.target = Target::Inventory(InventoryQuery {
            part_number: Some("NO-SUCH-PART".into()),
            ..InventoryQuery::default()
        });
        assert!(store
            .create_campaign(&nobody, 0)
            .unwrap_err()
            .to_string()
            .contains("no vehicle"));
        let mut junk = spec("junk");
        junk.image = b"not an image".to_vec();
        assert!(store
            .create_campaign(&junk, 0)
            .unwrap_err()
            .to_string()
            .contains("not an AutoPlug image"));
    }
}
