//! The signed firmware image of an AutoPlug ECU.
//!
//! An image file is
//!
//! ```text
//! header (512 bytes) ‖ payload (payload_len bytes) ‖ signature (64 bytes)
//! ```
//!
//! It is downloaded whole into the image slot the ECU is not running, and runs in place
//! there: the slot (0x0802_0000 or 0x0804_0000 on the F446RE, `autoplug_flash::ab`) begins
//! with the header, so the application's vector table — the first byte of the payload —
//! sits at slot start + 512, the header's `load_address`. An application is linked for one
//! slot, so a release carries one image per slot; a file may hold both, one after the
//! other ([`ImageSet`]), and the tester sends the one for the slot the ECU will write.
//!
//! The signature is Ed25519 over the 64-byte message `SHA-512(header ‖ payload)`, checked
//! with the `salty` crate on the ECU. The signed part covers the whole header, so the
//! target ECU, hardware id, version, load address and build id cannot be changed without
//! breaking the signature.
//!
//! # Header layout (all integers little-endian)
//!
//! | offset | size | field | rule |
//! |---:|---:|---|---|
//! | 0 | 8 | magic | `b"APLGIMG1"` |
//! | 8 | 2 | format version (u16) | 1 |
//! | 10 | 2 | header size (u16) | 512 |
//! | 12 | 1 | target node (u8) | the ECU's diagnostic node number |
//! | 13 | 1 | software variant (u8) | 0 standard, 1 faulty demonstration |
//! | 14 | 2 | flags (u16) | 0, or [`flags::HOST_LOGIC`] |
//! | 16 | 4 | hardware id (u32) | e.g. [`NUCLEO_F446RE`] |
//! | 20 | 1 | version major (u8) | |
//! | 21 | 1 | version minor (u8) | |
//! | 22 | 2 | version patch (u16) | |
//! | 24 | 4 | payload length (u32) | bytes between header and signature |
//! | 28 | 4 | load address (u32) | where the payload runs: slot start + 512 |
//! | 32 | 16 | build id | opaque bytes, shown in hex |
//! | 48 | 16 | part number | printable ASCII, NUL-padded (UDS DID F187) |
//! | 64 | 448 | reserved | all zero |
//!
//! The offsets are also the constants of [`offsets`].
//!
//! # On the ECU
//!
//! Once the image is in the slot it was downloaded to: read its first 512 bytes and
//! [`ImageHeader::parse`] them; [`ImageHeader::check`] them against the ECU's
//! [`Expectations`] (a hostile header can only make this refuse, and it bounds
//! `payload_len` by the partition before anything is read with it); feed the first
//! `512 + payload_len` bytes to a [`StreamVerifier`] and [`finish`](StreamVerifier::finish)
//! it with the 64 bytes that follow. The signature covers the header that was checked, so
//! the checks now hold for an authenticated header.
//!
//! # Features
//!
//! Without features the crate is `no_std` and allocates nothing: parsing, checks, whole
//! image and streaming verification, for the ECU. The `std` feature adds what the host
//! tool needs: `ImageBuilder`, `SigningKey` and the key files.
#![cfg_attr(not(any(feature = "std", test)), no_std)]
#![deny(missing_docs)]
#![forbid(unsafe_code)]

use core::fmt;
use core::str::FromStr;

pub mod floor;
mod set;
pub use set::{ImageSet, SetError, SetImage, MAX_SET_IMAGES};
#[cfg(feature = "std")]
pub mod elf;
#[cfg(feature = "std")]
mod host;
#[cfg(feature = "std")]
pub use host::{
    parse_public_key, public_key_to_file_string, ImageBuilder, KeyFileError, KeyGenError, KeyKind,
    SigningKey, PUBLIC_KEY_TAG, SECRET_KEY_TAG,
};

// The tests build images, which takes the host half.
#[cfg(all(test, feature = "std"))]
mod tests;

/// The header's flags.
pub mod flags {
    /// The payload is no machine code: the image is for the virtual car's ECUs, whose
    /// logic runs on the host and which take from the header only what software it names.
    /// An ECU that runs its firmware refuses such an image ([`ImageError::NoMachineCode`]):
    /// its bootloader would start bytes that are not a program.
    pub const HOST_LOGIC: u16 = 0x0001;
    /// Every flag this format defines.
    pub const KNOWN: u16 = HOST_LOGIC;
}

/// What an image's payload is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Payload {
    /// An application for the MCU, its vector table first.
    MachineCode,
    /// No program: a stand-in for the virtual car's host-logic ECUs ([`flags::HOST_LOGIC`]).
    HostLogic,
}

