//! ADC1 (RM0390, section 13): single software-started regular conversions, as the images
//! use it: SWSTART sets STRT at once and EOC when the conversion ends (the driver waits for
//! both, in that order), the result from the voltage the vehicle model puts on the channel.

use super::{merge, Unmodelled};

/// The analog supply the codes are relative to (a Nucleo's 3.3 V).
pub const VDDA: f32 = 3.3;
/// The internal reference voltage (datasheet: 1.21 V typical).
const VREFINT: f32 = 1.21;
/// The temperature sensor at 25 °C (datasheet: V25 = 0.76 V).
const V25: f32 = 0.76;

/// ADC1 and the ADC common registers.
#[derive(Clone, Debug)]
pub struct Adc {
    sr: u32,
    cr1: u32,
    cr2: u32,
    smpr: [u32; 2],
    jofr: [u32; 4],
    htr: u32,
    ltr: u32,
    sqr: [u32; 3],
    jsqr: u32,
    dr: u32,
    ccr: u32,
    /// When the conversion in progress ends (core cycle), and its result.
    converting: Option<(u64, u32)>,
    /// The volts on channels 0–15 (the board's analog pins).
    inputs: [f32; 16],
}

impl Default for Adc {
    fn default() -> Self {
        Adc {
            sr: 0,
            cr1: 0,
            cr2: 0,
            smpr: [0; 2],
            jofr: [0; 4],
            htr: 0xFFF,
            ltr: 0,
            sqr: [0; 3],
            jsqr: 0,
            dr: 0,
            ccr: 0,
            converting: None,
            inputs: [0.0; 16],
        }
    }
}

/// Sampling times in ADC clock cycles by SMPx.
const SAMPLE_CYCLES: [u64; 8] = [3, 15, 28, 56, 84, 112, 144, 480];

impl Adc {
    /// Puts `volts` on channel `channel` (0–15).
    pub fn set_input(&mut self, channel: usize, volts: f32) {
        if let Some(input) = self.inputs.get_mut(channel) {
            *input = volts;
        }
    }

    /// Keeps the ADC's state across resets of other parts (the inputs are the world's).
    pub fn inputs(&self) -> [f32; 16] {
        self.inputs
    }

    fn finish(&mut self, now: u64) {
        if let Some((at, code)) = self.converting {
            if now >= at {
                if self.sr & 0b10 != 0 {
                    self.sr |= 1 << 5;
                }
                self.dr = if self.cr2 & (1 << 11) != 0 {
                    code << 4
                } else {
                    code
                };
                self.sr |= 0b10;
                self.converting = None;
            }
        }
    }

    /// When the conversion in progress ends, if one is.
    pub fn next_event(&self) -> Option<u64> {
        self.converting.map(|(at, _)| at)
    }

    /// Whether the ADC interrupt line is high (EOCIE with EOC, OVRIE with OVR).
    pub fn irq(&self) -> bool {
        (self.cr1 & (1 << 5) != 0 && self.sr & 0b10 != 0)
            || (self.cr1 & (1 << 26) != 0 && self.sr & (1 << 5) != 0)
    }

    /// Reads a register of ADC1 (offsets 0x00–0x4C) or the common block (0x300–0x308).
    pub fn read(&mut self, offset: u32, now: u64) -> Result<u32, Unmodelled> {
        self.finish(now);
        Ok(match offset {
            0x00 => self.sr,
            0x04 => self.cr1,
            0x08 => self.cr2,
            0x0C => self.smpr[0],
            0x10 => self.smpr[1],
            0x14..=0x20 => self.jofr[((offset - 0x14) / 4) as usize],
            0x24 => self.htr,
            0x28 => self.ltr,
            0x2C..=0x34 => self.sqr[((offset - 0x2C) / 4) as usize],
            0x38 => self.jsqr,
            0x4C => {
                // Reading DR clears EOC.
                self.sr &= !0b10;
                self.dr
            }
            0x300 => self.sr,
            0x304 => self.ccr,
            _ => return Err(Unmodelled::register(offset)),
        })
    }

