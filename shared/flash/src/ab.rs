//! A/B slots executed in place: which slot the bootloader starts, and how an update and its
//! confirmation are recorded.
//!
//! Each slot ([`ImageSlot::A`], [`ImageSlot::B`]) holds a complete image linked for that slot's
//! address, and runs from where it lies. An update erases and writes the slot that is not
//! running; a reset then starts it once, on trial. Nothing is ever copied between slots, so a
//! 64 KiB update costs one 128 KiB sector erase (1 s on the F446) instead of embassy-boot's
//! swap of two erases and two page copies at every reset (3 s more). That is why this
//! module exists rather than embassy-boot: its swap cannot run images in place.
//!
//! # The boot record
//!
//! One record of the two-copy persistent state ([`crate::twin`], kind [`BOOT_RECORD`]) says
//! which slot is confirmed and whether the other is on trial:
//!
//! | byte | meaning |
//! |---:|---|
//! | 0 | confirmed slot: 0 = A, 1 = B |
//! | 1 | slot on trial: 0 = A, 1 = B, 0xFF none |
//! | 2 | trial phase: 0 = marked (not started yet), 1 = started |
//! | 3 | 1 if the last trial was reverted, else 0 |
//!
//! No record (a new board) reads as "A confirmed, nothing on trial". A record is one flash
//! program that a power cut leaves either complete or failing its check (then the previous
//! record stands), so every step below is atomic:
//!
//! 1. The application erases and writes the other slot, verifies the image, then
//!    [`mark_trial`]s it ("marked").
//! 2. The bootloader ([`choose`]) finds it marked, records "started", and starts it. Should
//!    that record fail to be kept, it starts the confirmed slot instead: an image that would
//!    crash must never be started without a record that it was.
//! 3. The new image passes its self-test and [`confirm`]s its slot; the old slot stays as
//!    it was until the next update erases it.
//! 4. A reset before that (a crash, the watchdog, a power cut) finds the trial "started":
//!    the bootloader records the revert and starts the confirmed slot again.
//!
//! Before the application erases a slot it calls [`prepare_download`]: a slot still marked
//! for trial from an earlier download is unmarked first, so a cut during the new download
//! can never leave a half-written slot marked.

use embedded_storage::nor_flash::NorFlash;

use crate::map::{Region, IMAGE_HEADER_SIZE, SLOT_A, SLOT_B, SRAM_SIZE, SRAM_START};
use crate::twin::{RecordKind, Twin, TwinError};

/// The record kind of the boot record.
pub const BOOT_RECORD: RecordKind = RecordKind([0xA5, 0x3E]);

/// One of the two image slots.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ImageSlot {
    /// Sector 5 ([`SLOT_A`]): what a new board starts.
    A,
    /// Sector 6 ([`SLOT_B`]).
    B,
}

impl ImageSlot {
    /// Both slots, A first.
    pub const ALL: [ImageSlot; 2] = [ImageSlot::A, ImageSlot::B];

    /// The flash the slot takes.
    pub const fn region(self) -> Region {
        match self {
            ImageSlot::A => SLOT_A,
            ImageSlot::B => SLOT_B,
        }
    }

    /// Where an image for this slot has its vector table: slot start + the image header.
    /// An application is linked here, and the image header's load address says it.
    pub const fn vector_table(self) -> u32 {
        self.region().start + IMAGE_HEADER_SIZE
    }

    /// The other slot.
    pub const fn other(self) -> ImageSlot {
        match self {
            ImageSlot::A => ImageSlot::B,
            ImageSlot::B => ImageSlot::A,
        }
    }

    /// The slot whose vector table is at `address`, if any (what an image header's load
    /// address or the running core's `VTOR` names).
    pub const fn at_vector_table(address: u32) -> Option<ImageSlot> {
        if address == ImageSlot::A.vector_table() {
            Some(ImageSlot::A)
        } else if address == ImageSlot::B.vector_table() {
            Some(ImageSlot::B)
        } else {
            None
        }
    }

    /// The slot's letter, for messages.
    pub const fn letter(self) -> char {
        match self {
            ImageSlot::A => 'A',
            ImageSlot::B => 'B',
        }
    }

    /// The slot's number in the boot record and on the wire (A 0, B 1).
    pub const fn number(self) -> u8 {
        match self {
            ImageSlot::A => 0,
            ImageSlot::B => 1,
        }
    }

    /// The slot of a number ([`ImageSlot::number`]).
    pub const fn from_number(number: u8) -> Option<ImageSlot> {
        match number {
            0 => Some(ImageSlot::A),
            1 => Some(ImageSlot::B),
            _ => None,
        }
    }
}

