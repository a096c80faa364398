//! ASAM MDF 4 bus logging (`.mf4`) read as frames: what CANalyzer/CANoe, Vector's and
//! CSS's loggers, asammdf and python-can write (see [`crate::mdf4`] for the blocks and
//! [`crate::mdf4::bus`] for where the frames are found).
//!
//! Each data group with bus logging is one stream of records, read block by block; sorted
//! files (one channel group a data group) give a stream a frame type, unsorted ones mix
//! them (and variable-length data bytes) with record ids. The streams are merged by time,
//! so frames come in time order across data groups and in file order within one.
//!
//! - `t_us`: the header's start time plus the record's time, to the microsecond.
//! - `channel`: `BusChannel` as the file has it. Vector's and CSS's loggers count from 1,
//!   python-can and asammdf write their channel numbers as they are (from 0); renumbering
//!   either would merge two buses of the other, so the number is kept.
//! - An `ID` with bit 31 set is extended, as with `IDE`.
//! - CAN FD frames (`EDL`) keep `BRS` and `ESI`; the length is `DataLength`, else what
//!   the `DLC` says.
//!
//! A record that does not make a frame (an identifier too large, 12 data bytes in a
//! classic frame) is an error naming its data group and record, and reading goes on.
//! Damage (a block outside the file, a DZ that does not inflate, a file cut short) ends
//! its data group with one fatal error after every frame before it; the other data
//! groups are read to their end first. An unfinalized file (`UnFinMF`, a logger that lost
//! power) is read to where its data stop: its last record may be cut short, and its
//! cycle counts are not trusted.

use std::collections::VecDeque;
use std::io::{Read, Seek};

use super::{LogError, Place};
use crate::frame::{dlc_to_len, Direction, FdFlags, FrameKind, LogFrame};
use crate::mdf4::blocks::{BlockError, Identification, MdfBlocks};
use crate::mdf4::bus::{
    bus_layout, BusDataGroup, BusGroup, DataBytes, FrameType, RecordLen, SignalData,
};
use crate::mdf4::data::{DataLink, DataStream};

/// The longest variable-length value taken (CAN FD's 64 bytes, CAN XL's 2048, with room):
/// a longer one is corruption.
const MAX_VALUE: u32 = 4096;
/// Frames a data group is read ahead of the merge.
const READ_AHEAD: usize = 256;
/// Values of a VLSD channel group kept waiting for their record (bounded: a hostile file
/// cannot grow it).
const MAX_WAITING: usize = 1024;

/// Signal data of one variable-length channel, read in order.
enum Signal {
    Blocks(DataStream),
    /// A VLSD channel group's records as they come in the data group's stream: the offset
    /// each would have in signal data blocks, and its bytes.
    Group {
        record_id: u64,
        waiting: VecDeque<(u64, Vec<u8>)>,
        next_offset: u64,
    },
}

/// One data group being read.
struct Source {
    group: BusDataGroup,
    stream: DataStream,
    /// Per bus group, its variable-length data, if any.
    signals: Vec<Option<Signal>>,
    /// Records read (every channel group's), for errors.
    records: u64,
    /// Per bus group, records read (its virtual time channel's index, and the cycle count
    /// check of a finalized sorted file).
    group_records: Vec<u64>,
    /// The bus group whose records are read many at a time from the stream's buffer
    /// ([`read_buffered`]): data frames with their bytes in the record, in a sorted data
    /// group or an unsorted one with 1-byte record ids.
    buffered_group: Option<usize>,
    /// What it has read ahead (frames, and errors in their place): up to [`READ_AHEAD`].
    ready: VecDeque<Result<LogFrame, LogError>>,
    done: bool,
    /// The last variable-length value taken.
    value: Vec<u8>,
}

/// Reads MDF 4 bus logging; see the [module](self).
pub struct Mf4Reader<R> {
    file: MdfBlocks<R>,
    identification: Identification,
    start_ns: u64,
    sources: Vec<Source>,
    fatal: Option<LogError>,
    finished: bool,
}

