//! `virtual-car`: runs scenarios on the AutoPlug virtual car and writes their reports.
//!
//!     virtual-car run scenarios/drive-cycle.toml            # as fast as possible
//!     virtual-car run scenarios/cruise-hold.toml --realtime --socketcand 127.0.0.1:29536
//!     virtual-car run scenarios/drive-cycle.toml --firmware all   # the nine firmwares, emulated
//!     virtual-car abs-sweep --out out                      # ABS stops over friction and speed
//!     virtual-car list

use autoplug_vin::Vin;
use autoplug_virtual_car::car::VirtualCar;
use autoplug_virtual_car::compare::{compare, table as compare_table};
use autoplug_virtual_car::console::ReaderMayLeave;
use autoplug_virtual_car::firmware::{self, FirmwareChoice};
use autoplug_virtual_car::report::{self, RunRecord};
use autoplug_virtual_car::scenario::Scenario;
use autoplug_virtual_car::socketcand::{CarBridge, SocketcandServer};
use clap::{Parser, Subcommand};
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::{Duration, Instant};

thread_local! {
    /// Standard output, which outlives its reader (`virtual-car run ... | head`).
    static STDOUT: std::cell::RefCell<ReaderMayLeave<std::io::Stdout>> =
        std::cell::RefCell::new(ReaderMayLeave::new(std::io::stdout()));
}

/// `print!` to standard output, except that a reader gone away does not end the program
/// (where `print!` would panic): the rest of the output is dropped and the work goes on,
/// so every scenario still writes its files. Any other write error ends the program with
/// a short message.
macro_rules! out {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        if let Err(e) = STDOUT.with(|out| write!(out.borrow_mut(), $($arg)*)) {
            eprintln!("error: cannot write to standard output: {e}");
            std::process::exit(1);
        }
    }};
}

/// [`out!`] with a newline.
macro_rules! outln {
    ($($arg:tt)*) => {
        out!("{}\n", format_args!($($arg)*))
    };
}

#[derive(Parser)]
#[command(
    name = "virtual-car",
    version,
    about = "The AutoPlug virtual car: vehicle model, CAN bus and the nine ECUs, driven by scenario files"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Runs scenarios and writes trace.csv, bus.log, summary.json and plots for each.
    Run {
        /// Scenario files (TOML).
        #[arg(required = true)]
        scenarios: Vec<PathBuf>,
        /// Output folder; each scenario writes into a folder named after it.
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Pace the simulation to real time (default: as fast as the machine allows).
        #[arg(long)]
        realtime: bool,
        /// Serve the bus over the socketcand protocol (raw mode) at HOST:PORT, so that
        /// python-can, cantools and SavvyCAN can attach. Implies --realtime.
        #[arg(long, value_name = "HOST:PORT")]
        socketcand: Option<String>,
        /// With --socketcand: wait up to this many seconds for a client in raw mode before
        /// starting.
        #[arg(long, value_name = "SECONDS", default_value_t = 0.0, value_parser = parse_wait)]
        wait_for_client: f64,
        /// The car's VIN (17 characters, check digit verified), in place of the scenario's:
        /// every ECU answers it as UDS DID F190.
        #[arg(long, value_parser = parse_vin)]
        vin: Option<Vin>,
        /// ECUs that run as their firmware (the release ELF with the bootloader) on
        /// emulated STM32F446s instead of host logic: `all`, or names separated by commas
        /// (cruise,abs). Their defmt logs go to firmware.log (and to the terminal with
        /// --realtime).
        #[arg(long, value_name = "all|ECU,...")]
        firmware: Option<String>,
        /// Where the firmware ELF files are: `boot` and `<ecu>-fw`.
        #[arg(long, value_name = "DIR", default_value = firmware::DEFAULT_FIRMWARE_DIR)]
        firmware_dir: PathBuf,
        /// A GDB server on an emulated ECU's debug port (loopback; default address
        /// 127.0.0.1:3333, then 3334…): the run waits for the debugger at power-on, and
        /// the whole car stands still while it holds the ECU halted. Repeatable.
        #[arg(long, value_name = "ECU[=ADDR]")]
        gdb: Vec<String>,
    },
    /// Runs scenarios twice, on host logic and with ECUs as their firmware on emulated
    /// STM32F446s, and compares the runs: every periodic message at its period, the gear
    /// sequence, distance, fuel and maximum speed within 1 %, every stop within 2 %.
    /// Writes both runs (host/ and firmware/) under --out; fails if a check fails.
    Compare {
        /// Scenario files (TOML).
        #[arg(required = true)]
        scenarios: Vec<PathBuf>,
        /// The ECUs that run as firmware: `all`, or names separated by commas.
        #[arg(long, value_name = "all|ECU,...", default_value = "all")]
        firmware: String,
        /// Where the firmware ELF files are: `boot` and `<ecu>-fw`.
        #[arg(long, value_name = "DIR", default_value = firmware::DEFAULT_FIRMWARE_DIR)]
        firmware_dir: PathBuf,
        /// Output folder; each scenario writes into a folder named after it.
        #[arg(long, default_value = "out/compare")]
        out: PathBuf,
        /// Run the emulated car a second time and require the same bus log, byte for
        /// byte: the emulation is deterministic.
        #[arg(long)]
        twice: bool,
    },
    /// Full braking over a grid of road friction (0.2 to 1.0) and speed (40 to 200 km/h),
    /// and on split friction: each stop against the limit v²/(2µg), as a table
    /// (abs-sweep.md) and a plot (abs-sweep.svg).
    AbsSweep {
        /// Output folder.
        #[arg(long, default_value = "out")]
        out: PathBuf,
    },
    /// Lists the scenarios in a folder with their descriptions.
    List {
        /// Folder of scenario files.
        #[arg(default_value = "scenarios")]
        dir: PathBuf,
    },
}

