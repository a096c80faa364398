use autoplug_image::{SigningKey, SoftwareVariant};
use autoplug_virtual_car::diag::{build_image, FACTORY_PAYLOAD_LEN};

use super::*;

const VIN: &str = "JA3AP47H0YF000042";
const NOW: i64 = 1_800_000_000_000;

fn fleet_key() -> SigningKey {
    SigningKey::from_seed([41; 32])
}

fn ecu_key() -> SigningKey {
    SigningKey::from_seed(autoplug_image::dev::SIGNING_SEED)
}

fn new_agent() -> VehicleAgent {
    VehicleAgent::new(AgentConfig {
        vin: Vin::parse(VIN).unwrap(),
        fleet_key: fleet_key().public_key(),
        image_key: ecu_key().public_key(),
    })
}

fn identity(ecu: &str, version: &str) -> EcuIdentity {
    EcuIdentity {
        ecu: ecu.into(),
        node: parse_ecu(ecu).and_then(|n| n.diag_node_number()).unwrap(),
        part_number: Some(format!("AP-{}-0001", ecu.to_uppercase())),
        software_version: Some(version.into()),
        hardware_version: Some("NUCLEO-F446RE".into()),
        serial_number: Some("AP0812345678".into()),
    }
}

fn inventory(cruise: &str) -> Vec<EcuIdentity> {
    vec![identity("engine", "1.0.0"), identity("cruise", cruise)]
}

fn fixed_image(node: Node, key: &SigningKey) -> Vec<u8> {
    build_image(
        node,
        Version::new(1, 2, 0),
        SoftwareVariant::Standard,
        FACTORY_PAYLOAD_LEN,
        key,
    )
}

fn instruction_for(image: &[u8], attempt: u32) -> Instruction {
    Instruction {
        number: attempt.into(),
        campaign: 3,
        name: "cruise-1.2.0".into(),
        vin: VIN.into(),
        ecu: "cruise".into(),
        image_sha256: sha256_hex(image),
        image_bytes: image.len() as u64,
        version: "1.2.0".into(),
        attempt,
        issued_at_ms: NOW,
        expires_at_ms: NOW + 86_400_000,
        message: "fixes the speed oscillation".into(),
    }
}

fn drain(agent: &mut VehicleAgent) -> Vec<Action> {
    std::iter::from_fn(|| agent.next_action()).collect()
}

/// The campaign reports among `actions`, decoded.
fn reports(actions: &[Action]) -> Vec<CampaignReport> {
    actions
        .iter()
        .filter_map(|a| match a {
            Action::Publish { topic, payload } if topic.ends_with("/report/campaign") => {
                Some(serde_json::from_slice(payload).unwrap())
            }
            _ => None,
        })
        .collect()
}

fn states(actions: &[Action]) -> Vec<VehicleState> {
    reports(actions).iter().map(|r| r.state).collect()
}

fn published_on(actions: &[Action], suffix: &str) -> usize {
    actions
        .iter()
        .filter(|a| matches!(a, Action::Publish { topic, .. } if topic.ends_with(suffix)))
        .count()
}

fn command_topic() -> String {
    topics::command(&Vin::parse(VIN).unwrap())
}

/// An agent running cruise 1.1.0 that has been sent `image`'s instruction.
fn instructed(image: &[u8]) -> VehicleAgent {
    let mut agent = new_agent();
    agent.on_inventory(inventory("1.1.0"), NOW);
    let signed = instruction_for(image, 1).sign(&fleet_key());
    agent.on_message(&command_topic(), &signed, NOW);
    agent
}

/// The same, with the image delivered: the driver is being asked.
fn offered(image: &[u8]) -> (VehicleAgent, Vec<Action>) {
    let mut agent = instructed(image);
    let mut actions = drain(&mut agent);
    agent.on_message(&topics::image(&sha256_hex(image)), image, NOW + 10);
    actions.extend(drain(&mut agent));
    (agent, actions)
}

