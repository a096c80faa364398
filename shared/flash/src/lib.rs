//! The flash of an AutoPlug ECU (STM32F446RE): its map, its timings, and (feature `sim`) a
//! simulated NOR flash with the F446's geometry, timings and power cuts.
//!
//! - [`map`] (no_std, always built): sectors, partitions and their compile-time checks. Its
//!   items are re-exported at the crate root.
//! - [`ab`] (no_std): the two image slots, run in place, and the boot record that says which
//!   one the bootloader starts (confirmed, on trial, reverted).
//! - [`timing`] (no_std): how long programming and erasing keep the flash busy (DS10693).
//! - [`twin`] (no_std): the ECU's persistent state (the boot record, the ECU data records) in
//!   two sectors written alternately, so that a power cut never loses it.
//! - `sim` (feature `sim`, std): `sim::SimFlash`, the whole 512 KiB flash with NOR
//!   semantics, busy-time accounting and power cuts at a chosen operation, and
//!   `sim::SimPartition`, partition handles implementing embedded-storage's `NorFlash` so the
//!   update and boot logic run on the host over the same map as on the ECU.
//!
//! The power-cut tests in `tests/power_cut.rs` drive the update, the trial start, the
//! confirmation and the revert over the simulation with a power cut at every flash
//! operation.
#![cfg_attr(not(feature = "sim"), no_std)]
#![deny(missing_docs)]

pub mod ab;
pub mod map;
pub mod timing;
pub mod twin;

#[cfg(feature = "sim")]
pub mod sim;

pub use map::*;
