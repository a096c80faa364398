//! The UDS server: one per ECU, fed whole request PDUs (ISO-TP reassembles them) and
//! answering with whole response PDUs. What the ECU itself provides (identification, live
//! data, DTCs, the flash it programs) comes through [`Backend`]; everything a tester can
//! see of the protocol (sessions, timing, security, the order of a download and the checks
//! of an image) is decided here, the same on the MCU and in the virtual car.

use autoplug_ecu::{status, Dtc, Dtcs, Instant};
use autoplug_image::{
    BootState, Expectations, ImageError, ImageHeader, ImageSlot, StreamVerifier, HEADER_LEN,
    SIGNATURE_LEN,
};

use crate::nrc::{sid, Nrc};
use crate::security::{key_for, keys_match, KEY_LEN, SEED_LEN};

/// Diagnostic sessions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
pub enum Session {
    /// 0x01: after power-up; reading only.
    Default = 0x01,
    /// 0x02: download and the programming routines.
    Programming = 0x02,
    /// 0x03: communication control, DTC setting, security access.
    Extended = 0x03,
}

/// Timing and security parameters of a server.
#[derive(Clone, Copy, Debug)]
pub struct Config {
    /// The ECU's diagnostic node number (part of the security key's MAC).
    pub node: u8,
    /// The secret shared with the tester for SecurityAccess.
    pub security_secret: &'static [u8],
    /// P2server: the longest time to the first response, announced in 0x50 (ms).
    pub p2_ms: u16,
    /// P2*server: the longest time after a 0x78 "response pending", announced in 0x50 (ms).
    pub p2_star_ms: u32,
    /// S3server: a non-default session without requests for this long ends (µs).
    pub s3_us: u64,
    /// Wrong keys in a row that lock security access.
    pub max_key_attempts: u8,
    /// How long the lock lasts (µs).
    pub lockout_us: u64,
}

impl Config {
    /// ISO 14229-2 default timing (P2 50 ms, P2* 5000 ms, S3 5000 ms); security locks for
    /// 10 s after 3 wrong keys.
    pub const fn new(node: u8, security_secret: &'static [u8]) -> Self {
        Self {
            node,
            security_secret,
            p2_ms: 50,
            p2_star_ms: 5_000,
            s3_us: 5_000_000,
            max_key_attempts: 3,
            lockout_us: 10_000_000,
        }
    }
}

/// Identification data of the ECU, for the F18x DIDs.
#[derive(Clone, Copy, Debug)]
pub struct Identification<'a> {
    /// F187: spare part number.
    pub part_number: &'a [u8],
    /// F189: application software version.
    pub software_version: &'a [u8],
    /// F18C: ECU serial number.
    pub serial_number: &'a [u8],
    /// F191: hardware version.
    pub hardware_version: &'a [u8],
    /// F190: the vehicle's VIN (17 characters), as the ECU was told it at the end of the
    /// line; empty while it has none (F190 is then not answered).
    pub vin: &'a [u8],
    /// F1A0: the image slot the ECU runs and how that image stands (`None` on an ECU
    /// without slots: F1A0 is then not answered).
    pub boot_slot: Option<(ImageSlot, BootState)>,
}

/// The two data bytes of DID F1A0: the running slot's number (A 0, B 1) and its state
/// ([`BootState::number`]: 0 confirmed, 1 on trial, 2 reverted).
pub const fn boot_slot_bytes(slot: ImageSlot, state: BootState) -> [u8; 2] {
    [slot.number(), state.number()]
}

/// What DID F1A0's data bytes say; `None` for bytes no ECU sends.
pub fn parse_boot_slot(bytes: &[u8]) -> Option<(ImageSlot, BootState)> {
    match bytes {
        [slot, state] => Some((
            ImageSlot::from_number(*slot)?,
            BootState::from_number(*state)?,
        )),
        _ => None,
    }
}

/// A flash operation failed (the backend logs the detail).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FlashError;

/// What the ECU provides to its UDS server.
pub trait Backend {
    /// Identification data.
    fn identification(&self) -> Identification<'_>;
    /// Live data: writes DID `did` into `out` and returns its length, or `None` for a DID
    /// this ECU does not have. [`crate::DiagNode`] answers it from the ECU's own frames.
    fn read_live_data(&mut self, did: u16, out: &mut [u8]) -> Option<usize> {
        let _ = (did, out);
        None
    }
    /// Vehicle speed as the ECU knows it, km/h; `None` while unknown (which counts as
    /// moving). [`crate::DiagNode`] answers it from the VehicleSpeedMsg it sees.
    fn vehicle_speed_kmh(&self) -> Option<f32> {
        None
    }
    /// Whether the car is proven to stand (programming is refused otherwise). By default:
    /// a known speed under 1 km/h. [`crate::DiagNode`] asks for more: every VehicleSpeedMsg
    /// of the last half second at its period, all standing (one spoofed frame is no proof).
    fn vehicle_standing(&self) -> bool {
        self.vehicle_speed_kmh().is_some_and(|v| v < STANDING_KMH)
            && !self.own_sensors_show_motion()
    }
    /// Whether the ECU's own sensors show the car moving or the engine above idle
    /// (`autoplug_ecu::EcuLogic::own_sensors_show_motion`): a veto on programming.
    fn own_sensors_show_motion(&self) -> bool {
        false
    }
    /// The ECU's DTCs.
    fn dtcs(&mut self) -> &mut Dtcs;
    /// Unpredictable bytes for a security seed (a [`crate::security::SeedSource`]).
    fn fill_random(&mut self, out: &mut [u8]);
    /// Wrong SecurityAccess keys in a row as the ECU keeps them across resets and power
    /// cycles (ISO 14229-1: the delay survives a reset). Read once after the start.
    fn stored_key_failures(&mut self) -> u8;
    /// Keeps the count of wrong keys in a row. The server counts an attempt *before* it
    /// checks the key, so a power cut at the check costs the attacker the attempt; `Err`
    /// (nothing kept) refuses the check.
    fn store_key_failures(&mut self, failures: u8) -> Result<(), FlashError>;
    /// What an image must be to be installed here.
    fn image_expectations(&self) -> Expectations;
    /// The key images are signed with.
    fn public_key(&self) -> [u8; 32];
    /// Number of erase steps (one step: one sector, from the start of the DFU slot, the
    /// image slot the ECU is not running) that cover its first `len` bytes. Only those are
    /// erased before a download.
    fn dfu_erase_steps(&self, len: u32) -> u32;
    /// Erases step `step` of the DFU slot (the core may stall for a second). The first
    /// step also withdraws an earlier download's trial mark of that slot.
    fn dfu_erase(&mut self, step: u32) -> Result<(), FlashError>;
    /// Programs `data` at `offset` in the DFU slot (erased before). Both are whole 32-bit
    /// flash words: multiples of 4.
    fn dfu_write(&mut self, offset: u32, data: &[u8]) -> Result<(), FlashError>;
    /// Reads the DFU slot.
    fn dfu_read(&mut self, offset: u32, out: &mut [u8]) -> Result<(), FlashError>;
    /// Marks the verified image in the DFU slot for a trial start at the next reset.
    fn mark_updated(&mut self) -> Result<(), FlashError>;
    /// The OBD-II mode 01 PIDs this ECU owns (not counting the support bitmaps);
    /// [`crate::DiagNode`] answers them from the ECU's own frames.
    fn obd_pids(&self) -> &'static [u8] {
        &[]
    }
    /// Writes the data bytes of mode 01 PID `pid` (one of [`Backend::obd_pids`]); `None`
    /// while the value is unknown.
    fn obd_read(&mut self, pid: u8, out: &mut [u8]) -> Option<usize> {
        let _ = (pid, out);
        None
    }
}

