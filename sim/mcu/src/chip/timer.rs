//! The general-purpose timers (RM0390, sections 18 and 19), counting up: TIM12 as
//! Embassy's time driver (overflow and compare interrupts), TIM3 for PWM (its duty read
//! by the vehicle model). Event-driven: the counter is computed from the core's cycle
//! count, and the next overflow or compare match is the next event; nothing happens per
//! tick.

use super::{merge, Unmodelled};

/// One timer.
#[derive(Clone, Debug)]
pub struct Timer {
    /// Channels (2 for TIM12, 4 for TIM3).
    channels: usize,
    /// A 32-bit counter (TIM2, TIM5) rather than 16-bit.
    wide: bool,
    cr1: u32,
    cr2: u32,
    smcr: u32,
    dier: u32,
    sr: u32,
    ccmr: [u32; 2],
    ccer: u32,
    psc: u32,
    /// The prescaler in use (PSC is loaded at an update event).
    psc_active: u32,
    arr: u32,
    /// ARR in use (ARR is loaded at once unless ARPE buffers it).
    arr_active: u32,
    ccr: [u32; 4],
    /// The counter's value at `origin` (a tick boundary).
    count: u32,
    /// The core cycle at which the counter held `count`.
    origin: u64,
    /// Core cycles per timer clock cycle (the timer clock's divisor from HCLK).
    clock_divisor: u64,
}

impl Timer {
    /// A timer after reset.
    pub fn new(channels: usize, wide: bool) -> Self {
        Timer {
            channels,
            wide,
            cr1: 0,
            cr2: 0,
            smcr: 0,
            dier: 0,
            sr: 0,
            ccmr: [0; 2],
            ccer: 0,
            psc: 0,
            psc_active: 0,
            arr: if wide { u32::MAX } else { 0xFFFF },
            arr_active: if wide { u32::MAX } else { 0xFFFF },
            ccr: [0; 4],
            count: 0,
            origin: 0,
            clock_divisor: 1,
        }
    }

    fn running(&self) -> bool {
        self.cr1 & 1 != 0
    }

    /// Core cycles per counter tick.
    fn tick(&self) -> u64 {
        self.clock_divisor * (self.psc_active as u64 + 1)
    }

    fn period(&self) -> u64 {
        self.arr_active as u64 + 1
    }

    /// Sets how many core cycles one timer clock cycle lasts (from the clock tree).
    pub fn set_clock_divisor(&mut self, divisor: u64, now: u64) {
        self.sync(now);
        self.clock_divisor = divisor.max(1);
    }

    /// Brings the counter and the flags up to `now`.
    pub fn sync(&mut self, now: u64) {
        if !self.running() || now <= self.origin {
            if !self.running() {
                self.origin = now;
            }
            return;
        }
        let tick = self.tick();
        let mut ticks = (now - self.origin) / tick;
        while ticks > 0 {
            let period = self.period();
            let start = self.count as u64;
            let to_overflow = period - start.min(period - 1);
            let step = ticks.min(to_overflow);
            // Compare matches: the counter enters CCRx during these ticks.
            let end = start + step;
            for ch in 0..self.channels {
                let ccr = self.ccr[ch] as u64;
                let entered = if end >= period {
                    ccr > start || ccr == 0
                } else {
                    ccr > start && ccr <= end
                };
                if entered && ccr < period {
                    self.sr |= 1 << (ch + 1);
                }
            }
            self.origin += step * tick;
            ticks -= step;
            if end >= period {
                self.count = 0;
                self.update_event(false);
                if self.cr1 & (1 << 3) != 0 {
                    // One-pulse mode stops at the update.
                    self.cr1 &= !1;
                    return;
                }
            } else {
                self.count = end as u32;
            }
        }
    }

    /// An update event: the preloaded registers take effect; UIF is set unless UDIS, or
    /// when software asked (UG) with URS set.
    fn update_event(&mut self, software: bool) {
        if self.cr1 & (1 << 1) != 0 {
            return;
        }
        self.psc_active = self.psc;
        self.arr_active = self.arr;
        if !(software && self.cr1 & (1 << 2) != 0) {
            self.sr |= 1;
        }
    }

