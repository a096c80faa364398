//! One pipeline for a live bus and a recorded log alike: a [`FrameSource`] gives frames,
//! the generated codec turns them into the [`CarState`], and every [`Observer`]
//! (diagnostics, trips, the recorder, the terminal view) sees each frame after the state
//! has taken it. There is no second code path for logs: a log is just another source.

use std::fmt;
use std::time::Duration;

use autoplug_logs::{LogError, LogFrame};

use crate::source::{FrameSource, Poll, SourceError};
use crate::state::{CarState, Update};

/// Something that watches the bus through the pipeline.
pub trait Observer {
    /// A frame, after the state took it (`update` says how).
    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState);

    /// No frame for a while (live sources only): a chance to flush files or redraw.
    fn on_idle(&mut self, _state: &CarState) {}
}

/// What to do with a malformed log line.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Strictness {
    /// Stop at the first one, naming its line.
    #[default]
    Strict,
    /// Skip it and count it.
    Lenient,
}

/// Why a run stopped early.
#[derive(Debug)]
pub enum PipelineError {
    /// The source failed (I/O, a closed connection).
    Source(SourceError),
    /// A malformed log line in strict mode.
    Malformed(LogError),
}

impl fmt::Display for PipelineError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PipelineError::Source(e) => e.fmt(f),
            PipelineError::Malformed(e) => write!(
                f,
                "{e} (use --lenient to skip malformed lines and count them)"
            ),
        }
    }
}

impl std::error::Error for PipelineError {}

/// The pipeline: the car state and what it counted on the way.
#[derive(Default)]
pub struct Pipeline {
    state: CarState,
    strictness: Strictness,
    malformed: u64,
    first_malformed: Option<LogError>,
    incomplete: Option<LogError>,
    dropped_by_logger: u64,
}

/// How long a live source is waited for before the observers get an idle call.
pub const IDLE_AFTER: Duration = Duration::from_millis(50);

impl Pipeline {
    /// A pipeline with an empty car state.
    pub fn new(strictness: Strictness) -> Self {
        Self {
            strictness,
            ..Self::default()
        }
    }

    /// The car state.
    pub fn state(&self) -> &CarState {
        &self.state
    }

    /// Malformed lines skipped (lenient mode).
    pub fn malformed(&self) -> u64 {
        self.malformed
    }

    /// The first malformed line skipped, for the report.
    pub fn first_malformed(&self) -> Option<&LogError> {
        self.first_malformed.as_ref()
    }

    /// Why the log could not be read to its end (a damaged tail, an I/O error), if so: the
    /// state holds what came before it.
    pub fn incomplete(&self) -> Option<&LogError> {
        self.incomplete.as_ref()
    }

    /// Frames the logger reported dropped (candump's `DROPCOUNT` lines).
    pub fn dropped_by_logger(&self) -> u64 {
        self.dropped_by_logger
    }

    /// Takes one frame through the state and the observers.
    pub fn feed(&mut self, frame: &LogFrame, observers: &mut [&mut dyn Observer]) -> Update {
        let update = self.state.update(frame);
        for observer in observers.iter_mut() {
            observer.on_frame(frame, update, &self.state);
        }
        update
    }

    /// Runs a source to its end (or until `stop` says so, checked between frames and at
    /// every idle moment of a live source). A log that cannot be read to its end ends the
    /// run as its end would, the frames before the damage taken: [`Pipeline::incomplete`]
    /// says why.
    pub fn run(
        &mut self,
        source: &mut dyn FrameSource,
        observers: &mut [&mut dyn Observer],
        stop: &mut dyn FnMut() -> bool,
    ) -> Result<(), PipelineError> {
        loop {
            if stop() {
                return Ok(());
            }
            match source.poll(IDLE_AFTER).map_err(PipelineError::Source)? {
                Poll::Frame(frame) => {
                    self.feed(&frame, observers);
                }
                Poll::Malformed(error) => match self.strictness {
                    Strictness::Strict => return Err(PipelineError::Malformed(error)),
                    Strictness::Lenient => {
                        self.malformed += 1;
                        self.first_malformed.get_or_insert(error);
                    }
                },
                Poll::Idle => {
                    if let Some(t_us) = source.clock_us() {
                        self.state.advance_clock(t_us);
                    }
                    for observer in observers.iter_mut() {
                        observer.on_idle(&self.state);
                    }
                }
                Poll::Dropped(n) => {
                    self.dropped_by_logger = self.dropped_by_logger.saturating_add(n);
                }
                // Not an error of the run, strict or lenient: what was read stands, and the
                // caller says the log was incomplete.
                Poll::Incomplete(error) => {
                    self.incomplete = Some(error);
                    return Ok(());
                }
                Poll::End => return Ok(()),
            }
        }
    }
}