/// The kinds of reset 0x11 asks for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(target_os = "none", derive(defmt::Format))]
pub enum ResetKind {
    /// 0x01: as a power cycle.
    Hard,
    /// 0x03: the application restarts.
    Soft,
}

/// What to do with the response buffer after a call.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reply {
    /// Nothing to send (suppressed positive response, or a functional request this ECU does
    /// not answer).
    Nothing,
    /// Send the first `n` bytes.
    Send(usize),
    /// Send the first `n` bytes (a 0x78 "response pending"), then call
    /// [`Server::resume`] until it returns something else.
    Pending(usize),
    /// Nothing to send yet: call [`Server::resume`] again.
    Working,
    /// Send the first `n` bytes, then reset the ECU.
    SendThenReset(usize, ResetKind),
}

/// Routine identifiers (ISO 14229-1 annex F): erase memory, check programming
/// dependencies (here: the downloaded image verifies and fits this ECU).
pub const ROUTINE_ERASE_MEMORY: u16 = 0xFF00;
/// See [`ROUTINE_ERASE_MEMORY`].
pub const ROUTINE_CHECK_PROGRAMMING_DEPENDENCIES: u16 = 0xFF01;

/// Identification DIDs.
pub mod did {
    /// Active diagnostic session (1 byte).
    pub const ACTIVE_SESSION: u16 = 0xF186;
    /// Spare part number.
    pub const PART_NUMBER: u16 = 0xF187;
    /// Application software version.
    pub const SOFTWARE_VERSION: u16 = 0xF189;
    /// ECU serial number.
    pub const SERIAL_NUMBER: u16 = 0xF18C;
    /// Hardware version.
    pub const HARDWARE_VERSION: u16 = 0xF191;
    /// Vehicle identification number (ISO 3779, 17 characters).
    pub const VIN: u16 = 0xF190;
    /// The running image slot and its state (2 bytes, [`super::boot_slot_bytes`]); in
    /// ISO 14229-1's vehicle-manufacturer-specific identification range F1A0–F1EF.
    pub const BOOT_SLOT: u16 = 0xF1A0;
}

/// Bytes of TransferData payload per block a tester may send: the 4095 bytes of an ISO-TP
/// PDU less the SID and the block counter. Announced in the 0x74 response as the block
/// length including those two bytes.
pub const MAX_BLOCK_LEN: u16 = 4095;

/// Bytes of the DFU slot read per [`Server::resume`] call while checking an image.
const CHECK_CHUNK: usize = 1024;

/// Programming granularity: slices of a block end on this many bytes (the F4 programs
/// 32-bit words).
const PROGRAM_ALIGN: usize = 4;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Security {
    Locked,
    SeedSent([u8; SEED_LEN]),
    Unlocked,
}

#[derive(Clone, Debug)]
enum Programming {
    /// Nothing erased since the last download (or since power-up).
    Idle,
    /// The first `len` bytes of the DFU slot are erased: a download of up to that
    /// many bytes may start.
    Erased { len: u32 },
    /// A download is under way.
    Downloading {
        size: u32,
        received: u32,
        /// The counter of the last block written (0 before the first; it wraps 0xFF → 0x00).
        last_counter: u8,
        header_checked: bool,
    },
    /// All bytes are in: the image may be checked.
    Downloaded { size: u32 },
    /// The image verified and is marked for its trial start.
    Verified,
}

// One `Work` lives inside the server at a time and there is no allocator to box the
// verifier's state into: the size difference is the point.
#[allow(clippy::large_enum_variant)]
#[derive(Debug)]
enum Work {
    Erase {
        step: u32,
        steps: u32,
        /// Bytes from the partition's start that the steps erase.
        len: u32,
    },
    Check {
        header: ImageHeader,
        verifier: StreamVerifier,
        offset: u32,
        signed_len: u32,
    },
}

/// The UDS server of one ECU.
#[derive(Debug)]
pub struct Server {
    config: Config,
    session: Session,
    last_request: Instant,
    security: Security,
    failed_keys: u8,
    /// Whether `failed_keys` was read from the ECU's flash since the start.
    failures_loaded: bool,
    locked_until: Option<Instant>,
    normal_rx: bool,
    normal_tx: bool,
    dtc_setting_on: bool,
    programming: Programming,
    work: Option<Work>,
    last_image_error: Option<ImageError>,
    /// The last TransferData block, acknowledged but not yet (completely) programmed: it
    /// is written in slices while the next block crosses the bus ([`Server::program_step`]),
    /// so that programming, which stalls the core, never holds up the transfer.
    unwritten: Unwritten,
}

