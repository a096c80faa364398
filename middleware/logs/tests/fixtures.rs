//! The readers against files python-can 4.6 wrote (tests/data/make_fixtures.py): the same
//! eight messages as candump, ASC and three kinds of BLF; and the MDF block layer on its
//! MF4.

use std::path::PathBuf;

use autoplug_logs::{open, Direction, FdFlags, FrameKind, LogError, LogFormat, LogFrame};

const T0: u64 = 1_700_000_000_000_000;

fn data(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(path)
}

fn read(name: &str, format: LogFormat) -> Vec<Result<LogFrame, LogError>> {
    let reader = open(data(name)).unwrap();
    assert_eq!(reader.format(), format);
    reader.collect()
}

fn frame(t_us: u64, channel: u8, id: u32, extended: bool, bytes: &[u8]) -> LogFrame {
    LogFrame::new(t_us, channel, id, extended, FrameKind::Data, bytes).unwrap()
}

/// What every format gives, with `t0` its time base, `remote_dlc` the remote frame's
/// length as the format keeps it and `error_id` its error frame's identifier.
fn expected(t0: u64, remote_dlc: u8, error_id: u32) -> Vec<LogFrame> {
    vec![
        frame(t0, 0, 0x00C, false, &[0x0A, 0x14, 0x1E, 0x28]),
        frame(t0 + 1_234, 0, 0x7FF, false, &[]),
        frame(t0 + 12_345, 1, 0x1ABC_DEF0, true, &[1, 2, 3, 4, 5, 6, 7, 8])
            .with_direction(Direction::Tx),
        LogFrame::remote(t0 + 100_000, 0, 0x123, false, remote_dlc).unwrap(),
        LogFrame::new(t0 + 200_000, 0, error_id, false, FrameKind::Error, &[]).unwrap(),
        LogFrame::new_fd(
            t0 + 300_000,
            0,
            0x456,
            false,
            &[0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11],
            FdFlags::default(),
        )
        .unwrap(),
        frame(t0 + 400_001, 0, 0x003, false, &[0x64]),
        frame(t0 + 1_500_000, 0, 0x123, true, &[0xFF]).with_direction(Direction::Tx),
    ]
}

/// Every item a frame, the CAN FD one (the sixth) among them, as expected.
fn check(got: Vec<Result<LogFrame, LogError>>, expected: Vec<LogFrame>) {
    let frames: Vec<LogFrame> = got.into_iter().map(|f| f.unwrap()).collect();
    assert_eq!(frames, expected);
}

#[test]
fn python_can_candump() {
    // CanutilsLogWriter writes remote frames without their DLC and error frames as
    // CAN_ERR_FLAG | CAN_ERR_BUSERROR.
    check(
        read("python-can.log", LogFormat::Candump),
        expected(T0, 0, 0x80),
    );
}

#[test]
fn python_can_asc() {
    // ASC times count from the start of the measurement.
    check(read("python-can.asc", LogFormat::Asc), expected(0, 4, 0));
}

#[test]
fn python_can_blf() {
    for name in [
        "python-can.blf",
        "python-can-stored.blf",
        "python-can-split.blf",
    ] {
        // python-can's error frame has its default `is_extended_id=True`, which BLF keeps.
        let mut expected = expected(T0, 4, 0);
        expected[4].extended = true;
        check(read(name, LogFormat::Blf), expected);
    }
}

/// python-can's MF4 (asammdf underneath: three sorted data groups, one per frame type,
/// transposed DZ blocks) and asammdf's saves of it with plain, deflate and transposed
/// data blocks: the same frames as python-can's other formats, merged in time order.
#[test]
fn python_can_and_asammdf_mf4() {
    for name in [
        "python-can.mf4",
        "asammdf-plain.mf4",
        "asammdf-deflate.mf4",
        "asammdf-transposed.mf4",
    ] {
        let mut expected = expected(T0, 4, 0);
        // python-can's error frame keeps its default `is_extended_id=True` (IDE 1).
        expected[4].extended = true;
        check(read(name, LogFormat::Mf4), expected);
    }
}

/// A damaged data group after good ones: their frames, then the damage, named.
#[test]
fn a_damaged_mf4_data_group_keeps_the_ones_before_it() {
    use autoplug_logs::mdf4::blocks::MdfBlocks;
    let mut bytes = std::fs::read(data("python-can.mf4")).unwrap();
    let (mut blocks, _) = MdfBlocks::open(std::io::Cursor::new(bytes.clone())).unwrap();
    let hd = blocks.block(64, &[b"HD"]).unwrap();
    let groups = blocks.chain(hd.link(0), 0, b"DG").unwrap();
    // The remote frames' data group (the third): its channel group link sent outside.
    let third = groups[2].header.at as usize;
    bytes[third + 24 + 8..third + 24 + 16].copy_from_slice(&u64::MAX.to_le_bytes());
    let got: Vec<_> =
        autoplug_logs::LogReader::seekable(LogFormat::Mf4, Box::new(std::io::Cursor::new(bytes)))
            .unwrap()
            .collect();
    let (last, frames) = got.split_last().unwrap();
    let mut expected = expected(T0, 4, 0);
    expected[4].extended = true;
    expected.retain(|f| f.kind != FrameKind::Remote);
    check(frames.to_vec(), expected);
    let e = last.as_ref().unwrap_err();
    assert!(e.fatal, "{e}");
    assert!(
        e.message
            .starts_with("##CG block at byte 18446744073709551615: a link"),
        "{e}"
    );
}

