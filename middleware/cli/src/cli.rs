//! The `autoplug` command: keys, images, identification and flashing.
//!
//! [`Cli`] is the command line (clap); [`run`] carries a parsed one out and writes what it
//! has to say to `out`, so tests run commands without a process; [`main`] is the whole
//! program.

use std::fmt;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use autoplug_can::Node;
use autoplug_image::{ImageHeader, SoftwareVariant, Version, BUILD_ID_LEN};
use clap::{Args, Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};

use autoplug_dashboard::session::{Session, SourceKind};
use autoplug_gateway::{Observer, Pipeline, RecordingSink, Strictness};
use autoplug_image_tool::{BuildOptions, ImageToolError, PayloadKind, SignatureCheck};
use autoplug_live::demo::Demo;
use autoplug_live::driving::DriverDesk;
use autoplug_live::sources::{BusUrl, Transmitting};
use autoplug_live::watch::{StatusLine, TripLog, Watch};
use autoplug_store::{SqliteStore, TripStore};
use autoplug_tester::bus_tester::BusTester;
use autoplug_tester::bus_tester::Outbox;
use autoplug_tester::driver::{self, DriveError};
use autoplug_tester::names::{ecu_label, parse_ecu, ECUS, ECU_NAME_LIST};
use autoplug_tester::DEV_SECURITY_SECRET;
use autoplug_tester::{
    dtc_table, identification_table, vin_line, DtcJob, FlashConfig, FlashError, FlashJob, IdentJob,
    TesterConfig,
};
use autoplug_transport::{Transport, TransportError, Via};
use autoplug_virtual_car::console::ReaderMayLeave;
use autoplug_virtual_car::firmware::FirmwareChoice;
use autoplug_virtual_car::scenario::Scenario;
use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;

/// The `autoplug` command line.
#[derive(Debug, Parser)]
#[command(
    name = "autoplug",
    version,
    about = "AutoPlug middleware: sign firmware images, read ECU identification and flash ECUs over CAN (UDS on ISO-TP), replay and diagnose recorded logs",
    after_help = "Transports (--via): socketcand://HOST:PORT/BUS (the virtual car's --socketcand server, or socketcand next to a real bus), socketcan://IFACE (Linux SocketCAN, e.g. a USB-CAN adapter)."
)]
pub struct Cli {
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
// Parsed once per run: the size of the largest variant does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Generate an Ed25519 key pair for signing images: PATH.key (secret, mode 0600) and
    /// PATH.pub. Never overwrites.
    Keygen {
        /// Where to write, without extension (e.g. keys/dev).
        #[arg(long, value_name = "PATH")]
        out: PathBuf,
    },
    /// Build or inspect a signed image.
    #[command(subcommand)]
    Image(ImageCommand),
    /// Read the identification (part number F187, software F189, serial F18C, hardware
    /// F191, VIN F190, running slot and its state F1A0) of one ECU or all nine.
    Ids(ReadArgs),
    /// Read the trouble codes (UDS 0x19 02 FF) of one ECU or all nine, with their status
    /// and description.
    Dtcs(ReadArgs),
    /// Flash an image into an ECU over CAN, with a progress bar and a timing report.
    Flash {
        /// The bus: socketcand://HOST:PORT/BUS or socketcan://IFACE.
        #[arg(long, value_name = "URL", value_parser = parse_via)]
        via: Via,
        /// The ECU to flash: engine, pedals, steering, transmission (trans), cabin,
        /// console, differential (diff), cruise, abs.
        #[arg(long, value_name = "NAME", value_parser = parse_ecu_arg)]
        ecu: Node,
        /// The signed image file.
        #[arg(long, value_name = "FILE")]
        image: PathBuf,
        /// The SecurityAccess secret (the file's bytes, less a final newline); default:
        /// the development secret of the AutoPlug ECUs.
        #[arg(long, value_name = "FILE")]
        secret_file: Option<PathBuf>,
        /// Verify the image's signature with this public key before flashing.
        #[arg(long, value_name = "FILE.pub")]
        key: Option<PathBuf>,
        /// Seconds the ECU may take to answer again after its reset.
        #[arg(long, value_name = "SECONDS", default_value_t = 30.0, value_parser = parse_seconds)]
        reset_timeout: f64,
        /// UDS timing.
        #[command(flatten)]
        timing: TimingArgs,
    },
    /// Run the gateway on a recorded log (candump .log, Vector .asc or .blf): the car
    /// state, the bus statistics and every ECU's diagnosis, as on a live bus.
    Replay {
        /// The log file.
        #[arg(value_name = "LOG")]
        log: PathBuf,
        /// Pace the replay at this multiple of the log's own time (1 = as recorded);
        /// default: as fast as the machine goes.
        #[arg(long, value_name = "X", value_parser = parse_speed)]
        speed: Option<f64>,
        /// Skip malformed lines and count them, instead of stopping at the first.
        #[arg(long)]
        lenient: bool,
        /// Judge the ECUs even on a bus that is not an AutoPlug car.
        #[arg(long)]
        force: bool,
        /// Also store the log's trips in this database (SQLite).
        #[arg(long, value_name = "FILE")]
        db: Option<PathBuf>,
        /// The vehicle's name (a VIN) in the trip database.
        #[arg(long, value_name = "NAME", default_value = "local", requires = "db")]
        vehicle: String,
    },
    /// Watch a live bus: the car's state in the terminal, every ECU's diagnosis, the trips
    /// into the database and, with --record, all traffic into candump files. Runs until the
    /// bus ends (the virtual car's scenario), --duration passes, or Ctrl-C.
    Gateway {
        /// The bus: virtual:SCENARIO.toml (the virtual car in this process),
        /// socketcand://HOST:PORT/BUS or socketcan://IFACE.
        #[arg(long, value_name = "URL", value_parser = parse_bus)]
        bus: BusUrl,
        /// Record all traffic into this directory (candump .log files, flushed every 100 ms).
        #[arg(long, value_name = "DIR")]
        record: Option<PathBuf>,
        /// Start a new recording file after this many MB.
        #[arg(long, value_name = "MB", value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
        rotate_mb: Option<u64>,
        /// Start a new recording file after this many minutes of bus time.
        #[arg(long, value_name = "MINUTES", value_parser = clap::value_parser!(u64).range(1..=100_000))]
        rotate_minutes: Option<u64>,
        /// The trip database (SQLite; created if missing).
        #[arg(long, value_name = "FILE", default_value = "autoplug.db")]
        db: PathBuf,
        /// Keep no trips.
        #[arg(long, conflicts_with = "db")]
        no_db: bool,
        /// The vehicle's name in the trip database (default: the VIN its ECUs answer,
        /// F190, else `local`).
        #[arg(long, value_name = "NAME")]
        vehicle: Option<String>,
        /// Pace the virtual car at this multiple of real time (default 1).
        #[arg(long, value_name = "X", value_parser = parse_speed, conflicts_with = "fast")]
        speed: Option<f64>,
        /// Run the virtual car as fast as the machine goes.
        #[arg(long)]
        fast: bool,
        /// Stop after this many seconds (at most 30 days).
        #[arg(long, value_name = "SECONDS", value_parser = parse_duration)]
        duration: Option<f64>,
        /// No status line (the summary at the end is still printed).
        #[arg(long)]
        quiet: bool,
        /// Let the gateway transmit: it reads every ECU's identification at the start (into
        /// the inventory) and their trouble codes (UDS 0x19) then and every
        /// --dtc-interval. Without it the gateway only listens.
        #[arg(long)]
        transmit: bool,
        /// Seconds of bus time between two readings of the trouble codes.
        #[arg(long, value_name = "SECONDS", default_value_t = 60.0, value_parser = parse_seconds, requires = "transmit")]
        dtc_interval: f64,
        /// Serve the car's decoded signals live over WebSocket (ws://ADDR/api/stream, the
        /// dashboard's stream) on this address, e.g. 127.0.0.1:8080. Keep it on loopback
        /// unless the bus must be watched from elsewhere.
        #[arg(long, value_name = "ADDR")]
        web: Option<std::net::SocketAddr>,
        /// A browser origin besides the server's own that may open the stream
        /// (http://host:port); repeatable.
        #[arg(long = "web-origin", value_name = "ORIGIN", requires = "web")]
        web_origins: Vec<String>,
        /// A host name besides the listening address the web server answers for (NAME or
        /// NAME:PORT, as in the browser's address bar); repeatable. Other names are
        /// refused (421), so a web page cannot point its own name at this server.
        #[arg(long = "allowed-host", value_name = "NAME", requires = "web")]
        allowed_hosts: Vec<String>,
        /// The fleet this vehicle reports to (needs --transmit).
        #[command(flatten)]
        fleet: crate::fleet_cli::VehicleFleetArgs,
        /// ECUs of the virtual car that run as their firmware.
        #[command(flatten)]
        firmware: FirmwareArgs,
    },
    /// The dashboard (the main command): the virtual car in real time (or a live bus), the
    /// gateway on its bus, trips and recordings in a data folder, and the web dashboard on
    /// loopback. Prints the page's address with the write token; runs until Ctrl-C.
    Dashboard {
        /// The bus: virtual (the virtual car, standing until you drive it from the page),
        /// virtual:SCENARIO.toml, socketcand://HOST:PORT/BUS or socketcan://IFACE.
        #[arg(long, value_name = "URL", default_value = "virtual", value_parser = parse_bus)]
        bus: BusUrl,
        /// Replay this log instead of a bus (candump, ASC, BLF), with play, pause, speed
        /// and seek on the page.
        #[arg(long, value_name = "LOG", conflicts_with = "bus")]
        log: Option<PathBuf>,
        /// The data folder: trips.db, recordings/, images/ (created if missing).
        #[arg(long, value_name = "DIR", default_value = "autoplug-data")]
        data: PathBuf,
        /// Where the dashboard listens. Keep it on loopback unless others must reach it.
        #[arg(long, value_name = "ADDR", default_value = "127.0.0.1:8080")]
        listen: std::net::SocketAddr,
        /// The write token (default: a new random one; or AUTOPLUG_TOKEN).
        #[arg(
            long,
            value_name = "TOKEN",
            env = "AUTOPLUG_TOKEN",
            hide_env_values = true
        )]
        token: Option<String>,
        /// Only show: no write actions at all (no token).
        #[arg(long, conflicts_with = "token")]
        read_only: bool,
        /// A browser origin besides the server's own that may open the stream
        /// (http://host:port); repeatable.
        #[arg(long = "web-origin", value_name = "ORIGIN")]
        web_origins: Vec<String>,
        /// A host name besides the listening address the dashboard answers for (NAME or
        /// NAME:PORT, as in the browser's address bar); repeatable. Other names are
        /// refused (421), so a web page cannot point its own name at the dashboard.
        #[arg(long = "allowed-host", value_name = "NAME")]
        allowed_hosts: Vec<String>,
        /// On a real bus, let the gateway transmit (identification, trouble codes,
        /// flashing). The virtual car's gateway always may.
        #[arg(long)]
        transmit: bool,
        /// The vehicle's name in the trip database (default: the VIN its ECUs answer,
        /// F190, else `local`).
        #[arg(long, value_name = "NAME")]
        vehicle: Option<String>,
        /// Stop after this many seconds (at most 30 days).
        #[arg(long, value_name = "SECONDS", value_parser = parse_duration)]
        duration: Option<f64>,
        /// Also print the status line every second.
        #[arg(long)]
        status: bool,
        /// Stop when standard input closes (a replay dashboard started by another one
        /// ends with it).
        #[arg(long, hide = true)]
        exit_with_input: bool,
        /// The fleet this vehicle reports to; the driver answers its update offers on
        /// the page.
        #[command(flatten)]
        fleet: crate::fleet_cli::VehicleFleetArgs,
        /// ECUs of the virtual car that run as their firmware.
        #[command(flatten)]
        firmware: FirmwareArgs,
        /// Show the campaigns of this fleet database on the Fleet view (postgresql://...
        /// or a SQLite file): the manufacturer's side, read only.
        #[arg(long, value_name = "ADDRESS")]
        fleet_db: Option<String>,
    },
    /// The trips in the database.
    #[command(subcommand)]
    Trips(TripsCommand),
    /// The fleet: recall queries, update campaigns, the fleet service and the broker's
    /// configuration (PostgreSQL or SQLite, MQTT).
    #[command(subcommand)]
    Fleet(crate::fleet_cli::FleetCommand),
    /// Log files.
    #[command(subcommand)]
    Log(LogCommand),
    /// Judge every ECU from a recorded log: verdict (ok, not exercised, suspect, faulty, no data), number,
    /// unit, thresholds and evidence window; first, whether the bus is an AutoPlug car at
    /// all. Exit status 0 when no ECU is faulty, 3 when one is, 4 when the log could not be
    /// read to its end (what precedes the damage is judged), 5 when the bus is not an
    /// AutoPlug car and nothing was judged (1 for an error, 2 for a wrong command line).
    Diagnose {
        /// The log file (candump .log, Vector .asc or .blf).
        #[arg(value_name = "LOG")]
        log: PathBuf,
        /// Print JSON for scripts instead of the table.
        #[arg(long)]
        json: bool,
        /// Skip malformed lines and count them, instead of stopping at the first.
        #[arg(long)]
        lenient: bool,
        /// Judge the ECUs even on a bus that is not an AutoPlug car.
        #[arg(long)]
        force: bool,
    },
    /// Run one of the report's demonstrations on the virtual car, the flashing done over
    /// CAN by this tool: `cruise` (scenario 1, the broken cruise control) or `abs`
    /// (scenario 2, the broken ABS). Run from the repository root (it reads
    /// scenarios/demo-*.toml).
    Demo {
        /// Which demonstration: cruise or abs.
        #[arg(value_parser = parse_demo)]
        which: Demo,
        /// Also write the run's trace, bus log, summary and plots here.
        #[arg(long, value_name = "DIR")]
        out: Option<PathBuf>,
        /// ECUs of the virtual car that run as their firmware (the flashed one among
        /// them); the releases flashed then come from --images.
        #[command(flatten)]
        firmware: FirmwareArgs,
        /// With --firmware: the directory of the signed releases flashed,
        /// `<ecu>-1.1.0-faulty.img` and `<ecu>-1.2.0.img` (scripts/firmware-demo-images
        /// builds them).
        #[arg(long, value_name = "DIR", requires = "firmware")]
        images: Option<PathBuf>,
    },
}

