//! A small client for the GDB Remote Serial Protocol ("Debugging with GDB", appendix E)
//! over TCP: the packets a debugger needs to load code, set registers, run to a breakpoint
//! and read the result back.
//!
//! Every read has a deadline; when it passes, the error names what was awaited. Packets
//! are acknowledged (`+`) unless the stub accepts `QStartNoAckMode`
//! ([`GdbClient::try_no_ack_mode`]); replies are run-length decoded, and the binary ones
//! (`qXfer`) unescaped.

use std::io::{ErrorKind, Read, Write};
use std::net::TcpStream;
use std::time::{Duration, Instant};

use super::OracleError;

/// How often a packet is sent again after the stub answered `-` (bad checksum).
const RETRIES: usize = 3;

/// A connection to a GDB stub.
#[derive(Debug)]
pub struct GdbClient {
    stream: TcpStream,
    /// Bytes received and not yet consumed.
    pending: Vec<u8>,
    /// Whether packets are acknowledged (until `QStartNoAckMode` is accepted).
    acks: bool,
    /// The deadline of each exchange, counted from its start.
    timeout: Duration,
    /// The largest packet the stub accepts (`PacketSize` in its `qSupported` reply).
    packet_size: usize,
}

/// Why the target stopped: a stop-reply packet (`S`, `T`, `W`, `X`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum StopReply {
    /// `Sxx` or `Txx...`: stopped with a signal (5, SIGTRAP, at a breakpoint or after a
    /// step); `info` holds the `T` packet's `name:value` pairs.
    Signal {
        /// The signal number.
        signal: u8,
        /// The `n:r;` pairs of a `T` packet.
        info: Vec<(String, String)>,
    },
    /// `Wxx`: the process exited with this status.
    Exited(u8),
    /// `Xxx`: the process was terminated by this signal.
    Terminated(u8),
}

/// One register of the target description.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RegisterInfo {
    /// Its name (`r0`, `sp`, `xpsr`, `d0`, `fpscr`, ...).
    pub name: String,
    /// Its number in `p`/`P` packets and its place in the `g` packet.
    pub number: usize,
    /// Its width in bits.
    pub bits: u32,
}

/// The registers a stub describes in `target.xml` and the files it includes.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct TargetDescription {
    /// Every register, in document order.
    pub registers: Vec<RegisterInfo>,
}

impl TargetDescription {
    /// The register with this name.
    pub fn find(&self, name: &str) -> Option<&RegisterInfo> {
        self.registers.iter().find(|r| r.name == name)
    }

    /// Parses one XML document of the description, following `xi:include`s through `fetch`
    /// (which returns a named annex's text). Registers are numbered as GDB numbers them: in
    /// document order, one after the other, a `regnum` attribute setting the number of its
    /// register and of those after it.
    pub fn parse(
        xml: &str,
        fetch: &mut dyn FnMut(&str) -> Result<String, OracleError>,
    ) -> Result<TargetDescription, OracleError> {
        let mut description = TargetDescription::default();
        let mut next = 0;
        parse_into(xml, fetch, &mut description, &mut next, 0)?;
        Ok(description)
    }
}

