//! The server against an ECU backend with an in-memory DFU partition, driven the way a
//! tester drives it: request, then `resume` while it answers "pending".

extern crate std;

use std::vec;
use std::vec::Vec;

use autoplug_ecu::{Dtc, DtcSystem, Dtcs, Instant};
use autoplug_image::{
    BootState, Expectations, ImageBuilder, ImageError, ImageSlot, SigningKey, Version,
    NUCLEO_F446RE,
};
use proptest::prelude::*;

use crate::obd::answer_mode01;
use crate::security::key_for;
use crate::server::did;
use crate::*;

const NODE: u8 = 0x0D;
const SECRET: &[u8] = b"autoplug test security secret";
const SLOT: usize = 128 * 1024;
const SECTOR: usize = 128 * 1024;

struct TestEcu {
    dfu: Vec<u8>,
    speed: Option<f32>,
    dtcs: Dtcs,
    random: u8,
    marked: bool,
    writes: usize,
    key: SigningKey,
    floor: Version,
    /// Wrong keys in a row as the flash keeps them (survives a server reset).
    stored_failures: u8,
    /// Every count written, in order.
    failure_writes: Vec<u8>,
    /// The flash refuses the write of the count.
    failures_unwritable: bool,
    /// The ECU's own sensors show the car moving.
    own_motion: bool,
}

impl TestEcu {
    fn new() -> Self {
        Self {
            dfu: vec![0x00; 2 * SECTOR],
            speed: Some(0.0),
            dtcs: Dtcs::new(),
            random: 0,
            marked: false,
            writes: 0,
            key: SigningKey::from_seed([7; 32]),
            floor: Version::new(1, 0, 0),
            stored_failures: 0,
            failure_writes: Vec::new(),
            failures_unwritable: false,
            own_motion: false,
        }
    }
}

/// Where the test ECU's downloads go: slot A (it runs slot B).
const DOWNLOAD_SLOT: u32 = ImageSlot::A.region().start;

impl Backend for TestEcu {
    fn identification(&self) -> Identification<'_> {
        Identification {
            part_number: b"AP-CRUISE-0001",
            software_version: b"1.2.0",
            serial_number: b"0D0000000042",
            hardware_version: b"NUCLEO-F446RE",
            vin: b"JA3AP47H0YF000042",
            // It runs slot B, so downloads go to slot A, where `ImageBuilder` links.
            boot_slot: Some((ImageSlot::B, BootState::Confirmed)),
        }
    }
    fn read_live_data(&mut self, did: u16, out: &mut [u8]) -> Option<usize> {
        (did == 0x0100).then(|| {
            out[0] = 90;
            1
        })
    }
    fn vehicle_speed_kmh(&self) -> Option<f32> {
        self.speed
    }
    fn dtcs(&mut self) -> &mut Dtcs {
        &mut self.dtcs
    }
    fn fill_random(&mut self, out: &mut [u8]) {
        for b in out {
            self.random = self.random.wrapping_add(37);
            *b = self.random;
        }
    }
    fn stored_key_failures(&mut self) -> u8 {
        self.stored_failures
    }
    fn own_sensors_show_motion(&self) -> bool {
        self.own_motion
    }
    fn store_key_failures(&mut self, failures: u8) -> Result<(), FlashError> {
        if self.failures_unwritable {
            return Err(FlashError);
        }
        self.stored_failures = failures;
        self.failure_writes.push(failures);
        Ok(())
    }
    fn image_expectations(&self) -> Expectations {
        Expectations {
            node: NODE,
            hardware_id: NUCLEO_F446RE,
            version_floor: self.floor,
            max_image_len: SLOT as u32,
            load_address: ImageSlot::A.vector_table(),
            runs_machine_code: true,
        }
    }
    fn public_key(&self) -> [u8; 32] {
        self.key.public_key()
    }
    fn dfu_erase_steps(&self, len: u32) -> u32 {
        len.min(self.dfu.len() as u32).div_ceil(SECTOR as u32)
    }
    fn dfu_erase(&mut self, step: u32) -> Result<(), FlashError> {
        let start = step as usize * SECTOR;
        self.dfu[start..start + SECTOR].fill(0xFF);
        Ok(())
    }
    fn dfu_write(&mut self, offset: u32, data: &[u8]) -> Result<(), FlashError> {
        // The F446 programs 32-bit words: the server must hand out whole ones.
        assert_eq!((offset % 4, data.len() % 4), (0, 0), "unaligned write");
        let range = offset as usize..offset as usize + data.len();
        if self.dfu[range.clone()].iter().any(|&b| b != 0xFF) {
            return Err(FlashError); // NOR: programming needs an erased cell
        }
        self.dfu[range].copy_from_slice(data);
        self.writes += 1;
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
    fn obd_pids(&self) -> &'static [u8] {
        &[0x0D]
    }
    fn obd_read(&mut self, pid: u8, out: &mut [u8]) -> Option<usize> {
        (pid == 0x0D).then(|| {
            out[0] = self.speed? as u8;
            Some(1)
        })?
    }
}

/// A tester on the other end: sends a request, follows "pending" to the final response.
struct Bench {
    server: Server,
    ecu: TestEcu,
    now: Instant,
    pending_seen: usize,
    reset: Option<ResetKind>,
}

impl Bench {
    fn new() -> Self {
        Self {
            server: Server::new(Config::new(NODE, SECRET), Instant::from_micros(0)),
            ecu: TestEcu::new(),
            now: Instant::from_micros(0),
            pending_seen: 0,
            reset: None,
        }
    }

    /// The ECU restarts (ECUReset or a power cycle): a new server, the flash as it was.
    fn restart(&mut self) {
        self.server = Server::new(Config::new(NODE, SECRET), self.now);
        self.server.poll(self.now, &mut self.ecu);
    }

    /// Sends a wrong key for a fresh seed; returns the response.
    fn wrong_key(&mut self) -> Vec<u8> {
        let seed = self.request(&[0x27, 0x01]);
        assert_eq!(&seed[..2], &[0x67, 0x01], "a seed");
        self.request(&[&[0x27, 0x02][..], &[0xAA; 16]].concat())
    }

    fn advance_ms(&mut self, ms: u64) {
        self.now = self.now.plus_micros(ms * 1000);
        self.server.poll(self.now, &mut self.ecu);
    }

