//! The MF4 reader on files laid out as the big loggers lay them out, built here block by
//! block: one unsorted data group with record ids, data bytes of variable length in a
//! VLSD channel group or in signal data blocks, bit fields, a time channel in integer
//! nanoseconds with a linear conversion, a channel group of something else among them;
//! a file a logger left unfinalized; and every kind of damage, each named with its block
//! and offset, with the frames before it kept.

use std::io::Cursor;

use autoplug_logs::{Direction, FdFlags, FrameKind, LogError, LogFormat, LogFrame, LogReader};

const START_NS: u64 = 1_700_000_000_000_000_000;

/// An MDF file being built: blocks appended, links patched afterwards.
struct Mdf {
    bytes: Vec<u8>,
}

impl Mdf {
    fn new(unfinished: Option<u16>) -> Self {
        let mut bytes = vec![0u8; 64];
        bytes[..8].copy_from_slice(if unfinished.is_some() {
            b"UnFinMF "
        } else {
            b"MDF     "
        });
        bytes[8..16].copy_from_slice(b"4.10    ");
        bytes[16..24].copy_from_slice(b"Logger  ");
        bytes[28..30].copy_from_slice(&410u16.to_le_bytes());
        if let Some(flags) = unfinished {
            bytes[60..62].copy_from_slice(&flags.to_le_bytes());
        }
        Self { bytes }
    }

    fn block(&mut self, id: &[u8; 2], links: &[u64], data: &[u8]) -> u64 {
        while self.bytes.len() % 8 != 0 {
            self.bytes.push(0);
        }
        let at = self.bytes.len() as u64;
        self.bytes.extend_from_slice(b"##");
        self.bytes.extend_from_slice(id);
        self.bytes.extend_from_slice(&[0; 4]);
        let length = 24 + 8 * links.len() + data.len();
        self.bytes.extend_from_slice(&(length as u64).to_le_bytes());
        self.bytes
            .extend_from_slice(&(links.len() as u64).to_le_bytes());
        for l in links {
            self.bytes.extend_from_slice(&l.to_le_bytes());
        }
        self.bytes.extend_from_slice(data);
        at
    }

    fn link(&mut self, block: u64, index: usize, to: u64) {
        let at = block as usize + 24 + 8 * index;
        self.bytes[at..at + 8].copy_from_slice(&to.to_le_bytes());
    }

    fn text(&mut self, s: &str) -> u64 {
        let mut data = s.as_bytes().to_vec();
        data.push(0);
        self.block(b"TX", &[], &data)
    }

    /// A CN block: its links (next, composition, name, source, conversion, data, unit,
    /// comment) and its 72 bytes of data.
    #[allow(clippy::too_many_arguments)]
    fn channel(
        &mut self,
        name: &str,
        kind: u8,
        sync: u8,
        data_type: u8,
        byte: u32,
        bit: u8,
        bits: u32,
        conversion: u64,
        data: u64,
    ) -> u64 {
        let name = self.text(name);
        let mut d = vec![0u8; 72];
        d[0] = kind;
        d[1] = sync;
        d[2] = data_type;
        d[3] = bit;
        d[4..8].copy_from_slice(&byte.to_le_bytes());
        d[8..12].copy_from_slice(&bits.to_le_bytes());
        self.block(b"CN", &[0, 0, name, 0, conversion, data, 0, 0], &d)
    }

    /// Links the channels in order (each's `next`) and returns the first.
    fn chain(&mut self, blocks: &[u64]) -> u64 {
        for pair in blocks.windows(2) {
            self.link(pair[0], 0, pair[1]);
        }
        blocks.first().copied().unwrap_or(0)
    }

    fn group(&mut self, record_id: u64, cycles: u64, flags: u16, bytes: u32, first: u64) -> u64 {
        let mut d = vec![0u8; 32];
        d[0..8].copy_from_slice(&record_id.to_le_bytes());
        d[8..16].copy_from_slice(&cycles.to_le_bytes());
        d[16..18].copy_from_slice(&flags.to_le_bytes());
        d[24..28].copy_from_slice(&bytes.to_le_bytes());
        self.block(b"CG", &[0, first, 0, 0, 0, 0], &d)
    }

