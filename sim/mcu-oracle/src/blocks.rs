//! A seeded generator of random, architecturally defined Thumb-2 instruction blocks for
//! differential testing (the ARMv7-M Architecture Reference Manual, DDI 0403E, is "the
//! manual" below; encodings are named as there).
//!
//! A [`Block`] is code that runs from [`CODE_BASE`] until PC reaches its end
//! (`CODE_BASE + code.len()`), a starting state and the starting contents of a data window
//! ([`DATA_BASE`], [`DATA_LEN`] bytes). Every load and store stays inside the window.
//!
//! # Rules the generator keeps
//!
//! - **No UNPREDICTABLE or UNDEFINED encodings.** Registers: SP and PC appear only where
//!   the encoding allows them and the generator means them (SP as a base, `MOV Rd, SP`,
//!   `ADD Rd, SP, #imm`, ADR and literal loads reading PC); every other register operand
//!   is r0–r12 or LR. RdLo ≠ RdHi for long multiplies; LDRD Rt ≠ Rt2; no writeback with
//!   the base being Rt, Rt2 or in an LDM/STM list (16-bit LDM with the base in the list
//!   has no writeback and is generated); STREX Rd ≠ Rt, Rd ≠ Rn; at least two registers in
//!   32-bit LDM/STM; REV/RBIT/CLZ with both register fields the same; SSAT ASR #1–31 only
//!   (ASR #0 is SSAT16); bit fields within the word; BFI msb ≥ lsb; modified immediates
//!   with a zero byte only in the plain form; VCVT fixed-point fraction bits ≥ 0;
//!   VLDM/VSTM of 1–16 registers not past s31; VMOV to two core registers with
//!   Rt ≠ Rt2 and Sm ≤ s30; VMSR writes only FPSCR's defined bits.
//! - **IT blocks** hold 1–4 instructions, none of them IT, CBZ/CBNZ, a branch, TBB/TBH,
//!   the 16-bit `MOVS Rd, Rm` (MOV (register) T2 is UNPREDICTABLE in an IT block), an
//!   exclusive access or anything that writes SP; the condition AL only with every slot
//!   "then". A block never ends inside an IT block.
//! - **SP** stays word-aligned and inside the window (between [`DATA_BASE`] and its end,
//!   both included); only PUSH/POP, VPUSH/VPOP, ADD/SUB SP, #imm and writeback with SP as
//!   the base change it, never conditionally. PC is written only by the forward branches.
//! - **Memory**: the generator knows the value of every register it has not overwritten
//!   with something it does not model (the start values, MOVW/MOVT pairs it emits,
//!   writeback); it addresses through those, emitting `MOVW`/`MOVT` into a register when
//!   none fits. LDRD/STRD, LDM/STM, LDREX/STREX, VLDR/VSTR and VLDM/VSTM are word-aligned,
//!   halfword exclusives halfword-aligned; LDR/STR/LDRH/STRH may be unaligned (CCR
//!   UNALIGN_TRP is 0 at reset). Literal loads read only code already in the block.
//! - **Exclusives**: the run starts with the local monitor in Open Access state (the
//!   oracle executes CLREX first); STREX comes right after the LDREX of the same address
//!   and size, or right after a CLREX (and then fails: Rd = 1).
//! - **Branches** go forward within the block; the instructions a branch may skip (and
//!   those a TBB/TBH may enter in the middle) follow the same rules as an IT block's.
//!
//! # Left out
//!
//! BL/BLX/BX (they write LR or PC with interworking), LDR into PC, POP {PC}, MSR/MRS,
//! CPS, SVC, BKPT, WFI/WFE/SEV, the hints, PLD/PLI, the unprivileged LDRT family, LDRD
//! literal, STM with SP, exception-raising or system instructions: a block must run from
//! start to end in Thread mode without exceptions.

use rand::seq::{IndexedRandom, SliceRandom};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::thumb::{self, Index, Insn, Width};
use autoplug_mcu::cpu::ArchState;

/// Where a block's code starts (QEMU `mps2-an386` RAM).
pub const CODE_BASE: u32 = 0x0000_1000;
/// The data window's start (QEMU RAM, and SRAM on the STM32F446). The 4 KiB below it stay
/// free for an exception's stack frame.
pub const DATA_BASE: u32 = 0x2000_1000;
/// The data window's length in bytes.
pub const DATA_LEN: u32 = 1024;
/// The data window's end (exclusive).
pub const DATA_END: u32 = DATA_BASE + DATA_LEN;

/// The Thumb bit of xPSR.
const T_BIT: u32 = 1 << 24;
/// About how many bytes of code a block gets at most.
const CODE_BUDGET: usize = 512;

/// Code, its starting state and the data window's starting contents.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Block {
    /// Thumb-2 instructions, little-endian halfwords, executed from [`CODE_BASE`].
    pub code: Vec<u8>,
    /// The starting registers: PC = [`CODE_BASE`], the Thumb bit set, IT bits zero.
    pub start: ArchState,
    /// The data window's starting contents, [`DATA_LEN`] bytes.
    pub data: Vec<u8>,
    /// Each instruction's (or table's) address and assembly text: a hint for humans.
    pub listing: Vec<(u32, String)>,
}

impl Block {
    /// A block from hand-written code: no listing.
    pub fn new(code: Vec<u8>, start: ArchState, data: Vec<u8>) -> Block {
        Block {
            code,
            start,
            data,
            listing: Vec::new(),
        }
    }

    /// The address where execution stops.
    pub fn end(&self) -> u32 {
        CODE_BASE + self.code.len() as u32
    }

    /// The listing with each instruction's bytes, one per line.
    pub fn disassembly(&self) -> String {
        let mut out = String::new();
        for (i, (addr, text)) in self.listing.iter().enumerate() {
            let from = (addr - CODE_BASE) as usize;
            let to = self
                .listing
                .get(i + 1)
                .map_or(self.code.len(), |(next, _)| (next - CODE_BASE) as usize);
            let bytes: Vec<String> = self.code[from..to]
                .chunks(2)
                .map(|h| match h {
                    [a, b] => format!("{:04x}", u16::from_le_bytes([*a, *b])),
                    [a] => format!("{a:02x}"),
                    _ => String::new(),
                })
                .collect();
            out.push_str(&format!("{addr:08x}: {:<14} {text}\n", bytes.join(" ")));
        }
        out
    }
}

/// The generator: the same seed gives the same blocks.
#[derive(Clone, Debug)]
pub struct BlockGen {
    seed: u64,
    index: u64,
}

impl BlockGen {
    /// A generator whose blocks follow from `seed`.
    pub fn new(seed: u64) -> BlockGen {
        BlockGen { seed, index: 0 }
    }

    /// The next block.
    #[allow(clippy::should_implement_trait)]
    pub fn next(&mut self) -> Block {
        let block = BlockGen::block(self.seed, self.index);
        self.index += 1;
        block
    }

    /// How many blocks [`BlockGen::next`] has returned.
    pub fn index(&self) -> u64 {
        self.index
    }

    /// Block number `index` (from 0) of seed `seed`, without generating those before it.
    pub fn block(seed: u64, index: u64) -> Block {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(index);
        let start = start_state(&mut rng);
        let data = window(&mut rng);
        let mut b = Builder::new(&mut rng, &start);
        let items = b.rng.random_range(1..=24);
        let mut done = 0;
        while done < items || b.code.is_empty() {
            if b.code.len() >= CODE_BUDGET {
                break;
            }
            b.item();
            done += 1;
        }
        let (code, listing) = (b.code, b.listing);
        Block {
            code,
            start,
            data,
            listing,
        }
    }
}

// ---------------------------------------------------------------------------------------
// Values.

/// Integers that find edge cases: zero, one, the extremes, small negatives, halfword and
/// byte lanes at their limits, or anything.
fn interesting_u32(rng: &mut ChaCha8Rng) -> u32 {
    const EDGES: [u32; 20] = [
        0,
        1,
        2,
        0x7fff_ffff,
        0x8000_0000,
        0xffff_ffff,
        0xffff_fffe,
        0x8000_0001,
        0x7fff,
        0x8000,
        0xffff,
        0x1_0000,
        0x7f,
        0x80,
        0xff,
        0x00ff_00ff,
        0xff00_ff00,
        0x7fff_8000,
        0x8000_7fff,
        0x7f80_807f,
    ];
    const LANE16: [u32; 8] = [0, 1, 0x7fff, 0x8000, 0xffff, 0x7f, 0x80, 0xff];
    const LANE8: [u32; 6] = [0, 1, 0x7f, 0x80, 0xff, 0xfe];
    match rng.random_range(0..10) {
        0 | 1 => *EDGES.choose(rng).unwrap_or(&0),
        2 => (rng.random_range(1..=16u32)).wrapping_neg(),
        3 => rng.random_range(0..=64),
        4 => {
            let hi = *LANE16.choose(rng).unwrap_or(&0);
            let lo = *LANE16.choose(rng).unwrap_or(&0);
            hi << 16 | lo
        }
        5 => (0..4).fold(0, |v, _| v << 8 | *LANE8.choose(rng).unwrap_or(&0)),
        _ => rng.random(),
    }
}

/// Single-precision bit patterns that find edge cases: zeros, infinities, quiet and
/// signalling NaNs, subnormals, the normal extremes, halves near rounding boundaries,
/// integer conversion limits, half-precision limits, or anything.
fn interesting_f32(rng: &mut ChaCha8Rng) -> u32 {
    let sign = if rng.random_bool(0.5) { 0x8000_0000 } else { 0 };
    let mantissa = rng.random::<u32>() & 0x7f_ffff;
    match rng.random_range(0..16) {
        0 => sign,
        1 => sign | 0x7f80_0000,
        2 => sign | 0x7fc0_0000 | ((mantissa & 0x3f_ffff) * u32::from(rng.random_bool(0.5))),
        3 => sign | 0x7f80_0000 | (mantissa & 0x3f_ffff).max(1),
        4 => sign | mantissa.max(1),
        5 => {
            sign | *[
                0x0080_0000,
                0x007f_ffff,
                0x0080_0001,
                0x7f7f_ffff,
                0x7f7f_fffe,
                0x0000_0001,
            ]
            .choose(rng)
            .unwrap_or(&0)
        }
        6 => {
            // k + 0.5 and its neighbours: ties in every rounding mode.
            let k = rng.random_range(0..8) as f32;
            let bits = (k + 0.5).to_bits();
            sign | bits.wrapping_add(rng.random_range(0..3)).wrapping_sub(1)
        }
        7 => {
            let edges = [
                0x4f00_0000u32,
                0x4eff_ffff,
                0x4f80_0000,
                0x4f7f_ffff,
                0x4f00_0001,
            ];
            sign | *edges.choose(rng).unwrap_or(&0)
        }
        8 => (rng.random_range(-100i32..=100) as f32).to_bits(),
        9 => {
            // 65504 (largest half), 65520 (rounds to infinity), 2^-14, 2^-24 and around.
            let edges = [
                0x477f_e000u32,
                0x477f_f000,
                0x3880_0000,
                0x3380_0000,
                0x477f_efff,
                0x3300_0000,
            ];
            sign | edges
                .choose(rng)
                .unwrap_or(&0)
                .wrapping_add(rng.random_range(0..3))
                .wrapping_sub(1)
        }
        10 => sign | 0x3f80_0000 | mantissa,
        11 => {
            let v = rng.random::<i16>() as f32 / (1u32 << rng.random_range(0..16)) as f32;
            v.to_bits()
        }
        12 => sign | rng.random_range(0x3000_0000..0x5000_0000u32),
        _ => rng.random(),
    }
}