fn parse_speed(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 && x <= 10_000.0 => Ok(x),
        _ => Err(format!("'{text}' is not a speed factor in (0, 10000]")),
    }
}

fn strictness(lenient: bool) -> autoplug_gateway::Strictness {
    if lenient {
        autoplug_gateway::Strictness::Lenient
    } else {
        autoplug_gateway::Strictness::Strict
    }
}

fn parse_demo(text: &str) -> Result<Demo, String> {
    match text {
        "cruise" => Ok(Demo::Cruise),
        "abs" => Ok(Demo::Abs),
        other => Err(format!("no demonstration '{other}': cruise or abs")),
    }
}

/// `trips` subcommands.
#[derive(Debug, Subcommand)]
pub enum TripsCommand {
    /// List the stored trips, newest first.
    List {
        /// The trip database.
        #[arg(long, value_name = "FILE", default_value = "autoplug.db")]
        db: PathBuf,
        /// Only this vehicle's trips.
        #[arg(long, value_name = "NAME")]
        vehicle: Option<String>,
        /// JSON for scripts.
        #[arg(long)]
        json: bool,
    },
    /// Show one trip: its statistics, verdicts and trouble codes.
    Show {
        /// The trip's number (from `trips list`).
        #[arg(value_name = "ID")]
        id: i64,
        /// The trip database.
        #[arg(long, value_name = "FILE", default_value = "autoplug.db")]
        db: PathBuf,
        /// JSON for scripts.
        #[arg(long)]
        json: bool,
    },
}

/// `log` subcommands.
#[derive(Debug, Subcommand)]
pub enum LogCommand {
    /// Convert a log (candump .log, Vector .asc or .blf) to Vector ASC, candump, or MCAP with
    /// the signals decoded.
    Export {
        /// The log to read.
        #[arg(value_name = "LOG")]
        log: PathBuf,
        /// The format to write.
        #[arg(long, value_enum, default_value_t = ExportFormat::Asc)]
        format: ExportFormat,
        /// The file to write (never overwritten).
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
        /// Skip malformed lines and count them, instead of stopping at the first.
        #[arg(long)]
        lenient: bool,
    },
}

/// `log export --format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExportFormat {
    /// Vector ASC (CANalyzer, CANoe, python-can, SavvyCAN).
    Asc,
    /// candump .log (can-utils, python-can, cantools).
    Candump,
    /// MCAP with every signal decoded (Foxglove, Lichtblick, PlotJuggler).
    Mcap,
}

fn parse_bus(text: &str) -> Result<BusUrl, String> {
    text.parse()
}

/// `image` subcommands.
#[derive(Debug, Subcommand)]
pub enum ImageCommand {
    /// Build a signed image from a raw binary or an ELF file, or a release for both slots
    /// (one image per slot, one file) from two ELF files.
    Build {
        /// The target ECU: engine, pedals, steering, transmission (trans), cabin, console,
        /// differential (diff), cruise, abs.
        #[arg(long, value_name = "NAME", value_parser = parse_ecu_arg)]
        ecu: Node,
        /// The software version, MAJOR.MINOR.PATCH.
        #[arg(long, value_name = "X.Y.Z", value_parser = parse_version)]
        version: Version,
        /// Standard software or the faulty demonstration.
        #[arg(long, value_enum, default_value_t = Variant::Standard)]
        variant: Variant,
        /// The part number (UDS F187), up to 16 printable ASCII characters.
        #[arg(long, value_name = "TEXT")]
        part_number: Option<String>,
        /// The build id, 32 hex digits; default: the first 16 bytes of the payload's
        /// SHA-256.
        #[arg(long, value_name = "HEX32", value_parser = parse_build_id)]
        build_id: Option<[u8; BUILD_ID_LEN]>,
        /// The application: a raw binary, or an ELF file linked for slot A (loadable
        /// segments from 0x08020200) or slot B (from 0x08040200). Give it twice, once per
        /// slot's build, for a release both slots can take.
        #[arg(long, value_name = "FILE", required = true)]
        payload: Vec<PathBuf>,
        /// The slot a raw binary is linked for (an ELF file says it itself).
        #[arg(long, value_enum)]
        slot: Option<SlotArg>,
        /// The secret key file to sign with ("dev": the development key, whose secret is
        /// public: for the virtual car and benches without their own keys).
        #[arg(long, value_name = "FILE.key")]
        key: PathBuf,
        /// The image file to write.
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
    },
    /// Show an image's header and sizes, and check its signature.
    Inspect {
        /// The image file.
        #[arg(value_name = "FILE")]
        file: PathBuf,
        /// The public key to check the signature with (a secret key file works too).
        #[arg(long, value_name = "FILE.pub")]
        key: Option<PathBuf>,
    },
}

