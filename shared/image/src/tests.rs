//! Behaviour of the format: round trip, every refusal, streaming, an independent salty
//! check and key files. Keys come from fixed seeds, so every run is the same
//! (only `generate_gives_distinct_working_keys` reads the OS random source).

use super::*;
use proptest::prelude::*;

const CRUISE: u8 = 0x0D;
const ABS: u8 = 0x0E;
/// An image slot size for the tests: 128 KiB.
const SLOT: u32 = 128 * 1024;

fn key() -> SigningKey {
    SigningKey::from_seed([7; 32])
}

fn other_key() -> SigningKey {
    SigningKey::from_seed([8; 32])
}

fn payload(len: usize) -> Vec<u8> {
    // Not all one value, so that a swapped or shifted byte changes the digest.
    (0..len).map(|i| (i * 31 % 251) as u8).collect()
}

fn builder() -> ImageBuilder {
    let mut b = ImageBuilder::new(CRUISE, Version::new(1, 2, 3), payload(1000));
    b.build_id = *b"\x01\x23\x45\x67\x89\xab\xcd\xef\xfe\xdc\xba\x98\x76\x54\x32\x10";
    b.part_number = PartNumber::new("AP-CRUISE-0001").unwrap();
    b
}

fn image() -> Vec<u8> {
    builder().sign(&key()).unwrap()
}

fn expectations() -> Expectations {
    Expectations {
        node: CRUISE,
        hardware_id: NUCLEO_F446RE,
        version_floor: Version::new(1, 2, 3),
        max_image_len: SLOT,
        load_address: ImageSlot::A.vector_table(),
        runs_machine_code: true,
    }
}

/// Signs arbitrary header bytes, so that header refusals are shown to come from the
/// header check and not from a broken signature.
fn sign_raw(header: &[u8; HEADER_LEN], payload: &[u8], key: &SigningKey) -> Vec<u8> {
    let mut image = header.to_vec();
    image.extend_from_slice(payload);
    let digest = salty::Sha512::new().updated(&image).finalize();
    image.extend_from_slice(&key.sign(&digest));
    image
}

/// A signed image whose header has `edit` applied to its bytes.
fn image_with_header_edit(edit: impl FnOnce(&mut [u8; HEADER_LEN])) -> Vec<u8> {
    let b = builder();
    let mut header = b.header().unwrap().to_bytes();
    edit(&mut header);
    sign_raw(&header, &b.payload, &key())
}

fn hex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

// --- layout and round trip -------------------------------------------------------------

#[test]
fn header_bytes_sit_at_the_documented_offsets() {
    let mut h = builder().header().unwrap();
    h.variant = SoftwareVariant::Faulty;
    h.hardware_id = 0x1122_3344;
    h.version = Version::new(5, 6, 0x0708);
    h.payload_len = 0x0A0B_0C0D;
    h.load_address = 0x0802_0200;
    let b = h.to_bytes();
    assert_eq!(&b[0..8], b"APLGIMG1");
    assert_eq!(&b[8..10], &[1, 0]);
    assert_eq!(&b[10..12], &[0x00, 0x02]); // 512
    assert_eq!(b[12], CRUISE);
    assert_eq!(b[13], 1);
    assert_eq!(&b[14..16], &[0, 0]);
    assert_eq!(&b[16..20], &[0x44, 0x33, 0x22, 0x11]);
    assert_eq!(&b[20..24], &[5, 6, 0x08, 0x07]);
    assert_eq!(&b[24..28], &[0x0D, 0x0C, 0x0B, 0x0A]);
    assert_eq!(&b[28..32], &[0x00, 0x02, 0x02, 0x08]);
    assert_eq!(&b[32..48], &h.build_id);
    assert_eq!(&b[48..64], b"AP-CRUISE-0001\0\0");
    assert!(b[64..].iter().all(|&x| x == 0));
    assert_eq!(ImageHeader::parse(&b), Ok(h));
}

