//! The host tool's half (feature `std`): signing keys, key files and building images.

use std::fmt;

use zeroize::Zeroize;

use crate::{
    ImageError, ImageHeader, ImageSlot, PartNumber, Payload, SoftwareVariant, Version,
    BUILD_ID_LEN, HEADER_LEN, MAX_PAYLOAD_LEN, NUCLEO_F446RE, PUBLIC_KEY_LEN, SIGNATURE_LEN,
};

/// First word of a secret key file.
pub const SECRET_KEY_TAG: &str = "autoplug-ed25519-secret-v1";
/// First word of a public key file.
pub const PUBLIC_KEY_TAG: &str = "autoplug-ed25519-public-v1";

/// Hex characters of a 32-byte key.
const KEY_HEX_LEN: usize = 64;

/// The two kinds of key file, told apart by their tag so that one is never taken for the
/// other.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KeyKind {
    /// The 32-byte Ed25519 seed that signs images.
    Secret,
    /// The 32-byte Ed25519 public key that ECUs verify with.
    Public,
}

impl KeyKind {
    /// The tag that starts a file of this kind.
    pub const fn tag(self) -> &'static str {
        match self {
            Self::Secret => SECRET_KEY_TAG,
            Self::Public => PUBLIC_KEY_TAG,
        }
    }

    const fn other(self) -> Self {
        match self {
            Self::Secret => Self::Public,
            Self::Public => Self::Secret,
        }
    }
}

impl fmt::Display for KeyKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Secret => "secret key",
            Self::Public => "public key",
        })
    }
}

/// Why a key file was refused.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum KeyFileError {
    /// The file has no text.
    Empty {
        /// The kind that was expected.
        expected: KeyKind,
    },
    /// The file is a key file of the other kind (e.g. a public key given to sign with).
    WrongKind {
        /// The kind that was expected.
        expected: KeyKind,
        /// The kind the file is.
        found: KeyKind,
    },
    /// The file does not start with a key file tag.
    UnknownTag {
        /// The kind that was expected.
        expected: KeyKind,
        /// The first word of the file (cut to 40 characters).
        found: String,
    },
    /// A character of the key is not a hex digit.
    NonHex {
        /// Column of the character in the line, counting from 1.
        position: usize,
        /// The character.
        character: char,
    },
    /// The key does not have 64 hex digits.
    WrongLength {
        /// Hex digits needed.
        expected: usize,
        /// Hex digits found.
        found: usize,
    },
    /// Text after the key line.
    TrailingText {
        /// Line number of the extra text, counting from 1.
        line: usize,
    },
    /// The 32 bytes of a public key file are not an Ed25519 public key.
    InvalidPublicKey,
}

impl fmt::Display for KeyFileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Empty { expected } => write!(
                f,
                "the {expected} file is empty: expected a line \"{} <64 hex digits>\"",
                expected.tag()
            ),
            Self::WrongKind { expected, found } => write!(
                f,
                "this is a {found} file (\"{}\"), a {expected} file (\"{}\") was expected",
                found.tag(),
                expected.tag()
            ),
            Self::UnknownTag { expected, found } => write!(
                f,
                "not a {expected} file: it starts with {found:?}, expected \"{}\"",
                expected.tag()
            ),
            Self::NonHex {
                position,
                character,
            } => write!(
                f,
                "non-hex character {character:?} at position {position} of the key line"
            ),
            Self::WrongLength { expected, found } => {
                write!(f, "the key has {found} hex digits, expected {expected}")
            }
            Self::TrailingText { line } => write!(
                f,
                "unexpected text on line {line}: a key file is a single line"
            ),
            Self::InvalidPublicKey => {
                f.write_str("the public key file holds 32 bytes that are not an Ed25519 public key")
            }
        }
    }
}

impl std::error::Error for KeyFileError {}

/// The OS random source failed while generating a key.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct KeyGenError(getrandom::Error);

impl fmt::Display for KeyGenError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "could not read 32 random bytes from the operating system: {}",
            self.0
        )
    }
}

impl std::error::Error for KeyGenError {}

/// Lower-case hex of `bytes`.
fn to_hex(bytes: &[u8]) -> String {
    use std::fmt::Write;
    let mut out = String::with_capacity(bytes.len() * 2);
    for b in bytes {
        // Writing to a String cannot fail.
        let _ = write!(out, "{b:02x}");
    }
    out
}

