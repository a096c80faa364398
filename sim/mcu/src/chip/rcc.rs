//! RCC and PWR (RM0390, sections 6 and 5): the clock tree decides the core's and the
//! buses' rates; the oscillators, PLLs and the over-drive switch report ready at once.

use super::{merge, Unmodelled};

/// The high-speed internal oscillator.
pub const HSI_HZ: u64 = 16_000_000;
/// The external clock on a Nucleo-F446RE: the ST-LINK's 8 MHz MCO (bypass).
pub const HSE_HZ: u64 = 8_000_000;
/// The low-speed internal oscillator (datasheet: 17–47 kHz, typically 32 kHz).
pub const LSI_HZ: u64 = 32_000;

/// The clock rates the RCC's registers select.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Clocks {
    /// SYSCLK and HCLK's source.
    pub sysclk: u64,
    /// The core's and AHB's clock.
    pub hclk: u64,
    /// APB1.
    pub pclk1: u64,
    /// APB2.
    pub pclk2: u64,
}

impl Clocks {
    /// The timers' clock on APB1 (twice PCLK1 when APB1 is divided, RM0390 6.2).
    pub fn apb1_timers(&self) -> u64 {
        if self.pclk1 == self.hclk {
            self.pclk1
        } else {
            2 * self.pclk1
        }
    }

    /// The timers' clock on APB2.
    pub fn apb2_timers(&self) -> u64 {
        if self.pclk2 == self.hclk {
            self.pclk2
        } else {
            2 * self.pclk2
        }
    }
}

/// Reset causes kept in RCC_CSR.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ResetCause {
    /// Power-on (POR, PIN, BOR flags).
    PowerOn,
    /// AIRCR.SYSRESETREQ (SFT, PIN).
    Software,
    /// The independent watchdog (IWDG, PIN).
    Watchdog,
}

/// The RCC's registers.
#[derive(Clone, Debug)]
pub struct Rcc {
    cr: u32,
    pllcfgr: u32,
    cfgr: u32,
    cir: u32,
    rstr: [u32; 5],
    enr: [u32; 5],
    lpenr: [u32; 5],
    bdcr: u32,
    csr: u32,
    sscgr: u32,
    plli2scfgr: u32,
    pllsaicfgr: u32,
    dckcfgr: u32,
    ckgatenr: u32,
    dckcfgr2: u32,
    /// PWR_CR and PWR_CSR.
    pwr_cr: u32,
    pwr_csr: u32,
}

/// Bus enable registers by their index in `enr`: AHB1, AHB2, AHB3, APB1, APB2.
pub const AHB1: usize = 0;
/// APB1's enable register.
pub const APB1: usize = 3;
/// APB2's enable register.
pub const APB2: usize = 4;

impl Rcc {
    /// The registers after a reset of the given cause. RCC_CSR's reset flags survive a
    /// system reset (RM0390 6.3.21) and gain the new cause's.
    pub fn new(cause: ResetCause, previous: Option<&Rcc>) -> Self {
        let flags = match cause {
            ResetCause::PowerOn => 0x0E00_0000,
            ResetCause::Software => 0x1400_0000,
            ResetCause::Watchdog => 0x2400_0000,
        };
        let kept = previous.map_or(0, |p| p.csr & 0xFE00_0000);
        Rcc {
            cr: 0x0000_0083,
            pllcfgr: 0x2400_3010,
            cfgr: 0,
            cir: 0,
            rstr: [0; 5],
            enr: [0x0010_0000, 0, 0, 0, 0],
            lpenr: [
                0x6065_50FF,
                0x0000_00F1,
                0x0000_0003,
                0x3FFF_CDFF,
                0x00C7_7F33,
            ],
            bdcr: 0,
            csr: kept | flags,
            sscgr: 0,
            plli2scfgr: 0x2400_3010,
            pllsaicfgr: 0x0400_3010,
            dckcfgr: 0,
            ckgatenr: 0xFFFF_FFFF,
            dckcfgr2: 0,
            pwr_cr: 0x0000_C000,
            pwr_csr: 0,
        }
    }

    /// Whether a peripheral's clock is enabled: bus register index and bit.
    pub fn enabled(&self, bus: usize, bit: u32) -> bool {
        self.enr[bus] & (1 << bit) != 0
    }

    /// The clock rates now.
    pub fn clocks(&self) -> Clocks {
        let pll_in = if self.pllcfgr & (1 << 22) != 0 {
            HSE_HZ
        } else {
            HSI_HZ
        };
        let m = (self.pllcfgr & 0x3F).max(2) as u64;
        let n = ((self.pllcfgr >> 6) & 0x1FF).max(2) as u64;
        let p = 2 * (((self.pllcfgr >> 16) & 3) as u64 + 1);
        let r = ((self.pllcfgr >> 28) & 7).max(2) as u64;
        let vco = pll_in / m * n;
        let sysclk = match self.cfgr >> 2 & 3 {
            0 => HSI_HZ,
            1 => HSE_HZ,
            2 => vco / p,
            _ => vco / r,
        };
        let hpre = self.cfgr >> 4 & 0xF;
        let hclk = if hpre < 8 {
            sysclk
        } else {
            sysclk >> [1, 2, 3, 4, 6, 7, 8, 9][(hpre - 8) as usize]
        };
        let apb = |ppre: u32| if ppre < 4 { hclk } else { hclk >> (ppre - 3) };
        Clocks {
            sysclk,
            hclk,
            pclk1: apb(self.cfgr >> 10 & 7),
            pclk2: apb(self.cfgr >> 13 & 7),
        }
    }

