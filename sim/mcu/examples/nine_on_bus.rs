//! The nine release firmwares on one bit-timed virtual bus, each on its own emulated
//! STM32F446: they boot through the bootloader, send their frames, and hear each other's
//! (an ECU whose inputs arrive no longer reports them stale). Prints each ECU's frames
//! sent and received, its warnings, and the bus load; fails if an ECU stops, faults or
//! sends nothing.
//!
//! ```text
//! cargo run --release -p autoplug-mcu --example nine_on_bus -- target/thumbv7em-none-eabihf/release [MS]
//! ```

use std::process::ExitCode;
use std::time::Instant;

use autoplug_mcu::mcu::Mcu;
use autoplug_mcu::node::{run_together, BusNode};
use autoplug_mcu::programming::FlashContents;
use autoplug_mcu::rtt::RttLog;
use autoplug_virtual_bus::{BusConfig, VirtualBus};

const ECUS: [&str; 9] = [
    "engine", "pedals", "steering", "trans", "cabin", "console", "diff", "cruise", "abs",
];

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = args
        .first()
        .map_or("target/thumbv7em-none-eabihf/release", String::as_str);
    let ms: u64 = match args.get(1).map(|a| a.parse()) {
        None => 3000,
        Some(Ok(ms)) => ms,
        Some(Err(_)) => {
            eprintln!("{}: not a number of milliseconds", args[1]);
            return ExitCode::from(2);
        }
    };
    let mut bus = VirtualBus::new(BusConfig::default());
    let mut nodes = Vec::new();
    let mut logs: Vec<Vec<RttLog>> = Vec::new();
    for (n, ecu) in ECUS.iter().enumerate() {
        let mut flash = FlashContents::erased();
        let mut ecu_logs = Vec::new();
        for file in [format!("{dir}/boot"), format!("{dir}/{ecu}-fw")] {
            let bytes = match std::fs::read(&file) {
                Ok(bytes) => bytes,
                Err(e) => {
                    eprintln!("{file}: {e}");
                    return ExitCode::FAILURE;
                }
            };
            if let Err(e) = flash.program_elf(&file, &bytes) {
                eprintln!("{e}");
                return ExitCode::FAILURE;
            }
            match RttLog::for_elf(&file, &bytes) {
                Ok(Some(log)) => ecu_logs.push(log),
                Ok(None) => {}
                Err(e) => {
                    eprintln!("{e}");
                    return ExitCode::FAILURE;
                }
            }
        }
        let mcu = match Mcu::power_on(
            flash.to_sim_flash(n as u64),
            [0x0031_0042 + n as u32, 0x3433_5107, 0x3236_3731],
        ) {
            Ok(mcu) => mcu,
            Err(e) => {
                eprintln!("{ecu}: {e}");
                return ExitCode::FAILURE;
            }
        };
        nodes.push(BusNode::attach(&mut bus, ecu, mcu));
        logs.push(ecu_logs);
    }
    let started = Instant::now();
    let mut warnings = vec![Vec::new(); ECUS.len()];
    let mut failed = false;
    for step in 1..=ms {
        if let Err((i, stop)) = run_together(&mut bus, &mut nodes, step * 1_000_000) {
            println!("{}: stopped: {stop}", ECUS[i]);
            failed = true;
            break;
        }
        for (i, node) in nodes.iter_mut().enumerate() {
            for log in &mut logs[i] {
                for line in log.poll(&mut node.mcu.chip) {
                    if line.level.as_deref() == Some("WARN")
                        || line.level.as_deref() == Some("ERROR")
                    {
                        warnings[i].push((step, line.text));
                    }
                }
            }
        }
    }
    let wall = started.elapsed().as_secs_f64();
    for (i, node) in nodes.iter().enumerate() {
        let stats = bus.node_stats(node.node);
        let late: Vec<_> = warnings[i]
            .iter()
            .filter(|(at, _)| *at > 1500)
            .map(|(at, text)| format!("{at} ms: {text}"))
            .collect();
        println!(
            "{:>9}: {} frames sent, {} received, {} warnings ({} after 1.5 s){}",
            ECUS[i],
            stats.tx_frames,
            stats.rx_frames,
            warnings[i].len(),
            late.len(),
            if late.is_empty() {
                String::new()
            } else {
                format!(": {}", late.join("; "))
            }
        );
        if stats.tx_frames == 0 || !node.mcu.faults.is_empty() {
            failed = true;
        }
    }
    let total: u64 = nodes.iter().map(|n| n.mcu.cpu.instructions()).sum();
    println!(
        "{ms} ms simulated in {wall:.2} s ({:.2}x real time), {:.1} M instructions per simulated second; bus: {} frames, {:.1} % load",
        ms as f64 / 1000.0 / wall,
        total as f64 / (ms as f64 / 1000.0) / 1e6,
        bus.bus_stats().frames,
        bus.bus_stats().load * 100.0
    );
    if failed {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}
