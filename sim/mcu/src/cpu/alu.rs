//! The integer arithmetic of the ARMv7-M pseudocode (DDI 0403E, A2.2 and the instruction
//! pages): shifts with carry, add with carry, saturation, and the SIMD lane helpers.

use super::op::Shift;

/// Shift_C: the shifted value and the carry out, for amounts 0–255 (a register shift uses
/// the bottom byte of the register; an immediate shift 1–32).
#[inline]
pub fn shift_c(value: u32, shift: Shift, amount: u32, carry_in: bool) -> (u32, bool) {
    if amount == 0 && shift != Shift::Rrx {
        return (value, carry_in);
    }
    match shift {
        Shift::Lsl => match amount {
            1..=31 => (value << amount, (value >> (32 - amount)) & 1 != 0),
            32 => (0, value & 1 != 0),
            _ => (0, false),
        },
        Shift::Lsr => match amount {
            1..=31 => (value >> amount, (value >> (amount - 1)) & 1 != 0),
            32 => (0, value >> 31 != 0),
            _ => (0, false),
        },
        Shift::Asr => match amount {
            1..=31 => (
                ((value as i32) >> amount) as u32,
                (value >> (amount - 1)) & 1 != 0,
            ),
            _ => {
                let sign = value >> 31 != 0;
                (if sign { u32::MAX } else { 0 }, sign)
            }
        },
        Shift::Ror => {
            let n = amount % 32;
            let result = value.rotate_right(n);
            (result, result >> 31 != 0)
        }
        Shift::Rrx => ((value >> 1) | ((carry_in as u32) << 31), value & 1 != 0),
    }
}

/// AddWithCarry: result, carry out, overflow.
#[inline]
pub fn add_with_carry(x: u32, y: u32, carry_in: bool) -> (u32, bool, bool) {
    let unsigned = x as u64 + y as u64 + carry_in as u64;
    let signed = x as i32 as i64 + y as i32 as i64 + carry_in as i64;
    let result = unsigned as u32;
    (result, unsigned >> 32 != 0, result as i32 as i64 != signed)
}

/// SignedSatQ: `value` saturated to `bits` bits, and whether it saturated.
#[inline]
pub fn signed_sat(value: i64, bits: u32) -> (u32, bool) {
    let max = (1i64 << (bits - 1)) - 1;
    let min = -(1i64 << (bits - 1));
    if value > max {
        (max as u32, true)
    } else if value < min {
        (min as u32, true)
    } else {
        (value as u32, false)
    }
}

/// UnsignedSatQ: `value` saturated to `bits` bits (0–31), and whether it saturated.
#[inline]
pub fn unsigned_sat(value: i64, bits: u32) -> (u32, bool) {
    let max = (1i64 << bits) - 1;
    if value > max {
        (max as u32, true)
    } else if value < 0 {
        (0, true)
    } else {
        (value as u32, false)
    }
}

/// The signed halfword `n` (0 low, 1 high) of `x`.
#[inline]
pub fn half_s(x: u32, n: u32) -> i32 {
    (x >> (16 * n)) as u16 as i16 as i32
}

/// The unsigned halfword `n` of `x`.
#[inline]
pub fn half_u(x: u32, n: u32) -> i32 {
    (x >> (16 * n)) as u16 as i32
}

/// The signed byte `n` of `x`.
#[inline]
pub fn byte_s(x: u32, n: u32) -> i32 {
    (x >> (8 * n)) as u8 as i8 as i32
}

/// The unsigned byte `n` of `x`.
#[inline]
pub fn byte_u(x: u32, n: u32) -> i32 {
    (x >> (8 * n)) as u8 as i32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shifts_by_zero_32_and_more_follow_shift_c() {
        assert_eq!(
            shift_c(0x8000_0001, Shift::Lsl, 0, true),
            (0x8000_0001, true)
        );
        assert_eq!(shift_c(0x8000_0001, Shift::Lsl, 32, false), (0, true));
        assert_eq!(shift_c(0x8000_0001, Shift::Lsl, 33, true), (0, false));
        assert_eq!(shift_c(0x8000_0001, Shift::Lsr, 32, false), (0, true));
        assert_eq!(
            shift_c(0x8000_0000, Shift::Asr, 40, false),
            (u32::MAX, true)
        );
        assert_eq!(shift_c(0x0000_0001, Shift::Ror, 32, false), (1, false));
        assert_eq!(
            shift_c(0x8000_0001, Shift::Ror, 1, false),
            (0xC000_0000, true)
        );
        assert_eq!(
            shift_c(0x0000_0001, Shift::Rrx, 1, true),
            (0x8000_0000, true)
        );
    }

    #[test]
    fn add_with_carry_gives_carry_and_overflow() {
        assert_eq!(
            add_with_carry(0x7FFF_FFFF, 1, false),
            (0x8000_0000, false, true)
        );
        assert_eq!(add_with_carry(0xFFFF_FFFF, 1, false), (0, true, false));
        // SUBS 0 - 0 is 0 + NOT 0 + 1: carry set (no borrow).
        assert_eq!(add_with_carry(0, !0, true), (0, true, false));
        assert_eq!(
            add_with_carry(0x8000_0000, !1, true),
            (0x7FFF_FFFF, true, true)
        );
    }

    #[test]
    fn saturation_clamps_and_reports() {
        assert_eq!(signed_sat(200, 8), (127, true));
        assert_eq!(signed_sat(-200, 8), (-128i32 as u32, true));
        assert_eq!(signed_sat(5, 8), (5, false));
        assert_eq!(unsigned_sat(-1, 8), (0, true));
        assert_eq!(unsigned_sat(256, 8), (255, true));
        assert_eq!(unsigned_sat(3, 0), (0, true));
    }
}
