//! Reading identification: part number (F187), software version (F189), serial number
//! (F18C), hardware version (F191), the vehicle's VIN (F190) and the running image slot with
//! its boot state (F1A0) of one ECU or all nine, in the default session.
//!
//! Each DID is read with a request of its own: the ECUs' identification strings have no
//! length field, so a response to several DIDs at once could not be split where one
//! string ends and the next identifier starts.

use std::fmt::Write as _;

use autoplug_can::Node;

use autoplug_image::{BootState, ImageSlot};
use autoplug_uds::server::{did, parse_boot_slot};
use autoplug_vin::Vin;

use super::job::{EachEcu, Requests};
use super::{Response, TesterConfig, UdsError};
use crate::names::ecu_name;

/// The DIDs read, in table order: part number, software version, serial number, hardware
/// version, VIN, running slot and boot state.
pub const IDENTIFICATION_DIDS: [u16; 6] = [
    did::PART_NUMBER,
    did::SOFTWARE_VERSION,
    did::SERIAL_NUMBER,
    did::HARDWARE_VERSION,
    did::VIN,
    did::BOOT_SLOT,
];

/// What one ECU said about itself; each value is the DID's data or why it is missing.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct EcuIdentification {
    /// The ECU.
    pub ecu: Node,
    /// F187, spare part number.
    pub part_number: Result<Vec<u8>, UdsError>,
    /// F189, application software version.
    pub software_version: Result<Vec<u8>, UdsError>,
    /// F18C, ECU serial number.
    pub serial_number: Result<Vec<u8>, UdsError>,
    /// F191, hardware version.
    pub hardware_version: Result<Vec<u8>, UdsError>,
    /// F190, the vehicle's VIN as this ECU holds it.
    pub vin: Result<Vec<u8>, UdsError>,
    /// F1A0, the image slot the ECU runs and that image's boot state (two bytes: see
    /// [`boot_slot_text`]).
    pub boot_slot: Result<Vec<u8>, UdsError>,
}

impl EcuIdentification {
    fn new(ecu: Node) -> Self {
        let missing = || Err(UdsError::Busy);
        Self {
            ecu,
            part_number: missing(),
            software_version: missing(),
            serial_number: missing(),
            hardware_version: missing(),
            vin: missing(),
            boot_slot: missing(),
        }
    }

    fn slot(&mut self, index: usize) -> &mut Result<Vec<u8>, UdsError> {
        match index {
            0 => &mut self.part_number,
            1 => &mut self.software_version,
            2 => &mut self.serial_number,
            3 => &mut self.hardware_version,
            4 => &mut self.vin,
            _ => &mut self.boot_slot,
        }
    }

    /// The six values in [`IDENTIFICATION_DIDS`] order.
    pub fn values(&self) -> [&Result<Vec<u8>, UdsError>; 6] {
        [
            &self.part_number,
            &self.software_version,
            &self.serial_number,
            &self.hardware_version,
            &self.vin,
            &self.boot_slot,
        ]
    }

    /// The running slot and its boot state, when the ECU answered F1A0 with bytes that say
    /// them.
    pub fn running_slot(&self) -> Option<(ImageSlot, BootState)> {
        self.boot_slot.as_deref().ok().and_then(parse_boot_slot)
    }

    /// Whether the ECU answered at all (a positive or a negative response).
    pub fn answered(&self) -> bool {
        self.values().iter().any(|v| {
            !matches!(
                v,
                Err(UdsError::Timeout { .. } | UdsError::Transport { .. } | UdsError::Busy)
            )
        })
    }
}

