//! Reading logs: each format's streaming reader, and [`open`], which picks the reader for
//! a file and returns them all as one [`LogReader`].
//!
//! Every reader is an iterator of `Result<LogFrame, LogError>` whose memory does not grow
//! with the file (a line, or one BLF container, at a time). A malformed line gives an
//! error naming it and reading goes on with the next one, so the caller chooses: stop at
//! the first error (strict) or skip and count (lenient). Errors the reader cannot go past
//! (I/O, a damaged BLF structure) are [fatal](LogError::is_fatal) and end the iteration;
//! every frame before the damage comes first, so a caller keeps them.
//! Frames come in file order; time going backwards is not judged here.

use std::fmt;
use std::fs::File;
use std::io::{self, BufRead, BufReader};
use std::path::{Path, PathBuf};

use crate::frame::LogFrame;

pub mod asc;
pub mod blf;
pub mod candump;
mod lines;
pub mod mf4;

pub use asc::AscReader;
pub use blf::BlfReader;
pub use candump::CandumpReader;
pub use mf4::Mf4Reader;

/// What an error's number counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Place {
    /// Lines of a text log (candump, ASC), from 1.
    Line,
    /// Objects of a BLF file, from 1 (log containers are not counted).
    Object,
    /// Records of an MF4 data group, from 1 (the message names the data group).
    Record,
}

/// A frame that could not be read, and where.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LogError {
    /// 1-based line number, or for BLF the 1-based object number (see `place`).
    pub line: u64,
    /// Whether `line` counts lines or BLF objects.
    pub place: Place,
    /// What is wrong.
    pub message: String,
    /// The reader cannot go on (I/O error, damaged file structure): it yields nothing
    /// after this error. Otherwise the next item is the next line's.
    pub fatal: bool,
}

impl LogError {
    /// A malformed line.
    pub fn at_line(line: u64, message: impl Into<String>) -> Self {
        Self {
            line,
            place: Place::Line,
            message: message.into(),
            fatal: false,
        }
    }

    /// A malformed BLF object.
    pub fn at_object(object: u64, message: impl Into<String>) -> Self {
        Self {
            line: object,
            place: Place::Object,
            message: message.into(),
            fatal: false,
        }
    }

    /// The same error, marked fatal.
    #[must_use]
    pub fn into_fatal(mut self) -> Self {
        self.fatal = true;
        self
    }

    /// Reading a text log failed at this line: fatal.
    pub(crate) fn io(line: u64, error: &io::Error) -> Self {
        Self::at_line(line, format!("cannot read the file: {error}")).into_fatal()
    }

    /// Whether the reader stopped here (see [`LogError::fatal`]).
    pub fn is_fatal(&self) -> bool {
        self.fatal
    }
}

impl fmt::Display for LogError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let place = match self.place {
            Place::Line => "line",
            Place::Object => "object",
            Place::Record => "record",
        };
        write!(f, "{place} {}: {}", self.line, self.message)
    }
}

impl std::error::Error for LogError {}

/// The log formats read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum LogFormat {
    /// can-utils' candump `-l` format (`.log`).
    Candump,
    /// Vector ASC (`.asc`).
    Asc,
    /// Vector BLF (`.blf`).
    Blf,
    /// ASAM MDF 4 bus logging (`.mf4`).
    Mf4,
}

impl LogFormat {
    /// The format a file name's extension says (`.log`, `.asc`, `.blf`, any case).
    pub fn from_extension(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "log" => Some(Self::Candump),
            "asc" => Some(Self::Asc),
            "blf" => Some(Self::Blf),
            "mf4" => Some(Self::Mf4),
            _ => None,
        }
    }

    /// The format the first bytes of a file suggest: `LOGG` is BLF; `MDF     ` or
    /// `UnFinMF ` is MF4; `date `, `base `,
    /// `//` or `Begin Triggerblock` is ASC; `(` is candump. Leading blank space and a
    /// UTF-8 byte-order mark are passed over.
    pub fn sniff(start: &[u8]) -> Option<Self> {
        if start.starts_with(b"LOGG") {
            return Some(Self::Blf);
        }
        if start.starts_with(b"MDF     ") || start.starts_with(b"UnFinMF ") {
            return Some(Self::Mf4);
        }
        let text = start.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(start);
        let first = text.iter().position(|b| !b.is_ascii_whitespace())?;
        let text = &text[first..];
        let starts =
            |word: &[u8]| text.len() >= word.len() && text[..word.len()].eq_ignore_ascii_case(word);
        if starts(b"date ") || starts(b"base ") || starts(b"//") || starts(b"begin triggerblock") {
            Some(Self::Asc)
        } else if text[0] == b'(' {
            Some(Self::Candump)
        } else {
            None
        }
    }

    /// `candump`, `ASC`, `BLF`.
    pub fn name(self) -> &'static str {
        match self {
            Self::Candump => "candump",
            Self::Asc => "ASC",
            Self::Blf => "BLF",
            Self::Mf4 => "MF4",
        }
    }
}

