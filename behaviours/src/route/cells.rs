//! The route's memory cells: where they lie in the world, the states a
//! cell takes, its neighbours, and what the local map shows of it (seen
//! wholly, how rough).

use arcnav_localmap::MapSnapshot;
use arcnav_vehicle::numbers::floor_i64;

use super::config::RouteConfig;

/// Where the memory cells lie: a square of `side` × `side` cells of
/// `cell_m`, cell (0, 0) at world cell index `origin` (`None` before the
/// first cycle).
#[derive(Debug, Clone)]
pub(super) struct Layout {
    pub(super) side: usize,
    /// World cell index of memory cell (0, 0).
    pub(super) origin: Option<(i64, i64)>,
    pub(super) cell_m: f64,
}

impl Layout {
    /// Memory cell of world point (x, y), if inside.
    pub(super) fn cell_at(&self, x: f64, y: f64) -> Option<usize> {
        let (i0, j0) = self.origin?;
        let (i, j) = (
            floor_i64(x / self.cell_m) - i0,
            floor_i64(y / self.cell_m) - j0,
        );
        let side = self.side as i64;
        ((0..side).contains(&i) && (0..side).contains(&j)).then(|| (j * side + i) as usize)
    }
    /// Memory cell (`x`, `y`) by its column and row, if inside.
    pub(super) fn index(&self, x: i64, y: i64) -> Option<usize> {
        let side = self.side as i64;
        ((0..side).contains(&x) && (0..side).contains(&y)).then(|| (y * side + x) as usize)
    }
    /// How far inside the window a memory cell's centre must lie for all
    /// of the cell to: half its diagonal.
    pub(super) fn whole_cell_margin(&self) -> f64 {
        self.cell_m * std::f64::consts::FRAC_1_SQRT_2
    }
    /// Column and row of memory cell `c`.
    pub(super) fn column_row(&self, c: usize) -> (i64, i64) {
        ((c % self.side) as i64, (c / self.side) as i64)
    }
    /// World centre of memory cell `c`.
    pub(super) fn centre(&self, c: usize) -> [f64; 2] {
        let (i0, j0) = self.origin.unwrap_or((0, 0));
        let (i, j) = self.column_row(c);
        let (i, j) = (i + i0, j + j0);
        [
            (i as f64 + 0.5) * self.cell_m,
            (j as f64 + 0.5) * self.cell_m,
        ]
    }
}

pub(super) const UNKNOWN: u8 = 0;
pub(super) const FREE: u8 = 1;
pub(super) const OBSTACLE: u8 = 2;
/// Seen free ground of roughness level 1 to [`ROUGH_LEVELS`]: `ROUGH + level - 1`.
pub(super) const ROUGH: u8 = 3;
pub(super) const ROUGH_LEVELS: u8 = 4;
/// Seen ground with a suspected drop-off in it (graded, reason drop-off:
/// a hole's edge seen from too far to show its depth).
pub(super) const SUSPECT: u8 = ROUGH + ROUGH_LEVELS;
/// The graded level that stands for a suspected drop-off in
/// `Route::graded` (above every roughness level).
pub(super) const SUSPECTED_LEVEL: u8 = u8::MAX;
/// Ground never seen that the vehicle was held short of: planned round
/// like an obstacle until an image sees it.
pub(super) const SHUT: u8 = SUSPECT + 1;
/// An obstacle seen only from farther than `confirm_within_m`: planned
/// through at `doubtful_cost`, so that a way closed only by what was seen
/// from afar (a gap's edges seen at a grazing angle) is looked at from
/// near before the route says there is none.
pub(super) const DOUBTFUL: u8 = SHUT + 1;

