//! A simulated AutoPlug bus for the tester's tests (feature `testing`; the tests of this
//! crate and of the `autoplug` command use it): the nine ECUs' diagnostic stacks
//! (`autoplug_uds::DiagNode`) on backends with an in-memory DFU slot (each ECU runs slot A,
//! so downloads go to slot B), one classic CAN
//! bus with arbitration and frame times at 500 kbit/s, and simulated time. Deterministic:
//! no clock, no threads, fixed seeds.
//!
//! The ECU backends charge the F446's flash times (1 s per 128 KiB sector erase, 16 µs per
//! programmed word) as time during which the ECU is stalled (frames queue in its receive
//! FIFO), as the real core stalls on a flash operation; they are polled every millisecond,
//! as the virtual car polls them; an ECU that resets is silent for a boot time, then comes
//! back with a fresh stack and its flash as it was.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::thread;
use std::time::{Duration, Instant as WallInstant};

use crate::names::ECUS;
use crate::Job;
use crate::DEV_SECURITY_SECRET;
use autoplug_can::{Frame, Node, VehicleSpeedMsg};
use autoplug_ecu::{Dtcs, Instant};
use autoplug_image::{
    BootState, Expectations, ImageBuilder, ImageSlot, PartNumber, SigningKey, Version,
    NUCLEO_F446RE,
};
use autoplug_uds::{Backend, DiagNode, FlashError, Identification, STANDSTILL_WINDOW_US};
use autoplug_virtual_car::socketcand::SocketcandServer;

/// The seed of the key every simulated ECU trusts.
pub const SIGNING_SEED: [u8; 32] = [7; 32];
/// The F446's DFU slot (the image slot not running): one 128 KiB sector.
pub const DFU_LEN: usize = 128 * 1024;
const SECTOR_LEN: usize = 128 * 1024;
/// An image slot, the largest image.
pub const SLOT_LEN: u32 = 128 * 1024;
/// The slot the simulated ECUs run; downloads go to the other.
pub const RUNNING_SLOT: ImageSlot = ImageSlot::A;
/// DS10693 typical times.
const SECTOR_ERASE_US: u64 = 1_000_000;
const WORD_PROGRAM_US: u64 = 16;
/// How long an ECU takes from its reset to answering again (the bootloader's boot record
/// and the application's start).
pub const DEFAULT_BOOT_US: u64 = 20_000;

/// An ECU's backend: identification, vehicle speed, DTCs, an in-memory DFU partition.
pub struct MemEcu {
    pub node: Node,
    pub number: u8,
    pub dfu: Vec<u8>,
    pub speed: Option<f32>,
    pub marked: bool,
    pub erases: u32,
    dtcs: Dtcs,
    random: u32,
    part_number: Vec<u8>,
    serial_number: Vec<u8>,
    public_key: [u8; 32],
    /// Flash busy time not yet charged by the bus.
    stall_us: u64,
    /// Wrong SecurityAccess keys in a row, as the ECU's flash keeps them.
    key_failures: u8,
}

impl MemEcu {
    pub fn new(node: Node) -> Self {
        let number = node.diag_node_number().expect("an ECU");
        Self {
            node,
            number,
            dfu: vec![0x00; DFU_LEN],
            speed: Some(0.0),
            marked: false,
            erases: 0,
            dtcs: Dtcs::new(),
            random: 0x1234_5678 ^ u32::from(number),
            part_number: format!("AP-{}-0001", node.name().to_ascii_uppercase()).into_bytes(),
            serial_number: format!("{number:02X}0000000042").into_bytes(),
            public_key: SigningKey::from_seed(SIGNING_SEED).public_key(),
            stall_us: 0,
            key_failures: 0,
        }
    }
}

