//! Thumb-2 instruction encoders: the fields of each encoding in the ARMv7-M Architecture
//! Reference Manual (DDI 0403E), section A7 (integer) and A7.7 (floating point), put in
//! place. They check only what the fields can hold; whether a combination is defined is
//! the caller's business (the generator in [`super::blocks`] says which rules it keeps).
//!
//! A 32-bit instruction is two halfwords, the first (`hw1`) at the lower address; each
//! halfword is stored little-endian.

/// One instruction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Insn {
    /// A 16-bit instruction.
    Narrow(u16),
    /// A 32-bit instruction: the first halfword, then the second.
    Wide(u16, u16),
}

impl Insn {
    /// Its size in bytes.
    pub fn len(self) -> usize {
        match self {
            Insn::Narrow(_) => 2,
            Insn::Wide(..) => 4,
        }
    }

    /// Always false: an instruction has at least one halfword.
    pub fn is_empty(self) -> bool {
        false
    }

    /// Its bytes in memory order.
    pub fn bytes(self) -> Vec<u8> {
        match self {
            Insn::Narrow(h) => h.to_le_bytes().to_vec(),
            Insn::Wide(a, b) => {
                let mut v = a.to_le_bytes().to_vec();
                v.extend_from_slice(&b.to_le_bytes());
                v
            }
        }
    }
}

fn r(reg: u8) -> u16 {
    debug_assert!(reg < 16);
    u16::from(reg & 15)
}

fn lo(reg: u8) -> u16 {
    debug_assert!(reg < 8, "r{reg} is not a low register");
    u16::from(reg & 7)
}

// ---------------------------------------------------------------------------------------
// 16-bit data processing (A5.2.1, A5.2.2, A5.2.3).

/// LSL/LSR/ASR (immediate) T1: `op` 0 LSL, 1 LSR, 2 ASR; `imm5` 0 means 32 for LSR/ASR
/// (and LSL #0 is MOV (register) T2, `MOVS Rd, Rm`).
pub fn shift_imm16(op: u8, rd: u8, rm: u8, imm5: u8) -> Insn {
    Insn::Narrow(u16::from(op) << 11 | u16::from(imm5 & 31) << 6 | lo(rm) << 3 | lo(rd))
}

/// ADD (register) T1 (`sub` false) or SUB (register) T1: `Rd = Rn +/- Rm`.
pub fn add_sub_reg16(sub: bool, rd: u8, rn: u8, rm: u8) -> Insn {
    Insn::Narrow(0x1800 | u16::from(sub) << 9 | lo(rm) << 6 | lo(rn) << 3 | lo(rd))
}

/// ADD (immediate) T1 or SUB (immediate) T1: `Rd = Rn +/- imm3`.
pub fn add_sub_imm3(sub: bool, rd: u8, rn: u8, imm3: u8) -> Insn {
    Insn::Narrow(0x1c00 | u16::from(sub) << 9 | u16::from(imm3 & 7) << 6 | lo(rn) << 3 | lo(rd))
}

/// MOV (immediate) T1 (`op` 0), CMP (immediate) T1 (1), ADD (immediate) T2 (2),
/// SUB (immediate) T2 (3), with an 8-bit immediate.
pub fn imm8_op(op: u8, rdn: u8, imm8: u8) -> Insn {
    Insn::Narrow(0x2000 | u16::from(op & 3) << 11 | lo(rdn) << 8 | u16::from(imm8))
}

/// The 16-bit data-processing (register) group, `010000 op Rm Rdn`: AND EOR LSL LSR ASR
/// ADC SBC ROR TST RSB(#0) CMP CMN ORR MUL BIC MVN for `op` 0..15.
pub fn dp16(op: u8, rdn: u8, rm: u8) -> Insn {
    Insn::Narrow(0x4000 | u16::from(op & 15) << 6 | lo(rm) << 3 | lo(rdn))
}

/// ADD (register) T2, `ADD Rdn, Rm` with any registers (never sets flags).
pub fn add_reg_t2(rdn: u8, rm: u8) -> Insn {
    Insn::Narrow(0x4400 | (r(rdn) & 8) << 4 | r(rm) << 3 | (r(rdn) & 7))
}

/// CMP (register) T2, `CMP Rn, Rm` with at least one high register.
pub fn cmp_reg_t2(rn: u8, rm: u8) -> Insn {
    Insn::Narrow(0x4500 | (r(rn) & 8) << 4 | r(rm) << 3 | (r(rn) & 7))
}

/// MOV (register) T1, `MOV Rd, Rm` with any registers (never sets flags).
pub fn mov_reg_t1(rd: u8, rm: u8) -> Insn {
    Insn::Narrow(0x4600 | (r(rd) & 8) << 4 | r(rm) << 3 | (r(rd) & 7))
}

/// ADR T1: `Rd = Align(PC, 4) + imm8 * 4`.
pub fn adr_t1(rd: u8, imm8: u8) -> Insn {
    Insn::Narrow(0xa000 | lo(rd) << 8 | u16::from(imm8))
}

/// ADD (SP plus immediate) T1: `Rd = SP + imm8 * 4`.
pub fn add_sp_imm_t1(rd: u8, imm8: u8) -> Insn {
    Insn::Narrow(0xa800 | lo(rd) << 8 | u16::from(imm8))
}

/// ADD (SP plus immediate) T2 or SUB (SP minus immediate) T1: `SP = SP +/- imm7 * 4`.
pub fn add_sub_sp_imm7(sub: bool, imm7: u8) -> Insn {
    Insn::Narrow(0xb000 | u16::from(sub) << 7 | u16::from(imm7 & 0x7f))
}