/// The first eight bytes of every image.
pub const MAGIC: [u8; 8] = *b"APLGIMG1";
/// The header format this crate reads and writes.
pub const FORMAT_VERSION: u16 = 1;
/// Length of the header in bytes; also the offset of the payload in the image.
pub const HEADER_LEN: usize = 512;
/// Length of the Ed25519 signature that ends the image.
pub const SIGNATURE_LEN: usize = 64;
/// Length of an Ed25519 public key.
pub const PUBLIC_KEY_LEN: usize = 32;
/// Header plus signature: the length of an image with an empty payload.
pub const OVERHEAD_LEN: usize = HEADER_LEN + SIGNATURE_LEN;
/// The largest payload the host tool builds: the image length then still fits a `u32`
/// (the download's length type). Parsing does not enforce it; [`ImageHeader::check`]
/// against the slot size refuses far smaller payloads.
pub const MAX_PAYLOAD_LEN: u32 = u32::MAX - OVERHEAD_LEN as u32;

/// Hardware id of the NUCLEO-F446RE board every AutoPlug ECU runs on.
///
/// The high half is the STM32F446's device id (`DBGMCU_IDCODE.DEV_ID` = 0x421), so the
/// firmware can cross-check it against the chip; the low half numbers the board built
/// around that chip (1 = NUCLEO-F446RE).
pub const NUCLEO_F446RE: u32 = 0x0421_0001;

/// The F446RE's two image slots (the flash map, `autoplug-flash`, is where they are
/// written): an image's load address is its slot's [`ImageSlot::vector_table`]; and how
/// the image in a slot stands (confirmed, on trial, reverted).
pub use autoplug_flash::ab::{BootState, ImageSlot};

// The flash map reserves room for exactly this format's header in front of the vector table.
const _: () = assert!(autoplug_flash::IMAGE_HEADER_SIZE as usize == HEADER_LEN);

/// The development signing key: what the virtual car, the tests and a bench without its
/// own keys use. Its secret is in this source code, so an image signed with it proves
/// nothing: a production bench generates its own pair (`autoplug keygen`) and builds its
/// ECUs with that public key.
pub mod dev {
    /// Seed of the development signing key (its secret; deliberately public).
    pub const SIGNING_SEED: [u8; 32] = *b"AutoPlug dev key: secret public!";
    /// Public key of [`SIGNING_SEED`] (a test checks the pair).
    pub const PUBLIC_KEY: [u8; 32] = [
        23, 149, 166, 247, 112, 140, 109, 188, 112, 73, 251, 179, 221, 220, 155, 196, 50, 225, 228,
        190, 104, 161, 232, 9, 132, 160, 252, 203, 32, 48, 232, 56,
    ];
}

/// Byte offsets of the header fields (see the table in the crate documentation).
pub mod offsets {
    /// `[u8; 8]`, [`MAGIC`](crate::MAGIC).
    pub const MAGIC: usize = 0;
    /// `u16`, [`FORMAT_VERSION`](crate::FORMAT_VERSION).
    pub const FORMAT_VERSION: usize = 8;
    /// `u16`, [`HEADER_LEN`](crate::HEADER_LEN).
    pub const HEADER_SIZE: usize = 10;
    /// `u8`, the target ECU's diagnostic node number.
    pub const NODE: usize = 12;
    /// `u8`, the [`SoftwareVariant`](crate::SoftwareVariant).
    pub const VARIANT: usize = 13;
    /// `u16`, must be zero.
    pub const FLAGS: usize = 14;
    /// `u32`, the hardware id.
    pub const HARDWARE_ID: usize = 16;
    /// `u8`, version major.
    pub const VERSION_MAJOR: usize = 20;
    /// `u8`, version minor.
    pub const VERSION_MINOR: usize = 21;
    /// `u16`, version patch.
    pub const VERSION_PATCH: usize = 22;
    /// `u32`, payload length in bytes.
    pub const PAYLOAD_LEN: usize = 24;
    /// `u32`, load address of the payload.
    pub const LOAD_ADDRESS: usize = 28;
    /// `[u8; 16]`, build id.
    pub const BUILD_ID: usize = 32;
    /// `[u8; 16]`, part number.
    pub const PART_NUMBER: usize = 48;
    /// First reserved byte; reserved bytes run to the end of the header and must be zero.
    pub const RESERVED: usize = 64;
}

/// Length of the build id field.
pub const BUILD_ID_LEN: usize = 16;
/// Length of the part number field.
pub const PART_NUMBER_LEN: usize = 16;

// ---------------------------------------------------------------------------------------
// Version
// ---------------------------------------------------------------------------------------

/// A software version, `major.minor.patch`.
///
/// Ordered field by field (major first), which is the order anti-rollback compares in:
/// 1.2.3 < 1.10.0 < 2.0.0.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Default)]
pub struct Version {
    /// Incompatible changes.
    pub major: u8,
    /// Compatible additions.
    pub minor: u8,
    /// Fixes.
    pub patch: u16,
}

impl Version {
    /// The version `major.minor.patch`.
    pub const fn new(major: u8, minor: u8, patch: u16) -> Self {
        Self {
            major,
            minor,
            patch,
        }
    }
}

impl fmt::Display for Version {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}.{}", self.major, self.minor, self.patch)
    }
}

