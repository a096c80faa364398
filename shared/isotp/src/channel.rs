//! One ISO-TP channel: a transmitter and a receiver state machine on a pair of
//! identifiers, sharing the one frame that may await its confirmation.

use autoplug_can::Frame;
use autoplug_ecu::Instant;

use crate::config::{Config, StMin};
use crate::event::{ChannelError, Event, SendError};
use crate::pdu::{
    self, FirstFrameLength, FlowStatus, Pdu, CONSECUTIVE_FRAME_MAX, FIRST_FRAME_DATA,
    SINGLE_FRAME_MAX,
};

/// Longest PDU a 12-bit first frame length carries.
pub const MAX_PDU_LEN: usize = 4095;

/// How many events may wait for [`Channel::poll`]. A call adds at most two, so a caller
/// that drains `poll` after each call never fills it.
const EVENT_QUEUE_LEN: usize = 4;

/// An ISO-TP channel on one pair of CAN identifiers, both directions at once.
///
/// `N` is the longest PDU it receives, `TX_N` the longest it sends (both at most 4095;
/// `TX_N` defaults to `N`). The channel owns both buffers, so it needs `N + TX_N` bytes.
///
/// It never reads a clock: every call takes the current time, and
/// [`Channel::next_deadline`] says when to call again. A polling loop:
///
/// ```
/// # use autoplug_isotp::{Channel, Config, Event};
/// # use autoplug_ecu::Instant;
/// # let mut channel: Channel<64> = Channel::new(Config::default_for(0x7E8, 0x7E0));
/// # let now = Instant::ZERO;
/// # let incoming: Option<autoplug_can::Frame> = None;
/// # fn handle(_: Event) {}
/// # fn bus_send(_: autoplug_can::Frame) {}
/// if let Some(frame) = incoming {
///     if let Some(event) = channel.on_frame(now, &frame) {
///         handle(event);
///     }
/// }
/// while let Some(event) = channel.poll(now) {
///     handle(event);
/// }
/// while let Some(frame) = channel.poll_transmit(now) {
///     bus_send(frame);
///     // Once the controller reports the frame sent (here: at once).
///     channel.confirm_transmit(now);
/// }
/// // Sleep until a frame arrives or `channel.next_deadline()`.
/// ```
pub struct Channel<const N: usize, const TX_N: usize = N> {
    config: Config,
    transmitter: Transmitter<TX_N>,
    receiver: Receiver<N>,
    /// The frame handed out by `poll_transmit` and not confirmed yet. Both directions
    /// send on the same identifier, so frames go out strictly one after the other.
    unconfirmed: Option<Unconfirmed>,
    events: EventQueue,
}