fn parse_into(
    xml: &str,
    fetch: &mut dyn FnMut(&str) -> Result<String, OracleError>,
    out: &mut TargetDescription,
    next: &mut usize,
    depth: usize,
) -> Result<(), OracleError> {
    if depth > 8 {
        return Err(OracleError::Protocol {
            what: "reading the target description".into(),
            detail: "xi:include nested too deeply".into(),
        });
    }
    let mut rest = xml;
    while let Some(open) = rest.find('<') {
        let after = &rest[open + 1..];
        // Comments may contain '>' and tags; skip them whole.
        if let Some(comment) = after.strip_prefix("!--") {
            let end = comment.find("-->").map_or(comment.len(), |e| e + 3);
            rest = &comment[end..];
            continue;
        }
        let close = after.find('>').ok_or_else(|| OracleError::Protocol {
            what: "reading the target description".into(),
            detail: "a tag without its closing '>'".into(),
        })?;
        let tag = &after[..close];
        rest = &after[close + 1..];
        let name = tag.split_whitespace().next().unwrap_or("");
        match name {
            "xi:include" => {
                let href = attribute(tag, "href").ok_or_else(|| OracleError::Protocol {
                    what: "reading the target description".into(),
                    detail: format!("xi:include without href: <{tag}>"),
                })?;
                let text = fetch(href)?;
                parse_into(&text, fetch, out, next, depth + 1)?;
            }
            "reg" => {
                let bad = |detail: String| OracleError::Protocol {
                    what: "reading the target description".into(),
                    detail,
                };
                let reg_name = attribute(tag, "name")
                    .ok_or_else(|| bad(format!("a register without a name: <{tag}>")))?;
                let bits = attribute(tag, "bitsize")
                    .and_then(|b| b.parse().ok())
                    .ok_or_else(|| bad(format!("a register without a bitsize: <{tag}>")))?;
                let number = match attribute(tag, "regnum") {
                    Some(n) => n
                        .parse()
                        .map_err(|_| bad(format!("a bad regnum: <{tag}>")))?,
                    None => *next,
                };
                *next = number + 1;
                out.registers.push(RegisterInfo {
                    name: reg_name.to_string(),
                    number,
                    bits,
                });
            }
            _ => {}
        }
    }
    Ok(())
}

/// The value of `name="..."` (or single quotes) in a tag's text.
fn attribute<'a>(tag: &'a str, name: &str) -> Option<&'a str> {
    let mut search = tag;
    while let Some(at) = search.find(name) {
        let before_ok = at == 0 || search.as_bytes()[at - 1].is_ascii_whitespace();
        let after = search[at + name.len()..].trim_start();
        if before_ok {
            if let Some(value) = after.strip_prefix('=') {
                let value = value.trim_start();
                let quote = value.chars().next()?;
                if quote == '"' || quote == '\'' {
                    let body = &value[1..];
                    return body.find(quote).map(|end| &body[..end]);
                }
            }
        }
        search = &search[at + name.len()..];
    }
    None
}

/// Lower-case hex of `bytes`, two digits a byte.
pub fn to_hex(bytes: &[u8]) -> String {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    let mut out = String::with_capacity(bytes.len() * 2);
    for &b in bytes {
        out.push(DIGITS[usize::from(b >> 4)] as char);
        out.push(DIGITS[usize::from(b & 15)] as char);
    }
    out
}

/// The bytes that the hex text `text` spells (an even number of digits, either case).
pub fn from_hex(text: &[u8]) -> Option<Vec<u8>> {
    if text.len() % 2 != 0 {
        return None;
    }
    text.chunks(2)
        .map(|pair| Some(hex_digit(pair[0])? << 4 | hex_digit(pair[1])?))
        .collect()
}

fn hex_digit(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'a'..=b'f' => Some(c - b'a' + 10),
        b'A'..=b'F' => Some(c - b'A' + 10),
        _ => None,
    }
}

/// The modulo-256 sum of `bytes`: a packet's checksum.
pub fn checksum(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0u8, |sum, &b| sum.wrapping_add(b))
}

/// `$payload#cs`. The payload must already be escaped where it needs to be.
pub fn frame(payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(payload.len() + 4);
    out.push(b'$');
    out.extend_from_slice(payload);
    out.push(b'#');
    out.extend_from_slice(to_hex(&[checksum(payload)]).as_bytes());
    out
}

/// A reply's payload as sent (between `$` and `#`) decoded: run-length encoding (`x*n`
/// repeats `x` `n - 29` more times) expanded and, for binary replies, `}`-escapes undone.
pub fn decode_payload(raw: &[u8], binary: bool) -> Result<Vec<u8>, String> {
    let mut out: Vec<u8> = Vec::with_capacity(raw.len());
    let mut i = 0;
    while i < raw.len() {
        let c = raw[i];
        if c == b'*' {
            let count = *raw
                .get(i + 1)
                .ok_or("a run-length '*' at the end of a packet")?;
            let last = *out.last().ok_or("a run-length '*' before any character")?;
            let repeat = usize::from(count)
                .checked_sub(29)
                .ok_or_else(|| format!("a bad run length {count:#x}"))?;
            out.extend(std::iter::repeat_n(last, repeat));
            i += 2;
        } else if binary && c == b'}' {
            let escaped = *raw
                .get(i + 1)
                .ok_or("an escape '}' at the end of a packet")?;
            out.push(escaped ^ 0x20);
            i += 2;
        } else {
            out.push(c);
            i += 1;
        }
    }
    Ok(out)
}

