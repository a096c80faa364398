//! Vector's binary logging format (BLF), as CANoe, CANalyzer and python-can write it.
//!
//! Our own minimal reader rather than a crate: when this was written (2026-11), `ablf`
//! 0.2.1 reads only CAN_MESSAGE2 (not CAN_MESSAGE, which python-can writes), reports no
//! errors (a bad object silently ends the iteration), prints to stdout on bad magic and
//! panics on a corrupt zlib container or an unknown compression method; `blf_asc` 0.2.0
//! gives timestamps as `f64` seconds (so microseconds of Unix time are not exact), opens
//! only a path, allocates whatever size a corrupt object header claims, and loops forever
//! on an inner object of a type it skips whose size field is 0. BLF for classic CAN needs
//! little: this reader takes a `Read`, keeps one log container in memory at a time and
//! never trusts a size it has not bounded.
//!
//! Layout (little-endian throughout):
//! - a file header: `LOGG`, its size, application and version bytes, file sizes, the
//!   object count, and the measurement start and end as Windows SYSTEMTIMEs;
//! - then objects, each `LOBJ`, header size (u16), header version (u16), object size
//!   (u32), object type (u32), usually followed by `object size % 4` padding bytes. Some
//!   types have none: CANoe writes Ethernet frames and errors (Ex and forwarded), FlexRay
//!   VFR receive Ex, test structures and diagnostic request interpretations unpadded, so
//!   the next `LOBJ` is taken straight after an object or after its padding, as python-can
//!   and Vector's own reader do. Almost all outer objects are LOG_CONTAINERs (type 10)
//!   holding a zlib-compressed (or stored) run of further objects; an inner object may
//!   continue in the next container.
//! - Inner objects have a v1 or v2 header carrying flags (timestamp unit: 10 µs or 1 ns)
//!   and a 64-bit timestamp relative to the measurement start.
//!
//! Read: CAN_MESSAGE (1), CAN_MESSAGE2 (86), CAN_ERROR (2), CAN_ERROR_EXT (73), and
//! CAN_FD_MESSAGE (100) and CAN_FD_MESSAGE_64 (101), classic or CAN FD (EDL). Other objects (statistics, markers, other buses) are
//! skipped. Errors name the object by its 1-based number among the inner objects
//! (containers are not counted). A damaged structure (bad signature, truncated file,
//! corrupt zlib data) ends the read with one fatal error: nothing after it can be
//! trusted. What precedes the damage is kept: the whole objects of a container cut short
//! (a logger that lost power) or whose zlib data breaks off are read first, as far as its
//! bytes go or inflate, and the fatal error comes after them.
//!
//! `t_us` is the measurement start from the file header (taken as UTC; python-can writes
//! UTC, to the millisecond) plus the object's time, rounded to the microsecond. A file
//! with no start date gives times since the start of the measurement.

use std::io::{self, Read};

use flate2::read::ZlibDecoder;

use super::LogError;
use crate::frame::{dlc_to_len, Direction, FdFlags, FrameKind, LogFrame, MAX_EXTENDED_ID};
use crate::time::Utc;

/// Size of the part of the file header this reader uses.
const FILE_HEADER: usize = 72;
/// Largest file header accepted (python-can and Vector write 144 bytes).
const MAX_FILE_HEADER: u32 = 64 * 1024;
/// Size of an object's base header (`LOBJ` ... type).
const BASE_HEADER: usize = 16;
/// Size of a LOG_CONTAINER's own header after the base header.
const CONTAINER_HEADER: usize = 16;
/// Largest object accepted, inner or outer. Containers hold about 128 KiB; CAN objects
/// are under 100 bytes. A bigger size field is corruption, and is refused before
/// anything of that size is allocated.
const MAX_OBJECT: u32 = 16 * 1024 * 1024;
/// Largest inflated container accepted (protects against zlib bombs).
const MAX_INFLATED: u64 = 16 * 1024 * 1024;

const LOG_CONTAINER: u32 = 10;
const CAN_MESSAGE: u32 = 1;
const CAN_ERROR: u32 = 2;
const CAN_ERROR_EXT: u32 = 73;
const CAN_MESSAGE2: u32 = 86;
const CAN_FD_MESSAGE: u32 = 100;
const CAN_FD_MESSAGE_64: u32 = 101;

const EXTENDED_FLAG: u32 = 0x8000_0000;

/// Reads a BLF file object by object; see the [module](self).
pub struct BlfReader<R> {
    input: R,
    start_us: Option<u64>,
    object_count: u32,
    /// Bytes of the file consumed so far (for error messages).
    offset: u64,
    /// Inner objects not yet parsed: `buf[pos..]`.
    buf: Vec<u8>,
    pos: usize,
    /// Padding the last inner object would have (`size % 4`): the next `LOBJ` is
    /// straight after the object or after these bytes.
    padding: usize,
    /// Bytes read after an outer object that start the next one's header (an outer object
    /// written without its padding).
    carry: Vec<u8>,
    /// Damage found in the last container read (cut short, corrupt zlib data): reported
    /// as the fatal error once the objects before it are read.
    damage: Option<String>,
    /// Inner objects read so far.
    objects: u64,
    /// Compressed bytes of the container being read (reused).
    packed: Vec<u8>,
    input_done: bool,
    done: bool,
}

/// What one inner object gave.
enum Parsed {
    Frame(LogFrame),
    Skip,
    Bad(String),
}

fn u16_at(b: &[u8], at: usize) -> u16 {
    u16::from_le_bytes([b[at], b[at + 1]])
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
}

fn u64_at(b: &[u8], at: usize) -> u64 {
    let mut bytes = [0u8; 8];
    bytes.copy_from_slice(&b[at..at + 8]);
    u64::from_le_bytes(bytes)
}

