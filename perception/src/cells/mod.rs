//! The per-image cell classifier of 002 §4 ("early traversability evaluation").
//!
//! Every valid pixel is projected into the gravity-aligned vehicle frame of
//! the capture pose (x forward, y left, z up; the pose's roll and pitch
//! removed) and, if it falls in the evaluated region around the vehicle
//! (`[perception.region]`), binned into a grid of 20 cm cells. Per cell it keeps the point
//! count, min/max z and the sums of a least-squares plane. A cell is
//! untraversable for
//!
//! - (a) **height variation**: its points span more than the tolerated step;
//! - (b) **slope**: its fitted plane is steeper than the vehicle's limit;
//! - (c) **discontinuity**: the heights of a neighbouring cell lie more than
//!   the tolerated step above or below its own;
//!
//! (a) and (b) only with at least 5 points, "to avoid frequent erroneous
//! classification". And, what a cell's own points cannot show:
//!
//! - (d) **drop-off**: it holds the near edge of ground the image did not see,
//!   wider than the vehicle bridges, beyond which the ground drops away (see
//!   `DropOffRule::judge`). Each image column is walked from its highest
//!   beam down, far returns to near ones, while the rows are binned.
//!
//! Untraversable cells are grouped into 8-connected regions. Only cells
//! with data are evaluated; nothing is interpolated; nothing is carried
//! from one image to the next.
//!
//! Work is proportional to the valid pixels: the grid itself is only a map
//! from cell to slot (4 bytes a cell, so it stays in cache); the
//! accumulators of the cells an image touches live densely in touch order,
//! and only those are evaluated and reset. Beam directions are
//! separable (`cos el·(cos az, sin az) , sin el`), so per image only one
//! 3-vector per column and per row is computed.

use arcnav_vehicle::Isometry;
use arcnav_vehicle::frames::{level_frame, wrap_angle};

use crate::config::{GridShape, PerceptionConfig};
use crate::evaluator::{
    ImageStats, InOrder, ObstacleCell, ObstacleReport, PerceptionError, Reasons, Region, Runner,
    TerrainEvaluator,
};
use crate::fov::FovBuilder;
use crate::image::RangeImage;
use crate::shadow::Shadow;

mod cell;
mod projection;

use cell::{BeamTrig, Cell, PlaneSums};
use projection::{Bins, DropOffRule, EMPTY_SLOT, PARALLEL_MIN_PIXELS, PARTS, Projection};

/// The 002 §4 classifier. Build it with [`PerceptionConfig::build_evaluator`]
/// or [`CellClassifier::new`].
pub struct CellClassifier {
    cell_size: f32,
    /// Half the slope window, cells.
    slope_radius: usize,
    min_points: u32,
    max_height_variation: f32,
    max_slope_tan2: f64,
    max_discontinuity: f32,
    min_plane_variance: f64,
    min_range: f32,
    max_range: f32,
    fov_max_vertices: usize,
    /// `[perception.drop_off]`, without a beam order: each image's binning
    /// uses it with the order of its rows.
    drop_off: DropOffRule<'static>,
    /// Grid indices of this image's drop-off cells (the parts' merged).
    drop_offs: Vec<u32>,
    /// Grid indices of this image's suspected drop-off cells (the parts'
    /// merged), and the cost they are reported at.
    suspects: Vec<u32>,
    suspect_cost: f32,
    /// This image's shadows (the parts' merged): (column, edge, beyond).
    shadows: Vec<(u32, f32, f32)>,
    /// The sensor's position in the level frame, this image.
    sensor_xy: [f32; 2],
    /// The grid over the region, in the level frame. Points are binned only
    /// `grid.margin` cells away from its edge, so every neighbour a window
    /// reaches exists.
    grid: GridShape,
    /// Index offsets of the slope window's cells, with their (dx, dy) in metres.
    window: Vec<(isize, f32, f32)>,
    /// Index offsets of a cell's eight neighbours.
    neighbours: [isize; 8],
    /// The parts' bins; the first holds the whole image once merged.
    bins: [Bins; PARTS],
    /// Per touched cell (same slot as in `bins[0]`): its reasons and its region.
    labels: Vec<(Reasons, u32)>,
    queue: Vec<u32>,
    trig: BeamTrig,
    column_terms: [Vec<f32>; 3],
    fov: FovBuilder,
}

