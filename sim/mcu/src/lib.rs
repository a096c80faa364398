//! An emulated STM32F446 that runs AutoPlug's unmodified firmware images (issue 31).
//!
//! Built in steps; this is the first: the chip's memory map ([`map`]) and its flash as a
//! programmer leaves it, the bootloader's and an ECU's release ELF files written where they
//! are linked ([`programming`]). The Cortex-M4F core, its exception model and the
//! peripherals the images use come next.
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod map;
pub mod programming;
