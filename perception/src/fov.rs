//! The ground footprint an image actually observed: per column of the image,
//! the nearest and the farthest return on the ground plane; the polygon runs
//! out along the far returns and back along the near ones. The local map
//! uses it to decide which of its cells this image should have seen again
//! (002 §5: the only sensor knowledge Ganesha has).
//!
//! The polygon is built from returns, not from the nominal frustum, so sky,
//! dropouts and the blind zone around a roof-mounted lidar are not claimed
//! as observed. Columns are grouped into buckets to bound the vertex count;
//! each bucket takes its farthest near point and its nearest far point, so
//! simplification only ever shrinks the footprint (a smaller footprint prunes
//! less, never more).

use arcnav_vehicle::Isometry;
use nalgebra::{Point2, Point3};

/// A simple polygon in the world's ground plane (x, y), counter-clockwise.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct FovPolygon {
    pub vertices: Vec<Point2<f64>>,
}

impl FovPolygon {
    pub fn new(vertices: Vec<Point2<f64>>) -> Self {
        Self { vertices }
    }

    /// Fewer than three vertices: covers nothing.
    pub fn is_empty(&self) -> bool {
        self.vertices.len() < 3
    }

    /// Twice the signed area... halved: the signed area, positive when
    /// counter-clockwise.
    pub fn signed_area(&self) -> f64 {
        let n = self.vertices.len();
        (0..n)
            .map(|i| {
                let (a, b) = (self.vertices[i], self.vertices[(i + 1) % n]);
                a.x * b.y - b.x * a.y
            })
            .sum::<f64>()
            / 2.0
    }

    /// Axis-aligned bounds `(min, max)`, `None` when empty.
    pub fn bounds(&self) -> Option<(Point2<f64>, Point2<f64>)> {
        if self.is_empty() {
            return None;
        }
        let mut min = self.vertices[0];
        let mut max = min;
        for v in &self.vertices {
            min = min.inf(v);
            max = max.sup(v);
        }
        Some((min, max))
    }

    /// True when `p` is inside (even-odd rule).
    pub fn contains(&self, p: Point2<f64>) -> bool {
        let n = self.vertices.len();
        if n < 3 {
            return false;
        }
        let mut inside = false;
        let mut j = n - 1;
        for i in 0..n {
            let (a, b) = (self.vertices[i], self.vertices[j]);
            if (a.y > p.y) != (b.y > p.y) && p.x < (b.x - a.x) * (p.y - a.y) / (b.y - a.y) + a.x {
                inside = !inside;
            }
            j = i;
        }
        inside
    }
}

#[derive(Debug, Clone, Copy)]
struct ColumnExtent {
    near_d2: f32,
    near: [f32; 2],
    far_d2: f32,
    far: [f32; 2],
}

impl ColumnExtent {
    const EMPTY: Self = Self {
        near_d2: f32::INFINITY,
        near: [0.0; 2],
        far_d2: -1.0,
        far: [0.0; 2],
    };

    fn seen(&self) -> bool {
        self.far_d2 >= 0.0
    }
}

/// Collects the near and far return of each image column while an
/// evaluator projects the points, then builds the polygon.
#[derive(Debug, Clone, Default)]
pub struct FovBuilder {
    columns: Vec<ColumnExtent>,
    origin: [f32; 2],
    // Scratch of `finish`, kept to allocate nothing per image.
    summary: Vec<Option<(f32, f32, f32)>>,
    near: Vec<Point2<f64>>,
}

impl FovBuilder {
    /// Starts an image of `cols` columns whose sensor stands at `sensor_xy`
    /// (in the frame the points will be given in).
    pub fn start(&mut self, cols: usize, sensor_xy: [f32; 2]) {
        self.columns.clear();
        self.columns.resize(cols, ColumnExtent::EMPTY);
        self.origin = sensor_xy;
    }

    /// A return of column `col` at ground position (x, y).
    #[inline]
    pub fn add(&mut self, col: usize, x: f32, y: f32) {
        let (dx, dy) = (x - self.origin[0], y - self.origin[1]);
        let d2 = dx * dx + dy * dy;
        if let Some(c) = self.columns.get_mut(col) {
            if d2 < c.near_d2 {
                c.near_d2 = d2;
                c.near = [x, y];
            }
            if d2 > c.far_d2 {
                c.far_d2 = d2;
                c.far = [x, y];
            }
        }
    }

