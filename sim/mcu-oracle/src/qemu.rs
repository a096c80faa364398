//! QEMU's `mps2-an386` (Cortex-M4 with FPv4-SP) as a separate process, driven through its
//! GDB stub: the oracle that runs one [`Block`] at a time.
//!
//! # The machine as the oracle sets it up
//!
//! The AN386 image has 4 MiB of RAM at 0x0000_0000 (`mps.ssram1`) and 4 MiB at
//! 0x2000_0000 (`mps.ssram23`) (QEMU's `info mtree`). Once per process (and again after a
//! fault, which leaves the core in Handler mode and is followed by `monitor system_reset`)
//! the oracle writes:
//!
//! - a vector table at 0 whose NMI, HardFault, MemManage, BusFault, UsageFault and other
//!   vectors all point at a fault stub ([`FAULT_STUB`]), which records IPSR, the stacked
//!   PC, CFSR, HFSR, MMFAR and BFAR and branches to [`STOP`];
//! - [`STOP`]: `b .` with a GDB breakpoint on it, where every run ends;
//! - a setup routine, run once: CPACR = 0x00F0_0000 (CP10 and CP11 full access: QEMU 7.2's
//!   gdbstub reads the System Control Space but drops writes to it while answering `OK`,
//!   so a debugger write does not enable the FPU) and SHCSR's MEMFAULTENA, BUSFAULTENA and
//!   USGFAULTENA (so that a fault keeps its own exception number instead of escalating to
//!   HardFault; an exception QEMU cannot take at all is a lockup, which QEMU 7.2 treats as
//!   a fatal error and exits).
//!
//! QEMU runs under `sh`, which kills it as soon as this process's end of a pipe closes:
//! when the [`Qemu`] is dropped (a panicking test included) or this process dies.
//!
//! # One run
//!
//! QEMU 7.2's `g` packet holds r0–r15 and xPSR only (the VFP registers are separate `p`
//! registers, one round trip each) and its stub knows no `QStartNoAckMode`. To keep a run
//! at five round trips, the floating-point registers go in and out through memory:
//!
//! 1. one `M` writes, just below [`CODE_BASE`], a pool (s0–s31 and r0's starting value)
//!    and a prologue, then the block's code, then an epilogue;
//! 2. one `M` writes the data window and clears the status word after it;
//! 3. one `G` writes r0–r15 and xPSR, with r0 = the starting FPSCR and PC = the prologue;
//! 4. `c` runs to [`STOP`]: the prologue does `VMSR FPSCR, r0`, `CLREX`, loads s0–s31 from
//!    the pool and r0 from the pool, falling into the block at [`CODE_BASE`] with exactly
//!    the block's starting state; the epilogue at the block's end parks r0 in PSP, PRIMASK
//!    and FAULTMASK (`MSR`; PSP alone would lose bits 1:0), then stores r0–r12, LR, SP,
//!    xPSR (`MRS`), s0–s31 and FPSCR after the data window and sets the status word;
//! 5. one `m` reads back the data window with the saved registers and the status.
//!
//! PC in the result is the block's end (the epilogue is only reached there) and xPSR is
//! what `MRS xPSR` reads (APSR and IPSR) with the Thumb bit set: EPSR's IT bits read as
//! zero, and the generator never ends a block inside an IT block.
//! [`Qemu::run_via_gdb`] does the same through the debugger alone (a breakpoint at the
//! block's end, every register by `g`/`p`): slow, and there to check the fast path.

use std::io::Read;
use std::net::{Ipv4Addr, SocketAddr, TcpListener};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::thread;
use std::time::{Duration, Instant};

use super::blocks::{Block, CODE_BASE, DATA_BASE, DATA_LEN};
use super::gdb::{GdbClient, StopReply, TargetDescription};
use super::thumb::{self, Insn};
use super::OracleError;
use autoplug_mcu::cpu::ArchState;

/// The vector table's address.
pub const VECTOR_TABLE: u32 = 0x0000_0000;
/// Where the fault vectors point (Thumb bit clear here; the table holds `FAULT_STUB | 1`).
pub const FAULT_STUB: u32 = 0x0000_0100;
/// `b .` with the breakpoint every run ends at.
pub const STOP: u32 = 0x0000_0200;
/// The setup routine (FPU on, fault handlers enabled).
pub const SETUP: u32 = 0x0000_0300;
/// The stack pointer the vector table gives at reset.
pub const RESET_SP: u32 = DATA_BASE - 0x100;

