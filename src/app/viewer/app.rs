//! The window: winit events in, softbuffer frames out.
//!
//! Owns the winit event loop (X11; Wayland sessions run it through XWayland),
//! the window and its software framebuffer, the two render [`Worker`]s and what
//! is on screen. Events become [`Input`]s for the [`State`]; the state's render
//! requests go to the workers; their frames come back as user events and are
//! presented with the overlay. The loop waits for events (`ControlFlow::Wait`),
//! waking on a timer only while a mask rebuild is shown in progress or a message
//! is about to expire: an idle window costs no CPU. With `--benchmark-drag` the
//! window drives a scripted drag through the same path (see [`super::bench`]).

use std::io::Write;
use std::num::NonZeroU32;
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result, anyhow};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, StartCause, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{Key as WKey, NamedKey};
use winit::window::{Window, WindowId};

use super::ViewCmd;
use super::bench::{Bench, Info, Marks, Phase, Sample};
use super::overlay::{self, Canvas, Controls, Hit};
use super::state::{
    Adaptive, Class, Display, Drag, HELP, Hud, Input, Key, Kind, Lens, Meter, Outcome, Request, Start, State, TissueInfo, button_labels,
};
use super::worker::{Frame, Renderers, Reply, Worker};
use crate::app::Usage;
use shearwarp::classify::presets::{self, Tissue};
use shearwarp::composite::Mode;
use shearwarp::render::{FrameStats, Settings};

/// How often the overlay refreshes while a mask rebuild is in progress.
const BUSY_TICK: Duration = Duration::from_millis(100);
/// How long a message (such as a saved PNG's path) stays on screen.
const MESSAGE_TIME: Duration = Duration::from_secs(4);
/// Window background outside the rendered frame.
const BACKGROUND: u32 = 0;