#[derive(Clone, Copy, Debug)]
struct Unconfirmed {
    kind: FrameKind,
    /// When N_As (data) or N_Ar (flow control) runs out.
    deadline: Instant,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum FrameKind {
    /// SF, FF or CF of the transmitter.
    Data,
    /// FC of the receiver.
    FlowControl(FlowStatus),
}

struct Transmitter<const T: usize> {
    buffer: [u8; T],
    len: usize,
    /// Payload bytes already placed in frames handed out.
    offset: usize,
    next_sequence_number: u8,
    state: TxState,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum TxState {
    Idle,
    /// `send` accepted a PDU at `since`; its SF or FF is due.
    FirstDue {
        since: Instant,
    },
    /// After an FF or a block. `deadline` is N_Bs, `None` until the FF or last CF is
    /// confirmed; `waits` counts FC.WAIT received in a row.
    AwaitingFlowControl {
        deadline: Option<Instant>,
        waits: u8,
    },
    /// Sending a block. `next_at`: when the next CF may go (`None` until the previous
    /// one is confirmed, since STmin counts from there); `left_in_block`: `None` for no
    /// limit (BS 0).
    SendingBlock {
        next_at: Option<Instant>,
        left_in_block: Option<u8>,
        st_min_us: u64,
    },
    /// The last frame is out; `Sent` follows its confirmation.
    AwaitingLastConfirmation,
}

struct Receiver<const R: usize> {
    buffer: [u8; R],
    /// Length of the complete PDU held for the upper layer until `release`.
    delivered: Option<usize>,
    ready: bool,
    state: RxState,
    /// A flow control decided on (CTS after an FF or a block, OVFLW for a refused FF)
    /// and not handed out yet, with the time it became due.
    flow_control_due: Option<(FlowStatus, Instant)>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum RxState {
    Idle,
    /// An FF arrived while the upper layer could not take it: FC.WAIT every N_Br.
    /// The FF's payload is kept here because the buffer may still hold the previous PDU.
    Waiting {
        len: usize,
        first_data: [u8; FIRST_FRAME_DATA],
        waits_sent: u8,
        /// When the next FC is due (`None` while a WAIT awaits confirmation).
        next_at: Option<Instant>,
        /// The FF's arrival or the last WAIT's confirmation: when a CTS is due once
        /// the receiver is ready.
        since: Instant,
    },
    /// Receiving consecutive frames into the buffer.
    Receiving {
        len: usize,
        received: usize,
        next_sequence_number: u8,
        /// CFs left until the next FC (`None`: BS 0, no limit).
        left_in_block: Option<u8>,
        /// N_Cr, `None` until the FC that lets the sender go on is confirmed.
        deadline: Option<Instant>,
    },
}

/// Events not returned at once, oldest first, with the time they happened.
struct EventQueue {
    slots: [Option<(Event, Instant)>; EVENT_QUEUE_LEN],
    head: usize,
    len: usize,
}

impl EventQueue {
    const fn new() -> Self {
        EventQueue {
            slots: [None; EVENT_QUEUE_LEN],
            head: 0,
            len: 0,
        }
    }

    /// Queues an event; if the caller let the queue fill up, the newest is dropped
    /// rather than overwriting an older one it has not seen.
    fn push(&mut self, event: Event, at: Instant) {
        if self.len < EVENT_QUEUE_LEN {
            self.slots[(self.head + self.len) % EVENT_QUEUE_LEN] = Some((event, at));
            self.len += 1;
        }
    }

    fn pop(&mut self) -> Option<Event> {
        if self.len == 0 {
            return None;
        }
        let slot = self.slots[self.head].take();
        self.head = (self.head + 1) % EVENT_QUEUE_LEN;
        self.len -= 1;
        slot.map(|(event, _)| event)
    }

    fn oldest_time(&self) -> Option<Instant> {
        if self.len == 0 {
            return None;
        }
        self.slots[self.head].map(|(_, at)| at)
    }

    fn is_empty(&self) -> bool {
        self.len == 0
    }
}

impl<const N: usize, const TX_N: usize> Channel<N, TX_N> {
    /// Rejects, at compile time, buffers a 12-bit length cannot fill.
    const BUFFERS_FIT_ISO_TP: () = assert!(
        N <= MAX_PDU_LEN && TX_N <= MAX_PDU_LEN,
        "ISO-TP on classic CAN carries at most 4095 bytes"
    );

    /// The longest PDU [`Channel::send`] accepts.
    pub const MAX_SEND_LEN: usize = TX_N;

    /// A channel with nothing in progress, ready to receive.
    pub const fn new(config: Config) -> Self {
        #[allow(clippy::let_unit_value)] // evaluating the constant is the check
        let () = Self::BUFFERS_FIT_ISO_TP;
        Channel {
            config,
            transmitter: Transmitter {
                buffer: [0; TX_N],
                len: 0,
                offset: 0,
                next_sequence_number: 0,
                state: TxState::Idle,
            },
            receiver: Receiver {
                buffer: [0; N],
                delivered: None,
                ready: true,
                state: RxState::Idle,
                flow_control_due: None,
            },
            unconfirmed: None,
            events: EventQueue::new(),
        }
    }

    /// The channel's parameters.
    pub const fn config(&self) -> &Config {
        &self.config
    }

    /// Starts sending `payload` (copied). Its frames come out of
    /// [`Channel::poll_transmit`]; [`Event::Sent`] or an [`Event::Error`] ends it.
    pub fn send(&mut self, now: Instant, payload: &[u8]) -> Result<(), SendError> {
        if self.transmitter.state != TxState::Idle {
            return Err(SendError::Busy);
        }
        if payload.is_empty() {
            return Err(SendError::Empty);
        }
        if payload.len() > TX_N {
            return Err(SendError::TooLong {
                len: payload.len(),
                max: TX_N,
            });
        }
        let tx = &mut self.transmitter;
        tx.buffer[..payload.len()].copy_from_slice(payload);
        tx.len = payload.len();
        tx.offset = 0;
        tx.state = TxState::FirstDue { since: now };
        Ok(())
    }

