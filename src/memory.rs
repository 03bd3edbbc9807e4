//! Memory: what every structure of a renderer holds, and allocations that fail
//! with an error instead of aborting.
//!
//! Owns [`Memory`] (bytes per structure and principal axis, as
//! [`crate::Renderer::memory`] reports them and
//! [`crate::render::estimate_axis`] predicts them before anything is built) and
//! `zeroed`, the fallible zero-filled allocation the large per-axis arrays
//! use: a scan too large for the machine, or for an address-space limit, gets
//! [`Error::Memory`] rather than a SIGABRT from the global allocator; and
//! [`parse_bytes`], the byte counts (memory budgets) the command line accepts.

use crate::error::{Error, Result};

/// Bytes held per structure (per principal axis x, y, z where there is one).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Memory {
    /// The volume's voxels, in their own type.
    pub volume: u64,
    /// The slice stacks (densities permuted for each principal axis).
    pub stacks: [u64; 3],
    /// The per-voxel normal codes (alone, or packed with the densities).
    pub normals: [u64; 3],
    /// The unsheared cell codes the masks are packed from.
    pub cell_codes: [u64; 3],
    /// The sheared masks' words, plus their super-cell codes when the cell size
    /// is above 1 (at 1 they share the cell codes).
    pub masks: [u64; 3],
    /// The run-length encodings of the pre-classified path.
    pub rle: [u64; 3],
    /// The intermediate image (colour and depth planes).
    pub intermediate: u64,
}

impl Memory {
    /// Everything together.
    pub fn total(&self) -> u64 {
        let axes: u64 = (0..3).map(|a| self.axis_total(a)).sum();
        self.volume + axes + self.intermediate
    }
    /// The structures of principal axis `a`.
    pub fn axis_total(&self, a: usize) -> u64 {
        self.stacks[a] + self.normals[a] + self.cell_codes[a] + self.masks[a] + self.rle[a]
    }
}

/// Types whose all-zero bit pattern is a valid value.
///
/// # Safety
/// Implement only for types for which every byte being 0 is a valid value.
pub(crate) unsafe trait Zeroable: Copy {}
// SAFETY: 0 is a valid value of every primitive integer and float type.
unsafe impl Zeroable for u8 {}
// SAFETY: as above.
unsafe impl Zeroable for u16 {}
// SAFETY: as above.
unsafe impl Zeroable for i16 {}
// SAFETY: as above.
unsafe impl Zeroable for u32 {}
// SAFETY: as above.
unsafe impl Zeroable for u64 {}
// SAFETY: as above (0 bits are +0.0).
unsafe impl Zeroable for f32 {}
// SAFETY: an array's bytes are its elements' bytes, each valid as all zeros.
unsafe impl<T: Zeroable, const N: usize> Zeroable for [T; N] {}

/// `n` zeros, or [`Error::Memory`] naming `what` when the allocation is refused
/// or its size overflows. Pages are zeroed lazily by the system, as with
/// `vec![0; n]`.
pub(crate) fn zeroed<T: Zeroable>(n: usize, what: &str) -> Result<Vec<T>> {
    let refused =
        || Error::Memory { what: what.to_string(), needed: (n as u64).saturating_mul(std::mem::size_of::<T>() as u64), held: 0, budget: 0 };
    if n == 0 || std::mem::size_of::<T>() == 0 {
        return Ok(Vec::new());
    }
    let layout = std::alloc::Layout::array::<T>(n).map_err(|_| refused())?;
    // SAFETY: `layout` has a non-zero size (n > 0 and T is not zero-sized).
    let ptr = unsafe { std::alloc::alloc_zeroed(layout) } as *mut T;
    if ptr.is_null() {
        return Err(refused());
    }
    // SAFETY: `ptr` was allocated by the global allocator with the layout of
    // `[T; n]` (so its alignment and size are those `Vec<T>` with capacity `n`
    // uses), it is non-null, and all `n` elements are initialized: the memory
    // is zeroed and the all-zero pattern is a valid `T` (`Zeroable`).
    Ok(unsafe { Vec::from_raw_parts(ptr, n, n) })
}

/// Parses a byte count with an optional binary suffix: `4096`, `512k`,
/// `300M`, `2G`, `1.5G` (k/M/G/T = 2^10/2^20/2^30/2^40; a trailing `B` or `iB`
/// is allowed).
pub fn parse_bytes(s: &str) -> Result<u64> {
    let t = s.trim();
    let t = t.strip_suffix("iB").or_else(|| t.strip_suffix('B')).unwrap_or(t);
    let (num, mult) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let m = match c.to_ascii_lowercase() {
                'k' => 1u64 << 10,
                'm' => 1 << 20,
                'g' => 1 << 30,
                't' => 1 << 40,
                _ => return Err(Error::value("byte count", format!("'{s}': the suffix must be k, M, G or T"))),
            };
            (&t[..i], m)
        }
        _ => (t, 1),
    };
    let x: f64 = num.trim().parse().map_err(|_| Error::value("byte count", format!("'{s}' is not a number of bytes (e.g. 512M, 2G)")))?;
    let v = x * mult as f64;
    if !(v.is_finite() && v >= 1.0 && v < 2f64.powi(63)) {
        return Err(Error::value("byte count", format!("'{s}' must be at least 1 byte and finite")));
    }
    Ok(v as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn byte_counts_parse_with_binary_suffixes() {
        assert_eq!(parse_bytes("4096").unwrap(), 4096);
        assert_eq!(parse_bytes("512k").unwrap(), 512 << 10);
        assert_eq!(parse_bytes("300M").unwrap(), 300 << 20);
        assert_eq!(parse_bytes("1.5G").unwrap(), 3 << 29);
        assert_eq!(parse_bytes("2GiB").unwrap(), 2 << 30);
        assert_eq!(parse_bytes("64MB").unwrap(), 64 << 20);
        for bad in ["", "x", "12Q", "-5M", "NaN", "0", "1e300G"] {
            assert!(parse_bytes(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn zeroed_gives_zeros_and_refuses_absurd_sizes() {
        let v: Vec<u32> = zeroed(1 << 20, "test").unwrap();
        assert_eq!(v.len(), 1 << 20);
        assert_eq!(v.capacity(), 1 << 20);
        assert!(v.iter().all(|&x| x == 0));
        let mut v = v;
        v.push(7); // a Vec like any other: grows, drops
        assert_eq!(v[1 << 20], 7);
        let f: Vec<f32> = zeroed(3, "test").unwrap();
        assert_eq!(f, vec![0.0; 3]);
        assert!(zeroed::<u8>(0, "test").unwrap().is_empty());
        // larger than any address space: refused with an error, not an abort
        let e = zeroed::<u64>(usize::MAX / 4, "the huge thing").unwrap_err().to_string();
        assert!(e.contains("the huge thing"), "{e}");
        let e = zeroed::<u64>(1 << 60, "a 8 EiB stack").unwrap_err().to_string();
        assert!(e.contains("a 8 EiB stack"), "{e}");
    }

    #[test]
    fn totals_add_up() {
        let m = Memory { volume: 1, stacks: [2, 0, 4], normals: [8, 0, 0], masks: [16, 0, 32], intermediate: 64, ..Default::default() };
        assert_eq!(m.total(), 127);
        assert_eq!(m.axis_total(0), 26);
    }
}
