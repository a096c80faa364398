//! Real-time transports: how frames reach a bus, behind one blocking [`Transport`] trait.
//!
//! - [`socketcand::SocketcandClient`]: the socketcand protocol (raw mode) over TCP, as a
//!   client of the virtual car's server or of a socketcand daemon next to a real bus;
//! - `socketcan::SocketCanTransport` (Linux only): a CAN interface of the kernel, e.g. a
//!   USB-CAN adapter.
//!
//! Which one is named by a URL ([`Via`]): `socketcand://HOST:PORT/BUS` or
//! `socketcan://IFACE`. `autoplug_tester::driver` runs a job over any of them with the wall clock.
//!
//! A transport takes only as many frames as its transmit queue holds and confirms each
//! once it is on the bus, so a sender is paced by the bus, whatever queues lie between:
//! SocketCAN with the kernel's echo of each frame sent, socketcand (whose server never
//! echoes) with a model of the bus ([`pace::BusModel`]).

#![deny(missing_docs)]

pub mod pace;
#[cfg(target_os = "linux")]
pub mod socketcan;
pub mod socketcand;
mod via;

pub use via::{Via, ViaError, DEFAULT_SOCKETCAND_PORT};

use std::fmt;
use std::io;
use std::time::Duration;

use autoplug_can::Frame;

/// When a frame was received.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Timestamp {
    /// On this host, when the transport handed the frame over.
    pub host: std::time::Instant,
    /// On the bus, as the other end reports it (socketcand's `SECS.USECS`), µs; `None`
    /// when the transport has no such time.
    pub bus_us: Option<u64>,
}

/// What a transport hands over.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Incoming {
    /// A frame another node sent.
    Frame(Frame, Timestamp),
    /// The oldest frame this side sent and not confirmed yet is on the bus: its
    /// transmission confirmation (ISO 15765-2's L_Data.con). Frames are confirmed in the
    /// order they were sent.
    Sent,
}

/// A way to put frames on a bus and take them off it, blocking with timeouts.
pub trait Transport {
    /// Offers `frame` for the bus. `Ok(true)`: taken, and an [`Incoming::Sent`] will say
    /// when it is on the bus. `Ok(false)`: the transmit queue is full (at most
    /// [`Transport::transmit_window`] frames wait for the bus): offer it again after a
    /// confirmation.
    fn send(&mut self, frame: &Frame) -> Result<bool, TransportError>;

    /// The next frame from the bus or confirmation of a frame sent, waiting at most
    /// `timeout`; `Ok(None)` when nothing came. Frames this side sent are not received
    /// back as frames.
    fn recv(&mut self, timeout: Duration) -> Result<Option<Incoming>, TransportError>;

    /// What the transport is connected to, for messages (`socketcand 127.0.0.1:29536 can0`).
    fn describe(&self) -> String;

    /// Frames the transport takes before the first of them is confirmed.
    fn transmit_window(&self) -> usize;

    /// ΔP2 (ISO 14229-2): the most the transport adds to the wait for a response, from
    /// an ECU's response on the bus to its arrival here, and from a frame on the bus to its
    /// confirmation here.
    fn network_delay(&self) -> Duration;
}

impl<T: Transport + ?Sized> Transport for Box<T> {
    fn send(&mut self, frame: &Frame) -> Result<bool, TransportError> {
        (**self).send(frame)
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<Incoming>, TransportError> {
        (**self).recv(timeout)
    }

    fn describe(&self) -> String {
        (**self).describe()
    }

    fn transmit_window(&self) -> usize {
        (**self).transmit_window()
    }

    fn network_delay(&self) -> Duration {
        (**self).network_delay()
    }
}

/// Why a transport failed.
#[derive(Debug)]
pub enum TransportError {
    /// An operating-system error, with what was being done.
    Io {
        /// What was being done, e.g. "connecting to socketcand at 127.0.0.1:29536".
        context: String,
        /// The error.
        source: io::Error,
    },
    /// The other end said something this client does not understand.
    Protocol(String),
    /// The other end refused a command (socketcand's `< error ... >`).
    Refused {
        /// The command.
        command: String,
        /// The server's message.
        message: String,
    },
    /// The connection was closed by the other end.
    Closed(String),
    /// This transport does not exist on this system or in this build.
    Unsupported(String),
}

impl fmt::Display for TransportError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TransportError::Io { context, source } => write!(f, "{context}: {source}"),
            TransportError::Protocol(message) => f.write_str(message),
            TransportError::Refused { command, message } => {
                write!(f, "the server refused '{command}': {message}")
            }
            TransportError::Closed(what) => write!(f, "{what} closed the connection"),
            TransportError::Unsupported(what) => f.write_str(what),
        }
    }
}

impl std::error::Error for TransportError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            TransportError::Io { source, .. } => Some(source),
            _ => None,
        }
    }
}

/// Connects to the bus `via` names.
pub fn open(via: &Via) -> Result<Box<dyn Transport>, TransportError> {
    match via {
        Via::Socketcand { host, port, bus } => Ok(Box::new(socketcand::SocketcandClient::connect(
            host,
            *port,
            bus,
            socketcand::CONNECT_TIMEOUT,
        )?)),
        #[cfg(target_os = "linux")]
        Via::Socketcan { interface } => {
            Ok(Box::new(socketcan::SocketCanTransport::open(interface)?))
        }
        #[cfg(not(target_os = "linux"))]
        Via::Socketcan { interface } => Err(TransportError::Unsupported(format!(
            "socketcan://{interface}: SocketCAN exists only on Linux"
        ))),
    }
}
