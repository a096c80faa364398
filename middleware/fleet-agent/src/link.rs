//! The gateway's link to the fleet (`autoplug gateway --transmit --fleet mqtt://...`, the
//! dashboard, each car of `autoplug fleet simulate`): it runs the vehicle's campaign agent
//! ([`crate::vehicle`]) against an MQTT connection and the gateway's own tester.
//!
//! The connection opens once the ECUs have answered the vehicle's VIN (its client id and,
//! with the shipped broker configuration, its login), with a persistent session, so the
//! campaign instructions sent while the car was off wait at the broker. The inventory goes
//! out when it changes, every trip when it ends (with the verdicts and trouble codes it
//! ended with). Every report stays in a bounded outbox until the fleet's receipt says it is
//! stored, and is published again while none comes ([`autoplug_fleet::outbox`]): a broker
//! that acknowledged a report and lost it (a restart) costs a delay, not the report.
//!
//! Whether the car stands is judged from the bus: the vehicle speed at 0 km/h for
//! [`STANDING_AFTER_US`]. A flash the driver agreed to waits for it.

use std::collections::VecDeque;
use std::time::Duration;

use crate::vehicle::{Action, AgentConfig, FlashResult, Offer, VehicleAgent};
use autoplug_can::{Node, VehicleSpeedMsg};
use autoplug_fleet::campaign::now_ms;
use autoplug_fleet::mqtt::{Broker, LinkOptions, LinkStatus, MqttLink};
use autoplug_fleet::outbox::{Confirmed, Outbox};
use autoplug_fleet::TripReport;
use autoplug_gateway::CarState;
use autoplug_image::PUBLIC_KEY_LEN;
use autoplug_store::{DtcRecord, EcuIdentity, VerdictRecord};
use autoplug_trips::CompletedTrip;

use autoplug_tester::bus_tester::{BusTester, UserJob};
use autoplug_tester::{FlashConfig, FlashJob, UdsError};

/// The vehicle speed must read 0 km/h this long before the car counts as standing, µs of
/// bus time (a stop, not a car rolling through 0 km/h).
pub const STANDING_AFTER_US: u64 = 2_000_000;
/// Reports kept until the fleet confirms them; the oldest go first beyond it.
pub const MAX_WAITING_REPORTS: usize = 256;
/// Events kept for the dashboard.
const MAX_EVENTS: usize = 20;
/// Broker messages taken per call: a flood cannot hold the pipeline up.
const MESSAGES_PER_POLL: usize = 16;

/// How the gateway reaches the fleet.
#[derive(Clone, Debug)]
pub struct FleetConfig {
    /// The broker (`mqtt://[VIN:password@]host[:port]`).
    pub broker: Broker,
    /// The fleet's public key: campaign instructions must verify with it.
    pub fleet_key: [u8; PUBLIC_KEY_LEN],
    /// The ECUs' image key: images must verify with it before the driver is asked.
    pub image_key: [u8; PUBLIC_KEY_LEN],
    /// The SecurityAccess secret for flashing.
    pub security_secret: Vec<u8>,
    /// How long a report waits for its receipt before it is published again, ms (doubling
    /// each time): [`autoplug_fleet::outbox::RESEND_AFTER_MS`] unless a test is in a hurry.
    pub resend_after_ms: i64,
    /// Where the vehicle keeps what it has seen of the fleet across restarts (the newest
    /// instruction number taken: [`FleetState`]); none: in memory only (a simulated car).
    pub state_file: Option<std::path::PathBuf>,
}

/// What the vehicle keeps of the fleet across restarts: the newest instruction number it
/// has taken, so an instruction played again after the next ignition is refused. A small
/// JSON file, replaced whole (written beside, then renamed) so a power cut leaves the old
/// one or the new one.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct FleetState {
    /// The vehicle it belongs to (a gateway moved to another car starts afresh).
    pub vin: String,
    /// The newest instruction number taken.
    pub newest_instruction: u64,
}

impl FleetState {
    /// Reads the state kept at `path` for `vin`: `Ok(None)` when there is none yet or it is
    /// another vehicle's; an error naming the file when it cannot be read or is damaged.
    pub fn load(path: &std::path::Path, vin: &str) -> Result<Option<FleetState>, String> {
        let text = match std::fs::read(path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => return Err(format!("cannot read {}: {e}", path.display())),
        };
        if text.len() > 4096 {
            return Err(format!(
                "{} is not a fleet state file (too large)",
                path.display()
            ));
        }
        let state: FleetState = serde_json::from_slice(&text)
            .map_err(|e| format!("{} is damaged: {e}", path.display()))?;
        Ok((state.vin == vin).then_some(state))
    }

