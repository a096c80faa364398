//! Writing logs: candump (what the gateway records and the virtual car's `bus.log`) and
//! Vector ASC (what engineers open in CANoe, CANalyzer or python-can), plus conversion of
//! any log read by [`crate::read`].
//!
//! BLF is written by [`crate::blf_write`]; [`export_blf`] converts any log to it.

use std::fmt;
use std::io::{self, Write};

use crate::frame::{Direction, FrameKind, LogFrame};
use crate::read::candump::CAN_ERR_FLAG;
use crate::read::LogError;
use crate::time::Utc;

/// Appends one candump line to `line`: `(secs.micros) canN ID#DATA`, 3 upper-case hex
/// digits for a standard identifier and 8 for an extended one or an error frame (with
/// `CAN_ERR_FLAG`), `ID#R` / `ID#R4` for a remote frame, `ID##F…` for CAN FD (F: the
/// flags digit, 1 BRS, 2 ESI); with `direction`, python-can's
/// ` R` / ` T` after it. Ends with `\n`.
pub fn format_candump(line: &mut Vec<u8>, frame: &LogFrame, direction: bool) {
    // Digits pushed by hand rather than through `write!`: a recording or a virtual car's
    // bus log is millions of lines, and core's formatting machinery was most of the cost.
    line.push(b'(');
    push_decimal(line, frame.t_us / 1_000_000, 1);
    line.push(b'.');
    push_decimal(line, frame.t_us % 1_000_000, 6);
    line.extend_from_slice(b") can");
    push_decimal(line, u64::from(frame.channel), 1);
    line.push(b' ');
    match (frame.kind, frame.extended) {
        (FrameKind::Error, _) => push_hex(line, frame.id | CAN_ERR_FLAG, 8),
        (_, true) => push_hex(line, frame.id, 8),
        (_, false) => push_hex(line, frame.id, 3),
    }
    line.push(b'#');
    if let Some(flags) = frame.fd() {
        line.push(b'#');
        push_hex(line, u32::from(flags.brs) | u32::from(flags.esi) << 1, 1);
    }
    if frame.kind == FrameKind::Remote {
        line.push(b'R');
        if !frame.is_empty() {
            push_decimal(line, frame.len() as u64, 1);
        }
    } else {
        for &b in frame.data() {
            push_hex(line, u32::from(b), 2);
        }
    }
    if direction {
        line.extend_from_slice(match frame.direction {
            Direction::Rx => b" R",
            Direction::Tx => b" T",
        });
    }
    line.push(b'\n');
}

/// Appends `n` in decimal, zero-padded to at least `width` digits (`{:0width$}`).
fn push_decimal(line: &mut Vec<u8>, n: u64, width: usize) {
    let mut digits = [0u8; 20];
    let mut len = 0;
    let mut rest = n;
    while rest > 0 || len < width.max(1) {
        digits[len] = b'0' + (rest % 10) as u8;
        rest /= 10;
        len += 1;
    }
    line.extend(digits[..len].iter().rev());
}

/// Appends `n` in upper-case hex, zero-padded to at least `width` digits (`{:0width$X}`).
fn push_hex(line: &mut Vec<u8>, n: u32, width: usize) {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    let mut digits = [0u8; 8];
    let mut len = 0;
    let mut rest = n;
    while rest > 0 || len < width.max(1) {
        digits[len] = HEX[(rest & 0xF) as usize];
        rest >>= 4;
        len += 1;
    }
    line.extend(digits[..len].iter().rev());
}

/// Writes frames as a candump log, one line each (see [`format_candump`]).
pub struct CandumpWriter<W> {
    out: W,
    direction: bool,
    line: Vec<u8>,
}

impl<W: Write> CandumpWriter<W> {
    /// A writer of plain candump lines, as `candump -l` writes them (no direction).
    pub fn new(out: W) -> Self {
        Self {
            out,
            direction: false,
            line: Vec::with_capacity(64),
        }
    }

    /// Appends python-can's ` R` / ` T` to each line, so the direction survives.
    #[must_use]
    pub fn with_direction(mut self, on: bool) -> Self {
        self.direction = on;
        self
    }

    /// Writes one frame.
    pub fn write(&mut self, frame: &LogFrame) -> io::Result<()> {
        self.line.clear();
        format_candump(&mut self.line, frame, self.direction);
        self.out.write_all(&self.line)
    }

