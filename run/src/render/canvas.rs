//! The drawing kit of the pictures: a canvas with shapes and text, and the
//! colour scales.

use std::path::Path;

use ab_glyph::{Font, FontRef, PxScale, ScaleFont, point};
use tiny_skia::{Color, FillRule, Paint, PathBuilder, Pixmap, Rect, Stroke, Transform};

/// A picture that could not be made.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error("picture of {width}×{height} pixels is not possible")]
    Size { width: u32, height: u32 },
    #[error("cannot write {path}: {reason}")]
    Write { path: String, reason: String },
}

/// RGBA, 0-255.
pub type Rgba = [u8; 4];

pub const WHITE: Rgba = [255, 255, 255, 255];
pub const BLACK: Rgba = [0, 0, 0, 255];
pub const RED: Rgba = [220, 30, 30, 255];
pub const BLUE: Rgba = [30, 80, 220, 255];

fn color(c: Rgba) -> Color {
    Color::from_rgba8(c[0], c[1], c[2], c[3])
}

fn paint(c: Rgba) -> Paint<'static> {
    let mut p = Paint::default();
    p.set_color(color(c));
    p.anti_alias = true;
    p
}

/// Red (-1) through yellow (0) to green (+1).
pub fn vote_color(v: f32) -> Rgba {
    let v = v.clamp(-1.0, 1.0);
    if v < 0.0 {
        let t = v + 1.0;
        [220, (40.0 + 170.0 * t) as u8, 40, 255]
    } else {
        [(220.0 * (1.0 - v)) as u8, (210.0 - 40.0 * v) as u8, 40, 255]
    }
}

/// Blue (slow) through green to red (fast) over [0, max].
pub fn speed_color(speed: f64, max: f64) -> Rgba {
    let t = (speed / max.max(0.1)).clamp(0.0, 1.0);
    let (r, g, b) = if t < 0.5 {
        let u = t * 2.0;
        (20.0, 80.0 + 150.0 * u, 230.0 - 170.0 * u)
    } else {
        let u = (t - 0.5) * 2.0;
        (20.0 + 220.0 * u, 230.0 - 190.0 * u, 60.0 - 40.0 * u)
    };
    [r as u8, g as u8, b as u8, 255]
}

/// A canvas with a text renderer.
pub struct Canvas {
    pub pixmap: Pixmap,
    font: FontRef<'static>,
}

impl Canvas {
    pub fn new(width: u32, height: u32, background: Rgba) -> Result<Self, RenderError> {
        let mut pixmap = Pixmap::new(width, height).ok_or(RenderError::Size { width, height })?;
        pixmap.fill(color(background));
        // The DejaVu font is compiled in; it always parses.
        let font =
            FontRef::try_from_slice(dejavu::sans::regular()).map_err(|_| RenderError::Size {
                width: 0,
                height: 0,
            })?;
        Ok(Self { pixmap, font })
    }

    pub fn width(&self) -> f32 {
        self.pixmap.width() as f32
    }

    pub fn height(&self) -> f32 {
        self.pixmap.height() as f32
    }

    pub fn fill_rect(&mut self, x: f32, y: f32, w: f32, h: f32, c: Rgba) {
        // A side under two pixels is snapped to whole pixels, at least one:
        // tiny-skia's anti-aliased fill trips a debug assertion on a rect
        // whose two edges fall in one pixel at fractional positions.
        let snap = |start: f32, size: f32| {
            if size < 2.0 {
                let a = start.round();
                (a, ((start + size).round() - a).max(1.0))
            } else {
                (start, size)
            }
        };
        let ((x, w), (y, h)) = (snap(x, w), snap(y, h));
        if let Some(rect) = Rect::from_xywh(x, y, w, h) {
            self.pixmap
                .fill_rect(rect, &paint(c), Transform::identity(), None);
        }
    }

    pub fn circle(
        &mut self,
        x: f32,
        y: f32,
        r: f32,
        fill: Option<Rgba>,
        outline: Option<(Rgba, f32)>,
    ) {
        let Some(path) = PathBuilder::from_circle(x, y, r.max(0.5)) else {
            return;
        };
        self.fill_and_outline(&path, fill, FillRule::Winding, outline);
    }

