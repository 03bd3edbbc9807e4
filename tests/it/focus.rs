//! Focus+context (`Renderer::set_focus`, `--focus`, `--focus-tissue`): inside
//! a region a second tissue preset classifies the samples.
//!
//! - With the focus tissue equal to the context tissue, every method (binary,
//!   brute, rle, brute-rle, rle with Deluxe P), both projections, iso and
//!   blend, renders the plain frame bit for bit.
//! - Accelerated equals brute force bit for bit with a focus region (binary
//!   vs brute, rle vs brute-rle, pre- and post-classified), random views and
//!   regions, early ray termination off.
//! - Analytic: a nested-shell phantom (a "skin" shell around a "bone" ball),
//!   a bone lens over the front of it: rays that enter the lens before the
//!   skin and meet the bone inside it show the bone surface's depth, rays
//!   that miss the lens the skin's (binary and brute iso, parallel; 0.5 voxel).
//! - Switching the context or the focus tissue rebuilds no mask (binary) and
//!   no encoding (rle with Deluxe P).
//! - Bad input is an error: an unknown focus tissue, a bad region, a renderer
//!   without presets, the BCC grid; on the command line exit 2.
//! - A convex mesh as the focus region (`focus_mesh`): the tissue of the
//!   analytic box of the same shape on ≥ 98 % of the pixels off its
//!   silhouette, accelerated equals brute force, equal tissues give the plain
//!   frame, an open or dented mesh is an error.
//! - Deluxe I with a focus (`focus_deluxe_i`; a midpoint between slices `k`
//!   and `k + 1` is in the focus iff both slices are): equal tissues give the
//!   plain I frame, accelerated equals brute force, the bone lens holds.

use crate::common;

use assert_cmd::Command;
use glam::{DMat3, DVec3, EulerRot};
use predicates::prelude::*;
use shearwarp::Volume;
use shearwarp::classify::TransferFunction;
use shearwarp::classify::presets::Tissue;
use shearwarp::composite::Mode;
use shearwarp::data::volume::VoxelData;
use shearwarp::render::{Deluxe, Focus, Method, Renderer, Settings};
use shearwarp::view::clip::Region;
use shearwarp::view::plan::FramePlan;
use shearwarp::view::{Camera, Projection};
use shearwarp::warp::Image;

use common::{bits, uniform};

/// Radii of the nested-shell phantom: the skin's outer surface and the bone's.
const R_SKIN: f64 = 15.0;
const R_BONE: f64 = 8.0;
const SKIN_ISO: f32 = 50.0;
const BONE_ISO: f32 = 550.0;
const N: usize = 40;

/// A ball of "bone" (1000) inside a shell of "skin" (100) in air (0), each
/// boundary a linear ramp two voxels wide centred on its radius, so the skin
/// threshold (50) is exactly the sphere of radius `R_SKIN` and the bone
/// threshold (550) exactly the one of radius `R_BONE`.
fn shells() -> Volume {
    let c = (N as f64 - 1.0) / 2.0;
    let mut data = Vec::with_capacity(N * N * N);
    for z in 0..N {
        for y in 0..N {
            for x in 0..N {
                let r = DVec3::new(x as f64 - c, y as f64 - c, z as f64 - c).length();
                let skin = ((R_SKIN - r) / 2.0 + 0.5).clamp(0.0, 1.0);
                let bone = ((R_BONE - r) / 2.0 + 0.5).clamp(0.0, 1.0);
                data.push((100.0 * skin + 900.0 * bone) as f32);
            }
        }
    }
    Volume::new([N, N, N], [1.0; 3], VoxelData::F32(data)).unwrap()
}

fn tissues() -> Vec<Tissue> {
    vec![
        Tissue {
            name: "skin",
            threshold: SKIN_ISO,
            rgb: [0.95, 0.7, 0.55],
            tf: TransferFunction::new(
                vec![(SKIN_ISO, 0.0), (150.0, 0.3), (1000.0, 0.6)],
                vec![(SKIN_ISO, [0.95, 0.7, 0.55]), (1000.0, [1.0, 0.9, 0.8])],
            )
            .unwrap(),
        },
        Tissue {
            name: "bone",
            threshold: BONE_ISO,
            rgb: [0.95, 0.95, 0.9],
            tf: TransferFunction::new(
                vec![(BONE_ISO, 0.0), (700.0, 0.5), (1000.0, 0.9)],
                vec![(BONE_ISO, [0.9, 0.9, 0.8]), (1000.0, [1.0, 1.0, 1.0])],
            )
            .unwrap(),
        },
    ]
}

