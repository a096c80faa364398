//! `autoplug diagnose`: every ECU of a recorded log judged, the verdict in the exit status.

use std::io::Write;

use super::{incomplete, strictness};
use crate::cli::{CliError, DiagnoseArgs};

/// Judges the log's ECUs and prints the verdicts (a table, or JSON); a faulty ECU, a
/// damaged log or a bus that is not an AutoPlug car is an error of its own (exit status
/// 3, 4, 5).
pub(crate) fn run(args: DiagnoseArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let DiagnoseArgs {
        log,
        json,
        lenient,
        force,
    } = args;
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
