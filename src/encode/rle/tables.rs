//! The per-view lookup tables of the pre-classified paths ([`ViewTables`]):
//! opacity-corrected premultiplied colour per class node, shade entry per
//! normal code.

use super::preclass::{Preclass, RleVoxel};
use crate::classify::TABLE_NODES;
use crate::classify::shade_table::ShadeTable;
use crate::classify::shading::{Shading, apply_shade, pow_int};
use crate::data::normals::{NORMAL_CODES, boxed, decode_normal};

/// The per-view lookup tables of the pre-classified paths. Fixed-size arrays
/// indexed with masks, so lookups need no bounds checks.
#[derive(Clone, Debug)]
pub struct ViewTables {
    /// Per class node: its opacity-corrected premultiplied colour, split for shading.
    lut: Box<[ClassEntry; TABLE_NODES]>,
    /// Per normal code (shared with the binary path's table shading).
    shade: ShadeTable,
    lut_key: Option<(u64, u32)>,
}

impl Default for ViewTables {
    fn default() -> Self {
        ViewTables { lut: boxed(ClassEntry::default()), shade: ShadeTable::default(), lut_key: None }
    }
}

impl ViewTables {
    /// Brings the tables up to date for classification `pre`, sample-spacing
    /// `ratio`, object-space headlight direction `light` and material `shading`;
    /// rebuilds only what changed. Returns true if anything was rebuilt.
    pub fn update(&mut self, pre: &Preclass, ratio: f32, light: [f32; 3], shading: Shading) -> bool {
        let ratio = if ratio.is_finite() && ratio > 0.0 { ratio } else { 1.0 };
        let mut rebuilt = false;
        let lut_key = Some((pre.id, ratio.to_bits()));
        if self.lut_key != lut_key {
            for (i, out) in self.lut.iter_mut().enumerate() {
                let a = pre.alpha[i];
                // α' = 1 − (1 − α)^ratio = 1 − exp(ratio · ln(1 − α))
                let a = if a <= 0.0 || a >= 1.0 || ratio == 1.0 { a.clamp(0.0, 1.0) } else { 1.0 - (ratio * pre.ln_clear[i]).exp() };
                *out = ClassEntry::new(a, pre.rgb[i]);
            }
            self.lut_key = lut_key;
            rebuilt = true;
        }
        self.shade.update(light, shading) || rebuilt
    }

    /// Shaded, opacity-corrected, premultiplied colour of a voxel.
    #[inline(always)]
    pub fn voxel(&self, v: RleVoxel) -> [f32; 4] {
        // classes are < TABLE_NODES, a power of two
        let [d, s] = self.shade.get(v.normal);
        self.lut[v.class as usize & (TABLE_NODES - 1)].shade(d, s)
    }

    /// [`ViewTables::voxel`], transparent black for `None`.
    #[inline(always)]
    pub(crate) fn get(&self, v: Option<RleVoxel>) -> [f32; 4] {
        match v {
            Some(v) => self.voxel(v),
            None => [0.0; 4],
        }
    }
}

/// A class node's opacity-corrected premultiplied colour `c = [α'r, α'g,
/// α'b, α']`, kept as the three vectors its shading adds up:
/// `rgb = [α'r, α'g, α'b, 0]`, `a = [α', α', α', 0]`, `a3 = [0, 0, 0, α']`.
/// A voxel shaded by its entry `[d, s]` is then `(rgb·d + a·s) + a3`: each
/// colour lane `α'r·d + α'·s`, the alpha lane `α'`, as `c·[d, d, d, 1] +
/// α'·[s, s, s, 0]` is, bit for bit (adding `+0` keeps every value but `−0`,
/// and a sum of products of non-negative numbers is never `−0`: [`ClassEntry::new`]
/// stores an opacity of `−0` as `+0`), in two products and two sums with no
/// lane moves.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(16))]
struct ClassEntry {
    rgb: [f32; 4],
    a: [f32; 4],
    a3: [f32; 4],
}

impl ClassEntry {
    /// The entry of opacity `a` (in [0, 1], or NaN) and colour `rgb` (each in [0, 1]).
    fn new(a: f32, rgb: [f32; 3]) -> Self {
        // −0 as +0 (see the type's docs); NaN stays
        let a = if a == 0.0 { 0.0 } else { a };
        ClassEntry { rgb: [a * rgb[0], a * rgb[1], a * rgb[2], 0.0], a: [a, a, a, 0.0], a3: [0.0, 0.0, 0.0, a] }
    }