#[test]
fn a_campaign_runs_from_instruction_to_installed_flashing_only_when_standing() {
    let image = fixed_image(Node::Cruise, &ecu_key());
    let (mut agent, actions) = offered(&image);
    assert_eq!(published_on(&actions, "/report/inventory"), 1);
    assert!(actions.contains(&Action::Subscribe(topics::image(&sha256_hex(&image)))));
    assert!(actions.contains(&Action::Unsubscribe(topics::image(&sha256_hex(&image)))));
    assert_eq!(states(&actions), [VehicleState::Received]);
    let offer = agent.offer().expect("the driver is asked");
    assert!(actions.contains(&Action::Ask(offer.clone())));
    assert_eq!(
        offer.question(),
        "An update for your cruise control is ready: install when parked?"
    );

    // Consent while driving: nothing is flashed until the car stands.
    agent.set_standing(false);
    agent.consent(3, true, NOW + 20).unwrap();
    let actions = drain(&mut agent);
    assert_eq!(states(&actions), [VehicleState::Installing]);
    assert!(!actions.iter().any(|a| matches!(a, Action::Flash { .. })));
    assert_eq!(agent.offer(), None);
    assert!(agent.consent(3, true, NOW).is_err(), "answered already");

    agent.set_standing(true);
    let actions = drain(&mut agent);
    let flashed: Vec<_> = actions
        .iter()
        .filter_map(|a| match a {
            Action::Flash { ecu, image } => Some((*ecu, image.clone())),
            _ => None,
        })
        .collect();
    assert_eq!(flashed, [(Node::Cruise, image.clone())]);

    // Installed only once the identification shows the new version.
    agent.flash_done(FlashResult::Flashed, NOW + 30);
    assert!(reports(&drain(&mut agent)).is_empty());
    agent.on_inventory(inventory("1.2.0"), NOW + 40);
    let actions = drain(&mut agent);
    assert_eq!(states(&actions), [VehicleState::Installed]);
    assert_eq!(
        reports(&actions)[0].version_running.as_deref(),
        Some("1.2.0")
    );
    assert_eq!(published_on(&actions, "/report/inventory"), 1, "it changed");

    // The same inventory again is not published; a repeated instruction gets the same
    // answer again, with no second flash.
    agent.on_inventory(inventory("1.2.0"), NOW + 50);
    let signed = instruction_for(&image, 1).sign(&fleet_key());
    agent.on_message(&command_topic(), &signed, NOW + 60);
    let actions = drain(&mut agent);
    assert_eq!(published_on(&actions, "/report/inventory"), 0);
    assert_eq!(states(&actions), [VehicleState::Installed]);
    assert!(!actions
        .iter()
        .any(|a| matches!(a, Action::Flash { .. } | Action::Subscribe(_))));
}

#[test]
fn forged_altered_and_foreign_instructions_are_refused_without_acting() {
    let image = fixed_image(Node::Cruise, &ecu_key());
    let mut agent = new_agent();
    agent.on_inventory(inventory("1.1.0"), NOW);
    drain(&mut agent);
    let forged = instruction_for(&image, 1).sign(&SigningKey::from_seed([9; 32]));
    let mut envelope: autoplug_fleet::campaign::Envelope =
        serde_json::from_slice(&instruction_for(&image, 1).sign(&fleet_key())).unwrap();
    envelope.instruction = envelope.instruction.replace("\"1.2.0\"", "\"1.0.0\"");
    let altered = serde_json::to_vec(&envelope).unwrap();
    let mut foreign = instruction_for(&image, 1);
    foreign.vin = "JA3AP47H3YF000777".into();
    let foreign = foreign.sign(&fleet_key());
    for (payload, why) in [
        (forged, "signature"),
        (altered, "signature"),
        (foreign, "JA3AP47H3YF000777"),
        (b"not json".to_vec(), "not a campaign instruction"),
    ] {
        agent.on_message(&command_topic(), &payload, NOW);
        let actions = drain(&mut agent);
        assert_eq!(actions.len(), 1, "{actions:?}");
        assert!(
            matches!(&actions[0], Action::Note(n) if n.contains("refused") && n.contains(why)),
            "{actions:?}"
        );
        assert_eq!(agent.activity(), None);
    }
}

