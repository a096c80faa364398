//! Firmware that goes wrong on the virtual car: the cruise ECU's release ELF with a
//! few instructions patched in, so that it takes a HardFault, locks up until its watchdog
//! resets it, hangs until its watchdog resets it, or writes to a peripheral no model covers. Each gets a clear report
//! (the registers that say where, the last log lines) and the rest of the car runs on.
//!
//! Ignored: they need the firmware built for the MCU (`cargo build --profile firmware --target
//! thumbv7em-none-eabihf -p autoplug-boot -p ecu-cruise`); `cargo test -p
//! autoplug-virtual-car --test firmware_faults -- --ignored` (CI does).

use std::path::{Path, PathBuf};

use autoplug_can::{EngineMsg, PedalBrake, TransMsg, WheelSpeedMsg};
use autoplug_virtual_car::car::VirtualCar;
use autoplug_virtual_car::firmware::{FirmwareChoice, DEFAULT_FIRMWARE_DIR};
use autoplug_virtual_car::scenario::Scenario;
use object::{Object, ObjectSection, ObjectSymbol};

/// Thumb: UDF #0 (permanently undefined: a UsageFault, escalated to HardFault).
const UDF: [u16; 1] = [0xDE00];
/// Thumb: B . (a branch to itself).
const SPIN: [u16; 1] = [0xE7FE];
/// MOVW r0, #0x7400; MOVT r0, #0x4000; STR r0, [r0]; B . — a write to the DAC
/// (0x4000_7400), which the images never use and no model covers.
const WRITE_TO_DAC: [u16; 6] = [0xF247, 0x4000, 0xF2C4, 0x0000, 0x6000, 0xE7FE];

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// A firmware directory with the bootloader and the cruise firmware, `patches` (symbol,
/// Thumb halfwords) written over the code at those symbols.
fn patched(patches: &[(&str, &[u16])]) -> tempfile::TempDir {
    let release = root().join(DEFAULT_FIRMWARE_DIR);
    let dir = tempfile::tempdir().unwrap();
    let read = |name: &str| {
        std::fs::read(release.join(name)).unwrap_or_else(|e| {
            panic!("{name}: {e} (build the firmware first: cargo build --profile firmware --target thumbv7em-none-eabihf -p autoplug-boot -p ecu-cruise)")
        })
    };
    std::fs::write(dir.path().join("boot"), read("boot")).unwrap();
    let mut elf = read("cruise-fw");
    let mut writes = Vec::new();
    {
        let file = object::File::parse(&*elf).unwrap();
        for (symbol, code) in patches {
            // `a~b`: a mangled name holding both parts (its hash changes with every build).
            let matches = |name: &str| match symbol.split_once('~') {
                Some((a, b)) => name.contains(a) && name.contains(b),
                None => name == *symbol,
            };
            let address = file
                .symbols()
                .find(|s| s.name().is_ok_and(matches))
                .unwrap_or_else(|| panic!("no symbol {symbol}"))
                .address()
                & !1;
            let section = file
                .sections()
                .find(|s| (s.address()..s.address() + s.size()).contains(&address))
                .unwrap();
            let (offset, _) = section.file_range().unwrap();
            writes.push(((offset + address - section.address()) as usize, *code));
        }
    }
    for (at, code) in writes {
        for (i, halfword) in code.iter().enumerate() {
            elf[at + 2 * i..at + 2 * i + 2].copy_from_slice(&halfword.to_le_bytes());
        }
    }
    std::fs::write(dir.path().join("cruise-fw"), elf).unwrap();
    dir
}

/// The dashboard's scenario with the cruise ECU on the patched firmware, run for `ms`; what
/// the car reported, and how many frames the other ECUs sent in the last second.
fn run(dir: &Path, ms: u64) -> (VirtualCar, Vec<String>, usize) {
    let scenario = Scenario::load(&root().join("scenarios/dashboard.toml")).unwrap();
    let choice = FirmwareChoice::parse("cruise", dir).unwrap();
    let mut car = VirtualCar::with_firmware(&scenario, &choice).expect("the car starts");
    let mut lines = Vec::new();
    while car.time_us() < ms * 1000 {
        car.tick();
        lines.extend(car.take_firmware_log().iter().map(|l| l.to_string()));
    }
    let ids = [
        EngineMsg::ID,
        WheelSpeedMsg::ID,
        PedalBrake::ID,
        TransMsg::ID,
    ];
    let from_us = car.time_us() - 1_000_000;
    let others = car
        .log()
        .iter()
        .filter(|f| f.t_us >= from_us && ids.contains(&f.frame.id()))
        .count();
    (car, lines, others)
}

