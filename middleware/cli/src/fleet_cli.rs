//! `autoplug fleet …`: the manufacturer's side of recall management. The fleet service
//! (`serve`: vehicles' reports from the broker into the database, campaign instructions
//! out), the recall queries, the campaigns, and the broker's configuration.
//!
//! The database is PostgreSQL (`postgresql://…`, the server any number of services share)
//! or an SQLite file (one machine, the default); the broker any MQTT 3.1.1 broker.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use autoplug_fleet::broker;
use autoplug_fleet::campaigns::{CampaignInfo, CampaignSpec, Target};
use autoplug_fleet::ingest::Ingest;
use autoplug_fleet::mqtt::{Broker, LinkOptions, MqttLink};
use autoplug_fleet::service::FleetService;
use autoplug_fleet::{topics, EvidenceQuery, Finding, FleetStore, InventoryQuery};
use autoplug_image::{SigningKey, Version};
use clap::{Args, Subcommand};

/// The database by default: an SQLite file in the working directory.
pub const DEFAULT_DB: &str = "fleet.db";

/// Where the fleet's data is.
#[derive(Debug, Args, Clone)]
pub struct DbArgs {
    /// The fleet database: postgresql://USER@HOST:PORT/DB (PostgreSQL) or an SQLite file.
    #[arg(long, value_name = "ADDRESS", env = "AUTOPLUG_FLEET_DB", default_value = DEFAULT_DB)]
    pub db: String,
}

/// The broker.
#[derive(Debug, Args, Clone)]
pub struct BrokerArgs {
    /// The MQTT broker: mqtt://[USER[:PASSWORD]@]HOST[:PORT].
    #[arg(long, value_name = "URL", env = "AUTOPLUG_BROKER", default_value = autoplug_fleet::mqtt::DEFAULT_BROKER, value_parser = parse_broker)]
    pub broker: Broker,
    /// Read the broker password from this file (instead of the URL, which others may see).
    #[arg(long, value_name = "FILE")]
    pub broker_password_file: Option<PathBuf>,
}

/// How a vehicle's gateway reports to the fleet (`autoplug gateway`, `autoplug dashboard`).
#[derive(Debug, Args, Clone)]
pub struct VehicleFleetArgs {
    /// Report to the fleet through this MQTT broker, mqtt://[VIN:PASSWORD@]HOST[:PORT]
    /// (the inventory, every trip with its verdicts and trouble codes) and take its update
    /// campaigns, which the driver is asked about. The connection opens once the ECUs
    /// answered the VIN; needs --fleet-key.
    #[arg(long, value_name = "URL", value_parser = parse_broker)]
    pub fleet: Option<Broker>,
    /// Read the broker password from this file (instead of the URL).
    #[arg(long, value_name = "FILE", requires = "fleet")]
    pub fleet_password_file: Option<PathBuf>,
    /// The fleet's public key (`autoplug keygen`'s FILE.pub): campaign instructions must
    /// verify with it.
    #[arg(long, value_name = "FILE.pub", requires = "fleet")]
    pub fleet_key: Option<PathBuf>,
    /// The ECUs' image key (`dev`: the development key): a campaign's image must verify
    /// with it before the driver is asked.
    #[arg(long, value_name = "FILE.pub", requires = "fleet")]
    pub image_key: Option<PathBuf>,
    /// Where the gateway keeps what it has seen of the fleet across restarts (the newest
    /// campaign instruction's number: one played again is refused); default
    /// `fleet-state.json` in the dashboard's data folder, or beside the gateway's --db.
    #[arg(long, value_name = "FILE", requires = "fleet")]
    pub fleet_state: Option<PathBuf>,
}