/// Longest wait for a client, s (a day: longer is a mistake, not a plan).
const MAX_WAIT_S: f64 = 86_400.0;

fn parse_wait(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(s) if s.is_finite() && (0.0..=MAX_WAIT_S).contains(&s) => Ok(s),
        _ => Err(format!(
            "'{text}' is not a number of seconds from 0 to {MAX_WAIT_S}"
        )),
    }
}

fn parse_vin(text: &str) -> Result<Vin, String> {
    Vin::parse(text).map_err(|e| e.to_string())
}

fn main() -> ExitCode {
    match Cli::parse().command {
        Command::Run {
            scenarios,
            out,
            realtime,
            socketcand,
            wait_for_client,
            vin,
            firmware,
            firmware_dir,
            gdb,
        } => {
            if !gdb.is_empty() && firmware.is_none() {
                eprintln!("error: --gdb debugs an ECU's firmware: name it with --firmware too");
                return ExitCode::from(2);
            }
            let firmware = match firmware
                .as_deref()
                .map(|list| FirmwareChoice::parse(list, &firmware_dir))
                .transpose()
                .and_then(|choice| choice.map(|c| c.debug(&gdb)).transpose())
                .and_then(|choice| choice.map(firmware_at_hand).transpose())
            {
                Ok(choice) => choice,
                Err(e) => {
                    eprintln!("error: {e}");
                    return ExitCode::from(2);
                }
            };
            if out.exists() && !out.is_dir() {
                eprintln!(
                    "error: --out '{}' is a file: it must be a folder (or not exist yet)",
                    out.display()
                );
                return ExitCode::from(2);
            }
            let server = match socketcand.as_deref().map(SocketcandServer::start) {
                None => None,
                Some(Ok(server)) => {
                    outln!("socketcand: serving can0 on {}", server.address());
                    Some(server)
                }
                Some(Err(e)) => {
                    eprintln!(
                        "error: cannot serve socketcand on {}: {e}",
                        socketcand.unwrap_or_default()
                    );
                    return ExitCode::from(2);
                }
            };
            if let Some(server) = &server {
                let deadline = Instant::now() + Duration::from_secs_f64(wait_for_client.max(0.0));
                while server.raw_clients() == 0 && Instant::now() < deadline {
                    std::thread::sleep(Duration::from_millis(10));
                }
            }
            let mut failed = false;
            for path in &scenarios {
                match Scenario::load(path) {
                    Ok(mut scenario) => {
                        if let Some(vin) = vin {
                            scenario.vin_text = Some(vin.to_string());
                        }
                        let car = match &firmware {
                            None => VirtualCar::new(&scenario),
                            // A real-time run shows the firmware's log as the car reads
                            // it, from the first start on and at a debugger's halts.
                            Some(choice) => match VirtualCar::with_firmware_showing_log(
                                &scenario,
                                choice,
                                (realtime || server.is_some())
                                    .then(|| Box::new(|line: &_| outln!("{line}")) as _),
                            ) {
                                Ok(car) => car,
                                Err(e) => {
                                    eprintln!("error: {e}");
                                    failed = true;
                                    continue;
                                }
                            },
                        };
                        match run_one(car, &out, realtime || server.is_some(), server.as_ref()) {
                            Ok(stopped) => failed |= stopped,
                            Err(e) => {
                                eprintln!(
                                    "error: --out '{}': cannot write the results of {}: {e}",
                                    out.display(),
                                    path.display()
                                );
                                failed = true;
                            }
                        }
                    }
                    Err(e) => {
                        eprintln!("error: {e}");
                        failed = true;
                    }
                }
            }
            if failed {
                ExitCode::FAILURE
            } else {
                ExitCode::SUCCESS
            }
        }
        Command::Compare {
            scenarios,
            firmware,
            firmware_dir,
            out,
            twice,
        } => {
            let choice =
                match FirmwareChoice::parse(&firmware, &firmware_dir).and_then(firmware_at_hand) {
                    Ok(choice) => choice,
                    Err(e) => {
                        eprintln!("error: {e}");
                        return ExitCode::from(2);
                    }
                };
            let mut failed = false;
            for path in &scenarios {
                let outcome = Scenario::load(path)
                    .map_err(|e| e.to_string())
                    .and_then(|scenario| compare_one(&scenario, &choice, &out, twice));
                match outcome {
                    Ok(true) => {}
                    Ok(false) => failed = true,
                    Err(e) => {
                        eprintln!("error: {e}");
                        failed = true;
                    }
                }
            }
            if failed {
                ExitCode::FAILURE
            } else {
                ExitCode::SUCCESS
            }
        }
        Command::AbsSweep { out } => abs_sweep(&out),
        Command::List { dir } => list(&dir),
    }
}

