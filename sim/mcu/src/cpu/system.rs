//! The ARMv7-M exception model (DDI 0403E, B1.5) and the system control space the core
//! models itself: NVIC, SCB, SysTick, the FPU's control registers, DWT, DCB and the STM32's
//! DBGMCU on the private peripheral bus.

use super::{Bus, Cpu, Fault, Halt, Size, Trap};

/// Exception numbers.
pub mod exception {
    /// Non-maskable interrupt.
    pub const NMI: u16 = 2;
    /// HardFault.
    pub const HARD_FAULT: u16 = 3;
    /// MemManage fault.
    pub const MEM_MANAGE: u16 = 4;
    /// BusFault.
    pub const BUS_FAULT: u16 = 5;
    /// UsageFault.
    pub const USAGE_FAULT: u16 = 6;
    /// Supervisor call.
    pub const SVCALL: u16 = 11;
    /// Pendable service call.
    pub const PENDSV: u16 = 14;
    /// SysTick.
    pub const SYSTICK: u16 = 15;
    /// The first external interrupt (IRQ 0).
    pub const IRQ0: u16 = 16;
}
use exception::*;

/// The external interrupts the NVIC has on the STM32F446 (RM0390, table 38: 0–96).
pub const IRQS: usize = 97;

/// FPCCR.LSPACT: lazy state preservation is active (space reserved, not yet written).
pub const FPCCR_LSPACT: u32 = 1 << 0;
/// FPCCR.LSPEN: lazy state preservation enabled.
pub const FPCCR_LSPEN: u32 = 1 << 30;
/// FPCCR.ASPEN: CONTROL.FPCA set automatically by the first FP instruction.
pub const FPCCR_ASPEN: u32 = 1 << 31;

const CCR_STKALIGN: u32 = 1 << 9;
const CCR_NONBASETHRDENA: u32 = 1 << 0;
const SCR_SEVONPEND: u32 = 1 << 4;
const HFSR_FORCED: u32 = 1 << 30;
const HFSR_DEBUGEVT: u32 = 1 << 31;
const SHCSR_ENABLES: [u32; 3] = [1 << 16, 1 << 17, 1 << 18];

/// A HardFault (or another fault) as a person debugging it wants to see it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExceptionReport {
    /// The exception taken (3: HardFault).
    pub exception: u16,
    /// What the core did wrong.
    pub fault: Fault,
    /// The faulting instruction's address.
    pub pc: u32,
    /// LR at the fault.
    pub lr: u32,
    /// The configurable fault status register after the fault.
    pub cfsr: u32,
    /// The HardFault status register after the fault.
    pub hfsr: u32,
    /// The BusFault address register.
    pub bfar: u32,
}

/// The system control space's state.
#[derive(Clone, Debug)]
pub struct Scs {
    /// VTOR.
    pub vtor: u32,
    prigroup: u32,
    scr: u32,
    /// CCR.
    pub ccr: u32,
    /// Priorities of the system exceptions 4–15 (SHPR1–3), by exception number.
    shpr: [u8; 16],
    shcsr: u32,
    /// CFSR.
    pub cfsr: u32,
    /// HFSR.
    pub hfsr: u32,
    mmfar: u32,
    bfar: u32,
    /// CPACR.
    pub cpacr: u32,
    /// FPCCR.
    pub fpccr: u32,
    /// FPCAR.
    pub fpcar: u32,
    /// FPDSCR.
    pub fpdscr: u32,
    irq_enabled: [u32; 4],
    irq_pending: [u32; 4],
    irq_active: [u32; 4],
    irq_priority: [u8; 128],
    /// System exceptions pending and active, by exception number.
    sys_pending: u16,
    sys_active: u16,
    /// Something changed that may let a pending exception preempt: look before the next
    /// instruction.
    pub(super) check_pending: bool,
    /// AIRCR.SYSRESETREQ was written: the chip should reset.
    pub reset_requested: bool,
    systick_csr: u32,
    systick_rvr: u32,
    /// Cycle at which SysTick's counter last reloaded, when it runs.
    systick_epoch: u64,
    /// The cycle at which SysTick next reaches zero, when it runs.
    pub(super) systick_next: Option<u64>,
    demcr: u32,
    dwt_ctrl: u32,
    /// CYCCNT = cycles - dwt_base while counting.
    dwt_base: u64,
    dwt_frozen: u32,
    dbgmcu: [u32; 3],
    actlr: u32,
    /// The last fault taken, for the caller's report.
    pub last_fault: Option<ExceptionReport>,
}

