//! The flashing job: the download sequence of a production flash tool, as a state
//! machine.
//!
//! | phase | requests |
//! |---|---|
//! | session setup | functional 0x10 03 (extended); physical 0x10 02 (programming: the ECU's standstill check); functional 0x85 02 (DTC setting off), 0x28 03 01 (normal communication off) |
//! | security | 0x27 01 (seed), 0x27 02 (key = `key_for(secret, node, seed)`) |
//! | erase | 0x22 F1A0 (the slot the ECU runs: the image goes to the other one); 0x31 01 FF00 44 (slot address, image length): the sectors the image needs, answered after a series of 0x78 |
//! | transfer | 0x34 00 44 (slot address, image length); 0x36 blocks of the announced length; 0x37 |
//! | check | 0x31 01 FF01 (the ECU verifies the signature and marks the image) |
//! | reset and wait | functional 0x28 00 01 (normal communication on); 0x11 01; TesterPresent (0x3E 00) until the ECU answers again |
//! | restore | functional 0x85 01, 0x10 01 |
//!
//! Switching normal communication off on every ECU frees the bus for the transfer; DTC
//! setting off keeps the others from recording "lost communication" DTCs while the target
//! is silent. The order is what keeps a car safe and its fault memory clean:
//! - The programming session, which the ECU grants only to a car it has seen stand, is
//!   asked for before DTC setting and communication go off: a refused flash (a moving car)
//!   never silences the bus, whose messages the car is driving on, nor the fault memory.
//! - DTC setting goes off before anything falls silent, and comes back on only once the
//!   target answers again after its reset.
//! - Communication comes back on before the target's reset: the target starts on a bus
//!   where every other ECU is sending again, so its own fresh start records no "lost
//!   communication" with them (its DTC setting is on from its start).
//!
//! A functional TesterPresent (0x3E 80) goes every 2 s throughout, so no ECU's S3 timer
//! ends its session meanwhile.
//!
//! The ECU runs its image in place from slot A or slot B and writes an update to the other
//! slot, so the image must be linked for that one: the file may hold a release's images for
//! both slots ([`autoplug_image::ImageSet`]), and the job sends the one the ECU will write.
//!
//! When a step fails, the restore phase still runs (its own failures are only noted), so
//! the car is left with communication and DTC setting on and every ECU in its default
//! session; the job then ends with the first failure.

use std::fmt;

use autoplug_can::Node;
use autoplug_ecu::Instant;
use autoplug_image::{BootState, ImageHeader, ImageSet, ImageSlot, Payload};
use autoplug_uds::security::{key_for, SEED_LEN};
use autoplug_uds::server::did;

use super::{hex_bytes, Job, Response, Tester, TesterConfig, UdsError};
use crate::names::ecu_name;

mod records;
mod report;

use records::{image_for, parse_max_block_len, slot_and_length, unstartable};
pub use report::{FlashError, FlashFailure, FlashReport, Phase, PhaseTiming, Progress};

/// What to flash where, and the timing to do it with.
#[derive(Debug, Clone)]
pub struct FlashConfig {
    /// The ECU to flash.
    pub ecu: Node,
    /// The signed image file: one image, downloaded as it is, or a release's images for
    /// both slots one after the other, of which the one for the slot the ECU writes goes.
    pub image: Vec<u8>,
    /// The SecurityAccess secret shared with the ECUs.
    pub security_secret: Vec<u8>,
    /// P2, P2*, functional window, TesterPresent interval.
    pub tester: TesterConfig,
    /// How long after ECUReset the ECU may take to answer again (the bootloader may
    /// record a trial start or a revert first, the application then starts), µs.
    pub reset_timeout_us: u64,
    /// Time from the reset's response to the first TesterPresent probe, and between probes
    /// that got no answer, µs.
    pub reset_probe_interval_us: u64,
    /// How often a TransferData block whose response is lost is sent again (the ECU
    /// acknowledges a repeated block without writing it twice).
    pub transfer_retries: u8,
    /// How long the job keeps asking for the programming session while the ECU answers
    /// conditionsNotCorrect (0x22: it enters it only once it has seen the car stand for
    /// [`autoplug_uds::STANDSTILL_WINDOW_US`], so right after the car started, or just
    /// after it stopped), asking every [`FlashConfig::reset_probe_interval_us`], µs.
    pub standstill_wait_us: u64,
}

