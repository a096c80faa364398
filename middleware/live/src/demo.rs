//! The report's two demonstrations on the virtual car, with the middleware doing the
//! flashing over CAN exactly as on a bench (`autoplug demo cruise`, `autoplug demo abs`):
//!
//! 1. **Broken cruise control** (`scenarios/demo-cruise-flash.toml`): the faulty cruise
//!    software is flashed while the car stands; with cruise engaged at 90 km/h the speed
//!    oscillates around the set speed; the car stops, the correct software is flashed,
//!    cruise holds the speed again. The symptom: the rms tracking error.
//! 2. **Broken ABS** (`scenarios/demo-abs-flash.toml`): the faulty ABS software is
//!    flashed; full braking from about 140 km/h on split friction locks the wheels and the
//!    car spins; the correct software is flashed; the same braking keeps it straight. The
//!    symptom: the heading change during the stop.
//!
//! On host logic the images are made here, signed with the development key, and the
//! virtual ECU runs what the signed header names (a host cannot execute the ARM payload:
//! see `autoplug_virtual_car::diag`). On firmware ([`OnFirmware`]) the flashed ECU runs its
//! release firmware with the bootloader on an emulated STM32F446, and the images are
//! signed releases of the real builds (`scripts/firmware-release`, the faulty one built
//! with the `faulty` feature): the firmware's UDS server writes them into its other slot,
//! the bootloader checks the signature and starts them on trial, they confirm themselves,
//! and what the car does afterwards is what that code does.

use std::fmt;

use autoplug_can::Node;
use autoplug_diagnostics::{Diagnostics, EcuDiagnosis};
use autoplug_gateway::{Pipeline, Strictness};
use autoplug_image::{SigningKey, SoftwareVariant, Version};
use autoplug_logs::LogFrame;
use autoplug_virtual_car::car::VirtualCar;
use autoplug_virtual_car::diag::{build_image, FACTORY_PAYLOAD_LEN};
use autoplug_virtual_car::firmware::{FirmwareChoice, FirmwareLogLine};
use autoplug_virtual_car::report::{RunRecord, Summary, TRACE_PERIOD_US};
use autoplug_virtual_car::scenario::Scenario;

use crate::on_car::OnCar;
use autoplug_tester::DEV_SECURITY_SECRET;
use autoplug_tester::{FlashConfig, FlashError, FlashJob, FlashReport};

/// Which demonstration.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Demo {
    /// Report scenario 1: the cruise control.
    Cruise,
    /// Report scenario 2: the ABS.
    Abs,
}

/// One flash of a demonstration.
#[derive(Clone, Copy, Debug)]
struct Flash {
    /// When it starts (the car stands then), s.
    at_s: f64,
    variant: SoftwareVariant,
    version: Version,
}

impl Demo {
    /// The scenario file, relative to the repository root.
    pub fn scenario_file(self) -> &'static str {
        match self {
            Demo::Cruise => "scenarios/demo-cruise-flash.toml",
            Demo::Abs => "scenarios/demo-abs-flash.toml",
        }
    }

    /// The ECU flashed.
    pub fn ecu(self) -> Node {
        match self {
            Demo::Cruise => Node::Cruise,
            Demo::Abs => Node::ABS,
        }
    }

    /// The two flashes: the faulty software first, then the correct one (a newer
    /// version, as a real fix would be: the version floor forbids going back).
    fn flashes(self) -> [Flash; 2] {
        let second_at_s = match self {
            Demo::Cruise => 85.0,
            Demo::Abs => 50.0,
        };
        [
            Flash {
                at_s: 1.0,
                variant: SoftwareVariant::Faulty,
                version: Version::new(1, 1, 0),
            },
            Flash {
                at_s: second_at_s,
                variant: SoftwareVariant::Standard,
                version: Version::new(1, 2, 0),
            },
        ]
    }
}

/// A demonstration on firmware: which ECUs run as their firmware (the flashed one among
/// them), and the two signed releases flashed into it.
pub struct OnFirmware {
    /// The ECUs on emulated MCUs, and where their ELF files are.
    pub choice: FirmwareChoice,
    /// The faulty release (1.1.0) and the fix (1.2.0), each a file as
    /// `scripts/firmware-release` writes it (an image per slot).
    pub images: [Vec<u8>; 2],
}

