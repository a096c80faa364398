//! The car as the bus shows it: every signal of the catalogue with its value, unit, time
//! of last update and freshness, and per message its count, measured period and jitter,
//! invalid values and wrong lengths; plus what did not belong on the bus at all.
//!
//! Everything here is computed from frames and their timestamps only, so a live bus and a
//! recorded log of it give the same state at the same bus time.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};

use rustc_hash::FxHashMap;

use autoplug_can::{Message, MessageSpec, Node, SignalKind, SignalSpec, MESSAGES};
use autoplug_ecu::STALE_AFTER_PERIODS;
use autoplug_logs::{FrameKind, LogFrame};

/// Distinct unknown identifiers listed one by one; more are only counted, so a bus full of
/// foreign traffic cannot grow the state without bound.
pub const MAX_LISTED_UNKNOWN_IDS: usize = 64;

/// One signal's latest value.
#[derive(Clone, Copy, Debug)]
pub struct SignalState {
    /// Its message.
    pub message: &'static MessageSpec,
    /// The signal.
    pub spec: &'static SignalSpec,
    /// Latest valid value, in the DBC's unit (0/1 for flags, the raw value of an
    /// enumeration); the start value until the first valid frame.
    pub value: f64,
    /// Latest valid raw value.
    pub raw: i64,
    /// Bus time of the latest valid value, µs; `None` before the first.
    pub updated_us: Option<u64>,
    /// Frames whose raw value for this signal was outside its range or value table (the
    /// last good value was kept).
    pub invalid: u64,
}

impl SignalState {
    /// How long after its last update a signal counts as stale: 3 periods of its message,
    /// the rule every ECU applies to its own inputs (spec section 2).
    pub fn stale_after_us(&self) -> u64 {
        u64::from(self.message.cycle_time_ms) * 1000 * STALE_AFTER_PERIODS
    }

    /// Whether the value is fresh at bus time `now_us`.
    pub fn is_fresh(&self, now_us: u64) -> bool {
        self.updated_us
            .is_some_and(|t| now_us.saturating_sub(t) <= self.stale_after_us())
    }

    /// The value's label in the signal's value table, if it has one.
    pub fn label(&self) -> Option<&'static str> {
        match self.spec.kind {
            SignalKind::Enum => self.spec.label(self.raw),
            _ => None,
        }
    }

    /// The COVESA VSS path (DBC attribute `VssPath`).
    pub fn vss(&self) -> &'static str {
        self.spec.vss
    }
}

/// Reception statistics of one message.
#[derive(Clone, Copy, Debug)]
pub struct MessageStats {
    /// Frames received with the right length.
    pub count: u64,
    /// Frames with a data length other than the catalogue's (not decoded).
    pub wrong_length: u64,
    /// Frames with at least one invalid signal value.
    pub invalid: u64,
    /// Bus time of the first and the latest frame, µs.
    pub first_us: Option<u64>,
    /// Bus time of the latest frame, µs.
    pub last_us: Option<u64>,
    intervals: u64,
    mean_interval_us: f64,
    m2: f64,
    /// Shortest interval between two frames, µs.
    pub min_interval_us: Option<u64>,
    /// Longest interval between two frames, µs.
    pub max_interval_us: Option<u64>,
    /// Data of the latest frame of the right length (the catalogue's length of bytes of
    /// it), as it came: the raw view's "last data".
    pub last_data: [u8; 8],
    /// The last [`RECENT_INTERVALS`] intervals, µs (a ring; `recent_len` of them filled),
    /// for the period and jitter a live view shows: over the whole run, one gap (an ECU
    /// being flashed) would weigh on the jitter for ever after.
    recent: [u32; RECENT_INTERVALS],
    recent_len: u8,
    recent_next: u8,
}

/// Intervals the recent period and jitter are measured over.
pub const RECENT_INTERVALS: usize = 64;

impl Default for MessageStats {
    fn default() -> Self {
        Self {
            count: 0,
            wrong_length: 0,
            invalid: 0,
            first_us: None,
            last_us: None,
            intervals: 0,
            mean_interval_us: 0.0,
            m2: 0.0,
            min_interval_us: None,
            max_interval_us: None,
            last_data: [0; 8],
            recent: [0; RECENT_INTERVALS],
            recent_len: 0,
            recent_next: 0,
        }
    }
}

