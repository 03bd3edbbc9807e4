//! The candidate slices of a ray that is not a mask column: the
//! binary rotator under scaled sample maps (a perspective plan, or a parallel
//! plan at another pixel pitch).
//!
//! The mask stays sheared to the plan's [`ShearState`] (for a perspective plan,
//! the parallel factorization of the same camera direction: the *central*
//! direction). A ray of a scaled plan samples slice `k` at
//! `x_k = σ_k · a + τ_k` (per in-slice axis), which is affine in `k`, and so is
//! its drift across the sheared mask, `u_k = x_k − trans[k]`. [`ColumnWalk`]
//! cuts the ray into segments of slices over which `floor(u_k)` stays put (on
//! both axes), and for each segment ORs the matching codes of the few mask
//! columns that can hold the sample's cell, masked to the segment's slices, then
//! bit-scans them: one masked word test per column and word of the segment.
//!
//! **Which columns hold a sample's cell.** The sample of slice `k` lies in cell
//! `c = floor(x_k)`, the only cell whose four corners its bilinear
//! interpolation reads. The mask keeps slice `k`'s cells at integer offset
//! `f = floor(trans[k])`, so with cell size 1 the cell sits in column
//! `c − f + PAD`, and `h = c − f = floor(u_k + trans[k]) − floor(trans[k])`
//! is `floor(u_k + frac(trans[k]))`: `floor(u_k)` or `floor(u_k) + 1`, and
//! exactly one of them where the slices' fractions allow (the walk bounds it
//! with the range of the fractions over each block of slices). With super cells of size `s` the slice sits
//! at super offset `F = ceil(f / s)`, `s·F = f + φ` with `0 ≤ φ < s`, and super
//! column `P` holds super cell `SI = P − PAD + F`, which covers cells
//! `[s·SI − (s − 1), s·SI + (s − 1)]`; `P − PAD = floor(g / s)` with
//! `g = h − φ` satisfies that, and `g` lies in `[h − (s − 1), h]`. So over a
//! segment with `h ∈ [h0, h1]` the columns
//! `PAD + [⌊(h0 − s + 1)/s⌋, ⌊h1/s⌋]` (at cell size 1 one or two per axis)
//! hold every sample's cell, and
//! the walk's candidates are a superset of the slices whose sample can be
//! visible: every candidate is confirmed by a real sample, as with super cells,
//! and the image is the brute force's, bit for bit. The bounds of `u` come from
//! the segment's end slices (affine: the extremes), widened by a rounding
//! margin; columns outside the grid hold nothing and are dropped.
//!
//! **Blocks.** A ray far from the central direction crosses a column every few
//! slices, so its empty stretches would cost a segment each. [`BlockOccupancy`]
//! (built once per frame from the sheared mask, after the shear) counts, for
//! every block of slices (a quarter of a word), the mask columns with a
//! matching code in the block, as a summed-area table over the occupied
//! rectangle. Before walking the segments of a block, the ray asks whether any
//! column of the rectangle its drift spans over the whole block has a match
//! there (four loads); if none does, the block is skipped at once. The
//! rectangle is a superset of every segment's columns, so nothing is lost. A
//! ray's slices are also cut to those with any non-zero code.
//!
//! **Groups.** Neighbouring rays cross the same empty blocks in front of (and
//! behind) the surface: [`BlockOccupancy::first_block`] asks the table once
//! per group of rays for the rectangle of the union of their drifts over each
//! block, and each ray walks only between its group's first and last blocks
//! with a possible candidate. A ray's drift comes from a [`Drift`] made once
//! per row (affine in the ray's sheared point).

//! **Rays that do not drift.** A parallel plan at another pixel pitch
//! (`--quality`, Deluxe M) has the same scale in every slice and translations
//! that move with the shear's, so a ray's drift `u` is the same in every slice
//! ([`Drift::is_still`]). Its cells then sit in the columns
//! `floor(u + frac(trans[k]))`: one or two per axis over the frame's range of
//! fractions (three where the rounding margin reaches past an integer).
//! [`StillWalk`] finds them once per ray and, per word of slices, bit-scans
//! the matches of their codes ORed, as a translated ray scans its one column: no
//! segments, no block table (the frame builds none). Callgrind, head phantom
//! at 512², `--quality 2`, 10 frames: render and table 963 M → 539 M
//! instructions against [`ColumnWalk`].

use crate::encode::depth::{Matcher, Search, Word, lz, tz};

