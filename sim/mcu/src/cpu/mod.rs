//! The Cortex-M4F core: ARMv7E-M Thumb-2 with the DSP extension and FPv4-SP, the ARMv7-M
//! exception model, and the core's private peripherals (NVIC, SCB, SysTick, DWT, the FPU's
//! control registers).
//!
//! The core reaches memory and the chip's peripherals through a [`Bus`]; everything on the
//! private peripheral bus (0xE000_0000–0xE00F_FFFF) it models itself ([`system`]).
//! Instructions are decoded once per address into [`op::Op`] and cached for the address
//! range the caller names as code (the flash), so a firmware's loop runs from the cache.

pub mod alu;
pub mod decode;
mod exec;
pub mod fp;
pub mod op;
mod state;
pub mod system;

pub use state::ArchState;
pub use system::{ExceptionReport, Scs};

use op::Op;

/// How many bytes an access moves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Size {
    /// One byte.
    Byte = 1,
    /// Two bytes.
    Half = 2,
    /// Four bytes.
    Word = 4,
}

/// Why the bus refused an access.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BusError {
    /// Nothing answers at the address: the core takes a BusFault, as the chip does.
    Fault,
    /// The address belongs to a peripheral register the emulator does not model: the run
    /// stops with this report (naming the peripheral), never returning a made-up value.
    Unmodelled(String),
}

/// The memory and peripherals outside the core, as the core's loads, stores and
/// instruction fetches reach them.
pub trait Bus {
    /// Reads `size` bytes at `address` (little-endian); `now` is the core's cycle count.
    fn read(&mut self, address: u32, size: Size, now: u64) -> Result<u32, BusError>;
    /// Writes the low `size` bytes of `value` at `address`; `now` is the core's cycle
    /// count.
    fn write(&mut self, address: u32, size: Size, value: u32, now: u64) -> Result<(), BusError>;
    /// Whether the core should stop after the current instruction and hand back to its
    /// caller: a peripheral access changed an interrupt line or the next event's time.
    fn yield_requested(&mut self) -> bool {
        false
    }
    /// Reads an instruction halfword: a read, which a debugger's data watchpoints do not
    /// see (the DWT's comparators match data accesses).
    #[inline]
    fn fetch(&mut self, address: u32, size: Size, now: u64) -> Result<u32, BusError> {
        self.read(address, size, now)
    }
}

/// Why the core stopped for good (until reset): what a person debugging it needs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Halt {
    /// An access to a register no model covers.
    Unmodelled {
        /// What the bus said (the peripheral and register).
        what: String,
        /// The address.
        address: u32,
        /// The instruction's address.
        pc: u32,
        /// A write rather than a read.
        write: bool,
    },
    /// A fault while a fault could not be taken (in HardFault or NMI): the core locked up.
    Lockup {
        /// The instruction's address.
        pc: u32,
        /// What faulted.
        reason: String,
    },
    /// BKPT with a debugger attached: the core halts at the instruction (a semihosting
    /// call when the immediate is 0xAB). [`Cpu::step_over_breakpoint`] resumes after it.
    Breakpoint {
        /// The instruction's immediate.
        imm: u8,
        /// Its address.
        pc: u32,
    },
}

/// What stopped a run of the core.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Exit {
    /// The cycle budget was used up.
    Budget,
    /// The core sleeps (WFI, WFE) until an interrupt or event.
    Sleeping,
    /// The bus asked for the run to end (an interrupt line or a timer changed).
    Yield,
    /// The core stopped for good.
    Halted(Halt),
    /// The core halted for a debugger ([`Cpu::debug`]): it resumes where it stopped.
    Debug(DebugStop),
}

/// Why the core halted for a debugger.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DebugStop {
    /// The next instruction's address is a breakpoint's (halted before executing it).
    Breakpoint(u32),
    /// One step done: an instruction executed, or an exception entered.
    Step,
    /// The instruction count reached [`DebugControl::stop_at_instruction`].
    Position,
    /// The core entered the HardFault handler (vector catch).
    HardFault,
}

