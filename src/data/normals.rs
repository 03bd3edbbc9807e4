//! Normal codes (VolPack's quantized normals).
//!
//! Owns the quantized normals that the table-shaded paths share, so a voxel
//! shades the same on all of them:
//!
//! - [`encode_normal`] / [`decode_normal`]: the 14-bit hemi-octahedral code of a
//!   gradient direction, up to sign (the headlight shading is two-sided).
//! - [`voxel_normal`]: the code of one voxel of a [`SliceStack`]: its
//!   central-difference gradient ([`SliceStack::gradient_at`]) mapped to object
//!   (world) space with the voxel spacing. The RLE encoding stores it per
//!   non-transparent voxel; [`NormalStack`] stores it for every voxel of one
//!   principal axis, laid out like the stack, for the binary path and its
//!   brute-force reference.
//! - [`cubic_voxel_normal`]: the code of one voxel under the cubic
//!   reconstruction ([`crate::kernels::reconstruct`]): the gradient of the
//!   cubic B-spline smoothing of the slices along the volume's z at the
//!   voxel, the normal the raycast paths' cubic hits are shaded with,
//!   evaluated at voxels. On thick slices it follows the surface where the
//!   central differences terrace.
//! - [`VoxelSource`]: what the pre-classified paths read voxels and their
//!   codes from (a cartesian stack, its codes chosen by the reconstruction
//!   with [`StackNormals`], or the BCC grid's slices).
//!
//! The per-view table of shades by code is
//! [`crate::classify::shade_table::ShadeTable`]: a sample shades as
//! `rgb·d + s` from the bilinear blend `[d, s]` of its cell's four corner
//! entries — four code loads and four table loads instead of a gradient, a
//! normalization and a power per sample.

use rayon::prelude::*;

use crate::data::packing::{BLOCK, InPlace, restride};
use crate::data::slices::{Densities, SliceStack, cell_corners, prefetch, prefetch_cell};
#[cfg(target_arch = "x86_64")]
use crate::data::slices::{bilinear_sse, bilinear_sse_bytes};
use crate::data::volume::{Volume, VoxelData, VoxelType};
use crate::kernels::Reconstruction;

/// Cells per side of the hemi-octahedral normal grid.
pub const NORMAL_SIDE: usize = 128;

/// Number of normal (shading) codes.
pub const NORMAL_CODES: usize = NORMAL_SIDE * NORMAL_SIDE;

/// The normal code of a zero gradient (shaded as facing the viewer).
pub const ZERO_NORMAL: u16 = 0;

/// The shading code of an object-space gradient `g` (any length): its direction
/// up to sign, since shading is two-sided (`|n · l|`).
///
/// Hemi-octahedral: `±g` is turned to `z ≥ 0`, projected onto the octahedron
/// `|x| + |y| + z = 1`, whose upper half (the diamond `|x| + |y| ≤ 1`) is rotated
/// 45° onto the square `[−1, 1]²` (`a = x + y`, `b = x − y`) and quantized to
/// [`NORMAL_SIDE`]² cells (code `u + NORMAL_SIDE·v`, corners on the square's
/// corners). The corners `(0, 0)` and `(side − 1, side − 1)` are the opposite
/// directions `∓x`, the same for shading; the encoder never emits the former,
/// which is [`ZERO_NORMAL`]. The worst direction error is about 1.1°.
#[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN counts as a zero gradient
pub fn encode_normal(g: [f32; 3]) -> u16 {
    let len2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
    // the same cut-off as headlight_ndl (NaN also counts as zero)
    if !(len2 > 1e-30) {
        return ZERO_NORMAL;
    }
    let g = if g[2] < 0.0 { g.map(|c| -c) } else { g };
    let l1 = g[0].abs() + g[1].abs() + g[2];
    let (x, y) = (g[0] / l1, g[1] / l1);
    let half = (NORMAL_SIDE - 1) as f32 / 2.0;
    let q = |c: f32| ((c + 1.0) * half + 0.5).clamp(0.0, (NORMAL_SIDE - 1) as f32) as usize;
    let code = q(x + y) + NORMAL_SIDE * q(x - y);
    if code == ZERO_NORMAL as usize { (NORMAL_CODES - 1) as u16 } else { code as u16 }
}

/// The (unnormalized, L1-unit) direction at the centre of cell `(u, v)`.
#[inline(always)]
fn hemi_dir(u: f32, v: f32) -> [f32; 3] {
    let step = 2.0 / (NORMAL_SIDE - 1) as f32;
    let (a, b) = (u * step - 1.0, v * step - 1.0);
    let (x, y) = (0.5 * (a + b), 0.5 * (a - b));
    // |x| + |y| = max(|a|, |b|) ≤ 1: z ≥ 0 up to rounding at the square's edge
    [x, y, (1.0 - x.abs() - y.abs()).max(0.0)]
}

/// The unit direction (`z ≥ 0`) of a normal code (`None` for [`ZERO_NORMAL`]).
pub fn decode_normal(code: u16) -> Option<[f32; 3]> {
    if code == ZERO_NORMAL {
        return None;
    }
    let c = code as usize;
    let d = hemi_dir((c % NORMAL_SIDE) as f32, (c / NORMAL_SIDE) as f32);
    let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    Some(d.map(|x| x / len))
}

/// A boxed array of `N` copies of `v` (built on the heap, not the stack).
pub(crate) fn boxed<T: Clone, const N: usize>(v: T) -> Box<[T; N]> {
    // a boxed slice of exactly N elements always converts
    vec![v; N].into_boxed_slice().try_into().unwrap_or_else(|_| unreachable!("length is N by construction"))
}

/// The normal code of voxel `(i, j, k)` of `stack`: its central-difference
/// gradient in object space (`inv_spacing` = `1 / spacing` per object axis).
#[inline]
pub fn voxel_normal(stack: &SliceStack, i: usize, j: usize, k: usize, inv_spacing: [f32; 3]) -> u16 {
    object_normal(stack.gradient_at(i, j, k), stack.perm(), inv_spacing)
}

/// The gradient (stack axes, voxel units) of the cubic reconstruction's
/// normal at voxel `(i, j, k)` of `stack`: the gradient of the cubic
/// B-spline smoothing of the slices along stack axis `za` (the volume's z,
/// [`crate::kernels::reconstruct::cubic_axis`]) evaluated at the voxel,
/// where the B-spline's fraction is 0 and its weights are `[1, 4, 1]/6` on
/// the voxels `z − 1, z, z + 1` and its derivatives `[−½, 0, ½]`
/// ([`crate::kernels::reconstruct::b_spline`]). Along `za` that is the
/// central difference `(p₊ − p₋)/2`; along each other axis the central
/// differences of the three voxels (one-sided at an in-plane border, as
/// [`SliceStack::gradient_at`]) blended by `[1, 4, 1]/6` — the function the
/// raycast paths' cubic hit is shaded with (its bilinear in-plane blend is
/// the voxel's own differences at a voxel), evaluated at voxels. A border
/// along `za` repeats its slice, as the cubic's four slices do (there the
/// difference along `za` is half the one-sided one). Every component is the
/// same float arithmetic on the same voxels whatever the stack's
/// permutation, so the code of a voxel is the same from every axis's stack.
#[inline]
pub fn cubic_voxel_gradient(stack: &SliceStack, i: usize, j: usize, k: usize, za: usize) -> [f32; 3] {
    let (n, d) = (stack.n, stack.data());
    let stride = [1, n[0], n[0] * n[1]];
    let c = [i, j, k];
    // the steps to the voxel before and after along each axis (0 at a border)
    let down: [usize; 3] = std::array::from_fn(|a| if c[a] > 0 { stride[a] } else { 0 });
    let up: [usize; 3] = std::array::from_fn(|a| if c[a] + 1 < n[a] { stride[a] } else { 0 });
    let b = stack.index(i, j, k);
    // the central difference along axis a at voxel index v (of this voxel's row along a)
    let cd = |v: usize, a: usize| {
        let span = (down[a] > 0) as u32 + (up[a] > 0) as u32;
        if span > 0 { (d[v + up[a]] - d[v - down[a]]) / span as f32 } else { 0.0 }
    };
    let (below, above) = (b - down[za], b + up[za]);
    std::array::from_fn(|a| if a == za { 0.5 * (d[above] - d[below]) } else { (cd(below, a) + 4.0 * cd(b, a) + cd(above, a)) / 6.0 })
}

