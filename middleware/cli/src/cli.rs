//! The `autoplug` command line: its arguments (clap), the parsers of their values, the
//! error a command ends with, and the program.
//!
//! [`Cli`] is the command line; [`run`] hands a parsed one to its command's module
//! (`cmd::<command>`), which writes what it has to say to `out`, so tests run commands
//! without a process; [`main`] is the whole program.

use std::fmt;
use std::io::{self, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use autoplug_can::Node;
use autoplug_image::{SoftwareVariant, Version, BUILD_ID_LEN};
use clap::{Args, Parser, Subcommand, ValueEnum};

use autoplug_image_tool::ImageToolError;
use autoplug_live::demo::Demo;
use autoplug_live::sources::BusUrl;
use autoplug_tester::names::{parse_ecu, ECUS, ECU_NAME_LIST};
use autoplug_tester::{FlashError, TesterConfig};
use autoplug_transport::{TransportError, Via};
use autoplug_virtual_car::console::ReaderMayLeave;
use autoplug_virtual_car::firmware::FirmwareChoice;

use crate::cmd;
// The secret file is the flash command's; its public path stays `cli::read_secret_file`.
pub use crate::cmd::ecu::read_secret_file;

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
    Flash(FlashArgs),
    /// Run the gateway on a recorded log (candump .log, Vector .asc or .blf): the car
    /// state, the bus statistics and every ECU's diagnosis, as on a live bus.
    Replay(ReplayArgs),
    /// Watch a live bus: the car's state in the terminal, every ECU's diagnosis, the trips
    /// into the database and, with --record, all traffic into candump files. Runs until the
    /// bus ends (the virtual car's scenario), --duration passes, or Ctrl-C.
    Gateway(GatewayArgs),
    /// The dashboard (the main command): the virtual car in real time (or a live bus), the
    /// gateway on its bus, trips and recordings in a data folder, and the web dashboard on
    /// loopback. Prints the page's address with the write token; runs until Ctrl-C.
    Dashboard(DashboardArgs),
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
    Diagnose(DiagnoseArgs),
    /// Run one of the report's demonstrations on the virtual car, the flashing done over
    /// CAN by this tool: `cruise` (scenario 1, the broken cruise control) or `abs`
    /// (scenario 2, the broken ABS). Run from the repository root (it reads
    /// scenarios/demo-*.toml).
    Demo(DemoArgs),
}

/// `autoplug flash`: the image, the ECU and the bus.
#[derive(Debug, Args)]
pub struct FlashArgs {
    /// The bus: socketcand://HOST:PORT/BUS or socketcan://IFACE.
    #[arg(long, value_name = "URL", value_parser = parse_via)]
    pub via: Via,
    /// The ECU to flash.
    #[arg(long, value_name = "NAME", value_parser = parse_ecu_arg, help = ecu_help("The ECU to flash"))]
    pub ecu: Node,
    /// The signed image file.
    #[arg(long, value_name = "FILE")]
    pub image: PathBuf,
    /// The SecurityAccess secret (the file's bytes, less a final newline); default:
    /// the development secret of the AutoPlug ECUs.
    #[arg(long, value_name = "FILE")]
    pub secret_file: Option<PathBuf>,
    /// Verify the image's signature with this public key before flashing.
    #[arg(long, value_name = "FILE.pub")]
    pub key: Option<PathBuf>,
    /// Seconds the ECU may take to answer again after its reset.
    #[arg(long, value_name = "SECONDS", default_value_t = 30.0, value_parser = parse_seconds)]
    pub reset_timeout: f64,
    /// UDS timing.
    #[command(flatten)]
    pub timing: TimingArgs,
}

/// `autoplug replay`: the log and how to play it.
#[derive(Debug, Args)]
pub struct ReplayArgs {
    /// The log file.
    #[arg(value_name = "LOG")]
    pub log: PathBuf,
    /// Pace the replay at this multiple of the log's own time (1 = as recorded);
    /// default: as fast as the machine goes.
    #[arg(long, value_name = "X", value_parser = parse_speed)]
    pub speed: Option<f64>,
    /// Skip malformed lines and count them, instead of stopping at the first.
    #[arg(long)]
    pub lenient: bool,
    /// Judge the ECUs even on a bus that is not an AutoPlug car.
    #[arg(long)]
    pub force: bool,
    /// Also store the log's trips in this database (SQLite).
    #[arg(long, value_name = "FILE")]
    pub db: Option<PathBuf>,
    /// The vehicle's name (a VIN) in the trip database.
    #[arg(long, value_name = "NAME", default_value = "local", requires = "db")]
    pub vehicle: String,
}

