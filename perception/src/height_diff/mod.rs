//! Multi-scale height differences: the drivability maps of Schwarz & Behnke
//! (paper 000, §4–§5.1), `perception.evaluator = "height_diff"`.
//!
//! 1. **Median outlier filter** of each range image (§4.1; [`crate::median`]).
//!    The paper's 10 × 10 pixel window of its 0.09°/pixel cameras is 0.9°;
//!    here the window is the largest odd number of the sensor's own pixels
//!    within that angle along each axis: 5 × 5 on a 0.14°/pixel depth
//!    camera, 1 row × 5 columns on a 64-beam lidar (whose rows, 0.42°
//!    apart, hit the ground metres apart), none on the 0.5°/pixel ERIM.
//! 2. **Height map** (§4.1): a gravity-aligned grid around the vehicle;
//!    each cell keeps the *maximum* height of the points falling in it
//!    ("small positive obstacles pose more danger than small negative
//!    ones"), NaN where none fell, and which sensor gave it. Several images
//!    taken at once (a ring of cameras) go into one map:
//!    [`HeightDiff::build_maps`].
//! 3. **Gap filling** (§4.2): a NaN cell whose nearest defined cells in at
//!    least two of the four axis directions lie closer than
//!    `δ = δ0 + Δ·r` (r: its distance from the vehicle) takes their
//!    inverse-distance weighted mean. The paper's δ0 = 4 cells and
//!    Δ = 0.054 of its 5 cm grid are δ0 = 0.2 m and Δ = 0.054 m/m.
//! 4. **Height differences** (§4.3) at scales l ∈ {1, 3, 6}:
//!    `D_l(x, y) = max |H(x, y) − H(u, v)|` over `|u−x| ≤ l, |v−y| ≤ l`,
//!    NaN when H(x, y) is NaN or no other cell of the window is defined.
//!    (The paper writes `< l`, under which D_1 would compare a cell with
//!    itself alone; its l are the neighbours' distances.)
//!    Differences are never taken across sensor boundaries: a cell is
//!    compared only with cells whose height came from the same sensor.
//! 5. **Cost** (§5.1): `D̃ = Σ_{l ∈ {1,3,6}} min{0.5, λ_l·D_l}` with
//!    λ = (5.0, 2.5, 3.5); an *absolute obstacle* has `λ_l·D_l ≥ 1` in some
//!    map. Absolute obstacles are inflated by the robot radius and costs
//!    averaged locally: `D_D = max{D̃, Σ_{P(x,y)} D̃ / |P|}` (the disc P of
//!    the robot radius is taken as the square of the same area).
//!
//! What the report carries: graded ground, the cells with
//! `graded_from ≤ D̃ / obstacle_cost < 1`, with that cost; and, untraversable,
//! the cells with `D̃ ≥ 1` (`obstacle_cost`) or
//! an absolute obstacle, reason `height difference`, and the drop-offs, footprint and
//! shadows every evaluator reports (`grid::SeenGround`). The
//! inflation and averaging of `D_D` are for planners that treat the
//! vehicle as a point (the paper's navfn); arcnav's behaviours sweep the
//! vehicle's footprint along each arc, so `D_D` is kept, graded, in
//! [`HeightDiffMaps::drivability`] rather than reported as obstacles
//! (that would close every gap narrower than two vehicle widths).
//!
//! The cell size sets what the scales mean on the ground. With 10 cm
//! cells D_6 spans ±0.6 m: an even incline is an absolute obstacle
//! (λ_6·D_6 ≥ 1) from 25.5° along a grid axis (18.6° along a diagonal,
//! where the window reaches 0.85 m), about the vehicle's 25°, and D̃
//! reaches 1 near 22° along an axis. A step of `1/λ_1` = 0.2 m is an
//! absolute obstacle at any cell size: the vehicle's tolerated step. A
//! step reaches D̃ = 1 from about 9 cm (0.5 + 0.25 + 0.35 at 10 cm): 000's
//! small robot avoided what this vehicle could climb; raise
//! `obstacle_cost` (at most 1.5, the three caps) to let it.

use arcnav_vehicle::config::ConfigError;
use arcnav_vehicle::{Isometry, VehicleConfig};

use crate::config::{GridShape, PerceptionConfig};

pub mod config;
use crate::evaluator::{
    ImageStats, ObstacleReport, PerceptionError, Reasons, Runner, TerrainEvaluator,
};
use crate::grid::{self, GridReport, Marked, Projector};
use crate::image::RangeImage;
use crate::median::{MedianOutliers, MedianParams};
use crate::plugin::EvaluatorPlugin;
use crate::window::WindowStats;
pub use config::HeightDiffConfig;