/// `--slot`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum SlotArg {
    /// Slot A (sector 5, vector table at 0x08020200).
    A,
    /// Slot B (sector 6, vector table at 0x08040200).
    B,
}

impl From<SlotArg> for autoplug_image::ImageSlot {
    fn from(slot: SlotArg) -> Self {
        match slot {
            SlotArg::A => autoplug_image::ImageSlot::A,
            SlotArg::B => autoplug_image::ImageSlot::B,
        }
    }
}

/// `--variant`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum Variant {
    /// The ECU's normal software.
    Standard,
    /// The deliberately faulty demonstration software.
    Faulty,
}

impl From<Variant> for SoftwareVariant {
    fn from(variant: Variant) -> Self {
        match variant {
            Variant::Standard => SoftwareVariant::Standard,
            Variant::Faulty => SoftwareVariant::Faulty,
        }
    }
}

/// `--ecu NAME|all`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EcuSelection {
    /// The nine ECUs.
    All,
    /// One of them.
    One(Node),
}

impl EcuSelection {
    /// The ECUs selected.
    pub fn ecus(self) -> Vec<Node> {
        match self {
            EcuSelection::All => ECUS.to_vec(),
            EcuSelection::One(node) => vec![node],
        }
    }
}

/// What `ids` and `dtcs` read from, and whom.
#[derive(Debug, Clone, Args)]
pub struct ReadArgs {
    /// The bus: socketcand://HOST:PORT/BUS or socketcan://IFACE.
    #[arg(long, value_name = "URL", value_parser = parse_via)]
    pub via: Via,
    /// Which ECU (engine, pedals, steering, transmission, cabin, console, differential,
    /// cruise, abs), or all.
    #[arg(long, value_name = "NAME|all", default_value = "all", value_parser = parse_selection)]
    pub ecu: EcuSelection,
    /// UDS timing.
    #[command(flatten)]
    pub timing: TimingArgs,
}

/// UDS timing options (ISO 14229-2: the tester waits P2server + ΔP2 from its request's
/// transmission confirmation).
#[derive(Debug, Clone, Copy, Args)]
pub struct TimingArgs {
    /// P2server: how long the ECU may take to start its response, in ms (the AutoPlug ECUs
    /// announce 50).
    #[arg(long, value_name = "MS", default_value_t = 50, value_parser = clap::value_parser!(u64).range(1..=60_000))]
    pub p2_ms: u64,
    /// P2*server: the longest wait after each "response pending", in ms.
    #[arg(long, value_name = "MS", default_value_t = 5000, value_parser = clap::value_parser!(u64).range(1..=600_000))]
    pub p2_star_ms: u64,
    /// ΔP2: what the network adds to every wait, in ms (default: the transport's, 50 for
    /// socketcand, 10 for SocketCAN; more for a socketcand link over a slow network).
    #[arg(long, value_name = "MS", value_parser = clap::value_parser!(u64).range(0..=60_000))]
    pub network_delay_ms: Option<u64>,
}

impl TimingArgs {
    /// The tester configuration these options give.
    pub fn tester_config(self) -> TesterConfig {
        TesterConfig {
            p2_us: self.p2_ms * 1000,
            p2_star_us: self.p2_star_ms * 1000,
            // An ECU slow enough to need a longer P2 is as slow for functional answers.
            functional_window_us: TesterConfig::DEFAULT
                .functional_window_us
                .max(self.p2_ms * 1000),
            network_delay_us: self.network_delay_ms.map(|ms| ms * 1000),
            ..TesterConfig::DEFAULT
        }
    }
}

fn parse_via(text: &str) -> Result<Via, String> {
    text.parse()
        .map_err(|e: autoplug_transport::ViaError| e.to_string())
}

fn parse_ecu_arg(text: &str) -> Result<Node, String> {
    parse_ecu(text).map_err(|e| e.to_string())
}

fn parse_selection(text: &str) -> Result<EcuSelection, String> {
    if text.eq_ignore_ascii_case("all") {
        return Ok(EcuSelection::All);
    }
    parse_ecu(text)
        .map(EcuSelection::One)
        .map_err(|_| format!("unknown ECU '{text}': expected all or one of {ECU_NAME_LIST}"))
}

fn parse_version(text: &str) -> Result<Version, String> {
    text.parse()
        .map_err(|e: autoplug_image::ParseVersionError| format!("version '{text}': {e}"))
}

fn parse_build_id(text: &str) -> Result<[u8; BUILD_ID_LEN], String> {
    autoplug_image_tool::parse_build_id(text)
}

fn parse_duration(text: &str) -> Result<f64, String> {
    const MAX_S: f64 = 30.0 * 86_400.0;
    match text.parse::<f64>() {
        Ok(s) if s.is_finite() && s > 0.0 && s <= MAX_S => Ok(s),
        _ => Err(format!(
            "'{text}' is not a number of seconds in (0, {MAX_S}]"
        )),
    }
}

fn parse_seconds(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(s) if s.is_finite() && s > 0.0 && s <= 3600.0 => Ok(s),
        _ => Err(format!("'{text}' is not a number of seconds in (0, 3600]")),
    }
}

/// Why a command failed.
#[derive(Debug)]
pub enum CliError {
    /// A key, payload or image file.
    Image(ImageToolError),
    /// The transport.
    Transport(TransportError),
    /// The flash job (its report was written before).
    Flash(Box<FlashError>),
    /// The security secret file.
    Secret {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The image does not suit the ECU named on the command line.
    WrongImage(String),
    /// ECUs that were asked did not answer.
    NoAnswer(String),
    /// Writing the output failed.
    Output(io::Error),
    /// A demonstration could not run.
    Demo(String),
    /// A log could not be replayed.
    Log(String),
    /// A fleet command failed (database, broker, campaign).
    Fleet(String),
    /// The diagnosis judged at least one ECU faulty (exit status 3; the report was
    /// printed).
    FaultyEcu(String),
    /// The log could not be read to its end (exit status 4; what precedes the damage was
    /// reported, exported or judged).
    Incomplete(String),
    /// The bus is not an AutoPlug car: no ECU was judged (exit status 5).
    NotAutoPlug(String),
}

impl fmt::Display for CliError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CliError::Demo(why) => write!(f, "demonstration: {why}"),
            CliError::Log(why) | CliError::Fleet(why) => f.write_str(why),
            CliError::FaultyEcu(which) => write!(f, "faulty: {which}"),
            CliError::Incomplete(why) => write!(f, "incomplete: {why}"),
            CliError::NotAutoPlug(why) => write!(f, "not judged: {why}"),
            CliError::Image(error) => error.fmt(f),
            CliError::Transport(error) => error.fmt(f),
            CliError::Flash(error) => error.fmt(f),
            CliError::Secret { path, reason } => {
                write!(f, "security secret file '{}': {reason}", path.display())
            }
            CliError::WrongImage(reason) | CliError::NoAnswer(reason) => f.write_str(reason),
            CliError::Output(error) => write!(f, "cannot write the output: {error}"),
        }
    }
}

impl std::error::Error for CliError {}

impl From<ImageToolError> for CliError {
    fn from(error: ImageToolError) -> Self {
        CliError::Image(error)
    }
}

impl From<TransportError> for CliError {
    fn from(error: TransportError) -> Self {
        CliError::Transport(error)
    }
}

impl From<io::Error> for CliError {
    fn from(error: io::Error) -> Self {
        CliError::Output(error)
    }
}

/// Reads a security secret file: its bytes, less one final newline.
pub fn read_secret_file(path: &Path) -> Result<Vec<u8>, CliError> {
    let mut bytes = std::fs::read(path).map_err(|e| CliError::Secret {
        path: path.to_path_buf(),
        reason: format!("cannot read it: {e}"),
    })?;
    if bytes.ends_with(b"\r\n") {
        bytes.truncate(bytes.len() - 2);
    } else if bytes.ends_with(b"\n") {
        bytes.truncate(bytes.len() - 1);
    }
    if bytes.is_empty() {
        return Err(CliError::Secret {
            path: path.to_path_buf(),
            reason: "it is empty".into(),
        });
    }
    Ok(bytes)
}

