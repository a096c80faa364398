//! The remote protocol's framing, checked before gdbstub sees a byte: `$body#cc` packets
//! within [`PACKET_SIZE`](super::PACKET_SIZE) and with the right checksum, and the single
//! bytes between them (`+`, `-`, Ctrl-C). gdbstub ends a session on a packet it cannot
//! frame or that overflows its buffer; here such a packet gets the protocol's answer (a
//! retransmission request, an error) and the session goes on.

/// What the framer made of the bytes so far.
#[derive(Debug, PartialEq, Eq)]
pub(super) enum Framed {
    /// A single byte outside a packet: `+`, `-` or 0x03 (Ctrl-C).
    Byte(u8),
    /// A whole packet, checked: `$`, the body, `#` and the checksum.
    Packet(Vec<u8>),
    /// Bytes to send back at once (a `-` for a bad checksum, an error for a packet that
    /// was too long).
    Reply(Vec<u8>),
}

#[derive(Debug, Default, Clone, Copy, PartialEq, Eq)]
enum State {
    #[default]
    Between,
    Body,
    Checksum(u8),
}

/// Frames the client's bytes into packets.
#[derive(Debug, Default)]
pub(super) struct Framer {
    state: State,
    packet: Vec<u8>,
    /// The packet outgrew the buffer: its bytes are dropped until its end.
    overflowed: bool,
    /// The client switched acknowledgements off (QStartNoAckMode).
    no_ack: bool,
}

impl Framer {
    /// Whether acknowledgements are off.
    pub(super) fn no_ack(&self) -> bool {
        self.no_ack
    }

    /// The next byte.
    pub(super) fn push(&mut self, byte: u8) -> Option<Framed> {
        match self.state {
            State::Between => match byte {
                b'$' => {
                    self.state = State::Body;
                    self.packet.clear();
                    self.packet.push(byte);
                    self.overflowed = false;
                    None
                }
                b'+' | b'-' | 0x03 => Some(Framed::Byte(byte)),
                // Anything else between packets is noise, as GDB treats it.
                _ => None,
            },
            State::Body => {
                if byte == b'#' {
                    self.state = State::Checksum(0);
                }
                if self.packet.len() + 3 >= super::PACKET_SIZE {
                    self.overflowed = true;
                } else {
                    self.packet.push(byte);
                }
                None
            }
            State::Checksum(n) => {
                self.packet.push(byte);
                if n == 0 {
                    self.state = State::Checksum(1);
                    return None;
                }
                self.state = State::Between;
                let packet = std::mem::take(&mut self.packet);
                if self.overflowed {
                    let mut reply = if self.no_ack {
                        Vec::new()
                    } else {
                        b"+".to_vec()
                    };
                    reply.extend(packet_bytes(b"E.packet longer than PacketSize"));
                    return Some(Framed::Reply(reply));
                }
                let end = packet.len() - 3;
                let sum = packet[1..end].iter().fold(0u8, |a, b| a.wrapping_add(*b));
                let given = std::str::from_utf8(&packet[end + 1..])
                    .ok()
                    .and_then(|h| u8::from_str_radix(h, 16).ok());
                if given != Some(sum) {
                    // In no-ack mode the client does not retransmit: the packet is lost,
                    // as the protocol has it.
                    return (!self.no_ack).then(|| Framed::Reply(b"-".to_vec()));
                }
                if body(&packet) == b"QStartNoAckMode" {
                    self.no_ack = true;
                }
                Some(Framed::Packet(packet))
            }
        }
    }
}

/// A memory read (`m` or `x`) asks for at most what a reply packet holds: a longer one is
/// cut to that (the protocol lets a stub return fewer bytes than asked), so one request
/// never makes the server produce more than a packet.
pub(super) fn bound_read(packet: Vec<u8>) -> Vec<u8> {
    let body = body(&packet);
    let (Some(&kind @ (b'm' | b'x')), Ok(text)) = (body.first(), std::str::from_utf8(&body[1..]))
    else {
        return packet;
    };
    let Some((address, len)) = text.split_once(',') else {
        return packet;
    };
    // Hex digits, two per byte in an `m` reply; `x` is binary, but escapes may double it.
    let most = (super::PACKET_SIZE - 8) / 2;
    match usize::from_str_radix(len, 16) {
        Ok(n) if n > most => packet_bytes(format!("{}{address},{most:x}", kind as char).as_bytes()),
        _ => packet,
    }
}

/// The body of a framed packet.
pub(super) fn body(packet: &[u8]) -> &[u8] {
    packet
        .get(1..packet.len().saturating_sub(3))
        .unwrap_or_default()
}

/// `$body#cc`.
pub(super) fn packet(body: &[u8]) -> Vec<u8> {
    packet_bytes(body)
}

fn packet_bytes(body: &[u8]) -> Vec<u8> {
    let sum = body.iter().fold(0u8, |a, b| a.wrapping_add(*b));
    let mut out = Vec::with_capacity(body.len() + 4);
    out.push(b'$');
    out.extend_from_slice(body);
    out.extend_from_slice(format!("#{sum:02x}").as_bytes());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all(framer: &mut Framer, bytes: &[u8]) -> Vec<Framed> {
        bytes.iter().filter_map(|&b| framer.push(b)).collect()
    }

    #[test]
    fn packets_acks_and_interrupts_are_framed() {
        let mut f = Framer::default();
        let got = all(&mut f, b"+$g#67\x03junk-");
        assert_eq!(
            got,
            [
                Framed::Byte(b'+'),
                Framed::Packet(b"$g#67".to_vec()),
                Framed::Byte(3),
                Framed::Byte(b'-')
            ]
        );
    }

    #[test]
    fn a_bad_checksum_asks_again_and_an_overlong_packet_is_an_error() {
        let mut f = Framer::default();
        assert_eq!(all(&mut f, b"$g#00"), [Framed::Reply(b"-".to_vec())]);
        assert_eq!(all(&mut f, b"$g#zz"), [Framed::Reply(b"-".to_vec())]);
        let mut long = b"$m".to_vec();
        long.extend(std::iter::repeat_n(b'0', 10 * super::super::PACKET_SIZE));
        long.extend(b"#00");
        let got = all(&mut f, &long);
        assert_eq!(got.len(), 1);
        let Framed::Reply(reply) = &got[0] else {
            panic!("{got:?}")
        };
        assert!(reply.starts_with(b"+$E.packet longer"), "{reply:?}");
        // The framer is ready for the next packet.
        assert_eq!(all(&mut f, b"$?#3f"), [Framed::Packet(b"$?#3f".to_vec())]);
        assert_eq!(packet(b"OK"), b"$OK#9a");
        assert_eq!(body(b"$OK#9a"), b"OK");
    }

    #[test]
    fn no_ack_mode_is_noticed() {
        let mut f = Framer::default();
        let start = packet(b"QStartNoAckMode");
        assert_eq!(all(&mut f, &start), [Framed::Packet(start.clone())]);
        assert!(f.no_ack());
        assert_eq!(all(&mut f, b"$g#00"), []);
    }
}
