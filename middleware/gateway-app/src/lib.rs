//! The AutoPlug gateway assembled into one run, as `autoplug gateway` and `autoplug
//! dashboard` start it (and the tests through them): the frame source (a live bus, the
//! virtual car or a recorded log), the tester when the gateway may transmit, the trip log,
//! the recording, the fleet link, the web dashboard's session and server, and the summary
//! the run leaves at its end. The command line only turns its arguments into
//! [`GatewayOptions`] and prints what [`run`] writes.
#![forbid(unsafe_code)]

use std::cell::RefCell;
use std::collections::VecDeque;
use std::fmt;
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use autoplug_dashboard::session::{Session, SourceKind};
use autoplug_gateway::{FrameSource, Observer, Pipeline, PipelineError, RecordingSink, Strictness};
use autoplug_live::driving::DriverDesk;
use autoplug_live::replay::ReplayDesk;
use autoplug_live::sources::{BusUrl, Transmitting};
use autoplug_live::watch::{StatusLine, TripLog, Watch};
use autoplug_store::SqliteStore;
use autoplug_tester::bus_tester::{BusTester, Outbox};
use autoplug_tester::names::ECUS;
use autoplug_tester::{identification_table, vin_line, TesterConfig};
use autoplug_virtual_car::firmware::{DebugPorts, FirmwareChoice};
use autoplug_web::LiveTable;

/// Why a run did not start or did not end well.
#[derive(Debug)]
pub enum RunError {
    /// The source, the log, the recording, the trip store or the web server failed, or the
    /// options do not go together.
    Failed(String),
    /// The fleet link could not start.
    Fleet(String),
    /// The log could not be read to its end (what precedes the damage was judged and
    /// reported).
    Incomplete(String),
    /// Writing the output failed.
    Output(io::Error),
}

impl fmt::Display for RunError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RunError::Failed(why) | RunError::Fleet(why) | RunError::Incomplete(why) => {
                f.write_str(why)
            }
            RunError::Output(e) => write!(f, "cannot write the output: {e}"),
        }
    }
}

impl std::error::Error for RunError {}

impl From<io::Error> for RunError {
    fn from(e: io::Error) -> Self {
        RunError::Output(e)
    }
}

/// What the gateway's run was asked to do besides watching (the `autoplug gateway` and
/// `autoplug dashboard` commands).
pub struct GatewayOptions {
    /// May transmit, reading the DTCs this often (µs of bus time).
    pub transmit: Option<u64>,
    pub record: Option<PathBuf>,
    pub rotate: autoplug_logs::RotatePolicy,
    /// candump or MF4 recordings.
    pub record_format: autoplug_logs::RecordFormat,
    pub db: Option<PathBuf>,
    /// `None`: the VIN the ECUs answer, else `local`.
    pub vehicle: Option<String>,
    pub speed: Option<f64>,
    pub fast: bool,
    pub duration: Option<f64>,
    pub quiet: bool,
    /// Serve the dashboard.
    pub web: Option<autoplug_web::WebConfig>,
    /// Where the dashboard's recordings go (`record` starts one at once).
    pub recordings_dir: Option<PathBuf>,
    /// Recordings may be opened in replay dashboards of their own.
    pub replay_pages: Option<autoplug_dashboard::dashboard::ReplayPages>,
    /// Report to a fleet (needs `transmit`).
    pub fleet: Option<autoplug_fleet_agent::link::FleetConfig>,
    /// ECUs of the virtual car that run as their firmware on emulated MCUs.
    pub firmware: Option<FirmwareChoice>,
}

/// Set by Ctrl-C: the live gateway stops at the next frame or idle moment.
static STOP: AtomicBool = AtomicBool::new(false);
/// Set when standard input closes, for `dashboard --exit-with-input`.
pub static EXIT_WITH_INPUT: AtomicBool = AtomicBool::new(false);