/// Why a string is not a [`Version`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ParseVersionError {
    /// Not three dot-separated fields.
    FieldCount(usize),
    /// A field is not a decimal number in its range.
    BadField {
        /// `"major"`, `"minor"` or `"patch"`.
        field: &'static str,
        /// The largest value the field holds.
        max: u16,
    },
}

impl fmt::Display for ParseVersionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::FieldCount(n) => write!(
                f,
                "a version is MAJOR.MINOR.PATCH (three fields separated by dots), found {n} field(s)"
            ),
            Self::BadField { field, max } => write!(
                f,
                "the {field} part of the version is not a decimal number from 0 to {max}"
            ),
        }
    }
}

impl core::error::Error for ParseVersionError {}

impl FromStr for Version {
    type Err = ParseVersionError;

    /// Parses `"1.2.3"`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let mut fields = s.split('.');
        let count = s.split('.').count();
        if count != 3 {
            return Err(ParseVersionError::FieldCount(count));
        }
        // Only ASCII digits: `u8::from_str` would also take a leading '+'.
        fn number(text: &str, field: &'static str, max: u16) -> Result<u16, ParseVersionError> {
            let bad = ParseVersionError::BadField { field, max };
            if text.is_empty() || !text.bytes().all(|b| b.is_ascii_digit()) {
                return Err(bad);
            }
            text.parse::<u32>()
                .ok()
                .and_then(|v| u16::try_from(v).ok())
                .filter(|v| *v <= max)
                .ok_or(bad)
        }
        let major = number(fields.next().unwrap_or(""), "major", u8::MAX.into())?;
        let minor = number(fields.next().unwrap_or(""), "minor", u8::MAX.into())?;
        let patch = number(fields.next().unwrap_or(""), "patch", u16::MAX)?;
        // The ranges above were checked, so the narrowing cannot fail.
        Ok(Version::new(major as u8, minor as u8, patch))
    }
}

// ---------------------------------------------------------------------------------------
// Software variant
// ---------------------------------------------------------------------------------------

/// Which software an image holds. The virtual car takes an ECU's behaviour after an update
/// from this field, so the faulty demonstrations can be installed like any other update.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum SoftwareVariant {
    /// The ECU's normal software.
    Standard = 0,
    /// The deliberately faulty demonstration software (broken cruise control, broken ABS).
    Faulty = 1,
}

impl SoftwareVariant {
    /// The variant stored as `value`; `None` for a value this format does not define.
    pub const fn from_u8(value: u8) -> Option<Self> {
        match value {
            0 => Some(Self::Standard),
            1 => Some(Self::Faulty),
            _ => None,
        }
    }

    /// The byte stored in the header.
    pub const fn as_u8(self) -> u8 {
        self as u8
    }
}

impl TryFrom<u8> for SoftwareVariant {
    type Error = ImageError;

    fn try_from(value: u8) -> Result<Self, ImageError> {
        Self::from_u8(value).ok_or(ImageError::UnknownVariant(value))
    }
}

impl fmt::Display for SoftwareVariant {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Standard => "standard",
            Self::Faulty => "faulty (demonstration)",
        })
    }
}

// ---------------------------------------------------------------------------------------
// Part number
// ---------------------------------------------------------------------------------------

/// The part number of the software (what UDS DID F187 reports), e.g. `AP-CRUISE-0001`:
/// up to 16 printable ASCII characters, NUL-padded in the header.
#[derive(Clone, Copy, PartialEq, Eq, Hash, Default)]
pub struct PartNumber([u8; PART_NUMBER_LEN]);

impl PartNumber {
    /// The part number `text`; refused when longer than 16 bytes or not printable ASCII.
    pub fn new(text: &str) -> Result<Self, ImageError> {
        let bytes = text.as_bytes();
        if bytes.len() > PART_NUMBER_LEN {
            return Err(ImageError::PartNumberTooLong { len: bytes.len() });
        }
        let mut field = [0u8; PART_NUMBER_LEN];
        field[..bytes.len()].copy_from_slice(bytes);
        Self::from_bytes(field)
    }

    /// The part number stored as `field`; refused unless it is printable ASCII followed by
    /// NUL padding only (a NUL followed by text would hide that text from a reader that
    /// stops at the NUL).
    pub fn from_bytes(field: [u8; PART_NUMBER_LEN]) -> Result<Self, ImageError> {
        let len = field
            .iter()
            .position(|&b| b == 0)
            .unwrap_or(PART_NUMBER_LEN);
        for (position, &byte) in field.iter().enumerate() {
            let ok = if position < len {
                (0x20..=0x7E).contains(&byte)
            } else {
                byte == 0
            };
            if !ok {
                return Err(ImageError::BadPartNumber { position, byte });
            }
        }
        Ok(Self(field))
    }

