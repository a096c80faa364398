//! The MCU's debug port as a GDB server (the GDB remote serial protocol, through the
//! `gdbstub` crate): what a debug probe and probe-rs's or OpenOCD's GDB server give on a
//! board, for the emulated STM32F446.
//!
//! The server listens on loopback (the protocol has no authentication: a remote debugger
//! comes through an SSH tunnel) and takes one client at a time; a second is told who has
//! the port and turned away. While the client holds the core halted, the MCU's caller
//! waits in [`Mcu::run_until`]: whatever runs the MCU in simulated time (the virtual car)
//! stands still with it, and resumes exactly where it stopped.
//!
//! Packets are checked before they reach `gdbstub` (framing, size, checksum), and a
//! command it cannot parse ends in an error reply, not the session: a hostile client gets
//! errors, and a client that goes away mid-packet leaves the MCU running on.

pub mod arch;
mod framer;
mod target;

pub use target::SW_BREAKPOINTS;

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{sync_channel, Receiver, TryRecvError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use gdbstub::common::Signal;
use gdbstub::stub::state_machine::GdbStubStateMachine;
use gdbstub::stub::{GdbStub, SingleThreadStopReason};
use gdbstub::target::ext::breakpoints::WatchKind as GdbWatchKind;

use crate::cpu::DebugStop;
use crate::debug::{Debugger, Halted, Resume, WatchKind};
use crate::mcu::Mcu;
use framer::{Framed, Framer};
use gdbstub::target::ext::base::reverse_exec::ReplayLogPosition;

/// The packet buffer: GDB is told this size (`PacketSize`), and a longer packet is
/// answered with an error.
pub const PACKET_SIZE: usize = 4096;

/// A client that stops reading its replies for this long is disconnected.
const WRITE_TIMEOUT: Duration = Duration::from_secs(10);

/// At most this many clients are being turned away with a reason at once.
const MAX_REFUSING: usize = 8;

/// Counts a refusing thread out however it ends.
struct Refusing(Arc<Shared>);

impl Drop for Refusing {
    fn drop(&mut self) {
        self.0.refusing.fetch_sub(1, Ordering::AcqRel);
    }
}

/// How long a client that comes while another is attached waits for it to detach before
/// it is turned away.
const HANDOVER_WAIT: Duration = Duration::from_secs(1);

/// Received chunks queued between the client's reader thread and the MCU (a client that
/// sends faster than the MCU serves waits in TCP's flow control).
const QUEUED_CHUNKS: usize = 16;

/// What the GDB server tells the rest of the program (the dashboard, a pacer).
#[derive(Debug)]
pub struct GdbStatus {
    /// Where the server listens.
    address: SocketAddr,
    attached: AtomicBool,
    halted: AtomicBool,
    halted_ns: AtomicU64,
    halted_since: Mutex<Option<Instant>>,
    peer: Mutex<Option<SocketAddr>>,
}

impl GdbStatus {
    fn new(address: SocketAddr) -> Self {
        Self {
            address,
            attached: AtomicBool::new(false),
            halted: AtomicBool::new(false),
            halted_ns: AtomicU64::new(0),
            halted_since: Mutex::new(None),
            peer: Mutex::new(None),
        }
    }

    /// Where the server listens (what a client connects to).
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Whether a client is attached.
    pub fn attached(&self) -> bool {
        self.attached.load(Ordering::Relaxed)
    }

    /// Whether the debugger holds the core halted now.
    pub fn halted(&self) -> bool {
        self.halted.load(Ordering::Relaxed)
    }

    /// The wall-clock time the core has spent halted by the debugger, all halts together
    /// (the one going on included): what a real-time pacer leaves out.
    pub fn halted_for(&self) -> Duration {
        let past = Duration::from_nanos(self.halted_ns.load(Ordering::Relaxed));
        let now = self
            .halted_since
            .lock()
            .map(|s| s.map_or(Duration::ZERO, |t| t.elapsed()))
            .unwrap_or_default();
        past + now
    }

    /// The attached client's address.
    pub fn peer(&self) -> Option<SocketAddr> {
        self.peer.lock().ok().and_then(|p| *p)
    }

    fn set_halted(&self, halted: bool) {
        let Ok(mut since) = self.halted_since.lock() else {
            return;
        };
        match (halted, since.take()) {
            (true, None) => *since = Some(Instant::now()),
            (true, Some(t)) => *since = Some(t),
            (false, Some(t)) => {
                self.halted_ns
                    .fetch_add(t.elapsed().as_nanos() as u64, Ordering::Relaxed);
            }
            (false, None) => {}
        }
        self.halted.store(halted, Ordering::Relaxed);
    }
}

struct Shared {
    /// The MCU's name in messages ("cruise").
    name: String,
    /// A client waiting to be attached.
    pending: Mutex<Option<(TcpStream, SocketAddr)>>,
    /// A client waits, or the attached client sent something: the MCU should look.
    attention: AtomicBool,
    /// A client is attached.
    busy: AtomicBool,
    /// The server is going away.
    closing: AtomicBool,
    /// Clients being turned away (each on a short-lived thread of its own).
    refusing: std::sync::atomic::AtomicUsize,
    status: Arc<GdbStatus>,
}

/// Parses a `--gdb` address: `PORT`, `:PORT` or `HOST:PORT`, on loopback only.
pub fn parse_address(text: &str) -> Result<SocketAddr, String> {
    let text = text.trim();
    let candidate = if let Ok(port) = text.trim_start_matches(':').parse::<u16>() {
        SocketAddr::from(([127, 0, 0, 1], port))
    } else if let Some(port) = text.strip_prefix("localhost:") {
        let port: u16 = port
            .parse()
            .map_err(|_| format!("--gdb {text}: '{port}' is not a port number"))?;
        SocketAddr::from(([127, 0, 0, 1], port))
    } else {
        text.parse::<SocketAddr>()
            .map_err(|_| format!("--gdb {text}: not an address (PORT, :PORT or 127.0.0.1:PORT)"))?
    };
    if !candidate.ip().is_loopback() {
        return Err(format!(
            "--gdb {text}: the GDB protocol has no authentication, so the server listens on loopback only (127.0.0.1 or [::1]); reach it from another machine through an SSH tunnel"
        ));
    }
    Ok(candidate)
}

/// The default debug port address, as OpenOCD's and probe-rs's GDB servers use.
pub const DEFAULT_ADDRESS: &str = "127.0.0.1:3333";

/// A GDB server for one MCU: put it in [`Mcu::debugger`].
pub struct GdbServer {
    shared: Arc<Shared>,
    local: SocketAddr,
    session: Option<Session<TcpStream>>,
}

impl GdbServer {
    /// Listens at `address` for the MCU called `name`.
    pub fn bind(name: &str, address: SocketAddr) -> Result<Self, String> {
        if !address.ip().is_loopback() {
            return Err(format!(
                "{name}: GDB server at {address}: loopback addresses only (the protocol has no authentication)"
            ));
        }
        let listener = TcpListener::bind(address)
            .map_err(|e| format!("{name}: cannot listen for GDB at {address}: {e}"))?;
        let local = listener
            .local_addr()
            .map_err(|e| format!("{name}: GDB server: {e}"))?;
        let shared = Arc::new(Shared {
            name: name.to_string(),
            pending: Mutex::new(None),
            attention: AtomicBool::new(false),
            busy: AtomicBool::new(false),
            closing: AtomicBool::new(false),
            refusing: std::sync::atomic::AtomicUsize::new(0),
            status: Arc::new(GdbStatus::new(local)),
        });
        let listening = Arc::clone(&shared);
        std::thread::Builder::new()
            .name(format!("gdb-{name}"))
            .spawn(move || listen(listener, &listening))
            .map_err(|e| format!("{name}: GDB server thread: {e}"))?;
        Ok(Self {
            shared,
            local,
            session: None,
        })
    }

    /// The address it listens at.
    pub fn local_addr(&self) -> SocketAddr {
        self.local
    }

    /// What the rest of the program may watch.
    pub fn status(&self) -> Arc<GdbStatus> {
        Arc::clone(&self.shared.status)
    }

    /// Waits until a client connects (the MCU's run starts under the debugger, as QEMU's
    /// `-S`), or `timeout` passes; whether one did.
    pub fn wait_for_client(&self, timeout: Option<Duration>) -> bool {
        let start = Instant::now();
        while !self.shared.attention.load(Ordering::Acquire) {
            if timeout.is_some_and(|t| start.elapsed() >= t) {
                return false;
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        true
    }

    fn attach(&mut self, mcu: &mut Mcu) -> bool {
        let Some((stream, peer)) = self.shared.pending.lock().ok().and_then(|mut p| p.take())
        else {
            return false;
        };
        // A client gone before its turn is not worth halting the MCU for.
        if hung_up(&stream) {
            return false;
        }
        match Session::start(stream, peer, mcu, &self.shared) {
            Ok(session) => {
                self.shared.busy.store(true, Ordering::Release);
                self.shared.status.attached.store(true, Ordering::Relaxed);
                if let Ok(mut p) = self.shared.status.peer.lock() {
                    *p = Some(peer);
                }
                eprintln!(
                    "{}: GDB attached from {peer}; the MCU (and whatever runs with it) is halted",
                    self.shared.name
                );
                self.session = Some(session);
                true
            }
            Err(e) => {
                eprintln!("{}: GDB client {peer}: {e}", self.shared.name);
                false
            }
        }
    }

    fn detach(&mut self, mcu: &mut Mcu, why: &str) {
        if let Some(session) = self.session.take() {
            session.end(mcu);
            eprintln!(
                "{}: GDB detached ({why}); the MCU runs on",
                self.shared.name
            );
        }
        self.shared.status.attached.store(false, Ordering::Relaxed);
        if let Ok(mut p) = self.shared.status.peer.lock() {
            *p = None;
        }
        self.shared.busy.store(false, Ordering::Release);
        // A client that came while this one was attached was turned away; one that came
        // since is served at the next look.
        if self.shared.pending.lock().is_ok_and(|p| p.is_some()) {
            self.shared.attention.store(true, Ordering::Release);
        }
    }

    /// Serves the client while the core is halted, until it resumes the core or goes.
    fn serve(&mut self, mcu: &mut Mcu) {
        while let Some(session) = self.session.as_mut() {
            match session.step(mcu, true) {
                Served::Halted => {}
                Served::Running => break,
                Served::Gone(why) => {
                    self.detach(mcu, &why);
                    break;
                }
            }
        }
    }
}

impl Drop for GdbServer {
    fn drop(&mut self) {
        self.shared.closing.store(true, Ordering::Release);
        // Wake the listener from its accept.
        let _ = TcpStream::connect_timeout(&self.local, Duration::from_millis(200));
    }
}

impl Debugger for GdbServer {
    fn wants_halt(&self) -> bool {
        self.shared.attention.load(Ordering::Relaxed)
    }

    fn halted(&mut self, mcu: &mut Mcu, why: Halted) {
        // Halted from here until the core resumes: said before any stop reply goes out.
        self.shared.status.set_halted(true);
        self.take_halt(mcu, why);
        self.shared.status.set_halted(false);
    }
}

impl GdbServer {
    fn take_halt(&mut self, mcu: &mut Mcu, why: Halted) {
        self.shared.attention.store(false, Ordering::Release);
        if self.session.is_none() {
            if matches!(why, Halted::Request) && self.attach(mcu) {
                self.serve(mcu);
            }
            return;
        }
        let reason = match why {
            Halted::Request => None,
            Halted::Core(DebugStop::Breakpoint(pc)) => {
                Some(if mcu.debug.hw_breakpoints.contains(&pc) {
                    SingleThreadStopReason::HwBreak(())
                } else {
                    SingleThreadStopReason::SwBreak(())
                })
            }
            Halted::Core(DebugStop::Step | DebugStop::Position) => {
                Some(SingleThreadStopReason::DoneStep)
            }
            Halted::Core(DebugStop::HardFault) => {
                if let Some(session) = self.session.as_mut() {
                    session.console(&hard_fault_text(mcu));
                }
                Some(SingleThreadStopReason::Signal(Signal::SIGSEGV))
            }
            Halted::Watch(hit) => Some(SingleThreadStopReason::Watch {
                tid: (),
                kind: gdb_watch_kind(hit.kind),
                addr: hit.watched,
            }),
            Halted::Lockup(halt) => {
                if let Some(session) = self.session.as_mut() {
                    session.console(&format!(
                        "{}; the core stays locked until a reset (monitor reset, or a running watchdog's); {}\n",
                        crate::mcu::Stop::Halted(halt),
                        fault_registers(mcu)
                    ));
                }
                Some(SingleThreadStopReason::Signal(Signal::SIGSEGV))
            }
            Halted::Bkpt { .. } => Some(SingleThreadStopReason::Signal(Signal::SIGTRAP)),
        };
        let Some(session) = self.session.as_mut() else {
            return;
        };
        let outcome = match reason {
            Some(reason) => session.report(mcu, reason),
            // Something arrived while the core ran: a Ctrl-C halts it.
            None => session.step(mcu, false),
        };
        match outcome {
            Served::Halted => self.serve(mcu),
            Served::Running => {}
            Served::Gone(why) => self.detach(mcu, &why),
        }
    }
}

fn gdb_watch_kind(kind: WatchKind) -> GdbWatchKind {
    match kind {
        WatchKind::Write => GdbWatchKind::Write,
        WatchKind::Read => GdbWatchKind::Read,
        WatchKind::Access => GdbWatchKind::ReadWrite,
    }
}

/// The HardFault the vector catch stopped at, as GDB's console shows it.
fn hard_fault_text(mcu: &mut Mcu) -> String {
    let at = mcu
        .faults
        .last()
        .map(|f| format!(" ({:?} at pc {:#010x}, lr {:#010x})", f.fault, f.pc, f.lr))
        .unwrap_or_default();
    format!(
        "HardFault{at}: {}; the core is halted at the handler (monitor fault repeats this)\n",
        fault_registers(mcu)
    )
}

/// The fault status and address registers, as GDB's console shows them.
fn fault_registers(mcu: &mut Mcu) -> String {
    let mut word = |a: u32| {
        mcu.cpu
            .debug_read_private(a, crate::cpu::Size::Word)
            .unwrap_or(0)
    };
    let (cfsr, hfsr, bfar, mmfar) = (
        word(0xE000_ED28),
        word(0xE000_ED2C),
        word(0xE000_ED38),
        word(0xE000_ED34),
    );
    format!("CFSR {cfsr:#010x}, HFSR {hfsr:#010x}, BFAR {bfar:#010x}, MMFAR {mmfar:#010x}")
}

/// Accepts clients: the first is handed to the MCU, a second is turned away.
fn listen(listener: TcpListener, shared: &Arc<Shared>) {
    for stream in listener.incoming() {
        if shared.closing.load(Ordering::Acquire) {
            return;
        }
        let Ok(stream) = stream else {
            continue;
        };
        let Ok(peer) = stream.peer_addr() else {
            continue;
        };
        let mut pending = match shared.pending.lock() {
            Ok(p) => p,
            Err(_) => return,
        };
        if shared.busy.load(Ordering::Acquire) || pending.is_some() {
            drop(pending);
            // A flood of connections is closed at once beyond a few being answered: the
            // threads that answer them are bounded.
            if shared.refusing.fetch_add(1, Ordering::AcqRel) >= MAX_REFUSING {
                shared.refusing.fetch_sub(1, Ordering::AcqRel);
                continue;
            }
            // Off this thread: a silent client must not hold up the next one. A client
            // that comes just as the last one detaches (GDB reconnecting) gets the port.
            let counter = Arc::clone(shared);
            let shared = Arc::clone(shared);
            let spawned = std::thread::Builder::new()
                .name("gdb-refuse".into())
                .spawn(move || {
                    let shared = Refusing(shared);
                    let shared = &shared.0;
                    let start = Instant::now();
                    while start.elapsed() < HANDOVER_WAIT {
                        // One that hung up while waiting gives its place back at once and
                        // never takes the port: a flood of dead connections must not
                        // halt the MCU one by one, nor crowd out the next real client.
                        if hung_up(&stream) {
                            return;
                        }
                        if !shared.busy.load(Ordering::Acquire) {
                            if let Ok(mut pending) = shared.pending.lock() {
                                if pending.is_none() {
                                    *pending = Some((stream, peer));
                                    shared.attention.store(true, Ordering::Release);
                                    return;
                                }
                            }
                        }
                        std::thread::sleep(Duration::from_millis(10));
                    }
                    let holder = shared
                        .status
                        .peer()
                        .map_or_else(|| "another client".to_string(), |p| p.to_string());
                    refuse(stream, &shared.name, &holder);
                });
            if spawned.is_err() {
                counter.refusing.fetch_sub(1, Ordering::AcqRel);
            }
            continue;
        }
        *pending = Some((stream, peer));
        shared.attention.store(true, Ordering::Release);
    }
}

/// Whether the client has closed its side (end of stream waiting to be read); its
/// packets, if any, stay unread.
fn hung_up(stream: &TcpStream) -> bool {
    if stream.set_nonblocking(true).is_err() {
        return true;
    }
    let mut probe = [0u8; 1];
    let gone = match stream.peek(&mut probe) {
        Ok(0) => true,
        Ok(_) => false,
        Err(e) => e.kind() != std::io::ErrorKind::WouldBlock,
    };
    gone || stream.set_nonblocking(false).is_err()
}

/// Tells a second client why it cannot have the port: an error reply to its first
/// packet, which GDB prints, and the connection closed.
fn refuse(mut stream: TcpStream, name: &str, holder: &str) {
    let _ = stream.set_read_timeout(Some(Duration::from_secs(2)));
    let _ = stream.set_write_timeout(Some(Duration::from_secs(2)));
    let mut framer = Framer::default();
    let mut buf = [0u8; 512];
    let started = Instant::now();
    'wait: while started.elapsed() < Duration::from_secs(2) {
        let Ok(n) = stream.read(&mut buf) else {
            break;
        };
        if n == 0 {
            return;
        }
        for &b in &buf[..n] {
            if matches!(framer.push(b), Some(Framed::Packet(_))) {
                break 'wait;
            }
        }
    }
    let text = format!("the debug port of {name} is in use by {holder}: one debugger at a time");
    let mut reply = b"+".to_vec();
    reply.extend(framer::packet(format!("E.{text}").as_bytes()));
    let _ = stream.write_all(&reply);
    let _ = stream.flush();
}

/// The fuzz target's entry: `bytes`, as a client sends them, through the whole packet
/// path (framing, gdbstub, the target's handlers, reverse execution) of a session with
/// `mcu`. A resume is answered at once with a step's stop, as if the core had run.
/// Whatever comes, nothing panics and the MCU is left as a detach leaves it.
pub fn fuzz_session(mcu: &mut Mcu, bytes: &[u8]) {
    let (tx, rx) = sync_channel(bytes.len() / 64 + 2);
    for chunk in bytes.chunks(64) {
        let _ = tx.send(chunk.to_vec());
    }
    drop(tx);
    let Ok(mut session) = Session::new(MemoryWire::default(), rx, mcu) else {
        return;
    };
    // Each chunk is served once; a resume's stop counts as one too.
    for _ in 0..bytes.len() + 2 {
        match session.step(mcu, true) {
            Served::Halted => {}
            Served::Running => {
                if !matches!(
                    session.report(mcu, SingleThreadStopReason::DoneStep),
                    Served::Halted
                ) {
                    break;
                }
            }
            Served::Gone(_) => break,
        }
    }
    session.end(mcu);
}

/// How serving the client ended.
enum Served {
    /// The core stays halted: serve on.
    Halted,
    /// The client resumed the core.
    Running,
    /// The client went, or the session failed.
    Gone(String),
}

/// The client's end of a session, as the server writes to it: its socket, or memory (the
/// fuzz target's session).
pub(crate) trait Wire: Write + Send + Sized + 'static {
    /// Another handle on the same end.
    fn duplicate(&self) -> std::io::Result<Self>;
    /// Closes it.
    fn close(&self);
}

impl Wire for TcpStream {
    fn duplicate(&self) -> std::io::Result<Self> {
        self.try_clone()
    }

    fn close(&self) {
        let _ = self.shutdown(std::net::Shutdown::Both);
    }
}

/// Replies kept in memory (the last [`PACKET_SIZE`] × 4 bytes of them).
#[derive(Clone, Default)]
pub(crate) struct MemoryWire(Arc<Mutex<Vec<u8>>>);

impl Write for MemoryWire {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if let Ok(mut out) = self.0.lock() {
            out.extend_from_slice(buf);
            let excess = out.len().saturating_sub(4 * PACKET_SIZE);
            out.drain(..excess);
        }
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Wire for MemoryWire {
    fn duplicate(&self) -> std::io::Result<Self> {
        Ok(self.clone())
    }

    fn close(&self) {}
}

/// Bytes to the client. Replies are collected and sent at each flush; muted, they are
/// dropped (a restarted session replaying the client's negotiation).
struct Link<W: Wire> {
    stream: W,
    out: Vec<u8>,
    mute: bool,
}

impl<W: Wire> gdbstub::conn::Connection for Link<W> {
    type Error = std::io::Error;

    fn write(&mut self, byte: u8) -> Result<(), Self::Error> {
        self.out.push(byte);
        Ok(())
    }

    fn write_all(&mut self, buf: &[u8]) -> Result<(), Self::Error> {
        self.out.extend_from_slice(buf);
        Ok(())
    }

    fn flush(&mut self) -> Result<(), Self::Error> {
        let out = std::mem::take(&mut self.out);
        if self.mute {
            return Ok(());
        }
        Write::write_all(&mut self.stream, &out)?;
        Write::flush(&mut self.stream)
    }
}

type Machine<W> = GdbStubStateMachine<'static, Mcu, Link<W>>;

/// One client's session.
struct Session<W: Wire> {
    machine: Option<Machine<W>>,
    /// Another handle on the client's socket: a restarted session's, and the console's.
    stream: W,
    input: Receiver<Vec<u8>>,
    framer: Framer,
    /// What the client negotiated (its qSupported and QStartNoAckMode packets), replayed
    /// into a restarted session.
    negotiation: Vec<Vec<u8>>,
    /// Whether the core was a debugger's before (semihosting's BKPTs halt, not fault).
    debugger_attached_before: bool,
    /// Sessions restarted after a packet gdbstub could not parse.
    restarts: u32,
}

impl Session<TcpStream> {
    /// A session with the client on `stream`, its bytes read on a thread of their own.
    fn start(
        stream: TcpStream,
        peer: SocketAddr,
        mcu: &mut Mcu,
        shared: &Arc<Shared>,
    ) -> Result<Self, String> {
        stream
            .set_write_timeout(Some(WRITE_TIMEOUT))
            .map_err(|e| e.to_string())?;
        stream.set_nodelay(true).map_err(|e| e.to_string())?;
        let reader = stream.try_clone().map_err(|e| e.to_string())?;
        let (tx, rx) = sync_channel::<Vec<u8>>(QUEUED_CHUNKS);
        let flag = Arc::clone(shared);
        std::thread::Builder::new()
            .name(format!("gdb-{peer}"))
            .spawn(move || {
                let mut reader = reader;
                let mut buf = vec![0u8; PACKET_SIZE];
                loop {
                    let n = reader.read(&mut buf).unwrap_or(0);
                    let chunk = buf[..n].to_vec();
                    let sent = tx.send(chunk).is_ok();
                    flag.attention.store(true, Ordering::Release);
                    if n == 0 || !sent {
                        return;
                    }
                }
            })
            .map_err(|e| e.to_string())?;
        Session::new(stream, rx, mcu)
    }
}

impl<W: Wire> Session<W> {
    /// A session writing to `stream`, reading what `input` brings.
    fn new(stream: W, input: Receiver<Vec<u8>>, mcu: &mut Mcu) -> Result<Self, String> {
        let spare = stream.duplicate().map_err(|e| e.to_string())?;
        let machine = Self::new_machine(stream, mcu)?;
        let debugger_attached_before = mcu.cpu.debugger_attached;
        mcu.cpu.debugger_attached = true;
        mcu.debug = Default::default();
        mcu.cpu.debug = Some(Box::new(mcu.debug.control()));
        mcu.start_history();
        Ok(Self {
            machine: Some(machine),
            stream: spare,
            input,
            framer: Framer::default(),
            negotiation: Vec::new(),
            debugger_attached_before,
            restarts: 0,
        })
    }

    fn new_machine(stream: W, mcu: &mut Mcu) -> Result<Machine<W>, String> {
        let link = Link {
            stream,
            out: Vec::new(),
            mute: false,
        };
        GdbStub::builder(link)
            .packet_buffer_size(PACKET_SIZE)
            .build()
            .map_err(|e| format!("{e:?}"))?
            .run_state_machine(mcu)
            .map_err(|e| e.to_string())
    }

    /// The session over: the breakpoints and watchpoints go, the core runs on.
    fn end(self, mcu: &mut Mcu) {
        // The car goes on from the present, whatever the debugger last looked at.
        mcu.return_to_present();
        mcu.history = None;
        mcu.debug = Default::default();
        mcu.cpu.debug = None;
        mcu.cpu.debugger_attached = self.debugger_attached_before;
        self.stream.close();
    }

    /// Text on GDB's console (an `O` packet, which GDB takes while the target runs).
    fn console(&mut self, text: &str) {
        let hex: String = text.bytes().map(|b| format!("{b:02x}")).collect();
        let _ = Write::write_all(
            &mut self.stream,
            &framer::packet(format!("O{hex}").as_bytes()),
        );
    }

    /// Reports why the running core stopped.
    fn report(&mut self, mcu: &mut Mcu, reason: SingleThreadStopReason<u32>) -> Served {
        match self.machine.take() {
            Some(GdbStubStateMachine::Running(running)) => match running.report_stop(mcu, reason) {
                Ok(machine) => {
                    self.machine = Some(machine);
                    Served::Halted
                }
                Err(e) => Served::Gone(format!("the connection failed: {e}")),
            },
            other => {
                self.machine = other;
                Served::Halted
            }
        }
    }

    /// Takes what the client sent (waiting for it when `wait`) and acts on it; then says
    /// whether the core is to stay halted.
    fn step(&mut self, mcu: &mut Mcu, wait: bool) -> Served {
        let chunk = if wait && self.is_idle() {
            match self.input.recv() {
                Ok(chunk) => Some(chunk),
                Err(_) => return Served::Gone("the client's connection closed".into()),
            }
        } else {
            match self.input.try_recv() {
                Ok(chunk) => Some(chunk),
                Err(TryRecvError::Empty) => None,
                Err(TryRecvError::Disconnected) => {
                    return Served::Gone("the client's connection closed".into())
                }
            }
        };
        if let Some(chunk) = chunk {
            if chunk.is_empty() {
                return Served::Gone("the client closed the connection".into());
            }
            for byte in chunk {
                if let Err(why) = self.feed(mcu, byte) {
                    return Served::Gone(why);
                }
            }
        }
        loop {
            match self.machine.take() {
                Some(GdbStubStateMachine::CtrlCInterrupt(interrupted)) => {
                    match interrupted.interrupt_handled(
                        mcu,
                        Some(SingleThreadStopReason::<u32>::Signal(Signal::SIGINT)),
                    ) {
                        Ok(machine) => self.machine = Some(machine),
                        Err(e) => return Served::Gone(format!("the connection failed: {e}")),
                    }
                }
                Some(GdbStubStateMachine::Disconnected(gone)) => {
                    return Served::Gone(format!("{:?}", gone.get_reason()).to_lowercase());
                }
                Some(running @ GdbStubStateMachine::Running(_)) => {
                    self.machine = Some(running);
                    if let Some(reason) = self.replayed(mcu) {
                        match self.report(mcu, reason) {
                            Served::Halted => continue,
                            other => return other,
                        }
                    }
                    if std::mem::take(&mut mcu.debug.changed_by_debugger) {
                        // What came before no longer leads here.
                        mcu.start_history();
                    }
                    // Resuming from a breakpoint executes its instruction (whether or
                    // not the client removed the breakpoint first).
                    let mut control = mcu.debug.control();
                    control.pass_breakpoint_at = Some(mcu.cpu.instructions());
                    mcu.cpu.debug = Some(Box::new(control));
                    return Served::Running;
                }
                Some(idle) => {
                    self.machine = Some(idle);
                    return Served::Halted;
                }
                None => return Served::Gone("the session failed".into()),
            }
        }
    }

    /// A resume served from the history: backwards, or forwards while the debugger looks
    /// at the past. The stop to report; `None` for a live resume.
    fn replayed(&mut self, mcu: &mut Mcu) -> Option<SingleThreadStopReason<u32>> {
        use crate::history::{Arrival, ReplayError};
        let resume = mcu.debug.resume.clone();
        let outcome = match resume {
            Resume::ReverseStep => mcu.reverse_step(),
            Resume::ReverseContinue => mcu.reverse_continue(),
            _ if !mcu.in_past() => return None,
            Resume::Continue => mcu.replay_continue(),
            Resume::Step => mcu.replay_step(),
            Resume::StepRange(range) => loop {
                match mcu.replay_step() {
                    Ok(Arrival::Position) if range.contains(&mcu.cpu.pc()) => continue,
                    other => break other,
                }
            },
        };
        let reason = match outcome {
            Ok(Arrival::Position) => SingleThreadStopReason::DoneStep,
            Ok(Arrival::Breakpoint(pc)) => {
                if mcu.debug.hw_breakpoints.contains(&pc) {
                    SingleThreadStopReason::HwBreak(())
                } else {
                    SingleThreadStopReason::SwBreak(())
                }
            }
            Ok(Arrival::Watch(hit)) => SingleThreadStopReason::Watch {
                tid: (),
                kind: gdb_watch_kind(hit.kind),
                addr: hit.watched,
            },
            Ok(Arrival::Beginning) | Err(ReplayError::Empty) => SingleThreadStopReason::ReplayLog {
                tid: None,
                pos: ReplayLogPosition::Begin,
            },
            Ok(Arrival::Present) => SingleThreadStopReason::ReplayLog {
                tid: None,
                pos: ReplayLogPosition::End,
            },
            Err(ReplayError::Diverged(why)) => {
                // Never expected: said, and the MCU put back at the present.
                self.console(&format!(
                    "reverse execution failed ({why}); back at the present\n"
                ));
                mcu.return_to_present();
                SingleThreadStopReason::Signal(Signal::SIGTRAP)
            }
        };
        mcu.debug.resume = Resume::Continue;
        Some(reason)
    }

    fn is_idle(&self) -> bool {
        matches!(self.machine, Some(GdbStubStateMachine::Idle(_)))
    }

    /// One byte from the client, through the framer to gdbstub.
    fn feed(&mut self, mcu: &mut Mcu, byte: u8) -> Result<(), String> {
        match self.framer.push(byte) {
            None => Ok(()),
            Some(Framed::Reply(reply)) => Write::write_all(&mut self.stream, &reply)
                .map_err(|e| format!("the connection failed: {e}")),
            Some(Framed::Byte(b)) => self.pump(mcu, &[b]),
            Some(Framed::Packet(packet)) => {
                let packet = framer::bound_read(packet);
                let body = framer::body(&packet);
                let negotiates = body.starts_with(b"qSupported") || body == b"QStartNoAckMode";
                let restarts = self.restarts;
                self.pump(mcu, &packet)?;
                // Only what gdbstub took is replayed into a restarted session.
                if negotiates && self.restarts == restarts {
                    self.negotiation.push(packet);
                }
                Ok(())
            }
        }
    }

    fn pump(&mut self, mcu: &mut Mcu, bytes: &[u8]) -> Result<(), String> {
        let was_idle = self.is_idle();
        for &b in bytes {
            let result = match self.machine.take() {
                Some(GdbStubStateMachine::Idle(idle)) => idle.incoming_data(mcu, b),
                Some(GdbStubStateMachine::Running(running)) => running.incoming_data(mcu, b),
                Some(other) => {
                    // A Ctrl-C or a disconnect is handled before more bytes come.
                    self.machine = Some(other);
                    return Ok(());
                }
                None => return Err("the session failed".into()),
            };
            match result {
                Ok(machine) => self.machine = Some(machine),
                Err(e) if e.is_connection_error() => {
                    return Err(format!("the connection failed: {e}"))
                }
                Err(e) if was_idle => return self.restart(mcu, &e.to_string()),
                Err(e) => {
                    return Err(format!(
                        "a packet it could not take while the core ran: {e}"
                    ))
                }
            }
        }
        Ok(())
    }

    /// gdbstub gave up on a packet it could not parse: a new session on the same
    /// connection, told what the client negotiated, answers it with an error.
    fn restart(&mut self, mcu: &mut Mcu, why: &str) -> Result<(), String> {
        let stream = self.stream.duplicate().map_err(|e| e.to_string())?;
        let mut machine = Self::new_machine(stream, mcu)?;
        let negotiation = self.negotiation.clone();
        for packet in &negotiation {
            if let GdbStubStateMachine::Idle(idle) = &mut machine {
                idle.borrow_conn().mute = true;
            }
            for &b in packet {
                machine = match machine {
                    GdbStubStateMachine::Idle(idle) => {
                        idle.incoming_data(mcu, b).map_err(|e| e.to_string())?
                    }
                    other => other,
                };
            }
        }
        if let GdbStubStateMachine::Idle(idle) = &mut machine {
            idle.borrow_conn().mute = false;
        }
        self.machine = Some(machine);
        self.restarts += 1;
        let _ = why;
        let ack = if self.framer.no_ack() { "" } else { "+" };
        let mut reply = ack.as_bytes().to_vec();
        reply.extend(framer::packet(b"E01"));
        Write::write_all(&mut self.stream, &reply)
            .map_err(|e| format!("the connection failed: {e}"))
    }
}
