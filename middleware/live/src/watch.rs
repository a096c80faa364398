//! What the gateway does with every frame, live or on a log: the diagnostics, the trips
//! and, when a store is given, the trips written to it as they happen (begun, checkpointed
//! every [`CHECKPOINT_US`] of bus time, finished with the verdicts). A store that fails (a
//! full disk) stops storing with its error kept for the report; the watching goes on.

use std::io::Write;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use autoplug_diagnostics::{describe_dtc, Diagnostics, DtcMonitor, EcuDiagnosis};
use autoplug_gateway::{CarState, Observer, Update};
use autoplug_logs::LogFrame;
use autoplug_store::{
    DtcRecord, EcuIdentity, FinishedTrip, NewTrip, TripId, TripStore, VerdictRecord,
};
use autoplug_trips::{CompletedTrip, TripEnd, TripStats, TripTracker};

use autoplug_tester::bus_tester::BusTester;
use autoplug_tester::names::ecu_name;
use autoplug_tester::{vehicle_vin, EcuIdentification};

/// How long a real bus may be silent before its trip ends: the trip rule's own.
pub const LIVE_SILENCE: Duration = Duration::from_micros(autoplug_trips::SILENT_AFTER_US);

/// How often the trip in progress is written to the store, µs of bus time: a crash (kill
/// -9, power loss) loses at most this much of a trip's statistics.
pub const CHECKPOINT_US: u64 = 5_000_000;

/// How often the findings are kept while the bus is alive, µs of bus time: a trip that
/// ends on the bus's silence ends with the last of them.
pub const ALIVE_FINDINGS_US: u64 = 1_000_000;

/// Where trips go, and what became of them.
pub struct TripLog {
    store: Box<dyn TripStore>,
    vehicle: String,
    source: String,
    /// The vehicle is named by the VIN its ECUs answer: no trip is begun in the store
    /// until the gateway's tester has read the identification (a few hundred ms).
    awaiting_vin: bool,
    /// Trips that ended while the VIN was awaited.
    held: Vec<CompletedTrip>,
    open: Option<TripId>,
    last_checkpoint_us: u64,
    /// Trips written to the store, finished.
    pub stored: Vec<TripId>,
    /// Why storing stopped, if it did.
    pub failure: Option<String>,
}

impl TripLog {
    /// Trips of `vehicle`, seen on `source`, into `store`.
    pub fn new(store: Box<dyn TripStore>, vehicle: &str, source: &str) -> Self {
        Self {
            store,
            vehicle: vehicle.to_string(),
            source: source.to_string(),
            awaiting_vin: false,
            held: Vec::new(),
            open: None,
            last_checkpoint_us: 0,
            stored: Vec::new(),
            failure: None,
        }
    }

    /// Names the vehicle by the VIN its ECUs answer (F190), `vehicle` if none does: for a
    /// gateway whose tester reads the identification (nothing is stored before it has).
    pub fn following_vin(mut self) -> Self {
        self.awaiting_vin = true;
        self
    }

    /// The vehicle's name in the store: its VIN, or the name given.
    pub fn vehicle(&self) -> &str {
        &self.vehicle
    }

    /// The store (for reading back what was written).
    pub fn store(&self) -> &dyn TripStore {
        self.store.as_ref()
    }

    fn record_inventory(&mut self, ecus: &[EcuIdentity]) {
        if self.failure.is_some() || ecus.is_empty() {
            return;
        }
        if let Err(e) = self.store.record_inventory(&self.vehicle, unix_ms(), ecus) {
            self.fail(e);
        }
    }

    fn fail(&mut self, error: impl ToString) {
        self.failure = Some(format!("trips no longer stored: {}", error.to_string()));
        self.open = None;
    }

