//! One ECU's diagnostic stack on the bus: ISO-TP on its physical identifiers (requests at
//! 0x700 + node number, responses at 0x780 + node number) and the functional identifier
//! 0x7DF, the UDS [`Server`], and OBD-II mode 01 answered on the ECU's ISO 15765-4
//! response identifier. The firmware and the virtual car feed it frames and time the same
//! way they feed the ECU's logic.

use autoplug_can::{EngineMsg, Frame, Node, VehicleSpeedMsg, DIAG_FUNCTIONAL_REQUEST_ID};
use autoplug_ecu::{Dtcs, Instant, STALE_AFTER_PERIODS};
use autoplug_image::Expectations;
use autoplug_isotp::{Channel, Config as IsoTpConfig, Event, StMin};

use crate::obd::{self, answer_mode01, ObdValues};
use crate::server::{Backend, Config, FlashError, Identification, Reply, ResetKind, Server};

/// Live data DIDs: 0x0100 + a CAN identifier the ECU sends = that message's last data.
pub const LIVE_DID_BASE: u16 = 0x0100;

/// More messages than any ECU of the catalogue sends.
const MAX_OWN_MESSAGES: usize = 8;

/// The last frame of each message the ECU itself sent: its live data DIDs, and the
/// OBD-II values of the ECUs that own one (what they measured, as they reported it).
#[derive(Clone, Copy, Debug, Default)]
struct SentFrames {
    frames: [Option<Frame>; MAX_OWN_MESSAGES],
}

impl SentFrames {
    fn note(&mut self, frame: &Frame) {
        let slot = self
            .frames
            .iter()
            .position(|f| f.is_some_and(|f| f.id() == frame.id()))
            .or_else(|| self.frames.iter().position(Option::is_none));
        if let Some(slot) = slot {
            self.frames[slot] = Some(*frame);
        }
    }

    fn get(&self, id: u16) -> Option<&Frame> {
        self.frames.iter().flatten().find(|f| f.id() == id)
    }

    fn obd_values(&self) -> ObdValues {
        let engine = self
            .get(EngineMsg::ID)
            .and_then(|f| EngineMsg::decode(f.data()).ok());
        let speed = self
            .get(VehicleSpeedMsg::ID)
            .and_then(|f| VehicleSpeedMsg::decode(f.data()).ok());
        ObdValues {
            engine_rpm: engine.map(|e| e.engine_rpm),
            fuel_l: engine.map(|e| e.fuel_level),
            speed_kmh: speed.map(|s| s.vehicle_speed),
        }
    }
}

/// How long a VehicleSpeedMsg counts, µs: 3 of its periods, as every CAN input.
const SPEED_VALID_US: u64 = VehicleSpeedMsg::CYCLE_TIME_MS as u64 * 1000 * STALE_AFTER_PERIODS;

/// How long the car must be seen standing before programming is allowed, µs: every
/// VehicleSpeedMsg of this window under [`crate::server::STANDING_KMH`], none missing for
/// more than 3 periods. A single spoofed zero-speed frame between the real sender's frames
/// proves nothing: the next real frame ends the chain. (An attacker who can silence the
/// real sender and send its frames instead can still pass; see docs/src/security.md, "What
/// is not protected".)
pub const STANDSTILL_WINDOW_US: u64 = 500_000;

/// The ECU's backend as the server sees it through the stack: what the stack knows itself
/// (vehicle speed, the ECU's own frames for live data and OBD-II) comes from the stack,
/// the rest from the ECU.
struct WithStack<'a, B: Backend> {
    ecu: &'a mut B,
    node: Node,
    sent: SentFrames,
    speed_kmh: Option<f32>,
    standing: bool,
}

