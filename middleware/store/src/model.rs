//! What the store keeps, as plain data: a trip as it starts and as it ends, the verdicts and
//! trouble codes it ended with, and the identity of a vehicle's ECUs.

use std::fmt;

use autoplug_trips::{TripEnd, TripStats};
use serde::{Deserialize, Serialize};

/// A trip as the gateway sees it start.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NewTrip {
    /// The vehicle: its VIN, or a name the user gives.
    pub vehicle: String,
    /// Where the frames come from: `bus.log`, `socketcand://...`.
    pub source: String,
    /// Wall clock when the gateway saw the trip start, ms since the Unix epoch (for a
    /// replayed log: when the replay ran).
    pub started_at_unix_ms: i64,
    /// Bus time of the trip's start, µs.
    pub start_us: u64,
}

/// The verdict of one diagnostic routine at the end of a trip.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct VerdictRecord {
    /// The ECU the routine judges.
    pub ecu: String,
    /// `ok`, `not exercised`, `suspect`, `faulty` or `no data`.
    pub verdict: String,
    /// The routine's name.
    pub routine: String,
    /// The number the verdict rests on, if any.
    pub number: Option<f64>,
    /// Its unit.
    pub unit: String,
    /// Above this the verdict is suspect.
    pub suspect_above: f64,
    /// Above this the verdict is faulty.
    pub faulty_above: f64,
    /// The evidence window, s from the trip's start (start, end).
    pub window_s: Option<(f64, f64)>,
    /// What the routine saw, in words.
    pub evidence: String,
}

/// A diagnostic trouble code read from an ECU at the end of a trip.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DtcRecord {
    /// The ECU that reported it.
    pub ecu: String,
    /// The code with its failure type, e.g. `U0126-87`.
    pub code: String,
    /// The DTC status byte (ISO 14229-1).
    pub status: u8,
    /// The code in words.
    pub description: String,
}

/// Everything a trip leaves behind when it ends (its series aside, which the store takes
/// separately, as it does at every checkpoint).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FinishedTrip {
    /// Its final statistics.
    pub stats: TripStats,
    /// Why it ended.
    pub end: TripEnd,
    /// The diagnostic routines' verdicts.
    pub verdicts: Vec<VerdictRecord>,
    /// The trouble codes read from the ECUs.
    pub dtcs: Vec<DtcRecord>,
}

/// The identity of one ECU, as read over UDS. `None`: the ECU did not answer that
/// identifier.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EcuIdentity {
    /// The ECU's name (`engine`, `abs`, ...).
    pub ecu: String,
    /// Its node number on the bus.
    pub node: u8,
    /// Spare part number.
    pub part_number: Option<String>,
    /// Application software version.
    pub software_version: Option<String>,
    /// Hardware version.
    pub hardware_version: Option<String>,
    /// Serial number.
    pub serial_number: Option<String>,
}

/// A trip's number in the store.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(transparent)]
pub struct TripId(pub i64);

impl fmt::Display for TripId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.fmt(f)
    }
}

/// Where a trip stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TripStatus {
    /// Under way: the gateway is still writing it.
    Open,
    /// Ended, with its verdicts and trouble codes.
    Closed,
    /// The gateway died during the trip (power cut, crash, kill -9): its statistics and
    /// series are those of its last checkpoint, and it has no end, verdicts or codes.
    Interrupted,
}

impl TripStatus {
    /// `open`, `closed`, `interrupted` (as stored).
    pub fn name(self) -> &'static str {
        match self {
            TripStatus::Open => "open",
            TripStatus::Closed => "closed",
            TripStatus::Interrupted => "interrupted",
        }
    }

    /// The inverse of [`TripStatus::name`].
    pub fn from_name(name: &str) -> Option<Self> {
        [Self::Open, Self::Closed, Self::Interrupted]
            .into_iter()
            .find(|s| s.name() == name)
    }
}

/// A trip as listed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TripRow {
    /// Its number.
    pub id: TripId,
    /// The vehicle (see [`NewTrip::vehicle`]).
    pub vehicle: String,
    /// Where its frames came from.
    pub source: String,
    /// Wall clock at its start, ms since the Unix epoch.
    pub started_at_unix_ms: i64,
    /// Where it stands.
    pub status: TripStatus,
    /// Why it ended (closed trips only).
    pub end: Option<TripEnd>,
    /// Its statistics: final if closed, else those of its last checkpoint.
    pub stats: TripStats,
}

/// A trip with everything stored about it but its series points.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TripDetail {
    /// The trip as listed.
    pub row: TripRow,
    /// Its verdicts, in the order given.
    pub verdicts: Vec<VerdictRecord>,
    /// Its trouble codes, in the order given.
    pub dtcs: Vec<DtcRecord>,
    /// The VSS paths of the signals it has series points of, sorted.
    pub series_signals: Vec<String>,
}
