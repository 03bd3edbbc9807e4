//! The overlay: text with an embedded 8×8 bitmap font (font8x8's public-domain
//! glyphs; no fontconfig, no system fonts), translucent panels, the clickable
//! tissue buttons and the iso slider, all drawn into a `0RGB` `u32` framebuffer.
//!
//! [`Layout`] places the controls for a window size and answers which control
//! a click hits, so input handling and drawing agree on the geometry.

/// Glyph size in pixels.
pub const GLYPH: usize = 8;
/// Line height of overlay text.
pub const LINE: usize = 10;

/// An axis-aligned rectangle in window pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rect {
    pub x: i32,
    pub y: i32,
    pub w: i32,
    pub h: i32,
}

impl Rect {
    /// Whether the point lies inside.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        x >= self.x as f64 && x < (self.x + self.w) as f64 && y >= self.y as f64 && y < (self.y + self.h) as f64
    }
}

impl std::fmt::Display for Rect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{},{},{},{}", self.x, self.y, self.w, self.h)
    }
}

/// What a click at a point hits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Hit {
    /// Tissue button `i`.
    Tissue(usize),
    /// The iso slider at fraction `t` (0 = low end, 1 = high end) of its track.
    Slider(f64),
    /// The view itself.
    View,
}

/// Where the controls sit: a row of tissue buttons and the iso slider along the
/// bottom edge, the key help above them.
#[derive(Clone, Debug, PartialEq)]
pub struct Layout {
    pub size: [usize; 2],
    pub buttons: Vec<Rect>,
    pub slider: Rect,
    /// The y of the key help line.
    pub help_y: i32,
}

/// Width of the slider's label column ("iso") and value column.
const SLIDER_LABEL: i32 = 4 * GLYPH as i32;
const SLIDER_VALUE: i32 = 8 * GLYPH as i32;

impl Layout {
    /// The layout for a `size` window with the given tissue button labels.
    pub fn new(size: [usize; 2], labels: &[String]) -> Self {
        let (w, h) = (size[0] as i32, size[1] as i32);
        let slider = Rect { x: 6 + SLIDER_LABEL, y: h - 16, w: (w - 12 - SLIDER_LABEL - SLIDER_VALUE).max(8), h: 12 };
        let by = h - 36;
        let mut x = 6;
        let buttons = labels
            .iter()
            .map(|l| {
                let r = Rect { x, y: by, w: (l.chars().count() * GLYPH) as i32 + 8, h: 16 };
                x += r.w + 4;
                r
            })
            .collect();
        Layout { size, buttons, slider, help_y: by - LINE as i32 - 2 }
    }

    /// The control under `(x, y)`.
    pub fn hit(&self, x: f64, y: f64) -> Hit {
        if let Some(i) = self.buttons.iter().position(|b| b.contains(x, y)) {
            return Hit::Tissue(i);
        }
        // the slider's hit area is a little taller than its track
        let s = self.slider;
        let grab = Rect { x: s.x - 4, y: s.y - 3, w: s.w + 8, h: s.h + 6 };
        if grab.contains(x, y) {
            return Hit::Slider(self.slider_fraction(x));
        }
        Hit::View
    }

    /// Fraction along the slider's track of window x coordinate `x`, clamped.
    pub fn slider_fraction(&self, x: f64) -> f64 {
        ((x - self.slider.x as f64) / (self.slider.w.max(1) as f64 - 1.0).max(1.0)).clamp(0.0, 1.0)
    }

    /// The top of the controls (everything below belongs to the overlay).
    pub fn controls_top(&self) -> i32 {
        self.help_y
    }

    /// One line describing the layout (for logs and window tests).
    pub fn describe(&self) -> String {
        let b: Vec<String> = self.buttons.iter().enumerate().map(|(i, r)| format!("button{i}={r}")).collect();
        format!("layout size={}x{} {} slider={}", self.size[0], self.size[1], b.join(" "), self.slider)
    }
}

/// A framebuffer to draw into: `0RGB` pixels, row-major, row 0 at the top.
pub struct Canvas<'a> {
    pub px: &'a mut [u32],
    pub w: usize,
    pub h: usize,
}

/// Packs 8-bit channels as `0RGB`.
pub const fn rgb(r: u8, g: u8, b: u8) -> u32 {
    (r as u32) << 16 | (g as u32) << 8 | b as u32
}

