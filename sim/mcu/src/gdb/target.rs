//! The emulated MCU as a GDB target: registers, memory, breakpoints, watchpoints, steps,
//! `monitor` commands, the memory map and flash programming (`load`).

use gdbstub::common::Signal;
use gdbstub::target::ext::base::reverse_exec::{
    ReverseCont, ReverseContOps, ReverseStep, ReverseStepOps,
};
use gdbstub::target::ext::base::singlethread::{
    SingleThreadBase, SingleThreadRangeStepping, SingleThreadRangeSteppingOps, SingleThreadResume,
    SingleThreadResumeOps, SingleThreadSingleStep, SingleThreadSingleStepOps,
};
use gdbstub::target::ext::base::BaseOps;
use gdbstub::target::ext::breakpoints::{
    Breakpoints, BreakpointsOps, HwBreakpoint, HwBreakpointOps, HwWatchpoint, HwWatchpointOps,
    SwBreakpoint, SwBreakpointOps, WatchKind as GdbWatchKind,
};
use gdbstub::target::ext::flash::{Flash, FlashOps};
use gdbstub::target::ext::memory_map::{MemoryMap, MemoryMapOps};
use gdbstub::target::ext::monitor_cmd::{outputln, ConsoleOutput, MonitorCmd, MonitorCmdOps};
use gdbstub::target::{Target, TargetError, TargetResult};

use super::arch::{CortexM4f, CortexM4fRegisters, MEMORY_MAP_XML, SPECIAL_SYSM};
use crate::cpu::{ArchState, Size};
use crate::debug::{Resume, WatchKind, Watchpoint, HW_BREAKPOINTS, WATCHPOINTS};
use crate::map::{FLASH, PRIVATE_PERIPHERALS};
use crate::mcu::Mcu;

/// The error a write gets while the debugger looks at the past (EROFS: the past cannot
/// be changed).
const PAST: u8 = 30;

/// A debugger's software breakpoints are matched by address: a bound keeps a hostile
/// client from growing the list without end.
pub const SW_BREAKPOINTS: usize = 256;

/// The largest range one DWT comparator covers (DWT_MASK up to 15: 32 KiB).
const WATCH_MAX: u32 = 1 << 15;

impl Target for Mcu {
    type Arch = CortexM4f;
    type Error = &'static str;

    fn base_ops(&mut self) -> BaseOps<'_, Self::Arch, Self::Error> {
        BaseOps::SingleThread(self)
    }

    fn support_breakpoints(&mut self) -> Option<BreakpointsOps<'_, Self>> {
        Some(self)
    }

    fn support_monitor_cmd(&mut self) -> Option<MonitorCmdOps<'_, Self>> {
        Some(self)
    }

    fn support_memory_map(&mut self) -> Option<MemoryMapOps<'_, Self>> {
        Some(self)
    }

    fn support_flash_operations(&mut self) -> Option<FlashOps<'_, Self>> {
        Some(self)
    }

    // GDB inserts a software breakpoint by writing to memory unless the stub says it
    // handles them: it does (by address, without patching the image).
    fn guard_rail_implicit_sw_breakpoints(&self) -> bool {
        true
    }
}

impl Mcu {
    /// Reads memory as a debugger does: flash, SRAM, the system memory and the modelled
    /// peripherals without side effects, the private peripheral bus through the core. The
    /// bytes read before the first address nothing answers at.
    pub fn debug_read(&mut self, start: u32, data: &mut [u8]) -> usize {
        let now = self.cpu.cycles();
        let mut done = 0;
        while done < data.len() {
            let address = start.wrapping_add(done as u32);
            let left = data.len() - done;
            let size = if address & 3 == 0 && left >= 4 {
                Size::Word
            } else {
                Size::Byte
            };
            let value = if PRIVATE_PERIPHERALS.contains(&address) {
                self.cpu.debug_read_private(address, size)
            } else {
                self.chip.peek(address, size, now).ok()
            };
            let Some(value) = value else {
                break;
            };
            let n = size as usize;
            data[done..done + n].copy_from_slice(&value.to_le_bytes()[..n]);
            done += n;
        }
        done
    }

