//! The diagnostic server of an AutoPlug ECU: UDS (ISO 14229-1) on the ECU's physical
//! identifiers and OBD-II mode 01 on the functional one, `no_std` and allocation-free, the
//! same code on the MCU and in the virtual car.
//!
//! | service | what | sessions | security |
//! |---|---|---|---|
//! | 0x10 | default, programming (only with the car standing), extended session; S3 5 s | all | — |
//! | 0x11 | hard (0x01) and soft (0x03) reset, after the response | all | — |
//! | 0x14 | clear all DTCs (group 0xFFFFFF) | all | — |
//! | 0x19 | DTCs: 0x01 count by status mask, 0x02 by status mask, 0x0A all stored | all | — |
//! | 0x22 | F186 session, F187 part number, F189 software version, F18C serial, F191 hardware version, F1A0 running image slot and its state, the ECU's live data | all | — |
//! | 0x27 | seed 0x01 / key 0x02: HMAC-SHA-512 of node ‖ seed; 3 wrong keys lock for 10 s, counted in flash before the key is checked and kept across resets | extended, programming | — |
//! | 0x28 | normal messages: rx/tx on/off | extended, programming | — |
//! | 0x3E | tester present | all | — |
//! | 0x31 | start FF00 erase (the DFU slot: the image slot not running), FF01 check the downloaded image (signature, ECU, hardware, load address, version floor, length) and mark it for a trial start | programming | yes |
//! | 0x34/0x36/0x37 | download an image to the slot address, 4093 data bytes per block | programming | yes |
//! | 0x85 | DTC setting on/off | extended, programming | — |
//!
//! Long operations answer 0x78 "response pending" first and continue in
//! [`Server::resume`], one flash sector or 1 KiB of verification per call.
//!
//! A bad image is refused as early as possible, with the negative response that says why:
//!
//! | image | refused at | NRC |
//! |---|---|---|
//! | larger than the slot | 0x34 | 0x70 upload/download not accepted |
//! | for another ECU, other hardware or load address, or older than the version floor | the 0x36 that completes the header | 0x31 request out of range |
//! | malformed header, or its length differs from the download's (truncated, trailing data) | the 0x36 that completes the header | 0x70 upload/download not accepted |
//! | shorter than a header and a signature | 0x31 FF01 | 0x72 general programming failure |
//! | any byte changed, unsigned, signed with another key | 0x31 FF01 | 0x72 general programming failure |
//!
//! Nothing is marked for a trial start unless FF01 succeeded, so the running firmware stays.
#![no_std]
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod node;
pub mod nrc;
pub mod obd;
pub mod security;
pub mod server;

pub use node::{DiagNode, STANDSTILL_WINDOW_US};

/// The SecurityAccess secret of the development setup (virtual car, tests, a bench
/// without its own): it is in this source code, so it keeps out only the careless. A
/// production bench builds its ECUs and its tester with its own secret.
pub const DEV_SECURITY_SECRET: &[u8] = b"AutoPlug development security secret";
pub use nrc::Nrc;
pub use server::{
    boot_slot_bytes, parse_boot_slot, Backend, Config, FlashError, Identification, Reply,
    ResetKind, Server, Session, MAX_BLOCK_LEN, ROUTINE_CHECK_PROGRAMMING_DEPENDENCIES,
    ROUTINE_ERASE_MEMORY,
};

#[cfg(test)]
mod tests;
