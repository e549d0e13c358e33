//! One grid cell's running sums (its points' moments, the plane fitted
//! to them) and the per-beam trigonometry that projects returns to cells.

#[derive(Debug, Clone, Copy)]
pub(super) struct Cell {
    /// Position in the grid (`iy * cols + ix`).
    pub(super) index: u32,
    pub(super) count: u32,
    pub(super) z_min: f32,
    pub(super) z_max: f32,
    /// Σx, Σy, Σz, Σxx, Σxy, Σyy, Σxz, Σyz with x, y relative to the cell centre.
    pub(super) sums: [f32; 8],
}

impl Cell {
    pub(super) fn new(index: u32) -> Self {
        Self {
            index,
            count: 0,
            z_min: f32::INFINITY,
            z_max: f32::NEG_INFINITY,
            sums: [0.0; 8],
        }
    }

    /// What a point (x, y relative to the cell centre) adds to `sums`.
    #[inline(always)]
    pub(super) fn terms(dx: f32, dy: f32, z: f32) -> [f32; 8] {
        [dx, dy, z, dx * dx, dx * dy, dy * dy, dx * z, dy * z]
    }
}

impl Cell {
    /// Adds the points of `other`, the same cell binned from other columns.
    pub(super) fn merge(&mut self, other: &Cell) {
        self.count += other.count;
        self.z_min = self.z_min.min(other.z_min);
        self.z_max = self.z_max.max(other.z_max);
        for (sum, term) in self.sums.iter_mut().zip(other.sums) {
            *sum += term;
        }
    }
}

/// Least-squares plane sums over one cell or a window of cells, with x and
/// y relative to the centre of the cell being judged (offsets stay below a
/// metre, so f32 keeps millimetres; the solve runs in f64).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct PlaneSums {
    pub(super) n: f32,
    pub(super) sx: f32,
    pub(super) sy: f32,
    pub(super) sz: f32,
    pub(super) sxx: f32,
    pub(super) sxy: f32,
    pub(super) syy: f32,
    pub(super) sxz: f32,
    pub(super) syz: f32,
}

impl PlaneSums {
    /// Adds a cell whose centre lies at (ox, oy) from the judged cell's.
    #[inline]
    pub(super) fn add(&mut self, cell: &Cell, ox: f32, oy: f32) {
        let n = cell.count as f32;
        let [sx, sy, sz, sxx, sxy, syy, sxz, syz] = cell.sums;
        self.n += n;
        self.sx += sx + n * ox;
        self.sy += sy + n * oy;
        self.sz += sz;
        self.sxx += sxx + 2.0 * ox * sx + n * ox * ox;
        self.syy += syy + 2.0 * oy * sy + n * oy * oy;
        self.sxy += sxy + ox * sy + oy * sx + n * ox * oy;
        self.sxz += sxz + ox * sz;
        self.syz += syz + oy * sz;
    }

    /// Tangent² of the fitted plane's tilt, if the points spread enough in
    /// both horizontal directions to define a plane.
    pub(super) fn slope_tan2(&self, min_variance: f64) -> Option<f64> {
        let n = f64::from(self.n);
        if n < 3.0 {
            return None;
        }
        let (mx, my, mz) = (
            f64::from(self.sx) / n,
            f64::from(self.sy) / n,
            f64::from(self.sz) / n,
        );
        let cxx = f64::from(self.sxx) / n - mx * mx;
        let cyy = f64::from(self.syy) / n - my * my;
        let cxy = f64::from(self.sxy) / n - mx * my;
        let cxz = f64::from(self.sxz) / n - mx * mz;
        let cyz = f64::from(self.syz) / n - my * mz;
        let det = cxx * cyy - cxy * cxy;
        let trace = cxx + cyy;
        let smallest = 0.5 * (trace - (trace * trace - 4.0 * det).max(0.0).sqrt());
        if smallest <= min_variance || det <= 0.0 {
            return None;
        }
        let a = (cyy * cxz - cxy * cyz) / det;
        let b = (cxx * cyz - cxy * cxz) / det;
        Some(a * a + b * b)
    }
}

/// The trig of the last beam table seen, so a sensor's table is processed once.
#[derive(Debug, Default)]
pub(super) struct BeamTrig {
    pub(super) elevation: Vec<f32>,
    pub(super) azimuth: Vec<f32>,
    pub(super) cos_el: Vec<f32>,
    pub(super) sin_el: Vec<f32>,
    pub(super) cos_az: Vec<f32>,
    pub(super) sin_az: Vec<f32>,
    /// The rows from the highest beam to the lowest: the order rows are
    /// binned in, so each column is walked from its far returns to its near
    /// ones.
    pub(super) order: Vec<u32>,
}

impl BeamTrig {
    pub(super) fn update(&mut self, elevation: &[f32], azimuth: &[f32]) {
        if self.elevation != elevation {
            self.elevation.clear();
            self.elevation.extend_from_slice(elevation);
            self.order.clear();
            self.order.extend(0..elevation.len() as u32);
            self.order
                .sort_by(|&a, &b| elevation[b as usize].total_cmp(&elevation[a as usize]));
            self.cos_el.clear();
            self.sin_el.clear();
            for &e in elevation {
                let (s, c) = f64::from(e).sin_cos();
                self.sin_el.push(s as f32);
                self.cos_el.push(c as f32);
            }
        }
        if self.azimuth != azimuth {
            self.azimuth.clear();
            self.azimuth.extend_from_slice(azimuth);
            self.cos_az.clear();
            self.sin_az.clear();
            for &a in azimuth {
                let (s, c) = f64::from(a).sin_cos();
                self.sin_az.push(s as f32);
                self.cos_az.push(c as f32);
            }
        }
    }
}

/// One row of a part, projected: per pixel its cell (or why it has none)
/// and its point relative to the cell's centre.
#[derive(Debug, Default)]
pub(super) struct ProjectedRow {
    pub(super) index: Vec<u32>,
    pub(super) dx: Vec<f32>,
    pub(super) dy: Vec<f32>,
    pub(super) z: Vec<f32>,
    /// Horizontal distance from the sensor.
    pub(super) d: Vec<f32>,
}

/// `ProjectedRow::index` of a pixel that has no cell, by reason (all above
/// any grid index).
pub(super) const NO_RETURN: u32 = u32::MAX;
pub(super) const OUT_OF_RANGE: u32 = u32::MAX - 1;
pub(super) const OUTSIDE_GRID: u32 = u32::MAX - 2;