impl CellClassifier {
    /// A classifier with a grid covering `max_range_m` around the sensor.
    pub fn new(config: &PerceptionConfig) -> Self {
        let c = &config.cells;
        let cell_size = c.cell_size_m as f32;
        let grid = config.grid();
        let radius = (c.slope_window_cells / 2) as isize;
        let s = grid.cols as isize;
        let window = (-radius..=radius)
            .flat_map(|dy| {
                (-radius..=radius)
                    .map(move |dx| (dy * s + dx, dx as f32 * cell_size, dy as f32 * cell_size))
            })
            .collect();
        Self {
            slope_radius: radius as usize,
            cell_size,
            min_points: c.min_points,
            max_height_variation: c.max_height_variation_m as f32,
            max_slope_tan2: if c.slope {
                c.max_slope_deg.to_radians().tan().powi(2)
            } else {
                f64::INFINITY
            },
            max_discontinuity: c.max_discontinuity_m as f32,
            min_plane_variance: c.min_plane_spread_m * c.min_plane_spread_m,
            min_range: config.min_range_m as f32,
            max_range: config.max_range_m as f32,
            fov_max_vertices: config.fov_max_vertices,
            drop_off: {
                let d = &config.drop_off;
                DropOffRule {
                    max_gap: if d.enabled {
                        d.max_gap_m
                    } else {
                        f64::INFINITY
                    } as f32,
                    min_depth: d.min_depth_m as f32,
                    depth_per_m: d.depth_per_m as f32,
                    noise: d.noise_m as f32,
                    tan_slope: c.max_slope_deg.to_radians().tan() as f32,
                    suspects: d.suspect_cost > 0.0,
                    order: &[],
                }
            },
            drop_offs: Vec::new(),
            suspects: Vec::new(),
            suspect_cost: config.drop_off.suspect_cost as f32,
            shadows: Vec::new(),
            sensor_xy: [0.0; 2],
            grid,
            window,
            neighbours: [-s - 1, -s, -s + 1, -1, 1, s - 1, s, s + 1],
            bins: std::array::from_fn(|_| Bins::new(grid.cols * grid.rows)),
            labels: Vec::new(),
            queue: Vec::new(),
            trig: BeamTrig::default(),
            column_terms: Default::default(),
            fov: FovBuilder::default(),
        }
    }

    /// Projects and bins every valid pixel, the parts through `runner`.
    fn bin(
        &mut self,
        image: &RangeImage,
        level_from_sensor: &Isometry,
        runner: &dyn Runner,
        stats: &mut ImageStats,
    ) {
        self.trig
            .update(&image.beams.elevation, &image.beams.azimuth);
        let rotation = level_from_sensor.rotation.to_rotation_matrix();
        let m = rotation.matrix();
        let column = |i: usize| [m[(0, i)] as f32, m[(1, i)] as f32, m[(2, i)] as f32];
        let (r0, r1, r2) = (column(0), column(1), column(2));
        let t = level_from_sensor.translation.vector;
        let t = [t.x as f32, t.y as f32, t.z as f32];
        let cols = image.cols();
        for (axis, terms) in self.column_terms.iter_mut().enumerate() {
            terms.clear();
            terms.extend(
                self.trig
                    .cos_az
                    .iter()
                    .zip(&self.trig.sin_az)
                    .map(|(&ca, &sa)| ca * r0[axis] + sa * r1[axis]),
            );
        }
        let projection = Projection {
            ranges: &image.range,
            cols,
            cos_el: &self.trig.cos_el,
            sin_el: &self.trig.sin_el,
            column_terms: &self.column_terms,
            r2,
            t,
            cell_size: self.cell_size,
            offset: self.grid.corner,
            stride: self.grid.cols,
            lo: [self.grid.margin as f32; 2],
            hi: [
                (self.grid.cols - self.grid.margin) as f32,
                (self.grid.rows - self.grid.margin) as f32,
            ],
            min_range: self.min_range.max(f32::MIN_POSITIVE),
            max_range: self.max_range,
            drop_off: DropOffRule {
                order: &self.trig.order,
                ..self.drop_off
            },
        };
        let parts: [std::ops::Range<usize>; PARTS] =
            std::array::from_fn(|k| cols * k / PARTS..cols * (k + 1) / PARTS);
        let [first, second] = &mut self.bins;
        let (left, right) = (parts[0].clone(), parts[1].clone());
        let mut tasks: [&mut (dyn FnMut() + Send); PARTS] =
            [&mut || projection.bin(left.clone(), first), &mut || {
                projection.bin(right.clone(), second)
            }];
        runner.run(&mut tasks);
        // Far and near return of each column, for the field of view.
        self.fov.start(cols, [t[0], t[1]]);
        for (bins, columns) in self.bins.iter().zip(&parts) {
            for (i, &(top, bottom)) in bins.column_rows.iter().enumerate() {
                if top == u32::MAX {
                    continue;
                }
                let col = columns.start + i;
                let u = self.column_terms.each_ref().map(|terms| terms[col]);
                for row in [top, bottom] {
                    let row = row as usize;
                    let (ce, se) = (self.trig.cos_el[row], self.trig.sin_el[row]);
                    let range = image.range[row * cols + col];
                    let x = (ce * u[0] + se * r2[0]) * range + t[0];
                    let y = (ce * u[1] + se * r2[1]) * range + t[1];
                    self.fov.add(col, x, y);
                }
            }
        }
        self.drop_offs.clear();
        self.suspects.clear();
        self.shadows.clear();
        for bins in &self.bins {
            self.drop_offs.extend_from_slice(&bins.found.drop_offs);
            self.suspects.extend_from_slice(&bins.found.suspects);
            self.shadows.extend_from_slice(&bins.found.shadows);
        }
        self.sensor_xy = [t[0], t[1]];
        let (first, rest) = self.bins.split_at_mut(1);
        for other in rest {
            first[0].absorb(other);
        }
        let [no_return, out_of_range, outside_grid, valid] = first[0].counts;
        stats.no_return += no_return;
        stats.out_of_range += out_of_range;
        stats.outside_grid += outside_grid;
        stats.valid_points += valid;
    }