/// The prologue's length in bytes: it ends at [`CODE_BASE`].
const PROLOGUE_LEN: u32 = 24;
/// The prologue's address.
pub const PROLOGUE: u32 = CODE_BASE - PROLOGUE_LEN;
/// The pool the prologue loads: s0–s31, then r0.
const POOL: u32 = PROLOGUE - 33 * 4;
/// Where the epilogue and the fault stub leave their results: right after the data
/// window, so that one `m` reads both.
pub const DUMP: u32 = DATA_BASE + DATA_LEN;
/// The dump's length in bytes.
const DUMP_LEN: u32 = 50 * 4;
// The dump's words.
const D_STATUS: usize = 0;
const D_R1: usize = 1; // r1..r12 at 1..=12
const D_LR: usize = 13;
const D_R0: usize = 14;
const D_SP: usize = 15;
const D_XPSR: usize = 16;
const D_S0: usize = 17; // s0..s31 at 17..=48
const D_FPSCR: usize = 49;
// The fault stub's words.
const F_IPSR: usize = 1;
const F_PC: usize = 2;
const F_CFSR: usize = 3;
const F_HFSR: usize = 4;
const F_MMFAR: usize = 5;
const F_BFAR: usize = 6;
// The status word's values.
const STATUS_FINISHED: u32 = 1;
const STATUS_FAULT: u32 = 2;

/// How long a block may run.
const RUN_TIMEOUT: Duration = Duration::from_secs(5);
/// How long each exchange with the stub may take.
const EXCHANGE_TIMEOUT: Duration = Duration::from_secs(5);
/// How long QEMU may take to start and connect.
const START_TIMEOUT: Duration = Duration::from_secs(20);

/// What a block did.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// It ran to its end: the registers there and the data window's contents.
    Finished {
        /// r0–r15 (PC = the block's end), xPSR, s0–s31, FPSCR.
        state: ArchState,
        /// The data window, [`DATA_LEN`] bytes from [`DATA_BASE`].
        data: Vec<u8>,
    },
    /// It raised an exception: the registers the fault stub saw.
    Fault {
        /// The stacked PC: the faulting instruction's address.
        pc: u32,
        /// The exception number (IPSR): 3 HardFault, 4 MemManage, 5 BusFault,
        /// 6 UsageFault, 2 NMI.
        exception: u32,
        /// The Configurable Fault Status Register (UFSR:BFSR:MMFSR).
        cfsr: u32,
        /// The HardFault Status Register.
        hfsr: u32,
        /// The MemManage Fault Address Register.
        mmfar: u32,
        /// The BusFault Address Register.
        bfar: u32,
    },
}

impl Outcome {
    /// The final state and data window, if the block finished.
    pub fn finished(&self) -> Option<(&ArchState, &[u8])> {
        match self {
            Outcome::Finished { state, data } => Some((state, data)),
            Outcome::Fault { .. } => None,
        }
    }
}

/// The GDB register numbers of the Cortex-M4F's registers, from the target description.
#[derive(Clone, Debug)]
struct Registers {
    core: [usize; 16],
    xpsr: usize,
    /// d0–d15 (s0–s31 in pairs, low word first).
    d: [usize; 16],
    fpscr: usize,
    /// The `g` packet's contents: (register number, byte offset, size), and its length.
    g_layout: Vec<(usize, usize, usize)>,
    g_len: usize,
}

impl Registers {
    fn find(description: &TargetDescription) -> Result<Registers, OracleError> {
        let number = |name: &str, bits: u32| -> Result<usize, OracleError> {
            let reg = description.find(name).ok_or_else(|| {
                OracleError::Setup(format!("the target description has no register {name}"))
            })?;
            if reg.bits != bits {
                return Err(OracleError::Setup(format!(
                    "register {name} is {} bits wide, not {bits}",
                    reg.bits
                )));
            }
            Ok(reg.number)
        };
        let names = [
            "r0", "r1", "r2", "r3", "r4", "r5", "r6", "r7", "r8", "r9", "r10", "r11", "r12", "sp",
            "lr", "pc",
        ];
        let mut core = [0; 16];
        for (slot, name) in core.iter_mut().zip(names) {
            *slot = number(name, 32)?;
        }
        let mut d = [0; 16];
        for (i, slot) in d.iter_mut().enumerate() {
            *slot = number(&format!("d{i}"), 64)?;
        }
        Ok(Registers {
            core,
            xpsr: number("xpsr", 32)?,
            d,
            fpscr: number("fpscr", 32)?,
            g_layout: Vec::new(),
            g_len: 0,
        })
    }

    /// Works out which registers the `g` packet holds: those of the description in number
    /// order, as many as fill the reply.
    fn learn_g_layout(
        &mut self,
        description: &TargetDescription,
        g_len: usize,
    ) -> Result<(), OracleError> {
        let mut regs: Vec<_> = description.registers.iter().collect();
        regs.sort_by_key(|r| r.number);
        let mut offset = 0;
        for reg in regs {
            if offset >= g_len {
                break;
            }
            let size = (reg.bits as usize).div_ceil(8);
            self.g_layout.push((reg.number, offset, size));
            offset += size;
        }
        if offset != g_len {
            return Err(OracleError::Setup(format!(
                "the 'g' reply's {g_len} bytes do not end at a register boundary of the \
                 target description"
            )));
        }
        self.g_len = g_len;
        for needed in self.core.iter().chain([&self.xpsr]) {
            if !self.g_layout.iter().any(|(n, ..)| n == needed) {
                return Err(OracleError::Setup(format!(
                    "register {needed} is not in the 'g' packet"
                )));
            }
        }
        Ok(())
    }

