//! Descriptions of messages and signals, generated into [`crate::MESSAGES`], for code that
//! handles any message generically.

use crate::codec::{self, DecodeError};
use crate::Node;
use autoplug_scaling::LinearScale;

/// What every generated message struct offers, for code generic over messages (transmit
/// schedulers, input monitors).
pub trait CanMessage: Sized + Copy + Default {
    /// CAN identifier.
    const ID: u16;
    /// Name in the DBC.
    const NAME: &'static str;
    /// Data length in bytes.
    const DLC: usize;
    /// Transmission period.
    const CYCLE_TIME_MS: u32;
    /// Shortest time between two transmissions.
    const MIN_GAP_MS: u32;
    /// Nodes that send it.
    const SENDERS: &'static [Node];
    /// Decodes a frame's data strictly (see the message's inherent `decode`).
    fn decode_data(data: &[u8]) -> Result<Self, DecodeError>;
    /// Updates valid signals, keeps the last good value of invalid ones.
    fn update_from_data(&mut self, data: &[u8]) -> Result<(), DecodeError>;
    /// The message as a frame.
    fn frame(&self) -> crate::Frame;
    /// The message in the catalogue-wide enum.
    fn into_message(self) -> crate::Message;
    /// This message out of the catalogue-wide enum, if it is this one.
    fn from_message(message: &crate::Message) -> Option<Self>;
}

/// How a signal's raw value is interpreted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SignalKind {
    /// A physical quantity: `raw * factor + offset`.
    Scaled,
    /// A one-bit flag.
    Bool,
    /// A value from a value table.
    Enum,
}

/// One signal of a message.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SignalSpec {
    /// Name in the DBC.
    pub name: &'static str,
    /// First bit (Intel numbering: bit 0 of byte 0 is 0).
    pub start_bit: u8,
    /// Length in bits.
    pub length: u8,
    /// Two's complement raw value.
    pub signed: bool,
    /// Conversion and valid raw range.
    pub scale: LinearScale,
    /// The DBC's factor at full precision, for host tools.
    pub factor: f64,
    /// The DBC's offset at full precision, for host tools.
    pub offset: f64,
    /// Unit text.
    pub unit: &'static str,
    /// Interpretation.
    pub kind: SignalKind,
    /// Value table, by raw value.
    pub values: &'static [(i64, &'static str)],
    /// Raw value assumed before the first frame.
    pub start_raw: i64,
    /// The signal's COVESA VSS path (DBC attribute `VssPath`): a standard path such as
    /// `Vehicle.Speed`, or one under the private branch `Vehicle.Private.AutoPlug` for
    /// what VSS has no path for. Empty for the diagnostic transport messages. The value
    /// keeps the DBC's unit and encoding.
    pub vss: &'static str,
    /// Nodes that use it.
    pub receivers: &'static [Node],
    /// DBC comment.
    pub comment: &'static str,
}

/// One message of the catalogue.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MessageSpec {
    /// 11-bit identifier.
    pub id: u16,
    /// Name in the DBC.
    pub name: &'static str,
    /// Data length in bytes.
    pub dlc: u8,
    /// Sending nodes.
    pub senders: &'static [Node],
    /// Transmission period.
    pub cycle_time_ms: u32,
    /// Shortest time between two transmissions.
    pub min_gap_ms: u32,
    /// Signals, in DBC order.
    pub signals: &'static [SignalSpec],
    /// DBC comment.
    pub comment: &'static str,
}

impl SignalSpec {
    /// Whether a raw value is valid for this signal.
    pub fn accepts_raw(&self, raw: i64) -> bool {
        match self.kind {
            SignalKind::Scaled => {
                raw >= i64::from(self.scale.raw_min()) && raw <= i64::from(self.scale.raw_max())
            }
            SignalKind::Bool => raw == 0 || raw == 1,
            SignalKind::Enum => self.values.iter().any(|(v, _)| *v == raw),
        }
    }

    /// The description of a raw value in the signal's value table.
    pub fn label(&self, raw: i64) -> Option<&'static str> {
        self.values.iter().find(|(v, _)| *v == raw).map(|(_, t)| *t)
    }

    /// The raw value of this signal in a frame's data (no validity check).
    pub fn raw_in(&self, bits: u64) -> i64 {
        codec::extract(
            bits,
            u32::from(self.start_bit),
            u32::from(self.length),
            self.signed,
        )
    }
}

impl MessageSpec {
    /// The description of the message with this identifier.
    pub fn by_id(id: u16) -> Option<&'static MessageSpec> {
        crate::MESSAGES.iter().find(|m| m.id == id)
    }

    /// The description of the message with this name.
    pub fn by_name(name: &str) -> Option<&'static MessageSpec> {
        crate::MESSAGES.iter().find(|m| m.name == name)
    }

    /// The signal with this name.
    pub fn signal(&self, name: &str) -> Option<&'static SignalSpec> {
        self.signals.iter().find(|s| s.name == name)
    }

    /// The bits that carry signals, as a little-endian word; the others are reserved and
    /// ignored by receivers.
    pub fn signal_bits(&self) -> u64 {
        self.signals.iter().fold(0, |acc, s| {
            acc | codec::insert(-1, u32::from(s.start_bit), u32::from(s.length))
        })
    }

    /// A signal's value as a number (see [`crate::Message::signal`]), decoded generically
    /// from a frame's data.
    pub fn decode_signal(&self, index: usize, data: &[u8]) -> Result<f32, DecodeError> {
        let bits = codec::load(data, usize::from(self.dlc), self.name)?;
        let Some(signal) = self.signals.get(index) else {
            return Err(DecodeError::UnknownId { id: self.id });
        };
        let raw = signal.raw_in(bits);
        match signal.kind {
            SignalKind::Scaled => codec::scaled(&signal.scale, raw, self.name, signal.name),
            _ if signal.accepts_raw(raw) => Ok(raw as f32),
            SignalKind::Bool | SignalKind::Enum => Err(DecodeError::UndefinedValue {
                message: self.name,
                signal: signal.name,
                raw,
            }),
        }
    }
}