impl Default for Scs {
    fn default() -> Self {
        Scs {
            vtor: 0,
            prigroup: 0,
            scr: 0,
            ccr: CCR_STKALIGN,
            shpr: [0; 16],
            shcsr: 0,
            cfsr: 0,
            hfsr: 0,
            mmfar: 0,
            bfar: 0,
            cpacr: 0,
            fpccr: FPCCR_ASPEN | FPCCR_LSPEN,
            fpcar: 0,
            fpdscr: 0,
            irq_enabled: [0; 4],
            irq_pending: [0; 4],
            irq_active: [0; 4],
            irq_priority: [0; 128],
            sys_pending: 0,
            sys_active: 0,
            check_pending: false,
            reset_requested: false,
            systick_csr: 0,
            systick_rvr: 0,
            systick_epoch: 0,
            systick_next: None,
            demcr: 0,
            dwt_ctrl: 0x4000_0000,
            dwt_base: 0,
            dwt_frozen: 0,
            dbgmcu: [0; 3],
            actlr: 0,
            last_fault: None,
        }
    }
}

impl Scs {
    /// Marks IRQ `irq` pending (a peripheral's interrupt line), unless it is active: a
    /// level-sensitive line still high when its handler returns pends it again then.
    pub fn raise_irq(&mut self, irq: usize) {
        if irq >= IRQS {
            return;
        }
        let (word, bit) = (irq / 32, 1u32 << (irq % 32));
        if self.irq_active[word] & bit == 0 && self.irq_pending[word] & bit == 0 {
            self.irq_pending[word] |= bit;
            self.check_pending = true;
        }
    }

    /// Whether IRQ `irq` is enabled in the NVIC.
    pub fn irq_enabled(&self, irq: usize) -> bool {
        irq < IRQS && self.irq_enabled[irq / 32] & (1 << (irq % 32)) != 0
    }

    /// Whether IRQ `irq` is pending.
    pub fn irq_pending(&self, irq: usize) -> bool {
        irq < IRQS && self.irq_pending[irq / 32] & (1 << (irq % 32)) != 0
    }

    /// Whether SCR.SEVONPEND is set.
    pub fn sev_on_pend(&self) -> bool {
        self.scr & SCR_SEVONPEND != 0
    }

    /// Whether SCR.SLEEPDEEP is set (the chip would enter Stop mode on WFI/WFE).
    pub fn sleep_deep(&self) -> bool {
        self.scr & (1 << 2) != 0
    }

    fn priority(&self, exc: u16) -> i16 {
        match exc {
            1 => -3,
            NMI => -2,
            HARD_FAULT => -1,
            4..=15 => self.shpr[exc as usize] as i16,
            _ => self.irq_priority[(exc - IRQ0) as usize] as i16,
        }
    }

    /// The group priority of a priority value (AIRCR.PRIGROUP splits group from
    /// subpriority).
    fn group(&self, priority: i16) -> i16 {
        if priority < 0 {
            return priority;
        }
        let mask = !((2i16 << self.prigroup) - 1);
        priority & mask
    }

    fn is_active(&self, exc: u16) -> bool {
        if exc < IRQ0 {
            self.sys_active & (1 << exc) != 0
        } else {
            let irq = (exc - IRQ0) as usize;
            self.irq_active[irq / 32] & (1 << (irq % 32)) != 0
        }
    }

    fn set_active(&mut self, exc: u16, on: bool) {
        if exc < IRQ0 {
            if on {
                self.sys_active |= 1 << exc;
            } else {
                self.sys_active &= !(1 << exc);
            }
        } else {
            let irq = (exc - IRQ0) as usize;
            if on {
                self.irq_active[irq / 32] |= 1 << (irq % 32);
            } else {
                self.irq_active[irq / 32] &= !(1 << (irq % 32));
            }
        }
    }

    fn set_pending(&mut self, exc: u16, on: bool) {
        if exc < IRQ0 {
            if on {
                self.sys_pending |= 1 << exc;
            } else {
                self.sys_pending &= !(1 << exc);
            }
        } else {
            let irq = (exc - IRQ0) as usize;
            if on {
                self.irq_pending[irq / 32] |= 1 << (irq % 32);
            } else {
                self.irq_pending[irq / 32] &= !(1 << (irq % 32));
            }
        }
        if on {
            self.check_pending = true;
        }
    }

    /// The highest-priority active exception's group priority (256 if none).
    fn active_priority(&self) -> i16 {
        let mut best = 256;
        for exc in 1..16u16 {
            if self.sys_active & (1 << exc) != 0 {
                best = best.min(self.group(self.priority(exc)));
            }
        }
        for (word, &active) in self.irq_active.iter().enumerate() {
            let mut bits = active;
            while bits != 0 {
                let irq = word * 32 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                best = best.min(self.group(self.irq_priority[irq] as i16));
            }
        }
        best
    }

    /// The pending exception that would be taken next, with its priority.
    fn best_pending(&self) -> Option<(i16, u16)> {
        let mut best: Option<(i16, u16)> = None;
        let mut consider = |priority: i16, exc: u16| {
            if best.is_none_or(|(p, _)| priority < p) {
                best = Some((priority, exc));
            }
        };
        for exc in 1..16u16 {
            if self.sys_pending & (1 << exc) != 0 {
                consider(self.priority(exc), exc);
            }
        }
        for word in 0..4 {
            let mut bits = self.irq_pending[word] & self.irq_enabled[word];
            while bits != 0 {
                let irq = word * 32 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                consider(self.irq_priority[irq] as i16, IRQ0 + irq as u16);
            }
        }
        best
    }

