//! Patient orientation: where the voxel index axes point in the patient, and
//! the named anatomical views (`anterior`, `left`, `superior`, …) that follow
//! from it.
//!
//! Conventions:
//! - Patient coordinates are **RAS** millimetres: +x toward the patient's
//!   right, +y anterior, +z superior (NIfTI's world space; DICOM and most NRRD
//!   files use LPS, which is RAS with x and y negated — the loaders convert).
//! - A [`PatientFrame`] holds the unit direction of each voxel index axis in
//!   RAS (the columns of [`PatientFrame::directions`]) and the RAS position of
//!   the centre of voxel (0, 0, 0). Spacing stays per index axis, on the
//!   [`Volume`](crate::Volume).
//! - An **orientation code** names, for index axes x, y, z in turn, the
//!   anatomical direction each points toward (the NIfTI / ITK "to" reading):
//!   `LPS` = x toward the left, y posterior, z superior; `RAS`; `LAS`; …
//! - A volume's frame is always **right-handed** (det +1): a file whose index
//!   axes are mirrored relative to the patient (det −1, e.g. `LAS`) has one
//!   voxel axis reversed when the frame is attached
//!   ([`Volume::set_frame`](crate::Volume::set_frame)), so the renderer's
//!   rotations stay proper and the picture is never mirrored.
//! - Oblique (tilted) grids are fine; a skewed (non-orthogonal) grid is
//!   approximated by the nearest orthonormal frame and the skew is reported.
//!
//! The object-to-eye rotation of a named view is
//! `view_in_RAS · directions` ([`view_rotation`]): the world of the render
//! core is the index frame scaled by the spacing, and `directions` maps it
//! onto RAS.

use glam::{DMat3, DVec3};

use crate::error::{Error, Result};
use crate::view::NamedView;

/// The index-to-patient transform of a volume, in RAS millimetres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PatientFrame {
    /// Column `a` is the unit RAS direction of voxel index axis `a`
    /// (orthonormal; det +1 once attached to a volume).
    pub directions: DMat3,
    /// RAS position (mm) of the centre of voxel (0, 0, 0).
    pub origin: DVec3,
    /// The index axis reversed when the frame was attached because the file's
    /// axes were mirrored relative to the patient (`None` when they were not).
    pub reversed_axis: Option<usize>,
    /// How far (degrees) the file's axes were from orthogonal before they were
    /// replaced by the nearest orthonormal frame (0 for ordinary scans).
    pub skew_deg: f64,
}

/// The object-to-eye rotation (for [`Camera::rotation`](crate::view::Camera))
/// that shows `view` of a volume whose index axes are placed in the patient by
/// `frame`. Without a frame (raw and .den files, unless told) the index axes
/// are taken to be RAS.
///
/// Always a proper rotation: a frame attached to a volume is right-handed.
pub fn view_rotation(view: NamedView, frame: Option<&PatientFrame>) -> DMat3 {
    let v = view.rotation();
    match frame {
        Some(f) => orthonormalize(v * f.directions),
        None => v,
    }
}

/// The RAS direction of each anatomical letter.
fn letter_dir(c: char) -> Option<DVec3> {
    Some(match c.to_ascii_uppercase() {
        'R' => DVec3::X,
        'L' => -DVec3::X,
        'A' => DVec3::Y,
        'P' => -DVec3::Y,
        'S' => DVec3::Z,
        'I' => -DVec3::Z,
        _ => return None,
    })
}

/// Parses an orientation code such as `RAS`, `LPS`, `LAS` or `PIR`: three
/// letters, one of R/L, one of A/P and one of S/I, naming where index axes
/// x, y, z point. Returns the direction matrix (columns in RAS).
pub fn parse_code(code: &str) -> Result<DMat3> {
    let bad = || {
        Error::value(
            "orientation",
            format!(
                "'{code}': expected three letters naming where the x, y and z index axes point, one of R/L, one of A/P and \
                 one of S/I (e.g. RAS, LPS, LAS)"
            ),
        )
    };
    let dirs: Vec<DVec3> = code.trim().chars().map(letter_dir).collect::<Option<_>>().ok_or_else(bad)?;
    if dirs.len() != 3 {
        return Err(bad());
    }
    let m = DMat3::from_cols(dirs[0], dirs[1], dirs[2]);
    if m.determinant().abs() < 0.5 {
        return Err(bad());
    }
    Ok(m)
}

