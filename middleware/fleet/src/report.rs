//! What a vehicle's gateway tells the fleet: its inventory when it changes, and each trip
//! with the verdicts and trouble codes it ended with. JSON, the payload of its MQTT
//! messages; the same types are what the store takes.

use autoplug_store::{DtcRecord, EcuIdentity, VerdictRecord};
use autoplug_trips::{TripEnd, TripStats};
use autoplug_vin::Vin;
use serde::{Deserialize, Serialize};

/// Largest report a fleet service takes, bytes (an inventory of nine ECUs is under 2 KiB; a
/// trip with every verdict and a few dozen codes under 16 KiB).
pub const MAX_REPORT_BYTES: usize = 256 * 1024;

/// A vehicle's inventory: the VIN and what each ECU answered about itself.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InventoryReport {
    /// The vehicle.
    pub vin: String,
    /// When the gateway read it, ms since the Unix epoch (the vehicle's clock).
    pub read_at_ms: i64,
    /// Each ECU that answered.
    pub ecus: Vec<EcuIdentity>,
}

/// A trip that ended, as its vehicle saw it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TripReport {
    /// The vehicle.
    pub vin: String,
    /// The vehicle's own number for the trip (its gateway's store): a report sent twice is
    /// stored once.
    pub trip: i64,
    /// Wall clock at the start and at the end, ms since the Unix epoch.
    pub started_at_ms: i64,
    /// See `started_at_ms`.
    pub ended_at_ms: i64,
    /// Its statistics.
    pub stats: TripStats,
    /// Why it ended.
    pub end: TripEnd,
    /// Every diagnostic routine's verdict at its end.
    pub verdicts: Vec<VerdictRecord>,
    /// The trouble codes read from the ECUs during it (latest per ECU).
    pub dtcs: Vec<DtcRecord>,
}

/// The fleet's word on one report, sent to the vehicle after the report's transaction
/// committed (or after it was refused for good): the vehicle keeps every report until its
/// receipt comes, and publishes it again meanwhile ([`crate::outbox`]). A broker
/// acknowledges a publish when it has queued it, which is not the same as stored: a
/// broker restarted before the services have subscribed again drops what it took.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Receipt {
    /// The report: SHA-256 of its payload, lower-case hex.
    pub report: String,
    /// Why it was refused (it will never be stored); none: stored.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub refused: Option<String>,
}

/// Largest receipt a vehicle reads, bytes.
pub const MAX_RECEIPT_BYTES: usize = 4 * 1024;

impl Receipt {
    /// The receipt of `payload`: stored, or refused for `refused`.
    pub fn of(payload: &[u8], refused: Option<String>) -> Self {
        Self {
            report: crate::campaign::sha256_hex(payload),
            // A reason is for a person; the receipt stays small whatever the report held.
            refused: refused.map(|r| r.chars().take(300).collect()),
        }
    }

    /// Its payload.
    pub fn to_json(&self) -> Vec<u8> {
        serde_json::to_vec(self).unwrap_or_default()
    }

    /// Reads a receipt; an error naming what is wrong.
    pub fn parse(payload: &[u8]) -> Result<Self, String> {
        if payload.len() > MAX_RECEIPT_BYTES {
            return Err(format!(
                "a receipt of {} bytes (at most {MAX_RECEIPT_BYTES})",
                payload.len()
            ));
        }
        let receipt: Receipt =
            serde_json::from_slice(payload).map_err(|e| format!("not a receipt: {e}"))?;
        if receipt.report.len() != 64 || !receipt.report.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Err("a receipt whose report is not a SHA-256 in hex".into());
        }
        Ok(receipt)
    }
}

/// Why a report was not taken.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ReportError(pub String);

impl std::fmt::Display for ReportError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ReportError {}

/// Longest text field the fleet keeps (part numbers, versions, evidence...), characters.
pub const MAX_FIELD_CHARS: usize = 2_000;

fn check_vin(vin: &str) -> Result<Vin, ReportError> {
    Vin::parse(vin).map_err(|e| ReportError(format!("VIN \"{}\": {e}", cut(vin))))
}

fn cut(text: &str) -> String {
    text.chars().take(40).collect()
}