    fn nested_activations(&self) -> u32 {
        (self.sys_active.count_ones()) + self.irq_active.iter().map(|w| w.count_ones()).sum::<u32>()
    }
}

impl Cpu {
    /// The execution priority (B1.5.4): the highest active exception's group priority,
    /// boosted by PRIMASK, FAULTMASK and BASEPRI.
    pub(super) fn execution_priority(&self) -> i16 {
        self.priority_with(self.primask)
    }

    fn priority_with(&self, primask: bool) -> i16 {
        let mut priority = self.scs.active_priority();
        if self.basepri != 0 {
            priority = priority.min(self.scs.group(self.basepri as i16));
        }
        if primask {
            priority = priority.min(0);
        }
        if self.faultmask {
            priority = priority.min(-1);
        }
        priority
    }

    /// WFI's wake-up condition: an exception pending that would preempt with PRIMASK clear.
    pub(super) fn exception_would_wake(&self) -> bool {
        match self.scs.best_pending() {
            Some((priority, _)) => self.scs.group(priority) < self.priority_with(false),
            None => false,
        }
    }

    /// Whether a sleeping core wakes now; wakes it if so.
    pub(super) fn wake_check(&mut self) -> bool {
        let wake = match self.sleep {
            None => true,
            Some(true) => self.exception_would_wake(),
            Some(false) => {
                if self.event {
                    self.event = false;
                    true
                } else {
                    self.exception_would_wake()
                }
            }
        };
        if wake {
            self.sleep = None;
        }
        wake
    }

    /// Takes the most urgent pending exception if it may preempt.
    pub(super) fn take_pending_exception<B: Bus>(&mut self, bus: &mut B) -> Result<(), Halt> {
        self.scs.check_pending = false;
        let Some((priority, exc)) = self.scs.best_pending() else {
            return Ok(());
        };
        if self.scs.group(priority) >= self.execution_priority() {
            return Ok(());
        }
        self.sleep = None;
        self.exception_entry(bus, exc)
    }

    /// Pends an SVCall, or a HardFault if SVCall could not be taken now (B1.5.6).
    pub(super) fn svc(&mut self) {
        if self.scs.group(self.scs.priority(SVCALL)) < self.execution_priority() {
            self.scs.set_pending(SVCALL, true);
        } else {
            self.scs.hfsr |= HFSR_FORCED;
            self.scs.set_pending(HARD_FAULT, true);
        }
    }

    /// A fault of the current instruction: its status bits, its exception (escalated to
    /// HardFault when disabled or not urgent enough), taken at once; a fault that cannot
    /// be taken locks the core up.
    pub(super) fn fault<B: Bus>(&mut self, bus: &mut B, fault: Fault) -> Result<(), Halt> {
        let (mut exc, status) = match fault {
            Fault::Undefined => (USAGE_FAULT, 1 << 16),
            Fault::InvalidState => (USAGE_FAULT, 1 << 17),
            Fault::InvalidPc => (USAGE_FAULT, 1 << 18),
            Fault::NoCoprocessor => (USAGE_FAULT, 1 << 19),
            Fault::Unaligned => (USAGE_FAULT, 1 << 24),
            Fault::DivideByZero => (USAGE_FAULT, 1 << 25),
            Fault::Data(address) => {
                self.scs.bfar = address;
                (BUS_FAULT, 1 << 9 | 1 << 15)
            }
            Fault::Fetch => (BUS_FAULT, 1 << 8),
            Fault::ExecuteNever => (MEM_MANAGE, 1 << 0),
            Fault::Breakpoint => (HARD_FAULT, 0),
        };
        self.scs.cfsr |= status;
        if fault == Fault::Breakpoint {
            self.scs.hfsr |= HFSR_DEBUGEVT;
        }
        let execution = self.execution_priority();
        if exc != HARD_FAULT {
            let enabled = self.scs.shcsr & SHCSR_ENABLES[(exc - MEM_MANAGE) as usize] != 0;
            if !enabled || self.scs.group(self.scs.priority(exc)) >= execution {
                exc = HARD_FAULT;
                self.scs.hfsr |= HFSR_FORCED;
            }
        }
        if exc == HARD_FAULT && execution <= -1 {
            return Err(Halt::Lockup {
                pc: self.pc,
                reason: format!("{fault:?} at priority {execution} (in HardFault or NMI)"),
            });
        }
        self.scs.last_fault = Some(ExceptionReport {
            exception: exc,
            fault,
            pc: self.pc,
            lr: self.r[14],
            cfsr: self.scs.cfsr,
            hfsr: self.scs.hfsr,
            bfar: self.scs.bfar,
        });
        self.scs.set_pending(exc, true);
        self.take_pending_exception(bus)
    }

