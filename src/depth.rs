//! Stage 5b — first-opaque depth search in packed depth rows.
//!
//! Owns the [`Word`] abstraction (one implementation of everything bit-packed,
//! generic over `u32` and `u64`), the bit order of a depth row, the paper's
//! byte-lookup-table search (a binary search for the first non-zero byte, then a
//! 256-entry table), the hardware bit-scan variant (`leading_zeros` /
//! `trailing_zeros`), and [`SetBits`]: the "next" search that clears the bits
//! already visited so internal empty regions are skipped too.
//!
//! **Bit order.** Slice `k` of a depth row lives in word `k / BITS` at bit
//! `BITS − 1 − k % BITS`: the most significant bit is the lowest slice. A view
//! that walks slices in ascending `k` searches from the MSB (leading zeros); a view
//! that walks them descending searches from the LSB of the last word (trailing
//! zeros).

use std::fmt::Debug;
use std::ops::{BitAnd, BitAndAssign, BitOr, BitOrAssign, Not, Shl, Shr};

/// A machine word used to pack depth rows: `u32` or `u64`.
pub trait Word:
    Copy
    + Eq
    + Debug
    + Default
    + Send
    + Sync
    + 'static
    + BitAnd<Output = Self>
    + BitOr<Output = Self>
    + Not<Output = Self>
    + Shl<u32, Output = Self>
    + Shr<u32, Output = Self>
    + BitAndAssign
    + BitOrAssign
{
    /// Bits per word.
    const BITS: u32;
    /// All zero.
    const ZERO: Self;
    /// The most significant bit alone.
    const MSB: Self;
    /// Leading zeros (hardware `lzcnt`/`bsr`).
    fn lz(self) -> u32;
    /// Trailing zeros (hardware `tzcnt`/`bsf`).
    fn tz(self) -> u32;
    /// The value as u64 (for byte extraction).
    fn as_u64(self) -> u64;
    /// Clears the lowest set bit (`x & (x − 1)`).
    fn clear_lowest(self) -> Self;
    /// Name for reports (`u32` / `u64`).
    const NAME: &'static str;
}

impl Word for u32 {
    const BITS: u32 = 32;
    const ZERO: Self = 0;
    const MSB: Self = 1 << 31;
    const NAME: &'static str = "u32";
    #[inline(always)]
    fn lz(self) -> u32 {
        self.leading_zeros()
    }
    #[inline(always)]
    fn tz(self) -> u32 {
        self.trailing_zeros()
    }
    #[inline(always)]
    fn as_u64(self) -> u64 {
        self as u64
    }
    #[inline(always)]
    fn clear_lowest(self) -> Self {
        self & self.wrapping_sub(1)
    }
}

impl Word for u64 {
    const BITS: u32 = 64;
    const ZERO: Self = 0;
    const MSB: Self = 1 << 63;
    const NAME: &'static str = "u64";
    #[inline(always)]
    fn lz(self) -> u32 {
        self.leading_zeros()
    }
    #[inline(always)]
    fn tz(self) -> u32 {
        self.trailing_zeros()
    }
    #[inline(always)]
    fn as_u64(self) -> u64 {
        self
    }
    #[inline(always)]
    fn clear_lowest(self) -> Self {
        self & self.wrapping_sub(1)
    }
}

/// Leading zeros of each byte value within 8 bits (`LZ8[0] = 8`).
pub static LZ8: [u8; 256] = {
    let mut t = [0u8; 256];
    let mut b = 0;
    while b < 256 {
        t[b] = (b as u8).leading_zeros() as u8;
        b += 1;
    }
    t
};

/// Trailing zeros of each byte value within 8 bits (`TZ8[0] = 8`).
pub static TZ8: [u8; 256] = {
    let mut t = [0u8; 256];
    let mut b = 0;
    while b < 256 {
        t[b] = (b as u8).trailing_zeros() as u8;
        b += 1;
    }
    t
};

/// How the first set bit of a word is found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Search {
    /// The paper's binary search for the first non-zero byte plus a byte table.
    Lut,
    /// Hardware bit scan (`leading_zeros` / `trailing_zeros`).
    Bitscan,
}

impl Search {
    /// Parses `lut` or `bitscan`.
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "lut" => Some(Search::Lut),
            "bitscan" | "bit-scan" => Some(Search::Bitscan),
            _ => None,
        }
    }
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Search::Lut => "lut",
            Search::Bitscan => "bitscan",
        }
    }
}

