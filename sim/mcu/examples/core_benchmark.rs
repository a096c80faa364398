//! The emulator's speed, measured (a benchmark, not a test):
//!
//! 1. the core alone: a loop of integer, memory and floating-point work (a bitwise CRC-32
//!    over 4 KiB of SRAM, a 4 KiB word copy, a multiply-accumulate series) running from
//!    flash, in emulated instructions per second of this machine;
//! 2. the nine ECU firmwares booted through the bootloader and run one after the other
//!    for the same simulated time, in simulated seconds per second of this machine (all
//!    nine on one core: the ratio is how many times faster than real time the whole car's
//!    firmware runs, without received traffic).
//!
//! ```text
//! cargo run --release -p autoplug-mcu --example core_benchmark -- [FIRMWARE_DIR] [SIMULATED_SECONDS]
//! ```
//!
//! The loop, as LLVM's assembler built it (flash at 0x0800_0000, vector table first):
//!
//! ```text
//! 0040: b 0x40 <unexpected> @ imm = #-4
//! 0042: ldr r0, [pc, #132] @ 0xc8 <$d.2>
//! 0044: mov.w r1, #15728640
//! 0048: str r1, [r0]
//! 004a: dsb sy
//! 004e: isb sy
//! 0052: mov.w r0, #536870912
//! 0056: movw r1, #4096
//! 005a: movs r2, #0
//! 005c: strb r2, [r0, r2]
//! 005e: adds r2, #1
//! 0060: cmp r2, r1
//! 0062: bne 0x5c <fill> @ imm = #-10
//! 0064: mvn r3, #0
//! 0068: movs r2, #0
//! 006a: ldr.w r8, [pc, #96] @ 0xcc <$d.2+0x4>
//! 006e: ldrb r4, [r0, r2]
//! 0070: eors r3, r4
//! 0072: movs r5, #8
//! 0074: lsrs r6, r3, #1
//! 0076: and r7, r3, #1
//! 007a: rsbs r7, r7, #0
//! 007c: and.w r7, r7, r8
//! 0080: eor.w r3, r6, r7
//! 0084: subs r5, #1
//! 0086: bne 0x74 <bit> @ imm = #-22
//! 0088: adds r2, #1
//! 008a: cmp r2, r1
//! 008c: bne 0x6e <byte> @ imm = #-34
//! 008e: add.w r9, r0, #4096
//! 0092: movs r2, #0
//! 0094: ldr r4, [r0, r2]
//! 0096: str.w r4, [r9, r2]
//! 009a: adds r2, #4
//! 009c: cmp r2, r1
//! 009e: bne 0x94 <copy> @ imm = #-14
//! 00a0: vmov.f32 s0, #1.000000e+00
//! 00a4: vmov.f32 s1, #5.000000e-01
//! 00a8: vmov.f32 s2, #1.000000e+00
//! 00ac: movs r2, #0
//! 00ae: vmul.f32 s3, s2, s2
//! 00b2: vadd.f32 s0, s0, s3
//! 00b6: vmla.f32 s0, s1, s2
//! 00ba: vadd.f32 s2, s2, s1
//! 00be: adds r2, #1
//! 00c0: cmp r2, r1
//! 00c2: bne 0xae <float> @ imm = #-24
//! 00c4: b 0x64 <outer> @ imm = #-100
//! 00c6: movs r0, r0
//! 00c8: .word 0xe000ed88
//! 00cc: .word 0xedb88320
//! ```

use std::time::Instant;

use autoplug_flash::sim::SimFlash;
use autoplug_mcu::chip::Chip;
use autoplug_mcu::cpu::{Cpu, Exit};
use autoplug_mcu::map::{BOOT_ALIAS, FLASH, FLASH_BASE};
use autoplug_mcu::mcu::Mcu;
use autoplug_mcu::programming::FlashContents;

