//! The ECU's persistent state in two sectors, so that no power cut can lose it.
//!
//! What an ECU keeps across resets — the boot record ([`crate::ab`]: which image slot is
//! confirmed, which on trial), the anti-rollback floor, failed SecurityAccess attempts, the
//! seed epoch — lives as records in one of two copies, each a whole erase sector ([`crate::STATE_COPIES`]).
//! A copy is valid once its header is programmed; of two valid copies the one with the
//! higher sequence number is current.
//!
//! | offset | bytes | what |
//! |---|---|---|
//! | 0 | 12 | header: magic, sequence number, check word (written last) |
//! | [`RECORDS_START`] | the rest | records of [`RECORD_LEN`] bytes, appended |
//!
//! When the record area runs full, the store prepares the *other* copy instead of erasing
//! the current one: erase it, program the latest record of each kind, and only then its
//! header with the next sequence number. A cut anywhere before the header's last word
//! leaves the current copy untouched and current; once the header is complete, the new copy
//! is. This is ST's two-page EEPROM emulation (AN3969); no crate offers it over
//! embedded-storage with the power-cut behaviour tested here, so it is written here.
//!
//! Record writes are single programs into erased words: a cut leaves a record that fails
//! its check and is skipped, and the previous record of its kind stands.

use embedded_storage::nor_flash::{NorFlash, NorFlashError, NorFlashErrorKind};

/// Bytes of a copy's header (three words written, one spare).
pub const HEADER_LEN: u32 = 16;
/// Offset of the first record in a copy.
pub const RECORDS_START: u32 = HEADER_LEN;
/// Bytes of one record: kind (2), payload (4), check, a zero byte.
pub const RECORD_LEN: u32 = 8;
/// Record kinds a switch carries over at most.
pub const MAX_KINDS: usize = 8;

/// "APs2": a copy of AutoPlug state, format 2 (format 1 had embassy-boot's state partition
/// between header and records; its copies do not read as format 2).
const MAGIC: u32 = u32::from_le_bytes(*b"APs2");
/// Mixed into the check word, so that neither an erased nor a zeroed header passes.
const CHECK_KEY: u32 = 0x5AC3_A53C;
/// The value of an erased byte (the F446's NOR cells erase to ones).
const ERASED: u8 = 0xFF;
/// Bytes of the header actually programmed.
const HEADER_WRITTEN: usize = 12;

/// The kind of a record: two bytes, never both 0xFF (that reads as erased).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RecordKind(pub [u8; 2]);

/// The anti-rollback version floor: major, minor, patch (little-endian); the same two
/// bytes as the floor records of the single ECU data sector before.
pub const FLOOR_RECORD: RecordKind = RecordKind([0xA5, 0x5A]);
/// Wrong SecurityAccess keys in a row (first payload byte), counted before each check.
pub const KEY_FAILURES_RECORD: RecordKind = RecordKind([0xA5, 0x3C]);
/// The seed epoch: a u32 (little-endian) raised at every start of the application.
pub const SEED_EPOCH_RECORD: RecordKind = RecordKind([0xA5, 0x3D]);

/// What a record slot holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    /// Never written.
    Erased,
    /// A complete record.
    Record(RecordKind, [u8; 4]),
    /// Written but not a valid record (cut by a power loss): skipped.
    Invalid,
}

/// The bytes of a record of `kind` holding `payload`.
pub fn encode_record(kind: RecordKind, payload: [u8; 4]) -> [u8; RECORD_LEN as usize] {
    let mut record = [0u8; RECORD_LEN as usize];
    record[..2].copy_from_slice(&kind.0);
    record[2..6].copy_from_slice(&payload);
    record[6] = record_check(&record);
    record
}

/// What the bytes of a record slot hold.
pub fn decode_record(record: &[u8; RECORD_LEN as usize]) -> Slot {
    if record.iter().all(|&b| b == ERASED) {
        Slot::Erased
    } else if record[6] == record_check(record) && record[7] == 0 && record[..2] != [ERASED; 2] {
        let mut payload = [0u8; 4];
        payload.copy_from_slice(&record[2..6]);
        Slot::Record(RecordKind([record[0], record[1]]), payload)
    } else {
        Slot::Invalid
    }
}

fn record_check(record: &[u8; RECORD_LEN as usize]) -> u8 {
    record[..6].iter().fold(0u8, |a, b| a.wrapping_add(*b)) ^ 0xFF
}

fn header_bytes(sequence: u32) -> [u8; HEADER_WRITTEN] {
    let mut header = [0u8; HEADER_WRITTEN];
    header[..4].copy_from_slice(&MAGIC.to_le_bytes());
    header[4..8].copy_from_slice(&sequence.to_le_bytes());
    header[8..].copy_from_slice(&(sequence ^ CHECK_KEY).rotate_left(7).to_le_bytes());
    header
}

