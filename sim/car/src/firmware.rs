//! ECUs that run as their firmware: the release ELF (the bytes `cargo fw -p ecu-<ecu>` flashes)
//! with the bootloader, on AutoPlug's emulated STM32F446 (`autoplug-mcu`). Such an ECU
//! meets the car as a board on the bench would: the vehicle model puts volts on its ADC
//! pins and levels on its switch inputs, reads its PWM duties and output levels, all by
//! the pins its crate declares (`ecu_<name>::pins`, which the firmware's board module
//! takes from the HAL), and its bxCAN is a node of the car's bit-timed bus.

use std::collections::VecDeque;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

use autoplug_can::{ecu_name, parse_ecu, Node, ECUS, ECU_NAME_LIST};
use autoplug_ecus::firmware_name;
use autoplug_mcu::chip::rcc::ResetCause;
use autoplug_mcu::gdb::{GdbServer, GdbStatus};
use autoplug_mcu::mcu::{Mcu, Stop};
use autoplug_mcu::node::{run_together, BusNode};
use autoplug_mcu::programming::FlashContents;
use autoplug_mcu::rtt::{LogLine, RttLog};
use autoplug_virtual_bus::{NodeId, VirtualBus};

/// Where the firmware the car runs comes from when none is named: the firmware build of
/// `cargo build --profile firmware --target thumbv7em-none-eabihf` ([`FIRMWARE_TARGET`]).
pub const DEFAULT_FIRMWARE_DIR: &str = "target/thumbv7em-none-eabihf/firmware";

/// The log lines the car keeps for its caller (the oldest go first beyond this).
const LOG_CAPACITY: usize = 100_000;

/// Which ECUs run as firmware, and where their ELF files are.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FirmwareChoice {
    /// The ECUs, in the catalogue's order.
    pub ecus: Vec<Node>,
    /// The directory with `boot` and `<ecu>-fw` (a cargo profile's directory).
    pub dir: PathBuf,
    /// ECUs whose debug port is a GDB server, and its address ([`FirmwareChoice::debug`]).
    pub gdb: Vec<(Node, SocketAddr)>,
    /// Whether the car waits at power-on for every debugger to attach (a run under a
    /// debugger starting at the reset vector, as QEMU's `-S`); otherwise it runs, and a
    /// debugger that attaches later halts it where it is (the dashboard: the page comes up
    /// first; `monitor reset halt` starts over).
    pub hold_for_debugger: bool,
}

impl FirmwareChoice {
    /// `all`, or ECU names separated by commas (`cruise,abs`), from `dir`.
    pub fn parse(list: &str, dir: &Path) -> Result<Self, String> {
        let mut ecus = Vec::new();
        if list.trim().eq_ignore_ascii_case("all") {
            ecus.extend(ECUS);
        } else {
            for name in list.split(',') {
                let node = parse_ecu(name).ok_or_else(|| {
                    format!(
                        "--firmware: no ECU '{}' (all, or some of: {ECU_NAME_LIST})",
                        name.trim()
                    )
                })?;
                if ecus.contains(&node) {
                    return Err(format!("--firmware: {} named twice", ecu_name(node)));
                }
                ecus.push(node);
            }
        }
        ecus.sort_by_key(|n| ECUS.iter().position(|e| e == n));
        Ok(Self {
            ecus,
            dir: dir.to_path_buf(),
            gdb: Vec::new(),
            hold_for_debugger: true,
        })
    }

