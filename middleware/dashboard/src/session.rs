//! The dashboard's session: the gateway's watch (diagnostics, trips, trouble codes, its
//! tester), the recording, the live table and the dashboard's commands, as one observer of
//! the pipeline, on the pipeline's thread.
//!
//! Between two frames (and while the bus is idle) it takes the commands the web server
//! queued: flashing and clearing go to the gateway's tester as jobs on the bus; recording
//! starts and stops a recorder; the person's driving goes to the virtual car's
//! [`DriverDesk`]. Twice a second (ten times during a flash) it writes its own state (verdicts, codes, inventory,
//! the job under way, the recording, the driver) into the live table's `session` object,
//! which the stream sends when it changed.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::rc::Rc;
use std::sync::Arc;
use std::time::{Duration, Instant};

use autoplug_can::Node;
use autoplug_gateway::{CarState, Observer, RecordingSink, Update};
use autoplug_image::{ImageSet, Payload};
use autoplug_logs::{LogFrame, RotatePolicy};
use autoplug_virtual_car::driver::clamped;
use autoplug_virtual_car::scenario::FRICTION_RANGE;
use autoplug_virtual_car::world::{world_file_for, WorldFileWriter};
use autoplug_web::world::WorldCursor;
use autoplug_web::{Action, Answer, Command, Commands, LiveTable, Publisher, ReplayAction};
use serde_json::{json, Value};

use autoplug_live::driving::{DeskInput, DriverDesk};
use autoplug_live::replay::{ReplayDesk, SPEED_RANGE};
use autoplug_live::watch::Watch;
use autoplug_tester::bus_tester::{JobOutcome, UserJob};
use autoplug_tester::names::{ecu_label, ecu_name, parse_ecu, ECUS};
use autoplug_tester::{value_text, ClearDtcsJob, FlashConfig, FlashJob, Phase, TesterConfig};

/// How often the session's state is written into the live table (wall time) while a job
/// runs (a flash's progress bar moves smoothly)...
pub const SESSION_PERIOD_BUSY: Duration = Duration::from_millis(100);
/// ...and otherwise: verdicts and trip figures need no more, and each change is resent
/// whole to every page.
pub const SESSION_PERIOD: Duration = Duration::from_millis(500);
/// Events the session keeps for the page (flash results, recordings...).
const MAX_EVENTS: usize = 20;

/// What the session's source is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SourceKind {
    /// The virtual car in this process: it can be driven.
    Virtual,
    /// A live bus (socketcand, SocketCAN).
    Bus,
    /// A recorded log, played with play, pause, speed and seek.
    Replay,
}

/// A flash as the page shows it.
struct FlashState {
    ecu: Node,
    origin: String,
    version: String,
    variant: String,
    /// The image that goes over CAN: the file's first until the ECU said which slot it
    /// writes, then the one for that slot (a release holds one per slot).
    image_bytes: u64,
    /// The file as given (both images of a release).
    file_bytes: usize,
    started: Instant,
    /// `None` while it runs.
    result: Option<Result<Value, String>>,
}

/// The simulator's world written beside a recording (`*.world.jsonl`, see
/// `autoplug_virtual_car::world`): never inside the candump file.
struct WorldRecording {
    writer: WorldFileWriter,
    path: PathBuf,
    cursor: WorldCursor,
    seen: u64,
    flushed: Instant,
}

/// How often the world file is flushed (as the candump file is).
const WORLD_FLUSH: Duration = Duration::from_millis(100);