impl VehicleFleetArgs {
    /// The link's configuration, if the gateway reports to a fleet; its state in
    /// `--fleet-state`, else in `default_state`.
    pub fn config(
        &self,
        default_state: Option<PathBuf>,
    ) -> Result<Option<autoplug_fleet_agent::link::FleetConfig>, String> {
        let Some(broker) = &self.fleet else {
            return Ok(None);
        };
        let fleet_key = self.fleet_key.as_deref().ok_or(
            "--fleet needs --fleet-key FILE.pub (the fleet's public key: instructions are checked with it)",
        )?;
        let image_key = self.image_key.as_deref().unwrap_or(Path::new("dev"));
        let broker = BrokerArgs {
            broker: broker.clone(),
            broker_password_file: self.fleet_password_file.clone(),
        }
        .broker()?;
        Ok(Some(autoplug_fleet_agent::link::FleetConfig {
            broker,
            fleet_key: autoplug_image_tool::read_public_key(fleet_key)
                .map_err(|e| e.to_string())?,
            image_key: autoplug_image_tool::read_public_key(image_key)
                .map_err(|e| e.to_string())?,
            security_secret: autoplug_tester::DEV_SECURITY_SECRET.to_vec(),
            resend_after_ms: autoplug_fleet::outbox::RESEND_AFTER_MS,
            state_file: self.fleet_state.clone().or(default_state),
        }))
    }
}

fn parse_broker(text: &str) -> Result<Broker, String> {
    text.parse()
}

impl BrokerArgs {
    fn broker(&self) -> Result<Broker, String> {
        let mut broker = self.broker.clone();
        if let Some(path) = &self.broker_password_file {
            let password = std::fs::read_to_string(path)
                .map_err(|e| format!("cannot read '{}': {e}", path.display()))?;
            broker.password = Some(password.trim_end_matches(['\r', '\n']).to_string());
        }
        Ok(broker)
    }
}

/// What a recall asks for by inventory.
#[derive(Debug, Args, Clone, Default)]
pub struct InventoryArgs {
    /// The ECU (engine, cruise, abs...).
    #[arg(long, value_name = "NAME")]
    pub ecu: Option<String>,
    /// Its part number, exactly.
    #[arg(long, value_name = "TEXT")]
    pub part_number: Option<String>,
    /// Lowest software version, inclusive (MAJOR.MINOR.PATCH).
    #[arg(long, value_name = "VERSION")]
    pub software_from: Option<Version>,
    /// Highest software version, inclusive.
    #[arg(long, value_name = "VERSION")]
    pub software_to: Option<Version>,
    /// The hardware version, exactly.
    #[arg(long, value_name = "TEXT")]
    pub hardware: Option<String>,
    /// Lowest serial number, inclusive (serials compare as text).
    #[arg(long, value_name = "TEXT")]
    pub serial_from: Option<String>,
    /// Highest serial number, inclusive.
    #[arg(long, value_name = "TEXT")]
    pub serial_to: Option<String>,
}

impl InventoryArgs {
    fn query(&self) -> InventoryQuery {
        InventoryQuery {
            ecu: self.ecu.clone(),
            part_number: self.part_number.clone(),
            software_from: self.software_from,
            software_to: self.software_to,
            hardware_version: self.hardware.clone(),
            serial_from: self.serial_from.clone(),
            serial_to: self.serial_to.clone(),
        }
    }
}

/// What a recall asks for by evidence.
#[derive(Debug, Args, Clone, Default)]
pub struct EvidenceArgs {
    /// Vehicles whose ECU was judged faulty at the end of a trip.
    #[arg(long, conflicts_with = "dtc")]
    pub faulty: bool,
    /// Vehicles whose ECU raised this trouble code (U0140, or U0140-87 for one failure
    /// type).
    #[arg(long, value_name = "CODE")]
    pub dtc: Option<String>,
    /// Only this ECU's evidence.
    #[arg(long, value_name = "NAME")]
    pub evidence_ecu: Option<String>,
    /// From this time, ms since the Unix epoch (default: the beginning).
    #[arg(long, value_name = "MS", default_value_t = 0)]
    pub since_ms: i64,
    /// Until this time, exclusive (default: no end).
    #[arg(long, value_name = "MS", default_value_t = i64::MAX)]
    pub until_ms: i64,
}

impl EvidenceArgs {
    fn query(&self) -> Option<EvidenceQuery> {
        let finding = match (&self.dtc, self.faulty) {
            (Some(code), _) => Finding::Dtc(code.clone()),
            (None, true) => Finding::Faulty,
            (None, false) => return None,
        };
        Some(EvidenceQuery {
            finding,
            ecu: self.evidence_ecu.clone(),
            since_ms: self.since_ms,
            until_ms: self.until_ms,
        })
    }
}

