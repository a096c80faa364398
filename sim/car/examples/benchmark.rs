//! How fast the full virtual car runs (vehicle model at 1 ms, the nine ECUs, the bit-timed
//! bus, trace recording) on one core, and the bus load of the drive cycle.
//!
//!     cargo run --release -p autoplug-virtual-car --example benchmark [-- SCENARIO [RUNS]]
//!
//! Goals: at least 1000x real time, bus load under 35 %. Each run is timed on
//! its own; the best and median are reported, since other processes only ever slow a
//! run down.

use autoplug_virtual_car::report;
use autoplug_virtual_car::scenario::Scenario;
use std::path::Path;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let path = args
        .first()
        .map(String::as_str)
        .unwrap_or("scenarios/drive-cycle.toml");
    let runs: usize = args.get(1).and_then(|r| r.parse().ok()).unwrap_or(5);
    let scenario = match Scenario::load(Path::new(path)) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(2);
        }
    };
    let mut factors = Vec::with_capacity(runs);
    let mut summary = None;
    for _ in 0..runs {
        let start = Instant::now();
        let record = report::run(&scenario);
        let wall = start.elapsed().as_secs_f64();
        factors.push(scenario.duration_s / wall);
        summary = Some(record.summary);
    }
    factors.sort_by(f64::total_cmp);
    let summary = summary.expect("at least one run");
    let ticks = scenario.duration_s * 1000.0;
    let best = factors[factors.len() - 1];
    let median = factors[factors.len() / 2];
    println!(
        "scenario            {} ({:.0} s simulated, {} runs)",
        scenario.name, scenario.duration_s, runs
    );
    println!(
        "real-time factor    best {best:.0}x, median {median:.0}x, worst {:.0}x (goal: >= 1000x)",
        factors[0]
    );
    println!(
        "per 1 ms tick       {:.0} ns (best run)",
        scenario.duration_s / best / ticks * 1e9
    );
    println!(
        "bus load            {:.1} % mean, {:.1} % peak over 100 ms (goal: < 35 %)",
        summary.bus_load * 100.0,
        summary.bus_load_peak_100ms * 100.0
    );
    println!(
        "frames              {} ({:.0} per simulated second)",
        summary.frames,
        summary.frames as f64 / scenario.duration_s
    );
}
