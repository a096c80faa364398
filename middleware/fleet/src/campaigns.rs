//! Update campaigns on the fleet's side: created from a signed image and a target query
//! (the exact vehicles it finds, kept with the query as the reason), rolled out in stages
//! as hawkBit's rollouts are (a first share, then the rest), paused by themselves when a
//! stage's failures pass the threshold, a failed vehicle retried within bounds, a silent
//! one reported as not answering.
//!
//! All of a campaign's state is in the database, so any number of stateless fleet
//! services may run [`FleetStore::campaign_tick`]: each tick works in one transaction
//! that holds the campaign's row (PostgreSQL: `FOR UPDATE`; SQLite: the write lock), so
//! two services never send the same instruction twice.

use std::collections::BTreeMap;

use autoplug_image::{ImageHeader, ImageSet, SigningKey};
use serde::{Deserialize, Serialize};

use crate::campaign::{sha256_hex, CampaignReport, Instruction, VehicleState};
use crate::db::{transaction, Db, Dialect, Value};
use crate::store::{int, text, EvidenceQuery, FleetStore, InventoryQuery, StoreError};
use crate::topics;

/// Which vehicles a campaign is for.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Target {
    /// Those carrying what the query describes.
    Inventory(InventoryQuery),
    /// Those with the evidence the query describes.
    Evidence(EvidenceQuery),
    /// These, by VIN.
    Vins(Vec<String>),
}

/// A campaign to create.
#[derive(Clone, Debug)]
pub struct CampaignSpec {
    /// Its name (unique).
    pub name: String,
    /// The ECU it updates.
    pub ecu: String,
    /// The signed image.
    pub image: Vec<u8>,
    /// Its vehicles.
    pub target: Target,
    /// Cumulative shares per stage, percent, increasing, the last 100 (e.g. `[10, 100]`).
    pub stages: Vec<f64>,
    /// Share of a stage's vehicles that may fail before the campaign pauses, 0 to 1.
    pub failure_threshold: f64,
    /// Instructions a vehicle gets at most (the first and the retries).
    pub max_attempts: u32,
    /// How long an instruction may go unanswered before it is sent again, ms.
    pub answer_within_ms: i64,
    /// How long an instruction holds, ms.
    pub valid_for_ms: i64,
    /// What the driver is told.
    pub message: String,
}

/// Defaults for a campaign's rollout.
impl CampaignSpec {
    /// A first stage of 10 %, then the rest; pause at 20 % failures; three attempts;
    /// an hour to answer; instructions valid 30 days.
    pub fn new(name: &str, ecu: &str, image: Vec<u8>, target: Target) -> Self {
        Self {
            name: name.into(),
            ecu: ecu.into(),
            image,
            target,
            stages: vec![10.0, 100.0],
            failure_threshold: 0.2,
            max_attempts: 3,
            answer_within_ms: 3_600_000,
            valid_for_ms: 30 * 86_400_000,
            message: String::new(),
        }
    }
}

/// A campaign that was created.
#[derive(Clone, Debug, PartialEq)]
pub struct Created {
    /// Its number.
    pub id: i64,
    /// Its vehicles, in VIN order, with their stage.
    pub vehicles: Vec<(String, u32)>,
}

/// A campaign's state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum CampaignState {
    /// Instructions go out.
    Running,
    /// Stopped by its failure threshold (or by hand): nothing new goes out.
    Paused,
    /// Every vehicle has a final state.
    Finished,
    /// Stopped for good.
    Cancelled,
}

impl CampaignState {
    fn name(self) -> &'static str {
        match self {
            CampaignState::Running => "running",
            CampaignState::Paused => "paused",
            CampaignState::Finished => "finished",
            CampaignState::Cancelled => "cancelled",
        }
    }

    fn parse(name: &str) -> Self {
        match name {
            "paused" => CampaignState::Paused,
            "finished" => CampaignState::Finished,
            "cancelled" => CampaignState::Cancelled,
            _ => CampaignState::Running,
        }
    }
}

