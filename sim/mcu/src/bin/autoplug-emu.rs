//! Runs a firmware ELF on the emulated STM32F446 with a debugger attached, as `probe-rs
//! run` runs it on a Nucleo-F446RE: the defmt log streamed as it is written (RTT, or
//! semihosting), a program's plain semihosting text (`hprintln!`) printed as text,
//! semihosting exit ending the run with its status, a HardFault reported
//! with its registers and the last log lines. An ECU firmware (linked for slot A) starts
//! through the bootloader, found beside it or given with `--boot`.
//!
//! ```text
//! autoplug-emu ELF [--boot BOOT_ELF] [--for SECONDS | --until-exit SECONDS] [--gdb [ADDR]]
//! ```
//!
//! Without `--for` or `--until-exit` it runs until stopped, at the pace of real time. With
//! `--gdb` the MCU's debug port is a GDB server (default 127.0.0.1:3333): the run waits
//! for the debugger, halted at the reset vector.
//!
//! Exit status: the program's own (semihosting exit), 0 after `--for SECONDS`, 1 on a
//! HardFault, lockup or unmodelled access, 124 if `--until-exit SECONDS` passed without an
//! exit, 2 on a usage error.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::{Arc, Mutex};

use autoplug_mcu::map::FLASH_BASE;
use autoplug_mcu::mcu::{Mcu, Stop};
use autoplug_mcu::programming::FlashContents;
use autoplug_mcu::rtt::{LogLine, RttLog};

const USAGE: &str =
    "usage: autoplug-emu ELF [--boot BOOT_ELF] [--for SECONDS | --until-exit SECONDS] [--gdb [ADDR]]";

const HELP: &str = "\
Runs a firmware ELF on AutoPlug's emulated STM32F446 (a Nucleo-F446RE), as probe-rs runs
it on a board: its defmt log (RTT or semihosting) decoded as it is written, its plain
semihosting text (cortex-m-semihosting's hprintln!) printed as text, a semihosting exit
ending the run with the program's status, a HardFault reported with its registers.
An application linked behind the bootloader starts through it (the `boot` ELF beside it,
or --boot).

Options:
  --boot BOOT_ELF        the bootloader to start the application through
  --for SECONDS          run this long in simulated time, as fast as the machine goes
  --until-exit SECONDS   as --for, and fail (status 124) if the program has not exited
  --gdb [ADDR]           a GDB server on the MCU's debug port (default 127.0.0.1:3333,
                         loopback only): the run waits for the debugger, halted at the
                         reset vector; simulated time stands still while it holds the
                         core halted
  -h, --help             this text
Without --for or --until-exit it runs until stopped, at the pace of real time.

Exit status: the program's own (semihosting exit); 0 after --for; 1 on a HardFault,
lockup or unmodelled access; 124 after --until-exit without an exit; 2 on a usage error.
";

struct Args {
    help: bool,
    elf: PathBuf,
    boot: Option<PathBuf>,
    seconds: f64,
    expect_exit: bool,
    gdb: Option<std::net::SocketAddr>,
}

