//! Stage 3 — the bit-packed binary cell mask of one principal axis, and its shear.
//!
//! Owns [`BinaryMask`]: for every cell `(ci, cj)` of every slice `k` one bit that
//! is 1 when the cell *may* hold a visible sample (decided by a predicate on the
//! range of its four in-slice corner densities, so it is conservative for any
//! transfer function), packed along depth into words of type `W` (u32 or u64,
//! one implementation), and kept *sheared*: the bit of cell `(ci, cj, k)` sits at
//! mask column `(ci + pad − floor_i[k], cj + pad − floor_j[k])`.
//!
//! Layout: `words[(q · width + p) · nw + w]` — the `nw` words of one depth row
//! (one ray of the intermediate image) are contiguous. The grid is padded by
//! `pad = ceil((nk − 1)/2) + 2` on every side, enough for any shear up to 45°
//! about the centre slice, so no bit is ever shifted out.
//!
//! Shearing: [`BinaryMask::shear_to`] moves the mask to a target [`ShearState`],
//! by incremental one-bit steps (per-bit shift vectors: each slice moves −1, 0
//! or +1, the split between directions may fall anywhere inside a word) when the
//! target is at most a few bits away, else by a direct shear (clear and re-scatter
//! from the unsheared cell bits). Either way only the occupied rectangle of the
//! grid is touched.

use bitvec::prelude::*;
use rayon::prelude::*;

use crate::depth::{Word, bit_of};
use crate::shear::{ShearState, shift_vectors};
use crate::slices::SliceStack;

/// Steps above this count are done as one direct shear instead.
pub const MAX_INCREMENTAL_STEPS: u32 = 6;

/// Padding and grid size of the sheared mask (and intermediate image) for a
/// volume of `cells` cells per slice and `nk` slices: `pad = ceil((nk − 1)/2) + 2`
/// covers every translation `|trans| ≤ (nk − 1)/2` of a view whose shear is at most
/// one (plus rounding), so no bit is ever shifted out.
pub fn geometry(cells: [usize; 2], nk: usize) -> (usize, [usize; 2]) {
    let pad = nk.saturating_sub(1).div_ceil(2) + 2;
    (pad, [cells[0] + 2 * pad, cells[1] + 2 * pad])
}

/// Inclusive rectangle `[p0, p1] × [q0, q1]` of mask columns.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rect {
    pub p0: usize,
    pub p1: usize,
    pub q0: usize,
    pub q1: usize,
}

impl Rect {
    fn union(a: Option<Rect>, b: Option<Rect>) -> Option<Rect> {
        match (a, b) {
            (Some(a), Some(b)) => Some(Rect {
                p0: a.p0.min(b.p0),
                p1: a.p1.max(b.p1),
                q0: a.q0.min(b.q0),
                q1: a.q1.max(b.q1),
            }),
            (a, None) => a,
            (None, b) => b,
        }
    }
}

/// How many words a step or shear touched (for the "limit of the shear step" report).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ShearWork {
    /// Incremental one-bit steps performed.
    pub steps: u32,
    /// Direct shears performed.
    pub direct: u32,
    /// Words read-modify-written.
    pub words: u64,
}

/// The sheared binary cell mask of one principal axis.
#[derive(Clone, Debug)]
pub struct BinaryMask<W: Word> {
    /// Cells along i and j.
    cells: [usize; 2],
    /// Slices.
    nk: usize,
    /// Padding on each side.
    pad: usize,
    /// Grid size `[width, height]` in mask columns.
    grid: [usize; 2],
    /// Words per depth row.
    nw: usize,
    words: Vec<W>,
    /// Unsheared cell bits, slice-major: `k · ci·cj + cj · ci + ci`.
    base: BitVec<u64, Lsb0>,
    /// Per-slice bounding box of set cells `[ci0, ci1, cj0, cj1]`.
    bbox: Vec<Option<[usize; 4]>>,
    /// Current mask offset of each slice along i and j: `pad − floor[k]`.
    off: [Vec<i32>; 2],
    /// Scratch for shifts (no allocation per frame).
    up: Vec<W>,
    down: Vec<W>,
    keep: Vec<W>,
    row_buf: Vec<W>,
    target: [Vec<i32>; 2],
}

