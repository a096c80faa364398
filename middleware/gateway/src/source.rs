//! Where frames come from: anything that yields timestamped frames, live or recorded,
//! behind one trait. The live transports (the virtual car in the process, socketcand,
//! SocketCAN) implement it in the command crate; recorded logs implement it here, as fast
//! as the machine goes or paced at ×N of their own time.

use std::fmt;
use std::sync::mpsc::{sync_channel, Receiver, SyncSender};
use std::time::{Duration, Instant};

use autoplug_logs::{LogError, LogFrame};

/// What a source has next.
#[derive(Debug)]
pub enum Poll {
    /// A frame.
    Frame(LogFrame),
    /// A log line that could not be read (the pipeline stops or skips, as asked).
    Malformed(LogError),
    /// The log cannot be read past here (a damaged tail, an I/O error): the source ends,
    /// and what came before it stands.
    Incomplete(LogError),
    /// The logger reported this many frames dropped here (candump's `DROPCOUNT`): frames
    /// that were on the bus and are not in the log.
    Dropped(u64),
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

    /// Puts a frame on the bus (a live source whose gateway may transmit): `Ok(false)` when
    /// it cannot take it yet (a full queue; offer it again later). A recorded log refuses.
    fn transmit(&mut self, _frame: &autoplug_can::Frame) -> Result<bool, SourceError> {
        Err(SourceError {
            source: self.describe(),
            message: "cannot transmit: not a live bus".into(),
        })
    }

    /// The bus time now, on the frames' time scale, for a source that knows it while the
    /// bus is silent (the virtual car's clock; a live bus's last timestamp plus the time
    /// since). The pipeline moves the car state's clock with it when the source is idle,
    /// so timers (a tester's timeouts, staleness) run on through a silence.
    fn clock_us(&self) -> Option<u64> {
        None
    }

    /// The wall-clock time the source has stood still on purpose so far, its own time
    /// not moving (a debugger holding the virtual car halted): what a pacer leaves out,
    /// so the source goes on at its pace afterwards instead of racing to catch up.
    fn paused_for(&self) -> Duration {
        Duration::ZERO
    }
}

/// A boxed source is a source (a wrapper generic over its inner source takes both).
impl<S: FrameSource + ?Sized> FrameSource for Box<S> {
    fn poll(&mut self, max_wait: Duration) -> Result<Poll, SourceError> {
        (**self).poll(max_wait)
    }

    fn describe(&self) -> String {
        (**self).describe()
    }

    fn transmit(&mut self, frame: &autoplug_can::Frame) -> Result<bool, SourceError> {
        (**self).transmit(frame)
    }

    fn clock_us(&self) -> Option<u64> {
        (**self).clock_us()
    }

    fn paused_for(&self) -> Duration {
        (**self).paused_for()
    }
}

/// Frames a log's reading thread hands over at a time.
const READ_BATCH: usize = 1024;
/// Batches read ahead at most: memory stays bounded (about 256 KiB of frames) however long
/// the log, and however slowly the pipeline takes them.
const READ_AHEAD_BATCHES: usize = 8;

/// What the reading thread hands over: the reader's items, and the frames its logger
/// reported dropped where it did.
enum ReadAhead {
    Item(Result<LogFrame, LogError>),
    Dropped(u64),
}

type Batch = Vec<ReadAhead>;

/// A recorded log, read as fast as the machine goes. Parsing runs on a thread of its own,
/// a few batches ahead of the pipeline: on a machine with two cores the text is read while
/// the frames before it are decoded and judged, so a replay goes at the pace of the slower
/// of the two instead of their sum. The frames arrive in the file's order, exactly as a
/// reader on this thread would give them.
pub struct LogSource {
    name: String,
    batches: Receiver<Batch>,
    current: std::vec::IntoIter<ReadAhead>,
}

impl LogSource {
    /// Opens a log file of any supported format (candump, ASC, BLF, MF4).
    pub fn open(path: &std::path::Path) -> Result<Self, SourceError> {
        // The open error's own text is the reason alone: the path is said once, here.
        let reader = autoplug_logs::open(path).map_err(|e| SourceError {
            source: path.display().to_string(),
            message: e.error.to_string(),
        })?;
        let (sender, batches) = sync_channel(READ_AHEAD_BATCHES);
        std::thread::Builder::new()
            .name("log reader".into())
            .spawn(move || read_ahead(reader, &sender))
            .map_err(|e| SourceError {
                source: path.display().to_string(),
                message: format!("cannot start the reading thread: {e}"),
            })?;
        Ok(Self {
            name: path.display().to_string(),
            batches,
            current: Vec::new().into_iter(),
        })
    }
}