/// A campaign as the command line and the fleet page show it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CampaignInfo {
    /// Its number.
    pub id: i64,
    /// Its name.
    pub name: String,
    /// The ECU.
    pub ecu: String,
    /// The image's version.
    pub version: String,
    /// The image's SHA-256.
    pub image_sha256: String,
    /// Where it stands.
    pub state: CampaignState,
    /// The stage under way (0 = the first).
    pub stage: u32,
    /// Cumulative shares per stage, percent.
    pub stages: Vec<f64>,
    /// The failure threshold, 0 to 1.
    pub failure_threshold: f64,
    /// Why it paused.
    pub paused_reason: Option<String>,
    /// Its vehicles.
    pub vehicles: i64,
    /// How many are in each state.
    pub counts: BTreeMap<String, i64>,
    /// When it was created, ms since the Unix epoch.
    pub created_at_ms: i64,
}

/// One vehicle of a campaign.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct CampaignVehicle {
    /// The VIN.
    pub vin: String,
    /// Its stage.
    pub stage: u32,
    /// Where it stands.
    pub state: VehicleState,
    /// Instructions sent.
    pub attempts: u32,
    /// The last report's reason.
    pub reason: Option<String>,
    /// The version the ECU runs, as last reported.
    pub version_running: Option<String>,
    /// Its last change, ms since the Unix epoch.
    pub updated_at_ms: i64,
}

/// An instruction to publish: to `topic`, the signed `payload`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Dispatch {
    /// The vehicle.
    pub vin: String,
    /// Its command topic.
    pub topic: String,
    /// The signed envelope.
    pub payload: Vec<u8>,
}

fn invalid(text: impl Into<String>) -> StoreError {
    StoreError::Invalid(text.into())
}

/// Checks a spec; the image's header when it is fine.
fn check_spec(spec: &CampaignSpec) -> Result<ImageHeader, StoreError> {
    if spec.name.trim().is_empty()
        || spec.name.len() > 100
        || spec.name.chars().any(char::is_control)
    {
        return Err(invalid(
            "a campaign needs a name of 1 to 100 printable characters",
        ));
    }
    // One image, or a release's images for both slots one after the other (the vehicle's
    // tester sends the one for the slot its ECU writes).
    let set = ImageSet::parse(&spec.image).map_err(|e| {
        invalid(format!(
            "the campaign's image is not an AutoPlug image or release: {e}"
        ))
    })?;
    let header = set.first();
    let node = autoplug_can::parse_ecu(&spec.ecu).ok_or_else(|| {
        invalid(format!(
            "'{}' is not an ECU ({})",
            spec.ecu,
            autoplug_can::ECU_NAME_LIST
        ))
    })?;
    for (_, image) in set.iter() {
        if node.diag_node_number() != Some(image.node) {
            return Err(invalid(format!(
                "the image is for node 0x{:02X}, not for {} (node 0x{:02X})",
                image.node,
                spec.ecu,
                node.diag_node_number().unwrap_or(0)
            )));
        }
        if (image.version, image.variant) != (header.version, header.variant) {
            return Err(invalid(format!(
                "the release's images differ: version {} ({}) and {} ({})",
                header.version, header.variant, image.version, image.variant
            )));
        }
    }
    let stages = &spec.stages;
    if stages.is_empty()
        || stages.len() > 10
        || stages
            .iter()
            .any(|s| !(s.is_finite() && *s > 0.0 && *s <= 100.0))
        || stages.windows(2).any(|w| w[0] >= w[1])
        || stages.last() != Some(&100.0)
    {
        return Err(invalid(
            "stages are increasing cumulative percentages ending at 100 (e.g. 10,100), at most 10",
        ));
    }
    if !(0.0..=1.0).contains(&spec.failure_threshold) {
        return Err(invalid("the failure threshold is a share from 0 to 1"));
    }
    if !(1..=10).contains(&spec.max_attempts) {
        return Err(invalid("a vehicle gets 1 to 10 attempts"));
    }
    if spec.answer_within_ms <= 0 || spec.valid_for_ms <= 0 {
        return Err(invalid("the answer time and the validity must be positive"));
    }
    if spec.message.len() > 500 || spec.message.chars().any(char::is_control) {
        return Err(invalid(
            "the driver's message is at most 500 printable characters",
        ));
    }
    Ok(header)
}

