//! The flash as a programmer leaves it: erased, then the bootloader's and an application's
//! ELF files written where they are linked (each loadable segment at its physical address:
//! .data's initial values sit in flash, where the startup code copies them from), as
//! `probe-rs download` would write them to a Nucleo-F446RE.

use std::fmt;

use autoplug_flash::ab::plausible_start;
use autoplug_flash::{ERASE_VALUE, PARTITIONS};

use crate::map::{FLASH, FLASH_BASE, FLASH_SIZE, SRAM};

/// What was written, from which file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Written {
    /// The file's name, as given.
    pub file: String,
    /// The first address written.
    pub start: u32,
    /// One past the last address written.
    pub end: u32,
}

/// Why a file could not be written to the flash. Nothing of the file is written then.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ProgramError {
    /// Not an ELF file for the chip (not an ELF file, another machine, a damaged file).
    NotFirmware {
        /// The file's name.
        file: String,
        /// What is wrong with it.
        reason: String,
    },
    /// A segment with data outside the flash (an image built to run from RAM, or for a
    /// chip with more flash).
    OutsideFlash {
        /// The file's name.
        file: String,
        /// The segment's first address.
        start: u32,
        /// One past its last address.
        end: u32,
    },
    /// A segment over flash another file (or the same file) already wrote.
    Overlap {
        /// The file's name.
        file: String,
        /// The segment's first address.
        start: u32,
        /// One past its last address.
        end: u32,
        /// The file that wrote there first.
        other: String,
    },
    /// No loadable segment with data.
    Empty {
        /// The file's name.
        file: String,
    },
}

impl fmt::Display for ProgramError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotFirmware { file, reason } => {
                write!(f, "{file}: not firmware for the STM32F446: {reason}")
            }
            Self::OutsideFlash { file, start, end } => write!(
                f,
                "{file}: a segment at 0x{start:08X}..0x{end:08X} lies outside the flash (0x{:08X}..0x{:08X}){}",
                FLASH.start,
                FLASH.end,
                if SRAM.contains(start) { ": the image is linked to run from RAM" } else { "" }
            ),
            Self::Overlap {
                file,
                start,
                end,
                other,
            } => write!(
                f,
                "{file}: a segment at 0x{start:08X}..0x{end:08X} overlaps flash {other} already wrote"
            ),
            Self::Empty { file } => write!(f, "{file}: no loadable segment with data"),
        }
    }
}

impl std::error::Error for ProgramError {}

/// The flash's 512 KiB as programmed.
#[derive(Clone)]
pub struct FlashContents {
    bytes: Vec<u8>,
    written: Vec<Written>,
}

impl Default for FlashContents {
    fn default() -> Self {
        Self::erased()
    }
}

impl fmt::Debug for FlashContents {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("FlashContents")
            .field("written", &self.written)
            .finish_non_exhaustive()
    }
}

impl FlashContents {
    /// An erased flash: every byte 0xFF.
    pub fn erased() -> Self {
        Self {
            bytes: vec![ERASE_VALUE; FLASH_SIZE as usize],
            written: Vec::new(),
        }
    }

    /// Writes the loadable segments of the ELF file `elf` (named `file` in errors); refuses
    /// the whole file, writing nothing, if any segment is outside the flash or over what is
    /// written already.
    pub fn program_elf(&mut self, file: &str, elf: &[u8]) -> Result<&Written, ProgramError> {
        let segments = autoplug_image::elf::loadable_segments(elf).map_err(|reason| {
            ProgramError::NotFirmware {
                file: file.to_string(),
                reason,
            }
        })?;
        if segments.is_empty() {
            return Err(ProgramError::Empty {
                file: file.to_string(),
            });
        }
        let mut ranges: Vec<(u32, u32)> = Vec::with_capacity(segments.len());
        for &(start, data) in &segments {
            let end = start + data.len() as u64;
            let (Ok(start32), Ok(end32)) = (u32::try_from(start), u32::try_from(end)) else {
                return Err(ProgramError::OutsideFlash {
                    file: file.to_string(),
                    start: start.min(u64::from(u32::MAX)) as u32,
                    end: u32::MAX,
                });
            };
            if start32 < FLASH.start || end32 > FLASH.end {
                return Err(ProgramError::OutsideFlash {
                    file: file.to_string(),
                    start: start32,
                    end: end32,
                });
            }
            let earlier = self
                .written
                .iter()
                .filter(|w| start32 < w.end && w.start < end32)
                .map(|w| w.file.clone())
                .chain(
                    ranges
                        .iter()
                        .filter(|&&(s, e)| start32 < e && s < end32)
                        .map(|_| file.to_string()),
                )
                .next();
            if let Some(other) = earlier {
                return Err(ProgramError::Overlap {
                    file: file.to_string(),
                    start: start32,
                    end: end32,
                    other,
                });
            }
            ranges.push((start32, end32));
        }
        for &(start, data) in &segments {
            let offset = (start - u64::from(FLASH_BASE)) as usize;
            self.bytes[offset..offset + data.len()].copy_from_slice(data);
        }
        let start = ranges.iter().map(|r| r.0).min().unwrap_or(FLASH_BASE);
        let end = ranges.iter().map(|r| r.1).max().unwrap_or(FLASH_BASE);
        self.written.push(Written {
            file: file.to_string(),
            start,
            end,
        });
        Ok(self.written.last().expect("just pushed"))
    }