    /// Adds GDB servers: `ECU[=ADDR]` items (the `--gdb` values), each ECU one that runs
    /// as firmware; without an address, 127.0.0.1:3333 for the first and the next ports
    /// for the others. Loopback addresses only.
    pub fn debug(mut self, items: &[String]) -> Result<Self, String> {
        let mut next_port = 3333u16;
        for item in items {
            let (name, address) = match item.split_once('=') {
                Some((name, address)) => (name, Some(address)),
                None => (item.as_str(), None),
            };
            let node = parse_ecu(name).ok_or_else(|| {
                format!(
                    "--gdb {item}: no ECU '{}' (one of: {ECU_NAME_LIST})",
                    name.trim()
                )
            })?;
            if !self.runs(node) {
                return Err(format!(
                    "--gdb {item}: {} does not run as firmware (add it to --firmware)",
                    ecu_name(node)
                ));
            }
            if self.gdb.iter().any(|(n, _)| *n == node) {
                return Err(format!("--gdb: {} named twice", ecu_name(node)));
            }
            let address = match address {
                Some(text) => autoplug_mcu::gdb::parse_address(text)?,
                None => {
                    let taken = |port: u16| self.gdb.iter().any(|(_, a)| a.port() == port);
                    while taken(next_port) {
                        next_port += 1;
                    }
                    SocketAddr::from(([127, 0, 0, 1], next_port))
                }
            };
            if self.gdb.iter().any(|(_, a)| *a == address) {
                return Err(format!("--gdb {item}: {address} is given twice"));
            }
            self.gdb.push((node, address));
        }
        Ok(self)
    }

    /// The ELF file of `node`'s firmware.
    pub fn elf(&self, node: Node) -> PathBuf {
        self.dir.join(format!("{}-fw", firmware_name(node)))
    }

    /// Whether `node` runs as firmware.
    pub fn runs(&self, node: Node) -> bool {
        self.ecus.contains(&node)
    }

    /// The ELF files the choice needs that its directory lacks, each with the cargo
    /// package that builds it: every ECU's firmware, and the bootloader (`autoplug-boot`).
    pub fn missing(&self) -> Vec<(String, PathBuf)> {
        let mut missing: Vec<(String, PathBuf)> = self
            .ecus
            .iter()
            .map(|&ecu| {
                let name = firmware_name(ecu);
                (format!("ecu-{name}"), self.dir.join(format!("{name}-fw")))
            })
            .filter(|(_, file)| !file.is_file())
            .collect();
        if !self.dir.join("boot").is_file() {
            missing.push(("autoplug-boot".into(), self.dir.join("boot")));
        }
        missing
    }

    /// The cargo commands (arguments after `cargo`) that build `missing`: the firmware in
    /// one build, the bootloader in one of its own (its HAL features differ from the
    /// firmware's, and one build would unify them).
    pub fn build_commands(missing: &[(String, PathBuf)]) -> Vec<Vec<String>> {
        let base = [
            "build",
            "--profile",
            FIRMWARE_PROFILE,
            "--target",
            FIRMWARE_TARGET,
        ]
        .map(String::from);
        let (boot, firmware): (Vec<&String>, Vec<&String>) = missing
            .iter()
            .map(|(package, _)| package)
            .partition(|p| *p == "autoplug-boot");
        [firmware, boot]
            .into_iter()
            .filter(|packages| !packages.is_empty())
            .map(|packages| {
                let mut args = base.to_vec();
                for p in packages {
                    args.extend(["-p".to_string(), p.clone()]);
                }
                args
            })
            .collect()
    }

    /// Nothing when every file is there; else an error naming every missing file at once
    /// and the commands that build them all.
    pub fn check_files(&self) -> Result<(), String> {
        let missing = self.missing();
        if missing.is_empty() {
            return Ok(());
        }
        let files: Vec<String> = missing
            .iter()
            .map(|(_, f)| f.display().to_string())
            .collect();
        let commands: Vec<String> = Self::build_commands(&missing)
            .iter()
            .map(|args| format!("cargo {}", args.join(" ")))
            .collect();
        Err(format!(
            "{} firmware file(s) missing: {}; build them in the AutoPlug checkout: {}",
            files.len(),
            files.join(", "),
            commands.join(" && ")
        ))
    }

