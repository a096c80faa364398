//! A deterministic, bit-timed simulation of the AutoPlug CAN bus: classic CAN, 11-bit
//! identifiers, 500 kbit/s by default. The virtual car runs its nine ECUs and the gateway
//! on it.
//!
//! ```
//! use autoplug_can::Frame;
//! use autoplug_virtual_bus::{AcceptanceFilter, BusConfig, VirtualBus};
//!
//! let mut bus = VirtualBus::new(BusConfig::default());
//! let cruise = bus.attach("Cruise", AcceptanceFilter::ids(&[0x008]));
//! let abs = bus.attach("ABS", AcceptanceFilter::ids(&[0x003, 0x004]));
//!
//! let speed = Frame::new(0x003, &[88]).unwrap();
//! bus.send(cruise, speed, 0).unwrap();
//! bus.run_until(1_000_000);
//!
//! let got = bus.recv(abs).unwrap();
//! assert_eq!((got.frame, got.from), (speed, cruise));
//! // Sent at once on the idle bus; received at the end of EOF: 44 + 8 bits unstuffed,
//! // 3 stuff bits, 2 µs each.
//! assert_eq!(got.t_ns, 110_000);
//! assert!(bus.recv(cruise).is_none()); // no loopback
//! ```
//!
//! # Model
//!
//! - **Time** is simulated nanoseconds (`u64`) on a grid of bit times anchored at t = 0
//!   (2000 ns at 500 kbit/s; any bit rate works). A frame's length is exact: its real bit
//!   sequence, CRC-15 and stuff bits included ([`frame_bits`]).
//! - **Sending**: [`VirtualBus::send`] queues a frame in the node's bounded transmit
//!   queue (overflow refused and counted). The node offers its lowest-identifier frame,
//!   like bxCAN's transmit-priority-by-identifier mailboxes. A frame sent at `t` on an idle
//!   bus starts at the first bit boundary at or after `t`; on a busy bus it waits for the
//!   current frame and its 3-bit intermission.
//! - **Arbitration**: all nodes ready at that bit offer their head frame; the lowest
//!   identifier wins and the bus is busy for its `total_with_ifs` bits.
//! - **Same identifier from two nodes** (AutoPlug's CruiseModeMsg 0x008 has two senders):
//!   identical frames (same data) go out as one frame, as on a real bus, and both senders
//!   count a success. Different data would be a bit error on a real bus; here the lowest
//!   [`NodeId`] sends and the others wait for the next arbitration, deterministically.
//!   Both cases count in [`BusStats::same_id_contentions`].
//! - **Receiving**: at the end of EOF every other node on the bus (not bus-off) whose
//!   [`AcceptanceFilter`] accepts the identifier gets a [`Delivered`] in its bounded
//!   receive queue (overrun counted), stamped with that time. A node never receives its
//!   own frame unless [`NodeConfig::loopback`]. The optional event log
//!   ([`VirtualBus::drain_events`]) is the bus monitor: every frame and error frame in
//!   time order, with its receivers.
//! - **Faults** ([`FaultRule`]): drop (occupies the bus, acknowledged, nobody gets it),
//!   corrupt (CRC error: error frame, TEC + 8, REC + 1, automatic retransmission),
//!   silence a node ([`VirtualBus::set_silenced`]) or put it bus-off
//!   ([`VirtualBus::force_bus_off`]). A node alone on the bus gets ACK errors.
//! - **Error confinement** per ISO 11898-1: error-active / error-passive (TEC or REC
//!   above 127, 8 bits suspend transmission) / bus-off (TEC above 255), recovery after
//!   128 × 11 recessive bits, automatic (bxCAN ABOM) or on request.
//! - **Statistics**: per identifier, per node and for the bus, including load over fixed
//!   windows; [`VirtualBus::report`] prints them.
//! - **Determinism**: no wall clock, no hash-ordered iteration, one seeded xorshift
//!   generator; the same calls give the same results on every machine.
//! - **Speed**: no allocation per frame once the queues exist; O(nodes) work per frame.
//!
//! Simplifications, each documented where it applies: error flags are modelled as
//! active (some receiver is error-active), a corruption is always a CRC error seen by all
//! receivers, the "REC + 8 for a dominant bit after the error flag" rule is not applied,
//! and overload frames do not occur.
#![deny(missing_docs)]

mod bus;
mod fault;
mod node;
mod stats;
mod timing;

pub use bus::{BusConfig, BusEvent, Delivered, Outcome, Transmitted, TxError, VirtualBus};
pub use fault::{FaultAction, FaultId, FaultRule, Trigger};
pub use node::{
    AcceptanceFilter, BusOffRecovery, ErrorState, MaskFilter, NodeConfig, NodeId, NodeSet,
    NodeStatus, MAX_NODES,
};
pub use stats::{BusStats, IdStats, NodeStats, Report};
pub use timing::{
    frame_bits, BitTiming, FrameBits, DEFAULT_BITRATE, INTERMISSION_BITS, STUFFED_REGION_BASE_BITS,
    TAIL_BITS,
};
