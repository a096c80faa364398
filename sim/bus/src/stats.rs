//! Bus-load and traffic statistics, and the text summary a runner prints.

use core::fmt;

use crate::bus::VirtualBus;
use crate::node::ErrorState;

/// Traffic of one identifier.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct IdStats {
    /// Frames that went through: acknowledged, `dropped` ones included.
    pub frames: u64,
    /// Of `frames`, those a drop fault kept from every receiver.
    pub dropped: u64,
    /// Attempts that ended in an error frame.
    pub error_frames: u64,
    /// Bus time the identifier took, in bits: frames, error frames, intermissions.
    pub bus_bits: u64,
    /// Longest wait from `send` to the start of the transmission that succeeded, ns.
    pub latency_max_ns: u64,
    /// Sum of those waits over `frames`, ns.
    pub latency_total_ns: u64,
}

impl IdStats {
    /// Mean wait from `send` to the start of the successful transmission, ns.
    pub fn latency_mean_ns(&self) -> Option<u64> {
        self.latency_total_ns.checked_div(self.frames)
    }

    /// Whether the identifier was ever on the bus.
    pub fn is_active(&self) -> bool {
        self.frames + self.error_frames > 0
    }
}

/// Traffic of one node.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NodeStats {
    /// Frames sent successfully (acknowledged).
    pub tx_frames: u64,
    /// Transmission attempts that ended in an error frame.
    pub tx_errors: u64,
    /// Frames given up after an error (auto-retransmission off).
    pub tx_abandoned: u64,
    /// Frames discarded because the node was silenced.
    pub tx_suppressed: u64,
    /// `send` calls refused because the transmit queue was full.
    pub tx_overflows: u64,
    /// Most frames ever waiting in the transmit queue (the one on the wire included).
    pub tx_queue_high_water: usize,
    /// Frames put into the receive queue.
    pub rx_frames: u64,
    /// Accepted frames lost because the receive queue was full.
    pub rx_overruns: u64,
    /// Times the node went bus-off.
    pub bus_off_events: u64,
    /// Times it came back from bus-off.
    pub recoveries: u64,
}

/// Whole-bus figures.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BusStats {
    /// Simulated time so far, ns.
    pub elapsed_ns: u64,
    /// Time the bus was occupied (frames, error frames, intermissions), ns.
    pub busy_ns: u64,
    /// `busy_ns / elapsed_ns`, 0..=1.
    pub load: f64,
    /// Highest load of a completed window of `load_window_ns`; `None` before the first
    /// window is complete.
    pub max_window_load: Option<f64>,
    /// Length of the load windows, ns.
    pub load_window_ns: u64,
    /// Frames that went through (acknowledged).
    pub frames: u64,
    /// Error frames.
    pub error_frames: u64,
    /// Frames dropped by fault injection.
    pub dropped_frames: u64,
    /// Arbitrations where two or more nodes offered the same identifier.
    pub same_id_contentions: u64,
    /// Of those, frames that identical senders sent together as one.
    pub merged_transmissions: u64,
    /// Events not recorded because the event log was full.
    pub events_lost: u64,
}

/// Busy bits per fixed window, for the load peak. Frames arrive in time order, so one
/// open window is enough.
#[derive(Clone, Debug)]
pub(crate) struct LoadMeter {
    window_bits: u64,
    busy_bits: u64,
    open_window: u64,
    open_busy: u64,
    max_closed_busy: Option<u64>,
}

impl LoadMeter {
    pub(crate) fn new(window_bits: u64) -> Self {
        Self {
            window_bits: window_bits.max(1),
            busy_bits: 0,
            open_window: 0,
            open_busy: 0,
            max_closed_busy: None,
        }
    }

    /// Records the bus busy over `[from, to)` bits; calls come in time order.
    pub(crate) fn add_busy(&mut self, mut from: u64, to: u64) {
        self.busy_bits += to - from;
        while from < to {
            let window = from / self.window_bits;
            let segment_end = to.min((window + 1) * self.window_bits);
            if window != self.open_window {
                self.close_open_window();
                self.open_window = window;
            }
            self.open_busy += segment_end - from;
            from = segment_end;
        }
    }

    fn close_open_window(&mut self) {
        self.max_closed_busy = Some(
            self.max_closed_busy
                .map_or(self.open_busy, |m| m.max(self.open_busy)),
        );
        self.open_busy = 0;
    }

    /// Busy bits before `now_bits`, given that the last frame keeps the bus until
    /// `free_at_bits` (its tail may lie in the future).
    pub(crate) fn busy_bits(&self, now_bits: u64, free_at_bits: u64) -> u64 {
        self.busy_bits - free_at_bits.saturating_sub(now_bits).min(self.busy_bits)
    }