    /// The header block at 64 (it must be the first block) with no data group yet.
    fn header(&mut self) -> u64 {
        let mut d = vec![0u8; 32];
        d[0..8].copy_from_slice(&START_NS.to_le_bytes());
        self.block(b"HD", &[0, 0, 0, 0, 0, 0], &d)
    }
}

/// One frame to write: time in ns since the start, and the frame.
struct Out {
    t_ns: u64,
    frame: LogFrame,
}

/// How the data bytes are kept.
#[derive(Clone, Copy, PartialEq)]
enum Layout {
    /// In a VLSD channel group of the data group (record id 2).
    VlsdGroup,
    /// In signal data blocks.
    SignalBlocks,
}

struct Built {
    mdf: Mdf,
    /// Offset of the data group's DT block.
    dt: u64,
    /// Offsets of the ID channel's CN block and the data group.
    id_cn: u64,
    dg: u64,
}

/// A Vector-style unsorted file: record id 1 the data frames (24 bytes: time u64 ns,
/// BusChannel u8, ID u32, flags byte (IDE bit 7), a byte with DLC bits 0-3, EDL 4, BRS 5,
/// ESI 6, Dir 7; DataLength u8; the VLSD offset u64 at 16); record id 3 error frames
/// (13 bytes: time, BusChannel, ID); record id 4 another measurement (16 bytes), passed
/// over; and for `Layout::VlsdGroup`, record id 2 the data bytes.
fn unsorted(frames: &[Out], layout: Layout, unfinished: Option<u16>) -> Built {
    let mut mdf = Mdf::new(unfinished);
    let hd = mdf.header();
    // Time: u64 ns, linear conversion 1e-9 to seconds.
    let mut cc = vec![0u8; 24 + 16];
    cc[0] = 1;
    cc[6..8].copy_from_slice(&2u16.to_le_bytes());
    cc[32..40].copy_from_slice(&1e-9f64.to_le_bytes());
    let conversion = mdf.block(b"CC", &[0, 0, 0, 0], &cc);

    // The data bytes' signal data, and the records.
    let mut records = Vec::new();
    let mut signal = Vec::new();
    for f in frames {
        let offset = signal.len() as u64;
        if f.frame.kind == FrameKind::Error {
            records.push(3u8);
            records.extend_from_slice(&f.t_ns.to_le_bytes());
            records.push(f.frame.channel);
            records.extend_from_slice(&f.frame.id.to_le_bytes());
            continue;
        }
        let mut value = (f.frame.len() as u32).to_le_bytes().to_vec();
        value.extend_from_slice(f.frame.data());
        if layout == Layout::VlsdGroup {
            records.push(2);
            records.extend_from_slice(&value);
        }
        signal.extend_from_slice(&value);
        records.push(4);
        records.extend_from_slice(&[0x44; 16]);
        records.push(1);
        records.extend_from_slice(&f.t_ns.to_le_bytes());
        records.push(f.frame.channel);
        records.extend_from_slice(&f.frame.id.to_le_bytes());
        records.push(if f.frame.extended { 0x80 } else { 0 });
        let fd = f.frame.fd();
        records.push(
            f.frame.dlc()
                | u8::from(fd.is_some()) << 4
                | u8::from(fd.is_some_and(|x| x.brs)) << 5
                | u8::from(fd.is_some_and(|x| x.esi)) << 6
                | u8::from(f.frame.direction == Direction::Tx) << 7,
        );
        records.push(f.frame.len() as u8);
        records.extend_from_slice(&offset.to_le_bytes());
    }

    let vlsd_cg = if layout == Layout::VlsdGroup {
        mdf.group(2, 0, 1, 0, 0)
    } else {
        0
    };
    let sd = if layout == Layout::SignalBlocks {
        mdf.block(b"SD", &[], &signal)
    } else {
        0
    };
    let time = mdf.channel("Timestamp", 2, 1, 0, 0, 0, 64, conversion, 0);
    let members = [
        mdf.channel("CAN_DataFrame.BusChannel", 0, 0, 0, 8, 0, 8, 0, 0),
        mdf.channel("CAN_DataFrame.ID", 0, 0, 0, 9, 0, 29, 0, 0),
        mdf.channel("CAN_DataFrame.IDE", 0, 0, 0, 13, 7, 1, 0, 0),
        mdf.channel("CAN_DataFrame.DLC", 0, 0, 0, 14, 0, 4, 0, 0),
        mdf.channel("CAN_DataFrame.EDL", 0, 0, 0, 14, 4, 1, 0, 0),
        mdf.channel("CAN_DataFrame.BRS", 0, 0, 0, 14, 5, 1, 0, 0),
        mdf.channel("CAN_DataFrame.ESI", 0, 0, 0, 14, 6, 1, 0, 0),
        mdf.channel("CAN_DataFrame.Dir", 0, 0, 0, 14, 7, 1, 0, 0),
        mdf.channel("CAN_DataFrame.DataLength", 0, 0, 0, 15, 0, 8, 0, 0),
        mdf.channel(
            "CAN_DataFrame.DataBytes",
            1,
            0,
            10,
            16,
            0,
            64,
            0,
            if layout == Layout::VlsdGroup {
                vlsd_cg
            } else {
                sd
            },
        ),
    ];
    let id_cn = members[1];
    let first_member = mdf.chain(&members);
    let frame_cn = mdf.channel("CAN_DataFrame", 0, 0, 10, 8, 0, 16 * 8, 0, 0);
    mdf.link(frame_cn, 1, first_member);
    let data_cg = mdf.group(1, frames.len() as u64, 2, 24, 0);
    let top = mdf.chain(&[time, frame_cn]);
    mdf.link(data_cg, 1, top);

    let error_time = mdf.channel("Timestamp", 2, 1, 0, 0, 0, 64, conversion, 0);
    let error_members = [
        mdf.channel("BusChannel", 0, 0, 0, 8, 0, 8, 0, 0),
        mdf.channel("ID", 0, 0, 0, 9, 0, 32, 0, 0),
    ];
    let first_error_member = mdf.chain(&error_members);
    let error_cn = mdf.channel("CAN_ErrorFrame", 0, 0, 10, 8, 0, 5 * 8, 0, 0);
    mdf.link(error_cn, 1, first_error_member);
    let error_cg = mdf.group(3, 0, 2, 13, 0);
    let top = mdf.chain(&[error_time, error_cn]);
    mdf.link(error_cg, 1, top);

    let other_time = mdf.channel("t", 2, 1, 4, 0, 0, 64, 0, 0);
    let other_value = mdf.channel("EngineSpeed", 0, 0, 4, 8, 0, 64, 0, 0);
    let first_other = mdf.chain(&[other_time, other_value]);
    let other_cg = mdf.group(4, 0, 0, 16, first_other);

    let cgs: Vec<u64> = [data_cg, vlsd_cg, error_cg, other_cg]
        .into_iter()
        .filter(|&c| c != 0)
        .collect();
    let first_cg = mdf.chain(&cgs);
    let mut dg_data = vec![0u8; 8];
    dg_data[0] = 1;
    let dg = mdf.block(b"DG", &[0, first_cg, 0, 0], &dg_data);
    mdf.link(hd, 0, dg);
    // The data last, as a logger writes them.
    let dt = mdf.block(b"DT", &[], &records);
    mdf.link(dg, 2, dt);
    Built { mdf, dt, id_cn, dg }
}