    fn offset_of(&self, number: usize) -> Option<usize> {
        self.g_layout
            .iter()
            .find(|(n, ..)| *n == number)
            .map(|(_, o, _)| *o)
    }

    /// r0–r15 and xPSR from a `g` reply.
    fn core_from_g(&self, g: &[u8]) -> Result<([u32; 16], u32), OracleError> {
        if g.len() != self.g_len {
            return Err(OracleError::Protocol {
                what: "reading the registers".into(),
                detail: format!("the 'g' reply has {} bytes, not {}", g.len(), self.g_len),
            });
        }
        let word = |number: usize| {
            let o = self.offset_of(number).unwrap_or(0);
            u32::from_le_bytes([g[o], g[o + 1], g[o + 2], g[o + 3]])
        };
        let mut r = [0; 16];
        for (value, &number) in r.iter_mut().zip(&self.core) {
            *value = word(number);
        }
        Ok((r, word(self.xpsr)))
    }

    /// A `G` packet's contents: `template` (a `g` reply) with r0–r15 and xPSR replaced.
    fn g_with(&self, template: &[u8], r: &[u32; 16], xpsr: u32) -> Vec<u8> {
        let mut g = template.to_vec();
        let mut put = |number: usize, value: u32| {
            if let Some(o) = self.offset_of(number) {
                g[o..o + 4].copy_from_slice(&value.to_le_bytes());
            }
        };
        for (&number, &value) in self.core.iter().zip(r) {
            put(number, value);
        }
        put(self.xpsr, xpsr);
        g
    }
}

/// A running `qemu-system-arm -M mps2-an386`, stopped between runs; killed when dropped.
#[derive(Debug)]
pub struct Qemu {
    /// `sh`, which runs QEMU and kills it when its stdin closes (this process exiting or
    /// [`Qemu`] being dropped): no QEMU outlives its test.
    child: Child,
    watchdog: Option<ChildStdin>,
    gdb: GdbClient,
    registers: Registers,
    /// A `g` reply, the template for `G` packets.
    g_template: Vec<u8>,
    /// QEMU's standard error, collected by a thread.
    stderr: Arc<Mutex<Vec<u8>>>,
    /// Whether the core must be reset and set up again before the next run (after a
    /// fault it is in Handler mode).
    needs_reset: bool,
}

/// The QEMU binary: `AUTOPLUG_QEMU`, or `qemu-system-arm` from `PATH`.
pub fn qemu_binary() -> String {
    std::env::var("AUTOPLUG_QEMU").unwrap_or_else(|_| "qemu-system-arm".to_string())
}

/// Finds `binary` as the shell would: a path as it is, a bare name in `PATH`.
fn resolve(binary: &str) -> Option<PathBuf> {
    let path = Path::new(binary);
    if binary.contains('/') {
        return path.is_file().then(|| path.to_path_buf());
    }
    std::env::var_os("PATH").and_then(|paths| {
        std::env::split_paths(&paths)
            .map(|dir| dir.join(binary))
            .find(|candidate| candidate.is_file())
    })
}

/// Runs `"$0" "$@"` (QEMU) in the background with its stdin from /dev/null and kills it
/// as soon as the shell's own stdin (a pipe from this process) reaches its end; exits with
/// QEMU's status when QEMU exits by itself.
const WATCHDOG: &str = r#"exec 3<&0
"$0" "$@" </dev/null &
q=$!
( read -r _ <&3; kill -9 "$q" 2>/dev/null ) &
w=$!
wait "$q"
s=$?
kill "$w" 2>/dev/null
exit "$s""#;

impl Qemu {
    /// Starts QEMU (the binary named by `AUTOPLUG_QEMU`, default `qemu-system-arm`),
    /// connects to its GDB stub and sets the machine up.
    pub fn start() -> Result<Qemu, OracleError> {
        Qemu::start_binary(&qemu_binary())
    }

