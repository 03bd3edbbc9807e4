//! One brick of a larger volume rendered into its share of the larger
//! volume's intermediate image: what a distributed frame asks of each brick
//! ([`Renderer::render_brick`]).
//!
//! The renderer holds the brick (its voxels and a ghost layer around them);
//! its plan is the brick's own parallel plan with every slice's map replaced
//! by the larger volume's ([`FramePlan::place_in`]), so each sample is the
//! larger volume's sample at the same place, and per-pixel ray limits keep
//! to each ray the samples whose cell the brick *owns*. Owned boxes tile the
//! larger volume, so every sample of every ray is composited by exactly one
//! brick. In iso mode a raycast ray also reads the sample just before its
//! first owned one (the one a hit is refined against): a hit there belongs
//! to the brick in front, whose partial image covers this one's.

use super::{FrameStats, Lattice, Renderer};

use crate::composite::{Intermediate, Mode, Rect};
use crate::error::{Error, Result};
use crate::view::plan::{FramePlan, RayLimits};
use crate::view::{Camera, Factorization};

/// Where a brick sits in the larger volume (voxel indices along x, y, z).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BrickView {
    /// The larger volume's size.
    pub global: [usize; 3],
    /// The larger volume's voxel at the brick's voxel `(0, 0, 0)`.
    pub origin: [usize; 3],
    /// The voxels `[lo, hi)` per axis the brick owns: along the principal
    /// axis, the slices whose samples it composites; along the other two,
    /// the cells (a cell `c` spans voxels `c` and `c + 1`).
    pub owned: [[usize; 2]; 3],
}

/// What [`Renderer::render_brick`] rendered.
#[derive(Clone, Copy, Debug, Default)]
pub struct BrickFrame {
    pub stats: FrameStats,
    /// Brick pixel `(p, q)` is the larger plan's pixel `(p, q) + offset`.
    pub offset: [i64; 2],
    /// The pixels of the brick's intermediate image written this frame.
    pub rect: Option<Rect>,
}