/// SXTH T1 (`op` 0), SXTB T1 (1), UXTH T1 (2), UXTB T1 (3).
pub fn extend16(op: u8, rd: u8, rm: u8) -> Insn {
    Insn::Narrow(0xb200 | u16::from(op & 3) << 6 | lo(rm) << 3 | lo(rd))
}

/// REV T1 (`op` 0), REV16 T1 (1), REVSH T1 (3).
pub fn rev16(op: u8, rd: u8, rm: u8) -> Insn {
    Insn::Narrow(0xba00 | u16::from(op & 3) << 6 | lo(rm) << 3 | lo(rd))
}

/// IT: `firstcond` and the 4-bit `mask` as encoded.
pub fn it(firstcond: u8, mask: u8) -> Insn {
    Insn::Narrow(0xbf00 | u16::from(firstcond & 15) << 4 | u16::from(mask & 15))
}

/// NOP T1.
pub fn nop16() -> Insn {
    Insn::Narrow(0xbf00)
}

/// B T1 (conditional): `offset` from the instruction's address + 4, even, -256..=254.
pub fn b_cond_t1(cond: u8, offset: i32) -> Insn {
    debug_assert!(offset % 2 == 0 && (-256..=254).contains(&offset));
    Insn::Narrow(0xd000 | u16::from(cond & 15) << 8 | ((offset >> 1) as u16 & 0xff))
}

/// B T2 (unconditional): `offset` even, -2048..=2046.
pub fn b_t2(offset: i32) -> Insn {
    debug_assert!(offset % 2 == 0 && (-2048..=2046).contains(&offset));
    Insn::Narrow(0xe000 | ((offset >> 1) as u16 & 0x7ff))
}

/// CBZ T1 (`nonzero` false) or CBNZ T1: forward `offset` 0..=126, even.
pub fn cbz(nonzero: bool, rn: u8, offset: u32) -> Insn {
    debug_assert!(offset % 2 == 0 && offset <= 126);
    let imm = offset >> 1;
    Insn::Narrow(
        0xb100
            | u16::from(nonzero) << 11
            | ((imm >> 5) as u16 & 1) << 9
            | (imm as u16 & 31) << 3
            | lo(rn),
    )
}

/// PUSH T1 (`pop` false, `extra` = LR) or POP T1 (`extra` = PC): `list` of r0–r7.
pub fn push_pop16(pop: bool, list: u8, extra: bool) -> Insn {
    Insn::Narrow(0xb400 | u16::from(pop) << 11 | u16::from(extra) << 8 | u16::from(list))
}

/// STM T1 (`load` false, always `Rn!`) or LDM T1 (writeback unless Rn is in the list).
pub fn ldm_stm16(load: bool, rn: u8, list: u8) -> Insn {
    Insn::Narrow(0xc000 | u16::from(load) << 11 | lo(rn) << 8 | u16::from(list))
}

// ---------------------------------------------------------------------------------------
// 16-bit loads and stores (A5.2.4).

/// The register-offset group `0101 opB Rm Rn Rt`: STR STRH STRB LDRSB LDR LDRH LDRB LDRSH
/// for `op` 0..7.
pub fn ldst_reg16(op: u8, rt: u8, rn: u8, rm: u8) -> Insn {
    Insn::Narrow(0x5000 | u16::from(op & 7) << 9 | lo(rm) << 6 | lo(rn) << 3 | lo(rt))
}

/// The immediate-offset group: `op` 0 STR, 1 LDR (imm5 * 4), 2 STRB, 3 LDRB (imm5),
/// 4 STRH, 5 LDRH (imm5 * 2).
pub fn ldst_imm16(op: u8, rt: u8, rn: u8, imm5: u8) -> Insn {
    let base: u16 = match op {
        0 => 0x6000,
        1 => 0x6800,
        2 => 0x7000,
        3 => 0x7800,
        4 => 0x8000,
        _ => 0x8800,
    };
    Insn::Narrow(base | u16::from(imm5 & 31) << 6 | lo(rn) << 3 | lo(rt))
}

/// STR (immediate) T2 / LDR (immediate) T2: `[SP, #imm8 * 4]`.
pub fn ldst_sp16(load: bool, rt: u8, imm8: u8) -> Insn {
    Insn::Narrow(0x9000 | u16::from(load) << 11 | lo(rt) << 8 | u16::from(imm8))
}

/// LDR (literal) T1: `[Align(PC, 4) + imm8 * 4]`.
pub fn ldr_literal16(rt: u8, imm8: u8) -> Insn {
    Insn::Narrow(0x4800 | lo(rt) << 8 | u16::from(imm8))
}

// ---------------------------------------------------------------------------------------
// 32-bit data processing (A5.3.1 to A5.3.4, A5.3.12 to A5.3.16).

/// The modified-immediate group (A5.3.1): `op` 0 AND/TST, 1 BIC, 2 ORR/MOV, 3 ORN/MVN,
/// 4 EOR/TEQ, 8 ADD/CMN, 10 ADC, 11 SBC, 13 SUB/CMP, 14 RSB; `imm12` = i:imm3:imm8.
pub fn dp_modimm(op: u8, s: bool, rd: u8, rn: u8, imm12: u16) -> Insn {
    Insn::Wide(
        0xf000 | (imm12 >> 11 & 1) << 10 | u16::from(op & 15) << 5 | u16::from(s) << 4 | r(rn),
        (imm12 >> 8 & 7) << 12 | r(rd) << 8 | (imm12 & 0xff),
    )
}

