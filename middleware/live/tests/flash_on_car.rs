//! Flashing an ECU of the running virtual car leaves the rest of the car as it was: a flash
//! refused because the car moves never silences the bus (the car drives on its messages),
//! and a flash of a standing car leaves no "lost communication" code in any ECU, the
//! flashed one included.

use std::path::{Path, PathBuf};

use autoplug_can::{Node, VehicleSpeedMsg};
use autoplug_ecu::{lost_communication, Dtcs};
use autoplug_image::{SigningKey, SoftwareVariant, Version};
use autoplug_live::on_car::OnCar;
use autoplug_tester::{FlashConfig, FlashFailure, FlashJob, DEV_SECURITY_SECRET};
use autoplug_virtual_car::car::VirtualCar;
use autoplug_virtual_car::diag::{build_image, FACTORY_PAYLOAD_LEN};
use autoplug_virtual_car::scenario::Scenario;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn cruise_release() -> Vec<u8> {
    let key = SigningKey::from_seed(autoplug_image::dev::SIGNING_SEED);
    build_image(
        Node::Cruise,
        Version::new(1, 2, 0),
        SoftwareVariant::Standard,
        FACTORY_PAYLOAD_LEN,
        &key,
    )
}

fn flash(
    car: &mut VirtualCar,
) -> Result<autoplug_tester::FlashReport, Box<autoplug_tester::FlashError>> {
    let job = FlashJob::new(FlashConfig::new(
        Node::Cruise,
        cruise_release(),
        DEV_SECURITY_SECRET,
    ))
    .unwrap();
    OnCar::new(job, car)
        .run(car, 120_000_000)
        .expect("the flash ends within two minutes")
        .map_err(Box::new)
}

/// The longest time between two VehicleSpeedMsg frames (10 ms period) on the bus from
/// `from_us` on, µs.
fn longest_speed_gap_us(car: &VirtualCar, from_us: u64) -> u64 {
    let times: Vec<u64> = car
        .log()
        .iter()
        .filter(|f| f.t_us >= from_us && f.frame.id() == VehicleSpeedMsg::ID)
        .map(|f| f.t_us)
        .collect();
    assert!(times.len() > 100, "{} speed frames", times.len());
    times.windows(2).map(|w| w[1] - w[0]).max().unwrap()
}

fn lost_communication_codes(car: &VirtualCar) -> Vec<String> {
    let mut found = Vec::new();
    for (node, dtcs) in car.dtcs() {
        let dtcs: &Dtcs = dtcs;
        for other in autoplug_can::ECUS {
            // Any record: active now, or stored from a moment the flash caused.
            if dtcs.get(lost_communication(other)).is_some() {
                found.push(format!(
                    "{} holds {} (lost communication with {})",
                    node.name(),
                    lost_communication(other),
                    other.name()
                ));
            }
        }
    }
    found
}

#[test]
fn a_flash_refused_at_speed_never_silences_the_bus() {
    let scenario = Scenario::load(&root().join("scenarios/cruise-hold.toml")).unwrap();
    let mut car = VirtualCar::new(&scenario);
    while car.time_us() < 5_000_000 {
        car.tick();
    }
    let speed_before = car.vehicle().speed_mps * 3.6;
    assert!(speed_before > 85.0, "{speed_before} km/h");
    let from_us = car.time_us();
    let error = flash(&mut car).expect_err("a moving car is not flashed");
    assert!(
        matches!(error.failure, FlashFailure::NotStanding { .. }),
        "{error}"
    );
    let until_us = car.time_us();
    // The car's messages went on throughout: no gap longer than a few periods.
    let gap = longest_speed_gap_us(&car, from_us);
    println!(
        "refused after {:.1} s at {speed_before:.1} km/h: {error}; longest VehicleSpeedMsg gap {:.1} ms",
        (until_us - from_us) as f64 / 1e6,
        gap as f64 / 1e3
    );
    assert!(gap <= 30_000, "VehicleSpeedMsg paused for {gap} µs");
    // The car drove on at its cruise speed (a silent bus had it coast and brake).
    let speed_after = car.vehicle().speed_mps * 3.6;
    assert!(
        (speed_after - speed_before).abs() < 3.0,
        "{speed_before:.1} → {speed_after:.1} km/h"
    );
    assert!(
        lost_communication_codes(&car).is_empty(),
        "{:?}",
        lost_communication_codes(&car)
    );
}

#[test]
fn a_flash_of_a_standing_car_leaves_no_lost_communication_code_in_any_ecu() {
    let scenario = Scenario::parse("name = \"standing\"\nduration_s = 600.0\n", "test").unwrap();
    let mut car = VirtualCar::new(&scenario);
    while car.time_us() < 3_000_000 {
        car.tick();
    }
    assert!(lost_communication_codes(&car).is_empty());
    let report = flash(&mut car).expect("the flash succeeds");
    println!("{report}");
    // Some seconds on, for any code a late timeout would leave.
    let end = car.time_us() + 5_000_000;
    while car.time_us() < end {
        car.tick();
    }
    let codes = lost_communication_codes(&car);
    assert!(codes.is_empty(), "{codes:#?}");
}