    /// The text without its padding.
    pub fn as_str(&self) -> &str {
        let len = self
            .0
            .iter()
            .position(|&b| b == 0)
            .unwrap_or(PART_NUMBER_LEN);
        // Construction admits printable ASCII only, which is UTF-8.
        core::str::from_utf8(&self.0[..len]).unwrap_or("")
    }

    /// The 16 bytes stored in the header.
    pub const fn as_bytes(&self) -> &[u8; PART_NUMBER_LEN] {
        &self.0
    }
}

impl fmt::Debug for PartNumber {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "PartNumber({:?})", self.as_str())
    }
}

impl fmt::Display for PartNumber {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

// ---------------------------------------------------------------------------------------
// Errors
// ---------------------------------------------------------------------------------------

/// Why an image, or a header, was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ImageError {
    /// The first eight bytes are not [`MAGIC`]: not an AutoPlug image.
    BadMagic {
        /// The bytes found instead.
        found: [u8; 8],
    },
    /// The header's format version is not [`FORMAT_VERSION`].
    UnsupportedFormat(u16),
    /// The header's size field is not [`HEADER_LEN`].
    BadHeaderSize {
        /// The size the header claims.
        found: u16,
    },
    /// A reserved header byte is not zero: written by a newer format this crate does not
    /// know, whose meaning must not be ignored silently.
    ReservedNotZero {
        /// Offset of the first non-zero reserved byte in the header.
        offset: usize,
    },
    /// The software variant byte is not one this format defines.
    UnknownVariant(u8),
    /// The flags field holds a flag this format does not define.
    NonZeroFlags(u16),
    /// The part number is not printable ASCII followed by NUL padding.
    BadPartNumber {
        /// Index of the offending byte in the 16-byte field.
        position: usize,
        /// The offending byte.
        byte: u8,
    },
    /// A part number given to [`PartNumber::new`] is longer than 16 bytes.
    PartNumberTooLong {
        /// Its length in bytes.
        len: usize,
    },
    /// The image is for another ECU.
    WrongEcu {
        /// This ECU's diagnostic node number.
        expected: u8,
        /// The node number in the image.
        found: u8,
    },
    /// The image is for other hardware.
    WrongHardware {
        /// This board's hardware id.
        expected: u32,
        /// The hardware id in the image.
        found: u32,
    },
    /// The image's payload would not run where this ECU puts it.
    WrongLoadAddress {
        /// Where the payload lands on this ECU.
        expected: u32,
        /// The load address in the image.
        found: u32,
    },
    /// The image's version is below the ECU's anti-rollback floor.
    Downgrade {
        /// The lowest version the ECU accepts.
        floor: Version,
        /// The version in the image.
        found: Version,
    },
    /// Fewer bytes than the image needs.
    Truncated {
        /// Bytes needed (for an image: 512 + payload length + 64).
        expected: u64,
        /// Bytes present.
        found: u64,
    },
    /// More bytes after the signature than the header accounts for.
    TrailingData {
        /// The image length the header gives (512 + payload length + 64).
        expected: u64,
        /// Bytes present.
        found: u64,
    },
    /// The image does not fit the slot it is for.
    Oversized {
        /// The largest image the slot takes, in bytes.
        max: u64,
        /// The image's length (512 + payload length + 64).
        found: u64,
    },
    /// The signature does not match the image and key: altered, corrupted, signed with
    /// another key, or not signed at all.
    BadSignature,
    /// The image holds no machine code (it is for the virtual car's host-logic ECUs) and
    /// this ECU runs its firmware.
    NoMachineCode,
    /// The payload's vector table cannot start the core where the image runs: its initial
    /// stack pointer is not in SRAM, or its reset handler not Thumb code inside the slot.
    NotStartable {
        /// The vector table's first word.
        initial_sp: u32,
        /// Its second: the reset handler.
        reset: u32,
    },
    /// The 32 bytes given as the public key are not an Ed25519 public key.
    BadPublicKey,
}

