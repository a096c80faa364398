//! Keys and images on disk: key generation, building a signed image from a raw binary or
//! an ELF file, and inspecting an image.
//!
//! The formats are `autoplug_image`'s; this module adds files, payload extraction and
//! errors that name the file and what is wrong with it.

use std::fmt;
use std::fs::{self, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

use autoplug_can::Node;
use autoplug_image::elf::loadable_segments;
use autoplug_image::{
    parse_public_key, verify, ImageBuilder, ImageError, ImageHeader, ImageSet, ImageSlot,
    KeyFileError, KeyGenError, KeyKind, PartNumber, SigningKey, SoftwareVariant, Version,
    BUILD_ID_LEN, HEADER_LEN, OVERHEAD_LEN, PUBLIC_KEY_LEN, SIGNATURE_LEN,
};
use object::elf;
use sha2::{Digest, Sha256};

use autoplug_tester::names::ecu_label;

/// Bytes of an F446RE image slot, where an image runs in place: header, payload and
/// signature must fit it.
pub const SLOT_LEN: u32 = autoplug_flash::SLOT_A.size;

/// The largest payload an image for the F446RE's slot can carry.
pub const MAX_PAYLOAD_LEN: usize = SLOT_LEN as usize - OVERHEAD_LEN;

/// Why a key, payload or image file could not be used.
#[derive(Debug)]
pub enum ImageToolError {
    /// Reading or writing a file failed.
    Io {
        /// What was being done, with the file's name.
        context: String,
        /// The error.
        source: io::Error,
    },
    /// `keygen` would overwrite a key file.
    Exists(PathBuf),
    /// A key file is malformed or of the wrong kind.
    KeyFile {
        /// The file.
        path: PathBuf,
        /// What is wrong with it.
        source: KeyFileError,
    },
    /// The operating system's random source failed.
    KeyGen(KeyGenError),
    /// The payload cannot go into an image.
    Payload {
        /// The payload file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// The image could not be built (e.g. a part number too long).
    Build(ImageError),
    /// A file is not an image (its header does not parse).
    NotAnImage {
        /// The file.
        path: PathBuf,
        /// Why.
        source: ImageError,
    },
    /// The node has no diagnostic node number, so no image can name it.
    NotAnEcu(Node),
    /// An image is damaged: wrong length or a signature that does not verify.
    Corrupted {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problems: Vec<String>,
    },
}

impl fmt::Display for ImageToolError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ImageToolError::Io { context, source } => write!(f, "{context}: {source}"),
            ImageToolError::Exists(path) => write!(
                f,
                "refusing to overwrite '{}': it exists (remove it or choose another --out)",
                path.display()
            ),
            ImageToolError::KeyFile { path, source } => {
                write!(f, "bad key file '{}': {source}", path.display())
            }
            ImageToolError::KeyGen(error) => error.fmt(f),
            ImageToolError::Payload { path, reason } => {
                write!(f, "payload '{}': {reason}", path.display())
            }
            ImageToolError::Build(error) => write!(f, "cannot build the image: {error}"),
            ImageToolError::NotAnImage { path, source } => write!(
                f,
                "'{}' is not a valid AutoPlug image: {source}",
                path.display()
            ),
            ImageToolError::NotAnEcu(node) => write!(
                f,
                "{} is not one of the nine ECUs: no image can be built for it",
                node.name()
            ),
            ImageToolError::Corrupted { path, problems } => write!(
                f,
                "'{}' is corrupted: {}",
                path.display(),
                problems.join("; ")
            ),
        }
    }
}

impl std::error::Error for ImageToolError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            ImageToolError::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

fn read_file(path: &Path, what: &str) -> Result<Vec<u8>, ImageToolError> {
    fs::read(path).map_err(|source| ImageToolError::Io {
        context: format!("cannot read {what} '{}'", path.display()),
        source,
    })
}

fn read_text(path: &Path, what: &str) -> Result<String, ImageToolError> {
    let bytes = read_file(path, what)?;
    String::from_utf8(bytes).map_err(|_| ImageToolError::KeyFile {
        path: path.to_path_buf(),
        source: KeyFileError::UnknownTag {
            expected: KeyKind::Secret,
            found: "(binary data, not text)".into(),
        },
    })
}

// ---------------------------------------------------------------------------------------
// Keys
// ---------------------------------------------------------------------------------------

