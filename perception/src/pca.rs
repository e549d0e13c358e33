//! Hierarchical PCA and scan-line roughness: the terrain analysis of
//! Pellenz et al. (paper 001, §3), `perception.evaluator = "pca"`.
//!
//! **Hierarchical PCA** (§3.2, Algorithm 1). The returns are binned into a
//! grid of 10 cm cells (the smallest region). A region's flatness is its
//! *local height disturbance*
//!
//! ```text
//! h = λ_k  with  k = argmax_i |e_iᵀ z|        (001 eq. 1)
//! ```
//!
//! the variance of its points along the eigenvector of their covariance
//! most aligned with the vertical, so a sloped but flat region scores low.
//! A region with `h ≤ t` is drivable; otherwise it is split at the middle
//! of its longest edge and both halves are judged again, down to one cell,
//! which is then an obstacle (reason `not flat`). Here `t` is given as a
//! standard deviation, `t = max_disturbance_m²` (3 cm: a step inside a
//! region tilts the fitted plane and hides much of itself in it, so a
//! 15 cm box in a 0.8 m tile leaves only about 4 cm).
//!
//! Two departures, both for a vehicle rather than 001's rescue robot:
//!
//! - The recursion starts from square tiles of `tile_m` (0.8 m), not from
//!   the whole grid: a 25 cm rock is 4 % of a 1.6 m square, too little of
//!   its points to raise h above t, but 14 % of a 0.8 m one.
//! - A flat region steeper than `vehicle.max_slope_deg` is an obstacle
//!   (reason `slope`): eq. 1 scores a flat 40° ramp as drivable, and 001's
//!   robot met no such slope alone.
//!
//! Regions with fewer than `min_points` returns are not judged (unknown
//! ground is the local map's to remember, not an obstacle).
//!
//! **Roughness** (§3.3). Each scan line (image row) is copied with missing
//! returns overwritten by the last valid one, smoothed by a mean filter of
//! 9, and each return's deviation δ_i from the smoothed line is kept. Per
//! cell, `σ̂_δ² = (1/n)Σδ_i² − ((1/n)Σδ_i)²` (eq. 3), the sensor's own
//! noise removed, `σ_δ² = max{0, σ̂_δ² − σ_L²}`, and divided by the squared
//! distance of the cell from the sensor, `r = σ_δ² / d²` (eq. 4): a graded
//! measure of rough but passable ground, in [`PcaMaps::roughness`].
//!
//! The report carries the `not flat` and `slope` cells and the drop-offs,
//! footprint and shadows every evaluator reports
//! ([`crate::grid::SeenGround`]).

use arcnav_vehicle::config::{self, ConfigError};
use arcnav_vehicle::{Isometry, VehicleConfig};
use nalgebra::{Matrix3, SymmetricEigen};
use serde::{Deserialize, Serialize};

use crate::config::{GridShape, PerceptionConfig};
use crate::evaluator::{
    ImageStats, InOrder, ObstacleReport, PerceptionError, Reasons, Runner, TerrainEvaluator,
};
use crate::grid::{self, GridReport, Marked, Point, Projector};
use crate::image::RangeImage;
use crate::registry::EvaluatorPlugin;

/// Lives in `[perception.pca]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PcaConfig {
    /// The smallest region, m (001 §3.2: 10 cm × 10 cm).
    pub cell_size_m: f64,
    /// Square tiles the recursion starts from, m (a whole number of cells).
    pub tile_m: f64,
    /// A region is flat when the standard deviation of its points along
    /// its most vertical eigenvector is at most this, m (t = this²).
    pub max_disturbance_m: f64,
    /// A region with fewer returns is not judged (4: three points always
    /// lie in a plane; a 10 cm cell on a box's edge 6 m from a 64-beam
    /// lidar holds about five).
    pub min_points: u32,
    /// A flat region steeper than this is an obstacle, degrees.
    pub max_slope_deg: f64,
    /// ... judged only when its points spread this much (standard
    /// deviation) along x and along y, m.
    pub min_plane_spread_m: f64,
    /// σ_L: the sensor's range noise, removed from the roughness, m.
    pub range_noise_m: f64,
    /// The mean filter along each scan line, returns (001 §3.3: 9).
    pub roughness_window: u32,
}

