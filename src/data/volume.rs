//! The volume: a regular grid of scalar densities with voxel spacing.
//!
//! Owns the voxel storage ([`VoxelData`], u8/u16/i16/f32), the grid dimensions and
//! the physical spacing, the size limits every loader checks *before* allocating,
//! and the NaN/Inf policy: non-finite f32 voxels are **rejected** with
//! [`Error::NonFinite`] when a volume is constructed, so no later stage ever sees one.
//!
//! Storage is x-fastest: voxel `(x, y, z)` lives at `x + nx * (y + ny * z)`.

use crate::data::orientation::PatientFrame;
use crate::data::stats::ValueStats;
pub use crate::data::voxels::{VoxelData, VoxelType};
use crate::error::{Error, Result};

/// Largest accepted edge length of a volume, in voxels.
pub const MAX_DIM: usize = 1 << 14;
/// Largest accepted voxel count (1 Gi voxels: 4 GiB as f32).
pub const MAX_VOXELS: u64 = 1 << 30;

/// Checks dimensions against the limits without allocating anything.
///
/// Every loader calls this on header values before it reserves memory, so a
/// header claiming 100000³ voxels fails at once.
pub fn check_dims(dims: [u64; 3]) -> Result<[usize; 3]> {
    let bad = |why: String| Err(Error::BadDims { dims: dims.to_vec(), why });
    if dims.contains(&0) {
        return bad("every dimension must be at least 1".into());
    }
    if let Some(d) = dims.iter().find(|&&d| d > MAX_DIM as u64) {
        return bad(format!("{d} exceeds the largest supported edge of {MAX_DIM} voxels"));
    }
    let n = dims[0] * dims[1] * dims[2];
    if n > MAX_VOXELS {
        return bad(format!("{n} voxels exceed the supported maximum of {MAX_VOXELS}"));
    }
    Ok([dims[0] as usize, dims[1] as usize, dims[2] as usize])
}

/// A scalar volume: dimensions, spacing, typed voxels and (when the file says)
/// where the index axes point in the patient.
#[derive(Clone, Debug, PartialEq)]
pub struct Volume {
    dims: [usize; 3],
    spacing: [f32; 3],
    /// Shared between clones (a clone costs no second copy of the voxels;
    /// [`Volume::reverse_axis`] copies on write).
    data: std::sync::Arc<VoxelData>,
    frame: Option<PatientFrame>,
    /// The value statistics, computed on first use (the voxel values never
    /// change after construction: [`Volume::reverse_axis`] only reorders them).
    stats: StatsCache,
}

/// A lazily computed [`ValueStats`]; equal for any two volumes (a cache, not data).
#[derive(Clone, Debug, Default)]
struct StatsCache(std::sync::OnceLock<ValueStats>);

impl PartialEq for StatsCache {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl Volume {
    /// Builds a volume, checking dims, spacing, the voxel count and (for f32) that
    /// every voxel is finite.
    pub fn new(dims: [usize; 3], spacing: [f32; 3], data: VoxelData) -> Result<Self> {
        let d = check_dims(dims.map(|d| d as u64))?;
        let n = d[0] * d[1] * d[2];
        if data.len() != n {
            return Err(Error::BadDims {
                dims: dims.iter().map(|&d| d as u64).collect(),
                why: format!("expected {n} voxels, got {}", data.len()),
            });
        }
        check_spacing(spacing)?;
        if let VoxelData::F32(v) = &data
            && let Some((index, &value)) = v.iter().enumerate().find(|(_, x)| !x.is_finite())
        {
            return Err(Error::NonFinite { index, value });
        }
        Ok(Volume { dims: d, spacing, data: std::sync::Arc::new(data), frame: None, stats: StatsCache::default() })
    }

    /// Builds an f32 volume by evaluating `f(x, y, z)` at every voxel.
    pub fn from_fn(dims: [usize; 3], spacing: [f32; 3], f: impl Fn(usize, usize, usize) -> f32) -> Result<Self> {
        let d = check_dims(dims.map(|d| d as u64))?;
        let mut v = Vec::with_capacity(d[0] * d[1] * d[2]);
        for z in 0..d[2] {
            for y in 0..d[1] {
                for x in 0..d[0] {
                    v.push(f(x, y, z));
                }
            }
        }
        Volume::new(d, spacing, VoxelData::F32(v))
    }