/// Where the slot on trial stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TrialPhase {
    /// Marked by the application; the next reset starts it.
    Marked,
    /// Started by the bootloader and not confirmed since: the next reset reverts.
    Started,
}

/// What the boot record says.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BootRecord {
    /// The slot known good.
    pub confirmed: ImageSlot,
    /// The other slot, on trial, if an update is under way.
    pub trial: Option<(ImageSlot, TrialPhase)>,
    /// The last trial was reverted (cleared by the next [`mark_trial`]).
    pub reverted: bool,
}

impl BootRecord {
    /// A new board: slot A confirmed, nothing on trial.
    pub const FACTORY: BootRecord = BootRecord {
        confirmed: ImageSlot::A,
        trial: None,
        reverted: false,
    };

    /// The record's payload.
    pub const fn to_payload(self) -> [u8; 4] {
        let (trial, phase) = match self.trial {
            Some((slot, TrialPhase::Marked)) => (slot.number(), 0),
            Some((slot, TrialPhase::Started)) => (slot.number(), 1),
            None => (0xFF, 0),
        };
        [self.confirmed.number(), trial, phase, self.reverted as u8]
    }

    /// The record a payload holds; `None` for one no version of this code writes (then
    /// the bootloader keeps to what it can start, see [`choose`]).
    pub const fn from_payload(payload: [u8; 4]) -> Option<BootRecord> {
        let Some(confirmed) = ImageSlot::from_number(payload[0]) else {
            return None;
        };
        let trial = match (payload[1], payload[2]) {
            (0xFF, 0) => None,
            (slot, phase) => {
                let Some(slot) = ImageSlot::from_number(slot) else {
                    return None;
                };
                if slot.number() == confirmed.number() {
                    return None;
                }
                match phase {
                    0 => Some((slot, TrialPhase::Marked)),
                    1 => Some((slot, TrialPhase::Started)),
                    _ => return None,
                }
            }
        };
        let reverted = match payload[3] {
            0 => false,
            1 => true,
            _ => return None,
        };
        Some(BootRecord {
            confirmed,
            trial,
            reverted,
        })
    }
}

/// How the running image stands, as the application sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BootState {
    /// The running slot is the confirmed one.
    Confirmed,
    /// The running slot was started on trial: it must confirm itself, or the next reset
    /// reverts to the other slot. No download is taken meanwhile.
    Trial,
    /// The confirmed slot runs after a trial of the other one was reverted.
    Reverted,
}

impl BootState {
    /// The state's number on the wire (UDS DID F1A0): 0 confirmed, 1 trial, 2 reverted.
    pub const fn number(self) -> u8 {
        match self {
            BootState::Confirmed => 0,
            BootState::Trial => 1,
            BootState::Reverted => 2,
        }
    }

    /// How tools name the state: `confirmed`, `on trial`, `reverted`.
    pub const fn name(self) -> &'static str {
        match self {
            BootState::Confirmed => "confirmed",
            BootState::Trial => "on trial",
            BootState::Reverted => "reverted",
        }
    }

    /// The state of a number ([`BootState::number`]).
    pub const fn from_number(number: u8) -> Option<BootState> {
        match number {
            0 => Some(BootState::Confirmed),
            1 => Some(BootState::Trial),
            2 => Some(BootState::Reverted),
            _ => None,
        }
    }
}

/// Why a boot record operation failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AbError<E> {
    /// The persistent state failed.
    Store(TwinError<E>),
    /// The running image is on trial: it confirms itself before it takes another download.
    Unconfirmed,
    /// The slot asked for is the running (or confirmed) one.
    SlotInUse(ImageSlot),
}

impl<E> From<TwinError<E>> for AbError<E> {
    fn from(error: TwinError<E>) -> Self {
        AbError::Store(error)
    }
}

/// The boot record as stored ([`BootRecord::FACTORY`] if none was written; `None` if the
/// stored one is not one this code writes).
pub fn read<F: NorFlash>(twin: &mut Twin<F>) -> Result<Option<BootRecord>, TwinError<F::Error>> {
    Ok(match twin.read_record(BOOT_RECORD)? {
        Some(payload) => BootRecord::from_payload(payload),
        None => Some(BootRecord::FACTORY),
    })
}

fn write<F: NorFlash>(twin: &mut Twin<F>, record: BootRecord) -> Result<(), TwinError<F::Error>> {
    twin.write_record(BOOT_RECORD, record.to_payload())
}