/// Runs `shearwarp view`.
pub fn run(cmd: &ViewCmd) -> Result<()> {
    let t_start = Instant::now();
    if !(cmd.drag_speed.is_finite() && cmd.drag_speed > 0.0) {
        return Err(anyhow::Error::new(Usage(format!("--drag-speed must be > 0, got {}", cmd.drag_speed))));
    }
    // check the options before loading anything
    let settings = cmd.render.settings()?;
    let sc = &cmd.render.scene;
    let (vol, name) = cmd.volume.load()?;
    crate::app::args::renderable(&name, &vol)?;
    let load_ms = t_start.elapsed().as_secs_f64() * 1e3;
    let t_setup = Instant::now();
    let camera = cmd.render.camera(vol.frame())?;
    let d = vol.dims();
    let tissues = presets::tissues_for(&vol);
    let range = vol.value_range();
    let spacing = vol.spacing();
    let settings = cmd.render.with_default_reconstruction(settings, spacing);
    let mut preview = Renderers::new(vol.clone(), &tissues, Settings { mode: Mode::Iso, ..settings })?;
    // the preview rotates: it takes the cell size that balances shear and
    // render for the tissue presets' codes (`--cell auto`); the keys change it
    let settings = Settings { cell: cmd.render.cell.or(preview.auto_cell()), ..settings };
    let sorted = preview.tissue_list();
    let class = initial_class(&cmd.render.tissue, cmd.render.iso, &sorted)?;
    let mut blend = Renderers::new(vol, &tissues, Settings { mode: Mode::Blend, ..settings })?;
    // --focus / --focus-tissue: the lens's tissue, and a lens to start with (a sphere)
    let lens = match crate::app::scene::focus_of(sc)? {
        None => None,
        Some((region, tissue)) => {
            for r in [&mut preview, &mut blend] {
                r.set_focus_tissue(&tissue).map_err(|e| anyhow::Error::new(Usage(format!("--focus-tissue: {e}"))))?;
            }
            let crate::app::scene::FocusArg::Region(shearwarp::view::clip::Region::Sphere { centre, radius }) = region else {
                return Err(anyhow::Error::new(Usage("the viewer's lens is a sphere: give --focus sphere:x,y,z,r".into())));
            };
            let unit = spacing.iter().fold(f32::INFINITY, |a, &b| a.min(b)) as f64;
            Some(Lens {
                centre: [0, 1, 2].map(|a| (centre[a] - (d[a] as f64 - 1.0) / 2.0) * spacing[a] as f64),
                radius: radius * unit,
                at: None,
            })
        }
    };
    // --perspective: both displays (a fixed eye distance; no fly-in yet)
    let projection = cmd.render.projection()?;
    preview.set_projection(projection)?;
    blend.set_projection(projection)?;
    // --clip-plane: both displays, every renderer they make
    let planes = cmd.render.clip_plane_list(d, spacing)?;
    preview.set_clip_planes(planes.clone())?;
    blend.set_clip_planes(planes)?;
    // --mesh, --needle, --clip-box, --clip-sphere, --clip-mesh: the scene of
    // render and rotate (its focus is the lens above), one per display
    let scene_args = crate::app::scene::SceneArgs { focus: None, focus_tissue: None, ..sc.clone() };
    let scene = crate::app::scene::Scene::new(&scene_args, None, d, spacing)?;
    let usage = |e: shearwarp::Error| anyhow::Error::new(Usage(format!("{e}")));
    preview.set_scene(Some(scene.clone())).map_err(usage)?;
    blend.set_scene(Some(scene)).map_err(usage)?;
    let setup_ms = t_setup.elapsed().as_secs_f64() * 1e3;
    let info = Info {
        volume: name.clone(),
        dims: d,
        size: camera.size,
        threads: if settings.threads == 0 { rayon::current_num_threads() } else { settings.threads },
        method: settings.method.name().to_string(),
        reconstruction: settings.reconstruction.name(),
        tissue: String::new(),
        iso: f32::NAN,
        cell: settings.cell,
        load_ms,
        setup_ms,
    };

    let event_loop = EventLoop::<Reply>::with_user_event()
        .build()
        .map_err(|e| anyhow!("cannot open a window: {e} (render, rotate and info need no display)"))?;
    let proxy = event_loop.create_proxy();
    let p2 = proxy.clone();
    let preview = Worker::spawn(Kind::Preview, preview, true, move |r| {
        let _ = proxy.send_event(r);
    });
    let blend = Worker::spawn(Kind::Blend, blend, false, move |r| {
        let _ = p2.send_event(r);
    });
    let state = State::new(Start {
        tissues: sorted.iter().map(|t| TissueInfo { name: t.name.to_string(), threshold: t.threshold }).collect(),
        range,
        camera,
        class,
        display: match cmd.render.mode {
            Mode::Iso => Display::Iso,
            Mode::Blend => Display::Blend,
        },
        cell: settings.cell,
        drag_speed: cmd.drag_speed,
        projection,
        adaptive: {
            let mut a = Adaptive::new(cmd.target_fps, cmd.render.quality()?.unwrap_or(1.0));
            a.fixed_in_parallel = matches!(settings.method, shearwarp::render::Method::Binary | shearwarp::render::Method::Brute);
            a
        },
        diagonal_mm: (0..3).map(|a| ((d[a].max(1) - 1) as f64 * spacing[a] as f64).powi(2)).sum::<f64>().sqrt(),
        lens,
    });
    let mut app = App {
        state,
        title: format!("{name} {}x{}x{}", d[0], d[1], d[2]),
        window: None,
        surface: None,
        preview,
        blend,
        shown: None,
        last_preview: None,
        blend_stats: None,
        blend_shown: false,
        meter: Meter::default(),
        presented: None,
        busy: None,
        message: None,
        save_dir: cmd.save_dir.clone(),
        verbose: cmd.verbose,
        error: None,
        cursor: (0.0, 0.0),
        t_start,
        masks_pending: false,
        received: None,
        bench: cmd.benchmark_drag.map(|n| Bench::new(n, cmd.drag_speed)),
        info,
    };
    event_loop.run_app(&mut app).map_err(|e| anyhow!("window event loop: {e}"))?;
    if cmd.verbose {
        eprintln!("quit");
    }
    match app.error.take() {
        Some(e) => Err(e),
        None => Ok(()),
    }
}

/// The starting classification from `--tissue` / `--iso`.
fn initial_class(tissue: &Option<String>, iso: Option<f32>, sorted: &[Tissue]) -> Result<Class> {
    if let Some(v) = iso {
        if !v.is_finite() {
            return Err(anyhow::Error::new(Usage("--iso must be a finite number".into())));
        }
        return Ok(Class::Custom(v));
    }
    match tissue.as_deref() {
        None | Some("auto") => Ok(Class::Tissue(0)),
        Some(n) => sorted.iter().position(|t| t.name == n).map(Class::Tissue).ok_or_else(|| {
            let names: Vec<&str> = sorted.iter().map(|t| t.name).collect();
            anyhow::Error::new(Usage(format!("unknown tissue '{n}' for this volume (its presets: {}, or auto)", names.join(", "))))
        }),
    }
}

