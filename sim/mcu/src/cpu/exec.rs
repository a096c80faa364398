//! Executing decoded instructions: the integer, DSP and system instructions here, the
//! floating-point ones in [`super::fp`].

use super::alu::*;
use super::op::*;
use super::{Bus, BusError, Cpu, Fault, Halt, Size, Trap};

/// The private peripheral bus, modelled by the core itself.
const PPB: core::ops::Range<u32> = 0xE000_0000..0xE010_0000;

impl Cpu {
    /// Writes a core register from an ALU result; PC takes BranchWritePC (A2.3.1), SP
    /// keeps its bottom two bits clear.
    #[inline]
    fn set(&mut self, rd: u8, value: u32) {
        match rd {
            15 => self.next = value & !1,
            13 => self.r[13] = value & !3,
            _ => self.r[rd as usize] = value,
        }
    }

    /// LoadWritePC / BXWritePC: an interworking branch, or an exception return from
    /// handler mode with an EXC_RETURN value.
    pub(super) fn bx_write_pc<B: Bus>(&mut self, bus: &mut B, value: u32) -> Result<(), Trap> {
        if self.ipsr != 0 && value >> 28 == 0xF {
            return self.exception_return(bus, value);
        }
        self.thumb = value & 1 != 0;
        self.next = value & !1;
        Ok(())
    }

    /// An immediate-offset access's address (the base itself when post-indexed) and the
    /// base plus the offset, which a write-back stores.
    #[inline(always)]
    fn indexed(&self, rn: u8, offset: i32, index: Index) -> (u32, u32) {
        let base = self.r[rn as usize];
        let offset_address = base.wrapping_add(offset as u32);
        let address = if index == Index::Post {
            base
        } else {
            offset_address
        };
        (address, offset_address)
    }

    #[inline]
    fn nz(&mut self, result: u32) {
        self.n = result >> 31 != 0;
        self.z = result == 0;
    }

    /// A data access through the core: the private peripheral bus is the core's own;
    /// unaligned word and halfword accesses are split into bytes (CCR.UNALIGN_TRP clear).
    #[inline]
    pub(super) fn load<B: Bus>(
        &mut self,
        bus: &mut B,
        address: u32,
        size: Size,
    ) -> Result<u32, Trap> {
        if address & (size as u32 - 1) != 0 {
            return self.load_unaligned(bus, address, size);
        }
        if PPB.contains(&address) {
            return self.scs_read(address, size);
        }
        match bus.read(address, size, self.cycles) {
            Ok(value) => Ok(value),
            Err(error) => Err(self.bus_error(error, address, false)),
        }
    }

    #[inline]
    pub(super) fn store<B: Bus>(
        &mut self,
        bus: &mut B,
        address: u32,
        size: Size,
        value: u32,
    ) -> Result<(), Trap> {
        if address & (size as u32 - 1) != 0 {
            return self.store_unaligned(bus, address, size, value);
        }
        if PPB.contains(&address) {
            return self.scs_write(address, size, value);
        }
        match bus.write(address, size, value, self.cycles) {
            Ok(()) => Ok(()),
            Err(error) => Err(self.bus_error(error, address, true)),
        }
    }

    fn bus_error(&mut self, error: BusError, address: u32, write: bool) -> Trap {
        match error {
            BusError::Fault => Trap::Fault(Fault::Data(address)),
            BusError::Unmodelled(what) => Trap::Halt(Halt::Unmodelled {
                what,
                address,
                pc: self.pc,
                write,
            }),
        }
    }

    #[cold]
    fn load_unaligned<B: Bus>(
        &mut self,
        bus: &mut B,
        address: u32,
        size: Size,
    ) -> Result<u32, Trap> {
        if self.scs.ccr & CCR_UNALIGN_TRP != 0 || PPB.contains(&address) {
            return Err(Fault::Unaligned.into());
        }
        let mut value = 0;
        for i in 0..size as u32 {
            value |= self.load(bus, address.wrapping_add(i), Size::Byte)? << (8 * i);
        }
        Ok(value)
    }

