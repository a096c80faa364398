//! A socketcand server in raw mode (the protocol of linux-can's socketcand, which
//! python-can's `socketcand` interface, `cantools monitor` through python-can, and
//! SavvyCAN speak), so tools attach to the virtual car's bus over TCP.
//!
//! Per client: `< hi >`; the client opens the bus (`< open can0 >` → `< ok >`) and asks for
//! raw mode (`< rawmode >` → `< ok >`); from then on every bus frame reaches it as
//! `< frame 123 12.345678 DEADBEEF >` and its `< send 123 4 de ad be ef >` puts a frame on
//! the bus. `< echo >` is answered with `< echo >`. What python-can needs, as checked in
//! `shared/spec/tool-interop.md`: each handshake reply is a write of its own, no frame is
//! sent before raw mode is acknowledged, Nagle is off, identifiers are exactly 3 hex digits
//! and a frame without data keeps its empty field. A client never receives its own frames.
//! Frames start [`RAW_MODE_GRACE`] after the rawmode `< ok >` is written: python-can reads
//! that reply with a single `recv()`, and a frame that reaches its socket first is glued to
//! the reply and fails its connect.
//!
//! The simulation thread only calls [`SocketcandServer::broadcast`] and
//! [`SocketcandServer::try_recv`], which never block it: each client has a writer thread fed
//! through a channel, and received frames wait in a channel until the simulation takes them.

use autoplug_can::Frame;
use std::io::{self, BufWriter, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::Duration;

/// The bus name clients open.
pub const BUS_NAME: &str = "can0";

/// Time between writing the rawmode `< ok >` and a client's first frame. python-can compares
/// that reply with what one `recv()` returns; on a busy machine it may reach that `recv()`
/// milliseconds after the reply arrived, and a frame arriving meanwhile makes the connect
/// fail (`Expected '< ok >' got: '< ok >< frame ...'`).
pub const RAW_MODE_GRACE: Duration = Duration::from_millis(50);

/// A frame a client sent, and which client.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClientFrame {
    /// The client (connection number, from 1).
    pub client: u64,
    /// The frame.
    pub frame: Frame,
}

struct Client {
    id: u64,
    raw_mode: Arc<AtomicBool>,
    outbox: Sender<Outgoing>,
}

/// What a client's writer thread is asked to do.
enum Outgoing {
    /// Write this message (one write of its own).
    Message(String),
    /// The rawmode `< ok >` has been written: after [`RAW_MODE_GRACE`], let frames through.
    EnterRawMode,
}

/// The running server.
pub struct SocketcandServer {
    address: SocketAddr,
    clients: Arc<Mutex<Vec<Client>>>,
    inbox: Receiver<ClientFrame>,
    refused: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
}

impl SocketcandServer {
    /// Listens on `address` (port 0 picks a free port; see [`SocketcandServer::address`]).
    pub fn start(address: &str) -> io::Result<Self> {
        let listener = TcpListener::bind(address)?;
        let address = listener.local_addr()?;
        listener.set_nonblocking(true)?;
        let clients: Arc<Mutex<Vec<Client>>> = Arc::default();
        let (to_sim, inbox) = mpsc::channel();
        let refused = Arc::new(AtomicU64::new(0));
        let stop = Arc::new(AtomicBool::new(false));
        {
            let clients = Arc::clone(&clients);
            let refused = Arc::clone(&refused);
            let stop = Arc::clone(&stop);
            thread::spawn(move || accept_loop(listener, clients, to_sim, refused, stop));
        }
        Ok(Self {
            address,
            clients,
            inbox,
            refused,
            stop,
        })
    }

    /// The address the server listens on.
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Clients in raw mode, receiving frames.
    pub fn raw_clients(&self) -> usize {
        self.lock_clients()
            .iter()
            .filter(|c| c.raw_mode.load(Ordering::Acquire))
            .count()
    }

    /// Sends a bus frame to every client in raw mode except `from_client` (its sender).
    pub fn broadcast(&self, t_us: u64, frame: &Frame, from_client: Option<u64>) {
        let text = frame_message(t_us, frame);
        let mut clients = self.lock_clients();
        // A client whose writer has gone (disconnected) is dropped here.
        clients.retain(|c| {
            if Some(c.id) == from_client || !c.raw_mode.load(Ordering::Acquire) {
                return true;
            }
            c.outbox.send(Outgoing::Message(text.clone())).is_ok()
        });
    }