    /// Flushes and hands back the output.
    pub fn finish(mut self) -> io::Result<W> {
        self.out.flush()?;
        Ok(self.out)
    }
}

/// `Tue Nov 14 22:13:20.000 2023`, the date form of ASC headers (UTC here).
fn asc_date(t_us: u64) -> String {
    let t = Utc::from_unix_us(t_us);
    format!(
        "{} {} {:02} {:02}:{:02}:{:02}.{:03} {}",
        t.weekday_name(),
        t.month_name(),
        t.day,
        t.hour,
        t.minute,
        t.second,
        t.micros / 1000,
        t.year
    )
}

/// Writes frames as a Vector ASC log: `base hex  timestamps absolute` (seconds since the
/// start of the measurement, 6 decimals), channels 1-based, `Rx`/`Tx`, `d LEN bytes`,
/// `r LEN`, `ErrorFrame`, extended identifiers with a trailing `x`. The header's date is
/// the start in UTC. Call [`AscWriter::finish`] to end the file (`End TriggerBlock`).
pub struct AscWriter<W> {
    out: W,
    start_us: Option<u64>,
    header_written: bool,
}

impl<W: Write> AscWriter<W> {
    /// A writer whose times count from the first frame.
    pub fn new(out: W) -> Self {
        Self {
            out,
            start_us: None,
            header_written: false,
        }
    }

    /// A writer whose times count from `start_us` (Unix microseconds, or whatever the
    /// frames' time base is); a frame before it is written at 0.
    pub fn with_start(out: W, start_us: u64) -> Self {
        Self {
            out,
            start_us: Some(start_us),
            header_written: false,
        }
    }

    fn header(&mut self, start_us: u64) -> io::Result<()> {
        let date = asc_date(start_us);
        write!(
            self.out,
            "date {date}\nbase hex  timestamps absolute\ninternal events logged\nBegin Triggerblock {date}\n   0.000000 Start of measurement\n"
        )?;
        self.header_written = true;
        Ok(())
    }

    /// Writes one frame (and the header, before the first).
    pub fn write(&mut self, frame: &LogFrame) -> io::Result<()> {
        let start = *self.start_us.get_or_insert(frame.t_us);
        if !self.header_written {
            self.header(start)?;
        }
        let t = frame.t_us.saturating_sub(start);
        let time = format!("{}.{:06}", t / 1_000_000, t % 1_000_000);
        let channel = u16::from(frame.channel) + 1;
        if frame.kind == FrameKind::Error {
            return writeln!(self.out, "{time:>11} {channel}  ErrorFrame");
        }
        let id = if frame.extended {
            format!("{:X}x", frame.id)
        } else {
            format!("{:X}", frame.id)
        };
        let direction = match frame.direction {
            Direction::Rx => "Rx",
            Direction::Tx => "Tx",
        };
        if let Some(flags) = frame.fd() {
            // As CANoe and python-can lay it out: BRS, ESI, DLC (hex), length, data, then
            // duration, bit count, flags, CRC and bit timings, which a log file does not
            // know (0) but for the flags: 0x1000 FDF, 0x2000 BRS, 0x4000 ESI.
            write!(
                self.out,
                "{time:>11} CANFD {channel:>3} {direction:<4} {id:>9} {:>32} {} {} {:x} {:>2}",
                "",
                u8::from(flags.brs),
                u8::from(flags.esi),
                frame.dlc(),
                frame.len()
            )?;
            for b in frame.data() {
                write!(self.out, " {b:02X}")?;
            }
            let bits = 0x1000 | u32::from(flags.brs) << 13 | u32::from(flags.esi) << 14;
            return writeln!(self.out, " {:>8} {:>4} {bits:>8X} {:>8} 0 0 0 0", 0, 0, 0);
        }
        write!(self.out, "{time:>11} {channel}  {id:<15} {direction:<4} ")?;
        if frame.kind == FrameKind::Remote {
            return writeln!(self.out, "r {:x}", frame.len());
        }
        write!(self.out, "d {:x}", frame.len())?;
        for b in frame.data() {
            write!(self.out, " {b:02X}")?;
        }
        writeln!(self.out)
    }