    fn request_as(&mut self, request: &[u8], functional: bool) -> Option<Vec<u8>> {
        let mut out = vec![0u8; 4095];
        let mut reply = self
            .server
            .handle(self.now, request, functional, &mut self.ecu, &mut out);
        loop {
            match reply {
                Reply::Nothing => return None,
                Reply::Send(n) => return Some(out[..n].to_vec()),
                Reply::SendThenReset(n, kind) => {
                    self.reset = Some(kind);
                    return (n > 0).then(|| out[..n].to_vec());
                }
                Reply::Pending(n) => {
                    assert_eq!(&out[..n], &[0x7F, request[0], 0x78]);
                    self.pending_seen += 1;
                }
                Reply::Working => {}
            }
            reply = self.server.resume(self.now, &mut self.ecu, &mut out);
        }
    }

    fn request(&mut self, request: &[u8]) -> Vec<u8> {
        self.request_as(request, false)
            .expect("a physical request gets a response")
    }

    fn unlock(&mut self) {
        let response = self.request(&[0x27, 0x01]);
        assert_eq!(&response[..2], &[0x67, 0x01]);
        let seed: [u8; 16] = response[2..].try_into().unwrap();
        let key = key_for(SECRET, NODE, &seed);
        let mut send = vec![0x27, 0x02];
        send.extend_from_slice(&key);
        assert_eq!(self.request(&send), [0x67, 0x02]);
    }

    fn enter_programming(&mut self) {
        assert_eq!(self.request(&[0x10, 0x03])[..2], [0x50, 0x03]);
        assert_eq!(self.request(&[0x10, 0x02])[..2], [0x50, 0x02]);
        self.unlock();
    }

    fn erase(&mut self) {
        assert_eq!(
            self.request(&[0x31, 0x01, 0xFF, 0x00]),
            [0x71, 0x01, 0xFF, 0x00, 0x00]
        );
    }

    /// RequestDownload, TransferData in 4093-byte blocks and RequestTransferExit; returns
    /// the first negative response, if any.
    fn download(&mut self, image: &[u8]) -> Result<(), Vec<u8>> {
        let mut request = vec![0x34, 0x00, 0x44];
        request.extend_from_slice(&DOWNLOAD_SLOT.to_be_bytes());
        request.extend_from_slice(&(image.len() as u32).to_be_bytes());
        let response = self.request(&request);
        if response[0] == 0x7F {
            return Err(response);
        }
        assert_eq!(response, [0x74, 0x20, 0x0F, 0xFF]);
        for (i, block) in image.chunks(4093).enumerate() {
            let counter = (i + 1) as u8;
            let mut request = vec![0x36, counter];
            request.extend_from_slice(block);
            let response = self.request(&request);
            if response[0] == 0x7F {
                return Err(response);
            }
            assert_eq!(response, [0x76, counter]);
        }
        let response = self.request(&[0x37]);
        if response[0] == 0x7F {
            return Err(response);
        }
        assert_eq!(response, [0x77]);
        Ok(())
    }

    fn check(&mut self) -> Vec<u8> {
        self.request(&[0x31, 0x01, 0xFF, 0x01])
    }
}

fn image_with(node: u8, version: Version, key: &SigningKey, len: usize) -> Vec<u8> {
    let mut payload: Vec<u8> = (0..len).map(|i| (i * 7 + 3) as u8).collect();
    if len >= 8 {
        payload[..8].copy_from_slice(&autoplug_image::stand_in_vector_table(ImageSlot::A));
    }
    let mut builder = ImageBuilder::new(node, version, payload);
    builder.build_id = [0xB1; 16];
    builder.sign(key).expect("a valid image")
}

fn good_image() -> Vec<u8> {
    image_with(
        NODE,
        Version::new(1, 3, 0),
        &SigningKey::from_seed([7; 32]),
        20_000,
    )
}

#[test]
fn sessions_and_their_timing_parameters() {
    let mut bench = Bench::new();
    // P2 50 ms, P2* 5000 ms in units of 10 ms.
    assert_eq!(
        bench.request(&[0x10, 0x03]),
        [0x50, 0x03, 0x00, 0x32, 0x01, 0xF4]
    );
    assert_eq!(bench.server.session(), Session::Extended);
    assert_eq!(bench.request(&[0x22, 0xF1, 0x86]), [0x62, 0xF1, 0x86, 0x03]);
    assert_eq!(bench.request(&[0x10, 0x04]), [0x7F, 0x10, 0x12]);
    assert_eq!(bench.request(&[0x10]), [0x7F, 0x10, 0x13]);
    assert_eq!(bench.request_as(&[0x10, 0x81], false), None);
    assert_eq!(bench.server.session(), Session::Default);
}

#[test]
fn no_programming_session_while_the_car_moves_or_its_speed_is_unknown() {
    let mut bench = Bench::new();
    bench.ecu.speed = Some(12.0);
    assert_eq!(bench.request(&[0x10, 0x02]), [0x7F, 0x10, 0x22]);
    bench.ecu.speed = None;
    assert_eq!(bench.request(&[0x10, 0x02]), [0x7F, 0x10, 0x22]);
    bench.ecu.speed = Some(0.0);
    assert_eq!(bench.request(&[0x10, 0x02])[..2], [0x50, 0x02]);
    // Nor an erase, should the car start moving once in the session.
    bench.unlock();
    bench.ecu.speed = Some(30.0);
    assert_eq!(bench.request(&[0x31, 0x01, 0xFF, 0x00]), [0x7F, 0x31, 0x22]);
}

#[test]
fn s3_ends_a_session_unless_the_tester_is_present() {
    let mut bench = Bench::new();
    bench.request(&[0x10, 0x03]);
    bench.unlock();
    for _ in 0..4 {
        bench.advance_ms(4_000);
        assert_eq!(bench.request(&[0x3E, 0x00]), [0x7E, 0x00]);
    }
    assert_eq!(bench.server.session(), Session::Extended);
    assert_eq!(bench.request_as(&[0x3E, 0x80], false), None);
    bench.advance_ms(5_001);
    assert_eq!(bench.server.session(), Session::Default);
    assert!(!bench.server.unlocked());
}

