//! A simulated STM32F446RE flash: NOR semantics, datasheet timings, and power cuts.
//!
//! # NOR semantics
//!
//! The flash reads [`ERASE_VALUE`] (0xFF) after an erase; erasing works on whole sectors;
//! programming works on 32-bit words ([`WRITE_SIZE`]) and can only clear bits.
//!
//! RM0390 ("Standard programming") allows programming a word again without an erase as long as
//! bits only go from 1 to 0, and says writing a 1 needs an erase. As far as RM0390 tells, the
//! F4 does not check this: there is no "location not erased" error like the F1's `PGERR`
//! (`PGSERR`, the programming sequence error, is about the `FLASH_CR` set-up), so on the
//! silicon such a write silently leaves `old & new`. The simulation is stricter on purpose:
//! a write whose data would need any 0 → 1 change is refused as a whole with
//! [`FlashError::NeedsErase`] before anything is programmed, so that a driver or updater bug
//! shows up in a test instead of as corrupt data. Programming a word that is not erased but
//! only clears further bits (or rewrites the same value) is allowed, as on the part, and
//! counted in [`FlashStats::reprogrammed_words`].
//!
//! # Operations, timing and power cuts
//!
//! An *operation* is one sector erase, or one `program` call (whatever its length; a
//! zero-length call is not one). [`SimFlash::erase`] over several sectors is one operation per
//! sector, in address order, as the F4 erases one sector per `STRT`. Operations are numbered
//! from 0 from the flash's creation ([`SimFlash::operations`] is how many have started).
//! Calls refused for their arguments or because the power is off start no operation.
//!
//! Each operation charges its busy time ([`crate::timing`]): 16 µs per word, 250/550/1000 ms
//! per 16/64/128 KiB sector. [`SimFlash::last_busy`] is the last operation's, and
//! [`SimFlash::total_busy`] the running total, so a simulation can stall the ECU exactly as
//! long as the real core would stall on the busy flash.
//!
//! [`SimFlash::cut_power_at`]`(k)` interrupts the `k`-th operation counted from that call
//! (0-based: `cut_power_at(0)` interrupts the very next one). What an interrupted operation
//! leaves is decided by a generator seeded at [`SimFlash::new`], so a run is reproducible:
//!
//! - an interrupted **program** of n words leaves words `0..k` programmed, word `k`
//!   half-programmed (a seeded subset of the bits it should clear is cleared: it may read as
//!   old, new or anything in between), and words after `k` untouched, with `k` drawn from
//!   `0..n`. The F4 programs one word after the other, so a prefix is what a cut leaves.
//! - an interrupted **erase** leaves the sector neither old nor erased. The real part erases
//!   all cells of a sector at once, so a cut leaves them scattered between the two states
//!   rather than a clean erased prefix: the generator draws how far the erase got (a share
//!   `p` in 0..1), then every word independently reads as garbage (random bits, one word in
//!   eight), as erased (share `p` of the others) or as its old value.
//!
//! After the cut the flash is unpowered: every erase or program fails with
//! [`FlashError::PowerLost`] and changes nothing until [`SimFlash::restore_power`] ("the ECU
//! is powered again"). Reads keep working and return the contents as the cut left them (the
//! test harness inspects the flash while the ECU is off).

use core::cell::RefCell;
use core::fmt;
use core::time::Duration;
use std::vec;
use std::vec::Vec;

use embedded_storage::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

use crate::map::{
    partition_of, Region, Sector, ERASE_VALUE, FLASH, FLASH_BASE, SECTORS, SLOT_ERASE_SIZE,
    SMALL_ERASE_SIZE, STATE_COPIES, WRITE_SIZE,
};
use crate::timing::{sector_erase_time, WORD_PROGRAM_TIME};
use crate::twin::{Twin, TwinError};

/// A word as it reads when erased.
const ERASED_WORD: u32 = u32::from_le_bytes([ERASE_VALUE; 4]);

/// Writes `0x0804_0000`-style addresses, as the reference manual does.
struct Addr(u32);

impl fmt::Display for Addr {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "0x{:04X}_{:04X}", self.0 >> 16, self.0 & 0xFFFF)
    }
}

/// Names the partition holding an address, for messages.
fn partition_name(address: u32) -> &'static str {
    match partition_of(address) {
        Some((name, _)) => name,
        None => "outside the map",
    }
}

/// What went wrong with a flash access.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FlashError {
    /// The access reaches outside the 512 KiB main flash.
    OutsideFlash {
        /// First address of the access.
        address: u32,
        /// Length of the access in bytes.
        len: u32,
    },
    /// The access reaches past the end of a partition.
    OutOfBounds {
        /// The partition.
        region: Region,
        /// Offset of the access in the partition.
        offset: u32,
        /// Length of the access in bytes.
        len: u32,
    },
    /// A program's address or length is not a whole number of words.
    NotAligned {
        /// First address of the write.
        address: u32,
        /// Length of the write in bytes.
        len: u32,
    },
    /// An erase range ends before it starts, or does not start and end on sector boundaries.
    BadEraseRange {
        /// First address to erase.
        from: u32,
        /// One past the last address to erase.
        to: u32,
    },
    /// There is no sector with this number.
    NoSuchSector {
        /// The sector number asked for.
        index: u8,
    },
    /// Programming this word would need a bit to go from 0 to 1, which only an erase does.
    NeedsErase {
        /// Address of the word.
        address: u32,
        /// What the word holds.
        current: u32,
        /// What the write asked for.
        requested: u32,
    },
    /// A partition was asked for over a region not made of sectors of its erase size.
    EraseSizeMismatch {
        /// The region.
        region: Region,
        /// The partition type's erase size.
        erase_size: u32,
    },
    /// The power was cut (see [`SimFlash::cut_power_at`]) and is not restored yet.
    PowerLost,
}