/// The plain-binary-immediate group (A5.3.3) with a 12-bit immediate: ADDW (`sub`
/// false) or SUBW; `Rn` = PC is ADR T3/T2.
pub fn addw_subw(sub: bool, rd: u8, rn: u8, imm12: u16) -> Insn {
    Insn::Wide(
        0xf200 | (imm12 >> 11 & 1) << 10 | u16::from(sub) << 7 | u16::from(sub) << 5 | r(rn),
        (imm12 >> 8 & 7) << 12 | r(rd) << 8 | (imm12 & 0xff),
    )
}

/// MOVW (`top` false, MOV (immediate) T3) or MOVT T1.
pub fn movw_movt(top: bool, rd: u8, imm16: u16) -> Insn {
    Insn::Wide(
        0xf240 | u16::from(top) << 7 | (imm16 >> 11 & 1) << 10 | (imm16 >> 12),
        (imm16 >> 8 & 7) << 12 | r(rd) << 8 | (imm16 & 0xff),
    )
}

/// The saturate and bit-field group (A5.3.3): `op` (bits 24:21 of the first halfword's
/// `op` field) 0 SSAT LSL, 1 SSAT ASR / SSAT16, 4 USAT LSL, 5 USAT ASR / USAT16,
/// 2 SBFX, 3 BFI/BFC, 6 UBFX; `imm5` = imm3:imm2, `low5` the low field (sat_imm,
/// widthm1, msb).
pub fn sat_bitfield(op: u8, rd: u8, rn: u8, imm5: u8, low5: u8) -> Insn {
    Insn::Wide(
        0xf300 | u16::from(op & 7) << 5 | r(rn),
        u16::from(imm5 >> 2 & 7) << 12
            | r(rd) << 8
            | u16::from(imm5 & 3) << 6
            | u16::from(low5 & 31),
    )
}

/// The shifted-register group (A5.3.11): `op` as for [`dp_modimm`] plus 6 PKH;
/// `shift_type` 0 LSL, 1 LSR, 2 ASR, 3 ROR (0 = RRX); `imm5` the shift amount field.
pub fn dp_shifted(op: u8, s: bool, rd: u8, rn: u8, rm: u8, shift_type: u8, imm5: u8) -> Insn {
    Insn::Wide(
        0xea00 | u16::from(op & 15) << 5 | u16::from(s) << 4 | r(rn),
        u16::from(imm5 >> 2 & 7) << 12
            | r(rd) << 8
            | u16::from(imm5 & 3) << 6
            | u16::from(shift_type & 3) << 4
            | r(rm),
    )
}

/// LSL/LSR/ASR/ROR (register) T2: `shift_type` 0..3.
pub fn shift_reg32(shift_type: u8, s: bool, rd: u8, rn: u8, rm: u8) -> Insn {
    Insn::Wide(
        0xfa00 | u16::from(shift_type & 3) << 5 | u16::from(s) << 4 | r(rn),
        0xf000 | r(rd) << 8 | r(rm),
    )
}

/// The extend group: `op` 0 SXTAH, 1 UXTAH, 2 SXTAB16, 3 UXTAB16, 4 SXTAB, 5 UXTAB, each
/// without the add (SXTH ...) when `Rn` is 15; `rot` 0..3 rotates by 8 * rot.
pub fn extend32(op: u8, rd: u8, rn: u8, rm: u8, rot: u8) -> Insn {
    Insn::Wide(
        0xfa00 | u16::from(op & 7) << 4 | r(rn),
        0xf080 | r(rd) << 8 | u16::from(rot & 3) << 4 | r(rm),
    )
}

/// Parallel addition and subtraction (A5.3.13, A5.3.14): `op1` 0 ADD8, 1 ADD16, 2 ASX,
/// 4 SUB8, 5 SUB16, 6 SAX; `op2` 0 S, 1 Q, 2 SH, 4 U, 5 UQ, 6 UH.
pub fn parallel(op1: u8, op2: u8, rd: u8, rn: u8, rm: u8) -> Insn {
    Insn::Wide(
        0xfa80 | u16::from(op1 & 7) << 4 | r(rn),
        0xf000 | r(rd) << 8 | u16::from(op2 & 7) << 4 | r(rm),
    )
}

/// Miscellaneous operations (A5.3.15): `op1`:`op2` 0:0 QADD, 0:1 QDADD, 0:2 QSUB,
/// 0:3 QDSUB (`Rd = op(Rm, Rn)`), 1:0 REV, 1:1 REV16, 1:2 RBIT, 1:3 REVSH, 2:0 SEL,
/// 3:0 CLZ. The one-operand forms need `rn == rm`.
pub fn misc32(op1: u8, op2: u8, rd: u8, rn: u8, rm: u8) -> Insn {
    Insn::Wide(
        0xfa80 | u16::from(op1 & 3) << 4 | r(rn),
        0xf080 | r(rd) << 8 | u16::from(op2 & 3) << 4 | r(rm),
    )
}

/// Multiply, multiply-accumulate and absolute difference (A5.3.16): `op1` 0 MLA/MUL/MLS,
/// 1 SMLAxy, 2 SMLAD, 3 SMLAWy, 4 SMLSD, 5 SMMLA, 6 SMMLS, 7 USADA8; `op2` the low bits
/// (N M, X, R, or MLS's 1); `Ra` 15 gives the forms without the accumulator.
pub fn mul32(op1: u8, op2: u8, rd: u8, rn: u8, rm: u8, ra: u8) -> Insn {
    Insn::Wide(
        0xfb00 | u16::from(op1 & 7) << 4 | r(rn),
        r(ra) << 12 | r(rd) << 8 | u16::from(op2 & 3) << 4 | r(rm),
    )
}