impl MessageStats {
    fn note(&mut self, t_us: u64) {
        if let Some(last) = self.last_us {
            if t_us >= last {
                // Welford's running mean and variance: one pass, constant memory.
                let dt = (t_us - last) as f64;
                self.intervals += 1;
                let delta = dt - self.mean_interval_us;
                self.mean_interval_us += delta / self.intervals as f64;
                self.m2 += delta * (dt - self.mean_interval_us);
                let dt = t_us - last;
                self.min_interval_us = Some(self.min_interval_us.map_or(dt, |m| m.min(dt)));
                self.max_interval_us = Some(self.max_interval_us.map_or(dt, |m| m.max(dt)));
                self.recent[usize::from(self.recent_next)] = u32::try_from(dt).unwrap_or(u32::MAX);
                self.recent_next = ((usize::from(self.recent_next) + 1) % RECENT_INTERVALS) as u8;
                self.recent_len = (usize::from(self.recent_len) + 1).min(RECENT_INTERVALS) as u8;
            }
        }
        self.first_us.get_or_insert(t_us);
        self.last_us = Some(self.last_us.map_or(t_us, |l| l.max(t_us)));
    }

    /// Mean interval between frames, ms (`None` before the second frame).
    pub fn period_ms(&self) -> Option<f64> {
        (self.intervals > 0).then(|| self.mean_interval_us / 1000.0)
    }

    /// Jitter: the standard deviation of the interval between frames, ms.
    pub fn jitter_ms(&self) -> Option<f64> {
        (self.intervals > 1).then(|| (self.m2 / (self.intervals - 1) as f64).sqrt() / 1000.0)
    }

    /// Mean interval over the last [`RECENT_INTERVALS`] intervals, ms.
    pub fn recent_period_ms(&self) -> Option<f64> {
        let recent = &self.recent[..usize::from(self.recent_len)];
        (!recent.is_empty()).then(|| {
            recent.iter().map(|&d| f64::from(d)).sum::<f64>() / recent.len() as f64 / 1000.0
        })
    }

    /// Standard deviation of the last [`RECENT_INTERVALS`] intervals, ms.
    pub fn recent_jitter_ms(&self) -> Option<f64> {
        let recent = &self.recent[..usize::from(self.recent_len)];
        let n = recent.len();
        if n < 2 {
            return None;
        }
        let mean = recent.iter().map(|&d| f64::from(d)).sum::<f64>() / n as f64;
        let m2: f64 = recent.iter().map(|&d| (f64::from(d) - mean).powi(2)).sum();
        Some((m2 / (n - 1) as f64).sqrt() / 1000.0)
    }
}

/// What reached the gateway that is not a catalogue message.
#[derive(Clone, Debug, Default)]
pub struct BusCounters {
    /// Frames of every kind, as received.
    pub frames: u64,
    /// Error frames.
    pub error_frames: u64,
    /// Remote frames.
    pub remote_frames: u64,
    /// Frames with a 29-bit identifier (not part of the AutoPlug bus).
    pub extended_frames: u64,
    /// CAN FD frames: a classic CAN bus such as AutoPlug's cannot carry them, so they are
    /// counted and left aside.
    pub fd_frames: u64,
    /// Diagnostic transport frames (UDS requests and responses, OBD-II).
    pub diagnostic_frames: u64,
    /// Standard frames whose identifier is not in the catalogue.
    pub unknown_frames: u64,
    /// The first [`MAX_LISTED_UNKNOWN_IDS`] unknown identifiers with their counts.
    pub unknown_ids: BTreeMap<u32, u64>,
    /// Frames whose timestamp was earlier than one already seen (kept, counted).
    pub time_backwards: u64,
}

/// Index of each standard identifier in [`MESSAGES`], for an O(1) look-up per frame.
struct IdIndex([u8; 2048]);

const NOT_IN_CATALOGUE: u8 = u8::MAX;

impl IdIndex {
    fn new() -> Self {
        let mut table = [NOT_IN_CATALOGUE; 2048];
        for (i, m) in MESSAGES.iter().enumerate() {
            table[usize::from(m.id)] = i as u8;
        }
        Self(table)
    }

    fn get(&self, id: u32) -> Option<usize> {
        let i = *self.0.get(id as usize)?;
        (i != NOT_IN_CATALOGUE).then_some(usize::from(i))
    }
}

