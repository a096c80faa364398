//! The diagnostic half of a virtual ECU: the same UDS stack (`autoplug_uds::DiagNode`) and
//! update logic as the firmware, over a simulated F446 flash (`autoplug_flash::SimFlash`)
//! with the datasheet's erase and program times, and the bootloader's own slot choice
//! (`autoplug_flash::ab`) at every reset.
//!
//! A host cannot execute the ARM code of an image, so a virtual ECU takes its behaviour
//! after an update from the signed image's header: the software variant (standard or the
//! faulty demonstration software) picks the logic it runs, the version and part number
//! are what it reports. Everything else — the download into the slot not running, the
//! checks, the trial start, the revert of an image that does not confirm itself, the time
//! all of it takes — is what the board does.
//!
//! Flash operations stall the core on the F446 (code runs from the flash being
//! programmed): while a virtual ECU is stalled it neither steps its logic nor sends, and of
//! the frames that arrive meanwhile only the 3 its bxCAN receive FIFO holds survive.

use std::cell::RefCell;

use autoplug_can::{Frame, Node, VehicleSpeedMsg, DIAG_FUNCTIONAL_REQUEST_ID};
use autoplug_ecu::{Dtcs, Instant};
use autoplug_flash::ab::{self, BootAction, BootState, ImageSlot};
use autoplug_flash::sim::{state_twin, SimFlash, SlotPartition};
use autoplug_flash::{SLOT_ERASE_SIZE, WRITE_SIZE};
use autoplug_image::{
    dev, floor, Expectations, ImageBuilder, ImageHeader, PartNumber, Payload, SigningKey,
    SoftwareVariant, Version, HEADER_LEN, NUCLEO_F446RE,
};
use autoplug_uds::security::SeedSource;
use autoplug_uds::{Backend, DiagNode, FlashError, Identification, DEV_SECURITY_SECRET};
use autoplug_vin::Vin;
use embedded_storage::nor_flash::{NorFlash, ReadNorFlash};

/// Frames the bxCAN receive FIFO holds while the core is stalled; one more is lost.
pub const RX_FIFO_DEPTH: usize = 3;

/// Time from the end of a reset (after the bootloader) until the application runs its
/// first control step: clocks, CAN initialisation.
pub const BOOT_TIME_US: u64 = 20_000;

/// The version every virtual ECU leaves the factory with.
pub const FACTORY_VERSION: Version = Version::new(1, 0, 0);

/// Bytes of a factory image's payload: about what the real firmwares take (the table of
/// `scripts/firmware-size`), so a download of one takes as long as a download of those would.
pub const FACTORY_PAYLOAD_LEN: usize = 30 * 1024;

/// The part number of an ECU's software (UDS F187).
pub fn part_number(node: Node) -> PartNumber {
    // Each ECU's from its crate; the gateway's own.
    let name = autoplug_ecus::ecu(node).map_or("AP-GATEWAY-0001", |e| e.part_number);
    PartNumber::new(name).expect("a valid part number")
}

/// A signed release for `node`, as the project's build would make it: one image per slot
/// (slot A's, then slot B's, in one file: `autoplug_image::ImageSet`), the development key.
pub fn build_image(
    node: Node,
    version: Version,
    variant: SoftwareVariant,
    payload_len: usize,
    key: &SigningKey,
) -> Vec<u8> {
    ImageSlot::ALL
        .iter()
        .flat_map(|&slot| build_slot_image(node, slot, version, variant, payload_len, key))
        .collect()
}

/// A signed image for `node` linked for `slot`: a deterministic payload of `payload_len`
/// bytes (at least 8) that starts like an application linked there (initial stack pointer,
/// a reset handler in the slot); the rest does not matter on a host. The header says it
/// holds no machine code ([`Payload::HostLogic`]), so that an ECU running its firmware
/// refuses it instead of starting bytes that are not a program.
pub fn build_slot_image(
    node: Node,
    slot: ImageSlot,
    version: Version,
    variant: SoftwareVariant,
    payload_len: usize,
    key: &SigningKey,
) -> Vec<u8> {
    let number = node.diag_node_number().expect("an ECU");
    let mut payload: Vec<u8> = (0..payload_len.max(8))
        .map(|i| (i as u32).wrapping_mul(2_654_435_761).to_le_bytes()[3] ^ number)
        .collect();
    payload[..8].copy_from_slice(&autoplug_image::stand_in_vector_table(slot));
    let mut builder = ImageBuilder::new(number, version, payload);
    builder.variant = variant;
    // Marked as no machine code: an ECU that runs its firmware refuses it.
    builder.payload_kind = Payload::HostLogic;
    builder.part_number = part_number(node);
    builder.load_address = slot.vector_table();
    builder.build_id[0] = number;
    builder.build_id[1..5].copy_from_slice(&u32::from(version.patch).to_le_bytes());
    builder.build_id[5] = slot.number();
    builder.sign(key).expect("a valid image")
}

