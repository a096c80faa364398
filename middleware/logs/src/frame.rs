//! One logged frame, whatever file it came from: the record every reader yields and
//! every writer takes, so the gateway handles a candump, ASC, BLF or MF4 log (or a live bus)
//! through the same code.

use std::fmt;

/// Which way the frame went, seen from the logging interface.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Direction {
    /// Received from the bus (the default: plain candump logs do not say).
    #[default]
    Rx,
    /// Transmitted by the logging interface itself.
    Tx,
}

/// What sort of frame it is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum FrameKind {
    /// A data frame.
    #[default]
    Data,
    /// A remote transmission request: a length (DLC) but no data.
    Remote,
    /// An error frame. Its `id` is what the format records: the SocketCAN error class
    /// bits for candump (`CAN_ERR_FLAG` removed), the CAN controller's identifier for
    /// BLF, 0 for ASC. Its data are the error details, if the format keeps any.
    Error,
}

/// The bits a CAN FD frame carries beyond a classic one.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct FdFlags {
    /// Bit rate switch: the data phase went at the faster data bit rate.
    pub brs: bool,
    /// Error state indicator: the sender was error passive.
    pub esi: bool,
}

/// A CAN frame (classic or CAN FD) with its time, channel and direction, as a log file
/// holds it.
///
/// The length, data and FD flags are private so that the length always suits the frame
/// (at most 8 bytes classic; 0 to 8, 12, 16, 20, 24, 32, 48 or 64 bytes CAN FD) and
/// [`LogFrame::data`] never panics; build frames with [`LogFrame::new`],
/// [`LogFrame::new_fd`], [`LogFrame::from_can`] or [`LogFrame::remote`].
#[derive(Clone, Copy, PartialEq, Eq, Hash)]
pub struct LogFrame {
    /// Time in microseconds, as the file gives it: Unix time for candump and BLF logs
    /// with a real start date, time since the start of the measurement for ASC. Integer,
    /// so a candump timestamp round-trips exactly.
    pub t_us: u64,
    /// Channel, counted from 0 (ASC and BLF channel 1 is 0 here; candump interfaces are
    /// numbered in order of first appearance).
    pub channel: u8,
    /// Identifier: 11 bits, or 29 bits when `extended` (see [`FrameKind::Error`] for
    /// error frames).
    pub id: u32,
    /// 29-bit identifier.
    pub extended: bool,
    /// Data, remote or error frame.
    pub kind: FrameKind,
    /// Received or transmitted.
    pub direction: Direction,
    len: u8,
    fd: Option<FdFlags>,
    data: [u8; 64],
}

/// Why a frame could not be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameError {
    /// The identifier does not fit 11 bits (standard) or 29 bits (extended, error).
    IdTooLarge {
        /// The identifier given.
        id: u32,
        /// Whether it was meant as a 29-bit identifier.
        extended: bool,
    },
    /// More than 8 data bytes (or a DLC above 8 for a remote frame).
    TooLong {
        /// The length given.
        len: usize,
    },
    /// A CAN FD frame whose length is not one a CAN FD DLC can say.
    NotFdLength {
        /// The length given.
        len: usize,
    },
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            FrameError::IdTooLarge {
                id,
                extended: false,
            } => write!(f, "identifier 0x{id:X} does not fit 11 bits"),
            FrameError::IdTooLarge { id, extended: true } => {
                write!(f, "identifier 0x{id:X} does not fit 29 bits")
            }
            FrameError::TooLong { len } => {
                write!(f, "{len} data bytes: a classic CAN frame carries at most 8")
            }
            FrameError::NotFdLength { len } => write!(
                f,
                "{len} data bytes: a CAN FD frame carries 0 to 8, 12, 16, 20, 24, 32, 48 or 64"
            ),
        }
    }
}

impl std::error::Error for FrameError {}

/// Largest standard identifier.
pub const MAX_STANDARD_ID: u32 = 0x7FF;
/// Largest extended identifier.
pub const MAX_EXTENDED_ID: u32 = 0x1FFF_FFFF;

/// Data length of each CAN FD DLC (ISO 11898-1:2015, table 5).
const FD_LENGTHS: [u8; 16] = [0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64];

/// The data length a DLC stands for: itself up to 8; for CAN FD 9 to 15 stand for 12 to 64
/// bytes, for classic CAN they mean 8.
pub fn dlc_to_len(dlc: u8, fd: bool) -> usize {
    let dlc = usize::from(dlc.min(15));
    if fd {
        usize::from(FD_LENGTHS[dlc])
    } else {
        dlc.min(8)
    }
}

/// The DLC that says `len` bytes, if there is one (0 to 8; 12 to 64 in CAN FD's steps).
pub fn len_to_dlc(len: usize) -> Option<u8> {
    FD_LENGTHS
        .iter()
        .position(|&l| usize::from(l) == len)
        .map(|dlc| dlc as u8)
}

