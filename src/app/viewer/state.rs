//! The viewer's state and what each input does to it.
//!
//! Owns [`State`]: the camera (rotation, zoom, window size), the classification
//! ([`Class`]: a tissue preset or a custom iso value), the display mode (iso
//! preview or alpha-blended), the super-cell size, the drag in progress, the
//! control [`Layout`], and which renders are pending. [`State::handle`] applies
//! one [`Input`]; every change that alters the picture bumps the sequence number
//! [`State::seq`]. [`State::requests`] then says which renders to start or cancel,
//! and [`State::accept`] decides whether a finished frame may be shown:
//!
//! - every change asks the preview worker for an iso frame of the new state
//!   (requests that arrive while it is busy replace each other, so a fast drag
//!   skips frames and the renderer catches up with several one-bit shears or a
//!   direct shear);
//! - in the blend display, once the preview of the current state is shown and no
//!   drag is in progress, the blend worker is asked for the full alpha-blended
//!   frame; it replaces the preview when it arrives, unless the state moved on or
//!   a drag started meanwhile, which cancel and discard it.
//!
//! Nothing here touches a window, so all of it is unit-tested.

use std::collections::VecDeque;
use std::time::{Duration, Instant};

use glam::{DMat3, DQuat};

use super::overlay::{Hit, Layout};
use shearwarp::encode::mask::MAX_CELL;
use shearwarp::render::{FrameStats, MAX_QUALITY, MIN_QUALITY};
use shearwarp::view::{Camera, Projection, rotate_eye};

/// The classification a frame uses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Class {
    /// Tissue preset `i` (O(1) switch on the shared threshold-coded mask).
    Tissue(usize),
    /// A custom iso value (its own mask, rebuilt when the value changes).
    Custom(f32),
}

/// What the window shows when the view is still.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Display {
    /// Iso-surface previews only.
    Iso,
    /// Iso previews while the view changes, then the full alpha-blended render.
    Blend,
}

/// Which worker made a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Preview,
    Blend,
}

impl Kind {
    pub fn name(self) -> &'static str {
        match self {
            Kind::Preview => "preview",
            Kind::Blend => "blend",
        }
    }
}

/// Everything a worker needs to render one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spec {
    pub seq: u64,
    pub camera: Camera,
    pub class: Class,
    pub cell: usize,
    pub projection: Projection,
    /// Intermediate pixels per voxel ([`shearwarp::Renderer::set_quality`]):
    /// the adaptive value while the view is dragged, at least 1 once it is still.
    pub quality: f64,
    /// The interactive clip plane (C key): the half-space `normal · w ≤ offset`
    /// in world millimetres from the volume centre, beside any `--clip-plane`.
    pub clip: Option<Plane>,
    /// The lens (L key, `--focus`): focus+context in a ball that follows the mouse.
    pub lens: Option<Lens>,
    /// A still view (no drag under way): the worker renders it with matched
    /// sampling (Deluxe M) where the zoom magnifies.
    pub still: bool,
}

/// The viewer's lens: a ball in world millimetres from the volume centre
/// inside which the focus tissue (`--focus-tissue`) classifies the volume.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lens {
    /// The centre the lens falls back on: at the volume centre's depth under
    /// the mouse, or `--focus`'s.
    pub centre: [f64; 3],
    pub radius: f64,
    /// The output pixel under the mouse the lens follows (None: `--focus`'s
    /// fixed lens): the worker centres the lens on the first visible surface
    /// there, `centre` where the ray meets none.
    pub at: Option<[f64; 2]>,
}

/// A clip plane in world millimetres from the volume centre: the side kept is
/// `normal · w ≤ offset` (the library's `ClipPlane` convention).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub normal: [f64; 3],
    pub offset: f64,
}

/// The adaptive intermediate image size (Schulze et al.): while the view is
/// dragged, the preview's quality `q` (intermediate pixels per voxel) follows
/// `q · sqrt(target / measured)` frame time — a frame's cost is about
/// proportional to its `q²` rays — with hysteresis, so it settles instead of
/// hunting: it moves only when the wanted value is more than [`Adaptive::BAND`]
/// away, to a multiple of 1/16. It stays in `[MIN_QUALITY, still]`; the frame
/// on release is rendered at `still ≥ 1`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Adaptive {
    /// The wanted preview frame time (ms), from `--target-fps`; `None`: no adaptation.
    pub target_ms: Option<f64>,
    /// The quality while dragging.
    pub moving: f64,
    /// The quality of a still view (≥ 1).
    pub still: f64,
    /// No adaptation in the parallel projection: the preview's path there
    /// (the binary rotator's translated rays) is fastest at one pixel per
    /// voxel — at another pitch its rays take the slower diverging walk.
    pub fixed_in_parallel: bool,
    /// Frame times (ms) measured at `moving` since it last changed (the last
    /// [`Adaptive::WINDOW`]).
    times: [f64; Adaptive::WINDOW],
    count: usize,
}

impl Adaptive {
    /// Relative change below which the quality stays put.
    pub const BAND: f64 = 0.15;
    /// Frames measured at one quality before it may change: their median
    /// decides, so one slow or fast frame (a page fault, another process)
    /// does not move it.
    pub const WINDOW: usize = 3;

    /// Adaptation to `target_fps` frames a second, starting at one pixel per
    /// voxel; without a target, `quality` while moving. Still views render at
    /// `quality` but at least 1.
    pub fn new(target_fps: Option<f64>, quality: f64) -> Self {
        let still = quality.clamp(1.0, MAX_QUALITY);
        let moving = if target_fps.is_some() { 1.0 } else { quality.clamp(MIN_QUALITY, MAX_QUALITY) };
        Adaptive {
            target_ms: target_fps.map(|f| 1000.0 / f),
            moving,
            still,
            fixed_in_parallel: false,
            times: [0.0; Self::WINDOW],
            count: 0,
        }
    }

