//! Runtime support shared by the on-target suites in `tests/`: the defmt transport, the
//! panic and fault handling that makes a failing run end with a non-zero exit, and the
//! link-time pieces (cortex-m-rt, `memory.x` from `build.rs`).
//!
//! Each suite is a defmt-test binary that calls the `test_cases` functions of a shared
//! crate, so the Cortex-M4F checks exactly what the host checks. Suites link this crate with
//! `use autoplug_target_tests as _;`.
//!
//! Transports (exactly one, target builds only):
//! - `qemu`: defmt frames over semihosting. A passing run ends in defmt-test's semihosting
//!   `exit(0)`; a panic or HardFault is logged and ends in semihosting `exit(1)`, so QEMU
//!   exits with status 1 instead of spinning until the runner's timeout.
//! - `probe`: defmt frames over RTT for `probe-rs run`. A passing run ends in the same
//!   semihosting `exit(0)`, which probe-rs understands; a panic is logged by panic-probe and
//!   ends in a HardFault, which probe-rs reports as a failure with a backtrace.
//!
//! On the host this crate is empty: the suites are gated on the `on-target` feature and,
//! if built for the host anyway (`--all-features`), only print that they were skipped.
#![no_std]

#[cfg(all(target_os = "none", not(any(feature = "qemu", feature = "probe"))))]
compile_error!("on-target suites need a transport: `--features qemu` or `--features probe`");

#[cfg(all(target_os = "none", feature = "qemu", feature = "probe"))]
compile_error!("features `qemu` and `probe` are mutually exclusive (two defmt loggers)");

#[cfg(target_os = "none")]
use cortex_m_rt as _;

#[cfg(all(target_os = "none", feature = "probe"))]
mod probe {
    use {defmt_rtt as _, panic_probe as _};

    /// `defmt::panic!` has already logged its message: go straight to panic-probe's
    /// HardFault (which probe-rs reports) instead of a second, empty `core::panic!`.
    #[defmt::panic_handler]
    fn defmt_panic() -> ! {
        panic_probe::hard_fault()
    }
}

#[cfg(all(target_os = "none", feature = "qemu"))]
mod qemu {
    use core::panic::PanicInfo;
    use cortex_m_rt::{exception, ExceptionFrame};
    use defmt_semihosting as _;

    /// Ends the run as failed: QEMU exits with status 1.
    fn fail() -> ! {
        semihosting::process::exit(1)
    }

    /// `core::panic!`, `assert!` and friends: log the message, then fail.
    #[panic_handler]
    fn panic(info: &PanicInfo) -> ! {
        cortex_m::interrupt::disable();
        defmt::error!("{}", defmt::Display2Format(info));
        fail()
    }

    /// `defmt::panic!` (also used by defmt-test for a failed `Result` outcome) has already
    /// logged its message; fail without a second, empty `core::panic!`.
    #[defmt::panic_handler]
    fn defmt_panic() -> ! {
        fail()
    }

    /// Without this, cortex-m-rt's default HardFault handler spins and the run only ends at
    /// the runner's timeout.
    #[exception]
    unsafe fn HardFault(frame: &ExceptionFrame) -> ! {
        defmt::error!("HardFault at pc={:#010x}", frame.pc());
        fail()
    }
}