    /// Writes it to `path` in place of what was there.
    pub fn save(&self, path: &std::path::Path) -> Result<(), String> {
        use std::io::Write;
        let fail = |e: std::io::Error| format!("cannot write {}: {e}", path.display());
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(fail)?;
        }
        let mut next = path.as_os_str().to_owned();
        next.push(".new");
        let next = std::path::PathBuf::from(next);
        let mut file = std::fs::File::create(&next).map_err(fail)?;
        file.write_all(&serde_json::to_vec(self).unwrap_or_default())
            .and_then(|()| file.sync_all())
            .map_err(fail)?;
        std::fs::rename(&next, path).map_err(fail)
    }
}

/// The link (see the module docs).
pub struct FleetLink {
    config: FleetConfig,
    runtime: tokio::runtime::Handle,
    agent: Option<VehicleAgent>,
    link: Option<MqttLink>,
    /// Reports not yet confirmed by the fleet, in order.
    outbox: Outbox,
    /// Trips that ended before the VIN was known (their `vin` is filled in then).
    held_trips: Vec<TripReport>,
    pending_flash: Option<(Node, Vec<u8>)>,
    /// Trips that ended before the VIN was known, beyond what is held.
    dropped_held: u64,
    offer: Option<Offer>,
    events: VecDeque<String>,
    zero_since_us: Option<u64>,
    standing: bool,
    /// Why the link is not open, when it is not.
    pub not_connected: Option<String>,
}

impl FleetLink {
    /// A link that opens once the VIN is read, its connection on `runtime`.
    pub fn new(config: FleetConfig, runtime: tokio::runtime::Handle) -> Self {
        let outbox = Outbox::new(MAX_WAITING_REPORTS, config.resend_after_ms);
        Self {
            config,
            runtime,
            agent: None,
            link: None,
            outbox,
            held_trips: Vec::new(),
            pending_flash: None,
            dropped_held: 0,
            offer: None,
            events: VecDeque::new(),
            zero_since_us: None,
            standing: false,
            not_connected: Some("waiting for the ECUs to answer the VIN".into()),
        }
    }

    /// The update the driver is asked about, if any.
    pub fn offer(&self) -> Option<&Offer> {
        self.offer.as_ref()
    }

    /// The campaign in progress and where it stands, in a word.
    pub fn activity(&self) -> Option<(i64, &'static str)> {
        self.agent.as_ref().and_then(|a| a.activity())
    }

    /// The latest events (instructions, checks, reports), oldest first.
    pub fn events(&self) -> impl Iterator<Item = &String> {
        self.events.iter()
    }

    /// The connection's state, once it is open.
    pub fn status(&self) -> Option<LinkStatus> {
        self.link.as_ref().map(|l| l.status())
    }

    /// The broker, without its password.
    pub fn broker(&self) -> String {
        self.config.broker.to_string()
    }

    /// The vehicle's VIN, once its ECUs answered it.
    pub fn vin(&self) -> Option<String> {
        self.agent.as_ref().map(|a| a.vin().to_string())
    }

    /// Whether the car stands, as judged from the bus.
    pub fn standing(&self) -> bool {
        self.standing
    }

    /// The vehicle's reports on campaigns (the latest few), oldest first.
    pub fn campaign_reports(&self) -> Vec<autoplug_fleet::campaign::CampaignReport> {
        self.agent
            .as_ref()
            .map(|a| a.reports().cloned().collect())
            .unwrap_or_default()
    }

    /// Whether the connection is open (it may still be connecting).
    pub fn online(&self) -> bool {
        self.link.is_some()
    }

    /// Closes the connection (the broker keeps the session: instructions sent meanwhile
    /// wait there) or opens it again. Reports wait in the queue while it is closed.
    pub fn set_online(&mut self, online: bool) {
        match (online, self.link.is_some()) {
            (false, true) => {
                self.flush();
                if let Some(link) = self.link.take() {
                    link.close(Duration::from_secs(2));
                }
                self.not_connected = Some("taken offline".into());
            }
            (true, false) => {
                if let Some(vin) = self.agent.as_ref().map(|a| *a.vin()) {
                    self.connect(vin);
                }
            }
            _ => {}
        }
    }