/// The two files of a key pair.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KeyPaths {
    /// `NAME.key`: the secret key (signs images); mode 0600.
    pub secret: PathBuf,
    /// `NAME.pub`: the public key (ECUs verify with it).
    pub public: PathBuf,
}

/// `keys/dev` → `keys/dev.key` and `keys/dev.pub` (a `.key` or `.pub` given is dropped
/// first, so `keys/dev.key` means the same).
pub fn key_paths(out: &Path) -> KeyPaths {
    let base = match out.extension().and_then(|e| e.to_str()) {
        Some("key" | "pub") => out.with_extension(""),
        _ => out.to_path_buf(),
    };
    let with = |ext: &str| {
        let mut name = base.as_os_str().to_os_string();
        name.push(ext);
        PathBuf::from(name)
    };
    KeyPaths {
        secret: with(".key"),
        public: with(".pub"),
    }
}

/// Generates a key pair from the OS random source and writes it (see [`write_key_pair`]).
pub fn keygen(out: &Path) -> Result<KeyPaths, ImageToolError> {
    let key = SigningKey::generate().map_err(ImageToolError::KeyGen)?;
    write_key_pair(out, &key)
}

/// Writes `key` as `NAME.key` (readable by the owner only) and `NAME.pub`, creating the
/// folder if needed. Refuses, before writing anything, if either file exists: a key
/// overwritten by mistake would orphan every image signed with it.
pub fn write_key_pair(out: &Path, key: &SigningKey) -> Result<KeyPaths, ImageToolError> {
    let paths = key_paths(out);
    for path in [&paths.secret, &paths.public] {
        if path.exists() {
            return Err(ImageToolError::Exists(path.clone()));
        }
    }
    if let Some(parent) = paths.secret.parent().filter(|p| !p.as_os_str().is_empty()) {
        fs::create_dir_all(parent).map_err(|source| ImageToolError::Io {
            context: format!("cannot create the folder '{}'", parent.display()),
            source,
        })?;
    }
    write_new(&paths.secret, key.to_file_string().as_bytes(), true)?;
    write_new(
        &paths.public,
        key.public_key_file_string().as_bytes(),
        false,
    )?;
    Ok(paths)
}

/// Creates `path` (failing if it exists, so a race cannot overwrite either) and writes it.
fn write_new(path: &Path, contents: &[u8], secret: bool) -> Result<(), ImageToolError> {
    let mut options = OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(if secret { 0o600 } else { 0o644 });
    }
    #[cfg(not(unix))]
    let _ = secret;
    let mut file = options.open(path).map_err(|source| {
        if source.kind() == io::ErrorKind::AlreadyExists {
            ImageToolError::Exists(path.to_path_buf())
        } else {
            ImageToolError::Io {
                context: format!("cannot create '{}'", path.display()),
                source,
            }
        }
    })?;
    file.write_all(contents)
        .map_err(|source| ImageToolError::Io {
            context: format!("cannot write '{}'", path.display()),
            source,
        })
}

/// What `--key dev` names: the development key pair (`autoplug_image::dev`), whose
/// secret is in the source code; for the virtual car and a bench without keys of its own.
pub const DEV_KEY: &str = "dev";

/// Reads a secret key file (or takes the development key for [`DEV_KEY`]).
pub fn read_signing_key(path: &Path) -> Result<SigningKey, ImageToolError> {
    if path == Path::new(DEV_KEY) {
        return Ok(SigningKey::from_seed(autoplug_image::dev::SIGNING_SEED));
    }
    let text = read_text(path, "the secret key")?;
    SigningKey::parse(&text).map_err(|source| ImageToolError::KeyFile {
        path: path.to_path_buf(),
        source,
    })
}

/// Reads a public key file; a secret key file is accepted too (its public half is used),
/// and [`DEV_KEY`] names the development key.
pub fn read_public_key(path: &Path) -> Result<[u8; PUBLIC_KEY_LEN], ImageToolError> {
    if path == Path::new(DEV_KEY) {
        return Ok(autoplug_image::dev::PUBLIC_KEY);
    }
    let text = read_text(path, "the public key")?;
    match parse_public_key(&text) {
        Ok(key) => Ok(key),
        Err(KeyFileError::WrongKind {
            found: KeyKind::Secret,
            ..
        }) => SigningKey::parse(&text)
            .map(|key| key.public_key())
            .map_err(|source| ImageToolError::KeyFile {
                path: path.to_path_buf(),
                source,
            }),
        Err(source) => Err(ImageToolError::KeyFile {
            path: path.to_path_buf(),
            source,
        }),
    }
}