    /// Grid size `[nx, ny, nz]`.
    pub fn dims(&self) -> [usize; 3] {
        self.dims
    }
    /// Physical voxel size along x, y, z (any unit, typically mm).
    pub fn spacing(&self) -> [f32; 3] {
        self.spacing
    }
    /// Replaces the spacing (checked: finite and positive).
    pub fn set_spacing(&mut self, spacing: [f32; 3]) -> Result<()> {
        check_spacing(spacing)?;
        self.spacing = spacing;
        Ok(())
    }
    /// Where the index axes point in the patient (`None`: unknown, e.g. raw
    /// and .den files; named views then take the index axes to be RAS).
    /// Always right-handed (see [`Volume::set_frame`]).
    pub fn frame(&self) -> Option<&PatientFrame> {
        self.frame.as_ref()
    }
    /// Attaches (or clears) the patient frame. A mirrored frame (index axes of
    /// the other handedness than the patient, e.g. `LAS`) reverses the voxels
    /// along [`PatientFrame::mirror_axis`] and records it, so the volume always
    /// carries a right-handed index frame and renders unmirrored.
    pub fn set_frame(&mut self, frame: Option<PatientFrame>) {
        self.frame = frame.map(|f| {
            let (f, reversed) = f.unmirrored(self.dims, self.spacing);
            if let Some(a) = reversed {
                self.reverse_axis(a);
            }
            f
        });
    }
    /// The volume with frame `frame` (see [`Volume::set_frame`]).
    pub fn with_frame(mut self, frame: Option<PatientFrame>) -> Self {
        self.set_frame(frame);
        self
    }
    /// Reverses the voxel order along index axis `axis` (the frame, if any, is
    /// left alone: [`Volume::set_frame`] is the way to unmirror a volume).
    pub fn reverse_axis(&mut self, axis: usize) {
        let [nx, ny, nz] = self.dims;
        fn rev<T: Copy>(v: &mut [T], axis: usize, nx: usize, ny: usize, nz: usize) {
            match axis {
                0 => v.chunks_exact_mut(nx).for_each(|row| row.reverse()),
                1 => {
                    for z in 0..nz {
                        let plane = &mut v[z * nx * ny..(z + 1) * nx * ny];
                        for y in 0..ny / 2 {
                            let (a, b) = plane.split_at_mut((ny - 1 - y) * nx);
                            a[y * nx..(y + 1) * nx].swap_with_slice(&mut b[..nx]);
                        }
                    }
                }
                _ => {
                    let p = nx * ny;
                    for z in 0..nz / 2 {
                        let (a, b) = v.split_at_mut((nz - 1 - z) * p);
                        a[z * p..(z + 1) * p].swap_with_slice(&mut b[..p]);
                    }
                }
            }
        }
        match std::sync::Arc::make_mut(&mut self.data) {
            VoxelData::U8(v) => rev(v, axis, nx, ny, nz),
            VoxelData::U16(v) => rev(v, axis, nx, ny, nz),
            VoxelData::I16(v) => rev(v, axis, nx, ny, nz),
            VoxelData::F32(v) => rev(v, axis, nx, ny, nz),
        }
    }
    /// How many handles share these voxels (this one included).
    pub(crate) fn data_handles(&self) -> usize {
        std::sync::Arc::strong_count(&self.data)
    }
    /// Lets go of this handle's voxels, keeping dims, spacing, frame and
    /// statistics (computed first): what a renderer does once its packed cells
    /// hold them. A parked volume reads as having no voxels; only the
    /// renderer holds one, and gives it back its voxels
    /// ([`Volume::unpark`]) before anything reads them.
    pub(crate) fn park(&mut self) {
        self.stats();
        let empty = match *self.data {
            VoxelData::U8(_) => VoxelData::U8(Vec::new()),
            VoxelData::U16(_) => VoxelData::U16(Vec::new()),
            VoxelData::I16(_) => VoxelData::I16(Vec::new()),
            VoxelData::F32(_) => VoxelData::F32(Vec::new()),
        };
        self.data = std::sync::Arc::new(empty);
    }
    /// True after [`Volume::park`] (until [`Volume::unpark`]).
    pub(crate) fn is_parked(&self) -> bool {
        self.data.len() != self.dims[0] * self.dims[1] * self.dims[2]
    }
    /// Gives a parked volume its voxels back (in its own order and type).
    pub(crate) fn unpark(&mut self, data: std::sync::Arc<VoxelData>) {
        assert!(
            data.len() == self.dims[0] * self.dims[1] * self.dims[2] && data.voxel_type() == self.data.voxel_type(),
            "the voxels of another volume"
        );
        self.data = data;
    }
    /// The voxel storage.
    pub fn data(&self) -> &VoxelData {
        &self.data
    }
    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.data.len()
    }
    /// Bytes of the voxels, in their own type.
    pub fn bytes(&self) -> u64 {
        (self.len() * self.data.voxel_type().size()) as u64
    }
    /// Always false: a volume has at least one voxel.
    pub fn is_empty(&self) -> bool {
        false
    }
    /// Linear index of voxel `(x, y, z)`.
    #[inline]
    pub fn index(&self, x: usize, y: usize, z: usize) -> usize {
        x + self.dims[0] * (y + self.dims[1] * z)
    }
    /// Density at voxel `(x, y, z)` as f32.
    #[inline]
    pub fn get(&self, x: usize, y: usize, z: usize) -> f32 {
        self.data.get(self.index(x, y, z))
    }
    /// The value statistics (computed once, in parallel, on first use).
    pub fn stats(&self) -> &ValueStats {
        self.stats.0.get_or_init(|| ValueStats::of(&self.data))
    }
    /// This volume with the value statistics `stats` in place of its own:
    /// a part of a larger volume (a brick) classified as the whole is,
    /// whose statistics it cannot compute alone. Every range, histogram
    /// and preset asked of it is then the larger volume's.
    pub fn with_stats(self, stats: ValueStats) -> Self {
        Volume { stats: StatsCache(std::sync::OnceLock::from(stats)), ..self }
    }
    /// Smallest and largest density.
    pub fn value_range(&self) -> (f32, f32) {
        let s = self.stats();
        (s.lo, s.hi)
    }
    /// Histogram of densities in `bins` equal bins over [`Volume::value_range`].
    pub fn histogram(&self, bins: usize) -> Vec<u64> {
        let (lo, hi) = self.value_range();
        self.stats().histogram_in(&self.data, bins, lo, hi)
    }
    /// All voxels converted to f32, x-fastest.
    pub fn to_f32(&self) -> Vec<f32> {
        (0..self.len()).map(|i| self.data.get(i)).collect()
    }

