//! Where an MDF 4 file keeps its CAN bus logging, as ASAM's bus-logging standard lays it
//! out: channel groups with a composed channel `CAN_DataFrame` (or `CAN_ErrorFrame`,
//! `CAN_RemoteFrame`) whose members (`BusChannel`, `ID`, `IDE`, `DLC`, `DataLength`,
//! `DataBytes`, `Dir`, `EDL`, `BRS`, `ESI`) each have their place in the group's records.
//!
//! Writers lay these out differently (asammdf and python-can one group per frame type,
//! fixed 64-byte data; Vector's and CSS's loggers one unsorted group with variable-length
//! data bytes in signal data blocks or in a VLSD channel group; member names with or
//! without the `CAN_DataFrame.` prefix), so the members are found by name, never by
//! position, and every place is checked against the record it must fit in before a record
//! is read. Channel groups of anything else (decoded signals, other buses) are passed over.

use std::io::{Read, Seek};

use super::blocks::{error, Block, BlockError, MdfBlocks};
use super::data::DataLink;

/// Which frames a channel group holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameType {
    /// `CAN_DataFrame`.
    Data,
    /// `CAN_RemoteFrame`.
    Remote,
    /// `CAN_ErrorFrame`.
    Error,
}

/// A channel's place in a record.
#[derive(Clone, Debug)]
pub struct Field {
    /// The offset of its CN block (for errors).
    pub cn_at: u64,
    /// Its byte offset in the record (after the record id).
    pub byte: usize,
    /// Its bit offset in that byte.
    pub bit: u32,
    /// Its size in bits.
    pub bits: u32,
    /// MDF's data type: 0/1 unsigned LE/BE, 2/3 signed, 4/5 float, 10 bytes.
    pub data_type: u8,
    /// Its value is the word at `byte` shifted by `bit` and masked (little-endian, within
    /// 8 bytes): worked out once, as every record reads it.
    word: bool,
    mask: u64,
}

impl Field {
    fn bytes_spanned(&self) -> usize {
        (self.bit as usize + self.bits as usize).div_ceil(8)
    }

    /// A field at `byte`, `bit` of `bits` bits, of MDF data type `data_type`.
    pub fn new(cn_at: u64, byte: usize, bit: u32, bits: u32, data_type: u8) -> Self {
        Self {
            cn_at,
            byte,
            bit,
            bits,
            data_type,
            word: !matches!(data_type, 1 | 3 | 5) && (1..=64).contains(&bits) && bit <= 64 - bits,
            mask: u64::MAX
                .checked_shr(64u32.saturating_sub(bits))
                .unwrap_or(0),
        }
    }

    /// The field as an unsigned integer (signed ones as their bits).
    #[inline]
    pub fn uint(&self, record: &[u8]) -> u64 {
        // Nearly every field of bus logging is little-endian within 8 bytes of the record
        // (whole words, and the bits and nibbles: IDE, Dir, DLC, EDL): one unaligned word,
        // shifted and masked. The reader hands over the record with what follows it in
        // its buffer, so the word is nearly always there.
        if self.word {
            if let Some(w) = record.get(self.byte..self.byte + 8) {
                let word = u64::from_le_bytes([w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7]]);
                return (word >> self.bit) & self.mask;
            }
        }
        self.uint_bytewise(record)
    }

    /// [`uint`](Self::uint) of a big-endian field, or one at the end of the buffer.
    #[cold]
    #[inline(never)]
    fn uint_bytewise(&self, record: &[u8]) -> u64 {
        let span = self.bytes_spanned();
        let bytes = &record[self.byte..self.byte + span];
        let mut window = [0u8; 16];
        let v = if matches!(self.data_type, 1 | 3 | 5) {
            window[16 - span..].copy_from_slice(bytes);
            u128::from_be_bytes(window)
        } else {
            window[..span].copy_from_slice(bytes);
            u128::from_le_bytes(window)
        };
        let v = v >> self.bit;
        let mask = if self.bits >= 64 {
            u64::MAX
        } else {
            (1u64 << self.bits) - 1
        };
        (v as u64) & mask
    }

    /// The field as a number: floats as floats, integers (signed or not) as theirs.
    #[inline]
    pub fn number(&self, record: &[u8]) -> f64 {
        let raw = self.uint(record);
        match (self.data_type, self.bits) {
            (4 | 5, 32) => f64::from(f32::from_bits(raw as u32)),
            (4 | 5, _) => f64::from_bits(raw),
            (2 | 3, bits) if bits < 64 && raw >> (bits - 1) & 1 == 1 => {
                (raw as i64 - (1i64 << bits)) as f64
            }
            (2 | 3, _) => raw as i64 as f64,
            _ => raw as f64,
        }
    }

    /// The field as bytes (a byte array: whole bytes).
    pub fn slice<'a>(&self, record: &'a [u8]) -> &'a [u8] {
        &record[self.byte..self.byte + self.bits as usize / 8]
    }
}

