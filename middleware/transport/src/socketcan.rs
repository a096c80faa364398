//! A Linux SocketCAN interface (a USB-CAN adapter's `can0`, or `vcan0`), raw socket.
//!
//! The interface has to be up at 500 kbit/s already
//! (`ip link set can0 up type can bitrate 500000`): configuring it needs privileges a
//! flash tool should not have. Remote, error and 29-bit frames are skipped; the AutoPlug
//! bus carries 11-bit data frames only.
//!
//! Each frame sent is confirmed by the kernel's echo of it (`CAN_RAW_RECV_OWN_MSGS`), which
//! comes once the controller has sent it, so a sender goes at the bus's pace. The echo is
//! told from other nodes' frames by its content: the oldest of this socket's frames not
//! confirmed yet (the tester's request identifiers are its own). At most
//! [`TRANSMIT_WINDOW`] frames wait for their echo, the interface's default queue length; a
//! queue full all the same (`ENOBUFS`, other sockets' frames in it) refuses the frame, to
//! be offered again.

use std::collections::VecDeque;
use std::io;
use std::time::{Duration, Instant as WallInstant};

use autoplug_can::Frame;
use socketcan::{
    CanDataFrame, CanFrame, CanSocket, EmbeddedFrame, Id, Socket, SocketOptions, StandardId,
};

use super::{Incoming, Timestamp, Transport, TransportError};

/// Frames sent and not echoed yet, at most: the kernel's default transmit queue length
/// (`txqueuelen` 10) for CAN interfaces.
pub const TRANSMIT_WINDOW: usize = 10;

/// ΔP2 on a local interface: the scheduler's latency both ways, and a response that waits
/// behind a few higher-priority frames.
pub const NETWORK_DELAY: Duration = Duration::from_millis(10);

/// `ENOBUFS`: the interface's transmit queue is full.
const ENOBUFS: i32 = 105;

/// The kernel's frame for `frame`.
pub fn to_socketcan(frame: &Frame) -> CanFrame {
    // `Frame` guarantees an 11-bit identifier and at most 8 bytes, which is all
    // `StandardId` and `CanDataFrame` ask for.
    let id = StandardId::new(frame.id()).unwrap_or(StandardId::ZERO);
    CanDataFrame::new(id, frame.data())
        .map(CanFrame::Data)
        .unwrap_or_default()
}

/// The AutoPlug frame of a kernel frame; `None` for remote, error and 29-bit frames.
pub fn from_socketcan(frame: &CanFrame) -> Option<Frame> {
    let CanFrame::Data(data) = frame else {
        return None;
    };
    let Id::Standard(id) = data.id() else {
        return None;
    };
    Frame::new(u32::from(id.as_raw()), data.data()).ok()
}

/// An open SocketCAN interface.
#[derive(Debug)]
pub struct SocketCanTransport {
    socket: CanSocket,
    interface: String,
    /// Frames sent and not echoed yet, oldest first.
    unconfirmed: VecDeque<Frame>,
}

impl SocketCanTransport {
    /// Opens `interface` (it must exist and be up).
    pub fn open(interface: &str) -> Result<Self, TransportError> {
        let socket = CanSocket::open(interface).map_err(|source| TransportError::Io {
            context: format!(
                "cannot open the SocketCAN interface '{interface}' (does it exist and is it up? `ip link set {interface} up type can bitrate 500000`)"
            ),
            source,
        })?;
        socket
            .set_recv_own_msgs(true)
            .map_err(|source| TransportError::Io {
                context: format!(
                    "asking '{interface}' to confirm the frames sent (CAN_RAW_RECV_OWN_MSGS)"
                ),
                source,
            })?;
        Ok(Self {
            socket,
            interface: interface.to_string(),
            unconfirmed: VecDeque::new(),
        })
    }

    /// Whether `frame` read from the socket is the echo of one sent here; takes it off
    /// the unconfirmed ones.
    fn is_echo(&mut self, frame: &Frame) -> bool {
        match self.unconfirmed.iter().position(|sent| sent == frame) {
            Some(index) => {
                self.unconfirmed.remove(index);
                true
            }
            None => false,
        }
    }
}

