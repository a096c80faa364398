//! The AutoPlug gateway's diagnostics: one routine per ECU, judged from the CAN traffic
//! alone, live or on a recorded log alike (they are [`Observer`]s of the one pipeline and
//! use only frame timestamps, so the same frames give the same verdicts).
//!
//! Each routine gives a [`Finding`]: a [`Verdict`] (ok, not exercised, suspect, faulty, no
//! data) with its
//! number, unit, thresholds and the time window that justifies it. Each routine's module
//! documentation says what it measures and why its thresholds are where they are. Every
//! ECU also gets the [`presence`] routine (its messages at their periods); an ECU whose
//! messages never arrived is "no data", whatever its other routines say.
//!
//! | module | ECU | measures |
//! |---|---|---|
//! | [`presence`] | all nine | longest gap between frames, in periods |
//! | [`ranges`] | all nine | frames with a value out of range or of the wrong length |
//! | [`cruise`] | cruise control | rms tracking error against the latched set speed |
//! | [`abs`] | ABS | longest wheel lock while braking |
//! | [`cabin`] | cabin comfort | longest time the fan worked against the temperature error |
//! | [`console`] | console | longest disagreement of the brake lights with the brake |
//! | [`differential`] | differential | torque split 0 under the hold conditions; split against the yaw-rate error |
//! | [`engine`] | engine | RPM against speed and gear; fuel never rising while driving |
//! | [`steering`] | steering | paddle requests as pulses: longest request, direct Up/Down changes; the angle's rate |
//! | [`transmission`] | transmission | time out of the shift schedule's band; shifts too soon, hunting |
//! | [`pedals`] | pedals | brake override of the accelerator; commands follow the cruise command |
//!
//! Besides the routines, [`dtcs`] reads the ECUs' trouble codes off the bus wherever a
//! tester (the gateway itself, when it may transmit) asked for them, with their descriptions,
//! and [`recognition`] says whether the bus is an AutoPlug car at all: verdicts on another
//! vehicle's bus judge its frames by a catalogue they do not follow.
#![deny(missing_docs)]
#![forbid(unsafe_code)]

pub mod abs;
pub mod cabin;
pub mod console;
pub mod cruise;
pub mod differential;
pub mod dtcs;
pub mod engine;
pub mod pedals;
pub mod presence;
pub mod ranges;
pub mod recognition;
mod span;
pub mod steering;
pub mod transmission;
mod verdict;

pub use dtcs::{describe as describe_dtc, DtcEntry, DtcMonitor, EcuDtcs};
pub use recognition::Recognition;
pub use verdict::{EcuDiagnosis, Finding, Verdict, Window};

use autoplug_can::Node;
use autoplug_gateway::{CarState, Observer, Update};
use autoplug_logs::LogFrame;
use serde::Serialize;

/// A diagnostic routine: watches frames, then says what it found about its ECU.
pub trait Routine {
    /// The ECU it judges.
    fn ecu(&self) -> Node;
    /// A frame, after the car state took it.
    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState);
    /// What it found so far (callable at any time, live).
    fn findings(&self, state: &CarState) -> Vec<Finding>;
}

/// The nine ECUs (the catalogue's nodes with a diagnostic address), in node-number order.
pub fn ecus() -> impl Iterator<Item = Node> {
    Node::ALL
        .into_iter()
        .filter(|n| n.diag_node_number().is_some())
}

/// An ECU the bus showed restarting: its positive response to an ECU reset (UDS 0x11),
/// as after a firmware update. What ran before is judged no more: its routines start over.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Restart {
    /// The ECU.
    #[serde(serialize_with = "verdict::node_name")]
    pub ecu: Node,
    /// Bus time of the response, µs.
    pub at_us: u64,
}

/// Every routine, as an observer of the pipeline.
pub struct Diagnostics {
    routines: Vec<Box<dyn Routine + Send>>,
    restarts: Vec<Restart>,
    tally: recognition::BusTally,
}

/// The routines that judge `node`: presence and ranges for every ECU, and its own.
fn routines_for(node: Node) -> Vec<Box<dyn Routine + Send>> {
    let mut routines: Vec<Box<dyn Routine + Send>> = vec![
        Box::new(presence::Presence::new(node)),
        Box::new(ranges::Ranges::new(node)),
    ];
    let own: Option<Box<dyn Routine + Send>> = match node {
        Node::Cruise => Some(Box::new(cruise::Cruise::default())),
        Node::ABS => Some(Box::new(abs::Abs::default())),
        Node::Console => Some(Box::new(console::Console::default())),
        Node::Engine => Some(Box::new(engine::Engine::default())),
        Node::Pedals => Some(Box::new(pedals::Pedals::default())),
        Node::Differential => Some(Box::new(differential::Differential::default())),
        Node::Cabin => Some(Box::new(cabin::Cabin::default())),
        Node::Transmission => Some(Box::new(transmission::Transmission::default())),
        Node::Steering => Some(Box::new(steering::Steering::default())),
        _ => None,
    };
    routines.extend(own);
    routines
}