/// Runs the gateway on `bus` until the bus ends, the duration passes or Ctrl-C (or, for
/// the dashboard, its input closes), then prints what the run leaves.
pub fn run(bus: &BusUrl, options: GatewayOptions, out: &mut dyn Write) -> Result<(), RunError> {
    let pace = pace(bus, &options)?;
    // With the dashboard, a person may drive the virtual car.
    let desk = match (bus, &options.web) {
        (BusUrl::Virtual(_) | BusUrl::Dashboard, Some(_)) => {
            Some(Rc::new(RefCell::new(DriverDesk::new())))
        }
        _ => None,
    };
    // The dashboard's live table, before the source: the virtual car publishes its world
    // beside it.
    let table = options.web.as_ref().map(|_| Arc::new(LiveTable::new()));
    let Opened {
        mut source,
        player: replay_desk,
        debug_ports,
    } = open_source(bus, &options, pace, desk.clone(), table.as_ref(), out)?;
    let replaying = matches!(bus, BusUrl::Replay(_));
    if replaying && options.transmit.is_some() {
        return Err(RunError::Failed(
            "a recorded log cannot be transmitted to: --transmit is for a live bus".into(),
        ));
    }
    if options.fleet.is_some() && options.transmit.is_none() {
        return Err(RunError::Failed(
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
            RunError::Failed(format!(
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
        Some(_) => Some(autoplug_fleet::mqtt::runtime().map_err(RunError::Fleet)?),
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
            let table = table.clone().unwrap_or_else(|| Arc::new(LiveTable::new()));
            let (control, commands) = autoplug_web::control::channel();
            let token = config.token.clone();
            let server = autoplug_web::WebServer::start(config, table.clone(), Some(control))
                .map_err(|e| RunError::Failed(e.to_string()))?;
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
            // Beside the session: its thread stands still with a car a debugger holds.
            let debugger_watch =
                autoplug_dashboard::debuggers::DebuggerWatch::start(debug_ports, table.clone());
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
                session = session.with_recordings(dir, options.rotate, options.record_format);
            }
            if options.record.is_some() {
                session.start_recording().map_err(RunError::Failed)?;
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
            drop(debugger_watch);
            drop(server);
            (result, session.watch, recorded)
        }
        None => {
            let recording = match options.record.as_deref() {
                Some(dir) => Some(RecordingSink::new(
                    autoplug_logs::Recorder::start_as(
                        dir,
                        "gateway",
                        options.rotate,
                        options.record_format,
                    )
                    .map_err(|e| RunError::Failed(e.to_string()))?,
                )),
                None => None,
            };
            let (result, recorded) = run_watching(
                &mut pipeline,
                source.as_mut(),
                &mut watch,
                recording,
                &mut stop,
                out,
            )?;
            (result, watch, recorded)
        }
    };
    report_run(&mut watch, &pipeline, recorded, out)?;
    drop(fleet_runtime);
    result.map_err(|e| RunError::Failed(e.to_string()))?;
    match pipeline.incomplete() {
        Some(e) => Err(RunError::Incomplete(format!("{}: {e}", source.describe()))),
        None => Ok(()),
    }
}

/// The pace the source plays at, a multiple of real time (`None`: as fast as it goes, or
/// at its own pace).
fn pace(bus: &BusUrl, options: &GatewayOptions) -> Result<Option<f64>, RunError> {
    Ok(match bus {
        BusUrl::Virtual(_) | BusUrl::Dashboard if options.fast => None,
        BusUrl::Virtual(_) | BusUrl::Dashboard => Some(options.speed.unwrap_or(1.0)),
        BusUrl::Transport(_) if options.fast || options.speed.is_some() => {
            return Err(RunError::Failed(
                "--speed and --fast pace the virtual car only: a real bus goes at its own pace"
                    .into(),
            ))
        }
        BusUrl::Transport(_) => None,
        // The dashboard's player paces itself (--speed sets where it starts).
        BusUrl::Replay(_) if options.web.is_some() => None,
        BusUrl::Replay(_) if options.fast => None,
        BusUrl::Replay(_) => Some(options.speed.unwrap_or(1.0)),
    })
}

/// The dashboard's player of a recorded log, shared with its session.
type Player = Rc<RefCell<ReplayDesk>>;

/// What [`open_source`] opened.
struct Opened {
    source: Box<dyn FrameSource>,
    player: Option<Player>,
    debug_ports: DebugPorts,
}

/// The frames: the dashboard's player over a recorded log (with the recording's world, if
/// it has one), or the bus opened at `pace`, the virtual car publishing its world into
/// `table`. Gives the player too, which the dashboard's session drives, and the GDB servers'
/// statuses of the ECUs debugged.
fn open_source(
    bus: &BusUrl,
    options: &GatewayOptions,
    pace: Option<f64>,
    desk: Option<Rc<RefCell<DriverDesk>>>,
    table: Option<&Arc<LiveTable>>,
    out: &mut dyn Write,
) -> Result<Opened, RunError> {
    let mut replay_desk = None;
    let mut debug_ports = Vec::new();
    let source = match (bus, &options.web) {
        (BusUrl::Replay(path), Some(_)) => {
            let (first_us, last_us) =
                autoplug_live::replay::log_span(path).map_err(RunError::Failed)?;
            let mut player =
                autoplug_live::replay::ReplayDesk::new((last_us - first_us) as f64 * 1e-6);
            player.speed = options.speed.unwrap_or(1.0);
            let player = Rc::new(RefCell::new(player));
            replay_desk = Some(player.clone());
            let mut source = autoplug_live::replay::ControlledReplay::open(path, first_us, player)
                .map_err(|e| RunError::Failed(e.to_string()))?;
            if let Some(table) = table {
                // A recording of the virtual car shows its world too; without a world
                // file the replay shows the bus alone.
                match source.with_world(world_feed(table.world().clone())) {
                    Ok(None) | Err(_) => {}
                    Ok(Some(damage)) => {
                        writeln!(out, "world file damaged, played up to the damage: {damage}")?
                    }
                }
            }
            Box::new(source) as Box<dyn FrameSource>
        }
        _ => {
            let (source, ports) = bus
                .open(
                    pace,
                    desk,
                    options.firmware.as_ref(),
                    table.map(|t| world_publisher(t.world().clone())),
                )
                .map_err(RunError::Failed)?;
            debug_ports = ports;
            source
        }
    };
    Ok(Opened {
        source,
        player: replay_desk,
        debug_ports,
    })
}

/// The gateway without the dashboard: the watch, and the recording with `--record`. Gives
/// the pipeline's result and the recording's summary.
fn run_watching(
    pipeline: &mut Pipeline,
    source: &mut dyn FrameSource,
    watch: &mut Watch<'_>,
    mut recording: Option<RecordingSink>,
    stop: &mut dyn FnMut() -> bool,
    out: &mut dyn Write,
) -> Result<(Result<(), PipelineError>, Option<String>), RunError> {
    let result = {
        let mut observers: Vec<&mut dyn Observer> = vec![watch];
        if let Some(sink) = recording.as_mut() {
            observers.push(sink);
        }
        pipeline.run(source, &mut observers, stop)
    };
    let recorded = match recording.as_mut() {
        Some(sink) => {
            if let Some(failure) = sink.failure() {
                writeln!(out, "{failure}")?;
            }
            let summary = sink.stop().map_err(|e| RunError::Failed(e.to_string()))?;
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
    Ok((result, recorded))
}

/// What a run leaves: the recording, the bus time, the trips, the verdicts, the
/// identification, the trouble codes heard and the fleet link's last word.
fn report_run(
    watch: &mut Watch<'_>,
    pipeline: &Pipeline,
    recorded: Option<String>,
    out: &mut dyn Write,
) -> Result<(), RunError> {
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
    Ok(())
}

/// Opens (or creates) the trip database for a run.
pub fn open_trip_log(db: &Path, vehicle: &str, source: &str) -> Result<TripLog, RunError> {
    let store = SqliteStore::open(db).map_err(|e| RunError::Failed(e.to_string()))?;
    Ok(TripLog::new(Box::new(store), vehicle, source))
}

/// The trips a run stored, and why it stopped storing them if it did.
pub fn report_trip_log(trip_log: &TripLog, out: &mut dyn Write) -> Result<(), RunError> {
    if !trip_log.stored.is_empty() {
        let ids: Vec<String> = trip_log.stored.iter().map(|id| id.to_string()).collect();
        writeln!(out, "stored trip(s) {} ", ids.join(", "))?;
    }
    if let Some(failure) = &trip_log.failure {
        writeln!(out, "{failure}")?;
    }
    Ok(())
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

/// What plays a recording's world into the dashboard's world channel.
fn world_feed(world: Arc<autoplug_web::WorldChannel>) -> autoplug_live::replay::WorldFeed {
    use autoplug_live::replay::WorldEvent;
    Box::new(move |event| match event {
        // Too large a description: the replay shows no world (the bus plays on).
        WorldEvent::Describe(json) => drop(world.describe(json)),
        WorldEvent::Pose(json) => world.publish(json),
    })
}

/// What publishes the virtual car's world into the dashboard's world channel: its
/// description (road and car) once, then its pose each time the source hands the car over.
fn world_publisher(world: Arc<autoplug_web::WorldChannel>) -> autoplug_live::sources::WorldSink {
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
