//! The transmission against the vehicle model (spec section 7: gear, gear command, shift
//! logic; section 8: 1 → 6 to about 150 km/h).

use autoplug_host_tests::*;
use autoplug_virtual_car::car::TraceRow;

/// Speed at each upshift into gear 2..=6 (None when not reached).
fn upshift_speeds(trace: &[TraceRow]) -> [Option<f64>; 5] {
    let mut speeds = [None; 5];
    let mut last_forward = 0;
    for row in trace {
        if row.gear > last_forward && row.gear >= 2 {
            speeds[(row.gear - 2) as usize].get_or_insert(row.speed_kmh);
        }
        if row.gear > 0 {
            last_forward = row.gear;
        }
    }
    speeds
}

/// Full throttle in automatic: 1 → 6 in order, never back down (no hunting), reaching
/// 150 km/h.
#[test]
fn automatic_steps_through_every_gear_in_order() {
    let r = run(&scenario("accel-economy"));
    let forward: Vec<i32> = r
        .summary
        .gear_sequence
        .iter()
        .copied()
        .filter(|g| *g > 0)
        .collect();
    assert_eq!(
        forward,
        vec![1, 2, 3, 4, 5, 6],
        "gear sequence {:?}",
        r.summary.gear_sequence
    );
    assert!(
        r.summary.max_speed_kmh >= 150.0,
        "reached {} km/h",
        r.summary.max_speed_kmh
    );
}

/// Sport mode shifts later than economy: every upshift happens at a higher speed.
#[test]
fn sport_shifts_later_than_economy() {
    let economy = upshift_speeds(&run(&scenario("accel-economy")).trace);
    let sport = upshift_speeds(&run(&scenario("accel-sport")).trace);
    let mut compared = 0;
    for (i, (e, s)) in economy.iter().zip(sport).enumerate() {
        if let (Some(e), Some(s)) = (e, s) {
            assert!(
                s > e + 10.0,
                "upshift into {}: sport {s:.1} km/h, economy {e:.1} km/h",
                i + 2
            );
            compared += 1;
        }
    }
    assert!(compared >= 3, "only {compared} upshifts to compare");
}

/// Manual mode follows the paddles one gear per press and refuses a downshift that would
/// over-rev the engine.
#[test]
fn manual_mode_follows_requests_and_refuses_over_revving() {
    let s = inline(
        r#"
name = "manual"
duration_s = 12.0
[initial]
speed_kmh = 80.0
gear = "3"
[driver]
manual_mode = true
accelerator = 15.0
[[at]]
t_s = 2.0
press = ["shift_up"]
[[at]]
t_s = 4.0
press = ["shift_down"]
[[at]]
t_s = 6.0
press = ["shift_down"]
[[at]]
t_s = 8.0
press = ["shift_down"]
"#,
    );
    let r = run(&s);
    assert_eq!(
        at(&r.trace, 1.9).gear,
        3,
        "manual: no automatic shift before the first press"
    );
    assert_eq!(at(&r.trace, 3.9).gear, 4, "up");
    assert_eq!(at(&r.trace, 5.9).gear, 3, "down");
    // Near 80 km/h, 3rd -> 2nd gives about 6000 rpm: allowed; 2nd -> 1st about 9000: refused.
    let before = at(&r.trace, 7.9);
    assert_eq!(before.gear, 2, "down again");
    assert!(
        before.speed_kmh > 65.0,
        "{} km/h: 1st would not over-rev",
        before.speed_kmh
    );
    assert_eq!(
        at(&r.trace, 9.9).gear,
        2,
        "1st at this speed would over-rev: refused"
    );
    assert_eq!(r.trace.last().unwrap().gear, 2);
    assert!(r.trace.iter().all(|row| row.engine_rpm < 7100.0));
}

/// The transmission's gearbox calibration is the model's gearbox.
#[test]
fn the_transmission_calibration_matches_the_vehicle() {
    let p = autoplug_vehicle::VehicleParams::evo_vi();
    let ratios = autoplug_ecus::trans::GEAR_RATIOS.map(f64::from);
    for (ecu, car) in ratios.iter().zip(p.driveline.gear_ratios) {
        assert!((ecu - car).abs() < 1e-6, "{ecu} vs {car}");
    }
    assert!(
        (f64::from(autoplug_ecus::trans::REVERSE_RATIO) - p.driveline.reverse_ratio).abs() < 1e-6
    );
    assert!(
        (f64::from(autoplug_ecus::trans::FINAL_DRIVE_RATIO) - p.driveline.final_drive_ratio).abs()
            < 1e-6
    );
    assert!(
        (f64::from(autoplug_ecus::trans::TYRE_RADIUS_M) - p.tyre.rolling_radius_m).abs() < 1e-6
    );
}