/// Why the store failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TwinError<E> {
    /// The flash failed (on the ECU: a flash error; in the simulation also a power cut).
    Flash(E),
    /// The copies do not fit the layout: different sizes, too small, not one erase unit
    /// each, or a write unit larger than a word.
    Geometry,
    /// A record kind of 0xFFFF, which reads as erased.
    OutOfBounds,
    /// More record kinds than a switch carries ([`MAX_KINDS`]).
    TooManyKinds,
}

impl<E: NorFlashError> NorFlashError for TwinError<E> {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            Self::Flash(e) => e.kind(),
            Self::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            Self::Geometry | Self::TooManyKinds => NorFlashErrorKind::Other,
        }
    }
}

impl<E: core::fmt::Debug> core::fmt::Display for TwinError<E> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Flash(e) => write!(f, "flash error {e:?}"),
            Self::Geometry => f.write_str("the state copies do not fit the layout"),
            Self::OutOfBounds => f.write_str("a record kind that reads as erased"),
            Self::TooManyKinds => f.write_str("more record kinds than a copy carries"),
        }
    }
}

/// The current copy.
#[derive(Clone, Copy, Debug)]
struct Current {
    index: usize,
    sequence: u32,
    /// The first record slot after the last written one, once looked up.
    free_slot: Option<u32>,
}

/// The two copies of the ECU's persistent state.
#[derive(Debug)]
pub struct Twin<F> {
    copies: [F; 2],
    current: Option<Current>,
}

impl<F: NorFlash> Twin<F> {
    /// Opens the store over its two copies (each one whole erase unit): reads both headers.
    /// Neither valid (a new board, erased flash) reads as an erased boot state and no
    /// records; the first write creates the first copy.
    pub fn open(mut copies: [F; 2]) -> Result<Self, TwinError<F::Error>> {
        let size = copies[0].capacity();
        let fits = size == copies[1].capacity()
            && size == F::ERASE_SIZE
            && F::WRITE_SIZE <= 4
            && 4 % F::WRITE_SIZE == 0
            && size >= (RECORDS_START + RECORD_LEN * MAX_KINDS as u32) as usize;
        if !fits {
            return Err(TwinError::Geometry);
        }
        let mut current: Option<Current> = None;
        for (index, copy) in copies.iter_mut().enumerate() {
            let mut header = [0u8; HEADER_WRITTEN];
            copy.read(0, &mut header).map_err(TwinError::Flash)?;
            let sequence = u32::from_le_bytes([header[4], header[5], header[6], header[7]]);
            let valid = header == header_bytes(sequence);
            if valid && current.is_none_or(|c| sequence > c.sequence) {
                current = Some(Current {
                    index,
                    sequence,
                    free_slot: None,
                });
            }
        }
        Ok(Self { copies, current })
    }

    /// The sequence number of the current copy (`None` before the first write).
    pub fn sequence(&self) -> Option<u32> {
        self.current.map(|c| c.sequence)
    }

    /// Which copy is current (0 or 1), if any.
    pub fn current_copy(&self) -> Option<usize> {
        self.current.map(|c| c.index)
    }

    /// The copies, back.
    pub fn into_copies(self) -> [F; 2] {
        self.copies
    }

    fn slots(&self) -> u32 {
        (self.copies[0].capacity() as u32 - RECORDS_START) / RECORD_LEN
    }

    fn read_slot(&mut self, index: usize, slot: u32) -> Result<Slot, TwinError<F::Error>> {
        let mut bytes = [0u8; RECORD_LEN as usize];
        self.copies[index]
            .read(RECORDS_START + slot * RECORD_LEN, &mut bytes)
            .map_err(TwinError::Flash)?;
        Ok(decode_record(&bytes))
    }

    /// The first slot after the last written one in the current copy.
    fn free_slot(&mut self) -> Result<Option<u32>, TwinError<F::Error>> {
        let Some(current) = self.current else {
            return Ok(None);
        };
        if let Some(free) = current.free_slot {
            return Ok(Some(free));
        }
        let mut free = 0;
        for slot in 0..self.slots() {
            if self.read_slot(current.index, slot)? != Slot::Erased {
                free = slot + 1;
            }
        }
        self.current = Some(Current {
            free_slot: Some(free),
            ..current
        });
        Ok(Some(free))
    }

