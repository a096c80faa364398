//! What a trip leaves behind: its statistics, why it ended, and a downsampled series of
//! every signal for plots. Plain data, so any store (SQLite here, a server database for a
//! fleet) can keep it.

use serde::{Deserialize, Serialize};

/// A trip's statistics, all from the bus.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TripStats {
    /// Bus time of the trip's first frame showing the engine running or the car moving, µs.
    pub start_us: u64,
    /// Bus time of its last such frame, µs.
    pub end_us: u64,
    /// Distance, m (vehicle speed integrated over time).
    pub distance_m: f64,
    /// Duration, s (`end_us - start_us`).
    pub duration_s: f64,
    /// Time with the car moving, s.
    pub moving_time_s: f64,
    /// Fuel used, L (the engine's fuel consumption counter).
    pub fuel_used_l: f64,
    /// Highest vehicle speed, km/h.
    pub max_speed_kmh: f64,
    /// Mean speed over the whole trip (distance / duration), km/h.
    pub mean_speed_kmh: f64,
    /// ABS interventions: stretches of the ABS releasing brake pressure, merged when
    /// less than [`crate::ABS_MERGE_GAP_US`] apart.
    pub abs_interventions: u32,
    /// Time the ABS was releasing brake pressure on any wheel, s.
    pub abs_time_s: f64,
    /// Brakings whose deceleration reached [`crate::HARD_BRAKING_MPS2`].
    pub hard_brakings: u32,
    /// Changes of engaged gear (reverse or a forward gear to another; neutral between
    /// them does not count).
    pub shifts: u32,
    /// Time with cruise control on, s.
    pub cruise_time_s: f64,
    /// Differential interventions: stretches of a non-zero torque split, merged when less
    /// than [`crate::DIFF_MERGE_GAP_US`] apart.
    pub diff_interventions: u32,
    /// Time with a non-zero torque split, s.
    pub diff_time_s: f64,
}

/// Why a trip ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TripEnd {
    /// Engine off and the car standing for [`crate::PARKED_AFTER_US`].
    Parked,
    /// No engine or vehicle-speed frame for [`crate::SILENT_AFTER_US`] (ignition off, or the
    /// gateway lost the bus).
    BusSilent,
    /// The log ended, or the gateway was stopped, during the trip.
    EndOfInput,
}

impl TripEnd {
    /// `parked`, `bus silent`, `end of input`.
    pub fn name(self) -> &'static str {
        match self {
            TripEnd::Parked => "parked",
            TripEnd::BusSilent => "bus silent",
            TripEnd::EndOfInput => "end of input",
        }
    }

    /// The inverse of [`TripEnd::name`] (for stores).
    pub fn from_name(name: &str) -> Option<Self> {
        [Self::Parked, Self::BusSilent, Self::EndOfInput]
            .into_iter()
            .find(|e| e.name() == name)
    }
}

/// One bucket of one signal in the downsampled series: mean, min and max over the bucket,
/// so a plot of the series keeps the peaks (as PlotJuggler's and cabana's downsampling do).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeriesPoint {
    /// The signal's VSS path.
    pub signal: String,
    /// Start of the bucket, s from the trip's start.
    pub t_s: f64,
    /// Mean of the values received in the bucket.
    pub mean: f64,
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
}