    /// Reports the fleet has not yet confirmed (sent or not).
    pub fn waiting_reports(&self) -> usize {
        self.outbox.len()
    }

    /// Reports dropped unconfirmed because the outbox was full (and trips that ended
    /// before the VIN was known, beyond what is held).
    pub fn dropped_reports(&self) -> u64 {
        self.outbox.dropped + self.dropped_held
    }

    /// Reports the fleet confirmed stored, and refused.
    pub fn confirmed_reports(&self) -> (u64, u64) {
        (self.outbox.stored, self.outbox.refused)
    }

    /// Publishes of a report that had been published before (no receipt came in time).
    pub fn resent_reports(&self) -> u64 {
        self.outbox.resent
    }

    /// The driver's answer to the offer of `campaign`.
    pub fn consent(&mut self, campaign: i64, install: bool) -> Result<(), String> {
        let agent = self
            .agent
            .as_mut()
            .ok_or("this vehicle is not connected to the fleet")?;
        agent.consent(campaign, install, now_ms())?;
        self.run_actions(None);
        Ok(())
    }

    /// The gateway read the ECUs' identification: the first time with a VIN, the link
    /// opens; every time, the inventory goes to the agent.
    pub fn on_identification(
        &mut self,
        vin: Result<Option<autoplug_vin::Vin>, String>,
        ecus: Vec<EcuIdentity>,
    ) {
        if self.agent.is_none() {
            match vin {
                Ok(Some(vin)) => self.open(vin),
                Ok(None) => {
                    self.not_connected = Some(
                        "no ECU answered the VIN (DID F190): not connected to the fleet".into(),
                    );
                    return;
                }
                Err(e) => {
                    self.not_connected = Some(format!("not connected to the fleet: {e}"));
                    return;
                }
            }
        }
        if let Some(agent) = self.agent.as_mut() {
            agent.on_inventory(ecus, now_ms());
        }
        self.run_actions(None);
    }

    fn open(&mut self, vin: autoplug_vin::Vin) {
        let mut agent = VehicleAgent::new(AgentConfig {
            vin,
            fleet_key: self.config.fleet_key,
            image_key: self.config.image_key,
        });
        if let Some(path) = &self.config.state_file {
            match FleetState::load(path, vin.as_str()) {
                Ok(Some(state)) => agent.set_newest_instruction(state.newest_instruction),
                Ok(None) => {}
                // Refusing every instruction would block every update for good: start the
                // series afresh, and say so.
                Err(e) => self.event(format!("fleet: {e}: starting with no instruction taken")),
            }
        }
        for mut trip in std::mem::take(&mut self.held_trips) {
            trip.vin = vin.to_string();
            agent.on_trip(&trip);
        }
        self.agent = Some(agent);
        self.connect(vin);
    }

    fn connect(&mut self, vin: autoplug_vin::Vin) {
        let mut options = LinkOptions::new(autoplug_fleet::mqtt::vehicle_client_id(
            vin.as_str(),
            self.config.broker.password.as_deref(),
        ));
        options.persistent_session = true;
        options.subscriptions = vec![
            autoplug_fleet::topics::command(&vin),
            autoplug_fleet::topics::receipt(&vin),
        ];
        options.max_backoff = Duration::from_secs(10);
        self.link = Some(MqttLink::connect(
            &self.runtime,
            &self.config.broker,
            options,
        ));
        self.not_connected = None;
        self.event(format!("fleet: {vin} connecting to {}", self.config.broker));
    }

    /// A trip ended, with the verdicts and trouble codes it ended with.
    pub fn on_trip(
        &mut self,
        done: &CompletedTrip,
        verdicts: Vec<VerdictRecord>,
        dtcs: Vec<DtcRecord>,
    ) {
        let ended_at_ms = now_ms();
        let report = TripReport {
            vin: self
                .agent
                .as_ref()
                .map_or_else(String::new, |a| a.vin().to_string()),
            // The gateway's number for the trip: its end on the gateway's clock, µs (a
            // report sent twice is stored once; two trips never end in the same µs).
            trip: unix_us(),
            started_at_ms: ended_at_ms - (done.stats.duration_s * 1000.0) as i64,
            ended_at_ms,
            stats: done.stats.clone(),
            end: done.end,
            verdicts,
            dtcs,
        };
        match self.agent.as_mut() {
            Some(agent) => {
                agent.on_trip(&report);
                self.run_actions(None);
            }
            None if self.held_trips.len() < MAX_WAITING_REPORTS => self.held_trips.push(report),
            None => self.dropped_held += 1,
        }
    }