    /// The slot of the cell `offset` grid indices away from `cell`, if it
    /// holds points. Binned cells keep a margin from the edge, so every
    /// offset of the window stays inside the grid.
    #[inline]
    fn neighbour(&self, cell: &Cell, offset: isize) -> Option<usize> {
        let slot = *self.bins[0]
            .slots
            .get((cell.index as isize + offset) as usize)?;
        (slot != EMPTY_SLOT).then_some(slot as usize)
    }

    /// Plane sums of the slope window around `cell`.
    fn window_sums(&self, cell: &Cell) -> PlaneSums {
        let mut sums = PlaneSums::default();
        for &(offset, ox, oy) in &self.window {
            if let Some(slot) = self.neighbour(cell, offset) {
                sums.add(&self.bins[0].cells[slot], ox, oy);
            }
        }
        sums
    }

    /// Applies criteria (a), (b), (c) to every touched cell.
    fn classify(&mut self, runner: &dyn Runner, stats: &mut ImageStats) {
        self.labels.clear();
        let cells = self.bins[0].cells.len();
        self.labels.resize(cells, (Reasons::NONE, u32::MAX));
        // Each cell is judged on its own (a jump between two cells marks
        // both, as each sees it): the halves may run at once.
        let mut labels = std::mem::take(&mut self.labels);
        let half = cells / 2;
        let (low, high) = labels.split_at_mut(half);
        let this = &*self;
        runner.run(&mut [&mut || this.judge(0, low), &mut || this.judge(half, high)]);
        self.labels = labels;
        for &index in &self.drop_offs {
            let slot = self.bins[0].slots[index as usize];
            self.labels[slot as usize].0.insert(Reasons::DROP_OFF);
        }
        for &(reasons, _) in &self.labels {
            stats.cells_evaluated += 1;
            if !reasons.is_empty() {
                stats.untraversable += 1;
                for (count, (reason, _)) in stats.by_reason.iter_mut().zip(Reasons::ALL) {
                    *count += u32::from(reasons.contains(reason));
                }
            }
        }
    }

    /// Applies (a), (b), (c) to the cells from slot `first` on, one per label
    /// (with AVX2 where the processor has it, as in [`Projection::bin`]).
    fn judge(&self, first: usize, labels: &mut [(Reasons, u32)]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            return unsafe { self.judge_avx2(first, labels) };
        }
        self.judge_portable(first, labels);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn judge_avx2(&self, first: usize, labels: &mut [(Reasons, u32)]) {
        self.judge_portable(first, labels);
    }

