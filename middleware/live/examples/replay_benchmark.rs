//! The gateway's replay throughput: a candump log through the whole pipeline (read, decode,
//! car state, every diagnostic routine, trips), as `autoplug replay` runs it.
//!
//! ```text
//! cargo run --release -p autoplug-live --example replay_benchmark -- make-log OUT.log MINUTES
//! cargo run --release -p autoplug-live --example replay_benchmark -- replay LOG
//! ```
//!
//! `make-log` writes the virtual car's drive cycle back to back, its times continued, until
//! the log lasts MINUTES (an hour: 24 drive cycles, about 4.3 million frames). `replay`
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

fn make_log(out: &Path, minutes: f64) -> Result<(), String> {
    let scenario = Scenario::load(Path::new("scenarios/drive-cycle.toml"))
        .map_err(|e| format!("{e} (run from the repository root)"))?;
    let run = report::run(&scenario);
    let cycle_us = (scenario.duration_s * 1e6) as u64;
    let until_us = (minutes * 60e6) as u64;
    let file = std::fs::File::create(out).map_err(|e| format!("{}: {e}", out.display()))?;
    let mut writer = CandumpWriter::new(BufWriter::new(file));
    let mut offset = 0;
    let mut frames = 0u64;
    while offset < until_us {
        for f in &run.log {
            let t_us = offset + f.t_us;
            if t_us >= until_us {
                break;
            }
            writer
                .write(&LogFrame::from_can(t_us, 0, &f.frame))
                .map_err(|e| e.to_string())?;
            frames += 1;
        }
        offset += cycle_us;
    }
    let mut inner = writer.finish().map_err(|e| e.to_string())?;
    inner.flush().map_err(|e| e.to_string())?;
    println!("wrote {} ({frames} frames, {minutes} min)", out.display());
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
        ["make-log", out, minutes] => match minutes.parse::<f64>() {
            Ok(m) if m > 0.0 && m <= 24.0 * 60.0 => make_log(Path::new(out), m),
            _ => Err(format!("'{minutes}' is not a number of minutes (0, 1440]")),
        },
        ["replay", log] => replay(Path::new(log)),
        _ => Err("usage: replay_benchmark make-log OUT.log MINUTES | replay LOG".into()),
    };
    if let Err(e) = result {
        eprintln!("replay_benchmark: {e}");
        std::process::exit(1);
    }
}
