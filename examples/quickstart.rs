//! Render one frame of a volume to a PNG with the library alone.
//!
//! `cargo run --release --example quickstart [SCAN] [TISSUE]`: the built-in CT
//! head phantom, or a scan (NRRD, NIfTI, DICOM directory, .den), seen from the
//! front through a tissue preset (default: the densest). Writes `quickstart.png`.

use std::path::Path;

use shearwarp::classify::presets::tissues_for;
use shearwarp::data::io::{LoadOptions, load};
use shearwarp::data::orientation::view_rotation;
use shearwarp::data::phantom;
use shearwarp::{Camera, Image, NamedView, Renderer, Settings};

fn main() -> shearwarp::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    // A scan from disk, or the built-in CT head (128×128×113, Hounsfield units).
    let volume = match args.first() {
        Some(path) => load(Path::new(path), &LoadOptions::default())?,
        None => phantom::head([128, 128, 113])?,
    };
    // Tissue presets: skin, fat, soft, bone for CT; low, mid, high otherwise.
    // Default: the densest (bone on CT).
    let tissues = tissues_for(&volume);
    let tissue = args.get(1).map(String::as_str).unwrap_or(tissues[tissues.len() - 1].name);
    // The patient's front, whatever order the file stores its axes in.
    let rotation = view_rotation(NamedView::Anterior, volume.frame());

    let mut renderer = Renderer::with_tissues(volume, &tissues, Settings::default())?;
    renderer.select_tissue_named(tissue)?;
    let camera = Camera::new(rotation, [512, 512]);
    let mut image = Image::new(512, 512);
    let stats = renderer.render(&camera, &mut image)?;
    image.save_png(Path::new("quickstart.png"))?;
    println!("quickstart.png: {tissue}, {:.2} ms a frame after {:.0} ms of set-up", stats.frame_ms(), stats.build_ms);
    Ok(())
}
