//! One volume as bricks, each rendered on its own and composited sort-last:
//! the frame a distributed (MPI) run makes, with no network in it.
//!
//! - **Split** ([`split`]): a k-d split of the volume's voxels over all three
//!   axes into `n` bricks of nearly equal size (the longest extent halved,
//!   in proportion to the bricks each side gets). A brick *owns* a box of
//!   voxel indices; the owned boxes tile the volume, and which slices or
//!   cells a brick composites follows from its box whatever the view
//!   ([`crate::render::BrickView`]), so no data moves when the view turns.
//! - **Ghosts** ([`Brick::ghosted`]): a brick holds [`GHOST`] voxels more on
//!   every side (clipped to the volume): the second voxel of its last cell,
//!   the sample a hit is refined against, and the central differences of
//!   the normals at all of them.
//! - **Render** ([`crate::render::Renderer::render_brick`]): each brick's
//!   renderer samples exactly where one renderer of the whole volume would
//!   and composites only its own samples, into its part of the whole
//!   volume's intermediate grid ([`Partial`]: the rectangle it covers).
//! - **Composite** ([`Compositor`]): the partial images "over" each other in
//!   the view's brick order ([`order`]: a front-to-back walk of the k-d
//!   tree), then the one warp of the whole volume's plan. An iso hit is
//!   opaque and a miss transparent, so iso pixels are the one renderer's to
//!   the bit; blended pixels round their partial sums differently (and a
//!   brick's early ray termination stops at its own opacity, the compositor
//!   at the accumulated one).
//!
//! [`render_split`] runs all of it in one process (what the tests hold
//! against one renderer); the command line's `--distributed` runs one brick
//! per MPI rank.

use rayon::prelude::*;

use crate::classify::presets::Tissue;
use crate::composite::{Intermediate, Mode, Rect, composite_premultiplied, terminated};
use crate::data::stats::ValueStats;
use crate::data::volume::{Volume, VoxelData};
use crate::error::{Error, Result};
use crate::render::{BrickView, Renderer, Settings};
use crate::view::plan::{FramePlan, Grid};
use crate::view::{Camera, Factorization};
use crate::warp::{Canvas, Texel, warp};

/// Pixels per parallel task of a partial image's conversions.
const ROWS: usize = 1 << 14;

/// Voxels a brick holds beyond its owned box on every side (see the module
/// documentation): a cell's second voxel (+1), the sample before the first
/// owned one (±1) and the central differences of its normals (±1).
pub const GHOST: usize = 3;

/// One brick: the voxels it owns and the voxels it holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Brick {
    /// The owned voxels `[lo, hi)` along x, y, z.
    pub owned: [[usize; 2]; 3],
    /// The held voxels: the owned ones and up to [`GHOST`] more each side.
    pub ghosted: [[usize; 2]; 3],
}

impl Brick {
    fn new(owned: [[usize; 2]; 3], dims: [usize; 3]) -> Brick {
        let ghosted = [0, 1, 2].map(|a| [owned[a][0].saturating_sub(GHOST), (owned[a][1] + GHOST).min(dims[a])]);
        Brick { owned, ghosted }
    }

    /// The held voxels' size.
    pub fn size(&self) -> [usize; 3] {
        self.ghosted.map(|[lo, hi]| hi - lo)
    }

    /// The brick as [`crate::render::Renderer::render_brick`] takes it, in a volume of `dims`.
    pub fn view(&self, dims: [usize; 3]) -> BrickView {
        BrickView { global: dims, origin: self.ghosted.map(|g| g[0]), owned: self.owned }
    }

    /// The held voxels of `volume` as a volume of their own, classified as
    /// `volume` is (its statistics: [`Volume::with_stats`]).
    pub fn extract(&self, volume: &Volume) -> Result<Volume> {
        let [nx, ny, _] = volume.dims();
        let [[x0, x1], [y0, y1], [z0, z1]] = self.ghosted;
        fn copy<T: Copy>(v: &[T], nx: usize, ny: usize, [x0, x1, y0, y1, z0, z1]: [usize; 6]) -> Vec<T> {
            let mut out = Vec::with_capacity((x1 - x0) * (y1 - y0) * (z1 - z0));
            for z in z0..z1 {
                for y in y0..y1 {
                    let at = (z * ny + y) * nx;
                    out.extend_from_slice(&v[at + x0..at + x1]);
                }
            }
            out
        }
        let r = [x0, x1, y0, y1, z0, z1];
        let data = match volume.data() {
            VoxelData::U8(v) => VoxelData::U8(copy(v, nx, ny, r)),
            VoxelData::U16(v) => VoxelData::U16(copy(v, nx, ny, r)),
            VoxelData::I16(v) => VoxelData::I16(copy(v, nx, ny, r)),
            VoxelData::F32(v) => VoxelData::F32(copy(v, nx, ny, r)),
        };
        Ok(Volume::new(self.size(), volume.spacing(), data)?.with_stats(volume.stats().clone()))
    }
}