/// The value of one hex digit.
fn hex_value(c: char) -> Option<u8> {
    c.to_digit(16).and_then(|v| u8::try_from(v).ok())
}

/// Reads the 32 bytes of a key file of `kind`.
fn parse_key_file(text: &str, kind: KeyKind) -> Result<[u8; 32], KeyFileError> {
    let mut lines = text.lines();
    // Trailing whitespace (a final newline, a stray "\r" or space) is harmless; anything else
    // is not what we wrote, so it is refused rather than guessed at.
    let line = lines.next().unwrap_or("").trim_end();
    if line.is_empty() {
        return Err(KeyFileError::Empty { expected: kind });
    }
    if let Some((n, _)) = lines.enumerate().find(|(_, l)| !l.trim().is_empty()) {
        return Err(KeyFileError::TrailingText { line: n + 2 });
    }
    let (tag, hex) = line.split_once(' ').unwrap_or((line, ""));
    if tag != kind.tag() {
        if tag == kind.other().tag() {
            return Err(KeyFileError::WrongKind {
                expected: kind,
                found: kind.other(),
            });
        }
        return Err(KeyFileError::UnknownTag {
            expected: kind,
            found: tag.chars().take(40).collect(),
        });
    }
    let first_column = tag.chars().count() + 2;
    if let Some((i, character)) = hex
        .chars()
        .enumerate()
        .find(|(_, c)| hex_value(*c).is_none())
    {
        return Err(KeyFileError::NonHex {
            position: first_column + i,
            character,
        });
    }
    // All characters are hex digits, hence ASCII: one byte each.
    if hex.len() != KEY_HEX_LEN {
        return Err(KeyFileError::WrongLength {
            expected: KEY_HEX_LEN,
            found: hex.len(),
        });
    }
    let mut key = [0u8; 32];
    let digits: Vec<u8> = hex.chars().filter_map(hex_value).collect();
    for (byte, pair) in key.iter_mut().zip(digits.chunks_exact(2)) {
        *byte = (pair[0] << 4) | pair[1];
    }
    Ok(key)
}

/// The text of a public key file: `autoplug-ed25519-public-v1 <64 hex digits>` and a newline.
pub fn public_key_to_file_string(public_key: &[u8; PUBLIC_KEY_LEN]) -> String {
    format!("{PUBLIC_KEY_TAG} {}\n", to_hex(public_key))
}

/// Reads a public key file (see [`public_key_to_file_string`]); refuses a secret key file,
/// a malformed one, and 32 bytes that are not an Ed25519 public key.
pub fn parse_public_key(text: &str) -> Result<[u8; PUBLIC_KEY_LEN], KeyFileError> {
    let key = parse_key_file(text, KeyKind::Public)?;
    salty::PublicKey::try_from(&key).map_err(|_| KeyFileError::InvalidPublicKey)?;
    Ok(key)
}

/// An Ed25519 signing key, kept as its 32-byte seed (RFC 8032's private key). The seed is
/// wiped from memory when the key is dropped.
pub struct SigningKey {
    seed: [u8; 32],
}

impl SigningKey {
    /// A new key from the operating system's random source.
    pub fn generate() -> Result<Self, KeyGenError> {
        let mut seed = [0u8; 32];
        getrandom::fill(&mut seed).map_err(KeyGenError)?;
        let key = Self::from_seed(seed);
        seed.zeroize();
        Ok(key)
    }

    /// The key with this seed (deterministic: for tests and for keys kept elsewhere).
    pub const fn from_seed(seed: [u8; 32]) -> Self {
        Self { seed }
    }

    /// The seed, which is all there is of the secret key.
    pub const fn seed(&self) -> &[u8; 32] {
        &self.seed
    }

    /// The key pair, from ed25519-compact rather than salty: Ed25519 signatures are
    /// deterministic (RFC 8032), so both give the same bytes (a test holds them to it),
    /// and salty's portable field arithmetic, which it uses off the Cortex-M, takes about
    /// a millisecond per scalar multiplication: a virtual car signing its nine factory
    /// images spent a tenth of its run doing so. Verification stays salty's everywhere,
    /// the same code as on the ECUs.
    fn keypair(&self) -> ed25519_compact::KeyPair {
        ed25519_compact::KeyPair::from_seed(ed25519_compact::Seed::new(self.seed))
    }