/// How the symptom looked with each software.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Symptom {
    /// With the faulty software.
    pub faulty: f64,
    /// With the correct software, after the second flash.
    pub fixed: f64,
}

/// What a demonstration showed.
pub struct DemoReport {
    /// Which one.
    pub demo: Demo,
    /// The two flashes, in order.
    pub flashes: Vec<(SoftwareVariant, Version, FlashReport)>,
    /// Cruise: rms speed error around the set speed, km/h. ABS: heading change during
    /// the stop, degrees.
    pub symptom: Symptom,
    /// The whole run: trace, bus log, summary.
    pub record: RunRecord,
    /// The gateway's diagnosis of the flashed ECU from the bus alone: just before the fix
    /// (the faulty software, judged since the bus showed it start), and at the end (the
    /// correct software, judged since the fix).
    pub gateway: [EcuDiagnosis; 2],
    /// The emulated ECUs' defmt log (empty on host logic).
    pub firmware_log: Vec<FirmwareLogLine>,
}

/// A demonstration could not run to its end.
#[derive(Debug)]
pub enum DemoError {
    /// A flash failed.
    Flash(Box<FlashError>),
    /// A flash did not end within its time.
    FlashTimeout {
        /// When it started, s.
        at_s: f64,
    },
    /// The car did not do what the scenario needs (e.g. no stop to measure).
    Scenario(String),
    /// The firmware could not be loaded, or an emulated ECU stopped.
    Firmware(String),
}

impl fmt::Display for DemoError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DemoError::Flash(e) => write!(f, "flashing failed: {e}"),
            DemoError::FlashTimeout { at_s } => {
                write!(f, "the flash started at {at_s} s did not end in time")
            }
            DemoError::Scenario(why) => write!(f, "the scenario did not play out: {why}"),
            DemoError::Firmware(why) => write!(f, "firmware: {why}"),
        }
    }
}

impl std::error::Error for DemoError {}

/// Whether `choice` fits a demonstration on firmware: the releases go into the
/// demonstrated ECU, so that one must run as its firmware.
pub fn check_choice(demo: Demo, choice: &FirmwareChoice) -> Result<(), DemoError> {
    if choice.runs(demo.ecu()) {
        return Ok(());
    }
    Err(DemoError::Firmware(format!(
        "the releases are flashed into the {} ECU: it must run as its firmware (--firmware {})",
        demo.ecu().name(),
        autoplug_can::ecu_name(demo.ecu())
    )))
}

/// Runs a demonstration on `scenario` (normally [`Demo::scenario_file`]'s) on host logic.
pub fn run(demo: Demo, scenario: &Scenario) -> Result<DemoReport, DemoError> {
    run_on(demo, scenario, None)
}