impl LogFrame {
    /// A frame, checked: the identifier fits 11 bits (29 if `extended` or for an error
    /// frame) and there are at most 8 bytes. For a remote frame the length of `data` is
    /// the DLC and its contents are ignored. Direction is [`Direction::Rx`]; see
    /// [`LogFrame::with_direction`].
    pub fn new(
        t_us: u64,
        channel: u8,
        id: u32,
        extended: bool,
        kind: FrameKind,
        data: &[u8],
    ) -> Result<Self, FrameError> {
        let wide = extended || kind == FrameKind::Error;
        let max = if wide {
            MAX_EXTENDED_ID
        } else {
            MAX_STANDARD_ID
        };
        if id > max {
            return Err(FrameError::IdTooLarge { id, extended: wide });
        }
        if data.len() > 8 {
            return Err(FrameError::TooLong { len: data.len() });
        }
        let mut bytes = [0u8; 64];
        if kind != FrameKind::Remote {
            bytes[..data.len()].copy_from_slice(data);
        }
        Ok(Self {
            t_us,
            channel,
            id,
            extended,
            kind,
            direction: Direction::Rx,
            len: data.len() as u8,
            fd: None,
            data: bytes,
        })
    }

    /// A CAN FD data frame, checked: the identifier fits 11 bits (29 if `extended`) and
    /// the length is one a CAN FD DLC says (0 to 8, 12, 16, 20, 24, 32, 48 or 64).
    pub fn new_fd(
        t_us: u64,
        channel: u8,
        id: u32,
        extended: bool,
        data: &[u8],
        flags: FdFlags,
    ) -> Result<Self, FrameError> {
        if len_to_dlc(data.len()).is_none() {
            return Err(FrameError::NotFdLength { len: data.len() });
        }
        let max = if extended {
            MAX_EXTENDED_ID
        } else {
            MAX_STANDARD_ID
        };
        if id > max {
            return Err(FrameError::IdTooLarge { id, extended });
        }
        let mut bytes = [0u8; 64];
        bytes[..data.len()].copy_from_slice(data);
        Ok(Self {
            t_us,
            channel,
            id,
            extended,
            kind: FrameKind::Data,
            direction: Direction::Rx,
            len: data.len() as u8,
            fd: Some(flags),
            data: bytes,
        })
    }

    /// A remote frame asking for `dlc` bytes.
    pub fn remote(
        t_us: u64,
        channel: u8,
        id: u32,
        extended: bool,
        dlc: u8,
    ) -> Result<Self, FrameError> {
        if dlc > 8 {
            return Err(FrameError::TooLong {
                len: usize::from(dlc),
            });
        }
        Self::new(
            t_us,
            channel,
            id,
            extended,
            FrameKind::Remote,
            &[0u8; 8][..usize::from(dlc)],
        )
    }

    /// The frame of the AutoPlug bus (standard identifier, data), received.
    pub fn from_can(t_us: u64, channel: u8, frame: &autoplug_can::Frame) -> Self {
        let mut data = [0u8; 64];
        data[..frame.len()].copy_from_slice(frame.data());
        Self {
            t_us,
            channel,
            id: u32::from(frame.id()),
            extended: false,
            kind: FrameKind::Data,
            direction: Direction::Rx,
            len: frame.len() as u8,
            fd: None,
            data,
        }
    }

    /// The same frame with this direction.
    #[must_use]
    pub fn with_direction(mut self, direction: Direction) -> Self {
        self.direction = direction;
        self
    }

    /// The data bytes (empty for a remote frame, whose [`len`](Self::len) is the DLC).
    pub fn data(&self) -> &[u8] {
        match self.kind {
            FrameKind::Remote => &[],
            _ => &self.data[..usize::from(self.len)],
        }
    }

    /// Number of data bytes, or the requested length (DLC) of a remote frame.
    pub fn len(&self) -> usize {
        usize::from(self.len)
    }

    /// Whether the frame has length 0.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The CAN FD bits, `None` for a classic frame.
    pub fn fd(&self) -> Option<FdFlags> {
        self.fd
    }

    /// Whether it is a CAN FD frame (which a classic CAN bus cannot carry).
    pub fn is_fd(&self) -> bool {
        self.fd.is_some()
    }

    /// The DLC on the wire: the length itself up to 8, CAN FD's code above.
    pub fn dlc(&self) -> u8 {
        // Every length a frame can hold has a DLC (the constructors see to it).
        len_to_dlc(self.len()).unwrap_or(15)
    }

    /// The frame as the generated codec takes it: `Some` only for a classic data frame
    /// with a standard identifier (the AutoPlug bus uses no other).
    pub fn as_can_frame(&self) -> Option<autoplug_can::Frame> {
        if self.kind != FrameKind::Data || self.extended || self.fd.is_some() {
            return None;
        }
        autoplug_can::Frame::new(self.id, self.data()).ok()
    }
}