    /// Writes memory as a debugger does: SRAM, the peripherals (with the effects a write
    /// has) and the private peripheral bus; not the flash (GDB's `load` programs it). On
    /// refusal, the address refused.
    pub fn debug_write_bytes(&mut self, start: u32, data: &[u8]) -> Result<(), u32> {
        use crate::cpu::Bus;
        let now = self.cpu.cycles();
        for (i, &byte) in data.iter().enumerate() {
            let address = start.wrapping_add(i as u32);
            if FLASH.contains(&address) || address < FLASH.end - FLASH.start {
                return Err(address);
            }
            if PRIVATE_PERIPHERALS.contains(&address) {
                // The core's registers are word-wide: read, merge, write back.
                let word = address & !3;
                let old = self
                    .cpu
                    .debug_read_private(word, Size::Word)
                    .ok_or(address)?;
                let shift = 8 * (address & 3);
                let value = (old & !(0xFF << shift)) | u32::from(byte) << shift;
                self.cpu
                    .debug_write(&mut self.chip, word, value)
                    .map_err(|_| address)?;
            } else {
                self.chip
                    .write(address, Size::Byte, u32::from(byte), now)
                    .map_err(|_| address)?;
            }
        }
        Ok(())
    }

    fn registers(&self) -> CortexM4fRegisters {
        let state = self.cpu.arch_state();
        CortexM4fRegisters {
            r: state.r,
            xpsr: state.xpsr,
            s: state.s,
            fpscr: state.fpscr,
            special: SPECIAL_SYSM.map(|sysm| self.cpu.special_register(sysm)),
        }
    }
}

impl SingleThreadBase for Mcu {
    fn read_registers(&mut self, regs: &mut CortexM4fRegisters) -> TargetResult<(), Self> {
        *regs = self.registers();
        Ok(())
    }

    fn write_registers(&mut self, regs: &CortexM4fRegisters) -> TargetResult<(), Self> {
        if self.in_past() {
            return Err(TargetError::Errno(PAST));
        }
        self.cpu.set_arch_state(&ArchState {
            r: regs.r,
            xpsr: regs.xpsr,
            s: regs.s,
            fpscr: regs.fpscr,
        });
        for (sysm, value) in SPECIAL_SYSM.iter().zip(regs.special) {
            // MSP and PSP after CONTROL's SPSEL: the order the core banks them in.
            if *sysm == 20 {
                self.cpu.set_special_register(*sysm, value);
            }
        }
        for (sysm, value) in SPECIAL_SYSM.iter().zip(regs.special) {
            if *sysm != 20 {
                self.cpu.set_special_register(*sysm, value);
            }
        }
        // The current SP is r13 in the `g` packet too: it wins over the banked copy.
        self.cpu.set_reg(13, regs.r[13]);
        self.debug.changed_by_debugger = true;
        Ok(())
    }

    fn read_addrs(&mut self, start: u32, data: &mut [u8]) -> TargetResult<usize, Self> {
        match self.debug_read(start, data) {
            0 if !data.is_empty() => Err(TargetError::Errno(14)), // EFAULT
            n => Ok(n),
        }
    }

    fn write_addrs(&mut self, start: u32, data: &[u8]) -> TargetResult<(), Self> {
        if self.in_past() {
            return Err(TargetError::Errno(PAST));
        }
        self.debug.changed_by_debugger = true;
        self.debug_write_bytes(start, data)
            .map_err(|_| TargetError::Errno(14))
    }

    fn support_resume(&mut self) -> Option<SingleThreadResumeOps<'_, Self>> {
        Some(self)
    }
}

impl SingleThreadResume for Mcu {
    fn resume(&mut self, _signal: Option<Signal>) -> Result<(), Self::Error> {
        self.debug.resume = Resume::Continue;
        Ok(())
    }

    fn support_single_step(&mut self) -> Option<SingleThreadSingleStepOps<'_, Self>> {
        Some(self)
    }

    fn support_range_step(&mut self) -> Option<SingleThreadRangeSteppingOps<'_, Self>> {
        Some(self)
    }

    fn support_reverse_step(&mut self) -> Option<ReverseStepOps<'_, (), Self>> {
        Some(self)
    }

    fn support_reverse_cont(&mut self) -> Option<ReverseContOps<'_, (), Self>> {
        Some(self)
    }
}

impl ReverseStep<()> for Mcu {
    fn reverse_step(&mut self, _tid: ()) -> Result<(), Self::Error> {
        self.debug.resume = Resume::ReverseStep;
        Ok(())
    }
}

impl ReverseCont<()> for Mcu {
    fn reverse_cont(&mut self) -> Result<(), Self::Error> {
        self.debug.resume = Resume::ReverseContinue;
        Ok(())
    }
}

impl SingleThreadSingleStep for Mcu {
    fn step(&mut self, _signal: Option<Signal>) -> Result<(), Self::Error> {
        self.debug.resume = Resume::Step;
        Ok(())
    }
}

impl SingleThreadRangeStepping for Mcu {
    fn resume_range_step(&mut self, start: u32, end: u32) -> Result<(), Self::Error> {
        self.debug.resume = Resume::StepRange(start..end);
        Ok(())
    }
}

