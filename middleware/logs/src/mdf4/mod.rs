//! ASAM MDF 4 (`.mf4`), the measurement files CANape, CANalyzer, INCA, Vector's and CSS's
//! loggers and asammdf write. Our own code rather than a crate: the Rust MDF crates are
//! young (2026-11: `mf4-rs`, `mdf4-rs`), and a log reader here must stream block by block
//! in bounded memory, name every damage with its block and offset, and keep what precedes
//! it. Built in layers:
//!
//! - [`blocks`]: the identification block and any block by its link, checked (inside the
//!   file, a possible length, the expected type, no loop in a chain);
//! - [`data`]: the bytes behind a data link (DT, DZ, DL, HL) as one stream;
//! - [`transpose`]: the column-wise layout of transposed DZ blocks;
//! - [`bus`]: where the CAN bus logging is (channel groups and their members' places);
//! - [`crate::read::mf4`]: the reader of frames on these;
//! - [`write`](mod@write): [`Mf4Writer`](write::Mf4Writer), the bus and the decoded signals.
pub mod blocks;
pub mod bus;
pub mod data;
pub mod transpose;
pub mod write;
