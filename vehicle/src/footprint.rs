//! The vehicle body's outline in the vehicle frame (x forward, y left,
//! origin under the middle of the rear axle): a rectangle (the HMMWV's,
//! `[vehicle] footprint = "rectangle"`), a circle, or any simple polygon,
//! convex or not (004 checks "a footprint of the robot's own shape").
//!
//! A rectangle keeps its own exact arithmetic (its edges are axis lines).
//! A circle is kept as the polygon of [`CIRCLE_SIDES`] sides drawn round
//! it (each side touches the circle: the polygon holds the circle and is
//! at most `1/cos(π/32) − 1` = 0.48 % wider), so that every check that
//! sweeps, grows, mirrors or clips the body does it for one kind of
//! outline.

use nalgebra::{Point2, Vector2};

use crate::numbers::{crossing_number_inside, segment_distance, segments_cross};

/// Sides of the polygon that stands for a circle.
pub const CIRCLE_SIDES: usize = 32;
/// Vertices a user's polygon may have.
pub const MAX_POLYGON_VERTICES: usize = 24;
/// Vertices an outline may have once grown and clipped (each clip by a
/// line adds at most one vertex per edge crossing it).
const MAX_VERTICES: usize = 64;

/// Why a set of vertices is not a body's outline.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum FootprintError {
    #[error("has {0} vertices; an outline needs 3 to {MAX_POLYGON_VERTICES}")]
    VertexCount(usize),
    #[error("vertex {0} is not a finite point")]
    NotFinite(usize),
    #[error("vertices {0} and {1} are the same point")]
    Repeated(usize, usize),
    #[error("edges {0} and {1} cross: the outline must not cross itself")]
    SelfCrossing(usize, usize),
    #[error("encloses no area")]
    NoArea,
    #[error("radius {0} m is not a positive length")]
    Radius(f64),
}

/// The vertices of an outline, counter-clockwise; a slice of points.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outline {
    len: usize,
    points: [Point2<f64>; MAX_VERTICES],
}

impl Outline {
    fn new() -> Self {
        Self {
            len: 0,
            points: [Point2::origin(); MAX_VERTICES],
        }
    }

    /// Appends `p` (dropping a point that repeats the last one).
    fn push(&mut self, p: Point2<f64>) {
        if self.len > 0 && self.points[self.len - 1] == p {
            return;
        }
        if self.len < MAX_VERTICES {
            self.points[self.len] = p;
            self.len += 1;
        }
    }

    fn from_points(points: impl IntoIterator<Item = Point2<f64>>) -> Self {
        let mut outline = Self::new();
        for p in points {
            outline.push(p);
        }
        if outline.len > 1 && outline.points[0] == outline.points[outline.len - 1] {
            outline.len -= 1;
        }
        outline
    }

    /// The outline with each vertex moved by `f` (placed in another frame).
    #[must_use]
    pub fn map(&self, f: impl Fn(Point2<f64>) -> Point2<f64>) -> Self {
        let mut moved = *self;
        for p in &mut moved.points[..self.len] {
            *p = f(*p);
        }
        moved
    }

    /// The edges, each from a vertex to the next.
    pub fn edges(&self) -> impl Iterator<Item = (Point2<f64>, Point2<f64>)> + '_ {
        let n = self.len;
        (0..n).map(move |i| (self.points[i], self.points[(i + 1) % n]))
    }
}

impl std::ops::Deref for Outline {
    type Target = [Point2<f64>];
    fn deref(&self) -> &[Point2<f64>] {
        &self.points[..self.len]
    }
}

/// The vehicle body in the vehicle frame. `x_min`, `x_max` and
/// `half_width` bound it (rear, front, the farthest side), and are the
/// rectangle itself when it is one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Footprint {
    /// Rearmost point, m (negative: behind the rear axle).
    pub x_min: f64,
    /// Frontmost point, m.
    pub x_max: f64,
    /// Farthest point from the centre line, m.
    pub half_width: f64,
    /// The outline when it is not the bounding rectangle.
    polygon: Option<Outline>,
}

