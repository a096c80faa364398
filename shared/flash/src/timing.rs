//! How long the flash is busy: typical values of the STM32F446xC/E datasheet (DS10693),
//! table "Flash memory programming", at x32 parallelism (2.7–3.6 V, `PSIZE = 32`, which is
//! what embassy-stm32 programs with).
//!
//! While the flash is busy the core stalls on any fetch from it, so an ECU erasing a
//! 128 KiB sector is deaf for about a second: the simulation charges these times so a virtual
//! ECU can be stalled exactly as long. These are typical, not worst-case, figures.

use core::time::Duration;

use crate::map::{LARGE_SECTOR_SIZE, MEDIUM_SECTOR_SIZE, SMALL_SECTOR_SIZE, WRITE_SIZE};

/// `t_PROG`: programming one 32-bit word (typ., x32).
pub const WORD_PROGRAM_TIME: Duration = Duration::from_micros(16);

/// `t_ERASE16KB`: erasing one 16 KiB sector (typ., x32).
pub const SMALL_SECTOR_ERASE_TIME: Duration = Duration::from_millis(250);

/// `t_ERASE64KB`: erasing the 64 KiB sector (typ., x32).
pub const MEDIUM_SECTOR_ERASE_TIME: Duration = Duration::from_millis(550);

/// `t_ERASE128KB`: erasing one 128 KiB sector (typ., x32).
pub const LARGE_SECTOR_ERASE_TIME: Duration = Duration::from_millis(1000);

/// Time to erase a sector of `size` bytes, `None` for a size the F446 has no sector of.
pub const fn sector_erase_time(size: u32) -> Option<Duration> {
    match size {
        SMALL_SECTOR_SIZE => Some(SMALL_SECTOR_ERASE_TIME),
        MEDIUM_SECTOR_SIZE => Some(MEDIUM_SECTOR_ERASE_TIME),
        LARGE_SECTOR_SIZE => Some(LARGE_SECTOR_ERASE_TIME),
        _ => None,
    }
}

/// Time to program `bytes` bytes, one word after the other (a partial word counts whole).
pub const fn program_time(bytes: usize) -> Duration {
    let words = bytes.div_ceil(WRITE_SIZE);
    // The flash is far smaller than u32::MAX words; saturate rather than wrap if misused.
    if words > u32::MAX as usize {
        return Duration::MAX;
    }
    match WORD_PROGRAM_TIME.checked_mul(words as u32) {
        Some(time) => time,
        None => Duration::MAX,
    }
}
