//! Vector's ASC text log (CANoe, CANalyzer, python-can's `ASCWriter`):
//!
//! ```text
//! date Thu Nov 23 13:28:00.000 2026
//! base hex  timestamps absolute
//! internal events logged
//! Begin Triggerblock Thu Nov 23 13:28:00.000 2026
//!    0.000000 Start of measurement
//!    0.012345 1  123             Rx   d 8 01 02 03 04 05 06 07 08
//!    0.013000 2  1ABCDEF0x       Tx   d 2 01 02  Length = 240000 BitCount = 62
//!    0.014000 1  123             Rx   r 4
//!    0.015000 1  ErrorFrame
//! End TriggerBlock
//! ```
//!
//! Times are seconds since the start of the measurement and stay so: `t_us` of an ASC
//! frame is relative to the file's start (its `date` line is kept as text, see
//! [`AscReader::date`]). With `timestamps relative` each time counts from the previous
//! event and the reader adds them up. Channels are 1-based in the file, 0-based in
//! [`LogFrame`]. `base dec` makes identifiers, DLCs and data bytes decimal.
//!
//! Comments, header lines and events that are not frames (statistics, chip states, start
//! of measurement, J1939 and the like) are skipped; CAN FD (`CANFD`) lines are errors a
//! lenient caller can skip.

use std::io::BufRead;

use super::lines::{Line, Lines};
use super::LogError;
use crate::frame::{Direction, FrameKind, LogFrame};
use crate::time::parse_seconds;

/// Reads an ASC log line by line; see the [module](self).
pub struct AscReader<R> {
    lines: Lines<R>,
    state: State,
    done: bool,
}

/// What the lines read so far set.
#[derive(Default)]
struct State {
    decimal: bool,
    relative: bool,
    /// Time of the previous event (`timestamps relative`).
    last_us: u64,
    date: Option<String>,
}

impl<R: BufRead> AscReader<R> {
    /// A reader of this input.
    pub fn new(input: R) -> Self {
        Self {
            lines: Lines::new(input),
            state: State::default(),
            done: false,
        }
    }

    /// The text of the header's `date` line (`Thu Nov 23 13:28:00.000 2026`), once read:
    /// the wall-clock start of the measurement, in the recording machine's local time.
    pub fn date(&self) -> Option<&str> {
        self.state.date.as_deref()
    }
}

impl State {
    /// One line: `Ok(None)` for anything that is not a frame.
    fn parse(&mut self, text: &str, line: u64) -> Result<Option<LogFrame>, LogError> {
        let err = |message: String| LogError::at_line(line, message);
        let trimmed = text.trim();
        let mut tokens = trimmed.split_whitespace();
        let Some(first) = tokens.next() else {
            return Ok(None);
        };
        if trimmed.starts_with("//") {
            return Ok(None);
        }
        if first.eq_ignore_ascii_case("date") {
            self.date = Some(trimmed[4..].trim().to_string());
            return Ok(None);
        }
        if first.eq_ignore_ascii_case("base") {
            match tokens.next() {
                Some(b) if b.eq_ignore_ascii_case("hex") => self.decimal = false,
                Some(b) if b.eq_ignore_ascii_case("dec") => self.decimal = true,
                other => {
                    return Err(err(format!(
                        "\"base {}\": expected \"base hex\" or \"base dec\"",
                        other.unwrap_or("")
                    )))
                }
            }
            if tokens
                .next()
                .is_some_and(|t| t.eq_ignore_ascii_case("timestamps"))
            {
                self.relative = tokens
                    .next()
                    .is_some_and(|t| t.eq_ignore_ascii_case("relative"));
            }
            return Ok(None);
        }
        if !first.as_bytes()[0].is_ascii_digit() {
            // Other header lines ("internal events logged", "Begin Triggerblock ...",
            // "End TriggerBlock") and events without a time.
            return Ok(None);
        }
        let t = parse_seconds(first)
            .ok_or_else(|| err(format!("timestamp \"{first}\" is not seconds.fraction")))?;
        let t_us = if self.relative {
            self.last_us = self.last_us.saturating_add(t);
            self.last_us
        } else {
            t
        };
        let Some(channel_text) = tokens.next() else {
            return Ok(None);
        };
        if channel_text.eq_ignore_ascii_case("CANFD") {
            return Err(err(
                "CAN FD frame (CANFD event) is not supported: classic CAN only".into(),
            ));
        }
        if !channel_text.bytes().all(|b| b.is_ascii_digit()) {
            // "Start of measurement", "SV:", "J1939TP", ...
            return Ok(None);
        }
        let channel = match channel_text.parse::<u32>() {
            Ok(n @ 1..=256) => (n - 1) as u8,
            _ => {
                return Err(err(format!(
                    "channel \"{channel_text}\": ASC channels are 1 to 256"
                )))
            }
        };
        let Some(id_text) = tokens.next() else {
            return Ok(None);
        };
        if id_text.eq_ignore_ascii_case("ErrorFrame") {
            let frame = LogFrame::new(t_us, channel, 0, false, FrameKind::Error, &[])
                .map_err(|e| err(e.to_string()))?;
            return Ok(Some(frame));
        }
        let direction = match tokens.next() {
            Some(d) if d.eq_ignore_ascii_case("Rx") => Direction::Rx,
            Some(d) if d.eq_ignore_ascii_case("Tx") => Direction::Tx,
            // "1 Statistic: ...", "1 Status: chip status error active", ...
            _ => return Ok(None),
        };
        let (digits, extended) = match id_text.strip_suffix(['x', 'X']) {
            Some(digits) => (digits, true),
            None => (id_text, false),
        };
        let id = self
            .number(digits)
            .ok_or_else(|| err(format!("identifier \"{id_text}\" is not {}", self.base())))?;
        let kind_text = tokens.next().unwrap_or("");
        let frame = if kind_text.eq_ignore_ascii_case("d") {
            let dlc_text = tokens
                .next()
                .ok_or_else(|| err("a data frame needs its DLC after \"d\"".into()))?;
            let dlc = self
                .number(dlc_text)
                .filter(|&d| d <= 15)
                .ok_or_else(|| err(format!("DLC \"{dlc_text}\" is not a number 0 to 15")))?;
            // A classic DLC of 9 to 15 still means 8 bytes.
            let len = dlc.min(8) as usize;
            let mut data = [0u8; 8];
            for (i, byte) in data.iter_mut().take(len).enumerate() {
                let b = tokens
                    .next()
                    .ok_or_else(|| err(format!("DLC {dlc} but only {i} data bytes")))?;
                *byte = self
                    .number(b)
                    .and_then(|v| u8::try_from(v).ok())
                    .ok_or_else(|| err(format!("data byte \"{b}\" is not {}", self.base())))?;
            }
            LogFrame::new(t_us, channel, id, extended, FrameKind::Data, &data[..len])
        } else if kind_text.eq_ignore_ascii_case("r") {
            let dlc = match tokens.next().and_then(|t| self.number(t)) {
                Some(d) => d.min(8) as u8,
                None => 0,
            };
            LogFrame::remote(t_us, channel, id, extended, dlc)
        } else {
            return Err(err(format!(
                "expected \"d\" (data) or \"r\" (remote) after {}, found \"{kind_text}\"",
                if direction == Direction::Rx {
                    "Rx"
                } else {
                    "Tx"
                }
            )));
        }
        .map_err(|e| err(e.to_string()))?;
        Ok(Some(frame.with_direction(direction)))
    }