    #[inline(always)]
    fn judge_portable(&self, first: usize, labels: &mut [(Reasons, u32)]) {
        let cells = &self.bins[0].cells[first..];
        for (cell, label) in cells.iter().zip(labels) {
            let jump = self.neighbours.iter().any(|&offset| {
                self.neighbour(cell, offset).is_some_and(|n| {
                    let neighbour = &self.bins[0].cells[n];
                    let gap = (neighbour.z_min - cell.z_max).max(cell.z_min - neighbour.z_max);
                    gap > self.max_discontinuity
                })
            });
            if jump {
                label.0.insert(Reasons::DISCONTINUITY);
            }
            if cell.count < self.min_points {
                continue;
            }
            if cell.z_max - cell.z_min > self.max_height_variation {
                label.0.insert(Reasons::HEIGHT_VARIATION);
            }
            if self
                .window_sums(cell)
                .slope_tan2(self.min_plane_variance)
                .is_some_and(|tan2| tan2 > self.max_slope_tan2)
            {
                label.0.insert(Reasons::SLOPE);
            }
        }
    }

    /// Groups untraversable cells into 8-connected regions and writes them,
    /// in the world frame, into `report`.
    fn emit(
        &mut self,
        world_from_level: &Isometry,
        report: &mut ObstacleReport,
        stats: &mut ImageStats,
    ) {
        for seed in 0..self.bins[0].cells.len() {
            if self.labels[seed].0.is_empty() || self.labels[seed].1 != u32::MAX {
                continue;
            }
            let region = report.regions.len() as u32;
            let mut summary = Region {
                cells: 0,
                reasons: Reasons::NONE,
            };
            self.queue.clear();
            self.queue.push(seed as u32);
            self.labels[seed].1 = region;
            while let Some(slot) = self.queue.pop() {
                let cell = self.bins[0].cells[slot as usize];
                summary.cells += 1;
                summary.reasons.insert(self.labels[slot as usize].0);
                for offset in self.neighbours {
                    let Some(n) = self.neighbour(&cell, offset) else {
                        continue;
                    };
                    let label = &mut self.labels[n];
                    if !label.0.is_empty() && label.1 == u32::MAX {
                        label.1 = region;
                        self.queue.push(n as u32);
                    }
                }
            }
            report.regions.push(summary);
        }
        let (sin, cos) = arcnav_vehicle::frames::yaw_of(world_from_level).sin_cos();
        let origin = world_from_level.translation.vector;
        let [ox, oy] = self.grid.corner;
        let (cols, size) = (self.grid.cols, self.cell_size);
        let world = |cell: &Cell, reasons, region, cost| {
            let (ix, iy) = (cell.index as usize % cols, cell.index as usize / cols);
            let cx = f64::from((ix as f32 + 0.5 - ox) * size);
            let cy = f64::from((iy as f32 + 0.5 - oy) * size);
            ObstacleCell {
                x: origin.x + cos * cx - sin * cy,
                y: origin.y + sin * cx + cos * cy,
                z_min: cell.z_min + origin.z as f32,
                z_max: cell.z_max + origin.z as f32,
                reasons,
                region,
                cost,
            }
        };
        for (cell, &(reasons, region)) in self.bins[0].cells.iter().zip(&self.labels) {
            if !reasons.is_empty() {
                report.cells.push(world(cell, reasons, region, 1.0));
            }
        }
        // Suspected drop-offs on cells judged traversable: graded ground
        // with the reason drop-off, in one region of their own.
        self.suspects.sort_unstable();
        self.suspects.dedup();
        let region = report.regions.len() as u32;
        let mut graded = 0;
        for &index in &self.suspects {
            let slot = self.bins[0].slots[index as usize] as usize;
            if self.labels[slot].0.is_empty() {
                let cell = &self.bins[0].cells[slot];
                report
                    .cells
                    .push(world(cell, Reasons::DROP_OFF, region, self.suspect_cost));
                graded += 1;
            }
        }
        if graded > 0 {
            report.regions.push(Region {
                cells: graded,
                reasons: Reasons::NONE,
            });
        }
        stats.graded += graded;
        stats.suspected += graded;
        stats.regions = report.regions.len() as u32;
    }