    /// Builds what the choice lacks with `cargo` in the workspace at `root` (cargo's output
    /// on this program's standard error); the packages built, none if nothing was missing.
    pub fn build_missing(&self, root: &Path, cargo: &Path) -> Result<Vec<String>, String> {
        let missing = self.missing();
        for args in Self::build_commands(&missing) {
            let shown = format!("{} {}", cargo.display(), args.join(" "));
            let status = std::process::Command::new(cargo)
                .args(&args)
                .current_dir(root)
                .stdin(std::process::Stdio::null())
                .stdout(std::io::stderr())
                .status()
                .map_err(|e| format!("cannot run {shown}: {e}"))?;
            if !status.success() {
                return Err(format!("{shown} failed ({status})"));
            }
        }
        self.check_files()?;
        Ok(missing.into_iter().map(|(package, _)| package).collect())
    }
}

/// The firmware's target: the Nucleo-F446RE's Cortex-M4F.
pub const FIRMWARE_TARGET: &str = "thumbv7em-none-eabihf";

/// The cargo profile the firmware is built in (the workspace's `Cargo.toml`: fat LTO,
/// optimised for size; the host programs' `release` is built for build time).
pub const FIRMWARE_PROFILE: &str = "firmware";

/// The AutoPlug cargo workspace `dir` is in (the folder with its `Cargo.toml`, the
/// bootloader's and the emulator's crates), if it is in one: there `--firmware` can build
/// what it needs.
pub fn workspace_root(dir: &Path) -> Option<PathBuf> {
    dir.ancestors()
        .find(|d| {
            d.join("Cargo.toml").is_file()
                && d.join("boot/Cargo.toml").is_file()
                && d.join("sim/mcu/Cargo.toml").is_file()
        })
        .map(Path::to_path_buf)
}

/// The cargo to build with: the one running this program, else `cargo` on the path.
pub fn cargo() -> PathBuf {
    std::env::var_os("CARGO").map_or_else(|| PathBuf::from("cargo"), PathBuf::from)
}

/// A line of an emulated ECU's defmt log.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FirmwareLogLine {
    /// When the car read it from the RTT buffer, µs of the scenario's time (negative in
    /// the warm-up before it).
    pub t_us: i64,
    /// The ECU's short name.
    pub ecu: &'static str,
    /// The level (`INFO`, `WARN`...), when the frame has one.
    pub level: Option<String>,
    /// The line as `defmt-print` shows it (the firmware's own timestamp first).
    pub text: String,
}

/// As the car's `firmware.log` and terminal show it: the scenario's time, the ECU, the
/// line.
impl std::fmt::Display for FirmwareLogLine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:>11.6} {:<8} {}",
            self.t_us as f64 * 1e-6,
            self.ecu,
            self.text
        )
    }
}

/// An emulated ECU that stopped: its MCU halted, locked up or ended, and left the bus.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FirmwareStop {
    /// The ECU.
    pub node: Node,
    /// When, µs of the scenario's time (negative in the warm-up).
    pub t_us: i64,
    /// Why, with the registers that say where.
    pub reason: String,
    /// Its last log lines.
    pub last_lines: Vec<String>,
}

/// One ECU on its emulated MCU.
pub(crate) struct EmulatedEcu {
    pub(crate) node: Node,
    /// Its RTT logs, shared with its debug port's halt.
    logs: Arc<Mutex<LogTap>>,
    /// Its last lines, for a stop's report.
    recent: VecDeque<String>,
    /// HardFaults already reported.
    faults_seen: usize,
    /// Lockups already reported.
    lockups_seen: usize,
    /// Watchdog resets already reported.
    resets_seen: usize,
    /// The set speed the cruise firmware latched, as its log line "cruise: engaged at X
    /// km/h" says: the firmware publishes it nowhere else (the DBC has no signal for it).
    logged_set_speed_kmh: Option<f32>,
}

/// An ECU's RTT logs and the lines its debug port's halt read from them, as probe-rs
/// reads RTT when the core halts: the lines logged before a breakpoint show while it
/// holds, though the car's own thread stands still.
struct LogTap {
    rtt: Vec<RttLog>,
    /// Read at a halt (and shown then), with the time: for the car's next read.
    read_at_halt: Vec<(i64, LogLine)>,
}