    /// Between frames: judges standing, takes the broker's messages and the tester's
    /// outcome, and does what the agent asks.
    pub fn poll(&mut self, state: &CarState, tester: Option<&mut BusTester>) {
        self.judge_standing(state);
        let Some(agent) = self.agent.as_mut() else {
            return;
        };
        agent.set_standing(self.standing);
        let receipts = autoplug_fleet::topics::receipt(agent.vin());
        let mut confirmed = Vec::new();
        if let Some(link) = self.link.as_mut() {
            for _ in 0..MESSAGES_PER_POLL {
                let Some(message) = link.try_recv() else {
                    break;
                };
                if message.topic == receipts {
                    confirmed.push(self.outbox.on_receipt(&message.payload));
                } else {
                    agent.on_message(&message.topic, &message.payload, now_ms());
                }
            }
        }
        for outcome in confirmed {
            match outcome {
                Ok(Some(Confirmed::Refused { topic, reason })) => {
                    self.event(format!(
                        "fleet: the fleet refused the report on {topic}: {reason}"
                    ));
                }
                Ok(_) => {}
                Err(e) => self.event(format!("fleet: {e}")),
            }
        }
        let Some(agent) = self.agent.as_mut() else {
            return;
        };
        let mut tester = tester;
        if let Some(tester) = tester.as_deref_mut() {
            while let Some((_, result)) = tester.take_fleet_outcome() {
                let result = match result {
                    Ok(_) => FlashResult::Flashed,
                    Err(e) if matches!(e.uds(), Some(UdsError::Negative { .. })) => {
                        FlashResult::RefusedByEcu(e.to_string())
                    }
                    Err(e) => FlashResult::Failed(e.to_string()),
                };
                agent.flash_done(result, now_ms());
            }
        }
        agent.tick(now_ms());
        self.run_actions(tester);
    }

    fn judge_standing(&mut self, state: &CarState) {
        let now = state.now_us();
        let Some(speed) = state.signal_of(VehicleSpeedMsg::ID, 0) else {
            return;
        };
        // A silent bus (the ECUs asleep, or their normal traffic off during a flash)
        // changes nothing: the car stands where it stood.
        if !speed.is_fresh(now) {
            return;
        }
        if state.get::<VehicleSpeedMsg>().vehicle_speed <= 0.0 {
            let since = *self.zero_since_us.get_or_insert(now);
            self.standing = now.saturating_sub(since) >= STANDING_AFTER_US;
        } else {
            self.zero_since_us = None;
            self.standing = false;
        }
    }

    fn run_actions(&mut self, tester: Option<&mut BusTester>) {
        while let Some(action) = self.agent.as_mut().and_then(|a| a.next_action()) {
            match action {
                Action::Publish { topic, payload } => self.outbox.push(topic, payload),
                Action::Subscribe(topic) => self.request(|l| l.subscribe(&topic)),
                Action::Unsubscribe(topic) => self.request(|l| l.unsubscribe(&topic)),
                Action::Ask(offer) => {
                    self.event(format!("fleet: {}", offer.question()));
                    self.offer = Some(offer);
                }
                Action::Withdraw(campaign) => {
                    if self.offer.as_ref().is_some_and(|o| o.campaign == campaign) {
                        self.offer = None;
                    }
                }
                Action::Flash { ecu, image } => self.pending_flash = Some((ecu, image)),
                Action::Note(text) => self.event(text),
                Action::Remember(number) => self.remember(number),
            }
        }
        self.start_flash(tester);
        self.flush();
    }

    fn start_flash(&mut self, tester: Option<&mut BusTester>) {
        let Some(tester) = tester else {
            return;
        };
        let Some((ecu, image)) = self.pending_flash.take() else {
            return;
        };
        let job = FlashJob::new(FlashConfig::new(
            ecu,
            image.clone(),
            &self.config.security_secret,
        ));
        let job = match job {
            Ok(job) => job,
            Err(e) => {
                if let Some(agent) = self.agent.as_mut() {
                    agent.flash_done(FlashResult::Failed(e.to_string()), now_ms());
                }
                return;
            }
        };
        if tester.queue(UserJob::FleetFlash(Box::new(job))).is_err() {
            // Another flash runs: try again at the next poll.
            self.pending_flash = Some((ecu, image));
        }
    }

