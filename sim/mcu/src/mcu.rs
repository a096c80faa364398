//! The emulated STM32F446 as a whole: the core, the chip, and the loop that runs them in
//! simulated time, event to event: the core runs until the next peripheral event (a timer
//! match, a finished conversion, the watchdog, the end of a CAN frame); a sleeping core
//! skips straight to it.

use core::time::Duration;

use autoplug_flash::sim::{FlashError, SimFlash};

use crate::chip::can::CanFrame;
use crate::chip::rcc::ResetCause;
use crate::chip::Chip;
use crate::cpu::{Cpu, ExceptionReport, Exit, Halt};
use crate::debug::{DebugUnit, Debugger, Halted, WatchBus};
use crate::map::{BOOT_ALIAS, FLASH};

/// What reads the probe's other channels as a debugger halts the core ([`Mcu::on_debug_halt`]).
pub type OnDebugHalt = Box<dyn FnMut(&mut Mcu) + Send>;

/// Why an emulated MCU stopped.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Stop {
    /// The core halted (an unmodelled access, a lockup).
    Halted(Halt),
    /// The simulated flash refused an operation: the power was cut during it, or the
    /// firmware programmed a word that needed an erase first.
    Flash(FlashError),
    /// The program ended through semihosting (with a debugger attached), with this exit
    /// status: 0 for ADP_Stopped_ApplicationExit with status 0.
    Exited(u32),
    /// The firmware used something the emulated car cannot carry (an extended CAN frame
    /// on the AutoPlug bus, say).
    Unsupported(String),
    /// A breakpoint with a debugger attached, or a semihosting call the emulator does
    /// not offer.
    Breakpoint {
        /// The BKPT's immediate.
        imm: u8,
        /// Its address.
        pc: u32,
        /// What was asked, for a semihosting call.
        what: String,
    },
}

impl core::fmt::Display for Stop {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Stop::Halted(Halt::Unmodelled {
                what,
                address,
                pc,
                write,
            }) => {
                let access = if *write { "write to" } else { "read of" };
                write!(f, "{access} {what} (address {address:#010x}) by the instruction at {pc:#010x}: no model covers it")
            }
            Stop::Halted(Halt::Lockup { pc, reason }) => {
                write!(f, "the core locked up at {pc:#010x}: {reason}")
            }
            Stop::Halted(Halt::Breakpoint { imm, pc }) => {
                write!(f, "breakpoint (BKPT {imm:#04x}) at {pc:#010x}")
            }
            Stop::Flash(error) => write!(f, "the flash refused an operation: {error}"),
            Stop::Exited(status) => write!(f, "the program exited with status {status}"),
            Stop::Unsupported(what) => write!(f, "not supported: {what}"),
            Stop::Breakpoint { imm, pc, what } => {
                write!(f, "BKPT {imm:#04x} at {pc:#010x}: {what}")
            }
        }
    }
}

/// A CAN frame the MCU sent, with the simulated time its transmission ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Sent {
    /// Nanoseconds since power-on.
    pub at_ns: u64,
    /// The frame.
    pub frame: CanFrame,
}

/// One emulated MCU.
pub struct Mcu {
    /// The core.
    pub cpu: Cpu,
    /// Flash, SRAM and peripherals.
    pub chip: Chip,
    /// The frame on the wire and the cycle its transmission ends, on the standalone bus.
    pub(crate) on_wire: Option<(CanFrame, u64)>,
    /// Frames sent on the standalone bus (every frame is acknowledged by a listener).
    pub sent: Vec<Sent>,
    /// System resets so far, by cause.
    pub resets: Vec<(u64, ResetCause)>,
    /// The HardFaults taken, as they were reported.
    pub faults: Vec<ExceptionReport>,
    /// The lockups a running watchdog ended, with the time each began (ns since power-on).
    pub lockups: Vec<(u64, Halt)>,
    /// The core is locked up (a fault it could not take): it executes nothing until a
    /// reset, while the chip around it runs on.
    pub(crate) locked_up: bool,
    /// What the program wrote to the console through semihosting.
    pub semihosting_output: Vec<u8>,
    /// CAN1 on a bus of its own where every frame is acknowledged (true), or attached to
    /// the virtual car's bus ([`crate::node::BusNode`]).
    pub standalone_can: bool,
    /// The debugger attached to the MCU's debug port, if any ([`crate::debug`]).
    pub debugger: Option<Box<dyn Debugger>>,
    /// Called as the debugger halts the core, before it waits: what reads the probe's
    /// other channels then, as probe-rs does (the RTT log up to the halt, so the lines
    /// logged before a breakpoint show while it holds).
    pub on_debug_halt: Option<OnDebugHalt>,
    /// What a debugger set: breakpoints, watchpoints, how the core resumes.
    pub debug: DebugUnit,
    /// The execution history a reverse debugger records ([`crate::history`]).
    pub history: Option<Box<crate::history::History>>,
    /// A replay reached its position: the run in progress ends there.
    pub(crate) abort_run: bool,
}

