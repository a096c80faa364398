//! The STM32F446RE flash map of an AutoPlug ECU.
//!
//! This module is the one place the partition addresses are written: the bootloader, the
//! application's linker script, the updater and the simulation all take them from here.
//!
//! | sectors | address       | size    | use                                               |
//! |---------|---------------|---------|---------------------------------------------------|
//! | 0–1     | `0x0800_0000` | 32 KiB  | bootloader ([`BOOTLOADER`])                       |
//! | 2       | `0x0800_8000` | 16 KiB  | persistent state, copy A ([`STATE_COPY_A`])       |
//! | 3       | `0x0800_C000` | 16 KiB  | persistent state, copy B ([`STATE_COPY_B`])       |
//! | 4       | `0x0801_0000` | 64 KiB  | spare ([`SPARE`])                                 |
//! | 5       | `0x0802_0000` | 128 KiB | image slot A ([`SLOT_A`])                         |
//! | 6       | `0x0804_0000` | 128 KiB | image slot B ([`SLOT_B`])                         |
//! | 7       | `0x0806_0000` | 128 KiB | spare ([`SPARE_HIGH`])                            |
//!
//! Images run in place from either slot ([`crate::ab`]): an image is linked for one slot, and
//! an update writes the slot that is not running. One slot per 128 KiB sector keeps an update
//! to one sector erase.

/// First address of the main flash memory (RM0390, "Embedded flash memory").
pub const FLASH_BASE: u32 = 0x0800_0000;

/// Size of the STM32F446RE's main flash memory: 512 KiB.
pub const FLASH_SIZE: u32 = 512 * 1024;

/// Size of sectors 0–3.
pub const SMALL_SECTOR_SIZE: u32 = 16 * 1024;
/// Size of sector 4.
pub const MEDIUM_SECTOR_SIZE: u32 = 64 * 1024;
/// Size of sectors 5–7.
pub const LARGE_SECTOR_SIZE: u32 = 128 * 1024;

/// Programming unit in bytes, as embassy-stm32 0.6 uses it on the F4 (`WRITE_SIZE = 4`,
/// from stm32-metapac's `write_size: 4` for the F446): it programs with x32 parallelism
/// (`PSIZE = 32`), one 32-bit word per flash operation. The simulation uses the same value so
/// code that runs against it runs unchanged against `embassy_stm32::flash`.
pub const WRITE_SIZE: usize = 4;

/// Value of an erased byte (stm32-metapac: `erase_value: 255` for the F446; the NOR cells
/// erase to all ones): what an erased slot, record or header reads as.
pub const ERASE_VALUE: u8 = 0xFF;

/// One erase sector of the flash.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Sector {
    /// Sector number, as written to `FLASH_CR.SNB` to erase it.
    pub index: u8,
    /// First address.
    pub start: u32,
    /// Size in bytes; erasing the sector erases all of them.
    pub size: u32,
}

impl Sector {
    /// One past the last address.
    pub const fn end(&self) -> u32 {
        self.start + self.size
    }

    /// Whether `address` lies in this sector.
    pub const fn contains(&self, address: u32) -> bool {
        address >= self.start && address < self.end()
    }
}

/// The eight sectors of the STM32F446RE (RM0390, table "Flash module organization").
pub const SECTORS: [Sector; 8] = [
    Sector {
        index: 0,
        start: 0x0800_0000,
        size: SMALL_SECTOR_SIZE,
    },
    Sector {
        index: 1,
        start: 0x0800_4000,
        size: SMALL_SECTOR_SIZE,
    },
    Sector {
        index: 2,
        start: 0x0800_8000,
        size: SMALL_SECTOR_SIZE,
    },
    Sector {
        index: 3,
        start: 0x0800_C000,
        size: SMALL_SECTOR_SIZE,
    },
    Sector {
        index: 4,
        start: 0x0801_0000,
        size: MEDIUM_SECTOR_SIZE,
    },
    Sector {
        index: 5,
        start: 0x0802_0000,
        size: LARGE_SECTOR_SIZE,
    },
    Sector {
        index: 6,
        start: 0x0804_0000,
        size: LARGE_SECTOR_SIZE,
    },
    Sector {
        index: 7,
        start: 0x0806_0000,
        size: LARGE_SECTOR_SIZE,
    },
];

/// The sector holding `address`, or `None` if it is outside the main flash.
pub const fn sector_of(address: u32) -> Option<Sector> {
    let mut i = 0;
    while i < SECTORS.len() {
        if SECTORS[i].contains(address) {
            return Some(SECTORS[i]);
        }
        i += 1;
    }
    None
}

