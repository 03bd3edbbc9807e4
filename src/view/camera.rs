//! The camera and its standard views.
//!
//! Owns [`Camera`] (object-to-eye rotation, zoom, output size), rotations about
//! the eye's axes ([`rotate_eye`]), the named anatomical views ([`NamedView`]:
//! anterior, left, superior, …, for a volume whose index axes are RAS), the
//! benchmark's standard views ([`standard_views`]: around the 45° principal
//! axis switch, the main diagonal, seeded random rotations), and the rotation
//! step that moves the outermost slice by one voxel ([`one_bit_step_deg`]).
//! The library, the command line, the bench runner and the viewer all take
//! their views from here.

use glam::{DMat3, DQuat, DVec3};

/// Orthographic camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Object-to-eye rotation.
    pub rotation: DMat3,
    /// Pixels per world unit; `None` fits the volume's bounding diagonal to the image.
    pub zoom: Option<f64>,
    /// Output image width and height in pixels.
    pub size: [usize; 2],
}

impl Camera {
    /// A camera with the given rotation and output size, zoom to fit.
    pub fn new(rotation: DMat3, size: [usize; 2]) -> Self {
        Camera { rotation, zoom: None, size }
    }
}

/// Rotation by `deg` degrees about eye axis `axis` (0 = x, 1 = y, 2 = z), applied
/// after `base` (i.e. `R = R_axis(deg) · base`).
pub fn rotate_eye(base: DMat3, axis: usize, deg: f64) -> DMat3 {
    let a = deg.to_radians();
    let r = match axis {
        0 => DMat3::from_rotation_x(a),
        1 => DMat3::from_rotation_y(a),
        _ => DMat3::from_rotation_z(a),
    };
    r * base
}

/// The six named anatomical views: from where the viewer looks at the
/// patient. [`NamedView::rotation`] is the view of a volume whose index axes
/// are RAS (+x toward the patient's right, +y anterior, +z superior);
/// [`crate::data::orientation::view_rotation`] turns it into the view of a
/// volume whose axes lie elsewhere in the patient.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
pub enum NamedView {
    /// In front of the patient, facing them: the patient's right on the image left.
    Anterior,
    /// Behind the patient: the patient's right on the image right.
    Posterior,
    /// At the patient's left side.
    Left,
    /// At the patient's right side.
    Right,
    /// Above the head, looking down.
    Superior,
    /// Below the feet, looking up.
    Inferior,
}

impl NamedView {
    /// Every view.
    pub const ALL: [NamedView; 6] =
        [NamedView::Anterior, NamedView::Posterior, NamedView::Left, NamedView::Right, NamedView::Superior, NamedView::Inferior];

    /// The view's lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            NamedView::Anterior => "anterior",
            NamedView::Posterior => "posterior",
            NamedView::Left => "left",
            NamedView::Right => "right",
            NamedView::Superior => "superior",
            NamedView::Inferior => "inferior",
        }
    }

    /// The object-to-eye rotation of this view of a volume whose index axes are
    /// RAS (the RAS-to-eye rotation; eye x right, y up, the viewer at +z).
    pub fn rotation(self) -> DMat3 {
        // anterior: eye x = −object x (patient's right on the image left), eye y = object z, eye z = object y
        let anterior = DMat3::from_cols_array(&[-1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0]);
        match self {
            NamedView::Anterior => anterior,
            NamedView::Posterior => rotate_eye(anterior, 1, 180.0),
            NamedView::Left => rotate_eye(anterior, 1, -90.0),
            NamedView::Right => rotate_eye(anterior, 1, 90.0),
            NamedView::Superior => rotate_eye(anterior, 0, 90.0),
            NamedView::Inferior => rotate_eye(anterior, 0, -90.0),
        }
    }
}

