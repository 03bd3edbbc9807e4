//! Render threads of the viewer.
//!
//! Owns [`Renderers`] (the renderers one worker switches between: the tissue
//! set, whose presets share one threshold-coded mask so a switch is O(1), and a
//! custom-iso renderer made on first use, whose mask is rebuilt when the value
//! changes) and [`Worker`] (a thread with a one-slot mailbox: a new request
//! replaces one that has not started, so requests coalesce and the worker always
//! renders the latest state). Finished frames go to a callback as `0RGB` pixels,
//! with the renderer's statistics; [`Worker::recycle`] gives their buffers back. Before a step that rebuilds a mask the worker
//! reports [`Reply::Busy`], so the window can show it; after a rebuild it builds
//! the other principal axes' masks while no request waits, so a later axis
//! switch does not stall a drag, and reports [`Reply::Prefetched`] when they are
//! all built. After a tissue switch (O(1) on the presets' code mask) the idle
//! worker likewise builds the new preset's own one-bit mask of every axis
//! ([`Renderer::prefetch_axis`]), which the frames after it read.

use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::Instant;

use super::state::{Class, Kind, Lens, Plane, Spec};
use crate::app::scene::Scene;
use shearwarp::classify::presets::{self, Tissue};
use shearwarp::composite::Mode;
use shearwarp::data::volume::Volume;
use shearwarp::geometry::hit::KeptHits;
use shearwarp::render::{Deluxe, Focus, Footprint, FrameStats, Method, Renderer, Settings, Target};
use shearwarp::view::Projection;
use shearwarp::view::clip::{ClipPlane, ClipPlanes, Limiters, Region};
use shearwarp::view::plan::Limiter;
use shearwarp::warp::{Canvas, Image, Image8, Texel};

/// A finished frame.
#[derive(Clone, Debug)]
pub struct Frame {
    pub seq: u64,
    pub kind: Kind,
    pub width: usize,
    pub height: usize,
    /// `0RGB` pixels over black, row 0 at the top.
    pub pixels: Vec<u32>,
    pub stats: FrameStats,
    /// Wall time of the request, including any mask rebuild and the conversion
    /// to `0RGB`.
    pub total_ms: f64,
    /// When the worker took the request from its mailbox.
    pub started: Instant,
    /// Whether the worker still has other principal axes' masks to build while
    /// idle ([`Reply::Prefetched`] follows when they are built).
    pub prefetch: bool,
    pub spec: Spec,
}

/// What a worker reports.
#[derive(Clone, Debug)]
pub enum Reply {
    /// A slow step (a mask rebuild) started for request `seq`.
    Busy {
        kind: Kind,
        seq: u64,
        what: String,
    },
    Frame(Box<Frame>),
    /// The idle worker has built the masks of every principal axis (after a
    /// frame that said [`Frame::prefetch`]): an axis switch no longer stalls.
    Prefetched {
        kind: Kind,
    },
    /// A request failed.
    Failed {
        kind: Kind,
        seq: u64,
        error: String,
    },
}

/// The renderers of one worker.
pub struct Renderers {
    tissues: Renderer,
    custom: Option<Renderer>,
    mode: Mode,
    hi: f32,
    /// Cell size each renderer's masks were last set to.
    cells: [usize; 2],
    /// Principal axes whose masks may be stale after the last rebuild.
    stale: [bool; 3],
    /// The projection of every renderer.
    projection: Projection,
    /// The ray limits of every renderer (clip planes and the scene's clip
    /// regions), if any.
    limiter: Option<Arc<dyn Limiter>>,
    /// The `--clip-plane` half-spaces every frame keeps ([`Renderers::set_clip_planes`]).
    planes: Vec<ClipPlane>,
    /// The interactive plane the limiter was last built with.
    interactive: Option<Plane>,
    spacing: [f32; 3],
    dims: [usize; 3],
    /// The lens's tissue preset (`--focus-tissue`; default bone, else the
    /// densest preset) and the lens the tissue renderer has now.
    focus_tissue: String,
    lens: Option<Lens>,
    /// The lens's surface: the context frame (no lens, iso at the tissue's
    /// threshold) of a spec (its `seq` and `lens` cleared), its plans and
    /// depths kept for the iso hit under the mouse, computed per move.
    surface: Option<(Spec, KeptHits)>,
    /// The geometry and clip regions (`--mesh`, `--needle`, `--clip-box`,
    /// `--clip-sphere`, `--clip-mesh`; [`Renderers::set_scene`]).
    scene: Option<Scene>,
    /// A frame of a scene that draws, in f32: the volume composited over the
    /// geometry there, then rounded into the caller's canvas.
    geometry_frame: Image,
}

impl Renderers {
    /// Renderers for `volume` with `tissues` (as [`presets::tissues_for`] gives),
    /// rendering in `settings.mode`.
    pub fn new(volume: Volume, tissues: &[Tissue], settings: Settings) -> shearwarp::Result<Self> {
        let hi = volume.value_range().1;
        let (spacing, dims) = (volume.spacing(), volume.dims());
        let mut r = Renderer::with_tissues(volume, tissues, settings)?;
        let names: Vec<&str> = r.tissues().map(|(t, _)| t.iter().map(|t| t.name).collect()).unwrap_or_default();
        let focus_tissue = if names.contains(&"bone") { "bone" } else { names.last().copied().unwrap_or("bone") }.to_string();
        r.set_memory_budget(crate::app::budget());
        Ok(Renderers {
            tissues: r,
            custom: None,
            mode: settings.mode,
            hi,
            cells: [settings.cell; 2],
            stale: [true; 3],
            projection: Projection::Parallel,
            limiter: None,
            planes: vec![],
            interactive: None,
            spacing,
            dims,
            focus_tissue,
            lens: None,
            surface: None,
            scene: None,
            geometry_frame: Image::new(0, 0),
        })
    }

    /// Sets the scene of every frame (built by [`Scene::new`] without clip
    /// planes: those are [`Renderers::set_clip_planes`]'s): its clip regions
    /// join the limiter beside the clip planes and the interactive one, and
    /// a scene that draws (meshes, a clip mesh) is drawn into every frame
    /// at the frame's size, camera and projection ([`Scene::render_geometry`]).
    pub fn set_scene(&mut self, scene: Option<Scene>) -> shearwarp::Result<()> {
        self.scene = scene;
        self.surface = None;
        self.build_limiter()
    }

    /// The lens's tissue preset (a name of the tissue set; an error otherwise).
    pub fn set_focus_tissue(&mut self, name: &str) -> shearwarp::Result<()> {
        let names: Vec<&str> = self.tissues.tissues().map(|(t, _)| t.iter().map(|t| t.name).collect()).unwrap_or_default();
        if !names.contains(&name) {
            return Err(shearwarp::Error::value(
                "focus tissue",
                format!("'{name}' is not in this volume's presets ({})", names.join(", ")),
            ));
        }
        self.focus_tissue = name.to_string();
        Ok(())
    }

    /// The lens as the library's focus region: its ball in voxel indices
    /// (radius in units of the smallest spacing).
    fn lens_focus(&self, lens: Lens) -> Focus {
        let unit = self.spacing.iter().fold(f32::INFINITY, |a, &b| a.min(b)) as f64;
        let centre = [0, 1, 2].map(|a| lens.centre[a] / self.spacing[a] as f64 + (self.dims[a] as f64 - 1.0) / 2.0);
        Focus::new(Region::Sphere { centre, radius: lens.radius / unit }, self.focus_tissue.clone())
    }

    /// Sets the projection of every renderer (a perspective one renders only
    /// with the RLE paths).
    pub fn set_projection(&mut self, projection: Projection) -> shearwarp::Result<()> {
        self.tissues.set_projection(projection)?;
        if let Some(c) = &mut self.custom {
            c.set_projection(projection)?;
        }
        self.projection = projection;
        Ok(())
    }

