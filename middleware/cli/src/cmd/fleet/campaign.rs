//! `autoplug fleet campaign …`: update campaigns created (their image published), shown,
//! paused and resumed.

use std::io::Write;
use std::time::Duration;

use autoplug_fleet::campaigns::{CampaignInfo, CampaignSpec, Target};
use autoplug_fleet::mqtt::{Broker, LinkOptions, MqttLink};
use autoplug_fleet::{topics, InventoryQuery};

use super::{io, json, mqtt_runtime, open};
use crate::fleet_cli::{CreateArgs, DbArgs};

/// Creates a campaign for the vehicles its target finds, once its image is on the broker.
pub(crate) fn create(args: CreateArgs, out: &mut dyn Write) -> Result<(), String> {
    let CreateArgs {
        db,
        broker,
        name,
        for_ecu,
        image,
        inventory,
        evidence,
        vins,
        stages,
        failure_threshold,
        max_attempts,
        answer_within,
        valid_days,
        message,
    } = args;
    let bytes = std::fs::read(&image)
        .map_err(|e| format!("cannot read the image '{}': {e}", image.display()))?;
    let by_inventory = inventory.query() != InventoryQuery::default();
    let target = match (by_inventory, evidence.query(), vins.is_empty()) {
        (true, None, true) => Target::Inventory(inventory.query()),
        (false, Some(query), true) => Target::Evidence(query),
        (false, None, false) => Target::Vins(vins),
        (false, None, true) => {
            return Err("name the vehicles: inventory filters (--ecu, --part-number, --software-from...), evidence (--faulty, --dtc) or --vins".into())
        }
        _ => return Err("one target at a time: inventory filters, evidence or --vins".into()),
    };
    if !(answer_within.is_finite()
        && answer_within > 0.0
        && valid_days.is_finite()
        && valid_days > 0.0)
    {
        return Err("--answer-within and --valid-days must be positive".into());
    }
    let mut spec = CampaignSpec::new(&name, &for_ecu, bytes, target);
    spec.stages = stages;
    spec.failure_threshold = failure_threshold;
    spec.max_attempts = max_attempts;
    spec.answer_within_ms = (answer_within * 1000.0) as i64;
    spec.valid_for_ms = (valid_days * 86_400_000.0) as i64;
    spec.message = message;
    // The image first: an instruction must never name an image vehicles cannot get.
    let sha = autoplug_fleet::campaign::sha256_hex(&spec.image);
    publish_image(&broker.broker()?, &sha, &spec.image)?;
    let mut store = open(&db)?;
    let created = store
        .create_campaign(&spec, autoplug_fleet::campaign::now_ms())
        .map_err(|e| e.to_string())?;
    let stages = spec.stages.len();
    writeln!(
        out,
        "campaign {} '{}': {} vehicle(s) in {stages} stage(s); image {sha} published",
        created.id,
        name,
        created.vehicles.len()
    )
    .map_err(io)?;
    Ok(())
}

/// The campaigns briefly, or one campaign with its vehicles; as a table or JSON.
pub(crate) fn status(
    campaign: Option<&str>,
    db: &DbArgs,
    as_json: bool,
    out: &mut dyn Write,
) -> Result<(), String> {
    let mut store = open(db)?;
    match campaign {
        None => {
            let all = store.campaigns().map_err(|e| e.to_string())?;
            if as_json {
                writeln!(out, "{}", json(&all)?).map_err(io)?;
            } else if all.is_empty() {
                writeln!(out, "no campaigns").map_err(io)?;
            } else {
                for c in &all {
                    campaign_line(c, out).map_err(io)?;
                }
            }
        }
        Some(which) => {
            let info = store.campaign(which).map_err(|e| e.to_string())?;
            let vehicles = store
                .campaign_vehicles(info.id)
                .map_err(|e| e.to_string())?;
            if as_json {
                let value = serde_json::json!({ "campaign": info, "vehicles": vehicles });
                writeln!(out, "{}", json(&value)?).map_err(io)?;
                return Ok(());
            }
            campaign_line(&info, out).map_err(io)?;
            writeln!(
                out,
                "{:<17} {:>5} {:<11} {:>8} {:<9} reason",
                "VIN", "stage", "state", "attempts", "running"
            )
            .map_err(io)?;
            for v in &vehicles {
                writeln!(
                    out,
                    "{:<17} {:>5} {:<11} {:>8} {:<9} {}",
                    v.vin,
                    v.stage + 1,
                    v.state.name(),
                    v.attempts,
                    v.version_running.as_deref().unwrap_or("-"),
                    v.reason.as_deref().unwrap_or("")
                )
                .map_err(io)?;
            }
        }
    }
    Ok(())
}

/// Pauses a running campaign.
pub(crate) fn pause(campaign: i64, db: &DbArgs, out: &mut dyn Write) -> Result<(), String> {
    open(db)?
        .pause_campaign(campaign)
        .map_err(|e| e.to_string())?;
    writeln!(out, "campaign {campaign} paused").map_err(io)?;
    Ok(())
}

/// Resumes a paused campaign.
pub(crate) fn resume(campaign: i64, db: &DbArgs, out: &mut dyn Write) -> Result<(), String> {
    open(db)?
        .resume_campaign(campaign)
        .map_err(|e| e.to_string())?;
    writeln!(out, "campaign {campaign} resumed").map_err(io)?;
    Ok(())
}

/// One line of a campaign: its target, state, stage and the vehicles' states.
fn campaign_line(c: &CampaignInfo, out: &mut dyn Write) -> std::io::Result<()> {
    let counts: Vec<String> = c.counts.iter().map(|(s, n)| format!("{n} {s}")).collect();
    writeln!(
        out,
        "campaign {} '{}': {} {} for {} vehicle(s), {:?}, stage {} of {}{}: {}",
        c.id,
        c.name,
        c.ecu,
        c.version,
        c.vehicles,
        c.state,
        c.stage + 1,
        c.stages.len(),
        c.paused_reason
            .as_ref()
            .map_or(String::new(), |r| format!(" ({r})")),
        counts.join(", ")
    )
}

/// Publishes an image, retained, at its SHA-256's topic; waits until the broker has it.
fn publish_image(broker: &Broker, sha: &str, image: &[u8]) -> Result<(), String> {
    let runtime = mqtt_runtime()?;
    let link = MqttLink::connect(
        runtime.handle(),
        broker,
        LinkOptions::new(format!("autoplug-fleet-publisher-{}", std::process::id())),
    );
    link.wait_connected(Duration::from_secs(10))
        .map_err(|e| e.to_string())?;
    link.publish(&topics::image(sha), image.to_vec(), true)
        .map_err(|e| e.to_string())?;
    link.close(Duration::from_secs(10));
    Ok(())
}
