//! Shared helpers of the closed-loop tests: the shipped scenarios, runs, and trace queries.
//! The tests use the scenario files users run, so they check what a user sees.

use autoplug_virtual_car::car::TraceRow;
use autoplug_virtual_car::report::{self, RunRecord};
use autoplug_virtual_car::scenario::Scenario;
use std::path::PathBuf;

/// The repository's `scenarios/` folder.
pub fn scenarios_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenarios")
}

/// A shipped scenario by name (`cruise-hold` for `scenarios/cruise-hold.toml`).
pub fn scenario(name: &str) -> Scenario {
    let path = scenarios_dir().join(format!("{name}.toml"));
    Scenario::load(&path).unwrap_or_else(|e| panic!("{e}"))
}

/// A scenario from inline TOML.
pub fn inline(text: &str) -> Scenario {
    Scenario::parse(text, "inline").unwrap_or_else(|e| panic!("{e}"))
}

/// Runs a scenario to its end.
pub fn run(scenario: &Scenario) -> RunRecord {
    report::run(scenario)
}

/// Rows with `from <= t < to`.
pub fn window(trace: &[TraceRow], from: f64, to: f64) -> impl Iterator<Item = &TraceRow> {
    trace
        .iter()
        .filter(move |r| r.t_s >= from - 1e-9 && r.t_s < to - 1e-9)
}

/// The row at time `t` (the first at or after it).
pub fn at(trace: &[TraceRow], t: f64) -> &TraceRow {
    trace
        .iter()
        .find(|r| r.t_s >= t - 1e-9)
        .unwrap_or_else(|| panic!("no row at {t} s"))
}