    /// Ends the file and hands back the output (a file with no frame still gets a
    /// header, dated at the given start or at 1970-01-01).
    pub fn finish(mut self) -> io::Result<W> {
        if !self.header_written {
            self.header(self.start_us.unwrap_or(0))?;
        }
        self.out.write_all(b"End TriggerBlock\n")?;
        self.out.flush()?;
        Ok(self.out)
    }
}

/// What a conversion did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ExportSummary {
    /// Frames written.
    pub frames: u64,
    /// Malformed lines (objects) skipped.
    pub skipped: u64,
    /// The first of them, to show the user.
    pub first_skipped: Option<LogError>,
    /// Why the input could not be read to its end (a damaged tail, an I/O error: a fatal
    /// [`LogError`]), if so. Every frame before it was written, and the output finished.
    pub incomplete: Option<LogError>,
}

/// Why a conversion stopped.
#[derive(Debug)]
pub enum ExportError {
    /// The output could not be written.
    Write(io::Error),
}

impl fmt::Display for ExportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ExportError::Write(e) => write!(f, "writing: {e}"),
        }
    }
}

impl std::error::Error for ExportError {}

fn export<I>(
    frames: I,
    mut write: impl FnMut(&LogFrame) -> io::Result<()>,
) -> Result<ExportSummary, ExportError>
where
    I: IntoIterator<Item = Result<LogFrame, LogError>>,
{
    let mut summary = ExportSummary::default();
    for item in frames {
        match item {
            Ok(frame) => {
                write(&frame).map_err(ExportError::Write)?;
                summary.frames += 1;
            }
            // What came before the damage is kept: the output is finished with it.
            Err(e) if e.is_fatal() => {
                summary.incomplete = Some(e);
                break;
            }
            Err(e) => {
                summary.skipped += 1;
                summary.first_skipped.get_or_insert(e);
            }
        }
    }
    Ok(summary)
}

/// Converts a log (any reader of [`crate::read`]) to ASC, times from its first frame.
/// Malformed lines are skipped and counted; a fatal read error ends the input there (see
/// [`ExportSummary::incomplete`]); a write error stops it.
pub fn export_asc<I, W>(frames: I, out: W) -> Result<ExportSummary, ExportError>
where
    I: IntoIterator<Item = Result<LogFrame, LogError>>,
    W: Write,
{
    let mut writer = AscWriter::new(out);
    let summary = export(frames, |f| writer.write(f))?;
    writer.finish().map_err(ExportError::Write)?;
    Ok(summary)
}

/// Converts a log to BLF (the output seekable: the file header is completed last); as
/// [`export_asc`] otherwise. A frame more than a second before the first (BLF counts time
/// up from the measurement start) stops the conversion with its error.
pub fn export_blf<I, W>(frames: I, out: W) -> Result<ExportSummary, ExportError>
where
    I: IntoIterator<Item = Result<LogFrame, LogError>>,
    W: Write + std::io::Seek,
{
    let mut writer = crate::blf_write::BlfWriter::new(out).map_err(ExportError::Write)?;
    let summary = export(frames, |f| writer.write(f))?;
    writer.finish().map_err(ExportError::Write)?;
    Ok(summary)
}

/// Converts a log to MDF 4.10 (see [`crate::mdf4::write`]), its data blocks compressed if
/// `compress`; as [`export_asc`] otherwise. The summary's count of decoded catalogue frames
/// comes second.
pub fn export_mf4<I, W>(
    frames: I,
    out: W,
    compress: bool,
) -> Result<(ExportSummary, u64), ExportError>
where
    I: IntoIterator<Item = Result<LogFrame, LogError>>,
    W: Write + std::io::Seek,
{
    let mut writer =
        crate::mdf4::write::Mf4Writer::new(out, compress).map_err(ExportError::Write)?;
    let summary = export(frames, |f| writer.write(f))?;
    let decoded = writer.decoded;
    writer.finish().map_err(ExportError::Write)?;
    Ok((summary, decoded))
}

