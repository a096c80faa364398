//! The bus engine: transmit queues, arbitration, delivery, error confinement, in simulated
//! time.
//!
//! Time runs on a bit grid anchored at t = 0: every frame starts on a bit boundary and
//! lasts a whole number of bits. The engine only ever decides the bus up to the time the
//! caller has reached, so a frame sent at `t` takes part in every arbitration at or after
//! `t` and in none before.

use std::collections::{BinaryHeap, VecDeque};
use std::fmt;

use autoplug_can::Frame;

use crate::fault::{FaultAction, FaultId, FaultRule, Faults, XorShift64};
use crate::node::{
    AcceptanceFilter, BusOffRecovery, ErrorCounters, ErrorState, IdBitmap, NodeConfig, NodeId,
    NodeSet, NodeStatus, MAX_NODES,
};
use crate::stats::{BusStats, IdStats, LoadMeter, NodeStats, Report};
use crate::timing::{frame_bits, BitTiming, FrameBits, DEFAULT_BITRATE};

/// Dominant bits of an error frame raised by every receiver at once after a CRC error:
/// the receivers' 6-bit flag plus one bit where the transmitter's own flag, one bit
/// late, still overlaps.
const CRC_ERROR_FLAG_BITS: u64 = 7;
/// A lone transmitter's error flag after a missing ACK.
const ACK_ERROR_FLAG_BITS: u64 = 6;
const ERROR_DELIMITER_BITS: u64 = 8;
const INTERMISSION_BITS: u64 = crate::timing::INTERMISSION_BITS as u64;
/// Extra wait of an error-passive transmitter before its next frame.
const SUSPEND_TRANSMISSION_BITS: u64 = 8;
/// Transmission records kept per reporting node until read.
const TRANSMITTED_KEPT: usize = 256;
/// Bus-off recovery: 128 sequences of 11 recessive bits.
const RECOVERY_SEQUENCES: u64 = 128;
const RECOVERY_SEQUENCE_BITS: u64 = 11;

/// Bus-wide settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BusConfig {
    /// Bit rate, bit/s (default 500 kbit/s, the AutoPlug bus).
    pub bitrate: u32,
    /// Seed of the generator behind probabilistic faults.
    pub seed: u64,
    /// Window for the peak bus load, ns (default 100 ms).
    pub load_window_ns: u64,
    /// Bus events kept for [`VirtualBus::drain_events`]; 0 disables the log. Events past
    /// a full log are counted in [`BusStats::events_lost`].
    pub event_log_capacity: usize,
}

impl Default for BusConfig {
    fn default() -> Self {
        Self {
            bitrate: DEFAULT_BITRATE,
            seed: 1,
            load_window_ns: 100_000_000,
            event_log_capacity: 0,
        }
    }
}

/// A frame as a node's software receives it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Delivered {
    /// End of the frame's EOF, ns: when the controller has it.
    pub t_ns: u64,
    /// The frame.
    pub frame: Frame,
    /// Who sent it (the lowest node, if identical senders sent it together).
    pub from: NodeId,
}

/// What became of one frame on the wire.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Outcome {
    /// Acknowledged and handed to these nodes (the ones whose filter accepts it and
    /// whose receive queue had room).
    Received {
        /// Nodes whose receive queue got the frame.
        receivers: NodeSet,
    },
    /// Acknowledged, but a drop fault kept it from every node.
    Dropped,
    /// Corrupted: receivers found a CRC error and raised an error frame.
    CrcError,
    /// No other node on the bus acknowledged it.
    AckError,
}

/// One frame on the wire, as a bus monitor (candump with error frames) would log it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BusEvent {
    /// Start of SOF, ns.
    pub start_ns: u64,
    /// End of EOF (when delivered), or of the error delimiter after an error, ns.
    pub end_ns: u64,
    /// The frame.
    pub frame: Frame,
    /// Lowest sending node.
    pub from: NodeId,
    /// Every node that sent it (more than one only for identical frames sent together).
    pub senders: NodeSet,
    /// What became of it.
    pub outcome: Outcome,
}

