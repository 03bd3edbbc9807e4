//! Opacity correction for sample spacing: the table the pre-classified paths
//! correct their premultiplied samples with ([`OpacityTable`], a ray's place
//! in it [`RayRow`]), and the raycast paths' straight-alpha correction
//! ([`correct_alpha`], with its log2 and exp2 approximations). The frame plan
//! owns the table, so it lives with the view.

/// Opacity bins of an [`OpacityTable`] row over `α ∈ [0, 1]`.
const ALPHA_BINS: usize = 1024;
/// Most rows of an [`OpacityTable`]: past it, the rows are spaced wider.
const MAX_ROWS: usize = 1024;

/// The opacity correction of the pre-classified paths' premultiplied samples,
/// each already corrected to one sample spacing, to a ray whose spacing is
/// `e ≥ 1` times that: `α' = 1 − (1 − α)^e`, the colour scaled with it (`c·α'/α`,
/// so premultiplied colour is attenuated once). Without a log2 and an exp2 per
/// sample: the table holds `g(α, e) = α'/α` (`e` at `α = 0`) at `α = i / 1024`
/// and on a fixed lattice of exponents `e = 1 + r·h`, and
/// [`OpacityTable::correct`] interpolates it bilinearly and multiplies the
/// sample by it. With `h` = 1/64 (exponents up to 17; 4 kB a row) its largest
/// error in `α'` is below 2e-5, one 200th of a 1/255 step (the unit test
/// measures it); past that the rows are spaced wider (at most 1024 of them),
/// `h` = 1/32 up to `e` = 33 (6.4e-5), 1/16 up to 65 (2.5e-4). `e = 1` (every ray of a
/// parallel view, the rays near a perspective view's axis) returns the sample
/// unchanged, bit for bit; so do `α = 0` and `α = 1`.
///
/// The frame plan owns one ([`crate::view::plan::FramePlan::correct_opacity`]),
/// grown to its largest exponent as frames need it ([`OpacityTable::cover`]),
/// so the RLE slices and their brute force correct with the same numbers.
#[derive(Clone, Debug, Default)]
pub struct OpacityTable {
    /// Rows per unit of exponent (`1/h`; 0 while empty).
    per_unit: f32,
    /// Rows held (0 or at least 2).
    rows: usize,
    /// `g` by row, `ALPHA_BINS + 1` entries a row.
    g: Vec<f32>,
}

impl OpacityTable {
    /// Makes the table hold every exponent in `[1, e_max]` (only the rows it
    /// lacks are computed: a table that already does is left as it is).
    pub fn cover(&mut self, e_max: f32) {
        let span = if e_max.is_finite() { (e_max - 1.0).max(0.0) as f64 } else { 0.0 };
        let mut per_unit = 64.0f64;
        while span * per_unit > (MAX_ROWS - 2) as f64 {
            per_unit *= 0.5;
        }
        let rows = (span * per_unit).ceil() as usize + 2;
        if per_unit as f32 != self.per_unit {
            (self.per_unit, self.rows) = (per_unit as f32, 0);
            self.g.clear();
        }
        for r in self.rows..rows {
            let e = 1.0 + r as f64 / per_unit;
            self.g.extend((0..=ALPHA_BINS).map(|i| {
                let a = i as f64 / ALPHA_BINS as f64;
                match (r, i) {
                    (0, _) => 1.0,
                    (_, 0) => e as f32,
                    _ => ((1.0 - (1.0 - a).powf(e)) / a) as f32,
                }
            }));
        }
        self.rows = self.rows.max(rows);
    }

    /// Sample `s` corrected to exponent `e` (in `[1, e_max]` of
    /// [`OpacityTable::cover`]).
    #[inline(always)]
    pub fn correct(&self, s: [f32; 4], e: f32) -> [f32; 4] {
        if e == 1.0 || self.rows < 2 {
            return s;
        }
        self.correct_row(s, self.row(e))
    }

    /// Where exponent `e` (in `[1, e_max]` of [`OpacityTable::cover`], which
    /// has been called) lies in the table: [`OpacityTable::correct_row`]
    /// with it is [`OpacityTable::correct`] with `e`, bit for bit, so a ray's
    /// row can be found once for all its samples.
    #[inline]
    pub fn row(&self, e: f32) -> RayRow {
        let (r, fe) = table_cell((e - 1.0) * self.per_unit);
        RayRow { at: (r.min(self.rows.max(2) - 2) * (ALPHA_BINS + 1)) as u32, fe }
    }