    fn base(&self) -> &'static str {
        if self.decimal {
            "decimal (base dec)"
        } else {
            "hexadecimal"
        }
    }

    fn number(&self, text: &str) -> Option<u32> {
        let radix = if self.decimal { 10 } else { 16 };
        if text.is_empty() || text.len() > 10 || !text.chars().all(|c| c.is_digit(radix)) {
            return None;
        }
        u32::from_str_radix(text, radix).ok()
    }
}

impl<R: BufRead> Iterator for AscReader<R> {
    type Item = Result<LogFrame, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        loop {
            let number = self.lines.number() + 1;
            let text = match self.lines.next_line() {
                None => {
                    self.done = true;
                    return None;
                }
                Some(Err(e)) => {
                    self.done = true;
                    return Some(Err(LogError::io(number, &e)));
                }
                Some(Ok(Line::Bad(message))) => {
                    return Some(Err(LogError::at_line(number, message)))
                }
                Some(Ok(Line::Text(text))) => text,
            };
            match self.state.parse(text, number) {
                Ok(None) => continue,
                Ok(Some(frame)) => return Some(Ok(frame)),
                Err(e) => return Some(Err(e)),
            }
        }
    }
}

impl<R> std::fmt::Debug for AscReader<R> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AscReader")
            .field("line", &self.lines.number())
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const HEADER: &str = "date Thu Nov 23 13:28:00.000 2026\nbase hex  timestamps absolute\ninternal events logged\n// version 13.0.0\nBegin Triggerblock Thu Nov 23 13:28:00.000 2026\n   0.000000 Start of measurement\n";

    fn read(text: &str) -> Vec<Result<LogFrame, LogError>> {
        AscReader::new(text.as_bytes()).collect()
    }

    fn frames(text: &str) -> Vec<LogFrame> {
        read(text).into_iter().map(|f| f.unwrap()).collect()
    }

    #[test]
    fn frames_of_every_kind() {
        let text = format!(
            "{HEADER}   0.012345 1  123             Rx   d 8 01 02 03 04 05 06 07 08\n\
             \x20  0.013000 2  1ABCDEF0x       Tx   d 2 0A FF  Length = 240000 BitCount = 62 ID = 123\n\
             \x20  0.014000 1  7FF             Rx   r 4\n\
             \x20  0.014500 1  10              Rx   r\n\
             \x20  0.015000 1  ErrorFrame\n\
             \x20  0.016000 1  20              Rx   d 0\n\
             End TriggerBlock\n"
        );
        let mut r = AscReader::new(text.as_bytes());
        let f: Vec<LogFrame> = r.by_ref().map(|f| f.unwrap()).collect();
        assert_eq!(r.date(), Some("Thu Nov 23 13:28:00.000 2026"));
        assert_eq!(f.len(), 6);
        assert_eq!((f[0].t_us, f[0].channel, f[0].id), (12_345, 0, 0x123));
        assert_eq!(f[0].data(), &[1, 2, 3, 4, 5, 6, 7, 8]);
        assert_eq!(
            (f[1].channel, f[1].id, f[1].extended),
            (1, 0x1ABC_DEF0, true)
        );
        assert_eq!(
            (f[1].direction, f[1].data()),
            (Direction::Tx, &[0x0A, 0xFF][..])
        );
        assert_eq!(
            (f[2].kind, f[2].len(), f[2].id),
            (FrameKind::Remote, 4, 0x7FF)
        );
        assert_eq!((f[3].kind, f[3].len()), (FrameKind::Remote, 0));
        assert_eq!((f[4].kind, f[4].t_us), (FrameKind::Error, 15_000));
        assert_eq!(f[5].len(), 0);
    }

    #[test]
    fn base_dec_and_relative_timestamps() {
        let text = "base dec  timestamps relative\n   1.000000 1  291 Rx d 2 10 255\n   0.500000 1  17x Tx d 1 0\n   0.250000 1  Statistic: D 1 R 0 XD 0 XR 0 E 0 O 0 B 0.1%\n   0.250000 1  1 Rx d 0\n";
        let f = frames(text);
        assert_eq!(f.len(), 3);
        assert_eq!(
            (f[0].id, f[0].data(), f[0].t_us),
            (291, &[10, 255][..], 1_000_000)
        );
        assert_eq!((f[1].id, f[1].extended, f[1].t_us), (17, true, 1_500_000));
        assert_eq!(
            f[2].t_us, 2_000_000,
            "the statistics line's time counts too"
        );
        let e = read("base dec\n 1.0 1 1A Rx d 0\n")[0].clone().unwrap_err();
        assert!(e.message.contains("not decimal"), "{e}");
    }

    #[test]
    fn unknown_events_comments_and_canfd() {
        let text = format!(
            "{HEADER}// a comment\n   0.100000 1  Status: chip status error active\n   0.110000 CANFD   1 Rx 123  1 0 8  8 01 02 03 04 05 06 07 08 0 0 1000 0 0 0 0 0\n   0.120000 Start of measurement\n   0.200000 1  123 Rx d 1 AA\nEnd TriggerBlock\n"
        );
        let got = read(&text);
        assert_eq!(got.len(), 2);
        let e = got[0].as_ref().unwrap_err();
        assert_eq!(e.line, 9);
        assert!(e.message.contains("CAN FD frame") && e.message.contains("not supported"));
        assert_eq!(got[1].as_ref().unwrap().data(), &[0xAA]);
    }

    #[test]
    fn malformed_lines_name_their_number_and_reading_goes_on() {
        let cases = [
            (
                "1.0 1 12G Rx d 1 00",
                "identifier \"12G\" is not hexadecimal",
            ),
            ("1.0 1 123 Rx d 2 00", "DLC 2 but only 1 data bytes"),
            ("1.0 1 123 Rx d", "needs its DLC"),
            ("1.0 1 123 Rx d Z", "DLC \"Z\""),
            ("1.0 1 123 Rx d 1 100", "data byte \"100\""),
            ("1.0 1 123 Rx q 1", "expected \"d\" (data) or \"r\""),
            ("1.0 1 800 Rx d 0", "does not fit 11 bits"),
            ("1.0 0 123 Rx d 0", "channel \"0\""),
            ("1.x 1 123 Rx d 0", "not seconds.fraction"),
            ("base oct", "expected \"base hex\""),
        ];
        for (line, expected) in cases {
            let text = format!("   0.5 1 001 Rx d 0\n{line}\n   2.0 1 002 Rx d 0\n");
            let got = read(&text);
            assert_eq!(got.len(), 3, "{line}");
            let e = got[1].as_ref().unwrap_err();
            assert_eq!(e.line, 2);
            assert!(e.message.contains(expected), "{line}: {e}");
            assert_eq!(got[2].as_ref().unwrap().id, 2);
        }
    }

    #[test]
    fn empty_blank_crlf_and_backwards_time() {
        assert!(read("").is_empty());
        assert!(read("\n \n\r\n").is_empty());
        assert!(read(HEADER).is_empty());
        let f = frames("   2.0 1 001 Rx d 0\r\n\r\n   1.0 1 002 Rx d 1 01\r\n");
        assert_eq!(
            f.iter().map(|f| f.t_us).collect::<Vec<_>>(),
            [2_000_000, 1_000_000]
        );
        assert_eq!(f[1].data(), &[1]);
    }
}
