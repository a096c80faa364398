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
//! and a frame without data keeps its empty field. A client never receives its own frames; the other clients get them once they are on the bus, as sockets on one SocketCAN interface do.
//! Frames start [`RAW_MODE_GRACE`] after the rawmode `< ok >` is written: python-can reads
//! that reply with a single `recv()`, and a frame that reaches its socket first is glued to
//! the reply and fails its connect.
//!
//! The simulation thread only calls [`SocketcandServer::broadcast`] and
//! [`SocketcandServer::try_recv`], which never block it: each client has a writer thread fed
//! through a bounded channel, and its received frames wait in a bounded queue of its own
//! until the simulation takes them, the clients in turn.
//!
//! **Limits**, for hostile clients: [`MAX_CLIENTS`] at once; [`CLIENT_TO_BUS_FRAMES`]
//! frames per client waiting for the bus and [`CLIENT_OUTBOX_MESSAGES`] messages waiting to
//! be written to it (beyond either, frames are dropped and counted, [`Drops`]);
//! [`MAX_MESSAGE_BYTES`] per message; [`HANDSHAKE_TIMEOUT`] of silence before raw mode.
//! However a connection ends (the client leaves in any state, talks nonsense, times out,
//! stops reading, or the server stops), its threads end and its socket is closed; the
//! frames it had queued for the bus are still sent, up to one queue's worth for all the
//! clients that have gone together.

use autoplug_can::Frame;
use std::collections::VecDeque;
use std::io::{self, BufWriter, Read, Write};
use std::net::{Shutdown, SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread;
use std::time::Duration;

/// The bus name clients open.
pub const BUS_NAME: &str = "can0";

/// Time between writing the rawmode `< ok >` and a client's first frame. python-can compares
/// that reply with what one `recv()` returns; on a busy machine it may reach that `recv()`
/// milliseconds after the reply arrived, and a frame arriving meanwhile makes the connect
/// fail (`Expected '< ok >' got: '< ok >< frame ...'`).
pub const RAW_MODE_GRACE: Duration = Duration::from_millis(50);

/// Clients at once; one more is told so and disconnected.
pub const MAX_CLIENTS: usize = 32;
/// Frames a client may have waiting for the bus: a whole ISO-TP message (4095 bytes, 586
/// frames) sent at once fits. Further frames are dropped and counted, as a CAN interface's
/// full transmit queue drops them: a flood cannot outlive its client or grow the server.
pub const CLIENT_TO_BUS_FRAMES: usize = 1024;
/// Messages waiting to be written to a client (about 3 s of the car's traffic): a client
/// that reads too slowly, or not at all, loses frames (counted), never the server's memory.
pub const CLIENT_OUTBOX_MESSAGES: usize = 4096;
/// Longest message a client may send, bytes (a `send` of 8 bytes is under 40).
pub const MAX_MESSAGE_BYTES: usize = 4096;
/// How long a client may stay silent before raw mode (a connection that never gets there
/// is not left holding a place).
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_secs(30);

/// The car's side of the server: after each tick of the car, the clients' frames go to its
/// external node (as many as its transmit queue takes, the rest wait in the server's
/// per-client queues, taken in turn) and the frames the bus carried go to the clients. A
/// client's own frame goes to the other clients once it is on the bus, not back to it, as
/// sockets on one SocketCAN interface see it.
#[derive(Debug, Default)]
pub struct CarBridge {
    /// A client frame the external node's queue could not take yet.
    held: Option<ClientFrame>,
    /// Client frames handed to the external node and not yet seen on the bus.
    on_the_way: VecDeque<ClientFrame>,
}

impl CarBridge {
    /// A bridge with nothing on the way.
    pub fn new() -> Self {
        Self::default()
    }

    /// Exchanges frames between `server`'s clients and `car`, whose bus carried `frames`
    /// in the tick just run.
    pub fn exchange(
        &mut self,
        server: &SocketcandServer,
        car: &mut crate::car::VirtualCar,
        frames: &[crate::car::LoggedFrame],
    ) {
        while let Some(sent) = self.held.take().or_else(|| server.try_recv()) {
            if !car.inject(sent.frame) {
                self.held = Some(sent);
                break;
            }
            self.on_the_way.push_back(sent);
        }
        for entry in frames {
            let from_client = if entry.sender.is_none() {
                // The external node sends its queue by priority: find the frame, not just
                // the oldest.
                self.on_the_way
                    .iter()
                    .position(|c| c.frame == entry.frame)
                    .and_then(|i| self.on_the_way.remove(i))
                    .map(|c| c.client)
            } else {
                None
            };
            server.broadcast(entry.t_us, &entry.frame, from_client);
        }
        // A frame the bus never carried (lost in an error) is not waited for forever.
        while self.on_the_way.len() > 64 {
            self.on_the_way.pop_front();
        }
    }
}

/// A frame a client sent, and which client.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ClientFrame {
    /// The client (connection number, from 1; 0 for a client that has gone).
    pub client: u64,
    /// The frame.
    pub frame: Frame,
}

