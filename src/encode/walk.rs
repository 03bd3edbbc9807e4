//! Stage 5b′ — the candidate slices of a ray that is not a mask column: the
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
//! `c − f + PAD`, and `c − f = floor(u_k + trans[k]) − floor(trans[k])` is
//! `floor(u_k)` or `floor(u_k) + 1`. With super cells of size `s` the slice sits
//! at super offset `F = ceil(f / s)`, `s·F = f + φ` with `0 ≤ φ < s`, and super
//! column `P` holds super cell `SI = P − PAD + F`, which covers cells
//! `[s·SI − (s − 1), s·SI + (s − 1)]`; `P − PAD = floor(g / s)` with
//! `g = c − f − φ` satisfies that, and `g` lies in
//! `[floor(u_k) − (s − 1), floor(u_k) + 1]`. So over a segment with
//! `floor(u_k) ∈ [m0, m1]` the columns `PAD + [⌊(m0 − s + 1)/s⌋, ⌊(m1 + 1)/s⌋]`
//! (two per axis, four in all, in the usual case) hold every sample's cell, and
//! the walk's candidates are a superset of the slices whose sample can be
//! visible: every candidate is confirmed by a real sample, as with super cells,
//! and the image is the brute force's, bit for bit. The bounds of `u` come from
//! the segment's end slices (affine: the extremes), widened by a rounding
//! margin; columns outside the grid hold nothing and are dropped.

use crate::encode::depth::{Matcher, Search, Word, lz, tz};
use crate::encode::mask::BinaryMask;
use crate::encode::shear::ShearState;
use crate::view::plan::ScaledMap;

/// Rounding margin on the drift `u` (voxels): the maps are computed per slice
/// in f64, affine in `k` to far below this.
const MARGIN: f64 = 1e-7;

/// The slices of one ray of a scaled plan whose mask codes match, front to back
/// (a superset of the slices whose sample may be visible; see the module docs).
pub struct ColumnWalk<'a, W: Word> {
    mask: &'a BinaryMask<W>,
    m: &'a Matcher,
    search: Search,
    ascending: bool,
    /// The ray's sheared point `(a, b)`.
    at: [f64; 2],
    scaled: &'a [ScaledMap],
    trans: &'a [Vec<f64>; 2],
    /// The next slice to cover (index), and the last one, in walking order;
    /// `done` once every slice is covered.
    next: usize,
    last: usize,
    done: bool,
    /// The segment in progress: its slices `[lo, hi]` (index order), its columns
    /// `[p0, p1] × [q0, q1]` and the word being scanned, `w`, with `cur` its
    /// remaining matches (top bit of each matching slot).
    seg: [usize; 2],
    cols: [usize; 4],
    w: usize,
    w_end: usize,
    cur: W,
    in_seg: bool,
    /// A slice found by [`ColumnWalk::peek`] and not yet returned.
    pending: Option<usize>,
    log_nb: u32,
}

