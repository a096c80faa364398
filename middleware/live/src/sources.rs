//! Live frame sources for the gateway: the virtual car in this process, and socketcand or
//! SocketCAN over the transports of [`autoplug_transport`]; [`BusUrl`] names one.

use std::cell::RefCell;
use std::collections::VecDeque;
use std::path::PathBuf;
use std::rc::Rc;
use std::str::FromStr;
use std::time::{Duration, Instant};

use autoplug_can::Frame;
use autoplug_gateway::{FrameSource, Paced, Poll, SourceError};
use autoplug_logs::LogFrame;
use autoplug_virtual_car::car::VirtualCar;
use autoplug_virtual_car::firmware::DebugPorts;
use autoplug_virtual_car::scenario::Scenario;

use autoplug_tester::bus_tester::Outbox;
use autoplug_transport::{Incoming, Transport, TransportError, Via};

/// The virtual car's bus as a live source: each poll runs the car on until it has put
/// frames on the bus, and hands them over in bus order with their bus time. The gateway
/// sees exactly what the car's bus log holds, and nothing of its internals.
pub struct VirtualCarSource {
    car: VirtualCar,
    pending: VecDeque<LogFrame>,
    desk: Option<Rc<RefCell<crate::driving::DriverDesk>>>,
    world: Option<WorldSink>,
    /// When the world sink is next due, µs of simulated time.
    next_world_us: u64,
}

/// Takes the car every [`WORLD_PERIOD_US`] of simulated time: what publishes the
/// simulator's world (the car's pose on its road) beside the bus, for the dashboard's
/// world view. The gateway never sees it.
pub type WorldSink = Box<dyn FnMut(&VirtualCar)>;

/// How often the world sink takes the car, µs of simulated time (20 Hz: the dashboard's
/// update rate; the page interpolates between).
pub const WORLD_PERIOD_US: u64 = 50_000;

impl VirtualCarSource {
    /// The source for a car (normally just built from a scenario).
    pub fn new(car: VirtualCar) -> Self {
        Self {
            car,
            pending: VecDeque::new(),
            desk: None,
            world: None,
            next_world_us: 0,
        }
    }

    /// The same, handing the car to `world` every [`WORLD_PERIOD_US`] (from the first
    /// poll on).
    pub fn with_world(mut self, world: WorldSink) -> Self {
        self.world = Some(world);
        self
    }

    /// The same, with a person at the `desk` who may take the wheel (the dashboard).
    pub fn with_desk(car: VirtualCar, desk: Rc<RefCell<crate::driving::DriverDesk>>) -> Self {
        Self {
            desk: Some(desk),
            ..Self::new(car)
        }
    }

    /// The car, for its own reports after the run.
    pub fn car(&self) -> &VirtualCar {
        &self.car
    }

    /// The car, for whoever drives it (a simulated driver of `autoplug fleet simulate`).
    pub fn car_mut(&mut self) -> &mut VirtualCar {
        &mut self.car
    }
}

/// Simulated time the car runs on a silent bus before its source reports idle (and its
/// clock), so the gateway's timers run on while no ECU transmits (during a flash, with
/// normal communication off).
pub const SILENCE_STEP_US: u64 = 5_000;

impl FrameSource for VirtualCarSource {
    fn poll(&mut self, _max_wait: Duration) -> Result<Poll, SourceError> {
        let silent_since = self.car.time_us();
        loop {
            if let Some(frame) = self.pending.pop_front() {
                return Ok(Poll::Frame(frame));
            }
            // With a person at the desk the car runs until the dashboard stops: the
            // scenario's duration only ends its timeline.
            if self.car.finished() && self.desk.is_none() {
                return Ok(Poll::End);
            }
            if self.car.time_us() >= silent_since + SILENCE_STEP_US {
                return Ok(Poll::Idle);
            }
            if let Some(desk) = &self.desk {
                desk.borrow_mut().apply(&mut self.car);
            }
            self.car.tick();
            if let Some(world) = &mut self.world {
                if self.car.time_us() >= self.next_world_us {
                    world(&self.car);
                    self.next_world_us = self.car.time_us() + WORLD_PERIOD_US;
                }
            }
            // Nothing here sums up stops: a person may drive the car for days.
            drop(self.car.take_brake_presses());
            // Taken, not copied: a long live run keeps no frames in the car.
            self.pending.extend(
                self.car
                    .take_log()
                    .iter()
                    .map(|f| LogFrame::from_can(f.t_us, 0, &f.frame)),
            );
        }
    }