/// The maps of the last image (or set of images), row-major over the grid
/// (`cols` cells along x ahead, `rows` along y left); NaN = unknown.
#[derive(Debug, Clone, Default)]
pub struct HeightDiffMaps {
    pub cols: usize,
    pub rows: usize,
    /// Cell size, m.
    pub cell: f32,
    /// Level-frame (x, y) of the first cell's corner, m.
    pub origin: [f32; 2],
    /// H: the highest point per cell, level-frame z, m.
    pub height: Vec<f32>,
    /// H after gap filling.
    pub filled: Vec<f32>,
    /// The image (index in the set) each cell's height came from.
    pub sensor: Vec<u8>,
    /// D_l per scale, m.
    pub differences: [Vec<f32>; 3],
    /// D̃.
    pub cost: Vec<f32>,
    /// Cells that are absolute obstacles (λ_l·D_l ≥ 1 in some map).
    pub absolute: Vec<bool>,
    /// D_D: D̃ with absolute obstacles inflated and local averages.
    pub drivability: Vec<f32>,
}

impl HeightDiffMaps {
    /// The cell holding level-frame (x, y).
    pub fn index(&self, x: f32, y: f32) -> Option<usize> {
        grid::layer_index(self.origin, self.cell, (self.cols, self.rows), x, y)
    }
}

/// The 000 evaluator. Build it with [`PerceptionConfig::build_evaluator`].
pub struct HeightDiff {
    config: HeightDiffConfig,
    cell: f32,
    grid: GridShape,
    min_range: f32,
    max_range: f32,
    out: GridReport,
    median: MedianOutliers,
    filtered: Vec<f32>,
    projector: Projector,
    lowest: Vec<f32>,
    maps: HeightDiffMaps,
    scratch: Scratch,
}

/// Buffers of the separable window passes.
#[derive(Debug, Default)]
struct Scratch {
    layer: Vec<f32>,
    windows: WindowStats,
    edges: Vec<usize>,
    spans: Vec<usize>,
    sums: Vec<f64>,
    counts: Vec<u32>,
    gaps: [Vec<u32>; 4],
    bins: Vec<Bin>,
}

/// A cell's returns while they are binned: the highest (-∞: none yet) and
/// the lowest (the image the highest came from is kept in the sensor map).
#[derive(Debug, Clone, Copy)]
struct Bin {
    highest: f32,
    lowest: f32,
}

impl Bin {
    const EMPTY: Self = Self {
        highest: f32::NEG_INFINITY,
        lowest: f32::INFINITY,
    };
}

impl EvaluatorPlugin for HeightDiff {
    const NAME: &'static str = "height_diff";
    const ABOUT: &'static str = "multi-scale height differences of a max-height map with gap filling (000, Schwarz & Behnke)";
    type Config = HeightDiffConfig;
    const FUSES_IMAGES: bool = true;

    fn config(perception: &PerceptionConfig) -> Result<Self::Config, ConfigError> {
        Ok(perception.height_diff.clone())
    }

    fn validate(
        config: &Self::Config,
        perception: &PerceptionConfig,
        vehicle: &VehicleConfig,
    ) -> Result<(), ConfigError> {
        config.validate(vehicle)?;
        grid::check_size(
            "height_diff.cell_size_m",
            &perception.region,
            config.cell_size_m,
        )
    }

    fn build(config: Self::Config, perception: &PerceptionConfig) -> Self {
        Self::new(config, perception)
    }
}

impl HeightDiff {
    /// An evaluator over `perception`'s region.
    pub fn new(config: HeightDiffConfig, perception: &PerceptionConfig) -> Self {
        let out = GridReport::new(perception, config.cell_size_m);
        let grid = out.grid();
        let cell = config.cell_size_m as f32;
        Self {
            cell,
            grid,
            min_range: perception.min_range_m as f32,
            max_range: perception.max_range_m as f32,
            out,
            median: MedianOutliers::default(),
            filtered: Vec::new(),
            projector: Projector::default(),
            lowest: Vec::new(),
            maps: HeightDiffMaps {
                cols: grid.cols,
                rows: grid.rows,
                cell,
                origin: [-grid.corner[0] * cell, -grid.corner[1] * cell],
                ..HeightDiffMaps::default()
            },
            scratch: Scratch::default(),
            config,
        }
    }