    /// Sample `s` corrected on the ray whose exponent is at `row`
    /// ([`OpacityTable::row`]). Exponent 1 (row 0, no fraction) returns `s`
    /// itself: that row is all ones.
    #[inline(always)]
    pub fn correct_row(&self, s: [f32; 4], row: RayRow) -> [f32; 4] {
        let a = s[3];
        if !(a > 0.0 && a < 1.0) {
            return s;
        }
        const W: usize = ALPHA_BINS + 1;
        let (i, fa) = table_cell(a * ALPHA_BINS as f32);
        let at = row.at as usize + i;
        let (g0, g1) = (&self.g[at..][..2], &self.g[at + W..][..2]);
        let lo = g0[0] + fa * (g0[1] - g0[0]);
        let hi = g1[0] + fa * (g1[1] - g1[0]);
        let g = lo + row.fe * (hi - lo);
        [s[0] * g, s[1] * g, s[2] * g, (a * g).min(1.0)]
    }
}

/// A ray's place in an [`OpacityTable`]: the offset of its exponent's lower
/// row and the fraction towards the next ([`OpacityTable::row`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RayRow {
    at: u32,
    fe: f32,
}

/// The lower corner of the table cell holding `x ≥ 0` (`x < 2²²`) and the
/// fraction past it, by rounding `x − ½` to an integer: adding 1.5·2²³ leaves
/// it in the low mantissa bits (the sum stays in `[2²³, 2²⁴)`, where f32 steps
/// by 1; a floor or a float-to-integer cast costs several instructions more).
#[inline(always)]
fn table_cell(x: f32) -> (usize, f32) {
    const MAGIC: f32 = 12_582_912.0;
    let b = x - 0.5 + MAGIC;
    ((b.to_bits() & 0x3f_ffff) as usize, x - (b - MAGIC))
}

/// The opacity `α` of one sample spacing corrected to `e` spacings,
/// `1 − (1 − α)^e`, to about 2e-7 (the raycast paths' straight-alpha samples;
/// `e = 1` and `α` of 0 or 1 return `α` bit for bit).
#[inline(always)]
pub fn correct_alpha(a: f32, e: f32) -> f32 {
    if e == 1.0 || !(a > 0.0 && a < 1.0) {
        return a;
    }
    1.0 - exp2_approx(e * log2_approx(1.0 - a))
}

/// `log2 x` for a normal `x > 0`, to about 1e-7 relative: the exponent from
/// the bits, the mantissa reduced to `[√½, √2)` and `2·atanh(t)/ln 2` with
/// `t = (m − 1)/(m + 1)` (`|t| ≤ 0.172`) to `t⁹`. Plain f32 arithmetic: the same
/// bits on every path and thread.
#[inline(always)]
fn log2_approx(x: f32) -> f32 {
    let bits = x.to_bits();
    let mut e = ((bits >> 23) & 0xff) as i32 - 127;
    let mut m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    if m > std::f32::consts::SQRT_2 {
        m *= 0.5;
        e += 1;
    }
    let t = (m - 1.0) / (m + 1.0);
    let t2 = t * t;
    let p = t * (2.0 + t2 * (2.0 / 3.0 + t2 * (2.0 / 5.0 + t2 * (2.0 / 7.0 + t2 * (2.0 / 9.0)))));
    e as f32 + p * std::f32::consts::LOG2_E
}

/// `2^y` for `y ≤ 0`, to about 2e-7 relative (0 below `2^−126`): `2^round(y)`
/// from the bits times the Taylor series of `e^(f·ln 2)`, `|f| ≤ 1/2`, to `f⁶`.
#[inline(always)]
fn exp2_approx(y: f32) -> f32 {
    // (NaN takes the first branch too)
    if y.is_nan() || y <= -126.0 {
        return 0.0;
    }
    // an integer within 1/2 of y (y ≤ 0; truncation of a positive number, not
    // a call to round, which the x86-64 baseline has no instruction for)
    let i = -((0.5 - y) as i32 as f32);
    let x = (y - i) * std::f32::consts::LN_2;
    let p = 1.0 + x * (1.0 + x * (0.5 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x * (1.0 / 120.0 + x * (1.0 / 720.0))))));
    p * f32::from_bits(((i as i32 + 127) as u32) << 23)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A wider span of exponents spaces the rows wider; a narrower one keeps them.
    #[test]
    fn rows_follow_the_span_of_exponents() {
        let mut table = OpacityTable::default();
        table.cover(3.0);
        table.cover(1.5);
        assert_eq!((table.per_unit, table.rows), (64.0, 130));
        table.cover(30.0);
        assert!(table.per_unit == 32.0 && table.rows <= MAX_ROWS);
        for (a, e) in [(0.25f32, 20.0f32), (0.01, 1.01), (0.5, 1.0234)] {
            let want = 1.0 - (1.0 - a as f64).powf(e as f64);
            assert!((table.correct([a; 4], e)[3] as f64 - want).abs() < 7e-5);
        }
        assert!((log2_approx(1e-30) as f64 - (1e-30f64).log2()).abs() < 1e-4);
        assert_eq!(exp2_approx(-200.0), 0.0);
    }
}
