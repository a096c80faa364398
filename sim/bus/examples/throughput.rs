//! How fast the virtual bus runs the AutoPlug catalogue: the 18 periodic messages
//! (1 to 8 bytes, 10/20/100 ms) between the 9 ECUs and the gateway, each node filtering
//! exactly the identifiers it consumes, stepped every 1 ms like the virtual car.
//!
//! ```sh
//! cargo run --release -p autoplug-virtual-bus --example throughput [-- SIMULATED_SECONDS]
//! ```

use std::time::Instant;

use autoplug_can::{Frame, Node, MESSAGES};
use autoplug_virtual_bus::{
    frame_bits, AcceptanceFilter, BusConfig, FrameBits, NodeId, VirtualBus,
};

const MS: u64 = 1_000_000;

struct Periodic {
    id: u16,
    dlc: usize,
    period_ms: u64,
    sender: NodeId,
}

fn main() {
    let seconds: u64 = std::env::args()
        .nth(1)
        .map(|arg| arg.parse().expect("simulated seconds, a whole number"))
        .unwrap_or(10);

    println!("frame lengths of the catalogue (bits incl. 3-bit intermission):");
    println!(
        "{:>5} {:<16} {:>3} {:>9} {:>9} {:>9}",
        "id", "message", "dlc", "unstuffed", "all-zero", "max"
    );
    for m in &MESSAGES {
        let dlc = usize::from(m.dlc);
        let zero = Frame::new(u32::from(m.id), &[0; 8][..dlc]).expect("catalogue frame");
        println!(
            "0x{:03X} {:<16} {:>3} {:>9} {:>9} {:>9}",
            m.id,
            m.name,
            dlc,
            FrameBits::unstuffed_with_ifs(dlc),
            frame_bits(&zero).total_with_ifs,
            FrameBits::unstuffed_with_ifs(dlc) + FrameBits::max_stuff_bits(dlc)
        );
    }

    let mut bus = VirtualBus::new(BusConfig::default());
    let nodes: Vec<NodeId> = Node::ALL
        .iter()
        .map(|node| {
            let filter = match node {
                Node::Gateway => AcceptanceFilter::All,
                _ => AcceptanceFilter::ids(node.received_ids()),
            };
            bus.attach(node.name(), filter)
        })
        .collect();
    let schedule: Vec<Periodic> = MESSAGES
        .iter()
        .map(|m| {
            let sender = Node::ALL
                .iter()
                .position(|n| *n == m.senders[0])
                .expect("sender is a node");
            Periodic {
                id: m.id,
                dlc: usize::from(m.dlc),
                period_ms: u64::from(m.cycle_time_ms),
                sender: nodes[sender],
            }
        })
        .collect();

    // Payloads change every period, so stuffing varies as with real signals.
    let mut payload_state: u64 = 0x2545_F491_4F6C_DD1D;
    let mut next_payload = || {
        payload_state ^= payload_state << 13;
        payload_state ^= payload_state >> 7;
        payload_state ^= payload_state << 17;
        payload_state.to_le_bytes()
    };

    let mut delivered = 0u64;
    let started = Instant::now();
    for step in 0..seconds * 1000 {
        let now = step * MS;
        for p in &schedule {
            if step % p.period_ms == 0 {
                let frame =
                    Frame::new(u32::from(p.id), &next_payload()[..p.dlc]).expect("valid frame");
                bus.send(p.sender, frame, now).expect("queue has room");
            }
        }
        bus.run_until(now + MS);
        for &node in &nodes {
            while bus.recv(node).is_some() {
                delivered += 1;
            }
        }
    }
    let wall = started.elapsed().as_secs_f64();

    println!();
    print!("{}", bus.report());
    let frames = bus.bus_stats().frames;
    println!();
    println!(
        "{seconds} s simulated in {:.1} ms wall: {frames} frames ({delivered} deliveries), {:.0} frames/s of wall time, {:.0}x real time",
        wall * 1e3,
        frames as f64 / wall,
        seconds as f64 / wall
    );
}