#[test]
fn identification_and_live_data() {
    let mut bench = Bench::new();
    let mut expected = vec![0x62, 0xF1, 0x87];
    expected.extend_from_slice(b"AP-CRUISE-0001");
    assert_eq!(bench.request(&[0x22, 0xF1, 0x87]), expected);
    let response = bench.request(&[0x22, 0xF1, 0x89, 0xF1, 0x8C, 0xF1, 0x91, 0x01, 0x00]);
    let mut expected = vec![0x62, 0xF1, 0x89];
    expected.extend_from_slice(b"1.2.0");
    expected.extend_from_slice(&[0xF1, 0x8C]);
    expected.extend_from_slice(b"0D0000000042");
    expected.extend_from_slice(&[0xF1, 0x91]);
    expected.extend_from_slice(b"NUCLEO-F446RE");
    expected.extend_from_slice(&[0x01, 0x00, 90]);
    assert_eq!(response, expected);
    // Unknown identifiers are left out; none known at all is out of range.
    assert_eq!(
        bench.request(&[0x22, 0x12, 0x34, 0x01, 0x00]),
        [0x62, 0x01, 0x00, 90]
    );
    assert_eq!(bench.request(&[0x22, 0x12, 0x34]), [0x7F, 0x22, 0x31]);
    assert_eq!(bench.request(&[0x22, 0xF1]), [0x7F, 0x22, 0x13]);
    // The VIN, as every ECU of the car holds it.
    let mut expected = vec![0x62, 0xF1, 0x90];
    expected.extend_from_slice(b"JA3AP47H0YF000042");
    assert_eq!(bench.request(&[0x22, 0xF1, 0x90]), expected);
    // The running slot and its state.
    assert_eq!(bench.request(&[0x22, 0xF1, 0xA0]), [0x62, 0xF1, 0xA0, 1, 0]);
    assert_eq!(
        crate::parse_boot_slot(&[1, 0]),
        Some((ImageSlot::B, BootState::Confirmed))
    );
    assert_eq!(
        crate::parse_boot_slot(&[0, 1]),
        Some((ImageSlot::A, BootState::Trial))
    );
    assert_eq!(crate::parse_boot_slot(&[2, 0]), None);
    assert_eq!(crate::parse_boot_slot(&[0, 3]), None);
    assert_eq!(crate::parse_boot_slot(&[0]), None);
    let _ = did::PART_NUMBER;
}

#[test]
fn security_access_seed_key_and_lockout() {
    let mut bench = Bench::new();
    assert_eq!(bench.request(&[0x27, 0x01]), [0x7F, 0x27, 0x7F]);
    bench.request(&[0x10, 0x03]);
    assert_eq!(bench.request(&[0x27, 0x02, 0, 0]), [0x7F, 0x27, 0x24]);
    // Two wrong keys: invalid key; the third locks.
    for attempt in 1..=3 {
        let seed = bench.request(&[0x27, 0x01]);
        assert!(seed[2..].iter().any(|&b| b != 0));
        let mut send = vec![0x27, 0x02];
        send.extend_from_slice(&[0xAA; 16]);
        let expected = if attempt < 3 { 0x35 } else { 0x36 };
        assert_eq!(bench.request(&send), [0x7F, 0x27, expected]);
    }
    assert_eq!(bench.request(&[0x27, 0x01]), [0x7F, 0x27, 0x37]);
    bench.advance_ms(3_000);
    bench.request(&[0x3E, 0x00]);
    bench.advance_ms(3_000);
    bench.request(&[0x3E, 0x00]);
    bench.advance_ms(3_000);
    assert_eq!(bench.request(&[0x27, 0x01]), [0x7F, 0x27, 0x37]);
    bench.advance_ms(1_001);
    bench.unlock();
    assert!(bench.server.unlocked());
    // Unlocked: the seed is all zeros.
    assert_eq!(
        bench.request(&[0x27, 0x01]),
        [vec![0x67, 0x01], vec![0; 16]].concat()
    );
    // A key from another ECU's MAC does not open this one.
    bench.request(&[0x10, 0x01]);
    bench.request(&[0x10, 0x03]);
    let seed: [u8; 16] = bench.request(&[0x27, 0x01])[2..].try_into().unwrap();
    let mut send = vec![0x27, 0x02];
    send.extend_from_slice(&key_for(SECRET, NODE + 1, &seed));
    assert_eq!(bench.request(&send), [0x7F, 0x27, 0x35]);
}

#[test]
fn the_lockout_survives_a_reset_and_a_power_cycle() {
    let mut bench = Bench::new();
    bench.request(&[0x10, 0x03]);
    for _ in 0..2 {
        assert_eq!(bench.wrong_key(), [0x7F, 0x27, 0x35]);
    }
    assert_eq!(bench.wrong_key(), [0x7F, 0x27, 0x36]);
    assert_eq!(bench.ecu.stored_failures, 3);
    // ECUReset needs no security: before, it gave three fresh guesses.
    assert_eq!(bench.request(&[0x11, 0x01]), [0x51, 0x01]);
    bench.restart();
    bench.request(&[0x10, 0x03]);
    assert_eq!(bench.request(&[0x27, 0x01]), [0x7F, 0x27, 0x37]);
    // The delay runs again from the start: 9 s after the reset, still locked.
    bench.advance_ms(4_000);
    bench.request(&[0x3E, 0x00]);
    bench.advance_ms(4_000);
    bench.request(&[0x3E, 0x00]);
    bench.advance_ms(1_000);
    assert_eq!(bench.request(&[0x27, 0x01]), [0x7F, 0x27, 0x37]);
    // A power cycle during the delay starts it again too.
    bench.restart();
    bench.request(&[0x10, 0x03]);
    assert_eq!(bench.request(&[0x27, 0x01]), [0x7F, 0x27, 0x37]);
    bench.advance_ms(4_000);
    bench.request(&[0x3E, 0x00]);
    bench.advance_ms(4_000);
    bench.request(&[0x3E, 0x00]);
    bench.advance_ms(2_001);
    bench.unlock();
    assert_eq!(bench.ecu.stored_failures, 0, "a good key clears the count");
}

#[test]
fn a_reset_between_wrong_keys_gives_no_fresh_attempts() {
    let mut bench = Bench::new();
    bench.request(&[0x10, 0x03]);
    assert_eq!(bench.wrong_key(), [0x7F, 0x27, 0x35]);
    assert_eq!(bench.wrong_key(), [0x7F, 0x27, 0x35]);
    bench.restart();
    bench.request(&[0x10, 0x03]);
    assert_eq!(
        bench.wrong_key(),
        [0x7F, 0x27, 0x36],
        "the third in all locks"
    );
    assert_eq!(bench.ecu.failure_writes, [1, 2, 3]);
}

#[test]
fn an_attempt_is_counted_in_flash_before_the_key_is_checked() {
    let mut bench = Bench::new();
    bench.request(&[0x10, 0x03]);
    // The right key, but the count cannot be kept: refused, and not unlocked.
    bench.ecu.failures_unwritable = true;
    let seed: [u8; 16] = bench.request(&[0x27, 0x01])[2..].try_into().unwrap();
    let key = key_for(SECRET, NODE, &seed);
    assert_eq!(
        bench.request(&[&[0x27, 0x02][..], &key].concat()),
        [0x7F, 0x27, 0x22]
    );
    assert!(!bench.server.unlocked());
    // The seed was used up: the same key again is out of sequence.
    assert_eq!(
        bench.request(&[&[0x27, 0x02][..], &key].concat()),
        [0x7F, 0x27, 0x24]
    );
    // A good key: the attempt is written (1) before the check, then cleared (0).
    bench.ecu.failures_unwritable = false;
    bench.unlock();
    assert_eq!(bench.ecu.failure_writes, [1, 0]);
}

