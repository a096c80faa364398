//! The anti-rollback version floor as an ECU keeps it: a record of the ECU's persistent
//! state (`autoplug_flash::twin`), the latest one counting.

use crate::Version;

pub use autoplug_flash::twin::FLOOR_RECORD as KIND;

/// The record payload of `floor`: major, minor, patch (little-endian).
pub fn to_payload(floor: Version) -> [u8; 4] {
    let patch = floor.patch.to_le_bytes();
    [floor.major, floor.minor, patch[0], patch[1]]
}

/// The floor a record payload holds.
pub fn from_payload(payload: [u8; 4]) -> Version {
    Version::new(
        payload[0],
        payload[1],
        u16::from_le_bytes([payload[2], payload[3]]),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_floor_reads_back_from_its_payload() {
        for floor in [
            Version::new(1, 2, 300),
            Version::new(0, 0, 0),
            Version::new(255, 255, 65535),
        ] {
            assert_eq!(from_payload(to_payload(floor)), floor);
        }
        assert_eq!(to_payload(Version::new(1, 2, 0x0304)), [1, 2, 4, 3]);
    }
}