    /// Takes the frame time `ms` of a preview rendered at quality `q` while
    /// moving (frames of another quality than the current one, still in
    /// flight when it changed, are ignored); once [`Adaptive::WINDOW`] frames
    /// are in, their median decides. Returns whether the moving quality changed.
    pub fn measured(&mut self, q: f64, ms: f64) -> bool {
        let Some(target) = self.target_ms else { return false };
        if !(ms.is_finite() && ms > 0.0) || q != self.moving {
            return false;
        }
        self.times[self.count % Self::WINDOW] = ms;
        self.count += 1;
        if self.count < Self::WINDOW {
            return false;
        }
        let mut t = self.times;
        t.sort_by(f64::total_cmp);
        let ms = t[Self::WINDOW / 2];
        let want = (q * (target / ms).sqrt()).clamp(MIN_QUALITY, self.still);
        if (want / self.moving - 1.0).abs() <= Self::BAND {
            return false;
        }
        let next = ((want * 16.0).round() / 16.0).clamp(MIN_QUALITY, self.still);
        let changed = next != self.moving;
        self.moving = next;
        self.count = 0;
        changed
    }
}

/// User input, already in window pixels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Input {
    /// Left button pressed at `(x, y)`.
    Press {
        x: f64,
        y: f64,
    },
    /// Right button pressed at `(x, y)` (drags the clip plane).
    PressRight {
        x: f64,
        y: f64,
    },
    /// Cursor moved to `(x, y)`.
    Move {
        x: f64,
        y: f64,
    },
    /// Left button released.
    Release,
    /// The mouse wheel turned by `lines` (positive: away from the user, which
    /// flies the perspective eye in).
    Wheel {
        lines: f64,
    },
    /// The window's inner size changed.
    Resize {
        w: usize,
        h: usize,
    },
    Key(Key),
}

/// Keyboard commands.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Key {
    /// Keys 1–9: tissue preset `i` (0-based).
    Tissue(usize),
    /// `[` / `]`: custom iso value one step down / up.
    IsoDown,
    IsoUp,
    /// `+` / `-`: super-cell size.
    CellUp,
    CellDown,
    /// Space: iso preview ↔ alpha-blended display.
    ToggleDisplay,
    /// P: parallel ↔ perspective projection.
    ToggleProjection,
    /// C: a clip plane through the volume's centre facing the viewer (the
    /// half nearer the viewer removed), or off again.
    ToggleClip,
    /// L: the lens on (centred on the first visible surface under the mouse,
    /// following it; at the volume centre's depth where the ray meets none) or off.
    ToggleLens,
    /// `,` / `.`: the lens smaller / larger.
    LensSmaller,
    LensBigger,
    /// R: back to the starting view.
    Reset,
    /// S: save the current view as PNG.
    Save,
    /// Esc / Q.
    Quit,
}

/// What the caller should do after an input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    Nothing,
    /// The state changed: dispatch [`State::requests`] and redraw the overlay.
    Redraw,
    Save,
    Quit,
}

/// A render to start or cancel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Request {
    Preview(Spec),
    Blend(Spec),
    CancelBlend,
}

/// A tissue preset as the controls show it.
#[derive(Clone, Debug, PartialEq)]
pub struct TissueInfo {
    pub name: String,
    pub threshold: f32,
}

/// Where the viewer starts.
#[derive(Clone, Debug)]
pub struct Start {
    pub tissues: Vec<TissueInfo>,
    /// The volume's value range (the iso slider's ends).
    pub range: (f32, f32),
    pub camera: Camera,
    pub class: Class,
    pub display: Display,
    pub cell: usize,
    /// Degrees per pixel of drag.
    pub drag_speed: f64,
    /// The starting projection.
    pub projection: Projection,
    /// The intermediate image size (`--target-fps`, `--quality`).
    pub adaptive: Adaptive,
    /// The volume's bounding diagonal in millimetres (how far a drag moves
    /// the clip plane: the window's smaller side is one diagonal).
    pub diagonal_mm: f64,
    /// The starting lens (`--focus sphere:...`), if any.
    pub lens: Option<Lens>,
}

/// A drag in progress.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Drag {
    /// Rotating the view; the last cursor position.
    Rotate { x: f64, y: f64 },
    /// Moving the iso slider.
    Slider,
    /// Moving the clip plane along its normal (right button): the press's
    /// cursor row and the plane's offset then.
    Clip { y: f64, offset: f64 },
}

/// The viewer state.
#[derive(Clone, Debug)]
pub struct State {
    pub tissues: Vec<TissueInfo>,
    pub range: (f32, f32),
    pub base: DMat3,
    pub rotation: DMat3,
    pub zoom: Option<f64>,
    pub size: [usize; 2],
    pub class: Class,
    pub display: Display,
    pub cell: usize,
    pub drag_speed: f64,
    pub drag: Option<Drag>,
    pub layout: Layout,
    pub projection: Projection,
    /// The perspective P switches to (the last one shown, or 40° from 2 diagonals).
    perspective: Projection,
    /// The intermediate image size while moving and when still.
    pub adaptive: Adaptive,
    /// The interactive clip plane, if on.
    pub clip: Option<Plane>,
    /// The lens, if on, and the radius it gets when turned on.
    pub lens: Option<Lens>,
    lens_radius: f64,
    pub diagonal_mm: f64,
    /// Bumped by every change of the picture.
    pub seq: u64,
    cursor: (f64, f64),
    preview_posted: u64,
    blend_posted: Option<u64>,
    shown: Option<(u64, Kind)>,
}

impl State {
    pub fn new(s: Start) -> Self {
        let layout = Layout::new(s.camera.size, &button_labels(&s.tissues));
        State {
            tissues: s.tissues,
            range: s.range,
            base: s.camera.rotation,
            rotation: s.camera.rotation,
            zoom: s.camera.zoom,
            size: s.camera.size,
            class: s.class,
            display: s.display,
            cell: s.cell.clamp(1, MAX_CELL),
            drag_speed: s.drag_speed,
            drag: None,
            layout,
            projection: s.projection,
            perspective: if s.projection.is_perspective() {
                s.projection
            } else {
                Projection::Perspective { fov_deg: 40.0, eye_distance: 2.0 }
            },
            adaptive: s.adaptive,
            clip: None,
            lens: s.lens,
            lens_radius: s.lens.map_or(0.3 * s.diagonal_mm.max(1.0), |l| l.radius),
            diagonal_mm: if s.diagonal_mm.is_finite() && s.diagonal_mm > 0.0 { s.diagonal_mm } else { 1.0 },
            seq: 1,
            cursor: (0.0, 0.0),
            preview_posted: 0,
            blend_posted: None,
            shown: None,
        }
    }

