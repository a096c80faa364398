//! ASAM MDF 4's blocks: the file's identification, and any block by its link, read with
//! every size and link checked against the file before it is trusted.
//!
//! Layout (MDF 4.1/4.2, little-endian): a 64-byte identification block at byte 0 (`MDF     `,
//! or `UnFinMF ` for a file a logger did not finalize, the version as text and number, the
//! unfinalized flags), then blocks anywhere in the file, each `##XX`, 4 reserved bytes, its
//! length (u64, header included), its link count (u64), the links (u64 file offsets, 0 for
//! none), then its data. Every error names the block and its offset.

use std::fmt;
use std::io::{self, Read, Seek, SeekFrom};

/// The identification block's size.
pub const ID_BLOCK: u64 = 64;
/// A block header's size: id, reserved, length, link count.
pub const BLOCK_HEADER: u64 = 24;
/// The most links a block may have here (a DL block lists its data blocks: 1 Mi of them is
/// far beyond any writer's).
const MAX_LINKS: u64 = 1 << 20;
/// The most data a metadata block may carry here (a comment, a channel's definition): a
/// bigger length is corruption, refused before anything of its size is allocated. Data
/// blocks (DT, SD, DZ...) are not loaded whole: see [`MdfBlocks::header`].
pub const MAX_METADATA: u64 = 16 * 1024 * 1024;

/// What an MDF file says of itself.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Identification {
    /// The version, e.g. 410 for 4.10.
    pub version: u16,
    /// The program that wrote it, as its 8 bytes say (trimmed).
    pub program: String,
    /// `UnFinMF `: a logger did not finalize it; the standard and custom flags saying
    /// what is left to do (cycle counts, the last data block's length...).
    pub unfinalized: Option<(u16, u16)>,
}

/// A block's header: where it is, what it is, how long, how many links.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BlockHeader {
    /// Its offset in the file.
    pub at: u64,
    /// Its type, without the `##` (`DG`, `CN`, `DT`...).
    pub id: [u8; 2],
    /// Its length, header included.
    pub length: u64,
    /// Its link count.
    pub links: u64,
}

impl BlockHeader {
    /// Where its data start.
    pub fn data_at(&self) -> u64 {
        self.at + BLOCK_HEADER + 8 * self.links
    }

    /// Its data's length.
    pub fn data_len(&self) -> u64 {
        self.length - BLOCK_HEADER - 8 * self.links
    }

    /// Its type as text (`##DG`).
    pub fn name(&self) -> String {
        format!("##{}", String::from_utf8_lossy(&self.id))
    }
}

/// A metadata block, loaded: its links and its data.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Block {
    /// Its header.
    pub header: BlockHeader,
    /// Its links (0: none).
    pub links: Vec<u64>,
    /// Its data.
    pub data: Vec<u8>,
}

impl Block {
    /// Link `i`, 0 (none) when the block has fewer.
    pub fn link(&self, i: usize) -> u64 {
        self.links.get(i).copied().unwrap_or(0)
    }
}

/// Why a file or a block could not be read: the block (when known) and its offset.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BlockError {
    /// The block's type as found or as expected (`##DG`), if any.
    pub block: Option<String>,
    /// Its offset in the file.
    pub at: u64,
    /// What was wrong.
    pub message: String,
}

impl fmt::Display for BlockError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.block {
            Some(block) => write!(f, "{block} block at byte {}: {}", self.at, self.message),
            None => write!(f, "byte {}: {}", self.at, self.message),
        }
    }
}

impl std::error::Error for BlockError {}

pub(crate) fn error(block: Option<String>, at: u64, message: impl Into<String>) -> BlockError {
    BlockError {
        block,
        at,
        message: message.into(),
    }
}

/// The blocks of an MDF file: reads them by their links, checked.
pub struct MdfBlocks<R> {
    input: R,
    len: u64,
}

