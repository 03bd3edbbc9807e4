//! Cell codes: what the binary mask is packed from.
//!
//! Owns [`CellCodes`]: one small code per cell `(ci, cj)` of every slice `k` of
//! one principal axis, computed from the range of its four in-slice corner
//! densities — 1 bit "may be visible" for a single transfer function, or the
//! interval index of the highest corner among `n` tissue thresholds (the
//! paper's adaptive threshold codes). They depend only on the classification:
//! a new cell size or word size re-packs the mask from the same codes.

use std::sync::Arc;

use rayon::prelude::*;

use crate::data::slices::Densities;
use crate::encode::depth::code_width_for;
use crate::error::{Error, Result};
use crate::kernels::reconstruct;

/// `nb`-bit codes (`nb` ∈ 1, 2, 4) of `rows` rows of `len` cells, each row
/// padded to whole u64 words: cell `i` of row `r` sits in the bits
/// `[(i % per)·nb, (i % per + 1)·nb)` of word `r·row_words + i / per`, with
/// `per = 64 / nb`. An eighth (1-bit codes) to a half (4-bit) of a byte per
/// cell, and a row's non-zero cells are found a word at a time.
#[derive(Clone, Debug, PartialEq)]
pub struct PackedCodes {
    nb: u32,
    len: usize,
    row_words: usize,
    words: Vec<u64>,
}