/// The orientation code of a direction matrix (columns in RAS): for each
/// index axis the letter of the anatomical direction it is closest to.
pub fn code_of(directions: &DMat3) -> String {
    let mut used = [false; 3];
    let mut out = String::new();
    for a in 0..3 {
        let c = directions.col(a);
        // the largest component not yet taken by an earlier axis
        let (mut best, mut best_abs) = (0usize, -1.0);
        for (k, &u) in used.iter().enumerate() {
            if !u && c[k].abs() > best_abs {
                best = k;
                best_abs = c[k].abs();
            }
        }
        used[best] = true;
        let pos = c[best] >= 0.0;
        out.push(match (best, pos) {
            (0, true) => 'R',
            (0, false) => 'L',
            (1, true) => 'A',
            (1, false) => 'P',
            (_, true) => 'S',
            (_, false) => 'I',
        });
    }
    out
}

/// The nearest orthonormal matrix (polar decomposition by Newton iteration):
/// keeps the sign of the determinant.
fn orthonormalize(m: DMat3) -> DMat3 {
    let mut q = m;
    for _ in 0..60 {
        let Some(inv_t) = (q.determinant().abs() > 1e-12).then(|| q.inverse().transpose()) else {
            break;
        };
        let next = (q + inv_t) * 0.5;
        let done = (next - q).to_cols_array().iter().all(|d| d.abs() < 1e-15);
        q = next;
        if done {
            break;
        }
    }
    q
}

impl PatientFrame {
    /// The RAS frame: index axes along R, A, S, voxel (0,0,0) at the origin.
    pub fn ras() -> Self {
        PatientFrame { directions: DMat3::IDENTITY, origin: DVec3::ZERO, reversed_axis: None, skew_deg: 0.0 }
    }

    /// A frame from an orientation code (see [`parse_code`]), origin 0.
    pub fn from_code(code: &str) -> Result<Self> {
        Ok(PatientFrame { directions: parse_code(code)?, ..PatientFrame::ras() })
    }

    /// A frame from the RAS vectors of one voxel step along each index axis
    /// (any length: NRRD `space directions`, a NIfTI affine's columns, DICOM
    /// cosines) and the RAS position of voxel (0, 0, 0).
    ///
    /// The vectors are normalised; a skewed set is replaced by the nearest
    /// orthonormal frame (its skew is recorded). The result may be left-handed
    /// until it is attached to a volume with [`Volume::set_frame`](crate::Volume::set_frame).
    /// Zero, non-finite or (nearly) coplanar vectors are an error.
    pub fn from_axes(axes: [DVec3; 3], origin: DVec3) -> Result<Self> {
        let bad = |why: &str| Error::value("orientation", format!("index axis directions {axes:?}: {why}"));
        if axes.iter().any(|a| !a.is_finite()) || !origin.is_finite() {
            return Err(bad("not finite"));
        }
        let mut cols = [DVec3::ZERO; 3];
        for (c, a) in cols.iter_mut().zip(&axes) {
            let n = a.length();
            if !(n > 0.0 && n.is_finite()) {
                return Err(bad("a direction is zero"));
            }
            *c = *a / n;
        }
        let m = DMat3::from_cols(cols[0], cols[1], cols[2]);
        if m.determinant().abs() < 1e-3 {
            return Err(bad("the directions are (nearly) coplanar"));
        }
        let q = orthonormalize(m);
        let skew_deg = (0..3).map(|a| m.col(a).dot(q.col(a)).clamp(-1.0, 1.0).acos().to_degrees()).fold(0.0, f64::max);
        Ok(PatientFrame { directions: q, origin, reversed_axis: None, skew_deg })
    }

    /// True when the index axes are mirrored relative to the patient (det < 0).
    pub fn is_mirrored(&self) -> bool {
        self.directions.determinant() < 0.0
    }

    /// The index axis to reverse to unmirror a mirrored frame: the one closest
    /// to the patient's left–right axis.
    pub fn mirror_axis(&self) -> usize {
        (0..3).max_by(|&a, &b| self.directions.col(a).x.abs().total_cmp(&self.directions.col(b).x.abs()).then(b.cmp(&a))).unwrap_or(0)
    }

    /// The right-handed frame a volume of `dims` voxels `spacing` apart
    /// carries for this one, and the index axis its voxels are reversed
    /// along to get it (`None`: the frame is not mirrored, nothing moves).
    pub fn unmirrored(&self, dims: [usize; 3], spacing: [f32; 3]) -> (PatientFrame, Option<usize>) {
        if self.is_mirrored() {
            let a = self.mirror_axis();
            (self.reversed(a, dims[a], spacing[a]), Some(a))
        } else {
            (*self, None)
        }
    }