impl<R: Read + Seek> MdfBlocks<R> {
    /// Reads the identification block of `input`.
    pub fn open(mut input: R) -> Result<(Self, Identification), BlockError> {
        let len = input
            .seek(SeekFrom::End(0))
            .map_err(|e| error(None, 0, format!("cannot read the file: {e}")))?;
        let mut blocks = Self { input, len };
        let mut id = [0u8; ID_BLOCK as usize];
        let got = blocks.read_at(0, &mut id).map_err(|e| error(None, 0, e))?;
        let unfinalized = match &id[..got.min(8)] {
            b"MDF     " => false,
            b"UnFinMF " => true,
            start => {
                return Err(error(
                    None,
                    0,
                    format!(
                        "not an MDF file: it starts with {:?} instead of \"MDF     \"",
                        String::from_utf8_lossy(start)
                    ),
                ))
            }
        };
        if got < ID_BLOCK as usize {
            return Err(error(
                None,
                0,
                format!(
                    "the identification block is cut short: {got} of 64 bytes (truncated file?)"
                ),
            ));
        }
        let version = u16::from_le_bytes([id[28], id[29]]);
        if !(400..500).contains(&version) {
            return Err(error(
                None,
                28,
                format!("MDF version {version}: only MDF 4 (400-499) is read"),
            ));
        }
        let program = String::from_utf8_lossy(&id[16..24]).trim_end().to_string();
        let flags = (
            u16::from_le_bytes([id[60], id[61]]),
            u16::from_le_bytes([id[62], id[63]]),
        );
        Ok((
            blocks,
            Identification {
                version,
                program,
                unfinalized: unfinalized.then_some(flags),
            },
        ))
    }

    /// The file's length.
    pub fn len(&self) -> u64 {
        self.len
    }

    /// Whether the file is empty (never, once opened).
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Reads as much of `buf` as the file has from `at`; the count read.
    pub(crate) fn read_at(&mut self, at: u64, buf: &mut [u8]) -> Result<usize, String> {
        self.input
            .seek(SeekFrom::Start(at))
            .map_err(|e| format!("cannot read the file: {e}"))?;
        let mut done = 0;
        while done < buf.len() {
            match self.input.read(&mut buf[done..]) {
                Ok(0) => break,
                Ok(n) => done += n,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(format!("cannot read the file: {e}")),
            }
        }
        Ok(done)
    }

    /// The header of the block at `at`, one of `expected` types (any when empty),
    /// checked: inside the file, its links and length possible.
    pub fn header(&mut self, at: u64, expected: &[&[u8; 2]]) -> Result<BlockHeader, BlockError> {
        let named = |id: Option<[u8; 2]>| {
            id.map(|id| format!("##{}", String::from_utf8_lossy(&id)))
                .or_else(|| {
                    expected
                        .first()
                        .map(|e| format!("##{}", String::from_utf8_lossy(*e)))
                })
        };
        if at < ID_BLOCK || at >= self.len {
            return Err(error(
                named(None),
                at,
                format!("a link to byte {at}, outside the file's {} bytes", self.len),
            ));
        }
        if at.saturating_add(BLOCK_HEADER) > self.len {
            return Err(error(
                named(None),
                at,
                format!(
                    "a link to byte {at}: the file's {} bytes end before a block header there (truncated file?)",
                    self.len
                ),
            ));
        }
        let mut head = [0u8; BLOCK_HEADER as usize];
        let got = self
            .read_at(at, &mut head)
            .map_err(|e| error(named(None), at, e))?;
        if got < head.len() {
            return Err(error(
                named(None),
                at,
                "the file ends inside the block header (truncated file?)",
            ));
        }
        if &head[..2] != b"##" {
            return Err(error(
                named(None),
                at,
                format!(
                    "expected a block (\"##\"), found {:?}: a link into the middle of something, or a corrupt file",
                    String::from_utf8_lossy(&head[..4])
                ),
            ));
        }
        let id = [head[2], head[3]];
        if !expected.is_empty() && !expected.contains(&&id) {
            let wanted: Vec<String> = expected
                .iter()
                .map(|e| format!("##{}", String::from_utf8_lossy(*e)))
                .collect();
            return Err(error(
                named(Some(id)),
                at,
                format!("a {} was expected here", wanted.join(" or ")),
            ));
        }
        let length = u64::from_le_bytes(head[8..16].try_into().unwrap_or_default());
        let links = u64::from_le_bytes(head[16..24].try_into().unwrap_or_default());
        let header = BlockHeader {
            at,
            id,
            length,
            links,
        };
        if links > MAX_LINKS || length < BLOCK_HEADER + 8 * links {
            return Err(error(
                named(Some(id)),
                at,
                format!("{links} links in a block of {length} bytes is not possible: corrupt file"),
            ));
        }
        Ok(header)
    }