    fn sync(
        &mut self,
        done: Vec<CompletedTrip>,
        trips: &mut TripTracker,
        report: impl Fn(TripEnd) -> Findings,
        now_us: u64,
    ) {
        if self.failure.is_some() {
            return;
        }
        if self.awaiting_vin {
            return self.held.extend(done);
        }
        let done: Vec<CompletedTrip> = std::mem::take(&mut self.held)
            .into_iter()
            .chain(done)
            .collect();
        for done in done {
            if let Err(e) = self.finish(done, &report) {
                return self.fail(e);
            }
        }
        let Some(current) = trips.current() else {
            return;
        };
        let id = match self.open {
            Some(id) => id,
            None => {
                let trip = NewTrip {
                    vehicle: self.vehicle.clone(),
                    source: self.source.clone(),
                    started_at_unix_ms: unix_ms(),
                    start_us: current.start_us,
                };
                match self.store.begin_trip(&trip) {
                    Ok(id) => {
                        self.open = Some(id);
                        self.last_checkpoint_us = now_us;
                        id
                    }
                    Err(e) => return self.fail(e),
                }
            }
        };
        if now_us.saturating_sub(self.last_checkpoint_us) >= CHECKPOINT_US {
            self.last_checkpoint_us = now_us;
            let series = trips.take_series();
            if let Err(e) = self.store.checkpoint_trip(id, &current, &series) {
                self.fail(e);
            }
        }
    }

    fn finish(
        &mut self,
        done: CompletedTrip,
        report: &impl Fn(TripEnd) -> Findings,
    ) -> Result<(), autoplug_store::StoreError> {
        let id = match self.open.take() {
            Some(id) => id,
            // A trip that began and ended between two frames: begin it now.
            None => self.store.begin_trip(&NewTrip {
                vehicle: self.vehicle.clone(),
                source: self.source.clone(),
                started_at_unix_ms: unix_ms(),
                start_us: done.stats.start_us,
            })?,
        };
        let (verdicts, dtcs) = report(done.end);
        let finished = FinishedTrip {
            stats: done.stats,
            end: done.end,
            verdicts,
            dtcs,
        };
        self.store.finish_trip(id, &finished, &done.series)?;
        self.stored.push(id);
        Ok(())
    }
}

/// The verdicts and the trouble codes a trip ends with.
type Findings = (Vec<VerdictRecord>, Vec<DtcRecord>);

/// Every ECU's verdict and the latest trouble codes heard on the bus.
fn findings(diagnostics: &Diagnostics, dtcs: &DtcMonitor, state: &CarState) -> Findings {
    let verdicts = diagnostics
        .report(state)
        .iter()
        .filter_map(verdict_record)
        .collect();
    let dtcs = dtcs
        .latest()
        .iter()
        .flat_map(|r| {
            r.entries.iter().map(|e| DtcRecord {
                ecu: ecu_name(r.ecu).to_string(),
                code: e.dtc.to_string(),
                status: e.status,
                description: describe_dtc(e.dtc),
            })
        })
        .collect();
    (verdicts, dtcs)
}

/// The identification the gateway read, as the inventory keeps it.
pub fn identities(rows: &[EcuIdentification]) -> Vec<EcuIdentity> {
    let text = |v: &Result<Vec<u8>, autoplug_tester::UdsError>| {
        v.as_ref().ok().map(|b| {
            String::from_utf8_lossy(b)
                .trim_end_matches('\0')
                .to_string()
        })
    };
    rows.iter()
        .filter(|r| r.answered())
        .map(|r| EcuIdentity {
            ecu: ecu_name(r.ecu).to_string(),
            node: r.ecu.diag_node_number().unwrap_or(0),
            part_number: text(&r.part_number),
            software_version: text(&r.software_version),
            hardware_version: text(&r.hardware_version),
            serial_number: r
                .serial_number
                .as_ref()
                .ok()
                .map(|b| b.iter().map(|x| format!("{x:02X}")).collect::<String>()),
        })
        .collect()
}

fn unix_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as i64)
}