#[test]
fn a_download_must_fit_what_the_erase_made_room_for() {
    let mut bench = Bench::new();
    bench.enter_programming();
    let image = good_image();
    // Erase for an image of 1000 bytes: one sector is erased, and the download of the
    // larger image is refused (uploadDownloadNotAccepted), not written.
    let mut erase = vec![0x31, 0x01, 0xFF, 0x00, 0x44];
    erase.extend_from_slice(&DOWNLOAD_SLOT.to_be_bytes());
    erase.extend_from_slice(&1000u32.to_be_bytes());
    assert_eq!(bench.request(&erase), [0x71, 0x01, 0xFF, 0x00, 0x00]);
    assert!(image.len() > 1000);
    assert_eq!(bench.download(&image), Err(vec![0x7F, 0x34, 0x70]));
    // Erased for the image's own size, it goes in.
    let mut erase = vec![0x31, 0x01, 0xFF, 0x00, 0x44];
    erase.extend_from_slice(&DOWNLOAD_SLOT.to_be_bytes());
    erase.extend_from_slice(&(image.len() as u32).to_be_bytes());
    assert_eq!(bench.request(&erase), [0x71, 0x01, 0xFF, 0x00, 0x00]);
    bench.download(&image).expect("accepted");
    assert_eq!(bench.check(), [0x71, 0x01, 0xFF, 0x01, 0x00]);
}

#[test]
fn a_complete_download_is_verified_marked_and_reset_into() {
    let mut bench = Bench::new();
    bench.enter_programming();
    bench.erase();
    assert!(bench.pending_seen >= 1, "a 0x78 per sector erased");
    // Only the sector that the largest image needs: the bootloader erases the second
    // DFU sector itself before it copies the old image there.
    assert!(bench.ecu.dfu[..SECTOR].iter().all(|&b| b == 0xFF));
    assert!(
        bench.ecu.dfu[SECTOR..].iter().all(|&b| b == 0x00),
        "second sector erased"
    );
    let image = good_image();
    bench.download(&image).expect("accepted");
    assert_eq!(&bench.ecu.dfu[..image.len()], &image[..]);
    assert!(!bench.ecu.marked);
    assert_eq!(bench.check(), [0x71, 0x01, 0xFF, 0x01, 0x00]);
    assert!(bench.ecu.marked);
    assert_eq!(bench.request(&[0x11, 0x01]), [0x51, 0x01]);
    assert_eq!(bench.reset, Some(ResetKind::Hard));
}

#[test]
fn programming_needs_the_session_security_and_an_erase() {
    let mut bench = Bench::new();
    let image = good_image();
    bench.request(&[0x10, 0x03]);
    assert_eq!(bench.download(&image), Err(vec![0x7F, 0x34, 0x7F]));
    assert_eq!(bench.request(&[0x31, 0x01, 0xFF, 0x00]), [0x7F, 0x31, 0x7F]);
    bench.request(&[0x10, 0x02]);
    assert_eq!(bench.download(&image), Err(vec![0x7F, 0x34, 0x33]));
    assert_eq!(bench.request(&[0x31, 0x01, 0xFF, 0x00]), [0x7F, 0x31, 0x33]);
    bench.unlock();
    assert_eq!(bench.download(&image), Err(vec![0x7F, 0x34, 0x22]));
    assert_eq!(bench.check(), [0x7F, 0x31, 0x24]);
    assert_eq!(bench.request(&[0x36, 0x01, 0x00]), [0x7F, 0x36, 0x24]);
    assert_eq!(bench.request(&[0x37]), [0x7F, 0x37, 0x24]);
    assert!(!bench.ecu.marked);
}

/// Runs a download of `image` after a fresh erase; returns the refusal (the negative
/// response) and checks that nothing was marked for a trial start.
fn refusal_of(image: &[u8]) -> Vec<u8> {
    let mut bench = Bench::new();
    bench.enter_programming();
    bench.erase();
    let refusal = match bench.download(image) {
        Err(response) => response,
        Ok(()) => bench.check(),
    };
    assert!(!bench.ecu.marked, "a refused image must never be marked");
    assert!(bench.server.last_image_error().is_some());
    refusal
}

#[test]
fn bad_images_are_refused_with_the_right_negative_response() {
    let key = SigningKey::from_seed([7; 32]);
    let good = good_image();

    let mut flipped = good.clone();
    flipped[600] ^= 0x01;
    assert_eq!(
        refusal_of(&flipped),
        [0x7F, 0x31, 0x72],
        "a flipped payload byte"
    );

    let mut flipped_signature = good.clone();
    let last = flipped_signature.len() - 1;
    flipped_signature[last] ^= 0x80;
    assert_eq!(refusal_of(&flipped_signature), [0x7F, 0x31, 0x72]);

    let foreign_key = image_with(
        NODE,
        Version::new(1, 3, 0),
        &SigningKey::from_seed([8; 32]),
        20_000,
    );
    assert_eq!(
        refusal_of(&foreign_key),
        [0x7F, 0x31, 0x72],
        "signed with another key"
    );

    let mut unsigned = good.clone();
    unsigned[good.len() - 64..].fill(0);
    assert_eq!(refusal_of(&unsigned), [0x7F, 0x31, 0x72], "unsigned");

    let other_ecu = image_with(0x0E, Version::new(1, 3, 0), &key, 20_000);
    assert_eq!(refusal_of(&other_ecu), [0x7F, 0x36, 0x31], "the ABS image");

    let downgrade = image_with(NODE, Version::new(0, 9, 9), &key, 20_000);
    assert_eq!(
        refusal_of(&downgrade),
        [0x7F, 0x36, 0x31],
        "below the version floor"
    );

    let truncated = &good[..good.len() - 100];
    assert_eq!(refusal_of(truncated), [0x7F, 0x36, 0x70], "truncated");

    let too_short = &good[..300];
    assert_eq!(
        refusal_of(too_short),
        [0x7F, 0x31, 0x72],
        "shorter than a header"
    );

    let oversized = image_with(NODE, Version::new(1, 3, 0), &key, SLOT);
    assert_eq!(
        refusal_of(&oversized),
        [0x7F, 0x34, 0x70],
        "larger than the slot"
    );
}