impl Footprint {
    /// The rectangle `x_min ≤ x ≤ x_max`, `|y| ≤ half_width`.
    pub const fn rectangle(x_min: f64, x_max: f64, half_width: f64) -> Self {
        Self {
            x_min,
            x_max,
            half_width,
            polygon: None,
        }
    }

    /// The circle of `radius` about `centre`, as the polygon of
    /// [`CIRCLE_SIDES`] sides drawn round it.
    pub fn circle(centre: Point2<f64>, radius: f64) -> Result<Self, FootprintError> {
        if !(radius.is_finite() && radius > 0.0) {
            return Err(FootprintError::Radius(radius));
        }
        if !(centre.x.is_finite() && centre.y.is_finite()) {
            return Err(FootprintError::NotFinite(0));
        }
        let step = std::f64::consts::TAU / CIRCLE_SIDES as f64;
        let corner = radius / (step / 2.0).cos();
        let outline = Outline::from_points((0..CIRCLE_SIDES).map(|k| {
            let (sin, cos) = (k as f64 * step).sin_cos();
            Point2::new(centre.x + corner * cos, centre.y + corner * sin)
        }));
        Ok(Self::of_outline(outline))
    }

    /// The simple polygon through `vertices` (either way round; convex or
    /// not; it need not hold the origin).
    pub fn polygon(vertices: &[Point2<f64>]) -> Result<Self, FootprintError> {
        let n = vertices.len();
        if !(3..=MAX_POLYGON_VERTICES).contains(&n) {
            return Err(FootprintError::VertexCount(n));
        }
        if let Some(i) = vertices
            .iter()
            .position(|p| !(p.x.is_finite() && p.y.is_finite()))
        {
            return Err(FootprintError::NotFinite(i));
        }
        for i in 0..n {
            for j in i + 1..n {
                if vertices[i] == vertices[j] {
                    return Err(FootprintError::Repeated(i, j));
                }
            }
        }
        let edge = |i: usize| (vertices[i], vertices[(i + 1) % n]);
        for i in 0..n {
            for j in i + 1..n {
                let adjacent = j == i + 1 || (i == 0 && j == n - 1);
                let ((a, b), (c, d)) = (edge(i), edge(j));
                if !adjacent && segments_meet(a, b, c, d) {
                    return Err(FootprintError::SelfCrossing(i, j));
                }
                // Adjacent edges meet at their shared vertex only: one
                // folding back along the other overlaps it.
                if adjacent && folds_back(a, b, c, d) {
                    return Err(FootprintError::SelfCrossing(i, j));
                }
            }
        }
        let area = signed_area(vertices);
        if area.abs() < 1e-9 {
            return Err(FootprintError::NoArea);
        }
        let outline = if area > 0.0 {
            Outline::from_points(vertices.iter().copied())
        } else {
            Outline::from_points(vertices.iter().rev().copied())
        };
        Ok(Self::of_outline(outline))
    }

    fn of_outline(outline: Outline) -> Self {
        let (mut x_min, mut x_max, mut half_width) = (f64::INFINITY, f64::NEG_INFINITY, 0.0f64);
        for p in outline.iter() {
            x_min = x_min.min(p.x);
            x_max = x_max.max(p.x);
            half_width = half_width.max(p.y.abs());
        }
        Self {
            x_min,
            x_max,
            half_width,
            polygon: Some(outline),
        }
    }

    /// Whether the body is the rectangle of its bounds.
    pub fn is_rectangle(&self) -> bool {
        self.polygon.is_none()
    }

    /// The outline's vertices, counter-clockwise (a rectangle's from its
    /// rear right corner).
    pub fn outline(&self) -> Outline {
        match &self.polygon {
            Some(outline) => *outline,
            None => Outline::from_points([
                Point2::new(self.x_min, -self.half_width),
                Point2::new(self.x_max, -self.half_width),
                Point2::new(self.x_max, self.half_width),
                Point2::new(self.x_min, self.half_width),
            ]),
        }
    }

