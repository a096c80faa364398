//! How long a frame occupies the wire: the exact bit sequence of a classic CAN base-format
//! data frame (ISO 11898-1), its bit stuffing, and the conversion between bits and
//! simulated nanoseconds.
//!
//! Layout of a data frame with `n` data bytes, in bits:
//!
//! ```text
//! SOF 1 | ID 11 | RTR 1 | IDE 1 | r0 1 | DLC 4 | data 8n | CRC 15   <- stuffed region, 34 + 8n
//! CRC delimiter 1 | ACK slot 1 | ACK delimiter 1 | EOF 7              <- tail, never stuffed, 10
//! intermission 3                                                     <- bus not yet free, 3
//! ```
//!
//! So an unstuffed frame costs `47 + 8n` bits including intermission (111 for 8 bytes),
//! and stuffing adds at most `floor((34 + 8n - 1) / 4)` bits (24 for 8 bytes): the first
//! stuff bit after 5 equal bits, every further one after 4 more, because a stuff bit
//! starts the next run.

use autoplug_can::Frame;

/// The AutoPlug bus bit rate (spec section 3), bit/s.
pub const DEFAULT_BITRATE: u32 = 500_000;

/// Bits of the stuffed region without data: SOF, identifier, RTR, IDE, r0, DLC, CRC.
pub const STUFFED_REGION_BASE_BITS: u32 = 1 + 11 + 1 + 1 + 1 + 4 + 15;
/// Bits after the CRC up to the end of the frame: CRC delimiter, ACK slot, ACK delimiter,
/// end of frame.
pub const TAIL_BITS: u32 = 1 + 1 + 1 + 7;
/// Recessive bits after end of frame before any node may start the next frame.
pub const INTERMISSION_BITS: u32 = 3;

const CRC15_POLY: u16 = 0x4599;

/// The length of one frame on the wire, in bit times.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FrameBits {
    /// Stuff bits inserted between SOF and the end of the CRC.
    pub stuff_bits: u32,
    /// SOF through end of frame, stuff bits included: the frame itself. A receiver takes
    /// the frame at the end of this.
    pub frame_len: u32,
    /// `frame_len` plus the 3-bit intermission: how long the frame keeps the bus from
    /// other frames, and what bus load counts.
    pub total_with_ifs: u32,
}

impl FrameBits {
    /// Bits of an unstuffed frame with `dlc` data bytes, intermission included (`47 + 8 dlc`).
    pub const fn unstuffed_with_ifs(dlc: usize) -> u32 {
        STUFFED_REGION_BASE_BITS + 8 * dlc as u32 + TAIL_BITS + INTERMISSION_BITS
    }

    /// Most stuff bits a frame with `dlc` data bytes can need.
    pub const fn max_stuff_bits(dlc: usize) -> u32 {
        (STUFFED_REGION_BASE_BITS + 8 * dlc as u32 - 1) / 4
    }

    /// Length of the stuffed region (SOF through CRC, stuff bits included).
    pub const fn stuffed_region(&self) -> u32 {
        self.frame_len - TAIL_BITS
    }
}

/// The exact length of `frame` on the wire, computed from its real bit sequence.
pub fn frame_bits(frame: &Frame) -> FrameBits {
    let stuff_bits = count_stuff_bits(&Region::of(frame));
    let frame_len = STUFFED_REGION_BASE_BITS + 8 * frame.len() as u32 + stuff_bits + TAIL_BITS;
    FrameBits {
        stuff_bits,
        frame_len,
        total_with_ifs: frame_len + INTERMISSION_BITS,
    }
}

/// The stuffed region of a frame (SOF through CRC) before stuffing, first bit on the
/// wire in the most significant bit. At most 98 bits. Dominant is 0, recessive 1.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) struct Region {
    bits: u128,
    len: u32,
}