/// Reads as much of `buf` as the input has; the count read (short only at the end).
fn read_full(input: &mut impl Read, buf: &mut [u8]) -> io::Result<usize> {
    let mut done = 0;
    while done < buf.len() {
        match input.read(&mut buf[done..]) {
            Ok(0) => break,
            Ok(n) => done += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(done)
}

fn invalid(message: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidData, message)
}

fn show(bytes: &[u8]) -> String {
    bytes
        .iter()
        .map(|b| format!("{b:02X}"))
        .collect::<Vec<_>>()
        .join(" ")
}

impl<R: Read> BlfReader<R> {
    /// Reads the file header; `ErrorKind::InvalidData` if this is not a BLF file.
    pub fn new(mut input: R) -> io::Result<Self> {
        let mut header = [0u8; FILE_HEADER];
        let n = read_full(&mut input, &mut header)?;
        if n < 4 || &header[..4] != b"LOGG" {
            return Err(invalid(format!(
                "not a BLF file: it starts with [{}] instead of \"LOGG\"",
                show(&header[..n.min(4)])
            )));
        }
        if n < FILE_HEADER {
            return Err(invalid(format!(
                "BLF file header cut short: {n} bytes, at least {FILE_HEADER} expected (truncated file?)"
            )));
        }
        let header_size = u32_at(&header, 4);
        if !(FILE_HEADER as u32..=MAX_FILE_HEADER).contains(&header_size) {
            return Err(invalid(format!(
                "BLF file header size {header_size} is not possible (corrupt file?)"
            )));
        }
        let rest = u64::from(header_size) - FILE_HEADER as u64;
        let skipped = io::copy(&mut (&mut input).take(rest), &mut io::sink())?;
        if skipped < rest {
            return Err(invalid(format!(
                "BLF file header cut short: {} of {header_size} bytes (truncated file?)",
                FILE_HEADER as u64 + skipped
            )));
        }
        let st: Vec<u32> = (0..8)
            .map(|i| u32::from(u16_at(&header, 40 + 2 * i)))
            .collect();
        let start_us = if st[0] == 0 {
            None
        } else {
            Utc {
                year: i64::from(st[0]),
                month: st[1],
                weekday: st[2],
                day: st[3],
                hour: st[4],
                minute: st[5],
                second: st[6],
                micros: st[7].saturating_mul(1000),
            }
            .to_unix_us()
        };
        Ok(Self {
            input,
            start_us,
            object_count: u32_at(&header, 32),
            offset: u64::from(header_size),
            buf: Vec::new(),
            pos: 0,
            padding: 0,
            carry: Vec::new(),
            damage: None,
            objects: 0,
            packed: Vec::new(),
            input_done: false,
            done: false,
        })
    }

    /// The measurement start from the file header, in Unix microseconds (`None` when
    /// the file gives none or an impossible date: times are then since the start).
    pub fn start_us(&self) -> Option<u64> {
        self.start_us
    }

    /// The object count the file header claims (containers not included).
    pub fn object_count(&self) -> u32 {
        self.object_count
    }

    fn fatal(&self, message: String) -> LogError {
        LogError::at_object(self.objects + 1, message).into_fatal()
    }

    fn io_error(&self, e: &io::Error) -> LogError {
        LogError::at_object(self.objects + 1, format!("cannot read the file: {e}")).into_fatal()
    }

    /// Loads the next outer object into `buf`; `false` at the end of the file.
    fn fill(&mut self) -> Result<bool, LogError> {
        if self.input_done {
            return Ok(false);
        }
        if self.pos > 0 {
            self.buf.drain(..self.pos);
            self.pos = 0;
        }
        let at = self.offset - self.carry.len() as u64;
        let mut base = [0u8; BASE_HEADER];
        let carried = self.carry.len();
        base[..carried].copy_from_slice(&self.carry);
        self.carry.clear();
        let n = carried
            + read_full(&mut self.input, &mut base[carried..]).map_err(|e| self.io_error(&e))?;
        self.offset += (n - carried) as u64;
        if n < BASE_HEADER {
            self.input_done = true;
            if base[..n].iter().all(|&b| b == 0) {
                return Ok(false);
            }
            return Err(self.fatal(format!(
                "the file ends inside an object header at byte {at} (truncated file?)"
            )));
        }
        if &base[..4] != b"LOBJ" {
            return Err(self.fatal(format!(
                "byte {at}: expected an object (\"LOBJ\"), found [{}]: corrupt file",
                show(&base[..4])
            )));
        }
        let size = u32_at(&base, 8);
        let kind = u32_at(&base, 12);
        if size < BASE_HEADER as u32 || size > MAX_OBJECT {
            return Err(self.fatal(format!(
                "byte {at}: object size {size} is not possible: corrupt file"
            )));
        }
        let size = size as usize;
        let padding = size % 4;
        let truncated = |me: &Self| {
            me.fatal(format!(
                "the file ends inside the object at byte {at} ({size} bytes): truncated file?"
            ))
        };
        if kind != LOG_CONTAINER {
            // An object outside any container: parse it as an inner one.
            self.buf.extend_from_slice(&base);
            let start = self.buf.len();
            self.buf.resize(start + size - BASE_HEADER, 0);
            let n = read_full(&mut self.input, &mut self.buf[start..])
                .map_err(|e| self.io_error(&e))?;
            self.offset += n as u64;
            if n < size - BASE_HEADER {
                // Its bytes present go to the parser, which reports the object cut short.
                self.buf.truncate(start + n);
                self.input_done = true;
                return Ok(true);
            }
            self.read_padding(padding)?;
            return Ok(true);
        }
        if size < BASE_HEADER + CONTAINER_HEADER {
            return Err(self.fatal(format!(
                "byte {at}: log container of {size} bytes is too small for its header: corrupt file"
            )));
        }
        let mut header = [0u8; CONTAINER_HEADER];
        let n = read_full(&mut self.input, &mut header).map_err(|e| self.io_error(&e))?;
        self.offset += n as u64;
        if n < CONTAINER_HEADER {
            return Err(truncated(self));
        }
        let method = u16_at(&header, 0);
        let inflated_size = u32_at(&header, 8);
        let packed_len = size - BASE_HEADER - CONTAINER_HEADER;
        self.packed.resize(packed_len, 0);
        let n = read_full(&mut self.input, &mut self.packed).map_err(|e| self.io_error(&e))?;
        self.offset += n as u64;
        if n < packed_len {
            // A logger that lost power: what the container's bytes present hold is read
            // before the error.
            self.packed.truncate(n);
            self.input_done = true;
            self.damage = Some(format!(
                "the file ends inside the log container at byte {at} ({} of its {size} bytes present): truncated file?",
                BASE_HEADER + CONTAINER_HEADER + n
            ));
        } else {
            self.read_padding(padding)?;
        }
        match method {
            0 => self.buf.extend_from_slice(&self.packed),
            2 => {
                let before = self.buf.len();
                let result = ZlibDecoder::new(&self.packed[..])
                    .take(MAX_INFLATED + 1)
                    .read_to_end(&mut self.buf);
                let inflated = self.buf.len() - before;
                if inflated as u64 > MAX_INFLATED {
                    return Err(self.fatal(format!(
                        "log container at byte {at} inflates to more than {MAX_INFLATED} bytes: corrupt file"
                    )));
                }
                // A container cut short inflates exactly as far as its bytes go: that is
                // kept. Corrupt data is another matter: deflate has no checksum before the
                // end, so nothing it gave can be trusted, and the container is dropped.
                if self.damage.is_none() {
                    let corrupt = match result {
                        Err(e) => Some(format!(
                            "log container at byte {at}: zlib data is corrupt ({e})"
                        )),
                        Ok(_) if inflated != inflated_size as usize => Some(format!(
                            "log container at byte {at}: zlib data gives {inflated} bytes, the container says {inflated_size}: corrupt file"
                        )),
                        Ok(_) => None,
                    };
                    if let Some(why) = corrupt {
                        self.buf.truncate(before);
                        self.input_done = true;
                        self.damage = Some(why);
                    }
                }
            }
            m => {
                return Err(self.fatal(format!(
                    "log container at byte {at}: unknown compression method {m}"
                )))
            }
        }
        Ok(true)
    }

    /// Reads the `padding` bytes after an outer object. If they start a `LOBJ` instead
    /// (an object written without padding), they are kept for the next object's header.
    fn read_padding(&mut self, padding: usize) -> Result<(), LogError> {
        let mut pad = [0u8; 3];
        let n = read_full(&mut self.input, &mut pad[..padding]).map_err(|e| self.io_error(&e))?;
        self.offset += n as u64;
        if n > 0 && b"LOBJ".starts_with(&pad[..n]) {
            self.carry.extend_from_slice(&pad[..n]);
        }
        Ok(())
    }

    /// Makes `n` bytes available at `pos`; `false` if the file ends first.
    fn ensure(&mut self, n: usize) -> Result<bool, LogError> {
        while self.buf.len() - self.pos < n {
            if !self.fill()? {
                return Ok(false);
            }
        }
        Ok(true)
    }

    /// The next inner object; `None` at a clean end of the file.
    fn next_object(&mut self) -> Result<Option<Parsed>, LogError> {
        let padding = std::mem::take(&mut self.padding);
        if !self.ensure(BASE_HEADER)? {
            let rest = &self.buf[self.pos..];
            if let Some(damage) = self.damage.take() {
                return Err(self.fatal(damage));
            }
            // The last object's padding, or zeros a writer left at the end.
            if rest.len() <= padding || rest.iter().all(|&b| b == 0) {
                return Ok(None);
            }
            return Err(self.fatal(format!(
                "the file ends inside object {} ({} bytes of it present): truncated file?",
                self.objects + 1,
                rest.len()
            )));
        }
        if &self.buf[self.pos..self.pos + 4] != b"LOBJ" {
            // The object before had its padding (or a writer padded with a few more zero
            // bytes): `LOBJ` follows a little further on.
            let window = &self.buf[self.pos..self.pos + BASE_HEADER];
            match window.windows(4).position(|w| w == b"LOBJ") {
                Some(k) if k <= padding || (k < 8 && window[..k].iter().all(|&b| b == 0)) => {
                    self.pos += k;
                    if !self.ensure(BASE_HEADER)? {
                        let why = self.damage.take().unwrap_or_else(|| {
                            format!(
                                "the file ends inside object {}: truncated file?",
                                self.objects + 1
                            )
                        });
                        return Err(self.fatal(why));
                    }
                }
                _ => {
                    // A damaged container found on the way says better what went wrong.
                    let why = self.damage.take().unwrap_or_else(|| {
                        format!(
                            "expected an object (\"LOBJ\") inside a log container, found [{}]: corrupt file",
                            show(&window[..4])
                        )
                    });
                    return Err(self.fatal(why));
                }
            }
        }
        let head = &self.buf[self.pos..self.pos + BASE_HEADER];
        let header_size = u16_at(head, 4);
        let version = u16_at(head, 6);
        let size = u32_at(head, 8);
        let kind = u32_at(head, 12);
        if usize::from(header_size) < BASE_HEADER
            || size < u32::from(header_size)
            || size > MAX_OBJECT
        {
            let why = self.damage.take().unwrap_or_else(|| {
                format!("object size {size} with a {header_size}-byte header is not possible: corrupt file")
            });
            return Err(self.fatal(why));
        }
        let size = size as usize;
        if !self.ensure(size)? {
            let why = self.damage.take().unwrap_or_else(|| {
                format!(
                    "the file ends inside this object (type {kind}, {size} bytes): truncated file?"
                )
            });
            return Err(self.fatal(why));
        }
        self.objects += 1;
        let object = &self.buf[self.pos..self.pos + size];
        let parsed = decode(object, header_size.into(), version, kind, self.start_us);
        self.pos += size;
        self.padding = size % 4;
        Ok(Some(parsed))
    }
}

/// Decodes one inner object (`object` is all of it, base header included).
fn decode(
    object: &[u8],
    header_size: usize,
    version: u16,
    kind: u32,
    start: Option<u64>,
) -> Parsed {
    let name = match kind {
        CAN_MESSAGE => "CAN_MESSAGE",
        CAN_MESSAGE2 => "CAN_MESSAGE2",
        CAN_ERROR => "CAN_ERROR",
        CAN_ERROR_EXT => "CAN_ERROR_EXT",
        CAN_FD_MESSAGE => "CAN_FD_MESSAGE",
        CAN_FD_MESSAGE_64 => "CAN_FD_MESSAGE_64",
        _ => return Parsed::Skip,
    };
    // v1: flags u32, client index u16, object version u16, timestamp u64.
    // v2: flags u32, timestamp status u8, reserved u8, object version u16, timestamp u64,
    //     original timestamp u64.
    let needed = match version {
        1 => 32,
        2 => 40,
        v => return Parsed::Bad(format!("{name} object with unknown header version {v}")),
    };
    if header_size < needed {
        return Parsed::Bad(format!(
            "{name} object header of {header_size} bytes, version {version} needs {needed}"
        ));
    }
    let flags = u32_at(object, 16);
    let stamp = u64_at(object, 24);
    let rel_us = if flags & 1 != 0 {
        stamp.saturating_mul(10)
    } else {
        stamp / 1000 + u64::from(stamp % 1000 >= 500)
    };
    let t_us = start.unwrap_or(0).saturating_add(rel_us);
    let body = &object[header_size..];
    let short = |needed: usize| {
        Parsed::Bad(format!(
            "{name} object body of {} bytes, {needed} expected",
            body.len()
        ))
    };
    let channel = |raw: u32| -> Result<u8, Parsed> {
        match raw {
            1..=256 => Ok((raw - 1) as u8),
            0 => Err(Parsed::Bad(format!(
                "{name} on channel 0: BLF channels count from 1"
            ))),
            // A frame's channel is a u8 here: AutoPlug's limit, not the format's.
            c => Err(Parsed::Bad(format!(
                "{name} on channel {c}: AutoPlug reads BLF channels 1 to 256 only (the format allows up to 65535)"
            ))),
        }
    };
    let result = match kind {
        CAN_MESSAGE | CAN_MESSAGE2 => {
            // channel u16, flags u8, dlc u8, id u32, data[8]
            if body.len() < 16 {
                return short(16);
            }
            let ch = match channel(u16_at(body, 0).into()) {
                Ok(c) => c,
                Err(bad) => return bad,
            };
            let flags = body[2];
            classic(
                t_us,
                ch,
                u32_at(body, 4),
                flags & 0x80 != 0,
                flags & 0x01 != 0,
                body[3],
                &body[8..16],
            )
        }
        CAN_ERROR => {
            // channel u16, length u16
            if body.len() < 4 {
                return short(4);
            }
            let ch = match channel(u16_at(body, 0).into()) {
                Ok(c) => c,
                Err(bad) => return bad,
            };
            LogFrame::new(t_us, ch, 0, false, FrameKind::Error, &[])
        }
        CAN_ERROR_EXT => {
            // channel u16, length u16, flags u32, ecc u8, position u8, dlc u8, reserved
            // u8, frame length u32, id u32, extended flags u16, reserved u16, data[8]
            if body.len() < 32 {
                return short(32);
            }
            let ch = match channel(u16_at(body, 0).into()) {
                Ok(c) => c,
                Err(bad) => return bad,
            };
            let raw = u32_at(body, 16);
            let len = usize::from(body[10] & 0x0F).min(8);
            LogFrame::new(
                t_us,
                ch,
                raw & MAX_EXTENDED_ID,
                raw & EXTENDED_FLAG != 0,
                FrameKind::Error,
                &body[24..24 + len],
            )
        }
        CAN_FD_MESSAGE => {
            // channel u16, flags u8, dlc u8, id u32, frame length u32, bit count u8,
            // FD flags u8, valid bytes u8, reserved[5], data[64]
            if body.len() < 28 {
                return short(28);
            }
            let ch = match channel(u16_at(body, 0).into()) {
                Ok(c) => c,
                Err(bad) => return bad,
            };
            let flags = body[2];
            let fd_flags = body[13];
            if fd_flags & 0x01 != 0 {
                let valid = usize::from(body[14]).min(64);
                fd(
                    t_us,
                    ch,
                    u32_at(body, 4),
                    flags & 0x01 != 0,
                    body[3],
                    &body[20..body.len().min(20 + valid)],
                    FdFlags {
                        brs: fd_flags & 0x02 != 0,
                        esi: fd_flags & 0x04 != 0,
                    },
                )
            } else {
                classic(
                    t_us,
                    ch,
                    u32_at(body, 4),
                    flags & 0x80 != 0,
                    flags & 0x01 != 0,
                    body[3],
                    &body[20..28],
                )
            }
        }
        CAN_FD_MESSAGE_64 => {
            // channel u8, dlc u8, valid bytes u8, tx count u8, id u32, frame length u32,
            // flags u32, 4 × u32 bit timing, bit count u16, direction u8, extended data
            // offset u8, crc u32, then data
            if body.len() < 40 {
                return short(40);
            }
            let flags = u32_at(body, 12);
            let ch = match channel(body[0].into()) {
                Ok(c) => c,
                Err(bad) => return bad,
            };
            if flags & 0x1000 != 0 {
                let valid = usize::from(body[2]).min(64);
                return match fd(
                    t_us,
                    ch,
                    u32_at(body, 4),
                    body[34] != 0,
                    body[1],
                    &body[40..body.len().min(40 + valid)],
                    FdFlags {
                        brs: flags & 0x2000 != 0,
                        esi: flags & 0x4000 != 0,
                    },
                ) {
                    Ok(frame) => Parsed::Frame(frame),
                    Err(e) => Parsed::Bad(format!("{name}: {e}")),
                };
            }
            // Bytes the object lacks are zero, as CANoe does (python-can issue 1905).
            let mut data = [0u8; 8];
            let present = &body[40..body.len().min(48)];
            data[..present.len()].copy_from_slice(present);
            classic(
                t_us,
                ch,
                u32_at(body, 4),
                flags & 0x0010 != 0,
                body[34] != 0,
                body[1],
                &data,
            )
        }
        _ => return Parsed::Skip,
    };
    match result {
        Ok(frame) => Parsed::Frame(frame),
        Err(e) => Parsed::Bad(format!("{name}: {e}")),
    }
}

/// A classic data or remote frame from its raw fields.
fn classic(
    t_us: u64,
    channel: u8,
    raw_id: u32,
    remote: bool,
    tx: bool,
    dlc: u8,
    data: &[u8],
) -> Result<LogFrame, crate::frame::FrameError> {
    let extended = raw_id & EXTENDED_FLAG != 0;
    let id = raw_id & !EXTENDED_FLAG;
    // A classic DLC of 9 to 15 still means 8 bytes.
    let len = dlc.min(8);
    let frame = if remote {
        LogFrame::remote(t_us, channel, id, extended, len)?
    } else {
        LogFrame::new(
            t_us,
            channel,
            id,
            extended,
            FrameKind::Data,
            &data[..usize::from(len)],
        )?
    };
    Ok(frame.with_direction(if tx { Direction::Tx } else { Direction::Rx }))
}

/// A CAN FD data frame from its raw fields: `dlc` says the length, `present` holds the
/// bytes the object has (those it lacks are zero, as for classic frames).
fn fd(
    t_us: u64,
    channel: u8,
    raw_id: u32,
    tx: bool,
    dlc: u8,
    present: &[u8],
    flags: FdFlags,
) -> Result<LogFrame, crate::frame::FrameError> {
    let extended = raw_id & EXTENDED_FLAG != 0;
    let id = raw_id & !EXTENDED_FLAG;
    let len = dlc_to_len(dlc, true);
    let mut data = [0u8; 64];
    let kept = present.len().min(len);
    data[..kept].copy_from_slice(&present[..kept]);
    let frame = LogFrame::new_fd(t_us, channel, id, extended, &data[..len], flags)?;
    Ok(frame.with_direction(if tx { Direction::Tx } else { Direction::Rx }))
}

impl<R: Read> Iterator for BlfReader<R> {
    type Item = Result<LogFrame, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if self.done {
                return None;
            }
            match self.next_object() {
                Ok(None) => {
                    self.done = true;
                    return None;
                }
                Ok(Some(Parsed::Frame(frame))) => return Some(Ok(frame)),
                Ok(Some(Parsed::Skip)) => continue,
                Ok(Some(Parsed::Bad(message))) => {
                    return Some(Err(LogError::at_object(self.objects, message)))
                }
                Err(fatal) => {
                    self.done = true;
                    return Some(Err(fatal));
                }
            }
        }
    }
}

