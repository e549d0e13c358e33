//! Height measurements for the local map's elevation layer (004 §III).
//!
//! Whatever evaluator judges an image, the local map also keeps a
//! robot-centric elevation map with a Kalman mean and variance per cell
//! (004 eqs. 1–4). Its measurements come from here: every return of the
//! image inside `[perception.region]` is placed in a world-aligned grid of
//! `[perception.heights] cell_size_m`, and each cell the image hit yields
//! one measurement h_t with a variance σ_t²:
//!
//! - h_t is the highest return in the cell: the surface a wheel or the
//!   chassis meets (a 30 cm rock that fills a quarter of the cell is 30 cm
//!   high to a tyre, not 7 cm as a mean would make it). Noise makes the
//!   maximum of n returns read a little high; the bias is the same on all
//!   ground, so slopes and heights above the ground under the wheels are
//!   unaffected.
//! - σ_t² = σ_r² + (r·σ_θ)², with σ_r the sensor's range noise and σ_θ the
//!   error of the pose's attitude (a tilt error of σ_θ moves a return at
//!   range r by r·σ_θ vertically): far returns count less, as in the
//!   elevation mapping 004 builds on (Fankhauser et al., 2014).
//!
//! A cell is world-aligned, so the same square of ground gets the same
//! index from every image and every sensor: the local map fuses the
//! measurements without resampling.

use arcnav_vehicle::Isometry;

use crate::config::{HeightsConfig, RegionConfig};
use crate::evaluator::{HeightSample, ImageStats, ObstacleReport};
use crate::grid::{Projector, RowPoints, level_frames};
use crate::image::RangeImage;

#[derive(Debug, Clone, Copy)]
struct Bin {
    z: f32,
    range: f32,
}

const EMPTY: Bin = Bin {
    z: f32::NEG_INFINITY,
    range: 0.0,
};

/// Turns images into [`HeightSample`]s. Allocates nothing once warmed up to
/// the image and region size.
#[derive(Debug, Default)]
pub struct HeightSampler {
    config: HeightsConfig,
    region: RegionConfig,
    min_range: f32,
    max_range: f32,
    projector: Projector,
    bins: Vec<Bin>,
    /// One bit a bin, set when the bin is first raised: read word by word,
    /// the touched bins come out in row-major order with no sort.
    touched: Vec<u64>,
    /// A row's cells by column (u32::MAX: none).
    row_cells: Vec<u32>,
    /// A row's points.
    points: RowPoints,
    /// Bins without AVX2 whatever the processor has: the tests compare.
    #[cfg(test)]
    portable_only: bool,
}

impl HeightSampler {
    pub fn new(
        config: &HeightsConfig,
        region: &RegionConfig,
        min_range: f64,
        max_range: f64,
    ) -> Self {
        Self {
            config: config.clone(),
            region: region.clone(),
            min_range: min_range as f32,
            max_range: max_range as f32,
            ..Self::default()
        }
    }

    pub fn config(&self) -> &HeightsConfig {
        &self.config
    }