/// The session (see the module docs).
pub struct Session<'a> {
    /// The gateway's watch: diagnostics, trips, codes, its tester.
    pub watch: Watch<'a>,
    table: Arc<LiveTable>,
    publisher: Publisher,
    commands: Commands,
    kind: SourceKind,
    source_name: String,
    desk: Option<Rc<RefCell<DriverDesk>>>,
    replay: Option<Rc<RefCell<ReplayDesk>>>,
    replay_pages: Option<crate::dashboard::ReplayPages>,
    security_secret: Vec<u8>,
    /// The virtual car's ECUs that run as their firmware on emulated MCUs: they refuse an
    /// image without machine code, which is said before a flash starts.
    firmware_ecus: Vec<Node>,
    recordings_dir: Option<PathBuf>,
    rotate: RotatePolicy,
    record_format: autoplug_logs::RecordFormat,
    recording: Option<RecordingSink>,
    /// The world file beside the recording's candump file (opened with its first file).
    world_file: Option<WorldRecording>,
    flash: Option<FlashState>,
    events: VecDeque<(f64, String)>,
    last_written: Option<Instant>,
    now_us: u64,
}

impl<'a> Session<'a> {
    /// A session over `watch`, publishing into `table`, taking `commands`.
    pub fn new(
        watch: Watch<'a>,
        table: Arc<LiveTable>,
        commands: Commands,
        kind: SourceKind,
        source_name: String,
    ) -> Self {
        Self {
            watch,
            publisher: Publisher::new(table.clone()),
            table,
            commands,
            kind,
            source_name,
            desk: None,
            replay: None,
            replay_pages: None,
            security_secret: autoplug_tester::DEV_SECURITY_SECRET.to_vec(),
            firmware_ecus: Vec::new(),
            recordings_dir: None,
            rotate: RotatePolicy::default(),
            record_format: autoplug_logs::RecordFormat::Candump,
            recording: None,
            world_file: None,
            flash: None,
            events: VecDeque::new(),
            last_written: None,
            now_us: 0,
        }
    }

    /// The virtual car's desk: the person may drive.
    pub fn with_desk(mut self, desk: Rc<RefCell<DriverDesk>>) -> Self {
        self.desk = Some(desk);
        self
    }

    /// The replay's controls: the page may play, pause, change speed and seek.
    pub fn with_replay(mut self, desk: Rc<RefCell<ReplayDesk>>) -> Self {
        self.replay = Some(desk);
        self
    }

    /// Recordings may be opened in replay dashboards of their own.
    pub fn with_replay_pages(mut self, pages: crate::dashboard::ReplayPages) -> Self {
        self.replay_pages = Some(pages);
        self
    }

    /// The replay jumped: what was judged so far belongs to another moment of the drive,
    /// so the diagnostics, the trouble codes and the trip start over from here.
    pub fn restart_analysis(&mut self) {
        self.watch.diagnostics = autoplug_diagnostics::Diagnostics::new();
        self.watch.dtcs = autoplug_diagnostics::DtcMonitor::new();
        self.watch.trips = autoplug_trips::TripTracker::without_series();
        self.watch.ended.clear();
        if let Some(desk) = &self.replay {
            let to = desk.borrow().seek_to.unwrap_or(0.0);
            self.event(format!(
                "replay: jumped to {to:.1} s, the analysis starts over"
            ));
        }
    }

    /// Where recordings go (without a directory, recording is refused).
    pub fn with_recordings(
        mut self,
        dir: PathBuf,
        rotate: RotatePolicy,
        format: autoplug_logs::RecordFormat,
    ) -> Self {
        self.record_format = format;
        self.recordings_dir = Some(dir);
        self.rotate = rotate;
        self
    }

    /// The virtual car's ECUs that run as their firmware (`--firmware`).
    pub fn with_firmware_ecus(mut self, ecus: &[Node]) -> Self {
        self.firmware_ecus = ecus.to_vec();
        self
    }

    /// The SecurityAccess secret for flashing (the development secret by default).
    pub fn with_security_secret(mut self, secret: Vec<u8>) -> Self {
        self.security_secret = secret;
        self
    }

    /// Starts recording all traffic (in the recordings directory).
    pub fn start_recording(&mut self) -> Result<(), String> {
        self.record(true).map(|_| ())
    }