#[test]
fn a_refused_image_leaves_a_good_one_installable() {
    let mut bench = Bench::new();
    bench.enter_programming();
    bench.erase();
    let mut flipped = good_image();
    flipped[1000] ^= 0x40;
    bench.download(&flipped).unwrap();
    assert_eq!(bench.check(), [0x7F, 0x31, 0x72]);
    // The check cannot be repeated on the refused image, a new download needs an erase.
    assert_eq!(bench.check(), [0x7F, 0x31, 0x24]);
    bench.erase();
    bench.download(&good_image()).unwrap();
    assert_eq!(bench.check(), [0x71, 0x01, 0xFF, 0x01, 0x00]);
    assert!(bench.ecu.marked);
}

#[test]
fn an_image_without_machine_code_is_refused_at_its_header_by_firmware() {
    let mut bench = Bench::new();
    bench.enter_programming();
    bench.erase();
    let mut builder = ImageBuilder::new(NODE, Version::new(1, 3, 0), vec![0x5A; 20_000]);
    builder.payload_kind = autoplug_image::Payload::HostLogic;
    let image = builder.sign(&SigningKey::from_seed([7; 32])).unwrap();
    // uploadDownloadNotAccepted at the first block: not what this ECU takes.
    assert_eq!(bench.download(&image), Err(vec![0x7F, 0x36, 0x70]));
    assert_eq!(
        bench.server.last_image_error(),
        Some(&ImageError::NoMachineCode)
    );
    assert!(!bench.ecu.marked);
}

#[test]
fn blocks_of_any_length_are_programmed_as_whole_words() {
    // 301, 7, 1000... bytes: the header straddles blocks and partial words carry over.
    let mut bench = Bench::new();
    bench.enter_programming();
    bench.erase();
    let image = good_image();
    let mut request = vec![0x34, 0x00, 0x44];
    request.extend_from_slice(&DOWNLOAD_SLOT.to_be_bytes());
    request.extend_from_slice(&(image.len() as u32).to_be_bytes());
    bench.request(&request);
    let sizes = [301usize, 7, 1, 203, 1000, 3333];
    let mut offset = 0;
    let mut counter = 0u8;
    let mut i = 0;
    while offset < image.len() {
        let end = (offset + sizes[i % sizes.len()]).min(image.len());
        counter = counter.wrapping_add(1);
        let request = [&[0x36, counter][..], &image[offset..end]].concat();
        assert_eq!(bench.request(&request), [0x76, counter], "block {counter}");
        // Programming in small slices between blocks, as the diagnostic node does.
        while bench.server.program_step(&mut bench.ecu, 64) {}
        offset = end;
        i += 1;
    }
    assert_eq!(bench.request(&[0x37]), [0x77]);
    assert_eq!(&bench.ecu.dfu[..image.len()], &image[..]);
    assert_eq!(bench.check(), [0x71, 0x01, 0xFF, 0x01, 0x00]);
}

#[test]
fn transfer_blocks_are_counted() {
    let mut bench = Bench::new();
    bench.enter_programming();
    bench.erase();
    let image = good_image();
    let mut request = vec![0x34, 0x00, 0x44];
    request.extend_from_slice(&DOWNLOAD_SLOT.to_be_bytes());
    request.extend_from_slice(&(image.len() as u32).to_be_bytes());
    bench.request(&request);
    let block = |counter: u8, data: &[u8]| [&[0x36, counter][..], data].concat();
    assert_eq!(bench.request(&block(2, &image[..100])), [0x7F, 0x36, 0x73]);
    assert_eq!(bench.request(&block(1, &image[..1000])), [0x76, 0x01]);
    // The same block again (the response was lost): acknowledged, not written twice.
    let writes = bench.ecu.writes;
    assert_eq!(bench.request(&block(1, &image[..1000])), [0x76, 0x01]);
    assert_eq!(bench.ecu.writes, writes);
    assert_eq!(bench.request(&block(2, &image[1000..2000])), [0x76, 0x02]);
    // Exit before the last byte: out of sequence.
    assert_eq!(bench.request(&[0x37]), [0x7F, 0x37, 0x24]);
    // Blocks up to 10 bytes short of the end, then one of 20: more than announced.
    let mut offset = 2000;
    let mut counter = 2u8;
    while offset + 10 < image.len() {
        let end = (offset + 4093).min(image.len() - 10);
        counter = counter.wrapping_add(1);
        assert_eq!(
            bench.request(&block(counter, &image[offset..end])),
            [0x76, counter]
        );
        offset = end;
    }
    let too_much = block(counter.wrapping_add(1), &[0xEE; 20]);
    assert_eq!(bench.request(&too_much), [0x7F, 0x36, 0x71]);
    // And a block longer than announced in 0x74 is malformed.
    assert_eq!(bench.request(&block(1, &vec![0; 4094])), [0x7F, 0x36, 0x13]);
}

#[test]
fn blocks_are_programmed_in_slices_while_the_next_one_arrives() {
    let mut bench = Bench::new();
    bench.enter_programming();
    bench.erase();
    let image = good_image();
    let mut request = vec![0x34, 0x00, 0x44];
    request.extend_from_slice(&DOWNLOAD_SLOT.to_be_bytes());
    request.extend_from_slice(&(image.len() as u32).to_be_bytes());
    bench.request(&request);
    let mut block = vec![0x36, 0x01];
    block.extend_from_slice(&image[..4093]);
    assert_eq!(bench.request(&block), [0x76, 0x01]);
    // Acknowledged at once, programmed afterwards: 64 bytes (16 words) per slice.
    assert_eq!(bench.ecu.writes, 0);
    assert!(bench.server.programming_pending());
    let mut slices = 0;
    while bench.server.program_step(&mut bench.ecu, 64) {
        slices += 1;
    }
    // 4092 bytes are whole words; the block's last byte waits for the next block.
    assert_eq!(slices + 1, 4092usize.div_ceil(64));
    assert_eq!(bench.ecu.writes, 4092usize.div_ceil(64));
    assert_eq!(&bench.ecu.dfu[..4092], &image[..4092]);
    assert_eq!(bench.ecu.dfu[4092], 0xFF);
    assert!(!bench.server.programming_pending());
}

#[test]
fn communication_control_and_dtc_setting_end_with_the_session() {
    let mut bench = Bench::new();
    assert_eq!(bench.request(&[0x28, 0x03, 0x01]), [0x7F, 0x28, 0x7F]);
    bench.request(&[0x10, 0x03]);
    assert_eq!(bench.request(&[0x28, 0x03, 0x01]), [0x68, 0x03]);
    assert!(!bench.server.normal_tx_enabled() && !bench.server.normal_rx_enabled());
    assert_eq!(bench.request(&[0x28, 0x01, 0x01]), [0x68, 0x01]);
    assert!(!bench.server.normal_tx_enabled() && bench.server.normal_rx_enabled());
    assert_eq!(bench.request(&[0x28, 0x05, 0x01]), [0x7F, 0x28, 0x12]);
    assert_eq!(bench.request(&[0x85, 0x02]), [0xC5, 0x02]);
    let dtc = Dtc::new(DtcSystem::U, 0x0100, 0x87);
    bench.ecu.dtcs.report_failed(dtc, bench.now);
    assert_eq!(bench.ecu.dtcs.records().count(), 0, "DTC setting off");
    bench.request(&[0x10, 0x01]);
    assert!(bench.server.normal_tx_enabled() && bench.server.dtc_setting_on());
    bench.ecu.dtcs.report_failed(dtc, bench.now);
    assert_eq!(bench.ecu.dtcs.records().count(), 1);
}