    /// Sets the ray limits (clip planes) of every renderer, this one's and any
    /// made later.
    pub fn set_limiter(&mut self, limiter: Option<Arc<dyn Limiter>>) {
        self.tissues.set_limiter(limiter.clone());
        if let Some(c) = &mut self.custom {
            c.set_limiter(limiter.clone());
        }
        self.limiter = limiter;
    }

    /// Sets the clip planes (world millimetres from the volume centre) every
    /// frame keeps, beside the interactive plane of each frame's spec.
    pub fn set_clip_planes(&mut self, planes: Vec<ClipPlane>) -> shearwarp::Result<()> {
        ClipPlanes::new(&planes, self.spacing)?;
        self.planes = planes;
        self.build_limiter()
    }

    /// The limiter of the `--clip-plane` planes and the interactive one (when
    /// there is no room for the interactive plane, six planes already, the
    /// given ones alone), followed by the scene's clip regions.
    fn build_limiter(&mut self) -> shearwarp::Result<()> {
        let mut all = self.planes.clone();
        if let Some(p) = self.interactive.and_then(|p| ClipPlane::new(p.normal, p.offset).ok()) {
            all.push(p);
        }
        let clip = ClipPlanes::new(&all, self.spacing).or_else(|_| ClipPlanes::new(&self.planes, self.spacing));
        let mut chain: Vec<Arc<dyn Limiter>> = match clip {
            Ok(c) if !c.planes().is_empty() => vec![Arc::new(c)],
            _ => vec![],
        };
        chain.extend(self.scene.as_ref().and_then(Scene::clip));
        let limiter: Option<Arc<dyn Limiter>> = match chain.len() {
            0 => None,
            1 => chain.pop(),
            _ => Some(Arc::new(Limiters::new(chain)?)),
        };
        self.set_limiter(limiter);
        Ok(())
    }

    /// The tissue presets, sorted by threshold as [`Renderer::with_tissues`] keeps them.
    pub fn tissue_list(&self) -> Vec<Tissue> {
        self.tissues.tissues().map(|(t, _)| t.to_vec()).unwrap_or_default()
    }

    /// Whether rendering `class` at `cell` must rebuild a mask first.
    pub fn needs_rebuild(&self, class: Class, cell: usize) -> bool {
        match class {
            Class::Tissue(_) => self.cells[0] != cell,
            Class::Custom(v) => self.custom.as_ref().is_none_or(|r| r.iso() != v) || self.cells[1] != cell,
        }
    }

    /// The cell size a rotation takes by default for the tissue presets
    /// ([`Renderer::auto_cell`]).
    pub fn auto_cell(&self) -> usize {
        self.tissues.auto_cell()
    }

    /// The renderer for `class` at `cell`, switched to it.
    pub fn select(&mut self, class: Class, cell: usize) -> shearwarp::Result<&mut Renderer> {
        if self.needs_rebuild(class, cell) {
            self.stale = [true; 3];
        }
        let (r, slot) = match class {
            Class::Tissue(i) => {
                if self.tissues.tissues().is_some_and(|(_, c)| c != i) {
                    // O(1): the frames read the threshold-coded mask until the
                    // idle worker has built the new preset's own mask
                    self.stale = [true; 3];
                }
                self.tissues.select_tissue(i)?;
                (&mut self.tissues, 0)
            }
            Class::Custom(v) => {
                let tf = presets::generic(v, self.hi).tf;
                match &mut self.custom {
                    Some(r) => {
                        if r.iso() != v {
                            r.set_transfer_function(&tf);
                        }
                    }
                    None => {
                        let s = Settings { cell, ..self.tissues.settings() };
                        let mut c = Renderer::new(self.tissues.volume()?.into_owned(), &tf, s)?;
                        c.set_memory_budget(crate::app::budget());
                        c.set_projection(self.projection)?;
                        c.set_limiter(self.limiter.clone());
                        self.custom = Some(c);
                        self.cells[1] = cell;
                    }
                }
                (self.custom.as_mut().expect("made above"), 1)
            }
        };
        if self.cells[slot] != cell {
            r.set_settings(Settings { cell, ..r.settings() })?;
            self.cells[slot] = cell;
        }
        debug_assert_eq!(r.settings().mode, self.mode);
        Ok(r)
    }

    /// Renders `spec` into `img` (its lens on the surface under the mouse:
    /// [`Renderers::lens_on_surface`]).
    pub fn render<T: Texel>(&mut self, spec: &Spec, img: &mut Canvas<T>) -> shearwarp::Result<FrameStats>
    where
        Canvas<T>: Target,
    {
        let lens = match spec.lens {
            Some(l) => Some(self.lens_on_surface(spec, l)?),
            None => None,
        };
        self.set_lens(lens)?;
        self.render_spec(spec, img)
    }

    fn set_lens(&mut self, lens: Option<Lens>) -> shearwarp::Result<()> {
        if lens != self.lens {
            let focus = lens.map(|l| self.lens_focus(l));
            self.tissues.set_focus(focus)?;
            self.lens = lens;
        }
        Ok(())
    }

    /// The lens `l` of `spec` centred on the first visible surface under
    /// the mouse (`l.at`): the iso hit of the context frame (`spec` without
    /// the lens, in iso mode: the tissue's threshold) under that output pixel
    /// ([`shearwarp::geometry::volume_hit`], the depth test's lookup; a
    /// perspective frame split into pyramids keeps their depths for it), and
    /// `l` as it is (the volume centre's depth) where the ray meets no
    /// surface. The blend display takes the same iso depth of the tissue's
    /// threshold: its traversal records no per-ray depth, and so the lens of
    /// the still blend frame is where the iso preview put it. Not the lens
    /// frame's own hit: inside the lens the focus tissue shows, so that hit
    /// lies deeper and the lens would walk away from the skin frame by
    /// frame. The lens moves with the mouse only: while the mouse stays (a
    /// rotation, a size or tissue change) it keeps its place in the volume,
    /// as before. The context frame is rendered once per view (camera, tissue,
    /// projection, quality, clip) and its plans and depths kept
    /// ([`KeptHits`]): each move computes the hit of its one pixel, so a
    /// mouse move over the same view costs one frame, the first after a
    /// rotation two (the context and the lens frame). Only on the raycaster (`--method binary` / `brute`,
    /// where a focus or mode switch rebuilds nothing); with the RLE paths and
    /// a custom iso value the lens stays at the volume centre's depth.
    pub fn lens_on_surface(&mut self, spec: &Spec, l: Lens) -> shearwarp::Result<Lens> {
        let Some([x, y]) = l.at else { return Ok(l) };
        // the mouse has not moved since the lens was placed (a rotation, a
        // size or tissue change): it stays where it is in the volume
        if let Some(prev) = self.lens.filter(|p| p.at == l.at) {
            return Ok(Lens { centre: prev.centre, ..l });
        }
        let raycast = matches!(self.tissues.settings().method, Method::Binary | Method::Brute);
        if !raycast || !matches!(spec.class, Class::Tissue(_)) {
            return Ok(l);
        }
        let key = Spec { seq: 0, lens: None, ..*spec };
        if self.surface.as_ref().is_none_or(|(k, _)| *k != key) {
            self.surface = None;
            self.set_lens(None)?;
            let mode = self.mode;
            let settings = self.tissues.settings();
            self.tissues.set_settings(Settings { mode: Mode::Iso, ..settings })?;
            self.mode = Mode::Iso;
            self.tissues.set_keep_depths(true);
            let [w, h] = spec.camera.size;
            let mut scratch = Image8::new(w, h);
            let done = self.render_spec(&key, &mut scratch);
            // the frame's plans and depths, for this move and the next ones over the same view
            let hits = KeptHits::of(&self.tissues);
            self.mode = mode;
            self.tissues.set_keep_depths(false);
            self.tissues.set_settings(Settings { mode, ..self.tissues.settings() })?;
            done?;
            self.surface = Some((key, hits));
        }
        let (_, hits) = self.surface.as_ref().expect("made above");
        let [w, h] = spec.camera.size;
        let (u, v) = (x.round(), y.round());
        if u < 0.0 || v < 0.0 || u >= w as f64 || v >= h as f64 {
            return Ok(l);
        }
        let Some(p) = hits.at(u, v).map(|v| v.to_array()).filter(|p| p.iter().all(|c| c.is_finite())) else { return Ok(l) };
        // voxel indices to world millimetres from the volume centre (lens_focus's inverse)
        let centre = [0, 1, 2].map(|a| (p[a] - (self.dims[a] as f64 - 1.0) / 2.0) * self.spacing[a] as f64);
        Ok(Lens { centre, ..l })
    }