/// The whole volume's value statistics from its bricks' (what makes every
/// brick classify as one renderer of the whole volume does, the tissue
/// presets included): each brick computes [`Brick::owned_stats`] of its
/// held voxels, the statistics are merged ([`ValueStats::merge`]); for f32
/// voxels, whose statistics hold no counts, each brick then computes
/// [`Brick::owned_histogram`] over the range [`preset_histogram_range`]
/// names, and the sum goes with the merged statistics
/// ([`ValueStats::with_histogram`]).
impl Brick {
    /// The statistics of the owned voxels of `held` (this brick's held voxels).
    pub fn owned_stats(&self, held: &Volume) -> Result<ValueStats> {
        Ok(ValueStats::of(self.owned_part(held)?.data()))
    }

    /// The histogram of the owned voxels of `held` that the presets read
    /// (`bins` over `[lo, hi]`, [`preset_histogram_range`]).
    pub fn owned_histogram(&self, held: &Volume, bins: usize, [lo, hi]: [f32; 2]) -> Result<Vec<u64>> {
        let own = self.owned_part(held)?;
        Ok(ValueStats::of(own.data()).histogram_in(own.data(), bins, lo, hi))
    }

    /// The owned voxels of `held`, as a volume of their own.
    fn owned_part(&self, held: &Volume) -> Result<Volume> {
        let local = [0, 1, 2].map(|a| [self.owned[a][0] - self.ghosted[a][0], self.owned[a][1] - self.ghosted[a][0]]);
        Brick { owned: local, ghosted: local }.extract(held)
    }
}

/// The histogram the tissue presets read of a volume whose statistics are
/// `whole` (bins and range), when the statistics cannot answer it without
/// the voxels (f32 voxels); `None` when they can.
pub fn preset_histogram_range(held: &Volume, whole: &ValueStats) -> Option<(usize, [f32; 2])> {
    if whole.has_counts() {
        return None;
    }
    let (lo, hi) = crate::classify::presets::data_range(&held.clone().with_stats(whole.clone())).working();
    Some((crate::classify::presets::HISTOGRAM_BINS, [lo, hi]))
}

/// The k-d tree of a split: a brick, or two halves along an axis.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Tree {
    Leaf(usize),
    Split { axis: usize, low: Box<Tree>, high: Box<Tree> },
}

/// Splits a volume of `dims` into `n` bricks (see the module
/// documentation). Brick `i` is rank `i`'s; the tree orders them per view.
pub fn split(dims: [usize; 3], n: usize) -> Result<(Vec<Brick>, Tree)> {
    if n == 0 {
        return Err(Error::value("bricks", "need at least one"));
    }
    fn go(owned: [[usize; 2]; 3], n: usize, dims: [usize; 3], out: &mut Vec<Brick>) -> Result<Tree> {
        if n == 1 {
            out.push(Brick::new(owned, dims));
            return Ok(Tree::Leaf(out.len() - 1));
        }
        // the longest extent (ties: z, then y, then x), in proportion to the bricks each side
        let axis = [2, 1, 0].into_iter().max_by_key(|&a| owned[a][1] - owned[a][0]).expect("three axes");
        let [lo, hi] = owned[axis];
        let nl = n / 2;
        let at = lo + (hi - lo) * nl / n;
        if at == lo || at == hi || hi - lo < 2 {
            return Err(Error::value("bricks", format!("{dims:?} voxels are too few for {n} bricks")));
        }
        let (mut a, mut b) = (owned, owned);
        a[axis][1] = at;
        b[axis][0] = at;
        let low = Box::new(go(a, nl, dims, out)?);
        let high = Box::new(go(b, n - nl, dims, out)?);
        Ok(Tree::Split { axis, low, high })
    }
    let mut out = Vec::with_capacity(n);
    let tree = go(dims.map(|d| [0, d]), n, dims, &mut out)?;
    Ok((out, tree))
}