/// How one of a node's frames went on the wire (for nodes with
/// [`NodeConfig::report_transmissions`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Transmitted {
    /// The frame.
    pub frame: Frame,
    /// End of its EOF (or of the error delimiter after an error), ns.
    pub end_ns: u64,
    /// Acknowledged (delivered or dropped by a fault) rather than ended by an error frame.
    pub ok: bool,
    /// After an error: the frame is queued again for an automatic retransmission.
    pub retrying: bool,
}

/// Why [`VirtualBus::send`] refused a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TxError {
    /// The node's transmit queue is full; the frame is lost and counted.
    QueueFull {
        /// The queue's capacity.
        capacity: usize,
    },
    /// The send time is before the bus's current time, which has been decided already.
    InPast {
        /// The time given.
        at_ns: u64,
        /// The bus's time.
        bus_now_ns: u64,
    },
}

impl fmt::Display for TxError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            TxError::QueueFull { capacity } => write!(f, "transmit queue full ({capacity} frames)"),
            TxError::InPast { at_ns, bus_now_ns } => {
                write!(
                    f,
                    "send at {at_ns} ns, but the bus is already at {bus_now_ns} ns"
                )
            }
        }
    }
}

impl std::error::Error for TxError {}

/// A frame waiting in a transmit queue.
#[derive(Clone, Copy, Debug)]
struct Pending {
    frame: Frame,
    bits: FrameBits,
    enqueued_ns: u64,
    /// Bus-wide send order: FIFO among frames with the same identifier.
    seq: u64,
}

// The queue is a max-heap: "greater" is the frame that goes first, lowest identifier,
// then oldest.
impl Ord for Pending {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        other
            .frame
            .id()
            .cmp(&self.frame.id())
            .then(other.seq.cmp(&self.seq))
    }
}
impl PartialOrd for Pending {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl PartialEq for Pending {
    fn eq(&self, other: &Self) -> bool {
        self.seq == other.seq
    }
}
impl Eq for Pending {}

/// A bus-off node on its way back.
#[derive(Clone, Copy, Debug)]
struct BusOff {
    /// Bit from which it counts recessive sequences; `None` until recovery is requested
    /// (manual recovery).
    counting_since: Option<u64>,
    sequences: u64,
}

impl BusOff {
    /// The bit at which recovery completes if the bus stays idle from the recessive run
    /// that began at `recessive_since`.
    fn completion_bit(&self, recessive_since: u64) -> Option<u64> {
        let since = self.counting_since?;
        Some(
            since.max(recessive_since)
                + RECOVERY_SEQUENCE_BITS * (RECOVERY_SEQUENCES - self.sequences),
        )
    }
}

struct NodeSlot {
    name: String,
    accept: IdBitmap,
    config: NodeConfig,
    tx: BinaryHeap<Pending>,
    /// The frame on the wire, out of `tx` until the bus says how it went.
    in_flight: Option<Pending>,
    /// First bit at which the oldest queued frame may start.
    ready_bits: u64,
    /// First bit at which the node may start a frame (suspend transmission, recovery).
    eligible_from_bits: u64,
    rx: VecDeque<Delivered>,
    /// How the node's frames went, when it asked ([`NodeConfig::report_transmissions`]).
    transmitted: VecDeque<Transmitted>,
    counters: ErrorCounters,
    bus_off: Option<BusOff>,
    silenced: bool,
    stats: NodeStats,
}

impl NodeSlot {
    fn head(&self) -> Option<&Pending> {
        self.tx.peek()
    }

    fn can_start_at(&self, bit: u64) -> bool {
        self.bus_off.is_none()
            && !self.tx.is_empty()
            && self.eligible_from_bits <= bit
            && self.ready_bits <= bit
    }

    fn queued(&self) -> usize {
        self.tx.len() + usize::from(self.in_flight.is_some())
    }

