//! A recorded log as the dashboard's bus, with the controls of a player: play, pause,
//! speed and seek. The frames go through the same pipeline as a live bus's; the clock is
//! the log's own, paced on the wall clock at the chosen speed.
//!
//! Seeking reads the log again from its start up to the new position (logs are text or
//! BLF, read forward), and the gateway starts its analysis over from there: a verdict or a
//! trip across a jump would mix two moments of the drive.
//!
//! A recording of the virtual car has its world file beside it (`drive.world.jsonl`:
//! the road and the car's poses, never inside the candump file); the player hands its
//! poses to a world feed as the log's clock passes them, so a replayed drive shows its
//! world too.

use std::cell::RefCell;
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::time::Duration;

use autoplug_gateway::{FrameSource, LogSource, Pacer, Poll, SourceError};
use autoplug_logs::LogFrame;

/// The slowest and fastest replay, × the log's own time.
pub const SPEED_RANGE: std::ops::RangeInclusive<f64> = 0.1..=100.0;

/// The player's controls and position, shared by the session (which takes the page's
/// commands) and the source (which plays). Both live on the gateway's thread.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplayDesk {
    /// Playing (else paused).
    pub playing: bool,
    /// × the log's own time.
    pub speed: f64,
    /// A seek asked for and not yet done, s from the log's start.
    pub seek_to: Option<f64>,
    /// Where the replay is, s from the log's start.
    pub position_s: f64,
    /// The log's length, s (first to last frame).
    pub duration_s: f64,
    /// The replay reached the end of the log (and paused there).
    pub at_end: bool,
    /// Seeks asked for so far: the gateway starts its analysis over once per seek.
    pub seeks: u64,
}

impl ReplayDesk {
    /// A player at the start of a log of `duration_s`, playing at 1×.
    pub fn new(duration_s: f64) -> Self {
        Self {
            playing: true,
            speed: 1.0,
            seek_to: None,
            position_s: 0.0,
            duration_s,
            at_end: false,
            seeks: 0,
        }
    }

    /// Asks for a jump to `to_s` from the log's start.
    pub fn seek(&mut self, to_s: f64) {
        self.seek_to = Some(to_s);
        self.at_end = false;
        self.seeks += 1;
    }
}

/// The log's first and last frame times, µs (reads it through once). A log whose tail is
/// damaged spans the frames before the damage: those are what the player can play.
pub fn log_span(path: &Path) -> Result<(u64, u64), String> {
    let reader = autoplug_logs::open(path).map_err(|e| e.to_string())?;
    let mut span: Option<(u64, u64)> = None;
    for item in reader {
        match item {
            Ok(frame) => {
                let (first, last) = span.get_or_insert((frame.t_us, frame.t_us));
                *first = (*first).min(frame.t_us);
                *last = (*last).max(frame.t_us);
            }
            Err(e) if e.is_fatal() && span.is_none() => return Err(e.to_string()),
            Err(e) if e.is_fatal() => break,
            // A malformed line is the pipeline's to report (strict: it stops there).
            Err(_) => {}
        }
    }
    span.ok_or_else(|| format!("'{}' holds no frame", path.display()))
}

/// What the player hands the world feed.
#[derive(Clone, Debug, PartialEq)]
pub enum WorldEvent {
    /// The world's description (JSON): a new world, its poses start over.
    Describe(String),
    /// A pose, as the world file holds it (JSON).
    Pose(String),
}

/// Takes the recording's world as the replay plays it.
pub type WorldFeed = Box<dyn FnMut(WorldEvent)>;

/// A recording's world, played beside its frames.
struct ReplayWorld {
    description: String,
    poses: Vec<autoplug_virtual_car::world::WorldPose>,
    /// The next pose to hand over.
    next: usize,
    feed: WorldFeed,
}

impl ReplayWorld {
    /// Hands over every pose up to `now_us`.
    fn play_until(&mut self, now_us: u64) {
        while let Some(pose) = self.poses.get(self.next) {
            if pose.t_s * 1e6 > now_us as f64 {
                break;
            }
            (self.feed)(WorldEvent::Pose(pose.to_json()));
            self.next += 1;
        }
    }

    /// Starts over (a seek): the world again, the poses from `from_us` on.
    fn restart_at(&mut self, from_us: u64) {
        (self.feed)(WorldEvent::Describe(self.description.clone()));
        self.next = self
            .poses
            .partition_point(|pose| pose.t_s * 1e6 < from_us as f64);
    }
}

/// The player (see the module docs).
pub struct ControlledReplay {
    path: PathBuf,
    source: LogSource,
    desk: Rc<RefCell<ReplayDesk>>,
    first_us: u64,
    /// The log's time on the wall clock (counting again at every speed change, pause and
    /// seek), and the speed the desk asked for it.
    pacer: Pacer,
    speed: f64,
    held: Option<LogFrame>,
    /// The log time reached, µs.
    now_us: u64,
    /// After a seek, the frames before this time are played at once (even while paused),
    /// so the car state at the new position is whole.
    prime_until: Option<u64>,
    world: Option<ReplayWorld>,
}

/// How much of the log before a seek's target is played at once: every message of the
/// catalogue comes at least every 100 ms, and a value is fresh for 3 of its periods.
const PRIME_US: u64 = 1_000_000;