impl Default for PcaConfig {
    fn default() -> Self {
        let vehicle = VehicleConfig::default();
        Self {
            cell_size_m: 0.1,
            tile_m: 0.8,
            max_disturbance_m: 0.03,
            min_points: 4,
            max_slope_deg: vehicle.max_slope_deg,
            min_plane_spread_m: 0.03,
            range_noise_m: 0.02,
            roughness_window: 9,
        }
    }
}

impl PcaConfig {
    /// Keys relative to `[perception]`.
    fn validate(&self, vehicle: &VehicleConfig) -> Result<(), ConfigError> {
        let key = |k: &str| format!("pca.{k}");
        config::in_range(&key("cell_size_m"), self.cell_size_m, 0.02, 1.0)?;
        config::in_range(&key("tile_m"), self.tile_m, self.cell_size_m, 20.0)?;
        config::positive(&key("max_disturbance_m"), self.max_disturbance_m)?;
        if !(4..=1_000_000).contains(&self.min_points) {
            return Err(ConfigError::new(
                key("min_points"),
                format!(
                    "is {}, must be at least 4 (three points always lie in a plane)",
                    self.min_points
                ),
            ));
        }
        config::in_range(&key("max_slope_deg"), self.max_slope_deg, 0.1, 89.0)?;
        if self.max_slope_deg > vehicle.max_slope_deg {
            return Err(ConfigError::new(
                key("max_slope_deg"),
                format!(
                    "is {}, more than vehicle.max_slope_deg ({}): perception would pass \
                     terrain the vehicle cannot drive",
                    self.max_slope_deg, vehicle.max_slope_deg
                ),
            ));
        }
        // A region holding a step of the tolerated height half on each
        // side has σ = step / 2: a laxer t passes it.
        if self.max_disturbance_m > vehicle.tolerated_step_m / 2.0 {
            return Err(ConfigError::new(
                key("max_disturbance_m"),
                format!(
                    "is {}, more than half vehicle.tolerated_step_m ({}): a region split evenly \
                     by a step the vehicle cannot drive would pass as flat",
                    self.max_disturbance_m, vehicle.tolerated_step_m
                ),
            ));
        }
        config::non_negative(&key("min_plane_spread_m"), self.min_plane_spread_m)?;
        config::non_negative(&key("range_noise_m"), self.range_noise_m)?;
        if !(1..=101).contains(&self.roughness_window) {
            return Err(ConfigError::new(
                key("roughness_window"),
                format!("is {}, must be 1 to 101", self.roughness_window),
            ));
        }
        Ok(())
    }
}

/// Moments of the points of a cell or region, coordinates relative to the
/// tile's corner (level frame, m).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct Moments {
    n: u32,
    s: [f64; 3],
    /// xx, xy, xz, yy, yz, zz.
    ss: [f64; 6],
}

impl Moments {
    fn add_point(&mut self, p: [f64; 3]) {
        self.n += 1;
        for (s, v) in self.s.iter_mut().zip(p) {
            *s += v;
        }
        let [x, y, z] = p;
        for (s, v) in self
            .ss
            .iter_mut()
            .zip([x * x, x * y, x * z, y * y, y * z, z * z])
        {
            *s += v;
        }
    }

    fn add(&mut self, other: &Moments) {
        self.n += other.n;
        for (a, b) in self.s.iter_mut().zip(other.s) {
            *a += b;
        }
        for (a, b) in self.ss.iter_mut().zip(other.ss) {
            *a += b;
        }
    }

    /// The smaller of the points' variances along x and along y, m².
    fn horizontal_spread(&self) -> f64 {
        let n = f64::from(self.n);
        let var = |k: usize, a: usize| self.ss[k] / n - (self.s[a] / n).powi(2);
        var(0, 0).min(var(3, 1))
    }

    /// `(h, tilt)`: the variance along the most vertical eigenvector (001
    /// eq. 1) and that eigenvector's angle from the vertical, radians.
    fn disturbance(&self) -> (f64, f64) {
        let n = f64::from(self.n);
        let m = self.s.map(|v| v / n);
        let c = |k: usize, a: usize, b: usize| self.ss[k] / n - m[a] * m[b];
        let cov = Matrix3::new(
            c(0, 0, 0),
            c(1, 0, 1),
            c(2, 0, 2),
            c(1, 0, 1),
            c(3, 1, 1),
            c(4, 1, 2),
            c(2, 0, 2),
            c(4, 1, 2),
            c(5, 2, 2),
        );
        let eigen = SymmetricEigen::new(cov);
        let k = (0..3)
            .max_by(|&a, &b| {
                eigen.eigenvectors[(2, a)]
                    .abs()
                    .total_cmp(&eigen.eigenvectors[(2, b)].abs())
            })
            .unwrap_or(2);
        let h = eigen.eigenvalues[k].max(0.0);
        let tilt = eigen.eigenvectors[(2, k)].abs().min(1.0).acos();
        (h, tilt)
    }
}

