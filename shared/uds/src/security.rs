//! SecurityAccess seed and key: the key is a keyed MAC of the seed (HMAC-SHA-512 with a
//! secret shared by the ECU and the tester, truncated to [`KEY_LEN`] bytes), so a key seen
//! on the bus is worth nothing for the next seed, and the secret never crosses the bus.
//! Seeds come from a [`SeedSource`].
//!
//! SHA-512 rather than SHA-256 because the firmware carries SHA-512 anyway (Ed25519 image
//! signatures hash with it): one hash in the image instead of two (sha2's SHA-256 cost
//! about 3 KB of every firmware's flash).

use salty::Sha512;

/// Bytes of a seed: 128 bits, so a seed repeats with negligible probability.
pub const SEED_LEN: usize = 16;
/// Bytes of a key: 128 bits of the MAC.
pub const KEY_LEN: usize = 16;

/// The key for `seed` on the ECU `node` under `secret`: HMAC-SHA-512(secret, node ‖ seed),
/// first [`KEY_LEN`] bytes. The node number is in the MAC so that a key observed for one
/// ECU does not open another that happened to draw the same seed.
pub fn key_for(secret: &[u8], node: u8, seed: &[u8; SEED_LEN]) -> [u8; KEY_LEN] {
    let mut mac = HmacSha512::new(secret);
    mac.update(&[node]);
    mac.update(seed);
    let digest = mac.finalize();
    let mut key = [0; KEY_LEN];
    key.copy_from_slice(&digest[..KEY_LEN]);
    key
}

/// SHA-512's block size in bytes (HMAC pads its key to it).
const SHA512_BLOCK: usize = 128;
/// SHA-512's output in bytes.
const SHA512_LEN: usize = 64;

/// HMAC (RFC 2104) over SHA-512. Written here over salty's SHA-512, the firmware's one
/// hash: RustCrypto's `hmac` wants a hash implementing `digest`'s traits, which salty's
/// does not, and taking sha2's SHA-512 for it would put a second SHA-512 in every image.
/// Checked against RFC 4231's test vectors and RustCrypto's HMAC in the tests.
pub struct HmacSha512 {
    inner: Sha512,
    outer_key: [u8; SHA512_BLOCK],
}

impl HmacSha512 {
    /// A MAC under `key` (any length: longer than a block, it is hashed first).
    pub fn new(key: &[u8]) -> Self {
        let mut block = [0u8; SHA512_BLOCK];
        if key.len() > SHA512_BLOCK {
            block[..SHA512_LEN].copy_from_slice(&Sha512::new().updated(key).finalize());
        } else {
            block[..key.len()].copy_from_slice(key);
        }
        let mut inner_key = block;
        for byte in &mut inner_key {
            *byte ^= 0x36;
        }
        for byte in &mut block {
            *byte ^= 0x5C;
        }
        Self {
            inner: Sha512::new().updated(&inner_key),
            outer_key: block,
        }
    }

    /// Adds `data` to the message.
    pub fn update(&mut self, data: &[u8]) {
        self.inner.update(data);
    }

    /// The MAC of the message.
    pub fn finalize(self) -> [u8; SHA512_LEN] {
        let inner = self.inner.finalize();
        Sha512::new()
            .updated(&self.outer_key)
            .updated(&inner)
            .finalize()
    }
}

/// Compares two keys in time independent of where they differ.
pub fn keys_match(a: &[u8], b: &[u8; KEY_LEN]) -> bool {
    a.len() == KEY_LEN && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Where an ECU's security seeds come from: an HMAC_DRBG (NIST SP 800-90A, SHA-512)
/// instantiated for each seed from an entropy pool, the ECU's seed epoch (a counter kept in
/// flash and raised at every start, so no start repeats an earlier one's seeds) and the
/// number of seeds drawn since the start.
///
/// What goes into the pool is the ECU's business: on the board the MCU's unique ID, the
/// jitter between its oscillators and the arrival times of CAN frames; in the virtual car a
/// per-car secret only, so that a run replays exactly. Anyone who learns the pool's inputs
/// can predict the seeds; anyone who only sees earlier seeds cannot (HMAC-SHA-512).
pub struct SeedSource {
    /// SHA-512 of everything added since the last draw, started with the digest of what
    /// came before it (a hash chain: no byte of entropy is ever dropped).
    pool: Sha512,
    epoch: u32,
    drawn: u32,
}

impl core::fmt::Debug for SeedSource {
    // The pool is secret: only the counters are shown.
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("SeedSource")
            .field("epoch", &self.epoch)
            .field("drawn", &self.drawn)
            .finish_non_exhaustive()
    }
}