/// A contiguous range of flash, made of whole sectors.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Region {
    /// First address.
    pub start: u32,
    /// Size in bytes.
    pub size: u32,
}

impl Region {
    /// One past the last address.
    pub const fn end(&self) -> u32 {
        self.start + self.size
    }

    /// Whether `address` lies in this region.
    pub const fn contains(&self, address: u32) -> bool {
        address >= self.start && address < self.end()
    }

    /// Whether `other` lies wholly in this region.
    pub const fn contains_region(&self, other: Region) -> bool {
        other.start >= self.start && other.end() <= self.end()
    }

    /// Offset of `address` from the region's start, if it lies in the region.
    pub const fn offset_of(&self, address: u32) -> Option<u32> {
        if self.contains(address) {
            Some(address - self.start)
        } else {
            None
        }
    }

    /// Whether this region and `other` share at least one byte.
    pub const fn overlaps(&self, other: &Region) -> bool {
        self.start < other.end() && other.start < self.end()
    }

    /// The sectors of this region, in address order (empty if the region does not start and
    /// end on sector boundaries inside the flash).
    pub fn sectors(&self) -> &'static [Sector] {
        match (self.first_sector_index(), self.end_sector_index()) {
            (Some(first), Some(end)) if first < end => &SECTORS[first..end],
            _ => &[],
        }
    }

    /// Index in [`SECTORS`] of the sector starting at this region's start.
    const fn first_sector_index(&self) -> Option<usize> {
        let mut i = 0;
        while i < SECTORS.len() {
            if SECTORS[i].start == self.start {
                return Some(i);
            }
            i += 1;
        }
        None
    }

    /// One past the index in [`SECTORS`] of the sector ending at this region's end.
    const fn end_sector_index(&self) -> Option<usize> {
        let mut i = 0;
        while i < SECTORS.len() {
            if SECTORS[i].end() == self.end() {
                return Some(i + 1);
            }
            i += 1;
        }
        None
    }

    /// Whether the region starts and ends on sector boundaries of the flash.
    pub const fn is_sector_aligned(&self) -> bool {
        match (self.first_sector_index(), self.end_sector_index()) {
            (Some(first), Some(end)) => first < end,
            _ => false,
        }
    }

    /// The erase size of the region if all its sectors have the same size (what a
    /// `NorFlash::ERASE_SIZE` over it has to be), `None` if they differ or the region is not
    /// sector aligned.
    pub const fn uniform_erase_size(&self) -> Option<u32> {
        let (first, end) = match (self.first_sector_index(), self.end_sector_index()) {
            (Some(first), Some(end)) if first < end => (first, end),
            _ => return None,
        };
        let size = SECTORS[first].size;
        let mut i = first;
        while i < end {
            if SECTORS[i].size != size {
                return None;
            }
            i += 1;
        }
        Some(size)
    }
}

/// The whole main flash.
pub const FLASH: Region = Region {
    start: FLASH_BASE,
    size: FLASH_SIZE,
};

/// The bootloader: sectors 0–1. The reset vector at 0x0800_0000 runs it.
pub const BOOTLOADER: Region = Region {
    start: 0x0800_0000,
    size: 2 * SMALL_SECTOR_SIZE,
};

/// The ECU's persistent state, copy A: sector 2. Its records (the boot record of
/// [`crate::ab`], the version floor, failed SecurityAccess attempts, the seed epoch) live
/// in one of the two copies, written alternately ([`crate::twin`]).
pub const STATE_COPY_A: Region = Region {
    start: 0x0800_8000,
    size: SMALL_SECTOR_SIZE,
};

/// The ECU's persistent state, copy B: sector 3 ([`STATE_COPY_A`]).
pub const STATE_COPY_B: Region = Region {
    start: 0x0800_C000,
    size: SMALL_SECTOR_SIZE,
};

/// Both copies of the persistent state, in the order [`crate::twin::Twin::open`] takes them.
pub const STATE_COPIES: [Region; 2] = [STATE_COPY_A, STATE_COPY_B];

/// Sector 4, unused (64 KiB: its size does not fit the 128 KiB slot pages).
pub const SPARE: Region = Region {
    start: 0x0801_0000,
    size: MEDIUM_SECTOR_SIZE,
};

/// Image slot A: sector 5. A signed image starts here with its header; a new board runs
/// it.
pub const SLOT_A: Region = Region {
    start: 0x0802_0000,
    size: LARGE_SECTOR_SIZE,
};