/// Long multiply and divide (A5.3.17): `op1` 0 SMULL, 1 SDIV, 2 UMULL, 3 UDIV, 4 SMLAL /
/// SMLALxy / SMLALD, 5 SMLSLD, 6 UMLAL / UMAAL; `op2` the 4-bit field.
pub fn long_mul(op1: u8, op2: u8, rdlo: u8, rdhi: u8, rn: u8, rm: u8) -> Insn {
    Insn::Wide(
        0xfb80 | u16::from(op1 & 7) << 4 | r(rn),
        r(rdlo) << 12 | r(rdhi) << 8 | u16::from(op2 & 15) << 4 | r(rm),
    )
}

// ---------------------------------------------------------------------------------------
// 32-bit loads and stores (A5.3.7 to A5.3.10, A5.3.5).

/// Size and signedness of a single load or store: the first halfword's bits 8:4 apart
/// from L.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Width {
    /// A byte, zero-extended on load.
    Byte,
    /// A halfword, zero-extended on load.
    Half,
    /// A word.
    Word,
    /// A byte, sign-extended (loads only).
    SignedByte,
    /// A halfword, sign-extended (loads only).
    SignedHalf,
}

impl Width {
    /// The access size in bytes.
    pub fn bytes(self) -> u32 {
        match self {
            Width::Byte | Width::SignedByte => 1,
            Width::Half | Width::SignedHalf => 2,
            Width::Word => 4,
        }
    }

    fn bits(self, load: bool) -> u16 {
        let (s, size) = match self {
            Width::Byte => (0, 0),
            Width::Half => (0, 1),
            Width::Word => (0, 2),
            Width::SignedByte => (1, 0),
            Width::SignedHalf => (1, 1),
        };
        0xf800 | s << 8 | size << 5 | u16::from(load) << 4
    }
}

/// LDR/STR{B,H,SB,SH} (immediate) T3/T2/T1: `[Rn, #imm12]`.
pub fn ldst_imm12(w: Width, load: bool, rt: u8, rn: u8, imm12: u16) -> Insn {
    Insn::Wide(w.bits(load) | 0x80 | r(rn), r(rt) << 12 | (imm12 & 0xfff))
}

/// How an immediate offset applies: `[Rn, #off]`, `[Rn, #off]!` or `[Rn], #off`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Index {
    /// Offset addressing, no writeback (P = 1, W = 0).
    Offset,
    /// Pre-indexed with writeback (P = 1, W = 1).
    Pre,
    /// Post-indexed with writeback (P = 0, W = 1).
    Post,
}

impl Index {
    /// The P and W bits.
    fn pw(self) -> (u16, u16) {
        match self {
            Index::Offset => (1, 0),
            Index::Pre => (1, 1),
            Index::Post => (0, 1),
        }
    }
}

/// LDR/STR{B,H,SB,SH} (immediate) T4/T3/T2 with an 8-bit offset, -255..=255 (the offset
/// form only negative: positive there is the unprivileged LDRT family).
pub fn ldst_imm8(w: Width, load: bool, rt: u8, rn: u8, index: Index, offset: i32) -> Insn {
    debug_assert!((-255..=255).contains(&offset) && (index != Index::Offset || offset <= 0));
    let (p, wb) = index.pw();
    Insn::Wide(
        w.bits(load) | r(rn),
        r(rt) << 12
            | 0x800
            | p << 10
            | u16::from(offset > 0) << 9
            | wb << 8
            | offset.unsigned_abs() as u16 & 0xff,
    )
}

/// LDR/STR{B,H,SB,SH} (register) T2: `[Rn, Rm, LSL #shift]`, shift 0..3.
pub fn ldst_reg32(w: Width, load: bool, rt: u8, rn: u8, rm: u8, shift: u8) -> Insn {
    Insn::Wide(
        w.bits(load) | r(rn),
        r(rt) << 12 | u16::from(shift & 3) << 4 | r(rm),
    )
}

/// LDR{B,H,SB,SH} (literal): `[Align(PC, 4) +/- imm12]`.
pub fn ldr_literal32(w: Width, rt: u8, up: bool, imm12: u16) -> Insn {
    Insn::Wide(
        w.bits(true) | u16::from(up) << 7 | 0xf,
        r(rt) << 12 | (imm12 & 0xfff),
    )
}

/// LDRD/STRD (immediate): an offset that is a multiple of 4 in -1020..=1020.
pub fn ldrd_strd(load: bool, rt: u8, rt2: u8, rn: u8, index: Index, offset: i32) -> Insn {
    debug_assert!(offset % 4 == 0 && (-1020..=1020).contains(&offset));
    let (p, wb) = index.pw();
    Insn::Wide(
        0xe840 | p << 8 | u16::from(offset >= 0) << 7 | wb << 5 | u16::from(load) << 4 | r(rn),
        r(rt) << 12 | r(rt2) << 8 | (offset.unsigned_abs() / 4) as u16 & 0xff,
    )
}

/// LDREX T1: `[Rn, #imm8 * 4]`.
pub fn ldrex(rt: u8, rn: u8, imm8: u8) -> Insn {
    Insn::Wide(0xe850 | r(rn), r(rt) << 12 | 0xf00 | u16::from(imm8))
}