impl fmt::Display for LogFormat {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The input a [`LogReader`] reads from.
pub type Input = Box<dyn BufRead + Send>;

/// An input that can also seek, as MF4 needs (its blocks link to each other anywhere in
/// the file): a file, or a cursor over bytes.
pub trait SeekInput: io::Read + io::Seek + Send {}
impl<T: io::Read + io::Seek + Send> SeekInput for T {}

enum Inner {
    Candump(CandumpReader<Input>),
    Asc(AscReader<Input>),
    Blf(BlfReader<Input>),
    Mf4(Box<Mf4Reader<Box<dyn SeekInput>>>),
}

/// A log of any supported format, read as one stream of frames.
pub struct LogReader {
    format: LogFormat,
    inner: Inner,
}

impl LogReader {
    /// A reader of `input` in this format. Reads the BLF file header at once
    /// (`ErrorKind::InvalidData` if it is not one). MF4 needs an input that seeks: see
    /// [`LogReader::seekable`] (`ErrorKind::InvalidInput` here).
    pub fn new(format: LogFormat, input: Input) -> io::Result<Self> {
        let inner = match format {
            LogFormat::Candump => Inner::Candump(CandumpReader::new(input)),
            LogFormat::Asc => Inner::Asc(AscReader::new(input)),
            LogFormat::Blf => Inner::Blf(BlfReader::new(input)?),
            LogFormat::Mf4 => return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                "an MF4 file is read from a file (its blocks link anywhere in it), not a stream",
            )),
        };
        Ok(Self { format, inner })
    }

    /// A reader of a seekable `input` in any format. Reads an MF4 file's blocks down to
    /// its channels at once (`ErrorKind::InvalidData`, naming the block and its offset, if
    /// they are damaged or hold no CAN bus logging).
    pub fn seekable(format: LogFormat, input: Box<dyn SeekInput>) -> io::Result<Self> {
        match format {
            LogFormat::Mf4 => {
                let reader = Mf4Reader::new(input)
                    .map_err(|e| io::Error::new(io::ErrorKind::InvalidData, e.to_string()))?;
                Ok(Self {
                    format,
                    inner: Inner::Mf4(Box::new(reader)),
                })
            }
            _ => Self::new(format, Box::new(io::BufReader::new(input))),
        }
    }

    /// The format being read.
    pub fn format(&self) -> LogFormat {
        self.format
    }

    /// Frames the logger reported dropped so far (candump's `DROPCOUNT` lines; 0 for the
    /// other formats).
    pub fn dropped_frames(&self) -> u64 {
        match &self.inner {
            Inner::Candump(r) => r.dropped_frames(),
            Inner::Asc(_) | Inner::Blf(_) | Inner::Mf4(_) => 0,
        }
    }
}

impl Iterator for LogReader {
    type Item = Result<LogFrame, LogError>;

    fn next(&mut self) -> Option<Self::Item> {
        match &mut self.inner {
            Inner::Candump(r) => r.next(),
            Inner::Asc(r) => r.next(),
            Inner::Blf(r) => r.next(),
            Inner::Mf4(r) => r.next(),
        }
    }
}

impl fmt::Debug for LogReader {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("LogReader")
            .field("format", &self.format)
            .finish_non_exhaustive()
    }
}

/// Why a log file could not be opened.
#[derive(Debug)]
pub struct OpenError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong (`NotFound`, `InvalidData` for an unknown or damaged format...).
    pub error: io::Error,
}

impl fmt::Display for OpenError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.path.display(), self.error)
    }
}

impl std::error::Error for OpenError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        Some(&self.error)
    }
}