    /// The frame the current state asks for.
    pub fn spec(&self) -> Spec {
        let quality = if self.drag.is_some() && self.adapts() { self.adaptive.moving } else { self.adaptive.still };
        Spec {
            seq: self.seq,
            camera: self.camera(),
            class: self.class,
            cell: self.cell,
            projection: self.projection,
            quality,
            clip: self.clip,
            lens: self.lens,
            still: self.drag.is_none(),
        }
    }

    /// Whether the preview's quality follows the frame rate now (not in the
    /// parallel projection when [`Adaptive::fixed_in_parallel`]).
    pub fn adapts(&self) -> bool {
        !self.adaptive.fixed_in_parallel || self.projection.is_perspective()
    }

    /// The current camera.
    pub fn camera(&self) -> Camera {
        Camera { rotation: self.rotation, zoom: self.zoom, size: self.size }
    }

    /// The iso value of the current classification.
    pub fn iso(&self) -> f32 {
        match self.class {
            Class::Tissue(i) => self.tissues[i].threshold,
            Class::Custom(v) => v,
        }
    }

    /// Name of the current classification.
    pub fn class_name(&self) -> String {
        match self.class {
            Class::Tissue(i) => self.tissues[i].name.clone(),
            Class::Custom(_) => "custom".into(),
        }
    }

    /// The iso value at fraction `t` of the slider.
    pub fn iso_at(&self, t: f64) -> f32 {
        let (lo, hi) = self.range;
        (lo as f64 + t.clamp(0.0, 1.0) * (hi - lo) as f64) as f32
    }

    /// The slider position of the current iso value.
    pub fn slider_fraction(&self) -> f64 {
        let (lo, hi) = self.range;
        if hi > lo { ((self.iso() - lo) as f64 / (hi - lo) as f64).clamp(0.0, 1.0) } else { 0.0 }
    }

    /// One step of `[` / `]`: 1/200 of the value range (at least 1e-6).
    pub fn iso_step(&self) -> f32 {
        ((self.range.1 - self.range.0) / 200.0).max(1e-6)
    }

    /// The frame on screen (sequence number and kind), if any.
    #[cfg(test)]
    pub fn shown(&self) -> Option<(u64, Kind)> {
        self.shown
    }

    /// Whether a blended frame has been requested and not yet arrived.
    pub fn blend_pending(&self) -> bool {
        self.blend_posted.is_some()
    }

    /// The world point (mm from the volume centre) under window pixel `(x,
    /// y)` at the depth of the volume centre (for either projection: a
    /// perspective view's scale at that depth is its resolved zoom).
    pub fn world_under(&self, x: f64, y: f64) -> [f64; 3] {
        let [w, h] = self.size;
        let zoom = match self.projection {
            Projection::Perspective { fov_deg, eye_distance } => {
                h as f64 / 2.0 / (fov_deg.to_radians() / 2.0).tan() / (eye_distance * self.diagonal_mm)
            }
            Projection::Parallel => self.zoom.unwrap_or(w.min(h) as f64 / self.diagonal_mm),
        };
        // image u = (W − 1)/2 + zoom·e.x, v = (H − 1)/2 − zoom·e.y; e = R·w
        let e = glam::DVec3::new((x - (w as f64 - 1.0) / 2.0) / zoom, -(y - (h as f64 - 1.0) / 2.0) / zoom, 0.0);
        (self.rotation.transpose() * e).to_array()
    }

    fn changed(&mut self) -> Outcome {
        self.seq += 1;
        Outcome::Redraw
    }

    fn set_class(&mut self, c: Class) -> Outcome {
        let c = match c {
            Class::Custom(v) if !v.is_finite() => return Outcome::Nothing,
            Class::Tissue(i) if i >= self.tissues.len() => return Outcome::Nothing,
            c => c,
        };
        if c == self.class {
            return Outcome::Nothing;
        }
        self.class = c;
        self.changed()
    }