impl Region {
    pub(crate) fn of(frame: &Frame) -> Self {
        // SOF, identifier, RTR, IDE, r0 (all dominant but the identifier's bits), DLC.
        let header = u32::from(frame.id()) << 7 | frame.len() as u32;
        // Leading zeros do not change a CRC that starts at 0, so five of them in front of
        // the 19 header bits make the message whole bytes for the table-driven CRC.
        let mut crc = 0;
        for &byte in header.to_be_bytes()[1..].iter().chain(frame.data()) {
            crc = crc15_update(crc, byte);
        }
        let mut region = Self { bits: 0, len: 0 };
        region.push_bits(header.into(), 19);
        for &byte in frame.data() {
            region.push_bits(byte.into(), 8);
        }
        region.push_bits(crc.into(), 15);
        region
    }

    /// Appends the low `count` bits of `value`, most significant first (CAN's bit order).
    fn push_bits(&mut self, value: u128, count: u32) {
        self.bits |= value << (128 - self.len - count);
        self.len += count;
    }

    pub(crate) fn get(&self, index: u32) -> bool {
        self.bits >> (127 - index) & 1 == 1
    }

    pub(crate) fn iter(&self) -> impl Iterator<Item = bool> + '_ {
        (0..self.len).map(|i| self.get(i))
    }
}

impl core::fmt::Debug for Region {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        for bit in self.iter() {
            f.write_str(if bit { "1" } else { "0" })?;
        }
        Ok(())
    }
}

const CRC15_TABLE: [u16; 256] = {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = (i as u16) << 7;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 0x4000 != 0 {
                (crc << 1) ^ CRC15_POLY
            } else {
                crc << 1
            } & 0x7FFF;
            bit += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
};

/// CRC-15/CAN (polynomial 0x4599, initial value 0, MSB first) over one more byte.
fn crc15_update(crc: u16, byte: u8) -> u16 {
    ((crc << 8) ^ CRC15_TABLE[usize::from((crc >> 7) as u8 ^ byte)]) & 0x7FFF
}

/// Stuffing state between bits: the last bit sent (stuff bits included) in bit 2 and
/// the length of its run, 1 to 4, as 0 to 3 in bits 0..=1. A run never rests at 5: the
/// stuff bit starts a run of 1 of the other value.
type StuffState = u8;

/// Before SOF the bus is idle (recessive), so SOF starts a run.
const STUFF_STATE_IDLE: StuffState = 0b100;

/// One bit through the stuffing rule: the next state and whether a stuff bit follows.
const fn stuff_step(state: StuffState, bit: bool) -> (StuffState, bool) {
    let last = state >> 2 == 1;
    let run = (state & 0b11) + 1;
    if bit != last {
        ((bit as u8) << 2, false)
    } else if run + 1 == 5 {
        ((!bit as u8) << 2, true)
    } else {
        ((bit as u8) << 2 | run, false)
    }
}

/// For every state and byte: the state after the byte (bits 0..=2) and the stuff bits
/// it needs (bits 3..), so stuffing costs one lookup per byte.
const STUFF_TABLE: [[u8; 256]; 8] = {
    let mut table = [[0u8; 256]; 8];
    let mut state = 0;
    while state < 8 {
        let mut byte = 0;
        while byte < 256 {
            let mut s = state as StuffState;
            let mut stuffed = 0;
            let mut bit = 8;
            while bit > 0 {
                bit -= 1;
                let (next, stuff) = stuff_step(s, byte >> bit & 1 == 1);
                s = next;
                stuffed += stuff as u8;
            }
            table[state][byte] = stuffed << 3 | s;
            byte += 1;
        }
        state += 1;
    }
    table
};

fn count_stuff_bits(region: &Region) -> u32 {
    let mut state = STUFF_STATE_IDLE;
    let mut stuff_bits = 0;
    let whole_bytes = region.len / 8;
    for i in 0..whole_bytes {
        let byte = (region.bits >> (120 - 8 * i)) as u8;
        let entry = STUFF_TABLE[usize::from(state)][usize::from(byte)];
        state = entry & 0b111;
        stuff_bits += u32::from(entry >> 3);
    }
    for i in whole_bytes * 8..region.len {
        let (next, stuff) = stuff_step(state, region.get(i));
        state = next;
        stuff_bits += u32::from(stuff);
    }
    stuff_bits
}

