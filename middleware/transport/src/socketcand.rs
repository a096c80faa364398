//! A socketcand client in raw mode: frames over TCP, as the virtual car's server
//! (`autoplug_virtual_car::socketcand`) and linux-can's socketcand daemon speak them.
//!
//! ```text
//! server: < hi >
//! client: < open can0 >                   server: < ok >
//! client: < rawmode >                     server: < ok >
//! client: < send 70D 8 02 10 03 cc cc cc cc cc >
//! server: < frame 78D 12.345678 065003003201F4CC >
//! ```
//!
//! Identifiers are hex (3 digits for 11-bit ones, 8 for 29-bit ones), lengths decimal,
//! bytes hex: separated by spaces in `send`, contiguous in `frame`. The server never echoes
//! a client's own frames, so the client confirms them by a model of the bus
//! ([`BusModel`]) and takes at most [`TRANSMIT_WINDOW`] frames ahead of it. Frames with
//! 29-bit identifiers, and `< error ... >` bus error notifications, are skipped: the
//! AutoPlug bus uses 11-bit identifiers only.

use std::collections::VecDeque;
use std::io::{self, Read, Write};
use std::net::{SocketAddr, TcpStream, ToSocketAddrs};
use std::time::{Duration, Instant as WallInstant};

use autoplug_can::Frame;
use autoplug_virtual_bus::DEFAULT_BITRATE;

use super::pace::BusModel;
use super::{Incoming, Timestamp, Transport, TransportError};

/// Frames the client sends ahead of the bus model (a SocketCAN interface's default transmit
/// queue, what the daemon on a bench writes into): 2.7 ms of 8-byte frames at 500 kbit/s.
pub const TRANSMIT_WINDOW: usize = 10;

/// ΔP2 over socketcand: the TCP link both ways, the server's own queues, and whatever the
/// bus model did not see in time (other nodes' frames still on their way to the client).
pub const NETWORK_DELAY: Duration = Duration::from_millis(50);

/// How long connecting and each handshake reply may take.
pub const CONNECT_TIMEOUT: Duration = Duration::from_secs(5);

/// How long the client waits for the answer to its `< echo >` after raw mode (see
/// [`SocketcandClient::handshake`]); a server that does not answer echo costs this once.
const ECHO_TIMEOUT: Duration = Duration::from_millis(500);

/// A server that sends this much without a complete `< ... >` is not speaking socketcand.
const MAX_PENDING_TEXT: usize = 64 * 1024;

/// What the server said, one `< ... >` message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ServerMessage {
    /// `< hi >`, the greeting.
    Hi,
    /// `< ok >`, a command was accepted.
    Ok,
    /// `< echo >`.
    Echo,
    /// `< frame ID SECS.USECS DATA >` with an 11-bit identifier.
    Frame {
        /// The frame.
        frame: Frame,
        /// The server's timestamp of it, µs.
        bus_us: u64,
    },
    /// A frame with a 29-bit identifier (not part of the AutoPlug bus).
    ExtendedFrame,
    /// `< error ... >`: a refused command or a bus error notification.
    Error(String),
    /// Anything else (e.g. modes this client does not use).
    Other(String),
}

/// Parses the inside of one message (`frame 123 1.000000 DEADBEEF`); `Err` says what is
/// wrong with a malformed frame.
pub fn parse_server_message(message: &str) -> Result<ServerMessage, String> {
    let mut words = message.split_whitespace();
    match words.next() {
        Some("hi") => Ok(ServerMessage::Hi),
        Some("ok") => Ok(ServerMessage::Ok),
        Some("echo") => Ok(ServerMessage::Echo),
        Some("error") => Ok(ServerMessage::Error(words.collect::<Vec<_>>().join(" "))),
        Some("frame") => {
            let id_text = words.next().ok_or("a frame without an identifier")?;
            let id = u32::from_str_radix(id_text, 16)
                .map_err(|_| format!("identifier '{id_text}' is not hexadecimal"))?;
            if id_text.len() > 3 {
                return Ok(ServerMessage::ExtendedFrame);
            }
            let time_text = words.next().ok_or("a frame without a timestamp")?;
            let bus_us = parse_timestamp(time_text)
                .ok_or_else(|| format!("timestamp '{time_text}' is not SECONDS.MICROSECONDS"))?;
            let hex: String = words.collect();
            if hex.len() % 2 != 0 || !hex.chars().all(|c| c.is_ascii_hexdigit()) {
                return Err(format!("data '{hex}' is not whole bytes in hexadecimal"));
            }
            let data: Vec<u8> = (0..hex.len())
                .step_by(2)
                .filter_map(|i| u8::from_str_radix(&hex[i..i + 2], 16).ok())
                .collect();
            let frame = Frame::new(id, &data).map_err(|e| e.to_string())?;
            Ok(ServerMessage::Frame { frame, bus_us })
        }
        Some(_) => Ok(ServerMessage::Other(message.to_string())),
        None => Err("an empty message '< >'".into()),
    }
}