impl Mcu {
    /// An MCU with this flash, powered on: the core starts from the vector table at the
    /// flash's base (BOOT0 low), as the chip does.
    pub fn power_on(flash: SimFlash, uid: [u32; 3]) -> Result<Self, Stop> {
        let mut mcu = Mcu {
            cpu: Cpu::new(FLASH),
            chip: Chip::new(flash, uid),
            on_wire: None,
            sent: Vec::new(),
            resets: Vec::new(),
            faults: Vec::new(),
            lockups: Vec::new(),
            locked_up: false,
            semihosting_output: Vec::new(),
            standalone_can: true,
            debugger: None,
            on_debug_halt: None,
            debug: DebugUnit::default(),
            history: None,
            abort_run: false,
        };
        mcu.cpu
            .reset(&mut mcu.chip, BOOT_ALIAS)
            .map_err(Stop::Halted)?;
        Ok(mcu)
    }

    /// Whether the core is locked up, waiting for the watchdog's reset.
    pub fn is_locked_up(&self) -> bool {
        self.locked_up
    }

    /// Simulated nanoseconds since power-on.
    pub fn now_ns(&self) -> u64 {
        self.chip.ns_at(self.cpu.cycles())
    }

    fn system_reset(&mut self, cause: ResetCause) -> Result<(), Stop> {
        let now = self.now_ns();
        self.resets.push((now, cause));
        self.chip.reset(cause, now);
        self.on_wire = None;
        self.locked_up = false;
        self.cpu
            .reset(&mut self.chip, BOOT_ALIAS)
            .map_err(Stop::Halted)
    }

    /// Runs until simulated time `until_ns` (nanoseconds since power-on).
    pub fn run_until(&mut self, until_ns: u64) -> Result<(), Stop> {
        if self.history.is_some() {
            self.record_run(until_ns);
        }
        loop {
            if self.debugger.as_ref().is_some_and(|d| d.wants_halt()) {
                self.debug_halt(Halted::Request);
            }
            let now = self.cpu.cycles();
            let now_ns = self.chip.ns_at(now);
            if now_ns >= until_ns {
                return Ok(());
            }
            self.chip.sync(now);
            if let Some(expiry) = self.chip.iwdg.expires() {
                if expiry <= now_ns {
                    self.system_reset(ResetCause::Watchdog)?;
                    continue;
                }
            }
            if self.standalone_can {
                self.standalone_can(now);
            }
            for irq in self.chip.irq_lines() {
                self.cpu.raise_irq(irq);
            }
            let deadline = self.chip.cycle_at(until_ns);
            let next = [
                self.chip.next_event(),
                self.on_wire.map(|(_, at)| at),
                Some(deadline),
            ]
            .into_iter()
            .flatten()
            .filter(|&at| at > now)
            .min()
            .unwrap_or(now + 1);
            if self.locked_up {
                // A locked-up core fetches nothing; time passes for the chip (the watchdog
                // counts down to the reset that ends the lockup).
                self.cpu.add_cycles(next - now);
                continue;
            }
            let exit = self.run_core(next);
            if std::mem::take(&mut self.abort_run) {
                return Ok(());
            }
            match exit {
                Exit::Budget => {}
                Exit::Sleeping => {
                    let now = self.cpu.cycles();
                    if next > now {
                        self.cpu.add_cycles(next - now);
                    }
                }
                Exit::Yield => self.after_yield()?,
                Exit::Halted(Halt::Breakpoint { imm: 0xAB, pc }) => self.semihosting(pc)?,
                // On the chip a lockup is not a reset: the core stays locked until one
                // comes. A running independent watchdog brings it (the bootloader starts
                // the IWDG before every start, so a trial image that locks up is reverted);
                // without one nothing ever will, and the run ends here with the report.
                Exit::Halted(halt @ Halt::Lockup { .. }) if self.chip.iwdg.expires().is_some() => {
                    self.lockups.push((self.now_ns(), halt));
                    self.locked_up = true;
                }
                Exit::Halted(halt) => return Err(Stop::Halted(halt)),
                // run_core serves the debugger's halts itself.
                Exit::Debug(_) => {}
            }
        }
    }