    #[cold]
    fn store_unaligned<B: Bus>(
        &mut self,
        bus: &mut B,
        address: u32,
        size: Size,
        value: u32,
    ) -> Result<(), Trap> {
        if self.scs.ccr & CCR_UNALIGN_TRP != 0 || PPB.contains(&address) {
            return Err(Fault::Unaligned.into());
        }
        for i in 0..size as u32 {
            self.store(bus, address.wrapping_add(i), Size::Byte, value >> (8 * i))?;
        }
        Ok(())
    }

    /// A word access that must be aligned (LDM, STM, LDRD, STRD, LDREX, STREX, VLDR…).
    #[inline]
    pub(super) fn load_aligned<B: Bus>(&mut self, bus: &mut B, address: u32) -> Result<u32, Trap> {
        if address & 3 != 0 {
            return Err(Fault::Unaligned.into());
        }
        self.load(bus, address, Size::Word)
    }

    #[inline]
    pub(super) fn store_aligned<B: Bus>(
        &mut self,
        bus: &mut B,
        address: u32,
        value: u32,
    ) -> Result<(), Trap> {
        if address & 3 != 0 {
            return Err(Fault::Unaligned.into());
        }
        self.store(bus, address, Size::Word, value)
    }

    fn load_width<B: Bus>(&mut self, bus: &mut B, address: u32, width: Width) -> Result<u32, Trap> {
        Ok(match width {
            Width::Byte => self.load(bus, address, Size::Byte)?,
            Width::SignedByte => self.load(bus, address, Size::Byte)? as u8 as i8 as u32,
            Width::Half => self.load(bus, address, Size::Half)?,
            Width::SignedHalf => self.load(bus, address, Size::Half)? as u16 as i16 as u32,
            Width::Word => self.load(bus, address, Size::Word)?,
        })
    }

    fn store_width<B: Bus>(
        &mut self,
        bus: &mut B,
        address: u32,
        width: Width,
        value: u32,
    ) -> Result<(), Trap> {
        match width {
            Width::Byte | Width::SignedByte => self.store(bus, address, Size::Byte, value),
            Width::Half | Width::SignedHalf => self.store(bus, address, Size::Half, value),
            Width::Word => self.store(bus, address, Size::Word, value),
        }
    }

    /// Writes a loaded value to Rt: PC takes LoadWritePC.
    fn load_to<B: Bus>(&mut self, bus: &mut B, rt: u8, value: u32) -> Result<(), Trap> {
        if rt == 15 {
            self.cycles += 2;
            self.bx_write_pc(bus, value)
        } else {
            self.set(rt, value);
            Ok(())
        }
    }

    /// Executes one decoded instruction. `in_it`: inside an IT block. The instructions a
    /// firmware runs most (data processing, loads and stores with an immediate offset,
    /// branches, IT) are handled here, inlined into the core's loop; the rest in
    /// [`Cpu::execute_other`], a call of its own, so that their code does not burden
    /// every instruction's.
    #[inline(always)]
    pub(super) fn execute<B: Bus>(&mut self, bus: &mut B, op: Op, in_it: bool) -> Result<(), Trap> {
        match op {
            Op::AluImm {
                op,
                s,
                rd,
                rn,
                imm,
                carry,
            } => {
                let s = flags(s, in_it);
                let carry = match carry {
                    ImmCarry::Keep => self.c,
                    ImmCarry::Set(c) => c,
                };
                let a = self.r[rn as usize];
                self.alu(op, s, rd, a, imm, carry);
            }
            Op::AluReg {
                op,
                s,
                rd,
                rn,
                rm,
                shift,
                amount,
            } => {
                let s = flags(s, in_it);
                let (b, carry) = shift_c(self.r[rm as usize], shift, amount as u32, self.c);
                let a = self.r[rn as usize];
                self.alu(op, s, rd, a, b, carry);
            }
            Op::Branch { cond, target } => {
                if cond == 14 || self.condition(cond) {
                    self.next = target;
                    self.cycles += 2;
                }
            }
            Op::CompareBranch {
                nonzero,
                rn,
                target,
            } => {
                if (self.r[rn as usize] != 0) == nonzero {
                    self.next = target;
                    self.cycles += 2;
                }
            }
            Op::It { state } => self.it = state,
            Op::LoadStoreImm {
                load,
                width,
                rt,
                rn,
                offset,
                index,
            } => {
                let (address, offset_address) = self.indexed(rn, offset, index);
                self.cycles += 1;
                if load {
                    let value = self.load_width(bus, address, width)?;
                    if index != Index::Offset {
                        self.set(rn, offset_address);
                    }
                    self.load_to(bus, rt, value)?;
                } else {
                    self.store_width(bus, address, width, self.r[rt as usize])?;
                    if index != Index::Offset {
                        self.set(rn, offset_address);
                    }
                }
            }
            Op::LoadStoreReg {
                load,
                width,
                rt,
                rn,
                rm,
                shift,
            } => {
                let address = self.r[rn as usize].wrapping_add(self.r[rm as usize] << shift);
                self.cycles += 1;
                if load {
                    let value = self.load_width(bus, address, width)?;
                    self.load_to(bus, rt, value)?;
                } else {
                    self.store_width(bus, address, width, self.r[rt as usize])?;
                }
            }
            Op::BranchLink { target } => {
                self.r[14] = self.next | 1;
                self.next = target;
                self.cycles += 2;
            }
            Op::BranchExchange { rm, link } => {
                let target = self.r[rm as usize];
                if link {
                    self.r[14] = self.next | 1;
                }
                self.cycles += 2;
                self.bx_write_pc(bus, target)?;
            }
            other => return self.execute_other(bus, other, in_it),
        }
        Ok(())
    }