/// A test-only bit string long enough for a whole frame.
#[cfg(test)]
#[derive(Clone, PartialEq, Eq)]
struct BitSeq(Vec<bool>);

#[cfg(test)]
impl BitSeq {
    fn len(&self) -> u32 {
        self.0.len() as u32
    }

    fn get(&self, index: u32) -> bool {
        self.0[index as usize]
    }

    fn iter(&self) -> impl Iterator<Item = bool> + '_ {
        self.0.iter().copied()
    }
}

#[cfg(test)]
impl core::fmt::Debug for BitSeq {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        for &bit in &self.0 {
            f.write_str(if bit { "1" } else { "0" })?;
        }
        Ok(())
    }
}

/// CRC-15/CAN bit by bit, the textbook shift register: the reference for the table.
#[cfg(test)]
fn crc15(bits: impl Iterator<Item = bool>) -> u16 {
    let mut crc: u16 = 0;
    for bit in bits {
        let feedback = bit ^ (crc >> 14 & 1 == 1);
        crc = (crc << 1) & 0x7FFF;
        if feedback {
            crc ^= CRC15_POLY;
        }
    }
    crc
}

/// The frame exactly as a transmitter drives the wire, SOF through EOF (acknowledged, so
/// the ACK slot is dominant). Stuffs bit by bit, independently of the table above; the
/// tests decode it to prove the stuffing and compare lengths with `frame_bits`.
#[cfg(test)]
fn wire_bits(frame: &Frame) -> BitSeq {
    let region = Region::of(frame);
    let mut wire = Vec::new();
    let mut last = true; // idle bus
    let mut run = 0;
    for bit in region.iter() {
        wire.push(bit);
        if bit == last {
            run += 1;
        } else {
            last = bit;
            run = 1;
        }
        if run == 5 {
            wire.push(!bit);
            last = !bit;
            run = 1;
        }
    }
    // CRC delimiter, ACK slot (driven by the receivers), ACK delimiter, 7 × EOF.
    wire.extend([true, false, true, true, true, true, true, true, true, true]);
    BitSeq(wire)
}

/// Converts between bit times and simulated nanoseconds. Bit `b` starts at
/// `floor(b * 1e9 / bitrate)` ns; the grid is anchored at t = 0.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BitTiming {
    bitrate: u32,
    /// Nanoseconds per bit when the bit rate divides 1 s exactly (all the usual ones do),
    /// so the hot path avoids 128-bit division.
    exact_bit_ns: Option<u64>,
}

const NS_PER_S: u64 = 1_000_000_000;

impl BitTiming {
    /// Timing for `bitrate` bit/s.
    ///
    /// # Panics
    /// If `bitrate` is 0.
    pub fn new(bitrate: u32) -> Self {
        assert!(bitrate > 0, "a CAN bus needs a bit rate above 0 bit/s");
        let exact_bit_ns =
            (NS_PER_S % u64::from(bitrate) == 0).then(|| NS_PER_S / u64::from(bitrate));
        Self {
            bitrate,
            exact_bit_ns,
        }
    }

    /// Bit rate, bit/s.
    pub fn bitrate(&self) -> u32 {
        self.bitrate
    }

    /// Start of bit `bits`, in ns.
    pub fn bits_to_ns(&self, bits: u64) -> u64 {
        match self.exact_bit_ns {
            Some(bit_ns) => bits * bit_ns,
            None => (u128::from(bits) * u128::from(NS_PER_S) / u128::from(self.bitrate)) as u64,
        }
    }

    /// The first bit boundary at or after `ns`.
    pub fn ns_to_bits_ceil(&self, ns: u64) -> u64 {
        match self.exact_bit_ns {
            Some(bit_ns) => ns.div_ceil(bit_ns),
            None => {
                (u128::from(ns) * u128::from(self.bitrate)).div_ceil(u128::from(NS_PER_S)) as u64
            }
        }
    }