#[test]
fn round_trip_build_verify_gives_the_same_header_and_payload() {
    let b = builder();
    let image = image();
    assert_eq!(image.len(), 512 + 1000 + 64);
    let verified = verify(&image, &key().public_key()).unwrap();
    assert_eq!(*verified.header(), b.header().unwrap());
    assert_eq!(verified.payload(), &b.payload[..]);
    assert_eq!(verified.signature()[..], image[512 + 1000..]);
    assert_eq!(verified.header().check(&expectations()), Ok(()));
    assert_eq!(verified.header().signed_len(), 1512);
    assert_eq!(verified.header().image_len(), 1576);
}

#[test]
fn empty_payload_round_trips() {
    let image = ImageBuilder::new(ABS, Version::new(0, 0, 1), Vec::new())
        .sign(&key())
        .unwrap();
    assert_eq!(image.len(), OVERHEAD_LEN);
    let verified = verify(&image, &key().public_key()).unwrap();
    assert_eq!(verified.header().payload_len, 0);
    assert!(verified.payload().is_empty());
}

#[test]
fn signing_is_deterministic() {
    assert_eq!(image(), image());
}

// --- signature refusals ----------------------------------------------------------------

#[test]
fn another_key_is_refused() {
    assert_eq!(
        verify(&image(), &other_key().public_key()),
        Err(ImageError::BadSignature)
    );
    let signed_by_other = builder().sign(&other_key()).unwrap();
    assert_eq!(
        verify(&signed_by_other, &key().public_key()),
        Err(ImageError::BadSignature)
    );
}

#[test]
fn unsigned_image_is_refused() {
    let mut image = image();
    let n = image.len();
    // No signature at all: header and payload only.
    assert_eq!(
        verify(&image[..n - 64], &key().public_key()),
        Err(ImageError::Truncated {
            expected: n as u64,
            found: (n - 64) as u64
        })
    );
    // A blank signature in its place.
    image[n - 64..].fill(0);
    assert_eq!(
        verify(&image, &key().public_key()),
        Err(ImageError::BadSignature)
    );
    image[n - 64..].fill(0xFF);
    assert_eq!(
        verify(&image, &key().public_key()),
        Err(ImageError::BadSignature)
    );
}

#[test]
fn an_invalid_public_key_is_named() {
    let bad = not_a_curve_point();
    assert_eq!(verify(&image(), &bad), Err(ImageError::BadPublicKey));
}

/// 32 bytes that do not decode to a point of the curve (about half of all y values).
fn not_a_curve_point() -> [u8; 32] {
    (0u8..=255)
        .map(|i| [i; 32])
        .find(|k| salty::PublicKey::try_from(k).is_err())
        .expect("some [i; 32] is not a curve point")
}

#[test]
fn a_non_canonical_signature_scalar_is_refused() {
    let mut image = image();
    let n = image.len();
    // s + L encodes the same signature a second way (malleability); RFC 8032 refuses it.
    let mut carry = 0u16;
    for i in 0..32 {
        let sum = u16::from(image[n - 32 + i]) + u16::from(GROUP_ORDER[i]) + carry;
        image[n - 32 + i] = sum as u8;
        carry = sum >> 8;
    }
    assert_eq!(carry, 0);
    // salty alone takes it (so this check is ours, not the bootloader's)...
    let digest = salty::Sha512::new().updated(&image[..n - 64]).finalize();
    let sig: [u8; 64] = image[n - 64..].try_into().unwrap();
    let pk = salty::PublicKey::try_from(&key().public_key()).unwrap();
    assert!(pk.verify(&digest, &salty::Signature::from(&sig)).is_ok());
    // ...and `verify` refuses it.
    assert_eq!(
        verify(&image, &key().public_key()),
        Err(ImageError::BadSignature)
    );
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Any single flipped bit, in header, payload or signature, is refused: a header that
    /// no longer parses or whose length no longer matches is refused as such, anything
    /// else by the signature.
    #[test]
    fn any_flipped_bit_is_refused(position in 0usize..(512 + 1000 + 64), bit in 0u8..8) {
        let mut image = image();
        image[position] ^= 1 << bit;
        let result = verify(&image, &key().public_key());
        prop_assert!(result.is_err(), "flip at {position} bit {bit} accepted");
        if position >= HEADER_LEN {
            prop_assert_eq!(result, Err(ImageError::BadSignature));
        } else if ImageHeader::parse(&image).is_ok_and(|h| h.payload_len == 1000) {
            // The header is still well formed and consistent: only the signature can tell.
            prop_assert_eq!(result, Err(ImageError::BadSignature));
        }
    }

    /// The streaming verifier agrees with `verify`, whatever the chunking, for a good
    /// image and for one with a corrupted byte.
    #[test]
    fn streaming_matches_whole_image_verification(
        cuts in proptest::collection::vec(0usize..=1512, 0..12),
        corrupt in proptest::option::of((0usize..1576, 1u8..=255)),
    ) {
        let mut image = image();
        if let Some((at, mask)) = corrupt {
            image[at] ^= mask;
        }
        let whole = verify(&image, &key().public_key());

        let mut cuts = cuts;
        cuts.push(0);
        cuts.push(1512);
        cuts.sort_unstable();
        let mut stream = StreamVerifier::new();
        for pair in cuts.windows(2) {
            stream.update(&image[pair[0]..pair[1]]);
        }
        prop_assert_eq!(stream.bytes_hashed(), 1512);
        let signature: [u8; 64] = image[1512..].try_into().unwrap();
        let streamed = stream.finish(&signature, &key().public_key());

        match whole {
            Ok(_) => prop_assert_eq!(streamed, Ok(())),
            // A corrupted header may be refused by `verify` before hashing; the stream
            // only hashes, and must refuse by the signature.
            Err(_) => prop_assert_eq!(streamed, Err(ImageError::BadSignature)),
        }
        prop_assert_eq!(corrupt.is_none(), verify(&image, &key().public_key()).is_ok());
    }
}