    /// Takes a received frame. Frames on other identifiers, and frames ISO 15765-2 has
    /// ignored (too short for their PCI, out of place), change nothing. Returns the next
    /// event, if any; a frame can cause two (an interrupted reception and the new PDU),
    /// the second then comes from [`Channel::poll`].
    pub fn on_frame(&mut self, now: Instant, frame: &Frame) -> Option<Event> {
        let id = frame.id();
        if id == self.config.rx_id {
            match pdu::decode(frame.data()) {
                Some(Pdu::Single(payload)) => self.on_single_frame(now, payload, false),
                Some(Pdu::First { length, data }) => self.on_first_frame(now, length, data),
                Some(Pdu::Consecutive {
                    sequence_number,
                    data,
                }) => self.on_consecutive_frame(now, sequence_number, data),
                Some(Pdu::FlowControl {
                    status,
                    block_size,
                    st_min,
                }) => self.on_flow_control(now, status, block_size, st_min),
                None => {}
            }
        } else if Some(id) == self.config.functional_rx_id {
            // Functional addressing is one-to-many: no flow control, so single frames only.
            if let Some(Pdu::Single(payload)) = pdu::decode(frame.data()) {
                self.on_single_frame(now, payload, true);
            }
        }
        self.events.pop()
    }

    /// The next frame to put on the bus now, if any: a flow control before a consecutive
    /// frame, none while the previous frame awaits [`Channel::confirm_transmit`], and
    /// consecutive frames no sooner than STmin after the previous one's confirmation.
    pub fn poll_transmit(&mut self, now: Instant) -> Option<Frame> {
        if self.unconfirmed.is_some() {
            return None;
        }
        if let Some(status) = self.flow_control_due(now) {
            return self.hand_out_flow_control(now, status);
        }
        self.hand_out_data(now)
    }

    /// Reports that the frame last handed out by [`Channel::poll_transmit`] is on the bus
    /// (the controller's transmit confirmation). Starts STmin, N_Bs or N_Cr as due;
    /// [`Event::Sent`] follows from [`Channel::poll`]. Without a frame awaiting
    /// confirmation, it does nothing.
    pub fn confirm_transmit(&mut self, now: Instant) {
        let Some(unconfirmed) = self.unconfirmed.take() else {
            return;
        };
        match unconfirmed.kind {
            FrameKind::Data => self.on_data_confirmed(now),
            FrameKind::FlowControl(status) => self.on_flow_control_confirmed(now, status),
        }
    }

    /// Events not returned yet, then timeouts (N_As, N_Ar, N_Bs, N_Cr) that have run out
    /// at `now`. Call until `None`.
    pub fn poll(&mut self, now: Instant) -> Option<Event> {
        if let Some(event) = self.events.pop() {
            return Some(event);
        }
        if let Some(unconfirmed) = self.unconfirmed {
            if now >= unconfirmed.deadline {
                self.unconfirmed = None;
                let error = match unconfirmed.kind {
                    FrameKind::Data => {
                        self.transmitter.state = TxState::Idle;
                        ChannelError::TimeoutAs
                    }
                    FrameKind::FlowControl(_) => {
                        self.abandon_reception();
                        ChannelError::TimeoutAr
                    }
                };
                return Some(Event::Error(error));
            }
        }
        if let TxState::AwaitingFlowControl {
            deadline: Some(deadline),
            ..
        } = self.transmitter.state
        {
            if now >= deadline {
                self.transmitter.state = TxState::Idle;
                return Some(Event::Error(ChannelError::TimeoutBs));
            }
        }
        if let RxState::Receiving {
            deadline: Some(deadline),
            ..
        } = self.receiver.state
        {
            if now >= deadline {
                self.abandon_reception();
                return Some(Event::Error(ChannelError::TimeoutCr));
            }
        }
        None
    }