impl fmt::Display for FlashError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            FlashError::OutsideFlash { address, len } => write!(
                f,
                "{len} bytes at {} reach outside the flash ({}..{})",
                Addr(address),
                Addr(FLASH.start),
                Addr(FLASH.end())
            ),
            FlashError::OutOfBounds { region, offset, len } => write!(
                f,
                "{len} bytes at offset {offset:#x} reach past the end of the {}-byte {} partition at {}",
                region.size,
                partition_name(region.start),
                Addr(region.start)
            ),
            FlashError::NotAligned { address, len } => write!(
                f,
                "program of {len} bytes at {} is not whole {WRITE_SIZE}-byte words",
                Addr(address)
            ),
            FlashError::BadEraseRange { from, to } if from > to => {
                write!(f, "erase range {}..{} ends before it starts", Addr(from), Addr(to))
            }
            FlashError::BadEraseRange { from, to } => write!(
                f,
                "erase range {}..{} does not start and end on sector boundaries",
                Addr(from),
                Addr(to)
            ),
            FlashError::NoSuchSector { index } => {
                write!(f, "there is no sector {index} (the F446RE has 0..={})", SECTORS.len() - 1)
            }
            FlashError::NeedsErase { address, current, requested } => write!(
                f,
                "programming {requested:#010x} over {current:#010x} at {} ({}) needs a 0 -> 1 bit change; erase the sector first",
                Addr(address),
                partition_name(address)
            ),
            FlashError::EraseSizeMismatch { region, erase_size } => write!(
                f,
                "the region {}..{} is not made of {erase_size}-byte sectors",
                Addr(region.start),
                Addr(region.end())
            ),
            FlashError::PowerLost => write!(f, "the flash lost power; operations fail until the power is restored"),
        }
    }
}

impl std::error::Error for FlashError {}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match *self {
            FlashError::OutsideFlash { .. }
            | FlashError::OutOfBounds { .. }
            | FlashError::NoSuchSector { .. } => NorFlashErrorKind::OutOfBounds,
            // embedded-storage's `check_erase` calls a reversed range out of bounds.
            FlashError::BadEraseRange { from, to } if from > to => NorFlashErrorKind::OutOfBounds,
            FlashError::NotAligned { .. } | FlashError::BadEraseRange { .. } => {
                NorFlashErrorKind::NotAligned
            }
            FlashError::NeedsErase { .. }
            | FlashError::EraseSizeMismatch { .. }
            | FlashError::PowerLost => NorFlashErrorKind::Other,
        }
    }
}

/// One flash operation, as recorded by [`SimFlash::record_trace`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FlashOp {
    /// Erase of one sector.
    Erase {
        /// The sector.
        sector: Sector,
    },
    /// One program call.
    Program {
        /// First address.
        address: u32,
        /// Length in bytes.
        len: u32,
    },
}

impl fmt::Display for FlashOp {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            FlashOp::Erase { sector } => write!(
                f,
                "erase of sector {} ({}, {} KiB at {})",
                sector.index,
                partition_name(sector.start),
                sector.size / 1024,
                Addr(sector.start)
            ),
            FlashOp::Program { address, len } => write!(
                f,
                "program of {len} bytes at {} ({} + {:#x})",
                Addr(address),
                partition_name(address),
                partition_of(address).map_or(0, |(_, region)| address - region.start)
            ),
        }
    }
}

/// Counters of what the flash did since it was created.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FlashStats {
    /// Operations started (erased sectors plus program calls, interrupted ones included).
    pub operations: u64,
    /// Sector erases started.
    pub sector_erases: u64,
    /// Program calls started.
    pub program_calls: u64,
    /// Words fully programmed.
    pub words_programmed: u64,
    /// Words programmed that were not erased before (only clearing further bits).
    pub reprogrammed_words: u64,
    /// Operations interrupted by a power cut.
    pub interrupted: u64,
    /// Busy time spent erasing.
    pub erase_busy: Duration,
    /// Busy time spent programming.
    pub program_busy: Duration,
}

impl FlashStats {
    /// Total busy time, erasing and programming.
    pub fn busy(&self) -> Duration {
        self.erase_busy + self.program_busy
    }
}

/// SplitMix64: a small, well-mixed generator; all the simulation needs is reproducible
/// garbage, not cryptographic quality.
#[derive(Clone, Debug)]
struct SeededRng(u64);

impl SeededRng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    fn next_u32(&mut self) -> u32 {
        (self.next_u64() >> 32) as u32
    }

    /// A value in `0..n` (n > 0), by multiply-shift: no modulo bias worth the name here.
    fn below(&mut self, n: u64) -> u64 {
        ((u128::from(self.next_u64()) * u128::from(n)) >> 64) as u64
    }
}

