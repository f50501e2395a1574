//! The driver's hashes, in one place: FNV-1a over bytes (journal checksums, the bake's
//! identity, the lights' fingerprint) and [`WordHash`] over 32-bit words (the scene's
//! geometry and materials fingerprints, the texel file's identity). Neither is
//! cryptographic: they tell one file, scene or bake from another, and detect torn writes.

use glam::{Vec2, Vec3};

/// A 64-bit FNV-1a hash: checksums of journal records, identities of bake settings and the
/// fingerprint of a scene's lights.
/// Not cryptographic; it detects torn writes and mismatched resumes.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    fnv1a64_more(FNV1A64_EMPTY, bytes)
}

/// FNV-1a's offset basis: [`fnv1a64`] of no bytes.
pub const FNV1A64_EMPTY: u64 = 0xcbf2_9ce4_8422_2325;

/// [`fnv1a64`] continued from the hash `h` over more bytes: a hash built piece by piece
/// (`fnv1a64_more(fnv1a64(a), b) == fnv1a64(a ++ b)`).
#[must_use]
pub fn fnv1a64_more(mut h: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// A fast 64-bit hash over 32-bit words: each step `h = (rotl(h, 5) ^ w) · K` (FxHash's),
/// then a SplitMix64 finaliser. Every step is a bijection of `h` for a fixed word, so two
/// inputs of the same length that differ in one word always hash differently. Not for
/// adversarial input: it tells one scene from another, as a checksum does.
#[derive(Clone, Copy, Debug)]
pub struct WordHash(u64);

const K: u64 = 0x517c_c1b7_2722_0a95;

impl WordHash {
    /// A hash seeded by `domain` (what is being hashed), so that the geometry and the
    /// materials of an empty scene do not share a fingerprint.
    pub fn new(domain: u64) -> Self {
        Self(domain.wrapping_mul(K) ^ 0x9e37_79b9_7f4a_7c15)
    }

    pub fn word(&mut self, w: u32) -> &mut Self {
        self.0 = (self.0.rotate_left(5) ^ u64::from(w)).wrapping_mul(K);
        self
    }

    pub fn u64(&mut self, w: u64) -> &mut Self {
        self.word(w as u32).word((w >> 32) as u32)
    }

    /// An `f32` by its bits, −0 taken as +0 (the same position, whichever way a file wrote it).
    pub fn f(&mut self, x: f32) -> &mut Self {
        self.word((x + 0.0).to_bits())
    }

    pub fn vec3(&mut self, v: Vec3) -> &mut Self {
        self.f(v.x).f(v.y).f(v.z)
    }

    pub fn vec2(&mut self, v: Vec2) -> &mut Self {
        self.f(v.x).f(v.y)
    }

    pub fn bytes(&mut self, b: &[u8]) -> &mut Self {
        self.u64(b.len() as u64);
        for chunk in b.chunks(4) {
            let mut w = [0u8; 4];
            w[..chunk.len()].copy_from_slice(chunk);
            self.word(u32::from_le_bytes(w));
        }
        self
    }

    /// The hash, never 0 (0 means "not recorded" wherever a fingerprint is stored).
    pub fn finish(&self) -> u64 {
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        (z ^ (z >> 31)).max(1)
    }
}