/// STREX T1: `Rd` gets 0 on success, 1 on failure.
pub fn strex(rd: u8, rt: u8, rn: u8, imm8: u8) -> Insn {
    Insn::Wide(0xe840 | r(rn), r(rt) << 12 | r(rd) << 8 | u16::from(imm8))
}

/// LDREXB T1 (`half` false) or LDREXH T1.
pub fn ldrex_bh(half: bool, rt: u8, rn: u8) -> Insn {
    Insn::Wide(0xe8d0 | r(rn), r(rt) << 12 | 0xf4f | u16::from(half) << 4)
}

/// STREXB T1 (`half` false) or STREXH T1.
pub fn strex_bh(half: bool, rd: u8, rt: u8, rn: u8) -> Insn {
    Insn::Wide(
        0xe8c0 | r(rn),
        r(rt) << 12 | 0xf40 | u16::from(half) << 4 | r(rd),
    )
}

/// CLREX T1.
pub fn clrex() -> Insn {
    Insn::Wide(0xf3bf, 0x8f2f)
}

/// DSB SY.
pub fn dsb() -> Insn {
    Insn::Wide(0xf3bf, 0x8f4f)
}

/// ISB SY.
pub fn isb() -> Insn {
    Insn::Wide(0xf3bf, 0x8f6f)
}

/// STM (STMIA) T2, LDM (LDMIA) T2, STMDB T1, LDMDB T1: `list` bits 0..15 (LDM may hold
/// LR or PC, STM neither SP nor PC); `wb` sets `Rn!`.
pub fn ldm_stm32(load: bool, db: bool, rn: u8, wb: bool, list: u16) -> Insn {
    let base = if db { 0xe900 } else { 0xe880 };
    Insn::Wide(
        base | u16::from(wb) << 5 | u16::from(load) << 4 | r(rn),
        list,
    )
}

/// TBB (`half` false) or TBH: `[Rn, Rm]` / `[Rn, Rm, LSL #1]`.
pub fn tbb(half: bool, rn: u8, rm: u8) -> Insn {
    Insn::Wide(0xe8d0 | r(rn), 0xf000 | u16::from(half) << 4 | r(rm))
}

/// B T3 (conditional, `cond` 0..13) with an even `offset` within +/-1 MiB.
pub fn b_cond_t3(cond: u8, offset: i32) -> Insn {
    debug_assert!(offset % 2 == 0 && (-(1 << 20)..(1 << 20)).contains(&offset));
    let imm = (offset >> 1) as u32;
    let s = (imm >> 19) & 1;
    let j2 = (imm >> 18) & 1;
    let j1 = (imm >> 17) & 1;
    Insn::Wide(
        (0xf000 | s << 10 | u32::from(cond & 15) << 6 | (imm >> 11 & 0x3f)) as u16,
        (0x8000 | j1 << 13 | j2 << 11 | (imm & 0x7ff)) as u16,
    )
}

/// B T4 (unconditional) with an even `offset` within +/-16 MiB.
pub fn b_t4(offset: i32) -> Insn {
    debug_assert!(offset % 2 == 0 && (-(1 << 24)..(1 << 24)).contains(&offset));
    let imm = (offset >> 1) as u32;
    let s = (imm >> 23) & 1;
    let i1 = (imm >> 22) & 1;
    let i2 = (imm >> 21) & 1;
    let j1 = (!(i1 ^ s)) & 1;
    let j2 = (!(i2 ^ s)) & 1;
    Insn::Wide(
        (0xf000 | s << 10 | (imm >> 11 & 0x3ff)) as u16,
        (0x9000 | j1 << 13 | j2 << 11 | (imm & 0x7ff)) as u16,
    )
}

/// MSR T1 to a special register (`sysm`: 0 APSR, 8 MSP, 9 PSP, ...); `mask` 2 writes
/// N Z C V Q, 3 also GE.
pub fn msr(sysm: u8, mask: u8, rn: u8) -> Insn {
    Insn::Wide(
        0xf380 | r(rn),
        0x8000 | u16::from(mask & 3) << 10 | u16::from(sysm),
    )
}

/// MRS T1 from a special register (`sysm`: 0 APSR, 3 xPSR, 5 IPSR, 9 PSP, ...).
pub fn mrs(rd: u8, sysm: u8) -> Insn {
    Insn::Wide(0xf3ef, 0x8000 | r(rd) << 8 | u16::from(sysm))
}

// ---------------------------------------------------------------------------------------
// Floating point (A6.4, A7.7): single-precision register numbers 0..31.

fn vd_bits(s: u8) -> (u16, u16) {
    debug_assert!(s < 32);
    (u16::from(s >> 1), u16::from(s & 1))
}

/// VMOV (between ARM core register and single-precision register): `to_core` is
/// `VMOV Rt, Sn`.
pub fn vmov_core_single(to_core: bool, rt: u8, sn: u8) -> Insn {
    let (vn, n) = vd_bits(sn);
    Insn::Wide(
        0xee00 | u16::from(to_core) << 4 | vn,
        r(rt) << 12 | 0xa10 | n << 7,
    )
}

/// VMOV (between two ARM core registers and two single-precision registers):
/// `Sm`, `Sm+1` and `Rt`, `Rt2`.
pub fn vmov_core_two_singles(to_core: bool, rt: u8, rt2: u8, sm: u8) -> Insn {
    let (vm, m) = vd_bits(sm);
    Insn::Wide(
        0xec40 | u16::from(to_core) << 4 | r(rt2),
        r(rt) << 12 | 0xa10 | m << 5 | vm,
    )
}

