//! What a node on the bus is: its handle, acceptance filter, queue configuration and the
//! ISO 11898-1 fault-confinement counters.

use core::fmt;

/// Most nodes one bus carries: a [`NodeSet`] is one 64-bit word.
pub const MAX_NODES: usize = 64;

/// Handle of a node attached to a [`crate::VirtualBus`], in attach order from 0.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct NodeId(pub(crate) u8);

impl NodeId {
    /// Position in attach order.
    pub const fn index(self) -> usize {
        self.0 as usize
    }
}

impl fmt::Display for NodeId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "node{}", self.0)
    }
}

/// A set of nodes of one bus, e.g. the receivers of a frame.
#[derive(Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct NodeSet(u64);

impl NodeSet {
    /// No node.
    pub const EMPTY: Self = Self(0);

    /// Whether `node` is in the set.
    pub const fn contains(self, node: NodeId) -> bool {
        self.0 >> node.0 & 1 == 1
    }

    /// Adds `node`.
    pub fn insert(&mut self, node: NodeId) {
        self.0 |= 1 << node.0;
    }

    /// Number of nodes in the set.
    pub const fn len(self) -> usize {
        self.0.count_ones() as usize
    }

    /// Whether the set is empty.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The lowest node in the set.
    pub fn first(self) -> Option<NodeId> {
        (self.0 != 0).then(|| NodeId(self.0.trailing_zeros() as u8))
    }

    /// The nodes in ascending order.
    pub fn iter(self) -> impl Iterator<Item = NodeId> {
        let mut rest = self.0;
        core::iter::from_fn(move || {
            let first = (rest != 0).then(|| NodeId(rest.trailing_zeros() as u8))?;
            rest &= rest - 1;
            Some(first)
        })
    }
}

impl fmt::Debug for NodeSet {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_set().entries(self.iter().map(|n| n.0)).finish()
    }
}

impl FromIterator<NodeId> for NodeSet {
    fn from_iter<I: IntoIterator<Item = NodeId>>(iter: I) -> Self {
        let mut set = Self::EMPTY;
        for node in iter {
            set.insert(node);
        }
        set
    }
}

/// One bxCAN-style identifier/mask filter: a frame passes when
/// `frame_id & mask == id & mask` (mask bit 1 = "must match", 0 = "don't care").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct MaskFilter {
    /// Identifier to compare against.
    pub id: u16,
    /// Bits of the identifier that must match.
    pub mask: u16,
}

/// Which frames a node's controller hands to its software. Error detection, ACK and
/// error counting happen before filtering, for every frame, as in a real controller.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum AcceptanceFilter {
    /// Every frame (a gateway, a logger).
    All,
    /// Exactly these identifiers (bxCAN identifier-list mode).
    Ids(Vec<u16>),
    /// Any of these identifier/mask pairs (bxCAN mask mode).
    Masks(Vec<MaskFilter>),
}

impl AcceptanceFilter {
    /// Exactly these identifiers, e.g. `autoplug_can::Node::received_ids()`.
    pub fn ids(ids: &[u16]) -> Self {
        Self::Ids(ids.to_vec())
    }

    /// No frame: a node that only transmits.
    pub fn none() -> Self {
        Self::Ids(Vec::new())
    }

    /// Whether the filter lets `id` through.
    pub fn accepts(&self, id: u16) -> bool {
        match self {
            Self::All => true,
            Self::Ids(ids) => ids.contains(&id),
            Self::Masks(masks) => masks.iter().any(|m| id & m.mask == m.id & m.mask),
        }
    }
}

/// An acceptance filter flattened to one bit per 11-bit identifier, so a delivery costs
/// one lookup per node whatever the filter's shape.
#[derive(Clone)]
pub(crate) struct IdBitmap([u64; 32]);

impl IdBitmap {
    pub(crate) fn new(filter: &AcceptanceFilter) -> Self {
        let mut words = [0u64; 32];
        for id in 0..=autoplug_can::Frame::MAX_ID {
            if filter.accepts(id) {
                words[usize::from(id / 64)] |= 1 << (id % 64);
            }
        }
        Self(words)
    }

    pub(crate) fn contains(&self, id: u16) -> bool {
        self.0[usize::from(id / 64) & 31] >> (id % 64) & 1 == 1
    }
}

/// What a bus-off node does to come back (bxCAN's ABOM bit).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum BusOffRecovery {
    /// ABOM = 1: the controller rejoins by itself once it has seen 128 sequences of 11
    /// consecutive recessive bits (ISO 11898-1), at least 1408 bit times (2.8 ms at
    /// 500 kbit/s) on an idle bus, longer on a busy one.
    Automatic,
    /// ABOM = 0: the node stays bus-off until software asks
    /// ([`crate::VirtualBus::request_recovery`]), then the same 128 × 11 bits apply.
    Manual,
}

/// Per-node settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct NodeConfig {
    /// Frames the node can hold waiting for the bus, the one on the wire included.
    /// A `send` beyond that fails with [`crate::TxError::QueueFull`] and is counted.
    pub tx_queue_capacity: usize,
    /// Received frames held until `recv`; one more is an overrun: the new frame is lost
    /// and counted (bxCAN FIFO in locked mode).
    pub rx_queue_capacity: usize,
    /// Deliver the node's own frames back to it too (through its filter).
    pub loopback: bool,
    /// Retransmit after an error frame (bxCAN with NART = 0). Without it a failed
    /// frame is abandoned and counted in [`crate::NodeStats::tx_abandoned`].
    pub auto_retransmit: bool,
    /// How the node leaves bus-off.
    pub bus_off_recovery: BusOffRecovery,
    /// Keep a record of how each of the node's frames went on the wire, for
    /// [`crate::VirtualBus::transmitted`]: a CAN controller model needs it to set its
    /// mailboxes' status (an emulated bxCAN's TXOK, TERR).
    pub report_transmissions: bool,
}