/// Carries out a parsed command line; what it prints goes to `out` (the progress bar of
/// `flash` goes to the terminal's stderr).
pub fn run(cli: Cli, out: &mut dyn Write) -> Result<(), CliError> {
    match cli.command {
        Command::Keygen { out: path } => {
            let paths = autoplug_image_tool::keygen(&path)?;
            writeln!(
                out,
                "wrote {} (secret, keep it private) and {} (public, for the ECUs)",
                paths.secret.display(),
                paths.public.display()
            )?;
            Ok(())
        }
        Command::Image(ImageCommand::Build {
            ecu,
            version,
            variant,
            part_number,
            build_id,
            payload,
            slot,
            key,
            out: image,
        }) => {
            let options = BuildOptions {
                ecu,
                version,
                variant: variant.into(),
                part_number,
                build_id,
                payloads: payload,
                slot: slot.map(Into::into),
                key,
                out: image,
            };
            let built = autoplug_image_tool::build_image(&options)?;
            writeln!(
                out,
                "wrote {} ({} bytes, {} image(s))",
                options.out.display(),
                built.image_len,
                built.images.len()
            )?;
            for (header, kind) in &built.images {
                let kind = match kind {
                    PayloadKind::Raw => "raw binary".to_string(),
                    PayloadKind::Elf { segments } => {
                        format!("ELF, {segments} loadable segment(s)")
                    }
                };
                let slot = header.slot().map_or('?', |slot| slot.letter());
                writeln!(
                    out,
                    "slot {slot}: payload {} bytes from {kind}\n{header}",
                    header.payload_len,
                )?;
            }
            Ok(())
        }
        Command::Image(ImageCommand::Inspect { file, key }) => {
            let inspections = autoplug_image_tool::inspect_file(&file, key.as_deref())?;
            writeln!(out, "File:           {}", file.display())?;
            let mut problems = Vec::new();
            for (index, inspection) in inspections.iter().enumerate() {
                if inspections.len() > 1 {
                    writeln!(out, "--- image {} of {}", index + 1, inspections.len())?;
                }
                writeln!(out, "{inspection}")?;
                problems.extend(inspection.problems());
            }
            if !problems.is_empty() {
                return Err(ImageToolError::Corrupted {
                    path: file,
                    problems,
                }
                .into());
            }
            Ok(())
        }
        Command::Dtcs(ReadArgs { via, ecu, timing }) => {
            let (reports, transport) =
                run_reading(&via, DtcJob::new(&ecu.ecus(), timing.tester_config()))?;
            write!(out, "{}", dtc_table(&reports))?;
            if reports.iter().all(|r| r.entries.is_err()) {
                return Err(CliError::NoAnswer(format!(
                    "no ECU answered on {}: is the bus the right one, and are the ECUs powered?",
                    transport.describe()
                )));
            }
            Ok(())
        }
        Command::Ids(ReadArgs { via, ecu, timing }) => {
            let (rows, transport) =
                run_reading(&via, IdentJob::new(&ecu.ecus(), timing.tester_config()))?;
            write!(out, "{}", identification_table(&rows))?;
            writeln!(out, "{}", vin_line(&rows))?;
            let silent: Vec<String> = rows
                .iter()
                .filter(|r| !r.answered())
                .map(|r| ecu_label(r.ecu))
                .collect();
            if silent.len() == rows.len() {
                return Err(CliError::NoAnswer(format!(
                    "no ECU answered on {} ({}): is the bus the right one, and are the ECUs powered?",
                    transport.describe(),
                    silent.join(", ")
                )));
            }
            Ok(())
        }
        Command::Flash {
            via,
            ecu,
            image,
            secret_file,
            key,
            reset_timeout,
            timing,
        } => flash(
            &via,
            ecu,
            &image,
            secret_file.as_deref(),
            key.as_deref(),
            reset_timeout,
            timing,
            out,
        ),
        Command::Demo {
            which,
            out: dir,
            firmware,
            images,
        } => {
            let on_firmware = match &firmware.firmware {
                None => None,
                Some(list) => Some(demo_on_firmware(
                    which,
                    FirmwareChoice::parse(list, &firmware.firmware_dir).map_err(CliError::Demo)?,
                    images.as_deref(),
                )?),
            };
            demo(which, dir.as_deref(), on_firmware.as_ref(), out)
        }
        Command::Replay {
            log,
            speed,
            lenient,
            force,
            db,
            vehicle,
        } => {
            let trip_log = match db {
                Some(db) => Some(open_trip_log(&db, &vehicle, &log.display().to_string())?),
                None => None,
            };
            let run = autoplug_live::gateway::run_log(&log, strictness(lenient), speed, trip_log)
                .map_err(CliError::Log)?;
            let state = run.pipeline.state();
            writeln!(out, "{}", log.display())?;
            autoplug_live::gateway::bus_summary(&run, out)?;
            writeln!(out)?;
            autoplug_live::gateway::signal_table(state, out)?;
            writeln!(out)?;
            if run.recognition.autoplug || force {
                autoplug_live::gateway::verdict_table(&run.diagnoses, out)?;
            } else {
                writeln!(out, "no ECU judged: {}", not_judged(&run))?;
            }
            autoplug_live::gateway::heard_dtcs(&run.dtcs, out)?;
            writeln!(out)?;
            autoplug_live::gateway::trips_table(&run.trips, out)?;
            if let Some(trip_log) = &run.trip_log {
                report_trip_log(trip_log, out)?;
            }
            match incomplete(&log, &run) {
                Some(why) => Err(CliError::Incomplete(why)),
                None => Ok(()),
            }
        }
        Command::Gateway {
            bus,
            record,
            rotate_mb,
            rotate_minutes,
            db,
            no_db,
            vehicle,
            speed,
            fast,
            duration,
            quiet,
            transmit,
            dtc_interval,
            web,
            web_origins,
            allowed_hosts,
            fleet,
            firmware,
        } => {
            let options = GatewayOptions {
                firmware: firmware.choice(&bus)?,
                transmit: transmit.then_some((dtc_interval * 1e6) as u64),
                record,
                rotate: autoplug_logs::RotatePolicy {
                    max_bytes: rotate_mb.map(|mb| mb * 1_000_000),
                    max_duration_us: rotate_minutes.map(|m| m * 60_000_000),
                },
                vehicle,
                speed,
                fast,
                duration,
                quiet,
                web: web.map(|addr| autoplug_web::WebConfig {
                    addr,
                    allowed_origins: web_origins,
                    allowed_hosts,
                    ..autoplug_web::WebConfig::loopback(0)
                }),
                recordings_dir: None,
                replay_pages: None,
                fleet: fleet
                    .config((!no_db).then(|| db.with_file_name("fleet-state.json")))
                    .map_err(CliError::Fleet)?,
                db: (!no_db).then_some(db),
            };
            gateway(&bus, options, out)
        }
        Command::Dashboard {
            bus,
            log,
            data,
            listen,
            token,
            read_only,
            web_origins,
            allowed_hosts,
            transmit,
            vehicle,
            duration,
            status,
            exit_with_input,
            fleet,
            fleet_db,
            firmware,
        } => {
            if exit_with_input {
                // Reads until the other end closes (the parent ended, however it ended).
                std::thread::spawn(|| {
                    let _ = io::copy(&mut io::stdin().lock(), &mut io::sink());
                    EXIT_WITH_INPUT.store(true, Ordering::SeqCst);
                });
            }
            let folder =
                autoplug_dashboard::dashboard::DataFolder::prepare(&data).map_err(CliError::Log)?;
            let bus = log.map_or(bus, BusUrl::Replay);
            let virtual_car = matches!(bus, BusUrl::Virtual(_) | BusUrl::Dashboard);
            let firmware = firmware.choice(&bus)?;
            if virtual_car {
                let emulated = firmware.as_ref().map_or(&[][..], |c| &c.ecus[..]);
                for name in folder.add_demo_images(emulated).map_err(CliError::Log)? {
                    writeln!(out, "firmware library: added {name}")?;
                }
                // The ECUs run as firmware: what they need, built from this checkout if
                // missing (nothing to prepare by hand). A build that fails is said; the
                // car then reports the missing ELF, the library the missing release.
                let cwd = std::env::current_dir().map_err(|e| CliError::Log(e.to_string()))?;
                let default_dir = Path::new(autoplug_virtual_car::firmware::DEFAULT_FIRMWARE_DIR);
                if let (Some(choice), Some(build)) = (
                    firmware.as_ref().filter(|c| c.dir == default_dir),
                    autoplug_dashboard::dashboard::FirmwareBuild::at(&cwd),
                ) {
                    let names: Vec<&str> = choice.ecus.iter().map(|n| n.name()).collect();
                    writeln!(
                        out,
                        "firmware: building what is missing of {} in {}",
                        names.join(", "),
                        choice.dir.display()
                    )?;
                    out.flush()?;
                    match build.firmware(&choice.ecus, &choice.dir) {
                        Ok(built) if built.is_empty() => {}
                        Ok(built) => writeln!(out, "firmware: built {}", built.join(", "))?,
                        Err(e) => writeln!(out, "firmware: {e}")?,
                    }
                    if choice.dir.join("boot").is_file() {
                        match build.demo_releases(&choice.ecus, &folder) {
                            Ok(written) => {
                                for name in written {
                                    writeln!(out, "firmware library: built {name} (scripts/firmware-demo-images, the development key)")?;
                                }
                            }
                            Err(e) => writeln!(out, "firmware library: {e}")?,
                        }
                    }
                }
                for (ecu, variant, version) in autoplug_dashboard::dashboard::DEMO_IMAGES {
                    let name =
                        autoplug_dashboard::dashboard::demo_image_name(ecu, variant, version);
                    if emulated.contains(&ecu) && !folder.images().join(&name).exists() {
                        writeln!(
                            out,
                            "firmware library: no {name}; {} runs its firmware: put its signed releases there (scripts/firmware-demo-images {})",
                            ecu.name(),
                            folder.images().display()
                        )?;
                    }
                }
            }
            let token = match (token, read_only) {
                (_, true) => None,
                (Some(token), false) => {
                    autoplug_dashboard::dashboard::check_token(&token).map_err(CliError::Log)?;
                    Some(token)
                }
                (None, false) => {
                    Some(autoplug_dashboard::dashboard::new_token().map_err(CliError::Log)?)
                }
            };
            let fleet_page = match fleet_db {
                Some(address) => {
                    let page = autoplug_dashboard::fleet_page::FleetPage::open(&address)
                        .map_err(CliError::Fleet)?;
                    writeln!(out, "fleet page: campaigns of {}", page.name())?;
                    Some(std::sync::Arc::new(page) as std::sync::Arc<dyn autoplug_web::FleetData>)
                }
                None => None,
            };
            let options = GatewayOptions {
                firmware,
                transmit: (virtual_car || (transmit && matches!(bus, BusUrl::Transport(_))))
                    .then_some(60_000_000),
                record: None,
                rotate: autoplug_logs::RotatePolicy::default(),
                db: Some(folder.trips_db()),
                vehicle,
                speed: None,
                fast: false,
                duration,
                quiet: !status,
                replay_pages: (!matches!(bus, BusUrl::Replay(_))).then(|| {
                    autoplug_dashboard::dashboard::ReplayPages::new(
                        listen.ip(),
                        data.clone(),
                        token.clone(),
                        &allowed_hosts,
                    )
                }),
                web: Some(autoplug_web::WebConfig {
                    addr: listen,
                    allowed_origins: web_origins,
                    allowed_hosts,
                    token,
                    trips_db: Some(folder.trips_db()),
                    recordings_dir: Some(folder.recordings()),
                    images_dir: Some(folder.images()),
                    fleet: fleet_page,
                    ..autoplug_web::WebConfig::loopback(0)
                }),
                recordings_dir: Some(folder.recordings()),
                fleet: fleet
                    .config(Some(folder.root.join("fleet-state.json")))
                    .map_err(CliError::Fleet)?,
            };
            gateway(&bus, options, out)
        }
        Command::Fleet(command) => crate::fleet_cli::run(command, out).map_err(CliError::Fleet),
        Command::Trips(TripsCommand::List { db, vehicle, json }) => {
            let store = open_existing_store(&db)?;
            let rows = store
                .trips(vehicle.as_deref())
                .map_err(|e| CliError::Log(e.to_string()))?;
            if json {
                let text = serde_json::to_string_pretty(&rows)
                    .map_err(|e| CliError::Log(e.to_string()))?;
                writeln!(out, "{text}")?;
            } else if rows.is_empty() {
                writeln!(out, "no trips in {}", db.display())?;
            } else {
                autoplug_live::gateway::stored_trips_table(&rows, out)?;
            }
            Ok(())
        }
        Command::Trips(TripsCommand::Show { id, db, json }) => {
            let store = open_existing_store(&db)?;
            let detail = store
                .trip(autoplug_store::TripId(id))
                .map_err(|e| CliError::Log(e.to_string()))?
                .ok_or_else(|| CliError::Log(format!("{}: there is no trip {id}", db.display())))?;
            if json {
                let text = serde_json::to_string_pretty(&detail)
                    .map_err(|e| CliError::Log(e.to_string()))?;
                writeln!(out, "{text}")?;
            } else {
                autoplug_live::gateway::trip_detail(&detail, out)?;
            }
            Ok(())
        }
        Command::Log(LogCommand::Export {
            log,
            format,
            out: file,
            lenient,
        }) => export_log(&log, format, &file, lenient, out),
        Command::Diagnose {
            log,
            json,
            lenient,
            force,
        } => {
            let run = autoplug_live::gateway::run_log(&log, strictness(lenient), None, None)
                .map_err(CliError::Log)?;
            let judged = run.recognition.autoplug || force;
            if json {
                writeln!(
                    out,
                    "{}",
                    autoplug_live::gateway::verdict_json(&log, &run, judged)
                )?;
            } else {
                writeln!(out, "bus: {}", run.recognition.summary())?;
                if judged {
                    autoplug_live::gateway::verdict_table(&run.diagnoses, out)?;
                }
                if let Some(first) = run.pipeline.first_malformed() {
                    writeln!(
                        out,
                        "{} malformed line(s) skipped, the first: {first}",
                        run.pipeline.malformed()
                    )?;
                }
                if run.pipeline.dropped_by_logger() > 0 {
                    writeln!(
                        out,
                        "{} frame(s) dropped by the logger (its DROPCOUNT lines)",
                        run.pipeline.dropped_by_logger()
                    )?;
                }
            }
            let faulty: Vec<&str> = run
                .diagnoses
                .iter()
                .filter(|d| judged && d.verdict == autoplug_diagnostics::Verdict::Faulty)
                .map(|d| autoplug_tester::names::ecu_name(d.ecu))
                .collect();
            let incomplete = incomplete(&log, &run);
            // A fault found in part of a log stays a fault: 3 before 4.
            match (faulty.is_empty(), incomplete) {
                (false, None) => Err(CliError::FaultyEcu(faulty.join(", "))),
                (false, Some(why)) => Err(CliError::FaultyEcu(format!(
                    "{} (in an incomplete log: {why})",
                    faulty.join(", ")
                ))),
                (true, Some(why)) => Err(CliError::Incomplete(why)),
                (true, None) if !judged => Err(CliError::NotAutoPlug(format!(
                    "{}: not an AutoPlug car, no ECU judged (--force judges it anyway)",
                    log.display()
                ))),
                (true, None) => Ok(()),
            }
        }
    }
}

