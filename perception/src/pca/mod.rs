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
//! distance of the cell from the sensor, `r = σ_δ² / d²` (eq. 4), in
//! [`PcaMaps::roughness`]. Eq. 3 is taken over the returns of a pool of
//! cells around the cell (`roughness_pool_m`, 0.5 m): a 10 cm cell holds
//! 2-5 returns of a 64-beam lidar, and a variance of so few speckles
//! (per cell, flat ground and 2 cm bumps overlapped; pooled, flat ground
//! reads under 2 mm and 2 cm bumps 1-2 cm).
//!
//! r becomes a height through eq. 2, `e = d·h₂/(h₁ − h₂)`: with
//! e/d = √r and h₁ the sensor's height above the plane fitted to the
//! cell's tile (along its normal, so a slope's grazing angle), the bumps are
//! `h₂ = h₁·√r/(1 + √r)` high ([`PcaMaps::bump_height`]). A cell judged
//! flat with `h₂ ≥ rough_from_m` is graded ground (no reason) of cost
//! `rough_max_cost · min(1, h₂ / rough_full_m)`, below 1: 001 uses r to
//! prefer a track over a still passable rubble pile, so rough ground
//! lowers an arc's vote and speed in obstacle avoidance and never blocks
//! it. The filter sees bumps shorter than its 9 returns span (at 10 m,
//! 0.3 m for lidar64, 0.5 m for the ERIM) and underestimates longer ones.
//!
//! The report carries the `not flat` and `slope` cells, the graded rough
//! ground, and the drop-offs, footprint and shadows every evaluator
//! reports (`grid::SeenGround`, crate-private).

use arcnav_vehicle::config::ConfigError;
use arcnav_vehicle::{Isometry, VehicleConfig};
use nalgebra::{Matrix3, SymmetricEigen};

use crate::config::{GridShape, PerceptionConfig};

