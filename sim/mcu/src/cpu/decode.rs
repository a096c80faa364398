//! The Thumb-2 decoder of ARMv7E-M with the FPv4-SP extension (ARMv7-M Architecture
//! Reference Manual, DDI 0403E, chapters A5–A7: the tables' names are given beside each
//! group). Decodes one instruction at a known address into an [`Op`].

use super::op::*;

/// Whether a first halfword starts a 32-bit instruction (A5.1).
pub fn is_wide(hw1: u16) -> bool {
    matches!(hw1 >> 11, 0b11101..=0b11111)
}

/// Decodes the instruction at `address`: `hw2` is the next halfword (ignored for a 16-bit
/// instruction). Returns the operation and its length in bytes.
pub fn decode(hw1: u16, hw2: u16, address: u32) -> (Op, u32) {
    if is_wide(hw1) {
        (decode32(hw1 as u32, hw2 as u32, address), 4)
    } else {
        (decode16(hw1 as u32, address), 2)
    }
}

#[inline]
fn bits(x: u32, hi: u32, lo: u32) -> u32 {
    (x >> lo) & ((1 << (hi - lo + 1)) - 1)
}

#[inline]
fn bit(x: u32, n: u32) -> bool {
    (x >> n) & 1 != 0
}

fn sign_extend(value: u32, width: u32) -> u32 {
    let shift = 32 - width;
    (((value << shift) as i32) >> shift) as u32
}

/// Align(PC, 4) as PC-relative addressing reads it: the instruction's address + 4, rounded
/// down to a word.
fn literal_base(address: u32) -> u32 {
    address.wrapping_add(4) & !3
}

/// DecodeImmShift (A7.4.2).
fn imm_shift(ty: u32, imm5: u32) -> (Shift, u8) {
    match (ty, imm5) {
        (0, n) => (Shift::Lsl, n as u8),
        (1, 0) => (Shift::Lsr, 32),
        (1, n) => (Shift::Lsr, n as u8),
        (2, 0) => (Shift::Asr, 32),
        (2, n) => (Shift::Asr, n as u8),
        (_, 0) => (Shift::Rrx, 1),
        (_, n) => (Shift::Ror, n as u8),
    }
}

/// ThumbExpandImm_C (A5.3.2): the 12-bit modified immediate and its carry out.
pub fn expand_imm(imm12: u32) -> Option<(u32, ImmCarry)> {
    let imm8 = imm12 & 0xFF;
    if imm12 >> 10 == 0 {
        let value = match bits(imm12, 9, 8) {
            0 => imm8,
            // The repeated patterns are UNPREDICTABLE with a zero byte.
            1 if imm8 != 0 => (imm8 << 16) | imm8,
            2 if imm8 != 0 => (imm8 << 24) | (imm8 << 8),
            3 if imm8 != 0 => (imm8 << 24) | (imm8 << 16) | (imm8 << 8) | imm8,
            _ => return None,
        };
        Some((value, ImmCarry::Keep))
    } else {
        let unrotated = 0x80 | (imm12 & 0x7F);
        let value = unrotated.rotate_right(bits(imm12, 11, 7));
        Some((value, ImmCarry::Set(value >> 31 != 0)))
    }
}

/// VFPExpandImm for single precision (A6.4.1 of the FP chapter).
fn vfp_expand_imm(imm8: u32) -> u32 {
    let b6 = bit(imm8, 6) as u32;
    (bit(imm8, 7) as u32) << 31
        | (b6 ^ 1) << 30
        | (if b6 == 1 { 0x1F } else { 0 }) << 25
        | bits(imm8, 5, 4) << 23
        | bits(imm8, 3, 0) << 19
}

/// BadReg: SP or PC, which most 32-bit encodings forbid (LR is allowed).
fn bad(n: u32) -> bool {
    n == 13 || n == 15
}

fn reg(n: u32) -> u8 {
    n as u8
}

fn alu_imm(op: Alu, s: SetFlags, rd: u32, rn: u32, imm: u32) -> Op {
    Op::AluImm {
        op,
        s,
        rd: reg(rd),
        rn: reg(rn),
        imm,
        carry: ImmCarry::Keep,
    }
}

fn alu_reg(op: Alu, s: SetFlags, rd: u32, rn: u32, rm: u32) -> Op {
    Op::AluReg {
        op,
        s,
        rd: reg(rd),
        rn: reg(rn),
        rm: reg(rm),
        shift: Shift::Lsl,
        amount: 0,
    }
}

