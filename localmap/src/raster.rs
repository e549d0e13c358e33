//! A field-of-view polygon on the patch grid: which patches have their
//! centre inside it. Built once per image by walking the polygon's edges and
//! recording, for every patch row, where the row's centre line crosses them;
//! a lookup then scans the two to four crossings of one row. Work is
//! proportional to the edges and rows, not to the area covered.

use arcnav_perception::FovPolygon;

/// Crossings of patch-row centre lines with a polygon, over its bounding box.
#[derive(Debug, Default, Clone)]
pub struct Coverage {
    /// Row of the box's first patch.
    j0: i64,
    rows: usize,
    patch_size: f64,
    /// Row r's crossings are `crossings[row_start[r]..row_start[r + 1]]`, sorted.
    row_start: Vec<u32>,
    crossings: Vec<f64>,
    fill: Vec<u32>,
}

impl Coverage {
    /// Prepares lookups of `polygon` for patches of `patch_size` (patch (i, j)
    /// spans [i·s, (i+1)·s) × [j·s, (j+1)·s) in the world), in patch rows
    /// `rows` only (the rows the map has patches in): the work and memory
    /// are bounded by those rows, however far the polygon reaches.
    pub fn rasterise(&mut self, polygon: &FovPolygon, patch_size: f64, rows: (i64, i64)) {
        self.rows = 0;
        self.patch_size = patch_size;
        let Some((min, max)) = polygon.bounds() else {
            return;
        };
        // Saturating casts: a vertex at 1e15 m gives a row far outside `rows`.
        let row_of = |y: f64| ((y / patch_size - 0.5).ceil() as i64).clamp(rows.0, rows.1 + 1);
        self.j0 = row_of(min.y);
        self.rows = (row_of(max.y).min(rows.1) - self.j0 + 1).max(0) as usize;
        // Rows whose centre line y = (j + 0.5)·s an edge crosses (half-open
        // in y), within `rows`.
        let span = |a: f64, b: f64| {
            let (lo, hi) = if a <= b { (a, b) } else { (b, a) };
            (row_of(lo), row_of(hi).min(rows.1 + 1))
        };
        let vertices = &polygon.vertices;
        let edges =
            || (0..vertices.len()).map(|k| (vertices[k], vertices[(k + 1) % vertices.len()]));
        self.row_start.clear();
        self.row_start.resize(self.rows + 1, 0);
        for (a, b) in edges() {
            let (first, end) = span(a.y, b.y);
            for j in first..end {
                self.row_start[(j - self.j0) as usize + 1] += 1;
            }
        }
        for r in 0..self.rows {
            self.row_start[r + 1] += self.row_start[r];
        }
        self.crossings.clear();
        self.crossings
            .resize(self.row_start[self.rows] as usize, 0.0);
        self.fill.clear();
        self.fill.extend_from_slice(&self.row_start[..self.rows]);
        for (a, b) in edges() {
            let (first, end) = span(a.y, b.y);
            for j in first..end {
                let y = (j as f64 + 0.5) * patch_size;
                let r = (j - self.j0) as usize;
                self.crossings[self.fill[r] as usize] = a.x + (y - a.y) * (b.x - a.x) / (b.y - a.y);
                self.fill[r] += 1;
            }
        }
        for r in 0..self.rows {
            let (start, end) = (self.row_start[r] as usize, self.row_start[r + 1] as usize);
            self.crossings[start..end].sort_by(f64::total_cmp);
        }
    }

    /// True when the centre of patch (i, j) lies inside the polygon (even-odd).
    pub fn covers(&self, i: i64, j: i64) -> bool {
        let r = j - self.j0;
        if r < 0 || r as usize >= self.rows {
            return false;
        }
        let r = r as usize;
        let x = (i as f64 + 0.5) * self.patch_size;
        let row = &self.crossings[self.row_start[r] as usize..self.row_start[r + 1] as usize];
        row.iter().take_while(|&&c| c <= x).count() % 2 == 1
    }

    /// Calls `visit(i, j)` for every patch whose centre lies inside, with
    /// `i` within `columns` (inclusive).
    pub fn for_each_covered(&self, columns: (i64, i64), mut visit: impl FnMut(i64, i64)) {
        for r in 0..self.rows {
            let row = &self.crossings[self.row_start[r] as usize..self.row_start[r + 1] as usize];
            let j = self.j0 + r as i64;
            for pair in row.chunks_exact(2) {
                // Centres (i + 0.5)·s in [pair[0], pair[1]).
                let first = (pair[0] / self.patch_size - 0.5).ceil();
                let end = (pair[1] / self.patch_size - 0.5).ceil();
                let first = (first.max(columns.0 as f64)) as i64;
                let end = (end.min(columns.1 as f64 + 1.0)) as i64;
                for i in first..end {
                    visit(i, j);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Point2;

    #[test]
    fn coverage_agrees_with_point_in_polygon_at_patch_centres() {
        let polygon = FovPolygon::new(vec![
            Point2::new(1.0, -3.0),
            Point2::new(14.3, -7.1),
            Point2::new(19.0, 0.2),
            Point2::new(12.5, 8.9),
            Point2::new(6.0, 2.0),
            Point2::new(1.2, 3.3),
        ]);
        let mut coverage = Coverage::default();
        coverage.rasterise(&polygon, 0.4, (-1000, 1000));
        let mut inside = 0;
        for i in -10..60 {
            for j in -30..30 {
                let centre = Point2::new((i as f64 + 0.5) * 0.4, (j as f64 + 0.5) * 0.4);
                assert_eq!(
                    coverage.covers(i, j),
                    polygon.contains(centre),
                    "patch ({i}, {j})"
                );
                inside += usize::from(coverage.covers(i, j));
            }
        }
        assert!(inside > 500);
        let mut visited = 0;
        coverage.for_each_covered((-10, 59), |i, j| {
            assert!(coverage.covers(i, j), "({i}, {j})");
            visited += 1;
        });
        assert_eq!(visited, inside, "every covered patch is visited once");
    }

    #[test]
    fn a_polygon_reaching_far_beyond_the_rows_asked_for_costs_only_those_rows() {
        // 40 000 km across: the whole raster would be 10^11 rows.
        let polygon = FovPolygon::new(vec![
            Point2::new(-2e7, -2e7),
            Point2::new(2e7, -2e7),
            Point2::new(2e7, 2e7),
            Point2::new(-2e7, 2e7),
        ]);
        let mut coverage = Coverage::default();
        coverage.rasterise(&polygon, 0.4, (-50, 50));
        assert!(
            coverage.crossings.len() <= 2 * 101,
            "{}",
            coverage.crossings.len()
        );
        assert!(coverage.covers(0, 0) && coverage.covers(1000, -50) && coverage.covers(-7, 50));
        assert!(
            !coverage.covers(0, 51),
            "rows not asked for are not covered"
        );
        // Rows asked for outside the polygon: nothing covered.
        let small = FovPolygon::new(vec![
            Point2::new(0.0, 0.0),
            Point2::new(4.0, 0.0),
            Point2::new(4.0, 4.0),
        ]);
        coverage.rasterise(&small, 0.4, (100, 200));
        assert!((100..=200).all(|j| !coverage.covers(1, j)));
        coverage.rasterise(&small, 0.4, (-200, -100));
        assert!((-200..=-100).all(|j| !coverage.covers(1, j)));
    }

    #[test]
    fn an_empty_polygon_covers_nothing() {
        let mut coverage = Coverage::default();
        coverage.rasterise(&FovPolygon::default(), 0.4, (-1000, 1000));
        assert!(!coverage.covers(0, 0));
    }
}
