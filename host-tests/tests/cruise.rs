//! Cruise control against the vehicle model (spec section 7: read speed, report the cruise
//! command, PI operation; section 8, scenario 1).

use autoplug_host_tests::*;

/// Engaged at 90 km/h on a level road: within ±1 km/h of the set speed in at most 8 s and
/// staying there; a +6 % grade step costs at most 3 km/h and is recovered.
#[test]
fn holds_the_set_speed_and_recovers_from_a_grade() {
    let s = scenario("cruise-hold");
    let r = run(&s);
    let cruise = r.summary.cruise.as_ref().expect("cruise engaged");
    let set = cruise.set_speed_kmh;
    assert!((set - 90.0).abs() < 1.0, "latched {set} km/h");
    let engaged = cruise.engaged_at_s;
    let settled = cruise.settle_time_s.expect("settles");
    assert!(settled <= 8.0, "settled after {settled} s");
    // Level road: from settling until the grade at 30 s, always within ±1 km/h.
    for row in window(&r.trace, engaged + settled, 30.0) {
        assert!(
            (row.speed_kmh - set).abs() <= 1.0,
            "{:.2} km/h at {:.2} s",
            row.speed_kmh,
            row.t_s
        );
        assert!(row.cruise_on);
    }
    // The grade: at most 3 km/h lost, and back within ±1 km/h by the end.
    let lowest = window(&r.trace, 30.0, 60.0)
        .map(|r| r.speed_kmh)
        .fold(f64::MAX, f64::min);
    assert!(set - lowest <= 3.0, "grade dip to {lowest:.2} km/h");
    assert!(
        lowest < set - 0.3,
        "the grade must actually load the controller"
    );
    for row in window(&r.trace, 50.0, 60.0) {
        assert!(
            (row.speed_kmh - set).abs() <= 1.0,
            "not recovered: {:.2} at {:.2} s",
            row.speed_kmh,
            row.t_s
        );
    }
    // A modest command, as in the report's figure.
    let largest = r
        .trace
        .iter()
        .map(|r| r.cruise_cmd.abs())
        .fold(0.0, f64::max);
    assert!(largest < 60.0, "command up to {largest}");
}

/// The faulty software (scenario 1): bang-bang, full throttle and full braking in turn,
/// and a tracking error clearly larger than the correct software's.
#[test]
fn faulty_cruise_oscillates_around_the_set_speed() {
    let good = run(&scenario("cruise-hold"));
    let bad = run(&scenario("cruise-faulty"));
    let good_rms = good.summary.cruise.as_ref().unwrap().rms_error_after_8s_kmh;
    let bad_cruise = bad.summary.cruise.as_ref().unwrap();
    assert!(
        bad_cruise.rms_error_after_8s_kmh > 2.0 * good_rms,
        "faulty rms {} vs correct {}",
        bad_cruise.rms_error_after_8s_kmh,
        good_rms
    );
    let full_throttle = bad.trace.iter().filter(|r| r.cruise_cmd >= 99.9).count();
    let full_brake = bad.trace.iter().filter(|r| r.cruise_cmd <= -99.9).count();
    assert!(
        full_throttle > 10 && full_brake > 10,
        "{full_throttle} / {full_brake} rows at full command"
    );
    // It keeps crossing the set speed: count sign changes of the error after 10 s.
    let set = bad_cruise.set_speed_kmh;
    let errors: Vec<f64> = window(&bad.trace, 10.0, 40.0)
        .map(|r| r.speed_kmh - set)
        .collect();
    let crossings = errors
        .windows(2)
        .filter(|w| w[0].signum() != w[1].signum())
        .count();
    assert!(crossings >= 6, "{crossings} crossings of the set speed");
}

/// A pedal press cancels cruise: the pedals send "off", the steering adopts it, cruise
/// disengages within a few frames.
#[test]
fn the_brake_pedal_cancels_cruise() {
    let s = inline(
        r#"
name = "cancel"
duration_s = 8.0
[initial]
speed_kmh = 90.0
gear = "5"
[driver]
accelerator = 22.0
economy_mode = true
[[at]]
t_s = 1.0
press = ["cruise_on"]
accelerator = 0.0
[[at]]
t_s = 5.0
brake = 20.0
"#,
    );
    let r = run(&s);
    assert!(at(&r.trace, 4.9).cruise_on, "engaged before the press");
    let off = r
        .trace
        .iter()
        .find(|row| row.t_s >= 5.0 && !row.cruise_on)
        .expect("cancelled");
    assert!(off.t_s <= 5.1, "still engaged at {:.2} s", off.t_s);
    for row in window(&r.trace, off.t_s, 8.0) {
        assert!(!row.cruise_on, "re-engaged at {:.2} s", row.t_s);
    }
}