    /// When [`Channel::poll`] or [`Channel::poll_transmit`] next has something to do
    /// (possibly already past); `None` if nothing will happen without a frame, a
    /// confirmation or a call from the upper layer.
    pub fn next_deadline(&self) -> Option<Instant> {
        let mut earliest = Earliest(self.events.oldest_time());
        if let Some(unconfirmed) = self.unconfirmed {
            earliest.take(Some(unconfirmed.deadline));
        } else {
            // Frames to hand out matter only while nothing awaits confirmation.
            earliest.take(self.receiver.flow_control_due.map(|(_, since)| since));
            if let RxState::Waiting {
                next_at: Some(next_at),
                since,
                ..
            } = self.receiver.state
            {
                earliest.take(Some(if self.can_take_new_pdu() {
                    since
                } else {
                    next_at
                }));
            }
            match self.transmitter.state {
                TxState::FirstDue { since } => earliest.take(Some(since)),
                TxState::SendingBlock { next_at, .. } => earliest.take(next_at),
                _ => {}
            }
        }
        if let TxState::AwaitingFlowControl { deadline, .. } = self.transmitter.state {
            earliest.take(deadline);
        }
        if let RxState::Receiving { deadline, .. } = self.receiver.state {
            earliest.take(deadline);
        }
        earliest.0
    }

    /// The last complete PDU received, from its [`Event::Received`] until
    /// [`Channel::release`]; empty otherwise.
    pub fn received(&self) -> &[u8] {
        match self.receiver.delivered {
            Some(len) => &self.receiver.buffer[..len],
            None => &[],
        }
    }

    /// The upper layer is done with [`Channel::received`]: the buffer takes the next PDU
    /// (a first frame being held off with FC.WAIT gets its CTS at the next
    /// [`Channel::poll_transmit`]).
    pub fn release(&mut self) {
        self.receiver.delivered = None;
    }

    /// Whether the upper layer takes new PDUs (initially true). While not ready, or while
    /// [`Channel::received`] is not released, a first frame is answered with FC.WAIT every
    /// N_Br, up to `max_wait_frames`, then FC.OVFLW, and a single frame is dropped with
    /// [`ChannelError::ReceiverBusy`]. A reception already under way is not affected.
    pub fn set_rx_ready(&mut self, ready: bool) {
        self.receiver.ready = ready;
    }

    /// Whether a transmission is in progress ([`Channel::send`] would be `Busy`).
    pub fn is_transmitting(&self) -> bool {
        self.transmitter.state != TxState::Idle
    }

    /// Whether a segmented reception is in progress or being held off with FC.WAIT.
    pub fn is_receiving(&self) -> bool {
        self.receiver.state != RxState::Idle
    }

    /// Whether the channel has nothing in progress: no transmission, no reception, no
    /// frame to send or to be confirmed, no event pending. A received PDU not yet
    /// released does not count.
    pub fn is_idle(&self) -> bool {
        self.transmitter.state == TxState::Idle
            && self.receiver.state == RxState::Idle
            && self.receiver.flow_control_due.is_none()
            && self.unconfirmed.is_none()
            && self.events.is_empty()
    }

    /// Abandons the transmission and reception in progress without an event, and forgets
    /// the frame awaiting confirmation (do not confirm it afterwards), e.g. after the CAN
    /// controller was reset. A received PDU not yet released stays, and so do pending
    /// events.
    pub fn abort(&mut self) {
        self.transmitter.state = TxState::Idle;
        self.abandon_reception();
        self.unconfirmed = None;
    }

    fn can_take_new_pdu(&self) -> bool {
        self.receiver.ready && self.receiver.delivered.is_none()
    }

    fn block_size_limit(&self) -> Option<u8> {
        match self.config.block_size {
            0 => None,
            block_size => Some(block_size),
        }
    }

    /// Ends the reception in progress, including a flow control not sent yet for it.
    fn abandon_reception(&mut self) {
        self.receiver.state = RxState::Idle;
        self.receiver.flow_control_due = None;
    }

