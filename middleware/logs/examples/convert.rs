//! Converts a CAN log (candump, ASC, BLF or MF4) to ASC, BLF, MF4 or candump, or dumps it
//! as JSON lines.
//!
//! ```text
//! cargo run -p autoplug-logs --example convert -- IN OUT.asc
//! cargo run -p autoplug-logs --example convert -- IN OUT.blf
//! cargo run -p autoplug-logs --example convert -- [--compress] IN OUT.mf4
//! cargo run -p autoplug-logs --example convert -- --recording [--crash] IN OUT.mf4
//! cargo run -p autoplug-logs --example convert -- [--direction] IN OUT.log
//! cargo run -p autoplug-logs --example convert -- --json IN
//! ```
//!
//! `--direction` appends python-can's ` R` / ` T` to candump lines. `--recording` writes
//! MF4 as the gateway records it (one growing data block), `--crash` leaves it as a
//! recorder killed after its last flush leaves it. `--json` prints one
//! object per frame (`{"t_us":..,"channel":..,"id":..,"extended":..,"kind":"data",
//! "direction":"rx","len":..,"data":"0A14","fd":false,"brs":false,"esi":false}`) or error (`{"error":"..","line":..,
//! "fatal":..}`), which tests/check_with_python.py compares with python-can and cantools.
//! Malformed lines are skipped and counted; the exit status is 1 on a fatal error (the
//! frames before it are written all the same).

use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;
use std::process::ExitCode;

use autoplug_logs::write::{export_asc, export_blf, export_candump, export_mf4, ExportError};
use autoplug_logs::{Direction, FrameKind, LogFormat};

fn usage() -> ExitCode {
    eprintln!("usage: convert [--direction] [--compress] IN OUT.asc|OUT.blf|OUT.mf4|OUT.log\n       convert --recording [--crash] IN OUT.mf4\n       convert --json IN");
    ExitCode::from(2)
}

fn json(input: &Path) -> Result<(), String> {
    let reader = autoplug_logs::open(input).map_err(|e| e.to_string())?;
    let stdout = io::stdout();
    let mut out = BufWriter::new(stdout.lock());
    let mut fatal = None;
    for item in reader {
        let line = match item {
            Ok(f) => {
                let data: String = f.data().iter().map(|b| format!("{b:02X}")).collect();
                let kind = match f.kind {
                    FrameKind::Data => "data",
                    FrameKind::Remote => "remote",
                    FrameKind::Error => "error",
                };
                let direction = match f.direction {
                    Direction::Rx => "rx",
                    Direction::Tx => "tx",
                };
                let fd = f.fd();
                format!(
                    "{{\"t_us\":{},\"channel\":{},\"id\":{},\"extended\":{},\"kind\":\"{kind}\",\"direction\":\"{direction}\",\"len\":{},\"data\":\"{data}\",\"fd\":{},\"brs\":{},\"esi\":{}}}",
                    f.t_us,
                    f.channel,
                    f.id,
                    f.extended,
                    f.len(),
                    fd.is_some(),
                    fd.is_some_and(|x| x.brs),
                    fd.is_some_and(|x| x.esi)
                )
            }
            Err(e) => {
                let text = e.to_string().replace('\\', "\\\\").replace('"', "\\\"");
                if e.fatal {
                    fatal = Some(e.to_string());
                }
                format!(
                    "{{\"error\":\"{text}\",\"line\":{},\"fatal\":{}}}",
                    e.line, e.fatal
                )
            }
        };
        writeln!(out, "{line}").map_err(|e| e.to_string())?;
    }
    out.flush().map_err(|e| e.to_string())?;
    fatal.map_or(Ok(()), Err)
}

/// IN as the gateway records MF4 (one growing data block); with `crash`, left as a
/// recorder killed after handing its records to the OS leaves it (`UnFinMF`).
fn record(input: &Path, output: &Path, crash: bool) -> Result<(), String> {
    let reader = autoplug_logs::open(input).map_err(|e| e.to_string())?;
    let file = File::create(output).map_err(|e| format!("{}: {e}", output.display()))?;
    let mut writer = autoplug_logs::Mf4Writer::growing(file).map_err(|e| e.to_string())?;
    for frame in reader {
        writer
            .write(&frame.map_err(|e| e.to_string())?)
            .map_err(|e| e.to_string())?;
    }
    if crash {
        writer.flush_data().map_err(|e| e.to_string())?;
    } else {
        writer.finish().map_err(|e| e.to_string())?;
    }
    Ok(())
}

fn convert(input: &Path, output: &Path, direction: bool, compress: bool) -> Result<(), String> {
    let reader = autoplug_logs::open(input).map_err(|e| e.to_string())?;
    let format = LogFormat::from_extension(output)
        .ok_or_else(|| format!("{}: name it .asc, .blf or .log", output.display()))?;
    let out =
        BufWriter::new(File::create(output).map_err(|e| format!("{}: {e}", output.display()))?);
    let summary = match format {
        LogFormat::Asc => export_asc(reader, out),
        LogFormat::Candump => export_candump(reader, out, direction),
        LogFormat::Blf => export_blf(reader, out),
        LogFormat::Mf4 => export_mf4(reader, out, compress).map(|(summary, _)| summary),
    }
    .map_err(|ExportError::Write(e)| format!("{}: {e}", output.display()))?;
    eprint!("{} frames written to {}", summary.frames, output.display());
    match summary.first_skipped {
        Some(first) => eprintln!("; {} malformed skipped (first: {})", summary.skipped, first),
        None => eprintln!(),
    }
    match summary.incomplete {
        Some(e) => Err(format!(
            "{}: {e} (the frames before it were written)",
            input.display()
        )),
        None => Ok(()),
    }
}

fn main() -> ExitCode {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let json_mode = args.iter().any(|a| a == "--json");
    let direction = args.iter().any(|a| a == "--direction");
    let compress = args.iter().any(|a| a == "--compress");
    let recording = args.iter().any(|a| a == "--recording");
    let crash = args.iter().any(|a| a == "--crash");
    args.retain(|a| {
        !matches!(
            a.as_str(),
            "--json" | "--direction" | "--compress" | "--recording" | "--crash"
        )
    });
    let result = match (json_mode, args.as_slice()) {
        (true, [input]) => json(Path::new(input)),
        (false, [input, output]) if recording => record(Path::new(input), Path::new(output), crash),
        (false, [input, output]) => {
            convert(Path::new(input), Path::new(output), direction, compress)
        }
        _ => return usage(),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("convert: {e}");
            ExitCode::FAILURE
        }
    }
}