impl PackedCodes {
    /// All-zero codes.
    pub fn new(nb: u32, len: usize, rows: usize) -> Self {
        assert!(matches!(nb, 1 | 2 | 4), "code width {nb}");
        let row_words = Self::row_words(nb, len);
        PackedCodes { nb, len, row_words, words: vec![0; row_words * rows] }
    }
    /// Words of one row of `len` codes of `nb` bits.
    fn row_words(nb: u32, len: usize) -> usize {
        (len * nb as usize).div_ceil(64)
    }
    /// The bytes [`PackedCodes::new`] allocates.
    pub fn bytes_for(nb: u32, len: usize, rows: usize) -> u64 {
        (Self::row_words(nb, len) * rows * 8) as u64
    }
    /// Cells per row.
    pub fn len(&self) -> usize {
        self.len
    }
    /// True when rows hold no cells.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.words.len() * 8
    }
    /// Codes per word.
    fn per(&self) -> usize {
        64 / self.nb as usize
    }
    /// The code of cell `i` of row `r`.
    #[inline]
    pub fn get(&self, r: usize, i: usize) -> u8 {
        let per = self.per();
        let w = self.words[r * self.row_words + i / per];
        ((w >> ((i % per) as u32 * self.nb)) & ((1u64 << self.nb) - 1)) as u8
    }
    /// The words of every `rows_per_chunk` rows, mutably, for filling in parallel.
    fn chunks_mut(&mut self, rows_per_chunk: usize) -> impl IndexedParallelIterator<Item = &mut [u64]> {
        let n = (self.row_words * rows_per_chunk).max(1);
        self.words.par_chunks_mut(n)
    }
    /// Packs `codes` (one row, each `< 2^nb`) into `out` (that row's words).
    fn pack_row(nb: u32, codes: &[u8], out: &mut [u64]) {
        let per = 64 / nb as usize;
        for (w, c) in out.iter_mut().zip(codes.chunks(per)) {
            *w = c.iter().enumerate().fold(0u64, |acc, (t, &x)| acc | (x as u64) << (t as u32 * nb));
        }
    }
    /// Unpacks row `r` into the first `len` bytes of `out` (one code a
    /// byte), a word at a time; an all-zero word is one fill.
    pub fn unpack_row(&self, r: usize, out: &mut [u8]) {
        let row = &self.words[r * self.row_words..(r + 1) * self.row_words];
        let n = self.len.min(out.len());
        match self.nb {
            1 => unpack_words::<1>(row, &mut out[..n]),
            2 => unpack_words::<2>(row, &mut out[..n]),
            _ => unpack_words::<4>(row, &mut out[..n]),
        }
    }
    /// Calls `f(i, code)` for every non-zero cell `i` in `[from, to]` of row `r`,
    /// in order, a word at a time (all-zero words cost one test).
    #[inline]
    #[allow(clippy::needless_range_loop)] // words are indexed by their position in the row
    pub fn for_each_nonzero(&self, r: usize, from: usize, to: usize, mut f: impl FnMut(usize, u8)) {
        if from > to || self.len == 0 {
            return;
        }
        let (nb, per) = (self.nb, self.per());
        let to = to.min(self.len - 1);
        let row = &self.words[r * self.row_words..(r + 1) * self.row_words];
        let low: u64 = match nb {
            1 => !0,
            2 => 0x5555_5555_5555_5555,
            _ => 0x1111_1111_1111_1111,
        };
        for wi in from / per..=to / per {
            let w = row[wi];
            if w == 0 {
                continue;
            }
            // one bit per non-zero code, at the code's lowest bit
            let mut any = w;
            if nb >= 2 {
                any |= any >> 1;
            }
            if nb >= 4 {
                any |= any >> 2;
            }
            let mut m = any & low;
            while m != 0 {
                let b = m.trailing_zeros();
                m &= m - 1;
                let i = wi * per + (b / nb) as usize;
                if i >= from && i <= to {
                    f(i, ((w >> b) & ((1u64 << nb) - 1)) as u8);
                }
            }
        }
    }
    /// One-bit codes of the same rows: 1 where this code is at least `c`
    /// (1..2^nb; a tissue preset's cells in a mask of threshold codes), a
    /// word at a time (every field compared at once, the flags gathered
    /// into `64 / nb` bits), in parallel over rows.
    pub fn at_least(&self, c: u8) -> PackedCodes {
        assert!(c >= 1 && (c as u32) < (1 << self.nb), "code {c} of {} bits", self.nb);
        let rows = self.words.len().checked_div(self.row_words).unwrap_or(0);
        let mut out = PackedCodes::new(1, self.len, rows);
        if self.nb == 1 || out.row_words == 0 {
            if self.nb == 1 {
                out.words.clone_from(&self.words);
            }
            return out;
        }
        let (nb, rw, orw) = (self.nb, self.row_words, out.row_words);
        let per = self.per() as u32;
        // (`nb` code words to a one-bit word; slot 0 in the least significant bits)
        out.words.par_chunks_mut(orw).zip(self.words.par_chunks(rw)).for_each(|(o, row)| {
            for (ow, ws) in o.iter_mut().zip(row.chunks(nb as usize)) {
                *ow = group_flags(ws.iter().copied(), nb, c, per, false);
            }
        });
        out
    }

    /// The first and last non-zero cell of row `r`, if any.
    pub fn nonzero_span(&self, r: usize) -> Option<(usize, usize)> {
        let (nb, per) = (self.nb, self.per());
        let row = &self.words[r * self.row_words..(r + 1) * self.row_words];
        let first = row.iter().position(|&w| w != 0)?;
        let last = row.iter().rposition(|&w| w != 0)?;
        let a = first * per + (row[first].trailing_zeros() / nb) as usize;
        let b = last * per + ((63 - row[last].leading_zeros()) / nb) as usize;
        Some((a, b))
    }
}

/// Super cells of size `s` along i and j for `cells` cells: super cell `SI`
/// covers cells `[s·SI − (s − 1), s·SI + (s − 1)]`; those that cover any cell.
pub fn super_cells(cells: [usize; 2], s: usize) -> [usize; 2] {
    cells.map(|c| if c == 0 { 0 } else { (c + s - 2) / s + 1 })
}

/// Unsheared per-cell codes of one principal axis.
#[derive(Clone, Debug)]
pub struct CellCodes {
    /// Cells along i and j.
    pub cells: [usize; 2],
    /// Slices.
    pub nk: usize,
    /// Bits per code.
    pub nb: u32,
    /// Code of cell `(ci, cj, k)`: cell `ci` of row `k · cells_j + cj`;
    /// shared with the masks packed from it at cell size 1 (no copy).
    pub codes: Arc<PackedCodes>,
}