/// What the server dropped because a queue was full.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Drops {
    /// Frames from clients that found their queue toward the bus full.
    pub to_bus: u64,
    /// Bus frames not sent to a client whose queue toward it was full.
    pub to_clients: u64,
}

/// What a client's reader and writer threads and the simulation share.
#[derive(Default)]
struct Shared {
    raw_mode: AtomicBool,
    to_bus: Mutex<VecDeque<Frame>>,
}

struct Client {
    id: u64,
    shared: Arc<Shared>,
    outbox: SyncSender<Outgoing>,
    /// A handle on the socket, to shut it down when the client is removed: the reader and
    /// writer threads then end, and the socket closes.
    stream: TcpStream,
}

impl Drop for Client {
    fn drop(&mut self) {
        let _ = self.stream.shutdown(Shutdown::Both);
    }
}

/// What a client's writer thread is asked to do.
enum Outgoing {
    /// Write this message (one write of its own).
    Message(String),
    /// The rawmode `< ok >` has been written: after [`RAW_MODE_GRACE`], let frames through.
    EnterRawMode,
}

/// What the server's threads share.
#[derive(Default)]
struct State {
    clients: Mutex<Vec<Client>>,
    refused: AtomicU64,
    accepted: AtomicU64,
    dropped_to_bus: AtomicU64,
    dropped_to_clients: AtomicU64,
    /// Where the next [`SocketcandServer::try_recv`] starts looking (round robin).
    next_client: AtomicUsize,
    /// Frames of clients that have gone, not yet on the bus: sent still, as an interface
    /// sends what was handed to it before its socket closed (a `cansend`-like tool connects,
    /// sends and leaves), but never more than one client's queue's worth.
    leftovers: Mutex<VecDeque<Frame>>,
    stop: AtomicBool,
}

impl State {
    fn clients(&self) -> MutexGuard<'_, Vec<Client>> {
        self.clients.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Removes a client: its socket is shut down, the frames it queued for the bus join the
    /// bounded leftovers.
    fn remove(&self, id: u64) {
        let removed: Vec<Client> = {
            let mut clients = self.clients();
            let (gone, kept) = std::mem::take(&mut *clients)
                .into_iter()
                .partition(|c| c.id == id);
            *clients = kept;
            gone
        };
        for client in removed {
            let queued = std::mem::take(
                &mut *client
                    .shared
                    .to_bus
                    .lock()
                    .unwrap_or_else(|e| e.into_inner()),
            );
            let mut leftovers = self.leftovers.lock().unwrap_or_else(|e| e.into_inner());
            for frame in queued {
                if leftovers.len() < CLIENT_TO_BUS_FRAMES {
                    leftovers.push_back(frame);
                } else {
                    self.dropped_to_bus.fetch_add(1, Ordering::Relaxed);
                }
            }
        }
    }
}

/// The running server.
pub struct SocketcandServer {
    address: SocketAddr,
    state: Arc<State>,
}

impl SocketcandServer {
    /// Listens on `address` (port 0 picks a free port; see [`SocketcandServer::address`]).
    pub fn start(address: &str) -> io::Result<Self> {
        let listener = TcpListener::bind(address)?;
        let address = listener.local_addr()?;
        listener.set_nonblocking(true)?;
        let state = Arc::new(State::default());
        {
            let state = Arc::clone(&state);
            thread::spawn(move || accept_loop(listener, state));
        }
        Ok(Self { address, state })
    }

    /// The address the server listens on.
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Waits up to `timeout` for a client in raw mode: whether there is one.
    pub fn wait_for_raw_client(&self, timeout: std::time::Duration) -> bool {
        let give_up = std::time::Instant::now() + timeout;
        while self.raw_clients() == 0 {
            if std::time::Instant::now() >= give_up {
                return false;
            }
            std::thread::sleep(std::time::Duration::from_millis(5));
        }
        true
    }

    /// Clients in raw mode, receiving frames.
    pub fn raw_clients(&self) -> usize {
        self.state
            .clients()
            .iter()
            .filter(|c| c.shared.raw_mode.load(Ordering::Acquire))
            .count()
    }

