//! Halting debug of the emulated MCU, as a debug probe gives it on the chip: breakpoints
//! (the FPB's six comparators, and a debugger's software breakpoints), the DWT's four data
//! watchpoints, single steps, the HardFault vector catch, and a halt on request. While a
//! [`Debugger`] holds the core halted the MCU's caller waits in [`Mcu::run_until`]
//! (crate::mcu::Mcu::run_until), so whatever runs the MCU in simulated time (the virtual
//! car: its bus, vehicle model and other ECUs) stands still with it.

use crate::chip::Chip;
use crate::cpu::{Bus, BusError, DebugStop, Size};
use crate::mcu::Mcu;

/// The Cortex-M4's Flash Patch and Breakpoint unit has six instruction comparators.
pub const HW_BREAKPOINTS: usize = 6;

/// The Cortex-M4's DWT has four comparators (DWT_CTRL.NUMCOMP).
pub const WATCHPOINTS: usize = 4;

/// The accesses a watchpoint halts on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WatchKind {
    /// Writes (DWT_FUNCTION 0b0110).
    Write,
    /// Reads (0b0101).
    Read,
    /// Either (0b0111).
    Access,
}

/// A DWT comparator set on a data range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Watchpoint {
    /// The first byte watched.
    pub address: u32,
    /// How many bytes (1 to 2^31, a power of two on the chip; any length here).
    pub len: u32,
    /// The accesses that halt.
    pub kind: WatchKind,
}

impl Watchpoint {
    fn matches(&self, address: u32, size: Size, write: bool) -> bool {
        let wanted = match self.kind {
            WatchKind::Write => write,
            WatchKind::Read => !write,
            WatchKind::Access => true,
        };
        let end = u64::from(self.address) + u64::from(self.len);
        wanted
            && u64::from(address) < end
            && u64::from(address) + size as u64 > u64::from(self.address)
    }
}

/// A data access a watchpoint matched.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WatchHit {
    /// The watchpoint's address (what GDB names in its stop reply).
    pub watched: u32,
    /// The watchpoint's kind.
    pub kind: WatchKind,
    /// The access: a write (true) or a read.
    pub write: bool,
}

/// The chip as the core sees it while watchpoints are set: each data access is compared
/// with them, and a match ends the core's run after the instruction (the DWT halts the
/// core after the access, not before it).
pub(crate) struct WatchBus<'a> {
    pub chip: &'a mut Chip,
    pub watch: &'a [Watchpoint],
    pub hit: Option<WatchHit>,
}

impl WatchBus<'_> {
    fn check(&mut self, address: u32, size: Size, write: bool) {
        if self.hit.is_none() {
            if let Some(w) = self.watch.iter().find(|w| w.matches(address, size, write)) {
                self.hit = Some(WatchHit {
                    watched: w.address,
                    kind: w.kind,
                    write,
                });
            }
        }
    }
}

impl Bus for WatchBus<'_> {
    #[inline]
    fn read(&mut self, address: u32, size: Size, now: u64) -> Result<u32, BusError> {
        self.check(address, size, false);
        self.chip.read(address, size, now)
    }

    #[inline]
    fn write(&mut self, address: u32, size: Size, value: u32, now: u64) -> Result<(), BusError> {
        self.check(address, size, true);
        self.chip.write(address, size, value, now)
    }

    fn yield_requested(&mut self) -> bool {
        self.chip.yield_requested() || self.hit.is_some()
    }

    #[inline]
    fn fetch(&mut self, address: u32, size: Size, now: u64) -> Result<u32, BusError> {
        self.chip.read(address, size, now)
    }
}

/// How the debugger resumes the core.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum Resume {
    /// Run until something halts it.
    #[default]
    Continue,
    /// One instruction (or exception entry).
    Step,
    /// Instructions while the next one's address is in the range (GDB's range stepping:
    /// a source line's instructions without a round trip each).
    StepRange(core::ops::Range<u32>),
    /// Back one instruction ([`crate::history`]).
    ReverseStep,
    /// Back to the last breakpoint or watchpoint hit.
    ReverseContinue,
}

/// What a debugger set on the MCU: the FPB's hardware breakpoints, its own software
/// breakpoints (matched by address here too: the image is never patched with BKPT, so
/// memory reads show the firmware's own code), the DWT's watchpoints, and how the core
/// resumes.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct DebugUnit {
    /// FPB comparators in use (at most [`HW_BREAKPOINTS`]).
    pub hw_breakpoints: Vec<u32>,
    /// Software breakpoints.
    pub sw_breakpoints: Vec<u32>,
    /// DWT comparators in use (at most [`WATCHPOINTS`]).
    pub watchpoints: Vec<Watchpoint>,
    /// How the core resumes.
    pub resume: Resume,
    /// The debugger changed the MCU's state (registers, memory, flash, a reset) since the
    /// flag was last cleared: what the MCU does from here is not what it would have done.
    pub changed_by_debugger: bool,
}

impl DebugUnit {
    /// What halts the core, for [`crate::cpu::Cpu::debug`]: the breakpoints, the step,
    /// and the HardFault vector catch.
    pub fn control(&self) -> crate::cpu::DebugControl {
        let mut breakpoints = self.hw_breakpoints.clone();
        breakpoints.extend(&self.sw_breakpoints);
        breakpoints.sort_unstable();
        breakpoints.dedup();
        crate::cpu::DebugControl {
            breakpoints,
            step: self.resume == Resume::Step,
            step_range: match &self.resume {
                Resume::StepRange(range) => Some(range.clone()),
                _ => None,
            },
            catch_hard_fault: true,
            ..Default::default()
        }
    }
}

/// Why the MCU halted for its debugger.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Halted {
    /// The debugger asked (a client attached, or Ctrl-C).
    Request,
    /// The core halted: a breakpoint, a step, a position, the HardFault vector catch.
    Core(DebugStop),
    /// A watchpoint matched the last instruction's access.
    Watch(WatchHit),
    /// The core locked up (a fault it cannot take, as in its HardFault handler): it
    /// stays locked until a reset, which the debugger may ask for.
    Lockup(crate::cpu::Halt),
    /// The core executed a BKPT instruction (other than a semihosting call).
    Bkpt {
        /// Its immediate.
        imm: u8,
        /// Its address.
        pc: u32,
    },
}

/// What a debugger attached to an MCU does when the core halts for it. It holds the MCU
/// (and whatever runs it) until it resumes the core, setting [`Mcu::debug`] for what
/// halts the core next.
pub trait Debugger: Send {
    /// Whether the debugger wants the core halted now: checked between the MCU's events,
    /// so it must be cheap (an atomic flag).
    fn wants_halt(&self) -> bool;
    /// The core halted: serve the debugger until it resumes the core.
    fn halted(&mut self, mcu: &mut Mcu, why: Halted);
}