/// `autoplug gateway`: the bus and what the gateway does besides watching it.
#[derive(Debug, Args)]
pub struct GatewayArgs {
    /// The bus: virtual:SCENARIO.toml (the virtual car in this process),
    /// socketcand://HOST:PORT/BUS or socketcan://IFACE.
    #[arg(long, value_name = "URL", value_parser = parse_bus)]
    pub bus: BusUrl,
    /// Record all traffic into this directory (candump .log or MF4 files, flushed every
    /// 100 ms).
    #[arg(long, value_name = "DIR")]
    pub record: Option<PathBuf>,
    /// The recordings' format: candump, or MF4 (the bus and every signal decoded; a file
    /// cut by a crash reads to its last flush).
    #[arg(long, value_enum, default_value_t = RecordFormatArg::Candump)]
    pub record_format: RecordFormatArg,
    /// Start a new recording file after this many MB.
    #[arg(long, value_name = "MB", value_parser = clap::value_parser!(u64).range(1..=1_000_000))]
    pub rotate_mb: Option<u64>,
    /// Start a new recording file after this many minutes of bus time.
    #[arg(long, value_name = "MINUTES", value_parser = clap::value_parser!(u64).range(1..=100_000))]
    pub rotate_minutes: Option<u64>,
    /// The trip database (SQLite; created if missing).
    #[arg(long, value_name = "FILE", default_value = "autoplug.db")]
    pub db: PathBuf,
    /// Keep no trips.
    #[arg(long, conflicts_with = "db")]
    pub no_db: bool,
    /// The vehicle's name in the trip database (default: the VIN its ECUs answer,
    /// F190, else `local`).
    #[arg(long, value_name = "NAME")]
    pub vehicle: Option<String>,
    /// Pace the virtual car at this multiple of real time (default 1).
    #[arg(long, value_name = "X", value_parser = parse_speed, conflicts_with = "fast")]
    pub speed: Option<f64>,
    /// Run the virtual car as fast as the machine goes.
    #[arg(long)]
    pub fast: bool,
    /// Stop after this many seconds (at most 30 days).
    #[arg(long, value_name = "SECONDS", value_parser = parse_duration)]
    pub duration: Option<f64>,
    /// No status line (the summary at the end is still printed).
    #[arg(long)]
    pub quiet: bool,
    /// Let the gateway transmit: it reads every ECU's identification at the start (into
    /// the inventory) and their trouble codes (UDS 0x19) then and every
    /// --dtc-interval. Without it the gateway only listens.
    #[arg(long)]
    pub transmit: bool,
    /// Seconds of bus time between two readings of the trouble codes.
    #[arg(long, value_name = "SECONDS", default_value_t = 60.0, value_parser = parse_seconds, requires = "transmit")]
    pub dtc_interval: f64,
    /// Serve the car's decoded signals live over WebSocket (ws://ADDR/api/stream, the
    /// dashboard's stream) on this address, e.g. 127.0.0.1:8080. Keep it on loopback
    /// unless the bus must be watched from elsewhere.
    #[arg(long, value_name = "ADDR")]
    pub web: Option<std::net::SocketAddr>,
    /// A browser origin besides the server's own that may open the stream
    /// (http://host:port); repeatable.
    #[arg(long = "web-origin", value_name = "ORIGIN", requires = "web")]
    pub web_origins: Vec<String>,
    /// A host name besides the listening address the web server answers for (NAME or
    /// NAME:PORT, as in the browser's address bar); repeatable. Other names are
    /// refused (421), so a web page cannot point its own name at this server.
    #[arg(long = "allowed-host", value_name = "NAME", requires = "web")]
    pub allowed_hosts: Vec<String>,
    /// The fleet this vehicle reports to (needs --transmit).
    #[command(flatten)]
    pub fleet: crate::fleet_cli::VehicleFleetArgs,
    /// ECUs of the virtual car that run as their firmware.
    #[command(flatten)]
    pub firmware: FirmwareArgs,
}