    /// Exception entry (B1.5.6): the frame pushed (with the FP context, lazily), the
    /// handler's address from the vector table.
    fn exception_entry<B: Bus>(&mut self, bus: &mut B, exc: u16) -> Result<(), Halt> {
        let fpca = self.control & 0b100 != 0;
        let thread = self.ipsr == 0;
        let on_psp = thread && self.control & 0b10 != 0;
        let frame_size: u32 = if fpca { 0x68 } else { 0x20 };
        let sp = self.r[13];
        let force_align = self.scs.ccr & CCR_STKALIGN != 0 && sp & 4 != 0;
        let align_mask = if self.scs.ccr & CCR_STKALIGN != 0 {
            !7
        } else {
            !3
        };
        let frame = sp.wrapping_sub(frame_size) & align_mask;
        let xpsr = self.xpsr() | (force_align as u32) << 9;
        let words = [
            self.r[0], self.r[1], self.r[2], self.r[3], self.r[12], self.r[14], self.pc, xpsr,
        ];
        let pc = self.pc;
        let halt = move |trap: Trap| match trap {
            Trap::Halt(halt) => halt,
            other => Halt::Lockup {
                pc,
                reason: format!("exception entry failed: {other:?}"),
            },
        };
        for (i, word) in words.iter().enumerate() {
            self.store_stack(bus, frame + 4 * i as u32, *word)
                .map_err(halt)?;
        }
        if fpca {
            if self.scs.fpccr & FPCCR_LSPEN != 0 {
                self.scs.fpccr |= FPCCR_LSPACT;
                self.scs.fpcar = frame + 0x20;
            } else {
                for i in 0..16 {
                    let value = self.s[i];
                    self.store_stack(bus, frame + 0x20 + 4 * i as u32, value)
                        .map_err(halt)?;
                }
                let fpscr = self.fpscr;
                self.store_stack(bus, frame + 0x60, fpscr).map_err(halt)?;
            }
        }
        self.r[13] = frame;
        self.r[14] =
            0xFFFF_FFE1 | (!fpca as u32) << 4 | (thread as u32) << 3 | (on_psp as u32) << 2;
        if on_psp {
            std::mem::swap(&mut self.r[13], &mut self.other_sp);
        }
        let vector_address = self.scs.vtor.wrapping_add(4 * exc as u32);
        let vector = match bus.read(vector_address, Size::Word, self.cycles) {
            Ok(vector) => vector,
            Err(e) => {
                return Err(Halt::Lockup {
                    pc: self.pc,
                    reason: format!(
                        "vector {exc} at {vector_address:#010x} cannot be read ({e:?})"
                    ),
                })
            }
        };
        self.pc = vector & !1;
        self.thumb = vector & 1 != 0;
        self.ipsr = exc;
        self.it = 0;
        self.control &= !0b100;
        self.scs.set_pending(exc, false);
        self.scs.set_active(exc, true);
        self.event = true;
        self.exclusive = None;
        self.cycles += 12;
        self.scs.check_pending = true;
        Ok(())
    }

    /// Exception return (B1.5.8), from BX, POP or LDR of an EXC_RETURN value in handler
    /// mode.
    pub(super) fn exception_return<B: Bus>(
        &mut self,
        bus: &mut B,
        exc_return: u32,
    ) -> Result<(), Trap> {
        let returning = self.ipsr;
        let to_thread = match exc_return & 0xF {
            0b0001 => false,
            0b1001 | 0b1101 => true,
            _ => return Err(Fault::InvalidPc.into()),
        };
        if exc_return & 0x0FFF_FFE0 != 0x0FFF_FFE0 || !self.scs.is_active(returning) {
            return Err(Fault::InvalidPc.into());
        }
        let others = self.scs.nested_activations() - 1;
        if (to_thread && others > 0 && self.scs.ccr & CCR_NONBASETHRDENA == 0)
            || (!to_thread && others == 0)
        {
            return Err(Fault::InvalidPc.into());
        }
        let use_psp = exc_return & 0xF == 0b1101;
        let frame = if use_psp { self.other_sp } else { self.r[13] };
        let mut words = [0u32; 8];
        for (i, word) in words.iter_mut().enumerate() {
            *word = self.load_aligned(bus, frame + 4 * i as u32)?;
        }
        let fp_frame = exc_return & 0x10 == 0;
        if fp_frame {
            if self.scs.fpccr & FPCCR_LSPACT != 0 {
                // The context was never written: the registers still hold it.
                self.scs.fpccr &= !FPCCR_LSPACT;
            } else {
                for i in 0..16 {
                    self.s[i] = self.load_aligned(bus, frame + 0x20 + 4 * i as u32)?;
                }
                self.fpscr = self.load_aligned(bus, frame + 0x60)? & super::FPSCR_MASK;
            }
        }
        let psr = words[7];
        let popped_ipsr = (psr & 0x1FF) as u16;
        if to_thread == (popped_ipsr != 0) {
            return Err(Fault::InvalidPc.into());
        }
        self.scs.set_active(returning, false);
        if returning != NMI {
            self.faultmask = false;
        }
        let size = if fp_frame { 0x68 } else { 0x20 } + if psr & (1 << 9) != 0 { 4 } else { 0 };
        let new_sp = frame.wrapping_add(size);
        self.r[..4].copy_from_slice(&words[..4]);
        self.r[12] = words[4];
        self.r[14] = words[5];
        self.next = words[6] & !1;
        self.set_xpsr(psr);
        self.control = (self.control & !0b110) | if fp_frame { 0b100 } else { 0 };
        if to_thread {
            self.control |= (use_psp as u8) << 1;
        }
        if use_psp {
            self.other_sp = self.r[13];
            self.r[13] = new_sp & !3;
        } else {
            self.r[13] = new_sp & !3;
        }
        self.event = true;
        self.exclusive = None;
        self.cycles += 10;
        self.scs.check_pending = true;
        self.yield_request = true;
        Err(Trap::Returned)
    }