/// Data of a TransferData block waiting to be programmed.
#[derive(Debug)]
struct Unwritten {
    /// The last block's bytes of whole flash words (the previous block's partial word in
    /// front); a final partial word is padded with the erased value.
    data: [u8; MAX_BLOCK_LEN as usize + PROGRAM_ALIGN],
    /// DFU offset of `data[0]` (a multiple of [`PROGRAM_ALIGN`]).
    offset: u32,
    /// Bytes of `data` to program (a multiple of [`PROGRAM_ALIGN`]).
    len: usize,
    /// Bytes of `data` already programmed.
    written: usize,
    /// The bytes of a word the block ended in, programmed with the next block.
    carry: [u8; PROGRAM_ALIGN],
    carry_len: usize,
    /// A slice failed: the download is lost, reported at the next request.
    failed: bool,
}

impl Unwritten {
    const fn new() -> Self {
        Self {
            data: [0; MAX_BLOCK_LEN as usize + PROGRAM_ALIGN],
            offset: 0,
            len: 0,
            written: 0,
            carry: [0; PROGRAM_ALIGN],
            carry_len: 0,
            failed: false,
        }
    }

    fn is_empty(&self) -> bool {
        self.written == self.len
    }

    /// Takes a block received at DFU offset `at` (right after the previous one): the
    /// carried partial word and the block's whole words become the data to program, its
    /// last partial word is carried, or padded with 0xFF (the erased value, which
    /// programming leaves as it is) when `last` ends the download.
    fn take_block(&mut self, at: u32, block: &[u8], last: bool) {
        let carried = self.carry_len;
        self.data[..carried].copy_from_slice(&self.carry[..carried]);
        self.data[carried..carried + block.len()].copy_from_slice(block);
        let total = carried + block.len();
        let whole = total - total % PROGRAM_ALIGN;
        self.offset = at - carried as u32;
        self.written = 0;
        if last {
            let padded = total.div_ceil(PROGRAM_ALIGN) * PROGRAM_ALIGN;
            self.data[total..padded].fill(0xFF);
            self.len = padded;
            self.carry_len = 0;
        } else {
            self.len = whole;
            self.carry_len = total - whole;
            self.carry[..self.carry_len].copy_from_slice(&self.data[whole..total]);
        }
    }
}

impl Server {
    /// A server in the default session, as after power-up.
    pub fn new(config: Config, now: Instant) -> Self {
        Self {
            config,
            session: Session::Default,
            last_request: now,
            security: Security::Locked,
            failed_keys: 0,
            failures_loaded: false,
            locked_until: None,
            normal_rx: true,
            normal_tx: true,
            dtc_setting_on: true,
            programming: Programming::Idle,
            work: None,
            last_image_error: None,
            unwritten: Unwritten::new(),
        }
    }

    /// Whether acknowledged download data still waits to be programmed.
    pub fn programming_pending(&self) -> bool {
        !self.unwritten.is_empty()
    }

    /// Programs up to `max_bytes` of the acknowledged download data (whole flash words;
    /// the caller picks a slice short enough for the ECU to keep up with the bus while the
    /// core stalls). Returns whether data is left.
    pub fn program_step(&mut self, backend: &mut impl Backend, max_bytes: usize) -> bool {
        let pending = &mut self.unwritten;
        if pending.is_empty() {
            return false;
        }
        // Whole flash words: the data starts and ends on a word.
        let slice = max_bytes.max(PROGRAM_ALIGN) / PROGRAM_ALIGN * PROGRAM_ALIGN;
        let end = pending.written.saturating_add(slice).min(pending.len);
        let offset = pending.offset + pending.written as u32;
        if backend
            .dfu_write(offset, &pending.data[pending.written..end])
            .is_err()
        {
            pending.failed = true;
            pending.written = pending.len;
            return false;
        }
        pending.written = end;
        !pending.is_empty()
    }

    /// Programs everything acknowledged; `Err` when a write failed (now or in an earlier
    /// slice), which loses the download.
    fn finish_programming(&mut self, backend: &mut impl Backend) -> Result<(), Nrc> {
        while self.program_step(backend, usize::MAX) {}
        if core::mem::take(&mut self.unwritten.failed) {
            self.programming = Programming::Idle;
            return Err(Nrc::GeneralProgrammingFailure);
        }
        Ok(())
    }

    /// The timing and security parameters it was made with.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The active session.
    pub fn session(&self) -> Session {
        self.session
    }

    /// Whether the application may send its normal messages (0x28 can switch them off).
    pub fn normal_tx_enabled(&self) -> bool {
        self.normal_tx
    }

    /// Whether the application should act on received normal messages.
    pub fn normal_rx_enabled(&self) -> bool {
        self.normal_rx
    }

    /// Whether DTCs are recorded (0x85 can switch it off).
    pub fn dtc_setting_on(&self) -> bool {
        self.dtc_setting_on
    }

    /// Whether security access is granted.
    pub fn unlocked(&self) -> bool {
        self.security == Security::Unlocked
    }

    /// Why the last image was refused, for logs and the tester's report.
    pub fn last_image_error(&self) -> Option<&ImageError> {
        self.last_image_error.as_ref()
    }

    /// Whether a long operation is under way ([`Server::resume`] has work to do).
    pub fn busy(&self) -> bool {
        self.work.is_some()
    }

    /// Ends a non-default session after S3 without requests: back to the default session,
    /// security locked, communication and DTC setting restored, a download abandoned.
    pub fn poll(&mut self, now: Instant, backend: &mut impl Backend) {
        if self.session != Session::Default
            && self.work.is_none()
            && now.micros_since(self.last_request) > self.config.s3_us
        {
            self.enter_default_session(backend);
        }
        self.load_key_failures(now, backend);
        self.lockout_active(now);
    }

    /// Takes the wrong keys counted before the last reset; if they reached the limit, the
    /// delay runs again from the start (the ECU has no clock that survives a reset).
    fn load_key_failures(&mut self, now: Instant, backend: &mut impl Backend) {
        if self.failures_loaded {
            return;
        }
        self.failures_loaded = true;
        self.failed_keys = backend.stored_key_failures();
        if self.failed_keys >= self.config.max_key_attempts {
            self.locked_until = Some(now.plus_micros(self.config.lockout_us));
        }
    }

