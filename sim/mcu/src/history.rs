//! The execution history of a debugged MCU, for running it backwards: snapshots of the
//! MCU every [`SNAPSHOT_INTERVAL_NS`] of simulated time, and a journal of everything that
//! reached it from outside between them (its runs' ends, CAN receptions and transmit
//! outcomes, error counters, ADC volts and input levels, the host's writes to its RAM).
//! The MCU is deterministic, so any past moment is the snapshot before it with the
//! journal replayed up to it: `reverse-stepi` to the instruction before, `reverse-continue`
//! to the last breakpoint or watchpoint hit. The rest of the car is not replayed: it
//! waits at the present while the debugger looks at the past, and the MCU is put back
//! exactly as it was before it runs on.
//!
//! Positions are instruction counts ([`Cpu::instructions`](crate::cpu::Cpu::instructions)).

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

use crate::chip::can::CanFrame;
use crate::chip::ChipSnapshot;
use crate::cpu::{Cpu, DebugControl, DebugStop};
use crate::debug::{Debugger, Halted, WatchHit};
use crate::mcu::{Mcu, Sent};

/// Simulated time between snapshots: a reverse step replays at most this much.
pub const SNAPSHOT_INTERVAL_NS: u64 = 100_000_000;

/// How far back the history reaches, in simulated time.
pub const WINDOW_NS: u64 = 12_000_000_000;

/// What reaches the MCU from outside between its runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Input {
    /// `run_until` to this simulated time (ns since power-on).
    Run(u64),
    /// A frame the bus delivered to CAN1.
    CanReceive(CanFrame),
    /// The bus's outcome for a mailbox's frame.
    CanComplete {
        /// The mailbox.
        mailbox: usize,
        /// Acknowledged.
        ok: bool,
        /// Lost arbitration or an error: it is tried again.
        retrying: bool,
    },
    /// The node's error counters and bus-off state.
    CanErrorState {
        /// Transmit error counter.
        tec: u16,
        /// Receive error counter.
        rec: u16,
        /// Bus-off.
        bus_off: bool,
    },
    /// The mailbox whose frame is on the wire (an abort of it waits for its end).
    CanSending(Option<usize>),
    /// Volts on an ADC channel.
    Analog {
        /// ADC1 channel.
        channel: usize,
        /// Volts.
        volts: f32,
    },
    /// A level driven on a pin from outside (`None`: released to its pull).
    Drive {
        /// Port index (A = 0).
        port: usize,
        /// Pin number.
        pin: u32,
        /// The level.
        level: Option<bool>,
    },
    /// A word the host wrote into SRAM (a probe moving the RTT read offset).
    HostWrite {
        /// Address.
        address: u32,
        /// Value.
        value: u32,
    },
}

impl Mcu {
    /// Applies `input`, journaling it while a history is recorded. Everything that reaches
    /// the MCU from outside between its runs comes through here.
    pub fn input(&mut self, input: Input) {
        if self.history.is_none() {
            self.apply(input);
            return;
        }
        let before = self.fingerprint(input);
        self.apply(input);
        // An input that changed nothing (the same error counters, the same level again:
        // most of them, window after window) need not be replayed.
        if before.is_some() && before == self.fingerprint(input) {
            return;
        }
        if let Some(history) = &mut self.history {
            history.journal.push_back(input);
        }
    }

    /// What `input` sets, for the kinds that only set state.
    fn fingerprint(&self, input: Input) -> Option<u64> {
        let can = &self.chip.can1;
        match input {
            Input::CanErrorState { .. } => {
                let (msr, esr) = (can.read(0x004).ok()?, can.read(0x018).ok()?);
                Some(u64::from(msr) << 32 | u64::from(esr))
            }
            Input::CanSending(_) => Some(can.sending().map_or(u64::MAX, |m| m as u64)),
            Input::Analog { channel, .. } => {
                Some(u64::from(self.chip.adc.inputs().get(channel)?.to_bits()))
            }
            Input::Drive { port, .. } => {
                let (levels, mask) = self.chip.gpio.get(port)?.driven();
                Some(u64::from(levels) << 16 | u64::from(mask))
            }
            _ => None,
        }
    }

