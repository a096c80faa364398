//! Flashing the virtual car while it runs in real time, as a user does: the command-line
//! flasher over socketcand against the car's server, and the tester against a transport
//! with a SocketCAN interface's limits (at most 10 frames queued, each confirmed only once
//! the bit-timed 500 kbit/s bus has carried it). The wall clock runs the tester's P2 in
//! both: a transfer that piles its frames up in a queue times out.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant as WallInstant};

use autoplug_can::{Frame, Node};
use autoplug_image::{SigningKey, SoftwareVariant, Version};
use autoplug_tester::driver;
use autoplug_tester::{FlashConfig, FlashJob, IdentJob, TesterConfig};
use autoplug_transport::{Incoming, Timestamp, Transport, TransportError};
use autoplug_uds::DEV_SECURITY_SECRET;
use autoplug_virtual_car::car::{LoggedFrame, VirtualCar};
use autoplug_virtual_car::diag::{build_image, FACTORY_PAYLOAD_LEN};
use autoplug_virtual_car::scenario::Scenario;
use autoplug_virtual_car::socketcand::{CarBridge, SocketcandServer};

/// The version flashed: newer than the car's factory software (1.0.0).
const NEW_VERSION: Version = Version::new(1, 2, 0);

fn workshop() -> Scenario {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/workshop.toml");
    Scenario::load(&path).expect("the workshop scenario")
}

fn cruise_release() -> Vec<u8> {
    let key = SigningKey::from_seed(autoplug_image::dev::SIGNING_SEED);
    build_image(
        Node::Cruise,
        NEW_VERSION,
        SoftwareVariant::Standard,
        FACTORY_PAYLOAD_LEN,
        &key,
    )
}

/// The virtual car's bus as a transport with a SocketCAN interface's limits: at most
/// [`PacedCar::WINDOW`] frames queued, each confirmed only once the bus has carried it. The
/// car runs in real time: each call catches its simulated time up with the wall clock.
struct PacedCar {
    car: VirtualCar,
    epoch: WallInstant,
    log: Vec<LoggedFrame>,
    /// Frames taken and not on the bus yet.
    queued: VecDeque<Frame>,
    incoming: VecDeque<Incoming>,
    /// The most frames that were queued at once, and how often the queue refused one.
    most_queued: usize,
    refused: u64,
}

impl PacedCar {
    const WINDOW: usize = 10;

    fn new() -> Self {
        let mut car = VirtualCar::new(&workshop());
        car.capture_external_rx(false);
        Self {
            car,
            epoch: WallInstant::now(),
            log: Vec::new(),
            queued: VecDeque::new(),
            incoming: VecDeque::new(),
            most_queued: 0,
            refused: 0,
        }
    }

    /// Runs the car up to the wall clock's time.
    fn catch_up(&mut self) {
        let target_us = self.epoch.elapsed().as_micros() as u64;
        while self.car.time_us() < target_us {
            self.car.tick();
            self.car.swap_log(&mut self.log);
            for entry in &self.log {
                if entry.sender.is_none() {
                    if let Some(i) = self.queued.iter().position(|f| *f == entry.frame) {
                        self.queued.remove(i);
                        self.incoming.push_back(Incoming::Sent);
                    }
                } else {
                    let at = Timestamp {
                        host: WallInstant::now(),
                        bus_us: Some(entry.t_us),
                    };
                    self.incoming.push_back(Incoming::Frame(entry.frame, at));
                }
            }
        }
    }
}

