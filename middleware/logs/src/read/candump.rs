//! The candump log format of linux-can's can-utils (`candump -l`), which canplayer,
//! python-can, cantools and SavvyCAN read: one frame per line,
//! `(1436509052.249713) can0 044#2A366C2BBA`.
//!
//! - 3 hex digits of identifier: standard frame; 8: extended, or an error frame when the
//!   `CAN_ERR_FLAG` bit (0x20000000) is set, as candump writes them.
//! - `123#R` / `123#R4`: remote frame (with its DLC).
//! - `123##1112233`: CAN FD; the digit after `##` holds its flags (0x1 BRS, 0x2 ESI;
//!   can-utils' 0x4 FDF is implied), then up to 64 data bytes.
//! - python-can appends ` R` (received) or ` T` (transmitted); plain candump says
//!   nothing and the frame counts as received.
//! - Data may hold `.` separators (`11.22.33`), and an 8-byte frame may carry candump's
//!   `_X` raw DLC suffix, which is ignored.
//! - `DROPCOUNT: dropped 3 CAN frames on 'can0' socket (total drops 7)`: candump's note
//!   that the kernel dropped frames before it could log them. Not a frame and not an
//!   error: the reader counts the frames lost ([`CandumpReader::dropped_frames`]).

use std::io::BufRead;

use super::lines::{Line, Lines, RawLine};
use super::LogError;
use crate::frame::{Direction, FdFlags, FrameKind, LogFrame, MAX_EXTENDED_ID, MAX_STANDARD_ID};
use crate::time::parse_seconds;

/// SocketCAN's error frame flag in a candump identifier.
pub const CAN_ERR_FLAG: u32 = 0x2000_0000;

/// Most interface names a log may use: channels are a `u8`.
const MAX_INTERFACES: usize = 256;

/// One parsed line: the frame (on channel 0) and the interface it names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CandumpLine<'a> {
    /// The interface name (`can0`, `vcan1`).
    pub interface: &'a str,
    /// The frame; its channel is 0 (the reader numbers interfaces).
    pub frame: LogFrame,
}