/// `SECS.USECS` (or whole seconds) in µs.
fn parse_timestamp(text: &str) -> Option<u64> {
    let (secs, frac) = text.split_once('.').unwrap_or((text, ""));
    let secs: u64 = secs.parse().ok()?;
    if frac.len() > 6 || !frac.chars().all(|c| c.is_ascii_digit()) {
        return None;
    }
    let micros: u64 = format!("{frac:0<6}").parse().ok()?;
    secs.checked_mul(1_000_000)?.checked_add(micros)
}

/// The `send` command for `frame`: `< send 70D 3 02 10 03 >`.
pub fn format_send(frame: &Frame) -> String {
    let mut text = format!("< send {:03X} {}", frame.id(), frame.len());
    for byte in frame.data() {
        text.push_str(&format!(" {byte:02x}"));
    }
    text.push_str(" >");
    text
}

/// Removes and returns the inside of the first complete `< ... >` in `buffer` (text before
/// its `<` is dropped).
fn take_message(buffer: &mut Vec<u8>) -> Option<String> {
    let start = buffer.iter().position(|&b| b == b'<')?;
    let end = start + buffer[start..].iter().position(|&b| b == b'>')?;
    let message = String::from_utf8_lossy(&buffer[start + 1..end])
        .trim()
        .to_string();
    buffer.drain(..=end);
    Some(message)
}

/// A connection to a socketcand server, in raw mode on one bus.
#[derive(Debug)]
pub struct SocketcandClient {
    stream: TcpStream,
    buffer: Vec<u8>,
    peer: String,
    bus: String,
    skipped: u64,
    /// Frames that arrived during the handshake.
    early: VecDeque<(Frame, u64)>,
    /// When this client's frames are on the bus (the server does not say).
    bus_model: BusModel,
}

impl SocketcandClient {
    /// Connects to `host:port`, opens `bus` and switches to raw mode.
    pub fn connect(
        host: &str,
        port: u16,
        bus: &str,
        timeout: Duration,
    ) -> Result<Self, TransportError> {
        let peer = if host.contains(':') {
            format!("[{host}]:{port}")
        } else {
            format!("{host}:{port}")
        };
        let addresses: Vec<SocketAddr> = (host, port)
            .to_socket_addrs()
            .map_err(|source| TransportError::Io {
                context: format!("cannot resolve the socketcand host '{host}'"),
                source,
            })?
            .collect();
        let mut last_error = None;
        for address in &addresses {
            match TcpStream::connect_timeout(address, timeout) {
                Ok(stream) => return Self::handshake(stream, &peer, bus, timeout),
                Err(error) => last_error = Some(error),
            }
        }
        Err(TransportError::Io {
            context: format!(
                "cannot connect to the socketcand server at {peer} (is the virtual car running with --socketcand {peer}, or socketcand on the bench?)"
            ),
            source: last_error
                .unwrap_or_else(|| io::Error::new(io::ErrorKind::NotFound, "no address")),
        })
    }

    /// Runs the handshake on a connected stream: `< hi >`, `open`, `rawmode`, then an
    /// `< echo >` round trip. The echo is there because a server may let frames through
    /// some time after its `< ok >` to rawmode (the virtual car's waits 50 ms, for
    /// python-can's sake): its answer comes after that, so no response to the first
    /// request is lost.
    pub fn handshake(
        stream: TcpStream,
        peer: &str,
        bus: &str,
        timeout: Duration,
    ) -> Result<Self, TransportError> {
        // Nagle would hold back the frames of a block by tens of milliseconds.
        stream
            .set_nodelay(true)
            .map_err(|source| TransportError::Io {
                context: format!("configuring the connection to {peer}"),
                source,
            })?;
        let mut client = Self {
            stream,
            buffer: Vec::new(),
            peer: peer.to_string(),
            bus: bus.to_string(),
            skipped: 0,
            early: VecDeque::new(),
            // The AutoPlug bus's rate (spec section 3).
            bus_model: BusModel::new(DEFAULT_BITRATE),
        };
        match client.expect_reply(timeout, "the greeting '< hi >'")? {
            ServerMessage::Hi => {}
            other => {
                return Err(TransportError::Protocol(format!(
                    "{peer} greeted with {other:?} instead of '< hi >': is it a socketcand server?"
                )))
            }
        }
        for command in [format!("open {bus}"), "rawmode".to_string()] {
            client.write_text(&format!("< {command} >"))?;
            match client.expect_reply(timeout, &format!("the answer to '{command}'"))? {
                ServerMessage::Ok => {}
                ServerMessage::Error(message) => {
                    return Err(TransportError::Refused { command, message })
                }
                other => {
                    return Err(TransportError::Protocol(format!(
                        "{peer} answered '{command}' with {other:?} instead of '< ok >'"
                    )))
                }
            }
        }
        client.write_text("< echo >")?;
        let deadline = WallInstant::now() + ECHO_TIMEOUT;
        loop {
            while let Some(message) = take_message(&mut client.buffer) {
                match parse_server_message(&message) {
                    Ok(ServerMessage::Echo) => return Ok(client),
                    Ok(ServerMessage::Frame { frame, bus_us }) => {
                        client.early.push_back((frame, bus_us))
                    }
                    Ok(_) => client.skipped += 1,
                    Err(reason) => {
                        return Err(TransportError::Protocol(format!(
                            "{peer} sent a malformed message '< {message} >': {reason}"
                        )))
                    }
                }
            }
            // A server without echo: go on, at worst a first answer is lost and repeated.
            if !client.read_more(deadline)? {
                return Ok(client);
            }
        }
    }