/// 16-bit Thumb instructions (A5.2).
fn decode16(h: u32, address: u32) -> Op {
    use SetFlags::{Always, Never, OutsideIt};
    let r0 = bits(h, 2, 0);
    let r3 = bits(h, 5, 3);
    let r6 = bits(h, 8, 6);
    let r8 = bits(h, 10, 8);
    let imm8 = bits(h, 7, 0);
    let imm5 = bits(h, 10, 6);
    match h >> 12 {
        // Shift (immediate), add, subtract, move and compare (A5.2.1).
        0b0000..=0b0011 => match bits(h, 13, 9) {
            0b00000..=0b01011 => {
                let (shift, amount) = imm_shift(bits(h, 12, 11), imm5);
                Op::AluReg {
                    op: Alu::Mov,
                    s: OutsideIt,
                    rd: reg(r0),
                    rn: 0,
                    rm: reg(r3),
                    shift,
                    amount,
                }
            }
            0b01100 => alu_reg(Alu::Add, OutsideIt, r0, r3, r6),
            0b01101 => alu_reg(Alu::Sub, OutsideIt, r0, r3, r6),
            0b01110 => alu_imm(Alu::Add, OutsideIt, r0, r3, r6),
            0b01111 => alu_imm(Alu::Sub, OutsideIt, r0, r3, r6),
            0b10000..=0b10011 => alu_imm(Alu::Mov, OutsideIt, r8, 0, imm8),
            0b10100..=0b10111 => alu_imm(Alu::Cmp, Always, 0, r8, imm8),
            0b11000..=0b11011 => alu_imm(Alu::Add, OutsideIt, r8, r8, imm8),
            _ => alu_imm(Alu::Sub, OutsideIt, r8, r8, imm8),
        },
        0b0100 => match bits(h, 11, 10) {
            // Data processing (A5.2.2).
            0b00 => {
                let shift_reg = |shift| Op::ShiftReg {
                    s: OutsideIt,
                    rd: reg(r0),
                    rn: reg(r0),
                    rm: reg(r3),
                    shift,
                };
                match bits(h, 9, 6) {
                    0b0000 => alu_reg(Alu::And, OutsideIt, r0, r0, r3),
                    0b0001 => alu_reg(Alu::Eor, OutsideIt, r0, r0, r3),
                    0b0010 => shift_reg(Shift::Lsl),
                    0b0011 => shift_reg(Shift::Lsr),
                    0b0100 => shift_reg(Shift::Asr),
                    0b0101 => alu_reg(Alu::Adc, OutsideIt, r0, r0, r3),
                    0b0110 => alu_reg(Alu::Sbc, OutsideIt, r0, r0, r3),
                    0b0111 => shift_reg(Shift::Ror),
                    0b1000 => alu_reg(Alu::Tst, Always, 0, r0, r3),
                    0b1001 => alu_imm(Alu::Rsb, OutsideIt, r0, r3, 0),
                    0b1010 => alu_reg(Alu::Cmp, Always, 0, r0, r3),
                    0b1011 => alu_reg(Alu::Cmn, Always, 0, r0, r3),
                    0b1100 => alu_reg(Alu::Orr, OutsideIt, r0, r0, r3),
                    0b1101 => Op::Mul {
                        s: OutsideIt,
                        rd: reg(r0),
                        rn: reg(r3),
                        rm: reg(r0),
                        ra: 15,
                        sub: false,
                    },
                    0b1110 => alu_reg(Alu::Bic, OutsideIt, r0, r0, r3),
                    _ => alu_reg(Alu::Mvn, OutsideIt, r0, 0, r3),
                }
            }
            // Special data instructions and branch and exchange (A5.2.3).
            0b01 => {
                let rdn = (bit(h, 7) as u32) << 3 | r0;
                let rm = bits(h, 6, 3);
                match bits(h, 9, 6) {
                    0b0000..=0b0011 if rdn == 15 && rm == 15 => Op::Unpredictable,
                    0b0000..=0b0011 => alu_reg(Alu::Add, Never, rdn, rdn, rm),
                    0b0100 => Op::Unpredictable,
                    0b0101..=0b0111 if rdn < 8 && rm < 8 => Op::Unpredictable,
                    0b0101..=0b0111 if rdn == 15 || rm == 15 => Op::Unpredictable,
                    0b0101..=0b0111 => alu_reg(Alu::Cmp, Always, 0, rdn, rm),
                    0b1000..=0b1011 => alu_reg(Alu::Mov, Never, rdn, 0, rm),
                    0b1100 | 0b1101 => Op::BranchExchange {
                        rm: reg(rm),
                        link: false,
                    },
                    _ if rm == 15 => Op::Unpredictable,
                    _ => Op::BranchExchange {
                        rm: reg(rm),
                        link: true,
                    },
                }
            }
            // LDR (literal) T1.
            _ => Op::LoadLiteral {
                width: Width::Word,
                rt: reg(r8),
                address: literal_base(address).wrapping_add(imm8 << 2),
            },
        },
        // Load/store single data item (A5.2.4).
        0b0101 => {
            let (load, width) = match bits(h, 11, 9) {
                0b000 => (false, Width::Word),
                0b001 => (false, Width::Half),
                0b010 => (false, Width::Byte),
                0b011 => (true, Width::SignedByte),
                0b100 => (true, Width::Word),
                0b101 => (true, Width::Half),
                0b110 => (true, Width::Byte),
                _ => (true, Width::SignedHalf),
            };
            Op::LoadStoreReg {
                load,
                width,
                rt: reg(r0),
                rn: reg(r3),
                rm: reg(r6),
                shift: 0,
            }
        }
        0b0110 | 0b0111 => {
            let (width, offset) = if bit(h, 12) {
                (Width::Byte, imm5)
            } else {
                (Width::Word, imm5 << 2)
            };
            Op::LoadStoreImm {
                load: bit(h, 11),
                width,
                rt: reg(r0),
                rn: reg(r3),
                offset: offset as i32,
                index: Index::Offset,
            }
        }
        0b1000 => Op::LoadStoreImm {
            load: bit(h, 11),
            width: Width::Half,
            rt: reg(r0),
            rn: reg(r3),
            offset: (imm5 << 1) as i32,
            index: Index::Offset,
        },
        0b1001 => Op::LoadStoreImm {
            load: bit(h, 11),
            width: Width::Word,
            rt: reg(r8),
            rn: 13,
            offset: (imm8 << 2) as i32,
            index: Index::Offset,
        },
        0b1010 => {
            if bit(h, 11) {
                alu_imm(Alu::Add, Never, r8, 13, imm8 << 2)
            } else {
                // ADR T1: the address, resolved now.
                alu_imm(
                    Alu::Mov,
                    Never,
                    r8,
                    0,
                    literal_base(address).wrapping_add(imm8 << 2),
                )
            }
        }
        0b1011 => decode16_misc(h, address),
        0b1100 => {
            let rn = r8;
            let list = imm8 as u16;
            if list == 0 {
                return Op::Unpredictable;
            }
            if bit(h, 11) {
                let writeback = list & (1 << rn) == 0;
                Op::Multiple {
                    load: true,
                    rn: reg(rn),
                    list,
                    writeback,
                    decrement: false,
                }
            } else {
                Op::Multiple {
                    load: false,
                    rn: reg(rn),
                    list,
                    writeback: true,
                    decrement: false,
                }
            }
        }
        0b1101 => match bits(h, 11, 8) {
            0b1110 => Op::Undefined,
            0b1111 => Op::Svc,
            cond => Op::Branch {
                cond: cond as u8,
                target: address
                    .wrapping_add(4)
                    .wrapping_add(sign_extend(imm8 << 1, 9)),
            },
        },
        0b1110 => {
            // B T2 (0b11100); 0b11101 is a 32-bit prefix and never reaches here.
            Op::Branch {
                cond: 14,
                target: address
                    .wrapping_add(4)
                    .wrapping_add(sign_extend(bits(h, 10, 0) << 1, 12)),
            }
        }
        _ => Op::Undefined,
    }
}

/// Miscellaneous 16-bit instructions (A5.2.5).
fn decode16_misc(h: u32, address: u32) -> Op {
    let rd = bits(h, 2, 0);
    let rm = bits(h, 5, 3);
    let op = bits(h, 11, 5);
    match op {
        0b0000000..=0b0000011 => alu_imm(Alu::Add, SetFlags::Never, 13, 13, bits(h, 6, 0) << 2),
        0b0000100..=0b0000111 => alu_imm(Alu::Sub, SetFlags::Never, 13, 13, bits(h, 6, 0) << 2),
        0b0001000..=0b0001111
        | 0b0011000..=0b0011111
        | 0b1001000..=0b1001111
        | 0b1011000..=0b1011111 => {
            let offset = (bit(h, 9) as u32) << 6 | bits(h, 7, 3) << 1;
            Op::CompareBranch {
                nonzero: bit(h, 11),
                rn: reg(rd),
                target: address.wrapping_add(4).wrapping_add(offset),
            }
        }
        0b0010000..=0b0010111 => {
            let op = match bits(h, 7, 6) {
                0 => Extend::Sxth,
                1 => Extend::Sxtb,
                2 => Extend::Uxth,
                _ => Extend::Uxtb,
            };
            Op::Extend {
                op,
                rd: reg(rd),
                rn: 15,
                rm: reg(rm),
                rot: 0,
            }
        }
        0b0100000..=0b0101111 => {
            let list = (bit(h, 8) as u16) << 14 | bits(h, 7, 0) as u16;
            if list == 0 {
                return Op::Unpredictable;
            }
            Op::Multiple {
                load: false,
                rn: 13,
                list,
                writeback: true,
                decrement: true,
            }
        }
        0b0110011 => {
            if bits(h, 3, 2) != 0 {
                return Op::Unpredictable;
            }
            Op::Cps {
                disable: bit(h, 4),
                i: bit(h, 1),
                f: bit(h, 0),
            }
        }
        0b1010000..=0b1010001 => Op::Unary {
            op: Unary::Rev,
            rd: reg(rd),
            rm: reg(rm),
        },
        0b1010010..=0b1010011 => Op::Unary {
            op: Unary::Rev16,
            rd: reg(rd),
            rm: reg(rm),
        },
        0b1010110..=0b1010111 => Op::Unary {
            op: Unary::Revsh,
            rd: reg(rd),
            rm: reg(rm),
        },
        0b1100000..=0b1101111 => {
            let list = (bit(h, 8) as u16) << 15 | bits(h, 7, 0) as u16;
            if list == 0 {
                return Op::Unpredictable;
            }
            Op::Multiple {
                load: true,
                rn: 13,
                list,
                writeback: true,
                decrement: false,
            }
        }
        0b1110000..=0b1110111 => Op::Bkpt {
            imm: bits(h, 7, 0) as u8,
        },
        0b1111000..=0b1111111 => {
            let first = bits(h, 7, 4);
            let mask = bits(h, 3, 0);
            if mask != 0 {
                // IT with the condition AL and more than one instruction is UNPREDICTABLE,
                // as is 0b1111.
                if first == 0b1111 || (first == 0b1110 && mask.count_ones() != 1) {
                    return Op::Unpredictable;
                }
                return Op::It {
                    state: (h & 0xFF) as u8,
                };
            }
            match first {
                0b0010 => Op::Wfe,
                0b0011 => Op::Wfi,
                0b0100 => Op::Sev,
                _ => Op::Nop,
            }
        }
        _ => Op::Undefined,
    }
}

