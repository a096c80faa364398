//! The A/B update on an ECU that runs its firmware: the cruise ECU's release
//! firmware and the bootloader on an emulated STM32F446, alone on a bit-timed bus with a
//! tester that downloads a signed release into it over UDS (the middleware's `FlashJob`).
//! The firmware writes the image into the slot it is not running, the bootloader checks the
//! signature and starts it on trial, the image confirms itself and raises the version
//! floor; an older release is then refused. And the power-cut sweep of
//! `shared/flash/tests/power_cut.rs`, here on the real code: one run per flash operation of
//! the update cuts the power at that operation (the flash's own, word by word as the chip
//! programs it); after power returns the board must start a complete image, the old or the
//! new one, and a download must then succeed. And two of timing: the erase's 0x78 out
//! before the erase stalls the core whenever in the firmware's tick the request ends, and
//! the update on a bus 87 % busy with frames above the ECU's.
//!
//! Ignored: they need the firmware built for the MCU and the demonstration's releases
//! (`cargo build --profile firmware --target thumbv7em-none-eabihf -p autoplug-boot -p ecu-cruise`,
//! `scripts/firmware-demo-images target/demo-images`); then `cargo test -p autoplug-live
//! --test firmware_update -- --ignored --nocapture` (CI does). The sweep cuts at every
//! operation outside the image's own words and at every `AUTOPLUG_CUT_STRIDE`-th word of the
//! image (default 512, the first and the last always); `AUTOPLUG_CUT_STRIDE=1` cuts at every
//! operation of the update.

use std::path::{Path, PathBuf};

use autoplug_can::{Frame, Node};
use autoplug_ecu::Instant;
use autoplug_flash::ab::ImageSlot;
use autoplug_flash::sim::{FlashOp, SimFlash};
use autoplug_flash::{FLASH_BASE, FLASH_SIZE};
use autoplug_mcu::mcu::{Mcu, Stop};
use autoplug_mcu::node::{run_together, BusNode};
use autoplug_mcu::rtt::RttLog;
use autoplug_tester::{FlashConfig, FlashError, FlashJob, FlashReport, Job, DEV_SECURITY_SECRET};
use autoplug_virtual_bus::{AcceptanceFilter, BusConfig, NodeConfig, NodeId, VirtualBus};
use autoplug_virtual_car::firmware::{board_uid, load, DEFAULT_FIRMWARE_DIR};

const ECU: Node = Node::Cruise;
/// The seed of the flash's interrupted operations.
const FLASH_SEED: u64 = 0x31_F446;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn release(name: &str) -> Vec<u8> {
    let path = root().join("target/demo-images").join(name);
    std::fs::read(&path).unwrap_or_else(|e| {
        panic!(
            "{}: {e}: build the releases first (scripts/firmware-demo-images target/demo-images)",
            path.display()
        )
    })
}

/// The board on its bench: the bus, the MCU on it, a tester node, the MCU's log.
struct Bench {
    bus: VirtualBus,
    board: Vec<BusNode>,
    tester: NodeId,
    /// A node sending bursts of high-priority frames, how many a burst has, and when the
    /// next is due (ns).
    traffic: Option<(NodeId, usize, u64)>,
    logs: Vec<RttLog>,
    lines: Vec<String>,
}

/// How a job on the bench ended.
enum Ended<T> {
    /// It gave its result.
    Done(T),
    /// The MCU stopped (the power cut).
    Stopped(Stop),
}

impl Bench {
    /// A board as it leaves the line: programmed, started once, powered on again.
    fn factory() -> Self {
        let dir = root().join(DEFAULT_FIRMWARE_DIR);
        let (mcu, logs) = load(ECU, &dir, FLASH_SEED).unwrap_or_else(|e| {
            panic!("{e} (build the firmware first: docs/src/firmware-without-a-board.md)")
        });
        Self::on(mcu, logs)
    }