    fn describe(&self) -> String {
        format!("virtual car ({})", self.car.scenario().name)
    }

    fn transmit(&mut self, frame: &Frame) -> Result<bool, SourceError> {
        Ok(self.car.inject(*frame))
    }

    fn clock_us(&self) -> Option<u64> {
        Some(self.car.time_us())
    }

    fn paused_for(&self) -> Duration {
        self.car.debugger_halted_for()
    }
}

/// A real-time transport (socketcand, SocketCAN) as a live source. Frames carry the bus
/// time the other end reports (socketcand's timestamps); without one, the time since the
/// source was opened on this host.
pub struct TransportSource {
    transport: Box<dyn Transport>,
    opened: Instant,
    /// The last frame's bus time and when it came, for the clock between frames.
    last: Option<(u64, Instant)>,
}

impl TransportSource {
    /// The source for an open transport.
    pub fn new(transport: Box<dyn Transport>) -> Self {
        Self {
            transport,
            opened: Instant::now(),
            last: None,
        }
    }
}

impl FrameSource for TransportSource {
    fn poll(&mut self, max_wait: Duration) -> Result<Poll, SourceError> {
        match self.transport.recv(max_wait) {
            // A frame of the gateway's own is on the bus: the queue has room again, which
            // the next transmit finds out for itself.
            Ok(Some(Incoming::Sent)) => Ok(Poll::Idle),
            Ok(Some(Incoming::Frame(frame, at))) => {
                let t_us = at.bus_us.unwrap_or_else(|| {
                    at.host.saturating_duration_since(self.opened).as_micros() as u64
                });
                self.last = Some((t_us, at.host));
                Ok(Poll::Frame(LogFrame::from_can(t_us, 0, &frame)))
            }
            Ok(None) => Ok(Poll::Idle),
            Err(TransportError::Closed(_)) => Ok(Poll::End),
            Err(error) => Err(SourceError {
                source: self.transport.describe(),
                message: error.to_string(),
            }),
        }
    }

    fn describe(&self) -> String {
        self.transport.describe()
    }

    fn clock_us(&self) -> Option<u64> {
        self.last
            .map(|(t_us, at)| t_us + at.elapsed().as_micros() as u64)
    }

    fn transmit(&mut self, frame: &Frame) -> Result<bool, SourceError> {
        self.transport.send(frame).map_err(|error| SourceError {
            source: self.transport.describe(),
            message: error.to_string(),
        })
    }
}

/// Frames a [`Transmitting`] source hands to the bus in a row, the observers refilling the
/// outbox between them, before it reads the bus again: a transfer's consecutive frames
/// follow each other as fast as the bus takes them (an ISO-TP sender hands out its next
/// frame only once the last is confirmed), and the bus is still read every so often.
pub const TX_BURST: usize = 64;

/// A live source that also sends what the gateway's tester queued, before each poll.
///
/// Having handed frames to the bus it reports an idle moment at once, without reading the
/// bus, so the tester (an observer, reached only through the pipeline) confirms them and
/// queues its next: up to [`TX_BURST`] frames, or until the bus refuses one (its controller
/// queue is full). Reading the bus between frames instead cost a 1 ms tick of the virtual
/// car per consecutive frame, or the pipeline's whole idle wait on a real bus that stays
/// silent while an ECU takes a download.
pub struct Transmitting<S: FrameSource = Box<dyn FrameSource>> {
    inner: S,
    outbox: Outbox,
    /// Frames handed over since the bus was last read.
    burst: usize,
}