    /// Handles one request PDU; writes the response into `out`, which must hold at least
    /// [`MIN_RESPONSE_BUFFER`] bytes (longer lists than `out` holds are refused with
    /// "response too long"). `functional`: the request came on the functional identifier,
    /// where a negative response for an unknown service, sub-function or identifier is
    /// not sent.
    pub fn handle(
        &mut self,
        now: Instant,
        request: &[u8],
        functional: bool,
        backend: &mut impl Backend,
        out: &mut [u8],
    ) -> Reply {
        let Some(&service) = request.first() else {
            return Reply::Nothing;
        };
        assert!(
            out.len() >= MIN_RESPONSE_BUFFER,
            "response buffer too small"
        );
        self.last_request = now;
        if self.work.is_some() {
            // One request at a time: the tester waits for the final response.
            return negative(service, Nrc::ConditionsNotCorrect, out);
        }
        let result = self.dispatch(now, service, request, backend, out);
        match result {
            Ok(reply) => reply,
            Err(nrc) if functional && suppressed_when_functional(nrc) => Reply::Nothing,
            Err(nrc) => negative(service, nrc, out),
        }
    }

    /// Continues a long operation (erase, image check) by one step; sends "response
    /// pending" before each step that may stall the core, and the final response at the
    /// end.
    pub fn resume(&mut self, now: Instant, backend: &mut impl Backend, out: &mut [u8]) -> Reply {
        self.last_request = now;
        let Some(work) = self.work.take() else {
            return Reply::Nothing;
        };
        match work {
            Work::Erase { step, steps, len } => {
                if backend.dfu_erase(step).is_err() {
                    self.programming = Programming::Idle;
                    return negative(sid::ROUTINE_CONTROL, Nrc::GeneralProgrammingFailure, out);
                }
                if step + 1 < steps {
                    self.work = Some(Work::Erase {
                        step: step + 1,
                        steps,
                        len,
                    });
                    // The next sector stalls the core again: keep the tester waiting.
                    return pending(sid::ROUTINE_CONTROL, out);
                }
                self.programming = Programming::Erased { len };
                Reply::Send(routine_ok(ROUTINE_ERASE_MEMORY, out))
            }
            Work::Check {
                header,
                mut verifier,
                offset,
                signed_len,
            } => {
                let mut chunk = [0u8; CHECK_CHUNK];
                let len = (signed_len - offset).min(CHECK_CHUNK as u32) as usize;
                if backend.dfu_read(offset, &mut chunk[..len]).is_err() {
                    self.programming = Programming::Idle;
                    return negative(sid::ROUTINE_CONTROL, Nrc::GeneralProgrammingFailure, out);
                }
                verifier.update(&chunk[..len]);
                let offset = offset + len as u32;
                if offset < signed_len {
                    self.work = Some(Work::Check {
                        header,
                        verifier,
                        offset,
                        signed_len,
                    });
                    return Reply::Working;
                }
                let mut signature = [0u8; SIGNATURE_LEN];
                let verdict = match backend.dfu_read(signed_len, &mut signature) {
                    Ok(()) => verifier.finish(&signature, &backend.public_key()),
                    Err(FlashError) => Err(ImageError::BadSignature),
                };
                match verdict.map(|()| backend.mark_updated()) {
                    Ok(Ok(())) => {
                        self.programming = Programming::Verified;
                        self.last_image_error = None;
                        Reply::Send(routine_ok(ROUTINE_CHECK_PROGRAMMING_DEPENDENCIES, out))
                    }
                    Ok(Err(FlashError)) => {
                        self.programming = Programming::Idle;
                        negative(sid::ROUTINE_CONTROL, Nrc::GeneralProgrammingFailure, out)
                    }
                    Err(error) => {
                        self.refuse_image(error);
                        negative(sid::ROUTINE_CONTROL, Nrc::GeneralProgrammingFailure, out)
                    }
                }
            }
        }
    }

    fn dispatch(
        &mut self,
        now: Instant,
        service: u8,
        request: &[u8],
        backend: &mut impl Backend,
        out: &mut [u8],
    ) -> Result<Reply, Nrc> {
        match service {
            sid::SESSION_CONTROL => self.session_control(request, backend, out),
            sid::ECU_RESET => self.ecu_reset(request, out),
            sid::TESTER_PRESENT => {
                let sub = sub_function(request, Length::Exactly(2))?;
                if sub & 0x7F != 0 {
                    return Err(Nrc::SubFunctionNotSupported);
                }
                Ok(positive(request, &[sub & 0x7F], out))
            }
            sid::READ_DID => self.read_data(request, backend, out),
            sid::SECURITY_ACCESS => self.security_access(now, request, backend, out),
            sid::COMMUNICATION_CONTROL => self.communication_control(request, out),
            sid::CONTROL_DTC_SETTING => self.control_dtc_setting(request, backend, out),
            sid::READ_DTC => read_dtc_information(request, backend.dtcs(), out),
            sid::CLEAR_DTC => {
                if request.len() != 4 {
                    return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
                }
                let group = u32::from_be_bytes([0, request[1], request[2], request[3]]);
                if group != 0xFF_FFFF {
                    // Only "all groups": the ECUs keep few codes, and a tester clears them all.
                    return Err(Nrc::RequestOutOfRange);
                }
                backend.dtcs().clear();
                Ok(Reply::Send(write(
                    out,
                    &[sid::CLEAR_DTC + sid::POSITIVE_OFFSET],
                )))
            }
            sid::ROUTINE_CONTROL => self.routine_control(request, backend, out),
            sid::REQUEST_DOWNLOAD => self.request_download(request, backend, out),
            sid::TRANSFER_DATA => self.transfer_data(request, backend, out),
            sid::REQUEST_TRANSFER_EXIT => self.request_transfer_exit(request, backend, out),
            _ => Err(Nrc::ServiceNotSupported),
        }
    }