    /// Stops the recording, if one runs (at the end of the session).
    pub fn stop_recording(&mut self) -> Option<String> {
        self.close_world_file();
        let mut sink = self.recording.take()?;
        Some(match sink.stop() {
            Ok(summary) => format!(
                "recording: {} frames, {} bytes in {} file(s)",
                summary.frames,
                summary.bytes,
                summary.files.len()
            ),
            Err(e) => format!("the recording failed: {e}"),
        })
    }

    fn event(&mut self, text: String) {
        if self.events.len() >= MAX_EVENTS {
            self.events.pop_front();
        }
        self.events.push_back((self.now_us as f64 * 1e-6, text));
    }

    fn take_commands(&mut self) {
        // Bounded per call: a flood of inputs cannot hold the pipeline up.
        for _ in 0..autoplug_web::control::CONTROL_QUEUE {
            let Some(command) = self.commands.next() else {
                return;
            };
            match command {
                Command::Act { action, reply } => {
                    let answer = self.act(action);
                    // The page may have gone: nobody to tell.
                    let _ = reply.send(answer);
                }
                Command::Drive(held) => {
                    if clamped(held).is_some() {
                        self.hand_to_desk(DeskInput::Hold(held));
                    }
                }
                Command::Press(button) => self.hand_to_desk(DeskInput::Press(button)),
                Command::DriverLeft => self.hand_to_desk(DeskInput::Release),
            }
        }
    }

    fn hand_to_desk(&mut self, input: DeskInput) {
        if let Some(desk) = &self.desk {
            // A full desk drops the input: the next one carries the same state.
            let _ = desk.borrow_mut().push(input);
        }
    }

    fn act(&mut self, action: Action) -> Answer {
        match action {
            Action::Flash { ecu, image, origin } => self.start_flash(&ecu, image, origin),
            Action::ClearDtcs { ecu } => self.clear_dtcs(ecu.as_deref()),
            Action::ResetVerdict { ecu } => self.reset_verdict(ecu.as_deref()),
            Action::Record(on) => self.record(on),
            Action::Road { mu_left, mu_right } => {
                let Some(desk) = &self.desk else {
                    return Err("only the virtual car's road can be changed".into());
                };
                for mu in [mu_left, mu_right] {
                    if !FRICTION_RANGE.contains(&mu) {
                        return Err(format!(
                            "friction {mu} is outside {}..={}",
                            FRICTION_RANGE.start(),
                            FRICTION_RANGE.end()
                        ));
                    }
                }
                desk.borrow_mut()
                    .push(DeskInput::Friction(mu_left, mu_right))
                    .map_err(str::to_string)?;
                self.event(format!(
                    "road friction: µ {mu_left} under the left wheels, {mu_right} under the right"
                ));
                Ok(json!({ "mu_left": mu_left, "mu_right": mu_right }))
            }
            Action::RoadStart => {
                let Some(desk) = &self.desk else {
                    return Err("only the virtual car can be taken back to the start".into());
                };
                let speed = desk.borrow().report().speed_mps.abs();
                if speed > autoplug_virtual_car::car::VirtualCar::STANDING_MPS {
                    return Err(format!(
                        "the car moves ({:.1} km/h): stop it first",
                        speed * 3.6
                    ));
                }
                desk.borrow_mut()
                    .push(DeskInput::ToStart)
                    .map_err(str::to_string)?;
                self.event("the car was taken back to the start".into());
                Ok(json!({ "to_start": true }))
            }
            Action::RoadSteering(on) => {
                let Some(desk) = &self.desk else {
                    return Err("only the virtual car can be steered along its road".into());
                };
                if on && !desk.borrow().report().on_track {
                    return Err(
                        "the car has no road to steer along (its scenario names no track)".into(),
                    );
                }
                desk.borrow_mut()
                    .push(DeskInput::SteerAlongRoad(on))
                    .map_err(str::to_string)?;
                self.event(
                    if on {
                        "the simulator steers along the road"
                    } else {
                        "the person steers"
                    }
                    .into(),
                );
                Ok(json!({ "along_road": on }))
            }
            Action::Replay(action) => self.control_replay(action),
            Action::ReplayRecording { path } => {
                let Some(pages) = self.replay_pages.as_mut() else {
                    return Err("this dashboard cannot open replays".into());
                };
                let port = pages.open(&path)?;
                let name = path
                    .file_name()
                    .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
                self.event(format!("replay of {name} opened on port {port}"));
                Ok(json!({ "port": port, "file": name }))
            }
            Action::CampaignConsent { campaign, install } => {
                let Some(fleet) = self.watch.fleet.as_mut() else {
                    return Err(
                        "this gateway is not connected to a fleet (start it with --fleet)".into(),
                    );
                };
                fleet.consent(campaign, install)?;
                Ok(json!({ "campaign": campaign, "install": install }))
            }
        }
    }