impl<W: Word> BinaryMask<W> {
    /// Builds the mask of `stack`: cell `(ci, cj, k)` is set when
    /// `visible(lo, hi)` for the range `[lo, hi]` of its four corner densities.
    /// The mask starts unsheared (identity state).
    pub fn build(stack: &SliceStack, visible: impl Fn(f32, f32) -> bool + Sync) -> Self {
        let [ci_n, cj_n] = stack.cells();
        let nk = stack.n[2];
        let per = ci_n * cj_n;
        // classify cells slice by slice in parallel; a row's column minima/maxima are reused
        let slices: Vec<(BitVec<u64, Lsb0>, Option<[usize; 4]>)> = (0..nk)
            .into_par_iter()
            .map(|k| {
                let mut bits = bitvec![u64, Lsb0; 0; per];
                let mut bb: Option<[usize; 4]> = None;
                let mut colmin = vec![0f32; ci_n + 1];
                let mut colmax = vec![0f32; ci_n + 1];
                for cj in 0..cj_n {
                    for (i, (mn, mx)) in colmin.iter_mut().zip(colmax.iter_mut()).enumerate() {
                        let (a, b) = (stack.at(i, cj, k), stack.at(i, cj + 1, k));
                        *mn = a.min(b);
                        *mx = a.max(b);
                    }
                    for ci in 0..ci_n {
                        let lo = colmin[ci].min(colmin[ci + 1]);
                        let hi = colmax[ci].max(colmax[ci + 1]);
                        if visible(lo, hi) {
                            bits.set(cj * ci_n + ci, true);
                            bb = Some(match bb {
                                None => [ci, ci, cj, cj],
                                Some([a, b, c, d]) => [a.min(ci), b.max(ci), c.min(cj), d.max(cj)],
                            });
                        }
                    }
                }
                (bits, bb)
            })
            .collect();
        let mut base = BitVec::with_capacity(per * nk);
        let mut bbox = Vec::with_capacity(nk);
        for (bits, bb) in slices {
            base.extend_from_bitslice(&bits);
            bbox.push(bb);
        }
        Self::from_cells([ci_n, cj_n], nk, base, bbox)
    }

    /// Builds from unsheared cell bits directly (used by super-cell and code masks).
    pub fn from_cells(
        cells: [usize; 2],
        nk: usize,
        base: BitVec<u64, Lsb0>,
        bbox: Vec<Option<[usize; 4]>>,
    ) -> Self {
        let (pad, grid) = geometry(cells, nk);
        let nw = nk.div_ceil(W::BITS as usize).max(1);
        let mut m = BinaryMask {
            cells,
            nk,
            pad,
            grid,
            nw,
            words: vec![W::ZERO; grid[0] * grid[1] * nw],
            base,
            bbox,
            off: [vec![pad as i32; nk], vec![pad as i32; nk]],
            up: vec![W::ZERO; nw],
            down: vec![W::ZERO; nw],
            keep: vec![W::ZERO; nw],
            row_buf: vec![W::ZERO; grid[0] * nw],
            target: [vec![0; nk], vec![0; nk]],
        };
        m.scatter();
        m
    }

    /// Grid size `[width, height]` in mask columns (= intermediate image size).
    pub fn grid(&self) -> [usize; 2] {
        self.grid
    }
    /// Padding on each side.
    pub fn pad(&self) -> usize {
        self.pad
    }
    /// Words per depth row.
    pub fn words_per_row(&self) -> usize {
        self.nw
    }
    /// Slices.
    pub fn slices(&self) -> usize {
        self.nk
    }
    /// Cells along i and j.
    pub fn cells(&self) -> [usize; 2] {
        self.cells
    }
    /// The depth row of mask column `(p, q)`.
    #[inline(always)]
    pub fn row(&self, p: usize, q: usize) -> &[W] {
        let s = (q * self.grid[0] + p) * self.nw;
        &self.words[s..s + self.nw]
    }
    /// All words (for comparisons in tests).
    pub fn words(&self) -> &[W] {
        &self.words
    }
    /// Bytes of the packed, sheared array.
    pub fn bytes(&self) -> usize {
        self.words.len() * W::BITS as usize / 8
    }
    /// The unsheared cell bit of `(ci, cj, k)`.
    pub fn cell(&self, ci: usize, cj: usize, k: usize) -> bool {
        self.base[(k * self.cells[1] + cj) * self.cells[0] + ci]
    }
    /// Current integer offsets `floor(trans)` of each slice along i and j.
    pub fn floors(&self) -> [Vec<i32>; 2] {
        [0, 1].map(|a| self.off[a].iter().map(|o| self.pad as i32 - o).collect())
    }