impl fmt::Debug for LogFrame {
    /// candump-like, with the rest spelled out: `12.000345 ch0 Rx 00C#0A141E28`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}.{:06} ch{} {:?} ",
            self.t_us / 1_000_000,
            self.t_us % 1_000_000,
            self.channel,
            self.direction
        )?;
        if self.extended {
            write!(f, "{:08X}x#", self.id)?;
        } else {
            write!(f, "{:03X}#", self.id)?;
        }
        if let Some(flags) = self.fd {
            write!(f, "#{:X}", u8::from(flags.brs) | u8::from(flags.esi) << 1)?;
        }
        match self.kind {
            FrameKind::Remote => write!(f, "R{}", self.len),
            FrameKind::Error | FrameKind::Data => {
                if self.kind == FrameKind::Error {
                    write!(f, "ERR:")?;
                }
                for b in self.data() {
                    write!(f, "{b:02X}")?;
                }
                Ok(())
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn construction_checks_id_and_length() {
        assert!(LogFrame::new(0, 0, 0x7FF, false, FrameKind::Data, &[]).is_ok());
        assert_eq!(
            LogFrame::new(0, 0, 0x800, false, FrameKind::Data, &[]),
            Err(FrameError::IdTooLarge {
                id: 0x800,
                extended: false
            })
        );
        assert!(LogFrame::new(0, 0, 0x1FFF_FFFF, true, FrameKind::Data, &[]).is_ok());
        assert!(LogFrame::new(0, 0, 0x2000_0000, true, FrameKind::Data, &[]).is_err());
        assert!(LogFrame::new(0, 0, 0x80, false, FrameKind::Error, &[]).is_ok());
        assert_eq!(
            LogFrame::new(0, 0, 1, false, FrameKind::Data, &[0; 9]),
            Err(FrameError::TooLong { len: 9 })
        );
        assert!(LogFrame::remote(0, 0, 1, false, 9).is_err());
    }

    #[test]
    fn fd_frames_take_fd_lengths_only() {
        let brs = FdFlags {
            brs: true,
            esi: false,
        };
        let f = LogFrame::new_fd(1, 0, 0x123, false, &[7; 12], brs).unwrap();
        assert_eq!(
            (f.len(), f.dlc(), f.fd(), f.is_fd()),
            (12, 9, Some(brs), true)
        );
        assert_eq!(f.data(), &[7; 12]);
        assert_eq!(f.as_can_frame(), None, "a classic bus cannot carry it");
        assert_eq!(
            format!("{f:?}"),
            "0.000001 ch0 Rx 123##1070707070707070707070707"
        );
        assert_eq!(
            LogFrame::new_fd(0, 0, 1, false, &[0; 9], brs),
            Err(FrameError::NotFdLength { len: 9 })
        );
        assert_eq!(
            LogFrame::new_fd(0, 0, 1, false, &[0; 65], brs)
                .unwrap_err()
                .to_string(),
            "65 data bytes: a CAN FD frame carries 0 to 8, 12, 16, 20, 24, 32, 48 or 64"
        );
        assert!(LogFrame::new_fd(0, 0, 0x800, false, &[], brs).is_err());
        assert!(LogFrame::new_fd(0, 0, 0x1FFF_FFFF, true, &[0; 64], brs).is_ok());
        let classic = LogFrame::new(0, 0, 1, false, FrameKind::Data, &[1, 2]).unwrap();
        assert_eq!((classic.fd(), classic.dlc()), (None, 2));
    }

    #[test]
    fn dlcs_and_lengths_convert_both_ways() {
        for dlc in 0..=15u8 {
            assert_eq!(len_to_dlc(dlc_to_len(dlc, true)), Some(dlc));
        }
        assert_eq!(dlc_to_len(13, false), 8);
        assert_eq!(dlc_to_len(13, true), 32);
        assert_eq!(len_to_dlc(9), None);
        assert_eq!(len_to_dlc(65), None);
    }

    #[test]
    fn remote_frames_have_a_length_but_no_data() {
        let r = LogFrame::remote(5, 1, 0x123, false, 4).unwrap();
        assert_eq!(r.len(), 4);
        assert!(r.data().is_empty());
        assert_eq!(r.as_can_frame(), None);
        assert_eq!(format!("{r:?}"), "0.000005 ch1 Rx 123#R4");
    }

    #[test]
    fn can_frames_convert_both_ways() {
        let frame = autoplug_can::Frame::new(0x00C, &[1, 2, 3]).unwrap();
        let f = LogFrame::from_can(7, 0, &frame);
        assert_eq!(f.data(), &[1, 2, 3]);
        assert_eq!(f.as_can_frame(), Some(frame));
        let ext = LogFrame::new(0, 0, 0x00C, true, FrameKind::Data, &[1]).unwrap();
        assert_eq!(
            ext.as_can_frame(),
            None,
            "extended ids are not the AutoPlug bus"
        );
        let err = LogFrame::new(0, 0, 0x00C, false, FrameKind::Error, &[1]).unwrap();
        assert_eq!(err.as_can_frame(), None);
        let tx = f.with_direction(Direction::Tx);
        assert_eq!(tx.direction, Direction::Tx);
        assert_eq!(format!("{tx:?}"), "0.000007 ch0 Tx 00C#010203");
    }
}
