//! FPv4-SP: single-precision arithmetic with the ARM pseudocode's rounding, NaN handling,
//! flush-to-zero and cumulative exception flags (DDI 0403E, A2.5), and the FPU's
//! instructions.
//!
//! Rust's f32 operations round to nearest and propagate NaNs as the host does, and cannot
//! raise the FPSCR's flags, so each operation is done exactly: in f64 (products and sums of
//! f32 values are exact there or have an exactly computable error) and rounded to single
//! (or half) precision here, with the rounding mode and the error's sign in hand. This is
//! the standard "exact result plus residual" method; no soft-float crate with ARM's
//! tininess-before-rounding and default-NaN rules and a compatible licence was found.

use super::op::{Op, VBinary, VConvert, VUnary};
use super::{Bus, Cpu, Fault, Halt, Trap};

/// FPSCR's cumulative exception bits.
pub const IOC: u32 = 1 << 0;
/// Division by zero.
pub const DZC: u32 = 1 << 1;
/// Overflow.
pub const OFC: u32 = 1 << 2;
/// Underflow.
pub const UFC: u32 = 1 << 3;
/// Inexact.
pub const IXC: u32 = 1 << 4;
/// Input denormal (flushed to zero).
pub const IDC: u32 = 1 << 7;
const FZ: u32 = 1 << 24;
const DN: u32 = 1 << 25;
const AHP: u32 = 1 << 26;

/// The default NaN.
pub const DEFAULT_NAN: u32 = 0x7FC0_0000;

/// The rounding modes of FPSCR.RMode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rounding {
    /// Round to nearest, ties to even.
    Nearest,
    /// Towards plus infinity.
    Plus,
    /// Towards minus infinity.
    Minus,
    /// Towards zero.
    Zero,
}

/// The FPSCR's controls and the flags an operation raises.
#[derive(Clone, Copy, Debug)]
pub struct Env {
    /// The rounding mode.
    pub rounding: Rounding,
    /// Flush-to-zero.
    pub fz: bool,
    /// Default NaN.
    pub dn: bool,
    /// Alternative half precision.
    pub ahp: bool,
    /// Exception flags raised (FPSCR bit positions).
    pub flags: u32,
}

impl Env {
    /// The controls of an FPSCR value.
    pub fn from_fpscr(fpscr: u32) -> Self {
        let rounding = match fpscr >> 22 & 3 {
            0 => Rounding::Nearest,
            1 => Rounding::Plus,
            2 => Rounding::Minus,
            _ => Rounding::Zero,
        };
        Env {
            rounding,
            fz: fpscr & FZ != 0,
            dn: fpscr & DN != 0,
            ahp: fpscr & AHP != 0,
            flags: 0,
        }
    }
}

#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Class {
    Zero,
    Normal,
    Infinity,
    QuietNan,
    SignallingNan,
}

/// FPUnpack for single precision: the class, the sign and the value (zero for a flushed
/// denormal).
fn unpack(bits: u32, env: &mut Env) -> (Class, bool, f64) {
    let sign = bits >> 31 != 0;
    let exp = bits >> 23 & 0xFF;
    let frac = bits & 0x7F_FFFF;
    let class = match exp {
        0 if frac == 0 => Class::Zero,
        0 if env.fz => {
            env.flags |= IDC;
            Class::Zero
        }
        0xFF if frac == 0 => Class::Infinity,
        0xFF if frac & 0x40_0000 != 0 => Class::QuietNan,
        0xFF => Class::SignallingNan,
        _ => Class::Normal,
    };
    let value = if class == Class::Normal {
        f32::from_bits(bits) as f64
    } else {
        0.0
    };
    (class, sign, value)
}

fn is_nan(class: Class) -> bool {
    matches!(class, Class::QuietNan | Class::SignallingNan)
}

/// FPProcessNaN.
fn process_nan(class: Class, bits: u32, env: &mut Env) -> u32 {
    let mut result = bits;
    if class == Class::SignallingNan {
        result |= 0x40_0000;
        env.flags |= IOC;
    }
    if env.dn {
        DEFAULT_NAN
    } else {
        result
    }
}

/// FPProcessNaNs over any number of operands: signalling NaNs first, then quiet, in order.
fn process_nans(ops: &[(Class, u32)], env: &mut Env) -> Option<u32> {
    if let Some(&(class, bits)) = ops.iter().find(|(c, _)| *c == Class::SignallingNan) {
        return Some(process_nan(class, bits, env));
    }
    ops.iter()
        .find(|(c, _)| *c == Class::QuietNan)
        .map(|&(class, bits)| process_nan(class, bits, env))
}

fn zero(sign: bool) -> u32 {
    (sign as u32) << 31
}

fn infinity(sign: bool) -> u32 {
    zero(sign) | 0x7F80_0000
}

/// A binary floating-point format's parameters.
#[derive(Clone, Copy)]
struct Format {
    /// Fraction bits.
    frac: u32,
    /// The exponent bias.
    bias: i32,
    /// The largest biased exponent of a finite number.
    max_exp: i32,
}

