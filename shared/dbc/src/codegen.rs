//! Generates the `no_std`, allocation-free Rust codec for a DBC.
//!
//! The output is included by `autoplug-can`, which provides the runtime it calls
//! (`crate::codec`) and the scale arithmetic (`autoplug_scaling::LinearScale`). What it
//! generates: the `Node` enum, one enum per value table, one struct per message with typed
//! physical fields and `encode` / `decode` / `update_from`, a `Message` enum over all of
//! them, and a `MESSAGES` table describing every message and signal for generic tools.

use crate::model::*;
use std::collections::BTreeMap;

/// Why a database cannot be turned into the embedded codec.
#[derive(Clone, Debug, PartialEq)]
pub struct GenerateError {
    /// DBC line of the object concerned (0 when it has none).
    pub line: usize,
    /// What is wrong.
    pub message: String,
}

impl std::fmt::Display for GenerateError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.line > 0 {
            write!(f, "line {}: {}", self.line, self.message)
        } else {
            f.write_str(&self.message)
        }
    }
}

/// How a signal appears in Rust.
#[derive(Clone, Debug, PartialEq)]
enum FieldType {
    /// Physical value as `f32`.
    Scaled,
    /// A one-bit flag without a value table.
    Bool,
    /// A value table, as the named enum.
    Enum(String),
}

struct Field<'a> {
    signal: &'a Signal,
    ident: String,
    konst: String,
    ty: FieldType,
    raw_min: i64,
    raw_max: i64,
    start_raw: i64,
    /// COVESA VSS path (attribute `VssPath`).
    vss: String,
}

/// Generates the codec source for a validated database.
pub fn generate(db: &Database) -> Result<String, GenerateError> {
    let enums = collect_enums(db)?;
    let mut out = String::new();
    let w = &mut out;
    line(
        w,
        "// Generated from the DBC by autoplug-dbc. Do not edit: edit the DBC.",
    );
    line(w, "");

    emit_network(db, w)?;
    emit_nodes(db, w)?;
    emit_diagnostics(db, w)?;
    for (name, entries) in &enums {
        emit_enum(name, entries, w)?;
    }

    let mut specs = Vec::new();
    for m in db.messages.iter().filter(|m| is_signal_message(db, m)) {
        let fields = fields_of(db, m, &enums)?;
        emit_message(db, m, &fields, w)?;
        specs.push((m, fields));
    }
    check_vss_paths(db, &specs)?;
    emit_message_table(&specs, w)?;
    emit_message_enum(&specs, w);
    Ok(out)
}

fn line(w: &mut String, s: &str) {
    w.push_str(s);
    w.push('\n');
}

fn gen_err(line: usize, message: impl Into<String>) -> GenerateError {
    GenerateError {
        line,
        message: message.into(),
    }
}

/// `EngineRPM` -> `engine_rpm`, `WheelSpeedFL` -> `wheel_speed_fl`.
pub fn snake_case(name: &str) -> String {
    let chars: Vec<char> = name.chars().collect();
    let mut out = String::new();
    for (i, &c) in chars.iter().enumerate() {
        if c.is_ascii_uppercase() {
            let prev = i.checked_sub(1).map(|p| chars[p]);
            let next = chars.get(i + 1);
            let boundary = match prev {
                Some(p) if p.is_ascii_lowercase() || p.is_ascii_digit() => true,
                Some(p) if p.is_ascii_uppercase() => next.is_some_and(|n| n.is_ascii_lowercase()),
                _ => false,
            };
            if boundary && !out.ends_with('_') {
                out.push('_');
            }
            out.push(c.to_ascii_lowercase());
        } else if c.is_ascii_alphanumeric() {
            out.push(c);
        } else if !out.ends_with('_') && !out.is_empty() {
            out.push('_');
        }
    }
    out
}

/// A value description as a Rust identifier: `"Sixth"` -> `Sixth`, `"no request"` ->
/// `NoRequest`, `"1st"` -> `V1st`.
pub fn variant_ident(text: &str) -> String {
    let mut out = String::new();
    for word in text.split(|c: char| !c.is_ascii_alphanumeric()) {
        let mut chars = word.chars();
        if let Some(first) = chars.next() {
            out.push(first.to_ascii_uppercase());
            out.extend(chars);
        }
    }
    if out.chars().next().is_none_or(|c| c.is_ascii_digit()) {
        out.insert(0, 'V');
    }
    out
}

fn rust_str(s: &str) -> String {
    format!("{s:?}")
}

/// An `f32` literal that reads back as the nearest `f32` to the DBC's decimal value.
fn f32_lit(v: f64) -> String {
    let f = v as f32;
    let s = format!("{f:?}");
    if s.contains('.') || s.contains('e') || s.contains("inf") || s.contains("NaN") {
        s
    } else {
        format!("{s}.0")
    }
}

fn doc(w: &mut String, indent: &str, text: &str) {
    for l in text.lines() {
        let l = l.trim_end();
        if l.is_empty() {
            line(w, &format!("{indent}///"));
        } else {
            line(w, &format!("{indent}/// {l}"));
        }
    }
}

fn enum_name_for(db: &Database, s: &Signal) -> String {
    let mut mine: Vec<_> = s.value_descriptions.clone();
    mine.sort();
    for table in &db.value_tables {
        let mut theirs = table.entries.clone();
        theirs.sort();
        if theirs == mine {
            return table.name.clone();
        }
    }
    s.name.clone()
}

fn collect_enums(db: &Database) -> Result<BTreeMap<String, Vec<(i64, String)>>, GenerateError> {
    let mut enums: BTreeMap<String, Vec<(i64, String)>> = BTreeMap::new();
    for m in db.messages.iter().filter(|m| is_signal_message(db, m)) {
        for s in &m.signals {
            if s.value_descriptions.is_empty() {
                continue;
            }
            let name = enum_name_for(db, s);
            let mut entries = s.value_descriptions.clone();
            entries.sort();
            let mut variants = std::collections::HashSet::new();
            for (_, text) in &entries {
                if !variants.insert(variant_ident(text)) {
                    return Err(gen_err(
                        s.line,
                        format!(
                            "signal {}.{}: value descriptions give the Rust variant {} twice",
                            m.name,
                            s.name,
                            variant_ident(text)
                        ),
                    ));
                }
            }
            match enums.get(&name) {
                Some(existing) if *existing != entries => {
                    return Err(gen_err(s.line, format!("signal {}.{}: its value table differs from another signal's enum {name}; declare a VAL_TABLE_ for each", m.name, s.name)));
                }
                _ => {
                    enums.insert(name, entries);
                }
            }
        }
    }
    Ok(enums)
}

