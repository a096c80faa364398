//! The live table: the car's decoded signals and bus counters as the dashboard streams them,
//! each entry stamped with the version that last changed it.
//!
//! The gateway's pipeline publishes into it (a few microseconds, under a short lock; it
//! never waits for a client), and each client's task takes what changed since the version
//! it last sent. A slow client therefore gets fewer, larger updates — the latest value of
//! each signal, never a backlog — and memory does not depend on the number of clients or
//! on how far behind they are.

use std::fmt::Write as _;
use std::sync::Mutex;

use autoplug_gateway::{CarState, SignalState};
use serde::Serialize;
use tokio::sync::watch;

/// One signal as the table keeps it.
#[derive(Clone, Debug, PartialEq)]
struct Entry {
    /// Its COVESA VSS path: the key of the stream.
    path: &'static str,
    /// Latest value, `None` while stale or never received.
    value: Option<f64>,
    /// Version that last changed it.
    changed: u64,
}

/// The bus counters streamed with the signals.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct BusFigures {
    /// Frames received.
    pub frames: u64,
    /// Error frames.
    pub error_frames: u64,
    /// Frames of identifiers outside the catalogue.
    pub unknown_frames: u64,
    /// Diagnostic transport frames.
    pub diagnostic_frames: u64,
    /// CAN FD frames: counted, and left out of everything else (a classic bus cannot
    /// carry them; they come from logs of other buses).
    pub fd_frames: u64,
    /// Bus load over the last second or more of bus time, percent of the bit rate: the
    /// frames' exact lengths on the wire, stuff bits and intermission included (`None`
    /// until a second has passed).
    pub load_percent: Option<f64>,
}

/// One catalogue message's reception, as the raw bus view shows it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct MessageEntry {
    name: &'static str,
    id: u16,
    dlc: u8,
    count: u64,
    wrong_length: u64,
    invalid: u64,
    period_ms: Option<f64>,
    jitter_ms: Option<f64>,
    /// Bus time of the latest frame, µs.
    last_us: Option<u64>,
    data: [u8; 8],
    changed: u64,
}

#[derive(Debug, Default)]
struct Table {
    version: u64,
    bus_time_us: u64,
    entries: Vec<Entry>,
    messages: Vec<MessageEntry>,
    bus: BusFigures,
    bus_changed: u64,
    /// The session's own state (verdicts, codes, jobs, recording...) as a JSON object,
    /// written by the session whole; empty until it first does.
    session: String,
    session_changed: u64,
    /// The debuggers of the virtual car's emulated ECUs (`--gdb`) as a JSON object,
    /// written from outside the pipeline (which stands still while a debugger holds the
    /// car); empty without any.
    debugger: String,
    debugger_changed: u64,
    /// The ECUs a debugger holds halted now (from the same object).
    halted_by_debugger: Vec<String>,
    /// Where the bus load was last measured from: bus time (µs) and wire bits so far.
    load_from: Option<(u64, u64)>,
}

/// The live table (see the module docs).
#[derive(Debug)]
pub struct LiveTable {
    table: Mutex<Table>,
    version: watch::Sender<u64>,
    /// The simulator's world, streamed beside the signals (never written by the
    /// pipeline: see [`crate::world`]).
    world: std::sync::Arc<crate::world::WorldChannel>,
    /// Every signal's history since the session began (the plots look back at it).
    history: crate::history::History,
    /// The last frames as they came (the Bus view's trace).
    trace: crate::trace::Trace,
    /// Bits on the wire of every frame taken so far (for the bus load).
    wire_bits: std::sync::atomic::AtomicU64,
}