    /// Whole bit times in `ns`.
    pub fn ns_to_bits_floor(&self, ns: u64) -> u64 {
        match self.exact_bit_ns {
            Some(bit_ns) => ns / bit_ns,
            None => (u128::from(ns) * u128::from(self.bitrate) / u128::from(NS_PER_S)) as u64,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn frame(id: u32, data: &[u8]) -> Frame {
        Frame::new(id, data).unwrap()
    }

    fn bits_from_str(s: &str) -> Vec<bool> {
        s.chars().map(|c| c == '1').collect()
    }

    /// Reads a wire bit stream back into a frame, checking every rule a receiver checks:
    /// stuffing, CRC, the fixed-form bits, the length. Independent of the encoder above
    /// except for `crc15`, which has its own check value test.
    fn decode_wire(wire: &[bool]) -> Result<Frame, String> {
        struct Destuffer<'a> {
            wire: &'a [bool],
            pos: usize,
            last: Option<bool>,
            run: u32,
            raw: Vec<bool>,
        }
        impl Destuffer<'_> {
            fn next(&mut self) -> Result<bool, String> {
                if self.run == 5 {
                    let stuff = *self.wire.get(self.pos).ok_or("ends inside a stuff bit")?;
                    if Some(stuff) == self.last {
                        return Err(format!("stuff error at bit {}", self.pos));
                    }
                    self.pos += 1;
                    self.last = Some(stuff);
                    self.run = 1;
                }
                let bit = *self.wire.get(self.pos).ok_or("frame too short")?;
                self.pos += 1;
                if Some(bit) == self.last {
                    self.run += 1;
                } else {
                    self.last = Some(bit);
                    self.run = 1;
                }
                self.raw.push(bit);
                Ok(bit)
            }
            fn field(&mut self, width: u32) -> Result<u32, String> {
                let mut value = 0;
                for _ in 0..width {
                    value = value << 1 | u32::from(self.next()?);
                }
                Ok(value)
            }
        }
        let mut rx = Destuffer {
            wire,
            pos: 0,
            last: None,
            run: 0,
            raw: Vec::new(),
        };
        if rx.field(1)? != 0 {
            return Err("SOF must be dominant".into());
        }
        let id = rx.field(11)?;
        if rx.field(3)? != 0 {
            return Err("RTR, IDE, r0 must be dominant in a base data frame".into());
        }
        let dlc = rx.field(4)? as usize;
        let data: Vec<u8> = (0..dlc.min(8))
            .map(|_| rx.field(8).map(|b| b as u8))
            .collect::<Result<_, _>>()?;
        let crc_input = rx.raw.len();
        let crc = rx.field(15)? as u16;
        if crc15(rx.raw[..crc_input].iter().copied()) != crc {
            return Err("CRC error".into());
        }
        // A run of five ending the CRC is followed by a stuff bit too.
        if rx.run == 5 {
            let stuff = *wire.get(rx.pos).ok_or("missing stuff bit after CRC")?;
            if Some(stuff) == rx.last {
                return Err("stuff error after CRC".into());
            }
            rx.pos += 1;
        }
        let tail = &wire[rx.pos..];
        let expected_tail = bits_from_str("1011111111");
        if tail != expected_tail.as_slice() {
            return Err(format!("bad tail {tail:?}"));
        }
        Frame::new(id, &data).map_err(|e| e.to_string())
    }

    #[test]
    fn crc15_matches_the_catalogued_check_value() {
        // CRC-15/CAN of ASCII "123456789" is 0x059E (reveng CRC catalogue).
        let bits = b"123456789"
            .iter()
            .flat_map(|byte| (0..8).rev().map(move |i| byte >> i & 1 == 1));
        assert_eq!(crc15(bits), 0x059E);
        assert_eq!(
            b"123456789"
                .iter()
                .fold(0, |crc, &byte| crc15_update(crc, byte)),
            0x059E
        );
    }

