//! Numbers for messages: densities and byte counts. The ground floor: every
//! stage's errors and reports print through it, and it imports nothing.

/// A density for messages: plain, or in scientific notation when huge or tiny
/// (a ±FLT_MAX sentinel prints as `-3.4028235e38`, not 39 digits).
pub fn fmt_density(x: f32) -> String {
    if x != 0.0 && !(1e-4..1e9).contains(&x.abs()) { format!("{x:e}") } else { format!("{x}") }
}

/// `bytes` in binary units: `512 B`, `3.2 KiB`, `108.3 MiB`, `1.50 GiB`.
pub fn fmt_bytes(bytes: u64) -> String {
    const K: f64 = 1024.0;
    let b = bytes as f64;
    if b < K {
        format!("{bytes} B")
    } else if b < K * K {
        format!("{:.1} KiB", b / K)
    } else if b < K * K * K {
        format!("{:.1} MiB", b / (K * K))
    } else {
        format!("{:.2} GiB", b / (K * K * K))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn densities_and_byte_counts() {
        assert_eq!(fmt_density(-f32::MAX), "-3.4028235e38");
        assert_eq!(fmt_density(-1000.0), "-1000");
        assert_eq!(fmt_density(0.0), "0");
        assert_eq!(fmt_bytes(512), "512 B");
        assert_eq!(fmt_bytes(108 << 20), "108.0 MiB");
    }
}