/// Every cut of python-can's MF4 and every byte flipped: an error naming a block, or the
/// frames before the damage, never a panic; what is read is what the file holds.
#[test]
fn truncated_and_corrupted_mf4_never_panic() {
    let good = std::fs::read(data("python-can.mf4")).unwrap();
    let all = expected(T0, 4, 0).len();
    for cut in 0..good.len() {
        let bytes = good[..cut].to_vec();
        match autoplug_logs::LogReader::seekable(
            LogFormat::Mf4,
            Box::new(std::io::Cursor::new(bytes)),
        ) {
            Err(e) => assert!(
                e.to_string().contains("block at byte") || e.to_string().contains("byte 0"),
                "{cut}: {e}"
            ),
            Ok(reader) => {
                let got: Vec<_> = reader.collect();
                assert!(got.len() <= all + 1, "{cut}");
                for item in &got[..got.len().saturating_sub(1)] {
                    assert!(item.as_ref().is_ok_and(|_| true) || !item.as_ref().unwrap_err().fatal);
                }
            }
        }
    }
    for at in 0..good.len() {
        let mut bytes = good.clone();
        bytes[at] ^= 0x55;
        if let Ok(reader) = autoplug_logs::LogReader::seekable(
            LogFormat::Mf4,
            Box::new(std::io::Cursor::new(bytes)),
        ) {
            let errors: Vec<LogError> = reader.filter_map(|f| f.err()).collect();
            assert!(errors.iter().filter(|e| e.fatal).count() <= 1);
        }
    }
}

#[test]
fn truncated_and_corrupted_blf_give_a_clear_error() {
    let good = std::fs::read(data("python-can.blf")).unwrap();
    for cut in 0..good.len() {
        let bytes = good[..cut].to_vec();
        match autoplug_logs::LogReader::new(LogFormat::Blf, Box::new(std::io::Cursor::new(bytes))) {
            Err(e) => assert!(cut < 144, "{cut}: {e}"),
            Ok(reader) => {
                let got: Vec<_> = reader.collect();
                if let Some(Err(e)) = got.last() {
                    if e.fatal {
                        assert!(e.message.contains("truncated"), "{cut}: {e}");
                    }
                }
            }
        }
    }
    for at in 144..good.len() {
        let mut bytes = good.clone();
        bytes[at] ^= 0x55;
        let reader =
            autoplug_logs::LogReader::new(LogFormat::Blf, Box::new(std::io::Cursor::new(bytes)))
                .unwrap();
        let errors: Vec<LogError> = reader.filter_map(|f| f.err()).collect();
        assert!(errors.iter().filter(|e| e.fatal).count() <= 1);
    }
}

/// The block layer of the MDF reader on python-can's MF4 (asammdf writes it): the header,
/// its data groups (data, error and remote frames, one each), and the bus-logging
/// channels of the first, composed under `CAN_DataFrame`, named as ASAM's bus-logging
/// standard names them.
#[test]
fn python_can_mf4_blocks() {
    use autoplug_logs::mdf4::blocks::{Block, MdfBlocks};
    let file = std::fs::File::open(data("python-can.mf4")).unwrap();
    let (mut blocks, id) = MdfBlocks::open(file).unwrap();
    assert_eq!((id.version, id.unfinalized), (410, None));
    let hd = blocks.block(64, &[b"HD"]).unwrap();
    let groups = blocks.chain(hd.link(0), 0, b"DG").unwrap();
    assert_eq!(groups.len(), 3);
    for dg in &groups {
        assert_eq!(blocks.chain(dg.link(1), 0, b"CG").unwrap().len(), 1);
    }
    let cg = blocks.block(groups[0].link(1), &[b"CG"]).unwrap();
    let channels = blocks.chain(cg.link(1), 0, b"CN").unwrap();
    let composed = blocks.chain(channels[1].link(1), 0, b"CN").unwrap();
    let mut names = |cns: &[Block]| -> Vec<String> {
        cns.iter()
            .map(|cn| {
                let tx = blocks.block(cn.link(2), &[b"TX"]).unwrap();
                String::from_utf8_lossy(&tx.data)
                    .trim_end_matches('\0')
                    .to_string()
            })
            .collect()
    };
    assert_eq!(names(&channels), ["time", "CAN_DataFrame"]);
    assert_eq!(
        names(&composed),
        [
            "CAN_DataFrame.BusChannel",
            "CAN_DataFrame.ID",
            "CAN_DataFrame.IDE",
            "CAN_DataFrame.DLC",
            "CAN_DataFrame.DataLength",
            "CAN_DataFrame.DataBytes",
            "CAN_DataFrame.Dir",
            "CAN_DataFrame.EDL",
            "CAN_DataFrame.BRS",
            "CAN_DataFrame.ESI"
        ]
    );
}
