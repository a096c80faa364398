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
        HmacDrbg::new(&[&entropy, &nonce, SEED_PERSONALIZATION]).fill(out);
    }
}

/// HMAC_DRBG with HMAC-SHA-256 (NIST SP 800-90A rev. 1, 10.1.2): instantiate, generate,
/// no reseed, no additional input. Written here over the firmware's one `Hmac<Sha256>`
/// rather than taken from `rfc6979` (whose `HmacDrbg` the tests compare it with): that
/// crate brings a second HMAC implementation (656 bytes more in cruise-fw).
struct HmacDrbg {
    key: [u8; 32],
    value: [u8; 32],
}

impl HmacDrbg {
    /// Instantiate with the seed material `entropy_input ‖ nonce ‖ personalization`.
    fn new(seed_material: &[&[u8]]) -> Self {
        let mut drbg = Self {
            key: [0x00; 32],
            value: [0x01; 32],
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
            let mut mac = mac_with(&self.key);
            mac.update(&self.value);
            mac.update(&[round]);
            for part in data {
                mac.update(part);
            }
            self.key = mac.finalize().into_bytes().into();
            let mut mac = mac_with(&self.key);
            mac.update(&self.value);
            self.value = mac.finalize().into_bytes().into();
        }
    }

    /// HMAC_DRBG_Generate of `out.len()` bytes.
    fn fill(&mut self, out: &mut [u8]) {
        for chunk in out.chunks_mut(32) {
            let mut mac = mac_with(&self.key);
            mac.update(&self.value);
            self.value = mac.finalize().into_bytes().into();
            chunk.copy_from_slice(&self.value[..chunk.len()]);
        }
        self.update(&[]);
    }
}

fn mac_with(key: &[u8; 32]) -> Hmac<Sha256> {
    // HMAC takes a key of any length: `new_from_slice` cannot fail for it.
    <Hmac<Sha256> as Mac>::new_from_slice(key).unwrap_or_else(|_| unreachable!())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The same bytes as RustCrypto's HMAC_DRBG (rfc6979's) for the same seed material,
    /// over several calls and lengths (partial blocks included).
    #[test]
    fn the_drbg_matches_rustcrypto_hmac_drbg() {
        for (entropy, nonce, personalization) in [
            (
                &b"totally random0123456789"[..],
                &b"secret nonce"[..],
                &b"my drbg"[..],
            ),
            (&[0u8; 32][..], &[][..], &[][..]),
            (
                &[0xA5; 55][..],
                &[1, 2, 3, 4, 5, 6, 7, 8][..],
                SEED_PERSONALIZATION,
            ),
        ] {
            let mut ours = HmacDrbg::new(&[entropy, nonce, personalization]);
            let mut theirs = rfc6979::HmacDrbg::<Sha256>::new(entropy, nonce, personalization);
            for len in [16, 32, 1, 70, 64] {
                let (mut a, mut b) = ([0u8; 70], [0u8; 70]);
                ours.fill(&mut a[..len]);
                theirs.fill_bytes(&mut b[..len]);
                assert_eq!(a[..len], b[..len], "{len} bytes");
            }
        }
    }
}
