//! The QEMU oracle (`autoplug_mcu_oracle`) against results known from the ARMv7-M
//! Architecture Reference Manual (DDI 0403E), and the block generator's promises.
//!
//! The hand-written blocks were assembled with LLVM 14's `llvm-mc -triple=thumbv7em-none-eabihf
//! -mcpu=cortex-m4 -mattr=+vfp4d16sp -show-encoding`; each byte string has its assembly
//! beside it. These tests need `qemu-system-arm` (scripts/setup-tests installs it, or name
//! another binary in AUTOPLUG_QEMU): without it they fail and say so.

use std::time::Instant;

use autoplug_mcu::cpu::ArchState;
use autoplug_mcu_oracle::qemu::qemu_binary;
use autoplug_mcu_oracle::{
    Block, BlockGen, OracleError, Outcome, Qemu, CODE_BASE, DATA_BASE, DATA_LEN,
};

const N: u32 = 1 << 31;
const Z: u32 = 1 << 30;
const C: u32 = 1 << 29;
const V: u32 = 1 << 28;
const Q: u32 = 1 << 27;
const T: u32 = 1 << 24;
const GE_SHIFT: u32 = 16;

// FPSCR.
const IOC: u32 = 1 << 0;
const UFC: u32 = 1 << 3;
const IXC: u32 = 1 << 4;
const IDC: u32 = 1 << 7;
const RP: u32 = 1 << 22;
const RM: u32 = 2 << 22;
const FZ: u32 = 1 << 24;
const DN: u32 = 1 << 25;
const AHP: u32 = 1 << 26;

fn qemu() -> Qemu {
    Qemu::start().unwrap_or_else(|e| panic!("the QEMU oracle could not start: {e}"))
}

/// A block with `code`, a quiet starting state changed by `setup`, and a zeroed window.
fn block(code: &[u8], setup: impl FnOnce(&mut ArchState)) -> Block {
    let mut start = ArchState {
        xpsr: T,
        ..ArchState::default()
    };
    start.r[13] = DATA_BASE + DATA_LEN / 2;
    start.r[15] = CODE_BASE;
    setup(&mut start);
    Block::new(code.to_vec(), start, vec![0; DATA_LEN as usize])
}

fn finish(qemu: &mut Qemu, block: &Block) -> (ArchState, Vec<u8>) {
    match qemu.run(block) {
        Ok(Outcome::Finished { state, data }) => {
            assert_eq!(state.r[15], block.end(), "PC at the end");
            (state, data)
        }
        other => panic!("the block did not finish: {other:x?}"),
    }
}

fn flags(state: &ArchState) -> u32 {
    state.xpsr & (N | Z | C | V | Q)
}

#[test]
fn adds_sets_carry_and_overflow() {
    let mut q = qemu();
    // adds r0, r1, r2: 0x7fffffff + 1 overflows into the sign bit.
    let b = block(&[0x88, 0x18], |s| {
        s.r[1] = 0x7fff_ffff;
        s.r[2] = 1;
        s.xpsr |= Z | C;
    });
    let (state, _) = finish(&mut q, &b);
    assert_eq!(state.r[0], 0x8000_0000);
    assert_eq!(flags(&state), N | V);
    assert_eq!(state.xpsr & T, T);
    // adds r3, r4, r5: 0xffffffff + 1 carries out and gives zero.
    let b = block(&[0x63, 0x19], |s| {
        s.r[4] = 0xffff_ffff;
        s.r[5] = 1;
        s.xpsr |= N | V;
    });
    let (state, _) = finish(&mut q, &b);
    assert_eq!(state.r[3], 0);
    assert_eq!(flags(&state), Z | C);
}