    /// Writes a register; `adc_clock_divisor` is core cycles per ADC clock cycle.
    pub fn write(
        &mut self,
        offset: u32,
        value: u32,
        mask: u32,
        now: u64,
        pclk2_divisor: u64,
    ) -> Result<(), Unmodelled> {
        self.finish(now);
        match offset {
            0x00 => self.sr &= value | !mask | !0x3F,
            0x04 => {
                let cr1 = merge(self.cr1, value, mask);
                if cr1 & (1 << 8) != 0 {
                    return Err(Unmodelled::feature("scan mode (CR1.SCAN)"));
                }
                self.cr1 = cr1;
            }
            0x08 => {
                let cr2 = merge(self.cr2, value, mask);
                if cr2 & (0b10 | 1 << 8) != 0 {
                    return Err(Unmodelled::feature(
                        "continuous or DMA conversions (CR2.CONT/DMA)",
                    ));
                }
                if cr2 & (1 << 22) != 0 {
                    return Err(Unmodelled::feature("injected conversions (CR2.JSWSTART)"));
                }
                self.cr2 = cr2 & !(1 << 30);
                if cr2 & (1 << 30) != 0 && cr2 & 1 != 0 {
                    self.start(now, pclk2_divisor)?;
                }
            }
            0x0C => self.smpr[0] = merge(self.smpr[0], value, mask),
            0x10 => self.smpr[1] = merge(self.smpr[1], value, mask),
            0x14..=0x20 => {
                let i = ((offset - 0x14) / 4) as usize;
                self.jofr[i] = merge(self.jofr[i], value, mask) & 0xFFF;
            }
            0x24 => self.htr = merge(self.htr, value, mask) & 0xFFF,
            0x28 => self.ltr = merge(self.ltr, value, mask) & 0xFFF,
            0x2C..=0x34 => {
                let i = ((offset - 0x2C) / 4) as usize;
                self.sqr[i] = merge(self.sqr[i], value, mask);
            }
            0x38 => self.jsqr = merge(self.jsqr, value, mask),
            0x304 => self.ccr = merge(self.ccr, value, mask),
            _ => return Err(Unmodelled::register(offset)),
        }
        Ok(())
    }

    fn start(&mut self, now: u64, pclk2_divisor: u64) -> Result<(), Unmodelled> {
        if self.sqr[0] >> 20 & 0xF != 0 {
            return Err(Unmodelled::feature(
                "a regular sequence longer than one (SQR1.L)",
            ));
        }
        let channel = (self.sqr[2] & 0x1F) as usize;
        let volts = match channel {
            0..=15 => self.inputs[channel],
            16 | 18 if self.ccr & (1 << 23) != 0 => V25,
            17 if self.ccr & (1 << 23) != 0 => VREFINT,
            _ => {
                return Err(Unmodelled::feature(
                    "an internal channel with TSVREFE clear",
                ))
            }
        };
        let code = ((volts / VDDA * 4096.0).round() as i64).clamp(0, 4095) as u32;
        let code = match self.cr1 >> 24 & 3 {
            0 => code,
            1 => code >> 2,
            2 => code >> 4,
            _ => code >> 6,
        };
        let smp = if channel < 10 {
            self.smpr[1] >> (3 * channel)
        } else {
            self.smpr[0] >> (3 * (channel - 10))
        } & 7;
        let prescaler = 2 * ((self.ccr >> 16 & 3) as u64 + 1);
        let adc_cycles = SAMPLE_CYCLES[smp as usize] + 12;
        self.sr |= 1 << 4;
        self.converting = Some((now + adc_cycles * prescaler * pclk2_divisor, code));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_conversion_sets_strt_at_once_and_eoc_when_it_ends() {
        let mut adc = Adc::default();
        adc.set_input(4, 1.65);
        adc.write(0x34, 4, u32::MAX, 0, 2).unwrap(); // SQR3: channel 4
        adc.write(0x08, 1, u32::MAX, 0, 2).unwrap(); // ADON
        adc.write(0x08, 1 | 1 << 30, u32::MAX, 100, 2).unwrap();
        assert_eq!(adc.read(0x00, 100).unwrap(), 1 << 4, "STRT, not EOC yet");
        let end = adc.next_event().unwrap();
        assert_eq!(
            end,
            100 + 15 * 2 * 2,
            "3 + 12 ADC clocks at /2 of PCLK2, PCLK2 at HCLK/2"
        );
        assert_eq!(adc.read(0x00, end).unwrap(), 1 << 4 | 0b10);
        assert_eq!(adc.read(0x4C, end).unwrap(), 2048, "half of VDDA");
        assert_eq!(
            adc.read(0x00, end).unwrap() & 0b10,
            0,
            "reading DR clears EOC"
        );
    }
}