    /// The next frame a client sent, if any (never blocks).
    pub fn try_recv(&self) -> Option<ClientFrame> {
        self.inbox.try_recv().ok()
    }

    /// Client commands refused so far (malformed `send`, unknown commands).
    pub fn refused_commands(&self) -> u64 {
        self.refused.load(Ordering::Relaxed)
    }

    fn lock_clients(&self) -> std::sync::MutexGuard<'_, Vec<Client>> {
        self.clients.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl Drop for SocketcandServer {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Release);
        // Dropping the outboxes ends the writer threads, which close their sockets.
        self.lock_clients().clear();
    }
}

/// `< frame 123 12.345678 DEADBEEF >`
fn frame_message(t_us: u64, frame: &Frame) -> String {
    let mut data = String::with_capacity(16);
    for b in frame.data() {
        data.push_str(&format!("{b:02X}"));
    }
    format!(
        "< frame {:03X} {}.{:06} {data} >",
        frame.id(),
        t_us / 1_000_000,
        t_us % 1_000_000
    )
}

fn accept_loop(
    listener: TcpListener,
    clients: Arc<Mutex<Vec<Client>>>,
    to_sim: Sender<ClientFrame>,
    refused: Arc<AtomicU64>,
    stop: Arc<AtomicBool>,
) {
    let mut next_id = 1;
    while !stop.load(Ordering::Acquire) {
        match listener.accept() {
            Ok((stream, _)) => {
                let id = next_id;
                next_id += 1;
                if let Err(e) = serve(stream, id, &clients, to_sim.clone(), Arc::clone(&refused)) {
                    eprintln!("socketcand: client {id}: {e}");
                }
            }
            Err(e) if e.kind() == io::ErrorKind::WouldBlock => {
                thread::sleep(Duration::from_millis(5));
            }
            Err(e) => {
                eprintln!("socketcand: accept failed: {e}");
                thread::sleep(Duration::from_millis(50));
            }
        }
    }
}

fn serve(
    stream: TcpStream,
    id: u64,
    clients: &Arc<Mutex<Vec<Client>>>,
    to_sim: Sender<ClientFrame>,
    refused: Arc<AtomicU64>,
) -> io::Result<()> {
    stream.set_nonblocking(false)?;
    stream.set_nodelay(true)?;
    let (outbox, outgoing) = mpsc::channel::<Outgoing>();
    let raw_mode = Arc::new(AtomicBool::new(false));
    let writer_stream = stream.try_clone()?;
    {
        let raw_mode = Arc::clone(&raw_mode);
        thread::spawn(move || write_loop(writer_stream, outgoing, raw_mode));
    }
    outbox
        .send(Outgoing::Message("< hi >".to_string()))
        .map_err(|_| io::Error::other("writer ended"))?;
    clients
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push(Client {
            id,
            raw_mode: Arc::clone(&raw_mode),
            outbox: outbox.clone(),
        });
    thread::spawn(move || read_loop(stream, id, outbox, to_sim, refused));
    Ok(())
}

/// One write per message: python-can compares each handshake reply as a whole `recv()`.
/// Raw mode starts here, [`RAW_MODE_GRACE`] after its `< ok >` went out, so no frame is
/// queued for the client before then.
fn write_loop(stream: TcpStream, outgoing: Receiver<Outgoing>, raw_mode: Arc<AtomicBool>) {
    let mut out = BufWriter::new(stream);
    for item in outgoing {
        match item {
            Outgoing::Message(message) => {
                if out
                    .write_all(message.as_bytes())
                    .and_then(|_| out.flush())
                    .is_err()
                {
                    break;
                }
            }
            Outgoing::EnterRawMode => {
                thread::sleep(RAW_MODE_GRACE);
                raw_mode.store(true, Ordering::Release);
            }
        }
    }
}