/// The vehicle's VIN as its ECUs answer it (F190, check digit verified): `Ok(None)` when
/// none answered one, `Err` with the ECUs and what each said when they disagree or one is
/// not a VIN (an ECU moved from another car, or never coded).
pub fn vehicle_vin(rows: &[EcuIdentification]) -> Result<Option<Vin>, String> {
    let mut found: Vec<(Node, Result<Vin, String>)> = Vec::new();
    for row in rows {
        if let Ok(bytes) = &row.vin {
            let vin = Vin::from_bytes(bytes).map_err(|e| format!("{}: {e}", value_text(&row.vin)));
            found.push((row.ecu, vin));
        }
    }
    let first = match found.first() {
        None => return Ok(None),
        Some((ecu, Err(e))) => return Err(format!("{} holds no valid VIN ({e})", ecu_name(*ecu))),
        Some((_, Ok(vin))) => *vin,
    };
    let odd: Vec<String> = found
        .iter()
        .filter(|(_, vin)| vin.as_ref() != Ok(&first))
        .map(|(ecu, vin)| match vin {
            Ok(vin) => format!("{} holds {vin}", ecu_name(*ecu)),
            Err(e) => format!("{} holds no valid VIN ({e})", ecu_name(*ecu)),
        })
        .collect();
    if odd.is_empty() {
        Ok(Some(first))
    } else {
        Err(format!(
            "the ECUs disagree on the VIN: {} holds {first}; {}",
            ecu_name(found[0].0),
            odd.join("; ")
        ))
    }
}

/// The line under the identification table that says which vehicle this is.
pub fn vin_line(rows: &[EcuIdentification]) -> String {
    match vehicle_vin(rows) {
        Ok(Some(vin)) => format!("vehicle: VIN {vin} (F190 of every ECU that answered)"),
        Ok(None) => "vehicle: no ECU answered a VIN (F190)".to_string(),
        Err(e) => format!("vehicle: {e}"),
    }
}

/// A DID's value as text: printable ASCII as it is, anything else in hex.
pub fn value_text(value: &Result<Vec<u8>, UdsError>) -> String {
    match value {
        Ok(bytes) if bytes.iter().all(|b| (0x20..=0x7E).contains(b)) => {
            String::from_utf8_lossy(bytes).into_owned()
        }
        Ok(bytes) => format!(
            "0x{}",
            bytes.iter().map(|b| format!("{b:02X}")).collect::<String>()
        ),
        Err(UdsError::Negative { nrc, name, .. }) => format!("NRC 0x{nrc:02X} {name}"),
        Err(UdsError::Timeout { .. }) => "no response".to_string(),
        Err(error) => format!("error: {error}"),
    }
}

/// F1A0's value as text: `slot B, on trial`; bytes no ECU sends in hex, an error as
/// [`value_text`] says it (an ECU without slots answers NRC 0x31).
pub fn boot_slot_text(value: &Result<Vec<u8>, UdsError>) -> String {
    match value {
        Ok(bytes) => match parse_boot_slot(bytes) {
            Some((slot, state)) => format!("slot {}, {}", slot.letter(), state.name()),
            None => format!(
                "0x{} (not a slot and state)",
                bytes.iter().map(|b| format!("{b:02X}")).collect::<String>()
            ),
        },
        Err(_) => value_text(value),
    }
}

/// The identification table the `ids` command prints.
pub fn identification_table(rows: &[EcuIdentification]) -> String {
    let headers = [
        "ECU",
        "node",
        "part number (F187)",
        "software (F189)",
        "serial (F18C)",
        "hardware (F191)",
        "VIN (F190)",
        "running (F1A0)",
    ];
    let cells: Vec<[String; 8]> = rows
        .iter()
        .map(|row| {
            let number = row
                .ecu
                .diag_node_number()
                .map_or_else(String::new, |n| format!("0x{n:02X}"));
            let [a, b, c, d, e, _] = row.values().map(value_text);
            let slot = boot_slot_text(&row.boot_slot);
            [ecu_name(row.ecu).to_string(), number, a, b, c, d, e, slot]
        })
        .collect();
    let mut widths = headers.map(str::len);
    for row in &cells {
        for (width, cell) in widths.iter_mut().zip(row) {
            *width = (*width).max(cell.chars().count());
        }
    }
    let mut out = String::new();
    let mut line = |cells: &[&str]| {
        let text: Vec<String> = cells
            .iter()
            .zip(widths)
            .map(|(cell, width)| format!("{cell:<width$}"))
            .collect();
        let _ = writeln!(out, "{}", text.join("  ").trim_end());
    };
    line(&headers);
    for row in &cells {
        line(&row.iter().map(String::as_str).collect::<Vec<_>>());
    }
    out
}