/// Parses one line (`line` is its number, for the error). Blank lines are errors here;
/// [`CandumpReader`] skips them.
pub fn parse_line(text: &str, line: u64) -> Result<CandumpLine<'_>, LogError> {
    let err = |message: String| LogError::at_line(line, message);
    if let Some(dropped) = dropcount(text) {
        return Err(err(match dropped {
            Ok(n) => {
                format!("DROPCOUNT line: {n} frame(s) the logger reported dropped, not a frame")
            }
            Err(why) => why,
        }));
    }
    let mut parts = text.split_ascii_whitespace();
    let (Some(stamp), Some(interface), Some(body)) = (parts.next(), parts.next(), parts.next())
    else {
        return Err(err(format!(
            "expected \"(seconds.micros) interface ID#DATA\", found \"{}\"",
            text.trim()
        )));
    };
    let direction = match parts.next() {
        None | Some("R" | "r") => Direction::Rx,
        Some("T" | "t") => Direction::Tx,
        Some(extra) => return Err(err(format!("unexpected \"{extra}\" after the frame"))),
    };
    if let Some(extra) = parts.next() {
        return Err(err(format!("unexpected \"{extra}\" after the frame")));
    }
    let stamp = stamp
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .ok_or_else(|| err(format!("timestamp \"{stamp}\" is not in parentheses")))?;
    let t_us = parse_seconds(stamp)
        .ok_or_else(|| err(format!("timestamp \"{stamp}\" is not seconds.fraction")))?;
    let (id_text, data_text) = body.split_once('#').ok_or_else(|| {
        err(format!(
            "frame \"{body}\" has no '#' between identifier and data"
        ))
    })?;
    // CAN FD: "##", one hex digit of flags, the data.
    let fd = match data_text.strip_prefix('#') {
        None => None,
        Some(rest) => {
            let mut chars = rest.chars();
            let flags = chars.next().and_then(|c| c.to_digit(16)).ok_or_else(|| {
                err(format!(
                    "CAN FD frame \"{body}\": \"##\" must be followed by a hex digit of flags"
                ))
            })?;
            Some((
                FdFlags {
                    brs: flags & 1 != 0,
                    esi: flags & 2 != 0,
                },
                chars.as_str(),
            ))
        }
    };
    if id_text.is_empty() || !id_text.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(err(format!("identifier \"{id_text}\" is not hexadecimal")));
    }
    // Only 3 or 8 hex digits are parsed: both fit a u32.
    let (id, extended, kind) = match id_text.len() {
        3 => {
            let id = u32::from_str_radix(id_text, 16).unwrap_or(u32::MAX);
            if id > MAX_STANDARD_ID {
                return Err(err(format!(
                    "identifier \"{id_text}\" does not fit 11 bits (3 digits mean a standard identifier, 000 to 7FF)"
                )));
            }
            (id, false, FrameKind::Data)
        }
        8 => {
            let raw = u32::from_str_radix(id_text, 16).unwrap_or(u32::MAX);
            if raw & CAN_ERR_FLAG != 0 {
                (raw & MAX_EXTENDED_ID, false, FrameKind::Error)
            } else if raw > MAX_EXTENDED_ID {
                return Err(err(format!(
                    "identifier \"{id_text}\" does not fit 29 bits"
                )));
            } else {
                (raw, true, FrameKind::Data)
            }
        }
        n => {
            return Err(err(format!(
                "identifier \"{id_text}\" has {n} digits: 3 for a standard identifier, 8 for an extended one"
            )))
        }
    };
    let frame = if let Some((flags, fd_data)) = fd {
        if kind == FrameKind::Error {
            return Err(err("an error frame cannot be a CAN FD frame".into()));
        }
        let data = parse_data(fd_data, true).map_err(err)?;
        LogFrame::new_fd(t_us, 0, id, extended, &data.bytes[..data.len], flags)
    } else if let Some(dlc_text) = data_text
        .strip_prefix('R')
        .or_else(|| data_text.strip_prefix('r'))
    {
        if kind == FrameKind::Error {
            return Err(err("an error frame cannot be a remote frame".into()));
        }
        let dlc = match dlc_text {
            "" => 0,
            d if d.len() == 1 && matches!(d.as_bytes()[0], b'0'..=b'8') => d.as_bytes()[0] - b'0',
            d => {
                return Err(err(format!(
                    "remote frame length \"{d}\" is not a digit 0 to 8"
                )))
            }
        };
        LogFrame::remote(t_us, 0, id, extended, dlc)
    } else {
        let data = parse_data(data_text, false).map_err(err)?;
        LogFrame::new(t_us, 0, id, extended, kind, &data.bytes[..data.len])
    }
    .map_err(|e| err(e.to_string()))?;
    Ok(CandumpLine {
        interface,
        frame: frame.with_direction(direction),
    })
}

/// The common line, `(SECS.MICROS) IFACE ID#DATA` with python-can's optional ` R`/` T`,
/// parsed in one pass over its bytes: a replay spends most of its reading time on lines.
/// Anything else (remote frames, separators in the data, a raw DLC, extra spaces,
/// malformed text) gives `None` and goes to [`parse_line`], which reads every form and
/// words the errors; a test holds the two to the same result.
fn parse_common(line: &[u8]) -> Option<(LogFrame, &[u8])> {
    let rest = line.strip_prefix(b"(")?;
    // Seconds: 1 to 20 digits; micros: up to 6 digits kept, further ones truncated.
    let mut i = 0;
    let mut secs: u64 = 0;
    while let Some(&b) = rest.get(i).filter(|b| b.is_ascii_digit()) {
        secs = secs.checked_mul(10)?.checked_add(u64::from(b - b'0'))?;
        i += 1;
    }
    if i == 0 || i > 20 {
        return None;
    }
    let mut micros: u64 = 0;
    let mut frac_digits = 0;
    if rest.get(i) == Some(&b'.') {
        i += 1;
        while let Some(&b) = rest.get(i).filter(|b| b.is_ascii_digit()) {
            if frac_digits < 6 {
                micros = micros * 10 + u64::from(b - b'0');
                frac_digits += 1;
            }
            i += 1;
        }
    }
    for _ in frac_digits..6 {
        micros *= 10;
    }
    let t_us = secs.checked_mul(1_000_000)?.checked_add(micros)?;
    let rest = rest[i..].strip_prefix(b") ")?;
    let space = rest.iter().position(|&b| b == b' ')?;
    let (interface, rest) = (&rest[..space], &rest[space + 1..]);
    if interface.is_empty() || !interface.iter().all(u8::is_ascii_graphic) {
        return None;
    }
    let hash = rest.iter().position(|&b| b == b'#')?;
    let (id_text, rest) = (&rest[..hash], &rest[hash + 1..]);
    let mut id: u32 = 0;
    for &b in id_text {
        id = id << 4 | u32::from(hex_value(b)?);
    }
    let (id, extended, kind) = match id_text.len() {
        3 if id <= MAX_STANDARD_ID => (id, false, FrameKind::Data),
        8 if id & CAN_ERR_FLAG != 0 => (id & MAX_EXTENDED_ID, false, FrameKind::Error),
        8 if id <= MAX_EXTENDED_ID => (id, true, FrameKind::Data),
        _ => return None,
    };
    let (hex, direction) = match rest {
        [hex @ .., b' ', b'R' | b'r'] => (hex, Direction::Rx),
        [hex @ .., b' ', b'T' | b't'] => (hex, Direction::Tx),
        hex => (hex, Direction::Rx),
    };
    if hex.len() % 2 != 0 || hex.len() > 16 {
        return None;
    }
    let mut data = [0u8; 8];
    for (byte, pair) in data.iter_mut().zip(hex.chunks_exact(2)) {
        *byte = hex_value(pair[0])? << 4 | hex_value(pair[1])?;
    }
    let frame = LogFrame::new(t_us, 0, id, extended, kind, &data[..hex.len() / 2]).ok()?;
    Some((frame.with_direction(direction), interface))
}