impl<R> std::fmt::Debug for BlfReader<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BlfReader")
            .field("start_us", &self.start_us)
            .field("objects", &self.objects)
            .finish_non_exhaustive()
    }
}

/// Builds BLF files in memory for the tests below.
#[cfg(test)]
pub(crate) mod build {
    use std::io::Write;

    /// A file header of 144 bytes with this start (year 0: none).
    pub fn header(systemtime: [u16; 8], objects: u32) -> Vec<u8> {
        let mut h = Vec::new();
        h.extend_from_slice(b"LOGG");
        h.extend_from_slice(&144u32.to_le_bytes());
        h.extend_from_slice(&[5, 0, 0, 0, 2, 6, 8, 1]);
        h.extend_from_slice(&0u64.to_le_bytes());
        h.extend_from_slice(&0u64.to_le_bytes());
        h.extend_from_slice(&objects.to_le_bytes());
        h.extend_from_slice(&0u32.to_le_bytes());
        for v in systemtime.iter().chain(systemtime.iter()) {
            h.extend_from_slice(&v.to_le_bytes());
        }
        h.resize(144, 0);
        h
    }

    /// An inner object with a v1 header, nanosecond time, and its padding.
    pub fn object(kind: u32, t_ns: u64, body: &[u8]) -> Vec<u8> {
        let size = 32 + body.len();
        let mut o = Vec::new();
        o.extend_from_slice(b"LOBJ");
        o.extend_from_slice(&32u16.to_le_bytes());
        o.extend_from_slice(&1u16.to_le_bytes());
        o.extend_from_slice(&(size as u32).to_le_bytes());
        o.extend_from_slice(&kind.to_le_bytes());
        o.extend_from_slice(&2u32.to_le_bytes());
        o.extend_from_slice(&[0; 4]);
        o.extend_from_slice(&t_ns.to_le_bytes());
        o.extend_from_slice(body);
        o.resize(size + size % 4, 0);
        o
    }