    /// The simulated NOR flash with these contents, as the MCU finds it at power-on: each
    /// written range programmed in whole words (`seed` decides what power cuts leave).
    pub fn to_sim_flash(&self, seed: u64) -> autoplug_flash::sim::SimFlash {
        let mut flash = autoplug_flash::sim::SimFlash::new(seed);
        for written in &self.written {
            let start = written.start & !3;
            let end = (written.end + 3) & !3;
            let bytes = &self.bytes[(start - FLASH_BASE) as usize..(end - FLASH_BASE) as usize];
            // Programming an erased flash in words inside it cannot fail.
            let _ = flash.program(start, bytes);
        }
        flash
    }

    /// The flash's bytes, from [`FLASH_BASE`].
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// What was written so far, file by file.
    pub fn written(&self) -> &[Written] {
        &self.written
    }

    /// The little-endian word at `address`; `None` outside the flash or unaligned.
    pub fn word(&self, address: u32) -> Option<u32> {
        if address % 4 != 0 || !FLASH.contains(&address) {
            return None;
        }
        let offset = (address - FLASH_BASE) as usize;
        let bytes = self.bytes.get(offset..offset + 4)?;
        Some(u32::from_le_bytes(bytes.try_into().ok()?))
    }

    /// The vector table at `address`: its initial stack pointer and reset vector, if they
    /// can start a Cortex-M core (the bootloader's own rule,
    /// `autoplug_flash::ab::plausible_start`: the stack pointer a word in SRAM, the reset
    /// vector Thumb code in the partition that holds the table). `Err` says why not.
    pub fn vector_table(&self, address: u32) -> Result<(u32, u32), String> {
        let (Some(sp), Some(reset)) = (self.word(address), self.word(address.wrapping_add(4)))
        else {
            return Err(format!(
                "no vector table at 0x{address:08X}: not in the flash"
            ));
        };
        let end = PARTITIONS
            .iter()
            .map(|(_, region)| region)
            .find(|region| region.contains(address))
            .map_or(FLASH.end, |region| region.end());
        if plausible_start(address, end, sp, reset) {
            return Ok((sp, reset));
        }
        Err(format!(
            "the vector table at 0x{address:08X} cannot start the core: initial stack pointer 0x{sp:08X} (a word in SRAM 0x{:08X}..=0x{:08X} expected), reset vector 0x{reset:08X} (Thumb code in 0x{address:08X}..0x{end:08X} expected)",
            SRAM.start, SRAM.end
        ))
    }
}

/// Where [`bare_program`] puts its code, from the start of flash: past the vector table's
/// first 16 entries (the core's exceptions).
pub const BARE_CODE_OFFSET: u32 = 0x40;