fn sample() -> Vec<Out> {
    let at = |t_ns: u64, frame: LogFrame| Out { t_ns, frame };
    let fd = |data: &[u8], brs, esi| {
        LogFrame::new_fd(0, 1, 0x1AB, false, data, FdFlags { brs, esi }).unwrap()
    };
    let mut frames = vec![
        at(
            0,
            LogFrame::new(0, 0, 0x00C, false, FrameKind::Data, &[1, 2, 3, 4]).unwrap(),
        ),
        at(
            1_500,
            LogFrame::new(0, 2, 0x1ABC_DEF0, true, FrameKind::Data, &[0xFF; 8])
                .unwrap()
                .with_direction(Direction::Tx),
        ),
        at(2_000_000, fd(&[0x5A; 64], true, false)),
        at(
            2_500_000,
            LogFrame::new(0, 0, 0x55, false, FrameKind::Error, &[]).unwrap(),
        ),
        at(3_000_999, fd(&[7; 12], false, true)),
        at(
            4_000_000,
            LogFrame::new(0, 0, 0x7FF, false, FrameKind::Data, &[]).unwrap(),
        ),
    ];
    for f in &mut frames {
        // To the nearest microsecond (3_000_999 ns: 3_001 µs).
        f.frame.t_us = (START_NS + f.t_ns + 500) / 1000;
    }
    frames
}

