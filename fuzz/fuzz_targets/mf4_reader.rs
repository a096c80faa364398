//! The MF4 reader on damaged files: real ones (python-can's and asammdf's, plain and
//! compressed data blocks) with bytes changed and cut where the fuzzer says, or the input
//! itself when it starts like an MDF file. Reading never panics, never loops, keeps its
//! memory bounded, and ends with at most one fatal error.
//!
//! Input: a byte choosing the file, two bytes of where to cut it (little-endian; past
//! its end: not cut), then three-byte patches (offset u16, a byte to XOR there).
#![no_main]

use std::io::Cursor;

use autoplug_logs::read::Mf4Reader;
use libfuzzer_sys::fuzz_target;

const SEEDS: [&[u8]; 3] = [
    include_bytes!("../../middleware/logs/tests/data/python-can.mf4"),
    include_bytes!("../../middleware/logs/tests/data/asammdf-plain.mf4"),
    include_bytes!("../../middleware/logs/tests/data/asammdf-deflate.mf4"),
];

fuzz_target!(|data: &[u8]| {
    let file = if data.starts_with(b"MDF ") || data.starts_with(b"UnFinMF") {
        data.to_vec()
    } else {
        let Some((&seed, rest)) = data.split_first() else {
            return;
        };
        let mut file = SEEDS[usize::from(seed) % SEEDS.len()].to_vec();
        let (cut, patches) = rest.split_at(rest.len().min(2));
        for patch in patches.chunks_exact(3) {
            let at = usize::from(u16::from_le_bytes([patch[0], patch[1]]));
            if let Some(byte) = file.get_mut(at) {
                *byte ^= patch[2];
            }
        }
        if let [lo, hi] = cut {
            file.truncate(usize::from(u16::from_le_bytes([*lo, *hi])));
        }
        file
    };
    let Ok(reader) = Mf4Reader::new(Cursor::new(file)) else {
        return;
    };
    let mut fatal = false;
    for (n, item) in reader.enumerate() {
        assert!(!fatal, "an item after a fatal error");
        assert!(n < 10_000_000, "more items than the file can hold");
        if let Err(e) = item {
            fatal = e.fatal;
        }
    }
});