impl CellCodes {
    /// Codes from `code(lo, hi)` of each cell's corner range (must be `< 2^nb`).
    pub fn build(stack: &(impl Densities + ?Sized), nb: u32, code: impl Fn(f32, f32) -> u8 + Sync) -> Self {
        let n = stack.dims();
        let [ci_n, cj_n] = [n[0].saturating_sub(1), n[1].saturating_sub(1)];
        let nk = n[2];
        let per = ci_n * cj_n;
        let mut codes = PackedCodes::new(nb, ci_n, cj_n * nk);
        if per > 0 {
            let rw = codes.row_words;
            codes.chunks_mut(cj_n).enumerate().for_each(|(k, out)| {
                let mut line = vec![0u8; ci_n];
                // a row's column minima/maxima are shared by neighbouring cells
                let mut colmin = vec![0f32; ci_n + 1];
                let mut colmax = vec![0f32; ci_n + 1];
                let n0 = ci_n + 1;
                let (mut r0, mut r1) = (vec![0f32; n0], vec![0f32; n0]);
                for cj in 0..cj_n {
                    if cj == 0 {
                        stack.row(0, k, &mut r0);
                    } else {
                        std::mem::swap(&mut r0, &mut r1);
                    }
                    stack.row(cj + 1, k, &mut r1);
                    for (((mn, mx), &a), &b) in colmin.iter_mut().zip(colmax.iter_mut()).zip(&r0).zip(&r1) {
                        *mn = a.min(b);
                        *mx = a.max(b);
                    }
                    for (ci, o) in line.iter_mut().enumerate() {
                        let lo = colmin[ci].min(colmin[ci + 1]);
                        let hi = colmax[ci].max(colmax[ci + 1]);
                        *o = code(lo, hi);
                    }
                    PackedCodes::pack_row(nb, &line, &mut out[cj * rw..(cj + 1) * rw]);
                }
            });
        }
        CellCodes { cells: [ci_n, cj_n], nk, nb, codes: Arc::new(codes) }
    }

    /// Codes for Shear-Warp Deluxe I ([`crate::composite::raycast::RayContext::with_intermediate`]):
    /// `code(lo, hi)` of the range of voxels `[ci − 1, ci + 2] × [cj − 1, cj + 2]
    /// × [k, k + 1]` (clipped to the volume) instead of the cell's four corners.
    /// A ray whose sample in slice `k` lies in cell `(ci, cj)` reads, at its
    /// midpoint between slices `k` and `k + 1`, a cell within one of it along
    /// each axis (it moves at most two voxels a slice, so at most one in half
    /// a slice) in both slices, and the trilinear sample there lies within
    /// the range of those eight voxels: so bit `k` of a mask packed from these
    /// codes covers the sample of slice `k` and the midpoint after it, for
    /// either walking order, and the mask stays conservative (one slice of
    /// dilation along depth, one cell in the slice).
    pub fn build_half(stack: &(impl Densities + ?Sized), nb: u32, code: impl Fn(f32, f32) -> u8 + Sync) -> Self {
        let n = stack.dims();
        let [ci_n, cj_n] = [n[0].saturating_sub(1), n[1].saturating_sub(1)];
        let nk = n[2];
        let mut codes = PackedCodes::new(nb, ci_n, cj_n * nk);
        if ci_n * cj_n > 0 {
            let rw = codes.row_words;
            let (n0, n1) = (n[0], n[1]);
            codes.chunks_mut(cj_n).enumerate().for_each(|(k, out)| {
                let k1 = (k + 1).min(nk - 1);
                let (mut a, mut b) = (vec![0f32; n0], vec![0f32; n0]);
                // per voxel row j, the range over both slices and voxels [ci − 1, ci + 2]
                let (mut rlo, mut rhi) = (vec![0f32; n1 * ci_n], vec![0f32; n1 * ci_n]);
                for j in 0..n1 {
                    stack.row(j, k, &mut a);
                    stack.row(j, k1, &mut b);
                    // a: the two slices' minima, b: their maxima
                    for (x, y) in a.iter_mut().zip(b.iter_mut()) {
                        (*x, *y) = (x.min(*y), x.max(*y));
                    }
                    let mx = &b;
                    for ci in 0..ci_n {
                        let (i0, i1) = (ci.saturating_sub(1), (ci + 2).min(n0 - 1));
                        rlo[j * ci_n + ci] = a[i0..=i1].iter().fold(f32::INFINITY, |m, &x| m.min(x));
                        rhi[j * ci_n + ci] = mx[i0..=i1].iter().fold(f32::NEG_INFINITY, |m, &x| m.max(x));
                    }
                }
                let mut line = vec![0u8; ci_n];
                for cj in 0..cj_n {
                    let (j0, j1) = (cj.saturating_sub(1), (cj + 2).min(n1 - 1));
                    for (ci, o) in line.iter_mut().enumerate() {
                        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
                        for j in j0..=j1 {
                            lo = lo.min(rlo[j * ci_n + ci]);
                            hi = hi.max(rhi[j * ci_n + ci]);
                        }
                        *o = code(lo, hi);
                    }
                    PackedCodes::pack_row(nb, &line, &mut out[cj * rw..(cj + 1) * rw]);
                }
            });
        }
        CellCodes { cells: [ci_n, cj_n], nk, nb, codes: Arc::new(codes) }
    }

