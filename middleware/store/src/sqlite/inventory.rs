//! The ECU inventory: a history row per identity, the newest the current one.

use rusqlite::{params, Connection, OptionalExtension};

use super::columns::u8_at;
use crate::model::EcuIdentity;

/// Records one ECU's identity (see [`crate::TripStore::record_inventory`]).
pub(super) fn put_identity(
    conn: &Connection,
    vehicle_id: i64,
    seen_at: i64,
    e: &EcuIdentity,
) -> rusqlite::Result<()> {
    let latest = conn
        .prepare_cached(
            "SELECT id, node, part_number, software_version, hardware_version, serial_number \
             FROM ecu_inventory WHERE vehicle_id = ? AND ecu = ? ORDER BY id DESC LIMIT 1",
        )?
        .query_row(params![vehicle_id, e.ecu], |r| {
            let known: [Option<String>; 4] = [r.get(2)?, r.get(3)?, r.get(4)?, r.get(5)?];
            Ok((r.get::<_, i64>(0)?, u8_at(r, 1)?, known))
        })
        .optional()?;
    let given = [
        &e.part_number,
        &e.software_version,
        &e.hardware_version,
        &e.serial_number,
    ];
    // Changed: an identifier both answered, with different values (a None is unknown,
    // not different).
    let unchanged = |node: u8, known: &[Option<String>; 4]| {
        node == e.node
            && known.iter().zip(given).all(|(k, g)| match (k, g) {
                (Some(k), Some(g)) => k == g,
                _ => true,
            })
    };
    match latest {
        Some((row, node, known)) if unchanged(node, &known) => {
            conn.prepare_cached(
                "UPDATE ecu_inventory SET part_number = coalesce(part_number, ?), \
                 software_version = coalesce(software_version, ?), \
                 hardware_version = coalesce(hardware_version, ?), \
                 serial_number = coalesce(serial_number, ?), \
                 first_seen_unix_ms = min(first_seen_unix_ms, ?), \
                 last_seen_unix_ms = max(last_seen_unix_ms, ?) WHERE id = ?",
            )?
            .execute(params![
                e.part_number,
                e.software_version,
                e.hardware_version,
                e.serial_number,
                seen_at,
                seen_at,
                row
            ])?;
        }
        _ => {
            conn.prepare_cached(
                "INSERT INTO ecu_inventory (vehicle_id, ecu, node, part_number, \
                 software_version, hardware_version, serial_number, first_seen_unix_ms, \
                 last_seen_unix_ms) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?)",
            )?
            .execute(params![
                vehicle_id,
                e.ecu,
                e.node,
                e.part_number,
                e.software_version,
                e.hardware_version,
                e.serial_number,
                seen_at,
                seen_at
            ])?;
        }
    }
    Ok(())
}

/// The current identity of each ECU of `vehicle`, first and last seen, sorted by ECU.
pub(super) fn current(
    conn: &Connection,
    vehicle: &str,
) -> rusqlite::Result<Vec<(EcuIdentity, i64, i64)>> {
    let mut stmt = conn.prepare_cached(
        "SELECT ecu, node, part_number, software_version, hardware_version, \
         serial_number, first_seen_unix_ms, last_seen_unix_ms \
         FROM ecu_current WHERE vehicle = ? ORDER BY ecu",
    )?;
    let rows = stmt.query_map([vehicle], |r| {
        let identity = EcuIdentity {
            ecu: r.get(0)?,
            node: u8_at(r, 1)?,
            part_number: r.get(2)?,
            software_version: r.get(3)?,
            hardware_version: r.get(4)?,
            serial_number: r.get(5)?,
        };
        Ok((identity, r.get(6)?, r.get(7)?))
    })?;
    rows.collect()
}