/// The normal code of voxel `(i, j, k)` of `stack` under the cubic
/// reconstruction: [`cubic_voxel_gradient`] along the volume's z, mapped to
/// object space with the voxel spacing (`inv_spacing` = `1 / spacing` per
/// object axis, as [`voxel_normal`]) and encoded.
#[inline]
pub fn cubic_voxel_normal(stack: &SliceStack, i: usize, j: usize, k: usize, inv_spacing: [f32; 3]) -> u16 {
    let za = crate::kernels::reconstruct::cubic_axis(stack.perm());
    object_normal(cubic_voxel_gradient(stack, i, j, k, za), stack.perm(), inv_spacing)
}

/// The normal code of a voxel-space gradient `g` of a stack with axis
/// permutation `perm`: mapped to object space, then encoded.
#[inline(always)]
fn object_normal(g: [f32; 3], perm: [usize; 3], inv_spacing: [f32; 3]) -> u16 {
    let mut w = [0f32; 3];
    for c in 0..3 {
        w[perm[c]] = g[c] * inv_spacing[perm[c]];
    }
    encode_normal(w)
}

/// The normal code of every voxel of one [`SliceStack`], in its `(i, j, k)`
/// layout (index [`SliceStack::index`]). Three layouts, the same image bit for
/// bit:
///
/// - **bytes** (`NormalStack::try_cells`, the binary path of 8-bit scans):
///   `[density, code]` in three bytes a voxel ([`ByteCells`]);
/// - **packed** (the binary path of 16-bit scans, and
///   [`NormalStack::with_packing`] of an f32 stack whose densities are
///   integers spanning at most 65 535): `[density − offset, code]` in two u16
///   ([`PackedCells`]);
/// - **codes** only, 2 bytes per voxel, beside the f32 stack.
///
/// In the first two a ray reads a cell's densities and codes from the same two
/// cache lines. Built by `NormalStack::try_cells`, they hold every voxel
/// exactly and need no f32 stack nor the volume beside them: the renderer lets
/// go of the volume and gets it back from them
/// ([`NormalStack::voxels_in_volume_order`]).
#[derive(Clone, Debug, PartialEq)]
pub struct NormalStack {
    /// Principal axis of the stack it was built from.
    pub axis: usize,
    /// Sizes along `(i, j, k)`.
    pub n: [usize; 3],
    store: Store,
    /// The scan's voxel type when the store holds every voxel exactly
    /// (built by [`NormalStack::try_cells`]).
    voxels: Option<VoxelType>,
}