    /// Reads an RCC register.
    pub fn read(&self, offset: u32) -> Result<u32, Unmodelled> {
        Ok(match offset {
            0x00 => self.cr,
            0x04 => self.pllcfgr,
            0x08 => self.cfgr,
            0x0C => self.cir,
            0x10 | 0x14 | 0x18 => self.rstr[((offset - 0x10) / 4) as usize],
            0x20 | 0x24 => self.rstr[((offset - 0x20) / 4 + 3) as usize],
            0x30 | 0x34 | 0x38 => self.enr[((offset - 0x30) / 4) as usize],
            0x40 | 0x44 => self.enr[((offset - 0x40) / 4 + 3) as usize],
            0x50 | 0x54 | 0x58 => self.lpenr[((offset - 0x50) / 4) as usize],
            0x60 | 0x64 => self.lpenr[((offset - 0x60) / 4 + 3) as usize],
            0x70 => self.bdcr,
            0x74 => self.csr,
            0x80 => self.sscgr,
            0x84 => self.plli2scfgr,
            0x88 => self.pllsaicfgr,
            0x8C => self.dckcfgr,
            0x90 => self.ckgatenr,
            0x94 => self.dckcfgr2,
            _ => return Err(Unmodelled::register(offset)),
        })
    }

    /// Writes an RCC register. Returns the bus and bits of peripherals newly put in reset
    /// (to be reset by the caller).
    pub fn write(
        &mut self,
        offset: u32,
        value: u32,
        mask: u32,
    ) -> Result<Option<(usize, u32)>, Unmodelled> {
        match offset {
            0x00 => {
                // The writable bits: HSION, HSITRIM, HSEON, HSEBYP, CSSON and the PLLs' ON.
                let cr = merge(self.cr, value, mask) & 0x150D_00F9;
                // Every oscillator and PLL is ready as soon as it is on (each ready bit is
                // the bit above its ON bit).
                let ready = (cr & (1 | 1 << 16 | 1 << 24 | 1 << 26 | 1 << 28)) << 1;
                self.cr = cr | ready;
            }
            0x04 => self.pllcfgr = merge(self.pllcfgr, value, mask) & 0x7F43_7FFF,
            0x08 => {
                let cfgr = merge(self.cfgr, value, mask) & !0xC;
                let sw = cfgr & 3;
                let ready = match sw {
                    0 => self.cr & 2 != 0,
                    1 => self.cr & (1 << 17) != 0,
                    _ => self.cr & (1 << 25) != 0,
                };
                let sws = if ready { sw } else { self.cfgr >> 2 & 3 };
                self.cfgr = cfgr | sws << 2;
            }
            0x0C => self.cir = merge(self.cir, value, mask) & 0x0000_7F00,
            0x10 | 0x14 | 0x18 | 0x20 | 0x24 => {
                let index = if offset < 0x20 {
                    (offset - 0x10) / 4
                } else {
                    (offset - 0x20) / 4 + 3
                } as usize;
                let old = self.rstr[index];
                self.rstr[index] = merge(old, value, mask);
                let entered = self.rstr[index] & !old;
                if entered != 0 {
                    return Ok(Some((index, entered)));
                }
            }
            0x30 | 0x34 | 0x38 => {
                let i = ((offset - 0x30) / 4) as usize;
                self.enr[i] = merge(self.enr[i], value, mask);
            }
            0x40 | 0x44 => {
                let i = ((offset - 0x40) / 4 + 3) as usize;
                self.enr[i] = merge(self.enr[i], value, mask);
            }
            0x50 | 0x54 | 0x58 => {
                let i = ((offset - 0x50) / 4) as usize;
                self.lpenr[i] = merge(self.lpenr[i], value, mask);
            }
            0x60 | 0x64 => {
                let i = ((offset - 0x60) / 4 + 3) as usize;
                self.lpenr[i] = merge(self.lpenr[i], value, mask);
            }
            0x70 => {
                let bdcr = merge(self.bdcr, value, mask) & 0x0001_830D;
                self.bdcr = bdcr | (bdcr & 1) << 1;
            }
            0x74 => {
                let value = merge(self.csr, value, mask);
                let mut csr = (self.csr & 0xFE00_0000) | (value & 1) | (value & 1) << 1;
                if value & (1 << 24) != 0 {
                    csr &= 0x00FF_FFFF;
                }
                self.csr = csr;
            }
            0x80 => self.sscgr = merge(self.sscgr, value, mask),
            0x84 => self.plli2scfgr = merge(self.plli2scfgr, value, mask),
            0x88 => self.pllsaicfgr = merge(self.pllsaicfgr, value, mask),
            0x8C => self.dckcfgr = merge(self.dckcfgr, value, mask),
            0x90 => self.ckgatenr = merge(self.ckgatenr, value, mask),
            0x94 => self.dckcfgr2 = merge(self.dckcfgr2, value, mask),
            _ => return Err(Unmodelled::register(offset)),
        }
        Ok(None)
    }

