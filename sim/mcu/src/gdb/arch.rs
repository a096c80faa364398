//! The Cortex-M4F as GDB sees it through the debug port: the core registers (the
//! `org.gnu.gdb.arm.m-profile` feature), the FPU (`org.gnu.gdb.arm.vfp`: d0–d15, which GDB
//! shows as s0–s31 too, and FPSCR), the two stack pointers (`org.gnu.gdb.arm.m-system`,
//! which lets GDB unwind through exception frames) and the special registers; and the
//! STM32F446's memory map, whose flash regions make GDB use hardware breakpoints there,
//! as it does with a probe.

use core::num::NonZeroUsize;

use gdbstub::arch::{Arch, RegId, Registers};

/// The registers in the order of [`TARGET_XML`] (GDB's `g` packet).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct CortexM4fRegisters {
    /// r0–r12, SP, LR, PC.
    pub r: [u32; 16],
    /// xPSR.
    pub xpsr: u32,
    /// s0–s31 (d0–d15 in pairs, low word first).
    pub s: [u32; 32],
    /// FPSCR.
    pub fpscr: u32,
    /// MSP, PSP, PRIMASK, BASEPRI, FAULTMASK, CONTROL.
    pub special: [u32; 6],
}

/// The special registers' MRS numbers, in [`CortexM4fRegisters::special`]'s order.
pub const SPECIAL_SYSM: [u8; 6] = [8, 9, 16, 17, 19, 20];

/// Bytes in the `g` packet: 17 words, 16 doublewords, 7 words.
const G_BYTES: usize = 17 * 4 + 16 * 8 + 7 * 4;

impl Registers for CortexM4fRegisters {
    type ProgramCounter = u32;

    fn pc(&self) -> u32 {
        self.r[15]
    }

    fn gdb_serialize(&self, mut write_byte: impl FnMut(Option<u8>)) {
        let mut word = |w: u32| {
            w.to_le_bytes()
                .into_iter()
                .for_each(|b| write_byte(Some(b)))
        };
        self.r.iter().for_each(|&r| word(r));
        word(self.xpsr);
        self.s.iter().for_each(|&s| word(s));
        word(self.fpscr);
        self.special.iter().for_each(|&s| word(s));
    }

    fn gdb_deserialize(&mut self, bytes: &[u8]) -> Result<(), ()> {
        if bytes.len() != G_BYTES {
            return Err(());
        }
        let mut words = bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]));
        let mut next = || words.next().ok_or(());
        for r in &mut self.r {
            *r = next()?;
        }
        self.xpsr = next()?;
        for s in &mut self.s {
            *s = next()?;
        }
        self.fpscr = next()?;
        for s in &mut self.special {
            *s = next()?;
        }
        Ok(())
    }
}

/// One register by its number in [`TARGET_XML`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CortexM4fRegId {
    /// r0–r15.
    Core(u8),
    /// xPSR.
    Xpsr,
    /// d0–d15.
    Double(u8),
    /// FPSCR.
    Fpscr,
    /// MSP, PSP, PRIMASK, BASEPRI, FAULTMASK, CONTROL (index into SPECIAL_SYSM).
    Special(u8),
}

impl RegId for CortexM4fRegId {
    fn from_raw_id(id: usize) -> Option<(Self, Option<NonZeroUsize>)> {
        let (reg, size) = match id {
            0..=15 => (CortexM4fRegId::Core(id as u8), 4),
            16 => (CortexM4fRegId::Xpsr, 4),
            17..=32 => (CortexM4fRegId::Double((id - 17) as u8), 8),
            33 => (CortexM4fRegId::Fpscr, 4),
            34..=39 => (CortexM4fRegId::Special((id - 34) as u8), 4),
            _ => return None,
        };
        Some((reg, NonZeroUsize::new(size)))
    }
}

/// The Cortex-M4F of the STM32F446.
pub enum CortexM4f {}

impl Arch for CortexM4f {
    type Usize = u32;
    type Registers = CortexM4fRegisters;
    type RegId = CortexM4fRegId;
    // Thumb breakpoints: 2 (16-bit) or 3/4 (32-bit instruction).
    type BreakpointKind = usize;

    fn target_description_xml() -> Option<&'static str> {
        Some(TARGET_XML)
    }
}

