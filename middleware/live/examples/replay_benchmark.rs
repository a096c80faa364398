//! The gateway's replay throughput: a candump log through the whole pipeline (read, decode,
//! car state, every diagnostic routine, trips), as `autoplug replay` runs it.
//!
//! ```text
//! cargo run --release -p autoplug-live --example replay_benchmark -- make-log OUT.log MINUTES
//! cargo run --release -p autoplug-live --example replay_benchmark -- make-log OUT.mf4 MINUTES [--compress]
//! cargo run --release -p autoplug-live --example replay_benchmark -- replay LOG
//! cargo run --release -p autoplug-live --example replay_benchmark -- decode LOG
//! ```
//!
//! `make-log` writes the virtual car's drive cycle back to back, its times continued, until
//! the log lasts MINUTES (an hour: 24 drive cycles, about 4.3 million frames), as candump
//! or (`.mf4`) MDF 4 with every signal decoded, and says how fast it wrote (the drive is
//! simulated before the clock starts). `decode` reads any log and decodes every catalogue
//! frame against the DBC, nothing more (what asammdf's `extract_bus_logging` does).
//! `replay`
//! prints one line of figures: frames, seconds, frames per second and the process's peak
//! resident memory (VmHWM), which stays flat in the log's length since nothing is kept per
//! frame. `scripts/replay-benchmark` runs both beside python-can + cantools.

use std::io::{BufWriter, Write};
use std::path::Path;
use std::time::Instant;

use autoplug_gateway::{LogSource, Pipeline, Strictness};
use autoplug_live::watch::Watch;
use autoplug_logs::{CandumpWriter, LogFrame};
use autoplug_virtual_car::report;
use autoplug_virtual_car::scenario::Scenario;

fn make_log(out: &Path, minutes: f64, compress: bool) -> Result<(), String> {
    let scenario = Scenario::load(Path::new("scenarios/drive-cycle.toml"))
        .map_err(|e| format!("{e} (run from the repository root)"))?;
    let run = report::run(&scenario);
    let cycle_us = (scenario.duration_s * 1e6) as u64;
    let until_us = (minutes * 60e6) as u64;
    let file = std::fs::File::create(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let mf4 = out.extension().is_some_and(|e| e == "mf4");
    let started = Instant::now();
    let mut candump = None;
    let mut mdf = None;
    if mf4 {
        mdf = Some(
            autoplug_logs::Mf4Writer::new(BufWriter::new(file), compress)
                .map_err(|e| e.to_string())?,
        );
    } else {
        candump = Some(CandumpWriter::new(BufWriter::new(file)));
    }
    let mut offset = 0;
    let mut frames = 0u64;
    while offset < until_us {
        for f in &run.log {
            let t_us = offset + f.t_us;
            if t_us >= until_us {
                break;
            }
            let frame = LogFrame::from_can(t_us, 0, &f.frame);
            match (&mut candump, &mut mdf) {
                (Some(w), _) => w.write(&frame),
                (_, Some(w)) => w.write(&frame),
                _ => Ok(()),
            }
            .map_err(|e| e.to_string())?;
            frames += 1;
        }
        offset += cycle_us;
    }
    if let Some(w) = candump {
        w.finish()
            .map_err(|e| e.to_string())?
            .flush()
            .map_err(|e| e.to_string())?;
    }
    if let Some(w) = mdf {
        w.finish()
            .map_err(|e| e.to_string())?
            .flush()
            .map_err(|e| e.to_string())?;
    }
    let seconds = started.elapsed().as_secs_f64();
    println!(
        "wrote {} ({frames} frames, {minutes} min) in {seconds:.2} s = {:.0} frames/s, peak RSS {} kB",
        out.display(),
        frames as f64 / seconds,
        peak_rss_kb().map_or("?".into(), |k| k.to_string())
    );
    Ok(())
}

/// Reads a log and decodes every catalogue frame against the DBC.
fn decode(log: &Path) -> Result<(), String> {
    let started = Instant::now();
    let reader = autoplug_logs::open(log).map_err(|e| e.to_string())?;
    let (mut frames, mut decoded, mut sum) = (0u64, 0u64, 0.0f64);
    for item in reader {
        let frame = item.map_err(|e| e.to_string())?;
        frames += 1;
        if let Some(can) = frame.as_can_frame() {
            if let Ok(message) = autoplug_can::Message::decode(can.id(), can.data()) {
                decoded += 1;
                // Every signal's physical value, as extract_bus_logging gives them.
                for i in 0.. {
                    match message.signal(i) {
                        Some(v) => sum += f64::from(v),
                        None => break,
                    }
                }
            }
        }
    }
    let seconds = started.elapsed().as_secs_f64();
    println!(
        "autoplug read + decode: {frames} frames ({decoded} decoded, checksum {sum:.3e}) in {seconds:.2} s = {:.0} frames/s, peak RSS {} kB",
        frames as f64 / seconds,
        peak_rss_kb().map_or("?".into(), |k| k.to_string())
    );
    Ok(())
}

/// Peak resident memory of this process, kB (Linux), from /proc/self/status.
fn peak_rss_kb() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn replay(log: &Path) -> Result<(), String> {
    let started = Instant::now();
    let mut source = LogSource::open(log).map_err(|e| e.to_string())?;
    let mut pipeline = Pipeline::new(Strictness::Strict);
    let mut watch = Watch::new(None);
    pipeline
        .run(&mut source, &mut [&mut watch], &mut || false)
        .map_err(|e| e.to_string())?;
    watch.finish(pipeline.state());
    let seconds = started.elapsed().as_secs_f64();
    let frames = pipeline.state().counters().frames;
    let report = watch.diagnostics.report(pipeline.state());
    println!(
        "autoplug replay pipeline: {frames} frames in {seconds:.2} s = {:.0} frames/s, peak RSS {} kB, {} trip(s), {} ECU verdicts",
        frames as f64 / seconds,
        peak_rss_kb().map_or("?".into(), |k| k.to_string()),
        watch.ended.len(),
        report.len()
    );
    Ok(())
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.iter().map(String::as_str).collect::<Vec<_>>()[..] {
        ["make-log", out, minutes, ref rest @ ..] if rest.is_empty() || rest == ["--compress"] => {
            match minutes.parse::<f64>() {
                Ok(m) if m > 0.0 && m <= 24.0 * 60.0 => {
                    make_log(Path::new(out), m, !rest.is_empty())
                }
                _ => Err(format!("'{minutes}' is not a number of minutes (0, 1440]")),
            }
        }
        ["replay", log] => replay(Path::new(log)),
        ["decode", log] => decode(Path::new(log)),
        _ => Err("usage: replay_benchmark make-log OUT.log|OUT.mf4 MINUTES [--compress] | replay LOG | decode LOG".into()),
    };
    if let Err(e) = result {
        eprintln!("replay_benchmark: {e}");
        std::process::exit(1);
    }
}
