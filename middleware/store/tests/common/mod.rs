//! Sample data for the tests: every field distinct, so a swapped column shows.
#![allow(dead_code)] // each test file uses a part

use autoplug_store::{DtcRecord, EcuIdentity, FinishedTrip, NewTrip, VerdictRecord};
use autoplug_trips::{SeriesPoint, TripEnd, TripStats};

pub fn new_trip(vehicle: &str, started_at_unix_ms: i64) -> NewTrip {
    NewTrip {
        vehicle: vehicle.into(),
        source: "socketcand://192.168.7.2:29536/can0".into(),
        started_at_unix_ms,
        start_us: 5_000_000,
    }
}

/// Statistics after `k` checkpoints, every field different from the others and from those
/// of another `k`.
pub fn stats(k: u32) -> TripStats {
    let x = f64::from(k);
    TripStats {
        start_us: 5_000_000,
        end_us: 5_000_000 + u64::from(k) * 1_000_003,
        distance_m: 11.5 * x,
        duration_s: 1.000_003 * x,
        moving_time_s: 0.75 * x,
        fuel_used_l: 0.001_25 * x,
        max_speed_kmh: 40.0 + x,
        mean_speed_kmh: 30.0 + x / 2.0,
        abs_interventions: k,
        abs_time_s: 0.125 * x,
        hard_brakings: 2 * k,
        shifts: 3 * k,
        cruise_time_s: 0.5 * x,
        diff_interventions: 4 * k,
        diff_time_s: 0.25 * x,
    }
}

pub const SPEED: &str = "Vehicle.Speed";
pub const RPM: &str = "Vehicle.Powertrain.CombustionEngine.Speed";

pub fn point(signal: &str, t_s: f64) -> SeriesPoint {
    SeriesPoint {
        signal: signal.into(),
        t_s,
        mean: t_s * 2.0 + 0.5,
        min: t_s * 2.0,
        max: t_s * 2.0 + 1.25,
    }
}

/// The points of both signals for buckets `from..to` (0.5 s buckets).
pub fn points(from: u32, to: u32) -> Vec<SeriesPoint> {
    (from..to)
        .flat_map(|i| {
            let t = f64::from(i) * 0.5;
            [point(SPEED, t), point(RPM, t)]
        })
        .collect()
}

pub fn finished(k: u32) -> FinishedTrip {
    FinishedTrip {
        stats: stats(k),
        end: TripEnd::BusSilent,
        verdicts: vec![
            VerdictRecord {
                ecu: "cruise".into(),
                verdict: "suspect".into(),
                routine: "cruise tracking error".into(),
                number: Some(3.75),
                unit: "km/h".into(),
                suspect_above: 3.0,
                faulty_above: 6.0,
                window_s: Some((12.5, 42.0)),
                evidence: "mean |set - actual| over 29.5 s of cruise".into(),
            },
            VerdictRecord {
                ecu: "abs".into(),
                verdict: "no data".into(),
                routine: "wheel lock".into(),
                number: None,
                unit: "s".into(),
                suspect_above: 0.2,
                faulty_above: f64::INFINITY,
                window_s: None,
                evidence: "no braking above 30 km/h".into(),
            },
        ],
        dtcs: vec![
            DtcRecord {
                ecu: "engine".into(),
                code: "U0126-87".into(),
                status: 0x2F,
                description: "lost communication with steering angle sensor".into(),
            },
            DtcRecord {
                ecu: "abs".into(),
                code: "C0035-1C".into(),
                status: 0xFF,
                description: "left front wheel speed sensor".into(),
            },
        ],
    }
}

pub fn identity(ecu: &str, node: u8, software: &str) -> EcuIdentity {
    EcuIdentity {
        ecu: ecu.into(),
        node,
        part_number: Some(format!("MR{node:03}-{ecu}")),
        software_version: Some(software.into()),
        hardware_version: Some("B".into()),
        serial_number: Some(format!("SN-{ecu}-0042")),
    }
}