#[test]
fn dtcs_are_read_and_cleared() {
    let mut bench = Bench::new();
    let lost = Dtc::new(DtcSystem::U, 0x0100, 0x87);
    bench.ecu.dtcs.report_failed(lost, bench.now);
    assert_eq!(
        bench.request(&[0x19, 0x01, 0xFF]),
        [0x59, 0x01, 0x2F, 0x01, 0x00, 0x01]
    );
    let response = bench.request(&[0x19, 0x02, 0x01]);
    let bytes = lost.to_bytes();
    assert_eq!(response[..3], [0x59, 0x02, 0x2F]);
    assert_eq!(response[3..6], bytes);
    assert!(response[6] & 0x01 != 0, "test failed");
    bench.ecu.dtcs.report_passed(lost);
    assert_eq!(bench.request(&[0x19, 0x02, 0x01]), [0x59, 0x02, 0x2F]);
    assert_eq!(bench.request(&[0x19, 0x0A]).len(), 3 + 4);
    assert_eq!(bench.request(&[0x14, 0x12, 0x34, 0x56]), [0x7F, 0x14, 0x31]);
    assert_eq!(bench.request(&[0x14, 0xFF, 0xFF, 0xFF]), [0x54]);
    assert_eq!(bench.request(&[0x19, 0x0A]), [0x59, 0x0A, 0x2F]);
    assert_eq!(bench.request(&[0x19, 0x42]), [0x7F, 0x19, 0x12]);
}

#[test]
fn functional_requests_get_no_not_here_negative_responses() {
    let mut bench = Bench::new();
    assert_eq!(bench.request_as(&[0x23, 0x00], true), None);
    assert_eq!(bench.request(&[0x23, 0x00]), [0x7F, 0x23, 0x11]);
    assert_eq!(bench.request_as(&[0x3E, 0x80], true), None);
    assert_eq!(
        bench.request_as(&[0x3E, 0x00], true),
        Some(vec![0x7E, 0x00])
    );
    // But a real refusal is still reported.
    bench.ecu.speed = Some(50.0);
    assert_eq!(
        bench.request_as(&[0x10, 0x02], true),
        Some(vec![0x7F, 0x10, 0x22])
    );
}

#[test]
fn obd_mode01_answers_only_what_the_ecu_owns() {
    let mut ecu = TestEcu::new();
    ecu.speed = Some(87.0);
    let mut out = [0u8; 8];
    assert_eq!(answer_mode01(&[0x01, 0x0D], &mut ecu, &mut out), Some(3));
    assert_eq!(out[..3], [0x41, 0x0D, 87]);
    assert_eq!(answer_mode01(&[0x01, 0x00], &mut ecu, &mut out), Some(6));
    assert_eq!(out[..6], [0x41, 0x00, 0x00, 0x08, 0x00, 0x00]);
    assert_eq!(answer_mode01(&[0x01, 0x0C], &mut ecu, &mut out), None);
    assert_eq!(answer_mode01(&[0x02, 0x0D], &mut ecu, &mut out), None);
    ecu.speed = None;
    assert_eq!(answer_mode01(&[0x01, 0x0D], &mut ecu, &mut out), None);
}

proptest! {
    /// Whatever arrives, the server neither panics nor answers with anything but a positive
    /// response to that service or a negative response naming it.
    #[test]
    fn arbitrary_requests_get_well_formed_answers(
        requests in proptest::collection::vec(proptest::collection::vec(any::<u8>(), 0..40), 1..30),
        functional in any::<bool>(),
    ) {
        let mut bench = Bench::new();
        bench.request(&[0x10, 0x02]);
        bench.unlock();
        for request in requests {
            if request.is_empty() {
                continue;
            }
            if let Some(response) = bench.request_as(&request, functional) {
                let ok = response[0] == request[0].wrapping_add(0x40)
                    || (response.len() == 3 && response[0] == 0x7F && response[1] == request[0]);
                prop_assert!(ok, "{request:02X?} -> {response:02X?}");
            }
        }
    }
}

/// A tester's ISO-TP channel and the ECU's [`DiagNode`] on one simulated bus, frames
/// taking 250 µs each.
struct Wire {
    ecu_node: DiagNode,
    ecu: TestEcu,
    tester: autoplug_isotp::Channel<4095>,
    now: Instant,
    frames: usize,
}

impl Wire {
    fn new() -> Self {
        let node = autoplug_can::Node::Cruise;
        let config = autoplug_isotp::Config::default_for(
            node.diag_request_id().unwrap(),
            node.diag_response_id().unwrap(),
        );
        let mut wire = Self {
            ecu_node: DiagNode::new(node, SECRET, Instant::from_micros(0)).unwrap(),
            ecu: TestEcu::new(),
            tester: autoplug_isotp::Channel::new(config),
            now: Instant::from_micros(0),
            frames: 0,
        };
        // The car has been standing for a while: the ECU heard VehicleSpeedMsg 0 at its
        // period.
        wire.drive(0.0, 600);
        wire
    }

    /// `ms` of VehicleSpeedMsg at `kmh`, every 10 ms.
    fn drive(&mut self, kmh: f32, ms: u64) {
        for _ in 0..ms / 10 {
            self.now = self.now.plus_micros(10_000);
            self.ecu_node.observe(self.now, &speed_frame(kmh));
        }
    }

    /// The extended, then the programming session, and security unlocked, over frames.
    fn enter_programming(&mut self) {
        let mut ask = |request: &[u8]| self.exchange(request, 10_000).expect("an answer");
        assert_eq!(ask(&[0x10, 0x03])[..2], [0x50, 0x03]);
        assert_eq!(ask(&[0x10, 0x02])[..2], [0x50, 0x02]);
        let seed: [u8; 16] = ask(&[0x27, 0x01])[2..].try_into().unwrap();
        let mut send = vec![0x27, 0x02];
        send.extend_from_slice(&key_for(SECRET, NODE, &seed));
        assert_eq!(ask(&send), [0x67, 0x02]);
    }

