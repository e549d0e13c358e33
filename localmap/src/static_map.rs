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

impl StaticMap {
    /// The patches of `patch_size_m` that `grid` occupies.
    pub fn from_grid(grid: &OccupancyGrid, patch_size_m: f64) -> Self {
        // Points sampled per cell so every patch a cell covers is hit.
        let samples = (grid.resolution_m / patch_size_m).ceil().max(1.0) as usize;
        let step = grid.resolution_m / samples as f64;
        let mut patches: Vec<(i64, i64)> = Vec::new();
        for row in 0..grid.rows {
            for col in 0..grid.cols {
                if !grid.occupied[row * grid.cols + col] {
                    continue;
                }
                for a in 0..samples {
                    for b in 0..samples {
                        let local = nalgebra::Point3::new(
                            col as f64 * grid.resolution_m + (a as f64 + 0.5) * step,
                            row as f64 * grid.resolution_m + (b as f64 + 0.5) * step,
                            0.0,
                        );
                        let p = grid.origin * local;
                        patches.push((
                            (p.x / patch_size_m).floor() as i64,
                            (p.y / patch_size_m).floor() as i64,
                        ));
                    }
                }
            }
        }
        let Some(((i0, j0), (i1, j1))) = patches.iter().fold(None, |b, &(i, j)| {
            Some(match b {
                None => ((i, j), (i, j)),
                Some(((a, c), (d, e))) => ((i.min(a), j.min(c)), (i.max(d), j.max(e))),
            })
        }) else {
            return Self::default();
        };
        let (cols, rows) = ((i1 - i0 + 1) as usize, (j1 - j0 + 1) as usize);
        let mut occupied = vec![false; cols * rows];
        for (i, j) in patches {
            occupied[(j - j0) as usize * cols + (i - i0) as usize] = true;
        }
        let count = occupied.iter().filter(|&&o| o).count();
        Self {
            i0,
            j0,
            cols,
            rows,
            occupied,
            count,
        }
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
        let map = StaticMap::from_grid(&grid, 0.4);
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
        let map = StaticMap::from_grid(&coarse, 0.4);
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
        let map = StaticMap::from_grid(&grid, 0.4);
        assert!(map.contains(-1, 9), "{map:?}");
        assert_eq!(map.len(), 1);
    }
}