/// What the last evaluation found, per cell of the grid (row-major,
/// `cols` along x ahead, `rows` along y left).
#[derive(Debug, Clone, Default)]
pub struct PcaMaps {
    pub cols: usize,
    pub rows: usize,
    /// Cell size, m.
    pub cell: f32,
    /// Level-frame (x, y) of the first cell's corner, m.
    pub origin: [f32; 2],
    /// r of 001 eq. 4 per cell (NaN: no return, or a single one).
    pub roughness: Vec<f32>,
    /// Side, in cells, of the largest region each cell was judged flat in
    /// (0: not judged flat).
    pub flat_region: Vec<u16>,
    /// Regions judged, and how many of them were single cells.
    pub regions_judged: u32,
    pub single_cells_judged: u32,
}

impl PcaMaps {
    /// The cell holding level-frame (x, y).
    pub fn index(&self, x: f32, y: f32) -> Option<usize> {
        grid::layer_index(self.origin, self.cell, (self.cols, self.rows), x, y)
    }
}

/// Per-cell accumulators.
#[derive(Debug, Clone, Copy, Default)]
struct CellSums {
    moments: Moments,
    z_min: f32,
    z_max: f32,
    /// Σδ, Σδ², Σ range of the points with a deviation.
    dev: [f64; 3],
    dev_n: u32,
}

/// The 001 evaluator. Build it with [`PerceptionConfig::build_evaluator`].
pub struct HierarchicalPca {
    config: PcaConfig,
    cell: f32,
    tile: usize,
    grid: GridShape,
    min_range: f32,
    max_range: f32,
    max_tilt: f64,
    out: GridReport,
    projector: Projector,
    points: Vec<Point>,
    deviation: Vec<f32>,
    line: Vec<f32>,
    cells: Vec<CellSums>,
    touched: Vec<u32>,
    maps: PcaMaps,
}

impl EvaluatorPlugin for HierarchicalPca {
    const NAME: &'static str = "pca";
    const ABOUT: &'static str =
        "hierarchical PCA flatness with scan-line roughness (001, Pellenz et al.)";
    type Config = PcaConfig;

    fn config(perception: &PerceptionConfig) -> Result<Self::Config, ConfigError> {
        Ok(perception.pca.clone())
    }

    fn validate(
        config: &Self::Config,
        _: &PerceptionConfig,
        vehicle: &VehicleConfig,
    ) -> Result<(), ConfigError> {
        config.validate(vehicle)
    }

    fn build(config: Self::Config, perception: &PerceptionConfig) -> Self {
        Self::new(config, perception)
    }
}

impl HierarchicalPca {
    /// An evaluator over `perception`'s region.
    pub fn new(config: PcaConfig, perception: &PerceptionConfig) -> Self {
        let out = GridReport::new(perception, config.cell_size_m);
        let grid = out.grid();
        let cell = config.cell_size_m as f32;
        Self {
            cell,
            tile: ((config.tile_m / config.cell_size_m).round() as usize).max(1),
            grid,
            min_range: perception.min_range_m as f32,
            max_range: perception.max_range_m as f32,
            max_tilt: config.max_slope_deg.to_radians(),
            out,
            projector: Projector::default(),
            points: Vec::new(),
            deviation: Vec::new(),
            line: Vec::new(),
            cells: vec![CellSums::default(); grid.cols * grid.rows],
            touched: Vec::new(),
            maps: PcaMaps {
                cols: grid.cols,
                rows: grid.rows,
                cell,
                origin: [-grid.corner[0] * cell, -grid.corner[1] * cell],
                ..PcaMaps::default()
            },
            config,
        }
    }

    /// What the last evaluation found.
    pub fn maps(&self) -> &PcaMaps {
        &self.maps
    }