    fn apply(&mut self, input: Input) {
        let can = &mut self.chip.can1;
        match input {
            Input::Run(_) => {}
            Input::CanReceive(frame) => {
                can.receive(&frame);
            }
            Input::CanComplete {
                mailbox,
                ok,
                retrying,
            } => can.complete(mailbox, ok, retrying),
            Input::CanErrorState { tec, rec, bus_off } => can.set_error_state(tec, rec, bus_off),
            Input::CanSending(mailbox) => can.set_sending(mailbox),
            Input::Analog { channel, volts } => self.chip.adc.set_input(channel, volts),
            Input::Drive { port, pin, level } => {
                if let Some(port) = self.chip.gpio.get_mut(port) {
                    port.drive(pin, level);
                }
            }
            Input::HostWrite { address, value } => self.chip.sram_set_word(address, value),
        }
    }

    /// The start of a run: a snapshot when one is due, and the run in the journal.
    pub(crate) fn record_run(&mut self, until_ns: u64) {
        let now_ns = self.now_ns();
        let due = self.history.as_ref().is_some_and(|h| {
            h.snapshots
                .back()
                .is_none_or(|s| now_ns >= s.ns + SNAPSHOT_INTERVAL_NS)
        });
        if let Some(mut history) = due.then(|| self.history.take()).flatten() {
            let state = McuState::capture(self, history.snapshots.back().map(|s| &s.state), false);
            let journal_index = history.journal_base + history.journal.len();
            history.push_snapshot(Snapshot {
                position: self.cpu.instructions(),
                ns: now_ns,
                journal_index,
                state,
            });
            self.history = Some(history);
        }
        if let Some(history) = &mut self.history {
            history.journal.push_back(Input::Run(until_ns));
            history.latest_ns = now_ns;
        }
    }

    /// Puts the MCU back as `state` found it.
    fn restore_state(&mut self, state: &McuState) {
        let code_changed = self.chip.restore(&state.chip);
        // The instruction cache holds decoded flash: forget it if the flash differs.
        let debug = self.cpu.debug.take();
        let attached = self.cpu.debugger_attached;
        self.cpu.restore(&state.cpu, code_changed);
        self.cpu.debug = debug;
        self.cpu.debugger_attached = attached;
        self.on_wire = state.on_wire;
        self.locked_up = state.locked_up;
        self.semihosting_output
            .clone_from(&state.semihosting_output);
        match &state.records {
            Records::Lengths {
                sent,
                resets,
                faults,
                lockups,
            } => {
                self.sent.truncate(*sent);
                self.resets.truncate(*resets);
                self.faults.truncate(*faults);
                self.lockups.truncate(*lockups);
            }
            Records::Whole {
                sent,
                resets,
                faults,
                lockups,
            } => {
                self.sent.clone_from(sent);
                self.resets.clone_from(resets);
                self.faults.clone_from(faults);
                self.lockups.clone_from(lockups);
            }
        }
    }
}

/// The records an MCU appends to: a snapshot keeps their lengths (replaying appends the
/// same again), the present keeps them whole.
#[derive(Clone)]
enum Records {
    Lengths {
        sent: usize,
        resets: usize,
        faults: usize,
        lockups: usize,
    },
    Whole {
        sent: Vec<Sent>,
        resets: Vec<(u64, crate::chip::rcc::ResetCause)>,
        faults: Vec<crate::cpu::ExceptionReport>,
        lockups: Vec<(u64, crate::cpu::Halt)>,
    },
}

/// The MCU's state at a moment.
#[derive(Clone)]
pub struct McuState {
    cpu: Cpu,
    chip: ChipSnapshot,
    on_wire: Option<(CanFrame, u64)>,
    locked_up: bool,
    semihosting_output: Vec<u8>,
    records: Records,
}

impl McuState {
    fn capture(mcu: &mut Mcu, last: Option<&McuState>, whole: bool) -> Self {
        let mut cpu = mcu.cpu.snapshot();
        cpu.debug = None;
        McuState {
            cpu,
            chip: mcu.chip.snapshot(last.map(|s| &s.chip)),
            on_wire: mcu.on_wire,
            locked_up: mcu.locked_up,
            semihosting_output: mcu.semihosting_output.clone(),
            records: if whole {
                Records::Whole {
                    sent: mcu.sent.clone(),
                    resets: mcu.resets.clone(),
                    faults: mcu.faults.clone(),
                    lockups: mcu.lockups.clone(),
                }
            } else {
                Records::Lengths {
                    sent: mcu.sent.len(),
                    resets: mcu.resets.len(),
                    faults: mcu.faults.len(),
                    lockups: mcu.lockups.len(),
                }
            },
        }
    }
}