    /// [`Cpu::execute`] for the instructions it does not handle itself.
    #[inline(never)]
    fn execute_other<B: Bus>(&mut self, bus: &mut B, op: Op, in_it: bool) -> Result<(), Trap> {
        match op {
            hot @ (Op::AluImm { .. }
            | Op::AluReg { .. }
            | Op::Branch { .. }
            | Op::CompareBranch { .. }
            | Op::It { .. }
            | Op::LoadStoreImm { .. }
            | Op::LoadStoreReg { .. }
            | Op::BranchLink { .. }
            | Op::BranchExchange { .. }) => return self.execute(bus, hot, in_it),
            Op::ShiftReg {
                s,
                rd,
                rn,
                rm,
                shift,
            } => {
                let s = flags(s, in_it);
                let amount = self.r[rm as usize] & 0xFF;
                let (result, carry) = shift_c(self.r[rn as usize], shift, amount, self.c);
                self.r[rd as usize] = result;
                if s {
                    self.nz(result);
                    self.c = carry;
                }
            }
            Op::Movt { rd, imm } => {
                let r = &mut self.r[rd as usize];
                *r = (*r & 0xFFFF) | (imm as u32) << 16;
            }
            Op::Mul {
                s,
                rd,
                rn,
                rm,
                ra,
                sub,
            } => {
                let product = self.r[rn as usize].wrapping_mul(self.r[rm as usize]);
                let result = if ra == 15 {
                    product
                } else {
                    self.cycles += 1;
                    let acc = self.r[ra as usize];
                    if sub {
                        acc.wrapping_sub(product)
                    } else {
                        acc.wrapping_add(product)
                    }
                };
                self.r[rd as usize] = result;
                if flags(s, in_it) {
                    self.nz(result);
                }
            }
            Op::LongMul {
                kind,
                rdlo,
                rdhi,
                rn,
                rm,
            } => {
                let (n, m) = (self.r[rn as usize], self.r[rm as usize]);
                let (lo, hi) = (self.r[rdlo as usize], self.r[rdhi as usize]);
                let acc = (hi as u64) << 32 | lo as u64;
                let result = match kind {
                    LongMul::Umull => n as u64 * m as u64,
                    LongMul::Smull => (n as i32 as i64 * m as i32 as i64) as u64,
                    LongMul::Umlal => (n as u64 * m as u64).wrapping_add(acc),
                    LongMul::Smlal => {
                        ((n as i32 as i64 * m as i32 as i64) as u64).wrapping_add(acc)
                    }
                    LongMul::Umaal => n as u64 * m as u64 + lo as u64 + hi as u64,
                };
                self.r[rdlo as usize] = result as u32;
                self.r[rdhi as usize] = (result >> 32) as u32;
            }
            Op::Div { signed, rd, rn, rm } => {
                let (n, m) = (self.r[rn as usize], self.r[rm as usize]);
                if m == 0 {
                    if self.scs.ccr & CCR_DIV_0_TRP != 0 {
                        return Err(Fault::DivideByZero.into());
                    }
                    self.r[rd as usize] = 0;
                } else {
                    // 2–12 cycles on the Cortex-M4, by the quotient's significant bits.
                    let q = if signed {
                        (n as i32).wrapping_div(m as i32) as u32
                    } else {
                        n / m
                    };
                    let bits =
                        32 - if signed { (q as i32).unsigned_abs() } else { q }.leading_zeros();
                    self.cycles += 1 + bits as u64 / 3;
                    self.r[rd as usize] = q;
                }
            }
            Op::Unary { op, rd, rm } => {
                let m = self.r[rm as usize];
                self.r[rd as usize] = match op {
                    Unary::Clz => m.leading_zeros(),
                    Unary::Rbit => m.reverse_bits(),
                    Unary::Rev => m.swap_bytes(),
                    Unary::Rev16 => ((m & 0x00FF_00FF) << 8) | ((m >> 8) & 0x00FF_00FF),
                    Unary::Revsh => (m as u16).swap_bytes() as i16 as u32,
                };
            }
            Op::Extend {
                op,
                rd,
                rn,
                rm,
                rot,
            } => {
                let m = self.r[rm as usize].rotate_right(rot as u32);
                let add = if rn == 15 { 0 } else { self.r[rn as usize] };
                self.r[rd as usize] = match op {
                    Extend::Sxtb => add.wrapping_add(m as u8 as i8 as u32),
                    Extend::Uxtb => add.wrapping_add(m & 0xFF),
                    Extend::Sxth => add.wrapping_add(m as u16 as i16 as u32),
                    Extend::Uxth => add.wrapping_add(m & 0xFFFF),
                    Extend::Sxtb16 => {
                        let lo = (add as u16).wrapping_add(m as u8 as i8 as u16);
                        let hi = ((add >> 16) as u16).wrapping_add((m >> 16) as u8 as i8 as u16);
                        (hi as u32) << 16 | lo as u32
                    }
                    Extend::Uxtb16 => {
                        let lo = (add as u16).wrapping_add(m as u8 as u16);
                        let hi = ((add >> 16) as u16).wrapping_add((m >> 16) as u8 as u16);
                        (hi as u32) << 16 | lo as u32
                    }
                };
            }
            Op::BitField {
                op,
                rd,
                rn,
                lsb,
                width,
            } => {
                let mask = if width == 32 {
                    u32::MAX
                } else {
                    (1u32 << width) - 1
                };
                let (lsb, width) = (lsb as u32, width as u32);
                self.r[rd as usize] = match op {
                    BitField::Insert => {
                        let src = if rn == 15 { 0 } else { self.r[rn as usize] };
                        (self.r[rd as usize] & !(mask << lsb)) | ((src & mask) << lsb)
                    }
                    BitField::Ubfx => (self.r[rn as usize] >> lsb) & mask,
                    BitField::Sbfx => {
                        let field = (self.r[rn as usize] >> lsb) & mask;
                        (((field << (32 - width)) as i32) >> (32 - width)) as u32
                    }
                };
            }
            Op::Saturate {
                signed,
                rd,
                rn,
                bits,
                shift,
                amount,
            } => {
                let (operand, _) = shift_c(self.r[rn as usize], shift, amount as u32, self.c);
                let (result, sat) = if signed {
                    signed_sat(operand as i32 as i64, bits as u32)
                } else {
                    unsigned_sat(operand as i32 as i64, bits as u32)
                };
                self.r[rd as usize] = result;
                self.q |= sat;
            }
            Op::Saturate16 {
                signed,
                rd,
                rn,
                bits,
            } => {
                let n = self.r[rn as usize];
                let mut result = 0;
                for lane in 0..2 {
                    let (v, sat) = if signed {
                        signed_sat(half_s(n, lane) as i64, bits as u32)
                    } else {
                        unsigned_sat(half_s(n, lane) as i64, bits as u32)
                    };
                    result |= (v & 0xFFFF) << (16 * lane);
                    self.q |= sat;
                }
                self.r[rd as usize] = result;
            }
            Op::SatArith { op, rd, rn, rm } => {
                let m = self.r[rm as usize] as i32 as i64;
                let n = self.r[rn as usize] as i32 as i64;
                let (result, sat) = match op {
                    SatArith::Qadd => signed_sat(m + n, 32),
                    SatArith::Qsub => signed_sat(m - n, 32),
                    SatArith::Qdadd | SatArith::Qdsub => {
                        let (doubled, sat1) = signed_sat(2 * n, 32);
                        let doubled = doubled as i32 as i64;
                        let (r, sat2) = if op == SatArith::Qdadd {
                            signed_sat(m + doubled, 32)
                        } else {
                            signed_sat(m - doubled, 32)
                        };
                        (r, sat1 || sat2)
                    }
                };
                self.r[rd as usize] = result;
                self.q |= sat;
            }
            Op::Parallel {
                lanes,
                op,
                rd,
                rn,
                rm,
            } => {
                let result = self.parallel(lanes, op, self.r[rn as usize], self.r[rm as usize]);
                self.r[rd as usize] = result;
            }
            Op::Sel { rd, rn, rm } => {
                let (n, m) = (self.r[rn as usize], self.r[rm as usize]);
                let mut result = 0;
                for i in 0..4 {
                    let from = if self.ge >> i & 1 != 0 { n } else { m };
                    result |= from & (0xFF << (8 * i));
                }
                self.r[rd as usize] = result;
            }
            Op::Usad8 { rd, rn, rm, ra } => {
                let (n, m) = (self.r[rn as usize], self.r[rm as usize]);
                let mut sum = if ra == 15 { 0 } else { self.r[ra as usize] };
                for i in 0..4 {
                    sum = sum.wrapping_add((byte_u(n, i) - byte_u(m, i)).unsigned_abs());
                }
                self.r[rd as usize] = sum;
            }
            Op::Pack {
                tb,
                rd,
                rn,
                rm,
                amount,
            } => {
                let (n, m) = (self.r[rn as usize], self.r[rm as usize]);
                self.r[rd as usize] = if tb {
                    let (shifted, _) = shift_c(m, Shift::Asr, amount as u32, false);
                    (n & 0xFFFF_0000) | (shifted & 0xFFFF)
                } else {
                    let shifted = m << amount;
                    (shifted & 0xFFFF_0000) | (n & 0xFFFF)
                };
            }
            Op::DspMul {
                op,
                rd,
                rn,
                rm,
                ra,
                n_top,
                m_top,
                round,
            } => self.dsp_mul(op, rd, rn, rm, ra, n_top, m_top, round),
            Op::DspLong {
                op,
                rdlo,
                rdhi,
                rn,
                rm,
                n_top,
                m_top,
            } => {
                let (n, m) = (self.r[rn as usize], self.r[rm as usize]);
                let acc =
                    ((self.r[rdhi as usize] as u64) << 32 | self.r[rdlo as usize] as u64) as i64;
                let m = if m_top && op != DspLong::Halves {
                    m.rotate_right(16)
                } else {
                    m
                };
                let add = match op {
                    DspLong::Halves => {
                        half_s(n, n_top as u32) as i64 * half_s(m, m_top as u32) as i64
                    }
                    DspLong::DualAdd => {
                        half_s(n, 0) as i64 * half_s(m, 0) as i64
                            + half_s(n, 1) as i64 * half_s(m, 1) as i64
                    }
                    DspLong::DualSub => {
                        half_s(n, 0) as i64 * half_s(m, 0) as i64
                            - half_s(n, 1) as i64 * half_s(m, 1) as i64
                    }
                };
                let result = acc.wrapping_add(add) as u64;
                self.r[rdlo as usize] = result as u32;
                self.r[rdhi as usize] = (result >> 32) as u32;
            }
            Op::TableBranch { half, rn, rm } => {
                let base = self.r[rn as usize];
                let index = self.r[rm as usize];
                let offset = if half {
                    self.load(bus, base.wrapping_add(index << 1), Size::Half)?
                } else {
                    self.load(bus, base.wrapping_add(index), Size::Byte)?
                };
                self.next = self.r[15].wrapping_add(offset << 1);
                self.cycles += 3;
            }
            Op::LoadLiteral { width, rt, address } => {
                self.cycles += 1;
                let value = self.load_width(bus, address, width)?;
                self.load_to(bus, rt, value)?;
            }
            Op::LoadStoreDual {
                load,
                rt,
                rt2,
                rn,
                offset,
                index,
            } => {
                let (address, writeback) = if rn == 15 {
                    (offset as u32, None)
                } else {
                    let (address, offset_address) = self.indexed(rn, offset, index);
                    (address, (index != Index::Offset).then_some(offset_address))
                };
                self.cycles += 2;
                if load {
                    let first = self.load_aligned(bus, address)?;
                    let second = self.load_aligned(bus, address.wrapping_add(4))?;
                    self.r[rt as usize] = first;
                    self.r[rt2 as usize] = second;
                } else {
                    self.store_aligned(bus, address, self.r[rt as usize])?;
                    self.store_aligned(bus, address.wrapping_add(4), self.r[rt2 as usize])?;
                }
                if let Some(value) = writeback {
                    self.set(rn, value);
                }
            }
            Op::Multiple {
                load,
                rn,
                list,
                writeback,
                decrement,
            } => self.multiple(bus, load, rn, list, writeback, decrement)?,
            Op::LoadExclusive {
                width,
                rt,
                rn,
                offset,
            } => {
                let (address, size) = self.exclusive_address(rn, offset, width)?;
                let value = self.load(bus, address, size)?;
                self.exclusive = Some(address);
                self.r[rt as usize] = value;
            }
            Op::StoreExclusive {
                width,
                rd,
                rt,
                rn,
                offset,
            } => {
                let (address, size) = self.exclusive_address(rn, offset, width)?;
                if self.exclusive == Some(address) {
                    self.store(bus, address, size, self.r[rt as usize])?;
                    self.r[rd as usize] = 0;
                } else {
                    self.r[rd as usize] = 1;
                }
                self.exclusive = None;
            }
            Op::ClearExclusive => self.exclusive = None,
            Op::Nop | Op::Isb => {}
            Op::Mrs { rd, sysm } => self.r[rd as usize] = self.read_special(sysm),
            Op::Msr { rn, sysm, mask } => self.write_special(sysm, mask, self.r[rn as usize]),
            Op::Cps { disable, i, f } => {
                if self.ipsr != 0 || self.control & 1 == 0 {
                    if i {
                        self.primask = disable;
                    }
                    // FAULTMASK cannot be set at priority -1 or above (in HardFault, NMI).
                    if f && (!disable || self.execution_priority() > -1) {
                        self.faultmask = disable;
                    }
                    self.scs.check_pending = true;
                }
            }
            Op::Wfe => {
                if self.event {
                    self.event = false;
                } else {
                    self.sleep = Some(false);
                    self.pc = self.next;
                    return Err(Trap::Sleep);
                }
            }
            Op::Wfi => {
                if !self.exception_would_wake() {
                    self.sleep = Some(true);
                    self.pc = self.next;
                    return Err(Trap::Sleep);
                }
            }
            Op::Sev => self.event = true,
            Op::Svc => self.svc(),
            Op::Bkpt { imm } if self.debugger_attached => {
                return Err(Trap::Halt(Halt::Breakpoint { imm, pc: self.pc }))
            }
            Op::Bkpt { .. } => return Err(Fault::Breakpoint.into()),
            Op::Undefined | Op::Unpredictable => return Err(Fault::Undefined.into()),
            Op::NoCoprocessor => return Err(Fault::NoCoprocessor.into()),
            fp => self.execute_fp(bus, fp)?,
        }
        Ok(())
    }

