//! The runtime the generated codec calls: bit packing, length checks and the errors a
//! receiver reports.

use autoplug_scaling::LinearScale;
use core::fmt;

/// Why a received frame (or one of its signals) was not accepted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DecodeError {
    /// No message of the catalogue has this identifier.
    UnknownId {
        /// The identifier received.
        id: u16,
    },
    /// The frame's data length is not the message's.
    WrongLength {
        /// Message name.
        message: &'static str,
        /// Its length in the catalogue.
        expected: usize,
        /// The length received.
        actual: usize,
    },
    /// A scaled signal's raw value is outside its valid range.
    OutOfRange {
        /// Message name.
        message: &'static str,
        /// Signal name.
        signal: &'static str,
        /// The raw value received.
        raw: i64,
        /// Smallest valid raw value.
        min: i64,
        /// Largest valid raw value.
        max: i64,
    },
    /// An enumerated signal's raw value is not in its value table.
    UndefinedValue {
        /// Message name.
        message: &'static str,
        /// Signal name.
        signal: &'static str,
        /// The raw value received.
        raw: i64,
    },
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            DecodeError::UnknownId { id } => {
                write!(f, "identifier 0x{id:03X} is not in the CAN catalogue")
            }
            DecodeError::WrongLength {
                message,
                expected,
                actual,
            } => write!(
                f,
                "{message}: frame has {actual} data bytes, the catalogue says {expected}"
            ),
            DecodeError::OutOfRange {
                message,
                signal,
                raw,
                min,
                max,
            } => write!(
                f,
                "{message}.{signal}: raw value {raw} is outside the valid range {min}..={max}"
            ),
            DecodeError::UndefinedValue {
                message,
                signal,
                raw,
            } => write!(
                f,
                "{message}.{signal}: raw value {raw} is not defined in its value table"
            ),
        }
    }
}

/// Why [`crate::Message::set_signal`] refused a value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SignalError {
    /// The message has no signal with this index.
    NoSuchSignal {
        /// The index asked for.
        index: usize,
    },
    /// The value is not in the signal's value table.
    UndefinedValue {
        /// The raw value asked for.
        raw: i64,
    },
}

impl fmt::Display for SignalError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            SignalError::NoSuchSignal { index } => write!(f, "no signal with index {index}"),
            SignalError::UndefinedValue { raw } => {
                write!(f, "raw value {raw} is not defined in the value table")
            }
        }
    }
}

const fn mask(len: u32) -> u64 {
    if len >= 64 {
        u64::MAX
    } else {
        (1u64 << len) - 1
    }
}

/// The frame's data as one little-endian word, after checking its length.
pub fn load(data: &[u8], dlc: usize, message: &'static str) -> Result<u64, DecodeError> {
    if data.len() != dlc || dlc > 8 {
        return Err(DecodeError::WrongLength {
            message,
            expected: dlc,
            actual: data.len(),
        });
    }
    let mut bytes = [0u8; 8];
    bytes[..dlc].copy_from_slice(data);
    Ok(u64::from_le_bytes(bytes))
}

/// The first `N` bytes of a little-endian word.
pub fn store<const N: usize>(bits: u64) -> [u8; N] {
    let bytes = bits.to_le_bytes();
    let mut out = [0u8; N];
    out.copy_from_slice(&bytes[..N]);
    out
}

/// The raw value of an Intel (little-endian) signal, sign-extended if it is signed.
pub const fn extract(bits: u64, start: u32, len: u32, signed: bool) -> i64 {
    let value = (bits >> start) & mask(len);
    if signed && len < 64 && (value >> (len - 1)) & 1 == 1 {
        (value | !mask(len)) as i64
    } else {
        value as i64
    }
}

/// An Intel signal's raw value placed at its bits (two's complement, truncated to `len`).
pub const fn insert(raw: i64, start: u32, len: u32) -> u64 {
    ((raw as u64) & mask(len)) << start
}

/// The physical value of a scaled signal, or why its raw value is invalid.
pub fn scaled(
    scale: &LinearScale,
    raw: i64,
    message: &'static str,
    signal: &'static str,
) -> Result<f32, DecodeError> {
    let in_range = raw >= i64::from(scale.raw_min()) && raw <= i64::from(scale.raw_max());
    if in_range {
        Ok(scale.to_physical_unchecked(raw as i32))
    } else {
        Err(DecodeError::OutOfRange {
            message,
            signal,
            raw,
            min: i64::from(scale.raw_min()),
            max: i64::from(scale.raw_max()),
        })
    }
}
