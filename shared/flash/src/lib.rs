//! The flash of an AutoPlug ECU (STM32F446RE): its map, its timings, and (feature `sim`) a
//! simulated NOR flash with the F446's geometry, timings and power cuts.
//!
//! - [`map`] (no_std, always built): sectors, partitions, the application's vector table, and
//!   compile-time checks of what embassy-boot 0.7 needs of them. Its items are re-exported at
//!   the crate root.
//! - [`timing`] (no_std): how long programming and erasing keep the flash busy (DS10693).
//! - [`twin`] (no_std): the ECU's persistent state (embassy-boot's state, the ECU data
//!   records) in two sectors written alternately, so that a power cut never loses it.
//! - `sim` (feature `sim`, std): `sim::SimFlash`, the whole 512 KiB flash with NOR
//!   semantics, busy-time accounting and power cuts at a chosen operation, and
//!   `sim::SimPartition`, partition handles implementing embedded-storage's `NorFlash` so
//!   embassy-boot's bootloader and updater run on the host over the same map as on the ECU.
//!
//! The power-cut tests in `tests/power_cut.rs` drive embassy-boot's update, swap, confirmation
//! and revert over the simulation with a power cut at every flash operation.
#![cfg_attr(not(feature = "sim"), no_std)]
#![deny(missing_docs)]

pub mod map;
pub mod timing;
pub mod twin;

#[cfg(feature = "sim")]
pub mod sim;

pub use map::*;
