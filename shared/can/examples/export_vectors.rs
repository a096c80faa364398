//! Writes, as JSON lines on stdout, what this codec believes about the catalogue, for an
//! independent tool to check (scripts/dbc-crosscheck.py does it with cantools):
//!
//! - one `"layout"` line per message: identifier, length, period, senders, and per signal
//!   its bits, signedness, factor, offset, valid range, unit and value table;
//! - `"frame"` lines: frames produced by the codec's encoders, with the raw and decoded
//!   values of every signal. Per message: the start values, each signal at both ends of
//!   its range, beyond them (clamped), at NaN, every value-table entry, and 200
//!   combinations from a fixed-seed generator, so every run writes the same file.
//!
//! - `"diag"` lines: per node, the diagnostic identifiers the codec derived (UDS request
//!   and response, OBD-II response), and the functional request identifier.
//!
//!     cargo run -p autoplug-can --example export_vectors > can-vectors.jsonl

use autoplug_can::{codec, Message, Node, SignalKind, DIAG_FUNCTIONAL_REQUEST_ID, MESSAGES};
use serde_json::{json, Map, Value};

/// xorshift64*: small, seeded, reproducible.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn frame_line(message: &Message, why: &str) -> Value {
    let spec = message.spec();
    let mut buf = [0u8; 8];
    let len = message.encode_into(&mut buf);
    let decoded = Message::decode(spec.id, &buf[..len]).expect("an encoded frame decodes");
    let bits = codec::load(&buf[..len], len, spec.name).expect("own length");
    let mut raw = Map::new();
    let mut physical = Map::new();
    for (i, signal) in spec.signals.iter().enumerate() {
        raw.insert(signal.name.into(), json!(signal.raw_in(bits)));
        physical.insert(signal.name.into(), json!(decoded.signal(i).unwrap() as f64));
    }
    let hex: String = buf[..len].iter().map(|b| format!("{b:02X}")).collect();
    json!({"kind": "frame", "message": spec.name, "id": spec.id, "data": hex,
           "why": why, "raw": raw, "physical": physical})
}

fn main() {
    for node in Node::ALL {
        println!(
            "{}",
            json!({"kind": "diag", "node": node.name(), "request": node.diag_request_id(),
                   "response": node.diag_response_id(), "obd_response": node.obd_response_id()})
        );
    }
    println!(
        "{}",
        json!({"kind": "functional", "id": DIAG_FUNCTIONAL_REQUEST_ID})
    );
    let mut rng = Rng(0x00A0_7091_2011_0001);
    for (index, spec) in MESSAGES.iter().enumerate() {
        let signals: Vec<Value> = spec
            .signals
            .iter()
            .map(|s| {
                json!({"name": s.name, "start_bit": s.start_bit, "length": s.length,
                       "signed": s.signed, "factor": s.factor, "offset": s.offset,
                       "raw_min": s.scale.raw_min(), "raw_max": s.scale.raw_max(),
                       "physical_min": s.scale.physical_min() as f64,
                       "physical_max": s.scale.physical_max() as f64,
                       "unit": s.unit, "start_raw": s.start_raw, "vss": s.vss,
                       "kind": format!("{:?}", s.kind),
                       "receivers": s.receivers.iter().map(|n| n.name()).collect::<Vec<_>>(),
                       "values": s.values.iter().map(|(v, t)| json!([v, t])).collect::<Vec<_>>()})
            })
            .collect();
        let senders: Vec<&str> = spec.senders.iter().map(|n| n.name()).collect();
        println!(
            "{}",
            json!({"kind": "layout", "message": spec.name, "id": spec.id, "dlc": spec.dlc,
                   "cycle_time_ms": spec.cycle_time_ms, "senders": senders, "signals": signals})
        );

        let start = Message::all_defaults()[index];
        println!("{}", frame_line(&start, "start values"));
        for (i, signal) in spec.signals.iter().enumerate() {
            let mut values: Vec<(f32, String)> = Vec::new();
            match signal.kind {
                SignalKind::Scaled => {
                    let (lo, hi) = (signal.scale.physical_min(), signal.scale.physical_max());
                    values.push((lo, "minimum".into()));
                    values.push((hi, "maximum".into()));
                    values.push(((lo + hi) / 2.0, "middle".into()));
                    values.push((lo - 1000.0, "below the range (clamped)".into()));
                    values.push((hi + 1000.0, "above the range (clamped)".into()));
                    values.push((f32::NAN, "NaN (neutral)".into()));
                }
                SignalKind::Bool => values.extend([(0.0, "off".into()), (1.0, "on".into())]),
                SignalKind::Enum => {
                    for (v, t) in signal.values {
                        values.push((*v as f32, format!("value {t}")));
                    }
                }
            }
            for (value, why) in values {
                let mut message = start;
                message.set_signal(i, value).expect("valid value");
                println!(
                    "{}",
                    frame_line(&message, &format!("{} {why}", signal.name))
                );
            }
        }
        for n in 0..200 {
            let mut message = start;
            for (i, signal) in spec.signals.iter().enumerate() {
                let value = match signal.kind {
                    SignalKind::Scaled => {
                        let (lo, hi) = (signal.scale.physical_min(), signal.scale.physical_max());
                        // Mostly inside the range, sometimes a little beyond it.
                        lo - (hi - lo) * 0.1 + (hi - lo) * 1.2 * rng.unit()
                    }
                    SignalKind::Bool => (rng.next() % 2) as f32,
                    SignalKind::Enum => {
                        signal.values[(rng.next() % signal.values.len() as u64) as usize].0 as f32
                    }
                };
                message.set_signal(i, value).expect("valid value");
            }
            println!(
                "{}",
                frame_line(&message, &format!("random combination {n}"))
            );
        }
    }
}
