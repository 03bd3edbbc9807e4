//! One principal axis's run-length encoding ([`RleVolume`]): per scanline,
//! `(transparent, non-transparent)` run pairs and the stored voxels, the
//! per-slice bounding boxes and per-scanline extents, and the run `Cursor`
//! the slice traversal walks two scanlines with.

use std::sync::Arc;

use rayon::prelude::*;

use super::preclass::{BRIDGE, BRIDGE_NORMAL, PostVisible, Preclass, RleVoxel, VoxelSource};
use crate::data::slices::{SliceStack, prefetch};
use crate::view::plan::FramePlan;
use crate::view::plan::Rect;

/// End of a scanline for the run cursors.
pub(crate) const INF: u32 = u32::MAX;

/// One principal axis of the volume, run-length encoded: a pointer table over
/// `Scanlines` it may share with another axis.
///
/// Two axes whose permutations run their scanlines along the same object axis
/// ([`crate::view::reuse_permutation`]: x = (y, z, x) and z = (y, x, z)) hold
/// the same scanlines, in another order: scanline `(j, k)` of one is scanline
/// `(k, j)` of the other. [`RleVolume::transposed`] makes the second axis's
/// encoding from the first's without encoding anything (Sweeney & Mueller's
/// re-use of RLE runs, §3.1): the runs and voxels are shared, and the second
/// keeps only its pointer table (which shared scanline each of its own is),
/// its per-scanline extents and its per-slice boxes.
#[derive(Clone, Debug)]
pub struct RleVolume {
    /// Principal axis (0 = x, 1 = y, 2 = z).
    pub axis: usize,
    /// Sizes along `(i, j, k)`.
    pub n: [usize; 3],
    /// Object axes of `(i, j, k)` (the permutation of the stack it was built
    /// from; `perm[2] == axis`).
    pub perm: [usize; 3],
    /// The runs and voxels, in the order of the axis that encoded them.
    lines: Scanlines,
    /// The pointer table: scanline `s = j + nj·k` is `lines`' scanline
    /// `map[s]`; empty for the axis that encoded them (the identity).
    map: Vec<u32>,
    /// Per scanline, the first and last column of its non-transparent voxels
    /// (`[u16::MAX, 0]` when it has none): lets a row pair that has nothing to do
    /// be rejected without walking its runs.
    pub(crate) extent: Vec<[u16; 2]>,
    /// Per slice, the bounding box `[i0, i1, j0, j1]` (inclusive) of its
    /// non-transparent voxels; `i0 > i1` when the slice is empty.
    pub(crate) bbox: Vec<[u32; 4]>,
}

/// The scanlines of one encoding, in the order of the axis that encoded them
/// (shared with the axis that re-uses them). Each array is an `Arc<Vec<T>>`:
/// the encoder's vector moves in without a second copy of the encoding (an
/// `Arc<[T]>` would copy it), for one more pointer to follow where a
/// scanline's cursor is set up (no measurable change in frame time).
#[derive(Clone, Debug)]
struct Scanlines {
    /// Run lengths: per scanline `(transparent, non-transparent)` pairs.
    runs: Arc<Vec<u16>>,
    /// Scanline `t` owns `runs[scan_runs[t]..scan_runs[t + 1]]` ...
    scan_runs: Arc<Vec<u32>>,
    /// ... and `voxels[scan_voxels[t]..scan_voxels[t + 1]]`.
    scan_voxels: Arc<Vec<u32>>,
    /// The non-transparent voxels, scanline by scanline, in `i` order.
    voxels: Arc<Vec<RleVoxel>>,
}

impl Scanlines {
    fn bytes(&self) -> usize {
        self.runs.len() * 2 + (self.scan_runs.len() + self.scan_voxels.len()) * 4 + self.voxels.len() * 4
    }
}

/// `v` shared, its spare capacity given back (in place for a large one).
fn owned<T>(mut v: Vec<T>) -> Arc<Vec<T>> {
    v.shrink_to_fit();
    Arc::new(v)
}