/// `autoplug dashboard`: the bus or log, the data folder and the web server.
#[derive(Debug, Args)]
pub struct DashboardArgs {
    /// The bus: virtual (the virtual car, standing until you drive it from the page),
    /// virtual:SCENARIO.toml, socketcand://HOST:PORT/BUS or socketcan://IFACE.
    #[arg(long, value_name = "URL", default_value = "virtual", value_parser = parse_bus)]
    pub bus: BusUrl,
    /// Replay this log instead of a bus (candump, ASC, BLF, MF4), with play, pause, speed
    /// and seek on the page.
    #[arg(long, value_name = "LOG", conflicts_with = "bus")]
    pub log: Option<PathBuf>,
    /// The data folder: trips.db, recordings/, images/ (created if missing).
    #[arg(long, value_name = "DIR", default_value = "autoplug-data")]
    pub data: PathBuf,
    /// Where the dashboard listens. Keep it on loopback unless others must reach it.
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1:8080")]
    pub listen: std::net::SocketAddr,
    /// The write token (default: a new random one; or AUTOPLUG_TOKEN).
    #[arg(
        long,
        value_name = "TOKEN",
        env = "AUTOPLUG_TOKEN",
        hide_env_values = true
    )]
    pub token: Option<String>,
    /// Only show: no write actions at all (no token).
    #[arg(long, conflicts_with = "token")]
    pub read_only: bool,
    /// A browser origin besides the server's own that may open the stream
    /// (http://host:port); repeatable.
    #[arg(long = "web-origin", value_name = "ORIGIN")]
    pub web_origins: Vec<String>,
    /// A host name besides the listening address the dashboard answers for (NAME or
    /// NAME:PORT, as in the browser's address bar); repeatable. Other names are
    /// refused (421), so a web page cannot point its own name at the dashboard.
    #[arg(long = "allowed-host", value_name = "NAME")]
    pub allowed_hosts: Vec<String>,
    /// On a real bus, let the gateway transmit (identification, trouble codes,
    /// flashing). The virtual car's gateway always may.
    #[arg(long)]
    pub transmit: bool,
    /// The vehicle's name in the trip database (default: the VIN its ECUs answer,
    /// F190, else `local`).
    #[arg(long, value_name = "NAME")]
    pub vehicle: Option<String>,
    /// Stop after this many seconds (at most 30 days).
    #[arg(long, value_name = "SECONDS", value_parser = parse_duration)]
    pub duration: Option<f64>,
    /// Also print the status line every second.
    #[arg(long)]
    pub status: bool,
    /// Stop when standard input closes (a replay dashboard started by another one
    /// ends with it).
    #[arg(long, hide = true)]
    pub exit_with_input: bool,
    /// The fleet this vehicle reports to; the driver answers its update offers on
    /// the page.
    #[command(flatten)]
    pub fleet: crate::fleet_cli::VehicleFleetArgs,
    /// ECUs of the virtual car that run as their firmware.
    #[command(flatten)]
    pub firmware: FirmwareArgs,
    /// Show the campaigns of this fleet database on the Fleet view (postgresql://...
    /// or a SQLite file): the manufacturer's side, read only.
    #[arg(long, value_name = "ADDRESS")]
    pub fleet_db: Option<String>,
}

/// `autoplug diagnose`: the log and how to judge it.
#[derive(Debug, Args)]
pub struct DiagnoseArgs {
    /// The log file (candump .log, Vector .asc or .blf).
    #[arg(value_name = "LOG")]
    pub log: PathBuf,
    /// Print JSON for scripts instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Skip malformed lines and count them, instead of stopping at the first.
    #[arg(long)]
    pub lenient: bool,
    /// Judge the ECUs even on a bus that is not an AutoPlug car.
    #[arg(long)]
    pub force: bool,
}