    /// The next cycle at which a flag that raises an interrupt gets set, if any.
    pub fn next_event(&self) -> Option<u64> {
        if !self.running() {
            return None;
        }
        let tick = self.tick();
        let period = self.period();
        let start = self.count as u64;
        let mut best: Option<u64> = None;
        let mut consider = |ticks: u64| {
            let at = self.origin + ticks * tick;
            best = Some(best.map_or(at, |b: u64| b.min(at)));
        };
        if self.dier & 1 != 0 {
            consider(period - start);
        }
        for ch in 0..self.channels {
            if self.dier & (1 << (ch + 1)) != 0 {
                let ccr = self.ccr[ch] as u64;
                if ccr < period {
                    consider(if ccr > start {
                        ccr - start
                    } else {
                        period - start + ccr
                    });
                }
            }
        }
        best
    }

    /// Whether the timer's interrupt line is high.
    pub fn irq(&self) -> bool {
        self.sr & self.dier & 0x1F != 0
    }

    /// A channel's PWM duty (0–1), if it is an enabled PWM output (mode 1 or 2).
    pub fn pwm_duty(&self, channel: usize) -> Option<f32> {
        if channel >= self.channels || self.ccer & (1 << (4 * channel)) == 0 {
            return None;
        }
        let ccmr = self.ccmr[channel / 2] >> (8 * (channel % 2));
        let mode = (ccmr >> 4) & 7;
        let duty = (self.ccr[channel] as f32 / (self.arr_active as f32 + 1.0)).min(1.0);
        match mode {
            6 => Some(duty),
            7 => Some(1.0 - duty),
            _ => None,
        }
    }

    /// Reads a register.
    pub fn read(&mut self, offset: u32, now: u64) -> Result<u32, Unmodelled> {
        self.sync(now);
        Ok(match offset {
            0x00 => self.cr1,
            0x04 => self.cr2,
            0x08 => self.smcr,
            0x0C => self.dier,
            0x10 => self.sr,
            0x14 => 0,
            0x18 => self.ccmr[0],
            0x1C if self.channels > 2 => self.ccmr[1],
            0x20 => self.ccer,
            0x24 => self.count,
            0x28 => self.psc,
            0x2C => self.arr,
            0x34..=0x40 if (((offset - 0x34) / 4) as usize) < self.channels => {
                self.ccr[((offset - 0x34) / 4) as usize]
            }
            _ => return Err(Unmodelled::register(offset)),
        })
    }