    /// Queues a frame that may start from `ready_bits` (a new one, or one to retransmit).
    fn enqueue(&mut self, pending: Pending, ready_bits: u64) {
        self.ready_bits = if self.tx.is_empty() {
            ready_bits
        } else {
            self.ready_bits.min(ready_bits)
        };
        self.tx.push(pending);
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Fate {
    Received,
    Dropped,
    CrcError,
    AckError,
}

/// The frame currently on the wire.
#[derive(Clone, Copy, Debug)]
struct Transmission {
    start_bits: u64,
    /// End of EOF, or of the error delimiter.
    end_bits: u64,
    /// First bit of the recessive run that ends the frame (ACK delimiter, or error
    /// delimiter): where bus-off recovery counting resumes.
    recessive_from_bits: u64,
    frame: Frame,
    senders: NodeSet,
    fate: Fate,
}

#[derive(Clone, Copy, Debug, Default)]
struct BusCounters {
    frames: u64,
    error_frames: u64,
    dropped: u64,
    same_id_contentions: u64,
    merged: u64,
    events_lost: u64,
}

/// A classic CAN bus in simulated time. See the crate documentation for the model.
pub struct VirtualBus {
    config: BusConfig,
    timing: BitTiming,
    nodes: Vec<NodeSlot>,
    now_ns: u64,
    /// First bit at which a new frame may start (end of the last intermission).
    free_at_bits: u64,
    /// Start of the recessive run the bus is in (or will be in after the frame on the
    /// wire), for bus-off recovery.
    recessive_since_bits: u64,
    on_wire: Option<Transmission>,
    next_seq: u64,
    faults: Faults,
    rng: XorShift64,
    id_stats: Vec<IdStats>,
    /// Each identifier's last frame sent and its length on the wire: periodic frames
    /// often repeat their data, and the CRC and stuffing need not be worked out again.
    last_bits: Vec<Option<(Frame, FrameBits)>>,
    load: LoadMeter,
    counters: BusCounters,
    events: Vec<BusEvent>,
}

impl VirtualBus {
    /// An idle bus at t = 0 with no node.
    ///
    /// # Panics
    /// If the bit rate is 0.
    pub fn new(config: BusConfig) -> Self {
        let timing = BitTiming::new(config.bitrate);
        Self {
            config,
            timing,
            nodes: Vec::new(),
            now_ns: 0,
            free_at_bits: 0,
            recessive_since_bits: 0,
            on_wire: None,
            next_seq: 0,
            faults: Faults::default(),
            rng: XorShift64::new(config.seed),
            id_stats: vec![IdStats::default(); usize::from(Frame::MAX_ID) + 1],
            last_bits: vec![None; usize::from(Frame::MAX_ID) + 1],
            load: LoadMeter::new(timing.ns_to_bits_floor(config.load_window_ns)),
            counters: BusCounters::default(),
            events: Vec::with_capacity(config.event_log_capacity),
        }
    }

    /// Attaches a node with the default [`NodeConfig`].
    ///
    /// # Panics
    /// Beyond [`MAX_NODES`] nodes.
    pub fn attach(&mut self, name: &str, filter: AcceptanceFilter) -> NodeId {
        self.attach_with(name, filter, NodeConfig::default())
    }

    /// Attaches a node. It takes part from the current time on.
    ///
    /// # Panics
    /// Beyond [`MAX_NODES`] nodes.
    pub fn attach_with(
        &mut self,
        name: &str,
        filter: AcceptanceFilter,
        config: NodeConfig,
    ) -> NodeId {
        assert!(
            self.nodes.len() < MAX_NODES,
            "a virtual bus carries at most {MAX_NODES} nodes"
        );
        let id = NodeId(self.nodes.len() as u8);
        self.nodes.push(NodeSlot {
            name: name.to_owned(),
            accept: IdBitmap::new(&filter),
            config,
            tx: BinaryHeap::with_capacity(config.tx_queue_capacity),
            in_flight: None,
            ready_bits: 0,
            eligible_from_bits: 0,
            rx: VecDeque::with_capacity(config.rx_queue_capacity),
            transmitted: VecDeque::new(),
            counters: ErrorCounters::default(),
            bus_off: None,
            silenced: false,
            stats: NodeStats::default(),
        });
        id
    }

    /// Queues `frame` for transmission by `node` at `now_ns`, first advancing the bus to
    /// `now_ns`. The node offers its lowest-identifier frame (oldest first among equal
    /// identifiers) at every arbitration from the first bit boundary at or after `now_ns`.
    ///
    /// A silenced node's frame is discarded and counted, and `Ok` returned: the fault is
    /// invisible to the node's software, as a dead transmitter would be.
    ///
    /// # Panics
    /// If `node` is not a node of this bus.
    pub fn send(&mut self, node: NodeId, frame: Frame, now_ns: u64) -> Result<(), TxError> {
        if now_ns < self.now_ns {
            return Err(TxError::InPast {
                at_ns: now_ns,
                bus_now_ns: self.now_ns,
            });
        }
        self.run_until(now_ns);
        let ready = self.timing.ns_to_bits_ceil(now_ns);
        let seq = self.next_seq;
        let slot = &mut self.nodes[node.index()];
        if slot.silenced {
            slot.stats.tx_suppressed += 1;
            return Ok(());
        }
        let capacity = slot.config.tx_queue_capacity;
        if slot.queued() >= capacity {
            slot.stats.tx_overflows += 1;
            return Err(TxError::QueueFull { capacity });
        }
        self.next_seq += 1;
        let bits = match &mut self.last_bits[usize::from(frame.id())] {
            Some((last, bits)) if *last == frame => *bits,
            entry => {
                let bits = frame_bits(&frame);
                *entry = Some((frame, bits));
                bits
            }
        };
        slot.enqueue(
            Pending {
                frame,
                bits,
                enqueued_ns: now_ns,
                seq,
            },
            ready,
        );
        slot.stats.tx_queue_high_water = slot.stats.tx_queue_high_water.max(slot.queued());
        Ok(())
    }

    /// Advances simulated time to `t_ns`: runs every arbitration that starts before
    /// `t_ns` and completes every frame whose end is at or before `t_ns`, filling the
    /// receive queues and the event log in time order. A frame still on the wire at
    /// `t_ns` completes in a later call. Does nothing if `t_ns` is in the past.
    pub fn run_until(&mut self, t_ns: u64) {
        if t_ns < self.now_ns {
            return;
        }
        loop {
            if let Some(tx) = self.on_wire {
                if self.timing.bits_to_ns(tx.end_bits) > t_ns {
                    break;
                }
                self.on_wire = None;
                self.complete(tx);
            }
            match self.next_start_bits() {
                Some(start) if self.timing.bits_to_ns(start) < t_ns => self.start(start),
                _ => break,
            }
        }
        self.now_ns = t_ns;
        let timing = self.timing;
        self.settle_recoveries(|bit| timing.bits_to_ns(bit) <= t_ns);
    }

    /// The next frame `node`'s software receives, oldest first.
    pub fn recv(&mut self, node: NodeId) -> Option<Delivered> {
        self.nodes[node.index()].rx.pop_front()
    }

    /// How the next of `node`'s frames went on the wire, oldest first (nodes attached with
    /// [`NodeConfig::report_transmissions`]; empty for the others).
    pub fn transmitted(&mut self, node: NodeId) -> Option<Transmitted> {
        self.nodes[node.index()].transmitted.pop_front()
    }

    /// Takes back a frame `node` queued and the bus has not started: a CAN controller's
    /// abort request (bxCAN ABRQ). Returns whether it was still waiting; a frame on the
    /// wire cannot be taken back (its transmission decides).
    pub fn cancel(&mut self, node: NodeId, frame: Frame) -> bool {
        let slot = &mut self.nodes[node.index()];
        let Some(seq) = slot
            .tx
            .iter()
            .filter(|p| p.frame == frame)
            .map(|p| p.seq)
            .min()
        else {
            return false;
        };
        slot.tx.retain(|p| p.seq != seq);
        true
    }

    /// The frame of `node`'s on the wire now, if one is (a controller cannot abort it: its
    /// transmission decides).
    pub fn transmitting(&self, node: NodeId) -> Option<Frame> {
        self.on_wire
            .filter(|tx| tx.senders.contains(node))
            .map(|tx| tx.frame)
    }

    /// When the frame on the wire ends (its EOF, or its error delimiter), if there is one:
    /// the next moment a receiver gets a frame or a sender learns how its frame went.
    pub fn wire_busy_until_ns(&self) -> Option<u64> {
        self.on_wire.map(|tx| self.timing.bits_to_ns(tx.end_bits))
    }

    /// Frames waiting in `node`'s receive queue.
    pub fn rx_pending(&self, node: NodeId) -> usize {
        self.nodes[node.index()].rx.len()
    }

    /// Frames waiting in `node`'s transmit queue, the one on the wire included.
    pub fn tx_pending(&self, node: NodeId) -> usize {
        self.nodes[node.index()].queued()
    }

    /// Every frame on the wire since the last drain, in time order (needs
    /// [`BusConfig::event_log_capacity`] above 0). The log keeps its memory.
    pub fn drain_events(&mut self) -> std::vec::Drain<'_, BusEvent> {
        self.events.drain(..)
    }

    /// Simulated time, ns: the last `run_until` or `send` time.
    pub fn now_ns(&self) -> u64 {
        self.now_ns
    }

    /// Bit timing of the bus.
    pub fn timing(&self) -> BitTiming {
        self.timing
    }

    /// The bus's configuration.
    pub fn config(&self) -> &BusConfig {
        &self.config
    }

    /// Every node, in attach order.
    pub fn nodes(&self) -> impl Iterator<Item = NodeId> {
        (0..self.nodes.len()).map(|i| NodeId(i as u8))
    }

    /// The name given at attach.
    pub fn node_name(&self, node: NodeId) -> &str {
        &self.nodes[node.index()].name
    }

    /// Fault-confinement state and error counters of `node`, as of [`Self::now_ns`].
    pub fn node_status(&self, node: NodeId) -> NodeStatus {
        let slot = &self.nodes[node.index()];
        let state = if slot.bus_off.is_some() {
            ErrorState::BusOff
        } else if slot.counters.is_passive() {
            ErrorState::Passive
        } else {
            ErrorState::Active
        };
        NodeStatus {
            state,
            tec: slot.counters.tec,
            rec: slot.counters.rec,
            silenced: slot.silenced,
        }
    }

    /// Traffic counters of `node`.
    pub fn node_stats(&self, node: NodeId) -> &NodeStats {
        &self.nodes[node.index()].stats
    }

    /// Traffic of identifier `id` (0x000..=0x7FF).
    pub fn id_stats(&self, id: u16) -> &IdStats {
        &self.id_stats[usize::from(id)]
    }

    /// Every identifier seen on the bus, ascending, with its traffic.
    pub fn id_stats_active(&self) -> impl Iterator<Item = (u16, &IdStats)> {
        self.id_stats
            .iter()
            .enumerate()
            .filter(|(_, s)| s.is_active())
            .map(|(id, s)| (id as u16, s))
    }

    /// Whole-bus figures as of [`Self::now_ns`].
    pub fn bus_stats(&self) -> BusStats {
        let now_bits = self.timing.ns_to_bits_floor(self.now_ns);
        let busy_ns = self
            .timing
            .bits_to_ns(self.load.busy_bits(now_bits, self.free_at_bits));
        let window_ns = self.timing.bits_to_ns(self.load.window_bits());
        BusStats {
            elapsed_ns: self.now_ns,
            busy_ns,
            load: if self.now_ns == 0 {
                0.0
            } else {
                busy_ns as f64 / self.now_ns as f64
            },
            max_window_load: self
                .load
                .max_window_busy(now_bits)
                .map(|busy| busy as f64 / self.load.window_bits() as f64),
            load_window_ns: window_ns,
            frames: self.counters.frames,
            error_frames: self.counters.error_frames,
            dropped_frames: self.counters.dropped,
            same_id_contentions: self.counters.same_id_contentions,
            merged_transmissions: self.counters.merged,
            events_lost: self.counters.events_lost,
        }
    }

    /// All statistics as printable tables.
    pub fn report(&self) -> Report<'_> {
        Report { bus: self }
    }