/// One slice's part of an encoding (built in parallel, then concatenated).
struct SliceRuns {
    runs: Vec<u16>,
    voxels: Vec<RleVoxel>,
    /// Per scanline: end of its runs and voxels (relative to the slice).
    ends: Vec<(u32, u32)>,
    extent: Vec<[u16; 2]>,
    bbox: [u32; 4],
}

/// Slices the encoder encodes before appending them to the whole (at least;
/// four a thread on more threads).
const ENCODE_GROUP: usize = 32;

impl RleVolume {
    /// Encodes `src` (one principal axis's slices: a [`SliceStack`], or the
    /// interleaved slices of a BCC grid) under classification `pre`, in
    /// parallel over slices (on the current rayon pool).
    pub fn encode<S: VoxelSource + ?Sized>(src: &S, pre: &Preclass) -> Self {
        Self::encode_with(src, pre, None)
    }

    /// The post-classified encoding (Deluxe P): a voxel is stored (with its
    /// node and normal code, transparent or not) when some cell around it —
    /// the 2×2×2 cells it is a corner of, which hold the in-slice 2×2 ones —
    /// may be visible under `vis`, so every voxel of such a cell is stored and
    /// a sample that reads a voxel left out is invisible. Bridged gaps store
    /// their voxels in full too.
    pub fn encode_post<S: VoxelSource + ?Sized>(src: &S, pre: &Preclass, vis: &PostVisible) -> Self {
        Self::encode_with(src, pre, Some(vis))
    }

    /// Per voxel of slice `k`, whether the post-classified encoding stores it
    /// (see [`RleVolume::encode_post`]).
    fn post_mask(stack: &SliceStack, pre: &Preclass, vis: &PostVisible, k: usize) -> Vec<bool> {
        let [ni, nj, nk] = stack.n;
        // cells along each axis: c covers voxels c and min(c + 1, n − 1)
        let cells = |n: usize| n.saturating_sub(1).max(1);
        let (ci_n, cj_n, ck_n) = (cells(ni), cells(nj), cells(nk));
        let nodes = |kk: usize| -> Vec<u16> {
            (0..nj).flat_map(|j| (0..ni).map(move |i| (i, j))).map(|(i, j)| pre.node(stack, i, j, kk)).collect()
        };
        let mut keep = vec![false; ni * nj];
        for ck in [k.wrapping_sub(1), k] {
            if ck >= ck_n {
                continue;
            }
            let (a, b) = (nodes(ck), nodes((ck + 1).min(nk - 1)));
            // per voxel column, the range over the two slices
            let lo: Vec<u16> = a.iter().zip(&b).map(|(x, y)| *x.min(y)).collect();
            let hi: Vec<u16> = a.iter().zip(&b).map(|(x, y)| *x.max(y)).collect();
            for cj in 0..cj_n {
                let (j0, j1) = (cj, (cj + 1).min(nj - 1));
                for ci in 0..ci_n {
                    let (i0, i1) = (ci, (ci + 1).min(ni - 1));
                    let at = [i0 + ni * j0, i1 + ni * j0, i0 + ni * j1, i1 + ni * j1];
                    let l = at.iter().map(|&x| lo[x]).min().unwrap_or(0);
                    let h = at.iter().map(|&x| hi[x]).max().unwrap_or(0);
                    if vis.cell(l, h) {
                        for x in at {
                            keep[x] = true;
                        }
                    }
                }
            }
        }
        keep
    }