const SINGLE: Format = Format {
    frac: 23,
    bias: 127,
    max_exp: 254,
};
const HALF: Format = Format {
    frac: 10,
    bias: 15,
    max_exp: 30,
};
const HALF_AHP: Format = Format {
    frac: 10,
    bias: 15,
    max_exp: 31,
};

/// FPRound: the exact value `magnitude + rel·ε` (ε infinitesimal; `rel` −1, 0 or +1) with
/// `sign`, rounded to `format` in the environment's mode. `magnitude` is a positive, normal
/// f64. Returns the bits of the result in the format.
fn round(sign: bool, magnitude: f64, rel: i32, format: Format, env: &mut Env, flush: bool) -> u32 {
    let bits64 = magnitude.to_bits();
    let e = (bits64 >> 52) as i32 - 1023;
    let m = (bits64 & ((1 << 52) - 1)) | (1 << 52);
    let min_exp = 1 - format.bias;
    let tiny = e < min_exp || (e == min_exp && m == 1 << 52 && rel < 0);
    if flush && env.fz && tiny {
        env.flags |= UFC;
        return (sign as u32) << (format.frac + exponent_bits(format));
    }
    // Bits of m dropped: to the format's precision, more below its normal range.
    let mut shift = 52 - format.frac as i32;
    if e < min_exp {
        shift += min_exp - e;
    }
    let (kept, rem, half) = if shift >= 60 {
        (0u64, m, 1u64 << 59)
    } else {
        (m >> shift, m & ((1u64 << shift) - 1), 1u64 << (shift - 1))
    };
    // The truncated result's bits (exponent and fraction as one integer, so that adding one
    // steps to the next representable number across binades).
    let mut truncated: u64 = if e < min_exp {
        kept
    } else {
        (((e + format.bias) as u64) << format.frac) + kept - (1 << format.frac)
    };
    #[derive(PartialEq)]
    enum Position {
        Exact,
        Below,
        Half,
        Above,
    }
    let position = if rem == 0 && rel == 0 {
        Position::Exact
    } else if rem == 0 && rel < 0 {
        truncated -= 1;
        Position::Above
    } else if rem > half || (rem == half && rel > 0) {
        Position::Above
    } else if rem < half || rel < 0 {
        Position::Below
    } else {
        Position::Half
    };
    let up = match (env.rounding, &position) {
        (_, Position::Exact) => false,
        (Rounding::Nearest, Position::Above) => true,
        (Rounding::Nearest, Position::Half) => truncated & 1 != 0,
        (Rounding::Nearest, Position::Below) => false,
        (Rounding::Zero, _) => false,
        (Rounding::Plus, _) => !sign,
        (Rounding::Minus, _) => sign,
    };
    let result = truncated + up as u64;
    let inexact = position != Position::Exact;
    let limit = ((format.max_exp + 1) as u64) << format.frac;
    let sign_bit = (sign as u32) << (format.frac + exponent_bits(format));
    if result >= limit {
        env.flags |= OFC | IXC;
        let away = match env.rounding {
            Rounding::Nearest => true,
            Rounding::Plus => !sign,
            Rounding::Minus => sign,
            Rounding::Zero => false,
        };
        let max = limit as u32 - 1;
        return sign_bit
            | if away && format.max_exp < (1 << exponent_bits(format)) - 1 {
                limit as u32
            } else {
                max
            };
    }
    if inexact {
        env.flags |= IXC;
        if tiny {
            env.flags |= UFC;
        }
    }
    sign_bit | result as u32
}

fn exponent_bits(format: Format) -> u32 {
    if format.frac == 23 {
        8
    } else {
        5
    }
}

/// Rounds an exact f64 value with a residual to single precision; zero results are the
/// caller's to sign.
fn round_single(value: f64, residual: f64, env: &mut Env) -> u32 {
    let sign = value < 0.0;
    let rel = if residual == 0.0 {
        0
    } else if (residual > 0.0) != sign {
        1
    } else {
        -1
    };
    round(sign, value.abs(), rel, SINGLE, env, true)
}

/// The exact sum a + b as a rounded f64 and its error (TwoSum).
fn two_sum(a: f64, b: f64) -> (f64, f64) {
    let s = a + b;
    let bb = s - a;
    let err = (a - (s - bb)) + (b - bb);
    (s, err)
}

/// The sign of an exact zero sum: minus only in round-towards-minus.
fn zero_sum(env: &Env) -> u32 {
    zero(env.rounding == Rounding::Minus)
}

/// An operand unpacked: its class, sign and value.
type Unpacked = (Class, bool, f64);

/// FPUnpack of two operands and FPProcessNaNs: the unpacked operands, or the NaN result.
fn operands(a: u32, b: u32, env: &mut Env) -> Result<(Unpacked, Unpacked), u32> {
    let first = unpack(a, env);
    let second = unpack(b, env);
    match process_nans(&[(first.0, a), (second.0, b)], env) {
        Some(nan) => Err(nan),
        None => Ok((first, second)),
    }
}