    /// The maps of the last evaluation.
    pub fn maps(&self) -> &HeightDiffMaps {
        &self.maps
    }

    /// The median outlier filter's window and bounds for `image` (its
    /// beam spacing sets the window's pixels).
    pub fn median_params(&self, image: &RangeImage) -> MedianParams {
        median_params(&self.config, self.max_range, image)
    }

    /// Builds every map from `images`, taken at once with the vehicle at
    /// `world_from_vehicle` (one image, or a ring of sensors). Their
    /// filtered returns go into one height map; differences are taken only
    /// between cells of the same image. Counts go into `stats`.
    pub fn build_maps(
        &mut self,
        images: &[&RangeImage],
        world_from_vehicle: &Isometry,
        stats: &mut ImageStats,
    ) -> Result<&HeightDiffMaps, PerceptionError> {
        let images = &images[..images.len().min(usize::from(u8::MAX))];
        for image in images {
            image.validate()?;
        }
        self.bin(
            images,
            |k| grid::level_frames(images[k], world_from_vehicle).1,
            |_, outliers| stats.outliers += outliers,
        );
        self.judge_heights();
        Ok(&self.maps)
    }

    /// Bins the filtered returns of each of `images` (valid, at most 255),
    /// image k placed by `map_from_sensor(k)`, into the height map,
    /// remembering which image each cell's highest return came from;
    /// `outliers(k, n)` is told how many returns the median filter removed
    /// from image k.
    fn bin(
        &mut self,
        images: &[&RangeImage],
        map_from_sensor: impl Fn(usize) -> Isometry,
        mut outliers: impl FnMut(usize, u32),
    ) {
        let n = self.grid.cols * self.grid.rows;
        let maps = &mut self.maps;
        // Heights binned into one array of cells (one cache line per run,
        // not two), spread into the maps after; the sensor of each cell's
        // highest straight into its map (a separate, small array: with it
        // in the bins, noisy images binned 0.3 ms slower).
        let bins = &mut self.scratch.bins;
        bins.clear();
        bins.resize(n, Bin::EMPTY);
        maps.sensor.clear();
        maps.sensor.resize(n, u8::MAX);
        let sensors = &mut maps.sensor;
        for (k, image) in images.iter().enumerate().take(usize::from(u8::MAX)) {
            let map_from_sensor = map_from_sensor(k);
            let cols = image.cols();
            let params = median_params(&self.config, self.max_range, image);
            outliers(
                k,
                self.median
                    .filter(&image.range, cols, &params, &mut self.filtered),
            );
            let (grid, cell) = (&self.grid, self.cell);
            self.projector.for_each_cell(
                image,
                &self.filtered,
                &map_from_sensor,
                (self.min_range, self.max_range),
                (grid, cell),
                &mut ImageStats::default(),
                |i, highest, lowest| {
                    // Heights are finite. Selected without a branch:
                    // whether a run is higher is a coin toss on noisy
                    // ground.
                    use std::hint::select_unpredictable as select;
                    let bin = &mut bins[i];
                    let higher = highest > bin.highest;
                    sensors[i] = select(higher, k as u8, sensors[i]);
                    bin.highest = select(higher, highest, bin.highest);
                    bin.lowest = select(lowest < bin.lowest, lowest, bin.lowest);
                },
            );
        }
        maps.height.clear();
        maps.height.extend(bins.iter().map(|b| {
            if b.highest == f32::NEG_INFINITY {
                f32::NAN
            } else {
                b.highest
            }
        }));
        self.lowest.clear();
        self.lowest.extend(bins.iter().map(|b| b.lowest));
    }