/// An ECU's diagnosis as the store keeps it: its verdict and the finding that decides it.
pub fn verdict_record(d: &EcuDiagnosis) -> Option<VerdictRecord> {
    let f = d.headline()?;
    Some(VerdictRecord {
        ecu: ecu_name(d.ecu).to_string(),
        verdict: d.verdict.name().to_string(),
        routine: f.routine.to_string(),
        number: f.value,
        unit: f.unit.to_string(),
        suspect_above: f.suspect_above,
        faulty_above: f.faulty_above,
        window_s: f
            .window
            .map(|w| (w.from_us as f64 * 1e-6, w.to_us as f64 * 1e-6)),
        evidence: f.evidence.clone(),
    })
}

/// A one-line view of the car for the terminal, every `every` of wall time.
pub struct StatusLine<'a> {
    out: &'a mut dyn Write,
    every: std::time::Duration,
    last: Option<Instant>,
}

impl<'a> StatusLine<'a> {
    /// Prints to `out` once per `every`, the first time `every` from now (before that
    /// every ECU would be "no data").
    pub fn new(out: &'a mut dyn Write, every: std::time::Duration) -> Self {
        Self {
            out,
            every,
            last: Some(Instant::now()),
        }
    }
}

/// The gateway's watch over the traffic: diagnostics, trips, the store, the status line.
pub struct Watch<'a> {
    /// Every ECU's diagnostic routines.
    pub diagnostics: Diagnostics,
    /// The trips.
    pub trips: TripTracker,
    /// Where the trips go, if anywhere.
    pub trip_log: Option<TripLog>,
    /// The terminal view, if any.
    pub status: Option<StatusLine<'a>>,
    /// The trips that have ended, in order.
    pub ended: Vec<(TripStats, TripEnd)>,
    /// The trouble codes heard on the bus.
    pub dtcs: DtcMonitor,
    /// The gateway's own tester, when it may transmit.
    pub tester: Option<BusTester>,
    /// The ECUs' identification, once the tester read it.
    pub identification: Option<Vec<EcuIdentification>>,
    /// The link to the fleet, if the gateway reports to one.
    pub fleet: Option<autoplug_fleet_agent::link::FleetLink>,
    /// The findings as of the last time the bus was alive (bus time, findings), taken
    /// every [`ALIVE_FINDINGS_US`] while a trip runs.
    alive_findings: Option<(u64, Findings)>,
    /// On a real bus: how long it may stay silent, in wall time, before the trip in
    /// progress ends (bus time stands still while no frame comes). `None` for a log or the
    /// virtual car, whose silences are in their own time.
    pub silent_after: Option<Duration>,
    idle_since: Option<Instant>,
}

impl Default for Watch<'_> {
    fn default() -> Self {
        Self::new(None)
    }
}

impl<'a> Watch<'a> {
    /// Diagnostics and trips; trips stored in `trip_log` if given (without one, no series
    /// is kept).
    pub fn new(trip_log: Option<TripLog>) -> Self {
        Self {
            diagnostics: Diagnostics::new(),
            trips: if trip_log.is_some() {
                TripTracker::new()
            } else {
                TripTracker::without_series()
            },
            trip_log,
            status: None,
            ended: Vec::new(),
            dtcs: DtcMonitor::new(),
            tester: None,
            identification: None,
            fleet: None,
            alive_findings: None,
            silent_after: None,
            idle_since: None,
        }
    }

    /// The input has ended: the trip in progress ends and is stored.
    pub fn finish(&mut self, state: &CarState) {
        self.trips.finish();
        self.sync(state);
    }