const PERSP: (f64, f64) = (40.0, 1.5);

fn renderer(method: Method, mode: Mode, deluxe: Deluxe, persp: bool, context: &str, focus: Option<Focus>) -> Renderer {
    let s = Settings { method, mode, deluxe, ert: 1.0, threads: 2, ..Settings::default() };
    let mut r = Renderer::with_tissues(shells(), &tissues(), s).unwrap();
    if persp {
        r.set_projection(Projection::perspective(PERSP.0, PERSP.1).unwrap()).unwrap();
    }
    r.select_tissue_named(context).unwrap();
    r.set_focus(focus).unwrap();
    r
}

fn frame(r: &mut Renderer, rot: DMat3, size: usize) -> Image {
    let mut img = Image::new(size, size);
    r.render(&Camera::new(rot, [size, size]), &mut img).unwrap();
    img
}

fn views() -> Vec<DMat3> {
    vec![
        DMat3::IDENTITY,
        DMat3::from_rotation_y(45f64.to_radians()),
        DMat3::from_euler(EulerRot::XYZ, 35.264f64.to_radians(), 45f64.to_radians(), 0.0),
        DMat3::from_euler(EulerRot::XYZ, 0.4, -0.9, 0.2),
    ]
}

/// Every (method, Deluxe) pair the focus renders.
fn methods() -> Vec<(Method, Deluxe)> {
    let p = Deluxe { post: true, ..Deluxe::STANDARD };
    vec![
        (Method::Binary, Deluxe::STANDARD),
        (Method::Brute, Deluxe::STANDARD),
        (Method::Rle, Deluxe::STANDARD),
        (Method::BruteRle, Deluxe::STANDARD),
        (Method::Rle, p),
        (Method::BruteRle, p),
    ]
}

fn lens() -> Region {
    let c = (N as f64 - 1.0) / 2.0;
    // over the front (the viewer of the identity view is at +z)
    Region::Sphere { centre: [c + 3.0, c - 2.0, c + 9.0], radius: 9.0 }
}

#[test]
fn focus_with_the_context_tissue_equals_the_plain_render() {
    assert_context_focus_is_plain(&methods(), [lens(), Region::Box { lo: [5.0, 8.5, 3.0], hi: [30.0, 25.0, 22.2] }]);
}

/// For every method and Deluxe option of `methods`, both modes, both
/// projections and two tissues: a focus `region` whose tissue is the context's
/// own renders every view bit for bit as no focus does.
fn assert_context_focus_is_plain(methods: &[(Method, Deluxe)], regions: [Region; 2]) {
    for &(method, deluxe) in methods {
        for mode in [Mode::Iso, Mode::Blend] {
            for persp in [false, true] {
                for tissue in ["skin", "bone"] {
                    for region in regions {
                        let mut plain = renderer(method, mode, deluxe, persp, tissue, None);
                        let mut focus = renderer(method, mode, deluxe, persp, tissue, Some(Focus::new(region, tissue)));
                        for rot in views() {
                            let (a, b) = (frame(&mut plain, rot, 64), frame(&mut focus, rot, 64));
                            assert!(
                                bits(&a) == bits(&b),
                                "{method:?} {deluxe:?} {mode:?} persp {persp} {tissue} {region:?} {rot:?}: the focus changed the frame"
                            );
                        }
                    }
                }
            }
        }
    }
}

#[test]
fn focus_accelerated_equals_brute_force() {
    let p = Deluxe { post: true, ..Deluxe::STANDARD };
    assert_focus_accelerated_is_brute(
        23,
        &[
            (Method::Binary, Method::Brute, Deluxe::STANDARD),
            (Method::Rle, Method::BruteRle, Deluxe::STANDARD),
            (Method::Rle, Method::BruteRle, p),
        ],
    );
}