impl Breakpoints for Mcu {
    fn support_sw_breakpoint(&mut self) -> Option<SwBreakpointOps<'_, Self>> {
        Some(self)
    }

    fn support_hw_breakpoint(&mut self) -> Option<HwBreakpointOps<'_, Self>> {
        Some(self)
    }

    fn support_hw_watchpoint(&mut self) -> Option<HwWatchpointOps<'_, Self>> {
        Some(self)
    }
}

impl SwBreakpoint for Mcu {
    fn add_sw_breakpoint(&mut self, addr: u32, _kind: usize) -> TargetResult<bool, Self> {
        // As on the chip: a software breakpoint is a BKPT written over the instruction,
        // which the flash cannot take from a debugger (GDB uses the FPB there).
        if FLASH.contains(&addr) || addr < FLASH.end - FLASH.start {
            return Ok(false);
        }
        let list = &mut self.debug.sw_breakpoints;
        if !list.contains(&addr) {
            if list.len() >= SW_BREAKPOINTS {
                return Ok(false);
            }
            list.push(addr);
        }
        Ok(true)
    }

    fn remove_sw_breakpoint(&mut self, addr: u32, _kind: usize) -> TargetResult<bool, Self> {
        let list = &mut self.debug.sw_breakpoints;
        let before = list.len();
        list.retain(|&a| a != addr);
        Ok(list.len() != before)
    }
}

impl HwBreakpoint for Mcu {
    fn add_hw_breakpoint(&mut self, addr: u32, _kind: usize) -> TargetResult<bool, Self> {
        let list = &mut self.debug.hw_breakpoints;
        if list.len() >= HW_BREAKPOINTS {
            return Ok(false);
        }
        list.push(addr);
        Ok(true)
    }

    fn remove_hw_breakpoint(&mut self, addr: u32, _kind: usize) -> TargetResult<bool, Self> {
        let list = &mut self.debug.hw_breakpoints;
        match list.iter().position(|&a| a == addr) {
            Some(i) => {
                list.remove(i);
                Ok(true)
            }
            None => Ok(false),
        }
    }
}

fn watch_kind(kind: GdbWatchKind) -> WatchKind {
    match kind {
        GdbWatchKind::Write => WatchKind::Write,
        GdbWatchKind::Read => WatchKind::Read,
        GdbWatchKind::ReadWrite => WatchKind::Access,
    }
}

impl HwWatchpoint for Mcu {
    fn add_hw_watchpoint(
        &mut self,
        addr: u32,
        len: u32,
        kind: GdbWatchKind,
    ) -> TargetResult<bool, Self> {
        // A DWT comparator matches an address under a mask: a power-of-two range,
        // aligned to its size, up to 32 KiB.
        let coverable = len.is_power_of_two() && len <= WATCH_MAX && addr % len == 0;
        if !coverable || self.debug.watchpoints.len() >= WATCHPOINTS {
            return Ok(false);
        }
        self.debug.watchpoints.push(Watchpoint {
            address: addr,
            len,
            kind: watch_kind(kind),
        });
        Ok(true)
    }

    fn remove_hw_watchpoint(
        &mut self,
        addr: u32,
        len: u32,
        kind: GdbWatchKind,
    ) -> TargetResult<bool, Self> {
        let wanted = Watchpoint {
            address: addr,
            len,
            kind: watch_kind(kind),
        };
        let list = &mut self.debug.watchpoints;
        match list.iter().position(|w| *w == wanted) {
            Some(i) => {
                list.remove(i);
                Ok(true)
            }
            None => Ok(false),
        }
    }
}

impl MemoryMap for Mcu {
    fn memory_map_xml(
        &self,
        offset: u64,
        length: usize,
        buf: &mut [u8],
    ) -> TargetResult<usize, Self> {
        let xml = MEMORY_MAP_XML.as_bytes();
        let start = (offset as usize).min(xml.len());
        let end = start
            .saturating_add(length)
            .min(xml.len())
            .min(start + buf.len());
        buf[..end - start].copy_from_slice(&xml[start..end]);
        Ok(end - start)
    }
}

impl Flash for Mcu {
    fn flash_erase(&mut self, start: u32, length: u32) -> TargetResult<(), Self> {
        if self.in_past() {
            return Err(TargetError::Errno(PAST));
        }
        self.debug.changed_by_debugger = true;
        let end = start.checked_add(length).ok_or(TargetError::Errno(22))?;
        self.chip
            .flash
            .erase(start, end)
            .map_err(|_| TargetError::Errno(5))
    }