/// The emulated ECUs of a car and their bus nodes (kept apart: the bus runs them as a
/// slice).
pub(crate) struct Firmware {
    ecus: Vec<EmulatedEcu>,
    nodes: Vec<BusNode>,
    log: LogBook,
    stops: Vec<FirmwareStop>,
    /// The GDB servers' statuses, by ECU.
    debugged: DebugPorts,
}

/// The GDB servers' statuses, by the ECU each debugs.
pub type DebugPorts = Vec<(Node, Arc<GdbStatus>)>;

/// Puts a GDB server on the debug port of each of `loaded` that `choice` names, and waits
/// for their debuggers when the choice holds for them (a run under a debugger then starts
/// at the reset vector, as QEMU's `-S`). The servers' statuses.
pub fn serve_debuggers(
    choice: &FirmwareChoice,
    loaded: &mut [(Node, Mcu, Vec<RttLog>)],
) -> Result<DebugPorts, String> {
    let mut statuses = Vec::new();
    let mut servers = Vec::new();
    for &(node, address) in &choice.gdb {
        let server = GdbServer::bind(ecu_name(node), address)?;
        eprintln!(
            "{}: GDB server on {}: gdb-multiarch {} -ex 'target extended-remote {}'",
            ecu_name(node),
            server.local_addr(),
            choice.elf(node).display(),
            server.local_addr()
        );
        statuses.push((node, server.status()));
        servers.push((node, server));
    }
    for (node, server) in servers {
        if choice.hold_for_debugger {
            eprintln!(
                "{}: waiting for the debugger (the car is held at power-on)",
                ecu_name(node)
            );
            server.wait_for_client(None);
        }
        if let Some((_, mcu, _)) = loaded.iter_mut().find(|(n, _, _)| *n == node) {
            mcu.debugger = Some(Box::new(server));
        }
    }
    Ok(statuses)
}

/// The unique ID of `node`'s board (the F446's 96-bit UID: lot, wafer, position).
pub fn board_uid(node: Node) -> [u32; 3] {
    let index = ECUS.iter().position(|n| *n == node).unwrap_or(0) as u32;
    [0x0031_0042 + index, 0x3433_5107, 0x3236_3731]
}

/// The bootloader and an ECU's firmware programmed into a fresh flash, as a programmer
/// writes them (the flash's interrupted operations seeded from `seed`), started once as
/// at the end of the line, and powered on again; its logs' decoders.
pub fn load(node: Node, dir: &Path, seed: u64) -> Result<(Mcu, Vec<RttLog>), String> {
    let mut flash = FlashContents::erased();
    let mut logs = Vec::new();
    let app = format!("{}-fw", firmware_name(node));
    for file in ["boot", app.as_str()] {
        let path = dir.join(file);
        let name = path.display().to_string();
        let bytes = std::fs::read(&path).map_err(|e| {
            format!(
                "{name}: {e} (build the firmware first: cargo build --profile firmware --target thumbv7em-none-eabihf -p {})",
                if file == "boot" {
                    "autoplug-boot".to_string()
                } else {
                    format!("ecu-{}", firmware_name(node))
                }
            )
        })?;
        flash
            .program_elf(&name, &bytes)
            .map_err(|e| e.to_string())?;
        if let Some(log) = RttLog::for_elf(&name, &bytes)? {
            logs.push(log);
        }
    }
    let index = ECUS.iter().position(|n| *n == node).unwrap_or(0) as u32;
    let uid = board_uid(node);
    let name = ecu_name(node);
    let mut first = Mcu::power_on(flash.to_sim_flash(seed ^ u64::from(index)), uid)
        .map_err(|e| format!("{name}: {e}"))?;
    // The board's first start, as at the end of the line: it formats the A/B record (a
    // sector erase, about 0.5 s) and reaches its control loop, then is powered off. The
    // car then starts a board that has run before, in a few milliseconds. A firmware that
    // faults, hangs or stops here does the same in the car, which reports it there and
    // runs on without it.
    let _ = first.run_until(FIRST_START_NS);
    let mcu = Mcu::power_on(first.chip.flash, uid).map_err(|e| format!("{name}: {e}"))?;
    Ok((mcu, logs))
}