impl Canvas<'_> {
    /// Fills `r` (clipped) with `color`.
    pub fn fill(&mut self, r: Rect, color: u32) {
        let Some((x0, y0, x1, y1)) = self.clip(r) else { return };
        for y in y0..y1 {
            self.px[y * self.w + x0..y * self.w + x1].fill(color);
        }
    }

    /// Darkens `r` (clipped) to `keep`/256 of its brightness: a translucent panel.
    pub fn shade(&mut self, r: Rect, keep: u32) {
        let Some((x0, y0, x1, y1)) = self.clip(r) else { return };
        for y in y0..y1 {
            for p in &mut self.px[y * self.w + x0..y * self.w + x1] {
                let c = *p;
                let ch = |s: u32| ((((c >> s) & 0xFF) * keep) >> 8) << s;
                *p = ch(16) | ch(8) | ch(0);
            }
        }
    }

    /// Outlines `r` (clipped) with a one-pixel border.
    pub fn frame(&mut self, r: Rect, color: u32) {
        self.fill(Rect { h: 1, ..r }, color);
        self.fill(Rect { y: r.y + r.h - 1, h: 1, ..r }, color);
        self.fill(Rect { w: 1, ..r }, color);
        self.fill(Rect { x: r.x + r.w - 1, w: 1, ..r }, color);
    }

    /// Draws `text` with its top-left corner at `(x, y)`; characters outside
    /// printable ASCII are drawn as `?`. Returns the x after the last glyph.
    pub fn text(&mut self, x: i32, y: i32, text: &str, color: u32) -> i32 {
        let mut cx = x;
        for ch in text.chars() {
            let code = if (' '..='~').contains(&ch) { ch as usize } else { '?' as usize };
            let glyph = font8x8::legacy::BASIC_LEGACY[code];
            for (gy, bits) in glyph.iter().enumerate() {
                let py = y + gy as i32;
                if py < 0 || py >= self.h as i32 {
                    continue;
                }
                for gx in 0..GLYPH {
                    let px = cx + gx as i32;
                    // bit 0 is the leftmost pixel
                    if bits >> gx & 1 == 1 && px >= 0 && px < self.w as i32 {
                        self.px[py as usize * self.w + px as usize] = color;
                    }
                }
            }
            cx += GLYPH as i32;
        }
        cx
    }

    /// Draws `lines` of text on a translucent panel at `(x, y)`.
    pub fn panel(&mut self, x: i32, y: i32, lines: &[String], color: u32) {
        let wmax = lines.iter().map(|l| l.chars().count()).max().unwrap_or(0);
        if wmax == 0 {
            return;
        }
        let r = Rect { x, y, w: (wmax * GLYPH) as i32 + 8, h: (lines.len() * LINE) as i32 + 6 };
        self.shade(r, 80);
        for (i, l) in lines.iter().enumerate() {
            self.text(x + 4, y + 4 + (i * LINE) as i32, l, color);
        }
    }

    fn clip(&self, r: Rect) -> Option<(usize, usize, usize, usize)> {
        let x0 = r.x.clamp(0, self.w as i32) as usize;
        let y0 = r.y.clamp(0, self.h as i32) as usize;
        let x1 = (r.x.saturating_add(r.w)).clamp(0, self.w as i32) as usize;
        let y1 = (r.y.saturating_add(r.h)).clamp(0, self.h as i32) as usize;
        (x0 < x1 && y0 < y1).then_some((x0, y0, x1, y1))
    }
}

/// Text colour of the overlay.
pub const TEXT: u32 = rgb(235, 235, 235);
/// Highlight (busy states, the current tissue).
pub const ACCENT: u32 = rgb(255, 200, 60);
const BUTTON: u32 = rgb(48, 52, 60);
const BUTTON_ON: u32 = rgb(170, 120, 20);
const TRACK: u32 = rgb(70, 70, 76);

/// What the controls show.
pub struct Controls<'a> {
    pub labels: &'a [String],
    /// The highlighted tissue button (none when a custom iso value is active).
    pub current: Option<usize>,
    /// Slider position in [0, 1] and the value to print beside it.
    pub slider: f64,
    pub value: f32,
    pub help: &'a str,
}

