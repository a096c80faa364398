//! Writing MDF 4.10 (`.mf4`): the bus as ASAM's bus-logging standard lays it out, and each
//! catalogue message's signals decoded, for asammdf, CANape, CANalyzer and python-can.
//!
//! Sorted, one data group per channel group:
//! - `CAN_DataFrame`, `CAN_ErrorFrame`, `CAN_RemoteFrame` (bus events, a CAN bus source),
//!   each a time channel and the composed frame channel with its members, as python-can and
//!   asammdf lay them out (84-byte records, data bytes in a 64-byte array, so CAN FD fits);
//! - one channel group per message of the DBC, named after it: a time channel and each
//!   signal's raw value with the DBC's linear conversion, its unit, and its COVESA VSS path
//!   as the channel's display name (and the DBC comment as its comment). A frame of the
//!   message at another length is in `CAN_DataFrame` only.
//!
//! Times are seconds (f64) since the header's start: the first frame's whole second for a
//! log in Unix time, 0 (1970) for a log in time since its own start. Each group's records
//! gather into data blocks of [`BLOCK_BYTES`] (compressed: `##DZ`, transposed deflate, as
//! asammdf's smallest), written as they fill, so memory does not grow with the log; a
//! data list per group, the cycle counts and the identification's "finalized" are written
//! by [`Mf4Writer::finish`] (until then the file says `UnFinMF`). The file history block
//! says what wrote the file, dated at the measurement's start so an export is the same
//! bytes every time.

use std::io::{self, Seek, SeekFrom, Write};

use autoplug_can::{MessageSpec, MESSAGES};
use flate2::write::ZlibEncoder;
use flate2::Compression;

use crate::frame::{Direction, FrameKind, LogFrame};

/// Records gathered before a data block is written.
pub const BLOCK_BYTES: usize = 1 << 20;
/// Frames in Unix time start after this (2000-01-01), µs; earlier ones count from 0.
const UNIX_TIME_FROM_US: u64 = 946_684_800_000_000;
/// A channel's flag: a bus event (ASAM bus logging; CANalyzer wants it on the members too).
const CN_BUS_EVENT: u32 = 0x400;
/// A channel group's flags: bus event, plain bus event.
const CG_BUS_EVENT: u16 = 0x2 | 0x4;
/// The bytes of a bus frame record after the time: channel, id, IDE, DLC, length, 64 data
/// bytes, direction, EDL, BRS, ESI.
const FRAME_BYTES: usize = 1 + 4 + 1 + 1 + 1 + 64 + 4;
/// A remote frame's: channel, id, IDE, DLC, length, direction.
const REMOTE_BYTES: usize = 1 + 4 + 1 + 1 + 1 + 1;

/// One channel group being written (its own data group).
struct Group {
    dg_at: u64,
    cg_at: u64,
    record_len: usize,
    pending: Vec<u8>,
    /// Written data blocks, with the stream offset where each begins.
    blocks: Vec<(u64, u64)>,
    written: u64,
    cycles: u64,
}

/// Writes MDF 4.10 bus logging with decoded signals; see the [module](self).
pub struct Mf4Writer<W: Write + Seek> {
    out: W,
    at: u64,
    compress: bool,
    hd_at: u64,
    start_ns: Option<u64>,
    /// 0 data frames, 1 error frames, 2 remote frames, then the messages of [`MESSAGES`].
    groups: Vec<Group>,
    /// The logger's layout: one growing data block.
    growing: Option<Growing>,
    /// Catalogue frames decoded into their message's group.
    pub decoded: u64,
}

/// The layout of a recording that a crash may end (see [`Mf4Writer::growing`]).
struct Growing {
    dt_at: u64,
    pending: Vec<u8>,
    data_bytes: u64,
}

/// A block's bytes: `##` id, reserved, length, link count, links, data (padded to 8).
fn block(id: &[u8; 2], links: &[u64], data: &[u8]) -> Vec<u8> {
    let mut b = Vec::with_capacity(24 + 8 * links.len() + data.len() + 7);
    b.extend_from_slice(b"##");
    b.extend_from_slice(id);
    b.extend_from_slice(&[0; 4]);
    let length = 24 + 8 * links.len() + data.len();
    b.extend_from_slice(&(length as u64).to_le_bytes());
    b.extend_from_slice(&(links.len() as u64).to_le_bytes());
    for l in links {
        b.extend_from_slice(&l.to_le_bytes());
    }
    b.extend_from_slice(data);
    while b.len() % 8 != 0 {
        b.push(0);
    }
    b
}