    /// Applies one input.
    pub fn handle(&mut self, input: Input) -> Outcome {
        match input {
            Input::Press { x, y } => {
                self.cursor = (x, y);
                match self.layout.hit(x, y) {
                    Hit::Tissue(i) => self.set_class(Class::Tissue(i)),
                    Hit::Slider(t) => {
                        self.drag = Some(Drag::Slider);
                        self.set_class(Class::Custom(self.iso_at(t)));
                        Outcome::Redraw
                    }
                    Hit::View => {
                        self.drag = Some(Drag::Rotate { x, y });
                        // a new drag cancels a pending blended render
                        Outcome::Redraw
                    }
                }
            }
            Input::PressRight { x, y } => {
                self.cursor = (x, y);
                match self.clip {
                    Some(c) if matches!(self.layout.hit(x, y), Hit::View) => {
                        self.drag = Some(Drag::Clip { y, offset: c.offset });
                        Outcome::Redraw
                    }
                    _ => Outcome::Nothing,
                }
            }
            Input::Move { x, y } => {
                self.cursor = (x, y);
                match self.drag {
                    Some(Drag::Clip { y: y0, offset }) => {
                        let Some(c) = self.clip else { return Outcome::Nothing };
                        // dragging up pushes the plane away from the viewer (more cut away)
                        let mm_per_px = self.diagonal_mm / self.size[0].min(self.size[1]).max(1) as f64;
                        let o = (offset - (y - y0) * mm_per_px).clamp(-self.diagonal_mm, self.diagonal_mm);
                        if o == c.offset || !o.is_finite() {
                            return Outcome::Nothing;
                        }
                        self.clip = Some(Plane { offset: o, ..c });
                        self.changed()
                    }
                    Some(Drag::Rotate { x: lx, y: ly }) => {
                        let (dx, dy) = (x - lx, y - ly);
                        if dx == 0.0 && dy == 0.0 {
                            return Outcome::Nothing;
                        }
                        self.drag = Some(Drag::Rotate { x, y });
                        self.rotate(dx * self.drag_speed, dy * self.drag_speed);
                        self.changed()
                    }
                    Some(Drag::Slider) => {
                        let t = self.layout.slider_fraction(x);
                        self.set_class(Class::Custom(self.iso_at(t)))
                    }
                    // the lens follows the mouse over the view
                    None => match self.lens {
                        Some(l) if matches!(self.layout.hit(x, y), Hit::View) => {
                            let centre = self.world_under(x, y);
                            if centre == l.centre || centre.iter().any(|c| !c.is_finite()) {
                                return Outcome::Nothing;
                            }
                            self.lens = Some(Lens { centre, at: Some([x, y]), ..l });
                            self.changed()
                        }
                        _ => Outcome::Nothing,
                    },
                }
            }
            Input::Release => {
                if self.drag.take().is_some() {
                    if self.adaptive.moving != self.adaptive.still {
                        // the frame on release: the still view's quality
                        return self.changed();
                    }
                    Outcome::Redraw
                } else {
                    Outcome::Nothing
                }
            }
            Input::Wheel { lines } => {
                let Projection::Perspective { fov_deg, eye_distance } = self.projection else { return Outcome::Nothing };
                let d = (eye_distance * 0.9f64.powf(lines)).clamp(MIN_EYE_DISTANCE, MAX_EYE_DISTANCE);
                if !d.is_finite() || d == eye_distance {
                    return Outcome::Nothing;
                }
                self.projection = Projection::Perspective { fov_deg, eye_distance: d };
                self.perspective = self.projection;
                self.changed()
            }
            Input::Resize { w, h } => {
                if w == 0 || h == 0 || [w, h] == self.size {
                    return Outcome::Nothing;
                }
                self.size = [w, h];
                self.layout = Layout::new(self.size, &button_labels(&self.tissues));
                self.changed()
            }
            Input::Key(k) => match k {
                Key::Tissue(i) => self.set_class(Class::Tissue(i)),
                Key::IsoDown | Key::IsoUp => {
                    let d = if k == Key::IsoUp { self.iso_step() } else { -self.iso_step() };
                    let (lo, hi) = self.range;
                    self.set_class(Class::Custom((self.iso() + d).clamp(lo, hi.max(lo))))
                }
                Key::CellUp | Key::CellDown => {
                    let c = if k == Key::CellUp { self.cell + 1 } else { self.cell.saturating_sub(1) };
                    let c = c.clamp(1, MAX_CELL);
                    if c == self.cell {
                        return Outcome::Nothing;
                    }
                    self.cell = c;
                    self.changed()
                }
                Key::ToggleDisplay => {
                    self.display = match self.display {
                        Display::Iso => Display::Blend,
                        Display::Blend => Display::Iso,
                    };
                    self.changed()
                }
                Key::ToggleClip => {
                    self.clip = match self.clip {
                        Some(_) => None,
                        None => {
                            // toward the viewer in world coordinates: eye e = R·w, viewer at +z
                            let r = self.rotation;
                            let n = [r.x_axis.z, r.y_axis.z, r.z_axis.z];
                            Some(Plane { normal: n, offset: 0.0 })
                        }
                    };
                    self.changed()
                }
                Key::ToggleLens => {
                    self.lens = match self.lens {
                        Some(_) => None,
                        None => Some(Lens {
                            centre: self.world_under(self.cursor.0, self.cursor.1),
                            radius: self.lens_radius,
                            at: Some([self.cursor.0, self.cursor.1]),
                        }),
                    };
                    self.changed()
                }
                Key::LensSmaller | Key::LensBigger => {
                    let f = if k == Key::LensBigger { 1.15 } else { 1.0 / 1.15 };
                    self.lens_radius = (self.lens_radius * f).clamp(0.01 * self.diagonal_mm, self.diagonal_mm);
                    match self.lens {
                        Some(l) => {
                            self.lens = Some(Lens { radius: self.lens_radius, ..l });
                            self.changed()
                        }
                        None => Outcome::Nothing,
                    }
                }
                Key::ToggleProjection => {
                    self.projection = if self.projection.is_perspective() { Projection::Parallel } else { self.perspective };
                    self.changed()
                }
                Key::Reset => {
                    self.rotation = self.base;
                    self.changed()
                }
                Key::Save => Outcome::Save,
                Key::Quit => Outcome::Quit,
            },
        }
    }

    /// Rotates by `yaw` degrees about the vertical eye axis (horizontal drag) and
    /// `pitch` degrees about the horizontal eye axis (vertical drag). A drag to the
    /// right turns the front of the object to the right, a drag down turns it down.
    pub fn rotate(&mut self, yaw: f64, pitch: f64) {
        let r = rotate_eye(rotate_eye(self.rotation, 1, yaw), 0, pitch);
        // re-orthonormalize so thousands of small steps do not drift off a rotation
        self.rotation = DMat3::from_quat(DQuat::from_mat3(&r).normalize());
    }

    /// The renders to start or cancel now; call after every input and every
    /// accepted frame.
    pub fn requests(&mut self) -> Vec<Request> {
        let mut out = Vec::new();
        if self.preview_posted != self.seq {
            self.preview_posted = self.seq;
            out.push(Request::Preview(self.spec()));
        }
        let want_blend = self.display == Display::Blend && self.drag.is_none() && self.shown == Some((self.seq, Kind::Preview));
        if want_blend {
            if self.blend_posted != Some(self.seq) {
                self.blend_posted = Some(self.seq);
                out.push(Request::Blend(self.spec()));
            }
        } else if self.blend_posted.take().is_some() {
            out.push(Request::CancelBlend);
        }
        out
    }

    /// Whether a finished frame of `seq` from the `kind` worker may replace what is
    /// shown; records it when it may. Previews of older states are still shown
    /// while a drag outpaces the renderer; a blended frame only for the current
    /// state, in the blend display, with no drag in progress.
    pub fn accept(&mut self, seq: u64, kind: Kind) -> bool {
        let ok = match kind {
            Kind::Preview => self.shown.is_none_or(|(s, k)| seq > s || (seq == s && k == Kind::Preview)),
            Kind::Blend => seq == self.seq && self.display == Display::Blend && self.drag.is_none(),
        };
        if kind == Kind::Blend && self.blend_posted == Some(seq) {
            self.blend_posted = None;
        }
        if ok {
            self.shown = Some((seq, kind));
        }
        ok
    }
}

/// Labels of the tissue buttons: "1 skin", "2 fat", …
pub fn button_labels(tissues: &[TissueInfo]) -> Vec<String> {
    tissues.iter().enumerate().map(|(i, t)| format!("{} {}", i + 1, t.name)).collect()
}

/// Angle in degrees of the rotation that takes `a` to `b`.
pub fn angle_between(a: DMat3, b: DMat3) -> f64 {
    let m = b * a.transpose();
    let c = ((m.x_axis.x + m.y_axis.y + m.z_axis.z - 1.0) / 2.0).clamp(-1.0, 1.0);
    c.acos().to_degrees()
}