/// Converts a log to candump, with python-can's direction suffix if `direction`; as
/// [`export_asc`] otherwise.
pub fn export_candump<I, W>(
    frames: I,
    out: W,
    direction: bool,
) -> Result<ExportSummary, ExportError>
where
    I: IntoIterator<Item = Result<LogFrame, LogError>>,
    W: Write,
{
    let mut writer = CandumpWriter::new(out).with_direction(direction);
    let summary = export(frames, |f| writer.write(f))?;
    writer.finish().map_err(ExportError::Write)?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::FdFlags;
    use crate::read::{AscReader, CandumpReader};

    fn sample() -> Vec<LogFrame> {
        let t0 = 1_700_000_000_000_000;
        vec![
            LogFrame::new(
                t0,
                0,
                0x00C,
                false,
                FrameKind::Data,
                &[0x0A, 0x14, 0x1E, 0x28],
            )
            .unwrap(),
            LogFrame::new(t0 + 5, 0, 0x7FF, false, FrameKind::Data, &[]).unwrap(),
            LogFrame::new(
                t0 + 1_234_567,
                1,
                0x1ABC_DEF0,
                true,
                FrameKind::Data,
                &[1, 2],
            )
            .unwrap()
            .with_direction(Direction::Tx),
            LogFrame::remote(t0 + 2_000_000, 0, 0x123, false, 4).unwrap(),
            LogFrame::remote(t0 + 2_000_001, 0, 0x1234, true, 0).unwrap(),
            LogFrame::new(t0 + 3_000_000, 0, 0x80, false, FrameKind::Error, &[]).unwrap(),
            LogFrame::new(
                t0 + 3_000_001,
                0,
                0x04,
                false,
                FrameKind::Error,
                &[0, 4, 0, 0, 0, 0, 0, 0],
            )
            .unwrap(),
            LogFrame::new_fd(
                t0 + 4_000_000,
                1,
                0x123,
                false,
                &[0x11; 12],
                FdFlags {
                    brs: true,
                    esi: false,
                },
            )
            .unwrap(),
            LogFrame::new_fd(
                t0 + 4_000_001,
                0,
                0x1ABC_DEF0,
                true,
                &core::array::from_fn::<u8, 64, _>(|i| i as u8),
                FdFlags {
                    brs: false,
                    esi: true,
                },
            )
            .unwrap()
            .with_direction(Direction::Tx),
        ]
    }

    #[test]
    fn candump_lines_are_as_candump_writes_them() {
        let mut line = Vec::new();
        let frame = autoplug_can::Frame::new(0x00C, &[0x0A, 0x14, 0x1E, 0x28]).unwrap();
        format_candump(&mut line, &LogFrame::from_can(12_345_678, 0, &frame), false);
        assert_eq!(line, b"(12.345678) can0 00C#0A141E28\n");
        let mut w = CandumpWriter::new(Vec::new());
        for f in sample() {
            w.write(&f).unwrap();
        }
        let text = String::from_utf8(w.finish().unwrap()).unwrap();
        assert_eq!(
            text,
            "(1700000000.000000) can0 00C#0A141E28\n\
             (1700000000.000005) can0 7FF#\n\
             (1700000001.234567) can1 1ABCDEF0#0102\n\
             (1700000002.000000) can0 123#R4\n\
             (1700000002.000001) can0 00001234#R\n\
             (1700000003.000000) can0 20000080#\n\
             (1700000003.000001) can0 20000004#0004000000000000\n\
             (1700000004.000000) can1 123##1111111111111111111111111\n\
             (1700000004.000001) can0 1ABCDEF0##2000102030405060708090A0B0C0D0E0F101112131415161718191A1B1C1D1E1F202122232425262728292A2B2C2D2E2F303132333435363738393A3B3C3D3E3F\n"
        );
    }

    #[test]
    fn candump_round_trip_with_and_without_directions() {
        for direction in [false, true] {
            let mut w = CandumpWriter::new(Vec::new()).with_direction(direction);
            for f in sample() {
                w.write(&f).unwrap();
            }
            let bytes = w.finish().unwrap();
            let back: Vec<LogFrame> = CandumpReader::new(&bytes[..]).map(|f| f.unwrap()).collect();
            let mut expected = sample();
            if !direction {
                expected[2].direction = Direction::Rx;
                expected[8].direction = Direction::Rx;
            }
            // Interfaces are numbered in order of appearance: can0 then can1.
            assert_eq!(back, expected);
        }
    }

    #[test]
    fn asc_output_and_round_trip() {
        let mut w = AscWriter::new(Vec::new());
        for f in sample() {
            w.write(&f).unwrap();
        }
        let text = String::from_utf8(w.finish().unwrap()).unwrap();
        assert_eq!(
            text,
            format!("date Tue Nov 14 22:13:20.000 2023\n\
             base hex  timestamps absolute\n\
             internal events logged\n\
             Begin Triggerblock Tue Nov 14 22:13:20.000 2023\n\
             \x20  0.000000 Start of measurement\n\
             \x20  0.000000 1  C               Rx   d 4 0A 14 1E 28\n\
             \x20  0.000005 1  7FF             Rx   d 0\n\
             \x20  1.234567 2  1ABCDEF0x       Tx   d 2 01 02\n\
             \x20  2.000000 1  123             Rx   r 4\n\
             \x20  2.000001 1  1234x           Rx   r 0\n\
             \x20  3.000000 1  ErrorFrame\n\
             \x20  3.000001 1  ErrorFrame\n\
             \x20  4.000000 CANFD   2 Rx         123                                  1 0 9 12 11 11 11 11 11 11 11 11 11 11 11 11        0    0     3000        0 0 0 0 0\n\
             \x20  4.000001 CANFD   1 Tx   1ABCDEF0x                                  0 1 f 64 {}        0    0     5000        0 0 0 0 0\n\
             End TriggerBlock\n",
            (0..64).map(|b| format!("{b:02X}")).collect::<Vec<_>>().join(" ")
        ));
        let back: Vec<LogFrame> = AscReader::new(text.as_bytes())
            .map(|f| f.unwrap())
            .collect();
        let t0 = sample()[0].t_us;
        for (b, s) in back.iter().zip(sample()) {
            assert_eq!(b.t_us, s.t_us - t0);
            assert_eq!(
                (b.channel, b.kind, b.direction),
                (s.channel, s.kind, s.direction)
            );
            if s.kind != FrameKind::Error {
                // ASC keeps neither the error class nor the error details.
                assert_eq!(
                    (b.id, b.extended, b.len(), b.data(), b.fd()),
                    (s.id, s.extended, s.len(), s.data(), s.fd())
                );
            }
        }
        assert_eq!(back.len(), 9);
    }

    #[test]
    fn asc_with_a_given_start_and_empty() {
        let mut w = AscWriter::with_start(Vec::new(), 1_000_000);
        w.write(&LogFrame::new(500_000, 0, 1, false, FrameKind::Data, &[]).unwrap())
            .unwrap();
        w.write(&LogFrame::new(3_500_000, 0, 1, false, FrameKind::Data, &[]).unwrap())
            .unwrap();
        let text = String::from_utf8(w.finish().unwrap()).unwrap();
        assert!(
            text.contains("date Thu Jan 01 00:00:01.000 1970\n"),
            "{text}"
        );
        assert!(
            text.contains("\n   0.000000 1  1 "),
            "before the start: written at 0"
        );
        assert!(text.contains("\n   2.500000 1  1 "));
        let empty = String::from_utf8(AscWriter::new(Vec::new()).finish().unwrap()).unwrap();
        assert!(empty.starts_with("date ") && empty.ends_with("End TriggerBlock\n"));
        assert_eq!(AscReader::new(empty.as_bytes()).count(), 0);
    }

    #[test]
    fn export_skips_malformed_lines_and_keeps_what_precedes_a_fatal_one() {
        let input = "(1.0) can0 001#00\n(2.0) can0 zz\n(3.0) can0 003#01\n";
        let mut out = Vec::new();
        let summary = export_asc(CandumpReader::new(input.as_bytes()), &mut out).unwrap();
        assert_eq!((summary.frames, summary.skipped), (2, 1));
        assert_eq!(summary.first_skipped.unwrap().line, 2);
        assert_eq!(AscReader::new(&out[..]).count(), 2);
        let fatal = vec![
            Ok(sample()[0]),
            Err(LogError::at_line(2, "gone").into_fatal()),
        ];
        let mut out = Vec::new();
        let summary = export_candump(fatal, &mut out, false).unwrap();
        assert_eq!(summary.frames, 1);
        assert_eq!(summary.incomplete.unwrap().to_string(), "line 2: gone");
        assert_eq!(CandumpReader::new(&out[..]).count(), 1);
    }
}
