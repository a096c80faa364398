//! Writing Vector's binary logging format (BLF), which CANalyzer, CANoe and python-can read:
//! the layout [`crate::read::blf`] reads, written as Vector's tools write it.
//!
//! Our own writer, beside our own reader (see there why no crate): a file header that
//! `finish` completes (sizes, object count, the measurement's start and end: the output
//! must be seekable), then LOG_CONTAINER objects of about 128 KiB each, zlib-compressed,
//! holding one object a frame: CAN_MESSAGE2 for data and remote frames, CAN_ERROR_EXT for
//! error frames, CAN_FD_MESSAGE_64 for CAN FD frames. Every object has a version 1 header with its time in nanoseconds since
//! the measurement start, so a frame's microseconds come back exactly.
//!
//! The measurement start: for a log in Unix time (anything after 2000), a whole second
//! at least one second before the first frame, which the file header holds to the
//! millisecond; a frame earlier than that is refused (BLF times count up from the start).
//! For a log in time since its own start (ASC), no date (all zero), times as they are.

use std::io::{self, Seek, SeekFrom, Write};

use flate2::write::ZlibEncoder;
use flate2::Compression;

use crate::frame::{Direction, FdFlags, FrameKind, LogFrame};
use crate::time::Utc;

/// The file header's size, as Vector's tools and python-can write it.
const FILE_HEADER: usize = 144;
/// Inner objects gathered before a container is compressed and written (as Vector's
/// loggers: a reader holds one container in memory at a time).
const CONTAINER_BYTES: usize = 128 * 1024;
/// An object's header (version 1): the base header, flags, client index, object
/// version and the timestamp.
const OBJECT_HEADER: usize = 32;

const LOG_CONTAINER: u32 = 10;
const CAN_ERROR_EXT: u32 = 73;
const CAN_MESSAGE2: u32 = 86;
const CAN_FD_MESSAGE: u32 = 100;
const CAN_FD_MESSAGE_64: u32 = 101;
/// CAN_FD_MESSAGE_64's flags: a CAN FD frame (EDL), bit rate switch, error state indicator.
const FD_EDL: u32 = 0x1000;
const FD_BRS: u32 = 0x2000;
const FD_ESI: u32 = 0x4000;
/// The object header's flag: its timestamp counts nanoseconds.
const TIME_ONE_NANS: u32 = 2;
const EXTENDED_FLAG: u32 = 0x8000_0000;
/// A CAN message's flags: transmitted by the logging interface, and a remote frame.
const TX_FLAG: u8 = 0x01;
const REMOTE_FLAG: u8 = 0x80;
/// Times from 2000-01-01 on are Unix times; earlier ones count from the log's own start.
const UNIX_TIME_FROM_US: u64 = 946_684_800_000_000;

/// Writes frames as BLF; see the [module](self).
pub struct BlfWriter<W: Write + Seek> {
    out: W,
    /// The measurement start in Unix µs (`Some`), or none (times since the log's start):
    /// decided by the first frame.
    start: Option<Option<u64>>,
    /// Inner objects not yet in a container.
    pending: Vec<u8>,
    /// Inner objects written, and their bytes uncompressed.
    objects: u32,
    inner_bytes: u64,
    /// Bytes of the file so far (the header's included).
    file_bytes: u64,
    last_us: u64,
    level: Compression,
}

impl<W: Write + Seek> BlfWriter<W> {
    /// A writer at the start of `out`; the header is completed by [`BlfWriter::finish`].
    pub fn new(mut out: W) -> io::Result<Self> {
        out.write_all(&[0u8; FILE_HEADER])?;
        Ok(Self {
            out,
            start: None,
            pending: Vec::with_capacity(CONTAINER_BYTES + 64),
            objects: 0,
            inner_bytes: 0,
            file_bytes: FILE_HEADER as u64,
            last_us: 0,
            level: Compression::default(),
        })
    }

    /// The zlib level of the containers (the default: 6, as Vector's tools).
    pub fn with_compression(mut self, level: u32) -> Self {
        self.level = Compression::new(level.min(9));
        self
    }