/// Where [`NormalStack::try_cells`] takes the voxels from.
#[derive(Clone, Copy, Debug)]
pub(crate) enum CellSource<'a> {
    /// The volume (8- or 16-bit voxels).
    Volume(&'a Volume),
    /// The cells of another axis that hold every voxel.
    Cells(&'a NormalStack),
}

/// A [`NormalStack::try_cells`] build between its two phases: the voxels
/// laid out, the codes not yet computed ([`CellBuild::finish`]).
#[derive(Debug)]
pub(crate) enum CellBuild {
    U8(InPlace<u8, 3>),
    U16 { cells: InPlace<u16, 2>, offset: f32, voxels: VoxelType },
}

impl CellBuild {
    /// Computes the codes (for voxel `spacing`) into the cells: the same codes
    /// bit for bit as [`NormalStack::try_with_codes`] of the whole f32 stack
    /// with the codes of `reconstruction`. Cannot fail.
    pub fn finish(self, spacing: [f32; 3], reconstruction: Reconstruction) -> NormalStack {
        let cubic = reconstruction == Reconstruction::Cubic;
        match self {
            CellBuild::U8(b) => {
                let (axis, n) = (b.axis, b.n);
                // exact: d is a u8 value
                let cells = b.finish(spacing, cubic, |e| e as f32, |d, c| [d as u8, c as u8, (c >> 8) as u8]);
                NormalStack { axis, n, store: Store::Bytes(cells), voxels: Some(VoxelType::U8) }
            }
            CellBuild::U16 { cells, offset, voxels } => {
                let (axis, n) = (cells.axis, cells.n);
                // exact: d − offset is an integer in 0..=65535
                let words = cells.finish(spacing, cubic, |e| e as f32 + offset, |d, c| [(d - offset) as u16, c]);
                NormalStack { axis, n, store: Store::Packed { words, offset }, voxels: Some(voxels) }
            }
        }
    }
}

/// How a [`NormalStack`] holds its codes.
#[derive(Clone, Debug, PartialEq)]
enum Store {
    /// One u16 code per voxel.
    Codes(Vec<u16>),
    /// Per voxel `[density − offset, code]`.
    Packed { words: Vec<[u16; 2]>, offset: f32 },
    /// Per voxel `[density, code low byte, code high byte]` (8-bit densities).
    Bytes(Vec<[u8; 3]>),
}

impl NormalStack {
    /// Codes every voxel of `stack` for a volume with voxel `spacing`, in
    /// parallel over slices (on the current rayon pool); packed with the
    /// densities when they allow it (see [`NormalStack`]).
    pub fn new(stack: &SliceStack, spacing: [f32; 3]) -> Self {
        Self::with_packing(stack, spacing, true)
    }

    /// [`NormalStack::new`], packed only if `pack` (and the densities allow it):
    /// `false` keeps the codes apart, the reference layout of tests and benches.
    ///
    /// # Panics
    /// When the system refuses the allocation (as `vec!` would).
    pub fn with_packing(stack: &SliceStack, spacing: [f32; 3], pack: bool) -> Self {
        Self::try_with_packing(stack, spacing, pack).unwrap_or_else(|e| panic!("{e}"))
    }

    /// [`NormalStack::with_packing`], or [`crate::Error::Memory`] when the
    /// system refuses the allocation.
    pub fn try_with_packing(stack: &SliceStack, spacing: [f32; 3], pack: bool) -> crate::error::Result<Self> {
        Self::try_with_codes(stack, spacing, pack, Reconstruction::Linear)
    }

    /// [`NormalStack::try_with_packing`] with the normal codes of
    /// `reconstruction`: the central differences ([`voxel_normal`]) of the
    /// linear one, or the B-spline gradient of the cubic one at each voxel
    /// ([`cubic_voxel_normal`]), the codes [`StackNormals`] gives.
    pub fn try_with_codes(stack: &SliceStack, spacing: [f32; 3], pack: bool, reconstruction: Reconstruction) -> crate::error::Result<Self> {
        let cubic = reconstruction == Reconstruction::Cubic;
        let len = stack.n[0] * stack.n[1] * stack.n[2];
        let store = match pack.then(|| packing_offset(stack.data())).flatten() {
            Some(offset) => {
                let mut words: Vec<[u16; 2]> = crate::memory::zeroed(len, "the packed densities and normal codes")?;
                // exact: d − offset is an integer in 0..=65535 (checked)
                code_slices(stack, 0..stack.n[2], spacing, cubic, &mut words, |w, d, c| *w = [(d - offset) as u16, c]);
                Store::Packed { words, offset }
            }
            None => {
                let mut codes: Vec<u16> = crate::memory::zeroed(len, "the normal codes")?;
                code_slices(stack, 0..stack.n[2], spacing, cubic, &mut codes, |w, _, c| *w = c);
                Store::Codes(codes)
            }
        };
        Ok(NormalStack { axis: stack.axis, n: stack.n, store, voxels: None })
    }

    /// Phase 1 of the binary path's cells of an 8- or 16-bit scan along
    /// `axis` (`None` for f32 voxels, or cells that do not hold every voxel):
    /// the cell array with the voxels of `src` laid out in it, and the f32
    /// windows phase 2 needs for `threads` workers ([`crate::data::packing`]).
    /// The source may be let go before [`CellBuild::finish`], which computes
    /// the codes and cannot fail: the volume and the cells are held together
    /// only while the voxels are laid out.
    pub(crate) fn try_cells(src: CellSource, axis: usize, threads: usize) -> crate::error::Result<Option<CellBuild>> {
        match src {
            CellSource::Volume(vol) => {
                let (d, lo) = (vol.dims(), vol.value_range().0 as i32);
                Ok(Some(match vol.data() {
                    VoxelData::U8(v) => CellBuild::U8(InPlace::new(v, 2, d, axis, threads, |x| x)?),
                    // exact: lo ≤ x ≤ lo + 65535 for every voxel of a 16-bit scan
                    VoxelData::U16(v) => CellBuild::U16 {
                        cells: InPlace::new(v, 2, d, axis, threads, |x| (x as i32 - lo) as u16)?,
                        offset: lo as f32,
                        voxels: VoxelType::U16,
                    },
                    VoxelData::I16(v) => CellBuild::U16 {
                        cells: InPlace::new(v, 2, d, axis, threads, |x| (x as i32 - lo) as u16)?,
                        offset: lo as f32,
                        voxels: VoxelType::I16,
                    },
                    VoxelData::F32(_) => return Ok(None),
                }))
            }
            CellSource::Cells(ns) => {
                let (from, n) = (ns.axis, ns.n);
                Ok(match (&ns.store, ns.voxels) {
                    (Store::Bytes(c), Some(_)) => Some(CellBuild::U8(InPlace::new(c, from, n, axis, threads, |c| c[0])?)),
                    (Store::Packed { words, offset }, Some(voxels)) => {
                        Some(CellBuild::U16 { cells: InPlace::new(words, from, n, axis, threads, |w| w[0])?, offset: *offset, voxels })
                    }
                    _ => None,
                })
            }
        }
    }

    /// True when this stack holds every voxel of the scan exactly (built by
    /// `NormalStack::try_cells`).
    pub fn holds_voxels(&self) -> bool {
        self.voxels.is_some()
    }

    /// The scan's voxels back in the volume's order and type, when this stack
    /// holds them ([`NormalStack::holds_voxels`]), or [`crate::Error::Memory`].
    pub fn voxels_in_volume_order(&self) -> crate::error::Result<Option<VoxelData>> {
        let (d, s) = restride(self.axis, self.n, 2);
        fn go<T: Copy + Sync, U: crate::memory::Zeroable + Send>(
            src: &[T],
            d: [usize; 3],
            s: [usize; 3],
            f: impl Fn(T) -> U + Sync,
        ) -> crate::error::Result<Vec<U>> {
            let mut out = crate::memory::zeroed(d[0] * d[1] * d[2], "the volume")?;
            crate::data::slices::gather(src, &mut out, d, s, f);
            Ok(out)
        }
        Ok(match (&self.store, self.voxels) {
            (Store::Bytes(c), Some(_)) => Some(VoxelData::U8(go(c, d, s, |c| c[0])?)),
            (Store::Packed { words, offset }, Some(VoxelType::U16)) => {
                let lo = *offset as i32;
                Some(VoxelData::U16(go(words, d, s, |w| (w[0] as i32 + lo) as u16)?))
            }
            (Store::Packed { words, offset }, Some(VoxelType::I16)) => {
                let lo = *offset as i32;
                Some(VoxelData::I16(go(words, d, s, |w| (w[0] as i32 + lo) as i16)?))
            }
            _ => None,
        })
    }

    /// The code of the voxel at stack index `index`.
    #[inline(always)]
    pub fn at(&self, index: usize) -> u16 {
        match &self.store {
            Store::Codes(c) => c[index],
            Store::Packed { words, .. } => words[index][1],
            Store::Bytes(c) => code_of(c[index]),
        }
    }

    /// The codes of the cell whose first voxel has stack index `b`, in the
    /// order of [`SliceStack::bilinear`]'s corners: one bounds check for all four.
    #[inline(always)]
    pub fn corners(&self, b: usize) -> [u16; 4] {
        match &self.store {
            Store::Codes(c) => cell_corners(c, b, self.n[0]),
            Store::Packed { words, .. } => cell_corners(words, b, self.n[0]).map(|w| w[1]),
            Store::Bytes(c) => cell_corners(c, b, self.n[0]).map(code_of),
        }
    }

    /// The codes apart (empty when packed).
    pub fn codes(&self) -> &[u16] {
        match &self.store {
            Store::Codes(c) => c,
            Store::Packed { .. } | Store::Bytes(_) => &[],
        }
    }

    /// The packed densities and codes, if this stack is packed.
    pub fn packed(&self) -> Option<PackedCells<'_>> {
        match &self.store {
            Store::Packed { words, offset } => Some(PackedCells { words, n0: self.n[0], offset: *offset }),
            _ => None,
        }
    }

    /// The 8-bit densities and codes, if this stack holds them.
    pub fn bytes_cells(&self) -> Option<ByteCells<'_>> {
        match &self.store {
            Store::Bytes(cells) => Some(ByteCells::new(cells, self.n[0])),
            _ => None,
        }
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        match &self.store {
            Store::Codes(c) => c.len() * 2,
            Store::Packed { words, .. } => words.len() * 4,
            Store::Bytes(c) => c.len() * 3,
        }
    }
}

impl Densities for NormalStack {
    fn dims(&self) -> [usize; 3] {
        self.n
    }
    /// # Panics
    /// For codes kept apart (no densities): only packed stacks hold them.
    fn row(&self, j: usize, k: usize, out: &mut [f32]) {
        let b = self.n[0] * (j + self.n[1] * k);
        match &self.store {
            Store::Packed { words, offset } => {
                for (o, &w) in out.iter_mut().zip(&words[b..b + self.n[0]]) {
                    *o = w[0] as f32 + offset;
                }
            }
            Store::Bytes(c) => {
                for (o, &w) in out.iter_mut().zip(&c[b..b + self.n[0]]) {
                    *o = w[0] as f32;
                }
            }
            Store::Codes(_) => panic!("a normal stack without densities"),
        }
    }
}

