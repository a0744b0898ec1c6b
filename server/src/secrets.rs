//! The secrets the coordinator hands out (a worker's, a lease's): 128 random bits from the
//! operating system as 32 hex characters, stored only as their SHA-256 hash, compared in
//! constant time.

use sha2::{Digest, Sha256};

/// A new secret: 16 bytes from the operating system's generator, as hex.
pub fn new_secret() -> std::io::Result<String> {
    let mut bytes = [0u8; 16];
    getrandom::fill(&mut bytes).map_err(|e| std::io::Error::other(e.to_string()))?;
    Ok(crate::uploads::hex(&bytes))
}

/// The stored form of a secret: its SHA-256 as hex.
pub fn hash(secret: &str) -> String {
    crate::uploads::hex(&Sha256::digest(secret.as_bytes()))
}

/// Whether two stored hashes are equal, in time independent of where they differ.
pub fn same(a: &str, b: &str) -> bool {
    constant_time_eq(a.as_bytes(), b.as_bytes())
}

/// Whether two secrets are equal, in a time that depends on their lengths only.
pub fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn secrets_are_distinct_hex_and_only_their_hash_matches() {
        let (a, b) = (new_secret().expect("rng"), new_secret().expect("rng"));
        assert_eq!(a.len(), 32);
        assert!(a.bytes().all(|c| c.is_ascii_hexdigit()));
        assert_ne!(a, b);
        assert!(same(&hash(&a), &hash(&a)));
        assert!(!same(&hash(&a), &hash(&b)));
        assert!(!same(&hash(&a), &a));
    }
}