    /// On a new SF or FF on the physical identifier: the reception in progress is lost.
    fn interrupt_reception(&mut self, now: Instant) {
        if self.receiver.state != RxState::Idle {
            self.events
                .push(Event::Error(ChannelError::ReceptionInterrupted), now);
        }
        // A flow control still due belongs to a PDU the sender has given up.
        self.abandon_reception();
    }

    fn on_single_frame(&mut self, now: Instant, payload: &[u8], functional: bool) {
        if functional {
            // A functional request (e.g. TesterPresent) must not end a physical transfer.
            if self.receiver.state != RxState::Idle {
                self.events
                    .push(Event::Error(ChannelError::ReceiverBusy), now);
                return;
            }
        } else {
            self.interrupt_reception(now);
        }
        if !self.can_take_new_pdu() {
            self.events
                .push(Event::Error(ChannelError::ReceiverBusy), now);
            return;
        }
        if payload.len() > N {
            self.events.push(
                Event::Error(ChannelError::IncomingTooLong {
                    announced: payload.len() as u32,
                    capacity: N,
                }),
                now,
            );
            return;
        }
        self.receiver.buffer[..payload.len()].copy_from_slice(payload);
        self.receiver.delivered = Some(payload.len());
        self.events.push(
            Event::Received {
                len: payload.len(),
                functional,
            },
            now,
        );
    }

    fn on_first_frame(&mut self, now: Instant, length: FirstFrameLength, data: &[u8]) {
        self.interrupt_reception(now);
        let len = match length {
            FirstFrameLength::Short(len) if len <= N => len,
            FirstFrameLength::Short(len) => {
                self.refuse_too_long(now, len as u32);
                return;
            }
            FirstFrameLength::Escaped(len) => {
                self.refuse_too_long(now, len);
                return;
            }
        };
        let mut first_data = [0; FIRST_FRAME_DATA];
        first_data.copy_from_slice(&data[..FIRST_FRAME_DATA]);
        if self.can_take_new_pdu() {
            self.start_reception(now, len, &first_data);
        } else if self.config.max_wait_frames > 0 {
            self.receiver.state = RxState::Waiting {
                len,
                first_data,
                waits_sent: 0,
                next_at: Some(now),
                since: now,
            };
        } else {
            self.receiver.flow_control_due = Some((FlowStatus::Overflow, now));
            self.events.push(
                Event::Error(ChannelError::IncomingRefused { waits: 0 }),
                now,
            );
        }
    }

    fn refuse_too_long(&mut self, now: Instant, announced: u32) {
        self.receiver.flow_control_due = Some((FlowStatus::Overflow, now));
        self.events.push(
            Event::Error(ChannelError::IncomingTooLong {
                announced,
                capacity: N,
            }),
            now,
        );
    }

    /// Takes an FF's payload into the buffer and has a CTS sent.
    fn start_reception(&mut self, now: Instant, len: usize, first_data: &[u8; FIRST_FRAME_DATA]) {
        self.receiver.buffer[..FIRST_FRAME_DATA].copy_from_slice(first_data);
        self.receiver.state = RxState::Receiving {
            len,
            received: FIRST_FRAME_DATA,
            next_sequence_number: 1,
            left_in_block: self.block_size_limit(),
            deadline: None,
        };
        self.receiver.flow_control_due = Some((FlowStatus::ContinueToSend, now));
    }

    fn on_consecutive_frame(&mut self, now: Instant, sequence_number: u8, data: &[u8]) {
        let RxState::Receiving {
            len,
            received,
            next_sequence_number,
            left_in_block,
            ..
        } = self.receiver.state
        else {
            return;
        };
        // Before our flow control is out, the sender has no right to send: out of place.
        if self.receiver.flow_control_due.is_some() {
            return;
        }
        let chunk_len = (len - received).min(CONSECUTIVE_FRAME_MAX);
        if data.len() < chunk_len {
            return;
        }
        if sequence_number != next_sequence_number {
            self.abandon_reception();
            self.events.push(
                Event::Error(ChannelError::WrongSequenceNumber {
                    expected: next_sequence_number,
                    got: sequence_number,
                }),
                now,
            );
            return;
        }
        let received = received + chunk_len;
        self.receiver.buffer[received - chunk_len..received].copy_from_slice(&data[..chunk_len]);
        if received == len {
            self.receiver.state = RxState::Idle;
            self.receiver.delivered = Some(len);
            self.events.push(
                Event::Received {
                    len,
                    functional: false,
                },
                now,
            );
            return;
        }
        let (left_in_block, deadline) = match left_in_block {
            Some(1) => {
                // Block complete: the sender waits for our next CTS; N_Cr restarts
                // once that is confirmed.
                self.receiver.flow_control_due = Some((FlowStatus::ContinueToSend, now));
                (self.block_size_limit(), None)
            }
            Some(left) => (Some(left - 1), Some(now.plus_micros(self.config.n_cr_us))),
            None => (None, Some(now.plus_micros(self.config.n_cr_us))),
        };
        self.receiver.state = RxState::Receiving {
            len,
            received,
            next_sequence_number: (next_sequence_number + 1) & 0x0F,
            left_in_block,
            deadline,
        };
    }