    /// Trilinear resampling onto a `dims` grid spanning the same physical box:
    /// the corner voxels of the output sit on the corner voxels of the input
    /// (output voxel `o` of an axis samples input coordinate `o·(n_in−1)/(n_out−1)`),
    /// and the spacing grows or shrinks to match. Densities stay f32.
    pub fn resampled(&self, dims: [usize; 3]) -> Result<Volume> {
        let d = check_dims(dims.map(|d| d as u64))?;
        // per axis: input coordinate step between output voxels
        let step: [f64; 3] = std::array::from_fn(|a| if d[a] > 1 { (self.dims[a] - 1) as f64 / (d[a] - 1) as f64 } else { 0.0 });
        let spacing: [f32; 3] =
            std::array::from_fn(|a| if d[a] > 1 && self.dims[a] > 1 { (self.spacing[a] as f64 * step[a]) as f32 } else { self.spacing[a] });
        // one axis's sample positions: lower input index and weight of the upper one
        let taps = |a: usize| -> Vec<(usize, f32)> {
            (0..d[a])
                .map(|o| {
                    let c = o as f64 * step[a];
                    let i = (c.floor() as usize).min(self.dims[a].saturating_sub(2));
                    let w = if self.dims[a] > 1 { (c - i as f64) as f32 } else { 0.0 };
                    (i, w)
                })
                .collect()
        };
        let (tx, ty, tz) = (taps(0), taps(1), taps(2));
        let [nx, ny, nz] = self.dims;
        let at = |x: usize, y: usize, z: usize| self.data.get(x.min(nx - 1) + nx * (y.min(ny - 1) + ny * z.min(nz - 1)));
        let mut out = Vec::with_capacity(d[0] * d[1] * d[2]);
        for &(z, wz) in &tz {
            for &(y, wy) in &ty {
                for &(x, wx) in &tx {
                    let lerp = |a: f32, b: f32, w: f32| a + (b - a) * w;
                    let plane = |z: usize| lerp(lerp(at(x, y, z), at(x + 1, y, z), wx), lerp(at(x, y + 1, z), at(x + 1, y + 1, z), wx), wy);
                    out.push(lerp(plane(z), plane(z + 1), wz));
                }
            }
        }
        Ok(Volume { frame: self.frame, ..Volume::new(d, spacing, VoxelData::F32(out))? })
    }

