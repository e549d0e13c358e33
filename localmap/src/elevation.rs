//! The elevation layer (004 §III): a robot-centric height map with a
//! Kalman mean and variance per cell, beside Ganesha's obstacle patches.
//!
//! Each cell m_n holds N(h, σ²) (004 eq. 2 without the occupancy, which
//! Ganesha's patches are). A measurement h_t with variance σ_t² (one image's
//! highest return in the cell, see `arcnav_perception::heights`) is fused
//! by the Kalman update of 004 eqs. 3–4:
//!
//! ```text
//! h_{0:t}  = (σ_t² · h_{0:t-1} + σ²_{0:t-1} · h_t) / (σ²_{0:t-1} + σ_t²)     (3)
//! σ²_{0:t} = (σ²_{0:t-1} · σ_t²) / (σ²_{0:t-1} + σ_t²)                         (4)
//! ```
//!
//! Two additions from the elevation mapping 004 builds on (its ref. \[7\],
//! Fankhauser et al., 2014), without which a fused map goes wrong as the
//! vehicle drives:
//!
//! - **Process noise**: before each update σ² grows by q² (`process_noise_m`),
//!   for the pose's drift between images. Without it σ² falls towards zero
//!   after a few dozen images and the cell stops listening.
//! - **Higher wins**: a measurement more than `mahalanobis` standard
//!   deviations (of σ² + σ_t²) above the mean replaces the cell (something
//!   stands there now that an earlier, lower return missed, such as a
//!   rock's top seen over its foot); one as far below is not fused (the far
//!   side of a rock seen past its top) and is counted.
//!
//! The grid is a power-of-two ring over world cells, each slot tagged with
//! the world cell it holds: as the vehicle moves nothing is copied or
//! cleared, a slot that now stands for another cell reads as unknown, and
//! lookups outside the square around the vehicle are unknown.

use arcnav_vehicle::numbers::floor_i64;
use serde::{Deserialize, Serialize};

use arcnav_perception::HeightSample;
use arcnav_vehicle::config::{ConfigError, in_range, non_negative, positive};

/// Lives in `[localmap.elevation]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ElevationConfig {
    /// Cell side, m (measurements of another size are placed by their
    /// centre).
    pub cell_size_m: f64,
    /// q: standard deviation added to a cell's height before each update, m.
    pub process_noise_m: f64,
    /// A measurement this many standard deviations above a cell's mean
    /// replaces it; as far below, it is not fused.
    pub mahalanobis: f64,
    /// Ground steeper than this in the layer, over metres (see
    /// [`ElevationGrid::steep_cells`]), joins the map's patches as an
    /// obstacle (reason `steep`): a bank's side, which perception's cells
    /// mark only in places, degrees; 90: never.
    pub steep_deg: f64,
}

impl Default for ElevationConfig {
    fn default() -> Self {
        Self {
            cell_size_m: 0.2,
            process_noise_m: 0.01,
            mahalanobis: 3.0,
            steep_deg: 32.0,
        }
    }
}

impl ElevationConfig {
    pub fn validate(&self) -> Result<(), ConfigError> {
        in_range("cell_size_m", self.cell_size_m, 0.05, 2.0)?;
        non_negative("process_noise_m", self.process_noise_m)?;
        in_range("steep_deg", self.steep_deg, 5.0, 90.0)?;
        positive("mahalanobis", self.mahalanobis)
    }
}

/// What the elevation layer did with the measurements it was given.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct ElevationStats {
    /// Fused by eqs. 3–4 (or the first in their cell).
    pub fused: u64,
    /// Far above the cell's mean: replaced it.
    pub replaced: u64,
    /// Far below the cell's mean: not fused.
    pub below: u64,
    /// Outside the square around the vehicle, or not finite.
    pub outside: u64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Slot {
    i: i64,
    j: i64,
    mean: f32,
    variance: f32,
}

const NOBODY: Slot = Slot {
    i: i64::MIN,
    j: i64::MIN,
    mean: f32::NAN,
    variance: f32::NAN,
};