    /// Starts this QEMU binary, connects to its GDB stub and sets the machine up.
    pub fn start_binary(binary: &str) -> Result<Qemu, OracleError> {
        let path = resolve(binary).ok_or_else(|| OracleError::QemuMissing {
            binary: binary.to_string(),
        })?;
        // QEMU connects to us (a chardev socket in client mode): no port to guess, no
        // polling for QEMU's listener.
        let listener =
            TcpListener::bind(SocketAddr::from((Ipv4Addr::LOCALHOST, 0))).map_err(|source| {
                OracleError::Io {
                    what: "listening for QEMU's GDB connection".into(),
                    source,
                }
            })?;
        let port = listener
            .local_addr()
            .map_err(|source| OracleError::Io {
                what: "reading the listener's port".into(),
                source,
            })?
            .port();
        let chardev = format!("socket,id=gdb0,host=127.0.0.1,port={port},nodelay=on");
        let mut child = Command::new("sh")
            .arg("-c")
            .arg(WATCHDOG)
            .arg(&path)
            .args(["-M", "mps2-an386", "-display", "none", "-S"])
            .args(["-monitor", "none", "-serial", "none", "-parallel", "none"])
            .args(["-chardev", &chardev, "-gdb", "chardev:gdb0"])
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| OracleError::Qemu {
                what: format!("starting {} through sh", path.display()),
                detail: e.to_string(),
            })?;
        let watchdog = child.stdin.take();
        let stderr = Arc::new(Mutex::new(Vec::new()));
        if let Some(mut pipe) = child.stderr.take() {
            let sink = Arc::clone(&stderr);
            thread::spawn(move || {
                let mut buffer = [0u8; 4096];
                while let Ok(n) = pipe.read(&mut buffer) {
                    if n == 0 {
                        break;
                    }
                    if let Ok(mut s) = sink.lock() {
                        s.extend_from_slice(&buffer[..n]);
                    }
                }
            });
        }
        let stream = match accept(&listener, &mut child) {
            Ok(stream) => stream,
            Err(e) => {
                drop(watchdog);
                let _ = child.wait();
                return Err(with_stderr(e, &stderr));
            }
        };
        let gdb = GdbClient::new(stream, EXCHANGE_TIMEOUT)?;
        let mut qemu = Qemu {
            child,
            watchdog,
            gdb,
            registers: Registers {
                core: [0; 16],
                xpsr: 0,
                d: [0; 16],
                fpscr: 0,
                g_layout: Vec::new(),
                g_len: 0,
            },
            g_template: Vec::new(),
            stderr,
            needs_reset: false,
        };
        qemu.connect().map_err(|e| qemu.explain(e))?;
        qemu.setup().map_err(|e| qemu.explain(e))?;
        qemu.check().map_err(|e| qemu.explain(e))?;
        Ok(qemu)
    }

    /// The GDB client, for experiments beyond [`Qemu::run`]. Whatever it changes stays
    /// changed; [`Qemu::reset`] puts the machine back as [`Qemu::start`] left it.
    pub fn gdb(&mut self) -> &mut GdbClient {
        &mut self.gdb
    }

    /// The handshake: features, the target description, the `g` packet's layout.
    fn connect(&mut self) -> Result<(), OracleError> {
        let features = self.gdb.query_supported()?;
        if !features.iter().any(|f| f == "qXfer:features:read+") {
            return Err(OracleError::Setup(format!(
                "the stub offers no target description (qSupported: {})",
                features.join(";")
            )));
        }
        self.gdb.try_no_ack_mode(&features)?;
        // Reading target.xml also switches QEMU's 'g' packet to the described registers.
        let description = self.gdb.target_description()?;
        self.registers = Registers::find(&description)?;
        match self.gdb.stop_reason()? {
            StopReply::Signal { .. } => {}
            other => {
                return Err(OracleError::Setup(format!(
                    "the target is not stopped: {other:?}"
                )))
            }
        }
        let g = self.gdb.read_registers()?;
        self.registers.learn_g_layout(&description, g.len())?;
        self.g_template = g;
        Ok(())
    }

    /// Writes the vector table and the stubs, runs the setup routine and leaves the
    /// breakpoint at [`STOP`].
    fn setup(&mut self) -> Result<(), OracleError> {
        let mut table = Vec::with_capacity(64);
        table.extend_from_slice(&RESET_SP.to_le_bytes());
        table.extend_from_slice(&(STOP | 1).to_le_bytes());
        for _ in 2..16 {
            table.extend_from_slice(&(FAULT_STUB | 1).to_le_bytes());
        }
        self.gdb.write_memory(VECTOR_TABLE, &table)?;
        self.gdb
            .write_memory(FAULT_STUB, &code_bytes(&fault_stub()))?;
        self.gdb
            .write_memory(STOP, &code_bytes(&[thumb::b_t2(-4)]))?;
        self.gdb
            .write_memory(SETUP, &code_bytes(&setup_routine()))?;
        self.gdb.insert_breakpoint(STOP, 2)?;
        let mut r = [0u32; 16];
        r[13] = RESET_SP;
        r[15] = SETUP;
        let g = self.registers.g_with(&self.g_template, &r, 1 << 24);
        self.gdb.write_registers(&g)?;
        self.expect_stop("the setup routine")?;
        let g = self.gdb.read_registers()?;
        let (r, xpsr) = self.registers.core_from_g(&g)?;
        if r[15] != STOP || xpsr & 0x1ff != 0 {
            return Err(OracleError::Setup(format!(
                "the setup routine stopped at {:#010x} with xPSR {xpsr:#010x}, not at the \
                 stop address {STOP:#010x} in Thread mode",
                r[15]
            )));
        }
        self.needs_reset = false;
        Ok(())
    }

    /// Runs a VADD with known values and FPSCR: the FPU must be on, the rounding mode
    /// must be the one loaded (round towards minus infinity: 1.0000001 + 1.0000002 rounds
    /// down), and the other registers must come back unchanged.
    fn check(&mut self) -> Result<(), OracleError> {
        let mut start = ArchState {
            xpsr: 1 << 24,
            fpscr: 0x0080_0000,
            ..ArchState::default()
        };
        start.r[13] = DATA_BASE + DATA_LEN / 2;
        for (i, s) in start.s.iter_mut().enumerate() {
            *s = 0x3f80_0000 + i as u32;
        }
        // vadd.f32 s0, s1, s2
        let block = Block::new(
            code_bytes(&[thumb::vfp3(3, false, 0, 1, 2)]),
            start,
            vec![0; DATA_LEN as usize],
        );
        let mut expected = start;
        expected.s[0] = 0x4000_0001;
        expected.fpscr |= 0x10; // IXC
        expected.r[15] = block.end();
        match self.run(&block)? {
            Outcome::Finished { state, .. } if state == expected => Ok(()),
            Outcome::Finished { state, .. } => Err(OracleError::Setup(format!(
                "a VADD with FPSCR.RMode = RM gave {state:x?}, not {expected:x?}"
            ))),
            fault => Err(OracleError::Setup(format!(
                "a VADD faulted (is the FPU enabled?): {fault:x?}"
            ))),
        }
    }

    /// Resets the core (`monitor system_reset`) and sets the machine up again.
    pub fn reset(&mut self) -> Result<(), OracleError> {
        self.gdb.monitor("system_reset")?;
        self.setup()
    }

    /// Runs `block`: from [`CODE_BASE`] with `block.start` and `block.data` until PC reaches
    /// the block's end or an exception is taken.
    pub fn run(&mut self, block: &Block) -> Result<Outcome, OracleError> {
        self.prepare()?;
        let result = self.run_fast(block);
        self.after(result)
    }

    /// Runs `block` through the debugger alone: a breakpoint at its end, the registers
    /// written and read with `G`/`P` and `g`/`p`. Slow; a check of [`Qemu::run`].
    pub fn run_via_gdb(&mut self, block: &Block) -> Result<Outcome, OracleError> {
        self.prepare()?;
        let result = self.run_slow(block);
        self.after(result)
    }

    fn prepare(&mut self) -> Result<(), OracleError> {
        if self.needs_reset {
            self.reset().map_err(|e| self.explain(e))?;
        }
        Ok(())
    }

    fn after(&mut self, result: Result<Outcome, OracleError>) -> Result<Outcome, OracleError> {
        match result {
            Ok(outcome) => {
                if matches!(outcome, Outcome::Fault { .. }) {
                    self.needs_reset = true;
                }
                Ok(outcome)
            }
            Err(e) => {
                self.needs_reset = true;
                Err(self.explain(e))
            }
        }
    }

    fn run_fast(&mut self, block: &Block) -> Result<Outcome, OracleError> {
        let end = block.end();
        let start = &block.start;
        // 1. Pool, prologue, code, epilogue.
        let mut image = Vec::with_capacity(block.code.len() + 256);
        for s in start.s {
            image.extend_from_slice(&s.to_le_bytes());
        }
        image.extend_from_slice(&start.r[0].to_le_bytes());
        image.extend(code_bytes(&prologue()));
        debug_assert_eq!(POOL + image.len() as u32, CODE_BASE);
        image.extend_from_slice(&block.code);
        image.extend(code_bytes(&epilogue(end)));
        self.gdb.write_memory(POOL, &image)?;
        // 2. The data window and a cleared status word.
        let mut data = window_of(block)?;
        data.extend_from_slice(&0u32.to_le_bytes());
        self.gdb.write_memory(DATA_BASE, &data)?;
        // 3. The core registers.
        let mut r = start.r;
        r[0] = start.fpscr;
        r[15] = PROLOGUE;
        let g = self
            .registers
            .g_with(&self.g_template, &r, thumb_xpsr(start.xpsr));
        self.gdb.write_registers(&g)?;
        // 4. Run.
        self.expect_stop("the block")?;
        // 5. The window and the dump.
        let bytes = self
            .gdb
            .read_memory(DATA_BASE, (DATA_LEN + DUMP_LEN) as usize)?;
        let (data, dump) = bytes.split_at(DATA_LEN as usize);
        let word = |i: usize| {
            u32::from_le_bytes([
                dump[4 * i],
                dump[4 * i + 1],
                dump[4 * i + 2],
                dump[4 * i + 3],
            ])
        };
        match word(D_STATUS) {
            STATUS_FINISHED => {
                let mut state = ArchState::default();
                state.r[0] = word(D_R0);
                for i in 1..=12 {
                    state.r[i] = word(D_R1 + i - 1);
                }
                state.r[13] = word(D_SP);
                state.r[14] = word(D_LR);
                state.r[15] = end;
                state.xpsr = word(D_XPSR) | 1 << 24;
                for (i, s) in state.s.iter_mut().enumerate() {
                    *s = word(D_S0 + i);
                }
                state.fpscr = word(D_FPSCR);
                Ok(Outcome::Finished {
                    state,
                    data: data.to_vec(),
                })
            }
            STATUS_FAULT => Ok(fault_from(&word)),
            other => Err(OracleError::Setup(format!(
                "the run stopped at the stop address with status word {other:#x}: neither \
                 the epilogue nor the fault stub ran"
            ))),
        }
    }

    fn run_slow(&mut self, block: &Block) -> Result<Outcome, OracleError> {
        let end = block.end();
        let start = &block.start;
        // CLREX, then the code, then `b .` after the end (the breakpoint stops there).
        let mut image = code_bytes(&[thumb::clrex()]);
        image.extend_from_slice(&block.code);
        image.extend(code_bytes(&[thumb::b_t2(-4)]));
        self.gdb.write_memory(CODE_BASE - 4, &image)?;
        let mut data = window_of(block)?;
        data.extend_from_slice(&0u32.to_le_bytes());
        self.gdb.write_memory(DATA_BASE, &data)?;
        let mut r = start.r;
        r[15] = CODE_BASE - 4;
        let g = self
            .registers
            .g_with(&self.g_template, &r, thumb_xpsr(start.xpsr));
        self.gdb.write_registers(&g)?;
        for (i, &number) in self.registers.d.clone().iter().enumerate() {
            let mut bytes = start.s[2 * i].to_le_bytes().to_vec();
            bytes.extend_from_slice(&start.s[2 * i + 1].to_le_bytes());
            self.gdb.write_register(number, &bytes)?;
        }
        let fpscr = self.registers.fpscr;
        self.gdb.write_register(fpscr, &start.fpscr.to_le_bytes())?;
        self.gdb.insert_breakpoint(end, 2)?;
        let stopped = self.expect_stop("the block (run through the debugger)");
        self.gdb.remove_breakpoint(end, 2)?;
        stopped?;
        let g = self.gdb.read_registers()?;
        let (r, xpsr) = self.registers.core_from_g(&g)?;
        if r[15] == STOP {
            let dump = self.gdb.read_memory(DUMP, DUMP_LEN as usize)?;
            let word = |i: usize| {
                u32::from_le_bytes([
                    dump[4 * i],
                    dump[4 * i + 1],
                    dump[4 * i + 2],
                    dump[4 * i + 3],
                ])
            };
            return Ok(fault_from(&word));
        }
        if r[15] != end {
            return Err(OracleError::Setup(format!(
                "the block stopped at {:#010x}, neither its end {end:#010x} nor the stop address",
                r[15]
            )));
        }
        let mut state = ArchState {
            r,
            xpsr,
            ..ArchState::default()
        };
        for (i, &number) in self.registers.d.clone().iter().enumerate() {
            let bytes = self.gdb.read_register(number)?;
            if bytes.len() != 8 {
                return Err(OracleError::Protocol {
                    what: format!("reading d{i}"),
                    detail: format!("{} bytes", bytes.len()),
                });
            }
            state.s[2 * i] = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
            state.s[2 * i + 1] = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]);
        }
        let bytes = self.gdb.read_register(fpscr)?;
        state.fpscr = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]);
        let data = self.gdb.read_memory(DATA_BASE, DATA_LEN as usize)?;
        Ok(Outcome::Finished { state, data })
    }

    /// Continues and expects a SIGTRAP stop.
    fn expect_stop(&mut self, what: &str) -> Result<(), OracleError> {
        match self.gdb.cont(RUN_TIMEOUT) {
            Ok(StopReply::Signal { signal: 5, .. }) => Ok(()),
            Ok(other) => Err(OracleError::Qemu {
                what: format!("running {what}"),
                detail: format!("stopped with {other:?}"),
            }),
            Err(OracleError::Timeout { after, .. }) => Err(OracleError::Timeout {
                what: format!("{what} to reach its end (interrupted)"),
                after,
            }),
            Err(e) => Err(e),
        }
    }

    /// Adds QEMU's own error output (and whether it exited) to an error.
    fn explain(&mut self, e: OracleError) -> OracleError {
        let exited = match self.child.try_wait() {
            Ok(Some(status)) => Some(status),
            _ => None,
        };
        match exited {
            Some(status) => {
                // Give the stderr thread a moment to collect the last words.
                thread::sleep(Duration::from_millis(50));
                let stderr = self
                    .stderr
                    .lock()
                    .map(|s| String::from_utf8_lossy(&s).into_owned())
                    .unwrap_or_default();
                OracleError::Qemu {
                    what: format!("QEMU exited ({status}) after: {e}"),
                    detail: stderr.lines().take(20).collect::<Vec<_>>().join("\n"),
                }
            }
            None => e,
        }
    }
}

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.gdb.kill();
        // Closing the watchdog's stdin kills QEMU; the shell then exits.
        drop(self.watchdog.take());
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            match self.child.try_wait() {
                Ok(Some(_)) | Err(_) => return,
                Ok(None) if Instant::now() < deadline => thread::sleep(Duration::from_millis(5)),
                Ok(None) => {
                    let _ = self.child.kill();
                    let _ = self.child.wait();
                    return;
                }
            }
        }
    }
}

