//! A scenario on the emulated firmware against the same scenario on host logic: does the
//! code that only a chip runs (clocks, bxCAN, interrupts, the executor, the ADC and PWM
//! drivers) keep the behaviour the logic has on the host?
//!
//! Not byte for byte: the firmware steps at its own ticker's moments, samples its inputs
//! with a 12-bit ADC and drives PWM at 1/10,000 steps, and boots before the scenario
//! begins, so events move by a control period and values by a quantum. What must hold:
//!
//! - every periodic message an emulated ECU sends is on the bus at its period: no gap
//!   longer than [`MAX_GAP_PERIODS`] periods (receivers call a message stale after three)
//!   and at least [`MIN_RATE`] of the frames its period gives over the run;
//! - the same gear sequence;
//! - distance, fuel used and maximum speed within [`FIGURE_TOLERANCE`]: a shift of one
//!   control period in a 150 s drive cycle moves the distance by well under 0.1 % (the
//!   drive cycle measured 0.03 %), so 1 % flags a real difference without flagging timing;
//!   the distance travelled while stopping is held to the stops' bound instead, so the
//!   distance's bound is 1 % of it plus 2 % of the stops' distances;
//! - every stop's distance within [`STOP_TOLERANCE`] (the 2 %): ABS cycles on the
//!   firmware's own 5 ms ticker against wheel speeds it samples itself, so a stop's
//!   release pattern differs (the wet stop measured +1.2 %).

use crate::car::LoggedFrame;
use crate::report::RunRecord;
use autoplug_can::{Node, MESSAGES};
use std::collections::BTreeMap;

/// The longest gap between two frames of a periodic message, in periods.
pub const MAX_GAP_PERIODS: f64 = 1.5;
/// The share of the frames a message's period gives over the run that must be there.
pub const MIN_RATE: f64 = 0.98;
/// Distance, fuel used and maximum speed: the largest relative difference.
pub const FIGURE_TOLERANCE: f64 = 0.01;
/// A stop's distance: the largest relative difference.
pub const STOP_TOLERANCE: f64 = 0.02;

/// One line of the comparison.
#[derive(Clone, Debug, PartialEq)]
pub struct Check {
    /// What was compared.
    pub what: String,
    /// On host logic.
    pub host: String,
    /// On the emulated firmware.
    pub firmware: String,
    /// The bound it is held to.
    pub bound: String,
    /// Whether it held.
    pub ok: bool,
}

/// Compares the two runs of one scenario; `emulated`: the ECUs that ran as firmware.
pub fn compare(host: &RunRecord, firmware: &RunRecord, emulated: &[Node]) -> Vec<Check> {
    let mut checks = Vec::new();
    let duration_s = firmware.summary.duration_s;
    let host_counts = counts(&host.log);
    for spec in MESSAGES.iter() {
        if spec.cycle_time_ms == 0 || !spec.senders.iter().any(|s| emulated.contains(s)) {
            continue;
        }
        let times: Vec<u64> = firmware
            .log
            .iter()
            .filter(|f| f.frame.id() == spec.id)
            .map(|f| f.t_us)
            .collect();
        let period_us = u64::from(spec.cycle_time_ms) * 1000;
        let longest_gap = times
            .windows(2)
            .map(|w| w[1] - w[0])
            .max()
            .unwrap_or(u64::MAX);
        let expected = duration_s * 1e6 / period_us as f64;
        let ok = !times.is_empty()
            && times[0] <= period_us * 3 / 2
            && longest_gap as f64 <= MAX_GAP_PERIODS * period_us as f64
            && times.len() as f64 >= MIN_RATE * expected.floor();
        checks.push(Check {
            what: format!("{} (every {} ms)", spec.name, spec.cycle_time_ms),
            host: format!("{} frames", host_counts.get(&spec.id).copied().unwrap_or(0)),
            firmware: if times.is_empty() {
                "none".into()
            } else {
                format!(
                    "{} frames, first at {:.1} ms, longest gap {:.1} ms",
                    times.len(),
                    times[0] as f64 / 1000.0,
                    longest_gap as f64 / 1000.0
                )
            },
            bound: format!(
                "first within {:.0} ms, gaps up to {:.0} ms, at least {:.0} frames",
                period_us as f64 * 1.5 / 1000.0,
                MAX_GAP_PERIODS * period_us as f64 / 1000.0,
                (MIN_RATE * expected.floor()).ceil()
            ),
            ok,
        });
    }
    let (h, f) = (&host.summary, &firmware.summary);
    checks.push(Check {
        what: "gear sequence".into(),
        host: format!("{:?}", h.gear_sequence),
        firmware: format!("{:?}", f.gear_sequence),
        bound: "the same".into(),
        ok: h.gear_sequence == f.gear_sequence,
    });
    let stopping_m: f64 = h.stops.iter().map(|s| s.distance_m).sum();
    let bound_m = FIGURE_TOLERANCE * h.distance_m + STOP_TOLERANCE * stopping_m;
    checks.push(Check {
        what: "distance".into(),
        host: format!("{} m", h.distance_m),
        firmware: format!(
            "{} m ({:+.2} %)",
            f.distance_m,
            signed_percent(h.distance_m, f.distance_m)
        ),
        bound: format!("within {bound_m:.2} m (1 % of it, 2 % of the {stopping_m:.1} m stopping)"),
        ok: (f.distance_m - h.distance_m).abs() <= bound_m,
    });
    for (what, unit, host_value, firmware_value) in [
        ("fuel used", "L", h.fuel_used_l, f.fuel_used_l),
        ("maximum speed", "km/h", h.max_speed_kmh, f.max_speed_kmh),
    ] {
        checks.push(relative(
            what,
            unit,
            host_value,
            firmware_value,
            FIGURE_TOLERANCE,
        ));
    }
    checks.push(Check {
        what: "stops".into(),
        host: h.stops.len().to_string(),
        firmware: f.stops.len().to_string(),
        bound: "as many".into(),
        ok: h.stops.len() == f.stops.len(),
    });
    for (i, (hs, fs)) in h.stops.iter().zip(&f.stops).enumerate() {
        checks.push(relative(
            &format!("stop {} from {:.0} km/h, distance", i + 1, hs.from_kmh),
            "m",
            hs.distance_m,
            fs.distance_m,
            STOP_TOLERANCE,
        ));
    }
    checks
}

