//! The AutoPlug gateway's pipeline: frames from a live bus or a recorded log, through the
//! codec generated from the DBC, into the car state that diagnostics, trips, recordings
//! and the dashboard read.
//!
//! | module | what |
//! |---|---|
//! | [`source`] | the [`FrameSource`] trait; recorded logs as sources, as fast as possible or paced |
//! | [`state`] | [`CarState`]: every signal with value, unit, last update, freshness and VSS path; per message count, period, jitter, invalid values; foreign traffic |
//! | [`pipeline`] | [`Pipeline`]: source → state → [`Observer`]s, strict or lenient on malformed lines |
//! | [`sinks`] | [`RecordingSink`]: the recorder as an observer; a full disk stops it, not the pipeline |
//!
//! The gateway knows only the bus: nothing here reads a simulator's internals, so the same
//! code serves the virtual car, a bench with real ECUs and a log of either.
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod pipeline;
pub mod sinks;
pub mod source;
pub mod state;

pub use pipeline::{Observer, Pipeline, PipelineError, Strictness};
pub use sinks::RecordingSink;
pub use source::{FrameSource, LogSource, Paced, Pacer, Poll, SourceError, VecSource};
pub use state::{
    BusCounters, CarState, MessageStats, SignalName, SignalState, Update, RECENT_INTERVALS,
};

#[cfg(test)]
mod tests;
