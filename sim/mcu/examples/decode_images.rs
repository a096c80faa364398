//! Decodes every instruction of the given firmware ELF files with the emulated core's
//! decoder, and fails if any is undefined or UNPREDICTABLE where the image does not mean
//! it (a `udf` is the images' deliberate trap). Code and data in `.text` are told apart by
//! the ELF's mapping symbols (`$t` code, `$d` literal pools), as disassemblers do.
//!
//! ```text
//! cargo run --release -p autoplug-mcu --example decode_images -- target/thumbv7em-none-eabihf/firmware/{boot,*-fw}
//! ```

use std::process::ExitCode;

use autoplug_mcu::cpu::decode::{decode, is_wide};
use autoplug_mcu::cpu::op::Op;
use object::{Object, ObjectSection, ObjectSymbol, SectionKind};

fn main() -> ExitCode {
    let files: Vec<String> = std::env::args().skip(1).collect();
    if files.is_empty() {
        eprintln!("usage: decode_images ELF [ELF ...]");
        return ExitCode::from(2);
    }
    let mut failed = false;
    for file in &files {
        match check(file) {
            Ok((count, traps)) => {
                println!("{file}: {count} instructions decode ({traps} deliberate udf traps)")
            }
            Err(e) => {
                println!("{file}: {e}");
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

fn check(file: &str) -> Result<(usize, usize), String> {
    let bytes = std::fs::read(file).map_err(|e| e.to_string())?;
    let elf = object::File::parse(&*bytes).map_err(|e| format!("not an ELF file: {e}"))?;
    // Mapping symbols: where Thumb code ($t) and data ($d) start.
    let mut marks: Vec<(u64, bool)> = elf
        .symbols()
        .filter_map(|s| match s.name() {
            Ok(name) if name == "$t" || name.starts_with("$t.") => Some((s.address(), true)),
            Ok(name) if name == "$d" || name.starts_with("$d.") => Some((s.address(), false)),
            _ => None,
        })
        .collect();
    marks.sort();
    let mut count = 0;
    let mut traps = 0;
    let mut problems = Vec::new();
    for section in elf.sections().filter(|s| s.kind() == SectionKind::Text) {
        let data = section.data().map_err(|e| e.to_string())?;
        let base = section.address();
        let mut at = 0usize;
        while at + 2 <= data.len() {
            let address = base + at as u64;
            let is_code = marks
                .iter()
                .rev()
                .find(|(a, _)| *a <= address)
                .is_none_or(|(_, code)| *code);
            if !is_code {
                at += 2;
                continue;
            }
            let hw1 = u16::from_le_bytes([data[at], data[at + 1]]);
            let wide = is_wide(hw1);
            if wide && at + 4 > data.len() {
                break;
            }
            let hw2 = if wide {
                u16::from_le_bytes([data[at + 2], data[at + 3]])
            } else {
                0
            };
            let (op, len) = decode(hw1, hw2, address as u32);
            count += 1;
            match op {
                // UDF T1 (0xDExx) and T2 (0xF7Fx 0xAxxx): the trap the images mean.
                Op::Undefined
                    if hw1 >> 8 == 0xDE || (hw1 & 0xFFF0 == 0xF7F0 && hw2 & 0xF000 == 0xA000) =>
                {
                    traps += 1
                }
                Op::Undefined | Op::Unpredictable | Op::NoCoprocessor => {
                    problems.push(format!(
                        "{address:#010x}: {hw1:04x} {hw2:04x} decodes as {op:?}"
                    ));
                }
                _ => {}
            }
            at += len as usize;
        }
    }
    if problems.is_empty() {
        Ok((count, traps))
    } else {
        Err(format!(
            "{} instructions do not decode:\n  {}",
            problems.len(),
            problems.join("\n  ")
        ))
    }
}