    /// Writes one frame.
    pub fn write(&mut self, frame: &LogFrame) -> io::Result<()> {
        let start = *self.start.get_or_insert_with(|| {
            (frame.t_us >= UNIX_TIME_FROM_US)
                .then(|| (frame.t_us - 1_000_000) / 1_000_000 * 1_000_000)
        });
        let since_start = frame.t_us.checked_sub(start.unwrap_or(0)).ok_or_else(|| {
            io::Error::new(
                io::ErrorKind::InvalidInput,
                format!(
                    "a frame at {} µs comes more than a second before the first: BLF times count up from the measurement's start",
                    frame.t_us
                ),
            )
        })?;
        self.last_us = self.last_us.max(frame.t_us);
        let channel = u16::from(frame.channel) + 1;
        let t_ns = since_start.saturating_mul(1000);
        let id = frame.id | if frame.extended { EXTENDED_FLAG } else { 0 };
        if let Some(fd) = frame.fd() {
            self.fd_object(frame, fd, channel, id, t_ns);
        } else {
            self.classic_object(frame, channel, id, t_ns);
        }
        if self.pending.len() >= CONTAINER_BYTES {
            self.flush_container()?;
        }
        Ok(())
    }

    /// A CAN FD frame: CAN_FD_MESSAGE_64 as CANoe writes it, or CAN_FD_MESSAGE (whose
    /// channel field is wider) on channel 256.
    fn fd_object(&mut self, frame: &LogFrame, fd: FdFlags, channel: u16, id: u32, t_ns: u64) {
        let tx = frame.direction == Direction::Tx;
        if let Ok(channel) = u8::try_from(channel) {
            // channel u8, DLC u8, valid bytes u8, tx count u8, identifier u32, frame
            // length (ns) u32, flags u32, 4 × u32 bit timing, bit count u16, direction u8,
            // extended data offset u8, CRC u32, data (padded to 4 bytes).
            let mut body = [0u8; 40 + 64];
            body[0] = channel;
            body[1] = frame.dlc();
            body[2] = frame.len() as u8;
            body[4..8].copy_from_slice(&id.to_le_bytes());
            let flags = FD_EDL | if fd.brs { FD_BRS } else { 0 } | if fd.esi { FD_ESI } else { 0 };
            body[12..16].copy_from_slice(&flags.to_le_bytes());
            body[34] = u8::from(tx);
            body[40..40 + frame.len()].copy_from_slice(frame.data());
            let size = 40 + frame.len().next_multiple_of(4);
            self.object(CAN_FD_MESSAGE_64, t_ns, &body[..size]);
        } else {
            // channel u16, flags u8, DLC u8, identifier u32, frame length u32, bit count
            // u8, FD flags u8 (EDL, BRS, ESI), valid bytes u8, reserved[5], data[64].
            let mut body = [0u8; 20 + 64];
            body[0..2].copy_from_slice(&channel.to_le_bytes());
            body[2] = if tx { TX_FLAG } else { 0 };
            body[3] = frame.dlc();
            body[4..8].copy_from_slice(&id.to_le_bytes());
            body[13] = 0x01 | u8::from(fd.brs) << 1 | u8::from(fd.esi) << 2;
            body[14] = frame.len() as u8;
            body[20..20 + frame.len()].copy_from_slice(frame.data());
            self.object(CAN_FD_MESSAGE, t_ns, &body);
        }
    }

    /// A classic frame: CAN_MESSAGE2, or CAN_ERROR_EXT for an error frame.
    fn classic_object(&mut self, frame: &LogFrame, channel: u16, id: u32, t_ns: u64) {
        let mut data = [0u8; 8];
        data[..frame.data().len()].copy_from_slice(frame.data());
        match frame.kind {
            FrameKind::Data | FrameKind::Remote => {
                let mut flags = 0;
                if frame.direction == Direction::Tx {
                    flags |= TX_FLAG;
                }
                if frame.kind == FrameKind::Remote {
                    flags |= REMOTE_FLAG;
                }
                // channel u16, flags u8, DLC u8, identifier u32, data[8], frame length
                // (ns) u32, bit count u8, reserved u8 + u16.
                let mut body = [0u8; 24];
                body[0..2].copy_from_slice(&channel.to_le_bytes());
                body[2] = flags;
                body[3] = frame.len() as u8;
                body[4..8].copy_from_slice(&id.to_le_bytes());
                body[8..16].copy_from_slice(&data);
                self.object(CAN_MESSAGE2, t_ns, &body);
            }
            FrameKind::Error => {
                // channel u16, length u16, flags u32, ECC u8, position u8, DLC u8,
                // reserved u8, frame length u32, identifier u32, extended flags u16,
                // reserved u16, data[8].
                let mut body = [0u8; 32];
                body[0..2].copy_from_slice(&channel.to_le_bytes());
                body[10] = frame.len() as u8;
                body[16..20].copy_from_slice(&id.to_le_bytes());
                body[24..32].copy_from_slice(&data);
                self.object(CAN_ERROR_EXT, t_ns, &body);
            }
        }
    }

