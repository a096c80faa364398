//! The ECU side of firmware upgrades on the F446: the UDS server's [`Backend`] over the
//! MCU's own flash (the image slot not running, the two-copy persistent state with the boot
//! record and the ECU data records), the identification of the running image, the
//! self-test that confirms a new image, and a watchdog that outlasts the long flash
//! operations.
//!
//! Erasing a 128 KiB sector stalls the core for about a second (the code runs from the
//! flash being erased), far beyond the control loop's watchdog timeout: the watchdog is
//! stretched to [`FLASH_WATCHDOG_TIMEOUT_US`] for each such operation and restored after.

use core::cell::RefCell;

use autoplug_can::Node;
use autoplug_ecu::Dtcs;
use autoplug_flash::ab::{self, BootState, ImageSlot};
use autoplug_flash::twin::Twin;
use autoplug_flash::{LARGE_SECTORS, SLOT_ERASE_SIZE, SMALL_SECTORS, STATE_COPIES};
use autoplug_image::{dev, floor, Expectations, ImageHeader, Version, HEADER_LEN, NUCLEO_F446RE};
use autoplug_uds::security::SeedSource;
use autoplug_uds::{Backend, FlashError, Identification};
use embassy_embedded_hal::flash::partition::BlockingPartition;
use embassy_stm32::flash::{Bank1Region1, Bank1Region3, Blocking};
use embassy_stm32::pac;
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_sync::blocking_mutex::Mutex;

/// Watchdog timeout during a flash operation: above the datasheet's worst 128 KiB sector
/// erase (2 s).
pub const FLASH_WATCHDOG_TIMEOUT_US: u32 = 4_000_000;

/// The version a firmware flashed by a probe (without an image header) reports.
const UNSIGNED_VERSION: Version = Version::new(0, 0, 0);

/// The flash of the ECU as the diagnostic server uses it.
pub struct EcuFlash {
    small: Mutex<NoopRawMutex, RefCell<Bank1Region1<'static, Blocking>>>,
    large: Mutex<NoopRawMutex, RefCell<Bank1Region3<'static, Blocking>>>,
    /// The slot this code runs from.
    running: ImageSlot,
    /// What the boot record says of it, read at start and after a confirmation.
    boot_state: BootState,
    header: Option<ImageHeader>,
    version_text: [u8; 16],
    version_len: usize,
    serial: [u8; 24],
    floor: Version,
}

impl EcuFlash {
    /// Reads what the running slot holds, the boot record and the stored version floor.
    pub fn new(
        small: Bank1Region1<'static, Blocking>,
        large: Bank1Region3<'static, Blocking>,
    ) -> Self {
        let running = running_slot();
        let mut flash = Self {
            small: Mutex::new(RefCell::new(small)),
            large: Mutex::new(RefCell::new(large)),
            running,
            boot_state: BootState::Confirmed,
            header: None,
            version_text: [0; 16],
            version_len: 0,
            serial: hex_uid(),
            floor: UNSIGNED_VERSION,
        };
        let mut bytes = [0u8; HEADER_LEN];
        let read = flash.large.lock(|r| {
            r.borrow_mut()
                .blocking_read(running.region().start - LARGE_SECTORS.start, &mut bytes)
        });
        flash.header = read.ok().and_then(|()| ImageHeader::parse(&bytes).ok());
        flash.boot_state = flash
            .with_twin(|twin| ab::state(twin, running).ok())
            .flatten()
            .unwrap_or(BootState::Confirmed);
        let version = flash.header.map_or(UNSIGNED_VERSION, |h| h.version);
        flash.version_len = write_version(&mut flash.version_text, version);
        flash.floor = flash.read_floor().unwrap_or(UNSIGNED_VERSION);
        match &flash.header {
            Some(h) => defmt::info!(
                "running image {=str} from slot {=char} {=u8}.{=u8}.{=u16} (variant {=u8}), version floor {=u8}.{=u8}.{=u16}",
                h.part_number.as_str(),
                running.letter(),
                h.version.major,
                h.version.minor,
                h.version.patch,
                h.variant.as_u8(),
                flash.floor.major,
                flash.floor.minor,
                flash.floor.patch
            ),
            None => defmt::warn!(
                "no image header in slot {=char}: flashed by a probe?",
                running.letter()
            ),
        }
        flash
    }