    fn on_flow_control(&mut self, now: Instant, status: u8, block_size: u8, st_min: u8) {
        let TxState::AwaitingFlowControl { waits, .. } = self.transmitter.state else {
            return;
        };
        let error = match status {
            0 => {
                self.transmitter.state = TxState::SendingBlock {
                    next_at: Some(now),
                    left_in_block: match block_size {
                        0 => None,
                        block_size => Some(block_size),
                    },
                    st_min_us: StMin::from_byte(st_min).as_micros(),
                };
                return;
            }
            1 if waits < self.config.max_wait_frames => {
                self.transmitter.state = TxState::AwaitingFlowControl {
                    deadline: Some(now.plus_micros(self.config.n_bs_us)),
                    waits: waits + 1,
                };
                return;
            }
            1 => ChannelError::TooManyWaits {
                max: self.config.max_wait_frames,
            },
            2 => ChannelError::Overflow,
            reserved => ChannelError::InvalidFlowStatus(reserved),
        };
        self.transmitter.state = TxState::Idle;
        self.events.push(Event::Error(error), now);
    }

    /// The flow control to send now, if any.
    fn flow_control_due(&self, now: Instant) -> Option<FlowStatus> {
        if let Some((status, _)) = self.receiver.flow_control_due {
            return Some(status);
        }
        let RxState::Waiting {
            waits_sent,
            next_at: Some(next_at),
            ..
        } = self.receiver.state
        else {
            return None;
        };
        if self.can_take_new_pdu() {
            Some(FlowStatus::ContinueToSend)
        } else if now < next_at {
            None
        } else if waits_sent < self.config.max_wait_frames {
            Some(FlowStatus::Wait)
        } else {
            Some(FlowStatus::Overflow)
        }
    }

    fn hand_out_flow_control(&mut self, now: Instant, status: FlowStatus) -> Option<Frame> {
        let (block_size, st_min) = match status {
            FlowStatus::ContinueToSend => (self.config.block_size, self.config.st_min.to_byte()),
            // Not relevant in WAIT and OVFLW: sent as zeros.
            FlowStatus::Wait | FlowStatus::Overflow => (0, 0),
        };
        let frame = pdu::flow_control(
            self.config.tx_id,
            self.config.padding,
            status,
            block_size,
            st_min,
        )?;
        self.receiver.flow_control_due = None;
        if let RxState::Waiting {
            len,
            first_data,
            waits_sent,
            ..
        } = self.receiver.state
        {
            match status {
                FlowStatus::ContinueToSend => {
                    self.start_reception(now, len, &first_data);
                    // Handed out right now, so not due any more.
                    self.receiver.flow_control_due = None;
                }
                FlowStatus::Wait => {
                    self.receiver.state = RxState::Waiting {
                        len,
                        first_data,
                        waits_sent: waits_sent + 1,
                        next_at: None,
                        since: now,
                    };
                }
                FlowStatus::Overflow => {
                    self.receiver.state = RxState::Idle;
                    self.events.push(
                        Event::Error(ChannelError::IncomingRefused { waits: waits_sent }),
                        now,
                    );
                }
            }
        }
        self.unconfirmed = Some(Unconfirmed {
            kind: FrameKind::FlowControl(status),
            deadline: now.plus_micros(self.config.n_ar_us),
        });
        Some(frame)
    }