fn read_loop(
    mut stream: TcpStream,
    id: u64,
    outbox: Sender<Outgoing>,
    to_sim: Sender<ClientFrame>,
    refused: Arc<AtomicU64>,
) {
    let mut buffer = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    let mut opened = false;
    // Raw mode as far as the client's commands go: sending is allowed from the `< ok >` on
    // (frames to the client start a grace later, see `write_loop`).
    let mut raw = false;
    loop {
        let n = match stream.read(&mut chunk) {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        buffer.extend_from_slice(&chunk[..n]);
        while let Some(message) = take_message(&mut buffer) {
            let mut entering_raw = false;
            let reply = match parse_command(&message) {
                Ok(Command::Open(bus)) if bus == BUS_NAME => {
                    opened = true;
                    Some("< ok >".to_string())
                }
                Ok(Command::Open(bus)) => {
                    refused.fetch_add(1, Ordering::Relaxed);
                    Some(format!(
                        "< error could not open bus '{bus}': this server has {BUS_NAME} >"
                    ))
                }
                Ok(Command::RawMode) if opened => {
                    entering_raw = !raw;
                    raw = true;
                    Some("< ok >".to_string())
                }
                Ok(Command::RawMode) => {
                    refused.fetch_add(1, Ordering::Relaxed);
                    Some("< error open a bus before rawmode >".to_string())
                }
                Ok(Command::Echo) => Some("< echo >".to_string()),
                Ok(Command::Send(frame)) if raw => {
                    if to_sim.send(ClientFrame { client: id, frame }).is_err() {
                        return;
                    }
                    None
                }
                Ok(Command::Send(_)) => {
                    refused.fetch_add(1, Ordering::Relaxed);
                    Some("< error send needs rawmode >".to_string())
                }
                Err(reason) => {
                    refused.fetch_add(1, Ordering::Relaxed);
                    eprintln!("socketcand: client {id}: refused '{message}': {reason}");
                    None
                }
            };
            if let Some(reply) = reply {
                if outbox.send(Outgoing::Message(reply)).is_err() {
                    return;
                }
            }
            // Frames only after the rawmode acknowledgement is written, and a grace later
            // (the writer thread switches raw mode on).
            if entering_raw && outbox.send(Outgoing::EnterRawMode).is_err() {
                return;
            }
        }
        if buffer.len() > 64 * 1024 {
            eprintln!("socketcand: client {id}: no '>' in 64 KiB, disconnecting");
            break;
        }
    }
}

/// Removes and returns the first complete `< ... >` message, without the brackets.
fn take_message(buffer: &mut Vec<u8>) -> Option<String> {
    let start = buffer.iter().position(|&b| b == b'<')?;
    let end = start + buffer[start..].iter().position(|&b| b == b'>')?;
    let message = String::from_utf8_lossy(&buffer[start + 1..end])
        .trim()
        .to_string();
    buffer.drain(..=end);
    Some(message)
}

/// A client command.
#[derive(Debug, PartialEq, Eq)]
pub enum Command {
    /// `open BUS`.
    Open(String),
    /// `rawmode`.
    RawMode,
    /// `echo`.
    Echo,
    /// `send ID LEN BYTES...`.
    Send(Frame),
}

/// Parses a message's inside (`send 123 2 de ad`).
pub fn parse_command(message: &str) -> Result<Command, String> {
    let mut words = message.split_whitespace();
    match words.next() {
        Some("open") => match (words.next(), words.next()) {
            (Some(bus), None) => Ok(Command::Open(bus.to_string())),
            _ => Err("expected 'open BUS'".into()),
        },
        Some("rawmode") => Ok(Command::RawMode),
        Some("echo") => Ok(Command::Echo),
        Some("send") => {
            let id_text = words.next().ok_or("send without an identifier")?;
            if id_text.len() == 8 {
                return Err(format!(
                    "identifier {id_text} is extended (29-bit); the AutoPlug bus uses 11-bit identifiers"
                ));
            }
            let id = u32::from_str_radix(id_text, 16)
                .map_err(|_| format!("identifier '{id_text}' is not hexadecimal"))?;
            let len: usize = words
                .next()
                .ok_or("send without a length")?
                .parse()
                .map_err(|_| "length is not a number".to_string())?;
            let mut data = Vec::with_capacity(8);
            for word in words {
                data.push(
                    u8::from_str_radix(word, 16)
                        .map_err(|_| format!("data byte '{word}' is not hexadecimal"))?,
                );
            }
            if data.len() != len {
                return Err(format!("length {len} but {} data bytes", data.len()));
            }
            Frame::new(id, &data)
                .map(Command::Send)
                .map_err(|e| e.to_string())
        }
        Some(other) => Err(format!("unknown command '{other}'")),
        None => Err("empty message".into()),
    }
}