/// [`load`] for each of `nodes`, on threads of their own (each is independent: its image's
/// symbols and debug information, its first start), in `nodes`' order.
pub fn load_all(
    nodes: &[Node],
    dir: &Path,
    seed: u64,
) -> Result<Vec<(Node, Mcu, Vec<RttLog>)>, String> {
    std::thread::scope(|scope| {
        let loads: Vec<_> = nodes
            .iter()
            .map(|&node| scope.spawn(move || load(node, dir, seed).map(|(m, l)| (node, m, l))))
            .collect();
        loads
            .into_iter()
            .map(|load| {
                load.join()
                    .unwrap_or_else(|_| Err("loading a firmware image panicked".into()))
            })
            .collect()
    })
}

/// How long a board's first start runs before it is powered off: past the A/B record's
/// sector erase and into the control loop.
const FIRST_START_NS: u64 = 800_000_000;

impl Firmware {
    pub(crate) fn new() -> Self {
        Self {
            ecus: Vec::new(),
            nodes: Vec::new(),
            log: LogBook::default(),
            stops: Vec::new(),
            debugged: Vec::new(),
        }
    }

    /// Keeps the GDB servers' statuses.
    pub(crate) fn set_debugged(&mut self, statuses: DebugPorts) {
        self.debugged = statuses;
    }

    /// The GDB server's status of `node`'s debug port, if it has one.
    pub(crate) fn debug_status(&self, node: Node) -> Option<Arc<GdbStatus>> {
        self.debugged
            .iter()
            .find(|(n, _)| *n == node)
            .map(|(_, s)| Arc::clone(s))
    }

    /// Every GDB server's status, by ECU.
    pub(crate) fn debug_ports(&self) -> DebugPorts {
        self.debugged.clone()
    }

    /// The wall-clock time debuggers held the car halted, all together.
    pub(crate) fn debugger_halted_for(&self) -> std::time::Duration {
        self.debugged.iter().map(|(_, s)| s.halted_for()).sum()
    }

    /// Puts an ECU's MCU on the bus as `node`'s board.
    pub(crate) fn attach(
        &mut self,
        bus: &mut VirtualBus,
        node: Node,
        mcu: Mcu,
        logs: Vec<RttLog>,
    ) -> NodeId {
        let logs = Arc::new(Mutex::new(LogTap {
            rtt: logs,
            read_at_halt: Vec::new(),
        }));
        let mut mcu = mcu;
        if mcu.debugger.is_some() {
            let (tap, live) = (Arc::clone(&logs), Arc::clone(&self.log.live));
            mcu.on_debug_halt = Some(Box::new(move |mcu: &mut Mcu| {
                let Ok(mut tap) = tap.lock() else {
                    return;
                };
                let t_us = scenario_us(mcu.now_ns() / 1000, live.start_us.load(Ordering::Relaxed));
                let mut read = Vec::new();
                for rtt in &mut tap.rtt {
                    read.extend(rtt.poll(mcu));
                }
                for line in read {
                    live.show(&FirmwareLogLine {
                        t_us,
                        ecu: ecu_name(node),
                        level: line.level.clone(),
                        text: line.text.clone(),
                    });
                    tap.read_at_halt.push((t_us, line));
                }
            }));
        }
        let bus_node = BusNode::attach(bus, node.name(), mcu);
        let id = bus_node.node;
        self.nodes.push(bus_node);
        self.ecus.push(EmulatedEcu {
            node,
            logs,
            recent: VecDeque::new(),
            faults_seen: 0,
            lockups_seen: 0,
            resets_seen: 0,
            logged_set_speed_kmh: None,
        });
        id
    }

    /// Whether any ECU runs as firmware.
    pub(crate) fn is_empty(&self) -> bool {
        self.ecus.is_empty() && self.stops.is_empty()
    }

