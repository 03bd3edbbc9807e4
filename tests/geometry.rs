//! Geometry in the volume through the frame plan (issue 23): a mesh's
//! inverse-warped depth limits every path the same way.

mod common;

use std::sync::Arc;

use common::{bits, blobs, render, renderer};
use glam::{DMat3, DVec3, EulerRot};
use shearwarp::classify::TransferFunction;
use shearwarp::composite::Mode;
use shearwarp::geometry::{Cull, GeometryImage, GeometryLimits, Material, Mesh, Projector, composite_over_geometry, rasterize};
use shearwarp::render::Method;
use shearwarp::view::{Camera, Projection};

/// Accelerated equals brute force with geometry, bit for bit: the binary
/// rotator and its brute force, the RLE path and its brute force, in iso and
/// blend mode, parallel and perspective, with a needle and a plate limiting
/// the rays; the geometry changes the image (it is really in the way), and
/// the final image composes the volume over the geometry's colour.
#[test]
fn geometry_accelerated_equals_brute_force() {
    let dims = [30, 26, 22];
    let vol = blobs(dims, 7, [1.0; 3]);
    let tf = TransferFunction::new(vec![(40.0, 0.0), (90.0, 0.6)], vec![(0.0, [1.0, 0.9, 0.8])]).unwrap();
    let c = DVec3::new(14.5, 12.5, 10.5);
    let mut mesh = Mesh::cylinder(c - DVec3::new(20.0, 4.0, 6.0), c + DVec3::new(18.0, 5.0, 7.0), 2.5, 24).unwrap();
    let plate = Mesh::cuboid(DVec3::new(-5.0, -5.0, 11.0), DVec3::new(35.0, 31.0, 12.5)).unwrap();
    let n = mesh.vertices.len() as u32;
    mesh.vertices.extend(plate.vertices);
    mesh.triangles.extend(plate.triangles.iter().map(|t| t.map(|i| i + n)));
    for (rx, ry, rz) in [(0.3, -0.6, 0.2), (1.1, 0.4, -0.9), (-0.5, 2.6, 0.7)] {
        let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, rx, ry, rz), [72, 64]);
        for projection in [Projection::Parallel, Projection::perspective(45.0, 1.8).unwrap()] {
            let proj = Projector::new(&cam, &projection, dims, [1.0; 3]).unwrap();
            let mut geo = GeometryImage::new(72, 64);
            rasterize(&mesh, &Material::default(), Cull::Back, &proj, &mut geo).unwrap();
            assert!(geo.coverage() > 0.1);
            let limits = Arc::new(GeometryLimits::new(proj, &geo));
            for mode in [Mode::Iso, Mode::Blend] {
                let iso = if mode == Mode::Iso { Some(60.0) } else { None };
                let frame = |method: Method, limited: bool| {
                    let mut r = renderer(&vol, &tf, method, mode, projection);
                    if let Some(t) = iso {
                        r.set_iso(t).unwrap();
                    }
                    if limited {
                        r.set_limiter(Some(limits.clone()));
                    }
                    render(&mut r, &cam)
                };
                let what = format!("{projection:?} {mode:?} ({rx}, {ry}, {rz})");
                let binary = frame(Method::Binary, true);
                assert_eq!(bits(&binary), bits(&frame(Method::Brute, true)), "binary vs brute, {what}");
                let rle = frame(Method::Rle, true);
                assert_eq!(bits(&rle), bits(&frame(Method::BruteRle, true)), "rle vs brute-rle, {what}");
                assert_ne!(bits(&binary), bits(&frame(Method::Binary, false)), "the geometry changes nothing, {what}");
                // the final image: the volume over the geometry, opaque where the geometry is
                let mut out = binary.clone();
                composite_over_geometry(&mut out, &geo);
                for (o, (v, g)) in out.data.iter().zip(binary.data.iter().zip(&geo.color)) {
                    if g[3] == 1.0 {
                        assert!((o[3] - 1.0).abs() < 1e-6, "{what}: not opaque over the geometry");
                    } else {
                        assert_eq!(o, v, "{what}: changed where no geometry is");
                    }
                }
            }
        }
    }
}