impl fmt::Display for ImageError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::BadMagic { found } => {
                f.write_str("not an AutoPlug image: magic is ")?;
                write_hex(f, found)?;
                f.write_str(", expected \"APLGIMG1\"")
            }
            Self::UnsupportedFormat(v) => write!(
                f,
                "unsupported image format version {v} (this software reads version {FORMAT_VERSION})"
            ),
            Self::BadHeaderSize { found } => write!(
                f,
                "header size field is {found}, expected {HEADER_LEN}"
            ),
            Self::ReservedNotZero { offset } => write!(
                f,
                "reserved header byte at offset {offset} is not zero (image from a newer format?)"
            ),
            Self::UnknownVariant(v) => write!(
                f,
                "unknown software variant {v} (0 = standard, 1 = faulty demonstration)"
            ),
            Self::NonZeroFlags(flags) => write!(
                f,
                "header flags are 0x{flags:04X}: flags 0x{:04X} are not defined",
                flags & !flags::KNOWN
            ),
            Self::BadPartNumber { position, byte } => write!(
                f,
                "part number byte {position} is 0x{byte:02X}: expected printable ASCII followed by NUL padding"
            ),
            Self::PartNumberTooLong { len } => write!(
                f,
                "part number is {len} bytes long, at most {PART_NUMBER_LEN} fit"
            ),
            Self::WrongEcu { expected, found } => {
                write!(f, "image is for ECU node 0x{found:02X}")?;
                if let Some(name) = node_name(*found) {
                    write!(f, " ({name})")?;
                }
                write!(f, ", this ECU is node 0x{expected:02X}")?;
                if let Some(name) = node_name(*expected) {
                    write!(f, " ({name})")?;
                }
                Ok(())
            }
            Self::WrongHardware { expected, found } => write!(
                f,
                "image is for hardware id 0x{found:08X}, this board is 0x{expected:08X}"
            ),
            Self::WrongLoadAddress { expected, found } => write!(
                f,
                "image is linked to run at 0x{found:08X}, this ECU runs it at 0x{expected:08X}"
            ),
            Self::Downgrade { floor, found } => write!(
                f,
                "image version {found} is below this ECU's anti-rollback floor {floor}"
            ),
            Self::Truncated { expected, found } => write!(
                f,
                "image is truncated: {found} bytes, expected {expected}"
            ),
            Self::TrailingData { expected, found } => write!(
                f,
                "image has {} trailing byte(s): {found} bytes, the header gives {expected}",
                found.saturating_sub(*expected)
            ),
            Self::Oversized { max, found } => write!(
                f,
                "image is {found} bytes, the slot takes at most {max}"
            ),
            Self::BadSignature => f.write_str(
                "signature does not match: the image was altered, or signed with another key, or not signed",
            ),
            Self::BadPublicKey => f.write_str("the public key is not a valid Ed25519 public key"),
            Self::NoMachineCode => f.write_str(
                "the image holds no machine code (it is built for the virtual car's host-logic ECUs) and this ECU runs its firmware: flash a firmware release (scripts/firmware-release)",
            ),
            Self::NotStartable { initial_sp, reset } => write!(
                f,
                "the payload's vector table cannot start the core (initial SP 0x{initial_sp:08X}, reset handler 0x{reset:08X}): the bootloader would never run it"
            ),
        }
    }
}

impl core::error::Error for ImageError {}

/// Lower-case hex of `bytes`, without allocating.
fn write_hex(f: &mut fmt::Formatter<'_>, bytes: &[u8]) -> fmt::Result {
    for b in bytes {
        write!(f, "{b:02x}")?;
    }
    Ok(())
}

/// The DBC name of the ECU with diagnostic node number `node`, if there is one.
pub fn node_name(node: u8) -> Option<&'static str> {
    autoplug_can::Node::ALL
        .iter()
        .find(|n| n.diag_node_number() == Some(node))
        .map(|n| n.name())
}

/// The name of a hardware id this crate knows.
pub fn hardware_name(hardware_id: u32) -> Option<&'static str> {
    match hardware_id {
        NUCLEO_F446RE => Some("NUCLEO-F446RE"),
        _ => None,
    }
}

// ---------------------------------------------------------------------------------------
// Header
// ---------------------------------------------------------------------------------------

/// The 512-byte header at the start of an image.
///
/// The fields are public so that the host tool can fill them; [`ImageHeader::parse`] is the
/// one door from bytes and refuses anything this format does not define. The header is
/// only trustworthy once the image's signature has been verified ([`verify`] or
/// [`StreamVerifier`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ImageHeader {
    /// Diagnostic node number of the ECU the image is for.
    pub node: u8,
    /// Standard or faulty demonstration software.
    pub variant: SoftwareVariant,
    /// Machine code, or a stand-in for host logic (the header's flags).
    pub payload: Payload,
    /// The board the image is for, e.g. [`NUCLEO_F446RE`].
    pub hardware_id: u32,
    /// The software version, compared with the ECU's anti-rollback floor.
    pub version: Version,
    /// Length of the payload between header and signature.
    pub payload_len: u32,
    /// Address the payload (the application's vector table) runs at.
    pub load_address: u32,
    /// Identifies the build (e.g. from the git commit); opaque.
    pub build_id: [u8; BUILD_ID_LEN],
    /// The software part number (UDS DID F187).
    pub part_number: PartNumber,
}

/// Reads a little-endian `u16` at `at`; `bytes` is a whole header, so the range exists.
fn le_u16(bytes: &[u8; HEADER_LEN], at: usize) -> u16 {
    u16::from_le_bytes([bytes[at], bytes[at + 1]])
}