    fn on(mcu: Mcu, logs: Vec<RttLog>) -> Self {
        let mut bus = VirtualBus::new(BusConfig::default());
        let board = vec![BusNode::attach(&mut bus, ECU.name(), mcu)];
        let tester = bus.attach("tester", AcceptanceFilter::All);
        Self {
            bus,
            board,
            tester,
            traffic: None,
            logs,
            lines: Vec::new(),
        }
    }

    fn flash(&mut self) -> &mut SimFlash {
        &mut self.board[0].mcu.chip.flash
    }

    /// The power off and on again: the same flash (and log decoders) in a board that
    /// starts from its reset vector.
    fn power_cycle(mut self) -> Self {
        let flash = std::mem::replace(self.flash(), SimFlash::new(0));
        self.power_on_with(flash)
    }

    /// The board powered on again with `flash` in it (as another board left it).
    fn power_on_with(self, mut flash: SimFlash) -> Self {
        flash.restore_power();
        flash.cancel_cut();
        let mcu = Mcu::power_on(flash, board_uid(ECU)).expect("the board powers on");
        Self::on(mcu, self.logs)
    }

    /// From now on, every 10 ms a burst of `frames` 8-byte frames at 0x001, above every
    /// frame of the ECU's in priority: the other ECUs' periodic messages as they come on
    /// the car's bus, here heavier (30 frames are about 75 % of the bus).
    fn add_traffic(&mut self, frames: usize) {
        let node = self.bus.attach_with(
            "traffic",
            AcceptanceFilter::Ids(Vec::new()),
            NodeConfig {
                tx_queue_capacity: frames.max(1),
                ..NodeConfig::default()
            },
        );
        self.traffic = Some((node, frames, self.bus.now_ns()));
    }

    /// A millisecond of the bench: the traffic's burst if one is due, the bus and the MCU.
    fn step_ms(&mut self) -> Result<(), Stop> {
        let now_ns = self.bus.now_ns();
        if let Some((node, frames, next_ns)) = &mut self.traffic {
            if now_ns >= *next_ns {
                *next_ns += 10_000_000;
                let frame = Frame::new(0x001, &[0x55; 8]).unwrap();
                for _ in 0..*frames {
                    // A burst the bus has not carried yet waits: the node's queue is full.
                    let _ = self.bus.send(*node, frame, now_ns);
                }
            }
        }
        run_together(&mut self.bus, &mut self.board, now_ns + 1_000_000).map_err(|(_, s)| s)
    }

    /// Runs the board for `us` alone: the tester's requests then come at another moment of
    /// the firmware's own 1 ms diagnostic tick.
    fn shift(&mut self, us: u64) -> Result<(), Stop> {
        let t_ns = self.bus.now_ns() + us * 1000;
        run_together(&mut self.bus, &mut self.board, t_ns).map_err(|(_, s)| s)
    }

    fn read_log(&mut self) {
        for log in &mut self.logs {
            for line in log.poll(&mut self.board[0].mcu.chip) {
                self.lines.push(line.text);
            }
        }
    }

    /// Runs for `ms` with no tester. The log is read every millisecond, as a probe polls
    /// it: the bootloader's buffer is gone once the application has started.
    fn idle(&mut self, ms: u64) -> Result<(), Stop> {
        for _ in 0..ms {
            let result = self.step_ms();
            self.read_log();
            result?;
        }
        Ok(())
    }

    /// Runs `job` to its end (or the MCU's stop), a millisecond at a time, as the
    /// middleware's tester does on the virtual car.
    fn drive<J: Job>(&mut self, job: &mut J, limit_ms: u64) -> Ended<Result<J::Output, J::Error>> {
        let mut held = None;
        for _ in 0..limit_ms {
            if let Err(stop) = self.step_ms() {
                self.read_log();
                return Ended::Stopped(stop);
            }
            self.read_log();
            let now = Instant::from_micros(self.bus.now_ns() / 1000);
            while let Some(delivered) = self.bus.recv(self.tester) {
                job.on_frame(now, &delivered.frame);
            }
            job.poll(now);
            while let Some(frame) = held.take().or_else(|| job.poll_transmit(now)) {
                if self.bus.send(self.tester, frame, self.bus.now_ns()).is_ok() {
                    job.confirm_transmit(now);
                } else {
                    held = Some(frame);
                    break;
                }
            }
            if let Some(result) = job.take_result() {
                self.read_log();
                return Ended::Done(result);
            }
        }
        self.read_log();
        panic!(
            "the job did not end in {limit_ms} ms; the firmware's log:\n{}",
            self.lines.join("\n")
        );
    }