/// The key command of a pressed key (`repeat`: held down, auto-repeating).
fn map_key(key: &WKey, repeat: bool) -> Option<Key> {
    let k = match key {
        WKey::Named(NamedKey::Escape) => Key::Quit,
        WKey::Named(NamedKey::Space) => Key::ToggleDisplay,
        WKey::Character(s) => match s.as_str() {
            "[" => Key::IsoDown,
            "]" => Key::IsoUp,
            "+" | "=" => Key::CellUp,
            "-" | "_" => Key::CellDown,
            " " => Key::ToggleDisplay,
            "r" | "R" => Key::Reset,
            "p" | "P" => Key::ToggleProjection,
            "c" | "C" => Key::ToggleClip,
            "l" | "L" => Key::ToggleLens,
            "," | "<" => Key::LensSmaller,
            "." | ">" => Key::LensBigger,
            "s" | "S" => Key::Save,
            "q" | "Q" => Key::Quit,
            d => match d.parse::<usize>() {
                Ok(n @ 1..=9) => Key::Tissue(n - 1),
                _ => return None,
            },
        },
        _ => return None,
    };
    // held keys repeat only the stepping commands
    let repeats = matches!(k, Key::IsoDown | Key::IsoUp | Key::CellUp | Key::CellDown);
    (!repeat || repeats).then_some(k)
}

struct App {
    state: State,
    title: String,
    window: Option<Rc<Window>>,
    surface: Option<softbuffer::Surface<Rc<Window>, Rc<Window>>>,
    preview: Worker,
    blend: Worker,
    /// The frame on screen.
    shown: Option<Frame>,
    /// The last preview's statistics and whether its principal axis differed from the one before.
    last_preview: Option<(FrameStats, bool)>,
    /// Statistics and wall milliseconds of the last blended frame rendered (a
    /// frame the renderer skipped as unchanged keeps the ones before).
    blend_stats: Option<(FrameStats, f64)>,
    /// Whether the frame on screen is the blended one.
    blend_shown: bool,
    /// Presented frames during the current (or last) drag.
    meter: Meter,
    /// The frame last presented (sequence number and kind), for the log.
    presented: Option<(u64, Kind)>,
    busy: Option<(Instant, String)>,
    message: Option<(Instant, String)>,
    save_dir: PathBuf,
    verbose: bool,
    error: Option<anyhow::Error>,
    cursor: (f64, f64),
    /// When the command started.
    t_start: Instant,
    /// Whether the preview worker is still building other axes' masks.
    masks_pending: bool,
    /// The last frame received from a worker (sequence number) and when.
    received: Option<(u64, Instant)>,
    /// The scripted drag of `--benchmark-drag`.
    bench: Option<Bench>,
    /// What the benchmark report says about the run.
    info: Info,
}

impl App {
    fn fail(&mut self, el: &ActiveEventLoop, e: anyhow::Error) {
        self.error.get_or_insert(e);
        el.exit();
    }

    fn redraw(&self) {
        if let Some(w) = &self.window {
            w.request_redraw();
        }
    }

    /// Applies one input and acts on the outcome.
    fn input(&mut self, el: &ActiveEventLoop, input: Input) {
        let was_rotating = matches!(self.state.drag, Some(Drag::Rotate { .. }));
        let outcome = self.state.handle(input);
        if !was_rotating && matches!(self.state.drag, Some(Drag::Rotate { .. })) {
            // a new drag: measure its frame rate and angular speed afresh
            self.meter = Meter::default();
        }
        match outcome {
            Outcome::Nothing => {}
            Outcome::Redraw => {
                if let Input::Resize { .. } = input {
                    self.log(self.state.layout.describe());
                }
                self.dispatch();
                // a drag's move changes nothing on screen until its frame
                // arrives (the overlay neither): presenting the old frame again
                // would only take CPU from the render
                if !(was_rotating && matches!(input, Input::Move { .. })) {
                    self.redraw();
                }
            }
            Outcome::Save => self.save(),
            Outcome::Quit => el.exit(),
        }
    }