/// `autoplug fleet` subcommands.
// Parsed once per run: the size of the largest variant does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Subcommand)]
pub enum FleetCommand {
    /// The fleet service: stores the vehicles' reports from the broker, sends the
    /// campaigns' instructions (signed with --key). Any number may run on one database
    /// and broker (they share the reports). Runs until Ctrl-C.
    Serve {
        /// The fleet database.
        #[command(flatten)]
        db: DbArgs,
        /// The broker.
        #[command(flatten)]
        broker: BrokerArgs,
        /// The fleet's signing key (from `autoplug keygen`): campaign instructions are
        /// signed with it. Without one, no instruction is sent.
        #[arg(long, value_name = "FILE.key")]
        key: Option<PathBuf>,
        /// Seconds between two passes over the campaigns.
        #[arg(long, value_name = "SECONDS", default_value_t = 1.0)]
        tick: f64,
        /// Stop after this many seconds.
        #[arg(long, value_name = "SECONDS")]
        duration: Option<f64>,
        /// The service's MQTT client id (unique per service).
        #[arg(long, value_name = "ID", default_value = "autoplug-fleet")]
        client_id: String,
        /// The services that split the reports between them (a shared subscription).
        #[arg(long, value_name = "NAME", default_value = "autoplug-fleet")]
        group: String,
        /// Keep no session at the broker (a one-off run or a test): reports published
        /// while the service is down are then not kept for it.
        #[arg(long)]
        clean_session: bool,
        /// Serve the fleet page (the dashboard's Fleet view: campaigns in total and per
        /// vehicle, read only) on this address, e.g. 127.0.0.1:8090.
        #[arg(long, value_name = "ADDR")]
        web: Option<std::net::SocketAddr>,
        /// A host name besides the listening address the fleet page answers for (NAME or
        /// NAME:PORT, as in the browser's address bar); repeatable. Other names are
        /// refused (421), so a web page cannot point its own name at this server and read
        /// the fleet.
        #[arg(long = "allowed-host", value_name = "NAME", requires = "web")]
        allowed_hosts: Vec<String>,
    },
    /// A fleet to try it on: N virtual cars, each with its gateway reporting to the broker
    /// (distinct VINs and serials, a mix of software releases, a share with the faulty
    /// cruise release 1.1.0, varied drives), headless and faster than real time. Between
    /// two drives the cars stay parked for --park seconds, answering the updates the fleet
    /// offers (their drivers agree; the ignition goes on for the flash).
    Simulate {
        /// How many cars.
        #[arg(long, value_name = "N", default_value_t = 200)]
        vehicles: usize,
        /// The seed the fleet is drawn from (the same seed, the same fleet).
        #[arg(long, default_value_t = 2026)]
        seed: u64,
        /// Drives per car.
        #[arg(long, value_name = "N", default_value_t = 2)]
        drives: usize,
        /// Seconds (wall time) the cars stay parked between two drives.
        #[arg(long = "park", value_name = "SECONDS", default_value_t = 0.0)]
        park_s: f64,
        /// The serial number (last six characters of the VIN) of the first car.
        #[arg(long, value_name = "NUMBER", default_value_t = 100_000)]
        first_serial: u32,
        /// Make each drive last about this many minutes (default: half a minute to a
        /// minute). A car lives at most an hour of simulated time.
        #[arg(long, value_name = "MINUTES")]
        drive_minutes: Option<f64>,
        /// Worker threads (each keeps its share of the cars).
        #[arg(long, value_name = "N")]
        threads: Option<usize>,
        /// The broker.
        #[command(flatten)]
        broker: BrokerArgs,
        /// The fleet's public key: instructions must verify with it.
        #[arg(long, value_name = "FILE.pub")]
        fleet_key: PathBuf,
        /// The ECUs' image key the gateways check images with (`dev`: the development key).
        #[arg(long, value_name = "FILE.pub", default_value = "dev")]
        image_key: PathBuf,
        /// Write every car's plan and what happened to it (the simulation's truth) here,
        /// as JSON.
        #[arg(long, value_name = "FILE.json")]
        truth: Option<PathBuf>,
        /// The share of drivers who decline an update (0 to 1), drawn per car from the
        /// seed.
        #[arg(long, value_name = "FRACTION", default_value_t = 0.0)]
        decline_share: f64,
        /// Give every car a login of its own (its VIN, a fresh password) on the running
        /// broker of this directory (`fleet broker init`), and connect each with it to the
        /// vehicles' listener of --broker: the per-vehicle rights are then exercised as on
        /// the road.
        #[arg(long, value_name = "DIR")]
        broker_dir: Option<PathBuf>,
    },
    /// Recall by inventory: the vehicles carrying what is described, each with the ECU
    /// that matched.
    Recall {
        /// The fleet database.
        #[command(flatten)]
        db: DbArgs,
        /// What the vehicles carry.
        #[command(flatten)]
        query: InventoryArgs,
        /// JSON for scripts.
        #[arg(long)]
        json: bool,
    },
    /// Recall by evidence: the vehicles whose ECU was judged faulty, or raised a trouble
    /// code, in a period, with every piece of evidence.
    Evidence {
        /// The fleet database.
        #[command(flatten)]
        db: DbArgs,
        /// What their drives showed.
        #[command(flatten)]
        query: EvidenceArgs,
        /// JSON for scripts.
        #[arg(long)]
        json: bool,
    },
    /// One vehicle's inventory.
    Vehicle {
        /// The VIN.
        vin: String,
        /// The fleet database.
        #[command(flatten)]
        db: DbArgs,
    },
    /// Update campaigns.
    #[command(subcommand)]
    Campaign(CampaignCommand),
    /// The broker's configuration.
    #[command(subcommand)]
    Broker(BrokerCommand),
}

