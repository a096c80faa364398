//! The ECUs' trouble codes as the bus shows them: every positive response to
//! ReadDTCInformation, reportDTCByStatusMask (UDS `59 02`), on an ECU's diagnostic response
//! identifier, reassembled from its ISO-TP frames by listening (the tester that asked sends
//! the flow control; the gateway or any other tool may be that tester). A log with the
//! requests and responses in it gives the same codes as the live bus, and each code comes
//! with its description from the ECUs' published definitions.

use autoplug_can::Node;
use autoplug_ecu::{invalid_data, lost_communication, Dtc};
use autoplug_gateway::{CarState, Observer, Update};
use autoplug_logs::LogFrame;
use serde::Serialize;

use crate::ecus;

/// One trouble code an ECU reported, with its status byte (ISO 14229-1 D.2).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct DtcEntry {
    /// The code (`U0104-87`).
    #[serde(serialize_with = "dtc_text")]
    pub dtc: Dtc,
    /// Its status bits.
    pub status: u8,
}

fn dtc_text<S: serde::Serializer>(dtc: &Dtc, s: S) -> Result<S::Ok, S::Error> {
    s.collect_str(dtc)
}

/// The latest report of one ECU.
#[derive(Clone, Debug, PartialEq, Eq, Serialize)]
pub struct EcuDtcs {
    /// The ECU.
    #[serde(serialize_with = "crate::verdict::node_name")]
    pub ecu: Node,
    /// Bus time of the response, µs.
    pub read_at_us: u64,
    /// Its codes, in the order it sent them.
    pub entries: Vec<DtcEntry>,
}

/// A response being put together from its frames.
#[derive(Default)]
struct Reassembly {
    expected: usize,
    payload: Vec<u8>,
    next_sequence: u8,
}

/// ISO-TP's longest payload on classic CAN (a 12-bit length).
const MAX_PAYLOAD: usize = 4095;

/// Listens for DTC reports: an [`Observer`] of the pipeline.
#[derive(Default)]
pub struct DtcMonitor {
    partial: Vec<(Node, Reassembly)>,
    latest: Vec<EcuDtcs>,
}

impl DtcMonitor {
    /// A monitor that has heard nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// The latest report of each ECU that sent one, in node order.
    pub fn latest(&self) -> &[EcuDtcs] {
        &self.latest
    }

    fn on_payload(&mut self, ecu: Node, t_us: u64, payload: &[u8]) {
        // 59 02 <availability mask> then 4 bytes per code: 3 of DTC, 1 of status.
        let [0x59, 0x02, _mask, records @ ..] = payload else {
            return;
        };
        if records.len() % 4 != 0 {
            return;
        }
        let entries = records
            .chunks_exact(4)
            .map(|r| DtcEntry {
                dtc: Dtc::from_u24(u32::from_be_bytes([0, r[0], r[1], r[2]])),
                status: r[3],
            })
            .collect();
        let report = EcuDtcs {
            ecu,
            read_at_us: t_us,
            entries,
        };
        match self.latest.iter_mut().find(|r| r.ecu == ecu) {
            Some(old) => *old = report,
            None => {
                self.latest.push(report);
                self.latest
                    .sort_by_key(|r| r.ecu.diag_node_number().unwrap_or(u8::MAX));
            }
        }
    }

    fn on_transport_frame(&mut self, ecu: Node, t_us: u64, data: &[u8]) {
        let Some(&pci) = data.first() else {
            return;
        };
        match pci >> 4 {
            0 => {
                let len = usize::from(pci & 0x0F);
                if (1..=7).contains(&len) && data.len() > len {
                    self.partial.retain(|(n, _)| *n != ecu);
                    self.on_payload(ecu, t_us, &data[1..=len]);
                }
            }
            1 => {
                let expected =
                    usize::from(pci & 0x0F) << 8 | usize::from(*data.get(1).unwrap_or(&0));
                self.partial.retain(|(n, _)| *n != ecu);
                if (8..=MAX_PAYLOAD).contains(&expected) && data.len() == 8 {
                    let mut payload = Vec::with_capacity(expected);
                    payload.extend_from_slice(&data[2..]);
                    self.partial.push((
                        ecu,
                        Reassembly {
                            expected,
                            payload,
                            next_sequence: 1,
                        },
                    ));
                }
            }
            2 => {
                let Some(i) = self.partial.iter().position(|(n, _)| *n == ecu) else {
                    return;
                };
                let r = &mut self.partial[i].1;
                if pci & 0x0F != r.next_sequence {
                    // A frame lost or out of order: this response cannot be trusted.
                    self.partial.remove(i);
                    return;
                }
                r.next_sequence = (r.next_sequence + 1) & 0x0F;
                let take = (r.expected - r.payload.len()).min(data.len() - 1);
                r.payload.extend_from_slice(&data[1..=take]);
                if r.payload.len() == r.expected {
                    let (_, done) = self.partial.remove(i);
                    self.on_payload(ecu, t_us, &done.payload);
                }
            }
            _ => {}
        }
    }
}

impl Observer for DtcMonitor {
    fn on_frame(&mut self, frame: &LogFrame, update: Update, _state: &CarState) {
        if update != Update::Diagnostic || frame.extended {
            return;
        }
        if let Some(ecu) = ecus().find(|n| n.diag_response_id().map(u32::from) == Some(frame.id)) {
            self.on_transport_frame(ecu, frame.t_us, frame.data());
        }
    }
}

/// What a code means, from the ECUs' published definitions (the DTC tables of
/// docs/src/ecus-and-bench.md).
pub fn describe(dtc: Dtc) -> String {
    for node in ecus() {
        if dtc == lost_communication(node) {
            return format!(
                "lost communication with the {} ECU (missing message)",
                node.name()
            );
        }
        if dtc == invalid_data(node) {
            return format!(
                "invalid data received from the {} ECU (signal invalid)",
                node.name()
            );
        }
    }
    if dtc == autoplug_ecu_params::trans::GEAR_NOT_ENGAGED {
        return "incorrect gear ratio: the commanded gear did not engage within 1 s".into();
    }
    const WHEELS: [&str; 4] = ["front left", "front right", "rear left", "rear right"];
    if let Some(i) = autoplug_ecu_params::abs::WHEEL_SENSOR_DTCS
        .iter()
        .position(|d| *d == dtc)
    {
        return format!(
            "{} wheel speed sensor implausible (signal plausibility failure): ABS off",
            WHEELS[i]
        );
    }
    let failure = match dtc.failure_type() {
        autoplug_ecu::FTB_MISSING_MESSAGE => "missing message",
        autoplug_ecu::FTB_SIGNAL_INVALID => "signal invalid",
        autoplug_ecu::FTB_SIGNAL_PLAUSIBILITY => "signal plausibility failure",
        _ => "failure type not known here",
    };
    format!("not an AutoPlug code ({failure})")
}
