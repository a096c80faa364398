//! The flash interface (RM0390, section 3): the key sequence, programming words with PG,
//! sector and mass erase with SER/MER and STRT, the status flags, and the access control
//! register. The flash itself is the project's simulated NOR flash
//! ([`autoplug_flash::sim::SimFlash`]), so its datasheet busy times and its power cuts are
//! the ones the rest of the project uses; the core stalls for the busy time, as it does on
//! the chip when it next fetches from the busy flash.

use core::time::Duration;

use autoplug_flash::sim::{FlashError, SimFlash};

use super::{merge, Unmodelled};

const KEY1: u32 = 0x4567_0123;
const KEY2: u32 = 0xCDEF_89AB;
const OPT_KEY1: u32 = 0x0819_2A3B;
const OPT_KEY2: u32 = 0x4C5D_6E7F;

const CR_PG: u32 = 1 << 0;
const CR_SER: u32 = 1 << 1;
const CR_MER: u32 = 1 << 2;
const CR_STRT: u32 = 1 << 16;
const CR_LOCK: u32 = 1 << 31;
const SR_EOP: u32 = 1 << 0;
const SR_PGAERR: u32 = 1 << 5;
const SR_PGPERR: u32 = 1 << 6;
const SR_PGSERR: u32 = 1 << 7;

/// What an access to the flash interface or the flash did.
#[derive(Debug)]
pub enum FlashEffect {
    /// Nothing beyond the registers.
    None,
    /// The flash changed in `range` and was busy for `busy`: the core stalls, and
    /// instructions decoded there are stale.
    Changed {
        /// The addresses changed.
        range: core::ops::Range<u32>,
        /// The datasheet's busy time.
        busy: Duration,
    },
    /// The operation was refused by the simulated flash (a power cut, or a word that needs
    /// an erase first): the emulation stops with this report.
    Failed(FlashError),
    /// A wrong key: the chip answers with a bus error and keeps FLASH_CR locked until reset.
    BusFault,
}

/// The flash interface registers.
#[derive(Clone, Debug)]
pub struct FlashInterface {
    acr: u32,
    key_step: u8,
    opt_key_step: u8,
    /// A wrong key locked FLASH_CR until reset.
    locked_out: bool,
    sr: u32,
    cr: u32,
    optcr: u32,
}

impl Default for FlashInterface {
    fn default() -> Self {
        FlashInterface {
            acr: 0,
            key_step: 0,
            opt_key_step: 0,
            locked_out: false,
            sr: 0,
            cr: CR_LOCK,
            optcr: 0x0FFF_AAED,
        }
    }
}

impl FlashInterface {
    /// Whether the flash interrupt line is high (EOP with EOPIE, errors with ERRIE).
    pub fn irq(&self) -> bool {
        (self.cr & (1 << 24) != 0 && self.sr & SR_EOP != 0)
            || (self.cr & (1 << 25) != 0 && self.sr & 0x1F2 != 0)
    }

    /// Reads a register.
    pub fn read(&self, offset: u32) -> Result<u32, Unmodelled> {
        Ok(match offset {
            0x00 => self.acr,
            0x04 | 0x08 => 0,
            0x0C => self.sr,
            0x10 => self.cr,
            0x14 => self.optcr,
            _ => return Err(Unmodelled::register(offset)),
        })
    }