// ---------------------------------------------------------------------------------------
// Payloads
// ---------------------------------------------------------------------------------------

/// What a payload file was.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PayloadKind {
    /// A raw binary, taken as it is.
    Raw,
    /// An ELF file; its loadable segments were laid out from the load address.
    Elf {
        /// Loadable segments with data.
        segments: usize,
    },
}

/// The payload in `bytes`: an ELF file's loadable segments laid out from `load_address`
/// (gaps filled with 0xFF, the erased flash value), or a raw binary as it is. Refused: an
/// empty payload, one longer than `max_len`, an ELF segment outside
/// `load_address..load_address + max_len`, an ELF whose first segment is not at the load
/// address (the vector table has to be there).
pub fn extract_payload(
    bytes: &[u8],
    load_address: u32,
    max_len: usize,
) -> Result<(Vec<u8>, PayloadKind), String> {
    let (payload, kind) = if bytes.starts_with(&elf::ELFMAG) {
        let (payload, segments) = elf_payload(bytes, load_address, max_len)?;
        (payload, PayloadKind::Elf { segments })
    } else {
        (bytes.to_vec(), PayloadKind::Raw)
    };
    if payload.is_empty() {
        return Err("the payload is empty".into());
    }
    if payload.len() > max_len {
        return Err(format!(
            "{} bytes do not fit the slot: an image for the F446RE carries at most {max_len} payload bytes ({} KiB slot less header and signature)",
            payload.len(),
            (max_len + OVERHEAD_LEN) / 1024
        ));
    }
    Ok((payload, kind))
}

/// The slot a payload is for: an ELF file's from where it is linked (its first loadable
/// segment is the vector table, at a slot's start + 512), a raw binary's as `given`
/// (default A). A `given` slot an ELF file is not linked for is refused.
pub fn payload_slot(bytes: &[u8], given: Option<ImageSlot>) -> Result<ImageSlot, String> {
    if !bytes.starts_with(&elf::ELFMAG) {
        return Ok(given.unwrap_or(ImageSlot::A));
    }
    let segments = loadable_segments(bytes)?;
    let Some(&(first, _)) = segments.first() else {
        return Err("the ELF file has no loadable segment with data".into());
    };
    let linked = u32::try_from(first)
        .ok()
        .and_then(ImageSlot::at_vector_table)
        .ok_or_else(|| {
            format!(
                "the ELF file is linked at 0x{first:08X}, not for slot A (0x{:08X}) or slot B (0x{:08X}): build the firmware with AUTOPLUG_SLOT=a or b",
                ImageSlot::A.vector_table(),
                ImageSlot::B.vector_table()
            )
        })?;
    match given {
        Some(slot) if slot != linked => Err(format!(
            "the ELF file is linked for slot {}, not slot {} as --slot says",
            linked.letter(),
            slot.letter()
        )),
        _ => Ok(linked),
    }
}

fn elf_payload(
    bytes: &[u8],
    load_address: u32,
    max_len: usize,
) -> Result<(Vec<u8>, usize), String> {
    let segments = loadable_segments(bytes)?;
    let slot_end = u64::from(load_address) + max_len as u64;
    for &(start, data) in &segments {
        let end = start + data.len() as u64;
        if start < u64::from(load_address) || end > slot_end {
            return Err(format!(
                "a loadable segment at 0x{start:08X}..0x{end:08X} lies outside the slot 0x{load_address:08X}..0x{slot_end:08X} (link the application for the AutoPlug slot)"
            ));
        }
    }
    let Some(&(first, _)) = segments.first() else {
        return Err("the ELF file has no loadable segment with data".into());
    };
    if first != u64::from(load_address) {
        return Err(format!(
            "the first loadable segment starts at 0x{first:08X}, not at the load address 0x{load_address:08X} where the vector table must be"
        ));
    }
    let mut payload: Vec<u8> = Vec::new();
    for (start, data) in &segments {
        let offset = (start - u64::from(load_address)) as usize;
        if offset < payload.len() {
            return Err(format!("loadable segments overlap at 0x{start:08X}"));
        }
        payload.resize(offset, 0xFF);
        payload.extend_from_slice(data);
    }
    Ok((payload, segments.len()))
}

