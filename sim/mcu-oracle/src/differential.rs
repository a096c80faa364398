//! Differential testing: the same generated block on the emulated core ([`emulate`]) and on
//! QEMU ([`super::Qemu::run`]), the results compared register by register, flag by flag
//! and byte by byte ([`compare`]).

use autoplug_mcu::cpu::{ArchState, Bus, BusError, Cpu, Size};

use super::{Block, Outcome, CODE_BASE, DATA_BASE, DATA_LEN};

/// QEMU's RAM as a block sees it: code from 0, the data window and the stack below it in
/// SRAM. Anything else has no memory (a BusFault), as on QEMU's machine for the addresses
/// the generator uses.
struct BlockMemory {
    code: Vec<u8>,
    sram: Vec<u8>,
}

const CODE_SIZE: u32 = 0x1_0000;
const SRAM_BASE: u32 = 0x2000_0000;
const SRAM_SIZE: u32 = 0x1_0000;

impl BlockMemory {
    fn slot(&mut self, address: u32, len: u32) -> Option<&mut [u8]> {
        let (memory, offset) = if address < CODE_SIZE {
            (&mut self.code, address)
        } else if address.wrapping_sub(SRAM_BASE) < SRAM_SIZE {
            (&mut self.sram, address - SRAM_BASE)
        } else {
            return None;
        };
        memory.get_mut(offset as usize..(offset + len) as usize)
    }
}

impl Bus for BlockMemory {
    fn read(&mut self, address: u32, size: Size, _now: u64) -> Result<u32, BusError> {
        let bytes = self.slot(address, size as u32).ok_or(BusError::Fault)?;
        let mut word = [0u8; 4];
        word[..bytes.len()].copy_from_slice(bytes);
        Ok(u32::from_le_bytes(word))
    }

    fn write(&mut self, address: u32, size: Size, value: u32, _now: u64) -> Result<(), BusError> {
        let bytes = self.slot(address, size as u32).ok_or(BusError::Fault)?;
        let len = bytes.len();
        bytes.copy_from_slice(&value.to_le_bytes()[..len]);
        Ok(())
    }
}

/// Where the emulated vector table sends every exception (`b .`).
const FAULT_STUB: u32 = 0x0000_0100;

/// Runs `block` on the emulated core as QEMU runs it: Thread mode, privileged, the FPU
/// enabled with an active FP context (so FPSCR is the block's own, not FPDSCR's), the
/// exclusive monitor open.
pub fn emulate(block: &Block) -> Outcome {
    let mut memory = BlockMemory {
        code: vec![0; CODE_SIZE as usize],
        sram: vec![0; SRAM_SIZE as usize],
    };
    // Vector table at 0: every handler at the fault stub, a `b .`.
    for exception in 1..16u32 {
        let at = 4 * exception as usize;
        memory.code[at..at + 4].copy_from_slice(&(FAULT_STUB | 1).to_le_bytes());
    }
    memory.code[FAULT_STUB as usize..FAULT_STUB as usize + 2]
        .copy_from_slice(&0xE7FEu16.to_le_bytes());
    let code_at = CODE_BASE as usize;
    memory.code[code_at..code_at + block.code.len()].copy_from_slice(&block.code);
    let data_at = (DATA_BASE - SRAM_BASE) as usize;
    memory.sram[data_at..data_at + block.data.len()].copy_from_slice(&block.data);

    // No decoded-instruction cache: blocks may load their own code as literals, and each
    // block is new code at the same address.
    let mut cpu = Cpu::new(0..0);
    // The reset vector: SP and PC are the block's anyway.
    memory.code[..4].copy_from_slice(&(DATA_BASE + DATA_LEN).to_le_bytes());
    memory.code[4..8].copy_from_slice(&(CODE_BASE | 1).to_le_bytes());
    if cpu.reset(&mut memory, 0).is_err() {
        return Outcome::Fault {
            pc: CODE_BASE,
            exception: 0,
            cfsr: 0,
            hfsr: 0,
            mmfar: 0,
            bfar: 0,
        };
    }
    cpu.scs.cpacr = 0x00F0_0000;
    cpu.set_control(0b100);
    // SHCSR: MemManage, BusFault and UsageFault enabled, as QEMU's setup routine leaves
    // them, so a fault is reported as itself rather than as a HardFault.
    if cpu
        .debug_write(&mut memory, 0xE000_ED24, 0x0007_0000)
        .is_err()
    {
        return Outcome::Fault {
            pc: CODE_BASE,
            exception: 0,
            cfsr: 0,
            hfsr: 0,
            mmfar: 0,
            bfar: 0,
        };
    }
    cpu.set_arch_state(&block.start);

    let end = block.end();
    // A block runs straight through, with forward branches only: never more steps than
    // halfwords.
    let limit = block.code.len() + 16;
    for _ in 0..limit {
        if cpu.pc() == end {
            let mut data = vec![0; DATA_LEN as usize];
            data.copy_from_slice(&memory.sram[data_at..data_at + DATA_LEN as usize]);
            return Outcome::Finished {
                state: cpu.arch_state(),
                data,
            };
        }
        let before = cpu.scs.last_fault.is_some();
        if let Err(halt) = cpu.step_one(&mut memory) {
            return Outcome::Fault {
                pc: cpu.pc(),
                exception: 0xFFFF,
                cfsr: 0,
                hfsr: 0,
                mmfar: 0,
                bfar: halt_code(&halt),
            };
        }
        if !before {
            if let Some(report) = &cpu.scs.last_fault {
                return Outcome::Fault {
                    pc: report.pc,
                    exception: report.exception as u32,
                    cfsr: report.cfsr,
                    hfsr: report.hfsr,
                    mmfar: 0,
                    bfar: report.bfar,
                };
            }
        }
    }
    Outcome::Fault {
        pc: cpu.pc(),
        exception: 0xFFFE,
        cfsr: 0,
        hfsr: 0,
        mmfar: 0,
        bfar: 0,
    }
}

