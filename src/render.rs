//! The frame pipeline: volume → classify → mask → factorize → composite → warp.
//!
//! Owns [`Renderer`], which holds the volume, the classification, one
//! [`SliceStack`] and one sheared mask per principal axis (each built only when a
//! view first needs it, and rebuilt only when the classification changes), the
//! reusable intermediate image and per-slice parameters, and a rayon pool of the
//! requested size. [`Renderer::render`] runs one frame and reports how long each
//! stage took. The output is the same for any thread count: every pixel is
//! computed by exactly one task from the same inputs.

use std::time::Instant;

use crate::classify::{Classifier, TransferFunction};
use crate::composite::{Intermediate, Shading};
use crate::depth::Search;
use crate::error::{Error, Result};
use crate::mask::{BinaryMask, Rect, ShearWork, geometry};
use crate::raycast::{Mode, RayContext, SliceParams, render_binary, render_brute, volume_rect};
use crate::shear::ShearState;
use crate::slices::SliceStack;
use crate::view::{Camera, Factorization};
use crate::volume::Volume;
use crate::warp::{Image, warp};

/// Which render path.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// The bit-packed binary shear-warp fast rotator.
    Binary,
    /// Unaccelerated reference: every slice of every ray, same sample positions.
    Brute,
}

impl Method {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Method::Binary => "binary",
            Method::Brute => "brute",
        }
    }
}

/// Word width of the packed mask.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum WordSize {
    U32,
    U64,
}

impl WordSize {
    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            WordSize::U32 => "u32",
            WordSize::U64 => "u64",
        }
    }
}

/// Render settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    pub method: Method,
    pub mode: Mode,
    pub word: WordSize,
    pub search: Search,
    /// Early ray termination threshold (blend mode); 1.0 disables it.
    pub ert: f32,
    pub shading: Shading,
    /// Worker threads (0 = all cores).
    pub threads: usize,
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            method: Method::Binary,
            mode: Mode::Iso,
            word: WordSize::U64,
            search: Search::Bitscan,
            ert: 0.99,
            shading: Shading::default(),
            threads: 0,
        }
    }
}

/// Timings and work of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct FrameStats {
    /// Building stacks/masks for a newly needed axis (0 when cached).
    pub build_ms: f64,
    pub shear_ms: f64,
    pub render_ms: f64,
    pub warp_ms: f64,
    /// Principal axis of the view.
    pub axis: usize,
    /// One-bit steps, direct shears and words touched by the shear.
    pub shear_steps: u32,
    pub shear_direct: u32,
    pub shear_words: u64,
    /// Rays cast (pixels of the valid rectangle of the intermediate image).
    pub rays: u64,
}

impl FrameStats {
    /// Shear + render + warp (the per-frame cost once masks exist).
    pub fn frame_ms(&self) -> f64 {
        self.shear_ms + self.render_ms + self.warp_ms
    }
}

#[derive(Clone, Debug)]
enum AnyMask {
    W32(BinaryMask<u32>),
    W64(BinaryMask<u64>),
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct MaskKey {
    mode: Mode,
    word: WordSize,
    generation: u64,
}

#[derive(Debug)]
struct AxisMask {
    key: MaskKey,
    mask: AnyMask,
}

/// Renders frames of one volume.
pub struct Renderer {
    volume: Volume,
    range: (f32, f32),
    classifier: Classifier,
    iso: f32,
    settings: Settings,
    /// Bumped whenever the classification changes (invalidates masks).
    generation: u64,
    stacks: [Option<SliceStack>; 3],
    masks: [Option<AxisMask>; 3],
    params: SliceParams,
    inter: Intermediate,
    last_fact: Option<Factorization>,
    pool: rayon::ThreadPool,
}

impl Renderer {
    /// A renderer for `volume` with transfer function `tf`; the iso value starts
    /// at the transfer function's lower threshold.
    pub fn new(volume: Volume, tf: &TransferFunction, settings: Settings) -> Result<Self> {
        let range = volume.value_range();
        let classifier = Classifier::new(tf, range.0, range.1);
        let iso = tf.lower_threshold().unwrap_or(f32::INFINITY);
        let pool = build_pool(settings.threads)?;
        Ok(Renderer {
            volume,
            range,
            classifier,
            iso,
            settings,
            generation: 0,
            stacks: [None, None, None],
            masks: [None, None, None],
            params: SliceParams::default(),
            inter: Intermediate::default(),
            last_fact: None,
            pool,
        })
    }

    /// The volume.
    pub fn volume(&self) -> &Volume {
        &self.volume
    }
    /// Current settings.
    pub fn settings(&self) -> Settings {
        self.settings
    }
    /// Changes settings (rebuilding the thread pool if the count changed).
    pub fn set_settings(&mut self, s: Settings) -> Result<()> {
        if s.threads != self.settings.threads {
            self.pool = build_pool(s.threads)?;
        }
        self.settings = s;
        Ok(())
    }
    /// Replaces the transfer function (masks are rebuilt on the next frame).
    pub fn set_transfer_function(&mut self, tf: &TransferFunction) {
        self.classifier = Classifier::new(tf, self.range.0, self.range.1);
        self.iso = tf.lower_threshold().unwrap_or(f32::INFINITY);
        self.generation += 1;
    }
    /// Sets the iso value of the preview (masks are rebuilt on the next iso frame).
    pub fn set_iso(&mut self, iso: f32) -> Result<()> {
        if iso.is_nan() {
            return Err(Error::value("iso value", "NaN"));
        }
        self.iso = iso;
        self.generation += 1;
        Ok(())
    }
    /// The iso value of the preview.
    pub fn iso(&self) -> f32 {
        self.iso
    }
    /// The classifier.
    pub fn classifier(&self) -> &Classifier {
        &self.classifier
    }
    /// The intermediate image of the last frame.
    pub fn intermediate(&self) -> &Intermediate {
        &self.inter
    }
    /// The factorization of the last frame.
    pub fn last_factorization(&self) -> Option<&Factorization> {
        self.last_fact.as_ref()
    }
    /// Bytes of the packed masks that exist now.
    pub fn mask_bytes(&self) -> usize {
        self.masks
            .iter()
            .flatten()
            .map(|m| match &m.mask {
                AnyMask::W32(m) => m.bytes(),
                AnyMask::W64(m) => m.bytes(),
            })
            .sum()
    }