/// The default build id: the first 16 bytes of the payload's SHA-256, so the same payload
/// always gets the same id and another payload a different one.
pub fn default_build_id(payload: &[u8]) -> [u8; BUILD_ID_LEN] {
    let digest = Sha256::digest(payload);
    let mut id = [0u8; BUILD_ID_LEN];
    id.copy_from_slice(&digest[..BUILD_ID_LEN]);
    id
}

/// Parses a build id given as 32 hex digits.
pub fn parse_build_id(text: &str) -> Result<[u8; BUILD_ID_LEN], String> {
    let digits = text.trim();
    if let Some((i, c)) = digits.char_indices().find(|(_, c)| !c.is_ascii_hexdigit()) {
        return Err(format!(
            "build id '{text}': {c:?} at position {} is not a hex digit",
            i + 1
        ));
    }
    if digits.len() != 2 * BUILD_ID_LEN {
        return Err(format!(
            "build id '{text}' has {} hex digits, expected {}",
            digits.len(),
            2 * BUILD_ID_LEN
        ));
    }
    let mut id = [0u8; BUILD_ID_LEN];
    for (i, byte) in id.iter_mut().enumerate() {
        *byte = u8::from_str_radix(&digits[2 * i..2 * i + 2], 16).unwrap_or(0);
    }
    Ok(id)
}

// ---------------------------------------------------------------------------------------
// Building
// ---------------------------------------------------------------------------------------

/// What goes into `image build`.
#[derive(Debug, Clone)]
pub struct BuildOptions {
    /// The target ECU.
    pub ecu: Node,
    /// The software version.
    pub version: Version,
    /// Standard or faulty demonstration software.
    pub variant: SoftwareVariant,
    /// The part number (F187); none if not given.
    pub part_number: Option<String>,
    /// The build id; [`default_build_id`] of the payload if not given.
    pub build_id: Option<[u8; BUILD_ID_LEN]>,
    /// The raw binaries or ELF files: one, or one per slot (the release for both slots in
    /// one file).
    pub payloads: Vec<PathBuf>,
    /// The slot a raw binary is linked for (an ELF file says it itself); default A.
    pub slot: Option<ImageSlot>,
    /// The secret key file.
    pub key: PathBuf,
    /// The image file to write.
    pub out: PathBuf,
}

/// What `image build` made.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Built {
    /// Each image written, in file order: its header and what its payload file was.
    pub images: Vec<(ImageHeader, PayloadKind)>,
    /// Bytes of the image file.
    pub image_len: usize,
}

/// Builds and signs an image per payload and writes them, one after the other, to
/// `options.out`. Two payloads must be linked for different slots.
pub fn build_image(options: &BuildOptions) -> Result<Built, ImageToolError> {
    let node = options
        .ecu
        .diag_node_number()
        .ok_or(ImageToolError::NotAnEcu(options.ecu))?;
    let bad = |path: &Path, reason: String| ImageToolError::Payload {
        path: path.to_path_buf(),
        reason,
    };
    match options.payloads.as_slice() {
        [] => return Err(bad(Path::new(""), "no payload given".into())),
        [_] | [_, _] => {}
        [.., third] => {
            return Err(bad(
                third,
                "at most two payloads, one per slot (A and B)".into(),
            ))
        }
    }
    if options.payloads.len() == 2 && options.slot.is_some() {
        return Err(bad(
            &options.payloads[0],
            "--slot is for one raw binary; two payloads must be ELF files, which say their slot"
                .into(),
        ));
    }
    // The key first: a bad key should not wait for a large payload to be read.
    let key = read_signing_key(&options.key)?;
    let mut file = Vec::new();
    let mut images = Vec::new();
    let mut slots = Vec::new();
    for path in &options.payloads {
        let bytes = read_file(path, "the payload")?;
        if options.payloads.len() == 2 && !bytes.starts_with(&elf::ELFMAG) {
            return Err(bad(
                path,
                "a raw binary does not say which slot it is linked for: give ELF files for a two-slot release".into(),
            ));
        }
        let slot = payload_slot(&bytes, options.slot).map_err(|reason| bad(path, reason))?;
        if slots.contains(&slot) {
            return Err(bad(
                path,
                format!(
                    "both payloads are linked for slot {}: a release holds one image per slot",
                    slot.letter()
                ),
            ));
        }
        slots.push(slot);
        let (payload, kind) = extract_payload(&bytes, slot.vector_table(), MAX_PAYLOAD_LEN)
            .map_err(|reason| bad(path, reason))?;
        let mut builder = ImageBuilder::new(node, options.version, Vec::new());
        builder.variant = options.variant;
        builder.load_address = slot.vector_table();
        builder.build_id = options
            .build_id
            .unwrap_or_else(|| default_build_id(&payload));
        if let Some(text) = &options.part_number {
            builder.part_number = PartNumber::new(text).map_err(ImageToolError::Build)?;
        }
        builder.payload = payload;
        let header = builder.header().map_err(ImageToolError::Build)?;
        file.extend_from_slice(&builder.sign(&key).map_err(ImageToolError::Build)?);
        images.push((header, kind));
    }
    fs::write(&options.out, &file).map_err(|source| ImageToolError::Io {
        context: format!("cannot write the image '{}'", options.out.display()),
        source,
    })?;
    Ok(Built {
        images,
        image_len: file.len(),
    })
}

