//! Diagnostic trouble codes as UDS reports them (ISO 14229-1 service 0x19): a 3-byte DTC
//! (the 2-byte SAE J2012 code plus a failure-type byte) and a status byte, kept in a
//! fixed-size store that needs no allocation.

use crate::Instant;
use autoplug_can::Node;
use core::fmt;

/// The system letter of a J2012 code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DtcSystem {
    /// Powertrain.
    P = 0,
    /// Chassis.
    C = 1,
    /// Body.
    B = 2,
    /// Network (communication).
    U = 3,
}

/// A DTC: `U0100-87` is "lost communication with the engine ECU, missing message".
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Dtc(u32);

/// Failure-type byte: the message stopped arriving (J2012 "missing message").
pub const FTB_MISSING_MESSAGE: u8 = 0x87;
/// Failure-type byte: a received signal was invalid (J2012 "signal invalid").
pub const FTB_SIGNAL_INVALID: u8 = 0x86;
/// Failure-type byte: a reading contradicts the others (J2012 "signal plausibility
/// failure").
pub const FTB_SIGNAL_PLAUSIBILITY: u8 = 0x64;

impl Dtc {
    /// A DTC from its system letter, its four digits as written (`0x0100` for `U0100`, the
    /// first digit 0..=3) and its failure-type byte.
    pub const fn new(system: DtcSystem, digits: u16, failure_type: u8) -> Self {
        let code = ((system as u32) << 14) | (digits as u32 & 0x3FFF);
        Self((code << 8) | failure_type as u32)
    }

    /// A DTC from its code's 16 bits (the system letter's two, then the digits': `0xC100`
    /// for `U0100`) and its failure-type byte. The network codes per node are the DBC's
    /// (`LostCommunicationDtc`, `InvalidDataDtc`: [`Node::network_dtc_codes`]).
    pub const fn from_code(code: u16, failure_type: u8) -> Self {
        Self(((code as u32) << 8) | failure_type as u32)
    }

    /// The 3 bytes UDS sends (high byte first), as a number.
    pub const fn to_u24(self) -> u32 {
        self.0
    }

    /// The 3 bytes UDS sends.
    pub const fn to_bytes(self) -> [u8; 3] {
        [(self.0 >> 16) as u8, (self.0 >> 8) as u8, self.0 as u8]
    }

    /// From the 3 bytes UDS sends.
    pub const fn from_u24(value: u32) -> Self {
        Self(value & 0xFF_FFFF)
    }

    /// The failure-type byte.
    pub const fn failure_type(self) -> u8 {
        self.0 as u8
    }
}

impl fmt::Display for Dtc {
    /// `U0100-87`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let code = self.0 >> 8;
        let letter = ['P', 'C', 'B', 'U'][(code >> 14) as usize & 3];
        write!(f, "{letter}{:04X}-{:02X}", code & 0x3FFF, self.0 & 0xFF)
    }
}

/// "Lost communication with `node`": an input from it went stale.
pub const fn lost_communication(node: Node) -> Dtc {
    Dtc::from_code(node.network_dtc_codes().0, FTB_MISSING_MESSAGE)
}

/// "Invalid data received from `node`": a frame from it was refused.
pub const fn invalid_data(node: Node) -> Dtc {
    Dtc::from_code(node.network_dtc_codes().1, FTB_SIGNAL_INVALID)
}

/// DTC status bits of ISO 14229-1.
pub mod status {
    /// The most recent test failed.
    pub const TEST_FAILED: u8 = 0x01;
    /// Failed during the current operation cycle.
    pub const TEST_FAILED_THIS_OPERATION_CYCLE: u8 = 0x02;
    /// Pending.
    pub const PENDING: u8 = 0x04;
    /// Confirmed (stored).
    pub const CONFIRMED: u8 = 0x08;
    /// Not completed since the last clear.
    pub const TEST_NOT_COMPLETED_SINCE_LAST_CLEAR: u8 = 0x10;
    /// Failed since the last clear.
    pub const TEST_FAILED_SINCE_LAST_CLEAR: u8 = 0x20;
    /// Not completed during the current operation cycle.
    pub const TEST_NOT_COMPLETED_THIS_OPERATION_CYCLE: u8 = 0x40;
    /// Warning indicator requested.
    pub const WARNING_INDICATOR: u8 = 0x80;
    /// Bits this implementation maintains (the DTCStatusAvailabilityMask).
    pub const AVAILABILITY_MASK: u8 = TEST_FAILED
        | TEST_FAILED_THIS_OPERATION_CYCLE
        | PENDING
        | CONFIRMED
        | TEST_FAILED_SINCE_LAST_CLEAR;
}