/// The whole 512 KiB main flash of an STM32F446RE, simulated. See the [module docs](self).
/// A clone is the same flash at the same moment (for sweeps that start many runs there).
#[derive(Clone)]
pub struct SimFlash {
    /// The flash's bytes, each stored inverted: an erased flash (all 0xFF) is then a
    /// zeroed allocation, which the OS hands out lazily, so a virtual car's nine 512 KiB
    /// flashes cost only the pages their images touch (and no 4.5 MB memset at start).
    inverted: Vec<u8>,
    rng: SeededRng,
    powered: bool,
    /// Absolute number of the operation to interrupt.
    cut_at: Option<u64>,
    last_busy: Duration,
    stats: FlashStats,
    trace: Option<Vec<FlashOp>>,
    last_error: Option<FlashError>,
}

impl fmt::Debug for SimFlash {
    // The contents are 512 KiB: show the state, not the bytes.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SimFlash")
            .field("powered", &self.powered)
            .field("cut_at", &self.cut_at)
            .field("stats", &self.stats)
            .field("last_error", &self.last_error)
            .finish_non_exhaustive()
    }
}

impl SimFlash {
    /// An erased, powered flash. `seed` decides what interrupted operations leave.
    pub fn new(seed: u64) -> Self {
        SimFlash {
            inverted: vec![!ERASE_VALUE; FLASH.size as usize],
            rng: SeededRng(seed),
            powered: true,
            cut_at: None,
            last_busy: Duration::ZERO,
            stats: FlashStats::default(),
            trace: None,
            last_error: None,
        }
    }

    /// Index into `inverted` of `len` bytes at `address`, if they are all in the flash.
    fn index_of(&self, address: u32, len: usize) -> Result<usize, FlashError> {
        let outside = FlashError::OutsideFlash {
            address,
            len: u32::try_from(len).unwrap_or(u32::MAX),
        };
        let start = address.checked_sub(FLASH_BASE).ok_or(outside.clone())? as usize;
        match start.checked_add(len) {
            Some(end) if end <= self.inverted.len() => Ok(start),
            _ => Err(outside),
        }
    }

    /// Reads `buf.len()` bytes at `address`. Works with the power off.
    pub fn read(&self, address: u32, buf: &mut [u8]) -> Result<(), FlashError> {
        let start = self.index_of(address, buf.len())?;
        for (out, stored) in buf.iter_mut().zip(&self.inverted[start..]) {
            *out = !stored;
        }
        Ok(())
    }