/// 32-bit Thumb instructions (A5.3).
fn decode32(h1: u32, h2: u32, address: u32) -> Op {
    let op1 = bits(h1, 12, 11);
    let op2 = bits(h1, 10, 4);
    match op1 {
        0b01 => {
            if op2 & 0b1100100 == 0 {
                decode_multiple(h1, h2)
            } else if op2 & 0b1100100 == 0b0000100 {
                decode_dual_exclusive(h1, h2, address)
            } else if op2 & 0b1100000 == 0b0100000 {
                decode_shifted_register(h1, h2)
            } else {
                decode_coprocessor(h1, h2, address)
            }
        }
        0b10 => {
            if bit(h2, 15) {
                decode_branch_misc(h1, h2, address)
            } else if op2 & 0b0100000 == 0 {
                decode_modified_immediate(h1, h2)
            } else {
                decode_plain_immediate(h1, h2, address)
            }
        }
        _ => {
            if op2 & 0b1110001 == 0 {
                decode_load_store(h1, h2, address, false)
            } else if op2 & 0b1100001 == 0b0000001 {
                if op2 & 0b110 == 0b110 {
                    Op::Undefined
                } else {
                    decode_load_store(h1, h2, address, true)
                }
            } else if op2 & 0b1110000 == 0b0100000 {
                decode_register(h1, h2)
            } else if op2 & 0b1111000 == 0b0110000 {
                decode_multiply(h1, h2)
            } else if op2 & 0b1111000 == 0b0111000 {
                decode_long_multiply(h1, h2)
            } else if op2 & 0b1000000 != 0 {
                decode_coprocessor(h1, h2, address)
            } else {
                Op::Undefined
            }
        }
    }
}

/// Load Multiple and Store Multiple (A5.3.5).
fn decode_multiple(h1: u32, h2: u32) -> Op {
    let rn = bits(h1, 3, 0);
    let load = bit(h1, 4);
    let writeback = bit(h1, 5);
    let decrement = match bits(h1, 8, 7) {
        0b01 => false,
        0b10 => true,
        _ => return Op::Undefined,
    };
    let list = h2 as u16;
    // Rules of LDM/STM T2 (A7.7.40, A7.7.159): at least two registers, no SP, no PC in a
    // store, not both PC and LR in a load, no base in the list with writeback.
    if rn == 15 || list.count_ones() < 2 || list & (1 << 13) != 0 {
        return Op::Unpredictable;
    }
    if load && list & 0xC000 == 0xC000 {
        return Op::Unpredictable;
    }
    if !load && list & 0x8000 != 0 {
        return Op::Unpredictable;
    }
    if writeback && list & (1 << rn) != 0 {
        return Op::Unpredictable;
    }
    Op::Multiple {
        load,
        rn: reg(rn),
        list,
        writeback,
        decrement,
    }
}

/// Load/store dual, exclusive, table branch (A5.3.6).
fn decode_dual_exclusive(h1: u32, h2: u32, address: u32) -> Op {
    let rn = bits(h1, 3, 0);
    let rt = bits(h2, 15, 12);
    let rt2 = bits(h2, 11, 8);
    let imm8 = bits(h2, 7, 0);
    let op1 = bits(h1, 8, 7);
    let op2 = bits(h1, 5, 4);
    match (op1, op2) {
        (0b00, 0b00) => {
            let rd = rt2;
            if rd == rn || rd == rt || bad(rd) || bad(rt) || rn == 15 {
                return Op::Unpredictable;
            }
            Op::StoreExclusive {
                width: Width::Word,
                rd: reg(rd),
                rt: reg(rt),
                rn: reg(rn),
                offset: imm8 << 2,
            }
        }
        (0b00, 0b01) => {
            if bad(rt) || rn == 15 {
                return Op::Unpredictable;
            }
            Op::LoadExclusive {
                width: Width::Word,
                rt: reg(rt),
                rn: reg(rn),
                offset: imm8 << 2,
            }
        }
        (0b01, 0b00) => {
            let rd = bits(h2, 3, 0);
            let width = match bits(h2, 7, 4) {
                0b0100 => Width::Byte,
                0b0101 => Width::Half,
                _ => return Op::Undefined,
            };
            if rd == rn || rd == rt || bad(rd) || bad(rt) || rn == 15 {
                return Op::Unpredictable;
            }
            Op::StoreExclusive {
                width,
                rd: reg(rd),
                rt: reg(rt),
                rn: reg(rn),
                offset: 0,
            }
        }
        (0b01, 0b01) => {
            let rm = bits(h2, 3, 0);
            match bits(h2, 7, 4) {
                0b0000 | 0b0001 => {
                    if rn == 13 || bad(rm) {
                        return Op::Unpredictable;
                    }
                    Op::TableBranch {
                        half: bit(h2, 4),
                        rn: reg(rn),
                        rm: reg(rm),
                    }
                }
                0b0100 | 0b0101 => {
                    if bad(rt) || rn == 15 {
                        return Op::Unpredictable;
                    }
                    let width = if bit(h2, 4) { Width::Half } else { Width::Byte };
                    Op::LoadExclusive {
                        width,
                        rt: reg(rt),
                        rn: reg(rn),
                        offset: 0,
                    }
                }
                _ => Op::Undefined,
            }
        }
        _ => {
            // LDRD/STRD (immediate, literal).
            let load = bit(h1, 4);
            let pre = bit(h1, 8);
            let add = bit(h1, 7);
            let wback = bit(h1, 5);
            let offset = if add {
                (imm8 << 2) as i32
            } else {
                -((imm8 << 2) as i32)
            };
            let index = match (pre, wback) {
                (true, false) => Index::Offset,
                (true, true) => Index::Pre,
                (false, true) => Index::Post,
                (false, false) => return Op::Undefined,
            };
            if wback && (rn == rt || rn == rt2) {
                return Op::Unpredictable;
            }
            if bad(rt) || bad(rt2) || (load && rt == rt2) {
                return Op::Unpredictable;
            }
            if rn == 15 {
                if !load || wback {
                    return Op::Unpredictable;
                }
                let target = literal_base(address).wrapping_add(offset as u32);
                return Op::LoadStoreDual {
                    load,
                    rt: reg(rt),
                    rt2: reg(rt2),
                    rn: 15,
                    offset: target as i32,
                    index,
                };
            }
            Op::LoadStoreDual {
                load,
                rt: reg(rt),
                rt2: reg(rt2),
                rn: reg(rn),
                offset,
                index,
            }
        }
    }
}

