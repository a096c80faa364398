//! `autoplug ids`, `autoplug dtcs` and `autoplug flash`: UDS over CAN with one ECU or all
//! nine, and the checks an image passes before a flash sends anything.

use std::io::Write;
use std::path::Path;

use autoplug_can::Node;
use autoplug_image::ImageHeader;
use autoplug_image_tool::{ImageToolError, SignatureCheck};
use indicatif::{ProgressBar, ProgressStyle};

use autoplug_tester::driver::{self, DriveError};
use autoplug_tester::names::{ecu_label, ECUS};
use autoplug_tester::DEV_SECURITY_SECRET;
use autoplug_tester::{
    dtc_table, identification_table, vin_line, DtcJob, FlashConfig, FlashJob, IdentJob,
};
use autoplug_transport::{Transport, Via};

use crate::cli::{CliError, FlashArgs, ReadArgs};

/// Reads the identification of the ECUs selected; an error if none answered.
pub(crate) fn ids(args: ReadArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let ReadArgs { via, ecu, timing } = args;
    let (rows, transport) = run_reading(&via, IdentJob::new(&ecu.ecus(), timing.tester_config()))?;
    write!(out, "{}", identification_table(&rows))?;
    writeln!(out, "{}", vin_line(&rows))?;
    let silent: Vec<String> = rows
        .iter()
        .filter(|r| !r.answered())
        .map(|r| ecu_label(r.ecu))
        .collect();
    if silent.len() == rows.len() {
        return Err(CliError::NoAnswer(format!(
            "no ECU answered on {} ({}): is the bus the right one, and are the ECUs powered?",
            transport.describe(),
            silent.join(", ")
        )));
    }
    Ok(())
}

/// Reads the trouble codes of the ECUs selected; an error if none answered.
pub(crate) fn dtcs(args: ReadArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let ReadArgs { via, ecu, timing } = args;
    let (reports, transport) = run_reading(&via, DtcJob::new(&ecu.ecus(), timing.tester_config()))?;
    write!(out, "{}", dtc_table(&reports))?;
    if reports.iter().all(|r| r.entries.is_err()) {
        return Err(CliError::NoAnswer(format!(
            "no ECU answered on {}: is the bus the right one, and are the ECUs powered?",
            transport.describe()
        )));
    }
    Ok(())
}

/// Runs a job that only reads (identification, DTCs: it cannot fail as a whole) over the
/// bus `via` names; gives its result and the transport, for messages.
fn run_reading<J>(via: &Via, mut job: J) -> Result<(J::Output, Box<dyn Transport>), CliError>
where
    J: autoplug_tester::Job<Error = std::convert::Infallible>,
{
    let mut transport = autoplug_transport::open(via)?;
    match driver::run(transport.as_mut(), &mut job) {
        Ok(output) => Ok((output, transport)),
        Err(DriveError::Transport(error)) => Err(error.into()),
        Err(DriveError::Job(never)) => match never {},
    }
}

/// Reads a security secret file: its bytes, less one final newline.
pub fn read_secret_file(path: &Path) -> Result<Vec<u8>, CliError> {
    let mut bytes = std::fs::read(path).map_err(|e| CliError::Secret {
        path: path.to_path_buf(),
        reason: format!("cannot read it: {e}"),
    })?;
    if bytes.ends_with(b"\r\n") {
        bytes.truncate(bytes.len() - 2);
    } else if bytes.ends_with(b"\n") {
        bytes.truncate(bytes.len() - 1);
    }
    if bytes.is_empty() {
        return Err(CliError::Secret {
            path: path.to_path_buf(),
            reason: "it is empty".into(),
        });
    }
    Ok(bytes)
}

