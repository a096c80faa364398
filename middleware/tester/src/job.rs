//! A job: a sequence of requests run by a [`Tester`], driven like the tester itself.

use std::convert::Infallible;

use autoplug_can::{Frame, Node};
use autoplug_ecu::Instant;

use super::{Response, Tester, TesterConfig, UdsError};

/// A state machine that issues requests through its [`Tester`] one after the other and
/// ends with a result.
///
/// It is driven exactly like the tester (and like an ECU's `DiagNode`): the provided
/// methods pass frames, confirmations and time to the tester and let the job react. A
/// caller with its own clock (a simulated bus, the virtual car) runs it as
///
/// ```text
/// loop {
///     job.poll(now);
///     while let Some(frame) = job.poll_transmit(now) {
///         bus.send(frame);              // when it is on the bus:
///         job.confirm_transmit(now);
///     }
///     if let Some(result) = job.take_result() { break result }
///     // wait for a frame (then job.on_frame(now, &frame)) or until job.next_deadline()
/// }
/// ```
///
/// [`crate::driver::run`] is that loop over a real-time transport with the wall clock.
pub trait Job {
    /// What the job gives when it succeeds.
    type Output;
    /// What it gives when it fails.
    type Error;

    /// The tester the job issues its requests through.
    fn tester(&self) -> &Tester;

    /// The same, mutable.
    fn tester_mut(&mut self) -> &mut Tester;

    /// Reacts to whatever the last call changed: takes a finished request's response and
    /// issues the next request.
    fn advance(&mut self, now: Instant);

    /// A time at which the job itself has something to do (e.g. the next probe of an ECU
    /// that resets), besides the tester's timers.
    fn own_deadline(&self) -> Option<Instant> {
        None
    }

    /// The job's result, once it has one (taken only once).
    fn take_result(&mut self) -> Option<Result<Self::Output, Self::Error>>;

    /// A frame received from the bus.
    fn on_frame(&mut self, now: Instant, frame: &Frame) {
        self.tester_mut().on_frame(now, frame);
        self.advance(now);
    }

    /// Timers: call at [`Job::next_deadline`] at the latest.
    fn poll(&mut self, now: Instant) {
        self.tester_mut().poll(now);
        self.advance(now);
    }

    /// The next frame to send, if any.
    fn poll_transmit(&mut self, now: Instant) -> Option<Frame> {
        self.tester_mut().poll_transmit(now)
    }

    /// The frame last handed out by [`Job::poll_transmit`] is on the bus.
    fn confirm_transmit(&mut self, now: Instant) {
        self.tester_mut().confirm_transmit(now);
        self.advance(now);
    }

    /// When [`Job::poll`] has something to do next (possibly already past).
    fn next_deadline(&self) -> Option<Instant> {
        match (self.tester().next_deadline(), self.own_deadline()) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        }
    }
}

/// What varies between the jobs that ask each ECU in turn (identification, trouble codes,
/// clearing): which request comes next and what its answer means. [`EachEcu`] does the
/// rest: one request in flight at a time, a failure to send taken as that request's
/// answer, the result once no request is left.
pub trait Requests {
    /// What the job gives at its end.
    type Output;

    /// The next request: the ECU, the request's bytes, and how many bytes after the
    /// service identifier its positive response echoes; `None` when all are asked.
    fn next_request(&self) -> Option<(Node, Vec<u8>, usize)>;

    /// The answer to the request [`Requests::next_request`] gave last (or why there is
    /// none: it could not be sent, it timed out, it was refused).
    fn answered(&mut self, outcome: Result<Response, UdsError>);

    /// What was gathered, once no request is left.
    fn finish(&mut self) -> Self::Output;
}

/// A job of requests to the ECUs one after the other; it never fails as a whole: its
/// output says, ECU by ECU, what each answered.
#[derive(Debug)]
pub struct EachEcu<R: Requests> {
    tester: Tester,
    requests: R,
    in_flight: bool,
    result: Option<R::Output>,
    done: bool,
}

impl<R: Requests> EachEcu<R> {
    /// A job asking what `requests` says, with its own tester of `config`.
    pub fn with(requests: R, config: TesterConfig) -> Self {
        Self {
            tester: Tester::new(config),
            requests,
            in_flight: false,
            result: None,
            done: false,
        }
    }
}

impl<R: Requests> Job for EachEcu<R> {
    type Output = R::Output;
    type Error = Infallible;

    fn tester(&self) -> &Tester {
        &self.tester
    }

    fn tester_mut(&mut self) -> &mut Tester {
        &mut self.tester
    }

    fn advance(&mut self, now: Instant) {
        while !self.done {
            if self.in_flight {
                let Some(outcome) = self.tester.take_response() else {
                    return;
                };
                self.in_flight = false;
                self.requests.answered(outcome);
                continue;
            }
            let Some((ecu, request, echo)) = self.requests.next_request() else {
                self.done = true;
                self.result = Some(self.requests.finish());
                return;
            };
            match self.tester.request_echoing(now, ecu, &request, echo) {
                Ok(()) => self.in_flight = true,
                Err(error) => self.requests.answered(Err(error)),
            }
        }
    }

    fn take_result(&mut self) -> Option<Result<R::Output, Infallible>> {
        self.result.take().map(Ok)
    }
}

/// The one request a job sends to each ECU and what the answer means (reading the trouble
/// codes, clearing them): with [`EveryEcu`], all such a job has to say.
pub trait OneRequest {
    /// What the job reports for one ECU.
    type Report;
    /// The request.
    const REQUEST: &'static [u8];
    /// How many bytes after the service identifier the positive response echoes.
    const ECHO: usize;
    /// The ECU's report from its answer (or from why there is none).
    fn report(ecu: Node, outcome: Result<Response, UdsError>) -> Self::Report;
}

/// The same request to each ECU of a list, in order: the [`Requests`] of a
/// [`OneRequest`] job.
#[derive(Debug)]
pub struct EveryEcu<O: OneRequest> {
    ecus: Vec<Node>,
    reports: Vec<O::Report>,
}

impl<O: OneRequest> EveryEcu<O> {
    /// Asks `ecus` in that order.
    pub fn new(ecus: &[Node]) -> Self {
        Self {
            ecus: ecus.to_vec(),
            reports: Vec::new(),
        }
    }
}

impl<O: OneRequest> Requests for EveryEcu<O> {
    type Output = Vec<O::Report>;

    fn next_request(&self) -> Option<(Node, Vec<u8>, usize)> {
        let ecu = *self.ecus.get(self.reports.len())?;
        Some((ecu, O::REQUEST.to_vec(), O::ECHO))
    }

    fn answered(&mut self, outcome: Result<Response, UdsError>) {
        let ecu = self.ecus[self.reports.len()];
        self.reports.push(O::report(ecu, outcome));
    }

    fn finish(&mut self) -> Vec<O::Report> {
        std::mem::take(&mut self.reports)
    }
}
