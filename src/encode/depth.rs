//! First-opaque depth search in packed depth rows.
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
    /// The low `BITS` bits of `x`.
    fn from_u64(x: u64) -> Self;
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
    #[inline(always)]
    fn from_u64(x: u64) -> Self {
        x as u32
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
    #[inline(always)]
    fn from_u64(x: u64) -> Self {
        x
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
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum Search {
    /// The paper's binary search for the first non-zero byte plus a byte table.
    Lut,
    /// Hardware bit scan (`leading_zeros` / `trailing_zeros`). At CPU level
    /// AVX2 the binary path's row loop runs a copy compiled for
    /// `lzcnt`/`tzcnt`; at the scalar level the plain build's `bsr`/`bsf`
    /// (the scalar reference, chosen by the `cpu` setting).
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

/// The bit of slice `k` within its word (1-bit rows).
#[inline(always)]
pub fn bit_of<W: Word>(k: usize) -> W {
    W::MSB >> (k as u32 % W::BITS)
}

/// Code widths a depth row may use: `nb` bits per slice, `nb` ∈ {1, 2, 4} so
/// that codes never straddle a byte (3-bit codes would waste bits in every word
/// and break the per-byte tables; 4 bits hold 15 thresholds instead of 7).
pub const CODE_WIDTHS: [u32; 3] = [1, 2, 4];

/// Smallest code width whose codes can tell `thresholds + 1` intervals apart.
pub fn code_width_for(thresholds: usize) -> Option<u32> {
    CODE_WIDTHS.into_iter().find(|&nb| thresholds < (1usize << nb))
}

/// Slot layout of `nb`-bit codes in a word: slice `k` is slot `k % slots` of
/// word `k / slots`, slot 0 in the most significant bits.
#[inline(always)]
pub fn slot_shift<W: Word>(nb: u32, slot: u32) -> u32 {
    W::BITS - nb * (slot + 1)
}

/// All `nb` bits of the slot of slice `k` (a 1-bit row's `bit_of`).
#[inline(always)]
pub fn slot_mask<W: Word>(nb: u32, k: usize) -> W {
    let slots = W::BITS / nb;
    let ones = W::from_u64((1u64 << nb) - 1);
    ones << slot_shift::<W>(nb, k as u32 % slots)
}

/// Finds slices whose code is at least `c` in rows of `nb`-bit codes (`nb = 1`,
/// `c = 1` is the plain binary mask). Holds the per-threshold byte tables.
#[derive(Clone, Debug)]
pub struct Matcher {
    nb: u32,
    c: u32,
    /// The top bit of every slot (as a 64-bit pattern; truncates for u32).
    top: u64,
    /// `2^nb − c` in every slot: a slot's code is ≥ c iff adding this carries
    /// out of the slot ([`Matcher::hits`]).
    add: u64,
    /// First slot (from the MSB) of a byte with code ≥ c, or `8/nb` if none.
    first: [u8; 256],
    /// Last slot of a byte with code ≥ c, or `8/nb` if none.
    last: [u8; 256],
}

impl Matcher {
    /// A matcher for codes ≥ `c` of width `nb` (`nb` ∈ [`CODE_WIDTHS`], `1 ≤ c < 2^nb`).
    pub fn new(nb: u32, c: u32) -> Self {
        assert!(CODE_WIDTHS.contains(&nb) && c >= 1 && c < (1 << nb), "bad code width {nb} / threshold {c}");
        let mut top = 0u64;
        let mut b = 64;
        while b >= nb {
            b -= nb;
            top |= 1u64 << (b + nb - 1);
        }
        let spb = 8 / nb;
        let mut first = [spb as u8; 256];
        let mut last = [spb as u8; 256];
        for byte in 0..256u32 {
            for j in 0..spb {
                let code = (byte >> (8 - nb * (j + 1))) & ((1 << nb) - 1);
                if code >= c {
                    if first[byte as usize] == spb as u8 {
                        first[byte as usize] = j as u8;
                    }
                    last[byte as usize] = j as u8;
                }
            }
        }
        // the lowest bit of every slot times 2^nb − c (< 2^nb: no slot overflows)
        let add = (top >> (nb - 1)) * ((1u64 << nb) - c as u64);
        Matcher { nb, c, top, add, first, last }
    }

    /// The plain binary matcher (1-bit codes, set bits).
    pub fn binary() -> Self {
        Self::new(1, 1)
    }

    /// Code width.
    pub fn width(&self) -> u32 {
        self.nb
    }

    /// Threshold index.
    pub fn threshold(&self) -> u32 {
        self.c
    }

    /// `log2(nb)` (nb is a power of two): slot arithmetic by shifts, since a
    /// division by the run-time `nb` is a `div` per search step in the ray loops.
    #[inline(always)]
    fn log_nb(&self) -> u32 {
        self.nb.trailing_zeros()
    }

    /// The top bit of every slot whose code is ≥ c (SWAR, branch-free).
    ///
    /// A slot's code `v` is ≥ `c` iff `v + (2^nb − c)` carries out of the
    /// slot. The low `nb − 1` bits of every slot are added first with the top
    /// bits masked off, so no carry crosses into the next slot (each sum is
    /// below `2^nb` and lands at most in the slot's own top bit, `cin`); the
    /// carry out of the top bit is then the full adder's majority of the two
    /// top bits and `cin`. Equal to [`Matcher::hits_planes`] (the bit-plane
    /// reference) for every word, width and threshold (tested).
    #[inline(always)]
    pub fn hits<W: Word>(&self, w: W) -> W {
        if self.nb == 1 {
            return w; // (1-bit codes: every set bit; the same as below, sooner)
        }
        let x = w.as_u64();
        let (top, add) = (self.top, self.add);
        let cin = ((x & !top) + (add & !top)) & top;
        let (xt, at) = (x & top, add & top);
        W::from_u64((xt & at) | ((xt ^ at) & cin))
    }

    /// Which of the four u64 words at `words` have a matching slot
    /// ([`Matcher::hits`] of each, in one AVX2 vector): bit `i` set when word
    /// `i` has one (one-bit codes: when it is not zero).
    ///
    /// # Safety
    /// The CPU must have AVX2, and the four words from `words` be readable.
    #[cfg(target_arch = "x86_64")]
    #[inline]
    #[target_feature(enable = "avx2")]
    pub unsafe fn hit_words4(&self, words: *const u64) -> u32 {
        use std::arch::x86_64::*;
        if self.nb == 1 {
            // SAFETY: this function's contract is that one's
            return unsafe { nonzero_words4(words) };
        }
        // SAFETY: the caller guarantees the four words readable (unaligned
        // load) and AVX2.
        let x = unsafe { _mm256_loadu_si256(words.cast::<__m256i>()) };
        let h = {
            let (top, add) = (_mm256_set1_epi64x(self.top as i64), self.add);
            let (add_low, add_top) = (_mm256_set1_epi64x((add & !self.top) as i64), _mm256_set1_epi64x((add & self.top) as i64));
            // the lanes of `hits`: cin, then the majority of the top bits and cin
            let cin = _mm256_and_si256(_mm256_add_epi64(_mm256_andnot_si256(top, x), add_low), top);
            let xt = _mm256_and_si256(x, top);
            _mm256_or_si256(_mm256_and_si256(xt, add_top), _mm256_and_si256(_mm256_xor_si256(xt, add_top), cin))
        };
        nonzero_lanes(h)
    }

    /// The reference of [`Matcher::hits`]: a bit-plane comparator over the
    /// slots from their top bit down.
    pub fn hits_planes<W: Word>(&self, w: W) -> W {
        if self.nb == 1 {
            return w;
        }
        let x = w.as_u64();
        let top = self.top;
        let (mut eq, mut gt) = (top, 0u64);
        for i in 0..self.nb {
            let plane = (x << i) & top;
            if (self.c >> (self.nb - 1 - i)) & 1 == 0 {
                gt |= eq & plane;
                eq &= !plane;
            } else {
                eq &= plane;
            }
        }
        W::from_u64(gt | eq)
    }

    /// The first (ascending: from the MSB; else from the LSB) slot of `w` whose
    /// code is ≥ c.
    #[inline(always)]
    pub fn first_slot<W: Word>(&self, w: W, ascending: bool, search: Search) -> Option<u32> {
        if w == W::ZERO {
            return None;
        }
        match (search, self.nb) {
            // the paper's Depth: binary search for the first non-zero byte + byte table
            (Search::Lut, 1) => Some(if ascending { lz_lut(w) } else { W::BITS - 1 - tz_lut(w) }),
            // per-threshold byte tables: "first code ≥ c in this byte"
            (Search::Lut, _) => {
                let x = w.as_u64();
                let (bytes, spb) = (W::BITS / 8, 8 >> self.log_nb());
                if ascending {
                    for bi in 0..bytes {
                        let f = self.first[((x >> (W::BITS - 8 * (bi + 1))) & 0xFF) as usize] as u32;
                        if f < spb {
                            return Some(bi * spb + f);
                        }
                    }
                } else {
                    for bi in (0..bytes).rev() {
                        let l = self.last[((x >> (W::BITS - 8 * (bi + 1))) & 0xFF) as usize] as u32;
                        if l < spb {
                            return Some(bi * spb + l);
                        }
                    }
                }
                None
            }
            (Search::Bitscan, _) => {
                let h = self.hits(w);
                if h == W::ZERO {
                    return None;
                }
                Some((if ascending { h.lz() } else { W::BITS - 1 - h.tz() }) >> self.log_nb())
            }
        }
    }
}

/// Iterates the slices of one depth row whose code matches, front to back,
/// clearing each visited slot in a local copy of the current word: the "next"
/// search of the paper, which also skips internal empty regions.
pub struct SetBits<'a, W: Word> {
    row: &'a [W],
    /// Index of the word being consumed.
    w: usize,
    /// Remaining codes of that word.
    cur: W,
    ascending: bool,
    /// 1-bit codes searched by bit scan (the binary mask's case): every set
    /// bit matches, so a step is one `lzcnt`/`tzcnt` and one bit clear,
    /// without [`Matcher::first_slot`]'s dispatch on search and width.
    plain: bool,
    search: Search,
    m: &'a Matcher,
}

static BINARY: std::sync::OnceLock<Matcher> = std::sync::OnceLock::new();

/// The shared binary matcher.
pub fn binary_matcher() -> &'static Matcher {
    BINARY.get_or_init(Matcher::binary)
}

impl<'a, W: Word> SetBits<'a, W> {
    /// Starts a front-to-back walk over the set bits of a 1-bit `row`.
    #[inline(always)]
    pub fn new(row: &'a [W], ascending: bool, search: Search) -> Self {
        Self::with_matcher(row, ascending, search, binary_matcher())
    }

    /// Starts a walk over the slices of `row` whose code `m` matches.
    #[inline(always)]
    pub fn with_matcher(row: &'a [W], ascending: bool, search: Search, m: &'a Matcher) -> Self {
        let (w, cur) = if row.is_empty() {
            (0, W::ZERO)
        } else if ascending {
            (0, row[0])
        } else {
            (row.len() - 1, row[row.len() - 1])
        };
        let plain = m.nb == 1 && search != Search::Lut;
        SetBits { row, w, cur, ascending, plain, search, m }
    }
}

impl<W: Word> SetBits<'_, W> {
    /// The slice [`Iterator::next`] will return, without consuming it (moves
    /// past empty words only, which does not change what follows).
    #[inline(always)]
    pub fn peek(&mut self) -> Option<usize> {
        self.peek_slot().map(|slot| self.slice_of(slot))
    }

    /// The slice of `slot` in the current word.
    #[inline(always)]
    fn slice_of(&self, slot: u32) -> usize {
        // slots per word: W::BITS / nb
        let per_word = if self.plain { W::BITS } else { W::BITS >> self.m.log_nb() };
        self.w * per_word as usize + slot as usize
    }

    /// The first matching slot of the current word, stepping over words with none.
    #[inline(always)]
    fn peek_slot(&mut self) -> Option<u32> {
        loop {
            if self.plain {
                if self.cur != W::ZERO {
                    return Some(if self.ascending { self.cur.lz() } else { W::BITS - 1 - self.cur.tz() });
                }
            } else if let Some(slot) = self.m.first_slot(self.cur, self.ascending, self.search) {
                return Some(slot);
            }
            if self.ascending {
                self.w += 1;
                if self.w >= self.row.len() {
                    return None;
                }
            } else {
                if self.w == 0 || self.row.is_empty() {
                    return None;
                }
                self.w -= 1;
            }
            self.cur = self.row[self.w];
        }
    }
}