    /// Busy bits of the fullest window whose count is final at `now_bits` (it has ended,
    /// or the bus is busy to its end). A window without any traffic counts as 0, which
    /// never raises the maximum, so it needs no record.
    pub(crate) fn max_window_busy(&self, now_bits: u64) -> Option<u64> {
        let open_complete = (self.open_window + 1) * self.window_bits <= now_bits;
        let any_complete = now_bits >= self.window_bits;
        let open = open_complete.then_some(self.open_busy);
        match (self.max_closed_busy, open) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b).or(any_complete.then_some(0)),
        }
    }

    pub(crate) fn window_bits(&self) -> u64 {
        self.window_bits
    }
}

/// The statistics as text tables, for a runner's summary: `println!("{}", bus.report())`.
pub struct Report<'a> {
    pub(crate) bus: &'a VirtualBus,
}

impl fmt::Display for Report<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let bus = self.bus;
        let s = bus.bus_stats();
        let percent = |x: f64| x * 100.0;
        writeln!(
            f,
            "CAN bus {} kbit/s: {:.3} s simulated, {} frames, {} error frames, {} dropped",
            bus.timing().bitrate() / 1000,
            s.elapsed_ns as f64 / 1e9,
            s.frames,
            s.error_frames,
            s.dropped_frames
        )?;
        write!(f, "load {:.2} %", percent(s.load))?;
        match s.max_window_load {
            Some(peak) => write!(
                f,
                ", peak {:.2} % over {} ms windows",
                percent(peak),
                s.load_window_ns / 1_000_000
            )?,
            None => write!(
                f,
                ", no complete {} ms window yet",
                s.load_window_ns / 1_000_000
            )?,
        }
        writeln!(
            f,
            "; same-ID contentions {} (merged {}){}",
            s.same_id_contentions,
            s.merged_transmissions,
            if s.events_lost > 0 {
                format!("; {} events not logged (log full)", s.events_lost)
            } else {
                String::new()
            }
        )?;

        writeln!(
            f,
            "{:>5} {:>9} {:>6} {:>6} {:>9} {:>7} {:>10} {:>10}",
            "id", "frames", "errors", "drops", "bits/frm", "load%", "lat mean", "lat max"
        )?;
        for (id, st) in bus.id_stats_active() {
            let bits_per_frame = st.bus_bits as f64 / (st.frames + st.error_frames).max(1) as f64;
            let load = bus.timing().bits_to_ns(st.bus_bits) as f64 / s.elapsed_ns.max(1) as f64;
            writeln!(
                f,
                "0x{id:03X} {:>9} {:>6} {:>6} {:>9.1} {:>7.2} {:>8.1}us {:>8.1}us",
                st.frames,
                st.error_frames,
                st.dropped,
                bits_per_frame,
                percent(load),
                st.latency_mean_ns().unwrap_or(0) as f64 / 1e3,
                st.latency_max_ns as f64 / 1e3
            )?;
        }

        writeln!(
            f,
            "{:<14} {:>8} {:>8} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>5} {:>4} {:>4} state",
            "node",
            "tx",
            "rx",
            "tx-err",
            "txq-hw",
            "tx-ovf",
            "rx-ovr",
            "supp",
            "aband",
            "boff",
            "TEC",
            "REC"
        )?;
        for node in bus.nodes() {
            let st = bus.node_stats(node);
            let status = bus.node_status(node);
            let state = match status.state {
                ErrorState::Active => "active",
                ErrorState::Passive => "passive",
                ErrorState::BusOff => "bus-off",
            };
            writeln!(
                f,
                "{:<14} {:>8} {:>8} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>5} {:>4} {:>4} {}{}",
                bus.node_name(node),
                st.tx_frames,
                st.rx_frames,
                st.tx_errors,
                st.tx_queue_high_water,
                st.tx_overflows,
                st.rx_overruns,
                st.tx_suppressed,
                st.tx_abandoned,
                st.bus_off_events,
                status.tec,
                status.rec,
                state,
                if status.silenced { " (silenced)" } else { "" }
            )?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn windows_split_frames_and_keep_the_peak() {
        // As in the engine: a frame is added when it starts, so before `now` passes it.
        let mut m = LoadMeter::new(100);
        assert_eq!(m.max_window_busy(99), None);
        m.add_busy(90, 130); // 10 bits in window 0, 30 in window 1
        assert_eq!(m.max_window_busy(99), Some(10)); // busy to its end: final
        assert_eq!(m.max_window_busy(100), Some(10));
        m.add_busy(150, 160); // window 1: 40 in all
        assert_eq!(m.max_window_busy(199), Some(10));
        assert_eq!(m.max_window_busy(200), Some(40));
        m.add_busy(420, 425); // window 4
        assert_eq!(m.max_window_busy(500), Some(40));
        assert_eq!(m.busy_bits(500, 425), 55);
        assert_eq!(m.busy_bits(422, 425), 52);
    }

    #[test]
    fn idle_complete_window_reports_zero() {
        let m = LoadMeter::new(100);
        assert_eq!(m.max_window_busy(250), Some(0));
    }
}
