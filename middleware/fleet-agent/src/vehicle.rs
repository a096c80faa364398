//! The vehicle's side of the fleet: what its gateway tells the fleet and how it carries
//! out a campaign, as a sans-IO state machine. It takes what happened (the inventory was
//! read, a trip ended, a message came from the broker, the driver answered, the car
//! stopped or moved, a flash ended) and gives what to do ([`Action`]: publish, subscribe,
//! ask the driver, flash an ECU over CAN). The gateway runs it against its MQTT link and
//! its tester; the tests run it against plain values.
//!
//! A campaign on the vehicle, in order (hawkBit's "download, then install when allowed",
//! Uptane's "the primary checks everything before an ECU sees a byte"):
//!
//! 1. The instruction's signature is checked with the fleet's key, then that it is for
//!    this VIN and not expired. Nothing else of it is read before that; an instruction
//!    that fails is noted and otherwise ignored (a forgery has no campaign to report to).
//!    Its number must be newer than the newest the vehicle has taken, which the gateway
//!    keeps across restarts ([`Action::Remember`]): a captured instruction played again
//!    (a finished campaign's, which the driver declined) is refused, as Uptane's vehicles
//!    refuse metadata older than what they have.
//! 2. The ECU must be in this vehicle's inventory; an ECU already running the version is
//!    reported installed at once (a retry, or a vehicle fixed at a workshop).
//! 3. The image is fetched (retained at the broker under its SHA-256) and checked: its
//!    length and SHA-256 against the instruction, its Ed25519 signature with the ECUs'
//!    image key, its header against the ECU (node, hardware, version named by the
//!    instruction, no downgrade). A failed check is reported `refused` with the reason;
//!    the ECU keeps its software.
//! 4. The driver is asked; declining is reported.
//! 5. With consent, the flash starts only while the car stands still.
//! 6. The ECU's own checks may still refuse the image (reported `refused` with the ECU's
//!    answer); a transfer may fail (`failed`). After a flash the gateway reads the
//!    identification again: `installed` only when the ECU answers with the new version.

use std::collections::VecDeque;

use autoplug_can::{ecu_name, parse_ecu, Node};
use autoplug_image::{hardware_name, ImageHeader, Version, PUBLIC_KEY_LEN};
use autoplug_store::EcuIdentity;
use autoplug_vin::Vin;

use autoplug_fleet::campaign::{sha256_hex, CampaignReport, Instruction, VehicleState};
use autoplug_fleet::report::{InventoryReport, TripReport};
use autoplug_fleet::topics::{self, ReportKind};

/// How long the image may take to arrive from the broker, ms, before the attempt fails.
pub const IMAGE_WAIT_MS: i64 = 10 * 60 * 1000;
/// How long after a flash the identification may take to show the new version, ms.
pub const CHECK_WAIT_MS: i64 = 2 * 60 * 1000;
/// Campaign reports kept to answer a repeated instruction with the same report.
const KEPT_REPORTS: usize = 8;

/// What the vehicle's agent needs to know.
#[derive(Clone, Debug)]
pub struct AgentConfig {
    /// The vehicle.
    pub vin: Vin,
    /// The fleet's public key: instructions must be signed with its secret half.
    pub fleet_key: [u8; PUBLIC_KEY_LEN],
    /// The ECUs' image key: an image must verify with it before it is offered.
    pub image_key: [u8; PUBLIC_KEY_LEN],
}

/// An update the driver is asked about.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Offer {
    /// The campaign.
    pub campaign: i64,
    /// Its name.
    pub name: String,
    /// The ECU (`cruise`...).
    pub ecu: String,
    /// The version it brings.
    pub version: String,
    /// What the fleet tells the driver.
    pub message: String,
    /// The image's size, bytes.
    pub bytes: u64,
}

impl Offer {
    /// The question as the driver reads it.
    pub fn question(&self) -> String {
        let what = match parse_ecu(&self.ecu) {
            Some(Node::Cruise) => "cruise control".to_string(),
            Some(Node::ABS) => "ABS".to_string(),
            Some(Node::Differential) => "differential".to_string(),
            Some(Node::Transmission) => "transmission".to_string(),
            _ => format!("{} ECU", self.ecu),
        };
        format!("An update for your {what} is ready: install when parked?")
    }
}