/// FPAdd.
pub fn add(a: u32, b: u32, env: &mut Env) -> u32 {
    let ((ca, sa, va), (cb, sb, vb)) = match operands(a, b, env) {
        Ok(operands) => operands,
        Err(nan) => return nan,
    };
    let (ia, ib) = (ca == Class::Infinity, cb == Class::Infinity);
    if ia && ib && sa != sb {
        env.flags |= IOC;
        return DEFAULT_NAN;
    }
    if ia {
        return infinity(sa);
    }
    if ib {
        return infinity(sb);
    }
    if ca == Class::Zero && cb == Class::Zero && sa == sb {
        return zero(sa);
    }
    let (s, err) = two_sum(va, vb);
    if s == 0.0 {
        return zero_sum(env);
    }
    round_single(s, err, env)
}

/// FPSub: the NaNs of the operands as they are, then op1 + (-op2).
pub fn sub(a: u32, b: u32, env: &mut Env) -> u32 {
    let (ca, _, _) = unpack(a, &mut Env { flags: 0, ..*env });
    let (cb, _, _) = unpack(b, &mut Env { flags: 0, ..*env });
    if is_nan(ca) || is_nan(cb) {
        // Unpack again for the flags (IDC cannot arise with a NaN, but keep the order).
        let (ca, _, _) = unpack(a, env);
        let (cb, _, _) = unpack(b, env);
        return process_nans(&[(ca, a), (cb, b)], env).unwrap_or(DEFAULT_NAN);
    }
    add(a, neg(b), env)
}

/// FPMul.
pub fn mul(a: u32, b: u32, env: &mut Env) -> u32 {
    let ((ca, sa, va), (cb, sb, vb)) = match operands(a, b, env) {
        Ok(operands) => operands,
        Err(nan) => return nan,
    };
    let sign = sa != sb;
    let (ia, ib) = (ca == Class::Infinity, cb == Class::Infinity);
    let (za, zb) = (ca == Class::Zero, cb == Class::Zero);
    if (ia && zb) || (za && ib) {
        env.flags |= IOC;
        return DEFAULT_NAN;
    }
    if ia || ib {
        return infinity(sign);
    }
    if za || zb {
        return zero(sign);
    }
    round_single(va * vb, 0.0, env)
}

/// FPDiv.
pub fn div(a: u32, b: u32, env: &mut Env) -> u32 {
    let ((ca, sa, va), (cb, sb, vb)) = match operands(a, b, env) {
        Ok(operands) => operands,
        Err(nan) => return nan,
    };
    let sign = sa != sb;
    let (ia, ib) = (ca == Class::Infinity, cb == Class::Infinity);
    let (za, zb) = (ca == Class::Zero, cb == Class::Zero);
    if (ia && ib) || (za && zb) {
        env.flags |= IOC;
        return DEFAULT_NAN;
    }
    if ia || zb {
        if !ia {
            env.flags |= DZC;
        }
        return infinity(sign);
    }
    if za || ib {
        return zero(sign);
    }
    let q = va / vb;
    // a - q·b is exact for a correctly rounded quotient; the true quotient is q + r/b.
    let r = (-q).mul_add(vb, va);
    let residual = if (r < 0.0) == (vb < 0.0) {
        r.abs()
    } else {
        -r.abs()
    };
    round_single(q, residual, env)
}

/// FPSqrt.
pub fn sqrt(a: u32, env: &mut Env) -> u32 {
    let (ca, sa, va) = unpack(a, env);
    if let Some(nan) = process_nans(&[(ca, a)], env) {
        return nan;
    }
    match ca {
        Class::Zero => zero(sa),
        Class::Infinity if !sa => infinity(false),
        _ if sa => {
            env.flags |= IOC;
            DEFAULT_NAN
        }
        _ => {
            let q = va.sqrt();
            let r = (-q).mul_add(q, va);
            round_single(q, r, env)
        }
    }
}

/// FPMulAdd: addend + op1·op2 with one rounding.
pub fn mul_add(addend: u32, op1: u32, op2: u32, env: &mut Env) -> u32 {
    let (ca, sa, va) = unpack(addend, env);
    let (c1, s1, v1) = unpack(op1, env);
    let (c2, s2, v2) = unpack(op2, env);
    let (i1, i2) = (c1 == Class::Infinity, c2 == Class::Infinity);
    let (z1, z2) = (c1 == Class::Zero, c2 == Class::Zero);
    let nan = process_nans(&[(ca, addend), (c1, op1), (c2, op2)], env);
    if ca == Class::QuietNan && ((i1 && z2) || (z1 && i2)) {
        env.flags |= IOC;
        return DEFAULT_NAN;
    }
    if let Some(nan) = nan {
        return nan;
    }
    if (i1 && z2) || (z1 && i2) {
        env.flags |= IOC;
        return DEFAULT_NAN;
    }
    let sp = s1 != s2;
    let ip = i1 || i2;
    let zp = z1 || z2;
    let ia = ca == Class::Infinity;
    if ia && ip && sa != sp {
        env.flags |= IOC;
        return DEFAULT_NAN;
    }
    if ia {
        return infinity(sa);
    }
    if ip {
        return infinity(sp);
    }
    if ca == Class::Zero && zp && sa == sp {
        return zero(sa);
    }
    // The product is exact in f64 (24 + 24 bits); the sum's error is exact by TwoSum.
    let product = if zp { 0.0 } else { v1 * v2 };
    let (s, err) = two_sum(va, product);
    if s == 0.0 && err == 0.0 {
        return zero_sum(env);
    }
    if s == 0.0 {
        return round_single(err, 0.0, env);
    }
    round_single(s, err, env)
}