/// The signed slot-A image `node` leaves the factory with. Building and signing one costs
/// about 2.3 M instructions (callgrind), a fifth of a second of the simulated car, and a
/// fleet, a benchmark or a test suite builds the same car many times over: each image is
/// signed once per process and copied after.
fn factory_image(node: Node, version: Version, variant: SoftwareVariant) -> Vec<u8> {
    type Signed = ((Node, Version, SoftwareVariant), Vec<u8>);
    static SIGNED: std::sync::Mutex<Vec<Signed>> = std::sync::Mutex::new(Vec::new());
    let wanted = (node, version, variant);
    // A poisoned lock only means another thread panicked mid-push; the list is still whole.
    let mut signed = SIGNED.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, image)) = signed.iter().find(|(k, _)| *k == wanted) {
        return image.clone();
    }
    let key = SigningKey::from_seed(dev::SIGNING_SEED);
    let image = build_slot_image(
        node,
        ImageSlot::A,
        version,
        variant,
        FACTORY_PAYLOAD_LEN,
        &key,
    );
    signed.push((wanted, image.clone()));
    image
}

/// What a virtual ECU runs after a (re)start.
#[derive(Debug)]
pub struct Boot {
    /// The header of the image in the slot started.
    pub header: ImageHeader,
    /// The slot started.
    pub slot: ImageSlot,
    /// What the bootloader did (a trial start of a new image, a revert, ...).
    pub action: BootAction,
    /// Simulated flash time the bootloader took (its boot record), µs.
    pub took_us: u64,
}

/// The diagnostic half of one virtual ECU.
pub struct VirtualDiag {
    node: Node,
    flash: RefCell<SimFlash>,
    /// Boxed: its buffers (8 KiB) would otherwise spread the car's per-tick data over
    /// many cache lines.
    stack: Box<DiagNode>,
    /// `stack.quiescent()` as of the last call into the stack: read every tick, so kept
    /// here, next to the rest of the tick's data.
    quiet: bool,
    installed: ImageHeader,
    floor: Version,
    serial: String,
    software_version: String,
    /// The car's VIN, as the end of the line wrote it into every ECU.
    vin: Vin,
    /// The slot the application runs from.
    running: ImageSlot,
    /// How its image stands (on trial: it confirms itself after its self-test).
    boot_state: BootState,
    /// The core is stalled (flash busy) or resetting until then, µs.
    stalled_until_us: u64,
    /// Frames accepted during the current stall.
    stalled_frames: usize,
    /// Frames lost to a full receive FIFO during stalls.
    overruns: u64,
    key: [u8; 32],
    booted_at_us: u64,
    /// The car's secret for security seeds: what makes this car's seeds its own.
    car_secret: [u8; 12],
    /// The logic's own sensors showed motion at its last step (a veto on programming).
    own_motion: bool,
    /// Security seeds of the current start ([`SeedSource`] over the car's secret and the
    /// seed epoch kept in the simulated flash).
    seeds: SeedSource,
}