/// Reads a little-endian `u32` at `at`; `bytes` is a whole header, so the range exists.
fn le_u32(bytes: &[u8; HEADER_LEN], at: usize) -> u32 {
    u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

/// Copies `N` bytes starting at `at`; `bytes` is a whole header, so the range exists.
fn array<const N: usize>(bytes: &[u8; HEADER_LEN], at: usize) -> [u8; N] {
    let mut out = [0u8; N];
    out.copy_from_slice(&bytes[at..at + N]);
    out
}

impl ImageHeader {
    /// Parses the header at the start of `bytes` (only the first 512 bytes are read, so a
    /// whole image may be passed).
    ///
    /// Checks the format only, not the signature nor whether the image suits this ECU
    /// (that is [`ImageHeader::check`]).
    pub fn parse(bytes: &[u8]) -> Result<ImageHeader, ImageError> {
        let Some(header) = bytes.first_chunk::<HEADER_LEN>() else {
            return Err(ImageError::Truncated {
                expected: HEADER_LEN as u64,
                found: bytes.len() as u64,
            });
        };
        let magic = array::<8>(header, offsets::MAGIC);
        if magic != MAGIC {
            return Err(ImageError::BadMagic { found: magic });
        }
        let format = le_u16(header, offsets::FORMAT_VERSION);
        if format != FORMAT_VERSION {
            return Err(ImageError::UnsupportedFormat(format));
        }
        let size = le_u16(header, offsets::HEADER_SIZE);
        if usize::from(size) != HEADER_LEN {
            return Err(ImageError::BadHeaderSize { found: size });
        }
        if let Some(i) = header[offsets::RESERVED..].iter().position(|&b| b != 0) {
            return Err(ImageError::ReservedNotZero {
                offset: offsets::RESERVED + i,
            });
        }
        let flags = le_u16(header, offsets::FLAGS);
        if flags & !flags::KNOWN != 0 {
            return Err(ImageError::NonZeroFlags(flags));
        }
        let payload = if flags & flags::HOST_LOGIC != 0 {
            Payload::HostLogic
        } else {
            Payload::MachineCode
        };
        let variant = SoftwareVariant::try_from(header[offsets::VARIANT])?;
        let part_number = PartNumber::from_bytes(array(header, offsets::PART_NUMBER))?;
        Ok(ImageHeader {
            node: header[offsets::NODE],
            variant,
            payload,
            hardware_id: le_u32(header, offsets::HARDWARE_ID),
            version: Version::new(
                header[offsets::VERSION_MAJOR],
                header[offsets::VERSION_MINOR],
                le_u16(header, offsets::VERSION_PATCH),
            ),
            payload_len: le_u32(header, offsets::PAYLOAD_LEN),
            load_address: le_u32(header, offsets::LOAD_ADDRESS),
            build_id: array(header, offsets::BUILD_ID),
            part_number,
        })
    }

    /// The 512 header bytes, as [`ImageHeader::parse`] reads them.
    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        let mut out = [0u8; HEADER_LEN];
        let mut put = |at: usize, bytes: &[u8]| out[at..at + bytes.len()].copy_from_slice(bytes);
        put(offsets::MAGIC, &MAGIC);
        put(offsets::FORMAT_VERSION, &FORMAT_VERSION.to_le_bytes());
        put(offsets::HEADER_SIZE, &(HEADER_LEN as u16).to_le_bytes());
        put(offsets::NODE, &[self.node]);
        put(offsets::VARIANT, &[self.variant.as_u8()]);
        if self.payload == Payload::HostLogic {
            put(offsets::FLAGS, &flags::HOST_LOGIC.to_le_bytes());
        }
        // The reserved bytes stay zero.
        put(offsets::HARDWARE_ID, &self.hardware_id.to_le_bytes());
        put(offsets::VERSION_MAJOR, &[self.version.major]);
        put(offsets::VERSION_MINOR, &[self.version.minor]);
        put(offsets::VERSION_PATCH, &self.version.patch.to_le_bytes());
        put(offsets::PAYLOAD_LEN, &self.payload_len.to_le_bytes());
        put(offsets::LOAD_ADDRESS, &self.load_address.to_le_bytes());
        put(offsets::BUILD_ID, &self.build_id);
        put(offsets::PART_NUMBER, self.part_number.as_bytes());
        out
    }

    /// Length of the signed part, header and payload.
    ///
    /// A `u64` because a hostile header may claim a payload close to `u32::MAX`; after
    /// [`ImageHeader::check`] it fits the slot and so a `u32`.
    pub const fn signed_len(&self) -> u64 {
        HEADER_LEN as u64 + self.payload_len as u64
    }

    /// Length of the whole image: header, payload and signature.
    pub const fn image_len(&self) -> u64 {
        self.signed_len() + SIGNATURE_LEN as u64
    }

    /// The F446RE slot the image is linked for (`None` for a load address of neither).
    pub const fn slot(&self) -> Option<ImageSlot> {
        ImageSlot::at_vector_table(self.load_address)
    }

    /// Whether this image may be installed on the ECU described by `expected`: its node,
    /// hardware, load address, size and anti-rollback floor. A version equal to the floor
    /// is accepted (re-installing the running software is allowed).
    pub fn check(&self, expected: &Expectations) -> Result<(), ImageError> {
        if self.payload == Payload::HostLogic && expected.runs_machine_code {
            return Err(ImageError::NoMachineCode);
        }
        if self.node != expected.node {
            return Err(ImageError::WrongEcu {
                expected: expected.node,
                found: self.node,
            });
        }
        if self.hardware_id != expected.hardware_id {
            return Err(ImageError::WrongHardware {
                expected: expected.hardware_id,
                found: self.hardware_id,
            });
        }
        if self.load_address != expected.load_address {
            return Err(ImageError::WrongLoadAddress {
                expected: expected.load_address,
                found: self.load_address,
            });
        }
        if self.image_len() > u64::from(expected.max_image_len) {
            return Err(ImageError::Oversized {
                max: expected.max_image_len.into(),
                found: self.image_len(),
            });
        }
        if self.version < expected.version_floor {
            return Err(ImageError::Downgrade {
                floor: expected.version_floor,
                found: self.version,
            });
        }
        Ok(())
    }
}