    /// Messages skipped so far (29-bit frames, error notifications, others).
    pub fn skipped(&self) -> u64 {
        self.skipped
    }

    fn expect_reply(
        &mut self,
        timeout: Duration,
        what: &str,
    ) -> Result<ServerMessage, TransportError> {
        let deadline = WallInstant::now() + timeout;
        loop {
            if let Some(message) = take_message(&mut self.buffer) {
                return parse_server_message(&message).map_err(|reason| {
                    TransportError::Protocol(format!(
                        "{} sent '< {message} >' where {what} was due: {reason}",
                        self.peer
                    ))
                });
            }
            if !self.read_more(deadline)? {
                return Err(TransportError::Protocol(format!(
                    "no {what} from {} within {} s: is it a socketcand server?",
                    self.peer,
                    timeout.as_secs_f32()
                )));
            }
        }
    }

    /// Reads what is there, waiting until `deadline` at most; `false` when nothing came.
    fn read_more(&mut self, deadline: WallInstant) -> Result<bool, TransportError> {
        let remaining = deadline.saturating_duration_since(WallInstant::now());
        let io_error = |source: io::Error, peer: &str| TransportError::Io {
            context: format!("reading from the socketcand server at {peer}"),
            source,
        };
        // A zero timeout means "only what is already there": a read timeout of zero is
        // not allowed, and the smallest one is rounded up to a kernel tick.
        let nonblocking = remaining.is_zero();
        let configured = if nonblocking {
            self.stream.set_nonblocking(true)
        } else {
            self.stream
                .set_nonblocking(false)
                .and_then(|()| self.stream.set_read_timeout(Some(remaining)))
        };
        configured.map_err(|e| io_error(e, &self.peer))?;
        let mut chunk = [0u8; 4096];
        let result = self.stream.read(&mut chunk);
        if nonblocking {
            self.stream
                .set_nonblocking(false)
                .map_err(|e| io_error(e, &self.peer))?;
        }
        match result {
            Ok(0) => Err(TransportError::Closed(format!(
                "the socketcand server at {}",
                self.peer
            ))),
            Ok(n) => {
                self.buffer.extend_from_slice(&chunk[..n]);
                if self.buffer.len() > MAX_PENDING_TEXT {
                    return Err(TransportError::Protocol(format!(
                        "{} sent {} bytes without a complete '< ... >' message: not socketcand",
                        self.peer,
                        self.buffer.len()
                    )));
                }
                Ok(true)
            }
            Err(e)
                if matches!(
                    e.kind(),
                    io::ErrorKind::WouldBlock
                        | io::ErrorKind::TimedOut
                        | io::ErrorKind::Interrupted
                ) =>
            {
                Ok(false)
            }
            Err(e) => Err(io_error(e, &self.peer)),
        }
    }

    fn write_text(&mut self, text: &str) -> Result<(), TransportError> {
        self.stream
            .write_all(text.as_bytes())
            .map_err(|source| TransportError::Io {
                context: format!("writing to the socketcand server at {}", self.peer),
                source,
            })
    }
}

impl SocketcandClient {
    /// The next frame already read, if any (the handshake's first); malformed messages
    /// are an error, others are skipped.
    fn buffered_frame(&mut self) -> Result<Option<Incoming>, TransportError> {
        if let Some((frame, bus_us)) = self.early.pop_front() {
            self.bus_model.seen(&frame);
            return Ok(Some(received(frame, bus_us)));
        }
        while let Some(message) = take_message(&mut self.buffer) {
            match parse_server_message(&message) {
                Ok(ServerMessage::Frame { frame, bus_us }) => {
                    self.bus_model.seen(&frame);
                    return Ok(Some(received(frame, bus_us)));
                }
                Ok(_) => self.skipped += 1,
                Err(reason) => {
                    return Err(TransportError::Protocol(format!(
                        "{} sent a malformed message '< {message} >': {reason}",
                        self.peer
                    )))
                }
            }
        }
        Ok(None)
    }
}