/// Voxels per task of the packing pass.
const PACK_CHUNK: usize = 1 << 16;

/// Writes `put(out, density, code)` for every voxel of `stack` (layout of
/// [`SliceStack::index`]), in parallel over slices. Interior voxels are coded a
/// row at a time by [`encode_interior_row`] (branch-free, so the compiler
/// vectorizes it); the border voxels by [`voxel_normal`]. Both give exactly
/// [`voxel_normal`]'s code (a test compares every voxel).
///
/// Only the slices `ks` of `stack` are coded (`out` holds exactly those): a
/// window of a larger stack codes its inner slices exactly as the whole stack
/// would when it also holds the slices next to them (or they are the volume's
/// first or last).
pub(crate) fn code_slices<T: Send>(
    stack: &SliceStack,
    ks: std::ops::Range<usize>,
    spacing: [f32; 3],
    cubic: bool,
    out: &mut [T],
    put: impl Fn(&mut T, f32, u16) + Sync,
) {
    let n = stack.n;
    let inv = spacing.map(|s| 1.0 / s);
    let perm = stack.perm();
    let (n0, n01, d) = (n[0], n[0] * n[1], stack.data());
    // the stack axis c whose difference feeds object axis perm[c]
    let mut src = [0usize; 3];
    for c in 0..3 {
        src[perm[c]] = c;
    }
    out.par_chunks_mut(n01.max(1)).enumerate().for_each(|(dk, slice)| {
        let k = ks.start + dk;
        let mut row_codes = vec![0u16; n0];
        for (j, row) in slice.chunks_mut(n0.max(1)).enumerate() {
            let b = n01 * k + n0 * j;
            if cubic {
                for (i, c) in row_codes.iter_mut().enumerate() {
                    *c = cubic_voxel_normal(stack, i, j, k, inv);
                }
                for ((o, &dv), &c) in row.iter_mut().zip(&d[b..b + n0]).zip(&row_codes) {
                    put(o, dv, c);
                }
                continue;
            }
            let interior = j >= 1 && j + 1 < n[1] && k >= 1 && k + 1 < n[2] && n0 >= 3;
            if interior {
                let m = n0 - 2;
                // per stack axis: the lower and upper neighbours of voxels 1..=m of the row
                let pairs: [(&[f32], &[f32]); 3] = [
                    (&d[b..b + m], &d[b + 2..b + 2 + m]),
                    (&d[b - n0 + 1..b - n0 + 1 + m], &d[b + n0 + 1..b + n0 + 1 + m]),
                    (&d[b - n01 + 1..b - n01 + 1 + m], &d[b + n01 + 1..b + n01 + 1 + m]),
                ];
                encode_interior_row(&mut row_codes[1..=m], [pairs[src[0]], pairs[src[1]], pairs[src[2]]], [inv[0], inv[1], inv[2]]);
                row_codes[0] = voxel_normal(stack, 0, j, k, inv);
                row_codes[n0 - 1] = voxel_normal(stack, n0 - 1, j, k, inv);
            } else {
                for (i, c) in row_codes.iter_mut().enumerate() {
                    *c = voxel_normal(stack, i, j, k, inv);
                }
            }
            for ((o, &dv), &c) in row.iter_mut().zip(&d[b..b + n0]).zip(&row_codes) {
                put(o, dv, c);
            }
        }
    });
}

/// The codes of a row of interior voxels: `g[a]` holds, for object axis `a`,
/// the densities one voxel below and above along the stack axis that maps to
/// it; `inv` the inverse spacing per object axis. The same arithmetic as
/// [`object_normal`] of a central difference and [`encode_normal`], written
/// without branches.
#[inline(always)]
fn encode_interior_row(out: &mut [u16], g: [(&[f32], &[f32]); 3], inv: [f32; 3]) {
    let m = out.len();
    let ([xl, xh], [yl, yh], [zl, zh]) = ([&g[0].0[..m], &g[0].1[..m]], [&g[1].0[..m], &g[1].1[..m]], [&g[2].0[..m], &g[2].1[..m]]);
    for t in 0..m {
        let w = [(xh[t] - xl[t]) * 0.5 * inv[0], (yh[t] - yl[t]) * 0.5 * inv[1], (zh[t] - zl[t]) * 0.5 * inv[2]];
        out[t] = encode_normal_branchless(w);
    }
}

/// [`encode_normal`] without branches (selects instead), for vectorized loops.
#[inline(always)]
#[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN counts as a zero gradient
fn encode_normal_branchless(g: [f32; 3]) -> u16 {
    let len2 = g[0] * g[0] + g[1] * g[1] + g[2] * g[2];
    let s = if g[2] < 0.0 { -1.0f32 } else { 1.0 };
    let (x, y, z) = (g[0] * s, g[1] * s, g[2] * s);
    let l1 = x.abs() + y.abs() + z;
    let (x, y) = (x / l1, y / l1);
    let half = (NORMAL_SIDE - 1) as f32 / 2.0;
    // `max` turns NaN into 0 (what `clamp` then `as` gives), so the value is
    // finite and in [0, 127]
    let q = |c: f32| {
        let v = ((c + 1.0) * half + 0.5).max(0.0).min((NORMAL_SIDE - 1) as f32);
        // SAFETY: `v` is finite and in [0, 127] (after `max`, `min`), so it is
        // representable in i32, which is all `to_int_unchecked` requires; unlike
        // `as`, it needs no saturation code, so the loop vectorizes.
        unsafe { v.to_int_unchecked::<i32>() }
    };
    let code = q(x + y) + NORMAL_SIDE as i32 * q(x - y);
    let code = if code == ZERO_NORMAL as i32 { (NORMAL_CODES - 1) as i32 } else { code };
    if !(len2 > 1e-30) { ZERO_NORMAL } else { code as u16 }
}

/// The offset that packs `data` into 16 bits exactly, if there is one: every
/// value an integer, the smallest at least −2^24 and the largest at most
/// 65 535 above it and below 2^24 (so `(v − offset) as u16 as f32 + offset == v`).
fn packing_offset(data: &[f32]) -> Option<f32> {
    // `v == (v as i32) as f32` is the integer test (cheaper than `trunc`, a libm
    // call on the baseline x86-64): beyond ±2^31 it may say yes, but such
    // values fail the ±2^24 bound below anyway
    const EXACT: f32 = (1 << 24) as f32;
    let (lo, hi, whole) = data
        .par_chunks(PACK_CHUNK)
        .map(|c| {
            c.iter().fold((f32::INFINITY, f32::NEG_INFINITY, true), |(lo, hi, w), &v| (lo.min(v), hi.max(v), w && v == (v as i32) as f32))
        })
        .reduce(|| (f32::INFINITY, f32::NEG_INFINITY, true), |a, b| (a.0.min(b.0), a.1.max(b.1), a.2 && b.2));
    (whole && lo <= hi && lo >= -EXACT && hi < EXACT && hi - lo <= u16::MAX as f32).then_some(lo)
}

/// A packed [`NormalStack`] as a ray reads it: per voxel, `density − offset`
/// in the low 16 bits and the normal code in the high 16.
#[derive(Clone, Copy, Debug)]
pub struct PackedCells<'a> {
    words: &'a [[u16; 2]],
    n0: usize,
    offset: f32,
}