    /// What the boot record says of the running image (Trial: started once after an
    /// update and not confirmed yet; the next reset reverts it).
    pub fn boot_state(&self) -> BootState {
        self.boot_state
    }

    /// Raises the seed epoch kept in flash and returns the new one: every start draws its
    /// seeds under a number no earlier start used (a failed write is logged; the seeds
    /// still differ by the entropy of this start).
    pub fn next_seed_epoch(&self) -> u32 {
        let epoch = stretched(|| self.with_twin(|twin| twin.raise_seed_epoch()));
        match epoch {
            Some((epoch, Ok(()))) => epoch,
            Some((epoch, Err(_))) => {
                defmt::warn!("the seed epoch {} could not be kept", epoch);
                epoch
            }
            None => 0,
        }
    }

    /// Confirms the running image after its self-test and raises the version floor to it.
    pub fn confirm(&mut self) -> bool {
        let running = self.running;
        let confirmed =
            stretched(|| self.with_twin(|twin| ab::confirm(twin, running).is_ok())) == Some(true);
        if confirmed {
            self.boot_state = BootState::Confirmed;
        }
        if let Some(version) = self.header.map(|h| h.version) {
            if confirmed && version > self.floor && stretched(|| self.write_floor(version)).is_ok()
            {
                self.floor = version;
            }
        }
        confirmed
    }

