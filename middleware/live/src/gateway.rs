//! The gateway's commands: `autoplug gateway --bus URL` (live: the status line, the
//! recording, trips into the store), `autoplug replay LOG` (the same pipeline on a log, as
//! fast as possible or paced), `autoplug diagnose LOG` (the verdict table, or JSON for
//! scripts), and the tables they print. Live and recorded input go through the same
//! pipeline and the same [`Watch`].

use std::io::Write;
use std::path::Path;

use autoplug_diagnostics::{DtcMonitor, EcuDiagnosis, Recognition, Verdict};
use autoplug_gateway::{CarState, FrameSource, LogSource, Paced, Pipeline, Strictness};
use autoplug_store::{TripDetail, TripRow};
use autoplug_trips::{TripEnd, TripStats};
use serde::Serialize;

use crate::watch::{TripLog, Watch};
use autoplug_tester::names::ecu_name;

/// What a run over a log found.
pub struct LogRun {
    /// The diagnosis of each ECU.
    pub diagnoses: Vec<EcuDiagnosis>,
    /// Whether the bus is an AutoPlug car: the diagnoses mean something only if it is.
    pub recognition: Recognition,
    /// The state at the end.
    pub pipeline: Pipeline,
    /// The trips found, in order.
    pub trips: Vec<(TripStats, TripEnd)>,
    /// Where the trips were stored, if anywhere, and how that went.
    pub trip_log: Option<TripLog>,
    /// The trouble codes heard in the log.
    pub dtcs: DtcMonitor,
}

/// Runs the gateway pipeline with the diagnostics and trips over a log file; trips go to
/// `trip_log` if given. A log that cannot be read to its end gives the run up to the
/// damage ([`Pipeline::incomplete`] says why).
pub fn run_log(
    path: &Path,
    strictness: Strictness,
    speed: Option<f64>,
    trip_log: Option<TripLog>,
) -> Result<LogRun, String> {
    let source = LogSource::open(path).map_err(|e| e.to_string())?;
    let mut source: Box<dyn FrameSource> = match speed {
        Some(speed) => Box::new(Paced::new(source, speed)),
        None => Box::new(source),
    };
    let mut pipeline = Pipeline::new(strictness);
    let mut watch = Watch::new(trip_log);
    pipeline
        .run(source.as_mut(), &mut [&mut watch], &mut || false)
        .map_err(|e| e.to_string())?;
    watch.finish(pipeline.state());
    Ok(LogRun {
        diagnoses: watch.diagnostics.report(pipeline.state()),
        recognition: watch.diagnostics.recognition(),
        pipeline,
        trips: watch.ended,
        trip_log: watch.trip_log,
        dtcs: watch.dtcs,
    })
}

/// The trouble codes the ECUs reported on the bus (to whichever tester asked), latest per
/// ECU; nothing if none was heard.
pub fn heard_dtcs(dtcs: &DtcMonitor, out: &mut dyn Write) -> std::io::Result<()> {
    for report in dtcs.latest() {
        if report.entries.is_empty() {
            writeln!(
                out,
                "DTCs {} at {:.2} s: none",
                ecu_name(report.ecu),
                report.read_at_us as f64 * 1e-6
            )?;
        }
        for e in &report.entries {
            writeln!(
                out,
                "DTCs {} at {:.2} s: {} status 0x{:02X}: {}",
                ecu_name(report.ecu),
                report.read_at_us as f64 * 1e-6,
                e.dtc,
                e.status,
                autoplug_diagnostics::describe_dtc(e.dtc)
            )?;
        }
    }
    Ok(())
}

/// The trips of a run, one line each.
pub fn trips_table(trips: &[(TripStats, TripEnd)], out: &mut dyn Write) -> std::io::Result<()> {
    writeln!(
        out,
        "{:>4} {:>9} {:>9} {:>9} {:>8} {:>8} {:>6} {:>11} {:>5} {:>6} {:>8} {:>9}  end",
        "trip",
        "start s",
        "duration",
        "km",
        "fuel L",
        "max km/h",
        "shifts",
        "ABS (s)",
        "hard",
        "cruise",
        "diff",
        "mean km/h"
    )?;
    for (i, (s, end)) in trips.iter().enumerate() {
        trip_line(&(i + 1).to_string(), s, end.name(), out)?;
    }
    Ok(())
}

fn trip_line(id: &str, s: &TripStats, end: &str, out: &mut dyn Write) -> std::io::Result<()> {
    writeln!(
        out,
        "{:>4} {:>9.2} {:>8.1}s {:>9.3} {:>8.3} {:>8.1} {:>6} {:>3} ({:>5.2}) {:>5} {:>5.0} s {:>3} ({:>3.1}) {:>9.1}  {end}",
        id,
        s.start_us as f64 * 1e-6,
        s.duration_s,
        s.distance_m / 1000.0,
        s.fuel_used_l,
        s.max_speed_kmh,
        s.shifts,
        s.abs_interventions,
        s.abs_time_s,
        s.hard_brakings,
        s.cruise_time_s,
        s.diff_interventions,
        s.diff_time_s,
        s.mean_speed_kmh,
    )
}

