//! The A/B update on an ECU that runs its firmware (issue 31): the cruise ECU's release
//! firmware and the bootloader on an emulated STM32F446, alone on a bit-timed bus with a
//! tester that downloads a signed release into it over UDS (the middleware's `FlashJob`).
//! The firmware writes the image into the slot it is not running, the bootloader checks the
//! signature and starts it on trial, the image confirms itself and raises the version
//! floor; an older release is then refused. And the power-cut sweep of
//! `shared/flash/tests/power_cut.rs`, here on the real code: one run per flash operation of
//! the update cuts the power at that operation (the flash's own, word by word as the chip
//! programs it); after power returns the board must start a complete image, the old or the
//! new one, and a download must then succeed.
//!
//! Ignored: they need the firmware built for the MCU and the demonstration's releases
//! (`cargo build --release --target thumbv7em-none-eabihf -p autoplug-boot -p ecu-cruise`,
//! `scripts/firmware-demo-images target/demo-images`); then `cargo test -p autoplug-live
//! --test firmware_update -- --ignored --nocapture` (CI does). The sweep cuts at every
//! operation outside the image's own words and at every `AUTOPLUG_CUT_STRIDE`-th word of the
//! image (default 512, the first and the last always); `AUTOPLUG_CUT_STRIDE=1` cuts at every
//! operation of the update.

use std::path::{Path, PathBuf};

use autoplug_can::Node;
use autoplug_ecu::Instant;
use autoplug_flash::ab::ImageSlot;
use autoplug_flash::sim::{FlashOp, SimFlash};
use autoplug_mcu::mcu::{Mcu, Stop};
use autoplug_mcu::node::{run_together, BusNode};
use autoplug_mcu::rtt::RttLog;
use autoplug_tester::{FlashConfig, FlashError, FlashJob, FlashReport, Job, DEV_SECURITY_SECRET};
use autoplug_virtual_bus::{AcceptanceFilter, BusConfig, NodeId, VirtualBus};
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
            panic!("{e} (build the firmware first: README, \"The virtual car on the firmware\")")
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
            let t_ns = self.bus.now_ns() + 1_000_000;
            let result = run_together(&mut self.bus, &mut self.board, t_ns).map_err(|(_, s)| s);
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
            let t_ns = self.bus.now_ns() + 1_000_000;
            if let Err((_, stop)) = run_together(&mut self.bus, &mut self.board, t_ns) {
                self.read_log();
                return Ended::Stopped(stop);
            }
            self.read_log();
            let now = Instant::from_micros(t_ns / 1000);
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
