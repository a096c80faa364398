//! The UDS client: the tester side of ISO 14229 over ISO-TP, sans-IO.
//!
//! [`Tester`] is the counterpart of `autoplug_uds::DiagNode` and is driven the same way:
//! frames in through [`Tester::on_frame`], frames out through [`Tester::poll_transmit`] and
//! [`Tester::confirm_transmit`], timers through [`Tester::poll`], and
//! [`Tester::next_deadline`] says when to call again. It never reads a clock, so the same
//! code runs on a simulated bus with simulated time and on a real bus with the wall clock
//! ([`crate::driver`]).
//!
//! On top of it, a [`Job`] is a state machine that issues requests one after the other:
//! [`FlashJob`] (the download sequence of a production flash tool) and [`IdentJob`]
//! (identification of one ECU or all nine). A job is driven exactly like the tester.
//!
//! # Requests
//!
//! One request is in progress at a time:
//!
//! - a physical request ([`Tester::request`]) goes to one ECU on its request identifier
//!   (0x700 + node number) and ends with its positive response, its negative response
//!   ([`UdsError::Negative`], with the NRC's ISO 14229-1 name), or a timeout. As ISO
//!   14229-2 has it, P2client = P2server (50 ms, as the ECUs announce) + ΔP2 (what the
//!   network adds: [`TesterConfig::network_delay_us`]) runs from the transmission
//!   confirmation of the request's last frame (the transport saying it is on the bus) to the
//!   first frame of the response; each 0x78 "response pending" restarts the wait with
//!   P2*server (5000 ms) + ΔP2;
//! - a functional request ([`Tester::request_functional`]) is a single frame on 0x7DF that
//!   every ECU receives; the responses that arrive within a window (extended by P2* for an
//!   ECU that answers "pending") are collected, whoever sent them.
//!
//! Besides, [`Tester::set_tester_present`] sends a functional TesterPresent with the
//! positive response suppressed (0x3E 0x80) at a fixed interval, so that no ECU's S3
//! timer ends its non-default session while the tester works with another.
//!
//! Every ECU has its own ISO-TP channel in the tester (responses come on 0x780 + node
//! number), so a multi-frame response to a functional request gets its flow control like
//! any other.
//!
//! # Frames in flight
//!
//! A transport with a transmit queue (SocketCAN, socketcand) confirms a frame only once it
//! is on the bus, a queue's length after it took it. With a transmit window above one
//! ([`Tester::set_transmit_window`]) the tester hands out up to that many frames before
//! their confirmations come back, so the queue never runs dry during a transfer; the
//! confirmations, in order, then say which request is on the bus, and P2 starts at its last
//! frame's. The ISO-TP channel counts a frame sent once it is handed out, and the tester
//! keeps N_As itself: a frame unconfirmed for that long ends the request.

//!
//! # This crate
//!
//! | module | what |
//! |---|---|
//! | (root) | the sans-IO UDS client and its jobs: flash, identification, trouble codes, clear |
//! | [`driver`] | runs a job over an `autoplug_transport` transport with the wall clock |
//! | [`bus_tester`] | the gateway as a tester on a live bus (`--transmit`): jobs as an observer of the pipeline |
//! | [`names`] | NRC and service names (ISO 14229-1), the ECUs' names on the command line |
//! | `testing` | (feature `testing`) the nine ECUs' diagnostic stacks on a simulated bus, signed test images |
//!
//! ```
//! use autoplug_can::Node;
//! use autoplug_tester::{FlashConfig, FlashJob, Job, DEV_SECURITY_SECRET};
//! use autoplug_ecu::Instant;
//!
//! let image = vec![0u8; 1024]; // a signed image file in practice
//! let mut job = FlashJob::new(FlashConfig::new(Node::Cruise, image, DEV_SECURITY_SECRET)).unwrap();
//! job.poll(Instant::ZERO);
//! // The sequence starts with a TesterPresent and the functional extended session.
//! let first = job.poll_transmit(Instant::ZERO).unwrap();
//! assert_eq!((first.id(), &first.data()[..3]), (0x7DF, &[0x02, 0x3E, 0x80][..]));
//! job.confirm_transmit(Instant::ZERO);
//! let second = job.poll_transmit(Instant::ZERO).unwrap();
//! assert_eq!((second.id(), &second.data()[..3]), (0x7DF, &[0x02, 0x10, 0x03][..]));
//! ```
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod bus_tester;
pub mod driver;
pub mod names;
// Test fixtures (simulated ECUs, bus and images), for this crate's tests and the command's;
// documented as a whole in the module's header.
#[cfg(feature = "testing")]
#[allow(missing_docs)]
pub mod testing;