    fn session_control(
        &mut self,
        request: &[u8],
        backend: &mut impl Backend,
        out: &mut [u8],
    ) -> Result<Reply, Nrc> {
        let sub = sub_function(request, Length::Exactly(2))?;
        let session = match sub & 0x7F {
            0x01 => Session::Default,
            0x02 => Session::Programming,
            0x03 => Session::Extended,
            _ => return Err(Nrc::SubFunctionNotSupported),
        };
        if session == Session::Programming && !vehicle_stationary(backend) {
            return Err(Nrc::ConditionsNotCorrect);
        }
        if session == Session::Default {
            self.enter_default_session(backend);
        } else if session != self.session {
            // A change of session relocks security (ISO 14229-1 9.2).
            self.security = Security::Locked;
            self.session = session;
        }
        let p2 = self.config.p2_ms.to_be_bytes();
        let p2_star = ((self.config.p2_star_ms / 10) as u16).to_be_bytes();
        if sub & 0x80 != 0 {
            return Ok(Reply::Nothing);
        }
        Ok(Reply::Send(write(
            out,
            &[
                sid::SESSION_CONTROL + sid::POSITIVE_OFFSET,
                sub,
                p2[0],
                p2[1],
                p2_star[0],
                p2_star[1],
            ],
        )))
    }

    fn enter_default_session(&mut self, backend: &mut impl Backend) {
        self.session = Session::Default;
        self.security = Security::Locked;
        self.normal_rx = true;
        self.normal_tx = true;
        self.dtc_setting_on = true;
        backend.dtcs().set_recording(true);
        if !matches!(self.programming, Programming::Verified) {
            self.programming = Programming::Idle;
            self.unwritten = Unwritten::new();
        }
    }

    fn ecu_reset(&mut self, request: &[u8], out: &mut [u8]) -> Result<Reply, Nrc> {
        let sub = sub_function(request, Length::Exactly(2))?;
        let kind = match sub & 0x7F {
            0x01 => ResetKind::Hard,
            0x03 => ResetKind::Soft,
            _ => return Err(Nrc::SubFunctionNotSupported),
        };
        if self.work.is_some() {
            return Err(Nrc::ConditionsNotCorrect);
        }
        let len = if sub & 0x80 != 0 {
            0
        } else {
            write(out, &[sid::ECU_RESET + sid::POSITIVE_OFFSET, sub])
        };
        Ok(Reply::SendThenReset(len, kind))
    }

    fn read_data(
        &mut self,
        request: &[u8],
        backend: &mut impl Backend,
        out: &mut [u8],
    ) -> Result<Reply, Nrc> {
        let dids = &request[1..];
        if dids.is_empty() || dids.len() % 2 != 0 {
            return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
        }
        out[0] = sid::READ_DID + sid::POSITIVE_OFFSET;
        let mut len = 1;
        let mut found = 0;
        for pair in dids.chunks_exact(2) {
            let did = u16::from_be_bytes([pair[0], pair[1]]);
            let room = out.len().checked_sub(len + 2).ok_or(Nrc::ResponseTooLong)?;
            let data = &mut out[len + 2..];
            let ident = backend.identification();
            let boot_slot = ident
                .boot_slot
                .map(|(slot, state)| boot_slot_bytes(slot, state));
            let fixed: Option<&[u8]> = match did {
                did::PART_NUMBER => Some(ident.part_number),
                did::SOFTWARE_VERSION => Some(ident.software_version),
                did::SERIAL_NUMBER => Some(ident.serial_number),
                did::HARDWARE_VERSION => Some(ident.hardware_version),
                did::VIN if !ident.vin.is_empty() => Some(ident.vin),
                did::BOOT_SLOT => boot_slot.as_ref().map(|bytes| bytes.as_slice()),
                did::ACTIVE_SESSION => Some(match self.session {
                    Session::Default => &[0x01],
                    Session::Programming => &[0x02],
                    Session::Extended => &[0x03],
                }),
                _ => None,
            };
            let written = match fixed {
                Some(bytes) if bytes.len() > room => return Err(Nrc::ResponseTooLong),
                Some(bytes) => {
                    data[..bytes.len()].copy_from_slice(bytes);
                    Some(bytes.len())
                }
                None => backend.read_live_data(did, data),
            };
            if let Some(n) = written {
                out[len..len + 2].copy_from_slice(&did.to_be_bytes());
                len += 2 + n;
                found += 1;
            }
        }
        if found == 0 {
            return Err(Nrc::RequestOutOfRange);
        }
        Ok(Reply::Send(len))
    }

    fn security_access(
        &mut self,
        now: Instant,
        request: &[u8],
        backend: &mut impl Backend,
        out: &mut [u8],
    ) -> Result<Reply, Nrc> {
        let sub = sub_function(request, Length::AtLeastSubFunction)?;
        if self.session == Session::Default {
            return Err(Nrc::ServiceNotSupportedInActiveSession);
        }
        self.load_key_failures(now, backend);
        match sub & 0x7F {
            0x01 => {
                if request.len() != 2 {
                    return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
                }
                if self.lockout_active(now) {
                    return Err(Nrc::RequiredTimeDelayNotExpired);
                }
                let mut seed = [0u8; SEED_LEN];
                if self.security != Security::Unlocked {
                    // An all-zero seed means "already unlocked": never hand one out otherwise.
                    while seed.iter().all(|&b| b == 0) {
                        backend.fill_random(&mut seed);
                    }
                    self.security = Security::SeedSent(seed);
                }
                let mut response = [0u8; 2 + SEED_LEN];
                response[0] = sid::SECURITY_ACCESS + sid::POSITIVE_OFFSET;
                response[1] = sub;
                response[2..].copy_from_slice(&seed);
                Ok(Reply::Send(write(out, &response)))
            }
            0x02 => {
                let Security::SeedSent(seed) = self.security else {
                    return Err(Nrc::RequestSequenceError);
                };
                if request.len() != 2 + KEY_LEN {
                    return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
                }
                // A seed is good for one try.
                self.security = Security::Locked;
                // The attempt is counted in flash before the key is looked at.
                let failures = self.failed_keys.saturating_add(1);
                if backend.store_key_failures(failures).is_err() {
                    return Err(Nrc::ConditionsNotCorrect);
                }
                let expected = key_for(self.config.security_secret, self.config.node, &seed);
                if keys_match(&request[2..], &expected) {
                    self.security = Security::Unlocked;
                    self.failed_keys = 0;
                    // Not kept: the next reset counts one attempt too many, never too few.
                    let _ = backend.store_key_failures(0);
                    return Ok(positive(request, &[sub], out));
                }
                self.failed_keys = failures;
                if self.failed_keys >= self.config.max_key_attempts {
                    self.locked_until = Some(now.plus_micros(self.config.lockout_us));
                    return Err(Nrc::ExceededNumberOfAttempts);
                }
                Err(Nrc::InvalidKey)
            }
            _ => Err(Nrc::SubFunctionNotSupported),
        }
    }

