//! Image parsing and verification on arbitrary bytes: `ImageHeader::parse`, `check` and
//! `verify` never panic, and whatever `verify` accepts is exactly what its header
//! describes (with a key nobody holds, acceptance would be a forged signature).
#![no_main]

use autoplug_image::{
    verify, Expectations, ImageHeader, ImageSet, ImageSlot, SigningKey, StreamVerifier, Version,
    HEADER_LEN, NUCLEO_F446RE, SIGNATURE_LEN,
};
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;

/// A real public key whose secret the fuzzer does not have.
fn key() -> &'static [u8; 32] {
    static KEY: OnceLock<[u8; 32]> = OnceLock::new();
    KEY.get_or_init(|| SigningKey::from_seed([1; 32]).public_key())
}

fuzz_target!(|data: &[u8]| {
    // A release splits into images that lie back to back and cover the file exactly.
    if let Ok(set) = ImageSet::parse(data) {
        let total: usize = set.iter().map(|(image, _)| image.len()).sum();
        assert_eq!(total, data.len());
    }
    if let Ok(header) = ImageHeader::parse(data) {
        // A header that parses re-encodes to the same bytes.
        assert_eq!(&header.to_bytes()[..], &data[..HEADER_LEN]);
        let expected = Expectations {
            node: 0x0D,
            hardware_id: NUCLEO_F446RE,
            version_floor: Version::new(1, 0, 0),
            max_image_len: 128 * 1024,
            load_address: ImageSlot::B.vector_table(),
            runs_machine_code: data.get(HEADER_LEN).is_some_and(|b| b & 1 == 0),
        };
        let _ = header.check(&expected);
    }
    if let Ok(image) = verify(data, key()) {
        panic!("forged image accepted: {}", image.header());
    }
    // The streaming verifier agrees with `verify` on any input long enough to split.
    if data.len() >= HEADER_LEN + SIGNATURE_LEN {
        let split = data.len() - SIGNATURE_LEN;
        let mut stream = StreamVerifier::new();
        for chunk in data[..split].chunks(97) {
            stream.update(chunk);
        }
        let signature: [u8; SIGNATURE_LEN] = data[split..].try_into().unwrap();
        assert!(stream.finish(&signature, key()).is_err());
    }
});
