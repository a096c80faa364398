//! CAN log files for the AutoPlug gateway, which replays a log through the same pipeline
//! as a live bus: the formats engineers use, read as one stream of [`LogFrame`]s, and
//! written back for their tools.
//!
//! | module | what |
//! | --- | --- |
//! | [`frame`] | [`LogFrame`]: a CAN or CAN FD frame with its time, channel, kind and direction |
//! | [`read`] | streaming readers of candump `.log`, Vector `.asc` and `.blf`, ASAM MDF 4 `.mf4` bus logging; [`open`] picks one from the name or the first bytes |
//! | [`write`](mod@write) | candump and ASC writers; [`export_asc`] converts any log |
//! | [`blf_write`] | the BLF writer ([`export_blf`] converts any log) |
//! | [`mdf4::write`] | the MF4 writer: bus logging and decoded signals ([`export_mf4`] converts any log) |
//! | [`mdf4`] | ASAM MDF 4: its blocks, read and checked; data streams; where the bus logging is |
//! | [`record`] | [`Recorder`]: live traffic to rotating candump or MF4 files, flushed every 100 ms |
//!
//! Readers never load a whole file and never panic on bad input: a malformed line is an
//! error naming its line number, and reading goes on with the next, so the caller chooses
//! to stop (strict) or skip and count (lenient). Timestamps are integer microseconds as
//! the file gives them. CAN FD frames are read and written in every format; the gateway,
//! whose bus is classic CAN, counts them and leaves them aside.
//!
//! ```
//! use autoplug_logs::{read::CandumpReader, FrameKind};
//! let log = "(1436509052.249713) can0 044#2A366C2BBA R\n(1436509052.25) can0 12G#00\n";
//! let mut frames = CandumpReader::new(log.as_bytes());
//! let first = frames.next().unwrap().unwrap();
//! assert_eq!((first.t_us, first.id, first.kind), (1_436_509_052_249_713, 0x044, FrameKind::Data));
//! let bad = frames.next().unwrap().unwrap_err();
//! assert_eq!(bad.to_string(), "line 2: identifier \"12G\" is not hexadecimal");
//! ```
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod blf_write;
pub mod frame;
pub mod mcap_export;
pub mod mdf4;
pub mod read;
pub mod record;
mod time;
pub mod write;

pub use blf_write::BlfWriter;
pub use frame::{dlc_to_len, len_to_dlc, Direction, FdFlags, FrameError, FrameKind, LogFrame};
pub use mcap_export::{export_mcap, McapSummary};
pub use mdf4::write::Mf4Writer;
pub use read::{open, LogError, LogFormat, LogReader, OpenError, Place};
pub use record::{RecordError, RecordFormat, RecordSummary, Recorder, RotatePolicy};
pub use time::Utc;
pub use write::{export_asc, export_blf, export_mf4, AscWriter, CandumpWriter};
