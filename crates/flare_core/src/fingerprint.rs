//! Stable fingerprints: what the app's caches, the bake's ghost keys and `.flut` files use to tell whether two
//! inputs are the same.
//!
//! # How it works
//! A fingerprint is the 64-bit FNV-1a hash ([`fnv1a`]) of a canonical serialisation: the value's serde JSON
//! ([`of`]). Unlike `Debug` text (not a stable format) or `std`'s hasher (which may change between Rust
//! releases), both are fixed: serde_json writes fields in declaration order and floats by the shortest
//! round-trip digits, so equal values give equal bytes on every machine and build, and a fingerprint written
//! into a file today is still comparable tomorrow. `SCHEME` names this rule; a file that stores a
//! fingerprint also stores the scheme, so one made by another rule is recognised and refused with a reason
//! instead of being compared.

use serde::Serialize;

/// The fingerprint rule (canonical JSON, FNV-1a 64). Files made before it carried none.
pub(crate) const SCHEME: u32 = 2;

/// FNV-1a's offset basis.
pub const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// 64-bit FNV-1a of `bytes`, continuing from `hash` (start from [`FNV_OFFSET`]).
pub fn fnv1a(bytes: &[u8], mut hash: u64) -> u64 {
    for &b in bytes {
        hash ^= u64::from(b);
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    }
    hash
}

/// A number no other call in this process returns: the identity of something built once and never changed
/// (a prepared flare, a loaded LUT), for caches that must tell a new one from an old one at the same address.
pub(crate) fn unique_id() -> u64 {
    static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
    NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
}

/// The fingerprint of `value`: FNV-1a of its canonical JSON.
pub fn of<T: Serialize + ?Sized>(value: &T) -> u64 {
    // Serialising plain data to a Vec cannot fail (no map with non-string keys is fingerprinted); should it
    // ever, the error's text is hashed instead, which still changes with the input.
    let bytes = serde_json::to_vec(value).unwrap_or_else(|e| e.to_string().into_bytes());
    fnv1a(&bytes, FNV_OFFSET)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fingerprints_are_stable_and_tell_values_apart() {
        // FNV-1a's published test vector.
        assert_eq!(fnv1a(b"a", FNV_OFFSET), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(of(&[1.0, 2.5]), of(&[1.0, 2.5]));
        assert_ne!(of(&[1.0, 2.5]), of(&[1.0, 2.5000001]));
        assert_ne!(of("a"), of("b"));
    }
}