/// The SecurityAccess secret of the AutoPlug ECUs in development: the key for a seed is
/// `autoplug_uds::security::key_for(secret, node, seed)`, and the ECU side
/// (`DiagNode::new(node, secret, now)`) is built with this same value, so a development
/// tester unlocks every development ECU.
///
/// It is public, so it protects nothing: a production bench must replace it, on the
/// ECUs and here (`autoplug flash --secret-file FILE`), with a secret of its own.
pub use autoplug_uds::DEV_SECURITY_SECRET;

mod clear;
mod dtcs;
mod flash;
mod ident;
mod job;

pub use clear::{ClearDtcsJob, Clearing, EcuClearReport, CLEAR_ALL_DTCS};
pub use dtcs::{dtc_table, parse_report, DtcJob, DtcReading, EcuDtcReport, REPORT_ALL_DTCS};
pub use flash::{
    FlashConfig, FlashError, FlashFailure, FlashJob, FlashReport, Phase, PhaseTiming, Progress,
};
pub use ident::{
    boot_slot_text, identification_table, value_text, vehicle_vin, vin_line, EcuIdentification,
    IdentJob, Identifying, IDENTIFICATION_DIDS,
};
pub use job::{EachEcu, EveryEcu, Job, OneRequest, Requests};

use std::collections::VecDeque;
use std::fmt;

use autoplug_can::{Frame, Node, DIAG_FUNCTIONAL_REQUEST_ID};
use autoplug_ecu::Instant;
use autoplug_isotp::{Channel, ChannelError, Config as IsoTpConfig, Event, SendError};

use crate::names::{ecu_label, nrc_name, service_name, ECUS};

/// The first byte of a negative response.
const NEGATIVE_RESPONSE: u8 = 0x7F;
/// A positive response's SID is the request's plus this.
const POSITIVE_OFFSET: u8 = 0x40;
/// The NRC "request correctly received, response pending".
const RESPONSE_PENDING: u8 = 0x78;

/// Timing parameters of the tester. All times in microseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TesterConfig {
    /// P2client: the longest wait from a request to the start of its response (the ECUs
    /// announce P2server = 50 ms in their 0x50 response).
    pub p2_us: u64,
    /// P2*client: the longest wait after each 0x78 "response pending" (the ECUs announce
    /// 5000 ms).
    pub p2_star_us: u64,
    /// How long a functional request collects responses after its frame is on the bus.
    pub functional_window_us: u64,
    /// Interval of the functional TesterPresent while it is on.
    pub tester_present_interval_us: u64,
    /// The byte that pads every frame to 8 bytes (ISO 15765-4 wants DLC 8).
    pub padding: u8,
    /// ΔP2 (ISO 14229-2): what the network adds to every wait for a response, P2, P2* and
    /// the functional window: the response's way back to the tester, and how late a
    /// transport's confirmation may be. `None`: the transport's own
    /// ([`autoplug_transport::Transport::network_delay`]; none on a simulated bus).
    pub network_delay_us: Option<u64>,
}

impl TesterConfig {
    /// ISO 14229-2's defaults as the AutoPlug ECUs announce them: P2 50 ms, P2* 5000 ms; a
    /// functional window of 100 ms (P2 plus room for nine responses queueing on the bus
    /// and for the latency of a TCP link to the bus); TesterPresent every 2 s (well within
    /// the ECUs' S3 of 5 s); padding 0xCC.
    pub const DEFAULT: TesterConfig = TesterConfig {
        p2_us: 50_000,
        p2_star_us: 5_000_000,
        functional_window_us: 100_000,
        tester_present_interval_us: 2_000_000,
        padding: 0xCC,
        network_delay_us: None,
    };

    /// ΔP2 as set, or none.
    pub fn delta_p2_us(&self) -> u64 {
        self.network_delay_us.unwrap_or(0)
    }
}

