//! SecurityAccess seed and key: the key is a keyed MAC of the seed (HMAC-SHA-256 with a
//! secret shared by the ECU and the tester, truncated to [`KEY_LEN`] bytes), so a key seen
//! on the bus is worth nothing for the next seed, and the secret never crosses the bus.
//! Seeds come from a [`SeedSource`].

use hmac::{Hmac, Mac};
use sha2::Sha256;

/// Bytes of a seed: 128 bits, so a seed repeats with negligible probability.
pub const SEED_LEN: usize = 16;
/// Bytes of a key: 128 bits of the MAC.
pub const KEY_LEN: usize = 16;

/// The key for `seed` on the ECU `node` under `secret`: HMAC-SHA-256(secret, node ‖ seed),
/// first [`KEY_LEN`] bytes. The node number is in the MAC so that a key observed for one
/// ECU does not open another that happened to draw the same seed.
pub fn key_for(secret: &[u8], node: u8, seed: &[u8; SEED_LEN]) -> [u8; KEY_LEN] {
    // HMAC takes a key of any length: `new_from_slice` cannot fail for it.
    let mut mac = <Hmac<Sha256> as Mac>::new_from_slice(secret).unwrap_or_else(|_| unreachable!());
    mac.update(&[node]);
    mac.update(seed);
    let digest = mac.finalize().into_bytes();
    let mut key = [0; KEY_LEN];
    key.copy_from_slice(&digest[..KEY_LEN]);
    key
}

/// Compares two keys in time independent of where they differ.
pub fn keys_match(a: &[u8], b: &[u8; KEY_LEN]) -> bool {
    a.len() == KEY_LEN && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Where an ECU's security seeds come from: an HMAC_DRBG (NIST SP 800-90A, SHA-256)
/// instantiated for each seed from an entropy pool, the ECU's seed epoch (a counter kept in
/// flash and raised at every start, so no start repeats an earlier one's seeds) and the
/// number of seeds drawn since the start.
///
/// What goes into the pool is the ECU's business: on the board the MCU's unique ID, the
/// jitter between its oscillators and the arrival times of CAN frames; in the virtual car a
/// per-car secret only, so that a run replays exactly. Anyone who learns the pool's inputs
/// can predict the seeds; anyone who only sees earlier seeds cannot (HMAC-SHA-256).
#[derive(Clone, Debug)]
pub struct SeedSource {
    pool: Sha256,
    epoch: u32,
    drawn: u32,
}

/// The personalization string of the DRBG: seeds are for nothing else.
const SEED_PERSONALIZATION: &[u8] = b"AutoPlug UDS SecurityAccess seed";

impl SeedSource {
    /// A source for the start numbered `epoch`, its pool started with `entropy`.
    pub fn new(entropy: &[u8], epoch: u32) -> Self {
        use sha2::Digest;
        let mut pool = Sha256::new();
        pool.update(entropy);
        Self {
            pool,
            epoch,
            drawn: 0,
        }
    }

    /// Adds bytes of entropy (or of anything unpredictable to an attacker) to the pool.
    pub fn add_entropy(&mut self, bytes: &[u8]) {
        use sha2::Digest;
        self.pool.update(bytes);
    }

    /// The seed epoch this source was made for.
    pub fn epoch(&self) -> u32 {
        self.epoch
    }

    /// Fills `out` with the next unpredictable bytes.
    pub fn fill(&mut self, out: &mut [u8]) {
        use sha2::Digest;
        let entropy = self.pool.clone().finalize();
        self.drawn = self.drawn.wrapping_add(1);
        let mut nonce = [0u8; 8];
        nonce[..4].copy_from_slice(&self.epoch.to_le_bytes());
        nonce[4..].copy_from_slice(&self.drawn.to_le_bytes());
        rfc6979::HmacDrbg::<Sha256>::new(&entropy, &nonce, SEED_PERSONALIZATION).fill_bytes(out);
    }
}