    /// Runs a download of `release` as [`Bench::drive`] does, except that its erase
    /// request goes out `delay_us` after the millisecond it was due at; ends at the erase's
    /// first answer (the 0x78), with how long after the request it came, or with the
    /// job's failure.
    fn erase_with_request_held(&mut self, release: &[u8], delay_us: u64) -> Result<u64, String> {
        let mut job = FlashJob::new(FlashConfig::new(ECU, release.to_vec(), DEV_SECURITY_SECRET))
            .expect("a release the job takes");
        let mut requested: Option<Instant> = None;
        let mut held = None;
        for _ in 0..10_000 {
            self.step_ms()
                .map_err(|stop| format!("the MCU stopped: {stop}"))?;
            let now = Instant::from_micros(self.bus.now_ns() / 1000);
            while let Some(delivered) = self.bus.recv(self.tester) {
                let data = delivered.frame.data();
                if let Some(at) = requested {
                    if data.get(1..4) == Some(&[0x7F, 0x31, 0x78][..]) {
                        return Ok(delivered.t_ns / 1000 - at.as_micros());
                    }
                }
                job.on_frame(now, &delivered.frame);
            }
            job.poll(now);
            while let Some(frame) = held.take().or_else(|| job.poll_transmit(now)) {
                let mut at = now;
                // The request's single frame, or its first frame (with the memory range
                // to erase it takes two).
                let data = frame.data();
                let service = match data.first().map(|pci| pci >> 4) {
                    Some(0) => data.get(1..5),
                    Some(1) => data.get(2..6),
                    _ => None,
                };
                if requested.is_none() && service == Some(&[0x31, 0x01, 0xFF, 0x00][..]) {
                    self.shift(delay_us)
                        .map_err(|stop| format!("the MCU stopped: {stop}"))?;
                    at = Instant::from_micros(self.bus.now_ns() / 1000);
                    requested = Some(at);
                }
                if self.bus.send(self.tester, frame, self.bus.now_ns()).is_ok() {
                    job.confirm_transmit(at);
                } else {
                    held = Some(frame);
                    break;
                }
            }
            if let Some(result) = job.take_result() {
                return Err(match result {
                    Ok(_) => "the download ended without a 0x78 for the erase".into(),
                    Err(e) => e.to_string(),
                });
            }
        }
        Err("no answer in 10 s".into())
    }

    /// Downloads `release` over UDS.
    fn download(&mut self, release: &[u8]) -> Ended<Result<FlashReport, Box<FlashError>>> {
        let mut job = FlashJob::new(FlashConfig::new(ECU, release.to_vec(), DEV_SECURITY_SECRET))
            .expect("a release the job takes");
        match self.drive(&mut job, 30_000) {
            Ended::Done(result) => Ended::Done(result.map_err(Box::new)),
            Ended::Stopped(stop) => Ended::Stopped(stop),
        }
    }

    /// What the board runs since its last start, from its log: the slot and the version
    /// line, once it reached its control loop.
    fn running(&self) -> Option<Running> {
        let start = self.lines.iter().rposition(|l| l.contains("boot: "))?;
        let since = &self.lines[start..];
        since.iter().find(|l| l.contains("control loop every"))?;
        if since
            .iter()
            .any(|l| l.contains("no image header in slot A"))
        {
            return Some(Running::Factory);
        }
        since.iter().find_map(|l| {
            let (_, rest) = l.split_once("running image AP-CRUISE-0001 from slot ")?;
            let slot = match rest.chars().next()? {
                'A' => ImageSlot::A,
                'B' => ImageSlot::B,
                _ => return None,
            };
            let version = rest.get(2..)?.split_whitespace().next()?.to_string();
            Some(Running::Release { slot, version })
        })
    }
}

