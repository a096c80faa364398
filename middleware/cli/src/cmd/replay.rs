//! `autoplug replay`: the gateway on a recorded log, its report printed at the end.

use std::io::Write;

use super::{incomplete, strictness};
use crate::cli::{CliError, ReplayArgs};
use autoplug_gateway_app::{open_trip_log, report_trip_log};

/// Runs the gateway over the log (into the trip database with `--db`) and prints the bus,
/// the signals, the verdicts, the trouble codes heard and the trips.
pub(crate) fn run(args: ReplayArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let ReplayArgs {
        log,
        speed,
        lenient,
        force,
        db,
        vehicle,
    } = args;
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

/// Why the ECUs of a log were not judged.
fn not_judged(run: &autoplug_live::gateway::LogRun) -> String {
    format!(
        "the bus is {} (--force judges it anyway)",
        run.recognition.summary()
    )
}