    /// Renders `spec` into `img` with the lens the renderers have now.
    fn render_spec<T: Texel>(&mut self, spec: &Spec, img: &mut Canvas<T>) -> shearwarp::Result<FrameStats>
    where
        Canvas<T>: Target,
    {
        if spec.projection != self.projection {
            self.set_projection(spec.projection)?;
        }
        if spec.clip != self.interactive {
            self.interactive = spec.clip;
            self.build_limiter()?;
        }
        let q = spec.quality;
        let r = self.select(spec.class, spec.cell)?;
        if r.quality() != q {
            r.set_quality(q)?;
            // a coarse grid while moving is for speed: sampled at pixel centres,
            // the frame at one pixel per voxel or finer with the box footprint
            // (and so a perspective's far slices)
            let footprint = if q < 1.0 { Footprint::Bilinear } else { Footprint::Box };
            r.set_settings(Settings { footprint, ..r.settings() })?;
        }
        // a still view (the release render after a drag) with matched sampling
        // (Deluxe M): as many samples per voxel as the zoom magnifies, none
        // more where it does not; a drag's frames without it
        let d = r.settings().deluxe;
        if d.matched != spec.still {
            r.set_settings(Settings { deluxe: Deluxe { matched: spec.still, ..d }, ..r.settings() })?;
        }
        // a scene that draws: the geometry stage of render and rotate, in
        // f32, rounded into `img` after the composite (no scene, or one of
        // clip regions alone: the renderer's own frame, nothing more); the
        // renderer selected above, beside the fields the stage reads
        let r = match spec.class {
            Class::Tissue(_) => &mut self.tissues,
            Class::Custom(_) => self.custom.as_mut().expect("selected above"),
        };
        let draws = self.scene.as_ref().filter(|s| s.draws());
        let (limiter, frame) = (&self.limiter, &mut self.geometry_frame);
        let mut once = |r: &mut Renderer| match draws {
            None => r.render(&spec.camera, img),
            Some(scene) => {
                let (st, _) = scene.render_geometry(r, &spec.camera, frame, limiter.clone(), false)?;
                frame.convert_into(img);
                Ok(st)
            }
        };
        let st = match once(r) {
            // a zoom whose matched grid is past the memory limit: the frame without M
            Err(_) if spec.still => {
                let s = r.settings();
                r.set_settings(Settings { deluxe: Deluxe { matched: false, ..s.deluxe }, ..s })?;
                once(r)?
            }
            st => st?,
        };
        self.stale[st.axis] = r.preset_mask_pending(st.axis);
        Ok(st)
    }

    /// Builds the mask of one stale principal axis of the current renderer, if
    /// any is left; returns whether it did.
    fn prepare_one(&mut self, class: Class, cell: usize) -> bool {
        let Some(axis) = self.stale.iter().position(|&s| s) else { return false };
        self.stale[axis] = false;
        if let Ok(r) = self.select(class, cell) {
            // an axis that does not fit the memory budget beside the others is
            // left for the frame that needs it (never evicting the one on screen)
            let _ = r.prefetch_axis(axis);
        }
        true
    }
}

#[derive(Default)]
struct Mailbox {
    job: Option<Spec>,
    quit: bool,
    /// Pixel buffers of frames no longer on screen, for the next frames.
    spare: Vec<Vec<u32>>,
}

/// How many returned pixel buffers a worker keeps.
const SPARE_BUFFERS: usize = 2;

/// A render thread with a one-slot mailbox.
pub struct Worker {
    mail: Arc<(Mutex<Mailbox>, Condvar)>,
    /// The render thread (joined only by tests; a dropped worker tells it to quit and detaches it).
    #[cfg_attr(not(test), allow(dead_code))]
    handle: Option<JoinHandle<()>>,
}

impl Worker {
    /// Starts a worker that renders with `renderers` and reports through `reply`.
    /// With `prepare`, it says it is busy building the first view (which the
    /// first request builds: one principal axis); whenever it is idle it builds
    /// the other axes, one per turn, and then says [`Reply::Prefetched`].
    pub fn spawn(kind: Kind, mut renderers: Renderers, prepare: bool, reply: impl Fn(Reply) + Send + 'static) -> Self {
        let mail: Arc<(Mutex<Mailbox>, Condvar)> = Arc::default();
        let m = mail.clone();
        let handle = std::thread::Builder::new()
            .name(format!("shearwarp-{}", kind.name()))
            .spawn(move || {
                if prepare {
                    // the first frame builds only what its view needs (one axis);
                    // the idle worker builds the other axes after it
                    reply(Reply::Busy { kind, seq: 0, what: "building the first view".into() });
                }
                // rounded to 8 bits by the warp: what the window shows
                let mut img = Image8::new(1, 1);
                let mut last: Option<Spec> = None;
                loop {
                    let next = {
                        let (lock, cv) = &*m;
                        let mut g = lock.lock().unwrap_or_else(|e| e.into_inner());
                        loop {
                            if g.quit {
                                return;
                            }
                            if let Some(s) = g.job.take() {
                                // a recycled buffer: no fresh megabyte to fault in per frame
                                break Some((s, g.spare.pop().unwrap_or_default()));
                            }
                            if last.is_some() && renderers.stale.contains(&true) {
                                break None;
                            }
                            g = cv.wait(g).unwrap_or_else(|e| e.into_inner());
                        }
                    };
                    let Some((spec, mut pixels)) = next else {
                        // idle: build the other axes' masks, one per turn, before sleeping
                        let l = last.expect("checked above");
                        renderers.prepare_one(l.class, l.cell);
                        if !renderers.stale.contains(&true) {
                            reply(Reply::Prefetched { kind });
                        }
                        continue;
                    };
                    let t = Instant::now();
                    if renderers.needs_rebuild(spec.class, spec.cell) {
                        let what = match spec.class {
                            Class::Custom(v) => format!("rebuilding mask for iso {v:.1}, cell {}", spec.cell),
                            Class::Tissue(_) => format!("rebuilding mask for cell {}", spec.cell),
                        };
                        reply(Reply::Busy { kind, seq: spec.seq, what });
                    }
                    match renderers.render(&spec, &mut img) {
                        Ok(stats) => {
                            img.to_0rgb(&mut pixels);
                            let total_ms = t.elapsed().as_secs_f64() * 1e3;
                            let (width, height) = (img.width, img.height);
                            let prefetch = renderers.stale.contains(&true);
                            let f = Frame { seq: spec.seq, kind, width, height, pixels, stats, total_ms, started: t, prefetch, spec };
                            reply(Reply::Frame(Box::new(f)));
                        }
                        Err(e) => reply(Reply::Failed { kind, seq: spec.seq, error: e.to_string() }),
                    }
                    last = Some(spec);
                }
            })
            .expect("spawn a render thread");
        Worker { mail, handle: Some(handle) }
    }

    /// Asks for `spec`, replacing a request that has not started.
    pub fn post(&self, spec: Spec) {
        let (lock, cv) = &*self.mail;
        lock.lock().unwrap_or_else(|e| e.into_inner()).job = Some(spec);
        cv.notify_one();
    }

