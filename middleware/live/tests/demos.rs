//! The report's two demonstrations as host tests (spec section 8): the faulty software is
//! flashed over CAN by the middleware, the car shows the symptom, the correct software is
//! flashed, the symptom is gone. The same runs as `autoplug demo cruise` / `demo abs`.
//!
//! The `*_on_firmware` tests (ignored: they need the firmware built for the MCU) run the
//! same with the flashed ECU on its release firmware and the bootloader, emulated, and the
//! real signed releases flashed: `scripts/firmware-demo-images target/demo-images`, then
//! `cargo test -p autoplug-live --test demos -- --ignored` (CI does).

use std::path::{Path, PathBuf};

use autoplug_diagnostics::Verdict;
use autoplug_image::{ImageSlot, SoftwareVariant, Version};
use autoplug_live::demo::{run_on, Demo, DemoReport, OnFirmware};
use autoplug_virtual_car::firmware::{FirmwareChoice, DEFAULT_FIRMWARE_DIR};
use autoplug_virtual_car::scenario::Scenario;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The flashed ECU on its firmware, the releases from `target/demo-images`.
fn on_firmware(which: Demo) -> OnFirmware {
    let ecu = autoplug_can::ecu_name(which.ecu());
    let images = root().join("target/demo-images");
    let read = |name: String| {
        std::fs::read(images.join(&name)).unwrap_or_else(|e| {
            panic!("{name}: {e}: build the releases first (scripts/firmware-demo-images target/demo-images)")
        })
    };
    OnFirmware {
        choice: FirmwareChoice::parse(ecu, &root().join(DEFAULT_FIRMWARE_DIR)).unwrap(),
        images: [
            read(format!("{ecu}-1.1.0-faulty.img")),
            read(format!("{ecu}-1.2.0.img")),
        ],
    }
}

fn demo(which: Demo) -> DemoReport {
    demo_on(which, None)
}

fn demo_on(which: Demo, firmware: Option<&OnFirmware>) -> DemoReport {
    let path = root().join(which.scenario_file());
    let scenario = Scenario::load(&path).expect("the demonstration's scenario");
    let report = run_on(which, &scenario, firmware).expect("the demonstration runs to its end");
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
    scenario_1(demo(Demo::Cruise));
}

#[test]
#[ignore = "needs the firmware and the releases: scripts/firmware-demo-images target/demo-images"]
fn scenario_1_on_firmware() {
    let report = demo_on(Demo::Cruise, Some(&on_firmware(Demo::Cruise)));
    went_through_the_bootloader(&report);
    scenario_1(report);
}

#[test]
#[ignore = "needs the firmware and the releases: scripts/firmware-demo-images target/demo-images"]
fn scenario_2_on_firmware() {
    let report = demo_on(Demo::Abs, Some(&on_firmware(Demo::Abs)));
    went_through_the_bootloader(&report);
    scenario_2(report);
}

/// The firmware took each release into its other slot, the bootloader started it on
/// trial, it confirmed itself, and it says which it is; the fix raised the version floor.
fn went_through_the_bootloader(report: &DemoReport) {
    let slots: Vec<_> = report.flashes.iter().map(|(_, _, f)| f.slot).collect();
    assert_eq!(slots, [Some(ImageSlot::B), Some(ImageSlot::A)]);
    let log: Vec<&str> = report
        .firmware_log
        .iter()
        .map(|l| l.text.as_str())
        .collect();
    for expected in [
        "boot: starting slot B on trial (new image)",
        "from slot B 1.1.0 (variant 1), version floor 0.0.0",
        "boot: starting slot A on trial (new image)",
        "from slot A 1.2.0 (variant 0), version floor 1.1.0",
    ] {
        assert!(
            log.iter().any(|l| l.contains(expected)),
            "no '{expected}' in the firmware's log:\n{}",
            log.join("\n")
        );
    }
    let confirmed = log
        .iter()
        .filter(|l| l.contains("self-test passed: this image is confirmed"))
        .count();
    assert_eq!(confirmed, 2, "{}", log.join("\n"));
}

fn scenario_1(report: DemoReport) {
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
    scenario_2(demo(Demo::Abs));
}

fn scenario_2(report: DemoReport) {
    let s = report.symptom;
    println!(
        "heading change while braking on split friction: faulty {:.1} deg, fixed {:.1} deg",
        s.faulty, s.fixed
    );
    assert!(s.faulty > 45.0, "the faulty ABS spins the car: {s:?}");
    assert!(s.fixed < 15.0, "the correct ABS keeps it straight: {s:?}");
    gateway_flags_then_clears(&report, "longest wheel lock while braking");
}