/// A signal of the catalogue, as the stream's first message describes it.
#[derive(Clone, Debug, Serialize)]
pub struct SignalInfo {
    /// COVESA VSS path (the key in updates).
    pub path: &'static str,
    /// `Message.Signal`, as in the DBC file.
    pub name: String,
    /// Unit of the value.
    pub unit: &'static str,
    /// The message's cycle time, ms.
    pub cycle_ms: u32,
    /// Value table of an enumeration: raw value and label.
    pub labels: Vec<(i64, &'static str)>,
}

/// A message of the catalogue, as the stream's first message describes it.
#[derive(Clone, Debug, Serialize)]
pub struct MessageInfo {
    /// Name in the DBC.
    pub name: &'static str,
    /// 11-bit identifier.
    pub id: u16,
    /// Data length, bytes.
    pub dlc: u8,
    /// Cycle time, ms (a message is overdue after 3 of them).
    pub cycle_ms: u32,
    /// The nodes that send it (DBC transmitters).
    pub senders: Vec<&'static str>,
}

impl Default for LiveTable {
    fn default() -> Self {
        Self::new()
    }
}

impl LiveTable {
    /// A table with every signal of the catalogue, none received yet.
    pub fn new() -> Self {
        let state = CarState::new();
        let entries: Vec<Entry> = state
            .signals()
            .iter()
            .map(|s| Entry {
                path: s.vss(),
                value: None,
                changed: 0,
            })
            .collect();
        let messages = autoplug_can::MESSAGES
            .iter()
            .map(|m| MessageEntry {
                name: m.name,
                id: m.id,
                dlc: m.dlc,
                ..MessageEntry::default()
            })
            .collect();
        let signals = entries.len();
        Self {
            table: Mutex::new(Table {
                entries,
                messages,
                ..Table::default()
            }),
            version: watch::channel(0).0,
            world: std::sync::Arc::new(crate::world::WorldChannel::new()),
            history: crate::history::History::new(signals),
            trace: crate::trace::Trace::new(),
            wire_bits: std::sync::atomic::AtomicU64::new(0),
        }
    }

    /// Every signal's history since the session began, in the catalogue's order.
    pub fn history(&self) -> &crate::history::History {
        &self.history
    }

    /// The last frames as they came.
    pub fn trace(&self) -> &crate::trace::Trace {
        &self.trace
    }

    /// Takes one frame in as it came: into the trace and the bus load (the signals come
    /// from the car state, at [`LiveTable::publish`]).
    pub fn note_frame(&self, frame: &autoplug_logs::LogFrame) {
        self.trace.push(frame);
        self.wire_bits
            .fetch_add(wire_bits(frame), std::sync::atomic::Ordering::Relaxed);
    }

    /// The world channel streamed beside the table: the virtual car's loop publishes the
    /// car's pose into it.
    pub fn world(&self) -> &std::sync::Arc<crate::world::WorldChannel> {
        &self.world
    }

    /// The catalogue's signals, in the table's order.
    pub fn catalog() -> Vec<SignalInfo> {
        CarState::new()
            .signals()
            .iter()
            .map(|s: &SignalState| SignalInfo {
                path: s.vss(),
                name: format!("{}.{}", s.message.name, s.spec.name),
                unit: s.spec.unit,
                cycle_ms: s.message.cycle_time_ms,
                labels: s.spec.values.to_vec(),
            })
            .collect()
    }

    /// The catalogue's messages.
    pub fn messages() -> Vec<MessageInfo> {
        autoplug_can::MESSAGES
            .iter()
            .map(|m| MessageInfo {
                name: m.name,
                id: m.id,
                dlc: m.dlc,
                cycle_ms: m.cycle_time_ms,
                senders: m.senders.iter().map(|n| n.name()).collect(),
            })
            .collect()
    }

