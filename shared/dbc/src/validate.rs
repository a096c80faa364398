//! Consistency checks a DBC must pass before code is generated from it. Each problem is
//! reported with the DBC line and the object it concerns.

use crate::model::*;
use std::collections::HashSet;
use std::fmt;

/// One inconsistency in a database.
#[derive(Clone, Debug, PartialEq)]
pub struct ValidationError {
    /// DBC line of the object concerned (0 when it has none).
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for ValidationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.line > 0 {
            write!(f, "line {}: {}", self.line, self.message)
        } else {
            f.write_str(&self.message)
        }
    }
}

/// Every inconsistency found, in file order (empty when the database is sound).
pub fn validate(db: &Database) -> Vec<ValidationError> {
    let mut errors = Vec::new();
    let mut err = |line: usize, message: String| errors.push(ValidationError { line, message });

    let mut node_names = HashSet::new();
    for node in &db.nodes {
        if !node_names.insert(node.name.as_str()) {
            err(0, format!("node {} is declared twice in BU_", node.name));
        }
    }
    let known_node = |n: &str| node_names.contains(n);

    let mut ids = HashSet::new();
    let mut names = HashSet::new();
    for m in &db.messages {
        let l = m.line;
        if !ids.insert((m.id, m.extended)) {
            err(
                l,
                format!("message {}: identifier 0x{:X} is used twice", m.name, m.id),
            );
        }
        if !names.insert(m.name.as_str()) {
            err(l, format!("message name {} is used twice", m.name));
        }
        let id_limit = if m.extended { 0x1FFF_FFFF } else { 0x7FF };
        if m.id > id_limit {
            err(
                l,
                format!(
                    "message {}: identifier 0x{:X} does not fit an {} identifier",
                    m.name,
                    m.id,
                    if m.extended { "29-bit" } else { "11-bit" }
                ),
            );
        }
        if m.dlc > 8 {
            err(
                l,
                format!(
                    "message {}: length {} bytes exceeds classic CAN's 8",
                    m.name, m.dlc
                ),
            );
        }
        for t in &m.transmitters {
            if !known_node(t) {
                err(
                    l,
                    format!("message {}: transmitter {t} is not a node in BU_", m.name),
                );
            }
        }

        let mut signal_names = HashSet::new();
        let mut used_bits: Vec<Option<&str>> = vec![None; usize::from(m.dlc) * 8];
        for s in &m.signals {
            let l = s.line;
            let what = format!("signal {}.{}", m.name, s.name);
            if !signal_names.insert(s.name.as_str()) {
                err(l, format!("{what} is declared twice"));
            }
            if s.length == 0 || s.length > 64 {
                err(l, format!("{what}: length {} bits is not 1..=64", s.length));
                continue;
            }
            if s.factor == 0.0 {
                err(l, format!("{what}: factor is zero"));
                continue;
            }
            for bit in s.bits() {
                match used_bits.get_mut(bit as usize) {
                    None => {
                        err(
                            l,
                            format!(
                                "{what}: bit {bit} lies beyond the message's {} bytes",
                                m.dlc
                            ),
                        );
                        break;
                    }
                    Some(Some(other)) => {
                        err(
                            l,
                            format!("{what}: bit {bit} is also used by signal {other}"),
                        );
                        break;
                    }
                    Some(slot) => *slot = Some(s.name.as_str()),
                }
            }
            if s.min > s.max {
                err(
                    l,
                    format!("{what}: minimum {} is above maximum {}", s.min, s.max),
                );
            }
            let (bit_lo, bit_hi) = s.bit_range();
            let (raw_lo, raw_hi) = s.raw_range();
            if !(s.min == 0.0 && s.max == 0.0) {
                let lo = (s.min - s.offset) / s.factor;
                let hi = (s.max - s.offset) / s.factor;
                let (lo, hi) = if lo <= hi { (lo, hi) } else { (hi, lo) };
                if lo < bit_lo as f64 - 1e-6 || hi > bit_hi as f64 + 1e-6 {
                    err(l, format!("{what}: range [{}|{}] needs raw {lo}..{hi}, but {} bits hold only {bit_lo}..={bit_hi}", s.min, s.max, s.length));
                }
            }
            if raw_lo > raw_hi {
                err(
                    l,
                    format!("{what}: range [{}|{}] contains no raw step", s.min, s.max),
                );
            }
            for (raw, text) in &s.value_descriptions {
                if *raw < raw_lo || *raw > raw_hi {
                    err(l, format!("{what}: value description {raw} \"{text}\" lies outside the valid raw range {raw_lo}..={raw_hi}"));
                }
            }
            for r in &s.receivers {
                if !known_node(r) {
                    err(l, format!("{what}: receiver {r} is not a node in BU_"));
                }
            }
            if let Some(v) = db.signal_attribute(s, "GenSigStartValue") {
                match v.as_int() {
                    Some(raw) if raw < raw_lo || raw > raw_hi => err(l, format!("{what}: GenSigStartValue {raw} lies outside the valid raw range {raw_lo}..={raw_hi}")),
                    Some(_) => {}
                    None => err(l, format!("{what}: GenSigStartValue {v:?} is not an integer raw value")),
                }
            }
        }
    }
    errors
}
