//! Trips, detected from the bus traffic alone, with their statistics: distance and
//! duration, fuel used, max and mean speed, ABS interventions, hard brakings, shifts,
//! cruise time and differential interventions, and a downsampled series of every signal
//! for plots.
//!
//! | module | what |
//! |---|---|
//! | [`tracker`] | [`TripTracker`]: the rule for a trip's start and end, and its statistics, as an observer of the gateway's pipeline |
//! | [`series`] | [`Downsampler`]: every signal in 1 s buckets of mean, min and max |
//! | `record` | [`TripStats`], [`TripEnd`], [`SeriesPoint`]: what a trip leaves behind, for a store |
//!
//! The tracker reads frames only, so a recorded log gives the trips the live bus gave. It
//! and the series are the default feature `tracker`; without it the crate is the records
//! alone (for stores and the fleet service, which need no gateway).
#![deny(missing_docs)]
#![forbid(unsafe_code)]

mod record;
#[cfg(feature = "tracker")]
pub mod series;
#[cfg(feature = "tracker")]
pub mod tracker;

pub use record::{SeriesPoint, TripEnd, TripStats};
#[cfg(feature = "tracker")]
pub use series::Downsampler;
#[cfg(feature = "tracker")]
pub use tracker::{CompletedTrip, TripTracker};

/// ABS release stretches closer together than this are one intervention: the ABS ECU's
/// own definition ([`autoplug_ecu_params::abs::INTERVENTION_MERGE_GAP_US`]).
pub const ABS_MERGE_GAP_US: u64 = autoplug_ecu_params::abs::INTERVENTION_MERGE_GAP_US;
/// Torque-split stretches closer together than this are one differential intervention (a
/// slalom's alternating corrections are one each; a second corner a second later is
/// another).
pub const DIFF_MERGE_GAP_US: u64 = 1_000_000;
/// Deceleration that makes a braking a hard one, m/s² (about 0.4 g: the usual
/// telematics threshold for harsh braking lies between 0.3 and 0.45 g).
pub const HARD_BRAKING_MPS2: f64 = 4.0;
/// Engine off and car standing this long ends a trip, µs.
pub const PARKED_AFTER_US: u64 = 30_000_000;
/// No engine or vehicle-speed frame for this long ends a trip, µs (both are sent every
/// 10-20 ms: 5 s is the ignition off, not a hiccup).
pub const SILENT_AFTER_US: u64 = 5_000_000;

#[cfg(all(test, feature = "tracker"))]
mod tests;
