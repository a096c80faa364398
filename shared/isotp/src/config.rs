//! A channel's parameters: identifiers, padding, the flow control it advertises as
//! receiver, and the ISO 15765-2 timing parameters.

/// Minimum separation time between consecutive frames (ISO 15765-2 STmin), as the
/// receiver advertises it in its flow control frames.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StMin {
    /// 0 to 127 ms (bytes 0x00..=0x7F). Values above 127 are read as 127.
    Millis(u8),
    /// 1 to 9 hundreds of microseconds, 100 to 900 µs (bytes 0xF1..=0xF9). 0 is read as
    /// no gap; values above 9 are encoded as the next whole millisecond (see
    /// [`StMin::to_byte`]).
    Micros100(u8),
}

impl StMin {
    /// The longest separation time, which ISO 15765-2 also prescribes for reserved bytes.
    pub const LONGEST: StMin = StMin::Millis(127);

    /// Decodes the STmin byte of a flow control frame. Reserved values (0x80..=0xF0,
    /// 0xFA..=0xFF) are read as 127 ms, as ISO 15765-2 requires of a sender.
    pub const fn from_byte(byte: u8) -> StMin {
        match byte {
            0x00..=0x7F => StMin::Millis(byte),
            0xF1..=0xF9 => StMin::Micros100(byte - 0xF0),
            _ => StMin::LONGEST,
        }
    }

    /// Encodes for a flow control frame. A value the byte cannot express is rounded up to
    /// the next one it can (never down, so a peer never sends faster than asked):
    /// `Millis` above 127 → 0x7F, `Micros100(0)` → 0x00, `Micros100` above 9 → whole
    /// milliseconds.
    pub const fn to_byte(self) -> u8 {
        match self {
            StMin::Millis(ms) if ms <= 0x7F => ms,
            StMin::Millis(_) => 0x7F,
            StMin::Micros100(0) => 0x00,
            StMin::Micros100(n @ 1..=9) => 0xF0 + n,
            StMin::Micros100(n) => (n as u16 * 100).div_ceil(1000) as u8,
        }
    }

    /// The separation time in microseconds.
    pub const fn as_micros(self) -> u64 {
        match self {
            StMin::Millis(ms) if ms <= 0x7F => ms as u64 * 1000,
            StMin::Millis(_) => 127_000,
            StMin::Micros100(n) => n as u64 * 100,
        }
    }
}

/// ISO 15765-2 default for the N_As, N_Ar, N_Bs and N_Cr timeouts: 1000 ms.
pub const DEFAULT_TIMEOUT_US: u64 = 1_000_000;

/// Default interval between FC.WAIT frames (N_Br): 500 ms, half the peer's default N_Bs,
/// so each WAIT reaches the peer well before its N_Bs timer (restarted by the previous
/// one) runs out, even if the frame waits for the bus.
pub const DEFAULT_N_BR_US: u64 = 500_000;

/// Default block size advertised as receiver: 8 frames. It bounds a burst to 8 frames, so
/// a receiver that empties its CAN receive queue (16 frames in the AutoPlug firmware)
/// once per control step never overflows it, while each block still goes at bus speed.
pub const DEFAULT_BLOCK_SIZE: u8 = 8;

/// Default N_WFTmax: 10 FC.WAIT frames, i.e. about 5 s of "not ready" at the default
/// N_Br before a reception is refused.
pub const DEFAULT_MAX_WAIT_FRAMES: u8 = 10;

/// Default padding byte: 0xCC, the value ISO 15765-2 recommends (few stuff bits).
pub const DEFAULT_PADDING: u8 = 0xCC;

/// One channel's parameters. All times are in microseconds.
///
/// The timeouts follow ISO 15765-2: N_As / N_Ar run from handing a frame out
/// ([`crate::Channel::poll_transmit`]) to its confirmation
/// ([`crate::Channel::confirm_transmit`]); N_Bs from the confirmation of a first frame or of
/// the last consecutive frame of a block (or from a received FC.WAIT) to the next flow
/// control; N_Cr from the confirmation of a flow control (or from a consecutive frame) to
/// the next consecutive frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    /// Identifier this side sends on (11 bits; higher bits are ignored).
    pub tx_id: u16,
    /// Identifier this side receives on (physical addressing).
    pub rx_id: u16,
    /// Identifier of functional requests (e.g. 0x7DF): single frames only, delivered
    /// with `functional: true`.
    pub functional_rx_id: Option<u16>,
    /// `Some(byte)`: every frame this side sends is padded to 8 bytes with it; `None`:
    /// frames are as short as their content.
    pub padding: Option<u8>,
    /// Block size advertised as receiver: consecutive frames the peer sends before it
    /// waits for the next flow control (0: all of them, no further flow control).
    pub block_size: u8,
    /// Separation time advertised as receiver.
    pub st_min: StMin,
    /// N_As: a data frame (SF, FF, CF) handed out must be confirmed within this time.
    pub n_as_us: u64,
    /// N_Ar: a flow control frame handed out must be confirmed within this time.
    pub n_ar_us: u64,
    /// N_Bs: how long the sender waits for a flow control.
    pub n_bs_us: u64,
    /// N_Cr: how long the receiver waits for the next consecutive frame.
    pub n_cr_us: u64,
    /// N_Br: interval between FC.WAIT frames while the receiver is not ready.
    pub n_br_us: u64,
    /// N_WFTmax: FC.WAIT frames accepted in a row as sender (one more aborts the
    /// transmission) and sent in a row as receiver (then the reception is refused with
    /// FC.OVFLW).
    pub max_wait_frames: u8,
}

impl Config {
    /// A channel sending on `tx_id` and receiving on `rx_id`, with the ISO 15765-2
    /// default timeouts (1000 ms), N_Br 500 ms, N_WFTmax 10, padding with 0xCC, block
    /// size 8, STmin 0 and no functional identifier (see the crate documentation for why).
    pub const fn default_for(tx_id: u16, rx_id: u16) -> Config {
        Config {
            tx_id,
            rx_id,
            functional_rx_id: None,
            padding: Some(DEFAULT_PADDING),
            block_size: DEFAULT_BLOCK_SIZE,
            st_min: StMin::Millis(0),
            n_as_us: DEFAULT_TIMEOUT_US,
            n_ar_us: DEFAULT_TIMEOUT_US,
            n_bs_us: DEFAULT_TIMEOUT_US,
            n_cr_us: DEFAULT_TIMEOUT_US,
            n_br_us: DEFAULT_N_BR_US,
            max_wait_frames: DEFAULT_MAX_WAIT_FRAMES,
        }
    }
}