/// FPNeg: the sign flipped, NaNs included.
pub fn neg(a: u32) -> u32 {
    a ^ 0x8000_0000
}

/// FPCompare: the NZCV flags (bits 31–28).
pub fn compare(a: u32, b: u32, signal_quiet: bool, env: &mut Env) -> u32 {
    let (ca, _, va) = unpack(a, env);
    let (cb, _, vb) = unpack(b, env);
    if is_nan(ca) || is_nan(cb) {
        if ca == Class::SignallingNan || cb == Class::SignallingNan || signal_quiet {
            env.flags |= IOC;
        }
        return 0b0011 << 28;
    }
    let value = |class: Class, bits: u32, v: f64| match class {
        Class::Infinity if bits >> 31 != 0 => f64::NEG_INFINITY,
        Class::Infinity => f64::INFINITY,
        _ => v,
    };
    let (x, y) = (value(ca, a, va), value(cb, b, vb));
    if x == y {
        0b0110 << 28
    } else if x < y {
        0b1000 << 28
    } else {
        0b0010 << 28
    }
}

/// FPToFixed: `bits` times 2^frac, rounded (towards zero, or by the environment's mode)
/// and saturated to a signed or unsigned integer of `width` bits.
pub fn to_fixed(
    bits: u32,
    width: u32,
    frac: u32,
    unsigned: bool,
    round_zero: bool,
    env: &mut Env,
) -> u32 {
    let (class, sign, value) = unpack(bits, env);
    if is_nan(class) {
        env.flags |= IOC;
        return 0;
    }
    let value = match class {
        Class::Infinity if sign => f64::NEG_INFINITY,
        Class::Infinity => f64::INFINITY,
        _ => value * (2f64).powi(frac as i32),
    };
    let floor = value.floor();
    let error = value - floor;
    let rounding = if round_zero {
        Rounding::Zero
    } else {
        env.rounding
    };
    let up = match rounding {
        Rounding::Nearest => error > 0.5 || (error == 0.5 && floor.rem_euclid(2.0) == 1.0),
        Rounding::Zero => error != 0.0 && floor < 0.0,
        Rounding::Plus => error != 0.0,
        Rounding::Minus => false,
    };
    let result = if value.is_infinite() {
        value
    } else {
        floor + up as u32 as f64
    };
    let (min, max) = if unsigned {
        (0.0, (2f64).powi(width as i32) - 1.0)
    } else {
        (
            -(2f64).powi(width as i32 - 1),
            (2f64).powi(width as i32 - 1) - 1.0,
        )
    };
    let clamped = result.clamp(min, max);
    if clamped != result {
        env.flags |= IOC;
    } else if error != 0.0 {
        env.flags |= IXC;
    }
    if unsigned {
        clamped as u64 as u32
    } else {
        clamped as i64 as u32
    }
}

/// FixedToFP: an integer over 2^frac, rounded to single precision (by the environment's
/// mode; VCVT from fixed point sets round-to-nearest first, A7.7.226).
pub fn from_fixed(value: u32, width: u32, frac: u32, unsigned: bool, env: &mut Env) -> u32 {
    let raw = if width == 16 { value & 0xFFFF } else { value };
    let integer = if unsigned {
        raw as f64
    } else if width == 16 {
        raw as u16 as i16 as f64
    } else {
        raw as i32 as f64
    };
    if integer == 0.0 {
        return 0;
    }
    round_single(integer / (2f64).powi(frac as i32), 0.0, env)
}

/// Half precision (IEEE or, with AHP, the alternative format) to single.
pub fn half_to_single(half: u32, env: &mut Env) -> u32 {
    let sign = half >> 15 & 1 != 0;
    let exp = half >> 10 & 0x1F;
    let frac = half & 0x3FF;
    if exp == 0x1F && !env.ahp {
        if frac == 0 {
            return infinity(sign);
        }
        let class = if frac & 0x200 != 0 {
            Class::QuietNan
        } else {
            Class::SignallingNan
        };
        let widened = zero(sign) | 0x7F80_0000 | frac << 13;
        return process_nan(class, widened, env);
    }
    if exp == 0 && frac == 0 {
        return zero(sign);
    }
    // Exact in f64 and in f32: at most 11 significant bits.
    let value = if exp == 0 {
        frac as f64 * (2f64).powi(-24)
    } else {
        (1024 + frac) as f64 * (2f64).powi(exp as i32 - 25)
    };
    let bits = (value as f32).to_bits();
    bits | zero(sign)
}

