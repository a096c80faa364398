//! Boots each ECU's release firmware through the bootloader on the emulated STM32F446 and
//! checks what a person with a board and a probe would check: the defmt log reaches the
//! control loop, the ECU sends its frames, nothing faults, no model is missing.
//!
//! ```text
//! cargo run --release -p autoplug-mcu --example boot_all -- target/thumbv7em-none-eabihf/firmware [MILLISECONDS]
//! ```

use std::process::ExitCode;
use std::time::Instant;

use autoplug_mcu::mcu::Mcu;
use autoplug_mcu::programming::FlashContents;
use autoplug_mcu::rtt::RttLog;

/// The ECUs' firmware names, from the catalogue's one list (`<name>-fw`).
fn ecus() -> impl Iterator<Item = &'static str> {
    autoplug_can::ECUS
        .iter()
        .map(|&node| autoplug_ecus::firmware_name(node))
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some(dir) = args.first() else {
        eprintln!("usage: boot_all FIRMWARE_DIR [MILLISECONDS]");
        return ExitCode::from(2);
    };
    let ms: u64 = match args.get(1).map(|a| a.parse()) {
        None => 1000,
        Some(Ok(ms)) => ms,
        Some(Err(_)) => {
            eprintln!("{}: not a number of milliseconds", args[1]);
            return ExitCode::from(2);
        }
    };
    let mut failed = false;
    for (n, ecu) in ecus().enumerate() {
        match boot(dir, ecu, n as u32, ms) {
            Ok(summary) => println!("{ecu:>9}: {summary}"),
            Err(why) => {
                println!("{ecu:>9}: FAILED: {why}");
                failed = true;
            }
        }
    }
    if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}

fn boot(dir: &str, ecu: &str, n: u32, ms: u64) -> Result<String, String> {
    let mut flash = FlashContents::erased();
    let mut logs = Vec::new();
    for file in [format!("{dir}/boot"), format!("{dir}/{ecu}-fw")] {
        let bytes = std::fs::read(&file).map_err(|e| format!("{file}: {e}"))?;
        flash
            .program_elf(&file, &bytes)
            .map_err(|e| e.to_string())?;
        if let Some(log) = RttLog::for_elf(&file, &bytes)? {
            logs.push(log);
        }
    }
    let mut mcu = Mcu::power_on(
        flash.to_sim_flash(n as u64),
        [0x0031_0042 + n, 0x3433_5107, 0x3236_3731],
    )
    .map_err(|e| e.to_string())?;
    let started = Instant::now();
    let mut lines = Vec::new();
    let mut result = Ok(());
    for step in 1..=ms {
        result = mcu.run_until(step * 1_000_000);
        for log in &mut logs {
            lines.extend(log.poll(&mut mcu.chip).into_iter().map(|l| l.text));
        }
        if result.is_err() {
            break;
        }
    }
    let wall = started.elapsed().as_secs_f64();
    let tail = lines
        .iter()
        .rev()
        .take(5)
        .rev()
        .cloned()
        .collect::<Vec<_>>()
        .join("\n    ");
    if let Err(stop) = result {
        return Err(format!("{stop}\n  last log lines:\n    {tail}"));
    }
    if let Some(fault) = mcu.faults.first() {
        return Err(format!(
            "HardFault {fault:?}\n  last log lines:\n    {tail}"
        ));
    }
    if !lines.iter().any(|l| l.contains("control loop")) {
        return Err(format!(
            "the log never reached the control loop\n  last log lines:\n    {tail}"
        ));
    }
    if mcu.sent.is_empty() {
        return Err("no CAN frame sent".into());
    }
    Ok(format!(
        "{} log lines, {} frames in {} ms, {:.2} M instructions per simulated s, {:.0} M instructions/s on this machine, resets {:?}",
        lines.len(),
        mcu.sent.len(),
        ms,
        mcu.cpu.instructions() as f64 / (ms as f64 / 1000.0) / 1e6,
        mcu.cpu.instructions() as f64 / wall / 1e6,
        mcu.resets.len(),
    ))
}