impl VirtualDiag {
    /// An ECU fresh from the factory: the development-signed `variant` image of `version`
    /// in slot A, booted, holding the car's `vin`. `seed` is the car's: its serial
    /// numbers and the secret its security seeds are drawn from (a simulation has no
    /// entropy source, and a run must replay exactly), so two cars with other seeds never
    /// share a seed, and no start of one car repeats an earlier start's seeds.
    pub fn new(
        node: Node,
        variant: SoftwareVariant,
        version: Version,
        vin: Vin,
        seed: u64,
    ) -> Self {
        let image = factory_image(node, version, variant);
        let mut flash = SimFlash::new(seed ^ u64::from(node.diag_node_number().unwrap_or(0)));
        flash
            .program(ImageSlot::A.region().start, &pad_to_words(&image))
            .expect("factory programming");
        let flash = RefCell::new(flash);
        write_floor(&flash, version).expect("factory floor");
        let number = node.diag_node_number().expect("an ECU");
        let mut car_secret = [0u8; 12];
        car_secret[..8].copy_from_slice(&seed.to_le_bytes());
        car_secret[8] = number;
        car_secret[9..].copy_from_slice(b"VEC");
        let stack =
            Box::new(DiagNode::new(node, DEV_SECURITY_SECRET, Instant::ZERO).expect("an ECU"));
        let mut diag = Self {
            node,
            flash,
            stack,
            quiet: true,
            installed: ImageHeader::parse(&image).expect("factory header"),
            floor: version,
            serial: format!("AP{number:02X}{:08X}", (seed as u32) ^ u32::from(number)),
            software_version: String::new(),
            vin,
            running: ImageSlot::A,
            boot_state: BootState::Confirmed,
            stalled_until_us: 0,
            stalled_frames: 0,
            overruns: 0,
            key: dev::PUBLIC_KEY,
            booted_at_us: 0,
            car_secret,
            own_motion: false,
            seeds: SeedSource::new(&car_secret, 0),
        };
        diag.boot(0);
        // The scenario starts with the ECUs running: power-up is before time zero.
        diag.stalled_until_us = 0;
        diag.booted_at_us = 0;
        diag
    }

    /// The header of the software the ECU runs.
    pub fn installed(&self) -> &ImageHeader {
        &self.installed
    }

    /// Whether the ECU is stalled (flash busy) or resetting at `t_us`.
    pub fn stalled(&self, t_us: u64) -> bool {
        t_us < self.stalled_until_us
    }

    /// Frames lost to the receive FIFO while the core was stalled.
    pub fn overruns(&self) -> u64 {
        self.overruns
    }

    /// Whether the application may send its normal messages (UDS 0x28).
    pub fn normal_tx_enabled(&self) -> bool {
        self.stack.server().normal_tx_enabled()
    }

    /// Whether the application takes received normal messages (UDS 0x28).
    pub fn normal_rx_enabled(&self) -> bool {
        self.stack.server().normal_rx_enabled()
    }

    /// The identifiers the diagnostic half listens to, for the acceptance filter.
    pub fn received_ids(node: Node) -> Vec<u16> {
        let mut ids = vec![DIAG_FUNCTIONAL_REQUEST_ID];
        ids.extend(node.diag_request_id());
        if node != Node::Cruise {
            // Everyone but its sender listens to the vehicle speed: no programming while
            // the car moves.
            ids.push(VehicleSpeedMsg::ID);
        }
        ids
    }

    /// Whether a frame arriving at `t_us` survives the receive FIFO (it always does unless
    /// the core is stalled and the FIFO is full).
    pub fn admit(&mut self, t_us: u64) -> bool {
        if !self.stalled(t_us) {
            return true;
        }
        if self.stalled_frames < RX_FIFO_DEPTH {
            self.stalled_frames += 1;
            true
        } else {
            self.overruns += 1;
            false
        }
    }

    /// Offers a received frame to the diagnostic half; returns whether it was a
    /// diagnostic frame (others, the vehicle speed among them, go on to the application).
    pub fn on_frame(&mut self, t_us: u64, frame: &Frame, dtcs: &mut Dtcs) -> bool {
        let now = Instant::from_micros(t_us);
        // Decided here, without touching the boxed stack: most frames are the
        // application's, and this runs for each of them.
        let id = frame.id();
        if id != DIAG_FUNCTIONAL_REQUEST_ID && Some(id) != self.node.diag_request_id() {
            if id == VehicleSpeedMsg::ID {
                self.stack.observe(now, frame);
            }
            return false;
        }
        let mut backend = backend!(self, dtcs);
        self.stack.on_frame(now, frame, &mut backend);
        let busy = backend.busy_us;
        self.stall(t_us, busy);
        self.quiet = self.stack.quiescent();
        true
    }

