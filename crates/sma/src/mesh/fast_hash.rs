//! A multiply–xorshift hasher for the integer keys of the mesh and criteria tables. The default
//! SipHash guards against adversarial keys, which ids made by this process are not, at several
//! times the cost; splits per second (target: >= 1 million, BENCHMARKS.md) hinge on these lookups.

use std::hash::{BuildHasherDefault, Hasher};

#[derive(Default, Clone, Copy)]
pub struct IdHasher(u64);

impl Hasher for IdHasher {
    fn finish(&self) -> u64 {
        // Fold the high bits down: hashbrown picks buckets with the low bits.
        self.0 ^ (self.0 >> 29)
    }

    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(u64::from(b));
        }
    }

    fn write_u32(&mut self, x: u32) {
        self.write_u64(u64::from(x));
    }

    /// Also what an enum's discriminant hashes as (through `write_isize`).
    fn write_usize(&mut self, x: usize) {
        self.write_u64(x as u64);
    }

    fn write_u64(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    }
}

pub type FastHash = BuildHasherDefault<IdHasher>;

#[cfg(test)]
mod tests {
    use super::*;
    use std::hash::BuildHasher;

    #[test]
    fn consecutive_keys_spread_over_low_bits() {
        let build = FastHash::default();
        let buckets: std::collections::HashSet<u64> =
            (0..1024u64).map(|k| build.hash_one(k) & 1023).collect();
        assert!(
            buckets.len() > 600,
            "only {} of 1024 buckets used",
            buckets.len()
        );
    }
}
