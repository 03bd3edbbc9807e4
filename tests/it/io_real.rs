//! The loaders on the real sample scans in `$SHEARWARP_DATA` (see
//! `tests/fetch-data.sh`); every test prints that it was skipped and passes
//! when the variable is unset.
//!
//! Each scan is also written out as raw + sidecar and read back identical.

use std::path::PathBuf;

use shearwarp::data::io::{Format, LoadOptions, load, save_raw};
use shearwarp::{Volume, VoxelType};

fn data_dir(test: &str) -> Option<PathBuf> {
    match std::env::var_os("SHEARWARP_DATA") {
        Some(d) if !d.is_empty() => Some(PathBuf::from(d)),
        _ => {
            println!("{test}: skipped (SHEARWARP_DATA is not set)");
            None
        }
    }
}

fn close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol
}

/// Writes `v` as raw + sidecar, reads it back through format inference, and
/// checks it is identical.
fn raw_round_trip(v: &Volume, name: &str) {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join(format!("{name}.raw"));
    let side = save_raw(v, &p).unwrap();
    assert!(side.ends_with(format!("{name}.raw.json")));
    let back = load(&p, &LoadOptions::default()).unwrap();
    assert_eq!(&back, v, "{name}: raw round trip differs");
}

#[test]
fn chest_ct_nrrd() {
    let Some(d) = data_dir("chest_ct_nrrd") else {
        return;
    };
    let p = d.join("chest-ct-lung1.nrrd");
    assert_eq!(Format::infer(&p).unwrap(), Format::Nrrd);
    let v = load(&p, &LoadOptions::default()).unwrap();
    assert_eq!(v.dims(), [512, 512, 48]);
    assert_eq!(v.data().voxel_type(), VoxelType::I16);
    let s = v.spacing();
    assert!(close(s[0], 0.5703125, 1e-6) && close(s[1], 0.5703125, 1e-6) && close(s[2], 5.0, 1e-6), "{s:?}");
    let (lo, hi) = v.value_range();
    println!("chest CT: HU range {lo}..{hi}");
    assert!(lo <= -1000.0 + 50.0, "air should be near -1000 HU, min is {lo}");
    assert!(hi > 300.0, "bone should be above 300 HU, max is {hi}");
    // Lungs and air: a large share of voxels below -500 HU; soft tissue around 0.
    let below = (0..v.len()).filter(|&i| v.data().get(i) < -500.0).count() as f64 / v.len() as f64;
    assert!((0.1..0.9).contains(&below), "fraction below -500 HU = {below}");
    raw_round_trip(&v, "chest");
}

#[test]
fn head_mri_nifti_gz() {
    let Some(d) = data_dir("head_mri_nifti_gz") else {
        return;
    };
    let p = d.join("head-mri-ch2.nii.gz");
    assert_eq!(Format::infer(&p).unwrap(), Format::Nifti);
    let v = load(&p, &LoadOptions::default()).unwrap();
    assert_eq!(v.dims(), [181, 217, 181]);
    assert_eq!(v.data().voxel_type(), VoxelType::U8);
    assert_eq!(v.spacing(), [1.0, 1.0, 1.0]);
    let (lo, hi) = v.value_range();
    assert_eq!(lo, 0.0);
    assert!(hi > 100.0, "max {hi}");
    // The head sits in the middle: the centre voxel is brighter than a corner.
    assert!(v.get(90, 108, 90) > v.get(0, 0, 0));
    raw_round_trip(&v, "head");
}

#[test]
fn brain_dicom_series() {
    let Some(d) = data_dir("brain_dicom_series") else {
        return;
    };
    let dir = d.join("dicom-brain-pd");
    assert_eq!(Format::infer(&dir).unwrap(), Format::Dicom);
    let v = load(&dir, &LoadOptions::default()).unwrap();
    assert_eq!(v.dims(), [256, 256, 20]);
    let s = v.spacing();
    println!("brain DICOM: spacing {s:?}, type {:?}, range {:?}", v.data().voxel_type(), v.value_range());
    assert!(close(s[0], 0.859375, 1e-4) && close(s[1], 0.859375, 1e-4), "{s:?}");
    // Consecutive ImagePositionPatient values are 7.0005 mm apart along the normal.
    assert!(close(s[2], 7.0005, 1e-3), "z spacing {}", s[2]);
    assert_eq!(v.data().voxel_type(), VoxelType::I16);
    let (lo, hi) = v.value_range();
    assert!(lo >= 0.0 && hi > 100.0, "{lo}..{hi}");
    // Loading through one slice file gives the same series.
    let one = load(&dir.join("brain_010.dcm"), &LoadOptions::default()).unwrap();
    assert_eq!(one, v);
    raw_round_trip(&v, "brain");
}

#[test]
fn brainsmall_den() {
    let Some(d) = data_dir("brainsmall_den") else {
        return;
    };
    let p = d.join("brainsmall.den");
    assert_eq!(Format::infer(&p).unwrap(), Format::Den);
    let v = load(&p, &LoadOptions::default()).unwrap();
    assert_eq!(v.dims(), [128, 128, 84]);
    assert_eq!(v.data().voxel_type(), VoxelType::U8);
    assert_eq!(v.spacing(), [1.0; 3]);
    let (_, hi) = v.value_range();
    assert!(hi > 100.0);
    raw_round_trip(&v, "brainsmall");
}

#[test]
fn magic_sniffing_without_extensions() {
    let Some(d) = data_dir("magic_sniffing_without_extensions") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    for (src, fmt) in [
        (d.join("chest-ct-lung1.nrrd"), Format::Nrrd),
        (d.join("head-mri-ch2.nii.gz"), Format::Nifti),
        (d.join("dicom-brain-pd/brain_001.dcm"), Format::Dicom),
        (d.join("brainsmall.den"), Format::Den),
    ] {
        let dst = tmp.path().join(format!("scan-{}.bin", fmt.name()));
        std::fs::copy(&src, &dst).unwrap();
        assert_eq!(Format::infer(&dst).unwrap(), fmt, "{}", src.display());
    }
}