    /// The public key the ECUs verify with.
    pub fn public_key(&self) -> [u8; PUBLIC_KEY_LEN] {
        *self.keypair().pk
    }

    /// Ed25519 signature of `message` (for images: the SHA-512 digest of header ‖ payload).
    pub fn sign(&self, message: &[u8]) -> [u8; SIGNATURE_LEN] {
        *self.keypair().sk.sign(message, None)
    }

    /// The text of a secret key file: `autoplug-ed25519-secret-v1 <64 hex digits>` and a
    /// newline.
    pub fn to_file_string(&self) -> String {
        format!("{SECRET_KEY_TAG} {}\n", to_hex(&self.seed))
    }

    /// Reads a secret key file (see [`SigningKey::to_file_string`]); refuses a public key
    /// file and a malformed one.
    pub fn parse(text: &str) -> Result<Self, KeyFileError> {
        let mut seed = parse_key_file(text, KeyKind::Secret)?;
        let key = Self::from_seed(seed);
        seed.zeroize();
        Ok(key)
    }

    /// The text of the matching public key file.
    pub fn public_key_file_string(&self) -> String {
        public_key_to_file_string(&self.public_key())
    }
}

impl Drop for SigningKey {
    fn drop(&mut self) {
        self.seed.zeroize();
    }
}

/// Shows the public key only, so that logging a key cannot leak it.
impl fmt::Debug for SigningKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "SigningKey {{ public: {} }}", to_hex(&self.public_key()))
    }
}

/// Everything that goes into an image; [`ImageBuilder::sign`] makes the image file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ImageBuilder {
    /// Diagnostic node number of the target ECU.
    pub node: u8,
    /// Standard or faulty demonstration software.
    pub variant: SoftwareVariant,
    /// Machine code (the default), or a stand-in for the virtual car's host logic.
    pub payload_kind: Payload,
    /// The board the image is for.
    pub hardware_id: u32,
    /// The software version.
    pub version: Version,
    /// Identifies the build (e.g. the first 16 bytes of the git commit).
    pub build_id: [u8; BUILD_ID_LEN],
    /// The software part number (UDS DID F187).
    pub part_number: PartNumber,
    /// Where the payload runs: slot start + 512.
    pub load_address: u32,
    /// The application binary, starting with its vector table.
    pub payload: Vec<u8>,
}

impl ImageBuilder {
    /// An image of `payload` for ECU `node` at `version`: standard software for the
    /// NUCLEO-F446RE linked for slot A ([`ImageSlot::vector_table`]), zero build id, no part
    /// number. Set the other fields directly.
    pub fn new(node: u8, version: Version, payload: Vec<u8>) -> Self {
        Self {
            node,
            variant: SoftwareVariant::Standard,
            payload_kind: Payload::MachineCode,
            hardware_id: NUCLEO_F446RE,
            version,
            build_id: [0; BUILD_ID_LEN],
            part_number: PartNumber::default(),
            load_address: ImageSlot::A.vector_table(),
            payload,
        }
    }

    /// The header of the image; refused when the payload is longer than
    /// [`MAX_PAYLOAD_LEN`] (the image length must fit a `u32`, the download's length type).
    pub fn header(&self) -> Result<ImageHeader, ImageError> {
        let payload_len = u32::try_from(self.payload.len())
            .ok()
            .filter(|len| *len <= MAX_PAYLOAD_LEN)
            .ok_or(ImageError::Oversized {
                max: u64::from(u32::MAX),
                found: (HEADER_LEN + self.payload.len() + SIGNATURE_LEN) as u64,
            })?;
        Ok(ImageHeader {
            node: self.node,
            variant: self.variant,
            payload: self.payload_kind,
            hardware_id: self.hardware_id,
            version: self.version,
            payload_len,
            load_address: self.load_address,
            build_id: self.build_id,
            part_number: self.part_number,
        })
    }

    /// The signed image file: header ‖ payload ‖ Ed25519(SHA-512(header ‖ payload)).
    pub fn sign(&self, key: &SigningKey) -> Result<Vec<u8>, ImageError> {
        let header = self.header()?.to_bytes();
        let mut image = Vec::with_capacity(HEADER_LEN + self.payload.len() + SIGNATURE_LEN);
        image.extend_from_slice(&header);
        image.extend_from_slice(&self.payload);
        let digest = salty::Sha512::new().updated(&image).finalize();
        image.extend_from_slice(&key.sign(&digest));
        Ok(image)
    }
}