/// The personalization string of the DRBG: seeds are for nothing else.
const SEED_PERSONALIZATION: &[u8] = b"AutoPlug UDS SecurityAccess seed";

impl SeedSource {
    /// A source for the start numbered `epoch`, its pool started with `entropy`.
    pub fn new(entropy: &[u8], epoch: u32) -> Self {
        Self {
            pool: Sha512::new().updated(entropy),
            epoch,
            drawn: 0,
        }
    }

    /// Adds bytes of entropy (or of anything unpredictable to an attacker) to the pool.
    pub fn add_entropy(&mut self, bytes: &[u8]) {
        self.pool.update(bytes);
    }

    /// The seed epoch this source was made for.
    pub fn epoch(&self) -> u32 {
        self.epoch
    }

    /// Fills `out` with the next unpredictable bytes.
    pub fn fill(&mut self, out: &mut [u8]) {
        let entropy = core::mem::take(&mut self.pool).finalize();
        self.pool.update(&entropy);
        self.drawn = self.drawn.wrapping_add(1);
        let mut nonce = [0u8; 8];
        nonce[..4].copy_from_slice(&self.epoch.to_le_bytes());
        nonce[4..].copy_from_slice(&self.drawn.to_le_bytes());
        HmacDrbg::new(&[&entropy, &nonce, SEED_PERSONALIZATION]).fill(out);
    }
}

/// HMAC_DRBG with HMAC-SHA-512 (NIST SP 800-90A rev. 1, 10.1.2): instantiate, generate,
/// no reseed, no additional input. Written here over [`HmacSha512`] rather than taken
/// from `rfc6979` (whose `HmacDrbg` the tests compare it with): that crate needs a
/// `digest` hash and brings its own HMAC.
struct HmacDrbg {
    key: [u8; SHA512_LEN],
    value: [u8; SHA512_LEN],
}

impl HmacDrbg {
    /// Instantiate with the seed material `entropy_input ‖ nonce ‖ personalization`.
    fn new(seed_material: &[&[u8]]) -> Self {
        let mut drbg = Self {
            key: [0x00; SHA512_LEN],
            value: [0x01; SHA512_LEN],
        };
        drbg.update(seed_material);
        drbg
    }

    /// HMAC_DRBG_Update: K = HMAC(K, V ‖ 0x00 ‖ data), V = HMAC(K, V), and again with 0x01
    /// when there is data.
    fn update(&mut self, data: &[&[u8]]) {
        for round in [0x00u8, 0x01] {
            if round == 0x01 && data.iter().all(|d| d.is_empty()) {
                break;
            }
            let mut mac = HmacSha512::new(&self.key);
            mac.update(&self.value);
            mac.update(&[round]);
            for part in data {
                mac.update(part);
            }
            self.key = mac.finalize();
            self.next_value();
        }
    }

    /// V = HMAC(K, V).
    fn next_value(&mut self) {
        let mut mac = HmacSha512::new(&self.key);
        mac.update(&self.value);
        self.value = mac.finalize();
    }

    /// HMAC_DRBG_Generate of `out.len()` bytes.
    fn fill(&mut self, out: &mut [u8]) {
        for chunk in out.chunks_mut(SHA512_LEN) {
            self.next_value();
            chunk.copy_from_slice(&self.value[..chunk.len()]);
        }
        self.update(&[]);
    }
}

#[cfg(test)]
mod tests {
    extern crate std;

    use super::*;
    use hmac::Mac;
    use proptest::prelude::*;
    use std::vec::Vec;