    /// Densities mapped linearly from the window `[lo, hi]` onto 0..=255
    /// (clamped, rounded to nearest): an 8-bit copy for tools that take only
    /// u8 voxels, such as VolPack's `.den` files. A density `v` becomes
    /// `round(255·(v − lo)/(hi − lo))`.
    pub fn window_u8(&self, lo: f32, hi: f32) -> Result<Volume> {
        if !(lo.is_finite() && hi.is_finite() && hi > lo) {
            return Err(Error::value("window", format!("[{lo}, {hi}] (need finite lo < hi)")));
        }
        let scale = 255.0 / (hi as f64 - lo as f64);
        let v = (0..self.len()).map(|i| ((self.data.get(i) as f64 - lo as f64) * scale).round().clamp(0.0, 255.0) as u8).collect();
        Ok(Volume { frame: self.frame, ..Volume::new(self.dims, self.spacing, VoxelData::U8(v))? })
    }
}

fn check_spacing(spacing: [f32; 3]) -> Result<()> {
    if spacing.iter().any(|s| !s.is_finite() || *s <= 0.0) {
        return Err(Error::value("spacing", format!("{spacing:?} (each must be finite and > 0)")));
    }
    let (lo, hi) = spacing.iter().fold((f32::MAX, 0f32), |(a, b), &s| (a.min(s), b.max(s)));
    if hi / lo > 1.0e4 {
        return Err(Error::value("spacing", format!("{spacing:?}: anisotropy above 10^4 is not supported")));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clones_share_voxels_and_copy_on_write() {
        let a = Volume::from_fn([4, 3, 2], [1.0; 3], |x, y, z| (x + 10 * y + 100 * z) as f32).unwrap();
        let mut b = a.clone();
        assert!(std::ptr::eq(a.data(), b.data()), "a clone shares the voxels");
        b.reverse_axis(0);
        assert!(!std::ptr::eq(a.data(), b.data()));
        assert_eq!((a.get(0, 1, 1), b.get(0, 1, 1)), (110.0, 113.0), "the original is untouched");
        assert_eq!(a.value_range(), b.value_range());
    }

    #[test]
    fn rejects_zero_and_absurd_dims_without_allocating() {
        assert!(check_dims([0, 4, 4]).is_err());
        assert!(check_dims([100_000, 100_000, 100_000]).is_err());
        assert!(check_dims([4096, 4096, 4096]).is_err());
        assert_eq!(check_dims([4096, 4, 4]).unwrap(), [4096, 4, 4]);
    }

    #[test]
    fn rejects_nan_and_inf() {
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let e = Volume::new([2, 1, 1], [1.0; 3], VoxelData::F32(vec![0.0, bad])).unwrap_err();
            assert!(matches!(e, Error::NonFinite { index: 1, .. }), "{e}");
        }
    }

    #[test]
    fn rejects_wrong_length_and_bad_spacing() {
        assert!(Volume::new([2, 2, 2], [1.0; 3], VoxelData::U8(vec![0; 7])).is_err());
        assert!(Volume::new([1, 1, 1], [0.0, 1.0, 1.0], VoxelData::U8(vec![0])).is_err());
        assert!(Volume::new([1, 1, 1], [f32::NAN, 1.0, 1.0], VoxelData::U8(vec![0])).is_err());
    }

    #[test]
    fn resampling_keeps_corners_and_linear_fields_exactly() {
        // a linear field is reproduced exactly by trilinear resampling
        let v = Volume::from_fn([5, 4, 3], [1.0, 2.0, 3.0], |x, y, z| (x + 10 * y + 100 * z) as f32).unwrap();
        let r = v.resampled([9, 7, 5]).unwrap();
        assert_eq!(r.dims(), [9, 7, 5]);
        assert_eq!(r.spacing(), [0.5, 1.0, 1.5]);
        for z in 0..5 {
            for y in 0..7 {
                for x in 0..9 {
                    let want = x as f32 * 0.5 + 10.0 * y as f32 * 0.5 + 100.0 * z as f32 * 0.5;
                    assert!((r.get(x, y, z) - want).abs() < 1e-3, "{x},{y},{z}: {} vs {want}", r.get(x, y, z));
                }
            }
        }
        // same dims: identity; one voxel along an axis: no step, spacing kept
        assert_eq!(v.resampled([5, 4, 3]).unwrap().to_f32(), v.to_f32());
        let flat = Volume::from_fn([3, 1, 2], [1.0; 3], |x, _, z| (x + z) as f32).unwrap();
        assert_eq!(flat.resampled([5, 1, 2]).unwrap().get(4, 0, 1), 3.0);
        assert!(v.resampled([0, 2, 2]).is_err());
    }

    #[test]
    fn windowing_to_u8_clamps_and_rounds() {
        let v = Volume::new([5, 1, 1], [1.0; 3], VoxelData::I16(vec![-2000, -1000, 275, 1550, 3000])).unwrap();
        let w = v.window_u8(-1000.0, 1550.0).unwrap();
        assert_eq!(w.data().voxel_type(), VoxelType::U8);
        assert_eq!(w.to_f32(), vec![0.0, 0.0, 128.0, 255.0, 255.0]); // 127.5 rounds up
        for (lo, hi) in [(1.0, 1.0), (2.0, 1.0), (f32::NAN, 1.0), (0.0, f32::INFINITY)] {
            assert!(v.window_u8(lo, hi).is_err());
        }
    }

    #[test]
    fn mirrored_frames_reverse_the_voxels() {
        let v = Volume::from_fn([3, 4, 5], [1.0, 2.0, 3.0], |x, y, z| (x + 10 * y + 100 * z) as f32).unwrap();
        for axis in 0..3 {
            let mut r = v.clone();
            r.reverse_axis(axis);
            for (x, y, z) in [(0, 0, 0), (2, 1, 3), (1, 3, 4)] {
                let mut p = [x, y, z];
                p[axis] = v.dims()[axis] - 1 - p[axis];
                assert_eq!(r.get(x, y, z), v.get(p[0], p[1], p[2]), "axis {axis}");
            }
            r.reverse_axis(axis);
            assert_eq!(r, v);
        }
        let las = PatientFrame::from_code("LAS").unwrap();
        let m = v.clone().with_frame(Some(las));
        assert_eq!(m.frame().unwrap().code(), "RAS");
        assert_eq!(m.frame().unwrap().reversed_axis, Some(0));
        assert_eq!(m.get(0, 1, 2), v.get(2, 1, 2));
        let lps = PatientFrame::from_code("LPS").unwrap();
        assert_eq!(v.clone().with_frame(Some(lps)).to_f32(), v.to_f32());
    }

    #[test]
    fn indexing_is_x_fastest() {
        let v = Volume::from_fn([3, 4, 5], [1.0; 3], |x, y, z| (x + 10 * y + 100 * z) as f32).unwrap();
        assert_eq!(v.get(2, 3, 4), 432.0);
        assert_eq!(v.value_range(), (0.0, 432.0));
        assert_eq!(v.histogram(4).iter().sum::<u64>(), 60);
    }
}
