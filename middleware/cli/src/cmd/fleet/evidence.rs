//! `autoplug fleet evidence`: the vehicles whose drives showed a fault or a trouble code.

use std::io::Write;

use super::{io, json, open};
use crate::fleet_cli::{DbArgs, EvidenceArgs};

/// Lists each vehicle found with its evidence (trip, ECU, what), or JSON.
pub(crate) fn run(
    db: &DbArgs,
    query: &EvidenceArgs,
    as_json: bool,
    out: &mut dyn Write,
) -> Result<(), String> {
    let query = query
        .query()
        .ok_or("name the evidence: --faulty or --dtc CODE")?;
    let hits = open(db)?
        .recall_by_evidence(&query)
        .map_err(|e| e.to_string())?;
    if as_json {
        writeln!(out, "{}", json(&hits)?).map_err(io)?;
        return Ok(());
    }
    for hit in &hits {
        writeln!(out, "{}", hit.vin).map_err(io)?;
        for e in &hit.evidence {
            writeln!(
                out,
                "  trip {:<6} {:<13} {}: {}",
                e.trip, e.ecu, e.what, e.detail
            )
            .map_err(io)?;
        }
    }
    writeln!(out, "{} vehicle(s)", hits.len()).map_err(io)?;
    Ok(())
}