#[derive(Clone, Debug, PartialEq, Eq)]
enum Running {
    /// The image the board was programmed with (no header: a probe wrote it).
    Factory,
    /// A release.
    Release { slot: ImageSlot, version: String },
}

fn done<T, E: std::fmt::Display>(ended: Ended<Result<T, E>>, what: &str) -> T {
    match ended {
        Ended::Done(Ok(value)) => value,
        Ended::Done(Err(e)) => panic!("{what} failed: {e}"),
        Ended::Stopped(stop) => panic!("{what}: the MCU stopped: {stop}"),
    }
}

#[test]
#[ignore = "needs the firmware and the releases: scripts/firmware-demo-images target/demo-images"]
fn an_update_starts_on_trial_confirms_itself_and_raises_the_version_floor() {
    let mut bench = Bench::factory();
    bench.idle(1000).unwrap();
    assert_eq!(
        bench.running(),
        Some(Running::Factory),
        "{:#?}",
        bench.lines
    );

    let report = done(bench.download(&release("cruise-1.2.0.img")), "1.2.0");
    assert_eq!(report.slot, Some(ImageSlot::B));
    bench.idle(1000).unwrap();
    let new = Running::Release {
        slot: ImageSlot::B,
        version: "1.2.0".into(),
    };
    assert_eq!(bench.running(), Some(new.clone()), "{:#?}", bench.lines);
    let log = bench.lines.join("\n");
    assert!(
        log.contains("boot: starting slot B on trial (new image)"),
        "{log}"
    );
    assert!(
        log.contains("self-test passed: this image is confirmed"),
        "{log}"
    );

    // Confirmed: the next start takes it without a trial.
    let mut bench = bench.power_cycle();
    bench.idle(1000).unwrap();
    assert_eq!(bench.running(), Some(new.clone()));
    assert!(bench
        .lines
        .iter()
        .any(|l| l.contains("boot: starting slot B") && !l.contains("trial")));
    assert!(bench
        .lines
        .iter()
        .any(|l| l.contains("from slot B 1.2.0 (variant 0), version floor 1.2.0")));

    // The floor: 1.1.0 is refused, and the ECU goes on running 1.2.0.
    let older = match bench.download(&release("cruise-1.1.0-faulty.img")) {
        Ended::Done(Err(e)) => e.to_string(),
        Ended::Done(Ok(report)) => panic!("1.1.0 went in below the floor: {report}"),
        Ended::Stopped(stop) => panic!("the MCU stopped: {stop}"),
    };
    println!("1.1.0 after 1.2.0: {older}");
    bench.idle(1000).unwrap();
    assert_eq!(bench.running(), Some(new));
}

/// The erase's 0x78 on the bus before the erase stalls the core, whenever in the
/// firmware's 1 ms diagnostic tick the request comes. The firmware's loop handled the
/// request, queued the 0x78 for its transmit task and, when the tick fell due meanwhile,
/// took the erase's first step at once: the transmit task had not run, and the 0x78 came a
/// second later, after the tester's P2 of 50 ms (CI saw it from the dashboard, whose paced
/// car lets the tester's requests come at any moment: "no response to 0x31 RoutineControl
/// within 50 ms"). Here the erase request is held back by 0 to 995 µs in steps of 5.
#[test]
#[ignore = "needs the firmware and the releases: scripts/firmware-demo-images target/demo-images"]
fn the_erase_is_announced_before_it_stalls_the_core_at_any_moment_of_the_tick() {
    let update = release("cruise-1.2.0.img");
    let mut bench = Bench::factory();
    bench.idle(1000).unwrap();
    let flash = bench.flash().clone();
    let mut late = Vec::new();
    let mut slowest_us = 0;
    for delay_us in (0..1000).step_by(5) {
        bench = bench.power_on_with(flash.clone());
        // The programming session needs the bus to have shown standstill for 0.5 s.
        bench.idle(600).unwrap();
        match bench.erase_with_request_held(&update, delay_us) {
            Ok(answer_us) => slowest_us = slowest_us.max(answer_us),
            Err(e) => late.push(format!("held {delay_us} us: {e}")),
        }
    }
    println!("the erase request at 200 moments of the tick: first answer within {slowest_us} us at worst");
    assert!(
        late.is_empty(),
        "{} of 200:\n{}",
        late.len(),
        late.join("\n")
    );
}