/// Whether `frame` is `node`'s positive response to an ECU reset: an ISO-TP single frame
/// `0x51 sub` on its diagnostic response identifier.
fn is_reset_response(node: Node, frame: &LogFrame) -> bool {
    let data = frame.data();
    node.diag_response_id().map(u32::from) == Some(frame.id)
        && !frame.extended
        && data.len() >= 3
        && data[0] >> 4 == 0
        && data[0] & 0x0F >= 2
        && data[1] == 0x51
}

impl Default for Diagnostics {
    fn default() -> Self {
        Self::new()
    }
}

impl Diagnostics {
    /// The standard set: presence and ranges for every ECU and each ECU's own routines.
    pub fn new() -> Self {
        Self {
            routines: ecus().flat_map(routines_for).collect(),
            restarts: Vec::new(),
            tally: recognition::BusTally::default(),
        }
    }

    /// Whether the bus seen so far is an AutoPlug car (see [`recognition`]): the verdicts
    /// of [`Diagnostics::report`] mean something only if it is.
    pub fn recognition(&self) -> Recognition {
        self.tally.recognition()
    }

    /// The ECU restarts the bus showed, in order (each started its routines over).
    pub fn restarts(&self) -> &[Restart] {
        &self.restarts
    }

    /// Forgets what `ecu`'s routines judged so far: they start over from the next frame,
    /// as after the ECU's restart (a person's reset of a verdict that no longer holds).
    pub fn reset(&mut self, ecu: Node) {
        self.routines.retain(|r| r.ecu() != ecu);
        self.routines.extend(routines_for(ecu));
    }

    /// The diagnosis of every ECU at this moment.
    pub fn report(&self, state: &CarState) -> Vec<EcuDiagnosis> {
        ecus()
            .map(|ecu| {
                let mut findings: Vec<Finding> = self
                    .routines
                    .iter()
                    .filter(|r| r.ecu() == ecu)
                    .flat_map(|r| r.findings(state))
                    .collect();
                let silent = findings.iter().any(|f| f.verdict == Verdict::NoData);
                let common =
                    |f: &Finding| f.routine == presence::ROUTINE || f.routine == ranges::ROUTINE;
                // Suspect or faulty anywhere decides. Otherwise the ECU is OK only if one of
                // its own routines judged something and found it right; if none had anything
                // to judge, the ECU's function is not exercised (its messages being present
                // and in range proves nothing about it).
                let worst = findings
                    .iter()
                    .map(|f| f.verdict)
                    .max()
                    .unwrap_or(Verdict::Ok);
                let own_ok = findings
                    .iter()
                    .any(|f| !common(f) && f.verdict == Verdict::Ok);
                let verdict = if silent {
                    Verdict::NoData
                } else if worst == Verdict::NotExercised && own_ok {
                    Verdict::Ok
                } else {
                    worst
                };
                // The finding that decides first: no data (it overrides), then the worst,
                // then what the verdict says. Among equals, the ECU's own routines before
                // the checks every ECU gets: they say more about it.
                findings.sort_by_key(|f| {
                    let rank = match f.verdict {
                        Verdict::NoData => 0,
                        Verdict::Faulty => 1,
                        Verdict::Suspect => 2,
                        Verdict::NotExercised if verdict == Verdict::NotExercised => 3,
                        Verdict::Ok => 4,
                        Verdict::NotExercised => 5,
                    };
                    (rank, common(f))
                });
                EcuDiagnosis {
                    ecu,
                    verdict,
                    findings,
                }
            })
            .collect()
    }
}

impl Observer for Diagnostics {
    fn on_frame(&mut self, frame: &LogFrame, update: Update, state: &CarState) {
        self.tally.note(frame, update);
        if update == Update::Diagnostic {
            if let Some(node) = ecus().find(|n| is_reset_response(*n, frame)) {
                self.reset(node);
                self.restarts.push(Restart {
                    ecu: node,
                    at_us: frame.t_us,
                });
            }
        }
        for routine in &mut self.routines {
            routine.on_frame(frame, update, state);
        }
    }
}

#[cfg(test)]
mod tests;