    /// Runs `op` on the two-copy persistent state (the boot record and the ECU data
    /// records); `None` if the copies cannot be read.
    fn with_twin<T>(&self, op: impl FnOnce(&mut Twin<SmallRegion<'_>>) -> T) -> Option<T> {
        let copies = STATE_COPIES.map(|copy| {
            BlockingPartition::new(&self.small, copy.start - SMALL_SECTORS.start, copy.size)
        });
        let mut twin = Twin::open(copies).ok()?;
        Some(op(&mut twin))
    }

    /// The version floor kept in flash.
    fn read_floor(&self) -> Option<Version> {
        self.with_twin(|twin| twin.read_record(floor::KIND).ok().flatten())
            .flatten()
            .map(floor::from_payload)
    }

    /// Records a new version floor.
    fn write_floor(&self, version: Version) -> Result<(), FlashError> {
        self.with_twin(|twin| twin.write_record(floor::KIND, floor::to_payload(version)))
            .and_then(Result::ok)
            .ok_or(FlashError)
    }

    /// The offset in the 128 KiB sectors (flash region 3) of `offset` in the slot a
    /// download goes to: the one not running.
    fn dfu_offset(&self, offset: u32) -> u32 {
        self.running.other().region().start - LARGE_SECTORS.start + offset
    }
}

/// The slot this code runs from: where its own functions lie (an image is linked for one
/// slot and runs in place there).
fn running_slot() -> ImageSlot {
    let here = running_slot as fn() -> ImageSlot as usize as u32;
    if ImageSlot::B.region().contains(here) {
        ImageSlot::B
    } else {
        ImageSlot::A
    }
}

/// A partition of the 16 KiB sectors (flash region 1).
type SmallRegion<'a> = BlockingPartition<'a, NoopRawMutex, Bank1Region1<'static, Blocking>>;

/// The MCU's 96-bit unique ID in hex: the ECU serial number (UDS F18C).
fn hex_uid() -> [u8; 24] {
    const HEX: &[u8; 16] = b"0123456789ABCDEF";
    let uid = embassy_stm32::uid::uid();
    let mut out = [0u8; 24];
    for (i, byte) in uid.iter().enumerate() {
        out[2 * i] = HEX[usize::from(byte >> 4)];
        out[2 * i + 1] = HEX[usize::from(byte & 0x0F)];
    }
    out
}

/// "major.minor.patch" into `out`; returns its length.
fn write_version(out: &mut [u8; 16], version: Version) -> usize {
    let mut len = 0;
    for (i, part) in [
        u32::from(version.major),
        u32::from(version.minor),
        u32::from(version.patch),
    ]
    .into_iter()
    .enumerate()
    {
        if i > 0 {
            out[len] = b'.';
            len += 1;
        }
        len += write_decimal(&mut out[len..], part);
    }
    len
}

/// `n` in decimal at the start of `out`; returns the digits written.
fn write_decimal(out: &mut [u8], mut n: u32) -> usize {
    let mut digits = [0u8; 10];
    let mut count = 0;
    loop {
        digits[count] = b'0' + (n % 10) as u8;
        count += 1;
        n /= 10;
        if n == 0 {
            break;
        }
    }
    for (slot, digit) in out.iter_mut().zip(digits[..count].iter().rev()) {
        *slot = *digit;
    }
    count
}

/// Runs a long flash operation with the watchdog stretched, then restores it.
fn stretched<T>(op: impl FnOnce() -> T) -> T {
    let iwdg = pac::IWDG;
    let (pr, rlr) = (iwdg.pr().read(), iwdg.rlr().read());
    load_watchdog(
        pac::iwdg::vals::Pr::DIVIDE_BY64,
        (FLASH_WATCHDOG_TIMEOUT_US / 2_000).min(0xFFF) as u16,
    );
    let result = op();
    load_watchdog(pr.pr(), rlr.rl());
    result
}

/// Sets the watchdog's prescaler and reload (at the 32 kHz LSI; 2 ms a count at /64) and
/// feeds it with them. The new values reach the watchdog's own clock domain up to five LSI
/// cycles later (SR.PVU and SR.RVU busy meanwhile, RM0390 21.4.4): a feed before that
/// would count down from the old ones, and a long erase would meet the 100 ms watchdog.
fn load_watchdog(prescaler: pac::iwdg::vals::Pr, reload: u16) {
    let iwdg = pac::IWDG;
    iwdg.kr().write(|w| w.set_key(pac::iwdg::vals::Key::ENABLE));
    iwdg.pr().write(|w| w.set_pr(prescaler));
    iwdg.rlr().write(|w| w.set_rl(reload));
    feed_watchdog_when_loaded();
}

/// Feeds the watchdog once its prescaler and reload writes have reached it. Also right
/// after it is started: the start counts down from 0xFFF at the prescaler then in use
/// (RM0390 21.3.1), which after the seed sampler's /32 is 4 s, not the loop's 100 ms, so a
/// hang before the first control step would go unnoticed that long.
pub(crate) fn feed_watchdog_when_loaded() {
    let iwdg = pac::IWDG;
    // Bounded: the LSI runs whenever the watchdog does, so this ends within five LSI
    // cycles (about 150 us); a chip whose LSI had stopped must not hang here.
    let mut polls = 0u32;
    while iwdg.sr().read().0 != 0 && polls < crate::entropy::MAX_POLLS {
        polls += 1;
    }
    iwdg.kr().write(|w| w.set_key(pac::iwdg::vals::Key::RESET));
}

/// The ECU as its UDS server sees it, for one call.
pub struct FirmwareBackend<'a> {
    /// The ECU's node.
    pub node: Node,
    /// Its flash.
    pub flash: &'a mut EcuFlash,
    /// The logic's DTCs.
    pub dtcs: &'a mut Dtcs,
    /// Where security seeds come from (see [`crate::entropy`]).
    pub seeds: &'a mut SeedSource,
    /// The logic's own sensors show the car moving (a veto on programming).
    pub own_motion: bool,
}