    /// Codes for the cubic reconstruction
    /// ([`crate::kernels::reconstruct::Reconstruction::Cubic`], Catmull–Rom
    /// along the stack axis `z_axis`, the volume's z): `code(lo, hi)` of the
    /// range the cubic can reach in what a ray through cell `(ci, cj)` of
    /// slice `k` reads, bounded by [`reconstruct::upper_bound`] (and
    /// [`reconstruct::lower_bound`]) from the maximum of the *inner* voxels
    /// and the minimum of the *outer* ones, so a mask packed from these codes
    /// stays conservative for the cubic:
    ///
    /// - `z_axis` 2 (the slices): a ray visiting slice `k` tests the segment
    ///   to the slice before it, whose cubic reads the ray's samples in
    ///   slices `k − 2 … k + 1` (or `k − 1 … k + 2` walking the other way). A
    ///   ray moves at most one voxel a slice, so its inner samples (slices
    ///   `k − 1 … k + 1`) lie in cells within one of `(ci, cj)`, voxels
    ///   `[ci − 1, ci + 2]`, and its outer ones (slices `k ± 2`) within two,
    ///   voxels `[ci − 2, ci + 3]` (the same along j).
    /// - `z_axis` 0 or 1 (in the slice): the sample reads the cell's two
    ///   voxel rows along z (inner) and the row before and after them (outer).
    ///
    /// Indices are clipped to the volume (a clamped sample repeats a voxel
    /// already in the range).
    pub fn build_cubic(stack: &(impl Densities + ?Sized), nb: u32, z_axis: usize, code: impl Fn(f32, f32) -> u8 + Sync) -> Self {
        let n = stack.dims();
        let [ci_n, cj_n] = [n[0].saturating_sub(1), n[1].saturating_sub(1)];
        let nk = n[2];
        let mut codes = PackedCodes::new(nb, ci_n, cj_n * nk);
        // voxel windows around a cell (along i, j) and a slice (along k): inner, outer
        let (inner, outer): ([usize; 3], [usize; 3]) = match z_axis {
            0 => ([0, 0, 0], [1, 0, 0]),
            1 => ([0, 0, 0], [0, 1, 0]),
            _ => ([1, 1, 1], [2, 2, 2]),
        };
        if ci_n * cj_n > 0 {
            let rw = codes.row_words;
            let (n0, n1) = (n[0], n[1]);
            codes.chunks_mut(cj_n).enumerate().for_each(|(k, out)| {
                // per voxel: the max over the inner slices, the min over the outer ones
                let (mut pmax, mut pmin) = (vec![f32::NEG_INFINITY; n0 * n1], vec![f32::INFINITY; n0 * n1]);
                let mut row = vec![0f32; n0];
                let (k0, k1) = (k.saturating_sub(outer[2]), (k + outer[2]).min(nk - 1));
                for kk in k0..=k1 {
                    let is_inner = kk + inner[2] >= k && kk <= k + inner[2];
                    for j in 0..n1 {
                        stack.row(j, kk, &mut row);
                        let (mx, mn) = (&mut pmax[j * n0..(j + 1) * n0], &mut pmin[j * n0..(j + 1) * n0]);
                        for ((x, m), &v) in mx.iter_mut().zip(mn.iter_mut()).zip(&row) {
                            if is_inner {
                                *x = x.max(v);
                            }
                            *m = m.min(v);
                        }
                    }
                }
                // windows along i per voxel row, then along j per cell
                let win = |c: usize, r: usize, len: usize| (c.saturating_sub(r), (c + 1 + r).min(len - 1));
                let (mut rmax, mut rmin) = (vec![0f32; n1 * ci_n], vec![0f32; n1 * ci_n]);
                for j in 0..n1 {
                    for ci in 0..ci_n {
                        let (a0, a1) = win(ci, inner[0], n0);
                        let (b0, b1) = win(ci, outer[0], n0);
                        rmax[j * ci_n + ci] = pmax[j * n0 + a0..=j * n0 + a1].iter().fold(f32::NEG_INFINITY, |m, &x| m.max(x));
                        rmin[j * ci_n + ci] = pmin[j * n0 + b0..=j * n0 + b1].iter().fold(f32::INFINITY, |m, &x| m.min(x));
                    }
                }
                let mut line = vec![0u8; ci_n];
                for cj in 0..cj_n {
                    let (a0, a1) = win(cj, inner[1], n1);
                    let (b0, b1) = win(cj, outer[1], n1);
                    for (ci, o) in line.iter_mut().enumerate() {
                        let hi = (a0..=a1).map(|j| rmax[j * ci_n + ci]).fold(f32::NEG_INFINITY, f32::max);
                        let lo = (b0..=b1).map(|j| rmin[j * ci_n + ci]).fold(f32::INFINITY, f32::min);
                        let up = reconstruct::upper_bound(hi as f64, lo as f64);
                        let down = reconstruct::lower_bound(lo as f64, hi as f64).min(lo as f64);
                        // rounded outward to f32
                        *o = code(next_down(down as f32, down), next_up(up as f32, up));
                    }
                    PackedCodes::pack_row(nb, &line, &mut out[cj * rw..(cj + 1) * rw]);
                }
            });
        }
        CellCodes { cells: [ci_n, cj_n], nk, nb, codes: Arc::new(codes) }
    }