    fn sync(&mut self, state: &CarState) {
        let done = self.trips.take_completed();
        self.ended
            .extend(done.iter().map(|t| (t.stats.clone(), t.end)));
        let (diagnostics, dtcs, alive) = (&self.diagnostics, &self.dtcs, &self.alive_findings);
        // A trip that ended on the bus's silence ends with what was judged while the bus
        // was alive: judged now, every ECU would be "no data".
        let report = |end: TripEnd| match (end, alive) {
            (TripEnd::BusSilent, Some((_, findings))) => findings.clone(),
            _ => findings(diagnostics, dtcs, state),
        };
        if let Some(fleet) = self.fleet.as_mut() {
            for trip in &done {
                let (verdicts, dtcs) = report(trip.end);
                fleet.on_trip(trip, verdicts, dtcs);
            }
        }
        if let Some(log) = self.trip_log.as_mut() {
            log.sync(done, &mut self.trips, report, state.now_us());
        }
    }

    /// The identification the tester read (again, after a flash), into the inventory.
    fn take_identities(&mut self) {
        let Some(rows) = self.tester.as_mut().and_then(|t| t.take_identities()) else {
            return;
        };
        if let Some(log) = self.trip_log.as_mut() {
            if std::mem::take(&mut log.awaiting_vin) {
                if let Ok(Some(vin)) = vehicle_vin(&rows) {
                    log.vehicle = vin.to_string();
                }
            }
            log.record_inventory(&identities(&rows));
        }
        if let Some(fleet) = self.fleet.as_mut() {
            fleet.on_identification(vehicle_vin(&rows), identities(&rows));
        }
        self.identification = Some(rows);
    }

    fn maybe_print_status(&mut self, state: &CarState) {
        let Some(status) = self.status.as_mut() else {
            return;
        };
        let now = Instant::now();
        if status
            .last
            .is_some_and(|t| now.duration_since(t) < status.every)
        {
            return;
        }
        status.last = Some(now);
        let line = status_text(state, &self.diagnostics, &self.trips);
        // The terminal view is best effort: a closed pipe must not stop the gateway.
        let _ = writeln!(status.out, "{line}");
    }
}

/// The car in one line: speed, RPM, gear, fuel, the trip so far and the diagnosis.
pub fn status_text(state: &CarState, diagnostics: &Diagnostics, trips: &TripTracker) -> String {
    use autoplug_can::{EngineMsg, TransMsg, VehicleSpeedMsg};
    let engine = state.get::<EngineMsg>();
    let gear = state.signal_of(TransMsg::ID, 0).and_then(|s| s.label());
    let trip = trips.current().map_or("no trip".to_string(), |t| {
        format!(
            "trip {:.2} km, {:.0} s",
            t.distance_m / 1000.0,
            t.duration_s
        )
    });
    let report = diagnostics.report(state);
    let flagged: Vec<String> = report
        .iter()
        .filter(|d| {
            !matches!(
                d.verdict,
                autoplug_diagnostics::Verdict::Ok | autoplug_diagnostics::Verdict::NotExercised
            )
        })
        .map(|d| {
            let number = d
                .headline()
                .and_then(|f| f.value.map(|v| format!(" {v:.2} {}", f.unit)))
                .unwrap_or_default();
            format!("{} {}{number}", ecu_name(d.ecu), d.verdict.name())
        })
        .collect();
    format!(
        "t {:>8.1} s | {:>3.0} km/h | {:>4.0} rpm | gear {:<7} | fuel {:>5.2} L | {} | {}",
        state.now_us() as f64 * 1e-6,
        state.get::<VehicleSpeedMsg>().vehicle_speed,
        engine.engine_rpm,
        gear.unwrap_or("-"),
        engine.fuel_level,
        trip,
        if flagged.is_empty() {
            "all ECUs ok".to_string()
        } else {
            flagged.join(", ")
        }
    )
}