/// Single to half precision (IEEE or, with AHP, the alternative format), rounded by the
/// environment's mode. Flush-to-zero applies to the single-precision input only.
pub fn single_to_half(bits: u32, env: &mut Env) -> u32 {
    let (class, sign, value) = unpack(bits, env);
    let sign_bit = (sign as u32) << 15;
    match class {
        Class::QuietNan | Class::SignallingNan => {
            if env.ahp {
                env.flags |= IOC;
                return sign_bit;
            }
            if class == Class::SignallingNan {
                env.flags |= IOC;
            }
            if env.dn {
                0x7E00
            } else {
                sign_bit | 0x7E00 | (bits >> 13 & 0x1FF)
            }
        }
        Class::Infinity => {
            if env.ahp {
                env.flags |= IOC;
                sign_bit | 0x7FFF
            } else {
                sign_bit | 0x7C00
            }
        }
        Class::Zero => sign_bit,
        Class::Normal => {
            let format = if env.ahp { HALF_AHP } else { HALF };
            let mut local = Env { fz: false, ..*env };
            let result = round(sign, value.abs(), 0, format, &mut local, false);
            // AHP has no infinity: an overflow is an Invalid Operation, not Overflow.
            if env.ahp && local.flags & OFC != 0 {
                env.flags |= IOC;
                return sign_bit | 0x7FFF;
            }
            env.flags |= local.flags;
            result
        }
    }
}

impl Cpu {
    /// ExecuteFPCheck: the FPU enabled in CPACR, a lazily stacked context saved, a new
    /// context marked in CONTROL.FPCA (with FPSCR's defaults from FPDSCR).
    fn fp_check<B: Bus>(&mut self, bus: &mut B) -> Result<(), Trap> {
        let access = self.scs.cpacr >> 20 & 0xF;
        let privileged = self.ipsr != 0 || self.control & 1 == 0;
        let allowed = match access {
            0b1111 => true,
            0b0101 => privileged,
            _ => false,
        };
        if !allowed {
            return Err(Fault::NoCoprocessor.into());
        }
        if self.scs.fpccr & super::system::FPCCR_LSPACT != 0 {
            self.preserve_fp_state(bus)?;
        }
        if self.scs.fpccr & super::system::FPCCR_ASPEN != 0 && self.control & 0b100 == 0 {
            self.fpscr = (self.fpscr & !0x07C0_0000) | (self.scs.fpdscr & 0x07C0_0000);
            self.control |= 0b100;
        }
        Ok(())
    }

    /// Lazy state preservation: s0–s15 and FPSCR to the space reserved at exception entry.
    fn preserve_fp_state<B: Bus>(&mut self, bus: &mut B) -> Result<(), Trap> {
        let base = self.scs.fpcar;
        for i in 0..16 {
            let value = self.s[i];
            self.store_stack(bus, base + 4 * i as u32, value)?;
        }
        let fpscr = self.fpscr;
        self.store_stack(bus, base + 0x40, fpscr)?;
        self.scs.fpccr &= !super::system::FPCCR_LSPACT;
        Ok(())
    }

    pub(super) fn store_stack<B: Bus>(
        &mut self,
        bus: &mut B,
        address: u32,
        value: u32,
    ) -> Result<(), Trap> {
        self.store_aligned(bus, address, value)
            .map_err(|trap| match trap {
                Trap::Fault(_) => Trap::Halt(Halt::Lockup {
                    pc: self.pc,
                    reason: format!(
                        "the stack at {address:#010x} cannot be written (stack overflow?)"
                    ),
                }),
                other => other,
            })
    }

    fn env(&self) -> Env {
        Env::from_fpscr(self.fpscr)
    }

    fn finish(&mut self, env: Env) {
        self.fpscr |= env.flags;
    }