    /// An inner object as Vector writes some types (Ethernet, test structures...):
    /// nothing after it, whatever its size.
    pub fn object_unpadded(kind: u32, t_ns: u64, body: &[u8]) -> Vec<u8> {
        let mut o = object(kind, t_ns, body);
        o.truncate(32 + body.len());
        o
    }

    /// A CAN_MESSAGE body.
    pub fn can_message(channel: u16, flags: u8, dlc: u8, id: u32, data: &[u8]) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend_from_slice(&channel.to_le_bytes());
        b.push(flags);
        b.push(dlc);
        b.extend_from_slice(&id.to_le_bytes());
        let mut d = [0u8; 8];
        d[..data.len()].copy_from_slice(data);
        b.extend_from_slice(&d);
        b
    }

    /// A LOG_CONTAINER of these inner bytes, zlib-compressed or stored.
    pub fn container(inner: &[u8], zlib: bool) -> Vec<u8> {
        let payload = if zlib {
            let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
            e.write_all(inner).unwrap();
            e.finish().unwrap()
        } else {
            inner.to_vec()
        };
        let size = 32 + payload.len();
        let mut c = Vec::new();
        c.extend_from_slice(b"LOBJ");
        c.extend_from_slice(&16u16.to_le_bytes());
        c.extend_from_slice(&1u16.to_le_bytes());
        c.extend_from_slice(&(size as u32).to_le_bytes());
        c.extend_from_slice(&10u32.to_le_bytes());
        c.extend_from_slice(&(if zlib { 2u16 } else { 0 }).to_le_bytes());
        c.extend_from_slice(&[0; 6]);
        c.extend_from_slice(&(inner.len() as u32).to_le_bytes());
        c.extend_from_slice(&[0; 4]);
        c.extend_from_slice(&payload);
        c.resize(size + size % 4, 0);
        c
    }
}