    fn privileged(&self) -> bool {
        self.ipsr != 0 || self.control & 1 == 0
    }

    /// The stack pointers as (MSP, PSP).
    fn stack_pointers(&self) -> (u32, u32) {
        if self.ipsr == 0 && self.control & 0b10 != 0 {
            (self.other_sp, self.r[13])
        } else {
            (self.r[13], self.other_sp)
        }
    }

    /// MRS.
    pub(super) fn read_special(&self, sysm: u8) -> u32 {
        let xpsr = self.xpsr();
        match sysm {
            0..=7 => {
                let mut value = 0;
                if sysm & 1 != 0 {
                    value |= xpsr & 0x1FF;
                }
                if sysm & 4 == 0 {
                    value |= xpsr & 0xF80F_0000;
                }
                value
            }
            8 => self.stack_pointers().0,
            9 => self.stack_pointers().1,
            16 => self.primask as u32,
            17 | 18 => self.basepri as u32,
            19 => self.faultmask as u32,
            20 => self.control as u32,
            _ => 0,
        }
    }

    /// A special register as a debugger reads it (MRS's numbering: 8 MSP, 9 PSP, 16
    /// PRIMASK, 17 BASEPRI, 19 FAULTMASK, 20 CONTROL).
    pub fn special_register(&self, sysm: u8) -> u32 {
        self.read_special(sysm)
    }

    /// Writes a special register as a debugger does: whatever the core's privilege.
    pub fn set_special_register(&mut self, sysm: u8, value: u32) {
        match sysm {
            16 => self.primask = value & 1 != 0,
            17 => self.basepri = (value & 0xF0) as u8,
            19 => self.faultmask = value & 1 != 0,
            20 => {
                let old_spsel = self.control & 0b10;
                let mut control = value as u8 & 0b111;
                if self.ipsr != 0 {
                    control = (control & !0b10) | old_spsel;
                } else if control & 0b10 != old_spsel {
                    std::mem::swap(&mut self.r[13], &mut self.other_sp);
                }
                self.control = control;
            }
            8 | 9 => {
                let current = (sysm == 9) == (self.ipsr == 0 && self.control & 0b10 != 0);
                if current {
                    self.r[13] = value & !3;
                } else {
                    self.other_sp = value & !3;
                }
            }
            _ => {}
        }
        self.scs.check_pending = true;
    }

    /// MSR.
    pub(super) fn write_special(&mut self, sysm: u8, mask: u8, value: u32) {
        match sysm {
            0..=3 => {
                if mask & 0b10 != 0 {
                    self.n = value >> 31 != 0;
                    self.z = value >> 30 & 1 != 0;
                    self.c = value >> 29 & 1 != 0;
                    self.v = value >> 28 & 1 != 0;
                    self.q = value >> 27 & 1 != 0;
                }
                if mask & 0b01 != 0 {
                    self.ge = (value >> 16 & 0xF) as u8;
                }
            }
            _ if !self.privileged() => {}
            8 => {
                if self.ipsr == 0 && self.control & 0b10 != 0 {
                    self.other_sp = value & !3;
                } else {
                    self.r[13] = value & !3;
                }
            }
            9 => {
                if self.ipsr == 0 && self.control & 0b10 != 0 {
                    self.r[13] = value & !3;
                } else {
                    self.other_sp = value & !3;
                }
            }
            16 => self.primask = value & 1 != 0,
            17 => self.basepri = (value & 0xF0) as u8,
            18 => {
                let v = (value & 0xF0) as u8;
                if v != 0 && (self.basepri == 0 || v < self.basepri) {
                    self.basepri = v;
                }
            }
            19 if self.execution_priority() > -1 => self.faultmask = value & 1 != 0,
            20 => {
                let old_spsel = self.control & 0b10;
                let mut control = (self.control & !0b101) | (value as u8 & 0b101);
                if self.ipsr == 0 {
                    control = (control & !0b10) | (value as u8 & 0b10);
                    if control & 0b10 != old_spsel {
                        std::mem::swap(&mut self.r[13], &mut self.other_sp);
                    }
                }
                self.control = control;
            }
            _ => {}
        }
        self.scs.check_pending = true;
    }

