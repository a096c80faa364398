//! The candump log format of linux-can's can-utils, which candump, canplayer, python-can,
//! cantools and SavvyCAN read: one frame per line, `(1436509052.249713) can0 044#2A366C2BBA`.

use autoplug_can::Frame;
use std::fmt;
use std::io::{self, BufRead, Write};

/// One logged frame.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LogRecord {
    /// Timestamp in microseconds.
    pub t_us: u64,
    /// Interface name (`can0`).
    pub interface: String,
    /// The frame.
    pub frame: Frame,
}

/// Writes `(seconds.micros) interface ID#DATA` with a 3-digit identifier.
pub fn write_record(
    out: &mut impl Write,
    t_us: u64,
    interface: &str,
    frame: &Frame,
) -> io::Result<()> {
    write!(
        out,
        "({}.{:06}) {interface} {:03X}#",
        t_us / 1_000_000,
        t_us % 1_000_000,
        frame.id()
    )?;
    for b in frame.data() {
        write!(out, "{b:02X}")?;
    }
    writeln!(out)
}

/// Why a log line was refused.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LogError {
    /// 1-based line number.
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for LogError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}: {}", self.line, self.message)
    }
}

impl std::error::Error for LogError {}

/// Parses one line. python-can's trailing ` R` / ` T` (received / transmitted) is accepted.
pub fn parse_line(text: &str, line: usize) -> Result<LogRecord, LogError> {
    let err = |message: String| LogError { line, message };
    let mut parts = text.split_whitespace();
    let (Some(stamp), Some(interface), Some(body)) = (parts.next(), parts.next(), parts.next())
    else {
        return Err(err(format!(
            "expected \"(seconds.micros) interface ID#DATA\", found \"{}\"",
            text.trim()
        )));
    };
    match parts.next() {
        None | Some("R") | Some("T") => {}
        Some(extra) => return Err(err(format!("unexpected \"{extra}\" after the frame"))),
    }
    if parts.next().is_some() {
        return Err(err("unexpected text after the frame".into()));
    }
    let stamp = stamp
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .ok_or_else(|| err(format!("timestamp \"{stamp}\" is not in parentheses")))?;
    let t_us = parse_timestamp(stamp)
        .ok_or_else(|| err(format!("timestamp \"{stamp}\" is not seconds.fraction")))?;
    let (id_text, data_text) = body.split_once('#').ok_or_else(|| {
        err(format!(
            "frame \"{body}\" has no '#' between identifier and data"
        ))
    })?;
    if data_text.starts_with('#') {
        return Err(err(
            "CAN FD frames (\"##\") are not part of a classic CAN log".into(),
        ));
    }
    if data_text.starts_with('R') {
        return Err(err("remote frames are not supported".into()));
    }
    if id_text.len() != 3 {
        return Err(err(format!(
            "identifier \"{id_text}\": the AutoPlug bus uses 11-bit identifiers written with 3 hex digits (8 digits mean an extended or error frame)"
        )));
    }
    let id = u32::from_str_radix(id_text, 16)
        .map_err(|_| err(format!("identifier \"{id_text}\" is not hexadecimal")))?;
    if data_text.len() % 2 != 0 {
        return Err(err(format!(
            "data \"{data_text}\" has an odd number of hex digits"
        )));
    }
    let mut data = [0u8; 8];
    let len = data_text.len() / 2;
    if len > 8 {
        return Err(err(format!(
            "{len} data bytes: a classic CAN frame carries at most 8"
        )));
    }
    for (i, byte) in data.iter_mut().take(len).enumerate() {
        *byte = u8::from_str_radix(&data_text[2 * i..2 * i + 2], 16)
            .map_err(|_| err(format!("data \"{data_text}\" is not hexadecimal")))?;
    }
    let frame = Frame::new(id, &data[..len]).map_err(|e| err(e.to_string()))?;
    Ok(LogRecord {
        t_us,
        interface: interface.to_string(),
        frame,
    })
}

/// `1436509052.249713` as microseconds, exactly (no floating point); more than 6 decimals
/// are truncated, fewer are padded.
fn parse_timestamp(text: &str) -> Option<u64> {
    let (secs, frac) = text.split_once('.').unwrap_or((text, ""));
    if secs.is_empty()
        || !secs.bytes().all(|b| b.is_ascii_digit())
        || !frac.bytes().all(|b| b.is_ascii_digit())
    {
        return None;
    }
    let secs: u64 = secs.parse().ok()?;
    let mut micros = 0u64;
    for (i, b) in frac
        .bytes()
        .chain(std::iter::repeat(b'0'))
        .take(6)
        .enumerate()
    {
        let _ = i;
        micros = micros * 10 + u64::from(b - b'0');
    }
    secs.checked_mul(1_000_000)?.checked_add(micros)
}

/// Reads a whole log. Blank lines are skipped; the first bad line stops the read with its
/// line number, and nothing read before it is lost to the caller (`Err` carries the
/// records read so far).
pub fn read_log(input: impl BufRead) -> Result<Vec<LogRecord>, (Vec<LogRecord>, LogError)> {
    let mut records = Vec::new();
    for (i, line) in input.lines().enumerate() {
        let line_no = i + 1;
        let text = match line {
            Ok(text) => text,
            Err(e) => {
                return Err((
                    records,
                    LogError {
                        line: line_no,
                        message: format!("cannot read: {e}"),
                    },
                ));
            }
        };
        if text.trim().is_empty() {
            continue;
        }
        match parse_line(&text, line_no) {
            Ok(record) => records.push(record),
            Err(e) => return Err((records, e)),
        }
    }
    Ok(records)
}