use crate::encode::mask::{BinaryMask, BlockOccupancy, SliceSpan, columns};
use crate::view::plan::{FramePlan, ScaledMap, floor_i64};
use crate::view::shear::ShearState;

/// Largest change of the drift per slice that [`Drift::is_still`] takes for
/// none: the translations' rounding (voxel units; far below [`MARGIN`](crate::encode::mask::MARGIN) over
/// any stack).
const STILL: f64 = 1e-12;

/// How many integer crossings of the drift a segment may span on each axis
/// (its columns come from its end slices, whatever its length): two halves
/// the segments of a fast-drifting ray for one more row read each (callgrind,
/// head phantom, FOV 30° from 2 diagonals: render 192.8 → 187.5 M
/// instructions; more than two changes nothing there, the blocks end first).
const SPAN: f64 = 2.0;

/// A scaled plan's drift across a mask sheared to the plan's shear, for every
/// ray at once: the drift of the ray through sheared point `a` at slice `k`,
/// `u = σ_k · a + τ_k − trans[k]`, is affine in `k` and, at any one slice, in
/// `a`, so it is `u0(a) + g(a) · (k − k0)` with `u0` and `g` affine in `a`
/// (per axis). Made once per row from the plan's end slices: a ray's walk
/// starts from two multiply-adds per axis instead of maps read at its own
/// end slices and a division.
#[derive(Clone, Copy, Debug)]
pub struct Drift {
    /// The reference slice.
    k0: f64,
    /// Per axis: `u0 = c[0] · a + c[1]`, `g = c[2] · a + c[3]`.
    c: [[f64; 4]; 2],
}

impl Drift {
    /// The drift of the rays of `scaled` maps across a mask sheared to `shear`,
    /// from the slices `lo` and `hi` (any two, the farther apart the better).
    pub fn new(shear: &ShearState, scaled: &[ScaledMap], lo: usize, hi: usize) -> Self {
        let c = [0, 1].map(|ax| {
            let (s0, t0) = (scaled[lo].scale, scaled[lo].trans[ax] - shear.trans[ax][lo]);
            if hi <= lo {
                return [s0, t0, 0.0, 0.0];
            }
            let (s1, t1) = (scaled[hi].scale, scaled[hi].trans[ax] - shear.trans[ax][hi]);
            let n = (hi - lo) as f64;
            [s0, t0, (s1 - s0) / n, (t1 - t0) / n]
        });
        Drift { k0: lo as f64, c }
    }

    /// The drift of `plan`'s rays across its mask (sheared to the plan's
    /// shear), from the ends of its slice range: what both the frame (which
    /// block table to build) and the rows (which walk) ask.
    pub fn for_plan(plan: &FramePlan) -> Self {
        let [lo, hi] = plan.k_range;
        Drift::new(&plan.shear, &plan.scaled, lo.min(hi), hi)
    }

    /// True when no ray drifts (a parallel plan at another pixel pitch: every
    /// slice has the same scale, and its translation moves with the shear's):
    /// each ray keeps its drift over all slices, and [`StillWalk`] serves it.
    /// (The drift is affine in `k`, so its two end slices decide.)
    pub fn is_still(&self) -> bool {
        self.c.iter().all(|c| c[2] == 0.0 && c[3].abs() < STILL)
    }

    /// The drift of the ray through `at` at the reference slice, and its
    /// change per slice (per axis).
    #[inline(always)]
    fn of(&self, at: [f64; 2]) -> ([f64; 2], [f64; 2]) {
        let c = &self.c;
        ([c[0][0] * at[0] + c[0][1], c[1][0] * at[1] + c[1][1]], [c[0][2] * at[0] + c[0][3], c[1][2] * at[1] + c[1][3]])
    }
}

/// The slots of slices `lo ..= hi` (index order, both in word `w` of a
/// depth row of `2^log_nb`-bit codes) as a mask over that word: what both
/// walks keep of a word's matches.
#[inline(always)]
fn slots_of<W: Word>(log_nb: u32, w: usize, lo: usize, hi: usize) -> W {
    let (slots, nb) = ((W::BITS >> log_nb) as usize, 1u32 << log_nb);
    let (j0, j1) = ((lo - w * slots) as u32, (hi - w * slots) as u32);
    let all = !W::ZERO;
    (all >> (nb * j0)) & (all << (W::BITS - nb * (j1 + 1)))
}