fn parse(args: &[String]) -> Result<Args, String> {
    let mut elf = None;
    let mut boot = None;
    let mut seconds = f64::INFINITY;
    let mut expect_exit = false;
    let mut gdb = None;
    let mut it = args.iter().peekable();
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "-h" | "--help" => {
                return Ok(Args {
                    help: true,
                    elf: PathBuf::new(),
                    boot: None,
                    seconds,
                    expect_exit,
                    gdb,
                })
            }
            "--gdb" => {
                // An address follows, or the default is meant.
                let given = it.peek().filter(|a| {
                    !a.starts_with("--") && autoplug_mcu::gdb::parse_address(a).is_ok()
                });
                let address = match given {
                    Some(_) => it.next().map(String::as_str).unwrap_or_default(),
                    None => match it.peek() {
                        Some(a) if a.contains(':') && !a.starts_with("--") => a.as_str(),
                        _ => autoplug_mcu::gdb::DEFAULT_ADDRESS,
                    },
                };
                gdb = Some(autoplug_mcu::gdb::parse_address(address)?);
            }
            "--boot" => boot = Some(PathBuf::from(it.next().ok_or("--boot needs a file")?)),
            "--for" | "--until-exit" => {
                let value = it
                    .next()
                    .ok_or_else(|| format!("{arg} needs a number of seconds"))?;
                seconds = value
                    .parse::<f64>()
                    .ok()
                    .filter(|s| *s > 0.0)
                    .ok_or_else(|| format!("{arg} {value}: not a positive number of seconds"))?;
                expect_exit = arg == "--until-exit";
            }
            other if other.starts_with("--") => return Err(format!("unknown option {other}")),
            // A cargo runner is given the test binary and then the test harness's arguments.
            other if elf.is_none() => elf = Some(PathBuf::from(other)),
            _ => {}
        }
    }
    Ok(Args {
        help: false,
        elf: elf.ok_or("no ELF file given")?,
        boot,
        seconds,
        expect_exit,
        gdb,
    })
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let args = match parse(&args) {
        Ok(args) => args,
        Err(e) => {
            eprintln!("autoplug-emu: {e}\n{USAGE}");
            return ExitCode::from(2);
        }
    };
    if args.help {
        println!("{USAGE}\n\n{HELP}");
        return ExitCode::SUCCESS;
    }
    match run(&args) {
        Ok(status) => ExitCode::from(status),
        Err(e) => {
            eprintln!("autoplug-emu: {e}");
            ExitCode::from(2)
        }
    }
}

fn load(file: &Path, flash: &mut FlashContents, logs: &mut Vec<RttLog>) -> Result<u32, String> {
    let name = file.display().to_string();
    let bytes = std::fs::read(file).map_err(|e| format!("{name}: {e}"))?;
    let written = flash
        .program_elf(&name, &bytes)
        .map_err(|e| e.to_string())?
        .start;
    if let Some(log) = RttLog::for_elf(&name, &bytes)? {
        logs.push(log);
    }
    Ok(written)
}