    /// Appends one inner object (its size a multiple of 4: no padding).
    fn object(&mut self, kind: u32, t_ns: u64, body: &[u8]) {
        let size = (OBJECT_HEADER + body.len()) as u32;
        let o = &mut self.pending;
        o.extend_from_slice(b"LOBJ");
        o.extend_from_slice(&(OBJECT_HEADER as u16).to_le_bytes());
        o.extend_from_slice(&1u16.to_le_bytes());
        o.extend_from_slice(&size.to_le_bytes());
        o.extend_from_slice(&kind.to_le_bytes());
        o.extend_from_slice(&TIME_ONE_NANS.to_le_bytes());
        o.extend_from_slice(&[0u8; 4]); // client index, object version
        o.extend_from_slice(&t_ns.to_le_bytes());
        o.extend_from_slice(body);
        self.objects += 1;
        self.inner_bytes += u64::from(size);
    }

    /// Compresses the pending objects into a LOG_CONTAINER and writes it.
    fn flush_container(&mut self) -> io::Result<()> {
        if self.pending.is_empty() {
            return Ok(());
        }
        let mut zlib = ZlibEncoder::new(Vec::with_capacity(self.pending.len() / 3), self.level);
        zlib.write_all(&self.pending)?;
        let packed = zlib.finish()?;
        let size = OBJECT_HEADER + packed.len();
        let mut head = [0u8; OBJECT_HEADER];
        head[0..4].copy_from_slice(b"LOBJ");
        head[4..6].copy_from_slice(&16u16.to_le_bytes());
        head[6..8].copy_from_slice(&1u16.to_le_bytes());
        head[8..12].copy_from_slice(&(size as u32).to_le_bytes());
        head[12..16].copy_from_slice(&LOG_CONTAINER.to_le_bytes());
        // Compression method 2 (zlib), reserved, the inflated size, reserved.
        head[16..18].copy_from_slice(&2u16.to_le_bytes());
        head[24..28].copy_from_slice(&(self.pending.len() as u32).to_le_bytes());
        self.out.write_all(&head)?;
        self.out.write_all(&packed)?;
        let padding = size % 4;
        self.out.write_all(&[0u8; 3][..padding])?;
        self.file_bytes += (size + padding) as u64;
        self.pending.clear();
        Ok(())
    }

    /// Writes the last container and completes the file header; hands back the output.
    pub fn finish(mut self) -> io::Result<W> {
        self.flush_container()?;
        let start = self.start.flatten();
        let mut header = [0u8; FILE_HEADER];
        header[0..4].copy_from_slice(b"LOGG");
        header[4..8].copy_from_slice(&(FILE_HEADER as u32).to_le_bytes());
        // The writing application (0: none of Vector's) and the format's version.
        header[12..16].copy_from_slice(&[4, 7, 1, 0]);
        header[16..24].copy_from_slice(&self.file_bytes.to_le_bytes());
        header[24..32].copy_from_slice(&(FILE_HEADER as u64 + self.inner_bytes).to_le_bytes());
        header[32..36].copy_from_slice(&self.objects.to_le_bytes());
        if let Some(start_us) = start {
            header[40..56].copy_from_slice(&system_time(start_us));
            header[56..72].copy_from_slice(&system_time(self.last_us.max(start_us)));
        }
        self.out.flush()?;
        self.out.seek(SeekFrom::Start(0))?;
        self.out.write_all(&header)?;
        self.out.seek(SeekFrom::End(0))?;
        self.out.flush()?;
        Ok(self.out)
    }
}