    /// The farthest point of the body from the vehicle origin, m.
    pub fn reach(&self) -> f64 {
        match &self.polygon {
            Some(outline) => outline.iter().map(|p| p.coords.norm()).fold(0.0, f64::max),
            None => self.x_max.max(-self.x_min).hypot(self.half_width),
        }
    }

    /// True when `p` (vehicle frame) lies inside or on the outline.
    pub fn contains(&self, p: Point2<f64>) -> bool {
        match &self.polygon {
            None => (self.x_min..=self.x_max).contains(&p.x) && p.y.abs() <= self.half_width,
            Some(outline) => {
                if p.x < self.x_min || p.x > self.x_max || p.y.abs() > self.half_width {
                    return false;
                }
                outline
                    .edges()
                    .any(|(a, b)| point_segment_distance(p, a, b) <= 1e-12)
                    || crossing_number_inside(outline.edges().map(|(a, b)| (xy(a), xy(b))), xy(p))
            }
        }
    }

    /// How far inside the outline `p` lies (its distance to the nearest
    /// edge; negative outside a rectangle, 0 or less outside a polygon).
    pub fn depth(&self, p: Point2<f64>) -> f64 {
        match &self.polygon {
            None => (self.x_max - p.x)
                .min(p.x - self.x_min)
                .min(self.half_width - p.y.abs()),
            Some(outline) => {
                let nearest = outline
                    .edges()
                    .map(|(a, b)| point_segment_distance(p, a, b))
                    .fold(f64::INFINITY, f64::min);
                if self.contains(p) { nearest } else { -nearest }
            }
        }
    }

    /// Distance from the segment a–b to the body (0 where they meet).
    pub fn distance_to_segment(&self, a: Point2<f64>, b: Point2<f64>) -> f64 {
        if self.contains(a) || self.contains(b) {
            return 0.0;
        }
        let outline = self.outline();
        let mut best = f64::INFINITY;
        for (c, d) in outline.edges() {
            if segments_meet(a, b, c, d) {
                return 0.0;
            }
            best = best
                .min(point_segment_distance(c, a, b))
                .min(point_segment_distance(a, c, d))
                .min(point_segment_distance(b, c, d));
        }
        best
    }

    /// The same body widened by `margin_m` at its sides (near-miss bands
    /// run beside the body; its front and rear stay where they are):
    /// [`Footprint::grown`] by `margin_m` at the sides only.
    #[must_use]
    pub fn widened(&self, margin_m: f64) -> Self {
        self.grown(0.0, 0.0, margin_m)
    }

    /// The body grown by `ahead` at the front, `behind` at the rear and
    /// `sides` at the sides. Any outline but a rectangle is grown all
    /// round by the largest of them and cut back to its own span along x
    /// grown by `ahead` and `behind`.
    #[must_use]
    pub fn grown(&self, ahead: f64, behind: f64, sides: f64) -> Self {
        match &self.polygon {
            None => Self::rectangle(
                self.x_min - behind,
                self.x_max + ahead,
                self.half_width + sides,
            ),
            Some(outline) => {
                let grown = offset(outline, ahead.max(behind).max(sides));
                Self::of_outline(clip_x(&grown, self.x_min - behind, self.x_max + ahead))
            }
        }
    }

    /// The body mirrored front to back (x → −x): the body as backing up
    /// sees it.
    #[must_use]
    pub fn mirrored(&self) -> Self {
        match &self.polygon {
            None => Self::rectangle(-self.x_max, -self.x_min, self.half_width),
            Some(outline) => Self::of_outline(Outline::from_points(
                outline.iter().rev().map(|p| Point2::new(-p.x, p.y)),
            )),
        }
    }