/// Waits for QEMU to connect, giving up when the shell (and so QEMU) exits.
fn accept(listener: &TcpListener, child: &mut Child) -> Result<std::net::TcpStream, OracleError> {
    listener
        .set_nonblocking(true)
        .map_err(|source| OracleError::Io {
            what: "making the listener non-blocking".into(),
            source,
        })?;
    let deadline = Instant::now() + START_TIMEOUT;
    loop {
        match listener.accept() {
            Ok((stream, _)) => {
                stream
                    .set_nonblocking(false)
                    .map_err(|source| OracleError::Io {
                        what: "making the GDB connection blocking".into(),
                        source,
                    })?;
                return Ok(stream);
            }
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => {}
            Err(source) => {
                return Err(OracleError::Io {
                    what: "accepting QEMU's GDB connection".into(),
                    source,
                })
            }
        }
        if let Ok(Some(status)) = child.try_wait() {
            return Err(OracleError::Qemu {
                what: "starting".into(),
                detail: format!("QEMU exited ({status}) before connecting"),
            });
        }
        if Instant::now() >= deadline {
            return Err(OracleError::Timeout {
                what: "QEMU to connect to the GDB listener".into(),
                after: START_TIMEOUT,
            });
        }
        thread::sleep(Duration::from_millis(2));
    }
}