fn check_text(what: &str, text: &str) -> Result<(), ReportError> {
    if text.chars().count() > MAX_FIELD_CHARS {
        return Err(ReportError(format!(
            "{what} is longer than {MAX_FIELD_CHARS} characters"
        )));
    }
    if text.chars().any(char::is_control) {
        return Err(ReportError(format!(
            "{what} \"{}\" holds control characters",
            cut(&text.escape_default().to_string())
        )));
    }
    Ok(())
}

/// The ECU called `name`, by the name the gateway gives it ([`autoplug_can::ecu_name`]):
/// recalls select ECUs by that name, so an alias, another spelling or an ECU the catalogue
/// does not know would be stored where no query finds it.
pub fn check_ecu_name(what: &str, name: &str) -> Result<autoplug_can::Node, ReportError> {
    autoplug_can::parse_ecu(name)
        .filter(|node| autoplug_can::ecu_name(*node) == name)
        .ok_or_else(|| {
            ReportError(format!(
                "{what} names ECU \"{}\", which is none of the car's ({})",
                cut(&name.escape_default().to_string()),
                autoplug_can::ECU_NAME_LIST
            ))
        })
}

/// The longest trip the fleet takes, s (30 days): a trip ends when the car is parked.
pub const MAX_TRIP_S: f64 = 30.0 * 24.0 * 3600.0;

/// The most fuel any road car's engine burns, L/h, at full load: a generous road-car bound
/// (the AutoPlug engine ECU publishes 150 L/h as its own counter's limit,
/// `ecu_engine::FUEL_FLOW_MAX_L_PER_H`, which the fleet does not link).
pub const MAX_FUEL_FLOW_L_PER_H: f64 = 600.0;

/// The most events of one kind (ABS interventions, shifts...) per second of trip: one per
/// period of the fastest message that can show one (AbsMsg's, in the catalogue: 10 ms).
pub fn max_events_per_s() -> f64 {
    1000.0 / f64::from(autoplug_can::AbsMsg::CYCLE_TIME_MS)
}

/// The highest speed a trip can show, km/h: the top of VehicleSpeedMsg's range in the
/// catalogue (the gateway's speed is that signal).
pub fn max_speed_kmh() -> f64 {
    f64::from(autoplug_can::VehicleSpeedMsg::VEHICLE_SPEED.physical_max())
}

impl InventoryReport {
    /// Checks a report before it is stored: a valid VIN, sane fields, each ECU once.
    pub fn check(&self) -> Result<Vin, ReportError> {
        let vin = check_vin(&self.vin)?;
        if self.ecus.len() > 64 {
            return Err(ReportError(format!(
                "{} ECUs in one inventory (at most 64)",
                self.ecus.len()
            )));
        }
        for (i, ecu) in self.ecus.iter().enumerate() {
            check_text("an ECU name", &ecu.ecu)?;
            if ecu.ecu.is_empty() {
                return Err(ReportError(format!("ECU {} has no name", i + 1)));
            }
            let node = check_ecu_name("the inventory", &ecu.ecu)?;
            let number = node.diag_node_number().unwrap_or(0);
            if ecu.node != number {
                return Err(ReportError(format!(
                    "the inventory gives ECU {} node 0x{:02X}; its node is 0x{number:02X}",
                    ecu.ecu, ecu.node
                )));
            }
            if self.ecus[..i].iter().any(|e| e.ecu == ecu.ecu) {
                return Err(ReportError(format!("ECU {} is listed twice", ecu.ecu)));
            }
            for (what, value) in [
                ("part number", &ecu.part_number),
                ("software version", &ecu.software_version),
                ("hardware version", &ecu.hardware_version),
                ("serial number", &ecu.serial_number),
            ] {
                if let Some(value) = value {
                    check_text(&format!("{} {what}", ecu.ecu), value)?;
                }
            }
        }
        Ok(vin)
    }
}