/// `autoplug fleet campaign` subcommands.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Subcommand)]
pub enum CampaignCommand {
    /// Create a campaign: a signed image for one ECU, the vehicles the target finds (by
    /// inventory, by evidence, or listed), rolled out in stages. Publishes the image to the
    /// broker; `fleet serve` sends the instructions.
    Create {
        /// The fleet database.
        #[command(flatten)]
        db: DbArgs,
        /// The broker.
        #[command(flatten)]
        broker: BrokerArgs,
        /// Its name (unique).
        #[arg(long)]
        name: String,
        /// The ECU it updates.
        #[arg(long = "for", value_name = "ECU")]
        for_ecu: String,
        /// The signed image.
        #[arg(long, value_name = "FILE")]
        image: PathBuf,
        /// What the vehicles carry.
        #[command(flatten)]
        inventory: InventoryArgs,
        /// What their drives showed.
        #[command(flatten)]
        evidence: EvidenceArgs,
        /// These vehicles, by VIN (comma-separated).
        #[arg(long, value_name = "VIN,...", value_delimiter = ',')]
        vins: Vec<String>,
        /// Cumulative shares per stage, percent (e.g. 10,100: a tenth first, then all).
        #[arg(
            long,
            value_name = "PERCENT,...",
            value_delimiter = ',',
            default_value = "10,100"
        )]
        stages: Vec<f64>,
        /// Pause when a stage's failures pass this share (0 to 1).
        #[arg(long, value_name = "SHARE", default_value_t = 0.2)]
        failure_threshold: f64,
        /// Instructions per vehicle at most (the first and the retries).
        #[arg(long, value_name = "N", default_value_t = 3)]
        max_attempts: u32,
        /// Seconds a vehicle may take to answer an instruction before it is sent again.
        #[arg(long, value_name = "SECONDS", default_value_t = 3600.0)]
        answer_within: f64,
        /// Days an instruction holds.
        #[arg(long, value_name = "DAYS", default_value_t = 30.0)]
        valid_days: f64,
        /// What the driver is told.
        #[arg(long, default_value = "")]
        message: String,
    },
    /// The campaigns, or one with its vehicles.
    Status {
        /// A campaign's number or name (default: all, briefly).
        campaign: Option<String>,
        /// The fleet database.
        #[command(flatten)]
        db: DbArgs,
        /// JSON for scripts.
        #[arg(long)]
        json: bool,
    },
    /// Pause a running campaign.
    Pause {
        /// Its number.
        campaign: i64,
        /// The fleet database.
        #[command(flatten)]
        db: DbArgs,
    },
    /// Resume a paused campaign.
    Resume {
        /// Its number.
        campaign: i64,
        /// The fleet database.
        #[command(flatten)]
        db: DbArgs,
    },
}