    /// Timers and a slice of pending programming; returns a reset request once its
    /// response is out.
    // Inlined up to the early return: the car calls this for each ECU every tick, and
    // nearly always the stack is quiet.
    #[inline]
    pub fn poll(&mut self, t_us: u64, dtcs: &mut Dtcs) -> bool {
        if self.quiet || self.stalled(t_us) {
            return false;
        }
        self.poll_busy(t_us, dtcs)
    }

    fn poll_busy(&mut self, t_us: u64, dtcs: &mut Dtcs) -> bool {
        let mut backend = backend!(self, dtcs);
        self.stack.poll(Instant::from_micros(t_us), &mut backend);
        let busy = backend.busy_us;
        self.stall(t_us, busy);
        let reset = self.stack.take_reset().is_some();
        self.quiet = self.stack.quiescent();
        reset
    }

    /// The diagnostic frames to send now (sent at once: the stack is told so).
    // Inlined up to the early return, as `poll`.
    #[inline]
    pub fn poll_transmit(&mut self, t_us: u64) -> Vec<Frame> {
        if self.quiet || self.stalled(t_us) {
            return Vec::new();
        }
        self.poll_transmit_busy(t_us)
    }

    fn poll_transmit_busy(&mut self, t_us: u64) -> Vec<Frame> {
        let mut frames = Vec::new();
        let now = Instant::from_micros(t_us);
        while let Some(frame) = self.stack.poll_transmit(now) {
            self.stack.confirm_transmit(now);
            frames.push(frame);
        }
        self.quiet = self.stack.quiescent();
        frames
    }

    /// One of the application's own frames, as it goes out (live data, OBD-II values and
    /// the vehicle speed the stack knows).
    pub fn note_sent(&mut self, t_us: u64, frame: &Frame) {
        self.stack.note_sent(Instant::from_micros(t_us), frame);
    }

    /// The self-test passed (CAN up, control loop running): an image booted unconfirmed
    /// confirms itself and raises the version floor to its own version.
    #[inline]
    pub fn self_test_passed(&mut self, t_us: u64) {
        if self.boot_state != BootState::Trial || self.stalled(t_us) {
            return;
        }
        self.confirm_trial(t_us);
    }

    fn confirm_trial(&mut self, t_us: u64) {
        let before = busy_us(&self.flash);
        let confirmed = state_twin(&self.flash)
            .is_ok_and(|mut twin| ab::confirm(&mut twin, self.running).is_ok());
        if confirmed {
            self.boot_state = BootState::Confirmed;
            if self.installed.version > self.floor
                && write_floor(&self.flash, self.installed.version).is_ok()
            {
                self.floor = self.installed.version;
            }
            autoplug_log::info!(
                "{}: software {} confirmed",
                self.node.name(),
                self.installed.version
            );
        }
        let busy = busy_us(&self.flash) - before;
        self.stall(t_us, busy);
    }

    /// What the logic's own sensors showed at its last step: motion vetoes programming
    /// (`EcuLogic::own_sensors_show_motion`).
    pub fn set_own_motion(&mut self, moving: bool) {
        self.own_motion = moving;
    }

    /// Whether the running image still has to confirm itself.
    pub fn unconfirmed(&self) -> bool {
        self.boot_state == BootState::Trial
    }

    /// The slot the application runs from.
    pub fn running_slot(&self) -> ImageSlot {
        self.running
    }

    /// When the application last started, µs.
    pub fn booted_at_us(&self) -> u64 {
        self.booted_at_us
    }

