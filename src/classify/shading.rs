//! The one shading model: a two-sided Blinn-Phong headlight.
//!
//! Owns the material ([`Shading`]), the integer power every path raises
//! `|n·l|` to ([`pow_int`]), and `|n·l|` of a voxel-space gradient under the
//! headlight ([`headlight_ndl`]). The per-sample gradient shading of the ray
//! paths and the per-view shade table of the table-shaded paths
//! ([`crate::classify::shade_table::ShadeTable`]) both evaluate [`Shading::entry`] and [`apply_shade`], so a
//! normal shades the same everywhere.

/// Blinn-Phong material for a headlight (light and eye along the view direction,
/// so the half vector is the light vector).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shading {
    pub ambient: f32,
    pub diffuse: f32,
    pub specular: f32,
    pub shininess: i32,
}

impl Default for Shading {
    fn default() -> Self {
        Shading { ambient: 0.15, diffuse: 0.75, specular: 0.3, shininess: 20 }
    }
}

impl Shading {
    /// Shaded colour of `rgb` for a surface with `|n · l| = ndl`.
    #[inline(always)]
    pub fn shade(&self, rgb: [f32; 3], ndl: f32) -> [f32; 3] {
        apply_shade(rgb, self.entry(ndl, pow_int(ndl, self.shininess)))
    }

    /// The exponent of the specular term: a negative shininess counts as 0
    /// (a constant specular term), on every path.
    #[inline(always)]
    pub fn exponent(&self) -> u32 {
        self.shininess.max(0) as u32
    }

    /// The shade entry `[ambient + diffuse·ndl, specular·pow]` of a surface with
    /// `|n · l| = ndl` and `ndl^exponent = pow`.
    #[inline(always)]
    pub fn entry(&self, ndl: f32, pow: f32) -> ShadeEntry {
        [self.ambient + self.diffuse * ndl, self.specular * pow]
    }
}

/// A shade entry `[d, s]`: a colour shades to `rgb·d + s`.
pub type ShadeEntry = [f32; 2];

/// The colour of `rgb` under shade entry `e`: `rgb·d + s`.
#[inline(always)]
pub fn apply_shade(rgb: [f32; 3], e: ShadeEntry) -> [f32; 3] {
    [rgb[0] * e[0] + e[1], rgb[1] * e[0] + e[1], rgb[2] * e[0] + e[1]]
}

/// `x^n` by repeated squaring, inline (`f32::powi` is a libcall on x86-64).
/// Negative `n` gives 1: shininess exponents are never negative.
#[inline(always)]
pub fn pow_int(x: f32, n: i32) -> f32 {
    let (mut r, mut b, mut e) = (1.0f32, x, n.max(0) as u32);
    while e > 0 {
        if e & 1 == 1 {
            r *= b;
        }
        b *= b;
        e >>= 1;
    }
    r
}

/// `|n · l|` for a voxel-space gradient `g`: `m` maps it to the eye-space z
/// component (the headlight's direction), `scale` to world units (for the length).
/// A zero gradient faces the viewer.
#[inline(always)]
pub fn headlight_ndl(g: [f32; 3], m: [f32; 3], scale: [f32; 3]) -> f32 {
    let dot = g[0] * m[0] + g[1] * m[1] + g[2] * m[2];
    let (a, b, c) = (g[0] * scale[0], g[1] * scale[1], g[2] * scale[2]);
    let len2 = a * a + b * b + c * c;
    if len2 > 1e-30 { (dot.abs() / len2.sqrt()).min(1.0) } else { 1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pow_int_matches_powi() {
        for n in 0..40 {
            for x in [0.0f32, 0.3, 0.5, 0.9, 1.0] {
                let (a, b) = (pow_int(x, n), x.powi(n));
                assert!((a - b).abs() <= 1e-6 * b.abs().max(1e-30), "{x}^{n}: {a} vs {b}");
            }
        }
    }

    #[test]
    fn headlight_facing_and_grazing() {
        let m = [0.0, 0.0, 1.0];
        let s = [1.0; 3];
        assert_eq!(headlight_ndl([0.0, 0.0, -3.0], m, s), 1.0);
        assert_eq!(headlight_ndl([2.0, 0.0, 0.0], m, s), 0.0);
        assert_eq!(headlight_ndl([0.0; 3], m, s), 1.0);
        let sh = Shading::default();
        assert!(sh.shade([1.0; 3], 1.0)[0] > sh.shade([1.0; 3], 0.2)[0]);
    }

    #[test]
    fn a_negative_shininess_is_a_constant_specular_term_on_every_path() {
        let sh = Shading { shininess: -3, ..Shading::default() };
        assert_eq!(sh.exponent(), 0);
        assert_eq!(pow_int(0.5, -3), 1.0);
        // the gradient path and the table entry agree
        let ndl = 0.5;
        assert_eq!(sh.shade([0.2, 0.4, 0.6], ndl), apply_shade([0.2, 0.4, 0.6], sh.entry(ndl, 1.0)));
    }
}
