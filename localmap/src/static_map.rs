//! A static 2-D occupancy map of the area (001 §3.4): walls, buildings,
//! known hazards a user already has, merged with what perception reports.
//!
//! 001 keeps its 3-D obstacles in a map of their own and stores one "if it
//! is not already marked in the occupancy grid" (eq. 6): obstacles the 2-D
//! map holds are not stored twice. Here the occupied cells, gathered onto
//! the local map's patches, are patches of the local map whenever they lie
//! in its window (reason `static map`): the behaviours see them as they
//! see perception's, and no image prunes them. A perception cell on a
//! patch the static map already holds is not stored again (counted in
//! [`crate::MapStats::already_in_static_map`]).

use arcnav_vehicle::Isometry;
use arcnav_vehicle::numbers::floor_i64;

/// An occupancy grid in the world frame: `cols × rows` cells of
/// `resolution_m`, cell (row 0, col 0) with its corner at `origin`, rows
/// along the origin's +y, columns along its +x.
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyGrid {
    pub resolution_m: f64,
    /// World pose of the corner of cell (0, 0): x, y and the grid's yaw.
    pub origin: Isometry,
    pub cols: usize,
    pub rows: usize,
    /// Row-major, `rows × cols`.
    pub occupied: Vec<bool>,
}

/// The occupied cells of an [`OccupancyGrid`], as world patches of the
/// local map: a patch is occupied when any occupied cell's centre lies in
/// it (or, for cells larger than a patch, any point of the cell sampled at
/// the patch size).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct StaticMap {
    i0: i64,
    j0: i64,
    cols: usize,
    rows: usize,
    occupied: Vec<bool>,
    count: usize,
}

/// The most patches a static map's extent may span: 2²⁶ (a 1.6 km square
/// of 0.2 m patches), one byte each.
pub const MAX_PATCHES: u64 = 1 << 26;

/// The most points sampled to gather a grid of cells coarser than the
/// patches onto them: 2²⁴, or the grid's own number of cells if larger
/// (each cell is sampled once at least, so the work is bounded by the
/// map's size or by this).
pub const MAX_SAMPLES: u64 = 1 << 24;

/// A grid too large to gather onto the local map's patches.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum StaticMapError {
    #[error(
        "its occupied cells span {patches} patches of {patch_size_m} m, more than {MAX_PATCHES}: \
         is its resolution ({resolution_m} m per cell) right?"
    )]
    Extent {
        patches: u64,
        patch_size_m: f64,
        resolution_m: f64,
    },
    #[error(
        "its {cells} occupied cells of {resolution_m} m are {samples} samples at the {patch_size_m} m \
         patch size, more than {MAX_SAMPLES} or its cells: is its resolution right?"
    )]
    Samples {
        cells: u64,
        samples: f64,
        patch_size_m: f64,
        resolution_m: f64,
    },
}

impl StaticMap {
    /// The patches of `patch_size_m` that `grid` occupies. Nothing is
    /// allocated or sampled before the work is known to be bounded: a
    /// 1-pixel map of 100 km cells had asked for 4 GB.
    pub fn from_grid(grid: &OccupancyGrid, patch_size_m: f64) -> Result<Self, StaticMapError> {
        let cells = grid.occupied.iter().filter(|&&o| o).count() as u64;
        // Points sampled per cell side so every patch a cell covers is hit.
        let per_side = (grid.resolution_m / patch_size_m).ceil().max(1.0);
        let samples = per_side * per_side * cells as f64;
        let budget = MAX_SAMPLES.max(grid.occupied.len() as u64) as f64;
        if samples.is_nan() || samples > budget {
            return Err(StaticMapError::Samples {
                cells,
                samples,
                patch_size_m,
                resolution_m: grid.resolution_m,
            });
        }
        let per_side = per_side as usize;
        let step = grid.resolution_m / per_side as f64;
        let each_patch = |f: &mut dyn FnMut(i64, i64)| {
            for (k, _) in grid.occupied.iter().enumerate().filter(|(_, o)| **o) {
                let (row, col) = (k / grid.cols, k % grid.cols);
                for a in 0..per_side {
                    for b in 0..per_side {
                        let local = nalgebra::Point3::new(
                            col as f64 * grid.resolution_m + (a as f64 + 0.5) * step,
                            row as f64 * grid.resolution_m + (b as f64 + 0.5) * step,
                            0.0,
                        );
                        let p = grid.origin * local;
                        f(floor_i64(p.x / patch_size_m), floor_i64(p.y / patch_size_m));
                    }
                }
            }
        };
        let mut bounds: Option<[i64; 4]> = None;
        each_patch(&mut |i, j| {
            let b = bounds.get_or_insert([i, j, i, j]);
            *b = [b[0].min(i), b[1].min(j), b[2].max(i), b[3].max(j)];
        });
        let Some([i0, j0, i1, j1]) = bounds else {
            return Ok(Self::default());
        };
        let span = |lo: i64, hi: i64| (i128::from(hi) - i128::from(lo) + 1) as u128;
        let patches = span(i0, i1).saturating_mul(span(j0, j1));
        if patches > u128::from(MAX_PATCHES) {
            return Err(StaticMapError::Extent {
                patches: u64::try_from(patches).unwrap_or(u64::MAX),
                patch_size_m,
                resolution_m: grid.resolution_m,
            });
        }
        let (cols, rows) = (span(i0, i1) as usize, span(j0, j1) as usize);
        let mut occupied = vec![false; cols * rows];
        each_patch(&mut |i, j| occupied[(j - j0) as usize * cols + (i - i0) as usize] = true);
        let count = occupied.iter().filter(|&&o| o).count();
        Ok(Self {
            i0,
            j0,
            cols,
            rows,
            occupied,
            count,
        })
    }