    /// A reset: the bootloader chooses the slot to start (`autoplug_flash::ab::choose`, a
    /// trial start of a marked image or the revert of one that did not confirm itself, each
    /// a record in the flash), then the application starts with what that slot holds. The
    /// caller rebuilds the ECU's logic for [`VirtualDiag::installed`]'s variant.
    pub fn boot(&mut self, t_us: u64) -> Boot {
        let before = busy_us(&self.flash);
        let choice = match state_twin(&self.flash) {
            Ok(mut twin) => ab::choose(&mut twin, |slot| startable(&self.flash, slot)),
            // The real bootloader starts slot A when it cannot read the state copies.
            Err(_) => ab::BootChoice {
                slot: ImageSlot::A,
                action: BootAction::Fallback,
            },
        };
        let took_us = busy_us(&self.flash) - before;
        let mut header = [0u8; HEADER_LEN];
        self.flash
            .borrow()
            .read(choice.slot.region().start, &mut header)
            .expect("the slot is in the flash");
        // Only a verified image is ever marked for a start, and the factory's is signed
        // (the power-cut tests of autoplug-flash): a header that does not parse is a bug.
        self.installed = ImageHeader::parse(&header).expect("a complete image in the slot started");
        self.software_version = self.installed.version.to_string();
        self.running = choice.slot;
        self.boot_state = state_twin(&self.flash)
            .ok()
            .and_then(|mut twin| ab::state(&mut twin, choice.slot).ok())
            .unwrap_or(BootState::Confirmed);
        // What the application reads of its persistent state at the start: the floor, and
        // the seed epoch, raised for this start before any seed is drawn.
        self.floor = read_floor(&self.flash).unwrap_or(self.floor);
        let epoch = next_seed_epoch(&self.flash);
        self.seeds = SeedSource::new(&self.car_secret, epoch);
        *self.stack = DiagNode::new(self.node, DEV_SECURITY_SECRET, Instant::from_micros(t_us))
            .expect("an ECU");
        self.quiet = true;
        self.stalled_frames = 0;
        self.stalled_until_us = t_us + took_us + BOOT_TIME_US;
        self.booted_at_us = self.stalled_until_us;
        if choice.action != BootAction::Normal {
            autoplug_log::info!(
                "{}: bootloader {:?}: slot {}, running {} {}",
                self.node.name(),
                choice.action,
                choice.slot.letter(),
                self.installed.variant,
                self.installed.version
            );
        }
        Boot {
            header: self.installed,
            slot: choice.slot,
            action: choice.action,
            took_us,
        }
    }

    fn stall(&mut self, t_us: u64, busy_us: u64) {
        if busy_us > 0 {
            let from = self.stalled_until_us.max(t_us);
            if from == t_us {
                self.stalled_frames = 0;
            }
            self.stalled_until_us = from + busy_us;
        }
    }
}

/// The ECU's side of its UDS server for one call, from the fields of a [`VirtualDiag`]
/// other than its stack (a macro, so the borrows stay per field).
macro_rules! backend {
    ($diag:expr, $dtcs:expr) => {
        EcuBackend {
            node: $diag.node,
            flash: &$diag.flash,
            dtcs: $dtcs,
            installed: &$diag.installed,
            software_version: &$diag.software_version,
            serial: &$diag.serial,
            vin: &$diag.vin,
            floor: $diag.floor,
            running: $diag.running,
            boot_state: $diag.boot_state,
            key: $diag.key,
            seeds: &mut $diag.seeds,
            own_motion: $diag.own_motion,
            busy_us: 0,
        }
    };
}
use backend;

/// The ECU as its UDS server sees it.
struct EcuBackend<'a> {
    node: Node,
    flash: &'a RefCell<SimFlash>,
    dtcs: &'a mut Dtcs,
    installed: &'a ImageHeader,
    software_version: &'a str,
    serial: &'a str,
    vin: &'a Vin,
    floor: Version,
    running: ImageSlot,
    boot_state: BootState,
    key: [u8; 32],
    seeds: &'a mut SeedSource,
    own_motion: bool,
    /// Flash busy time of the operations of this call, µs.
    busy_us: u64,
}

impl EcuBackend<'_> {
    fn timed<T>(&mut self, op: impl FnOnce(&RefCell<SimFlash>) -> T) -> T {
        let before = busy_us(self.flash);
        let result = op(self.flash);
        self.busy_us += busy_us(self.flash) - before;
        result
    }

    /// The slot downloads go to: the one not running.
    fn dfu_slot(&self) -> ImageSlot {
        self.running.other()
    }
}