// --- an independent check ---------------------------------------------------------------

#[test]
fn plain_salty_verifies_the_signature_over_any_chunking() {
    let image = image();
    let n = image.len();
    let update_len = n - 64;
    // salty's own API, without this crate's verifier: SHA-512 of the first `update_len`
    // bytes fed through a 2-byte chunk buffer (as a reader of flash may), then
    // `PublicKey::verify`.
    let mut hasher = salty::Sha512::new();
    for chunk in image[..update_len].chunks(2) {
        hasher.update(chunk);
    }
    let message = hasher.finalize();
    let mut one_shot = [0u8; 64];
    one_shot.copy_from_slice(
        &salty::Sha512::new()
            .updated(&image[..update_len])
            .finalize(),
    );
    assert_eq!(message, one_shot);

    let pk_bytes = key().public_key();
    let public_key = salty::PublicKey::try_from(&pk_bytes).unwrap();
    let sig_bytes: [u8; 64] = image[update_len..].try_into().unwrap();
    let signature = salty::Signature::from(&sig_bytes);
    assert!(public_key.verify(&message, &signature).is_ok());
    // And a payload change is caught by the same check.
    let mut altered = image.clone();
    altered[600] ^= 1;
    let message = salty::Sha512::new()
        .updated(&altered[..update_len])
        .finalize();
    assert!(public_key.verify(&message, &signature).is_err());
}

#[test]
fn sha512_and_ed25519_match_the_standard_vectors() {
    // FIPS 180-2 SHA-512("abc").
    let digest = salty::Sha512::new().updated(b"abc").finalize();
    assert_eq!(
        digest[..],
        hex(
            "ddaf35a193617abacc417349ae20413112e6fa4e89a97ea20a9eeee64b55d39a\
             2192992a274fc1a836ba3c23a3feebbd454d4423643ce80e2a9ac94fa54ca49f"
        )[..]
    );
    // RFC 8032 section 7.1, test 1 (empty message).
    let seed: [u8; 32] = hex("9d61b19deffd5a60ba844af492ec2cc44449c5697b326919703bac031cae7f60")
        .try_into()
        .unwrap();
    let key = SigningKey::from_seed(seed);
    assert_eq!(
        key.public_key()[..],
        hex("d75a980182b10ab7d54bfed3c964073a0ee172f3daa62325af021a68f707511a")[..]
    );
    assert_eq!(
        key.sign(b"")[..],
        hex("e5564300c360ac729086e2cc806e828a84877f1eb8e5d974d873e065224901555fb8821590a33bacc61e39701cf9b46bd25bf5f0595bbe24655141438e7a100b")[..]
    );
}

