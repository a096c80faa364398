//! `autoplug dashboard`: the web dashboard over the virtual car, a live bus or a log, on
//! the gateway's run ([`autoplug_gateway_app::run`]), with its data folder and firmware library.

use std::io::{self, Write};
use std::path::Path;
use std::sync::atomic::Ordering;

use autoplug_dashboard::dashboard::DataFolder;
use autoplug_live::sources::BusUrl;
use autoplug_virtual_car::firmware::FirmwareChoice;

use crate::cli::{CliError, DashboardArgs};

/// Prepares the data folder (and the firmware the virtual car runs), then runs the
/// gateway with the dashboard until Ctrl-C or `--duration`.
pub(crate) fn run(args: DashboardArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let DashboardArgs {
        bus,
        log,
        data,
        listen,
        token,
        read_only,
        web_origins,
        allowed_hosts,
        transmit,
        vehicle,
        duration,
        status,
        exit_with_input,
        fleet,
        fleet_db,
        firmware,
    } = args;
    if exit_with_input {
        // Reads until the other end closes (the parent ended, however it ended).
        std::thread::spawn(|| {
            let _ = io::copy(&mut io::stdin().lock(), &mut io::sink());
            autoplug_gateway_app::EXIT_WITH_INPUT.store(true, Ordering::SeqCst);
        });
    }
    let folder = DataFolder::prepare(&data).map_err(CliError::Log)?;
    let bus = log.map_or(bus, BusUrl::Replay);
    let virtual_car = matches!(bus, BusUrl::Virtual(_) | BusUrl::Dashboard);
    let firmware = firmware.choice(&bus, true)?;
    if virtual_car {
        firmware_library(&folder, firmware.as_ref(), out)?;
    }
    let token = match (token, read_only) {
        (_, true) => None,
        (Some(token), false) => {
            autoplug_dashboard::dashboard::check_token(&token).map_err(CliError::Log)?;
            Some(token)
        }
        (None, false) => Some(autoplug_dashboard::dashboard::new_token().map_err(CliError::Log)?),
    };
    let fleet_page = match fleet_db {
        Some(address) => {
            let page = autoplug_dashboard::fleet_page::FleetPage::open(&address)
                .map_err(CliError::Fleet)?;
            writeln!(out, "fleet page: campaigns of {}", page.name())?;
            Some(std::sync::Arc::new(page) as std::sync::Arc<dyn autoplug_web::FleetData>)
        }
        None => None,
    };
    let options = autoplug_gateway_app::GatewayOptions {
        firmware,
        transmit: (virtual_car || (transmit && matches!(bus, BusUrl::Transport(_))))
            .then_some(60_000_000),
        record: None,
        rotate: autoplug_logs::RotatePolicy::default(),
        record_format: autoplug_logs::RecordFormat::Candump,
        db: Some(folder.trips_db()),
        vehicle,
        speed: None,
        fast: false,
        duration,
        quiet: !status,
        replay_pages: (!matches!(bus, BusUrl::Replay(_))).then(|| {
            autoplug_dashboard::dashboard::ReplayPages::new(
                listen.ip(),
                data.clone(),
                token.clone(),
                &allowed_hosts,
            )
        }),
        web: Some(autoplug_web::WebConfig {
            addr: listen,
            allowed_origins: web_origins,
            allowed_hosts,
            token,
            trips_db: Some(folder.trips_db()),
            recordings_dir: Some(folder.recordings()),
            images_dir: Some(folder.images()),
            fleet: fleet_page,
            ..autoplug_web::WebConfig::loopback(0)
        }),
        recordings_dir: Some(folder.recordings()),
        fleet: fleet
            .config(Some(folder.root.join("fleet-state.json")))
            .map_err(CliError::Fleet)?,
    };
    Ok(autoplug_gateway_app::run(&bus, options, out)?)
}

/// The virtual car's firmware library in the data folder: the demonstration releases,
/// and what the ECUs that run as their firmware need.
fn firmware_library(
    folder: &DataFolder,
    firmware: Option<&FirmwareChoice>,
    out: &mut dyn Write,
) -> Result<(), CliError> {
    let emulated = firmware.map_or(&[][..], |c| &c.ecus[..]);
    for name in folder.add_demo_images(emulated).map_err(CliError::Log)? {
        writeln!(out, "firmware library: added {name}")?;
    }
    // The ECUs run as firmware: what they need, built from this checkout if
    // missing (nothing to prepare by hand). A build that fails is said; the
    // car then reports the missing ELF, the library the missing release.
    let cwd = std::env::current_dir().map_err(|e| CliError::Log(e.to_string()))?;
    let default_dir = Path::new(autoplug_virtual_car::firmware::DEFAULT_FIRMWARE_DIR);
    if let (Some(choice), Some(build)) = (
        firmware.filter(|c| c.dir == default_dir),
        autoplug_dashboard::dashboard::FirmwareBuild::at(&cwd),
    ) {
        let names: Vec<&str> = choice.ecus.iter().map(|n| n.name()).collect();
        writeln!(
            out,
            "firmware: building what is missing of {} in {}",
            names.join(", "),
            choice.dir.display()
        )?;
        out.flush()?;
        match build.firmware(&choice.ecus, &choice.dir) {
            Ok(built) if built.is_empty() => {}
            Ok(built) => writeln!(out, "firmware: built {}", built.join(", "))?,
            Err(e) => writeln!(out, "firmware: {e}")?,
        }
        if choice.dir.join("boot").is_file() {
            match build.demo_releases(&choice.ecus, folder) {
                Ok(written) => {
                    for name in written {
                        writeln!(out, "firmware library: built {name} (scripts/firmware-demo-images, the development key)")?;
                    }
                }
                Err(e) => writeln!(out, "firmware library: {e}")?,
            }
        }
    }
    for (ecu, variant, version) in autoplug_dashboard::dashboard::DEMO_IMAGES {
        let name = autoplug_dashboard::dashboard::demo_image_name(ecu, variant, version);
        if emulated.contains(&ecu) && !folder.images().join(&name).exists() {
            writeln!(
                out,
                "firmware library: no {name}; {} runs its firmware: put its signed releases there (scripts/firmware-demo-images {})",
                ecu.name(),
                folder.images().display()
            )?;
        }
    }
    Ok(())
}