impl PackedCells<'_> {
    /// The density of voxel `b` (exactly the stack's value).
    #[inline(always)]
    pub fn density(&self, b: usize) -> f32 {
        self.words[b][0] as f32 + self.offset
    }

    /// The four corner densities of the cell at stack index `b` (exactly the
    /// stack's values; order of [`SliceStack::bilinear`]).
    #[inline(always)]
    pub fn densities(&self, b: usize) -> [f32; 4] {
        cell_corners(self.words, b, self.n0).map(|w| w[0] as f32 + self.offset)
    }

    /// The four corner codes of the cell at stack index `b`.
    #[inline(always)]
    pub fn codes(&self, b: usize) -> [u16; 4] {
        cell_corners(self.words, b, self.n0).map(|w| w[1])
    }

    /// Hints the cache to fetch both rows of the cell at stack index `b`.
    #[inline(always)]
    pub fn prefetch(&self, b: usize) {
        prefetch_cell(self.words, b, self.n0);
    }

    /// Hints the cache to fetch the line of voxel `b` (densities and codes
    /// share it): no effect on results.
    #[inline(always)]
    pub fn prefetch_voxel(&self, b: usize) {
        prefetch(self.words, b);
    }

    /// [`crate::data::slices::bilinear`] of [`PackedCells::densities`] at `(wi, wj)`, bit for bit:
    /// each row's two voxels in one 8-byte load, the four densities moved
    /// into one vector by a byte shuffle, interpolated there with the same
    /// float operations.
    ///
    /// # Safety
    /// The CPU must have SSSE3, and the caller be compiled with it.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub unsafe fn sample_ssse3(&self, b: usize, wi: f32, wj: f32) -> f32 {
        use std::arch::x86_64::*;
        assert!(b + self.n0 + 2 <= self.words.len(), "a cell outside the stack");
        let p = self.words.as_ptr();
        // SAFETY: voxels `b, b + 1` and `b + n0, b + n0 + 1` lie in `words`
        // (asserted), each pair 8 contiguous bytes read unaligned; the
        // intrinsics need SSSE3 (pshufb) and SSE3, which the caller guarantees.
        unsafe {
            let (r0, r1) = (p.add(b).cast::<i64>().read_unaligned(), p.add(b + self.n0).cast::<i64>().read_unaligned());
            // bytes: row 0 [d00 c00 d10 c10], row 1 [d01 c01 d11 c11] (u16 each);
            // lanes [d00, d01, d10, d11] zero-extended, converted exactly
            let x = _mm_shuffle_epi8(_mm_set_epi64x(r1, r0), _mm_setr_epi8(0, 1, -1, -1, 8, 9, -1, -1, 4, 5, -1, -1, 12, 13, -1, -1));
            let f = _mm_add_ps(_mm_cvtepi32_ps(x), _mm_set1_ps(self.offset));
            bilinear_sse(f, wi, wj)
        }
    }
}

/// The code of a `[density, code low byte, code high byte]` cell.
#[inline(always)]
fn code_of(c: [u8; 3]) -> u16 {
    u16::from_le_bytes([c[1], c[2]])
}

/// Every byte as f32 (`BYTE_F32[v] == f32::from(v)`): one load where a
/// conversion takes two instructions and a dependency break.
static BYTE_F32: [f32; 256] = {
    let mut t = [0.0f32; 256];
    let mut i = 0;
    while i < 256 {
        t[i] = i as f32;
        i += 1;
    }
    t
};

/// A bytes [`NormalStack`] as a ray reads it: per voxel the 8-bit density and
/// the normal code in three bytes.
#[derive(Clone, Copy, Debug)]
pub struct ByteCells<'a> {
    cells: &'a [[u8; 3]],
    n0: usize,
    /// One past the largest index whose cell (the voxel, its right and lower
    /// neighbours) lies in `cells`: `len − n0 − 1`, saturating.
    end: usize,
}

impl<'a> ByteCells<'a> {
    /// The density of voxel `b` (exactly the stack's value).
    #[inline(always)]
    pub fn density(&self, b: usize) -> f32 {
        f32::from(self.cells[b][0])
    }

    fn new(cells: &'a [[u8; 3]], n0: usize) -> Self {
        ByteCells { cells, n0, end: cells.len().saturating_sub(n0 + 1) }
    }

    /// The bytes of the two voxel pairs of the cell at stack index `b`: its
    /// first row's two voxels and its second row's (three bytes a voxel, so
    /// each pair is six contiguous bytes). One test for both; panics if the
    /// cell is not in the stack.
    #[inline(always)]
    fn pairs(&self, b: usize) -> [[u8; 6]; 2] {
        assert!(b < self.end, "a cell outside the stack");
        let p = self.cells.as_flattened().as_ptr();
        // SAFETY: `b < end = len − n0 − 1` gives `b + n0 + 1 < len` (no
        // overflow: a slice has fewer than isize::MAX / 3 voxels), so the
        // six bytes from voxel `b` and the six from voxel `b + n0` (voxels
        // `b, b + 1` and `b + n0, b + n0 + 1`) lie within the `3·len` bytes
        // of `cells`; `[u8; 6]` has alignment 1. Exercised by every binary
        // render of an 8-bit volume (tests/invariants.rs, tests/lean_frame.rs).
        unsafe { [p.add(3 * b).cast::<[u8; 6]>().read(), p.add(3 * (b + self.n0)).cast::<[u8; 6]>().read()] }
    }

    /// The four corner densities of the cell at stack index `b` (order of
    /// [`SliceStack::bilinear`]): the first byte of each voxel, read from the
    /// cell's two rows without moving the codes.
    #[inline(always)]
    pub fn densities(&self, b: usize) -> [f32; 4] {
        let [t, u] = self.pairs(b);
        [t[0], t[3], u[0], u[3]].map(|v| BYTE_F32[v as usize])
    }

    /// The four corner codes of the cell at stack index `b` (each voxel's
    /// second and third bytes, little-endian).
    #[inline(always)]
    pub fn codes(&self, b: usize) -> [u16; 4] {
        let [t, u] = self.pairs(b);
        [[t[1], t[2]], [t[4], t[5]], [u[1], u[2]], [u[4], u[5]]].map(u16::from_le_bytes)
    }

    /// Hints the cache to fetch both rows of the cell at stack index `b`.
    #[inline(always)]
    pub fn prefetch(&self, b: usize) {
        prefetch_cell(self.cells, b, self.n0);
    }

    /// Hints the cache to fetch the line of voxel `b` (densities and codes
    /// share it): no effect on results.
    #[inline(always)]
    pub fn prefetch_voxel(&self, b: usize) {
        prefetch(self.cells, b);
    }