impl<B: Backend> Backend for WithStack<'_, B> {
    fn identification(&self) -> Identification<'_> {
        self.ecu.identification()
    }
    fn read_live_data(&mut self, did: u16, out: &mut [u8]) -> Option<usize> {
        let data = self.sent.get(did.checked_sub(LIVE_DID_BASE)?)?.data();
        let target = out.get_mut(..data.len())?;
        target.copy_from_slice(data);
        Some(data.len())
    }
    fn vehicle_speed_kmh(&self) -> Option<f32> {
        self.speed_kmh
    }
    fn vehicle_standing(&self) -> bool {
        self.standing && !self.ecu.own_sensors_show_motion()
    }
    fn own_sensors_show_motion(&self) -> bool {
        self.ecu.own_sensors_show_motion()
    }
    fn dtcs(&mut self) -> &mut Dtcs {
        self.ecu.dtcs()
    }
    fn fill_random(&mut self, out: &mut [u8]) {
        self.ecu.fill_random(out)
    }
    fn stored_key_failures(&mut self) -> u8 {
        self.ecu.stored_key_failures()
    }
    fn store_key_failures(&mut self, failures: u8) -> Result<(), FlashError> {
        self.ecu.store_key_failures(failures)
    }
    fn image_expectations(&self) -> Expectations {
        self.ecu.image_expectations()
    }
    fn public_key(&self) -> [u8; 32] {
        self.ecu.public_key()
    }
    fn dfu_erase_steps(&self, len: u32) -> u32 {
        self.ecu.dfu_erase_steps(len)
    }
    fn dfu_erase(&mut self, step: u32) -> Result<(), FlashError> {
        self.ecu.dfu_erase(step)
    }
    fn dfu_write(&mut self, offset: u32, data: &[u8]) -> Result<(), FlashError> {
        self.ecu.dfu_write(offset, data)
    }
    fn dfu_read(&mut self, offset: u32, out: &mut [u8]) -> Result<(), FlashError> {
        self.ecu.dfu_read(offset, out)
    }
    fn mark_updated(&mut self) -> Result<(), FlashError> {
        self.ecu.mark_updated()
    }
    fn obd_pids(&self) -> &'static [u8] {
        obd::pids_of(self.node)
    }
    fn obd_read(&mut self, pid: u8, out: &mut [u8]) -> Option<usize> {
        obd::encode(pid, &self.sent.obd_values(), out)
    }
}

/// Byte that pads every frame the ECU sends to 8 bytes (ISO 15765-4 requires DLC 8).
pub const PADDING: u8 = 0xCC;

/// Bytes programmed per [`DiagNode::poll`] while a download is under way: 16 flash words,
/// about 0.26 ms of stall on the F446, shorter than the 3 frames (about 0.7 ms) the bxCAN
/// receive FIFO holds at full bus load.
pub const PROGRAM_SLICE: usize = 64;

/// The ISO-TP parameters of an ECU: block size 0 and STmin 0 (the tester may send a whole
/// TransferData block back to back: the ECU buffers it in RAM and programs it while the
/// next one arrives), padding, ISO 15765-2 default timeouts.
pub const fn isotp_config(node: Node) -> Option<IsoTpConfig> {
    let (Some(rx_id), Some(tx_id)) = (node.diag_request_id(), node.diag_response_id()) else {
        return None;
    };
    let mut config = IsoTpConfig::default_for(tx_id, rx_id);
    config.functional_rx_id = Some(DIAG_FUNCTIONAL_REQUEST_ID);
    config.padding = Some(PADDING);
    config.block_size = 0;
    config.st_min = StMin::Millis(0);
    Some(config)
}

/// Which source the frame last handed out came from, for its confirmation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Handed {
    Nothing,
    Channel,
    Obd,
}

/// The longest response an ECU sends: identification strings and DTC lists are short, and
/// a smaller transmit buffer keeps the stack within the firmware's RAM budget.
pub const MAX_RESPONSE_LEN: usize = 256;

/// An ECU's diagnostic stack.
pub struct DiagNode {
    node: Node,
    channel: Channel<4095, MAX_RESPONSE_LEN>,
    server: Server,
    response: [u8; MAX_RESPONSE_LEN],
    /// A response the channel could not take yet (it was still sending).
    queued: Option<usize>,
    /// A reset to perform once the response before it is out.
    reset_after_send: Option<ResetKind>,
    reset_due: Option<ResetKind>,
    /// Waiting for the 0x78 to be out before the next step of a long operation.
    resume_after_send: bool,
    obd_frame: Option<Frame>,
    handed: Handed,
    sent: SentFrames,
    /// The last VehicleSpeedMsg on the bus (received, or sent by this ECU), and when.
    speed: Option<(Instant, f32)>,
    /// Since when every VehicleSpeedMsg showed the car standing, without a gap.
    standing_since: Option<Instant>,
}

impl DiagNode {
    /// The stack of `node` (an ECU with a diagnostic node number; `None` for another node).
    pub fn new(node: Node, security_secret: &'static [u8], now: Instant) -> Option<Self> {
        let config = isotp_config(node)?;
        let number = node.diag_node_number()?;
        Some(Self {
            node,
            channel: Channel::new(config),
            server: Server::new(Config::new(number, security_secret), now),
            response: [0; MAX_RESPONSE_LEN],
            queued: None,
            reset_after_send: None,
            reset_due: None,
            resume_after_send: false,
            obd_frame: None,
            handed: Handed::Nothing,
            sent: SentFrames::default(),
            speed: None,
            standing_since: None,
        })
    }