impl Backend for EcuBackend<'_> {
    fn identification(&self) -> Identification<'_> {
        Identification {
            part_number: self.installed.part_number.as_str().as_bytes(),
            software_version: self.software_version.as_bytes(),
            serial_number: self.serial.as_bytes(),
            hardware_version: b"NUCLEO-F446RE",
            vin: self.vin.as_bytes(),
            boot_slot: Some((self.running, self.boot_state)),
        }
    }

    fn dtcs(&mut self) -> &mut Dtcs {
        self.dtcs
    }

    fn own_sensors_show_motion(&self) -> bool {
        self.own_motion
    }

    fn fill_random(&mut self, out: &mut [u8]) {
        self.seeds.fill(out);
    }

    fn stored_key_failures(&mut self) -> u8 {
        state_twin(self.flash)
            .ok()
            .and_then(|mut twin| twin.key_failures().ok())
            .unwrap_or(0)
    }

    fn store_key_failures(&mut self, failures: u8) -> Result<(), FlashError> {
        self.timed(|flash| {
            let mut twin = state_twin(flash).map_err(|_| FlashError)?;
            twin.store_key_failures(failures).map_err(|_| FlashError)
        })
    }

    fn image_expectations(&self) -> Expectations {
        Expectations {
            node: self.node.diag_node_number().unwrap_or(0),
            hardware_id: NUCLEO_F446RE,
            version_floor: self.floor,
            max_image_len: self.dfu_slot().region().size,
            load_address: self.dfu_slot().vector_table(),
            runs_machine_code: false,
        }
    }

    fn public_key(&self) -> [u8; 32] {
        self.key
    }

    fn dfu_erase_steps(&self, len: u32) -> u32 {
        len.min(self.dfu_slot().region().size)
            .div_ceil(SLOT_ERASE_SIZE)
    }

    fn dfu_erase(&mut self, step: u32) -> Result<(), FlashError> {
        let (running, target) = (self.running, self.dfu_slot());
        self.timed(|flash| {
            if step == 0 {
                // Refused while the running image is on trial; withdraws an earlier
                // download's trial mark of the slot before it is erased.
                let mut twin = state_twin(flash).map_err(|_| FlashError)?;
                ab::prepare_download(&mut twin, running, target).map_err(|_| FlashError)?;
            }
            SlotPartition::slot(flash, target)
                .erase(step * SLOT_ERASE_SIZE, (step + 1) * SLOT_ERASE_SIZE)
                .map_err(|_| FlashError)
        })
    }

    fn dfu_write(&mut self, offset: u32, data: &[u8]) -> Result<(), FlashError> {
        let target = self.dfu_slot();
        self.timed(|flash| {
            SlotPartition::slot(flash, target)
                .write(offset, data)
                .map_err(|_| FlashError)
        })
    }

    fn dfu_read(&mut self, offset: u32, out: &mut [u8]) -> Result<(), FlashError> {
        SlotPartition::slot(self.flash, self.dfu_slot())
            .read(offset, out)
            .map_err(|_| FlashError)
    }

    fn mark_updated(&mut self) -> Result<(), FlashError> {
        let (running, target) = (self.running, self.dfu_slot());
        self.timed(|flash| {
            let mut twin = state_twin(flash).map_err(|_| FlashError)?;
            ab::mark_trial(&mut twin, running, target).map_err(|_| FlashError)
        })
    }
}

fn busy_us(flash: &RefCell<SimFlash>) -> u64 {
    flash.borrow().total_busy().as_micros() as u64
}

/// The image padded with the erased value to whole flash words.
fn pad_to_words(image: &[u8]) -> Vec<u8> {
    let mut padded = image.to_vec();
    padded.resize(image.len().div_ceil(WRITE_SIZE) * WRITE_SIZE, 0xFF);
    padded
}

/// Whether `slot` holds something the bootloader would start: a vector table linked for it
/// (what `autoplug_flash::ab::plausible_vector_table` checks on the ECU).
fn startable(flash: &RefCell<SimFlash>, slot: ImageSlot) -> bool {
    let mut table = [0u8; 8];
    let read = flash.borrow().read(slot.vector_table(), &mut table).is_ok();
    let word =
        |at: usize| u32::from_le_bytes([table[at], table[at + 1], table[at + 2], table[at + 3]]);
    read && ab::plausible_vector_table(slot, word(0), word(4))
}

/// How the image in `running` stands as the application reads it (confirmed if the state
/// cannot be read).
#[cfg(test)]
fn boot_state(flash: &RefCell<SimFlash>, running: ImageSlot) -> BootState {
    state_twin(flash)
        .ok()
        .and_then(|mut twin| ab::state(&mut twin, running).ok())
        .unwrap_or(BootState::Confirmed)
}