fn read(bytes: Vec<u8>) -> Result<Vec<Result<LogFrame, LogError>>, String> {
    LogReader::seekable(LogFormat::Mf4, Box::new(Cursor::new(bytes)))
        .map(|r| r.collect())
        .map_err(|e| e.to_string())
}

fn frames_of(sample: &[Out]) -> Vec<LogFrame> {
    sample.iter().map(|o| o.frame).collect()
}

#[test]
fn unsorted_files_with_variable_length_data_are_read_whole() {
    let sample = sample();
    for layout in [Layout::VlsdGroup, Layout::SignalBlocks] {
        let built = unsorted(&sample, layout, None);
        let got: Vec<LogFrame> = read(built.mdf.bytes)
            .unwrap()
            .into_iter()
            .map(|f| f.unwrap())
            .collect();
        assert_eq!(got, frames_of(&sample));
    }
}

#[test]
fn an_unfinalized_file_is_read_to_where_its_data_stop() {
    let sample = sample();
    // The logger wrote the DT block's header when it began (length: the header alone),
    // then records until its power went, the last one cut short.
    let built = unsorted(&sample, Layout::VlsdGroup, Some(0x1 | 0x4));
    let mut bytes = built.mdf.bytes;
    let dt = built.dt as usize;
    bytes[dt + 8..dt + 16].copy_from_slice(&24u64.to_le_bytes());
    bytes.truncate(bytes.len() - 10);
    let got = read(bytes).unwrap();
    let frames: Vec<LogFrame> = got.iter().map(|f| *f.as_ref().unwrap()).collect();
    assert_eq!(frames, frames_of(&sample[..sample.len() - 1]));
}

#[test]
fn a_file_cut_short_keeps_the_frames_before_the_cut() {
    let sample = sample();
    let built = unsorted(&sample, Layout::VlsdGroup, None);
    let mut bytes = built.mdf.bytes;
    bytes.truncate(bytes.len() - 10);
    let got = read(bytes).unwrap();
    let (last, frames) = got.split_last().unwrap();
    let frames: Vec<LogFrame> = frames.iter().map(|f| *f.as_ref().unwrap()).collect();
    assert_eq!(frames, frames_of(&sample[..sample.len() - 1]));
    let e = last.as_ref().unwrap_err();
    assert!(e.fatal);
    assert!(
        e.to_string()
            .contains(&format!("##DT block at byte {}", built.dt))
            && e.to_string().contains("truncated file?"),
        "{e}"
    );
}

/// Damage found when the file is opened: one line naming the block and its offset.
#[test]
fn damaged_structures_are_named_with_their_block_and_offset() {
    let sample = sample();
    let fresh = || unsorted(&sample, Layout::VlsdGroup, None);

    // A block pointing outside the file.
    let mut b = fresh();
    b.mdf.link(b.dg, 2, 1 << 40);
    let e = read(b.mdf.bytes).unwrap_err();
    assert!(
        e.contains("a link to byte 1099511627776, outside the file"),
        "{e}"
    );

    // A loop in the links: the ID channel's next is itself.
    let mut b = fresh();
    b.mdf.link(b.id_cn, 0, b.id_cn);
    let e = read(b.mdf.bytes).unwrap_err();
    assert_eq!(
        e,
        format!(
            "##CN block at byte {}: the chain of blocks comes back to this one: a loop in the links (corrupt file)",
            b.id_cn
        )
    );

    // An unknown block type where data was expected.
    let mut b = fresh();
    let dt = b.dt as usize;
    b.mdf.bytes[dt + 2..dt + 4].copy_from_slice(b"XY");
    let e = read(b.mdf.bytes).unwrap_err();
    assert!(
        e.starts_with(&format!(
            "##XY block at byte {dt}: a ##DT or ##DZ or ##DL or ##HL was expected here"
        )),
        "{e}"
    );

    // An impossible bit layout: the ID at byte 22 of a 24-byte record.
    let mut b = fresh();
    let at = b.id_cn as usize + 24 + 8 * 8 + 4;
    b.mdf.bytes[at..at + 4].copy_from_slice(&22u32.to_le_bytes());
    let e = read(b.mdf.bytes).unwrap_err();
    assert_eq!(
        e,
        format!(
            "##CN block at byte {}: channel \"CAN_DataFrame.ID\": byte 22 bit 0, 29 bits do not fit the channel group's 24-byte records",
            b.id_cn
        )
    );

    // A block longer than the file.
    let mut b = fresh();
    let dg = b.dg as usize;
    b.mdf.bytes[dg + 8..dg + 16].copy_from_slice(&(1u64 << 30).to_le_bytes());
    let e = read(b.mdf.bytes).unwrap_err();
    assert!(e.starts_with(&format!("##DG block at byte {dg}: ")), "{e}");
}

