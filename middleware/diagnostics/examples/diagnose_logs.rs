//! Prints the diagnosis of each log given: `cargo run -p autoplug-diagnostics --example diagnose_logs -- LOG...`
//! (a development aid for tuning thresholds; the user's command is `autoplug diagnose`).
use autoplug_diagnostics::Diagnostics;
use autoplug_gateway::{LogSource, Pipeline, Strictness};

fn main() {
    for path in std::env::args().skip(1) {
        let mut source = match LogSource::open(std::path::Path::new(&path)) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("{e}");
                continue;
            }
        };
        let mut pipeline = Pipeline::new(Strictness::Strict);
        let mut diagnostics = Diagnostics::new();
        if let Err(e) = pipeline.run(&mut source, &mut [&mut diagnostics], &mut || false) {
            eprintln!("{path}: {e}");
            continue;
        }
        println!("{path}");
        for d in diagnostics.report(pipeline.state()) {
            for f in &d.findings {
                println!(
                    "  {:<13} {:<8} {:<34} {:>8} {:<9} {}",
                    d.ecu.name(),
                    f.verdict.name(),
                    f.routine,
                    f.value.map_or("-".into(), |v| format!("{v:.3}")),
                    f.unit,
                    f.evidence
                );
            }
        }
    }
}
