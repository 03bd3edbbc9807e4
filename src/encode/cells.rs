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

/// Unsheared per-cell codes of one principal axis.
#[derive(Clone, Debug)]
pub struct CellCodes {
    /// Cells along i and j.
    pub cells: [usize; 2],
    /// Slices.
    pub nk: usize,
    /// Bits per code.
    pub nb: u32,
    /// Code of cell `(ci, cj, k)` at `(k · cells_j + cj) · cells_i + ci`;
    /// shared with the masks packed from it at cell size 1 (no copy).
    pub codes: Arc<Vec<u8>>,
}

impl CellCodes {
    /// Codes from `code(lo, hi)` of each cell's corner range (must be `< 2^nb`).
    pub fn build(stack: &(impl Densities + ?Sized), nb: u32, code: impl Fn(f32, f32) -> u8 + Sync) -> Self {
        let n = stack.dims();
        let [ci_n, cj_n] = [n[0].saturating_sub(1), n[1].saturating_sub(1)];
        let nk = n[2];
        let per = ci_n * cj_n;
        let mut codes = vec![0u8; per * nk];
        if per > 0 {
            codes.par_chunks_mut(per).enumerate().for_each(|(k, out)| {
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
                    let row = &mut out[cj * ci_n..(cj + 1) * ci_n];
                    for (ci, o) in row.iter_mut().enumerate() {
                        let lo = colmin[ci].min(colmin[ci + 1]);
                        let hi = colmax[ci].max(colmax[ci + 1]);
                        *o = code(lo, hi);
                    }
                }
            });
        }
        CellCodes { cells: [ci_n, cj_n], nk, nb, codes: Arc::new(codes) }
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
        self.codes.len()
    }

    /// The code of cell `(ci, cj, k)`.
    #[inline]
    pub fn code(&self, ci: usize, cj: usize, k: usize) -> u8 {
        self.codes[(k * self.cells[1] + cj) * self.cells[0] + ci]
    }

    /// Super-cell codes for cell size `s` (dilated: see the module docs), with
    /// each slice's bounding box of non-zero super cells.
    pub(crate) fn supercells(&self, s: usize) -> ([usize; 2], Arc<Vec<u8>>, Vec<Option<[usize; 4]>>) {
        let [ci_n, cj_n] = self.cells;
        // super cell SI covers cells [s·SI − (s − 1), s·SI + (s − 1)]; count those that cover any cell
        let count = |c: usize| if c == 0 { 0 } else { (c + s - 2) / s + 1 };
        let span = |si: usize, c: usize| ((s * si).saturating_sub(s - 1), (s * si + s).min(c));
        let sc = [count(ci_n), count(cj_n)];
        let per = sc[0] * sc[1];
        let mut bbox: Vec<Option<[usize; 4]>> = vec![None; self.nk];
        if s == 1 {
            // no dilation: the codes themselves, plus each slice's bounding box
            let out = self.codes.clone();
            if per > 0 {
                out.par_chunks(per).zip(bbox.par_iter_mut()).for_each(|(o, bb)| {
                    for (cj, line) in o.chunks_exact(ci_n).enumerate() {
                        let (Some(a), Some(b)) = (line.iter().position(|&c| c != 0), line.iter().rposition(|&c| c != 0)) else { continue };
                        *bb = Some(match *bb {
                            None => [a, b, cj, cj],
                            Some([p, q, r, _]) => [p.min(a), q.max(b), r, cj],
                        });
                    }
                });
            }
            return (sc, out, bbox);
        }
        let mut out = vec![0u8; per * self.nk];
        if per == 0 {
            return (sc, Arc::new(out), bbox);
        }
        out.par_chunks_mut(per).zip(bbox.par_iter_mut()).enumerate().for_each(|(k, (o, bb))| {
            let slice = &self.codes[k * ci_n * cj_n..(k + 1) * ci_n * cj_n];
            // max over the span along i, then along j
            let mut rows = vec![0u8; sc[0] * cj_n];
            for cj in 0..cj_n {
                let r = &slice[cj * ci_n..(cj + 1) * ci_n];
                for si in 0..sc[0] {
                    let (a, b) = span(si, ci_n);
                    rows[cj * sc[0] + si] = r[a..b].iter().copied().max().unwrap_or(0);
                }
            }
            for sj in 0..sc[1] {
                let (a, b) = span(sj, cj_n);
                for si in 0..sc[0] {
                    let m = (a..b).map(|cj| rows[cj * sc[0] + si]).max().unwrap_or(0);
                    o[sj * sc[0] + si] = m;
                    if m != 0 {
                        *bb = Some(match *bb {
                            None => [si, si, sj, sj],
                            Some([p, q, r, t]) => [p.min(si), q.max(si), r.min(sj), t.max(sj)],
                        });
                    }
                }
            }
        });
        (sc, Arc::new(out), bbox)
    }
}