    /// Hands the state's render requests to the workers.
    fn dispatch(&mut self) {
        for r in self.state.requests() {
            match r {
                Request::Preview(s) => self.preview.post(s),
                Request::Blend(s) => {
                    self.log(format!("blend requested seq={}", s.seq));
                    self.blend.post(s)
                }
                Request::CancelBlend => {
                    self.log("blend cancelled".into());
                    self.blend.cancel()
                }
            }
        }
    }

    fn log(&self, line: String) {
        if self.verbose {
            eprintln!("{line}");
        }
    }

    fn class_name(&self, c: Class) -> String {
        match c {
            Class::Tissue(i) => self.state.tissues.get(i).map_or("?".into(), |t| t.name.clone()),
            Class::Custom(_) => "custom".into(),
        }
    }

    fn on_frame(&mut self, f: Frame) {
        self.received = Some((f.seq, Instant::now()));
        if f.kind == Kind::Preview {
            self.busy = None;
            self.masks_pending = f.prefetch;
        }
        // an unchanged frame the renderer skipped has no timings of its own
        if f.kind == Kind::Preview && !f.stats.skipped {
            let switched = self.last_preview.is_some_and(|(p, _)| p.axis != f.stats.axis);
            self.last_preview = Some((f.stats, switched));
        }
        if !self.state.accept(f.seq, f.kind) {
            self.log(format!("frame seq={} kind={} discarded", f.seq, f.kind.name()));
            self.recycle(f);
            self.dispatch();
            self.redraw();
            return;
        }
        if matches!(self.state.drag, Some(Drag::Rotate { .. })) {
            self.meter.record(Instant::now(), f.spec.camera.rotation);
            // the adaptive image size follows the previews' cost while dragging
            if f.kind == Kind::Preview
                && !f.stats.skipped
                && self.state.adapts()
                && self.state.adaptive.measured(f.spec.quality, f.total_ms)
            {
                self.log(format!("quality {} px/voxel while moving", self.state.adaptive.moving));
            }
        }
        if f.kind == Kind::Blend && !f.stats.skipped {
            self.blend_stats = Some((f.stats, f.total_ms));
        }
        self.blend_shown = f.kind == Kind::Blend;
        let s = &f.stats;
        let iso = match f.spec.class {
            Class::Tissue(i) => self.state.tissues.get(i).map_or(f32::NAN, |t| t.threshold),
            Class::Custom(v) => v,
        };
        self.log(format!(
            "frame seq={} kind={} size={}x{} tissue={} iso={iso} cell={} axis={} skipped={} steps={} direct={} ms={:.2} shear={:.3} render={:.3} warp={:.3} build={:.1} total={:.1}",
            f.seq,
            f.kind.name(),
            f.width,
            f.height,
            self.class_name(f.spec.class),
            f.spec.cell,
            super::state::AXES[s.axis.min(2)],
            s.skipped,
            s.shear_steps,
            s.shear_direct,
            s.frame_ms(),
            s.shear_ms,
            s.render_ms,
            s.warp_ms,
            s.build_ms,
            f.total_ms,
        ));
        if let Some(old) = self.shown.replace(f) {
            self.recycle(old);
        }
        self.dispatch();
        self.redraw();
    }

    /// Gives a frame's pixel buffer back to the worker that made it.
    fn recycle(&self, f: Frame) {
        match f.kind {
            Kind::Preview => self.preview.recycle(f.pixels),
            Kind::Blend => self.blend.recycle(f.pixels),
        }
    }