#[test]
fn ssat_saturates_and_sets_q() {
    let mut q = qemu();
    // ssat r0, #8, r1 ; ssat r2, #8, r3, asr #2
    let code = [0x01, 0xf3, 0x07, 0x00, 0x23, 0xf3, 0x87, 0x02];
    let b = block(&code, |s| {
        s.r[1] = 300;
        s.r[3] = (-600i32) as u32;
    });
    let (state, _) = finish(&mut q, &b);
    assert_eq!(state.r[0], 127);
    assert_eq!(state.r[2], (-128i32) as u32);
    assert_eq!(flags(&state), Q);
    // In range: the result is the value and Q stays as it was (clear).
    let b = block(&code, |s| {
        s.r[1] = (-128i32) as u32;
        s.r[3] = 508; // 508 >> 2 = 127
    });
    let (state, _) = finish(&mut q, &b);
    assert_eq!(state.r[0], (-128i32) as u32);
    assert_eq!(state.r[2], 127);
    assert_eq!(flags(&state), 0);
}

#[test]
fn uqadd8_saturates_uadd8_sets_ge_and_sel_reads_it() {
    let mut q = qemu();
    // uqadd8 r0, r1, r2 ; uadd8 r3, r1, r2 ; sel r4, r5, r6
    let code = [
        0x81, 0xfa, 0x52, 0xf0, 0x81, 0xfa, 0x42, 0xf3, 0xa5, 0xfa, 0x86, 0xf4,
    ];
    let b = block(&code, |s| {
        s.r[1] = 0xff80_0110;
        s.r[2] = 0x0180_ff01;
        s.r[5] = 0xaabb_ccdd;
        s.r[6] = 0x1122_3344;
        s.xpsr |= 0b0001 << GE_SHIFT;
    });
    let (state, _) = finish(&mut q, &b);
    assert_eq!(state.r[0], 0xffff_ff11);
    // Lanes 3, 2 and 1 carry out (GE set), lane 0 does not.
    assert_eq!(state.r[3], 0x0000_0011);
    assert_eq!(state.xpsr >> GE_SHIFT & 15, 0b1110);
    assert_eq!(state.r[4], 0xaabb_cc44);
}

#[test]
fn adds_t1_in_an_it_block_leaves_the_flags_alone() {
    let mut q = qemu();
    // cmp r0, r0 ; ite eq ; addeq r1, r2, r3 (ADDS T1 outside IT) ; subne r4, r4, #1
    let code = [0x80, 0x42, 0x0c, 0xbf, 0xd1, 0x18, 0x64, 0x1e];
    let b = block(&code, |s| {
        s.r[2] = 0x7fff_ffff;
        s.r[3] = 1;
        s.r[4] = 10;
        s.xpsr |= N | V;
    });
    let (state, _) = finish(&mut q, &b);
    assert_eq!(state.r[1], 0x8000_0000, "the then-slot executed");
    assert_eq!(state.r[4], 10, "the else-slot did not");
    assert_eq!(flags(&state), Z | C, "the flags are CMP's, not the ADD's");
    assert_eq!(state.xpsr & 0x0600_fc00, 0, "no IT state left");
}

#[test]
fn vadd_rounds_as_fpscr_says() {
    let mut q = qemu();
    // vadd.f32 s0, s1, s2: 1.0 + 2^-24 is a tie between 1.0 and 1.0 + 2^-23.
    let code = [0x30, 0xee, 0x81, 0x0a];
    let run = |q: &mut Qemu, fpscr: u32, a: u32, b: u32| {
        let (state, _) = finish(
            q,
            &block(&code, |s| {
                s.fpscr = fpscr;
                s.s[1] = a;
                s.s[2] = b;
            }),
        );
        (state.s[0], state.fpscr)
    };
    // Round to nearest, ties to even.
    assert_eq!(run(&mut q, 0, 0x3f80_0000, 0x3380_0000), (0x3f80_0000, IXC));
    // Round towards plus infinity.
    assert_eq!(
        run(&mut q, RP, 0x3f80_0000, 0x3380_0000),
        (0x3f80_0001, RP | IXC)
    );
    // Round towards minus infinity, negative operands.
    assert_eq!(
        run(&mut q, RM, 0xbf80_0000, 0xb380_0000),
        (0xbf80_0001, RM | IXC)
    );
    // Exact: no flag.
    assert_eq!(run(&mut q, 0, 0x3f80_0000, 0x3f80_0000), (0x4000_0000, 0));
}