/// Why a log run's report covers only part of the log, if it does.
fn incomplete(log: &Path, run: &autoplug_live::gateway::LogRun) -> Option<String> {
    run.pipeline.incomplete().map(|e| {
        format!(
            "{}: {e} (the report covers the {} frames before it)",
            log.display(),
            run.pipeline.state().counters().frames
        )
    })
}

/// Why the ECUs of a log were not judged.
fn not_judged(run: &autoplug_live::gateway::LogRun) -> String {
    format!(
        "the bus is {} (--force judges it anyway)",
        run.recognition.summary()
    )
}

/// Runs a job that only reads (identification, DTCs: it cannot fail as a whole) over the
/// bus `via` names; gives its result and the transport, for messages.
fn run_reading<J>(via: &Via, mut job: J) -> Result<(J::Output, Box<dyn Transport>), CliError>
where
    J: autoplug_tester::Job<Error = std::convert::Infallible>,
{
    let mut transport = autoplug_transport::open(via)?;
    match driver::run(transport.as_mut(), &mut job) {
        Ok(output) => Ok((output, transport)),
        Err(DriveError::Transport(error)) => Err(error.into()),
        Err(DriveError::Job(never)) => match never {},
    }
}

/// Opens (or creates) the trip database for a run.
fn open_trip_log(db: &Path, vehicle: &str, source: &str) -> Result<TripLog, CliError> {
    let store = SqliteStore::open(db).map_err(|e| CliError::Log(e.to_string()))?;
    Ok(TripLog::new(Box::new(store), vehicle, source))
}

/// Opens a trip database that must exist (the read commands never create one).
fn open_existing_store(db: &Path) -> Result<SqliteStore, CliError> {
    if !db.exists() {
        return Err(CliError::Log(format!(
            "{}: no such trip database (the gateway creates it: autoplug gateway --db FILE)",
            db.display()
        )));
    }
    SqliteStore::open(db).map_err(|e| CliError::Log(e.to_string()))
}

fn report_trip_log(trip_log: &TripLog, out: &mut dyn Write) -> Result<(), CliError> {
    if !trip_log.stored.is_empty() {
        let ids: Vec<String> = trip_log.stored.iter().map(|id| id.to_string()).collect();
        writeln!(out, "stored trip(s) {} ", ids.join(", "))?;
    }
    if let Some(failure) = &trip_log.failure {
        writeln!(out, "{failure}")?;
    }
    Ok(())
}

/// What `autoplug gateway` was asked to do besides watching.
struct GatewayOptions {
    /// May transmit, reading the DTCs this often (µs of bus time).
    transmit: Option<u64>,
    record: Option<PathBuf>,
    rotate: autoplug_logs::RotatePolicy,
    db: Option<PathBuf>,
    /// `None`: the VIN the ECUs answer, else `local`.
    vehicle: Option<String>,
    speed: Option<f64>,
    fast: bool,
    duration: Option<f64>,
    quiet: bool,
    /// Serve the dashboard.
    web: Option<autoplug_web::WebConfig>,
    /// Where the dashboard's recordings go (`record` starts one at once).
    recordings_dir: Option<PathBuf>,
    /// Recordings may be opened in replay dashboards of their own.
    replay_pages: Option<autoplug_dashboard::dashboard::ReplayPages>,
    /// Report to a fleet (needs `transmit`).
    fleet: Option<autoplug_fleet_agent::link::FleetConfig>,
    /// ECUs of the virtual car that run as their firmware on emulated MCUs.
    firmware: Option<FirmwareChoice>,
}

/// `--firmware`: ECUs of the virtual car that run as their firmware.
#[derive(Debug, clap::Args, Clone)]
pub struct FirmwareArgs {
    /// Run these ECUs of the virtual car as their firmware (the release ELF and the
    /// bootloader) on emulated STM32F446s instead of host logic: `all`, or names separated
    /// by commas (cruise,abs).
    #[arg(long, value_name = "all|ECU,...")]
    firmware: Option<String>,
    /// Where the firmware ELF files are: `boot` and `<ecu>-fw`.
    #[arg(
        long,
        value_name = "DIR",
        default_value = autoplug_virtual_car::firmware::DEFAULT_FIRMWARE_DIR,
        requires = "firmware"
    )]
    firmware_dir: PathBuf,
}

impl FirmwareArgs {
    /// The choice, for a bus that is the virtual car.
    fn choice(&self, bus: &BusUrl) -> Result<Option<FirmwareChoice>, CliError> {
        let Some(list) = &self.firmware else {
            return Ok(None);
        };
        if !matches!(bus, BusUrl::Virtual(_) | BusUrl::Dashboard) {
            return Err(CliError::Log(
                "--firmware runs ECUs of the virtual car: the bus is not the virtual car".into(),
            ));
        }
        FirmwareChoice::parse(list, &self.firmware_dir)
            .map(Some)
            .map_err(CliError::Log)
    }
}