/// The update on a bus busy with frames of higher priority than the ECU's (its own
/// frames wait in its mailboxes; the 0x78 before each sector erase must still be out
/// before the erase stalls the core): through, and the new image running.
#[test]
#[ignore = "needs the firmware and the releases: scripts/firmware-demo-images target/demo-images"]
fn an_update_goes_through_on_a_busy_bus() {
    let mut bench = Bench::factory();
    bench.add_traffic(30);
    bench.idle(1000).unwrap();
    let report = done(
        bench.download(&release("cruise-1.2.0.img")),
        "1.2.0 on a busy bus",
    );
    println!("on a bus busy with bursts of 30 frames every 10 ms: {report}");
    bench.idle(1000).unwrap();
    let load = bench.bus.bus_stats().load;
    assert_eq!(
        bench.running(),
        Some(Running::Release {
            slot: ImageSlot::B,
            version: "1.2.0".into(),
        }),
        "{:#?}",
        bench.lines
    );
    println!("bus load over the run: {:.0} %", load * 100.0);
}

#[test]
#[ignore = "needs the firmware and the releases: scripts/firmware-demo-images target/demo-images"]
fn a_power_cut_at_any_flash_operation_of_an_update_leaves_a_complete_image() {
    let stride: usize = std::env::var("AUTOPLUG_CUT_STRIDE")
        .ok()
        .map(|s| s.parse().expect("AUTOPLUG_CUT_STRIDE: a whole number"))
        .unwrap_or(512)
        .max(1);
    let update = release("cruise-1.2.0.img");

    // The update without a cut, its flash operations traced: the download's, the
    // bootloader's trial mark, the image's confirmation and new floor.
    let mut bench = Bench::factory();
    bench.idle(1000).unwrap();
    bench.flash().record_trace(true);
    let first = bench.flash().operations();
    let reference = done(bench.download(&update), "the update");
    bench.idle(1000).unwrap();
    let ops: Vec<FlashOp> = bench.flash().trace().to_vec();
    assert_eq!(bench.flash().operations() - first, ops.len() as u64);
    let slot_b = ImageSlot::B.region();
    let in_image =
        |op: &FlashOp| matches!(op, FlashOp::Program { address, .. } if slot_b.contains(*address));
    let image_ops = ops.iter().filter(|op| in_image(op)).count();
    let mut cuts = Vec::new();
    let mut image_seen = 0;
    for (k, op) in ops.iter().enumerate() {
        if in_image(op) {
            if image_seen % stride == 0 || image_seen + 1 == image_ops {
                cuts.push(k);
            }
            image_seen += 1;
        } else {
            cuts.push(k);
        }
    }
    println!(
        "update of {} bytes into slot B: {} flash operations ({} erases, {} programs of the image's words, {} others); cutting at {}",
        reference.image_len,
        ops.len(),
        ops.iter().filter(|op| matches!(op, FlashOp::Erase { .. })).count(),
        image_ops,
        ops.len() - image_ops - ops.iter().filter(|op| matches!(op, FlashOp::Erase { .. })).count(),
        cuts.len()
    );

    let (mut old, mut new, mut retries) = (0, 0, 0);
    let mut bench = Bench::factory();
    let factory = bench.flash().clone();
    for (i, &k) in cuts.iter().enumerate() {
        bench = bench.power_on_with(factory.clone());
        // The programming session needs the bus to have shown standstill for 0.5 s.
        bench.idle(600).unwrap();
        bench.flash().cut_power_at(k as u64);
        match bench.download(&update) {
            Ended::Stopped(Stop::Flash(_)) => {}
            // The cut may fall after the download, in the bootloader's or the image's
            // own writes.
            Ended::Done(_) => match bench.idle(1000) {
                Err(Stop::Flash(_)) => {}
                other => panic!("cut at operation {k} ({}): not reached: {other:?}", ops[k]),
            },
            Ended::Stopped(stop) => panic!("cut at operation {k}: the MCU stopped: {stop}"),
        }
        assert!(!bench.flash().is_powered(), "cut at operation {k}");
        bench = bench.power_cycle();
        let lines_before = bench.lines.len();
        bench.idle(600).unwrap_or_else(|stop| {
            panic!(
                "cut at operation {k} ({}): after power returned the MCU stopped: {stop}",
                ops[k]
            )
        });
        let running = bench.running();
        match &running {
            Some(Running::Factory) => old += 1,
            Some(Running::Release {
                slot: ImageSlot::B,
                version,
            }) if version == "1.2.0" => new += 1,
            other => panic!(
                "cut at operation {k} ({}): a brick: it runs {other:?}; its log:\n{}",
                ops[k],
                bench.lines[lines_before..].join("\n")
            ),
        }
        // Consistent: from here an update goes in (a download after every cut outside
        // the image's words, after every fourth inside), or is in already.
        if running == Some(Running::Factory) && (!in_image(&ops[k]) || i % 4 == 0) {
            done(bench.download(&update), "the retry");
            bench.idle(600).unwrap();
            assert_eq!(
                bench.running(),
                Some(Running::Release {
                    slot: ImageSlot::B,
                    version: "1.2.0".into()
                }),
                "cut at operation {k} ({}): after the retry",
                ops[k]
            );
            retries += 1;
        }
        bench.lines.clear();
    }
    println!(
        "firmware A/B power-cut sweep: {} cuts, 0 bricks; after the cut the board ran the old image {old} times, the new one {new} times; {retries} downloads after a cut, all in",
        cuts.len()
    );
}