/// Whether a standard identifier is a diagnostic transport one of the catalogue.
pub fn is_diagnostic_id(id: u32) -> bool {
    let Ok(id) = u16::try_from(id) else {
        return false;
    };
    id == autoplug_can::DIAG_FUNCTIONAL_REQUEST_ID
        || Node::ALL.iter().any(|n| {
            n.diag_request_id() == Some(id)
                || n.diag_response_id() == Some(id)
                || n.obd_response_id() == Some(id)
        })
}

/// A signal named in code (`Message.Signal` or its VSS path), looked up by name once and
/// by index ever after: routines that read signals on every frame keep these in statics.
///
/// ```
/// use autoplug_gateway::{CarState, SignalName};
/// static SPEED: SignalName = SignalName::new("VehicleSpeedMsg.VehicleSpeed");
/// let state = CarState::new();
/// assert_eq!(state.signal_named(&SPEED).map(|s| s.vss()), Some("Vehicle.Speed"));
/// ```
pub struct SignalName {
    name: &'static str,
    /// Index in the catalogue's signal order + 1; 0 until resolved.
    index: AtomicUsize,
}

impl SignalName {
    /// A name to resolve on first use.
    pub const fn new(name: &'static str) -> Self {
        Self {
            name,
            index: AtomicUsize::new(0),
        }
    }

    /// The name.
    pub fn name(&self) -> &'static str {
        self.name
    }
}

/// The result of taking one frame into the state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Update {
    /// A catalogue message: index in [`MESSAGES`]; `valid` when every signal was valid.
    Message {
        /// Index in [`MESSAGES`] and [`CarState::messages`].
        index: usize,
        /// Every signal in range.
        valid: bool,
    },
    /// A catalogue identifier with the wrong data length: counted, not decoded.
    WrongLength,
    /// A diagnostic transport frame.
    Diagnostic,
    /// An error frame.
    Error,
    /// Anything else (unknown, extended, remote or CAN FD): counted.
    Other,
}

/// The car state.
pub struct CarState {
    ids: IdIndex,
    messages: Vec<Message>,
    stats: Vec<MessageStats>,
    signals: Vec<SignalState>,
    /// Index of each message's first signal in `signals`.
    first_signal: Vec<usize>,
    counters: BusCounters,
    now_us: u64,
    started: bool,
    /// Index in `signals` of each signal by `Message.Signal` name and by VSS path: the
    /// routines look signals up by name on every frame, so this must not be a search.
    by_name: FxHashMap<String, usize>,
}

impl Default for CarState {
    fn default() -> Self {
        Self::new()
    }
}

impl CarState {
    /// The state before any frame: every signal at its start value, never updated.
    pub fn new() -> Self {
        let messages = Message::all_defaults().to_vec();
        let mut signals = Vec::new();
        let mut first_signal = Vec::new();
        for (spec, message) in MESSAGES.iter().zip(&messages) {
            first_signal.push(signals.len());
            for (i, s) in spec.signals.iter().enumerate() {
                signals.push(SignalState {
                    message: spec,
                    spec: s,
                    value: f64::from(message.signal(i).unwrap_or(0.0)),
                    raw: s.start_raw,
                    updated_us: None,
                    invalid: 0,
                });
            }
        }
        let mut by_name = FxHashMap::default();
        for (i, s) in signals.iter().enumerate() {
            by_name.insert(format!("{}.{}", s.message.name, s.spec.name), i);
            by_name.insert(s.spec.vss.to_string(), i);
        }
        Self {
            by_name,
            ids: IdIndex::new(),
            messages,
            stats: vec![MessageStats::default(); MESSAGES.len()],
            signals,
            first_signal,
            counters: BusCounters::default(),
            now_us: 0,
            started: false,
        }
    }

    /// Bus time passed without a frame (the source's clock: see
    /// `FrameSource::clock_us`): signals age, timers run. Only forward, and only once a
    /// frame has set the time scale.
    pub fn advance_clock(&mut self, t_us: u64) {
        if self.started && t_us > self.now_us {
            self.now_us = t_us;
        }
    }