    /// The MCU of `node`'s board, while it runs.
    pub(crate) fn mcu(&mut self, node: Node) -> Option<&mut Mcu> {
        let i = self.ecus.iter().position(|e| e.node == node)?;
        Some(&mut self.nodes[i].mcu)
    }

    /// Runs the bus and the MCUs to `until_ns`. An MCU that stops leaves the bus (its node
    /// falls silent) and is reported; the others run on.
    pub(crate) fn run(&mut self, bus: &mut VirtualBus, until_ns: u64, start_us: u64) {
        self.log.live.start_us.store(start_us, Ordering::Relaxed);
        while let Err((i, stop)) = run_together(bus, &mut self.nodes, until_ns) {
            let node = self.nodes.remove(i);
            let mut ecu = self.ecus.remove(i);
            let mut chip = node.mcu.chip;
            let t_us = scenario_us(bus.now_ns() / 1000, start_us);
            Self::read_log(&mut ecu, &mut chip, t_us, &mut self.log);
            bus.set_silenced(node.node, true);
            let mut reason = stop.to_string();
            if let Some(fault) = node.mcu.faults.last() {
                reason.push_str(&format!(
                    "; after a HardFault at PC {:#010x} (LR {:#010x}, CFSR {:#010x}, HFSR {:#010x})",
                    fault.pc, fault.lr, fault.cfsr, fault.hfsr
                ));
            }
            self.stops.push(FirmwareStop {
                node: ecu.node,
                t_us,
                reason,
                last_lines: ecu.recent.into_iter().collect(),
            });
        }
    }

    /// Reads what each firmware logged since the last call, and reports HardFaults it
    /// took (the firmware's fault handler logs and resets; the car runs on).
    pub(crate) fn poll_logs(&mut self, bus_us: u64, start_us: u64) {
        let t_us = scenario_us(bus_us, start_us);
        for (ecu, node) in self.ecus.iter_mut().zip(&mut self.nodes) {
            Self::read_log(ecu, &mut node.mcu, t_us, &mut self.log);
            for fault in &node.mcu.faults[ecu.faults_seen..] {
                let text = format!(
                    "emulator: HardFault at PC {:#010x}, LR {:#010x}, CFSR {:#010x}, HFSR {:#010x}, BFAR {:#010x} ({:?})",
                    fault.pc, fault.lr, fault.cfsr, fault.hfsr, fault.bfar, fault.fault
                );
                emulator_error(&mut self.log, t_us, ecu.node, text);
            }
            ecu.faults_seen = node.mcu.faults.len();
            // A lockup with the watchdog running: the chip waits for its reset, as a board
            // does (the reset follows as a watchdog reset, below).
            for (at_ns, halt) in &node.mcu.lockups[ecu.lockups_seen..] {
                emulator_error(
                    &mut self.log,
                    scenario_us(at_ns / 1000, start_us),
                    ecu.node,
                    format!(
                        "emulator: {}; the independent watchdog (IWDG) runs, so its reset will end the lockup",
                        Stop::Halted(halt.clone())
                    ),
                );
            }
            ecu.lockups_seen = node.mcu.lockups.len();
            // A watchdog reset says the firmware stopped feeding it: a hang, reported
            // like a fault (the firmware's own log says it only after the restart).
            for (at_ns, cause) in &node.mcu.resets[ecu.resets_seen..] {
                if *cause == ResetCause::Watchdog {
                    emulator_error(
                        &mut self.log,
                        scenario_us(at_ns / 1000, start_us),
                        ecu.node,
                        "emulator: reset by the independent watchdog (IWDG): the firmware stopped feeding it".into(),
                    );
                }
            }
            ecu.resets_seen = node.mcu.resets.len();
        }
    }