    /// Saves the frame on screen (without the overlay) as the next free
    /// `shearwarp-view-NNN.png` in the save directory and prints its path.
    fn save(&mut self) {
        let Some(f) = &self.shown else {
            self.message = Some((Instant::now(), "nothing to save yet".into()));
            self.redraw();
            return;
        };
        let res = (|| -> Result<PathBuf> {
            std::fs::create_dir_all(&self.save_dir).with_context(|| format!("{}: cannot create directory", self.save_dir.display()))?;
            let path = next_free(&self.save_dir)?;
            let img = image::RgbImage::from_fn(f.width as u32, f.height as u32, |x, y| {
                let p = f.pixels[y as usize * f.width + x as usize];
                image::Rgb([(p >> 16) as u8, (p >> 8) as u8, p as u8])
            });
            shearwarp::output::write_png(&path, &img)?;
            Ok(path)
        })();
        let msg = match res {
            Ok(path) => {
                let shown = std::path::absolute(&path).unwrap_or(path.clone());
                println!("saved {} ({}, {}x{})", shown.display(), f.kind.name(), f.width, f.height);
                let _ = std::io::stdout().flush();
                format!("saved {}", path.file_name().map_or(String::new(), |n| n.to_string_lossy().into_owned()))
            }
            Err(e) => {
                eprintln!("error: {e:#}");
                format!("save failed: {e}")
            }
        };
        self.message = Some((Instant::now(), msg));
        self.redraw();
    }

    /// Draws the frame on screen and the overlay into the window; returns the
    /// sequence number of the frame if it is presented for the first time.
    fn present(&mut self) -> Result<Option<u64>> {
        let (Some(window), Some(surface)) = (&self.window, &mut self.surface) else { return Ok(None) };
        let size = window.inner_size();
        let (Some(nw), Some(nh)) = (NonZeroU32::new(size.width), NonZeroU32::new(size.height)) else { return Ok(None) };
        surface.resize(nw, nh).map_err(|e| anyhow!("cannot size the framebuffer: {e}"))?;
        let mut buf = surface.buffer_mut().map_err(|e| anyhow!("cannot get the framebuffer: {e}"))?;
        let (w, h) = (size.width as usize, size.height as usize);
        for (y, row) in buf.chunks_exact_mut(w).enumerate() {
            match &self.shown {
                Some(f) if y < f.height => {
                    let n = w.min(f.width);
                    row[..n].copy_from_slice(&f.pixels[y * f.width..y * f.width + n]);
                    row[n..].fill(BACKGROUND);
                }
                _ => row.fill(BACKGROUND),
            }
        }
        let mut new = None;
        if let Some(f) = self.shown.as_ref().filter(|f| self.presented != Some((f.seq, f.kind))) {
            self.presented = Some((f.seq, f.kind));
            new = Some(f.seq);
            if self.verbose {
                let c = match f.spec.class {
                    Class::Tissue(i) => self.state.tissues.get(i).map_or("?".into(), |t| t.name.clone()),
                    Class::Custom(_) => "custom".into(),
                };
                eprintln!("presented seq={} kind={} size={}x{} tissue={c} cell={}", f.seq, f.kind.name(), f.width, f.height, f.spec.cell);
            }
        }
        let (fps, degps) = self.meter.rates();
        let hud = Hud {
            title: self.title.clone(),
            preview: self.last_preview,
            blend: self.blend_stats.filter(|_| self.blend_shown),
            fps,
            degps,
            busy: self.busy.as_ref().filter(|(t, _)| t.elapsed() >= BUSY_TICK).map(|(t, s)| (s.clone(), t.elapsed().as_secs_f64())),
            message: self.message.as_ref().map(|m| m.1.clone()),
            background: self.masks_pending,
        };
        let lines = self.state.overlay_lines(&hud);
        let labels = button_labels(&self.state.tissues);
        let mut c = Canvas { px: &mut buf, w, h };
        c.panel(4, 4, &lines, overlay::TEXT);
        let current = match self.state.class {
            Class::Tissue(i) => Some(i),
            Class::Custom(_) => None,
        };
        let ctl = Controls { labels: &labels, current, slider: self.state.slider_fraction(), value: self.state.iso(), help: HELP };
        overlay::draw_controls(&mut c, &self.state.layout, &ctl);
        buf.present().map_err(|e| anyhow!("cannot present the frame: {e}"))?;
        Ok(new)
    }

