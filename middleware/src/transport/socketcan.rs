//! A Linux SocketCAN interface (a USB-CAN adapter's `can0`, or `vcan0`), raw socket.
//!
//! The interface has to be up at 500 kbit/s already
//! (`ip link set can0 up type can bitrate 500000`): configuring it needs privileges a
//! flash tool should not have. Remote, error and 29-bit frames are skipped; the AutoPlug
//! bus carries 11-bit data frames only.

use std::io;
use std::time::{Duration, Instant as WallInstant};

use autoplug_can::Frame;
use socketcan::{CanDataFrame, CanFrame, CanSocket, EmbeddedFrame, Id, Socket, StandardId};

use super::{Timestamp, Transport, TransportError};

/// How long `send` retries while the interface's transmit queue is full (ENOBUFS): the
/// tester hands out a whole TransferData block at once, faster than 500 kbit/s drains it.
const SEND_RETRY_LIMIT: Duration = Duration::from_secs(1);

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
        Ok(Self {
            socket,
            interface: interface.to_string(),
        })
    }
}

impl Transport for SocketCanTransport {
    fn send(&mut self, frame: &Frame) -> Result<(), TransportError> {
        let frame = to_socketcan(frame);
        let give_up = WallInstant::now() + SEND_RETRY_LIMIT;
        loop {
            match self.socket.write_frame(&frame) {
                Ok(()) => return Ok(()),
                // The transmit queue is full: wait for the bus to drain it.
                Err(error)
                    if error.raw_os_error() == Some(105 /* ENOBUFS */)
                        || error.kind() == io::ErrorKind::WouldBlock =>
                {
                    if WallInstant::now() >= give_up {
                        return Err(TransportError::Io {
                            context: format!(
                                "the transmit queue of {} stayed full for {} s (is the bus connected and terminated?)",
                                self.interface,
                                SEND_RETRY_LIMIT.as_secs()
                            ),
                            source: error,
                        });
                    }
                    std::thread::sleep(Duration::from_micros(200));
                }
                Err(source) => {
                    return Err(TransportError::Io {
                        context: format!("sending on {}", self.interface),
                        source,
                    })
                }
            }
        }
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<(Frame, Timestamp)>, TransportError> {
        let deadline = WallInstant::now() + timeout;
        loop {
            let remaining = deadline.saturating_duration_since(WallInstant::now());
            match self.socket.read_frame_timeout(remaining) {
                Ok(frame) => {
                    if let Some(frame) = from_socketcan(&frame) {
                        let timestamp = Timestamp {
                            host: WallInstant::now(),
                            bus_us: None,
                        };
                        return Ok(Some((frame, timestamp)));
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