impl FlashConfig {
    /// Flashing `image` into `ecu` with the default timing: ISO 14229-2 defaults, 30 s for
    /// the ECU to come back after its reset (probed every 100 ms), one repeat of a block
    /// whose response is lost.
    pub fn new(ecu: Node, image: Vec<u8>, security_secret: &[u8]) -> Self {
        Self {
            ecu,
            image,
            security_secret: security_secret.to_vec(),
            tester: TesterConfig::DEFAULT,
            reset_timeout_us: 30_000_000,
            reset_probe_interval_us: 100_000,
            transfer_retries: 1,
            // Six standstill windows: a car that stands gets its programming session.
            standstill_wait_us: 6 * autoplug_uds::STANDSTILL_WINDOW_US,
        }
    }
}

/// The NRC an ECU answers a programming request with while the car does not stand.
const NRC_CONDITIONS_NOT_CORRECT: u8 = 0x22;
/// The NRC an ECU refuses an image's header with when the download is not what it takes
/// (a length or format it does not accept, or no machine code for an ECU running firmware).
const NRC_UPLOAD_DOWNLOAD_NOT_ACCEPTED: u8 = 0x70;

/// One request of the sequence.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    Extended,
    DtcOff,
    CommOff,
    Programming,
    Seed,
    Key,
    ReadSlot,
    Erase,
    RequestDownload,
    TransferData,
    TransferExit,
    Check,
    ResumeComm,
    Reset,
    AwaitReturn,
    CommOn,
    DtcOn,
    DefaultSession,
    Finished,
}

impl Step {
    const fn phase(self) -> Phase {
        match self {
            Step::Extended | Step::DtcOff | Step::CommOff | Step::Programming => {
                Phase::SessionSetup
            }
            Step::Seed | Step::Key => Phase::Security,
            Step::ReadSlot | Step::Erase => Phase::Erase,
            Step::RequestDownload | Step::TransferData | Step::TransferExit => Phase::Transfer,
            Step::Check => Phase::Check,
            Step::ResumeComm | Step::Reset | Step::AwaitReturn => Phase::ResetAndWait,
            Step::CommOn | Step::DtcOn | Step::DefaultSession | Step::Finished => Phase::Restore,
        }
    }

    const fn describe(self) -> &'static str {
        match self {
            Step::Extended => "functional 0x10 03 (extended session)",
            Step::DtcOff => "functional 0x85 02 (DTC setting off)",
            Step::CommOff => "functional 0x28 03 01 (communication off)",
            Step::Programming => "0x10 02 (programming session)",
            Step::Seed => "0x27 01 (request seed)",
            Step::Key => "0x27 02 (send key)",
            Step::ReadSlot => "0x22 F1A0 (the running image slot)",
            Step::Erase => "0x31 01 FF00 (erase memory)",
            Step::RequestDownload => "0x34 (request download)",
            Step::TransferData => "0x36 (transfer data)",
            Step::TransferExit => "0x37 (request transfer exit)",
            Step::Check => "0x31 01 FF01 (check programming dependencies)",
            Step::ResumeComm => "functional 0x28 00 01 (communication on before the reset)",
            Step::Reset => "0x11 01 (hard reset)",
            Step::AwaitReturn => "0x3E 00 (tester present after the reset)",
            Step::CommOn => "functional 0x28 00 01 (communication on)",
            Step::DtcOn => "functional 0x85 01 (DTC setting on)",
            Step::DefaultSession => "functional 0x10 01 (default session)",
            Step::Finished => "the end of the job",
        }
    }

    const fn is_restore(self) -> bool {
        matches!(
            self,
            Step::CommOn | Step::DtcOn | Step::DefaultSession | Step::Finished
        )
    }
}

/// The flash job (see the module documentation).
pub struct FlashJob {
    tester: Tester,
    config: FlashConfig,
    /// The node number (checked in `new`).
    node_number: u8,
    step: Step,
    /// A request of `step` is in progress.
    in_flight: bool,
    started: Option<Instant>,
    current: Option<(Phase, Instant, u32)>,
    phases: Vec<PhaseTiming>,
    notes: Vec<String>,
    key: [u8; 16],
    /// The image going to the ECU: until the ECU said which slot it runs, the first of the
    /// file; then the one for the other slot.
    image: Vec<u8>,
    /// The slot it goes to, once known.
    target: Option<ImageSlot>,
    block_len: usize,
    offset: usize,
    counter: u8,
    blocks: u32,
    retries_left: u8,
    probe_at: Option<Instant>,
    /// Since when the ECU refuses the programming session because the car does not stand.
    refused_since: Option<Instant>,
    /// Normal communication was switched off and not yet on again.
    comm_off: bool,
    /// A request went to the car (a job refused before that leaves nothing to restore).
    requested: bool,
    return_deadline: Option<Instant>,
    reset_at: Option<Instant>,
    failure: Option<(Phase, Step, FlashFailure)>,
    result: Option<Result<FlashReport, FlashError>>,
    observer: Option<Box<dyn FnMut(Progress)>>,
    last_progress: Option<Progress>,
}