    /// Starts the benchmark drag once the first frame is on screen and the
    /// preview worker has the masks of every principal axis: a press in the
    /// middle of the view, then the first move.
    fn bench_poll(&mut self, el: &ActiveEventLoop) {
        let Some(b) = &self.bench else { return };
        if b.phase != Phase::Waiting || self.presented.is_none() || self.masks_pending {
            return;
        }
        // the middle of the window, or in a small one the row nearest it that is not a control
        let [w, h] = self.state.size;
        let (x, mid) = ((w / 2) as f64, h / 2);
        let mut rows = (0..=mid).flat_map(|d| [mid - d, mid + d]).filter(|&r| r < h).map(|r| r as f64);
        let Some(y) = rows.find(|&y| matches!(self.state.layout.hit(x, y), Hit::View)) else {
            return self.fail(el, anyhow!("--benchmark-drag: the {w}x{h} window has no room to drag in"));
        };
        self.input(el, Input::Press { x, y });
        if !matches!(self.state.drag, Some(Drag::Rotate { .. })) {
            return self.fail(el, anyhow!("--benchmark-drag: the press at ({x}, {y}) did not start a drag"));
        }
        let now = Instant::now();
        let b = self.bench.as_mut().expect("checked above");
        b.ready_ms = Some(now.duration_since(self.t_start).as_secs_f64() * 1e3);
        b.cursor = (x, y);
        b.begun = Some(now);
        let line = format!("benchmark drag: {} frames from ({x}, {y}), {} px each", b.frames, b.dx);
        self.log(line);
        self.bench_move(el);
    }

    /// The next move of the benchmark drag, as a cursor motion event would make it.
    fn bench_move(&mut self, el: &ActiveEventLoop) {
        let Some(b) = self.bench.as_mut() else { return };
        let (x, y) = b.next_move();
        let before = self.state.seq;
        let at = Instant::now();
        self.input(el, Input::Move { x, y });
        if self.state.seq == before {
            return self.fail(el, anyhow!("--benchmark-drag: the move to ({x}, {y}) did not change the view"));
        }
        if let Some(b) = self.bench.as_mut() {
            b.phase = Phase::Pending { seq: self.state.seq, at };
        }
    }

    /// After a present that began at `start` and newly showed frame `new`:
    /// notes the first frame, or records the pending benchmark frame and makes
    /// the next move (or reports, when all are done).
    fn bench_presented(&mut self, el: &ActiveEventLoop, start: Instant, new: Option<u64>) {
        let now = Instant::now();
        let Some(b) = self.bench.as_mut() else { return };
        match b.phase {
            Phase::Waiting => {
                if new.is_some() && b.first_frame_ms.is_none() {
                    b.first_frame_ms = Some(now.duration_since(self.t_start).as_secs_f64() * 1e3);
                }
                self.bench_poll(el);
            }
            Phase::Pending { seq, at } => {
                let Some(f) = self.shown.as_ref().filter(|f| new == Some(f.seq) && f.seq >= seq && f.kind == Kind::Preview) else { return };
                let received = self.received.filter(|r| r.0 == f.seq).map_or(start, |r| r.1);
                let m = Marks { requested: at, started: f.started, worker_ms: f.total_ms, received, present_start: start, presented: now };
                if b.record(Sample::new(&m, f.stats), now) {
                    self.bench_finish(el);
                } else {
                    self.bench_move(el);
                }
            }
            Phase::Done => {}
        }
    }

    /// Prints the benchmark's JSON report and quits.
    fn bench_finish(&mut self, el: &ActiveEventLoop) {
        let Some(b) = &self.bench else { return };
        let info = Info {
            size: self.state.size,
            tissue: self.state.class_name(),
            iso: self.state.iso(),
            cell: self.state.cell,
            ..self.info.clone()
        };
        println!("{}", b.report(&info));
        let _ = std::io::stdout().flush();
        el.exit();
    }
}

/// `dir/shearwarp-view-NNN.png` with the first NNN not taken.
fn next_free(dir: &Path) -> Result<PathBuf> {
    for n in 1..100_000 {
        let p = dir.join(format!("shearwarp-view-{n:03}.png"));
        if !p.exists() {
            return Ok(p);
        }
    }
    Err(anyhow!("{}: no free shearwarp-view-NNN.png name", dir.display()))
}