    /// The word at `address` (word-aligned), all ones outside the flash: the emulated
    /// core's fetches and loads, which must not allocate or check a slice per access.
    #[inline]
    pub fn read_word(&self, address: u32) -> u32 {
        let start = address.wrapping_sub(FLASH_BASE) as usize;
        match self.inverted.get(start..start + 4) {
            Some(bytes) => !u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]),
            None => u32::MAX,
        }
    }

    /// A copy of the contents of `region`. Works with the power off.
    pub fn contents(&self, region: Region) -> Result<Vec<u8>, FlashError> {
        let mut bytes = vec![0; region.size as usize];
        self.read(region.start, &mut bytes)?;
        Ok(bytes)
    }

    /// Programs `data` at `address`: one operation. Both must be whole words; every word
    /// must be programmable without a 0 → 1 change (see the [module docs](self)).
    pub fn program(&mut self, address: u32, data: &[u8]) -> Result<(), FlashError> {
        let result = self.program_inner(address, data);
        self.note(result)
    }

    /// Erases sector `index`: one operation.
    pub fn erase_sector(&mut self, index: u8) -> Result<(), FlashError> {
        let result = self.erase_sector_inner(index);
        self.note(result)
    }

    /// Erases the sectors of `from..to` (absolute addresses on sector boundaries), one
    /// operation per sector in address order; stops at the first failure.
    pub fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        let result = self.erase_inner(from, to);
        self.note(result)
    }

    /// Reseeds the generator that decides what interrupted operations leave.
    pub fn reseed(&mut self, seed: u64) {
        self.rng = SeededRng(seed);
    }

    /// Arms a power cut: the `operation`-th erase or program from now (0-based) is
    /// interrupted, and the flash stays unpowered after it. Replaces any cut already armed.
    pub fn cut_power_at(&mut self, operation: u64) {
        self.cut_at = Some(self.stats.operations + operation);
    }

    /// Disarms a power cut that has not happened yet.
    pub fn cancel_cut(&mut self) {
        self.cut_at = None;
    }

    /// How many operations from now the armed cut will interrupt, if one is armed.
    pub fn pending_cut(&self) -> Option<u64> {
        self.cut_at.map(|at| at - self.stats.operations)
    }

    /// The ECU is powered again: erases and programs work again, on the contents as left.
    pub fn restore_power(&mut self) {
        self.powered = true;
    }

    /// Whether the flash is powered (no cut since the last [`restore_power`](Self::restore_power)).
    pub fn is_powered(&self) -> bool {
        self.powered
    }

    /// Operations started since creation: the number the next operation will have.
    pub fn operations(&self) -> u64 {
        self.stats.operations
    }

    /// Busy time of the last operation (up to the cut for an interrupted one).
    pub fn last_busy(&self) -> Duration {
        self.last_busy
    }

    /// Busy time of all operations since creation.
    pub fn total_busy(&self) -> Duration {
        self.stats.busy()
    }

    /// Counters since creation.
    pub fn stats(&self) -> FlashStats {
        self.stats
    }

    /// Starts (or stops, and clears) recording every operation started, for diagnostics.
    pub fn record_trace(&mut self, on: bool) {
        self.trace = if on { Some(Vec::new()) } else { None };
    }

    /// The operations recorded since [`record_trace`](Self::record_trace)`(true)`.
    pub fn trace(&self) -> &[FlashOp] {
        self.trace.as_deref().unwrap_or(&[])
    }

    /// The last error an erase or program returned (a `NorFlash` user sees only its kind).
    pub fn last_error(&self) -> Option<&FlashError> {
        self.last_error.as_ref()
    }

    fn note(&mut self, result: Result<(), FlashError>) -> Result<(), FlashError> {
        if let Err(error) = &result {
            self.last_error = Some(error.clone());
        }
        result
    }

    fn check_powered(&self) -> Result<(), FlashError> {
        if self.powered {
            Ok(())
        } else {
            Err(FlashError::PowerLost)
        }
    }

    /// Numbers a new operation; returns whether the power cut interrupts it.
    fn start_operation(&mut self, op: FlashOp) -> bool {
        let number = self.stats.operations;
        self.stats.operations += 1;
        if let Some(trace) = &mut self.trace {
            trace.push(op);
        }
        let interrupted = self.cut_at == Some(number);
        if interrupted {
            self.cut_at = None;
            self.powered = false;
            self.stats.interrupted += 1;
        }
        interrupted
    }

    fn word_at(&self, index: usize) -> u32 {
        !u32::from_le_bytes([
            self.inverted[index],
            self.inverted[index + 1],
            self.inverted[index + 2],
            self.inverted[index + 3],
        ])
    }

    fn set_word(&mut self, index: usize, word: u32) {
        self.inverted[index..index + WRITE_SIZE].copy_from_slice(&(!word).to_le_bytes());
    }

    fn program_inner(&mut self, address: u32, data: &[u8]) -> Result<(), FlashError> {
        // A dead flash refuses everything, even malformed calls: nothing runs without power.
        self.check_powered()?;
        let start = self.index_of(address, data.len())?;
        if address as usize % WRITE_SIZE != 0 || data.len() % WRITE_SIZE != 0 {
            return Err(FlashError::NotAligned {
                address,
                len: data.len() as u32,
            });
        }
        if data.is_empty() {
            return Ok(());
        }
        let words: Vec<u32> = data
            .chunks_exact(WRITE_SIZE)
            .map(|w| u32::from_le_bytes([w[0], w[1], w[2], w[3]]))
            .collect();
        // Refuse the whole call before touching anything (see the module docs on why the
        // simulation is stricter than the silicon here).
        for (i, &requested) in words.iter().enumerate() {
            let current = self.word_at(start + i * WRITE_SIZE);
            if current & requested != requested {
                return Err(FlashError::NeedsErase {
                    address: address + (i * WRITE_SIZE) as u32,
                    current,
                    requested,
                });
            }
        }

        self.stats.program_calls += 1;
        let interrupted = self.start_operation(FlashOp::Program {
            address,
            len: data.len() as u32,
        });
        let complete = if interrupted {
            self.rng.below(words.len() as u64) as usize
        } else {
            words.len()
        };
        for (i, &requested) in words.iter().enumerate().take(complete) {
            let index = start + i * WRITE_SIZE;
            if self.word_at(index) != ERASED_WORD {
                self.stats.reprogrammed_words += 1;
            }
            self.set_word(index, requested);
        }
        self.stats.words_programmed += complete as u64;
        let mut busy = WORD_PROGRAM_TIME * complete as u32;
        if interrupted {
            // The word being programmed when the supply went: some of its bits made it.
            let index = start + complete * WRITE_SIZE;
            let current = self.word_at(index);
            let to_clear = current & !words[complete];
            let cleared = to_clear & self.rng.next_u32();
            self.set_word(index, current & !cleared);
            busy += WORD_PROGRAM_TIME / 2;
        }
        self.last_busy = busy;
        self.stats.program_busy += busy;
        if interrupted {
            Err(FlashError::PowerLost)
        } else {
            Ok(())
        }
    }

    fn erase_sector_inner(&mut self, index: u8) -> Result<(), FlashError> {
        self.check_powered()?;
        let sector = *SECTORS
            .get(index as usize)
            .ok_or(FlashError::NoSuchSector { index })?;
        let full_time = sector_erase_time(sector.size).unwrap_or(Duration::ZERO);
        let start = (sector.start - FLASH_BASE) as usize;
        let range = start..start + sector.size as usize;
        self.stats.sector_erases += 1;
        if !self.start_operation(FlashOp::Erase { sector }) {
            self.inverted[range].fill(!ERASE_VALUE);
            self.last_busy = full_time;
            self.stats.erase_busy += full_time;
            return Ok(());
        }

        // How far the erase got, as a fraction of 2^32.
        let progress = u64::from(self.rng.next_u32());
        for index in range.step_by(WRITE_SIZE) {
            let draw = self.rng.next_u64();
            if draw % 8 == 0 {
                let garbage = self.rng.next_u32();
                self.set_word(index, garbage);
            } else if (draw >> 32) < progress {
                self.set_word(index, ERASED_WORD);
            }
        }
        let nanos = (full_time.as_nanos() as u64).saturating_mul(progress) >> 32;
        let busy = Duration::from_nanos(nanos);
        self.last_busy = busy;
        self.stats.erase_busy += busy;
        Err(FlashError::PowerLost)
    }

    fn erase_inner(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        self.check_powered()?;
        let bad = FlashError::BadEraseRange { from, to };
        if from > to {
            return Err(bad);
        }
        let on_boundary =
            |address: u32| SECTORS.iter().any(|s| s.start == address) || address == FLASH.end();
        if !on_boundary(from) || !on_boundary(to) {
            return Err(bad);
        }
        for index in SECTORS
            .iter()
            .filter(|s| s.start >= from && s.end() <= to)
            .map(|s| s.index)
        {
            self.erase_sector_inner(index)?;
        }
        Ok(())
    }
}

