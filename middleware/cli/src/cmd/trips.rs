//! `autoplug trips list` and `autoplug trips show`: the trip database, read only.

use std::io::Write;
use std::path::Path;

use autoplug_store::{SqliteStore, TripStore};

use crate::cli::CliError;

/// Lists the trips (of one vehicle), newest first, as a table or JSON.
pub(crate) fn list(
    db: &Path,
    vehicle: Option<&str>,
    json: bool,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let store = open_existing_store(db)?;
    let rows = store
        .trips(vehicle)
        .map_err(|e| CliError::Log(e.to_string()))?;
    if json {
        let text = serde_json::to_string_pretty(&rows).map_err(|e| CliError::Log(e.to_string()))?;
        writeln!(out, "{text}")?;
    } else if rows.is_empty() {
        writeln!(out, "no trips in {}", db.display())?;
    } else {
        autoplug_live::gateway::stored_trips_table(&rows, out)?;
    }
    Ok(())
}

/// Shows one trip: statistics, verdicts and trouble codes, or JSON.
pub(crate) fn show(id: i64, db: &Path, json: bool, out: &mut dyn Write) -> Result<(), CliError> {
    let store = open_existing_store(db)?;
    let detail = store
        .trip(autoplug_store::TripId(id))
        .map_err(|e| CliError::Log(e.to_string()))?
        .ok_or_else(|| CliError::Log(format!("{}: there is no trip {id}", db.display())))?;
    if json {
        let text =
            serde_json::to_string_pretty(&detail).map_err(|e| CliError::Log(e.to_string()))?;
        writeln!(out, "{text}")?;
    } else {
        autoplug_live::gateway::trip_detail(&detail, out)?;
    }
    Ok(())
}

/// Opens a trip database that must exist (the read commands never create one).
fn open_existing_store(db: &Path) -> Result<SqliteStore, CliError> {
    if !db.exists() {
        return Err(CliError::Log(format!(
            "{}: no such trip database (the gateway creates it: autoplug gateway --db FILE)",
            db.display()
        )));
    }
    SqliteStore::open(db).map_err(|e| CliError::Log(e.to_string()))
}