    /// The node's colour shaded by the entry `[d, s]` (both finite and
    /// non-negative, as every shade-table entry is).
    #[inline(always)]
    fn shade(&self, d: f32, s: f32) -> [f32; 4] {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::*;
            // SAFETY: SSE belongs to the x86-64 baseline, enabled in every
            // build for this architecture; the loads read the entry's own
            // 16-byte aligned arrays (`repr(align(16))`, each array 16 bytes
            // at an offset that is a multiple of 16). Exercised by
            // `class_entries_shade_as_the_formula` and every pre-classified
            // RLE frame.
            unsafe {
                let o = _mm_add_ps(
                    _mm_mul_ps(_mm_load_ps(self.rgb.as_ptr()), _mm_set1_ps(d)),
                    _mm_mul_ps(_mm_load_ps(self.a.as_ptr()), _mm_set1_ps(s)),
                );
                let mut out = [0f32; 4];
                _mm_storeu_ps(out.as_mut_ptr(), _mm_add_ps(o, _mm_load_ps(self.a3.as_ptr())));
                out
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let mut out = [0f32; 4];
            for i in 0..4 {
                out[i] = (self.rgb[i] * d + self.a[i] * s) + self.a3[i];
            }
            out
        }
    }
}

/// The per-view tables of the post-classified sampler (Shear-Warp Deluxe P,
/// [`crate::composite::slices::Sampler`]): per class node its colour and
/// opacity-corrected opacity `[r, g, b, α']` (the classifier's table, corrected
/// like [`ViewTables`]' premultiplied one), the decoded unit normal of every
/// normal code (zero for [`crate::data::normals::ZERO_NORMAL`]), the object-space headlight and the
/// material. A voxel is the 4-vector `[node, n_x, n_y, n_z]` (its classifier
/// node as a float: interpolating nodes is interpolating densities, the
/// node spacing being uniform); a blend of them is classified at its
/// interpolated node (linear between nodes, as
/// [`crate::classify::Classifier::classify`]) and shaded with its normalized
/// interpolated normal by the one shading model (`|n·l|`, [`Shading::entry`],
/// [`crate::classify::shading::apply_shade`]; a zero normal faces the viewer).
#[derive(Clone, Debug)]
pub struct PostTables {
    lut: Box<[[f32; 4]; TABLE_NODES]>,
    normals: Box<[[f32; 3]; NORMAL_CODES]>,
    light: [f32; 3],
    shading: Shading,
    pow: i32,
    lut_key: Option<(u64, u32)>,
}

impl Default for PostTables {
    fn default() -> Self {
        let mut normals: Box<[[f32; 3]; NORMAL_CODES]> = boxed([0.0; 3]);
        for (c, n) in normals.iter_mut().enumerate() {
            *n = decode_normal(c as u16).unwrap_or([0.0; 3]);
        }
        PostTables { lut: boxed([0.0; 4]), normals, light: [0.0, 0.0, 1.0], shading: Shading::default(), pow: 0, lut_key: None }
    }
}

impl PostTables {
    /// Brings the tables up to date (arguments as [`ViewTables::update`]).
    /// Returns true if the classification table was rebuilt.
    pub fn update(&mut self, pre: &Preclass, ratio: f32, light: [f32; 3], shading: Shading) -> bool {
        let ratio = if ratio.is_finite() && ratio > 0.0 { ratio } else { 1.0 };
        (self.light, self.shading, self.pow) = (light, shading, shading.exponent() as i32);
        let lut_key = Some((pre.id, ratio.to_bits()));
        if self.lut_key == lut_key {
            return false;
        }
        for (i, out) in self.lut.iter_mut().enumerate() {
            let a = pre.alpha[i];
            let a = if a <= 0.0 || a >= 1.0 || ratio == 1.0 { a.clamp(0.0, 1.0) } else { 1.0 - (ratio * pre.ln_clear[i]).exp() };
            let c = pre.rgb[i];
            *out = [c[0], c[1], c[2], a];
        }
        self.lut_key = lut_key;
        true
    }

