//! `autoplug fleet vehicle`: one vehicle's inventory.

use std::io::Write;

use super::{io, json, open};
use crate::fleet_cli::DbArgs;

/// Prints the inventory of the vehicle `vin` as JSON; an error if the fleet knows none.
pub(crate) fn run(vin: &str, db: &DbArgs, out: &mut dyn Write) -> Result<(), String> {
    autoplug_vin::Vin::parse(vin).map_err(|e| format!("VIN \"{vin}\": {e}"))?;
    let rows = open(db)?
        .vehicle_inventory(vin)
        .map_err(|e| e.to_string())?;
    if rows.is_empty() {
        return Err(format!("the fleet knows no vehicle {vin}"));
    }
    writeln!(out, "{}", json(&rows)?).map_err(io)?;
    Ok(())
}