fn fields_of<'a>(
    db: &Database,
    m: &'a Message,
    enums: &BTreeMap<String, Vec<(i64, String)>>,
) -> Result<Vec<Field<'a>>, GenerateError> {
    if m.extended {
        return Err(gen_err(
            m.line,
            format!(
                "message {}: 29-bit identifiers are not part of the AutoPlug bus",
                m.name
            ),
        ));
    }
    let mut fields = Vec::new();
    for s in &m.signals {
        let what = format!("signal {}.{}", m.name, s.name);
        if s.byte_order != ByteOrder::LittleEndian {
            return Err(gen_err(s.line, format!("{what}: Motorola (@0) byte order is not supported by the generator; the catalogue is Intel (@1)")));
        }
        if s.multiplexing != Multiplexing::None {
            return Err(gen_err(
                s.line,
                format!("{what}: multiplexed signals are not supported by the generator"),
            ));
        }
        if s.length > 31 {
            return Err(gen_err(
                s.line,
                format!("{what}: {} bits is more than the generator's 31", s.length),
            ));
        }
        let (raw_min, raw_max) = s.raw_range();
        let ty = if !s.value_descriptions.is_empty() {
            let name = enum_name_for(db, s);
            debug_assert!(enums.contains_key(&name));
            FieldType::Enum(name)
        } else if s.length == 1 && s.factor == 1.0 && s.offset == 0.0 {
            FieldType::Bool
        } else {
            FieldType::Scaled
        };
        let start_raw = db
            .signal_attribute(s, "GenSigStartValue")
            .and_then(AttributeValue::as_int)
            .unwrap_or(0);
        if start_raw < raw_min || start_raw > raw_max {
            return Err(gen_err(s.line, format!("{what}: start value {start_raw} is outside {raw_min}..={raw_max}; give a GenSigStartValue inside the range")));
        }
        if let FieldType::Enum(_) = ty {
            if !s.value_descriptions.iter().any(|(v, _)| *v == start_raw) {
                return Err(gen_err(
                    s.line,
                    format!("{what}: start value {start_raw} has no value description"),
                ));
            }
        }
        let vss = match db.signal_attribute(s, "VssPath") {
            Some(AttributeValue::Str(path)) => path.clone(),
            _ => String::new(),
        };
        if !vss.is_empty() && !is_vss_path(&vss) {
            return Err(gen_err(s.line, format!("{what}: VssPath {vss:?} is not a VSS path (Vehicle.Branch.Leaf, letters and digits only)")));
        }
        let ident = snake_case(&s.name);
        fields.push(Field {
            signal: s,
            konst: ident.to_ascii_uppercase(),
            ident,
            ty,
            raw_min,
            raw_max,
            start_raw,
            vss,
        });
    }
    Ok(fields)
}