// --- length refusals -------------------------------------------------------------------

#[test]
fn truncated_images_are_refused() {
    let image = image();
    let n = image.len() as u64;
    let pk = key().public_key();
    for cut in [1usize, 63, 64, 65, 1000 + 64] {
        let short = &image[..image.len() - cut];
        assert_eq!(
            verify(short, &pk),
            Err(ImageError::Truncated {
                expected: n,
                found: n - cut as u64
            }),
            "cut {cut}"
        );
    }
    // Header only (512 bytes, below header + signature): still names the full length.
    assert_eq!(
        verify(&image[..512], &pk),
        Err(ImageError::Truncated {
            expected: n,
            found: 512
        })
    );
    // Less than a header: only the minimum is known.
    for len in [0usize, 1, 100, 511] {
        assert_eq!(
            verify(&image[..len], &pk),
            Err(ImageError::Truncated {
                expected: OVERHEAD_LEN as u64,
                found: len as u64
            })
        );
    }
    assert_eq!(
        ImageHeader::parse(&image[..511]),
        Err(ImageError::Truncated {
            expected: 512,
            found: 511
        })
    );
}

#[test]
fn trailing_bytes_are_refused() {
    let mut image = image();
    let n = image.len() as u64;
    image.push(0);
    assert_eq!(
        verify(&image, &key().public_key()),
        Err(ImageError::TrailingData {
            expected: n,
            found: n + 1
        })
    );
    image.extend_from_slice(&[0xFF; 100]);
    assert_eq!(
        verify(&image, &key().public_key()),
        Err(ImageError::TrailingData {
            expected: n,
            found: n + 101
        })
    );
}

#[test]
fn a_header_claiming_a_huge_payload_is_refused_without_overflow() {
    let image = image_with_header_edit(|h| h[24..28].copy_from_slice(&u32::MAX.to_le_bytes()));
    let expected = u64::from(u32::MAX) + 576;
    assert_eq!(
        verify(&image, &key().public_key()),
        Err(ImageError::Truncated {
            expected,
            found: image.len() as u64
        })
    );
    let header = ImageHeader::parse(&image).unwrap();
    assert_eq!(
        header.check(&expectations()),
        Err(ImageError::Oversized {
            max: SLOT.into(),
            found: expected
        })
    );
}

// --- checks against the ECU ------------------------------------------------------------

#[test]
fn an_image_for_another_ecu_is_refused() {
    let mut b = builder();
    b.node = ABS;
    let image = b.sign(&key()).unwrap();
    let header = *verify(&image, &key().public_key()).unwrap().header();
    let err = header.check(&expectations()).unwrap_err();
    assert_eq!(
        err,
        ImageError::WrongEcu {
            expected: CRUISE,
            found: ABS
        }
    );
    assert_eq!(
        err.to_string(),
        "image is for ECU node 0x0E (ABS), this ECU is node 0x0D (Cruise)"
    );
}

#[test]
fn an_image_for_other_hardware_is_refused() {
    let mut b = builder();
    b.hardware_id = 0x0421_0002;
    let header = b.header().unwrap();
    assert_eq!(
        header.check(&expectations()),
        Err(ImageError::WrongHardware {
            expected: NUCLEO_F446RE,
            found: 0x0421_0002
        })
    );
}

#[test]
fn an_image_linked_elsewhere_is_refused() {
    let mut b = builder();
    b.load_address = ImageSlot::A.region().start;
    assert_eq!(
        b.header().unwrap().check(&expectations()),
        Err(ImageError::WrongLoadAddress {
            expected: 0x0802_0200,
            found: 0x0802_0000
        })
    );
}

#[test]
fn anti_rollback_refuses_below_the_floor_only() {
    let floor = Version::new(1, 2, 3);
    let check = |version: Version| {
        let mut b = builder();
        b.version = version;
        b.header().unwrap().check(&expectations())
    };
    for lower in [
        Version::new(1, 2, 2),
        Version::new(1, 1, 9999),
        Version::new(0, 255, 65535),
    ] {
        assert_eq!(
            check(lower),
            Err(ImageError::Downgrade {
                floor,
                found: lower
            })
        );
    }
    assert_eq!(check(floor), Ok(()));
    for higher in [
        Version::new(1, 2, 4),
        Version::new(1, 3, 0),
        Version::new(2, 0, 0),
    ] {
        assert_eq!(check(higher), Ok(()));
    }
}

