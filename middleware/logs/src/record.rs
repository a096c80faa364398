//! Recording live traffic to candump or MF4 files, the way the gateway does it: one file
//! per segment, rotated on size or time, flushed to the OS at least every
//! [`FLUSH_INTERVAL`], so a crash or `kill -9` loses at most the last 100 ms.
//!
//! An MF4 segment is laid out as data loggers lay out theirs ([`Mf4Writer::growing`]):
//! its blocks first, then one data block that grows, the file `UnFinMF` until the segment
//! is closed; a crash leaves a file that reads to its last record handed to the OS.
//!
//! Files are named `PREFIX-YYYYmmddTHHMMSSZ-NNN.log` (`.mf4`): the UTC wall-clock time the
//! segment was opened, then its number in the recording, so names sort in time order.
//! Rotation never splits a line: a segment is closed before the line that would take it
//! past `max_bytes`, or before the first frame `max_duration_us` (in the frames' own
//! time) after the segment's first frame. A closed segment is synced to disk.
//!
//! A write error (a full disk: `ErrorKind::StorageFull`) stops the recorder with an
//! error naming the file and the frames safely written; the file is cut back to its last
//! complete line, so everything already written stays readable.

use std::fmt;
use std::fs::{File, OpenOptions};
use std::io::{self, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use crate::frame::LogFrame;
use crate::mdf4::write::Mf4Writer;
use crate::time::Utc;
use crate::write::format_candump;

/// The format a recording is written in.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RecordFormat {
    /// candump `.log` lines.
    #[default]
    Candump,
    /// ASAM MDF 4 `.mf4`: the bus and every signal decoded.
    Mf4,
}

/// A bound on the bytes one frame takes in an MF4 segment (its bus record and its decoded
/// signals' record), for rotation on size.
const MF4_FRAME_BYTES: u64 = 128;

/// Longest time frames wait in the recorder's buffer before they are handed to the OS.
pub const FLUSH_INTERVAL: Duration = Duration::from_millis(100);

/// Buffered bytes that trigger a write regardless of time.
const BUFFER_LIMIT: usize = 64 * 1024;

/// When to start a new file (`None`: never for that reason).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RotatePolicy {
    /// Largest segment, in bytes (a single longer line still gets its own segment).
    pub max_bytes: Option<u64>,
    /// Longest segment, in microseconds of the frames' time.
    pub max_duration_us: Option<u64>,
}

/// Opens a segment's file for writing (tests substitute one that fails).
pub type FileOpener = Box<dyn FnMut(&Path) -> io::Result<File> + Send>;

/// What a recording wrote.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RecordSummary {
    /// The segment files, in order.
    pub files: Vec<PathBuf>,
    /// Frames written to them.
    pub frames: u64,
    /// Bytes written to them.
    pub bytes: u64,
}

/// Why the recorder stopped.
#[derive(Debug)]
pub enum RecordError {
    /// Opening, writing or syncing a file failed: the recorder has stopped. Frames
    /// written before are in the files, as complete lines.
    Io {
        /// The file.
        file: PathBuf,
        /// Frames safely written before the failure (all segments).
        frames: u64,
        /// The failure.
        error: io::Error,
    },
    /// The recorder stopped after an earlier error and takes no more frames.
    Stopped,
}

impl RecordError {
    /// Whether the disk (or the quota) is full.
    pub fn is_disk_full(&self) -> bool {
        matches!(self, RecordError::Io { error, .. } if error.kind() == io::ErrorKind::StorageFull)
    }
}

impl fmt::Display for RecordError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RecordError::Io {
                file,
                frames,
                error,
            } => {
                let what = if self.is_disk_full() {
                    "disk full".to_string()
                } else {
                    error.to_string()
                };
                write!(
                    f,
                    "recording stopped: {what} writing {} after {frames} frames",
                    file.display()
                )
            }
            RecordError::Stopped => write!(f, "recording stopped after an earlier error"),
        }
    }
}

impl std::error::Error for RecordError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            RecordError::Io { error, .. } => Some(error),
            RecordError::Stopped => None,
        }
    }
}

/// Where a segment's bytes go.
enum Sink {
    Candump(File),
    Mf4(Box<Mf4Writer<File>>),
}