/// Each vehicle's stage: the first `ceil(n * share)` vehicles (in VIN order) in stage 0,
/// and so on.
fn stage_of(stages: &[f64], index: usize, n: usize) -> u32 {
    stages
        .iter()
        .position(|share| index < (n as f64 * share / 100.0).ceil() as usize)
        .unwrap_or(stages.len() - 1) as u32
}

const CAMPAIGN_COLUMNS: &str = "id, name, ecu, image_version, image_sha256, state, stage, stages,
    failure_threshold, paused_reason, created_at_ms";

impl FleetStore {
    /// Creates a campaign: checks the spec, finds its vehicles (exactly those the target
    /// names, each once), assigns their stages. Nothing is sent until
    /// [`Self::campaign_tick`].
    pub fn create_campaign(
        &mut self,
        spec: &CampaignSpec,
        now_ms: i64,
    ) -> Result<Created, StoreError> {
        let header = check_spec(spec)?;
        let mut vins: Vec<String> = match &spec.target {
            Target::Inventory(query) => self
                .recall_by_inventory(query)?
                .into_iter()
                .map(|hit| hit.vin)
                .collect(),
            Target::Evidence(query) => self
                .recall_by_evidence(query)?
                .into_iter()
                .map(|hit| hit.vin)
                .collect(),
            Target::Vins(vins) => {
                for vin in vins {
                    autoplug_vin::Vin::parse(vin)
                        .map_err(|e| invalid(format!("VIN \"{vin}\": {e}")))?;
                }
                vins.clone()
            }
        };
        vins.sort();
        vins.dedup();
        if vins.is_empty() {
            return Err(invalid("no vehicle matches the campaign's target"));
        }
        let target = serde_json::to_string(&spec.target).map_err(|e| invalid(e.to_string()))?;
        let stages = serde_json::to_string(&spec.stages).map_err(|e| invalid(e.to_string()))?;
        let n = vins.len();
        let vehicles: Vec<(String, u32)> = vins
            .into_iter()
            .enumerate()
            .map(|(i, vin)| (vin, stage_of(&spec.stages, i, n)))
            .collect();
        let id = transaction(self.db(), |db| -> Result<i64, StoreError> {
            let known = db.query(
                "SELECT count(*) FROM campaigns WHERE name = $1",
                &[Value::from(spec.name.as_str())],
            )?;
            if known.first().is_some_and(|r| int(r, 0) > 0) {
                return Err(invalid(format!(
                    "a campaign named '{}' exists already",
                    spec.name
                )));
            }
            let rows = db.query(
                "INSERT INTO campaigns (name, ecu, image_sha256, image_version, image_bytes,
                     target, stages, failure_threshold, max_attempts, answer_within_ms,
                     valid_for_ms, message, state, stage, created_at_ms, updated_at_ms)
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, 'running', 0, $13, $13)
                 RETURNING id",
                &[
                    Value::from(spec.name.as_str()),
                    Value::from(spec.ecu.as_str()),
                    Value::from(sha256_hex(&spec.image)),
                    Value::from(header.version.to_string()),
                    Value::Int(spec.image.len() as i64),
                    Value::from(target),
                    Value::from(stages),
                    Value::Float(spec.failure_threshold),
                    Value::Int(spec.max_attempts.into()),
                    Value::Int(spec.answer_within_ms),
                    Value::Int(spec.valid_for_ms),
                    Value::from(spec.message.as_str()),
                    Value::Int(now_ms),
                ],
            )?;
            let id = rows
                .first()
                .map(|r| int(r, 0))
                .ok_or_else(|| invalid("no id"))?;
            for (vin, stage) in &vehicles {
                db.execute(
                    "INSERT INTO campaign_vehicles (campaign, vin, stage, state, attempts, updated_at_ms)
                     VALUES ($1, $2, $3, 'waiting', 0, $4)",
                    &[Value::Int(id), Value::from(vin.as_str()), Value::Int((*stage).into()), Value::Int(now_ms)],
                )?;
            }
            Ok(id)
        })?;
        Ok(Created { id, vehicles })
    }

    /// Moves every running campaign on at `now_ms`: unanswered instructions past their
    /// time are sent again (or the vehicle marked as not answering after its last
    /// attempt), failed vehicles retried within their attempts, the stage's failures
    /// checked against the threshold (pausing the campaign), the next stage begun when
    /// this one is done. Returns the instructions to publish, signed with `key`.
    pub fn campaign_tick(
        &mut self,
        key: &SigningKey,
        now_ms: i64,
    ) -> Result<Vec<Dispatch>, StoreError> {
        let running = self.db().query(
            "SELECT id FROM campaigns WHERE state = 'running' ORDER BY id",
            &[],
        )?;
        let mut out = Vec::new();
        for row in running {
            let id = int(&row, 0);
            let dialect = self.db().dialect();
            let dispatches = transaction(self.db(), |db| tick_one(db, dialect, id, key, now_ms))?;
            out.extend(dispatches);
        }
        Ok(out)
    }

    /// Stores a vehicle's report on a campaign. A report on an earlier attempt than the
    /// last sent is kept in the audit trail only; an installed vehicle stays installed.
    pub fn record_campaign_report(&mut self, report: &CampaignReport) -> Result<(), StoreError> {
        autoplug_vin::Vin::parse(&report.vin).map_err(|e| invalid(format!("VIN: {e}")))?;
        crate::report::check_ecu_name("a campaign report", &report.ecu)
            .map_err(|e| invalid(e.0))?;
        for (what, value) in [
            ("reason", &report.reason),
            ("version", &report.version_running),
        ] {
            if let Some(v) = value {
                if v.chars().count() > 2000 || v.chars().any(char::is_control) {
                    return Err(invalid(format!(
                        "a campaign report's {what} is too long or holds control characters"
                    )));
                }
            }
        }
        if matches!(
            report.state,
            VehicleState::Waiting | VehicleState::Sent | VehicleState::NoAnswer
        ) {
            return Err(invalid(format!(
                "a vehicle does not report '{}'",
                report.state.name()
            )));
        }
        transaction(self.db(), |db| -> Result<(), StoreError> {
            let rows = db.query(
                "SELECT v.state, v.attempts, c.state FROM campaign_vehicles v
                 JOIN campaigns c ON c.id = v.campaign
                 WHERE v.campaign = $1 AND v.vin = $2",
                &[
                    Value::Int(report.campaign),
                    Value::from(report.vin.as_str()),
                ],
            )?;
            let Some(row) = rows.first() else {
                return Err(invalid(format!(
                    "{} is not a vehicle of campaign {}",
                    report.vin, report.campaign
                )));
            };
            // A campaign is finished once every vehicle has a final state (or cancelled): a
            // report after that is a replay (a captured instruction offered again) or a stray, and
            // would rewrite what the campaign ended with.
            let campaign_state = CampaignState::parse(&text(row, 2).unwrap_or_default());
            if matches!(
                campaign_state,
                CampaignState::Finished | CampaignState::Cancelled
            ) {
                return Err(invalid(format!(
                    "{}: a '{}' report for campaign {}, which is {}",
                    report.vin,
                    report.state.name(),
                    report.campaign,
                    campaign_state.name()
                )));
            }
            let state = text(row, 0)
                .and_then(|s| VehicleState::parse(&s))
                .unwrap_or(VehicleState::Waiting);
            let attempts = int(row, 1);
            // The vehicle sends a report again until its receipt comes: the same report
            // twice is one event, and an older one after a newer is kept in the audit
            // trail only. Compared with the vehicle's own reports only: the fleet's events
            // ('sent'...) are on the fleet's clock.
            let seen = db.query(
                "SELECT at_ms, state FROM campaign_events
                 WHERE campaign = $1 AND vin = $2 AND attempt = $3 AND at_ms >= $4
                   AND state NOT IN ('waiting', 'sent', 'no_answer')",
                &[
                    Value::Int(report.campaign),
                    Value::from(report.vin.as_str()),
                    Value::Int(report.attempt.into()),
                    Value::Int(report.at_ms),
                ],
            )?;
            if seen.iter().any(|r| {
                int(r, 0) == report.at_ms && text(r, 1).as_deref() == Some(report.state.name())
            }) {
                return Ok(());
            }
            let stale = seen.iter().any(|r| int(r, 0) > report.at_ms);
            db.execute(
                "INSERT INTO campaign_events (campaign, vin, at_ms, attempt, state, reason)
                 VALUES ($1, $2, $3, $4, $5, $6)",
                &[
                    Value::Int(report.campaign),
                    Value::from(report.vin.as_str()),
                    Value::Int(report.at_ms),
                    Value::Int(report.attempt.into()),
                    Value::from(report.state.name()),
                    Value::from(report.reason.clone()),
                ],
            )?;
            if i64::from(report.attempt) < attempts || state == VehicleState::Installed || stale {
                return Ok(());
            }
            db.execute(
                "UPDATE campaign_vehicles SET state = $3, reason = $4,
                     version_running = COALESCE($5, version_running), updated_at_ms = $6
                 WHERE campaign = $1 AND vin = $2",
                &[
                    Value::Int(report.campaign),
                    Value::from(report.vin.as_str()),
                    Value::from(report.state.name()),
                    Value::from(report.reason.clone()),
                    Value::from(report.version_running.clone()),
                    Value::Int(crate::store::now_ms()),
                ],
            )?;
            Ok(())
        })
    }

    /// Every campaign, newest first.
    pub fn campaigns(&mut self) -> Result<Vec<CampaignInfo>, StoreError> {
        let rows = self.db().query(
            &format!("SELECT {CAMPAIGN_COLUMNS} FROM campaigns ORDER BY id DESC"),
            &[],
        )?;
        rows.iter().map(|r| self.info_of(r)).collect()
    }

    /// One campaign by number, if there is one.
    pub fn campaign_by_id(&mut self, id: i64) -> Result<Option<CampaignInfo>, StoreError> {
        let rows = self.db().query(
            &format!("SELECT {CAMPAIGN_COLUMNS} FROM campaigns WHERE id = $1"),
            &[Value::Int(id)],
        )?;
        rows.first().map(|r| self.info_of(r)).transpose()
    }

    /// One campaign, by number or name.
    pub fn campaign(&mut self, id_or_name: &str) -> Result<CampaignInfo, StoreError> {
        let rows = match id_or_name.parse::<i64>() {
            Ok(id) => self.db().query(
                &format!("SELECT {CAMPAIGN_COLUMNS} FROM campaigns WHERE id = $1"),
                &[Value::Int(id)],
            )?,
            Err(_) => self.db().query(
                &format!("SELECT {CAMPAIGN_COLUMNS} FROM campaigns WHERE name = $1"),
                &[Value::from(id_or_name)],
            )?,
        };
        let row = rows
            .first()
            .ok_or_else(|| invalid(format!("no campaign '{id_or_name}'")))?;
        self.info_of(row)
    }

    fn info_of(&mut self, r: &crate::db::Row) -> Result<CampaignInfo, StoreError> {
        let id = int(r, 0);
        let counts_rows = self.db().query(
            "SELECT state, count(*) FROM campaign_vehicles WHERE campaign = $1 GROUP BY state",
            &[Value::Int(id)],
        )?;
        let counts: BTreeMap<String, i64> = counts_rows
            .iter()
            .map(|c| (text(c, 0).unwrap_or_default(), int(c, 1)))
            .collect();
        Ok(CampaignInfo {
            id,
            name: text(r, 1).unwrap_or_default(),
            ecu: text(r, 2).unwrap_or_default(),
            version: text(r, 3).unwrap_or_default(),
            image_sha256: text(r, 4).unwrap_or_default(),
            state: CampaignState::parse(&text(r, 5).unwrap_or_default()),
            stage: int(r, 6) as u32,
            stages: serde_json::from_str(&text(r, 7).unwrap_or_default()).unwrap_or_default(),
            failure_threshold: crate::store::float(r, 8).unwrap_or(0.0),
            paused_reason: text(r, 9),
            vehicles: counts.values().sum(),
            counts,
            created_at_ms: int(r, 10),
        })
    }

    /// A campaign's vehicles, in VIN order.
    pub fn campaign_vehicles(&mut self, id: i64) -> Result<Vec<CampaignVehicle>, StoreError> {
        let rows = self.db().query(
            "SELECT vin, stage, state, attempts, reason, version_running, updated_at_ms
             FROM campaign_vehicles WHERE campaign = $1 ORDER BY vin",
            &[Value::Int(id)],
        )?;
        Ok(rows
            .iter()
            .map(|r| CampaignVehicle {
                vin: text(r, 0).unwrap_or_default(),
                stage: int(r, 1) as u32,
                state: text(r, 2)
                    .and_then(|s| VehicleState::parse(&s))
                    .unwrap_or(VehicleState::Waiting),
                attempts: int(r, 3) as u32,
                reason: text(r, 4),
                version_running: text(r, 5),
                updated_at_ms: int(r, 6),
            })
            .collect())
    }

    /// Resumes a paused campaign (after its failures were looked into).
    pub fn resume_campaign(&mut self, id: i64) -> Result<(), StoreError> {
        self.set_campaign_state(id, CampaignState::Paused, CampaignState::Running)
    }

    /// Pauses a running campaign by hand.
    pub fn pause_campaign(&mut self, id: i64) -> Result<(), StoreError> {
        self.set_campaign_state(id, CampaignState::Running, CampaignState::Paused)
    }

    fn set_campaign_state(
        &mut self,
        id: i64,
        from: CampaignState,
        to: CampaignState,
    ) -> Result<(), StoreError> {
        let n = self.db().execute(
            "UPDATE campaigns SET state = $3, paused_reason = NULL, updated_at_ms = $4
             WHERE id = $1 AND state = $2",
            &[
                Value::Int(id),
                Value::from(from.name()),
                Value::from(to.name()),
                Value::Int(crate::store::now_ms()),
            ],
        )?;
        if n == 0 {
            return Err(invalid(format!("campaign {id} is not {}", from.name())));
        }
        Ok(())
    }
}