/// The direction each ray of view `f` walks along the volume's axes x, y,
/// z: +1 towards higher indices, −1 lower, 0 not at all (an in-slice axis
/// without shear).
pub fn walk_directions(f: &Factorization) -> [i32; 3] {
    let k = if f.ascending { 1 } else { -1 };
    let mut d = [0; 3];
    d[f.perm[2]] = k;
    for a in 0..2 {
        d[f.perm[a]] = if f.shear[a] > 0.0 {
            k
        } else if f.shear[a] < 0.0 {
            -k
        } else {
            0
        };
    }
    d
}

/// The bricks of `tree` front to back for rays walking `dirs`
/// ([`walk_directions`]): every ray meets them in this order.
pub fn order(tree: &Tree, dirs: [i32; 3]) -> Vec<usize> {
    fn go(t: &Tree, dirs: [i32; 3], out: &mut Vec<usize>) {
        match t {
            Tree::Leaf(i) => out.push(*i),
            Tree::Split { axis, low, high } => {
                let (a, b) = if dirs[*axis] >= 0 { (low, high) } else { (high, low) };
                go(a, dirs, out);
                go(b, dirs, out);
            }
        }
    }
    let mut out = vec![];
    go(tree, dirs, &mut out);
    out
}

/// A brick's partial image: the rectangle of the whole volume's
/// intermediate grid it covers, and its premultiplied RGBA there (row-major).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Partial {
    pub rect: Option<Rect>,
    pub rgba: Vec<[f32; 4]>,
}

impl Partial {
    /// The part of `inter` a brick rendered ([`crate::render::BrickFrame`]'s
    /// rectangle and offset), in the whole volume's grid of `size`. A
    /// rectangle may reach past that grid (a super-cell mask's occupied
    /// rectangle is coarse): the rays there miss the volume, and are left out.
    pub fn of(inter: &Intermediate, rect: Option<Rect>, offset: [i64; 2], size: [usize; 2]) -> Result<Partial> {
        let Some(r) = rect else { return Ok(Partial::default()) };
        let clip =
            |lo: usize, hi: usize, off: i64, n: usize| -> [i64; 2] { [(lo as i64 + off).max(0), (hi as i64 + off).min(n as i64 - 1)] };
        let ([p0, p1], [q0, q1]) = (clip(r.p0, r.p1, offset[0], size[0]), clip(r.q0, r.q1, offset[1], size[1]));
        let w = inter.size[0];
        // what is left out holds nothing
        let inside = |p: usize, q: usize| {
            let (gp, gq) = (p as i64 + offset[0], q as i64 + offset[1]);
            (p0..=p1).contains(&gp) && (q0..=q1).contains(&gq)
        };
        let whole =
            [p0, p1, q0, q1] == [r.p0 as i64 + offset[0], r.p1 as i64 + offset[0], r.q0 as i64 + offset[1], r.q1 as i64 + offset[1]];
        for q in (r.q0..=r.q1).filter(|_| !whole) {
            for p in r.p0..=r.p1 {
                if !inside(p, q) && inter.rgba[q * w + p] != [0.0; 4] {
                    return Err(Error::Other(format!("internal: a brick's pixel ({p}, {q}) + {offset:?} is outside the {size:?} grid")));
                }
            }
        }
        if p0 > p1 || q0 > q1 {
            return Ok(Partial::default());
        }
        let mut rgba = Vec::with_capacity(((p1 - p0 + 1) * (q1 - q0 + 1)) as usize);
        for q in q0..=q1 {
            let row = (q - offset[1]) as usize * w;
            rgba.extend_from_slice(&inter.rgba[row + (p0 - offset[0]) as usize..=row + (p1 - offset[0]) as usize]);
        }
        let rect = Rect { p0: p0 as usize, p1: p1 as usize, q0: q0 as usize, q1: q1 as usize };
        Ok(Partial { rect: Some(rect), rgba })
    }

    /// Bytes this partial image takes on the wire ([`Partial::to_bytes`]).
    pub fn wire_bytes(&self) -> usize {
        16 + self.rgba.len() * 16
    }