    /// §3.3: each return's deviation from its scan line smoothed by a mean
    /// filter (NaN where there was no return).
    fn deviations(&mut self, image: &RangeImage) {
        let cols = image.cols();
        let half = (self.config.roughness_window / 2) as usize;
        self.deviation.clear();
        self.deviation.resize(image.range.len(), f32::NAN);
        for (row, ranges) in image.range.chunks_exact(cols.max(1)).enumerate() {
            // Missing returns overwritten by the last valid one (the first
            // valid one before any).
            let valid = |r: f32| r.is_finite() && r > 0.0;
            let Some(first) = ranges.iter().copied().find(|&r| valid(r)) else {
                continue;
            };
            self.line.clear();
            let mut last = first;
            for &r in ranges {
                if valid(r) {
                    last = r;
                }
                self.line.push(last);
            }
            let mut sum: f64 = self.line[..half.min(cols)]
                .iter()
                .map(|&v| f64::from(v))
                .sum();
            let deviations = &mut self.deviation[row * cols..(row + 1) * cols];
            for (col, (&range, deviation)) in ranges.iter().zip(deviations).enumerate() {
                if col + half < cols {
                    sum += f64::from(self.line[col + half]);
                }
                if col > half {
                    sum -= f64::from(self.line[col - half - 1]);
                }
                let width = (col + half + 1).min(cols) - col.saturating_sub(half);
                if valid(range) {
                    *deviation = (sum / width as f64) as f32 - range;
                }
            }
        }
    }

    /// The moments of the cells `[x0, x1) × [y0, y1)`.
    fn moments(&self, x0: usize, x1: usize, y0: usize, y1: usize) -> Moments {
        let cols = self.grid.cols;
        let mut total = Moments::default();
        for y in y0..y1 {
            for x in x0..x1 {
                total.add(&self.cells[y * cols + x].moments);
            }
        }
        total
    }

    /// Algorithm 1 on the cells `[x0, x1) × [y0, y1)`. A region too sparse
    /// to judge is left alone, except as the half of a region found not
    /// flat: no finer region can show it flat, so it stays an obstacle.
    fn judge(&mut self, x0: usize, x1: usize, y0: usize, y1: usize, parent_not_flat: bool) {
        let total = self.moments(x0, x1, y0, y1);
        if total.n < self.config.min_points {
            if parent_not_flat && total.n > 0 {
                self.mark(x0, x1, y0, y1, Reasons::NOT_FLAT);
            }
            return;
        }
        self.maps.regions_judged += 1;
        let single = x1 - x0 == 1 && y1 - y0 == 1;
        self.maps.single_cells_judged += u32::from(single);
        let (h, tilt) = total.disturbance();
        let t = self.config.max_disturbance_m * self.config.max_disturbance_m;
        let reasons = if h <= t {
            // A plane is tilted only as far as the points show it: a few
            // returns along one scan line give any tilt across it.
            let spread = self.config.min_plane_spread_m * self.config.min_plane_spread_m;
            if tilt <= self.max_tilt || total.horizontal_spread() < spread {
                let side = (x1 - x0).max(y1 - y0).min(usize::from(u16::MAX)) as u16;
                let cols = self.grid.cols;
                for y in y0..y1 {
                    for x in x0..x1 {
                        self.maps.flat_region[y * cols + x] = side;
                    }
                }
                return;
            }
            Reasons::SLOPE
        } else if single {
            Reasons::NOT_FLAT
        } else {
            if x1 - x0 >= y1 - y0 {
                let mid = x0 + (x1 - x0) / 2;
                self.judge(x0, mid, y0, y1, true);
                self.judge(mid, x1, y0, y1, true);
            } else {
                let mid = y0 + (y1 - y0) / 2;
                self.judge(x0, x1, y0, mid, true);
                self.judge(x0, x1, mid, y1, true);
            }
            return;
        };
        self.mark(x0, x1, y0, y1, reasons);
    }

    /// Marks the cells with returns in `[x0, x1) × [y0, y1)`.
    fn mark(&mut self, x0: usize, x1: usize, y0: usize, y1: usize, reasons: Reasons) {
        let cols = self.grid.cols;
        for y in y0..y1 {
            for x in x0..x1 {
                let c = &self.cells[y * cols + x];
                if c.moments.n > 0 {
                    self.out.marked.push(Marked {
                        index: (y * cols + x) as u32,
                        reasons,
                        cost: 1.0,
                        z_min: c.z_min,
                        z_max: c.z_max,
                    });
                }
            }
        }
    }
}