impl GdbClient {
    /// Wraps a connected stream; `timeout` bounds every exchange.
    pub fn new(stream: TcpStream, timeout: Duration) -> Result<GdbClient, OracleError> {
        stream.set_nodelay(true).map_err(|source| OracleError::Io {
            what: "setting TCP_NODELAY on the GDB connection".into(),
            source,
        })?;
        Ok(GdbClient {
            stream,
            pending: Vec::new(),
            acks: true,
            timeout,
            packet_size: 400,
        })
    }

    /// The deadline of each exchange.
    pub fn timeout(&self) -> Duration {
        self.timeout
    }

    /// Changes the deadline of each exchange.
    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
    }

    /// The largest packet the stub accepts, as it said in `qSupported`.
    pub fn packet_size(&self) -> usize {
        self.packet_size
    }

    /// `qSupported`: tells the stub what this client handles and returns its features
    /// (`PacketSize=...;qXfer:features:read+;...`), remembering its packet size.
    pub fn query_supported(&mut self) -> Result<Vec<String>, OracleError> {
        let reply = self.command_text("qSupported:swbreak+;hwbreak+;xmlRegisters=arm")?;
        let features: Vec<String> = reply.split(';').map(str::to_string).collect();
        for feature in &features {
            if let Some(size) = feature.strip_prefix("PacketSize=") {
                if let Ok(size) = usize::from_str_radix(size, 16) {
                    self.packet_size = size.max(64);
                }
            }
        }
        Ok(features)
    }

    /// Asks for `QStartNoAckMode` when `features` (the `qSupported` reply) offers it;
    /// returns whether acknowledgements are now off.
    pub fn try_no_ack_mode(&mut self, features: &[String]) -> Result<bool, OracleError> {
        if !features.iter().any(|f| f == "QStartNoAckMode+") {
            return Ok(false);
        }
        let reply = self.command_text("QStartNoAckMode")?;
        if reply == "OK" {
            self.acks = false;
            Ok(true)
        } else {
            Ok(false)
        }
    }

    /// `?`: why the target is stopped.
    pub fn stop_reason(&mut self) -> Result<StopReply, OracleError> {
        let reply = self.command(b"?", "the reply to '?'")?;
        parse_stop_reply(&reply)
    }

    /// Reads a `qXfer:features:read` annex whole (`target.xml`, or a file it includes).
    pub fn read_feature(&mut self, annex: &str) -> Result<String, OracleError> {
        let mut text = Vec::new();
        let chunk = self.packet_size.saturating_sub(8).max(64);
        loop {
            let request = format!("qXfer:features:read:{annex}:{:x},{chunk:x}", text.len());
            let what = format!("the reply to qXfer for {annex}");
            let raw = self.exchange(request.as_bytes(), &what)?;
            let reply = decode_payload(&raw, true).map_err(|detail| OracleError::Protocol {
                what: what.clone(),
                detail,
            })?;
            match reply.first() {
                Some(b'l') => {
                    text.extend_from_slice(&reply[1..]);
                    break;
                }
                Some(b'm') if reply.len() > 1 => text.extend_from_slice(&reply[1..]),
                _ => {
                    return Err(OracleError::Protocol {
                        what,
                        detail: String::from_utf8_lossy(&reply).into_owned(),
                    })
                }
            }
        }
        String::from_utf8(text).map_err(|_| OracleError::Protocol {
            what: format!("reading {annex}"),
            detail: "not UTF-8".into(),
        })
    }

    /// Reads `target.xml` and every file it includes.
    pub fn target_description(&mut self) -> Result<TargetDescription, OracleError> {
        let top = self.read_feature("target.xml")?;
        TargetDescription::parse(&top, &mut |annex| self.read_feature(annex))
    }

    /// `g`: the registers of the `g` packet, as the raw bytes the stub sends.
    pub fn read_registers(&mut self) -> Result<Vec<u8>, OracleError> {
        self.command_hex(b"g", "the registers (reply to 'g')")
    }

    /// `G`: writes the registers of the `g` packet.
    pub fn write_registers(&mut self, bytes: &[u8]) -> Result<(), OracleError> {
        let mut request = b"G".to_vec();
        request.extend_from_slice(to_hex(bytes).as_bytes());
        self.command_ok(&request, "the reply to 'G'")
    }

    /// `p`: one register's raw bytes (target byte order).
    pub fn read_register(&mut self, number: usize) -> Result<Vec<u8>, OracleError> {
        let request = format!("p{number:x}");
        self.command_hex(
            request.as_bytes(),
            &format!("register {number} (reply to '{request}')"),
        )
    }

    /// `P`: writes one register's raw bytes (target byte order).
    pub fn write_register(&mut self, number: usize, bytes: &[u8]) -> Result<(), OracleError> {
        let request = format!("P{number:x}={}", to_hex(bytes));
        self.command_ok(
            request.as_bytes(),
            &format!("the reply to writing register {number}"),
        )
    }

    /// `m`: reads `len` bytes from `addr`, in as many packets as the packet size needs.
    pub fn read_memory(&mut self, addr: u32, len: usize) -> Result<Vec<u8>, OracleError> {
        let chunk = (self.packet_size.saturating_sub(8) / 2).max(16);
        let mut out = Vec::with_capacity(len);
        while out.len() < len {
            let n = chunk.min(len - out.len());
            let at = addr.wrapping_add(out.len() as u32);
            let request = format!("m{at:x},{n:x}");
            let bytes = self.command_hex(request.as_bytes(), &format!("memory at {at:#010x}"))?;
            if bytes.is_empty() || bytes.len() > n {
                return Err(OracleError::Protocol {
                    what: format!("reading {n} bytes at {at:#010x}"),
                    detail: format!("{} bytes came back", bytes.len()),
                });
            }
            out.extend_from_slice(&bytes);
        }
        Ok(out)
    }

    /// `M`: writes `bytes` at `addr`, in as many packets as the packet size needs.
    pub fn write_memory(&mut self, addr: u32, bytes: &[u8]) -> Result<(), OracleError> {
        let chunk = (self.packet_size.saturating_sub(32) / 2).max(16);
        for (i, piece) in bytes.chunks(chunk).enumerate() {
            let at = addr.wrapping_add((i * chunk) as u32);
            let request = format!("M{at:x},{:x}:{}", piece.len(), to_hex(piece));
            self.command_ok(
                request.as_bytes(),
                &format!("the reply to writing memory at {at:#010x}"),
            )?;
        }
        Ok(())
    }

    /// `Z0`: a software breakpoint at `addr`; `kind` is the instruction size (2 for Thumb).
    pub fn insert_breakpoint(&mut self, addr: u32, kind: u32) -> Result<(), OracleError> {
        let request = format!("Z0,{addr:x},{kind:x}");
        self.command_ok(
            request.as_bytes(),
            &format!("the reply to inserting a breakpoint at {addr:#010x}"),
        )
    }

    /// `z0`: removes the software breakpoint at `addr`.
    pub fn remove_breakpoint(&mut self, addr: u32, kind: u32) -> Result<(), OracleError> {
        let request = format!("z0,{addr:x},{kind:x}");
        self.command_ok(
            request.as_bytes(),
            &format!("the reply to removing the breakpoint at {addr:#010x}"),
        )
    }

    /// `c`: continues and waits (at most `wait`) for the stop reply. On timeout the
    /// target is interrupted (so that it is stopped again) and the error returned.
    pub fn cont(&mut self, wait: Duration) -> Result<StopReply, OracleError> {
        self.resume(b"c", wait, "the stop reply after 'c' (continue)")
    }

    /// `s`: executes one instruction and waits for the stop reply.
    pub fn step(&mut self) -> Result<StopReply, OracleError> {
        let wait = self.timeout;
        self.resume(b"s", wait, "the stop reply after 's' (step)")
    }

    fn resume(
        &mut self,
        request: &[u8],
        wait: Duration,
        what: &str,
    ) -> Result<StopReply, OracleError> {
        self.send(request, what)?;
        let deadline = Instant::now() + wait;
        match self.receive(deadline, what) {
            Ok(raw) => parse_stop_reply(&decode(&raw, what)?),
            Err(OracleError::Timeout { .. }) => {
                // Stop the runaway target so that the connection stays usable.
                let _ = self.interrupt();
                Err(OracleError::Timeout {
                    what: what.to_string(),
                    after: wait,
                })
            }
            Err(other) => Err(other),
        }
    }

    /// Sends the interrupt byte (0x03) and waits for the stop reply it causes.
    pub fn interrupt(&mut self) -> Result<StopReply, OracleError> {
        let what = "the stop reply after an interrupt (0x03)";
        self.write_all(&[0x03], what)?;
        let deadline = Instant::now() + self.timeout;
        let raw = self.receive(deadline, what)?;
        parse_stop_reply(&decode(&raw, what)?)
    }

    /// `qRcmd`: runs a monitor command (`monitor system_reset`) and returns its output.
    pub fn monitor(&mut self, command: &str) -> Result<String, OracleError> {
        let what = format!("the reply to monitor command `{command}`");
        let request = format!("qRcmd,{}", to_hex(command.as_bytes()));
        self.send(request.as_bytes(), &what)?;
        let deadline = Instant::now() + self.timeout;
        let mut output = Vec::new();
        loop {
            let reply = decode(&self.receive(deadline, &what)?, &what)?;
            match reply.first() {
                // Console output, more to come.
                Some(b'O') if reply != b"OK" => {
                    output.extend(from_hex(&reply[1..]).unwrap_or_default());
                }
                _ if reply == b"OK" => break,
                _ if reply.is_empty() => {
                    return Err(OracleError::Protocol {
                        what,
                        detail: "the stub does not support qRcmd".into(),
                    })
                }
                _ => {
                    // A hex reply is the command's output itself.
                    match from_hex(&reply) {
                        Some(text) => {
                            output.extend(text);
                            break;
                        }
                        None => {
                            return Err(OracleError::Protocol {
                                what,
                                detail: String::from_utf8_lossy(&reply).into_owned(),
                            })
                        }
                    }
                }
            }
        }
        Ok(String::from_utf8_lossy(&output).into_owned())
    }

    /// `k`: kills the target. The stub may close the connection without replying.
    pub fn kill(&mut self) -> Result<(), OracleError> {
        self.send(b"k", "the acknowledgement of 'k'")
    }

    /// Sends `request` and returns its reply decoded (not binary-unescaped).
    pub fn command(&mut self, request: &[u8], what: &str) -> Result<Vec<u8>, OracleError> {
        let raw = self.exchange(request, what)?;
        decode(&raw, what)
    }

    fn command_text(&mut self, request: &str) -> Result<String, OracleError> {
        let what = format!("the reply to '{request}'");
        let reply = self.command(request.as_bytes(), &what)?;
        Ok(String::from_utf8_lossy(&reply).into_owned())
    }

    fn command_ok(&mut self, request: &[u8], what: &str) -> Result<(), OracleError> {
        let reply = self.command(request, what)?;
        if reply == b"OK" {
            Ok(())
        } else {
            Err(refused(what, &reply))
        }
    }

    fn command_hex(&mut self, request: &[u8], what: &str) -> Result<Vec<u8>, OracleError> {
        let reply = self.command(request, what)?;
        if reply.first() == Some(&b'E') && reply.len() == 3 || reply.is_empty() {
            return Err(refused(what, &reply));
        }
        from_hex(&reply).ok_or_else(|| OracleError::Protocol {
            what: what.to_string(),
            detail: format!("not hex: {}", String::from_utf8_lossy(&reply)),
        })
    }

    /// Sends a packet and returns the raw payload of the reply.
    fn exchange(&mut self, request: &[u8], what: &str) -> Result<Vec<u8>, OracleError> {
        self.send(request, what)?;
        let deadline = Instant::now() + self.timeout;
        self.receive(deadline, what)
    }

    /// Sends one packet, then (with acknowledgements on) waits for its `+`, sending it
    /// again after a `-`.
    fn send(&mut self, payload: &[u8], what: &str) -> Result<(), OracleError> {
        let packet = frame(payload);
        let deadline = Instant::now() + self.timeout;
        for _ in 0..RETRIES {
            self.write_all(&packet, what)?;
            if !self.acks {
                return Ok(());
            }
            loop {
                if let Some(&c) = self.pending.first() {
                    match c {
                        b'+' => {
                            self.pending.remove(0);
                            return Ok(());
                        }
                        b'-' => {
                            self.pending.remove(0);
                            break;
                        }
                        // A stop reply can overtake an acknowledgement only if the target
                        // was running; leave it for `receive`.
                        b'$' => return Ok(()),
                        _ => {
                            self.pending.remove(0);
                        }
                    }
                } else {
                    self.fill(deadline, &format!("the acknowledgement before {what}"))?;
                }
            }
        }
        Err(OracleError::Protocol {
            what: what.to_string(),
            detail: format!("the stub refused the packet {RETRIES} times (bad checksum)"),
        })
    }

    /// Waits for one packet and returns its raw payload, acknowledging it (or asking for
    /// it again when its checksum is wrong).
    fn receive(&mut self, deadline: Instant, what: &str) -> Result<Vec<u8>, OracleError> {
        loop {
            // Drop anything before the start of a packet (stray acknowledgements).
            match self.pending.iter().position(|&c| c == b'$') {
                Some(start) => {
                    self.pending.drain(..start);
                }
                None => {
                    self.pending.clear();
                    self.fill(deadline, what)?;
                    continue;
                }
            }
            let Some(hash) = self.pending.iter().position(|&c| c == b'#') else {
                self.fill(deadline, what)?;
                continue;
            };
            if self.pending.len() < hash + 3 {
                self.fill(deadline, what)?;
                continue;
            }
            let payload = self.pending[1..hash].to_vec();
            let sent = from_hex(&self.pending[hash + 1..hash + 3]);
            self.pending.drain(..hash + 3);
            if sent == Some(vec![checksum(&payload)]) {
                if self.acks {
                    self.write_all(b"+", what)?;
                }
                return Ok(payload);
            }
            if self.acks {
                self.write_all(b"-", what)?;
            } else {
                return Err(OracleError::Protocol {
                    what: what.to_string(),
                    detail: "a packet with a bad checksum".into(),
                });
            }
        }
    }

    /// Reads whatever arrives before `deadline` into `pending`.
    fn fill(&mut self, deadline: Instant, what: &str) -> Result<(), OracleError> {
        let now = Instant::now();
        if now >= deadline {
            return Err(OracleError::Timeout {
                what: what.to_string(),
                after: self.timeout,
            });
        }
        self.stream
            .set_read_timeout(Some((deadline - now).max(Duration::from_millis(1))))
            .map_err(|source| OracleError::Io {
                what: format!("setting the read timeout for {what}"),
                source,
            })?;
        let mut buffer = [0u8; 8192];
        match self.stream.read(&mut buffer) {
            Ok(0) => Err(OracleError::Protocol {
                what: what.to_string(),
                detail: "the stub closed the connection (did QEMU exit?)".into(),
            }),
            Ok(n) => {
                self.pending.extend_from_slice(&buffer[..n]);
                Ok(())
            }
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                Err(OracleError::Timeout {
                    what: what.to_string(),
                    after: self.timeout,
                })
            }
            Err(e) if e.kind() == ErrorKind::Interrupted => Ok(()),
            Err(source) => Err(OracleError::Io {
                what: format!("reading {what}"),
                source,
            }),
        }
    }

    fn write_all(&mut self, bytes: &[u8], what: &str) -> Result<(), OracleError> {
        self.stream
            .set_write_timeout(Some(self.timeout))
            .and_then(|()| self.stream.write_all(bytes))
            .map_err(|source| OracleError::Io {
                what: format!("sending the request for {what}"),
                source,
            })
    }
}