    /// The partial image as bytes: the rectangle (four u32, `p1 < p0` for
    /// none) and the pixels (f32, little-endian).
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut b = vec![0u8; self.wire_bytes()];
        let r = self.rect.map_or([1, 0, 1, 0], |r| [r.p0, r.p1, r.q0, r.q1].map(|x| x as u32));
        for (d, x) in b.chunks_exact_mut(4).zip(r) {
            d.copy_from_slice(&x.to_le_bytes());
        }
        b[16..].par_chunks_mut(16 * ROWS).zip(self.rgba.par_chunks(ROWS)).for_each(|(d, px)| {
            for (d, px) in d.chunks_exact_mut(16).zip(px) {
                for (d, x) in d.chunks_exact_mut(4).zip(px) {
                    d.copy_from_slice(&x.to_le_bytes());
                }
            }
        });
        b
    }

    /// A partial image from [`Partial::to_bytes`].
    pub fn from_bytes(b: &[u8]) -> Result<Partial> {
        let bad = || Error::Other(format!("internal: a partial image of {} bytes is malformed", b.len()));
        if b.len() < 16 || !(b.len() - 16).is_multiple_of(16) {
            return Err(bad());
        }
        let u = |i: usize| u32::from_le_bytes(b[4 * i..4 * i + 4].try_into().expect("4 bytes")) as usize;
        let (p0, p1, q0, q1) = (u(0), u(1), u(2), u(3));
        let mut rgba = vec![[0f32; 4]; (b.len() - 16) / 16];
        rgba.par_chunks_mut(ROWS).zip(b[16..].par_chunks(16 * ROWS)).for_each(|(px, c)| {
            for (px, c) in px.iter_mut().zip(c.chunks_exact(16)) {
                for (x, c) in px.iter_mut().zip(c.chunks_exact(4)) {
                    *x = f32::from_le_bytes([c[0], c[1], c[2], c[3]]);
                }
            }
        });
        if p1 < p0 || q1 < q0 {
            return if rgba.is_empty() { Ok(Partial::default()) } else { Err(bad()) };
        }
        if rgba.len() != (p1 - p0 + 1) * (q1 - q0 + 1) {
            return Err(bad());
        }
        Ok(Partial { rect: Some(Rect { p0, p1, q0, q1 }), rgba })
    }
}

/// The whole volume's frame: its plan (grid and warp) and the bricks'
/// order, the partial images composited into its intermediate image.
pub struct Compositor {
    plan: FramePlan,
    inter: Intermediate,
    order: Vec<usize>,
    ert: f32,
}

impl Compositor {
    /// The frame of `camera` over a volume of `dims` and `spacing` split as
    /// `tree`, for a renderer of `settings` (parallel projection).
    pub fn new(camera: &Camera, dims: [usize; 3], spacing: [f32; 3], tree: &Tree, settings: &Settings) -> Result<Compositor> {
        let f = factorization(camera, dims, spacing, settings)?;
        let plan = FramePlan::parallel(&f, spacing);
        let mut inter = Intermediate::default();
        inter.prepare(plan.grid.size);
        let ert = if settings.mode == Mode::Iso && settings.method.is_raycast() { 1.0 } else { settings.ert };
        Ok(Compositor { order: order(tree, walk_directions(&f)), plan, inter, ert })
    }

    /// Starts the next frame (what [`Compositor::new`] makes), reusing the
    /// image: only the last frame's rectangle is cleared.
    pub fn reset(&mut self, camera: &Camera, dims: [usize; 3], spacing: [f32; 3], tree: &Tree, settings: &Settings) -> Result<()> {
        let f = factorization(camera, dims, spacing, settings)?;
        self.plan.set_parallel(&f, spacing);
        if let Some(r) = self.inter.valid.filter(|_| self.inter.size == self.plan.grid.size) {
            let w = self.inter.size[0];
            for q in r.q0..=r.q1 {
                self.inter.rgba[q * w + r.p0..=q * w + r.p1].fill([0.0; 4]);
            }
        } else {
            self.inter = Intermediate::default();
        }
        self.inter.prepare(self.plan.grid.size);
        self.order = order(tree, walk_directions(&f));
        self.ert = if settings.mode == Mode::Iso && settings.method.is_raycast() { 1.0 } else { settings.ert };
        Ok(())
    }

    /// The bricks front to back.
    pub fn order(&self) -> &[usize] {
        &self.order
    }

    /// The whole volume's intermediate grid size.
    pub fn grid(&self) -> [usize; 2] {
        self.plan.grid.size
    }

    /// Composites `part` behind everything composited so far (call in
    /// [`Compositor::order`]). A pixel already at the early-termination
    /// opacity takes nothing more.
    pub fn add(&mut self, part: &Partial) {
        let Some(r) = part.rect else { return };
        let w = self.inter.size[0];
        let rw = r.p1 - r.p0 + 1;
        let ert = self.ert;
        let rows = self.inter.rgba[r.q0 * w..(r.q1 + 1) * w].par_chunks_mut(w);
        rows.zip(part.rgba.par_chunks(rw)).for_each(|(row, src)| {
            for (acc, s) in row[r.p0..=r.p1].iter_mut().zip(src) {
                if !terminated(acc[3], ert) {
                    composite_premultiplied(acc, *s);
                }
            }
        });
        self.inter.valid = Rect::union(self.inter.valid, Some(r));
    }