    fn control_replay(&mut self, action: ReplayAction) -> Answer {
        let Some(desk) = &self.replay else {
            return Err(format!(
                "{} is a live bus, not a replay: it has no play, pause or seek",
                self.source_name
            ));
        };
        let mut desk = desk.borrow_mut();
        match action {
            ReplayAction::Play => {
                if desk.at_end {
                    desk.seek(0.0);
                }
                desk.playing = true;
            }
            ReplayAction::Pause => desk.playing = false,
            ReplayAction::Speed { speed } => {
                if !SPEED_RANGE.contains(&speed) {
                    return Err(format!(
                        "speed {speed} is outside {}..={}",
                        SPEED_RANGE.start(),
                        SPEED_RANGE.end()
                    ));
                }
                desk.speed = speed;
            }
            ReplayAction::Seek { t } => {
                if !(t.is_finite() && (0.0..=desk.duration_s).contains(&t)) {
                    return Err(format!(
                        "{t} s is outside the log (0 to {:.1} s)",
                        desk.duration_s
                    ));
                }
                desk.seek(t);
            }
        }
        Ok(replay_state(&desk))
    }

    fn tester(&mut self) -> Result<&mut autoplug_tester::bus_tester::BusTester, String> {
        self.watch.tester.as_mut().ok_or_else(|| {
            "the gateway only listens on this bus (start it with --transmit to flash or clear)"
                .to_string()
        })
    }

    fn start_flash(&mut self, ecu: &str, image: Vec<u8>, origin: String) -> Answer {
        let node = parse_ecu(ecu).map_err(|e| e.to_string())?;
        // The whole file is checked here, not only the image that will go: a truncated
        // release or bytes after its second image mean a broken file, whichever slot the
        // ECU runs.
        let set = ImageSet::parse(&image)
            .map_err(|e| format!("'{origin}' is not a firmware image or release: {e}"))?;
        for (_, header) in set.iter() {
            if Some(header.node) != node.diag_node_number() {
                let target = ECUS
                    .iter()
                    .find(|n| n.diag_node_number() == Some(header.node))
                    .map_or_else(|| format!("node 0x{:02X}", header.node), |n| ecu_label(*n));
                return Err(format!(
                    "'{origin}' is an image for {target}, not for {}: the ECU would refuse it",
                    ecu_label(node)
                ));
            }
            if header.payload == Payload::HostLogic && self.firmware_ecus.contains(&node) {
                return Err(format!(
                    "'{origin}' holds no machine code (it is built for the virtual car's host-logic ECUs) and {} runs its firmware on an emulated STM32F446: flash a firmware release (scripts/firmware-release, or the library's releases from scripts/firmware-demo-images)",
                    ecu_label(node)
                ));
            }
        }
        let header = set.first();
        let image_bytes = set.first_image().len() as u64;
        let images = set.len();
        let file_bytes = image.len();
        let job = FlashJob::new(FlashConfig::new(node, image, &self.security_secret))
            .map_err(|e| format!("cannot flash '{origin}': {e}"))?;
        self.tester()?.queue(UserJob::Flash(Box::new(job)))?;
        let version = header.version.to_string();
        let variant = format!("{:?}", header.variant).to_lowercase();
        self.event(format!(
            "flashing {} with {origin} ({version}, {variant})",
            ecu_name(node)
        ));
        self.flash = Some(FlashState {
            ecu: node,
            origin,
            version: version.clone(),
            variant: variant.clone(),
            image_bytes,
            file_bytes,
            started: Instant::now(),
            result: None,
        });
        Ok(json!({
            "ecu": ecu_name(node),
            "version": version,
            "variant": variant,
            "bytes": image_bytes,
            "file_bytes": file_bytes,
            "images": images,
        }))
    }