impl<'a, W: Word> ColumnWalk<'a, W> {
    /// The walk of the ray through sheared point `at` over slices `[lo, hi]`
    /// (index order; none when `lo > hi`) of a mask sheared to `shear`, under
    /// the slices' `scaled` maps.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        mask: &'a BinaryMask<W>,
        shear: &'a ShearState,
        scaled: &'a [ScaledMap],
        at: [f64; 2],
        lo: usize,
        hi: usize,
        ascending: bool,
        search: Search,
        m: &'a Matcher,
    ) -> Self {
        let (next, last) = if ascending { (lo, hi) } else { (hi, lo) };
        ColumnWalk {
            mask,
            m,
            search,
            ascending,
            at,
            scaled,
            trans: &shear.trans,
            next,
            last,
            done: lo > hi,
            seg: [0, 0],
            cols: [0; 4],
            w: 0,
            w_end: 0,
            cur: W::ZERO,
            in_seg: false,
            pending: None,
            log_nb: m.width().trailing_zeros(),
        }
    }

    /// The drift `u_k` of the ray across the mask along axis `ax` at slice `k`.
    #[inline(always)]
    fn drift(&self, ax: usize, k: usize) -> f64 {
        let m = &self.scaled[k];
        m.scale * self.at[ax] + m.trans[ax] - self.trans[ax][k]
    }

    /// Starts the next segment from slice `self.next`; false when none is left.
    #[inline]
    fn start_segment(&mut self) -> bool {
        if self.done {
            return false;
        }
        let k0 = self.next;
        let left = if self.ascending { self.last - k0 } else { k0 - self.last };
        // the slices until floor(u) may change on either axis
        let mut len = left;
        let u0 = [self.drift(0, k0), self.drift(1, k0)];
        if left > 0 {
            let k1 = if self.ascending { k0 + 1 } else { k0 - 1 };
            for (ax, &u) in u0.iter().enumerate() {
                let du = self.drift(ax, k1) - u;
                let f = u.floor();
                let room = if du > 0.0 {
                    (f + 1.0 - u) / du
                } else if du < 0.0 {
                    (u - f) / -du
                } else {
                    f64::INFINITY
                };
                // the slices after k0 with the same floor (u reaches the next
                // integer `room` steps on); only an estimate: the segment's
                // columns come from its end slices' drifts, whatever its length
                if room.is_finite() {
                    len = len.min((room.ceil() - 1.0).max(0.0) as usize);
                }
            }
        }
        let k1 = if self.ascending { k0 + len } else { k0 - len };
        if k1 == self.last {
            self.done = true;
        } else {
            self.next = if self.ascending { k1 + 1 } else { k1 - 1 };
        }
        let (lo, hi) = if self.ascending { (k0, k1) } else { (k1, k0) };
        let s = self.mask.cell_size() as i64;
        let pad = self.mask.pad() as i64;
        let grid = self.mask.grid();
        let mut cols = [0usize; 4];
        for ax in 0..2 {
            let (a, b) = (u0[ax], self.drift(ax, k1));
            let m0 = (a.min(b) - MARGIN).floor() as i64;
            let m1 = (a.max(b) + MARGIN).floor() as i64;
            let c0 = (m0 - s + 1).div_euclid(s) + pad;
            let c1 = (m1 + 1).div_euclid(s) + pad;
            let (c0, c1) = (c0.max(0), c1.min(grid[ax] as i64 - 1));
            if c0 > c1 {
                // the ray is outside the grid over this segment: nothing to find
                self.in_seg = false;
                return true;
            }
            cols[2 * ax] = c0 as usize;
            cols[2 * ax + 1] = c1 as usize;
        }
        let slots = (W::BITS >> self.log_nb) as usize;
        self.seg = [lo, hi];
        self.cols = cols;
        let (wl, wh) = (lo / slots, hi / slots);
        (self.w, self.w_end) = if self.ascending { (wl, wh) } else { (wh, wl) };
        self.cur = self.word(self.w);
        self.in_seg = true;
        true
    }

    /// The matches of word `w` of the segment's columns, within its slices.
    #[inline(always)]
    fn word(&self, w: usize) -> W {
        let slots = (W::BITS >> self.log_nb) as usize;
        let nb = 1u32 << self.log_nb;
        let [lo, hi] = self.seg;
        let j0 = lo.max(w * slots) - w * slots;
        let j1 = hi.min(w * slots + slots - 1) - w * slots;
        let all = !W::ZERO;
        let range = (all >> (nb * j0 as u32)) & (all << (W::BITS - nb * (j1 as u32 + 1)));
        let [p0, p1, q0, q1] = self.cols;
        let mut h = W::ZERO;
        for q in q0..=q1 {
            for p in p0..=p1 {
                h |= self.m.hits(self.mask.row(p, q)[w]);
            }
        }
        h & range
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
            if self.in_seg {
                if self.cur != W::ZERO {
                    let bit = if self.ascending { lz(self.cur, self.search) } else { W::BITS - 1 - tz(self.cur, self.search) };
                    // clear it (the top bit of its slot)
                    self.cur &= !(W::MSB >> bit);
                    return Some(self.w * slots + (bit >> self.log_nb) as usize);
                }
                if self.w != self.w_end {
                    self.w = if self.ascending { self.w + 1 } else { self.w - 1 };
                    self.cur = self.word(self.w);
                    continue;
                }
                self.in_seg = false;
            }
            if !self.start_segment() {
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