    /// Adds a fault rule; it applies to frames starting from now on.
    pub fn add_fault(&mut self, rule: FaultRule) -> FaultId {
        self.faults.add(rule)
    }

    /// Removes a fault rule; `false` if it was already gone.
    pub fn remove_fault(&mut self, fault: FaultId) -> bool {
        self.faults.remove(fault)
    }

    /// How many frames a fault rule has hit.
    pub fn fault_hits(&self, fault: FaultId) -> u64 {
        self.faults.hits(fault)
    }

    /// Silences `node`'s transmitter (or lets it speak again). While silenced, its queued
    /// and future frames are discarded and counted in [`NodeStats::tx_suppressed`]; a
    /// frame already on the wire finishes. It still receives and acknowledges.
    pub fn set_silenced(&mut self, node: NodeId, silenced: bool) {
        let slot = &mut self.nodes[node.index()];
        slot.silenced = silenced;
        if silenced {
            slot.stats.tx_suppressed += slot.tx.len() as u64;
            slot.tx.clear();
        }
    }

    /// Puts `node` bus-off now, as if its TEC had passed 255; it recovers per its
    /// [`BusOffRecovery`]. A frame it has on the wire still finishes.
    pub fn force_bus_off(&mut self, node: NodeId) {
        let now_bits = self.timing.ns_to_bits_ceil(self.now_ns);
        let slot = &mut self.nodes[node.index()];
        if slot.bus_off.is_none() {
            slot.counters.tec = 256;
            enter_bus_off(slot, now_bits);
        }
    }

