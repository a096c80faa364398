//! Emulated MCUs as nodes of the virtual car's bit-timed bus (`autoplug-virtual-bus`):
//! each bxCAN's pending mailboxes are its node's transmit queue, an abort takes a frame
//! back, the bus's deliveries go through the bxCAN's own filters into its FIFOs, and the
//! node's error counters are the bxCAN's.
//!
//! [`run_together`] advances the bus and the MCUs in lockstep. The MCUs run to the next
//! moment the bus hands something over (the end of the frame on the wire) or at most
//! [`WINDOW_BITS`] ahead; their transmit requests then reach the bus at the simulated time
//! they were made, in time order across the MCUs, before the bus decides its next
//! arbitration. A window is shorter than the shortest frame, so a frame started inside a
//! window ends in a later one: every delivery and every transmit confirmation reaches an
//! MCU at the very time the bus completes it.

use autoplug_can::Frame;
use autoplug_virtual_bus::{
    AcceptanceFilter, BusOffRecovery, ErrorState, NodeConfig, NodeId, VirtualBus,
};

use crate::chip::can::CanFrame;
use crate::history::Input;
use crate::mcu::{Mcu, Stop};

/// The longest step the MCUs run ahead of the bus, in bit times: under the shortest frame
/// (a data frame without data: 44 bits from SOF to the end of EOF, the 3-bit intermission
/// not counted; an error frame is longer), so that a frame started inside a window ends
/// in a later one. 43 bits: 86 µs at 500 kbit/s. The longer the step, the less the MCUs'
/// bookkeeping costs per simulated second (most of them sleep through most windows).
pub const WINDOW_BITS: u64 = (autoplug_virtual_bus::FrameBits::unstuffed_with_ifs(0)
    - autoplug_virtual_bus::INTERMISSION_BITS) as u64
    - 1;

/// An emulated MCU on the bus.
pub struct BusNode {
    /// The MCU.
    pub mcu: Mcu,
    /// Its node on the bus.
    pub node: NodeId,
    /// The frame each mailbox has handed to the bus and not yet seen through, with the
    /// cycle of its transmit request (which tells it from a later request of the same
    /// mailbox, even one with the same frame).
    offered: [Option<(Frame, u64)>; 3],
}

impl BusNode {
    /// Attaches `mcu` to `bus` as `name`. The node hears every frame (the bxCAN filters),
    /// holds the three mailboxes' frames, and leaves bus-off by itself (bxCAN ABOM).
    pub fn attach(bus: &mut VirtualBus, name: &str, mut mcu: Mcu) -> Self {
        mcu.standalone_can = false;
        let node = bus.attach_with(
            name,
            AcceptanceFilter::All,
            NodeConfig {
                tx_queue_capacity: 3,
                rx_queue_capacity: 64,
                report_transmissions: true,
                bus_off_recovery: BusOffRecovery::Automatic,
                ..NodeConfig::default()
            },
        );
        BusNode {
            mcu,
            node,
            offered: [None; 3],
        }
    }

    /// Transmit requests the bus has not been given yet: (simulated ns of the request,
    /// mailbox, frame).
    fn new_requests(&self) -> Result<Vec<(u64, usize, Frame, u64)>, Stop> {
        let can = &self.mcu.chip.can1;
        if can.fifo_priority() {
            return Err(Stop::Unsupported("transmit priority by request order (CAN_MCR.TXFP) on the virtual bus, whose nodes send their lowest identifier first".into()));
        }
        let mut requests = Vec::new();
        for (mailbox, frame, cycle) in can.requests() {
            if self.offered[mailbox].is_some_and(|(_, at)| at == cycle) {
                continue;
            }
            if frame.extended || frame.remote {
                return Err(Stop::Unsupported(format!(
                    "{} frame {:#x}: the AutoPlug bus carries classic data frames with 11-bit identifiers",
                    if frame.extended { "an extended" } else { "a remote" },
                    frame.id
                )));
            }
            let len = usize::from(frame.dlc.min(8));
            let Ok(bus_frame) = Frame::new(frame.id, &frame.data[..len]) else {
                return Err(Stop::Unsupported(format!(
                    "frame {:#x} does not fit the bus",
                    frame.id
                )));
            };
            requests.push((self.mcu.chip.ns_at(cycle), mailbox, bus_frame, cycle));
        }
        Ok(requests)
    }

