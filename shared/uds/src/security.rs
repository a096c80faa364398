//! SecurityAccess seed and key: the key is a keyed MAC of the seed (HMAC-SHA-256 with a
//! secret shared by the ECU and the tester, truncated to [`KEY_LEN`] bytes), so a key seen
//! on the bus is worth nothing for the next seed, and the secret never crosses the bus.

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