/// VMOV (immediate) with the 8-bit VFPExpandImm field.
pub fn vmov_imm(sd: u8, imm8: u8) -> Insn {
    let (vd, d) = vd_bits(sd);
    Insn::Wide(
        0xeeb0 | d << 6 | u16::from(imm8 >> 4),
        vd << 12 | 0xa00 | u16::from(imm8 & 15),
    )
}

/// VLDR/VSTR: `[Rn, #+/-imm8 * 4]`.
pub fn vldr_vstr(load: bool, sd: u8, rn: u8, up: bool, imm8: u8) -> Insn {
    let (vd, d) = vd_bits(sd);
    Insn::Wide(
        0xed00 | u16::from(up) << 7 | d << 6 | u16::from(load) << 4 | r(rn),
        vd << 12 | 0xa00 | u16::from(imm8),
    )
}

/// VLDM/VSTM (VPUSH and VPOP with `Rn` = SP): `db` decrement-before (with writeback),
/// otherwise increment-after with or without `wb`; `count` registers from `sd`.
pub fn vldm_vstm(load: bool, db: bool, wb: bool, rn: u8, sd: u8, count: u8) -> Insn {
    let (vd, d) = vd_bits(sd);
    let (p, u) = if db { (1u16, 0u16) } else { (0, 1) };
    Insn::Wide(
        0xec00 | p << 8 | u << 7 | d << 6 | u16::from(wb) << 5 | u16::from(load) << 4 | r(rn),
        vd << 12 | 0xa00 | u16::from(count),
    )
}

/// VMRS `Rt, FPSCR` (`Rt` = 15 is `APSR_nzcv, FPSCR`).
pub fn vmrs(rt: u8) -> Insn {
    Insn::Wide(0xeef1, r(rt) << 12 | 0xa10)
}

/// VMSR `FPSCR, Rt`.
pub fn vmsr(rt: u8) -> Insn {
    Insn::Wide(0xeee1, r(rt) << 12 | 0xa10)
}

/// The three-register data-processing group (A6.4 table A6-15): `opc` 0 VMLA/VMLS (by
/// `op`), 1 VNMLS/VNMLA, 2 VMUL/VNMUL, 3 VADD/VSUB, 4 VDIV, 5 VFNMS/VFNMA, 6 VFMA/VFMS.
pub fn vfp3(opc: u8, op: bool, sd: u8, sn: u8, sm: u8) -> Insn {
    let (vd, d) = vd_bits(sd);
    let (vn, n) = vd_bits(sn);
    let (vm, m) = vd_bits(sm);
    Insn::Wide(
        0xee00 | u16::from(opc >> 2 & 1) << 7 | d << 6 | u16::from(opc & 3) << 4 | vn,
        vd << 12 | 0xa00 | n << 7 | u16::from(op) << 6 | m << 5 | vm,
    )
}

/// The "other" group (A6.4 table A6-15 with opc1 = 1x11): `opc2` 0 VMOV/VABS, 1 VNEG /
/// VSQRT, 2 VCVTB/VCVTT from half, 3 to half, 4 VCMP(E), 5 VCMP(E) #0, 8 VCVT to float,
/// 12 and 13 VCVT(R) to unsigned / signed; `o` is bit 7 of the second halfword (VABS,
/// VSQRT, T, E, signed source, round towards zero).
pub fn vfp2(opc2: u8, o: bool, sd: u8, sm: u8) -> Insn {
    let (vd, d) = vd_bits(sd);
    let (vm, m) = vd_bits(sm);
    Insn::Wide(
        0xeeb0 | d << 6 | u16::from(opc2 & 15),
        vd << 12 | 0xa40 | u16::from(o) << 7 | m << 5 | vm,
    )
}

/// VCMP(E) with #0.0.
pub fn vcmp_zero(e: bool, sd: u8) -> Insn {
    let (vd, d) = vd_bits(sd);
    Insn::Wide(0xeeb5 | d << 6, vd << 12 | 0xa40 | u16::from(e) << 7)
}

/// VCVT (between floating-point and fixed-point): `to_fixed`, `unsigned`, `sx` (32-bit
/// fixed point, else 16), `imm5` = imm4:i (fraction bits = size - imm5).
pub fn vcvt_fixed(to_fixed: bool, unsigned: bool, sx: bool, sd: u8, imm5: u8) -> Insn {
    let (vd, d) = vd_bits(sd);
    Insn::Wide(
        0xeeba | d << 6 | u16::from(to_fixed) << 2 | u16::from(unsigned),
        vd << 12
            | 0xa40
            | u16::from(sx) << 7
            | u16::from(imm5 & 1) << 5
            | u16::from(imm5 >> 1 & 15),
    )
}

/// VFPExpandImm (A6.4.1) for single precision: the value VMOV (immediate) writes.
pub fn vfp_expand_imm(imm8: u8) -> u32 {
    let imm = u32::from(imm8);
    let sign = imm >> 7;
    let b = imm >> 6 & 1;
    let exponent = (b ^ 1) << 7 | (if b == 1 { 0x1f } else { 0 }) << 2 | (imm >> 4 & 3);
    sign << 31 | exponent << 23 | (imm & 15) << 19
}