impl Backend for FirmwareBackend<'_> {
    fn identification(&self) -> Identification<'_> {
        Identification {
            part_number: self
                .flash
                .header
                .as_ref()
                .map_or(b"AP-UNSIGNED".as_slice(), |h| {
                    h.part_number.as_str().as_bytes()
                }),
            software_version: &self.flash.version_text[..self.flash.version_len],
            serial_number: &self.flash.serial,
            hardware_version: b"NUCLEO-F446RE",
            // Not yet written at the end of the line: F190 is not answered.
            vin: b"",
            boot_slot: Some((self.flash.running, self.flash.boot_state)),
        }
    }

    fn dtcs(&mut self) -> &mut Dtcs {
        self.dtcs
    }

    fn own_sensors_show_motion(&self) -> bool {
        self.own_motion
    }

    fn fill_random(&mut self, out: &mut [u8]) {
        // The moment of the request, to the CPU cycle, is one more input.
        self.seeds
            .add_entropy(&cortex_m::peripheral::DWT::cycle_count().to_le_bytes());
        self.seeds.fill(out);
    }

    fn stored_key_failures(&mut self) -> u8 {
        self.flash
            .with_twin(|twin| twin.key_failures().ok())
            .flatten()
            .unwrap_or(0)
    }

    fn store_key_failures(&mut self, failures: u8) -> Result<(), FlashError> {
        let flash = &*self.flash;
        // A record is one word program; when a copy is full, a switch erases 16 KiB.
        stretched(|| flash.with_twin(|twin| twin.store_key_failures(failures)))
            .and_then(Result::ok)
            .ok_or(FlashError)
    }

    fn image_expectations(&self) -> Expectations {
        Expectations {
            node: self.node.diag_node_number().unwrap_or(0),
            hardware_id: NUCLEO_F446RE,
            version_floor: self.flash.floor,
            max_image_len: self.flash.running.other().region().size,
            load_address: self.flash.running.other().vector_table(),
            runs_machine_code: true,
        }
    }

    fn public_key(&self) -> [u8; 32] {
        dev::PUBLIC_KEY
    }

    fn dfu_erase_steps(&self, len: u32) -> u32 {
        len.min(self.flash.running.other().region().size)
            .div_ceil(SLOT_ERASE_SIZE)
    }

    fn dfu_erase(&mut self, step: u32) -> Result<(), FlashError> {
        let flash = &*self.flash;
        let (running, target) = (flash.running, flash.running.other());
        let from = flash.dfu_offset(step * SLOT_ERASE_SIZE);
        stretched(|| {
            if step == 0 {
                // Refused while the running image is on trial; withdraws an earlier
                // download's trial mark of the slot before it is erased.
                flash
                    .with_twin(|twin| ab::prepare_download(twin, running, target).is_ok())
                    .filter(|&prepared| prepared)
                    .ok_or(FlashError)?;
            }
            flash.large.lock(|r| {
                r.borrow_mut()
                    .blocking_erase(from, from + SLOT_ERASE_SIZE)
                    .map_err(|_| FlashError)
            })
        })
    }

    fn dfu_write(&mut self, offset: u32, data: &[u8]) -> Result<(), FlashError> {
        let at = self.flash.dfu_offset(offset);
        self.flash.large.lock(|r| {
            r.borrow_mut()
                .blocking_write(at, data)
                .map_err(|_| FlashError)
        })
    }

    fn dfu_read(&mut self, offset: u32, out: &mut [u8]) -> Result<(), FlashError> {
        let at = self.flash.dfu_offset(offset);
        self.flash.large.lock(|r| {
            r.borrow_mut()
                .blocking_read(at, out)
                .map_err(|_| FlashError)
        })
    }

    fn mark_updated(&mut self) -> Result<(), FlashError> {
        let flash = &*self.flash;
        let (running, target) = (flash.running, flash.running.other());
        stretched(|| {
            flash.with_twin(|twin| ab::mark_trial(twin, running, target).map_err(|_| FlashError))
        })
        .unwrap_or(Err(FlashError))
    }
}