/// The others' periodic messages went on: EngineMsg, WheelSpeedMsg, PedalBrake and TransMsg
/// (10 and 20 ms periods) give well over 200 frames a second.
fn the_rest_runs_on(others: usize, lines: &[String]) {
    assert!(
        others > 200,
        "{others} frames of the other ECUs in the last second:\n{}",
        lines.join("\n")
    );
}

#[test]
#[ignore = "needs the firmware built for the MCU"]
fn a_hardfault_is_reported_with_its_registers_and_the_ecu_restarts() {
    let dir = patched(&[("main", &UDF)]);
    let (car, lines, others) = run(dir.path(), 2000);
    let fault = lines
        .iter()
        .find(|l| l.contains("emulator: HardFault at PC"))
        .unwrap_or_else(|| panic!("no HardFault report:\n{}", lines.join("\n")));
    for register in ["LR 0x", "CFSR 0x", "HFSR 0x"] {
        assert!(fault.contains(register), "{fault}");
    }
    println!("{fault}");
    // The firmware's fault handler resets the chip: the ECU starts again (and faults
    // again), and stays on the bus.
    let faults = lines
        .iter()
        .filter(|l| l.contains("emulator: HardFault"))
        .count();
    assert!(faults >= 2, "{faults} faults:\n{}", lines.join("\n"));
    assert!(
        car.firmware_stops().is_empty(),
        "{:?}",
        car.firmware_stops()
    );
    the_rest_runs_on(others, &lines);
}

#[test]
#[ignore = "needs the firmware built for the MCU"]
fn a_lockup_is_ended_by_the_watchdog_and_reported() {
    // A fault in the HardFault handler locks the core up. As on the chip, the lockup is no
    // reset: the independent watchdog the bootloader started (4 s) brings one.
    let dir = patched(&[("main", &UDF), ("HardFault", &UDF)]);
    let (car, lines, others) = run(dir.path(), 9000);
    let lockup = lines
        .iter()
        .find(|l| l.contains("emulator: the core locked up at"))
        .unwrap_or_else(|| panic!("no lockup reported:\n{}", lines.join("\n")));
    println!("{lockup}");
    assert!(lockup.contains("watchdog"), "{lockup}");
    assert!(
        lines
            .iter()
            .any(|l| l.contains("emulator: reset by the independent watchdog")),
        "no watchdog reset:\n{}",
        lines.join("\n")
    );
    // The ECU starts again (and locks up again), on the bus all along.
    let starts = lines
        .iter()
        .filter(|l| l.contains("boot: starting slot A"))
        .count();
    assert!(starts >= 2, "{starts} starts:\n{}", lines.join("\n"));
    assert!(
        car.firmware_stops().is_empty(),
        "{:?}",
        car.firmware_stops()
    );
    the_rest_runs_on(others, &lines);
}

#[test]
#[ignore = "needs the firmware built for the MCU"]
fn a_hang_is_ended_by_the_watchdog_and_reported() {
    // The control loop spins where it asks the diagnostic stack whether it is idle (once
    // a step, after the watchdog started): nothing feeds the watchdog.
    let dir = patched(&[("8DiagNode~9quiescent", &SPIN)]);
    let (car, lines, others) = run(dir.path(), 2000);
    let report = lines
        .iter()
        .find(|l| l.contains("emulator: reset by the independent watchdog"))
        .unwrap_or_else(|| panic!("no watchdog reset:\n{}", lines.join("\n")));
    println!("{report}");
    assert!(
        lines
            .iter()
            .any(|l| l.contains("reset cause: IndependentWatchdog")),
        "the firmware's own log says why it restarted:\n{}",
        lines.join("\n")
    );
    assert!(car.firmware_stops().is_empty());
    the_rest_runs_on(others, &lines);
}

#[test]
#[ignore = "needs the firmware built for the MCU"]
fn a_write_where_no_model_is_stops_the_ecu_with_the_address() {
    let dir = patched(&[("main", &WRITE_TO_DAC)]);
    let (car, lines, others) = run(dir.path(), 1000);
    let stop = car
        .firmware_stops()
        .first()
        .unwrap_or_else(|| panic!("no stop reported:\n{}", lines.join("\n")));
    println!("{}", stop.reason);
    assert!(stop.reason.contains("0x40007400"), "{}", stop.reason);
    the_rest_runs_on(others, &lines);
}