impl<S: FrameSource> Transmitting<S> {
    /// `inner`, sending what `outbox` holds.
    pub fn new(inner: S, outbox: Outbox) -> Self {
        Self {
            inner,
            outbox,
            burst: 0,
        }
    }

    /// The source inside (the virtual car, for whoever drives it).
    pub fn inner_mut(&mut self) -> &mut S {
        &mut self.inner
    }
}

impl<S: FrameSource> FrameSource for Transmitting<S> {
    fn poll(&mut self, max_wait: Duration) -> Result<Poll, SourceError> {
        let mut refused = false;
        let mut sent = 0;
        while self.burst < TX_BURST {
            let Some(frame) = self.outbox.borrow_mut().pop_front() else {
                break;
            };
            if !self.inner.transmit(&frame)? {
                self.outbox.borrow_mut().push_front(frame);
                refused = true;
                break;
            }
            sent += 1;
            self.burst += 1;
        }
        if sent > 0 && !refused && self.burst < TX_BURST {
            return Ok(Poll::Idle);
        }
        self.burst = 0;
        self.inner.poll(max_wait)
    }

    fn describe(&self) -> String {
        self.inner.describe()
    }

    fn transmit(&mut self, frame: &Frame) -> Result<bool, SourceError> {
        self.inner.transmit(frame)
    }

    fn clock_us(&self) -> Option<u64> {
        self.inner.clock_us()
    }

    fn paused_for(&self) -> Duration {
        self.inner.paused_for()
    }
}

/// The dashboard's car: it stands until a person drives it.
pub const DASHBOARD_SCENARIO: &str = include_str!("../../../scenarios/dashboard.toml");

/// The `--bus` URL of `autoplug gateway`: the in-process virtual car, or a transport.
#[derive(Debug, Clone, PartialEq)]
pub enum BusUrl {
    /// `virtual`: the virtual car in this process, standing until a person drives it from
    /// the dashboard (`scenarios/dashboard.toml`, built into the program).
    Dashboard,
    /// `virtual:SCENARIO.toml`: the virtual car in this process, driven by a scenario file.
    Virtual(PathBuf),
    /// `socketcand://HOST:PORT/BUS` or `socketcan://IFACE`.
    Transport(Via),
    /// `log:FILE`: a recorded log, played with the dashboard's play, pause, speed and seek.
    Replay(PathBuf),
}

impl FromStr for BusUrl {
    type Err = String;

    fn from_str(url: &str) -> Result<Self, String> {
        if url == "virtual" {
            return Ok(BusUrl::Dashboard);
        }
        if let Some(path) = url.strip_prefix("log:") {
            if path.is_empty() {
                return Err(format!(
                    "invalid bus URL '{url}': name a log file, e.g. log:rec/drive.log"
                ));
            }
            return Ok(BusUrl::Replay(PathBuf::from(path)));
        }
        if let Some(path) = url.strip_prefix("virtual:") {
            if path.is_empty() {
                return Err(format!(
                    "invalid bus URL '{url}': name a scenario file, e.g. virtual:scenarios/drive-cycle.toml"
                ));
            }
            return Ok(BusUrl::Virtual(PathBuf::from(path)));
        }
        url.parse::<Via>().map(BusUrl::Transport).map_err(|e| {
            format!("{e}, or virtual:SCENARIO.toml for the virtual car in this process")
        })
    }
}

