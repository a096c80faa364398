//! The gateway commands on recorded logs: `autoplug replay LOG` (the pipeline on a log,
//! as fast as possible or paced) and `autoplug diagnose LOG` (the verdict table, or JSON
//! for scripts). They run the same pipeline and observers as the live gateway.

use std::io::Write;
use std::path::Path;

use autoplug_diagnostics::{Diagnostics, EcuDiagnosis, Verdict};
use autoplug_gateway::{CarState, FrameSource, LogSource, Paced, Pipeline, Strictness};
use serde::Serialize;

use crate::names::ecu_name;

/// What a run over a log found.
pub struct LogRun {
    /// The diagnosis of each ECU.
    pub diagnoses: Vec<EcuDiagnosis>,
    /// The state at the end.
    pub pipeline: Pipeline,
}

/// Runs the gateway pipeline with the diagnostics over a log file.
pub fn run_log(path: &Path, strictness: Strictness, speed: Option<f64>) -> Result<LogRun, String> {
    let source = LogSource::open(path).map_err(|e| e.to_string())?;
    let mut source: Box<dyn FrameSource> = match speed {
        Some(speed) => Box::new(Paced::new(source, speed)),
        None => Box::new(source),
    };
    let mut pipeline = Pipeline::new(strictness);
    let mut diagnostics = Diagnostics::new();
    pipeline
        .run(source.as_mut(), &mut [&mut diagnostics], &mut || false)
        .map_err(|e| e.to_string())?;
    Ok(LogRun {
        diagnoses: diagnostics.report(pipeline.state()),
        pipeline,
    })
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
    any_faulty: bool,
    ecus: Vec<JsonEcu<'a>>,
}

/// The diagnosis as JSON.
pub fn verdict_json(path: &Path, run: &LogRun) -> String {
    let ecus = run
        .diagnoses
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
        any_faulty: any_faulty(&run.diagnoses),
        ecus,
    };
    serde_json::to_string_pretty(&report).unwrap_or_else(|e| format!("{{\"error\": \"{e}\"}}"))
}

/// Whether any ECU was judged faulty.
pub fn any_faulty(diagnoses: &[EcuDiagnosis]) -> bool {
    diagnoses.iter().any(|d| d.verdict == Verdict::Faulty)
}

/// What the bus held: frames, messages with their measured periods, foreign traffic.
pub fn bus_summary(state: &CarState, malformed: u64, out: &mut dyn Write) -> std::io::Result<()> {
    let c = state.counters();
    writeln!(
        out,
        "{} frames over {:.1} s: {} diagnostic, {} unknown identifier(s) in {} frame(s), {} extended, {} remote, {} error frames, {} out of time order, {} malformed line(s) skipped",
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
        c.remote_frames,
        c.error_frames,
        c.time_backwards,
        malformed
    )?;
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