/// The slot of the first match of `cur` (the top bits of its matching slots;
/// not zero) in walking order, cleared from `cur`: the step both walks'
/// searches share.
#[inline(always)]
fn take_first<W: Word>(cur: &mut W, ascending: bool, search: Search, log_nb: u32) -> usize {
    let bit = if ascending { lz(*cur, search) } else { W::BITS - 1 - tz(*cur, search) };
    // clear it (the top bit of its slot)
    *cur &= !(W::MSB >> bit);
    (bit >> log_nb) as usize
}

/// The slices of one ray of a scaled plan whose mask codes match, front to back
/// (a superset of the slices whose sample may be visible; see the module docs).
pub struct ColumnWalk<'a, W: Word> {
    mask: &'a BinaryMask<W>,
    occ: &'a BlockOccupancy,
    m: &'a Matcher,
    search: Search,
    ascending: bool,
    /// The drift along each axis: `u(k) = u0 + g · (k − k0)`; `step` is the
    /// slices per unit of drift, `1/|g|` (infinite for no drift).
    u0: [f64; 2],
    g: [f64; 2],
    step: [f64; 2],
    k0: f64,
    /// Slices of the ray `[lo, hi]` (index order).
    lo: usize,
    hi: usize,
    /// The next block (word index) to examine and the last one, in walking
    /// order; `done` once every block is examined.
    block: usize,
    block_end: usize,
    done: bool,
    /// The word of the block in progress.
    word: usize,
    /// Within the block: the next slice to cover and the block's last, in
    /// walking order (`in_block` false: the block is finished).
    next: usize,
    last: usize,
    in_block: bool,
    /// The current segment's matches (top bit of each matching slot) in word
    /// `block`.
    cur: W,
    /// A slice found by [`ColumnWalk::peek`] and not yet returned.
    pending: Option<usize>,
    log_nb: u32,
}

impl<'a, W: Word> ColumnWalk<'a, W> {
    /// The walk of the ray through sheared point `at` over the slices of
    /// `span` of a mask whose drift is `drift`,
    /// skipping blocks by `occ` (built for this mask, shear and matcher).
    #[inline(always)]
    pub fn new(
        mask: &'a BinaryMask<W>,
        occ: &'a BlockOccupancy,
        drift: &Drift,
        at: [f64; 2],
        span: SliceSpan,
        search: Search,
        m: &'a Matcher,
    ) -> Self {
        let SliceSpan { lo, hi, ascending } = span;
        let log_nb = m.width().trailing_zeros();
        // only the slices with a non-zero code
        let (lo, hi) = (lo.max(occ.slices[0]), hi.min(occ.slices[1]));
        let (u0, g) = drift.of(at);
        let (bl, bh) = (lo >> occ.log_len, hi >> occ.log_len);
        let (block, block_end) = if ascending { (bl, bh) } else { (bh, bl) };
        ColumnWalk {
            mask,
            occ,
            m,
            search,
            ascending,
            u0,
            g,
            step: g.map(|x| 1.0 / x.abs()),
            k0: drift.k0,
            lo,
            hi,
            block,
            block_end,
            done: lo > hi,
            word: 0,
            next: 0,
            last: 0,
            in_block: false,
            cur: W::ZERO,
            pending: None,
            log_nb,
        }
    }

    /// The walk that returns slice `k` alone (a ray whose first sample is
    /// already its result).
    pub fn only(mask: &'a BinaryMask<W>, occ: &'a BlockOccupancy, m: &'a Matcher, search: Search, k: usize) -> Self {
        ColumnWalk {
            mask,
            occ,
            m,
            search,
            ascending: true,
            u0: [0.0; 2],
            g: [0.0; 2],
            step: [f64::INFINITY; 2],
            k0: k as f64,
            lo: k,
            hi: k,
            block: 0,
            block_end: 0,
            done: true,
            word: 0,
            next: 0,
            last: 0,
            in_block: false,
            cur: W::ZERO,
            pending: Some(k),
            log_nb: m.width().trailing_zeros(),
        }
    }

    /// The drift along axis `ax` at slice `k`.
    #[inline(always)]
    fn drift(&self, ax: usize, k: usize) -> f64 {
        self.u0[ax] + self.g[ax] * (k as f64 - self.k0)
    }