/// `autoplug trips list`: the stored trips, newest first.
pub fn stored_trips_table(rows: &[TripRow], out: &mut dyn Write) -> std::io::Result<()> {
    writeln!(out, "{:<24} {:<12} source", "started (UTC)", "vehicle")?;
    for row in rows {
        writeln!(
            out,
            "{:<24} {:<12} {} [{}]",
            utc(row.started_at_unix_ms),
            row.vehicle,
            row.source,
            row.status.name()
        )?;
        trip_line(
            &row.id.to_string(),
            &row.stats,
            row.end.map_or("-", |e| e.name()),
            out,
        )?;
    }
    Ok(())
}

/// `autoplug trips show ID`: one trip with its verdicts and trouble codes.
pub fn trip_detail(detail: &TripDetail, out: &mut dyn Write) -> std::io::Result<()> {
    let row = &detail.row;
    let s = &row.stats;
    writeln!(out, "trip {} of {} ({})", row.id, row.vehicle, row.source)?;
    writeln!(out, "  started          {}", utc(row.started_at_unix_ms))?;
    writeln!(
        out,
        "  status           {}{}",
        row.status.name(),
        row.end
            .map_or(String::new(), |e| format!(", ended: {}", e.name()))
    )?;
    writeln!(
        out,
        "  bus time         {:.3}-{:.3} s",
        s.start_us as f64 * 1e-6,
        s.end_us as f64 * 1e-6
    )?;
    writeln!(
        out,
        "  duration         {:.1} s ({:.1} s moving)",
        s.duration_s, s.moving_time_s
    )?;
    writeln!(out, "  distance         {:.3} km", s.distance_m / 1000.0)?;
    writeln!(out, "  fuel used        {:.3} L", s.fuel_used_l)?;
    writeln!(
        out,
        "  speed            max {:.0} km/h, mean {:.1} km/h",
        s.max_speed_kmh, s.mean_speed_kmh
    )?;
    writeln!(out, "  shifts           {}", s.shifts)?;
    writeln!(
        out,
        "  ABS              {} intervention(s), {:.2} s",
        s.abs_interventions, s.abs_time_s
    )?;
    writeln!(out, "  hard brakings    {}", s.hard_brakings)?;
    writeln!(out, "  cruise           {:.1} s", s.cruise_time_s)?;
    writeln!(
        out,
        "  differential     {} intervention(s), {:.2} s",
        s.diff_interventions, s.diff_time_s
    )?;
    writeln!(out, "  verdicts:")?;
    for v in &detail.verdicts {
        writeln!(
            out,
            "    {:<13} {:<8} {:>10} {:<10} {}: {}",
            v.ecu,
            v.verdict,
            v.number.map_or("-".into(), |n| format!("{n:.3}")),
            v.unit,
            v.routine,
            v.evidence
        )?;
    }
    if detail.dtcs.is_empty() {
        writeln!(out, "  DTCs: none recorded")?;
    }
    for d in &detail.dtcs {
        writeln!(
            out,
            "    DTC {} {} status 0x{:02X}: {}",
            d.ecu, d.code, d.status, d.description
        )?;
    }
    writeln!(
        out,
        "  series: {} signal(s), 1 s buckets (mean, min, max)",
        detail.series_signals.len()
    )?;
    Ok(())
}

/// Milliseconds since the epoch as `YYYY-mm-dd HH:MM:SS`, UTC.
fn utc(unix_ms: i64) -> String {
    let t = autoplug_logs::Utc::from_unix_us(u64::try_from(unix_ms).unwrap_or(0) * 1000);
    format!(
        "{:04}-{:02}-{:02} {:02}:{:02}:{:02}",
        t.year, t.month, t.day, t.hour, t.minute, t.second
    )
}

/// The verdict table, one line per ECU with its deciding finding.
pub fn verdict_table(diagnoses: &[EcuDiagnosis], out: &mut dyn Write) -> std::io::Result<()> {
    writeln!(
        out,
        "{:<13} {:<8} {:>10} {:<10} {:>15} {:<15} finding",
        "ECU", "verdict", "number", "unit", "suspect/faulty", "window"
    )?;
    for d in diagnoses {
        let Some(f) = d.headline() else { continue };
        writeln!(
            out,
            "{:<13} {:<8} {:>10} {:<10} {:>15} {:<15} {}: {}",
            ecu_name(d.ecu),
            d.verdict.name(),
            f.value.map_or("-".into(), |v| format!("{v:.3}")),
            f.unit,
            format!("> {} / > {}", f.suspect_above, f.faulty_above),
            f.window.map_or("-".into(), |w| w.to_string()),
            f.routine,
            f.evidence
        )?;
    }
    Ok(())
}

/// One ECU in `autoplug diagnose --json`.
#[derive(Serialize)]
struct JsonEcu<'a> {
    ecu: &'a str,
    node: Option<u8>,
    verdict: Verdict,
    routine: &'a str,
    number: Option<f64>,
    unit: &'a str,
    suspect_above: f64,
    faulty_above: f64,
    window_s: Option<[f64; 2]>,
    evidence: &'a str,
    findings: &'a [autoplug_diagnostics::Finding],
}