impl Transport for SocketCanTransport {
    fn send(&mut self, frame: &Frame) -> Result<bool, TransportError> {
        if self.unconfirmed.len() >= TRANSMIT_WINDOW {
            return Ok(false);
        }
        match self.socket.write_frame(&to_socketcan(frame)) {
            Ok(()) => {
                self.unconfirmed.push_back(*frame);
                Ok(true)
            }
            // The queue is full all the same: offered again once the bus has drained some.
            Err(error)
                if error.raw_os_error() == Some(ENOBUFS)
                    || error.kind() == io::ErrorKind::WouldBlock =>
            {
                Ok(false)
            }
            Err(source) => Err(TransportError::Io {
                context: format!("sending on {}", self.interface),
                source,
            }),
        }
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<Incoming>, TransportError> {
        let deadline = WallInstant::now() + timeout;
        loop {
            let remaining = deadline.saturating_duration_since(WallInstant::now());
            match self.socket.read_frame_timeout(remaining) {
                Ok(frame) => {
                    if let Some(frame) = from_socketcan(&frame) {
                        if self.is_echo(&frame) {
                            return Ok(Some(Incoming::Sent));
                        }
                        let timestamp = Timestamp {
                            host: WallInstant::now(),
                            bus_us: None,
                        };
                        return Ok(Some(Incoming::Frame(frame, timestamp)));
                    }
                    if remaining.is_zero() {
                        return Ok(None);
                    }
                }
                Err(error)
                    if matches!(
                        error.kind(),
                        io::ErrorKind::TimedOut
                            | io::ErrorKind::WouldBlock
                            | io::ErrorKind::Interrupted
                    ) =>
                {
                    return Ok(None)
                }
                Err(source) => {
                    return Err(TransportError::Io {
                        context: format!("receiving on {}", self.interface),
                        source,
                    })
                }
            }
        }
    }

    fn describe(&self) -> String {
        format!("SocketCAN {}", self.interface)
    }

    fn transmit_window(&self) -> usize {
        TRANSMIT_WINDOW
    }

    fn network_delay(&self) -> Duration {
        NETWORK_DELAY
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use socketcan::{CanRemoteFrame, ExtendedId};

    #[test]
    fn frames_convert_both_ways() {
        for frame in [
            Frame::new(0x70D, &[0x02, 0x10, 0x03, 0xCC, 0xCC, 0xCC, 0xCC, 0xCC]).unwrap(),
            Frame::new(0x7DF, &[0x02, 0x3E, 0x80]).unwrap(),
            Frame::new(0x000, &[]).unwrap(),
            Frame::new(0x7FF, &[0xFF; 8]).unwrap(),
        ] {
            let kernel = to_socketcan(&frame);
            assert_eq!(
                kernel.id(),
                Id::Standard(StandardId::new(frame.id()).unwrap())
            );
            assert_eq!(kernel.data(), frame.data());
            assert_eq!(from_socketcan(&kernel), Some(frame));
        }
    }

    #[test]
    fn frames_outside_the_autoplug_bus_are_skipped() {
        let extended = CanFrame::Data(
            CanDataFrame::new(ExtendedId::new(0x18DA_F110).unwrap(), &[1, 2]).unwrap(),
        );
        assert_eq!(from_socketcan(&extended), None);
        let remote = CanFrame::Remote(
            CanRemoteFrame::new_remote(StandardId::new(0x123).unwrap(), 2).unwrap(),
        );
        assert_eq!(from_socketcan(&remote), None);
    }

    #[test]
    fn a_missing_interface_is_a_clear_error() {
        // This kernel has no SocketCAN (or no such interface): either way, the error names
        // the interface and how to bring it up.
        let error = SocketCanTransport::open("autoplug-none")
            .unwrap_err()
            .to_string();
        assert!(error.contains("'autoplug-none'"), "{error}");
        assert!(error.contains("ip link set"), "{error}");
    }
}