/// How the image in `running` stands (what the application asks at its start).
pub fn state<F: NorFlash>(
    twin: &mut Twin<F>,
    running: ImageSlot,
) -> Result<BootState, TwinError<F::Error>> {
    let record = read(twin)?.unwrap_or(BootRecord::FACTORY);
    Ok(match record.trial {
        Some((slot, TrialPhase::Started)) if slot == running => BootState::Trial,
        _ if record.reverted && record.confirmed == running => BootState::Reverted,
        _ => BootState::Confirmed,
    })
}

/// Before the application erases `target` for a download while `running` runs: refuses if
/// the running image is on trial or `target` is the running slot, and unmarks a trial of
/// `target` left from an earlier download.
pub fn prepare_download<F: NorFlash>(
    twin: &mut Twin<F>,
    running: ImageSlot,
    target: ImageSlot,
) -> Result<(), AbError<F::Error>> {
    may_write(twin, running, target)?;
    let record = read(twin)?;
    let marked_there = matches!(record.and_then(|r| r.trial), Some((slot, _)) if slot == target);
    let confirmed_here = record.is_some_and(|r| r.confirmed == running);
    if marked_there || !confirmed_here {
        // Whatever the record said, the running slot is the good one.
        write(
            twin,
            BootRecord {
                confirmed: running,
                trial: None,
                reverted: false,
            },
        )?;
    }
    Ok(())
}

/// The application may write `target` while `running` runs: not the running slot, and
/// not while the running image is on trial (it could still be reverted to the slot a
/// download would erase).
fn may_write<F: NorFlash>(
    twin: &mut Twin<F>,
    running: ImageSlot,
    target: ImageSlot,
) -> Result<(), AbError<F::Error>> {
    if target == running {
        return Err(AbError::SlotInUse(target));
    }
    if state(twin, running)? == BootState::Trial {
        return Err(AbError::Unconfirmed);
    }
    Ok(())
}

/// Marks `target`, downloaded and verified while `running` runs, for a trial at the next
/// reset.
pub fn mark_trial<F: NorFlash>(
    twin: &mut Twin<F>,
    running: ImageSlot,
    target: ImageSlot,
) -> Result<(), AbError<F::Error>> {
    may_write(twin, running, target)?;
    write(
        twin,
        BootRecord {
            confirmed: running,
            trial: Some((target, TrialPhase::Marked)),
            reverted: false,
        },
    )?;
    Ok(())
}

/// The running image passed its self-test: `running` becomes the confirmed slot. Nothing is
/// written if it already is.
pub fn confirm<F: NorFlash>(
    twin: &mut Twin<F>,
    running: ImageSlot,
) -> Result<(), TwinError<F::Error>> {
    let record = read(twin)?;
    if record.is_some_and(|r| r.confirmed == running && r.trial.is_none()) {
        return Ok(());
    }
    write(
        twin,
        BootRecord {
            confirmed: running,
            trial: None,
            reverted: record.is_some_and(|r| r.reverted && r.confirmed == running),
        },
    )
}

/// What the bootloader starts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BootChoice {
    /// The slot to start.
    pub slot: ImageSlot,
    /// What the bootloader did on the way.
    pub action: BootAction,
}

/// What the bootloader did before it starts a slot.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BootAction {
    /// Nothing pending: the confirmed slot.
    Normal,
    /// A marked slot starts on trial.
    Trial,
    /// A trial that did not confirm itself was reverted.
    Reverted,
    /// Something was off (the record, the store, or the slot it names holds no startable
    /// image): the bootloader starts what it can.
    Fallback,
}

/// The bootloader's decision at a reset, recorded before it is acted on. `startable` says
/// whether a slot holds something that can be started (a plausible vector table); the
/// record is only followed to a startable slot.
pub fn choose<F: NorFlash>(
    twin: &mut Twin<F>,
    startable: impl Fn(ImageSlot) -> bool,
) -> BootChoice {
    let fallback = |preferred: ImageSlot| {
        let slot = if startable(preferred) {
            preferred
        } else if startable(preferred.other()) {
            preferred.other()
        } else {
            preferred
        };
        BootChoice {
            slot,
            action: BootAction::Fallback,
        }
    };
    let record = match read(twin) {
        Ok(Some(record)) => record,
        _ => return fallback(ImageSlot::A),
    };
    let confirmed = record.confirmed;
    match record.trial {
        None if startable(confirmed) => BootChoice {
            slot: confirmed,
            action: BootAction::Normal,
        },
        None => fallback(confirmed),
        Some((slot, TrialPhase::Marked)) if startable(slot) => {
            let started = BootRecord {
                trial: Some((slot, TrialPhase::Started)),
                reverted: false,
                ..record
            };
            match write(twin, started) {
                Ok(()) => BootChoice {
                    slot,
                    action: BootAction::Trial,
                },
                // Not recorded: a crash of the new image would start it again and again.
                Err(_) => fallback(confirmed),
            }
        }
        Some((_, phase)) => {
            let reverted = BootRecord {
                confirmed,
                trial: None,
                reverted: phase == TrialPhase::Started,
            };
            // Not kept: the next reset finds the same record and tries again.
            let _ = write(twin, reverted);
            if startable(confirmed) {
                BootChoice {
                    slot: confirmed,
                    action: BootAction::Reverted,
                }
            } else {
                fallback(confirmed)
            }
        }
    }
}