/// Image slot B: sector 6, the same size as [`SLOT_A`].
pub const SLOT_B: Region = Region {
    start: 0x0804_0000,
    size: LARGE_SECTOR_SIZE,
};

/// Sector 7, unused: room for a third slot or a larger image layout.
pub const SPARE_HIGH: Region = Region {
    start: 0x0806_0000,
    size: LARGE_SECTOR_SIZE,
};

/// The 16 KiB sectors 0–3: embassy-stm32's flash region 1 of the F446 (`bank1_region1`),
/// whose offsets count from its start. The state copies are in it.
pub const SMALL_SECTORS: Region = Region {
    start: FLASH_BASE,
    size: 4 * SMALL_SECTOR_SIZE,
};

/// The 128 KiB sectors 5–7: embassy-stm32's flash region 3 of the F446 (`bank1_region3`),
/// whose offsets count from its start. Both image slots are in it.
pub const LARGE_SECTORS: Region = Region {
    start: FLASH_BASE + 4 * SMALL_SECTOR_SIZE + MEDIUM_SECTOR_SIZE,
    size: 3 * LARGE_SECTOR_SIZE,
};

/// Every partition of the map with a name for messages, in address order.
pub const PARTITIONS: [(&str, Region); 7] = [
    ("bootloader", BOOTLOADER),
    ("state copy A", STATE_COPY_A),
    ("state copy B", STATE_COPY_B),
    ("spare", SPARE),
    ("slot A", SLOT_A),
    ("slot B", SLOT_B),
    ("spare (sector 7)", SPARE_HIGH),
];

/// The named partition holding `address`, if any.
pub const fn partition_of(address: u32) -> Option<(&'static str, Region)> {
    let mut i = 0;
    while i < PARTITIONS.len() {
        if PARTITIONS[i].1.contains(address) {
            return Some(PARTITIONS[i]);
        }
        i += 1;
    }
    None
}

/// First address of the F446RE's SRAM (RM0390, memory map): where an application's stack
/// and data live, and where a vector table's initial stack pointer must point.
pub const SRAM_START: u32 = 0x2000_0000;

/// Size of the F446RE's SRAM (SRAM1 and SRAM2 as one block), bytes.
pub const SRAM_SIZE: u32 = 128 * 1024;

/// Size of the signed image's header at the start of a slot.
pub const IMAGE_HEADER_SIZE: u32 = 512;

/// Erase size of the image slots ([`SLOT_A`], [`SLOT_B`]): the 128 KiB sectors.
pub const SLOT_ERASE_SIZE: u32 = LARGE_SECTOR_SIZE;

/// Erase size of the state copies ([`STATE_COPIES`]): the 16 KiB sectors.
pub const SMALL_ERASE_SIZE: u32 = SMALL_SECTOR_SIZE;

// The sector table tiles the flash exactly, in order.
// embassy-stm32's regions are where the sectors say, and hold the partitions the
// bootloader and the application address through them.
const _: () = {
    assert!(SMALL_SECTORS.start == SECTORS[0].start);
    assert!(LARGE_SECTORS.start == SECTORS[5].start);
    assert!(
        SMALL_SECTORS.contains_region(STATE_COPY_A) && SMALL_SECTORS.contains_region(STATE_COPY_B)
    );
    assert!(LARGE_SECTORS.contains_region(SLOT_A) && LARGE_SECTORS.contains_region(SLOT_B));
};

const _: () = {
    assert!(SECTORS[0].start == FLASH_BASE);
    let mut i = 0;
    while i < SECTORS.len() {
        assert!(
            SECTORS[i].index as usize == i,
            "sector numbers are their table index"
        );
        if i + 1 < SECTORS.len() {
            assert!(
                SECTORS[i].end() == SECTORS[i + 1].start,
                "sectors are contiguous"
            );
        }
        i += 1;
    }
    assert!(SECTORS[SECTORS.len() - 1].end() == FLASH_BASE + FLASH_SIZE);
};

// Every partition is made of whole sectors, and no two share one: erasing one partition
// must never erase a byte of another.
const _: () = {
    let mut i = 0;
    while i < PARTITIONS.len() {
        let part = PARTITIONS[i].1;
        assert!(part.is_sector_aligned(), "partitions are whole sectors");
        assert!(part.end() <= FLASH_BASE + FLASH_SIZE);
        let mut j = i + 1;
        while j < PARTITIONS.len() {
            assert!(
                !part.overlaps(&PARTITIONS[j].1),
                "partitions do not overlap"
            );
            j += 1;
        }
        i += 1;
    }
    // The bootloader must hold the reset vector.
    assert!(BOOTLOADER.start == FLASH_BASE);
};

