//! Where frames come from: anything that yields timestamped frames, live or recorded,
//! behind one trait. The live transports (the virtual car in the process, socketcand,
//! SocketCAN) implement it in the command crate; recorded logs implement it here, as fast
//! as the machine goes or paced at ×N of their own time.

use std::fmt;
use std::time::{Duration, Instant};

use autoplug_logs::{LogError, LogFrame};

/// What a source has next.
#[derive(Debug)]
pub enum Poll {
    /// A frame.
    Frame(LogFrame),
    /// A log line that could not be read (the pipeline stops or skips, as asked).
    Malformed(LogError),
    /// Nothing arrived within the wait (live sources).
    Idle,
    /// The source has ended (end of the log, connection closed by the other side).
    End,
}

/// Why a source cannot go on.
#[derive(Debug)]
pub struct SourceError {
    /// What the source is (a file, a bus URL).
    pub source: String,
    /// What went wrong.
    pub message: String,
}

impl fmt::Display for SourceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: {}", self.source, self.message)
    }
}

impl std::error::Error for SourceError {}

/// A source of frames.
pub trait FrameSource {
    /// The next frame, waiting at most `max_wait` on a live source.
    fn poll(&mut self, max_wait: Duration) -> Result<Poll, SourceError>;

    /// What it is, for messages ("bus.log", "socketcand://127.0.0.1:29536/can0").
    fn describe(&self) -> String;
}

/// A recorded log, read as fast as the machine goes.
pub struct LogSource {
    name: String,
    reader: autoplug_logs::LogReader,
}

impl LogSource {
    /// Opens a log file of any supported format (candump, ASC, BLF).
    pub fn open(path: &std::path::Path) -> Result<Self, SourceError> {
        let reader = autoplug_logs::open(path).map_err(|e| SourceError {
            source: path.display().to_string(),
            message: e.to_string(),
        })?;
        Ok(Self {
            name: path.display().to_string(),
            reader,
        })
    }
}

impl FrameSource for LogSource {
    fn poll(&mut self, _max_wait: Duration) -> Result<Poll, SourceError> {
        match self.reader.next() {
            None => Ok(Poll::End),
            Some(Ok(frame)) => Ok(Poll::Frame(frame)),
            Some(Err(error)) if error.is_fatal() => Err(SourceError {
                source: self.name.clone(),
                message: error.to_string(),
            }),
            Some(Err(error)) => Ok(Poll::Malformed(error)),
        }
    }

    fn describe(&self) -> String {
        self.name.clone()
    }
}

/// Frames held in memory (tests, and a live run handed over in chunks).
pub struct VecSource {
    name: String,
    frames: std::vec::IntoIter<LogFrame>,
}

impl VecSource {
    /// A source of these frames, in order.
    pub fn new(name: impl Into<String>, frames: Vec<LogFrame>) -> Self {
        Self {
            name: name.into(),
            frames: frames.into_iter(),
        }
    }
}

impl FrameSource for VecSource {
    fn poll(&mut self, _max_wait: Duration) -> Result<Poll, SourceError> {
        Ok(self.frames.next().map_or(Poll::End, Poll::Frame))
    }

    fn describe(&self) -> String {
        self.name.clone()
    }
}

/// Replays another source at `speed` × its own time (1.0: as recorded). Each frame is
/// held until its time has come on the wall clock, measured from the first frame; a jump
/// back in the log's time is not waited for.
pub struct Paced<S> {
    inner: S,
    speed: f64,
    start: Option<(Instant, u64)>,
    held: Option<LogFrame>,
}

impl<S: FrameSource> Paced<S> {
    /// Paces `inner` at `speed` (finite, above zero; others are taken as 1.0).
    pub fn new(inner: S, speed: f64) -> Self {
        let speed = if speed.is_finite() && speed > 0.0 {
            speed
        } else {
            1.0
        };
        Self {
            inner,
            speed,
            start: None,
            held: None,
        }
    }

    fn due(&mut self, frame: &LogFrame) -> Instant {
        let (wall, t0) = *self.start.get_or_insert((Instant::now(), frame.t_us));
        let offset_us = frame.t_us.saturating_sub(t0) as f64 / self.speed;
        wall + Duration::from_micros(offset_us as u64)
    }
}

impl<S: FrameSource> FrameSource for Paced<S> {
    fn poll(&mut self, max_wait: Duration) -> Result<Poll, SourceError> {
        let frame = match self.held.take() {
            Some(frame) => frame,
            None => match self.inner.poll(max_wait)? {
                Poll::Frame(frame) => frame,
                other => return Ok(other),
            },
        };
        let due = self.due(&frame);
        let now = Instant::now();
        if due <= now {
            return Ok(Poll::Frame(frame));
        }
        let wait = due - now;
        if wait > max_wait {
            // Hold it, so the pipeline's idle duties (flushing, redrawing) still run.
            std::thread::sleep(max_wait);
            self.held = Some(frame);
            return Ok(Poll::Idle);
        }
        std::thread::sleep(wait);
        Ok(Poll::Frame(frame))
    }

    fn describe(&self) -> String {
        format!("{} (x{})", self.inner.describe(), self.speed)
    }
}