/// The image of a bare program for the start of flash, without an ELF file (the core's
/// tests and examples): `vectors` (the initial SP, then the reset vector and the others,
/// Thumb bit set) and `code`, Thumb halfwords from [`BARE_CODE_OFFSET`].
pub fn bare_program(vectors: &[u32], code: &[u16]) -> Vec<u8> {
    let start = BARE_CODE_OFFSET as usize;
    // Whole double words, as the flash is programmed.
    let len = (start + 2 * code.len())
        .max(4 * vectors.len())
        .next_multiple_of(8);
    let mut image = vec![0u8; len];
    for (i, word) in vectors.iter().enumerate() {
        image[4 * i..4 * i + 4].copy_from_slice(&word.to_le_bytes());
    }
    for (i, halfword) in code.iter().enumerate() {
        image[start + 2 * i..start + 2 * i + 2].copy_from_slice(&halfword.to_le_bytes());
    }
    image
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoplug_image::elf::minimal_elf;
    use object::elf::{EM_386, EM_ARM};

    const BOOT: u32 = 0x0800_0000;
    const SLOT_A: u32 = 0x0802_0200;

    fn table(sp: u32, reset: u32) -> Vec<u8> {
        [sp.to_le_bytes(), reset.to_le_bytes()].concat()
    }

    #[test]
    fn the_bootloader_and_an_application_are_written_where_they_are_linked() {
        let mut flash = FlashContents::erased();
        let boot = minimal_elf(&[(BOOT, &table(0x2002_0000, BOOT + 0x201))], EM_ARM);
        let app = minimal_elf(
            &[
                (SLOT_A, &table(0x2001_8000, SLOT_A + 0x401)),
                (SLOT_A + 0x400, &[0x70, 0x47]),
            ],
            EM_ARM,
        );
        assert_eq!(
            flash.program_elf("boot.elf", &boot).unwrap(),
            &Written {
                file: "boot.elf".into(),
                start: BOOT,
                end: BOOT + 8
            }
        );
        assert_eq!(
            flash.program_elf("app.elf", &app).unwrap().end,
            SLOT_A + 0x402
        );
        assert_eq!(flash.vector_table(BOOT), Ok((0x2002_0000, BOOT + 0x201)));
        assert_eq!(
            flash.vector_table(SLOT_A),
            Ok((0x2001_8000, SLOT_A + 0x401))
        );
        assert_eq!(flash.word(SLOT_A + 0x400), Some(0xFFFF_4770));
        // Between the segments the flash stays erased.
        assert_eq!(flash.word(SLOT_A + 8), Some(0xFFFF_FFFF));
        assert_eq!(flash.written().len(), 2);
    }

    #[test]
    fn files_that_are_not_firmware_for_the_chip_are_refused_and_write_nothing() {
        let mut flash = FlashContents::erased();
        let error = flash.program_elf("notes.txt", b"hello").unwrap_err();
        assert_eq!(
            error.to_string(),
            "notes.txt: not firmware for the STM32F446: not an ELF file"
        );
        let x86 = minimal_elf(&[(BOOT, &[0; 8])], EM_386);
        let error = flash.program_elf("x86.elf", &x86).unwrap_err();
        assert!(error.to_string().contains("for machine 3"), "{error}");
        let in_ram = minimal_elf(&[(0x2000_0000, &[0; 8])], EM_ARM);
        let error = flash.program_elf("ram.elf", &in_ram).unwrap_err();
        assert_eq!(
            error,
            ProgramError::OutsideFlash {
                file: "ram.elf".into(),
                start: 0x2000_0000,
                end: 0x2000_0008
            }
        );
        assert!(
            error.to_string().ends_with("linked to run from RAM"),
            "{error}"
        );
        let past_end = minimal_elf(&[(0x0807_FFFC, &[0; 8])], EM_ARM);
        assert!(matches!(
            flash.program_elf("big.elf", &past_end),
            Err(ProgramError::OutsideFlash { .. })
        ));
        assert!(flash.written().is_empty());
        assert!(flash.bytes().iter().all(|&b| b == ERASE_VALUE));
    }

    #[test]
    fn a_file_over_another_is_refused_whole() {
        let mut flash = FlashContents::erased();
        let boot = minimal_elf(&[(BOOT, &[1; 64])], EM_ARM);
        flash.program_elf("boot.elf", &boot).unwrap();
        let clash = minimal_elf(&[(SLOT_A, &[2; 8]), (BOOT + 60, &[3; 8])], EM_ARM);
        let error = flash.program_elf("app.elf", &clash).unwrap_err();
        assert_eq!(
            error.to_string(),
            "app.elf: a segment at 0x0800003C..0x08000044 overlaps flash boot.elf already wrote"
        );
        // Nothing of the refused file was written, not even its first segment.
        assert_eq!(flash.word(SLOT_A), Some(0xFFFF_FFFF));
        let twice = minimal_elf(&[(SLOT_A, &[2; 8]), (SLOT_A + 4, &[3; 8])], EM_ARM);
        assert!(matches!(
            flash.program_elf("twice.elf", &twice),
            Err(ProgramError::Overlap { other, .. }) if other == "twice.elf"
        ));
    }

    #[test]
    fn a_vector_table_that_cannot_start_a_core_says_why() {
        let mut flash = FlashContents::erased();
        assert!(flash
            .vector_table(BOOT)
            .unwrap_err()
            .contains("initial stack pointer 0xFFFFFFFF"));
        let arm_mode = minimal_elf(&[(BOOT, &table(0x2002_0000, BOOT + 0x200))], EM_ARM);
        flash.program_elf("boot.elf", &arm_mode).unwrap();
        assert!(flash
            .vector_table(BOOT)
            .unwrap_err()
            .contains("reset vector 0x08000200 (Thumb code in 0x08000000..0x08008000"));
        // Thumb code, but in another partition: the bootloader's table may not start slot A.
        let mut flash = FlashContents::erased();
        let elsewhere = minimal_elf(&[(BOOT, &table(0x2002_0000, SLOT_A + 0x401))], EM_ARM);
        flash.program_elf("boot.elf", &elsewhere).unwrap();
        assert!(flash.vector_table(BOOT).is_err());
        assert!(flash
            .vector_table(0x2000_0000)
            .unwrap_err()
            .contains("not in the flash"));
    }
}
