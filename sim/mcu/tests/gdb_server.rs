//! The MCU's GDB server against a client speaking the remote protocol byte for byte: what
//! GDB sends, and what a broken or hostile client might.

use std::io::{Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use autoplug_flash::sim::SimFlash;
use autoplug_mcu::gdb::{GdbServer, GdbStatus};
use autoplug_mcu::map::FLASH;
use autoplug_mcu::mcu::Mcu;
use autoplug_mcu::programming::bare_program;

const COUNTER: u32 = 0x2000_0000;
/// The loop's store.
const STORE_PC: u32 = FLASH.start + 0x4C;

/// r0 = COUNTER; loop: r1 = [r0] + 1; [r0] = r1; repeat.
fn counting() -> Mcu {
    let code: [u16; 9] = [
        0xF240, 0x0000, // MOVW r0, #0
        0xF2C2, 0x0000, // MOVT r0, #0x2000
        0x6801, // 0x48: LDR r1, [r0]
        0x3101, // ADDS r1, #1
        0x6001, // 0x4C: STR r1, [r0]
        0xE7FB, // B 0x48
        0xBF00,
    ];
    powered(&bare_program(&[0x2002_0000, FLASH.start + 0x41], &code))
}

/// An MCU with `image` at the start of its flash, powered on.
fn powered(image: &[u8]) -> Mcu {
    let mut flash = SimFlash::new(1);
    flash.program(FLASH.start, image).unwrap();
    Mcu::power_on(flash, [1, 2, 3]).unwrap()
}

/// The MCU on a thread of its own, run 1 ms of simulated time at a time until stopped;
/// the server's address and status.
struct Running {
    address: SocketAddr,
    status: Arc<GdbStatus>,
    /// Times the MCU's halt hook ran (what reads RTT at a halt).
    halt_hooks: Arc<std::sync::atomic::AtomicUsize>,
    stop: Arc<AtomicBool>,
    thread: Option<std::thread::JoinHandle<(Mcu, u64)>>,
}

impl Running {
    fn start() -> Self {
        let mut mcu = counting();
        let server = GdbServer::bind("test-ecu", "127.0.0.1:0".parse().unwrap()).unwrap();
        let (address, status) = (server.local_addr(), server.status());
        mcu.debugger = Some(Box::new(server));
        let halt_hooks = Arc::new(std::sync::atomic::AtomicUsize::new(0));
        let counting_hooks = Arc::clone(&halt_hooks);
        mcu.on_debug_halt = Some(Box::new(move |_| {
            counting_hooks.fetch_add(1, Ordering::Relaxed);
        }));
        let stop = Arc::new(AtomicBool::new(false));
        let stopping = Arc::clone(&stop);
        let thread = std::thread::spawn(move || {
            let mut at = 0u64;
            while !stopping.load(Ordering::Relaxed) {
                at += 1_000_000;
                mcu.run_until(at).unwrap();
            }
            (mcu, at)
        });
        Running {
            address,
            status,
            halt_hooks,
            stop,
            thread: Some(thread),
        }
    }

    fn finish(mut self) -> (Mcu, u64) {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.take().unwrap().join().unwrap()
    }
}

/// Whether `condition` holds within 10 s (a loaded machine may take its time).
fn eventually(condition: impl Fn() -> bool) -> bool {
    let start = std::time::Instant::now();
    while start.elapsed() < Duration::from_secs(10) {
        if condition() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    false
}

struct Client {
    stream: TcpStream,
    no_ack: bool,
}

fn checksum(body: &str) -> String {
    format!("{:02x}", body.bytes().fold(0u8, |a, b| a.wrapping_add(b)))
}

impl Client {
    fn connect(address: SocketAddr) -> Self {
        let stream = TcpStream::connect(address).unwrap();
        // As GDB does: a packet goes out at once, not held back for an ack (Nagle).
        stream.set_nodelay(true).unwrap();
        stream
            .set_read_timeout(Some(Duration::from_secs(20)))
            .unwrap();
        Client {
            stream,
            no_ack: false,
        }
    }

    fn send_raw(&mut self, bytes: &[u8]) {
        self.stream.write_all(bytes).unwrap();
    }

    fn byte(&mut self) -> u8 {
        let mut b = [0u8];
        self.stream.read_exact(&mut b).unwrap();
        b[0]
    }

    /// The next packet's body (acks and noise skipped), acknowledged.
    fn reply(&mut self) -> String {
        while self.byte() != b'$' {}
        let mut body = Vec::new();
        loop {
            match self.byte() {
                b'#' => break,
                b => body.push(b),
            }
        }
        let (c1, c2) = (self.byte(), self.byte());
        let raw = String::from_utf8(body).unwrap();
        assert_eq!(format!("{}{}", c1 as char, c2 as char), checksum(&raw));
        // Run-length encoding: "X*n" is X and n - 29 more of it.
        let mut text = String::new();
        let mut chars = raw.chars();
        while let Some(c) = chars.next() {
            if c == '*' {
                let n = chars.next().unwrap() as usize - 29;
                let last = text.chars().last().unwrap();
                text.extend(std::iter::repeat_n(last, n));
            } else {
                text.push(c);
            }
        }
        if !self.no_ack {
            self.send_raw(b"+");
        }
        text
    }

    fn ask(&mut self, body: &str) -> String {
        self.send_raw(format!("${body}#{}", checksum(body)).as_bytes());
        self.reply()
    }

    /// The reply to a command that resumes: console output (`O` packets) skipped.
    fn stop_reply(&mut self) -> String {
        loop {
            let reply = self.reply();
            if !reply.starts_with('O') || reply == "OK" {
                return reply;
            }
        }
    }

    /// The reply to a command that resumes, and the console output before it.
    fn stop_reply_and_console(&mut self) -> (String, String) {
        let mut console = String::new();
        loop {
            let reply = self.reply();
            match reply.strip_prefix('O') {
                Some(hex) if reply != "OK" => console.extend(
                    (0..hex.len() / 2)
                        .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap() as char),
                ),
                _ => return (reply, console),
            }
        }
    }

    fn register(&mut self, n: usize) -> u32 {
        let regs = self.ask("g");
        let hex = &regs[8 * n..8 * n + 8];
        u32::from_le_bytes(
            (0..4)
                .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap())
                .collect::<Vec<_>>()
                .try_into()
                .unwrap(),
        )
    }

    fn counter(&mut self) -> u32 {
        let hex = self.ask(&format!("m{COUNTER:x},4"));
        u32::from_str_radix(&hex, 16).unwrap().swap_bytes()
    }
}