/// Six random views, each with a random focus sphere or box and the tissues
/// either way round: for each `(fast, brute, deluxe)` of `pairs`, both modes
/// and both projections, the accelerated frame is the brute force's bit for
/// bit, and at least half the frames differ from the plain (no focus) one.
fn assert_focus_accelerated_is_brute(seed: u64, pairs: &[(Method, Method, Deluxe)]) {
    let mut rnd = uniform(seed);
    let c = (N as f64 - 1.0) / 2.0;
    let (mut frames, mut differ_from_plain) = (0, 0);
    for case in 0..6 {
        let rot = DMat3::from_euler(EulerRot::XYZ, rnd() * 6.3, rnd() * 6.3, rnd() * 6.3);
        let region = if case % 2 == 0 {
            Region::Sphere {
                centre: [c + 10.0 * (rnd() - 0.5), c + 10.0 * (rnd() - 0.5), c + 20.0 * (rnd() - 0.5)],
                radius: 4.0 + 8.0 * rnd(),
            }
        } else {
            let lo = [rnd() * 20.0, rnd() * 20.0, rnd() * 20.0];
            Region::Box { lo, hi: [lo[0] + 5.0 + 15.0 * rnd(), lo[1] + 5.0 + 15.0 * rnd(), lo[2] + 5.0 + 15.0 * rnd()] }
        };
        let (context, focus) = if case % 3 == 2 { ("bone", "skin") } else { ("skin", "bone") };
        for &(fast, brute, deluxe) in pairs {
            for mode in [Mode::Iso, Mode::Blend] {
                for persp in [false, true] {
                    let f = Some(Focus::new(region, focus));
                    let a = frame(&mut renderer(fast, mode, deluxe, persp, context, f.clone()), rot, 64);
                    let b = frame(&mut renderer(brute, mode, deluxe, persp, context, f), rot, 64);
                    assert!(bits(&a) == bits(&b), "case {case} {fast:?} {deluxe:?} {mode:?} persp {persp} {region:?} {context}/{focus}");
                    let plain = frame(&mut renderer(fast, mode, deluxe, persp, context, None), rot, 64);
                    frames += 1;
                    differ_from_plain += (bits(&a) != bits(&plain)) as usize;
                }
            }
        }
    }
    // the focus shows: most of these frames differ from the plain ones
    assert!(differ_from_plain * 2 >= frames, "only {differ_from_plain} of {frames} frames show the focus");
}

/// The voxel position of pixel `(p, q)`'s sample in slice `k`.
fn sample(plan: &FramePlan, k: usize, p: usize, q: usize) -> DVec3 {
    let mut v = [0.0; 3];
    v[plan.view.perm[0]] = plan.sample_at(k, 0, p);
    v[plan.view.perm[1]] = plan.sample_at(k, 1, q);
    v[plan.view.perm[2]] = k as f64;
    DVec3::from_array(v)
}

/// The front crossing `t` (along `o + t·d`, `|d| = 1`) of the sphere of
/// `centre`, `radius`, and the back one, if the line meets it.
fn crossing(o: DVec3, d: DVec3, centre: DVec3, radius: f64) -> Option<[f64; 2]> {
    let oc = o - centre;
    let b = oc.dot(d);
    let disc = b * b - (oc.length_squared() - radius * radius);
    (disc >= 0.0).then(|| [-b - disc.sqrt(), -b + disc.sqrt()])
}

#[test]
fn focus_bone_lens_shows_bone_inside_and_skin_outside() {
    bone_lens_shows_bone_inside_and_skin_outside(Deluxe::STANDARD);
}

