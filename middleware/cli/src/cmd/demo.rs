//! `autoplug demo`: one of the report's demonstrations on the virtual car, the flashing
//! done over CAN by the tester, optionally on the ECUs' firmware.

use std::io::Write;
use std::path::Path;

use autoplug_image::{SoftwareVariant, Version};
use autoplug_image_tool::ImageToolError;
use autoplug_live::demo::Demo;
use autoplug_virtual_car::firmware::FirmwareChoice;
use autoplug_virtual_car::scenario::Scenario;

use crate::cli::{CliError, DemoArgs};

/// Runs the demonstration asked for, on the releases of `--images` with `--firmware`.
pub(crate) fn run(args: DemoArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let DemoArgs {
        which,
        out: dir,
        firmware,
        images,
    } = args;
    if !firmware.gdb.is_empty() {
        return Err(CliError::Demo(
            "--gdb: a demonstration runs as fast as it can; debug its firmware in `autoplug dashboard --firmware ... --gdb ECU` or `virtual-car run`".into(),
        ));
    }
    let on_firmware = match &firmware.firmware {
        None => None,
        Some(list) => Some(demo_on_firmware(
            which,
            FirmwareChoice::parse(list, &firmware.firmware_dir).map_err(CliError::Demo)?,
            images.as_deref(),
        )?),
    };
    demo(which, dir.as_deref(), on_firmware.as_ref(), out)
}

/// The releases a demonstration on firmware flashes, read from `images` and checked: the
/// demonstrated ECU's, the faulty 1.1.0 and the correct 1.2.0, signed with the development
/// key the firmware's bootloader trusts.
fn demo_on_firmware(
    which: Demo,
    choice: FirmwareChoice,
    images: Option<&Path>,
) -> Result<autoplug_live::demo::OnFirmware, CliError> {
    autoplug_live::demo::check_choice(which, &choice).map_err(|e| CliError::Demo(e.to_string()))?;
    let dir = images.ok_or_else(|| {
        CliError::Demo(
            "--firmware needs --images DIR, the signed releases to flash (scripts/firmware-demo-images DIR builds them)"
                .into(),
        )
    })?;
    let mut files = Vec::new();
    for (variant, version) in [
        (SoftwareVariant::Faulty, Version::new(1, 1, 0)),
        (SoftwareVariant::Standard, Version::new(1, 2, 0)),
    ] {
        let path = dir.join(autoplug_dashboard::dashboard::demo_image_name(
            which.ecu(),
            variant,
            version,
        ));
        let bytes = std::fs::read(&path).map_err(|source| {
            CliError::Image(ImageToolError::Io {
                context: format!("cannot read the release '{}'", path.display()),
                source,
            })
        })?;
        let inspections =
            autoplug_image_tool::inspect(&bytes, Some(&autoplug_image::dev::PUBLIC_KEY)).map_err(
                |source| {
                    CliError::Image(ImageToolError::NotAnImage {
                        path: path.clone(),
                        source,
                    })
                },
            )?;
        for inspection in &inspections {
            let h = &inspection.header;
            if Some(h.node) != which.ecu().diag_node_number()
                || h.variant != variant
                || h.version != version
            {
                return Err(CliError::WrongImage(format!(
                    "'{}' is {} software {} for ECU node {} (the demonstration flashes the {} ECU's {variant} software {version})",
                    path.display(),
                    h.variant,
                    h.version,
                    h.node,
                    which.ecu().name(),
                )));
            }
            if let Some(problem) = inspection.problems().first() {
                return Err(CliError::WrongImage(format!(
                    "'{}': {problem} (the firmware's bootloader trusts the development key)",
                    path.display()
                )));
            }
        }
        files.push(bytes);
    }
    let [faulty, fixed] = <[Vec<u8>; 2]>::try_from(files)
        .map_err(|_| CliError::Demo("two releases expected".into()))?;
    Ok(autoplug_live::demo::OnFirmware {
        choice,
        images: [faulty, fixed],
    })
}

/// Runs a demonstration and reports what it showed.
fn demo(
    which: Demo,
    dir: Option<&Path>,
    firmware: Option<&autoplug_live::demo::OnFirmware>,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let path = Path::new(which.scenario_file());
    let scenario = Scenario::load(path).map_err(|e| CliError::Demo(e.to_string()))?;
    let report = autoplug_live::demo::run_on(which, &scenario, firmware)
        .map_err(|e| CliError::Demo(e.to_string()))?;
    let w = |out: &mut dyn Write, text: String| writeln!(out, "{text}").map_err(CliError::Output);
    w(
        out,
        format!("{} ({})", scenario.name, which.scenario_file()),
    )?;
    if let Some(on) = firmware {
        let names: Vec<_> = on.choice.ecus.iter().map(|n| n.name()).collect();
        w(
            out,
            format!(
                "on firmware: {} run their release firmware with the bootloader on emulated STM32F446s; {} defmt log lines",
                names.join(", "),
                report.firmware_log.len()
            ),
        )?;
    }
    for (variant, version, flash) in &report.flashes {
        w(
            out,
            format!(
                "flashed {variant} software {version} into the {} ECU over CAN:",
                which.ecu().name()
            ),
        )?;
        w(out, format!("{flash}"))?;
    }
    let s = report.symptom;
    match which {
        Demo::Cruise => w(
            out,
            format!(
                "cruise at 90 km/h, rms speed error around the set speed: faulty software {:.2} km/h, correct software {:.2} km/h",
                s.faulty, s.fixed
            ),
        )?,
        Demo::Abs => w(
            out,
            format!(
                "full braking on split friction, heading change: faulty software {:.1} deg, correct software {:.1} deg",
                s.faulty, s.fixed
            ),
        )?,
    }
    for (when, d) in ["before the fix", "after the fix"]
        .iter()
        .zip(&report.gateway)
    {
        let finding = d.headline().map_or("-".to_string(), |f| {
            format!(
                "{}: {} (suspect above {}, faulty above {}{})",
                f.routine,
                f.value.map_or("-".into(), |v| format!("{v:.2} {}", f.unit)),
                f.suspect_above,
                f.faulty_above,
                f.window.map_or(String::new(), |w| format!(", over {w}"))
            )
        });
        w(
            out,
            format!(
                "gateway diagnosis {when}: {} {}, {finding}",
                which.ecu().name(),
                d.verdict.name().to_uppercase()
            ),
        )?;
    }
    if let Some(dir) = dir {
        let dir = dir.join(&scenario.name);
        std::fs::create_dir_all(&dir).map_err(CliError::Output)?;
        autoplug_virtual_car::report::write_outputs(&dir, &report.record)
            .map_err(CliError::Output)?;
        if firmware.is_some() {
            let text: String = report
                .firmware_log
                .iter()
                .map(|line| format!("{line}\n"))
                .collect();
            std::fs::write(dir.join("firmware.log"), text).map_err(CliError::Output)?;
        }
        w(out, format!("written to {}", dir.display()))?;
    }
    Ok(())
}