/// candump's `DROPCOUNT: dropped N CAN frame(s) on 'IFACE' socket (total drops M)`: the
/// N frames dropped, or what is wrong with the line; `None` for any other line.
fn dropcount(text: &str) -> Option<Result<u64, String>> {
    let rest = text.trim_start().strip_prefix("DROPCOUNT:")?;
    let mut words = rest.split_ascii_whitespace();
    Some(
        match (words.next(), words.next().and_then(|n| n.parse().ok())) {
            (Some("dropped"), Some(n)) => Ok(n),
            _ => Err(format!(
                "DROPCOUNT line (frames the logger reported dropped) does not say how many: \"{}\"",
                text.trim()
            )),
        },
    )
}

struct Data {
    bytes: [u8; 64],
    len: usize,
}

/// `2A366C2BBA`, `2A.36.6C`, `0102030405060708_9`.
fn parse_data(text: &str, fd: bool) -> Result<Data, String> {
    let (hex, raw_dlc) = match text.split_once('_') {
        Some((hex, dlc)) => (hex, Some(dlc)),
        None => (text, None),
    };
    let mut data = Data {
        bytes: [0; 64],
        len: 0,
    };
    let max = if fd { 64 } else { 8 };
    let mut digits = hex.bytes().filter(|&b| b != b'.');
    while let Some(hi) = digits.next() {
        let Some(lo) = digits.next() else {
            return Err(format!("data \"{text}\" has an odd number of hex digits"));
        };
        let (Some(hi), Some(lo)) = (hex_value(hi), hex_value(lo)) else {
            return Err(format!("data \"{text}\" is not hexadecimal"));
        };
        if data.len == max {
            let count = hex.bytes().filter(|&b| b != b'.').count() / 2;
            return Err(if fd {
                format!("{count} data bytes: a CAN FD frame carries at most 64")
            } else {
                format!("{count} data bytes: a classic CAN frame carries at most 8")
            });
        }
        data.bytes[data.len] = hi << 4 | lo;
        data.len += 1;
    }
    if let Some(dlc) = raw_dlc {
        // candump's raw DLC 9..F of an 8-byte frame: nothing the frame keeps.
        let ok =
            !fd && data.len == 8 && dlc.len() == 1 && dlc.bytes().all(|b| b.is_ascii_hexdigit());
        if !ok {
            return Err(format!(
                "data \"{text}\": '_' must be followed by one hex digit after 8 bytes"
            ));
        }
    }
    Ok(data)
}

fn hex_value(b: u8) -> Option<u8> {
    match b {
        b'0'..=b'9' => Some(b - b'0'),
        b'a'..=b'f' => Some(b - b'a' + 10),
        b'A'..=b'F' => Some(b - b'A' + 10),
        _ => None,
    }
}

/// Reads a candump log line by line; see the [module](self) for the format. Interface
/// names become channels in order of first appearance (the first name is channel 0).
pub struct CandumpReader<R> {
    lines: Lines<R>,
    interfaces: Vec<String>,
    dropped: u64,
    done: bool,
}