    /// Writes a register.
    pub fn write(
        &mut self,
        offset: u32,
        value: u32,
        mask: u32,
        now: u64,
    ) -> Result<(), Unmodelled> {
        self.sync(now);
        let counter_mask = if self.wide { u32::MAX } else { 0xFFFF };
        match offset {
            0x00 => {
                let cr1 = merge(self.cr1, value, mask) & 0x3FF;
                if cr1 & (0b111 << 4) != 0 {
                    return Err(Unmodelled::feature(
                        "counting down or centre-aligned (CR1.DIR/CMS)",
                    ));
                }
                if cr1 & 1 != 0 && self.cr1 & 1 == 0 {
                    self.origin = now;
                }
                self.cr1 = cr1;
            }
            0x04 => self.cr2 = merge(self.cr2, value, mask),
            0x08 => {
                let smcr = merge(self.smcr, value, mask);
                if smcr & 7 != 0 {
                    return Err(Unmodelled::feature("slave mode (SMCR.SMS)"));
                }
                self.smcr = smcr;
            }
            0x0C => {
                let dier = merge(self.dier, value, mask);
                if dier & 0x5F00 != 0 {
                    return Err(Unmodelled::feature("DMA requests (DIER.*DE)"));
                }
                self.dier = dier;
            }
            // rc_w0: writing 0 clears a flag, 1 leaves it.
            0x10 => self.sr &= value | !mask,
            0x14 => {
                if value & 1 != 0 {
                    self.count = 0;
                    self.origin = now;
                    let udis = self.cr1 & (1 << 1);
                    self.cr1 &= !(1 << 1);
                    self.update_event(true);
                    self.cr1 |= udis;
                }
                self.sr |= value & mask & 0x1E & ((1 << (self.channels + 1)) - 1);
            }
            0x18 => self.ccmr[0] = merge(self.ccmr[0], value, mask),
            0x1C if self.channels > 2 => self.ccmr[1] = merge(self.ccmr[1], value, mask),
            0x20 => self.ccer = merge(self.ccer, value, mask),
            0x24 => {
                self.count = merge(self.count, value, mask) & counter_mask;
                self.origin = now;
            }
            0x28 => self.psc = merge(self.psc, value, mask) & 0xFFFF,
            0x2C => {
                self.arr = merge(self.arr, value, mask) & counter_mask;
                if self.cr1 & (1 << 7) == 0 {
                    self.arr_active = self.arr;
                }
            }
            0x34..=0x40 if (((offset - 0x34) / 4) as usize) < self.channels => {
                let ch = ((offset - 0x34) / 4) as usize;
                self.ccr[ch] = merge(self.ccr[ch], value, mask) & counter_mask;
            }
            _ => return Err(Unmodelled::register(offset)),
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_counter_runs_from_the_cycle_count_and_flags_overflow_and_compare() {
        let mut t = Timer::new(2, false);
        t.set_clock_divisor(2, 0);
        t.write(0x28, 9, u32::MAX, 0).unwrap(); // PSC 9: one tick per 20 cycles
        t.write(0x2C, 99, u32::MAX, 0).unwrap(); // ARR 99
        t.write(0x34, 50, u32::MAX, 0).unwrap(); // CCR1
        t.write(0x0C, 0b11, u32::MAX, 0).unwrap(); // UIE, CC1IE
        t.write(0x14, 1, u32::MAX, 0).unwrap(); // UG loads PSC
        t.write(0x10, 0, u32::MAX, 0).unwrap();
        t.write(0x00, 1, u32::MAX, 0).unwrap();
        assert_eq!(t.next_event(), Some(50 * 20));
        assert_eq!(t.read(0x24, 40 * 20 + 19).unwrap(), 40);
        assert!(!t.irq());
        t.sync(50 * 20);
        assert_eq!(t.read(0x10, 50 * 20).unwrap(), 0b10, "CC1IF at the match");
        assert!(t.irq());
        t.write(0x10, 0, u32::MAX, 50 * 20).unwrap();
        assert_eq!(t.next_event(), Some(100 * 20), "the overflow next");
        // CCR2 is 0: the counter entering 0 at the overflow is a match too.
        assert_eq!(
            t.read(0x10, 100 * 20).unwrap(),
            0b101,
            "UIF and CC2IF at the overflow"
        );
        assert_eq!(t.read(0x24, 100 * 20).unwrap(), 0);
        // A long sleep: several periods pass, both flags set, the count wraps.
        assert_eq!(t.read(0x24, 1000 * 20 + 7 * 20).unwrap(), 7);
        assert_eq!(t.read(0x10, 1000 * 20 + 7 * 20).unwrap(), 0b111);
    }

    #[test]
    fn pwm_duty_follows_the_compare_register() {
        let mut t = Timer::new(4, false);
        t.write(0x2C, 999, u32::MAX, 0).unwrap();
        t.write(0x1C, 0x6 << 4, u32::MAX, 0).unwrap(); // CH3 PWM mode 1
        t.write(0x3C, 250, u32::MAX, 0).unwrap();
        assert_eq!(t.pwm_duty(2), None, "output not enabled yet");
        t.write(0x20, 1 << 8, u32::MAX, 0).unwrap();
        assert_eq!(t.pwm_duty(2), Some(0.25));
    }
}