/// A channel's place and kind.
struct Cn<'a> {
    name: &'a str,
    kind: u8,
    sync: u8,
    data_type: u8,
    byte: u32,
    bits: u32,
    flags: u32,
    unit: &'a str,
    comment: Option<String>,
    conversion: Option<(f64, f64)>,
}

impl<'a> Cn<'a> {
    fn number(name: &'a str, byte: u32, bits: u32, flags: u32) -> Self {
        Self {
            name,
            kind: 0,
            sync: 0,
            data_type: 0,
            byte,
            bits,
            flags,
            unit: "",
            comment: None,
            conversion: None,
        }
    }

    fn time() -> Self {
        Self {
            name: "t",
            kind: 2,
            sync: 1,
            data_type: 4,
            byte: 0,
            bits: 64,
            flags: 0,
            unit: "s",
            comment: None,
            conversion: None,
        }
    }
}

fn xml_escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

impl<W: Write + Seek> Mf4Writer<W> {
    /// A writer that writes the file's blocks down to its channels now; `compress` makes
    /// its data blocks `##DZ` (transposed deflate). Sorted: a data group per channel group.
    pub fn new(out: W, compress: bool) -> io::Result<Self> {
        Self::start(out, compress, false)
    }

    /// A writer laid out as data loggers lay out a recording, so a crash leaves a file that
    /// reads to its last record: one unsorted data group (record ids), its one data block
    /// last in the file and growing, the file `UnFinMF` with "the last data block's length
    /// is not written" until [`finish`](Self::finish). Records are handed to `out` by
    /// [`flush_data`](Self::flush_data). Not compressed (a zlib block cannot grow).
    pub fn growing(out: W) -> io::Result<Self> {
        Self::start(out, false, true)
    }

    fn start(mut out: W, compress: bool, growing: bool) -> io::Result<Self> {
        let at = out.stream_position()?;
        let mut w = Self {
            out,
            at,
            compress,
            hd_at: 0,
            start_ns: None,
            groups: Vec::new(),
            growing: None,
            decoded: 0,
        };
        let mut id = [0u8; 64];
        id[..8].copy_from_slice(b"UnFinMF ");
        id[8..16].copy_from_slice(b"4.10    ");
        id[16..24].copy_from_slice(b"AutoPlug");
        id[28..30].copy_from_slice(&410u16.to_le_bytes());
        // Until `finish`: cycle counts, and data lists or the last block's length, left to
        // write.
        let left: u16 = if growing { 0x1 | 0x4 } else { 0x1 | 0x10 };
        id[60..62].copy_from_slice(&left.to_le_bytes());
        w.put(&id)?;
        // HD: links DG, FH, CH, AT, EV, comment; data: start (patched at the first frame),
        // time zone and DST offsets, flags, start angle and distance.
        w.hd_at = w.put(&block(b"HD", &[0; 6], &[0; 32]))?;
        let source_name = w.text("CAN")?;
        let source = w.put(&block(
            b"SI",
            &[source_name, source_name, 0],
            &[2, 2, 0, 0, 0, 0, 0, 0],
        ))?;
        for (name, members, record) in [
            ("CAN_DataFrame", FrameType::Data, FRAME_BYTES),
            ("CAN_ErrorFrame", FrameType::Error, FRAME_BYTES),
            ("CAN_RemoteFrame", FrameType::Remote, REMOTE_BYTES),
        ] {
            w.bus_group(name, members, record, source)?;
        }
        for spec in MESSAGES {
            w.message_group(&spec)?;
        }
        let cgs: Vec<u64> = w.groups.iter().map(|g| g.cg_at).collect();
        let first_dg = if growing {
            for pair in cgs.windows(2) {
                w.patch(pair[0] + 24, &pair[1].to_le_bytes())?;
            }
            let mut d = [0u8; 8];
            d[0] = 1; // one byte of record id
            let dg = w.put(&block(b"DG", &[0, cgs[0], 0, 0], &d))?;
            // The data block last: its length (the header's alone) is written at the end.
            let dt_at = w.put(&block(b"DT", &[], &[]))?;
            w.patch(dg + 24 + 2 * 8, &dt_at.to_le_bytes())?;
            w.growing = Some(Growing {
                dt_at,
                pending: Vec::new(),
                data_bytes: 0,
            });
            dg
        } else {
            let mut dgs = Vec::new();
            for (i, cg) in cgs.iter().enumerate() {
                let dg = w.put(&block(b"DG", &[0, *cg, 0, 0], &[0; 8]))?;
                w.groups[i].dg_at = dg;
                dgs.push(dg);
            }
            for pair in dgs.windows(2) {
                w.patch(pair[0] + 24, &pair[1].to_le_bytes())?;
            }
            dgs[0]
        };
        w.patch(w.hd_at + 24, &first_dg.to_le_bytes())?;
        Ok(w)
    }