/// The opcode table shared by the modified-immediate and shifted-register forms (A5.3.1,
/// A5.3.11): the operation, and whether Rd = 15 with S makes it a compare (TST, TEQ,
/// CMN, CMP), and Rn = 15 a move (MOV, MVN).
fn dp_opcode(op: u32, rd: u32, rn: u32, s: bool) -> Option<(Alu, bool)> {
    let compare = rd == 15 && s;
    Some(match op {
        0b0000 if compare => (Alu::Tst, true),
        0b0000 => (Alu::And, false),
        0b0001 => (Alu::Bic, false),
        0b0010 if rn == 15 => (Alu::Mov, false),
        0b0010 => (Alu::Orr, false),
        0b0011 if rn == 15 => (Alu::Mvn, false),
        0b0011 => (Alu::Orn, false),
        0b0100 if compare => (Alu::Teq, true),
        0b0100 => (Alu::Eor, false),
        0b1000 if compare => (Alu::Cmn, true),
        0b1000 => (Alu::Add, false),
        0b1010 => (Alu::Adc, false),
        0b1011 => (Alu::Sbc, false),
        0b1101 if compare => (Alu::Cmp, true),
        0b1101 => (Alu::Sub, false),
        0b1110 => (Alu::Rsb, false),
        _ => return None,
    })
}

/// Register rules of the 32-bit data-processing forms: SP only where the manual allows it
/// (ADD/SUB/CMP/CMN/MOV with SP), PC never.
fn dp_registers_ok(op: Alu, rd: u32, rn: u32, rm: Option<u32>) -> bool {
    let sp_ok = matches!(op, Alu::Add | Alu::Sub | Alu::Cmp | Alu::Cmn | Alu::Mov);
    let bad = |r: u32| r == 15 || (r == 13 && !sp_ok);
    let writes = !matches!(op, Alu::Tst | Alu::Teq | Alu::Cmp | Alu::Cmn);
    let reads_n = !matches!(op, Alu::Mov | Alu::Mvn);
    if writes && bad(rd) {
        return false;
    }
    // ADD/SUB with Rd = SP need Rn = SP.
    if writes && rd == 13 && matches!(op, Alu::Add | Alu::Sub) && rn != 13 {
        return false;
    }
    if reads_n && bad(rn) {
        return false;
    }
    match rm {
        // Rm may never be SP or PC in the shifted-register forms (MOV with SP is the
        // 16-bit form's), except as the manual allows for ADD/SUB/CMP... conservatively none.
        Some(rm) => !bad(rm),
        None => true,
    }
}

/// Data processing (shifted register) (A5.3.11).
fn decode_shifted_register(h1: u32, h2: u32) -> Op {
    let op = bits(h1, 8, 5);
    let s = bit(h1, 4);
    let rn = bits(h1, 3, 0);
    let rd = bits(h2, 11, 8);
    let rm = bits(h2, 3, 0);
    let imm5 = bits(h2, 14, 12) << 2 | bits(h2, 7, 6);
    let ty = bits(h2, 5, 4);
    if op == 0b0110 {
        if s || bit(h2, 4) || bad(rd) || bad(rn) || bad(rm) {
            return if s || bit(h2, 4) {
                Op::Undefined
            } else {
                Op::Unpredictable
            };
        }
        let tb = bit(h2, 5);
        let amount = if tb && imm5 == 0 { 32 } else { imm5 as u8 };
        return Op::Pack {
            tb,
            rd: reg(rd),
            rn: reg(rn),
            rm: reg(rm),
            amount,
        };
    }
    let Some((alu, _)) = dp_opcode(op, rd, rn, s) else {
        return Op::Undefined;
    };
    if !dp_registers_ok(alu, rd, rn, Some(rm)) {
        return Op::Unpredictable;
    }
    let (shift, amount) = imm_shift(ty, imm5);
    let s = if s { SetFlags::Always } else { SetFlags::Never };
    Op::AluReg {
        op: alu,
        s,
        rd: reg(rd),
        rn: reg(rn),
        rm: reg(rm),
        shift,
        amount,
    }
}

/// Data processing (modified immediate) (A5.3.1).
fn decode_modified_immediate(h1: u32, h2: u32) -> Op {
    let op = bits(h1, 8, 5);
    let s = bit(h1, 4);
    let rn = bits(h1, 3, 0);
    let rd = bits(h2, 11, 8);
    let imm12 = (bit(h1, 10) as u32) << 11 | bits(h2, 14, 12) << 8 | bits(h2, 7, 0);
    let Some((alu, _)) = dp_opcode(op, rd, rn, s) else {
        return Op::Undefined;
    };
    if !dp_registers_ok(alu, rd, rn, None) {
        return Op::Unpredictable;
    }
    let Some((imm, carry)) = expand_imm(imm12) else {
        return Op::Unpredictable;
    };
    let s = if s { SetFlags::Always } else { SetFlags::Never };
    Op::AluImm {
        op: alu,
        s,
        rd: reg(rd),
        rn: reg(rn),
        imm,
        carry,
    }
}

/// Data processing (plain binary immediate) (A5.3.3).
fn decode_plain_immediate(h1: u32, h2: u32, address: u32) -> Op {
    let op = bits(h1, 8, 4);
    let rn = bits(h1, 3, 0);
    let rd = bits(h2, 11, 8);
    let imm3_2 = bits(h2, 14, 12) << 2 | bits(h2, 7, 6);
    let imm12 = (bit(h1, 10) as u32) << 11 | bits(h2, 14, 12) << 8 | bits(h2, 7, 0);
    let imm16 = rn << 12 | imm12;
    let low5 = bits(h2, 4, 0);
    let plain_rd_ok = !bad(rd);
    match op {
        0b00000 | 0b01010 => {
            let sub = op == 0b01010;
            if rn == 15 {
                // ADR T2/T3, resolved now.
                if !plain_rd_ok {
                    return Op::Unpredictable;
                }
                let base = literal_base(address);
                let value = if sub {
                    base.wrapping_sub(imm12)
                } else {
                    base.wrapping_add(imm12)
                };
                return alu_imm(Alu::Mov, SetFlags::Never, rd, 0, value);
            }
            // ADDW/SUBW: Rd = SP only with Rn = SP.
            if rd == 15 || (rd == 13 && rn != 13) {
                return Op::Unpredictable;
            }
            alu_imm(
                if sub { Alu::Sub } else { Alu::Add },
                SetFlags::Never,
                rd,
                rn,
                imm12,
            )
        }
        0b00100 => {
            if !plain_rd_ok {
                return Op::Unpredictable;
            }
            alu_imm(Alu::Mov, SetFlags::Never, rd, 0, imm16)
        }
        0b01100 => {
            if !plain_rd_ok {
                return Op::Unpredictable;
            }
            Op::Movt {
                rd: reg(rd),
                imm: imm16 as u16,
            }
        }
        0b10000 | 0b10010 | 0b11000 | 0b11010 => {
            let signed = op & 0b01000 == 0;
            let asr = bit(h1, 5);
            if !plain_rd_ok || bad(rn) {
                return Op::Unpredictable;
            }
            if asr && imm3_2 == 0 {
                // SSAT16 / USAT16.
                if bits(h2, 5, 4) != 0 {
                    return Op::Undefined;
                }
                let bits16 = bits(h2, 3, 0);
                return Op::Saturate16 {
                    signed,
                    rd: reg(rd),
                    rn: reg(rn),
                    bits: (bits16 + signed as u32) as u8,
                };
            }
            let (shift, amount) = if asr {
                (Shift::Asr, imm3_2 as u8)
            } else {
                (Shift::Lsl, imm3_2 as u8)
            };
            Op::Saturate {
                signed,
                rd: reg(rd),
                rn: reg(rn),
                bits: (low5 + signed as u32) as u8,
                shift,
                amount,
            }
        }
        0b10100 | 0b11100 => {
            let width = low5 + 1;
            if !plain_rd_ok || bad(rn) || imm3_2 + width > 32 {
                return Op::Unpredictable;
            }
            let op = if op == 0b10100 {
                BitField::Sbfx
            } else {
                BitField::Ubfx
            };
            Op::BitField {
                op,
                rd: reg(rd),
                rn: reg(rn),
                lsb: imm3_2 as u8,
                width: width as u8,
            }
        }
        0b10110 => {
            if !plain_rd_ok || rn == 13 || low5 < imm3_2 {
                return Op::Unpredictable;
            }
            Op::BitField {
                op: BitField::Insert,
                rd: reg(rd),
                rn: reg(rn),
                lsb: imm3_2 as u8,
                width: (low5 - imm3_2 + 1) as u8,
            }
        }
        _ => Op::Undefined,
    }
}