/// `autoplug demo`: the demonstration and where it runs.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Which demonstration: cruise or abs.
    #[arg(value_parser = parse_demo)]
    pub which: Demo,
    /// Also write the run's trace, bus log, summary and plots here.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// ECUs of the virtual car that run as their firmware (the flashed one among
    /// them); the releases flashed then come from --images.
    #[command(flatten)]
    pub firmware: FirmwareArgs,
    /// With --firmware: the directory of the signed releases flashed,
    /// `<ecu>-1.1.0-faulty.img` and `<ecu>-1.2.0.img` (scripts/firmware-demo-images
    /// builds them).
    #[arg(long, value_name = "DIR", requires = "firmware")]
    pub images: Option<PathBuf>,
}

fn parse_speed(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(x) if x.is_finite() && x > 0.0 && x <= 10_000.0 => Ok(x),
        _ => Err(format!("'{text}' is not a speed factor in (0, 10000]")),
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
    /// Convert a log (candump .log, Vector .asc or .blf) to Vector ASC, candump, Vector BLF,
    /// or MCAP with the signals decoded.
    Export(ExportArgs),
}

/// `autoplug log export`: the log, the format and the output.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// The log to read.
    #[arg(value_name = "LOG")]
    pub log: PathBuf,
    /// The format to write.
    #[arg(long, value_enum, default_value_t = ExportFormat::Asc)]
    pub format: ExportFormat,
    /// The file to write (never overwritten).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Skip malformed lines and count them, instead of stopping at the first.
    #[arg(long)]
    pub lenient: bool,
    /// MF4 only: compress its data blocks (transposed deflate, as asammdf's smallest).
    #[arg(long)]
    pub compress: bool,
}

/// `gateway --record-format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum RecordFormatArg {
    /// candump .log lines.
    Candump,
    /// ASAM MDF 4 .mf4.
    Mf4,
}

/// `log export --format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ExportFormat {
    /// Vector ASC (CANalyzer, CANoe, python-can, SavvyCAN).
    Asc,
    /// candump .log (can-utils, python-can, cantools).
    Candump,
    /// Vector BLF, zlib-compressed (CANalyzer, CANoe, python-can).
    Blf,
    /// ASAM MDF 4.10: the bus logging and every signal decoded (asammdf, CANape,
    /// CANalyzer, python-can).
    Mf4,
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
    Build(BuildArgs),
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

