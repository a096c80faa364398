//! An emulated STM32F446 that runs AutoPlug's unmodified firmware images: the
//! bootloader and an ECU's release ELF files, as `cargo fw -p ecu-<ecu>` would flash them, boot on
//! it and run their Embassy executors, timers, watchdog, flash writes and CAN.
//!
//! - [`cpu`]: the Cortex-M4F core (ARMv7E-M Thumb-2 with DSP and FPv4-SP), its exception
//!   model and its private peripherals;
//! - [`chip`]: flash, SRAM, the device signature and the peripherals the images use
//!   (RCC/PWR, FLASH, GPIO, ADC1, TIM3, TIM12, IWDG, CAN1), modelled from RM0390;
//! - [`mcu`]: the two together, run event to event in simulated time;
//! - [`node`]: emulated MCUs as nodes of the virtual car's bit-timed bus;
//! - [`map`] and [`programming`]: the memory map, and the flash as a programmer leaves it;
//! - [`rtt`]: the firmware's defmt log from its RTT buffer;
//!
//! The virtual car (`autoplug-virtual-car`) runs the ECUs' firmware on it, the pins joined
//! to the vehicle model and the CAN controller to its bus.
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod chip;
pub mod cpu;
pub mod debug;
pub mod gdb;
pub mod history;
pub mod map;
pub mod mcu;
pub mod node;
pub mod programming;
pub mod rtt;