    fn lockout_active(&mut self, now: Instant) -> bool {
        match self.locked_until {
            Some(until) if now.as_micros() < until.as_micros() => true,
            Some(_) => {
                self.locked_until = None;
                self.failed_keys = 0;
                false
            }
            None => false,
        }
    }

    fn communication_control(&mut self, request: &[u8], out: &mut [u8]) -> Result<Reply, Nrc> {
        let sub = sub_function(request, Length::Exactly(3))?;
        if request.len() != 3 {
            return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
        }
        if self.session == Session::Default {
            return Err(Nrc::ServiceNotSupportedInActiveSession);
        }
        let (rx, tx) = match sub & 0x7F {
            0x00 => (true, true),
            0x01 => (true, false),
            0x02 => (false, true),
            0x03 => (false, false),
            _ => return Err(Nrc::SubFunctionNotSupported),
        };
        // Communication type: bits 0..1 select normal (1) and network management (2)
        // messages; this network has no network management, so only normal ones matter.
        let comm_type = request[2] & 0x03;
        if comm_type == 0 {
            return Err(Nrc::RequestOutOfRange);
        }
        if comm_type & 0x01 != 0 {
            self.normal_rx = rx;
            self.normal_tx = tx;
        }
        Ok(positive(request, &[sub & 0x7F], out))
    }

    fn control_dtc_setting(
        &mut self,
        request: &[u8],
        backend: &mut impl Backend,
        out: &mut [u8],
    ) -> Result<Reply, Nrc> {
        let sub = sub_function(request, Length::Exactly(2))?;
        if self.session == Session::Default {
            return Err(Nrc::ServiceNotSupportedInActiveSession);
        }
        let on = match sub & 0x7F {
            0x01 => true,
            0x02 => false,
            _ => return Err(Nrc::SubFunctionNotSupported),
        };
        self.dtc_setting_on = on;
        backend.dtcs().set_recording(on);
        Ok(positive(request, &[sub & 0x7F], out))
    }

    fn routine_control(
        &mut self,
        request: &[u8],
        backend: &mut impl Backend,
        out: &mut [u8],
    ) -> Result<Reply, Nrc> {
        if request.len() < 4 {
            return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
        }
        let sub = request[1] & 0x7F;
        let routine = u16::from_be_bytes([request[2], request[3]]);
        if routine != ROUTINE_ERASE_MEMORY && routine != ROUTINE_CHECK_PROGRAMMING_DEPENDENCIES {
            return Err(Nrc::RequestOutOfRange);
        }
        if sub != 0x01 {
            return Err(Nrc::SubFunctionNotSupported);
        }
        if self.session != Session::Programming {
            return Err(Nrc::ServiceNotSupportedInActiveSession);
        }
        if !self.unlocked() {
            return Err(Nrc::SecurityAccessDenied);
        }
        if routine == ROUTINE_ERASE_MEMORY {
            // Only what the image needs: the size the tester gave, else the largest image.
            let len = self
                .check_erase_option(&request[4..], backend)?
                .unwrap_or(backend.image_expectations().max_image_len);
            if !vehicle_stationary(backend) {
                return Err(Nrc::ConditionsNotCorrect);
            }
            self.programming = Programming::Idle;
            self.unwritten = Unwritten::new();
            self.work = Some(Work::Erase {
                step: 0,
                steps: backend.dfu_erase_steps(len),
                len,
            });
            return Ok(pending(sid::ROUTINE_CONTROL, out));
        }
        if request.len() != 4 {
            return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
        }
        let Programming::Downloaded { size } = self.programming else {
            return Err(Nrc::RequestSequenceError);
        };
        let mut bytes = [0u8; HEADER_LEN];
        if size < (HEADER_LEN + SIGNATURE_LEN) as u32 || backend.dfu_read(0, &mut bytes).is_err() {
            self.refuse_image(ImageError::Truncated {
                expected: (HEADER_LEN + SIGNATURE_LEN) as u64,
                found: u64::from(size),
            });
            return Err(Nrc::GeneralProgrammingFailure);
        }
        // The header was checked when it arrived; parse it again from flash, which is what
        // the signature will be checked over.
        let header = match ImageHeader::parse(&bytes) {
            Ok(header) => header,
            Err(error) => {
                self.refuse_image(error);
                return Err(Nrc::GeneralProgrammingFailure);
            }
        };
        if let Err(error) = header.check(&backend.image_expectations()) {
            self.refuse_image(error);
            return Err(Nrc::GeneralProgrammingFailure);
        }
        if header.image_len() != u64::from(size) {
            self.refuse_image(ImageError::Truncated {
                expected: header.image_len(),
                found: u64::from(size),
            });
            return Err(Nrc::GeneralProgrammingFailure);
        }
        self.work = Some(Work::Check {
            signed_len: header.signed_len() as u32,
            header,
            verifier: StreamVerifier::new(),
            offset: 0,
        });
        Ok(pending(sid::ROUTINE_CONTROL, out))
    }

    /// The erase routine's option record: empty (room for the largest image), or
    /// addressAndLengthFormatIdentifier 0x44, the slot's address and a size within it
    /// (returned).
    fn check_erase_option(
        &self,
        option: &[u8],
        backend: &impl Backend,
    ) -> Result<Option<u32>, Nrc> {
        if option.is_empty() {
            return Ok(None);
        }
        let (address, size) = address_and_size(option)?;
        let expected = backend.image_expectations();
        if address != slot_address(&expected) || size == 0 || size > expected.max_image_len {
            return Err(Nrc::RequestOutOfRange);
        }
        Ok(Some(size))
    }