impl FlashJob {
    /// A job flashing `config.image` into `config.ecu`. Refused when the node is not one of
    /// the nine ECUs; an empty image or one too long for a 32-bit length fails at the
    /// first poll.
    pub fn new(config: FlashConfig) -> Result<Self, UdsError> {
        let node_number = config
            .ecu
            .diag_node_number()
            .ok_or(UdsError::NotAnEcu(config.ecu))?;
        Ok(Self {
            tester: Tester::new(config.tester),
            node_number,
            step: Step::Extended,
            in_flight: false,
            started: None,
            current: None,
            phases: Vec::new(),
            notes: Vec::new(),
            key: [0; 16],
            block_len: 0,
            offset: 0,
            counter: 1,
            blocks: 0,
            retries_left: config.transfer_retries,
            probe_at: None,
            refused_since: None,
            comm_off: false,
            requested: false,
            return_deadline: None,
            reset_at: None,
            image: ImageSet::parse(&config.image)
                .map_or_else(|_| config.image.clone(), |set| set.first_image().to_vec()),
            target: None,
            failure: None,
            result: None,
            observer: None,
            last_progress: None,
            config,
        })
    }

    /// Calls `observer` at each change of phase and each time more of the image is on the
    /// bus (e.g. to move a progress bar).
    pub fn on_progress(&mut self, observer: impl FnMut(Progress) + 'static) {
        self.observer = Some(Box::new(observer));
    }

    /// The ECU it flashes.
    pub fn ecu(&self) -> Node {
        self.config.ecu
    }

    /// Where the job is now.
    pub fn progress(&self) -> Progress {
        Progress {
            phase: self.step.phase(),
            transferred: self.transferred() as u64,
            total: self.image.len() as u64,
        }
    }

    fn transferred(&self) -> usize {
        let mut done = self.offset;
        if self.step == Step::TransferData && self.in_flight {
            if let Some((sent, len)) = self.tester.request_progress() {
                let block = len.saturating_sub(2);
                done += sent.saturating_sub(2).min(block);
            }
        }
        done.min(self.image.len())
    }

    fn report_progress(&mut self) {
        let progress = self.progress();
        if self.last_progress != Some(progress) {
            self.last_progress = Some(progress);
            if let Some(observer) = &mut self.observer {
                observer(progress);
            }
        }
    }

    /// Closes the phase under way at `now` (counting the pending responses it saw).
    fn close_phase(&mut self, now: Instant) {
        if let Some((phase, start, pending)) = self.current.take() {
            self.phases.push(PhaseTiming {
                phase,
                duration_us: now.micros_since(start),
                response_pending: pending,
            });
        }
    }

    fn enter_phase(&mut self, now: Instant, phase: Phase) {
        if self.current.map(|(p, ..)| p) != Some(phase) {
            self.close_phase(now);
            self.current = Some((phase, now, 0));
        }
    }

    fn report(&self, now: Instant) -> FlashReport {
        FlashReport {
            ecu: self.config.ecu,
            slot: self.target,
            image_len: self.image.len() as u64,
            block_len: self.block_len,
            blocks: self.blocks,
            phases: self.phases.clone(),
            notes: self.notes.clone(),
            total_us: self.started.map_or(0, |s| now.micros_since(s)),
        }
    }