    /// The UDS server (session, communication control, DTC setting...).
    pub fn server(&self) -> &Server {
        &self.server
    }

    /// Whether nothing is under way: no transfer in either direction, nothing queued, the
    /// default session, no long operation or programming pending. [`DiagNode::poll`] has
    /// nothing to do then, until the next frame arrives.
    pub fn quiescent(&self) -> bool {
        self.channel.is_idle()
            && self.queued.is_none()
            && !self.resume_after_send
            && self.reset_after_send.is_none()
            && self.reset_due.is_none()
            && self.obd_frame.is_none()
            && self.server.session() == crate::Session::Default
            && !self.server.busy()
            && !self.server.programming_pending()
    }

    /// Whether a long operation waits for its last frame (a 0x78) to be out before its
    /// next step, which [`DiagNode::poll`] takes once the channel is idle. A caller that
    /// confirms a frame when it queues it rather than when it is on the bus (the firmware)
    /// holds that poll until its transmit path is empty: the next step may stall the core
    /// (a sector erase, a second or more) with the 0x78 still queued, past the tester's P2.
    pub fn resumes_after_send(&self) -> bool {
        self.resume_after_send
    }

    /// Whether `id` is one of the diagnostic identifiers this ECU listens to.
    pub fn accepts(&self, id: u16) -> bool {
        Some(id) == self.node.diag_request_id() || id == DIAG_FUNCTIONAL_REQUEST_ID
    }

    /// A frame the ECU received that is not diagnostic: the stack notes the vehicle speed
    /// (no programming while the car moves).
    pub fn observe(&mut self, now: Instant, frame: &Frame) {
        if frame.id() == VehicleSpeedMsg::ID {
            let Ok(message) = VehicleSpeedMsg::decode(frame.data()) else {
                // An invalid speed frame proves nothing either way, and breaks the chain.
                self.standing_since = None;
                return;
            };
            let standing = message.vehicle_speed < crate::server::STANDING_KMH;
            let unbroken = self.speed.is_some_and(|(at, v)| {
                v < crate::server::STANDING_KMH && now.micros_since(at) <= SPEED_VALID_US
            });
            self.standing_since = match (standing, unbroken) {
                (true, true) => self.standing_since.or(Some(now)),
                (true, false) => Some(now),
                (false, _) => None,
            };
            self.speed = Some((now, message.vehicle_speed));
        }
    }

    /// A frame of the ECU's own application, as it goes out: its data is the ECU's live
    /// data (DIDs 0x0100 + identifier) and, for the engine and cruise ECUs, their OBD-II
    /// values; a VehicleSpeedMsg is also the speed the ECU knows.
    pub fn note_sent(&mut self, now: Instant, frame: &Frame) {
        self.sent.note(frame);
        self.observe(now, frame);
    }

    /// The vehicle speed the ECU knows, km/h: the last VehicleSpeedMsg, stale after 3 of
    /// its periods like every input, except while the tester has switched normal
    /// communication off (0x28): the bus is silent on purpose and the last speed stands.
    pub fn vehicle_speed_kmh(&self, now: Instant) -> Option<f32> {
        let server = &self.server;
        let silenced = !server.normal_tx_enabled() || !server.normal_rx_enabled();
        self.speed
            .filter(|(at, _)| silenced || now.micros_since(*at) <= SPEED_VALID_US)
            .map(|(_, v)| v)
    }

    /// Whether the car is proven to stand: the speed known and standing, and every
    /// VehicleSpeedMsg of the last [`STANDSTILL_WINDOW_US`] standing.
    pub fn vehicle_standing(&self, now: Instant) -> bool {
        self.vehicle_speed_kmh(now)
            .is_some_and(|v| v < crate::server::STANDING_KMH)
            && self
                .standing_since
                .is_some_and(|since| now.micros_since(since) >= STANDSTILL_WINDOW_US)
    }

    /// A frame received on one of [`DiagNode::accepts`]' identifiers (others are ignored).
    pub fn on_frame(&mut self, now: Instant, frame: &Frame, ecu: &mut impl Backend) {
        if !self.accepts(frame.id()) {
            return;
        }
        let mut backend = self.with_stack(now, ecu);
        if frame.id() == DIAG_FUNCTIONAL_REQUEST_ID && self.answer_obd(frame, &mut backend) {
            return;
        }
        if let Some(event) = self.channel.on_frame(now, frame) {
            self.on_event(now, event, &mut backend);
        }
    }