    fn request_download(
        &mut self,
        request: &[u8],
        backend: &mut impl Backend,
        out: &mut [u8],
    ) -> Result<Reply, Nrc> {
        if request.len() < 3 {
            return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
        }
        if self.session != Session::Programming {
            return Err(Nrc::ServiceNotSupportedInActiveSession);
        }
        if !self.unlocked() {
            return Err(Nrc::SecurityAccessDenied);
        }
        if request[1] != 0x00 {
            // Neither compression nor encryption is supported.
            return Err(Nrc::RequestOutOfRange);
        }
        let (address, size) = address_and_size(&request[2..])?;
        let expected = backend.image_expectations();
        if address != slot_address(&expected) {
            return Err(Nrc::RequestOutOfRange);
        }
        if size == 0 || size > expected.max_image_len {
            self.refuse_image(ImageError::Oversized {
                max: u64::from(expected.max_image_len),
                found: u64::from(size),
            });
            return Err(Nrc::UploadDownloadNotAccepted);
        }
        let Programming::Erased { len: erased } = self.programming else {
            return Err(Nrc::ConditionsNotCorrect);
        };
        if size > erased {
            // More than the erase routine was asked to make room for.
            self.refuse_image(ImageError::Oversized {
                max: u64::from(erased),
                found: u64::from(size),
            });
            return Err(Nrc::UploadDownloadNotAccepted);
        }
        self.programming = Programming::Downloading {
            size,
            received: 0,
            last_counter: 0,
            header_checked: false,
        };
        let block = MAX_BLOCK_LEN.to_be_bytes();
        // lengthFormatIdentifier 0x20: maxNumberOfBlockLength in two bytes.
        Ok(Reply::Send(write(
            out,
            &[
                sid::REQUEST_DOWNLOAD + sid::POSITIVE_OFFSET,
                0x20,
                block[0],
                block[1],
            ],
        )))
    }

    fn transfer_data(
        &mut self,
        request: &[u8],
        backend: &mut impl Backend,
        out: &mut [u8],
    ) -> Result<Reply, Nrc> {
        if request.len() < 2 || request.len() > usize::from(MAX_BLOCK_LEN) {
            return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
        }
        let Programming::Downloading {
            size,
            received,
            last_counter,
            header_checked,
        } = self.programming
        else {
            return Err(Nrc::RequestSequenceError);
        };
        let counter = request[1];
        let data = &request[2..];
        if counter == last_counter && received > 0 {
            // The tester repeated the last block (our response was lost): it is already
            // written, acknowledge it again.
            return Ok(positive(request, &[counter], out));
        }
        if counter != last_counter.wrapping_add(1) {
            return Err(Nrc::WrongBlockSequenceCounter);
        }
        if data.is_empty() {
            return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
        }
        let end = received + data.len() as u32;
        if end > size {
            self.programming = Programming::Idle;
            return Err(Nrc::TransferDataSuspended);
        }
        // The previous block must be in flash before this one takes the buffer (normally it
        // is: it was programmed while this block crossed the bus).
        self.finish_programming(backend)?;
        let mut header_checked = header_checked;
        if !header_checked && end as usize >= HEADER_LEN {
            // The header is complete: refuse an image that can never be installed here
            // before the rest of it crosses the bus. Its first bytes may already be in
            // flash (blocks shorter than a header).
            // Earlier blocks are in flash, but for the partial word carried to this block.
            let mut bytes = [0u8; HEADER_LEN];
            let before = (received as usize).min(HEADER_LEN);
            let carried = self.unwritten.carry_len;
            let in_flash = (received as usize - carried).min(HEADER_LEN);
            if backend.dfu_read(0, &mut bytes[..in_flash]).is_err() {
                self.programming = Programming::Idle;
                return Err(Nrc::GeneralProgrammingFailure);
            }
            bytes[in_flash..before].copy_from_slice(&self.unwritten.carry[..before - in_flash]);
            bytes[before..].copy_from_slice(&data[..HEADER_LEN - before]);
            let verdict = ImageHeader::parse(&bytes).and_then(|header| {
                header.check(&backend.image_expectations())?;
                if header.image_len() != u64::from(size) {
                    return Err(ImageError::Truncated {
                        expected: header.image_len(),
                        found: u64::from(size),
                    });
                }
                Ok(())
            });
            if let Err(error) = verdict {
                let nrc = image_refusal_nrc(&error);
                self.refuse_image(error);
                return Err(nrc);
            }
            header_checked = true;
        }
        self.unwritten.take_block(received, data, end == size);
        self.programming = Programming::Downloading {
            size,
            received: end,
            last_counter: counter,
            header_checked,
        };
        Ok(positive(request, &[counter], out))
    }

    fn request_transfer_exit(
        &mut self,
        request: &[u8],
        backend: &mut impl Backend,
        out: &mut [u8],
    ) -> Result<Reply, Nrc> {
        let Programming::Downloading { size, received, .. } = self.programming else {
            return Err(Nrc::RequestSequenceError);
        };
        if received != size {
            return Err(Nrc::RequestSequenceError);
        }
        let _ = request;
        self.finish_programming(backend)?;
        self.programming = Programming::Downloaded { size };
        Ok(Reply::Send(write(
            out,
            &[sid::REQUEST_TRANSFER_EXIT + sid::POSITIVE_OFFSET],
        )))
    }

    fn refuse_image(&mut self, error: ImageError) {
        self.unwritten = Unwritten::new();
        self.programming = Programming::Idle;
        self.last_image_error = Some(error);
    }
}

/// The NRC that tells a tester why an image header is refused: the image can never be
/// installed on this ECU (another ECU, other hardware, an older version than the floor,
/// another load address) → request out of range; the download itself is not what the
/// header describes (length, format) or not what this ECU takes (no machine code) →
/// upload/download not accepted. (An arm of its own for "no machine code" cost the ABS
/// firmware 36 bytes of flash it does not have.)
fn image_refusal_nrc(error: &ImageError) -> Nrc {
    match error {
        ImageError::WrongEcu { .. }
        | ImageError::WrongHardware { .. }
        | ImageError::Downgrade { .. }
        | ImageError::WrongLoadAddress { .. } => Nrc::RequestOutOfRange,
        _ => Nrc::UploadDownloadNotAccepted,
    }
}

/// The address a download names: the start of the slot the image is written to and will
/// run from (its load address less the header).
fn slot_address(expected: &Expectations) -> u32 {
    expected.load_address - HEADER_LEN as u32
}