/// Branches and miscellaneous control (A5.3.4).
fn decode_branch_misc(h1: u32, h2: u32, address: u32) -> Op {
    let op = bits(h1, 10, 4);
    let op1 = bits(h2, 14, 12);
    let s = bit(h1, 10) as u32;
    let j1 = bit(h2, 13) as u32;
    let j2 = bit(h2, 11) as u32;
    let next = address.wrapping_add(4);
    if op1 & 0b101 == 0b000 {
        if op & 0b0111000 != 0b0111000 {
            let offset =
                s << 20 | j2 << 19 | j1 << 18 | bits(h1, 5, 0) << 12 | bits(h2, 10, 0) << 1;
            return Op::Branch {
                cond: bits(h1, 9, 6) as u8,
                target: next.wrapping_add(sign_extend(offset, 21)),
            };
        }
        return match op {
            0b0111000 | 0b0111001 => {
                let rn = bits(h1, 3, 0);
                let sysm = bits(h2, 7, 0) as u8;
                let mask = bits(h2, 11, 10) as u8;
                if bad(rn) {
                    return Op::Unpredictable;
                }
                if sysm <= 3 && mask == 0 {
                    return Op::Unpredictable;
                }
                Op::Msr {
                    rn: reg(rn),
                    sysm,
                    mask,
                }
            }
            0b0111010 => match bits(h2, 7, 0) {
                2 => Op::Wfe,
                3 => Op::Wfi,
                4 => Op::Sev,
                _ => Op::Nop,
            },
            0b0111011 => match bits(h2, 7, 4) {
                0b0010 => Op::ClearExclusive,
                0b0100 | 0b0101 => Op::Nop,
                0b0110 => Op::Isb,
                _ => Op::Undefined,
            },
            0b0111110 | 0b0111111 => {
                let rd = bits(h2, 11, 8);
                if bad(rd) {
                    return Op::Unpredictable;
                }
                Op::Mrs {
                    rd: reg(rd),
                    sysm: bits(h2, 7, 0) as u8,
                }
            }
            _ => Op::Undefined,
        };
    }
    if op1 == 0b010 {
        return Op::Undefined;
    }
    let i1 = (j1 ^ s) ^ 1;
    let i2 = (j2 ^ s) ^ 1;
    let offset = s << 24 | i1 << 23 | i2 << 22 | bits(h1, 9, 0) << 12 | bits(h2, 10, 0) << 1;
    let target = next.wrapping_add(sign_extend(offset, 25));
    match op1 {
        0b001 | 0b011 => Op::Branch { cond: 14, target },
        0b101 | 0b111 => Op::BranchLink { target },
        _ => Op::Undefined,
    }
}

/// Store single data item, load byte/halfword/word (A5.3.10, A5.3.9, A5.3.8, A5.3.7).
fn decode_load_store(h1: u32, h2: u32, address: u32, load: bool) -> Op {
    let rn = bits(h1, 3, 0);
    let rt = bits(h2, 15, 12);
    let signed = bit(h1, 8);
    let width = match (bits(h1, 6, 5), signed) {
        (0, false) => Width::Byte,
        (0, true) => Width::SignedByte,
        (1, false) => Width::Half,
        (1, true) => Width::SignedHalf,
        (2, false) => Width::Word,
        _ => return Op::Undefined,
    };
    if !load && signed {
        return Op::Undefined;
    }
    // Loads of bytes and halfwords to PC are the preload hints.
    let hint = load && rt == 15 && width != Width::Word;
    if load && rn == 15 {
        if hint {
            return Op::Nop;
        }
        let imm12 = bits(h2, 11, 0);
        let base = literal_base(address);
        let target = if bit(h1, 7) {
            base.wrapping_add(imm12)
        } else {
            base.wrapping_sub(imm12)
        };
        return Op::LoadLiteral {
            width,
            rt: reg(rt),
            address: target,
        };
    }
    if rn == 15 {
        return Op::Undefined;
    }
    let (op, writeback) = if bit(h1, 7) {
        let offset = bits(h2, 11, 0) as i32;
        (
            Op::LoadStoreImm {
                load,
                width,
                rt: reg(rt),
                rn: reg(rn),
                offset,
                index: Index::Offset,
            },
            false,
        )
    } else if bit(h2, 11) {
        let imm8 = bits(h2, 7, 0) as i32;
        let (pre, add, wback) = (bit(h2, 10), bit(h2, 9), bit(h2, 8));
        let offset = if add { imm8 } else { -imm8 };
        let index = match (pre, wback) {
            (true, false) => Index::Offset,
            (true, true) => Index::Pre,
            (false, true) => Index::Post,
            (false, false) => return Op::Undefined,
        };
        (
            Op::LoadStoreImm {
                load,
                width,
                rt: reg(rt),
                rn: reg(rn),
                offset,
                index,
            },
            wback,
        )
    } else if bits(h2, 11, 6) == 0 {
        let rm = bits(h2, 3, 0);
        if bad(rm) {
            return Op::Unpredictable;
        }
        (
            Op::LoadStoreReg {
                load,
                width,
                rt: reg(rt),
                rn: reg(rn),
                rm: reg(rm),
                shift: bits(h2, 5, 4) as u8,
            },
            false,
        )
    } else {
        return Op::Undefined;
    };
    if hint {
        return if writeback {
            Op::Unpredictable
        } else {
            Op::Nop
        };
    }
    if writeback && rn == rt {
        return Op::Unpredictable;
    }
    // PC as the register stored, or as a byte/halfword load's target, is UNPREDICTABLE; SP
    // likewise for the byte and halfword forms.
    if (!load && rt == 15) || (width != Width::Word && rt == 13) {
        return Op::Unpredictable;
    }
    op
}