fn with_stderr(e: OracleError, stderr: &Arc<Mutex<Vec<u8>>>) -> OracleError {
    thread::sleep(Duration::from_millis(50));
    let text = stderr
        .lock()
        .map(|s| String::from_utf8_lossy(&s).into_owned())
        .unwrap_or_default();
    if text.trim().is_empty() {
        e
    } else {
        OracleError::Qemu {
            what: e.to_string(),
            detail: text.lines().take(20).collect::<Vec<_>>().join("\n"),
        }
    }
}

/// xPSR as written to QEMU: the Thumb bit set, the exception number left alone (the stub
/// ignores it).
fn thumb_xpsr(xpsr: u32) -> u32 {
    xpsr | 1 << 24
}

fn window_of(block: &Block) -> Result<Vec<u8>, OracleError> {
    if block.data.len() != DATA_LEN as usize {
        return Err(OracleError::Setup(format!(
            "a block's data window must be {DATA_LEN} bytes, not {}",
            block.data.len()
        )));
    }
    Ok(block.data.clone())
}

fn fault_from(word: &dyn Fn(usize) -> u32) -> Outcome {
    Outcome::Fault {
        pc: word(F_PC),
        exception: word(F_IPSR),
        cfsr: word(F_CFSR),
        hfsr: word(F_HFSR),
        mmfar: word(F_MMFAR),
        bfar: word(F_BFAR),
    }
}