impl Backend for MemEcu {
    fn identification(&self) -> Identification<'_> {
        Identification {
            part_number: &self.part_number,
            software_version: b"1.2.0",
            serial_number: &self.serial_number,
            hardware_version: b"NUCLEO-F446RE",
            vin: b"JA3AP47H0YF000042",
            boot_slot: Some((RUNNING_SLOT, BootState::Confirmed)),
        }
    }

    fn dtcs(&mut self) -> &mut Dtcs {
        &mut self.dtcs
    }

    fn fill_random(&mut self, out: &mut [u8]) {
        // xorshift32: fixed seed per ECU, so every run draws the same seeds.
        for byte in out {
            self.random ^= self.random << 13;
            self.random ^= self.random >> 17;
            self.random ^= self.random << 5;
            *byte = self.random as u8;
        }
    }

    fn stored_key_failures(&mut self) -> u8 {
        self.key_failures
    }

    fn store_key_failures(&mut self, failures: u8) -> Result<(), FlashError> {
        self.key_failures = failures;
        Ok(())
    }

    fn image_expectations(&self) -> Expectations {
        Expectations {
            node: self.number,
            hardware_id: NUCLEO_F446RE,
            version_floor: Version::new(1, 0, 0),
            max_image_len: SLOT_LEN,
            load_address: RUNNING_SLOT.other().vector_table(),
            runs_machine_code: true,
        }
    }

    fn public_key(&self) -> [u8; 32] {
        self.public_key
    }

    fn dfu_erase_steps(&self, len: u32) -> u32 {
        (len as usize).min(DFU_LEN).div_ceil(SECTOR_LEN) as u32
    }

    fn dfu_erase(&mut self, step: u32) -> Result<(), FlashError> {
        let start = step as usize * SECTOR_LEN;
        self.dfu
            .get_mut(start..start + SECTOR_LEN)
            .ok_or(FlashError)?
            .fill(0xFF);
        self.erases += 1;
        self.stall_us += SECTOR_ERASE_US;
        Ok(())
    }

    fn dfu_write(&mut self, offset: u32, data: &[u8]) -> Result<(), FlashError> {
        let start = offset as usize;
        let cells = self
            .dfu
            .get_mut(start..start + data.len())
            .ok_or(FlashError)?;
        if cells.iter().any(|&b| b != 0xFF) {
            return Err(FlashError); // NOR flash: only erased cells can be programmed
        }
        cells.copy_from_slice(data);
        self.stall_us += data.len().div_ceil(4) as u64 * WORD_PROGRAM_US;
        Ok(())
    }

    fn dfu_read(&mut self, offset: u32, out: &mut [u8]) -> Result<(), FlashError> {
        let start = offset as usize;
        out.copy_from_slice(self.dfu.get(start..start + out.len()).ok_or(FlashError)?);
        Ok(())
    }

    fn mark_updated(&mut self) -> Result<(), FlashError> {
        self.marked = true;
        Ok(())
    }
}

/// One ECU on the bus.
pub struct SimEcu {
    pub backend: MemEcu,
    /// `None` while it boots after a reset.
    pub diag: Option<DiagNode>,
    busy_until: Instant,
    rx: VecDeque<Frame>,
    tx: Option<Frame>,
    reboot_at: Option<Instant>,
    /// Resets performed.
    pub resets: u32,
    /// Whether its normal communication / DTC setting was ever switched off.
    pub saw_comm_off: bool,
    pub saw_dtc_off: bool,
    /// Set to make it ignore every frame (an ECU that is not there).
    pub absent: bool,
}

impl SimEcu {
    fn new(node: Node) -> Self {
        Self {
            backend: MemEcu::new(node),
            diag: DiagNode::new(node, DEV_SECURITY_SECRET, Instant::ZERO),
            busy_until: Instant::ZERO,
            rx: VecDeque::new(),
            tx: None,
            reboot_at: None,
            resets: 0,
            saw_comm_off: false,
            saw_dtc_off: false,
            absent: false,
        }
    }

    pub fn node(&self) -> Node {
        self.backend.node
    }

    /// Charges the flash time the last call used.
    fn charge_stall(&mut self, now: Instant) {
        let stall = std::mem::take(&mut self.backend.stall_us);
        if stall > 0 {
            self.busy_until = self.busy_until.max(now).plus_micros(stall);
        }
    }

    fn running(&self) -> bool {
        self.diag.is_some() && !self.absent
    }
}

/// The vehicle speed the car broadcasts (VehicleSpeedMsg), as every ECU hears it (these
/// test buses carry only the diagnostic traffic); `None`: nobody sends it.
pub fn hear_vehicle_speed(diag: &mut DiagNode, now: Instant, kmh: Option<f32>) {
    if let Some(kmh) = kmh {
        let data = VehicleSpeedMsg { vehicle_speed: kmh }.encode();
        let frame = Frame::new(u32::from(VehicleSpeedMsg::ID), &data).expect("a catalogue frame");
        diag.observe(now, &frame);
    }
}

/// `us` of a standing car's VehicleSpeedMsg, every 10 ms from time zero: the ECU has seen
/// the car standing long enough to allow programming (the caller's clock goes on from `us`).
pub fn stood_for(diag: &mut DiagNode, us: u64) {
    let frame = Frame::new(
        u32::from(VehicleSpeedMsg::ID),
        &VehicleSpeedMsg { vehicle_speed: 0.0 }.encode(),
    )
    .expect("a catalogue frame");
    for t in (0..=us).step_by(10_000) {
        diag.observe(Instant::from_micros(t), &frame);
    }
}