#[cfg(test)]
mod tests {
    use super::build::*;
    use super::*;

    /// 2023-11-14 22:13:20.000 UTC, a Tuesday: 1_700_000_000 s.
    const START: [u16; 8] = [2023, 11, 2, 14, 22, 13, 20, 0];
    const START_US: u64 = 1_700_000_000_000_000;

    fn read(bytes: &[u8]) -> Vec<Result<LogFrame, LogError>> {
        BlfReader::new(bytes).unwrap().collect()
    }

    fn sample_inner() -> Vec<u8> {
        let mut inner = Vec::new();
        inner.extend(object(1, 1_000, &can_message(1, 0, 3, 0x123, &[1, 2, 3])));
        inner.extend(object(65, 2_000, &[0; 21])); // APP_TEXT: skipped
        inner.extend(object(86, 12_345_678, &{
            let mut b = can_message(2, 0x01, 2, 0x1ABC_DEF0 | EXTENDED_FLAG, &[9, 8]);
            b.extend_from_slice(&[0; 8]);
            b
        }));
        inner.extend(object(1, 13_000_000, &can_message(1, 0x80, 4, 0x7FF, &[])));
        inner
    }

    fn check_sample(got: &[Result<LogFrame, LogError>]) {
        assert_eq!(got.len(), 3, "{got:?}");
        let f: Vec<&LogFrame> = got.iter().map(|f| f.as_ref().unwrap()).collect();
        assert_eq!((f[0].t_us, f[0].channel, f[0].id), (START_US + 1, 0, 0x123));
        assert_eq!(
            (f[0].data(), f[0].direction),
            (&[1u8, 2, 3][..], Direction::Rx)
        );
        assert_eq!((f[1].t_us, f[1].channel), (START_US + 12_346, 1));
        assert_eq!(
            (f[1].id, f[1].extended, f[1].direction),
            (0x1ABC_DEF0, true, Direction::Tx)
        );
        assert_eq!(
            (f[2].kind, f[2].len(), f[2].t_us),
            (FrameKind::Remote, 4, START_US + 13_000)
        );
    }