/// `autoplug fleet broker` subcommands.
#[derive(Debug, Subcommand)]
pub enum BrokerCommand {
    /// Write a Mosquitto configuration for a fleet (logins, per-vehicle ACL, persistent
    /// sessions) into a directory: run `mosquitto -c DIR/mosquitto.conf`.
    Init {
        /// The directory (created).
        #[arg(long, value_name = "DIR")]
        dir: PathBuf,
        /// Where the broker listens for vehicles.
        #[arg(long, value_name = "ADDR:PORT", default_value = "127.0.0.1:1883")]
        listen: std::net::SocketAddr,
        /// Where it listens for the fleet services (their own logins; each process keeps
        /// its own client id there).
        #[arg(long, value_name = "ADDR:PORT", default_value = "127.0.0.1:1884")]
        fleet_listen: std::net::SocketAddr,
    },
    /// Add a login to the running broker: a vehicle (its VIN) or the fleet services
    /// (autoplug-fleet); a login there already gets the new password. Prints the
    /// password once unless --password-file names one to use.
    Add {
        /// The directory of `broker init`.
        #[arg(long, value_name = "DIR")]
        dir: PathBuf,
        /// The user: a VIN, or autoplug-fleet.
        #[arg(long)]
        user: String,
        /// Use the password in this file.
        #[arg(long, value_name = "FILE")]
        password_file: Option<PathBuf>,
    },
}

fn open(db: &DbArgs) -> Result<FleetStore, String> {
    FleetStore::open(&db.db).map_err(|e| e.to_string())
}

fn json(value: &impl serde::Serialize) -> Result<String, String> {
    serde_json::to_string_pretty(value).map_err(|e| e.to_string())
}

fn read_key(path: &Path) -> Result<SigningKey, String> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| format!("cannot read the key '{}': {e}", path.display()))?;
    SigningKey::parse(&text).map_err(|e| format!("'{}': {e}", path.display()))
}

/// Runs `autoplug fleet simulate` (see [`FleetCommand::Simulate`]).
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
    let io = |e: std::io::Error| format!("cannot write the output: {e}");
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
        broker::add_logins(&broker::BrokerDir::at(dir), &logins)?;
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