    /// Starts bus-off recovery of a node configured with [`BusOffRecovery::Manual`]
    /// (software clearing bxCAN's INRQ). Returns whether the node was waiting for it.
    pub fn request_recovery(&mut self, node: NodeId) -> bool {
        let now_bits = self.timing.ns_to_bits_ceil(self.now_ns);
        match &mut self.nodes[node.index()].bus_off {
            Some(off) if off.counting_since.is_none() => {
                off.counting_since = Some(now_bits);
                true
            }
            _ => false,
        }
    }

    /// The earliest bit at which some node may start a frame, if any node has one.
    fn next_start_bits(&self) -> Option<u64> {
        let recessive_since = self.recessive_since_bits;
        self.nodes
            .iter()
            .filter(|slot| !slot.tx.is_empty())
            .filter_map(|slot| {
                let eligible = match &slot.bus_off {
                    Some(off) => off.completion_bit(recessive_since)?,
                    None => slot.eligible_from_bits,
                };
                Some(eligible.max(slot.ready_bits))
            })
            .min()
            .map(|bit| bit.max(self.free_at_bits))
    }

    /// Arbitration at bit `start` and the frame's fate, decided now so that the whole
    /// frame is known when it completes.
    fn start(&mut self, start: u64) {
        self.settle_recoveries(|bit| bit <= start);
        // Recovering nodes count the 11-bit recessive sequences of the idle stretch.
        for slot in &mut self.nodes {
            if let Some(off) = &mut slot.bus_off {
                if let Some(since) = off.counting_since {
                    let idle = start.saturating_sub(since.max(self.recessive_since_bits));
                    off.sequences =
                        (off.sequences + idle / RECOVERY_SEQUENCE_BITS).min(RECOVERY_SEQUENCES - 1);
                }
            }
        }

        // Lowest identifier wins; among nodes offering it, the lowest node's frame goes,
        // together with every other node offering the very same frame.
        let (first, id) = self
            .nodes
            .iter()
            .enumerate()
            .filter(|(_, slot)| slot.can_start_at(start))
            .map(|(i, slot)| (i, slot.head().map_or(u16::MAX, |p| p.frame.id())))
            .min_by_key(|&(i, id)| (id, i))
            .expect("next_start_bits found a node ready to send");
        let winner = *self.nodes[first].head().expect("the winner has a frame");
        let mut senders = NodeSet::EMPTY;
        let mut contenders = 0;
        for (i, slot) in self.nodes.iter_mut().enumerate().skip(first) {
            let Some(head) = slot.head() else { continue };
            if !slot.can_start_at(start) || head.frame.id() != id {
                continue;
            }
            contenders += 1;
            if head.frame == winner.frame {
                slot.in_flight = slot.tx.pop();
                senders.insert(NodeId(i as u8));
            }
        }
        if contenders > 1 {
            self.counters.same_id_contentions += 1;
            if senders.len() > 1 {
                self.counters.merged += 1;
            }
        }

        let acknowledged = self
            .nodes
            .iter()
            .enumerate()
            .any(|(i, slot)| slot.bus_off.is_none() && !senders.contains(NodeId(i as u8)));
        let fate = if !acknowledged {
            Fate::AckError
        } else {
            match self
                .faults
                .evaluate(id, senders, self.timing.bits_to_ns(start), &mut self.rng)
            {
                Some(FaultAction::Corrupt) => Fate::CrcError,
                Some(FaultAction::Drop) => Fate::Dropped,
                None => Fate::Received,
            }
        };

        let region = u64::from(winner.bits.stuffed_region());
        let (end_bits, recessive_from_bits, free_at_bits) = match fate {
            Fate::Received | Fate::Dropped => (
                start + u64::from(winner.bits.frame_len),
                start + region + 2,
                start + u64::from(winner.bits.total_with_ifs),
            ),
            // Receivers flag a CRC error from the bit after the ACK delimiter.
            Fate::CrcError => {
                let delimiter = start + region + 3 + CRC_ERROR_FLAG_BITS;
                (
                    delimiter + ERROR_DELIMITER_BITS,
                    delimiter,
                    delimiter + ERROR_DELIMITER_BITS + INTERMISSION_BITS,
                )
            }
            // The transmitter flags a missing ACK from the ACK delimiter.
            Fate::AckError => {
                let delimiter = start + region + 2 + ACK_ERROR_FLAG_BITS;
                (
                    delimiter + ERROR_DELIMITER_BITS,
                    delimiter,
                    delimiter + ERROR_DELIMITER_BITS + INTERMISSION_BITS,
                )
            }
        };
        self.free_at_bits = free_at_bits;
        self.recessive_since_bits = recessive_from_bits;
        self.load.add_busy(start, free_at_bits);
        self.id_stats[usize::from(id)].bus_bits += free_at_bits - start;
        self.on_wire = Some(Transmission {
            start_bits: start,
            end_bits,
            recessive_from_bits,
            frame: winner.frame,
            senders,
            fate,
        });
    }