/// The whole flash as a tester reads it back.
fn image_of(flash: &SimFlash) -> Vec<u8> {
    let mut bytes = vec![0; FLASH_SIZE as usize];
    flash.read(FLASH_BASE, &mut bytes).expect("the flash reads");
    bytes
}

/// A power cut at every one of the update's flash operations in turn, each board then
/// powered on: it must start a complete image, the old or the new one. The update runs once,
/// its operations traced; the flash as a cut at operation k leaves it is then rebuilt from
/// the factory flash by replaying operations 0..k and cutting the power in operation k
/// (what an interrupted erase or program leaves is the simulated flash's own, as in the run
/// above), which takes milliseconds where rerunning the download takes most of a second.
/// The bytes of each program come from the updated flash: the trace programs no byte twice
/// (checked), and replaying all of it gives the updated flash byte for byte (checked). A
/// download must go in after every cut outside the image's words and after every
/// `AUTOPLUG_RETRY_STRIDE`-th inside (default 512). On demand (14,789 cuts): `cargo test -p
/// autoplug-live --test firmware_update -- --ignored --nocapture every_flash_operation`;
/// `AUTOPLUG_CUT_STRIDE=N` cuts at every N-th operation only.
#[test]
#[ignore = "on demand (minutes): needs the firmware and the releases (scripts/firmware-demo-images target/demo-images)"]
fn every_flash_operation_of_an_update_cut_in_turn_leaves_a_board_that_starts_a_complete_image() {
    let env = |name: &str, default: usize| -> usize {
        std::env::var(name)
            .ok()
            .map(|s| {
                s.parse()
                    .unwrap_or_else(|_| panic!("{name}: a whole number"))
            })
            .unwrap_or(default)
            .max(1)
    };
    let (cut_stride, retry_stride) = (
        env("AUTOPLUG_CUT_STRIDE", 1),
        env("AUTOPLUG_RETRY_STRIDE", 512),
    );
    let update = release("cruise-1.2.0.img");
    let started = std::time::Instant::now();

    let mut bench = Bench::factory();
    bench.idle(1000).unwrap();
    let factory = bench.flash().clone();
    bench.flash().record_trace(true);
    done(bench.download(&update), "the update");
    bench.idle(1000).unwrap();
    let ops: Vec<FlashOp> = bench.flash().trace().to_vec();
    bench.flash().record_trace(false);
    let updated = bench.flash().clone();

    // No byte programmed twice between erases of its sector: each program's bytes are the
    // updated flash's.
    let mut programmed = vec![false; FLASH_SIZE as usize];
    for (k, op) in ops.iter().enumerate() {
        match *op {
            FlashOp::Erase { sector } => {
                let from = (sector.start - FLASH_BASE) as usize;
                programmed[from..from + sector.size as usize].fill(false);
            }
            FlashOp::Program { address, len } => {
                let from = (address - FLASH_BASE) as usize;
                for byte in &mut programmed[from..from + len as usize] {
                    assert!(!*byte, "operation {k} ({op}) programs a byte again");
                    *byte = true;
                }
            }
        }
    }
    let apply = |flash: &mut SimFlash, op: &FlashOp| match *op {
        FlashOp::Erase { sector } => flash.erase_sector(sector.index),
        FlashOp::Program { address, len } => {
            let mut data = vec![0; len as usize];
            updated
                .read(address, &mut data)
                .expect("the updated flash reads");
            flash.program(address, &data)
        }
    };
    let mut before = factory.clone();
    for op in &ops {
        apply(&mut before, op).expect("the replay programs as the run did");
    }
    assert!(
        image_of(&before) == image_of(&updated),
        "the replay gives the updated flash"
    );

    let in_image = |op: &FlashOp| matches!(op, FlashOp::Program { address, .. } if ImageSlot::B.region().contains(*address));
    let (mut cuts, mut old, mut new, mut retries, mut image_seen) = (0, 0, 0, 0, 0);
    let mut before = factory;
    for (k, op) in ops.iter().enumerate() {
        let image_op = in_image(op);
        if k % cut_stride == 0 || k + 1 == ops.len() {
            cuts += 1;
            let mut flash = before.clone();
            flash.cut_power_at(0);
            assert!(
                apply(&mut flash, op).is_err(),
                "cut at operation {k} ({op}): not cut"
            );
            assert!(!flash.is_powered());
            bench = bench.power_on_with(flash);
            // To the control loop (a repair after the cut may erase a sector first).
            let mut ran_ms = 0;
            while ran_ms < 200 || (bench.running().is_none() && ran_ms < 1500) {
                bench.idle(50).unwrap_or_else(|stop| {
                    panic!(
                        "cut at operation {k} ({op}): after power returned the MCU stopped: {stop}"
                    )
                });
                ran_ms += 50;
            }
            let running = bench.running();
            match &running {
                Some(Running::Factory) => old += 1,
                Some(Running::Release {
                    slot: ImageSlot::B,
                    version,
                }) if version == "1.2.0" => new += 1,
                other => panic!(
                    "cut at operation {k} ({op}): a brick: it runs {other:?}; its log:\n{}",
                    bench.lines.join("\n")
                ),
            }
            if running == Some(Running::Factory) && (!image_op || image_seen % retry_stride == 0) {
                bench.idle(400).unwrap();
                done(bench.download(&update), "the retry");
                bench.idle(600).unwrap();
                assert_eq!(
                    bench.running(),
                    Some(Running::Release {
                        slot: ImageSlot::B,
                        version: "1.2.0".into()
                    }),
                    "cut at operation {k} ({op}): after the retry"
                );
                retries += 1;
            }
            bench.lines.clear();
        }
        if image_op {
            image_seen += 1;
        }
        apply(&mut before, op).expect("the replay programs as the run did");
    }
    println!(
        "firmware A/B power-cut sweep, replayed: {} flash operations, cut at {cuts}, 0 bricks; after the cut the board ran the old image {old} times, the new one {new} times; {retries} downloads after a cut, all in; {:.0} s",
        ops.len(),
        started.elapsed().as_secs_f64()
    );
}

