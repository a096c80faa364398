//! `autoplug gateway`: the gateway on a live bus, the virtual car or a log, until it ends:
//! the arguments turned into the run's options ([`autoplug_gateway_app::run`] assembles it).

use std::io::Write;

use autoplug_gateway_app::GatewayOptions;

use crate::cli::{CliError, GatewayArgs, RecordFormatArg};

/// Watches the bus `--bus` names with the options of the command line.
pub(crate) fn run(args: GatewayArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let GatewayArgs {
        bus,
        record,
        rotate_mb,
        rotate_minutes,
        record_format,
        db,
        no_db,
        vehicle,
        speed,
        fast,
        duration,
        quiet,
        transmit,
        dtc_interval,
        web,
        web_origins,
        allowed_hosts,
        fleet,
        firmware,
    } = args;
    let options = GatewayOptions {
        firmware: firmware.choice(&bus, web.is_some())?,
        transmit: transmit.then_some((dtc_interval * 1e6) as u64),
        record,
        rotate: autoplug_logs::RotatePolicy {
            max_bytes: rotate_mb.map(|mb| mb * 1_000_000),
            max_duration_us: rotate_minutes.map(|m| m * 60_000_000),
        },
        record_format: match record_format {
            RecordFormatArg::Candump => autoplug_logs::RecordFormat::Candump,
            RecordFormatArg::Mf4 => autoplug_logs::RecordFormat::Mf4,
        },
        vehicle,
        speed,
        fast,
        duration,
        quiet,
        web: web.map(|addr| autoplug_web::WebConfig {
            addr,
            allowed_origins: web_origins,
            allowed_hosts,
            ..autoplug_web::WebConfig::loopback(0)
        }),
        recordings_dir: None,
        replay_pages: None,
        fleet: fleet
            .config((!no_db).then(|| db.with_file_name("fleet-state.json")))
            .map_err(CliError::Fleet)?,
        db: (!no_db).then_some(db),
    };
    Ok(autoplug_gateway_app::run(&bus, options, out)?)
}