/// The elevation layer.
#[derive(Debug)]
pub struct ElevationLayer {
    config: ElevationConfig,
    /// Cells reached to each side of the centre.
    reach: i64,
    mask: i64,
    side: usize,
    slots: Vec<Slot>,
    /// World cell of the vehicle.
    centre: (i64, i64),
    stats: ElevationStats,
    /// Bumped by every change to the cells; the last snapshot and the
    /// version it shows (a cycle without a new image shares it).
    version: u64,
    cache: std::sync::Mutex<(u64, std::sync::Arc<ElevationGrid>)>,
}

impl Clone for ElevationLayer {
    fn clone(&self) -> Self {
        Self {
            config: self.config.clone(),
            reach: self.reach,
            mask: self.mask,
            side: self.side,
            slots: self.slots.clone(),
            centre: self.centre,
            stats: self.stats,
            version: self.version + 1,
            cache: std::sync::Mutex::default(),
        }
    }
}

impl ElevationLayer {
    /// A layer that keeps the cells within `radius_m` of the vehicle
    /// (along each axis).
    pub fn new(config: &ElevationConfig, radius_m: f64) -> Self {
        let reach = (radius_m / config.cell_size_m).ceil() as i64 + 1;
        let side = ((2 * reach + 1) as usize).next_power_of_two();
        Self {
            config: config.clone(),
            reach,
            mask: side as i64 - 1,
            side,
            slots: vec![NOBODY; side * side],
            centre: (0, 0),
            stats: ElevationStats::default(),
            version: 1,
            cache: std::sync::Mutex::default(),
        }
    }

    pub fn config(&self) -> &ElevationConfig {
        &self.config
    }

    /// Slots along each side of the ring.
    pub fn side(&self) -> usize {
        self.side
    }

    /// Memory the ring holds, bytes.
    pub fn memory_bytes(&self) -> usize {
        self.slots.len() * std::mem::size_of::<Slot>()
    }

    pub fn stats(&self) -> &ElevationStats {
        &self.stats
    }

    /// World cell holding world (x, y).
    pub fn cell_of(&self, x: f64, y: f64) -> (i64, i64) {
        let s = self.config.cell_size_m;
        (floor_i64(x / s), floor_i64(y / s))
    }

    /// Moves the square's centre to the vehicle at world (x, y).
    pub fn recentre(&mut self, x: f64, y: f64) {
        // The snapshot is not rebuilt for a new centre alone: its cells are
        // world-aligned, so it stays right, and its square (a cell wider
        // than the window each way) lags by at most what the vehicle
        // drives between two images.
        self.centre = self.cell_of(x, y);
    }

    /// Forgets every cell.
    pub fn clear(&mut self) {
        self.slots.fill(NOBODY);
        self.version += 1;
    }

    fn in_square(&self, (i, j): (i64, i64)) -> bool {
        (i - self.centre.0).abs() <= self.reach && (j - self.centre.1).abs() <= self.reach
    }

    fn slot(&self, (i, j): (i64, i64)) -> usize {
        (j & self.mask) as usize * self.side + (i & self.mask) as usize
    }

    /// Fuses the measurements of one image, each made in a world cell of
    /// `sample_cell_m`.
    pub fn insert(&mut self, samples: &[HeightSample], sample_cell_m: f64) {
        let same = (sample_cell_m - self.config.cell_size_m).abs() < 1e-6;
        if !samples.is_empty() {
            self.version += 1;
        }
        let q = (self.config.process_noise_m * self.config.process_noise_m) as f32;
        let gate = (self.config.mahalanobis * self.config.mahalanobis) as f32;
        for s in samples {
            let cell = if same {
                (s.i, s.j)
            } else {
                self.cell_of(
                    (s.i as f64 + 0.5) * sample_cell_m,
                    (s.j as f64 + 0.5) * sample_cell_m,
                )
            };
            let valid = s.z.is_finite() && s.variance.is_finite() && s.variance > 0.0;
            if !(valid && self.in_square(cell)) {
                self.stats.outside += 1;
                continue;
            }
            let index = self.slot(cell);
            let slot = &mut self.slots[index];
            if (slot.i, slot.j) != cell {
                *slot = Slot {
                    i: cell.0,
                    j: cell.1,
                    mean: s.z,
                    variance: s.variance,
                };
                self.stats.fused += 1;
                continue;
            }
            let prior = slot.variance + q;
            let d = s.z - slot.mean;
            if d * d > gate * (prior + s.variance) {
                if d > 0.0 {
                    slot.mean = s.z;
                    slot.variance = s.variance;
                    self.stats.replaced += 1;
                } else {
                    slot.variance = prior;
                    self.stats.below += 1;
                }
                continue;
            }
            // 004 eqs. 3 and 4.
            let total = prior + s.variance;
            slot.mean = (s.variance * slot.mean + prior * s.z) / total;
            slot.variance = prior * s.variance / total;
            self.stats.fused += 1;
        }
    }