    /// The same placement with index axis `axis` (of `n` voxels, `spacing` mm
    /// apart) reversed: the old last voxel becomes voxel 0.
    pub fn reversed(&self, axis: usize, n: usize, spacing: f32) -> Self {
        let a = axis.min(2);
        let d = self.directions.col(a);
        let mut cols = [self.directions.x_axis, self.directions.y_axis, self.directions.z_axis];
        cols[a] = -d;
        PatientFrame {
            directions: DMat3::from_cols(cols[0], cols[1], cols[2]),
            origin: self.origin + d * (spacing as f64 * n.saturating_sub(1) as f64),
            reversed_axis: Some(a),
            skew_deg: self.skew_deg,
        }
    }

    /// The orientation code of the index axes (nearest letters when oblique).
    pub fn code(&self) -> String {
        code_of(&self.directions)
    }

    /// The code the file's own axes had (differs from [`PatientFrame::code`]
    /// in the reversed axis when the frame was unmirrored).
    pub fn stored_code(&self) -> String {
        match self.reversed_axis {
            Some(a) => {
                let mut m = self.directions;
                let c = -m.col(a);
                match a {
                    0 => m.x_axis = c,
                    1 => m.y_axis = c,
                    _ => m.z_axis = c,
                }
                code_of(&m)
            }
            None => self.code(),
        }
    }

    /// The largest angle (degrees) between an index axis and the nearest
    /// patient axis: 0 for axis-aligned scans, more for tilted (oblique) ones.
    pub fn obliquity_deg(&self) -> f64 {
        (0..3)
            .map(|a| {
                let c = self.directions.col(a);
                c.abs().max_element().clamp(-1.0, 1.0).acos().to_degrees()
            })
            .fold(0.0, f64::max)
    }

    /// The RAS frame centred on the origin for a volume of `dims` voxels
    /// `spacing` apart (how the built-in phantoms are placed).
    pub fn centred_ras(dims: [usize; 3], spacing: [f32; 3]) -> Self {
        let origin = DVec3::from_array(std::array::from_fn(|a| -(dims[a] as f64 - 1.0) / 2.0 * spacing[a] as f64));
        PatientFrame { origin, ..PatientFrame::ras() }
    }

    /// One line for reports: the code, where each index axis points, and any
    /// reversal, obliquity or skew, e.g. `LPS (index x → left, y → posterior,
    /// z → superior)`.
    pub fn describe(&self) -> String {
        let word = |c: char| match c {
            'R' => "right",
            'L' => "left",
            'A' => "anterior",
            'P' => "posterior",
            'S' => "superior",
            _ => "inferior",
        };
        let code = self.code();
        let axes: Vec<String> = code.chars().zip(["x", "y", "z"]).map(|(c, a)| format!("{a} → {}", word(c))).collect();
        let mut notes = vec![format!("index {}", axes.join(", "))];
        if let Some(a) = self.reversed_axis {
            notes.push(format!(
                "stored {}: the {} axis was reversed on load so the picture is not mirrored",
                self.stored_code(),
                ["x", "y", "z"][a]
            ));
        }
        if self.obliquity_deg() > 0.01 {
            notes.push(format!("oblique: up to {:.1}° off the patient axes", self.obliquity_deg()));
        }
        if self.skew_deg > 0.01 {
            notes.push(format!("skewed grid, drawn with the nearest orthogonal axes ({:.2}° off)", self.skew_deg));
        }
        format!("{code} ({})", notes.join("; "))
    }

    /// The origin in LPS (DICOM's patient coordinates).
    pub fn origin_lps(&self) -> DVec3 {
        DVec3::new(-self.origin.x, -self.origin.y, self.origin.z)
    }
}

/// What reports say about a volume without orientation.
pub const UNKNOWN: &str = "unknown (this format carries none): named views take the index axes as RAS; set it with --orientation CODE";