    /// Takes one frame in. Never fails: whatever the frame, it is counted somewhere.
    pub fn update(&mut self, frame: &LogFrame) -> Update {
        let t_us = frame.t_us;
        self.counters.frames += 1;
        if self.started && t_us < self.now_us {
            self.counters.time_backwards += 1;
        } else {
            self.now_us = t_us;
            self.started = true;
        }
        match frame.kind {
            FrameKind::Error => {
                self.counters.error_frames += 1;
                return Update::Error;
            }
            FrameKind::Remote => {
                self.counters.remote_frames += 1;
                return Update::Other;
            }
            FrameKind::Data => {}
        }
        if frame.is_fd() {
            self.counters.fd_frames += 1;
            return Update::Other;
        }
        if frame.extended {
            self.counters.extended_frames += 1;
            return Update::Other;
        }
        let Some(index) = self.ids.get(frame.id) else {
            if is_diagnostic_id(frame.id) {
                self.counters.diagnostic_frames += 1;
                return Update::Diagnostic;
            }
            self.counters.unknown_frames += 1;
            let listed = self.counters.unknown_ids.len();
            if let Some(n) = self.counters.unknown_ids.get_mut(&frame.id) {
                *n += 1;
            } else if listed < MAX_LISTED_UNKNOWN_IDS {
                self.counters.unknown_ids.insert(frame.id, 1);
            }
            return Update::Other;
        };
        let spec = &MESSAGES[index];
        let data = frame.data();
        if data.len() != usize::from(spec.dlc) {
            self.stats[index].wrong_length += 1;
            return Update::WrongLength;
        }
        let mut bits = 0u64;
        for (i, b) in data.iter().enumerate() {
            bits |= u64::from(*b) << (8 * i);
        }
        // The typed copy keeps the last good value of each invalid signal, as the ECUs do.
        let valid = self.messages[index].update_from(data).is_ok();
        let first = self.first_signal[index];
        for (i, s) in spec.signals.iter().enumerate() {
            let state = &mut self.signals[first + i];
            let raw = s.raw_in(bits);
            if s.accepts_raw(raw) {
                state.raw = raw;
                state.value = f64::from(self.messages[index].signal(i).unwrap_or(0.0));
                state.updated_us = Some(t_us);
            } else {
                state.invalid += 1;
            }
        }
        let stats = &mut self.stats[index];
        stats.last_data[..data.len()].copy_from_slice(data);
        stats.count += 1;
        if !valid {
            stats.invalid += 1;
        }
        stats.note(t_us);
        Update::Message { index, valid }
    }

    /// Bus time: the latest timestamp seen, µs.
    pub fn now_us(&self) -> u64 {
        self.now_us
    }

    /// The latest value of each message, typed (index as in [`MESSAGES`]).
    pub fn messages(&self) -> &[Message] {
        &self.messages
    }

    /// The latest value of message `M`.
    pub fn get<M: autoplug_can::CanMessage>(&self) -> M {
        self.ids
            .get(u32::from(M::ID))
            .and_then(|i| M::from_message(&self.messages[i]))
            .unwrap_or_default()
    }

    /// Reception statistics, per message (index as in [`MESSAGES`]).
    pub fn stats(&self) -> &[MessageStats] {
        &self.stats
    }

    /// Statistics of the message with this identifier.
    pub fn stats_of(&self, id: u16) -> Option<&MessageStats> {
        self.ids.get(u32::from(id)).map(|i| &self.stats[i])
    }

    /// Every signal, in catalogue order.
    pub fn signals(&self) -> &[SignalState] {
        &self.signals
    }

    /// Signal `i` of the message with this identifier (O(1): for per-frame use, where
    /// [`CarState::signal`]'s search by name is too slow).
    pub fn signal_of(&self, id: u16, i: usize) -> Option<&SignalState> {
        let index = self.ids.get(u32::from(id))?;
        if i >= MESSAGES[index].signals.len() {
            return None;
        }
        self.signals.get(self.first_signal[index] + i)
    }

    /// A signal by a [`SignalName`] (O(1) after its first use).
    pub fn signal_named(&self, name: &SignalName) -> Option<&SignalState> {
        // Every CarState lists the catalogue's signals in the same order, so the index
        // found in one holds for all.
        match name.index.load(Ordering::Relaxed) {
            0 => {
                let i = *self.by_name.get(name.name)?;
                name.index.store(i + 1, Ordering::Relaxed);
                self.signals.get(i)
            }
            i => self.signals.get(i - 1),
        }
    }

    /// A signal by `Message.Signal` name or by VSS path.
    pub fn signal(&self, name: &str) -> Option<&SignalState> {
        self.by_name.get(name).map(|&i| &self.signals[i])
    }

    /// What was not a catalogue message.
    pub fn counters(&self) -> &BusCounters {
        &self.counters
    }
}