    /// The mask columns `[c0, c1]` along axis `ax` that hold the cells of the
    /// samples of slices from `ka` to `kb`, clipped to the grid (`None`: off
    /// the grid).
    #[inline(always)]
    fn columns(&self, ax: usize, ka: usize, kb: usize) -> Option<(usize, usize)> {
        let (a, b) = (self.drift(ax, ka), self.drift(ax, kb));
        // (ka and kb share a block)
        columns(self.mask, &self.occ.frac[ka >> self.occ.log_len], ax, a.min(b), a.max(b))
    }

    /// Starts the next block with a possible match; false when none is left.
    #[inline]
    fn start_block(&mut self) -> bool {
        let len = self.occ.len;
        while !self.done {
            let b = self.block;
            if b == self.block_end {
                self.done = true;
            } else {
                self.block = if self.ascending { b + 1 } else { b - 1 };
            }
            let (ka, kb) = (self.lo.max(b * len), self.hi.min(b * len + len - 1));
            let (Some((p0, p1)), Some((q0, q1))) = (self.columns(0, ka, kb), self.columns(1, ka, kb)) else { continue };
            // (asked even for a rectangle a segment would read: the table's four
            // loads are cheaper than the mask's rows; interleaved A/B, head
            // 256³ at 512², FOV 30°: render 16–18 ms against 24–26 ms)
            if !self.occ.any(b, p0, p1, q0, q1) {
                continue;
            }
            // a block lies within one word (its length divides the word's slots;
            // shifts: a division per block was a visible cost)
            self.word = (ka << self.log_nb) / W::BITS as usize;
            (self.next, self.last) = if self.ascending { (ka, kb) } else { (kb, ka) };
            self.in_block = true;
            return true;
        }
        false
    }

    /// Starts the next segment of the block in progress, its matches in `cur`;
    /// false when the block is finished.
    #[inline]
    fn start_segment(&mut self) -> bool {
        if !self.in_block {
            return false;
        }
        let k0 = self.next;
        let left = if self.ascending { self.last - k0 } else { k0 - self.last };
        // the slices after k0 before the drift's floor changes `SPAN` times on
        // either axis (u reaches the next integer `room` steps on); only an
        // estimate: the segment's columns come from its end slices' drifts,
        // whatever its length
        let mut len = left;
        for ax in 0..2 {
            let (u, du) = (self.drift(ax, k0), if self.ascending { self.g[ax] } else { -self.g[ax] });
            let f = floor_i64(u) as f64;
            // (no drift: an infinite step, and a room no segment reaches)
            let room = if du > 0.0 { (f + SPAN - u) * self.step[ax] } else { (u - f + SPAN - 1.0) * self.step[ax] };
            if room < left as f64 {
                // ceil(room) − 1, without a call to `ceil`
                len = len.min((-floor_i64(-room) - 1).max(0) as usize);
            }
        }
        let k1 = if self.ascending { k0 + len } else { k0 - len };
        if k1 == self.last {
            self.in_block = false;
        } else {
            self.next = if self.ascending { k1 + 1 } else { k1 - 1 };
        }
        let (Some((p0, p1)), Some((q0, q1))) = (self.columns(0, k0, k1), self.columns(1, k0, k1)) else {
            self.cur = W::ZERO;
            return true;
        };
        let (lo, hi) = if self.ascending { (k0, k1) } else { (k1, k0) };
        let w = self.word;
        let range = slots_of::<W>(self.log_nb, w, lo, hi);
        let mut h = W::ZERO;
        for q in q0..=q1 {
            for p in p0..=p1 {
                h |= self.m.hits(self.mask.row(p, q)[w]);
            }
        }
        self.cur = h & range;
        true
    }

    /// The next matching slice, without consuming it.
    #[inline]
    pub fn peek(&mut self) -> Option<usize> {
        if self.pending.is_none() {
            self.pending = self.find();
        }
        self.pending
    }

    #[inline]
    fn find(&mut self) -> Option<usize> {
        let slots = (W::BITS >> self.log_nb) as usize;
        loop {
            if self.cur != W::ZERO {
                return Some(self.word * slots + take_first(&mut self.cur, self.ascending, self.search, self.log_nb));
            }
            if self.start_segment() {
                continue;
            }
            if !self.start_block() {
                return None;
            }
        }
    }
}

impl<W: Word> Iterator for ColumnWalk<'_, W> {
    type Item = usize;
    #[inline]
    fn next(&mut self) -> Option<usize> {
        match self.pending.take() {
            Some(k) => Some(k),
            None => self.find(),
        }
    }
}