/// Who sent a frame.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Sender {
    Tester,
    Ecu(usize),
}

/// The time a classic CAN data frame with an 11-bit identifier takes at 500 kbit/s: 47
/// bits of frame, 8 per data byte, about one stuff bit in ten, 2 µs a bit.
pub fn frame_time_us(frame: &Frame) -> u64 {
    let bits = 47 + 8 * frame.len() as u64;
    let stuffing = (34 + 8 * frame.len() as u64) / 10;
    (bits + stuffing) * 2
}

/// A frame the test drops (e.g. a lost response); returns whether to drop it.
pub type DropRule = Box<dyn FnMut(&Frame) -> bool>;

/// The simulated bus.
pub struct SimBus {
    pub now: Instant,
    pub ecus: Vec<SimEcu>,
    tester_tx: Option<Frame>,
    next_tick: Instant,
    /// Frames that went over the bus (dropped ones included).
    pub frames: u64,
    pub dropped: u64,
    drop_rule: Option<DropRule>,
    pub boot_us: u64,
}

impl Default for SimBus {
    fn default() -> Self {
        Self::new()
    }
}

impl SimBus {
    /// The nine ECUs, standing car.
    pub fn new() -> Self {
        Self::with(&ECUS)
    }

    /// The given ECUs only.
    pub fn with(nodes: &[Node]) -> Self {
        // The clock starts where the standing history laid by `stand_for` ends.
        let start = Instant::from_micros(STANDSTILL_WINDOW_US);
        let mut bus = Self {
            now: start,
            ecus: nodes.iter().map(|&n| SimEcu::new(n)).collect(),
            tester_tx: None,
            next_tick: start,
            frames: 0,
            dropped: 0,
            drop_rule: None,
            boot_us: DEFAULT_BOOT_US,
        };
        // The car has stood long enough for the ECUs to allow programming.
        bus.stand_for(STANDSTILL_WINDOW_US);
        bus
    }

    /// Every ECU hears the standing car's VehicleSpeedMsg every 10 ms from time zero to `us`.
    fn stand_for(&mut self, us: u64) {
        for ecu in &mut self.ecus {
            if let Some(diag) = &mut ecu.diag {
                stood_for(diag, us);
            }
        }
    }

    /// Every ECU sees this vehicle speed (`None`: unknown).
    pub fn set_speed(&mut self, kmh: Option<f32>) {
        for ecu in &mut self.ecus {
            ecu.backend.speed = kmh;
        }
    }

    pub fn ecu(&self, node: Node) -> &SimEcu {
        self.ecus
            .iter()
            .find(|e| e.node() == node)
            .expect("an ECU on this bus")
    }

    pub fn ecu_mut(&mut self, node: Node) -> &mut SimEcu {
        self.ecus
            .iter_mut()
            .find(|e| e.node() == node)
            .expect("an ECU on this bus")
    }

    /// Frames for which `rule` returns true are lost on the bus (nobody receives them).
    pub fn drop_frames(&mut self, rule: impl FnMut(&Frame) -> bool + 'static) {
        self.drop_rule = Some(Box::new(rule));
    }