    /// Clients connected, in any state.
    pub fn clients(&self) -> usize {
        self.state.clients().len()
    }

    /// Sends a bus frame to every client in raw mode except `from_client` (its sender).
    /// Never blocks: a client whose queue is full misses the frame (counted in
    /// [`SocketcandServer::drops`]).
    pub fn broadcast(&self, t_us: u64, frame: &Frame, from_client: Option<u64>) {
        let text = frame_message(t_us, frame);
        let mut gone = Vec::new();
        for c in self.state.clients().iter() {
            if Some(c.id) == from_client || !c.shared.raw_mode.load(Ordering::Acquire) {
                continue;
            }
            match c.outbox.try_send(Outgoing::Message(text.clone())) {
                Ok(()) => {}
                Err(TrySendError::Full(_)) => {
                    self.state
                        .dropped_to_clients
                        .fetch_add(1, Ordering::Relaxed);
                }
                Err(TrySendError::Disconnected(_)) => gone.push(c.id),
            }
        }
        for id in gone {
            self.state.remove(id);
        }
    }

    /// The next frame a client sent, if any (never blocks). Clients take turns, so one that
    /// floods cannot hold back the others' frames.
    pub fn try_recv(&self) -> Option<ClientFrame> {
        let clients = self.state.clients();
        // The clients' queues, and the leftovers of those that have gone as one more.
        let n = clients.len() + 1;
        let start = self.state.next_client.load(Ordering::Relaxed);
        for k in 0..n {
            let i = (start + k) % n;
            let (client, queue) = match clients.get(i) {
                Some(c) => (c.id, &c.shared.to_bus),
                None => (0, &self.state.leftovers),
            };
            let frame = queue.lock().unwrap_or_else(|e| e.into_inner()).pop_front();
            if let Some(frame) = frame {
                self.state.next_client.store(i + 1, Ordering::Relaxed);
                return Some(ClientFrame { client, frame });
            }
        }
        None
    }

    /// Connections accepted so far (the server full or not).
    pub fn accepted(&self) -> u64 {
        self.state.accepted.load(Ordering::Relaxed)
    }

    /// Client commands refused so far (malformed `send`, unknown commands).
    pub fn refused_commands(&self) -> u64 {
        self.state.refused.load(Ordering::Relaxed)
    }

    /// Frames dropped so far because a queue was full.
    pub fn drops(&self) -> Drops {
        Drops {
            to_bus: self.state.dropped_to_bus.load(Ordering::Relaxed),
            to_clients: self.state.dropped_to_clients.load(Ordering::Relaxed),
        }
    }
}

