//! The bytes behind an MDF data link, read as one stream in bounded memory: a data block
//! (`##DT`, `##SD`), a zlib block (`##DZ`, deflate or transposed deflate) or a list of
//! them (`##DL`, and `##HL` over a DL chain), whichever the writer chose.
//!
//! A plain data block is read a piece at a time ([`PIECE`]); a DZ block is inflated whole
//! (writers split data into DZ blocks of a few MiB; one declaring more than [`MAX_DZ`] is
//! refused before anything of its size is allocated). Damage (a block past the file's end,
//! a DZ that does not inflate to its declared length) ends the stream with an error naming
//! the block and its offset; every byte before it is delivered first.

use std::io::{Read, Seek};

use flate2::read::ZlibDecoder;

use super::blocks::{error, BlockError, BlockHeader, MdfBlocks};

/// How much of a plain data block is read at a time.
pub const PIECE: usize = 1 << 20;
/// The most a DZ block may inflate to here (writers use a few MiB: asammdf 4 MiB).
pub const MAX_DZ: u64 = 64 << 20;

/// Where a stream's blocks are, and what they must be.
#[derive(Clone, Debug)]
pub struct DataLink {
    /// The leaf blocks (DT, SD, DZ...), in order.
    pub blocks: Vec<u64>,
    /// The plain block type the data is (`DT` for records, `SD` for signal data); a DZ
    /// must say it holds this.
    pub kind: [u8; 2],
    /// A logger that lost power did not write the last block's length: it runs to the
    /// file's end (`UnFinMF`, flag 0x4, for the block found last in the file).
    pub open_ended: Option<u64>,
}

impl DataLink {
    /// The leaf blocks behind the link at `at` (0: none), expected of type `kind` (or
    /// DZ holding it).
    pub fn resolve<R: Read + Seek>(
        file: &mut MdfBlocks<R>,
        at: u64,
        kind: [u8; 2],
    ) -> Result<Self, BlockError> {
        let mut blocks = Vec::new();
        if at != 0 {
            let header = file.header(at, &[&kind, b"DZ", b"DL", b"HL"])?;
            match &header.id {
                b"DL" => dl_chain(file, at, &mut blocks)?,
                b"HL" => {
                    let hl = file.block(at, &[b"HL"])?;
                    dl_chain(file, hl.link(0), &mut blocks)?;
                }
                _ => blocks.push(at),
            }
        }
        Ok(Self {
            blocks,
            kind,
            open_ended: None,
        })
    }
}

/// The data blocks a chain of DL blocks lists.
fn dl_chain<R: Read + Seek>(
    file: &mut MdfBlocks<R>,
    first: u64,
    out: &mut Vec<u64>,
) -> Result<(), BlockError> {
    for dl in file.chain(first, 0, b"DL")? {
        let count = dl
            .data
            .get(4..8)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
            .ok_or_else(|| {
                error(
                    Some("##DL".into()),
                    dl.header.at,
                    "its data are too short for a block count",
                )
            })?;
        let listed = dl.links.len().saturating_sub(1);
        if count > listed {
            return Err(error(
                Some("##DL".into()),
                dl.header.at,
                format!("lists {count} data blocks but has links for {listed}"),
            ));
        }
        out.extend(dl.links[1..1 + count].iter().filter(|&&l| l != 0));
    }
    Ok(())
}

/// A plain block being read piece by piece: where its next bytes are, how many are left.
struct Plain {
    at: u64,
    left: u64,
    /// The error to give when it is done: it declared more than the file holds.
    cut: Option<BlockError>,
}

/// `buf` at least `len` long: zeroed only where it grows.
fn make_room(buf: &mut Vec<u8>, len: usize) {
    if buf.len() < len {
        buf.resize(len, 0);
    }
}

/// The stream of one [`DataLink`]'s bytes.
pub struct DataStream {
    link: DataLink,
    next: usize,
    plain: Option<Plain>,
    /// The bytes loaded are `buf[pos..end]`; the rest of `buf` is room, kept initialized
    /// from one load to the next: zeroing a megabyte piece before reading into it was a
    /// tenth of reading a file (callgrind), and is done only as the buffer grows.
    buf: Vec<u8>,
    pos: usize,
    end: usize,
    /// Bytes taken so far: the stream offset of `buf[pos]`.
    taken: u64,
    damage: Option<BlockError>,
    done: bool,
}