impl<R: BufRead> CandumpReader<R> {
    /// A reader of this input.
    pub fn new(input: R) -> Self {
        Self {
            lines: Lines::new(input),
            interfaces: Vec::new(),
            dropped: 0,
            done: false,
        }
    }

    /// The interface names seen so far; channel `n` is `interfaces()[n]`.
    pub fn interfaces(&self) -> &[String] {
        &self.interfaces
    }

    /// Frames the logger reported dropped so far (its `DROPCOUNT` lines): frames that were
    /// on the bus and are not in the log.
    pub fn dropped_frames(&self) -> u64 {
        self.dropped
    }
}

impl<R: BufRead> Iterator for CandumpReader<R> {
    type Item = Result<LogFrame, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        loop {
            let number = self.lines.number() + 1;
            let raw = match self.lines.next_raw() {
                None => {
                    self.done = true;
                    return None;
                }
                Some(Err(e)) => {
                    self.done = true;
                    return Some(Err(LogError::io(number, &e)));
                }
                Some(Ok(raw)) => raw,
            };
            if let RawLine::Bytes(bytes) = raw {
                if let Some((mut frame, interface)) = parse_common(bytes) {
                    // parse_common takes ASCII interface names only.
                    let name = std::str::from_utf8(interface).unwrap_or_default();
                    return Some(match channel_of(&mut self.interfaces, name) {
                        Ok(channel) => {
                            frame.channel = channel;
                            Ok(frame)
                        }
                        Err(message) => Err(LogError::at_line(number, message)),
                    });
                }
            }
            let text = match raw.text() {
                Line::Bad(message) => return Some(Err(LogError::at_line(number, message))),
                Line::Text(text) if text.trim().is_empty() => continue,
                Line::Text(text) => text,
            };
            match dropcount(text) {
                Some(Ok(n)) => {
                    self.dropped = self.dropped.saturating_add(n);
                    continue;
                }
                Some(Err(why)) => return Some(Err(LogError::at_line(number, why))),
                None => {}
            }
            let parsed = match parse_line(text, number) {
                Ok(parsed) => parsed,
                Err(e) => return Some(Err(e)),
            };
            let channel = match channel_of(&mut self.interfaces, parsed.interface) {
                Ok(channel) => channel,
                Err(message) => return Some(Err(LogError::at_line(number, message))),
            };
            let mut frame = parsed.frame;
            frame.channel = channel;
            return Some(Ok(frame));
        }
    }
}

/// The channel of an interface name: its place in order of first appearance.
fn channel_of(interfaces: &mut Vec<String>, name: &str) -> Result<u8, String> {
    match interfaces.iter().position(|n| n == name) {
        Some(i) => Ok(i as u8),
        None if interfaces.len() < MAX_INTERFACES => {
            interfaces.push(name.to_string());
            Ok((interfaces.len() - 1) as u8)
        }
        None => Err(format!(
            "interface \"{name}\" is one more than the {MAX_INTERFACES} channels a log may use"
        )),
    }
}