/// `autoplug diagnose --json`.
#[derive(Serialize)]
struct JsonReport<'a> {
    log: String,
    frames: u64,
    malformed_lines_skipped: u64,
    frames_dropped_by_logger: u64,
    /// CAN FD frames, which the classic bus's diagnostics leave aside.
    can_fd_frames: u64,
    /// Why the log could not be read to its end; the report covers what came before.
    incomplete: Option<String>,
    vehicle: &'a Recognition,
    /// Whether the ECUs were judged (an AutoPlug car, or `--force`).
    judged: bool,
    any_faulty: bool,
    ecus: Vec<JsonEcu<'a>>,
}

/// The diagnosis as JSON; `judged` false leaves the ECUs out (not an AutoPlug car).
pub fn verdict_json(path: &Path, run: &LogRun, judged: bool) -> String {
    let diagnoses: &[EcuDiagnosis] = if judged { &run.diagnoses } else { &[] };
    let ecus = diagnoses
        .iter()
        .filter_map(|d| {
            let f = d.headline()?;
            Some(JsonEcu {
                ecu: ecu_name(d.ecu),
                node: d.ecu.diag_node_number(),
                verdict: d.verdict,
                routine: f.routine,
                number: f.value,
                unit: f.unit,
                suspect_above: f.suspect_above,
                faulty_above: f.faulty_above,
                window_s: f
                    .window
                    .map(|w| [w.from_us as f64 * 1e-6, w.to_us as f64 * 1e-6]),
                evidence: &f.evidence,
                findings: &d.findings,
            })
        })
        .collect();
    let report = JsonReport {
        log: path.display().to_string(),
        frames: run.pipeline.state().counters().frames,
        malformed_lines_skipped: run.pipeline.malformed(),
        frames_dropped_by_logger: run.pipeline.dropped_by_logger(),
        can_fd_frames: run.pipeline.state().counters().fd_frames,
        incomplete: run.pipeline.incomplete().map(ToString::to_string),
        vehicle: &run.recognition,
        judged,
        any_faulty: any_faulty(diagnoses),
        ecus,
    };
    serde_json::to_string_pretty(&report).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
}

/// Whether any ECU was judged faulty.
pub fn any_faulty(diagnoses: &[EcuDiagnosis]) -> bool {
    diagnoses.iter().any(|d| d.verdict == Verdict::Faulty)
}

/// What the bus held: frames, messages with their measured periods, foreign traffic, and
/// whether it is an AutoPlug car at all.
pub fn bus_summary(run: &LogRun, out: &mut dyn Write) -> std::io::Result<()> {
    let state = run.pipeline.state();
    let c = state.counters();
    writeln!(
        out,
        "{} frames over {:.1} s: {} diagnostic, {} unknown identifier(s) in {} frame(s), {} extended, {} CAN FD (not for a classic bus), {} remote, {} error frames, {} out of time order, {} malformed line(s) skipped, {} frame(s) dropped by the logger",
        c.frames,
        state.now_us() as f64 * 1e-6
            - state
                .stats()
                .iter()
                .filter_map(|s| s.first_us)
                .min()
                .map_or(0.0, |t| t as f64 * 1e-6),
        c.diagnostic_frames,
        c.unknown_ids.len(),
        c.unknown_frames,
        c.extended_frames,
        c.fd_frames,
        c.remote_frames,
        c.error_frames,
        c.time_backwards,
        run.pipeline.malformed(),
        run.pipeline.dropped_by_logger()
    )?;
    writeln!(out, "bus: {}", run.recognition.summary())?;
    writeln!(
        out,
        "{:<16} {:>5} {:>8} {:>10} {:>10} {:>8} {:>8}",
        "message", "id", "frames", "period ms", "jitter ms", "invalid", "bad len"
    )?;
    for (spec, s) in autoplug_can::MESSAGES.iter().zip(state.stats()) {
        writeln!(
            out,
            "{:<16} 0x{:03X} {:>8} {:>10} {:>10} {:>8} {:>8}",
            spec.name,
            spec.id,
            s.count,
            s.period_ms().map_or("-".into(), |p| format!("{p:.2}")),
            s.jitter_ms().map_or("-".into(), |j| format!("{j:.2}")),
            s.invalid,
            s.wrong_length
        )?;
    }
    Ok(())
}

/// The latest value of every signal, with its VSS path and freshness.
pub fn signal_table(state: &CarState, out: &mut dyn Write) -> std::io::Result<()> {
    let now = state.now_us();
    for s in state.signals() {
        let value = match s.label() {
            Some(label) => label.to_string(),
            None => format!("{} {}", s.value, s.spec.unit),
        };
        writeln!(
            out,
            "{:<28} {:<14} {:<58} {}",
            format!("{}.{}", s.message.name, s.spec.name),
            value,
            s.vss(),
            if s.is_fresh(now) { "fresh" } else { "stale" }
        )?;
    }
    Ok(())
}