impl ControlledReplay {
    /// Opens `path` (its span already measured by [`log_span`]) under `desk`'s control.
    pub fn open(
        path: &Path,
        first_us: u64,
        desk: Rc<RefCell<ReplayDesk>>,
    ) -> Result<Self, SourceError> {
        Ok(Self {
            path: path.to_path_buf(),
            source: LogSource::open(path)?,
            desk,
            first_us,
            pacer: Pacer::new(1.0),
            speed: 1.0,
            held: None,
            now_us: first_us,
            prime_until: None,
            world: None,
        })
    }

    /// Plays the recording's world file (beside the log, see the module docs) into
    /// `feed`. Without one, or with one that cannot be read, the replay has no world and
    /// says why (`Err`); a damaged world file plays up to the damage (`Ok` with the
    /// reason).
    pub fn with_world(&mut self, mut feed: WorldFeed) -> Result<Option<String>, String> {
        let path = autoplug_virtual_car::world::world_file_for(&self.path);
        if !path.exists() {
            return Err(format!("no world file ({}) beside the log", path.display()));
        }
        let log = autoplug_virtual_car::world::read_world_file(&path)?;
        let description = log.description.to_string();
        feed(WorldEvent::Describe(description.clone()));
        let mut world = ReplayWorld {
            description,
            poses: log.poses,
            next: 0,
            feed,
        };
        world.play_until(self.now_us);
        self.world = Some(world);
        Ok(log.damaged)
    }

    fn play_world(&mut self) {
        if let Some(world) = &mut self.world {
            world.play_until(self.now_us);
        }
    }

    fn seek(&mut self, to_s: f64) -> Result<(), SourceError> {
        let target = self.first_us + (to_s.max(0.0) * 1e6) as u64;
        let primed_from = target.saturating_sub(PRIME_US).max(self.first_us);
        self.source = LogSource::open(&self.path)?;
        self.held = None;
        self.prime_until = Some(target);
        loop {
            match self.source.poll(Duration::ZERO)? {
                Poll::Frame(frame) if frame.t_us >= primed_from => {
                    self.held = Some(frame);
                    break;
                }
                Poll::Frame(_) | Poll::Malformed(_) | Poll::Dropped(_) | Poll::Idle => {}
                Poll::End | Poll::Incomplete(_) => break,
            }
        }
        self.now_us = primed_from;
        if let Some(world) = &mut self.world {
            world.restart_at(primed_from);
        }
        self.pacer.restart();
        let mut desk = self.desk.borrow_mut();
        desk.position_s = to_s;
        desk.at_end = self.held.is_none();
        Ok(())
    }
}

impl FrameSource for ControlledReplay {
    fn poll(&mut self, max_wait: Duration) -> Result<Poll, SourceError> {
        let (playing, speed, seek) = {
            let mut desk = self.desk.borrow_mut();
            (desk.playing, desk.speed, desk.seek_to.take())
        };
        if let Some(to_s) = seek {
            self.seek(to_s)?;
            return Ok(Poll::Idle);
        }
        if let Some(until) = self.prime_until {
            let frame = match self.held.take() {
                Some(frame) => Some(frame),
                None => match self.source.poll(max_wait)? {
                    Poll::Frame(frame) => Some(frame),
                    Poll::Malformed(e) => return Ok(Poll::Malformed(e)),
                    Poll::Dropped(n) => return Ok(Poll::Dropped(n)),
                    _ => None,
                },
            };
            match frame {
                Some(frame) if frame.t_us < until => {
                    self.now_us = self.now_us.max(frame.t_us);
                    self.play_world();
                    return Ok(Poll::Frame(frame));
                }
                other => {
                    // Primed: the replay goes on from the target at its pace, or stays paused.
                    self.held = other;
                    self.prime_until = None;
                    self.now_us = until;
                    self.play_world();
                    self.pacer.restart();
                }
            }
        }
        if !playing {
            // Paused: the log's clock stands; the session still takes commands.
            self.pacer.restart();
            std::thread::sleep(max_wait.min(Duration::from_millis(20)));
            return Ok(Poll::Idle);
        }
        let frame = match self.held.take() {
            Some(frame) => frame,
            None => match self.source.poll(max_wait)? {
                Poll::Frame(frame) => frame,
                // A damaged tail ends the log where the damage starts.
                Poll::End | Poll::Incomplete(_) => {
                    // Stay at the end, paused, so the page can seek back.
                    let mut desk = self.desk.borrow_mut();
                    desk.playing = false;
                    desk.at_end = true;
                    return Ok(Poll::Idle);
                }
                other => return Ok(other),
            },
        };
        if speed != self.speed {
            // The new speed counts from where the log is.
            self.speed = speed;
            self.pacer = Pacer::new(speed);
        }
        self.pacer.start_at(self.now_us.min(frame.t_us));
        if !self.pacer.wait_until_due(frame.t_us, max_wait) {
            self.held = Some(frame);
            return Ok(Poll::Idle);
        }
        self.now_us = self.now_us.max(frame.t_us);
        self.play_world();
        self.desk.borrow_mut().position_s = self.now_us.saturating_sub(self.first_us) as f64 * 1e-6;
        Ok(Poll::Frame(frame))
    }

    fn describe(&self) -> String {
        format!("replay of {}", self.path.display())
    }

    fn clock_us(&self) -> Option<u64> {
        Some(self.now_us)
    }
}