/// The segment being written.
struct Segment {
    path: PathBuf,
    sink: Sink,
    /// Bytes handed to the OS (all complete lines).
    written: u64,
    /// Bytes in the segment, buffered ones included (for rotation).
    bytes: u64,
    first_t_us: Option<u64>,
}

/// Records frames to rotating candump files; see the [module](self).
pub struct Recorder {
    dir: PathBuf,
    prefix: String,
    policy: RotatePolicy,
    opener: FileOpener,
    segment: Option<Segment>,
    number: u32,
    buf: Vec<u8>,
    buffered_frames: u64,
    line: Vec<u8>,
    last_flush: Instant,
    summary: RecordSummary,
    failed: bool,
    format: RecordFormat,
}

impl Recorder {
    /// Starts a recording in `dir` (created if needed), opening its first segment.
    pub fn start(
        dir: impl AsRef<Path>,
        prefix: &str,
        policy: RotatePolicy,
    ) -> Result<Self, RecordError> {
        Self::start_with(
            dir,
            prefix,
            policy,
            Box::new(|path| OpenOptions::new().write(true).create_new(true).open(path)),
        )
    }

    /// As [`Recorder::start`], in `format`.
    pub fn start_as(
        dir: impl AsRef<Path>,
        prefix: &str,
        policy: RotatePolicy,
        format: RecordFormat,
    ) -> Result<Self, RecordError> {
        Self::start_with_format(
            dir,
            prefix,
            policy,
            Box::new(|path| {
                OpenOptions::new()
                    .read(true)
                    .write(true)
                    .create_new(true)
                    .open(path)
            }),
            format,
        )
    }

    /// As [`Recorder::start`], opening files with `opener` (which should create the file
    /// new, and fail if it exists).
    pub fn start_with(
        dir: impl AsRef<Path>,
        prefix: &str,
        policy: RotatePolicy,
        opener: FileOpener,
    ) -> Result<Self, RecordError> {
        Self::start_with_format(dir, prefix, policy, opener, RecordFormat::Candump)
    }

    /// As [`Recorder::start_with`], in `format`.
    pub fn start_with_format(
        dir: impl AsRef<Path>,
        prefix: &str,
        policy: RotatePolicy,
        opener: FileOpener,
        format: RecordFormat,
    ) -> Result<Self, RecordError> {
        let dir = dir.as_ref().to_path_buf();
        std::fs::create_dir_all(&dir).map_err(|error| RecordError::Io {
            file: dir.clone(),
            frames: 0,
            error,
        })?;
        let mut recorder = Self {
            dir,
            prefix: prefix.to_string(),
            policy,
            opener,
            segment: None,
            number: 0,
            buf: Vec::with_capacity(BUFFER_LIMIT),
            buffered_frames: 0,
            line: Vec::with_capacity(64),
            last_flush: Instant::now(),
            summary: RecordSummary::default(),
            failed: false,
            format,
        };
        recorder.open_segment()?;
        Ok(recorder)
    }

    fn fail(&mut self, file: PathBuf, error: io::Error) -> RecordError {
        self.failed = true;
        self.buf.clear();
        self.buffered_frames = 0;
        RecordError::Io {
            file,
            frames: self.summary.frames,
            error,
        }
    }

