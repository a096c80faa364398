//! The active differential against the vehicle model (spec section 7: yaw-rate error,
//! torque split, PID operation).

use autoplug_host_tests::*;

/// Under a step steer at speed the peak yaw-rate error is clearly smaller with the
/// differential ECU active than with it disabled, and the split does not oscillate.
#[test]
fn step_steer_peak_yaw_error_is_smaller_with_the_differential() {
    let active = run(&scenario("diff-step-steer"));
    let open = run(&scenario("diff-step-steer-open"));
    let peak = |r: &autoplug_virtual_car::report::RunRecord| r.summary.peak_yaw_rate_error_rad_s;
    assert!(
        peak(&active) <= 0.8 * peak(&open),
        "peak yaw-rate error {} with the differential, {} without",
        peak(&active),
        peak(&open)
    );
    let integral = |r: &autoplug_virtual_car::report::RunRecord| {
        r.trace
            .iter()
            .map(|row| (row.yaw_rate_ref_rad_s - row.yaw_rate_rad_s).abs() * 0.01)
            .sum::<f64>()
    };
    assert!(integral(&active) <= 0.8 * integral(&open));
    assert!(
        open.trace.iter().all(|row| row.torque_split_nm == 0.0),
        "disabled: no split"
    );
    // The split acts, within the catalogue's ±50 N·m, and changes sign only a few times.
    let splits: Vec<f64> = active.trace.iter().map(|row| row.torque_split_nm).collect();
    assert!(splits.iter().any(|s| s.abs() > 10.0));
    assert!(splits.iter().all(|s| s.abs() <= 50.0 + 1e-9));
    let signs: Vec<f64> = splits
        .iter()
        .filter(|s| s.abs() > 1.0)
        .map(|s| s.signum())
        .collect();
    let reversals = signs.windows(2).filter(|w| w[0] != w[1]).count();
    assert!(reversals <= 3, "split reverses {reversals} times");
}