    #[inline(always)]
    fn alu(&mut self, op: Alu, s: bool, rd: u8, a: u32, b: u32, shifter_carry: bool) {
        let (result, arithmetic) = match op {
            Alu::And | Alu::Tst => (a & b, None),
            Alu::Bic => (a & !b, None),
            Alu::Orr => (a | b, None),
            Alu::Orn => (a | !b, None),
            Alu::Eor | Alu::Teq => (a ^ b, None),
            Alu::Mov => (b, None),
            Alu::Mvn => (!b, None),
            Alu::Add | Alu::Cmn => {
                if !s {
                    (a.wrapping_add(b), None)
                } else {
                    let (r, c, v) = add_with_carry(a, b, false);
                    (r, Some((c, v)))
                }
            }
            Alu::Adc => {
                let (r, c, v) = add_with_carry(a, b, self.c);
                (r, Some((c, v)))
            }
            Alu::Sub | Alu::Cmp => {
                if !s {
                    (a.wrapping_sub(b), None)
                } else {
                    let (r, c, v) = add_with_carry(a, !b, true);
                    (r, Some((c, v)))
                }
            }
            Alu::Sbc => {
                let (r, c, v) = add_with_carry(a, !b, self.c);
                (r, Some((c, v)))
            }
            Alu::Rsb => {
                let (r, c, v) = add_with_carry(!a, b, true);
                (r, Some((c, v)))
            }
        };
        if !matches!(op, Alu::Tst | Alu::Teq | Alu::Cmp | Alu::Cmn) {
            self.set(rd, result);
        }
        if s {
            self.nz(result);
            match arithmetic {
                Some((c, v)) => {
                    self.c = c;
                    self.v = v;
                }
                None => {
                    if matches!(op, Alu::Add | Alu::Sub | Alu::Cmn | Alu::Cmp) {
                        unreachable!("arithmetic with flags computes them")
                    }
                    self.c = shifter_carry;
                }
            }
        }
    }