    fn read_log(
        ecu: &mut EmulatedEcu,
        chip: &mut impl autoplug_mcu::rtt::HostMemory,
        t_us: i64,
        log: &mut LogBook,
    ) {
        let Ok(mut tap) = ecu.logs.lock() else {
            return;
        };
        // What a debugger's halt read first (shown then), then what came since.
        let mut lines: Vec<(i64, LogLine, bool)> = std::mem::take(&mut tap.read_at_halt)
            .into_iter()
            .map(|(t_us, line)| (t_us, line, true))
            .collect();
        for rtt in &mut tap.rtt {
            lines.extend(rtt.poll(chip).into_iter().map(|line| (t_us, line, false)));
        }
        drop(tap);
        for (t_us, line, shown) in lines {
            if ecu.recent.len() == 20 {
                ecu.recent.pop_front();
            }
            ecu.recent.push_back(line.text.clone());
            if ecu.node == Node::Cruise {
                if let Some(kmh) = logged_set_speed(&line.text) {
                    ecu.logged_set_speed_kmh = Some(kmh);
                }
            }
            let line = FirmwareLogLine {
                t_us,
                ecu: ecu_name(ecu.node),
                level: line.level,
                text: line.text,
            };
            if shown {
                log.keep(line);
            } else {
                log.push(line);
            }
        }
    }

    /// Shows each log line as it is read (and as a debugger halts an ECU) from now on:
    /// set before anything runs.
    pub(crate) fn show_log(&mut self, sink: LiveLogSink) {
        if let Ok(mut show) = self.log.live.show.lock() {
            *show = Some(sink);
        }
    }

    /// The log lines since the last call.
    pub(crate) fn take_log(&mut self) -> Vec<FirmwareLogLine> {
        self.log.lines.drain(..).collect()
    }

    /// Lines dropped because nobody took them in time.
    pub(crate) fn dropped_lines(&self) -> u64 {
        self.log.dropped
    }

    /// The ECUs that stopped.
    pub(crate) fn stops(&self) -> &[FirmwareStop] {
        &self.stops
    }

    /// The set speed the emulated cruise ECU logged when it last engaged.
    pub(crate) fn cruise_set_speed_kmh(&self) -> Option<f32> {
        self.ecus
            .iter()
            .find(|e| e.node == Node::Cruise)
            .and_then(|e| e.logged_set_speed_kmh)
    }

    /// Instructions the emulated cores have run.
    pub(crate) fn instructions(&self) -> u64 {
        self.nodes.iter().map(|n| n.mcu.cpu.instructions()).sum()
    }
}

/// The speed of a cruise log line `… cruise: engaged at 90.5 km/h …` (ecu-cruise's
/// `engage`), as defmt prints it.
fn logged_set_speed(text: &str) -> Option<f32> {
    let (_, rest) = text.split_once("cruise: engaged at ")?;
    let (number, _) = rest.split_once(" km/h")?;
    number.trim().parse::<f32>().ok().filter(|v| v.is_finite())
}

/// A time on the bus's clock as the scenario's (negative before it began).
fn scenario_us(bus_us: u64, start_us: u64) -> i64 {
    bus_us as i64 - start_us as i64
}

/// What the emulator itself reports about an ECU's chip (a fault, a lockup, a watchdog
/// reset), as an error line of that ECU's log.
fn emulator_error(log: &mut LogBook, t_us: i64, node: Node, text: String) {
    log.push(FirmwareLogLine {
        t_us,
        ecu: ecu_name(node),
        level: Some("ERROR".into()),
        text,
    });
}

/// The lines the car read from its ECUs, kept for its caller, and shown as they come by
/// whoever watches live.
#[derive(Default)]
struct LogBook {
    lines: VecDeque<FirmwareLogLine>,
    /// Lines dropped because nobody took them in time.
    dropped: u64,
    live: Arc<LiveLog>,
}

impl LogBook {
    /// Shows a line live and keeps it.
    fn push(&mut self, line: FirmwareLogLine) {
        self.live.show(&line);
        self.keep(line);
    }

    /// Keeps a line (shown already).
    fn keep(&mut self, line: FirmwareLogLine) {
        if self.lines.len() == LOG_CAPACITY {
            self.lines.pop_front();
            self.dropped += 1;
        }
        self.lines.push_back(line);
    }
}