    /// [`crate::data::slices::bilinear`] of [`ByteCells::densities`] at `(wi, wj)`, bit for bit:
    /// each row's first voxel and the next one's density in one 4-byte load,
    /// the four densities moved into one vector by a byte shuffle,
    /// interpolated there with the same float operations.
    ///
    /// # Safety
    /// The CPU must have SSSE3, and the caller be compiled with it.
    #[cfg(target_arch = "x86_64")]
    #[inline(always)]
    pub unsafe fn sample_ssse3(&self, b: usize, wi: f32, wj: f32) -> f32 {
        use std::arch::x86_64::*;
        assert!(b < self.end, "a cell outside the stack");
        let p = self.cells.as_flattened().as_ptr();
        // SAFETY: as in `pairs`, the six bytes from voxel `b` and those from
        // voxel `b + n0` lie in `cells`; each read takes the first four of
        // them, unaligned. The intrinsics need SSSE3 (pshufb) and SSE3, which
        // the caller guarantees.
        unsafe {
            let (r0, r1) = (p.add(3 * b).cast::<i32>().read_unaligned(), p.add(3 * (b + self.n0)).cast::<i32>().read_unaligned());
            // bytes: row 0 [d00 c00 c00 d10], row 1 [d01 c01 c01 d11]; lanes
            // [d00, d01, d10, d11] zero-extended, converted exactly
            let x =
                _mm_shuffle_epi8(_mm_setr_epi32(r0, r1, 0, 0), _mm_setr_epi8(0, -1, -1, -1, 4, -1, -1, -1, 3, -1, -1, -1, 7, -1, -1, -1));
            // (bytes: whole numbers in [0, 255], which neither clamp binds)
            bilinear_sse_bytes(_mm_cvtepi32_ps(x), wi, wj)
        }
    }
}

/// What the pre-classified paths read voxels from: slices of densities (a
/// [`SliceStack`]: its sizes, axis and densities) and each voxel's normal
/// code. A cartesian [`SliceStack`] is its own source (central differences
/// between neighbouring voxels, [`voxel_normal`]); the interleaved slices of a
/// BCC grid ([`crate::data::bcc::BccStack`]) differentiate across slices two
/// apart (the same sub-grid). The encoder ([`crate::encode::rle::RleVolume::encode`]) and
/// the brute force ([`crate::composite::slices::render_brute_preclassified`])
/// see only this.
pub trait VoxelSource: Sync {
    /// The slices' densities (sizes along `(i, j, k)`, principal axis).
    fn slices(&self) -> &SliceStack;
    /// The normal code of voxel `(i, j, k)` (`inv_spacing`: `1 / spacing` per
    /// object axis of the cartesian volume).
    fn normal(&self, i: usize, j: usize, k: usize, inv_spacing: [f32; 3]) -> u16;
}

impl VoxelSource for SliceStack {
    #[inline(always)]
    fn slices(&self) -> &SliceStack {
        self
    }
    #[inline]
    fn normal(&self, i: usize, j: usize, k: usize, inv_spacing: [f32; 3]) -> u16 {
        voxel_normal(self, i, j, k, inv_spacing)
    }
}

/// A cartesian [`SliceStack`] whose voxels' normal codes are those of a
/// reconstruction ([`crate::kernels::Reconstruction`]): the linear one's
/// central differences ([`voxel_normal`], what the stack as its own source
/// gives), or the cubic one's B-spline gradient ([`cubic_voxel_normal`]).
/// What the RLE paths encode and their brute force classifies under
/// `--reconstruction`: both read the same codes, so they stay equal.
#[derive(Clone, Copy, Debug)]
pub struct StackNormals<'a> {
    stack: &'a SliceStack,
    cubic: bool,
}

impl<'a> StackNormals<'a> {
    /// `stack` with the normal codes of `reconstruction`.
    pub fn new(stack: &'a SliceStack, reconstruction: crate::kernels::Reconstruction) -> Self {
        StackNormals { stack, cubic: reconstruction == crate::kernels::Reconstruction::Cubic }
    }
}

impl VoxelSource for StackNormals<'_> {
    #[inline(always)]
    fn slices(&self) -> &SliceStack {
        self.stack
    }
    #[inline]
    fn normal(&self, i: usize, j: usize, k: usize, inv_spacing: [f32; 3]) -> u16 {
        if self.cubic { cubic_voxel_normal(self.stack, i, j, k, inv_spacing) } else { voxel_normal(self.stack, i, j, k, inv_spacing) }
    }
}

