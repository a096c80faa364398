//! Runs a sans-IO [`Job`] over a real-time [`Transport`] with the wall clock.
//!
//! The loop: poll the job, hand its frames to the transport while the transport takes
//! them, then wait for a frame or a confirmation until the job's next deadline. The job's
//! tester hands out as many frames as the transport queues ([`Transport::transmit_window`])
//! and learns when each is on the bus from the transport's confirmations, so the frames of
//! a block follow each other as fast as the bus takes them (the ECUs advertise block size 0
//! and STmin 0) and P2 starts when the request's last frame is on the bus, not when it was
//! queued; the tester's ΔP2 is the transport's unless the job's configuration names one.

use std::fmt;
use std::time::{Duration, Instant as WallInstant};

use autoplug_ecu::Instant;

use crate::Job;
use autoplug_transport::{Incoming, Transport, TransportError};

/// The longest the loop sleeps in the transport, even without a deadline: a bound on how
/// late a timer set by a callback (e.g. a progress bar) is noticed.
pub const MAX_WAIT: Duration = Duration::from_millis(10);

/// Frames taken from the transport before the job gets to send again.
const MAX_BATCH: usize = 64;

/// How long a finished job's frames may take to be confirmed before the transport is
/// handed back (the next job would take their confirmations for its own).
const SETTLE_LIMIT: Duration = Duration::from_secs(1);

/// The wall clock as the sans-IO code sees it: microseconds since the clock was made.
#[derive(Debug, Clone, Copy)]
pub struct WallClock {
    epoch: WallInstant,
}

impl WallClock {
    /// A clock reading 0 now.
    pub fn new() -> Self {
        Self {
            epoch: WallInstant::now(),
        }
    }

    /// The time now.
    pub fn now(&self) -> Instant {
        Instant::from_micros(self.epoch.elapsed().as_micros() as u64)
    }
}

impl Default for WallClock {
    fn default() -> Self {
        Self::new()
    }
}

/// Why a driven job did not give its output.
#[derive(Debug)]
pub enum DriveError<E> {
    /// The transport failed (the job was abandoned where it stood).
    Transport(TransportError),
    /// The job failed.
    Job(E),
}

impl<E: fmt::Display> fmt::Display for DriveError<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            DriveError::Transport(error) => write!(f, "transport failed: {error}"),
            DriveError::Job(error) => error.fmt(f),
        }
    }
}

impl<E: std::error::Error + 'static> std::error::Error for DriveError<E> {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            DriveError::Transport(error) => Some(error),
            DriveError::Job(error) => Some(error),
        }
    }
}

/// Runs `job` over `transport` until it has a result.
pub fn run<J: Job + ?Sized>(
    transport: &mut dyn Transport,
    job: &mut J,
) -> Result<J::Output, DriveError<J::Error>> {
    let clock = WallClock::new();
    let delta_p2_us = transport.network_delay().as_micros() as u64;
    job.tester_mut()
        .set_transport(transport.transmit_window(), delta_p2_us);
    // A frame the transport refused (its queue full), offered again first.
    let mut held = None;
    // Frames the transport took and has not confirmed yet.
    let mut unconfirmed = 0usize;
    loop {
        let now = clock.now();
        job.poll(now);
        while let Some(frame) = held.take().or_else(|| job.poll_transmit(now)) {
            if transport.send(&frame).map_err(DriveError::Transport)? {
                unconfirmed += 1;
            } else {
                held = Some(frame);
                break;
            }
        }
        if let Some(result) = job.take_result() {
            settle(transport, unconfirmed).map_err(DriveError::Transport)?;
            return result.map_err(DriveError::Job);
        }
        let now = clock.now();
        let wait = job
            .next_deadline()
            .map_or(MAX_WAIT, |deadline| {
                Duration::from_micros(deadline.micros_since(now))
            })
            .min(MAX_WAIT);
        let mut timeout = wait;
        // What has arrived (a bounded batch, so a busy bus cannot starve the job's own
        // frames and timers), then back to the job.
        for _ in 0..MAX_BATCH {
            match transport.recv(timeout).map_err(DriveError::Transport)? {
                Some(Incoming::Frame(frame, _)) => job.on_frame(clock.now(), &frame),
                Some(Incoming::Sent) => {
                    unconfirmed = unconfirmed.saturating_sub(1);
                    job.confirm_transmit(clock.now());
                }
                None => break,
            }
            timeout = Duration::ZERO;
        }
    }
}