/// Set by Ctrl-C: the live gateway stops at the next frame or idle moment.
static STOP: AtomicBool = AtomicBool::new(false);
/// Set when standard input closes, for `dashboard --exit-with-input`.
static EXIT_WITH_INPUT: AtomicBool = AtomicBool::new(false);

fn gateway(bus: &BusUrl, options: GatewayOptions, out: &mut dyn Write) -> Result<(), CliError> {
    let pace = match bus {
        BusUrl::Virtual(_) | BusUrl::Dashboard if options.fast => None,
        BusUrl::Virtual(_) | BusUrl::Dashboard => Some(options.speed.unwrap_or(1.0)),
        BusUrl::Transport(_) if options.fast || options.speed.is_some() => {
            return Err(CliError::Log(
                "--speed and --fast pace the virtual car only: a real bus goes at its own pace"
                    .into(),
            ))
        }
        BusUrl::Transport(_) => None,
        // The dashboard's player paces itself (--speed sets where it starts).
        BusUrl::Replay(_) if options.web.is_some() => None,
        BusUrl::Replay(_) if options.fast => None,
        BusUrl::Replay(_) => Some(options.speed.unwrap_or(1.0)),
    };
    // With the dashboard, a person may drive the virtual car.
    let desk = match (bus, &options.web) {
        (BusUrl::Virtual(_) | BusUrl::Dashboard, Some(_)) => {
            Some(Rc::new(RefCell::new(DriverDesk::new())))
        }
        _ => None,
    };
    // The dashboard's live table, before the source: the virtual car publishes its world
    // beside it.
    let table = options
        .web
        .as_ref()
        .map(|_| std::sync::Arc::new(autoplug_web::LiveTable::new()));
    let mut replay_desk = None;
    let mut source = match (bus, &options.web) {
        (BusUrl::Replay(path), Some(_)) => {
            let (first_us, last_us) =
                autoplug_live::replay::log_span(path).map_err(CliError::Log)?;
            let mut player =
                autoplug_live::replay::ReplayDesk::new((last_us - first_us) as f64 * 1e-6);
            player.speed = options.speed.unwrap_or(1.0);
            let player = Rc::new(RefCell::new(player));
            replay_desk = Some(player.clone());
            let mut source = autoplug_live::replay::ControlledReplay::open(path, first_us, player)
                .map_err(|e| CliError::Log(e.to_string()))?;
            if let Some(table) = &table {
                // A recording of the virtual car shows its world too; without a world
                // file the replay shows the bus alone.
                match source.with_world(world_feed(table.world().clone())) {
                    Ok(None) | Err(_) => {}
                    Ok(Some(damage)) => {
                        writeln!(out, "world file damaged, played up to the damage: {damage}")?
                    }
                }
            }
            Box::new(source) as Box<dyn autoplug_gateway::FrameSource>
        }
        _ => bus
            .open(
                pace,
                desk.clone(),
                options.firmware.as_ref(),
                table.as_ref().map(|t| world_publisher(t.world().clone())),
            )
            .map_err(CliError::Log)?,
    };
    let replaying = matches!(bus, BusUrl::Replay(_));
    if replaying && options.transmit.is_some() {
        return Err(CliError::Log(
            "a recorded log cannot be transmitted to: --transmit is for a live bus".into(),
        ));
    }
    if options.fleet.is_some() && options.transmit.is_none() {
        return Err(CliError::Log(
            "--fleet needs --transmit: the gateway reads the VIN and flashes the fleet's updates over the bus".into(),
        ));
    }
    let mut tester = None;
    if let Some(dtc_interval_us) = options.transmit {
        let outbox: Outbox = Rc::new(RefCell::new(VecDeque::new()));
        source = Box::new(Transmitting::new(source, Rc::clone(&outbox)));
        tester = Some(BusTester::new(
            &ECUS,
            TesterConfig::DEFAULT,
            outbox,
            dtc_interval_us,
        ));
    }
    let trip_log = match &options.db {
        // A replay in the dashboard jumps about: its trips are not the drive's.
        Some(_) if replaying && options.web.is_some() => None,
        Some(db) => Some(match &options.vehicle {
            Some(vehicle) => open_trip_log(db, vehicle, &source.describe())?,
            None if options.transmit.is_some() => {
                open_trip_log(db, "local", &source.describe())?.following_vin()
            }
            None => open_trip_log(db, "local", &source.describe())?,
        }),
        None => None,
    };
    if let Some(dir) = &options.record {
        std::fs::create_dir_all(dir).map_err(|e| {
            CliError::Log(format!(
                "cannot create the recording directory '{}': {e}",
                dir.display()
            ))
        })?;
    }
    // A second handler cannot be set (a test running several gateways): Ctrl-C then stops
    // the first one's way, through the same flag.
    STOP.store(false, Ordering::SeqCst);
    let _ = ctrlc::set_handler(|| STOP.store(true, Ordering::SeqCst));
    writeln!(
        out,
        "gateway on {}{}{} (Ctrl-C stops)",
        source.describe(),
        options.record.as_ref().map_or(String::new(), |d| format!(
            ", recording into {}",
            d.display()
        )),
        match (&trip_log, &options.db) {
            (Some(_), Some(d)) => format!(", trips into {}", d.display()),
            _ => String::new(),
        }
    )?;
    let deadline = options
        .duration
        .map(|s| Instant::now() + Duration::from_secs_f64(s));
    // A viewer goes on past a bad line of a recording (and counts it); a live bus has none.
    let strictness = if replaying && options.web.is_some() {
        Strictness::Lenient
    } else {
        Strictness::Strict
    };
    let mut pipeline = Pipeline::new(strictness);
    let mut status_out = io::stderr();
    let mut watch = Watch::new(trip_log);
    watch.tester = tester;
    // The broker connection's tasks run here; the pipeline only trades messages with them.
    let fleet_runtime = match &options.fleet {
        Some(_) => Some(crate::fleet_cli::mqtt_runtime().map_err(CliError::Fleet)?),
        None => None,
    };
    if let (Some(config), Some(runtime)) = (options.fleet.clone(), &fleet_runtime) {
        writeln!(out, "reporting to the fleet at {}", config.broker)?;
        watch.fleet = Some(autoplug_fleet_agent::link::FleetLink::new(
            config,
            runtime.handle().clone(),
        ));
    }
    if let BusUrl::Transport(_) = bus {
        watch.silent_after = Some(autoplug_live::watch::LIVE_SILENCE);
    }
    if !options.quiet {
        watch.status = Some(StatusLine::new(&mut status_out, Duration::from_secs(1)));
    }
    let mut stop = || {
        STOP.load(Ordering::SeqCst)
            || EXIT_WITH_INPUT.load(Ordering::SeqCst)
            || deadline.is_some_and(|d| Instant::now() >= d)
    };
    let (result, mut watch, recorded) = match options.web {
        Some(config) => {
            // The dashboard: the session takes the watch, the recording and the commands.
            let table = table
                .clone()
                .unwrap_or_else(|| std::sync::Arc::new(autoplug_web::LiveTable::new()));
            let (control, commands) = autoplug_web::control::channel();
            let token = config.token.clone();
            let server = autoplug_web::WebServer::start(config, table.clone(), Some(control))
                .map_err(|e| CliError::Log(e.to_string()))?;
            let page = match &token {
                Some(token) => format!("http://{}/#token={token}", server.addr()),
                None => format!("http://{}/ (read only: no token)", server.addr()),
            };
            writeln!(out, "dashboard on {page}")?;
            writeln!(out, "live stream on ws://{}/api/stream", server.addr())?;
            out.flush()?;
            let kind = match bus {
                BusUrl::Virtual(_) | BusUrl::Dashboard => SourceKind::Virtual,
                BusUrl::Transport(_) => SourceKind::Bus,
                BusUrl::Replay(_) => SourceKind::Replay,
            };
            let mut session = Session::new(watch, table, commands, kind, source.describe());
            if let Some(choice) = &options.firmware {
                session = session.with_firmware_ecus(&choice.ecus);
            }
            if let Some(desk) = desk {
                session = session.with_desk(desk);
            }
            if let Some(player) = &replay_desk {
                session = session.with_replay(player.clone());
            }
            if let Some(pages) = options.replay_pages {
                session = session.with_replay_pages(pages);
            }
            if let Some(dir) = options.recordings_dir.clone().or(options.record.clone()) {
                session = session.with_recordings(dir, options.rotate);
            }
            if options.record.is_some() {
                session.start_recording().map_err(CliError::Log)?;
            }
            let seeks = || replay_desk.as_ref().map_or(0, |d| d.borrow().seeks);
            let mut handled = seeks();
            let result = loop {
                let result = pipeline.run(source.as_mut(), &mut [&mut session], &mut || {
                    stop() || seeks() != handled
                });
                if result.is_err() || seeks() == handled || stop() {
                    break result;
                }
                // The player jumps at its next poll: the analysis starts over from there.
                handled = seeks();
                pipeline = Pipeline::new(strictness);
                session.restart_analysis();
            };
            let recorded = session.stop_recording();
            drop(server);
            (result, session.watch, recorded)
        }
        None => {
            let mut recording = match &options.record {
                Some(dir) => {
                    let recorder = autoplug_logs::Recorder::start(dir, "gateway", options.rotate)
                        .map_err(|e| CliError::Log(e.to_string()))?;
                    Some(RecordingSink::new(recorder))
                }
                None => None,
            };
            let result = {
                let mut observers: Vec<&mut dyn Observer> = vec![&mut watch];
                if let Some(sink) = recording.as_mut() {
                    observers.push(sink);
                }
                pipeline.run(source.as_mut(), &mut observers, &mut stop)
            };
            let recorded = match recording.as_mut() {
                Some(sink) => {
                    if let Some(failure) = sink.failure() {
                        writeln!(out, "{failure}")?;
                    }
                    let summary = sink.stop().map_err(|e| CliError::Log(e.to_string()))?;
                    for file in &summary.files {
                        writeln!(out, "recorded {}", file.display())?;
                    }
                    Some(format!(
                        "recording: {} frames, {} bytes in {} file(s)",
                        summary.frames,
                        summary.bytes,
                        summary.files.len()
                    ))
                }
                None => None,
            };
            (result, watch, recorded)
        }
    };
    watch.status = None;
    watch.finish(pipeline.state());
    if let Some(recorded) = recorded {
        writeln!(out, "{recorded}")?;
    }
    let state = pipeline.state();
    writeln!(
        out,
        "{} frames, {:.1} s of bus time",
        state.counters().frames,
        state.now_us() as f64 * 1e-6
    )?;
    autoplug_live::gateway::trips_table(&watch.ended, out)?;
    if let Some(trip_log) = &watch.trip_log {
        report_trip_log(trip_log, out)?;
    }
    autoplug_live::gateway::verdict_table(&watch.diagnostics.report(state), out)?;
    if let Some(rows) = &watch.identification {
        write!(out, "{}", identification_table(rows))?;
        writeln!(out, "{}", vin_line(rows))?;
    }
    autoplug_live::gateway::heard_dtcs(&watch.dtcs, out)?;
    if let Some(fleet) = watch.fleet.take() {
        let (vin, not_connected, broker) =
            (fleet.vin(), fleet.not_connected.clone(), fleet.broker());
        let reports = fleet.campaign_reports();
        // The last trip's report goes out before the connection closes.
        let closed = fleet.close(Duration::from_secs(5));
        fleet_summary(vin, not_connected, &broker, &reports, closed, out)?;
    }
    drop(fleet_runtime);
    result.map_err(|e| CliError::Log(e.to_string()))?;
    match pipeline.incomplete() {
        Some(e) => Err(CliError::Incomplete(format!("{}: {e}", source.describe()))),
        None => Ok(()),
    }
}