/// What halts the core for a debugger: the FPB's and the debugger's breakpoints, a single
/// step (DHCSR.C_STEP), a position in the instruction count (the reverse execution's
/// replays), and the HardFault vector catch (DEMCR.VC_HARDERR).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DebugControl {
    /// Instruction addresses that halt the core before it executes them.
    pub breakpoints: Vec<u32>,
    /// Halt after one instruction (or exception entry).
    pub step: bool,
    /// Halt once the next instruction's address leaves this range, or on exception entry.
    pub step_range: Option<core::ops::Range<u32>>,
    /// Halt when the instruction count is this, before the next instruction executes:
    /// before a pending exception is taken (`true`: the state the last instruction left),
    /// or after (`false`: where a breakpoint is checked).
    pub stop_at_instruction: Option<(u64, bool)>,
    /// Ignore a breakpoint while the instruction count is this (resuming from it).
    pub pass_breakpoint_at: Option<u64>,
    /// Halt on entering HardFault.
    pub catch_hard_fault: bool,
    /// A step's instruction ended the run (a peripheral access, a watchpoint): the step is
    /// reported at the next run, once the caller has handled what ended it.
    pub step_done: bool,
}

/// A fault of the instruction being executed, before the exception is chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// UsageFault: undefined instruction.
    Undefined,
    /// UsageFault: the T bit was clear (a branch to an even address or a vector without
    /// bit 0).
    InvalidState,
    /// UsageFault: an invalid EXC_RETURN or an illegal return.
    InvalidPc,
    /// UsageFault: a coprocessor that is absent or disabled (the FPU with CPACR off).
    NoCoprocessor,
    /// UsageFault: an unaligned access that must be aligned.
    Unaligned,
    /// UsageFault: division by zero with CCR.DIV_0_TRP set.
    DivideByZero,
    /// BusFault on a data access at the address (precise).
    Data(u32),
    /// BusFault on an instruction fetch.
    Fetch,
    /// MemManage: execution from an execute-never region.
    ExecuteNever,
    /// BKPT with no debugger attached: escalates to HardFault (DEBUGEVT).
    Breakpoint,
}

/// Internal: how an instruction ended other than normally.
#[derive(Clone, Debug)]
enum Trap {
    /// It faulted; the exception is taken with the instruction's address as the return.
    Fault(Fault),
    /// The core stops for good.
    Halt(Halt),
    /// It completed, and the core sleeps (WFI, WFE).
    Sleep,
    /// It completed with an exception return: the IT state came from the stack.
    Returned,
    /// It completed, and the run should end (AIRCR.SYSRESETREQ).
    Yield,
}

impl From<Fault> for Trap {
    fn from(fault: Fault) -> Self {
        Trap::Fault(fault)
    }
}

/// One decoded instruction in the cache.
#[derive(Clone, Copy)]
struct Cached {
    op: Op,
    len: u8,
}