    fn encode_with<S: VoxelSource + ?Sized>(src: &S, pre: &Preclass, post: Option<&PostVisible>) -> Self {
        let stack: &SliceStack = src.slices();
        let [ni, nj, nk] = stack.n;
        let encode_slice = |k: usize| {
            let keep = post.map(|vis| Self::post_mask(stack, pre, vis, k));
            let voxel = |i: usize, j: usize| match &keep {
                None => pre.classify_voxel(src, i, j, k),
                Some(m) => m[i + ni * j].then(|| pre.post_voxel(src, i, j, k)),
            };
            let bridge = |i: usize, j: usize| match &keep {
                None => pre.bridge_voxel(stack, i, j, k),
                Some(_) => pre.post_voxel(src, i, j, k),
            };
            let mut s = SliceRuns {
                runs: Vec::new(),
                voxels: Vec::new(),
                ends: Vec::with_capacity(nj),
                extent: Vec::with_capacity(nj),
                bbox: [u32::MAX, 0, u32::MAX, 0],
            };
            for j in 0..nj {
                s.extent.push([u16::MAX, 0]);
                // `gap` is where the current transparent run began; `run` where the
                // current non-transparent run began; `pending` counts the
                // transparent voxels since its last non-transparent one
                let (mut gap, mut run, mut pending): (usize, Option<usize>, usize) = (0, None, 0);
                for i in 0..ni {
                    match voxel(i, j) {
                        Some(v) => {
                            // a short gap inside the run: bridge it with its transparent voxels
                            if run.is_some() {
                                s.voxels.extend((i - pending..i).map(|b| bridge(b, j)));
                            }
                            run.get_or_insert(i);
                            pending = 0;
                            s.voxels.push(v);
                        }
                        None => {
                            if let Some(start) = run {
                                pending += 1;
                                if pending > BRIDGE {
                                    let end = i + 1 - pending;
                                    s.push_pair(start - gap, end - start, start, end - 1, j);
                                    (gap, run, pending) = (end, None, 0);
                                }
                            }
                        }
                    }
                }
                if let Some(start) = run {
                    let end = ni - pending;
                    s.push_pair(start - gap, end - start, start, end - 1, j);
                }
                s.ends.push((s.runs.len() as u32, s.voxels.len() as u32));
            }
            s
        };
        let (mut runs, mut voxels) = (Vec::new(), Vec::new());
        let (mut scan_runs, mut scan_voxels) = (Vec::with_capacity(nj * nk + 1), Vec::with_capacity(nj * nk + 1));
        let (mut extent, mut bbox) = (Vec::with_capacity(nj * nk), Vec::with_capacity(nk));
        scan_runs.push(0);
        scan_voxels.push(0);
        // a group of slices at a time, in parallel, appended in order: the
        // encoding's peak is the whole plus one group's slices, not twice the whole
        let group = (4 * rayon::current_num_threads()).max(ENCODE_GROUP);
        for k0 in (0..nk).step_by(group) {
            let slices: Vec<SliceRuns> = (k0..(k0 + group).min(nk)).into_par_iter().map(encode_slice).collect();
            for s in slices {
                // run and voxel counts fit u32: the volume has at most 2^30 voxels
                let (r0, v0) = (runs.len() as u32, voxels.len() as u32);
                scan_runs.extend(s.ends.iter().map(|e| r0 + e.0));
                scan_voxels.extend(s.ends.iter().map(|e| v0 + e.1));
                runs.extend_from_slice(&s.runs);
                voxels.extend_from_slice(&s.voxels);
                extent.extend_from_slice(&s.extent);
                bbox.push(s.bbox);
            }
        }
        let lines = Scanlines { runs: owned(runs), scan_runs: owned(scan_runs), scan_voxels: owned(scan_voxels), voxels: owned(voxels) };
        RleVolume { axis: stack.axis, n: stack.n, perm: stack.perm(), lines, map: Vec::new(), extent, bbox }
    }