/// A data block whose records do not add up (bytes left after the last whole record) and
/// a record id no channel group has: the frames before, then the error.
#[test]
fn damaged_data_keep_the_frames_before_the_damage() {
    let sample = sample();
    let b = unsorted(&sample, Layout::VlsdGroup, None);
    let mut bytes = b.mdf.bytes.clone();
    // Record id 1 of the last frame made 9: nothing after it can be placed.
    let last_frame_record = find_last_record(&bytes, b.dt, 1);
    bytes[last_frame_record] = 9;
    let got = read(bytes).unwrap();
    let (last, frames) = got.split_last().unwrap();
    assert_eq!(frames.len(), sample.len() - 1);
    let e = last.as_ref().unwrap_err();
    assert!(
        e.fatal
            && e.to_string()
                .contains("record id 9 belongs to no channel group"),
        "{e}"
    );
}

/// The offset of the last record with this id in the DT block at `dt` (records of the
/// layout `unsorted` writes).
fn find_last_record(bytes: &[u8], dt: u64, wanted: u8) -> usize {
    let length = u64::from_le_bytes(bytes[dt as usize + 8..dt as usize + 16].try_into().unwrap());
    let mut at = dt as usize + 24;
    let end = dt as usize + length as usize;
    let mut last = None;
    while at < end {
        let id = bytes[at];
        if id == wanted {
            last = Some(at);
        }
        at += 1 + match id {
            1 => 24,
            2 => 4 + u32::from_le_bytes(bytes[at + 1..at + 5].try_into().unwrap()) as usize,
            3 => 13,
            _ => 16,
        };
    }
    last.unwrap()
}

/// The growing layout (what the gateway records): read back whole once finished, and
/// after a "crash" (the writer dropped after handing its records over, the file never
/// finished) read to its last record, a record cut in half at the end included.
#[test]
fn a_growing_recording_reads_whole_and_after_a_crash() {
    let frames: Vec<LogFrame> = frames_of(&sample())
        .into_iter()
        .chain((0..500u64).map(|i| {
            let speed = autoplug_can::Frame::new(0x003, &[(i % 200) as u8]).unwrap();
            LogFrame::from_can(1_700_000_010_000_000 + i * 10_000, 0, &speed)
        }))
        .collect();
    let mut finished = Vec::new();
    let mut writer = autoplug_logs::Mf4Writer::growing(Cursor::new(&mut finished)).unwrap();
    for f in &frames {
        writer.write(f).unwrap();
    }
    assert_eq!(writer.decoded, 501, "the 500 speeds and the sample's 0x00C");
    writer.finish().unwrap();
    assert!(finished.starts_with(b"MDF     "));
    let got: Vec<LogFrame> = read(finished)
        .unwrap()
        .into_iter()
        .map(|f| f.unwrap())
        .collect();
    assert!(
        got == frames,
        "one data group, the file's order: {} frames",
        got.len()
    );

    let mut crashed = Vec::new();
    let mut writer = autoplug_logs::Mf4Writer::growing(Cursor::new(&mut crashed)).unwrap();
    for f in &frames[..300] {
        writer.write(f).unwrap();
    }
    writer.flush_data().unwrap();
    for f in &frames[300..] {
        // Written after the last flush: lost with the crash.
        writer.write(f).unwrap();
    }
    drop(writer);
    assert!(crashed.starts_with(b"UnFinMF "));
    let got: Vec<LogFrame> = read(crashed.clone())
        .unwrap()
        .into_iter()
        .map(|f| f.unwrap())
        .collect();
    assert!(got == frames[..300], "{} frames", got.len());
    // Power lost in the middle of a record: the last frame's decoded record (13 bytes)
    // and the end of its bus record.
    crashed.truncate(crashed.len() - 20);
    let got: Vec<LogFrame> = read(crashed)
        .unwrap()
        .into_iter()
        .map(|f| f.unwrap())
        .collect();
    assert!(got == frames[..299], "{} frames", got.len());
}