pub mod config;
use crate::evaluator::{
    ImageStats, ObstacleReport, PerceptionError, Reasons, Runner, TerrainEvaluator,
};
use crate::grid::{self, GridReport, Marked, Point, Projector};
use crate::image::RangeImage;
use crate::plugin::EvaluatorPlugin;
pub use config::PcaConfig;

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

    /// `(h, tilt, normal)`: the variance along the most vertical
    /// eigenvector (001 eq. 1), that eigenvector's angle from the vertical,
    /// radians, and the eigenvector itself, pointing up.
    fn disturbance(&self) -> (f64, f64, [f64; 3]) {
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
        let e = eigen.eigenvectors.column(k);
        let up = e[2].signum();
        (h, tilt, [e[0] * up, e[1] * up, e[2] * up])
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
    /// r of 001 eq. 4 per cell, over the returns of its pool (NaN: fewer
    /// than two returns with a deviation).
    pub roughness: Vec<f32>,
    /// The bump height h₂ that r shows (eq. 2 solved for h₂; see
    /// `rough_from_m`), m, in cells judged flat (NaN elsewhere).
    pub bump_height: Vec<f32>,
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
    /// The sensor's height above the plane of the cell's tile, m (cells
    /// judged flat).
    sensor_above: f32,
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
    prefix: Vec<f64>,
    cells: Vec<CellSums>,
    touched: Vec<u32>,
    /// Half the side of the roughness pool, cells.
    pool: usize,
    /// The sensor's level-frame position for the image being judged.
    sensor: [f64; 3],
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
        perception: &PerceptionConfig,
        vehicle: &VehicleConfig,
    ) -> Result<(), ConfigError> {
        config.validate(vehicle)?;
        grid::check_size("pca.cell_size_m", &perception.region, config.cell_size_m)
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
            prefix: Vec::new(),
            cells: vec![CellSums::default(); grid.cols * grid.rows],
            touched: Vec::new(),
            sensor: [0.0; 3],
            pool: ((config.roughness_pool_m / config.cell_size_m - 1.0) / 2.0)
                .round()
                .max(0.0) as usize,
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
        let max_jump = self.config.roughness_max_jump as f32;
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
            // Prefix sums: the window shrinks symmetrically at the ends of
            // the line, so a steadily changing range (a level row across a
            // tilted sensor's image) leaves no deviation there.
            self.prefix.clear();
            self.prefix.push(0.0);
            let mut total = 0.0;
            for &v in &self.line {
                total += f64::from(v);
                self.prefix.push(total);
            }
            let deviations = &mut self.deviation[row * cols..(row + 1) * cols];
            for (col, (&range, deviation)) in ranges.iter().zip(deviations).enumerate() {
                let h = half.min(col).min(cols - 1 - col);
                if !valid(range) {
                    continue;
                }
                // A window across an edge (an obstacle's silhouette against
                // the ground behind it) deviates by the jump, not by bumps:
                // no deviation is taken there.
                let window = &self.line[col - h..=col + h];
                let (low, high) = window
                    .iter()
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &v| {
                        (lo.min(v), hi.max(v))
                    });
                if high - low > max_jump * range {
                    continue;
                }
                let sum = self.prefix[col + h + 1] - self.prefix[col - h];
                *deviation = (sum / (2 * h + 1) as f64) as f32 - range;
            }
        }
    }

    /// §3.3 eqs. 3-4 per touched cell, over the returns of its pool:
    ///
    /// ```text
    /// σ̂_δ² = (1/n)Σδ_i² − ((1/n)Σδ_i)²     (001 eq. 3)
    /// σ_δ² = max{0, σ̂_δ² − σ_L²}
    /// r    = σ_δ² / d_Cell²                  (001 eq. 4)
    /// ```
    ///
    fn roughness(&mut self) {
        let (cols, rows) = (self.grid.cols, self.grid.rows);
        let maps = &mut self.maps;
        for layer in [&mut maps.roughness, &mut maps.bump_height] {
            layer.clear();
            layer.resize(cols * rows, f32::NAN);
        }
        let noise = self.config.range_noise_m * self.config.range_noise_m;
        let pool = self.pool;
        for &i in &self.touched {
            let i = i as usize;
            let (x, y) = (i % cols, i / cols);
            let (mut sums, mut count) = ([0.0; 3], 0);
            for v in y.saturating_sub(pool)..(y + pool + 1).min(rows) {
                for c in &self.cells
                    [v * cols + x.saturating_sub(pool)..v * cols + (x + pool + 1).min(cols)]
                {
                    for (s, d) in sums.iter_mut().zip(c.dev) {
                        *s += d;
                    }
                    count += c.dev_n;
                }
            }
            if count < 2 {
                continue;
            }
            let k = f64::from(count);
            let variance = sums[1] / k - (sums[0] / k).powi(2);
            let d = sums[2] / k;
            maps.roughness[i] = ((variance - noise).max(0.0) / (d * d)) as f32;
        }
    }

    /// The bump height of each cell judged flat, from its roughness by
    /// eq. 2, `e = d·h₂/(h₁ − h₂)`, solved for h₂ with e/d = √r:
    /// `h₂ = h₁·√r / (1 + √r)`. h₁ is the sensor's height above the plane
    /// fitted to the cell's tile, along its normal: eq. 2 is drawn over
    /// level ground, and on a slope the ray's grazing angle is the one to
    /// the slope (the level height overstates bumps on ground falling away
    /// and understates them on ground rising). Cells whose bump height
    /// reaches `rough_from_m` are marked as graded ground (cost below 1,
    /// no reason).
    fn grade_rough_ground(&mut self) {
        let c = &self.config;
        let (from, full, top) = (c.rough_from_m, c.rough_full_m, c.rough_max_cost);
        assert!(full > from);
        for &i in &self.touched {
            let i = i as usize;
            let r = f64::from(self.maps.roughness[i]);
            if self.maps.flat_region[i] == 0 || r.is_nan() {
                continue;
            }
            let cell = &self.cells[i];
            let bump = f64::from(cell.sensor_above) * r.sqrt() / (1.0 + r.sqrt());
            self.maps.bump_height[i] = bump as f32;
            if bump < from {
                continue;
            }
            self.out.marked.push(Marked {
                index: i as u32,
                reasons: Reasons::NONE,
                cost: (top * (bump / full).min(1.0)) as f32,
                z_min: cell.z_min,
                z_max: cell.z_max,
            });
        }
    }

    /// Level-frame (x, y) of the corner of the tile holding cell (x, y):
    /// moments are taken relative to it, for precision.
    fn tile_corner(&self, x: usize, y: usize) -> [f32; 2] {
        let (tile, cell) = (self.tile, self.cell);
        [
            self.maps.origin[0] + (x / tile * tile) as f32 * cell,
            self.maps.origin[1] + (y / tile * tile) as f32 * cell,
        ]
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

    /// Algorithm 1 on the cells `[x0, x1) × [y0, y1)`: a whole tile
    /// (`tile_above` None), or the half of a region found not flat, with
    /// the sensor's height above its tile's plane. A region too sparse to
    /// judge is left alone, except as such a half: no finer region can
    /// show it flat, so it stays an obstacle.
    fn judge(&mut self, x0: usize, x1: usize, y0: usize, y1: usize, tile_above: Option<f32>) {
        let total = self.moments(x0, x1, y0, y1);
        if total.n < self.config.min_points {
            if tile_above.is_some() && total.n > 0 {
                self.mark(x0, x1, y0, y1, Reasons::NOT_FLAT);
            }
            return;
        }
        self.maps.regions_judged += 1;
        let single = x1 - x0 == 1 && y1 - y0 == 1;
        self.maps.single_cells_judged += u32::from(single);
        let (h, tilt, normal) = total.disturbance();
        // A plane is tilted only as far as the points show it: a few
        // returns along one scan line give any tilt across it.
        let spread = self.config.min_plane_spread_m * self.config.min_plane_spread_m;
        let planar = total.horizontal_spread() >= spread;
        // The sensor's height above the tile's plane (above the level
        // plane through its centroid where its points show no plane), for
        // the roughness's bump height: the tile's, not a small region's,
        // whose plane may be a bump's flank.
        let above = tile_above.unwrap_or_else(|| {
            let n = if planar { normal } else { [0.0, 0.0, 1.0] };
            let count = f64::from(total.n);
            let corner = self.tile_corner(x0, y0);
            let centroid = [
                total.s[0] / count + f64::from(corner[0]),
                total.s[1] / count + f64::from(corner[1]),
                total.s[2] / count,
            ];
            (0..3)
                .map(|a| (self.sensor[a] - centroid[a]) * n[a])
                .sum::<f64>()
                .max(0.0) as f32
        });
        let t = self.config.max_disturbance_m * self.config.max_disturbance_m;
        let reasons = if h <= t {
            if tilt <= self.max_tilt || !planar {
                let side = (x1 - x0).max(y1 - y0).min(usize::from(u16::MAX)) as u16;
                let cols = self.grid.cols;
                for y in y0..y1 {
                    for x in x0..x1 {
                        self.maps.flat_region[y * cols + x] = side;
                        self.cells[y * cols + x].sensor_above = above;
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
                self.judge(x0, mid, y0, y1, Some(above));
                self.judge(mid, x1, y0, y1, Some(above));
            } else {
                let mid = y0 + (y1 - y0) / 2;
                self.judge(x0, x1, y0, mid, Some(above));
                self.judge(x0, x1, mid, y1, Some(above));
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

    /// A tile (the largest region the recursion judges), the roughness
    /// pool, and the scan-line filter's half window.
    fn support(&self) -> crate::Support {
        let c = &self.config;
        crate::Support {
            metres: (c.tile_m + c.roughness_pool_m + c.cell_size_m) * std::f64::consts::SQRT_2,
            pixels: c.roughness_window / 2 + 1,
            radians: 0.0,
        }
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
        self.sensor = [sensor.x, sensor.y, sensor.z];
        for p in &self.points {
            let Some(i) = self.grid.index(cell, p.xyz[0], p.xyz[1]) else {
                continue;
            };
            // Relative to the corner of the cell's tile, for precision.
            let corner = self.tile_corner(i % cols, i / cols);
            let c = &mut self.cells[i];
            if c.moments.n == 0 {
                self.touched.push(i as u32);
                c.z_min = f32::INFINITY;
                c.z_max = f32::NEG_INFINITY;
            }
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
        self.maps.flat_region.clear();
        self.maps.flat_region.resize(n, 0);
        self.maps.regions_judged = 0;
        self.maps.single_cells_judged = 0;
        stats.cells_evaluated += self.touched.len() as u32;
        self.roughness();
        let (gcols, grows) = (self.grid.cols, self.grid.rows);
        for ty in (0..grows).step_by(tile) {
            for tx in (0..gcols).step_by(tile) {
                self.judge(tx, (tx + tile).min(gcols), ty, (ty + tile).min(grows), None);
            }
        }
        self.grade_rough_ground();
        for &i in &self.touched {
            self.cells[i as usize] = CellSums::default();
        }
        self.touched.clear();
        self.out
            .finish(image, world_from_vehicle, report, &mut stats);
        Ok(stats)
    }
}