/// How a flash the agent asked for ended.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FlashResult {
    /// The ECU took the image and restarted.
    Flashed,
    /// The ECU refused the image (a negative response): its reason.
    RefusedByEcu(String),
    /// The flash did not complete (a timeout, the bus): why.
    Failed(String),
}

/// What the agent asks its gateway to do.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Action {
    /// Publish at QoS 1.
    Publish {
        /// The topic.
        topic: String,
        /// The payload.
        payload: Vec<u8>,
    },
    /// Subscribe (QoS 1) to a topic (the image of a campaign).
    Subscribe(String),
    /// End a subscription.
    Unsubscribe(String),
    /// Ask the driver (the dashboard shows the offer until answered or withdrawn).
    Ask(Offer),
    /// The offer of this campaign is no longer open.
    Withdraw(i64),
    /// Flash `image` into `ecu` over CAN now (the car stands).
    Flash {
        /// The ECU.
        ecu: Node,
        /// The signed image, checked.
        image: Vec<u8>,
    },
    /// Something for the gateway's event log.
    Note(String),
    /// Keep this as the newest instruction number taken, across restarts (give it back
    /// with [`VehicleAgent::set_newest_instruction`]), before anything else is done.
    Remember(u64),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Step {
    /// Subscribed to the image, since then (ms).
    Image { since_ms: i64 },
    /// The driver was asked.
    Consent,
    /// The driver agreed; waiting for the car to stand still.
    Standstill,
    /// The flash runs.
    Flashing,
    /// Flashed at then (ms); waiting for the identification to show the new version.
    Checking { since_ms: i64 },
}

struct Job {
    instruction: Instruction,
    ecu: Node,
    step: Step,
    image: Option<Vec<u8>>,
}

/// The vehicle's agent (see the module docs).
pub struct VehicleAgent {
    config: AgentConfig,
    inventory: Option<Vec<EcuIdentity>>,
    published_inventory: Option<Vec<EcuIdentity>>,
    job: Option<Job>,
    /// The newest instruction that came while another was being installed, or before the
    /// inventory was read.
    waiting: Option<Instruction>,
    reported: VecDeque<CampaignReport>,
    standing: bool,
    actions: VecDeque<Action>,
    /// The newest instruction number taken.
    newest_instruction: u64,
}

impl VehicleAgent {
    /// The agent of one vehicle.
    pub fn new(config: AgentConfig) -> Self {
        Self {
            config,
            inventory: None,
            published_inventory: None,
            job: None,
            waiting: None,
            reported: VecDeque::new(),
            standing: false,
            actions: VecDeque::new(),
            newest_instruction: 0,
        }
    }

    /// The newest instruction number taken before (kept by the gateway across restarts):
    /// an instruction not newer is refused.
    pub fn set_newest_instruction(&mut self, number: u64) {
        self.newest_instruction = self.newest_instruction.max(number);
    }

    /// The newest instruction number taken.
    pub fn newest_instruction(&self) -> u64 {
        self.newest_instruction
    }

    /// The vehicle.
    pub fn vin(&self) -> &Vin {
        &self.config.vin
    }

    /// The topics the vehicle's session subscribes to: its campaign commands.
    pub fn subscriptions(&self) -> Vec<String> {
        vec![topics::command(&self.config.vin)]
    }

    /// The next thing to do, if any.
    pub fn next_action(&mut self) -> Option<Action> {
        self.actions.pop_front()
    }

    /// The offer the driver is being asked about, if any.
    pub fn offer(&self) -> Option<Offer> {
        self.job
            .as_ref()
            .filter(|j| j.step == Step::Consent)
            .map(|j| offer_of(&j.instruction))
    }

    /// The campaign in progress and where it is, in a word (for the dashboard).
    pub fn activity(&self) -> Option<(i64, &'static str)> {
        self.job.as_ref().map(|j| {
            let word = match j.step {
                Step::Image { .. } => "fetching the image",
                Step::Consent => "asking the driver",
                Step::Standstill => "waiting for the car to stand still",
                Step::Flashing => "flashing",
                Step::Checking { .. } => "checking the new version",
            };
            (j.instruction.campaign, word)
        })
    }