/// The analytic bone lens (see [`focus_bone_lens_shows_bone_inside_and_skin_outside`]) with `deluxe`.
fn bone_lens_shows_bone_inside_and_skin_outside(deluxe: Deluxe) {
    let c = DVec3::splat((N as f64 - 1.0) / 2.0);
    let Region::Sphere { centre, radius } = lens() else { unreachable!() };
    let lc = DVec3::from_array(centre);
    for method in [Method::Binary, Method::Brute] {
        for rot in [DMat3::IDENTITY, DMat3::from_rotation_y(20f64.to_radians())] {
            let mut r = renderer(method, Mode::Iso, deluxe, false, "skin", Some(Focus::new(lens(), "bone")));
            frame(&mut r, rot, 96);
            let plan = r.last_plan().unwrap().clone();
            let inter = r.intermediate();
            let [w, h] = inter.size;
            let nk = plan.slices();
            let (mut bone, mut skin) = (0, 0);
            for q in 0..h {
                for p in 0..w {
                    // the ray in voxel space, parametrised by slice index (t = k · |d|)
                    let o = sample(&plan, 0, p, q);
                    let step = sample(&plan, nk - 1, p, q) - o;
                    let (d, len) = (step.normalize(), step.length() / (nk - 1) as f64);
                    // front to back: ascending slices or descending
                    let (o, d, k_of) = if plan.view.ascending {
                        (o, d, Box::new(move |t: f64| t / len) as Box<dyn Fn(f64) -> f64>)
                    } else {
                        let e = sample(&plan, nk - 1, p, q);
                        (e, -d, Box::new(move |t: f64| (nk - 1) as f64 - t / len) as Box<dyn Fn(f64) -> f64>)
                    };
                    let got = inter.depth[q * w + p];
                    let skin_t = crossing(o, d, c, R_SKIN);
                    let bone_t = crossing(o, d, c, R_BONE);
                    let lens_t = crossing(o, d, lc, radius);
                    match (lens_t, skin_t, bone_t) {
                        // enters the lens a voxel before the skin, meets the bone a voxel inside it
                        (Some([l0, l1]), Some([s0, _]), Some([b0, _])) if l0 + 1.0 < s0 && l0 + 1.0 < b0 && b0 + 1.0 < l1 => {
                            let want = k_of(b0);
                            assert!((got as f64 - want).abs() <= 0.5, "{method:?} pixel ({p}, {q}): depth {got}, the bone's {want:.2}");
                            bone += 1;
                        }
                        // misses the lens by a voxel: the skin (away from its silhouette)
                        (None, Some([s0, s1]), _) if s1 - s0 > 4.0 => {
                            let ld = (lc - o) - d * (lc - o).dot(d);
                            if ld.length() > radius + 1.0 {
                                let want = k_of(s0);
                                assert!((got as f64 - want).abs() <= 0.5, "{method:?} pixel ({p}, {q}): depth {got}, the skin's {want:.2}");
                                skin += 1;
                            }
                        }
                        _ => {}
                    }
                }
            }
            assert!(bone > 40 && skin > 100, "{method:?}: {bone} bone and {skin} skin pixels checked");
        }
    }
}

#[test]
fn focus_tissue_switches_rebuild_no_mask_and_no_encoding() {
    let rot = DMat3::from_euler(EulerRot::XYZ, 0.3, 0.5, 0.0);
    // binary: the one threshold-coded mask
    let mut r = renderer(Method::Binary, Mode::Iso, Deluxe::STANDARD, false, "skin", Some(Focus::new(lens(), "bone")));
    frame(&mut r, rot, 64);
    let (bytes, built) = (r.mask_bytes(), format!("{:?}", r.build_times()));
    for i in 0..6 {
        r.select_tissue(i % 2).unwrap();
        r.set_focus(Some(Focus::new(lens(), ["skin", "bone"][(i / 2) % 2]))).unwrap();
        frame(&mut r, rot, 64);
        // (a structure built again would have a new build time)
        assert_eq!(format!("{:?}", r.build_times()), built, "switch {i} built something");
        // (the first preset's own one-bit mask goes once the code mask serves another preset)
        assert!(r.mask_bytes() <= bytes);
    }
    // rle with Deluxe P: the encoding keeps every preset's voxels
    let p = Deluxe { post: true, ..Deluxe::STANDARD };
    let mut r = renderer(Method::Rle, Mode::Blend, p, false, "skin", Some(Focus::new(lens(), "bone")));
    frame(&mut r, rot, 64);
    let built = r.rle_cache().encodings_built();
    for i in 0..6 {
        r.select_tissue(i % 2).unwrap();
        r.set_focus(Some(Focus::new(lens(), ["skin", "bone"][(i / 2) % 2]))).unwrap();
        frame(&mut r, rot, 64);
        assert_eq!(r.rle_cache().encodings_built(), built, "switch {i} re-encoded");
    }
}