    /// Runs the core to cycle `next` or the first event that ends its run, serving the
    /// debugger's halts on the way: after one, the core goes on as if it had not stopped
    /// (the same run, to the same `next`), so a debugged run is the undebugged one.
    fn run_core(&mut self, next: u64) -> Exit {
        loop {
            let (exit, hit) = if self.debug.watchpoints.is_empty() {
                (self.cpu.run(&mut self.chip, next), None)
            } else {
                let mut bus = WatchBus {
                    chip: &mut self.chip,
                    watch: &self.debug.watchpoints,
                    hit: None,
                };
                let exit = self.cpu.run(&mut bus, next);
                (exit, bus.hit)
            };
            if let Some(report) = self.cpu.scs.last_fault.take() {
                if report.exception == crate::cpu::system::exception::HARD_FAULT {
                    self.faults.push(report);
                }
            }
            let reset = match (exit, hit) {
                (Exit::Debug(stop), _) => self.debug_halt(Halted::Core(stop)),
                (Exit::Yield, Some(hit)) => {
                    let reset = self.debug_halt(Halted::Watch(hit));
                    if self.chip.is_touched() {
                        // A peripheral access too: the loop handles it before going on.
                        return Exit::Yield;
                    }
                    reset
                }
                (Exit::Halted(Halt::Breakpoint { imm, pc }), _)
                    if imm != 0xAB && self.debugger.is_some() =>
                {
                    self.debug_halt(Halted::Bkpt { imm, pc })
                }
                // The debugger sees the lockup, as a probe does; unless it resets the
                // chip, the core stays locked (the loop's lockup handling).
                (Exit::Halted(halt @ Halt::Lockup { .. }), _) if self.debugger.is_some() => {
                    if !self.debug_halt(Halted::Lockup(halt.clone())) {
                        return Exit::Halted(halt);
                    }
                    true
                }
                (other, _) => return other,
            };
            // After a reset (`monitor reset`) the cycle count starts again: the loop
            // works out the next event anew.
            if reset || self.abort_run || self.cpu.cycles() >= next {
                return Exit::Budget;
            }
        }
    }

    /// Hands the halted MCU to its debugger until it resumes the core.
    fn debug_halt(&mut self, why: Halted) -> bool {
        let resets = self.resets.len();
        if let Some(mut debugger) = self.debugger.take() {
            if let Some(mut on_halt) = self.on_debug_halt.take() {
                on_halt(self);
                self.on_debug_halt.get_or_insert(on_halt);
            }
            debugger.halted(self, why);
            if self.debugger.is_none() {
                self.debugger = Some(debugger);
            }
        }
        self.resets.len() != resets
    }

    /// A system reset asked for by a debugger (`monitor reset`), as AIRCR.SYSRESETREQ
    /// through the debug port does it.
    pub fn debug_reset(&mut self) -> Result<(), Stop> {
        self.system_reset(ResetCause::Software)
    }

    fn debug_word(&mut self, address: u32) -> u32 {
        use crate::cpu::{Bus, Size};
        self.chip
            .read(address, Size::Word, self.cpu.cycles())
            .unwrap_or(0)
    }