/// Checks an image file against the ECU before anything is sent: a header, the right
/// ECU, the right length, and the signature if a key is given.
fn precheck_image(
    ecu: Node,
    path: &Path,
    key: Option<&Path>,
) -> Result<(Vec<u8>, ImageHeader), CliError> {
    let inspections = autoplug_image_tool::inspect_file(path, key)?;
    for inspection in &inspections {
        precheck_one(ecu, path, inspection)?;
    }
    let bytes = std::fs::read(path).map_err(|source| {
        CliError::Image(ImageToolError::Io {
            context: format!("cannot read the image '{}'", path.display()),
            source,
        })
    })?;
    // `inspect_file` returns at least one inspection, or an error.
    let header = inspections
        .first()
        .map(|i| i.header)
        .ok_or_else(|| CliError::WrongImage(format!("'{}' holds no image", path.display())))?;
    Ok((bytes, header))
}

/// One image of the file against the ECU.
fn precheck_one(
    ecu: Node,
    path: &Path,
    inspection: &autoplug_image_tool::Inspection,
) -> Result<(), CliError> {
    let header = inspection.header;
    if Some(header.node) != ecu.diag_node_number() {
        let target = ECUS
            .iter()
            .find(|n| n.diag_node_number() == Some(header.node))
            .map_or_else(|| format!("node 0x{:02X}", header.node), |n| ecu_label(*n));
        return Err(CliError::WrongImage(format!(
            "'{}' is an image for {target}, not for {}: the ECU would refuse it",
            path.display(),
            ecu_label(ecu)
        )));
    }
    let problems = inspection.problems();
    if !problems.is_empty() {
        return Err(ImageToolError::Corrupted {
            path: path.to_path_buf(),
            problems,
        }
        .into());
    }
    if let SignatureCheck::Invalid(error) = &inspection.signature {
        return Err(ImageToolError::Corrupted {
            path: path.to_path_buf(),
            problems: vec![error.to_string()],
        }
        .into());
    }
    Ok(())
}

/// Flashes an image into an ECU once it passed the checks, with a progress bar on stderr
/// and the job's report.
pub(crate) fn flash(args: FlashArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let FlashArgs {
        via,
        ecu,
        image,
        secret_file,
        key,
        reset_timeout,
        timing,
    } = args;
    let (bytes, header) = precheck_image(ecu, &image, key.as_deref())?;
    let secret = match secret_file.as_deref() {
        Some(path) => read_secret_file(path)?,
        None => DEV_SECURITY_SECRET.to_vec(),
    };
    let mut transport = autoplug_transport::open(&via)?;
    writeln!(
        out,
        "flashing {} with {} (version {}, {} bytes) via {}",
        ecu_label(ecu),
        image.display(),
        header.version,
        header.image_len(),
        transport.describe()
    )?;
    let total = header.image_len();
    let mut config = FlashConfig::new(ecu, bytes, &secret);
    config.tester = timing.tester_config();
    config.reset_timeout_us = (reset_timeout * 1e6) as u64;
    // `new` refuses only nodes without a diagnostic address, which `--ecu` cannot name.
    let mut job = FlashJob::new(config).map_err(|e| CliError::WrongImage(e.to_string()))?;
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template(
            "{msg:>14} [{bar:40.cyan/blue}] {bytes}/{total_bytes} {bytes_per_sec} {elapsed}",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    let observer = bar.clone();
    let mut phase = None;
    job.on_progress(move |progress| {
        if phase != Some(progress.phase) {
            phase = Some(progress.phase);
            if progress.phase == autoplug_tester::Phase::Transfer {
                // The rate shown is the transfer's, not diluted by the setup and erase.
                observer.reset();
            }
            observer.set_message(progress.phase.name());
        }
        // The image for the slot the ECU writes is known once the ECU said which it runs.
        observer.set_length(progress.total);
        observer.set_position(progress.transferred);
    });
    let result = driver::run(transport.as_mut(), &mut job);
    match result {
        Ok(report) => {
            bar.finish_and_clear();
            writeln!(out, "{report}")?;
            writeln!(out, "done: {} runs the new image", ecu_label(ecu))?;
            Ok(())
        }
        Err(DriveError::Job(error)) => {
            bar.abandon();
            writeln!(out, "{}", error.report)?;
            Err(CliError::Flash(Box::new(error)))
        }
        Err(DriveError::Transport(error)) => {
            bar.abandon();
            Err(error.into())
        }
    }
}