/// Data processing (register) (A5.3.12) with the parallel add/subtract (A5.3.13–14) and
/// the miscellaneous operations (A5.3.15).
fn decode_register(h1: u32, h2: u32) -> Op {
    let op1 = bits(h1, 7, 4);
    let op2 = bits(h2, 7, 4);
    let rn = bits(h1, 3, 0);
    let rd = bits(h2, 11, 8);
    let rm = bits(h2, 3, 0);
    if bits(h2, 15, 12) != 0b1111 {
        return Op::Undefined;
    }
    if bad(rd) || bad(rm) || (bad(rn) && !(op1 < 0b1000 && op2 >= 0b1000 && rn == 15)) {
        return Op::Unpredictable;
    }
    if op1 < 0b1000 && op2 == 0 {
        let shift = match op1 >> 1 {
            0 => Shift::Lsl,
            1 => Shift::Lsr,
            2 => Shift::Asr,
            _ => Shift::Ror,
        };
        let s = if op1 & 1 != 0 {
            SetFlags::Always
        } else {
            SetFlags::Never
        };
        return Op::ShiftReg {
            s,
            rd: reg(rd),
            rn: reg(rn),
            rm: reg(rm),
            shift,
        };
    }
    if op1 < 0b1000 && op2 >= 0b1000 {
        let ext = match op1 {
            0b0000 => Extend::Sxth,
            0b0001 => Extend::Uxth,
            0b0010 => Extend::Sxtb16,
            0b0011 => Extend::Uxtb16,
            0b0100 => Extend::Sxtb,
            0b0101 => Extend::Uxtb,
            _ => return Op::Undefined,
        };
        if bit(h2, 6) {
            return Op::Undefined;
        }
        return Op::Extend {
            op: ext,
            rd: reg(rd),
            rn: reg(rn),
            rm: reg(rm),
            rot: (bits(h2, 5, 4) << 3) as u8,
        };
    }
    if op1 >= 0b1000 && op2 < 0b1000 {
        let op = match bits(h1, 6, 4) {
            0b001 => LaneOp::Add16,
            0b010 => LaneOp::Asx,
            0b110 => LaneOp::Sax,
            0b101 => LaneOp::Sub16,
            0b000 => LaneOp::Add8,
            0b100 => LaneOp::Sub8,
            _ => return Op::Undefined,
        };
        let lanes = match (bit(h2, 6), bits(h2, 5, 4)) {
            (false, 0) => Lanes::Signed,
            (false, 1) => Lanes::SignedSat,
            (false, 2) => Lanes::SignedHalving,
            (true, 0) => Lanes::Unsigned,
            (true, 1) => Lanes::UnsignedSat,
            (true, 2) => Lanes::UnsignedHalving,
            _ => return Op::Undefined,
        };
        return Op::Parallel {
            lanes,
            op,
            rd: reg(rd),
            rn: reg(rn),
            rm: reg(rm),
        };
    }
    if op1 & 0b1100 == 0b1000 && op2 & 0b1100 == 0b1000 {
        let (a, b) = (bits(h1, 5, 4), bits(h2, 5, 4));
        // The one-register operations repeat Rm in the Rn field.
        let one = |op| {
            if rn == rm {
                Op::Unary {
                    op,
                    rd: reg(rd),
                    rm: reg(rm),
                }
            } else {
                Op::Unpredictable
            }
        };
        return match (a, b) {
            (0, 0) => Op::SatArith {
                op: SatArith::Qadd,
                rd: reg(rd),
                rn: reg(rn),
                rm: reg(rm),
            },
            (0, 1) => Op::SatArith {
                op: SatArith::Qdadd,
                rd: reg(rd),
                rn: reg(rn),
                rm: reg(rm),
            },
            (0, 2) => Op::SatArith {
                op: SatArith::Qsub,
                rd: reg(rd),
                rn: reg(rn),
                rm: reg(rm),
            },
            (0, 3) => Op::SatArith {
                op: SatArith::Qdsub,
                rd: reg(rd),
                rn: reg(rn),
                rm: reg(rm),
            },
            (1, 0) => one(Unary::Rev),
            (1, 1) => one(Unary::Rev16),
            (1, 2) => one(Unary::Rbit),
            (1, 3) => one(Unary::Revsh),
            (2, 0) => Op::Sel {
                rd: reg(rd),
                rn: reg(rn),
                rm: reg(rm),
            },
            (3, 0) => one(Unary::Clz),
            _ => Op::Undefined,
        };
    }
    Op::Undefined
}

/// Multiply, multiply accumulate, and absolute difference (A5.3.16).
fn decode_multiply(h1: u32, h2: u32) -> Op {
    let op1 = bits(h1, 6, 4);
    let op2 = bits(h2, 5, 4);
    let rn = bits(h1, 3, 0);
    let ra = bits(h2, 15, 12);
    let rd = bits(h2, 11, 8);
    let rm = bits(h2, 3, 0);
    if bits(h2, 7, 6) != 0 {
        return Op::Undefined;
    }
    if bad(rd) || bad(rn) || bad(rm) || ra == 13 {
        return Op::Unpredictable;
    }
    let dsp = |op, n_top, m_top, round| Op::DspMul {
        op,
        rd: reg(rd),
        rn: reg(rn),
        rm: reg(rm),
        ra: reg(ra),
        n_top,
        m_top,
        round,
    };
    match (op1, op2) {
        (0b000, 0b00) => Op::Mul {
            s: SetFlags::Never,
            rd: reg(rd),
            rn: reg(rn),
            rm: reg(rm),
            ra: reg(ra),
            sub: false,
        },
        (0b000, 0b01) if ra != 15 => Op::Mul {
            s: SetFlags::Never,
            rd: reg(rd),
            rn: reg(rn),
            rm: reg(rm),
            ra: reg(ra),
            sub: true,
        },
        (0b001, _) => dsp(DspMul::Halves, bit(h2, 5), bit(h2, 4), false),
        (0b010, 0b00 | 0b01) => dsp(DspMul::DualAdd, false, bit(h2, 4), false),
        (0b011, 0b00 | 0b01) => dsp(DspMul::Wide, false, bit(h2, 4), false),
        (0b100, 0b00 | 0b01) => dsp(DspMul::DualSub, false, bit(h2, 4), false),
        (0b101, 0b00 | 0b01) => dsp(DspMul::MostAdd, false, false, bit(h2, 4)),
        (0b110, 0b00 | 0b01) if ra != 15 => dsp(DspMul::MostSub, false, false, bit(h2, 4)),
        (0b111, 0b00) => Op::Usad8 {
            rd: reg(rd),
            rn: reg(rn),
            rm: reg(rm),
            ra: reg(ra),
        },
        _ => Op::Undefined,
    }
}

/// Long multiply, long multiply accumulate, and divide (A5.3.17).
fn decode_long_multiply(h1: u32, h2: u32) -> Op {
    let op1 = bits(h1, 6, 4);
    let op2 = bits(h2, 7, 4);
    let rn = bits(h1, 3, 0);
    let rdlo = bits(h2, 15, 12);
    let rdhi = bits(h2, 11, 8);
    let rm = bits(h2, 3, 0);
    if op1 == 0b001 || op1 == 0b011 {
        if op2 != 0b1111 {
            return Op::Undefined;
        }
        if rdlo != 0b1111 || bad(rdhi) || bad(rn) || bad(rm) {
            return Op::Unpredictable;
        }
        return Op::Div {
            signed: op1 == 0b001,
            rd: reg(rdhi),
            rn: reg(rn),
            rm: reg(rm),
        };
    }
    if bad(rdlo) || bad(rdhi) || bad(rn) || bad(rm) || rdlo == rdhi {
        return Op::Unpredictable;
    }
    let long = |kind| Op::LongMul {
        kind,
        rdlo: reg(rdlo),
        rdhi: reg(rdhi),
        rn: reg(rn),
        rm: reg(rm),
    };
    let dsp = |op, n_top, m_top| Op::DspLong {
        op,
        rdlo: reg(rdlo),
        rdhi: reg(rdhi),
        rn: reg(rn),
        rm: reg(rm),
        n_top,
        m_top,
    };
    match (op1, op2) {
        (0b000, 0b0000) => long(LongMul::Smull),
        (0b010, 0b0000) => long(LongMul::Umull),
        (0b100, 0b0000) => long(LongMul::Smlal),
        (0b100, 0b1000..=0b1011) => dsp(DspLong::Halves, bit(h2, 5), bit(h2, 4)),
        (0b100, 0b1100 | 0b1101) => dsp(DspLong::DualAdd, false, bit(h2, 4)),
        (0b101, 0b1100 | 0b1101) => dsp(DspLong::DualSub, false, bit(h2, 4)),
        (0b110, 0b0000) => long(LongMul::Umlal),
        (0b110, 0b0110) => long(LongMul::Umaal),
        _ => Op::Undefined,
    }
}

