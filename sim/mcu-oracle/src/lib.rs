//! An independent Cortex-M4F for differential testing of AutoPlug's emulated core
//! (`autoplug-mcu`): QEMU's
//! `mps2-an386` machine (a Cortex-M4 with the FPv4-SP unit) run as a separate process and
//! driven through its GDB stub.
//!
//! - [`gdb`]: a small client for the GDB Remote Serial Protocol over TCP;
//! - [`qemu`]: starts `qemu-system-arm`, prepares the machine once (vector table, fault
//!   stub, FPU enabled) and runs one [`blocks::Block`] at a time, reporting the final
//!   registers and data window or the fault;
//! - [`blocks`]: a seeded generator of random, architecturally defined Thumb-2 blocks
//!   (integer, DSP, load/store, IT blocks, short branches, single-precision floating point);
//! - [`thumb`]: the instruction encoders the generator and the harness share.
//!
//! The oracle needs `qemu-system-arm` (Debian's `qemu-system-arm` package, which
//! `scripts/setup-tests` installs); `AUTOPLUG_QEMU` names another binary.

pub mod blocks;
pub mod differential;
pub mod gdb;
pub mod qemu;
pub mod thumb;

use std::fmt;
use std::time::Duration;

pub use blocks::{Block, BlockGen, CODE_BASE, DATA_BASE, DATA_LEN};
pub use qemu::{Outcome, Qemu};

/// What went wrong while driving QEMU: every variant says what was being done or awaited.
#[derive(Debug)]
pub enum OracleError {
    /// The QEMU binary could not be found.
    QemuMissing {
        /// The binary that was looked for.
        binary: String,
    },
    /// QEMU could not be started, or stopped unexpectedly.
    Qemu {
        /// What was being done.
        what: String,
        /// The cause, with QEMU's own error output where there is some.
        detail: String,
    },
    /// A socket operation failed.
    Io {
        /// What was being done.
        what: String,
        /// The error.
        source: std::io::Error,
    },
    /// Nothing (or not enough) arrived in time.
    Timeout {
        /// What was awaited.
        what: String,
        /// How long it was awaited.
        after: Duration,
    },
    /// The stub said something this client does not understand, or refused a request.
    Protocol {
        /// What was being done.
        what: String,
        /// What arrived.
        detail: String,
    },
    /// The machine did not end up as it was set up to be (the setup's own checks).
    Setup(String),
}

impl fmt::Display for OracleError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            OracleError::QemuMissing { binary } => write!(
                f,
                "the QEMU binary `{binary}` was not found: install Debian's qemu-system-arm \
                 package (scripts/setup-tests does), or name another binary in AUTOPLUG_QEMU"
            ),
            OracleError::Qemu { what, detail } => write!(f, "QEMU: {what}: {detail}"),
            OracleError::Io { what, source } => write!(f, "{what}: {source}"),
            OracleError::Timeout { what, after } => {
                write!(f, "timed out after {after:?} awaiting {what}")
            }
            OracleError::Protocol { what, detail } => {
                write!(f, "GDB remote protocol, {what}: {detail}")
            }
            OracleError::Setup(what) => write!(f, "QEMU oracle setup: {what}"),
        }
    }
}

impl std::error::Error for OracleError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            OracleError::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}