    /// The reports sent so far on campaigns (the latest few), newest last.
    pub fn reports(&self) -> impl Iterator<Item = &CampaignReport> {
        self.reported.iter()
    }

    /// The gateway read the ECUs' identification (at start, and after every flash): the
    /// inventory is published when it changed, and a flashed ECU's version is checked.
    pub fn on_inventory(&mut self, ecus: Vec<EcuIdentity>, now_ms: i64) {
        if ecus.is_empty() {
            return;
        }
        if self.published_inventory.as_ref() != Some(&ecus) {
            let report = InventoryReport {
                vin: self.config.vin.to_string(),
                read_at_ms: now_ms,
                ecus: ecus.clone(),
            };
            self.publish(ReportKind::Inventory, &report);
            self.published_inventory = Some(ecus.clone());
        }
        self.inventory = Some(ecus);
        if let Some(job) = self
            .job
            .as_ref()
            .filter(|j| matches!(j.step, Step::Checking { .. }))
        {
            let running = self.running_version(job.ecu);
            let expected = job.instruction.version.clone();
            if running.as_deref() == Some(expected.as_str()) {
                self.finish(VehicleState::Installed, None, now_ms);
            } else {
                let reason = format!(
                    "after the flash the {} ECU runs {}, not {expected} (it went back to its previous image)",
                    ecu_name(job.ecu),
                    running.as_deref().unwrap_or("no answered version")
                );
                self.finish(VehicleState::Failed, Some(reason), now_ms);
            }
        }
        self.start_waiting(now_ms);
    }

    /// A trip ended: its report goes to the fleet.
    pub fn on_trip(&mut self, report: &TripReport) {
        self.publish(ReportKind::Trip, report);
    }

    /// A message from the broker: a campaign instruction, or the image of the campaign
    /// in progress; anything else is noted.
    pub fn on_message(&mut self, topic: &str, payload: &[u8], now_ms: i64) {
        if topic == topics::command(&self.config.vin) {
            return self.on_instruction(payload, now_ms);
        }
        let image_topic = self.job.as_ref().and_then(|j| match j.step {
            Step::Image { .. } => Some(topics::image(&j.instruction.image_sha256)),
            _ => None,
        });
        if image_topic.as_deref() == Some(topic) {
            return self.on_image(payload, now_ms);
        }
        self.note(format!(
            "fleet: a message on {} ({} bytes) that no campaign step waits for",
            cut(topic),
            payload.len()
        ));
    }

    /// The driver answered the offer of `campaign`: install or not. An error when no such
    /// offer is open.
    pub fn consent(&mut self, campaign: i64, install: bool, now_ms: i64) -> Result<(), String> {
        let Some(job) = self
            .job
            .as_mut()
            .filter(|j| j.step == Step::Consent && j.instruction.campaign == campaign)
        else {
            return Err(format!(
                "no update of campaign {campaign} is waiting for an answer"
            ));
        };
        if install {
            job.step = Step::Standstill;
            self.actions.push_back(Action::Withdraw(campaign));
            self.report(VehicleState::Installing, None, now_ms);
            self.maybe_flash();
        } else {
            self.finish(
                VehicleState::Declined,
                Some("the driver declined".into()),
                now_ms,
            );
            self.start_waiting(now_ms);
        }
        Ok(())
    }

    /// Whether the car stands still (the gateway judges it from the bus): a flash waits
    /// for it.
    pub fn set_standing(&mut self, standing: bool) {
        self.standing = standing;
        self.maybe_flash();
    }

    /// The flash asked for ended.
    pub fn flash_done(&mut self, result: FlashResult, now_ms: i64) {
        let Some(job) = self.job.as_mut().filter(|j| j.step == Step::Flashing) else {
            return;
        };
        match result {
            FlashResult::Flashed => {
                job.step = Step::Checking { since_ms: now_ms };
                job.image = None;
                let ecu = job.ecu;
                self.note(format!(
                    "fleet: {} flashed, reading its identification",
                    ecu_name(ecu)
                ));
            }
            FlashResult::RefusedByEcu(reason) => {
                let reason = format!("the {} ECU refused the image: {reason}", ecu_name(job.ecu));
                self.finish(VehicleState::Refused, Some(reason), now_ms);
                self.start_waiting(now_ms);
            }
            FlashResult::Failed(reason) => {
                self.finish(VehicleState::Failed, Some(reason), now_ms);
                self.start_waiting(now_ms);
            }
        }
    }