/// The reader takes the records whole in its buffer many at a time, and hands the others
/// (an FD frame, a remote frame's record among them, one it refuses) to its one-record
/// path: across hundreds of records, the frames come out the same and in order, and the
/// refused record's error comes out in its place with every frame around it kept. Sorted
/// (one data group a frame type) and as a recording grows (one unsorted data group).
#[test]
fn records_read_many_at_a_time_come_out_as_one_at_a_time() {
    let marker = [0xA5, 0x5A, 0xC3, 0x3C, 0x96, 0x69, 0x0F, 0xF0];
    let frames: Vec<LogFrame> = (0..700u32)
        .map(|k| {
            let t_us = 1_000_000 + 997 * u64::from(k);
            match k {
                300 => LogFrame::new(t_us, 0, 0x123, false, FrameKind::Data, &marker).unwrap(),
                200 | 450 => LogFrame::new_fd(
                    t_us,
                    1,
                    0x1AB,
                    false,
                    &[k as u8; 12],
                    FdFlags {
                        brs: true,
                        esi: false,
                    },
                )
                .unwrap(),
                420 => LogFrame::remote(t_us, 0, 0x2F0, false, 3).unwrap(),
                _ => LogFrame::new(
                    t_us,
                    (k % 3) as u8,
                    k % 0x7FF,
                    k % 5 == 0,
                    FrameKind::Data,
                    &k.to_le_bytes()[..(k % 9) as usize % 5],
                )
                .unwrap()
                .with_direction(if k % 7 == 0 {
                    Direction::Tx
                } else {
                    Direction::Rx
                }),
            }
        })
        .collect();
    for growing in [false, true] {
        let mut writer = if growing {
            autoplug_logs::Mf4Writer::growing(Cursor::new(Vec::new())).unwrap()
        } else {
            autoplug_logs::Mf4Writer::new(Cursor::new(Vec::new()), false).unwrap()
        };
        for f in &frames {
            writer.write(f).unwrap();
        }
        let bytes = writer.finish().unwrap().into_inner();
        let got: Vec<LogFrame> = read(bytes.clone())
            .unwrap()
            .into_iter()
            .map(|f| f.unwrap())
            .collect();
        assert_eq!(got, frames, "growing: {growing}");

        // Frame 300's identifier made 0x800 without IDE: a record the reader refuses.
        let data_at = bytes
            .windows(8)
            .position(|w| w == marker)
            .expect("the marker's data bytes");
        let mut damaged = bytes;
        // The record: time (8), BusChannel, ID (4), IDE, DLC, DataLength, DataBytes.
        damaged[data_at - 7..data_at - 3].copy_from_slice(&0x800u32.to_le_bytes());
        let got = read(damaged).unwrap();
        assert_eq!(got.len(), frames.len(), "growing: {growing}");
        for (k, (got, want)) in got.iter().zip(&frames).enumerate() {
            match (k, got) {
                (300, Err(e)) => {
                    assert!(!e.fatal);
                    assert!(
                        e.to_string()
                            .contains("identifier 0x800 does not fit 11 bits"),
                        "{e}"
                    );
                }
                (_, Ok(f)) => assert_eq!(f, want, "frame {k}, growing: {growing}"),
                (_, other) => panic!("frame {k}, growing: {growing}: {other:?}"),
            }
        }
    }
}