/// The fleet link at the end of a run: where it reported, what the fleet confirmed, the
/// campaigns.
fn fleet_summary(
    vin: Option<String>,
    not_connected: Option<String>,
    broker: &str,
    reports: &[autoplug_fleet::campaign::CampaignReport],
    closed: autoplug_fleet_agent::link::Closed,
    out: &mut dyn Write,
) -> io::Result<()> {
    match (&vin, &not_connected) {
        (_, Some(why)) => writeln!(out, "fleet: {why}")?,
        (Some(vin), None) => writeln!(
            out,
            "fleet: reported as {vin} to {broker}; {} report(s) confirmed stored by the fleet, {} refused, {} published without a receipt yet (the broker holds them), {} not published, {} dropped",
            closed.stored, closed.refused, closed.unconfirmed, closed.unsent, closed.dropped
        )?,
        (None, None) => {}
    }
    for report in reports {
        writeln!(
            out,
            "fleet: campaign {} ({}): {}{}, running {}",
            report.campaign,
            report.ecu,
            report.state.name(),
            report
                .reason
                .as_deref()
                .map_or(String::new(), |r| format!(" ({r})")),
            report.version_running.as_deref().unwrap_or("?")
        )?;
    }
    Ok(())
}

/// `autoplug log export`: written to FILE.partial and renamed when complete, so a failed
/// or refused export never leaves a half-written file under the name asked for.
fn export_log(
    log: &Path,
    format: ExportFormat,
    file: &Path,
    lenient: bool,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    if file.exists() {
        return Err(CliError::Log(format!(
            "{}: already exists (not overwritten)",
            file.display()
        )));
    }
    let mut reader = autoplug_logs::open(log).map_err(|e| CliError::Log(e.to_string()))?;
    let mut partial = file.as_os_str().to_owned();
    partial.push(".partial");
    let partial = PathBuf::from(partial);
    let output = std::fs::File::create(&partial)
        .map_err(|e| CliError::Log(format!("cannot create {}: {e}", partial.display())))?;
    let writer = io::BufWriter::new(output);
    let mut decoded = None;
    let result = match format {
        ExportFormat::Asc => autoplug_logs::export_asc(&mut reader, writer),
        ExportFormat::Candump => autoplug_logs::write::export_candump(&mut reader, writer, false),
        ExportFormat::Mcap => autoplug_logs::export_mcap(&mut reader, writer).map(|s| {
            decoded = Some((s.decoded, s.undecodable));
            s.export
        }),
    };
    let dropped = reader.dropped_frames();
    let fail = |message: String| {
        let _ = std::fs::remove_file(&partial);
        CliError::Log(message)
    };
    let summary = result.map_err(|e| fail(format!("{}: {e}", log.display())))?;
    if let (false, Some(first)) = (lenient, &summary.first_skipped) {
        return Err(fail(format!(
            "{first} (use --lenient to skip malformed lines and count them)"
        )));
    }
    std::fs::rename(&partial, file)
        .map_err(|e| fail(format!("cannot write {}: {e}", file.display())))?;
    writeln!(
        out,
        "wrote {} ({} frames{}{})",
        file.display(),
        summary.frames,
        decoded.map_or(String::new(), |(ok, bad)| format!(
            ", {ok} decoded into their messages' channels{}",
            if bad > 0 {
                format!(", {bad} not decodable (raw only)")
            } else {
                String::new()
            }
        )),
        if summary.skipped > 0 {
            format!(", {} malformed line(s) skipped", summary.skipped)
        } else {
            String::new()
        }
    )?;
    if dropped > 0 {
        writeln!(
            out,
            "{dropped} frame(s) dropped by the logger (its DROPCOUNT lines) are not in the log"
        )?;
    }
    // The frames before a damaged tail are written: the file is kept, the status says
    // it is not the whole log.
    match summary.incomplete {
        Some(e) => Err(CliError::Incomplete(format!(
            "{}: {e} (the {} frames before it were written)",
            log.display(),
            summary.frames
        ))),
        None => Ok(()),
    }
}

/// The releases a demonstration on firmware flashes, read from `images` and checked: the
/// demonstrated ECU's, the faulty 1.1.0 and the correct 1.2.0, signed with the development
/// key the firmware's bootloader trusts.
fn demo_on_firmware(
    which: Demo,
    choice: FirmwareChoice,
    images: Option<&Path>,
) -> Result<autoplug_live::demo::OnFirmware, CliError> {
    autoplug_live::demo::check_choice(which, &choice).map_err(|e| CliError::Demo(e.to_string()))?;
    let dir = images.ok_or_else(|| {
        CliError::Demo(
            "--firmware needs --images DIR, the signed releases to flash (scripts/firmware-demo-images DIR builds them)"
                .into(),
        )
    })?;
    let mut files = Vec::new();
    for (variant, version) in [
        (SoftwareVariant::Faulty, Version::new(1, 1, 0)),
        (SoftwareVariant::Standard, Version::new(1, 2, 0)),
    ] {
        let path = dir.join(autoplug_dashboard::dashboard::demo_image_name(
            which.ecu(),
            variant,
            version,
        ));
        let bytes = std::fs::read(&path).map_err(|source| {
            CliError::Image(ImageToolError::Io {
                context: format!("cannot read the release '{}'", path.display()),
                source,
            })
        })?;
        let inspections =
            autoplug_image_tool::inspect(&bytes, Some(&autoplug_image::dev::PUBLIC_KEY)).map_err(
                |source| {
                    CliError::Image(ImageToolError::NotAnImage {
                        path: path.clone(),
                        source,
                    })
                },
            )?;
        for inspection in &inspections {
            let h = &inspection.header;
            if Some(h.node) != which.ecu().diag_node_number()
                || h.variant != variant
                || h.version != version
            {
                return Err(CliError::WrongImage(format!(
                    "'{}' is {} software {} for ECU node {} (the demonstration flashes the {} ECU's {variant} software {version})",
                    path.display(),
                    h.variant,
                    h.version,
                    h.node,
                    which.ecu().name(),
                )));
            }
            if let Some(problem) = inspection.problems().first() {
                return Err(CliError::WrongImage(format!(
                    "'{}': {problem} (the firmware's bootloader trusts the development key)",
                    path.display()
                )));
            }
        }
        files.push(bytes);
    }
    let [faulty, fixed] = <[Vec<u8>; 2]>::try_from(files)
        .map_err(|_| CliError::Demo("two releases expected".into()))?;
    Ok(autoplug_live::demo::OnFirmware {
        choice,
        images: [faulty, fixed],
    })
}

/// What plays a recording's world into the dashboard's world channel.
fn world_feed(
    world: std::sync::Arc<autoplug_web::WorldChannel>,
) -> autoplug_live::replay::WorldFeed {
    use autoplug_live::replay::WorldEvent;
    Box::new(move |event| match event {
        // Too large a description: the replay shows no world (the bus plays on).
        WorldEvent::Describe(json) => drop(world.describe(json)),
        WorldEvent::Pose(json) => world.publish(json),
    })
}

