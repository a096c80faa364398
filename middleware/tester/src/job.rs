//! A job: a sequence of requests run by a [`Tester`], driven like the tester itself.

use autoplug_can::Frame;
use autoplug_ecu::Instant;

use super::Tester;

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