#[test]
fn bad_focus_is_an_error() {
    let mut r = renderer(Method::Binary, Mode::Iso, Deluxe::STANDARD, false, "skin", None);
    assert!(r.set_focus(Some(Focus::new(lens(), "enamel"))).unwrap_err().to_string().contains("enamel"));
    assert!(r.set_focus(Some(Focus::new(Region::Sphere { centre: [1.0; 3], radius: -1.0 }, "bone"))).is_err());
    assert!(r.set_focus(Some(Focus::new(Region::Sphere { centre: [f64::NAN, 0.0, 0.0], radius: 1.0 }, "bone"))).is_err());
    assert!(r.set_focus(Some(Focus::new(Region::Box { lo: [0.0; 3], hi: [1.0, 0.0, 1.0] }, "bone"))).is_err());
    // one transfer function: no presets to focus with
    let tf = TransferFunction::ramp(40.0, 180.0, 0.7, [0.9, 0.7, 0.5]);
    let mut one = Renderer::new(shells(), &tf, Settings::default()).unwrap();
    assert!(one.set_focus(Some(Focus::new(lens(), "bone"))).is_err());
    // the BCC grid: refused at the frame, with a message naming it
    let s = Settings { method: Method::Rle, lattice: shearwarp::Lattice::Bcc, threads: 2, ..Settings::default() };
    let mut r = Renderer::with_tissues(shells(), &tissues(), s).unwrap();
    r.set_focus(Some(Focus::new(lens(), "bone"))).unwrap();
    let mut img = Image::new(32, 32);
    let e = r.render(&Camera::new(DMat3::IDENTITY, [32, 32]), &mut img).unwrap_err();
    assert!(e.to_string().contains("BCC"), "{e}");
}