/// Opens a log file, its format known from the extension (`.log`, `.asc`, `.blf`,
/// `.mf4`) or else from its first bytes.
pub fn open(path: impl AsRef<Path>) -> Result<LogReader, OpenError> {
    let path = path.as_ref();
    let fail = |error: io::Error| OpenError {
        path: path.to_path_buf(),
        error,
    };
    let file = File::open(path)
        .map_err(|e| fail(io::Error::new(e.kind(), format!("cannot open: {e}"))))?;
    let mut input = BufReader::with_capacity(64 * 1024, file);
    let format = match LogFormat::from_extension(path) {
        Some(format) => format,
        None => {
            let start = input
                .fill_buf()
                .map_err(|e| fail(io::Error::new(e.kind(), format!("cannot read: {e}"))))?;
            LogFormat::sniff(start).ok_or_else(|| {
                fail(io::Error::new(
                    io::ErrorKind::InvalidData,
                    if start.is_empty() {
                        "empty file of unknown format (name it .log, .asc, .blf or .mf4)".to_string()
                    } else {
                        "unknown log format: the name does not end in .log, .asc, .blf or .mf4, and the file does not start like a candump (\"(\"), ASC (\"date \", \"base \"), BLF (\"LOGG\") or MF4 (\"MDF \") log".to_string()
                    },
                ))
            })?
        }
    };
    if format == LogFormat::Mf4 {
        return LogReader::seekable(format, Box::new(input)).map_err(fail);
    }
    LogReader::new(format, Box::new(input)).map_err(fail)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn formats_from_names_and_contents() {
        assert_eq!(
            LogFormat::from_extension(Path::new("a/b.LOG")),
            Some(LogFormat::Candump)
        );
        assert_eq!(
            LogFormat::from_extension(Path::new("b.Asc")),
            Some(LogFormat::Asc)
        );
        assert_eq!(
            LogFormat::from_extension(Path::new("b.blf")),
            Some(LogFormat::Blf)
        );
        assert_eq!(LogFormat::from_extension(Path::new("b.txt")), None);
        assert_eq!(LogFormat::from_extension(Path::new("blf")), None);
        assert_eq!(LogFormat::sniff(b"LOGG\x90\0\0\0"), Some(LogFormat::Blf));
        assert_eq!(LogFormat::sniff(b"date Thu Nov"), Some(LogFormat::Asc));
        assert_eq!(
            LogFormat::sniff(b"\xEF\xBB\xBFbase hex"),
            Some(LogFormat::Asc)
        );
        assert_eq!(LogFormat::sniff(b"\r\n// comment"), Some(LogFormat::Asc));
        assert_eq!(
            LogFormat::sniff(b"(1.0) can0 123#"),
            Some(LogFormat::Candump)
        );
        assert_eq!(LogFormat::sniff(b"hello"), None);
        assert_eq!(LogFormat::sniff(b""), None);
        assert_eq!(LogFormat::sniff(b"  "), None);
    }

    #[test]
    fn open_by_extension_or_sniffing() {
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str, text: &[u8]| {
            let path = dir.path().join(name);
            std::fs::File::create(&path)
                .unwrap()
                .write_all(text)
                .unwrap();
            path
        };
        let log = write("a.log", b"(1.0) can0 123#01\n");
        let r = open(&log).unwrap();
        assert_eq!(r.format(), LogFormat::Candump);
        assert_eq!(r.count(), 1);
        let sniffed = write(
            "capture",
            b"base hex timestamps absolute\n 1.0 1 123 Rx d 1 01\n",
        );
        let r = open(&sniffed).unwrap();
        assert_eq!(r.format(), LogFormat::Asc);
        assert_eq!(r.map(|f| f.unwrap().id).collect::<Vec<_>>(), [0x123]);
        let empty = write("empty.log", b"");
        assert_eq!(open(&empty).unwrap().count(), 0);

        let e = open(dir.path().join("missing.log")).unwrap_err();
        assert_eq!(e.error.kind(), io::ErrorKind::NotFound);
        assert!(e.to_string().contains("missing.log: cannot open"), "{e}");
        let e = open(write("x.dat", b"hello")).unwrap_err();
        assert!(e.to_string().contains("x.dat: unknown log format"), "{e}");
        let e = open(write("y.dat", b"")).unwrap_err();
        assert!(e.to_string().contains("empty file"), "{e}");
        let e = open(write("z.blf", b"(1.0) can0 123#01\n")).unwrap_err();
        assert!(e.to_string().contains("z.blf: not a BLF file"), "{e}");
    }
}