/// The target description GDB reads (`qXfer:features:read:target.xml`).
pub const TARGET_XML: &str = r#"<?xml version="1.0"?>
<!DOCTYPE target SYSTEM "gdb-target.dtd">
<target version="1.0">
  <architecture>armv7e-m</architecture>
  <feature name="org.gnu.gdb.arm.m-profile">
    <reg name="r0" bitsize="32" regnum="0" type="uint32" group="general"/>
    <reg name="r1" bitsize="32" type="uint32" group="general"/>
    <reg name="r2" bitsize="32" type="uint32" group="general"/>
    <reg name="r3" bitsize="32" type="uint32" group="general"/>
    <reg name="r4" bitsize="32" type="uint32" group="general"/>
    <reg name="r5" bitsize="32" type="uint32" group="general"/>
    <reg name="r6" bitsize="32" type="uint32" group="general"/>
    <reg name="r7" bitsize="32" type="uint32" group="general"/>
    <reg name="r8" bitsize="32" type="uint32" group="general"/>
    <reg name="r9" bitsize="32" type="uint32" group="general"/>
    <reg name="r10" bitsize="32" type="uint32" group="general"/>
    <reg name="r11" bitsize="32" type="uint32" group="general"/>
    <reg name="r12" bitsize="32" type="uint32" group="general"/>
    <reg name="sp" bitsize="32" type="data_ptr" group="general"/>
    <reg name="lr" bitsize="32" type="uint32" group="general"/>
    <reg name="pc" bitsize="32" type="code_ptr" group="general"/>
    <reg name="xpsr" bitsize="32" type="uint32" group="general"/>
  </feature>
  <feature name="org.gnu.gdb.arm.vfp">
    <reg name="d0" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d1" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d2" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d3" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d4" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d5" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d6" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d7" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d8" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d9" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d10" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d11" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d12" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d13" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d14" bitsize="64" type="ieee_double" group="float"/>
    <reg name="d15" bitsize="64" type="ieee_double" group="float"/>
    <reg name="fpscr" bitsize="32" type="int" group="float"/>
  </feature>
  <feature name="org.gnu.gdb.arm.m-system">
    <reg name="msp" bitsize="32" type="data_ptr" group="system"/>
    <reg name="psp" bitsize="32" type="data_ptr" group="system"/>
  </feature>
  <feature name="net.autoplug.arm.m-special">
    <reg name="primask" bitsize="32" type="uint32" group="system"/>
    <reg name="basepri" bitsize="32" type="uint32" group="system"/>
    <reg name="faultmask" bitsize="32" type="uint32" group="system"/>
    <reg name="control" bitsize="32" type="uint32" group="system"/>
  </feature>
</target>
"#;

/// The STM32F446RE's memory as GDB is told it (`qXfer:memory-map:read`): the flash in
/// its sectors (16, 64 and 128 KiB: RM0390 3.3), its alias at 0, SRAM, the system memory
/// (the device signature), the peripherals and the private peripheral bus.
pub const MEMORY_MAP_XML: &str = r#"<?xml version="1.0"?>
<!DOCTYPE memory-map PUBLIC "+//IDN gnu.org//DTD GDB Memory Map V1.0//EN" "http://sourceware.org/gdb/gdb-memory-map.dtd">
<memory-map>
  <memory type="rom" start="0x00000000" length="0x80000"/>
  <memory type="flash" start="0x08000000" length="0x10000">
    <property name="blocksize">0x4000</property>
  </memory>
  <memory type="flash" start="0x08010000" length="0x10000">
    <property name="blocksize">0x10000</property>
  </memory>
  <memory type="flash" start="0x08020000" length="0x60000">
    <property name="blocksize">0x20000</property>
  </memory>
  <memory type="rom" start="0x1fff0000" length="0x10000"/>
  <memory type="ram" start="0x20000000" length="0x20000"/>
  <memory type="ram" start="0x40000000" length="0x20000000"/>
  <memory type="ram" start="0xe0000000" length="0x100000"/>
</memory-map>
"#;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_g_packet_round_trips_in_the_descriptions_order() {
        let mut regs = CortexM4fRegisters::default();
        regs.r[15] = 0x0800_1234;
        regs.s[1] = 0x3F80_0000;
        regs.special[5] = 2;
        let mut bytes = Vec::new();
        regs.gdb_serialize(|b| bytes.push(b.unwrap()));
        assert_eq!(bytes.len(), G_BYTES);
        assert_eq!(&bytes[60..64], &0x0800_1234u32.to_le_bytes());
        // d0 = s0 (low word), s1 (high word): 1.0f in s1 at byte 68 + 4.
        assert_eq!(&bytes[72..76], &0x3F80_0000u32.to_le_bytes());
        let mut back = CortexM4fRegisters::default();
        back.gdb_deserialize(&bytes).unwrap();
        assert_eq!(back, regs);
        assert!(back.gdb_deserialize(&bytes[1..]).is_err());
        // Register numbers: as many as the description has, in its order.
        let described = TARGET_XML.matches("<reg ").count();
        assert_eq!(described, 40);
        assert!(CortexM4fRegId::from_raw_id(described - 1).is_some());
        assert!(CortexM4fRegId::from_raw_id(described).is_none());
    }
}
