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
//! of measurement, global markers, J1939 and the like) are skipped. A `CANFD` event whose
//! flags have the FDF bit (0x1000) clear holds a classic frame (CANoe logs classic frames
//! on a CAN FD channel so, and can-utils' `log2asc -f` writes every frame so) and is read
//! as one, remote when the flags have 0x10; with FDF set it is a CAN FD frame (BRS and ESI
//! from their columns or the flags 0x2000 and 0x4000). `CANXL` events are errors a lenient
//! caller can skip.
//!
//! ```text
//!    0.100000 CANFD   1 Rx        123  EngineData  0 0 8  8 01 02 03 04 05 06 07 08   130000  130        0 0 0 0 0 0
//! ```
//!
//! (channel, direction, identifier, an optional symbolic name, BRS, ESI, DLC in hex, data
//! length in decimal, the data, frame duration, bit count, flags in hex, CRC, bit timings.)

use std::io::BufRead;

use super::lines::{Line, Lines};
use super::LogError;
use crate::frame::{dlc_to_len, Direction, FdFlags, FrameKind, LogFrame};
use crate::time::parse_seconds;

/// The FDF (EDL) bit of a `CANFD` event's flags: the frame is CAN FD.
const ASC_FDF: u32 = 0x1000;
/// The remote-frame bit of a `CANFD` event's flags.
const ASC_RTR: u32 = 0x10;
/// The bit rate switch bit of a `CANFD` event's flags.
const ASC_BRS: u32 = 0x2000;
/// The error state indicator bit of a `CANFD` event's flags.
const ASC_ESI: u32 = 0x4000;