struct Snapshot {
    /// The instruction count when it was taken.
    position: u64,
    /// Simulated ns when it was taken.
    ns: u64,
    /// The journal entry that follows it (an absolute index).
    journal_index: usize,
    state: McuState,
}

/// Why a replay stopped where it did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arrival {
    /// At the position asked for.
    Position,
    /// At a breakpoint (its address).
    Breakpoint(u32),
    /// After an access a watchpoint matched.
    Watch(WatchHit),
    /// At the first moment the history holds.
    Beginning,
    /// Back at the present.
    Present,
}

/// A hit found while scanning the history.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Hit {
    position: u64,
    arrival: Arrival,
}

/// The execution history of one MCU.
pub struct History {
    snapshots: VecDeque<Snapshot>,
    journal: VecDeque<Input>,
    /// The absolute index of the journal's first entry.
    journal_base: usize,
    /// The present, while the debugger looks at the past.
    present: Option<(u64, Box<McuState>)>,
    /// Simulated ns at the latest run's start.
    latest_ns: u64,
}

impl History {
    /// An empty history: it begins at the MCU's next run.
    pub fn new() -> Self {
        History {
            snapshots: VecDeque::new(),
            journal: VecDeque::new(),
            journal_base: 0,
            present: None,
            latest_ns: 0,
        }
    }

    fn push_snapshot(&mut self, snapshot: Snapshot) {
        let ns = snapshot.ns;
        self.snapshots.push_back(snapshot);
        // Keep the window (and one snapshot before it, so the window's start is reachable).
        while self.snapshots.len() > 2 && self.snapshots[1].ns + WINDOW_NS < ns {
            self.snapshots.pop_front();
            let first = self.snapshots[0].journal_index;
            let drop = first - self.journal_base;
            self.journal.drain(..drop);
            self.journal_base = first;
        }
    }

    /// Whether the debugger looks at the past.
    pub fn in_past(&self) -> bool {
        self.present.is_some()
    }

    /// The simulated time the history spans, ns.
    pub fn span_ns(&self) -> u64 {
        self.snapshots
            .front()
            .map_or(0, |s| self.latest_ns.saturating_sub(s.ns))
    }

    /// Bytes the history holds: the SRAM pages and flash copies its snapshots do not share,
    /// and the journal.
    pub fn bytes(&self) -> usize {
        let mut pages = std::collections::HashSet::new();
        let mut flashes = std::collections::HashSet::new();
        let mut bytes = 0usize;
        for snapshot in &self.snapshots {
            let (sram, flash) = snapshot.state.chip.memories();
            for page in sram {
                if pages.insert(Arc::as_ptr(page) as *const u8 as usize) {
                    bytes += page.len();
                }
            }
            if flashes.insert(Arc::as_ptr(flash) as usize) {
                bytes += autoplug_flash::FLASH_SIZE as usize;
            }
            bytes += std::mem::size_of::<Snapshot>();
        }
        bytes + self.journal.len() * std::mem::size_of::<Input>()
    }
}

impl Default for History {
    fn default() -> Self {
        Self::new()
    }
}

/// The debugger a replay installs: it notes the hits and ends the run at the position.
struct Probe {
    hits: Arc<Mutex<Vec<Hit>>>,
    /// Hits are noted after this position only (all of them with `None`).
    after: Option<u64>,
}

impl Debugger for Probe {
    fn wants_halt(&self) -> bool {
        false
    }

    fn halted(&mut self, mcu: &mut Mcu, why: Halted) {
        let position = mcu.cpu.instructions();
        let arrival = match why {
            Halted::Core(DebugStop::Position) => {
                mcu.abort_run = true;
                return;
            }
            Halted::Core(DebugStop::Breakpoint(pc)) => {
                // Note it, and pass it on the way on.
                if let Some(control) = mcu.cpu.debug.as_deref_mut() {
                    control.pass_breakpoint_at = Some(position);
                }
                Arrival::Breakpoint(pc)
            }
            Halted::Watch(hit) => Arrival::Watch(hit),
            _ => return,
        };
        if self.after.is_none_or(|after| position > after) {
            if let Ok(mut hits) = self.hits.lock() {
                hits.push(Hit { position, arrival });
            }
        }
    }
}