    /// The 4-vector `[node, n]` of a stored voxel. (A normal code holds a
    /// direction up to sign, so two neighbours' codes may point opposite
    /// ways where the surface's normal crosses the codes' hemisphere
    /// boundary: the sampler turns a cell's normals to one side before
    /// blending them: a slice's cell column by column
    /// ([`crate::composite::slices::Sampler::column`] and `blend_columns`),
    /// a midpoint's eight together (`align_normals`).)
    #[inline(always)]
    pub fn voxel(&self, v: RleVoxel) -> [f32; 4] {
        let n = self.normals[v.normal as usize & (NORMAL_CODES - 1)];
        [v.class as f32, n[0], n[1], n[2]]
    }

    /// A blend of voxels' 4-vectors → the premultiplied, shaded sample; exact
    /// zeros where the interpolated opacity is zero or the blend is NaN (it
    /// read a voxel the encoding left out).
    #[allow(clippy::neg_cmp_op_on_partial_ord)] // NaN takes the "zero" branch
    #[inline(always)]
    pub fn finish(&self, s: [f32; 4]) -> [f32; 4] {
        let p = s[0];
        if !(p >= 0.0) {
            return [0.0; 4];
        }
        let p = p.min((TABLE_NODES - 1) as f32);
        // (p is in [0, TABLE_NODES − 1] here, so through i32: one conversion
        // instead of the float-to-usize sequence; the same index)
        let i = (p as i32 as usize).min(TABLE_NODES - 2);
        let t = p - i as f32;
        let (a, b) = (self.lut[i], self.lut[i + 1]);
        let alpha = a[3] + (b[3] - a[3]) * t;
        if !(alpha > 0.0) {
            return [0.0; 4];
        }
        let rgb = [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t, a[2] + (b[2] - a[2]) * t];
        let l = self.light;
        let (nx, ny, nz) = (s[1], s[2], s[3]);
        let len2 = nx * nx + ny * ny + nz * nz;
        let ndl = if len2 > 1e-30 { ((nx * l[0] + ny * l[1] + nz * l[2]).abs() / len2.sqrt()).min(1.0) } else { 1.0 };
        let c = apply_shade(rgb, self.shading.entry(ndl, pow_int(ndl, self.pow)));
        [alpha * c[0], alpha * c[1], alpha * c[2], alpha]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A [`ClassEntry`]'s shade is `c·[d, d, d, 1] + α'·[s, s, s, 0]` lane
    /// by lane with `c = [α'r, α'g, α'b, α']`, bit for bit, over the
    /// tables' ranges: opacities and colours in [0, 1] (zero of either sign,
    /// the smallest and largest), entries finite and non-negative, and a
    /// NaN opacity.
    #[test]
    fn class_entries_shade_as_the_formula() {
        let formula = |c: [f32; 4], d: f32, s: f32| {
            let (dd, ss) = ([d, d, d, 1.0], [s, s, s, 0.0]);
            let mut out = [0f32; 4];
            for i in 0..4 {
                out[i] = c[i] * dd[i] + c[3] * ss[i];
            }
            out
        };
        let xs = [0.0, -0.0, 1.0, 0.5, 1e-30, 1e-45, 0.3333, 0.999_999_9, 1e-7, 0.75];
        let entries = [0.0, 1.0, 0.5, 1e-30, 0.3333, 0.999_999_9, 2.5, 1e-7, 0.75, 3.4e38];
        let mut n = 0;
        for (i, &a) in xs.iter().chain([f32::NAN].iter()).enumerate() {
            for (j, &d) in entries.iter().enumerate() {
                for &s in &entries {
                    let rgb = [xs[(i + j) % xs.len()], xs[(i * 3 + 1) % xs.len()], xs[j % xs.len()]];
                    let e = ClassEntry::new(a, rgb);
                    // the premultiplied colour the table held before, of the stored opacity
                    let a = e.a3[3];
                    let c = [a * rgb[0], a * rgb[1], a * rgb[2], a];
                    let (got, want) = (e.shade(d, s), formula(c, d, s));
                    for l in 0..4 {
                        assert!(
                            got[l].to_bits() == want[l].to_bits() || (got[l].is_nan() && want[l].is_nan()),
                            "{c:?} {d} {s}: {got:?} vs {want:?}"
                        );
                    }
                    n += 1;
                }
            }
        }
        assert!(n > 1000);
    }
}