    /// Issues the request of the current step.
    fn issue(&mut self, now: Instant) -> Result<(), FlashFailure> {
        self.enter_phase(now, self.step.phase());
        let ecu = self.config.ecu;
        let tester = &mut self.tester;
        let sent = match self.step {
            Step::Extended => tester.request_functional(now, &[0x10, 0x03]),
            Step::DtcOff => tester.request_functional(now, &[0x85, 0x02]),
            Step::CommOff => {
                self.comm_off = true;
                tester.request_functional(now, &[0x28, 0x03, 0x01])
            }
            Step::Programming => tester.request_echoing(now, ecu, &[0x10, 0x02], 1),
            Step::Seed => tester.request_echoing(now, ecu, &[0x27, 0x01], 1),
            Step::Key => {
                let mut request = vec![0x27, 0x02];
                request.extend_from_slice(&self.key);
                tester.request_echoing(now, ecu, &request, 1)
            }
            Step::ReadSlot => {
                let [high, low] = did::BOOT_SLOT.to_be_bytes();
                tester.request(now, ecu, &[0x22, high, low])
            }
            Step::Erase => {
                // With the image's length (addressAndLengthFormatIdentifier 0x44): the ECU
                // erases only the sectors the image needs.
                let mut request = vec![0x31, 0x01, 0xFF, 0x00];
                let slot = self.target.unwrap_or(ImageSlot::A);
                if let Some(record) = slot_and_length(slot, self.image.len()) {
                    request.extend_from_slice(&record);
                }
                tester.request_echoing(now, ecu, &request, 3)
            }
            Step::RequestDownload => {
                let slot = self.target.unwrap_or(ImageSlot::A);
                let record = slot_and_length(slot, self.image.len()).ok_or_else(|| {
                    FlashFailure::Invalid(format!(
                        "an image of {} bytes cannot be downloaded (1 byte to 4 GiB)",
                        self.image.len()
                    ))
                })?;
                let mut request = vec![0x34, 0x00];
                request.extend_from_slice(&record);
                tester.request(now, ecu, &request)
            }
            Step::TransferData => {
                let end = (self.offset + self.block_len).min(self.image.len());
                let mut request = Vec::with_capacity(2 + end - self.offset);
                request.extend_from_slice(&[0x36, self.counter]);
                request.extend_from_slice(&self.image[self.offset..end]);
                tester.request_echoing(now, ecu, &request, 1)
            }
            Step::TransferExit => tester.request(now, ecu, &[0x37]),
            Step::Check => tester.request_echoing(now, ecu, &[0x31, 0x01, 0xFF, 0x01], 3),
            Step::Reset => tester.request_echoing(now, ecu, &[0x11, 0x01], 1),
            Step::AwaitReturn => tester.request_echoing(now, ecu, &[0x3E, 0x00], 1),
            Step::CommOn | Step::ResumeComm => tester.request_functional(now, &[0x28, 0x00, 0x01]),
            Step::DtcOn => tester.request_functional(now, &[0x85, 0x01]),
            Step::DefaultSession => tester.request_functional(now, &[0x10, 0x01]),
            Step::Finished => return Ok(()),
        };
        sent.map_err(FlashFailure::Uds)?;
        self.requested = true;
        self.in_flight = true;
        Ok(())
    }