#[test]
fn a_bad_image_is_refused_with_the_reason_before_the_driver_is_asked() {
    // Signed with another key than the ECUs', for another ECU, or older than what runs.
    let other_key = SigningKey::from_seed([5; 32]);
    let older = build_image(
        Node::Cruise,
        Version::new(1, 0, 5),
        SoftwareVariant::Standard,
        1024,
        &ecu_key(),
    );
    for (image, why) in [
        (fixed_image(Node::Cruise, &other_key), "does not verify"),
        (fixed_image(Node::ABS, &ecu_key()), "is for abs"),
        (older, "version 1.0.5"),
    ] {
        let mut agent = new_agent();
        agent.on_inventory(inventory("1.1.0"), NOW);
        let mut instruction = instruction_for(&image, 1);
        if why.starts_with("version") {
            instruction.version = "1.0.5".into();
        }
        agent.on_message(&command_topic(), &instruction.sign(&fleet_key()), NOW);
        agent.on_message(&topics::image(&sha256_hex(&image)), &image, NOW);
        let actions = drain(&mut agent);
        let reports = reports(&actions);
        assert_eq!(reports.len(), 1, "{why}: {actions:?}");
        assert_eq!(reports[0].state, VehicleState::Refused);
        let reason = reports[0].reason.clone().unwrap();
        assert!(reason.contains(why), "{reason}");
        assert_eq!(reports[0].version_running.as_deref(), Some("1.1.0"));
        assert!(!actions
            .iter()
            .any(|a| matches!(a, Action::Ask(_) | Action::Flash { .. })));
        assert_eq!(agent.offer(), None);
    }

    // An image that is not the one named: refused on its digest.
    let image = fixed_image(Node::Cruise, &ecu_key());
    let mut agent = instructed(&image);
    let mut swapped = image.clone();
    swapped[600] ^= 1;
    agent.on_message(&topics::image(&sha256_hex(&image)), &swapped, NOW);
    let reports = reports(&drain(&mut agent));
    assert!(reports[0].reason.as_ref().unwrap().contains("SHA-256"));
}

#[test]
fn the_ecus_refusal_and_a_failed_flash_are_reported_with_the_old_version() {
    let image = fixed_image(Node::Cruise, &ecu_key());
    for (result, state, why) in [
        (
            FlashResult::RefusedByEcu("0x31 refused: requestSequenceError".into()),
            VehicleState::Refused,
            "the cruise ECU refused the image: 0x31",
        ),
        (
            FlashResult::Failed("no answer to TransferData".into()),
            VehicleState::Failed,
            "no answer",
        ),
    ] {
        let (mut agent, _) = offered(&image);
        agent.set_standing(true);
        agent.consent(3, true, NOW).unwrap();
        assert!(drain(&mut agent)
            .iter()
            .any(|a| matches!(a, Action::Flash { .. })));
        agent.flash_done(result, NOW + 1);
        let reports = reports(&drain(&mut agent));
        assert_eq!(reports.len(), 1);
        assert_eq!(reports[0].state, state);
        assert!(reports[0].reason.as_ref().unwrap().contains(why));
        assert_eq!(reports[0].version_running.as_deref(), Some("1.1.0"));
        assert_eq!(agent.activity(), None);
    }

    // Flashed, but the ECU came back on its old software: failed, not installed.
    let (mut agent, _) = offered(&image);
    agent.set_standing(true);
    agent.consent(3, true, NOW).unwrap();
    agent.flash_done(FlashResult::Flashed, NOW);
    agent.on_inventory(inventory("1.1.0"), NOW + 1);
    let reports = reports(&drain(&mut agent));
    assert_eq!(reports.last().unwrap().state, VehicleState::Failed);
    assert!(reports
        .last()
        .unwrap()
        .reason
        .as_ref()
        .unwrap()
        .contains("runs 1.1.0"));
}