    /// The metadata block at `at` (one of `expected` types), loaded: its links and data,
    /// which must lie inside the file and be at most [`MAX_METADATA`] long.
    pub fn block(&mut self, at: u64, expected: &[&[u8; 2]]) -> Result<Block, BlockError> {
        let header = self.header(at, expected)?;
        let name = Some(header.name());
        if header.data_len() > MAX_METADATA {
            return Err(error(
                name,
                at,
                format!(
                    "{} bytes of data is beyond any block of its kind: corrupt file",
                    header.data_len()
                ),
            ));
        }
        if at.saturating_add(header.length) > self.len {
            return Err(error(
                name,
                at,
                format!(
                    "the block is {} bytes long, and the file ends {} bytes after its start (truncated file?)",
                    header.length,
                    self.len - at
                ),
            ));
        }
        let mut rest = vec![0u8; (header.length - BLOCK_HEADER) as usize];
        let got = self
            .read_at(at + BLOCK_HEADER, &mut rest)
            .map_err(|e| error(name.clone(), at, e))?;
        if got < rest.len() {
            return Err(error(
                name,
                at,
                "the file ends inside the block (truncated file?)",
            ));
        }
        let split = 8 * header.links as usize;
        let links = rest[..split]
            .chunks_exact(8)
            .map(|c| u64::from_le_bytes(c.try_into().unwrap_or_default()))
            .collect();
        let data = rest.split_off(split);
        Ok(Block {
            header,
            links,
            data,
        })
    }

