//! A classic CAN data frame with an 11-bit identifier: what travels between ECUs, the
//! simulated bus, log files and the gateway.

use core::fmt;

/// A classic CAN data frame, standard (11-bit) identifier, 0 to 8 data bytes.
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Frame {
    id: u16,
    len: u8,
    data: [u8; 8],
}

/// Why a frame could not be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// The identifier does not fit 11 bits.
    IdTooLarge {
        /// The identifier given.
        id: u32,
    },
    /// More than 8 data bytes.
    TooLong {
        /// The length given.
        len: usize,
    },
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            FrameError::IdTooLarge { id } => write!(
                f,
                "identifier 0x{id:X} does not fit 11 bits (the AutoPlug bus uses standard identifiers, 0x000..=0x7FF)"
            ),
            FrameError::TooLong { len } => {
                write!(f, "{len} data bytes: a classic CAN frame carries at most 8")
            }
        }
    }
}

impl Frame {
    /// Largest standard identifier.
    pub const MAX_ID: u16 = 0x7FF;

    /// A frame with this identifier and data.
    pub fn new(id: u32, data: &[u8]) -> Result<Self, FrameError> {
        if id > u32::from(Self::MAX_ID) {
            return Err(FrameError::IdTooLarge { id });
        }
        if data.len() > 8 {
            return Err(FrameError::TooLong { len: data.len() });
        }
        let mut bytes = [0u8; 8];
        bytes[..data.len()].copy_from_slice(data);
        Ok(Self {
            id: id as u16,
            len: data.len() as u8,
            data: bytes,
        })
    }

    /// A frame of the catalogue, whose identifier and length the generator has checked.
    pub(crate) fn from_catalogue(id: u16, data: &[u8]) -> Self {
        let mut bytes = [0u8; 8];
        let len = data.len().min(8);
        bytes[..len].copy_from_slice(&data[..len]);
        Self {
            id: id & Self::MAX_ID,
            len: len as u8,
            data: bytes,
        }
    }

    /// The 11-bit identifier.
    pub const fn id(&self) -> u16 {
        self.id
    }

    /// The data bytes.
    pub fn data(&self) -> &[u8] {
        &self.data[..usize::from(self.len)]
    }

    /// Number of data bytes (the DLC).
    pub const fn len(&self) -> usize {
        self.len as usize
    }

    /// Whether the frame carries no data.
    pub const fn is_empty(&self) -> bool {
        self.len == 0
    }
}

impl fmt::Debug for Frame {
    /// candump style: `00C#0A141E28`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:03X}#", self.id)?;
        for b in self.data() {
            write!(f, "{b:02X}")?;
        }
        Ok(())
    }
}

impl crate::Message {
    /// The message as a frame.
    pub fn to_frame(&self) -> Frame {
        let mut buf = [0u8; 8];
        let len = self.encode_into(&mut buf);
        Frame::from_catalogue(self.id(), &buf[..len])
    }

    /// Decodes a frame of the catalogue.
    pub fn from_frame(frame: &Frame) -> Result<Self, crate::DecodeError> {
        Self::decode(frame.id(), frame.data())
    }
}