    /// [`CellCodes::binary`] for the cubic reconstruction ([`CellCodes::build_cubic`]).
    pub fn binary_cubic(stack: &(impl Densities + ?Sized), z_axis: usize, visible: impl Fn(f32, f32) -> bool + Sync) -> Self {
        Self::build_cubic(stack, 1, z_axis, |lo, hi| visible(lo, hi) as u8)
    }

    /// [`CellCodes::thresholds`] for the cubic reconstruction ([`CellCodes::build_cubic`]).
    pub fn thresholds_cubic(stack: &(impl Densities + ?Sized), z_axis: usize, thresholds: &[f32]) -> Result<Self> {
        let nb = check_thresholds(thresholds)?;
        Ok(Self::build_cubic(stack, nb, z_axis, |_, hi| thresholds.iter().map(|&t| (t <= hi) as u8).sum()))
    }

    /// [`CellCodes::binary`] for Deluxe I ([`CellCodes::build_half`]).
    pub fn binary_half(stack: &(impl Densities + ?Sized), visible: impl Fn(f32, f32) -> bool + Sync) -> Self {
        Self::build_half(stack, 1, |lo, hi| visible(lo, hi) as u8)
    }

    /// [`CellCodes::thresholds`] for Deluxe I ([`CellCodes::build_half`]).
    pub fn thresholds_half(stack: &(impl Densities + ?Sized), thresholds: &[f32]) -> Result<Self> {
        if thresholds.is_empty() || !thresholds.windows(2).all(|w| w[0] < w[1]) || thresholds.iter().any(|t| t.is_nan()) {
            return Err(Error::value("thresholds", format!("{thresholds:?} (need 1..=15 strictly ascending values)")));
        }
        let nb = code_width_for(thresholds.len())
            .ok_or_else(|| Error::value("thresholds", format!("{} thresholds (at most 15)", thresholds.len())))?;
        Ok(Self::build_half(stack, nb, |_, hi| thresholds.iter().map(|&t| (t <= hi) as u8).sum()))
    }

    /// 1-bit codes: 1 where `visible(lo, hi)`.
    pub fn binary(stack: &(impl Densities + ?Sized), visible: impl Fn(f32, f32) -> bool + Sync) -> Self {
        Self::build(stack, 1, |lo, hi| visible(lo, hi) as u8)
    }

