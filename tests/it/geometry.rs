//! Geometry in the volume through the frame plan: a mesh's
//! inverse-warped depth limits every path the same way.

use crate::common;

use std::sync::Arc;

use common::{bits, blobs, render, renderer};
use glam::{DMat3, DVec3, EulerRot};
use shearwarp::accuracy::truth::cylinder_hit;
use shearwarp::classify::TransferFunction;
use shearwarp::composite::Mode;
use shearwarp::geometry::{Cull, GeometryImage, GeometryLimits, Material, Mesh, Projector, composite_over_geometry, rasterize};
use shearwarp::render::Method;
use shearwarp::view::{Camera, Projection};

/// Accelerated equals brute force with geometry, bit for bit: the binary
/// rotator and its brute force, the RLE path and its brute force, in iso and
/// blend mode (iso also with the crossing slice kept), parallel and
/// perspective, with a needle and a plate limiting the rays; the geometry changes the image (it is really in the way), and
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
            // iso mode also with the crossing slice kept (the scene's iso limits on the raycaster)
            for (mode, crossing) in [(Mode::Iso, false), (Mode::Iso, true), (Mode::Blend, false)] {
                let limits = Arc::new(GeometryLimits::new(proj, &geo).with_iso_crossing(crossing));
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
                let what = format!("{projection:?} {mode:?} crossing {crossing} ({rx}, {ry}, {rz})");
                let binary = frame(Method::Binary, true);
                assert_eq!(bits(&binary), bits(&frame(Method::Brute, true)), "binary vs brute, {what}");
                let rle = frame(Method::Rle, true);
                assert_eq!(bits(&rle), bits(&frame(Method::BruteRle, true)), "rle vs brute-rle, {what}");
                assert_ne!(bits(&binary), bits(&frame(Method::Binary, false)), "the geometry changes nothing, {what}");
                // the final image: the volume over the geometry, opaque where the geometry is
                let mut out = binary.clone();
                composite_over_geometry(&mut out, &geo);
                for (o, (v, g)) in out.data.iter().zip(binary.data.iter().zip(geo.color())) {
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

/// A mesh entirely in front of, behind and inside the opaque sphere phantom
/// (binary iso and RLE blend, parallel and perspective): in front, the
/// volume composites nothing where the mesh covers and the final image is the
/// mesh there; behind, the volume's pixels are the plain render bit for bit
/// and the mesh shows only where the volume is transparent; inside the ball
/// (hidden by its surface), the final image is the plain render bit for bit
/// wherever the sphere is opaque.
#[test]
fn geometry_mesh_in_front_behind_and_inside_the_volume() {
    use shearwarp::data::phantom::{SPHERE_ISO, sphere, sphere_geometry};
    use shearwarp::render::{Renderer, Settings};
    use shearwarp::warp::Image;
    let dims = [40, 40, 40];
    let vol = sphere(dims).unwrap();
    let (c, radius) = sphere_geometry(dims);
    let c = DVec3::from_array(c);
    let cam = Camera::new(DMat3::from_euler(EulerRot::XYZ, 0.3, -0.5, 0.1), [64, 64]);
    // the view direction in voxel space: the camera looks along −z of eye space
    let toward_eye = cam.rotation.transpose() * DVec3::Z;
    let plate_at = |offset: f64| {
        // a square plate facing the eye, `offset` voxels from the centre toward it
        let (u, v) = (toward_eye.any_orthonormal_pair().0 * 60.0, toward_eye.any_orthonormal_pair().1 * 60.0);
        let o = c + toward_eye * offset;
        let vs = vec![o - u - v, o + u - v, o + u + v, o - u + v];
        let mut m = Mesh::new(vs, vec![[0, 1, 2], [0, 2, 3]]).unwrap();
        // wound to face the eye
        if (m.vertices[1] - m.vertices[0]).cross(m.vertices[2] - m.vertices[0]).dot(toward_eye) < 0.0 {
            m.triangles = vec![[0, 2, 1], [0, 3, 2]];
        }
        m
    };
    let inside = Mesh::cuboid(c - DVec3::splat(radius * 0.4), c + DVec3::splat(radius * 0.4)).unwrap();
    for projection in [Projection::Parallel, Projection::perspective(40.0, 2.5).unwrap()] {
        for (method, mode) in [(Method::Binary, Mode::Iso), (Method::Rle, Mode::Blend)] {
            let tf = TransferFunction::threshold(SPHERE_ISO, [1.0; 3]);
            let mut r = Renderer::new(vol.clone(), &tf, Settings { method, mode, threads: 2, ..Settings::default() }).unwrap();
            r.set_iso(SPHERE_ISO).unwrap();
            r.set_projection(projection).unwrap();
            let mut plain = Image::new(64, 64);
            r.render(&cam, &mut plain).unwrap();
            let proj = Projector::new(&cam, &projection, dims, [1.0; 3]).unwrap();
            for (name, mesh) in [("front", plate_at(radius + 6.0)), ("behind", plate_at(-radius - 6.0)), ("inside", inside.clone())] {
                let mut geo = GeometryImage::new(64, 64);
                rasterize(&mesh, &Material::default(), Cull::None, &proj, &mut geo).unwrap();
                assert!(geo.coverage() > 0.01, "{name}: the mesh is on screen ({})", geo.coverage());
                r.set_limiter(Some(Arc::new(GeometryLimits::new(proj, &geo))));
                let mut img = Image::new(64, 64);
                r.render(&cam, &mut img).unwrap();
                r.set_limiter(None);
                let vol_img = img.clone();
                composite_over_geometry(&mut img, &geo);
                let ctx = format!("{name} {projection:?} {method:?}");
                for (i, (&v, &p)) in vol_img.data.iter().zip(&plain.data).enumerate() {
                    let covered = geo.depth()[i].is_finite();
                    match name {
                        "front" if covered => {
                            assert_eq!(v, [0.0; 4], "{ctx}: pixel {i}: the volume behind the plate composites nothing");
                            assert_eq!(img.data[i], geo.color()[i], "{ctx}: pixel {i} is the plate");
                        }
                        "behind" | "inside" => {
                            assert_eq!(v, p, "{ctx}: pixel {i}: the volume in front of the mesh is the plain render");
                            if p[3] >= 1.0 {
                                assert_eq!(img.data[i], p, "{ctx}: pixel {i}: the opaque volume hides the mesh");
                            }
                        }
                        _ => {}
                    }
                }
            }
        }
    }
}

/// `shearwarp render` of the 32³ sphere phantom at 64² into `dir/name`, with `extra` arguments.
fn render_sphere(dir: &std::path::Path, extra: &[&str], name: &str) -> assert_cmd::assert::Assert {
    let o = dir.join(name);
    let mut args =
        vec!["render", "--phantom", "sphere", "--phantom-dims", "32,32,32", "--size", "64", "--quiet", "-o", o.to_str().unwrap()];
    args.extend_from_slice(extra);
    assert_cmd::Command::cargo_bin("shearwarp").unwrap().args(&args).assert()
}

/// `--mesh` on the command line: an OBJ plate in front of the sphere
/// phantom covers it (the output differs from the plain render and `--json`
/// reports the geometry's costs), one far behind shows only around it, and a
/// missing or malformed file is a usage error naming it.
#[test]
fn geometry_mesh_on_the_command_line() {
    use predicates::prelude::*;
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("plate.obj");
    // a plate across the whole volume at y = 1 (the anterior view looks along y)
    std::fs::write(&obj, "v -10 1 -10\nv 45 1 -10\nv 45 1 45\nv -10 1 45\nf 1 2 3 4\n").unwrap();
    let bad = dir.path().join("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nf 1 2 3\n").unwrap();
    let run = |extra: &[&str], name: &str| render_sphere(dir.path(), extra, name);
    run(&[], "plain.png").success();
    let out = run(&["--mesh", obj.to_str().unwrap(), "--json"], "front.png").success();
    let j: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    assert!(j["geometry"]["inverse_warp_ms"].as_f64().unwrap() >= 0.0, "{j}");
    // the same plate moved behind the ball
    run(&["--mesh", obj.to_str().unwrap(), "--mesh-translate", "0,30,0"], "behind.png").success();
    let px = |n: &str| image::open(dir.path().join(n)).unwrap().to_rgb8();
    let (plain, front, behind) = (px("plain.png"), px("front.png"), px("behind.png"));
    assert!(plain != front, "the plate in front shows");
    assert!(plain != behind, "the plate behind shows around the ball");
    // the centre pixel: one placement is in front of the ball (the plate shows),
    // the other behind it (the opaque ball shows, as without the plate)
    let (a, b, p) = (front.get_pixel(32, 32), behind.get_pixel(32, 32), plain.get_pixel(32, 32));
    assert!((a == p) != (b == p), "centre: {a:?} / {b:?}, plain {p:?}");
    run(&["--mesh", dir.path().join("missing.obj").to_str().unwrap()], "x.png")
        .failure()
        .code(2)
        .stderr(predicate::str::contains("missing.obj"));
    run(&["--mesh", bad.to_str().unwrap()], "x.png").failure().code(2).stderr(predicate::str::contains("bad.obj"));
    run(&["--mesh", obj.to_str().unwrap(), "--mesh-scale", "0"], "x.png")
        .failure()
        .code(2)
        .stderr(predicate::str::contains("--mesh-scale"));
}

/// `--needle` on the command line: a cylinder through the sphere phantom
/// shows beside the ball (the frame differs from the plain render at the
/// needle's ends and not far from it), `--json` reports the geometry's
/// costs, and a needle with equal ends, a radius ≤ 0 or too few numbers is a
/// usage error naming the flag.
#[test]
fn geometry_needle_on_the_command_line() {
    use predicates::prelude::*;
    let dir = tempfile::tempdir().unwrap();
    let run = |extra: &[&str], name: &str| render_sphere(dir.path(), extra, name);
    run(&[], "plain.png").success();
    // along x through the ball's centre, poking out on both sides (the anterior view looks along y)
    let out = run(&["--needle=-20,15.5,15.5,51,15.5,15.5,1.5", "--json"], "needle.png").success();
    let j: serde_json::Value = serde_json::from_slice(&out.get_output().stdout).unwrap();
    assert!(j["geometry"]["inverse_warp_ms"].as_f64().unwrap() >= 0.0, "{j}");
    let px = |n: &str| image::open(dir.path().join(n)).unwrap().to_rgb8();
    let (plain, needle) = (px("plain.png"), px("needle.png"));
    let differ = |x: u32, y: u32| plain.get_pixel(x, y) != needle.get_pixel(x, y);
    // the needle's row beside the ball (off the volume: background in the plain frame)
    assert!(differ(3, 32) || differ(3, 31), "the needle shows left of the ball");
    assert!(differ(60, 32) || differ(60, 31), "the needle shows right of the ball");
    assert!(!differ(32, 5) && !differ(32, 58), "far from the needle the frame is the plain one");
    for (bad, says) in [("1,1,1,1,1,1,2", "ends must differ"), ("1,1,1,5,5,5,0", "radius"), ("1,2,3", "7 numbers")] {
        run(&["--needle", bad], "x.png").failure().code(2).stderr(predicate::str::contains("--needle").and(predicate::str::contains(says)));
    }
}

/// The needle through the sphere phantom in a perspective frame split into
/// Lacroute's pyramids (the eye beside the ball, inside the volume's box, a
/// 90° field of view: `last_plans().len() > 1`), binary and brute iso with the
/// crossing slice kept and the pyramids' depths kept
/// (`Renderer::set_keep_depths`): the depth test of
/// `composite_iso_over_geometry` reads each pixel's hit through the pyramid
/// that owns it (`geometry::volume_hit`), so the visible surface is the
/// nearer of the analytic sphere and the analytic cylinder within half a
/// voxel (¾ where the needle pierces the sphere), at the pixels away from
/// the needle's outline where the unlimited iso depth is itself that
/// accurate — the tolerances, exclusions and share of the single-plan test
/// (`inverse_warp_needle_through_the_sphere_is_the_nearer_surface`). The
/// needle hides the volume wherever the volume's hit is at or behind it.
/// Binary equals brute force: the images before and after the depth test,
/// bit for bit, and the hits.
#[test]
fn geometry_split_frame_needle_through_the_sphere_is_the_nearer_surface() {
    use shearwarp::accuracy::reference::Rays;
    use shearwarp::data::phantom::{SPHERE_ISO, sphere, sphere_geometry};
    use shearwarp::geometry::{composite_iso_over_geometry, volume_hit};
    use shearwarp::render::{Renderer, Settings};
    use shearwarp::view::{NamedView, rotate_eye};
    use shearwarp::warp::Image;
    let dims = [48, 48, 48];
    let vol = sphere(dims).unwrap();
    let (c, radius) = sphere_geometry(dims);
    let c = DVec3::from_array(c);
    let size = 128;
    let cam = Camera::new(rotate_eye(rotate_eye(NamedView::Anterior.rotation(), 1, 25.0), 0, 15.0), [size, size]);
    // the needle across the ball, and a second one leaving its front face 30° off the view
    // (where it pierces the surface the sphere lies less than a slice behind it: the depth test decides)
    let (toward_eye, ex) = (cam.rotation.transpose() * DVec3::Z, cam.rotation.transpose() * DVec3::X);
    let dir = toward_eye * 30f64.to_radians().cos() + ex * 30f64.to_radians().sin();
    let needles = [(c + DVec3::new(-30.0, -6.0, -4.0), c + DVec3::new(30.0, 8.0, 5.0), 3.5), (c - dir * 8.0, c + dir * 26.0, 3.5)];
    let mut needle = Mesh::cylinder(needles[0].0, needles[0].1, needles[0].2, 64).unwrap();
    let second = Mesh::cylinder(needles[1].0, needles[1].1, needles[1].2, 64).unwrap();
    let n = needle.vertices.len() as u32;
    needle.vertices.extend(second.vertices);
    needle.triangles.extend(second.triangles.iter().map(|t| t.map(|i| i + n)));
    let projection = Projection::perspective(90.0, 0.45).unwrap();
    let proj = Projector::new(&cam, &projection, dims, [1.0; 3]).unwrap();
    let mut geo = GeometryImage::new(size, size);
    rasterize(&needle, &Material::default(), Cull::Back, &proj, &mut geo).unwrap();
    let rays = Rays::with_projection(&cam, &projection, dims, [1.0; 3]).unwrap();
    let depths = |r: &Renderer| -> Vec<f64> {
        (0..size * size).map(|i| volume_hit(r, (i % size) as f64, (i / size) as f64).map_or(f64::NAN, |at| rays.depth_of(at))).collect()
    };
    let mut frames = vec![];
    for method in [Method::Binary, Method::Brute] {
        let settings = Settings { method, mode: Mode::Iso, threads: 2, ..Settings::default() };
        let tf = TransferFunction::threshold(SPHERE_ISO, [1.0; 3]);
        let mut r = Renderer::new(vol.clone(), &tf, settings).unwrap();
        r.set_iso(SPHERE_ISO).unwrap();
        r.set_projection(projection).unwrap();
        r.set_keep_depths(true);
        let mut img = Image::new(size, size);
        r.render(&cam, &mut img).unwrap();
        assert!(r.last_plans().len() > 1, "{method:?}: the frame splits into pyramids ({})", r.last_plans().len());
        let plain = depths(&r);
        let gl = GeometryLimits::new(proj, &geo).with_iso_crossing(true);
        r.set_limiter(Some(Arc::new(gl.clone())));
        r.render(&cam, &mut img).unwrap();
        let vdepth = depths(&r);
        let mut fin = img.clone();
        composite_iso_over_geometry(&mut fin, &geo, &r, &gl);
        let mut hidden = 0;
        for (i, (&vd, &gd)) in vdepth.iter().zip(geo.depth()).enumerate() {
            if gd.is_finite() && vd >= gd {
                assert_eq!(fin.data[i], geo.color()[i], "{method:?}: pixel {i}: the needle hides the volume behind it");
                hidden += 1;
            }
        }
        // the depth test decides somewhere: composed without it, those pixels differ
        let mut untested = img.clone();
        composite_over_geometry(&mut untested, &geo);
        assert!(hidden > 10 && fin != untested, "{method:?}: {hidden} pixels where the needle hides the volume");
        let (mut checked, mut needle_px) = (0, 0);
        for y in 0..size {
            for x in 0..size {
                let i = y * size + x;
                let covered = |x: i64, y: i64| {
                    geo.depth()[(y.clamp(0, size as i64 - 1) as usize) * size + x.clamp(0, size as i64 - 1) as usize].is_finite()
                };
                let here = covered(x as i64, y as i64);
                if (-2..=2).any(|dy| (-2..=2).any(|dx| covered(x as i64 + dx, y as i64 + dy) != here)) {
                    continue;
                }
                let (o, d) = rays.ray(x as f64, y as f64);
                let oc = o - c;
                let (a, b, cc) = (d.dot(d), oc.dot(d), oc.dot(oc) - radius * radius);
                let ts = if b * b - a * cc >= 0.0 { Some((-b - (b * b - a * cc).sqrt()) / a).filter(|&t| t >= 0.0) } else { None };
                let tn = needles.iter().filter_map(|&(na, nb, nr)| cylinder_hit(o, d, na, nb, nr, 0.0)).reduce(f64::min);
                let sphere_depth = ts.map(|t| rays.depth_of(o + t * d));
                let own_ok = match (sphere_depth, plain[i].is_nan()) {
                    (Some(s), false) => (plain[i] - s).abs() <= 0.5,
                    (None, true) => true,
                    _ => false,
                };
                if !own_ok {
                    continue;
                }
                let truth = [ts, tn].into_iter().flatten().map(|t| rays.depth_of(o + t * d)).fold(f64::INFINITY, f64::min);
                let seen = if vdepth[i].is_nan() { geo.depth()[i] } else { vdepth[i].min(geo.depth()[i]) };
                if truth.is_infinite() {
                    assert!(seen.is_infinite(), "{method:?} ({x}, {y}): {seen} where nothing is");
                    continue;
                }
                checked += 1;
                needle_px += here as usize;
                let pierce = matches!((sphere_depth, tn.map(|t| rays.depth_of(o + t * d))), (Some(a), Some(b)) if (a - b).abs() < 0.25);
                let tol = if pierce { 0.75 } else { 0.5 };
                assert!(
                    (seen - truth).abs() <= tol,
                    "{method:?} ({x}, {y}): seen {seen} (volume {}, needle {}), truth {truth} (sphere {sphere_depth:?}, needle {:?})",
                    vdepth[i],
                    geo.depth()[i],
                    tn.map(|t| rays.depth_of(o + t * d))
                );
            }
        }
        eprintln!("{method:?}: {} pyramids, {checked} pixels checked, {needle_px} on the needle, {hidden} hidden", r.last_plans().len());
        // without the kept depths the split frame is composed without the test (the old behaviour)
        r.set_keep_depths(false);
        let mut old = Image::new(size, size);
        r.render(&cam, &mut old).unwrap();
        composite_iso_over_geometry(&mut old, &geo, &r, &gl);
        assert!(old == untested, "{method:?}: no depths kept, no depth test");
        assert!(checked > 1000 && needle_px > 100, "{method:?}: {checked} pixels checked, {needle_px} on the needle");
        frames.push((bits(&img), bits(&fin), vdepth.iter().map(|d| d.to_bits()).collect::<Vec<_>>()));
    }
    assert!(frames[0] == frames[1], "binary equals brute force in the split frame (images, final images, hits)");
}