    /// Time passes: an image that never comes, an identification that never shows the
    /// new version, an offer whose instruction expired.
    pub fn tick(&mut self, now_ms: i64) {
        let Some(job) = &self.job else {
            return;
        };
        match job.step {
            Step::Image { since_ms } if now_ms - since_ms > IMAGE_WAIT_MS => {
                let reason = format!(
                    "the image did not arrive from the broker within {} s",
                    IMAGE_WAIT_MS / 1000
                );
                self.finish(VehicleState::Failed, Some(reason), now_ms);
            }
            Step::Checking { since_ms } if now_ms - since_ms > CHECK_WAIT_MS => {
                let reason = format!(
                    "no identification within {} s after the flash",
                    CHECK_WAIT_MS / 1000
                );
                self.finish(VehicleState::Failed, Some(reason), now_ms);
            }
            Step::Consent | Step::Standstill if now_ms > job.instruction.expires_at_ms => {
                // Nothing to report: the fleet counts the vehicle as not answering.
                let campaign = job.instruction.campaign;
                self.note(format!(
                    "fleet: the offer of campaign {campaign} expired unanswered"
                ));
                self.actions.push_back(Action::Withdraw(campaign));
                self.job = None;
            }
            _ => return,
        }
        self.start_waiting(now_ms);
    }

    fn on_instruction(&mut self, payload: &[u8], now_ms: i64) {
        let instruction = match Instruction::open(
            payload,
            &self.config.fleet_key,
            self.config.vin.as_str(),
            now_ms,
        ) {
            Ok(instruction) => instruction,
            // Not reported: a forgery has no campaign to report to, and an instruction for
            // another vehicle or out of time is the fleet's to resend.
            Err(e) => return self.note(format!("fleet: instruction refused: {e}")),
        };
        let key = (instruction.campaign, instruction.attempt);
        if let Some(done) = self
            .reported
            .iter()
            .rev()
            .find(|r| (r.campaign, r.attempt) == key && r.state.is_final())
            .cloned()
        {
            // A repeated delivery (QoS 1 is at least once): the same answer again.
            return self.publish(ReportKind::Campaign, &done);
        }
        if self
            .job
            .as_ref()
            .is_some_and(|j| (j.instruction.campaign, j.instruction.attempt) == key)
            || self
                .waiting
                .as_ref()
                .is_some_and(|w| (w.campaign, w.attempt) == key)
        {
            return; // A repeated delivery of what runs or waits.
        }
        if instruction.number <= self.newest_instruction {
            return self.note(format!(
                "fleet: instruction {} (campaign {}) refused: not newer than the newest taken, {} (played again)",
                instruction.number, instruction.campaign, self.newest_instruction
            ));
        }
        self.newest_instruction = instruction.number;
        self.actions.push_back(Action::Remember(instruction.number));
        if let Some(job) = &self.job {
            let installing = matches!(job.step, Step::Flashing | Step::Checking { .. });
            if installing || job.instruction.campaign != instruction.campaign {
                self.note(format!(
                    "fleet: campaign {} waits until campaign {} is done",
                    instruction.campaign, job.instruction.campaign
                ));
                self.waiting = Some(instruction);
                return;
            }
            // A newer attempt of the same campaign replaces the one not yet installing.
            let old = self.job.take().map(|j| j.instruction);
            if let Some(old) = old {
                self.actions
                    .push_back(Action::Unsubscribe(topics::image(&old.image_sha256)));
                self.actions.push_back(Action::Withdraw(old.campaign));
            }
        }
        self.waiting = Some(instruction);
        self.start_waiting(now_ms);
    }