#[test]
fn an_image_larger_than_the_slot_is_refused_and_an_exact_fit_accepted() {
    let exact = SLOT as usize - OVERHEAD_LEN;
    let mut b = builder();
    b.payload = payload(exact);
    assert_eq!(b.header().unwrap().check(&expectations()), Ok(()));
    b.payload = payload(exact + 1);
    assert_eq!(
        b.header().unwrap().check(&expectations()),
        Err(ImageError::Oversized {
            max: SLOT.into(),
            found: u64::from(SLOT) + 1
        })
    );
}

// --- header refusals (signed correctly, so the header check is what refuses) -----------

#[test]
fn a_non_zero_reserved_byte_is_refused() {
    for offset in [64usize, 200, 511] {
        let image = image_with_header_edit(|h| h[offset] = 0x01);
        assert_eq!(
            verify(&image, &key().public_key()),
            Err(ImageError::ReservedNotZero { offset })
        );
    }
}

#[test]
fn an_unknown_variant_is_refused() {
    let image = image_with_header_edit(|h| h[13] = 2);
    assert_eq!(
        verify(&image, &key().public_key()),
        Err(ImageError::UnknownVariant(2))
    );
    assert_eq!(SoftwareVariant::try_from(1), Ok(SoftwareVariant::Faulty));
    assert_eq!(
        SoftwareVariant::try_from(255),
        Err(ImageError::UnknownVariant(255))
    );
}

#[test]
fn bad_magic_format_size_and_flags_are_refused() {
    let pk = key().public_key();
    let image = image_with_header_edit(|h| h[0..8].copy_from_slice(b"APLGIMG2"));
    assert_eq!(
        verify(&image, &pk),
        Err(ImageError::BadMagic {
            found: *b"APLGIMG2"
        })
    );
    let image = image_with_header_edit(|h| h[8] = 2);
    assert_eq!(verify(&image, &pk), Err(ImageError::UnsupportedFormat(2)));
    let image = image_with_header_edit(|h| h[10..12].copy_from_slice(&256u16.to_le_bytes()));
    assert_eq!(
        verify(&image, &pk),
        Err(ImageError::BadHeaderSize { found: 256 })
    );
    let image = image_with_header_edit(|h| h[15] = 0x80);
    assert_eq!(verify(&image, &pk), Err(ImageError::NonZeroFlags(0x8000)));
}

#[test]
fn a_malformed_part_number_is_refused() {
    // Text after the NUL padding would be hidden from a reader that stops at the NUL.
    let image = image_with_header_edit(|h| h[48 + 15] = b'X');
    assert_eq!(
        verify(&image, &key().public_key()),
        Err(ImageError::BadPartNumber {
            position: 15,
            byte: b'X'
        })
    );
    let image = image_with_header_edit(|h| h[48 + 2] = 0x07);
    assert_eq!(
        verify(&image, &key().public_key()),
        Err(ImageError::BadPartNumber {
            position: 2,
            byte: 0x07
        })
    );
    assert_eq!(
        PartNumber::new("AP-CRUISE-0001-XYZ"),
        Err(ImageError::PartNumberTooLong { len: 18 })
    );
    assert_eq!(
        PartNumber::new("AP-CRÜISE"),
        Err(ImageError::BadPartNumber {
            position: 5,
            byte: 0xC3
        })
    );
    assert_eq!(
        PartNumber::new("AP-CRUISE-0001").unwrap().as_str(),
        "AP-CRUISE-0001"
    );
    assert_eq!(
        PartNumber::new("0123456789ABCDEF").unwrap().as_str().len(),
        16
    );
    assert_eq!(PartNumber::new("").unwrap(), PartNumber::default());
}

// --- versions and text -----------------------------------------------------------------

