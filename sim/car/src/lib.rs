//! The AutoPlug virtual car: the vehicle model, a bit-timed CAN bus and the nine ECUs'
//! logic (the same code the firmware runs), driven by scenario files.
#![deny(missing_docs)]

pub mod car;
pub mod compare;
pub mod console;
pub mod decimal;
pub mod diag;
pub mod driver;
pub mod firmware;
pub mod path_plot;
pub mod plot;
pub mod report;
pub mod scenario;
pub mod socketcand;
pub mod sweep;
pub mod track;
mod wiring;
pub mod world;

#[cfg(test)]
mod tests;
