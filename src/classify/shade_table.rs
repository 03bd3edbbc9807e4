//! The per-view shade table of the normal codes: one shading-model entry
//! per code ([`ShadeTable`]), rebuilt when the light or the material
//! changes, and the headlight's direction in object space
//! ([`headlight_object`]). The codes themselves are [`crate::data::normals`]'s.

use std::sync::OnceLock;

use rayon::prelude::*;

use crate::classify::shading::{ShadeEntry, Shading};
use crate::data::normals::{NORMAL_CODES, ZERO_NORMAL, boxed, decode_normal};
use crate::view::Factorization;

/// Entries of a [`ShadeTable`]: one per `u16`, so any code indexes it with no
/// bounds check or mask; the [`NORMAL_CODES`] normal codes are the first.
const TABLE_LEN: usize = 1 << 16;

/// The per-view shade table: one [`ShadeEntry`] per normal code. A fixed-size
/// array of an entry per `u16` value, so a lookup needs no bounds check; the
/// entries past the normal codes stay zero (their pages are never touched
/// unless read).
#[derive(Clone, Debug)]
pub struct ShadeTable {
    shade: Box<[ShadeEntry; TABLE_LEN]>,
    key: Option<([u32; 3], Shading)>,
}

impl Default for ShadeTable {
    fn default() -> Self {
        ShadeTable { shade: boxed([0.0; 2]), key: None }
    }
}

impl ShadeTable {
    /// Brings the table up to date for the object-space headlight direction
    /// `light` and material `shading`; returns true if it was rebuilt.
    pub fn update(&mut self, light: [f32; 3], shading: Shading) -> bool {
        let key = Some((light.map(f32::to_bits), shading));
        if self.key == key {
            return false;
        }
        let [nx, ny, nz] = unit_normals();
        const BLOCK: usize = 4096;
        self.shade[..NORMAL_CODES].par_chunks_mut(BLOCK).enumerate().for_each(|(c, out)| {
            let r = c * BLOCK..c * BLOCK + out.len();
            shade_block(out, &nx[r.clone()], &ny[r.clone()], &nz[r], light, &shading);
        });
        // a zero gradient faces the viewer
        self.shade[ZERO_NORMAL as usize] = shading.entry(1.0, 1.0);
        self.key = key;
        true
    }

    /// The entry of `code` (codes above the normal codes, such as the RLE
    /// path's bridge marker, index a real entry: the code's low bits).
    #[inline(always)]
    pub fn get(&self, code: u16) -> ShadeEntry {
        *self.entry(code & (NORMAL_CODES - 1) as u16)
    }

    /// The entry of a normal code, by reference (for loads straight into a
    /// vector), with no mask: [`ShadeTable::get`] for every normal code
    /// (below [`NORMAL_CODES`], as every code of a voxel is); a `u16` above
    /// them reads a zero entry.
    #[inline(always)]
    pub fn entry(&self, code: u16) -> &ShadeEntry {
        debug_assert!((code as usize) < NORMAL_CODES, "code {code} is not a normal code");
        &self.shade[code as usize]
    }

    /// The bilinear blend of the entries of a cell's four corner codes (order of
    /// [`crate::data::normals::NormalStack::corners`]) at in-cell weights `(wi, wj)`.
    #[inline(always)]
    pub fn blend(&self, codes: [u16; 4], wi: f32, wj: f32) -> ShadeEntry {
        let [e00, e10, e01, e11] = codes.map(|c| self.get(c));
        let mut out = [0f32; 2];
        for a in 0..2 {
            let top = e00[a] + (e10[a] - e00[a]) * wi;
            let bot = e01[a] + (e11[a] - e01[a]) * wi;
            out[a] = top + (bot - top) * wj;
        }
        out
    }
}

/// The unit direction of every normal code, as three coordinate arrays (built
/// once per process: 768 KiB, view-independent; code 0 holds +z).
fn unit_normals() -> &'static [Vec<f32>; 3] {
    static NORMALS: OnceLock<[Vec<f32>; 3]> = OnceLock::new();
    NORMALS.get_or_init(|| {
        let dirs: Vec<[f32; 3]> = (0..NORMAL_CODES).map(|c| decode_normal(c as u16).unwrap_or([0.0, 0.0, 1.0])).collect();
        [0, 1, 2].map(|a| dirs.iter().map(|d| d[a]).collect())
    })
}

/// Lanes of the shade-table build: sixteen entries at a time stay in registers.
const LANES: usize = 16;