    /// The part of the body from `x_lo` to `x_hi` along x (none: an
    /// outline of no area, which contains only points on its line).
    #[must_use]
    pub fn clipped(&self, x_lo: f64, x_hi: f64) -> Self {
        match &self.polygon {
            None => Self::rectangle(self.x_min.max(x_lo), self.x_max.min(x_hi), self.half_width),
            Some(outline) => Self::of_outline(clip_x(outline, x_lo, x_hi)),
        }
    }
}

/// The signed area of a polygon (positive counter-clockwise).
fn signed_area(points: &[Point2<f64>]) -> f64 {
    let n = points.len();
    (0..n)
        .map(|i| {
            let (a, b) = (points[i], points[(i + 1) % n]);
            a.x * b.y - b.x * a.y
        })
        .sum::<f64>()
        / 2.0
}

fn cross(u: Vector2<f64>, v: Vector2<f64>) -> f64 {
    u.x * v.y - u.y * v.x
}

fn xy(p: Point2<f64>) -> [f64; 2] {
    [p.x, p.y]
}

/// Distance from `p` to the segment a–b.
fn point_segment_distance(p: Point2<f64>, a: Point2<f64>, b: Point2<f64>) -> f64 {
    segment_distance(xy(p), xy(a), xy(b))
}

/// Whether the segments a–b and c–d have a point in common (crossing, or
/// an end of one on the other).
fn segments_meet(a: Point2<f64>, b: Point2<f64>, c: Point2<f64>, d: Point2<f64>) -> bool {
    let on =
        |p: Point2<f64>, q: Point2<f64>, r: Point2<f64>| point_segment_distance(r, p, q) <= 1e-12;
    segments_cross(xy(a), xy(b), xy(c), xy(d))
        || on(a, b, c)
        || on(a, b, d)
        || on(c, d, a)
        || on(c, d, b)
}

/// Whether of two edges sharing a vertex one runs back along the other.
fn folds_back(a: Point2<f64>, b: Point2<f64>, c: Point2<f64>, d: Point2<f64>) -> bool {
    // The shared vertex and the two far ends.
    let (shared, u, v) = if b == c {
        (b, a, d)
    } else if d == a {
        (a, b, c)
    } else {
        return false;
    };
    let (eu, ev) = (u - shared, v - shared);
    cross(eu, ev).abs() <= 1e-12 * eu.norm() * ev.norm() && eu.dot(&ev) > 0.0
}

/// The outline grown outwards by `m` (its edges moved out by `m`, each
/// vertex where its two moved edges meet; at a corner sharper than a
/// right angle, the corner is cut square `m` beyond the edges' ends so
/// that everything within `m` of the outline stays inside).
fn offset(outline: &Outline, m: f64) -> Outline {
    let n = outline.len;
    let mut grown = Outline::new();
    if m == 0.0 {
        return *outline;
    }
    for i in 0..n {
        let (prev, here, next) = (
            outline.points[(i + n - 1) % n],
            outline.points[i],
            outline.points[(i + 1) % n],
        );
        let (d1, d2) = ((here - prev).normalize(), (next - here).normalize());
        // Outward normals of a counter-clockwise outline: to the right.
        let (n1, n2) = (Vector2::new(d1.y, -d1.x), Vector2::new(d2.y, -d2.x));
        let convex = cross(d1, d2) > 0.0;
        let bend = 1.0 + n1.dot(&n2);
        if convex && n1.dot(&n2) < 0.0 {
            grown.push(here + (n1 + d1) * m);
            grown.push(here + (n2 - d2) * m);
        } else if bend > 1e-9 {
            grown.push(here + (n1 + n2) * (m / bend));
        } else {
            grown.push(here + n1 * m);
            grown.push(here + n2 * m);
        }
    }
    grown
}

/// The part of the outline with `lo ≤ x ≤ hi` (Sutherland–Hodgman, one
/// line at a time).
fn clip_x(outline: &Outline, lo: f64, hi: f64) -> Outline {
    let keep_lo = |p: &Point2<f64>| p.x >= lo;
    let keep_hi = |p: &Point2<f64>| p.x <= hi;
    let once = clip_by(outline, lo, &keep_lo);
    clip_by(&once, hi, &keep_hi)
}