/// Whether the first 8 bytes of a slot's vector table (`initial_sp`, `reset`) look like an
/// application linked for `slot`: the stack pointer in the F446's SRAM and word aligned, the
/// reset handler a Thumb address inside the slot. An erased or half-written slot fails.
pub const fn plausible_vector_table(slot: ImageSlot, initial_sp: u32, reset: u32) -> bool {
    plausible_start(slot.vector_table(), slot.region().end(), initial_sp, reset)
}

/// Whether a vector table at `table` (`initial_sp`, `reset`) can start a Cortex-M core on the
/// F446 running code linked between `table` and `end`: the stack pointer in SRAM (or at its
/// end) and word aligned, the reset handler a Thumb address in that range. The rule of
/// [`plausible_vector_table`], for any code in flash (the bootloader's too).
pub const fn plausible_start(table: u32, end: u32, initial_sp: u32, reset: u32) -> bool {
    let sp_ok =
        initial_sp > SRAM_START && initial_sp <= SRAM_START + SRAM_SIZE && initial_sp % 4 == 0;
    let code = reset & !1;
    let reset_ok = reset & 1 == 1 && code >= table && code < end;
    sp_ok && reset_ok
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_record_reads_back_from_its_payload() {
        for confirmed in ImageSlot::ALL {
            for trial in [
                None,
                Some((confirmed.other(), TrialPhase::Marked)),
                Some((confirmed.other(), TrialPhase::Started)),
            ] {
                for reverted in [false, true] {
                    let record = BootRecord {
                        confirmed,
                        trial,
                        reverted,
                    };
                    assert_eq!(BootRecord::from_payload(record.to_payload()), Some(record));
                }
            }
        }
        assert_eq!(BootRecord::FACTORY.to_payload(), [0, 0xFF, 0, 0]);
    }

    #[test]
    fn malformed_payloads_are_not_boot_records() {
        for payload in [
            [2, 0xFF, 0, 0],
            [0, 0, 0, 0],
            [0, 1, 2, 0],
            [0, 2, 0, 0],
            [0, 0xFF, 1, 0],
            [0, 0xFF, 0, 2],
        ] {
            assert_eq!(BootRecord::from_payload(payload), None, "{payload:?}");
        }
    }

    #[test]
    fn slots_know_their_addresses() {
        assert_eq!(ImageSlot::A.vector_table(), 0x0802_0200);
        assert_eq!(ImageSlot::B.vector_table(), 0x0804_0200);
        assert_eq!(ImageSlot::at_vector_table(0x0804_0200), Some(ImageSlot::B));
        assert_eq!(ImageSlot::at_vector_table(0x0802_0000), None);
        for slot in ImageSlot::ALL {
            assert_eq!(ImageSlot::from_number(slot.number()), Some(slot));
            assert_eq!(slot.other().other(), slot);
        }
    }

    #[test]
    fn vector_tables_are_checked_against_their_slot() {
        let a = ImageSlot::A;
        assert!(plausible_vector_table(a, 0x2002_0000, 0x0802_0401));
        assert!(
            !plausible_vector_table(a, 0x2002_0000, 0x0802_0400),
            "not Thumb"
        );
        assert!(
            !plausible_vector_table(a, 0x2002_0000, 0x0804_0401),
            "slot B code"
        );
        assert!(
            !plausible_vector_table(a, 0xFFFF_FFFF, 0xFFFF_FFFF),
            "erased"
        );
        assert!(
            !plausible_vector_table(a, 0x2002_0002, 0x0802_0401),
            "unaligned SP"
        );
        assert!(plausible_vector_table(
            ImageSlot::B,
            0x2001_0000,
            0x0804_1235
        ));
    }
}
