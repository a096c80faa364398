//! `virtual-car`: runs scenarios on the AutoPlug virtual car and writes their reports.
//!
//!     virtual-car run scenarios/drive-cycle.toml            # as fast as possible
//!     virtual-car run scenarios/cruise-hold.toml --realtime --socketcand 127.0.0.1:29536
//!     virtual-car abs-sweep --out out                      # ABS stops over friction and speed
//!     virtual-car list

use autoplug_vin::Vin;
use autoplug_virtual_car::console::ReaderMayLeave;
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
        } => {
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
                        if let Err(e) = run_one(
                            &scenario,
                            &out,
                            realtime || server.is_some(),
                            server.as_ref(),
                        ) {
                            eprintln!(
                                "error: --out '{}': cannot write the results of {}: {e}",
                                out.display(),
                                path.display()
                            );
                            failed = true;
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

fn run_one(
    scenario: &Scenario,
    out: &Path,
    realtime: bool,
    server: Option<&SocketcandServer>,
) -> std::io::Result<()> {
    let wall = Instant::now();
    let dir = out.join(&scenario.name);
    std::fs::create_dir_all(&dir)?;
    let mut bus_log = BufWriter::new(File::create(dir.join("bus.log"))?);
    let mut trace = BufWriter::new(File::create(dir.join("trace.csv"))?);
    let mut bridge = CarBridge::new();
    let record: RunRecord = report::run_streaming(
        scenario,
        &mut bus_log,
        &mut trace,
        |car, frames| {
            if let Some(server) = server {
                bridge.exchange(server, car, frames);
            }
            if realtime && car.time_us() % 10_000 == 0 {
                let target = Duration::from_micros(car.time_us());
                if let Some(wait) = target.checked_sub(wall.elapsed()) {
                    std::thread::sleep(wait);
                }
            }
        },
        // Rendered while the writer thread finishes the bus log and the trace.
        |record| report::write_summary_and_plots(&dir, record),
    )?;
    let elapsed = wall.elapsed().as_secs_f64();
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
        "  {:<28} {:.3} s wall for {:.1} s simulated ({:.0}x real time)",
        "run time",
        elapsed,
        scenario.duration_s,
        scenario.duration_s / elapsed.max(1e-9)
    );
    outln!("  {:<28} {}", "written to", dir.display());
    Ok(())
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