/// One campaign's tick, inside its transaction.
fn tick_one(
    db: &mut dyn Db,
    dialect: Dialect,
    id: i64,
    key: &SigningKey,
    now_ms: i64,
) -> Result<Vec<Dispatch>, StoreError> {
    let lock = match dialect {
        Dialect::Postgres => " FOR UPDATE",
        Dialect::Sqlite => "",
    };
    let rows = db.query(
        &format!(
            "SELECT state, stage, stages, failure_threshold, max_attempts, answer_within_ms,
                    name, ecu, image_sha256, image_bytes, image_version, message, valid_for_ms
             FROM campaigns WHERE id = $1{lock}"
        ),
        &[Value::Int(id)],
    )?;
    let Some(c) = rows.first() else {
        return Ok(Vec::new());
    };
    if text(c, 0).as_deref() != Some("running") {
        return Ok(Vec::new()); // Another service paused or finished it meanwhile.
    }
    let mut stage = int(c, 1);
    let stages: Vec<f64> =
        serde_json::from_str(&text(c, 2).unwrap_or_default()).unwrap_or_default();
    let threshold = crate::store::float(c, 3).unwrap_or(0.0);
    let max_attempts = int(c, 4);
    let answer_within = int(c, 5);
    let valid_for_ms = int(c, 12);
    let event = |db: &mut dyn Db, vin: &str, attempt: i64, state: &str, reason: Option<String>| {
        db.execute(
            "INSERT INTO campaign_events (campaign, vin, at_ms, attempt, state, reason)
             VALUES ($1, $2, $3, $4, $5, $6)",
            &[
                Value::Int(id),
                Value::from(vin),
                Value::Int(now_ms),
                Value::Int(attempt),
                Value::from(state),
                Value::from(reason),
            ],
        )
    };

    // Unanswered instructions: again, or no answer after the last attempt.
    let silent = db.query(
        "SELECT vin, attempts FROM campaign_vehicles
         WHERE campaign = $1 AND state = 'sent' AND sent_at_ms <= $2",
        &[Value::Int(id), Value::Int(now_ms - answer_within)],
    )?;
    for r in &silent {
        let (vin, attempts) = (text(r, 0).unwrap_or_default(), int(r, 1));
        let next = if attempts < max_attempts {
            "waiting"
        } else {
            "no_answer"
        };
        db.execute(
            "UPDATE campaign_vehicles SET state = $3, updated_at_ms = $4 WHERE campaign = $1 AND vin = $2",
            &[Value::Int(id), Value::from(vin.as_str()), Value::from(next), Value::Int(now_ms)],
        )?;
        if next == "no_answer" {
            event(
                db,
                &vin,
                attempts,
                next,
                Some(format!("no answer to {attempts} instruction(s)")),
            )?;
        }
    }
    // Failed flashes: again while attempts remain.
    db.execute(
        "UPDATE campaign_vehicles SET state = 'waiting', updated_at_ms = $3
         WHERE campaign = $1 AND state = 'failed' AND attempts < $2",
        &[Value::Int(id), Value::Int(max_attempts), Value::Int(now_ms)],
    )?;

    let mut out = Vec::new();
    loop {
        // The stage's failures: refusals, and failures with no attempt left.
        let counts = db.query(
            "SELECT count(*),
                    sum(CASE WHEN state = 'refused' OR (state = 'failed' AND attempts >= $3) THEN 1 ELSE 0 END),
                    sum(CASE WHEN state IN ('installed', 'declined', 'refused', 'no_answer')
                              OR (state = 'failed' AND attempts >= $3) THEN 1 ELSE 0 END)
             FROM campaign_vehicles WHERE campaign = $1 AND stage <= $2",
            &[Value::Int(id), Value::Int(stage), Value::Int(max_attempts)],
        )?;
        let (size, failed, done) = counts
            .first()
            .map_or((0, 0, 0), |r| (int(r, 0), int(r, 1), int(r, 2)));
        if size > 0 && failed as f64 > threshold * size as f64 {
            let reason = format!(
                "stage {}: {failed} of {size} vehicles failed ({:.0} % > {:.0} %)",
                stage + 1,
                100.0 * failed as f64 / size as f64,
                100.0 * threshold
            );
            db.execute(
                "UPDATE campaigns SET state = 'paused', paused_reason = $2, updated_at_ms = $3 WHERE id = $1",
                &[Value::Int(id), Value::from(reason), Value::Int(now_ms)],
            )?;
            return Ok(out);
        }
        // This stage's waiting vehicles: their instruction.
        let waiting = db.query(
            "SELECT vin, attempts FROM campaign_vehicles
             WHERE campaign = $1 AND stage <= $2 AND state = 'waiting' ORDER BY vin",
            &[Value::Int(id), Value::Int(stage)],
        )?;
        for r in &waiting {
            let (vin, attempts) = (text(r, 0).unwrap_or_default(), int(r, 1) + 1);
            // The vehicle's next number, in the campaign row's transaction: two services
            // never issue one number twice.
            let number = next_instruction_number(db, &vin)?;
            let instruction = Instruction {
                number,
                campaign: id,
                name: text(c, 6).unwrap_or_default(),
                vin: vin.clone(),
                ecu: text(c, 7).unwrap_or_default(),
                image_sha256: text(c, 8).unwrap_or_default(),
                image_bytes: int(c, 9) as u64,
                version: text(c, 10).unwrap_or_default(),
                attempt: attempts as u32,
                issued_at_ms: now_ms,
                expires_at_ms: now_ms + valid_for_ms,
                message: text(c, 11).unwrap_or_default(),
            };
            db.execute(
                "UPDATE campaign_vehicles SET state = 'sent', attempts = $3, sent_at_ms = $4, updated_at_ms = $4
                 WHERE campaign = $1 AND vin = $2",
                &[Value::Int(id), Value::from(vin.as_str()), Value::Int(attempts), Value::Int(now_ms)],
            )?;
            event(db, &vin, attempts, "sent", None)?;
            let topic = autoplug_vin::Vin::parse(&vin)
                .map(|v| topics::command(&v))
                .map_err(|e| invalid(format!("VIN {vin}: {e}")))?;
            out.push(Dispatch {
                vin,
                topic,
                payload: instruction.sign(key),
            });
        }
        if done < size || !waiting.is_empty() {
            return Ok(out);
        }
        // The stage is done: the next one, or the end.
        if (stage + 1) as usize >= stages.len() {
            db.execute(
                "UPDATE campaigns SET state = 'finished', updated_at_ms = $2 WHERE id = $1",
                &[Value::Int(id), Value::Int(now_ms)],
            )?;
            return Ok(out);
        }
        stage += 1;
        db.execute(
            "UPDATE campaigns SET stage = $2, updated_at_ms = $3 WHERE id = $1",
            &[Value::Int(id), Value::Int(stage), Value::Int(now_ms)],
        )?;
    }
}