// The slots: one sector each, the same size, so any image fits either; the state copies:
// one erase unit each (what `Twin::open` checks).
const _: () = {
    assert!(matches!(SLOT_A.uniform_erase_size(), Some(SLOT_ERASE_SIZE)));
    assert!(SLOT_A.size == SLOT_ERASE_SIZE && SLOT_B.size == SLOT_ERASE_SIZE);
    assert!(matches!(
        STATE_COPY_A.uniform_erase_size(),
        Some(SMALL_ERASE_SIZE)
    ));
    assert!(STATE_COPY_A.size == SMALL_ERASE_SIZE && STATE_COPY_B.size == SMALL_ERASE_SIZE);
};

// The image layout: the vector table follows the header, and is aligned as VTOR needs. The
// F446 has 16 system + 97 interrupt vectors (452 bytes), so VTOR wants 512-byte alignment.
const _: () = {
    assert!((SLOT_A.start + IMAGE_HEADER_SIZE) % 512 == 0);
    assert!((SLOT_B.start + IMAGE_HEADER_SIZE) % 512 == 0);
    assert!(IMAGE_HEADER_SIZE % WRITE_SIZE as u32 == 0);
};

#[cfg(test)]
mod tests {
    // The crate is no_std; its tests run on the host and may allocate.
    extern crate std;
    use std::vec::Vec;

    use super::*;

    #[test]
    fn sector_of_finds_the_sector_at_both_ends() {
        let cases = [
            (0x0800_0000, 0),
            (0x0800_3FFF, 0),
            (0x0800_4000, 1),
            (0x0800_8000, 2),
            (0x0800_C000, 3),
            (0x0800_FFFF, 3),
            (0x0801_0000, 4),
            (0x0801_FFFF, 4),
            (0x0802_0000, 5),
            (0x0803_FFFF, 5),
            (0x0804_0000, 6),
            (0x0806_0000, 7),
            (0x0807_FFFF, 7),
        ];
        for (address, index) in cases {
            assert_eq!(
                sector_of(address).map(|s| s.index),
                Some(index),
                "{address:#x}"
            );
        }
        assert_eq!(sector_of(0x07FF_FFFF), None);
        assert_eq!(sector_of(0x0808_0000), None);
    }

    #[test]
    fn partitions_are_the_documented_sectors() {
        let indices = |region: Region| region.sectors().iter().map(|s| s.index).collect::<Vec<_>>();
        assert_eq!(indices(BOOTLOADER), [0, 1]);
        assert_eq!(indices(STATE_COPY_A), [2]);
        assert_eq!(indices(STATE_COPY_B), [3]);
        assert_eq!(indices(SPARE), [4]);
        assert_eq!(indices(SLOT_A), [5]);
        assert_eq!(indices(SLOT_B), [6]);
        assert_eq!(indices(SPARE_HIGH), [7]);
    }

    #[test]
    fn partitions_tile_the_flash_in_order() {
        let mut next = FLASH_BASE;
        for (name, region) in PARTITIONS {
            assert_eq!(
                region.start, next,
                "{name} starts where the previous partition ends"
            );
            assert_eq!(partition_of(region.start).map(|p| p.0), Some(name));
            assert_eq!(partition_of(region.end() - 1).map(|p| p.0), Some(name));
            next = region.end();
        }
        assert_eq!(next, FLASH.end());
        assert_eq!(partition_of(FLASH.end()), None);
    }

    #[test]
    fn region_helpers() {
        assert_eq!(SLOT_A.offset_of(0x0802_0200), Some(IMAGE_HEADER_SIZE));
        assert_eq!(SLOT_A.offset_of(SLOT_B.start), None);
        assert!(SLOT_B.overlaps(&Region {
            start: 0x0805_0000,
            size: 4
        }));
        assert!(!SLOT_B.overlaps(&SLOT_A));
        // Sectors 3 and 4 differ in size: no single erase size, as a partition needs.
        let mixed = Region {
            start: 0x0800_C000,
            size: SMALL_SECTOR_SIZE + MEDIUM_SECTOR_SIZE,
        };
        assert!(mixed.is_sector_aligned());
        assert_eq!(mixed.uniform_erase_size(), None);
        let unaligned = Region {
            start: 0x0800_0100,
            size: SMALL_SECTOR_SIZE,
        };
        assert!(!unaligned.is_sector_aligned());
        assert!(unaligned.sectors().is_empty());
        assert_eq!(SLOT_B.uniform_erase_size(), Some(SLOT_ERASE_SIZE));
    }
}