impl DataStream {
    /// A stream over `link`'s blocks, none read yet.
    pub fn new(link: DataLink) -> Self {
        Self {
            link,
            next: 0,
            plain: None,
            buf: Vec::new(),
            pos: 0,
            end: 0,
            taken: 0,
            damage: None,
            done: false,
        }
    }

    /// The stream offset of the next byte [`take`](Self::take) gives.
    pub fn offset(&self) -> u64 {
        self.taken
    }

    /// The next `n` bytes, `Ok(None)` at the end of the data (what is left, if anything,
    /// is less than `n`: see [`leftover`](Self::leftover)), or the damage that ended it.
    pub fn take<R: Read + Seek>(
        &mut self,
        file: &mut MdfBlocks<R>,
        n: usize,
    ) -> Result<Option<&[u8]>, BlockError> {
        while self.end - self.pos < n {
            if !self.load(file)? {
                return match self.damage.take() {
                    Some(e) => Err(e),
                    None => Ok(None),
                };
            }
        }
        let at = self.pos;
        self.pos += n;
        self.taken += n as u64;
        Ok(Some(&self.buf[at..at + n]))
    }

    /// The last `n` bytes taken (at most what the last `take` gave), and up to 8 bytes
    /// that follow them if the buffer has them: a field is read as the word it starts.
    pub fn last_taken(&self, n: usize) -> &[u8] {
        let start = self.pos.saturating_sub(n);
        &self.buf[start..(self.pos + 8).min(self.end)]
    }

    /// The bytes loaded and not yet taken: a reader may look at several records here
    /// at once and then [`consume`](Self::consume) them.
    pub fn buffered(&self) -> &[u8] {
        &self.buf[self.pos..self.end]
    }

    /// Takes the first `n` of the [`buffered`](Self::buffered) bytes (at most all of them).
    pub fn consume(&mut self, n: usize) {
        let n = n.min(self.end - self.pos);
        self.pos += n;
        self.taken += n as u64;
    }

    /// Passes over `n` bytes; `false` if the data end first.
    pub fn skip<R: Read + Seek>(
        &mut self,
        file: &mut MdfBlocks<R>,
        mut n: u64,
    ) -> Result<bool, BlockError> {
        while n > 0 {
            let step = n.min(PIECE as u64) as usize;
            if self.take(file, step)?.is_none() {
                return Ok(false);
            }
            n -= step as u64;
        }
        Ok(true)
    }

    /// Bytes left over at the end that did not make a whole `take`.
    pub fn leftover(&self) -> usize {
        self.end - self.pos
    }

    /// Appends more data to the buffer; `false` when there is none (or damage was found:
    /// kept in `damage`, given once the bytes before it are taken).
    fn load<R: Read + Seek>(&mut self, file: &mut MdfBlocks<R>) -> Result<bool, BlockError> {
        if self.done {
            return Ok(false);
        }
        // Keep the unread bytes only.
        if self.pos > 0 {
            self.buf.copy_within(self.pos..self.end, 0);
            self.end -= self.pos;
            self.pos = 0;
        }
        loop {
            if let Some(plain) = &mut self.plain {
                if plain.left > 0 {
                    let n = plain.left.min(PIECE as u64) as usize;
                    let start = self.end;
                    make_room(&mut self.buf, start + n);
                    let got = file
                        .read_at(plain.at, &mut self.buf[start..start + n])
                        .map_err(|e| {
                            error(Some(format!("##{}", kind(&self.link.kind))), plain.at, e)
                        })?;
                    self.end = start + got;
                    plain.at += got as u64;
                    plain.left -= got as u64;
                    if got < n {
                        // The file changed under us (it was measured at open).
                        plain.left = 0;
                    }
                    if got > 0 {
                        return Ok(true);
                    }
                }
                let cut = self.plain.take().and_then(|p| p.cut);
                if let Some(cut) = cut {
                    self.damage = Some(cut);
                    self.done = true;
                    return Ok(false);
                }
            }
            let Some(&at) = self.link.blocks.get(self.next) else {
                self.done = true;
                return Ok(false);
            };
            self.next += 1;
            match self.open_block(file, at) {
                Ok(Some(bytes)) => {
                    let start = self.end;
                    make_room(&mut self.buf, start + bytes.len());
                    self.buf[start..start + bytes.len()].copy_from_slice(&bytes);
                    self.end = start + bytes.len();
                    return Ok(true);
                }
                Ok(None) => {}
                Err(e) => {
                    self.damage = Some(e);
                    self.done = true;
                    return Ok(false);
                }
            }
        }
    }