    /// ID 0x000, 8 × 0x00, worked by hand. SOF, the 11 ID bits and RTR/IDE/r0 are 15
    /// dominant bits: three runs of 5, each followed by a recessive stuff bit. The stuff
    /// bit and the DLC's leading 1 make a recessive run of 2. Then DLC `000`, 64 data
    /// zeros and the CRC's two leading zeros are 69 dominant bits: 13 more stuff bits
    /// (13 × 5 = 65, 4 left over). The CRC 0x145B = `001010001011011` has no run of 5.
    /// 16 stuff bits: 98 + 16 + 10 = 124 bits, 127 with intermission.
    #[test]
    fn all_zero_frame_is_heavily_stuffed() {
        let f = frame(0x000, &[0; 8]);
        let region = Region::of(&f);
        assert_eq!(
            format!("{region:?}"),
            concat!(
                "000000000000000", // SOF, ID, RTR, IDE, r0
                "1000",            // DLC 8
                "0000000000000000000000000000000000000000000000000000000000000000",
                "001010001011011", // CRC 0x145B
            )
        );
        // Stuffed: the 15 leading zeros as 3 × "00000" + stuff "1"; the DLC's "1"; the
        // 69 zeros as 13 × "00000" + stuff "1" and 4 left over; the rest of the CRC; the
        // tail (CRC delimiter, dominant ACK slot, ACK delimiter, 7 × EOF).
        let expected = format!(
            "{}1{}0000{}{}",
            "000001".repeat(3),
            "000001".repeat(13),
            "1010001011011",
            "1011111111"
        );
        assert_eq!(format!("{:?}", wire_bits(&f)), expected);
        assert_eq!(
            frame_bits(&f),
            FrameBits {
                stuff_bits: 16,
                frame_len: 124,
                total_with_ifs: 127,
            }
        );
    }

    /// ID 0x2AA (`01010101010`), 8 × 0x55, worked by hand: the longest runs are SOF with
    /// the ID's leading 0 (2 bits), the ID's last 0 with RTR/IDE/r0 (4 bits), and DLC
    /// `1000`'s zeros with the first data bit (4 bits); CRC 0x251C = `010010100011100`
    /// has runs of at most 3. No stuff bit: the minimum, 47 + 64 = 111 bits.
    #[test]
    fn alternating_frame_needs_no_stuffing() {
        let f = frame(0x2AA, &[0x55; 8]);
        let region = Region::of(&f);
        assert_eq!(
            format!("{region:?}"),
            concat!(
                "0",
                "01010101010",
                "000",
                "1000",
                "0101010101010101010101010101010101010101010101010101010101010101",
                "010010100011100",
            )
        );
        assert_eq!(
            frame_bits(&f),
            FrameBits {
                stuff_bits: 0,
                frame_len: 108,
                total_with_ifs: 111,
            }
        );
    }

    /// ID 0x7FF, 8 × 0xFF: the recessive mirror image; CRC 0x4C89. 15 stuff bits.
    #[test]
    fn all_recessive_frame() {
        let f = frame(0x7FF, &[0xFF; 8]);
        assert_eq!(frame_bits(&f).stuff_bits, 15);
        assert_eq!(frame_bits(&f).total_with_ifs, 126);
    }

    #[test]
    fn bounds_per_dlc_match_the_textbook_formulas() {
        let expected = [
            (0, 47, 8),
            (1, 55, 10),
            (2, 63, 12),
            (3, 71, 14),
            (4, 79, 16),
            (8, 111, 24),
        ];
        for (dlc, unstuffed, max_stuff) in expected {
            assert_eq!(FrameBits::unstuffed_with_ifs(dlc), unstuffed, "dlc {dlc}");
            assert_eq!(FrameBits::max_stuff_bits(dlc), max_stuff, "dlc {dlc}");
        }
    }