/// The virtual car's demonstration image of the cruise ECU: signed with the development
/// key, for the right ECU and board, linked for slot B, but with no machine code inside.
fn host_logic_image() -> Vec<u8> {
    let key = autoplug_image::SigningKey::from_seed(autoplug_image::dev::SIGNING_SEED);
    autoplug_virtual_car::diag::build_slot_image(
        ECU,
        ImageSlot::B,
        autoplug_image::Version::new(1, 1, 0),
        autoplug_image::SoftwareVariant::Faulty,
        autoplug_virtual_car::diag::FACTORY_PAYLOAD_LEN,
        &key,
    )
}

/// The dashboard's demonstration image for the virtual car, flashed into the ECU running
/// its firmware: refused at its header, with the reason, and the ECU runs on as it was.
#[test]
#[ignore = "needs the firmware and the releases: scripts/firmware-demo-images target/demo-images"]
fn an_image_without_machine_code_is_refused_by_the_firmware() {
    let mut bench = Bench::factory();
    bench.idle(1000).unwrap();
    let refused = match bench.download(&host_logic_image()) {
        Ended::Done(Err(e)) => e.to_string(),
        Ended::Done(Ok(report)) => panic!("the firmware took an image without code: {report}"),
        Ended::Stopped(stop) => panic!("the MCU stopped: {stop}"),
    };
    println!("the virtual car's image into the firmware: {refused}");
    assert!(refused.contains("no machine code"), "{refused}");
    assert!(refused.contains("phase 'transfer'"), "{refused}");
    bench.idle(1000).unwrap();
    assert_eq!(
        bench.running(),
        Some(Running::Factory),
        "{:#?}",
        bench.lines
    );
}