/// Shade-table entries for the unit normals `(nx, ny, nz)` (same lengths as
/// `out`, a multiple of [`LANES`]): plain fixed-size loops, so they vectorize.
#[inline(never)]
fn shade_block(out: &mut [ShadeEntry], nx: &[f32], ny: &[f32], nz: &[f32], l: [f32; 3], sh: &Shading) {
    let lanes = out.chunks_exact_mut(LANES).zip(nx.chunks_exact(LANES).zip(ny.chunks_exact(LANES)).zip(nz.chunks_exact(LANES)));
    for (o, ((x, y), z)) in lanes {
        let mut ndl = [0f32; LANES];
        for t in 0..LANES {
            ndl[t] = (x[t] * l[0] + y[t] * l[1] + z[t] * l[2]).abs().min(1.0);
        }
        // ndl^shininess by repeated squaring (the exponent is the same for every lane)
        let mut pow = [1f32; LANES];
        let mut base = ndl;
        let mut e = sh.exponent();
        while e > 0 {
            if e & 1 == 1 {
                for t in 0..LANES {
                    pow[t] *= base[t];
                }
            }
            e >>= 1;
            for b in base.iter_mut() {
                *b *= *b;
            }
        }
        for t in 0..LANES {
            o[t] = sh.entry(ndl[t], pow[t]);
        }
    }
}

/// The headlight direction (towards the viewer) in object space for view `f`.
pub fn headlight_object(f: &Factorization) -> [f32; 3] {
    // grad_to_eye_z[c] = R[2][perm[c]] · grad_scale[c]
    let mut l = [0f32; 3];
    for c in 0..3 {
        l[f.perm[c]] = (f.grad_to_eye_z[c] / f.grad_scale[c]) as f32;
    }
    l
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::classify::shading::apply_shade;
    use crate::data::normals::encode_normal;

    #[test]
    fn shade_table_matches_the_shading_model() {
        let l = [0.36f32, -0.48, 0.8];
        for sh in [Shading::default(), Shading { shininess: 7, ..Shading::default() }, Shading { shininess: 0, ..Shading::default() }] {
            let [nx, ny, nz] = unit_normals();
            let mut out = vec![[0.0; 2]; NORMAL_CODES];
            shade_block(&mut out, nx, ny, nz, l, &sh);
            for code in (1..NORMAL_CODES).step_by(7) {
                let n = decode_normal(code as u16).unwrap();
                let ndl = (n[0] * l[0] + n[1] * l[1] + n[2] * l[2]).abs().min(1.0);
                let want = sh.entry(ndl, ndl.powi(sh.shininess));
                let got = out[code];
                assert!((0..2).all(|a| (got[a] - want[a]).abs() < 1e-5), "{code}: {got:?} vs {want:?}");
            }
        }
    }

    #[test]
    fn shade_table_blend_is_bilinear_and_applies_like_the_shading_model() {
        let sh = Shading::default();
        let mut t = ShadeTable::default();
        assert!(t.update([0.0, 0.6, 0.8], sh));
        assert!(!t.update([0.0, 0.6, 0.8], sh), "same light and material: no rebuild");
        let codes = [encode_normal([0.0, 0.0, 1.0]), encode_normal([1.0, 0.0, 0.0]), encode_normal([0.0, 1.0, 0.0]), ZERO_NORMAL];
        for (i, &c) in codes.iter().enumerate() {
            let (wi, wj) = ((i & 1) as f32, (i >> 1) as f32);
            let (e, want) = (t.blend(codes, wi, wj), t.get(c));
            assert!((0..2).all(|a| (e[a] - want[a]).abs() < 1e-6), "corner {i}: {e:?} vs {want:?}");
        }
        let e = t.blend(codes, 0.25, 0.5);
        let want = [0, 1].map(|a| {
            let g = codes.map(|c| t.get(c)[a]);
            0.5 * (0.75 * g[0] + 0.25 * g[1]) + 0.5 * (0.75 * g[2] + 0.25 * g[3])
        });
        assert!((0..2).all(|a| (e[a] - want[a]).abs() < 1e-6), "{e:?} vs {want:?}");
        // the entry of a normal along the light is the shading model's at ndl = 1
        let up = t.get(encode_normal([0.0, 0.6, 0.8]));
        let rgb = [0.9, 0.5, 0.2];
        let (a, b) = (apply_shade(rgb, up), sh.shade(rgb, 1.0));
        assert!((0..3).all(|c| (a[c] - b[c]).abs() < 1e-3), "{a:?} vs {b:?}");
        assert_eq!(t.get(u16::MAX), t.get(NORMAL_CODES as u16 - 1));
    }
}