fn received(frame: Frame, bus_us: u64) -> Incoming {
    let timestamp = Timestamp {
        host: WallInstant::now(),
        bus_us: Some(bus_us),
    };
    Incoming::Frame(frame, timestamp)
}

impl Transport for SocketcandClient {
    fn send(&mut self, frame: &Frame) -> Result<bool, TransportError> {
        if self.bus_model.in_flight() >= TRANSMIT_WINDOW {
            return Ok(false);
        }
        self.write_text(&format_send(frame))?;
        self.bus_model.sent(WallInstant::now(), frame);
        Ok(true)
    }

    fn recv(&mut self, timeout: Duration) -> Result<Option<Incoming>, TransportError> {
        let deadline = WallInstant::now() + timeout;
        let mut read = false;
        loop {
            if self.bus_model.confirm_due(WallInstant::now()) {
                return Ok(Some(Incoming::Sent));
            }
            if let Some(incoming) = self.buffered_frame()? {
                return Ok(Some(incoming));
            }
            // At least one look at the socket, even with no time to wait.
            if read && WallInstant::now() >= deadline {
                return Ok(None);
            }
            let wake = self
                .bus_model
                .next_confirmation()
                .map_or(deadline, |due| due.min(deadline));
            self.read_more(wake)?;
            read = true;
        }
    }

    fn describe(&self) -> String {
        format!("socketcand {} bus {}", self.peer, self.bus)
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

    #[test]
    fn frames_and_replies_parse() {
        assert_eq!(parse_server_message("hi"), Ok(ServerMessage::Hi));
        assert_eq!(parse_server_message("ok"), Ok(ServerMessage::Ok));
        assert_eq!(
            parse_server_message("frame 78D 12.345678 065003003201F4CC"),
            Ok(ServerMessage::Frame {
                frame: Frame::new(0x78D, &[0x06, 0x50, 0x03, 0x00, 0x32, 0x01, 0xF4, 0xCC])
                    .unwrap(),
                bus_us: 12_345_678
            })
        );
        // Spaces between bytes, a short fraction, no data at all.
        assert_eq!(
            parse_server_message("frame 7df 3.5 02 3e 80"),
            Ok(ServerMessage::Frame {
                frame: Frame::new(0x7DF, &[0x02, 0x3E, 0x80]).unwrap(),
                bus_us: 3_500_000
            })
        );
        assert_eq!(
            parse_server_message("frame 7FF 1795235969.750426"),
            Ok(ServerMessage::Frame {
                frame: Frame::new(0x7FF, &[]).unwrap(),
                bus_us: 1_795_235_969_750_426
            })
        );
        assert_eq!(
            parse_server_message("frame 18DAF110 1.0 01"),
            Ok(ServerMessage::ExtendedFrame)
        );
        assert_eq!(
            parse_server_message("error could not open bus"),
            Ok(ServerMessage::Error("could not open bus".into()))
        );
    }

    #[test]
    fn malformed_frames_say_what_is_wrong() {
        let reason = |m: &str| parse_server_message(m).unwrap_err();
        assert!(reason("frame").contains("without an identifier"));
        assert!(reason("frame XYZ 1.0 00").contains("'XYZ' is not hexadecimal"));
        assert!(reason("frame 123").contains("without a timestamp"));
        assert!(reason("frame 123 now 00").contains("timestamp 'now'"));
        assert!(reason("frame 123 1.0 ABC").contains("not whole bytes"));
        assert!(reason("frame 123 1.0 0011223344556677AA").contains("at most 8"));
        assert!(reason("").contains("empty"));
    }

    #[test]
    fn send_commands_and_message_framing() {
        let frame = Frame::new(0x70D, &[0x02, 0x10, 0x03]).unwrap();
        assert_eq!(format_send(&frame), "< send 70D 3 02 10 03 >");
        assert_eq!(
            format_send(&Frame::new(0x7FF, &[]).unwrap()),
            "< send 7FF 0 >"
        );
        let mut buffer = b"< hi >< ok ><frame 1 2".to_vec();
        assert_eq!(take_message(&mut buffer).as_deref(), Some("hi"));
        assert_eq!(take_message(&mut buffer).as_deref(), Some("ok"));
        assert_eq!(take_message(&mut buffer), None);
        buffer.extend_from_slice(b".0 >");
        assert_eq!(take_message(&mut buffer).as_deref(), Some("frame 1 2.0"));
        assert!(buffer.is_empty());
    }
}