    /// Writes the image's shadows, in the world frame, into `report`. A
    /// column's sector reaches halfway to the farther of its neighbours'
    /// directions (in the level frame, where a tilted sensor's columns
    /// spread wider than in its own).
    fn emit_shadows(&self, world_from_level: &Isometry, report: &mut ObstacleReport) {
        let [ux, uy, _] = &self.column_terms;
        let cols = ux.len();
        // The angle between the horizontal directions of two columns, as
        // its sine (columns are well under 0.1 rad apart): no trigonometry.
        let between = |a: usize, b: usize| {
            let cross = ux[a] * uy[b] - uy[a] * ux[b];
            cross.abs() / (ux[a].hypot(uy[a]) * ux[b].hypot(uy[b]))
        };
        let yaw = arcnav_vehicle::frames::yaw_of(world_from_level);
        let origin = world_from_level
            * nalgebra::Point3::new(
                f64::from(self.sensor_xy[0]),
                f64::from(self.sensor_xy[1]),
                0.0,
            );
        report.shadows.origin = nalgebra::Point2::new(origin.x, origin.y);
        for &(col, near, far) in &self.shadows {
            let col = col as usize;
            let spacing = [col.checked_sub(1), (col + 1 < cols).then_some(col + 1)]
                .into_iter()
                .flatten()
                .map(|n| between(col, n))
                .fold(0.0f32, f32::max);
            report.shadows.sectors.push(Shadow {
                azimuth: wrap_angle(f64::from(uy[col].atan2(ux[col])) + yaw) as f32,
                // A hair wider, so neighbouring columns' sectors overlap
                // rather than leave a rounding gap between them.
                half_width: (0.51 * spacing).min(Shadow::MAX_HALF_WIDTH),
                near,
                far,
            });
        }
    }

    fn reset_touched(&mut self) {
        let bins = &mut self.bins[0];
        for cell in &bins.cells {
            bins.slots[cell.index as usize] = EMPTY_SLOT;
        }
        bins.cells.clear();
    }
}

impl crate::plugin::EvaluatorPlugin for CellClassifier {
    const NAME: &'static str = "cells";
    const ABOUT: &'static str =
        "per-cell height variation, slope and discontinuity (002, Langer, Rosenblatt & Hebert)";
    type Config = crate::config::CellsConfig;

    /// `[perception.cells]`, checked with the rest of `[perception]`.
    fn config(perception: &PerceptionConfig) -> Result<Self::Config, arcnav_vehicle::ConfigError> {
        Ok(perception.cells.clone())
    }

    fn build(_: Self::Config, perception: &PerceptionConfig) -> Self {
        Self::new(perception)
    }
}

impl TerrainEvaluator for CellClassifier {
    fn name(&self) -> &'static str {
        "cells"
    }

    /// A cell's own returns, its slope window's and its neighbours' (the
    /// discontinuity), each a cell diagonal from its centre at most. The
    /// drop-off rule looks along the cell's own columns only.
    fn support(&self) -> crate::Support {
        let cells = (self.slope_radius + 2) as f64;
        crate::Support {
            metres: cells * f64::from(self.cell_size) * std::f64::consts::SQRT_2,
            pixels: 1,
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
        report.clear();
        image.validate()?;
        report.utime = image.utime;
        report.sensor.push_str(&image.sensor);
        report.cell_size_m = f64::from(self.cell_size);
        let mut stats = ImageStats {
            pixels: image.range.len() as u32,
            ..ImageStats::default()
        };
        if image.range.is_empty() {
            return Ok(stats);
        }
        let world_from_level = level_frame(world_from_vehicle);
        let level_from_sensor =
            world_from_level.inverse() * world_from_vehicle * image.vehicle_from_sensor;
        let runner: &dyn Runner = if image.range.len() >= PARALLEL_MIN_PIXELS {
            runner
        } else {
            &InOrder
        };
        self.bin(image, &level_from_sensor, runner, &mut stats);
        self.classify(runner, &mut stats);
        self.emit(&world_from_level, report, &mut stats);
        self.fov
            .finish(&world_from_level, self.fov_max_vertices, &mut report.fov);
        self.emit_shadows(&world_from_level, report);
        self.reset_touched();
        Ok(stats)
    }
}