    fn parallel(&mut self, lanes: Lanes, op: LaneOp, n: u32, m: u32) -> u32 {
        let byte_lanes = matches!(op, LaneOp::Add8 | LaneOp::Sub8);
        let signed = matches!(
            lanes,
            Lanes::Signed | Lanes::SignedSat | Lanes::SignedHalving
        );
        let (count, width) = if byte_lanes { (4, 8) } else { (2, 16) };
        let lane = |x: u32, i: u32| -> i64 {
            match (byte_lanes, signed) {
                (true, true) => byte_s(x, i) as i64,
                (true, false) => byte_u(x, i) as i64,
                (false, true) => half_s(x, i) as i64,
                (false, false) => half_u(x, i) as i64,
            }
        };
        let mut result = 0u32;
        let mut ge = 0u8;
        for i in 0..count {
            let a = lane(n, i);
            let sum = match op {
                LaneOp::Add16 | LaneOp::Add8 => a + lane(m, i),
                LaneOp::Sub16 | LaneOp::Sub8 => a - lane(m, i),
                // ASX: low lane n.lo - m.hi, high lane n.hi + m.lo.
                LaneOp::Asx => {
                    if i == 0 {
                        a - lane(m, 1)
                    } else {
                        a + lane(m, 0)
                    }
                }
                // SAX: low lane n.lo + m.hi, high lane n.hi - m.lo.
                LaneOp::Sax => {
                    if i == 0 {
                        a + lane(m, 1)
                    } else {
                        a - lane(m, 0)
                    }
                }
            };
            let value = match lanes {
                Lanes::Signed | Lanes::Unsigned => sum as u32,
                Lanes::SignedSat => signed_sat(sum, width).0,
                Lanes::UnsignedSat => unsigned_sat(sum, width).0,
                Lanes::SignedHalving | Lanes::UnsignedHalving => (sum >> 1) as u32,
            };
            let mask = (1u32 << width) - 1;
            result |= (value & mask) << (width * i);
            let lane_ge = match lanes {
                Lanes::Signed => sum >= 0,
                Lanes::Unsigned => match op {
                    LaneOp::Add16 | LaneOp::Add8 => sum >= 1 << width,
                    LaneOp::Sub16 | LaneOp::Sub8 => sum >= 0,
                    LaneOp::Asx | LaneOp::Sax => {
                        let adds = (op == LaneOp::Asx) == (i == 1);
                        if adds {
                            sum >= 1 << width
                        } else {
                            sum >= 0
                        }
                    }
                },
                _ => false,
            };
            if lane_ge {
                ge |= if byte_lanes { 1 << i } else { 0b11 << (2 * i) };
            }
        }
        if matches!(lanes, Lanes::Signed | Lanes::Unsigned) {
            self.ge = ge;
        }
        result
    }