/// The core.
#[derive(Clone)]
pub struct Cpu {
    /// r0–r15. r13 is the current stack pointer; r15 reads as the instruction's address
    /// plus 4 while it executes.
    r: [u32; 16],
    /// The other stack pointer (PSP while MSP is in use, and the reverse).
    other_sp: u32,
    /// The address of the instruction to execute next.
    pc: u32,
    /// Where the current instruction continues (set by branches).
    next: u32,
    /// The APSR's flags.
    n: bool,
    z: bool,
    c: bool,
    v: bool,
    q: bool,
    ge: u8,
    /// ITSTATE (EPSR.IT).
    it: u8,
    /// EPSR.T: clear after an interworking branch to an even address.
    thumb: bool,
    /// IPSR: the exception number being handled, 0 in thread mode.
    ipsr: u16,
    /// CONTROL: nPRIV (bit 0), SPSEL (bit 1), FPCA (bit 2).
    control: u8,
    primask: bool,
    faultmask: bool,
    basepri: u8,
    /// The single-precision registers.
    s: [u32; 32],
    fpscr: u32,
    /// The event register of WFE and SEV.
    event: bool,
    /// The core sleeps in WFI (true) or WFE (false).
    sleep: Option<bool>,
    /// The local exclusive monitor: the address of the last LDREX.
    exclusive: Option<u32>,
    /// Cycles executed since reset.
    cycles: u64,
    /// The system control space: NVIC, SCB, SysTick, DWT, FPU control.
    pub scs: Scs,
    /// Decoded instructions of the code region, one slot per halfword.
    code: Vec<Option<Cached>>,
    code_base: u32,
    /// Instructions executed since reset.
    instructions: u64,
    /// A debugger is attached (as probe-rs is): BKPT halts the core instead of escalating
    /// to HardFault.
    pub debugger_attached: bool,
    /// End the run after this instruction (an exception returned: the caller samples the
    /// interrupt lines again, as a level-sensitive line re-pends then).
    yield_request: bool,
    /// Halting debug: what stops the core for a debugger. `None` (no debugger) runs the
    /// instructions without looking.
    pub debug: Option<Box<DebugControl>>,
}

impl Cpu {
    /// A core whose instructions in `code` (the flash) are decoded once and cached;
    /// anywhere else they are decoded at each execution. Call [`Cpu::reset`] before
    /// running.
    pub fn new(code: core::ops::Range<u32>) -> Self {
        let halfwords = (code.end - code.start) as usize / 2;
        Cpu {
            r: [0; 16],
            other_sp: 0,
            pc: 0,
            next: 0,
            n: false,
            z: false,
            c: false,
            v: false,
            q: false,
            ge: 0,
            it: 0,
            thumb: true,
            ipsr: 0,
            control: 0,
            primask: false,
            faultmask: false,
            basepri: 0,
            s: [0; 32],
            fpscr: 0,
            event: false,
            sleep: None,
            exclusive: None,
            cycles: 0,
            scs: Scs::default(),
            code: vec![None; halfwords],
            code_base: code.start,
            instructions: 0,
            debugger_attached: false,
            yield_request: false,
            debug: None,
        }
    }

    /// Takes the core out of reset: the system registers at their reset values, SP and PC
    /// from the vector table at `vtor` (as the chip fetches them from its boot alias).
    pub fn reset<B: Bus>(&mut self, bus: &mut B, vtor: u32) -> Result<(), Halt> {
        let code = std::mem::take(&mut self.code);
        let code_base = self.code_base;
        let debugger_attached = self.debugger_attached;
        let debug = self.debug.take();
        *self = Cpu::new(code_base..code_base);
        self.code = code;
        self.debugger_attached = debugger_attached;
        self.debug = debug;
        self.scs.vtor = vtor;
        let read = |bus: &mut B, address: u32| {
            bus.read(address, Size::Word, 0).map_err(|e| Halt::Lockup {
                pc: address,
                reason: format!("the reset vector at {address:#010x} cannot be read ({e:?})"),
            })
        };
        let sp = read(bus, vtor)?;
        let reset = read(bus, vtor + 4)?;
        self.r[13] = sp & !3;
        self.r[14] = 0xFFFF_FFFF;
        self.pc = reset & !1;
        self.thumb = reset & 1 != 0;
        Ok(())
    }

    /// The core's state now, without its cache of decoded instructions (a reverse
    /// debugger's snapshot).
    pub fn snapshot(&mut self) -> Cpu {
        let code = std::mem::take(&mut self.code);
        let saved = self.clone();
        self.code = code;
        saved
    }

    /// Puts the core back as `snapshot` found it, keeping the decoded instructions
    /// (forgotten with `code_changed`: the flash differs).
    pub fn restore(&mut self, snapshot: &Cpu, code_changed: bool) {
        let mut code = std::mem::take(&mut self.code);
        if code_changed {
            code.iter_mut().for_each(|slot| *slot = None);
        }
        *self = snapshot.clone();
        self.code = code;
    }