    /// Starts the waiting instruction, if nothing else runs and the inventory is known.
    fn start_waiting(&mut self, now_ms: i64) {
        if self.job.is_some() || self.inventory.is_none() {
            return;
        }
        let Some(instruction) = self.waiting.take() else {
            return;
        };
        let refuse = |agent: &mut Self, reason: String| {
            agent.answer(
                &instruction,
                None,
                VehicleState::Refused,
                Some(reason),
                now_ms,
            );
        };
        let Some(ecu) = parse_ecu(&instruction.ecu) else {
            return refuse(
                self,
                format!("no ECU is called \"{}\"", cut(&instruction.ecu)),
            );
        };
        let Some(identity) = self.identity(ecu).cloned() else {
            return refuse(
                self,
                format!("this vehicle has no {} ECU that answers", ecu_name(ecu)),
            );
        };
        if identity.software_version.as_deref() == Some(instruction.version.as_str()) {
            let version = identity.software_version.clone();
            return self.answer(&instruction, version, VehicleState::Installed, None, now_ms);
        }
        self.note(format!(
            "fleet: campaign {} ({}): fetching {} {}",
            instruction.campaign,
            instruction.name,
            ecu_name(ecu),
            instruction.version
        ));
        self.actions
            .push_back(Action::Subscribe(topics::image(&instruction.image_sha256)));
        self.job = Some(Job {
            instruction,
            ecu,
            step: Step::Image { since_ms: now_ms },
            image: None,
        });
    }

    fn on_image(&mut self, image: &[u8], now_ms: i64) {
        let Some(job) = self.job.as_mut() else {
            return;
        };
        self.actions.push_back(Action::Unsubscribe(topics::image(
            &job.instruction.image_sha256,
        )));
        let (ecu, instruction) = (job.ecu, job.instruction.clone());
        let identity = self
            .inventory
            .as_ref()
            .and_then(|inv| inv.iter().find(|e| parse_ecu(&e.ecu) == Some(ecu)));
        match check_image(image, &instruction, ecu, identity, &self.config.image_key) {
            Ok(()) => {
                if let Some(job) = self.job.as_mut() {
                    job.image = Some(image.to_vec());
                    job.step = Step::Consent;
                }
                self.report(VehicleState::Received, None, now_ms);
                self.actions.push_back(Action::Ask(offer_of(&instruction)));
            }
            Err(reason) => {
                self.finish(VehicleState::Refused, Some(reason), now_ms);
                self.start_waiting(now_ms);
            }
        }
    }

    fn maybe_flash(&mut self) {
        if !self.standing {
            return;
        }
        let Some(job) = self.job.as_mut().filter(|j| j.step == Step::Standstill) else {
            return;
        };
        let Some(image) = job.image.take() else {
            return;
        };
        job.step = Step::Flashing;
        let ecu = job.ecu;
        let version = job.instruction.version.clone();
        self.note(format!(
            "fleet: the car stands: flashing {} {version}",
            ecu_name(ecu)
        ));
        self.actions.push_back(Action::Flash { ecu, image });
    }

    fn identity(&self, ecu: Node) -> Option<&EcuIdentity> {
        self.inventory
            .as_ref()?
            .iter()
            .find(|e| parse_ecu(&e.ecu) == Some(ecu))
    }

    fn running_version(&self, ecu: Node) -> Option<String> {
        self.identity(ecu)?.software_version.clone()
    }

    /// Reports on the job in progress, which goes on.
    fn report(&mut self, state: VehicleState, reason: Option<String>, now_ms: i64) {
        let Some(job) = &self.job else {
            return;
        };
        let instruction = job.instruction.clone();
        let version = self.running_version(job.ecu);
        self.answer(&instruction, version, state, reason, now_ms);
    }

    /// Reports the job's end and drops it.
    fn finish(&mut self, state: VehicleState, reason: Option<String>, now_ms: i64) {
        self.report(state, reason, now_ms);
        if let Some(job) = self.job.take() {
            if job.step == Step::Consent {
                self.actions
                    .push_back(Action::Withdraw(job.instruction.campaign));
            }
        }
    }