/// Where a variable-length channel's values are.
#[derive(Clone, Debug)]
pub enum SignalData {
    /// Signal data blocks (SD, or DZ/DL/HL of them): each value a u32 length and its bytes,
    /// the record holding its offset.
    Blocks(DataLink),
    /// The records of a VLSD channel group of the same data group, in its order, the
    /// record holding the offset each would have in signal data blocks.
    Group(u64),
}

/// The data bytes of a frame: in the record, or variable-length elsewhere.
#[derive(Clone, Debug)]
pub enum DataBytes {
    /// A byte array in the record.
    Fixed(Field),
    /// An offset in the record, the bytes in signal data.
    Variable(Field, SignalData),
}

/// A channel group's time: a channel, or the record's index (a virtual master), converted
/// to seconds by `offset + factor * value`.
#[derive(Clone, Debug)]
pub struct Time {
    /// The master channel, `None` for a virtual one.
    pub field: Option<Field>,
    /// Conversion offset.
    pub offset: f64,
    /// Conversion factor.
    pub factor: f64,
}

/// One channel group of bus logging: its record and where each member is.
#[derive(Clone, Debug)]
pub struct BusGroup {
    /// The CG block's offset.
    pub cg_at: u64,
    /// Its record id (unsorted data groups).
    pub record_id: u64,
    /// Bytes of a record (data and invalidation bytes, without the record id).
    pub record_len: usize,
    /// Records it says it holds (not to be trusted in an unfinalized file).
    pub cycles: u64,
    /// Which frames.
    pub frame_type: FrameType,
    /// Time stamps.
    pub time: Time,
    /// `BusChannel`.
    pub bus_channel: Option<Field>,
    /// `ID`.
    pub id: Option<Field>,
    /// `IDE`.
    pub ide: Option<Field>,
    /// `DLC`.
    pub dlc: Option<Field>,
    /// `DataLength`.
    pub data_length: Option<Field>,
    /// `DataBytes`.
    pub data_bytes: Option<DataBytes>,
    /// `Dir`.
    pub dir: Option<Field>,
    /// `EDL` (CAN FD).
    pub edl: Option<Field>,
    /// `BRS`.
    pub brs: Option<Field>,
    /// `ESI`.
    pub esi: Option<Field>,
}

/// A record of an unsorted data group: how long it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordLen {
    /// Fixed: this many bytes.
    Fixed(usize),
    /// A VLSD channel group's: a u32 length, then that many bytes.
    Variable,
}

/// A data group holding bus logging.
#[derive(Clone, Debug)]
pub struct BusDataGroup {
    /// The DG block's offset.
    pub dg_at: u64,
    /// Bytes of record id before each record (0: sorted, one channel group).
    pub record_id_len: usize,
    /// Its data.
    pub data: DataLink,
    /// Its bus-logging channel groups.
    pub groups: Vec<BusGroup>,
    /// Every channel group's record length by record id (unsorted groups).
    pub records: Vec<(u64, RecordLen)>,
}

/// The bus logging of a file.
#[derive(Clone, Debug)]
pub struct BusLayout {
    /// The measurement's start, ns since 1970 (the header block's).
    pub start_ns: u64,
    /// The data groups with bus logging.
    pub data_groups: Vec<BusDataGroup>,
    /// Channel groups passed over (no bus logging in them).
    pub other_groups: usize,
    /// Damage found in a data group after those read: they are read, then it is told.
    pub damage: Option<BlockError>,
}

/// The text of a TX (or MD) block, "" for link 0.
pub fn text<R: Read + Seek>(file: &mut MdfBlocks<R>, at: u64) -> Result<String, BlockError> {
    if at == 0 {
        return Ok(String::new());
    }
    let block = file.block(at, &[b"TX", b"MD"])?;
    let end = block
        .data
        .iter()
        .position(|&b| b == 0)
        .unwrap_or(block.data.len());
    Ok(String::from_utf8_lossy(&block.data[..end]).into_owned())
}