    /// Adaptive threshold codes: the index of the interval of the highest corner
    /// among the ascending `thresholds` (0 below the first, `n` at or above the
    /// last), in the smallest code width that holds `n + 1` intervals.
    pub fn thresholds(stack: &(impl Densities + ?Sized), thresholds: &[f32]) -> Result<Self> {
        if thresholds.is_empty() || !thresholds.windows(2).all(|w| w[0] < w[1]) || thresholds.iter().any(|t| t.is_nan()) {
            return Err(Error::value("thresholds", format!("{thresholds:?} (need 1..=15 strictly ascending values)")));
        }
        let nb = code_width_for(thresholds.len())
            .ok_or_else(|| Error::value("thresholds", format!("{} thresholds (at most 15)", thresholds.len())))?;
        // the count of thresholds at or below `hi` (= `partition_point(|t| t <= hi)`
        // of the ascending list), without a branch per threshold
        Ok(Self::build(stack, nb, |_, hi| thresholds.iter().map(|&t| (t <= hi) as u8).sum()))
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.codes.bytes()
    }

    /// The code of cell `(ci, cj, k)`.
    #[inline]
    pub fn code(&self, ci: usize, cj: usize, k: usize) -> u8 {
        self.codes.get(k * self.cells[1] + cj, ci)
    }

    /// Super-cell codes for cell size `s` (dilated: see the module docs), with
    /// each slice's bounding box of non-zero super cells.
    pub(crate) fn supercells(&self, s: usize) -> ([usize; 2], Arc<PackedCodes>, Vec<Option<[usize; 4]>>) {
        let [ci_n, cj_n] = self.cells;
        let span = |si: usize, c: usize| ((s * si).saturating_sub(s - 1), (s * si + s).min(c));
        let sc = super_cells(self.cells, s);
        let per = sc[0] * sc[1];
        let mut bbox: Vec<Option<[usize; 4]>> = vec![None; self.nk];
        if s == 1 {
            // no dilation: the codes themselves, plus each slice's bounding box
            return (sc, self.codes.clone(), slice_boxes(&self.codes, self.cells, self.nk));
        }
        let mut out = PackedCodes::new(self.nb, sc[0], sc[1] * self.nk);
        if per == 0 {
            return (sc, Arc::new(out), bbox);
        }
        let (nb, rw) = (self.nb, out.row_words);
        out.chunks_mut(sc[1]).zip(bbox.par_iter_mut()).enumerate().for_each(|(k, (o, bb))| {
            // max over the span along i, then along j
            let mut line = vec![0u8; ci_n];
            let mut rows = vec![0u8; sc[0] * cj_n];
            for cj in 0..cj_n {
                self.codes.unpack_row(k * cj_n + cj, &mut line);
                for si in 0..sc[0] {
                    let (a, b) = span(si, ci_n);
                    rows[cj * sc[0] + si] = line[a..b].iter().copied().max().unwrap_or(0);
                }
            }
            let mut sline = vec![0u8; sc[0]];
            for sj in 0..sc[1] {
                let (a, b) = span(sj, cj_n);
                for (si, m) in sline.iter_mut().enumerate() {
                    *m = (a..b).map(|cj| rows[cj * sc[0] + si]).max().unwrap_or(0);
                    if *m != 0 {
                        *bb = Some(match *bb {
                            None => [si, si, sj, sj],
                            Some([p, q, r, t]) => [p.min(si), q.max(si), r.min(sj), t.max(sj)],
                        });
                    }
                }
                PackedCodes::pack_row(nb, &sline, &mut o[sj * rw..(sj + 1) * rw]);
            }
        });
        (sc, Arc::new(out), bbox)
    }
}

/// Per slice `k` of `codes` (rows `k·cells[1] …`, `cells[0]` long), the
/// bounding box `[i0, i1, j0, j1]` of its non-zero codes, if any.
pub(crate) fn slice_boxes(codes: &PackedCodes, cells: [usize; 2], nk: usize) -> Vec<Option<[usize; 4]>> {
    let mut bbox: Vec<Option<[usize; 4]>> = vec![None; nk];
    let cj_n = cells[1];
    if cells[0] * cj_n == 0 {
        return bbox;
    }
    bbox.par_iter_mut().enumerate().for_each(|(k, bb)| {
        for cj in 0..cj_n {
            let Some((a, b)) = codes.nonzero_span(k * cj_n + cj) else { continue };
            *bb = Some(match *bb {
                None => [a, b, cj, cj],
                Some([p, q, r, _]) => [p.min(a), q.max(b), r, cj],
            });
        }
    });
    bbox
}