    fn with_stack<'a, B: Backend>(&self, now: Instant, ecu: &'a mut B) -> WithStack<'a, B> {
        WithStack {
            ecu,
            node: self.node,
            sent: self.sent,
            speed_kmh: self.vehicle_speed_kmh(now),
            standing: self.vehicle_standing(now),
        }
    }

    /// Timeouts, the session timer, a slice of programming, the next step of a long
    /// operation. Call often (every millisecond in the virtual car, every loop on the MCU).
    pub fn poll(&mut self, now: Instant, ecu: &mut impl Backend) {
        let backend = &mut self.with_stack(now, ecu);
        while let Some(event) = self.channel.poll(now) {
            self.on_event(now, event, backend);
        }
        self.server.poll(now, backend);
        self.server.program_step(backend, PROGRAM_SLICE);
        if self.resume_after_send && self.channel.is_idle() && self.queued.is_none() {
            self.resume_after_send = false;
            let reply = self.server.resume(now, backend, &mut self.response);
            self.on_reply(now, reply);
        }
        self.flush_queued(now);
    }

    /// The next frame to send, if any.
    pub fn poll_transmit(&mut self, now: Instant) -> Option<Frame> {
        if self.handed != Handed::Nothing {
            return None;
        }
        if let Some(frame) = self.obd_frame.take() {
            self.handed = Handed::Obd;
            return Some(frame);
        }
        let frame = self.channel.poll_transmit(now)?;
        self.handed = Handed::Channel;
        Some(frame)
    }

    /// The frame last handed out by [`DiagNode::poll_transmit`] is on the bus.
    pub fn confirm_transmit(&mut self, now: Instant) {
        if self.handed == Handed::Channel {
            self.channel.confirm_transmit(now);
        }
        self.handed = Handed::Nothing;
    }

    /// A reset the tester asked for, once its response is out: the ECU performs it (on
    /// the MCU a system reset into the bootloader; in the virtual car the same).
    pub fn take_reset(&mut self) -> Option<ResetKind> {
        self.reset_due.take()
    }

    fn on_event(&mut self, now: Instant, event: Event, backend: &mut impl Backend) {
        match event {
            Event::Received { len, functional } => {
                let request = &self.channel.received()[..len];
                let reply =
                    self.server
                        .handle(now, request, functional, backend, &mut self.response);
                self.channel.release();
                self.on_reply(now, reply);
            }
            Event::Sent => {
                if let Some(kind) = self.reset_after_send.take() {
                    self.reset_due = Some(kind);
                }
            }
            // A lost PDU: the tester repeats its request after its own timeout.
            Event::Error(_) => {}
        }
    }

    fn on_reply(&mut self, now: Instant, reply: Reply) {
        match reply {
            Reply::Nothing => {}
            Reply::Send(len) => self.send(now, len),
            Reply::Pending(len) => {
                self.send(now, len);
                self.resume_after_send = true;
            }
            Reply::Working => self.resume_after_send = true,
            Reply::SendThenReset(0, kind) => self.reset_due = Some(kind),
            Reply::SendThenReset(len, kind) => {
                self.reset_after_send = Some(kind);
                self.send(now, len);
            }
        }
    }

    fn send(&mut self, now: Instant, len: usize) {
        if self.channel.send(now, &self.response[..len]).is_err() {
            self.queued = Some(len);
        }
    }

    fn flush_queued(&mut self, now: Instant) {
        if let Some(len) = self.queued {
            if self.channel.send(now, &self.response[..len]).is_ok() {
                self.queued = None;
            }
        }
    }

    /// OBD-II mode 01 on the functional identifier, for the ECUs with an OBD response
    /// identifier. Returns whether the frame was an OBD-II request (answered or not).
    fn answer_obd(&mut self, frame: &Frame, backend: &mut impl Backend) -> bool {
        let data = frame.data();
        // A single frame (PCI 0x0L) whose service is mode 01.
        let Some(&pci) = data.first() else {
            return false;
        };
        let len = usize::from(pci & 0x0F);
        if pci >> 4 != 0 || len == 0 || len + 1 > data.len() || data[1] != 0x01 {
            return false;
        }
        let Some(response_id) = self.node.obd_response_id() else {
            return true; // not an OBD-II ECU: silent, as OBD-II wants
        };
        let mut out = [0u8; 8];
        if let Some(n) = answer_mode01(&data[1..1 + len], backend, &mut out[1..]) {
            out[0] = n as u8;
            out[1 + n..].fill(PADDING);
            self.obd_frame = Frame::new(u32::from(response_id), &out).ok();
        }
        true
    }
}