    fn reset_verdict(&mut self, ecu: Option<&str>) -> Answer {
        let ecus = match ecu {
            Some(name) => vec![parse_ecu(name).map_err(|e| e.to_string())?],
            None => ECUS.to_vec(),
        };
        for &node in &ecus {
            self.watch.diagnostics.reset(node);
        }
        let names: Vec<&str> = ecus.iter().map(|n| ecu_name(*n)).collect();
        self.event(format!(
            "verdicts reset: {} judged again from now on",
            names.join(", ")
        ));
        Ok(json!({ "ecus": names }))
    }

    fn clear_dtcs(&mut self, ecu: Option<&str>) -> Answer {
        let ecus = match ecu {
            Some(name) => vec![parse_ecu(name).map_err(|e| e.to_string())?],
            None => ECUS.to_vec(),
        };
        let job = ClearDtcsJob::new(&ecus, TesterConfig::DEFAULT);
        self.tester()?.queue(UserJob::Clear(Box::new(job)))?;
        let names: Vec<&str> = ecus.iter().map(|n| ecu_name(*n)).collect();
        Ok(json!({ "ecus": names }))
    }

    fn record(&mut self, on: bool) -> Answer {
        if !on {
            let Some(mut sink) = self.recording.take() else {
                return Err("no recording is running".into());
            };
            self.close_world_file();
            let summary = sink.stop().map_err(|e| e.to_string())?;
            let files: Vec<String> = summary
                .files
                .iter()
                .filter_map(|f| f.file_name().map(|n| n.to_string_lossy().into_owned()))
                .collect();
            self.event(format!(
                "recording stopped: {} frames in {}",
                summary.frames,
                files.join(", ")
            ));
            return Ok(json!({ "frames": summary.frames, "bytes": summary.bytes, "files": files }));
        }
        if self.recording.is_some() {
            return Err("a recording is already running".into());
        }
        let Some(dir) = self.recordings_dir.clone() else {
            return Err("this gateway has no recordings directory".into());
        };
        std::fs::create_dir_all(&dir)
            .map_err(|e| format!("cannot create '{}': {e}", dir.display()))?;
        let recorder =
            autoplug_logs::Recorder::start_as(&dir, "dashboard", self.rotate, self.record_format)
                .map_err(|e| e.to_string())?;
        self.recording = Some(RecordingSink::new(recorder));
        self.event("recording started".into());
        Ok(json!({ "on": true }))
    }