/// `UnFinMF` flag: the last DT block's length was not written.
const UNFIN_LAST_DT_LENGTH: u16 = 0x4;

impl<R: Read + Seek> Mf4Reader<R> {
    /// Reads the file's blocks down to its channels and checks every place a frame's
    /// member has; an error names the block and its offset.
    pub fn new(input: R) -> Result<Self, BlockError> {
        let (mut file, identification) = MdfBlocks::open(input)?;
        let layout = bus_layout(&mut file)?;
        if layout.data_groups.is_empty() {
            return Err(BlockError {
                block: Some("##HD".into()),
                at: 64,
                message: format!(
                    "no CAN bus logging in the file (no channel group with a CAN_DataFrame, CAN_RemoteFrame or CAN_ErrorFrame channel; {} other channel group(s))",
                    layout.other_groups
                ),
            });
        }
        let open_ended = identification
            .unfinalized
            .filter(|(standard, _)| standard & UNFIN_LAST_DT_LENGTH != 0)
            .and_then(|_| {
                layout
                    .data_groups
                    .iter()
                    .filter_map(|g| g.data.blocks.last().copied())
                    .max()
            });
        let mut sources = Vec::new();
        for mut group in layout.data_groups {
            group.data.open_ended = open_ended;
            let mut signals = Vec::new();
            for bus in &group.groups {
                signals.push(match &bus.data_bytes {
                    Some(DataBytes::Variable(_, SignalData::Blocks(link))) => {
                        let mut link: DataLink = link.clone();
                        link.open_ended = open_ended;
                        Some(Signal::Blocks(DataStream::new(link)))
                    }
                    Some(DataBytes::Variable(_, SignalData::Group(record_id))) => {
                        Some(Signal::Group {
                            record_id: *record_id,
                            waiting: VecDeque::new(),
                            next_offset: 0,
                        })
                    }
                    _ => None,
                });
            }
            let in_record = |g: &BusGroup| {
                g.frame_type == FrameType::Data
                    && !matches!(g.data_bytes, Some(DataBytes::Variable(..)))
            };
            let buffered_group = match group.record_id_len {
                0 if group.groups.len() == 1 => Some(0),
                1 => group.groups.iter().position(in_record),
                _ => None,
            }
            .filter(|&k| in_record(&group.groups[k]));
            sources.push(Source {
                buffered_group,
                stream: DataStream::new(group.data.clone()),
                group_records: vec![0; group.groups.len()],
                group,
                signals,
                records: 0,
                ready: VecDeque::with_capacity(READ_AHEAD),
                done: false,
                value: Vec::new(),
            });
        }
        Ok(Self {
            file,
            identification,
            start_ns: layout.start_ns,
            sources,
            fatal: layout.damage.map(|e| LogError {
                line: 0,
                place: Place::Record,
                message: e.to_string(),
                fatal: true,
            }),
            finished: false,
        })
    }

    /// What the file says of itself (version, writer, unfinalized).
    pub fn identification(&self) -> &Identification {
        &self.identification
    }

    /// The measurement's start, µs since 1970.
    pub fn start_us(&self) -> u64 {
        self.start_ns / 1000
    }

    /// Reads source `i` ahead, up to [`READ_AHEAD`] frames: one call a batch rather than
    /// one a frame keeps the reading in a tight loop (with the merge's choice, the per-call
    /// work was half a frame's cost).
    fn advance(&mut self, i: usize) {
        let unfinalized = self.identification.unfinalized.is_some();
        let start_ns = self.start_ns;
        let source = &mut self.sources[i];
        let file = &mut self.file;
        while source.ready.len() < READ_AHEAD && !source.done {
            if read_buffered(source, start_ns, unfinalized) {
                continue;
            }
            match next_record(file, source, unfinalized) {
                Ok(Some((index, record_number))) => {
                    match decode(file, source, index, record_number, start_ns) {
                        Ok(frame) => source.ready.push_back(Ok(frame)),
                        Err(message) => source.ready.push_back(Err(LogError {
                            line: source.records,
                            place: Place::Record,
                            message: format!(
                                "##DG block at byte {}: {message}",
                                source.group.dg_at
                            ),
                            fatal: false,
                        })),
                    }
                }
                Ok(None) => {}
                Err(e) => {
                    source.done = true;
                    if let Some(e) = e {
                        let error = LogError {
                            line: source.records,
                            place: Place::Record,
                            message: e,
                            fatal: true,
                        };
                        // The first damage is the one reported; the other data groups
                        // are read to their end meanwhile.
                        self.fatal.get_or_insert(error);
                    }
                }
            }
        }
    }
}