    /// Gives the pixel buffer of a frame no longer shown back for later frames.
    pub fn recycle(&self, pixels: Vec<u32>) {
        let (lock, _) = &*self.mail;
        let mut g = lock.lock().unwrap_or_else(|e| e.into_inner());
        if g.spare.len() < SPARE_BUFFERS && pixels.capacity() > 0 {
            g.spare.push(pixels);
        }
    }

    /// Drops a request that has not started (one in progress still reports; its
    /// sequence number tells the caller to discard it).
    pub fn cancel(&self) {
        let (lock, _) = &*self.mail;
        lock.lock().unwrap_or_else(|e| e.into_inner()).job = None;
    }

    /// Stops the thread after its current render and waits for it.
    #[cfg(test)]
    pub fn stop(mut self) {
        self.signal_quit();
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }

    fn signal_quit(&self) {
        let (lock, cv) = &*self.mail;
        lock.lock().unwrap_or_else(|e| e.into_inner()).quit = true;
        cv.notify_one();
    }
}

impl Drop for Worker {
    /// Tells the thread to stop without waiting for a render in progress.
    fn drop(&mut self) {
        self.signal_quit();
    }
}

#[cfg(test)]
mod tests {
    use std::sync::mpsc;
    use std::time::Duration;

    use super::*;
    use shearwarp::data::phantom::Phantom;
    use shearwarp::view::Camera;
    use shearwarp::warp::Image;

    /// The first tissue's still parallel frame through `camera`.
    pub(super) fn spec_at(camera: Camera) -> Spec {
        Spec {
            seq: 1,
            camera,
            class: Class::Tissue(0),
            cell: 1,
            projection: Projection::Parallel,
            quality: 1.0,
            clip: None,
            lens: None,
            still: true,
        }
    }

    /// The small head phantom's renderers with `s`, and [`spec_at`] a 64×48
    /// anterior camera.
    fn setup_with(s: Settings) -> (Renderers, Spec) {
        let vol = Phantom::Head.build([40, 40, 36]).unwrap();
        let tissues = presets::tissues_for(&vol);
        let r = Renderers::new(vol, &tissues, s).unwrap();
        let cam = Camera { rotation: shearwarp::view::NamedView::Anterior.rotation(), zoom: None, size: [64, 48] };
        (r, spec_at(cam))
    }

    fn setup(mode: Mode) -> (Renderers, Spec) {
        setup_with(Settings { mode, threads: 1, ..Settings::default() })
    }

    fn frame(rx: &mpsc::Receiver<Reply>) -> Frame {
        loop {
            match rx.recv_timeout(Duration::from_secs(60)).expect("a reply") {
                Reply::Frame(f) => return *f,
                Reply::Failed { error, .. } => panic!("{error}"),
                Reply::Busy { .. } | Reply::Prefetched { .. } => {}
            }
        }
    }

    /// The lens under the mouse is centred on the first visible surface
    /// (the iso hit of the context frame at the tissue's threshold): over the
    /// sphere phantom, on the analytic iso surface of the tissue's threshold
    /// (the phantom's density is 100 + 25·(R − r)) within a voxel and within
    /// a voxel of the pixel's ray, on the eye's side; off the ball, at the
    /// fallback centre given. The iso preview and the blend display put it at
    /// the same place; parallel, and a perspective frame split into pyramids.
    #[test]
    fn lens_centre_is_on_the_surface_under_the_mouse() {
        use shearwarp::accuracy::reference::Rays;
        use shearwarp::data::phantom::{sphere, sphere_geometry};
        let dims = [40, 40, 40];
        let vol = sphere(dims).unwrap();
        let (c, radius) = sphere_geometry(dims);
        let c = glam::DVec3::from_array(c);
        let tissues = presets::tissues_for(&vol);
        let t = tissues[0].threshold as f64;
        assert!(t > 0.0 && t < 200.0, "the tissue's iso surface is in the ramp ({t})");
        let surface = radius + (100.0 - t) / 25.0;
        let rot = shearwarp::view::rotate_eye(shearwarp::view::NamedView::Anterior.rotation(), 1, 20.0);
        let cam = Camera { rotation: rot, zoom: None, size: [64, 48] };
        let fallback = Lens { centre: [1.0, 2.0, 3.0], radius: 10.0, at: None };
        for projection in [Projection::Parallel, Projection::perspective(90.0, 0.45).unwrap()] {
            let mut centres = vec![];
            for mode in [Mode::Iso, Mode::Blend] {
                let mut r = Renderers::new(vol.clone(), &tissues, Settings { mode, threads: 1, ..Settings::default() }).unwrap();
                let spec = Spec { projection, ..spec_at(cam) };
                let rays = Rays::with_projection(&cam, &projection, dims, [1.0; 3]).unwrap();
                let toward_eye = rot.transpose() * glam::DVec3::Z;
                let mut img = Image::new(64, 48);
                for at in [[32.0, 24.0], [40.0, 20.0], [25.0, 30.0]] {
                    let l = Lens { at: Some(at), ..fallback };
                    let got = r.lens_on_surface(&Spec { lens: Some(l), ..spec }, l).unwrap();
                    let p = glam::DVec3::from_array([0, 1, 2].map(|a| got.centre[a] + (dims[a] as f64 - 1.0) / 2.0));
                    let what = format!("{projection:?} {mode:?} at {at:?}: {p}");
                    assert!(((p - c).length() - surface).abs() <= 1.0, "{what}: {} from the centre, surface {surface}", (p - c).length());
                    let (o, d) = rays.ray(at[0], at[1]);
                    assert!((p - o).cross(d).length() / d.length() <= 1.0, "{what}: off the pixel's ray");
                    assert!((p - c).dot(toward_eye) > 0.0, "{what}: on the far side");
                    centres.push(got.centre);
                    // the frame renders with it (a lens that follows the mouse)
                    r.render(&Spec { lens: Some(l), ..spec }, &mut img).unwrap();
                }
                if projection.is_perspective() {
                    assert!(r.select(Class::Tissue(0), 1).unwrap().last_plans().len() > 1, "the frame splits");
                }
                // off the ball: the fallback
                let l = Lens { at: Some([1.0, 1.0]), ..fallback };
                assert_eq!(r.lens_on_surface(&Spec { lens: Some(l), ..spec }, l).unwrap(), l, "{projection:?} {mode:?}: off the ball");
                let l = Lens { at: None, ..fallback };
                assert_eq!(r.lens_on_surface(&Spec { lens: Some(l), ..spec }, l).unwrap(), l, "a --focus lens stays");
            }
            assert_eq!(centres[..3], centres[3..], "{projection:?}: the preview and the blend display agree");
        }
    }

    /// The context frame's kept hits ([`KeptHits`], what the lens reads
    /// under the mouse) are [`volume_hit`] of that frame bit for bit, after
    /// the renderer has rendered another frame (the lens frame, its own
    /// depths); parallel, and a perspective frame split into pyramids.
    #[test]
    fn lens_kept_hits_are_the_volume_hit_of_the_context_frame() {
        use shearwarp::geometry::volume_hit;
        let vol = Phantom::Head.build([40, 40, 36]).unwrap();
        let tissues = presets::tissues_for(&vol);
        let rot = shearwarp::view::rotate_eye(shearwarp::view::NamedView::Anterior.rotation(), 1, 25.0);
        let cam = Camera { rotation: rot, zoom: None, size: [64, 48] };
        for projection in [Projection::Parallel, Projection::perspective(90.0, 0.45).unwrap()] {
            let mut r =
                Renderer::with_tissues(vol.clone(), &tissues, Settings { mode: Mode::Iso, threads: 1, ..Settings::default() }).unwrap();
            r.set_projection(projection).unwrap();
            r.set_keep_depths(true);
            let mut img = Image::new(64, 48);
            r.render(&cam, &mut img).unwrap();
            let want: Vec<Option<glam::DVec3>> = (0..64 * 48).map(|i| volume_hit(&r, (i % 64) as f64, (i / 64) as f64)).collect();
            let n = want.iter().filter(|h| h.is_some()).count();
            assert!(n > 100, "{projection:?}: the head is hit ({n} pixels)");
            let kept = KeptHits::of(&r);
            // another frame (another view) over the renderer's own plans and depths
            r.set_keep_depths(false);
            let other = Camera { rotation: shearwarp::view::rotate_eye(rot, 0, 30.0), ..cam };
            r.render(&other, &mut img).unwrap();
            for (i, w) in want.iter().enumerate() {
                let (u, v) = ((i % 64) as f64, (i / 64) as f64);
                let got = kept.at(u, v);
                assert_eq!(
                    got.map(|g| g.to_array().map(f64::to_bits)),
                    w.map(|g| g.to_array().map(f64::to_bits)),
                    "{projection:?} pixel {u} {v}"
                );
            }
            if projection.is_perspective() {
                assert!(r.last_plans().len() > 1, "the frame splits");
            }
        }
    }