/// Why the history could not take the debugger where it asked.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ReplayError {
    /// There is no history (no debugger recording, or nothing recorded yet).
    Empty,
    /// The MCU stopped in the replay where it did not in the recording: the history does
    /// not describe it (a bug of the emulator, reported rather than hidden).
    Diverged(String),
}

impl Mcu {
    /// Starts recording a history (a debugger attached), or starts it anew (the debugger
    /// changed the MCU: what came before no longer leads to it).
    pub fn start_history(&mut self) {
        self.history = Some(Box::new(History::new()));
    }

    /// Whether the debugger looks at the past.
    pub fn in_past(&self) -> bool {
        self.history.as_ref().is_some_and(|h| h.in_past())
    }

    /// Back to the present, if the debugger looked at the past.
    pub fn return_to_present(&mut self) {
        let present = self.history.as_mut().and_then(|h| h.present.take());
        if let Some((_, state)) = present {
            self.restore_state(&state);
        }
    }

    /// The present's position: where the MCU is, or was before the debugger looked back.
    pub fn present_position(&self) -> u64 {
        self.history
            .as_ref()
            .and_then(|h| h.present.as_ref().map(|(p, _)| *p))
            .unwrap_or_else(|| self.cpu.instructions())
    }

    /// Remembers the present before the first look back.
    fn keep_present(&mut self) {
        if self.history.as_ref().is_some_and(|h| h.present.is_none()) {
            let position = self.cpu.instructions();
            let state = Box::new(McuState::capture(self, None, true));
            if let Some(history) = &mut self.history {
                history.present = Some((position, state));
            }
        }
    }

    /// Replays from the last snapshot at or before `from` to `to` (exclusive of hits at or
    /// before `from`), with the debugger's breakpoints and watchpoints when `hits` is
    /// wanted; ends at `to` with `before_entry` as [`DebugControl::stop_at_instruction`]
    /// says. The hits on the way.
    fn replay(
        &mut self,
        from: u64,
        to: u64,
        before_entry: bool,
        with_hits: bool,
    ) -> Result<Vec<Hit>, ReplayError> {
        self.replay_noting(from, Some(from), to, before_entry, with_hits)
    }

    /// [`Mcu::replay`], noting the hits after `after` (all with `None`).
    fn replay_noting(
        &mut self,
        from: u64,
        after: Option<u64>,
        to: u64,
        before_entry: bool,
        with_hits: bool,
    ) -> Result<Vec<Hit>, ReplayError> {
        let history = self.history.take().ok_or(ReplayError::Empty)?;
        let Some(index) = history
            .snapshots
            .iter()
            .rposition(|s| s.position <= from.min(to))
        else {
            self.history = Some(history);
            return Err(ReplayError::Empty);
        };
        let snapshot = &history.snapshots[index];
        self.restore_state(&snapshot.state);
        let hits = Arc::new(Mutex::new(Vec::new()));
        let debugger = self.debugger.replace(Box::new(Probe {
            hits: Arc::clone(&hits),
            after,
        }));
        // The past's log was read when it happened: a replay's halts read nothing.
        let on_halt = self.on_debug_halt.take();
        let saved_control = self.cpu.debug.take();
        let watchpoints = std::mem::take(&mut self.debug.watchpoints);
        if with_hits {
            self.debug.watchpoints.clone_from(&watchpoints);
        }
        let mut control = if with_hits {
            self.debug.control()
        } else {
            DebugControl::default()
        };
        control.catch_hard_fault = false;
        control.stop_at_instruction = Some((to, before_entry));
        self.cpu.debug = Some(Box::new(control));
        let start = snapshot.journal_index - history.journal_base;
        let mut result = Ok(());
        for &input in history.journal.range(start..) {
            if self.cpu.instructions() == to && before_entry {
                break;
            }
            match input {
                Input::Run(ns) => {
                    if let Err(stop) = self.run_until(ns) {
                        result = Err(stop);
                        break;
                    }
                    if self.reached(to) {
                        break;
                    }
                }
                other => self.apply(other),
            }
        }
        self.cpu.debug = saved_control;
        self.debug.watchpoints = watchpoints;
        self.debugger = debugger;
        self.on_debug_halt = on_halt;
        self.history = Some(history);
        if let Err(stop) = result {
            return Err(ReplayError::Diverged(format!("the replay stopped: {stop}")));
        }
        let hits = hits.lock().map(|h| h.clone()).unwrap_or_default();
        Ok(hits)
    }