/// Coprocessor instructions (A5.3.18): the FPU's (coprocessors 10 and 11, A6.4–A6.6);
/// any other coprocessor is absent on the Cortex-M4.
fn decode_coprocessor(h1: u32, h2: u32, address: u32) -> Op {
    if bits(h2, 11, 9) != 0b101 {
        return if bits(h1, 9, 4) & 0b111110 == 0 {
            Op::Undefined
        } else {
            Op::NoCoprocessor
        };
    }
    // The T2 forms (first halfword 0xFxxx) of coprocessors 10 and 11 are Advanced SIMD,
    // which the M profile does not have.
    if bit(h1, 12) {
        return Op::Undefined;
    }
    let op1 = bits(h1, 9, 4);
    let double = bit(h2, 8);
    if op1 & 0b111110 == 0 {
        return Op::Undefined;
    }
    if op1 & 0b111110 == 0b000100 {
        // 64-bit transfers between core and extension registers (A6.6).
        let to_core = bit(h1, 4);
        let rt = bits(h2, 15, 12);
        let rt2 = bits(h1, 3, 0);
        let (vm, m) = (bits(h2, 3, 0), bit(h2, 5) as u32);
        let sm = if double {
            (m << 4 | vm) * 2
        } else {
            vm << 1 | m
        };
        if bits(h2, 7, 6) != 0 || !bit(h2, 4) {
            return Op::Undefined;
        }
        if bad(rt) || bad(rt2) || sm == 31 || (to_core && rt == rt2) {
            return Op::Unpredictable;
        }
        return Op::VMovPair {
            to_core,
            rt: reg(rt),
            rt2: reg(rt2),
            sm: sm as u8,
        };
    }
    if op1 & 0b100000 == 0 {
        return decode_vfp_load_store(h1, h2, address);
    }
    if op1 & 0b110000 != 0b100000 {
        return Op::Undefined;
    }
    if bit(h2, 4) {
        decode_vfp_transfer(h1, h2)
    } else {
        decode_vfp_data(h1, h2)
    }
}

/// Extension register load/store (A6.5).
fn decode_vfp_load_store(h1: u32, h2: u32, address: u32) -> Op {
    let (p, u, w, load) = (bit(h1, 8), bit(h1, 7), bit(h1, 5), bit(h1, 4));
    let rn = bits(h1, 3, 0);
    let d = bit(h1, 6) as u32;
    let vd = bits(h2, 15, 12);
    let double = bit(h2, 8);
    let imm8 = bits(h2, 7, 0);
    let sd = if double {
        (d << 4 | vd) * 2
    } else {
        vd << 1 | d
    };
    if p && !w {
        // VLDR/VSTR.
        let offset = if u {
            (imm8 << 2) as i32
        } else {
            -((imm8 << 2) as i32)
        };
        if rn == 15 {
            if !load {
                return Op::Unpredictable;
            }
            let target = literal_base(address).wrapping_add(offset as u32);
            return Op::VLoadStore {
                load,
                sd: sd as u8,
                double,
                rn: 15,
                offset: target as i32,
            };
        }
        return Op::VLoadStore {
            load,
            sd: sd as u8,
            double,
            rn: reg(rn),
            offset,
        };
    }
    if p == u {
        return Op::Undefined;
    }
    let decrement = p;
    if decrement && !w {
        return Op::Undefined;
    }
    // An odd count with double registers is FLDMX/FSTMX, deprecated and UNPREDICTABLE-ish on
    // M profile.
    if imm8 == 0 || (double && imm8 & 1 != 0) || rn == 15 {
        return Op::Unpredictable;
    }
    if sd + imm8 > 32 {
        return Op::Unpredictable;
    }
    Op::VMultiple {
        load,
        rn: reg(rn),
        sd: sd as u8,
        words: imm8 as u8,
        writeback: w,
        decrement,
    }
}

/// 8, 16 and 32-bit transfers between core and extension registers (A6.7).
fn decode_vfp_transfer(h1: u32, h2: u32) -> Op {
    let a = bits(h1, 7, 5);
    let load = bit(h1, 4);
    let c = bit(h2, 8);
    let rt = bits(h2, 15, 12);
    if bits(h2, 6, 5) != 0 || bits(h2, 3, 0) != 0 {
        return Op::Undefined;
    }
    if !c && a == 0b000 {
        if bad(rt) {
            return Op::Unpredictable;
        }
        let sn = bits(h1, 3, 0) << 1 | bit(h2, 7) as u32;
        return Op::VMovCore {
            to_core: load,
            rt: reg(rt),
            sn: sn as u8,
        };
    }
    if !c && a == 0b111 {
        if bits(h1, 3, 0) != 0b0001 {
            // Only FPSCR is reachable on the M profile.
            return Op::Undefined;
        }
        if load {
            return if rt == 13 {
                Op::Unpredictable
            } else {
                Op::Vmrs { rt: reg(rt) }
            };
        }
        return if bad(rt) {
            Op::Unpredictable
        } else {
            Op::Vmsr { rt: reg(rt) }
        };
    }
    if c && a & 0b110 == 0 {
        // VMOV between a core register and a 32-bit scalar of a double register.
        if bad(rt) {
            return Op::Unpredictable;
        }
        let dreg = (bit(h2, 7) as u32) << 4 | bits(h1, 3, 0);
        if dreg >= 16 {
            return Op::Undefined;
        }
        let sn = dreg * 2 + bit(h1, 5) as u32;
        return Op::VMovCore {
            to_core: load,
            rt: reg(rt),
            sn: sn as u8,
        };
    }
    Op::Undefined
}