/// Reads the identification DIDs of the given ECUs, one request at a time. An ECU that
/// does not answer its first request is not asked the rest (each would only time out
/// again); the job never fails as a whole, each value says what happened.
pub type IdentJob = EachEcu<Identifying>;

impl IdentJob {
    /// A job reading `ecus` (in that order) with the given timing.
    pub fn new(ecus: &[Node], config: TesterConfig) -> Self {
        EachEcu::with(
            Identifying {
                rows: ecus
                    .iter()
                    .map(|&ecu| EcuIdentification::new(ecu))
                    .collect(),
                ecu: 0,
                did: 0,
            },
            config,
        )
    }
}

/// The requests of an [`IdentJob`]: every identification DID of each ECU in turn.
#[derive(Debug)]
pub struct Identifying {
    rows: Vec<EcuIdentification>,
    ecu: usize,
    did: usize,
}

impl Identifying {
    fn next_did(&mut self) {
        self.did += 1;
        if self.did == IDENTIFICATION_DIDS.len() {
            self.did = 0;
            self.ecu += 1;
        }
    }
}

impl Requests for Identifying {
    type Output = Vec<EcuIdentification>;

    fn next_request(&self) -> Option<(Node, Vec<u8>, usize)> {
        let row = self.rows.get(self.ecu)?;
        let did = IDENTIFICATION_DIDS[self.did].to_be_bytes();
        Some((row.ecu, vec![0x22, did[0], did[1]], 2))
    }

    fn answered(&mut self, outcome: Result<Response, UdsError>) {
        let did = IDENTIFICATION_DIDS[self.did];
        let value = match outcome {
            Ok(Response::Positive(response)) => match response.as_slice() {
                [0x62, hi, lo, data @ ..] if u16::from_be_bytes([*hi, *lo]) == did => {
                    Ok(data.to_vec())
                }
                _ => Err(UdsError::UnexpectedResponse {
                    service: 0x22,
                    response,
                    expected: format!("62 {:02X} {:02X} and the data", did >> 8, did & 0xFF),
                }),
            },
            Ok(Response::Functional(_)) => Err(UdsError::Busy),
            Err(error) => Err(error),
        };
        let row = &mut self.rows[self.ecu];
        if matches!(value, Err(UdsError::Timeout { .. })) {
            // Nobody there: the remaining DIDs get the same answer without asking.
            for index in self.did..IDENTIFICATION_DIDS.len() {
                *row.slot(index) = value.clone();
            }
            self.did = 0;
            self.ecu += 1;
        } else {
            *row.slot(self.did) = value;
            self.next_did();
        }
    }