#[test]
fn focus_cli_renders_and_refuses_bad_input() {
    let dir = std::env::temp_dir().join(format!("shearwarp-focus-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("lens.png");
    Command::cargo_bin("shearwarp")
        .unwrap()
        .args([
            "render",
            "--phantom-dims",
            "48,48,42",
            "--size",
            "64",
            "--tissue",
            "skin",
            "--focus",
            "sphere:24,30,20,12",
            "--focus-tissue",
            "bone",
            "-o",
        ])
        .arg(&out)
        .assert()
        .success();
    assert!(out.exists());
    for bad in [
        vec!["--focus", "sphere:1,2,3,-4"],
        vec!["--focus", "sphere:1,2,nan,4"],
        vec!["--focus", "cone:1,2,3,4"],
        vec!["--focus", "box:5,5,5,1,1,1"],
        vec!["--focus", "sphere:1,2,3,4", "--focus-tissue", "enamel"],
        vec!["--focus-tissue", "bone"],
        vec!["--focus", "sphere:1,2,3,4", "--iso", "100"],
        vec!["--focus", "sphere:1,2,3,4", "--grid", "bcc", "--method", "rle"],
    ] {
        Command::cargo_bin("shearwarp")
            .unwrap()
            .args(["render", "--phantom-dims", "32,32,28", "--size", "32", "-o"])
            .arg(dir.join("bad.png"))
            .args(&bad)
            .assert()
            .code(2)
            .stderr(predicate::str::contains("panicked").not());
    }
    let _ = std::fs::remove_dir_all(&dir);
}

// ---- a convex mesh as the focus region (`Renderer::set_focus_limiter`, `--focus mesh:FILE`)

/// The boxes the mesh focus tests use, over the nested shells (each holds
/// skin and bone).
fn focus_boxes() -> [Region; 2] {
    let c = (N as f64 - 1.0) / 2.0;
    [
        Region::Box { lo: [c - 12.3, c - 6.0, c - 2.0], hi: [c + 5.5, c + 10.2, c + 21.0] },
        Region::Box { lo: [3.0, 8.5, 3.0], hi: [30.0, 25.0, 22.2] },
    ]
}

/// The convex mesh of box `region` (a cuboid).
fn box_mesh(region: Region) -> shearwarp::geometry::ConvexMesh {
    let Region::Box { lo, hi } = region else { unreachable!() };
    let m = shearwarp::geometry::Mesh::cuboid(DVec3::from_array(lo), DVec3::from_array(hi)).unwrap();
    shearwarp::geometry::ConvexMesh::new(&m).unwrap()
}

/// One frame of `rot` with the focus in `mesh` (tissue `tissue`), its faces
/// drawn with the frame's camera as `--focus mesh:` does.
fn mesh_frame(r: &mut Renderer, mesh: &shearwarp::geometry::ConvexMesh, tissue: &str, rot: DMat3, size: usize) -> Image {
    use shearwarp::geometry::{MeshClip, Projector};
    let cam = Camera::new(rot, [size, size]);
    let proj = Projector::new(&cam, &r.projection(), [N; 3], [1.0; 3]).unwrap();
    let clip = MeshClip::new(mesh, proj, shearwarp::view::clip::Keep::Inside).unwrap();
    r.set_focus_limiter(std::sync::Arc::new(clip), tissue).unwrap();
    let mut img = Image::new(size, size);
    r.render(&cam, &mut img).unwrap();
    img
}

/// A box-shaped mesh as the focus picks the same tissue as the analytic box
/// (`--focus box:`): skin outside, bone inside, binary iso in both
/// projections; per intermediate pixel off the box's silhouette (two pixels:
/// rays whose analytic focus interval is at most two slices long or whose
/// neighbour's is empty where theirs is not, or the reverse), both miss or
/// both hit within 0.5 voxel (the skin and the bone surface are seven voxels
/// apart, so a pixel showing the other tissue is far off) on at least 98 %.
#[test]
fn focus_mesh_picks_the_tissue_of_the_analytic_box() {
    let (mut pixels, mut same) = (0usize, 0usize);
    for persp in [false, true] {
        for region in focus_boxes() {
            let mesh = box_mesh(region);
            for rot in views() {
                let mut rb = renderer(Method::Binary, Mode::Iso, Deluxe::STANDARD, persp, "skin", Some(Focus::new(region, "bone")));
                let mut rm = renderer(Method::Binary, Mode::Iso, Deluxe::STANDARD, persp, "skin", None);
                frame(&mut rb, rot, 96);
                mesh_frame(&mut rm, &mesh, "bone", rot, 96);
                let plan = rb.last_plan().unwrap();
                let fb = plan.focus.as_ref().unwrap();
                let (ib, im) = (rb.intermediate(), rm.intermediate());
                let [w, h] = plan.grid.size;
                let len = |p: usize, q: usize| {
                    let [a, b] = fb.get(p, q);
                    if a > b { 0 } else { b - a + 1 }
                };
                for q in 0..h {
                    for p in 0..w {
                        // (a ray off the output image: the faces were not drawn there)
                        let [a, b] = plan.intermediate_to_sheared(p as f64, q as f64);
                        let Some([u, v]) = plan.warp.to_output(a, b) else { continue };
                        if !(0.0..=95.0).contains(&u) || !(0.0..=95.0).contains(&v) {
                            continue;
                        }
                        let n = len(p, q);
                        let silhouette = (1..=2).contains(&n)
                            || (-2i64..=2).any(|dq| {
                                (-2i64..=2).any(|dp| {
                                    let (x, y) = (p as i64 + dp, q as i64 + dq);
                                    x >= 0 && y >= 0 && x < w as i64 && y < h as i64 && (len(x as usize, y as usize) == 0) != (n == 0)
                                })
                            });
                        if silhouette {
                            continue;
                        }
                        let (db, dm) = (ib.depth_at(p, q) as f64, im.depth_at(p, q) as f64);
                        let step = (sample(plan, 1, p, q) - sample(plan, 0, p, q)).length();
                        pixels += 1;
                        same += match (db.is_finite(), dm.is_finite()) {
                            (false, false) => 1,
                            (true, true) => ((db - dm).abs() * step <= 0.5) as usize,
                            _ => 0,
                        };
                    }
                }
            }
        }
    }
    eprintln!("{same} of {pixels} pixels pick the same tissue");
    assert!(pixels > 20_000 && same as f64 >= 0.98 * pixels as f64, "{same} of {pixels} pixels pick the same tissue");
}

/// Accelerated equals brute force bit for bit with a mesh focus (binary vs
/// brute, rle vs brute-rle, pre- and post-classified; iso and blend; both
/// projections; early ray termination off).
#[test]
fn focus_mesh_accelerated_equals_brute_force() {
    let p = Deluxe { post: true, ..Deluxe::STANDARD };
    let pairs = [
        (Method::Binary, Method::Brute, Deluxe::STANDARD),
        (Method::Rle, Method::BruteRle, Deluxe::STANDARD),
        (Method::Rle, Method::BruteRle, p),
    ];
    let mut differ_from_plain = 0;
    for (i, region) in focus_boxes().into_iter().enumerate() {
        let mesh = box_mesh(region);
        let (context, focus) = if i == 0 { ("skin", "bone") } else { ("bone", "skin") };
        for rot in [views()[2], views()[3]] {
            for (fast, brute, deluxe) in pairs {
                for mode in [Mode::Iso, Mode::Blend] {
                    for persp in [false, true] {
                        let a = mesh_frame(&mut renderer(fast, mode, deluxe, persp, context, None), &mesh, focus, rot, 64);
                        let b = mesh_frame(&mut renderer(brute, mode, deluxe, persp, context, None), &mesh, focus, rot, 64);
                        assert!(bits(&a) == bits(&b), "{fast:?} {deluxe:?} {mode:?} persp {persp} {region:?} {context}/{focus}");
                        let plain = frame(&mut renderer(fast, mode, deluxe, persp, context, None), rot, 64);
                        differ_from_plain += (bits(&a) != bits(&plain)) as usize;
                    }
                }
            }
        }
    }
    assert!(differ_from_plain >= 36, "only {differ_from_plain} of 48 frames show the focus");
}

/// A mesh focus with the context's own tissue renders the plain frame bit
/// for bit (every method, iso and blend, both projections).
#[test]
fn focus_mesh_with_the_context_tissue_equals_the_plain_render() {
    let mesh = box_mesh(focus_boxes()[0]);
    for (method, deluxe) in methods() {
        for mode in [Mode::Iso, Mode::Blend] {
            for persp in [false, true] {
                for tissue in ["skin", "bone"] {
                    let mut plain = renderer(method, mode, deluxe, persp, tissue, None);
                    let mut focus = renderer(method, mode, deluxe, persp, tissue, None);
                    for rot in views() {
                        let (a, b) = (frame(&mut plain, rot, 64), mesh_frame(&mut focus, &mesh, tissue, rot, 64));
                        assert!(
                            bits(&a) == bits(&b),
                            "{method:?} {deluxe:?} {mode:?} persp {persp} {tissue} {rot:?}: the focus changed the frame"
                        );
                    }
                }
            }
        }
    }
}

/// `--focus mesh:FILE` on the command line: a closed convex mesh renders
/// (the same mesh placed by the --mesh-* flags as --focus box: of its box
/// differs from the plain frame); an open, a non-convex or a missing mesh
/// is a usage error (exit 2), and so is a mesh focus in the viewer.
#[test]
fn focus_mesh_on_the_command_line_and_an_open_mesh_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let m = shearwarp::geometry::Mesh::cuboid(DVec3::splat(-0.5), DVec3::splat(0.5)).unwrap();
    let obj = |name: &str, v: &[DVec3], t: &[[u32; 3]]| {
        let mut s = String::new();
        for p in v {
            s += &format!("v {} {} {}\n", p.x, p.y, p.z);
        }
        for f in t {
            s += &format!("f {} {} {}\n", f[0] + 1, f[1] + 1, f[2] + 1);
        }
        let path = dir.path().join(name);
        std::fs::write(&path, s).unwrap();
        format!("mesh:{}", path.display())
    };
    let cube = obj("cube.obj", &m.vertices, &m.triangles);
    let open = obj("open.obj", &m.vertices, &m.triangles[..10]);
    let mut dented = m.vertices.clone();
    dented[7] = DVec3::splat(0.2);
    let dent = obj("dent.obj", &dented, &m.triangles);
    let run = |extra: &[&str], name: &str| {
        let o = dir.path().join(name);
        Command::cargo_bin("shearwarp")
            .unwrap()
            .args(["render", "--phantom-dims", "40,40,36", "--size", "64", "--quiet", "--tissue", "skin", "-o"])
            .arg(&o)
            .args(extra)
            .assert()
    };
    run(&[], "plain.png").success();
    run(&["--focus", &cube, "--focus-tissue", "bone", "--mesh-scale", "16", "--mesh-translate", "20,22,26"], "mesh.png").success();
    let px = |n: &str| image::open(dir.path().join(n)).unwrap().to_rgb8().into_raw();
    assert_ne!(px("plain.png"), px("mesh.png"));
    run(&["--focus", &open], "x.png").failure().code(2).stderr(predicate::str::contains("not closed"));
    run(&["--focus", &dent, "--mesh-scale", "10"], "x.png").failure().code(2).stderr(predicate::str::contains("not convex"));
    run(&["--focus", "mesh:/nonexistent/x.obj"], "x.png").failure().code(2).stderr(predicate::str::contains("panicked").not());
    run(&["--focus", &cube, "--focus-tissue", "enamel"], "x.png").failure().code(2).stderr(predicate::str::contains("enamel"));
    run(&["--focus", &cube, "--iso", "100"], "x.png").failure().code(2);
}

// ---- Deluxe I with a focus: a midpoint between slices k and k + 1 takes the
// focus iff both slices' samples do

/// Every (method, Deluxe) pair with intermediate slices (I, and I with P on the RLE paths).
fn methods_i() -> Vec<(Method, Deluxe)> {
    let i = Deluxe { intermediate: true, ..Deluxe::STANDARD };
    let ip = Deluxe { post: true, ..i };
    vec![(Method::Binary, i), (Method::Brute, i), (Method::Rle, i), (Method::BruteRle, i), (Method::Rle, ip), (Method::BruteRle, ip)]
}

#[test]
fn focus_deluxe_i_with_the_context_tissue_equals_the_plain_render() {
    assert_context_focus_is_plain(&methods_i(), [lens(), focus_boxes()[1]]);
}

#[test]
fn focus_deluxe_i_accelerated_equals_brute_force() {
    let i = Deluxe { intermediate: true, ..Deluxe::STANDARD };
    let ip = Deluxe { post: true, ..i };
    assert_focus_accelerated_is_brute(
        29,
        &[(Method::Binary, Method::Brute, i), (Method::Rle, Method::BruteRle, i), (Method::Rle, Method::BruteRle, ip)],
    );
}

/// The analytic bone lens of the nested shells with Deluxe I: the same
/// tolerance (0.5 voxel) as without it.
#[test]
fn focus_deluxe_i_bone_lens_shows_bone_inside_and_skin_outside() {
    bone_lens_shows_bone_inside_and_skin_outside(Deluxe { intermediate: true, ..Deluxe::STANDARD });
}

/// Deluxe I with a mesh focus: accelerated equals brute force (binary and rle, iso and blend).
#[test]
fn focus_deluxe_i_mesh_accelerated_equals_brute_force() {
    let i = Deluxe { intermediate: true, ..Deluxe::STANDARD };
    let mesh = box_mesh(focus_boxes()[0]);
    for (fast, brute) in [(Method::Binary, Method::Brute), (Method::Rle, Method::BruteRle)] {
        for mode in [Mode::Iso, Mode::Blend] {
            for persp in [false, true] {
                let rot = views()[3];
                let a = mesh_frame(&mut renderer(fast, mode, i, persp, "skin", None), &mesh, "bone", rot, 64);
                let b = mesh_frame(&mut renderer(brute, mode, i, persp, "skin", None), &mesh, "bone", rot, 64);
                assert!(bits(&a) == bits(&b), "{fast:?} {mode:?} persp {persp}");
            }
        }
    }
}
