//! The per-view lookup tables of the pre-classified paths ([`ViewTables`]):
//! opacity-corrected premultiplied colour per class node, shade entry per
//! normal code.

use super::preclass::{Preclass, RleVoxel};
use crate::classify::TABLE_NODES;
use crate::classify::shading::Shading;
pub use crate::data::normals::{NORMAL_CODES, NORMAL_SIDE, ZERO_NORMAL, decode_normal, encode_normal, headlight_object};
use crate::data::normals::{ShadeTable, boxed};

/// The per-view lookup tables of the pre-classified paths. Fixed-size arrays
/// indexed with masks, so lookups need no bounds checks.
#[derive(Clone, Debug)]
pub struct ViewTables {
    /// Per class node: opacity-corrected premultiplied colour `[α'r, α'g, α'b, α']`.
    lut: Box<[[f32; 4]; TABLE_NODES]>,
    /// Per normal code (shared with the binary path's table shading).
    shade: ShadeTable,
    lut_key: Option<(u64, u32)>,
}

impl Default for ViewTables {
    fn default() -> Self {
        ViewTables { lut: boxed([0.0; 4]), shade: ShadeTable::default(), lut_key: None }
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
                let c = pre.rgb[i];
                *out = [a * c[0], a * c[1], a * c[2], a];
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
        let c = self.lut[v.class as usize & (TABLE_NODES - 1)];
        let [d, s] = self.shade.get(v.normal);
        // c·[d, d, d, 1] + α'·[s, s, s, 0]: the alpha lane stays α'
        let (dd, ss) = ([d, d, d, 1.0], [s, s, s, 0.0]);
        let mut out = [0f32; 4];
        for i in 0..4 {
            out[i] = c[i] * dd[i] + c[3] * ss[i];
        }
        out
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