    /// The encoding of the axis whose permutation is this one's with `j` and
    /// `k` swapped (`[perm[0], perm[2], perm[1]]`, principal axis `perm[1]`),
    /// sharing this one's runs and voxels: its scanline `(j, k)` is this
    /// one's scanline `(k, j)`, so it needs only the pointer table, the
    /// extents in its order and its slices' boxes (from the extents: exactly
    /// what encoding its own stack would give).
    pub fn transposed(&self) -> RleVolume {
        let [ni, nj, nk] = self.n;
        let mut map = Vec::with_capacity(nj * nk);
        let mut extent = Vec::with_capacity(nj * nk);
        let mut bbox = Vec::with_capacity(nj);
        // its slice kt is this one's row j = kt; its row jt is this one's slice k = jt
        for kt in 0..nj {
            let mut b = [u32::MAX, 0, u32::MAX, 0];
            for jt in 0..nk {
                let s = kt + nj * jt;
                map.push(self.line(s) as u32);
                let e = self.extent[s];
                extent.push(e);
                if e[0] <= e[1] {
                    b = [b[0].min(e[0] as u32), b[1].max(e[1] as u32), b[2].min(jt as u32), b[3].max(jt as u32)];
                }
            }
            bbox.push(b);
        }
        RleVolume {
            axis: self.perm[1],
            n: [ni, nk, nj],
            perm: [self.perm[0], self.perm[2], self.perm[1]],
            lines: self.lines.clone(),
            map,
            extent,
            bbox,
        }
    }

    /// True when `other` reads the same runs and voxels (one of them built
    /// from the other by [`RleVolume::transposed`]).
    pub fn shares_scanlines(&self, other: &RleVolume) -> bool {
        Arc::ptr_eq(&self.lines.voxels, &other.lines.voxels)
    }

    /// True when this axis reads another axis's scanlines through its pointer table.
    pub fn is_transposed(&self) -> bool {
        !self.map.is_empty()
    }

    /// The shared scanline of scanline `s`.
    #[inline(always)]
    fn line(&self, s: usize) -> usize {
        if self.map.is_empty() { s } else { self.map[s] as usize }
    }

    /// Bytes held by the encoding: [`RleVolume::table_bytes`] plus
    /// [`RleVolume::shared_bytes`] (held once by the axes that share them).
    pub fn bytes(&self) -> usize {
        self.table_bytes() + self.shared_bytes()
    }

    /// Bytes of this axis's own tables: the pointer table, the extents and
    /// the slices' boxes.
    pub fn table_bytes(&self) -> usize {
        (self.map.len() + self.extent.len()) * 4 + self.bbox.len() * 16
    }

    /// Bytes of the runs and voxels (shared with a transposed axis, if any).
    pub fn shared_bytes(&self) -> usize {
        self.lines.bytes()
    }

    /// Number of voxels stored: the non-transparent ones and the bridged transparent ones.
    pub fn voxel_count(&self) -> usize {
        self.lines.voxels.len()
    }

    /// Number of bridged transparent voxels stored (see [`BRIDGE`]).
    pub fn bridged_count(&self) -> usize {
        self.lines.voxels.iter().filter(|v| v.normal == BRIDGE_NORMAL).count()
    }

    /// Number of non-transparent runs.
    pub fn run_count(&self) -> usize {
        self.lines.runs.len() / 2
    }

    /// The `(transparent, non-transparent)` run-length pairs of scanline `(j, k)`
    /// (a non-transparent run may contain bridged transparent voxels).
    pub fn scanline_runs(&self, j: usize, k: usize) -> &[u16] {
        let (l, t) = (&self.lines, self.line(j + self.n[1] * k));
        &l.runs[l.scan_runs[t] as usize..l.scan_runs[t + 1] as usize]
    }