/// The slices of one ray of a plan whose rays do not drift
/// ([`Drift::is_still`]) whose mask codes match, front to back: the ray's
/// cells sit in the same one or two mask columns per axis in every slice (see
/// the module docs: `floor(u + frac(trans[k]))` with `u` fixed; the columns
/// from the frame's range of fractions, found once), so the walk reads, per
/// word of slices, those columns' codes ORed, matches them once, masks the
/// matches to the ray's slices and bit-scans them, as a translated ray scans
/// its one column. No block table and no segments: one match per word.
pub struct StillWalk<'a, W: Word> {
    /// The mask's rows ([`BinaryMask::words`]) and where the ray's columns'
    /// rows start in them (`n` of them).
    words: &'a [W],
    rows: [u32; 9],
    n: usize,
    m: &'a Matcher,
    search: Search,
    ascending: bool,
    /// The ray's slices `[lo, hi]` (index order).
    lo: usize,
    hi: usize,
    /// The word in progress and the last one, in walking order; `done` once
    /// the last is read.
    word: usize,
    word_end: usize,
    done: bool,
    /// The matches (top bit of each matching slot) left in `word`.
    cur: W,
    pending: Option<usize>,
    log_nb: u32,
}

impl<'a, W: Word> StillWalk<'a, W> {
    /// The walk of the ray through sheared point `at` over the slices of
    /// `span` of a mask whose rays do not drift
    /// (`drift`: [`Drift::is_still`]), its columns chosen by `occ`'s fractions.
    #[inline(always)]
    pub fn new(
        mask: &'a BinaryMask<W>,
        occ: &'a BlockOccupancy,
        drift: &Drift,
        at: [f64; 2],
        span: SliceSpan,
        search: Search,
        m: &'a Matcher,
    ) -> Self {
        let SliceSpan { lo, hi, ascending } = span;
        let log_nb = m.width().trailing_zeros();
        let (lo, hi) = (lo.max(occ.slices[0]), hi.min(occ.slices[1]));
        let (u, _) = drift.of(at);
        let (wl, wh) = ((lo << log_nb) / W::BITS as usize, (hi << log_nb) / W::BITS as usize);
        let (word, word_end) = if ascending { (wl, wh) } else { (wh, wl) };
        let mut rows = [0u32; 9];
        let mut n = 0;
        let f = &occ.all_frac;
        if let (Some((p0, p1)), Some((q0, q1))) = (columns(mask, f, 0, u[0], u[0]), columns(mask, f, 1, u[1], u[1])) {
            // (two columns per axis, or three where the rounding margin
            // reaches past an integer: see the module docs)
            for q in q0..=q1 {
                for p in p0..=p1 {
                    rows[n] = mask.row_start(p, q) as u32;
                    n += 1;
                }
            }
        }
        let mut it = StillWalk {
            words: mask.words(),
            rows,
            n,
            m,
            search,
            ascending,
            lo,
            hi,
            word,
            word_end,
            done: lo > hi || n == 0,
            cur: W::ZERO,
            pending: None,
            log_nb,
        };
        if !it.done {
            it.load();
        }
        it
    }

    /// Reads word `word`: the matches of the ray's columns' codes ORed,
    /// masked to the ray's slices; marks the walk done at the last word.
    #[inline(always)]
    fn load(&mut self) {
        let w = self.word;
        self.done = w == self.word_end;
        // the codes ORed, then matched once: a slot's `a | b` is at least
        // `max(a, b)`, so every match of a column is a match of the OR (a
        // superset, as the columns are; exact for 1-bit codes and for
        // thresholds that are a power of two)
        let mut x = W::ZERO;
        for &r in &self.rows[..self.n] {
            x |= self.words[r as usize + w];
        }
        // the ray's slices in this word
        let slots = (W::BITS >> self.log_nb) as usize;
        let first = w * slots;
        self.cur = self.m.hits(x) & slots_of::<W>(self.log_nb, w, self.lo.max(first), self.hi.min(first + slots - 1));
    }

    /// The next matching slice, without consuming it.
    #[inline]
    pub fn peek(&mut self) -> Option<usize> {
        if self.pending.is_none() {
            self.pending = self.find();
        }
        self.pending
    }

    #[inline]
    fn find(&mut self) -> Option<usize> {
        let slots = (W::BITS >> self.log_nb) as usize;
        loop {
            if self.cur != W::ZERO {
                return Some(self.word * slots + take_first(&mut self.cur, self.ascending, self.search, self.log_nb));
            }
            if self.done {
                return None;
            }
            self.word = if self.ascending { self.word + 1 } else { self.word - 1 };
            self.load();
        }
    }
}