/// Frames per second and degrees per second of the frames actually presented,
/// over the last second of them.
#[derive(Clone, Debug, Default)]
pub struct Meter {
    samples: VecDeque<(Instant, f64)>,
    last: Option<DMat3>,
}

impl Meter {
    const WINDOW: Duration = Duration::from_secs(1);

    /// Records a presented frame of rotation `r` at time `t`.
    pub fn record(&mut self, t: Instant, r: DMat3) {
        let deg = self.last.map_or(0.0, |l| angle_between(l, r));
        self.last = Some(r);
        self.samples.push_back((t, deg));
        while self.samples.front().is_some_and(|&(s, _)| t.duration_since(s) > Self::WINDOW) {
            self.samples.pop_front();
        }
    }

    /// `(frames per second, degrees per second)` over the recorded window; zero
    /// with fewer than two frames.
    pub fn rates(&self) -> (f64, f64) {
        let (Some(&(t0, _)), Some(&(t1, _))) = (self.samples.front(), self.samples.back()) else { return (0.0, 0.0) };
        let span = t1.duration_since(t0).as_secs_f64();
        if self.samples.len() < 2 || span <= 0.0 {
            return (0.0, 0.0);
        }
        let deg: f64 = self.samples.iter().skip(1).map(|s| s.1).sum();
        ((self.samples.len() - 1) as f64 / span, deg / span)
    }
}

/// How the mask got to the frame's view, for the overlay.
pub fn shear_summary(s: &FrameStats) -> String {
    match (s.shear_direct, s.shear_steps) {
        (d, _) if d > 0 => "direct shear (jump > 6 bits)".into(),
        (_, 0) => "no shear (same mask position)".into(),
        (_, 1) => "incremental: 1 one-bit step".into(),
        (_, n) => format!("incremental: {n} one-bit steps (catch-up)"),
    }
}

/// Axis names.
pub const AXES: [&str; 3] = ["x", "y", "z"];

/// What the overlay reports besides the state.
#[derive(Clone, Debug, Default)]
pub struct Hud {
    pub title: String,
    /// The last preview frame's statistics, and whether its principal axis
    /// differed from the frame before.
    pub preview: Option<(FrameStats, bool)>,
    /// Statistics and wall milliseconds (with any mask build) of the blended
    /// frame on screen.
    pub blend: Option<(FrameStats, f64)>,
    pub fps: f64,
    pub degps: f64,
    /// A slow step in progress and for how long.
    pub busy: Option<(String, f64)>,
    /// A short-lived message (e.g. where a PNG went).
    pub message: Option<String>,
    /// The other principal axes are being built in the background (a turn
    /// onto one of them would wait for its build until they are done).
    pub background: bool,
}

impl State {
    /// The overlay's text lines.
    pub fn overlay_lines(&self, hud: &Hud) -> Vec<String> {
        let mut l = vec![hud.title.clone()];
        match &hud.preview {
            Some((s, switched)) => {
                let f = s.frame_ms();
                let fps = if f > 0.0 { 1000.0 / f } else { 0.0 };
                l.push(format!("{f:.2} ms/frame = shear {:.2} + render {:.2} + warp {:.2}", s.shear_ms, s.render_ms, s.warp_ms));
                l.push(format!("{fps:.0} fps max; drag: {:.0} fps shown, {:.0} deg/s", hud.fps, hud.degps));
                if let Some(t) = self.adaptive.target_ms {
                    l.push(match self.adapts() {
                        true => {
                            format!("target {:.0} fps: {} px/voxel moving, {} still", 1000.0 / t, self.adaptive.moving, self.adaptive.still)
                        }
                        false => format!("target {:.0} fps: 1 px/voxel in parallel (fastest there)", 1000.0 / t),
                    });
                }
                let axis = if *switched { " (axis switch)" } else { "" };
                l.push(format!("axis {}{axis}, {}", AXES[s.axis.min(2)], shear_summary(s)));
            }
            None => l.push("waiting for the first frame".into()),
        }
        let mode = match (self.display, hud.blend, self.blend_pending()) {
            (Display::Iso, _, _) => "iso preview".to_string(),
            (Display::Blend, Some((s, ms)), _) => format!("blend {:.1} ms/frame ({ms:.0} ms with build)", s.frame_ms()),
            (Display::Blend, None, true) => "blend: rendering in background...".into(),
            (Display::Blend, None, false) => "blend: iso preview while moving".into(),
        };
        l.push(format!("cell {}, {mode}", self.cell));
        l.push(match self.class {
            Class::Tissue(_) => format!("tissue {} (iso {})", self.class_name(), short(self.iso())),
            Class::Custom(v) => format!("custom iso {v:.1}"),
        });
        if let Some(c) = self.clip {
            l.push(format!("clip plane {:+.1} mm from the centre (right-drag moves it, C removes it)", c.offset));
        }
        if let Some(lens) = self.lens {
            l.push(match self.class {
                Class::Tissue(_) => format!("lens r {:.1} mm (follows the mouse; , . size, L removes it)", lens.radius),
                Class::Custom(_) => "lens: needs a tissue preset (keys 1-9)".into(),
            });
        }
        if hud.background {
            l.push("building the other axes in the background ...".into());
        }
        if let Some((what, secs)) = &hud.busy {
            l.push(format!("{what}... {secs:.1} s"));
        }
        if let Some(m) = &hud.message {
            l.push(m.clone());
        }
        l
    }
}

/// A density for the overlay: whole numbers as they are, others to one decimal.
pub fn short(v: f32) -> String {
    if v.fract() == 0.0 { format!("{v:.0}") } else { format!("{v:.1}") }
}

/// The key help line.
pub const HELP: &str = "drag rotate 1-4 tissue L lens , . [ ] iso +- cell spc blend P persp wheel fly C clip (right-drag) R S Q";

/// The eye distances (volume diagonals) the mouse wheel keeps to.
pub const MIN_EYE_DISTANCE: f64 = 0.05;
pub const MAX_EYE_DISTANCE: f64 = 1000.0;

#[cfg(test)]
mod tests {
    use super::*;

    fn start() -> State {
        State::new(Start {
            tissues: ["skin", "fat", "soft", "bone"]
                .iter()
                .zip([-500.0, -200.0, -20.0, 300.0])
                .map(|(n, t)| TissueInfo { name: n.to_string(), threshold: t })
                .collect(),
            range: (-1000.0, 1000.0),
            camera: Camera { rotation: DMat3::IDENTITY, zoom: None, size: [512, 512] },
            class: Class::Tissue(0),
            display: Display::Blend,
            cell: 1,
            drag_speed: 0.5,
            projection: Projection::Parallel,
            adaptive: Adaptive::new(None, 1.0),
            diagonal_mm: 200.0,
            lens: None,
        })
    }