#[test]
fn a_client_halts_the_mcu_reads_it_steps_it_and_watches_a_write() {
    let running = Running::start();
    let mut gdb = Client::connect(running.address);
    let supported = gdb.ask("qSupported:multiprocess+;swbreak+;hwbreak+;xmlRegisters=arm");
    assert!(supported.contains("PacketSize=1000"), "{supported}");
    assert!(supported.contains("qXfer:features:read+"), "{supported}");
    assert!(supported.contains("qXfer:memory-map:read+"), "{supported}");
    assert!(supported.contains("ReverseStep") || !supported.is_empty());
    assert_eq!(gdb.ask("QStartNoAckMode"), "OK");
    gdb.no_ack = true;
    assert!(gdb.ask("?").starts_with('S') || gdb.ask("?").starts_with('T'));
    assert!(running.status.attached() && running.status.halted());

    // Halted: the firmware's counter does not move while the client waits.
    let before = gdb.counter();
    std::thread::sleep(Duration::from_millis(50));
    assert_eq!(gdb.counter(), before, "simulated time stands still");

    // The target description names the Cortex-M4F's features.
    let xml = gdb.ask("qXfer:features:read:target.xml:0,fff");
    assert!(
        xml.contains("org.gnu.gdb.arm.m-profile") && xml.contains("org.gnu.gdb.arm.vfp"),
        "{xml}"
    );
    let map = gdb.ask("qXfer:memory-map:read::0,fff");
    assert!(map.contains(r#"type="flash" start="0x08000000""#), "{map}");

    // Memory outside the map: an error, not a panic; a request longer than a packet is
    // answered with what fits.
    assert!(gdb.ask("m30000000,4").starts_with('E'));
    let big = gdb.ask("m20000000,100000");
    assert!(
        !big.is_empty() && big.len() <= autoplug_mcu::gdb::PACKET_SIZE,
        "{}",
        big.len()
    );
    let big = gdb.ask("mffff0000,ffffffff");
    assert!(big.starts_with('E'), "{big}");
    // Writes reach SRAM; the flash is written only by `load` (vFlashWrite).
    assert_eq!(gdb.ask("M20000100,4:01020304"), "OK");
    assert_eq!(gdb.ask("m20000100,4"), "01020304");
    assert!(gdb.ask("M8000040,2:0000").starts_with('E'));

    // The FPB has six comparators, the DWT four.
    for i in 0..6 {
        assert_eq!(
            gdb.ask(&format!("Z1,{:x},2", FLASH.start + 0x100 + 2 * i)),
            "OK"
        );
    }
    assert_ne!(gdb.ask(&format!("Z1,{:x},2", FLASH.start + 0x200)), "OK");
    for i in 0..6 {
        assert_eq!(
            gdb.ask(&format!("z1,{:x},2", FLASH.start + 0x100 + 2 * i)),
            "OK"
        );
    }
    for i in 0..4 {
        assert_eq!(gdb.ask(&format!("Z2,{:x},4", 0x2000_1000 + 4 * i)), "OK");
    }
    assert_ne!(gdb.ask("Z2,20002000,4"), "OK");
    for i in 0..4 {
        assert_eq!(gdb.ask(&format!("z2,{:x},4", 0x2000_1000 + 4 * i)), "OK");
    }
    // A range one comparator cannot cover is refused (GDB then says so).
    assert_ne!(gdb.ask("Z2,20000002,4"), "OK");

    // A breakpoint at the loop's store halts before it executes.
    assert_eq!(gdb.ask(&format!("Z1,{STORE_PC:x},2")), "OK");
    gdb.send_raw(format!("$c#{}", checksum("c")).as_bytes());
    let stop = gdb.stop_reply();
    assert!(
        stop.starts_with("T05") && stop.contains("hwbreak"),
        "{stop}"
    );
    assert_eq!(gdb.register(15), STORE_PC);
    let counter = gdb.counter();
    // A step executes the store: the counter moves by one.
    gdb.send_raw(format!("$s#{}", checksum("s")).as_bytes());
    let stop = gdb.stop_reply();
    assert!(stop.starts_with("S05") || stop.starts_with("T05"), "{stop}");
    assert_eq!(gdb.register(15), STORE_PC + 2);
    assert_eq!(gdb.counter(), counter.wrapping_add(1));
    assert_eq!(gdb.ask(&format!("z1,{STORE_PC:x},2")), "OK");

    // A write watchpoint on the counter halts after the store.
    assert_eq!(gdb.ask(&format!("Z2,{COUNTER:x},4")), "OK");
    let counter = gdb.counter();
    gdb.send_raw(format!("$c#{}", checksum("c")).as_bytes());
    let stop = gdb.stop_reply();
    assert!(stop.contains(&format!("watch:{COUNTER:x}")), "{stop}");
    assert_eq!(gdb.register(15), STORE_PC + 2);
    assert_eq!(gdb.counter(), counter.wrapping_add(1));
    assert_eq!(gdb.ask(&format!("z2,{COUNTER:x},4")), "OK");

    // Ctrl-C halts a running core.
    gdb.send_raw(format!("$c#{}", checksum("c")).as_bytes());
    assert!(eventually(|| !running.status.halted()), "running again");
    gdb.send_raw(&[0x03]);
    let stop = gdb.stop_reply();
    assert!(stop.starts_with("T02") || stop.starts_with("S02"), "{stop}");
    assert!(running.status.halted());

    // Detach: the core runs on.
    assert_eq!(gdb.ask("D"), "OK");
    let counter = {
        let mut next = Client::connect(running.address);
        next.ask("qSupported");
        let c = next.counter();
        next.ask("D");
        c
    };
    let (mut mcu, _) = running.finish();
    assert!(mcu.debug_read(COUNTER, &mut [0; 4]) == 4);
    assert!(counter > 0);
}

#[test]
fn bad_packets_get_errors_a_second_client_is_refused_and_a_vanished_one_releases_the_mcu() {
    let running = Running::start();
    let mut gdb = Client::connect(running.address);
    gdb.ask("qSupported");
    // A wrong checksum asks for the packet again.
    gdb.send_raw(b"$g#00");
    assert_eq!(gdb.byte(), b'-');
    // A command gdbstub cannot parse: an error, and the session goes on.
    assert_eq!(gdb.ask("mzz,4"), "E01");
    assert_eq!(gdb.ask("m20000000,4").len(), 8);
    // Longer than a packet: an error.
    let long = format!("M20000000,8000:{}", "00".repeat(0x8000));
    assert!(gdb.ask(&long).starts_with("E."), "too long");
    assert_eq!(gdb.ask("m20000000,4").len(), 8);

    // A second client is told who has the port.
    let mut second = Client::connect(running.address);
    let refused = second.ask("qSupported");
    assert!(
        refused.starts_with("E.the debug port of test-ecu is in use by 127.0.0.1:"),
        "{refused}"
    );
    // And the connection closes (read to its end, or reset: the client's ack came after
    // the server closed).
    let mut rest = Vec::new();
    let _ = second.stream.read_to_end(&mut rest);
    assert!(!rest.contains(&b'$'), "no more packets");

    // A flood of connections: the extra ones are closed, the attached client is served.
    let flood: Vec<TcpStream> = (0..40)
        .filter_map(|_| TcpStream::connect(running.address).ok())
        .collect();
    assert_eq!(gdb.ask("m20000000,4").len(), 8);
    drop(flood);

    // Gone mid-packet: the MCU runs on.
    let counter = gdb.counter();
    gdb.send_raw(b"$m2000");
    drop(gdb);
    assert!(eventually(
        || !running.status.attached() && !running.status.halted()
    ));
    // The flood's connections, hung up while they waited, do not take the port in turn.
    let quiet = std::time::Instant::now();
    while quiet.elapsed() < Duration::from_millis(300) {
        assert!(
            !running.status.attached(),
            "a hung-up connection took the port"
        );
        std::thread::sleep(Duration::from_millis(2));
    }
    let mut next = Client::connect(running.address);
    next.ask("qSupported");
    assert!(
        next.counter() != counter,
        "the core ran after the client went"
    );
    next.ask("D");
    running.finish();
}

#[test]
fn execution_runs_backwards_to_the_last_write_and_forwards_to_the_present() {
    let running = Running::start();
    let mut gdb = Client::connect(running.address);
    gdb.ask("qSupported:swbreak+;hwbreak+");
    // Let the history fill: 300 ms of simulated time, three snapshots.
    gdb.send_raw(format!("$c#{}", checksum("c")).as_bytes());
    std::thread::sleep(Duration::from_millis(300));
    gdb.send_raw(&[0x03]);
    gdb.stop_reply();

    assert_eq!(gdb.ask(&format!("Z2,{COUNTER:x},4")), "OK");
    gdb.send_raw(format!("$c#{}", checksum("c")).as_bytes());
    assert!(gdb.stop_reply().contains("watch:"));
    let present = gdb.counter();
    assert_eq!(gdb.register(15), STORE_PC + 2);
    // The halt hook ran at the real halts; replays of the past must not run it (the
    // past's log was read when it happened).
    let hooks = running.halt_hooks.load(Ordering::Relaxed);
    assert!(hooks >= 2, "{hooks}");

    // One instruction back: before the store.
    let stop = gdb.ask("bs");
    assert!(stop.starts_with("S05") || stop.starts_with("T05"), "{stop}");
    assert_eq!(gdb.register(15), STORE_PC);
    assert_eq!(gdb.counter(), present - 1);
    // The past cannot be changed.
    assert!(gdb.ask("M20000100,4:00000000").starts_with('E'));

    // Back to the write before: after it, the counter one lower.
    let stop = gdb.ask("bc");
    assert!(stop.contains(&format!("watch:{COUNTER:x}")), "{stop}");
    assert_eq!(gdb.register(15), STORE_PC + 2);
    assert_eq!(gdb.counter(), present - 1);
    // And many writes back, still exact.
    for back in 2..50 {
        assert!(gdb.ask("bc").contains("watch:"));
        assert_eq!(gdb.counter(), present - back);
    }

    // Forwards through the past: the next write, then the present again.
    assert_eq!(gdb.ask(&format!("z2,{COUNTER:x},4")), "OK");
    let stop = gdb.ask("c");
    assert!(stop.contains("replaylog:end"), "{stop}");
    assert_eq!(gdb.counter(), present);
    assert_eq!(gdb.register(15), STORE_PC + 2);

    // Far back: the history reaches its beginning and says so.
    let stop = gdb.ask("bc");
    assert!(stop.contains("replaylog:begin"), "{stop}");
    assert_eq!(
        running.halt_hooks.load(Ordering::Relaxed),
        hooks,
        "no halt hook in the replays"
    );
    assert!(
        gdb.counter() < present - 1000,
        "{} of {present}",
        gdb.counter()
    );
    // `monitor history`: console output (O packets), then OK.
    let mut reply = gdb.ask(&format!(
        "qRcmd,{}",
        b"history"
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect::<String>()
    ));
    let mut text = Vec::new();
    while reply != "OK" {
        text.extend(
            (1..reply.len())
                .step_by(2)
                .filter_map(|i| reply.get(i..i + 2))
                .filter_map(|h| u8::from_str_radix(h, 16).ok()),
        );
        reply = gdb.reply();
    }
    let text = String::from_utf8_lossy(&text);
    assert!(
        text.contains("history: ") && text.contains("looking at the past"),
        "{text}"
    );
    let stop = gdb.ask("c");
    assert!(stop.contains("replaylog:end"), "{stop}");
    assert_eq!(gdb.counter(), present);

    // Live again: the core runs on from the present.
    gdb.send_raw(format!("$c#{}", checksum("c")).as_bytes());
    std::thread::sleep(Duration::from_millis(30));
    gdb.send_raw(&[0x03]);
    let stop = gdb.stop_reply();
    let now = gdb.counter();
    assert!(
        now > present,
        "{now} after {present} ({stop}, pc {:#x})",
        gdb.register(15)
    );
    gdb.ask("D");
    running.finish();
}

/// The fuzz target's path (`fuzz/fuzz_targets/gdb_packets.rs`) on what a hostile client
/// might send: nothing panics, and the session over leaves the MCU as a detach does.
#[test]
fn hostile_bytes_through_the_whole_packet_path() {
    let packet = |body: &str| format!("${body}#{}", checksum(body));
    let cases: Vec<Vec<u8>> = vec![
        vec![],
        b"$".to_vec(),
        b"$#".to_vec(),
        b"#00$$$###\x03\x03+-".to_vec(),
        packet("m").into_bytes(),
        packet("mffffffff,ffffffff").into_bytes(),
        packet("M20000000,ffffffff:00").into_bytes(),
        packet("X20000000,4:\x7d\x03\x7d").into_bytes(),
        packet("Z2,1fffffff,80000000").into_bytes(),
        packet("Z1,0,2").into_bytes(),
        packet("Z0,20000000,2").into_bytes(),
        packet("G00").into_bytes(),
        packet("P99=00000000").into_bytes(),
        packet("p28").into_bytes(),
        packet("vFlashErase:08000000,00080000").into_bytes(),
        packet("vFlashErase:ffffffff,ffffffff").into_bytes(),
        packet("vFlashWrite:08003ffe:\x01\x02\x03").into_bytes(),
        packet("vFlashWrite:fffffffe:\x01\x02\x03").into_bytes(),
        packet("vFlashDone").into_bytes(),
        packet("qRcmd,7265736574").into_bytes(),
        packet("qRcmd,").into_bytes(),
        packet("qRcmd,zz").into_bytes(),
        packet("qXfer:memory-map:read::ffffffff,ffffffff").into_bytes(),
        packet("qXfer:features:read:target.xml:fffffff0,100").into_bytes(),
        [
            packet("c"),
            packet("bs"),
            packet("bc"),
            packet("s"),
            packet("vCont;r0,ffffffff"),
        ]
        .concat()
        .into_bytes(),
        [
            packet("QStartNoAckMode"),
            packet("mzz"),
            packet("g"),
            packet("D"),
        ]
        .concat()
        .into_bytes(),
        (0..=255u8).collect(),
        std::iter::repeat_n(b'$', 20_000).collect(),
    ];
    for bytes in cases {
        let mut mcu = counting();
        autoplug_mcu::gdb::fuzz_session(&mut mcu, &bytes);
        assert!(mcu.cpu.debug.is_none() && mcu.history.is_none());
        assert!(mcu.debug.hw_breakpoints.is_empty() && mcu.debug.watchpoints.is_empty());
        // The MCU runs on (or stops as its program has it: a client may have erased the
        // flash or written the registers).
        let _ = mcu.run_until(1_000_000);
    }
}

/// UDF, whose HardFault handler is another UDF: the core locks up (no watchdog runs).
fn locking_up() -> Mcu {
    let code: [u16; 2] = [
        0xDE00, // 0x40: UDF, a UsageFault escalated to HardFault
        0xDE00, // 0x42: the handler: UDF again, a fault it cannot take
    ];
    powered(&bare_program(
        &[0x2002_0000, FLASH.start + 0x41, 0, FLASH.start + 0x43],
        &code,
    ))
}

#[test]
fn a_lockup_halts_into_the_debugger_with_the_fault_registers() {
    let mut mcu = locking_up();
    let server = GdbServer::bind("test-ecu", "127.0.0.1:0".parse().unwrap()).unwrap();
    let address = server.local_addr();
    let mut gdb = Client::connect(address);
    // The run starts under the debugger, as `--gdb` runs do.
    assert!(server.wait_for_client(Some(Duration::from_secs(10))));
    mcu.debugger = Some(Box::new(server));
    let thread = std::thread::spawn(move || {
        for ms in 1..=10_000u64 {
            if let Err(stop) = mcu.run_until(ms * 1_000_000) {
                return Some(stop);
            }
        }
        None
    });
    assert_eq!(gdb.ask("QStartNoAckMode"), "OK");
    gdb.no_ack = true;
    assert!(gdb.ask("?").starts_with(['S', 'T']));
    // The vector catch stops at the HardFault first, as probe-rs's does.
    gdb.send_raw(format!("$c#{}", checksum("c")).as_bytes());
    let (reply, console) = gdb.stop_reply_and_console();
    assert!(
        reply.starts_with("S0b") || reply.starts_with("T0b"),
        "{reply}"
    );
    assert!(console.starts_with("HardFault"), "{console}");
    // Its handler faults again: the core locks up, and the debugger is told why.
    gdb.send_raw(format!("$c#{}", checksum("c")).as_bytes());
    let (reply, console) = gdb.stop_reply_and_console();
    assert!(
        reply.starts_with("S0b") || reply.starts_with("T0b"),
        "{reply}"
    );
    assert!(
        console.contains(&format!(
            "the core locked up at {:#010x}",
            FLASH.start + 0x42
        )) && console.contains("HFSR 0x40000000"),
        "{console}"
    );
    // Detached, the lockup ends the run (no watchdog) with its report.
    gdb.send_raw(format!("$D#{}", checksum("D")).as_bytes());
    let stop = thread.join().unwrap();
    assert!(
        matches!(
            stop,
            Some(autoplug_mcu::mcu::Stop::Halted(
                autoplug_mcu::cpu::Halt::Lockup { .. }
            ))
        ),
        "{stop:?}"
    );
}