    #[test]
    fn a_run_of_five_ending_the_crc_is_stuffed() {
        // Find a frame whose CRC ends in 5 equal bits and check the stuff bit is sent.
        let f = (0..=0x7FFu32)
            .map(|id| frame(id, &[]))
            .find(|f| {
                let region = Region::of(f);
                let n = region.len;
                let tail: Vec<bool> = (n - 5..n).map(|i| region.get(i)).collect();
                tail.iter().all(|&b| b == tail[0]) && region.get(n - 6) != tail[0]
            })
            .expect("some ID gives a CRC ending in a run of 5");
        let wire = wire_bits(&f);
        let region_end = wire.len() - TAIL_BITS;
        assert_ne!(
            wire.get(region_end - 1),
            wire.get(region_end - 2),
            "{wire:?}"
        );
        assert_eq!(decode_wire(&wire.iter().collect::<Vec<_>>()), Ok(f));
    }

    #[test]
    fn bit_timing_conversions() {
        let t = BitTiming::new(500_000);
        assert_eq!(t.bits_to_ns(111), 222_000);
        assert_eq!(t.ns_to_bits_ceil(0), 0);
        assert_eq!(t.ns_to_bits_ceil(1), 1);
        assert_eq!(t.ns_to_bits_ceil(2000), 1);
        assert_eq!(t.ns_to_bits_floor(3999), 1);
        // 83.333 kbit/s does not divide a second: 12 000.048 ns per bit.
        let odd = BitTiming::new(83_333);
        assert_eq!(odd.bits_to_ns(83_333), 1_000_000_000);
        assert_eq!(odd.ns_to_bits_ceil(1_000_000_000), 83_333);
        assert_eq!(odd.ns_to_bits_ceil(12_001), 2);
        assert_eq!(odd.ns_to_bits_floor(12_001), 1);
    }

    fn any_frame() -> impl Strategy<Value = Frame> {
        (0u32..=0x7FF, proptest::collection::vec(any::<u8>(), 0..=8))
            .prop_map(|(id, data)| Frame::new(id, &data).unwrap())
    }

    /// Frames biased towards long runs, where stuffing matters most.
    fn runny_frame() -> impl Strategy<Value = Frame> {
        (
            prop_oneof![Just(0u32), Just(0x7FF), 0u32..=0x7FF],
            proptest::collection::vec(
                prop_oneof![Just(0u8), Just(0xFF), Just(0x0F), Just(0xF0), any::<u8>()],
                0..=8,
            ),
        )
            .prop_map(|(id, data)| Frame::new(id, &data).unwrap())
    }

    proptest! {
        #[test]
        fn stuffed_length_is_within_bounds(f in prop_oneof![any_frame(), runny_frame()]) {
            let bits = frame_bits(&f);
            let unstuffed = FrameBits::unstuffed_with_ifs(f.len());
            prop_assert!(bits.total_with_ifs >= unstuffed);
            prop_assert!(bits.total_with_ifs <= unstuffed + FrameBits::max_stuff_bits(f.len()));
            prop_assert_eq!(bits.total_with_ifs, unstuffed + bits.stuff_bits);
            prop_assert_eq!(wire_bits(&f).len(), bits.frame_len);
        }

        #[test]
        fn wire_bits_decode_back_to_the_frame(f in prop_oneof![any_frame(), runny_frame()]) {
            let wire: Vec<bool> = wire_bits(&f).iter().collect();
            prop_assert_eq!(decode_wire(&wire), Ok(f));
            // Never six equal bits in the stuffed region (six recessive is EOF's job).
            let region = &wire[..wire.len() - TAIL_BITS as usize];
            prop_assert!(region.windows(6).all(|w| w.iter().any(|&b| b != w[0])), "{:?}", wire_bits(&f));
        }

        #[test]
        fn a_flipped_bit_is_detected(f in any_frame(), flip in 0usize..200) {
            let mut wire: Vec<bool> = wire_bits(&f).iter().collect();
            let region_len = wire.len() - TAIL_BITS as usize;
            let flip = flip % region_len;
            wire[flip] = !wire[flip];
            // One bit error in the stuffed region: a stuff, CRC or form error, or (when a
            // stuff bit is destroyed or created) a frame of another length, never the
            // same frame accepted silently.
            prop_assert_ne!(decode_wire(&wire), Ok(f));
        }
    }
}