/// The version floor kept in the persistent state.
fn read_floor(flash: &RefCell<SimFlash>) -> Option<Version> {
    let payload = state_twin(flash).ok()?.read_record(floor::KIND).ok()??;
    Some(floor::from_payload(payload))
}

/// Records a new version floor in the persistent state.
fn write_floor(flash: &RefCell<SimFlash>, version: Version) -> Result<(), FlashError> {
    state_twin(flash)
        .and_then(|mut twin| twin.write_record(floor::KIND, floor::to_payload(version)))
        .map_err(|_| FlashError)
}

/// Raises the seed epoch kept in the persistent state and returns the new one.
fn next_seed_epoch(flash: &RefCell<SimFlash>) -> u32 {
    state_twin(flash).map_or(0, |mut twin| twin.raise_seed_epoch().0)
}

#[cfg(test)]
mod tests {
    use autoplug_flash::twin::{RECORDS_START, RECORD_LEN};
    use autoplug_flash::SMALL_SECTOR_SIZE;
    use autoplug_uds::security::key_for;
    use autoplug_uds::{Config, Reply, Server};

    use super::*;

    const NODE: Node = Node::Cruise;

    /// A virtual ECU and a UDS server over its backend, as after a start at `t_us`.
    struct Ecu {
        diag: VirtualDiag,
        server: Server,
        dtcs: Dtcs,
        t_us: u64,
    }

    impl Ecu {
        fn new(car_seed: u64) -> Self {
            let diag = VirtualDiag::new(
                NODE,
                SoftwareVariant::Standard,
                FACTORY_VERSION,
                crate::scenario::vin_from_seed(car_seed),
                car_seed,
            );
            Self::started(diag, 0)
        }

        fn started(diag: VirtualDiag, t_us: u64) -> Self {
            let number = NODE.diag_node_number().expect("an ECU");
            let mut ecu = Self {
                diag,
                server: Server::new(
                    Config::new(number, DEV_SECURITY_SECRET),
                    Instant::from_micros(t_us),
                ),
                dtcs: Dtcs::new(),
                t_us,
            };
            let now = Instant::from_micros(t_us);
            ecu.server.poll(now, &mut backend!(ecu.diag, &mut ecu.dtcs));
            ecu
        }

        /// ECUReset or a power cycle: the bootloader, then a fresh application.
        fn restart(self) -> Self {
            let Self { mut diag, t_us, .. } = self;
            let t_us = t_us + 1_000;
            diag.boot(t_us);
            Self::started(diag, t_us)
        }

        fn request(&mut self, request: &[u8]) -> Vec<u8> {
            let mut out = [0u8; 256];
            let now = Instant::from_micros(self.t_us);
            let mut backend = backend!(self.diag, &mut self.dtcs);
            match self
                .server
                .handle(now, request, false, &mut backend, &mut out)
            {
                Reply::Send(n) | Reply::SendThenReset(n, _) => out[..n].to_vec(),
                other => panic!("unexpected reply {other:?}"),
            }
        }

        fn seed(&mut self) -> [u8; 16] {
            self.request(&[0x10, 0x03]);
            let response = self.request(&[0x27, 0x01]);
            assert_eq!(&response[..2], &[0x67, 0x01], "a seed: {response:02X?}");
            response[2..].try_into().expect("16 bytes")
        }

        fn wrong_key(&mut self) -> Vec<u8> {
            self.seed();
            self.request(&[&[0x27, 0x02][..], &[0xAA; 16]].concat())
        }

        fn stored_failures(&mut self) -> u8 {
            backend!(self.diag, &mut self.dtcs).stored_key_failures()
        }
    }

    #[test]
    fn seeds_differ_across_cars_and_starts_and_replay_for_the_same_car() {
        let first = Ecu::new(1).seed();
        assert_eq!(first, Ecu::new(1).seed(), "the same car replays exactly");
        assert_ne!(first, Ecu::new(2).seed(), "another car");
        let mut ecu = Ecu::new(1);
        let before = ecu.seed();
        let mut ecu = ecu.restart();
        let after = ecu.seed();
        assert_ne!(before, after, "the next start");
        let mut again = ecu.restart();
        assert_ne!(again.seed(), after);
    }