/// Leading zeros of a non-zero word by the paper's method: halve the word until a
/// byte is left (each step asks "is the upper half empty?"), then a byte table.
/// For `u32` this is exactly the paper's `Depth` routine: two comparisons and one
/// table look-up.
#[inline(always)]
pub fn lz_lut<W: Word>(w: W) -> u32 {
    debug_assert!(w != W::ZERO);
    let mut x = w.as_u64();
    let mut n = 0;
    let mut width = W::BITS;
    while width > 8 {
        width /= 2;
        let upper = x >> width;
        if upper == 0 {
            n += width;
        } else {
            x = upper;
        }
    }
    n + LZ8[x as usize] as u32
}

/// Trailing zeros of a non-zero word by halving plus a byte table.
#[inline(always)]
pub fn tz_lut<W: Word>(w: W) -> u32 {
    debug_assert!(w != W::ZERO);
    let mut x = w.as_u64();
    let mut n = 0;
    let mut width = W::BITS;
    while width > 8 {
        width /= 2;
        let low = x & ((1u64 << width) - 1);
        if low == 0 {
            n += width;
            x >>= width;
        } else {
            x = low;
        }
    }
    n + TZ8[x as usize] as u32
}

/// Leading zeros of a non-zero word by the chosen method.
#[inline(always)]
pub fn lz<W: Word>(w: W, s: Search) -> u32 {
    match s {
        Search::Lut => lz_lut(w),
        Search::Bitscan => w.lz(),
    }
}

/// Trailing zeros of a non-zero word by the chosen method.
#[inline(always)]
pub fn tz<W: Word>(w: W, s: Search) -> u32 {
    match s {
        Search::Lut => tz_lut(w),
        Search::Bitscan => w.tz(),
    }
}

/// The bit of slice `k` within its word.
#[inline(always)]
pub fn bit_of<W: Word>(k: usize) -> W {
    W::MSB >> (k as u32 % W::BITS)
}

/// Iterates the set bits of one depth row front to back, clearing each visited
/// bit in a local copy of the current word: the "next" search of the paper.
pub struct SetBits<'a, W: Word> {
    row: &'a [W],
    /// Index of the word being consumed.
    w: usize,
    /// Remaining bits of that word.
    cur: W,
    ascending: bool,
    search: Search,
}

impl<'a, W: Word> SetBits<'a, W> {
    /// Starts a front-to-back walk over `row`.
    #[inline(always)]
    pub fn new(row: &'a [W], ascending: bool, search: Search) -> Self {
        let (w, cur) = if row.is_empty() {
            (0, W::ZERO)
        } else if ascending {
            (0, row[0])
        } else {
            (row.len() - 1, row[row.len() - 1])
        };
        SetBits {
            row,
            w,
            cur,
            ascending,
            search,
        }
    }

    /// Drops every bit at or before slice `k` in walking order, so the next call
    /// returns the first set slice strictly after `k`.
    #[inline]
    pub fn skip_through(&mut self, k: usize) {
        let b = W::BITS as usize;
        let wk = k / b;
        let pos = (k % b) as u32; // bit index from the MSB
        if self.ascending {
            if wk >= self.row.len() {
                // past the end: nothing is left
                self.w = self.row.len().saturating_sub(1);
                self.cur = W::ZERO;
                return;
            }
            if wk > self.w {
                self.w = wk;
                self.cur = self.row[wk];
            }
            if wk == self.w {
                // keep bits strictly after pos (towards the LSB)
                let keep = if pos + 1 >= W::BITS {
                    W::ZERO
                } else {
                    !W::ZERO >> (pos + 1)
                };
                self.cur &= keep;
            }
        } else {
            if wk < self.w {
                self.w = wk;
                self.cur = self.row[wk];
            }
            if wk == self.w {
                // keep bits strictly before pos from the MSB (towards the MSB)
                let keep = if pos == 0 {
                    W::ZERO
                } else {
                    !(!W::ZERO >> pos)
                };
                self.cur &= keep;
            }
        }
    }
}