    /// Marks, for `image`'s report, the cells of the maps built last whose
    /// height came from image `owner` of the set: untraversable ones
    /// (`D̃ ≥ obstacle_cost` or an absolute obstacle) and graded ones. The
    /// maps lie in the level frame `map`; the marks go on the grid of
    /// `image`'s own level frame `own` (the same grid when the two are
    /// one, as for a single image or a ring captured at once). A cell whose
    /// centre leaves that grid is counted in `outside_grid`.
    fn mark(&mut self, owner: u8, map: &Isometry, own: &Isometry, stats: &mut ImageStats) {
        let maps = &self.maps;
        let obstacle = self.config.obstacle_cost as f32;
        let graded = self.config.graded_from as f32 * obstacle;
        let own_from_map = (own != map).then(|| own.inverse() * map);
        let (cols, cell) = (maps.cols, maps.cell);
        let centre = |k: usize, origin: f32| f64::from(origin + (k as f32 + 0.5) * cell);
        // Heights move with the frame's height (level frames differ by a
        // translation and a yaw).
        let dz = (own_from_map.as_ref()).map_or(0.0, |t| t.translation.vector.z as f32);
        for i in 0..maps.filled.len() {
            let h = maps.filled[i];
            if h.is_nan() || maps.sensor[i] != owner {
                continue;
            }
            stats.cells_evaluated += 1;
            let cost = maps.cost[i];
            let untraversable = maps.absolute[i] || cost >= obstacle;
            if !(untraversable || (graded > 0.0 && cost >= graded)) {
                continue;
            }
            let low = self.lowest[i];
            let (z_min, z_max) = (if low.is_finite() { low } else { h }, h);
            let index = match &own_from_map {
                None => Some(i),
                Some(own_from_map) => {
                    let p = own_from_map
                        * nalgebra::Point3::new(
                            centre(i % cols, maps.origin[0]),
                            centre(i / cols, maps.origin[1]),
                            0.0,
                        );
                    maps.index(p.x as f32, p.y as f32)
                }
            };
            let Some(index) = index else {
                stats.outside_grid += 1;
                continue;
            };
            self.out.marked.push(Marked {
                index: index as u32,
                reasons: if untraversable {
                    Reasons::HEIGHT_DIFFERENCE
                } else {
                    Reasons::NONE
                },
                cost: if untraversable { 1.0 } else { cost / obstacle },
                z_min: z_min + dz,
                z_max: z_max + dz,
            });
        }
    }

    /// The report of image `owner` of the maps built last (lying in the
    /// level frame `map`): its footprint, shadows and drop-offs, and the
    /// cells it gave the height of.
    #[allow(clippy::too_many_arguments)]
    fn report_member(
        &mut self,
        owner: usize,
        outliers: u32,
        image: &RangeImage,
        world_from_vehicle: &Isometry,
        map: &Isometry,
        report: &mut ObstacleReport,
        runner: &dyn Runner,
    ) -> Result<ImageStats, PerceptionError> {
        let mut stats = self.out.start(image, world_from_vehicle, runner, report)?;
        stats.outliers += outliers;
        let (own, _) = grid::level_frames(image, world_from_vehicle);
        self.mark(owner as u8, map, &own, &mut stats);
        self.out
            .finish(image, world_from_vehicle, report, &mut stats);
        Ok(stats)
    }