    #[allow(clippy::too_many_arguments)]
    fn dsp_mul(
        &mut self,
        op: DspMul,
        rd: u8,
        rn: u8,
        rm: u8,
        ra: u8,
        n_top: bool,
        m_top: bool,
        round: bool,
    ) {
        let (n, m) = (self.r[rn as usize], self.r[rm as usize]);
        let acc = if ra == 15 {
            None
        } else {
            Some(self.r[ra as usize])
        };
        let result = match op {
            DspMul::Halves => {
                let product = half_s(n, n_top as u32) as i64 * half_s(m, m_top as u32) as i64;
                self.accumulate_q(product, acc)
            }
            DspMul::Wide => {
                let product = (n as i32 as i64 * half_s(m, m_top as u32) as i64) >> 16;
                self.accumulate_q(product, acc)
            }
            DspMul::DualAdd | DspMul::DualSub => {
                let m = if m_top { m.rotate_right(16) } else { m };
                let p1 = half_s(n, 0) as i64 * half_s(m, 0) as i64;
                let p2 = half_s(n, 1) as i64 * half_s(m, 1) as i64;
                let sum = if op == DspMul::DualAdd {
                    p1 + p2
                } else {
                    p1 - p2
                };
                self.accumulate_q(sum, acc)
            }
            DspMul::MostAdd | DspMul::MostSub => {
                let product = n as i32 as i64 * m as i32 as i64;
                let acc = (acc.unwrap_or(0) as i64) << 32;
                let mut value = if op == DspMul::MostAdd {
                    acc.wrapping_add(product)
                } else {
                    acc.wrapping_sub(product)
                };
                if round {
                    value = value.wrapping_add(0x8000_0000);
                }
                (value >> 32) as u32
            }
        };
        self.r[rd as usize] = result;
    }

