//! ISO 15765-2 (ISO-TP) transport over classic CAN, for UDS (ISO 14229) on the AutoPlug
//! bus: `no_std`, no allocation, no `unsafe`.
//!
//! A [`Channel`] carries PDUs of up to 4095 bytes in both directions at once over one
//! pair of identifiers, e.g. an ECU's UDS request identifier (received) and response
//! identifier (sent), plus optionally a functional request identifier (0x7DF) on which
//! only single frames are taken. It is a state machine driven by a polling loop with
//! explicit time, the same on the Cortex-M4F and in the simulation: received frames go in
//! through [`Channel::on_frame`], frames to send come out of [`Channel::poll_transmit`]
//! and are confirmed with [`Channel::confirm_transmit`] once on the bus, timeouts and
//! queued events come out of [`Channel::poll`], and [`Channel::next_deadline`] says when
//! to call again. A received PDU stays in the channel's buffer ([`Channel::received`])
//! until the upper layer [`Channel::release`]s it.
//!
//! # Covered
//!
//! - Classic CAN (8-byte frames), normal addressing, 11-bit identifiers, physical
//!   addressing both ways and functional addressing on reception (single frames only,
//!   reported with `functional: true`; a functional request does not disturb a physical
//!   reception, it is dropped with [`ChannelError::ReceiverBusy`] instead).
//! - Single frames (1..=7 bytes), first frames with the 12-bit length (8..=4095),
//!   consecutive frames (sequence numbers 1..=15, then 0, 1, ...), flow control (CTS,
//!   WAIT, OVFLW), block size and STmin in milliseconds and 100 µs steps, reserved STmin
//!   values read as 127 ms.
//! - Padding of every frame sent to 8 bytes with a configured byte, or minimal DLCs;
//!   both accepted from the peer.
//! - The N_As, N_Ar, N_Bs and N_Cr timeouts, FC.WAIT as sender (restarts N_Bs, at most
//!   `max_wait_frames` in a row) and as receiver (sent every N_Br while the upper layer
//!   is not ready, then FC.OVFLW), FC.OVFLW both ways, wrong sequence numbers, a new
//!   single or first frame interrupting a reception.
//! - Frames that are not valid PDUs are ignored, as ISO 15765-2 requires: too short for
//!   their PCI, a single frame of length 0 or longer than its frame, a first frame shorter
//!   than 8 bytes or announcing fewer than 8, a consecutive frame shorter than the bytes
//!   it has to carry, consecutive and flow control frames out of place, reserved PCI types.
//!
//! # Not covered
//!
//! - CAN FD (longer single frames, the SF_DL escape, data lengths above 8), extended and
//!   mixed addressing, 29-bit identifiers.
//! - Sending or receiving PDUs longer than 4095 bytes: a first frame with the 32-bit
//!   length escape is answered with FC.OVFLW.
//! - N_Bs and N_Cr as performance targets (N_Br / N_Cs): the channel answers and sends as
//!   soon as it is polled; N_Br is used only as the interval between FC.WAIT frames.
//! - Changing STmin or BS through the upper layer mid-transfer (the N_ChangeParameter
//!   service): they are fixed per [`Config`]. As sender, each FC.CTS's BS and STmin apply
//!   to the block it opens.
//!
//! # Timing parameters and defaults
//!
//! [`Config::default_for`] gives:
//!
//! | parameter | meaning | default |
//! | --- | --- | --- |
//! | N_As / N_Ar | frame handed out → its confirmation (data / flow control) | 1000 ms (ISO 15765-2) |
//! | N_Bs | sender: FF, end of block or FC.WAIT → next flow control | 1000 ms (ISO 15765-2) |
//! | N_Cr | receiver: its FC confirmed or a CF → next CF | 1000 ms (ISO 15765-2) |
//! | N_Br | receiver: interval between FC.WAIT frames | 500 ms |
//! | N_WFTmax | FC.WAIT in a row accepted (sender) / sent (receiver) | 10 |
//! | BS | block size advertised as receiver | 8 |
//! | STmin | separation time advertised as receiver | 0 |
//! | padding | byte filling frames to 8 bytes | 0xCC |
//!
//! N_Br is half the peer's default N_Bs, so a WAIT reaches the peer well before its N_Bs
//! (restarted by the previous WAIT) runs out; with N_WFTmax 10 a not-ready receiver
//! holds a sender off for about 5 s. BS 8 with STmin 0 lets each block go at bus speed
//! but bounds a burst to 8 frames, which the AutoPlug firmware's 16-frame receive queue
//! absorbs even when the channel is only polled once per control step. Padding with 0xCC
//! (ISO 15765-2's recommendation) gives every frame the same length on the bus. STmin
//! counts from the confirmation of the previous consecutive frame.
//!
//! # Driving a channel
//!
//! Only one frame of a channel is on its way to the bus at a time: after
//! [`Channel::poll_transmit`] handed one out, it hands out the next only after
//! [`Channel::confirm_transmit`]. Confirm when the CAN controller reports the frame sent;
//! where that is not known, confirm right after queueing it (STmin then counts from
//! there). Events that are not returned by the call that caused them (a second event of
//! one frame, [`Event::Sent`] after a confirmation) come from [`Channel::poll`]: drain it
//! after each call.
#![no_std]
#![deny(missing_docs)]
#![forbid(unsafe_code)]

mod channel;
mod config;
mod event;
mod pdu;

pub use channel::{Channel, MAX_PDU_LEN};
pub use config::{
    Config, StMin, DEFAULT_BLOCK_SIZE, DEFAULT_MAX_WAIT_FRAMES, DEFAULT_N_BR_US, DEFAULT_PADDING,
    DEFAULT_TIMEOUT_US,
};
pub use event::{ChannelError, Direction, Event, SendError};

/// Test cases shared by the host and on-target suites.
#[cfg(any(test, feature = "test-cases"))]
pub mod test_cases;

#[cfg(test)]
mod tests;