    /// Reads a PWR register.
    pub fn pwr_read(&self, offset: u32) -> Result<u32, Unmodelled> {
        match offset {
            0x00 => Ok(self.pwr_cr),
            0x04 => Ok(self.pwr_csr),
            _ => Err(Unmodelled::register(offset)),
        }
    }

    /// Writes a PWR register: over-drive and its switch report ready at once, and the
    /// voltage scaling is ready once the PLL runs.
    pub fn pwr_write(&mut self, offset: u32, value: u32, mask: u32) -> Result<(), Unmodelled> {
        match offset {
            0x00 => {
                self.pwr_cr = merge(self.pwr_cr, value, mask) & 0x000F_CFFF;
                let od = self.pwr_cr & (1 << 16);
                let odsw = self.pwr_cr & (1 << 17);
                let vos = if self.cr & (1 << 25) != 0 { 1 << 14 } else { 0 };
                self.pwr_csr = (self.pwr_csr & !0x0003_4000) | od | odsw | vos;
            }
            0x04 => {
                // Only EWUP and BRE are writable; the rest are status bits (CSR's
                // write-to-clear bits are in PWR_CR: CWUF, CSBF).
                self.pwr_csr = (self.pwr_csr & !0x0000_0300)
                    | (merge(self.pwr_csr, value, mask) & 0x0000_0300);
            }
            _ => return Err(Unmodelled::register(offset)),
        }
        // VOSRDY follows the PLL.
        if self.cr & (1 << 25) != 0 {
            self.pwr_csr |= 1 << 14;
        }
        Ok(())
    }

    /// Called after an RCC write: VOSRDY follows the PLL.
    pub fn settle(&mut self) {
        if self.cr & (1 << 25) != 0 {
            self.pwr_csr |= 1 << 14;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_firmwares_clock_tree_gives_168_mhz_and_its_bus_rates() {
        let mut rcc = Rcc::new(ResetCause::PowerOn, None);
        assert_eq!(rcc.clocks().hclk, HSI_HZ);
        // HSE bypass on, PLL: M 4, N 168, P 2 from HSE; APB1 /4, APB2 /2; PLL on; SW = PLL.
        rcc.write(0x00, 1 << 16 | 1 << 18 | 1, u32::MAX).unwrap();
        assert_ne!(rcc.read(0x00).unwrap() & (1 << 17), 0, "HSERDY");
        rcc.write(0x04, 4 | 168 << 6 | 1 << 22 | 7 << 24 | 2 << 28, u32::MAX)
            .unwrap();
        rcc.write(0x00, 1 << 24 | 1 << 16 | 1 << 18 | 1, u32::MAX)
            .unwrap();
        rcc.write(0x08, 0b101 << 10 | 0b100 << 13, u32::MAX)
            .unwrap();
        rcc.write(0x08, 0b101 << 10 | 0b100 << 13 | 2, u32::MAX)
            .unwrap();
        assert_eq!(
            rcc.read(0x08).unwrap() >> 2 & 3,
            2,
            "SWS follows SW once the PLL is ready"
        );
        let clocks = rcc.clocks();
        assert_eq!(
            (clocks.hclk, clocks.pclk1, clocks.pclk2),
            (168_000_000, 42_000_000, 84_000_000)
        );
        assert_eq!(clocks.apb1_timers(), 84_000_000);
    }

    #[test]
    fn over_drive_reports_ready_and_reset_flags_accumulate_until_cleared() {
        let mut rcc = Rcc::new(ResetCause::PowerOn, None);
        rcc.pwr_write(0x00, 1 << 16, 1 << 16).unwrap();
        rcc.pwr_write(0x00, 3 << 16, 3 << 16).unwrap();
        assert_eq!(
            rcc.pwr_read(0x04).unwrap() & (3 << 16),
            3 << 16,
            "ODRDY and ODSWRDY"
        );
        let after = Rcc::new(ResetCause::Watchdog, Some(&rcc));
        assert_eq!(
            after.read(0x74).unwrap() >> 24,
            0x2E,
            "POR, PIN, BOR kept; IWDG added"
        );
        let mut cleared = after.clone();
        cleared.write(0x74, 1 << 24, u32::MAX).unwrap();
        assert_eq!(cleared.read(0x74).unwrap() >> 24, 0);
    }
}