    /// A still view that magnifies renders with matched sampling (Deluxe M:
    /// 4 samples per voxel at a zoom of 4), a drag's frame without it, and a
    /// still view that does not magnify at one sample per voxel.
    #[test]
    fn still_views_use_matched_sampling_when_the_zoom_magnifies() {
        let (mut r, spec) = setup(Mode::Iso);
        let cam = Camera { zoom: Some(4.0), size: [96, 96], ..spec.camera };
        let mut img = Image::new(96, 96);
        let pitch = |r: &mut Renderers| r.select(Class::Tissue(0), 1).unwrap().last_plan().unwrap().grid.pitch;
        r.render(&Spec { camera: cam, ..spec }, &mut img).unwrap();
        assert_eq!(pitch(&mut r), [0.25; 2]);
        r.render(&Spec { camera: cam, still: false, ..spec }, &mut img).unwrap();
        assert_eq!(pitch(&mut r), [1.0; 2]);
        r.render(&spec, &mut img).unwrap();
        assert_eq!(pitch(&mut r), [1.0; 2]);
    }

    /// `view --method rle --perspective FOV`: the preview, the blend display
    /// and a custom iso all render the perspective projection.
    #[test]
    fn renderers_render_perspective() {
        for mode in [Mode::Iso, Mode::Blend] {
            let (mut r, spec) = setup_with(Settings { mode, threads: 1, method: shearwarp::render::Method::Rle, ..Settings::default() });
            let mut par = Image::new(64, 48);
            r.render(&spec, &mut par).unwrap();
            // the spec's projection is what renders
            let persp = Projection::perspective(40.0, 1.5).unwrap();
            for class in [Class::Tissue(0), Class::Custom(100.0)] {
                let mut img = Image::new(64, 48);
                r.render(&Spec { class, projection: persp, ..spec }, &mut img).unwrap();
                assert!(img.coverage() > 0.05, "{mode:?} {class:?}");
                assert!(r.select(class, 1).unwrap().last_plan().unwrap().perspective.is_some());
            }
        }
    }

    /// The C key's plane reaches every renderer through the spec: through the
    /// centre facing the viewer it cuts away about half the head's pixels'
    /// nearest surface; far behind the volume it removes everything; off
    /// again, the whole image comes back bit for bit.
    #[test]
    fn renderers_render_the_interactive_clip_plane() {
        for mode in [Mode::Iso, Mode::Blend] {
            let (mut r, spec) = setup(mode);
            let mut whole = Image::new(64, 48);
            r.render(&spec, &mut whole).unwrap();
            let r3 = spec.camera.rotation;
            let toward = [r3.x_axis.z, r3.y_axis.z, r3.z_axis.z];
            let mut cut = Image::new(64, 48);
            r.render(&Spec { clip: Some(Plane { normal: toward, offset: 0.0 }), ..spec }, &mut cut).unwrap();
            assert!(cut.coverage() > 0.0 && cut != whole, "{mode:?}: the plane changed nothing");
            let mut none = Image::new(64, 48);
            r.render(&Spec { clip: Some(Plane { normal: toward, offset: -1e4 }), ..spec }, &mut none).unwrap();
            assert_eq!(none.coverage(), 0.0, "{mode:?}");
            let mut back = Image::new(64, 48);
            r.render(&spec, &mut back).unwrap();
            assert!(back == whole, "{mode:?}: removing the plane did not restore the image");
        }
    }

    /// `view --clip-plane`: the preview, a custom iso and the blend display
    /// all render the clipped volume (a plane keeping nothing: an empty image).
    #[test]
    fn renderers_render_clip_planes() {
        use shearwarp::view::clip::{ClipPlane, ClipPlanes};
        for mode in [Mode::Iso, Mode::Blend] {
            let (mut r, spec) = setup(mode);
            let sp = r.select(Class::Tissue(0), 1).unwrap().spacing();
            let half = ClipPlanes::new(&[ClipPlane::new([1.0, 0.0, 0.0], 0.0).unwrap()], sp).unwrap();
            let none = ClipPlanes::new(&[ClipPlane::new([1.0, 0.0, 0.0], -1e6).unwrap()], sp).unwrap();
            for class in [Class::Tissue(0), Class::Custom(100.0)] {
                let (mut full, mut cut, mut empty) = (Image::new(64, 48), Image::new(64, 48), Image::new(64, 48));
                r.set_limiter(None);
                r.render(&Spec { class, ..spec }, &mut full).unwrap();
                r.set_limiter(Some(std::sync::Arc::new(half.clone())));
                r.render(&Spec { class, ..spec }, &mut cut).unwrap();
                r.set_limiter(Some(std::sync::Arc::new(none.clone())));
                r.render(&Spec { class, ..spec }, &mut empty).unwrap();
                assert!(full.coverage() > 0.05, "{mode:?} {class:?}");
                assert!(cut.coverage() > 0.2 * full.coverage() && cut.coverage() < 0.8 * full.coverage(), "{mode:?} {class:?}");
                assert_eq!(empty.coverage(), 0.0, "{mode:?} {class:?}");
            }
        }
    }

    /// The scene flags of `shearwarp view FLAGS` (the command line's defaults
    /// for the rest).
    fn scene_args(flags: &[&str]) -> crate::app::scene::SceneArgs {
        use clap::Parser;
        let cli = crate::app::cli::Cli::try_parse_from(["shearwarp", "view"].iter().chain(flags)).expect("parses");
        let crate::app::cli::Command::View(v) = cli.command else { panic!("not the view command") };
        v.render.scene
    }

    /// The scene of `args` for the head phantom of [`setup`]'s size (no clip
    /// planes: the viewer's are its own).
    fn scene(args: &crate::app::scene::SceneArgs) -> Scene {
        let vol = Phantom::Head.build([40, 40, 36]).unwrap();
        Scene::new(args, None, vol.dims(), vol.spacing()).unwrap()
    }

    /// The CLI's frame (`render` / `rotate`: [`Scene::new`], [`Scene::install`],
    /// [`Scene::render`] on one renderer) of the head phantom with the
    /// settings, tissue and projection the viewer's renderer of `class` has
    /// after rendering `spec` (the library renderer of the same limiters).
    fn cli_frame(r: &mut Renderers, spec: &Spec, args: &crate::app::scene::SceneArgs, planes: Option<Arc<dyn Limiter>>) -> Image {
        let vr = r.select(spec.class, spec.cell).unwrap();
        let (settings, quality) = (vr.settings(), vr.quality());
        let vol = Phantom::Head.build([40, 40, 36]).unwrap();
        let (dims, sp) = (vol.dims(), vol.spacing());
        let mut cli = match spec.class {
            Class::Tissue(i) => {
                let mut c = Renderer::with_tissues(vol.clone(), &presets::tissues_for(&vol), settings).unwrap();
                c.select_tissue(i).unwrap();
                c
            }
            Class::Custom(v) => Renderer::new(vol.clone(), &presets::generic(v, vol.value_range().1).tf, settings).unwrap(),
        };
        cli.set_projection(spec.projection).unwrap();
        cli.set_quality(quality).unwrap();
        let scene = Scene::new(args, planes, dims, sp).unwrap();
        scene.install(&mut cli);
        let mut img = Image::new(spec.camera.size[0], spec.camera.size[1]);
        scene.render(&mut cli, &spec.camera, &mut img).unwrap();
        img
    }