/// Floating-point data processing (A6.4).
fn decode_vfp_data(h1: u32, h2: u32) -> Op {
    let opc1 = bits(h1, 7, 4) & 0b1011;
    let opc2 = bits(h1, 3, 0);
    let opc3 = bits(h2, 7, 6);
    let double = bit(h2, 8);
    let sd = (bits(h2, 15, 12) << 1 | bit(h1, 6) as u32) as u8;
    let sn = (bits(h1, 3, 0) << 1 | bit(h2, 7) as u32) as u8;
    let sm = (bits(h2, 3, 0) << 1 | bit(h2, 5) as u32) as u8;
    let op6 = bit(h2, 6);
    // FPv4-SP has no double-precision arithmetic: every sz = 1 form is UNDEFINED.
    if double {
        return Op::Undefined;
    }
    let binary = |op| Op::VBinary { op, sd, sn, sm };
    match opc1 {
        0b0000 => binary(if op6 { VBinary::Mls } else { VBinary::Mla }),
        0b0001 => binary(if op6 { VBinary::Nmla } else { VBinary::Nmls }),
        0b0010 => binary(if op6 { VBinary::Nmul } else { VBinary::Mul }),
        0b0011 => binary(if op6 { VBinary::Sub } else { VBinary::Add }),
        0b1000 if !op6 => binary(VBinary::Div),
        0b1001 => binary(if op6 { VBinary::Fnma } else { VBinary::Fnms }),
        0b1010 => binary(if op6 { VBinary::Fms } else { VBinary::Fma }),
        0b1011 => {
            if opc3 & 1 == 0 {
                if bits(h2, 7, 4) & 0b1011 != 0 {
                    return Op::Undefined;
                }
                return Op::VMovImm {
                    sd,
                    bits: vfp_expand_imm(opc2 << 4 | bits(h2, 3, 0)),
                };
            }
            let top = bit(h2, 7);
            match opc2 {
                0b0000 => Op::VUnary {
                    op: if top { VUnary::Abs } else { VUnary::Mov },
                    sd,
                    sm,
                },
                0b0001 => Op::VUnary {
                    op: if top { VUnary::Sqrt } else { VUnary::Neg },
                    sd,
                    sm,
                },
                0b0010 => Op::VConvert {
                    op: VConvert::FromHalf { top },
                    sd,
                    sm,
                },
                0b0011 => Op::VConvert {
                    op: VConvert::ToHalf { top },
                    sd,
                    sm,
                },
                0b0100 => Op::VCompare {
                    signal: top,
                    sd,
                    sm: Some(sm),
                },
                0b0101 => {
                    if bits(h2, 5, 5) != 0 || bits(h2, 3, 0) != 0 {
                        return Op::Undefined;
                    }
                    Op::VCompare {
                        signal: top,
                        sd,
                        sm: None,
                    }
                }
                0b1000 => {
                    let op = if top {
                        VConvert::FromSigned
                    } else {
                        VConvert::FromUnsigned
                    };
                    Op::VConvert { op, sd, sm }
                }
                0b1010 | 0b1011 | 0b1110 | 0b1111 => {
                    // VCVT between floating point and fixed point (A7.7.227).
                    let to_fixed = opc2 & 0b0100 != 0;
                    let unsigned = opc2 & 1 != 0;
                    let half = !top;
                    let size = if half { 16 } else { 32 };
                    let imm5 = bits(h2, 3, 0) << 1 | bit(h2, 5) as u32;
                    if imm5 > size {
                        return Op::Unpredictable;
                    }
                    let frac = (size - imm5) as u8;
                    let signed = !unsigned;
                    let op = if to_fixed {
                        VConvert::ToFixed { signed, half, frac }
                    } else {
                        VConvert::FromFixed { signed, half, frac }
                    };
                    Op::VConvert { op, sd, sm: sd }
                }
                0b1100 => Op::VConvert {
                    op: VConvert::ToUnsigned { round_zero: top },
                    sd,
                    sm,
                },
                0b1101 => Op::VConvert {
                    op: VConvert::ToSigned { round_zero: top },
                    sd,
                    sm,
                },
                _ => Op::Undefined,
            }
        }
        _ => Op::Undefined,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn d16(h: u16) -> Op {
        decode(h, 0, 0x100).0
    }

    fn d32(word: u32) -> Op {
        decode((word >> 16) as u16, word as u16, 0x100).0
    }

    #[test]
    fn modified_immediates_follow_thumb_expand_imm() {
        assert_eq!(expand_imm(0x0AB), Some((0xAB, ImmCarry::Keep)));
        assert_eq!(expand_imm(0x1AB), Some((0x00AB_00AB, ImmCarry::Keep)));
        assert_eq!(expand_imm(0x2AB), Some((0xAB00_AB00, ImmCarry::Keep)));
        assert_eq!(expand_imm(0x3AB), Some((0xABAB_ABAB, ImmCarry::Keep)));
        assert_eq!(expand_imm(0x100), None);
        // 0x4FF: rotation 9 of 0xFF -> 0x7F80_0000, carry from bit 31 clear.
        assert_eq!(expand_imm(0x4FF), Some((0x7F80_0000, ImmCarry::Set(false))));
        // rotation 8 of 0x80 -> 0x8000_0000, carry set.
        assert_eq!(expand_imm(0x400), Some((0x8000_0000, ImmCarry::Set(true))));
    }

    #[test]
    fn sixteen_bit_forms_decode_as_the_manual_says() {
        // adds r0, r1, r2 = 0x1888
        assert_eq!(
            d16(0x1888),
            Op::AluReg {
                op: Alu::Add,
                s: SetFlags::OutsideIt,
                rd: 0,
                rn: 1,
                rm: 2,
                shift: Shift::Lsl,
                amount: 0
            }
        );
        // lsrs r1, r2, #32 = 0x0811 (imm5 = 0 means 32)
        assert_eq!(
            d16(0x0811),
            Op::AluReg {
                op: Alu::Mov,
                s: SetFlags::OutsideIt,
                rd: 1,
                rn: 0,
                rm: 2,
                shift: Shift::Lsr,
                amount: 32
            }
        );
        // ldr r0, [pc, #4] at 0x102: Align(0x106, 4) + 4 = 0x108
        assert_eq!(
            decode(0x4801, 0, 0x102).0,
            Op::LoadLiteral {
                width: Width::Word,
                rt: 0,
                address: 0x108
            }
        );
        // ite eq = 0xbf0c
        assert_eq!(d16(0xBF0C), Op::It { state: 0x0C });
        // push {r4, lr} = 0xb510
        assert_eq!(
            d16(0xB510),
            Op::Multiple {
                load: false,
                rn: 13,
                list: 0x4010,
                writeback: true,
                decrement: true
            }
        );
        // ldm r1, {r0, r1}: base in the list, no writeback.
        assert_eq!(
            d16(0xC903),
            Op::Multiple {
                load: true,
                rn: 1,
                list: 0x3,
                writeback: false,
                decrement: false
            }
        );
        // cbz r0, +4 at 0x100: target 0x108
        assert_eq!(
            d16(0xB110),
            Op::CompareBranch {
                nonzero: false,
                rn: 0,
                target: 0x108
            }
        );
        assert_eq!(d16(0xDE00), Op::Undefined);
    }

    #[test]
    fn thirty_two_bit_forms_decode_as_the_manual_says() {
        // bl with offset -4 at 0x100: f7ff fffe -> target 0x100
        assert_eq!(d32(0xF7FF_FFFE), Op::BranchLink { target: 0x100 });
        // umaal r0, r1, r2, r3 = fbe2 0163
        assert_eq!(
            d32(0xFBE2_0163),
            Op::LongMul {
                kind: LongMul::Umaal,
                rdlo: 0,
                rdhi: 1,
                rn: 2,
                rm: 3
            }
        );
        // uxtb16 r0, r1 = fa3f f081
        assert_eq!(
            d32(0xFA3F_F081),
            Op::Extend {
                op: Extend::Uxtb16,
                rd: 0,
                rn: 15,
                rm: 1,
                rot: 0
            }
        );
        // pkhtb r0, r1, r2, asr #32 (encoded as asr #0)
        assert_eq!(
            d32(0xEAC1_0022),
            Op::Pack {
                tb: true,
                rd: 0,
                rn: 1,
                rm: 2,
                amount: 32
            }
        );
        // uqadd8 r0, r1, r2 = fa81 f052
        assert_eq!(
            d32(0xFA81_F052),
            Op::Parallel {
                lanes: Lanes::UnsignedSat,
                op: LaneOp::Add8,
                rd: 0,
                rn: 1,
                rm: 2
            }
        );
        // vadd.f32 s0, s1, s2 = ee30 0a81
        assert_eq!(
            d32(0xEE30_0A81),
            Op::VBinary {
                op: VBinary::Add,
                sd: 0,
                sn: 1,
                sm: 2
            }
        );
        // vcvt.s32.f32 s0, s0 = eebd 0ac0
        assert_eq!(
            d32(0xEEBD_0AC0),
            Op::VConvert {
                op: VConvert::ToSigned { round_zero: true },
                sd: 0,
                sm: 0
            }
        );
        // vpush {d8-d9} = ed2d 8b04
        assert_eq!(
            d32(0xED2D_8B04),
            Op::VMultiple {
                load: false,
                rn: 13,
                sd: 16,
                words: 4,
                writeback: true,
                decrement: true
            }
        );
        // vmrs APSR_nzcv, fpscr = eef1 fa10
        assert_eq!(d32(0xEEF1_FA10), Op::Vmrs { rt: 15 });
        // vmov.f32 s0, #1.0 = eeb7 0a00
        assert_eq!(
            d32(0xEEB7_0A00),
            Op::VMovImm {
                sd: 0,
                bits: 0x3F80_0000
            }
        );
        // vadd.f64 is UNDEFINED on FPv4-SP: ee30 0b01
        assert_eq!(d32(0xEE30_0B01), Op::Undefined);
        // A coprocessor other than the FPU.
        assert_eq!(d32(0xEE00_0E10), Op::NoCoprocessor);
    }
}
