//! The GPIO ports (RM0390, section 7): modes, outputs, and the input levels the vehicle
//! model drives.

use super::{merge, Unmodelled};

/// One port, A to H.
#[derive(Clone, Debug)]
pub struct Port {
    moder: u32,
    otyper: u32,
    ospeedr: u32,
    pupdr: u32,
    odr: u32,
    lckr: u32,
    afr: [u32; 2],
    /// Levels driven from outside on each pin (the vehicle model, a button), if any.
    driven: u16,
    driven_mask: u16,
}

impl Port {
    /// Port `index` (0 = A) after reset: PA13/14/15 and PB3/4 are the debug pins.
    pub fn new(index: usize) -> Self {
        let (moder, ospeedr, pupdr) = match index {
            0 => (0xA800_0000, 0x0C00_0000, 0x6400_0000),
            1 => (0x0000_0280, 0x0000_00C0, 0x0000_0100),
            _ => (0, 0, 0),
        };
        Port {
            moder,
            otyper: 0,
            ospeedr,
            pupdr,
            odr: 0,
            lckr: 0,
            afr: [0; 2],
            driven: 0,
            driven_mask: 0,
        }
    }

    /// Takes the externally driven levels of `other` (across a reset of the port).
    pub fn copy_inputs(&mut self, other: &Port) {
        self.driven = other.driven;
        self.driven_mask = other.driven_mask;
    }

    /// Pin `pin`'s mode: 0 input, 1 output, 2 alternate function, 3 analog.
    pub fn mode(&self, pin: u32) -> u32 {
        (self.moder >> (2 * pin)) & 3
    }

    /// The level an output pin drives.
    pub fn output(&self, pin: u32) -> bool {
        self.odr & (1 << pin) != 0
    }

    /// The levels driven from outside and which pins they drive (levels, mask).
    pub fn driven(&self) -> (u16, u16) {
        (self.driven, self.driven_mask)
    }

    /// Drives pin `pin` from outside (None: released, it floats to its pull).
    pub fn drive(&mut self, pin: u32, level: Option<bool>) {
        let bit = 1u16 << pin;
        match level {
            Some(high) => {
                self.driven_mask |= bit;
                if high {
                    self.driven |= bit;
                } else {
                    self.driven &= !bit;
                }
            }
            None => self.driven_mask &= !bit,
        }
    }

    fn idr(&self) -> u32 {
        let mut idr = 0;
        for pin in 0..16 {
            let level = match self.mode(pin) {
                1 => self.output(pin),
                _ if self.driven_mask & (1 << pin) != 0 => self.driven & (1 << pin) != 0,
                _ => (self.pupdr >> (2 * pin)) & 3 == 1,
            };
            idr |= (level as u32) << pin;
        }
        idr
    }

    /// Reads a register.
    pub fn read(&self, offset: u32) -> Result<u32, Unmodelled> {
        Ok(match offset {
            0x00 => self.moder,
            0x04 => self.otyper,
            0x08 => self.ospeedr,
            0x0C => self.pupdr,
            0x10 => self.idr(),
            0x14 => self.odr,
            0x18 => 0,
            0x1C => self.lckr,
            0x20 => self.afr[0],
            0x24 => self.afr[1],
            _ => return Err(Unmodelled::register(offset)),
        })
    }

    /// Writes a register.
    pub fn write(&mut self, offset: u32, value: u32, mask: u32) -> Result<(), Unmodelled> {
        match offset {
            0x00 => self.moder = merge(self.moder, value, mask),
            0x04 => self.otyper = merge(self.otyper, value, mask) & 0xFFFF,
            0x08 => self.ospeedr = merge(self.ospeedr, value, mask),
            0x0C => self.pupdr = merge(self.pupdr, value, mask),
            0x10 => {}
            0x14 => self.odr = merge(self.odr, value, mask) & 0xFFFF,
            0x18 => {
                let value = value & mask;
                self.odr = (self.odr | (value & 0xFFFF)) & !(value >> 16 & !value & 0xFFFF);
            }
            0x1C => self.lckr = merge(self.lckr, value, mask) & 0x1_FFFF,
            0x20 => self.afr[0] = merge(self.afr[0], value, mask),
            0x24 => self.afr[1] = merge(self.afr[1], value, mask),
            _ => return Err(Unmodelled::register(offset)),
        }
        Ok(())
    }
}
