//! Instructions in the decoded form the core executes.
//!
//! Each Thumb instruction is decoded once into an [`Op`] (operands split out, immediates
//! expanded, PC-relative addresses resolved for the instruction's own address) and cached
//! per address, so running an instruction again costs one match and no bit-fiddling. This
//! is why the decoder is the project's own rather than a general disassembler crate's: those
//! decode to a textual or operand-list form that would be decoded again at every execution.

/// When a 16-bit data-processing instruction sets the flags: outside an IT block only
/// (ARMv7-M ARM A6.3: `ADDS r0, r1, r2` inside IT is `ADD`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SetFlags {
    /// Never (32-bit encodings without S, ADDW, MOV T1 high registers, …).
    Never,
    /// Always (32-bit encodings with S; CMP, CMN, TST, TEQ).
    Always,
    /// Outside an IT block (most 16-bit encodings).
    OutsideIt,
}

/// The data-processing operations.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Alu {
    /// Rd = Rn AND op2.
    And,
    /// Rd = Rn AND NOT op2.
    Bic,
    /// Rd = Rn OR op2.
    Orr,
    /// Rd = Rn OR NOT op2.
    Orn,
    /// Rd = Rn EOR op2.
    Eor,
    /// Rd = op2.
    Mov,
    /// Rd = NOT op2.
    Mvn,
    /// Flags of Rn AND op2.
    Tst,
    /// Flags of Rn EOR op2.
    Teq,
    /// Rd = Rn + op2.
    Add,
    /// Rd = Rn + op2 + C.
    Adc,
    /// Rd = Rn - op2.
    Sub,
    /// Rd = Rn - op2 - NOT C.
    Sbc,
    /// Rd = op2 - Rn.
    Rsb,
    /// Flags of Rn - op2.
    Cmp,
    /// Flags of Rn + op2.
    Cmn,
}

/// The barrel shifter's operations (DecodeImmShift, A7.4.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shift {
    /// Logical shift left.
    Lsl,
    /// Logical shift right (an immediate of 0 is encoded as 32).
    Lsr,
    /// Arithmetic shift right (an immediate of 0 is encoded as 32).
    Asr,
    /// Rotate right.
    Ror,
    /// Rotate right by one through the carry flag.
    Rrx,
}

/// What a modified immediate does to the carry flag (ThumbExpandImm_C).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ImmCarry {
    /// Unchanged (the immediate was not rotated).
    Keep,
    /// Set to the given value (bit 31 of the rotated immediate).
    Set(bool),
}

/// Access size and signedness of a load or store.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Width {
    /// Byte, zero-extended on load.
    Byte,
    /// Byte, sign-extended on load.
    SignedByte,
    /// Halfword, zero-extended on load.
    Half,
    /// Halfword, sign-extended on load.
    SignedHalf,
    /// Word.
    Word,
}

/// Indexing of an immediate-offset load or store.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Index {
    /// Address = Rn + offset, Rn unchanged.
    Offset,
    /// Address = Rn + offset, Rn written back.
    Pre,
    /// Address = Rn, Rn + offset written back.
    Post,
}

/// Operations on one register that need no second operand.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unary {
    /// Count leading zeros.
    Clz,
    /// Reverse the bits.
    Rbit,
    /// Reverse the bytes.
    Rev,
    /// Reverse the bytes in each halfword.
    Rev16,
    /// Reverse the bytes of the low halfword and sign-extend.
    Revsh,
}

/// The extend operations (with an optional add: SXTAB etc. when `rn` is not 15).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Extend {
    /// Sign-extend a byte.
    Sxtb,
    /// Zero-extend a byte.
    Uxtb,
    /// Sign-extend a halfword.
    Sxth,
    /// Zero-extend a halfword.
    Uxth,
    /// Sign-extend bytes 0 and 2 to halfwords.
    Sxtb16,
    /// Zero-extend bytes 0 and 2 to halfwords.
    Uxtb16,
}