impl Renderer {
    /// Renders this renderer's volume as the brick `b` of a larger volume
    /// under parallel view `camera`, into [`Renderer::intermediate`] (no
    /// warp): the samples are the larger volume's
    /// ([`FramePlan::place_in`]), the brick composites only those it owns
    /// (see the module documentation), and [`BrickFrame::offset`] places the
    /// image in the larger volume's intermediate image. The renderer's
    /// volume must hold the owned cells, the voxels they read and the ghost
    /// layer their refinement and normals read: see
    /// [`crate::bricks::Brick::ghosted`].
    ///
    /// Parallel projection, the cartesian grid, quality 1, no Deluxe I or M,
    /// no clip region, geometry or focus: anything else is an error.
    pub fn render_brick(&mut self, camera: &Camera, b: &BrickView) -> Result<BrickFrame> {
        let unsupported = |what: &str| Err(Error::value("distributed frame", format!("{what} is not supported across bricks")));
        if self.frame.projection.is_perspective() {
            return unsupported("a perspective projection");
        }
        if self.settings.lattice == Lattice::Bcc {
            return unsupported("the BCC grid");
        }
        if self.frame.limiter.is_some() || self.classes.focus.is_some() {
            return unsupported("a clip region, geometry or focus");
        }
        if self.frame.quality != 1.0 || self.settings.deluxe.intermediate || self.settings.deluxe.matched {
            return unsupported("--quality other than 1, or Deluxe I or M");
        }
        let (dims, spacing) = (self.volume.dims(), self.volume.spacing());
        for a in 0..3 {
            let [lo, hi] = b.owned[a];
            if !(b.origin[a] <= lo && lo <= hi && hi <= b.origin[a] + dims[a] && b.origin[a] + dims[a] <= b.global[a]) {
                return Err(Error::value("brick", format!("{b:?} does not fit a brick of {dims:?} voxels")));
            }
        }
        let perms = [0, 1, 2].map(|a| self.axis_perm(a));
        let fg = Factorization::with_permutations(camera, b.global, spacing, perms)?;
        let f = Factorization::with_permutations(camera, dims, spacing, perms)?;
        if (f.axis, f.ascending, f.perm) != (fg.axis, fg.ascending, fg.perm) {
            return Err(Error::Other("internal: a brick's factorization disagrees with its volume's".into()));
        }
        let mut stats = FrameStats { axis: f.axis, ..Default::default() };
        stats.build_ms = self.ensure_axis(f.axis)?;
        let mut plan = self.frame.plan.take().unwrap_or_else(|| FramePlan::parallel(&f, spacing));
        let limits = plan.take_limits();
        plan.take_focus();
        plan.set_parallel(&f, spacing);
        let p = f.perm;
        let origin = [0, 1, 2].map(|c| b.origin[p[c]]);
        let offset = plan.place_in(&fg, origin);
        if let Err(e) = self.finish_plan(&mut plan, None, None) {
            self.frame.plan = Some(plan);
            return Err(e);
        }
        // ownership: the slices of each ray whose cell lies in the owned box
        let own = [0, 1, 2].map(|c| [b.owned[p[c]][0] as i64 - origin[c] as i64, b.owned[p[c]][1] as i64 - origin[c] as i64]);
        let before = self.settings.mode == Mode::Iso && self.settings.method.is_raycast();
        let ascending = f.ascending;
        let owner = |plan: &FramePlan, limits: &mut RayLimits| {
            use rayon::prelude::*;
            let pad = plan.grid.pad as i64;
            let nk = plan.slices() as i64;
            let ks = [own[2][0].max(0), (own[2][1] - 1).min(nk - 1)];
            // per grid column (row), the slices whose cell along i (j) is owned:
            // the ray's cell at slice k is monotone in k
            let along = |a: usize| -> Vec<Option<[i64; 2]>> {
                (0..plan.grid.size[a] as i64).map(|x| inside(ks, own[a], |k| x - pad + plan.maps[k as usize].floor[a] as i64)).collect()
            };
            let (ti, tj) = (along(0), along(1));
            limits.par_rows_mut().zip(tj.par_iter()).for_each(|(row, kj)| {
                for (l, ki) in row.iter_mut().zip(&ti) {
                    *l = match (ki, kj) {
                        (Some([a0, a1]), Some([b0, b1])) if a0.max(b0) <= a1.min(b1) => {
                            let (k0, k1) = (*a0.max(b0), *a1.min(b1));
                            match (before, ascending) {
                                (true, true) => [(k0 - 1).max(0) as u32, k1 as u32],
                                (true, false) => [k0 as u32, (k1 + 1).min(nk - 1) as u32],
                                _ => [k0 as u32, k1 as u32],
                            }
                        }
                        _ => [1, 0],
                    };
                }
            });
        };
        plan.apply_limiter(&owner, limits.unwrap_or_default());
        self.pyramids.last_split = false;
        let result = self.composite_plan(&plan, &mut stats, |_: &Intermediate| {});
        let rect = self.inter.valid;
        self.frame.plan = Some(plan);
        // the intermediate image is the brick's now: no later frame may be skipped as unchanged
        self.frame.last_frame = None;
        result?;
        Ok(BrickFrame { stats, offset, rect })
    }
}

/// The slices `k` in `[k0, k1]` whose cell `c(k)` (monotone in `k`) lies in
/// `[lo, hi)`, as one interval (`None`: none).
fn inside([k0, k1]: [i64; 2], [lo, hi]: [i64; 2], c: impl Fn(i64) -> i64) -> Option<[i64; 2]> {
    if k0 > k1 {
        return None;
    }
    // the first k in [a, b] with pred(k), pred false then true over [a, b]
    let first = |a: i64, b: i64, pred: &dyn Fn(i64) -> bool| {
        let (mut a, mut b) = (a, b + 1);
        while a < b {
            let m = a + (b - a) / 2;
            if pred(m) { b = m } else { a = m + 1 }
        }
        a
    };
    let (a, b) = if c(k0) <= c(k1) {
        (first(k0, k1, &|k| c(k) >= lo), first(k0, k1, &|k| c(k) >= hi) - 1)
    } else {
        (first(k0, k1, &|k| c(k) < hi), first(k0, k1, &|k| c(k) < lo) - 1)
    };
    (a <= b).then_some([a, b])
}

#[cfg(test)]
mod tests {
    use super::inside;

    #[test]
    fn the_owned_slices_of_a_monotone_ray_are_found_exactly() {
        for step in [-3i64, -1, 0, 1, 2] {
            for off in -8..8 {
                for (lo, hi) in [(0, 4), (2, 3), (-5, 20), (7, 9)] {
                    let c = |k: i64| off + step * k / 2;
                    let want: Vec<i64> = (0..=9).filter(|&k| (lo..hi).contains(&c(k))).collect();
                    let got = inside([0, 9], [lo, hi], c).map_or(vec![], |[a, b]| (a..=b).collect());
                    assert_eq!(got, want, "step {step} off {off} [{lo}, {hi})");
                }
            }
        }
    }
}