impl<W: Word> Iterator for SetBits<'_, W> {
    type Item = usize;
    #[inline(always)]
    fn next(&mut self) -> Option<usize> {
        let slot = self.peek_slot()?;
        // clear the visited slot (all its bits) so the next search moves on
        if self.plain {
            self.cur &= !(W::MSB >> slot);
        } else {
            let nb = self.m.nb;
            let ones = W::from_u64((1u64 << nb) - 1);
            self.cur &= !(ones << slot_shift::<W>(nb, slot));
        }
        Some(self.slice_of(slot))
    }
}

/// The first matching slice of a 1-bit row in walking order, or `None`.
#[inline]
pub fn first_set<W: Word>(row: &[W], ascending: bool, search: Search) -> Option<usize> {
    SetBits::new(row, ascending, search).next()
}

/// Which of the four u64 words at `words` are not zero: bit `i` set when
/// word `i` is not (the matching words of one-bit codes,
/// [`Matcher::hit_words4`]).
///
/// # Safety
/// The CPU must have AVX2, and the four words from `words` be readable.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
pub unsafe fn nonzero_words4(words: *const u64) -> u32 {
    use std::arch::x86_64::*;
    // SAFETY: the caller guarantees the four words readable (unaligned load)
    // and AVX2.
    nonzero_lanes(unsafe { _mm256_loadu_si256(words.cast::<__m256i>()) })
}