/// addressAndLengthFormatIdentifier (only 0x44: four bytes each), address, size.
fn address_and_size(bytes: &[u8]) -> Result<(u32, u32), Nrc> {
    match bytes {
        [0x44, a0, a1, a2, a3, s0, s1, s2, s3] => Ok((
            u32::from_be_bytes([*a0, *a1, *a2, *a3]),
            u32::from_be_bytes([*s0, *s1, *s2, *s3]),
        )),
        [0x44, ..] => Err(Nrc::IncorrectMessageLengthOrInvalidFormat),
        _ => Err(Nrc::RequestOutOfRange),
    }
}

/// Below this the car stands, km/h (VehicleSpeedMsg has 1 km/h steps).
pub const STANDING_KMH: f32 = 1.0;

fn vehicle_stationary(backend: &impl Backend) -> bool {
    // Unknown speed counts as moving: programming needs proof that the car stands.
    backend.vehicle_standing()
}

/// How long a request with a sub-function must be.
#[derive(Clone, Copy)]
enum Length {
    /// Exactly this many bytes.
    Exactly(usize),
    /// The service checks the rest.
    AtLeastSubFunction,
}

/// The sub-function byte of a request, after a check of its length.
fn sub_function(request: &[u8], length: Length) -> Result<u8, Nrc> {
    let ok = match length {
        Length::Exactly(n) => request.len() == n,
        Length::AtLeastSubFunction => request.len() >= 2,
    };
    if !ok {
        return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
    }
    Ok(request[1])
}

/// ISO 14229-1 7.5: a functionally addressed request gets no negative response that only
/// says "not here" (this ECU does not support the service, sub-function or identifier).
fn suppressed_when_functional(nrc: Nrc) -> bool {
    matches!(
        nrc,
        Nrc::ServiceNotSupported
            | Nrc::SubFunctionNotSupported
            | Nrc::RequestOutOfRange
            | Nrc::SubFunctionNotSupportedInActiveSession
            | Nrc::ServiceNotSupportedInActiveSession
    )
}

/// Writes a short response (every caller's is at most 18 bytes; [`Server::handle`] asks
/// for a buffer of at least [`MIN_RESPONSE_BUFFER`]).
fn write(out: &mut [u8], bytes: &[u8]) -> usize {
    out[..bytes.len()].copy_from_slice(bytes);
    bytes.len()
}

/// The smallest response buffer [`Server::handle`] works with: room for every fixed-size
/// response (the longest, a security seed, is 18 bytes); DID and DTC lists that do not fit
/// are refused with "response too long".
pub const MIN_RESPONSE_BUFFER: usize = 32;

/// A positive response echoing `echo` after the SID, or nothing when the request's
/// sub-function asks to suppress it (bit 7).
fn positive(request: &[u8], echo: &[u8], out: &mut [u8]) -> Reply {
    if request.get(1).is_some_and(|sub| sub & 0x80 != 0) && request[0] != sid::TRANSFER_DATA {
        return Reply::Nothing;
    }
    out[0] = request[0] + sid::POSITIVE_OFFSET;
    out[1..1 + echo.len()].copy_from_slice(echo);
    Reply::Send(1 + echo.len())
}

fn negative(service: u8, nrc: Nrc, out: &mut [u8]) -> Reply {
    Reply::Send(write(out, &[sid::NEGATIVE_RESPONSE, service, nrc.code()]))
}

fn pending(service: u8, out: &mut [u8]) -> Reply {
    Reply::Pending(write(
        out,
        &[sid::NEGATIVE_RESPONSE, service, Nrc::ResponsePending.code()],
    ))
}

fn routine_ok(routine: u16, out: &mut [u8]) -> usize {
    let id = routine.to_be_bytes();
    // routineStatusRecord 0x00: the routine completed correctly.
    write(
        out,
        &[
            sid::ROUTINE_CONTROL + sid::POSITIVE_OFFSET,
            0x01,
            id[0],
            id[1],
            0x00,
        ],
    )
}

/// ReadDTCInformation: 0x01 number of DTCs by status mask, 0x02 DTCs by status mask,
/// 0x0A every supported (stored) DTC.
fn read_dtc_information(request: &[u8], dtcs: &Dtcs, out: &mut [u8]) -> Result<Reply, Nrc> {
    let sub = *request
        .get(1)
        .ok_or(Nrc::IncorrectMessageLengthOrInvalidFormat)?;
    let positive_sid = sid::READ_DTC + sid::POSITIVE_OFFSET;
    match sub {
        0x01 | 0x02 => {
            if request.len() != 3 {
                return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
            }
            let mask = request[2] & status::AVAILABILITY_MASK;
            let matching = dtcs.records().filter(|r| r.status & mask != 0);
            if sub == 0x01 {
                let count = (matching.count() as u16).to_be_bytes();
                // DTCFormatIdentifier 0x01: ISO 14229-1 DTC format.
                return Ok(Reply::Send(write(
                    out,
                    &[
                        positive_sid,
                        sub,
                        status::AVAILABILITY_MASK,
                        0x01,
                        count[0],
                        count[1],
                    ],
                )));
            }
            let mut len = write(out, &[positive_sid, sub, status::AVAILABILITY_MASK]);
            for record in matching {
                len = push_dtc(out, len, record.dtc, record.status)?;
            }
            Ok(Reply::Send(len))
        }
        0x0A => {
            if request.len() != 2 {
                return Err(Nrc::IncorrectMessageLengthOrInvalidFormat);
            }
            let mut len = write(out, &[positive_sid, sub, status::AVAILABILITY_MASK]);
            for record in dtcs.records() {
                len = push_dtc(out, len, record.dtc, record.status)?;
            }
            Ok(Reply::Send(len))
        }
        _ => Err(Nrc::SubFunctionNotSupported),
    }
}

fn push_dtc(out: &mut [u8], len: usize, dtc: Dtc, status: u8) -> Result<usize, Nrc> {
    let bytes = dtc.to_bytes();
    let end = len + 4;
    if end > out.len() {
        return Err(Nrc::ResponseTooLong);
    }
    out[len..end].copy_from_slice(&[bytes[0], bytes[1], bytes[2], status]);
    Ok(end)
}