/// Where the DBC defines the `VssPath` attribute, every application signal has a path of
/// its own: a gateway publishing by VSS name must never merge two signals into one.
fn check_vss_paths(
    db: &Database,
    specs: &[(&Message, Vec<Field<'_>>)],
) -> Result<(), GenerateError> {
    if db
        .attribute_definition(AttributeObject::Signal, "VssPath")
        .is_none()
    {
        return Ok(());
    }
    let mut seen: BTreeMap<&str, String> = BTreeMap::new();
    for (m, fields) in specs {
        for f in fields {
            let what = format!("signal {}.{}", m.name, f.signal.name);
            if f.vss.is_empty() {
                return Err(gen_err(f.signal.line, format!("{what} has no VssPath: give it a VSS path, or one under Vehicle.Private.AutoPlug")));
            }
            if let Some(other) = seen.insert(&f.vss, what.clone()) {
                return Err(gen_err(
                    f.signal.line,
                    format!("{what}: VssPath {:?} is already {other}'s", f.vss),
                ));
            }
        }
    }
    Ok(())
}

/// Whether a text is a VSS path: `Vehicle` and at least one more dot-separated element,
/// each an ASCII letter followed by letters and digits.
fn is_vss_path(path: &str) -> bool {
    let mut parts = path.split('.');
    parts.next() == Some("Vehicle")
        && path.contains('.')
        && parts.all(|p| {
            p.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
                && p.chars().all(|c| c.is_ascii_alphanumeric())
        })
}

/// The message attribute `DiagKind` of the catalogue: what a diagnostic transport message
/// (ISO-TP frames, no application signals) is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum DiagKind {
    None,
    PhysicalRequest,
    PhysicalResponse,
    FunctionalRequest,
    ObdResponse,
}

const DIAG_KINDS: [(&str, DiagKind); 5] = [
    ("None", DiagKind::None),
    ("PhysicalRequest", DiagKind::PhysicalRequest),
    ("PhysicalResponse", DiagKind::PhysicalResponse),
    ("FunctionalRequest", DiagKind::FunctionalRequest),
    ("ObdResponse", DiagKind::ObdResponse),
];

/// UDS physical request identifiers are this plus the node number; responses add
/// [`DIAG_RESPONSE_BASE`] (spec section 4).
const DIAG_REQUEST_BASE: u32 = 0x700;
const DIAG_RESPONSE_BASE: u32 = 0x780;
/// The OBD-II functional request identifier and the ISO 15765-4 response range.
const OBD_FUNCTIONAL_ID: u32 = 0x7DF;
const OBD_RESPONSE_IDS: std::ops::RangeInclusive<u32> = 0x7E8..=0x7EF;

fn diag_kind(db: &Database, m: &Message) -> Result<DiagKind, GenerateError> {
    let Some(value) = db.message_attribute(m, "DiagKind") else {
        return Ok(DiagKind::None);
    };
    let found = match value {
        AttributeValue::Int(i) => usize::try_from(*i).ok().and_then(|i| DIAG_KINDS.get(i)),
        AttributeValue::Str(name) => DIAG_KINDS.iter().find(|(n, _)| n == name),
        AttributeValue::Float(_) => None,
    };
    found.map(|(_, kind)| *kind).ok_or_else(|| {
        gen_err(
            m.line,
            format!("message {}: DiagKind {value:?} is not one of None, PhysicalRequest, PhysicalResponse, FunctionalRequest, ObdResponse", m.name),
        )
    })
}

/// An application message: signals the codec encodes and decodes. The diagnostic
/// transport messages (attribute `DiagKind`) carry ISO-TP frames instead.
fn is_signal_message(db: &Database, m: &Message) -> bool {
    matches!(diag_kind(db, m), Ok(DiagKind::None))
}

/// The one node that receives a diagnostic message's `Data` signal.
fn sole_receiver(m: &Message) -> Option<&str> {
    match m.signals.as_slice() {
        [signal] if signal.receivers.len() == 1 => Some(signal.receivers[0].as_str()),
        _ => None,
    }
}

/// Checks the diagnostic transport messages against spec section 4 and emits their
/// identifiers: per node, the physical request and response identifiers and the OBD-II
/// response identifier, and the functional request identifier.
fn emit_diagnostics(db: &Database, w: &mut String) -> Result<(), GenerateError> {
    let mut functional = None;
    let mut per_node: BTreeMap<&str, [Option<u32>; 3]> = BTreeMap::new();
    for m in &db.messages {
        let kind = diag_kind(db, m)?;
        if kind == DiagKind::None {
            continue;
        }
        let err = |what: String| gen_err(m.line, format!("diagnostic message {}: {what}", m.name));
        let payload_ok = m.dlc == 8
            && matches!(m.signals.as_slice(), [s] if s.start_bit == 0 && s.length == 64 && s.byte_order == ByteOrder::LittleEndian);
        if !payload_ok {
            return Err(err(
                "must be 8 bytes with one 64-bit signal at bit 0 (the ISO-TP frame)".into(),
            ));
        }
        let sender = m.transmitters.first().map(String::as_str).unwrap_or("");
        let number_of = |name: &str| {
            db.nodes
                .iter()
                .find(|n| n.name == name)
                .and_then(|n| db.node_attribute(n, "DiagNodeNumber"))
                .and_then(AttributeValue::as_int)
                .filter(|&n| n > 0)
                .map(|n| n as u32)
        };
        let (node, slot, expected) = match kind {
            DiagKind::None => unreachable!(),
            DiagKind::FunctionalRequest => {
                if m.id != OBD_FUNCTIONAL_ID {
                    return Err(err(format!("the functional request identifier is 0x{OBD_FUNCTIONAL_ID:03X}, not 0x{:03X}", m.id)));
                }
                if functional.replace(m.id).is_some() {
                    return Err(err("a second functional request message".into()));
                }
                continue;
            }
            DiagKind::PhysicalRequest => {
                let node = sole_receiver(m)
                    .ok_or_else(|| err("a request must have exactly one receiving node".into()))?;
                let number = number_of(node)
                    .ok_or_else(|| err(format!("receiver {node} has no DiagNodeNumber")))?;
                (node, 0, Some(DIAG_REQUEST_BASE + number))
            }
            DiagKind::PhysicalResponse => {
                let number = number_of(sender)
                    .ok_or_else(|| err(format!("sender {sender} has no DiagNodeNumber")))?;
                (sender, 1, Some(DIAG_RESPONSE_BASE + number))
            }
            DiagKind::ObdResponse => {
                if !OBD_RESPONSE_IDS.contains(&m.id) {
                    return Err(err(format!(
                        "OBD-II responses use 0x7E8..=0x7EF (ISO 15765-4), not 0x{:03X}",
                        m.id
                    )));
                }
                (sender, 2, None)
            }
        };
        if let Some(expected) = expected {
            if m.id != expected {
                return Err(err(format!(
                    "identifier 0x{:03X}, but {node}'s node number gives 0x{expected:03X}",
                    m.id
                )));
            }
        }
        let ids = per_node.entry(node).or_default();
        if ids[slot].replace(m.id).is_some() {
            return Err(err(format!("{node} already has a message of this kind")));
        }
    }
    for n in &db.nodes {
        let numbered = db
            .node_attribute(n, "DiagNodeNumber")
            .and_then(AttributeValue::as_int)
            .is_some_and(|v| v > 0);
        let ids = per_node.get(n.name.as_str()).copied().unwrap_or_default();
        if numbered && (ids[0].is_none() || ids[1].is_none()) {
            return Err(gen_err(
                0,
                format!("node {} has a DiagNodeNumber but not both a DiagKind PhysicalRequest and PhysicalResponse message", n.name),
            ));
        }
    }
    if functional.is_none()
        && per_node.is_empty()
        && !db.nodes.iter().any(|n| {
            db.node_attribute(n, "DiagNodeNumber")
                .and_then(AttributeValue::as_int)
                .is_some_and(|v| v > 0)
        })
    {
        // A network without diagnostics: nothing to emit.
        return Ok(());
    }
    let functional =
        functional.ok_or_else(|| gen_err(0, "no DiagKind FunctionalRequest message (0x7DF)"))?;

    line(
        w,
        "/// The functional request identifier (OBD-II, and UDS requests to every ECU at once):",
    );
    line(w, "/// the DBC's `DiagKind` FunctionalRequest message.");
    line(
        w,
        &format!("pub const DIAG_FUNCTIONAL_REQUEST_ID: u16 = 0x{functional:03X};"),
    );
    line(w, "");
    line(w, "impl Node {");
    let methods = [
        ("UDS physical request identifier (0x700 + node number; `DiagKind` PhysicalRequest).", "diag_request_id"),
        ("UDS response identifier (0x780 + node number; `DiagKind` PhysicalResponse).", "diag_response_id"),
        ("OBD-II response identifier (ISO 15765-4; `DiagKind` ObdResponse), for the ECUs that\nown an OBD-II value.", "obd_response_id"),
    ];
    for (slot, (docs, name)) in methods.iter().enumerate() {
        doc(w, "    ", docs);
        line(
            w,
            &format!("    pub const fn {name}(self) -> Option<u16> {{"),
        );
        line(w, "        match self {");
        for n in &db.nodes {
            let v = match per_node.get(n.name.as_str()).and_then(|ids| ids[slot]) {
                Some(id) => format!("Some(0x{id:03X})"),
                None => "None".to_string(),
            };
            line(
                w,
                &format!("            Node::{} => {v},", variant_ident(&n.name)),
            );
        }
        line(w, "        }");
        line(w, "    }");
        line(w, "");
    }
    line(w, "}");
    line(w, "");
    Ok(())
}

fn emit_network(db: &Database, w: &mut String) -> Result<(), GenerateError> {
    let baud = db
        .network_attribute("Baudrate")
        .and_then(AttributeValue::as_int)
        .ok_or_else(|| gen_err(0, "the network has no integer Baudrate attribute"))?;
    line(
        w,
        "/// Bus bit rate in bit/s (network attribute `Baudrate`).",
    );
    line(w, &format!("pub const BAUDRATE: u32 = {baud};"));
    line(w, "");
    line(w, "/// The DBC `VERSION` string.");
    line(
        w,
        &format!("pub const DBC_VERSION: &str = {};", rust_str(&db.version)),
    );
    line(w, "");
    Ok(())
}

fn emit_nodes(db: &Database, w: &mut String) -> Result<(), GenerateError> {
    line(w, "/// A node on the bus (`BU_`).");
    line(
        w,
        "#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]",
    );
    line(w, "#[cfg_attr(feature = \"defmt\", derive(defmt::Format))]");
    line(w, "pub enum Node {");
    for n in &db.nodes {
        if let Some(c) = &n.comment {
            doc(w, "    ", c);
        }
        line(w, &format!("    {},", variant_ident(&n.name)));
    }
    line(w, "}");
    line(w, "");
    line(w, "impl Node {");
    line(w, "    /// Every node, in DBC order.");
    let all: Vec<String> = db
        .nodes
        .iter()
        .map(|n| format!("Node::{}", variant_ident(&n.name)))
        .collect();
    line(
        w,
        &format!(
            "    pub const ALL: [Node; {}] = [{}];",
            all.len(),
            all.join(", ")
        ),
    );
    // The ECUs are the nodes a tester can address: every list of them (the command line's,
    // the gateway's inventory, the fleet's) comes from here.
    let ecus: Vec<&Node> = db
        .nodes
        .iter()
        .filter(|n| {
            db.node_attribute(n, "DiagNodeNumber")
                .and_then(AttributeValue::as_int)
                .is_some_and(|num| num != 0)
        })
        .collect();
    line(w, "");
    line(
        w,
        "    /// The ECUs: the nodes with a diagnostic address (attribute `DiagNodeNumber`), in",
    );
    line(w, "    /// DBC order.");
    let list: Vec<String> = ecus
        .iter()
        .map(|n| format!("Node::{}", variant_ident(&n.name)))
        .collect();
    line(
        w,
        &format!(
            "    pub const ECUS: [Node; {}] = [{}];",
            list.len(),
            list.join(", ")
        ),
    );
    line(w, "");
    line(
        w,
        "    /// The ECUs' names as people type them (the DBC's names in lower case), for help",
    );
    line(w, "    /// texts and error messages.");
    let names: Vec<String> = ecus.iter().map(|n| n.name.to_lowercase()).collect();
    line(
        w,
        &format!(
            "    pub const ECU_NAMES: &'static str = {};",
            rust_str(&names.join(", "))
        ),
    );
    line(w, "");
    line(
        w,
        "    /// The node's name as people type it: the DBC's name in lower case (`cruise`).",
    );
    line(w, "    pub const fn short_name(self) -> &'static str {");
    line(w, "        match self {");
    for n in &db.nodes {
        line(
            w,
            &format!(
                "            Node::{} => {},",
                variant_ident(&n.name),
                rust_str(&n.name.to_lowercase())
            ),
        );
    }
    line(w, "        }");
    line(w, "    }");
    line(w, "");
    line(w, "    /// The node's name in the DBC.");
    line(w, "    pub const fn name(self) -> &'static str {");
    line(w, "        match self {");
    for n in &db.nodes {
        line(
            w,
            &format!(
                "            Node::{} => {},",
                variant_ident(&n.name),
                rust_str(&n.name)
            ),
        );
    }
    line(w, "        }");
    line(w, "    }");
    line(w, "");
    line(
        w,
        "    /// Diagnostic node number (attribute `DiagNodeNumber`); `None` for a node without",
    );
    line(w, "    /// a diagnostic address.");
    line(w, "    pub const fn diag_node_number(self) -> Option<u8> {");
    line(w, "        match self {");
    for n in &db.nodes {
        let num = db
            .node_attribute(n, "DiagNodeNumber")
            .and_then(AttributeValue::as_int)
            .unwrap_or(0);
        if !(0..=255).contains(&num) {
            return Err(gen_err(
                0,
                format!("node {}: DiagNodeNumber {num} does not fit a byte", n.name),
            ));
        }
        let v = if num == 0 {
            "None".to_string()
        } else {
            format!("Some(0x{num:02X})")
        };
        line(
            w,
            &format!("            Node::{} => {v},", variant_ident(&n.name)),
        );
    }
    line(w, "        }");
    line(w, "    }");
    line(w, "");
    line(w, "");
    network_dtc_method(db, w)?;
    node_ids_method(
        db,
        w,
        "Identifiers of the messages this node sends.",
        "transmitted_ids",
        |n, m| is_signal_message(db, m) && m.transmitters.contains(&n.name),
    );
    node_ids_method(
        db,
        w,
        "Identifiers of the messages with a signal this node receives: what its\nacceptance filters must let through for the application (the diagnostic identifiers\ncome on top: [`Node::diag_request_id`], [`DIAG_FUNCTIONAL_REQUEST_ID`]).",
        "received_ids",
        |n, m| is_signal_message(db, m) && m.signals.iter().any(|s| s.receivers.contains(&n.name)),
    );
    line(w, "}");
    line(w, "");
    Ok(())
}

/// `pub const fn network_dtc_codes(self) -> (u16, u16)`: the node's "lost communication"
/// and "invalid data" trouble codes (attributes `LostCommunicationDtc`, `InvalidDataDtc`, as
/// `U0100`), as the code's 16 bits without its failure type.
/// A DBC that defines neither attribute (a catalogue without trouble codes) gets no method.
fn network_dtc_method(db: &Database, w: &mut String) -> Result<(), GenerateError> {
    let attributes = ["LostCommunicationDtc", "InvalidDataDtc"];
    if db
        .nodes
        .iter()
        .all(|n| attributes.iter().all(|a| db.node_attribute(n, a).is_none()))
    {
        return Ok(());
    }
    line(
        w,
        "    /// The trouble codes recorded against this node as an input's sender: \"lost",
    );
    line(
        w,
        "    /// communication with\" and \"invalid data received from\" (attributes",
    );
    line(
        w,
        "    /// `LostCommunicationDtc` and `InvalidDataDtc`, SAE J2012's U-codes), as a DTC's",
    );
    line(w, "    /// high 16 bits: (`U0100` → `0xC100`, ...).");
    line(
        w,
        "    pub const fn network_dtc_codes(self) -> (u16, u16) {",
    );
    line(w, "        match self {");
    for n in &db.nodes {
        let code = |attribute: &str| -> Result<u16, GenerateError> {
            let text = match db.node_attribute(n, attribute) {
                Some(AttributeValue::Str(text)) => text.as_str(),
                _ => "",
            };
            u_code_bits(text).ok_or_else(|| {
                gen_err(
                    0,
                    format!(
                        "node {}: {attribute} must be a network trouble code such as \"U0100\"; it is \"{text}\"",
                        n.name
                    ),
                )
            })
        };
        let (lost, invalid) = (code("LostCommunicationDtc")?, code("InvalidDataDtc")?);
        line(
            w,
            &format!(
                "            Node::{} => (0x{lost:04X}, 0x{invalid:04X}),",
                variant_ident(&n.name)
            ),
        );
    }
    line(w, "        }");
    line(w, "    }");
    line(w, "");
    Ok(())
}

/// `U0100` → 0xC100: SAE J2012's letter (P, C, B, U) in the top two bits, then the four hex
/// digits' 14 bits (the first digit 0–3).
fn u_code_bits(text: &str) -> Option<u16> {
    let mut chars = text.chars();
    let system = match chars.next()? {
        'P' => 0,
        'C' => 1,
        'B' => 2,
        'U' => 3,
        _ => return None,
    };
    let digits = chars.as_str();
    if digits.len() != 4 || !digits.chars().all(|c| c.is_ascii_hexdigit()) {
        return None;
    }
    let value = u16::from_str_radix(digits, 16).ok()?;
    (value <= 0x3FFF).then_some((system << 14) | value)
}

/// `pub const fn NAME(self) -> &'static [u16]`: per node, the identifiers of the messages
/// `wanted` selects for it.
fn node_ids_method(
    db: &Database,
    w: &mut String,
    docs: &str,
    name: &str,
    wanted: impl Fn(&Node, &Message) -> bool,
) {
    doc(w, "    ", docs);
    line(
        w,
        &format!("    pub const fn {name}(self) -> &'static [u16] {{"),
    );
    line(w, "        match self {");
    for n in &db.nodes {
        let ids: Vec<String> = db
            .messages
            .iter()
            .filter(|m| wanted(n, m))
            .map(|m| format!("0x{:03X}", m.id))
            .collect();
        let node = variant_ident(&n.name);
        line(
            w,
            &format!("            Node::{node} => &[{}],", ids.join(", ")),
        );
    }
    line(w, "        }");
    line(w, "    }");
    line(w, "");
}

fn emit_enum(name: &str, entries: &[(i64, String)], w: &mut String) -> Result<(), GenerateError> {
    let ty = variant_ident(name);
    line(w, &format!("/// Value table `{name}`."));
    line(
        w,
        "#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]",
    );
    line(w, "#[cfg_attr(feature = \"defmt\", derive(defmt::Format))]");
    line(w, &format!("pub enum {ty} {{"));
    for (raw, text) in entries {
        line(w, &format!("    /// Raw {raw}: \"{text}\"."));
        line(w, &format!("    {},", variant_ident(text)));
    }
    line(w, "}");
    line(w, "");
    line(w, &format!("impl {ty} {{"));
    let all: Vec<String> = entries
        .iter()
        .map(|(_, t)| format!("{ty}::{}", variant_ident(t)))
        .collect();
    line(w, "    /// Every value, in raw order.");
    line(
        w,
        &format!(
            "    pub const ALL: [{ty}; {}] = [{}];",
            all.len(),
            all.join(", ")
        ),
    );
    line(w, "");
    line(w, "    /// The raw value on the bus.");
    line(w, "    pub const fn raw(self) -> i64 {");
    line(w, "        match self {");
    for (raw, text) in entries {
        line(
            w,
            &format!("            {ty}::{} => {raw},", variant_ident(text)),
        );
    }
    line(w, "        }");
    line(w, "    }");
    line(w, "");
    line(
        w,
        "    /// The value for a raw value, if the table defines it.",
    );
    line(w, "    pub const fn from_raw(raw: i64) -> Option<Self> {");
    line(w, "        match raw {");
    for (raw, text) in entries {
        line(
            w,
            &format!("            {raw} => Some({ty}::{}),", variant_ident(text)),
        );
    }
    line(w, "            _ => None,");
    line(w, "        }");
    line(w, "    }");
    line(w, "");
    line(w, "    /// The description the DBC gives this value.");
    line(w, "    pub const fn label(self) -> &'static str {");
    line(w, "        match self {");
    for (_, text) in entries {
        line(
            w,
            &format!(
                "            {ty}::{} => {},",
                variant_ident(text),
                rust_str(text)
            ),
        );
    }
    line(w, "        }");
    line(w, "    }");
    line(w, "}");
    line(w, "");
    Ok(())
}

fn emit_message(
    db: &Database,
    m: &Message,
    fields: &[Field],
    w: &mut String,
) -> Result<(), GenerateError> {
    let ty = variant_ident(&m.name);
    let cycle = db
        .message_attribute(m, "GenMsgCycleTime")
        .and_then(AttributeValue::as_int)
        .unwrap_or(0);
    let gap = db
        .message_attribute(m, "GenMsgDelayTime")
        .and_then(AttributeValue::as_int)
        .unwrap_or(0);
    let senders: Vec<String> = m
        .transmitters
        .iter()
        .map(|t| format!("Node::{}", variant_ident(t)))
        .collect();

    let bytes = if m.dlc == 1 { "byte" } else { "bytes" };
    let mut header = format!(
        "{} (0x{:03X}, {} {bytes}), sent by {} every {cycle} ms.",
        m.name,
        m.id,
        m.dlc,
        m.transmitters.join(" and ")
    );
    if let Some(c) = &m.comment {
        header.push_str("\n\n");
        header.push_str(c);
    }
    doc(w, "", &header);
    line(w, "#[derive(Clone, Copy, Debug, PartialEq)]");
    line(w, "#[cfg_attr(feature = \"defmt\", derive(defmt::Format))]");
    line(w, &format!("pub struct {ty} {{"));
    for f in fields {
        let s = f.signal;
        let mut text = match &f.ty {
            FieldType::Scaled => format!(
                "`{}` [{}], {}..={} (raw {}..={}, {} per bit).",
                s.name,
                if s.unit.is_empty() { "-" } else { &s.unit },
                f32_lit(s.min),
                f32_lit(s.max),
                f.raw_min,
                f.raw_max,
                f32_lit(s.factor)
            ),
            FieldType::Bool => format!("`{}`, one bit.", s.name),
            FieldType::Enum(e) => format!("`{}`, value table {e}.", s.name),
        };
        if let Some(c) = &s.comment {
            text.push(' ');
            text.push_str(c);
        }
        doc(w, "    ", &text);
        let rust_ty = match &f.ty {
            FieldType::Scaled => "f32".to_string(),
            FieldType::Bool => "bool".to_string(),
            FieldType::Enum(e) => variant_ident(e),
        };
        line(w, &format!("    pub {}: {rust_ty},", f.ident));
    }
    line(w, "}");
    line(w, "");

    line(w, &format!("impl {ty} {{"));
    line(w, "    /// CAN identifier (11-bit).");
    line(w, &format!("    pub const ID: u16 = 0x{:03X};", m.id));
    line(w, "    /// Name in the DBC.");
    line(
        w,
        &format!("    pub const NAME: &'static str = {};", rust_str(&m.name)),
    );
    line(
        w,
        "    /// Data length in bytes; a frame of any other length is rejected.",
    );
    line(w, &format!("    pub const DLC: usize = {};", m.dlc));
    line(w, "    /// Transmission period (`GenMsgCycleTime`).");
    line(w, &format!("    pub const CYCLE_TIME_MS: u32 = {cycle};"));
    line(
        w,
        "    /// Shortest time between two transmissions, on change included (`GenMsgDelayTime`).",
    );
    line(w, &format!("    pub const MIN_GAP_MS: u32 = {gap};"));
    line(w, "    /// Nodes that send it.");
    line(
        w,
        &format!(
            "    pub const SENDERS: &'static [Node] = &[{}];",
            senders.join(", ")
        ),
    );
    for f in fields {
        if f.ty == FieldType::Scaled {
            let s = f.signal;
            line(
                w,
                &format!(
                    "    /// Scale of `{}`: physical = raw * {} + {}.",
                    s.name,
                    f32_lit(s.factor),
                    f32_lit(s.offset)
                ),
            );
            line(
                w,
                &format!(
                    "    pub const {}: LinearScale = LinearScale::new({}, {}, {}, {});",
                    f.konst,
                    f32_lit(s.factor),
                    f32_lit(s.offset),
                    f.raw_min,
                    f.raw_max
                ),
            );
        }
    }
    line(w, "");
    line(
        w,
        "    /// The frame's data bytes. Scaled values are rounded to the nearest step and",
    );
    line(
        w,
        "    /// clamped to their valid range: an out-of-range value is never sent.",
    );
    line(
        w,
        &format!("    pub fn encode(&self) -> [u8; {}] {{", m.dlc),
    );
    line(w, "        let mut bits: u64 = 0;");
    for f in fields {
        let s = f.signal;
        let raw = match &f.ty {
            FieldType::Scaled => format!(
                "i64::from(Self::{}.to_raw_saturating(self.{}))",
                f.konst, f.ident
            ),
            FieldType::Bool => format!("i64::from(self.{})", f.ident),
            FieldType::Enum(_) => format!("self.{}.raw()", f.ident),
        };
        line(
            w,
            &format!(
                "        bits |= codec::insert({raw}, {}, {});",
                s.start_bit, s.length
            ),
        );
    }
    line(w, "        codec::store(bits)");
    line(w, "    }");
    line(w, "");
    line(
        w,
        "    /// Decodes a frame's data. Wrong length, or any signal with an invalid raw",
    );
    line(w, "    /// value, rejects the whole frame.");
    line(
        w,
        "    pub fn decode(data: &[u8]) -> Result<Self, DecodeError> {",
    );
    line(
        w,
        "        let bits = codec::load(data, Self::DLC, Self::NAME)?;",
    );
    line(w, "        Ok(Self {");
    for (i, f) in fields.iter().enumerate() {
        line(
            w,
            &format!("            {}: Self::decode_signal_{i}(bits)?,", f.ident),
        );
    }
    line(w, "        })");
    line(w, "    }");
    line(w, "");
    line(
        w,
        "    /// Updates each signal from a frame, keeping the last good value of any signal whose",
    );
    line(
        w,
        "    /// raw value is invalid (spec: receivers keep the last good value and count a",
    );
    line(
        w,
        "    /// fault). Returns the first problem found; a frame of the wrong length changes",
    );
    line(w, "    /// nothing.");
    line(
        w,
        "    pub fn update_from(&mut self, data: &[u8]) -> Result<(), DecodeError> {",
    );
    line(
        w,
        "        let bits = codec::load(data, Self::DLC, Self::NAME)?;",
    );
    line(w, "        let mut first_error = None;");
    for (i, f) in fields.iter().enumerate() {
        line(
            w,
            &format!("        match Self::decode_signal_{i}(bits) {{"),
        );
        line(w, &format!("            Ok(v) => self.{} = v,", f.ident));
        line(w, "            Err(e) => { first_error.get_or_insert(e); }");
        line(w, "        }");
    }
    line(w, "        first_error.map_or(Ok(()), Err)");
    line(w, "    }");
    for (i, f) in fields.iter().enumerate() {
        let s = f.signal;
        line(w, "");
        let (ret, body) = match &f.ty {
            FieldType::Scaled => (
                "f32".to_string(),
                format!(
                    "codec::scaled(&Self::{}, raw, Self::NAME, {})",
                    f.konst,
                    rust_str(&s.name)
                ),
            ),
            FieldType::Bool => ("bool".to_string(), "Ok(raw != 0)".to_string()),
            FieldType::Enum(e) => {
                let e = variant_ident(e);
                (e.clone(), format!("{e}::from_raw(raw).ok_or(DecodeError::UndefinedValue {{ message: Self::NAME, signal: {}, raw }})", rust_str(&s.name)))
            }
        };
        line(
            w,
            &format!("    fn decode_signal_{i}(bits: u64) -> Result<{ret}, DecodeError> {{"),
        );
        line(
            w,
            &format!(
                "        let raw = codec::extract(bits, {}, {}, {});",
                s.start_bit, s.length, s.signed
            ),
        );
        line(w, &format!("        {body}"));
        line(w, "    }");
    }
    line(w, "}");
    line(w, "");

    line(w, &format!("impl CanMessage for {ty} {{"));
    for konst in [
        "ID: u16",
        "NAME: &'static str",
        "DLC: usize",
        "CYCLE_TIME_MS: u32",
        "MIN_GAP_MS: u32",
        "SENDERS: &'static [Node]",
    ] {
        let name = konst.split(':').next().unwrap_or_default();
        line(w, &format!("    const {konst} = {ty}::{name};"));
    }
    line(
        w,
        "    fn decode_data(data: &[u8]) -> Result<Self, DecodeError> { Self::decode(data) }",
    );
    line(w, "    fn update_from_data(&mut self, data: &[u8]) -> Result<(), DecodeError> { self.update_from(data) }");
    line(
        w,
        "    fn frame(&self) -> Frame { Frame::from_catalogue(Self::ID, &self.encode()) }",
    );
    line(
        w,
        &format!("    fn into_message(self) -> Message {{ Message::{ty}(self) }}"),
    );
    line(
        w,
        &format!("    fn from_message(message: &Message) -> Option<Self> {{ match message {{ Message::{ty}(m) => Some(*m), #[allow(unreachable_patterns)] _ => None }} }}"),
    );
    line(w, "}");
    line(w, "");
    line(w, &format!("impl Default for {ty} {{"));
    line(
        w,
        "    /// Every signal at its start value (`GenSigStartValue`, else raw 0): what a",
    );
    line(w, "    /// receiver assumes before the first frame.");
    line(w, "    fn default() -> Self {");
    line(w, "        Self {");
    for f in fields {
        let v = match &f.ty {
            FieldType::Scaled => {
                format!("Self::{}.to_physical_unchecked({})", f.konst, f.start_raw)
            }
            FieldType::Bool => format!("{}", f.start_raw != 0),
            FieldType::Enum(e) => {
                let text = &f
                    .signal
                    .value_descriptions
                    .iter()
                    .find(|(v, _)| *v == f.start_raw)
                    .expect("checked in fields_of")
                    .1;
                format!("{}::{}", variant_ident(e), variant_ident(text))
            }
        };
        line(w, &format!("            {}: {v},", f.ident));
    }
    line(w, "        }");
    line(w, "    }");
    line(w, "}");
    line(w, "");
    Ok(())
}

fn emit_message_table(
    specs: &[(&Message, Vec<Field>)],
    w: &mut String,
) -> Result<(), GenerateError> {
    line(
        w,
        "/// Every message of the catalogue, in DBC order, for tools that handle them generically",
    );
    line(
        w,
        "/// (dashboard, logger, bus-load accounting, cross-checks).",
    );
    line(
        w,
        &format!("pub static MESSAGES: [MessageSpec; {}] = [", specs.len()),
    );
    for (m, fields) in specs {
        let ty = variant_ident(&m.name);
        line(w, "    MessageSpec {");
        line(w, &format!("        id: {ty}::ID,"));
        line(w, &format!("        name: {ty}::NAME,"));
        line(w, &format!("        dlc: {},", m.dlc));
        line(w, &format!("        senders: {ty}::SENDERS,"));
        line(w, &format!("        cycle_time_ms: {ty}::CYCLE_TIME_MS,"));
        line(w, &format!("        min_gap_ms: {ty}::MIN_GAP_MS,"));
        line(
            w,
            &format!(
                "        comment: {},",
                rust_str(m.comment.as_deref().unwrap_or(""))
            ),
        );
        line(w, "        signals: &[");
        for f in fields {
            let s = f.signal;
            let kind = match &f.ty {
                FieldType::Scaled => "SignalKind::Scaled",
                FieldType::Bool => "SignalKind::Bool",
                FieldType::Enum(_) => "SignalKind::Enum",
            };
            let receivers: Vec<String> = s
                .receivers
                .iter()
                .map(|r| format!("Node::{}", variant_ident(r)))
                .collect();
            let mut values = s.value_descriptions.clone();
            values.sort();
            let values: Vec<String> = values
                .iter()
                .map(|(v, t)| format!("({v}, {})", rust_str(t)))
                .collect();
            line(w, "            SignalSpec {");
            line(w, &format!("                name: {},", rust_str(&s.name)));
            line(w, &format!("                start_bit: {},", s.start_bit));
            line(w, &format!("                length: {},", s.length));
            line(w, &format!("                signed: {},", s.signed));
            line(
                w,
                &format!(
                    "                scale: LinearScale::new({}, {}, {}, {}),",
                    f32_lit(s.factor),
                    f32_lit(s.offset),
                    f.raw_min,
                    f.raw_max
                ),
            );
            line(w, &format!("                factor: {:?},", s.factor));
            line(w, &format!("                offset: {:?},", s.offset));
            line(w, &format!("                unit: {},", rust_str(&s.unit)));
            line(w, &format!("                kind: {kind},"));
            line(
                w,
                &format!("                values: &[{}],", values.join(", ")),
            );
            line(w, &format!("                start_raw: {},", f.start_raw));
            line(w, &format!("                vss: {},", rust_str(&f.vss)));
            line(
                w,
                &format!("                receivers: &[{}],", receivers.join(", ")),
            );
            line(
                w,
                &format!(
                    "                comment: {},",
                    rust_str(s.comment.as_deref().unwrap_or(""))
                ),
            );
            line(w, "            },");
        }
        line(w, "        ],");
        line(w, "    },");
    }
    line(w, "];");
    line(w, "");
    Ok(())
}

/// A method of `Message` whose body is one `match`, with an arm per message (`arm` gets the
/// message's index, type name and fields) and an optional catch-all arm.
fn match_method(
    w: &mut String,
    specs: &[(&Message, Vec<Field>)],
    docs: &str,
    signature: &str,
    scrutinee: &str,
    arm: impl Fn(usize, &str, &[Field]) -> String,
    otherwise: Option<&str>,
) {
    doc(w, "    ", docs);
    line(w, &format!("    {signature} {{"));
    line(w, &format!("        match {scrutinee} {{"));
    for (i, (m, fields)) in specs.iter().enumerate() {
        line(
            w,
            &format!("            {}", arm(i, &variant_ident(&m.name), fields)),
        );
    }
    if let Some(otherwise) = otherwise {
        line(w, &format!("            _ => {otherwise},"));
    }
    line(w, "        }");
    line(w, "    }");
    line(w, "");
}

/// `match index { 0 => …, 1 => …, _ => fallback }` over a message's signals.
fn per_signal(fields: &[Field], value: impl Fn(&Field) -> String, fallback: &str) -> String {
    let mut arms: Vec<String> = fields
        .iter()
        .enumerate()
        .map(|(i, f)| format!("{i} => {},", value(f)))
        .collect();
    arms.push(format!("_ => {fallback},"));
    format!("match index {{ {} }}", arms.join(" "))
}

fn emit_message_enum(specs: &[(&Message, Vec<Field>)], w: &mut String) {
    line(w, "/// Any message of the catalogue.");
    line(w, "#[derive(Clone, Copy, Debug, PartialEq)]");
    line(w, "#[cfg_attr(feature = \"defmt\", derive(defmt::Format))]");
    line(w, "pub enum Message {");
    for (m, _) in specs {
        let ty = variant_ident(&m.name);
        line(w, &format!("    /// See [`{ty}`]."));
        line(w, &format!("    {ty}({ty}),"));
    }
    line(w, "}");
    line(w, "");
    line(w, "impl Message {");
    match_method(
        w,
        specs,
        "Decodes a frame by identifier; unknown identifiers, wrong lengths and invalid\nraw values are errors.",
        "pub fn decode(id: u16, data: &[u8]) -> Result<Self, DecodeError>",
        "id",
        |_, ty, _| format!("{ty}::ID => {ty}::decode(data).map(Message::{ty}),"),
        Some("Err(DecodeError::UnknownId { id })"),
    );
    match_method(
        w,
        specs,
        "Updates from a frame of this message, keeping the last good value of each\ninvalid signal (see the typed `update_from`).",
        "pub fn update_from(&mut self, data: &[u8]) -> Result<(), DecodeError>",
        "self",
        |_, ty, _| format!("Message::{ty}(msg) => msg.update_from(data),"),
        None,
    );
    line(
        w,
        "    /// Every message at its start values, in DBC order.",
    );
    line(
        w,
        &format!("    pub fn all_defaults() -> [Message; {}] {{", specs.len()),
    );
    let defaults: Vec<String> = specs
        .iter()
        .map(|(m, _)| {
            let ty = variant_ident(&m.name);
            format!("Message::{ty}({ty}::default())")
        })
        .collect();
    line(w, &format!("        [{}]", defaults.join(", ")));
    line(w, "    }");
    line(w, "");
    match_method(
        w,
        specs,
        "CAN identifier.",
        "pub const fn id(&self) -> u16",
        "self",
        |_, ty, _| format!("Message::{ty}(_) => {ty}::ID,"),
        None,
    );
    match_method(
        w,
        specs,
        "Index of this message in [`MESSAGES`].",
        "pub const fn index(&self) -> usize",
        "self",
        |i, ty, _| format!("Message::{ty}(_) => {i},"),
        None,
    );
    line(w, "    /// Description of this message.");
    line(w, "    pub fn spec(&self) -> &'static MessageSpec {");
    line(w, "        &MESSAGES[self.index()]");
    line(w, "    }");
    line(w, "");
    match_method(
        w,
        specs,
        "Encodes into `buf` and returns the data length.",
        "pub fn encode_into(&self, buf: &mut [u8; 8]) -> usize",
        "self",
        |_, ty, _| {
            format!("Message::{ty}(msg) => {{ buf[..{ty}::DLC].copy_from_slice(&msg.encode()); {ty}::DLC }}")
        },
        None,
    );
    match_method(
        w,
        specs,
        "Signal `index` (in [`MessageSpec::signals`] order) as a number: the physical\nvalue of a scaled signal, 0 or 1 for a flag, the raw value of an enumeration.",
        "pub fn signal(&self, index: usize) -> Option<f32>",
        "self",
        |_, ty, fields| {
            let value = |f: &Field| match &f.ty {
                FieldType::Scaled => format!("Some(msg.{})", f.ident),
                FieldType::Bool => format!("Some(if msg.{} {{ 1.0 }} else {{ 0.0 }})", f.ident),
                FieldType::Enum(_) => format!("Some(msg.{}.raw() as f32)", f.ident),
            };
            format!("Message::{ty}(msg) => {},", per_signal(fields, value, "None"))
        },
        None,
    );
    match_method(
        w,
        specs,
        "Sets signal `index` from a number, the inverse of [`Message::signal`]. A scaled\nvalue is stored as given (encoding clamps it); a flag is set for values of 0.5\nand above; an enumeration takes the nearest raw value and refuses one the table\ndoes not define.",
        "pub fn set_signal(&mut self, index: usize, value: f32) -> Result<(), SignalError>",
        "self",
        |_, ty, fields| {
            let assign = |f: &Field| match &f.ty {
                FieldType::Scaled => format!("{{ msg.{} = value; Ok(()) }}", f.ident),
                FieldType::Bool => format!("{{ msg.{} = value >= 0.5; Ok(()) }}", f.ident),
                FieldType::Enum(e) => format!(
                    "{{ let raw = i64::from(round_half_away_from_zero(value)); msg.{} = {}::from_raw(raw).ok_or(SignalError::UndefinedValue {{ raw }})?; Ok(()) }}",
                    f.ident,
                    variant_ident(e)
                ),
            };
            let fallback = "Err(SignalError::NoSuchSignal { index })";
            format!("Message::{ty}(msg) => {},", per_signal(fields, assign, fallback))
        },
        None,
    );
    line(w, "}");
}
