//! The binary path's cells of an integer scan, built in place.
//!
//! Owns `InPlace`: one principal axis of an 8- or 16-bit scan as the cells a
//! binary ray reads, each voxel's density beside its normal code in one small
//! array element (`[u8; 3]`: the u8 density and the u16 code; `[u16; 2]`: the
//! 16-bit density less an offset and the code), so a cell's densities and
//! codes share their cache lines, in 3 (or 4) bytes a voxel.
//!
//! The cells are built without the volume beside them: the voxels are first
//! laid out in slicing order in the *last* `N` elements of the cell array
//! (phase 1, from the volume or from the cells of another axis), the caller
//! lets go of its source, and the codes are then computed front to back in
//! waves of slice blocks (phase 2), each wave first copying the densities it
//! reads into small f32 windows and then writing its cells. A wave's cells
//! `[s, e)` overwrite elements `< K·e`; the voxels that later waves read lie at
//! `(K−1)·N + j` for `j ≥ e − n01`, which is beyond `K·e` whenever
//! `e ≤ N − n01/(K−1)` — true for every wave but the last, which no wave
//! follows — and voxels already converted are read from their cells. So the
//! peak is the cell array, not the volume plus the cells (tested against the
//! codes of the whole f32 stack, voxel for voxel).

use crate::memory::Zeroable;
use crate::view::permutation;

/// Slices per block of phase 2 (a window holds the block and one slice on
/// either side).
pub(crate) const BLOCK: usize = 8;

/// The cells of one principal axis under construction: phase 1 done (the
/// voxels in slicing order at the end of `cells`), phase 2 pending
/// (`InPlace::finish`, with the normal codes: [`crate::data::normals`]). `E` is the element (u8 or u16), `K` the elements per
/// cell.
#[derive(Debug)]
pub(crate) struct InPlace<E, const K: usize> {
    /// Principal axis.
    pub axis: usize,
    /// Sizes along `(i, j, k)`.
    pub n: [usize; 3],
    pub(crate) cells: Vec<[E; K]>,
    /// One f32 window per block of a wave, allocated before the source is let
    /// go, so phase 2 cannot fail.
    pub(crate) windows: Vec<Vec<f32>>,
}

/// The sizes along `(i, j, k)` of the stack along `to` of a stack along `from`
/// with sizes `n`, and the strides in the source of its `(i, j, k)`.
pub(crate) fn restride(from: usize, n: [usize; 3], to: usize) -> ([usize; 3], [usize; 3]) {
    let (pf, pt) = (permutation(from), permutation(to));
    let own = [1usize, n[0], n[0] * n[1]];
    let (mut d, mut stride) = ([0usize; 3], [0usize; 3]);
    for t in 0..3 {
        d[pf[t]] = n[t];
        stride[pf[t]] = own[t];
    }
    ([d[pt[0]], d[pt[1]], d[pt[2]]], [stride[pt[0]], stride[pt[1]], stride[pt[2]]])
}

impl<E: Zeroable + Send + Sync, const K: usize> InPlace<E, K> {
    /// Phase 1: the cell array, with the voxels of `src` (a stack along
    /// `from` with sizes `src_n`; a volume is the stack along z) along `axis`
    /// converted by `conv` in its last `N` elements; the f32 windows of phase 2
    /// for `threads` workers. Fails with [`crate::Error::Memory`] before
    /// anything is written.
    pub(crate) fn new<T: Copy + Sync>(
        src: &[T],
        from: usize,
        src_n: [usize; 3],
        axis: usize,
        threads: usize,
        conv: impl Fn(T) -> E + Sync,
    ) -> crate::error::Result<Self> {
        let (n, s) = restride(from, src_n, axis);
        let len = n[0] * n[1] * n[2];
        let mut cells: Vec<[E; K]> = crate::memory::zeroed(len, "the packed densities and normal codes")?;
        let n01 = n[0] * n[1];
        let windows = (0..threads.max(1))
            .map(|_| crate::memory::zeroed((BLOCK + 2).min(n[2]) * n01, "a window of the slice stack"))
            .collect::<crate::error::Result<Vec<Vec<f32>>>>()?;
        let flat = cells.as_flattened_mut();
        crate::data::slices::gather(src, &mut flat[(K - 1) * len..], n, s, conv);
        Ok(InPlace { axis, n, cells, windows })
    }
}