// ---------------------------------------------------------------------------------------
// Inspecting
// ---------------------------------------------------------------------------------------

/// Whether the signature was checked, and how that went.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SignatureCheck {
    /// No key was given.
    NotChecked,
    /// It verifies under the key.
    Valid,
    /// It does not (or the image's length is wrong, so it could not be checked).
    Invalid(ImageError),
}

/// What `image inspect` finds in an image file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Inspection {
    /// The header.
    pub header: ImageHeader,
    /// Bytes of the file this image takes (up to the next image of a release, or the end).
    pub file_len: u64,
    /// The signature check.
    pub signature: SignatureCheck,
    /// The public key checked against, if any.
    pub public_key: Option<[u8; PUBLIC_KEY_LEN]>,
}

impl Inspection {
    /// What is wrong with the image: its length against the header, its signature. Empty
    /// when nothing is known to be wrong.
    pub fn problems(&self) -> Vec<String> {
        let mut problems = Vec::new();
        let expected = self.header.image_len();
        if self.file_len < expected {
            problems.push(format!(
                "truncated: {} bytes, the header gives {expected}",
                self.file_len
            ));
        } else if self.file_len > expected {
            problems.push(format!(
                "{} trailing bytes: {} bytes, the header gives {expected}",
                self.file_len - expected,
                self.file_len
            ));
        }
        if let SignatureCheck::Invalid(error) = &self.signature {
            if !matches!(
                error,
                ImageError::Truncated { .. } | ImageError::TrailingData { .. }
            ) {
                problems.push(error.to_string());
            }
        }
        problems
    }
}

/// Inspects the images in `bytes` (one, or a release's two one after the other); checks
/// their signatures when `public_key` is given. `Err` when the first header does not
/// parse. A file that is not a well-formed set is inspected as one image, so its length
/// problems are reported against the first header.
pub fn inspect(
    bytes: &[u8],
    public_key: Option<&[u8; PUBLIC_KEY_LEN]>,
) -> Result<Vec<Inspection>, ImageError> {
    match ImageSet::parse(bytes) {
        Ok(set) => set
            .iter()
            .map(|(image, _)| inspect_one(image, public_key))
            .collect(),
        Err(_) => Ok(vec![inspect_one(bytes, public_key)?]),
    }
}

fn inspect_one(
    bytes: &[u8],
    public_key: Option<&[u8; PUBLIC_KEY_LEN]>,
) -> Result<Inspection, ImageError> {
    let header = ImageHeader::parse(bytes)?;
    let signature = match public_key {
        None => SignatureCheck::NotChecked,
        Some(key) => match verify(bytes, key) {
            Ok(_) => SignatureCheck::Valid,
            Err(error) => SignatureCheck::Invalid(error),
        },
    };
    Ok(Inspection {
        header,
        file_len: bytes.len() as u64,
        signature,
        public_key: public_key.copied(),
    })
}

/// Reads and inspects an image file.
pub fn inspect_file(path: &Path, key: Option<&Path>) -> Result<Vec<Inspection>, ImageToolError> {
    let public_key = key.map(read_public_key).transpose()?;
    let bytes = read_file(path, "the image")?;
    inspect(&bytes, public_key.as_ref()).map_err(|source| ImageToolError::NotAnImage {
        path: path.to_path_buf(),
        source,
    })
}