/// The next record of the source, left as the stream's last taken bytes:
/// `Ok(Some((bus group index, its record number)))` for a bus group's record, `Ok(None)`
/// for another (read past), `Err(None)` at the end, `Err(Some(message))` on damage.
fn next_record<R: Read + Seek>(
    file: &mut MdfBlocks<R>,
    source: &mut Source,
    unfinalized: bool,
) -> Result<Option<(usize, u64)>, Option<String>> {
    let id_len = source.group.record_id_len;
    let end = |stream: &DataStream, what: &str| -> Option<String> {
        let left = stream.leftover();
        (left > 0 && !unfinalized)
            .then(|| format!("the data end {left} bytes into a {what} (truncated file?)"))
    };
    let damage = |e: BlockError| Some(e.to_string());
    if id_len == 0 {
        let group = &source.group.groups[0];
        // A finalized file's cycle count says where its records end.
        if !unfinalized && source.group_records[0] >= group.cycles {
            return Err(None);
        }
        let len = group.record_len;
        match source.stream.take(file, len).map_err(damage)? {
            Some(_) => {}
            None => return Err(end(&source.stream, "record")),
        }
        source.records += 1;
        source.group_records[0] += 1;
        return Ok(Some((0, source.group_records[0] - 1)));
    }
    let Some(id_bytes) = source.stream.take(file, id_len).map_err(damage)? else {
        return Err(end(&source.stream, "record id"));
    };
    let mut id = 0u64;
    for (k, &b) in id_bytes.iter().enumerate() {
        id |= u64::from(b) << (8 * k);
    }
    source.records += 1;
    let Some(&(_, len)) = source.group.records.iter().find(|(r, _)| *r == id) else {
        return Err(Some(format!(
            "##DG block at byte {}: record {}: record id {id} belongs to no channel group of the data group (corrupt data: nothing after it can be placed)",
            source.group.dg_at, source.records
        )));
    };
    match len {
        RecordLen::Fixed(len) => {
            if source.stream.take(file, len).map_err(damage)?.is_none() {
                return Err(end(&source.stream, "record"));
            }
            let Some(index) = source.group.groups.iter().position(|g| g.record_id == id) else {
                return Ok(None);
            };
            source.group_records[index] += 1;
            Ok(Some((index, source.group_records[index] - 1)))
        }
        RecordLen::Variable => {
            let Some(n) = source.stream.take(file, 4).map_err(damage)? else {
                return Err(end(&source.stream, "variable-length record"));
            };
            let n = u32::from_le_bytes([n[0], n[1], n[2], n[3]]);
            if n > MAX_VALUE {
                return Err(Some(format!(
                    "##DG block at byte {}: record {}: a variable-length value of {n} bytes (corrupt data)",
                    source.group.dg_at, source.records
                )));
            }
            let Some(bytes) = source.stream.take(file, n as usize).map_err(damage)? else {
                return Err(end(&source.stream, "variable-length record"));
            };
            for signal in source.signals.iter_mut().flatten() {
                if let Signal::Group {
                    record_id,
                    waiting,
                    next_offset,
                } = signal
                {
                    if *record_id == id {
                        if waiting.len() == MAX_WAITING {
                            waiting.pop_front();
                        }
                        waiting.push_back((*next_offset, bytes.to_vec()));
                        *next_offset += 4 + u64::from(n);
                    }
                }
            }
            Ok(None)
        }
    }
}

