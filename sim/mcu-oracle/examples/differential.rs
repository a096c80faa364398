//! The emulated core against QEMU (`mps2-an386`, Debian's `qemu-system-arm`) on generated
//! instruction blocks: the long run of the differential test.
//!
//! ```text
//! cargo run --release -p autoplug-mcu-oracle --example differential -- [--blocks N] [--seed S] [--show K] [--only I]
//! ```
//!
//! Prints how many blocks ran and every disagreement (the first `--show` in full, with the
//! block's listing); exits non-zero if there was one. `--only I` runs block I of the seed.

use std::process::ExitCode;
use std::time::Instant;

use autoplug_mcu_oracle::differential::{compare, emulate};
use autoplug_mcu_oracle::{BlockGen, Qemu};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut blocks = 10_000u64;
    let mut seed = 1u64;
    let mut show = 3usize;
    let mut only = None;
    let mut it = args.iter();
    while let Some(arg) = it.next() {
        let value = it.next().and_then(|v| v.parse::<u64>().ok());
        match (arg.as_str(), value) {
            ("--blocks", Some(v)) => blocks = v,
            ("--seed", Some(v)) => seed = v,
            ("--show", Some(v)) => show = v as usize,
            ("--only", Some(v)) => only = Some(v),
            _ => {
                eprintln!("usage: differential [--blocks N] [--seed S] [--show K] [--only I]");
                return ExitCode::from(2);
            }
        }
    }
    let mut qemu = match Qemu::start() {
        Ok(qemu) => qemu,
        Err(e) => {
            eprintln!("differential: {e}");
            return ExitCode::FAILURE;
        }
    };
    let started = Instant::now();
    let indices: Vec<u64> = match only {
        Some(i) => vec![i],
        None => (0..blocks).collect(),
    };
    let mut disagreements = 0;
    let mut generator = BlockGen::new(seed);
    for &i in &indices {
        let block = if only.is_some() {
            BlockGen::block(seed, i)
        } else {
            generator.next()
        };
        let theirs = match qemu.run(&block) {
            Ok(outcome) => outcome,
            Err(e) => {
                eprintln!("QEMU on block {i}: {e}");
                return ExitCode::FAILURE;
            }
        };
        if let Err(report) = compare(&block, &emulate(&block), &theirs) {
            disagreements += 1;
            if disagreements <= show {
                println!("block {i} of seed {seed} disagrees:\n{report}\n");
            } else {
                println!("block {i}: {}", report.lines().next().unwrap_or_default());
            }
        }
    }
    println!(
        "{} blocks of seed {seed} in {:.1} s: {disagreements} disagreements",
        indices.len(),
        started.elapsed().as_secs_f64()
    );
    if disagreements == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