    /// Appends the measurements of `image`, taken at `world_from_vehicle`,
    /// to `report.heights` (in row-major world cell order).
    pub fn sample(
        &mut self,
        image: &RangeImage,
        world_from_vehicle: &Isometry,
        report: &mut ObstacleReport,
    ) {
        report.heights_cell_m = self.config.cell_size_m;
        if !self.config.enabled {
            return;
        }
        let out = &mut report.heights;
        let cell = self.config.cell_size_m;
        let (world_from_level, level_from_sensor) = level_frames(image, world_from_vehicle);
        let t = world_from_level.translation.vector;
        let yaw = arcnav_vehicle::frames::yaw_of(&world_from_level);
        let (sin, cos) = yaw.sin_cos();
        // The region's corners in the world give the grid's bounds.
        let r = &self.region;
        let corners = [
            (r.ahead_m, r.half_width_m),
            (r.ahead_m, -r.half_width_m),
            (-r.behind_m, r.half_width_m),
            (-r.behind_m, -r.half_width_m),
        ];
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for (x, y) in corners {
            let w = [t.x + cos * x - sin * y, t.y + sin * x + cos * y];
            for a in 0..2 {
                lo[a] = lo[a].min(w[a]);
                hi[a] = hi[a].max(w[a]);
            }
        }
        let i0 = (lo[0] / cell).floor() as i64;
        let j0 = (lo[1] / cell).floor() as i64;
        let cols = ((hi[0] / cell).floor() as i64 - i0 + 1).max(1) as usize;
        let rows = ((hi[1] / cell).floor() as i64 - j0 + 1).max(1) as usize;
        if self.bins.len() < cols * rows {
            self.bins.resize(cols * rows, EMPTY);
        }
        // Only the words covering this grid: the rest stay clear.
        let words = (cols * rows).div_ceil(64);
        if self.touched.len() < words {
            self.touched.resize(words, 0);
        }
        // Points are binned relative to the grid's corner in f32.
        let grid = HeightGrid {
            corner: [
                (t.x - i0 as f64 * cell) as f32,
                (t.y - j0 as f64 * cell) as f32,
            ],
            sin_cos: [sin as f32, cos as f32],
            inverse: (1.0 / cell) as f32,
            region: [r.ahead_m as f32, r.behind_m as f32, r.half_width_m as f32],
            tz: t.z as f32,
            cols,
            rows,
        };
        self.bin(image, &level_from_sensor, &grid, words);
        let (bins, touched) = (&mut self.bins, &mut self.touched[..words]);
        out.reserve(touched.iter().map(|w| w.count_ones() as usize).sum());
        for (w, word) in touched.iter_mut().enumerate() {
            let mut bits = std::mem::take(word);
            while bits != 0 {
                let index = w * 64 + bits.trailing_zeros() as usize;
                bits &= bits - 1;
                let bin = std::mem::replace(&mut bins[index], EMPTY);
                out.push(HeightSample {
                    i: i0 + (index % cols) as i64,
                    j: j0 + (index / cols) as i64,
                    z: bin.z,
                    variance: self.config.variance(bin.range),
                });
            }
        }
    }

    /// Raises each bin of `grid` to the highest return of `image` in it
    /// (with that return's range), marking the bins first raised in the
    /// `words` words of `self.touched`. With AVX2 where the processor has
    /// it (as [`crate::cells`] bins): the same arithmetic (no fused
    /// multiply-add), so the same bins.
    fn bin(
        &mut self,
        image: &RangeImage,
        level_from_sensor: &Isometry,
        grid: &HeightGrid,
        words: usize,
    ) {
        #[cfg(test)]
        let avx2_allowed = !self.portable_only;
        #[cfg(not(test))]
        let avx2_allowed = true;
        #[cfg(target_arch = "x86_64")]
        if avx2_allowed && std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the processor has AVX2, checked just above.
            return unsafe { self.bin_avx2(image, level_from_sensor, grid, words) };
        }
        let _ = avx2_allowed;
        self.bin_portable(image, level_from_sensor, grid, words);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn bin_avx2(
        &mut self,
        image: &RangeImage,
        level_from_sensor: &Isometry,
        grid: &HeightGrid,
        words: usize,
    ) {
        self.bin_portable(image, level_from_sensor, grid, words);
    }