    #[test]
    fn compressed_stored_and_split_containers() {
        let inner = sample_inner();
        for zlib in [true, false] {
            let mut file = header(START, 4);
            file.extend(container(&inner, zlib));
            check_sample(&read(&file));
        }
        // Objects cut across containers at every possible point.
        for cut in 1..inner.len() {
            let mut file = header(START, 4);
            file.extend(container(&inner[..cut], true));
            file.extend(container(&inner[cut..], false));
            check_sample(&read(&file));
        }
        // Objects outside any container.
        let mut file = header(START, 4);
        file.extend(&inner);
        check_sample(&read(&file));
    }

    #[test]
    fn no_start_date_gives_times_since_the_start() {
        let mut file = header([0; 8], 1);
        file.extend(container(
            &object(1, 5_000_000, &can_message(1, 0, 0, 1, &[])),
            true,
        ));
        let r = BlfReader::new(&file[..]).unwrap();
        assert_eq!(r.start_us(), None);
        assert_eq!(r.object_count(), 1);
        let f: Vec<_> = r.map(|f| f.unwrap().t_us).collect();
        assert_eq!(f, [5_000]);
    }

    /// CAN_FD_MESSAGE_64 with EDL: the DLC says the length, the object holds the bytes it
    /// names valid (missing ones are zero).
    #[test]
    fn fd_64_objects_are_read_with_their_flags() {
        let fd64 = |dlc: u8, valid: u8, flags: u32, data: &[u8]| {
            let mut body = vec![1, dlc, valid, 0];
            body.extend_from_slice(&(0x1ABC_DEF0u32 | EXTENDED_FLAG).to_le_bytes());
            body.extend_from_slice(&[0; 4]);
            body.extend_from_slice(&flags.to_le_bytes());
            body.extend_from_slice(&[0; 24]);
            body.extend_from_slice(data);
            body
        };
        let mut inner = Vec::new();
        let bytes: Vec<u8> = (0..64).collect();
        inner.extend(object(101, 1_000, &fd64(15, 64, 0x1000 | 0x4000, &bytes)));
        inner.extend(object(
            101,
            2_000,
            &fd64(10, 10, 0x1000 | 0x2000, &bytes[..10]),
        ));
        let mut file = header(START, 2);
        file.extend(container(&inner, true));
        let got = read(&file);
        let f = got[0].as_ref().unwrap();
        assert_eq!(
            (f.id, f.extended, f.len(), f.data(), f.fd()),
            (
                0x1ABC_DEF0,
                true,
                64,
                &bytes[..],
                Some(FdFlags {
                    brs: false,
                    esi: true
                })
            )
        );
        let f = got[1].as_ref().unwrap();
        assert_eq!(
            (f.len(), &f.data()[..10], &f.data()[10..]),
            (16, &bytes[..10], &[0u8; 6][..])
        );
        assert!(f.fd().unwrap().brs);
    }