    /// Gap filling, height differences and costs of the height map, with
    /// AVX2 where the processor has it (the same operations, no fused
    /// multiply-add, so the same maps).
    fn judge_heights(&mut self) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            return unsafe { self.judge_heights_avx2() };
        }
        self.judge_heights_portable();
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn judge_heights_avx2(&mut self) {
        self.judge_heights_portable();
    }

    #[inline(always)]
    fn judge_heights_portable(&mut self) {
        self.fill_gaps();
        self.differences();
        self.costs();
    }

    /// §4.2: fills NaN cells with at least two axis neighbours within δ.
    #[inline(always)]
    fn fill_gaps(&mut self) {
        let (cols, cell) = (self.grid.cols, self.cell);
        let maps = &mut self.maps;
        maps.filled.clone_from(&maps.height);
        let h = &maps.height;
        // Only the box the defined cells span can be filled: a cell beside
        // it has a defined cell on one side along one axis at most.
        let Some(bounds) = defined_box(h, cols) else {
            return;
        };
        let (x0, y0) = (bounds.x0, bounds.y0);
        // Per cell of the box (row-major over it), the box coordinate along
        // its line of the nearest defined cell (NONE: none) before and
        // after it along x, and along y. (A defined cell's own entries are
        // never read.)
        const NONE: u32 = u32::MAX;
        let (w, bh) = (bounds.w, bounds.h);
        let [x_before, x_after, y_before, y_after] = &mut self.scratch.gaps;
        for side in [&mut *x_before, &mut *x_after, &mut *y_before, &mut *y_after] {
            side.clear();
            side.resize(w * bh, NONE);
        }
        let at = |bx: usize, by: usize| (y0 + by) * cols + x0 + bx;
        for by in 0..bh {
            let line = &h[at(0, by)..][..w];
            let (before, after) = (&mut x_before[by * w..][..w], &mut x_after[by * w..][..w]);
            let mut last = NONE;
            for (bx, (v, out)) in line.iter().zip(before).enumerate() {
                last = if v.is_nan() { last } else { bx as u32 };
                *out = last;
            }
            last = NONE;
            for (bx, (v, out)) in line.iter().zip(after).enumerate().rev() {
                last = if v.is_nan() { last } else { bx as u32 };
                *out = last;
            }
        }
        // Along y a whole row at a time, each column's last defined row
        // carried in the row before's entries (so the rows vectorise).
        let rows_of = |by: usize| &h[at(0, by)..][..w];
        sweep_rows(0..bh, w, rows_of, y_before);
        sweep_rows((0..bh).rev(), w, rows_of, y_after);
        let [ox, oy] = maps.origin;
        let (base, per_m) = (self.config.gap_base_m as f32, self.config.gap_per_m as f32);
        for by in 0..bounds.h {
            for bx in 0..bounds.w {
                let i = at(bx, by);
                if !h[i].is_nan() {
                    continue;
                }
                let j = by * w + bx;
                let sides = [x_before[j], x_after[j], y_before[j], y_after[j]];
                if sides.iter().filter(|&&s| s != NONE).count() < 2 {
                    continue;
                }
                // Each side's cell and distance in cells (u16::MAX: none).
                let (mut index, mut distance) = ([0usize; 4], [u16::MAX; 4]);
                let cells = |apart: usize| apart.min(usize::from(u16::MAX - 1)) as u16;
                for (side, &k) in sides.iter().enumerate().filter(|&(_, &k)| k != NONE) {
                    let k = k as usize;
                    (index[side], distance[side]) = if side < 2 {
                        (at(k, by), cells(k.abs_diff(bx)))
                    } else {
                        (at(bx, k), cells(k.abs_diff(by)))
                    };
                }
                let (x, y) = (
                    ox + ((x0 + bx) as f32 + 0.5) * cell,
                    oy + ((y0 + by) as f32 + 0.5) * cell,
                );
                let delta = (base + per_m * x.hypot(y)) / cell;
                // Filled from one sensor only, the nearest neighbour's (the
                // first of the nearest): a value between two sensors'
                // heights would put a step inside each.
                let mut within = [false; 4];
                let mut nearest: Option<usize> = None;
                for side in 0..4 {
                    let d = distance[side];
                    within[side] = d != u16::MAX && f32::from(d) < delta;
                    if within[side] && nearest.is_none_or(|n| d < distance[n]) {
                        nearest = Some(side);
                    }
                }
                let Some(owner) = nearest.map(|side| maps.sensor[index[side]]) else {
                    continue;
                };
                let (mut weight, mut sum, mut found) = (0.0f32, 0.0f32, 0);
                for side in (0..4).filter(|&side| within[side] && maps.sensor[index[side]] == owner)
                {
                    let w = 1.0 / f32::from(distance[side]);
                    weight += w;
                    sum += w * h[index[side]];
                    found += 1;
                }
                if found >= 2 {
                    maps.filled[i] = sum / weight;
                    maps.sensor[i] = owner;
                }
            }
        }
    }

    /// §4.3: D_l for each scale, within each sensor's cells: per sensor,
    /// only over the box its cells span (a camera of a ring sees a wedge).
    #[inline(always)]
    fn differences(&mut self) {
        let (cols, rows) = (self.grid.cols, self.grid.rows);
        let n = cols * rows;
        let maps = &mut self.maps;
        let s = &mut self.scratch;
        // Per sensor: the box of its cells, (x0, x1, y0, y1) inclusive.
        let mut boxes = [(usize::MAX, 0usize, usize::MAX, 0usize); 256];
        // A row's cells of one sensor come in long runs (NaN between them
        // does not end one): a box is updated once per run.
        let mut add = |run: Option<(u8, usize, usize)>, y: usize| {
            if let Some((k, first, last)) = run {
                let b = &mut boxes[usize::from(k)];
                *b = (b.0.min(first), b.1.max(last), b.2.min(y), b.3.max(y));
            }
        };
        let lines = maps
            .sensor
            .chunks_exact(cols)
            .zip(maps.filled.chunks_exact(cols));
        for (y, (sensors, heights)) in lines.enumerate() {
            let mut run: Option<(u8, usize, usize)> = None;
            for (x, (&k, v)) in sensors.iter().zip(heights).enumerate() {
                if v.is_nan() {
                    continue;
                }
                match &mut run {
                    Some((sensor, _, last)) if *sensor == k => *last = x,
                    _ => {
                        add(run, y);
                        run = Some((k, x, x));
                    }
                }
            }
            add(run, y);
        }
        for d in &mut maps.differences {
            d.clear();
            d.resize(n, f32::NAN);
        }
        for (k, &(x0, x1, y0, y1)) in boxes.iter().enumerate() {
            if x0 > x1 {
                continue;
            }
            let k = k as u8;
            let rect = Rect {
                x0,
                y0,
                w: x1 - x0 + 1,
                h: y1 - y0 + 1,
            };
            s.layer.clear();
            for y in y0..=y1 {
                let row = y * cols;
                s.layer.extend((x0..=x1).map(|x| {
                    if maps.sensor[row + x] == k {
                        maps.filled[row + x]
                    } else {
                        f32::NAN
                    }
                }));
            }
            let halves = self.config.scales.map(|scale| scale as usize);
            s.windows.compute(&s.layer, rect.w, rect.h, &halves);
            for (k, d) in maps.differences.iter_mut().enumerate() {
                let (max, min, count) = (s.windows.max(k), s.windows.min(k), s.windows.count(k));
                for (r, line) in s.layer.chunks_exact(rect.w).enumerate() {
                    let out = &mut d[(rect.y0 + r) * cols + rect.x0..][..rect.w];
                    let j = r * rect.w;
                    let windows = max[j..][..rect.w]
                        .iter()
                        .zip(&min[j..][..rect.w])
                        .zip(&count[j..][..rect.w]);
                    // Each cell is its own sensor's: written from one box
                    // only (a select, so that it vectorises).
                    for ((o, &h), ((&max, &min), &count)) in out.iter_mut().zip(line).zip(windows) {
                        let (up, down) = (max - h, h - min);
                        let d = if up > down { up } else { down };
                        *o = if !h.is_nan() && count >= 2 { d } else { *o };
                    }
                }
            }
        }
    }

    /// §5.1: D̃, absolute obstacles and D_D.
    #[inline(always)]
    fn costs(&mut self) {
        let (cols, rows, cell) = (self.grid.cols, self.grid.rows, self.cell);
        let n = cols * rows;
        let c = &self.config;
        let maps = &mut self.maps;
        maps.cost.clear();
        maps.cost.resize(n, f32::NAN);
        maps.absolute.clear();
        maps.absolute.resize(n, false);
        // A scale at a time over the whole map, with no branch (it
        // vectorises); per cell the scales are added in order.
        let cap = c.cap as f32;
        for (d, &lambda) in maps.differences.iter().zip(&c.weights) {
            let cells = maps.cost.iter_mut().zip(maps.absolute.iter_mut());
            for ((total, absolute), &d) in cells.zip(d) {
                let weighted = lambda as f32 * d;
                *absolute |= weighted >= 1.0;
                let sum = if total.is_nan() { 0.0 } else { *total } + weighted.min(cap);
                *total = if weighted.is_nan() { *total } else { sum };
            }
        }
        // D_D: absolute obstacles inflated by the robot radius, then the
        // larger of D̃ and its local mean over a square of the disc's area.
        maps.drivability.clone_from(&maps.cost);
        let radius = (c.robot_radius_m as f32 / cell).round() as usize;
        // A point within the radius of an absolute cell is within it of
        // one on its region's edge (or is absolute itself): only edges stamp.
        let absolute = &maps.absolute;
        let edge = |x: usize, y: usize, i: usize| {
            x == 0
                || y == 0
                || x + 1 == cols
                || y + 1 == rows
                || !(absolute[i - 1] && absolute[i + 1] && absolute[i - cols] && absolute[i + cols])
        };
        let mut edges = std::mem::take(&mut self.scratch.edges);
        edges.clear();
        for (y, line) in absolute.chunks_exact(cols).enumerate() {
            if !line.contains(&true) {
                continue;
            }
            for (x, _) in line.iter().enumerate().filter(|&(_, &a)| a) {
                let i = y * cols + x;
                if edge(x, y, i) {
                    edges.push(i);
                }
            }
        }
        // The disc's half width on each row of it.
        let mut spans = std::mem::take(&mut self.scratch.spans);
        spans.clear();
        spans.extend((0..=radius).map(|dy| (radius * radius - dy * dy).isqrt()));
        for &i in &edges {
            let (x, y) = (i % cols, i / cols);
            for v in y.saturating_sub(radius)..(y + radius + 1).min(rows) {
                let half = spans[v.abs_diff(y)];
                let row = v * cols;
                let span = row + x.saturating_sub(half)..row + (x + half + 1).min(cols);
                let costs = &maps.cost[span.clone()];
                for (d, &cost) in maps.drivability[span].iter_mut().zip(costs) {
                    *d = d.max(1.0).max(cost);
                }
            }
        }
        self.scratch.edges = edges;
        self.scratch.spans = spans;
        let half =
            ((c.robot_radius_m as f32 / cell) * std::f32::consts::PI.sqrt() / 2.0).round() as usize;
        // Summed-area tables of D̃ and of its defined cells, over the box
        // that holds defined cells (outside it every window adds nothing).
        let Some(b) = defined_box(&maps.cost, cols) else {
            return;
        };
        let s = &mut self.scratch;
        let w = b.w + 1;
        s.sums.clear();
        s.sums.resize(w * (b.h + 1), 0.0);
        s.counts.clear();
        s.counts.resize(w * (b.h + 1), 0);
        for y in 0..b.h {
            let line = &maps.cost[(b.y0 + y) * cols + b.x0..][..b.w];
            let (above, here) = s.sums.split_at_mut((y + 1) * w);
            let (counts_above, counts_here) = s.counts.split_at_mut((y + 1) * w);
            let (mut sum, mut count) = (0.0, 0);
            for x in 0..b.w {
                let v = line[x];
                if !v.is_nan() {
                    sum += f64::from(v);
                    count += 1;
                }
                here[x + 1] = sum + above[y * w + x + 1];
                counts_here[x + 1] = count + counts_above[y * w + x + 1];
            }
        }
        for y in 0..b.h {
            let (y0, y1) = (y.saturating_sub(half), (y + half + 1).min(b.h));
            for x in 0..b.w {
                let i = (b.y0 + y) * cols + b.x0 + x;
                if maps.cost[i].is_nan() {
                    continue;
                }
                let (x0, x1) = (x.saturating_sub(half), (x + half + 1).min(b.w));
                let box_of =
                    |t: &[f64]| t[y1 * w + x1] - t[y0 * w + x1] - t[y1 * w + x0] + t[y0 * w + x0];
                let count = s.counts[y1 * w + x1] + s.counts[y0 * w + x0]
                    - s.counts[y0 * w + x1]
                    - s.counts[y1 * w + x0];
                let mean = box_of(&s.sums) / f64::from(count.max(1));
                maps.drivability[i] = maps.drivability[i].max(mean as f32);
            }
        }
    }
}