    fn answer(
        &mut self,
        instruction: &Instruction,
        version_running: Option<String>,
        state: VehicleState,
        reason: Option<String>,
        now_ms: i64,
    ) {
        let report = CampaignReport {
            vin: self.config.vin.to_string(),
            campaign: instruction.campaign,
            attempt: instruction.attempt,
            state,
            reason: reason.clone(),
            ecu: instruction.ecu.clone(),
            version_running,
            at_ms: now_ms,
        };
        self.note(format!(
            "fleet: campaign {} {}{}",
            instruction.campaign,
            state.name(),
            reason.map_or(String::new(), |r| format!(": {r}"))
        ));
        self.publish(ReportKind::Campaign, &report);
        if self.reported.len() >= KEPT_REPORTS {
            self.reported.pop_front();
        }
        self.reported.push_back(report);
    }

    fn publish<T: serde::Serialize>(&mut self, kind: ReportKind, report: &T) {
        match serde_json::to_vec(report) {
            Ok(payload) => self.actions.push_back(Action::Publish {
                topic: topics::report(&self.config.vin, kind),
                payload,
            }),
            Err(e) => self.note(format!(
                "fleet: cannot encode a {} report: {e}",
                kind.name()
            )),
        }
    }

    fn note(&mut self, text: String) {
        self.actions.push_back(Action::Note(text));
    }
}

fn offer_of(instruction: &Instruction) -> Offer {
    Offer {
        campaign: instruction.campaign,
        name: instruction.name.clone(),
        ecu: instruction.ecu.clone(),
        version: instruction.version.clone(),
        message: instruction.message.clone(),
        bytes: instruction.image_bytes,
    }
}

fn cut(text: &str) -> String {
    text.chars().take(80).collect()
}

/// The image against the instruction and the ECU, before anything is offered: what the
/// ECU itself would check (signature, node, hardware, no downgrade), plus that it is the
/// very image the fleet signed the instruction for.
fn check_image(
    image: &[u8],
    instruction: &Instruction,
    ecu: Node,
    identity: Option<&EcuIdentity>,
    image_key: &[u8; PUBLIC_KEY_LEN],
) -> Result<(), String> {
    if image.len() as u64 != instruction.image_bytes {
        return Err(format!(
            "the image has {} bytes, the instruction names {}",
            image.len(),
            instruction.image_bytes
        ));
    }
    if sha256_hex(image) != instruction.image_sha256 {
        return Err("the image's SHA-256 is not the one the instruction names".into());
    }
    // One image, or a release's images for both slots: each must verify, and all say the
    // same of themselves (the tester sends the one for the slot the ECU writes).
    let set = autoplug_image::ImageSet::parse(image)
        .map_err(|e| format!("the image does not verify with the ECUs' key: {e}"))?;
    for (slot_image, _) in set.iter() {
        autoplug_image::verify(slot_image, image_key)
            .map_err(|e| format!("the image does not verify with the ECUs' key: {e}"))?;
    }
    let first = set.first();
    if set.iter().any(|(_, h)| {
        (h.node, h.version, h.hardware_id) != (first.node, first.version, first.hardware_id)
    }) {
        return Err("the release's images differ in ECU, version or hardware".into());
    }
    let header: &ImageHeader = &first;
    let node = ecu.diag_node_number().unwrap_or(0);
    if header.node != node {
        let target = Node::ALL
            .into_iter()
            .find(|n| n.diag_node_number() == Some(header.node))
            .map_or("an unknown ECU", ecu_name);
        return Err(format!(
            "the image is for {target} (node 0x{:02X}), not for {} (node 0x{node:02X})",
            header.node,
            ecu_name(ecu)
        ));
    }
    if header.version.to_string() != instruction.version {
        return Err(format!(
            "the image carries version {}, the instruction names {}",
            header.version, instruction.version
        ));
    }
    if let Some(hardware) = identity.and_then(|i| i.hardware_version.as_deref()) {
        let image_hw = hardware_name(header.hardware_id);
        if image_hw != Some(hardware) {
            return Err(format!(
                "the image is for hardware {}, the ECU is {hardware}",
                image_hw.map_or_else(|| format!("0x{:08X}", header.hardware_id), str::to_string)
            ));
        }
    }
    let running = identity
        .and_then(|i| i.software_version.as_deref())
        .and_then(|v| v.parse::<Version>().ok());
    if let Some(running) = running.filter(|r| header.version < *r) {
        return Err(format!(
            "the image's version {} is older than the {running} the ECU runs (no downgrade)",
            header.version
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests;