    /// Forgets decoded instructions in `range` (after flash is programmed or erased).
    pub fn invalidate_code(&mut self, range: core::ops::Range<u32>) {
        let end = self.code_base as u64 + self.code.len() as u64 * 2;
        let start = range.start.max(self.code_base) as u64;
        // An instruction may start two bytes before the range and reach into it.
        let start = start.saturating_sub(2).max(self.code_base as u64);
        let stop = (range.end as u64).min(end);
        if start >= stop {
            return;
        }
        let first = ((start - self.code_base as u64) / 2) as usize;
        let last = ((stop - self.code_base as u64).div_ceil(2)) as usize;
        let last = last.min(self.code.len());
        for slot in &mut self.code[first..last] {
            *slot = None;
        }
    }

    /// Cycles executed since reset (one per instruction plus the Cortex-M4's extra cycles
    /// for loads, multiples, branches, divides and exception entry).
    pub fn cycles(&self) -> u64 {
        self.cycles
    }

    /// Adds cycles the core spent stalled (a flash write, a sleep skipped by the caller).
    pub fn add_cycles(&mut self, cycles: u64) {
        self.cycles += cycles;
    }

    /// Instructions executed since reset.
    pub fn instructions(&self) -> u64 {
        self.instructions
    }

    /// The address of the next instruction.
    pub fn pc(&self) -> u32 {
        self.pc
    }

    /// A peripheral's interrupt line went high: IRQ `irq` pends (and, with
    /// SCR.SEVONPEND, the pending transition is an event that wakes WFE).
    pub fn raise_irq(&mut self, irq: usize) {
        let was = self.scs.irq_pending(irq);
        self.scs.raise_irq(irq);
        if !was && self.scs.irq_pending(irq) && self.scs.sev_on_pend() {
            self.event = true;
        }
    }

    /// Whether the core sleeps in WFI or WFE.
    pub fn is_sleeping(&self) -> bool {
        self.sleep.is_some()
    }

    /// Writes a word as a debugger does, through the core's view of memory (the system
    /// control space included).
    pub fn debug_write<B: Bus>(
        &mut self,
        bus: &mut B,
        address: u32,
        value: u32,
    ) -> Result<(), Halt> {
        match self.store(bus, address, Size::Word, value) {
            Ok(()) | Err(Trap::Yield) => Ok(()),
            Err(Trap::Halt(halt)) => Err(halt),
            Err(other) => Err(Halt::Lockup {
                pc: self.pc,
                reason: format!("debug write to {address:#010x}: {other:?}"),
            }),
        }
    }

    /// Reads a register of the private peripheral bus (NVIC, SCB, SysTick, DWT, the FPU's)
    /// as a debugger does; `None` for an unaligned or unmodelled one.
    pub fn debug_read_private(&mut self, address: u32, size: Size) -> Option<u32> {
        if address & (size as u32 - 1) != 0 {
            return None;
        }
        self.scs_read(address, size).ok()
    }

    /// Resumes after a BKPT the core halted on (a debugger's semihosting service done).
    pub fn step_over_breakpoint(&mut self) {
        self.pc = self.pc.wrapping_add(2);
    }

    /// Sets register `n` (0–14) as a debugger does.
    pub fn set_reg(&mut self, n: usize, value: u32) {
        if n < 15 {
            self.r[n] = if n == 13 { value & !3 } else { value };
        }
    }

    /// Register `n` (0–15; 15 gives the next instruction's address).
    pub fn reg(&self, n: usize) -> u32 {
        if n == 15 {
            self.pc
        } else {
            self.r[n]
        }
    }

    /// The combined xPSR.
    pub fn xpsr(&self) -> u32 {
        let it = self.it as u32;
        (self.n as u32) << 31
            | (self.z as u32) << 30
            | (self.c as u32) << 29
            | (self.v as u32) << 28
            | (self.q as u32) << 27
            | (it & 0b11) << 25
            | (self.thumb as u32) << 24
            | (self.ge as u32) << 16
            | (it >> 2) << 10
            | self.ipsr as u32
    }