    fn finish(&mut self) -> Vec<EcuIdentification> {
        std::mem::take(&mut self.rows)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_shows_text_hex_and_errors() {
        let rows = vec![
            EcuIdentification {
                ecu: Node::Cruise,
                part_number: Ok(b"AP-CRUISE-0001".to_vec()),
                software_version: Ok(b"1.2.0".to_vec()),
                serial_number: Ok(vec![0x0D, 0x00, 0x42]),
                hardware_version: Err(UdsError::negative(0x22, 0x31)),
                vin: Ok(b"JA3AP47H0YF000042".to_vec()),
                boot_slot: Ok(vec![1, 1]),
            },
            EcuIdentification {
                ecu: Node::ABS,
                part_number: Err(UdsError::Timeout {
                    service: 0x22,
                    waited_us: 50_000,
                    pending: 0,
                }),
                software_version: Err(UdsError::Timeout {
                    service: 0x22,
                    waited_us: 50_000,
                    pending: 0,
                }),
                serial_number: Err(UdsError::Busy),
                hardware_version: Err(UdsError::Busy),
                vin: Err(UdsError::Busy),
                boot_slot: Err(UdsError::Busy),
            },
        ];
        let table = identification_table(&rows);
        let lines: Vec<&str> = table.lines().collect();
        assert_eq!(lines.len(), 3, "{table}");
        assert!(lines[0].starts_with("ECU"), "{table}");
        assert!(lines[1].contains("cruise"), "{table}");
        assert!(lines[1].contains("0x0D"), "{table}");
        assert!(lines[1].contains("AP-CRUISE-0001"), "{table}");
        assert!(lines[1].contains("0x0D0042"), "{table}");
        assert!(lines[1].contains("NRC 0x31 requestOutOfRange"), "{table}");
        assert!(lines[2].contains("no response"), "{table}");
        assert!(lines[1].contains("JA3AP47H0YF000042"), "{table}");
        assert!(lines[0].contains("running (F1A0)"), "{table}");
        assert!(lines[1].ends_with("slot B, on trial"), "{table}");
        assert_eq!(
            rows[0].running_slot(),
            Some((ImageSlot::B, BootState::Trial))
        );
        assert_eq!(rows[1].running_slot(), None);
        assert!(rows[0].answered());
        assert!(!rows[1].answered());
    }

    fn with_vin(ecu: Node, vin: Result<&[u8], UdsError>) -> EcuIdentification {
        let mut row = EcuIdentification::new(ecu);
        row.vin = vin.map(<[u8]>::to_vec);
        row
    }

    #[test]
    fn the_running_slot_reads_as_slot_and_state_and_odd_bytes_in_hex() {
        assert_eq!(boot_slot_text(&Ok(vec![0, 0])), "slot A, confirmed");
        assert_eq!(boot_slot_text(&Ok(vec![0, 2])), "slot A, reverted");
        assert_eq!(
            boot_slot_text(&Ok(vec![2, 0])),
            "0x0200 (not a slot and state)"
        );
        assert_eq!(boot_slot_text(&Ok(vec![0])), "0x00 (not a slot and state)");
        // An ECU without slots does not know F1A0.
        assert_eq!(
            boot_slot_text(&Err(UdsError::negative(0x22, 0x31))),
            "NRC 0x31 requestOutOfRange"
        );
    }

    #[test]
    fn the_vehicle_vin_is_the_one_all_answering_ecus_hold() {
        let good: &[u8] = b"JA3AP47H0YF000042";
        let rows = [
            with_vin(Node::Engine, Ok(good)),
            with_vin(Node::Cruise, Err(UdsError::negative(0x22, 0x31))),
            with_vin(Node::ABS, Ok(good)),
        ];
        assert_eq!(
            vehicle_vin(&rows).unwrap().map(|v| v.to_string()),
            Some("JA3AP47H0YF000042".into())
        );
        assert_eq!(vehicle_vin(&rows[1..2]), Ok(None));
        // An ECU from another car.
        let rows = [
            with_vin(Node::Engine, Ok(good)),
            with_vin(Node::ABS, Ok(b"JA3AP47H2YF000043")),
        ];
        let error = vehicle_vin(&rows).unwrap_err();
        assert!(error.contains("abs holds JA3AP47H2YF000043"), "{error}");
        // One that was never coded right.
        let rows = [with_vin(Node::ABS, Ok(b"JA3AP47H9YF000042"))];
        let error = vehicle_vin(&rows).unwrap_err();
        assert!(error.contains("abs holds no valid VIN"), "{error}");
        assert!(error.contains("check digit"), "{error}");
    }
}
