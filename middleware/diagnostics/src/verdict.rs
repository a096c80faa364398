//! What a diagnostic routine concludes, and why.

use std::fmt;

use autoplug_can::Node;
use serde::Serialize;

/// A routine's conclusion about an ECU.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// The ECU's own messages never reached the gateway (or stopped): nothing to judge.
    NoData,
    /// Works as specified, as far as the traffic shows.
    Ok,
    /// The situation the routine judges never arose (no cruise engagement held long
    /// enough, no hard braking...): nothing to say either way. Above OK, so that an ECU
    /// whose own routine has had nothing to judge does not look proven.
    NotExercised,
    /// Past the first threshold: worth a look, not proof of a fault.
    Suspect,
    /// Past the fault threshold.
    Faulty,
}

impl Verdict {
    /// `ok`, `not exercised`, `suspect`, `faulty`, `no data`.
    pub fn name(self) -> &'static str {
        match self {
            Verdict::NoData => "no data",
            Verdict::Ok => "ok",
            Verdict::NotExercised => "not exercised",
            Verdict::Suspect => "suspect",
            Verdict::Faulty => "faulty",
        }
    }

    /// The verdict of a number against its two thresholds (above = worse).
    pub fn of(value: f64, suspect_above: f64, faulty_above: f64) -> Self {
        if value > faulty_above {
            Verdict::Faulty
        } else if value > suspect_above {
            Verdict::Suspect
        } else {
            Verdict::Ok
        }
    }
}

impl fmt::Display for Verdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// The stretch of bus time that justifies a finding, µs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub struct Window {
    /// Start, bus time in µs.
    pub from_us: u64,
    /// End, bus time in µs.
    pub to_us: u64,
}

impl fmt::Display for Window {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{:.2}-{:.2} s",
            self.from_us as f64 * 1e-6,
            self.to_us as f64 * 1e-6
        )
    }
}

/// One routine's finding about one ECU.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Finding {
    /// What was measured ("tracking error").
    pub routine: &'static str,
    /// The conclusion.
    pub verdict: Verdict,
    /// The number behind it (absent when the situation to judge never arose).
    pub value: Option<f64>,
    /// Its unit.
    pub unit: &'static str,
    /// Above this: suspect.
    pub suspect_above: f64,
    /// Above this: faulty.
    pub faulty_above: f64,
    /// Where in the traffic the number comes from.
    pub window: Option<Window>,
    /// In words, for a person.
    pub evidence: String,
}

/// Everything the diagnostics say about one ECU: its findings, the worst first.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EcuDiagnosis {
    /// The ECU.
    #[serde(serialize_with = "node_name")]
    pub ecu: Node,
    /// The worst of the findings (no data if the ECU was silent).
    pub verdict: Verdict,
    /// The findings, worst first.
    pub findings: Vec<Finding>,
}

pub(crate) fn node_name<S: serde::Serializer>(node: &Node, s: S) -> Result<S::Ok, S::Error> {
    s.serialize_str(node.name())
}

impl EcuDiagnosis {
    /// The finding that decides the verdict.
    pub fn headline(&self) -> Option<&Finding> {
        self.findings.first()
    }
}