    /// Takes the outcome of the current step's request and picks the next step.
    fn on_outcome(&mut self, now: Instant, outcome: Result<Response, UdsError>) {
        let pending = self.tester.last_pending_count();
        if let Some((_, _, count)) = &mut self.current {
            *count += pending;
        }
        let step = self.step;
        let next = match (step, outcome) {
            (
                Step::Extended | Step::DtcOff | Step::CommOff | Step::ResumeComm,
                Ok(Response::Functional(list)),
            ) => {
                self.note_functional(step, &list);
                Ok(match step {
                    Step::Extended => Step::Programming,
                    Step::DtcOff => Step::CommOff,
                    Step::CommOff => Step::Seed,
                    _ => {
                        self.comm_off = false;
                        Step::Reset
                    }
                })
            }
            (Step::CommOn | Step::DtcOn | Step::DefaultSession, outcome) => {
                match outcome {
                    Ok(Response::Functional(list)) => self.note_functional(step, &list),
                    Ok(Response::Positive(_)) => {}
                    Err(error) => self.notes.push(format!("{}: {error}", step.describe())),
                }
                if step == Step::CommOn {
                    self.comm_off = false;
                }
                Ok(match step {
                    Step::CommOn => Step::DtcOn,
                    Step::DtcOn => Step::DefaultSession,
                    _ => Step::Finished,
                })
            }
            (Step::AwaitReturn, outcome) => {
                // Any answer, even a negative one, shows the ECU runs again.
                let answered = match outcome {
                    Ok(_) => true,
                    Err(error) => matches!(error, UdsError::Negative { .. }),
                };
                if answered {
                    Ok(Step::DtcOn)
                } else if self.return_deadline.is_some_and(|d| now >= d) {
                    Err(FlashFailure::NoReturnAfterReset {
                        waited_us: self.reset_at.map_or(0, |r| now.micros_since(r)),
                    })
                } else {
                    self.probe_at = Some(now.plus_micros(self.config.reset_probe_interval_us));
                    Ok(Step::AwaitReturn)
                }
            }
            (
                Step::Programming,
                Err(UdsError::Negative {
                    nrc: NRC_CONDITIONS_NOT_CORRECT,
                    ..
                }),
            ) => {
                // The ECU has not seen the car stand long enough (it just started, or the
                // car just stopped): ask again shortly, for a while.
                let since = *self.refused_since.get_or_insert(now);
                let waited_us = now.micros_since(since);
                if waited_us >= self.config.standstill_wait_us {
                    Err(FlashFailure::NotStanding { waited_us })
                } else {
                    if waited_us == 0 {
                        self.notes.push(
                            "the ECU refused the programming session until it saw the car stand (NRC 0x22 conditionsNotCorrect): asked again".into(),
                        );
                    }
                    self.probe_at = Some(now.plus_micros(self.config.reset_probe_interval_us));
                    Ok(Step::Programming)
                }
            }
            (Step::Reset, Err(UdsError::Timeout { .. })) => {
                // The ECU may reset before its response is out: find out by probing.
                self.notes
                    .push("no response to ECUReset: probing whether the ECU reset".into());
                self.start_waiting_for_return(now);
                Ok(Step::AwaitReturn)
            }
            (Step::TransferData, Err(error @ UdsError::Timeout { .. }))
                if self.retries_left > 0 =>
            {
                self.retries_left -= 1;
                self.notes.push(format!(
                    "TransferData block {}: {error}; sent again",
                    self.counter
                ));
                Ok(Step::TransferData)
            }
            (step, Ok(Response::Positive(response))) => self.on_positive(now, step, &response),
            (_, Ok(Response::Functional(_))) => Err(FlashFailure::Invalid(
                "internal error: a functional answer to a physical request".into(),
            )),
            (
                Step::TransferData,
                Err(UdsError::Negative {
                    nrc: NRC_UPLOAD_DOWNLOAD_NOT_ACCEPTED,
                    ..
                }),
            ) if ImageHeader::parse(&self.image)
                .is_ok_and(|h| h.payload == Payload::HostLogic) =>
            {
                Err(FlashFailure::Invalid(
                    "the ECU refused the image's header (NRC 0x70 uploadDownloadNotAccepted): the image holds no machine code (it is built for the virtual car's host-logic ECUs), and an ECU that runs its firmware takes only a firmware release (scripts/firmware-release)".into(),
                ))
            }
            (_, Err(error)) => Err(FlashFailure::Uds(error)),
        };
        match next {
            Ok(next) => self.step = next,
            Err(failure) => self.fail(now, failure),
        }
    }