/// Bit `i` set when 64-bit lane `i` of `x` is not zero.
#[cfg(target_arch = "x86_64")]
#[inline]
#[target_feature(enable = "avx2")]
fn nonzero_lanes(x: std::arch::x86_64::__m256i) -> u32 {
    use std::arch::x86_64::*;
    let zero = _mm256_cmpeq_epi64(x, _mm256_setzero_si256());
    _mm256_movemask_pd(_mm256_castsi256_pd(zero)) as u32 ^ 0xf
}

#[cfg(test)]
mod tests {
    use super::*;

    fn naive_first<W: Word>(row: &[W], ascending: bool) -> Option<usize> {
        let n = row.len() * W::BITS as usize;
        let set = |k: usize| row[k / W::BITS as usize] & bit_of::<W>(k) != W::ZERO;
        if ascending { (0..n).find(|&k| set(k)) } else { (0..n).rev().find(|&k| set(k)) }
    }

    /// `hits` by its definition: the top bit of every slot whose code is ≥ c.
    fn naive_hits(x: u64, nb: u32, c: u32, bits: u32) -> u64 {
        let mut out = 0u64;
        for s in 0..bits / nb {
            let shift = bits - nb * (s + 1);
            if ((x >> shift) & ((1 << nb) - 1)) as u32 >= c {
                out |= 1u64 << (shift + nb - 1);
            }
        }
        out
    }

