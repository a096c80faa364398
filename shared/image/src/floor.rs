//! The anti-rollback version floor as an ECU keeps it in its ECU data sector: 8-byte
//! records appended one after the other (a flash word can be programmed once per erase),
//! the last valid one counting. The sector is erased only when full.

use crate::Version;

/// Bytes of one record.
pub const RECORD_LEN: usize = 8;

/// The first two bytes of a record.
const MAGIC: [u8; 2] = [0xA5, 0x5A];
/// The value of erased flash.
const ERASED: u8 = 0xFF;

/// What a record slot holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Record {
    /// Never written: the records end here.
    Erased,
    /// A floor.
    Floor(Version),
    /// Written but not a valid record (a write cut by a power loss): skipped.
    Invalid,
}

/// The record of `floor`: magic, major, minor, patch (little-endian), check, pad.
pub fn encode(floor: Version) -> [u8; RECORD_LEN] {
    let mut record = [0u8; RECORD_LEN];
    record[..2].copy_from_slice(&MAGIC);
    record[2] = floor.major;
    record[3] = floor.minor;
    record[4..6].copy_from_slice(&floor.patch.to_le_bytes());
    record[6] = check(&record);
    record
}

/// What a record slot holds.
pub fn decode(record: &[u8; RECORD_LEN]) -> Record {
    if record.iter().all(|&b| b == ERASED) {
        Record::Erased
    } else if record[..2] == MAGIC && record[6] == check(record) && record[7] == 0 {
        Record::Floor(Version::new(
            record[2],
            record[3],
            u16::from_le_bytes([record[4], record[5]]),
        ))
    } else {
        Record::Invalid
    }
}

fn check(record: &[u8; RECORD_LEN]) -> u8 {
    record[..6].iter().fold(0u8, |a, b| a.wrapping_add(*b)) ^ 0xFF
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_record_reads_back_and_damage_is_noticed() {
        let floor = Version::new(1, 2, 300);
        let record = encode(floor);
        assert_eq!(decode(&record), Record::Floor(floor));
        assert_eq!(decode(&[ERASED; RECORD_LEN]), Record::Erased);
        for byte in 0..RECORD_LEN {
            let mut damaged = record;
            damaged[byte] ^= 0x10;
            assert_eq!(decode(&damaged), Record::Invalid, "byte {byte}");
        }
        // A write cut half way: the rest still erased.
        let mut torn = [ERASED; RECORD_LEN];
        torn[..4].copy_from_slice(&record[..4]);
        assert_eq!(decode(&torn), Record::Invalid);
    }
}