/// The `NB`-bit codes of `words` into `out`, one a byte (slot `t` of a word
/// is bits `[t·NB, (t + 1)·NB)`, as in [`PackedCodes`]).
#[inline]
fn unpack_words<const NB: u32>(words: &[u64], out: &mut [u8]) {
    let per = 64 / NB as usize;
    for (o, &w) in out.chunks_mut(per).zip(words) {
        if w == 0 {
            o.fill(0);
            continue;
        }
        for (t, x) in o.iter_mut().enumerate() {
            *x = ((w >> (t as u32 * NB)) & ((1 << NB) - 1)) as u8;
        }
    }
}

/// The one-bit word of a group of (at most) `nb` words of `nb`-bit codes,
/// `per` codes each (`u64` or `u32` words, 2- or 4-bit codes): each code at
/// least `c` as one bit, every word's flags ([`field_flags`]) in `per` bits
/// of the result, the group's first word in the lowest bits, or with
/// `msb_first` (the mask's slot order) in the highest.
#[inline]
pub(crate) fn group_flags(ws: impl Iterator<Item = u64>, nb: u32, c: u8, per: u32, msb_first: bool) -> u64 {
    ws.enumerate().fold(0u64, |acc, (g, w)| {
        let at = if msb_first { nb - 1 - g as u32 } else { g as u32 };
        acc | field_flags(w, nb, c) << (at * per)
    })
}

/// Of the `64 / nb` `nb`-bit codes of `w` (`nb` 2 or 4), those at least `c`
/// (`1 ≤ c < 2^nb`) as one bit each, code `t` at bit `t`.
#[inline]
fn field_flags(w: u64, nb: u32, c: u8) -> u64 {
    debug_assert!(matches!(nb, 2 | 4) && c >= 1 && (c as u32) < (1 << nb));
    const ONES: u64 = 0x0101_0101_0101_0101;
    if nb == 2 {
        // per 2-bit field v = (h, l): v ≥ 1 is h | l, v ≥ 2 is h, v ≥ 3 is h & l
        let (l, h) = (w & 0x5555_5555_5555_5555, (w >> 1) & 0x5555_5555_5555_5555);
        let f = match c {
            1 => h | l,
            2 => h,
            _ => h & l,
        };
        return compress_every(f, 2);
    }
    // 4-bit fields: the even and the odd ones in byte lanes, where
    // v + 0x80 − c reaches bit 7 exactly when v ≥ c (v ≤ 15, no carry out)
    let bias = ONES * (0x80 - c as u64);
    let lo = (((w & 0x0F0F_0F0F_0F0F_0F0F) + bias) >> 7) & ONES;
    let hi = ((((w >> 4) & 0x0F0F_0F0F_0F0F_0F0F) + bias) >> 7) & ONES;
    // field 2m's flag at bit 8m, field 2m + 1's at bit 8m + 4: each at its field's lowest bit
    compress_every(lo | hi << 4, 4)
}

/// The bits of `x` at multiples of `nb` (2 or 4; the others zero) gathered
/// into the low `64 / nb` bits.
#[inline]
fn compress_every(x: u64, nb: u32) -> u64 {
    if nb == 2 {
        let mut x = x & 0x5555_5555_5555_5555;
        x = (x | x >> 1) & 0x3333_3333_3333_3333;
        x = (x | x >> 2) & 0x0F0F_0F0F_0F0F_0F0F;
        x = (x | x >> 4) & 0x00FF_00FF_00FF_00FF;
        x = (x | x >> 8) & 0x0000_FFFF_0000_FFFF;
        (x | x >> 16) & 0x0000_0000_FFFF_FFFF
    } else {
        let mut x = x & 0x1111_1111_1111_1111;
        x = (x | x >> 3) & 0x0303_0303_0303_0303;
        x = (x | x >> 6) & 0x000F_000F_000F_000F;
        x = (x | x >> 12) & 0x0000_00FF_0000_00FF;
        (x | x >> 24) & 0x0000_0000_0000_FFFF
    }
}