#[test]
fn versions_order_and_print() {
    assert!(Version::new(1, 2, 3) < Version::new(1, 10, 0));
    assert!(Version::new(1, 10, 0) < Version::new(2, 0, 0));
    assert!(Version::new(1, 2, 300) > Version::new(1, 2, 29));
    assert_eq!(Version::new(1, 2, 3).to_string(), "1.2.3");
    assert_eq!("1.2.3".parse(), Ok(Version::new(1, 2, 3)));
    assert_eq!("255.255.65535".parse(), Ok(Version::new(255, 255, 65535)));
    assert_eq!(
        "1.2".parse::<Version>(),
        Err(ParseVersionError::FieldCount(2))
    );
    assert_eq!(
        "1.256.0".parse::<Version>(),
        Err(ParseVersionError::BadField {
            field: "minor",
            max: 255
        })
    );
    assert_eq!(
        "1.2.+3".parse::<Version>(),
        Err(ParseVersionError::BadField {
            field: "patch",
            max: 65535
        })
    );
    assert_eq!(
        "1.2.70000".parse::<Version>().unwrap_err().to_string(),
        "the patch part of the version is not a decimal number from 0 to 65535"
    );
}

#[test]
fn header_display_is_what_inspect_prints() {
    let mut h = builder().header().unwrap();
    h.variant = SoftwareVariant::Faulty;
    assert_eq!(
        h.to_string(),
        "ECU node:       0x0D (Cruise)\n\
         Variant:        faulty (demonstration)\n\
         Hardware:       0x04210001 (NUCLEO-F446RE)\n\
         Version:        1.2.3\n\
         Payload length: 1000 bytes\n\
         Load address:   0x08020200\n\
         Build id:       0123456789abcdeffedcba9876543210\n\
         Part number:    AP-CRUISE-0001"
    );
}

#[test]
fn errors_name_the_field_and_values() {
    let cases = [
        (
            ImageError::BadMagic {
                found: *b"ELF\0\0\0\0\0",
            },
            "magic is 454c460000000000, expected \"APLGIMG1\"",
        ),
        (ImageError::UnsupportedFormat(3), "format version 3"),
        (
            ImageError::BadHeaderSize { found: 256 },
            "header size field is 256, expected 512",
        ),
        (ImageError::ReservedNotZero { offset: 77 }, "offset 77"),
        (ImageError::UnknownVariant(9), "unknown software variant 9"),
        (
            ImageError::NonZeroFlags(0x8001),
            "flags 0x8000 are not defined",
        ),
        (ImageError::NoMachineCode, "no machine code"),
        (
            ImageError::NotStartable {
                initial_sp: 0xFFFF_FFFF,
                reset: 0xFFFF_FFFF,
            },
            "bootloader would never run it",
        ),
        (
            ImageError::WrongHardware {
                expected: 1,
                found: 2,
            },
            "hardware id 0x00000002, this board is 0x00000001",
        ),
        (
            ImageError::Downgrade {
                floor: Version::new(2, 0, 0),
                found: Version::new(1, 9, 9),
            },
            "version 1.9.9 is below this ECU's anti-rollback floor 2.0.0",
        ),
        (
            ImageError::Truncated {
                expected: 1576,
                found: 1575,
            },
            "truncated: 1575 bytes, expected 1576",
        ),
        (
            ImageError::TrailingData {
                expected: 1576,
                found: 1580,
            },
            "4 trailing byte(s)",
        ),
        (
            ImageError::Oversized {
                max: 100,
                found: 200,
            },
            "200 bytes, the slot takes at most 100",
        ),
        (ImageError::BadSignature, "signature does not match"),
        (ImageError::BadPublicKey, "not a valid Ed25519 public key"),
    ];
    for (error, text) in cases {
        let shown = error.to_string();
        assert!(shown.contains(text), "{shown:?} lacks {text:?}");
    }
}

// --- keys and key files ----------------------------------------------------------------

