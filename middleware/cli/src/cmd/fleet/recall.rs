//! `autoplug fleet recall`: the vehicles carrying what an inventory query describes.

use std::io::Write;

use super::{io, json, open};
use crate::fleet_cli::{DbArgs, InventoryArgs};

/// Lists each vehicle that matched with the ECU that did, as a table or JSON.
pub(crate) fn run(
    db: &DbArgs,
    query: &InventoryArgs,
    as_json: bool,
    out: &mut dyn Write,
) -> Result<(), String> {
    let hits = open(db)?
        .recall_by_inventory(&query.query())
        .map_err(|e| e.to_string())?;
    if as_json {
        writeln!(out, "{}", json(&hits)?).map_err(io)?;
        return Ok(());
    }
    writeln!(
        out,
        "{:<17} {:<13} {:<16} {:<9} {:<16} serial",
        "VIN", "ECU", "part number", "software", "hardware"
    )
    .map_err(io)?;
    for h in &hits {
        let o = |v: &Option<String>| v.clone().unwrap_or_else(|| "-".into());
        writeln!(
            out,
            "{:<17} {:<13} {:<16} {:<9} {:<16} {}",
            h.vin,
            h.ecu,
            o(&h.part_number),
            o(&h.software_version),
            o(&h.hardware_version),
            o(&h.serial)
        )
        .map_err(io)?;
    }
    let vehicles: std::collections::BTreeSet<&str> = hits.iter().map(|h| h.vin.as_str()).collect();
    writeln!(out, "{} vehicle(s)", vehicles.len()).map_err(io)?;
    Ok(())
}