    fn reached(&self, to: u64) -> bool {
        self.cpu.instructions() >= to
    }

    /// The first position the history holds.
    fn history_start(&self) -> Option<u64> {
        self.history
            .as_ref()
            .and_then(|h| h.snapshots.front().map(|s| s.position))
    }

    fn snapshot_positions(&self) -> Vec<u64> {
        self.history
            .as_ref()
            .map(|h| h.snapshots.iter().map(|s| s.position).collect())
            .unwrap_or_default()
    }

    /// Goes to position `to` (before a pending exception is taken: the state the
    /// instruction before left), remembering the present first.
    fn go_to(&mut self, to: u64) -> Result<(), ReplayError> {
        self.keep_present();
        self.replay(to, to, true, false)?;
        if self.cpu.instructions() != to {
            return Err(ReplayError::Diverged(format!(
                "asked for instruction {to}, the replay reached {}",
                self.cpu.instructions()
            )));
        }
        Ok(())
    }

    /// `reverse-stepi`: to the instruction before.
    pub fn reverse_step(&mut self) -> Result<Arrival, ReplayError> {
        let here = self.cpu.instructions();
        let start = self.history_start().ok_or(ReplayError::Empty)?;
        if here <= start {
            return Ok(Arrival::Beginning);
        }
        self.go_to(here - 1)?;
        Ok(Arrival::Position)
    }

    /// `reverse-continue`: back to the last breakpoint or watchpoint hit before here, or
    /// to the history's beginning.
    pub fn reverse_continue(&mut self) -> Result<Arrival, ReplayError> {
        let here = self.cpu.instructions();
        let start = self.history_start().ok_or(ReplayError::Empty)?;
        self.keep_present();
        let positions = self.snapshot_positions();
        // Segment by segment, the latest first: the last hit in the latest segment that
        // has one.
        let mut end = here;
        for &segment_start in positions.iter().rev().filter(|&&p| p < here) {
            // Hits from the segment's first instruction on.
            let hits = self.replay_noting(
                segment_start,
                segment_start.checked_sub(1),
                end,
                false,
                true,
            )?;
            let before: Vec<Hit> = hits
                .into_iter()
                .filter(|h| h.position < here && h.position >= segment_start)
                .collect();
            if let Some(hit) = before.last() {
                return self.arrive(*hit);
            }
            end = segment_start;
        }
        self.go_to(start)?;
        Ok(Arrival::Beginning)
    }

    /// Forward in the past: `stepi`.
    pub fn replay_step(&mut self) -> Result<Arrival, ReplayError> {
        let here = self.cpu.instructions();
        let present = self.present_position();
        if here + 1 >= present {
            self.return_to_present();
            return Ok(Arrival::Present);
        }
        self.go_to(here + 1)?;
        Ok(Arrival::Position)
    }

    /// Forward in the past: `continue`, to the next hit or back to the present.
    pub fn replay_continue(&mut self) -> Result<Arrival, ReplayError> {
        let here = self.cpu.instructions();
        let present = self.present_position();
        let positions = self.snapshot_positions();
        let mut segments: Vec<u64> = positions.iter().copied().filter(|&p| p > here).collect();
        segments.insert(0, here);
        segments.push(present);
        for pair in segments.windows(2) {
            let (from, to) = (pair[0], pair[1]);
            let hits = self.replay(from.max(here), to, false, true)?;
            if let Some(hit) = hits
                .into_iter()
                .find(|h| h.position > here && h.position < present)
            {
                return self.arrive(hit);
            }
        }
        self.return_to_present();
        Ok(Arrival::Present)
    }

    fn arrive(&mut self, hit: Hit) -> Result<Arrival, ReplayError> {
        let before_entry = matches!(hit.arrival, Arrival::Watch(_));
        self.replay(hit.position, hit.position, before_entry, false)?;
        if self.cpu.instructions() != hit.position {
            return Err(ReplayError::Diverged(format!(
                "a hit at instruction {}, the replay reached {}",
                hit.position,
                self.cpu.instructions()
            )));
        }
        Ok(hit.arrival)
    }
}