/// `autoplug image build`: the payloads, what the header says, the key and the output.
#[derive(Debug, Args)]
pub struct BuildArgs {
    /// The target ECU.
    #[arg(long, value_name = "NAME", value_parser = parse_ecu_arg, help = ecu_help("The target ECU"))]
    pub ecu: Node,
    /// The software version, MAJOR.MINOR.PATCH.
    #[arg(long, value_name = "X.Y.Z", value_parser = parse_version)]
    pub version: Version,
    /// Standard software or the faulty demonstration.
    #[arg(long, value_enum, default_value_t = Variant::Standard)]
    pub variant: Variant,
    /// The part number (UDS F187), up to 16 printable ASCII characters.
    #[arg(long, value_name = "TEXT")]
    pub part_number: Option<String>,
    /// The build id, 32 hex digits; default: the first 16 bytes of the payload's
    /// SHA-256.
    #[arg(long, value_name = "HEX32", value_parser = parse_build_id)]
    pub build_id: Option<[u8; BUILD_ID_LEN]>,
    /// The application: a raw binary, or an ELF file linked for slot A (loadable
    /// segments from 0x08020200) or slot B (from 0x08040200). Give it twice, once per
    /// slot's build, for a release both slots can take.
    #[arg(long, value_name = "FILE", required = true)]
    pub payload: Vec<PathBuf>,
    /// The slot a raw binary is linked for (an ELF file says it itself).
    #[arg(long, value_enum)]
    pub slot: Option<SlotArg>,
    /// The secret key file to sign with ("dev": the development key, whose secret is
    /// public: for the virtual car and benches without their own keys).
    #[arg(long, value_name = "FILE.key")]
    pub key: PathBuf,
    /// The image file to write.
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
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

/// The help of an `--ecu NAME` option: what it is, then every ECU's name (from the DBC).
fn ecu_help(what: &str) -> String {
    format!("{what}: {ECU_NAME_LIST} (or a name's start, four letters or more: trans, diff)")
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

impl From<autoplug_gateway_app::RunError> for CliError {
    fn from(e: autoplug_gateway_app::RunError) -> Self {
        use autoplug_gateway_app::RunError;
        match e {
            RunError::Failed(why) => CliError::Log(why),
            RunError::Fleet(why) => CliError::Fleet(why),
            RunError::Incomplete(why) => CliError::Incomplete(why),
            RunError::Output(e) => CliError::Output(e),
        }
    }
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

/// Carries out a parsed command line; what it prints goes to `out` (the progress bar of
/// `flash` goes to the terminal's stderr).
pub fn run(cli: Cli, out: &mut dyn Write) -> Result<(), CliError> {
    match cli.command {
        Command::Keygen { out: path } => cmd::keygen::run(&path, out),
        Command::Image(ImageCommand::Build(args)) => cmd::image::build(args, out),
        Command::Image(ImageCommand::Inspect { file, key }) => {
            cmd::image::inspect(&file, key.as_deref(), out)
        }
        Command::Ids(args) => cmd::ecu::ids(args, out),
        Command::Dtcs(args) => cmd::ecu::dtcs(args, out),
        Command::Flash(args) => cmd::ecu::flash(args, out),
        Command::Demo(args) => cmd::demo::run(args, out),
        Command::Replay(args) => cmd::replay::run(args, out),
        Command::Diagnose(args) => cmd::diagnose::run(args, out),
        Command::Gateway(args) => cmd::gateway::run(args, out),
        Command::Dashboard(args) => cmd::dashboard::run(args, out),
        Command::Trips(TripsCommand::List { db, vehicle, json }) => {
            cmd::trips::list(&db, vehicle.as_deref(), json, out)
        }
        Command::Trips(TripsCommand::Show { id, db, json }) => cmd::trips::show(id, &db, json, out),
        Command::Log(LogCommand::Export(args)) => cmd::log::export(args, out),
        Command::Fleet(command) => crate::fleet_cli::run(command, out).map_err(CliError::Fleet),
    }
}

/// `--firmware`: ECUs of the virtual car that run as their firmware.
#[derive(Debug, clap::Args, Clone)]
pub struct FirmwareArgs {
    /// Run these ECUs of the virtual car as their firmware (the release ELF and the
    /// bootloader) on emulated STM32F446s instead of host logic: `all`, or names separated
    /// by commas (cruise,abs).
    #[arg(long, value_name = "all|ECU,...")]
    pub(crate) firmware: Option<String>,
    /// Where the firmware ELF files are: `boot` and `<ecu>-fw`.
    #[arg(
        long,
        value_name = "DIR",
        default_value = autoplug_virtual_car::firmware::DEFAULT_FIRMWARE_DIR,
        requires = "firmware"
    )]
    pub(crate) firmware_dir: PathBuf,
    /// A GDB server on this ECU's emulated MCU (one that runs as firmware), at ADDR
    /// (loopback only; 127.0.0.1:3333 and up by default); repeatable. Without a page the
    /// car waits at power-on for the debugger; with one (the dashboard, --web) it runs,
    /// and the debugger halts it when it attaches.
    #[arg(long, value_name = "ECU[=ADDR]", requires = "firmware")]
    pub(crate) gdb: Vec<String>,
}

impl FirmwareArgs {
    /// The choice, for a bus that is the virtual car; `with_page`: a web page shows the
    /// car, so it does not wait at power-on for its debuggers.
    pub(crate) fn choice(
        &self,
        bus: &BusUrl,
        with_page: bool,
    ) -> Result<Option<FirmwareChoice>, CliError> {
        let Some(list) = &self.firmware else {
            return Ok(None);
        };
        if !matches!(bus, BusUrl::Virtual(_) | BusUrl::Dashboard) {
            return Err(CliError::Log(
                "--firmware runs ECUs of the virtual car: the bus is not the virtual car".into(),
            ));
        }
        let mut choice = FirmwareChoice::parse(list, &self.firmware_dir)
            .and_then(|c| c.debug(&self.gdb))
            .map_err(CliError::Log)?;
        choice.hold_for_debugger = !with_page;
        Ok(Some(choice))
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