#[test]
fn declining_an_already_installed_version_and_an_instruction_before_the_inventory() {
    let image = fixed_image(Node::Cruise, &ecu_key());
    let (mut agent, _) = offered(&image);
    agent.consent(3, false, NOW).unwrap();
    let actions = drain(&mut agent);
    assert_eq!(states(&actions), [VehicleState::Declined]);
    assert!(actions.contains(&Action::Withdraw(3)));

    // The instruction waits for the inventory; a vehicle already running the version
    // answers installed without fetching anything.
    let mut agent = new_agent();
    agent.on_message(
        &command_topic(),
        &instruction_for(&image, 2).sign(&fleet_key()),
        NOW,
    );
    assert!(reports(&drain(&mut agent)).is_empty());
    agent.on_inventory(inventory("1.2.0"), NOW + 5);
    let actions = drain(&mut agent);
    assert_eq!(states(&actions), [VehicleState::Installed]);
    assert!(!actions.iter().any(|a| matches!(a, Action::Subscribe(_))));

    // A vehicle without the ECU refuses.
    let mut agent = new_agent();
    agent.on_inventory(vec![identity("engine", "1.0.0")], NOW);
    agent.on_message(
        &command_topic(),
        &instruction_for(&image, 1).sign(&fleet_key()),
        NOW,
    );
    let reports = reports(&drain(&mut agent));
    assert_eq!(reports[0].state, VehicleState::Refused);
    assert!(reports[0]
        .reason
        .as_ref()
        .unwrap()
        .contains("no cruise ECU"));
}

#[test]
fn an_image_that_never_comes_and_an_offer_that_expires_end_the_attempt() {
    let image = fixed_image(Node::Cruise, &ecu_key());
    let mut agent = instructed(&image);
    drain(&mut agent);
    agent.tick(NOW + IMAGE_WAIT_MS);
    assert!(reports(&drain(&mut agent)).is_empty());
    agent.tick(NOW + IMAGE_WAIT_MS + 1);
    assert_eq!(states(&drain(&mut agent)), [VehicleState::Failed]);

    let (mut agent, _) = offered(&image);
    agent.tick(NOW + 86_400_001);
    let actions = drain(&mut agent);
    assert!(actions.contains(&Action::Withdraw(3)));
    assert_eq!(agent.offer(), None);
}

#[test]
fn an_instruction_played_again_after_a_restart_is_refused_and_a_newer_one_taken() {
    // The driver declines campaign 3 (instruction number 1): the gateway is told to keep
    // the number.
    let image = fixed_image(Node::Cruise, &ecu_key());
    let (mut agent, actions) = offered(&image);
    assert!(actions.contains(&Action::Remember(1)), "{actions:?}");
    agent.consent(3, false, NOW).unwrap();
    drain(&mut agent);
    let kept = agent.newest_instruction();
    assert_eq!(kept, 1);

    // The next ignition: a new agent given the kept number. The captured instruction,
    // played to it again, is refused: nothing fetched, nothing offered, nothing reported.
    let captured = instruction_for(&image, 1).sign(&fleet_key());
    let mut agent = new_agent();
    agent.set_newest_instruction(kept);
    agent.on_inventory(inventory("1.1.0"), NOW + 1_000);
    drain(&mut agent);
    agent.on_message(&command_topic(), &captured, NOW + 2_000);
    let actions = drain(&mut agent);
    assert_eq!(actions.len(), 1, "{actions:?}");
    assert!(
        matches!(&actions[0], Action::Note(n) if n.contains("not newer than the newest taken, 1")),
        "{actions:?}"
    );
    assert_eq!(agent.activity(), None);
    assert_eq!(agent.offer(), None);

    // Without the kept number (a gateway that forgot it) the same bytes are acted on:
    // what the number protects against.
    let mut forgetful = new_agent();
    forgetful.on_inventory(inventory("1.1.0"), NOW + 1_000);
    forgetful.on_message(&command_topic(), &captured, NOW + 2_000);
    assert!(drain(&mut forgetful)
        .iter()
        .any(|a| matches!(a, Action::Subscribe(_))));

    // The fleet's next instruction for this vehicle (number 2, a new attempt) is taken.
    agent.on_message(
        &command_topic(),
        &instruction_for(&image, 2).sign(&fleet_key()),
        NOW + 3_000,
    );
    let actions = drain(&mut agent);
    assert!(actions.contains(&Action::Remember(2)), "{actions:?}");
    assert!(actions.iter().any(|a| matches!(a, Action::Subscribe(_))));
}