const LOOP: &[u8] = &[
    0x00, 0x00, 0x02, 0x20, 0x43, 0x00, 0x00, 0x08, 0x41, 0x00, 0x00, 0x08, 0x41, 0x00, 0x00, 0x08,
    0x41, 0x00, 0x00, 0x08, 0x41, 0x00, 0x00, 0x08, 0x41, 0x00, 0x00, 0x08, 0x41, 0x00, 0x00, 0x08,
    0x41, 0x00, 0x00, 0x08, 0x41, 0x00, 0x00, 0x08, 0x41, 0x00, 0x00, 0x08, 0x41, 0x00, 0x00, 0x08,
    0x41, 0x00, 0x00, 0x08, 0x41, 0x00, 0x00, 0x08, 0x41, 0x00, 0x00, 0x08, 0x41, 0x00, 0x00, 0x08,
    0xfe, 0xe7, 0x21, 0x48, 0x4f, 0xf4, 0x70, 0x01, 0x01, 0x60, 0xbf, 0xf3, 0x4f, 0x8f, 0xbf, 0xf3,
    0x6f, 0x8f, 0x4f, 0xf0, 0x00, 0x50, 0x41, 0xf2, 0x00, 0x01, 0x00, 0x22, 0x82, 0x54, 0x01, 0x32,
    0x8a, 0x42, 0xfb, 0xd1, 0x6f, 0xf0, 0x00, 0x03, 0x00, 0x22, 0xdf, 0xf8, 0x60, 0x80, 0x84, 0x5c,
    0x63, 0x40, 0x08, 0x25, 0x5e, 0x08, 0x03, 0xf0, 0x01, 0x07, 0x7f, 0x42, 0x07, 0xea, 0x08, 0x07,
    0x86, 0xea, 0x07, 0x03, 0x01, 0x3d, 0xf5, 0xd1, 0x01, 0x32, 0x8a, 0x42, 0xef, 0xd1, 0x00, 0xf5,
    0x80, 0x59, 0x00, 0x22, 0x84, 0x58, 0x49, 0xf8, 0x02, 0x40, 0x04, 0x32, 0x8a, 0x42, 0xf9, 0xd1,
    0xb7, 0xee, 0x00, 0x0a, 0xf6, 0xee, 0x00, 0x0a, 0xb7, 0xee, 0x00, 0x1a, 0x00, 0x22, 0x61, 0xee,
    0x01, 0x1a, 0x30, 0xee, 0x21, 0x0a, 0x00, 0xee, 0x81, 0x0a, 0x31, 0xee, 0x20, 0x1a, 0x01, 0x32,
    0x8a, 0x42, 0xf4, 0xd1, 0xce, 0xe7, 0x00, 0x00, 0x88, 0xed, 0x00, 0xe0, 0x20, 0x83, 0xb8, 0xed,
];

/// The ECUs' firmware names, from the catalogue's one list (`<name>-fw`).
fn ecus() -> impl Iterator<Item = &'static str> {
    autoplug_can::ECUS
        .iter()
        .map(|&node| autoplug_ecus::firmware_name(node))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let dir = args
        .first()
        .map_or("target/thumbv7em-none-eabihf/firmware", String::as_str);
    let seconds: u64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(10);

    // 1. The core alone.
    let mut flash = SimFlash::new(1);
    let mut image = LOOP.to_vec();
    image.resize(LOOP.len().next_multiple_of(4), 0xFF);
    flash
        .program(FLASH_BASE, &image)
        .expect("an erased flash takes the loop");
    let mut chip = Chip::new(flash, [0; 3]);
    let mut cpu = Cpu::new(FLASH);
    cpu.reset(&mut chip, BOOT_ALIAS)
        .expect("the loop's vector table reads");
    let started = Instant::now();
    let mut budget = 0u64;
    while started.elapsed().as_secs_f64() < 3.0 {
        budget += 50_000_000;
        match cpu.run(&mut chip, budget) {
            Exit::Budget | Exit::Yield => {}
            other => panic!("the benchmark loop stopped: {other:?}"),
        }
    }
    let wall = started.elapsed().as_secs_f64();
    println!(
        "core alone: {} instructions in {wall:.2} s: {:.1} M instructions/s",
        cpu.instructions(),
        cpu.instructions() as f64 / wall / 1e6
    );

    // 2. The nine firmwares.
    let mut total_instructions = 0;
    let mut total_wall = 0.0;
    for (n, ecu) in ecus().enumerate() {
        let mut contents = FlashContents::erased();
        for file in [format!("{dir}/boot"), format!("{dir}/{ecu}-fw")] {
            let bytes = match std::fs::read(&file) {
                Ok(bytes) => bytes,
                Err(e) => {
                    eprintln!(
                        "{file}: {e} (build them first: docs/src/firmware-without-a-board.md)"
                    );
                    std::process::exit(1);
                }
            };
            if let Err(e) = contents.program_elf(&file, &bytes) {
                eprintln!("{e}");
                std::process::exit(1);
            }
        }
        let mut mcu =
            Mcu::power_on(contents.to_sim_flash(n as u64), [n as u32, 0, 0]).expect("power-on");
        let started = Instant::now();
        if let Err(stop) = mcu.run_until(seconds * 1_000_000_000) {
            eprintln!("{ecu}: {stop}");
            std::process::exit(1);
        }
        let wall = started.elapsed().as_secs_f64();
        total_wall += wall;
        total_instructions += mcu.cpu.instructions();
        println!(
            "{ecu:>9}: {:.2} M instructions per simulated second, {:.0} M instructions/s, {:.1}x real time alone",
            mcu.cpu.instructions() as f64 / seconds as f64 / 1e6,
            mcu.cpu.instructions() as f64 / wall / 1e6,
            seconds as f64 / wall
        );
    }
    println!(
        "all nine: {:.1} M instructions per simulated second; {seconds} simulated seconds of all nine in {total_wall:.2} s: {:.2}x real time on one core",
        total_instructions as f64 / seconds as f64 / 1e6,
        seconds as f64 / total_wall
    );
}