    /// Writes the polygon, mapped to the world by `world_from_frame`, with at
    /// most `max_vertices` vertices, into `out`.
    ///
    /// Each bucket of columns becomes two vertices on the ray of its middle
    /// seen column: the far one at the smallest far distance of the bucket
    /// and its two neighbours, the near one at their largest near distance.
    /// Every chord between neighbouring vertices then stays within the
    /// returns of the columns it spans.
    pub fn finish(
        &mut self,
        world_from_frame: &Isometry,
        max_vertices: usize,
        out: &mut FovPolygon,
    ) {
        out.vertices.clear();
        let cols = self.columns.len();
        let buckets = cols.min(max_vertices / 2);
        if buckets == 0 {
            return;
        }
        // Per bucket: (direction of its middle seen column, min far, max near).
        let summary = &mut self.summary;
        summary.clear();
        for b in 0..buckets {
            let columns = &self.columns[(b * cols / buckets)..((b + 1) * cols / buckets)];
            let seen = || columns.iter().filter(|c| c.seen());
            let count = seen().count();
            summary.push(seen().nth(count / 2).map(|middle| {
                let angle = (middle.far[1] - self.origin[1]).atan2(middle.far[0] - self.origin[0]);
                let far = seen()
                    .map(|c| c.far_d2)
                    .fold(f32::INFINITY, f32::min)
                    .sqrt();
                let near = seen().map(|c| c.near_d2).fold(0.0, f32::max).sqrt();
                (angle, far, near)
            }));
        }
        let origin = self.origin;
        let to_world = |angle: f32, radius: f32| {
            let (sin, cos) = angle.sin_cos();
            let x = f64::from(origin[0] + radius * cos);
            let y = f64::from(origin[1] + radius * sin);
            let w = world_from_frame * Point3::new(x, y, 0.0);
            Point2::new(w.x, w.y)
        };
        let near = &mut self.near;
        near.clear();
        for b in 0..buckets {
            let Some((angle, _, _)) = summary[b] else {
                continue;
            };
            let neighbours = [
                b.checked_sub(1),
                Some(b),
                (b + 1 < buckets).then_some(b + 1),
            ];
            let (mut far, mut near_radius) = (f32::INFINITY, 0.0f32);
            for (_, f, n) in neighbours.into_iter().flatten().filter_map(|i| summary[i]) {
                far = far.min(f);
                near_radius = near_radius.max(n);
            }
            if near_radius < far {
                out.vertices.push(to_world(angle, far));
                near.push(to_world(angle, near_radius));
            }
        }
        if out.vertices.len() < 2 {
            out.vertices.clear();
            return;
        }
        out.vertices.extend(near.iter().rev());
        if out.signed_area() < 0.0 {
            out.vertices.reverse();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arcnav_vehicle::frames::planar_isometry;

    fn square() -> FovPolygon {
        FovPolygon::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(2.0, 0.0),
            Point2::new(2.0, 2.0),
            Point2::new(0.0, 2.0),
        ])
    }

    #[test]
    fn point_in_polygon() {
        let s = square();
        assert!(s.contains(Point2::new(1.0, 1.0)));
        assert!(!s.contains(Point2::new(3.0, 1.0)));
        assert!(!s.contains(Point2::new(1.0, -0.1)));
        assert_eq!(s.signed_area(), 4.0);
        assert!(!FovPolygon::default().contains(Point2::new(0.0, 0.0)));
    }

    #[test]
    fn a_wedge_of_returns_gives_an_annular_sector_in_the_world() {
        let mut builder = FovBuilder::default();
        builder.start(3, [0.0, 0.0]);
        // Three columns looking left, ahead, right; returns 5..20 m.
        for (col, angle) in [(0usize, 0.5f32), (1, 0.0), (2, -0.5)] {
            for d in [5.0f32, 12.0, 20.0] {
                builder.add(col, d * angle.cos(), d * angle.sin());
            }
        }
        let mut fov = FovPolygon::default();
        // The vehicle stands at (100, 50) heading north.
        builder.finish(
            &planar_isometry(100.0, 50.0, std::f64::consts::FRAC_PI_2),
            64,
            &mut fov,
        );
        assert_eq!(fov.vertices.len(), 6);
        assert!(fov.signed_area() > 0.0, "counter-clockwise");
        // Neighbours limit each other: far radius 20, near radius 5 everywhere.
        assert!(
            fov.contains(Point2::new(100.0, 60.0)),
            "10 m ahead is observed"
        );
        assert!(
            !fov.contains(Point2::new(100.0, 52.0)),
            "2 m ahead is in the blind zone"
        );
        assert!(
            !fov.contains(Point2::new(100.0, 75.0)),
            "25 m ahead is beyond the returns"
        );
        assert!(
            !fov.contains(Point2::new(90.0, 50.0)),
            "beside the vehicle is outside"
        );
    }

    #[test]
    fn simplification_only_shrinks_the_footprint() {
        let mut builder = FovBuilder::default();
        builder.start(100, [0.0, 0.0]);
        for col in 0..100 {
            let angle = 0.5 - col as f32 * 0.01;
            let far = 15.0 + (col % 7) as f32;
            let near = 4.0 + (col % 3) as f32 * 0.5;
            builder.add(col, far * angle.cos(), far * angle.sin());
            builder.add(col, near * angle.cos(), near * angle.sin());
        }
        let (mut full, mut coarse) = (FovPolygon::default(), FovPolygon::default());
        builder.finish(&Isometry::identity(), 200, &mut full);
        // The full-resolution polygon through every column's own returns.
        let mut exact = FovPolygon::default();
        for col in 0..100 {
            let c = builder.columns[col];
            exact
                .vertices
                .push(Point2::new(f64::from(c.far[0]), f64::from(c.far[1])));
        }
        for col in (0..100).rev() {
            let c = builder.columns[col];
            exact
                .vertices
                .push(Point2::new(f64::from(c.near[0]), f64::from(c.near[1])));
        }
        builder.finish(&Isometry::identity(), 16, &mut coarse);
        assert_eq!(coarse.vertices.len(), 16);
        assert!(coarse.signed_area() < exact.signed_area().abs());
        for polygon in [&full, &coarse] {
            for x in 0..100 {
                for y in -60..60 {
                    let p = Point2::new(x as f64 * 0.25, y as f64 * 0.25);
                    assert!(
                        !polygon.contains(p) || exact.contains(p),
                        "{p} is not observed but claimed"
                    );
                }
            }
        }
    }

    #[test]
    fn no_returns_no_footprint() {
        let mut builder = FovBuilder::default();
        builder.start(256, [0.0, 0.0]);
        let mut fov = FovPolygon::default();
        builder.finish(&Isometry::identity(), 128, &mut fov);
        assert!(fov.is_empty());
    }
}