/// What `inspect` prints: one field per line.
impl fmt::Display for ImageHeader {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ECU node:       0x{:02X}", self.node)?;
        match node_name(self.node) {
            Some(name) => writeln!(f, " ({name})")?,
            None => writeln!(f, " (unknown)")?,
        }
        writeln!(f, "Variant:        {}", self.variant)?;
        if self.payload == Payload::HostLogic {
            writeln!(
                f,
                "Payload:        host logic (no machine code: for the virtual car's ECUs)"
            )?;
        }
        write!(f, "Hardware:       0x{:08X}", self.hardware_id)?;
        match hardware_name(self.hardware_id) {
            Some(name) => writeln!(f, " ({name})")?,
            None => writeln!(f, " (unknown)")?,
        }
        writeln!(f, "Version:        {}", self.version)?;
        writeln!(f, "Payload length: {} bytes", self.payload_len)?;
        writeln!(f, "Load address:   0x{:08X}", self.load_address)?;
        f.write_str("Build id:       ")?;
        write_hex(f, &self.build_id)?;
        writeln!(f)?;
        if self.part_number.as_str().is_empty() {
            write!(f, "Part number:    (none)")
        } else {
            write!(f, "Part number:    {}", self.part_number)
        }
    }
}

/// What an ECU accepts: checked by [`ImageHeader::check`] after the signature.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Expectations {
    /// This ECU's diagnostic node number.
    pub node: u8,
    /// This board's hardware id, e.g. [`NUCLEO_F446RE`].
    pub hardware_id: u32,
    /// The lowest version this ECU installs (anti-rollback); stored on the ECU.
    pub version_floor: Version,
    /// The largest image (header + payload + signature) the slot holds.
    pub max_image_len: u32,
    /// Where the payload will run on this ECU: the start of the slot it is written to
    /// + 512 ([`ImageSlot::vector_table`]).
    pub load_address: u32,
    /// The ECU runs its firmware from the slot: an image without machine code
    /// ([`Payload::HostLogic`]) is refused. `false` only for the virtual car's host-logic
    /// ECUs.
    pub runs_machine_code: bool,
}

/// The first two words of a vector table that [`check_startable`] accepts for `slot`: the
/// top of the F446's SRAM as the initial stack pointer and a Thumb reset handler just past
/// a full vector table (452 bytes). For payloads that stand in for an application (tests,
/// the virtual car's images); a real one comes from the linker.
pub const fn stand_in_vector_table(slot: ImageSlot) -> [u8; 8] {
    let sp = (autoplug_flash::SRAM_START + autoplug_flash::SRAM_SIZE).to_le_bytes();
    let reset = (slot.vector_table() + 0x1C5).to_le_bytes();
    [
        sp[0], sp[1], sp[2], sp[3], reset[0], reset[1], reset[2], reset[3],
    ]
}