    /// The DWT cycle counter's value.
    fn cyccnt(&self) -> u32 {
        if self.scs.dwt_ctrl & 1 != 0 && self.scs.demcr & (1 << 24) != 0 {
            self.cycles.wrapping_sub(self.scs.dwt_base) as u32
        } else {
            self.scs.dwt_frozen
        }
    }

    fn systick_divisor(&self) -> u64 {
        // CLKSOURCE clear: the STM32's external reference is HCLK/8 (RM0390, 6.2).
        if self.scs.systick_csr & 0b100 != 0 {
            1
        } else {
            8
        }
    }

    fn systick_current(&self) -> u32 {
        match self.scs.systick_next {
            Some(_) => {
                let period = self.scs.systick_rvr as u64 + 1;
                let ticks = (self.cycles - self.scs.systick_epoch) / self.systick_divisor();
                (self.scs.systick_rvr as u64 - ticks % period) as u32
            }
            None => 0,
        }
    }

    fn systick_schedule(&mut self) {
        if self.scs.systick_csr & 1 != 0 && self.scs.systick_rvr != 0 {
            self.scs.systick_epoch = self.cycles;
            self.scs.systick_next =
                Some(self.cycles + (self.scs.systick_rvr as u64 + 1) * self.systick_divisor());
        } else {
            self.scs.systick_next = None;
        }
    }

    /// SysTick's counter reached zero at its scheduled cycle: COUNTFLAG, the interrupt,
    /// the next period.
    pub(super) fn systick_expired(&mut self) {
        let Some(at) = self.scs.systick_next else {
            return;
        };
        self.scs.systick_csr |= 1 << 16;
        if self.scs.systick_csr & 0b10 != 0 {
            self.scs.set_pending(SYSTICK, true);
        }
        let period = (self.scs.systick_rvr as u64 + 1) * self.systick_divisor();
        self.scs.systick_next = Some(at + period);
    }

    /// Reads a register of the system control space.
    pub(super) fn scs_read(&mut self, address: u32, size: Size) -> Result<u32, Trap> {
        let word_address = address & !3;
        let shift = 8 * (address & 3);
        let word = match word_address {
            0xE000_E004 => (IRQS as u32).div_ceil(32) - 1,
            0xE000_E008 => self.scs.actlr,
            0xE000_E010 => {
                let value = self.scs.systick_csr;
                self.scs.systick_csr &= !(1 << 16);
                value
            }
            0xE000_E014 => self.scs.systick_rvr,
            0xE000_E018 => self.systick_current(),
            // SYST_CALIB: no reference clock calibration (NOREF clear, SKEW set, TENMS 0):
            // the STM32's calibration value is 22500 for a 1 ms tick at 180 MHz / 8.
            0xE000_E01C => 0x4000_0000 | (22_500 - 1),
            0xE000_E100..=0xE000_E10C => {
                self.scs.irq_enabled[((word_address - 0xE000_E100) / 4) as usize]
            }
            0xE000_E180..=0xE000_E18C => {
                self.scs.irq_enabled[((word_address - 0xE000_E180) / 4) as usize]
            }
            0xE000_E200..=0xE000_E20C => {
                self.scs.irq_pending[((word_address - 0xE000_E200) / 4) as usize]
            }
            0xE000_E280..=0xE000_E28C => {
                self.scs.irq_pending[((word_address - 0xE000_E280) / 4) as usize]
            }
            0xE000_E300..=0xE000_E30C => {
                self.scs.irq_active[((word_address - 0xE000_E300) / 4) as usize]
            }
            0xE000_E400..=0xE000_E45C => {
                let i = (word_address - 0xE000_E400) as usize;
                u32::from_le_bytes(
                    self.scs.irq_priority[i..i + 4]
                        .try_into()
                        .unwrap_or_default(),
                )
            }
            0xE000_ED00 => 0x410F_C241,
            0xE000_ED04 => self.icsr(),
            0xE000_ED08 => self.scs.vtor,
            0xE000_ED0C => 0xFA05_0000 | self.scs.prigroup << 8,
            0xE000_ED10 => self.scs.scr,
            0xE000_ED14 => self.scs.ccr,
            0xE000_ED18..=0xE000_ED20 => {
                let i = (word_address - 0xE000_ED18) as usize + 4;
                u32::from_le_bytes(self.scs.shpr[i..i + 4].try_into().unwrap_or_default())
            }
            0xE000_ED24 => self.shcsr(),
            0xE000_ED28 => self.scs.cfsr,
            0xE000_ED2C => self.scs.hfsr,
            0xE000_ED30 => 0,
            0xE000_ED34 => self.scs.mmfar,
            0xE000_ED38 => self.scs.bfar,
            0xE000_ED3C => 0,
            0xE000_ED88 => self.scs.cpacr,
            // MPU_TYPE: eight regions; the MPU itself is left disabled by the images.
            0xE000_ED90 => 0x0000_0800,
            0xE000_ED94 => 0,
            // DHCSR: no debugger attached.
            0xE000_EDF0 => 0,
            0xE000_EDFC => self.scs.demcr,
            0xE000_EF34 => self.scs.fpccr,
            0xE000_EF38 => self.scs.fpcar,
            0xE000_EF3C => self.scs.fpdscr,
            0xE000_EF40 => 0x1011_0021,
            0xE000_EF44 => 0x1100_0011,
            0xE000_1000 => self.scs.dwt_ctrl,
            0xE000_1004 => self.cyccnt(),
            // DBGMCU_IDCODE: the STM32F446 (DEV_ID 0x421), revision A.
            0xE004_2000 => 0x1000_6421,
            0xE004_2004..=0xE004_200C => {
                self.scs.dbgmcu[((word_address - 0xE004_2004) / 4) as usize]
            }
            _ => return Err(self.unmodelled_scs(address, false)),
        };
        Ok(match size {
            Size::Word => word,
            Size::Half => (word >> shift) & 0xFFFF,
            Size::Byte => (word >> shift) & 0xFF,
        })
    }