/// Degrees per frame that move the outermost slice of the deepest axis of a
/// volume of `dims` voxels by one voxel.
pub fn one_bit_step_deg(dims: [usize; 3]) -> f64 {
    let h = dims.iter().map(|&n| (n as f64 - 1.0) / 2.0).fold(1.0, f64::max);
    (1.0 / h).to_degrees()
}

/// A named view.
#[derive(Clone, Debug, PartialEq)]
pub struct View {
    pub name: String,
    pub rotation: DMat3,
}

/// The rotation whose viewing direction is the world's main diagonal: the
/// viewer on the `(1, 1, 1)` side, eye y as close to world z as possible.
pub fn diagonal_view() -> DMat3 {
    let z = DVec3::ONE.normalize();
    let y = (DVec3::Z - z * z.z).normalize();
    let x = y.cross(z);
    DMat3::from_cols(x, y, z).transpose()
}

/// A uniformly distributed random rotation from three uniform deviates in [0, 1) (Shoemake).
fn uniform_rotation(u: [f64; 3]) -> DMat3 {
    use std::f64::consts::TAU;
    let (a, b) = ((1.0 - u[0]).sqrt(), u[0].sqrt());
    let q = DQuat::from_xyzw(a * (TAU * u[1]).sin(), a * (TAU * u[1]).cos(), b * (TAU * u[2]).sin(), b * (TAU * u[2]).cos());
    DMat3::from_quat(q.normalize())
}

/// The benchmark's views: `base` turned about the eye's vertical axis by 0°,
/// 22.5°, 44.9°, 45°, 45.1° and 60° (around the 45° principal-axis switch),
/// the world's main diagonal, and `random` seeded uniformly random rotations.
pub fn standard_views(base: DMat3, random: usize, seed: u64) -> Vec<View> {
    let mut v: Vec<View> =
        [0.0, 22.5, 44.9, 45.0, 45.1, 60.0].iter().map(|&a| View { name: format!("{a}°"), rotation: rotate_eye(base, 1, a) }).collect();
    v.push(View { name: "diagonal".into(), rotation: diagonal_view() });
    let mut s = seed;
    let mut next = || {
        // splitmix64
        s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = s;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    for i in 0..random {
        let u = [next(), next(), next()];
        v.push(View { name: format!("random-{}", i + 1), rotation: uniform_rotation(u) });
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::view::Factorization;

    #[test]
    fn views_are_rotations_and_deterministic() {
        let a = standard_views(DMat3::IDENTITY, 3, 7);
        assert_eq!(a, standard_views(DMat3::IDENTITY, 3, 7));
        assert_ne!(a[7].rotation, standard_views(DMat3::IDENTITY, 3, 8)[7].rotation);
        assert_eq!(a.len(), 10);
        for v in &a {
            let r = v.rotation;
            assert!((r.determinant() - 1.0).abs() < 1e-12 && (r * r.transpose()).abs_diff_eq(DMat3::IDENTITY, 1e-12), "{}", v.name);
        }
        // the diagonal view looks along −(1, 1, 1)
        let d = diagonal_view().transpose() * DVec3::NEG_Z;
        assert!((d + DVec3::ONE.normalize()).length() < 1e-12);
        assert_eq!(crate::view::principal_axis(d), 2);
        let f = Factorization::new(&Camera::new(diagonal_view(), [8, 8]), [5, 5, 5], [1.0; 3]).unwrap();
        assert!((f.shear[0].abs() - 1.0).abs() < 1e-12 && (f.shear[1].abs() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn named_views_are_proper_rotations() {
        for v in [NamedView::Anterior, NamedView::Posterior, NamedView::Left, NamedView::Right, NamedView::Superior, NamedView::Inferior] {
            let r = v.rotation();
            assert!((r.determinant() - 1.0).abs() < 1e-12);
        }
        // anterior: the viewer on the +y (anterior) side
        let eye_dir = NamedView::Anterior.rotation().transpose() * DVec3::Z;
        assert!((eye_dir - DVec3::Y).length() < 1e-12);
    }
}