/// Bit-field operations.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BitField {
    /// Insert the low bits of Rn (BFI) or zeros (BFC, Rn = 15).
    Insert,
    /// Extract and zero-extend.
    Ubfx,
    /// Extract and sign-extend.
    Sbfx,
}

/// Long multiplies.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LongMul {
    /// RdHi:RdLo = Rn * Rm, unsigned.
    Umull,
    /// RdHi:RdLo = Rn * Rm, signed.
    Smull,
    /// RdHi:RdLo += Rn * Rm, unsigned.
    Umlal,
    /// RdHi:RdLo += Rn * Rm, signed.
    Smlal,
    /// RdHi:RdLo = Rn * Rm + RdLo + RdHi, unsigned.
    Umaal,
}

/// The saturating add and subtract of whole words.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SatArith {
    /// Rd = sat(Rm + Rn).
    Qadd,
    /// Rd = sat(Rm - Rn).
    Qsub,
    /// Rd = sat(Rm + sat(2 * Rn)).
    Qdadd,
    /// Rd = sat(Rm - sat(2 * Rn)).
    Qdsub,
}

/// The parallel add and subtract family's prefix (A6.3.14/15).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Lanes {
    /// Signed, setting GE.
    Signed,
    /// Signed saturating.
    SignedSat,
    /// Signed halving.
    SignedHalving,
    /// Unsigned, setting GE.
    Unsigned,
    /// Unsigned saturating.
    UnsignedSat,
    /// Unsigned halving.
    UnsignedHalving,
}

/// The parallel add and subtract family's operation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LaneOp {
    /// Two halfword additions.
    Add16,
    /// High halfword: add, low: subtract, of Rm's halves swapped.
    Asx,
    /// High halfword: subtract, low: add, of Rm's halves swapped.
    Sax,
    /// Two halfword subtractions.
    Sub16,
    /// Four byte additions.
    Add8,
    /// Four byte subtractions.
    Sub8,
}

/// The DSP multiplies that produce one word.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DspMul {
    /// SMULxy / SMLAxy (with an accumulator): 16×16.
    Halves,
    /// SMULWy / SMLAWy: 32×16, the top 32 bits of 48.
    Wide,
    /// SMUAD / SMLAD: sum of the two 16×16 products.
    DualAdd,
    /// SMUSD / SMLSD: difference of the two 16×16 products.
    DualSub,
    /// SMMUL / SMMLA: the top word of the 64-bit product, plus Ra.
    MostAdd,
    /// SMMLS: Ra minus the product, top word.
    MostSub,
}

/// The DSP multiplies that accumulate into a doubleword.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DspLong {
    /// SMLALxy: 16×16 added to RdHi:RdLo.
    Halves,
    /// SMLALD: the sum of the two products added.
    DualAdd,
    /// SMLSLD: the difference of the two products added.
    DualSub,
}

/// Special registers of MRS and MSR (the SYSm field, B5.1.1).
pub type SysReg = u8;

/// The single-precision arithmetic with two operands (and VMLA-style accumulation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VBinary {
    /// Sd = Sn + Sm.
    Add,
    /// Sd = Sn - Sm.
    Sub,
    /// Sd = Sn * Sm.
    Mul,
    /// Sd = -(Sn * Sm).
    Nmul,
    /// Sd = Sn / Sm.
    Div,
    /// Sd = Sd + Sn * Sm (two roundings).
    Mla,
    /// Sd = Sd - Sn * Sm (two roundings).
    Mls,
    /// Sd = -Sd - Sn * Sm (two roundings).
    Nmla,
    /// Sd = -Sd + Sn * Sm (two roundings).
    Nmls,
    /// Sd = Sd + Sn * Sm (one rounding).
    Fma,
    /// Sd = Sd - Sn * Sm (one rounding).
    Fms,
    /// Sd = -Sd - Sn * Sm (one rounding).
    Fnma,
    /// Sd = -Sd + Sn * Sm (one rounding).
    Fnms,
}