    fn set_xpsr(&mut self, value: u32) {
        self.n = value >> 31 & 1 != 0;
        self.z = value >> 30 & 1 != 0;
        self.c = value >> 29 & 1 != 0;
        self.v = value >> 28 & 1 != 0;
        self.q = value >> 27 & 1 != 0;
        self.ge = (value >> 16 & 0xF) as u8;
        self.it = ((value >> 25 & 0b11) | (value >> 10 & 0x3F) << 2) as u8;
        self.thumb = value >> 24 & 1 != 0;
        self.ipsr = (value & 0x1FF) as u16;
    }

    /// The state a debugger sees.
    pub fn arch_state(&self) -> ArchState {
        let mut r = self.r;
        r[15] = self.pc;
        ArchState {
            r,
            xpsr: self.xpsr(),
            s: self.s,
            fpscr: self.fpscr,
        }
    }

    /// Sets the state a debugger would set (registers, flags, FP registers). The exception
    /// number in xPSR is kept as it is.
    pub fn set_arch_state(&mut self, state: &ArchState) {
        let ipsr = self.ipsr;
        self.r[..15].copy_from_slice(&state.r[..15]);
        self.r[13] &= !3;
        self.pc = state.r[15] & !1;
        self.set_xpsr(state.xpsr);
        self.ipsr = ipsr;
        self.s = state.s;
        self.fpscr = state.fpscr & FPSCR_MASK;
    }

    /// CONTROL.
    pub fn control(&self) -> u8 {
        self.control
    }

    /// Sets CONTROL as a debugger would (no stack pointer swap).
    pub fn set_control(&mut self, value: u8) {
        self.control = value & 0b111;
    }

    /// Runs until `cycles()` reaches `until`, the core sleeps, the bus asks for a yield or
    /// the core halts.
    pub fn run<B: Bus>(&mut self, bus: &mut B, until: u64) -> Exit {
        if self.sleep.is_some() && !self.wake_check() {
            return Exit::Sleeping;
        }
        if self.debug.is_some() {
            return self.run_debugged(bus, until);
        }
        self.run_to_systick::<B, false>(bus, until)
    }

    /// The run in stretches between SysTick's expiries (a SysTick that expires pends its
    /// exception between instructions), each stretch run by `run_until`, or with the
    /// debugger's checks by `run_until_debugged` (`DEBUGGED`).
    #[inline(always)]
    fn run_to_systick<B: Bus, const DEBUGGED: bool>(&mut self, bus: &mut B, until: u64) -> Exit {
        loop {
            let limit = match self.scs.systick_next {
                Some(at) if at <= self.cycles => {
                    self.systick_expired();
                    continue;
                }
                Some(at) => at.min(until),
                None => until,
            };
            if self.cycles >= limit {
                return Exit::Budget;
            }
            let exit = if DEBUGGED {
                self.run_until_debugged(bus, limit)
            } else {
                self.run_until(bus, limit)
            };
            match exit {
                Exit::Budget => {}
                other => return other,
            }
        }
    }

    #[inline(always)]
    fn run_until<B: Bus>(&mut self, bus: &mut B, until: u64) -> Exit {
        while self.cycles < until {
            if self.scs.check_pending {
                if let Err(halt) = self.take_pending_exception(bus) {
                    return Exit::Halted(halt);
                }
            }
            match self.step(bus) {
                Ok(()) => {}
                Err(Trap::Sleep) => return Exit::Sleeping,
                Err(Trap::Yield) => return Exit::Yield,
                Err(Trap::Halt(halt)) => return Exit::Halted(halt),
                Err(Trap::Fault(fault)) => {
                    if let Err(halt) = self.fault(bus, fault) {
                        return Exit::Halted(halt);
                    }
                }
                Err(Trap::Returned) => {}
            }
            if self.yield_request || bus.yield_requested() {
                self.yield_request = false;
                return Exit::Yield;
            }
        }
        Exit::Budget
    }