/// Phase 2 of the packed cells: their normal codes (phase 1, the packing, is
/// [`InPlace::new`]).
impl<E: crate::memory::Zeroable + Send + Sync, const K: usize> InPlace<E, K> {
    /// Phase 2: codes every voxel (for voxel `spacing`, with the cubic's codes
    /// if `cubic`, as [`code_slices`] of the whole f32 stack would) and writes
    /// each cell as `make(density, code)`; `density` reads an element back as
    /// f32. Returns the cells.
    pub(crate) fn finish(
        mut self,
        spacing: [f32; 3],
        cubic: bool,
        density: impl Fn(E) -> f32 + Sync,
        make: impl Fn(f32, u16) -> [E; K] + Sync,
    ) -> Vec<[E; K]> {
        let n = self.n;
        let (n01, len) = (n[0] * n[1], n[0] * n[1] * n[2]);
        if len == 0 {
            return self.cells;
        }
        let per_wave = self.windows.len();
        let mut s0 = 0;
        while s0 < n[2] {
            let s1 = (s0 + BLOCK * per_wave).min(n[2]);
            let blocks: Vec<(usize, usize)> = (s0..s1).step_by(BLOCK).map(|k0| (k0, (k0 + BLOCK).min(s1))).collect();
            // copy what the wave reads: converted voxels from their cells, the
            // others from the voxels at the end, all intact (module docs)
            let (cells, done) = (self.cells.as_flattened(), s0 * n01);
            self.windows.par_iter_mut().zip(blocks.par_iter()).for_each(|(win, &(k0, k1))| {
                let (w0, w1) = (k0.saturating_sub(1), (k1 + 1).min(n[2]));
                let split = done.clamp(w0 * n01, w1 * n01);
                win.truncate(0);
                win.extend((w0 * n01..split).map(|j| density(cells[K * j])));
                win.extend((split..w1 * n01).map(|j| density(cells[(K - 1) * len + j])));
            });
            // then write the wave's cells, a block per window
            let out = &mut self.cells[s0 * n01..s1 * n01];
            out.par_chunks_mut(BLOCK * n01).zip(self.windows.par_iter_mut()).zip(blocks.par_iter()).for_each(|((out, win), &(k0, k1))| {
                let w0 = k0.saturating_sub(1);
                let w1 = (k1 + 1).min(n[2]);
                let stack = SliceStack::from_parts(self.axis, [n[0], n[1], w1 - w0], std::mem::take(win));
                code_slices(&stack, k0 - w0..k1 - w0, spacing, cubic, out, |c, d, code| *c = make(d, code));
                *win = stack.into_data();
            });
            s0 = s1;
        }
        self.cells
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::volume::Volume;

    #[test]
    fn the_byte_table_is_the_conversion() {
        for v in 0..=255u8 {
            assert_eq!(BYTE_F32[v as usize].to_bits(), f32::from(v).to_bits());
        }
    }

    #[test]
    fn normal_codes_keep_the_direction_within_1_2_degrees() {
        let mut seed = 99u64;
        let mut rnd = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (seed >> 11) as f32 / (1u64 << 53) as f32 * 2.0 - 1.0
        };
        let mut worst = 0f32;
        for _ in 0..100_000 {
            let g = [rnd(), rnd(), rnd()];
            let len = (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]).sqrt();
            let code = encode_normal(g);
            assert_ne!(code, ZERO_NORMAL);
            let n = decode_normal(code).unwrap();
            assert!(n[2] >= 0.0);
            // the code keeps the direction up to sign
            let cos = (n[0] * g[0] + n[1] * g[1] + n[2] * g[2]).abs() / len;
            worst = worst.max(cos.min(1.0).acos().to_degrees());
        }
        assert!(worst < 1.2, "worst angle {worst}°");
        // axes, both signs
        for g in [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 1.0, 0.0]] {
            let n = decode_normal(encode_normal(g)).unwrap();
            let dot: f32 = (0..3).map(|c| n[c] * g[c]).sum();
            assert!(dot.abs() > 0.9999, "{g:?} → {n:?}");
        }
        assert_eq!(encode_normal([0.0; 3]), ZERO_NORMAL);
        assert_eq!(encode_normal([f32::NAN, 0.0, 1.0]), ZERO_NORMAL);
    }

    #[test]
    fn branchless_encoder_equals_encode_normal() {
        let mut next = crate::testing::xorshift(0x9E3779B97F4A7C15);
        let mut r = move || (next() >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0;
        let special = [
            0.0,
            -0.0,
            1.0,
            -1.0,
            1e-16,
            -1e-16,
            1e-15,
            3.0e-16,
            0.5,
            -0.5,
            127.5,
            f32::MAX / 4.0,
            f32::MAX,
            f32::INFINITY,
            -f32::INFINITY,
            f32::NAN,
        ];
        for &a in &special {
            for &b in &special {
                for &c in &special {
                    assert_eq!(encode_normal_branchless([a, b, c]), encode_normal([a, b, c]), "{a} {b} {c}");
                }
            }
        }
        for _ in 0..200_000 {
            let g = [r(), r(), r()].map(|x| x * 300.0);
            assert_eq!(encode_normal_branchless(g), encode_normal(g), "{g:?}");
            let g = [r().round(), r().round() * 0.5, 0.0];
            assert_eq!(encode_normal_branchless(g), encode_normal(g), "{g:?}");
        }
    }

    #[test]
    fn normal_stack_codes_every_voxel_like_voxel_normal_for_any_shape() {
        for dims in [[2, 3, 4], [3, 1, 3], [9, 3, 3], [4, 4, 2], [1, 5, 5]] {
            let v = Volume::from_fn(dims, [0.7, 1.3, 0.4], |x, y, z| ((x * 5 + y * 11 + z * 3) % 7) as f32 * 1.5 - y as f32).unwrap();
            for axis in 0..3 {
                let s = SliceStack::new(&v, axis);
                let inv = v.spacing().map(|x| 1.0 / x);
                for pack in [false, true] {
                    let ns = NormalStack::with_packing(&s, v.spacing(), pack);
                    for k in 0..s.n[2] {
                        for j in 0..s.n[1] {
                            for i in 0..s.n[0] {
                                assert_eq!(ns.at(s.index(i, j, k)), voxel_normal(&s, i, j, k, inv), "{dims:?} axis {axis}");
                            }
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn normal_stack_codes_every_voxel_like_voxel_normal() {
        let v =
            Volume::from_fn([7, 6, 5], [0.5, 1.0, 2.0], |x, y, z| ((x * 7 + y * 13 + z * 29) % 11) as f32 - (x * z) as f32 * 0.3).unwrap();
        for axis in 0..3 {
            let s = SliceStack::new(&v, axis);
            let ns = NormalStack::new(&s, v.spacing());
            assert_eq!(ns.bytes(), 2 * 7 * 6 * 5);
            let inv = v.spacing().map(|x| 1.0 / x);
            for k in 0..s.n[2] {
                for j in 0..s.n[1] {
                    for i in 0..s.n[0] {
                        assert_eq!(ns.at(s.index(i, j, k)), voxel_normal(&s, i, j, k, inv));
                    }
                }
            }
            let b = s.index(2, 3, 1);
            assert_eq!(ns.corners(b), [ns.at(b), ns.at(b + 1), ns.at(b + s.n[0]), ns.at(b + s.n[0] + 1)]);
        }
    }

    /// The cubic normal at a voxel is the reference's cubic gradient
    /// ([`crate::accuracy::reference::ReferenceRenderer::gradient_cubic`],
    /// f64) evaluated there, borders and flat axes included; its code is
    /// the same from the stack of every principal axis, bit for bit; and
    /// [`StackNormals`] gives each reconstruction's codes.
    #[test]
    fn cubic_normal_is_the_b_spline_gradient_at_the_voxel_from_every_axis() {
        use crate::accuracy::reference::ReferenceRenderer;
        use crate::kernels::reconstruct::cubic_axis;
        for dims in [[7, 6, 5], [5, 4, 2], [4, 5, 1], [1, 3, 4]] {
            let sp = [0.6, 0.9, 2.5];
            let v =
                Volume::from_fn(dims, sp, |x, y, z| ((x * 7 + y * 13 + z * 29) % 11) as f32 * 3.0 - (x * z) as f32 * 0.7 + (y * y) as f32)
                    .unwrap();
            let model = ReferenceRenderer::new(&v);
            let inv = sp.map(|s| 1.0 / s);
            let stacks: Vec<SliceStack> = (0..3).map(|a| SliceStack::new(&v, a)).collect();
            for z in 0..dims[2] {
                for y in 0..dims[1] {
                    for x in 0..dims[0] {
                        let want = model.gradient_cubic(glam::DVec3::new(x as f64, y as f64, z as f64));
                        let mut codes = vec![];
                        for s in &stacks {
                            let p = s.perm();
                            let c = p.map(|a| [x, y, z][a]);
                            let g = cubic_voxel_gradient(s, c[0], c[1], c[2], cubic_axis(p));
                            for a in 0..3 {
                                let w = want[p[a]];
                                assert!(
                                    (g[a] as f64 - w).abs() <= 1e-5 * (1.0 + w.abs()),
                                    "{dims:?} ({x}, {y}, {z}) axis {}: {g:?} vs {want}",
                                    s.axis
                                );
                            }
                            let code = cubic_voxel_normal(s, c[0], c[1], c[2], inv);
                            assert_eq!(StackNormals::new(s, Reconstruction::Cubic).normal(c[0], c[1], c[2], inv), code);
                            assert_eq!(
                                StackNormals::new(s, Reconstruction::Linear).normal(c[0], c[1], c[2], inv),
                                voxel_normal(s, c[0], c[1], c[2], inv)
                            );
                            codes.push(code);
                        }
                        assert!(codes.iter().all(|&c| c == codes[0]), "{dims:?} ({x}, {y}, {z}): {codes:?}");
                    }
                }
            }
        }
    }

    /// Away from the volume's first and last slice the cubic normal's
    /// gradient is exact on a density linear in-plane and quadratic along z
    /// (the B-spline's derivative at a voxel is the central difference).
    #[test]
    fn cubic_normal_is_exact_on_quadratics_along_z() {
        let f = |x: usize, y: usize, z: usize| 3.0 * x as f32 - 2.0 * y as f32 + 0.25 * (z * z) as f32;
        let v = Volume::from_fn([5, 4, 6], [1.0, 1.0, 4.0], f).unwrap();
        for axis in 0..3 {
            let s = SliceStack::new(&v, axis);
            let p = s.perm();
            for z in 1..5 {
                for y in 0..4 {
                    for x in 0..5 {
                        let c = p.map(|a| [x, y, z][a]);
                        let g = cubic_voxel_gradient(&s, c[0], c[1], c[2], crate::kernels::reconstruct::cubic_axis(p));
                        let want = [3.0, -2.0, 0.5 * z as f32];
                        assert_eq!(
                            (0..3).map(|a| g[a]).collect::<Vec<_>>(),
                            (0..3).map(|a| want[p[a]]).collect::<Vec<_>>(),
                            "({x}, {y}, {z})"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn packed_stack_holds_every_density_exactly_and_the_same_codes() {
        // integers around a negative offset (CT-like), spanning exactly 65 535
        let f = |x: usize, y: usize, z: usize| ((x * 7919 + y * 104_729 + z * 1_299_709) % 4001) as f32 - 1024.0;
        let v = Volume::from_fn([7, 6, 5], [0.5, 1.0, 2.0], |x, y, z| if (x, y, z) == (3, 3, 3) { 64_511.0 } else { f(x, y, z) }).unwrap();
        for axis in 0..3 {
            let s = SliceStack::new(&v, axis);
            let ns = NormalStack::new(&s, v.spacing());
            let apart = NormalStack::with_packing(&s, v.spacing(), false);
            let p = ns.packed().expect("16-bit integer densities are packed");
            assert!(apart.packed().is_none());
            assert_eq!((ns.bytes(), apart.bytes()), (4 * 7 * 6 * 5, 2 * 7 * 6 * 5));
            assert!(ns.codes().is_empty());
            for k in 0..s.n[2] {
                for j in 0..s.n[1] - 1 {
                    for i in 0..s.n[0] - 1 {
                        let b = s.index(i, j, k);
                        assert_eq!(ns.at(b), apart.at(b));
                        assert_eq!(p.codes(b), apart.corners(b));
                        assert_eq!(ns.corners(b), apart.corners(b));
                        let want = [s.at(i, j, k), s.at(i + 1, j, k), s.at(i, j + 1, k), s.at(i + 1, j + 1, k)];
                        assert_eq!(p.densities(b).map(f32::to_bits), want.map(f32::to_bits), "({i}, {j}, {k})");
                    }
                }
            }
        }
    }

    #[test]
    fn cells_built_in_place_hold_the_stacks_densities_and_codes() {
        // 21 slices: waves of blocks of 8 with a partial last one, along z;
        // 1..=3 workers: waves of 1, 2 and 3 blocks
        let dims = [9, 7, 21];
        let n = 9 * 7 * 21;
        let h = |i: usize| (i * 2_654_435_761usize) >> 7;
        let vols = [
            VoxelData::U8((0..n).map(|i| (h(i) % 256) as u8).collect()),
            VoxelData::I16((0..n).map(|i| (h(i) % 4096) as i16 - 1024).collect()),
            VoxelData::U16((0..n).map(|i| (h(i) % 65536) as u16).collect()),
            VoxelData::I16((0..n).map(|i| if i == 5 { -32768 } else { (h(i) % 3000) as i16 }).collect()),
        ];
        for (t, data) in vols.into_iter().enumerate() {
            let v = Volume::new(dims, [0.7, 1.1, 1.9], data).unwrap();
            for (axis, recon) in (0..3).flat_map(|a| [(a, Reconstruction::Linear), (a, Reconstruction::Cubic)]) {
                let s = SliceStack::new(&v, axis);
                let want = NormalStack::try_with_codes(&s, v.spacing(), false, recon).unwrap();
                for threads in 1..=3 {
                    let got = NormalStack::try_cells(CellSource::Volume(&v), axis, threads)
                        .unwrap()
                        .expect("integer voxels")
                        .finish(v.spacing(), recon);
                    assert!(got.holds_voxels());
                    assert_eq!(got.packed().is_some(), t > 0, "16-bit scans pack in two u16, 8-bit ones in three bytes");
                    assert_eq!(got.bytes_cells().is_some(), t == 0);
                    assert_eq!(got.bytes(), n * if t == 0 { 3 } else { 4 });
                    // the volume comes back from them, voxel for voxel
                    assert_eq!(got.voxels_in_volume_order().unwrap().as_ref(), Some(v.data()), "type {t} axis {axis}");
                    // and so do the cells of every other axis, from these
                    for other in 0..3 {
                        let again =
                            NormalStack::try_cells(CellSource::Cells(&got), other, threads).unwrap().unwrap().finish(v.spacing(), recon);
                        assert_eq!(again.voxels_in_volume_order().unwrap().as_ref(), Some(v.data()), "type {t} axis {axis} to {other}");
                        assert_eq!((again.axis, again.n), (other, SliceStack::new(&v, other).n));
                    }
                    // every code, every row of densities and every cell a ray reads are the f32 stack's
                    for i in 0..n {
                        assert_eq!(got.at(i), want.at(i), "type {t} axis {axis} {recon:?} voxel {i}");
                    }
                    let (mut a, mut b) = (vec![0f32; s.n[0]], vec![0f32; s.n[0]]);
                    for k in 0..s.n[2] {
                        for j in 0..s.n[1] {
                            Densities::row(&got, j, k, &mut a);
                            Densities::row(&s, j, k, &mut b);
                            assert_eq!(a, b);
                        }
                        for j in 0..s.n[1] - 1 {
                            for i in 0..s.n[0] - 1 {
                                let bi = s.index(i, j, k);
                                let (dc, cc) = match (got.packed(), got.bytes_cells()) {
                                    (Some(c), _) => (c.densities(bi), c.codes(bi)),
                                    (_, Some(c)) => (c.densities(bi), c.codes(bi)),
                                    _ => unreachable!(),
                                };
                                assert_eq!(dc, s.cell_at(bi));
                                assert_eq!(cc, want.corners(bi));
                            }
                        }
                    }
                }
            }
        }
        // f32 voxels have no packed cells of their own type
        let f = Volume::from_fn([4, 4, 4], [1.0; 3], |x, _, _| x as f32).unwrap();
        assert!(NormalStack::try_cells(CellSource::Volume(&f), 0, 2).unwrap().is_none());
        // nor do cells built from an f32 stack (they may not hold every voxel)
        let packed = NormalStack::new(&SliceStack::new(&f, 1), f.spacing());
        assert!(!packed.holds_voxels() && NormalStack::try_cells(CellSource::Cells(&packed), 0, 2).unwrap().is_none());
    }

    #[test]
    fn only_exact_16_bit_integer_ranges_pack() {
        assert_eq!(packing_offset(&[3.0, 0.0, 65_535.0]), Some(0.0));
        assert_eq!(packing_offset(&[-1024.0, 3071.0]), Some(-1024.0));
        assert_eq!(packing_offset(&[0.0, 65_536.0]), None, "17 bits");
        assert_eq!(packing_offset(&[0.0, 0.5]), None, "not an integer");
        assert_eq!(packing_offset(&[2.0e7, 2.0e7 + 2.0]), None, "beyond exact f32 integers");
        assert_eq!(packing_offset(&[-2.0e7, -2.0e7 + 2.0]), None, "beyond exact f32 integers");
        assert_eq!(packing_offset(&[1.0, f32::NAN]), None);
        assert_eq!(packing_offset(&[f32::INFINITY]), None);
        assert_eq!(packing_offset(&[]), None);
        // more than one task's chunk: the reduction across chunks
        let mut big = vec![7.0f32; 3 * PACK_CHUNK + 5];
        big[2 * PACK_CHUNK + 1] = -9.0;
        assert_eq!(packing_offset(&big), Some(-9.0));
        big[PACK_CHUNK + 3] = 0.25;
        assert_eq!(packing_offset(&big), None);
    }
}