impl fmt::Display for Inspection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "{}", self.header)?;
        let header = &self.header;
        write!(
            f,
            "Sizes:          header {HEADER_LEN} + payload {} + signature {SIGNATURE_LEN} = {} bytes; {} bytes in the file",
            header.payload_len,
            header.image_len(),
            self.file_len
        )?;
        if self.file_len == header.image_len() {
            writeln!(f, " (matches)")?;
        } else {
            writeln!(f, " (MISMATCH)")?;
        }
        let linked = match header.slot() {
            Some(slot) => format!("linked for slot {}", slot.letter()),
            None => "linked for NEITHER slot (A 0x08020200, B 0x08040200)".to_string(),
        };
        if header.image_len() <= u64::from(SLOT_LEN) {
            writeln!(
                f,
                "Slot:           {linked}; fits an F446RE slot ({} of {SLOT_LEN} bytes)",
                header.image_len()
            )?;
        } else {
            writeln!(
                f,
                "Slot:           {linked}; TOO LARGE for an F446RE slot ({} of {SLOT_LEN} bytes)",
                header.image_len()
            )?;
        }
        if let Some(node) = Node::ALL
            .iter()
            .find(|n| n.diag_node_number() == Some(header.node))
        {
            writeln!(f, "Target:         {}", ecu_label(*node))?;
        }
        let key = self.public_key.map(|k| {
            k.iter()
                .take(8)
                .map(|b| format!("{b:02x}"))
                .collect::<String>()
        });
        match (&self.signature, key) {
            (SignatureCheck::NotChecked, _) | (_, None) => {
                write!(f, "Signature:      not checked (give --key FILE.pub)")
            }
            (SignatureCheck::Valid, Some(key)) => {
                write!(f, "Signature:      valid (public key {key}...)")
            }
            (SignatureCheck::Invalid(error), Some(key)) => {
                write!(
                    f,
                    "Signature:      INVALID under public key {key}...: {error}"
                )
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoplug_image::elf::minimal_elf;

    #[test]
    fn key_file_names() {
        let expect = |out: &str, secret: &str, public: &str| {
            assert_eq!(
                key_paths(Path::new(out)),
                KeyPaths {
                    secret: secret.into(),
                    public: public.into()
                }
            );
        };
        expect("keys/dev", "keys/dev.key", "keys/dev.pub");
        expect("keys/dev.key", "keys/dev.key", "keys/dev.pub");
        expect("keys/dev.pub", "keys/dev.key", "keys/dev.pub");
        expect("keys/dev.v2", "keys/dev.v2.key", "keys/dev.v2.pub");
    }

    #[test]
    fn build_ids() {
        assert_eq!(
            parse_build_id("00112233445566778899aabbccddeeff"),
            Ok([
                0x00, 0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77, 0x88, 0x99, 0xAA, 0xBB, 0xCC, 0xDD,
                0xEE, 0xFF
            ])
        );
        assert!(parse_build_id("0011")
            .unwrap_err()
            .contains("4 hex digits, expected 32"));
        assert!(parse_build_id("zz112233445566778899aabbccddeeff")
            .unwrap_err()
            .contains("'z' at position 1"));
        let a = default_build_id(b"payload");
        assert_eq!(a, default_build_id(b"payload"));
        assert_ne!(a, default_build_id(b"payloae"));
        // SHA-256("abc") starts ba7816bf 8f01cfea 414140de 5dae2223.
        assert_eq!(
            default_build_id(b"abc"),
            [
                0xba, 0x78, 0x16, 0xbf, 0x8f, 0x01, 0xcf, 0xea, 0x41, 0x41, 0x40, 0xde, 0x5d, 0xae,
                0x22, 0x23
            ]
        );
    }

    #[test]
    fn elf_segments_are_laid_out_from_the_load_address() {
        let load = ImageSlot::A.vector_table();
        let file = minimal_elf(&[(load, &[1, 2, 3, 4]), (load + 8, &[9, 9])], elf::EM_ARM);
        let (payload, kind) = extract_payload(&file, load, MAX_PAYLOAD_LEN).unwrap();
        assert_eq!(payload, [1, 2, 3, 4, 0xFF, 0xFF, 0xFF, 0xFF, 9, 9]);
        assert_eq!(kind, PayloadKind::Elf { segments: 2 });
    }

    #[test]
    fn elf_segments_outside_the_slot_are_refused() {
        let load = ImageSlot::A.vector_table();
        let bootloader = minimal_elf(&[(0x0800_0000, &[1, 2, 3, 4])], elf::EM_ARM);
        let error = extract_payload(&bootloader, load, MAX_PAYLOAD_LEN).unwrap_err();
        assert!(
            error.contains("0x08000000..0x08000004 lies outside the slot"),
            "{error}"
        );
        let past_end = minimal_elf(
            &[
                (load, &[0; 4]),
                (load + MAX_PAYLOAD_LEN as u32 - 2, &[0; 4]),
            ],
            elf::EM_ARM,
        );
        let error = extract_payload(&past_end, load, MAX_PAYLOAD_LEN).unwrap_err();
        assert!(error.contains("outside the slot"), "{error}");
        let late_start = minimal_elf(&[(load + 0x100, &[0; 4])], elf::EM_ARM);
        let error = extract_payload(&late_start, load, MAX_PAYLOAD_LEN).unwrap_err();
        assert!(error.contains("not at the load address"), "{error}");
        let overlapping = minimal_elf(&[(load, &[0; 8]), (load + 4, &[0; 8])], elf::EM_ARM);
        let error = extract_payload(&overlapping, load, MAX_PAYLOAD_LEN).unwrap_err();
        assert!(error.contains("overlap"), "{error}");
        let x86 = minimal_elf(&[(load, &[0; 4])], elf::EM_386);
        let error = extract_payload(&x86, load, MAX_PAYLOAD_LEN).unwrap_err();
        assert!(error.contains("not firmware for the STM32F446"), "{error}");
        let error =
            extract_payload(&[0x7F, b'E', b'L', b'F', 2], load, MAX_PAYLOAD_LEN).unwrap_err();
        assert!(error.contains("64-bit"), "{error}");
        let error = extract_payload(&bootloader[..20], load, MAX_PAYLOAD_LEN).unwrap_err();
        assert!(error.contains("not a readable ELF file"), "{error}");
    }

    #[test]
    fn raw_payloads_must_fit_the_slot() {
        let load = ImageSlot::A.vector_table();
        let (payload, kind) = extract_payload(&[1, 2, 3], load, MAX_PAYLOAD_LEN).unwrap();
        assert_eq!(
            (payload.as_slice(), kind),
            (&[1u8, 2, 3][..], PayloadKind::Raw)
        );
        let error =
            extract_payload(&vec![0; MAX_PAYLOAD_LEN + 1], load, MAX_PAYLOAD_LEN).unwrap_err();
        assert!(error.contains("do not fit the slot"), "{error}");
        assert!(extract_payload(&[], load, MAX_PAYLOAD_LEN)
            .unwrap_err()
            .contains("empty"));
        assert_eq!(MAX_PAYLOAD_LEN, 128 * 1024 - 576);
    }

    #[test]
    fn the_slot_of_a_payload_is_where_its_elf_is_linked() {
        let a = minimal_elf(&[(ImageSlot::A.vector_table(), &[0; 8])], elf::EM_ARM);
        let b = minimal_elf(&[(ImageSlot::B.vector_table(), &[0; 8])], elf::EM_ARM);
        assert_eq!(payload_slot(&a, None), Ok(ImageSlot::A));
        assert_eq!(payload_slot(&b, None), Ok(ImageSlot::B));
        assert_eq!(payload_slot(&b, Some(ImageSlot::B)), Ok(ImageSlot::B));
        let error = payload_slot(&b, Some(ImageSlot::A)).unwrap_err();
        assert!(error.contains("linked for slot B"), "{error}");
        let elsewhere = minimal_elf(&[(0x0801_0000, &[0; 8])], elf::EM_ARM);
        let error = payload_slot(&elsewhere, None).unwrap_err();
        assert!(error.contains("not for slot A"), "{error}");
        assert_eq!(payload_slot(&[1, 2, 3], None), Ok(ImageSlot::A));
        assert_eq!(
            payload_slot(&[1, 2, 3], Some(ImageSlot::B)),
            Ok(ImageSlot::B)
        );
    }
}