/// Draws the tissue buttons, the iso slider and the key help.
pub fn draw_controls(c: &mut Canvas<'_>, layout: &Layout, ctl: &Controls<'_>) {
    let top = layout.controls_top();
    c.shade(Rect { x: 0, y: top - 2, w: c.w as i32, h: c.h as i32 - top + 2 }, 90);
    c.text(6, layout.help_y, ctl.help, TEXT);
    for (i, (r, label)) in layout.buttons.iter().zip(ctl.labels).enumerate() {
        let on = ctl.current == Some(i);
        c.fill(*r, if on { BUTTON_ON } else { BUTTON });
        c.frame(*r, if on { ACCENT } else { rgb(110, 110, 120) });
        c.text(r.x + 4, r.y + 4, label, TEXT);
    }
    let s = layout.slider;
    c.text(6, s.y + 2, "iso", TEXT);
    c.fill(Rect { x: s.x, y: s.y + s.h / 2 - 1, w: s.w, h: 3 }, TRACK);
    let kx = s.x + (ctl.slider.clamp(0.0, 1.0) * (s.w - 1).max(0) as f64).round() as i32;
    c.fill(Rect { x: kx - 3, y: s.y, w: 7, h: s.h }, if ctl.current.is_none() { ACCENT } else { TEXT });
    c.text(s.x + s.w + 6, s.y + 2, &format!("{:.0}", ctl.value), TEXT);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn labels() -> Vec<String> {
        ["1 skin", "2 fat", "3 soft", "4 bone"].map(String::from).to_vec()
    }

    #[test]
    fn text_sets_pixels_inside_its_cell_only() {
        let mut px = vec![0u32; 32 * 16];
        let mut c = Canvas { px: &mut px, w: 32, h: 16 };
        let end = c.text(2, 3, "A", TEXT);
        assert_eq!(end, 10);
        let set: Vec<(usize, usize)> = (0..16).flat_map(|y| (0..32).map(move |x| (x, y))).filter(|&(x, y)| px[y * 32 + x] != 0).collect();
        assert!(set.len() > 10, "the A glyph has pixels");
        assert!(set.iter().all(|&(x, y)| (2..10).contains(&x) && (3..11).contains(&y)));
    }

    #[test]
    fn drawing_clips_at_every_edge() {
        let mut px = vec![0u32; 10 * 10];
        let mut c = Canvas { px: &mut px, w: 10, h: 10 };
        c.text(-4, -4, "WW", TEXT);
        c.text(6, 6, "WW", TEXT);
        c.fill(Rect { x: -5, y: 8, w: 100, h: 100 }, 1);
        c.shade(Rect { x: i32::MIN / 2, y: 0, w: i32::MAX, h: 3 }, 10);
        c.panel(5, 5, &["a long line that does not fit".into()], TEXT);
        assert_eq!(px[9 * 10], 1, "the clipped fill reached the bottom-left corner");
    }

    #[test]
    fn shade_darkens_each_channel() {
        let mut px = vec![rgb(200, 100, 50)];
        Canvas { px: &mut px, w: 1, h: 1 }.shade(Rect { x: 0, y: 0, w: 1, h: 1 }, 128);
        assert_eq!(px[0], rgb(100, 50, 25));
    }

    #[test]
    fn layout_hits_buttons_slider_and_view() {
        let l = Layout::new([512, 512], &labels());
        assert_eq!(l.buttons.len(), 4);
        for (i, b) in l.buttons.iter().enumerate() {
            assert_eq!(l.hit(b.x as f64 + 2.0, b.y as f64 + 2.0), Hit::Tissue(i));
            assert!(b.x + b.w <= 512 && b.y + b.h <= 512);
        }
        let s = l.slider;
        assert_eq!(l.hit(s.x as f64, s.y as f64 + 5.0), Hit::Slider(0.0));
        assert_eq!(l.hit((s.x + s.w - 1) as f64, s.y as f64 + 5.0), Hit::Slider(1.0));
        assert_eq!(l.hit(256.0, 200.0), Hit::View);
        assert!(l.describe().starts_with("layout size=512x512 button0="));
    }

    #[test]
    fn tiny_windows_still_have_a_layout() {
        let l = Layout::new([1, 1], &labels());
        assert!(l.slider.w >= 8);
        let mut px = vec![0u32; 1];
        let mut c = Canvas { px: &mut px, w: 1, h: 1 };
        draw_controls(&mut c, &l, &Controls { labels: &labels(), current: Some(0), slider: 0.5, value: 1.0, help: "help" });
    }
}