/// For each cell of a `w`-wide box whose rows are `line(by)`, taken in the
/// order `rows`: the last row in that order, itself included, in which its
/// column was defined (`u32::MAX`: none), into `out` (row-major, `w` wide).
#[inline(always)]
fn sweep_rows<'a>(
    mut rows: impl Iterator<Item = usize>,
    w: usize,
    line: impl Fn(usize) -> &'a [f32],
    out: &mut [u32],
) {
    let Some(mut previous) = rows.next() else {
        return;
    };
    for (v, o) in line(previous).iter().zip(&mut out[previous * w..][..w]) {
        *o = if v.is_nan() {
            u32::MAX
        } else {
            previous as u32
        };
    }
    for by in rows {
        let (here, carried) = if previous < by {
            let (a, b) = out.split_at_mut(by * w);
            (&mut b[..w], &a[previous * w..][..w])
        } else {
            let (a, b) = out.split_at_mut(previous * w);
            (&mut a[by * w..][..w], &b[..w])
        };
        for ((v, o), &c) in line(by).iter().zip(here).zip(carried) {
            *o = if v.is_nan() { c } else { by as u32 };
        }
        previous = by;
    }
}

/// The median window for `image`'s beam spacing: half sizes in rows
/// and columns.
fn median_params(config: &HeightDiffConfig, max_range: f32, image: &RangeImage) -> MedianParams {
    let half = |angles: &[f32]| {
        let n = angles.len();
        if n < 2 {
            return 0;
        }
        let spacing = ((angles[n - 1] - angles[0]) / (n - 1) as f32)
            .abs()
            .to_degrees();
        // The largest odd number of pixels within the window's angle.
        let pixels = config.median_window_deg as f32 / spacing.max(1e-6);
        (((pixels - 1.0) / 2.0).floor().max(0.0) as usize).min(16)
    };
    MedianParams {
        half_rows: half(&image.beams.elevation),
        half_cols: half(&image.beams.azimuth),
        max_range,
        abs: config.outlier_m as f32,
        rel: config.outlier_fraction as f32,
    }
}