    fn debug_bytes(&mut self, address: u32, len: u32) -> Vec<u8> {
        use crate::cpu::{Bus, Size};
        let now = self.cpu.cycles();
        (0..len.min(1 << 20))
            .map(|i| {
                self.chip
                    .read(address.wrapping_add(i), Size::Byte, now)
                    .unwrap_or(0) as u8
            })
            .collect()
    }

    /// A semihosting call (ARM's semihosting specification, version 2), served as a
    /// debugger serves it: console output and the program's exit. Files on the host are
    /// not offered.
    fn semihosting(&mut self, pc: u32) -> Result<(), Stop> {
        const APPLICATION_EXIT: u32 = 0x2_0026;
        let (op, arg) = (self.cpu.reg(0), self.cpu.reg(1));
        let result = match op {
            // SYS_OPEN: only the console, ":tt" (stdin, stdout, stderr by mode).
            0x01 => {
                let (name, mode, len) = (
                    self.debug_word(arg),
                    self.debug_word(arg + 4),
                    self.debug_word(arg + 8),
                );
                if self.debug_bytes(name, len) == b":tt" {
                    1 + mode / 4
                } else {
                    u32::MAX
                }
            }
            // SYS_CLOSE.
            0x02 => 0,
            // SYS_WRITEC.
            0x03 => {
                let byte = self.debug_bytes(arg, 1);
                self.semihosting_output.extend_from_slice(&byte);
                0
            }
            // SYS_WRITE0.
            0x04 => {
                let mut at = arg;
                loop {
                    let byte = self.debug_bytes(at, 1)[0];
                    if byte == 0 || at.wrapping_sub(arg) > 1 << 16 {
                        break;
                    }
                    self.semihosting_output.push(byte);
                    at = at.wrapping_add(1);
                }
                0
            }
            // SYS_WRITE: [handle, buffer, length]; returns the bytes not written.
            0x05 => {
                let (buffer, len) = (self.debug_word(arg + 4), self.debug_word(arg + 8));
                let bytes = self.debug_bytes(buffer, len);
                self.semihosting_output.extend_from_slice(&bytes);
                0
            }
            // SYS_EXIT: the reason in r1 (32-bit form).
            0x18 => return Err(Stop::Exited(if arg == APPLICATION_EXIT { 0 } else { 1 })),
            // SYS_EXIT_EXTENDED: [reason, subcode].
            0x20 => {
                let (reason, code) = (self.debug_word(arg), self.debug_word(arg + 4));
                return Err(Stop::Exited(if reason == APPLICATION_EXIT {
                    code
                } else {
                    1
                }));
            }
            _ => {
                return Err(Stop::Breakpoint {
                    imm: 0xAB,
                    pc,
                    what: format!("semihosting operation {op:#04x} is not offered"),
                })
            }
        };
        self.cpu.set_reg(0, result);
        self.cpu.step_over_breakpoint();
        Ok(())
    }

    /// Applies what a peripheral access left for the loop: the flash's stall and changed
    /// code, a flash failure, a reset request.
    fn after_yield(&mut self) -> Result<(), Stop> {
        self.chip.take_touched();
        let pending = std::mem::take(&mut self.chip.pending);
        if let Some(range) = pending.code_changed {
            self.cpu.invalidate_code(range.clone());
            self.cpu
                .invalidate_code(range.start - FLASH.start..range.end - FLASH.start);
        }
        if pending.stall > Duration::ZERO {
            let hz = self.chip.clocks().hclk as u128;
            let cycles = (pending.stall.as_nanos() * hz).div_ceil(1_000_000_000) as u64;
            self.cpu.add_cycles(cycles);
        }
        if let Some(error) = pending.flash_failed {
            return Err(Stop::Flash(error));
        }
        if std::mem::take(&mut self.cpu.scs.reset_requested) {
            self.system_reset(ResetCause::Software)?;
        }
        Ok(())
    }