    /// The occupied rectangle of the grid for the given offsets, if any bit is set.
    fn occupied(&self, off: &[Vec<i32>; 2]) -> Option<Rect> {
        let mut r: Option<Rect> = None;
        for (k, bb) in self.bbox.iter().enumerate() {
            if let Some([ci0, ci1, cj0, cj1]) = *bb {
                let (oi, oj) = (off[0][k], off[1][k]);
                let s = Rect {
                    p0: (ci0 as i32 + oi) as usize,
                    p1: (ci1 as i32 + oi) as usize,
                    q0: (cj0 as i32 + oj) as usize,
                    q1: (cj1 as i32 + oj) as usize,
                };
                r = Rect::union(r, Some(s));
            }
        }
        r
    }

    /// The occupied rectangle in the current state.
    pub fn occupied_rect(&self) -> Option<Rect> {
        self.occupied(&self.off)
    }

    /// Checks that a state fits this mask (slice count and ≤ 45° shear).
    fn offsets_for(&self, state: &ShearState, out: &mut [Vec<i32>; 2]) {
        assert_eq!(
            state.slices(),
            self.nk,
            "shear state for a different slice count"
        );
        for a in 0..2 {
            for (o, &f) in out[a].iter_mut().zip(&state.floor[a]) {
                let v = self.pad as i32 - f;
                // pad covers |floor| ≤ ceil((nk-1)/2)+1: a principal-axis view never exceeds it
                assert!(
                    v >= 0 && v as usize + self.cells[a] <= self.grid[a],
                    "shear beyond 45° for this mask"
                );
                *o = v;
            }
        }
    }

    /// Moves the mask to `state`: incrementally when every slice is at most
    /// [`MAX_INCREMENTAL_STEPS`] bits away, else by a direct shear.
    pub fn shear_to(&mut self, state: &ShearState) -> ShearWork {
        let mut target = std::mem::take(&mut self.target);
        self.offsets_for(state, &mut target);
        let dist = (0..2)
            .flat_map(|a| {
                self.off[a]
                    .iter()
                    .zip(&target[a])
                    .map(|(x, y)| (x - y).unsigned_abs())
            })
            .max()
            .unwrap_or(0);
        let work = if dist == 0 {
            ShearWork::default()
        } else if dist <= MAX_INCREMENTAL_STEPS {
            let mut w = ShearWork::default();
            for _ in 0..dist {
                w.words += self.step_towards(&target);
                w.steps += 1;
            }
            w
        } else {
            self.direct(&target)
        };
        self.target = target;
        work
    }

    /// Moves the mask to `state` by a direct shear (the reset): clear the occupied
    /// region, then scatter every cell bit to its target position.
    pub fn shear_direct(&mut self, state: &ShearState) -> ShearWork {
        let mut target = std::mem::take(&mut self.target);
        self.offsets_for(state, &mut target);
        let w = self.direct(&target);
        self.target = target;
        w
    }

    fn direct(&mut self, target: &[Vec<i32>; 2]) -> ShearWork {
        let mut words = 0;
        if let Some(r) = self.occupied_rect() {
            let nw = self.nw;
            for q in r.q0..=r.q1 {
                let s = (q * self.grid[0] + r.p0) * nw;
                let e = (q * self.grid[0] + r.p1 + 1) * nw;
                self.words[s..e].fill(W::ZERO);
                words += (e - s) as u64;
            }
        }
        for a in 0..2 {
            self.off[a].copy_from_slice(&target[a]);
        }
        self.scatter();
        ShearWork {
            steps: 0,
            direct: 1,
            words,
        }
    }