impl<W: Word> Iterator for SetBits<'_, W> {
    type Item = usize;
    #[inline(always)]
    fn next(&mut self) -> Option<usize> {
        let b = W::BITS as usize;
        if self.ascending {
            loop {
                if self.cur != W::ZERO {
                    let z = lz(self.cur, self.search);
                    self.cur &= !(W::MSB >> z);
                    return Some(self.w * b + z as usize);
                }
                self.w += 1;
                if self.w >= self.row.len() {
                    return None;
                }
                self.cur = self.row[self.w];
            }
        } else {
            loop {
                if self.cur != W::ZERO {
                    let z = tz(self.cur, self.search);
                    self.cur = self.cur.clear_lowest();
                    return Some(self.w * b + (b - 1 - z as usize));
                }
                if self.w == 0 || self.row.is_empty() {
                    return None;
                }
                self.w -= 1;
                self.cur = self.row[self.w];
            }
        }
    }
}

/// The first set slice of a row in walking order, or `None` (no clearing).
#[inline]
pub fn first_set<W: Word>(row: &[W], ascending: bool, search: Search) -> Option<usize> {
    SetBits::new(row, ascending, search).next()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive_first<W: Word>(row: &[W], ascending: bool) -> Option<usize> {
        let n = row.len() * W::BITS as usize;
        let set = |k: usize| row[k / W::BITS as usize] & bit_of::<W>(k) != W::ZERO;
        if ascending {
            (0..n).find(|&k| set(k))
        } else {
            (0..n).rev().find(|&k| set(k))
        }
    }

    #[test]
    fn lut_equals_bitscan_for_every_byte_in_every_position() {
        for b in 1u64..256 {
            for shift in (0..32).step_by(1) {
                let w = (b << shift) as u32;
                if w == 0 {
                    continue;
                }
                assert_eq!(lz_lut(w), w.leading_zeros());
                assert_eq!(tz_lut(w), w.trailing_zeros());
            }
            for shift in 0..64 {
                let w = b << shift;
                if w == 0 {
                    continue;
                }
                assert_eq!(lz_lut(w), w.leading_zeros());
                assert_eq!(tz_lut(w), w.trailing_zeros());
            }
        }
    }

    #[test]
    fn lut_equals_bitscan_on_random_words() {
        let mut s = 0x9E3779B97F4A7C15u64;
        for _ in 0..200_000 {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            // sparse words too: and several random values
            let w64 = s & (s >> 23) & (s >> 41) | (s & 1) << (s >> 58);
            for w in [s, w64] {
                if w != 0 {
                    assert_eq!(lz_lut(w), w.leading_zeros());
                    assert_eq!(tz_lut(w), w.trailing_zeros());
                }
                let w32 = w as u32;
                if w32 != 0 {
                    assert_eq!(lz_lut(w32), w32.leading_zeros());
                    assert_eq!(tz_lut(w32), w32.trailing_zeros());
                }
            }
        }
    }

    fn check_row<W: Word>(row: &[W]) {
        for asc in [true, false] {
            for s in [Search::Lut, Search::Bitscan] {
                assert_eq!(first_set(row, asc, s), naive_first(row, asc));
                let all: Vec<usize> = SetBits::new(row, asc, s).collect();
                let n = row.len() * W::BITS as usize;
                let set = |k: usize| row[k / W::BITS as usize] & bit_of::<W>(k) != W::ZERO;
                let mut want: Vec<usize> = (0..n).filter(|&k| set(k)).collect();
                if !asc {
                    want.reverse();
                }
                assert_eq!(all, want);
                // skip_through: the next after k is the first set strictly after k
                for k in [0, 1, 7, 31, 32, 33, 63, 64, 100]
                    .into_iter()
                    .filter(|&k| k < n)
                {
                    let mut it = SetBits::new(row, asc, s);
                    it.skip_through(k);
                    let exp = want
                        .iter()
                        .copied()
                        .find(|&x| if asc { x > k } else { x < k });
                    assert_eq!(it.next(), exp, "k={k} asc={asc}");
                }
            }
        }
    }

    #[test]
    fn set_bits_walks_in_order_both_ways() {
        let mut s = 0x1234_5678_9abc_def0u64;
        for len in 0..5 {
            for _ in 0..300 {
                let mut row32 = vec![0u32; len];
                let mut row64 = vec![0u64; len];
                for w in 0..len {
                    s ^= s << 13;
                    s ^= s >> 7;
                    s ^= s << 17;
                    let sparse = s & (s >> 17) & (s >> 33);
                    row64[w] = if s & 3 == 0 { 0 } else { sparse };
                    row32[w] = row64[w] as u32;
                }
                check_row(&row32);
                check_row(&row64);
            }
        }
    }
}