    /// The next step after a positive response of `step`, or why the response is wrong.
    fn on_positive(
        &mut self,
        now: Instant,
        step: Step,
        response: &[u8],
    ) -> Result<Step, FlashFailure> {
        let unexpected = |service: u8, expected: &str| {
            FlashFailure::Uds(UdsError::UnexpectedResponse {
                service,
                response: response.to_vec(),
                expected: expected.to_string(),
            })
        };
        match step {
            Step::Programming => match response {
                [0x50, 0x02, ..] => Ok(Step::DtcOff),
                _ => Err(unexpected(0x10, "50 02 ...")),
            },
            Step::Seed => {
                let Some(seed) = response
                    .strip_prefix(&[0x67, 0x01])
                    .and_then(|s| <[u8; SEED_LEN]>::try_from(s).ok())
                else {
                    return Err(unexpected(0x27, "67 01 and a 16-byte seed"));
                };
                if seed.iter().all(|&b| b == 0) {
                    // ISO 14229-1: an all-zero seed means "already unlocked".
                    return Ok(Step::ReadSlot);
                }
                self.key = key_for(&self.config.security_secret, self.node_number, &seed);
                Ok(Step::Key)
            }
            Step::Key => match response {
                [0x67, 0x02, ..] => Ok(Step::ReadSlot),
                _ => Err(unexpected(0x27, "67 02")),
            },
            Step::ReadSlot => {
                let [high, low] = did::BOOT_SLOT.to_be_bytes();
                let Some((running, state)) = response
                    .strip_prefix(&[0x62, high, low])
                    .and_then(autoplug_uds::parse_boot_slot)
                else {
                    return Err(unexpected(0x22, "62 F1 A0, the slot and its state"));
                };
                if state == BootState::Trial {
                    return Err(FlashFailure::Invalid(format!(
                        "the ECU runs a new image in slot {} that has not confirmed itself yet (its self-test runs after a start): try again once it has",
                        running.letter()
                    )));
                }
                let target = running.other();
                self.image = image_for(&self.config.image, running, target)
                    .map_err(FlashFailure::Invalid)?;
                self.target = Some(target);
                Ok(Step::Erase)
            }
            Step::Erase | Step::Check => {
                let id: &[u8] = if step == Step::Erase {
                    &[0xFF, 0x00]
                } else {
                    &[0xFF, 0x01]
                };
                match response {
                    [0x71, 0x01, a, b, status @ ..] if [*a, *b] == id => {
                        // routineStatusRecord: 0x00 is "completed correctly".
                        if let Some(&status) = status.first() {
                            if status != 0 {
                                return Err(unexpected(
                                    0x31,
                                    "routine status 00 (completed correctly)",
                                ));
                            }
                        }
                        Ok(if step == Step::Erase {
                            Step::RequestDownload
                        } else {
                            Step::ResumeComm
                        })
                    }
                    _ => Err(unexpected(0x31, &format!("71 01 {}", hex_bytes(id)))),
                }
            }
            Step::RequestDownload => {
                let max = parse_max_block_len(response)
                    .ok_or_else(|| unexpected(0x34, "74, a length format and the block length"))?;
                // The announced length counts the SID and the block counter; a PDU carries
                // at most 4095 bytes.
                let block_len = max.min(4095).saturating_sub(2);
                if block_len == 0 {
                    return Err(unexpected(0x34, "a block length of 3 bytes or more"));
                }
                self.block_len = block_len;
                self.offset = 0;
                self.counter = 1;
                self.retries_left = self.config.transfer_retries;
                Ok(Step::TransferData)
            }
            Step::TransferData => match response {
                [0x76, counter, ..] if *counter == self.counter => {
                    self.offset = (self.offset + self.block_len).min(self.image.len());
                    self.blocks += 1;
                    // The block sequence counter wraps 0xFF → 0x00 (ISO 14229-1 14.4).
                    self.counter = self.counter.wrapping_add(1);
                    self.retries_left = self.config.transfer_retries;
                    Ok(if self.offset >= self.image.len() {
                        Step::TransferExit
                    } else {
                        Step::TransferData
                    })
                }
                _ => Err(unexpected(
                    0x36,
                    &format!("76 {:02X} (the block counter)", self.counter),
                )),
            },
            Step::TransferExit => match response {
                [0x77, ..] => Ok(Step::Check),
                _ => Err(unexpected(0x37, "77")),
            },
            Step::Reset => match response {
                [0x51, 0x01, ..] => {
                    self.start_waiting_for_return(now);
                    Ok(Step::AwaitReturn)
                }
                _ => Err(unexpected(0x11, "51 01")),
            },
            _ => Ok(step),
        }
    }

    fn start_waiting_for_return(&mut self, now: Instant) {
        self.reset_at = Some(now);
        self.return_deadline = Some(now.plus_micros(self.config.reset_timeout_us));
        // The first probe waits too: an ECU still running when it arrives would answer it
        // from the old software.
        self.probe_at = Some(now.plus_micros(self.config.reset_probe_interval_us));
    }

    fn note_functional(&mut self, step: Step, list: &[super::FunctionalResponse]) {
        for response in list {
            if let Err(error) = &response.result {
                self.notes.push(format!(
                    "{}: {} answered: {error}",
                    step.describe(),
                    ecu_name(response.ecu)
                ));
            }
        }
    }

    fn fail(&mut self, now: Instant, failure: FlashFailure) {
        if self.step.is_restore() {
            self.notes
                .push(format!("{}: {failure}", self.step.describe()));
            self.step = match self.step {
                Step::CommOn => Step::DtcOn,
                Step::DtcOn => Step::DefaultSession,
                _ => Step::Finished,
            };
            return;
        }
        self.failure = Some((self.step.phase(), self.step, failure));
        // Leave the car as it was: communication (if it went off), DTC setting, default
        // session.
        self.close_phase(now);
        self.step = if !self.requested {
            Step::Finished
        } else if self.comm_off {
            Step::CommOn
        } else {
            Step::DtcOn
        };
    }