/// A partition of a shared [`SimFlash`] with the erase size `ERASE_SIZE` of its sectors,
/// implementing embedded-storage's NOR flash traits with offsets relative to the partition
/// (as embedded-storage's partitions have them).
///
/// Several handles share one flash through a `RefCell`; each access borrows it only for the
/// call, so the bootloader's three partitions and the updater's two can coexist.
#[derive(Clone, Copy, Debug)]
pub struct SimPartition<'a, const ERASE_SIZE: u32> {
    flash: &'a RefCell<SimFlash>,
    region: Region,
}

/// A partition of 128 KiB sectors: an image slot.
pub type SlotPartition<'a> = SimPartition<'a, SLOT_ERASE_SIZE>;

/// A partition of 16 KiB sectors: the boot state and the ECU data.
pub type SmallPartition<'a> = SimPartition<'a, SMALL_ERASE_SIZE>;

impl<'a, const ERASE_SIZE: u32> SimPartition<'a, ERASE_SIZE> {
    /// A partition over `region`, which must be made of sectors of `ERASE_SIZE` bytes.
    pub fn new(flash: &'a RefCell<SimFlash>, region: Region) -> Result<Self, FlashError> {
        if region.uniform_erase_size() == Some(ERASE_SIZE) {
            Ok(SimPartition { flash, region })
        } else {
            Err(FlashError::EraseSizeMismatch {
                region,
                erase_size: ERASE_SIZE,
            })
        }
    }

    /// The region of the flash this partition covers.
    pub fn region(&self) -> Region {
        self.region
    }

    /// The shared flash.
    pub fn flash(&self) -> &'a RefCell<SimFlash> {
        self.flash
    }

    /// Absolute address of `len` bytes at `offset`, if they fit the partition.
    fn address_of(&self, offset: u32, len: usize) -> Result<u32, FlashError> {
        let fits = u64::from(offset) + len as u64 <= u64::from(self.region.size);
        if fits {
            Ok(self.region.start + offset)
        } else {
            Err(FlashError::OutOfBounds {
                region: self.region,
                offset,
                len: u32::try_from(len).unwrap_or(u32::MAX),
            })
        }
    }
}

// The map's compile-time checks make these regions match their partition types.
impl<'a> SlotPartition<'a> {
    /// Image slot `slot` ([`crate::SLOT_A`], [`crate::SLOT_B`]).
    pub fn slot(flash: &'a RefCell<SimFlash>, slot: crate::ab::ImageSlot) -> Self {
        SimPartition {
            flash,
            region: slot.region(),
        }
    }
}

impl<'a> SmallPartition<'a> {
    /// The two copies of the persistent state ([`STATE_COPIES`]).
    pub fn state_copies(flash: &'a RefCell<SimFlash>) -> [Self; 2] {
        STATE_COPIES.map(|region| SimPartition { flash, region })
    }
}

/// The ECU's persistent state over the simulated flash, as the bootloader and the
/// application open it at each use.
pub fn state_twin(
    flash: &RefCell<SimFlash>,
) -> Result<Twin<SmallPartition<'_>>, TwinError<FlashError>> {
    Twin::open(SmallPartition::state_copies(flash))
}

impl<const ERASE_SIZE: u32> ErrorType for SimPartition<'_, ERASE_SIZE> {
    type Error = FlashError;
}

impl<const ERASE_SIZE: u32> ReadNorFlash for SimPartition<'_, ERASE_SIZE> {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        let address = self.address_of(offset, bytes.len())?;
        self.flash.borrow().read(address, bytes)
    }

    fn capacity(&self) -> usize {
        self.region.size as usize
    }
}

impl<const ERASE_SIZE: u32> NorFlash for SimPartition<'_, ERASE_SIZE> {
    const WRITE_SIZE: usize = WRITE_SIZE;
    const ERASE_SIZE: usize = ERASE_SIZE as usize;

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        let address = self.address_of(offset, bytes.len())?;
        self.flash.borrow_mut().program(address, bytes)
    }

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        if from > to || to > self.region.size {
            return Err(FlashError::OutOfBounds {
                region: self.region,
                offset: from,
                len: to.saturating_sub(from),
            });
        }
        let aligned = from % ERASE_SIZE == 0 && to % ERASE_SIZE == 0;
        let (from, to) = (self.region.start + from, self.region.start + to);
        if !aligned {
            return Err(FlashError::BadEraseRange { from, to });
        }
        self.flash.borrow_mut().erase(from, to)
    }
}