    /// As [`Cpu::run`], halting where [`Cpu::debug`] says: the checks cost a few
    /// comparisons an instruction, so they run only while a debugger is attached.
    // Kept out of `run`, whose loop is the emulator's hot path.
    #[inline(never)]
    fn run_debugged<B: Bus>(&mut self, bus: &mut B, until: u64) -> Exit {
        if let Some(control) = self.debug.as_deref_mut() {
            if std::mem::take(&mut control.step_done) {
                return Exit::Debug(DebugStop::Step);
            }
        }
        self.run_to_systick::<B, true>(bus, until)
    }

    fn run_until_debugged<B: Bus>(&mut self, bus: &mut B, until: u64) -> Exit {
        let Some(control) = self.debug.as_deref() else {
            return self.run_until(bus, until);
        };
        let range = control.step_range.clone();
        let (step, stop_at, pass_at, catch) = (
            control.step || range.is_some(),
            control.stop_at_instruction,
            control.pass_breakpoint_at,
            control.catch_hard_fault,
        );
        let breakpoints = control.breakpoints.clone();
        while self.cycles < until {
            if stop_at == Some((self.instructions, true)) {
                return Exit::Debug(DebugStop::Position);
            }
            if self.scs.check_pending {
                let before = (self.pc, self.ipsr);
                if let Err(halt) = self.take_pending_exception(bus) {
                    return Exit::Halted(halt);
                }
                if (self.pc, self.ipsr) != before {
                    if catch && self.ipsr == system::exception::HARD_FAULT {
                        return Exit::Debug(DebugStop::HardFault);
                    }
                    if step {
                        return Exit::Debug(DebugStop::Step);
                    }
                }
            }
            if stop_at == Some((self.instructions, false)) {
                return Exit::Debug(DebugStop::Position);
            }
            if pass_at != Some(self.instructions) && breakpoints.contains(&self.pc) {
                return Exit::Debug(DebugStop::Breakpoint(self.pc));
            }
            let ipsr = self.ipsr;
            match self.step(bus) {
                Ok(()) => {}
                Err(Trap::Sleep) if step => return Exit::Debug(DebugStop::Step),
                Err(Trap::Sleep) => return Exit::Sleeping,
                Err(Trap::Yield) => return Exit::Yield,
                Err(Trap::Halt(halt)) => return Exit::Halted(halt),
                Err(Trap::Fault(fault)) => {
                    if let Err(halt) = self.fault(bus, fault) {
                        return Exit::Halted(halt);
                    }
                    if catch && self.ipsr == system::exception::HARD_FAULT && ipsr != self.ipsr {
                        return Exit::Debug(DebugStop::HardFault);
                    }
                }
                Err(Trap::Returned) => {}
            }
            if self.yield_request || bus.yield_requested() {
                self.yield_request = false;
                let left = !range.as_ref().is_some_and(|r| r.contains(&self.pc));
                if let (true, Some(control)) = (step && left, self.debug.as_deref_mut()) {
                    control.step_done = true;
                }
                return Exit::Yield;
            }
            if step && !range.as_ref().is_some_and(|r| r.contains(&self.pc)) {
                return Exit::Debug(DebugStop::Step);
            }
        }
        Exit::Budget
    }

    /// Executes one instruction (or takes a pending exception first).
    pub fn step_one<B: Bus>(&mut self, bus: &mut B) -> Result<(), Halt> {
        if self.scs.check_pending {
            self.take_pending_exception(bus)?;
        }
        match self.step(bus) {
            Ok(()) | Err(Trap::Sleep | Trap::Yield | Trap::Returned) => Ok(()),
            Err(Trap::Halt(halt)) => Err(halt),
            Err(Trap::Fault(fault)) => self.fault(bus, fault),
        }
    }