    /// The frame on the wire has ended: counters, deliveries, retransmission, event log.
    fn complete(&mut self, tx: Transmission) {
        let id = tx.frame.id();
        let start_ns = self.timing.bits_to_ns(tx.start_bits);
        let end_ns = self.timing.bits_to_ns(tx.end_bits);
        let free_at_bits = self.free_at_bits;
        let success = matches!(tx.fate, Fate::Received | Fate::Dropped);
        let id_stats = &mut self.id_stats[usize::from(id)];

        for sender in tx.senders.iter() {
            let slot = &mut self.nodes[sender.index()];
            let pending = slot
                .in_flight
                .take()
                .expect("a sender has its frame on the wire");
            if success {
                slot.counters.transmitted();
                slot.stats.tx_frames += 1;
                let latency = start_ns - pending.enqueued_ns;
                id_stats.latency_max_ns = id_stats.latency_max_ns.max(latency);
                id_stats.latency_total_ns += latency;
            } else {
                slot.counters.transmit_error(tx.fate == Fate::AckError);
                slot.stats.tx_errors += 1;
                if slot.bus_off.is_none() && slot.counters.is_bus_off() {
                    enter_bus_off(slot, tx.recessive_from_bits);
                }
                if slot.silenced {
                    slot.stats.tx_suppressed += 1;
                } else if slot.bus_off.is_some() || slot.config.auto_retransmit {
                    // bxCAN keeps the request pending through bus-off.
                    slot.enqueue(pending, tx.start_bits);
                } else {
                    slot.stats.tx_abandoned += 1;
                }
            }
            if slot.bus_off.is_none() && slot.counters.is_passive() {
                slot.eligible_from_bits = free_at_bits + SUSPEND_TRANSMISSION_BITS;
            }
            if slot.config.report_transmissions {
                let retrying = !success && slot.tx.iter().any(|p| p.seq == pending.seq);
                // Bounded: a caller that never reads the record loses its oldest entries.
                if slot.transmitted.len() == TRANSMITTED_KEPT {
                    slot.transmitted.pop_front();
                }
                slot.transmitted.push_back(Transmitted {
                    frame: tx.frame,
                    end_ns,
                    ok: success,
                    retrying,
                });
            }
        }

        let from = tx.senders.first().expect("a frame has a sender");
        let mut receivers = NodeSet::EMPTY;
        for (i, slot) in self.nodes.iter_mut().enumerate() {
            let node = NodeId(i as u8);
            let is_sender = tx.senders.contains(node);
            if slot.bus_off.is_some() {
                continue;
            }
            if !is_sender {
                match tx.fate {
                    Fate::Received | Fate::Dropped => slot.counters.received(),
                    Fate::CrcError => slot.counters.receive_error(),
                    Fate::AckError => {}
                }
            }
            if tx.fate == Fate::Received
                && (!is_sender || slot.config.loopback)
                && slot.accept.contains(id)
            {
                if slot.rx.len() < slot.config.rx_queue_capacity {
                    slot.rx.push_back(Delivered {
                        t_ns: end_ns,
                        frame: tx.frame,
                        from,
                    });
                    slot.stats.rx_frames += 1;
                    receivers.insert(node);
                } else {
                    slot.stats.rx_overruns += 1;
                }
            }
        }

        let id_stats = &mut self.id_stats[usize::from(id)];
        if success {
            id_stats.frames += 1;
            self.counters.frames += 1;
        } else {
            id_stats.error_frames += 1;
            self.counters.error_frames += 1;
        }
        if tx.fate == Fate::Dropped {
            id_stats.dropped += 1;
            self.counters.dropped += 1;
        }

        if self.config.event_log_capacity > 0 {
            if self.events.len() < self.config.event_log_capacity {
                self.events.push(BusEvent {
                    start_ns,
                    end_ns,
                    frame: tx.frame,
                    from,
                    senders: tx.senders,
                    outcome: match tx.fate {
                        Fate::Received => Outcome::Received { receivers },
                        Fate::Dropped => Outcome::Dropped,
                        Fate::CrcError => Outcome::CrcError,
                        Fate::AckError => Outcome::AckError,
                    },
                });
            } else {
                self.counters.events_lost += 1;
            }
        }
    }

