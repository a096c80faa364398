//! What a flash job tells: its phases, their timing, its report and its failures, and
//! its progress as it goes.

use std::fmt;

use autoplug_can::Node;
use autoplug_image::ImageSlot;

use crate::{label, UdsError};

/// The phases of a flash job, in order; each is timed in the [`FlashReport`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Phase {
    /// Extended session for all, programming session for the target, DTC setting and
    /// communication off.
    SessionSetup,
    /// Seed and key.
    Security,
    /// The erase routine.
    Erase,
    /// RequestDownload, TransferData, RequestTransferExit.
    Transfer,
    /// The check routine (signature, ECU, version).
    Check,
    /// Communication on, ECUReset and the wait until the ECU answers again.
    ResetAndWait,
    /// DTC setting on (and communication, after a failure), default session for all.
    Restore,
}

impl Phase {
    /// Every phase, in order.
    pub const ALL: [Phase; 7] = [
        Phase::SessionSetup,
        Phase::Security,
        Phase::Erase,
        Phase::Transfer,
        Phase::Check,
        Phase::ResetAndWait,
        Phase::Restore,
    ];

    /// How reports name the phase.
    pub const fn name(self) -> &'static str {
        match self {
            Phase::SessionSetup => "session setup",
            Phase::Security => "security",
            Phase::Erase => "erase",
            Phase::Transfer => "transfer",
            Phase::Check => "check",
            Phase::ResetAndWait => "reset and wait",
            Phase::Restore => "restore",
        }
    }
}

impl fmt::Display for Phase {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// How long one phase took.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PhaseTiming {
    /// The phase.
    pub phase: Phase,
    /// From its first request to the response of its last, µs.
    pub duration_us: u64,
    /// 0x78 "response pending" received during the phase.
    pub response_pending: u32,
}

/// What a flash job did and how long it took (also what a failed job did so far).
#[derive(Debug, Clone, PartialEq)]
pub struct FlashReport {
    /// The ECU flashed.
    pub ecu: Node,
    /// The slot the image went to (`None` before the ECU said which it runs).
    pub slot: Option<ImageSlot>,
    /// Bytes of the image.
    pub image_len: u64,
    /// Data bytes per TransferData block (the ECU's maxNumberOfBlockLength less 2); 0
    /// before RequestDownload was answered.
    pub block_len: usize,
    /// TransferData blocks acknowledged.
    pub blocks: u32,
    /// The phases that ran, in order.
    pub phases: Vec<PhaseTiming>,
    /// Whatever deserves a mention without failing the job (negative answers to the
    /// functional requests, a repeated block...).
    pub notes: Vec<String>,
    /// From the job's first poll to its end, µs.
    pub total_us: u64,
}

impl FlashReport {
    /// How long `phase` took, if it ran.
    pub fn duration_us(&self, phase: Phase) -> Option<u64> {
        self.phases
            .iter()
            .find(|p| p.phase == phase)
            .map(|p| p.duration_us)
    }

    /// Image bytes per second over the transfer phase (RequestDownload to the end of
    /// RequestTransferExit); `None` unless the whole image was transferred.
    pub fn transfer_throughput(&self) -> Option<f64> {
        let duration = self.duration_us(Phase::Transfer)?;
        let transferred = self.blocks > 0 && self.duration_us(Phase::Check).is_some();
        (transferred && duration > 0).then(|| self.image_len as f64 * 1e6 / duration as f64)
    }
}

impl fmt::Display for FlashReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}: {} bytes, {} blocks of up to {} bytes",
            label(self.ecu),
            self.image_len,
            self.blocks,
            self.block_len
        )?;
        match self.slot {
            Some(slot) => writeln!(f, ", into slot {}", slot.letter())?,
            None => writeln!(f)?,
        }
        writeln!(f, "{:<16} {:>11}", "phase", "time")?;
        for timing in &self.phases {
            write!(
                f,
                "{:<16} {:>8.1} ms",
                timing.phase.name(),
                timing.duration_us as f64 / 1000.0
            )?;
            if timing.phase == Phase::Transfer {
                if let Some(rate) = self.transfer_throughput() {
                    write!(f, "   {:.0} bytes/s ({:.1} KiB/s)", rate, rate / 1024.0)?;
                }
            }
            if timing.response_pending > 0 {
                write!(f, "   {} x response pending", timing.response_pending)?;
            }
            writeln!(f)?;
        }
        write!(
            f,
            "{:<16} {:>8.1} ms",
            "total",
            self.total_us as f64 / 1000.0
        )?;
        for note in &self.notes {
            write!(f, "\nnote: {note}")?;
        }
        Ok(())
    }
}

/// What made a flash job fail.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FlashFailure {
    /// A request failed (negative response, timeout, ISO-TP error, odd response).
    Uds(UdsError),
    /// The ECU did not answer TesterPresent within the reset timeout after ECUReset.
    NoReturnAfterReset {
        /// How long the tester waited, µs.
        waited_us: u64,
    },
    /// The job cannot run as configured (no image, an image too large for a download).
    Invalid(String),
    /// The ECU kept refusing the programming session with conditionsNotCorrect: it has not
    /// seen the car stand.
    NotStanding {
        /// How long the tester kept asking, µs.
        waited_us: u64,
    },
}

impl fmt::Display for FlashFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            FlashFailure::Uds(error) => error.fmt(f),
            FlashFailure::NoReturnAfterReset { waited_us } => write!(
                f,
                "the ECU did not answer TesterPresent within {:.1} s after its reset",
                *waited_us as f64 / 1e6
            ),
            FlashFailure::Invalid(reason) => f.write_str(reason),
            FlashFailure::NotStanding { waited_us } => write!(
                f,
                "the ECU refused the programming session for {:.1} s (NRC 0x22 conditionsNotCorrect): it reprograms only a car it has seen stand, VehicleSpeedMsg under 1 km/h for {} ms; stop the car and flash again",
                *waited_us as f64 / 1e6,
                autoplug_uds::STANDSTILL_WINDOW_US / 1000
            ),
        }
    }
}

/// A failed flash job: where and why, and the report of what it did.
#[derive(Debug, Clone, PartialEq)]
pub struct FlashError {
    /// The ECU being flashed.
    pub ecu: Node,
    /// The phase that failed.
    pub phase: Phase,
    /// The request that failed, e.g. `"0x31 01 FF00 (erase)"`.
    pub step: &'static str,
    /// Why.
    pub failure: FlashFailure,
    /// What was done, restore included.
    pub report: FlashReport,
}

impl FlashError {
    /// The UDS error, when a request failed.
    pub fn uds(&self) -> Option<&UdsError> {
        match &self.failure {
            FlashFailure::Uds(error) => Some(error),
            _ => None,
        }
    }
}

impl fmt::Display for FlashError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "flashing {} failed in phase '{}' at {}: {}",
            label(self.ecu),
            self.phase,
            self.step,
            self.failure
        )
    }
}

impl std::error::Error for FlashError {}

/// Where a flash job is: progress callbacks get one at each change of phase and each
/// time more of the image is on the bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Progress {
    /// The phase under way.
    pub phase: Phase,
    /// Image bytes on the bus (acknowledged blocks plus the frames of the block going out).
    pub transferred: u64,
    /// Bytes of the image.
    pub total: u64,
}