    fn take_outcomes(&mut self) {
        while let Some(outcome) = self.watch.tester.as_mut().and_then(|t| t.take_outcome()) {
            match outcome {
                JobOutcome::Flash(node, result) => {
                    let sent_bytes = result.as_ref().ok().map(|report| report.image_len);
                    let (text, result) = match result {
                        Ok(report) => (
                            format!(
                                "{} flashed in {:.1} s",
                                ecu_name(node),
                                report.total_us as f64 * 1e-6
                            ),
                            Ok(json!({
                                "slot": report.slot.map(|s| s.letter().to_string()),
                                "image_bytes": report.image_len,
                                "total_s": report.total_us as f64 * 1e-6,
                                "phases": phases(&report.phases),
                                "throughput_bps": report.transfer_throughput(),
                            })),
                        ),
                        Err(error) => (error.to_string(), Err(error.to_string())),
                    };
                    self.event(text);
                    if let Some(flash) = self.flash.as_mut().filter(|f| f.ecu == node) {
                        flash.image_bytes = sent_bytes.unwrap_or(flash.image_bytes);
                        flash.result = Some(result);
                    }
                }
                JobOutcome::Cleared(reports) => {
                    let failed: Vec<String> = reports
                        .iter()
                        .filter_map(|r| {
                            r.outcome
                                .as_ref()
                                .err()
                                .map(|e| format!("{}: {e}", ecu_name(r.ecu)))
                        })
                        .collect();
                    let text = if failed.is_empty() {
                        format!("trouble codes cleared ({} ECUs)", reports.len())
                    } else {
                        format!("clearing failed for {}", failed.join("; "))
                    };
                    self.event(text);
                }
            }
        }
    }

    /// The session's state as the page reads it (see the module docs).
    fn state(&mut self, state: &CarState) -> Value {
        let replay_page = match self.replay_pages.as_mut().and_then(|p| p.running()) {
            Some(page) => {
                json!({ "file": page.file, "port": page.port, "listening": page.listening })
            }
            None => Value::Null,
        };
        let diagnostics: Vec<Value> = self
            .watch
            .diagnostics
            .report(state)
            .iter()
            .map(|d| {
                let f = d.headline();
                json!({
                    "ecu": ecu_name(d.ecu),
                    "node": d.ecu.diag_node_number(),
                    "verdict": d.verdict.name(),
                    "routine": f.map(|f| f.routine),
                    "number": f.and_then(|f| f.value).filter(|v| v.is_finite()),
                    "unit": f.map(|f| f.unit),
                    "suspect_above": f.map(|f| f.suspect_above),
                    "faulty_above": f.map(|f| f.faulty_above),
                    "evidence": f.map(|f| f.evidence.as_str()),
                })
            })
            .collect();
        let dtcs: Vec<Value> = self
            .watch
            .dtcs
            .latest()
            .iter()
            .map(|r| {
                json!({
                    "ecu": ecu_name(r.ecu),
                    "read_at": r.read_at_us as f64 * 1e-6,
                    "codes": r.entries.iter().map(|e| json!({
                        "code": e.dtc.to_string(),
                        "status": e.status,
                        "description": autoplug_diagnostics::describe_dtc(e.dtc),
                    })).collect::<Vec<_>>(),
                })
            })
            .collect();
        let inventory: Vec<Value> = self
            .watch
            .identification
            .iter()
            .flatten()
            .map(|row| {
                let text = |v: &Result<Vec<u8>, _>| v.is_ok().then(|| value_text(v));
                json!({
                    "ecu": ecu_name(row.ecu),
                    "node": row.ecu.diag_node_number(),
                    "answered": row.answered(),
                    "part_number": text(&row.part_number),
                    "software_version": text(&row.software_version),
                    "hardware_version": text(&row.hardware_version),
                    "serial_number": text(&row.serial_number),
                    "slot": row.running_slot().map(|(slot, _)| slot.letter().to_string()),
                    "boot_state": row.running_slot().map(|(_, state)| state.name()),
                })
            })
            .collect();
        let tester = self.watch.tester.as_ref();
        let progress = tester.and_then(|t| t.flash_progress());
        let flash = self.flash.as_mut().map(|f| {
            let running = progress.filter(|(node, _)| *node == f.ecu);
            if let Some((_, p)) = running {
                f.image_bytes = p.total;
            }
            json!({
                "ecu": ecu_name(f.ecu),
                "image": f.origin,
                "version": f.version,
                "variant": f.variant,
                "bytes": f.image_bytes,
                "file_bytes": f.file_bytes,
                "state": match (&f.result, running) {
                    (Some(Ok(_)), _) => "done",
                    (Some(Err(_)), _) => "failed",
                    (None, Some(_)) => "running",
                    (None, None) => "queued",
                },
                "phase": running.map(|(_, p)| p.phase.name()),
                "transferred": running.map(|(_, p)| p.transferred),
                "elapsed_s": f.started.elapsed().as_secs_f64(),
                "report": f.result.as_ref().and_then(|r| r.as_ref().ok()),
                "error": f.result.as_ref().and_then(|r| r.as_ref().err()),
            })
        });
        let recording = self.recording.as_ref().map(|sink| {
            let (summary, file) = sink.written();
            json!({
                "frames": summary.frames,
                "bytes": summary.bytes,
                "file": file.and_then(|f| f.file_name().map(|n| n.to_string_lossy().into_owned())),
                "failure": sink.failure().map(|e| e.to_string()),
            })
        });
        let driver = self.desk.as_ref().map(|desk| {
            let report = desk.borrow().report();
            json!({
                "person": report.held.is_some(),
                "held": report.held.map(|h| json!({
                    "accelerator": h.accelerator,
                    "brake": h.brake,
                    "steering_deg": h.steering_deg,
                    "headlights": h.headlights,
                    "economy_mode": h.economy_mode,
                    "manual_mode": h.manual_mode,
                    "set_temp_f": h.set_temp_f,
                })),
                "mu_left": report.friction.0,
                "mu_right": report.friction.1,
                "on_track": report.on_track,
                "steers_along_road": report.steers_along_road,
            })
        });
        json!({
            "source": {
                "name": self.source_name,
                "kind": match self.kind {
                    SourceKind::Virtual => "virtual",
                    SourceKind::Bus => "bus",
                    SourceKind::Replay => "replay",
                },
                "transmit": tester.is_some(),
                "drive": self.desk.is_some(),
                "replay": self.replay.is_some(),
            },
            "replay": self.replay.as_ref().map(|d| replay_state(&d.borrow())),
            "replay_page": replay_page,
            "tester": tester.map(|t| t.activity()),
            "diagnostics": diagnostics,
            "dtcs": dtcs,
            "inventory": inventory,
            "flash": flash,
            "recording": recording,
            "driver": driver,
            "trip": self.watch.trips.current(),
            "fleet": self.watch.fleet.as_ref().map(fleet_state),
            "events": self.events.iter().map(|(t, text)| json!({ "t": t, "text": text })).collect::<Vec<_>>(),
        })
    }