    /// Runs `job` until it has a result; panics (failing the test) if it has none after
    /// `limit_us` of simulated time.
    pub fn run<J: Job + ?Sized>(
        &mut self,
        job: &mut J,
        limit_us: u64,
    ) -> Result<J::Output, J::Error> {
        let end = self.now.plus_micros(limit_us);
        loop {
            if self.now >= self.next_tick {
                self.tick_ecus();
                self.next_tick = Instant::from_micros((self.now.as_micros() / 1000 + 1) * 1000);
            }
            job.poll(self.now);
            if let Some(result) = job.take_result() {
                return result;
            }
            assert!(
                self.now < end,
                "the job did not finish within {} s of simulated time",
                limit_us as f64 / 1e6
            );
            if self.tester_tx.is_none() {
                self.tester_tx = job.poll_transmit(self.now);
            }
            let now = self.now;
            for ecu in &mut self.ecus {
                if ecu.tx.is_none() && ecu.running() && ecu.busy_until <= now {
                    if let Some(diag) = &mut ecu.diag {
                        ecu.tx = diag.poll_transmit(now);
                    }
                }
            }
            // Arbitration: the lowest identifier wins.
            let mut winner: Option<(Sender, Frame)> = self.tester_tx.map(|f| (Sender::Tester, f));
            for (i, ecu) in self.ecus.iter().enumerate() {
                if let Some(frame) = ecu.tx {
                    if winner.is_none_or(|(_, w)| frame.id() < w.id()) {
                        winner = Some((Sender::Ecu(i), frame));
                    }
                }
            }
            let Some((sender, frame)) = winner else {
                // Nothing to send: on to the next event (a tick, the tester's next deadline,
                // the end of an ECU's stall, when its pending frame goes out).
                let mut next = self.next_tick;
                if let Some(deadline) = job.next_deadline() {
                    next = next.min(deadline);
                }
                for ecu in &self.ecus {
                    if ecu.busy_until > self.now {
                        next = next.min(ecu.busy_until);
                    }
                }
                self.now = next.max(self.now.plus_micros(1));
                continue;
            };
            self.now = self.now.plus_micros(frame_time_us(&frame));
            let now = self.now;
            self.frames += 1;
            match sender {
                Sender::Tester => {
                    self.tester_tx = None;
                    job.confirm_transmit(now);
                }
                Sender::Ecu(i) => {
                    let ecu = &mut self.ecus[i];
                    ecu.tx = None;
                    if let Some(diag) = &mut ecu.diag {
                        diag.confirm_transmit(now);
                    }
                }
            }
            if std::env::var_os("SIM_TRACE").is_some() {
                eprintln!(
                    "{:>10} {:03X} {:02X?}",
                    now.as_micros(),
                    frame.id(),
                    frame.data()
                );
            }
            if self.drop_rule.as_mut().is_some_and(|rule| rule(&frame)) {
                self.dropped += 1;
                continue;
            }
            if sender != Sender::Tester {
                job.on_frame(now, &frame);
            }
            for (i, ecu) in self.ecus.iter_mut().enumerate() {
                if sender == Sender::Ecu(i) || !ecu.running() {
                    continue;
                }
                let Some(diag) = &mut ecu.diag else { continue };
                if !diag.accepts(frame.id()) {
                    continue;
                }
                // A stalled core leaves frames in the receive FIFO, to be read in order.
                if ecu.busy_until > now || !ecu.rx.is_empty() {
                    ecu.rx.push_back(frame);
                } else {
                    diag.on_frame(now, &frame, &mut ecu.backend);
                    ecu.charge_stall(now);
                }
            }
        }
    }

    /// Runs the ECUs alone (no tester) for `us`.
    pub fn idle(&mut self, us: u64) {
        struct Nothing(crate::Tester, Instant, bool);
        impl Job for Nothing {
            type Output = ();
            type Error = ();
            fn tester(&self) -> &crate::Tester {
                &self.0
            }
            fn tester_mut(&mut self) -> &mut crate::Tester {
                &mut self.0
            }
            fn advance(&mut self, now: Instant) {
                self.2 = now >= self.1;
            }
            fn own_deadline(&self) -> Option<Instant> {
                Some(self.1)
            }
            fn take_result(&mut self) -> Option<Result<(), ()>> {
                self.2.then_some(Ok(()))
            }
        }
        let mut job = Nothing(
            crate::Tester::new(Default::default()),
            self.now.plus_micros(us),
            false,
        );
        let _ = self.run(&mut job, us + 1_000_000);
    }

    /// One millisecond step of every ECU: boot, queued frames, poll, reset.
    fn tick_ecus(&mut self) {
        let now = self.now;
        for ecu in &mut self.ecus {
            let node = ecu.node();
            if ecu.reboot_at.is_some_and(|at| now >= at) {
                ecu.reboot_at = None;
                ecu.diag = DiagNode::new(node, DEV_SECURITY_SECRET, now);
                ecu.busy_until = now;
            }
            if !ecu.running() || ecu.busy_until > now {
                continue;
            }
            let Some(diag) = &mut ecu.diag else { continue };
            hear_vehicle_speed(diag, now, ecu.backend.speed);
            while let Some(frame) = ecu.rx.pop_front() {
                diag.on_frame(now, &frame, &mut ecu.backend);
            }
            diag.poll(now, &mut ecu.backend);
            ecu.saw_comm_off |= !diag.server().normal_tx_enabled();
            ecu.saw_dtc_off |= !diag.server().dtc_setting_on();
            if diag.take_reset().is_some() {
                ecu.diag = None;
                ecu.tx = None;
                ecu.rx.clear();
                ecu.resets += 1;
                ecu.reboot_at = Some(now.plus_micros(self.boot_us));
            }
            ecu.charge_stall(now);
        }
    }
}