    /// Mean and variance of the world cell `cell`, if known and in the square.
    pub fn get(&self, cell: (i64, i64)) -> Option<(f32, f32)> {
        if !self.in_square(cell) {
            return None;
        }
        let slot = &self.slots[self.slot(cell)];
        ((slot.i, slot.j) == cell).then_some((slot.mean, slot.variance))
    }

    /// The known cells of the square around the vehicle, as a dense grid,
    /// shared until the cells change (a new image, a clear). A new centre
    /// alone keeps it: see [`ElevationLayer::recentre`].
    pub fn snapshot(&self) -> std::sync::Arc<ElevationGrid> {
        let mut cache = self.cache.lock().unwrap_or_else(|e| e.into_inner());
        if cache.0 != self.version {
            *cache = (self.version, std::sync::Arc::new(self.grid()));
        }
        cache.1.clone()
    }

    /// [`ElevationLayer::snapshot`], built afresh.
    fn grid(&self) -> ElevationGrid {
        let side = (2 * self.reach + 1) as usize;
        let (i0, j0) = (self.centre.0 - self.reach, self.centre.1 - self.reach);
        let mut cells = Vec::with_capacity(side * side);
        for j in j0..j0 + side as i64 {
            for i in i0..i0 + side as i64 {
                let slot = &self.slots[self.slot((i, j))];
                cells.push(if (slot.i, slot.j) == (i, j) {
                    [slot.mean, slot.variance]
                } else {
                    [f32::NAN, f32::NAN]
                });
            }
        }
        ElevationGrid {
            cell_size_m: self.config.cell_size_m,
            origin: (i0, j0),
            side: side as u32,
            cells,
        }
    }
}

/// A square of the elevation layer, world-aligned: what behaviours read.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ElevationGrid {
    pub cell_size_m: f64,
    /// World cell (i, j) of `cells[0]`; cell (i, j) spans
    /// [i·s, (i+1)·s) × [j·s, (j+1)·s).
    pub origin: (i64, i64),
    /// Cells along each side.
    pub side: u32,
    /// Row-major (rows along +y): mean height (world z, m) and variance (m²);
    /// NaN where unknown.
    pub cells: Vec<[f32; 2]>,
}

impl ElevationGrid {
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// Mean and variance at world (x, y), if known.
    #[inline]
    pub fn at(&self, x: f64, y: f64) -> Option<[f32; 2]> {
        if self.side == 0 {
            return None;
        }
        let inverse = 1.0 / self.cell_size_m;
        let i = floor_i64(x * inverse) - self.origin.0;
        let j = floor_i64(y * inverse) - self.origin.1;
        let side = i64::from(self.side);
        if !(0..side).contains(&i) || !(0..side).contains(&j) {
            return None;
        }
        let cell = self.cells[(j * side + i) as usize];
        cell[0].is_finite().then_some(cell)
    }

    /// Known cells.
    pub fn known(&self) -> usize {
        self.cells.iter().filter(|c| c[0].is_finite()).count()
    }