#[test]
fn vcvt_to_integer_saturates_and_nan_gives_zero() {
    let mut q = qemu();
    // vcvt.s32.f32 s0, s1 ; vcvt.u32.f32 s2, s3 ; vcvtr.s32.f32 s4, s5
    let code = [
        0xbd, 0xee, 0xe0, 0x0a, 0xbc, 0xee, 0xe1, 0x1a, 0xbd, 0xee, 0x62, 0x2a,
    ];
    let b = block(&code, |s| {
        s.s[1] = 0x7fc0_0000; // NaN
        s.s[3] = (-1.5f32).to_bits(); // -1 after rounding towards zero: below 0
        s.s[5] = 2.5f32.to_bits(); // ties to even: 2
    });
    let (state, _) = finish(&mut q, &b);
    assert_eq!(state.s[0], 0);
    assert_eq!(state.s[2], 0);
    assert_eq!(state.s[4], 2);
    assert_eq!(state.fpscr, IOC | IXC);
    // VCVTR follows FPSCR.RMode (towards plus infinity: 3); VCVT rounds towards zero.
    let b = block(&code, |s| {
        s.fpscr = RP;
        s.s[1] = (-2.75f32).to_bits();
        s.s[3] = 4.0e9f32.to_bits();
        s.s[5] = 2.5f32.to_bits();
    });
    let (state, _) = finish(&mut q, &b);
    assert_eq!(state.s[0], (-2i32) as u32);
    assert_eq!(state.s[2], 4_000_000_000);
    assert_eq!(state.s[4], 3);
    assert_eq!(state.fpscr, RP | IXC);
}

#[test]
fn nans_denormals_and_half_precision_follow_fpscr() {
    let mut q = qemu();
    // vadd.f32 s0, s1, s2
    let vadd = [0x30, 0xee, 0x81, 0x0a];
    // vmul.f32 s0, s1, s2
    let vmul = [0x20, 0xee, 0x81, 0x0a];
    // vcvtb.f16.f32 s0, s1
    let to_half = [0xb3, 0xee, 0x60, 0x0a];
    let run = |q: &mut Qemu, code: &[u8], fpscr: u32, a: u32, b: u32| {
        let (state, _) = finish(
            q,
            &block(code, |s| {
                s.fpscr = fpscr;
                s.s[1] = a;
                s.s[2] = b;
            }),
        );
        (state.s[0], state.fpscr & !(RP | RM))
    };
    // A quiet NaN's payload propagates, unless DN asks for the default NaN.
    assert_eq!(
        run(&mut q, &vadd, 0, 0x7fc1_2345, 0x3f80_0000),
        (0x7fc1_2345, 0)
    );
    assert_eq!(
        run(&mut q, &vadd, DN, 0x7fc1_2345, 0x3f80_0000),
        (0x7fc0_0000, DN)
    );
    // A signalling NaN is quieted and raises Invalid Operation, and beats a quiet NaN.
    assert_eq!(
        run(&mut q, &vadd, 0, 0x7fc1_1111, 0xff82_2222),
        (0xffc2_2222, IOC)
    );
    // FZ flushes a denormal input (IDC) and a tiny result (UFC, not IXC).
    assert_eq!(run(&mut q, &vadd, 0, 1, 0), (1, 0));
    assert_eq!(run(&mut q, &vadd, FZ, 1, 0), (0, FZ | IDC));
    assert_eq!(
        run(&mut q, &vmul, 0, 0x0080_0000, 0x3f00_0000),
        (0x0040_0000, 0)
    );
    assert_eq!(
        run(&mut q, &vmul, FZ, 0x0080_0000, 0x3f00_0000),
        (0, FZ | UFC)
    );
    // To half precision: 65520 overflows to infinity in IEEE format; with AHP it is 65536
    // (exponent 31 is a number there) and infinity becomes the largest value with IOC.
    assert_eq!(run(&mut q, &to_half, 0, 0x477f_f000, 0), (0x7c00, 0x14));
    assert_eq!(
        run(&mut q, &to_half, AHP, 0x477f_f000, 0),
        (0x7c00, AHP | IXC)
    );
    assert_eq!(
        run(&mut q, &to_half, AHP, 0x7f80_0000, 0),
        (0x7fff, AHP | IOC)
    );
    // FZ does not flush half-precision results: 2^-25 + ulp rounds to the smallest
    // half-precision denormal.
    assert_eq!(
        run(&mut q, &to_half, FZ, 0x3300_0001, 0),
        (0x0001, FZ | UFC | IXC)
    );
}