fn start_state(rng: &mut ChaCha8Rng) -> ArchState {
    let mut s = ArchState::default();
    for r in &mut s.r[..13] {
        *r = if rng.random_bool(0.25) {
            DATA_BASE + rng.random_range(0..DATA_LEN)
        } else {
            interesting_u32(rng)
        };
    }
    s.r[13] = DATA_BASE + 4 * rng.random_range(8..=(DATA_LEN / 4 - 8));
    s.r[14] = interesting_u32(rng);
    s.r[15] = CODE_BASE;
    // N Z C V Q and GE random, the Thumb bit set, no IT state, Thread mode.
    s.xpsr = (rng.random::<u32>() & 0xf800_0000) | (rng.random::<u32>() & 0x000f_0000) | T_BIT;
    for v in &mut s.s {
        *v = interesting_f32(rng);
    }
    s.fpscr = random_fpscr(rng);
    s
}

/// FPSCR with only its defined bits: N Z C V, AHP, DN, FZ, RMode and the cumulative
/// exception flags (cleared half the time).
fn random_fpscr(rng: &mut ChaCha8Rng) -> u32 {
    let mut v = rng.random::<u32>() & 0xf000_0000;
    v |= rng.random::<u32>() & 0x07c0_0000; // AHP, DN, FZ, RMode
    if rng.random_bool(0.5) {
        v |= rng.random::<u32>() & 0x9f;
    }
    v
}

fn window(rng: &mut ChaCha8Rng) -> Vec<u8> {
    let mut data = Vec::with_capacity(DATA_LEN as usize);
    while data.len() < DATA_LEN as usize {
        let word = match rng.random_range(0..3) {
            0 => interesting_u32(rng),
            1 => interesting_f32(rng),
            _ => rng.random(),
        };
        data.extend_from_slice(&word.to_le_bytes());
    }
    data
}

// ---------------------------------------------------------------------------------------
// Text.

const REG: [&str; 16] = [
    "r0", "r1", "r2", "r3", "r4", "r5", "r6", "r7", "r8", "r9", "r10", "r11", "r12", "sp", "lr",
    "pc",
];
const COND: [&str; 15] = [
    "eq", "ne", "cs", "cc", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt", "le", "",
];
const SHIFT: [&str; 4] = ["lsl", "lsr", "asr", "ror"];

fn reg(r: u8) -> &'static str {
    REG[usize::from(r & 15)]
}

fn sreg(s: u8) -> String {
    format!("s{s}")
}

fn reglist(list: u16) -> String {
    let regs: Vec<&str> = (0..16)
        .filter(|i| list >> i & 1 == 1)
        .map(|i| reg(i as u8))
        .collect();
    format!("{{{}}}", regs.join(", "))
}

/// "lsl #3", "asr #32", "rrx" or "" for LSL #0.
fn shift_text(shift_type: u8, imm5: u8) -> String {
    match (shift_type, imm5) {
        (0, 0) => String::new(),
        (3, 0) => ", rrx".into(),
        (1 | 2, 0) => format!(", {} #32", SHIFT[usize::from(shift_type)]),
        _ => format!(", {} #{imm5}", SHIFT[usize::from(shift_type)]),
    }
}

// ---------------------------------------------------------------------------------------
// The builder.

/// The general-purpose registers an operand may name where SP and PC may not be.
const GP: [u8; 14] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 14];
/// GP and SP: bases of 32-bit loads and stores.
const BASES: [u8; 15] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14];
const LOW: [u8; 8] = [0, 1, 2, 3, 4, 5, 6, 7];

/// An addressing constraint: `size` bytes at an `align`-aligned address in the window;
/// the offset a multiple of `step` in `min..=max`; `post` (the address is the base) and
/// `wb` (the base is written back).
#[derive(Clone, Copy, Debug)]
struct Addr {
    size: u32,
    align: u32,
    min: i32,
    max: i32,
    step: i32,
    post: bool,
    wb: bool,
}

impl Addr {
    fn offset(size: u32, align: u32, min: i32, max: i32, step: i32) -> Addr {
        Addr {
            size,
            align,
            min,
            max,
            step,
            post: false,
            wb: false,
        }
    }
}

struct Builder<'a> {
    rng: &'a mut ChaCha8Rng,
    code: Vec<u8>,
    listing: Vec<(u32, String)>,
    /// The registers' values where the generator knows them.
    known: [Option<u32>; 16],
    /// Inside an IT block or code a branch may skip.
    conditional: bool,
    /// The condition of the current IT slot.
    it_cond: Option<u8>,
    /// Literal loads read only code before this offset (later code may still be patched).
    literal_limit: Option<usize>,
}

impl<'a> Builder<'a> {
    fn new(rng: &'a mut ChaCha8Rng, start: &ArchState) -> Builder<'a> {
        let mut known = [None; 16];
        for (k, &v) in known.iter_mut().zip(&start.r).take(15) {
            *k = Some(v);
        }
        Builder {
            rng,
            code: Vec::new(),
            listing: Vec::new(),
            known,
            conditional: false,
            it_cond: None,
            literal_limit: None,
        }
    }

    // -- Plumbing.

    fn pc(&self) -> u32 {
        CODE_BASE + self.code.len() as u32
    }

    fn emit(&mut self, insn: Insn, text: String) {
        self.listing.push((self.pc(), text));
        self.code.extend(insn.bytes());
    }

    fn chance(&mut self, p: f64) -> bool {
        self.rng.random_bool(p)
    }

    fn below(&mut self, n: u32) -> u32 {
        self.rng.random_range(0..n)
    }

    fn pick(&mut self, from: &[u8]) -> u8 {
        *from.choose(self.rng).unwrap_or(&0)
    }

    fn pick_except(&mut self, from: &[u8], except: &[u8]) -> u8 {
        let allowed: Vec<u8> = from
            .iter()
            .copied()
            .filter(|r| !except.contains(r))
            .collect();
        *allowed.choose(self.rng).unwrap_or(&from[0])
    }

    fn gp(&mut self) -> u8 {
        self.pick(&GP)
    }

    fn low(&mut self) -> u8 {
        self.pick(&LOW)
    }

    /// A weighted choice: the index into `weights`.
    fn weighted(&mut self, weights: &[u32]) -> usize {
        let total: u32 = weights.iter().sum();
        let mut x = self.below(total);
        for (i, &w) in weights.iter().enumerate() {
            if x < w {
                return i;
            }
            x -= w;
        }
        weights.len() - 1
    }

    /// The suffix of a 16-bit instruction that sets the flags outside IT blocks only.
    fn s16(&self) -> &'static str {
        match self.it_cond {
            Some(c) => COND[usize::from(c)],
            None => "s",
        }
    }