#[test]
fn key_files_round_trip() {
    let key = key();
    let secret = key.to_file_string();
    assert!(secret.starts_with("autoplug-ed25519-secret-v1 "));
    assert_eq!(secret.len(), SECRET_KEY_TAG.len() + 1 + 64 + 1);
    assert_eq!(SigningKey::parse(&secret).unwrap().seed(), key.seed());

    let public = key.public_key_file_string();
    assert_eq!(public, public_key_to_file_string(&key.public_key()));
    assert!(public.starts_with("autoplug-ed25519-public-v1 "));
    assert_eq!(parse_public_key(&public), Ok(key.public_key()));

    // What editors do to a one-line file is harmless: no final newline, CRLF, upper case.
    assert_eq!(parse_public_key(public.trim_end()), Ok(key.public_key()));
    assert_eq!(
        parse_public_key(&public.replace('\n', "\r\n")),
        Ok(key.public_key())
    );
    let upper = format!(
        "{PUBLIC_KEY_TAG} {}",
        public.trim_end()[PUBLIC_KEY_TAG.len() + 1..].to_uppercase()
    );
    assert_eq!(parse_public_key(&upper), Ok(key.public_key()));
}

#[test]
fn key_file_errors_say_what_is_wrong() {
    let key = key();
    let secret = key.to_file_string();
    let public = key.public_key_file_string();

    assert_eq!(
        SigningKey::parse(&public).unwrap_err(),
        KeyFileError::WrongKind {
            expected: KeyKind::Secret,
            found: KeyKind::Public
        }
    );
    let err = parse_public_key(&secret).unwrap_err();
    assert_eq!(
        err,
        KeyFileError::WrongKind {
            expected: KeyKind::Public,
            found: KeyKind::Secret
        }
    );
    assert!(err.to_string().contains("this is a secret key file"));

    assert_eq!(
        parse_public_key("").unwrap_err(),
        KeyFileError::Empty {
            expected: KeyKind::Public
        }
    );
    assert_eq!(
        parse_public_key("ssh-ed25519 AAAAC3Nza").unwrap_err(),
        KeyFileError::UnknownTag {
            expected: KeyKind::Public,
            found: "ssh-ed25519".into()
        }
    );

    // A 'g' as the fifth hex digit: column = tag (26) + space (1) + 5.
    let mut bad = public.clone().into_bytes();
    bad[PUBLIC_KEY_TAG.len() + 1 + 4] = b'g';
    let err = parse_public_key(std::str::from_utf8(&bad).unwrap()).unwrap_err();
    assert_eq!(
        err,
        KeyFileError::NonHex {
            position: 32,
            character: 'g'
        }
    );
    assert_eq!(
        err.to_string(),
        "non-hex character 'g' at position 32 of the key line"
    );

    let short = &public.trim_end()[..public.trim_end().len() - 2];
    assert_eq!(
        parse_public_key(short).unwrap_err(),
        KeyFileError::WrongLength {
            expected: 64,
            found: 62
        }
    );
    assert_eq!(
        SigningKey::parse(&format!("{}00", secret.trim_end())).unwrap_err(),
        KeyFileError::WrongLength {
            expected: 64,
            found: 66
        }
    );
    assert_eq!(
        parse_public_key(PUBLIC_KEY_TAG).unwrap_err(),
        KeyFileError::WrongLength {
            expected: 64,
            found: 0
        }
    );
    assert_eq!(
        parse_public_key(&format!("{public}\n{public}")).unwrap_err(),
        KeyFileError::TrailingText { line: 3 }
    );

    let invalid = public_key_to_file_string(&not_a_curve_point());
    assert_eq!(
        parse_public_key(&invalid).unwrap_err(),
        KeyFileError::InvalidPublicKey
    );
}

#[test]
fn debug_of_a_signing_key_does_not_show_the_seed() {
    let shown = format!("{:?}", key());
    assert!(!shown.contains(&"07".repeat(32)), "{shown}");
    assert!(shown.contains("public"));
}

#[test]
fn generate_gives_distinct_working_keys() {
    let a = SigningKey::generate().unwrap();
    let b = SigningKey::generate().unwrap();
    assert_ne!(a.seed(), b.seed());
    let image = builder().sign(&a).unwrap();
    assert!(verify(&image, &a.public_key()).is_ok());
    assert_eq!(
        verify(&image, &b.public_key()),
        Err(ImageError::BadSignature)
    );
}