fn u32_at(data: &[u8], at: usize) -> u32 {
    data.get(at..at + 4)
        .map_or(0, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
}

fn u64_at(data: &[u8], at: usize) -> u64 {
    data.get(at..at + 8)
        .and_then(|b| b.try_into().ok())
        .map_or(0, u64::from_le_bytes)
}

fn f64_at(data: &[u8], at: usize) -> f64 {
    f64::from_bits(u64_at(data, at))
}

/// A CN block's name and the fields of its data this reader uses.
struct Channel {
    block: Block,
    name: String,
}

impl Channel {
    fn kind(&self) -> u8 {
        self.block.data[0]
    }
    fn sync(&self) -> u8 {
        self.block.data[1]
    }
    fn at(&self) -> u64 {
        self.block.header.at
    }

    /// Its place, checked to fit a record of `record_len` bytes: a byte array (`bytes`),
    /// or a number (a variable-length channel's: its offset, an unsigned integer
    /// whatever the values' data type).
    fn field(&self, record_len: usize, bytes: bool) -> Result<Field, BlockError> {
        let d = &self.block.data;
        let field = Field::new(
            self.at(),
            u32_at(d, 4) as usize,
            u32::from(d[3]),
            u32_at(d, 8),
            if self.kind() == 1 { 0 } else { d[2] },
        );
        let bad = |why: String| {
            error(
                Some("##CN".into()),
                self.at(),
                format!("channel \"{}\": {why}", self.name),
            )
        };
        let layout = format!("byte {} bit {}, {} bits", field.byte, field.bit, field.bits);
        if bytes {
            if field.bit != 0 || field.bits % 8 != 0 || field.bits == 0 {
                return Err(bad(format!(
                    "{layout}: a byte array must start and end on whole bytes"
                )));
            }
        } else if field.bits == 0 || field.bits > 64 || field.bit > 7 {
            return Err(bad(format!(
                "{layout}: not a possible number (1 to 64 bits, bit offset 0 to 7)"
            )));
        } else if matches!(field.data_type, 4 | 5) && !matches!(field.bits, 32 | 64) {
            return Err(bad(format!("{layout}: a float has 32 or 64 bits")));
        } else if field.data_type > 5 {
            return Err(bad(format!(
                "data type {}: a number was expected here",
                field.data_type
            )));
        }
        if field
            .byte
            .checked_add(field.bytes_spanned())
            .is_none_or(|end| end > record_len)
        {
            return Err(bad(format!(
                "{layout} do not fit the channel group's {record_len}-byte records"
            )));
        }
        Ok(field)
    }
}

fn channels<R: Read + Seek>(
    file: &mut MdfBlocks<R>,
    first: u64,
) -> Result<Vec<Channel>, BlockError> {
    let mut out = Vec::new();
    for block in file.chain(first, 0, b"CN")? {
        if block.data.len() < 72 {
            return Err(error(
                Some("##CN".into()),
                block.header.at,
                format!("{} bytes of data: a CN block has 72", block.data.len()),
            ));
        }
        let name = text(file, block.link(2))?;
        out.push(Channel { block, name });
    }
    Ok(out)
}

/// The last part of a dotted name: `CAN_DataFrame.ID` is `ID`.
fn short(name: &str) -> &str {
    name.rsplit('.').next().unwrap_or(name)
}

/// The bus logging in the file behind `file`.
pub fn bus_layout<R: Read + Seek>(file: &mut MdfBlocks<R>) -> Result<BusLayout, BlockError> {
    let hd = file.block(64, &[b"HD"])?;
    let start_ns = u64_at(&hd.data, 0);
    let mut data_groups = Vec::new();
    let mut other_groups = 0;
    let mut damage = None;
    let mut seen = std::collections::HashSet::new();
    let mut next = hd.link(0);
    while next != 0 {
        let dg = if seen.insert(next) {
            file.block(next, &[b"DG"])
        } else {
            Err(error(
                Some("##DG".into()),
                next,
                "the chain of blocks comes back to this one: a loop in the links (corrupt file)",
            ))
        };
        let group = dg.and_then(|dg| {
            next = dg.link(0);
            bus_data_group(file, &dg, &mut other_groups)
        });
        match group {
            Ok(Some(group)) => data_groups.push(group),
            Ok(None) => {}
            // The data groups before the damage are read; it is reported after them.
            Err(e) if !data_groups.is_empty() => {
                damage = Some(e);
                break;
            }
            Err(e) => return Err(e),
        }
    }
    Ok(BusLayout {
        start_ns,
        data_groups,
        other_groups,
        damage,
    })
}

/// The data group `dg`'s bus logging, `None` if it has none.
fn bus_data_group<R: Read + Seek>(
    file: &mut MdfBlocks<R>,
    dg: &Block,
    other_groups: &mut usize,
) -> Result<Option<BusDataGroup>, BlockError> {
    let record_id_len = usize::from(dg.data.first().copied().unwrap_or(0));
    if !matches!(record_id_len, 0 | 1 | 2 | 4 | 8) {
        return Err(error(
            Some("##DG".into()),
            dg.header.at,
            format!("record ids of {record_id_len} bytes: MDF has 0, 1, 2, 4 or 8"),
        ));
    }
    let cgs = file.chain(dg.link(1), 0, b"CG")?;
    if record_id_len == 0 && cgs.len() > 1 {
        return Err(error(
            Some("##DG".into()),
            dg.header.at,
            format!(
                "{} channel groups and no record ids: its records cannot be told apart",
                cgs.len()
            ),
        ));
    }
    let mut groups = Vec::new();
    let mut records = Vec::new();
    let mut vlsd_groups = Vec::new();
    for cg in &cgs {
        if cg.data.len() < 32 {
            return Err(error(
                Some("##CG".into()),
                cg.header.at,
                format!("{} bytes of data: a CG block has 32", cg.data.len()),
            ));
        }
        let record_id = u64_at(&cg.data, 0);
        let flags = u16::from_le_bytes([cg.data[16], cg.data[17]]);
        if flags & 1 != 0 {
            records.push((record_id, RecordLen::Variable));
            vlsd_groups.push((cg.header.at, record_id));
            continue;
        }
        let record_len = u32_at(&cg.data, 24) as usize + u32_at(&cg.data, 28) as usize;
        records.push((record_id, RecordLen::Fixed(record_len)));
        match bus_group(file, cg, record_len)? {
            Some(group) => groups.push(group),
            None => *other_groups += 1,
        }
    }
    // A VLSD channel's data link names its channel group: its record id.
    for group in &mut groups {
        if let Some(DataBytes::Variable(_, SignalData::Group(cg_at))) = &mut group.data_bytes {
            let Some(&(_, id)) = vlsd_groups.iter().find(|(at, _)| at == cg_at) else {
                return Err(error(
                    Some("##CG".into()),
                    *cg_at,
                    "a VLSD channel's data link points to a channel group that is not a VLSD one of its data group",
                ));
            };
            *cg_at = id;
        }
    }
    if groups.is_empty() {
        return Ok(None);
    }
    let data = DataLink::resolve(file, dg.link(2), *b"DT")?;
    Ok(Some(BusDataGroup {
        dg_at: dg.header.at,
        record_id_len,
        data,
        groups,
        records,
    }))
}

/// The channel group `cg` as bus logging, `None` if it is not.
fn bus_group<R: Read + Seek>(
    file: &mut MdfBlocks<R>,
    cg: &Block,
    record_len: usize,
) -> Result<Option<BusGroup>, BlockError> {
    let top = channels(file, cg.link(1))?;
    let frame = top.iter().find_map(|c| {
        let kind = match short(&c.name) {
            "CAN_DataFrame" => FrameType::Data,
            "CAN_RemoteFrame" => FrameType::Remote,
            "CAN_ErrorFrame" => FrameType::Error,
            _ => return None,
        };
        (c.block.link(1) != 0).then_some((c, kind))
    });
    let Some((frame, frame_type)) = frame else {
        return Ok(None);
    };
    let composition = frame.block.link(1);
    if file.header(composition, &[])?.id != *b"CN" {
        return Err(error(
            Some("##CN".into()),
            frame.at(),
            format!(
                "channel \"{}\" is composed of something other than channels (an array?): not read here",
                frame.name
            ),
        ));
    }
    let members = channels(file, composition)?;
    let time = master(file, &top, record_len)?;
    let mut group = BusGroup {
        cg_at: cg.header.at,
        record_id: u64_at(&cg.data, 0),
        record_len,
        cycles: u64_at(&cg.data, 8),
        frame_type,
        time,
        bus_channel: None,
        id: None,
        ide: None,
        dlc: None,
        data_length: None,
        data_bytes: None,
        dir: None,
        edl: None,
        brs: None,
        esi: None,
    };
    for m in &members {
        let slot = match short(&m.name) {
            "BusChannel" => &mut group.bus_channel,
            "ID" => &mut group.id,
            "IDE" => &mut group.ide,
            "DLC" => &mut group.dlc,
            "DataLength" => &mut group.data_length,
            "Dir" => &mut group.dir,
            "EDL" => &mut group.edl,
            "BRS" => &mut group.brs,
            "ESI" => &mut group.esi,
            "DataBytes" => {
                group.data_bytes = Some(if m.kind() == 1 {
                    let field = m.field(record_len, false)?;
                    let link = m.block.link(5);
                    let header = file.header(link, &[b"SD", b"DZ", b"DL", b"HL", b"CG"])?;
                    let source = if header.id == *b"CG" {
                        SignalData::Group(link)
                    } else {
                        SignalData::Blocks(DataLink::resolve(file, link, *b"SD")?)
                    };
                    DataBytes::Variable(field, source)
                } else {
                    DataBytes::Fixed(m.field(record_len, true)?)
                });
                continue;
            }
            _ => continue,
        };
        *slot = Some(m.field(record_len, false)?);
    }
    if group.id.is_none() && frame_type != FrameType::Error {
        return Err(error(
            Some("##CN".into()),
            frame.at(),
            format!("channel \"{}\" has no ID member", frame.name),
        ));
    }
    Ok(Some(group))
}

/// The channel group's time: its master channel (time sync), converted to seconds.
fn master<R: Read + Seek>(
    file: &mut MdfBlocks<R>,
    top: &[Channel],
    record_len: usize,
) -> Result<Time, BlockError> {
    let Some(m) = top
        .iter()
        .find(|c| matches!(c.kind(), 2 | 3) && c.sync() == 1)
    else {
        return Err(error(
            Some("##CN".into()),
            top.first().map_or(0, Channel::at),
            "the channel group has no time channel (a master channel synchronised on time)",
        ));
    };
    let field = if m.kind() == 2 {
        Some(m.field(record_len, false)?)
    } else {
        None
    };
    let (offset, factor) = match m.block.link(4) {
        0 => (0.0, 1.0),
        at => {
            let cc = file.block(at, &[b"CC"])?;
            let kind = cc.data.first().copied().unwrap_or(0);
            let values = usize::from(u16::from_le_bytes([
                cc.data.get(6).copied().unwrap_or(0),
                cc.data.get(7).copied().unwrap_or(0),
            ]));
            match kind {
                0 => (0.0, 1.0),
                1 if values >= 2 && cc.data.len() >= 40 => (f64_at(&cc.data, 24), f64_at(&cc.data, 32)),
                _ => {
                    return Err(error(
                        Some("##CC".into()),
                        at,
                        format!(
                            "the time channel's conversion is of type {kind}: only none (0) and linear (1) are read"
                        ),
                    ))
                }
            }
        }
    };
    Ok(Time {
        field,
        offset,
        factor,
    })
}

#[cfg(test)]
mod tests {
    use super::Field;

    /// The bits of `record` from bit `first` on, `bits` of them, as MDF counts them
    /// (little-endian: bit 0 of byte 0 first; big-endian: the bytes spanned reversed).
    fn by_bits(record: &[u8], byte: usize, bit: u32, bits: u32, big_endian: bool) -> u64 {
        let span = (bit + bits).div_ceil(8) as usize;
        let mut bytes = record[byte..byte + span].to_vec();
        if big_endian {
            bytes.reverse();
        }
        (0..bits).fold(0u64, |value, k| {
            let at = (bit + k) as usize;
            value | (u64::from(bytes[at / 8] >> (at % 8) & 1) << k)
        })
    }

    #[test]
    fn a_field_reads_the_same_whether_its_word_is_loaded_whole_or_not() {
        // A record with every byte different, and 8 more after it (as the reader's buffer
        // mostly has): the word load and the byte-exact path must agree everywhere.
        let record: Vec<u8> = (0..24u32).map(|i| (i * 37 + 11) as u8).collect();
        for data_type in [0u8, 1, 2] {
            for byte in 0..4usize {
                for bit in 0..8u32 {
                    for bits in 1..=64u32 {
                        if bit + bits > 64 + 7 {
                            continue;
                        }
                        let field = Field::new(0, byte, bit, bits, data_type);
                        let span = (bit + bits).div_ceil(8) as usize;
                        let exact = &record[..byte + span];
                        let expected = by_bits(&record, byte, bit, bits, data_type == 1);
                        assert_eq!(field.uint(&record), expected, "{byte}.{bit} {bits} bits");
                        assert_eq!(field.uint(exact), expected, "{byte}.{bit} {bits} bits");
                    }
                }
            }
        }
    }
}