/// Forced past every check (written into slot B and marked for a trial as a download
/// would, without the ECU's checks), the image's bytes start and the core locks up; the
/// independent watchdog the bootloader started resets the chip within its timeout, and the
/// bootloader goes back to the confirmed image.
#[test]
#[ignore = "needs the firmware and the releases: scripts/firmware-demo-images target/demo-images"]
fn a_trial_image_that_locks_up_is_reverted_by_the_watchdog() {
    use std::cell::RefCell;

    let mut bench = Bench::factory();
    bench.idle(1000).unwrap();
    let image = host_logic_image();
    let cell = RefCell::new(bench.flash().clone());
    {
        let mut flash = cell.borrow_mut();
        let slot = ImageSlot::B.region();
        flash.erase(slot.start, slot.start + slot.size).unwrap();
        let mut padded = image.clone();
        padded.resize(image.len().next_multiple_of(4), 0xFF);
        flash.program(slot.start, &padded).unwrap();
    }
    {
        let mut twin = autoplug_flash::sim::state_twin(&cell).unwrap();
        autoplug_flash::ab::mark_trial(&mut twin, ImageSlot::A, ImageSlot::B).unwrap();
    }
    let mut bench = bench.power_on_with(cell.into_inner());
    bench.idle(6000).unwrap();
    let mcu = &bench.board[0].mcu;
    let log = bench.lines.join("\n");
    println!("{log}");
    assert!(
        log.contains("boot: starting slot B on trial (new image)"),
        "{log}"
    );
    let (locked_at, halt) = mcu.lockups.first().cloned().unwrap_or_else(|| {
        panic!(
            "no lockup; resets {:?}, faults {:?}\n{log}",
            mcu.resets, mcu.faults
        )
    });
    let (reset_at, _) = *mcu
        .resets
        .iter()
        .find(|(_, cause)| *cause == autoplug_mcu::chip::rcc::ResetCause::Watchdog)
        .unwrap_or_else(|| panic!("no watchdog reset after {halt:?}\n{log}"));
    println!(
        "trial image locked up at {:.3} s ({halt:?}), the watchdog reset the chip at {:.3} s",
        locked_at as f64 / 1e9,
        reset_at as f64 / 1e9
    );
    // The bootloader's watchdog timeout (4 s) bounds the time from the start to the reset.
    assert!(
        reset_at - locked_at <= 4_000_000_000,
        "{locked_at} → {reset_at}"
    );
    assert!(
        log.contains("boot: the image on trial did not confirm itself: back to slot A"),
        "{log}"
    );
    assert_eq!(bench.running(), Some(Running::Factory), "{log}");
}
