//! The gateway as a tester on the live bus, when it may transmit (`autoplug gateway
//! --transmit`, and the dashboard): it reads every ECU's identification once (part number,
//! software and hardware version, serial: the inventory recall management needs) and their
//! trouble codes at the start and then every `dtc_interval`, with the same sans-IO jobs as
//! `autoplug ids` and `autoplug dtcs`; and it runs the jobs a user asks for (flash an ECU,
//! clear the codes) in between, one job at a time, as a workshop tester does.
//!
//! It is an observer of the pipeline: the bus time of the frames it sees is its clock (and,
//! while the bus is silent, the source's clock through the pipeline's idle calls), and what
//! it sends waits in an [`Outbox`] for the source. The codes it asks for come back on the
//! bus, where the gateway's DTC monitor hears them, so a recording of the session replays to
//! the same codes.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::rc::Rc;

use autoplug_can::{Frame, Node};
use autoplug_ecu::Instant;
use autoplug_gateway::{CarState, Observer, Update};
use autoplug_logs::LogFrame;

use crate::{
    ClearDtcsJob, DtcJob, EcuClearReport, EcuIdentification, FlashError, FlashJob, FlashReport,
    IdentJob, Job, Progress, TesterConfig,
};

/// Frames the gateway's own tester wants on the bus, waiting for the source: the tester
/// is an observer of the pipeline and cannot reach the source the pipeline is reading.
/// Bounded: a tester that got ahead of the bus by more than this is stopped by it.
pub type Outbox = Rc<RefCell<VecDeque<Frame>>>;

/// Most frames waiting in an [`Outbox`] (a 4 KiB ISO-TP transfer is 586 frames).
pub const OUTBOX_CAPACITY: usize = 1024;

/// A job a user asked for.
pub enum UserJob {
    /// Flash an image.
    Flash(Box<FlashJob>),
    /// Flash an image for the fleet's update campaign: its outcome goes to the fleet's
    /// agent ([`BusTester::take_fleet_outcome`]), not to the user's.
    FleetFlash(Box<FlashJob>),
    /// Clear trouble codes.
    Clear(Box<ClearDtcsJob>),
}

/// How a user's job ended.
#[derive(Debug)]
pub enum JobOutcome {
    /// A flash, with what it did.
    Flash(Node, Result<FlashReport, Box<FlashError>>),
    /// A clear, with each ECU's answer.
    Cleared(Vec<EcuClearReport>),
}

/// How a flash ended, for its ECU.
pub type FlashOutcome = (Node, Result<FlashReport, Box<FlashError>>);

/// What the tester is doing.
enum Current {
    Ident(Box<IdentJob>),
    Dtcs(Box<DtcJob>),
    /// A flash, and whether the fleet asked for it.
    Flash(Box<FlashJob>, bool),
    Clear(Box<ClearDtcsJob>),
    Idle,
}

/// Frames of a job handed to the source and not yet taken, at most: a few, so the bus
/// stays busy during a transfer while the job's timers start near the real send time.
pub const IN_FLIGHT: usize = 4;

/// User jobs waiting at most.
pub const MAX_QUEUED_JOBS: usize = 4;

/// The gateway's tester.
pub struct BusTester {
    ecus: Vec<Node>,
    config: TesterConfig,
    outbox: Outbox,
    current: Current,
    queued: VecDeque<UserJob>,
    outcomes: VecDeque<JobOutcome>,
    fleet_outcomes: VecDeque<FlashOutcome>,
    dtc_interval_us: u64,
    next_dtc_us: Option<u64>,
    /// Read the identification again when idle (after a flash).
    reidentify: bool,
    /// Frames of the job in the outbox, not yet taken by the source.
    in_flight: usize,
    identities: Option<Vec<EcuIdentification>>,
    /// DTC reads completed.
    pub dtc_reads: u32,
    /// Frames dropped because the outbox was full (the source could not keep up).
    pub dropped: u64,
}

impl BusTester {
    /// Reads `ecus`, queuing its frames in `outbox`, reading DTCs every `dtc_interval_us`
    /// of bus time.
    pub fn new(ecus: &[Node], config: TesterConfig, outbox: Outbox, dtc_interval_us: u64) -> Self {
        Self {
            ecus: ecus.to_vec(),
            config,
            outbox,
            current: Current::Ident(Box::new(IdentJob::new(ecus, config))),
            queued: VecDeque::new(),
            outcomes: VecDeque::new(),
            fleet_outcomes: VecDeque::new(),
            dtc_interval_us,
            next_dtc_us: None,
            reidentify: false,
            in_flight: 0,
            identities: None,
            dtc_reads: 0,
            dropped: 0,
        }
    }

    /// The identification, each time it was read (taken).
    pub fn take_identities(&mut self) -> Option<Vec<EcuIdentification>> {
        self.identities.take()
    }

    /// Queues a user's job: it runs when the job under way ends. Refused (with the reason)
    /// when [`MAX_QUEUED_JOBS`] wait already, or a flash is asked while one runs or waits.
    pub fn queue(&mut self, job: UserJob) -> Result<(), String> {
        let is_flash = |j: &UserJob| matches!(j, UserJob::Flash(_) | UserJob::FleetFlash(_));
        let flashing =
            matches!(self.current, Current::Flash(..)) || self.queued.iter().any(is_flash);
        if is_flash(&job) && flashing {
            return Err("a flash is already under way: wait for its end".into());
        }
        if self.queued.len() >= MAX_QUEUED_JOBS {
            return Err(format!("{MAX_QUEUED_JOBS} jobs wait already"));
        }
        self.queued.push_back(job);
        Ok(())
    }

    /// How the user's jobs ended, oldest first (taken).
    pub fn take_outcome(&mut self) -> Option<JobOutcome> {
        self.outcomes.pop_front()
    }