    /// Warps the composited image into `out` (of the camera's size).
    pub fn finish<T: Texel>(&mut self, camera: &Camera, out: &mut Canvas<T>) {
        let valid = self.inter.valid;
        self.inter.seal(valid);
        out.prepare(camera.size[0], camera.size[1]);
        warp(&self.inter, &self.plan, out);
    }
}

/// The factorization of `camera`'s parallel view of a volume of `dims` and
/// `spacing` that a renderer of `settings` makes.
fn factorization(camera: &Camera, dims: [usize; 3], spacing: [f32; 3], settings: &Settings) -> Result<Factorization> {
    let perms = [0, 1, 2].map(|a| {
        if settings.rle_reuse && settings.method.is_rle() { crate::view::reuse_permutation(a) } else { crate::view::permutation(a) }
    });
    Factorization::with_permutations(camera, dims, spacing, perms)
}

/// The size of the whole volume's intermediate grid under `camera` (what
/// [`Partial::of`] places a brick's image in), without a [`Compositor`].
pub fn grid_of(camera: &Camera, dims: [usize; 3], spacing: [f32; 3], settings: &Settings) -> Result<[usize; 2]> {
    let f = factorization(camera, dims, spacing, settings)?;
    Ok(Grid::parallel([f.n[0].saturating_sub(1), f.n[1].saturating_sub(1)], f.n[2]).size)
}

/// Renders `camera`'s view of `volume` as `n` bricks in this process, one
/// renderer each (classified by `tissues`, tissue `tissue` selected), and
/// composites them into `out`: what `n` ranks render together.
pub fn render_split<T: Texel>(
    volume: &Volume,
    tissues: &[Tissue],
    tissue: usize,
    settings: Settings,
    camera: &Camera,
    n: usize,
    out: &mut Canvas<T>,
) -> Result<()> {
    let dims = volume.dims();
    let (bricks, tree) = split(dims, n)?;
    let mut comp = Compositor::new(camera, dims, volume.spacing(), &tree, &settings)?;
    let mut parts = vec![Partial::default(); n];
    for (i, b) in bricks.iter().enumerate() {
        let mut r = Renderer::with_tissues(b.extract(volume)?, tissues, settings)?;
        r.select_tissue(tissue)?;
        let f = r.render_brick(camera, &b.view(dims))?;
        parts[i] = Partial::of(r.intermediate(), f.rect, f.offset, comp.grid())?;
    }
    for i in comp.order().to_vec() {
        comp.add(&parts[i]);
    }
    comp.finish(camera, out);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_split_tiles_the_volume_and_every_brick_is_in_each_order() {
        for n in 1..=9 {
            let dims = [37, 20, 51];
            let (bricks, tree) = split(dims, n).unwrap();
            assert_eq!(bricks.len(), n);
            let mut count = vec![0u8; dims.iter().product()];
            for b in &bricks {
                for z in b.owned[2][0]..b.owned[2][1] {
                    for y in b.owned[1][0]..b.owned[1][1] {
                        for x in b.owned[0][0]..b.owned[0][1] {
                            count[(z * dims[1] + y) * dims[0] + x] += 1;
                        }
                    }
                }
            }
            assert!(count.iter().all(|&c| c == 1), "{n} bricks do not tile the volume");
            let mut o = order(&tree, [1, -1, 0]);
            o.sort();
            assert_eq!(o, (0..n).collect::<Vec<_>>());
        }
        assert!(split([1, 1, 2], 3).is_err());
    }

    #[test]
    fn a_partial_image_survives_its_bytes() {
        let p = Partial { rect: Some(Rect { p0: 2, p1: 3, q0: 5, q1: 5 }), rgba: vec![[0.5, 0.25, 0.0, 1.0], [0.0, 0.0, 0.1, 0.2]] };
        assert_eq!(Partial::from_bytes(&p.to_bytes()).unwrap(), p);
        assert_eq!(Partial::from_bytes(&Partial::default().to_bytes()).unwrap(), Partial::default());
        assert!(Partial::from_bytes(&[0; 20]).is_err());
    }
}
