//! Programs the emulated STM32F446's flash with ELF files in order, as a programmer would
//! write them to a Nucleo-F446RE, and checks that each file's vector table (at the first
//! address it writes) can start a Cortex-M core.
//!
//! ```text
//! cargo run -p autoplug-mcu --example program -- \
//!     target/thumbv7em-none-eabihf/firmware/boot target/thumbv7em-none-eabihf/firmware/cruise-fw
//! ```

use std::process::ExitCode;

use autoplug_mcu::programming::FlashContents;

fn main() -> ExitCode {
    let files: Vec<String> = std::env::args().skip(1).collect();
    if files.is_empty() {
        eprintln!("usage: program ELF [ELF ...]  (the bootloader first, then an application)");
        return ExitCode::from(2);
    }
    let mut flash = FlashContents::erased();
    for file in &files {
        let bytes = match std::fs::read(file) {
            Ok(bytes) => bytes,
            Err(e) => {
                eprintln!("{file}: {e}");
                return ExitCode::FAILURE;
            }
        };
        let written = match flash.program_elf(file, &bytes) {
            Ok(written) => written.clone(),
            Err(e) => {
                eprintln!("{e}");
                return ExitCode::FAILURE;
            }
        };
        match flash.vector_table(written.start) {
            Ok((sp, reset)) => println!(
                "{file}: 0x{:08X}..0x{:08X} ({} bytes), initial stack pointer 0x{sp:08X}, reset vector 0x{reset:08X}",
                written.start,
                written.end,
                written.end - written.start
            ),
            Err(e) => {
                eprintln!("{file}: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    ExitCode::SUCCESS
}