    /// The 32-bit result of a DSP multiply with an optional accumulator: Q is set if the
    /// result does not fit in 32 signed bits (the result wraps, as the manual says).
    fn accumulate_q(&mut self, value: i64, acc: Option<u32>) -> u32 {
        let total = value + acc.map_or(0, |a| a as i32 as i64);
        if total != total as i32 as i64 {
            self.q = true;
        }
        total as u32
    }

    /// An exclusive access's address and size; it must be aligned to its size.
    fn exclusive_address(
        &mut self,
        rn: u8,
        offset: u32,
        width: Width,
    ) -> Result<(u32, Size), Trap> {
        let address = self.r[rn as usize].wrapping_add(offset);
        let size = exclusive_size(width);
        if address & (size as u32 - 1) != 0 {
            return Err(Fault::Unaligned.into());
        }
        self.cycles += 1;
        Ok((address, size))
    }

    fn multiple<B: Bus>(
        &mut self,
        bus: &mut B,
        load: bool,
        rn: u8,
        list: u16,
        writeback: bool,
        decrement: bool,
    ) -> Result<(), Trap> {
        let count = list.count_ones();
        let base = self.r[rn as usize];
        let start = if decrement {
            base.wrapping_sub(4 * count)
        } else {
            base
        };
        let end = if decrement {
            start
        } else {
            base.wrapping_add(4 * count)
        };
        self.cycles += count as u64;
        let mut address = start;
        if load {
            let mut values = [0u32; 16];
            for (i, slot) in values.iter_mut().enumerate() {
                if list & (1 << i) != 0 {
                    *slot = self.load_aligned(bus, address)?;
                    address = address.wrapping_add(4);
                }
            }
            if writeback {
                self.set(rn, end);
            }
            for (i, value) in values.iter().enumerate().take(15) {
                if list & (1 << i) != 0 {
                    self.set(i as u8, *value);
                }
            }
            if list & 0x8000 != 0 {
                self.cycles += 2;
                self.bx_write_pc(bus, values[15])?;
            }
        } else {
            for i in 0..15 {
                if list & (1 << i) != 0 {
                    let value = self.r[i];
                    self.store_aligned(bus, address, value)?;
                    address = address.wrapping_add(4);
                }
            }
            if writeback {
                self.set(rn, end);
            }
        }
        Ok(())
    }
}

/// Whether a 16-bit instruction's flag setting applies.
#[inline]
fn flags(s: SetFlags, in_it: bool) -> bool {
    match s {
        SetFlags::Never => false,
        SetFlags::Always => true,
        SetFlags::OutsideIt => !in_it,
    }
}

fn exclusive_size(width: Width) -> Size {
    match width {
        Width::Byte | Width::SignedByte => Size::Byte,
        Width::Half | Width::SignedHalf => Size::Half,
        Width::Word => Size::Word,
    }
}

/// CCR.UNALIGN_TRP: unaligned word and halfword accesses fault.
pub(super) const CCR_UNALIGN_TRP: u32 = 1 << 3;
/// CCR.DIV_0_TRP: division by zero faults.
pub(super) const CCR_DIV_0_TRP: u32 = 1 << 4;
