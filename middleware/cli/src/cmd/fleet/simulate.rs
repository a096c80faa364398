//! `autoplug fleet simulate`: a fleet of virtual cars reporting to the broker, driving
//! and parked by turns, answering the fleet's update offers.

use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use autoplug_fleet::broker;

use super::{io, mqtt_runtime};
use crate::fleet_cli::{BrokerArgs, SimulateArgs};

/// Checks the plan's numbers and runs the simulated fleet.
pub(crate) fn run(args: SimulateArgs, out: &mut dyn Write) -> Result<(), String> {
    let SimulateArgs {
        vehicles,
        seed,
        drives,
        park_s,
        first_serial,
        drive_minutes,
        threads,
        broker,
        fleet_key,
        image_key,
        truth,
        decline_share,
        broker_dir,
    } = args;
    let mut plan = autoplug_fleet_sim::FleetPlan::new(vehicles, seed);
    plan.drives = drives;
    if !(decline_share.is_finite() && (0.0..=1.0).contains(&decline_share)) {
        return Err("--decline-share is a fraction, 0 to 1".into());
    }
    plan.decline_share = decline_share;
    plan.first_serial = first_serial;
    if let Some(minutes) = drive_minutes {
        if !(minutes.is_finite() && (0.5..=50.0).contains(&minutes))
            || minutes * drives as f64 > 50.0
        {
            return Err(
                "--drive-minutes is 0.5 to 50, and all drives of a car together at most 50 minutes (a car lives an hour of simulated time)"
                    .into(),
            );
        }
        plan.drive_minutes = Some(minutes);
    }
    simulate(
        plan,
        park_s,
        threads,
        &broker,
        &fleet_key,
        &image_key,
        truth.as_deref(),
        broker_dir.as_deref(),
        out,
    )
}

