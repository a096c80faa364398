//! What a channel reports to the layer above, and why a send is refused.

use core::fmt;

/// Something the upper layer has to know about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Event {
    /// A complete PDU of `len` bytes is in [`crate::Channel::received`] until
    /// [`crate::Channel::release`].
    Received {
        /// Its length.
        len: usize,
        /// Whether it came on the functional identifier.
        functional: bool,
    },
    /// The PDU given to [`crate::Channel::send`] is out: its last frame was confirmed.
    Sent,
    /// A PDU was lost: the transmission or reception in progress (see
    /// [`ChannelError::direction`]) was abandoned, or an incoming one was refused.
    Error(ChannelError),
}

/// Which half of a channel an error ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Direction {
    /// The PDU being sent is lost; the channel can send again.
    Transmit,
    /// The PDU being received (or arriving) is lost.
    Receive,
}

/// Why a PDU was lost. Each one ends the transfer it concerns; the other direction goes
/// on. Frames that are merely invalid or out of place are ignored without an event.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ChannelError {
    /// A data frame (SF, FF, CF) handed out was not confirmed within N_As.
    TimeoutAs,
    /// A flow control frame handed out was not confirmed within N_Ar.
    TimeoutAr,
    /// No flow control within N_Bs after a first frame, a block or an FC.WAIT.
    TimeoutBs,
    /// No consecutive frame within N_Cr.
    TimeoutCr,
    /// A consecutive frame with an unexpected sequence number.
    WrongSequenceNumber {
        /// The sequence number due.
        expected: u8,
        /// The one received.
        got: u8,
    },
    /// The peer answered FC.OVFLW: the PDU is too long for it.
    Overflow,
    /// The peer sent more FC.WAIT frames in a row than `max_wait_frames`.
    TooManyWaits {
        /// The limit that was exceeded.
        max: u8,
    },
    /// The peer sent a flow control with a reserved flow status.
    InvalidFlowStatus(u8),
    /// A new single or first frame on the physical identifier ended the reception in
    /// progress (the new PDU is handled as usual).
    ReceptionInterrupted,
    /// An incoming PDU longer than the receive buffer (or with the 32-bit length escape)
    /// was refused with FC.OVFLW, or, as a single frame, dropped.
    IncomingTooLong {
        /// The length the first (or single) frame announced.
        announced: u32,
        /// The receive buffer's size.
        capacity: usize,
    },
    /// An incoming segmented PDU was refused with FC.OVFLW: the receiver was still not
    /// ready (not released, or not set ready) after `waits` FC.WAIT frames.
    IncomingRefused {
        /// FC.WAIT frames sent before giving up.
        waits: u8,
    },
    /// A single frame was dropped: the previous PDU was not released yet, the receiver
    /// was set not ready, or (for a functional one) a physical reception was in progress.
    ReceiverBusy,
}

impl ChannelError {
    /// Whether the error ended a transmission or a reception.
    pub const fn direction(&self) -> Direction {
        match self {
            ChannelError::TimeoutAs
            | ChannelError::TimeoutBs
            | ChannelError::Overflow
            | ChannelError::TooManyWaits { .. }
            | ChannelError::InvalidFlowStatus(_) => Direction::Transmit,
            ChannelError::TimeoutAr
            | ChannelError::TimeoutCr
            | ChannelError::WrongSequenceNumber { .. }
            | ChannelError::ReceptionInterrupted
            | ChannelError::IncomingTooLong { .. }
            | ChannelError::IncomingRefused { .. }
            | ChannelError::ReceiverBusy => Direction::Receive,
        }
    }
}

impl fmt::Display for ChannelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            ChannelError::TimeoutAs => f.write_str(
                "N_As timeout: a data frame handed out was not confirmed sent; transmission aborted",
            ),
            ChannelError::TimeoutAr => f.write_str(
                "N_Ar timeout: a flow control frame handed out was not confirmed sent; reception aborted",
            ),
            ChannelError::TimeoutBs => f.write_str(
                "N_Bs timeout: no flow control from the receiver; transmission aborted",
            ),
            ChannelError::TimeoutCr => f.write_str(
                "N_Cr timeout: no consecutive frame from the sender; reception aborted",
            ),
            ChannelError::WrongSequenceNumber { expected, got } => write!(
                f,
                "consecutive frame with sequence number {got} where {expected} was due; reception aborted"
            ),
            ChannelError::Overflow => f.write_str(
                "the receiver answered FC.OVFLW (PDU too long for it); transmission aborted",
            ),
            ChannelError::TooManyWaits { max } => write!(
                f,
                "the receiver sent more than {max} FC.WAIT in a row; transmission aborted"
            ),
            ChannelError::InvalidFlowStatus(status) => write!(
                f,
                "flow control with reserved flow status {status}; transmission aborted"
            ),
            ChannelError::ReceptionInterrupted => f.write_str(
                "a new single or first frame arrived during a segmented reception; the old PDU is lost",
            ),
            ChannelError::IncomingTooLong {
                announced,
                capacity,
            } => write!(
                f,
                "incoming PDU of {announced} bytes does not fit the {capacity}-byte receive buffer; refused"
            ),
            ChannelError::IncomingRefused { waits } => write!(
                f,
                "incoming PDU refused with FC.OVFLW: receiver still not ready after {waits} FC.WAIT"
            ),
            ChannelError::ReceiverBusy => f.write_str(
                "single frame dropped: the receiver still held an unreleased PDU, was not ready, or was receiving",
            ),
        }
    }
}

/// Why [`crate::Channel::send`] refused a PDU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SendError {
    /// A transmission is in progress; wait for its [`Event::Sent`] or error.
    Busy,
    /// An empty PDU: ISO-TP has no frame for it.
    Empty,
    /// Longer than the transmit buffer or the 4095 bytes a 12-bit length carries.
    TooLong {
        /// The length given.
        len: usize,
        /// The longest this channel sends.
        max: usize,
    },
}

impl fmt::Display for SendError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            SendError::Busy => f.write_str(
                "a transmission is already in progress on this channel (wait for Sent or an error)",
            ),
            SendError::Empty => f.write_str("empty PDU: ISO-TP carries 1 byte or more"),
            SendError::TooLong { len, max } => {
                write!(f, "PDU of {len} bytes: this channel sends at most {max}")
            }
        }
    }
}
