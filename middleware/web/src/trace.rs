//! The bus trace: the last [`TRACE_FRAMES`] frames as they came, each numbered, for the
//! Bus view's trace (CANalyzer's Trace window, cabana's and SavvyCAN's frame lists).
//!
//! The pipeline pushes every frame (a copy into a ring, under a lock held for that copy
//! alone); a page asks for what came after the last number it has, at most a page at a
//! time, and is told how many it missed when it fell more than the ring behind. Memory is
//! the ring's, whatever the number of pages.

use std::collections::VecDeque;
use std::fmt::Write as _;
use std::sync::Mutex;

use autoplug_can::{Node, MESSAGES};
use autoplug_logs::{Direction, FrameKind, LogFrame};

/// Frames kept: a few seconds of a busy bus.
pub const TRACE_FRAMES: usize = 8192;

/// Frames sent in one answer at most.
pub const MAX_PAGE: usize = 2000;

#[derive(Clone, Copy, Debug)]
struct Entry {
    seq: u64,
    frame: LogFrame,
}

#[derive(Debug, Default)]
struct Ring {
    next_seq: u64,
    frames: VecDeque<Entry>,
}

/// The trace (see the module docs).
#[derive(Debug, Default)]
pub struct Trace {
    ring: Mutex<Ring>,
}

/// What [`Trace::after`] gives a reader.
#[derive(Clone, Debug, PartialEq)]
pub struct TracePage {
    /// The number to ask after next time.
    pub last: u64,
    /// Frames that came after the reader's number but are no longer kept.
    pub missed: u64,
    /// The frames, as JSON arrays (see [`frame_json`]).
    pub frames: Vec<String>,
}

