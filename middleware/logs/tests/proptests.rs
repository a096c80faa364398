//! No input makes a reader panic or loop, and what the writers write reads back.

use std::io::Cursor;

use autoplug_logs::read::{AscReader, CandumpReader};
use autoplug_logs::{
    AscWriter, CandumpWriter, Direction, FdFlags, FrameKind, LogError, LogFormat, LogFrame,
    LogReader,
};
use proptest::prelude::*;

/// Reads everything, checking that a fatal error is the last item and that the count of
/// items stays within `max`.
fn drain(format: LogFormat, bytes: Vec<u8>, max: usize) -> Vec<Result<LogFrame, LogError>> {
    let Ok(reader) = LogReader::new(format, Box::new(Cursor::new(bytes))) else {
        return Vec::new();
    };
    let mut items = Vec::new();
    for item in reader {
        if let Some(Err(e)) = items.last() {
            let e: &LogError = e;
            assert!(!e.fatal, "an item after a fatal error");
        }
        items.push(item);
        assert!(items.len() <= max, "more items than the input can hold");
    }
    items
}

fn lines(count: usize) -> usize {
    count + 1
}

/// Lines that look like candump lines, often enough to reach every check.
fn candump_line() -> impl Strategy<Value = String> {
    prop_oneof![
        "\\([0-9]{1,12}\\.[0-9]{0,8}\\) (can|vcan)[0-9] [0-9A-F]{3}#[0-9A-F]{0,18}( [RT])?",
        "\\([0-9]{1,3}\\.[0-9]{6}\\) can[0-9] [0-9A-F]{8}#([0-9A-F]{0,16}|R[0-9]?)( [RT])?",
        "\\([0-9.]{0,8}\\)? ?[a-z0-9]{0,5} ?[0-9A-Fa-fRrxX#._]{0,24}( [RTX])?",
        ".{0,40}",
    ]
}

/// Lines that look like ASC lines.
fn asc_line() -> impl Strategy<Value = String> {
    prop_oneof![
        " {0,4}[0-9]{1,4}\\.[0-9]{1,7} [0-9]{1,3} {1,2}[0-9A-F]{1,8}x? +(Rx|Tx) +[dr] [0-9A-F]{0,2}( [0-9A-F]{2}){0,10}( Length = [0-9]+)?",
        " {0,4}[0-9.]{1,8} (CANFD|[0-9]{1,3}) +(ErrorFrame|Statistic:|[0-9A-Za-z]{0,9}) ?(Rx|Tx)? ?.{0,20}",
        "(date|base|Begin Triggerblock|End TriggerBlock|internal events logged|//) ?(hex|dec|[A-Za-z0-9: .]{0,20}) ?(timestamps)? ?(absolute|relative)?",
        ".{0,40}",
    ]
}

fn join(lines: Vec<String>, crlf: bool) -> Vec<u8> {
    lines.join(if crlf { "\r\n" } else { "\n" }).into_bytes()
}

fn frame_strategy() -> impl Strategy<Value = LogFrame> {
    (
        0u64..4_000_000_000_000_000,
        0u8..4,
        any::<bool>(),
        0u8..4,
        any::<bool>(),
        proptest::collection::vec(any::<u8>(), 0..=64),
        any::<u32>(),
        0u8..4,
    )
        .prop_map(
            |(t_us, channel, extended, kind, tx, mut data, id, fd_bits)| {
                let id = if extended {
                    id & 0x1FFF_FFFF
                } else {
                    id & 0x7FF
                };
                if kind != 3 {
                    data.truncate(8);
                }
                let frame = match kind {
                    3 => {
                        // CAN FD: cut to the nearest length a DLC can say.
                        let len = (0..=data.len())
                            .rev()
                            .find(|&n| autoplug_logs::len_to_dlc(n).is_some())
                            .unwrap_or(0);
                        let flags = FdFlags {
                            brs: fd_bits & 1 != 0,
                            esi: fd_bits & 2 != 0,
                        };
                        LogFrame::new_fd(t_us, channel, id, extended, &data[..len], flags)
                    }
                    0 => LogFrame::new(t_us, channel, id, extended, FrameKind::Data, &data),
                    1 => LogFrame::remote(t_us, channel, id, extended, data.len() as u8),
                    _ => LogFrame::new(
                        t_us,
                        channel,
                        id & 0x1FFF_FFFF,
                        false,
                        FrameKind::Error,
                        &data,
                    ),
                }
                .unwrap();
                frame.with_direction(if tx { Direction::Tx } else { Direction::Rx })
            },
        )
}