    #[test]
    fn the_lockout_is_kept_in_the_simulated_flash_across_a_reset() {
        let mut ecu = Ecu::new(1);
        assert_eq!(ecu.wrong_key(), [0x7F, 0x27, 0x35]);
        assert_eq!(ecu.wrong_key(), [0x7F, 0x27, 0x35]);
        assert_eq!(ecu.wrong_key(), [0x7F, 0x27, 0x36]);
        let mut ecu = ecu.restart();
        ecu.request(&[0x10, 0x03]);
        assert_eq!(ecu.request(&[0x27, 0x01]), [0x7F, 0x27, 0x37]);
        assert_eq!(ecu.stored_failures(), 3);
        // After the delay, a good key opens it and clears the count.
        ecu.t_us += 10_000_001;
        let seed = ecu.seed();
        let number = NODE.diag_node_number().expect("an ECU");
        let key = key_for(DEV_SECURITY_SECRET, number, &seed);
        assert_eq!(
            ecu.request(&[&[0x27, 0x02][..], &key].concat()),
            [0x67, 0x02]
        );
        assert_eq!(ecu.restart().stored_failures(), 0);
    }

    /// A power cut at every flash operation of counting a wrong key — a record write, and
    /// with a full copy the switch to the other one — never gives a free attempt: either the
    /// key was not judged, or the count holds it after power returns; the version floor and
    /// the boot state survive.
    #[test]
    fn a_power_cut_while_counting_a_wrong_key_gives_no_free_attempt() {
        let slots = (SMALL_SECTOR_SIZE - RECORDS_START) / RECORD_LEN;
        for fill_copy in [false, true] {
            let mut ecu = Ecu::new(7);
            assert_eq!(ecu.wrong_key(), [0x7F, 0x27, 0x35]);
            if fill_copy {
                // Run into a fresh copy (floor, epoch and count carried over), then fill it
                // but for one slot: the next start's epoch takes that one, and the count of
                // the attempt below makes the switch.
                let mut twin = state_twin(&ecu.diag.flash).expect("open");
                let sequence = twin.sequence();
                while twin.sequence() == sequence {
                    twin.store_key_failures(1).expect("record");
                }
                for _ in 0..slots - 3 - 1 {
                    twin.store_key_failures(1).expect("record");
                }
            }
            let base = ecu.diag.flash.borrow().clone();
            // A fresh start from `base` that asked for a seed, with the cut armed at `k`.
            let attempt = |cut_at: Option<u64>| {
                let ecu = Ecu::new(7);
                *ecu.diag.flash.borrow_mut() = base.clone();
                let mut ecu = ecu.restart();
                let stored = ecu.stored_failures();
                ecu.seed();
                let ops_before = ecu.diag.flash.borrow().operations();
                if let Some(k) = cut_at {
                    ecu.diag.flash.borrow_mut().reseed(k ^ 0x5EED);
                    ecu.diag.flash.borrow_mut().cut_power_at(k);
                }
                let response = ecu.request(&[&[0x27, 0x02][..], &[0xAA; 16]].concat());
                let ops = ecu.diag.flash.borrow().operations() - ops_before;
                (ecu, stored, response, ops)
            };
            let (_, stored, response, ops) = attempt(None);
            assert_eq!((stored, response), (1, vec![0x7F, 0x27, 0x35]));
            if fill_copy {
                assert!(ops > 1, "the count makes the switch: {ops} operations");
            } else {
                assert_eq!(ops, 1, "one record");
            }
            for k in 0..ops {
                let (cut, stored, response, _) = attempt(Some(k));
                assert_eq!(
                    response,
                    [0x7F, 0x27, 0x22],
                    "fill {fill_copy}, cut at {k}: no verdict without the count"
                );
                cut.diag.flash.borrow_mut().restore_power();
                let mut after = cut.restart();
                let kept = after.stored_failures();
                assert!(
                    kept >= stored,
                    "fill {fill_copy}, cut at {k}: count {kept} below {stored}"
                );
                assert_eq!(read_floor(&after.diag.flash), Some(FACTORY_VERSION));
                assert_eq!(
                    boot_state(&after.diag.flash, ImageSlot::A),
                    BootState::Confirmed
                );
                assert_eq!(after.diag.running_slot(), ImageSlot::A);
            }
        }
    }
}