    /// `view --clip-box … --clip-keep inside|outside` (and `--clip-sphere`):
    /// the viewer's frames (its f32 and its 8-bit canvas) are the CLI's
    /// frames of the same clip region bit for bit, for a preset, another
    /// preset, a custom iso and the blend display, parallel and perspective;
    /// with the interactive plane (C) the region chains after it, as the
    /// CLI's `--clip-plane` does; the region changes the picture.
    #[test]
    fn renderers_render_clip_regions_as_the_cli() {
        let boxed = |keep| scene_args(&["--clip-box", "0,0,0,20,39,35", "--clip-keep", keep]);
        let ball = scene_args(&["--clip-sphere", "20,14,18,12", "--clip-keep", "outside"]);
        let persp = Projection::perspective(40.0, 1.5).unwrap();
        for mode in [Mode::Iso, Mode::Blend] {
            for args in [boxed("inside"), boxed("outside"), ball.clone()] {
                let (mut r, spec) = setup(mode);
                let mut plain = Image::new(64, 48);
                r.render(&spec, &mut plain).unwrap();
                r.set_scene(Some(scene(&args))).unwrap();
                for (class, projection) in
                    [(Class::Tissue(0), Projection::Parallel), (Class::Tissue(3), persp), (Class::Custom(100.0), Projection::Parallel)]
                {
                    let spec = Spec { class, projection, ..spec };
                    let (mut img, mut img8) = (Image::new(64, 48), Image8::new(64, 48));
                    r.render(&spec, &mut img).unwrap();
                    r.render(&spec, &mut img8).unwrap();
                    let want = cli_frame(&mut r, &spec, &args, None);
                    let what = format!("{mode:?} {args:?} {class:?} {projection:?}");
                    assert!(img == want, "{what}: the viewer's frame is not the CLI's");
                    assert_eq!(img8.data, want.to_rgba8(), "{what}: 8 bits");
                    assert!(want.coverage() > 0.02, "{what}: something is left");
                }
                let mut cut = Image::new(64, 48);
                r.render(&spec, &mut cut).unwrap();
                assert!(cut != plain, "{mode:?} {args:?}: the region changed nothing");
                // the interactive plane and the region: the CLI's --clip-plane and region
                let r3 = spec.camera.rotation;
                let plane = Plane { normal: [r3.x_axis.z, r3.y_axis.z, r3.z_axis.z], offset: 10.0 };
                let spec = Spec { clip: Some(plane), ..spec };
                let mut img = Image::new(64, 48);
                r.render(&spec, &mut img).unwrap();
                let sp = Phantom::Head.build([40, 40, 36]).unwrap().spacing();
                let planes = ClipPlanes::new(&[ClipPlane::new(plane.normal, plane.offset).unwrap()], sp).unwrap();
                let want = cli_frame(&mut r, &spec, &args, Some(Arc::new(planes)));
                assert!(img == want, "{mode:?} {args:?}: the plane and the region");
                assert!(img != cut, "{mode:?} {args:?}: the plane changed nothing");
            }
        }
    }

    /// A closed cube, voxels 8 to 20 on every axis (OBJ).
    const CUBE_OBJ: &str = "v 8 8 8\nv 20 8 8\nv 20 20 8\nv 8 20 8\nv 8 8 20\nv 20 8 20\nv 20 20 20\nv 8 20 20\n\
        f 1 3 2\nf 1 4 3\nf 5 6 7\nf 5 7 8\nf 1 2 6\nf 1 6 5\nf 2 3 7\nf 2 7 6\nf 3 4 8\nf 3 8 7\nf 4 1 5\nf 4 5 8\n";