/// The single-precision operations with one operand.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VUnary {
    /// Copy.
    Mov,
    /// Clear the sign bit.
    Abs,
    /// Flip the sign bit.
    Neg,
    /// Square root.
    Sqrt,
}

/// The conversions of VCVT.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VConvert {
    /// Float to signed integer; `round_zero` picks round-towards-zero over FPSCR's mode.
    ToSigned {
        /// VCVT (towards zero) rather than VCVTR (FPSCR's mode).
        round_zero: bool,
    },
    /// Float to unsigned integer.
    ToUnsigned {
        /// VCVT (towards zero) rather than VCVTR (FPSCR's mode).
        round_zero: bool,
    },
    /// Signed integer to float.
    FromSigned,
    /// Unsigned integer to float.
    FromUnsigned,
    /// Float to fixed point in place (round towards zero).
    ToFixed {
        /// Signed rather than unsigned.
        signed: bool,
        /// A 16-bit rather than a 32-bit fixed-point value.
        half: bool,
        /// Fraction bits.
        frac: u8,
    },
    /// Fixed point to float in place (FPSCR's rounding mode).
    FromFixed {
        /// Signed rather than unsigned.
        signed: bool,
        /// A 16-bit rather than a 32-bit fixed-point value.
        half: bool,
        /// Fraction bits.
        frac: u8,
    },
    /// Half precision (the bottom or top half of Sm) to single.
    FromHalf {
        /// The top half (VCVTT) rather than the bottom (VCVTB).
        top: bool,
    },
    /// Single to half precision, into the bottom or top half of Sd.
    ToHalf {
        /// The top half (VCVTT) rather than the bottom (VCVTB).
        top: bool,
    },
}

