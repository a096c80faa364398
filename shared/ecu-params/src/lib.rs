//! The ECUs' published parameters: the calibration and thresholds an ECU's behaviour is
//! defined by, and the trouble codes it sets, in one place that both the ECU logic and the
//! tools that judge it read.
//!
//! An ECU's control crate re-exports its module here (`ecu_trans::GEAR_RATIOS` is
//! `autoplug_ecu_params::trans::GEAR_RATIOS`), so the firmware and the virtual car run on
//! the same values. The gateway's diagnostics and trip statistics read them from this
//! crate and link no control code: a diagnostic tool knows an ECU by its published
//! description (the role ODX and A2L files play for production ECUs), not by its code.
#![no_std]
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod abs;
pub mod console;
pub mod diff;
pub mod engine;
pub mod pedals;
pub mod steering;
pub mod trans;
