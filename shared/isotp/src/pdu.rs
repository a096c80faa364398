//! The four N_PDU kinds of ISO 15765-2 on classic CAN with normal addressing: decoding a
//! frame's data field, and building the frames this side sends.

use autoplug_can::Frame;

/// Largest payload of a single frame (classic CAN, normal addressing).
pub(crate) const SINGLE_FRAME_MAX: usize = 7;
/// Payload bytes in a first frame with a 12-bit length.
pub(crate) const FIRST_FRAME_DATA: usize = 6;
/// Largest payload of a consecutive frame.
pub(crate) const CONSECUTIVE_FRAME_MAX: usize = 7;

const PCI_SINGLE: u8 = 0x0;
const PCI_FIRST: u8 = 0x1;
const PCI_CONSECUTIVE: u8 = 0x2;
const PCI_FLOW_CONTROL: u8 = 0x3;

/// The length a first frame announces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum FirstFrameLength {
    /// The 12-bit FF_DL, 8..=4095.
    Short(usize),
    /// The 32-bit escape (FF_DL = 0 followed by 4 length bytes), for PDUs beyond 4095.
    Escaped(u32),
}

/// A decoded N_PDU. Frames whose PCI does not fit their length are not PDUs at all.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Pdu<'a> {
    /// A complete PDU of 1..=7 bytes.
    Single(&'a [u8]),
    /// The start of a segmented PDU; `data` is the payload the frame carries.
    First {
        length: FirstFrameLength,
        data: &'a [u8],
    },
    /// A continuation; `data` is everything after the PCI byte, padding included, since
    /// only the receiver knows how many bytes are left.
    Consecutive { sequence_number: u8, data: &'a [u8] },
    /// The receiver's answer to a first frame or a block.
    FlowControl {
        status: u8,
        block_size: u8,
        st_min: u8,
    },
}

/// Decodes a frame's data field; `None` if it is no valid PDU (ISO 15765-2 has such
/// frames ignored).
pub(crate) fn decode(data: &[u8]) -> Option<Pdu<'_>> {
    let (&pci, rest) = data.split_first()?;
    match pci >> 4 {
        PCI_SINGLE => {
            // SF_DL 0 is the CAN FD escape, invalid on classic CAN.
            let length = usize::from(pci & 0x0F);
            if length == 0 || length > SINGLE_FRAME_MAX || length > rest.len() {
                return None;
            }
            Some(Pdu::Single(&rest[..length]))
        }
        PCI_FIRST => {
            // A first frame always fills a classic CAN frame.
            if data.len() != 8 {
                return None;
            }
            let short = usize::from(pci & 0x0F) << 8 | usize::from(data[1]);
            match short {
                0 => Some(Pdu::First {
                    length: FirstFrameLength::Escaped(u32::from_be_bytes([
                        data[2], data[3], data[4], data[5],
                    ])),
                    data: &data[6..],
                }),
                // A PDU this short belongs in a single frame.
                1..=SINGLE_FRAME_MAX => None,
                _ => Some(Pdu::First {
                    length: FirstFrameLength::Short(short),
                    data: &data[2..],
                }),
            }
        }
        PCI_CONSECUTIVE => Some(Pdu::Consecutive {
            sequence_number: pci & 0x0F,
            data: rest,
        }),
        PCI_FLOW_CONTROL => match rest {
            [block_size, st_min, ..] => Some(Pdu::FlowControl {
                status: pci & 0x0F,
                block_size: *block_size,
                st_min: *st_min,
            }),
            _ => None,
        },
        _ => None,
    }
}

/// The flow status of a flow control frame this side sends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub(crate) enum FlowStatus {
    /// FS 0: send the next block.
    ContinueToSend,
    /// FS 1: not ready, keep waiting.
    Wait,
    /// FS 2: the PDU does not fit, abort.
    Overflow,
}

impl FlowStatus {
    pub(crate) const fn code(self) -> u8 {
        match self {
            FlowStatus::ContinueToSend => 0,
            FlowStatus::Wait => 1,
            FlowStatus::Overflow => 2,
        }
    }
}

/// Up to 8 data bytes being assembled for a frame.
struct FrameBytes {
    bytes: [u8; 8],
    len: usize,
}

impl FrameBytes {
    fn with_pci(pci: &[u8]) -> Self {
        let mut frame = FrameBytes {
            bytes: [0; 8],
            len: 0,
        };
        frame.push(pci);
        frame
    }

    fn push(&mut self, data: &[u8]) {
        let end = self.len + data.len();
        self.bytes[self.len..end].copy_from_slice(data);
        self.len = end;
    }

    /// The frame, padded to 8 bytes if padding is configured. The identifier is masked to
    /// 11 bits and at most 8 bytes are ever pushed, so this is always `Some`; callers
    /// still build the frame before changing state, so even a failure could not corrupt it.
    fn finish(mut self, id: u16, padding: Option<u8>) -> Option<Frame> {
        if let Some(byte) = padding {
            self.bytes[self.len..].fill(byte);
            self.len = 8;
        }
        Frame::new(u32::from(id & Frame::MAX_ID), &self.bytes[..self.len]).ok()
    }
}

/// A single frame carrying `payload` (1..=7 bytes).
pub(crate) fn single_frame(id: u16, padding: Option<u8>, payload: &[u8]) -> Option<Frame> {
    let mut frame = FrameBytes::with_pci(&[PCI_SINGLE << 4 | payload.len() as u8]);
    frame.push(payload);
    frame.finish(id, padding)
}

/// A first frame announcing `total` bytes (8..=4095) and carrying the first 6.
pub(crate) fn first_frame(id: u16, total: usize, first: &[u8]) -> Option<Frame> {
    let mut frame =
        FrameBytes::with_pci(&[PCI_FIRST << 4 | (total >> 8) as u8 & 0x0F, total as u8]);
    frame.push(first);
    frame.finish(id, None)
}

/// A consecutive frame with sequence number `sequence_number` (0..=15) and 1..=7 bytes.
pub(crate) fn consecutive_frame(
    id: u16,
    padding: Option<u8>,
    sequence_number: u8,
    chunk: &[u8],
) -> Option<Frame> {
    let mut frame = FrameBytes::with_pci(&[PCI_CONSECUTIVE << 4 | sequence_number & 0x0F]);
    frame.push(chunk);
    frame.finish(id, padding)
}

/// A flow control frame.
pub(crate) fn flow_control(
    id: u16,
    padding: Option<u8>,
    status: FlowStatus,
    block_size: u8,
    st_min: u8,
) -> Option<Frame> {
    FrameBytes::with_pci(&[PCI_FLOW_CONTROL << 4 | status.code(), block_size, st_min])
        .finish(id, padding)
}