/// The validated code width of ascending `thresholds`.
fn check_thresholds(thresholds: &[f32]) -> Result<u32> {
    if thresholds.is_empty() || !thresholds.windows(2).all(|w| w[0] < w[1]) || thresholds.iter().any(|t| t.is_nan()) {
        return Err(Error::value("thresholds", format!("{thresholds:?} (need 1..=15 strictly ascending values)")));
    }
    code_width_for(thresholds.len()).ok_or_else(|| Error::value("thresholds", format!("{} thresholds (at most 15)", thresholds.len())))
}

/// `x` (`v` rounded to f32), or the next f32 above it when it rounded down.
fn next_up(x: f32, v: f64) -> f32 {
    if (x as f64) < v { x.next_up() } else { x }
}

/// `x` (`v` rounded to f32), or the next f32 below it when it rounded up.
fn next_down(x: f32, v: f64) -> f32 {
    if (x as f64) > v { x.next_down() } else { x }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The one-bit codes "code ≥ c" of packed codes equal the comparison
    /// cell by cell, for every width, code and row length.
    #[test]
    fn at_least_equals_the_comparison_of_each_code() {
        let mut rnd = crate::testing::xorshift(0x13198A2E03707344);
        for nb in [1u32, 2, 4] {
            for len in [1usize, 15, 16, 17, 31, 32, 33, 64, 65, 130, 200] {
                let rows = 4;
                let plain: Vec<Vec<u8>> = (0..rows).map(|_| (0..len).map(|_| (rnd() % (1 << nb)) as u8).collect()).collect();
                let mut p = PackedCodes::new(nb, len, rows);
                p.chunks_mut(1).enumerate().for_each(|(r, o)| PackedCodes::pack_row(nb, &plain[r], o));
                for c in 1..(1u8 << nb) {
                    let one = p.at_least(c);
                    assert_eq!((one.nb, one.len, one.row_words), (1, len, len.div_ceil(64)));
                    for (r, row) in plain.iter().enumerate() {
                        for (i, &v) in row.iter().enumerate() {
                            assert_eq!(one.get(r, i), (v >= c) as u8, "{nb}-bit code {v} at ({r}, {i}) against {c}");
                        }
                    }
                }
            }
        }
    }

    /// Packing, reading and the non-zero walk agree with plain byte codes, for
    /// every width, row length (word boundaries included) and sub-range.
    #[test]
    fn packed_codes_equal_plain_codes() {
        let mut rnd = crate::testing::xorshift(0x243F6A8885A308D3);
        for nb in [1u32, 2, 4] {
            for len in [1usize, 7, 15, 16, 31, 32, 33, 63, 64, 65, 130, 200] {
                let rows = 5;
                let plain: Vec<Vec<u8>> = (0..rows)
                    .map(|r| (0..len).map(|_| if r == 2 || rnd().is_multiple_of(3) { 0 } else { (rnd() % (1 << nb)) as u8 }).collect())
                    .collect();
                let mut p = PackedCodes::new(nb, len, rows);
                let rw = p.row_words;
                p.chunks_mut(1).enumerate().for_each(|(r, o)| {
                    assert_eq!(o.len(), rw);
                    PackedCodes::pack_row(nb, &plain[r], o);
                });
                assert_eq!(p.bytes(), rows * len.div_ceil(64 / nb as usize) * 8);
                let mut line = vec![0u8; len];
                for (r, want) in plain.iter().enumerate() {
                    p.unpack_row(r, &mut line);
                    assert_eq!(&line, want);
                    assert!((0..len).all(|i| p.get(r, i) == want[i]));
                    let nz: Vec<usize> = (0..len).filter(|&i| want[i] != 0).collect();
                    assert_eq!(p.nonzero_span(r), nz.first().map(|&a| (a, *nz.last().unwrap())), "nb {nb} len {len} row {r}");
                    for _ in 0..20 {
                        let (a, b) = ((rnd() as usize) % (len + 2), (rnd() as usize) % (len + 2));
                        let mut got = vec![];
                        p.for_each_nonzero(r, a, b, |i, c| got.push((i, c)));
                        let expect: Vec<(usize, u8)> = (a..=b.min(len - 1)).filter(|&i| want[i] != 0).map(|i| (i, want[i])).collect();
                        assert_eq!(got, expect, "nb {nb} len {len} row {r} [{a}, {b}]");
                    }
                }
            }
        }
    }
}