fn abs_sweep(out: &Path) -> ExitCode {
    use autoplug_virtual_car::sweep;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let wall = Instant::now();
    let stops = match sweep::run_sweep(
        &sweep::FRICTIONS,
        &sweep::SPEEDS_KMH,
        &sweep::SPLIT_FRICTIONS,
        &sweep::SPLIT_SPEEDS_KMH,
        threads,
    ) {
        Ok(stops) => stops,
        Err(e) => {
            eprintln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    let table = sweep::table(&stops);
    let written = std::fs::create_dir_all(out)
        .and_then(|()| std::fs::write(out.join("abs-sweep.md"), &table))
        .and_then(|()| std::fs::write(out.join("abs-sweep.svg"), sweep::plot(&stops).to_svg()));
    if let Err(e) = written {
        eprintln!(
            "error: --out '{}': cannot write the sweep: {e}",
            out.display()
        );
        return ExitCode::FAILURE;
    }
    out!("{table}");
    outln!(
        "{} stops in {:.1} s; table and plot in {}",
        stops.len(),
        wall.elapsed().as_secs_f64(),
        out.display()
    );
    ExitCode::SUCCESS
}

/// Runs the car's scenario and writes its results; `Ok(true)` when an emulated ECU stopped
/// on the way (the rest of the car ran on).
fn run_one(
    car: VirtualCar,
    out: &Path,
    realtime: bool,
    server: Option<&SocketcandServer>,
) -> std::io::Result<bool> {
    let wall = Instant::now();
    let scenario = car.scenario().clone();
    let debug_ports = car.debug_ports();
    let dir = out.join(&scenario.name);
    std::fs::create_dir_all(&dir)?;
    let mut bus_log = BufWriter::new(File::create(dir.join("bus.log"))?);
    let mut trace = BufWriter::new(File::create(dir.join("trace.csv"))?);
    let firmware_log_path = dir.join("firmware.log");
    let mut firmware_log: Option<BufWriter<File>> = None;
    let mut firmware_log_error = None;
    let mut bridge = CarBridge::new();
    let record: RunRecord = report::run_car_streaming(
        car,
        &mut bus_log,
        &mut trace,
        |car, frames| {
            for line in car.take_firmware_log() {
                let text = line.to_string();
                if firmware_log_error.is_none() {
                    use std::io::Write as _;
                    let written = match &mut firmware_log {
                        Some(file) => writeln!(file, "{text}"),
                        None => File::create(&firmware_log_path).and_then(|f| {
                            let mut f = BufWriter::new(f);
                            let w = writeln!(f, "{text}");
                            firmware_log = Some(f);
                            w
                        }),
                    };
                    firmware_log_error = written.err();
                }
            }
            if let Some(server) = server {
                bridge.exchange(server, car, frames);
            }
            if realtime && car.time_us() % 10_000 == 0 {
                let target = Duration::from_micros(car.time_us());
                // The car stood still while a debugger held an ECU: that time is not
                // the car's to catch up.
                let elapsed = wall.elapsed().saturating_sub(car.debugger_halted_for());
                if let Some(wait) = target.checked_sub(elapsed) {
                    std::thread::sleep(wait);
                }
            }
        },
        // Rendered while the writer thread finishes the bus log and the trace.
        |record| report::write_summary_and_plots(&dir, record),
    )?;
    if let Some(e) = firmware_log_error {
        return Err(e);
    }
    if let Some(mut file) = firmware_log {
        use std::io::Write as _;
        file.flush()?;
    }
    // The time a debugger held the car is not the run's.
    let halted = debug_ports
        .iter()
        .map(|(_, status)| status.halted_for())
        .sum::<Duration>()
        .as_secs_f64();
    let elapsed = wall.elapsed().as_secs_f64() - halted;
    outln!("{}", scenario.name);
    if !scenario.description.is_empty() {
        outln!("  {}", scenario.description);
    }
    out!("{}", record.summary.table());
    if let Some(server) = server {
        let drops = server.drops();
        outln!(
            "  {:<28} {} frame(s) dropped toward the bus, {} toward clients (queues full), {} command(s) refused",
            "socketcand",
            drops.to_bus,
            drops.to_clients,
            server.refused_commands()
        );
    }
    outln!(
        "  {:<28} {:.3} s wall for {:.1} s simulated ({:.0}x real time){}",
        "run time",
        elapsed,
        scenario.duration_s,
        scenario.duration_s / elapsed.max(1e-9),
        if halted > 0.0 {
            format!(", besides {halted:.3} s halted by the debugger")
        } else {
            String::new()
        }
    );
    outln!("  {:<28} {}", "written to", dir.display());
    for stop in &record.summary.firmware_stops {
        eprintln!("error: firmware stopped: {stop}");
    }
    Ok(!record.summary.firmware_stops.is_empty())
}

/// A run of the emulated car, with its firmware log and how fast it went.
struct EmulatedRun {
    record: RunRecord,
    firmware_log: Vec<String>,
    /// Loading the images (their symbols and debug information) and each board's first
    /// start, s.
    setup_s: f64,
    /// The run itself, s.
    wall_s: f64,
    instructions: u64,
}

fn run_emulated(scenario: &Scenario, choice: &FirmwareChoice) -> Result<EmulatedRun, String> {
    let setup = Instant::now();
    let car = VirtualCar::with_firmware(scenario, choice)?;
    let setup_s = setup.elapsed().as_secs_f64();
    let wall = Instant::now();
    let mut firmware_log = Vec::new();
    let mut instructions = 0;
    let record = report::run_car(car, |car| {
        for line in car.take_firmware_log() {
            firmware_log.push(format!(
                "{:>11.6} {:<12} {}",
                line.t_us as f64 * 1e-6,
                line.ecu,
                line.text
            ));
        }
        instructions = car.firmware_instructions();
    });
    Ok(EmulatedRun {
        record,
        firmware_log,
        setup_s,
        wall_s: wall.elapsed().as_secs_f64(),
        instructions,
    })
}

/// The run's bus log as `bus.log` holds it (candump).
fn candump(record: &RunRecord) -> Result<Vec<u8>, String> {
    let mut bytes = Vec::new();
    report::write_bus_log(&mut bytes, &record.log).map_err(|e| e.to_string())?;
    Ok(bytes)
}

fn write_run(dir: &Path, record: &RunRecord, firmware_log: &[String]) -> Result<(), String> {
    let written = (|| -> std::io::Result<()> {
        std::fs::create_dir_all(dir)?;
        std::fs::write(
            dir.join("bus.log"),
            candump(record).map_err(std::io::Error::other)?,
        )?;
        let mut trace = BufWriter::new(File::create(dir.join("trace.csv"))?);
        report::write_trace(&mut trace, &record.trace)?;
        std::io::Write::flush(&mut trace)?;
        if !firmware_log.is_empty() {
            std::fs::write(dir.join("firmware.log"), firmware_log.join("\n") + "\n")?;
        }
        report::write_summary_and_plots(dir, record)
    })();
    written.map_err(|e| format!("{}: {e}", dir.display()))
}

/// Compares one scenario on host logic and on the emulated firmware; `Ok(false)` when a
/// check failed.
fn compare_one(
    scenario: &Scenario,
    choice: &FirmwareChoice,
    out: &Path,
    twice: bool,
) -> Result<bool, String> {
    let dir = out.join(&scenario.name);
    let host_wall = Instant::now();
    let host = report::run(scenario);
    let host_wall_s = host_wall.elapsed().as_secs_f64();
    write_run(&dir.join("host"), &host, &[])?;
    let emulated = run_emulated(scenario, choice)?;
    write_run(
        &dir.join("firmware"),
        &emulated.record,
        &emulated.firmware_log,
    )?;
    let checks = compare(&host, &emulated.record, &choice.ecus);
    outln!(
        "{}: host logic against the firmware of {}",
        scenario.name,
        emulated.record.summary.firmware.join(", ")
    );
    out!("{}", compare_table(&checks));
    let mut ok = checks.iter().all(|c| c.ok);
    for stop in &emulated.record.summary.firmware_stops {
        outln!("  FAIL firmware stopped: {stop}");
        ok = false;
    }
    outln!(
        "  {:<28} {:.3} s wall for {:.1} s simulated ({:.0}x real time)",
        "host-logic run",
        host_wall_s,
        scenario.duration_s,
        scenario.duration_s / host_wall_s.max(1e-9)
    );
    outln!(
        "  {:<28} {:.1} s wall for {:.1} s simulated ({:.2}x real time), {:.1} M instructions per simulated second; before it {:.2} s loading the images, each board's first start and the ignition",
        "emulated run",
        emulated.wall_s,
        scenario.duration_s,
        scenario.duration_s / emulated.wall_s.max(1e-9),
        emulated.instructions as f64 / scenario.duration_s / 1e6,
        emulated.setup_s
    );
    if twice {
        let again = run_emulated(scenario, choice)?;
        let (first, second) = (candump(&emulated.record)?, candump(&again.record)?);
        let same = first == second && emulated.firmware_log == again.firmware_log;
        outln!(
            "  {} {:<44} {} bytes of bus log and {} firmware log lines, then {} and {}",
            if same { "ok  " } else { "FAIL" },
            "the same run twice: the same bus log",
            first.len(),
            emulated.firmware_log.len(),
            second.len(),
            again.firmware_log.len()
        );
        ok &= same;
    }
    outln!("  {:<28} {}", "written to", dir.display());
    Ok(ok)
}

fn list(dir: &Path) -> ExitCode {
    let entries = match std::fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) => {
            eprintln!("error: cannot read {}: {e}", dir.display());
            return ExitCode::FAILURE;
        }
    };
    let mut paths: Vec<PathBuf> = entries
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    paths.sort();
    let mut ok = true;
    for path in paths {
        match Scenario::load(&path) {
            Ok(s) => outln!(
                "{:<32} {:>6.1} s  {}",
                path.display(),
                s.duration_s,
                s.description
            ),
            Err(e) => {
                eprintln!("error: {e}");
                ok = false;
            }
        }
    }
    if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

/// The firmware `choice` needs, built first when files are missing and this is run from
/// the AutoPlug checkout whose release folder it names (`cargo`, as `cargo build-fw -p ecu-<ecu>`
/// does); elsewhere an error names every missing file and the commands that build them.
fn firmware_at_hand(choice: FirmwareChoice) -> Result<FirmwareChoice, String> {
    if choice.missing().is_empty() {
        return Ok(choice);
    }
    let cwd = std::env::current_dir().map_err(|e| format!("the current folder: {e}"))?;
    let root = firmware::workspace_root(&cwd);
    let ours = root.as_ref().is_some_and(|root| {
        let dir = cwd.join(&choice.dir);
        dir == root.join(firmware::DEFAULT_FIRMWARE_DIR)
    });
    match root {
        Some(root) if ours => {
            eprintln!(
                "virtual-car: building the missing firmware: {}",
                choice
                    .missing()
                    .iter()
                    .map(|(package, _)| package.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            );
            choice.build_missing(&root, &firmware::cargo())?;
            Ok(choice)
        }
        _ => choice.check_files().map(|()| choice),
    }
}