    #[test]
    fn errors_fd_frames_and_bad_objects() {
        let mut inner = Vec::new();
        // CAN_ERROR_EXT: channel 1, dlc 2, id 0x55.
        let mut err = vec![1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 2, 0, 0, 0, 0, 0];
        err.extend_from_slice(&0x55u32.to_le_bytes());
        err.extend_from_slice(&[0; 4]);
        err.extend_from_slice(&[0xE1, 0xE2, 0, 0, 0, 0, 0, 0]);
        inner.extend(object(73, 1_000, &err));
        // CAN_FD_MESSAGE with EDL and BRS, 12 bytes (DLC 9).
        let mut fd = can_message(1, 0, 9, 0x100, &[]);
        fd.truncate(8);
        fd.extend_from_slice(&[0, 0, 0, 0, 0, 0x03, 12, 0, 0, 0, 0, 0]);
        fd.extend_from_slice(&[0x5A; 64]);
        inner.extend(object(100, 2_000, &fd));
        // CAN_FD_MESSAGE_64 carrying a classic frame (EDL clear), transmitted.
        let mut fd64 = vec![1, 2, 2, 0];
        fd64.extend_from_slice(&0x321u32.to_le_bytes());
        fd64.extend_from_slice(&[0; 26]);
        fd64.push(1); // direction: Tx
        fd64.extend_from_slice(&[0; 5]);
        fd64.extend_from_slice(&[0xAB, 0xCD]);
        inner.extend(object(101, 3_000, &fd64));
        // Channel 0, a standard id that is too big, a body cut short.
        inner.extend(object(1, 4_000, &can_message(0, 0, 0, 1, &[])));
        inner.extend(object(1, 5_000, &can_message(1, 0, 0, 0x800, &[])));
        inner.extend(object(1, 6_000, &[1, 0]));
        inner.extend(object(1, 7_000, &can_message(1, 0, 1, 7, &[7])));
        let mut file = header(START, 8);
        file.extend(container(&inner, true));
        let got = read(&file);
        assert_eq!(got.len(), 7, "{got:?}");
        let e = got[0].as_ref().unwrap();
        assert_eq!(
            (e.kind, e.id, e.data()),
            (FrameKind::Error, 0x55, &[0xE1, 0xE2][..])
        );
        let fd = got[1].as_ref().unwrap();
        assert_eq!(
            (fd.id, fd.data(), fd.fd()),
            (
                0x100,
                &[0x5A; 12][..],
                Some(FdFlags {
                    brs: true,
                    esi: false
                })
            )
        );
        let c = got[2].as_ref().unwrap();
        assert_eq!(
            (c.id, c.data(), c.direction),
            (0x321, &[0xAB, 0xCD][..], Direction::Tx)
        );
        assert!(got[3].as_ref().unwrap_err().message.contains("channel 0"));
        assert!(got[4]
            .as_ref()
            .unwrap_err()
            .message
            .contains("does not fit 11 bits"));
        assert!(got[5]
            .as_ref()
            .unwrap_err()
            .message
            .contains("body of 2 bytes"));
        assert_eq!(got[6].as_ref().unwrap().id, 7, "reading went on");
    }

    /// CANoe writes Ethernet frames (and their errors), FlexRay VFR receive Ex objects,
    /// test structures and diagnostic request interpretations with no padding after them.
    #[test]
    fn objects_written_without_padding_are_read() {
        let can = |id: u32| {
            object(
                1,
                u64::from(id) * 1_000,
                &can_message(1, 0, 1, id, &[id as u8]),
            )
        };
        let mut inner = Vec::new();
        inner.extend(can(0x100));
        // ETHERNET_FRAME_EX, 32 + 41 bytes: 1 byte short of a multiple of 4, no padding.
        inner.extend(object_unpadded(120, 5_000, &[0xEE; 41]));
        inner.extend(can(0x101));
        // TEST_STRUCTURE, 32 + 39 bytes, no padding.
        inner.extend(object_unpadded(118, 6_000, &[0x54; 39]));
        inner.extend(can(0x102));
        // APP_TEXT, 32 + 21 bytes, with its padding as every other type has it.
        inner.extend(object(65, 7_000, &[0x41; 21]));
        inner.extend(can(0x103));
        // DIAG_REQUEST_INTERPRETATION last, unpadded, right at the end of the data.
        inner.extend(object_unpadded(119, 8_000, &[0x19; 17]));
        let ids = |got: Vec<Result<LogFrame, LogError>>| -> Vec<u32> {
            got.into_iter()
                .map(|f| f.unwrap_or_else(|e| panic!("{e}")).id)
                .collect()
        };
        let mut file = header(START, 8);
        file.extend(container(&inner, true));
        assert_eq!(ids(read(&file)), [0x100, 0x101, 0x102, 0x103]);
        // The same run split across two containers at every point.
        for cut in 1..inner.len() {
            let mut file = header(START, 8);
            file.extend(container(&inner[..cut], true));
            file.extend(container(&inner[cut..], false));
            assert_eq!(
                ids(read(&file)),
                [0x100, 0x101, 0x102, 0x103],
                "cut at {cut}"
            );
        }
        // And outside any container.
        let mut file = header(START, 8);
        file.extend(&inner);
        assert_eq!(ids(read(&file)), [0x100, 0x101, 0x102, 0x103]);
    }