    /// The latest complete record of `kind`, if any.
    pub fn read_record(
        &mut self,
        kind: RecordKind,
    ) -> Result<Option<[u8; 4]>, TwinError<F::Error>> {
        let (Some(current), Some(end)) = (self.current, self.free_slot()?) else {
            return Ok(None);
        };
        let mut latest = None;
        for slot in 0..end {
            if let Slot::Record(k, payload) = self.read_slot(current.index, slot)? {
                if k == kind {
                    latest = Some(payload);
                }
            }
        }
        Ok(latest)
    }

    /// Appends a record of `kind`; when the copy is full, moves to the other copy with the
    /// latest record of every kind.
    pub fn write_record(
        &mut self,
        kind: RecordKind,
        payload: [u8; 4],
    ) -> Result<(), TwinError<F::Error>> {
        if kind.0 == [ERASED; 2] {
            return Err(TwinError::OutOfBounds);
        }
        let record = encode_record(kind, payload);
        match (self.current, self.free_slot()?) {
            (Some(current), Some(free)) if free < self.slots() => {
                // The slot is taken even if the write is cut: it reads as written then.
                self.current = Some(Current {
                    free_slot: Some(free + 1),
                    ..current
                });
                self.copies[current.index]
                    .write(RECORDS_START + free * RECORD_LEN, &record)
                    .map_err(TwinError::Flash)
            }
            _ => self.switch(Some(record)),
        }
    }

    /// Wrong SecurityAccess keys in a row as kept ([`KEY_FAILURES_RECORD`]; 0 if never
    /// written).
    pub fn key_failures(&mut self) -> Result<u8, TwinError<F::Error>> {
        Ok(self.read_record(KEY_FAILURES_RECORD)?.map_or(0, |p| p[0]))
    }

    /// Keeps the count of wrong SecurityAccess keys in a row.
    pub fn store_key_failures(&mut self, failures: u8) -> Result<(), TwinError<F::Error>> {
        self.write_record(KEY_FAILURES_RECORD, [failures, 0, 0, 0])
    }

    /// Raises the seed epoch ([`SEED_EPOCH_RECORD`]) for a new start and returns it, with
    /// whether it was kept: if not, the start still gets the next number (its seeds may
    /// then share the epoch of a later start; the ECU's entropy still tells them apart).
    pub fn raise_seed_epoch(&mut self) -> (u32, Result<(), TwinError<F::Error>>) {
        let epoch = match self.read_record(SEED_EPOCH_RECORD) {
            Ok(payload) => payload.map_or(0, u32::from_le_bytes).wrapping_add(1),
            Err(e) => return (1, Err(e)),
        };
        (
            epoch,
            self.write_record(SEED_EPOCH_RECORD, epoch.to_le_bytes()),
        )
    }

    /// Makes the other copy current: the latest record of each kind, `extra` last.
    fn switch(
        &mut self,
        extra: Option<[u8; RECORD_LEN as usize]>,
    ) -> Result<(), TwinError<F::Error>> {
        let mut records = [[ERASED; RECORD_LEN as usize]; MAX_KINDS];
        let mut count = 0;
        if let (Some(current), Some(end)) = (self.current, self.free_slot()?) {
            for slot in 0..end {
                if let Slot::Record(kind, payload) = self.read_slot(current.index, slot)? {
                    keep_latest(&mut records, &mut count, encode_record(kind, payload))?;
                }
            }
        }
        if let Some(extra) = extra {
            keep_latest(&mut records, &mut count, extra)?;
        }
        let target = self.current.map_or(0, |c| 1 - c.index);
        let sequence = self.current.map_or(1, |c| c.sequence.wrapping_add(1));
        let size = self.copies[target].capacity() as u32;
        self.copies[target]
            .erase(0, size)
            .map_err(TwinError::Flash)?;
        for (slot, record) in records[..count].iter().enumerate() {
            self.copies[target]
                .write(RECORDS_START + slot as u32 * RECORD_LEN, record)
                .map_err(TwinError::Flash)?;
        }
        self.copies[target]
            .write(0, &header_bytes(sequence))
            .map_err(TwinError::Flash)?;
        self.current = Some(Current {
            index: target,
            sequence,
            free_slot: Some(count as u32),
        });
        Ok(())
    }
}

/// Puts `record` into `records`, replacing an earlier one of its kind.
fn keep_latest<E>(
    records: &mut [[u8; RECORD_LEN as usize]; MAX_KINDS],
    count: &mut usize,
    record: [u8; RECORD_LEN as usize],
) -> Result<(), TwinError<E>> {
    if let Some(same) = records[..*count].iter_mut().find(|r| r[..2] == record[..2]) {
        *same = record;
        return Ok(());
    }
    let slot = records.get_mut(*count).ok_or(TwinError::TooManyKinds)?;
    *slot = record;
    *count += 1;
    Ok(())
}