    /// Starts the block at `at`: a plain one is set to be read piece by piece (`None`), a
    /// DZ one is inflated whole.
    fn open_block<R: Read + Seek>(
        &mut self,
        file: &mut MdfBlocks<R>,
        at: u64,
    ) -> Result<Option<Vec<u8>>, BlockError> {
        let header = file.header(at, &[&self.link.kind, b"DZ"])?;
        if header.id == *b"DZ" {
            return inflate(file, &header, self.link.kind).map(Some);
        }
        let len = file.len();
        let start = header.data_at();
        let declared_end = header.at.saturating_add(header.length);
        let (end, cut) = if self.link.open_ended == Some(at) {
            (len, None)
        } else if declared_end > len {
            (
                len,
                Some(error(
                    Some(header.name()),
                    at,
                    format!(
                        "the block is {} bytes long, and the file ends {} bytes after its start (truncated file?)",
                        header.length,
                        len - at
                    ),
                )),
            )
        } else {
            (declared_end, None)
        };
        self.plain = Some(Plain {
            at: start,
            left: end.saturating_sub(start),
            cut,
        });
        Ok(None)
    }
}

fn kind(k: &[u8; 2]) -> String {
    String::from_utf8_lossy(k).into_owned()
}

/// A DZ block's data, inflated (and transposed back), checked against what it declares.
fn inflate<R: Read + Seek>(
    file: &mut MdfBlocks<R>,
    header: &BlockHeader,
    expected: [u8; 2],
) -> Result<Vec<u8>, BlockError> {
    let name = Some(header.name());
    let at = header.at;
    let fail = |message: String| error(name.clone(), at, message);
    // original type [2], zip type u8, reserved u8, zip parameter u32, original length u64,
    // compressed length u64, then the compressed bytes.
    let data_len = header.data_len();
    if data_len < 24 {
        return Err(fail(format!(
            "{data_len} bytes of data: a DZ block has at least 24"
        )));
    }
    if at.saturating_add(header.length) > file.len() {
        return Err(fail(format!(
            "the block is {} bytes long, and the file ends {} bytes after its start (truncated file?)",
            header.length,
            file.len() - at
        )));
    }
    let mut head = [0u8; 24];
    let got = file.read_at(header.data_at(), &mut head).map_err(&fail)?;
    if got < head.len() {
        return Err(fail(
            "the file ends inside the block (truncated file?)".into(),
        ));
    }
    let original = [head[0], head[1]];
    let zip_type = head[2];
    let parameter = u32::from_le_bytes([head[4], head[5], head[6], head[7]]);
    let original_len = u64::from_le_bytes(head[8..16].try_into().unwrap_or_default());
    let compressed_len = u64::from_le_bytes(head[16..24].try_into().unwrap_or_default());
    if original != expected {
        return Err(fail(format!(
            "holds a ##{} block where a ##{} was expected",
            kind(&original),
            kind(&expected)
        )));
    }
    if compressed_len > data_len - 24 {
        return Err(fail(format!(
            "declares {compressed_len} compressed bytes, and the block holds {}",
            data_len - 24
        )));
    }
    if original_len > MAX_DZ {
        return Err(fail(format!(
            "inflates to {original_len} bytes, more than the {MAX_DZ} AutoPlug takes from one block"
        )));
    }
    if zip_type > 1 {
        return Err(fail(format!(
            "compression type {zip_type}: only deflate (0) and transposed deflate (1) exist in MDF 4.1"
        )));
    }
    let mut compressed = vec![0u8; compressed_len as usize];
    let got = file
        .read_at(header.data_at() + 24, &mut compressed)
        .map_err(&fail)?;
    if got < compressed.len() {
        return Err(fail(
            "the file ends inside the block (truncated file?)".into(),
        ));
    }
    // Grown as it inflates: a corrupt length allocates nothing up front.
    let mut out = Vec::with_capacity((original_len as usize).min(4 * compressed.len() + 4096));
    ZlibDecoder::new(&compressed[..])
        .take(original_len + 1)
        .read_to_end(&mut out)
        .map_err(|e| fail(format!("its data do not inflate: {e}")))?;
    if out.len() as u64 > original_len {
        return Err(fail(format!(
            "inflates to more than the {original_len} bytes it declares"
        )));
    }
    if (out.len() as u64) < original_len {
        return Err(fail(format!(
            "inflates to {} bytes, and declares {original_len}",
            out.len()
        )));
    }
    if zip_type == 1 {
        let columns = parameter as usize;
        if columns == 0 {
            return Err(fail("transposed with 0 columns".into()));
        }
        out = super::transpose::rows_from_columns(&out, columns);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{Cursor, Write};

    fn id_block() -> Vec<u8> {
        let mut b = vec![0u8; 64];
        b[..8].copy_from_slice(b"MDF     ");
        b[28..30].copy_from_slice(&410u16.to_le_bytes());
        b
    }

    fn push(file: &mut Vec<u8>, id: &[u8; 2], links: &[u64], data: &[u8]) -> u64 {
        let at = file.len() as u64;
        file.extend_from_slice(b"##");
        file.extend_from_slice(id);
        file.extend_from_slice(&[0; 4]);
        file.extend_from_slice(&((24 + 8 * links.len() + data.len()) as u64).to_le_bytes());
        file.extend_from_slice(&(links.len() as u64).to_le_bytes());
        for l in links {
            file.extend_from_slice(&l.to_le_bytes());
        }
        file.extend_from_slice(data);
        at
    }

    fn dz(original: &[u8], transposed_columns: Option<u32>) -> Vec<u8> {
        let mut input = original.to_vec();
        if let Some(cols) = transposed_columns {
            let cols = cols as usize;
            let rows = input.len() / cols;
            for r in 0..rows {
                for c in 0..cols {
                    input[c * rows + r] = original[r * cols + c];
                }
            }
        }
        let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        e.write_all(&input).unwrap();
        let compressed = e.finish().unwrap();
        let mut data = b"DT".to_vec();
        data.push(u8::from(transposed_columns.is_some()));
        data.push(0);
        data.extend_from_slice(&transposed_columns.unwrap_or(0).to_le_bytes());
        data.extend_from_slice(&(original.len() as u64).to_le_bytes());
        data.extend_from_slice(&(compressed.len() as u64).to_le_bytes());
        data.extend_from_slice(&compressed);
        data
    }

    fn all(file: Vec<u8>, at: u64, n: usize) -> (Vec<u8>, Option<BlockError>) {
        let (mut blocks, _) = MdfBlocks::open(Cursor::new(file)).unwrap();
        let link = DataLink::resolve(&mut blocks, at, *b"DT").unwrap();
        let mut stream = DataStream::new(link);
        let mut out = Vec::new();
        loop {
            match stream.take(&mut blocks, n) {
                Ok(Some(bytes)) => out.extend_from_slice(bytes),
                Ok(None) => return (out, None),
                Err(e) => return (out, Some(e)),
            }
        }
    }

    #[test]
    fn plain_zipped_transposed_and_listed_blocks_make_one_stream() {
        let records: Vec<u8> = (0..=255u8).cycle().take(7 * 300).collect();
        let mut file = id_block();
        let a = push(&mut file, b"DT", &[], &records[..700]);
        let b = push(&mut file, b"DZ", &[], &dz(&records[700..1400], None));
        // 700 bytes as 7 columns: 100 rows; a ragged tail stays as it is.
        let c = push(&mut file, b"DZ", &[], &dz(&records[1400..2100], Some(7)));
        let mut dl = vec![0u8; 8];
        dl[4..8].copy_from_slice(&3u32.to_le_bytes());
        let list = push(&mut file, b"DL", &[0, a, b, c], &dl);
        for n in [1, 7, 1000, 5000] {
            let (got, damage) = all(file.clone(), list, n);
            assert!(damage.is_none());
            assert_eq!(got, records[..records.len() / n * n], "{n}");
        }
        let ragged = push(&mut file, b"DZ", &[], &dz(&records[..701], Some(7)));
        assert_eq!(all(file.clone(), ragged, 1).0, records[..701]);
        let hl = push(&mut file, b"HL", &[list], &[1, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(all(file, hl, 7).0, records);
    }

    #[test]
    fn room_kept_from_a_larger_load_is_never_given_out() {
        // A large block, then a small one: after the first is taken, the buffer keeps its
        // room (stale bytes) past what the second load put there.
        let records: Vec<u8> = (0..=250u8).cycle().take(3005).collect();
        let mut file = id_block();
        let a = push(&mut file, b"DZ", &[], &dz(&records[..3000], None));
        let b = push(&mut file, b"DT", &[], &records[3000..]);
        let mut dl = vec![0u8; 8];
        dl[4..8].copy_from_slice(&2u32.to_le_bytes());
        let list = push(&mut file, b"DL", &[0, a, b], &dl);
        let (mut blocks, _) = MdfBlocks::open(Cursor::new(file)).unwrap();
        let link = DataLink::resolve(&mut blocks, list, *b"DT").unwrap();
        let mut stream = DataStream::new(link);
        let mut got = Vec::new();
        while let Some(bytes) = stream.take(&mut blocks, 7).unwrap() {
            got.extend_from_slice(bytes);
            // The record and what follows it, all of it loaded data.
            let seen = stream.last_taken(7);
            assert!((7..=15).contains(&seen.len()), "{}", seen.len());
            assert_eq!(seen, &records[got.len() - 7..got.len() - 7 + seen.len()]);
        }
        assert_eq!(got, records[..3003]);
        assert_eq!(stream.leftover(), 2);
        assert_eq!(stream.buffered(), &records[3003..]);
    }

    #[test]
    fn damage_comes_after_the_bytes_before_it_and_names_the_block() {
        let mut file = id_block();
        let a = push(&mut file, b"DT", &[], &[1; 100]);
        let mut bad = dz(&[2; 100], None);
        let n = bad.len();
        bad[n - 3] ^= 0xFF;
        let b = push(&mut file, b"DZ", &[], &bad);
        let mut dl = vec![0u8; 8];
        dl[4..8].copy_from_slice(&2u32.to_le_bytes());
        let list = push(&mut file, b"DL", &[0, a, b], &dl);
        let (got, damage) = all(file.clone(), list, 10);
        assert_eq!(got, [1; 100]);
        let e = damage.unwrap().to_string();
        assert!(e.starts_with(&format!("##DZ block at byte {b}: ")), "{e}");

        // A plain block cut short by the file's end: what is there, then the error.
        let mut cut = id_block();
        let t = push(&mut cut, b"DT", &[], &[3; 100]);
        cut.truncate(cut.len() - 40);
        let (got, damage) = all(cut, t, 10);
        assert_eq!(got, [3; 60]);
        assert!(damage.unwrap().to_string().contains("truncated file?"));

        // A DZ that claims more compressed bytes than it holds, or inflates to another
        // length, or holds another block type.
        let mut file = id_block();
        let mut long = dz(&[4; 50], None);
        long[16..24].copy_from_slice(&9999u64.to_le_bytes());
        let at = push(&mut file, b"DZ", &[], &long);
        assert!(all(file.clone(), at, 1)
            .1
            .unwrap()
            .to_string()
            .contains("declares 9999 compressed bytes"));
        let mut short = dz(&[4; 50], None);
        short[8..16].copy_from_slice(&60u64.to_le_bytes());
        let at = push(&mut file, b"DZ", &[], &short);
        assert!(all(file.clone(), at, 1)
            .1
            .unwrap()
            .to_string()
            .contains("inflates to 50 bytes, and declares 60"));
        let mut sd = dz(&[4; 50], None);
        sd[..2].copy_from_slice(b"SD");
        let at = push(&mut file, b"DZ", &[], &sd);
        assert!(all(file, at, 1)
            .1
            .unwrap()
            .to_string()
            .contains("holds a ##SD block where a ##DT"));
    }

    #[test]
    fn a_list_longer_than_its_links_is_refused() {
        let mut file = id_block();
        let a = push(&mut file, b"DT", &[], &[1; 10]);
        let mut dl = vec![0u8; 8];
        dl[4..8].copy_from_slice(&5u32.to_le_bytes());
        let list = push(&mut file, b"DL", &[0, a], &dl);
        let (mut blocks, _) = MdfBlocks::open(Cursor::new(file)).unwrap();
        let e = DataLink::resolve(&mut blocks, list, *b"DT").unwrap_err();
        assert_eq!(
            e.to_string(),
            format!("##DL block at byte {list}: lists 5 data blocks but has links for 1")
        );
    }
}