#[test]
fn the_development_key_pair_matches() {
    let key = SigningKey::from_seed(crate::dev::SIGNING_SEED);
    assert_eq!(key.public_key(), crate::dev::PUBLIC_KEY);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Signing (ed25519-compact) and verification (salty, as on the ECUs) are two
    /// implementations of RFC 8032: same public key, same deterministic signature, and
    /// salty accepts it.
    #[test]
    fn signing_agrees_with_the_verifier(seed in any::<[u8; 32]>(), message in proptest::collection::vec(any::<u8>(), 0..200)) {
        let key = SigningKey::from_seed(seed);
        let reference = salty::Keypair::from(&seed);
        prop_assert_eq!(key.public_key(), reference.public.to_bytes());
        let signature = key.sign(&message);
        prop_assert_eq!(signature, reference.sign(&message).to_bytes());
        let public = salty::PublicKey::try_from(&key.public_key()).unwrap();
        prop_assert!(public.verify(&message, &salty::Signature::from(&signature)).is_ok());
    }
}

/// RFC 8032, section 7.1, test 2: the signer gives the standard's bytes.
#[test]
fn signing_matches_rfc_8032() {
    let hex = |s: &str| -> Vec<u8> {
        (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
            .collect()
    };
    let seed: [u8; 32] = hex("4ccd089b28ff96da9db6c346ec114e0f5b8a319f35aba624da8cf6ed4fb8a6fb")
        .try_into()
        .unwrap();
    let key = SigningKey::from_seed(seed);
    assert_eq!(
        key.public_key().to_vec(),
        hex("3d4017c3e843895a92b70aa74d1b7ebc9c982ccf2ec4968cc0cd55f12af4660c")
    );
    assert_eq!(
        key.sign(&[0x72]).to_vec(),
        hex("92a009a9f0d4cab8720e820b5f642540a2b27b5416503f8fb3762223ebdb69da085ac1e43e15996e458f3613d0f11d8c387b2eaeb4302aeeb00d291612bb0c00")
    );
}

#[test]
fn a_host_logic_image_is_refused_by_an_ecu_that_runs_firmware() {
    let mut b = builder();
    b.payload_kind = Payload::HostLogic;
    let host_logic = b.sign(&key()).unwrap();
    let header = ImageHeader::parse(&host_logic).unwrap();
    assert_eq!(header.payload, Payload::HostLogic);
    assert_eq!(host_logic[14..16], flags::HOST_LOGIC.to_le_bytes());
    assert!(header.to_string().contains("host logic"), "{header}");
    let public = key().public_key();
    assert_eq!(
        verify(&host_logic, &public).map(|v| *v.header()),
        Ok(header)
    );
    assert_eq!(
        header.check(&expectations()),
        Err(ImageError::NoMachineCode)
    );
    let host_logic_ecu = Expectations {
        runs_machine_code: false,
        ..expectations()
    };
    assert_eq!(header.check(&host_logic_ecu), Ok(()));
    // A machine-code image suits both.
    let header = ImageHeader::parse(&image()).unwrap();
    assert_eq!(header.payload, Payload::MachineCode);
    assert_eq!(header.check(&expectations()), Ok(()));
    assert_eq!(header.check(&host_logic_ecu), Ok(()));
}

#[test]
fn only_a_vector_table_the_bootloader_would_start_is_startable() {
    let table = |sp: u32, reset: u32| {
        let mut bytes = sp.to_le_bytes().to_vec();
        bytes.extend_from_slice(&reset.to_le_bytes());
        bytes
    };
    let a = ImageSlot::A;
    assert_eq!(check_startable(a, &table(0x2002_0000, 0x0802_0401)), Ok(()));
    for (sp, reset) in [
        (0xFFFF_FFFF, 0xFFFF_FFFF), // erased
        (0x2002_0000, 0x0804_0401), // linked for slot B
        (0x2002_0000, 0x0802_0400), // not Thumb
        (0x0800_0000, 0x0802_0401), // the stack in flash
    ] {
        assert_eq!(
            check_startable(a, &table(sp, reset)),
            Err(ImageError::NotStartable {
                initial_sp: sp,
                reset
            })
        );
    }
    assert!(check_startable(a, &[0x00, 0x00, 0x02]).is_err());
}