    /// L puts a lens under the mouse (its fallback centre at the volume
    /// centre's depth, the pixel for the worker's surface); it follows the
    /// mouse, `,` / `.` size it, L removes it.
    #[test]
    fn lens_key_places_a_lens_that_follows_the_mouse() {
        let mut s = start();
        s.handle(Input::Move { x: 255.5, y: 100.0 });
        assert_eq!(s.handle(Input::Key(Key::ToggleLens)), Outcome::Redraw);
        let l = s.spec().lens.expect("a lens");
        // 512 px for a 200 mm diagonal: 155.5 px above the centre is +60.7 mm in eye y = world y
        assert!(l.centre[0].abs() < 1e-9 && (l.centre[1] - 155.5 * 200.0 / 512.0).abs() < 1e-9 && l.centre[2].abs() < 1e-9, "{l:?}");
        let seq = s.seq;
        assert_eq!(s.handle(Input::Move { x: 300.0, y: 100.0 }), Outcome::Redraw);
        assert!(s.seq > seq && s.spec().lens.unwrap().centre[0] > 0.0);
        assert_eq!(s.handle(Input::Key(Key::LensBigger)), Outcome::Redraw);
        assert!(s.spec().lens.unwrap().radius > l.radius);
        assert_eq!(s.handle(Input::Key(Key::ToggleLens)), Outcome::Redraw);
        assert_eq!(s.spec().lens, None);
        assert_eq!(s.handle(Input::Move { x: 10.0, y: 10.0 }), Outcome::Nothing, "no lens: a move changes nothing");
    }

    /// P toggles the projection; the wheel flies a perspective eye in and out
    /// (and does nothing in parallel); each change is a new frame.
    #[test]
    fn perspective_key_and_wheel_fly_in() {
        let mut s = start();
        assert_eq!(s.handle(Input::Wheel { lines: 1.0 }), Outcome::Nothing, "parallel: no eye to move");
        let seq = s.seq;
        assert_eq!(s.handle(Input::Key(Key::ToggleProjection)), Outcome::Redraw);
        assert_eq!(s.spec().projection, Projection::Perspective { fov_deg: 40.0, eye_distance: 2.0 });
        assert!(s.seq > seq);
        s.handle(Input::Wheel { lines: 2.0 });
        let Projection::Perspective { eye_distance, .. } = s.spec().projection else { panic!() };
        assert!((eye_distance - 2.0 * 0.81).abs() < 1e-12, "{eye_distance}");
        // far out and back: clamped, never zero or infinite
        s.handle(Input::Wheel { lines: -1e6 });
        assert_eq!(s.spec().projection, Projection::Perspective { fov_deg: 40.0, eye_distance: MAX_EYE_DISTANCE });
        s.handle(Input::Wheel { lines: 1e6 });
        assert_eq!(s.spec().projection, Projection::Perspective { fov_deg: 40.0, eye_distance: MIN_EYE_DISTANCE });
        assert_eq!(s.handle(Input::Wheel { lines: f64::NAN }), Outcome::Nothing);
        // P back to parallel, and again to the perspective last shown
        s.handle(Input::Key(Key::ToggleProjection));
        assert_eq!(s.spec().projection, Projection::Parallel);
        s.handle(Input::Key(Key::ToggleProjection));
        assert_eq!(s.spec().projection, Projection::Perspective { fov_deg: 40.0, eye_distance: MIN_EYE_DISTANCE });
    }

    /// `--target-fps`: while dragging, the preview's quality follows
    /// `q · sqrt(target / measured)` in 1/16 steps, inside its band it stays
    /// put (no hunting on noisy timings), it never leaves [0.25, still]; the
    /// release asks for a new preview at the still quality (≥ 1).
    #[test]
    fn adaptive_quality_follows_the_target_with_hysteresis() {
        // `n` frames of `ms` at the current quality
        fn feed(a: &mut Adaptive, ms: &[f64]) -> bool {
            let mut changed = false;
            for &m in ms {
                changed |= a.measured(a.moving, m);
            }
            changed
        }
        let mut a = Adaptive::new(Some(50.0), 1.0);
        assert_eq!((a.target_ms, a.moving, a.still), (Some(20.0), 1.0, 1.0));
        // 80 ms at q 1 (the median of three, one outlier each way): a quarter
        // of the rays wanted, q 0.5
        assert!(!feed(&mut a, &[80.0, 5.0]));
        assert!(a.measured(1.0, 300.0));
        assert_eq!(a.moving, 0.5);
        // a late frame of the old quality is ignored
        assert!(!a.measured(1.0, 1e6));
        // within the band: no change, whichever side
        assert!(!feed(&mut a, &[22.0, 22.0, 22.0, 18.0, 18.0, 18.0]));
        assert_eq!(a.moving, 0.5);
        // one odd frame among steady ones does not move it
        assert!(!feed(&mut a, &[20.0, 1000.0, 20.0]));
        // a frame cost that scales with q² settles: 20 ms at 0.5 becomes the
        // target, wherever it started
        let cost = |q: f64| 80.0 * q * q;
        let mut b = Adaptive::new(Some(50.0), 1.0);
        for _ in 0..15 {
            let m = cost(b.moving);
            b.measured(b.moving, m);
        }
        assert!((cost(b.moving) - 20.0).abs() / 20.0 < 0.3, "settled at q {} ({} ms)", b.moving, cost(b.moving));
        // clamped: very slow frames stop at 0.25, fast ones at the still quality
        assert!(feed(&mut a, &[1e6; 3]));
        assert_eq!(a.moving, MIN_QUALITY);
        assert!(feed(&mut a, &[0.01; 3]));
        assert_eq!(a.moving, 1.0);
        for bad in [f64::NAN, 0.0, -1.0, f64::INFINITY] {
            assert!(!feed(&mut a, &[bad; 3]));
        }
        // without a target nothing adapts; --quality sets the moving value and,
        // at least 1, the still one
        let mut n = Adaptive::new(None, 0.5);
        assert!(!n.measured(0.5, 1e6));
        assert_eq!((n.moving, n.still), (0.5, 1.0));
        assert_eq!(Adaptive::new(None, 2.0).still, 2.0);
        // the state: dragged frames at the moving quality, the release a new
        // preview at the still one
        let mut s = start();
        s.adaptive = Adaptive::new(Some(50.0), 1.0);
        feed(&mut s.adaptive, &[80.0; 3]);
        s.requests();
        s.handle(Input::Press { x: 200.0, y: 200.0 });
        s.handle(Input::Move { x: 210.0, y: 200.0 });
        assert_eq!(s.spec().quality, 0.5);
        let seq = s.seq;
        assert_eq!(s.handle(Input::Release), Outcome::Redraw);
        assert!(s.seq > seq, "the release renders again");
        assert_eq!(s.spec().quality, 1.0);
        assert!(matches!(s.requests()[..], [Request::Preview(Spec { quality: 1.0, .. }), ..]));
        // the binary rotator's parallel preview stays at one pixel per voxel
        // (its translated rays are fastest there); in perspective it adapts
        s.adaptive.fixed_in_parallel = true;
        s.handle(Input::Press { x: 200.0, y: 200.0 });
        s.handle(Input::Move { x: 220.0, y: 200.0 });
        assert!(!s.adapts());
        assert_eq!(s.spec().quality, 1.0);
        s.handle(Input::Key(Key::ToggleProjection));
        assert!(s.adapts());
        assert_eq!(s.spec().quality, 0.5);
    }