    /// Writes every base cell bit at its current offset (the grid must be clear there).
    fn scatter(&mut self) {
        let [ci_n, cj_n] = self.cells;
        let (gw, nw, nk) = (self.grid[0], self.nw, self.nk);
        let (base, off, bbox) = (&self.base, &self.off, &self.bbox);
        // parallel over grid rows q: each row's words are written by one task
        self.words
            .par_chunks_mut(gw * nw)
            .enumerate()
            .for_each(|(q, row)| {
                for k in 0..nk {
                    let Some([_, _, cj0, cj1]) = bbox[k] else {
                        continue;
                    };
                    let cj = q as i32 - off[1][k];
                    if cj < cj0 as i32 || cj > cj1 as i32 {
                        continue;
                    }
                    let cj = cj as usize;
                    debug_assert!(cj < cj_n);
                    let bit = bit_of::<W>(k);
                    let w = k / W::BITS as usize;
                    let start = (k * cj_n + cj) * ci_n;
                    for ci in base[start..start + ci_n].iter_ones() {
                        let p = (ci as i32 + off[0][k]) as usize;
                        row[p * nw + w] |= bit;
                    }
                }
            });
    }

    /// One incremental step: every slice moves at most one column along i and one
    /// row along j towards `target`. Returns the number of words touched.
    fn step_towards(&mut self, target: &[Vec<i32>; 2]) -> u64 {
        let before = self.occupied_rect();
        // next offsets: one step towards the target per slice
        let mut next = std::mem::take(&mut self.off);
        let prev = next.clone();
        for a in 0..2 {
            for (o, &t) in next[a].iter_mut().zip(&target[a]) {
                *o += (t - *o).signum();
            }
        }
        let after = self.occupied(&next);
        let Some(r) = Rect::union(before, after) else {
            self.off = next;
            return 0;
        };
        let mut touched = 0;
        // along i (columns p)
        if shift_vectors(&prev[0], &next[0], &mut self.up, &mut self.down) > 0 {
            self.set_keep();
            touched += self.shift_columns(r);
        }
        // along j (rows q)
        if shift_vectors(&prev[1], &next[1], &mut self.up, &mut self.down) > 0 {
            self.set_keep();
            touched += self.shift_rows(r);
        }
        self.off = next;
        touched
    }

    fn set_keep(&mut self) {
        for ((k, u), d) in self.keep.iter_mut().zip(&self.up).zip(&self.down) {
            *k = !(*u | *d);
        }
    }

    /// `new[p] = old[p] & keep | old[p−1] & up | old[p+1] & down` over the rect.
    fn shift_columns(&mut self, r: Rect) -> u64 {
        let nw = self.nw;
        let gw = self.grid[0];
        let (up, down, keep) = (&self.up, &self.down, &self.keep);
        let (ps, pe) = (r.p0, r.p1.min(gw - 1));
        self.words
            .par_chunks_mut(gw * nw)
            .skip(r.q0)
            .take(r.q1 - r.q0 + 1)
            .for_each(|row| {
                for w in 0..nw {
                    let (u, d, kp) = (up[w], down[w], keep[w]);
                    // the column before the rect is empty (outside the occupied region)
                    let mut prev = if ps > 0 {
                        row[(ps - 1) * nw + w]
                    } else {
                        W::ZERO
                    };
                    for p in ps..=pe {
                        let cur = row[p * nw + w];
                        let next = if p + 1 < gw {
                            row[(p + 1) * nw + w]
                        } else {
                            W::ZERO
                        };
                        row[p * nw + w] = (cur & kp) | (prev & u) | (next & d);
                        prev = cur;
                    }
                }
            });
        ((r.q1 - r.q0 + 1) * (pe - ps + 1) * nw) as u64
    }

    /// `new[q] = old[q] & keep | old[q−1] & up | old[q+1] & down` over the rect.
    fn shift_rows(&mut self, r: Rect) -> u64 {
        let nw = self.nw;
        let gw = self.grid[0];
        let gh = self.grid[1];
        let (ps, pe) = (r.p0 * nw, (r.p1 + 1).min(gw) * nw);
        let prev = &mut self.row_buf[..pe - ps];
        prev.fill(W::ZERO);
        if r.q0 > 0 {
            let s = (r.q0 - 1) * gw * nw;
            prev.copy_from_slice(&self.words[s + ps..s + pe]);
        }
        for q in r.q0..=r.q1 {
            let (head, tail) = self.words.split_at_mut((q + 1) * gw * nw);
            let row = &mut head[q * gw * nw + ps..q * gw * nw + pe];
            let next: &[W] = if q + 1 < gh { &tail[ps..pe] } else { &[] };
            for (idx, cell) in row.iter_mut().enumerate() {
                let w = idx % nw;
                let cur = *cell;
                let nx = next.get(idx).copied().unwrap_or(W::ZERO);
                *cell = (cur & self.keep[w]) | (prev[idx] & self.up[w]) | (nx & self.down[w]);
                prev[idx] = cur;
            }
        }
        ((r.q1 - r.q0 + 1) * (pe - ps)) as u64
    }