    fn flash_write(&mut self, start: u32, data: &[u8]) -> TargetResult<(), Self> {
        if self.in_past() {
            return Err(TargetError::Errno(PAST));
        }
        self.debug.changed_by_debugger = true;
        // Whole words, as the flash is programmed: the bytes around the data are
        // programmed with what they hold, which changes nothing.
        let aligned = start & !3;
        let end = start
            .checked_add(data.len() as u32)
            .ok_or(TargetError::Errno(22))?;
        let aligned_end = end
            .checked_next_multiple_of(4)
            .ok_or(TargetError::Errno(22))?;
        let mut words = vec![0xFF; (aligned_end - aligned) as usize];
        self.chip
            .flash
            .read(aligned, &mut words)
            .map_err(|_| TargetError::Errno(5))?;
        words[(start - aligned) as usize..(end - aligned) as usize].copy_from_slice(data);
        self.chip
            .flash
            .program(aligned, &words)
            .map_err(|_| TargetError::Errno(5))
    }

    fn flash_done(&mut self) -> TargetResult<(), Self> {
        self.cpu.invalidate_code(FLASH);
        self.cpu.invalidate_code(0..FLASH.end - FLASH.start);
        Ok(())
    }
}

impl MonitorCmd for Mcu {
    fn handle_monitor_cmd(
        &mut self,
        cmd: &[u8],
        mut out: ConsoleOutput<'_>,
    ) -> Result<(), Self::Error> {
        let cmd = String::from_utf8_lossy(cmd);
        match cmd.split_whitespace().collect::<Vec<_>>().as_slice() {
            ["reset"] | ["reset", "halt"] | ["reset", "init"] if self.in_past() => {
                outputln!(out, "reset: the debugger looks at the past; continue to the present (or detach) first");
            }
            ["reset"] | ["reset", "halt"] | ["reset", "init"] => {
                // The core stays halted at its reset vector either way: GDB would not know
                // of a core that ran on.
                self.debug.changed_by_debugger = true;
                match self.debug_reset() {
                    Ok(()) => outputln!(
                        out,
                        "reset: the MCU is halted at its reset vector (pc {:#010x}); continue runs it",
                        self.cpu.pc()
                    ),
                    Err(e) => outputln!(out, "reset failed: {e}"),
                }
            }
            // What a client asks of a probe's server before it looks (Cortex-Debug's
            // attach): the core is halted whenever a monitor command comes.
            ["halt"] => outputln!(out, "halt: the MCU is halted (pc {:#010x})", self.cpu.pc()),
            ["fault"] | ["faults"] => self.fault_report(&mut out),
            ["history"] => match &self.history {
                Some(h) => outputln!(
                    out,
                    "history: {:.1} s of simulated time, {} KiB ({}); {}",
                    h.span_ns() as f64 * 1e-9,
                    h.bytes() / 1024,
                    "snapshots and the journal of inputs",
                    if h.in_past() {
                        "looking at the past"
                    } else {
                        "at the present"
                    }
                ),
                None => outputln!(out, "history: none recorded"),
            },
            ["help"] | [] => {
                outputln!(out, "monitor reset [halt]  a system reset; the MCU stays halted at its reset vector");
                outputln!(
                    out,
                    "monitor fault         the fault status registers and the last HardFault"
                );
                outputln!(
                    out,
                    "monitor history       how far back reverse execution reaches, and its memory"
                );
                outputln!(
                    out,
                    "monitor halt          nothing to do: the MCU is halted while GDB talks to it"
                );
            }
            _ => outputln!(
                out,
                "unknown monitor command '{cmd}' (monitor help lists them)"
            ),
        }
        Ok(())
    }
}

impl Mcu {
    fn fault_report(&mut self, out: &mut ConsoleOutput<'_>) {
        let mut word = |address: u32| {
            self.cpu
                .debug_read_private(address, Size::Word)
                .unwrap_or(0)
        };
        let (cfsr, hfsr, mmfar, bfar) = (
            word(0xE000_ED28),
            word(0xE000_ED2C),
            word(0xE000_ED34),
            word(0xE000_ED38),
        );
        outputln!(
            out,
            "CFSR  {cfsr:#010x}  (UFSR {:#06x}, BFSR {:#04x}, MMFSR {:#04x})",
            cfsr >> 16,
            (cfsr >> 8) & 0xFF,
            cfsr & 0xFF
        );
        outputln!(
            out,
            "HFSR  {hfsr:#010x}{}",
            if hfsr & (1 << 30) != 0 {
                "  (FORCED: a fault escalated)"
            } else {
                ""
            }
        );
        outputln!(out, "MMFAR {mmfar:#010x}  BFAR {bfar:#010x}");
        match self.faults.last() {
            Some(f) => outputln!(
                out,
                "last HardFault: {:?} at pc {:#010x}, lr {:#010x}",
                f.fault,
                f.pc,
                f.lr
            ),
            None => outputln!(out, "no HardFault taken since power-on"),
        }
    }
}