    /// Writes what the world channel has new into the world file beside the recording,
    /// opening it once the recording has its first file. A write error ends the world
    /// file (the recording goes on) and says so.
    fn record_world(&mut self) {
        let Some(sink) = &self.recording else {
            return;
        };
        let world = self.table.world().clone();
        if self.world_file.is_none() {
            if !world.is_described() {
                return;
            }
            let Some(candump) = sink.written().1 else {
                return;
            };
            let path = world_file_for(&candump);
            match WorldFileWriter::create(&path) {
                Ok(writer) => {
                    self.world_file = Some(WorldRecording {
                        writer,
                        path,
                        cursor: WorldCursor::default(),
                        seen: u64::MAX,
                        flushed: Instant::now(),
                    })
                }
                Err(e) => {
                    // Tried once per recording: the event says why there is no world file.
                    self.event(format!(
                        "the world file {} cannot be written: {e}",
                        path.display()
                    ));
                    return;
                }
            }
        }
        let Some(file) = self.world_file.as_mut() else {
            return;
        };
        let version = world.version();
        let mut written = Ok(());
        if version != file.seen {
            file.seen = version;
            if let Some(news) = world.take_since(file.cursor) {
                file.cursor = news.cursor;
                if let Some(description) = &news.description {
                    written = file.writer.describe(description);
                }
                for pose in &news.poses {
                    if written.is_err() {
                        break;
                    }
                    written = file.writer.pose(pose);
                }
            }
        }
        if written.is_ok() && file.flushed.elapsed() >= WORLD_FLUSH {
            file.flushed = Instant::now();
            written = file.writer.flush();
        }
        if let Err(e) = written {
            let path = file.path.display().to_string();
            self.world_file = None;
            self.event(format!("the world file {path} stopped: {e}"));
        }
    }