/// One stored DTC.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DtcRecord {
    /// The code.
    pub dtc: Dtc,
    /// ISO 14229-1 status byte.
    pub status: u8,
    /// How many times the test went from passed to failed.
    pub occurrences: u16,
    /// When it first failed.
    pub first_failed: Instant,
    /// When it last failed.
    pub last_failed: Instant,
}

impl DtcRecord {
    /// Whether the fault is present now.
    pub fn is_active(&self) -> bool {
        self.status & status::TEST_FAILED != 0
    }
}

/// The DTCs an ECU has recorded, at most `N` different codes.
///
/// A failure confirms the DTC at once: the faults recorded here (a lost or invalid input)
/// are already debounced by the 3-period stale timeout.
#[derive(Clone, Debug)]
pub struct DtcStore<const N: usize> {
    records: [Option<DtcRecord>; N],
    recording_enabled: bool,
    dropped: u32,
}

impl<const N: usize> Default for DtcStore<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> DtcStore<N> {
    /// An empty store, recording.
    pub const fn new() -> Self {
        Self {
            records: [None; N],
            recording_enabled: true,
            dropped: 0,
        }
    }

    /// Records a failed test. Returns true when the DTC became active (it was not before).
    pub fn report_failed(&mut self, dtc: Dtc, now: Instant) -> bool {
        if !self.recording_enabled {
            return false;
        }
        let failed_bits = status::TEST_FAILED
            | status::TEST_FAILED_THIS_OPERATION_CYCLE
            | status::PENDING
            | status::CONFIRMED
            | status::TEST_FAILED_SINCE_LAST_CLEAR;
        if let Some(record) = self.find_mut(dtc) {
            let newly = !record.is_active();
            if newly {
                record.occurrences = record.occurrences.saturating_add(1);
            }
            record.status |= failed_bits;
            record.last_failed = now;
            return newly;
        }
        match self.records.iter_mut().find(|r| r.is_none()) {
            Some(slot) => {
                *slot = Some(DtcRecord {
                    dtc,
                    status: failed_bits,
                    occurrences: 1,
                    first_failed: now,
                    last_failed: now,
                });
                true
            }
            None => {
                self.dropped = self.dropped.saturating_add(1);
                false
            }
        }
    }

    /// Records a passed test: the fault is no longer present (it stays stored).
    pub fn report_passed(&mut self, dtc: Dtc) {
        if !self.recording_enabled {
            return;
        }
        if let Some(record) = self.find_mut(dtc) {
            record.status &= !status::TEST_FAILED;
        }
    }

    /// Clears every DTC (UDS 0x14 ClearDiagnosticInformation).
    pub fn clear(&mut self) {
        self.records = [None; N];
        self.dropped = 0;
    }

    /// Turns recording on or off (UDS 0x85 ControlDTCSetting).
    pub fn set_recording(&mut self, enabled: bool) {
        self.recording_enabled = enabled;
    }

    /// The stored DTCs, in the order they were first recorded.
    pub fn records(&self) -> impl Iterator<Item = &DtcRecord> {
        self.records.iter().flatten()
    }

    /// The record of a DTC, if stored.
    pub fn get(&self, dtc: Dtc) -> Option<&DtcRecord> {
        self.records().find(|r| r.dtc == dtc)
    }

    /// Whether a DTC is present now.
    pub fn is_active(&self, dtc: Dtc) -> bool {
        self.get(dtc).is_some_and(DtcRecord::is_active)
    }

    /// DTCs that could not be stored because the store was full.
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    fn find_mut(&mut self, dtc: Dtc) -> Option<&mut DtcRecord> {
        self.records.iter_mut().flatten().find(|r| r.dtc == dtc)
    }
}