    /// The condition suffix inside an IT block.
    fn c(&self) -> &'static str {
        self.it_cond.map_or("", |c| COND[usize::from(c)])
    }

    /// Register `r` is written with a value the generator does not follow.
    fn wr(&mut self, r: u8) {
        debug_assert!(r != 13 && r != 15, "the generator wrote {}", reg(r));
        self.known[usize::from(r)] = None;
    }

    /// Register `r` is written with `v` (unknown when the write is conditional).
    fn set(&mut self, r: u8, v: u32) {
        self.known[usize::from(r)] = if self.conditional { None } else { Some(v) };
    }

    /// MOVW (and MOVT when needed) of `v` into `r`.
    fn materialise(&mut self, r: u8, v: u32) {
        debug_assert!(!self.conditional);
        self.emit(
            thumb::movw_movt(false, r, v as u16),
            format!("movw {}, #{:#x}", reg(r), v & 0xffff),
        );
        if v >> 16 != 0 {
            self.emit(
                thumb::movw_movt(true, r, (v >> 16) as u16),
                format!("movt {}, #{:#x}", reg(r), v >> 16),
            );
        }
        self.set(r, v);
    }

    // -- Addresses.

    fn fits(&self, a: Addr, rb: u8, b: u32, o: i32) -> bool {
        let ea = if a.post { b } else { b.wrapping_add(o as u32) };
        let inside = u64::from(ea) >= u64::from(DATA_BASE)
            && u64::from(ea) + u64::from(a.size) <= u64::from(DATA_END)
            && ea % a.align == 0;
        if !inside {
            return false;
        }
        if rb == 13 && a.wb {
            let new = b.wrapping_add(o as u32);
            return !self.conditional && new % 4 == 0 && (DATA_BASE..=DATA_END).contains(&new);
        }
        true
    }

    fn random_offset(&mut self, a: Addr, lo: i64, hi: i64) -> Option<i32> {
        let step = i64::from(a.step.max(1));
        let first = lo.div_euclid(step) * step + if lo.rem_euclid(step) == 0 { 0 } else { step };
        if first > hi {
            return None;
        }
        let n = (hi - first) / step;
        Some((first + step * self.rng.random_range(0..=n)) as i32)
    }

    /// A base register from `cands` (not in `except`) and an offset meeting `a`: a
    /// register whose value is known if one fits, else (outside conditional code) a
    /// register given a fitting value by MOVW/MOVT.
    fn address(&mut self, a: Addr, cands: &[u8], except: &[u8]) -> Option<(u8, i32)> {
        let mut order: Vec<u8> = cands
            .iter()
            .copied()
            .filter(|r| !except.contains(r))
            .collect();
        order.shuffle(self.rng);
        for &rb in &order {
            let Some(b) = self.known[usize::from(rb)] else {
                continue;
            };
            let (lo, hi) = if a.post {
                (i64::from(a.min), i64::from(a.max))
            } else {
                (
                    i64::from(a.min).max(i64::from(DATA_BASE) - i64::from(b)),
                    i64::from(a.max).min(i64::from(DATA_END) - i64::from(a.size) - i64::from(b)),
                )
            };
            for _ in 0..8 {
                match self.random_offset(a, lo, hi) {
                    Some(o) if self.fits(a, rb, b, o) => return Some((rb, o)),
                    Some(_) => {}
                    None => break,
                }
            }
        }
        if self.conditional {
            return None;
        }
        let movable: Vec<u8> = order.iter().copied().filter(|&r| r != 13).collect();
        let rb = *movable.choose(self.rng)?;
        for _ in 0..16 {
            let slots = (DATA_LEN - a.size) / a.align + 1;
            let ea = DATA_BASE + a.align * self.below(slots);
            let o = self.random_offset(a, i64::from(a.min), i64::from(a.max))?;
            let b = if a.post {
                ea
            } else {
                ea.wrapping_sub(o as u32)
            };
            if self.fits(a, rb, b, o) {
                self.materialise(rb, b);
                return Some((rb, o));
            }
        }
        None
    }

    /// After a writeback of `o` to base `rb`.
    fn written_back(&mut self, rb: u8, o: i32) {
        if rb == 13 {
            debug_assert!(!self.conditional);
            let sp = self.known[13].unwrap_or(0).wrapping_add(o as u32);
            debug_assert!(sp % 4 == 0 && (DATA_BASE..=DATA_END).contains(&sp));
            self.known[13] = Some(sp);
        } else {
            match self.known[usize::from(rb)] {
                Some(b) => self.set(rb, b.wrapping_add(o as u32)),
                None => self.wr(rb),
            }
        }
    }

    fn sp(&self) -> u32 {
        self.known[13].unwrap_or(DATA_BASE)
    }

    // -- Items.

    /// One item: an instruction, a short pattern, an IT block or a branch over code.
    fn item(&mut self) {
        match self.weighted(&[30, 8, 8, 4, 5, 16]) {
            0 => self.simple(),
            1 => self.it_block(),
            2 => self.branch(),
            3 => self.exclusive(),
            4 => self.stack(),
            _ => self.fp_any(),
        }
    }

    /// One instruction that may go into an IT block or skipped code (and anywhere else).
    fn simple(&mut self) {
        match self.weighted(&[14, 8, 8, 4, 4, 4, 4, 6, 4, 6, 3, 6, 12, 3, 3, 3, 12]) {
            0 => self.dp16(),
            1 => self.dp_modimm(),
            2 => self.dp_shifted(),
            3 => self.shift_reg(),
            4 => self.plain_imm(),
            5 => self.sat_bitfield(),
            6 => self.misc(),
            7 => self.multiply(),
            8 => self.long_multiply(),
            9 => self.parallel(),
            10 => self.extend(),
            11 => self.compare(),
            12 => self.load_store(),
            13 => self.load_store_dual(),
            14 => self.load_store_multiple(),
            15 => self.literal(),
            _ => self.fp_simple(),
        }
    }

    // -- Integer data processing.

    /// The 16-bit data-processing encodings (A5.2.1 to A5.2.3, A5.2.5).
    fn dp16(&mut self) {
        let s = self.s16();
        let c = self.c();
        match self.below(12) {
            0 => {
                // LSL/LSR/ASR (immediate) T1; LSL #0 is MOVS (register) T2, not in IT.
                let op = self.below(3) as u8;
                let (rd, rm) = (self.low(), self.low());
                let mut imm = *[0u8, 1, 31, 16].choose(self.rng).unwrap_or(&1);
                if self.chance(0.5) {
                    imm = self.below(32) as u8;
                }
                if op == 0 && imm == 0 && self.it_cond.is_some() {
                    imm = 1;
                }
                let text = if op == 0 && imm == 0 {
                    format!("movs {}, {}", reg(rd), reg(rm))
                } else {
                    let amount = if imm == 0 { 32 } else { imm };
                    format!(
                        "{}{s} {}, {}, #{amount}",
                        SHIFT[usize::from(op)],
                        reg(rd),
                        reg(rm)
                    )
                };
                self.emit(thumb::shift_imm16(op, rd, rm, imm), text);
                self.wr(rd);
            }
            1 => {
                // ADD (register) T1 / SUB (register) T1.
                let sub = self.chance(0.5);
                let (rd, rn, rm) = (self.low(), self.low(), self.low());
                let m = if sub { "sub" } else { "add" };
                self.emit(
                    thumb::add_sub_reg16(sub, rd, rn, rm),
                    format!("{m}{s} {}, {}, {}", reg(rd), reg(rn), reg(rm)),
                );
                self.wr(rd);
            }
            2 => {
                // ADD (immediate) T1 / SUB (immediate) T1.
                let sub = self.chance(0.5);
                let (rd, rn, imm) = (self.low(), self.low(), self.below(8) as u8);
                let m = if sub { "sub" } else { "add" };
                self.emit(
                    thumb::add_sub_imm3(sub, rd, rn, imm),
                    format!("{m}{s} {}, {}, #{imm}", reg(rd), reg(rn)),
                );
                self.wr(rd);
            }
            3 => {
                // MOV (immediate) T1, ADD (immediate) T2, SUB (immediate) T2.
                let op = *[0u8, 2, 3].choose(self.rng).unwrap_or(&0);
                let rd = self.low();
                let imm = if self.chance(0.3) {
                    *[0u8, 1, 0x7f, 0x80, 0xff].choose(self.rng).unwrap_or(&0)
                } else {
                    self.rng.random()
                };
                let m = ["mov", "cmp", "add", "sub"][usize::from(op)];
                self.emit(
                    thumb::imm8_op(op, rd, imm),
                    format!("{m}{s} {}, #{imm}", reg(rd)),
                );
                self.wr(rd);
            }
            4..=6 => {
                // The data-processing (register) group, TST/CMP/CMN aside.
                let op = *[0u8, 1, 2, 3, 4, 5, 6, 7, 9, 12, 13, 14, 15]
                    .choose(self.rng)
                    .unwrap_or(&0);
                let (rdn, rm) = (self.low(), self.low());
                if matches!(op, 2 | 3 | 4 | 7) && self.chance(0.4) && !self.conditional {
                    // A shift amount with edge cases: Rm[7:0] of 0, 31, 32, 33, 255, 256.
                    let amount = *[0u32, 1, 31, 32, 33, 255, 256]
                        .choose(self.rng)
                        .unwrap_or(&0);
                    if rm != rdn {
                        self.materialise(rm, amount);
                    }
                }
                let m = [
                    "and", "eor", "lsl", "lsr", "asr", "adc", "sbc", "ror", "tst", "rsb", "cmp",
                    "cmn", "orr", "mul", "bic", "mvn",
                ][usize::from(op)];
                let text = match op {
                    9 => format!("rsb{s} {}, {}, #0", reg(rdn), reg(rm)),
                    13 => format!("mul{s} {}, {}, {}", reg(rdn), reg(rm), reg(rdn)),
                    15 => format!("mvn{s} {}, {}", reg(rdn), reg(rm)),
                    _ => format!("{m}{s} {}, {}", reg(rdn), reg(rm)),
                };
                self.emit(thumb::dp16(op, rdn, rm), text);
                self.wr(rdn);
            }
            7 => {
                // ADD (register) T2 with any registers but SP (Rm may be PC).
                let rdn = self.gp();
                let rm = if self.chance(0.15) { 15 } else { self.gp() };
                self.emit(
                    thumb::add_reg_t2(rdn, rm),
                    format!("add{c} {}, {}", reg(rdn), reg(rm)),
                );
                self.wr(rdn);
            }
            8 => {
                // MOV (register) T1 with any registers, Rm may be SP.
                let rd = self.gp();
                let rm = if self.chance(0.2) { 13 } else { self.gp() };
                self.emit(
                    thumb::mov_reg_t1(rd, rm),
                    format!("mov{c} {}, {}", reg(rd), reg(rm)),
                );
                match self.known[usize::from(rm)] {
                    Some(v) => self.set(rd, v),
                    None => self.wr(rd),
                }
            }
            9 => {
                // ADR T1 / ADD (SP plus immediate) T1.
                let rd = self.low();
                let imm = self.rng.random::<u8>();
                if self.chance(0.5) {
                    self.emit(
                        thumb::adr_t1(rd, imm),
                        format!("adr{c} {}, #{}", reg(rd), u32::from(imm) * 4),
                    );
                    let v = ((self.pc() - 2 + 4) & !3) + u32::from(imm) * 4;
                    self.set(rd, v);
                } else {
                    self.emit(
                        thumb::add_sp_imm_t1(rd, imm),
                        format!("add{c} {}, sp, #{}", reg(rd), u32::from(imm) * 4),
                    );
                    let v = self.sp() + u32::from(imm) * 4;
                    self.set(rd, v);
                }
            }
            10 => {
                // SXTH/SXTB/UXTH/UXTB T1.
                let op = self.below(4) as u8;
                let (rd, rm) = (self.low(), self.low());
                let m = ["sxth", "sxtb", "uxth", "uxtb"][usize::from(op)];
                self.emit(
                    thumb::extend16(op, rd, rm),
                    format!("{m}{c} {}, {}", reg(rd), reg(rm)),
                );
                self.wr(rd);
            }
            _ => {
                // REV/REV16/REVSH T1.
                let op = *[0u8, 1, 3].choose(self.rng).unwrap_or(&0);
                let (rd, rm) = (self.low(), self.low());
                let m = ["rev", "rev16", "", "revsh"][usize::from(op)];
                self.emit(
                    thumb::rev16(op, rd, rm),
                    format!("{m}{c} {}, {}", reg(rd), reg(rm)),
                );
                self.wr(rd);
            }
        }
    }

    /// A modified immediate (A5.3.2): the plain byte, the three replicated forms (with a
    /// non-zero byte) and the rotated forms, biased to the edges.
    fn modified_imm(&mut self) -> u16 {
        let imm8: u16 = self.rng.random::<u8>().into();
        match self.below(4) {
            0 => imm8,
            1 => (self.rng.random_range(1..4) << 8) | imm8.max(1),
            2 => {
                let rot = *[8u16, 9, 16, 24, 30, 31].choose(self.rng).unwrap_or(&8);
                rot << 7 | (imm8 & 0x7f)
            }
            _ => self.rng.random_range(8u16..32) << 7 | (imm8 & 0x7f),
        }
    }

    /// Data processing (modified immediate) (A5.3.1).
    fn dp_modimm(&mut self) {
        let c = self.c();
        let imm12 = self.modified_imm();
        let (v, _) = thumb::expand_imm(imm12);
        let names = [
            "and", "bic", "orr", "orn", "eor", "", "", "", "add", "", "adc", "sbc", "", "sub",
            "rsb",
        ];
        let op = *[0u8, 1, 2, 3, 4, 8, 10, 11, 13, 14]
            .choose(self.rng)
            .unwrap_or(&0);
        let s = self.chance(0.5);
        let sx = if s { "s" } else { "" };
        // MOV and MVN are ORR and ORN with Rn = PC.
        if matches!(op, 2 | 3) && self.chance(0.35) {
            let rd = self.gp();
            let m = if op == 2 { "mov" } else { "mvn" };
            self.emit(
                thumb::dp_modimm(op, s, rd, 15, imm12),
                format!("{m}{sx}{c}.w {}, #{v:#x}", reg(rd)),
            );
            self.wr(rd);
            return;
        }
        let (rd, rn) = (self.gp(), self.gp());
        self.emit(
            thumb::dp_modimm(op, s, rd, rn, imm12),
            format!(
                "{}{sx}{c}.w {}, {}, #{v:#x}",
                names[usize::from(op)],
                reg(rd),
                reg(rn)
            ),
        );
        self.wr(rd);
    }

    /// A shift for the shifted-register forms, biased to the edges (LSL #0, LSR #32,
    /// ASR #32, RRX, #1, #31).
    fn imm_shift(&mut self) -> (u8, u8) {
        let t = self.below(4) as u8;
        let imm = if self.chance(0.5) {
            *[0u8, 1, 31].choose(self.rng).unwrap_or(&0)
        } else {
            self.below(32) as u8
        };
        (t, imm)
    }

    /// Data processing (shifted register) (A5.3.11): AND BIC ORR ORN EOR ADD ADC SBC SUB
    /// RSB with S or not, MOV/MVN with every immediate shift (LSL LSR ASR ROR RRX), PKHBT and
    /// PKHTB.
    fn dp_shifted(&mut self) {
        let c = self.c();
        let names = [
            "and", "bic", "orr", "orn", "eor", "", "", "", "add", "", "adc", "sbc", "", "sub",
            "rsb",
        ];
        let (t, imm) = self.imm_shift();
        match self.below(8) {
            0 | 1 => {
                // MOV (register) T3 and the immediate shifts LSL/LSR/ASR/ROR/RRX T2, MVN.
                let s = self.chance(0.5);
                let sx = if s { "s" } else { "" };
                let (rd, rm) = (self.gp(), self.gp());
                let mvn = self.chance(0.25);
                let op = if mvn { 3 } else { 2 };
                let text = if mvn {
                    format!(
                        "mvn{sx}{c}.w {}, {}{}",
                        reg(rd),
                        reg(rm),
                        shift_text(t, imm)
                    )
                } else {
                    match (t, imm) {
                        (0, 0) => format!("mov{sx}{c}.w {}, {}", reg(rd), reg(rm)),
                        (3, 0) => format!("rrx{sx}{c} {}, {}", reg(rd), reg(rm)),
                        _ => format!(
                            "{}{sx}{c}.w {}, {}, #{}",
                            SHIFT[usize::from(t)],
                            reg(rd),
                            reg(rm),
                            if imm == 0 { 32 } else { imm }
                        ),
                    }
                };
                self.emit(thumb::dp_shifted(op, s, rd, 15, rm, t, imm), text);
                self.wr(rd);
            }
            2 => {
                // PKHBT (LSL) / PKHTB (ASR, #0 meaning 32).
                let tb = self.chance(0.5);
                let (rd, rn, rm) = (self.gp(), self.gp(), self.gp());
                let text = if tb {
                    format!(
                        "pkhtb{c} {}, {}, {}, asr #{}",
                        reg(rd),
                        reg(rn),
                        reg(rm),
                        if imm == 0 { 32 } else { imm }
                    )
                } else {
                    format!("pkhbt{c} {}, {}, {}, lsl #{imm}", reg(rd), reg(rn), reg(rm))
                };
                self.emit(
                    thumb::dp_shifted(6, false, rd, rn, rm, if tb { 2 } else { 0 }, imm),
                    text,
                );
                self.wr(rd);
            }
            _ => {
                let op = *[0u8, 1, 2, 3, 4, 8, 10, 11, 13, 14]
                    .choose(self.rng)
                    .unwrap_or(&0);
                let s = self.chance(0.5);
                let sx = if s { "s" } else { "" };
                let (rd, rn, rm) = (self.gp(), self.gp(), self.gp());
                self.emit(
                    thumb::dp_shifted(op, s, rd, rn, rm, t, imm),
                    format!(
                        "{}{sx}{c}.w {}, {}, {}{}",
                        names[usize::from(op)],
                        reg(rd),
                        reg(rn),
                        reg(rm),
                        shift_text(t, imm)
                    ),
                );
                self.wr(rd);
            }
        }
    }

    /// LSL/LSR/ASR/ROR (register) T2, the amount in Rm[7:0] sometimes set to an edge.
    fn shift_reg(&mut self) {
        let c = self.c();
        let t = self.below(4) as u8;
        let s = self.chance(0.5);
        let (rd, rn, rm) = (self.gp(), self.gp(), self.gp());
        if !self.conditional && self.chance(0.5) && rm != rn {
            let amount = *[0u32, 1, 31, 32, 33, 255, 256, 0xffff_ff20]
                .choose(self.rng)
                .unwrap_or(&0);
            self.materialise(rm, amount);
        }
        let sx = if s { "s" } else { "" };
        self.emit(
            thumb::shift_reg32(t, s, rd, rn, rm),
            format!(
                "{}{sx}{c}.w {}, {}, {}",
                SHIFT[usize::from(t)],
                reg(rd),
                reg(rn),
                reg(rm)
            ),
        );
        self.wr(rd);
    }

    /// Data processing (plain binary immediate) (A5.3.3): ADDW, SUBW, MOVW, MOVT, ADR T2/T3.
    fn plain_imm(&mut self) {
        let c = self.c();
        let rd = self.gp();
        match self.below(4) {
            0 => {
                let sub = self.chance(0.5);
                let rn = self.gp();
                let imm = self.rng.random_range(0..4096u16);
                let m = if sub { "subw" } else { "addw" };
                self.emit(
                    thumb::addw_subw(sub, rd, rn, imm),
                    format!("{m}{c} {}, {}, #{imm}", reg(rd), reg(rn)),
                );
                self.wr(rd);
            }
            1 => {
                let imm: u16 = self.rng.random();
                self.emit(
                    thumb::movw_movt(false, rd, imm),
                    format!("movw{c} {}, #{imm:#x}", reg(rd)),
                );
                self.set(rd, u32::from(imm));
            }
            2 => {
                let imm: u16 = self.rng.random();
                self.emit(
                    thumb::movw_movt(true, rd, imm),
                    format!("movt{c} {}, #{imm:#x}", reg(rd)),
                );
                match self.known[usize::from(rd)] {
                    Some(v) => self.set(rd, (v & 0xffff) | u32::from(imm) << 16),
                    None => self.wr(rd),
                }
            }
            _ => {
                // ADR T3 (add) / T2 (subtract): ADDW/SUBW with Rn = PC.
                let sub = self.chance(0.5);
                let imm = self.rng.random_range(0..4096u16);
                let base = (self.pc() + 4) & !3;
                self.emit(
                    thumb::addw_subw(sub, rd, 15, imm),
                    format!("adr{c}.w {}, #{}{imm}", reg(rd), if sub { "-" } else { "" }),
                );
                let v = if sub {
                    base.wrapping_sub(imm.into())
                } else {
                    base + u32::from(imm)
                };
                self.set(rd, v);
            }
        }
    }

    /// SSAT, USAT, SSAT16, USAT16, SBFX, UBFX, BFI, BFC (A5.3.3).
    fn sat_bitfield(&mut self) {
        let c = self.c();
        let (rd, rn) = (self.gp(), self.gp());
        match self.below(7) {
            0 | 1 => {
                // SSAT/USAT with LSL #0-31 or ASR #1-31.
                let unsigned = self.chance(0.5);
                let asr = self.chance(0.5);
                let amount = if asr {
                    self.rng.random_range(1..32)
                } else {
                    self.below(32) as u8
                };
                let sat = if self.chance(0.3) {
                    *[0u8, 1, 15, 30, 31].choose(self.rng).unwrap_or(&0)
                } else {
                    self.below(32) as u8
                };
                let op = (if unsigned { 4 } else { 0 }) | u8::from(asr);
                let shown = if unsigned { sat } else { sat + 1 };
                let text = format!(
                    "{}{c} {}, #{shown}, {}, {} #{amount}",
                    if unsigned { "usat" } else { "ssat" },
                    reg(rd),
                    reg(rn),
                    if asr { "asr" } else { "lsl" }
                );
                self.emit(thumb::sat_bitfield(op, rd, rn, amount, sat), text);
            }
            2 => {
                // SSAT16 (to 1-16 bits) / USAT16 (to 0-15 bits).
                let unsigned = self.chance(0.5);
                let sat = self.below(16) as u8;
                let shown = if unsigned { sat } else { sat + 1 };
                let op = if unsigned { 5 } else { 1 };
                self.emit(
                    thumb::sat_bitfield(op, rd, rn, 0, sat),
                    format!(
                        "{}{c} {}, #{shown}, {}",
                        if unsigned { "usat16" } else { "ssat16" },
                        reg(rd),
                        reg(rn)
                    ),
                );
            }
            3 | 4 => {
                // SBFX/UBFX: lsb + width <= 32.
                let unsigned = self.chance(0.5);
                let lsb = self.below(32) as u8;
                let width = self.rng.random_range(1..=32 - lsb);
                let op = if unsigned { 6 } else { 2 };
                self.emit(
                    thumb::sat_bitfield(op, rd, rn, lsb, width - 1),
                    format!(
                        "{}{c} {}, {}, #{lsb}, #{width}",
                        if unsigned { "ubfx" } else { "sbfx" },
                        reg(rd),
                        reg(rn)
                    ),
                );
            }
            _ => {
                // BFI/BFC: msb >= lsb.
                let lsb = self.below(32) as u8;
                let msb = self.rng.random_range(lsb..32);
                let width = msb - lsb + 1;
                if self.chance(0.3) {
                    self.emit(
                        thumb::sat_bitfield(3, rd, 15, lsb, msb),
                        format!("bfc{c} {}, #{lsb}, #{width}", reg(rd)),
                    );
                } else {
                    self.emit(
                        thumb::sat_bitfield(3, rd, rn, lsb, msb),
                        format!("bfi{c} {}, {}, #{lsb}, #{width}", reg(rd), reg(rn)),
                    );
                }
            }
        }
        self.wr(rd);
    }

    /// QADD, QDADD, QSUB, QDSUB, REV, REV16, RBIT, REVSH, SEL, CLZ (A5.3.15).
    fn misc(&mut self) {
        let c = self.c();
        let (rd, rn, rm) = (self.gp(), self.gp(), self.gp());
        let (op1, op2) = *[
            (0u8, 0u8),
            (0, 1),
            (0, 2),
            (0, 3),
            (1, 0),
            (1, 1),
            (1, 2),
            (1, 3),
            (2, 0),
            (3, 0),
            (3, 0),
        ]
        .choose(self.rng)
        .unwrap_or(&(0, 0));
        let (insn, text) = match op1 {
            0 => {
                let m = ["qadd", "qdadd", "qsub", "qdsub"][usize::from(op2)];
                (
                    thumb::misc32(0, op2, rd, rn, rm),
                    format!("{m}{c} {}, {}, {}", reg(rd), reg(rm), reg(rn)),
                )
            }
            1 => {
                let m = ["rev", "rev16", "rbit", "revsh"][usize::from(op2)];
                (
                    thumb::misc32(1, op2, rd, rm, rm),
                    format!("{m}{c}.w {}, {}", reg(rd), reg(rm)),
                )
            }
            2 => (
                thumb::misc32(2, 0, rd, rn, rm),
                format!("sel{c} {}, {}, {}", reg(rd), reg(rn), reg(rm)),
            ),
            _ => (
                thumb::misc32(3, 0, rd, rm, rm),
                format!("clz{c} {}, {}", reg(rd), reg(rm)),
            ),
        };
        self.emit(insn, text);
        self.wr(rd);
    }

    /// MUL, MLA, MLS and the DSP multiplies (A5.3.16).
    fn multiply(&mut self) {
        let c = self.c();
        let (rd, rn, rm) = (self.gp(), self.gp(), self.gp());
        let ra = self.gp();
        let op1 = self.below(8) as u8;
        let accumulate = self.chance(0.5);
        let (op2, name, always_ra) = match op1 {
            0 => {
                if self.chance(0.3) {
                    (1, "mls".to_string(), true)
                } else {
                    (0, if accumulate { "mla" } else { "mul" }.to_string(), false)
                }
            }
            1 => {
                let (n, m) = (self.below(2) as u8, self.below(2) as u8);
                let xy = format!(
                    "{}{}",
                    ["b", "t"][usize::from(n)],
                    ["b", "t"][usize::from(m)]
                );
                (
                    n << 1 | m,
                    format!("{}{xy}", if accumulate { "smla" } else { "smul" }),
                    false,
                )
            }
            2 | 4 => {
                let x = self.below(2) as u8;
                let base = match (op1, accumulate) {
                    (2, true) => "smlad",
                    (2, false) => "smuad",
                    (_, true) => "smlsd",
                    _ => "smusd",
                };
                (x, format!("{base}{}", if x == 1 { "x" } else { "" }), false)
            }
            3 => {
                let y = self.below(2) as u8;
                (
                    y,
                    format!(
                        "{}{}",
                        if accumulate { "smlaw" } else { "smulw" },
                        ["b", "t"][usize::from(y)]
                    ),
                    false,
                )
            }
            5 | 6 => {
                let round = self.below(2) as u8;
                let base = match (op1, accumulate) {
                    (5, true) => "smmla",
                    (5, false) => "smmul",
                    _ => "smmls",
                };
                (
                    round,
                    format!("{base}{}", if round == 1 { "r" } else { "" }),
                    op1 == 6,
                )
            }
            _ => (
                0,
                if accumulate { "usada8" } else { "usad8" }.to_string(),
                false,
            ),
        };
        let with_ra = always_ra || accumulate;
        let ra_field = if with_ra { ra } else { 15 };
        let text = if with_ra {
            format!(
                "{name}{c} {}, {}, {}, {}",
                reg(rd),
                reg(rn),
                reg(rm),
                reg(ra)
            )
        } else {
            format!("{name}{c} {}, {}, {}", reg(rd), reg(rn), reg(rm))
        };
        self.emit(thumb::mul32(op1, op2, rd, rn, rm, ra_field), text);
        self.wr(rd);
    }

    /// SMULL, UMULL, SMLAL, UMLAL, UMAAL, SMLALxy, SMLALD(X), SMLSLD(X), SDIV, UDIV (A5.3.17).
    fn long_multiply(&mut self) {
        let c = self.c();
        if self.chance(0.25) {
            // SDIV/UDIV, with division by zero and INT_MIN / -1 now and then.
            let unsigned = self.chance(0.5);
            let (rd, rn, rm) = (self.gp(), self.gp(), self.gp());
            if !self.conditional && rn != rm && self.chance(0.3) {
                if self.chance(0.5) {
                    self.materialise(rm, 0);
                } else {
                    self.materialise(rn, 0x8000_0000);
                    self.materialise(rm, 0xffff_ffff);
                }
            }
            let op1 = if unsigned { 3 } else { 1 };
            self.emit(
                thumb::long_mul(op1, 15, 15, rd, rn, rm),
                format!(
                    "{}{c} {}, {}, {}",
                    if unsigned { "udiv" } else { "sdiv" },
                    reg(rd),
                    reg(rn),
                    reg(rm)
                ),
            );
            self.wr(rd);
            return;
        }
        let rdlo = self.gp();
        let rdhi = self.pick_except(&GP, &[rdlo]);
        let (rn, rm) = (self.gp(), self.gp());
        let (op1, op2, name) = match self.below(8) {
            0 => (0u8, 0u8, "smull".to_string()),
            1 => (2, 0, "umull".to_string()),
            2 => (4, 0, "smlal".to_string()),
            3 => (6, 0, "umlal".to_string()),
            4 => (6, 6, "umaal".to_string()),
            5 => {
                let (n, m) = (self.below(2) as u8, self.below(2) as u8);
                (
                    4,
                    0b1000 | n << 1 | m,
                    format!(
                        "smlal{}{}",
                        ["b", "t"][usize::from(n)],
                        ["b", "t"][usize::from(m)]
                    ),
                )
            }
            6 => {
                let x = self.below(2) as u8;
                (
                    4,
                    0b1100 | x,
                    format!("smlald{}", if x == 1 { "x" } else { "" }),
                )
            }
            _ => {
                let x = self.below(2) as u8;
                (
                    5,
                    0b1100 | x,
                    format!("smlsld{}", if x == 1 { "x" } else { "" }),
                )
            }
        };
        self.emit(
            thumb::long_mul(op1, op2, rdlo, rdhi, rn, rm),
            format!(
                "{name}{c} {}, {}, {}, {}",
                reg(rdlo),
                reg(rdhi),
                reg(rn),
                reg(rm)
            ),
        );
        self.wr(rdlo);
        self.wr(rdhi);
    }

    /// The parallel addition and subtraction family (A5.3.13, A5.3.14), then now and then
    /// SEL, which reads the GE bits they set.
    fn parallel(&mut self) {
        let c = self.c();
        let op1 = *[0u8, 1, 2, 4, 5, 6].choose(self.rng).unwrap_or(&0);
        let op2 = *[0u8, 1, 2, 4, 5, 6].choose(self.rng).unwrap_or(&0);
        let (rd, rn, rm) = (self.gp(), self.gp(), self.gp());
        let prefix = ["s", "q", "sh", "", "u", "uq", "uh"][usize::from(op2)];
        let op = ["add8", "add16", "asx", "", "sub8", "sub16", "sax"][usize::from(op1)];
        self.emit(
            thumb::parallel(op1, op2, rd, rn, rm),
            format!("{prefix}{op}{c} {}, {}, {}", reg(rd), reg(rn), reg(rm)),
        );
        self.wr(rd);
        if self.it_cond.is_none() && self.chance(0.3) {
            let (rd, rn, rm) = (self.gp(), self.gp(), self.gp());
            self.emit(
                thumb::misc32(2, 0, rd, rn, rm),
                format!("sel {}, {}, {}", reg(rd), reg(rn), reg(rm)),
            );
            self.wr(rd);
        }
    }

    /// SXTB/UXTB/SXTH/UXTH/SXTB16/UXTB16 and the add forms, rotated (A5.3.12).
    fn extend(&mut self) {
        let c = self.c();
        let op = self.below(6) as u8;
        let (rd, rm) = (self.gp(), self.gp());
        let add = self.chance(0.6);
        let rn = if add { self.gp() } else { 15 };
        let rot = self.below(4) as u8;
        let names = ["h", "h", "b16", "b16", "b", "b"];
        let sign = if op % 2 == 0 { "s" } else { "u" };
        let rot_text = if rot == 0 {
            String::new()
        } else {
            format!(", ror #{}", 8 * rot)
        };
        let text = if add {
            format!(
                "{sign}xta{}{c} {}, {}, {}{rot_text}",
                names[usize::from(op)],
                reg(rd),
                reg(rn),
                reg(rm)
            )
        } else {
            format!(
                "{sign}xt{}{c}.w {}, {}{rot_text}",
                names[usize::from(op)],
                reg(rd),
                reg(rm)
            )
        };
        self.emit(thumb::extend32(op, rd, rn, rm, rot), text);
        self.wr(rd);
    }

    /// CMP/CMN/TST/TEQ in their 16- and 32-bit encodings.
    fn compare(&mut self) {
        let c = self.c();
        match self.below(7) {
            0 => {
                let (rn, imm) = (self.low(), self.rng.random::<u8>());
                self.emit(
                    thumb::imm8_op(1, rn, imm),
                    format!("cmp{c} {}, #{imm}", reg(rn)),
                );
            }
            1 => {
                let op = *[8u8, 10, 11].choose(self.rng).unwrap_or(&10);
                let (rn, rm) = (self.low(), self.low());
                let m = ["tst", "", "cmp", "cmn"][usize::from(op - 8)];
                self.emit(
                    thumb::dp16(op, rn, rm),
                    format!("{m}{c} {}, {}", reg(rn), reg(rm)),
                );
            }
            2 => {
                // CMP (register) T2: not both low.
                let rn = self.gp();
                let rm = if rn < 8 {
                    self.pick(&[8, 9, 10, 11, 12, 14])
                } else {
                    self.gp()
                };
                self.emit(
                    thumb::cmp_reg_t2(rn, rm),
                    format!("cmp{c} {}, {}", reg(rn), reg(rm)),
                );
            }
            3 | 4 => {
                let op = *[0u8, 4, 8, 13].choose(self.rng).unwrap_or(&0);
                let m = match op {
                    0 => "tst",
                    4 => "teq",
                    8 => "cmn",
                    _ => "cmp",
                };
                let rn = self.gp();
                let imm12 = self.modified_imm();
                let (v, _) = thumb::expand_imm(imm12);
                self.emit(
                    thumb::dp_modimm(op, true, 15, rn, imm12),
                    format!("{m}{c}.w {}, #{v:#x}", reg(rn)),
                );
            }
            _ => {
                let op = *[0u8, 4, 8, 13].choose(self.rng).unwrap_or(&0);
                let m = match op {
                    0 => "tst",
                    4 => "teq",
                    8 => "cmn",
                    _ => "cmp",
                };
                let (rn, rm) = (self.gp(), self.gp());
                let (t, imm) = self.imm_shift();
                self.emit(
                    thumb::dp_shifted(op, true, 15, rn, rm, t, imm),
                    format!("{m}{c}.w {}, {}{}", reg(rn), reg(rm), shift_text(t, imm)),
                );
            }
        }
    }

    // -- Loads and stores.

    /// A random single-access width: loads may be signed.
    fn width(&mut self, load: bool) -> Width {
        let choices: &[Width] = if load {
            &[
                Width::Word,
                Width::Word,
                Width::Byte,
                Width::Half,
                Width::SignedByte,
                Width::SignedHalf,
            ]
        } else {
            &[Width::Word, Width::Word, Width::Byte, Width::Half]
        };
        *choices.choose(self.rng).unwrap_or(&Width::Word)
    }

    /// Natural alignment most of the time, none (allowed for LDR/STR/LDRH/STRH) otherwise.
    fn alignment(&mut self, w: Width) -> u32 {
        if self.chance(0.8) {
            w.bytes()
        } else {
            1
        }
    }

    fn mnemonic(w: Width, load: bool) -> &'static str {
        match (w, load) {
            (Width::Word, true) => "ldr",
            (Width::Word, false) => "str",
            (Width::Byte, true) => "ldrb",
            (Width::Byte, false) => "strb",
            (Width::Half, true) => "ldrh",
            (Width::Half, false) => "strh",
            (Width::SignedByte, _) => "ldrsb",
            (Width::SignedHalf, _) => "ldrsh",
        }
    }

    /// LDR/STR/LDRB/STRB/LDRH/STRH/LDRSB/LDRSH in their 16-bit (immediate, register, SP)
    /// and 32-bit (imm12, negative imm8, pre- and post-indexed, register LSL #0-3) forms.
    fn load_store(&mut self) {
        let c = self.c();
        let load = self.chance(0.55);
        match self.below(7) {
            0 => {
                // 16-bit immediate: STR/LDR imm5*4, STRB/LDRB imm5, STRH/LDRH imm5*2.
                let w = *[Width::Word, Width::Byte, Width::Half]
                    .choose(self.rng)
                    .unwrap_or(&Width::Word);
                let scale = w.bytes() as i32;
                let align = self.alignment(w);
                let a = Addr::offset(w.bytes(), align, 0, 31 * scale, scale);
                let rt = self.low();
                let Some((rn, o)) = self.address(a, &LOW, &[]) else {
                    return;
                };
                let op = match w {
                    Width::Word => 0,
                    Width::Byte => 2,
                    _ => 4,
                } + u8::from(load);
                self.emit(
                    thumb::ldst_imm16(op, rt, rn, (o / scale) as u8),
                    format!(
                        "{}{c} {}, [{}, #{o}]",
                        Self::mnemonic(w, load),
                        reg(rt),
                        reg(rn)
                    ),
                );
                if load {
                    self.wr(rt);
                }
            }
            1 => {
                // 16-bit register offset: Rm small and known.
                let w = self.width(load);
                let align = self.alignment(w);
                let a = Addr::offset(w.bytes(), align, 0, 0, 1);
                let Some((rn, _)) = self.address(a, &LOW, &[]) else {
                    return;
                };
                let base = self.known[usize::from(rn)].unwrap_or(0);
                let Some(rm) = self.index_register(&LOW, &[rn], base, w.bytes(), align, 0) else {
                    return;
                };
                let rt = self.low();
                let op = match (w, load) {
                    (Width::Word, false) => 0,
                    (Width::Half, false) => 1,
                    (Width::Byte, false) => 2,
                    (Width::SignedByte, _) => 3,
                    (Width::Word, true) => 4,
                    (Width::Half, true) => 5,
                    (Width::Byte, true) => 6,
                    (Width::SignedHalf, _) => 7,
                };
                self.emit(
                    thumb::ldst_reg16(op, rt, rn, rm),
                    format!(
                        "{}{c} {}, [{}, {}]",
                        Self::mnemonic(w, load),
                        reg(rt),
                        reg(rn),
                        reg(rm)
                    ),
                );
                if load {
                    self.wr(rt);
                }
            }
            2 => {
                // LDR/STR (immediate) T2, SP-relative.
                let sp = self.sp();
                let lo = 0.max((DATA_BASE as i64 - sp as i64) / 4);
                let hi = 255.min((DATA_END as i64 - 4 - sp as i64) / 4);
                if lo > hi {
                    return;
                }
                let imm = self.rng.random_range(lo..=hi) as u8;
                let rt = self.low();
                self.emit(
                    thumb::ldst_sp16(load, rt, imm),
                    format!(
                        "{}{c} {}, [sp, #{}]",
                        if load { "ldr" } else { "str" },
                        reg(rt),
                        u32::from(imm) * 4
                    ),
                );
                if load {
                    self.wr(rt);
                }
            }
            3 => {
                // 32-bit imm12, SP allowed as the base.
                let w = self.width(load);
                let align = self.alignment(w);
                let a = Addr::offset(w.bytes(), align, 0, 4095, 1);
                let rt = self.gp();
                let Some((rn, o)) = self.address(a, &BASES, &[]) else {
                    return;
                };
                self.emit(
                    thumb::ldst_imm12(w, load, rt, rn, o as u16),
                    format!(
                        "{}{c}.w {}, [{}, #{o}]",
                        Self::mnemonic(w, load),
                        reg(rt),
                        reg(rn)
                    ),
                );
                if load {
                    self.wr(rt);
                }
            }
            4 | 5 => {
                // 32-bit imm8: offset (negative), pre-indexed or post-indexed with writeback.
                let w = self.width(load);
                let align = self.alignment(w);
                let rt = self.gp();
                let mode = self.below(3);
                let a = match mode {
                    0 => Addr::offset(w.bytes(), align, -255, 0, 1),
                    _ => Addr {
                        size: w.bytes(),
                        align,
                        min: -255,
                        max: 255,
                        step: 1,
                        post: mode == 2,
                        wb: true,
                    },
                };
                // Writeback with Rn = Rt is UNPREDICTABLE; SP as a writeback base only in
                // word steps (SP stays aligned).
                let except: Vec<u8> = if mode == 0 { vec![] } else { vec![rt] };
                let mut a = a;
                let cands: &[u8] = if mode == 0 { &BASES } else { &GP };
                if mode != 0
                    && !self.conditional
                    && self.chance(0.2)
                    && w == Width::Word
                    && rt != 13
                {
                    a.step = 4;
                    if let Some((rn, o)) = self.address(a, &[13], &except) {
                        self.emit_imm8(w, load, rt, rn, mode, o);
                        return;
                    }
                    a.step = 1;
                }
                let Some((rn, o)) = self.address(a, cands, &except) else {
                    return;
                };
                self.emit_imm8(w, load, rt, rn, mode, o);
            }
            _ => {
                // 32-bit register offset, LSL #0-3.
                let w = self.width(load);
                let align = self.alignment(w);
                let shift = self.below(4) as u8;
                let a = Addr::offset(w.bytes(), align, 0, 0, 1);
                let Some((rn, _)) = self.address(a, &BASES, &[]) else {
                    return;
                };
                let base = self.known[usize::from(rn)].unwrap_or(0);
                let Some(rm) = self.index_register(&GP, &[rn], base, w.bytes(), align, shift)
                else {
                    return;
                };
                let rt = self.gp();
                let sh = if shift == 0 {
                    String::new()
                } else {
                    format!(", lsl #{shift}")
                };
                self.emit(
                    thumb::ldst_reg32(w, load, rt, rn, rm, shift),
                    format!(
                        "{}{c}.w {}, [{}, {}{sh}]",
                        Self::mnemonic(w, load),
                        reg(rt),
                        reg(rn),
                        reg(rm)
                    ),
                );
                if load {
                    self.wr(rt);
                }
            }
        }
    }

    fn emit_imm8(&mut self, w: Width, load: bool, rt: u8, rn: u8, mode: u32, o: i32) {
        let c = self.c();
        let (index, wb) = match mode {
            0 => (Index::Offset, false),
            1 => (Index::Pre, true),
            _ => (Index::Post, true),
        };
        let m = Self::mnemonic(w, load);
        let text = match mode {
            0 => format!("{m}{c} {}, [{}, #{o}]", reg(rt), reg(rn)),
            1 => format!("{m}{c} {}, [{}, #{o}]!", reg(rt), reg(rn)),
            _ => format!("{m}{c} {}, [{}], #{o}", reg(rt), reg(rn)),
        };
        self.emit(thumb::ldst_imm8(w, load, rt, rn, index, o), text);
        if load {
            self.wr(rt);
        }
        if wb {
            self.written_back(rn, o);
        }
    }

    /// A register holding an index `i` with `base + (i << shift)` a fitting address: one
    /// whose value is known, or (outside conditional code) one given it by MOVW.
    fn index_register(
        &mut self,
        cands: &[u8],
        except: &[u8],
        base: u32,
        size: u32,
        align: u32,
        shift: u8,
    ) -> Option<u8> {
        let fits = |i: u32| {
            let ea = base.wrapping_add(i << shift);
            ea >= DATA_BASE
                && u64::from(ea) + u64::from(size) <= u64::from(DATA_END)
                && ea % align == 0
        };
        let mut order: Vec<u8> = cands
            .iter()
            .copied()
            .filter(|r| !except.contains(r))
            .collect();
        order.shuffle(self.rng);
        for &r in &order {
            if let Some(v) = self.known[usize::from(r)] {
                if fits(v) {
                    return Some(r);
                }
            }
        }
        if self.conditional {
            return None;
        }
        // Indices reaching the window from the base, as a small non-negative number.
        let lo = i64::from(DATA_BASE) - i64::from(base);
        let hi = i64::from(DATA_END) - i64::from(size) - i64::from(base);
        let hi = hi.min(0xffff << shift);
        if hi < 0 {
            return None;
        }
        let lo = lo.max(0);
        for _ in 0..16 {
            let i = (self.rng.random_range(lo..=hi) >> shift) as u32;
            if fits(i) {
                let r = *order.choose(self.rng)?;
                self.materialise(r, i);
                return Some(r);
            }
        }
        None
    }

    /// LDRD/STRD (immediate): offset, pre-indexed or post-indexed, word-aligned.
    fn load_store_dual(&mut self) {
        let c = self.c();
        let load = self.chance(0.5);
        let rt = self.gp();
        let rt2 = if load {
            self.pick_except(&GP, &[rt])
        } else {
            self.gp()
        };
        let mode = self.below(3);
        let a = Addr {
            size: 8,
            align: 4,
            min: -1020,
            max: 1020,
            step: 4,
            post: mode == 2,
            wb: mode != 0,
        };
        let except: Vec<u8> = if mode == 0 { vec![] } else { vec![rt, rt2] };
        // SP as a writeback base of LDRD/STRD is defined (DDI 0403E A7.7.50) but LLVM 14's
        // disassembler calls the pre-indexed form "potentially undefined": not generated.
        let cands: &[u8] = if mode == 0 { &BASES } else { &GP };
        let Some((rn, o)) = self.address(a, cands, &except) else {
            return;
        };
        let m = if load { "ldrd" } else { "strd" };
        let text = match mode {
            0 => format!("{m}{c} {}, {}, [{}, #{o}]", reg(rt), reg(rt2), reg(rn)),
            1 => format!("{m}{c} {}, {}, [{}, #{o}]!", reg(rt), reg(rt2), reg(rn)),
            _ => format!("{m}{c} {}, {}, [{}], #{o}", reg(rt), reg(rt2), reg(rn)),
        };
        let (index, wb) = match mode {
            0 => (Index::Offset, false),
            1 => (Index::Pre, true),
            _ => (Index::Post, true),
        };
        self.emit(thumb::ldrd_strd(load, rt, rt2, rn, index, o), text);
        if load {
            self.wr(rt);
            self.wr(rt2);
        }
        if wb {
            self.written_back(rn, o);
        }
    }

    /// LDM/STM: 16-bit (STM always with writeback, the base not in the list unless lowest;
    /// LDM with writeback unless the base is in the list) and 32-bit IA/DB with or without
    /// writeback (at least two registers, never SP or PC, the base not in the list with
    /// writeback).
    fn load_store_multiple(&mut self) {
        let c = self.c();
        let load = self.chance(0.5);
        if self.chance(0.4) {
            let mut list: u8 = self.rng.random::<u8>() | 1 << self.below(8);
            let a = Addr::offset(4 * list.count_ones(), 4, 0, 0, 1);
            let Some((rn, _)) = self.address(a, &LOW, &[]) else {
                return;
            };
            let in_list = list >> rn & 1 == 1;
            if !load && in_list && list.trailing_zeros() != u32::from(rn) {
                list &= !(1 << rn);
                if list == 0 {
                    return;
                }
            }
            let size = 4 * list.count_ones();
            let base = self.known[usize::from(rn)].unwrap_or(0);
            if !(base % 4 == 0 && base >= DATA_BASE && base + size <= DATA_END) {
                return;
            }
            let in_list = list >> rn & 1 == 1;
            let wb = !load || !in_list;
            let m = if load { "ldm" } else { "stm" };
            self.emit(
                thumb::ldm_stm16(load, rn, list),
                format!(
                    "{m}{c} {}{}, {}",
                    reg(rn),
                    if wb { "!" } else { "" },
                    reglist(list.into())
                ),
            );
            if load {
                for r in (0..8).filter(|r| list >> r & 1 == 1) {
                    self.wr(r);
                }
            }
            if wb {
                // (STM with the base lowest in the list stores its original value.)
                self.written_back(rn, size as i32);
            }
            return;
        }
        let mut list: u16 = 0;
        while list.count_ones() < 2 {
            list |= 1 << self.pick(&GP);
            if self.chance(0.3) {
                list |= self.rng.random::<u16>() & 0x5fff;
            }
        }
        let db = self.chance(0.5);
        let wb = self.chance(0.6);
        let size = 4 * list.count_ones();
        let fixed = if db { -(size as i32) } else { 0 };
        let a = Addr::offset(size, 4, fixed, fixed, 1);
        let except: Vec<u8> = if wb {
            (0..16).filter(|r| list >> r & 1 == 1).collect()
        } else {
            vec![]
        };
        let Some((rn, _)) = self.address(a, &GP, &except) else {
            return;
        };
        let m = match (load, db) {
            (true, false) => "ldmia",
            (true, true) => "ldmdb",
            (false, false) => "stmia",
            (false, true) => "stmdb",
        };
        self.emit(
            thumb::ldm_stm32(load, db, rn, wb, list),
            format!(
                "{m}{c}.w {}{}, {}",
                reg(rn),
                if wb { "!" } else { "" },
                reglist(list)
            ),
        );
        if load {
            for r in (0..16u8).filter(|r| list >> r & 1 == 1) {
                self.wr(r);
            }
        }
        if wb {
            self.written_back(rn, if db { -(size as i32) } else { size as i32 });
        }
    }

    /// LDR/LDRB/LDRH/LDRSB/LDRSH (literal), reading code already in the block.
    fn literal(&mut self) {
        let c = self.c();
        let limit = self.literal_limit.unwrap_or(self.code.len()) as u32;
        let w = self.width(true);
        let size = w.bytes();
        if limit < size {
            return;
        }
        let at = self.pc();
        let base = (at + 4) & !3;
        let lowest = base.saturating_sub(4095).max(CODE_BASE);
        let highest = CODE_BASE + limit - size;
        if lowest > highest {
            return;
        }
        let target = self.rng.random_range(lowest..=highest);
        let imm = base - target;
        let rt = self.gp();
        self.emit(
            thumb::ldr_literal32(w, rt, false, imm as u16),
            format!(
                "{}{c}.w {}, [pc, #-{imm}]",
                Self::mnemonic(w, true),
                reg(rt)
            ),
        );
        self.wr(rt);
    }

    // -- Patterns outside IT blocks.

    /// LDREX/STREX (word, byte, halfword) on one address, or CLREX then a STREX that fails.
    fn exclusive(&mut self) {
        let kind = self.below(4);
        let (size, align) = match kind {
            0 | 3 => (4, 4),
            1 => (1, 1),
            _ => (2, 2),
        };
        let (max, step) = if size == 4 { (1020, 4) } else { (0, 1) };
        let a = Addr::offset(size, align, 0, max, step);
        let Some((rn, o)) = self.address(a, &BASES, &[]) else {
            return;
        };
        let rt = self.gp();
        if kind == 3 {
            self.emit(thumb::clrex(), "clrex".into());
        } else {
            let (insn, text) = match kind {
                0 => (
                    thumb::ldrex(rt, rn, (o / 4) as u8),
                    format!("ldrex {}, [{}, #{o}]", reg(rt), reg(rn)),
                ),
                1 => (
                    thumb::ldrex_bh(false, rt, rn),
                    format!("ldrexb {}, [{}]", reg(rt), reg(rn)),
                ),
                _ => (
                    thumb::ldrex_bh(true, rt, rn),
                    format!("ldrexh {}, [{}]", reg(rt), reg(rn)),
                ),
            };
            self.emit(insn, text);
            self.wr(rt);
            if rt == rn {
                // The base is gone: no STREX to the same address.
                return;
            }
        }
        let rt2 = self.gp();
        let rd = self.pick_except(&GP, &[rt2, rn]);
        let (insn, text) = match kind {
            0 | 3 => (
                thumb::strex(rd, rt2, rn, (o / 4) as u8),
                format!("strex {}, {}, [{}, #{o}]", reg(rd), reg(rt2), reg(rn)),
            ),
            1 => (
                thumb::strex_bh(false, rd, rt2, rn),
                format!("strexb {}, {}, [{}]", reg(rd), reg(rt2), reg(rn)),
            ),
            _ => (
                thumb::strex_bh(true, rd, rt2, rn),
                format!("strexh {}, {}, [{}]", reg(rd), reg(rt2), reg(rn)),
            ),
        };
        self.emit(insn, text);
        self.wr(rd);
    }

    /// PUSH/POP (16- and 32-bit, one register or many), VPUSH/VPOP, ADD/SUB SP, #imm:
    /// SP stays aligned inside the window.
    fn stack(&mut self) {
        let sp = self.sp();
        let room_below = (sp - DATA_BASE) / 4;
        let room_above = (DATA_END - sp) / 4;
        match self.below(7) {
            0 => {
                // PUSH T1 (r0-r7, LR).
                let list = self.rng.random::<u8>();
                let lr = self.chance(0.3) || list == 0;
                let n = list.count_ones() + u32::from(lr);
                if n > room_below {
                    return;
                }
                let mut all = u16::from(list);
                if lr {
                    all |= 1 << 14;
                }
                self.emit(
                    thumb::push_pop16(false, list, lr),
                    format!("push {}", reglist(all)),
                );
                self.known[13] = Some(sp - 4 * n);
            }
            1 => {
                // POP T1 (r0-r7, never PC).
                let list = self.rng.random::<u8>().max(1);
                let n = list.count_ones();
                if n > room_above {
                    return;
                }
                self.emit(
                    thumb::push_pop16(true, list, false),
                    format!("pop {}", reglist(list.into())),
                );
                for r in (0..8).filter(|r| list >> r & 1 == 1) {
                    self.wr(r);
                }
                self.known[13] = Some(sp + 4 * n);
            }
            2 => {
                // PUSH T2 / POP T2 (STMDB SP! / LDMIA SP!), two or more of r0-r12, LR.
                let pop = self.chance(0.5);
                let mut list: u16 = 0;
                while list.count_ones() < 2 {
                    list |= 1 << self.pick(&GP);
                    if self.chance(0.3) {
                        list |= self.rng.random::<u16>() & 0x5fff;
                    }
                }
                let n = list.count_ones();
                if n > if pop { room_above } else { room_below } {
                    return;
                }
                self.emit(
                    thumb::ldm_stm32(pop, !pop, 13, true, list),
                    format!("{}.w {}", if pop { "pop" } else { "push" }, reglist(list)),
                );
                if pop {
                    for r in (0..16u8).filter(|r| list >> r & 1 == 1) {
                        self.wr(r);
                    }
                    self.known[13] = Some(sp + 4 * n);
                } else {
                    self.known[13] = Some(sp - 4 * n);
                }
            }
            3 => {
                // PUSH T3 / POP T3: STR Rt, [SP, #-4]! / LDR Rt, [SP], #4.
                let pop = self.chance(0.5);
                if (pop && room_above == 0) || (!pop && room_below == 0) {
                    return;
                }
                let rt = self.gp();
                if pop {
                    self.emit(
                        thumb::ldst_imm8(Width::Word, true, rt, 13, Index::Post, 4),
                        format!("pop.w {{{}}}", reg(rt)),
                    );
                    self.wr(rt);
                    self.known[13] = Some(sp + 4);
                } else {
                    self.emit(
                        thumb::ldst_imm8(Width::Word, false, rt, 13, Index::Pre, -4),
                        format!("push.w {{{}}}", reg(rt)),
                    );
                    self.known[13] = Some(sp - 4);
                }
            }
            4 => {
                // VPUSH/VPOP of 1-16 single-precision registers.
                let pop = self.chance(0.5);
                let room = if pop { room_above } else { room_below };
                let first = self.below(32) as u8;
                let max = (32 - u32::from(first)).min(16).min(room);
                if max == 0 {
                    return;
                }
                let n = self.rng.random_range(1..=max) as u8;
                self.emit(
                    thumb::vldm_vstm(pop, !pop, true, 13, first, n),
                    format!(
                        "{} {{s{first}-s{}}}",
                        if pop { "vpop" } else { "vpush" },
                        first + n - 1
                    ),
                );
                self.known[13] = Some(if pop {
                    sp + 4 * u32::from(n)
                } else {
                    sp - 4 * u32::from(n)
                });
            }
            _ => {
                // ADD (SP plus immediate) T2 / SUB (SP minus immediate) T1.
                let sub = self.chance(0.5);
                let room = if sub { room_below } else { room_above }.min(127);
                if room == 0 {
                    return;
                }
                let n = self.rng.random_range(0..=room);
                self.emit(
                    thumb::add_sub_sp_imm7(sub, n as u8),
                    format!("{} sp, #{}", if sub { "sub" } else { "add" }, 4 * n),
                );
                self.known[13] = Some(if sub { sp - 4 * n } else { sp + 4 * n });
            }
        }
    }

    /// An IT block of 1-4 instructions with random conditions (AL only with all "then").
    fn it_block(&mut self) {
        let n = self.rng.random_range(1..=4usize);
        let firstcond = if self.chance(0.05) {
            14
        } else {
            self.below(14) as u8
        };
        let mut conds = vec![firstcond];
        let mut letters = String::new();
        let mut mask: u8 = 0;
        for k in 1..n {
            let then = firstcond == 14 || self.chance(0.5);
            let bit = if then {
                firstcond & 1
            } else {
                (firstcond & 1) ^ 1
            };
            mask |= bit << (4 - k);
            conds.push((firstcond & !1) | bit);
            letters.push(if then { 't' } else { 'e' });
        }
        mask |= 1 << (4 - n);
        let name = if firstcond == 14 {
            "al"
        } else {
            COND[usize::from(firstcond)]
        };
        self.emit(thumb::it(firstcond, mask), format!("it{letters} {name}"));
        let was = self.conditional;
        self.conditional = true;
        for cond in conds {
            self.it_cond = Some(cond);
            let before = self.code.len();
            let lines = self.listing.len();
            // Each slot holds exactly one instruction (in an IT block no item emits more
            // than one): retry the rare items that emit nothing (no base register fits),
            // then fall back to a conditional NOP.
            for _ in 0..8 {
                if self.chance(0.4) {
                    self.dp16();
                } else {
                    self.simple();
                }
                if self.code.len() != before {
                    break;
                }
            }
            if self.code.len() == before {
                let c = self.c();
                self.emit(thumb::nop16(), format!("nop{c}"));
            }
            assert_eq!(self.listing.len(), lines + 1, "one instruction per IT slot");
        }
        self.it_cond = None;
        self.conditional = was;
    }

    /// A forward branch over 1-4 instructions: B<c> (16- and 32-bit), B (16- and 32-bit),
    /// CBZ/CBNZ, or TBB/TBH into a run of instructions.
    fn branch(&mut self) {
        let kind = self.below(6);
        if kind >= 4 {
            self.table_branch(kind == 5);
            return;
        }
        let at = self.code.len();
        let insn_len = if kind == 1 { 4 } else { 2 };
        // A placeholder, patched once the skipped code is known.
        self.emit(thumb::nop16(), String::new());
        if insn_len == 4 {
            self.code.extend(thumb::nop16().bytes());
        }
        let listing_at = self.listing.len() - 1;
        self.skipped_code(at, 1..=4, 100);
        let end = self.code.len();
        let region = (end - at - insn_len) as i32;
        let cond = self.below(14) as u8;
        let unconditional = self.chance(0.2);
        let (insn, text) = match kind {
            0 if unconditional => (
                thumb::b_t2(region - 2 + insn_len as i32 - 2),
                format!("b #{}", region),
            ),
            0 => (
                thumb::b_cond_t1(cond, region - 2 + insn_len as i32 - 2),
                format!("b{} #{}", COND[usize::from(cond)], region),
            ),
            1 if unconditional => (thumb::b_t4(region), format!("b.w #{region}")),
            1 => (
                thumb::b_cond_t3(cond, region),
                format!("b{}.w #{region}", COND[usize::from(cond)]),
            ),
            _ => {
                let rn = self.low();
                let nonzero = kind == 3;
                (
                    thumb::cbz(nonzero, rn, (region - 2) as u32),
                    format!(
                        "{} {}, #{region}",
                        if nonzero { "cbnz" } else { "cbz" },
                        reg(rn)
                    ),
                )
            }
        };
        debug_assert_eq!(insn.len(), insn_len);
        self.code.splice(at..at + insn_len, insn.bytes());
        self.listing[listing_at].1 = format!("{text} (skips {region} bytes)");
    }

    /// Code a branch may skip (or enter in the middle): `count` instructions of the kinds
    /// an IT block may hold, at most `max_bytes`.
    fn skipped_code(
        &mut self,
        patch_at: usize,
        count: std::ops::RangeInclusive<usize>,
        max_bytes: usize,
    ) -> Vec<usize> {
        let was = (self.conditional, self.literal_limit);
        self.conditional = true;
        self.literal_limit = Some(patch_at);
        let start = self.code.len();
        let n = self.rng.random_range(count);
        let mut boundaries = Vec::new();
        for _ in 0..n {
            if self.code.len() - start + 4 > max_bytes {
                break;
            }
            let before = self.code.len();
            self.simple();
            if self.code.len() != before {
                boundaries.push(before);
            }
        }
        if self.code.len() == start {
            self.emit(thumb::nop16(), "nop".into());
            boundaries.push(start);
        }
        (self.conditional, self.literal_limit) = was;
        boundaries
    }

    /// `MOVW Rm, #index; TBB [PC, Rm]` (or TBH [PC, Rm, LSL #1]), the table, then the
    /// instructions its entries lead into.
    fn table_branch(&mut self, half: bool) {
        let entries = self.rng.random_range(1..=4usize);
        let index = self.below(entries as u32);
        let rm = self.gp();
        self.materialise(rm, index);
        let at = self.code.len();
        let insn = thumb::tbb(half, 15, rm);
        self.emit(
            insn,
            if half {
                format!("tbh [pc, {}, lsl #1]", reg(rm))
            } else {
                format!("tbb [pc, {}]", reg(rm))
            },
        );
        let table_at = self.code.len();
        let table_len = if half {
            2 * entries
        } else {
            entries.next_multiple_of(2)
        };
        self.listing.push((self.pc(), String::new()));
        let listing_at = self.listing.len() - 1;
        self.code.extend(std::iter::repeat_n(0, table_len));
        let boundaries = self.skipped_code(at, entries..=entries + 2, 200);
        let end = self.code.len();
        // Targets: instruction boundaries or the end; entry = (target - table) / 2.
        let mut targets = Vec::new();
        for _ in 0..entries {
            let t = if self.chance(0.15) {
                end
            } else {
                *boundaries.choose(self.rng).unwrap_or(&end)
            };
            targets.push(((t - table_at) / 2) as u16);
        }
        let mut table = Vec::new();
        for &t in &targets {
            if half {
                table.extend_from_slice(&t.to_le_bytes());
            } else {
                table.push(t as u8);
            }
        }
        table.resize(table_len, 0);
        self.code[table_at..table_at + table_len].copy_from_slice(&table);
        let shown: Vec<String> = targets.iter().map(|t| format!("{t}")).collect();
        self.listing[listing_at].1 = format!(
            "{} {} (halfwords from the table)",
            if half { ".short" } else { ".byte" },
            shown.join(", ")
        );
    }

    // -- Floating point.

    fn s(&mut self) -> u8 {
        self.below(32) as u8
    }

    /// Any floating-point item: the simple ones, or VMSR of a new FPSCR.
    fn fp_any(&mut self) {
        if self.chance(0.08) {
            let rt = self.gp();
            let v = random_fpscr(self.rng);
            self.materialise(rt, v);
            self.emit(thumb::vmsr(rt), format!("vmsr fpscr, {}", reg(rt)));
        } else {
            self.fp_simple();
        }
    }

    /// A floating-point instruction that may go into an IT block.
    fn fp_simple(&mut self) {
        let c = self.c();
        match self.weighted(&[10, 4, 3, 4, 4, 3, 3, 2, 3, 3, 2]) {
            0 => {
                // VADD VSUB VMUL VNMUL VDIV VMLA VMLS VNMLA VNMLS VFMA VFMS VFNMA VFNMS.
                let (opc, op, name) = *[
                    (3u8, false, "vadd"),
                    (3, true, "vsub"),
                    (2, false, "vmul"),
                    (2, true, "vnmul"),
                    (4, false, "vdiv"),
                    (0, false, "vmla"),
                    (0, true, "vmls"),
                    (1, true, "vnmla"),
                    (1, false, "vnmls"),
                    (6, false, "vfma"),
                    (6, true, "vfms"),
                    (5, true, "vfnma"),
                    (5, false, "vfnms"),
                ]
                .choose(self.rng)
                .unwrap_or(&(3, false, "vadd"));
                let (d, n, m) = (self.s(), self.s(), self.s());
                self.emit(
                    thumb::vfp3(opc, op, d, n, m),
                    format!("{name}{c}.f32 {}, {}, {}", sreg(d), sreg(n), sreg(m)),
                );
            }
            1 => {
                // VABS VNEG VSQRT VMOV (register).
                let (opc2, o, name) = *[
                    (0u8, true, "vabs"),
                    (1, false, "vneg"),
                    (1, true, "vsqrt"),
                    (0, false, "vmov"),
                ]
                .choose(self.rng)
                .unwrap_or(&(0, true, "vabs"));
                let (d, m) = (self.s(), self.s());
                self.emit(
                    thumb::vfp2(opc2, o, d, m),
                    format!("{name}{c}.f32 {}, {}", sreg(d), sreg(m)),
                );
            }
            2 => {
                // VCMP/VCMPE with a register or zero, then (often) VMRS APSR_nzcv, FPSCR.
                let e = self.chance(0.5);
                let d = self.s();
                let name = if e { "vcmpe" } else { "vcmp" };
                if self.chance(0.3) {
                    self.emit(
                        thumb::vcmp_zero(e, d),
                        format!("{name}{c}.f32 {}, #0", sreg(d)),
                    );
                } else {
                    let m = self.s();
                    self.emit(
                        thumb::vfp2(4, e, d, m),
                        format!("{name}{c}.f32 {}, {}", sreg(d), sreg(m)),
                    );
                }
                if self.it_cond.is_none() && self.chance(0.7) {
                    self.emit(thumb::vmrs(15), "vmrs APSR_nzcv, fpscr".into());
                }
            }
            3 => {
                // VCVT(R) between f32 and s32/u32.
                let (d, m) = (self.s(), self.s());
                match self.below(3) {
                    0 => {
                        let signed = self.chance(0.5);
                        self.emit(
                            thumb::vfp2(8, signed, d, m),
                            format!(
                                "vcvt{c}.f32.{}32 {}, {}",
                                if signed { "s" } else { "u" },
                                sreg(d),
                                sreg(m)
                            ),
                        );
                    }
                    _ => {
                        let signed = self.chance(0.5);
                        let toward_zero = self.chance(0.5);
                        self.emit(
                            thumb::vfp2(if signed { 13 } else { 12 }, toward_zero, d, m),
                            format!(
                                "vcvt{}{c}.{}32.f32 {}, {}",
                                if toward_zero { "" } else { "r" },
                                if signed { "s" } else { "u" },
                                sreg(d),
                                sreg(m)
                            ),
                        );
                    }
                }
            }
            4 => {
                // VCVT between f32 and 16- or 32-bit fixed point.
                let to_fixed = self.chance(0.5);
                let unsigned = self.chance(0.5);
                let sx = self.chance(0.5);
                let size = if sx { 32 } else { 16 };
                let imm5 = if sx {
                    self.below(32) as u8
                } else {
                    self.below(17) as u8
                };
                let frac = size - u32::from(imm5);
                let d = self.s();
                let ty = format!("{}{size}", if unsigned { "u" } else { "s" });
                let text = if to_fixed {
                    format!("vcvt{c}.{ty}.f32 {}, {}, #{frac}", sreg(d), sreg(d))
                } else {
                    format!("vcvt{c}.f32.{ty} {}, {}, #{frac}", sreg(d), sreg(d))
                };
                self.emit(thumb::vcvt_fixed(to_fixed, unsigned, sx, d, imm5), text);
            }
            5 => {
                // VCVTB/VCVTT between half and single precision.
                let to_half = self.chance(0.5);
                let top = self.chance(0.5);
                let (d, m) = (self.s(), self.s());
                let text = format!(
                    "vcvt{}{c}.{} {}, {}",
                    if top { "t" } else { "b" },
                    if to_half { "f16.f32" } else { "f32.f16" },
                    sreg(d),
                    sreg(m)
                );
                self.emit(thumb::vfp2(if to_half { 3 } else { 2 }, top, d, m), text);
            }
            6 => {
                // VMOV (immediate).
                let d = self.s();
                let imm8: u8 = self.rng.random();
                let value = f32::from_bits(thumb::vfp_expand_imm(imm8));
                self.emit(
                    thumb::vmov_imm(d, imm8),
                    format!("vmov{c}.f32 {}, #{value:e}", sreg(d)),
                );
            }
            7 => {
                // VMOV between a core register and a single-precision register.
                let to_core = self.chance(0.5);
                let (rt, n) = (self.gp(), self.s());
                if to_core {
                    self.emit(
                        thumb::vmov_core_single(true, rt, n),
                        format!("vmov{c} {}, {}", reg(rt), sreg(n)),
                    );
                    self.wr(rt);
                } else {
                    self.emit(
                        thumb::vmov_core_single(false, rt, n),
                        format!("vmov{c} {}, {}", sreg(n), reg(rt)),
                    );
                }
            }
            8 => {
                // VMOV between two core registers and two consecutive singles.
                let to_core = self.chance(0.5);
                let rt = self.gp();
                let rt2 = if to_core {
                    self.pick_except(&GP, &[rt])
                } else {
                    self.gp()
                };
                let m = self.below(31) as u8;
                if to_core {
                    self.emit(
                        thumb::vmov_core_two_singles(true, rt, rt2, m),
                        format!(
                            "vmov{c} {}, {}, {}, {}",
                            reg(rt),
                            reg(rt2),
                            sreg(m),
                            sreg(m + 1)
                        ),
                    );
                    self.wr(rt);
                    self.wr(rt2);
                } else {
                    self.emit(
                        thumb::vmov_core_two_singles(false, rt, rt2, m),
                        format!(
                            "vmov{c} {}, {}, {}, {}",
                            sreg(m),
                            sreg(m + 1),
                            reg(rt),
                            reg(rt2)
                        ),
                    );
                }
            }
            9 => {
                // VLDR/VSTR.
                let load = self.chance(0.5);
                let d = self.s();
                let a = Addr::offset(4, 4, -1020, 1020, 4);
                let Some((rn, o)) = self.address(a, &BASES, &[]) else {
                    return;
                };
                self.emit(
                    thumb::vldr_vstr(load, d, rn, o >= 0, (o.unsigned_abs() / 4) as u8),
                    format!(
                        "{}{c} {}, [{}, #{o}]",
                        if load { "vldr" } else { "vstr" },
                        sreg(d),
                        reg(rn)
                    ),
                );
            }
            _ => {
                // VLDM/VSTM: IA with or without writeback, DB with writeback.
                let load = self.chance(0.5);
                let first = self.s();
                let n = self.rng.random_range(1..=(32 - u32::from(first)).min(16)) as u8;
                let db = self.chance(0.4);
                let wb = db || self.chance(0.5);
                let size = 4 * u32::from(n);
                let fixed = if db { -(size as i32) } else { 0 };
                let a = Addr::offset(size, 4, fixed, fixed, 1);
                let Some((rn, _)) = self.address(a, &GP, &[]) else {
                    return;
                };
                let m = match (load, db) {
                    (true, false) => "vldmia",
                    (true, true) => "vldmdb",
                    (false, false) => "vstmia",
                    (false, true) => "vstmdb",
                };
                self.emit(
                    thumb::vldm_vstm(load, db, wb, rn, first, n),
                    format!(
                        "{m}{c} {}{}, {{s{first}-s{}}}",
                        reg(rn),
                        if wb { "!" } else { "" },
                        first + n - 1
                    ),
                );
                if wb {
                    self.written_back(rn, if db { -(size as i32) } else { size as i32 });
                }
            }
        }
        if self.it_cond.is_none() && self.chance(0.05) {
            // VMRS Rt, FPSCR now and then.
            let rt = self.gp();
            self.emit(
                thumb::vmrs(rt),
                format!("vmrs{} {}, fpscr", self.c(), reg(rt)),
            );
            self.wr(rt);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_seed_gives_the_same_blocks() {
        let a: Vec<Block> = {
            let mut g = BlockGen::new(7);
            (0..50).map(|_| g.next()).collect()
        };
        let mut g = BlockGen::new(7);
        for block in &a {
            assert_eq!(&g.next(), block);
        }
        assert_eq!(BlockGen::block(7, 13), a[13]);
        assert_ne!(BlockGen::block(8, 13), a[13]);
    }

    #[test]
    fn blocks_keep_their_invariants() {
        let mut g = BlockGen::new(3);
        for _ in 0..500 {
            let b = g.next();
            assert!(!b.code.is_empty() && b.code.len() % 2 == 0);
            assert_eq!(b.data.len(), DATA_LEN as usize);
            assert_eq!(b.start.r[15], CODE_BASE);
            assert_eq!(b.start.xpsr & (T_BIT | 0x0600_fc00), T_BIT);
            assert!(b.start.r[13] % 4 == 0 && (DATA_BASE..=DATA_END).contains(&b.start.r[13]));
            assert!(b
                .listing
                .iter()
                .all(|(a, _)| (CODE_BASE..b.end()).contains(a)));
        }
    }
}
