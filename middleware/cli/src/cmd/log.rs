//! `autoplug log export`: a log converted to ASC, candump, BLF, MF4 or MCAP.

use std::io::{self, Write};
use std::path::PathBuf;

use crate::cli::{CliError, ExportArgs, ExportFormat};

/// `autoplug log export`: written to FILE.partial and renamed when complete, so a failed
/// or refused export never leaves a half-written file under the name asked for.
pub(crate) fn export(args: ExportArgs, out: &mut dyn Write) -> Result<(), CliError> {
    let ExportArgs {
        log,
        format,
        out: file,
        lenient,
        compress,
    } = args;
    if compress && format != ExportFormat::Mf4 {
        return Err(CliError::Log(
            "--compress is for --format mf4 (BLF and MCAP are always compressed, ASC and candump never)".into(),
        ));
    }
    if file.exists() {
        return Err(CliError::Log(format!(
            "{}: already exists (not overwritten)",
            file.display()
        )));
    }
    let mut reader = autoplug_logs::open(&log).map_err(|e| CliError::Log(e.to_string()))?;
    let mut partial = file.as_os_str().to_owned();
    partial.push(".partial");
    let partial = PathBuf::from(partial);
    let output = std::fs::File::create(&partial)
        .map_err(|e| CliError::Log(format!("cannot create {}: {e}", partial.display())))?;
    let writer = io::BufWriter::new(output);
    let mut decoded = None;
    let result = match format {
        ExportFormat::Asc => autoplug_logs::export_asc(&mut reader, writer),
        ExportFormat::Candump => autoplug_logs::write::export_candump(&mut reader, writer, false),
        ExportFormat::Blf => autoplug_logs::export_blf(&mut reader, writer),
        ExportFormat::Mf4 => {
            autoplug_logs::export_mf4(&mut reader, writer, compress).map(|(s, ok)| {
                decoded = Some((ok, 0));
                s
            })
        }
        ExportFormat::Mcap => autoplug_logs::export_mcap(&mut reader, writer).map(|s| {
            decoded = Some((s.decoded, s.undecodable));
            s.export
        }),
    };
    let dropped = reader.dropped_frames();
    let fail = |message: String| {
        let _ = std::fs::remove_file(&partial);
        CliError::Log(message)
    };
    let summary = result.map_err(|e| fail(format!("{}: {e}", log.display())))?;
    if let (false, Some(first)) = (lenient, &summary.first_skipped) {
        return Err(fail(format!(
            "{first} (use --lenient to skip malformed lines and count them)"
        )));
    }
    std::fs::rename(&partial, &file)
        .map_err(|e| fail(format!("cannot write {}: {e}", file.display())))?;
    writeln!(
        out,
        "wrote {} ({} frames{}{})",
        file.display(),
        summary.frames,
        decoded.map_or(String::new(), |(ok, bad)| format!(
            ", {ok} decoded into their messages' signals{}",
            if bad > 0 {
                format!(", {bad} not decodable (raw only)")
            } else {
                String::new()
            }
        )),
        if summary.skipped > 0 {
            format!(", {} malformed line(s) skipped", summary.skipped)
        } else {
            String::new()
        }
    )?;
    if dropped > 0 {
        writeln!(
            out,
            "{dropped} frame(s) dropped by the logger (its DROPCOUNT lines) are not in the log"
        )?;
    }
    // The frames before a damaged tail are written: the file is kept, the status says
    // it is not the whole log.
    match summary.incomplete {
        Some(e) => Err(CliError::Incomplete(format!(
            "{}: {e} (the {} frames before it were written)",
            log.display(),
            summary.frames
        ))),
        None => Ok(()),
    }
}