/// The bytes of a sequence of instructions.
pub fn code_bytes(insns: &[Insn]) -> Vec<u8> {
    insns.iter().flat_map(|i| i.bytes()).collect()
}

/// `MOVW Rd, #lo; MOVT Rd, #hi`.
fn load_const(rd: u8, value: u32) -> [Insn; 2] {
    [
        thumb::movw_movt(false, rd, value as u16),
        thumb::movw_movt(true, rd, (value >> 16) as u16),
    ]
}

/// Branch (B T4) from `from` to `to`.
fn branch(from: u32, to: u32) -> Insn {
    thumb::b_t4(to.wrapping_sub(from.wrapping_add(4)) as i32)
}

/// Enables the FPU and the configurable fault handlers, then stops.
fn setup_routine() -> Vec<Insn> {
    let mut code = Vec::new();
    // CPACR (0xE000ED88) = CP10, CP11 full access.
    code.extend(load_const(0, 0xe000_ed88));
    code.extend(load_const(1, 0x00f0_0000));
    code.push(thumb::ldst_imm16(0, 1, 0, 0)); // str r1, [r0]
                                              // SHCSR (0xE000ED24) = MEMFAULTENA | BUSFAULTENA | USGFAULTENA.
    code.extend(load_const(0, 0xe000_ed24));
    code.extend(load_const(1, 0x0007_0000));
    code.push(thumb::ldst_imm16(0, 1, 0, 0)); // str r1, [r0]
    code.push(thumb::dsb());
    code.push(thumb::isb());
    let at = SETUP + code.iter().map(|i| i.len() as u32).sum::<u32>();
    code.push(branch(at, STOP));
    code
}