fn halt_code(halt: &autoplug_mcu::cpu::Halt) -> u32 {
    match halt {
        autoplug_mcu::cpu::Halt::Unmodelled { address, .. } => *address,
        _ => 0,
    }
}

/// The differences between the emulator's outcome and QEMU's for `block`, or `Ok`.
pub fn compare(block: &Block, ours: &Outcome, theirs: &Outcome) -> Result<(), String> {
    let mut differences = Vec::new();
    match (ours, theirs) {
        (Outcome::Finished { state: a, data: da }, Outcome::Finished { state: b, data: db }) => {
            compare_states(a, b, &mut differences);
            for (i, (x, y)) in da.iter().zip(db).enumerate() {
                if x != y {
                    differences.push(format!(
                        "data[{:#010x}]: emulator {x:#04x}, QEMU {y:#04x}",
                        DATA_BASE + i as u32
                    ));
                }
            }
        }
        (
            Outcome::Fault {
                pc: pa,
                exception: ea,
                ..
            },
            Outcome::Fault {
                pc: pb,
                exception: eb,
                ..
            },
        ) => {
            if (pa, ea) != (pb, eb) {
                differences.push(format!("emulator faulted at {pa:#x} (exception {ea}), QEMU at {pb:#x} (exception {eb})"));
            }
        }
        (a, b) => differences.push(format!("emulator: {}; QEMU: {}", summary(a), summary(b))),
    }
    if differences.is_empty() {
        Ok(())
    } else {
        Err(format!(
            "{}\n{}",
            differences.join("\n"),
            block.disassembly()
        ))
    }
}

fn summary(outcome: &Outcome) -> String {
    match outcome {
        Outcome::Finished { .. } => "ran to the end".into(),
        Outcome::Fault {
            pc,
            exception,
            cfsr,
            ..
        } => format!("fault at {pc:#x} (exception {exception}, CFSR {cfsr:#x})"),
    }
}

fn compare_states(a: &ArchState, b: &ArchState, differences: &mut Vec<String>) {
    for i in 0..16 {
        if a.r[i] != b.r[i] {
            differences.push(format!(
                "r{i}: emulator {:#010x}, QEMU {:#010x}",
                a.r[i], b.r[i]
            ));
        }
    }
    if a.xpsr != b.xpsr {
        differences.push(format!(
            "xPSR: emulator {:#010x}, QEMU {:#010x}",
            a.xpsr, b.xpsr
        ));
    }
    for i in 0..32 {
        if a.s[i] != b.s[i] {
            differences.push(format!(
                "s{i}: emulator {:#010x} ({}), QEMU {:#010x} ({})",
                a.s[i],
                f32::from_bits(a.s[i]),
                b.s[i],
                f32::from_bits(b.s[i])
            ));
        }
    }
    if a.fpscr != b.fpscr {
        differences.push(format!(
            "FPSCR: emulator {:#010x}, QEMU {:#010x}",
            a.fpscr, b.fpscr
        ));
    }
}