/// What shows the log live, as the car reads it and as a debugger halts an ECU (when the
/// car's own thread stands still); and the car's start, for the halt's time stamps.
#[derive(Default)]
pub(crate) struct LiveLog {
    show: Mutex<Option<LiveLogSink>>,
    start_us: AtomicU64,
}

/// Shows a log line as it is read (`VirtualCar::with_firmware_showing_log`).
pub type LiveLogSink = Box<dyn FnMut(&FirmwareLogLine) + Send>;

impl LiveLog {
    fn show(&self, line: &FirmwareLogLine) {
        if let Ok(mut show) = self.show.lock() {
            if let Some(show) = show.as_mut() {
                show(line);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_choice_is_all_or_named_ecus_in_the_catalogues_order() {
        let dir = Path::new("fw");
        assert_eq!(FirmwareChoice::parse("all", dir).unwrap().ecus, ECUS);
        let choice = FirmwareChoice::parse("abs, Cruise,trans", dir).unwrap();
        assert_eq!(choice.ecus, [Node::Transmission, Node::Cruise, Node::ABS]);
        assert!(choice.runs(Node::ABS) && !choice.runs(Node::Engine));
        let twice = FirmwareChoice::parse("cruise,cruise", dir).unwrap_err();
        assert_eq!(twice, "--firmware: cruise named twice");
        let unknown = FirmwareChoice::parse("cruise,brakes", dir).unwrap_err();
        assert!(
            unknown.starts_with("--firmware: no ECU 'brakes' (all, or some of: engine"),
            "{unknown}"
        );
    }

    #[test]
    fn gdb_ports_go_to_ecus_that_run_as_firmware_on_loopback() {
        let dir = Path::new("fw");
        let choice = FirmwareChoice::parse("cruise,abs", dir).unwrap();
        let debugged = choice
            .clone()
            .debug(&["cruise".into(), "abs=127.0.0.1:4444".into()])
            .unwrap();
        assert_eq!(
            debugged.gdb,
            [
                (Node::Cruise, "127.0.0.1:3333".parse().unwrap()),
                (Node::ABS, "127.0.0.1:4444".parse().unwrap())
            ]
        );
        let not_firmware = choice.clone().debug(&["engine".into()]).unwrap_err();
        assert!(
            not_firmware.contains("engine does not run as firmware"),
            "{not_firmware}"
        );
        let remote = choice
            .clone()
            .debug(&["cruise=0.0.0.0:3333".into()])
            .unwrap_err();
        assert!(remote.contains("loopback only"), "{remote}");
        let twice = choice
            .debug(&["cruise=3333".into(), "abs=:3333".into()])
            .unwrap_err();
        assert!(twice.contains("given twice"), "{twice}");
    }

    #[test]
    fn a_missing_or_damaged_image_is_refused_with_its_name() {
        let dir = tempfile::tempdir().unwrap();
        let missing = load(Node::Cruise, dir.path(), 1).err().unwrap();
        assert!(missing.contains("boot: No such file"), "{missing}");
        assert!(missing.contains("-p autoplug-boot"), "{missing}");
        std::fs::write(dir.path().join("boot"), b"#!/bin/sh\necho not firmware\n").unwrap();
        let not_elf = load(Node::Cruise, dir.path(), 1).err().unwrap();
        assert!(
            not_elf.contains("boot") && not_elf.contains("ELF"),
            "{not_elf}"
        );
    }

    #[test]
    fn the_cruise_set_speed_is_read_from_its_engage_line() {
        let line = "45.101234 INFO  cruise: engaged at 89.73126 km/h";
        assert_eq!(logged_set_speed(line), Some(89.73126));
        assert_eq!(logged_set_speed("1.0 INFO  cruise: disengaged"), None);
        assert_eq!(logged_set_speed("cruise: engaged at NaN km/h"), None);
        assert_eq!(logged_set_speed("cruise: engaged at 90"), None);
    }
}