    fn mask_key(&self) -> MaskKey {
        MaskKey {
            mode: self.settings.mode,
            word: self.settings.word,
            generation: self.generation,
        }
    }

    /// Makes sure the slice stack (and, for the binary path, the mask) of `axis`
    /// exist and are current. Returns the milliseconds spent building.
    fn ensure_axis(&mut self, axis: usize) -> f64 {
        let t = Instant::now();
        if self.stacks[axis].is_none() {
            let vol = &self.volume;
            self.stacks[axis] = Some(self.pool.install(|| SliceStack::new(vol, axis)));
        }
        if self.settings.method == Method::Binary {
            let key = self.mask_key();
            if self.masks[axis].as_ref().map(|m| m.key) != Some(key) {
                let stack = self.stacks[axis].as_ref().expect("stack built above");
                let (mode, iso, cls) = (self.settings.mode, self.iso, &self.classifier);
                let visible = move |lo: f32, hi: f32| match mode {
                    Mode::Iso => hi >= iso,
                    Mode::Blend => cls.may_be_visible(lo, hi),
                };
                let mask = self.pool.install(|| match key.word {
                    WordSize::U32 => AnyMask::W32(BinaryMask::build(stack, visible)),
                    WordSize::U64 => AnyMask::W64(BinaryMask::build(stack, visible)),
                });
                self.masks[axis] = Some(AxisMask { key, mask });
            }
        }
        t.elapsed().as_secs_f64() * 1e3
    }

    /// Builds the stack and mask of every axis now (so frames measure only shear,
    /// render and warp). Returns the milliseconds spent.
    pub fn prepare_all_axes(&mut self) -> f64 {
        (0..3).map(|a| self.ensure_axis(a)).sum()
    }

    /// Renders one frame of `camera` into `out` (resized if needed).
    pub fn render(&mut self, camera: &Camera, out: &mut Image) -> Result<FrameStats> {
        let f = Factorization::new(camera, self.volume.dims(), self.volume.spacing())?;
        let mut stats = FrameStats {
            axis: f.axis,
            ..Default::default()
        };
        stats.build_ms = self.ensure_axis(f.axis);
        let min_sp = self
            .volume
            .spacing()
            .iter()
            .fold(f32::MAX, |a, &b| a.min(b)) as f64;
        self.classifier
            .set_sample_ratio((f.sample_spacing / min_sp) as f32);

        // shear
        let t = Instant::now();
        let state = ShearState::from_view(&f);
        self.params.fill(&state);
        let stack = self.stacks[f.axis].as_ref().expect("ensured");
        let (pad, grid) = geometry(stack.cells(), stack.n[2]);
        let rect: Option<Rect> = match self.settings.method {
            Method::Binary => {
                let m = self.masks[f.axis].as_mut().expect("ensured");
                let w: ShearWork = match &mut m.mask {
                    AnyMask::W32(m) => m.shear_to(&state),
                    AnyMask::W64(m) => m.shear_to(&state),
                };
                stats.shear_steps = w.steps;
                stats.shear_direct = w.direct;
                stats.shear_words = w.words;
                match &m.mask {
                    AnyMask::W32(m) => m.occupied_rect(),
                    AnyMask::W64(m) => m.occupied_rect(),
                }
            }
            Method::Brute => volume_rect(&self.params, stack.cells(), pad, grid),
        };
        stats.shear_ms = t.elapsed().as_secs_f64() * 1e3;

        // render the intermediate image
        let t = Instant::now();
        self.inter.prepare(grid);
        let ctx = RayContext::new(
            stack,
            &self.classifier,
            &self.params,
            &f,
            pad,
            self.settings.mode,
            self.iso,
            self.settings.shading,
            self.settings.ert,
        );
        let (inter, search) = (&mut self.inter, self.settings.search);
        let mask = self.masks[f.axis].as_ref().map(|m| &m.mask);
        self.pool.install(|| match (self.settings.method, mask) {
            (Method::Binary, Some(AnyMask::W32(m))) => render_binary(&ctx, m, search, rect, inter),
            (Method::Binary, Some(AnyMask::W64(m))) => render_binary(&ctx, m, search, rect, inter),
            _ => render_brute(&ctx, rect, inter),
        });
        stats.rays = rect.map_or(0, |r| ((r.p1 - r.p0 + 1) * (r.q1 - r.q0 + 1)) as u64);
        stats.render_ms = t.elapsed().as_secs_f64() * 1e3;

        // warp
        let t = Instant::now();
        out.prepare(camera.size[0], camera.size[1]);
        let inter = &self.inter;
        self.pool
            .install(|| warp(inter, &f, [pad as f64, pad as f64], out));
        stats.warp_ms = t.elapsed().as_secs_f64() * 1e3;
        self.last_fact = Some(f);
        Ok(stats)
    }
}

fn build_pool(threads: usize) -> Result<rayon::ThreadPool> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .map_err(|e| Error::Other(format!("cannot start {threads} worker threads: {e}")))
}