impl Transport for PacedCar {
    fn send(&mut self, frame: &Frame) -> Result<bool, TransportError> {
        self.catch_up();
        if self.queued.len() >= Self::WINDOW || !self.car.inject(*frame) {
            self.refused += 1;
            return Ok(false);
        }
        self.queued.push_back(*frame);
        self.most_queued = self.most_queued.max(self.queued.len());
        Ok(true)
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<Incoming>, TransportError> {
        let deadline = WallInstant::now() + timeout;
        loop {
            self.catch_up();
            if let Some(incoming) = self.incoming.pop_front() {
                return Ok(Some(incoming));
            }
            let now = WallInstant::now();
            if now >= deadline {
                return Ok(None);
            }
            thread::sleep((deadline - now).min(Duration::from_micros(200)));
        }
    }

    fn describe(&self) -> String {
        "the virtual car's bus, 10 frames queued at most".into()
    }

    fn transmit_window(&self) -> usize {
        Self::WINDOW
    }

    fn network_delay(&self) -> Duration {
        // Confirmations and frames come straight from the bus.
        Duration::ZERO
    }
}

#[test]
fn a_transfer_goes_at_the_pace_of_a_bus_that_confirms_what_it_sent() {
    let mut bus = PacedCar::new();
    // Straight after the car started: the ECU has not seen it stand for 500 ms yet.
    let mut job = FlashJob::new(FlashConfig::new(
        Node::Cruise,
        cruise_release(),
        DEV_SECURITY_SECRET,
    ))
    .unwrap();
    let report = driver::run(&mut bus, &mut job).unwrap_or_else(|e| panic!("{e}"));
    println!("{report}");
    println!(
        "most frames queued: {}, refused offers: {}",
        bus.most_queued, bus.refused
    );
    assert!(
        report
            .notes
            .iter()
            .any(|n| n.contains("until it saw the car stand")),
        "the tester waited for the standstill: {:?}",
        report.notes
    );
    assert!(
        !report.notes.iter().any(|n| n.contains("sent again")),
        "every block answered in time: {:?}",
        report.notes
    );
    // The tester kept the queue full, never beyond it.
    assert_eq!(bus.most_queued, PacedCar::WINDOW);
    let rate = report.transfer_throughput().expect("the whole image went");
    assert!(rate > 10_000.0, "{rate} bytes/s");

    let mut ids = IdentJob::new(&[Node::Cruise], TesterConfig::default());
    let rows = driver::run(&mut bus, &mut ids).unwrap();
    assert_eq!(
        rows[0].software_version.as_deref(),
        Ok(NEW_VERSION.to_string().as_bytes())
    );
}

/// The virtual car in real time behind a socketcand server, on a thread, as
/// `virtual-car run scenarios/workshop.toml --realtime --socketcand ADDRESS` runs it.
struct RealTimeCar {
    port: u16,
    stop: Arc<AtomicBool>,
    thread: Option<thread::JoinHandle<()>>,
}

impl RealTimeCar {
    fn start() -> Self {
        let server = SocketcandServer::start("127.0.0.1:0").unwrap();
        let port = server.address().port();
        let stop = Arc::new(AtomicBool::new(false));
        let thread = {
            let stop = Arc::clone(&stop);
            thread::spawn(move || {
                let mut car = VirtualCar::new(&workshop());
                let mut bridge = CarBridge::new();
                let mut frames = Vec::new();
                let epoch = WallInstant::now();
                while !stop.load(Ordering::Acquire) {
                    car.tick();
                    car.swap_log(&mut frames);
                    bridge.exchange(&server, &mut car, &frames);
                    // Paced as the virtual-car command paces --realtime: every 10 ms of
                    // simulated time, it waits for the wall clock.
                    if car.time_us() % 10_000 == 0 {
                        let target = Duration::from_micros(car.time_us());
                        if let Some(wait) = target.checked_sub(epoch.elapsed()) {
                            thread::sleep(wait);
                        }
                    }
                }
            })
        };
        Self {
            port,
            stop,
            thread: Some(thread),
        }
    }

    fn url(&self) -> String {
        format!("socketcand://127.0.0.1:{}/can0", self.port)
    }
}

impl Drop for RealTimeCar {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

fn autoplug(args: &[&str]) -> (bool, String, String) {
    let output = Command::new(env!("CARGO_BIN_EXE_autoplug"))
        .args(args)
        .output()
        .expect("the autoplug binary runs");
    (
        output.status.success(),
        String::from_utf8_lossy(&output.stdout).into_owned(),
        String::from_utf8_lossy(&output.stderr).into_owned(),
    )
}

fn temp_file(name: &str, bytes: &[u8]) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).unwrap();
    (dir, path)
}

#[test]
fn autoplug_flash_over_socketcand_flashes_the_real_time_car() {
    let car = RealTimeCar::start();
    let url = car.url();
    let (_dir, image) = temp_file("cruise-1.2.0.img", &cruise_release());
    // The default timing, as a user runs it.
    let (ok, out, err) = autoplug(&[
        "flash",
        "--via",
        &url,
        "--ecu",
        "cruise",
        "--image",
        image.to_str().unwrap(),
    ]);
    println!("{out}{err}");
    assert!(ok, "the flash failed:\n{out}\n{err}");
    assert!(
        out.contains("done: cruise (0x0D) runs the new image"),
        "{out}"
    );
    assert!(!out.contains("sent again"), "{out}");

    let (ok, out, err) = autoplug(&["ids", "--via", &url, "--ecu", "cruise"]);
    assert!(ok, "{out}\n{err}");
    assert!(out.contains(&NEW_VERSION.to_string()), "{out}");
}