/// Records the fault (IPSR, stacked PC, CFSR, HFSR, MMFAR, BFAR and the status word in the
/// dump), then stops.
fn fault_stub() -> Vec<Insn> {
    let mut code = Vec::new();
    code.extend(load_const(0, DUMP + 4 * F_IPSR as u32));
    code.push(thumb::mrs(1, 5)); // mrs r1, ipsr
    code.push(thumb::ldst_sp16(true, 2, 6)); // ldr r2, [sp, #24]: the stacked PC
    code.extend(load_const(4, 0xe000_ed28));
    code.push(thumb::ldst_imm16(1, 3, 4, 0)); // ldr r3, [r4]: CFSR
    code.push(thumb::ldst_imm16(1, 5, 4, 1)); // ldr r5, [r4, #4]: HFSR
    code.push(thumb::ldst_imm16(1, 6, 4, 3)); // ldr r6, [r4, #12]: MMFAR
    code.push(thumb::ldst_imm16(1, 7, 4, 4)); // ldr r7, [r4, #16]: BFAR
    code.push(thumb::ldm_stm16(false, 0, 0b1110_1110)); // stmia r0!, {r1-r3, r5-r7}
    code.extend(load_const(0, DUMP));
    code.extend(load_const(1, STATUS_FAULT));
    code.push(thumb::ldst_imm16(0, 1, 0, 0)); // str r1, [r0]
    let at = FAULT_STUB + code.iter().map(|i| i.len() as u32).sum::<u32>();
    code.push(branch(at, STOP));
    code
}

/// The prologue at [`PROLOGUE`], ending at [`CODE_BASE`]: r0 holds the starting FPSCR.
fn prologue() -> Vec<Insn> {
    let [movw, movt] = load_const(0, POOL);
    let code = vec![
        thumb::vmsr(0),                                         // vmsr fpscr, r0
        thumb::clrex(),                                         // the local monitor: Open Access
        movw,                                                   // movw r0, #:lower16:POOL
        movt,                                                   // movt r0, #:upper16:POOL
        thumb::vldm_vstm(true, false, false, 0, 0, 32),         // vldmia r0, {s0-s31}
        thumb::ldst_imm12(thumb::Width::Word, true, 0, 0, 128), // ldr.w r0, [r0, #128]
    ];
    debug_assert_eq!(
        code.iter().map(|i| i.len() as u32).sum::<u32>(),
        PROLOGUE_LEN
    );
    code
}

/// The epilogue at the block's end `end`: saves every register to the dump, then stops.
///
/// r0 must be parked before anything can be stored (a store needs a base register). No
/// 32-bit special register takes it whole (PSP's bits 1:0 are zero), so bits 31:2 go to
/// PSP, bit 0 to PRIMASK and bit 1 (after a flagless ROR) to FAULTMASK; both masks are
/// cleared again (CPSIE) before the stop. Nothing before the `MRS xPSR` sets flags.
fn epilogue(end: u32) -> Vec<Insn> {
    let mut code = vec![
        thumb::msr(9, 2, 0),                         // msr psp, r0: r0[31:2]
        thumb::msr(16, 2, 0),                        // msr primask, r0: r0[0]
        thumb::dp_shifted(2, false, 0, 15, 0, 3, 1), // ror.w r0, r0, #1
        thumb::msr(19, 2, 0),                        // msr faultmask, r0: r0[1]
    ];
    code.extend(load_const(0, DUMP + 4 * D_R1 as u32));
    code.push(thumb::ldm_stm32(false, false, 0, true, 0x5ffe)); // stmia r0!, {r1-r12, lr}
    code.push(thumb::mrs(3, 3)); // mrs r3, xpsr (APSR and IPSR)
    code.push(thumb::mrs(1, 9)); // mrs r1, psp
    code.push(thumb::mrs(2, 16)); // mrs r2, primask
    code.push(thumb::dp_shifted(2, false, 1, 1, 2, 0, 0)); // orr.w r1, r1, r2
    code.push(thumb::mrs(2, 19)); // mrs r2, faultmask
    code.push(thumb::dp_shifted(2, false, 1, 1, 2, 0, 1)); // orr.w r1, r1, r2, lsl #1
    code.push(Insn::Narrow(0xb663)); // cpsie if
    code.push(thumb::mov_reg_t1(2, 13)); // mov r2, sp
    code.push(thumb::ldm_stm16(false, 0, 0b1110)); // stmia r0!, {r1-r3}: r0, SP, xPSR
    code.push(thumb::vldm_vstm(false, false, true, 0, 0, 32)); // vstmia r0!, {s0-s31}
    code.push(thumb::vmrs(1)); // vmrs r1, fpscr
    code.push(thumb::ldst_imm16(0, 1, 0, 0)); // str r1, [r0]
    code.extend(load_const(0, DUMP));
    code.extend(load_const(1, STATUS_FINISHED));
    code.push(thumb::ldst_imm16(0, 1, 0, 0)); // str r1, [r0]
    let at = end + code.iter().map(|i| i.len() as u32).sum::<u32>();
    code.push(branch(at, STOP));
    code
}