impl Default for TesterConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Why a request did not get a positive response.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum UdsError {
    /// The ECU answered with a negative response.
    Negative {
        /// The request's service identifier.
        service: u8,
        /// The negative response code.
        nrc: u8,
        /// The NRC's ISO 14229-1 name, e.g. `"uploadDownloadNotAccepted"`.
        name: &'static str,
    },
    /// No (final) response in time.
    Timeout {
        /// The request's service identifier.
        service: u8,
        /// How long the last wait was (P2, or P2* after a "response pending"), µs.
        waited_us: u64,
        /// How many 0x78 "response pending" came before the silence.
        pending: u32,
    },
    /// ISO-TP lost the request or the response (e.g. no flow control from the ECU).
    Transport {
        /// The request's service identifier.
        service: u8,
        /// What the ISO-TP channel reported.
        error: ChannelError,
    },
    /// The request could not be sent at all (empty, or too long for ISO-TP).
    Unsendable {
        /// The request's service identifier (0 for an empty request).
        service: u8,
        /// Why the channel refused it.
        error: SendError,
    },
    /// A positive response that is not what the request asks for.
    UnexpectedResponse {
        /// The request's service identifier.
        service: u8,
        /// The response as received.
        response: Vec<u8>,
        /// What was expected instead.
        expected: String,
    },
    /// A request was started while another was still in progress.
    Busy,
    /// The node has no diagnostic address (the gateway).
    NotAnEcu(Node),
}

impl UdsError {
    /// The negative response code, for a negative response.
    pub fn nrc(&self) -> Option<u8> {
        match self {
            UdsError::Negative { nrc, .. } => Some(*nrc),
            _ => None,
        }
    }

    /// A negative response to `service` with `nrc`, named.
    pub fn negative(service: u8, nrc: u8) -> Self {
        UdsError::Negative {
            service,
            nrc,
            name: nrc_name(nrc),
        }
    }
}

impl fmt::Display for UdsError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            UdsError::Negative { service, nrc, name } => write!(
                f,
                "negative response to 0x{service:02X} {}: NRC 0x{nrc:02X} {name}",
                service_name(*service)
            ),
            UdsError::Timeout {
                service,
                waited_us,
                pending,
            } => {
                write!(
                    f,
                    "no response to 0x{service:02X} {} within {} ms",
                    service_name(*service),
                    waited_us / 1000
                )?;
                if *pending > 0 {
                    write!(f, " after {pending} 'response pending'")?;
                }
                Ok(())
            }
            UdsError::Transport { service, error } => write!(
                f,
                "ISO-TP error during 0x{service:02X} {}: {error}",
                service_name(*service)
            ),
            UdsError::Unsendable { service, error } => write!(
                f,
                "request 0x{service:02X} {} cannot be sent: {error}",
                service_name(*service)
            ),
            UdsError::UnexpectedResponse {
                service,
                response,
                expected,
            } => write!(
                f,
                "unexpected response to 0x{service:02X} {}: {} (expected {expected})",
                service_name(*service),
                hex_bytes(response)
            ),
            UdsError::Busy => f.write_str(
                "a request is still in progress: the tester sends one request at a time",
            ),
            UdsError::NotAnEcu(node) => write!(
                f,
                "{} has no diagnostic address: it is not one of the nine ECUs",
                node.name()
            ),
        }
    }
}

impl std::error::Error for UdsError {}

/// Space-separated upper-case hex, at most 24 bytes (then "...").
pub(crate) fn hex_bytes(bytes: &[u8]) -> String {
    let mut text: Vec<String> = bytes.iter().take(24).map(|b| format!("{b:02X}")).collect();
    if bytes.len() > 24 {
        text.push(format!("... ({} bytes)", bytes.len()));
    }
    text.join(" ")
}

/// One ECU's answer to a functional request.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FunctionalResponse {
    /// Who answered.
    pub ecu: Node,
    /// The positive response, or why there is none ([`UdsError::Negative`] for a negative
    /// response, [`UdsError::Transport`] for a response ISO-TP lost).
    pub result: Result<Vec<u8>, UdsError>,
}

/// What a finished request gives.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Response {
    /// The positive response of the ECU a physical request went to.
    Positive(Vec<u8>),
    /// Every answer to a functional request that arrived within the window, in order of
    /// arrival.
    Functional(Vec<FunctionalResponse>),
}