    /// The stream's first message: `{"type":"catalog","signals":[…],"messages":[…]}`.
    pub fn catalog_message() -> serde_json::Value {
        serde_json::json!({
            "type": "catalog",
            "signals": Self::catalog(),
            "messages": Self::messages(),
        })
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Table> {
        // A panic elsewhere while holding the lock leaves plain data: keep serving it.
        self.table.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Takes the car state in: every signal whose value or freshness changed, and the bus
    /// counters, get the next version. Returns the version (unchanged if nothing changed).
    pub fn publish(&self, state: &CarState) -> u64 {
        let now = state.now_us();
        let counters = state.counters();
        let wire_bits = self.wire_bits.load(std::sync::atomic::Ordering::Relaxed);
        let mut table = self.lock();
        let mut load_percent = table.bus.load_percent;
        match table.load_from {
            Some((t, bits)) if now >= t && wire_bits >= bits => {
                if now - t >= 1_000_000 {
                    let seconds = (now - t) as f64 * 1e-6;
                    load_percent = Some(
                        100.0 * (wire_bits - bits) as f64
                            / (seconds * f64::from(autoplug_can::BAUDRATE)),
                    );
                    table.load_from = Some((now, wire_bits));
                }
            }
            // The first publication, or time gone back (a replay started over).
            _ => {
                table.load_from = Some((now, wire_bits));
                load_percent = None;
            }
        }
        let bus = BusFigures {
            frames: counters.frames,
            error_frames: counters.error_frames,
            unknown_frames: counters.unknown_frames,
            diagnostic_frames: counters.diagnostic_frames,
            fd_frames: counters.fd_frames,
            load_percent,
        };
        let next = table.version + 1;
        let mut changed = false;
        for (entry, signal) in table.entries.iter_mut().zip(state.signals()) {
            let value = signal.is_fresh(now).then_some(signal.value);
            if entry.value != value {
                entry.value = value;
                entry.changed = next;
                changed = true;
            }
        }
        for (entry, stats) in table.messages.iter_mut().zip(state.stats()) {
            if entry.count != stats.count || entry.wrong_length != stats.wrong_length {
                entry.count = stats.count;
                entry.wrong_length = stats.wrong_length;
                entry.invalid = stats.invalid;
                entry.period_ms = stats.recent_period_ms();
                entry.jitter_ms = stats.recent_jitter_ms();
                entry.last_us = stats.last_us;
                entry.data = stats.last_data;
                entry.changed = next;
                changed = true;
            }
        }
        if table.bus != bus {
            table.bus = bus;
            table.bus_changed = next;
            changed = true;
        }
        table.bus_time_us = now;
        if changed {
            table.version = next;
            self.version.send_replace(next);
        }
        let version = table.version;
        let values: Vec<Option<f64>> = table.entries.iter().map(|e| e.value).collect();
        drop(table);
        self.history.record(now, &values);
        version
    }

    /// Replaces the session's state (a JSON object: see the crate docs). Streamed only
    /// when its text changed; returns the version.
    pub fn set_session(&self, session: &serde_json::Value) -> u64 {
        let text = session.to_string();
        let mut table = self.lock();
        if table.session != text {
            table.session = text;
            table.session_changed = self.next_version(&mut table);
        }
        table.version
    }

    /// A new version of `table`, announced to the streams.
    fn next_version(&self, table: &mut Table) -> u64 {
        table.version += 1;
        self.version.send_replace(table.version);
        table.version
    }

    /// Replaces what the page shows of the debuggers (a JSON object: see the crate
    /// docs). Streamed only when its text changed; returns the version. Called from the
    /// thread that watches the GDB servers, not the pipeline's.
    pub fn set_debugger(&self, debugger: &serde_json::Value) -> u64 {
        let text = debugger.to_string();
        let mut table = self.lock();
        if table.debugger != text {
            table.halted_by_debugger = debugger["ecus"]
                .as_array()
                .into_iter()
                .flatten()
                .filter(|e| e["halted"] == true)
                .filter_map(|e| e["ecu"].as_str().map(str::to_string))
                .collect();
            table.debugger = text;
            table.debugger_changed = self.next_version(&mut table);
        }
        table.version
    }

    /// The ECUs a debugger holds halted now (the whole car stands still meanwhile).
    pub fn halted_by_debugger(&self) -> Vec<String> {
        self.lock().halted_by_debugger.clone()
    }

    /// The latest version.
    pub fn version(&self) -> u64 {
        self.lock().version
    }

    /// A receiver that wakes when the version changes.
    pub fn subscribe(&self) -> watch::Receiver<u64> {
        self.version.subscribe()
    }

    /// The update message with everything changed after version `since` (all of it for
    /// 0), and the version it brings the client to.
    pub fn update_since(&self, since: u64) -> (String, u64) {
        let table = self.lock();
        let mut json = String::with_capacity(64 + 40 * table.entries.len());
        let _ = write!(
            json,
            "{{\"type\":\"update\",\"version\":{},\"t\":{:.6},\"signals\":{{",
            table.version,
            table.bus_time_us as f64 / 1e6
        );
        let mut first = true;
        for entry in table
            .entries
            .iter()
            .filter(|e| since == 0 || e.changed > since)
        {
            if !first {
                json.push(',');
            }
            first = false;
            // VSS paths are dotted identifiers: no character needs escaping.
            let _ = match entry.value {
                Some(v) if v.is_finite() => write!(json, "\"{}\":{}", entry.path, v),
                _ => write!(json, "\"{}\":null", entry.path),
            };
        }
        json.push('}');
        let mut first = true;
        for m in table
            .messages
            .iter()
            .filter(|m| since == 0 || m.changed > since)
        {
            json.push_str(if first { ",\"messages\":{" } else { "," });
            first = false;
            let number = |v: Option<f64>| match v {
                Some(v) if v.is_finite() => format!("{v:.3}"),
                _ => "null".to_string(),
            };
            let data: String = m.data[..usize::from(m.dlc)]
                .iter()
                .map(|b| format!("{b:02X}"))
                .collect();
            // Message names are DBC identifiers: no character needs escaping.
            let _ = write!(
                json,
                "\"{}\":{{\"id\":{},\"count\":{},\"wrong_length\":{},\"invalid\":{},\"period_ms\":{},\"jitter_ms\":{},\"last_t\":{},\"data\":\"{}\"}}",
                m.name,
                m.id,
                m.count,
                m.wrong_length,
                m.invalid,
                number(m.period_ms),
                number(m.jitter_ms),
                number(m.last_us.map(|t| t as f64 * 1e-6)),
                data
            );
        }
        if !first {
            json.push('}');
        }
        if since == 0 || table.bus_changed > since {
            let _ = write!(
                json,
                ",\"bus\":{}",
                serde_json::to_string(&table.bus).unwrap_or_else(|_| "null".into())
            );
        }
        if !table.session.is_empty() && (since == 0 || table.session_changed > since) {
            json.push_str(",\"session\":");
            json.push_str(&table.session);
        }
        if !table.debugger.is_empty() && (since == 0 || table.debugger_changed > since) {
            json.push_str(",\"debugger\":");
            json.push_str(&table.debugger);
        }
        json.push('}');
        (json, table.version)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_catalogue_signal_has_a_unique_path() {
        let catalog = LiveTable::catalog();
        assert_eq!(catalog.len(), CarState::new().signals().len());
        let mut paths: Vec<_> = catalog.iter().map(|s| s.path).collect();
        paths.sort_unstable();
        paths.dedup();
        assert_eq!(paths.len(), catalog.len(), "VSS paths are unique");
        assert!(paths.iter().all(|p| p
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '.' || c == '_')));
    }

    #[test]
    fn an_empty_state_changes_nothing_after_the_first_publish() {
        let table = LiveTable::new();
        let state = CarState::new();
        assert_eq!(
            table.publish(&state),
            0,
            "nothing received: all null, as before"
        );
        let (json, version) = table.update_since(0);
        assert_eq!(version, 0);
        let parsed: serde_json::Value = serde_json::from_str(&json).expect("JSON");
        assert_eq!(parsed["type"], "update");
        assert!(parsed["signals"]["Vehicle.Speed"].is_null());
    }
}

/// Bus time between two publications of the [`Publisher`], µs: the fastest messages come
/// every 10 ms, so nothing a client could see is skipped, and a fast replay does not spend
/// its time comparing.
pub const PUBLISH_EVERY_US: u64 = 10_000;

/// The pipeline's observer that publishes the car state into a [`LiveTable`].
#[derive(Debug)]
pub struct Publisher {
    table: std::sync::Arc<LiveTable>,
    last_us: Option<u64>,
}

impl Publisher {
    /// Publishes into `table`.
    pub fn new(table: std::sync::Arc<LiveTable>) -> Self {
        Self {
            table,
            last_us: None,
        }
    }
}

/// The bits `frame` takes on the wire, intermission included: exact for a standard data
/// frame (its stuff bits counted from its real bit sequence); a remote, 29-bit, error or
/// CAN FD frame, which the AutoPlug bus does not send, at its length without stuff bits
/// (CAN FD's all at the nominal rate: a log does not say how fast its data phase went).
fn wire_bits(frame: &autoplug_logs::LogFrame) -> u64 {
    use autoplug_logs::FrameKind;
    if let Some(can) = frame.as_can_frame() {
        return u64::from(autoplug_virtual_bus::frame_bits(&can).total_with_ifs);
    }
    match frame.kind {
        // Error flag, its superposition and delimiter, intermission.
        FrameKind::Error => 6 + 6 + 8 + 3,
        FrameKind::Remote if frame.extended => 67,
        FrameKind::Remote => 47,
        FrameKind::Data if frame.extended => 67 + 8 * frame.len() as u64,
        FrameKind::Data => 47 + 8 * frame.len() as u64,
    }
}

impl autoplug_gateway::Observer for Publisher {
    fn on_frame(
        &mut self,
        frame: &autoplug_logs::LogFrame,
        _update: autoplug_gateway::Update,
        state: &CarState,
    ) {
        self.table.note_frame(frame);
        let now = state.now_us();
        if self
            .last_us
            .is_none_or(|last| now.saturating_sub(last) >= PUBLISH_EVERY_US || now < last)
        {
            self.table.publish(state);
            self.last_us = Some(now);
        }
    }

    fn on_idle(&mut self, state: &CarState) {
        self.table.publish(state);
    }
}