    /// C places a plane through the centre facing the viewer (the near half
    /// removed: the eye-space +z side), a right-drag moves it along its normal
    /// (up: away from the viewer), C again removes it; every change is a new
    /// frame and the spec carries the plane.
    #[test]
    fn clip_key_places_a_plane_facing_the_viewer_and_a_right_drag_moves_it() {
        let mut s = start();
        assert_eq!(s.handle(Input::PressRight { x: 200.0, y: 200.0 }), Outcome::Nothing, "no plane to drag");
        s.rotation = rotate_eye(DMat3::IDENTITY, 1, 30.0);
        let seq = s.seq;
        assert_eq!(s.handle(Input::Key(Key::ToggleClip)), Outcome::Redraw);
        assert!(s.seq > seq);
        let c = s.spec().clip.expect("a plane");
        // its normal is the direction toward the viewer: R · n = +z
        let e = s.rotation * glam::DVec3::from_array(c.normal);
        assert!((e - glam::DVec3::Z).length() < 1e-12, "{e:?}");
        assert_eq!(c.offset, 0.0);
        // rotating keeps the plane where it is in the volume
        s.handle(Input::Press { x: 200.0, y: 200.0 });
        s.handle(Input::Move { x: 230.0, y: 200.0 });
        s.handle(Input::Release);
        assert_eq!(s.spec().clip, Some(c));
        // a right-drag up by 64 px moves it 200 mm · 64 / 512 = 25 mm away from the viewer
        assert_eq!(s.handle(Input::PressRight { x: 200.0, y: 200.0 }), Outcome::Redraw);
        let seq = s.seq;
        assert_eq!(s.handle(Input::Move { x: 200.0, y: 136.0 }), Outcome::Redraw);
        assert!(s.seq > seq);
        assert!((s.spec().clip.unwrap().offset - 25.0).abs() < 1e-9, "{:?}", s.spec().clip);
        assert_eq!(s.spec().clip.unwrap().normal, c.normal);
        // clamped to a diagonal either way
        s.handle(Input::Move { x: 200.0, y: -1e6 });
        assert_eq!(s.spec().clip.unwrap().offset, 200.0);
        s.handle(Input::Release);
        assert_eq!(s.drag, None);
        s.handle(Input::Key(Key::ToggleClip));
        assert_eq!(s.spec().clip, None);
    }

    fn previews(r: &[Request]) -> Vec<u64> {
        r.iter().filter_map(|x| if let Request::Preview(s) = x { Some(s.seq) } else { None }).collect()
    }

    #[test]
    fn first_requests_are_one_preview_then_the_blend() {
        let mut s = start();
        let r = s.requests();
        assert_eq!(previews(&r), vec![1]);
        assert_eq!(r.len(), 1);
        assert!(s.requests().is_empty(), "nothing new");
        assert!(s.accept(1, Kind::Preview));
        let r = s.requests();
        assert!(matches!(r[..], [Request::Blend(Spec { seq: 1, .. })]));
        assert!(s.blend_pending());
        assert!(s.accept(1, Kind::Blend));
        assert!(!s.blend_pending());
        assert!(s.requests().is_empty());
        assert_eq!(s.shown(), Some((1, Kind::Blend)));
    }

    #[test]
    fn iso_display_never_asks_for_a_blend() {
        let mut s = start();
        s.handle(Input::Key(Key::ToggleDisplay));
        assert_eq!(s.display, Display::Iso);
        s.requests();
        s.accept(s.seq, Kind::Preview);
        assert!(s.requests().is_empty());
    }

    #[test]
    fn drag_rotates_and_cancels_then_release_asks_for_the_blend_again() {
        let mut s = start();
        s.requests();
        s.accept(1, Kind::Preview);
        s.requests(); // blend of 1 posted
        assert_eq!(s.handle(Input::Press { x: 100.0, y: 100.0 }), Outcome::Redraw);
        assert_eq!(s.requests(), vec![Request::CancelBlend]);
        assert_eq!(s.handle(Input::Move { x: 120.0, y: 100.0 }), Outcome::Redraw);
        assert_eq!(s.seq, 2);
        // horizontal drag: about the vertical eye axis by 20 px × 0.5°
        assert!((angle_between(DMat3::IDENTITY, s.rotation) - 10.0).abs() < 1e-9);
        let front = s.rotation * glam::DVec3::Z;
        assert!(front.x > 0.0 && front.y.abs() < 1e-12, "the front turns right: {front}");
        s.handle(Input::Move { x: 120.0, y: 110.0 });
        let front = s.rotation * glam::DVec3::Z;
        assert!(front.y < 0.0, "a downward drag turns the front down: {front}");
        assert_eq!(previews(&s.requests()), vec![3]);
        // the stale blend of seq 1 arrives: discarded
        assert!(!s.accept(1, Kind::Blend));
        assert!(s.accept(3, Kind::Preview));
        assert!(s.requests().is_empty(), "no blend while dragging");
        s.handle(Input::Release);
        assert!(matches!(s.requests()[..], [Request::Blend(Spec { seq: 3, .. })]));
        // a new drag before the blend arrives discards it even at the same seq
        s.handle(Input::Press { x: 5.0, y: 5.0 });
        assert_eq!(s.requests(), vec![Request::CancelBlend]);
        assert!(!s.accept(3, Kind::Blend));
        assert_eq!(s.shown(), Some((3, Kind::Preview)));
    }