    /// Writes a register; an erase starts here (STRT).
    pub fn write(
        &mut self,
        offset: u32,
        value: u32,
        mask: u32,
        flash: &mut SimFlash,
    ) -> Result<FlashEffect, Unmodelled> {
        match offset {
            0x00 => {
                // ICRST/DCRST reset the caches and read as 0.
                self.acr = merge(self.acr, value, mask) & 0x070F;
            }
            0x04 => {
                let key = value & mask;
                match (self.key_step, key) {
                    _ if self.locked_out => return Ok(FlashEffect::BusFault),
                    (0, KEY1) => self.key_step = 1,
                    (1, KEY2) if self.cr & CR_LOCK != 0 => {
                        self.key_step = 0;
                        self.cr &= !CR_LOCK;
                    }
                    _ => {
                        self.key_step = 0;
                        self.locked_out = true;
                        self.cr |= CR_LOCK;
                        return Ok(FlashEffect::BusFault);
                    }
                }
            }
            0x08 => match (self.opt_key_step, value & mask) {
                (0, OPT_KEY1) => self.opt_key_step = 1,
                (1, OPT_KEY2) => {
                    self.opt_key_step = 0;
                    self.optcr &= !1;
                }
                _ => {
                    self.opt_key_step = 0;
                    return Ok(FlashEffect::BusFault);
                }
            },
            0x0C => self.sr &= !(value & mask & 0x1F3),
            0x10 => {
                let value = merge(self.cr, value, mask);
                if self.cr & CR_LOCK != 0 {
                    // Locked: only LOCK itself (already set) takes.
                    return Ok(FlashEffect::None);
                }
                self.cr = value & 0x8301_03FF;
                if value & CR_STRT != 0 {
                    return Ok(self.erase(flash));
                }
            }
            0x14 => {
                if self.optcr & 1 != 0 {
                    return Ok(FlashEffect::None);
                }
                let optcr = merge(self.optcr, value, mask);
                if optcr & 2 != 0 {
                    return Err(Unmodelled::feature(
                        "option byte programming (OPTCR.OPTSTRT)",
                    ));
                }
                self.optcr = optcr;
            }
            _ => return Err(Unmodelled::register(offset)),
        }
        Ok(FlashEffect::None)
    }

    fn erase(&mut self, flash: &mut SimFlash) -> FlashEffect {
        let before = flash.total_busy();
        let result = if self.cr & CR_SER != 0 {
            let sector = (self.cr >> 3 & 0xF) as u8;
            match autoplug_flash::SECTORS.iter().find(|s| s.index == sector) {
                Some(s) => flash
                    .erase_sector(sector)
                    .map(|()| s.start..s.start + s.size),
                None => {
                    self.sr |= SR_PGSERR;
                    return FlashEffect::None;
                }
            }
        } else if self.cr & CR_MER != 0 {
            let range =
                autoplug_flash::FLASH_BASE..autoplug_flash::FLASH_BASE + autoplug_flash::FLASH_SIZE;
            flash.erase(range.start, range.end).map(|()| range)
        } else {
            self.sr |= SR_PGSERR;
            return FlashEffect::None;
        };
        self.finish(result, flash.total_busy() - before)
    }

    fn finish(
        &mut self,
        result: Result<core::ops::Range<u32>, FlashError>,
        busy: Duration,
    ) -> FlashEffect {
        match result {
            Ok(range) => {
                if self.cr & (1 << 24) != 0 {
                    self.sr |= SR_EOP;
                }
                FlashEffect::Changed { range, busy }
            }
            Err(error) => FlashEffect::Failed(error),
        }
    }

    /// A write to the flash's address space: a word programmed if PG is set with a 32-bit
    /// parallelism; otherwise the error flags the chip sets.
    pub fn program(&mut self, address: u32, bytes: &[u8], flash: &mut SimFlash) -> FlashEffect {
        if self.cr & CR_PG == 0 || self.cr & CR_LOCK != 0 {
            self.sr |= SR_PGSERR;
            return FlashEffect::None;
        }
        let psize = 1usize << (self.cr >> 8 & 3);
        if bytes.len() != psize {
            self.sr |= SR_PGPERR;
            return FlashEffect::None;
        }
        if address as usize % psize != 0 {
            self.sr |= SR_PGAERR;
            return FlashEffect::None;
        }
        if psize != 4 {
            // The simulated flash programs whole words, as embassy-stm32 does (x32).
            self.sr |= SR_PGPERR;
            return FlashEffect::None;
        }
        let before = flash.total_busy();
        let result = flash.program(address, bytes).map(|()| address..address + 4);
        self.finish(result, flash.total_busy() - before)
    }
}