/// Whether a payload beginning with `vector_table` (its first 8 bytes or more) can start
/// the core when it runs from `slot`: what the bootloader checks before it starts a slot,
/// checked before an image is accepted so that one it would never start is refused with a
/// reason instead of reverted without one.
pub fn check_startable(slot: ImageSlot, vector_table: &[u8]) -> Result<(), ImageError> {
    let word = |at: usize| {
        vector_table
            .get(at..at + 4)
            .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let (initial_sp, reset) = (word(0), word(4));
    if autoplug_flash::ab::plausible_vector_table(slot, initial_sp, reset) {
        Ok(())
    } else {
        Err(ImageError::NotStartable { initial_sp, reset })
    }
}

// ---------------------------------------------------------------------------------------
// Verification
// ---------------------------------------------------------------------------------------

/// The group order L of Ed25519, little-endian.
const GROUP_ORDER: [u8; 32] = [
    0xed, 0xd3, 0xf5, 0x5c, 0x1a, 0x63, 0x12, 0x58, 0xd6, 0x9c, 0xf7, 0xa2, 0xde, 0xf9, 0xde, 0x14,
    0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x10,
];

/// Whether the signature's scalar `s` is below L. salty does not check this, so a second
/// encoding `s + L` of a valid signature would also pass; RFC 8032 refuses it, and so do
/// we (our signer never produces one, so this refuses no image of ours).
fn scalar_is_canonical(signature: &[u8; SIGNATURE_LEN]) -> bool {
    let s = &signature[32..];
    for i in (0..32).rev() {
        if s[i] != GROUP_ORDER[i] {
            return s[i] < GROUP_ORDER[i];
        }
    }
    false
}

/// Ed25519 check of `signature` over `message` (the SHA-512 digest of the signed part).
fn check_signature(
    message: &[u8; 64],
    signature: &[u8; SIGNATURE_LEN],
    public_key: &[u8; PUBLIC_KEY_LEN],
) -> Result<(), ImageError> {
    let key = salty::PublicKey::try_from(public_key).map_err(|_| ImageError::BadPublicKey)?;
    if !scalar_is_canonical(signature) {
        return Err(ImageError::BadSignature);
    }
    let signature = salty::Signature::from(signature);
    key.verify(message, &signature)
        .map_err(|_| ImageError::BadSignature)
}

/// An image whose header parsed and whose signature verified.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VerifiedImage<'a> {
    header: ImageHeader,
    payload: &'a [u8],
    signature: [u8; SIGNATURE_LEN],
}

impl<'a> VerifiedImage<'a> {
    /// The header, now authenticated.
    pub const fn header(&self) -> &ImageHeader {
        &self.header
    }

    /// The payload: the application, starting with its vector table.
    pub const fn payload(&self) -> &'a [u8] {
        self.payload
    }

    /// The signature that verified.
    pub const fn signature(&self) -> &[u8; SIGNATURE_LEN] {
        &self.signature
    }
}

/// Verifies a whole image held in memory: its length against the header, the header's
/// format and the Ed25519 signature over SHA-512(header ‖ payload).
///
/// Whether the image suits a given ECU is [`ImageHeader::check`], to be called on the
/// returned header.
pub fn verify<'a>(
    image: &'a [u8],
    public_key: &[u8; PUBLIC_KEY_LEN],
) -> Result<VerifiedImage<'a>, ImageError> {
    let found = image.len() as u64;
    if image.len() < OVERHEAD_LEN {
        // With a readable header the full expected length is the more useful answer.
        let expected = ImageHeader::parse(image)
            .map(|h| h.image_len())
            .unwrap_or(OVERHEAD_LEN as u64);
        return Err(ImageError::Truncated { expected, found });
    }
    let header = ImageHeader::parse(image)?;
    let expected = header.image_len();
    if found < expected {
        return Err(ImageError::Truncated { expected, found });
    }
    if found > expected {
        return Err(ImageError::TrailingData { expected, found });
    }
    // The length is at least 576 (checked above), so both splits succeed.
    let Some((signed, signature)) = image.split_last_chunk::<SIGNATURE_LEN>() else {
        return Err(ImageError::Truncated { expected, found });
    };
    let mut hasher = StreamVerifier::new();
    hasher.update(signed);
    hasher.finish(signature, public_key)?;
    Ok(VerifiedImage {
        header,
        payload: signed.get(HEADER_LEN..).unwrap_or(&[]),
        signature: *signature,
    })
}

/// Verifies an image chunk by chunk, for an ECU whose image sits in flash and does not fit
/// in RAM: feed it header and payload (the first `512 + payload_len` bytes) in any chunking, then [`finish`](Self::finish) with the signature that
/// follows them. Same digest and check as [`verify`].
///
/// The caller decides how many bytes to feed, from a header it parsed and
/// [`check`](ImageHeader::check)ed; the signature then authenticates that header too.
pub struct StreamVerifier {
    hasher: salty::Sha512,
    len: u64,
}

impl StreamVerifier {
    /// A verifier that has seen nothing yet.
    pub fn new() -> Self {
        Self {
            hasher: salty::Sha512::new(),
            len: 0,
        }
    }

    /// Hashes the next `chunk` of header ‖ payload.
    pub fn update(&mut self, chunk: &[u8]) {
        self.hasher.update(chunk);
        self.len += chunk.len() as u64;
    }

    /// How many bytes have been fed so far.
    pub const fn bytes_hashed(&self) -> u64 {
        self.len
    }

    /// Checks `signature` under `public_key` over everything fed.
    pub fn finish(
        self,
        signature: &[u8; SIGNATURE_LEN],
        public_key: &[u8; PUBLIC_KEY_LEN],
    ) -> Result<(), ImageError> {
        let digest = self.hasher.finalize();
        check_signature(&digest, signature, public_key)
    }
}

impl Default for StreamVerifier {
    fn default() -> Self {
        Self::new()
    }
}

impl fmt::Debug for StreamVerifier {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("StreamVerifier")
            .field("bytes_hashed", &self.len)
            .finish_non_exhaustive()
    }
}