/// One decoded instruction. Register numbers are 0–15 (core) or 0–31 (single-precision).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Op {
    /// An undefined or unallocated encoding: UsageFault (UNDEFINSTR).
    Undefined,
    /// A coprocessor instruction for a coprocessor other than the FPU: UsageFault (NOCP).
    NoCoprocessor,
    /// An encoding the architecture calls UNPREDICTABLE; run as a UsageFault so a firmware
    /// that contains one is reported rather than given one chip's behaviour.
    Unpredictable,
    /// NOP, YIELD and the hints that do nothing here; DMB and DSB (the emulated bus has no
    /// reordering).
    Nop,
    /// ISB: also nothing to flush, but kept apart for the trace.
    Isb,
    /// Data processing with an immediate operand.
    AluImm {
        /// The operation.
        op: Alu,
        /// Whether it sets the flags.
        s: SetFlags,
        /// Destination.
        rd: u8,
        /// First operand.
        rn: u8,
        /// The immediate.
        imm: u32,
        /// Its carry out.
        carry: ImmCarry,
    },
    /// Data processing with a shifted register operand.
    AluReg {
        /// The operation.
        op: Alu,
        /// Whether it sets the flags.
        s: SetFlags,
        /// Destination.
        rd: u8,
        /// First operand.
        rn: u8,
        /// Second operand.
        rm: u8,
        /// How it is shifted.
        shift: Shift,
        /// By how much (1–32; 0 for LSL means no shift).
        amount: u8,
    },
    /// A shift by a register (LSL, LSR, ASR, ROR register forms).
    ShiftReg {
        /// Whether it sets the flags.
        s: SetFlags,
        /// Destination.
        rd: u8,
        /// The value shifted.
        rn: u8,
        /// The register whose bottom byte is the amount.
        rm: u8,
        /// Which shift.
        shift: Shift,
    },
    /// MOVT: the top halfword of Rd.
    Movt {
        /// Destination.
        rd: u8,
        /// The halfword.
        imm: u16,
    },
    /// MUL, MLA, MLS.
    Mul {
        /// Whether it sets N and Z (MULS T1 outside IT).
        s: SetFlags,
        /// Destination.
        rd: u8,
        /// Multiplicand.
        rn: u8,
        /// Multiplier.
        rm: u8,
        /// Accumulator, 15 for none.
        ra: u8,
        /// Subtract the product from Ra (MLS).
        sub: bool,
    },
    /// UMULL, SMULL, UMLAL, SMLAL, UMAAL.
    LongMul {
        /// Which.
        kind: LongMul,
        /// Low word of the result.
        rdlo: u8,
        /// High word of the result.
        rdhi: u8,
        /// First operand.
        rn: u8,
        /// Second operand.
        rm: u8,
    },
    /// SDIV and UDIV.
    Div {
        /// Signed.
        signed: bool,
        /// Destination.
        rd: u8,
        /// Dividend.
        rn: u8,
        /// Divisor.
        rm: u8,
    },
    /// CLZ, RBIT, REV, REV16, REVSH.
    Unary {
        /// Which.
        op: Unary,
        /// Destination.
        rd: u8,
        /// Source.
        rm: u8,
    },
    /// SXTB and friends, with an add when `rn` is not 15.
    Extend {
        /// Which.
        op: Extend,
        /// Destination.
        rd: u8,
        /// The register added, 15 for none.
        rn: u8,
        /// Source.
        rm: u8,
        /// Rotation of Rm: 0, 8, 16 or 24.
        rot: u8,
    },
    /// BFI, BFC, UBFX, SBFX.
    BitField {
        /// Which.
        op: BitField,
        /// Destination.
        rd: u8,
        /// Source (15 for BFC).
        rn: u8,
        /// The field's lowest bit.
        lsb: u8,
        /// The field's width, 1–32.
        width: u8,
    },
    /// SSAT and USAT (with a shift of Rn first).
    Saturate {
        /// Signed.
        signed: bool,
        /// Destination.
        rd: u8,
        /// Source.
        rn: u8,
        /// The saturation bit position (SSAT: 1–32 bits; USAT: 0–31).
        bits: u8,
        /// Shift applied first: LSL or ASR.
        shift: Shift,
        /// The shift's amount.
        amount: u8,
    },
    /// SSAT16 and USAT16.
    Saturate16 {
        /// Signed.
        signed: bool,
        /// Destination.
        rd: u8,
        /// Source.
        rn: u8,
        /// The saturation bit position.
        bits: u8,
    },
    /// QADD, QSUB, QDADD, QDSUB.
    SatArith {
        /// Which.
        op: SatArith,
        /// Destination.
        rd: u8,
        /// The operand doubled in QDADD/QDSUB.
        rn: u8,
        /// The other operand.
        rm: u8,
    },
    /// The parallel add and subtract family.
    Parallel {
        /// Signed/unsigned, plain/saturating/halving.
        lanes: Lanes,
        /// The lane operation.
        op: LaneOp,
        /// Destination.
        rd: u8,
        /// First operand.
        rn: u8,
        /// Second operand.
        rm: u8,
    },
    /// SEL: bytes from Rn or Rm by the GE flags.
    Sel {
        /// Destination.
        rd: u8,
        /// Bytes where GE is set.
        rn: u8,
        /// Bytes where GE is clear.
        rm: u8,
    },
    /// USAD8 and USADA8 (Ra = 15: no accumulation).
    Usad8 {
        /// Destination.
        rd: u8,
        /// First operand.
        rn: u8,
        /// Second operand.
        rm: u8,
        /// Accumulator, 15 for none.
        ra: u8,
    },
    /// PKHBT and PKHTB.
    Pack {
        /// PKHTB (top from Rn, bottom from Rm ASR) rather than PKHBT.
        tb: bool,
        /// Destination.
        rd: u8,
        /// First operand.
        rn: u8,
        /// Second operand, shifted.
        rm: u8,
        /// Shift amount (ASR 32 is encoded as 0 for PKHTB and given here as 32).
        amount: u8,
    },
    /// The DSP multiplies into one word.
    DspMul {
        /// Which.
        op: DspMul,
        /// Destination.
        rd: u8,
        /// First operand.
        rn: u8,
        /// Second operand.
        rm: u8,
        /// Accumulator, 15 for none.
        ra: u8,
        /// Halves: the top half of Rn. Other kinds: unused.
        n_top: bool,
        /// Halves and Wide: the top half of Rm. Dual: Rm's halves swapped (the X forms).
        m_top: bool,
        /// SMMUL/SMMLA/SMMLS: round (the R forms).
        round: bool,
    },
    /// The DSP multiplies into a doubleword.
    DspLong {
        /// Which.
        op: DspLong,
        /// Low word.
        rdlo: u8,
        /// High word.
        rdhi: u8,
        /// First operand.
        rn: u8,
        /// Second operand.
        rm: u8,
        /// Halves: the top half of Rn.
        n_top: bool,
        /// Halves: the top half of Rm. Dual: Rm's halves swapped.
        m_top: bool,
    },
    /// B (unconditional, or conditional outside IT with its own condition).
    Branch {
        /// The condition (14: always).
        cond: u8,
        /// The target address.
        target: u32,
    },
    /// BL.
    BranchLink {
        /// The target address.
        target: u32,
    },
    /// BX and BLX (register).
    BranchExchange {
        /// The target register.
        rm: u8,
        /// BLX: link.
        link: bool,
    },
    /// CBZ and CBNZ.
    CompareBranch {
        /// CBNZ.
        nonzero: bool,
        /// The register tested.
        rn: u8,
        /// The target address.
        target: u32,
    },
    /// TBB and TBH.
    TableBranch {
        /// TBH.
        half: bool,
        /// The table's base.
        rn: u8,
        /// The index.
        rm: u8,
    },
    /// IT.
    It {
        /// The IT state after this instruction (firstcond:mask).
        state: u8,
    },
    /// Loads and stores with an immediate offset.
    LoadStoreImm {
        /// Load rather than store.
        load: bool,
        /// Size and signedness.
        width: Width,
        /// The register loaded or stored.
        rt: u8,
        /// The base.
        rn: u8,
        /// The offset, signed.
        offset: i32,
        /// Indexing and writeback.
        index: Index,
    },
    /// Loads and stores with a register offset, shifted left.
    LoadStoreReg {
        /// Load rather than store.
        load: bool,
        /// Size and signedness.
        width: Width,
        /// The register loaded or stored.
        rt: u8,
        /// The base.
        rn: u8,
        /// The offset register.
        rm: u8,
        /// LSL amount, 0–3.
        shift: u8,
    },
    /// A load from a PC-relative address (resolved at decode).
    LoadLiteral {
        /// Size and signedness.
        width: Width,
        /// The register loaded.
        rt: u8,
        /// The address.
        address: u32,
    },
    /// LDRD and STRD (immediate, or literal with `rn` = 15 and the address resolved).
    LoadStoreDual {
        /// Load rather than store.
        load: bool,
        /// First register.
        rt: u8,
        /// Second register.
        rt2: u8,
        /// The base (15: `offset` is the absolute address).
        rn: u8,
        /// The offset, signed.
        offset: i32,
        /// Indexing and writeback.
        index: Index,
    },
    /// LDM, STM, PUSH, POP.
    Multiple {
        /// Load rather than store.
        load: bool,
        /// The base.
        rn: u8,
        /// The register list.
        list: u16,
        /// Write the base back.
        writeback: bool,
        /// Decrement before (STMDB/LDMDB, PUSH) rather than increment after.
        decrement: bool,
    },
    /// LDREX, LDREXB, LDREXH.
    LoadExclusive {
        /// Size.
        width: Width,
        /// The register loaded.
        rt: u8,
        /// The base.
        rn: u8,
        /// The offset (word forms only).
        offset: u32,
    },
    /// STREX, STREXB, STREXH.
    StoreExclusive {
        /// Size.
        width: Width,
        /// The status register (0: stored).
        rd: u8,
        /// The register stored.
        rt: u8,
        /// The base.
        rn: u8,
        /// The offset (word forms only).
        offset: u32,
    },
    /// CLREX.
    ClearExclusive,
    /// MRS.
    Mrs {
        /// Destination.
        rd: u8,
        /// The special register.
        sysm: SysReg,
    },
    /// MSR.
    Msr {
        /// Source.
        rn: u8,
        /// The special register.
        sysm: SysReg,
        /// The APSR fields written: bit 1 NZCVQ, bit 0 GE.
        mask: u8,
    },
    /// CPSIE/CPSID.
    Cps {
        /// Disable (set the mask) rather than enable.
        disable: bool,
        /// PRIMASK.
        i: bool,
        /// FAULTMASK.
        f: bool,
    },
    /// WFE.
    Wfe,
    /// WFI.
    Wfi,
    /// SEV.
    Sev,
    /// SVC.
    Svc,
    /// BKPT.
    Bkpt {
        /// The immediate.
        imm: u8,
    },
    /// Two-operand single-precision arithmetic.
    VBinary {
        /// Which.
        op: VBinary,
        /// Destination (and accumulator).
        sd: u8,
        /// First operand.
        sn: u8,
        /// Second operand.
        sm: u8,
    },
    /// One-operand single-precision operations.
    VUnary {
        /// Which.
        op: VUnary,
        /// Destination.
        sd: u8,
        /// Source.
        sm: u8,
    },
    /// VMOV (immediate).
    VMovImm {
        /// Destination.
        sd: u8,
        /// The value's bits.
        bits: u32,
    },
    /// VCMP and VCMPE (`sm` = None: compare with zero).
    VCompare {
        /// VCMPE: a quiet NaN raises Invalid Operation too.
        signal: bool,
        /// First operand.
        sd: u8,
        /// Second operand, or zero.
        sm: Option<u8>,
    },
    /// VCVT in all its forms on single precision.
    VConvert {
        /// Which.
        op: VConvert,
        /// Destination.
        sd: u8,
        /// Source.
        sm: u8,
    },
    /// VMOV between a core register and a single-precision register.
    VMovCore {
        /// To the core register.
        to_core: bool,
        /// The core register.
        rt: u8,
        /// The single-precision register.
        sn: u8,
    },
    /// VMOV between two core registers and two consecutive single registers (or one
    /// double: the same pair).
    VMovPair {
        /// To the core registers.
        to_core: bool,
        /// First core register.
        rt: u8,
        /// Second core register.
        rt2: u8,
        /// The first single-precision register.
        sm: u8,
    },
    /// VMRS (to APSR_nzcv when `rt` = 15).
    Vmrs {
        /// Destination.
        rt: u8,
    },
    /// VMSR.
    Vmsr {
        /// Source.
        rt: u8,
    },
    /// VLDR and VSTR of one single or double register.
    VLoadStore {
        /// Load rather than store.
        load: bool,
        /// The first single-precision register.
        sd: u8,
        /// Two words (a double register) rather than one.
        double: bool,
        /// The base (15: PC-relative, `offset` relative to Align(PC, 4)).
        rn: u8,
        /// The offset, signed.
        offset: i32,
    },
    /// VLDM, VSTM, VPUSH, VPOP.
    VMultiple {
        /// Load rather than store.
        load: bool,
        /// The base.
        rn: u8,
        /// The first single-precision register.
        sd: u8,
        /// The number of words.
        words: u8,
        /// Write the base back.
        writeback: bool,
        /// Decrement before rather than increment after.
        decrement: bool,
    },
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_decoded_form_stays_small() {
        // The cache holds one slot per halfword of flash for each of the car's nine MCUs:
        // a larger Op costs memory bandwidth on every instruction.
        assert!(
            core::mem::size_of::<super::Op>() <= 12,
            "{} bytes",
            core::mem::size_of::<super::Op>()
        );
    }
}