    /// Moves frames both ways until the tester has a response (not a 0x78) or `limit_ms`
    /// passes; returns it.
    fn exchange(&mut self, request: &[u8], limit_ms: u64) -> Option<Vec<u8>> {
        self.tester.send(self.now, request).unwrap();
        let end = self.now.plus_micros(limit_ms * 1000);
        while self.now.as_micros() < end.as_micros() {
            self.now = self.now.plus_micros(250);
            // The car's VehicleSpeedMsg, as the ECU hears it: standing.
            self.ecu_node.observe(self.now, &speed_frame(0.0));
            self.ecu_node.poll(self.now, &mut self.ecu);
            if let Some(frame) = self.tester.poll_transmit(self.now) {
                self.tester.confirm_transmit(self.now);
                self.frames += 1;
                self.ecu_node.on_frame(self.now, &frame, &mut self.ecu);
            } else if let Some(frame) = self.ecu_node.poll_transmit(self.now) {
                self.ecu_node.confirm_transmit(self.now);
                self.frames += 1;
                if let Some(autoplug_isotp::Event::Received { len, .. }) =
                    self.tester.on_frame(self.now, &frame)
                {
                    let response = self.tester.received()[..len].to_vec();
                    self.tester.release();
                    if response.len() == 3 && response[0] == 0x7F && response[2] == 0x78 {
                        continue;
                    }
                    return Some(response);
                }
            }
            while self.tester.poll(self.now).is_some() {}
        }
        None
    }
}

#[test]
fn a_download_over_iso_tp_frames_reaches_the_dfu_partition() {
    let mut wire = Wire::new();
    let ask = |wire: &mut Wire, request: &[u8]| wire.exchange(request, 10_000).expect("an answer");
    wire.enter_programming();
    assert_eq!(
        ask(&mut wire, &[0x31, 0x01, 0xFF, 0x00]),
        [0x71, 0x01, 0xFF, 0x00, 0x00]
    );
    let image = good_image();
    let mut request = vec![0x34, 0x00, 0x44];
    request.extend_from_slice(&DOWNLOAD_SLOT.to_be_bytes());
    request.extend_from_slice(&(image.len() as u32).to_be_bytes());
    assert_eq!(ask(&mut wire, &request), [0x74, 0x20, 0x0F, 0xFF]);
    for (i, block) in image.chunks(4093).enumerate() {
        let counter = (i + 1) as u8;
        let request = [&[0x36, counter][..], block].concat();
        assert_eq!(ask(&mut wire, &request), [0x76, counter]);
    }
    assert_eq!(ask(&mut wire, &[0x37]), [0x77]);
    assert_eq!(&wire.ecu.dfu[..image.len()], &image[..]);
    assert_eq!(
        ask(&mut wire, &[0x31, 0x01, 0xFF, 0x01]),
        [0x71, 0x01, 0xFF, 0x01, 0x00]
    );
    assert!(wire.ecu.marked);
    assert_eq!(ask(&mut wire, &[0x11, 0x01]), [0x51, 0x01]);
    // The reset comes once the response is out, not before.
    wire.ecu_node.poll(wire.now, &mut wire.ecu);
    assert_eq!(wire.ecu_node.take_reset(), Some(ResetKind::Hard));
}

/// A long operation's next step waits for its 0x78 to be confirmed, and the node says it is
/// waiting: the firmware, which confirms a frame when it queues it, holds its poll on that
/// until its transmit path is empty (a sector erase stalls its core for a second).
#[test]
fn a_long_operation_waits_for_its_0x78_to_be_out() {
    let mut wire = Wire::new();
    wire.enter_programming();
    assert!(!wire.ecu_node.resumes_after_send());

    wire.ecu.dfu.fill(0);
    let now = wire.now;
    wire.tester.send(now, &[0x31, 0x01, 0xFF, 0x00]).unwrap();
    let request = wire.tester.poll_transmit(now).expect("the erase request");
    wire.tester.confirm_transmit(now);
    wire.ecu_node.on_frame(now, &request, &mut wire.ecu);
    wire.ecu_node.poll(now, &mut wire.ecu);
    let pending = wire.ecu_node.poll_transmit(now).expect("a first response");
    assert_eq!(pending.data()[..4], [0x03, 0x7F, 0x31, 0x78]);
    assert!(wire.ecu_node.resumes_after_send());
    // Handed out, not confirmed: polls leave the flash alone.
    for ms in 1..=20 {
        wire.ecu_node
            .poll(now.plus_micros(ms * 1000), &mut wire.ecu);
    }
    assert!(wire.ecu.dfu[..SECTOR].iter().all(|&b| b == 0));
    assert!(wire.ecu_node.resumes_after_send());
    // Out: the next poll erases.
    let now = now.plus_micros(21_000);
    wire.ecu_node.confirm_transmit(now);
    wire.ecu_node.poll(now, &mut wire.ecu);
    assert!(wire.ecu.dfu[..SECTOR].iter().all(|&b| b == 0xFF));
}

#[test]
fn obd_requests_on_0x7df_are_answered_on_the_iso_15765_4_identifier() {
    let mut node =
        DiagNode::new(autoplug_can::Node::Cruise, SECRET, Instant::from_micros(0)).unwrap();
    let mut ecu = TestEcu::new();
    let now = Instant::from_micros(1000);
    let request = autoplug_can::Frame::new(0x7DF, &[0x02, 0x01, 0x0D, 0, 0, 0, 0, 0]).unwrap();
    // Before the cruise ECU has reported a speed, it has no value to give: silent.
    node.on_frame(now, &request, &mut ecu);
    assert!(node.poll_transmit(now).is_none());
    // It reports what it sent itself on VehicleSpeedMsg (its own measurement).
    node.note_sent(now, &speed_frame(87.0));
    node.on_frame(now, &request, &mut ecu);
    let response = node.poll_transmit(now).expect("an OBD-II response");
    assert_eq!(response.id(), 0x7E9);
    assert_eq!(
        response.data(),
        [0x03, 0x41, 0x0D, 87, 0xCC, 0xCC, 0xCC, 0xCC]
    );
    // An ECU without OBD-II values stays silent; UDS on 0x7DF still works.
    let mut abs = DiagNode::new(autoplug_can::Node::ABS, SECRET, Instant::from_micros(0)).unwrap();
    abs.on_frame(now, &request, &mut ecu);
    assert!(abs.poll_transmit(now).is_none());
    let present = autoplug_can::Frame::new(0x7DF, &[0x02, 0x3E, 0x00, 0, 0, 0, 0, 0]).unwrap();
    abs.on_frame(now, &present, &mut ecu);
    abs.poll(now, &mut ecu);
    let response = abs.poll_transmit(now).expect("tester present answered");
    assert_eq!(response.id(), 0x78E);
    assert_eq!(response.data()[..3], [0x02, 0x7E, 0x00]);
}