impl<R> std::fmt::Debug for CandumpReader<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CandumpReader")
            .field("line", &self.lines.number())
            .field("interfaces", &self.interfaces)
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The fast path agrees with the full parser wherever it answers, and leaves every
    /// other form to it.
    fn same_as_parse_line(line: &str) -> bool {
        let full = parse_line(line, 1);
        match parse_common(line.as_bytes()) {
            Some((frame, interface)) => {
                let full = full.unwrap_or_else(|e| panic!("{line}: fast path took it, {e}"));
                assert_eq!(
                    (frame, interface),
                    (full.frame, full.interface.as_bytes()),
                    "{line}"
                );
                true
            }
            None => false,
        }
    }

    #[test]
    fn the_fast_path_reads_common_lines_as_parse_line_does() {
        for line in [
            "(1436509052.249713) can0 044#2A366C2BBA",
            "(0.002146) can0 006#919F00F500",
            "(12) vcan0 7FF#",
            "(12.) can1 7ff#aabb T",
            "(1.1234567) can0 123#00 R",
            "(3.000001) can0 12345678#0102030405060708 t",
            "(3.5) can0 20000004#0000000000000000",
            "(9999999999999.999999) x 000#01",
        ] {
            assert!(
                same_as_parse_line(line),
                "{line}: the fast path should read it"
            );
        }
        for line in [
            "(1.0) can0 123#R",
            "(1.0) can0 123#R4",
            "(1.0) can0 123#11.22",
            "(1.0) can0 12345678#0102030405060708_9",
            "(1.0)  can0 123#11",
            "(1.0)\tcan0 123#11",
            "(1.0) can0 123##011",
            "(1.0) can0 800#11",
            "(1.0) can0 1234#11",
            "(1.0) can0 123#112",
            "(1.0) can0 123#112233445566778899",
            "(1.0) can0 123#11 X",
            "(1.0) can0 123#11 ",
            "(.5) can0 123#11",
            "(123456789012345678901.0) can0 123#11",
            "(1.0) can0 123#1G",
            "1.0 can0 123#11",
        ] {
            assert!(!same_as_parse_line(line), "{line}: left to parse_line");
        }
    }

    proptest::proptest! {
        #[test]
        fn the_fast_path_never_disagrees(
            secs in 0u64..2_000_000_000,
            micros in 0u32..1_000_000,
            id in 0u32..0x4000_0000,
            wide in proptest::bool::ANY,
            data in proptest::collection::vec(proptest::num::u8::ANY, 0..=9),
            tail in proptest::sample::select(vec!["", " R", " T", " r", " x"]),
            noise in proptest::option::of((0usize..40, proptest::num::u8::ANY)),
        ) {
            let id_text = if wide { format!("{id:08X}") } else { format!("{:03X}", id & 0xFFF) };
            let hex: String = data.iter().map(|b| format!("{b:02x}")).collect();
            let mut line = format!("({secs}.{micros:06}) can0 {id_text}#{hex}{tail}").into_bytes();
            if let Some((at, byte)) = noise {
                let at = at.min(line.len() - 1);
                line[at] = byte;
            }
            if let Ok(line) = String::from_utf8(line) {
                same_as_parse_line(&line);
            }
        }
    }

    fn read(text: &str) -> Vec<Result<LogFrame, LogError>> {
        CandumpReader::new(text.as_bytes()).collect()
    }

    fn frame(t_us: u64, id: u32, data: &[u8]) -> LogFrame {
        LogFrame::new(t_us, 0, id, false, FrameKind::Data, data).unwrap()
    }

    #[test]
    fn plain_lines() {
        let l = parse_line("(1436509052.249713) can0 044#2A366C2BBA", 1).unwrap();
        assert_eq!(l.interface, "can0");
        assert_eq!(
            l.frame,
            frame(1_436_509_052_249_713, 0x44, &[0x2A, 0x36, 0x6C, 0x2B, 0xBA])
        );
        assert_eq!(l.frame.direction, Direction::Rx);
        assert_eq!(parse_line("(1.5) vcan0 123#", 1).unwrap().frame.len(), 0);
        assert_eq!(
            parse_line("(0.000001) can0 7ff#aa.bb", 1).unwrap().frame,
            frame(1, 0x7FF, &[0xAA, 0xBB])
        );
    }

    #[test]
    fn python_can_direction_suffix() {
        let rx = parse_line("(1.000000) can0 044#01 R", 1).unwrap().frame;
        let tx = parse_line("(1.000000) can0 044#01 T", 1).unwrap().frame;
        assert_eq!(rx.direction, Direction::Rx);
        assert_eq!(tx.direction, Direction::Tx);
        assert_eq!(rx.data(), tx.data());
    }

    #[test]
    fn extended_remote_and_error_frames() {
        let ext = parse_line("(2.0) can0 1ABCDEF0#0102", 1).unwrap().frame;
        assert!(ext.extended);
        assert_eq!(
            (ext.id, ext.kind, ext.data()),
            (0x1ABC_DEF0, FrameKind::Data, &[1u8, 2][..])
        );
        // An extended identifier below 0x800 keeps its 8 digits and its kind.
        assert!(
            parse_line("(2.0) can0 00000123#", 1)
                .unwrap()
                .frame
                .extended
        );

        let rtr = parse_line("(2.0) can0 123#R", 1).unwrap().frame;
        assert_eq!((rtr.kind, rtr.len()), (FrameKind::Remote, 0));
        let rtr = parse_line("(2.0) can0 123#R4 T", 1).unwrap().frame;
        assert_eq!(
            (rtr.kind, rtr.len(), rtr.direction),
            (FrameKind::Remote, 4, Direction::Tx)
        );
        let rtr = parse_line("(2.0) can0 1ABCDEF0#R8", 1).unwrap().frame;
        assert!(rtr.extended && rtr.kind == FrameKind::Remote && rtr.len() == 8);

        // candump -l with error frames enabled; python-can's way (no data, no R/T).
        let e = parse_line("(3.0) can0 20000004#0004000000000000", 1)
            .unwrap()
            .frame;
        assert_eq!((e.kind, e.id, e.extended), (FrameKind::Error, 0x4, false));
        assert_eq!(e.data(), &[0, 4, 0, 0, 0, 0, 0, 0]);
        let e = parse_line("(3.0) can0 20000080#", 1).unwrap().frame;
        assert_eq!((e.kind, e.id, e.len()), (FrameKind::Error, 0x80, 0));
        // The raw DLC suffix of an 8-byte frame.
        let f = parse_line("(3.0) can0 123#0102030405060708_C", 1)
            .unwrap()
            .frame;
        assert_eq!(f.len(), 8);
    }

    #[test]
    fn fd_frames_keep_their_flags_and_64_bytes() {
        let f = parse_line("(4.0) can0 123##1112233445566778899AABBCC", 1)
            .unwrap()
            .frame;
        assert_eq!(
            (f.id, f.len(), f.dlc(), f.fd()),
            (
                0x123,
                12,
                9,
                Some(FdFlags {
                    brs: true,
                    esi: false
                })
            )
        );
        assert_eq!(f.data()[11], 0xCC);
        let text = format!("(4.0) can1 1ABCDEF0##3{} T", "A5".repeat(64));
        let f = parse_line(&text, 1).unwrap().frame;
        assert_eq!(
            (f.extended, f.len(), f.direction),
            (true, 64, Direction::Tx)
        );
        assert_eq!(
            f.fd(),
            Some(FdFlags {
                brs: true,
                esi: true
            })
        );
        // can-utils 2023 also writes the FDF bit (0x4); nothing else changes.
        let f = parse_line("(4.0) can0 7FF##4", 1).unwrap().frame;
        assert_eq!(
            (f.len(), f.fd(), f.is_fd()),
            (0, Some(FdFlags::default()), true)
        );
        let long = format!("(4.0) can0 123##0{}", "00".repeat(65));
        assert_eq!(
            parse_line(&long, 1).unwrap_err().message,
            "65 data bytes: a CAN FD frame carries at most 64"
        );
    }

    #[test]
    fn broken_lines_are_named() {
        let cases = [
            ("(1.0) can0 12345#00", "has 5 digits"),
            ("(1.0) can0 123#0", "odd number of hex digits"),
            (
                "(1.0) can0 123#000102030405060708",
                "9 data bytes: a classic CAN frame carries at most 8",
            ),
            (
                "(1.0) can0 123##G00",
                "\"##\" must be followed by a hex digit of flags",
            ),
            ("(1.0) can0 123##", "a hex digit of flags"),
            (
                "(1.0) can0 123##1000102030405060708",
                "9 data bytes: a CAN FD frame carries 0 to 8, 12",
            ),
            ("(1.0) can0 20000004##100", "cannot be a CAN FD frame"),
            ("(1.0) can0 123#R9", "remote frame length \"9\""),
            ("(1.0) can0 20000004#R", "cannot be a remote frame"),
            ("1.0 can0 123#00", "not in parentheses"),
            ("(1.x) can0 123#00", "not seconds.fraction"),
            ("(-1.0) can0 123#00", "not seconds.fraction"),
            ("(1.0) can0 12G#00", "identifier \"12G\" is not hexadecimal"),
            ("(1.0) can0 +12#00", "not hexadecimal"),
            ("(1.0) can0 #00", "not hexadecimal"),
            ("(1.0) can0 123#0G", "not hexadecimal"),
            ("(1.0) can0 123#01_2", "'_' must be followed"),
            ("(1.0) can0", "expected"),
            ("(1.0) can0 123#00 X", "unexpected \"X\""),
            ("(1.0) can0 123#00 R R", "unexpected \"R\""),
            ("(1.0) can0 123", "no '#'"),
            ("(1.0) can0 800#00", "does not fit 11 bits"),
            ("(1.0) can0 C0000000#00", "does not fit 29 bits"),
        ];
        for (line, expected) in cases {
            let e = parse_line(line, 7).unwrap_err();
            assert_eq!(e.line, 7);
            assert!(!e.is_fatal());
            assert!(e.message.contains(expected), "{line}: {e}");
        }
        assert_eq!(
            parse_line("(1.0) can0 12G#00", 17).unwrap_err().to_string(),
            "line 17: identifier \"12G\" is not hexadecimal"
        );
    }

    #[test]
    fn a_bad_line_in_the_middle_is_reported_and_reading_goes_on() {
        let got =
            read("(1.0) can0 001#00\n\n(2.0) can0 002#01\n(3.0) can0 zz\n(4.0) can0 004#00\n");
        assert_eq!(got.len(), 4);
        assert_eq!(got[1].as_ref().unwrap().id, 2);
        let e = got[2].as_ref().unwrap_err();
        assert_eq!(e.line, 4, "blank lines count");
        assert_eq!(got[3].as_ref().unwrap().id, 4);
    }

    /// candump -l writes a line when the kernel reports frames its socket dropped.
    #[test]
    fn dropcount_lines_are_counted_and_reading_goes_on() {
        let text = "(1.0) can0 001#00\n\
                    DROPCOUNT: dropped 3 CAN frames on 'can0' socket (total drops 3)\n\
                    (2.0) can0 002#01\n\
                    DROPCOUNT: dropped 1 CAN frame on 'can0' socket (total drops 4)\n\
                    (3.0) can0 003#02\n";
        let mut r = CandumpReader::new(text.as_bytes());
        let got: Vec<u32> = r
            .by_ref()
            .map(|f| f.unwrap_or_else(|e| panic!("{e}")).id)
            .collect();
        assert_eq!(got, [1, 2, 3]);
        assert_eq!(r.dropped_frames(), 4);

        let got = read("(1.0) can0 001#00\nDROPCOUNT: lost some\n(2.0) can0 002#01\n");
        assert_eq!(got.len(), 3);
        let e = got[1].as_ref().unwrap_err();
        assert_eq!(
            e.to_string(),
            "line 2: DROPCOUNT line (frames the logger reported dropped) does not say how many: \"DROPCOUNT: lost some\""
        );
        let e = parse_line(
            "DROPCOUNT: dropped 2 CAN frames on 'can0' socket (total drops 2)",
            9,
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "line 9: DROPCOUNT line: 2 frame(s) the logger reported dropped, not a frame"
        );
    }

    #[test]
    fn empty_blank_and_crlf() {
        assert!(read("").is_empty());
        assert!(read("\n\n   \r\n").is_empty());
        let got = read("(1.0) can0 001#00\r\n(2.0) can0 002#0102\r\n");
        assert_eq!(got.len(), 2);
        assert_eq!(got[1].as_ref().unwrap().data(), &[1, 2]);
    }

    #[test]
    fn interfaces_become_channels_in_order_of_appearance() {
        let mut r =
            CandumpReader::new("(1.0) vcan1 001#\n(2.0) can0 002#\n(3.0) vcan1 003#\n".as_bytes());
        let channels: Vec<u8> = r.by_ref().map(|f| f.unwrap().channel).collect();
        assert_eq!(channels, [0, 1, 0]);
        assert_eq!(r.interfaces(), ["vcan1", "can0"]);
    }

    #[test]
    fn time_going_backwards_is_not_judged() {
        let got: Vec<u64> = read("(5.0) can0 001#\n(1.0) can0 001#\n(3.0) can0 001#\n")
            .into_iter()
            .map(|f| f.unwrap().t_us)
            .collect();
        assert_eq!(got, [5_000_000, 1_000_000, 3_000_000]);
    }

    #[test]
    fn io_errors_are_fatal_and_end_the_read() {
        struct Failing(u8);
        impl std::io::Read for Failing {
            fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
                if self.0 == 0 {
                    return Err(std::io::Error::other("device gone"));
                }
                self.0 -= 1;
                let line = b"(1.0) can0 001#00\n";
                buf[..line.len()].copy_from_slice(line);
                Ok(line.len())
            }
        }
        let mut r = CandumpReader::new(std::io::BufReader::with_capacity(64, Failing(1)));
        assert!(r.next().unwrap().is_ok());
        let e = r.next().unwrap().unwrap_err();
        assert!(e.is_fatal());
        assert_eq!(e.to_string(), "line 2: cannot read the file: device gone");
        assert!(r.next().is_none());
    }
}