/// What publishes the virtual car's world into the dashboard's world channel: its
/// description (road and car) once, then its pose each time the source hands the car over.
fn world_publisher(
    world: std::sync::Arc<autoplug_web::WorldChannel>,
) -> autoplug_live::sources::WorldSink {
    use autoplug_virtual_car::world::{description, WorldPose};
    Box::new(move |car| {
        if !world.is_described() {
            let about = description(
                car.scenario().track.as_deref(),
                &autoplug_virtual_car::car::VirtualCar::vehicle_params(),
            );
            // A shipped or scenario road is far below the limit; a larger one has no view.
            if world.describe(about.to_string()).is_err() {
                return;
            }
        }
        world.publish(WorldPose::of(car).to_json());
    })
}

/// Runs a demonstration and reports what it showed.
fn demo(
    which: Demo,
    dir: Option<&Path>,
    firmware: Option<&autoplug_live::demo::OnFirmware>,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let path = Path::new(which.scenario_file());
    let scenario = Scenario::load(path).map_err(|e| CliError::Demo(e.to_string()))?;
    let report = autoplug_live::demo::run_on(which, &scenario, firmware)
        .map_err(|e| CliError::Demo(e.to_string()))?;
    let w = |out: &mut dyn Write, text: String| writeln!(out, "{text}").map_err(CliError::Output);
    w(
        out,
        format!("{} ({})", scenario.name, which.scenario_file()),
    )?;
    if let Some(on) = firmware {
        let names: Vec<_> = on.choice.ecus.iter().map(|n| n.name()).collect();
        w(
            out,
            format!(
                "on firmware: {} run their release firmware with the bootloader on emulated STM32F446s; {} defmt log lines",
                names.join(", "),
                report.firmware_log.len()
            ),
        )?;
    }
    for (variant, version, flash) in &report.flashes {
        w(
            out,
            format!(
                "flashed {variant} software {version} into the {} ECU over CAN:",
                which.ecu().name()
            ),
        )?;
        w(out, format!("{flash}"))?;
    }
    let s = report.symptom;
    match which {
        Demo::Cruise => w(
            out,
            format!(
                "cruise at 90 km/h, rms speed error around the set speed: faulty software {:.2} km/h, correct software {:.2} km/h",
                s.faulty, s.fixed
            ),
        )?,
        Demo::Abs => w(
            out,
            format!(
                "full braking on split friction, heading change: faulty software {:.1} deg, correct software {:.1} deg",
                s.faulty, s.fixed
            ),
        )?,
    }
    for (when, d) in ["before the fix", "after the fix"]
        .iter()
        .zip(&report.gateway)
    {
        let finding = d.headline().map_or("-".to_string(), |f| {
            format!(
                "{}: {} (suspect above {}, faulty above {}{})",
                f.routine,
                f.value.map_or("-".into(), |v| format!("{v:.2} {}", f.unit)),
                f.suspect_above,
                f.faulty_above,
                f.window.map_or(String::new(), |w| format!(", over {w}"))
            )
        });
        w(
            out,
            format!(
                "gateway diagnosis {when}: {} {}, {finding}",
                which.ecu().name(),
                d.verdict.name().to_uppercase()
            ),
        )?;
    }
    if let Some(dir) = dir {
        let dir = dir.join(&scenario.name);
        std::fs::create_dir_all(&dir).map_err(CliError::Output)?;
        autoplug_virtual_car::report::write_outputs(&dir, &report.record)
            .map_err(CliError::Output)?;
        if firmware.is_some() {
            let text: String = report
                .firmware_log
                .iter()
                .map(|line| format!("{line}\n"))
                .collect();
            std::fs::write(dir.join("firmware.log"), text).map_err(CliError::Output)?;
        }
        w(out, format!("written to {}", dir.display()))?;
    }
    Ok(())
}

/// Checks an image file against the ECU before anything is sent: a header, the right
/// ECU, the right length, and the signature if a key is given.
fn precheck_image(
    ecu: Node,
    path: &Path,
    key: Option<&Path>,
) -> Result<(Vec<u8>, ImageHeader), CliError> {
    let inspections = autoplug_image_tool::inspect_file(path, key)?;
    for inspection in &inspections {
        precheck_one(ecu, path, inspection)?;
    }
    let bytes = std::fs::read(path).map_err(|source| {
        CliError::Image(ImageToolError::Io {
            context: format!("cannot read the image '{}'", path.display()),
            source,
        })
    })?;
    // `inspect_file` returns at least one inspection, or an error.
    let header = inspections
        .first()
        .map(|i| i.header)
        .ok_or_else(|| CliError::WrongImage(format!("'{}' holds no image", path.display())))?;
    Ok((bytes, header))
}

/// One image of the file against the ECU.
fn precheck_one(
    ecu: Node,
    path: &Path,
    inspection: &autoplug_image_tool::Inspection,
) -> Result<(), CliError> {
    let header = inspection.header;
    if Some(header.node) != ecu.diag_node_number() {
        let target = ECUS
            .iter()
            .find(|n| n.diag_node_number() == Some(header.node))
            .map_or_else(|| format!("node 0x{:02X}", header.node), |n| ecu_label(*n));
        return Err(CliError::WrongImage(format!(
            "'{}' is an image for {target}, not for {}: the ECU would refuse it",
            path.display(),
            ecu_label(ecu)
        )));
    }
    let problems = inspection.problems();
    if !problems.is_empty() {
        return Err(ImageToolError::Corrupted {
            path: path.to_path_buf(),
            problems,
        }
        .into());
    }
    if let SignatureCheck::Invalid(error) = &inspection.signature {
        return Err(ImageToolError::Corrupted {
            path: path.to_path_buf(),
            problems: vec![error.to_string()],
        }
        .into());
    }
    Ok(())
}

#[allow(clippy::too_many_arguments)] // one per command-line option
fn flash(
    via: &Via,
    ecu: Node,
    image: &Path,
    secret_file: Option<&Path>,
    key: Option<&Path>,
    reset_timeout: f64,
    timing: TimingArgs,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let (bytes, header) = precheck_image(ecu, image, key)?;
    let secret = match secret_file {
        Some(path) => read_secret_file(path)?,
        None => DEV_SECURITY_SECRET.to_vec(),
    };
    let mut transport = autoplug_transport::open(via)?;
    writeln!(
        out,
        "flashing {} with {} (version {}, {} bytes) via {}",
        ecu_label(ecu),
        image.display(),
        header.version,
        header.image_len(),
        transport.describe()
    )?;
    let total = header.image_len();
    let mut config = FlashConfig::new(ecu, bytes, &secret);
    config.tester = timing.tester_config();
    config.reset_timeout_us = (reset_timeout * 1e6) as u64;
    // `new` refuses only nodes without a diagnostic address, which `--ecu` cannot name.
    let mut job = FlashJob::new(config).map_err(|e| CliError::WrongImage(e.to_string()))?;
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template(
            "{msg:>14} [{bar:40.cyan/blue}] {bytes}/{total_bytes} {bytes_per_sec} {elapsed}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    let observer = bar.clone();
    let mut phase = None;
    job.on_progress(move |progress| {
        if phase != Some(progress.phase) {
            phase = Some(progress.phase);
            if progress.phase == autoplug_tester::Phase::Transfer {
                // The rate shown is the transfer's, not diluted by the setup and erase.
                observer.reset();
            }
            observer.set_message(progress.phase.name());
        }
        // The image for the slot the ECU writes is known once the ECU said which it runs.
        observer.set_length(progress.total);
        observer.set_position(progress.transferred);
    });
    let result = driver::run(transport.as_mut(), &mut job);
    match result {
        Ok(report) => {
            bar.finish_and_clear();
            writeln!(out, "{report}")?;
            writeln!(out, "done: {} runs the new image", ecu_label(ecu))?;
            Ok(())
        }
        Err(DriveError::Job(error)) => {
            bar.abandon();
            writeln!(out, "{}", error.report)?;
            Err(CliError::Flash(Box::new(error)))
        }
        Err(DriveError::Transport(error)) => {
            bar.abandon();
            Err(error.into())
        }
    }
}

/// The `autoplug` program: parses the command line, runs it, prints an error and exits
/// with status 1 if it fails (2 for a command-line error, as clap does).
pub fn main() -> ExitCode {
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(error) => error.exit(),
    };
    // A reader gone away (`| head`) ends neither a gateway's trips nor a flash.
    let mut out = ReaderMayLeave::new(io::stdout().lock());
    let result = run(cli, &mut out);
    let _ = out.flush();
    // Not eprintln!: it panics when standard error is a closed pipe too (`2>&1 | head`).
    let complain = |text: String| {
        let _ = writeln!(io::stderr(), "autoplug: {text}");
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(CliError::FaultyEcu(which)) => {
            complain(format!("judged faulty: {which}"));
            ExitCode::from(3)
        }
        Err(error @ CliError::Incomplete(_)) => {
            complain(error.to_string());
            ExitCode::from(4)
        }
        Err(error @ CliError::NotAutoPlug(_)) => {
            complain(error.to_string());
            ExitCode::from(5)
        }
        Err(error) => {
            complain(format!("error: {error}"));
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// clap's own consistency checks over every subcommand (unique names, valid
    /// defaults...), which otherwise fire only when that subcommand is used.
    #[test]
    fn the_command_line_is_consistent() {
        use clap::CommandFactory;
        Cli::command().debug_assert();
    }
}