fn clip_by(outline: &Outline, x: f64, keep: &dyn Fn(&Point2<f64>) -> bool) -> Outline {
    let mut out = Outline::new();
    let n = outline.len;
    for i in 0..n {
        let (a, b) = (outline.points[i], outline.points[(i + 1) % n]);
        let crossing = || {
            let t = (x - a.x) / (b.x - a.x);
            Point2::new(x, a.y + t * (b.y - a.y))
        };
        match (keep(&a), keep(&b)) {
            (true, true) => out.push(b),
            (true, false) => out.push(crossing()),
            (false, true) => {
                out.push(crossing());
                out.push(b);
            }
            (false, false) => {}
        }
    }
    if out.len > 1 && out.points[0] == out.points[out.len - 1] {
        out.len -= 1;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(x: f64, y: f64) -> Point2<f64> {
        Point2::new(x, y)
    }

    /// An L: 3 m long, 2 m wide at the rear, 1 m wide (the left half)
    /// for its front 1.5 m.
    fn ell() -> Footprint {
        Footprint::polygon(&[
            p(0.0, -1.0),
            p(1.5, -1.0),
            p(1.5, 0.0),
            p(3.0, 0.0),
            p(3.0, 1.0),
            p(0.0, 1.0),
        ])
        .unwrap()
    }

    #[test]
    fn a_rectangle_contains_what_lies_within_its_bounds() {
        let f = Footprint::rectangle(-0.6, 4.0, 1.1);
        assert!(f.contains(p(0.0, 0.0)) && f.contains(p(4.0, 1.1)));
        assert!(!f.contains(p(4.1, 0.0)) && !f.contains(p(1.0, 1.2)));
        assert_eq!(f.outline().len(), 4);
        assert!((f.reach() - 4.0f64.hypot(1.1)).abs() < 1e-12);
        assert!((f.depth(p(0.0, 0.0)) - 0.6).abs() < 1e-12);
    }

    #[test]
    fn an_l_shaped_polygon_holds_its_arms_and_not_its_notch() {
        let f = ell();
        assert_eq!((f.x_min, f.x_max, f.half_width), (0.0, 3.0, 1.0));
        assert!(f.contains(p(2.5, 0.5)), "the front arm");
        assert!(f.contains(p(0.5, -0.5)), "the rear");
        assert!(!f.contains(p(2.5, -0.5)), "the notch");
        assert!(f.contains(p(1.5, -0.5)), "on the notch's edge");
        assert!((f.depth(p(2.5, 0.5)) - 0.5).abs() < 1e-12);
        assert!(f.depth(p(2.5, -0.5)) < 0.0);
        // Given clockwise, the same outline.
        let mut cw: Vec<_> = ell().outline().to_vec();
        cw.reverse();
        let g = Footprint::polygon(&cw).unwrap();
        for q in [p(2.5, 0.5), p(2.5, -0.5), p(0.5, -0.9)] {
            assert_eq!(f.contains(q), g.contains(q));
        }
    }

    #[test]
    fn a_circle_is_held_by_its_polygon_and_barely_wider() {
        let f = Footprint::circle(p(0.5, 0.0), 0.6).unwrap();
        for k in 0..360 {
            let (s, c) = f64::from(k).to_radians().sin_cos();
            assert!(
                f.contains(p(0.5 + 0.6 * c, 0.6 * s)),
                "on the circle at {k}°"
            );
            assert!(
                !f.contains(p(0.5 + 0.61 * c, 0.61 * s)),
                "beyond it at {k}°"
            );
        }
        assert!((f.half_width - 0.6).abs() < 0.003);
    }

    #[test]
    fn outlines_that_are_no_body_are_refused() {
        let bow_tie = [p(0.0, 0.0), p(1.0, 1.0), p(1.0, 0.0), p(0.0, 1.0)];
        assert!(matches!(
            Footprint::polygon(&bow_tie),
            Err(FootprintError::SelfCrossing(..))
        ));
        assert_eq!(
            Footprint::polygon(&[p(0.0, 0.0), p(1.0, 0.0)]),
            Err(FootprintError::VertexCount(2))
        );
        assert_eq!(
            Footprint::polygon(&[p(0.0, 0.0), p(1.0, 0.0), p(2.0, 0.0)]),
            Err(FootprintError::SelfCrossing(0, 2))
        );
        assert_eq!(
            Footprint::polygon(&[p(0.0, 0.0), p(1.0, 0.0), p(0.0, 0.0), p(0.0, 1.0)]),
            Err(FootprintError::Repeated(0, 2))
        );
        assert_eq!(
            Footprint::polygon(&[p(0.0, 0.0), p(f64::NAN, 0.0), p(0.0, 1.0)]),
            Err(FootprintError::NotFinite(1))
        );
        assert_eq!(
            Footprint::circle(p(0.0, 0.0), 0.0),
            Err(FootprintError::Radius(0.0))
        );
    }

    #[test]
    fn widening_keeps_everything_within_the_margin_beside_the_body_and_little_more() {
        for f in [ell(), Footprint::circle(p(0.3, 0.1), 0.7).unwrap()] {
            let g = f.widened(0.25);
            assert_eq!(
                (g.x_min, g.x_max),
                (f.x_min, f.x_max),
                "front and rear stay"
            );
            // Points on a fine grid within the body's span along x: within
            // 0.25 of the body → inside; beyond the span → outside.
            for i in -20..=40 {
                for j in -20..=20 {
                    let q = p(f64::from(i) * 0.1 + 0.05, f64::from(j) * 0.1);
                    let gap = f.distance_to_segment(q, q);
                    let beside = (f.x_min..=f.x_max).contains(&q.x);
                    if beside && gap <= 0.25 - 1e-9 {
                        assert!(g.contains(q), "{q:?} is {gap} m from the body");
                    }
                    if !beside || gap > 0.25 * std::f64::consts::SQRT_2 + 1e-9 {
                        assert!(!g.contains(q), "{q:?} is {gap} m from the body");
                    }
                }
            }
        }
    }

    #[test]
    fn grown_mirrored_and_clipped_outlines() {
        let r = Footprint::rectangle(-0.6, 4.0, 1.1);
        assert_eq!(
            r.grown(0.1, 0.0, 0.1),
            Footprint::rectangle(-0.6, 4.0 + 0.1, 1.1 + 0.1)
        );
        assert_eq!(r.mirrored(), Footprint::rectangle(-4.0, 0.6, 1.1));
        assert_eq!(r.clipped(-1.0, 3.3), Footprint::rectangle(-0.6, 3.3, 1.1));
        let f = ell();
        let g = f.grown(0.1, 0.0, 0.1);
        assert_eq!((g.x_min, g.x_max), (0.0, 3.1));
        assert!((g.half_width - 1.1).abs() < 1e-12);
        assert!(g.contains(p(3.05, 0.5)) && !g.contains(p(-0.05, 0.0)));
        let m = f.mirrored();
        assert!(m.contains(p(-2.5, 0.5)) && !m.contains(p(-2.5, -0.5)));
        let c = f.clipped(0.0, 2.0);
        assert_eq!((c.x_min, c.x_max), (0.0, 2.0));
        assert!(c.contains(p(1.9, 0.5)) && !c.contains(p(1.9, -0.5)));
        assert!(!c.contains(p(2.5, 0.5)));
    }

    #[test]
    fn distances_to_segments() {
        let f = ell();
        assert!((f.distance_to_segment(p(2.5, -0.5), p(2.5, -0.5)) - 0.5).abs() < 1e-12);
        assert_eq!(f.distance_to_segment(p(2.0, -3.0), p(2.0, 3.0)), 0.0);
        assert!((f.distance_to_segment(p(4.0, 2.0), p(5.0, 2.0)) - 2f64.sqrt()).abs() < 1e-12);
    }
}