/// A signed image of `payload_len` bytes for `node`, signed with the key the ECUs trust
/// unless `seed` says otherwise.
pub fn image_for(node: Node, payload_len: usize, seed: [u8; 32]) -> Vec<u8> {
    image_for_slot(node, RUNNING_SLOT.other(), payload_len, seed)
}

/// A signed image for `node` linked for `slot`.
pub fn image_for_slot(node: Node, slot: ImageSlot, payload_len: usize, seed: [u8; 32]) -> Vec<u8> {
    let mut payload: Vec<u8> = (0..payload_len).map(|i| (i * 7 + i / 251) as u8).collect();
    // A vector table the bootloader would start (the ECU checks it).
    if payload.len() >= 8 {
        payload[..8].copy_from_slice(&autoplug_image::stand_in_vector_table(slot));
    }
    let mut builder = ImageBuilder::new(
        node.diag_node_number().expect("an ECU"),
        Version::new(1, 3, 0),
        payload,
    );
    builder.load_address = slot.vector_table();
    builder.build_id = [0xB1; 16];
    builder.part_number = PartNumber::new("AP-TEST-0001").expect("a valid part number");
    builder
        .sign(&SigningKey::from_seed(seed))
        .expect("a valid image")
}

/// The nine ECUs' diagnostic stacks behind the virtual car's socketcand server, in real
/// time, on a thread: what the virtual car does, without the car.
pub struct EcuServer {
    pub address: std::net::SocketAddr,
    stop: Arc<AtomicBool>,
    thread: Option<thread::JoinHandle<Vec<MemEcu>>>,
}

impl EcuServer {
    pub fn start(nodes: &[Node]) -> Self {
        let server = SocketcandServer::start("127.0.0.1:0").unwrap();
        let address = server.address();
        let stop = Arc::new(AtomicBool::new(false));
        let nodes = nodes.to_vec();
        let thread = {
            let stop = Arc::clone(&stop);
            thread::spawn(move || serve_ecus(&server, &nodes, &stop))
        };
        Self {
            address,
            stop,
            thread: Some(thread),
        }
    }

    pub fn url(&self) -> String {
        format!("socketcand://127.0.0.1:{}/can0", self.address.port())
    }

    /// Stops the ECUs and gives their backends back.
    pub fn stop(mut self) -> Vec<MemEcu> {
        self.stop.store(true, Ordering::Release);
        self.thread.take().unwrap().join().unwrap()
    }
}

pub fn serve_ecus(server: &SocketcandServer, nodes: &[Node], stop: &AtomicBool) -> Vec<MemEcu> {
    // The ECUs' clock starts past the standing history laid below.
    let history = Duration::from_micros(STANDSTILL_WINDOW_US);
    let epoch = WallInstant::now();
    let now = || Instant::from_micros((epoch.elapsed() + history).as_micros() as u64);
    let mut ecus: Vec<(MemEcu, Option<DiagNode>, Option<Instant>)> = nodes
        .iter()
        .map(|&n| {
            (
                MemEcu::new(n),
                DiagNode::new(n, DEV_SECURITY_SECRET, now()).map(|mut d| {
                    stood_for(&mut d, STANDSTILL_WINDOW_US);
                    d
                }),
                None,
            )
        })
        .collect();
    while !stop.load(Ordering::Acquire) {
        let t = now();
        while let Some(sent) = server.try_recv() {
            for (backend, diag, _) in &mut ecus {
                if let Some(diag) = diag {
                    diag.on_frame(t, &sent.frame, backend);
                }
            }
        }
        for (backend, diag, reboot) in &mut ecus {
            if reboot.is_some_and(|at| t >= at) {
                *reboot = None;
                *diag = DiagNode::new(backend.node, DEV_SECURITY_SECRET, t);
            }
            let Some(node) = diag else { continue };
            hear_vehicle_speed(node, t, backend.speed);
            node.poll(t, backend);
            while let Some(frame) = node.poll_transmit(t) {
                server.broadcast(t.as_micros(), &frame, None);
                node.confirm_transmit(t);
            }
            if node.take_reset().is_some() {
                *diag = None;
                *reboot = Some(t.plus_micros(200_000));
            }
        }
        thread::sleep(Duration::from_micros(500));
    }
    ecus.into_iter().map(|(backend, ..)| backend).collect()
}