impl<W: Word> Iterator for StillWalk<'_, W> {
    type Item = usize;
    #[inline]
    fn next(&mut self) -> Option<usize> {
        match self.pending.take() {
            Some(k) => Some(k),
            None => self.find(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::slices::SliceStack;
    use crate::data::volume::Volume;

    #[test]
    fn quarter_flags_mark_the_non_zero_quarters() {
        let mut next = crate::testing::xorshift(0x2545_F491_4F6C_DD1D);
        for n in 0..20_000u32 {
            let s = next();
            // sparse words too: most quarters empty, single bits at the edges
            let x = match n % 4 {
                0 => s,
                1 => s & (s >> 3) & (s >> 7) & (s >> 11),
                2 => 1u64 << (s % 64),
                _ => 0,
            };
            let want = |bits: u32| (0..4).fold(0u64, |f, j| f | ((((x >> (j * bits)) & ((1u64 << bits) - 1)) != 0) as u64) << (16 * j));
            assert_eq!(crate::encode::mask::quarter_flags::<u64>(x), want(16), "u64 {x:#x}");
            let y = x & 0xFFFF_FFFF;
            let want32 = (0..4).fold(0u64, |f, j| f | ((((y >> (j * 8)) & 0xFF) != 0) as u64) << (16 * j));
            assert_eq!(crate::encode::mask::quarter_flags::<u32>(y), want32, "u32 {y:#x}");
        }
    }

    /// The block occupancy's answer for any rectangle and block is the naive
    /// scan of the mask's words, for 1-bit masks and threshold codes, u32 and
    /// u64, cell sizes 1 and 2, sheared.
    #[test]
    fn block_occupancy_equals_a_naive_scan() {
        let v = Volume::from_fn([15, 13, 70], [1.0; 3], |x, y, z| if (x * 7 + y * 13 + z * 5) % 31 == 0 { 100.0 } else { 0.0 }).unwrap();
        let st = SliceStack::new(&v, 2);
        let mut rnd = crate::testing::xorshift(77);
        fn check<W: Word>(codes: &CellCodes, s: usize, m: &Matcher, rnd: &mut impl FnMut() -> u64) {
            let mut mask = BinaryMask::<W>::from_codes(codes, s);
            let st = ShearState::from_ends(codes.nk, [[-9.3, 8.7], [5.2, -6.1]]);
            mask.shear_to(&st);
            mask.update_occupancy(m, &st, true);
            let occ = mask.occupancy();
            let [gw, gh] = mask.grid();
            let slots = (W::BITS / m.width()) as usize;
            let len = occ.block_len();
            for _ in 0..400 {
                let (mut p0, mut p1) = ((rnd() % gw as u64) as usize, (rnd() % gw as u64) as usize);
                let (mut q0, mut q1) = ((rnd() % gh as u64) as usize, (rnd() % gh as u64) as usize);
                if p0 > p1 {
                    std::mem::swap(&mut p0, &mut p1);
                }
                if q0 > q1 {
                    std::mem::swap(&mut q0, &mut q1);
                }
                let b = (rnd() % (mask.words_per_row() * slots / len) as u64) as usize;
                let naive = (q0..=q1).any(|q| {
                    (p0..=p1).any(|p| {
                        (b * len..(b + 1) * len)
                            .any(|k| m.hits(mask.row(p, q)[k / slots] & crate::encode::depth::slot_mask::<W>(m.width(), k)) != W::ZERO)
                    })
                });
                assert_eq!(occ.any(b, p0, p1, q0, q1), naive, "block {b} [{p0}, {p1}] x [{q0}, {q1}]");
            }
        }
        use crate::encode::mask::CellCodes;
        let binary = CellCodes::binary(&st, |_, hi| hi > 50.0);
        let coded = CellCodes::thresholds(&st, &[20.0, 50.0, 90.0]).unwrap();
        for s in [1, 2] {
            check::<u64>(&binary, s, &Matcher::binary(), &mut rnd);
            check::<u32>(&binary, s, &Matcher::binary(), &mut rnd);
            for c in 1..=3 {
                check::<u64>(&coded, s, &Matcher::new(2, c), &mut rnd);
                check::<u32>(&coded, s, &Matcher::new(2, c), &mut rnd);
            }
        }
    }
}
