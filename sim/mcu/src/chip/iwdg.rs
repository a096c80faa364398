//! The independent watchdog (RM0390, section 21): LSI-clocked, a reset when it counts down
//! to zero. Its time is simulated nanoseconds, not core cycles: the LSI does not follow the
//! clock tree.

use super::rcc::LSI_HZ;
use super::{merge, Unmodelled};

/// Nanoseconds per LSI cycle, rounded: the LSI at 32 kHz.
const LSI_NS: u64 = 1_000_000_000 / LSI_HZ;

/// The IWDG.
#[derive(Clone, Debug)]
pub struct Iwdg {
    /// Write access to PR and RLR (key 0x5555).
    unlocked: bool,
    pr: u32,
    rlr: u32,
    /// The prescaler and reload in use (updated after the register update time).
    pr_active: u32,
    rlr_active: u32,
    /// Until when SR.PVU / SR.RVU read as busy (ns).
    pvu_until: u64,
    rvu_until: u64,
    /// When the counter reaches zero (ns), if started.
    expires: Option<u64>,
}

impl Default for Iwdg {
    fn default() -> Self {
        Iwdg {
            unlocked: false,
            pr: 0,
            rlr: 0xFFF,
            pr_active: 0,
            rlr_active: 0xFFF,
            pvu_until: 0,
            rvu_until: 0,
            expires: None,
        }
    }
}

impl Iwdg {
    fn divider(&self) -> u64 {
        4u64 << self.pr_active.min(6)
    }

    /// A feed (0xAAAA) loads the counter from RLR.
    fn timeout_ns(&self) -> u64 {
        (self.rlr_active as u64 + 1) * self.divider() * LSI_NS
    }

    /// When the watchdog resets the chip, if running.
    pub fn expires(&self) -> Option<u64> {
        self.expires
    }

    fn settle(&mut self, now_ns: u64) {
        if now_ns >= self.pvu_until {
            self.pr_active = self.pr;
        }
        if now_ns >= self.rvu_until {
            self.rlr_active = self.rlr;
        }
    }

    /// Reads a register.
    pub fn read(&mut self, offset: u32, now_ns: u64) -> Result<u32, Unmodelled> {
        self.settle(now_ns);
        match offset {
            0x00 => Ok(0),
            0x04 => Ok(self.pr),
            0x08 => Ok(self.rlr),
            0x0C => Ok((now_ns < self.pvu_until) as u32 | ((now_ns < self.rvu_until) as u32) << 1),
            _ => Err(Unmodelled::register(offset)),
        }
    }

    /// Writes a register. The prescaler and reload updates take five LSI cycles (RM0390
    /// 21.4.4: PVU/RVU busy meanwhile).
    pub fn write(
        &mut self,
        offset: u32,
        value: u32,
        mask: u32,
        now_ns: u64,
    ) -> Result<(), Unmodelled> {
        self.settle(now_ns);
        match offset {
            0x00 => match value & mask & 0xFFFF {
                0x5555 => self.unlocked = true,
                0xAAAA => {
                    self.unlocked = false;
                    if self.expires.is_some() {
                        self.expires = Some(now_ns + self.timeout_ns());
                    }
                }
                // The start counts down from the counter's reset value 0xFFF, not from
                // RLR (RM0390 21.3.1): until the first feed the period is the longest one
                // at the prescaler then in use.
                0xCCCC => {
                    self.unlocked = false;
                    if self.expires.is_none() {
                        self.expires = Some(now_ns + 0x1000 * self.divider() * LSI_NS);
                    }
                }
                _ => self.unlocked = false,
            },
            0x04 if self.unlocked => {
                self.pr = merge(self.pr, value, mask) & 7;
                self.pvu_until = now_ns + 5 * LSI_NS;
            }
            0x08 if self.unlocked => {
                self.rlr = merge(self.rlr, value, mask) & 0xFFF;
                self.rvu_until = now_ns + 5 * LSI_NS;
            }
            // Locked: the write is ignored, as on the chip.
            0x04 | 0x08 => {}
            _ => return Err(Unmodelled::register(offset)),
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_watchdog_expires_unless_fed_and_its_updates_take_five_lsi_cycles() {
        let mut iwdg = Iwdg::default();
        iwdg.write(0x00, 0x5555, u32::MAX, 0).unwrap();
        iwdg.write(0x04, 3, u32::MAX, 0).unwrap(); // /32
        iwdg.write(0x08, 99, u32::MAX, 0).unwrap();
        assert_eq!(iwdg.read(0x0C, 0).unwrap(), 0b11, "PVU and RVU busy");
        assert_eq!(iwdg.read(0x0C, 5 * LSI_NS).unwrap(), 0);
        iwdg.write(0x00, 0xCCCC, u32::MAX, 5 * LSI_NS).unwrap();
        assert_eq!(
            iwdg.expires(),
            Some(5 * LSI_NS + 0x1000 * 32 * LSI_NS),
            "started: from the counter's reset value 0xFFF"
        );
        let timeout = 100 * 32 * LSI_NS;
        iwdg.write(0x00, 0xAAAA, u32::MAX, 1_000_000).unwrap();
        assert_eq!(
            iwdg.expires(),
            Some(1_000_000 + timeout),
            "fed: the count restarts"
        );
        // Locked again: a write to RLR is ignored.
        iwdg.write(0x08, 5, u32::MAX, 2_000_000).unwrap();
        assert_eq!(iwdg.read(0x08, 2_000_000).unwrap(), 99);
    }
}
