//! Helpers shared by the unit tests.

/// Deterministic pseudo-random u64s (xorshift64) from a non-zero `seed`.
pub fn xorshift(mut s: u64) -> impl FnMut() -> u64 {
    move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    }
}