    /// Fills `path` (by `rule`) and strokes its outline, either optional.
    fn fill_and_outline(
        &mut self,
        path: &tiny_skia::Path,
        fill: Option<Rgba>,
        rule: FillRule,
        outline: Option<(Rgba, f32)>,
    ) {
        if let Some(c) = fill {
            self.pixmap
                .fill_path(path, &paint(c), rule, Transform::identity(), None);
        }
        if let Some((c, width)) = outline {
            let stroke = Stroke {
                width,
                ..Stroke::default()
            };
            self.pixmap
                .stroke_path(path, &paint(c), &stroke, Transform::identity(), None);
        }
    }

    pub fn polyline(&mut self, points: &[(f32, f32)], c: Rgba, width: f32, dashed: bool) {
        let length: f32 = points
            .windows(2)
            .map(|w| (w[1].0 - w[0].0).hypot(w[1].1 - w[0].1))
            .sum();
        if points.len() < 2 || length < 1e-3 {
            return;
        }
        let pb = through(points);
        let Some(path) = pb.finish() else { return };
        let mut stroke = Stroke {
            width,
            ..Stroke::default()
        };
        if dashed {
            stroke.dash = tiny_skia::StrokeDash::new(vec![4.0, 4.0], 0.0);
        }
        self.pixmap
            .stroke_path(&path, &paint(c), &stroke, Transform::identity(), None);
    }

    pub fn polygon(
        &mut self,
        points: &[(f32, f32)],
        fill: Option<Rgba>,
        outline: Option<(Rgba, f32)>,
    ) {
        if points.len() < 3 {
            return;
        }
        let mut pb = through(points);
        pb.close();
        let Some(path) = pb.finish() else { return };
        self.fill_and_outline(&path, fill, FillRule::EvenOdd, outline);
    }

    /// Text with its baseline at (x, y); returns the width drawn.
    pub fn text(&mut self, x: f32, y: f32, size: f32, c: Rgba, text: &str) -> f32 {
        let scale = PxScale::from(size);
        let font = self.font.as_scaled(scale);
        let mut caret = x;
        let (w, h) = (self.pixmap.width() as i32, self.pixmap.height() as i32);
        let pixels = self.pixmap.pixels_mut();
        for ch in text.chars() {
            let id = font.glyph_id(ch);
            let advance = font.h_advance(id);
            let glyph = id.with_scale_and_position(scale, point(caret, y));
            if let Some(outlined) = self.font.outline_glyph(glyph) {
                let bounds = outlined.px_bounds();
                outlined.draw(|gx, gy, coverage| {
                    let (px, py) = (
                        bounds.min.x as i32 + gx as i32,
                        bounds.min.y as i32 + gy as i32,
                    );
                    if px < 0 || py < 0 || px >= w || py >= h {
                        return;
                    }
                    let pixel = &mut pixels[(py * w + px) as usize];
                    let a = coverage.clamp(0.0, 1.0) * f32::from(c[3]) / 255.0;
                    let blend = |under: u8, over: u8| {
                        (f32::from(under) * (1.0 - a) + f32::from(over) * a) as u8
                    };
                    if let Some(mixed) = tiny_skia::PremultipliedColorU8::from_rgba(
                        blend(pixel.red(), c[0]),
                        blend(pixel.green(), c[1]),
                        blend(pixel.blue(), c[2]),
                        255,
                    ) {
                        *pixel = mixed;
                    }
                });
            }
            caret += advance;
        }
        caret - x
    }

    /// Text on a light box for legibility over a picture.
    pub fn label(&mut self, x: f32, y: f32, size: f32, c: Rgba, text: &str) {
        let width = text.chars().count() as f32 * size * 0.6;
        self.fill_rect(
            x - 3.0,
            y - size,
            width + 6.0,
            size * 1.35,
            [255, 255, 255, 200],
        );
        self.text(x, y, size, c, text);
    }

    /// Writes the PNG (in full or not at all: see [`crate::output`]).
    pub fn save(&self, path: &Path) -> Result<(), RenderError> {
        let failed = |reason: String| RenderError::Write {
            path: path.display().to_string(),
            reason,
        };
        let png = self
            .pixmap
            .encode_png()
            .map_err(|e| failed(e.to_string()))?;
        crate::output::write_file(path, &png).map_err(|e| failed(e.to_string()))
    }
}

/// A path from the first of `points` (at least one) through the others.
fn through(points: &[(f32, f32)]) -> PathBuilder {
    let mut pb = PathBuilder::new();
    pb.move_to(points[0].0, points[0].1);
    for p in &points[1..] {
        pb.line_to(p.0, p.1);
    }
    pb
}