impl ApplicationHandler<Reply> for App {
    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.window.is_some() {
            return;
        }
        let [w, h] = self.state.size;
        let attrs = Window::default_attributes()
            .with_title(format!("shearwarp view - {}", self.title))
            .with_inner_size(PhysicalSize::new(w as u32, h as u32));
        let made = (|| -> Result<_> {
            let window = Rc::new(el.create_window(attrs).context("cannot create the window")?);
            let context = softbuffer::Context::new(window.clone()).map_err(|e| anyhow!("softbuffer: {e}"))?;
            let surface = softbuffer::Surface::new(&context, window.clone()).map_err(|e| anyhow!("softbuffer: {e}"))?;
            Ok((window, surface))
        })();
        match made {
            Ok((window, surface)) => {
                let s = window.inner_size();
                self.window = Some(window);
                self.surface = Some(surface);
                self.state.handle(Input::Resize { w: s.width as usize, h: s.height as usize });
                self.log(self.state.layout.describe());
                self.dispatch();
                self.redraw();
            }
            Err(e) => self.fail(el, e),
        }
    }

    fn new_events(&mut self, _el: &ActiveEventLoop, cause: StartCause) {
        if let StartCause::ResumeTimeReached { .. } = cause {
            if self.message.as_ref().is_some_and(|(t, _)| t.elapsed() >= MESSAGE_TIME) {
                self.message = None;
            }
            self.redraw();
        }
    }

    fn user_event(&mut self, el: &ActiveEventLoop, reply: Reply) {
        match reply {
            Reply::Busy { kind, seq, what } => {
                self.log(format!("busy kind={} seq={seq} {what}", kind.name()));
                if kind == Kind::Preview {
                    self.busy = Some((Instant::now(), what));
                    self.redraw();
                }
            }
            Reply::Frame(f) => self.on_frame(*f),
            Reply::Prefetched { kind } => {
                self.log(format!("masks ready kind={}", kind.name()));
                if kind == Kind::Preview {
                    self.masks_pending = false;
                    if self.bench.is_none() {
                        self.redraw(); // the overlay's background line goes
                    }
                    self.bench_poll(el);
                }
            }
            Reply::Failed { kind, seq, error } => {
                if self.bench.is_some() {
                    return self.fail(el, anyhow!("--benchmark-drag: {} render of state {seq} failed: {error}", kind.name()));
                }
                eprintln!("error: {} render of state {seq}: {error}", kind.name());
                if kind == Kind::Preview {
                    self.busy = None;
                }
                self.message = Some((Instant::now(), format!("render failed: {error}")));
                self.redraw();
            }
        }
    }

    fn window_event(&mut self, el: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => el.exit(),
            WindowEvent::RedrawRequested => {
                let start = Instant::now();
                match self.present() {
                    Ok(new) => self.bench_presented(el, start, new),
                    Err(e) => self.fail(el, e),
                }
            }
            WindowEvent::MouseWheel { delta, .. } => {
                let lines = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y as f64,
                    MouseScrollDelta::PixelDelta(p) => p.y / 40.0,
                };
                self.input(el, Input::Wheel { lines })
            }
            WindowEvent::Resized(s) => self.input(el, Input::Resize { w: s.width as usize, h: s.height as usize }),
            WindowEvent::CursorMoved { position, .. } => {
                self.cursor = (position.x, position.y);
                self.input(el, Input::Move { x: position.x, y: position.y });
            }
            WindowEvent::MouseInput { state, button: MouseButton::Right, .. } => {
                let input = match state {
                    ElementState::Pressed => Input::PressRight { x: self.cursor.0, y: self.cursor.1 },
                    ElementState::Released => Input::Release,
                };
                self.input(el, input);
            }
            WindowEvent::MouseInput { state, button: MouseButton::Left, .. } => {
                let input = match state {
                    ElementState::Pressed => Input::Press { x: self.cursor.0, y: self.cursor.1 },
                    ElementState::Released => Input::Release,
                };
                self.input(el, input);
            }
            WindowEvent::KeyboardInput { event, .. } if event.state == ElementState::Pressed => {
                if let Some(k) = map_key(&event.logical_key, event.repeat) {
                    self.log(format!("key {k:?}"));
                    self.input(el, Input::Key(k));
                }
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, el: &ActiveEventLoop) {
        // sleep until the next event; wake on a timer only for a visible countdown
        let now = Instant::now();
        let mut wake: Option<Instant> = None;
        if self.busy.is_some() {
            wake = Some(now + BUSY_TICK);
        }
        if let Some((t, _)) = &self.message {
            let at = *t + MESSAGE_TIME;
            wake = Some(wake.map_or(at, |w| w.min(at)));
        }
        el.set_control_flow(match wake {
            Some(t) => ControlFlow::WaitUntil(t),
            None => ControlFlow::Wait,
        });
    }
}
