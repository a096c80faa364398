//! Runs the bootloader and an ECU's release firmware on the emulated STM32F446 for a
//! simulated time, and reports how it went.
//!
//! ```text
//! cargo run --release -p autoplug-mcu --example run -- \
//!     target/thumbv7em-none-eabihf/firmware/boot target/thumbv7em-none-eabihf/firmware/cruise-fw 100
//! ```

use std::process::ExitCode;
use std::time::Instant;

use autoplug_mcu::mcu::Mcu;
use autoplug_mcu::programming::FlashContents;
use autoplug_mcu::rtt::RttLog;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() != 3 {
        eprintln!("usage: run BOOT_ELF APP_ELF MILLISECONDS");
        return ExitCode::from(2);
    }
    let Ok(ms) = args[2].parse::<u64>() else {
        eprintln!("{}: not a number of milliseconds", args[2]);
        return ExitCode::from(2);
    };
    let mut flash = FlashContents::erased();
    let mut logs = Vec::new();
    for file in &args[..2] {
        let bytes = match std::fs::read(file) {
            Ok(bytes) => bytes,
            Err(e) => {
                eprintln!("{file}: {e}");
                return ExitCode::FAILURE;
            }
        };
        if let Err(e) = flash.program_elf(file, &bytes) {
            eprintln!("{e}");
            return ExitCode::FAILURE;
        }
        match RttLog::for_elf(file, &bytes) {
            Ok(Some(log)) => logs.push(log),
            Ok(None) => {}
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::FAILURE;
            }
        }
    }
    let mut mcu = match Mcu::power_on(
        flash.to_sim_flash(1),
        [0x0031_0042, 0x3433_5107, 0x3236_3731],
    ) {
        Ok(mcu) => mcu,
        Err(e) => {
            eprintln!("power-on: {e}");
            return ExitCode::FAILURE;
        }
    };
    let started = Instant::now();
    let mut result = Ok(());
    // A probe polls RTT now and then; every simulated millisecond here.
    for step in 1..=ms {
        result = mcu.run_until(step * 1_000_000);
        for log in &mut logs {
            for line in log.poll(&mut mcu.chip) {
                println!("{line}");
            }
        }
        if result.is_err() {
            break;
        }
    }
    let wall = started.elapsed();
    println!(
        "{} ms simulated in {:.3} s: {} instructions ({:.1} M/s), {} cycles, pc {:#010x}, {} frames sent, resets {:?}, faults {:?}",
        mcu.now_ns() / 1_000_000,
        wall.as_secs_f64(),
        mcu.cpu.instructions(),
        mcu.cpu.instructions() as f64 / wall.as_secs_f64() / 1e6,
        mcu.cpu.cycles(),
        mcu.cpu.pc(),
        mcu.sent.len(),
        mcu.resets,
        mcu.faults,
    );
    if let Err(stop) = result {
        eprintln!("stopped: {stop}");
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}