    /// Executes a floating-point instruction.
    pub(super) fn execute_fp<B: Bus>(&mut self, bus: &mut B, op: Op) -> Result<(), Trap> {
        self.fp_check(bus)?;
        match op {
            Op::VBinary { op, sd, sn, sm } => {
                let mut env = self.env();
                let (d, n, m) = (
                    self.s[sd as usize],
                    self.s[sn as usize],
                    self.s[sm as usize],
                );
                let result = match op {
                    VBinary::Add => add(n, m, &mut env),
                    VBinary::Sub => sub(n, m, &mut env),
                    VBinary::Mul => mul(n, m, &mut env),
                    VBinary::Nmul => neg(mul(n, m, &mut env)),
                    VBinary::Div => {
                        self.cycles += 13;
                        div(n, m, &mut env)
                    }
                    VBinary::Mla => {
                        let product = mul(n, m, &mut env);
                        add(d, product, &mut env)
                    }
                    VBinary::Mls => {
                        let product = mul(n, m, &mut env);
                        add(d, neg(product), &mut env)
                    }
                    VBinary::Nmla => {
                        let product = mul(n, m, &mut env);
                        add(neg(d), neg(product), &mut env)
                    }
                    VBinary::Nmls => {
                        let product = mul(n, m, &mut env);
                        add(neg(d), product, &mut env)
                    }
                    VBinary::Fma => mul_add(d, n, m, &mut env),
                    VBinary::Fms => mul_add(d, neg(n), m, &mut env),
                    VBinary::Fnma => mul_add(neg(d), neg(n), m, &mut env),
                    VBinary::Fnms => mul_add(neg(d), n, m, &mut env),
                };
                if matches!(
                    op,
                    VBinary::Mla
                        | VBinary::Mls
                        | VBinary::Nmla
                        | VBinary::Nmls
                        | VBinary::Fma
                        | VBinary::Fms
                        | VBinary::Fnma
                        | VBinary::Fnms
                ) {
                    self.cycles += 2;
                }
                self.s[sd as usize] = result;
                self.finish(env);
            }
            Op::VUnary { op, sd, sm } => {
                let m = self.s[sm as usize];
                self.s[sd as usize] = match op {
                    VUnary::Mov => m,
                    VUnary::Abs => m & 0x7FFF_FFFF,
                    VUnary::Neg => neg(m),
                    VUnary::Sqrt => {
                        let mut env = self.env();
                        let result = sqrt(m, &mut env);
                        self.finish(env);
                        self.cycles += 13;
                        result
                    }
                };
            }
            Op::VMovImm { sd, bits } => self.s[sd as usize] = bits,
            Op::VCompare { signal, sd, sm } => {
                let mut env = self.env();
                let other = sm.map_or(0, |sm| self.s[sm as usize]);
                let nzcv = compare(self.s[sd as usize], other, signal, &mut env);
                self.fpscr = (self.fpscr & 0x0FFF_FFFF) | nzcv;
                self.finish(env);
            }
            Op::VConvert { op, sd, sm } => {
                let mut env = self.env();
                let m = self.s[sm as usize];
                let d = self.s[sd as usize];
                self.s[sd as usize] = match op {
                    VConvert::ToSigned { round_zero } => {
                        to_fixed(m, 32, 0, false, round_zero, &mut env)
                    }
                    VConvert::ToUnsigned { round_zero } => {
                        to_fixed(m, 32, 0, true, round_zero, &mut env)
                    }
                    VConvert::FromSigned => from_fixed(m, 32, 0, false, &mut env),
                    VConvert::FromUnsigned => from_fixed(m, 32, 0, true, &mut env),
                    VConvert::ToFixed { signed, half, frac } => {
                        let width = if half { 16 } else { 32 };
                        let result = to_fixed(m, width, frac as u32, !signed, true, &mut env);
                        if half {
                            if signed {
                                result as u16 as i16 as u32
                            } else {
                                result & 0xFFFF
                            }
                        } else {
                            result
                        }
                    }
                    VConvert::FromFixed { signed, half, frac } => {
                        // FixedToFP with round_to_nearest (A7.7.226): FPSCR's mode is not used.
                        let mut nearest = Env {
                            rounding: Rounding::Nearest,
                            ..env
                        };
                        let result = from_fixed(
                            m,
                            if half { 16 } else { 32 },
                            frac as u32,
                            !signed,
                            &mut nearest,
                        );
                        env.flags |= nearest.flags;
                        result
                    }
                    VConvert::FromHalf { top } => {
                        half_to_single(if top { m >> 16 } else { m & 0xFFFF }, &mut env)
                    }
                    VConvert::ToHalf { top } => {
                        let half = single_to_half(m, &mut env);
                        if top {
                            (d & 0xFFFF) | half << 16
                        } else {
                            (d & 0xFFFF_0000) | half
                        }
                    }
                };
                self.finish(env);
            }
            Op::VMovCore { to_core, rt, sn } => {
                if to_core {
                    self.r[rt as usize] = self.s[sn as usize];
                } else {
                    self.s[sn as usize] = self.r[rt as usize];
                }
            }
            Op::VMovPair {
                to_core,
                rt,
                rt2,
                sm,
            } => {
                if to_core {
                    self.r[rt as usize] = self.s[sm as usize];
                    self.r[rt2 as usize] = self.s[sm as usize + 1];
                } else {
                    self.s[sm as usize] = self.r[rt as usize];
                    self.s[sm as usize + 1] = self.r[rt2 as usize];
                }
                self.cycles += 1;
            }
            Op::Vmrs { rt } => {
                if rt == 15 {
                    let f = self.fpscr;
                    self.n = f >> 31 != 0;
                    self.z = f >> 30 & 1 != 0;
                    self.c = f >> 29 & 1 != 0;
                    self.v = f >> 28 & 1 != 0;
                } else {
                    self.r[rt as usize] = self.fpscr;
                }
            }
            Op::Vmsr { rt } => self.fpscr = self.r[rt as usize] & super::FPSCR_MASK,
            Op::VLoadStore {
                load,
                sd,
                double,
                rn,
                offset,
            } => {
                let address = if rn == 15 {
                    offset as u32
                } else {
                    (self.r[rn as usize]).wrapping_add(offset as u32)
                };
                let words = if double { 2 } else { 1 };
                self.cycles += 1;
                for i in 0..words {
                    let at = address.wrapping_add(4 * i as u32);
                    if load {
                        self.s[sd as usize + i] = self.load_aligned(bus, at)?;
                    } else {
                        self.store_aligned(bus, at, self.s[sd as usize + i])?;
                    }
                }
            }
            Op::VMultiple {
                load,
                rn,
                sd,
                words,
                writeback,
                decrement,
            } => {
                let base = self.r[rn as usize];
                let bytes = 4 * words as u32;
                let start = if decrement {
                    base.wrapping_sub(bytes)
                } else {
                    base
                };
                self.cycles += words as u64;
                for i in 0..words as usize {
                    let at = start.wrapping_add(4 * i as u32);
                    if load {
                        self.s[sd as usize + i] = self.load_aligned(bus, at)?;
                    } else {
                        self.store_aligned(bus, at, self.s[sd as usize + i])?;
                    }
                }
                if writeback {
                    let value = if decrement {
                        start
                    } else {
                        base.wrapping_add(bytes)
                    };
                    self.r[rn as usize] = if rn == 13 { value & !3 } else { value };
                }
            }
            _ => return Err(Fault::Undefined.into()),
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env(rounding: Rounding) -> Env {
        Env {
            rounding,
            fz: false,
            dn: false,
            ahp: false,
            flags: 0,
        }
    }

    fn f(x: f32) -> u32 {
        x.to_bits()
    }

    #[test]
    fn add_rounds_by_the_mode_with_the_error_seen() {
        // 1 + 2^-30 is not representable: nearest gives 1, plus gives the next float up.
        let tiny = f((2f32).powi(-30));
        let mut e = env(Rounding::Nearest);
        assert_eq!(add(f(1.0), tiny, &mut e), f(1.0));
        assert_eq!(e.flags, IXC);
        let mut e = env(Rounding::Plus);
        assert_eq!(add(f(1.0), tiny, &mut e), f(1.0) + 1);
        let mut e = env(Rounding::Zero);
        assert_eq!(add(f(1.0), f(-(2f32).powi(-30)), &mut e), f(1.0) - 1);
        // Far below the f64 precision too: 2^100 + 2^-100 rounded up in Plus.
        let mut e = env(Rounding::Plus);
        assert_eq!(
            add(f((2f32).powi(100)), f((2f32).powi(-100)), &mut e),
            f((2f32).powi(100)) + 1
        );
        // x + (-x) is +0, or -0 rounding towards minus.
        assert_eq!(add(f(3.0), f(-3.0), &mut env(Rounding::Nearest)), 0);
        assert_eq!(add(f(3.0), f(-3.0), &mut env(Rounding::Minus)), 0x8000_0000);
    }

    #[test]
    fn overflow_gives_infinity_or_the_largest_by_mode() {
        let max = f(f32::MAX);
        let mut e = env(Rounding::Nearest);
        assert_eq!(mul(max, f(2.0), &mut e), f(f32::INFINITY));
        assert_eq!(e.flags, OFC | IXC);
        let mut e = env(Rounding::Zero);
        assert_eq!(mul(max, f(2.0), &mut e), max);
        assert_eq!(e.flags, OFC | IXC);
        let mut e = env(Rounding::Plus);
        assert_eq!(mul(f(-f32::MAX), f(2.0), &mut e), f(-f32::MAX));
    }

    #[test]
    fn underflow_is_tininess_before_rounding_and_flush_to_zero_flushes() {
        let min_normal = f32::MIN_POSITIVE;
        // MIN_NORMAL * 0.5 is exactly representable as a subnormal: no underflow flag.
        let mut e = env(Rounding::Nearest);
        assert_eq!(mul(f(min_normal), f(0.5), &mut e), f(min_normal * 0.5));
        assert_eq!(e.flags, 0);
        // An inexact tiny result flags UFC and IXC.
        let mut e = env(Rounding::Nearest);
        mul(f(min_normal), f(1.0 / 3.0), &mut e);
        assert_eq!(e.flags, UFC | IXC);
        // With FZ: a tiny result is zero, UFC only; a denormal input is zero, IDC.
        let mut e = Env {
            fz: true,
            ..env(Rounding::Nearest)
        };
        assert_eq!(mul(f(min_normal), f(0.5), &mut e), 0);
        assert_eq!(e.flags, UFC);
        let mut e = Env {
            fz: true,
            ..env(Rounding::Nearest)
        };
        assert_eq!(add(f(min_normal * 0.5), f(1.0), &mut e), f(1.0));
        assert_eq!(e.flags, IDC);
    }

    #[test]
    fn nans_propagate_as_arm_says() {
        let snan = 0x7F80_0001;
        let qnan = 0xFFC0_0002;
        let mut e = env(Rounding::Nearest);
        // A signalling NaN in the second operand wins over a quiet one in the first.
        assert_eq!(add(qnan, snan, &mut e), 0x7FC0_0001);
        assert_eq!(e.flags, IOC);
        let mut e = Env {
            dn: true,
            ..env(Rounding::Nearest)
        };
        assert_eq!(add(qnan, f(1.0), &mut e), DEFAULT_NAN);
        let mut e = env(Rounding::Nearest);
        assert_eq!(mul(f(f32::INFINITY), 0, &mut e), DEFAULT_NAN);
        assert_eq!(e.flags, IOC);
        // VFMA with a quiet NaN addend and inf × 0 is the default NaN with Invalid.
        let mut e = env(Rounding::Nearest);
        assert_eq!(mul_add(qnan, f(f32::INFINITY), 0, &mut e), DEFAULT_NAN);
        assert_eq!(e.flags, IOC);
    }

    #[test]
    fn division_and_square_root_round_correctly() {
        let mut e = env(Rounding::Nearest);
        assert_eq!(div(f(1.0), f(3.0), &mut e), f(1.0 / 3.0));
        // 1/3 to nearest rounds up (0x3EAAAAAB): towards plus is the same, towards zero
        // one less; -1/3 towards minus is the nearest's negative.
        let mut e = env(Rounding::Plus);
        assert_eq!(div(f(1.0), f(3.0), &mut e), f(1.0 / 3.0));
        let mut e = env(Rounding::Zero);
        assert_eq!(div(f(1.0), f(3.0), &mut e), f(1.0 / 3.0) - 1);
        let mut e = env(Rounding::Minus);
        assert_eq!(div(f(-1.0), f(3.0), &mut e), f(-1.0 / 3.0));
        let mut e = env(Rounding::Nearest);
        assert_eq!(div(f(1.0), 0, &mut e), f(f32::INFINITY));
        assert_eq!(e.flags, DZC);
        let mut e = env(Rounding::Nearest);
        assert_eq!(sqrt(f(2.0), &mut e), f(2f32.sqrt()));
        assert_eq!(sqrt(f(-0.0), &mut e), f(-0.0));
        let mut e = env(Rounding::Nearest);
        assert_eq!(sqrt(f(-1.0), &mut e), DEFAULT_NAN);
        assert_eq!(e.flags, IOC);
    }

    #[test]
    fn conversions_saturate_and_flag() {
        let mut e = env(Rounding::Nearest);
        assert_eq!(to_fixed(f(-1.5), 32, 0, false, true, &mut e), -1i32 as u32);
        assert_eq!(e.flags, IXC);
        let mut e = env(Rounding::Nearest);
        assert_eq!(to_fixed(f(2.5), 32, 0, false, false, &mut e), 2);
        let mut e = env(Rounding::Nearest);
        assert_eq!(
            to_fixed(f(3e10), 32, 0, false, true, &mut e),
            i32::MAX as u32
        );
        assert_eq!(e.flags, IOC);
        let mut e = env(Rounding::Nearest);
        assert_eq!(to_fixed(f(-1.0), 32, 0, true, true, &mut e), 0);
        assert_eq!(e.flags, IOC);
        let mut e = env(Rounding::Nearest);
        assert_eq!(to_fixed(0x7FC0_0000, 32, 0, false, true, &mut e), 0);
        assert_eq!(e.flags, IOC);
        let mut e = env(Rounding::Nearest);
        assert_eq!(
            from_fixed(0xFFFF_FFFF, 32, 0, true, &mut e),
            f(4294967296.0)
        );
        assert_eq!(e.flags, IXC);
        let mut e = env(Rounding::Nearest);
        assert_eq!(from_fixed(0x8000, 16, 15, false, &mut e), f(-1.0));
    }

    #[test]
    fn half_precision_round_trips_and_overflows() {
        let mut e = env(Rounding::Nearest);
        assert_eq!(single_to_half(f(1.0), &mut e), 0x3C00);
        assert_eq!(half_to_single(0x3C00, &mut e), f(1.0));
        assert_eq!(half_to_single(0x0001, &mut e), f((2f32).powi(-24)));
        assert_eq!(half_to_single(0xFC00, &mut e), f(f32::NEG_INFINITY));
        assert_eq!(single_to_half(f(65520.0), &mut e), 0x7C00);
        assert_eq!(e.flags, OFC | IXC);
        let mut e = Env {
            ahp: true,
            ..env(Rounding::Nearest)
        };
        assert_eq!(half_to_single(0x7C00, &mut e), f(65536.0));
        assert_eq!(single_to_half(f(1e6), &mut e), 0x7FFF);
        assert_eq!(e.flags, IOC);
    }
}