/// A frame's channel, 1-based in the file, 0-based in [`LogFrame`].
fn channel(text: &str) -> Result<u8, String> {
    match text.parse::<u32>() {
        Ok(n @ 1..=256) => Ok((n - 1) as u8),
        Ok(0) => Err("channel \"0\": ASC channels count from 1".into()),
        // A frame's channel is a u8 here: AutoPlug's limit, not the format's.
        _ => Err(format!(
            "channel \"{text}\": AutoPlug reads ASC channels 1 to 256 only"
        )),
    }
}

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
            return self.canfd(tokens, t_us).map_err(err);
        }
        if channel_text.eq_ignore_ascii_case("CANXL") {
            return Err(err(
                "CAN XL frame (CANXL event) is not supported: CAN and CAN FD only".into(),
            ));
        }
        if !channel_text.bytes().all(|b| b.is_ascii_digit()) {
            // "Start of measurement", "SV:", "J1939TP", ...
            return Ok(None);
        }
        // What the line is decides whether its channel matters: a global marker's channel
        // field is 0 ("2.2 0 16777215 0 1 GMGroup: ..."), and it is no frame.
        let Some(id_text) = tokens.next() else {
            return Ok(None);
        };
        if id_text.eq_ignore_ascii_case("ErrorFrame") {
            let channel = channel(channel_text).map_err(err)?;
            let frame = LogFrame::new(t_us, channel, 0, false, FrameKind::Error, &[])
                .map_err(|e| err(e.to_string()))?;
            return Ok(Some(frame));
        }
        let direction = match tokens.next() {
            Some(d) if d.eq_ignore_ascii_case("Rx") => Direction::Rx,
            Some(d) if d.eq_ignore_ascii_case("Tx") => Direction::Tx,
            // "1 Statistic: ...", "1 Status: chip status error active", markers, ...
            _ => return Ok(None),
        };
        let channel = channel(channel_text).map_err(err)?;
        let (id, extended) = self.identifier(id_text).map_err(err)?;
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

    /// The rest of a `CANFD` line (see the [module](self) for its layout): a CAN FD frame
    /// when its FDF flag is set, else a classic one.
    fn canfd<'a>(
        &self,
        mut tokens: impl Iterator<Item = &'a str> + Clone,
        t_us: u64,
    ) -> Result<Option<LogFrame>, String> {
        let mut next = |what: &str| {
            tokens
                .next()
                .ok_or_else(|| format!("CANFD line ends before its {what}"))
        };
        let channel_text = next("channel")?;
        let direction = match next("direction")? {
            d if d.eq_ignore_ascii_case("Rx") => Direction::Rx,
            d if d.eq_ignore_ascii_case("Tx") => Direction::Tx,
            d => {
                return Err(format!(
                    "expected Rx or Tx after the CANFD channel, found \"{d}\""
                ))
            }
        };
        let id_text = next("identifier")?;
        if id_text.eq_ignore_ascii_case("ErrorFrame") {
            let frame = LogFrame::new(
                t_us,
                channel(channel_text)?,
                0,
                false,
                FrameKind::Error,
                &[],
            )
            .map_err(|e| e.to_string())?;
            return Ok(Some(frame.with_direction(direction)));
        }
        let (id, extended) = self.identifier(id_text)?;
        // BRS is 0 or 1; anything else there is the frame's symbolic name, BRS after it.
        let mut brs = next("BRS flag")?;
        if brs != "0" && brs != "1" {
            brs = next("BRS flag")?;
        }
        let esi = next("ESI flag")?;
        let dlc_text = next("DLC")?;
        let dlc = self
            .number(dlc_text)
            .filter(|&d| d <= 15)
            .ok_or_else(|| format!("DLC \"{dlc_text}\" is not a number 0 to 15"))?;
        let length_text = next("data length")?;
        let length = length_text
            .parse::<usize>()
            .ok()
            .filter(|&n| n <= 64)
            .ok_or_else(|| format!("data length \"{length_text}\" is not a number 0 to 64"))?;
        // The flags come after the data, the frame's duration and its bit count.
        let data_tokens = tokens.clone();
        for present in 0..length {
            if tokens.next().is_none() {
                return Err(format!("{length} data bytes announced, {present} present"));
            }
        }
        let mut after_data = |what: &str| {
            tokens
                .next()
                .ok_or_else(|| format!("CANFD line ends before its {what}"))
        };
        after_data("flags")?;
        after_data("flags")?;
        let flags_text = after_data("flags")?;
        let flags = u32::from_str_radix(flags_text, 16)
            .map_err(|_| format!("flags \"{flags_text}\" are not hexadecimal"))?;
        let fd = flags & ASC_FDF != 0;
        if fd && dlc_to_len(dlc as u8, true) != length {
            return Err(format!(
                "DLC {dlc:X} says {} data bytes, the data length {length}",
                dlc_to_len(dlc as u8, true)
            ));
        }
        if !fd && length > 8 {
            return Err(format!(
                "{length} data bytes in a classic frame (FDF flag clear): at most 8"
            ));
        }
        let channel = channel(channel_text)?;
        let mut data = [0u8; 64];
        for (byte, text) in data.iter_mut().zip(data_tokens).take(length) {
            *byte = self
                .number(text)
                .and_then(|v| u8::try_from(v).ok())
                .ok_or_else(|| format!("data byte \"{text}\" is not {}", self.base()))?;
        }
        let frame = if fd {
            let flags = FdFlags {
                brs: brs == "1" || flags & ASC_BRS != 0,
                esi: esi == "1" || flags & ASC_ESI != 0,
            };
            LogFrame::new_fd(t_us, channel, id, extended, &data[..length], flags)
        } else if flags & ASC_RTR != 0 {
            // A classic DLC of 9 to 15 still means 8 bytes.
            LogFrame::remote(t_us, channel, id, extended, dlc.min(8) as u8)
        } else {
            LogFrame::new(
                t_us,
                channel,
                id,
                extended,
                FrameKind::Data,
                &data[..length],
            )
        }
        .map_err(|e| e.to_string())?;
        Ok(Some(frame.with_direction(direction)))
    }

    /// `123` or `1ABCDEF0x` (extended).
    fn identifier(&self, text: &str) -> Result<(u32, bool), String> {
        let (digits, extended) = match text.strip_suffix(['x', 'X']) {
            Some(digits) => (digits, true),
            None => (text, false),
        };
        let id = self
            .number(digits)
            .ok_or_else(|| format!("identifier \"{text}\" is not {}", self.base()))?;
        Ok((id, extended))
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
        let fd = got[0].as_ref().unwrap();
        assert_eq!((fd.id, fd.len(), fd.is_fd()), (0x123, 8, true));
        assert_eq!(got[1].as_ref().unwrap().data(), &[0xAA]);
    }

    /// With its FDF bit (0x1000 in the flags) clear, a CANFD event holds a classic frame:
    /// how CANoe logs classic frames on a CAN FD channel, and what can-utils' `log2asc -f`
    /// writes. Layout: channel, direction, identifier, an optional symbolic name, BRS, ESI,
    /// DLC (hex), data length (decimal), the data, then duration, bit count, flags (hex),
    /// CRC and the bit timings.
    #[test]
    fn canfd_events_with_classic_frames_are_read() {
        let text = format!(
            "{HEADER}\
             \x20  0.100000 CANFD   1 Rx        123                                   0 0 8  8 01 02 03 04 05 06 07 08   130000  130        0 0 0 0 0 0\n\
             \x20  0.110000 CANFD   2 Tx   1ABCDEF0x  EngineData  0 0 3  3 0A 0B 0C  112000  112  0  1c2d 0 0 0 0\n\
             \x20  0.120000 CANFD   1 Rx        7FF                                   0 0 4  0   130000  130       10 0 0 0 0 0\n\
             \x20  0.130000 CANFD   1 Rx        100                                   1 0 9 12 00 01 02 03 04 05 06 07 08 09 0A 0B   130000  130     3000 0 0 0 0 0\n\
             \x20  0.140000 CANFD   1 Rx        020                                   0 0 0  0   130000  130        0 0 0 0 0 0\n\
             \x20  0.150000 CANFD   1 Rx        101  0 0 8  8 11 22 33 44 55 66 77 88 0 0 1000 0 0 0 0 0\n\
             End TriggerBlock\n"
        );
        let got = read(&text);
        assert_eq!(got.len(), 6, "{got:?}");
        let f = got[0].as_ref().unwrap();
        assert_eq!(
            (f.t_us, f.channel, f.id, f.extended, f.kind, f.direction),
            (100_000, 0, 0x123, false, FrameKind::Data, Direction::Rx)
        );
        assert_eq!(f.data(), &[1, 2, 3, 4, 5, 6, 7, 8]);
        let f = got[1].as_ref().unwrap();
        assert_eq!(
            (f.channel, f.id, f.extended, f.direction, f.data()),
            (1, 0x1ABC_DEF0, true, Direction::Tx, &[0x0A, 0x0B, 0x0C][..])
        );
        let f = got[2].as_ref().unwrap();
        assert_eq!((f.kind, f.id, f.len()), (FrameKind::Remote, 0x7FF, 4));
        // FDF set (0x1000): CAN FD, here with BRS (its column and 0x2000).
        let f = got[3].as_ref().unwrap();
        let brs = FdFlags {
            brs: true,
            esi: false,
        };
        assert_eq!((f.id, f.len(), f.dlc(), f.fd()), (0x100, 12, 9, Some(brs)));
        assert_eq!(f.data()[11], 0x0B);
        let f = got[4].as_ref().unwrap();
        assert_eq!((f.kind, f.id, f.len()), (FrameKind::Data, 0x020, 0));
        let f = got[5].as_ref().unwrap();
        assert_eq!(
            (f.id, f.len(), f.fd()),
            (0x101, 8, Some(FdFlags::default()))
        );
    }

    #[test]
    fn canfd_frames_as_python_can_writes_them() {
        // python-can 4.6's ASCWriter: ESI and BRS in their columns and in the flags.
        let text = format!(
            "{HEADER}                0.100000 CANFD   1 Rx      1ABCDEF0x                                  0 1 f 64 {} 0    0     5000        0        0        0        0        0
",
            ["5A"; 64].join(" ")
        );
        let got = read(&text);
        let f = got[0].as_ref().unwrap();
        assert_eq!(
            (f.id, f.extended, f.len(), f.fd()),
            (
                0x1ABC_DEF0,
                true,
                64,
                Some(FdFlags {
                    brs: false,
                    esi: true
                })
            )
        );
    }

    #[test]
    fn canfd_lines_cut_short_are_named() {
        let cases = [
            (
                "1.0 CANFD 1 Rx 123 0 0 2 2 01",
                "2 data bytes announced, 1 present",
            ),
            (
                "1.0 CANFD 1 Rx 123 0 0 2 2 01 02 130000 130",
                "ends before its flags",
            ),
            (
                "1.0 CANFD 1 Rx 123 0 0 2 2 01 02 130000 130 1G00",
                "flags \"1G00\" are not hexadecimal",
            ),
            (
                "1.0 CANFD 1 Rx 123 0 0 9 12 00 01 02 03 04 05 06 07 08 09 0A 0B 0 0 0 0",
                "12 data bytes in a classic frame",
            ),
            ("1.0 CANFD 0 Rx 123 0 0 0 0 0 0 0 0", "channel \"0\""),
            (
                "1.0 CANFD 1 Rx 123 0 0 9 8 00 01 02 03 04 05 06 07 0 0 1000 0",
                "DLC 9 says 12 data bytes, the data length 8",
            ),
        ];
        for (line, expected) in cases {
            let got = read(&format!("{line}\n   2.0 1 002 Rx d 0\n"));
            assert_eq!(got.len(), 2, "{line}: {got:?}");
            let e = got[0].as_ref().unwrap_err();
            assert_eq!(e.line, 1);
            assert!(e.message.contains(expected), "{line}: {e}");
            assert_eq!(got[1].as_ref().unwrap().id, 2);
        }
    }

    #[test]
    fn canxl_events_are_refused_as_canfd_ones_are() {
        let text = format!(
            "{HEADER}   0.100000 CANXL 1 Rx XLFF 1 0 123 0 0 0 12 12 00 01 02 03 04 05 06 07 08 09 0A 0B\n   0.200000 1  123 Rx d 1 AA\n"
        );
        let got = read(&text);
        assert_eq!(got.len(), 2, "{got:?}");
        let e = got[0].as_ref().unwrap_err();
        assert_eq!((e.line, e.fatal), (7, false));
        assert_eq!(
            e.message,
            "CAN XL frame (CANXL event) is not supported: CAN and CAN FD only"
        );
        assert_eq!(got[1].as_ref().unwrap().data(), &[0xAA]);
    }

    /// A Global Marker: channel field 0, then its type, colours and texts; not a frame.
    #[test]
    fn global_markers_are_not_frames_and_not_errors() {
        let text = format!(
            "{HEADER}   2.200804 0 16777215 0 1 GMGroup: Marker Group GMMarker: Marker 1 GMDescription: Description\n   2.300000 1  123 Rx d 1 AA\n"
        );
        let got = read(&text);
        assert_eq!(got.len(), 1, "{got:?}");
        assert_eq!(got[0].as_ref().unwrap().id, 0x123);
        // A frame on channel 0 is still refused, an error frame there too.
        for line in ["2.0 0 123 Rx d 0", "2.0 0 ErrorFrame"] {
            let e = read(line)[0].clone().unwrap_err();
            assert!(e.message.contains("channel \"0\""), "{line}: {e}");
        }
        let e = read("2.0 300 123 Rx d 0")[0].clone().unwrap_err();
        assert_eq!(
            e.message,
            "channel \"300\": AutoPlug reads ASC channels 1 to 256 only"
        );
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