impl Default for NodeConfig {
    fn default() -> Self {
        Self {
            tx_queue_capacity: 32,
            rx_queue_capacity: 32,
            loopback: false,
            auto_retransmit: true,
            bus_off_recovery: BusOffRecovery::Automatic,
            report_transmissions: false,
        }
    }
}

/// ISO 11898-1 fault-confinement state.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ErrorState {
    /// TEC and REC at most 127: sends active (dominant) error flags.
    Active,
    /// TEC or REC above 127: passive error flags, and 8 bits of suspend transmission
    /// after each of its own frames.
    Passive,
    /// TEC above 255: off the bus, neither sending nor receiving until recovery.
    BusOff,
}

/// A node's fault-confinement state and counters.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct NodeStatus {
    /// Active, passive or bus-off.
    pub state: ErrorState,
    /// Transmit error counter.
    pub tec: u16,
    /// Receive error counter.
    pub rec: u16,
    /// Whether fault injection has silenced the node's transmitter.
    pub silenced: bool,
}

/// Transmit and receive error counters with the ISO 11898-1 rules the simulation needs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct ErrorCounters {
    pub(crate) tec: u16,
    pub(crate) rec: u16,
}

impl ErrorCounters {
    const PASSIVE_ABOVE: u16 = 127;
    const BUS_OFF_ABOVE: u16 = 255;

    pub(crate) fn is_passive(&self) -> bool {
        self.tec > Self::PASSIVE_ABOVE || self.rec > Self::PASSIVE_ABOVE
    }

    pub(crate) fn is_bus_off(&self) -> bool {
        self.tec > Self::BUS_OFF_ABOVE
    }

    pub(crate) fn transmitted(&mut self) {
        self.tec = self.tec.saturating_sub(1);
    }

    /// An error while transmitting: +8, except an error-passive transmitter's ACK
    /// error (rule 3, exception 1), so a node alone on the bus stays error-passive
    /// instead of going bus-off.
    pub(crate) fn transmit_error(&mut self, ack_error: bool) {
        if !(ack_error && self.is_passive()) {
            self.tec += 8;
        }
    }

    pub(crate) fn received(&mut self) {
        // ISO 11898-1 sets a REC above 127 back to "between 119 and 127".
        self.rec = if self.rec > Self::PASSIVE_ABOVE {
            Self::PASSIVE_ABOVE
        } else {
            self.rec.saturating_sub(1)
        };
    }

    pub(crate) fn receive_error(&mut self) {
        self.rec = (self.rec + 1).min(Self::BUS_OFF_ABOVE);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mask_filters_work_like_bxcan() {
        // 0x020..=0x027: the differential's and cabin's block.
        let f = AcceptanceFilter::Masks(vec![MaskFilter {
            id: 0x020,
            mask: 0x7F8,
        }]);
        assert!((0x020..=0x027).all(|id| f.accepts(id)));
        assert!(!f.accepts(0x028) && !f.accepts(0x01F) && !f.accepts(0x420));
        let bitmap = IdBitmap::new(&f);
        assert!((0..=0x7FF).all(|id| bitmap.contains(id) == f.accepts(id)));
    }

    #[test]
    fn id_lists_and_extremes() {
        let f = AcceptanceFilter::ids(&[0x003, 0x7FF]);
        let bitmap = IdBitmap::new(&f);
        assert!(bitmap.contains(0x003) && bitmap.contains(0x7FF));
        assert_eq!((0..=0x7FF).filter(|&id| bitmap.contains(id)).count(), 2);
        assert!((0..=0x7FF).all(|id| IdBitmap::new(&AcceptanceFilter::All).contains(id)));
        assert!((0..=0x7FF).all(|id| !IdBitmap::new(&AcceptanceFilter::none()).contains(id)));
    }

    #[test]
    fn node_set_iterates_in_order() {
        let set: NodeSet = [NodeId(5), NodeId(0), NodeId(63)].into_iter().collect();
        assert_eq!(
            set.iter().collect::<Vec<_>>(),
            [NodeId(0), NodeId(5), NodeId(63)]
        );
        assert_eq!(set.len(), 3);
        assert_eq!(set.first(), Some(NodeId(0)));
        assert!(set.contains(NodeId(63)) && !set.contains(NodeId(1)));
    }

    #[test]
    fn error_counter_rules() {
        let mut c = ErrorCounters::default();
        for _ in 0..16 {
            c.transmit_error(false);
        }
        assert_eq!(c.tec, 128);
        assert!(c.is_passive() && !c.is_bus_off());
        c.transmit_error(true); // passive ACK error: no increment
        assert_eq!(c.tec, 128);
        c.transmitted();
        assert!(!c.is_passive());
        for _ in 0..17 {
            c.transmit_error(false);
        }
        assert!(c.is_bus_off());

        let mut r = ErrorCounters::default();
        for _ in 0..200 {
            r.receive_error();
        }
        assert!(r.is_passive());
        r.received();
        assert_eq!(r.rec, 127);
        assert!(!r.is_passive());
    }
}