    /// One paper-style rotation step of `state` (see [`ShearState::rotated`]),
    /// applied to the mask incrementally; returns the new state.
    pub fn rotate_step(&mut self, state: &ShearState, along: usize, dir: i32) -> ShearState {
        let next = state.rotated(along, dir);
        self.shear_to(&next);
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::volume::Volume;

    fn blob(n: [usize; 3], seed: u64) -> Volume {
        Volume::from_fn(n, [1.0; 3], |x, y, z| {
            let mut s =
                seed ^ (x as u64 * 0x9E37_79B9 + y as u64 * 0x85EB_CA6B + z as u64 * 0xC2B2_AE35);
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s = s.wrapping_mul(0x2545F4914F6CDD1D);
            if (s >> 40) % 7 == 0 { 100.0 } else { 0.0 }
        })
        .unwrap()
    }

    /// The mask recomputed from scratch: bit (p, q, k) set iff base cell at
    /// (p − off_i, q − off_j) is set.
    fn naive<W: Word>(m: &BinaryMask<W>) -> Vec<W> {
        let mut out = vec![W::ZERO; m.words.len()];
        let fl = m.floors();
        for k in 0..m.nk {
            for cj in 0..m.cells[1] {
                for ci in 0..m.cells[0] {
                    if m.cell(ci, cj, k) {
                        let p = (ci as i32 + m.pad as i32 - fl[0][k]) as usize;
                        let q = (cj as i32 + m.pad as i32 - fl[1][k]) as usize;
                        out[(q * m.grid[0] + p) * m.nw + k / W::BITS as usize] |= bit_of::<W>(k);
                    }
                }
            }
        }
        out
    }

    fn check_incremental<W: Word>(n: [usize; 3]) {
        let v = blob(n, 99);
        let st = SliceStack::new(&v, 2);
        let mut m = BinaryMask::<W>::build(&st, |_, hi| hi > 50.0);
        assert_eq!(m.words, naive(&m));
        let mut s = ShearState::identity(n[2]);
        let mut seed = 3u64;
        let lim = (n[2] as i64 - 1) / 2;
        let mut net = [0i64; 2];
        for step in 0..400 {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let along = (seed >> 35) as usize & 1;
            let dir = if (seed >> 45) & 1 == 0 { 1 } else { -1 };
            if (net[along] + dir as i64).abs() > lim {
                continue;
            }
            net[along] += dir as i64;
            s = m.rotate_step(&s, along, dir);
            if step % 37 == 0 {
                assert_eq!(m.words, naive(&m), "after step {step}");
            }
        }
        let mut direct = BinaryMask::<W>::build(&st, |_, hi| hi > 50.0);
        direct.shear_direct(&s);
        assert_eq!(m.words, direct.words);
        assert_eq!(m.words, naive(&m));
    }

    #[test]
    fn incremental_equals_direct_u32_and_u64() {
        check_incremental::<u32>([13, 11, 45]);
        check_incremental::<u64>([13, 11, 45]);
        check_incremental::<u32>([9, 7, 70]);
        check_incremental::<u64>([9, 7, 130]);
        check_incremental::<u32>([5, 6, 2]);
    }

    #[test]
    fn build_is_exactly_the_corner_rule() {
        let v = blob([9, 8, 7], 5);
        let st = SliceStack::new(&v, 2);
        let m = BinaryMask::<u32>::build(&st, |_, hi| hi > 50.0);
        for k in 0..7 {
            for cj in 0..7 {
                for ci in 0..8 {
                    let any = [(0, 0), (1, 0), (0, 1), (1, 1)]
                        .iter()
                        .any(|&(a, b)| st.at(ci + a, cj + b, k) > 50.0);
                    assert_eq!(m.cell(ci, cj, k), any);
                }
            }
        }
    }
}