    #[test]
    fn swar_hits_equal_the_bit_planes_and_the_definition() {
        let mut next = crate::testing::xorshift(0x9E37_79B9_7F4A_7C15);
        for nb in CODE_WIDTHS {
            for c in 1..(1u32 << nb) {
                let m = Matcher::new(nb, c);
                // every slot value in every slot (the rest of the word random), and random words
                let mut words: Vec<u64> = (0..64 / nb)
                    .flat_map(|slot| (0..1u64 << nb).map(move |v| (slot, v)))
                    .map(|(slot, v)| {
                        let shift = 64 - nb * (slot + 1);
                        (next() & !(((1u64 << nb) - 1) << shift)) | (v << shift)
                    })
                    .collect();
                words.extend((0..2000).map(|_| next()));
                words.extend([0, u64::MAX, 0x5555_5555_5555_5555, 0xAAAA_AAAA_AAAA_AAAA]);
                for &x in &words {
                    let want = naive_hits(x, nb, c, 64);
                    assert_eq!(m.hits(x), want, "u64 nb {nb} c {c} x {x:#x}");
                    assert_eq!(m.hits_planes(x), want, "planes u64 nb {nb} c {c} x {x:#x}");
                    let y = x as u32;
                    let want = naive_hits(y as u64, nb, c, 32) as u32;
                    assert_eq!(m.hits(y), want, "u32 nb {nb} c {c} x {y:#x}");
                    assert_eq!(m.hits_planes(y), want, "planes u32 nb {nb} c {c} x {y:#x}");
                }
            }
        }
    }