impl TerrainEvaluator for HierarchicalPca {
    fn name(&self) -> &'static str {
        "pca"
    }

    fn evaluate(
        &mut self,
        image: &RangeImage,
        world_from_vehicle: &Isometry,
        report: &mut ObstacleReport,
    ) -> Result<ImageStats, PerceptionError> {
        self.evaluate_with(image, world_from_vehicle, report, &InOrder)
    }

    fn evaluate_with(
        &mut self,
        image: &RangeImage,
        world_from_vehicle: &Isometry,
        report: &mut ObstacleReport,
        runner: &dyn Runner,
    ) -> Result<ImageStats, PerceptionError> {
        let mut stats = self.out.start(image, world_from_vehicle, runner, report)?;
        if image.range.is_empty() {
            return Ok(stats);
        }
        let (_, level_from_sensor) = grid::level_frames(image, world_from_vehicle);
        self.deviations(image);
        self.points.clear();
        self.projector.project(
            image,
            &image.range,
            &level_from_sensor,
            self.min_range,
            self.max_range,
            &mut self.points,
            &mut ImageStats::default(),
        );
        let (cols, cell, tile) = (self.grid.cols, self.cell, self.tile);
        let sensor = level_from_sensor.translation.vector;
        for p in &self.points {
            let Some(i) = self.grid.index(cell, p.xyz[0], p.xyz[1]) else {
                continue;
            };
            let c = &mut self.cells[i];
            if c.moments.n == 0 {
                self.touched.push(i as u32);
                c.z_min = f32::INFINITY;
                c.z_max = f32::NEG_INFINITY;
            }
            // Relative to the corner of the cell's tile, for precision.
            let corner = [
                self.maps.origin[0] + ((i % cols) / tile * tile) as f32 * cell,
                self.maps.origin[1] + ((i / cols) / tile * tile) as f32 * cell,
            ];
            c.moments.add_point([
                f64::from(p.xyz[0] - corner[0]),
                f64::from(p.xyz[1] - corner[1]),
                f64::from(p.xyz[2]),
            ]);
            c.z_min = c.z_min.min(p.xyz[2]);
            c.z_max = c.z_max.max(p.xyz[2]);
            let delta = self.deviation[p.row as usize * image.cols() + p.col as usize];
            if delta.is_finite() {
                let d = (p.xyz[0] - sensor.x as f32)
                    .hypot(p.xyz[1] - sensor.y as f32)
                    .hypot(p.xyz[2] - sensor.z as f32);
                c.dev[0] += f64::from(delta);
                c.dev[1] += f64::from(delta) * f64::from(delta);
                c.dev[2] += f64::from(d);
                c.dev_n += 1;
            }
        }
        // Moments are relative to tile corners: a region never spans two
        // tiles, so the sums of its cells share one origin.
        let n = cols * self.grid.rows;
        self.maps.roughness.clear();
        self.maps.roughness.resize(n, f32::NAN);
        self.maps.flat_region.clear();
        self.maps.flat_region.resize(n, 0);
        self.maps.regions_judged = 0;
        self.maps.single_cells_judged = 0;
        let noise = self.config.range_noise_m * self.config.range_noise_m;
        for &i in &self.touched {
            let c = &self.cells[i as usize];
            stats.cells_evaluated += 1;
            if c.dev_n >= 2 {
                let k = f64::from(c.dev_n);
                let variance = c.dev[1] / k - (c.dev[0] / k).powi(2);
                let d = c.dev[2] / k;
                self.maps.roughness[i as usize] = ((variance - noise).max(0.0) / (d * d)) as f32;
            }
        }
        let (gcols, grows) = (self.grid.cols, self.grid.rows);
        for ty in (0..grows).step_by(tile) {
            for tx in (0..gcols).step_by(tile) {
                self.judge(
                    tx,
                    (tx + tile).min(gcols),
                    ty,
                    (ty + tile).min(grows),
                    false,
                );
            }
        }
        for &i in &self.touched {
            self.cells[i as usize] = CellSums::default();
        }
        self.touched.clear();
        self.out
            .finish(image, world_from_vehicle, report, &mut stats);
        Ok(stats)
    }
}