/// Converts an LPS vector (DICOM, NRRD `left-posterior-superior`) to RAS.
pub fn lps_to_ras(v: DVec3) -> DVec3 {
    DVec3::new(-v.x, -v.y, v.z)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn close(a: DMat3, b: DMat3) -> bool {
        a.abs_diff_eq(b, 1e-9)
    }

    #[test]
    fn codes_parse_and_print() {
        for code in ["RAS", "LPS", "LAS", "PIR", "SAL", "ras"] {
            let m = parse_code(code).unwrap();
            assert_eq!(code_of(&m), code.to_ascii_uppercase());
        }
        for bad in ["", "RA", "RAR", "RLS", "XYZ", "RASS", "R A S"] {
            assert!(parse_code(bad).is_err(), "{bad}");
        }
        assert!(parse_code("LAS").unwrap().determinant() < 0.0);
        assert!(parse_code("LPS").unwrap().determinant() > 0.0);
    }

    #[test]
    fn views_are_proper_and_the_anterior_view_faces_the_patient() {
        for v in NamedView::ALL {
            let r = v.rotation();
            assert!((r.determinant() - 1.0).abs() < 1e-12, "{v:?}");
        }
        let a = NamedView::Anterior.rotation();
        // anterior toward the viewer, superior up, the patient's right on the image left
        assert!(close(DMat3::from_cols(a * DVec3::X, a * DVec3::Y, a * DVec3::Z), a));
        assert_eq!(a * DVec3::Y, DVec3::Z);
        assert_eq!(a * DVec3::Z, DVec3::Y);
        assert_eq!(a * DVec3::X, -DVec3::X);
        // left view: the patient's left toward the viewer
        let l = NamedView::Left.rotation();
        assert!((l * -DVec3::X).abs_diff_eq(DVec3::Z, 1e-12), "{:?}", l * -DVec3::X);
        assert!((NamedView::Superior.rotation() * DVec3::Z).abs_diff_eq(DVec3::Z, 1e-12));
        assert!((NamedView::Posterior.rotation() * -DVec3::Y).abs_diff_eq(DVec3::Z, 1e-12));
    }

    #[test]
    fn lps_volume_views_match_ras_in_the_patient() {
        // an LPS index frame is RAS turned 180° about S: the rotation must undo it
        let lps = PatientFrame::from_code("LPS").unwrap();
        let r = view_rotation(NamedView::Anterior, Some(&lps));
        // index +y points posterior: it must point away from the viewer
        assert!((r * DVec3::Y).abs_diff_eq(-DVec3::Z, 1e-12));
        assert!((r.determinant() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn mirrored_frames_reverse_the_left_right_axis() {
        let las = PatientFrame::from_code("LAS").unwrap();
        assert!(las.is_mirrored());
        assert_eq!(las.mirror_axis(), 0);
        let f = las.reversed(0, 10, 2.0);
        assert!(!f.is_mirrored());
        assert_eq!(f.code(), "RAS");
        assert_eq!(f.stored_code(), "LAS");
        // voxel 9 of the old x axis (at L 18 mm) is the new voxel 0
        assert!(f.origin.abs_diff_eq(DVec3::new(-18.0, 0.0, 0.0), 1e-12));
        // sagittal: index z runs left-right
        let f = PatientFrame::from_code("ASL").unwrap();
        assert_eq!(f.mirror_axis(), 2);
    }

    #[test]
    fn oblique_and_skewed_axes_become_orthonormal() {
        let t = 20f64.to_radians();
        let x = DVec3::new(t.cos(), t.sin(), 0.0) * 0.7;
        let y = DVec3::new(-t.sin(), t.cos(), 0.0) * 0.7;
        let z = DVec3::new(0.0, 0.0, 3.0);
        let f = PatientFrame::from_axes([x, y, z], DVec3::ZERO).unwrap();
        assert!(f.skew_deg < 1e-9);
        assert!((f.obliquity_deg() - 20.0).abs() < 1e-9);
        assert_eq!(f.code(), "RAS");
        let f = PatientFrame::from_axes([x, y + x * 0.05, z], DVec3::ZERO).unwrap();
        assert!(f.skew_deg > 0.5 && f.skew_deg < 3.0, "{}", f.skew_deg);
        assert!((f.directions.transpose() * f.directions).abs_diff_eq(DMat3::IDENTITY, 1e-12));
        assert!((view_rotation(NamedView::Left, Some(&f)).determinant() - 1.0).abs() < 1e-12);
        assert!(PatientFrame::from_axes([x, x, z], DVec3::ZERO).is_err());
        assert!(PatientFrame::from_axes([x, DVec3::ZERO, z], DVec3::ZERO).is_err());
        assert!(PatientFrame::from_axes([x, y, DVec3::NAN], DVec3::ZERO).is_err());
    }
}