    /// Two regions keeping their outside (a box and a clip mesh) are refused
    /// by the scene, as by the CLI; a clip plane chained with one is not.
    #[test]
    fn two_outside_clip_regions_are_refused() {
        let dir = std::env::temp_dir().join(format!("shearwarp-viewer-clip-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cube = dir.join("cube.obj");
        std::fs::write(&cube, CUBE_OBJ).unwrap();
        let vol = Phantom::Head.build([40, 40, 36]).unwrap();
        let cube = cube.to_str().unwrap();
        let args = scene_args(&["--clip-box", "0,0,0,20,20,20", "--clip-mesh", cube, "--clip-keep", "outside"]);
        let e = Scene::new(&args, None, vol.dims(), vol.spacing()).err().expect("refused");
        assert!(e.to_string().contains("at most one region may keep its outside"), "{e}");
        let (mut r, spec) = setup(Mode::Iso);
        r.set_clip_planes(vec![ClipPlane::new([1.0, 0.0, 0.0], 0.0).unwrap()]).unwrap();
        r.set_scene(Some(scene(&scene_args(&["--clip-mesh", cube, "--clip-keep", "outside"])))).unwrap();
        let mut img = Image::new(64, 48);
        r.render(&spec, &mut img).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// `view --needle …`: the viewer's frame of a needle through the head is
    /// `Scene::render`'s frame (the CLI's) of the same camera bit for bit, in
    /// f32 and after the same rounding to 8 bits: the iso preview (rays stop
    /// at the needle, the crossing depth-tested) and the blend display,
    /// drag frames at a coarse quality and still frames, parallel and
    /// perspective, with the interactive plane; the needle shows.
    #[test]
    fn renderers_render_geometry_as_scene_render() {
        let args = scene_args(&["--needle", "-10,20,18,50,20,18,1.5"]);
        let persp = Projection::perspective(40.0, 1.5).unwrap();
        let rot = shearwarp::view::rotate_eye(shearwarp::view::NamedView::Anterior.rotation(), 1, 30.0);
        for mode in [Mode::Iso, Mode::Blend] {
            let (mut r, spec) = setup(mode);
            let spec = Spec { camera: Camera { rotation: rot, ..spec.camera }, ..spec };
            let mut plain = Image::new(64, 48);
            r.render(&spec, &mut plain).unwrap();
            r.set_scene(Some(scene(&args))).unwrap();
            let r3 = rot;
            let plane = Plane { normal: [r3.x_axis.z, r3.y_axis.z, r3.z_axis.z], offset: 5.0 };
            for (projection, quality, still, clip) in [
                (Projection::Parallel, 1.0, true, None),
                (Projection::Parallel, 0.5, false, None),
                (persp, 1.0, true, None),
                (persp, 0.7, false, None),
                (Projection::Parallel, 1.0, true, Some(plane)),
            ] {
                let spec = Spec { projection, quality, still, clip, ..spec };
                let (mut img, mut img8) = (Image::new(64, 48), Image8::new(64, 48));
                r.render(&spec, &mut img).unwrap();
                r.render(&spec, &mut img8).unwrap();
                let planes: Option<Arc<dyn Limiter>> = clip.map(|p| {
                    let sp = Phantom::Head.build([40, 40, 36]).unwrap().spacing();
                    Arc::new(ClipPlanes::new(&[ClipPlane::new(p.normal, p.offset).unwrap()], sp).unwrap()) as Arc<dyn Limiter>
                });
                let want = cli_frame(&mut r, &spec, &args, planes);
                let what = format!("{mode:?} {projection:?} quality {quality} still {still} clip {clip:?}");
                assert!(img == want, "{what}: the viewer's frame is not Scene::render's");
                assert_eq!(img8.data, want.to_rgba8(), "{what}: 8 bits");
                if clip.is_none() && projection == Projection::Parallel && still {
                    assert!(img != plain, "{what}: the needle does not show");
                    // the needle's colour where it passes beside the head (pixels the volume leaves empty)
                    let gold = img.data.iter().zip(&plain.data).filter(|(a, b)| b[3] == 0.0 && a[3] > 0.9 && a[0] > a[2]).count();
                    assert!(gold > 10, "{what}: {gold} needle pixels beside the head");
                }
            }
        }
    }

    /// A reused canvas keeps nothing of the last geometry frame: a needle
    /// drawn beside the head in one view, the next view's frame equals that
    /// view rendered into a fresh canvas (the composite's pixels outside the
    /// volume's span are cleared by the next warp), f32 and 8-bit.
    #[test]
    fn geometry_frames_leave_no_trace_in_the_next() {
        let args = scene_args(&["--needle", "-30,20,18,70,20,18,1.5"]);
        let (mut r, spec) = setup(Mode::Iso);
        r.set_scene(Some(scene(&args))).unwrap();
        let base = spec.camera.rotation;
        let tilted = Spec { camera: Camera { rotation: shearwarp::view::rotate_eye(base, 2, 40.0), ..spec.camera }, ..spec };
        let (mut img, mut img8) = (Image::new(64, 48), Image8::new(64, 48));
        r.render(&spec, &mut img).unwrap();
        r.render(&spec, &mut img8).unwrap();
        r.render(&tilted, &mut img).unwrap();
        r.render(&tilted, &mut img8).unwrap();
        let (mut fresh, mut fresh8) = (Image::new(64, 48), Image8::new(64, 48));
        r.render(&tilted, &mut fresh).unwrap();
        r.render(&tilted, &mut fresh8).unwrap();
        assert!(img == fresh, "the last frame's needle is left in the f32 frame");
        assert!(img8 == fresh8, "the last frame's needle is left in the 8-bit frame");
    }

    /// The lens (L) over a scene with geometry and a clip box: the lens
    /// frames render (the hit under the mouse found or not, nothing panics),
    /// on the iso preview and the blend display, parallel and perspective.
    #[test]
    fn lens_renders_with_geometry_and_clip() {
        let args = scene_args(&["--needle", "-10,20,18,50,20,18,1.5", "--clip-box", "0,0,0,28,39,35", "--clip-keep", "outside"]);
        for mode in [Mode::Iso, Mode::Blend] {
            let (mut r, spec) = setup(mode);
            r.set_scene(Some(scene(&args))).unwrap();
            for projection in [Projection::Parallel, Projection::perspective(40.0, 1.5).unwrap()] {
                let spec = Spec { projection, ..spec };
                let mut img = Image8::new(64, 48);
                r.render(&spec, &mut img).unwrap();
                let before = img.clone();
                for at in [[32.0, 24.0], [5.0, 24.0], [60.0, 40.0], [-3.0, 100.0]] {
                    let lens = Lens { centre: [0.0; 3], radius: 15.0, at: Some(at) };
                    r.render(&Spec { lens: Some(lens), ..spec }, &mut img).unwrap();
                    assert!(img.coverage() > 0.02, "{mode:?} {projection:?} {at:?}");
                }
                r.render(&spec, &mut img).unwrap();
                assert!(img == before, "{mode:?} {projection:?}: the lens off, the frame as before");
            }
        }
    }

    #[test]
    fn switching_renderers_rebuilds_only_when_needed() {
        let (mut r, spec) = setup(Mode::Iso);
        let mut img = Image::new(1, 1);
        let names: Vec<&str> = r.tissue_list().iter().map(|t| t.name).collect();
        assert_eq!(names, ["skin", "fat", "soft", "bone"]);
        assert!(!r.needs_rebuild(Class::Tissue(3), 1), "tissue switch is O(1)");
        assert!(r.needs_rebuild(Class::Tissue(0), 2), "cell size");
        assert!(r.needs_rebuild(Class::Custom(100.0), 1), "first custom iso");
        r.render(&spec, &mut img).unwrap();
        let skin = img.clone();
        r.render(&Spec { class: Class::Custom(100.0), ..spec }, &mut img).unwrap();
        assert!(!r.needs_rebuild(Class::Custom(100.0), 1));
        assert!(r.needs_rebuild(Class::Custom(120.0), 1));
        // back to the preset: no rebuild, the same picture as before
        assert!(!r.needs_rebuild(Class::Tissue(0), 1));
        r.render(&spec, &mut img).unwrap();
        assert_eq!(img, skin);
        // super cells are lossless: same picture at cell 3
        r.render(&Spec { cell: 3, ..spec }, &mut img).unwrap();
        assert_eq!(img, skin);
    }

    #[test]
    fn worker_renders_latest_request_and_reports_rebuilds() {
        let (r, spec) = setup(Mode::Iso);
        let (tx, rx) = mpsc::channel();
        let w = Worker::spawn(Kind::Preview, r, true, move |m| {
            let _ = tx.send(m);
        });
        w.post(spec);
        let f = frame(&rx);
        assert_eq!((f.seq, f.kind, f.width, f.height), (1, Kind::Preview, 64, 48));
        assert_eq!(f.pixels.len(), 64 * 48);
        let lit = f.pixels.iter().filter(|&&p| p != 0).count();
        assert!(lit > 100 && lit < 64 * 48, "the head is visible: {lit} lit pixels");
        w.post(Spec { seq: 2, class: Class::Custom(300.0), ..spec });
        let mut busy = false;
        let f = loop {
            match rx.recv_timeout(Duration::from_secs(60)).unwrap() {
                Reply::Busy { seq: 2, what, .. } => busy = what.contains("iso 300"),
                Reply::Frame(f) => break *f,
                // (the first frame's idle turns may have built its other axes
                // before the second request came: the worker answers in order,
                // so that report comes before the second frame's)
                Reply::Prefetched { kind: Kind::Preview } if !busy => {}
                m => panic!("{m:?}"),
            }
        };
        assert!(busy, "the rebuild was reported first");
        assert_eq!(f.seq, 2);
        // the new mask was built for one axis: the idle worker builds the others and says so
        assert!(f.prefetch);
        match rx.recv_timeout(Duration::from_secs(60)).unwrap() {
            Reply::Prefetched { kind: Kind::Preview } => {}
            m => panic!("{m:?}"),
        }
        w.stop();
    }

    /// A tissue switch: the frame after it reads the presets' code mask
    /// (nothing rebuilt, no busy report); the idle worker then builds the new
    /// preset's own one-bit mask (and says so), which the next frame reads.
    #[test]
    fn the_idle_worker_builds_a_switched_presets_own_mask() {
        let (r, spec) = setup(Mode::Iso);
        assert!(r.tissue_list().len() > 1);
        let (tx, rx) = mpsc::channel();
        let w = Worker::spawn(Kind::Preview, r, false, move |m| {
            let _ = tx.send(m);
        });
        let prefetched = |rx: &mpsc::Receiver<Reply>| loop {
            match rx.recv_timeout(Duration::from_secs(60)).expect("a reply") {
                Reply::Prefetched { .. } => break,
                Reply::Failed { error, .. } => panic!("{error}"),
                Reply::Busy { what, .. } => panic!("busy: {what}"),
                Reply::Frame(_) => {}
            }
        };
        w.post(spec);
        assert!(frame(&rx).stats.preset_mask, "built with the code mask");
        prefetched(&rx);
        w.post(Spec { seq: 2, class: Class::Tissue(1), ..spec });
        let f = frame(&rx);
        assert!(!f.stats.preset_mask && f.prefetch, "after the switch: the code mask, the preset's mask to build");
        prefetched(&rx);
        let moved = Camera { rotation: spec.camera.rotation * glam::DMat3::from_rotation_z(0.02), ..spec.camera };
        w.post(Spec { seq: 3, class: Class::Tissue(1), camera: moved, ..spec });
        let f = frame(&rx);
        assert!(f.stats.preset_mask && !f.prefetch, "after the idle build: the preset's own mask");
        w.stop();
    }

    #[test]
    fn recycled_pixel_buffers_are_reused() {
        let (r, spec) = setup(Mode::Iso);
        let (tx, rx) = mpsc::channel();
        let w = Worker::spawn(Kind::Preview, r, false, move |m| {
            let _ = tx.send(m);
        });
        w.post(spec);
        let f = frame(&rx);
        let (ptr, pixels) = (f.pixels.as_ptr(), f.pixels.clone());
        w.recycle(f.pixels);
        w.post(Spec { seq: 2, ..spec });
        let g = frame(&rx);
        assert_eq!(g.pixels.as_ptr(), ptr, "the returned buffer holds the next frame");
        assert_eq!(g.pixels, pixels, "the same view, the same picture");
        w.stop();
    }

    #[test]
    fn blend_worker_draws_translucent_tissue() {
        let (r, spec) = setup(Mode::Blend);
        let (tx, rx) = mpsc::channel();
        let w = Worker::spawn(Kind::Blend, r, false, move |m| {
            let _ = tx.send(m);
        });
        w.post(spec);
        let f = frame(&rx);
        assert_eq!(f.kind, Kind::Blend);
        assert!(f.pixels.iter().any(|&p| p != 0));
        w.cancel();
        w.stop();
    }
}

/// Timing harness of the lens (ignored: slow; run with `--ignored --nocapture`).
#[cfg(test)]
mod lens_timing {
    use std::time::Instant;

    use super::*;
    use shearwarp::data::phantom::Phantom;
    use shearwarp::view::Camera;

    fn ms(t: Instant) -> f64 {
        t.elapsed().as_secs_f64() * 1e3
    }

    fn median(v: &[f64]) -> f64 {
        let mut v = v.to_vec();
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    }

    /// The viewer's lens frame against the plain frame, the same view and
    /// size (512²; tissue skin, focus bone): per round, a plain frame of a
    /// new view, the first mouse move over that view (lens on), a second
    /// move over it, and a rotation with the lens on (the mouse still); each
    /// frame's wall time and the renderer's own (shear + composite + warp),
    /// and the focus limiter alone on the lens frame's plan. The chest CT
    /// needs `SHEARWARP_DATA`; the head phantom always runs (`LENS_VOLS`
    /// picks, `LENS_STILL=0` renders drag frames, `LENS_ROUNDS` rounds,
    /// `LENS_RADIUS` millimetres; the viewer's L starts at 0.3 of the diagonal).
    #[test]
    #[ignore]
    fn lens_frame_time_against_the_plain_frame() {
        let pick = std::env::var("LENS_VOLS").unwrap_or_else(|_| "chest,head".into());
        let mut vols = vec![];
        if let (Ok(dir), true) = (std::env::var("SHEARWARP_DATA"), pick.contains("chest")) {
            let p = std::path::Path::new(&dir).join("chest-ct-lung1.nrrd");
            vols.push(("chest", shearwarp::data::io::load(&p, &Default::default()).unwrap()));
        }
        if pick.contains("head") {
            vols.push(("head", Phantom::Head.build(Phantom::Head.default_dims()).unwrap()));
        }
        let rounds: usize = std::env::var("LENS_ROUNDS").ok().and_then(|s| s.parse().ok()).unwrap_or(5);
        let still = std::env::var("LENS_STILL").map_or(true, |s| s != "0");
        for (name, vol) in vols {
            let tissues = presets::tissues_for(&vol);
            for mode in [Mode::Iso, Mode::Blend] {
                let mut r = Renderers::new(vol.clone(), &tissues, Settings { mode, ..Settings::default() }).unwrap();
                let skin = r.tissue_list().iter().position(|t| t.name == "skin").unwrap_or(0);
                let base = shearwarp::view::NamedView::Anterior.rotation();
                let cam = |deg: f64| Camera { rotation: shearwarp::view::rotate_eye(base, 1, deg), zoom: None, size: [512, 512] };
                let spec = Spec { class: Class::Tissue(skin), still, ..super::tests::spec_at(cam(0.0)) };
                let radius = std::env::var("LENS_RADIUS").ok().and_then(|s| s.parse().ok()).unwrap_or(40.0);
                let lens = Lens { centre: [0.0; 3], radius, at: None };
                let bone = r.tissue_list().iter().position(|t| t.name == "bone").unwrap_or(0);
                let mut img = Image8::new(512, 512);
                r.render(&spec, &mut img).unwrap();
                // [wall, renderer] per kind of frame: plain, first move, next move, rotation
                let mut t = [[vec![], vec![]], [vec![], vec![]], [vec![], vec![]], [vec![], vec![]], [vec![], vec![]]];
                let mut limiter = vec![];
                let mut frame = |r: &mut Renderers, s: &Spec, i: usize, t: &mut [[Vec<f64>; 2]; 5]| {
                    let t0 = Instant::now();
                    let st = r.render(s, &mut img).unwrap();
                    assert!(!st.skipped);
                    t[i][0].push(ms(t0));
                    t[i][1].push(st.frame_ms());
                };
                for i in 0..rounds {
                    let s = Spec { camera: cam(10.0 + 3.0 * i as f64), ..spec };
                    frame(&mut r, &s, 0, &mut t);
                    let at = |k: f64| Some([256.0 + 7.0 * k + i as f64, 200.0 + 3.0 * k]);
                    let l = Lens { at: at(0.0), ..lens };
                    frame(&mut r, &Spec { lens: Some(l), ..s }, 1, &mut t);
                    let l = Lens { at: at(1.0), ..lens };
                    frame(&mut r, &Spec { lens: Some(l), ..s }, 2, &mut t);
                    let s2 = Spec { camera: cam(11.5 + 3.0 * i as f64), ..s };
                    frame(&mut r, &Spec { lens: Some(l), ..s2 }, 3, &mut t);
                    // the focus limiter alone on the lens frame's plan
                    let focus = r.lens_focus(r.lens.unwrap());
                    let region = shearwarp::view::clip::ClipRegion::new(focus.region, vol.spacing()).unwrap();
                    let rr = r.select(Class::Tissue(skin), 1).unwrap();
                    let mut plan = rr.last_plan().unwrap().clone();
                    if i == 0 {
                        eprintln!("  the lens frame's grid {:?}, {} slices, {:?}", plan.grid.size, plan.slices(), plan.kind);
                    }
                    let t0 = Instant::now();
                    rr.install(|| plan.apply_focus(&region, Default::default()));
                    limiter.push(ms(t0));
                    // the lens off again (the next plain frame), and the focus tissue's own frame
                    r.set_lens(None).unwrap();
                    frame(&mut r, &Spec { class: Class::Tissue(bone), ..s2 }, 4, &mut t);
                }
                let m = |i: usize, j: usize| median(&t[i][j]);
                let p = m(0, 0);
                eprintln!(
                    "lens timing {name} {mode:?} 512² still {still}, medians of {rounds}, wall (renderer's shear+composite+warp) ms: plain {p:.1} ({:.1}), first move over a view {:.1} ({:.1}) {:.2}×, next move {:.1} ({:.1}) {:.2}×, rotation with the lens {:.1} ({:.1}) {:.2}×; the focus limiter alone {:.1}; a plain frame of the focus tissue {:.1} ({:.1})",
                    m(0, 1),
                    m(1, 0),
                    m(1, 1),
                    m(1, 0) / p,
                    m(2, 0),
                    m(2, 1),
                    m(2, 0) / p,
                    m(3, 0),
                    m(3, 1),
                    m(3, 0) / p,
                    median(&limiter),
                    m(4, 0),
                    m(4, 1),
                );
            }
        }
    }
}