    /// The four-word AVX2 test is `hits` of each word, for every width and
    /// threshold, with groups where one word, several or none match.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn hit_words4_is_the_hits_of_four_words() {
        if !std::is_x86_feature_detected!("avx2") {
            return;
        }
        let mut next = crate::testing::xorshift(0x2545_F491_4F6C_DD1D);
        for nb in CODE_WIDTHS {
            for c in 1..(1u32 << nb) {
                let m = Matcher::new(nb, c);
                for _ in 0..4000 {
                    // words of codes below c, each slot drawn from 0..c
                    let mut below = || (0..64 / nb).fold(0u64, |w, slot| w | ((next() % c as u64) << (64 - nb * (slot + 1))));
                    let mut g = [below(), below(), below(), below()];
                    for _ in 0..next() % 3 {
                        g[(next() % 4) as usize] = next();
                    }
                    let want = (0..4).filter(|&i| m.hits(g[i]) != 0).fold(0u32, |a, i| a | 1 << i);
                    // SAFETY: AVX2 detected above; `g` holds four words.
                    assert_eq!(unsafe { m.hit_words4(g.as_ptr()) }, want, "nb {nb} c {c} {g:x?}");
                }
            }
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

    fn check_codes<W: Word>(nb: u32, row: &[W]) {
        let slots = (W::BITS / nb) as usize;
        let code = |k: usize| -> u32 {
            let w = row[k / slots].as_u64();
            ((w >> slot_shift::<W>(nb, (k % slots) as u32)) & ((1 << nb) - 1)) as u32
        };
        let n = row.len() * slots;
        for c in 1..(1u32 << nb) {
            let m = Matcher::new(nb, c);
            for asc in [true, false] {
                let mut want: Vec<usize> = (0..n).filter(|&k| code(k) >= c).collect();
                if !asc {
                    want.reverse();
                }
                for s in [Search::Lut, Search::Bitscan] {
                    let got: Vec<usize> = SetBits::with_matcher(row, asc, s, &m).collect();
                    assert_eq!(got, want, "nb={nb} c={c} asc={asc} {s:?}");
                    // peeking (even twice) before each step changes nothing
                    let mut it = SetBits::with_matcher(row, asc, s, &m);
                    let mut peeked = Vec::new();
                    while let Some(k) = it.peek() {
                        assert_eq!(it.peek(), Some(k));
                        assert_eq!(it.next(), Some(k));
                        peeked.push(k);
                    }
                    assert_eq!(it.next(), None);
                    assert_eq!(peeked, want, "peek nb={nb} c={c} asc={asc} {s:?}");
                }
            }
        }
    }

    #[test]
    fn code_search_lut_bitscan_and_naive_agree() {
        // exhaustive over every byte in every byte position, then random words
        for nb in CODE_WIDTHS {
            for byte in 0..256u64 {
                for pos in 0..8 {
                    check_codes::<u64>(nb, &[byte << (8 * pos)]);
                    if pos < 4 {
                        check_codes::<u32>(nb, &[(byte << (8 * pos)) as u32]);
                    }
                }
            }
        }
        let mut s = 0xABCDEFu64;
        for _ in 0..3000 {
            let mut row = [0u64; 3];
            for w in row.iter_mut() {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                *w = if s & 7 == 0 { 0 } else { s & (s >> 9) };
            }
            for nb in CODE_WIDTHS {
                check_codes::<u64>(nb, &row);
                check_codes::<u32>(nb, &row.map(|x| x as u32));
            }
        }
    }

    #[test]
    fn code_widths() {
        assert_eq!(code_width_for(1), Some(1));
        assert_eq!(code_width_for(3), Some(2));
        assert_eq!(code_width_for(4), Some(4));
        assert_eq!(code_width_for(15), Some(4));
        assert_eq!(code_width_for(16), None);
        assert_eq!(slot_mask::<u32>(2, 0), 0xC000_0000);
        assert_eq!(slot_mask::<u64>(4, 17), 0xF << (64 - 4 * 2));
    }
}
