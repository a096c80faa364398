//! `autoplug fleet …`: the manufacturer's side of recall management. The fleet service
//! (`serve`: vehicles' reports from the broker into the database, campaign instructions
//! out), the recall queries, the campaigns, and the broker's configuration.
//!
//! The database is PostgreSQL (`postgresql://…`, the server any number of services share)
//! or an SQLite file (one machine, the default); the broker any MQTT 3.1.1 broker.
//!
//! Here are the arguments; [`run`] hands each subcommand to its module under `cmd::fleet`.

use std::io::Write;
use std::path::{Path, PathBuf};

use autoplug_fleet::mqtt::Broker;
use autoplug_fleet::{EvidenceQuery, Finding, InventoryQuery};
use autoplug_image::Version;
use clap::{Args, Subcommand};

use crate::cmd::fleet;

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

fn parse_queue(text: &str) -> Result<autoplug_fleet::nats::NatsServers, String> {
    text.parse()
}

fn parse_broker(text: &str) -> Result<Broker, String> {
    text.parse()
}

impl BrokerArgs {
    pub(crate) fn broker(&self) -> Result<Broker, String> {
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
    pub(crate) fn query(&self) -> InventoryQuery {
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
    pub(crate) fn query(&self) -> Option<EvidenceQuery> {
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
    Serve(ServeArgs),
    /// A fleet to try it on: N virtual cars, each with its gateway reporting to the broker
    /// (distinct VINs and serials, a mix of software releases, a share with the faulty
    /// cruise release 1.1.0, varied drives), headless and faster than real time. Between
    /// two drives the cars stay parked for --park seconds, answering the updates the fleet
    /// offers (their drivers agree; the ignition goes on for the flash).
    Simulate(SimulateArgs),
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

/// The fleet's messaging.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Engine {
    /// One Mosquitto broker: the default, for one machine.
    Mosquitto,
    /// A NATS cluster with JetStream: for fleets that outgrow one broker.
    Nats,
}

/// `autoplug fleet serve`: the database, the broker, the signing key and the service's
/// settings.
#[derive(Debug, Args)]
pub struct ServeArgs {
    /// The fleet database.
    #[command(flatten)]
    pub db: DbArgs,
    /// The broker.
    #[command(flatten)]
    pub broker: BrokerArgs,
    /// The fleet's signing key (from `autoplug keygen`): campaign instructions are
    /// signed with it. Without one, no instruction is sent.
    #[arg(long, value_name = "FILE.key")]
    pub key: Option<PathBuf>,
    /// Seconds between two passes over the campaigns.
    #[arg(long, value_name = "SECONDS", default_value_t = 1.0)]
    pub tick: f64,
    /// Stop after this many seconds.
    #[arg(long, value_name = "SECONDS")]
    pub duration: Option<f64>,
    /// The service's MQTT client id (unique per service).
    #[arg(long, value_name = "ID", default_value = "autoplug-fleet")]
    pub client_id: String,
    /// The services that split the reports between them (a shared subscription).
    #[arg(long, value_name = "NAME", default_value = "autoplug-fleet")]
    pub group: String,
    /// Take the reports from the clustered engine's work queue (NATS JetStream),
    /// nats://[USER[:PASSWORD]@]HOST[:PORT][,HOST[:PORT]…], instead of a shared
    /// subscription; receipts and instructions still go out through --broker (the
    /// cluster's MQTT).
    #[arg(long, value_name = "URL", env = "AUTOPLUG_QUEUE", value_parser = parse_queue)]
    pub queue: Option<autoplug_fleet::nats::NatsServers>,
    /// Read the work queue's password from this file (instead of the URL).
    #[arg(long, value_name = "FILE", requires = "queue")]
    pub queue_password_file: Option<PathBuf>,
    /// Keep the service's session at the broker while it is down (its subscription and
    /// the reports for it). Only for a service that runs alone: in a group, the broker
    /// goes on handing a stopped member's session its turn of every report, stranded
    /// there until it comes back. Without it (the default) the session ends with the
    /// connection, and the cars publish again what a stopped service held.
    #[arg(long)]
    pub persistent_session: bool,
    /// The default now (the session ends with the connection); kept so that scripts
    /// written for earlier versions still run.
    #[arg(long, hide = true, conflicts_with = "persistent_session")]
    pub clean_session: bool,
    /// Serve the fleet page (the dashboard's Fleet view: campaigns in total and per
    /// vehicle, read only) on this address, e.g. 127.0.0.1:8090.
    #[arg(long, value_name = "ADDR")]
    pub web: Option<std::net::SocketAddr>,
    /// A host name besides the listening address the fleet page answers for (NAME or
    /// NAME:PORT, as in the browser's address bar); repeatable. Other names are
    /// refused (421), so a web page cannot point its own name at this server and read
    /// the fleet.
    #[arg(long = "allowed-host", value_name = "NAME", requires = "web")]
    pub allowed_hosts: Vec<String>,
}

/// `autoplug fleet simulate`: the fleet drawn, its drives, the broker and the keys.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// How many cars.
    #[arg(long, value_name = "N", default_value_t = 200)]
    pub vehicles: usize,
    /// The seed the fleet is drawn from (the same seed, the same fleet).
    #[arg(long, default_value_t = 2026)]
    pub seed: u64,
    /// Drives per car.
    #[arg(long, value_name = "N", default_value_t = 2)]
    pub drives: usize,
    /// Seconds (wall time) the cars stay parked between two drives.
    #[arg(long = "park", value_name = "SECONDS", default_value_t = 0.0)]
    pub park_s: f64,
    /// The serial number (last six characters of the VIN) of the first car.
    #[arg(long, value_name = "NUMBER", default_value_t = 100_000)]
    pub first_serial: u32,
    /// Make each drive last about this many minutes (default: half a minute to a
    /// minute). A car lives at most an hour of simulated time.
    #[arg(long, value_name = "MINUTES")]
    pub drive_minutes: Option<f64>,
    /// Worker threads (each keeps its share of the cars).
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// The broker.
    #[command(flatten)]
    pub broker: BrokerArgs,
    /// The fleet's public key: instructions must verify with it.
    #[arg(long, value_name = "FILE.pub")]
    pub fleet_key: PathBuf,
    /// The ECUs' image key the gateways check images with (`dev`: the development key).
    #[arg(long, value_name = "FILE.pub", default_value = "dev")]
    pub image_key: PathBuf,
    /// Write every car's plan and what happened to it (the simulation's truth) here,
    /// as JSON.
    #[arg(long, value_name = "FILE.json")]
    pub truth: Option<PathBuf>,
    /// The share of drivers who decline an update (0 to 1), drawn per car from the
    /// seed.
    #[arg(long, value_name = "FRACTION", default_value_t = 0.0)]
    pub decline_share: f64,
    /// Give every car a login of its own (its VIN, a fresh password) on the running
    /// broker of this directory (`fleet broker init`, Mosquitto's or a NATS cluster's),
    /// and connect each with it to the vehicles' listener of --broker: the per-vehicle
    /// rights are then exercised as on the road.
    #[arg(long, value_name = "DIR")]
    pub broker_dir: Option<PathBuf>,
}

/// `autoplug fleet campaign` subcommands.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Subcommand)]
pub enum CampaignCommand {
    /// Create a campaign: a signed image for one ECU, the vehicles the target finds (by
    /// inventory, by evidence, or listed), rolled out in stages. Publishes the image to the
    /// broker; `fleet serve` sends the instructions.
    Create(CreateArgs),
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

/// `autoplug fleet campaign create`: the image, the target and the rollout.
#[derive(Debug, Args)]
pub struct CreateArgs {
    /// The fleet database.
    #[command(flatten)]
    pub db: DbArgs,
    /// The broker.
    #[command(flatten)]
    pub broker: BrokerArgs,
    /// Its name (unique).
    #[arg(long)]
    pub name: String,
    /// The ECU it updates.
    #[arg(long = "for", value_name = "ECU")]
    pub for_ecu: String,
    /// The signed image.
    #[arg(long, value_name = "FILE")]
    pub image: PathBuf,
    /// What the vehicles carry.
    #[command(flatten)]
    pub inventory: InventoryArgs,
    /// What their drives showed.
    #[command(flatten)]
    pub evidence: EvidenceArgs,
    /// These vehicles, by VIN (comma-separated).
    #[arg(long, value_name = "VIN,...", value_delimiter = ',')]
    pub vins: Vec<String>,
    /// Cumulative shares per stage, percent (e.g. 10,100: a tenth first, then all).
    #[arg(
        long,
        value_name = "PERCENT,...",
        value_delimiter = ',',
        default_value = "10,100"
    )]
    pub stages: Vec<f64>,
    /// Pause when a stage's failures pass this share (0 to 1).
    #[arg(long, value_name = "SHARE", default_value_t = 0.2)]
    pub failure_threshold: f64,
    /// Instructions per vehicle at most (the first and the retries).
    #[arg(long, value_name = "N", default_value_t = 3)]
    pub max_attempts: u32,
    /// Seconds a vehicle may take to answer an instruction before it is sent again.
    #[arg(long, value_name = "SECONDS", default_value_t = 3600.0)]
    pub answer_within: f64,
    /// Days an instruction holds.
    #[arg(long, value_name = "DAYS", default_value_t = 30.0)]
    pub valid_days: f64,
    /// What the driver is told.
    #[arg(long, default_value = "")]
    pub message: String,
}

/// `autoplug fleet broker` subcommands.
#[derive(Debug, Subcommand)]
pub enum BrokerCommand {
    /// Write a Mosquitto configuration for a fleet (logins, per-vehicle ACL, persistent
    /// sessions) into a directory: run `mosquitto -c DIR/mosquitto.conf`.
    ///
    /// With --engine nats: a NATS cluster's nodes instead (JetStream replicated by RAFT,
    /// MQTT for the vehicles, a work queue for the services): run
    /// `nats-server -c DIR/node-N.conf` for each.
    Init {
        /// The directory (created).
        #[arg(long, value_name = "DIR")]
        dir: PathBuf,
        /// Where the broker listens for vehicles (MQTT); with several nodes, node N on
        /// this port plus N-1.
        #[arg(long, value_name = "ADDR:PORT", default_value = "127.0.0.1:1883")]
        listen: std::net::SocketAddr,
        /// Mosquitto: where it listens for the fleet services (their own logins; each
        /// process keeps its own client id there).
        #[arg(long, value_name = "ADDR:PORT", default_value = "127.0.0.1:1884")]
        fleet_listen: std::net::SocketAddr,
        /// The engine: one Mosquitto (one machine), or a NATS cluster.
        #[arg(long, value_enum, default_value_t = Engine::Mosquitto)]
        engine: Engine,
        /// NATS: the cluster's nodes (3 survive the loss of one).
        #[arg(long, value_name = "N", default_value_t = 3, value_parser = clap::value_parser!(u16).range(1..=9))]
        nodes: u16,
        /// NATS: where node 1 listens for the fleet services (node N: the port plus N-1).
        #[arg(long, value_name = "ADDR:PORT", default_value = "127.0.0.1:4222")]
        client_listen: std::net::SocketAddr,
        /// NATS: where node 1 listens for the other nodes (node N: the port plus N-1).
        #[arg(long, value_name = "ADDR:PORT", default_value = "127.0.0.1:6222")]
        cluster_listen: std::net::SocketAddr,
    },
    /// Add a login to the running broker: a vehicle (its VIN) or the fleet services
    /// (autoplug-fleet); a login there already gets the new password. Prints the
    /// password once unless --password-file names one to use. A NATS cluster's
    /// directory: the logins' file rewritten and its running nodes told to reload.
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

/// Carries out `autoplug fleet …`.
pub fn run(command: FleetCommand, out: &mut dyn Write) -> Result<(), String> {
    match command {
        FleetCommand::Serve(args) => fleet::serve::run(args, out),
        FleetCommand::Simulate(args) => fleet::simulate::run(args, out),
        FleetCommand::Recall { db, query, json } => fleet::recall::run(&db, &query, json, out),
        FleetCommand::Evidence { db, query, json } => fleet::evidence::run(&db, &query, json, out),
        FleetCommand::Vehicle { vin, db } => fleet::vehicle::run(&vin, &db, out),
        FleetCommand::Campaign(CampaignCommand::Create(args)) => fleet::campaign::create(args, out),
        FleetCommand::Campaign(CampaignCommand::Status { campaign, db, json }) => {
            fleet::campaign::status(campaign.as_deref(), &db, json, out)
        }
        FleetCommand::Campaign(CampaignCommand::Pause { campaign, db }) => {
            fleet::campaign::pause(campaign, &db, out)
        }
        FleetCommand::Campaign(CampaignCommand::Resume { campaign, db }) => {
            fleet::campaign::resume(campaign, &db, out)
        }
        FleetCommand::Broker(BrokerCommand::Init {
            dir,
            listen,
            fleet_listen,
            engine: Engine::Mosquitto,
            ..
        }) => fleet::broker::init(&dir, listen, fleet_listen, out),
        FleetCommand::Broker(BrokerCommand::Init {
            dir,
            listen,
            engine: Engine::Nats,
            nodes,
            client_listen,
            cluster_listen,
            ..
        }) => fleet::broker::init_nats(
            &dir,
            nodes.into(),
            listen,
            client_listen,
            cluster_listen,
            out,
        ),
        FleetCommand::Broker(BrokerCommand::Add {
            dir,
            user,
            password_file,
        }) => fleet::broker::add(&dir, &user, password_file.as_deref(), out),
    }
}