    fn request(
        &mut self,
        call: impl FnOnce(&MqttLink) -> Result<(), autoplug_fleet::mqtt::LinkError>,
    ) {
        if let Some(link) = &self.link {
            if let Err(e) = call(link) {
                self.event(format!("fleet: {e}"));
            }
        }
    }

    /// Hands the reports that are due to the connection, in order, while it takes them.
    fn flush(&mut self) {
        let Some(link) = &self.link else {
            return;
        };
        // Not before the receipts can come (see `MqttLink::subscribed`).
        let Some(vin) = self.agent.as_ref().map(|a| a.vin()) else {
            return;
        };
        if !link.subscribed(&autoplug_fleet::topics::receipt(vin)) {
            return;
        }
        self.outbox.send_due(now_ms(), |topic, payload| {
            link.publish(topic, payload.to_vec(), false).is_ok()
        });
    }

    /// Keeps the newest instruction number taken in the state file, if there is one.
    fn remember(&mut self, number: u64) {
        let (Some(path), Some(vin)) = (&self.config.state_file, self.vin()) else {
            return;
        };
        let state = FleetState {
            vin,
            newest_instruction: number,
        };
        if let Err(e) = state.save(path) {
            self.event(format!(
                "fleet: {e} (a replayed instruction would not be recognised after a restart)"
            ));
        }
    }

    fn event(&mut self, text: String) {
        if self.events.len() >= MAX_EVENTS {
            self.events.pop_front();
        }
        self.events.push_back(text);
    }

    /// Sends what waits and disconnects, waiting at most `timeout` for the fleet's receipts
    /// of what was sent (none come while no service runs) and for the broker to take the
    /// rest; what then stands.
    pub fn close(mut self, timeout: Duration) -> Closed {
        let deadline = std::time::Instant::now() + timeout;
        let receipts = self
            .agent
            .as_ref()
            .map(|a| autoplug_fleet::topics::receipt(a.vin()));
        while self.link.is_some() && !self.outbox.is_empty() && std::time::Instant::now() < deadline
        {
            self.flush();
            let Some(link) = self.link.as_mut() else {
                break;
            };
            if let Some(message) = link.recv_timeout(Duration::from_millis(20)) {
                if Some(&message.topic) == receipts.as_ref() {
                    let _ = self.outbox.on_receipt(&message.payload);
                }
            }
        }
        let closed = Closed {
            stored: self.outbox.stored,
            refused: self.outbox.refused,
            unsent: self.outbox.unsent(),
            unconfirmed: self.outbox.len() - self.outbox.unsent(),
            dropped: self.dropped_reports(),
        };
        if let Some(link) = self.link.take() {
            link.close(
                deadline
                    .saturating_duration_since(std::time::Instant::now())
                    .max(Duration::from_millis(200)),
            );
        }
        closed
    }
}

/// Where the reports stood when the link closed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Closed {
    /// Confirmed stored by the fleet.
    pub stored: u64,
    /// Refused by the fleet.
    pub refused: u64,
    /// Never handed to the broker.
    pub unsent: usize,
    /// Handed to the broker, no receipt yet (the broker holds them for the fleet).
    pub unconfirmed: usize,
    /// Dropped unconfirmed, the outbox being full.
    pub dropped: u64,
}

fn unix_us() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_fleet_state_survives_a_restart_and_a_damaged_or_foreign_one_is_named() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("data/fleet-state.json");
        let vin = "JA3AP47H0YF000042";
        assert_eq!(FleetState::load(&path, vin), Ok(None));
        let state = FleetState {
            vin: vin.into(),
            newest_instruction: 7,
        };
        state.save(&path).unwrap();
        assert_eq!(FleetState::load(&path, vin), Ok(Some(state)));
        assert_eq!(FleetState::load(&path, "JA3AP47H2YF000043"), Ok(None));
        std::fs::write(&path, b"{\"vin\": \"JA3AP").unwrap();
        let e = FleetState::load(&path, vin).unwrap_err();
        assert!(e.contains("fleet-state.json is damaged"), "{e}");
    }
}