    #[inline(always)]
    fn fetch<B: Bus>(&mut self, bus: &mut B, address: u32) -> Result<(Op, u32), Trap> {
        let offset = address.wrapping_sub(self.code_base) as usize / 2;
        if let Some(Some(cached)) = self.code.get(offset) {
            return Ok((cached.op, cached.len as u32));
        }
        // The default memory map's execute-never regions (ARMv7-M B3.1): peripherals,
        // external devices and the system region. A fetch there faults, as on the chip,
        // before the bus is asked.
        if matches!(address, 0x4000_0000..=0x5FFF_FFFF | 0xA000_0000..=0xFFFF_FFFF) {
            return Err(Fault::ExecuteNever.into());
        }
        let hw1 = self.fetch_half(bus, address)?;
        let hw2 = if decode::is_wide(hw1) {
            self.fetch_half(bus, address.wrapping_add(2))?
        } else {
            0
        };
        let (op, len) = decode::decode(hw1, hw2, address);
        if let Some(slot) = self.code.get_mut(offset) {
            *slot = Some(Cached { op, len: len as u8 });
        }
        Ok((op, len))
    }

    fn fetch_half<B: Bus>(&mut self, bus: &mut B, address: u32) -> Result<u16, Trap> {
        match bus.fetch(address, Size::Half, self.cycles) {
            Ok(value) => Ok(value as u16),
            Err(BusError::Fault) => Err(Fault::Fetch.into()),
            Err(BusError::Unmodelled(what)) => Err(Trap::Halt(Halt::Unmodelled {
                what,
                address,
                pc: self.pc,
                write: false,
            })),
        }
    }

    // Always inlined (as `fetch` and `run_until`): the core's loop is where the emulator
    // spends its time, and with a second caller (the debugged loop) LLVM called them
    // instead (14 % more instructions on the nine-firmware car, measured with callgrind).
    #[inline(always)]
    fn step<B: Bus>(&mut self, bus: &mut B) -> Result<(), Trap> {
        if !self.thumb {
            return Err(Fault::InvalidState.into());
        }
        let pc = self.pc;
        let (op, len) = self.fetch(bus, pc)?;
        self.instructions += 1;
        self.cycles += 1;
        let it = self.it;
        if it != 0 {
            let pass = self.condition(it >> 4);
            if !pass {
                self.it = advance_it(it);
                self.pc = pc.wrapping_add(len);
                return Ok(());
            }
        }
        self.r[15] = pc.wrapping_add(4);
        self.next = pc.wrapping_add(len);
        match self.execute(bus, op, it != 0) {
            Ok(()) => {}
            Err(Trap::Returned) => {
                self.pc = self.next;
                return Ok(());
            }
            Err(Trap::Yield) => {
                self.it = advance_it(self.it);
                self.pc = self.next;
                return Err(Trap::Yield);
            }
            Err(other) => return Err(other),
        }
        if it != 0 {
            self.it = advance_it(self.it);
        }
        self.pc = self.next;
        Ok(())
    }

    /// ConditionPassed for a 4-bit condition.
    #[inline]
    fn condition(&self, cond: u8) -> bool {
        let result = match cond >> 1 {
            0 => self.z,
            1 => self.c,
            2 => self.n,
            3 => self.v,
            4 => self.c && !self.z,
            5 => self.n == self.v,
            6 => self.n == self.v && !self.z,
            _ => return true,
        };
        if cond & 1 != 0 {
            !result
        } else {
            result
        }
    }
}

/// ITAdvance.
#[inline]
fn advance_it(it: u8) -> u8 {
    if it & 0b111 == 0 {
        0
    } else {
        (it & 0b1110_0000) | ((it << 1) & 0b1_1111)
    }
}

/// The FPSCR bits that exist on FPv4-SP: N Z C V, AHP, DN, FZ, RMode, and the cumulative
/// exception flags IDC, IXC, UFC, OFC, DZC, IOC.
pub const FPSCR_MASK: u32 = 0xF7C0_009F;