impl Observer for Watch<'_> {
    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState) {
        self.idle_since = None;
        self.diagnostics.on_frame(frame, update, state);
        self.dtcs.on_frame(frame, update, state);
        if let Some(tester) = self.tester.as_mut() {
            tester.on_frame(frame, update, state);
            self.take_identities();
        }
        self.trips.on_frame(frame, update, state);
        let t = frame.t_us;
        // Only the ECUs' own traffic shows the bus alive: the gateway's tester may still
        // be asking a bus that has gone to sleep.
        if matches!(update, Update::Message { .. })
            && self
                .alive_findings
                .as_ref()
                .is_none_or(|(at, _)| t.saturating_sub(*at) >= ALIVE_FINDINGS_US)
            && self.trips.current().is_some()
        {
            self.alive_findings = Some((t, findings(&self.diagnostics, &self.dtcs, state)));
        }
        self.sync(state);
        if let Some(fleet) = self.fleet.as_mut() {
            fleet.poll(state, self.tester.as_mut());
        }
        self.maybe_print_status(state);
    }

    fn on_idle(&mut self, state: &CarState) {
        if let Some(tester) = self.tester.as_mut() {
            tester.on_idle(state);
            self.take_identities();
        }
        self.trips.on_idle(state);
        self.sync(state);
        if let Some(fleet) = self.fleet.as_mut() {
            fleet.poll(state, self.tester.as_mut());
        }
        let Some(silent_after) = self.silent_after else {
            return self.maybe_print_status(state);
        };
        // The first idle call comes 50 ms after the last frame (the pipeline's IDLE_AFTER).
        let since = *self.idle_since.get_or_insert_with(Instant::now);
        if since.elapsed() >= silent_after && self.trips.current().is_some() {
            self.trips.bus_silent();
            self.sync(state);
        }
        self.maybe_print_status(state);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoplug_can::{CanMessage, VehicleSpeedMsg};
    use autoplug_gateway::{FrameSource, Pipeline, Poll, SourceError, Strictness};

    /// Frames for a while, then a bus that stays silent.
    struct Falls {
        frames: std::vec::IntoIter<LogFrame>,
    }

    impl FrameSource for Falls {
        fn poll(&mut self, max_wait: Duration) -> Result<Poll, SourceError> {
            Ok(match self.frames.next() {
                Some(f) => Poll::Frame(f),
                None => {
                    std::thread::sleep(max_wait);
                    Poll::Idle
                }
            })
        }

        fn describe(&self) -> String {
            "a bus that falls silent".into()
        }
    }

    #[test]
    fn a_live_bus_that_falls_silent_ends_its_trip_without_another_frame() {
        let frames: Vec<LogFrame> = (0..100)
            .map(|i| {
                LogFrame::from_can(
                    i * 10_000,
                    0,
                    &VehicleSpeedMsg {
                        vehicle_speed: 50.0,
                    }
                    .frame(),
                )
            })
            .collect();
        let mut source = Falls {
            frames: frames.into_iter(),
        };
        let mut watch = Watch::new(None);
        watch.silent_after = Some(Duration::from_millis(200));
        let mut pipeline = Pipeline::new(Strictness::Strict);
        let started = Instant::now();
        pipeline
            .run(&mut source, &mut [&mut watch], &mut || {
                started.elapsed() > Duration::from_secs(2)
            })
            .unwrap();
        assert_eq!(watch.ended.len(), 1, "ended while the bus was silent");
        assert_eq!(watch.ended[0].1, TripEnd::BusSilent);
        assert_eq!(watch.ended[0].0.end_us, 990_000);

        // A log's own silences are in its time: a replay's watch ignores the wall clock.
        let mut replay = Watch::new(None);
        let mut source = Falls {
            frames: vec![LogFrame::from_can(
                0,
                0,
                &VehicleSpeedMsg {
                    vehicle_speed: 50.0,
                }
                .frame(),
            )]
            .into_iter(),
        };
        let started = Instant::now();
        let mut pipeline = Pipeline::new(Strictness::Strict);
        pipeline
            .run(&mut source, &mut [&mut replay], &mut || {
                started.elapsed() > Duration::from_millis(300)
            })
            .unwrap();
        assert!(replay.ended.is_empty());
    }
}