    /// The blocks of a chain (each's link `next` to the following one) from `first`, all of
    /// the `expected` type; a chain that comes back to a block it passed is an error, not
    /// a loop.
    pub fn chain(
        &mut self,
        first: u64,
        next: usize,
        expected: &[u8; 2],
    ) -> Result<Vec<Block>, BlockError> {
        let mut blocks: Vec<Block> = Vec::new();
        let mut seen = std::collections::HashSet::new();
        let mut at = first;
        while at != 0 {
            if !seen.insert(at) {
                return Err(error(
                    Some(format!("##{}", String::from_utf8_lossy(expected))),
                    at,
                    "the chain of blocks comes back to this one: a loop in the links (corrupt file)",
                ));
            }
            let block = self.block(at, &[expected])?;
            at = block.link(next);
            blocks.push(block);
        }
        Ok(blocks)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    /// An identification block: `MDF     ` (or `UnFinMF `), version 4.10.
    fn id_block(unfinished: bool) -> Vec<u8> {
        let mut b = vec![0u8; 64];
        b[..8].copy_from_slice(if unfinished { b"UnFinMF " } else { b"MDF     " });
        b[8..16].copy_from_slice(b"4.10    ");
        b[16..24].copy_from_slice(b"autoplug");
        b[28..30].copy_from_slice(&410u16.to_le_bytes());
        if unfinished {
            b[60..62].copy_from_slice(&1u16.to_le_bytes());
        }
        b
    }

    /// A block of type `id` with these links and data, at the end of `file`; its offset.
    fn push_block(file: &mut Vec<u8>, id: &[u8; 2], links: &[u64], data: &[u8]) -> u64 {
        let at = file.len() as u64;
        file.extend_from_slice(b"##");
        file.extend_from_slice(id);
        file.extend_from_slice(&[0; 4]);
        let length = 24 + 8 * links.len() + data.len();
        file.extend_from_slice(&(length as u64).to_le_bytes());
        file.extend_from_slice(&(links.len() as u64).to_le_bytes());
        for link in links {
            file.extend_from_slice(&link.to_le_bytes());
        }
        file.extend_from_slice(data);
        while file.len() % 8 != 0 {
            file.push(0);
        }
        at
    }

    #[test]
    fn the_identification_says_version_program_and_unfinished() {
        let (_, id) = MdfBlocks::open(Cursor::new(id_block(false))).unwrap();
        assert_eq!(
            (id.version, id.program.as_str(), id.unfinalized),
            (410, "autoplug", None)
        );
        let (_, id) = MdfBlocks::open(Cursor::new(id_block(true))).unwrap();
        assert_eq!(id.unfinalized, Some((1, 0)));
        let error = MdfBlocks::open(Cursor::new(b"LOGG".to_vec()))
            .err()
            .unwrap();
        assert_eq!(
            error.to_string(),
            "byte 0: not an MDF file: it starts with \"LOGG\" instead of \"MDF     \""
        );
        let error = MdfBlocks::open(Cursor::new(id_block(false)[..40].to_vec()))
            .err()
            .unwrap();
        assert!(error.to_string().contains("cut short: 40 of 64"), "{error}");
    }

    #[test]
    fn a_chain_is_read_and_a_loop_in_it_is_an_error() {
        let mut file = id_block(false);
        let second = 64 + 40;
        let first = push_block(&mut file, b"TX", &[second], b"one\0");
        assert_eq!(first, 64);
        assert_eq!(push_block(&mut file, b"TX", &[0], b"two\0"), second);
        let (mut blocks, _) = MdfBlocks::open(Cursor::new(file.clone())).unwrap();
        let chain = blocks.chain(first, 0, b"TX").unwrap();
        assert_eq!(
            chain.iter().map(|b| b.data.clone()).collect::<Vec<_>>(),
            [b"one\0".to_vec(), b"two\0".to_vec()]
        );
        // The second links back to the first.
        file[second as usize + 24..second as usize + 32].copy_from_slice(&first.to_le_bytes());
        let (mut blocks, _) = MdfBlocks::open(Cursor::new(file)).unwrap();
        let error = blocks.chain(first, 0, b"TX").unwrap_err();
        assert_eq!(error.to_string(), "##TX block at byte 64: the chain of blocks comes back to this one: a loop in the links (corrupt file)");
    }

    #[test]
    fn damaged_blocks_are_named_with_their_offset() {
        let mut file = id_block(false);
        let dg = push_block(&mut file, b"DG", &[0, 0, 0, 0], &[0; 8]);
        let (mut blocks, _) = MdfBlocks::open(Cursor::new(file.clone())).unwrap();
        // Outside the file, of another type, cut short, an impossible length.
        let outside = blocks.header(10_000, &[b"CG"]).unwrap_err();
        assert!(
            outside
                .to_string()
                .starts_with("##CG block at byte 10000: a link to byte 10000"),
            "{outside}"
        );
        let other = blocks.block(dg, &[b"CG"]).unwrap_err();
        assert_eq!(
            other.to_string(),
            "##DG block at byte 64: a ##CG was expected here"
        );
        let (mut cut, _) = MdfBlocks::open(Cursor::new(file[..file.len() - 4].to_vec())).unwrap();
        let short = cut.block(dg, &[b"DG"]).unwrap_err();
        assert!(short.to_string().contains("truncated file?"), "{short}");
        let mut bad = file.clone();
        bad[dg as usize + 16..dg as usize + 24].copy_from_slice(&1000u64.to_le_bytes());
        let (mut bad, _) = MdfBlocks::open(Cursor::new(bad)).unwrap();
        let impossible = bad.block(dg, &[b"DG"]).unwrap_err();
        assert!(
            impossible
                .to_string()
                .contains("1000 links in a block of 64 bytes"),
            "{impossible}"
        );
        // Into the middle of a block.
        let middle = blocks.block(dg + 8, &[]).unwrap_err();
        assert!(middle.to_string().contains("expected a block"), "{middle}");
    }
}