/// Carries out `autoplug fleet …`.
pub fn run(command: FleetCommand, out: &mut dyn Write) -> Result<(), String> {
    let io = |e: std::io::Error| format!("cannot write the output: {e}");
    match command {
        FleetCommand::Simulate {
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
        } => {
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
        FleetCommand::Serve {
            db,
            broker,
            key,
            tick,
            duration,
            client_id,
            group,
            clean_session,
            web,
            allowed_hosts,
        } => {
            let mut options = LinkOptions::new(client_id);
            options.persistent_session = !clean_session;
            options.manual_acks = true;
            if group.is_empty() || group.contains(['/', '+', '#']) {
                return Err(format!("'{group}' cannot name a group (no '/', '+', '#')"));
            }
            options.subscriptions = vec![topics::reports_shared(&group)];
            let settings = ServeSettings {
                key,
                tick,
                duration,
                web,
                allowed_hosts,
            };
            serve(&db, &broker, settings, options, out)
        }
        FleetCommand::Recall {
            db,
            query,
            json: as_json,
        } => {
            let hits = open(&db)?
                .recall_by_inventory(&query.query())
                .map_err(|e| e.to_string())?;
            if as_json {
                writeln!(out, "{}", json(&hits)?).map_err(io)?;
                return Ok(());
            }
            writeln!(
                out,
                "{:<17} {:<13} {:<16} {:<9} {:<16} serial",
                "VIN", "ECU", "part number", "software", "hardware"
            )
            .map_err(io)?;
            for h in &hits {
                let o = |v: &Option<String>| v.clone().unwrap_or_else(|| "-".into());
                writeln!(
                    out,
                    "{:<17} {:<13} {:<16} {:<9} {:<16} {}",
                    h.vin,
                    h.ecu,
                    o(&h.part_number),
                    o(&h.software_version),
                    o(&h.hardware_version),
                    o(&h.serial)
                )
                .map_err(io)?;
            }
            let vehicles: std::collections::BTreeSet<&str> =
                hits.iter().map(|h| h.vin.as_str()).collect();
            writeln!(out, "{} vehicle(s)", vehicles.len()).map_err(io)?;
            Ok(())
        }
        FleetCommand::Evidence {
            db,
            query,
            json: as_json,
        } => {
            let query = query
                .query()
                .ok_or("name the evidence: --faulty or --dtc CODE")?;
            let hits = open(&db)?
                .recall_by_evidence(&query)
                .map_err(|e| e.to_string())?;
            if as_json {
                writeln!(out, "{}", json(&hits)?).map_err(io)?;
                return Ok(());
            }
            for hit in &hits {
                writeln!(out, "{}", hit.vin).map_err(io)?;
                for e in &hit.evidence {
                    writeln!(
                        out,
                        "  trip {:<6} {:<13} {}: {}",
                        e.trip, e.ecu, e.what, e.detail
                    )
                    .map_err(io)?;
                }
            }
            writeln!(out, "{} vehicle(s)", hits.len()).map_err(io)?;
            Ok(())
        }
        FleetCommand::Vehicle { vin, db } => {
            autoplug_vin::Vin::parse(&vin).map_err(|e| format!("VIN \"{vin}\": {e}"))?;
            let rows = open(&db)?
                .vehicle_inventory(&vin)
                .map_err(|e| e.to_string())?;
            if rows.is_empty() {
                return Err(format!("the fleet knows no vehicle {vin}"));
            }
            writeln!(out, "{}", json(&rows)?).map_err(io)?;
            Ok(())
        }
        FleetCommand::Campaign(command) => campaign(command, out),
        FleetCommand::Broker(BrokerCommand::Init {
            dir,
            listen,
            fleet_listen,
        }) => {
            let files = broker::init(
                &dir,
                &listen.ip().to_string(),
                listen.port(),
                &fleet_listen.ip().to_string(),
                fleet_listen.port(),
            )?;
            writeln!(
                out,
                "wrote {} (with the logins' file, dynamic-security.json, and the administrator's password): vehicles on {listen}, fleet services on {fleet_listen}\nrun it with: mosquitto -c {}\nthen add logins with: autoplug fleet broker add --dir {} --user VIN (or --user {})",
                files.config.display(),
                files.config.display(),
                dir.display(),
                broker::FLEET_USER
            )
            .map_err(io)?;
            Ok(())
        }
        FleetCommand::Broker(BrokerCommand::Add {
            dir,
            user,
            password_file,
        }) => {
            let (password, show) = match password_file {
                Some(path) => (
                    std::fs::read_to_string(&path)
                        .map_err(|e| format!("cannot read '{}': {e}", path.display()))?
                        .trim_end_matches(['\r', '\n'])
                        .to_string(),
                    false,
                ),
                None => (broker::random_password()?, true),
            };
            broker::add_login(&broker::BrokerDir::at(&dir), &user, &password)?;
            writeln!(out, "added {user} to the running broker").map_err(io)?;
            if show {
                writeln!(out, "password: {password}").map_err(io)?;
            }
            Ok(())
        }
    }
}

fn campaign(command: CampaignCommand, out: &mut dyn Write) -> Result<(), String> {
    let io = |e: std::io::Error| format!("cannot write the output: {e}");
    match command {
        CampaignCommand::Create {
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
        } => {
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
        CampaignCommand::Status {
            campaign,
            db,
            json: as_json,
        } => {
            let mut store = open(&db)?;
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
                    let info = store.campaign(&which).map_err(|e| e.to_string())?;
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
        CampaignCommand::Pause { campaign, db } => {
            open(&db)?
                .pause_campaign(campaign)
                .map_err(|e| e.to_string())?;
            writeln!(out, "campaign {campaign} paused").map_err(io)?;
            Ok(())
        }
        CampaignCommand::Resume { campaign, db } => {
            open(&db)?
                .resume_campaign(campaign)
                .map_err(|e| e.to_string())?;
            writeln!(out, "campaign {campaign} resumed").map_err(io)?;
            Ok(())
        }
    }
}

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

/// A runtime for the fleet's MQTT connections (two workers: the connections only move
/// bytes).
pub fn mqtt_runtime() -> Result<tokio::runtime::Runtime, String> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .thread_name("mqtt")
        .enable_all()
        .build()
        .map_err(|e| format!("cannot start the MQTT runtime: {e}"))
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

/// `autoplug fleet serve`'s settings besides the database and the broker.
struct ServeSettings {
    key: Option<PathBuf>,
    tick: f64,
    duration: Option<f64>,
    web: Option<std::net::SocketAddr>,
    allowed_hosts: Vec<String>,
}

fn serve(
    db: &DbArgs,
    broker: &BrokerArgs,
    settings: ServeSettings,
    options: LinkOptions,
    out: &mut dyn Write,
) -> Result<(), String> {
    let io = |e: std::io::Error| format!("cannot write the output: {e}");
    let ServeSettings {
        key,
        tick,
        duration,
        web,
        allowed_hosts,
    } = settings;
    if !(tick.is_finite() && (0.01..=3600.0).contains(&tick)) {
        return Err("--tick is 0.01 to 3600 seconds".into());
    }
    let key = key.as_deref().map(read_key).transpose()?;
    let store = open(db)?;
    // The fleet page reads through a connection of its own (the service's is busy).
    let _page_server = match web {
        Some(addr) => {
            let page = autoplug_dashboard::fleet_page::FleetPage::open(&db.db)?;
            let config = autoplug_web::WebConfig {
                addr,
                fleet: Some(Arc::new(page)),
                live: false,
                allowed_hosts,
                ..autoplug_web::WebConfig::loopback(0)
            };
            let server = autoplug_web::WebServer::start(
                config,
                Arc::new(autoplug_web::LiveTable::new()),
                None,
            )
            .map_err(|e| e.to_string())?;
            writeln!(out, "fleet page on http://{}/fleet", server.addr()).map_err(io)?;
            Some(server)
        }
        None => None,
    };
    let runtime = mqtt_runtime()?;
    let broker = broker.broker()?;
    let link = MqttLink::connect(runtime.handle(), &broker, options);
    link.wait_connected(Duration::from_secs(10))
        .map_err(|e| e.to_string())?;
    writeln!(
        out,
        "fleet service: reports from {broker} into {}; campaigns {}",
        store.name(),
        if key.is_some() {
            "sent"
        } else {
            "not sent (no --key)"
        }
    )
    .map_err(io)?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // A second service or a test may have set a handler: then Ctrl-C just ends.
        let _ = ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed));
    }
    let started = Instant::now();
    let mut service =
        FleetService::new(Ingest::new(store, link), key, Duration::from_secs_f64(tick));
    while !stop.load(Ordering::Relaxed)
        && duration.is_none_or(|d| started.elapsed().as_secs_f64() < d)
    {
        service.step(&stop, Duration::from_millis(50));
        // As they happen, so an operator sees a database that fails, and its return.
        for notice in service.ingest.take_notices() {
            eprintln!("fleet: {notice}");
        }
    }
    let sends = service.sends_campaigns();
    let (sent, failure) = (service.sent, service.failure.take());
    let ingest = service.ingest;
    let s = &ingest.stats;
    writeln!(
        out,
        "stored {} inventories, {} trips ({} duplicates), {} campaign reports; refused {}",
        s.inventories, s.trips, s.duplicates, s.campaign_reports, s.rejected
    )
    .map_err(io)?;
    for reason in &s.last_rejections {
        writeln!(out, "  refused: {reason}").map_err(io)?;
    }
    if sends {
        writeln!(out, "sent {sent} campaign instructions").map_err(io)?;
    }
    if let Some(failure) = failure {
        writeln!(out, "last campaign error: {failure}").map_err(io)?;
    }
    ingest.link.close(Duration::from_secs(5));
    Ok(())
}