    /// Brings back every recovering node whose 128th recessive sequence ends at a bit
    /// for which `reached` holds.
    fn settle_recoveries(&mut self, reached: impl Fn(u64) -> bool) {
        let recessive_since = self.recessive_since_bits;
        for slot in &mut self.nodes {
            let Some(done) = slot
                .bus_off
                .and_then(|off| off.completion_bit(recessive_since))
            else {
                continue;
            };
            if reached(done) {
                slot.bus_off = None;
                slot.counters = ErrorCounters::default();
                slot.eligible_from_bits = done;
                slot.stats.recoveries += 1;
            }
        }
    }
}

/// Takes `slot` off the bus; with automatic recovery it counts recessive sequences from
/// `recessive_from_bits`.
fn enter_bus_off(slot: &mut NodeSlot, recessive_from_bits: u64) {
    slot.stats.bus_off_events += 1;
    slot.bus_off = Some(BusOff {
        counting_since: (slot.config.bus_off_recovery == BusOffRecovery::Automatic)
            .then_some(recessive_from_bits),
        sequences: 0,
    });
}

impl fmt::Debug for VirtualBus {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("VirtualBus")
            .field("bitrate", &self.timing.bitrate())
            .field("now_ns", &self.now_ns)
            .field(
                "nodes",
                &self.nodes.iter().map(|n| &n.name).collect::<Vec<_>>(),
            )
            .finish_non_exhaustive()
    }
}