#[test]
fn division_by_zero_gives_zero() {
    let mut q = qemu();
    // sdiv r0, r1, r2 ; udiv r3, r4, r5
    let code = [0x91, 0xfb, 0xf2, 0xf0, 0xb4, 0xfb, 0xf5, 0xf3];
    let b = block(&code, |s| {
        s.r[0] = 0x1234;
        s.r[1] = 77;
        s.r[4] = 7;
        s.r[5] = 2;
    });
    let (state, _) = finish(&mut q, &b);
    assert_eq!(state.r[0], 0);
    assert_eq!(state.r[3], 3);
    // INT_MIN / -1 overflows to INT_MIN without a trap.
    let b = block(&code, |s| {
        s.r[1] = 0x8000_0000;
        s.r[2] = 0xffff_ffff;
        s.r[5] = 1;
    });
    let (state, _) = finish(&mut q, &b);
    assert_eq!(state.r[0], 0x8000_0000);
}

#[test]
fn loads_stores_and_exclusives_use_the_window() {
    let mut q = qemu();
    // ldm r1, {r0, r1, r2}: the base is in the list, so no writeback.
    let mut b = block(&[0x07, 0xc9], |s| s.r[1] = DATA_BASE + 16);
    b.data[16..28].copy_from_slice(&[0x11, 0, 0, 0, 0x22, 0, 0, 0, 0x33, 0, 0, 0]);
    let (state, _) = finish(&mut q, &b);
    assert_eq!(&state.r[..3], &[0x11, 0x22, 0x33]);
    // ldrex r0, [r1] ; strex r2, r3, [r1] ; clrex ; strex r4, r5, [r1]
    let code = [
        0x51, 0xe8, 0x00, 0x0f, 0x41, 0xe8, 0x00, 0x32, 0xbf, 0xf3, 0x2f, 0x8f, 0x41, 0xe8, 0x00,
        0x54,
    ];
    let mut b = block(&code, |s| {
        s.r[1] = DATA_BASE + 8;
        s.r[3] = 0xcafe_f00d;
        s.r[5] = 0xdead_beef;
    });
    b.data[8..12].copy_from_slice(&0x0102_0304u32.to_le_bytes());
    let (state, data) = finish(&mut q, &b);
    assert_eq!(state.r[0], 0x0102_0304);
    assert_eq!(state.r[2], 0, "STREX after LDREX succeeds");
    assert_eq!(state.r[4], 1, "STREX after CLREX fails");
    assert_eq!(&data[8..12], &0xcafe_f00du32.to_le_bytes());
}

#[test]
fn a_fault_is_reported_and_the_next_block_runs() {
    let mut q = qemu();
    // nop ; udf #0
    let b = block(&[0x00, 0xbf, 0x00, 0xde], |_| {});
    match q.run(&b).expect("the run") {
        Outcome::Fault {
            pc,
            exception,
            cfsr,
            ..
        } => {
            assert_eq!(pc, CODE_BASE + 2);
            assert_eq!(exception, 6, "UsageFault");
            assert_eq!(cfsr, 1 << 16, "UNDEFINSTR");
        }
        other => panic!("UDF did not fault: {other:x?}"),
    }
    // ldr r0, [r1] from unmapped memory: a precise BusFault.
    let b = block(&[0x08, 0x68], |s| s.r[1] = 0x3000_0000);
    match q.run(&b).expect("the run") {
        Outcome::Fault {
            pc,
            exception,
            cfsr,
            bfar,
            ..
        } => {
            assert_eq!((pc, exception, bfar), (CODE_BASE, 5, 0x3000_0000));
            assert_eq!(cfsr, 0x8200, "PRECISERR and BFARVALID");
        }
        other => panic!("the load did not fault: {other:x?}"),
    }
    // adds r0, r1, r2
    let b = block(&[0x88, 0x18], |s| {
        s.r[1] = 2;
        s.r[2] = 3;
    });
    let (state, _) = finish(&mut q, &b);
    assert_eq!(state.r[0], 5);
    assert_eq!(state.xpsr & 0x1ff, 0, "back in Thread mode");
}