/// A VehicleSpeedMsg frame.
fn speed_frame(kmh: f32) -> autoplug_can::Frame {
    let data = autoplug_can::VehicleSpeedMsg { vehicle_speed: kmh }.encode();
    autoplug_can::Frame::new(u32::from(autoplug_can::VehicleSpeedMsg::ID), &data).unwrap()
}

#[test]
fn the_stack_knows_the_speed_from_the_bus_and_keeps_it_while_the_bus_is_silenced() {
    let mut node = DiagNode::new(autoplug_can::Node::ABS, SECRET, Instant::ZERO).unwrap();
    let mut ecu = TestEcu::new();
    let t = |ms: u64| Instant::from_millis(ms);
    assert_eq!(node.vehicle_speed_kmh(t(0)), None, "nothing heard: unknown");
    node.observe(t(0), &speed_frame(0.0));
    assert_eq!(node.vehicle_speed_kmh(t(30)), Some(0.0));
    assert_eq!(
        node.vehicle_speed_kmh(t(31)),
        None,
        "stale after 3 periods of 10 ms"
    );
    // Normal communication off (functional extended session, then 0x28 03 01): the
    // silence is the tester's doing, the last speed stands.
    node.observe(t(40), &speed_frame(0.0));
    for request in [[0x02, 0x10, 0x03], [0x03, 0x28, 0x03]] {
        let mut data = [0u8; 8];
        data[..3].copy_from_slice(&request);
        data[3] = 0x01;
        let frame = autoplug_can::Frame::new(0x7DF, &data).unwrap();
        node.on_frame(t(41), &frame, &mut ecu);
    }
    assert!(!node.server().normal_tx_enabled());
    assert_eq!(node.vehicle_speed_kmh(t(5_000)), Some(0.0));
    // Live data: what the ECU last sent on a message, at DID 0x0100 + its identifier.
    let trac = autoplug_can::Frame::new(0x00F, &[42]).unwrap();
    node.note_sent(t(41), &trac);
    let request = autoplug_can::Frame::new(0x70E, &[0x03, 0x22, 0x01, 0x0F, 0, 0, 0, 0]).unwrap();
    node.on_frame(t(42), &request, &mut ecu);
    let mut responses = Vec::new();
    for _ in 0..10 {
        node.poll(t(42), &mut ecu);
        while let Some(frame) = node.poll_transmit(t(42)) {
            node.confirm_transmit(t(42));
            responses.push(frame);
        }
    }
    let live = responses
        .iter()
        .find(|f| f.data()[1] == 0x62)
        .expect("a 0x22 response");
    assert_eq!(live.id(), 0x78E);
    assert_eq!(live.data()[..5], [0x04, 0x62, 0x01, 0x0F, 42]);
}

#[test]
fn one_spoofed_zero_speed_frame_does_not_open_programming_at_speed() {
    let mut wire = Wire::new();
    assert_eq!(
        wire.exchange(&[0x10, 0x03], 1000).unwrap()[..2],
        [0x50, 0x03]
    );
    // Driving at 90 km/h for a second.
    wire.drive(90.0, 1000);
    assert_eq!(wire.ecu_node.vehicle_speed_kmh(wire.now), Some(90.0));
    // An attacker's single zero-speed frame, just before the request: the last frame the
    // ECU heard says "standing", but the car was not seen standing over the window.
    wire.now = wire.now.plus_micros(1000);
    wire.ecu_node.observe(wire.now, &speed_frame(0.0));
    assert!(!wire.ecu_node.vehicle_standing(wire.now));
    // (`exchange` itself feeds standing frames every 250 us; keep its request short.)
    let request_at_speed = |wire: &mut Wire| {
        wire.tester.send(wire.now, &[0x10, 0x02]).unwrap();
        for _ in 0..400 {
            wire.now = wire.now.plus_micros(250);
            wire.ecu_node.poll(wire.now, &mut wire.ecu);
            if let Some(frame) = wire.tester.poll_transmit(wire.now) {
                wire.tester.confirm_transmit(wire.now);
                wire.ecu_node.on_frame(wire.now, &frame, &mut wire.ecu);
            } else if let Some(frame) = wire.ecu_node.poll_transmit(wire.now) {
                wire.ecu_node.confirm_transmit(wire.now);
                if let Some(autoplug_isotp::Event::Received { len, .. }) =
                    wire.tester.on_frame(wire.now, &frame)
                {
                    let response = wire.tester.received()[..len].to_vec();
                    wire.tester.release();
                    return response;
                }
            }
            while wire.tester.poll(wire.now).is_some() {}
        }
        panic!("no answer")
    };
    assert_eq!(
        request_at_speed(&mut wire),
        [0x7F, 0x10, 0x22],
        "conditions not correct: the car was not seen standing"
    );
    // Zero-speed frames over the whole window, as from an attacker who silenced the real
    // sender: the ECU's own sensors (wheels turning, engine above idle) still veto.
    wire.drive(0.0, 600);
    assert!(wire.ecu_node.vehicle_standing(wire.now));
    wire.ecu.own_motion = true;
    assert_eq!(
        request_at_speed(&mut wire),
        [0x7F, 0x10, 0x22],
        "the ECU's own sensors show motion"
    );
    // Standing for real, over the window, by the bus and the ECU's sensors: allowed.
    wire.ecu.own_motion = false;
    wire.drive(0.0, 600);
    assert_eq!(request_at_speed(&mut wire)[..2], [0x50, 0x02]);
}

#[test]
fn seeds_differ_across_cars_starts_and_draws_and_replay_per_car() {
    use crate::security::SeedSource;
    let draw = |entropy: &[u8], epoch: u32, nth: usize| {
        let mut source = SeedSource::new(entropy, epoch);
        let mut seed = [0u8; 16];
        for _ in 0..=nth {
            source.fill(&mut seed);
        }
        seed
    };
    let first = draw(b"car 1", 1, 0);
    assert_eq!(
        first,
        draw(b"car 1", 1, 0),
        "the same car and start replays"
    );
    assert_ne!(first, draw(b"car 2", 1, 0), "another car");
    assert_ne!(first, draw(b"car 1", 2, 0), "the next start");
    assert_ne!(first, draw(b"car 1", 1, 1), "the next seed");
    let mut mixed = SeedSource::new(b"car 1", 1);
    mixed.add_entropy(&[0x5A]);
    let mut seed = [0u8; 16];
    mixed.fill(&mut seed);
    assert_ne!(first, seed, "entropy added changes the seeds");
    assert_eq!(mixed.epoch(), 1);
}