/// One ECU's ISO-TP channel: requests out on 0x700 + n, responses in on 0x780 + n.
struct Link {
    node: Node,
    channel: Box<Channel<4095>>,
}

/// Why a frame of the functional queue is sent.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Purpose {
    TesterPresent,
    Request,
}

/// A frame handed out by `poll_transmit` and not confirmed yet.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Handed {
    Functional(Purpose),
    /// A frame of link `link` carrying `bytes` bytes of its PDU, handed out at `at`, of
    /// the physical request numbered `request` (none for a flow control).
    Link {
        link: usize,
        bytes: usize,
        at: Instant,
        request: Option<u32>,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Wait {
    /// The request's frames are going out.
    Sending,
    /// All its frames are handed out; the last ones' confirmations are due.
    Confirming,
    /// Waiting for the (first frame of the) response until `deadline`.
    Awaiting { deadline: Instant },
    /// A multi-frame response is coming in (ISO-TP's N_Cr guards it).
    Receiving,
}

#[derive(Debug)]
struct Physical {
    /// The request's number (they are counted), to tell its frames from earlier ones'.
    id: u32,
    link: usize,
    service: u8,
    /// What a positive response must repeat after its SID.
    echo: Vec<u8>,
    len: usize,
    sent: usize,
    wait: Wait,
    /// P2, or P2* after a "response pending".
    timeout_us: u64,
    pending: u32,
}

#[derive(Debug)]
struct Functional {
    service: u8,
    /// Set once the request frame is on the bus.
    deadline: Option<Instant>,
    responses: Vec<FunctionalResponse>,
}

#[derive(Debug)]
enum InFlight {
    Idle,
    Physical(Physical),
    Functional(Functional),
}

/// The UDS client (see the module documentation).
pub struct Tester {
    config: TesterConfig,
    links: Vec<Link>,
    functional_queue: VecDeque<(Frame, Purpose)>,
    /// Frames handed out and not confirmed yet, oldest first (at most `window`).
    handed: VecDeque<Handed>,
    /// Frames that may be handed out before their confirmations come back.
    window: usize,
    /// Physical requests started so far.
    requests: u32,
    in_flight: InFlight,
    outcome: Option<Result<Response, UdsError>>,
    last_pending: u32,
    tester_present: bool,
    tester_present_due: Option<Instant>,
}

impl Tester {
    /// A tester for the nine ECUs, nothing in progress, TesterPresent off.
    pub fn new(config: TesterConfig) -> Self {
        let links = ECUS
            .iter()
            .filter_map(|&node| {
                let (tx, rx) = (node.diag_request_id()?, node.diag_response_id()?);
                let mut isotp = IsoTpConfig::default_for(tx, rx);
                isotp.padding = Some(config.padding);
                Some(Link {
                    node,
                    channel: Box::new(Channel::new(isotp)),
                })
            })
            .collect();
        Self {
            config,
            links,
            functional_queue: VecDeque::new(),
            handed: VecDeque::new(),
            window: 1,
            requests: 0,
            in_flight: InFlight::Idle,
            outcome: None,
            last_pending: 0,
            tester_present: false,
            tester_present_due: None,
        }
    }

    /// The timing parameters.
    pub fn config(&self) -> &TesterConfig {
        &self.config
    }

    /// Adopts a transport's properties: how many frames it takes before their
    /// confirmations (at least one), and its ΔP2 unless the configuration names one.
    pub fn set_transport(&mut self, window: usize, network_delay_us: u64) {
        self.window = window.max(1);
        self.config.network_delay_us.get_or_insert(network_delay_us);
    }

    /// How many frames the tester hands out before their confirmations come back.
    pub fn transmit_window(&self) -> usize {
        self.window
    }

    /// P2client: P2server + ΔP2, µs.
    fn p2_client_us(&self) -> u64 {
        self.config.p2_us + self.config.delta_p2_us()
    }

    /// Starts a physical request to `ecu`. Its outcome comes from [`Tester::take_response`].
    pub fn request(&mut self, now: Instant, ecu: Node, request: &[u8]) -> Result<(), UdsError> {
        self.request_echoing(now, ecu, request, 0)
    }

    /// Starts a physical request whose positive response echoes the `echo` bytes that
    /// follow the service identifier (a sub-function, a data or routine identifier, a
    /// block counter: `0x36 07 ...` is answered `0x76 07`). A positive response that does
    /// not is a late answer to an earlier request (one that timed out and was repeated)
    /// and is not taken for this one's.
    pub fn request_echoing(
        &mut self,
        now: Instant,
        ecu: Node,
        request: &[u8],
        echo: usize,
    ) -> Result<(), UdsError> {
        if !matches!(self.in_flight, InFlight::Idle) || self.outcome.is_some() {
            return Err(UdsError::Busy);
        }
        let service = request.first().copied().unwrap_or(0);
        let link = self
            .links
            .iter()
            .position(|l| l.node == ecu)
            .ok_or(UdsError::NotAnEcu(ecu))?;
        let channel = &mut self.links[link].channel;
        if channel.is_transmitting() {
            // Only after an ISO-TP error left a transmission behind: start afresh.
            channel.abort();
        }
        channel
            .send(now, request)
            .map_err(|error| UdsError::Unsendable { service, error })?;
        self.requests = self.requests.wrapping_add(1);
        self.in_flight = InFlight::Physical(Physical {
            id: self.requests,
            link,
            service,
            echo: request
                .get(1..=echo)
                .or_else(|| request.get(1..))
                .unwrap_or(&[])
                .to_vec(),
            len: request.len(),
            sent: 0,
            wait: Wait::Sending,
            timeout_us: self.p2_client_us(),
            pending: 0,
        });
        Ok(())
    }

    /// Starts a functional request (one single frame on 0x7DF, so at most 7 bytes). Its
    /// outcome, [`Response::Functional`], comes from [`Tester::take_response`] once the
    /// window has passed.
    pub fn request_functional(&mut self, _now: Instant, request: &[u8]) -> Result<(), UdsError> {
        if !matches!(self.in_flight, InFlight::Idle) || self.outcome.is_some() {
            return Err(UdsError::Busy);
        }
        let service = request.first().copied().unwrap_or(0);
        let frame = self
            .single_frame(request)
            .map_err(|error| UdsError::Unsendable { service, error })?;
        self.functional_queue.push_back((frame, Purpose::Request));
        self.in_flight = InFlight::Functional(Functional {
            service,
            deadline: None,
            responses: Vec::new(),
        });
        Ok(())
    }

    /// The outcome of the last request, once it has one (taken only once).
    pub fn take_response(&mut self) -> Option<Result<Response, UdsError>> {
        self.outcome.take()
    }

    /// Whether a request is in progress or its outcome not taken yet.
    pub fn is_busy(&self) -> bool {
        !matches!(self.in_flight, InFlight::Idle) || self.outcome.is_some()
    }

    /// How many 0x78 "response pending" the last finished physical request received.
    pub fn last_pending_count(&self) -> u32 {
        self.last_pending
    }

    /// Bytes of the physical request in progress that are on the bus, and its length.
    pub fn request_progress(&self) -> Option<(usize, usize)> {
        match &self.in_flight {
            InFlight::Physical(p) => Some((p.sent.min(p.len), p.len)),
            _ => None,
        }
    }

    /// Switches the periodic functional TesterPresent (0x3E 0x80) on or off. Switched on,
    /// the first one goes at the next [`Tester::poll`].
    pub fn set_tester_present(&mut self, on: bool) {
        self.tester_present = on;
        self.tester_present_due = None;
        if !on {
            self.functional_queue
                .retain(|(_, purpose)| *purpose != Purpose::TesterPresent);
        }
    }

    /// A frame received from the bus. Frames that are not responses of the nine ECUs are
    /// ignored.
    pub fn on_frame(&mut self, now: Instant, frame: &Frame) {
        let Some(link) = self
            .links
            .iter()
            .position(|l| l.channel.config().rx_id == frame.id())
        else {
            return;
        };
        if let Some(event) = self.links[link].channel.on_frame(now, frame) {
            self.on_link_event(now, link, event);
        }
        self.drain_link(now, link);
        // P2 runs to the start of the response: once its first frame is in, ISO-TP's N_Cr
        // guards the rest.
        if let InFlight::Physical(p) = &mut self.in_flight {
            if p.link == link
                && matches!(p.wait, Wait::Awaiting { .. })
                && self.links[link].channel.is_receiving()
            {
                p.wait = Wait::Receiving;
            }
        }
    }

    /// Timeouts (ISO-TP's, P2, P2*, the functional window) and the TesterPresent timer.
    pub fn poll(&mut self, now: Instant) {
        for link in 0..self.links.len() {
            self.drain_link(now, link);
        }
        self.check_confirmations(now);
        match &mut self.in_flight {
            InFlight::Physical(p) => {
                if let Wait::Awaiting { deadline } = p.wait {
                    if now >= deadline {
                        let error = UdsError::Timeout {
                            service: p.service,
                            waited_us: p.timeout_us,
                            pending: p.pending,
                        };
                        self.finish(Err(error));
                    }
                }
            }
            InFlight::Functional(f) => {
                let receiving = self.links.iter().any(|l| l.channel.is_receiving());
                if f.deadline.is_some_and(|d| now >= d) && !receiving {
                    let responses = std::mem::take(&mut f.responses);
                    self.finish(Ok(Response::Functional(responses)));
                }
            }
            InFlight::Idle => {}
        }
        if self.tester_present {
            let due = *self.tester_present_due.get_or_insert(now);
            if now >= due {
                self.tester_present_due =
                    Some(now.plus_micros(self.config.tester_present_interval_us));
                let queued = self
                    .functional_queue
                    .iter()
                    .any(|(_, purpose)| *purpose == Purpose::TesterPresent);
                if !queued {
                    // Suppress the positive response (bit 7): nine answers every 2 s would
                    // only load the bus.
                    if let Ok(frame) = self.single_frame(&[0x3E, 0x80]) {
                        self.functional_queue
                            .push_back((frame, Purpose::TesterPresent));
                    }
                }
            }
        }
    }

    /// The next frame to put on the bus, if any; none while the transmit window's worth of
    /// frames await [`Tester::confirm_transmit`] (one, unless a transport set more).
    pub fn poll_transmit(&mut self, now: Instant) -> Option<Frame> {
        if self.handed.len() >= self.window {
            return None;
        }
        if let Some((frame, purpose)) = self.functional_queue.pop_front() {
            self.handed.push_back(Handed::Functional(purpose));
            return Some(frame);
        }
        for index in 0..self.links.len() {
            let Some(frame) = self.links[index].channel.poll_transmit(now) else {
                continue;
            };
            let request = match &self.in_flight {
                InFlight::Physical(p) if p.link == index && p.wait == Wait::Sending => Some(p.id),
                _ => None,
            };
            self.handed.push_back(Handed::Link {
                link: index,
                bytes: pdu_bytes(&frame),
                at: now,
                request,
            });
            if self.window > 1 {
                // The channel hands out its next frame only once this one counts as sent:
                // the transport's queue, not the channel, holds the frames in flight.
                self.links[index].channel.confirm_transmit(now);
                self.drain_link(now, index);
            }
            return Some(frame);
        }
        None
    }

    /// The oldest frame handed out by [`Tester::poll_transmit`] and not confirmed yet is on
    /// the bus (frames are confirmed in the order they were handed out).
    pub fn confirm_transmit(&mut self, now: Instant) {
        match self.handed.pop_front() {
            None | Some(Handed::Functional(Purpose::TesterPresent)) => {}
            Some(Handed::Functional(Purpose::Request)) => {
                let window_us = self.config.functional_window_us + self.config.delta_p2_us();
                if let InFlight::Functional(f) = &mut self.in_flight {
                    f.deadline.get_or_insert(now.plus_micros(window_us));
                }
            }
            Some(Handed::Link {
                link,
                bytes,
                request,
                ..
            }) => {
                if self.window == 1 {
                    self.links[link].channel.confirm_transmit(now);
                }
                let still_handed = request.is_some_and(|id| self.handed_of(id));
                if let InFlight::Physical(p) = &mut self.in_flight {
                    if request == Some(p.id) {
                        p.sent += bytes;
                        if p.wait == Wait::Confirming && !still_handed {
                            // The request's last frame is on the bus: P2 from here.
                            p.sent = p.len;
                            p.wait = Wait::Awaiting {
                                deadline: now.plus_micros(p.timeout_us),
                            };
                        }
                    }
                }
                self.drain_link(now, link);
            }
        }
    }

    /// Whether frames of the physical request numbered `id` await their confirmation.
    fn handed_of(&self, id: u32) -> bool {
        self.handed
            .iter()
            .any(|h| matches!(h, Handed::Link { request: Some(r), .. } if *r == id))
    }

    /// N_As for frames in flight (the channel does not see them once handed out): the
    /// oldest one unconfirmed that long ends its request, and the frames handed after it.
    fn check_confirmations(&mut self, now: Instant) {
        if self.window == 1 {
            return;
        }
        let Some(&Handed::Link { link, at, .. }) = self.handed.front() else {
            return;
        };
        if now.micros_since(at) < self.links[link].channel.config().n_as_us {
            return;
        }
        self.handed.clear();
        self.links[link].channel.abort();
        if let InFlight::Physical(p) = &self.in_flight {
            if p.link == link {
                let error = UdsError::Transport {
                    service: p.service,
                    error: ChannelError::TimeoutAs,
                };
                self.finish(Err(error));
            }
        }
    }

    /// When [`Tester::poll`] or [`Tester::poll_transmit`] next has something to do
    /// (possibly already past); `None` when nothing happens without a frame or a call.
    pub fn next_deadline(&self) -> Option<Instant> {
        let mut earliest = None;
        let mut take = |t: Option<Instant>| {
            if let Some(t) = t {
                earliest = Some(earliest.map_or(t, |e: Instant| e.min(t)));
            }
        };
        for link in &self.links {
            take(link.channel.next_deadline());
        }
        match &self.in_flight {
            InFlight::Physical(Physical {
                wait: Wait::Awaiting { deadline },
                ..
            }) => take(Some(*deadline)),
            InFlight::Functional(f) => take(f.deadline),
            _ => {}
        }
        if self.tester_present {
            take(Some(self.tester_present_due.unwrap_or(Instant::ZERO)));
        }
        if self.handed.len() < self.window && !self.functional_queue.is_empty() {
            take(Some(Instant::ZERO));
        }
        if let (true, Some(Handed::Link { link, at, .. })) = (self.window > 1, self.handed.front())
        {
            take(Some(
                at.plus_micros(self.links[*link].channel.config().n_as_us),
            ));
        }
        earliest
    }

    /// A single frame on the functional identifier, padded.
    fn single_frame(&self, request: &[u8]) -> Result<Frame, SendError> {
        if request.is_empty() {
            return Err(SendError::Empty);
        }
        if request.len() > 7 {
            return Err(SendError::TooLong {
                len: request.len(),
                max: 7,
            });
        }
        let mut data = [self.config.padding; 8];
        data[0] = request.len() as u8;
        data[1..=request.len()].copy_from_slice(request);
        Frame::new(u32::from(DIAG_FUNCTIONAL_REQUEST_ID), &data).map_err(|_| SendError::Empty)
    }

    fn drain_link(&mut self, now: Instant, link: usize) {
        while let Some(event) = self.links[link].channel.poll(now) {
            self.on_link_event(now, link, event);
        }
    }

    fn on_link_event(&mut self, now: Instant, link: usize, event: Event) {
        match event {
            Event::Received { len, .. } => {
                let channel = &mut self.links[link].channel;
                let pdu = channel.received()[..len].to_vec();
                channel.release();
                self.on_response(now, link, pdu);
            }
            Event::Sent => {
                let still_handed = match &self.in_flight {
                    InFlight::Physical(p) => self.handed_of(p.id),
                    _ => false,
                };
                if let InFlight::Physical(p) = &mut self.in_flight {
                    if p.link == link && p.wait == Wait::Sending {
                        if still_handed {
                            // Handed out whole, not all on the bus yet: P2 starts at the
                            // last frame's confirmation (`confirm_transmit`).
                            p.wait = Wait::Confirming;
                        } else {
                            p.sent = p.len;
                            p.wait = Wait::Awaiting {
                                deadline: now.plus_micros(p.timeout_us),
                            };
                        }
                    }
                }
            }
            Event::Error(error) => match &mut self.in_flight {
                InFlight::Physical(p) if p.link == link => {
                    let error = UdsError::Transport {
                        service: p.service,
                        error,
                    };
                    self.finish(Err(error));
                }
                InFlight::Functional(f) => {
                    // The ECU's answer is lost; the others may still come.
                    f.responses.push(FunctionalResponse {
                        ecu: self.links[link].node,
                        result: Err(UdsError::Transport {
                            service: f.service,
                            error,
                        }),
                    });
                }
                _ => {}
            },
        }
    }

    fn on_response(&mut self, now: Instant, link: usize, pdu: Vec<u8>) {
        let config = self.config;
        match &mut self.in_flight {
            // Nothing answers a request before it is on the bus: whatever comes meanwhile
            // is a late answer to an earlier one. An answer before the request's
            // confirmation shows it was on the bus (a transport that models its
            // confirmations may be later than the bus).
            InFlight::Physical(p) if p.link == link && p.wait != Wait::Sending => {
                let mut answer = classify(p.service, &pdu);
                if matches!(answer, Answer::Positive)
                    && pdu.get(1..=p.echo.len()) != Some(&p.echo[..])
                {
                    // A positive answer to an earlier request of the same service.
                    answer = Answer::Other;
                }
                match answer {
                    Answer::Pending => {
                        p.pending += 1;
                        p.timeout_us = config.p2_star_us + config.delta_p2_us();
                        p.wait = Wait::Awaiting {
                            deadline: now.plus_micros(p.timeout_us),
                        };
                    }
                    Answer::Negative(nrc) => {
                        let error = UdsError::negative(p.service, nrc);
                        self.finish(Err(error));
                    }
                    Answer::Positive => self.finish(Ok(Response::Positive(pdu))),
                    Answer::Other => {
                        // Not ours (e.g. the answer to a TesterPresent that reached a busy
                        // ECU, or a late answer to an earlier request): keep waiting.
                        if p.wait == Wait::Receiving {
                            p.wait = Wait::Awaiting {
                                deadline: now.plus_micros(p.timeout_us),
                            };
                        }
                    }
                }
            }
            InFlight::Functional(f) => {
                let ecu = self.links[link].node;
                match classify(f.service, &pdu) {
                    Answer::Pending => {
                        if let Some(deadline) = &mut f.deadline {
                            let wait_us = config.p2_star_us + config.delta_p2_us();
                            *deadline = (*deadline).max(now.plus_micros(wait_us));
                        }
                    }
                    Answer::Negative(nrc) => f.responses.push(FunctionalResponse {
                        ecu,
                        result: Err(UdsError::negative(f.service, nrc)),
                    }),
                    Answer::Positive => f.responses.push(FunctionalResponse {
                        ecu,
                        result: Ok(pdu),
                    }),
                    Answer::Other => {}
                }
            }
            _ => {}
        }
    }

    fn finish(&mut self, outcome: Result<Response, UdsError>) {
        self.last_pending = match &self.in_flight {
            InFlight::Physical(p) => p.pending,
            _ => 0,
        };
        self.in_flight = InFlight::Idle;
        self.outcome = Some(outcome);
    }
}

impl fmt::Debug for Tester {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Tester")
            .field("config", &self.config)
            .field("in_flight", &self.in_flight)
            .field("tester_present", &self.tester_present)
            .finish_non_exhaustive()
    }
}

/// What a response PDU is to a request of `service`.
enum Answer {
    Positive,
    Negative(u8),
    Pending,
    Other,
}

fn classify(service: u8, pdu: &[u8]) -> Answer {
    match pdu {
        [NEGATIVE_RESPONSE, sid, RESPONSE_PENDING, ..] if *sid == service => Answer::Pending,
        [NEGATIVE_RESPONSE, sid, nrc, ..] if *sid == service => Answer::Negative(*nrc),
        [sid, ..] if *sid == service.wrapping_add(POSITIVE_OFFSET) => Answer::Positive,
        _ => Answer::Other,
    }
}

/// Bytes of its PDU an ISO-TP frame carries (for progress; a last consecutive frame counts
/// whole and is capped by the caller).
fn pdu_bytes(frame: &Frame) -> usize {
    match frame.data().first().map(|pci| pci >> 4) {
        Some(0) => usize::from(frame.data()[0] & 0x0F),
        Some(1) => 6,
        Some(2) => 7,
        _ => 0,
    }
}

/// `ecu_label` for error messages of this module's jobs.
pub(crate) fn label(node: Node) -> String {
    ecu_label(node)
}

#[cfg(test)]
mod tests;