fn decode(raw: &[u8], what: &str) -> Result<Vec<u8>, OracleError> {
    decode_payload(raw, false).map_err(|detail| OracleError::Protocol {
        what: what.to_string(),
        detail,
    })
}

fn refused(what: &str, reply: &[u8]) -> OracleError {
    OracleError::Protocol {
        what: what.to_string(),
        detail: if reply.is_empty() {
            "the stub does not support the request (empty reply)".into()
        } else {
            format!("the stub answered {}", String::from_utf8_lossy(reply))
        },
    }
}

/// Parses a stop reply (`S05`, `T05thread:01;`, `W00`, `X09`).
pub fn parse_stop_reply(reply: &[u8]) -> Result<StopReply, OracleError> {
    let bad = || OracleError::Protocol {
        what: "parsing a stop reply".into(),
        detail: String::from_utf8_lossy(reply).into_owned(),
    };
    let code = reply
        .get(1..3)
        .and_then(from_hex)
        .map(|b| b[0])
        .ok_or_else(bad)?;
    match reply[0] {
        b'S' => Ok(StopReply::Signal {
            signal: code,
            info: Vec::new(),
        }),
        b'T' => {
            let text = String::from_utf8_lossy(&reply[3..]);
            let info = text
                .split(';')
                .filter(|p| !p.is_empty())
                .map(|pair| match pair.split_once(':') {
                    Some((n, v)) => (n.to_string(), v.to_string()),
                    None => (pair.to_string(), String::new()),
                })
                .collect();
            Ok(StopReply::Signal { signal: code, info })
        }
        b'W' => Ok(StopReply::Exited(code)),
        b'X' => Ok(StopReply::Terminated(code)),
        _ => Err(bad()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn framing_and_checksums() {
        assert_eq!(frame(b"g"), b"$g#67");
        assert_eq!(frame(b""), b"$#00");
        assert_eq!(checksum(b"OK"), 0x9a);
    }

    #[test]
    fn run_length_and_escapes() {
        // "0* " is '0' and 3 more ('  ' is 32, 32 - 29 = 3).
        assert_eq!(decode_payload(b"0* 1", false).unwrap(), b"00001");
        assert_eq!(decode_payload(b"}]", true).unwrap(), b"}");
        assert_eq!(decode_payload(b"}]", false).unwrap(), b"}]");
        assert!(decode_payload(b"*!", false).is_err());
    }

    #[test]
    fn hex_round_trip() {
        assert_eq!(to_hex(&[0x00, 0xab, 0x7f]), "00ab7f");
        assert_eq!(from_hex(b"00AB7f").unwrap(), vec![0x00, 0xab, 0x7f]);
        assert!(from_hex(b"0").is_none());
        assert!(from_hex(b"zz").is_none());
    }

    #[test]
    fn stop_replies() {
        assert_eq!(
            parse_stop_reply(b"T05thread:p01.01;").unwrap(),
            StopReply::Signal {
                signal: 5,
                info: vec![("thread".into(), "p01.01".into())]
            }
        );
        assert_eq!(parse_stop_reply(b"W00").unwrap(), StopReply::Exited(0));
        assert!(parse_stop_reply(b"Q").is_err());
    }

    #[test]
    fn register_numbers_follow_gdb() {
        let top = r#"<?xml version="1.0"?><target><xi:include href="a.xml"/><xi:include href="b.xml"/></target>"#;
        let a = r#"<feature name="x"><!-- <reg name="no" bitsize="1"/> --><reg name="r0" bitsize="32"/><reg name="r1" bitsize="32"/><reg name="xpsr" bitsize="32" regnum="25"/></feature>"#;
        let b = r#"<feature name="y"><reg name="d0" bitsize="64" type="float"/><reg name='fpscr' bitsize='32'/></feature>"#;
        let description = TargetDescription::parse(top, &mut |annex| match annex {
            "a.xml" => Ok(a.to_string()),
            "b.xml" => Ok(b.to_string()),
            _ => panic!("unexpected {annex}"),
        })
        .unwrap();
        let numbers: Vec<(&str, usize, u32)> = description
            .registers
            .iter()
            .map(|r| (r.name.as_str(), r.number, r.bits))
            .collect();
        assert_eq!(
            numbers,
            [
                ("r0", 0, 32),
                ("r1", 1, 32),
                ("xpsr", 25, 32),
                ("d0", 26, 64),
                ("fpscr", 27, 32)
            ]
        );
    }
}