    /// Takes back from the bus the frames of mailboxes the firmware aborted, whether the
    /// mailbox is empty now or holds a request made since (the HAL aborts the
    /// lowest-priority frame to put a higher one in its place).
    fn withdraw_aborted(&mut self, bus: &mut VirtualBus) {
        let pending: Vec<(usize, u64)> = self
            .mcu
            .chip
            .can1
            .requests()
            .map(|(mailbox, _, cycle)| (mailbox, cycle))
            .collect();
        for mailbox in 0..3 {
            if let Some((frame, at)) = self.offered[mailbox] {
                if !pending.contains(&(mailbox, at)) {
                    // Aborted before the bus started it (an abort of the frame on the
                    // wire waits for its end in the bxCAN model).
                    bus.cancel(self.node, frame);
                    self.offered[mailbox] = None;
                }
            }
        }
    }

    /// What the bus did for this node: its frames' outcomes, the frames it received, its
    /// error counters.
    fn collect(&mut self, bus: &mut VirtualBus) {
        while let Some(done) = bus.transmitted(self.node) {
            if let Some(mailbox) = self
                .offered
                .iter()
                .position(|o| o.is_some_and(|(f, _)| f == done.frame))
            {
                if !done.retrying {
                    self.offered[mailbox] = None;
                }
                self.mcu.input(Input::CanComplete {
                    mailbox,
                    ok: done.ok,
                    retrying: done.retrying,
                });
            }
        }
        while let Some(delivered) = bus.recv(self.node) {
            let frame = delivered.frame;
            let mut data = [0u8; 8];
            data[..frame.len()].copy_from_slice(frame.data());
            self.mcu.input(Input::CanReceive(CanFrame {
                id: u32::from(frame.id()),
                extended: false,
                remote: false,
                dlc: frame.len() as u8,
                data,
            }));
        }
        let status = bus.node_status(self.node);
        self.mcu.input(Input::CanErrorState {
            tec: status.tec,
            rec: status.rec,
            bus_off: status.state == ErrorState::BusOff,
        });
    }
}

/// Runs `bus` and the emulated `nodes` together up to `until_ns`. On a stop, the index of
/// the node that stopped and why.
pub fn run_together(
    bus: &mut VirtualBus,
    nodes: &mut [BusNode],
    until_ns: u64,
) -> Result<(), (usize, Stop)> {
    let window_ns = bus.timing().bits_to_ns(WINDOW_BITS);
    loop {
        let now = bus.now_ns();
        if now >= until_ns {
            return Ok(());
        }
        let window_end = until_ns.min(now + window_ns);
        let next = match bus.wire_busy_until_ns() {
            Some(end) if end > now => window_end.min(end),
            _ => window_end,
        };
        let mut requests = Vec::new();
        for (i, node) in nodes.iter_mut().enumerate() {
            // The mailbox whose frame is on the wire for this window (the window ends
            // with it): an abort of it waits for its end.
            let on_wire = bus.transmitting(node.node).and_then(|frame| {
                node.offered
                    .iter()
                    .position(|o| o.is_some_and(|(f, _)| f == frame))
            });
            node.mcu.input(Input::CanSending(on_wire));
            node.mcu.run_until(next).map_err(|stop| (i, stop))?;
            node.withdraw_aborted(bus);
            for (at, mailbox, frame, cycle) in node.new_requests().map_err(|stop| (i, stop))? {
                requests.push((at.max(now), i, mailbox, frame, cycle));
            }
        }
        requests.sort_by_key(|&(at, i, mailbox, _, _)| (at, i, mailbox));
        for (at, i, mailbox, frame, cycle) in requests {
            let node = &mut nodes[i];
            // A mailbox is one frame: the node's queue (three) cannot overflow.
            if bus.send(node.node, frame, at).is_ok() {
                node.offered[mailbox] = Some((frame, cycle));
            }
        }
        bus.run_until(next);
        for node in nodes.iter_mut() {
            node.collect(bus);
        }
    }
}