/// Runs a demonstration on `scenario`, on host logic or on `firmware`.
pub fn run_on(
    demo: Demo,
    scenario: &Scenario,
    firmware: Option<&OnFirmware>,
) -> Result<DemoReport, DemoError> {
    let key = SigningKey::from_seed(autoplug_image::dev::SIGNING_SEED);
    let mut car = match firmware {
        None => VirtualCar::new(scenario),
        Some(on) => {
            check_choice(demo, &on.choice)?;
            VirtualCar::with_firmware(scenario, &on.choice).map_err(DemoError::Firmware)?
        }
    };
    let mut trace = Vec::new();
    let mut flashes = Vec::new();
    for (i, flash) in demo.flashes().into_iter().enumerate() {
        advance_to(&mut car, flash.at_s, &mut trace);
        let image = match firmware {
            Some(on) => on.images[i].clone(),
            None => build_image(
                demo.ecu(),
                flash.version,
                flash.variant,
                FACTORY_PAYLOAD_LEN,
                &key,
            ),
        };
        let job = FlashJob::new(FlashConfig::new(demo.ecu(), image, DEV_SECURITY_SECRET))
            .map_err(|e| DemoError::Scenario(e.to_string()))?;
        let mut on_car = OnCar::new(job, &mut car);
        let report = loop {
            car.tick();
            record_row(&car, &mut trace);
            if let Some(result) = on_car.step(&mut car) {
                break result.map_err(|e| DemoError::Flash(Box::new(e)))?;
            }
            if car.time_us() as f64 > (flash.at_s + 60.0) * 1e6 {
                return Err(DemoError::FlashTimeout { at_s: flash.at_s });
            }
        };
        flashes.push((flash.variant, flash.version, report));
    }
    advance_to(&mut car, scenario.duration_s, &mut trace);
    if let Some(stop) = car.firmware_stops().first() {
        return Err(DemoError::Firmware(format!(
            "the {} ECU stopped at {:.3} s: {}",
            stop.node.name(),
            stop.t_us as f64 * 1e-6,
            stop.reason
        )));
    }
    let firmware_log = car.take_firmware_log();
    trace.push(car.trace_row());
    let summary = Summary::compute(scenario, &trace, &car);
    let record = RunRecord {
        trace,
        log: car.log().to_vec(),
        summary,
        track: scenario.track.clone(),
    };
    let symptom = match demo {
        Demo::Cruise => Symptom {
            faulty: rms_cruise_error(&record, 55.0, 75.0)?,
            fixed: rms_cruise_error(&record, 140.0, 160.0)?,
        },
        Demo::Abs => {
            let stops: Vec<_> = record
                .summary
                .stops
                .iter()
                .filter(|s| s.from_kmh > 80.0)
                .collect();
            let [faulty, fixed] = stops[..] else {
                return Err(DemoError::Scenario(format!(
                    "expected two hard stops, found {}",
                    stops.len()
                )));
            };
            Symptom {
                faulty: faulty.heading_change_deg.abs(),
                fixed: fixed.heading_change_deg.abs(),
            }
        }
    };
    let fix_us = (demo.flashes()[1].at_s * 1e6) as u64;
    let gateway = gateway_diagnosis(demo.ecu(), &record, fix_us)?;
    Ok(DemoReport {
        demo,
        flashes,
        symptom,
        record,
        gateway,
        firmware_log,
    })
}

/// The gateway's diagnosis of `ecu` on the run's bus log at `fix_us` (before the fix is
/// flashed) and at the end: the same pipeline and routines as `autoplug gateway`.
fn gateway_diagnosis(
    ecu: Node,
    record: &RunRecord,
    fix_us: u64,
) -> Result<[EcuDiagnosis; 2], DemoError> {
    let mut pipeline = Pipeline::new(Strictness::Strict);
    let mut diagnostics = Diagnostics::new();
    let of_ecu = |diagnostics: &Diagnostics, pipeline: &Pipeline| {
        diagnostics
            .report(pipeline.state())
            .into_iter()
            .find(|d| d.ecu == ecu)
            .ok_or_else(|| DemoError::Scenario(format!("no diagnosis of {}", ecu.name())))
    };
    let mut before = None;
    for f in &record.log {
        if f.t_us >= fix_us && before.is_none() {
            before = Some(of_ecu(&diagnostics, &pipeline)?);
        }
        pipeline.feed(
            &LogFrame::from_can(f.t_us, 0, &f.frame),
            &mut [&mut diagnostics],
        );
    }
    let before =
        before.ok_or_else(|| DemoError::Scenario("the bus log ends before the fix".into()))?;
    Ok([before, of_ecu(&diagnostics, &pipeline)?])
}

fn record_row(car: &VirtualCar, trace: &mut Vec<autoplug_virtual_car::car::TraceRow>) {
    if car.time_us() % TRACE_PERIOD_US == 0 {
        trace.push(car.trace_row());
    }
}

fn advance_to(
    car: &mut VirtualCar,
    t_s: f64,
    trace: &mut Vec<autoplug_virtual_car::car::TraceRow>,
) {
    while (car.time_us() as f64) < t_s * 1e6 && !car.finished() {
        record_row(car, trace);
        car.tick();
    }
}

/// The rms difference between speed and set speed while cruise is engaged in [from, to) s.
fn rms_cruise_error(record: &RunRecord, from_s: f64, to_s: f64) -> Result<f64, DemoError> {
    let errors: Vec<f64> = record
        .trace
        .iter()
        .filter(|r| r.t_s >= from_s && r.t_s < to_s && r.cruise_on)
        .map(|r| r.speed_kmh - r.cruise_set_kmh)
        .collect();
    if errors.len() < 100 {
        return Err(DemoError::Scenario(format!(
            "cruise was engaged for only {} trace rows between {from_s} and {to_s} s",
            errors.len()
        )));
    }
    Ok((errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt())
}
