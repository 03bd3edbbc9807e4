//! The shear state of the binary rotator: the translation arrays of the
//! slices (the shift vectors that move a sheared mask by them are
//! [`crate::encode::shift`]'s).
//!
//! Owns [`ShearState`]: the exact (f64) translation of every slice along both
//! in-slice axes, kept as the line through the two end slices (the paper's
//! `trans_x`, `trans_y` with end points `p0`, `p1`), and the integer part of each
//! translation, which is where the slice's bits sit in the sheared mask. The
//! incremental one-bit rotation step moves the two end points by one voxel in
//! opposite directions; every translation is then recomputed *in closed form*
//! from the end points (never accumulated), so nothing drifts.
//!
//! Derivation (the paper's listing has typos): slice `k` of `Z` slices sits on the
//! line from `(x0, 0)` to `(x1, l)`, `l = Z − 1`, so
//! `trans[k] = (x0·(l − k) + x1·k) / l`. A slice's bits move by
//! `floor(new) − floor(old)`, which is −1, 0 or +1 whenever the end points move by
//! at most one voxel, because `|Δtrans[k]| ≤ max(|Δx0|, |Δx1|)` (a convex
//! combination). The shift vectors hold one bit per slice for each direction; a
//! slice that does not move has its bit *cleared* (`&= !bit`, not `|= !bit`).

use crate::view::Factorization;

/// Translations of every slice along the two in-slice axes.
#[derive(Clone, Debug, PartialEq)]
pub struct ShearState {
    /// End-point translations `[x0, x1]` along i and `[y0, y1]` along j.
    pub ends: [[f64; 2]; 2],
    /// Exact translation of each slice along i and j.
    pub trans: [Vec<f64>; 2],
    /// `floor(trans)`: the integer offset of each slice (its bits' position).
    pub floor: [Vec<i32>; 2],
}

impl ShearState {
    /// The state with translations `trans[a][k] = s[a] · (k − kc)` of a factorized view.
    pub fn from_view(f: &Factorization) -> Self {
        let mut s = ShearState { ends: [[0.0; 2]; 2], trans: [vec![], vec![]], floor: [vec![], vec![]] };
        s.set_view(f);
        s
    }

    /// Overwrites this state with that of a factorized view, reusing the arrays
    /// (no allocation per frame once they have grown to the slice count).
    #[allow(clippy::needless_range_loop)] // the index picks one axis of several arrays
    pub fn set_view(&mut self, f: &Factorization) {
        let nk = f.n[2];
        for a in 0..2 {
            self.trans[a].clear();
            self.floor[a].clear();
        }
        for k in 0..nk {
            let t = f.trans(k);
            for a in 0..2 {
                self.trans[a].push(t[a]);
                self.floor[a].push(t[a].floor() as i32);
            }
        }
        self.ends = [0, 1].map(|a| [self.trans[a].first().copied().unwrap_or(0.0), self.trans[a].last().copied().unwrap_or(0.0)]);
    }

    /// The state whose slices lie on the lines through the given end points.
    pub fn from_ends(nk: usize, ends: [[f64; 2]; 2]) -> Self {
        let trans = [0, 1].map(|a| (0..nk).map(|k| line(ends[a], nk, k)).collect::<Vec<f64>>());
        Self::with_trans(ends, trans)
    }

    /// The unsheared state (all translations zero).
    pub fn identity(nk: usize) -> Self {
        Self::from_ends(nk, [[0.0; 2]; 2])
    }

    fn with_trans(ends: [[f64; 2]; 2], trans: [Vec<f64>; 2]) -> Self {
        let floor = [0, 1].map(|a| trans[a].iter().map(|t| t.floor() as i32).collect());
        ShearState { ends, trans, floor }
    }

    /// Number of slices.
    pub fn slices(&self) -> usize {
        self.trans[0].len()
    }

    /// One incremental rotation step about the in-slice axis perpendicular to
    /// `along` (0 = i, 1 = j): the first slice's end point moves by `−dir` and the
    /// last slice's by `+dir` voxels along `along`. Returns the new state.
    pub fn rotated(&self, along: usize, dir: i32) -> Self {
        let mut ends = self.ends;
        ends[along][0] -= dir as f64;
        ends[along][1] += dir as f64;
        Self::from_ends(self.slices(), ends)
    }

    /// Shear `s = (x1 − x0)/l` along each axis.
    pub fn shear(&self) -> [f64; 2] {
        let l = (self.slices() as f64 - 1.0).max(1.0);
        [0, 1].map(|a| (self.ends[a][1] - self.ends[a][0]) / l)
    }
}

/// Translation of slice `k` on the line through `ends`.
fn line(ends: [f64; 2], nk: usize, k: usize) -> f64 {
    if nk <= 1 {
        return ends[0];
    }
    let l = (nk - 1) as f64;
    (ends[0] * (l - k as f64) + ends[1] * k as f64) / l
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    #[allow(clippy::needless_range_loop)] // the index picks one axis of several arrays
    fn rotation_steps_stay_in_closed_form() {
        let nk = 113;
        let mut s = ShearState::identity(nk);
        let mut net = [0i64; 2];
        let mut seed = 7u64;
        for _ in 0..10_000 {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
            let along = (seed >> 33) as usize & 1;
            let dir = if (seed >> 40) & 1 == 0 { 1 } else { -1 };
            // stay within ±45°: |x1 − x0| ≤ l
            if ((net[along] + dir as i64) * 2).unsigned_abs() as usize > nk - 1 {
                continue;
            }
            let next = s.rotated(along, dir);
            for a in 0..2 {
                for k in 0..nk {
                    assert!((next.floor[a][k] - s.floor[a][k]).abs() <= 1, "a slice moved more than one bit");
                }
            }
            s = next;
            net[along] += dir as i64;
        }
        for a in 0..2 {
            for k in 0..nk {
                let closed = -(net[a] as f64) + 2.0 * net[a] as f64 * k as f64 / (nk - 1) as f64;
                assert!((s.trans[a][k] - closed).abs() < 1e-9);
            }
        }
    }
}