/// A BLF file of these frames written by hand (v1 headers, nanoseconds, one container):
/// CAN_MESSAGE for classic frames, CAN_FD_MESSAGE (as python-can writes them) for CAN FD.
fn blf_of(frames: &[LogFrame], zlib: bool) -> Vec<u8> {
    use std::io::Write;
    let mut inner = Vec::new();
    for f in frames {
        let mut body = Vec::new();
        body.extend_from_slice(&(u16::from(f.channel) + 1).to_le_bytes());
        body.push(
            u8::from(f.direction == Direction::Tx)
                | if f.kind == FrameKind::Remote { 0x80 } else { 0 },
        );
        body.push(f.dlc());
        body.extend_from_slice(&(f.id | if f.extended { 0x8000_0000 } else { 0 }).to_le_bytes());
        let kind = if let Some(fd) = f.fd() {
            // frame length u32, bit count u8, FD flags u8, valid bytes u8, reserved[5]
            body.extend_from_slice(&[0; 5]);
            body.push(1 | u8::from(fd.brs) << 1 | u8::from(fd.esi) << 2);
            body.push(f.len() as u8);
            body.extend_from_slice(&[0; 5]);
            let mut data = [0u8; 64];
            data[..f.len()].copy_from_slice(f.data());
            body.extend_from_slice(&data);
            100u32
        } else {
            let mut data = [0u8; 8];
            data[..f.data().len()].copy_from_slice(f.data());
            body.extend_from_slice(&data);
            1
        };
        let size = 32 + body.len();
        inner.extend_from_slice(b"LOBJ");
        inner.extend_from_slice(&32u16.to_le_bytes());
        inner.extend_from_slice(&1u16.to_le_bytes());
        inner.extend_from_slice(&(size as u32).to_le_bytes());
        inner.extend_from_slice(&kind.to_le_bytes());
        inner.extend_from_slice(&2u32.to_le_bytes());
        inner.extend_from_slice(&[0; 4]);
        inner.extend_from_slice(&(f.t_us * 1000).to_le_bytes());
        inner.extend_from_slice(&body);
    }
    let mut file = b"LOGG".to_vec();
    file.extend_from_slice(&144u32.to_le_bytes());
    file.resize(144, 0);
    let payload = if zlib {
        let mut e = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::fast());
        e.write_all(&inner).unwrap();
        e.finish().unwrap()
    } else {
        inner.clone()
    };
    let size = 32 + payload.len();
    file.extend_from_slice(b"LOBJ");
    file.extend_from_slice(&16u16.to_le_bytes());
    file.extend_from_slice(&1u16.to_le_bytes());
    file.extend_from_slice(&(size as u32).to_le_bytes());
    file.extend_from_slice(&10u32.to_le_bytes());
    file.extend_from_slice(&(if zlib { 2u16 } else { 0 }).to_le_bytes());
    file.extend_from_slice(&[0; 6]);
    file.extend_from_slice(&(inner.len() as u32).to_le_bytes());
    file.extend_from_slice(&[0; 4]);
    file.extend_from_slice(&payload);
    file.resize(file.len() + size % 4, 0);
    file
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn arbitrary_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2000)) {
        let newlines = bytes.iter().filter(|&&b| b == b'\n').count();
        drain(LogFormat::Candump, bytes.clone(), lines(newlines));
        drain(LogFormat::Asc, bytes.clone(), lines(newlines));
        drain(LogFormat::Blf, bytes.clone(), bytes.len() / 16 + 1);
        let mut blf = b"LOGG\x90\0\0\0".to_vec();
        blf.resize(144, 0);
        blf.extend_from_slice(&bytes);
        drain(LogFormat::Blf, blf, bytes.len() / 16 + 1);
    }

    #[test]
    fn arbitrary_candump_lines_never_panic(ls in proptest::collection::vec(candump_line(), 0..30), crlf in any::<bool>()) {
        let n = ls.len();
        let items = drain(LogFormat::Candump, join(ls, crlf), lines(n));
        for item in items {
            if let Err(e) = item {
                prop_assert!(e.line >= 1 && e.line as usize <= n && !e.fatal, "{}", e);
            }
        }
    }

    #[test]
    fn arbitrary_asc_lines_never_panic(ls in proptest::collection::vec(asc_line(), 0..30), crlf in any::<bool>()) {
        let n = ls.len();
        let items = drain(LogFormat::Asc, join(ls, crlf), lines(n));
        for item in items {
            if let Err(e) = item {
                prop_assert!(e.line >= 1 && e.line as usize <= n && !e.fatal, "{}", e);
            }
        }
    }

    #[test]
    fn damaged_blf_never_panics(
        frames in proptest::collection::vec(frame_strategy(), 0..20),
        zlib in any::<bool>(),
        flips in proptest::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..4),
        cut in any::<prop::sample::Index>(),
    ) {
        let frames: Vec<LogFrame> = frames.into_iter().filter(|f| f.kind != FrameKind::Error).collect();
        let mut bytes = blf_of(&frames, zlib);
        let items = drain(LogFormat::Blf, bytes.clone(), frames.len() + 1);
        let got: Vec<LogFrame> = items.into_iter().map(|f| f.unwrap()).collect();
        prop_assert_eq!(&got, &frames);
        for (at, value) in flips {
            let i = at.index(bytes.len());
            bytes[i] ^= value;
        }
        let len = cut.index(bytes.len() + 1);
        bytes.truncate(len);
        drain(LogFormat::Blf, bytes, frames.len() + 2);
    }

    #[test]
    fn candump_round_trip(frames in proptest::collection::vec(frame_strategy(), 0..40)) {
        let mut w = CandumpWriter::new(Vec::new()).with_direction(true);
        for f in &frames {
            w.write(f).unwrap();
        }
        let bytes = w.finish().unwrap();
        let mut reader = CandumpReader::new(&bytes[..]);
        let got: Vec<LogFrame> = reader.by_ref().map(|f| f.unwrap()).collect();
        // Channels come back numbered by first appearance of their interface.
        let names = reader.interfaces().to_vec();
        prop_assert_eq!(got.len(), frames.len());
        for (g, f) in got.iter().zip(&frames) {
            let mut g = *g;
            g.channel = names[usize::from(g.channel)][3..].parse().unwrap();
            prop_assert_eq!(g, *f);
        }
    }

    #[test]
    fn blf_round_trip(mut frames in proptest::collection::vec(frame_strategy(), 0..40)) {
        // BLF counts time up from the measurement start: a log in time order.
        frames.sort_by_key(|f| f.t_us);
        let mut w = autoplug_logs::BlfWriter::new(std::io::Cursor::new(Vec::new())).unwrap();
        for f in &frames {
            w.write(f).unwrap();
        }
        let bytes = w.finish().unwrap().into_inner();
        let got: Vec<LogFrame> = autoplug_logs::read::BlfReader::new(&bytes[..])
            .unwrap()
            .map(|f| f.unwrap())
            .collect();
        prop_assert_eq!(got.len(), frames.len());
        for (g, f) in got.iter().zip(&frames) {
            if f.kind == FrameKind::Error {
                // CAN_ERROR_EXT keeps no direction.
                prop_assert_eq!(*g, f.with_direction(Direction::Rx));
            } else {
                prop_assert_eq!(g, f);
            }
        }
    }

    #[test]
    fn mf4_round_trip(mut frames in proptest::collection::vec(frame_strategy(), 0..40), compress in any::<bool>()) {
        frames.sort_by_key(|f| f.t_us);
        let (summary, _) = autoplug_logs::export_mf4(frames.iter().map(|f| Ok(*f)), std::io::Cursor::new(Vec::new()), compress).unwrap();
        prop_assert_eq!(summary.frames, frames.len() as u64);
        let mut writer = autoplug_logs::Mf4Writer::new(std::io::Cursor::new(Vec::new()), compress).unwrap();
        for f in &frames {
            writer.write(f).unwrap();
        }
        let bytes = writer.finish().unwrap().into_inner();
        let got: Vec<LogFrame> = autoplug_logs::read::Mf4Reader::new(std::io::Cursor::new(bytes))
            .unwrap()
            .map(|f| f.unwrap())
            .collect();
        // One data group per frame type, merged by time: data, error, remote at a tie.
        let rank = |f: &LogFrame| match f.kind {
            FrameKind::Data => 0,
            FrameKind::Error => 1,
            FrameKind::Remote => 2,
        };
        let mut expected = frames.clone();
        expected.sort_by_key(|f| (f.t_us, rank(f)));
        prop_assert_eq!(got, expected);
    }

    #[test]
    fn asc_round_trip(frames in proptest::collection::vec(frame_strategy(), 0..40)) {
        let mut w = AscWriter::new(Vec::new());
        for f in &frames {
            w.write(f).unwrap();
        }
        let bytes = w.finish().unwrap();
        let got: Vec<LogFrame> = AscReader::new(&bytes[..]).map(|f| f.unwrap()).collect();
        prop_assert_eq!(got.len(), frames.len());
        let t0 = frames.first().map_or(0, |f| f.t_us);
        for (g, f) in got.iter().zip(&frames) {
            prop_assert_eq!(g.t_us, f.t_us.saturating_sub(t0));
            prop_assert_eq!((g.channel, g.kind), (f.channel, f.kind));
            if f.kind != FrameKind::Error {
                prop_assert_eq!((g.id, g.extended, g.direction, g.len(), g.data(), g.fd()), (f.id, f.extended, f.direction, f.len(), f.data(), f.fd()));
            }
        }
    }
}