/// A box of grid cells.
#[derive(Debug, Clone, Copy)]
struct Rect {
    x0: usize,
    y0: usize,
    w: usize,
    h: usize,
}

/// The box the defined (not NaN) cells of a `cols`-wide grid (row-major)
/// span; `None` when none is.
fn defined_box(layer: &[f32], cols: usize) -> Option<Rect> {
    let (mut x0, mut x1, mut y0, mut y1) = (usize::MAX, 0, usize::MAX, 0);
    for (y, line) in layer.chunks_exact(cols).enumerate() {
        let Some(first) = line.iter().position(|v| !v.is_nan()) else {
            continue;
        };
        let last = line.iter().rposition(|v| !v.is_nan()).unwrap_or(first);
        (x0, x1, y0, y1) = (x0.min(first), x1.max(last), y0.min(y), y1.max(y));
    }
    (x0 <= x1).then(|| Rect {
        x0,
        y0,
        w: x1 - x0 + 1,
        h: y1 - y0 + 1,
    })
}

impl TerrainEvaluator for HeightDiff {
    fn name(&self) -> &'static str {
        "height_diff"
    }

    /// The largest scale's window, the gap filling's reach at the farthest
    /// return (δ = δ0 + Δ·r), the obstacles' inflation by the robot's
    /// radius, and the median window in beam angle.
    fn support(&self) -> crate::Support {
        let c = &self.config;
        let largest = f64::from(c.scales.iter().copied().max().unwrap_or(1)) * c.cell_size_m;
        let gap = c.gap_base_m + c.gap_per_m * f64::from(self.max_range);
        crate::Support {
            metres: (largest + gap + c.robot_radius_m) * std::f64::consts::SQRT_2,
            pixels: 1,
            radians: c.median_window_deg.to_radians(),
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
        self.build_maps(&[image], world_from_vehicle, &mut stats)?;
        let (level, _) = grid::level_frames(image, world_from_vehicle);
        self.mark(0, &level, &level, &mut stats);
        self.out
            .finish(image, world_from_vehicle, report, &mut stats);
        Ok(stats)
    }

    /// One height map from every valid image (000 §4.1), in the level
    /// frame of the newest image's capture pose, each image's returns
    /// placed with its own pose; differences within each image's cells
    /// (§4.3); each image reports the cells its returns gave the height of,
    /// and its own footprint, shadows and drop-offs.
    fn evaluate_fused(
        &mut self,
        images: &[(&RangeImage, &Isometry)],
        reports: &mut [ObstacleReport],
        runner: &dyn Runner,
    ) -> Vec<Result<ImageStats, PerceptionError>> {
        // The images the map is built of (at most 255: a cell names its
        // image in a byte), by index into `images`.
        let mut members = Vec::with_capacity(images.len());
        let mut results: Vec<Result<ImageStats, PerceptionError>> =
            Vec::with_capacity(images.len());
        for (k, (image, _)) in images.iter().enumerate() {
            let valid = image.validate();
            if valid.is_ok() && !image.range.is_empty() && members.len() < usize::from(u8::MAX) {
                members.push(k);
            }
            results.push(
                valid
                    .map(|()| ImageStats::default())
                    .map_err(PerceptionError::from),
            );
        }
        let Some(&newest) = members.iter().max_by_key(|&&k| images[k].0.utime) else {
            // Nothing to build a map of: each image as it is.
            return crate::evaluator::evaluate_each(self, images, reports, runner);
        };
        let (map, _) = grid::level_frames(images[newest].0, images[newest].1);
        let map_from_world = map.inverse();
        let member_images: Vec<&RangeImage> = members.iter().map(|&k| images[k].0).collect();
        let mut outliers = vec![0; members.len()];
        self.bin(
            &member_images,
            |j| {
                let (image, pose) = images[members[j]];
                map_from_world * pose * image.vehicle_from_sensor
            },
            |j, n| outliers[j] = n,
        );
        self.judge_heights();
        for (k, ((image, pose), report)) in images.iter().zip(reports).enumerate() {
            let owner = members.iter().position(|&m| m == k);
            let result = match (owner, &results[k]) {
                (Some(j), Ok(_)) => {
                    self.report_member(j, outliers[j], image, pose, &map, report, runner)
                }
                // Valid but empty: its report says so.
                (None, Ok(_)) => self.evaluate_with(image, pose, report, runner),
                (_, Err(_)) => continue,
            };
            results[k] = result;
        }
        results
    }
}