#[test]
fn the_generator_is_deterministic() {
    let first: Vec<Block> = {
        let mut g = BlockGen::new(1);
        (0..100).map(|_| g.next()).collect()
    };
    let mut again = BlockGen::new(1);
    for (i, block) in first.iter().enumerate() {
        assert_eq!(&again.next(), block, "block {i} of seed 1");
    }
    assert_eq!(BlockGen::block(1, 42), first[42]);
    assert_ne!(BlockGen::new(2).next(), first[0]);
}

#[test]
fn generated_blocks_run_without_faults() {
    let mut q = qemu();
    let mut g = BlockGen::new(1);
    let blocks: Vec<Block> = (0..300).map(|_| g.next()).collect();
    let started = Instant::now();
    for (i, block) in blocks.iter().enumerate() {
        match q.run(block) {
            Ok(Outcome::Finished { state, data }) => {
                assert_eq!(state.r[15], block.end());
                assert_eq!(data.len(), DATA_LEN as usize);
                assert!(
                    state.r[13] % 4 == 0
                        && (DATA_BASE..=DATA_BASE + DATA_LEN).contains(&state.r[13]),
                    "block {i}: SP left the window: {:#x}",
                    state.r[13]
                );
            }
            Ok(fault) => panic!(
                "block {i} of seed 1 faulted: {fault:x?}\n{}",
                block.disassembly()
            ),
            Err(e) => panic!("block {i} of seed 1: {e}\n{}", block.disassembly()),
        }
    }
    let elapsed = started.elapsed();
    println!(
        "{} blocks in {elapsed:.2?}: {:.0} blocks per second",
        blocks.len(),
        blocks.len() as f64 / elapsed.as_secs_f64()
    );
}

#[test]
fn the_fast_run_agrees_with_the_debugger() {
    let mut q = qemu();
    let mut g = BlockGen::new(5);
    for i in 0..60 {
        let block = g.next();
        let fast = q.run(&block).unwrap_or_else(|e| panic!("block {i}: {e}"));
        let slow = q
            .run_via_gdb(&block)
            .unwrap_or_else(|e| panic!("block {i}: {e}"));
        assert_eq!(fast, slow, "block {i} of seed 5\n{}", block.disassembly());
    }
}

#[test]
fn a_missing_qemu_says_how_to_install_it() {
    let e = Qemu::start_binary("/nonexistent/qemu-system-arm").expect_err("no such binary");
    assert!(matches!(e, OracleError::QemuMissing { .. }));
    let message = e.to_string();
    assert!(message.contains("scripts/setup-tests"), "{message}");
    assert!(message.contains("AUTOPLUG_QEMU"), "{message}");
    // And the configured one is there (the other tests need it).
    assert!(
        Qemu::start().is_ok(),
        "`{}` does not start: install qemu-system-arm (scripts/setup-tests)",
        qemu_binary()
    );
}

/// The emulated core against QEMU on generated blocks: the CI sample. A longer run:
/// `cargo run --release -p autoplug-mcu-oracle --example differential -- --blocks 100000`.
#[test]
fn the_emulated_core_agrees_with_qemu_on_generated_blocks() {
    use autoplug_mcu_oracle::differential::{compare, emulate};
    let mut qemu = qemu();
    let mut blocks = BlockGen::new(20_111);
    let count = 2_000;
    let mut disagreements = Vec::new();
    for i in 0..count {
        let block = blocks.next();
        let theirs = qemu
            .run(&block)
            .unwrap_or_else(|e| panic!("QEMU on block {i}: {e}"));
        if let Err(report) = compare(&block, &emulate(&block), &theirs) {
            disagreements.push(format!("block {i} of seed 20111:\n{report}"));
        }
    }
    if std::env::var("DIFF_ALL").is_ok() {
        for d in &disagreements {
            eprintln!("{}", d.lines().take(3).collect::<Vec<_>>().join(" | "));
        }
    }
    assert!(
        disagreements.is_empty(),
        "{} of {count} blocks disagree; the first:\n{}",
        disagreements.len(),
        disagreements[0]
    );
}