/// Half the angle ahead of the vehicle's heading in which unseen ground is
/// shut when it starts to back up (`shut_unseen_m`).
pub(super) const SHUT_HALF_ANGLE_DEG: f64 = 60.0;
/// Shutting spreads only through cells at least this far inside the local
/// map's window (at the pose the vehicle backed up from), m: ground that
/// close to the vehicle and still unseen lay in view and out of sight (a
/// shadow), where the edge of the ground ever seen runs along the edge of
/// the window.
pub(super) const SHUT_IN_VIEW_M: f64 = 2.0;
/// Shutting spreads through unseen cells with seen ground this many cells
/// away on both sides (see `Route::between_seen`).
pub(super) const SHADOW_CELLS: i64 = 8;

/// Whether every local-map patch that overlaps the memory cell `cell` m
/// square centred on world (x, y) was seen.
pub(super) fn wholly_seen(map: &MapSnapshot, x: f64, y: f64, cell: f64) -> bool {
    let s = map.patch_size_m;
    let half = cell / 2.0;
    // Patches from the one holding the cell's low edge to the one holding
    // its high edge (a hair inside, so a patch that only touches it is out).
    let span = |c: f64| {
        (
            floor_i64((c - half) / s),
            ((c + half) / s - 1e-9).ceil() as i64,
        )
    };
    let ((i0, i1), (j0, j1)) = (span(x), span(y));
    (j0..j1).all(|j| (i0..i1).all(|i| map.seen.contains(i, j)))
}

/// A cell seen in part only is shut when backing up if shut cells lie this
/// many cells away on both sides (a gap in the shut band along an edge no
/// wider than the vehicle; see `Route::shut_unseen_ahead`).
pub(super) const GAP_CELLS: i64 = 2;

/// A row, a column and the two diagonals through a memory cell, each as
/// one of its two directions.
pub(super) const AXES: [(i64, i64); 4] = [(1, 0), (0, 1), (1, 1), (1, -1)];

/// A memory cell's eight neighbours.
pub(super) const NEIGHBOURS: [(i64, i64); 8] = [
    (-1, -1),
    (0, -1),
    (1, -1),
    (-1, 0),
    (1, 0),
    (-1, 1),
    (0, 1),
    (1, 1),
];

/// How rough the memory cell centred on world (x, y) is, from the map's
/// elevation layer: 0 (smooth or unmeasured) to [`ROUGH_LEVELS`]. The
/// measure is the mean |second difference| of the layer's heights
/// along x and y over the cell (`2·z(i) − z(i−1) − z(i+1)`): a plane
/// of any slope has none, stones and ruts smaller than the cell have
/// about twice their height. It rises from `rough_m[0]` (level 0) to
/// `rough_m[1]` (the top level).
pub(super) fn roughness_level(config: &RouteConfig, map: &MapSnapshot, x: f64, y: f64) -> u8 {
    let grid = &map.elevation;
    if grid.side < 3 {
        return 0;
    }
    let s = grid.cell_size_m;
    let half = config.cell_m / 2.0;
    let side = i64::from(grid.side);
    let (lo_i, hi_i) = (
        floor_i64((x - half) / s) - grid.origin.0,
        ((x + half) / s).ceil() as i64 - 1 - grid.origin.0,
    );
    let (lo_j, hi_j) = (
        floor_i64((y - half) / s) - grid.origin.1,
        ((y + half) / s).ceil() as i64 - 1 - grid.origin.1,
    );
    let z = |i: i64, j: i64| grid.cells[(j * side + i) as usize][0];
    let (mut sum, mut count) = (0.0f32, 0u32);
    for j in lo_j.max(1)..=hi_j.min(side - 2) {
        for i in lo_i.max(1)..=hi_i.min(side - 2) {
            let centre = 2.0 * z(i, j);
            for d in [
                centre - z(i - 1, j) - z(i + 1, j),
                centre - z(i, j - 1) - z(i, j + 1),
            ] {
                if d.is_finite() {
                    sum += d.abs();
                    count += 1;
                }
            }
        }
    }
    if count < 4 {
        return 0;
    }
    let [smooth, rough] = config.rough_m;
    let severity = ((f64::from(sum / count as f32) - smooth) / (rough - smooth)).clamp(0.0, 1.0);
    (severity * f64::from(ROUGH_LEVELS)).round() as u8
}