    fn open_segment(&mut self) -> Result<(), RecordError> {
        let stamp = {
            let now = SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| d.as_micros() as u64);
            let t = Utc::from_unix_us(now);
            format!(
                "{:04}{:02}{:02}T{:02}{:02}{:02}Z",
                t.year, t.month, t.day, t.hour, t.minute, t.second
            )
        };
        // A name taken (another recording in the same second) moves on to the next number.
        let mut tries = 0;
        loop {
            let extension = match self.format {
                RecordFormat::Candump => "log",
                RecordFormat::Mf4 => "mf4",
            };
            let path = self.dir.join(format!(
                "{}-{stamp}-{:03}.{extension}",
                self.prefix, self.number
            ));
            self.number += 1;
            match (self.opener)(&path) {
                Ok(file) => {
                    let sink = match self.format {
                        RecordFormat::Candump => Sink::Candump(file),
                        RecordFormat::Mf4 => match Mf4Writer::growing(file) {
                            Ok(w) => Sink::Mf4(Box::new(w)),
                            Err(e) => return Err(self.fail(path, e)),
                        },
                    };
                    let written = match &sink {
                        Sink::Mf4(w) => w.flushed_len(),
                        Sink::Candump(_) => 0,
                    };
                    self.summary.bytes += written;
                    self.summary.files.push(path.clone());
                    self.segment = Some(Segment {
                        path,
                        sink,
                        written,
                        bytes: written,
                        first_t_us: None,
                    });
                    return Ok(());
                }
                Err(e) if e.kind() == io::ErrorKind::AlreadyExists && tries < 1000 => tries += 1,
                Err(e) => return Err(self.fail(path, e)),
            }
        }
    }

    /// Hands the buffer to the OS. On failure the file is cut back to its last
    /// complete line (record) and the recorder stops.
    fn flush_buffer(&mut self) -> Result<(), RecordError> {
        self.last_flush = Instant::now();
        let Some(segment) = self.segment.as_mut() else {
            return Ok(());
        };
        let result = match &mut segment.sink {
            Sink::Candump(file) => {
                if self.buf.is_empty() {
                    return Ok(());
                }
                file.write_all(&self.buf).map(|()| self.buf.len() as u64)
            }
            Sink::Mf4(writer) => {
                let before = writer.flushed_len();
                writer.flush_data().map(|()| writer.flushed_len() - before)
            }
        };
        match result {
            Ok(bytes) => {
                segment.written += bytes;
                self.summary.bytes += bytes;
                self.summary.frames += self.buffered_frames;
                self.buf.clear();
                self.buffered_frames = 0;
                Ok(())
            }
            Err(error) => {
                // Part of the buffer may have reached the file: drop it, so the file
                // ends with a complete line (best effort: a device cannot be cut).
                let file = match &segment.sink {
                    Sink::Candump(file) => file,
                    Sink::Mf4(writer) => writer.get_ref(),
                };
                let _ = file.set_len(segment.written);
                let path = segment.path.clone();
                Err(self.fail(path, error))
            }
        }
    }

    /// Flushes, syncs and closes the current segment.
    fn close_segment(&mut self) -> Result<(), RecordError> {
        self.flush_buffer()?;
        if let Some(segment) = self.segment.take() {
            let file = match segment.sink {
                Sink::Candump(file) => Ok(file),
                Sink::Mf4(writer) => {
                    let before = writer.flushed_len();
                    writer.finish().inspect(|file| {
                        // Its length: the end (lists, history) written by `finish`.
                        let after = file.metadata().map_or(before, |m| m.len());
                        self.summary.bytes += after.saturating_sub(before);
                    })
                }
            };
            if let Err(error) = file.and_then(|f| f.sync_all()) {
                return Err(self.fail(segment.path, error));
            }
        }
        Ok(())
    }

    /// Records one frame (as a candump line on `can<channel>`, without direction, or its
    /// MF4 records). Flushes if [`FLUSH_INTERVAL`] has passed since the last flush.
    pub fn write(&mut self, frame: &LogFrame) -> Result<(), RecordError> {
        if self.failed {
            return Err(RecordError::Stopped);
        }
        self.line.clear();
        let len = match self.format {
            RecordFormat::Candump => {
                format_candump(&mut self.line, frame, false);
                self.line.len() as u64
            }
            RecordFormat::Mf4 => MF4_FRAME_BYTES,
        };
        let rotate = match &self.segment {
            None => true,
            Some(s) => {
                let too_big = self
                    .policy
                    .max_bytes
                    .is_some_and(|max| s.bytes > 0 && s.bytes + len > max);
                let too_long = match (self.policy.max_duration_us, s.first_t_us) {
                    (Some(max), Some(first)) => frame.t_us.saturating_sub(first) >= max,
                    _ => false,
                };
                too_big || too_long
            }
        };
        if rotate {
            self.close_segment()?;
            self.open_segment()?;
        }
        let segment = self.segment.as_mut().ok_or(RecordError::Stopped)?;
        segment.first_t_us.get_or_insert(frame.t_us);
        let buffered = match &mut segment.sink {
            Sink::Candump(_) => {
                segment.bytes += len;
                self.buf.extend_from_slice(&self.line);
                self.buf.len()
            }
            Sink::Mf4(writer) => {
                if let Err(error) = writer.write(frame) {
                    let path = segment.path.clone();
                    return Err(self.fail(path, error));
                }
                segment.bytes = writer.len();
                (writer.len() - writer.flushed_len()) as usize
            }
        };
        self.buffered_frames += 1;
        if buffered >= BUFFER_LIMIT || self.last_flush.elapsed() >= FLUSH_INTERVAL {
            self.flush_buffer()?;
        }
        Ok(())
    }

    /// To be called by the owner's loop: flushes if [`FLUSH_INTERVAL`] has passed since
    /// the last flush at `now`.
    pub fn poll(&mut self, now: Instant) -> Result<(), RecordError> {
        if self.failed {
            return Err(RecordError::Stopped);
        }
        if now.saturating_duration_since(self.last_flush) >= FLUSH_INTERVAL {
            self.flush_buffer()?;
        }
        Ok(())
    }

    /// What has been written so far (frames still in the buffer not counted).
    pub fn summary(&self) -> &RecordSummary {
        &self.summary
    }

    /// The file being written.
    pub fn current_file(&self) -> Option<&Path> {
        self.segment.as_ref().map(|s| s.path.as_path())
    }

    /// Flushes, syncs the last file to disk and returns what was written. After an
    /// earlier error, returns what was written before it.
    pub fn stop(mut self) -> Result<RecordSummary, RecordError> {
        if !self.failed {
            self.close_segment()?;
        }
        Ok(std::mem::take(&mut self.summary))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::FrameKind;
    use crate::read::CandumpReader;

    fn frame(i: u64) -> LogFrame {
        LogFrame::new(
            1_700_000_000_000_000 + i * 1000,
            0,
            (i % 0x800) as u32,
            false,
            FrameKind::Data,
            &[i as u8, (i >> 8) as u8, 0xAA],
        )
        .unwrap()
    }

    fn read_back(files: &[PathBuf]) -> Vec<LogFrame> {
        files
            .iter()
            .flat_map(|p| {
                let bytes = std::fs::read(p).unwrap();
                assert!(bytes.is_empty() || bytes.ends_with(b"\n"), "complete lines");
                CandumpReader::new(&bytes[..])
                    .map(|f| f.unwrap())
                    .collect::<Vec<_>>()
            })
            .collect()
    }

    #[test]
    fn a_recording_reads_back_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = Recorder::start(dir.path(), "bus", RotatePolicy::default()).unwrap();
        let frames: Vec<LogFrame> = (0..1000).map(frame).collect();
        for f in &frames {
            r.write(f).unwrap();
        }
        let summary = r.stop().unwrap();
        assert_eq!(summary.files.len(), 1);
        assert_eq!(summary.frames, 1000);
        let name = summary.files[0]
            .file_name()
            .unwrap()
            .to_str()
            .unwrap()
            .to_string();
        assert!(
            name.starts_with("bus-20") && name.ends_with("Z-000.log"),
            "{name}"
        );
        assert_eq!(name.len(), "bus-20261123T132800Z-000.log".len());
        assert_eq!(
            summary.bytes,
            std::fs::metadata(&summary.files[0]).unwrap().len()
        );
        assert_eq!(read_back(&summary.files), frames);
    }

    fn read_mf4(path: &Path) -> Vec<LogFrame> {
        crate::read::Mf4Reader::new(std::fs::File::open(path).unwrap())
            .unwrap()
            .map(|f| f.unwrap())
            .collect()
    }

    /// MF4 segments: rotated like candump ones, each finished (`MDF`), read back whole; a
    /// recorder that dies (no `stop`) leaves an `UnFinMF` file that reads to its last
    /// flush.
    #[test]
    fn an_mf4_recording_reads_back_exactly_and_survives_a_crash() {
        let dir = tempfile::tempdir().unwrap();
        let policy = RotatePolicy {
            max_bytes: Some(200_000),
            max_duration_us: None,
        };
        let mut r = Recorder::start_as(dir.path(), "bus", policy, RecordFormat::Mf4).unwrap();
        let frames: Vec<LogFrame> = (0..4000).map(frame).collect();
        for f in &frames {
            r.write(f).unwrap();
        }
        let summary = r.stop().unwrap();
        assert!(summary.files.len() >= 2, "{:?}", summary.files);
        assert_eq!(summary.frames, 4000);
        let total: u64 = summary
            .files
            .iter()
            .map(|f| std::fs::metadata(f).unwrap().len())
            .sum();
        assert_eq!(summary.bytes, total);
        let mut back = Vec::new();
        for f in &summary.files {
            assert!(f.to_str().unwrap().ends_with(".mf4"));
            let bytes = std::fs::read(f).unwrap();
            assert!(bytes.starts_with(b"MDF     "), "finished");
            assert!(bytes.len() <= 200_000 + 4096, "{}", bytes.len());
            back.extend(read_mf4(f));
        }
        assert!(back == frames, "{} frames back", back.len());

        let crash = tempfile::tempdir().unwrap();
        let mut r = Recorder::start_as(
            crash.path(),
            "bus",
            RotatePolicy::default(),
            RecordFormat::Mf4,
        )
        .unwrap();
        for f in &frames[..100] {
            r.write(f).unwrap();
        }
        r.poll(Instant::now() + FLUSH_INTERVAL).unwrap();
        r.write(&frames[100]).unwrap();
        let path = r.current_file().unwrap().to_path_buf();
        drop(r);
        assert!(std::fs::read(&path).unwrap().starts_with(b"UnFinMF "));
        assert!(read_mf4(&path) == frames[..100]);
    }

    #[test]
    fn rotation_by_size_never_splits_a_line() {
        let dir = tempfile::tempdir().unwrap();
        let policy = RotatePolicy {
            max_bytes: Some(1000),
            max_duration_us: None,
        };
        let mut r = Recorder::start(dir.path(), "size", policy).unwrap();
        let frames: Vec<LogFrame> = (0..500).map(frame).collect();
        for f in &frames {
            r.write(f).unwrap();
        }
        let summary = r.stop().unwrap();
        assert!(summary.files.len() > 10, "{}", summary.files.len());
        let mut sorted = summary.files.clone();
        sorted.sort();
        assert_eq!(sorted, summary.files, "names sort in recording order");
        for (i, f) in summary.files.iter().enumerate() {
            let len = std::fs::metadata(f).unwrap().len();
            let last = i + 1 == summary.files.len();
            assert!(len <= 1000 && (len > 900 || last), "{len}");
        }
        assert_eq!(read_back(&summary.files), frames);
    }

    #[test]
    fn rotation_by_time() {
        let dir = tempfile::tempdir().unwrap();
        let policy = RotatePolicy {
            max_bytes: None,
            max_duration_us: Some(100_000),
        };
        let mut r = Recorder::start(dir.path(), "time", policy).unwrap();
        // One frame per ms for a second: ten segments of 100 frames.
        let frames: Vec<LogFrame> = (0..1000).map(frame).collect();
        for f in &frames {
            r.write(f).unwrap();
        }
        let summary = r.stop().unwrap();
        assert_eq!(summary.files.len(), 10);
        for f in &summary.files {
            let got = read_back(std::slice::from_ref(f));
            assert_eq!(got.len(), 100);
            assert!(got.last().unwrap().t_us - got[0].t_us < 100_000);
        }
        assert_eq!(read_back(&summary.files), frames);
    }

    #[test]
    fn frames_reach_the_os_within_the_flush_interval() {
        let dir = tempfile::tempdir().unwrap();
        let mut r = Recorder::start(dir.path(), "flush", RotatePolicy::default()).unwrap();
        r.write(&frame(1)).unwrap();
        let path = r.current_file().unwrap().to_path_buf();
        assert_eq!(std::fs::read(&path).unwrap().len(), 0, "still buffered");
        r.poll(Instant::now()).unwrap();
        r.poll(Instant::now() + FLUSH_INTERVAL).unwrap();
        assert_eq!(read_back(std::slice::from_ref(&path)), [frame(1)]);
        // And from `write` alone, once the interval has passed.
        std::thread::sleep(FLUSH_INTERVAL);
        r.write(&frame(2)).unwrap();
        assert_eq!(read_back(std::slice::from_ref(&path)), [frame(1), frame(2)]);
        assert_eq!(r.summary().frames, 2);
        r.stop().unwrap();
    }

    /// An opener that gives `/dev/full` (every write fails with ENOSPC) from the
    /// `full_from`-th segment on.
    fn full_disk_from(full_from: usize) -> FileOpener {
        let mut opened = 0;
        Box::new(move |path| {
            opened += 1;
            if opened > full_from {
                OpenOptions::new().write(true).open("/dev/full")
            } else {
                OpenOptions::new().write(true).create_new(true).open(path)
            }
        })
    }

    #[test]
    fn dev_full_really_is_full() {
        let mut f = OpenOptions::new().write(true).open("/dev/full").unwrap();
        let e = f.write_all(b"x").unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::StorageFull);
        assert_eq!(e.raw_os_error(), Some(28), "ENOSPC");
    }

    fn full_policy() -> RotatePolicy {
        RotatePolicy {
            max_bytes: Some(1000),
            max_duration_us: None,
        }
    }

    fn check_disk_full(error: &RecordError, file: &Path, frames: u64) {
        assert!(error.is_disk_full(), "{error}");
        assert_eq!(
            error.to_string(),
            format!(
                "recording stopped: disk full writing {} after {frames} frames",
                file.display()
            )
        );
    }

    #[test]
    fn a_full_disk_stops_the_recording_and_keeps_what_was_written() {
        // Flushed after every frame (the owner's loop polling): the failure shows in the
        // first poll after the third segment, on /dev/full, was opened.
        let dir = tempfile::tempdir().unwrap();
        let mut r =
            Recorder::start_with(dir.path(), "full", full_policy(), full_disk_from(2)).unwrap();
        let mut accepted = Vec::new();
        let error = loop {
            let f = frame(accepted.len() as u64);
            // (On a slow machine `write` may find the interval passed and flush itself.)
            if let Err(e) = r.write(&f) {
                break e;
            }
            accepted.push(f);
            if let Err(e) = r.poll(Instant::now() + FLUSH_INTERVAL) {
                break e;
            }
            assert!(
                accepted.len() < 10_000,
                "the recorder never noticed the full disk"
            );
        };
        let files = r.summary().files.clone();
        assert_eq!(files.len(), 3);
        let kept = read_back(&files[..2]);
        check_disk_full(&error, &files[2], kept.len() as u64);
        assert_eq!(kept, accepted[..kept.len()], "earlier segments intact");
        assert!(
            accepted.len() <= kept.len() + 1,
            "only the unflushed frame is lost"
        );
        assert!(matches!(r.write(&frame(0)), Err(RecordError::Stopped)));
        assert!(matches!(r.poll(Instant::now()), Err(RecordError::Stopped)));
        let summary = r.stop().unwrap();
        assert_eq!(summary.frames, kept.len() as u64);
    }

    #[test]
    fn a_full_disk_is_noticed_by_write_alone() {
        // No polls: the third segment's lines fail when its rotation flushes them.
        let dir = tempfile::tempdir().unwrap();
        let mut r =
            Recorder::start_with(dir.path(), "full", full_policy(), full_disk_from(2)).unwrap();
        let mut accepted = Vec::new();
        let error = loop {
            let f = frame(accepted.len() as u64);
            match r.write(&f) {
                Ok(()) => accepted.push(f),
                Err(e) => break e,
            }
            assert!(
                accepted.len() < 10_000,
                "the recorder never noticed the full disk"
            );
        };
        let files = r.summary().files.clone();
        assert_eq!(files.len(), 3);
        let kept = read_back(&files[..2]);
        check_disk_full(&error, &files[2], kept.len() as u64);
        assert_eq!(kept, accepted[..kept.len()]);
        r.stop().unwrap();
    }

    #[test]
    fn a_full_disk_at_stop_is_reported() {
        let dir = tempfile::tempdir().unwrap();
        let mut r =
            Recorder::start_with(dir.path(), "full", full_policy(), full_disk_from(0)).unwrap();
        r.write(&frame(1)).unwrap();
        let file = r.current_file().unwrap().to_path_buf();
        let error = r.stop().unwrap_err();
        check_disk_full(&error, &file, 0);
    }

    #[test]
    fn other_errors_are_named_too() {
        let dir = tempfile::tempdir().unwrap();
        let opener: FileOpener =
            Box::new(|_| Err(io::Error::from(io::ErrorKind::PermissionDenied)));
        let e = Recorder::start_with(dir.path(), "x", RotatePolicy::default(), opener)
            .err()
            .unwrap();
        assert!(!e.is_disk_full());
        let text = e.to_string();
        assert!(
            text.starts_with("recording stopped: permission denied writing "),
            "{text}"
        );
        assert!(text.ends_with("-000.log after 0 frames"), "{text}");
    }
}