/// Reads the records whole in the stream's buffer of the source's
/// [`buffered_group`](Source::buffered_group) into its frames, up to [`READ_AHEAD`]; `false`
/// if there was none to read. It stops at the first record that is not one (another
/// group's, an FD frame, anything [`decode`] would refuse), which [`next_record`] and
/// [`decode`] then read as any other: a frame comes out the same either way.
///
/// Why: taken one at a time, a record cost the stream's `take`, the record id's lookup and
/// the errors' plumbing, five times the work of making its frame (callgrind).
fn read_buffered(source: &mut Source, start_ns: u64, unfinalized: bool) -> bool {
    let Some(k) = source.buffered_group else {
        return false;
    };
    let group = &source.group.groups[k];
    let id_len = source.group.record_id_len;
    let step = id_len + group.record_len;
    let mut room = READ_AHEAD.saturating_sub(source.ready.len());
    if id_len == 0 && !unfinalized {
        // A finalized file's cycle count says where its records end.
        let left = group.cycles.saturating_sub(source.group_records[k]);
        room = room.min(usize::try_from(left).unwrap_or(usize::MAX));
    }
    let buffered = source.stream.buffered();
    let (mut used, mut n) = (0, 0u64);
    while (n as usize) < room && buffered.len() - used >= step {
        let at = &buffered[used..];
        if id_len == 1 && u64::from(at[0]) != group.record_id {
            break;
        }
        let Some(frame) =
            classic_frame(group, &at[id_len..], source.group_records[k] + n, start_ns)
        else {
            break;
        };
        source.ready.push_back(Ok(frame));
        used += step;
        n += 1;
    }
    source.stream.consume(used);
    source.records += n;
    source.group_records[k] += n;
    n > 0
}

/// The classic data frame of a data frame group's record (its bytes in the record, which
/// runs on with what follows it in the buffer), as [`decode`] makes it; `None` for any
/// other (an FD frame, or one [`decode`] refuses with an error).
#[inline]
fn classic_frame(
    group: &BusGroup,
    record: &[u8],
    record_number: u64,
    start_ns: u64,
) -> Option<LogFrame> {
    let value = |field: &Option<crate::mdf4::bus::Field>| field.as_ref().map(|f| f.uint(record));
    if value(&group.edl).is_some_and(|v| v != 0) {
        return None;
    }
    let t_us = time_us(group, record, record_number, start_ns).ok()?;
    let channel = u8::try_from(value(&group.bus_channel).unwrap_or(0)).ok()?;
    let raw_id = value(&group.id).unwrap_or(0) as u32;
    let extended = value(&group.ide).is_some_and(|v| v != 0) || raw_id & 0x8000_0000 != 0;
    let direction = if value(&group.dir) == Some(1) {
        Direction::Tx
    } else {
        Direction::Rx
    };
    let dlc = value(&group.dlc).unwrap_or(0).min(15) as u8;
    let bytes: &[u8] = match &group.data_bytes {
        None => &[],
        Some(DataBytes::Fixed(field)) => field.slice(record),
        Some(DataBytes::Variable(..)) => return None,
    };
    let len = value(&group.data_length).map_or(dlc_to_len(dlc, false), |l| l as usize);
    let frame = LogFrame::new(
        t_us,
        channel,
        raw_id & 0x1FFF_FFFF,
        extended,
        FrameKind::Data,
        bytes.get(..len)?,
    );
    Some(frame.ok()?.with_direction(direction))
}