impl TripReport {
    /// Checks a report before it is stored: a valid VIN, finite figures, sane text.
    pub fn check(&self) -> Result<Vin, ReportError> {
        let vin = check_vin(&self.vin)?;
        let s = &self.stats;
        let trip = self.trip;
        // Short figures whatever their size (1.7e308 written out has 309 digits).
        let figure = |v: f64| {
            if v.abs() >= 1e9 {
                format!("{v:e}")
            } else {
                format!("{}", (v * 10.0).round() / 10.0)
            }
        };
        let implausible = |what: &str, value: f64, most: f64, why: &str| {
            ReportError(format!(
                "trip {trip}: {what} is {}, more than {} ({why})",
                figure(value),
                figure(most)
            ))
        };
        for (what, v) in [
            ("distance", s.distance_m),
            ("duration", s.duration_s),
            ("moving time", s.moving_time_s),
            ("fuel used", s.fuel_used_l),
            ("maximum speed", s.max_speed_kmh),
            ("mean speed", s.mean_speed_kmh),
            ("ABS time", s.abs_time_s),
            ("cruise time", s.cruise_time_s),
            ("differential time", s.diff_time_s),
        ] {
            if !v.is_finite() || v < 0.0 {
                return Err(ReportError(format!("trip {trip}: {what} is {v}")));
            }
        }
        // What no car can show: see the bounds' constants. Sums over a fleet's trips stay
        // far inside the database's numbers.
        if s.duration_s > MAX_TRIP_S {
            return Err(implausible(
                "the duration (s)",
                s.duration_s,
                MAX_TRIP_S,
                "30 days",
            ));
        }
        // A little room for rounding in the gateway's integration.
        let duration = s.duration_s * 1.01 + 1.0;
        for (what, v) in [
            ("the moving time (s)", s.moving_time_s),
            ("the ABS time (s)", s.abs_time_s),
            ("the cruise time (s)", s.cruise_time_s),
            ("the differential time (s)", s.diff_time_s),
        ] {
            if v > duration {
                return Err(implausible(what, v, duration, "the trip's duration"));
            }
        }
        let top = max_speed_kmh();
        for (what, v) in [
            ("the maximum speed (km/h)", s.max_speed_kmh),
            ("the mean speed (km/h)", s.mean_speed_kmh),
        ] {
            if v > top {
                return Err(implausible(what, v, top, "VehicleSpeedMsg's range"));
            }
        }
        let farthest = top / 3.6 * duration;
        if s.distance_m > farthest {
            return Err(implausible(
                "the distance (m)",
                s.distance_m,
                farthest,
                "the top speed for the whole trip",
            ));
        }
        let most_fuel = MAX_FUEL_FLOW_L_PER_H / 3600.0 * duration + 1.0;
        if s.fuel_used_l > most_fuel {
            return Err(implausible(
                "the fuel used (L)",
                s.fuel_used_l,
                most_fuel,
                "600 L/h for the whole trip",
            ));
        }
        let most_events = max_events_per_s() * duration;
        for (what, n) in [
            ("ABS interventions", s.abs_interventions),
            ("hard brakings", s.hard_brakings),
            ("shifts", s.shifts),
            ("differential interventions", s.diff_interventions),
        ] {
            if f64::from(n) > most_events {
                return Err(implausible(
                    what,
                    f64::from(n),
                    most_events,
                    "one per 10 ms",
                ));
            }
        }
        if self.ended_at_ms < self.started_at_ms {
            return Err(ReportError(format!(
                "trip {trip}: it ends ({}) before it starts ({})",
                self.ended_at_ms, self.started_at_ms
            )));
        }
        if self.verdicts.len() > 256 || self.dtcs.len() > 1024 {
            return Err(ReportError(format!(
                "trip {}: {} verdicts and {} trouble codes (at most 256 and 1024)",
                self.trip,
                self.verdicts.len(),
                self.dtcs.len()
            )));
        }
        for v in &self.verdicts {
            check_ecu_name(&format!("trip {trip}: a verdict"), &v.ecu)?;
            for (what, text) in [
                ("ECU", &v.ecu),
                ("verdict", &v.verdict),
                ("routine", &v.routine),
                ("unit", &v.unit),
                ("evidence", &v.evidence),
            ] {
                check_text(&format!("a verdict's {what}"), text)?;
            }
        }
        for d in &self.dtcs {
            check_ecu_name(&format!("trip {trip}: a trouble code"), &d.ecu)?;
            for (what, text) in [
                ("ECU", &d.ecu),
                ("code", &d.code),
                ("description", &d.description),
            ] {
                check_text(&format!("a trouble code's {what}"), text)?;
            }
        }
        Ok(vin)
    }
}