    /// How the fleet's flashes ended, oldest first (taken).
    pub fn take_fleet_outcome(&mut self) -> Option<FlashOutcome> {
        self.fleet_outcomes.pop_front()
    }

    /// The flash under way: its ECU and progress.
    pub fn flash_progress(&self) -> Option<(Node, Progress)> {
        match &self.current {
            Current::Flash(job, _) => Some((job.ecu(), job.progress())),
            _ => None,
        }
    }

    /// What the tester is doing, in a word.
    pub fn activity(&self) -> &'static str {
        match self.current {
            Current::Ident(_) => "reading identification",
            Current::Dtcs(_) => "reading trouble codes",
            Current::Flash(_, false) => "flashing",
            Current::Flash(_, true) => "flashing for the fleet's campaign",
            Current::Clear(_) => "clearing trouble codes",
            Current::Idle => "idle",
        }
    }

    /// Polls the job, confirms the frames the source has taken from the outbox since, and
    /// queues its next frames, at most [`IN_FLIGHT`] not yet taken. A frame counts as sent
    /// when the source took it (put it on the bus, or in the controller's queue): confirming
    /// it when queued would start the job's timers (P2) while a long transfer still waits.
    fn drive<J: Job + ?Sized>(
        job: &mut J,
        now: Instant,
        outbox: &Outbox,
        in_flight: &mut usize,
        dropped: &mut u64,
    ) {
        job.poll(now);
        loop {
            let waiting = outbox.borrow().len().min(*in_flight);
            for _ in waiting..*in_flight {
                job.confirm_transmit(now);
            }
            *in_flight = waiting;
            if *in_flight >= IN_FLIGHT {
                return;
            }
            let Some(frame) = job.poll_transmit(now) else {
                return;
            };
            let mut queue = outbox.borrow_mut();
            if queue.len() < OUTBOX_CAPACITY {
                queue.push_back(frame);
                *in_flight += 1;
            } else {
                // Lost: the job's timeout will tell (the source is stuck).
                *dropped += 1;
                drop(queue);
                job.confirm_transmit(now);
            }
        }
    }

    /// Passes a frame (if any) and the time to the job under way, and starts the next one
    /// when it ends.
    fn step(&mut self, t_us: u64, frame: Option<&autoplug_can::Frame>) {
        let now = Instant::from_micros(t_us);
        let (outbox, in_flight, dropped) = (&self.outbox, &mut self.in_flight, &mut self.dropped);
        let ended = match &mut self.current {
            Current::Ident(job) => {
                if let Some(frame) = frame {
                    job.on_frame(now, frame);
                }
                Self::drive(job.as_mut(), now, outbox, in_flight, dropped);
                match job.take_result() {
                    Some(Ok(rows)) => {
                        self.identities = Some(rows);
                        self.next_dtc_us = Some(t_us);
                        true
                    }
                    None => false,
                }
            }
            Current::Dtcs(job) => {
                if let Some(frame) = frame {
                    job.on_frame(now, frame);
                }
                Self::drive(job.as_mut(), now, outbox, in_flight, dropped);
                let done = job.take_result().is_some();
                if done {
                    self.dtc_reads += 1;
                    self.next_dtc_us = Some(t_us.saturating_add(self.dtc_interval_us));
                }
                done
            }
            Current::Flash(job, for_fleet) => {
                if let Some(frame) = frame {
                    job.on_frame(now, frame);
                }
                Self::drive(job.as_mut(), now, outbox, in_flight, dropped);
                match job.take_result() {
                    Some(result) => {
                        let ecu = job.ecu();
                        let result = result.map_err(Box::new);
                        if *for_fleet {
                            self.fleet_outcomes.push_back((ecu, result));
                        } else {
                            self.outcomes.push_back(JobOutcome::Flash(ecu, result));
                        }
                        // The inventory shows the new software, the codes what it did.
                        self.reidentify = true;
                        true
                    }
                    None => false,
                }
            }
            Current::Clear(job) => {
                if let Some(frame) = frame {
                    job.on_frame(now, frame);
                }
                Self::drive(job.as_mut(), now, outbox, in_flight, dropped);
                match job.take_result() {
                    Some(Ok(reports)) => {
                        self.outcomes.push_back(JobOutcome::Cleared(reports));
                        // Read them back, so the view shows what the ECUs now hold.
                        self.next_dtc_us = Some(t_us);
                        true
                    }
                    None => false,
                }
            }
            Current::Idle => true,
        };
        if !ended {
            return;
        }
        self.in_flight = 0;
        self.current = if let Some(job) = self.queued.pop_front() {
            match job {
                UserJob::Flash(job) => Current::Flash(job, false),
                UserJob::FleetFlash(job) => Current::Flash(job, true),
                UserJob::Clear(job) => Current::Clear(job),
            }
        } else if std::mem::take(&mut self.reidentify) {
            Current::Ident(Box::new(IdentJob::new(&self.ecus, self.config)))
        } else if self.next_dtc_us.is_some_and(|t| t_us >= t) {
            Current::Dtcs(Box::new(DtcJob::new(&self.ecus, self.config)))
        } else {
            Current::Idle
        };
        if !matches!(self.current, Current::Idle) {
            // Its first requests go out now, not at the next frame.
            self.step(t_us, None);
        }
    }
}

impl Observer for BusTester {
    fn on_frame(&mut self, frame: &LogFrame, _update: Update, _state: &CarState) {
        let can = frame.as_can_frame();
        self.step(frame.t_us, can.as_ref());
    }

    fn on_idle(&mut self, state: &CarState) {
        // The bus is silent (a flash turned normal communication off): time still runs.
        self.step(state.now_us(), None);
    }
}