/// Waits (at most [`SETTLE_LIMIT`]) for the confirmations of `unconfirmed` frames a
/// finished job left on the way; what else arrives meanwhile was the job's.
fn settle(transport: &mut dyn Transport, mut unconfirmed: usize) -> Result<(), TransportError> {
    let give_up = WallInstant::now() + SETTLE_LIMIT;
    while unconfirmed > 0 {
        let left = give_up.saturating_duration_since(WallInstant::now());
        match transport.recv(left.min(MAX_WAIT))? {
            Some(Incoming::Sent) => unconfirmed -= 1,
            Some(Incoming::Frame(..)) => {}
            None if left.is_zero() => break,
            None => {}
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::collections::VecDeque;
    use std::io;

    use autoplug_can::{Frame, Node};

    use super::*;
    use crate::{IdentJob, TesterConfig, UdsError, IDENTIFICATION_DIDS};
    use autoplug_transport::Timestamp;

    /// A bus with one ECU that answers every ReadDataByIdentifier with "AB", or a link
    /// that breaks at the first frame.
    struct Scripted {
        broken: bool,
        inbox: VecDeque<Incoming>,
        sent: usize,
    }

    impl Transport for Scripted {
        fn send(&mut self, frame: &Frame) -> Result<bool, TransportError> {
            if self.broken {
                return Err(TransportError::Io {
                    context: "writing to the test link".into(),
                    source: io::Error::new(io::ErrorKind::BrokenPipe, "gone"),
                });
            }
            self.sent += 1;
            // On the bus at once: its confirmation first, then the ECU's answer.
            self.inbox.push_back(Incoming::Sent);
            let data = frame.data();
            if frame.id() == 0x70D && data[1] == 0x22 {
                let answer = [0x05, 0x62, data[2], data[3], b'A', b'B', 0xCC, 0xCC];
                let timestamp = Timestamp {
                    host: WallInstant::now(),
                    bus_us: None,
                };
                self.inbox.push_back(Incoming::Frame(
                    Frame::new(0x78D, &answer).unwrap(),
                    timestamp,
                ));
            }
            Ok(true)
        }

        fn recv(&mut self, timeout: Duration) -> Result<Option<Incoming>, TransportError> {
            match self.inbox.pop_front() {
                Some(incoming) => Ok(Some(incoming)),
                None => {
                    std::thread::sleep(timeout);
                    Ok(None)
                }
            }
        }

        fn describe(&self) -> String {
            "scripted".into()
        }

        fn transmit_window(&self) -> usize {
            1
        }

        fn network_delay(&self) -> Duration {
            Duration::ZERO
        }
    }

    #[test]
    fn a_job_runs_over_a_transport_with_the_wall_clock() {
        let mut link = Scripted {
            broken: false,
            inbox: VecDeque::new(),
            sent: 0,
        };
        let mut job = IdentJob::new(&[Node::Cruise, Node::ABS], TesterConfig::default());
        let rows = run(&mut link, &mut job).unwrap();
        assert_eq!(
            link.sent,
            IDENTIFICATION_DIDS.len() + 1,
            "every identification DID of the cruise ECU, one of the silent ABS"
        );
        assert_eq!(rows[0].part_number.as_deref(), Ok(&b"AB"[..]));
        assert_eq!(rows[0].hardware_version.as_deref(), Ok(&b"AB"[..]));
        assert!(matches!(rows[1].part_number, Err(UdsError::Timeout { .. })));
    }

    #[test]
    fn a_broken_transport_ends_the_job_with_its_error() {
        let mut link = Scripted {
            broken: true,
            inbox: VecDeque::new(),
            sent: 0,
        };
        let mut job = IdentJob::new(&[Node::Cruise], TesterConfig::default());
        let error = run(&mut link, &mut job).unwrap_err();
        assert!(matches!(error, DriveError::Transport(_)));
        assert_eq!(
            error.to_string(),
            "transport failed: writing to the test link: gone"
        );
    }
}