    fn hex(text: &str) -> Vec<u8> {
        (0..text.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&text[i..i + 2], 16).unwrap())
            .collect()
    }

    /// RFC 4231's HMAC-SHA-512 test cases 1, 2, 6 (key longer than a block) and 7.
    #[test]
    fn hmac_sha512_gives_rfc_4231_results() {
        let long_key = [0xAAu8; 131];
        for (key, data, expected) in [
            (
                &[0x0Bu8; 20][..],
                &b"Hi There"[..],
                "87aa7cdea5ef619d4ff0b4241a1d6cb02379f4e2ce4ec2787ad0b30545e17cde\
                 daa833b7d6b8a702038b274eaea3f4e4be9d914eeb61f1702e696c203a126854",
            ),
            (
                &b"Jefe"[..],
                &b"what do ya want for nothing?"[..],
                "164b7a7bfcf819e2e395fbe73b56e0a387bd64222e831fd610270cd7ea250554\
                 9758bf75c05a994a6d034f65f8f0e6fdcaeab1a34d4a6b4b636e070a38bce737",
            ),
            (
                &long_key[..],
                &b"Test Using Larger Than Block-Size Key - Hash Key First"[..],
                "80b24263c7c1a3ebb71493c1dd7be8b49b46d1f41b4aeec1121b013783f8f352\
                 6b56d037e05f2598bd0fd2215d6a1e5295e64f73f63f0aec8b915a985d786598",
            ),
            (
                &long_key[..],
                &b"This is a test using a larger than block-size key and a larger than block-size data. The key needs to be hashed before being used by the HMAC algorithm."[..],
                "e37b6a775dc87dbaa4dfa9f96e5e3ffddebd71f8867289865df5a32d20cdc944\
                 b6022cac3c4982b10d5eeb55c3e4de15134676fb6de0446065c97440fa8c6a58",
            ),
        ] {
            let mut mac = HmacSha512::new(key);
            mac.update(data);
            assert_eq!(mac.finalize().to_vec(), hex(&expected.replace(' ', "")));
        }
    }

    proptest! {
        /// The same MAC as RustCrypto's HMAC-SHA-512 for any key and any message, fed in
        /// two parts split anywhere (across SHA-512's block boundaries too).
        #[test]
        fn hmac_sha512_matches_rustcrypto(
            key in proptest::collection::vec(any::<u8>(), 0..300),
            message in proptest::collection::vec(any::<u8>(), 0..400),
            split in any::<prop::sample::Index>(),
        ) {
            let at = split.index(message.len() + 1);
            let mut ours = HmacSha512::new(&key);
            ours.update(&message[..at]);
            ours.update(&message[at..]);
            let mut theirs = <hmac::Hmac<sha2::Sha512> as Mac>::new_from_slice(&key).unwrap();
            theirs.update(&message);
            prop_assert_eq!(ours.finalize().to_vec(), theirs.finalize().into_bytes().to_vec());
        }
    }

    /// The same bytes as RustCrypto's HMAC_DRBG (rfc6979's) over SHA-512 for the same seed
    /// material, over several calls and lengths (partial blocks included).
    #[test]
    fn the_drbg_matches_rustcrypto_hmac_drbg() {
        for (entropy, nonce, personalization) in [
            (
                &b"totally random0123456789"[..],
                &b"secret nonce"[..],
                &b"my drbg"[..],
            ),
            (&[0u8; 64][..], &[][..], &[][..]),
            (
                &[0xA5; 155][..],
                &[1, 2, 3, 4, 5, 6, 7, 8][..],
                SEED_PERSONALIZATION,
            ),
        ] {
            let mut ours = HmacDrbg::new(&[entropy, nonce, personalization]);
            let mut theirs =
                rfc6979::HmacDrbg::<sha2::Sha512>::new(entropy, nonce, personalization);
            for len in [16, 64, 1, 140, 128] {
                let (mut a, mut b) = ([0u8; 140], [0u8; 140]);
                ours.fill(&mut a[..len]);
                theirs.fill_bytes(&mut b[..len]);
                assert_eq!(a[..len], b[..len], "{len} bytes");
            }
        }
    }

    /// Entropy added before a draw changes that draw and every later one, and a draw leaves
    /// what the pool held in it (the next draw differs from a fresh source's).
    #[test]
    fn the_pool_keeps_what_it_was_given() {
        let draw = |source: &mut SeedSource| {
            let mut seed = [0u8; SEED_LEN];
            source.fill(&mut seed);
            seed
        };
        let mut plain = SeedSource::new(b"car", 3);
        let mut mixed = SeedSource::new(b"car", 3);
        mixed.add_entropy(b"jitter");
        assert_ne!(draw(&mut plain), draw(&mut mixed));
        assert_ne!(draw(&mut plain), draw(&mut mixed));
        let mut fresh = SeedSource::new(b"car", 3);
        let mut drawn_once = SeedSource::new(b"car", 3);
        draw(&mut drawn_once);
        // Same epoch and counter value on the second draw of `fresh` as on `drawn_once`'s
        // second: they differ by the pool only.
        draw(&mut fresh);
        fresh.pool = Sha512::new().updated(b"car");
        assert_ne!(draw(&mut fresh), draw(&mut drawn_once));
    }
}