impl Trace {
    /// An empty trace.
    pub fn new() -> Self {
        Self::default()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Ring> {
        // A panic elsewhere while holding the lock leaves plain data: go on with it.
        self.ring.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Appends a frame; the oldest goes beyond [`TRACE_FRAMES`].
    pub fn push(&self, frame: &LogFrame) {
        let mut ring = self.lock();
        ring.next_seq += 1;
        let seq = ring.next_seq;
        if ring.frames.len() == TRACE_FRAMES {
            ring.frames.pop_front();
        }
        ring.frames.push_back(Entry { seq, frame: *frame });
    }

    /// The frames numbered after `after`, at most `limit` (and [`MAX_PAGE`]) of them,
    /// oldest first. `after` 0 with `limit` n: the newest n (a page that just opened).
    pub fn after(&self, after: u64, limit: usize) -> TracePage {
        let limit = limit.min(MAX_PAGE);
        let (entries, newest, oldest) = {
            let ring = self.lock();
            let oldest = ring.frames.front().map_or(ring.next_seq + 1, |e| e.seq);
            let start = if after == 0 {
                ring.frames.len().saturating_sub(limit)
            } else {
                ring.frames.partition_point(|e| e.seq <= after)
            };
            let entries: Vec<Entry> = ring.frames.range(start..).take(limit).copied().collect();
            (entries, ring.next_seq, oldest)
        };
        let missed = if after == 0 {
            0
        } else {
            oldest
                .saturating_sub(after.saturating_add(1))
                .min(newest - after.min(newest))
        };
        TracePage {
            last: entries.last().map_or(after.min(newest), |e| e.seq),
            missed,
            frames: entries.iter().map(frame_json).collect(),
        }
    }
}

/// A frame of the trace as a JSON array: `[seq, t, id, flags, dlc, data, name, sender]`:
/// bus time in s, flags a string of `x` (29-bit identifier), `r` (remote), `e` (error),
/// `f` (CAN FD), `t` (sent by the gateway itself), data in hex, and the name and sender the DBC gives
/// the identifier (for the diagnostic identifiers: the UDS request or response and the
/// node; empty when unknown).
fn frame_json(entry: &Entry) -> String {
    let f = &entry.frame;
    let mut flags = String::new();
    if f.extended {
        flags.push('x');
    }
    match f.kind {
        FrameKind::Data => {}
        FrameKind::Remote => flags.push('r'),
        FrameKind::Error => flags.push('e'),
    }
    if f.is_fd() {
        flags.push('f');
    }
    if f.direction == Direction::Tx {
        flags.push('t');
    }
    let data: String = f.data().iter().map(|b| format!("{b:02X}")).collect();
    // A CAN FD frame is not the catalogue's message whatever its identifier.
    let (name, sender) = if f.extended || f.kind == FrameKind::Error || f.is_fd() {
        (String::new(), String::new())
    } else {
        describe(f.id)
    };
    let mut json = String::with_capacity(80);
    // Names come from the DBC (identifiers) and the fixed texts below: nothing to escape.
    let _ = write!(
        json,
        "[{},{:.6},{},\"{flags}\",{},\"{data}\",\"{name}\",\"{sender}\"]",
        entry.seq,
        f.t_us as f64 * 1e-6,
        f.id,
        f.len(),
    );
    json
}

/// The name and sender of a standard identifier: a catalogue message with its DBC
/// transmitters, or a diagnostic identifier.
pub fn describe(id: u32) -> (String, String) {
    if let Some(m) = MESSAGES.iter().find(|m| u32::from(m.id) == id) {
        let senders: Vec<&str> = m.senders.iter().map(|n| n.name()).collect();
        return (m.name.to_string(), senders.join(" "));
    }
    if id == u32::from(autoplug_can::DIAG_FUNCTIONAL_REQUEST_ID) {
        return ("UDS functional request".into(), "tester".into());
    }
    for node in Node::ALL {
        if node.diag_request_id().map(u32::from) == Some(id) {
            return (format!("UDS request to {}", node.name()), "tester".into());
        }
        if node.diag_response_id().map(u32::from) == Some(id) {
            return ("UDS response".into(), node.name().into());
        }
        if node.obd_response_id().map(u32::from) == Some(id) {
            return ("OBD-II response".into(), node.name().into());
        }
    }
    (String::new(), String::new())
}

#[cfg(test)]
mod tests {
    use super::*;
    use autoplug_can::{CanMessage, VehicleSpeedMsg};

    fn frame(i: u64) -> LogFrame {
        LogFrame::from_can(
            i * 1000,
            0,
            &VehicleSpeedMsg {
                vehicle_speed: i as f32,
            }
            .frame(),
        )
    }

    fn parse(json: &str) -> serde_json::Value {
        serde_json::from_str(json).unwrap()
    }

    #[test]
    fn a_reader_gets_what_came_after_its_number_with_names_and_senders() {
        let trace = Trace::new();
        for i in 0..10 {
            trace.push(&frame(i));
        }
        let first = trace.after(0, 4);
        assert_eq!(first.frames.len(), 4, "the newest four");
        assert_eq!(first.last, 10);
        let f = parse(&first.frames[3]);
        assert_eq!(f[0], 10);
        assert_eq!(f[6], "VehicleSpeedMsg");
        assert!(!f[7].as_str().unwrap().is_empty(), "{f}");
        assert_eq!(f[4], 1, "VehicleSpeedMsg is one byte: {f}");
        trace.push(&frame(10));
        let next = trace.after(first.last, 100);
        assert_eq!((next.frames.len(), next.last, next.missed), (1, 11, 0));
        let none = trace.after(next.last, 100);
        assert_eq!((none.frames.len(), none.last), (0, 11));
    }

    #[test]
    fn memory_is_the_rings_and_a_reader_that_fell_behind_is_told_how_far() {
        let trace = Trace::new();
        for i in 0..(TRACE_FRAMES as u64 + 100) {
            trace.push(&frame(i));
        }
        let page = trace.after(50, 10);
        assert_eq!(page.missed, 50, "frames 51..=100 are gone");
        assert_eq!(parse(&page.frames[0])[0], 101);
        assert_eq!(trace.after(0, usize::MAX).frames.len(), MAX_PAGE);
        // A number from the future (a page kept over a restart) gets nothing, and no panic.
        let ahead = trace.after(u64::MAX, 10);
        assert!(ahead.frames.is_empty());
    }

    #[test]
    fn can_fd_frames_are_flagged_and_not_named_as_the_catalogue() {
        let trace = Trace::new();
        let id = u32::from(VehicleSpeedMsg::ID);
        let fd = LogFrame::new_fd(5, 0, id, false, &[0xAB; 16], Default::default()).unwrap();
        trace.push(&fd);
        let f = parse(&trace.after(0, 1).frames[0]);
        assert_eq!((&f[3], &f[4], &f[6]), (&"f".into(), &16.into(), &"".into()));
        assert_eq!(f[5].as_str().unwrap(), "AB".repeat(16));
    }

    #[test]
    fn diagnostic_identifiers_are_named() {
        let engine = Node::ALL
            .iter()
            .find(|n| n.diag_request_id().is_some())
            .unwrap();
        let (name, sender) = describe(u32::from(engine.diag_request_id().unwrap()));
        assert!(name.starts_with("UDS request to "), "{name}");
        assert_eq!(sender, "tester");
        assert_eq!(describe(0x7FF), (String::new(), String::new()));
    }
}
