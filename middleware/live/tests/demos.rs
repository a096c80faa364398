//! The report's two demonstrations as host tests (spec section 8): the faulty software is
//! flashed over CAN by the middleware, the car shows the symptom, the correct software is
//! flashed, the symptom is gone. The same runs as `autoplug demo cruise` / `demo abs`.

use std::path::Path;

use autoplug_diagnostics::Verdict;
use autoplug_image::{SoftwareVariant, Version};
use autoplug_live::demo::{run, Demo, DemoReport};
use autoplug_virtual_car::scenario::Scenario;

fn demo(which: Demo) -> DemoReport {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(which.scenario_file());
    let scenario = Scenario::load(&path).expect("the demonstration's scenario");
    let report = run(which, &scenario).expect("the demonstration runs to its end");
    let flashed: Vec<_> = report
        .flashes
        .iter()
        .map(|(v, ver, _)| (*v, *ver))
        .collect();
    assert_eq!(
        flashed,
        [
            (SoftwareVariant::Faulty, Version::new(1, 1, 0)),
            (SoftwareVariant::Standard, Version::new(1, 2, 0)),
        ]
    );
    for (_, _, flash) in &report.flashes {
        println!(
            "{:?}: flashed {} bytes in {:.2} s, transfer {:.0} B/s",
            which,
            flash.image_len,
            flash.total_us as f64 * 1e-6,
            flash.transfer_throughput().unwrap_or(0.0)
        );
    }
    report
}

#[test]
fn scenario_1_the_faulty_cruise_oscillates_and_the_flashed_fix_holds_the_speed() {
    let report = demo(Demo::Cruise);
    let s = report.symptom;
    println!(
        "cruise rms tracking error: faulty {:.2} km/h, fixed {:.2} km/h",
        s.faulty, s.fixed
    );
    assert!(s.faulty > 1.0, "the faulty cruise oscillates: {s:?}");
    assert!(s.fixed < 0.6, "the correct cruise holds the speed: {s:?}");
    assert!(s.faulty > 2.5 * s.fixed, "{s:?}");
    gateway_flags_then_clears(&report, "tracking error");
}

/// The gateway's own diagnosis, from the bus alone: the ECU judged faulty with its number
/// before the fix, ok after it (its routines start over when the bus shows the ECU reset).
fn gateway_flags_then_clears(report: &DemoReport, routine: &str) {
    let [before, after] = &report.gateway;
    let finding = before.headline().unwrap();
    assert_eq!(
        (before.verdict, finding.routine),
        (Verdict::Faulty, routine),
        "{before:?}"
    );
    assert!(finding.value.unwrap() > finding.faulty_above, "{finding:?}");
    assert_eq!(after.verdict, Verdict::Ok, "{after:?}");
    let fixed = after
        .findings
        .iter()
        .find(|f| f.routine == routine)
        .unwrap();
    assert!(fixed.value.unwrap() <= fixed.suspect_above, "{fixed:?}");
    assert!(
        fixed
            .window
            .is_none_or(|w| w.from_us > finding.window.unwrap().to_us),
        "judged on the fixed software only: {fixed:?}"
    );
}

#[test]
fn scenario_2_the_faulty_abs_spins_the_car_and_the_flashed_fix_keeps_it_straight() {
    let report = demo(Demo::Abs);
    let s = report.symptom;
    println!(
        "heading change while braking on split friction: faulty {:.1} deg, fixed {:.1} deg",
        s.faulty, s.fixed
    );
    assert!(s.faulty > 45.0, "the faulty ABS spins the car: {s:?}");
    assert!(s.fixed < 15.0, "the correct ABS keeps it straight: {s:?}");
    gateway_flags_then_clears(&report, "longest wheel lock while braking");
}