impl Drop for SocketcandServer {
    fn drop(&mut self) {
        self.state.stop.store(true, Ordering::Release);
        // Removing the clients shuts their sockets down: their threads end.
        self.state.clients().clear();
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

fn accept_loop(listener: TcpListener, state: Arc<State>) {
    let mut next_id = 1;
    // Each connection's reader thread, joined once it has ended (it joins its writer):
    // no connection thread is detached. A test of a thousand hostile connections under
    // load once died of SIGSEGV inside glibc's pthread_detach as a dropped handle
    // detached a thread just spawned; joined threads never go through it.
    let mut readers: Vec<thread::JoinHandle<()>> = Vec::new();
    while !state.stop.load(Ordering::Acquire) {
        let mut i = 0;
        while i < readers.len() {
            if readers[i].is_finished() {
                let _ = readers.swap_remove(i).join();
            } else {
                i += 1;
            }
        }
        match listener.accept() {
            Ok((stream, _)) => {
                state.accepted.fetch_add(1, Ordering::Relaxed);
                let id = next_id;
                next_id += 1;
                match serve(stream, id, &state) {
                    Ok(Some(reader)) => readers.push(reader),
                    Ok(None) => {}
                    Err(e) => eprintln!("socketcand: client {id}: {e}"),
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
    // Stopped: the server's drop has removed the clients and shut their sockets down.
    for reader in readers {
        let _ = reader.join();
    }
}

/// Serves one connection: its reader thread (which ends it all), `None` if the server
/// was full and the client was told so.
fn serve(
    mut stream: TcpStream,
    id: u64,
    state: &Arc<State>,
) -> io::Result<Option<thread::JoinHandle<()>>> {
    stream.set_nonblocking(false)?;
    stream.set_nodelay(true)?;
    if state.clients().len() >= MAX_CLIENTS {
        let _ = stream.write_all(
            format!("< error this server takes {MAX_CLIENTS} clients at once >").as_bytes(),
        );
        let _ = stream.shutdown(Shutdown::Both);
        return Ok(None);
    }
    stream.set_read_timeout(Some(HANDSHAKE_TIMEOUT))?;
    let (outbox, outgoing) = mpsc::sync_channel::<Outgoing>(CLIENT_OUTBOX_MESSAGES);
    let shared = Arc::new(Shared::default());
    let writer_stream = stream.try_clone()?;
    let handle = stream.try_clone()?;
    outbox
        .send(Outgoing::Message("< hi >".to_string()))
        .map_err(|_| io::Error::other("writer ended"))?;
    state.clients().push(Client {
        id,
        shared: Arc::clone(&shared),
        outbox: outbox.clone(),
        stream: handle,
    });
    let writer = {
        let shared = Arc::clone(&shared);
        thread::spawn(move || write_loop(writer_stream, outgoing, &shared))
    };
    let state = Arc::clone(state);
    Ok(Some(thread::spawn(move || {
        read_loop(&stream, &outbox, &shared, &state);
        // Whatever ended the connection, everything of it goes: the client entry (and
        // with it the writer's last sender and the frames it had queued for the bus), the
        // socket, then the writer (its queue closed, its socket shut down).
        drop(outbox);
        state.remove(id);
        let _ = stream.shutdown(Shutdown::Both);
        let _ = writer.join();
    })))
}

/// One write per message: python-can compares each handshake reply as a whole `recv()`.
/// Raw mode starts here, [`RAW_MODE_GRACE`] after its `< ok >` went out, so no frame is
/// queued for the client before then. A failed write shuts the socket down, which ends the
/// reader too.
fn write_loop(stream: TcpStream, outgoing: Receiver<Outgoing>, shared: &Shared) {
    let mut out = BufWriter::new(&stream);
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
                shared.raw_mode.store(true, Ordering::Release);
            }
        }
    }
    drop(out);
    let _ = stream.shutdown(Shutdown::Both);
}

fn read_loop(
    mut stream: &TcpStream,
    outbox: &SyncSender<Outgoing>,
    shared: &Shared,
    state: &State,
) {
    let mut buffer = Vec::with_capacity(1024);
    let mut chunk = [0u8; 1024];
    let mut opened = false;
    // Raw mode as far as the client's commands go: sending is allowed from the `< ok >` on
    // (frames to the client start a grace later, see `write_loop`).
    let mut raw = false;
    loop {
        let n = match stream.read(&mut chunk) {
            Ok(0) | Err(_) => return,
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
                    state.refused.fetch_add(1, Ordering::Relaxed);
                    Some(format!(
                        "< error could not open bus '{}': this server has {BUS_NAME} >",
                        bus.chars().take(32).collect::<String>()
                    ))
                }
                Ok(Command::RawMode) if opened => {
                    entering_raw = !raw;
                    raw = true;
                    // A client in raw mode may listen without a word for as long as it likes.
                    if stream.set_read_timeout(None).is_err() {
                        return;
                    }
                    Some("< ok >".to_string())
                }
                Ok(Command::RawMode) => {
                    state.refused.fetch_add(1, Ordering::Relaxed);
                    Some("< error open a bus before rawmode >".to_string())
                }
                Ok(Command::Echo) => Some("< echo >".to_string()),
                Ok(Command::Send(frame)) if raw => {
                    let mut queue = shared.to_bus.lock().unwrap_or_else(|e| e.into_inner());
                    if queue.len() < CLIENT_TO_BUS_FRAMES {
                        queue.push_back(frame);
                    } else {
                        state.dropped_to_bus.fetch_add(1, Ordering::Relaxed);
                    }
                    None
                }
                Ok(Command::Send(_)) => {
                    state.refused.fetch_add(1, Ordering::Relaxed);
                    Some("< error send needs rawmode >".to_string())
                }
                Err(_) => {
                    // Counted, not logged: a flood of bad commands must not flood the log.
                    state.refused.fetch_add(1, Ordering::Relaxed);
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
        if buffer.len() > MAX_MESSAGE_BYTES {
            // No complete message in that much: not socketcand. Disconnect.
            let _ = outbox.try_send(Outgoing::Message(format!(
                "< error no complete message in {MAX_MESSAGE_BYTES} bytes >"
            )));
            return;
        }
    }
}

/// Removes and returns the first complete `< ... >` message, without the brackets (and
/// whatever came before its `<`).
pub fn take_message(buffer: &mut Vec<u8>) -> Option<String> {
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