/// A record's time, µs since 1970 (the header's start plus the record's time), or the
/// seconds it says if they are not a number.
#[inline]
fn time_us(group: &BusGroup, record: &[u8], record_number: u64, start_ns: u64) -> Result<u64, f64> {
    let seconds = group.time.offset
        + group.time.factor
            * group
                .time
                .field
                .as_ref()
                .map_or(record_number as f64, |f| f.number(record));
    if !seconds.is_finite() {
        return Err(seconds);
    }
    // The start and the record's offset added as integer nanoseconds, then rounded to
    // the microsecond: exact for any time a file holds (i64 ns: ±292 years).
    let offset_ns = seconds * 1e9;
    let t_ns = if offset_ns.abs() < 9e18 {
        (start_ns as i64)
            .saturating_add(round_to_integer(offset_ns))
            .max(0)
    } else if offset_ns < 0.0 {
        0
    } else {
        i64::MAX
    };
    Ok((t_ns as u64).saturating_add(500) / 1000)
}

/// The frame of bus group `index`'s record, the stream's last taken bytes.
fn decode<R: Read + Seek>(
    file: &mut MdfBlocks<R>,
    source: &mut Source,
    index: usize,
    record_number: u64,
    start_ns: u64,
) -> Result<LogFrame, String> {
    let group: &BusGroup = &source.group.groups[index];
    // The record and what follows it in the buffer (fields are read as whole words).
    let record = source.stream.last_taken(group.record_len);
    let value = |field: &Option<crate::mdf4::bus::Field>| field.as_ref().map(|f| f.uint(record));
    let t_us = time_us(group, record, record_number, start_ns)
        .map_err(|seconds| format!("record {}: time {seconds} s", source.records))?;
    let channel = value(&group.bus_channel).unwrap_or(0);
    let channel = u8::try_from(channel).map_err(|_| {
        format!(
            "record {}: bus channel {channel}: AutoPlug reads channels 0 to 255",
            source.records
        )
    })?;
    let raw_id = value(&group.id).unwrap_or(0) as u32;
    let extended = value(&group.ide).is_some_and(|v| v != 0) || raw_id & 0x8000_0000 != 0;
    let id = raw_id & 0x1FFF_FFFF;
    let direction = if value(&group.dir) == Some(1) {
        Direction::Tx
    } else {
        Direction::Rx
    };
    let fd = value(&group.edl).is_some_and(|v| v != 0);
    let dlc = value(&group.dlc).unwrap_or(0).min(15) as u8;
    let bad = |e: crate::frame::FrameError| format!("record {}: {e}", source.records);
    let frame = match group.frame_type {
        FrameType::Remote => LogFrame::remote(t_us, channel, id, extended, dlc.min(8)),
        FrameType::Data | FrameType::Error => {
            let length = value(&group.data_length).map(|l| l as usize);
            let records = source.records;
            let bytes: &[u8] = match &group.data_bytes {
                None => &[],
                Some(DataBytes::Fixed(field)) => field.slice(record),
                Some(DataBytes::Variable(field, _)) => {
                    let offset = field.uint(record);
                    source.value = signal_value(file, source.signals[index].as_mut(), offset)
                        .map_err(|e| format!("record {records}: {e}"))?;
                    &source.value
                }
            };
            let variable = matches!(group.data_bytes, Some(DataBytes::Variable(..)));
            let len = length.unwrap_or(if variable {
                bytes.len()
            } else {
                dlc_to_len(dlc, fd)
            });
            if len > bytes.len() {
                return Err(format!(
                    "record {records}: {len} data bytes, and its data bytes channel holds {}",
                    bytes.len()
                ));
            }
            let data = &bytes[..len];
            if group.frame_type == FrameType::Error {
                LogFrame::new(
                    t_us,
                    channel,
                    id,
                    extended,
                    FrameKind::Error,
                    &data[..len.min(8)],
                )
            } else if fd {
                let flags = FdFlags {
                    brs: value(&group.brs).is_some_and(|v| v != 0),
                    esi: value(&group.esi).is_some_and(|v| v != 0),
                };
                LogFrame::new_fd(t_us, channel, id, extended, data, flags)
            } else {
                LogFrame::new(t_us, channel, id, extended, FrameKind::Data, data)
            }
        }
    }
    .map_err(bad)?;
    Ok(frame.with_direction(direction))
}