    fn unmodelled_scs(&self, address: u32, write: bool) -> Trap {
        let block = match address {
            0xE000_0000..=0xE000_0FFF => "ITM",
            0xE000_1000..=0xE000_1FFF => "DWT",
            0xE000_2000..=0xE000_2FFF => "FPB",
            0xE000_E000..=0xE000_E0FF => "SCS (SysTick)",
            0xE000_E100..=0xE000_ECFF => "NVIC",
            0xE000_ED00..=0xE000_ED8F => "SCB",
            0xE000_ED90..=0xE000_EDEF => "MPU",
            0xE000_EDF0..=0xE000_EEFF => "debug control",
            0xE000_EF00..=0xE000_EFFF => "SCS (FPU, STIR, IDs)",
            0xE004_0000..=0xE004_0FFF => "TPIU",
            0xE004_2000..=0xE004_2FFF => "DBGMCU",
            _ => "private peripheral bus",
        };
        Trap::Halt(Halt::Unmodelled {
            what: format!("{block} register {address:#010x}"),
            address,
            pc: self.pc,
            write,
        })
    }

    fn icsr(&self) -> u32 {
        let mut value = self.ipsr as u32;
        if let Some((_, exc)) = self.scs.best_pending() {
            value |= (exc as u32) << 12;
        }
        if self.scs.irq_pending.iter().any(|w| *w != 0) {
            value |= 1 << 22;
        }
        if self.scs.nested_activations() <= 1 {
            value |= 1 << 11;
        }
        if self.scs.sys_pending & (1 << PENDSV) != 0 {
            value |= 1 << 28;
        }
        if self.scs.sys_pending & (1 << SYSTICK) != 0 {
            value |= 1 << 26;
        }
        if self.scs.sys_pending & (1 << NMI) != 0 {
            value |= 1 << 31;
        }
        value
    }

    fn shcsr(&self) -> u32 {
        let s = &self.scs;
        let active = |exc: u16| (s.sys_active >> exc & 1) as u32;
        let pending = |exc: u16| (s.sys_pending >> exc & 1) as u32;
        (s.shcsr & 0x7_0000)
            | active(MEM_MANAGE)
            | active(BUS_FAULT) << 1
            | active(USAGE_FAULT) << 3
            | active(SVCALL) << 7
            | active(PENDSV) << 10
            | active(SYSTICK) << 11
            | pending(USAGE_FAULT) << 12
            | pending(MEM_MANAGE) << 13
            | pending(BUS_FAULT) << 14
            | pending(SVCALL) << 15
    }