    /// The file's length so far, records not yet handed to the output included.
    pub fn len(&self) -> u64 {
        self.at
            + self
                .groups
                .iter()
                .map(|g| g.pending.len() as u64)
                .sum::<u64>()
            + self.growing.as_ref().map_or(0, |g| g.pending.len() as u64)
    }

    /// Whether nothing has been written (never: the blocks are written at the start).
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Hands the records gathered so far to the output (the growing layout; the sorted
    /// one writes a block as it fills). Until then they are in memory only.
    pub fn flush_data(&mut self) -> io::Result<()> {
        let Some(mut growing) = self.growing.take() else {
            return Ok(());
        };
        let result = self.put(&growing.pending);
        if result.is_ok() {
            growing.data_bytes += growing.pending.len() as u64;
            growing.pending.clear();
        }
        self.growing = Some(growing);
        result.map(|_| ())
    }

    /// The bytes handed to the output: where a file cut after a failed write is whole.
    pub fn flushed_len(&self) -> u64 {
        self.at
    }

    /// The output.
    pub fn get_ref(&self) -> &W {
        &self.out
    }

    /// Appends bytes at the end; where they start.
    fn put(&mut self, bytes: &[u8]) -> io::Result<u64> {
        let at = self.at;
        self.out.write_all(bytes)?;
        self.at += bytes.len() as u64;
        Ok(at)
    }

    /// Overwrites bytes already written, then goes back to the end.
    fn patch(&mut self, at: u64, bytes: &[u8]) -> io::Result<()> {
        self.out.seek(SeekFrom::Start(at))?;
        self.out.write_all(bytes)?;
        self.out.seek(SeekFrom::Start(self.at))?;
        Ok(())
    }

    fn text(&mut self, text: &str) -> io::Result<u64> {
        if text.is_empty() {
            return Ok(0);
        }
        let mut data = text.as_bytes().to_vec();
        data.push(0);
        self.put(&block(b"TX", &[], &data))
    }

    fn metadata(&mut self, xml: &str) -> io::Result<u64> {
        let mut data = xml.as_bytes().to_vec();
        data.push(0);
        self.put(&block(b"MD", &[], &data))
    }

    /// Writes the channels (each with its name, unit, conversion and comment), linked in
    /// order; the first's offset.
    fn channels(&mut self, channels: &[Cn], compositions: &[u64]) -> io::Result<u64> {
        let mut offsets = Vec::new();
        for (i, c) in channels.iter().enumerate() {
            let name = self.text(c.name)?;
            let unit = self.text(c.unit)?;
            let comment = match &c.comment {
                Some(xml) => self.metadata(xml)?,
                None => 0,
            };
            let conversion = match c.conversion {
                Some((factor, offset)) => {
                    // CC: links name, unit, comment, inverse; data: type 1 (linear),
                    // precision, flags, reference count, value count 2, physical range,
                    // then offset and factor.
                    let mut d = vec![0u8; 24];
                    d[0] = 1;
                    d[6..8].copy_from_slice(&2u16.to_le_bytes());
                    d.extend_from_slice(&offset.to_le_bytes());
                    d.extend_from_slice(&factor.to_le_bytes());
                    self.put(&block(b"CC", &[0, unit, 0, 0], &d))?
                }
                None => 0,
            };
            let mut d = vec![0u8; 72];
            d[0] = c.kind;
            d[1] = c.sync;
            d[2] = c.data_type;
            d[4..8].copy_from_slice(&c.byte.to_le_bytes());
            d[8..12].copy_from_slice(&c.bits.to_le_bytes());
            d[12..16].copy_from_slice(&c.flags.to_le_bytes());
            let composition = compositions.get(i).copied().unwrap_or(0);
            offsets.push(self.put(&block(
                b"CN",
                &[0, composition, name, 0, conversion, 0, unit, comment],
                &d,
            ))?);
        }
        for pair in offsets.windows(2) {
            self.patch(pair[0] + 24, &pair[1].to_le_bytes())?;
        }
        Ok(offsets.first().copied().unwrap_or(0))
    }

    /// A CG of `record_len` data bytes (the time included); its offset.
    fn group(
        &mut self,
        first_cn: u64,
        name: &str,
        source: u64,
        flags: u16,
        record_len: usize,
        comment: u64,
    ) -> io::Result<u64> {
        let name = self.text(name)?;
        let mut d = vec![0u8; 32];
        // Record ids from 1, used by the growing layout's one data group.
        d[0..8].copy_from_slice(&(self.groups.len() as u64 + 1).to_le_bytes());
        d[16..18].copy_from_slice(&flags.to_le_bytes());
        d[24..28].copy_from_slice(&(record_len as u32).to_le_bytes());
        let cg = self.put(&block(b"CG", &[0, first_cn, name, source, 0, comment], &d))?;
        self.groups.push(Group {
            dg_at: 0,
            cg_at: cg,
            record_len,
            pending: Vec::new(),
            blocks: Vec::new(),
            written: 0,
            cycles: 0,
        });
        Ok(cg)
    }

    fn bus_group(
        &mut self,
        name: &str,
        kind: FrameType,
        bytes: usize,
        source: u64,
    ) -> io::Result<u64> {
        let member = |short: &str| format!("{name}.{short}");
        let names: Vec<String> = match kind {
            FrameType::Remote => ["BusChannel", "ID", "IDE", "DLC", "DataLength", "Dir"]
                .iter()
                .map(|s| member(s))
                .collect(),
            _ => [
                "BusChannel",
                "ID",
                "IDE",
                "DLC",
                "DataLength",
                "DataBytes",
                "Dir",
                "EDL",
                "BRS",
                "ESI",
            ]
            .iter()
            .map(|s| member(s))
            .collect(),
        };
        let mut members = Vec::new();
        let mut byte = 8u32;
        for n in &names {
            let (bits, data_type) = match n.rsplit('.').next() {
                Some("ID") => (32, 0),
                Some("DataBytes") => (64 * 8, 10),
                _ => (8, 0),
            };
            let mut cn = Cn::number(n, byte, bits, CN_BUS_EVENT);
            cn.data_type = data_type;
            members.push(cn);
            byte += bits / 8;
        }
        let first_member = self.channels(&members, &[])?;
        let mut frame = Cn::number(name, 8, bytes as u32 * 8, CN_BUS_EVENT);
        frame.data_type = 10;
        let first = self.channels(&[Cn::time(), frame], &[0, first_member])?;
        self.group(first, "CAN", source, CG_BUS_EVENT, 8 + bytes, 0)
    }

    fn message_group(&mut self, spec: &MessageSpec) -> io::Result<u64> {
        let mut channels = vec![Cn::time()];
        let mut byte = 8u32;
        for s in spec.signals {
            let bits = u32::from(s.length);
            let width = if bits <= 32 { 4 } else { 8 };
            let mut cn = Cn::number(s.name, byte, bits, 0);
            cn.data_type = if s.signed { 2 } else { 0 };
            cn.unit = s.unit;
            cn.conversion = Some((s.factor, s.offset));
            let display = if s.vss.is_empty() {
                String::new()
            } else {
                format!("<names><display>{}</display></names>", xml_escape(s.vss))
            };
            cn.comment = Some(format!(
                "<CNcomment><TX>{}</TX>{display}</CNcomment>",
                xml_escape(s.comment)
            ));
            channels.push(cn);
            byte += width;
        }
        let first = self.channels(&channels, &[])?;
        let comment = self.metadata(&format!(
            "<CGcomment><TX>CAN identifier 0x{:03X}: {}</TX></CGcomment>",
            spec.id,
            xml_escape(spec.comment)
        ))?;
        self.group(first, spec.name, 0, 0, byte as usize, comment)
    }

    /// Writes one frame, and its message's signals when it is a catalogue frame of the
    /// catalogue's length.
    pub fn write(&mut self, frame: &LogFrame) -> io::Result<()> {
        let start_ns = match self.start_ns {
            Some(s) => s,
            None => {
                let start_us = if frame.t_us >= UNIX_TIME_FROM_US {
                    frame.t_us / 1_000_000 * 1_000_000
                } else {
                    0
                };
                let start_ns = start_us * 1000;
                self.patch(self.hd_at + 24 + 6 * 8, &start_ns.to_le_bytes())?;
                self.start_ns = Some(start_ns);
                start_ns
            }
        };
        // Whole microseconds as f64 seconds: read back to the nanosecond, so exactly.
        let t = (frame.t_us as i64 - (start_ns / 1000) as i64) as f64 / 1e6;
        let mut record = [0u8; 8 + FRAME_BYTES];
        record[..8].copy_from_slice(&t.to_le_bytes());
        record[8] = frame.channel;
        record[9..13].copy_from_slice(&frame.id.to_le_bytes());
        record[13] = u8::from(frame.extended);
        record[14] = frame.dlc();
        let tx = u8::from(frame.direction == Direction::Tx);
        let (group, len) = match frame.kind {
            FrameKind::Remote => {
                record[14] = frame.len() as u8;
                record[15] = 0;
                record[16] = tx;
                (2, 8 + REMOTE_BYTES)
            }
            kind => {
                record[15] = frame.len() as u8;
                record[16..16 + frame.len()].copy_from_slice(frame.data());
                record[80] = tx;
                let fd = frame.fd();
                record[81] = u8::from(fd.is_some());
                record[82] = u8::from(fd.is_some_and(|f| f.brs));
                record[83] = u8::from(fd.is_some_and(|f| f.esi));
                (usize::from(kind == FrameKind::Error), 8 + FRAME_BYTES)
            }
        };
        self.record(group, &record[..len])?;
        if frame.kind != FrameKind::Data || frame.extended || frame.is_fd() {
            return Ok(());
        }
        let Some(index) = MESSAGES.iter().position(|m| u32::from(m.id) == frame.id) else {
            return Ok(());
        };
        let spec = &MESSAGES[index];
        if frame.len() != usize::from(spec.dlc) {
            return Ok(());
        }
        let mut bits = 0u64;
        for (i, b) in frame.data().iter().enumerate() {
            bits |= u64::from(*b) << (8 * i);
        }
        let mut record = Vec::with_capacity(self.groups[3 + index].record_len);
        record.extend_from_slice(&t.to_le_bytes());
        for s in spec.signals {
            let raw = s.raw_in(bits);
            if s.length <= 32 {
                record.extend_from_slice(&(raw as u32).to_le_bytes());
            } else {
                record.extend_from_slice(&(raw as u64).to_le_bytes());
            }
        }
        self.record(3 + index, &record)?;
        self.decoded += 1;
        Ok(())
    }

    fn record(&mut self, group: usize, record: &[u8]) -> io::Result<()> {
        if let Some(growing) = self.growing.as_mut() {
            growing.pending.push(group as u8 + 1);
            growing.pending.extend_from_slice(record);
            self.groups[group].cycles += 1;
            return Ok(());
        }
        let g = &mut self.groups[group];
        g.pending.extend_from_slice(record);
        g.cycles += 1;
        if g.pending.len() + g.record_len > BLOCK_BYTES {
            self.flush(group)?;
        }
        Ok(())
    }

    /// Writes a group's gathered records as a data block.
    fn flush(&mut self, group: usize) -> io::Result<()> {
        let pending = std::mem::take(&mut self.groups[group].pending);
        if pending.is_empty() {
            return Ok(());
        }
        let record_len = self.groups[group].record_len;
        let bytes = if self.compress {
            let transposed = super::transpose::columns_from_rows(&pending, record_len);
            let mut z = ZlibEncoder::new(Vec::new(), Compression::default());
            z.write_all(&transposed)?;
            let zipped = z.finish()?;
            let mut d = Vec::with_capacity(24 + zipped.len());
            d.extend_from_slice(b"DT");
            d.push(1);
            d.push(0);
            d.extend_from_slice(&(record_len as u32).to_le_bytes());
            d.extend_from_slice(&(pending.len() as u64).to_le_bytes());
            d.extend_from_slice(&(zipped.len() as u64).to_le_bytes());
            d.extend_from_slice(&zipped);
            block(b"DZ", &[], &d)
        } else {
            block(b"DT", &[], &pending)
        };
        let at = self.put(&bytes)?;
        let g = &mut self.groups[group];
        g.blocks.push((at, g.written));
        g.written += pending.len() as u64;
        // The buffer is used again: no allocation per block.
        g.pending = pending;
        g.pending.clear();
        Ok(())
    }

    /// Writes what is gathered, each group's data list and cycle count, the file history
    /// and the identification's "finalized"; hands back the output.
    pub fn finish(mut self) -> io::Result<W> {
        if self.start_ns.is_none() {
            self.start_ns = Some(0);
        }
        if let Some(dt) = self.growing.as_ref().map(|g| g.dt_at) {
            self.flush_data()?;
            let data = self.growing.as_ref().map_or(0, |g| g.data_bytes);
            self.patch(dt + 8, &(24 + data).to_le_bytes())?;
            // The block ends the data: the next block starts 8-byte aligned.
            let pad = (8 - (self.at % 8)) % 8;
            self.put(&vec![0u8; pad as usize])?;
        }
        for group in 0..self.groups.len() {
            if self.growing.is_some() {
                let (cg, cycles) = (self.groups[group].cg_at, self.groups[group].cycles);
                self.patch(cg + 24 + 6 * 8 + 8, &cycles.to_le_bytes())?;
                continue;
            }
            self.flush(group)?;
            let (dg, cg, cycles, blocks) = {
                let g = &self.groups[group];
                (g.dg_at, g.cg_at, g.cycles, g.blocks.clone())
            };
            let data = match blocks.as_slice() {
                [] => 0,
                [(only, _)] => *only,
                many => {
                    // DL: links next and the blocks; data flags, count, each one's offset.
                    let mut links = vec![0u64];
                    links.extend(many.iter().map(|(at, _)| *at));
                    let mut d = vec![0u8; 8];
                    d[4..8].copy_from_slice(&(many.len() as u32).to_le_bytes());
                    for (_, offset) in many {
                        d.extend_from_slice(&offset.to_le_bytes());
                    }
                    self.put(&block(b"DL", &links, &d))?
                }
            };
            self.patch(dg + 24 + 2 * 8, &data.to_le_bytes())?;
            self.patch(cg + 24 + 6 * 8 + 8, &cycles.to_le_bytes())?;
        }
        let start_ns = self.start_ns.unwrap_or(0);
        let comment = self.metadata(&format!(
            "<FHcomment><TX>written by AutoPlug (autoplug-logs {})</TX><tool_id>AutoPlug</tool_id><tool_vendor>AutoPlug</tool_vendor><tool_version>{}</tool_version></FHcomment>",
            env!("CARGO_PKG_VERSION"),
            env!("CARGO_PKG_VERSION")
        ))?;
        let mut d = vec![0u8; 16];
        d[..8].copy_from_slice(&start_ns.to_le_bytes());
        let fh = self.put(&block(b"FH", &[0, comment], &d))?;
        self.patch(self.hd_at + 24 + 8, &fh.to_le_bytes())?;
        // Finalized: the identification says so, no flags left.
        self.patch(0, b"MDF     ")?;
        self.patch(60, &[0; 4])?;
        self.out.flush()?;
        Ok(self.out)
    }
}

#[derive(Clone, Copy)]
enum FrameType {
    Data,
    Error,
    Remote,
}