    fn finish(&mut self, now: Instant) {
        self.close_phase(now);
        self.tester.set_tester_present(false);
        let report = self.report(now);
        self.result = Some(match self.failure.take() {
            None => Ok(report),
            Some((phase, step, failure)) => Err(FlashError {
                ecu: self.config.ecu,
                phase,
                step: step.describe(),
                failure,
                report,
            }),
        });
    }
}

impl Job for FlashJob {
    type Output = FlashReport;
    type Error = FlashError;

    fn tester(&self) -> &Tester {
        &self.tester
    }

    fn tester_mut(&mut self) -> &mut Tester {
        &mut self.tester
    }

    fn advance(&mut self, now: Instant) {
        if self.result.is_some() {
            return;
        }
        if self.started.is_none() {
            self.started = Some(now);
            if let Some(reason) = unstartable(&self.config.image) {
                // Refused before anything goes to the car.
                self.failure = Some((
                    Phase::SessionSetup,
                    Step::Extended,
                    FlashFailure::Invalid(reason),
                ));
                self.finish(now);
                return;
            }
            self.tester.set_tester_present(true);
            // The first TesterPresent goes out now, before the first request.
            self.tester.poll(now);
        }
        loop {
            if self.in_flight {
                let Some(outcome) = self.tester.take_response() else {
                    break;
                };
                self.in_flight = false;
                self.on_outcome(now, outcome);
                continue;
            }
            if self.step == Step::Finished {
                self.finish(now);
                break;
            }
            if matches!(self.step, Step::AwaitReturn | Step::Programming) {
                match self.probe_at {
                    Some(at) if now < at => break,
                    _ => self.probe_at = None,
                }
            }
            if let Err(failure) = self.issue(now) {
                self.fail(now, failure);
            }
        }
        self.report_progress();
    }

    fn own_deadline(&self) -> Option<Instant> {
        if matches!(self.step, Step::AwaitReturn | Step::Programming) && !self.in_flight {
            self.probe_at
        } else {
            None
        }
    }

    fn take_result(&mut self) -> Option<Result<FlashReport, FlashError>> {
        self.result.take()
    }
}

impl fmt::Debug for FlashJob {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("FlashJob")
            .field("ecu", &self.config.ecu)
            .field("image_len", &self.image.len())
            .field("step", &self.step)
            .field("offset", &self.offset)
            .finish_non_exhaustive()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_block_length_of_a_request_download_response() {
        assert_eq!(parse_max_block_len(&[0x74, 0x20, 0x0F, 0xFF]), Some(4095));
        assert_eq!(parse_max_block_len(&[0x74, 0x10, 0x82]), Some(0x82));
        assert_eq!(
            parse_max_block_len(&[0x74, 0x40, 0x00, 0x00, 0x01, 0x02]),
            Some(0x102)
        );
        assert_eq!(parse_max_block_len(&[0x74, 0x20, 0x0F]), None);
        assert_eq!(parse_max_block_len(&[0x74, 0x00]), None);
        assert_eq!(parse_max_block_len(&[0x75, 0x20, 0x0F, 0xFF]), None);
    }

    #[test]
    fn a_report_shows_every_phase_and_the_throughput() {
        let report = FlashReport {
            ecu: Node::Cruise,
            slot: Some(ImageSlot::B),
            image_len: 65_536,
            block_len: 4093,
            blocks: 17,
            phases: Phase::ALL
                .iter()
                .map(|&phase| PhaseTiming {
                    phase,
                    duration_us: if phase == Phase::Transfer {
                        2_000_000
                    } else {
                        100_000
                    },
                    response_pending: u32::from(phase == Phase::Erase) * 2,
                })
                .collect(),
            notes: vec!["something".into()],
            total_us: 2_600_000,
        };
        assert_eq!(report.transfer_throughput(), Some(32_768.0));
        let text = report.to_string();
        for phase in Phase::ALL {
            assert!(text.contains(phase.name()), "{text}");
        }
        assert!(text.contains("32768 bytes/s (32.0 KiB/s)"), "{text}");
        assert!(text.contains("2 x response pending"), "{text}");
        assert!(text.contains("note: something"), "{text}");
        assert!(text.contains("into slot B"), "{text}");
    }
}