    /// 600 CAN_MESSAGEs of 48 bytes in one container, as a logger that lost power leaves
    /// them: the container's last 200 bytes never reached the disk.
    fn cut_file(zlib: bool) -> (Vec<u8>, Vec<u8>) {
        let mut inner = Vec::new();
        for i in 0..600u32 {
            let id = i % 0x7FF;
            inner.extend(object(
                1,
                u64::from(i) * 1_000_000,
                &can_message(1, 0, 2, id, &[i as u8, (i >> 8) as u8]),
            ));
        }
        let mut file = header(START, 600);
        file.extend(container(&inner, zlib));
        file.truncate(file.len() - 200);
        (file, inner)
    }

    fn check_cut(got: &[Result<LogFrame, LogError>], expected_frames: usize) {
        assert_eq!(got.len(), expected_frames + 1, "frames then one error");
        for (i, f) in got[..expected_frames].iter().enumerate() {
            let f = f.as_ref().unwrap_or_else(|e| panic!("item {i}: {e}"));
            assert_eq!(
                (f.id, f.data(), f.t_us),
                (
                    i as u32 % 0x7FF,
                    &[i as u8, (i >> 8) as u8][..],
                    START_US + i as u64 * 1_000
                )
            );
        }
        let e = got[expected_frames].as_ref().unwrap_err();
        assert!(e.is_fatal(), "{e}");
        assert_eq!(e.line, expected_frames as u64 + 1, "{e}");
        assert!(
            e.message.contains("truncated") && e.message.contains("byte 144"),
            "{e}"
        );
    }

    #[test]
    fn a_stored_container_cut_short_gives_its_whole_objects() {
        let (file, _) = cut_file(false);
        // 28,800 bytes of objects, 200 missing: 28,600 present, 595 whole objects.
        check_cut(&read(&file), 595);
    }

    #[test]
    fn a_zlib_container_cut_short_gives_what_inflates() {
        let (file, inner) = cut_file(true);
        // What the compressed bytes present inflate to, by zlib itself.
        let mut inflater = flate2::Decompress::new(true);
        let mut out = vec![0u8; inner.len()];
        let _ = inflater.decompress(&file[144 + 32..], &mut out, flate2::FlushDecompress::Sync);
        let inflated = inflater.total_out() as usize;
        assert_eq!(&out[..inflated], &inner[..inflated]);
        let whole = inflated / 48;
        assert!((500..600).contains(&whole), "{whole} objects inflate");
        check_cut(&read(&file), whole);
    }

    #[test]
    fn channels_above_256_are_autoplugs_limit_not_the_formats() {
        let mut inner = Vec::new();
        inner.extend(object(1, 1_000, &can_message(300, 0, 0, 1, &[])));
        inner.extend(object(1, 2_000, &can_message(0, 0, 0, 2, &[])));
        inner.extend(object(1, 3_000, &can_message(256, 0, 0, 3, &[])));
        let mut file = header(START, 3);
        file.extend(container(&inner, true));
        let got = read(&file);
        assert_eq!(got.len(), 3, "{got:?}");
        assert_eq!(
            got[0].as_ref().unwrap_err().to_string(),
            "object 1: CAN_MESSAGE on channel 300: AutoPlug reads BLF channels 1 to 256 only (the format allows up to 65535)"
        );
        assert_eq!(
            got[1].as_ref().unwrap_err().to_string(),
            "object 2: CAN_MESSAGE on channel 0: BLF channels count from 1"
        );
        assert_eq!(got[2].as_ref().unwrap().channel, 255);
    }

    #[test]
    fn damaged_files_give_one_fatal_error() {
        assert!(BlfReader::new(&b""[..]).is_err());
        assert!(BlfReader::new(&b"LOGG"[..])
            .unwrap_err()
            .to_string()
            .contains("cut short"));
        let e = BlfReader::new(&b"(1.0) can0 123#\n"[..]).err().unwrap();
        assert!(e.to_string().contains("not a BLF file"), "{e}");

        let mut good = header(START, 4);
        good.extend(container(&sample_inner(), true));
        // Truncated anywhere after the header: the frames before the cut, then at most
        // one fatal error, never a panic.
        for cut in 144..good.len() {
            let got = read(&good[..cut]);
            let errors: Vec<_> = got.iter().filter_map(|r| r.as_ref().err()).collect();
            assert!(errors.len() <= 1);
            if let Some(e) = errors.first() {
                assert!(e.is_fatal(), "{e}");
                assert!(
                    e.message.contains("truncated") || e.message.contains("corrupt"),
                    "{e}"
                );
            }
        }
        let got = read(&good[..good.len() - 10]);
        assert!(got
            .last()
            .unwrap()
            .as_ref()
            .unwrap_err()
            .message
            .contains("truncated"));

        // Corrupt zlib data.
        let mut bad = good.clone();
        let n = bad.len();
        bad[n - 20] ^= 0xFF;
        bad[n - 21] ^= 0x5A;
        let got = read(&bad);
        let e = got.last().unwrap().as_ref().unwrap_err();
        assert!(e.is_fatal() && e.message.contains("corrupt"), "{e}");

        // A bad signature, a zero-size inner object, an absurd size.
        let mut sig = header(START, 1);
        sig.extend(b"LOBX0000000000000000");
        assert!(read(&sig)[0]
            .as_ref()
            .unwrap_err()
            .message
            .contains("expected an object"));
        let mut zero = object(1, 0, &can_message(1, 0, 0, 1, &[]));
        zero[8..12].copy_from_slice(&0u32.to_le_bytes());
        let mut file = header(START, 1);
        file.extend(container(&zero, false));
        assert!(read(&file)[0]
            .as_ref()
            .unwrap_err()
            .message
            .contains("not possible"));
        let mut huge = header(START, 1);
        huge.extend(b"LOBJ\x10\x00\x01\x00\xFF\xFF\xFF\xFF\x0A\x00\x00\x00");
        assert!(read(&huge)[0]
            .as_ref()
            .unwrap_err()
            .message
            .contains("not possible"));
    }
}