    #[inline(always)]
    fn bin_portable(
        &mut self,
        image: &RangeImage,
        level_from_sensor: &Isometry,
        grid: &HeightGrid,
        words: usize,
    ) {
        let &HeightGrid {
            corner: [ox, oy],
            sin_cos: [sin, cos],
            inverse,
            region: [ahead, behind, half],
            tz,
            cols,
            rows,
        } = grid;
        let start = self.projector.prepare(image, level_from_sensor);
        let kept = (self.min_range, self.max_range);
        let image_cols = image.cols();
        let (bins, cells, points) = (&mut self.bins, &mut self.row_cells, &mut self.points);
        let touched = &mut self.touched[..words];
        // The counts of returns skipped are perception's to give, not ours.
        let mut stats = ImageStats::default();
        for row in 0..image.beams.elevation.len() {
            let line = &image.range[row * image_cols..(row + 1) * image_cols];
            self.projector
                .project_row(&start, row, line, kept, points, &mut stats);
            // Each column's cell (u32::MAX: none) with no branch, so it
            // vectorises; then the bins, return by return.
            cells.resize(points.x.len(), u32::MAX);
            let columns = points.x.iter().zip(&points.y).zip(&points.used);
            for (((&x, &y), &used), cell) in columns.zip(cells.iter_mut()) {
                let inside = used && x <= ahead && x >= -behind && y.abs() <= half;
                let (gx, gy) = (
                    (ox + cos * x - sin * y) * inverse,
                    (oy + sin * x + cos * y) * inverse,
                );
                // In the grid: whole cells below its size (at most a
                // few thousand), so the conversions are exact.
                let inside =
                    inside && gx >= 0.0 && gy >= 0.0 && gx < cols as f32 && gy < rows as f32;
                let (ci, cj) = if inside {
                    (gx as u32, gy as u32)
                } else {
                    (0, 0)
                };
                *cell = if inside {
                    // Exact (a cell of the grid); wrapping, so that a
                    // checked build vectorises the loop too.
                    cj.wrapping_mul(cols as u32).wrapping_add(ci)
                } else {
                    u32::MAX
                };
            }
            for ((&index, &z), &range) in cells.iter().zip(&points.z).zip(line) {
                if index == u32::MAX {
                    continue;
                }
                let bin = &mut bins[index as usize];
                if bin.z == f32::NEG_INFINITY {
                    touched[index as usize / 64] |= 1 << (index % 64);
                }
                let z = z + tz;
                if z > bin.z {
                    *bin = Bin { z, range };
                }
            }
        }
    }
}

/// Where [`HeightSampler::sample`] bins an image's returns: a grid of
/// `cols` × `rows` world-aligned cells, its corner at `corner` from the
/// level frame's origin (metres, world axes), the level frame turned by
/// the heading whose sine and cosine are `sin_cos`, `inverse` cells a
/// metre; returns count only within the region (`[ahead, behind,
/// half_width]` metres of the level frame), at their height plus `tz`.
struct HeightGrid {
    corner: [f32; 2],
    sin_cos: [f32; 2],
    inverse: f32,
    region: [f32; 3],
    tz: f32,
    cols: usize,
    rows: usize,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::HeightFunction;

    #[test]
    fn a_flat_plane_gives_one_sample_per_cell_at_its_height() {
        let model = crate::SensorModel::erim();
        let pose = Isometry::identity();
        let image = model.render(0, &pose, &HeightFunction::new(|_, _| 0.0));
        let mut sampler = HeightSampler::new(
            &HeightsConfig::default(),
            &RegionConfig::default(),
            0.5,
            40.0,
        );
        let mut report = ObstacleReport::default();
        sampler.sample(&image, &pose, &mut report);
        let out = report.heights;
        assert!(out.len() > 500, "{} samples", out.len());
        for s in &out {
            assert!(s.z.abs() < 1e-3, "{s:?}");
            assert!(s.variance > 0.0);
        }
        let mut cells: Vec<_> = out.iter().map(|s| (s.i, s.j)).collect();
        cells.dedup();
        assert_eq!(cells.len(), out.len(), "one sample per cell");
        // Again: nothing is left over from the first image.
        let mut again = ObstacleReport::default();
        sampler.sample(&image, &pose, &mut again);
        assert_eq!(again.heights, out);
    }

    /// The AVX2 binning and the portable one give the same samples, bit
    /// for bit, on rough ground seen from a turned, tilted vehicle (with
    /// returns beyond the region, outside the ranges kept and missing).
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn binning_with_avx2_gives_the_samples_binning_without_it_gives() {
        if !crate::avx2_to_test("the AVX2 height binning") {
            return;
        }
        let model = crate::SensorModel::erim();
        let pose =
            arcnav_vehicle::frames::isometry_from_xyz_rpy([3.7, -2.2, 0.3], 0.08, -0.05, 2.4);
        let scene = HeightFunction::with_step(crate::scene::rough_ground, 0.1);
        let image = model.render(0, &pose, &scene);
        let sample = |portable_only: bool| {
            let mut sampler = HeightSampler::new(
                &HeightsConfig::default(),
                &RegionConfig::default(),
                4.0,
                18.0,
            );
            sampler.portable_only = portable_only;
            let mut report = ObstacleReport::default();
            sampler.sample(&image, &pose, &mut report);
            report.heights
        };
        let (portable, dispatched) = (sample(true), sample(false));
        assert!(portable.len() > 500, "{} samples", portable.len());
        assert_eq!(portable, dispatched);
    }
}