impl BusUrl {
    /// Opens the bus as a frame source; `speed` paces the virtual car (1 = real time,
    /// `None` = as fast as the machine goes).
    /// `desk`: a person may drive the virtual car (ignored for a real bus).
    /// `firmware`: ECUs of the virtual car that run as their firmware on emulated MCUs.
    /// `world`: takes the virtual car's world (ignored for a real bus).
    /// Gives the source, and the GDB servers' statuses of the ECUs debugged (`--gdb`).
    pub fn open(
        &self,
        speed: Option<f64>,
        desk: Option<Rc<RefCell<crate::driving::DriverDesk>>>,
        firmware: Option<&autoplug_virtual_car::firmware::FirmwareChoice>,
        world: Option<WorldSink>,
    ) -> Result<(Box<dyn FrameSource>, DebugPorts), String> {
        match self {
            BusUrl::Virtual(_) | BusUrl::Dashboard => {
                let scenario = match self {
                    BusUrl::Virtual(path) => Scenario::load(path).map_err(|e| e.to_string())?,
                    _ => Scenario::parse(DASHBOARD_SCENARIO, "scenarios/dashboard.toml")
                        .map_err(|e| e.to_string())?,
                };
                let car = match firmware {
                    Some(choice) => VirtualCar::with_firmware(&scenario, choice)?,
                    None => VirtualCar::new(&scenario),
                };
                let mut source = match desk {
                    Some(desk) => VirtualCarSource::with_desk(car, desk),
                    None => VirtualCarSource::new(car),
                };
                if let Some(world) = world {
                    source = source.with_world(world);
                }
                let debugged = source.car().debug_ports();
                Ok((
                    match speed {
                        Some(speed) => Box::new(Paced::new(source, speed)),
                        None => Box::new(source),
                    },
                    debugged,
                ))
            }
            BusUrl::Transport(via) => {
                let transport = autoplug_transport::open(via).map_err(|e| e.to_string())?;
                Ok((Box::new(TransportSource::new(transport)), Vec::new()))
            }
            BusUrl::Replay(path) => {
                let source = autoplug_gateway::LogSource::open(path).map_err(|e| e.to_string())?;
                Ok((
                    match speed {
                        Some(speed) => Box::new(Paced::new(source, speed)),
                        None => Box::new(source),
                    },
                    Vec::new(),
                ))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoplug_can::Node;
    use autoplug_gateway::{Pipeline, Strictness};
    use autoplug_image::{SigningKey, SoftwareVariant, Version};
    use autoplug_tester::bus_tester::{BusTester, JobOutcome, UserJob};
    use autoplug_tester::{FlashConfig, FlashJob, Phase, TesterConfig};
    use autoplug_virtual_car::diag::{build_image, FACTORY_PAYLOAD_LEN};
    use autoplug_virtual_car::scenario::Scenario;

    /// A bus that takes `accepts` frames, then refuses (its queue is full), and is silent.
    struct Silent {
        accepts: usize,
        taken: usize,
        polls: usize,
    }

    impl FrameSource for Silent {
        fn poll(&mut self, _max_wait: Duration) -> Result<Poll, SourceError> {
            self.polls += 1;
            Ok(Poll::Idle)
        }

        fn describe(&self) -> String {
            "a silent bus".into()
        }

        fn transmit(&mut self, _frame: &Frame) -> Result<bool, SourceError> {
            if self.taken == self.accepts {
                return Ok(false);
            }
            self.taken += 1;
            Ok(true)
        }
    }

    fn outbox_of(frames: usize) -> Outbox {
        let frame = Frame::new(0x70D, &[0x21; 8]).unwrap();
        Rc::new(RefCell::new((0..frames).map(|_| frame).collect()))
    }

    #[test]
    fn handed_frames_let_the_tester_refill_before_the_bus_is_read() {
        // Frames taken: an idle moment at once, the bus not read (on a silent real bus the
        // read would wait the pipeline's whole idle time for each frame).
        let outbox = outbox_of(3);
        let silent = Silent {
            accepts: usize::MAX,
            taken: 0,
            polls: 0,
        };
        let mut source = Transmitting::new(silent, Rc::clone(&outbox));
        assert!(matches!(source.poll(Duration::ZERO), Ok(Poll::Idle)));
        assert_eq!((source.inner.taken, source.inner.polls), (3, 0));
        // Nothing to send: the bus is read.
        assert!(matches!(source.poll(Duration::ZERO), Ok(Poll::Idle)));
        assert_eq!(source.inner.polls, 1);

        // A long queue: at most TX_BURST frames between two reads of the bus.
        let outbox = outbox_of(3 * TX_BURST);
        let silent = Silent {
            accepts: usize::MAX,
            taken: 0,
            polls: 0,
        };
        let mut source = Transmitting::new(silent, Rc::clone(&outbox));
        source.poll(Duration::ZERO).unwrap();
        assert_eq!((source.inner.taken, source.inner.polls), (TX_BURST, 1));
        source.poll(Duration::ZERO).unwrap();
        assert_eq!((source.inner.taken, source.inner.polls), (2 * TX_BURST, 2));

        // A full controller queue: the frame stays first in the outbox, the bus is read.
        let outbox = outbox_of(5);
        let silent = Silent {
            accepts: 2,
            taken: 0,
            polls: 0,
        };
        let mut source = Transmitting::new(silent, Rc::clone(&outbox));
        source.poll(Duration::ZERO).unwrap();
        assert_eq!((source.inner.taken, source.inner.polls), (2, 1));
        assert_eq!(outbox.borrow().len(), 3);
    }

    /// A live car runs as long as someone drives it: it keeps no record of the brake
    /// presses, which only a finished run's summary needs.
    #[test]
    fn a_live_car_keeps_no_brake_presses() {
        let scenario = autoplug_virtual_car::sweep::braking_scenario(1.0, 1.0, 50.0).unwrap();
        let mut source = VirtualCarSource::new(VirtualCar::new(&scenario));
        while source.car().time_us() < 500_000 {
            source.poll(Duration::ZERO).unwrap();
        }
        assert!(
            source.car().controls().held.brake > 0.0,
            "the brake is pressed"
        );
        assert!(source.car().brake_presses().is_empty());
    }

    /// The gateway's tester flashing the virtual car through the pipeline, as the dashboard
    /// and the fleet's agent do: the transfer runs near the bus's pace (in simulated time).
    /// When the source read the bus between consecutive frames, each one waited for the
    /// car's next 1 ms tick and the transfer ran at 3.5 kB/s.
    #[test]
    fn the_gateways_tester_keeps_the_bus_busy_during_a_download() {
        let scenario = Scenario::parse(DASHBOARD_SCENARIO, "dashboard").unwrap();
        let outbox: Outbox = Rc::default();
        let mut source = Transmitting::new(
            VirtualCarSource::new(VirtualCar::new(&scenario)),
            Rc::clone(&outbox),
        );
        let mut tester = BusTester::new(&[Node::Cruise], TesterConfig::DEFAULT, outbox, u64::MAX);
        let key = SigningKey::from_seed(autoplug_image::dev::SIGNING_SEED);
        let release = build_image(
            Node::Cruise,
            Version::new(1, 2, 0),
            SoftwareVariant::Standard,
            FACTORY_PAYLOAD_LEN,
            &key,
        );
        let job = FlashJob::new(FlashConfig::new(
            Node::Cruise,
            release,
            autoplug_tester::DEV_SECURITY_SECRET,
        ))
        .unwrap();
        let mut pipeline = Pipeline::new(Strictness::Strict);
        // A thousand polls of the pipeline, the tester its observer.
        let mut run = |source: &mut Transmitting<VirtualCarSource>, tester: &mut BusTester| {
            let mut polls = 0;
            pipeline
                .run(source, &mut [tester], &mut || {
                    polls += 1;
                    polls > 1000
                })
                .unwrap();
        };
        // The car wakes up and the tester reads the ECU's identification first.
        while source.inner.car().time_us() < 2_000_000 {
            run(&mut source, &mut tester);
        }
        tester.queue(UserJob::Flash(Box::new(job))).unwrap();
        let outcome = loop {
            run(&mut source, &mut tester);
            if let Some(outcome) = tester.take_outcome() {
                break outcome;
            }
            assert!(
                source.inner.car().time_us() < 60_000_000,
                "no outcome in a minute"
            );
        };
        let JobOutcome::Flash(Node::Cruise, Ok(report)) = outcome else {
            panic!("the flash failed: {outcome:?}");
        };
        let throughput = report.transfer_throughput().expect("a whole transfer");
        println!(
            "{report}: transfer {:.0} bytes/s over {} us",
            throughput,
            report.duration_us(Phase::Transfer).unwrap()
        );
        assert!(throughput > 20_000.0, "{throughput:.0} bytes/s");
    }
}