fn relative(what: &str, unit: &str, host: f64, firmware: f64, tolerance: f64) -> Check {
    let difference = if host == firmware {
        0.0
    } else {
        (firmware - host).abs() / host.abs().max(f64::MIN_POSITIVE)
    };
    Check {
        what: what.into(),
        host: format!("{host} {unit}"),
        firmware: format!(
            "{firmware} {unit} ({:+.2} %)",
            signed_percent(host, firmware)
        ),
        bound: format!("within {} %", tolerance * 100.0),
        ok: difference <= tolerance,
    }
}

fn signed_percent(host: f64, firmware: f64) -> f64 {
    if host == 0.0 {
        0.0
    } else {
        (firmware - host) / host.abs() * 100.0
    }
}

fn counts(log: &[LoggedFrame]) -> BTreeMap<u16, usize> {
    let mut counts = BTreeMap::new();
    for f in log {
        *counts.entry(f.frame.id()).or_insert(0) += 1;
    }
    counts
}

/// The checks as a table, a line each.
pub fn table(checks: &[Check]) -> String {
    let mut out = String::new();
    for c in checks {
        out.push_str(&format!(
            "  {} {:<44} host: {:<28} firmware: {}  [{}]\n",
            if c.ok { "ok  " } else { "FAIL" },
            c.what,
            c.host,
            c.firmware,
            c.bound
        ));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report;
    use crate::scenario::Scenario;
    use autoplug_can::ECUS;

    fn stop_100_dry() -> RunRecord {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../scenarios/stop-100-dry.toml"
        );
        report::run(&Scenario::load(std::path::Path::new(path)).expect("scenario"))
    }

    fn failed(checks: &[Check]) -> Vec<&str> {
        checks
            .iter()
            .filter(|c| !c.ok)
            .map(|c| c.what.as_str())
            .collect()
    }

    #[test]
    fn a_run_matches_itself() {
        let run = stop_100_dry();
        let checks = compare(&run, &run, &ECUS);
        assert!(failed(&checks).is_empty(), "{}", table(&checks));
        // Every periodic message of the catalogue is checked, and the figures and stops.
        let periodic = MESSAGES.iter().filter(|m| m.cycle_time_ms > 0).count();
        assert_eq!(checks.len(), periodic + 1 + 3 + 1 + run.summary.stops.len());
        assert_eq!(run.summary.stops.len(), 1);
    }

    #[test]
    fn a_missing_or_late_message_fails() {
        let host = stop_100_dry();
        let mut firmware = host.clone();
        firmware.log.retain(|f| f.frame.id() != 0x021);
        assert_eq!(
            failed(&compare(&host, &firmware, &ECUS)),
            ["YawErrorMsg (every 10 ms)"]
        );
        // One period of AccMsg (100 ms) missed: a gap of two periods.
        let mut firmware = host.clone();
        let acc: Vec<u64> = host
            .log
            .iter()
            .filter(|f| f.frame.id() == 0x018)
            .map(|f| f.t_us)
            .collect();
        firmware
            .log
            .retain(|f| !(f.frame.id() == 0x018 && f.t_us == acc[10]));
        assert_eq!(
            failed(&compare(&host, &firmware, &ECUS)),
            ["AccMsg (every 100 ms)"]
        );
        // A message of an ECU on host logic is not the firmware's to keep.
        assert!(failed(&compare(&host, &firmware, &[Node::Cruise])).is_empty());
    }

    #[test]
    fn figures_beyond_their_tolerance_fail() {
        let host = stop_100_dry();
        let mut firmware = host.clone();
        firmware.summary.distance_m *= 1.009;
        firmware.summary.distance_m += host.summary.stops[0].distance_m * 0.019;
        firmware.summary.stops[0].distance_m *= 1.019;
        assert!(failed(&compare(&host, &firmware, &ECUS)).is_empty());
        let stopping: f64 = host.summary.stops.iter().map(|s| s.distance_m).sum();
        firmware.summary.distance_m = host.summary.distance_m * 1.01 + stopping * 0.02 + 0.01;
        firmware.summary.fuel_used_l *= 0.98;
        firmware.summary.stops[0].distance_m = host.summary.stops[0].distance_m * 0.979;
        firmware.summary.gear_sequence.push(2);
        assert_eq!(
            failed(&compare(&host, &firmware, &ECUS)),
            [
                "gear sequence",
                "distance",
                "fuel used",
                "stop 1 from 98 km/h, distance"
            ]
        );
    }
}