    fn close_world_file(&mut self) {
        if let Some(mut file) = self.world_file.take() {
            if let Err(e) = file.writer.flush() {
                let path = file.path.display().to_string();
                self.event(format!("the world file {path} failed: {e}"));
            }
        }
    }

    fn housekeeping(&mut self, state: &CarState) {
        self.now_us = state.now_us();
        self.record_world();
        self.take_commands();
        self.take_outcomes();
        let busy = self
            .watch
            .tester
            .as_ref()
            .is_some_and(|t| t.flash_progress().is_some())
            || self.flash.as_ref().is_some_and(|f| f.result.is_none());
        let period = if busy {
            SESSION_PERIOD_BUSY
        } else {
            SESSION_PERIOD
        };
        if self.last_written.is_none_or(|t| t.elapsed() >= period) {
            self.last_written = Some(Instant::now());
            let value = self.state(state);
            self.table.set_session(&value);
        }
    }
}

/// The fleet link as the page shows it: the offer the driver answers, the campaign's
/// progress, the connection.
fn fleet_state(fleet: &autoplug_fleet_agent::link::FleetLink) -> Value {
    let status = fleet.status();
    json!({
        "broker": fleet.broker(),
        "online": fleet.online(),
        "connected": status.as_ref().is_some_and(|s| s.connected),
        "problem": fleet.not_connected.as_deref().or_else(|| {
            status
                .as_ref()
                .filter(|s| !s.connected)
                .and_then(|s| s.refused.as_deref().or(s.last_error.as_deref()))
        }),
        "vin": fleet.vin(),
        "standing": fleet.standing(),
        "offer": fleet.offer().map(|o| json!({
            "campaign": o.campaign,
            "name": o.name,
            "ecu": o.ecu,
            "version": o.version,
            "message": o.message,
            "bytes": o.bytes,
            "question": o.question(),
        })),
        "activity": fleet.activity().map(|(campaign, what)| json!({ "campaign": campaign, "what": what })),
        "reports": fleet.campaign_reports(),
        "events": fleet.events().collect::<Vec<_>>(),
        "waiting_reports": fleet.waiting_reports(),
        "dropped_reports": fleet.dropped_reports(),
    })
}

fn replay_state(desk: &ReplayDesk) -> Value {
    json!({
        "playing": desk.playing,
        "speed": desk.speed,
        "position_s": desk.position_s,
        "duration_s": desk.duration_s,
        "at_end": desk.at_end,
    })
}

fn phases(phases: &[autoplug_tester::PhaseTiming]) -> Vec<Value> {
    Phase::ALL
        .iter()
        .filter_map(|phase| {
            let p = phases.iter().find(|p| p.phase == *phase)?;
            Some(json!({ "phase": phase.name(), "s": p.duration_us as f64 * 1e-6 }))
        })
        .collect()
}

impl Observer for Session<'_> {
    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState) {
        self.watch.on_frame(frame, update, state);
        if let Some(sink) = self.recording.as_mut() {
            sink.on_frame(frame, update, state);
        }
        self.publisher.on_frame(frame, update, state);
        self.housekeeping(state);
    }

    fn on_idle(&mut self, state: &CarState) {
        self.watch.on_idle(state);
        if let Some(sink) = self.recording.as_mut() {
            sink.on_idle(state);
        }
        self.publisher.on_idle(state);
        self.housekeeping(state);
    }
}