fn run(args: &Args) -> Result<u8, String> {
    let mut flash = FlashContents::erased();
    let mut logs = Vec::new();
    let bytes = std::fs::read(&args.elf).map_err(|e| format!("{}: {e}", args.elf.display()))?;
    let start = autoplug_image::elf::loadable_segments(&bytes)
        .map_err(|e| format!("{}: {e}", args.elf.display()))?
        .iter()
        .map(|(address, _)| *address as u32)
        .min()
        .unwrap_or(FLASH_BASE);
    if start != FLASH_BASE {
        // An application behind the bootloader: the bootloader goes first.
        let boot = match &args.boot {
            Some(boot) => boot.clone(),
            None => {
                let beside = args.elf.with_file_name("boot");
                if !beside.exists() {
                    return Err(format!(
                        "{} starts at {start:#010x}, behind the bootloader, and there is no {} (build it: cargo build --profile firmware --target thumbv7em-none-eabihf -p autoplug-boot, or give --boot)",
                        args.elf.display(),
                        beside.display()
                    ));
                }
                beside
            }
        };
        load(&boot, &mut flash, &mut logs)?;
    }
    load(&args.elf, &mut flash, &mut logs)?;
    // Semihosting output is the program's defmt log when it has a defmt table (through
    // its RTT log, or a decoder of its own for defmt-semihosting); without one it is text.
    let name = args.elf.display().to_string();
    let semihosting_defmt = match logs.pop() {
        Some(log) if log.name() == name => Some(log),
        other => {
            logs.extend(other);
            RttLog::defmt_only(&name, &bytes)?
        }
    };
    let mut text = SemihostingText::default();
    let mut mcu = Mcu::power_on(
        flash.to_sim_flash(1),
        [0x0031_0042, 0x3433_5107, 0x3236_3731],
    )
    .map_err(|e| e.to_string())?;
    mcu.cpu.debugger_attached = true;
    let gdb_status = match args.gdb {
        Some(address) => {
            let server = autoplug_mcu::gdb::GdbServer::bind("the MCU", address)?;
            let status = server.status();
            eprintln!(
                "autoplug-emu: GDB server on {}: gdb-multiarch {} -ex 'target extended-remote {}'",
                server.local_addr(),
                args.elf.display(),
                server.local_addr()
            );
            eprintln!(
                "autoplug-emu: waiting for the debugger (the MCU is halted at its reset vector)"
            );
            server.wait_for_client(None);
            mcu.debugger = Some(Box::new(server));
            Some(status)
        }
        None => None,
    };
    // The RTT logs are read after each step, and by the debug port's halt (the lines
    // logged before a breakpoint show while it holds, as probe-rs shows them).
    let shared = Arc::new(Mutex::new(Logs {
        rtt: logs,
        own: semihosting_defmt,
        recent: Vec::new(),
    }));
    if gdb_status.is_some() {
        let logs = Arc::clone(&shared);
        mcu.on_debug_halt = Some(Box::new(move |mcu| {
            if let Ok(mut logs) = logs.lock() {
                logs.poll(mcu);
            }
        }));
    }
    let mut recent: Vec<LogLine> = Vec::new();
    let print = |lines: Vec<LogLine>, recent: &mut Vec<LogLine>| {
        for line in lines {
            println!("{line}");
            recent.push(line);
            if recent.len() > 10 {
                recent.remove(0);
            }
        }
    };
    let step_ns = 1_000_000;
    let limit_ns = if args.seconds.is_finite() {
        (args.seconds * 1e9) as u64
    } else {
        u64::MAX
    };
    let mut at = 0u64;
    // Run for ever (no --for/--until-exit): a person is watching, so keep to real time, as
    // a board would; otherwise as fast as the machine goes.
    let paced = !args.seconds.is_finite();
    let wall = std::time::Instant::now();
    let outcome = loop {
        at = at.saturating_add(step_ns).min(limit_ns);
        if paced {
            // The time the debugger held the core is not the firmware's.
            let halted = gdb_status
                .as_ref()
                .map_or(std::time::Duration::ZERO, |s| s.halted_for());
            let ahead = std::time::Duration::from_nanos(mcu.now_ns())
                .saturating_sub(wall.elapsed().saturating_sub(halted));
            if !ahead.is_zero() {
                std::thread::sleep(ahead);
            }
        }
        let result = mcu.run_until(at);
        let Ok(mut logs) = shared.lock() else {
            break 1;
        };
        logs.poll(&mut mcu);
        recent.append(&mut logs.recent);
        if recent.len() > 10 {
            recent.drain(..recent.len() - 10);
        }
        if !mcu.semihosting_output.is_empty() {
            let bytes = std::mem::take(&mut mcu.semihosting_output);
            match logs.own.as_mut() {
                // A write of printable text with no zero byte outside a defmt frame is the
                // program's own text (hprintln!): defmt frames are binary and end in zero.
                Some(log) if log.mid_frame() || !looks_like_text(&bytes) => {
                    let lines = log.decode(&bytes);
                    print(lines, &mut recent);
                }
                _ => print(text.take(&bytes), &mut recent),
            }
        }
        if let Some(fault) = mcu.faults.first().cloned() {
            eprintln!(
                "autoplug-emu: HardFault ({:?}) at pc {:#010x}, lr {:#010x}, CFSR {:#010x}, HFSR {:#010x}, BFAR {:#010x}",
                fault.fault, fault.pc, fault.lr, fault.cfsr, fault.hfsr, fault.bfar
            );
            break 1;
        }
        match result {
            Ok(()) if at >= limit_ns => {
                if args.expect_exit {
                    eprintln!(
                        "autoplug-emu: no exit after {} s of simulated time (a hung test?)",
                        args.seconds
                    );
                    break 124;
                }
                break 0;
            }
            Ok(()) => {}
            Err(Stop::Exited(status)) => break status.min(255) as u8,
            Err(stop) => {
                eprintln!("autoplug-emu: {stop}");
                break 1;
            }
        }
    };
    print(text.finish(), &mut recent);
    if outcome != 0 && !recent.is_empty() {
        eprintln!("autoplug-emu: the last log lines:");
        for line in &recent {
            eprintln!("  {}", line.text);
        }
    }
    Ok(outcome)
}