    /// The standalone bus: a frame takes its bit time on the wire and is acknowledged.
    fn standalone_can(&mut self, now: u64) {
        if let Some((frame, at)) = self.on_wire {
            if at > now {
                return;
            }
            self.chip.can1.transmitted(true, false);
            self.sent.push(Sent {
                at_ns: self.chip.ns_at(at),
                frame,
            });
            self.on_wire = None;
        }
        if let Some(frame) = self.chip.can1.next_transmit() {
            let clocks = self.chip.clocks();
            let bit_rate = self.chip.can1.bit_rate(clocks.pclk1).max(1);
            // The exact bit count (stuffing included) for a classic base-format data frame,
            // as the virtual bus counts it; an extended or remote frame, which the AutoPlug
            // bus never carries, takes its unstuffed worst case (67 + 8n bits with IFS).
            let len = usize::from(frame.dlc.min(8));
            let bits = match autoplug_can::Frame::new(frame.id, &frame.data[..len]) {
                Ok(f) if !frame.extended && !frame.remote => {
                    u64::from(autoplug_virtual_bus::frame_bits(&f).total_with_ifs)
                }
                _ => 67 + 8 * len as u64 + (54 + 8 * len as u64) / 4,
            };
            let cycles = (bits * clocks.hclk).div_ceil(bit_rate);
            self.on_wire = Some((frame, now + cycles));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A program that (with `start_watchdog`) starts the IWDG and then executes UDF, whose
    /// HardFault handler is another UDF: the core locks up.
    fn locking_up(start_watchdog: bool) -> Mcu {
        const SP: u32 = 0x2002_0000;
        let code: [u16; 8] = [
            0xF243,
            0x0000, // MOVW r0, #0x3000
            0xF2C4,
            0x0000, // MOVT r0, #0x4000: IWDG_KR
            0xF64C,
            0x41CC,                                       // MOVW r1, #0xCCCC: start
            if start_watchdog { 0x6001 } else { 0xBF00 }, // STR r1, [r0] (or NOP)
            0xDE00, // UDF: a UsageFault, escalated to HardFault
        ];
        let undefined = FLASH.start + 0x40 + 14;
        let image =
            crate::programming::bare_program(&[SP, FLASH.start + 0x41, 0, undefined | 1], &code);
        let mut flash = SimFlash::new(1);
        flash.program(FLASH.start, &image).unwrap();
        Mcu::power_on(flash, [1, 2, 3]).unwrap()
    }

    #[test]
    fn a_running_watchdog_resets_a_locked_up_core() {
        let mut mcu = locking_up(true);
        mcu.run_until(1_200_000_000)
            .expect("the watchdog ends each lockup");
        // The IWDG's first period at its reset prescaler (/4): 0x1000 LSI counts of 4, 512 ms.
        let period_ns = 0x1000 * 4 * 1_000_000_000 / crate::chip::rcc::LSI_HZ;
        let watchdog_resets: Vec<u64> = mcu
            .resets
            .iter()
            .filter(|(_, cause)| *cause == ResetCause::Watchdog)
            .map(|(at, _)| *at)
            .collect();
        assert_eq!(watchdog_resets.len(), 2, "{:?}", mcu.resets);
        assert!(
            watchdog_resets[0].abs_diff(period_ns) < 1_000_000,
            "the first reset {} ns after power-on, the watchdog's period is {period_ns} ns",
            watchdog_resets[0]
        );
        // Locked up after power-on, after the first reset, and after the second.
        assert_eq!(mcu.lockups.len(), 3, "{:?}", mcu.lockups);
        assert!(mcu
            .lockups
            .iter()
            .all(|(_, halt)| matches!(halt, Halt::Lockup { .. })));
        assert!(mcu.is_locked_up());
    }

    #[test]
    fn without_a_watchdog_a_lockup_ends_the_run_with_its_report() {
        let mut mcu = locking_up(false);
        match mcu.run_until(100_000_000) {
            Err(Stop::Halted(Halt::Lockup { pc, .. })) => assert_eq!(pc, FLASH.start + 0x4E),
            other => panic!("{other:?}"),
        }
        assert!(mcu.resets.is_empty());
    }
}