    #[test]
    fn older_previews_still_show_while_a_drag_outpaces_the_renderer() {
        let mut s = start();
        s.requests();
        s.handle(Input::Press { x: 0.0, y: 200.0 });
        for x in 1..10 {
            s.handle(Input::Move { x: x as f64, y: 200.0 });
        }
        assert_eq!(previews(&s.requests()), vec![10], "only the latest state is asked for");
        assert!(s.accept(1, Kind::Preview));
        assert!(s.accept(10, Kind::Preview));
        assert!(!s.accept(4, Kind::Preview), "never go back");
    }

    #[test]
    fn tissue_keys_buttons_and_the_slider() {
        let mut s = start();
        assert_eq!(s.handle(Input::Key(Key::Tissue(3))), Outcome::Redraw);
        assert_eq!(s.class, Class::Tissue(3));
        assert_eq!(s.iso(), 300.0);
        assert_eq!(s.handle(Input::Key(Key::Tissue(3))), Outcome::Nothing, "same tissue: no new frame");
        assert_eq!(s.handle(Input::Key(Key::Tissue(7))), Outcome::Nothing, "no such preset");
        let b = s.layout.buttons[1];
        s.handle(Input::Press { x: b.x as f64 + 1.0, y: b.y as f64 + 1.0 });
        assert_eq!(s.class, Class::Tissue(1));
        assert_eq!(s.drag, None, "a button click is not a drag");
        s.handle(Input::Release);
        let sl = s.layout.slider;
        let mid = sl.x as f64 + (sl.w - 1) as f64 / 2.0;
        s.handle(Input::Press { x: mid, y: sl.y as f64 + 4.0 });
        assert_eq!(s.class, Class::Custom(0.0));
        assert_eq!(s.drag, Some(Drag::Slider));
        let seq = s.seq;
        s.handle(Input::Move { x: (sl.x + sl.w + 50) as f64, y: 0.0 });
        assert_eq!(s.class, Class::Custom(1000.0), "clamped to the top of the range");
        assert_eq!(s.seq, seq + 1);
        assert_eq!(s.rotation, DMat3::IDENTITY, "the slider does not rotate");
        s.handle(Input::Release);
        s.handle(Input::Key(Key::IsoDown));
        assert_eq!(s.class, Class::Custom(990.0));
        s.handle(Input::Key(Key::IsoUp));
        s.handle(Input::Key(Key::IsoUp));
        assert_eq!(s.class, Class::Custom(1000.0));
        assert!((s.slider_fraction() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn cell_reset_resize_save_quit() {
        let mut s = start();
        assert_eq!(s.handle(Input::Key(Key::CellDown)), Outcome::Nothing);
        for _ in 0..20 {
            s.handle(Input::Key(Key::CellUp));
        }
        assert_eq!(s.cell, MAX_CELL);
        s.rotate(30.0, 10.0);
        s.handle(Input::Key(Key::Reset));
        assert_eq!(s.rotation, DMat3::IDENTITY);
        assert_eq!(s.handle(Input::Resize { w: 300, h: 200 }), Outcome::Redraw);
        assert_eq!(s.spec().camera.size, [300, 200]);
        assert_eq!(s.layout.size, [300, 200]);
        assert_eq!(s.handle(Input::Resize { w: 0, h: 200 }), Outcome::Nothing, "minimized");
        assert_eq!(s.handle(Input::Key(Key::Save)), Outcome::Save);
        assert_eq!(s.handle(Input::Key(Key::Quit)), Outcome::Quit);
    }

    #[test]
    fn long_drags_stay_rotations() {
        let mut s = start();
        s.handle(Input::Press { x: 0.0, y: 0.0 });
        for i in 1..5000 {
            s.handle(Input::Move { x: (i % 97) as f64 * 3.0, y: (i % 89) as f64 * 2.0 });
        }
        let r = s.rotation;
        assert!((r.determinant() - 1.0).abs() < 1e-9);
        assert!((r * r.transpose()).abs_diff_eq(DMat3::IDENTITY, 1e-9));
    }

    #[test]
    fn meter_measures_presented_frames() {
        let mut m = Meter::default();
        assert_eq!(m.rates(), (0.0, 0.0));
        let t0 = Instant::now();
        for i in 0..11 {
            m.record(t0 + Duration::from_millis(50 * i), DMat3::from_rotation_y((i as f64).to_radians()));
        }
        let (fps, degps) = m.rates();
        assert!((fps - 20.0).abs() < 1e-6, "{fps}");
        assert!((degps - 20.0).abs() < 1e-6, "{degps}");
    }

    #[test]
    fn overlay_lines_name_everything() {
        let mut s = start();
        let stats = FrameStats { shear_ms: 0.1, render_ms: 2.0, warp_ms: 1.0, axis: 1, shear_steps: 3, ..Default::default() };
        let hud =
            Hud { title: "head".into(), preview: Some((stats, true)), busy: Some(("rebuilding mask".into(), 0.4)), ..Default::default() };
        let text = s.overlay_lines(&hud).join("\n");
        for want in [
            "3.10 ms/frame",
            "shear 0.10",
            "render 2.00",
            "warp 1.00",
            "fps",
            "deg/s",
            "axis y (axis switch)",
            "3 one-bit steps",
            "cell 1",
            "tissue skin",
            "rebuilding mask... 0.4 s",
        ] {
            assert!(text.contains(want), "{want} missing from\n{text}");
        }
        s.handle(Input::Key(Key::IsoUp));
        let d = FrameStats { shear_direct: 1, ..stats };
        let text = s.overlay_lines(&Hud { preview: Some((d, false)), ..hud }).join("\n");
        assert!(text.contains("direct shear") && text.contains("custom iso -490.0"), "{text}");
        assert_eq!((short(29.765625), short(-500.0)), ("29.8".to_string(), "-500".to_string()));
        assert!(s.overlay_lines(&Hud::default()).iter().all(|l| l.len() <= 64));
    }
}