    /// The world cells (i, j) steeper than `steep_deg`: the slope from
    /// central differences over the four neighbours, every one of them
    /// measured, and at least two of the eight around it steep as well.
    /// A bank's side is steep over metres; on a 15-25° hillside the layer's
    /// noise lifts single cells above 32° (about 1 in 10 000 within 12 m of
    /// the vehicle on `hillside_steep`), rarely two side by side.
    /// `scratch` is reused between calls.
    pub fn steep_cells(&self, steep_deg: f64, scratch: &mut Vec<bool>, out: &mut Vec<(i64, i64)>) {
        out.clear();
        let side = self.side as usize;
        if steep_deg >= 90.0 || side < 3 {
            return;
        }
        let rise = steep_deg.to_radians().tan() * 2.0 * self.cell_size_m;
        let limit = (rise * rise) as f32;
        let height = |i: usize, j: usize| self.cells[j * side + i][0];
        let steep = scratch;
        steep.clear();
        steep.resize(side * side, false);
        for j in 1..side - 1 {
            for i in 1..side - 1 {
                let (dx, dy) = (
                    height(i + 1, j) - height(i - 1, j),
                    height(i, j + 1) - height(i, j - 1),
                );
                // An unmeasured neighbour (NaN) compares false.
                steep[j * side + i] = dx * dx + dy * dy > limit;
            }
        }
        for j in 1..side - 1 {
            for i in 1..side - 1 {
                if !steep[j * side + i] {
                    continue;
                }
                let around = (j - 1..=j + 1)
                    .flat_map(|b| (i - 1..=i + 1).map(move |a| (a, b)))
                    .filter(|&(a, b)| (a, b) != (i, j) && steep[b * side + a])
                    .count();
                if around >= 2 {
                    out.push((self.origin.0 + i as i64, self.origin.1 + j as i64));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(i: i64, j: i64, z: f32, sigma: f32) -> HeightSample {
        HeightSample {
            i,
            j,
            z,
            variance: sigma * sigma,
        }
    }

    #[test]
    fn kalman_update_weights_by_variance() {
        let config = ElevationConfig {
            process_noise_m: 0.0,
            ..ElevationConfig::default()
        };
        let mut layer = ElevationLayer::new(&config, 10.0);
        layer.insert(&[sample(3, 4, 1.0, 0.1)], 0.2);
        layer.insert(&[sample(3, 4, 1.2, 0.1)], 0.2);
        let (mean, variance) = layer.get((3, 4)).unwrap();
        // Equal variances: the mean halfway, the variance halved (eqs. 3, 4).
        assert!((mean - 1.1).abs() < 1e-5, "{mean}");
        assert!((variance - 0.005).abs() < 1e-7, "{variance}");
    }

    #[test]
    fn a_much_higher_measurement_replaces_and_a_much_lower_is_not_fused() {
        let mut layer = ElevationLayer::new(&ElevationConfig::default(), 10.0);
        layer.insert(&[sample(0, 0, 0.0, 0.02)], 0.2);
        layer.insert(&[sample(0, 0, 0.5, 0.02)], 0.2);
        assert_eq!(layer.get((0, 0)).unwrap().0, 0.5);
        layer.insert(&[sample(0, 0, 0.0, 0.02)], 0.2);
        assert_eq!(layer.get((0, 0)).unwrap().0, 0.5);
        assert_eq!(
            (
                layer.stats().fused,
                layer.stats().replaced,
                layer.stats().below
            ),
            (1, 1, 1)
        );
    }

    #[test]
    fn cells_outside_the_square_are_counted_not_kept_and_a_reused_slot_reads_unknown() {
        let mut layer = ElevationLayer::new(&ElevationConfig::default(), 2.0);
        layer.insert(&[sample(100, 0, 1.0, 0.1)], 0.2);
        assert_eq!(layer.stats().outside, 1);
        layer.insert(&[sample(5, 5, 1.0, 0.1)], 0.2);
        assert!(layer.get((5, 5)).is_some());
        // Drive 100 m: the same ring slot now stands for other ground.
        layer.recentre(100.0 * 0.2 * 16.0 / 16.0 + 0.1, 0.1);
        assert!(layer.get((5, 5)).is_none());
        let grid = layer.snapshot();
        assert_eq!(grid.known(), 0);
    }

    #[test]
    fn measurements_of_another_cell_size_land_by_their_centre() {
        let mut layer = ElevationLayer::new(&ElevationConfig::default(), 10.0);
        // A 0.5 m cell (2, 1) has its centre at (1.25, 0.75): 0.2 m cell (6, 3).
        layer.insert(&[sample(2, 1, 0.7, 0.1)], 0.5);
        assert_eq!(layer.get((6, 3)).unwrap().0, 0.7);
        let grid = layer.snapshot();
        assert_eq!(grid.at(1.25, 0.75).unwrap()[0], 0.7);
        assert!(grid.at(0.0, 0.0).is_none());
    }
}