/// Runs `autoplug fleet simulate` (see [`crate::fleet_cli::FleetCommand::Simulate`]).
#[allow(clippy::too_many_arguments)]
fn simulate(
    plan: autoplug_fleet_sim::FleetPlan,
    park_s: f64,
    threads: Option<usize>,
    broker: &BrokerArgs,
    fleet_key: &Path,
    image_key: &Path,
    truth: Option<&Path>,
    broker_dir: Option<&Path>,
    out: &mut dyn Write,
) -> Result<(), String> {
    use autoplug_fleet_sim::{Order, SimFleet};
    if plan.vehicles == 0 || plan.vehicles > 100_000 {
        return Err("--vehicles is 1 to 100000".into());
    }
    if plan.drives == 0 || plan.drives > 100 {
        return Err("--drives is 1 to 100".into());
    }
    if !(park_s.is_finite() && (0.0..=86_400.0).contains(&park_s)) {
        return Err("--park is 0 to 86400 seconds".into());
    }
    let config = autoplug_fleet_agent::link::FleetConfig {
        broker: broker.broker()?,
        fleet_key: autoplug_image_tool::read_public_key(fleet_key).map_err(|e| e.to_string())?,
        image_key: autoplug_image_tool::read_public_key(image_key).map_err(|e| e.to_string())?,
        security_secret: autoplug_tester::DEV_SECURITY_SECRET.to_vec(),
        resend_after_ms: autoplug_fleet::outbox::RESEND_AFTER_MS,
        // A simulated car lives as long as the run.
        state_file: None,
    };
    let threads = threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
        .clamp(1, 256);
    let mut specs = autoplug_fleet_sim::plan(&plan);
    if let Some(dir) = broker_dir {
        let mut logins = Vec::with_capacity(specs.len());
        for spec in &mut specs {
            let password = broker::random_password()?;
            logins.push((spec.vin.clone(), password.clone()));
            spec.broker_password = Some(password);
        }
        let cluster = autoplug_fleet::nats_cluster::ClusterDir::at(dir);
        if cluster.logins.is_file() {
            // A NATS cluster's directory: its running nodes reload the logins.
            let logins: Vec<(String, String, bool)> = logins
                .iter()
                .map(|(u, p)| (u.clone(), p.clone(), false))
                .collect();
            autoplug_fleet::nats_cluster::add_logins(&cluster, &logins)?;
            // A reload takes effect within moments; the first cars connect after it.
            std::thread::sleep(std::time::Duration::from_millis(500));
        } else {
            broker::add_logins(&broker::BrokerDir::at(dir), &logins)?;
        }
        writeln!(
            out,
            "{} logins added to the broker of {} (one per car: its VIN)",
            logins.len(),
            dir.display()
        )
        .map_err(io)?;
    }
    let carriers = specs.iter().filter(|s| s.cruise_faulty).count();
    writeln!(
        out,
        "{} cars ({carriers} with the faulty cruise release {}), reporting to {}",
        specs.len(),
        autoplug_fleet_sim::FAULTY_CRUISE,
        config.broker
    )
    .map_err(io)?;
    let runtime = mqtt_runtime()?;
    let started = Instant::now();
    let (mut fleet, mut statuses) =
        SimFleet::start(specs.clone(), config, runtime.handle().clone(), threads)?;
    let simulated = |statuses: &[autoplug_fleet_sim::VehicleStatus]| -> f64 {
        statuses.iter().map(|s| s.sim_s).sum()
    };
    // What a step took: wall time, simulated time over all cars, the reports still queued.
    let report = |what: &str,
                  statuses: &[autoplug_fleet_sim::VehicleStatus],
                  sim_before: f64,
                  since: Instant,
                  out: &mut dyn Write| {
        let wall = since.elapsed().as_secs_f64();
        let sim = simulated(statuses) - sim_before;
        let errors: Vec<String> = statuses
            .iter()
            .filter_map(|s| s.error.as_ref().map(|e| format!("{}: {e}", s.vin)))
            .collect();
        writeln!(
            out,
            "{what}: {wall:.1} s; {sim:.0} s simulated in all ({:.0}x real time); {} reports waiting{}",
            sim / wall.max(1e-9),
            statuses.iter().map(|s| s.waiting_reports).sum::<usize>(),
            if errors.is_empty() {
                String::new()
            } else {
                format!("; errors: {}", errors.join("; "))
            }
        )
        .map_err(io)
    };
    report("connected and identified", &statuses, 0.0, started, out)?;
    for drive in 0..plan.drives {
        let (since, before) = (Instant::now(), simulated(&statuses));
        statuses = fleet.order(Order::Drive)?;
        let showed = statuses
            .iter()
            .filter(|s| s.drives.last().is_some_and(|d| d.showed_faulty_cruise()))
            .count();
        report(
            &format!("drive {} ({showed} showed the faulty cruise)", drive + 1),
            &statuses,
            before,
            since,
            out,
        )?;
        if drive + 1 < plan.drives && park_s > 0.0 {
            let (since, before) = (Instant::now(), simulated(&statuses));
            let flag = Arc::new(AtomicBool::new(false));
            let timer = {
                let flag = flag.clone();
                std::thread::spawn(move || {
                    std::thread::sleep(Duration::from_secs_f64(park_s));
                    flag.store(true, Ordering::SeqCst);
                })
            };
            statuses = fleet.order(Order::Park(flag))?;
            let _ = timer.join();
            let installed = statuses
                .iter()
                .flat_map(|s| &s.campaign_reports)
                .filter(|r| r.state == autoplug_fleet::campaign::VehicleState::Installed)
                .count();
            report(
                &format!("parked ({installed} updates installed)"),
                &statuses,
                before,
                since,
                out,
            )?;
        }
    }
    if let Some(path) = truth {
        // The statuses come back in the workers' order: each plan finds its car by VIN.
        let by_vin: std::collections::HashMap<&str, &autoplug_fleet_sim::VehicleStatus> =
            statuses.iter().map(|s| (s.vin.as_str(), s)).collect();
        let cars: Vec<serde_json::Value> = specs
            .iter()
            .map(|spec| {
                let outcome = by_vin.get(spec.vin.as_str()).copied();
                serde_json::json!({ "plan": spec, "outcome": outcome })
            })
            .collect();
        let text = serde_json::to_string_pretty(&cars).map_err(|e| e.to_string())?;
        std::fs::write(path, text)
            .map_err(|e| format!("cannot write '{}': {e}", path.display()))?;
        writeln!(out, "the simulation's truth: {}", path.display()).map_err(io)?;
    }
    fleet.finish();
    Ok(())
}