/// The next number of `vin`'s instruction series (1 for its first), taken for good.
fn next_instruction_number(db: &mut dyn Db, vin: &str) -> Result<u64, StoreError> {
    let rows = db.query(
        "INSERT INTO instruction_numbers (vin, issued) VALUES ($1, 1)
         ON CONFLICT (vin) DO UPDATE SET issued = instruction_numbers.issued + 1
         RETURNING issued",
        &[Value::from(vin)],
    )?;
    rows.first()
        .map(|r| int(r, 0) as u64)
        .ok_or_else(|| invalid(format!("no instruction number for {vin}")))
}

impl FleetStore {
    /// Takes the next number of `vin`'s instruction series, as signing an instruction for
    /// it does (an instruction made outside the campaigns, e.g. a test's).
    pub fn next_instruction_number(&mut self, vin: &str) -> Result<u64, StoreError> {
        next_instruction_number(self.db(), vin)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stages_take_the_first_share_then_the_rest() {
        let stages = [10.0, 100.0];
        let of: Vec<u32> = (0..20).map(|i| stage_of(&stages, i, 20)).collect();
        assert_eq!(of.iter().filter(|s| **s == 0).count(), 2);
        assert_eq!(of.iter().filter(|s| **s == 1).count(), 18);
        // A single vehicle is the first stage.
        assert_eq!(stage_of(&stages, 0, 1), 0);
        let three = [25.0, 50.0, 100.0];
        let of: Vec<u32> = (0..4).map(|i| stage_of(&three, i, 4)).collect();
        assert_eq!(of, vec![0, 1, 2, 2]);
    }
}