// Every sector size of the map has a datasheet erase time, so `sector_erase_time` never
// falls back to zero above.
const _: () = {
    let mut i = 0;
    while i < SECTORS.len() {
        assert!(sector_erase_time(SECTORS[i].size).is_some());
        i += 1;
    }
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ab::ImageSlot;
    use crate::map::{
        BOOTLOADER, LARGE_SECTOR_SIZE, MEDIUM_SECTOR_SIZE, SLOT_A, SLOT_B, SMALL_SECTOR_SIZE, SPARE,
    };

    /// Sectors 6–7: a two-sector partition of the large sectors.
    const UPPER: Region = Region {
        start: SLOT_B.start,
        size: 2 * LARGE_SECTOR_SIZE,
    };
    use crate::timing::{
        LARGE_SECTOR_ERASE_TIME, MEDIUM_SECTOR_ERASE_TIME, SMALL_SECTOR_ERASE_TIME,
    };

    fn word(flash: &SimFlash, address: u32) -> u32 {
        let mut buf = [0; 4];
        flash.read(address, &mut buf).expect("read in range");
        u32::from_le_bytes(buf)
    }

    fn words(values: &[u32]) -> Vec<u8> {
        values.iter().flat_map(|w| w.to_le_bytes()).collect()
    }

    fn sector_contents(flash: &SimFlash, index: usize) -> Vec<u8> {
        let sector = SECTORS[index];
        flash
            .contents(Region {
                start: sector.start,
                size: sector.size,
            })
            .expect("sector")
            .to_vec()
    }

    #[test]
    fn a_new_flash_is_erased_and_powered() {
        let flash = SimFlash::new(1);
        assert!(flash
            .contents(FLASH)
            .expect("whole flash")
            .iter()
            .all(|&b| b == 0xFF));
        assert!(flash.is_powered());
        assert_eq!(flash.operations(), 0);
        assert_eq!(flash.total_busy(), Duration::ZERO);
        assert_eq!(flash.pending_cut(), None);
    }

    #[test]
    fn programming_only_clears_bits() {
        let mut flash = SimFlash::new(1);
        let at = STATE_COPIES[1].start;
        flash
            .program(at, &words(&[0x1234_5678, 0x0000_00FF]))
            .expect("erased words");
        assert_eq!(word(&flash, at), 0x1234_5678);
        // Clearing further bits of a programmed word is allowed, as on the F4.
        flash
            .program(at, &words(&[0x1030_5070]))
            .expect("only clears bits");
        assert_eq!(word(&flash, at), 0x1030_5070);
        assert_eq!(flash.stats().reprogrammed_words, 1);
        // A 0 -> 1 change anywhere refuses the whole call, which changes nothing.
        let error = flash
            .program(at, &words(&[0, 0x0000_0F00]))
            .expect_err("needs an erase");
        assert_eq!(
            error,
            FlashError::NeedsErase {
                address: at + 4,
                current: 0xFF,
                requested: 0xF00
            }
        );
        assert_eq!(word(&flash, at), 0x1030_5070);
        assert_eq!(error.kind(), NorFlashErrorKind::Other);
        assert_eq!(flash.last_error(), Some(&error));
        assert_eq!(flash.operations(), 2, "a refused call starts no operation");
        let message = error.to_string();
        assert!(
            message.contains("0x0800_C004") && message.contains("state copy B"),
            "{message}"
        );
    }

    #[test]
    fn erase_restores_a_whole_sector() {
        let mut flash = SimFlash::new(1);
        flash
            .program(STATE_COPIES[0].start + 0x100, &words(&[0, 0]))
            .expect("program");
        flash
            .program(STATE_COPIES[1].start, &words(&[0]))
            .expect("program");
        flash.erase_sector(2).expect("erase");
        assert!(sector_contents(&flash, 2).iter().all(|&b| b == ERASE_VALUE));
        assert_eq!(
            word(&flash, STATE_COPIES[1].start),
            0,
            "the next sector is untouched"
        );
        assert_eq!(flash.stats().sector_erases, 1);
    }

    #[test]
    fn argument_errors_name_what_was_wrong() {
        let mut flash = SimFlash::new(1);
        let end = FLASH.end();
        assert_eq!(
            flash.program(end - 4, &[0; 8]),
            Err(FlashError::OutsideFlash {
                address: end - 4,
                len: 8
            })
        );
        assert_eq!(
            flash.program(0x0800_0002, &[0; 4]),
            Err(FlashError::NotAligned {
                address: 0x0800_0002,
                len: 4
            })
        );
        assert_eq!(
            flash.program(0x0800_0000, &[0; 3]),
            Err(FlashError::NotAligned {
                address: 0x0800_0000,
                len: 3
            })
        );
        let mut buf = [0; 4];
        assert!(matches!(
            flash.read(0x07FF_FFFE, &mut buf),
            Err(FlashError::OutsideFlash { .. })
        ));
        assert_eq!(
            flash.erase_sector(8),
            Err(FlashError::NoSuchSector { index: 8 })
        );
        let bad = FlashError::BadEraseRange {
            from: 0x0800_4000,
            to: 0x0800_6000,
        };
        assert_eq!(flash.erase(0x0800_4000, 0x0800_6000), Err(bad.clone()));
        assert_eq!(bad.kind(), NorFlashErrorKind::NotAligned);
        let reversed = FlashError::BadEraseRange {
            from: 0x0800_8000,
            to: 0x0800_4000,
        };
        assert_eq!(flash.erase(0x0800_8000, 0x0800_4000), Err(reversed.clone()));
        assert_eq!(reversed.kind(), NorFlashErrorKind::OutOfBounds);
        assert!(reversed.to_string().contains("ends before it starts"));
        assert_eq!(
            flash.operations(),
            0,
            "no refused call started an operation"
        );
        // Empty ranges and zero-length writes do nothing.
        flash
            .erase(SLOT_A.start, SLOT_A.start)
            .expect("empty erase");
        flash.program(SLOT_A.start, &[]).expect("empty program");
        assert_eq!(flash.operations(), 0);
    }

    #[test]
    fn busy_time_follows_the_datasheet() {
        let mut flash = SimFlash::new(1);
        flash.program(SLOT_A.start, &[0; 4096]).expect("program");
        assert_eq!(flash.last_busy(), Duration::from_micros(16 * 1024));
        flash
            .erase(BOOTLOADER.start, BOOTLOADER.end())
            .expect("erase");
        assert_eq!(flash.last_busy(), SMALL_SECTOR_ERASE_TIME);
        flash.erase(SPARE.start, SPARE.end()).expect("erase");
        assert_eq!(flash.last_busy(), MEDIUM_SECTOR_ERASE_TIME);
        flash.erase_sector(7).expect("erase");
        assert_eq!(flash.last_busy(), LARGE_SECTOR_ERASE_TIME);
        let stats = flash.stats();
        assert_eq!(
            stats.erase_busy,
            Duration::from_millis(2 * 250 + 550 + 1000)
        );
        assert_eq!(stats.program_busy, Duration::from_micros(16 * 1024));
        assert_eq!(flash.total_busy(), stats.erase_busy + stats.program_busy);
        assert_eq!(
            (stats.operations, stats.sector_erases, stats.program_calls),
            (5, 4, 1)
        );
        assert_eq!(stats.words_programmed, 1024);
    }

    #[test]
    fn a_cut_erase_leaves_a_mixture_and_the_flash_unpowered() {
        let mut flash = SimFlash::new(7);
        let old: Vec<u8> = (0..LARGE_SECTOR_SIZE)
            .map(|i| (i % 251) as u8 & 0x7F)
            .collect();
        flash.program(SLOT_A.start, &old).expect("program");
        flash.cut_power_at(0);
        assert_eq!(flash.pending_cut(), Some(0));
        assert_eq!(
            flash.erase(SLOT_A.start, SLOT_A.end()),
            Err(FlashError::PowerLost)
        );
        assert!(!flash.is_powered());
        assert!(flash.last_busy() < LARGE_SECTOR_ERASE_TIME);
        let left = sector_contents(&flash, 5);
        let chunks = || left.chunks(4).zip(old.chunks(4));
        let kept = chunks().filter(|(l, o)| l == o).count();
        let erased = chunks()
            .filter(|(l, _)| l.iter().all(|&b| b == 0xFF))
            .count();
        let garbage = chunks().count() - kept - erased;
        assert!(
            kept > 0 && erased > 0 && garbage > 0,
            "kept {kept}, erased {erased}, garbage {garbage}"
        );

        // Unpowered: erases and programs fail and change nothing; reads work.
        assert_eq!(flash.erase_sector(5), Err(FlashError::PowerLost));
        assert_eq!(
            flash.program(UPPER.start, &[0; 4]),
            Err(FlashError::PowerLost)
        );
        assert_eq!(sector_contents(&flash, 5), left);
        assert_eq!(word(&flash, UPPER.start), 0xFFFF_FFFF);
        assert_eq!(flash.stats().interrupted, 1);
        assert_eq!(flash.operations(), 2, "refused operations are not counted");

        flash.restore_power();
        flash.erase_sector(5).expect("powered again");
        assert!(sector_contents(&flash, 5).iter().all(|&b| b == 0xFF));
    }

    #[test]
    fn a_cut_write_leaves_a_prefix() {
        for seed in 0..20 {
            let mut flash = SimFlash::new(seed);
            let data: Vec<u8> = (0..1024u32)
                .flat_map(|i| (i.wrapping_mul(0x0101_0101) & 0x7F7F_7F7F).to_le_bytes())
                .collect();
            flash.cut_power_at(0);
            assert_eq!(
                flash.program(UPPER.start, &data),
                Err(FlashError::PowerLost)
            );
            let left = flash
                .contents(Region {
                    start: UPPER.start,
                    size: 4096,
                })
                .expect("range")
                .to_vec();
            let programmed = left
                .chunks(4)
                .zip(data.chunks(4))
                .take_while(|(l, d)| l == d)
                .count();
            assert!(
                programmed < 1024,
                "seed {seed}: an interrupted write cannot complete"
            );
            // The word being programmed holds some of the cleared bits, never a 0 -> 1.
            let half = u32::from_le_bytes(
                left[programmed * 4..programmed * 4 + 4]
                    .try_into()
                    .expect("word"),
            );
            let wanted = u32::from_le_bytes(
                data[programmed * 4..programmed * 4 + 4]
                    .try_into()
                    .expect("word"),
            );
            assert_eq!(half & wanted, wanted, "seed {seed}");
            // Everything after it is untouched.
            assert!(
                left[programmed * 4 + 4..].iter().all(|&b| b == 0xFF),
                "seed {seed}"
            );
            assert_eq!(
                flash.last_busy(),
                WORD_PROGRAM_TIME * programmed as u32 + WORD_PROGRAM_TIME / 2
            );
        }
    }

    #[test]
    fn the_cut_is_counted_from_when_it_is_armed() {
        let mut flash = SimFlash::new(3);
        flash.program(SLOT_A.start, &[0; 4]).expect("op 0");
        flash.cut_power_at(2);
        flash
            .program(SLOT_A.start + 4, &[0; 4])
            .expect("first after arming");
        assert_eq!(flash.pending_cut(), Some(1));
        // An erase over two sectors is two operations: the cut hits the second sector.
        assert_eq!(
            flash.erase(UPPER.start, UPPER.end()),
            Err(FlashError::PowerLost)
        );
        assert!(
            sector_contents(&flash, 6).iter().all(|&b| b == 0xFF),
            "the first sector was erased"
        );
        assert_eq!(flash.operations(), 4);
        assert_eq!(flash.pending_cut(), None);

        flash.restore_power();
        flash.cut_power_at(0);
        flash.cancel_cut();
        flash.erase_sector(7).expect("the cut was cancelled");
    }

    #[test]
    fn runs_are_reproducible_from_the_seed() {
        let run = |seed| {
            let mut flash = SimFlash::new(seed);
            flash.program(SLOT_A.start, &[0x55; 8192]).expect("program");
            flash.cut_power_at(0);
            let _ = flash.erase_sector(5);
            flash.restore_power();
            flash.cut_power_at(0);
            let _ = flash.program(UPPER.start, &[0; 4096]);
            flash.contents(FLASH).expect("whole flash").to_vec()
        };
        assert_eq!(run(11), run(11));
        assert_ne!(run(11), run(12));
    }

    #[test]
    fn the_trace_names_each_operation() {
        let mut flash = SimFlash::new(1);
        flash.record_trace(true);
        flash.erase(UPPER.start, UPPER.end()).expect("erase");
        flash
            .program(STATE_COPIES[0].start + 4, &[0; 4])
            .expect("program");
        let trace: Vec<String> = flash.trace().iter().map(|op| op.to_string()).collect();
        assert_eq!(
            trace,
            [
                "erase of sector 6 (slot B, 128 KiB at 0x0804_0000)",
                "erase of sector 7 (spare (sector 7), 128 KiB at 0x0806_0000)",
                "program of 4 bytes at 0x0800_8004 (state copy A + 0x4)",
            ]
        );
        flash.record_trace(false);
        assert!(flash.trace().is_empty());
    }

    #[test]
    fn partitions_use_offsets_and_their_own_erase_size() {
        let flash = RefCell::new(SimFlash::new(1));
        assert_eq!(<SlotPartition as NorFlash>::ERASE_SIZE, 128 * 1024);
        assert_eq!(<SmallPartition as NorFlash>::ERASE_SIZE, 16 * 1024);
        assert_eq!(<SlotPartition as NorFlash>::WRITE_SIZE, 4);

        let mut dfu = SlotPartition::new(&flash, UPPER).expect("sectors 6-7");
        assert_eq!(dfu.capacity(), 256 * 1024);
        dfu.write(0x2_0000, &[0xA5; 8])
            .expect("write in the second sector");
        assert_eq!(word(&flash.borrow(), 0x0806_0000), 0xA5A5_A5A5);
        let mut buf = [0; 8];
        dfu.read(0x2_0000, &mut buf).expect("read");
        assert_eq!(buf, [0xA5; 8]);
        dfu.erase(0x2_0000, 0x4_0000)
            .expect("erase the second sector");
        assert_eq!(word(&flash.borrow(), 0x0806_0000), 0xFFFF_FFFF);

        let out = dfu.write(0x3_FFFC, &[0; 8]).expect_err("past the end");
        assert_eq!(
            out,
            FlashError::OutOfBounds {
                region: UPPER,
                offset: 0x3_FFFC,
                len: 8
            }
        );
        assert_eq!(out.kind(), NorFlashErrorKind::OutOfBounds);
        assert!(out.to_string().contains("slot B"), "{out}");
        assert_eq!(
            dfu.read(0x4_0000, &mut buf).map_err(|e| e.kind()),
            Err(NorFlashErrorKind::OutOfBounds)
        );
        assert_eq!(
            dfu.erase(0, 0x1000).map_err(|e| e.kind()),
            Err(NorFlashErrorKind::NotAligned)
        );
        assert_eq!(
            dfu.erase(0x2_0000, 0).map_err(|e| e.kind()),
            Err(NorFlashErrorKind::OutOfBounds)
        );
        assert_eq!(
            dfu.write(2, &[0; 4]).map_err(|e| e.kind()),
            Err(NorFlashErrorKind::NotAligned)
        );

        let [mut a, b] = SmallPartition::state_copies(&flash);
        a.erase(0, 0x4000).expect("one 16 KiB sector");
        assert_eq!([a.region(), b.region()], STATE_COPIES);
        assert_eq!(SlotPartition::slot(&flash, ImageSlot::A).region(), SLOT_A);
        assert_eq!(SlotPartition::slot(&flash, ImageSlot::B).region(), SLOT_B);
    }

    #[test]
    fn a_partition_must_match_its_sectors() {
        let flash = RefCell::new(SimFlash::new(1));
        assert!(SlotPartition::new(&flash, SLOT_A).is_ok());
        assert!(SmallPartition::new(&flash, STATE_COPIES[0]).is_ok());
        let error = SlotPartition::new(&flash, SPARE).expect_err("64 KiB sector");
        assert_eq!(
            error,
            FlashError::EraseSizeMismatch {
                region: SPARE,
                erase_size: LARGE_SECTOR_SIZE
            }
        );
        assert!(SimPartition::<MEDIUM_SECTOR_SIZE>::new(&flash, SPARE).is_ok());
        assert!(SmallPartition::new(&flash, BOOTLOADER).is_ok());
        assert!(SmallPartition::new(
            &flash,
            Region {
                start: BOOTLOADER.start,
                size: SMALL_SECTOR_SIZE / 2
            }
        )
        .is_err());
    }
}