    /// Decodes scanline `(j, k)`: its non-transparent voxels with their `i`
    /// (bridged transparent voxels left out).
    pub fn decode_scanline(&self, j: usize, k: usize) -> impl Iterator<Item = (usize, RleVoxel)> + '_ {
        self.stored_scanline(j, k).filter(|(_, v)| v.normal != BRIDGE_NORMAL)
    }

    /// Every voxel stored for scanline `(j, k)` with its `i`, bridged
    /// transparent voxels included.
    pub fn stored_scanline(&self, j: usize, k: usize) -> impl Iterator<Item = (usize, RleVoxel)> + '_ {
        let (l, t) = (&self.lines, self.line(j + self.n[1] * k));
        let vox = &l.voxels[l.scan_voxels[t] as usize..l.scan_voxels[t + 1] as usize];
        let mut pos = 0usize;
        let mut next = 0usize;
        self.scanline_runs(j, k).chunks_exact(2).flat_map(move |pair| {
            let start = pos + pair[0] as usize;
            let len = pair[1] as usize;
            pos = start + len;
            let first = next;
            next += len;
            (0..len).map(move |t| (start + t, vox[first + t]))
        })
    }

    /// Hints the cache to fetch scanline `s`'s voxels near columns `a` and `b`
    /// (assuming one run from its first non-transparent column: exact for solid
    /// objects, a harmless guess otherwise).
    #[inline(always)]
    pub(crate) fn prefetch_scanline(&self, s: usize, a: usize, b: usize) {
        if s >= self.extent.len() {
            return;
        }
        let (l, t) = (&self.lines, self.line(s));
        let (v0, v1) = (l.scan_voxels[t] as usize, l.scan_voxels[t + 1] as usize);
        if v0 == v1 {
            return;
        }
        let lo = self.extent[s][0] as usize;
        let at = |c: usize| (v0 + c.saturating_sub(lo)).min(v1 - 1);
        prefetch(&l.voxels, at(a));
        prefetch(&l.voxels, at(b));
    }

    /// A run cursor at the start of scanline `s = j + nj·k` (through the
    /// pointer table of a transposed axis).
    #[inline(always)]
    pub(crate) fn cursor(&self, s: usize) -> Cursor<'_> {
        let (l, t) = (&self.lines, self.line(s));
        let runs = &l.runs[l.scan_runs[t] as usize..l.scan_runs[t + 1] as usize];
        let vox = &l.voxels[l.scan_voxels[t] as usize..l.scan_voxels[t + 1] as usize];
        Cursor::new(runs, vox)
    }

    /// The rectangle of the intermediate grid this view can write: the union over
    /// slices of the pixels whose cell touches a non-transparent voxel.
    pub fn rect(&self, plan: &FramePlan) -> Option<Rect> {
        let grid = plan.grid.size;
        let [ni, nj, _] = self.n;
        if ni < 2 || nj < 2 {
            return None;
        }
        let (mut lo, mut hi) = ([i64::MAX; 2], [i64::MIN; 2]);
        for k in plan.front_to_back() {
            let b = self.bbox[k];
            if b[0] > b[1] {
                continue;
            }
            // voxel v touches cells v − 1 and v (and, under a box footprint,
            // the cells of pixels whose footprint reaches it)
            let span = [(b[0], b[1], ni), (b[2], b[3], nj)];
            for (a, &(v0, v1, n)) in span.iter().enumerate() {
                let reach = plan.footprint_reach(k, a);
                let [x0, x1] = plan.pixels_of_cells(k, a, (v0 as i64 - 1 - reach).max(0), (v1 as i64 + reach).min(n as i64 - 2));
                if x0 <= x1 {
                    lo[a] = lo[a].min(x0);
                    hi[a] = hi[a].max(x1);
                }
            }
        }
        if plan.intermediate() && plan.slices() > 0 {
            // the intermediate samples between slices k and k + 1 read both
            let [k0, k1] = plan.k_range;
            for k in k0..k1.min(plan.slices() - 1) {
                let (a, b) = (self.bbox[k], self.bbox[k + 1]);
                let bx = [a[0].min(b[0]), a[1].max(b[1]), a[2].min(b[2]), a[3].max(b[3])];
                if bx[0] > bx[1] {
                    continue;
                }
                let span = [(bx[0], bx[1], ni), (bx[2], bx[3], nj)];
                for (a, &(v0, v1, n)) in span.iter().enumerate() {
                    let [x0, x1] = plan.mid_map(k, a).pixels_of_cells((v0 as i64 - 1).max(0), (v1 as i64).min(n as i64 - 2));
                    if x0 <= x1 {
                        lo[a] = lo[a].min(x0);
                        hi[a] = hi[a].max(x1);
                    }
                }
            }
        }
        if lo[0] > hi[0] || lo[1] > hi[1] {
            return None;
        }
        let clamp = |x: i64, a: usize| x.clamp(0, grid[a] as i64 - 1) as usize;
        Some(Rect { p0: clamp(lo[0], 0), p1: clamp(hi[0], 0), q0: clamp(lo[1], 1), q1: clamp(hi[1], 1) })
    }
}