    /// Writes a register of the system control space.
    pub(super) fn scs_write(&mut self, address: u32, size: Size, value: u32) -> Result<(), Trap> {
        // Byte-wide registers: the NVIC's and the system handlers' priorities.
        if (0xE000_E400..0xE000_E460).contains(&address)
            || (0xE000_ED18..0xE000_ED24).contains(&address)
        {
            let bytes = value.to_le_bytes();
            for (i, byte) in bytes.iter().enumerate().take(size as usize) {
                let at = address as usize + i;
                let priority = byte & 0xF0;
                if at >= 0xE000_ED18 {
                    self.scs.shpr[at - 0xE000_ED18 + 4] = priority;
                } else {
                    self.scs.irq_priority[at - 0xE000_E400] = priority;
                }
            }
            self.scs.check_pending = true;
            return Ok(());
        }
        // CFSR is write-one-to-clear in any width.
        if (0xE000_ED28..0xE000_ED2C).contains(&address) {
            self.scs.cfsr &= !(value << (8 * (address & 3)));
            return Ok(());
        }
        if size != Size::Word {
            if address & !3 == 0xE004_2004 || address & !3 == 0xE000_E010 {
                // Narrow writes to DBGMCU_CR and SYST_CSR: merge into the word.
            } else {
                return Err(self.unmodelled_scs(address, true));
            }
        }
        let word_address = address & !3;
        let value = if size == Size::Word {
            value
        } else {
            let shift = 8 * (address & 3);
            let mask = if size == Size::Half { 0xFFFF } else { 0xFF } << shift;
            let old = self.scs_read(word_address, Size::Word)?;
            (old & !mask) | ((value << shift) & mask)
        };
        let index = |base: u32| ((word_address - base) / 4) as usize;
        match word_address {
            0xE000_E008 => self.scs.actlr = value & 0x307,
            0xE000_E010 => {
                let was = self.scs.systick_csr & 1;
                self.scs.systick_csr = (self.scs.systick_csr & (1 << 16)) | (value & 0b111);
                if value & 1 != was {
                    self.systick_schedule();
                }
            }
            0xE000_E014 => self.scs.systick_rvr = value & 0x00FF_FFFF,
            0xE000_E018 => {
                self.scs.systick_csr &= !(1 << 16);
                self.systick_schedule();
            }
            0xE000_E100..=0xE000_E10C => {
                self.scs.irq_enabled[index(0xE000_E100)] |= value;
                self.scs.check_pending = true;
            }
            0xE000_E180..=0xE000_E18C => self.scs.irq_enabled[index(0xE000_E180)] &= !value,
            0xE000_E200..=0xE000_E20C => {
                self.scs.irq_pending[index(0xE000_E200)] |= value;
                self.scs.check_pending = true;
                if self.scs.scr & SCR_SEVONPEND != 0 {
                    self.event = true;
                }
            }
            0xE000_E280..=0xE000_E28C => self.scs.irq_pending[index(0xE000_E280)] &= !value,
            0xE000_ED04 => {
                if value & (1 << 31) != 0 {
                    self.scs.set_pending(NMI, true);
                }
                if value & (1 << 28) != 0 {
                    self.scs.set_pending(PENDSV, true);
                } else if value & (1 << 27) != 0 {
                    self.scs.set_pending(PENDSV, false);
                }
                if value & (1 << 26) != 0 {
                    self.scs.set_pending(SYSTICK, true);
                } else if value & (1 << 25) != 0 {
                    self.scs.set_pending(SYSTICK, false);
                }
            }
            0xE000_ED08 => self.scs.vtor = value & 0xFFFF_FF80,
            0xE000_ED0C => {
                if value >> 16 == 0x05FA {
                    self.scs.prigroup = value >> 8 & 7;
                    if value & (1 << 2) != 0 {
                        self.scs.reset_requested = true;
                        return Err(Trap::Yield);
                    }
                    self.scs.check_pending = true;
                }
            }
            0xE000_ED10 => self.scs.scr = value & 0b1_0110,
            0xE000_ED14 => self.scs.ccr = value & 0x31B | CCR_STKALIGN & value,
            0xE000_ED24 => self.scs.shcsr = value & 0x7_0000,
            0xE000_ED2C => self.scs.hfsr &= !value,
            0xE000_ED34 => self.scs.mmfar = value,
            0xE000_ED38 => self.scs.bfar = value,
            0xE000_ED88 => self.scs.cpacr = value & 0x00F0_0000,
            // MPU_CTRL: the images leave the MPU off; enabling it would need a model.
            0xE000_ED94 if value & 1 == 0 => {}
            0xE000_EDFC => {
                if value & (1 << 24) != 0 && self.scs.demcr & (1 << 24) == 0 {
                    self.scs.dwt_base = self.cycles.wrapping_sub(self.scs.dwt_frozen as u64);
                }
                self.scs.demcr = value & 0x010F_07F1;
            }
            0xE000_EF00 => {
                let irq = (value & 0x1FF) as usize;
                if irq < IRQS {
                    self.scs.irq_pending[irq / 32] |= 1 << (irq % 32);
                    self.scs.check_pending = true;
                }
            }
            0xE000_EF34 => {
                self.scs.fpccr =
                    (self.scs.fpccr & !0xC000_0000) | (value & 0xC000_0000) | (value & FPCCR_LSPACT)
            }
            0xE000_EF38 => self.scs.fpcar = value & !7,
            0xE000_EF3C => self.scs.fpdscr = value & 0x07C0_0000,
            0xE000_1000 => {
                let counting = self.scs.dwt_ctrl & 1 != 0;
                if counting && value & 1 == 0 {
                    self.scs.dwt_frozen = self.cyccnt();
                } else if !counting && value & 1 != 0 {
                    self.scs.dwt_base = self.cycles.wrapping_sub(self.scs.dwt_frozen as u64);
                }
                self.scs.dwt_ctrl = (self.scs.dwt_ctrl & 0xFFFF_0000) | (value & 0xFFFF);
            }
            0xE000_1004 => {
                self.scs.dwt_frozen = value;
                self.scs.dwt_base = self.cycles.wrapping_sub(value as u64);
            }
            0xE004_2004..=0xE004_200C => self.scs.dbgmcu[index(0xE004_2004)] = value,
            _ => return Err(self.unmodelled_scs(address, true)),
        }
        Ok(())
    }
}