/// The reading thread: batches until the end of the log or a fatal error, or until the
/// source is dropped (its receiver gone, the next send fails and the thread ends).
fn read_ahead(mut reader: autoplug_logs::LogReader, sender: &SyncSender<Batch>) {
    let mut batch = Vec::with_capacity(READ_BATCH);
    let mut dropped = 0;
    // Drops the logger reported since the last look, before the item that follows them.
    let mut note_drops = |reader: &autoplug_logs::LogReader, batch: &mut Batch| {
        if reader.dropped_frames() > dropped {
            batch.push(ReadAhead::Dropped(reader.dropped_frames() - dropped));
            dropped = reader.dropped_frames();
        }
    };
    while let Some(item) = reader.next() {
        note_drops(&reader, &mut batch);
        let fatal = matches!(&item, Err(e) if e.is_fatal());
        batch.push(ReadAhead::Item(item));
        if fatal {
            break;
        }
        if batch.len() >= READ_BATCH {
            let full = std::mem::replace(&mut batch, Vec::with_capacity(READ_BATCH));
            if sender.send(full).is_err() {
                return;
            }
        }
    }
    note_drops(&reader, &mut batch);
    if !batch.is_empty() {
        let _ = sender.send(batch);
    }
}

impl FrameSource for LogSource {
    fn poll(&mut self, _max_wait: Duration) -> Result<Poll, SourceError> {
        let item = match self.current.next() {
            Some(item) => item,
            None => match self.batches.recv() {
                Ok(batch) => {
                    self.current = batch.into_iter();
                    match self.current.next() {
                        Some(item) => item,
                        None => return Ok(Poll::End),
                    }
                }
                // The thread has sent everything and ended.
                Err(_) => return Ok(Poll::End),
            },
        };
        match item {
            ReadAhead::Item(Ok(frame)) => Ok(Poll::Frame(frame)),
            // The frames before a damaged tail were handed over first: they stand.
            ReadAhead::Item(Err(error)) if error.is_fatal() => Ok(Poll::Incomplete(error)),
            ReadAhead::Item(Err(error)) => Ok(Poll::Malformed(error)),
            ReadAhead::Dropped(n) => Ok(Poll::Dropped(n)),
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

/// A log's time on the wall clock at a speed: when each frame of a replay is due. It counts
/// from an anchor (a log time and the wall time it was reached); a pause, a seek or a new
/// speed starts counting again from where the log is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pacer {
    speed: f64,
    anchor: Option<(Instant, u64)>,
}

impl Pacer {
    /// A pacer at `speed` × the log's time (finite, above zero; others are taken as 1.0).
    pub fn new(speed: f64) -> Self {
        let speed = if speed.is_finite() && speed > 0.0 {
            speed
        } else {
            1.0
        };
        Self {
            speed,
            anchor: None,
        }
    }

    /// × the log's time.
    pub fn speed(&self) -> f64 {
        self.speed
    }

    /// Counts from log time `t_us`, reached now, unless it counts already.
    pub fn start_at(&mut self, t_us: u64) {
        self.anchor.get_or_insert((Instant::now(), t_us));
    }

    /// Moves the anchor `by` later: the log's time stood still that long on the wall
    /// clock (a source paused on purpose), and is due that much later from now on.
    pub fn postpone(&mut self, by: Duration) {
        if let Some((wall, _)) = &mut self.anchor {
            *wall += by;
        }
    }

    /// Stops counting: the next [`Pacer::start_at`] (or frame) anchors again.
    pub fn restart(&mut self) {
        self.anchor = None;
    }

    /// When log time `t_us` is due on the wall clock (counting from it, now, if not
    /// counting yet); a time before the anchor is due at once.
    pub fn due(&mut self, t_us: u64) -> Instant {
        let (wall, t0) = *self.anchor.get_or_insert((Instant::now(), t_us));
        wall + Duration::from_secs_f64(t_us.saturating_sub(t0) as f64 * 1e-6 / self.speed)
    }

    /// Sleeps until log time `t_us` is due, or for `max_wait` if that comes first: whether
    /// it is due (a caller told no holds the frame, so its idle duties still run).
    pub fn wait_until_due(&mut self, t_us: u64, max_wait: Duration) -> bool {
        let due = self.due(t_us);
        let now = Instant::now();
        if due <= now {
            return true;
        }
        let wait = due - now;
        if wait > max_wait {
            std::thread::sleep(max_wait);
            return false;
        }
        std::thread::sleep(wait);
        true
    }
}

/// Replays another source at `speed` × its own time (1.0: as recorded). Each frame is
/// held until its time has come on the wall clock, measured from the first frame; a jump
/// back in the log's time is not waited for.
pub struct Paced<S> {
    inner: S,
    pacer: Pacer,
    held: Option<LogFrame>,
    /// The inner source's pauses taken into account so far.
    paused: Duration,
}

impl<S: FrameSource> Paced<S> {
    /// Paces `inner` at `speed` (finite, above zero; others are taken as 1.0).
    pub fn new(inner: S, speed: f64) -> Self {
        Self {
            inner,
            pacer: Pacer::new(speed),
            held: None,
            paused: Duration::ZERO,
        }
    }
}

impl<S: FrameSource> FrameSource for Paced<S> {
    fn poll(&mut self, max_wait: Duration) -> Result<Poll, SourceError> {
        let polled = match self.held.take() {
            Some(frame) => Poll::Frame(frame),
            None => self.inner.poll(max_wait)?,
        };
        // A pause of the inner source (taken while it was polled) is not caught up on.
        let paused = self.inner.paused_for();
        if paused > self.paused {
            self.pacer.postpone(paused - self.paused);
            self.paused = paused;
        }
        let frame = match polled {
            Poll::Frame(frame) => frame,
            Poll::Idle => {
                // A source with a clock (the virtual car) went on through a silence:
                // its time is paced like its frames', or it would race ahead.
                if let Some(t_us) = self.inner.clock_us() {
                    self.pacer.wait_until_due(t_us, max_wait);
                }
                return Ok(Poll::Idle);
            }
            other => return Ok(other),
        };
        if self.pacer.wait_until_due(frame.t_us, max_wait) {
            Ok(Poll::Frame(frame))
        } else {
            // Held, so the pipeline's idle duties (flushing, redrawing) still run.
            self.held = Some(frame);
            Ok(Poll::Idle)
        }
    }

    fn describe(&self) -> String {
        format!("{} (x{})", self.inner.describe(), self.pacer.speed())
    }

    fn transmit(&mut self, frame: &autoplug_can::Frame) -> Result<bool, SourceError> {
        self.inner.transmit(frame)
    }

    fn clock_us(&self) -> Option<u64> {
        self.inner.clock_us()
    }

    fn paused_for(&self) -> Duration {
        self.inner.paused_for()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames 100 ms apart; pauses of 10 s (on purpose) once its first frame was taken.
    struct Pausing {
        next: u64,
        paused: Duration,
    }

    impl FrameSource for Pausing {
        fn poll(&mut self, _max_wait: Duration) -> Result<Poll, SourceError> {
            let t_us = self.next;
            self.next += 100_000;
            if t_us > 0 {
                self.paused = Duration::from_secs(10);
            }
            Ok(Poll::Frame(LogFrame::from_can(
                t_us,
                0,
                &autoplug_can::Frame::new(0x100, &[]).unwrap(),
            )))
        }

        fn describe(&self) -> String {
            "pausing".into()
        }

        fn paused_for(&self) -> Duration {
            self.paused
        }
    }

    #[test]
    fn a_pacer_postponed_counts_the_rest_from_later() {
        let mut pacer = Pacer::new(2.0);
        let start = pacer.due(1_000_000);
        pacer.postpone(Duration::from_secs(3));
        assert_eq!(pacer.due(1_000_000), start + Duration::from_secs(3));
        assert_eq!(
            pacer.due(3_000_000),
            start + Duration::from_secs(3) + Duration::from_secs(1),
            "2 s of the log at 2x: 1 s on the wall"
        );
    }

    #[test]
    fn a_source_paused_on_purpose_is_not_caught_up_on() {
        let mut paced = Paced::new(
            Pausing {
                next: 0,
                paused: Duration::ZERO,
            },
            1.0,
        );
        let t = |poll| match poll {
            Poll::Frame(f) => f.t_us,
            other => panic!("{other:?}"),
        };
        assert_eq!(t(paced.poll(Duration::from_secs(1)).unwrap()), 0);
        // The 10 s pause came during the second poll: its frame, 100 ms on, is 10.1 s
        // from the first on the wall clock, so it is held (no catching up).
        assert!(matches!(
            paced.poll(Duration::from_millis(1)).unwrap(),
            Poll::Idle
        ));
        let due = paced.pacer.due(100_000);
        let from_now = due.saturating_duration_since(Instant::now());
        assert!(from_now > Duration::from_secs(9), "{from_now:?}");
    }
}