/// ThumbExpandImm_C (A5.3.2): the value of a modified immediate and, for the rotated
/// forms, the carry out (`None`: the carry flag is unchanged).
pub fn expand_imm(imm12: u16) -> (u32, Option<bool>) {
    let imm8 = u32::from(imm12 & 0xff);
    if imm12 >> 10 == 0 {
        let v = match imm12 >> 8 & 3 {
            0 => imm8,
            1 => imm8 << 16 | imm8,
            2 => imm8 << 24 | imm8 << 8,
            _ => imm8 * 0x0101_0101,
        };
        (v, None)
    } else {
        let unrotated = 0x80 | (imm8 & 0x7f);
        let v = unrotated.rotate_right(u32::from(imm12 >> 7 & 31));
        (v, Some(v >> 31 == 1))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wide(b: [u8; 4]) -> Insn {
        Insn::Wide(
            u16::from_le_bytes([b[0], b[1]]),
            u16::from_le_bytes([b[2], b[3]]),
        )
    }

    /// Encodings checked against LLVM 14's assembler (`llvm-mc -show-encoding`).
    #[test]
    fn encodings_match_the_assembler() {
        // adds r0, r1, r2
        assert_eq!(add_sub_reg16(false, 0, 1, 2), Insn::Narrow(0x1888));
        // sadd16 r1, r2, r3 / uhadd16 r1, r2, r3
        assert_eq!(parallel(1, 0, 1, 2, 3), wide([0x92, 0xfa, 0x03, 0xf1]));
        assert_eq!(parallel(1, 6, 1, 2, 3), wide([0x92, 0xfa, 0x63, 0xf1]));
        // qdadd r1, r2, r3 (Rm = r2, Rn = r3)
        assert_eq!(misc32(0, 1, 1, 3, 2), wide([0x83, 0xfa, 0x92, 0xf1]));
        // clz r1, r2
        assert_eq!(misc32(3, 0, 1, 2, 2), wide([0xb2, 0xfa, 0x82, 0xf1]));
        // smlaltb r1, r2, r3, r4
        assert_eq!(
            long_mul(4, 0b1010, 1, 2, 3, 4),
            wide([0xc3, 0xfb, 0xa4, 0x12])
        );
        // smmlsr r1, r2, r3, r4
        assert_eq!(mul32(6, 1, 1, 2, 3, 4), wide([0x62, 0xfb, 0x13, 0x41]));
        // sxtah r1, r2, r3, ror #8
        assert_eq!(extend32(0, 1, 2, 3, 1), wide([0x02, 0xfa, 0x93, 0xf1]));
        // ssat r1, #5, r2, asr #3 (sat_imm = 4)
        assert_eq!(sat_bitfield(1, 1, 2, 3, 4), wide([0x22, 0xf3, 0xc4, 0x01]));
        // bfc r1, #3, #5 (msb = 7)
        assert_eq!(sat_bitfield(3, 1, 15, 3, 7), wide([0x6f, 0xf3, 0xc7, 0x01]));
        // pkhtb r1, r2, r3, asr #4
        assert_eq!(
            dp_shifted(6, false, 1, 2, 3, 2, 4),
            wide([0xc2, 0xea, 0x23, 0x11])
        );
        // movw r1, #0x1234 / movt r1, #0x1234
        assert_eq!(movw_movt(false, 1, 0x1234), wide([0x41, 0xf2, 0x34, 0x21]));
        assert_eq!(movw_movt(true, 1, 0x1234), wide([0xc1, 0xf2, 0x34, 0x21]));
        // subw r1, r2, #0x123
        assert_eq!(addw_subw(true, 1, 2, 0x123), wide([0xa2, 0xf2, 0x23, 0x11]));
        // ldr r1, [r2], #-255 / ldrsh r1, [r2, #-1]
        assert_eq!(
            ldst_imm8(Width::Word, true, 1, 2, Index::Post, -255),
            wide([0x52, 0xf8, 0xff, 0x19])
        );
        assert_eq!(
            ldst_imm8(Width::SignedHalf, true, 1, 2, Index::Offset, -1),
            wide([0x32, 0xf9, 0x01, 0x1c])
        );
        // strh.w r1, [r2, r3, lsl #2]
        assert_eq!(
            ldst_reg32(Width::Half, false, 1, 2, 3, 2),
            wide([0x22, 0xf8, 0x23, 0x10])
        );
        // ldrd r1, r2, [r3, #-8]!
        assert_eq!(
            ldrd_strd(true, 1, 2, 3, Index::Pre, -8),
            wide([0x73, 0xe9, 0x02, 0x12])
        );
        // strex r3, r1, [r2, #8] / strexh r3, r1, [r2]
        assert_eq!(strex(3, 1, 2, 2), wide([0x42, 0xe8, 0x02, 0x13]));
        assert_eq!(strex_bh(true, 3, 1, 2), wide([0xc2, 0xe8, 0x53, 0x1f]));
        // stmdb r2!, {r1, r3} / pop.w {r1, r3}
        assert_eq!(
            ldm_stm32(false, true, 2, true, 0b1010),
            wide([0x22, 0xe9, 0x0a, 0x00])
        );
        assert_eq!(
            ldm_stm32(true, false, 13, true, 0b1010),
            wide([0xbd, 0xe8, 0x0a, 0x00])
        );
        // tbh [r1, r2, lsl #1]
        assert_eq!(tbb(true, 1, 2), wide([0xd1, 0xe8, 0x12, 0xf0]));
        // msr psp, r0 / mrs r3, xpsr
        assert_eq!(msr(9, 2, 0), wide([0x80, 0xf3, 0x09, 0x88]));
        assert_eq!(mrs(3, 3), wide([0xef, 0xf3, 0x03, 0x83]));
        // vmov r1, r2, s3, s4 / vmov s3, r2
        assert_eq!(
            vmov_core_two_singles(true, 1, 2, 3),
            wide([0x52, 0xec, 0x31, 0x1a])
        );
        assert_eq!(
            vmov_core_single(false, 2, 3),
            wide([0x01, 0xee, 0x90, 0x2a])
        );
        // vmov.f32 s3, #1.0
        assert_eq!(vmov_imm(3, 0x70), wide([0xf7, 0xee, 0x00, 0x1a]));
        // vldr s3, [r2, #-8] / vldmdb r2!, {s3-s5} / vpop {s3-s5}
        assert_eq!(
            vldr_vstr(true, 3, 2, false, 2),
            wide([0x52, 0xed, 0x02, 0x1a])
        );
        assert_eq!(
            vldm_vstm(true, true, true, 2, 3, 3),
            wide([0x72, 0xed, 0x03, 0x1a])
        );
        assert_eq!(
            vldm_vstm(true, false, true, 13, 3, 3),
            wide([0xfd, 0xec, 0x03, 0x1a])
        );
        // vmrs APSR_nzcv, fpscr / vmsr fpscr, r2
        assert_eq!(vmrs(15), wide([0xf1, 0xee, 0x10, 0xfa]));
        assert_eq!(vmsr(2), wide([0xe1, 0xee, 0x10, 0x2a]));
        // vnmla.f32 s1, s2, s3 / vfnms.f32 s1, s2, s3 / vdiv.f32 s1, s2, s3
        assert_eq!(vfp3(1, true, 1, 2, 3), wide([0x51, 0xee, 0x61, 0x0a]));
        assert_eq!(vfp3(5, false, 1, 2, 3), wide([0xd1, 0xee, 0x21, 0x0a]));
        assert_eq!(vfp3(4, false, 1, 2, 3), wide([0xc1, 0xee, 0x21, 0x0a]));
        // vsqrt.f32 s1, s3 / vcvtr.u32.f32 s1, s3 / vcvtt.f16.f32 s1, s3
        assert_eq!(vfp2(1, true, 1, 3), wide([0xf1, 0xee, 0xe1, 0x0a]));
        assert_eq!(vfp2(12, false, 1, 3), wide([0xfc, 0xee, 0x61, 0x0a]));
        assert_eq!(vfp2(3, true, 1, 3), wide([0xf3, 0xee, 0xe1, 0x0a]));
        // vcmpe.f32 s1, #0
        assert_eq!(vcmp_zero(true, 1), wide([0xf5, 0xee, 0xc0, 0x0a]));
        // vcvt.s16.f32 s1, s1, #3 / vcvt.f32.u32 s1, s1, #32
        assert_eq!(
            vcvt_fixed(true, false, false, 1, 13),
            wide([0xfe, 0xee, 0x66, 0x0a])
        );
        assert_eq!(
            vcvt_fixed(false, true, true, 1, 0),
            wide([0xfb, 0xee, 0xc0, 0x0a])
        );
    }

    #[test]
    fn branches() {
        // b.w with offsets either way, checked by decoding the fields back.
        for offset in [-(1 << 24), -4, 0, 2, 1000, (1 << 24) - 2] {
            let Insn::Wide(a, b) = b_t4(offset) else {
                unreachable!()
            };
            let s = u32::from(a >> 10 & 1);
            let j1 = u32::from(b >> 13 & 1);
            let j2 = u32::from(b >> 11 & 1);
            let i1 = !(j1 ^ s) & 1;
            let i2 = !(j2 ^ s) & 1;
            let imm = s << 24
                | i1 << 23
                | i2 << 22
                | u32::from(a & 0x3ff) << 12
                | u32::from(b & 0x7ff) << 1;
            assert_eq!(((imm << 7) as i32) >> 7, offset);
        }
        // beq.w #8 (llvm-mc: [0x00,0xf0,0x04,0x80])
        assert_eq!(b_cond_t3(0, 8), wide([0x00, 0xf0, 0x04, 0x80]));
        // cbz r1, #64 ([0x01,0xb3]) / cbnz r1, #64 ([0x01,0xbb])
        assert_eq!(cbz(false, 1, 64), Insn::Narrow(0xb301));
        assert_eq!(cbz(true, 1, 64), Insn::Narrow(0xbb01));
    }

    #[test]
    fn vfp_immediates() {
        assert_eq!(f32::from_bits(vfp_expand_imm(0x70)), 1.0);
        assert_eq!(f32::from_bits(vfp_expand_imm(0x1d)), 7.25);
        assert_eq!(f32::from_bits(vfp_expand_imm(0x90)), -4.0);
        assert_eq!(f32::from_bits(vfp_expand_imm(0x55)), 0.328125);
    }

    #[test]
    fn modified_immediates() {
        assert_eq!(expand_imm(0x0ab), (0xab, None));
        assert_eq!(expand_imm(0x1ab), (0x00ab_00ab, None));
        assert_eq!(expand_imm(0x2ab), (0xab00_ab00, None));
        assert_eq!(expand_imm(0x3ab), (0xabab_abab, None));
        // rotation 8: 0x80 | 0x2b ror 8 = 0xab000000, carry = 1
        assert_eq!(expand_imm(0x42b), (0xab00_0000, Some(true)));
        // rotation 31: 0x80 ror 31 = 0x100
        assert_eq!(expand_imm(0xf80), (0x100, Some(false)));
    }
}
