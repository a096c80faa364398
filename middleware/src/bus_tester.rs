//! The gateway as a tester on the live bus, when it may transmit (`autoplug gateway
//! --transmit`): it reads every ECU's identification once (part number, software and
//! hardware version, serial: the inventory recall management needs) and their trouble
//! codes at the start and then every `dtc_interval`, with the same sans-IO jobs as
//! `autoplug ids` and `autoplug dtcs`. It is an observer of the pipeline: the bus time of
//! the frames it sees is its clock, and what it sends waits in an [`Outbox`] for the source.
//! The codes it asks for come back on the bus, where the gateway's DTC monitor hears them,
//! so a recording of the session replays to the same codes.

use autoplug_can::Node;
use autoplug_ecu::Instant;
use autoplug_gateway::{CarState, Observer, Update};
use autoplug_logs::LogFrame;

use crate::live::{Outbox, OUTBOX_CAPACITY};
use crate::tester::{DtcJob, EcuIdentification, IdentJob, Job, TesterConfig};

/// What the tester is doing.
enum Current {
    Ident(Box<IdentJob>),
    Dtcs(Box<DtcJob>),
    Idle,
}

/// The gateway's tester.
pub struct BusTester {
    ecus: Vec<Node>,
    config: TesterConfig,
    outbox: Outbox,
    current: Current,
    dtc_interval_us: u64,
    next_dtc_us: Option<u64>,
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
            dtc_interval_us,
            next_dtc_us: None,
            identities: None,
            dtc_reads: 0,
            dropped: 0,
        }
    }

    /// The identification read at the start, once (taken).
    pub fn take_identities(&mut self) -> Option<Vec<EcuIdentification>> {
        self.identities.take()
    }

    fn drive<J: Job>(job: &mut J, now: Instant, outbox: &Outbox, dropped: &mut u64) {
        job.poll(now);
        while let Some(frame) = job.poll_transmit(now) {
            let mut queue = outbox.borrow_mut();
            if queue.len() < OUTBOX_CAPACITY {
                queue.push_back(frame);
            } else {
                *dropped += 1;
            }
            job.confirm_transmit(now);
        }
    }
}

impl Observer for BusTester {
    fn on_frame(&mut self, frame: &LogFrame, _update: Update, _state: &CarState) {
        let now = Instant::from_micros(frame.t_us);
        let can = frame.as_can_frame();
        match &mut self.current {
            Current::Ident(job) => {
                if let Some(can) = &can {
                    job.on_frame(now, can);
                }
                Self::drive(job.as_mut(), now, &self.outbox, &mut self.dropped);
                if let Some(Ok(rows)) = job.take_result() {
                    self.identities = Some(rows);
                    self.next_dtc_us = Some(frame.t_us);
                    self.current = Current::Idle;
                }
            }
            Current::Dtcs(job) => {
                if let Some(can) = &can {
                    job.on_frame(now, can);
                }
                Self::drive(job.as_mut(), now, &self.outbox, &mut self.dropped);
                if job.take_result().is_some() {
                    self.dtc_reads += 1;
                    self.next_dtc_us = Some(frame.t_us + self.dtc_interval_us);
                    self.current = Current::Idle;
                }
            }
            Current::Idle => {
                if self.next_dtc_us.is_some_and(|t| frame.t_us >= t) {
                    let mut job = Box::new(DtcJob::new(&self.ecus, self.config));
                    Self::drive(job.as_mut(), now, &self.outbox, &mut self.dropped);
                    self.current = Current::Dtcs(job);
                }
            }
        }
    }
}