    /// Whether world patch (`i`, `j`) is occupied.
    #[inline]
    pub fn contains(&self, i: i64, j: i64) -> bool {
        let (c, r) = (i - self.i0, j - self.j0);
        c >= 0
            && r >= 0
            && (c as usize) < self.cols
            && (r as usize) < self.rows
            && self.occupied[r as usize * self.cols + c as usize]
    }

    /// Occupied patches.
    pub fn len(&self) -> usize {
        self.count
    }

    pub fn is_empty(&self) -> bool {
        self.count == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arcnav_vehicle::frames::planar_isometry;

    #[test]
    fn fine_cells_gather_onto_patches_and_coarse_ones_cover_every_patch() {
        // 5 cm cells, one occupied at the corner of a 0.4 m patch grid.
        let mut grid = OccupancyGrid {
            resolution_m: 0.05,
            origin: planar_isometry(10.0, -2.0, 0.0),
            cols: 40,
            rows: 40,
            occupied: vec![false; 1600],
        };
        grid.occupied[3 * 40 + 17] = true; // centre (10.875, -1.825)
        let map = StaticMap::from_grid(&grid, 0.4).unwrap();
        assert_eq!(map.len(), 1);
        assert!(map.contains(27, -5));
        assert!(!map.contains(27, -4) && !map.contains(26, -5));
        // 1 m cells: one cell covers 3 × 3 patches or more.
        let coarse = OccupancyGrid {
            resolution_m: 1.0,
            origin: planar_isometry(0.0, 0.0, 0.0),
            cols: 1,
            rows: 1,
            occupied: vec![true],
        };
        let map = StaticMap::from_grid(&coarse, 0.4).unwrap();
        assert!(map.contains(0, 0) && map.contains(2, 2) && map.contains(1, 2));
        assert!(!map.contains(3, 0));
    }

    #[test]
    fn a_rotated_grid_lands_where_its_origin_says() {
        // Turned 90°: the grid's +x runs along the world's +y.
        let mut grid = OccupancyGrid {
            resolution_m: 0.4,
            origin: planar_isometry(0.0, 0.0, std::f64::consts::FRAC_PI_2),
            cols: 10,
            rows: 1,
            occupied: vec![false; 10],
        };
        grid.occupied[9] = true; // local (3.8, 0.2) → world (-0.2, 3.8)
        let map = StaticMap::from_grid(&grid, 0.4).unwrap();
        assert!(map.contains(-1, 9), "{map:?}");
        assert_eq!(map.len(), 1);
    }

    #[test]
    fn a_grid_too_large_for_the_patches_is_refused_before_anything_is_allocated() {
        // One 100 km cell (resolution: 100000 and a 1×1 image): it had
        // asked for 4 GB and aborted.
        let huge = OccupancyGrid {
            resolution_m: 100_000.0,
            origin: planar_isometry(0.0, 0.0, 0.0),
            cols: 1,
            rows: 1,
            occupied: vec![true],
        };
        let e = StaticMap::from_grid(&huge, 0.2).unwrap_err();
        assert!(matches!(e, StaticMapError::Samples { .. }), "{e}");
        // Two small cells 5 km apart on a diagonal: few samples, an extent
        // too large (3.5 km square).
        let diagonal = planar_isometry(0.0, 0.0, std::f64::consts::FRAC_PI_4);
        let line = |cols: usize| {
            let mut grid = OccupancyGrid {
                resolution_m: 0.2,
                origin: diagonal,
                cols,
                rows: 1,
                occupied: vec![false; cols],
            };
            grid.occupied[0] = true;
            grid.occupied[cols - 1] = true;
            grid
        };
        let e = StaticMap::from_grid(&line(25_000), 0.2).err().unwrap();
        assert!(matches!(e, StaticMapError::Extent { .. }), "{e}");
        assert!(
            e.to_string()
                .contains("is its resolution (0.2 m per cell) right?")
        );
        // 1.5 km along the diagonal (a 1.06 km square) is within the bound.
        let within = StaticMap::from_grid(&line(7_500), 0.2).ok().unwrap();
        assert_eq!(within.len(), 2);
    }
}