/// `x.round()` as an integer, for |x| < 9e18: the same value, without the call to libm's
/// `round` that the baseline x86-64 target makes of it (a fiftieth of reading a frame).
#[inline]
fn round_to_integer(x: f64) -> i64 {
    // Exact: below 2^53 the truncated part converts back exactly, above it x is whole.
    let whole = x as i64;
    let rest = x - whole as f64;
    if rest >= 0.5 {
        whole + 1
    } else if rest <= -0.5 {
        whole - 1
    } else {
        whole
    }
}

/// The variable-length value at `offset` of a channel's signal data.
fn signal_value<R: Read + Seek>(
    file: &mut MdfBlocks<R>,
    signal: Option<&mut Signal>,
    offset: u64,
) -> Result<Vec<u8>, String> {
    match signal {
        None => Err("no signal data".into()),
        Some(Signal::Blocks(stream)) => {
            let at = stream.offset();
            if offset < at {
                return Err(format!(
                    "signal data offset {offset} is behind {at}: AutoPlug reads signal data in order"
                ));
            }
            let short = || format!("signal data offset {offset} is past their end");
            if !stream.skip(file, offset - at).map_err(|e| e.to_string())? {
                return Err(short());
            }
            let n = stream
                .take(file, 4)
                .map_err(|e| e.to_string())?
                .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
                .ok_or_else(short)?;
            if n > MAX_VALUE {
                return Err(format!(
                    "a signal data value of {n} bytes at offset {offset} (corrupt data)"
                ));
            }
            stream
                .take(file, n as usize)
                .map_err(|e| e.to_string())?
                .map(<[u8]>::to_vec)
                .ok_or_else(short)
        }
        Some(Signal::Group { waiting, .. }) => {
            while waiting.front().is_some_and(|(o, _)| *o < offset) {
                waiting.pop_front();
            }
            match waiting.pop_front() {
                Some((o, bytes)) if o == offset => Ok(bytes),
                other => {
                    if let Some(entry) = other {
                        waiting.push_front(entry);
                    }
                    Err(format!(
                        "no VLSD record at offset {offset} before this record: AutoPlug reads a VLSD channel group's records before the records that use them"
                    ))
                }
            }
        }
    }
}

impl<R: Read + Seek> Iterator for Mf4Reader<R> {
    type Item = Result<LogFrame, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.finished {
            return None;
        }
        for i in 0..self.sources.len() {
            if self.sources[i].ready.is_empty() && !self.sources[i].done {
                self.advance(i);
            }
        }
        // The earliest frame of the sources; an error comes out where it was found.
        let mut earliest: Option<(u64, usize)> = None;
        for (i, source) in self.sources.iter().enumerate() {
            let t = match source.ready.front() {
                Some(Ok(frame)) => frame.t_us,
                Some(Err(_)) => 0,
                None => continue,
            };
            if earliest.is_none_or(|(e, _)| t < e) {
                earliest = Some((t, i));
            }
        }
        match earliest {
            Some((_, i)) => self.sources[i].ready.pop_front(),
            None => {
                self.finished = true;
                self.fatal.take().map(Err)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::round_to_integer;

    #[test]
    fn integer_rounding_is_f64_round() {
        let edges = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            2.5,
            -2.5,
            0.499_999_999_999_999_94,
            -0.499_999_999_999_999_94,
            4_503_599_627_370_495.5,
            9_007_199_254_740_993.0,
            1_700_000_000_123_456_789.0,
            -8.9e18,
            8.9e18,
        ];
        // And a sweep of times as files hold them: seconds with nine decimals and noise.
        let sweep = (0..100_000).map(|i| f64::from(i) * 1.234_567_891e-3 * 1e9 + 0.499_999);
        for x in edges.into_iter().chain(sweep) {
            assert_eq!(round_to_integer(x), x.round() as i64, "{x}");
        }
    }
}