impl SliceRuns {
    /// Appends a pair: `gap` transparent voxels, then `len` non-transparent ones
    /// spanning `i0..=i1` of row `j` (scanlines are at most 2^14 long, so u16 fits).
    fn push_pair(&mut self, gap: usize, len: usize, i0: usize, i1: usize, j: usize) {
        self.runs.push(gap as u16);
        self.runs.push(len as u16);
        // the scanline's extent (pairs come in increasing i)
        if let Some(e) = self.extent.last_mut() {
            e[0] = e[0].min(i0 as u16);
            e[1] = i1 as u16;
        }
        let b = &mut self.bbox;
        b[0] = b[0].min(i0 as u32);
        b[1] = b[1].max(i1 as u32);
        b[2] = b[2].min(j as u32);
        b[3] = b[3].max(j as u32);
    }
}

/// Walks the non-transparent runs of one scanline with a monotone column.
#[derive(Clone, Copy)]
pub(crate) struct Cursor<'a> {
    runs: &'a [u16],
    pub(crate) vox: &'a [RleVoxel],
    /// Next pair to read.
    r: usize,
    /// Current non-transparent run `[s, e)` (`INF` past the last one) ...
    pub(crate) s: u32,
    pub(crate) e: u32,
    /// ... whose voxel at column `x` is `vox[base + x]` (wrapping arithmetic).
    pub(crate) base: u32,
}

impl<'a> Cursor<'a> {
    #[inline(always)]
    pub(crate) fn new(runs: &'a [u16], vox: &'a [RleVoxel]) -> Self {
        let mut c = Cursor { runs, vox, r: 0, s: 0, e: 0, base: 0 };
        c.next_run();
        c
    }

    #[inline(always)]
    fn next_run(&mut self) {
        // the voxel index of the next run's first column is where this run ends
        let v = self.base.wrapping_add(self.e);
        if self.r + 1 < self.runs.len() {
            self.s = self.e + self.runs[self.r] as u32;
            self.e = self.s + self.runs[self.r + 1] as u32;
            self.r += 2;
        } else {
            self.s = INF;
            self.e = INF;
        }
        self.base = v.wrapping_sub(self.s);
    }

    /// Moves to the run containing or following column `x` (`x` never decreases).
    #[inline(always)]
    pub(crate) fn seek(&mut self, x: u32) {
        while self.e <= x {
            self.next_run();
        }
    }

    /// [`Cursor::seek`] to `x` from `x − 1`: runs are never empty and never
    /// adjacent, so at most one step.
    #[inline(always)]
    pub(crate) fn step(&mut self, x: u32) {
        if self.e <= x {
            self.next_run();
        }
    }

    /// First non-transparent column at or after `x` (after `seek(x)`).
    #[inline(always)]
    pub(crate) fn first_from(&self, x: u32) -> u32 {
        self.s.max(x)
    }

    /// The voxel at column `x` (after `seek(x)`), `None` if transparent.
    #[inline(always)]
    pub(crate) fn at(&self, x: u32) -> Option<RleVoxel> {
        if x >= self.s { Some(self.vox[self.base.wrapping_add(x) as usize]) } else { None }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cursor_walks_runs() {
        // columns 2..4 and 7..8 non-transparent
        let runs = [2u16, 2, 3, 1];
        let vox: Vec<RleVoxel> = (0..3).map(|c| RleVoxel { class: c, normal: 0 }).collect();
        let mut c = Cursor::new(&runs, &vox);
        let mut got = vec![];
        for x in 0..10 {
            c.seek(x);
            got.push(c.at(x).map(|v| v.class));
            if x == 4 {
                assert_eq!(c.first_from(x), 7);
            }
        }
        assert_eq!(got, [None, None, Some(0), Some(1), None, None, None, Some(2), None, None]);
        c.seek(50);
        assert_eq!(c.first_from(50), INF);
    }
}