/// The RTT logs of the images loaded, and the lines they printed since the last look.
struct Logs {
    rtt: Vec<RttLog>,
    /// The program's own (its defmt table decodes its semihosting output too).
    own: Option<RttLog>,
    recent: Vec<LogLine>,
}

impl Logs {
    /// Prints what each log holds now.
    fn poll(&mut self, mcu: &mut Mcu) {
        for log in self.rtt.iter_mut().chain(self.own.as_mut()) {
            for line in log.poll(mcu) {
                println!("{line}");
                self.recent.push(line);
            }
        }
        if self.recent.len() > 10 {
            self.recent.drain(..self.recent.len() - 10);
        }
    }
}

/// A program's plain semihosting text, printed line by line as it comes (a line may come in
/// several writes).
#[derive(Default)]
struct SemihostingText {
    partial: Vec<u8>,
}

impl SemihostingText {
    /// The lines `bytes` completes.
    fn take(&mut self, bytes: &[u8]) -> Vec<LogLine> {
        self.partial.extend_from_slice(bytes);
        let Some(end) = self.partial.iter().rposition(|&b| b == b'\n') else {
            return Vec::new();
        };
        let complete: Vec<u8> = self.partial.drain(..=end).collect();
        String::from_utf8_lossy(&complete)
            .lines()
            .map(|line| LogLine {
                level: None,
                text: line.trim_end_matches('\r').to_string(),
                location: None,
            })
            .collect()
    }

    /// What is left without a line end, at the end of the run.
    fn finish(&mut self) -> Vec<LogLine> {
        if self.partial.is_empty() {
            return Vec::new();
        }
        self.take(b"\n")
    }
}

/// Printable UTF-8 text with no zero byte (what `hprintln!` writes; never a defmt frame,
/// whose rzCOBS encoding ends each frame in a zero byte).
fn looks_like_text(bytes: &[u8]) -> bool {
    !bytes.contains(&0)
        && std::str::from_utf8(bytes).is_ok_and(|s| {
            s.chars()
                .all(|c| !c.is_control() || matches!(c, '\n' | '\r' | '\t'))
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_text_is_told_from_defmt_frames() {
        assert!(looks_like_text(b"Hello, world!\n"));
        assert!(looks_like_text("42 °C\r\n".as_bytes()));
        assert!(
            !looks_like_text(&[0x03, 0x01, 0x2A, 0x00]),
            "an rzCOBS frame ends in 0"
        );
        assert!(!looks_like_text(&[0x1B, 0x80, 0xFF]));
    }

    #[test]
    fn text_is_printed_a_line_at_a_time_whatever_the_writes() {
        let mut text = SemihostingText::default();
        assert!(text.take(b"Hello, ").is_empty());
        let lines = text.take(b"world!\nsecond");
        assert_eq!(lines.len(), 1);
        assert_eq!(lines[0].text, "Hello, world!");
        let rest = text.finish();
        assert_eq!(rest[0].text, "second");
        assert!(text.finish().is_empty());
    }

    #[test]
    fn help_is_an_answer_not_an_error() {
        let args = parse(&["--help".to_string()]).unwrap();
        assert!(args.help);
        let error = parse(&["--frobnicate".to_string()]).err().unwrap();
        assert!(error.contains("--frobnicate"), "{error}");
    }
}