/// A Windows SYSTEMTIME (year, month, weekday, day, hour, minute, second, millisecond:
/// eight u16), UTC.
fn system_time(t_us: u64) -> [u8; 16] {
    let utc = Utc::from_unix_us(t_us);
    let fields = [
        utc.year.clamp(0, i64::from(u16::MAX)) as u16,
        utc.month as u16,
        utc.weekday as u16,
        utc.day as u16,
        utc.hour as u16,
        utc.minute as u16,
        utc.second as u16,
        (utc.micros / 1000) as u16,
    ];
    let mut bytes = [0u8; 16];
    for (i, field) in fields.iter().enumerate() {
        bytes[2 * i..2 * i + 2].copy_from_slice(&field.to_le_bytes());
    }
    bytes
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::read::BlfReader;
    use std::io::Cursor;

    fn frames(t0: u64) -> Vec<LogFrame> {
        let mut remote = LogFrame::remote(t0 + 2_500, 1, 0x1AB, false, 4).unwrap();
        remote.direction = Direction::Tx;
        vec![
            LogFrame::new(t0, 0, 0x0C8, false, FrameKind::Data, &[1, 2, 3]).unwrap(),
            LogFrame::new(t0 + 1, 0, 0x18DB_33F1, true, FrameKind::Data, &[0xFF; 8]).unwrap(),
            remote,
            LogFrame::new(t0 + 999_999, 2, 0, false, FrameKind::Error, &[]).unwrap(),
            LogFrame::new(t0 + 1_000_000, 0, 0x7FF, false, FrameKind::Data, &[]).unwrap(),
            fd(t0 + 1_000_001, 0, &[0xA5; 12], true, false).with_direction(Direction::Tx),
            fd(t0 + 1_000_002, 1, &[0x5A; 64], false, true),
            fd(t0 + 1_000_003, 0, &[1, 2, 3], false, false),
            // Channel 256: CAN_FD_MESSAGE, whose channel field is 16 bits.
            fd(t0 + 1_000_004, 255, &[9; 20], true, true).with_direction(Direction::Tx),
        ]
    }

    fn fd(t_us: u64, channel: u8, data: &[u8], brs: bool, esi: bool) -> LogFrame {
        LogFrame::new_fd(t_us, channel, 0x1AB, false, data, FdFlags { brs, esi }).unwrap()
    }

    fn round_trip(written: &[LogFrame]) -> (Vec<LogFrame>, Option<u64>, u32) {
        let mut writer = BlfWriter::new(Cursor::new(Vec::new())).unwrap();
        for frame in written {
            writer.write(frame).unwrap();
        }
        let bytes = writer.finish().unwrap().into_inner();
        let reader = BlfReader::new(&bytes[..]).unwrap();
        let (start, count) = (reader.start_us(), reader.object_count());
        let read: Vec<LogFrame> = reader.map(|f| f.unwrap()).collect();
        (read, start, count)
    }

    #[test]
    fn unix_times_come_back_to_the_microsecond() {
        let t0 = 1_700_000_000_123_457;
        let written = frames(t0);
        let (read, start, count) = round_trip(&written);
        assert_eq!(read, written);
        assert_eq!(
            start,
            Some(1_699_999_999_000_000),
            "a whole second before the first"
        );
        assert_eq!(count, written.len() as u32);
    }

    #[test]
    fn times_since_the_start_stay_so() {
        let written = frames(0);
        let (read, start, _) = round_trip(&written);
        assert_eq!(read, written);
        assert_eq!(start, None);
    }

    #[test]
    fn many_frames_fill_several_containers() {
        let t0 = 1_700_000_000_000_000;
        let written: Vec<LogFrame> = (0..20_000u64)
            .map(|i| {
                LogFrame::new(
                    t0 + i * 137,
                    (i % 3) as u8,
                    (i % 0x7FF) as u32,
                    false,
                    FrameKind::Data,
                    &i.to_le_bytes(),
                )
                .unwrap()
            })
            .collect();
        let (read, _, count) = round_trip(&written);
        assert_eq!(read.len(), written.len());
        assert_eq!(read, written);
        assert_eq!(count, 20_000);
    }

    #[test]
    fn a_frame_before_the_measurement_start_is_refused() {
        let t0 = 1_700_000_000_500_000;
        let mut writer = BlfWriter::new(Cursor::new(Vec::new())).unwrap();
        writer.write(&frames(t0)[0]).unwrap();
        let early = LogFrame::new(t0 - 1_600_000, 0, 1, false, FrameKind::Data, &[]).unwrap();
        let error = writer.write(&early).unwrap_err();
        assert_eq!(error.kind(), io::ErrorKind::InvalidInput);
        assert!(error.to_string().contains("before the first"), "{error}");
        // Within the second before the first frame is fine.
        let close = LogFrame::new(t0 - 400_000, 0, 1, false, FrameKind::Data, &[]).unwrap();
        writer.write(&close).unwrap();
    }
}