    fn hand_out_data(&mut self, now: Instant) -> Option<Frame> {
        let tx = &mut self.transmitter;
        let (frame, next_state) = match tx.state {
            TxState::FirstDue { .. } if tx.len <= SINGLE_FRAME_MAX => {
                let frame = pdu::single_frame(
                    self.config.tx_id,
                    self.config.padding,
                    &tx.buffer[..tx.len],
                )?;
                tx.offset = tx.len;
                (frame, TxState::AwaitingLastConfirmation)
            }
            TxState::FirstDue { .. } => {
                let frame =
                    pdu::first_frame(self.config.tx_id, tx.len, &tx.buffer[..FIRST_FRAME_DATA])?;
                tx.offset = FIRST_FRAME_DATA;
                tx.next_sequence_number = 1;
                let awaiting = TxState::AwaitingFlowControl {
                    deadline: None,
                    waits: 0,
                };
                (frame, awaiting)
            }
            TxState::SendingBlock {
                next_at: Some(next_at),
                left_in_block,
                st_min_us,
            } if now >= next_at => {
                let end = (tx.offset + CONSECUTIVE_FRAME_MAX).min(tx.len);
                let frame = pdu::consecutive_frame(
                    self.config.tx_id,
                    self.config.padding,
                    tx.next_sequence_number,
                    &tx.buffer[tx.offset..end],
                )?;
                tx.offset = end;
                tx.next_sequence_number = (tx.next_sequence_number + 1) & 0x0F;
                let next_state = if end == tx.len {
                    TxState::AwaitingLastConfirmation
                } else {
                    match left_in_block {
                        Some(1) => TxState::AwaitingFlowControl {
                            deadline: None,
                            waits: 0,
                        },
                        left => TxState::SendingBlock {
                            next_at: None,
                            left_in_block: left.map(|left| left - 1),
                            st_min_us,
                        },
                    }
                };
                (frame, next_state)
            }
            _ => return None,
        };
        tx.state = next_state;
        self.unconfirmed = Some(Unconfirmed {
            kind: FrameKind::Data,
            deadline: now.plus_micros(self.config.n_as_us),
        });
        Some(frame)
    }

    fn on_data_confirmed(&mut self, now: Instant) {
        let tx = &mut self.transmitter;
        match tx.state {
            TxState::AwaitingLastConfirmation => {
                tx.state = TxState::Idle;
                self.events.push(Event::Sent, now);
            }
            TxState::AwaitingFlowControl {
                deadline: None,
                waits,
            } => {
                tx.state = TxState::AwaitingFlowControl {
                    deadline: Some(now.plus_micros(self.config.n_bs_us)),
                    waits,
                };
            }
            TxState::SendingBlock {
                next_at: None,
                left_in_block,
                st_min_us,
            } => {
                tx.state = TxState::SendingBlock {
                    next_at: Some(now.plus_micros(st_min_us)),
                    left_in_block,
                    st_min_us,
                };
            }
            // A flow control overtook the confirmation (N_Bs or STmin already settled),
            // or the transmission was ended meanwhile.
            _ => {}
        }
    }

    fn on_flow_control_confirmed(&mut self, now: Instant, status: FlowStatus) {
        let rx = &mut self.receiver;
        match (status, &mut rx.state) {
            (FlowStatus::ContinueToSend, RxState::Receiving { deadline, .. })
                // Not if a newer FF replaced the reception and its own CTS is still due.
                if rx.flow_control_due.is_none() =>
            {
                *deadline = Some(now.plus_micros(self.config.n_cr_us));
            }
            (
                FlowStatus::Wait,
                RxState::Waiting {
                    next_at: next_at @ None,
                    since,
                    ..
                },
            ) => {
                *next_at = Some(now.plus_micros(self.config.n_br_us));
                *since = now;
            }
            _ => {}
        }
    }
}

/// The earliest of some optional instants.
struct Earliest(Option<Instant>);

impl Earliest {
    fn take(&mut self, candidate: Option<Instant>) {
        self.0 = match (self.0, candidate) {
            (Some(current), Some(candidate)) => Some(current.min(candidate)),
            (current, candidate) => current.or(candidate),
        };
    }
}
