//! The vehicle-frame bitmap the local map is rasterised into, and each
//! arc's swept bands over it: which cells an arc's footprint meets, and
//! how far along the arc.

use std::collections::HashMap;

use arcnav_vehicle::{Arc, ArcPose, Footprint, SweptFootprint};
use nalgebra::Point2;

use super::config::UnseenGround;
use crate::behaviour::VoteContext;

/// One group of grid cells of an arc's swept band.
#[derive(Debug, Clone, Copy)]
pub(super) struct Entry {
    /// Distance along the arc at which the footprint first touches the group.
    pub(super) s: f32,
    /// Word of the bitmap.
    pub(super) word: u32,
    pub(super) mask: u64,
}

/// The swept bands of one arc, each a list of entries in distance order.
#[derive(Debug, Clone)]
pub(super) struct Template {
    pub(super) bands: Vec<Vec<Entry>>,
    /// The body's band (band 0) cell by cell: the distance at which the
    /// footprint first touches the cell, and its centre, by distance.
    pub(super) body: Vec<(f32, [f32; 2])>,
    /// `body` in runs of [`BODY_RUN`] cells: where each run ends in it,
    /// and the box its centres lie in (lowest and highest x and y), so
    /// that a run whose box holds nothing can be passed over whole.
    pub(super) body_runs: Vec<(usize, [f64; 4])>,
}

/// Cells of a body run (see [`Template::body_runs`]).
const BODY_RUN: usize = 32;

/// The grid cells that the points of a box, and those within half a cell
/// of it, fall in: first and last row and column, clipped to the grid.
#[derive(Debug, Clone, Copy)]
pub(super) struct Cover {
    pub(super) rows: (usize, usize),
    pub(super) columns: (usize, usize),
    /// Whether every such point lies on the grid (none was clipped).
    pub(super) whole: bool,
}

/// The vehicle-frame grid the map is rasterised into.
#[derive(Debug, Clone)]
pub(super) struct Grid {
    pub(super) x0: f64,
    pub(super) y0: f64,
    pub(super) resolution: f64,
    /// 1 / resolution.
    pub(super) per_m: f64,
    pub(super) rows: usize,
    pub(super) columns: usize,
    pub(super) words_per_row: usize,
}

impl Grid {
    pub(super) fn cell(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let (fx, fy) = ((x - self.x0) * self.per_m, (y - self.y0) * self.per_m);
        (fx >= 0.0 && fy >= 0.0 && fx < self.rows as f64 && fy < self.columns as f64)
            .then_some((fx as usize, fy as usize))
    }

    /// The cells that the points of the box `lo`..`hi` (grid frame) fall
    /// in, with a margin of half a cell so that rounding cannot move a
    /// point of the box (or a cell centre a polygon within it holds) out
    /// of them; none when the box misses the grid (or is not a number).
    pub(super) fn cover(&self, lo: Point2<f64>, hi: Point2<f64>) -> Option<Cover> {
        let (r0, r1) = (
            (lo.x - self.x0) * self.per_m - 0.5,
            (hi.x - self.x0) * self.per_m + 0.5,
        );
        let (c0, c1) = (
            (lo.y - self.y0) * self.per_m - 0.5,
            (hi.y - self.y0) * self.per_m + 0.5,
        );
        let (rows, columns) = (self.rows as f64, self.columns as f64);
        if !(r0 < rows && c0 < columns && r1 >= 0.0 && c1 >= 0.0 && r0 <= r1 && c0 <= c1) {
            return None;
        }
        Some(Cover {
            rows: (r0.max(0.0) as usize, (r1 as usize).min(self.rows - 1)),
            columns: (c0.max(0.0) as usize, (c1 as usize).min(self.columns - 1)),
            whole: r0 >= 0.0 && c0 >= 0.0 && r1 < rows && c1 < columns,
        })
    }

    /// Whether `layer` has a cell set in `cover`.
    pub(super) fn any_set(&self, layer: &[u64], cover: &Cover) -> bool {
        let (from, to) = cover.columns;
        (cover.rows.0..=cover.rows.1).any(|row| first_set(layer, self, row, from, to).is_some())
    }

    /// Whether `layer` may have a cell set whose centre lies inside the
    /// polygon `corners` (false only when none can: no cell of the
    /// polygon's box is set).
    pub(super) fn may_hold(&self, layer: &[u64], corners: &[Point2<f64>]) -> bool {
        let (lo, hi) = bounds(corners.iter().copied());
        self.cover(lo, hi)
            .is_some_and(|cover| self.any_set(layer, &cover))
    }

    /// The first cell of `bitmap` that `entry` holds (it must hold one).
    pub(super) fn first_cell(&self, entry: &Entry, bitmap: &[u64]) -> (usize, usize) {
        let hits = bitmap[entry.word as usize] & entry.mask;
        let row = entry.word as usize / self.words_per_row;
        let column =
            (entry.word as usize % self.words_per_row) * 64 + hits.trailing_zeros() as usize;
        (row, column)
    }

    /// The bitmap word holding cell `cell` (`row · columns + column`).
    pub(super) fn word_of(&self, cell: u32) -> usize {
        let (row, column) = (cell as usize / self.columns, cell as usize % self.columns);
        row * self.words_per_row + column / 64
    }

    pub(super) fn centre(&self, row: usize, column: usize) -> Point2<f64> {
        Point2::new(
            self.x0 + (row as f64 + 0.5) * self.resolution,
            self.y0 + (column as f64 + 0.5) * self.resolution,
        )
    }
}

/// The map rasterised into a vehicle-frame grid: its cells, the ground no
/// image has seen, and which map patch set each cell. With `mirror` -1 the
/// grid holds the ground behind the vehicle with x negated (backing up).
#[derive(Debug, Clone)]
pub(super) struct Raster {
    pub(super) grid: Grid,
    /// 1 for the ground ahead, -1 for the mirrored ground behind.
    pub(super) mirror: f64,
    pub(super) bitmap: Vec<u64>,
    /// Cells whose ground no image has seen (same layout as `bitmap`).
    pub(super) unseen: Vec<u64>,
    /// Cells the vehicle stands on: never unseen.
    pub(super) standing: Vec<u64>,
    /// Map patch index per grid cell that holds one (u32::MAX otherwise).
    pub(super) causes: Vec<u32>,
    pub(super) set_cells: Vec<u32>,
    /// Cells holding graded ground (patches of cost below 1), same layout
    /// as `bitmap`, and the highest cost per grid cell.
    pub(super) graded: Vec<u64>,
    pub(super) graded_cost: Vec<f32>,
    pub(super) graded_cells: Vec<u32>,
    /// Cells holding a suspected drop-off (graded patches with the reason
    /// drop-off), same layout as `bitmap`, and which they are.
    pub(super) suspect: Vec<u64>,
    pub(super) suspect_cells: Vec<u32>,
    /// Cells and unseen ground together, when unseen ground is an
    /// obstacle (`unseen_blocks`).
    pub(super) blocked: Vec<u64>,
    pub(super) unseen_blocks: bool,
    /// The y of each column's cell centres.
    column_y: Vec<f64>,
}

impl Raster {
    /// A raster over `grid`; `standing(p)` tells the vehicle-frame points
    /// the vehicle stands on.
    pub(super) fn new(grid: Grid, mirror: f64, standing: impl Fn(Point2<f64>) -> bool) -> Self {
        let words = grid.rows * grid.words_per_row;
        let mut mask = vec![0; words];
        for row in 0..grid.rows {
            for column in 0..grid.columns {
                let p = grid.centre(row, column);
                if standing(Point2::new(mirror * p.x, p.y)) {
                    mask[row * grid.words_per_row + column / 64] |= 1 << (column % 64);
                }
            }
        }
        Self {
            bitmap: vec![0; words],
            unseen: vec![0; words],
            standing: mask,
            causes: vec![u32::MAX; grid.rows * grid.columns],
            set_cells: Vec::new(),
            graded: vec![0; words],
            graded_cost: vec![0.0; grid.rows * grid.columns],
            graded_cells: Vec::new(),
            suspect: vec![0; words],
            suspect_cells: Vec::new(),
            blocked: vec![0; words],
            unseen_blocks: false,
            column_y: (0..grid.columns)
                .map(|column| grid.centre(0, column).y)
                .collect(),
            mirror,
            grid,
        }
    }

    /// Rasterises the map's cells (clearing the last cycle's).
    pub(super) fn rasterise(&mut self, ctx: &VoteContext<'_>) {
        let mirror = self.mirror;
        self.rasterise_with(ctx, 0..ctx.map.patches.len(), |x, y| (mirror * x, y));
    }

    /// Rasterises the map's patches of index `patches` placed by `to_grid`
    /// (vehicle frame to this raster's frame), clearing the last ones.
    pub(super) fn rasterise_with(
        &mut self,
        ctx: &VoteContext<'_>,
        patches: impl Iterator<Item = usize>,
        to_grid: impl Fn(f64, f64) -> (f64, f64),
    ) {
        for &cell in &self.set_cells {
            self.bitmap[self.grid.word_of(cell)] = 0;
            self.causes[cell as usize] = u32::MAX;
        }
        self.set_cells.clear();
        for &cell in &self.graded_cells {
            self.graded[self.grid.word_of(cell)] = 0;
            self.graded_cost[cell as usize] = 0.0;
        }
        self.graded_cells.clear();
        for &cell in &self.suspect_cells {
            self.suspect[self.grid.word_of(cell)] = 0;
        }
        self.suspect_cells.clear();
        for index in patches {
            let Some(patch) = ctx.map.patches.get(index) else {
                continue;
            };
            let (x, y) = to_grid(f64::from(patch.x), f64::from(patch.y));
            let Some((row, column)) = self.grid.cell(x, y) else {
                continue;
            };
            let cell = row * self.grid.columns + column;
            let bit = 1 << (column % 64);
            if patch.is_suspected_drop_off() {
                // A suspected drop-off: it only slows the vehicle.
                let word = &mut self.suspect[row * self.grid.words_per_row + column / 64];
                if *word & bit == 0 {
                    self.suspect_cells.push(cell as u32);
                }
                *word |= bit;
                continue;
            }
            if !patch.is_obstacle() {
                // Graded ground: no collision, a price (highest per cell).
                self.graded[row * self.grid.words_per_row + column / 64] |= 1 << (column % 64);
                if self.graded_cost[cell] == 0.0 {
                    self.graded_cells.push(cell as u32);
                }
                self.graded_cost[cell] = self.graded_cost[cell].max(patch.cost);
                continue;
            }
            self.bitmap[row * self.grid.words_per_row + column / 64] |= 1 << (column % 64);
            if self.causes[cell] == u32::MAX {
                self.causes[cell] = index as u32;
                self.set_cells.push(cell as u32);
            }
        }
    }

    /// Marks the cells whose ground no image has seen.
    pub(super) fn rasterise_unseen(&mut self, ctx: &VoteContext<'_>) {
        let seen = ctx.map.seen_frame();
        let grid = &self.grid;
        for row in 0..grid.rows {
            let words = &mut self.unseen[row * grid.words_per_row..][..grid.words_per_row];
            words.fill(0);
            let line = seen.across(self.mirror * grid.centre(row, 0).x);
            for (column, &y) in self.column_y.iter().enumerate() {
                if !line.seen(y) {
                    words[column / 64] |= 1 << (column % 64);
                }
            }
            let standing = &self.standing[row * grid.words_per_row..][..grid.words_per_row];
            for (word, standing) in words.iter_mut().zip(standing) {
                *word &= !standing;
            }
        }
    }

    /// The map cell behind a hit entry of `layer` (the blocked layer, or
    /// one cleared of cells), vehicle frame (none for unseen ground).
    pub(super) fn cause(
        &self,
        entry: &Entry,
        layer: &[u64],
        ctx: &VoteContext<'_>,
    ) -> Option<[f32; 2]> {
        let (row, column) = self.grid.first_cell(entry, layer);
        self.cause_at(row, column, ctx)
    }

    /// The map patch behind grid cell (row, column), vehicle frame.
    pub(super) fn cause_at(
        &self,
        row: usize,
        column: usize,
        ctx: &VoteContext<'_>,
    ) -> Option<[f32; 2]> {
        let patch = self.causes.get(row * self.grid.columns + column)?;
        let patch = ctx.map.patches.get(*patch as usize)?;
        Some([patch.x, patch.y])
    }

    /// Whether the ground at `p` (this raster's frame) is unseen, if `p`
    /// lies on the grid.
    pub(super) fn unseen_at(&self, p: Point2<f64>) -> Option<bool> {
        let (row, column) = self.grid.cell(p.x, p.y)?;
        Some(self.unseen[row * self.grid.words_per_row + column / 64] & (1 << (column % 64)) != 0)
    }

    /// Whether the ground at `p` (this raster's frame) is unseen: the
    /// raster's cell where `p` lies on it, the map's own (`seen`) beyond
    /// it, but never where the wheels stand (`standing`).
    pub(super) fn unseen_or_beyond(
        &self,
        p: Point2<f64>,
        seen: &impl Fn(f64, f64) -> bool,
        standing: &Footprint,
    ) -> bool {
        self.unseen_at(p)
            .unwrap_or_else(|| !seen(p.x, p.y) && !standing.contains(p))
    }

    /// What collisions are tested against: the map's cells, and unseen
    /// ground when it is an obstacle (see [`Raster::block`]).
    pub(super) fn blocked(&self) -> &[u64] {
        if self.unseen_blocks {
            &self.blocked
        } else {
            &self.bitmap
        }
    }

    /// Makes unseen ground block (`obstacle`) or not.
    pub(super) fn block(&mut self, policy: UnseenGround) {
        self.unseen_blocks = policy == UnseenGround::Obstacle;
        if self.unseen_blocks {
            for ((blocked, cell), unseen) in
                self.blocked.iter_mut().zip(&self.bitmap).zip(&self.unseen)
            {
                *blocked = cell | unseen;
            }
        }
    }

    /// Marks as unseen the cells of `band` within `reach` (this raster's
    /// frame) that `unseen` says no image has seen; the rest of the layer
    /// is cleared.
    pub(super) fn unseen_over(
        &mut self,
        band: &[Entry],
        reach: f32,
        unseen: impl Fn(Point2<f64>) -> bool,
    ) {
        self.unseen.fill(0);
        for entry in band.iter().take_while(|e| e.s <= reach) {
            let row = entry.word as usize / self.grid.words_per_row;
            let base = (entry.word as usize % self.grid.words_per_row) * 64;
            let mut bits = entry.mask;
            while bits != 0 {
                let bit = bits.trailing_zeros();
                bits &= bits - 1;
                if unseen(self.grid.centre(row, base + bit as usize)) {
                    self.unseen[entry.word as usize] |= 1 << bit;
                }
            }
        }
    }
}

impl Raster {
    /// The highest graded cost the band crosses within `reach`, and within
    /// `near` (the speed horizon).
    pub(super) fn graded_crossed(&self, band: &[Entry], reach: f32, near: f32) -> (f32, f32) {
        let (mut all, mut close) = (0.0f32, 0.0f32);
        if self.graded_cells.is_empty() {
            return (all, close);
        }
        for entry in band.iter().take_while(|e| e.s <= reach) {
            let mut hits = self.graded[entry.word as usize] & entry.mask;
            let row = entry.word as usize / self.grid.words_per_row;
            let base = (entry.word as usize % self.grid.words_per_row) * 64;
            while hits != 0 {
                let column = base + hits.trailing_zeros() as usize;
                hits &= hits - 1;
                let cost = self.graded_cost[row * self.grid.columns + column];
                all = all.max(cost);
                if entry.s <= near {
                    close = close.max(cost);
                }
            }
        }
        (all, close)
    }
}

/// The grid covering every outline of `footprint` swept `reach` along
/// every arc.
pub(super) fn grid_around(
    arcs: &arcnav_vehicle::ArcSet,
    footprint: Footprint,
    reach: f64,
    r: f64,
) -> Grid {
    let (lo, hi) = bounds(arcs.iter().flat_map(|arc| {
        arc.swept(footprint, reach)
            .outlines(0.25)
            .into_iter()
            .flatten()
    }));
    let rows = ((hi.x - lo.x) / r).ceil() as usize + 1;
    let columns = ((hi.y - lo.y) / r).ceil() as usize + 1;
    Grid {
        x0: lo.x,
        y0: lo.y,
        resolution: r,
        per_m: 1.0 / r,
        rows,
        columns,
        words_per_row: columns.div_ceil(64),
    }
}

/// The first entry of `band` within `reach` that holds a cell of `bitmap`.
pub(super) fn first_in<'t>(bitmap: &[u64], band: &'t [Entry], reach: f32) -> Option<&'t Entry> {
    band.iter()
        .take_while(|e| e.s <= reach)
        .find(|e| bitmap[e.word as usize] & e.mask != 0)
}

/// Visits, row by row, the cells of `grid` whose centres lie inside the
/// polygon `corners` (grid frame; a body's outline, convex or not) as runs
/// `(row, first column, last column)`; stops when `visit` returns true,
/// and says whether it did.
pub(super) fn cells_inside(
    grid: &Grid,
    corners: &[Point2<f64>],
    mut visit: impl FnMut(usize, usize, usize) -> bool,
) -> bool {
    const MAX_EDGES: usize = 64;
    let n = corners.len().min(MAX_EDGES);
    if n < 3 {
        return false;
    }
    let r = grid.resolution;
    let (lo_x, hi_x) = corners[..n]
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), c| {
            (lo.min(c.x), hi.max(c.x))
        });
    // Rows whose centre x lies within the corners' span.
    let first = ceil((lo_x - grid.x0) / r - 0.5).max(0.0);
    let last = floor((hi_x - grid.x0) / r - 0.5);
    if first.is_nan() || last.is_nan() || first > last || first >= grid.rows as f64 {
        return false;
    }
    let last = (last as usize).min(grid.rows - 1);
    // Each edge: its ends and its slope dy/dx (none when it runs along y).
    let mut edges = [(Point2::origin(), Point2::origin(), None); MAX_EDGES];
    for (i, edge) in edges.iter_mut().enumerate().take(n) {
        let (a, b) = (corners[i], corners[(i + 1) % n]);
        *edge = (a, b, (a.x != b.x).then(|| (b.y - a.y) / (b.x - a.x)));
    }
    let edges = &edges[..n];
    let convex = is_convex(&corners[..n]);
    // A row's runs: one across a convex outline; for any other, the
    // stretches between the outline's crossings taken in pairs.
    let mut crossings: Vec<f64> = Vec::new();
    let mut run = |row: usize, lo: f64, hi: f64| {
        let from = ceil((lo - grid.y0) / r - 0.5).max(0.0);
        let to = floor((hi - grid.y0) / r - 0.5);
        if from.is_nan() || to.is_nan() || from > to || from >= grid.columns as f64 {
            return false;
        }
        visit(row, from as usize, (to as usize).min(grid.columns - 1))
    };
    for row in first as usize..=last {
        let x = grid.x0 + (row as f64 + 0.5) * r;
        if convex {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for &(a, b, slope) in edges {
                if (a.x - x) * (b.x - x) > 0.0 {
                    continue;
                }
                let (y0, y1) = match slope {
                    Some(slope) => {
                        let y = a.y + (x - a.x) * slope;
                        (y, y)
                    }
                    None => (a.y, b.y),
                };
                lo = lo.min(y0).min(y1);
                hi = hi.max(y0).max(y1);
            }
            if run(row, lo, hi) {
                return true;
            }
        } else {
            crossings.clear();
            crossings.extend(
                edges
                    .iter()
                    .filter(|(a, b, _)| (a.x > x) != (b.x > x))
                    .map(|&(a, _, slope)| a.y + (x - a.x) * slope.unwrap_or(0.0)),
            );
            crossings.sort_unstable_by(f64::total_cmp);
            for pair in crossings.chunks_exact(2) {
                if run(row, pair[0], pair[1]) {
                    return true;
                }
            }
        }
    }
    false
}

/// Whether the polygon turns the same way at every vertex.
fn is_convex(corners: &[Point2<f64>]) -> bool {
    let n = corners.len();
    let turn = |i: usize| {
        let (a, b, c) = (corners[i], corners[(i + 1) % n], corners[(i + 2) % n]);
        (b.x - a.x) * (c.y - b.y) - (b.y - a.y) * (c.x - b.x)
    };
    (0..n).all(|i| turn(i) >= 0.0) || (0..n).all(|i| turn(i) <= 0.0)
}

/// `x.floor()` without the library call the baseline x86-64 target makes
/// of it (no SSE4.1); NaN stays NaN, and beyond ±2⁵³ x is whole already.
pub(super) fn floor(x: f64) -> f64 {
    if x.is_nan() || x.abs() >= 9.0e15 {
        return x;
    }
    let t = x as i64 as f64;
    if t > x { t - 1.0 } else { t }
}

/// `x.ceil()`, as [`floor`].
pub(super) fn ceil(x: f64) -> f64 {
    -floor(-x)
}

/// A pose's rotation and translation, its sine and cosine taken once.
#[derive(Debug, Clone, Copy)]
pub(super) struct Rigid {
    pub(super) cos: f64,
    pub(super) sin: f64,
    pub(super) x: f64,
    pub(super) y: f64,
}

impl Rigid {
    pub(super) fn of(pose: &ArcPose) -> Self {
        let (sin, cos) = pose.heading.sin_cos();
        Self {
            cos,
            sin,
            x: pose.position.x,
            y: pose.position.y,
        }
    }

    /// `p`, given in the pose's frame, in the frame the pose is given in.
    pub(super) fn apply(&self, p: Point2<f64>) -> Point2<f64> {
        Point2::new(
            self.x + self.cos * p.x - self.sin * p.y,
            self.y + self.sin * p.x + self.cos * p.y,
        )
    }

    /// `p`, given in the frame the pose is given in, in the pose's frame.
    pub(super) fn invert(&self, p: Point2<f64>) -> Point2<f64> {
        let (dx, dy) = (p.x - self.x, p.y - self.y);
        Point2::new(
            self.cos * dx + self.sin * dy,
            -self.sin * dx + self.cos * dy,
        )
    }
}

/// Distance from the origin to the nearest cell centre set in `layer`, m.
/// On a row (one x) that is the set cell of least |y|: the last set
/// before the first column of centre y ≥ 0, or the first set from it.
pub(super) fn nearest_set(layer: &[u64], grid: &Grid) -> f64 {
    let split = (0..grid.columns)
        .find(|&column| grid.centre(0, column).y >= 0.0)
        .unwrap_or(grid.columns);
    let mut nearest = f64::INFINITY;
    for row in 0..grid.rows {
        let below = split
            .checked_sub(1)
            .and_then(|to| last_set(layer, grid, row, 0, to));
        let above = (split < grid.columns)
            .then(|| first_set(layer, grid, row, split, grid.columns - 1))
            .flatten();
        for column in below.into_iter().chain(above) {
            let c = grid.centre(row, column);
            nearest = nearest.min(c.x.hypot(c.y));
        }
    }
    nearest
}

/// The words of `row` of `layer` that hold columns `from..=to`, each
/// masked to them: (its first column, its bits).
fn masked_words<'a>(
    layer: &'a [u64],
    grid: &Grid,
    row: usize,
    from: usize,
    to: usize,
) -> impl DoubleEndedIterator<Item = (usize, u64)> + 'a {
    let base = row * grid.words_per_row;
    (from / 64..=to / 64).map(move |word| {
        let low = if word == from / 64 { from % 64 } else { 0 };
        let high = if word == to / 64 { to % 64 } else { 63 };
        let mask = (u64::MAX << low) & (u64::MAX >> (63 - high));
        (word * 64, layer[base + word] & mask)
    })
}

/// The first column in `from..=to` of `row` set in `layer`.
pub(super) fn first_set(
    layer: &[u64],
    grid: &Grid,
    row: usize,
    from: usize,
    to: usize,
) -> Option<usize> {
    masked_words(layer, grid, row, from, to)
        .find_map(|(first, bits)| (bits != 0).then(|| first + bits.trailing_zeros() as usize))
}

/// The last column in `from..=to` of `row` set in `layer`.
pub(super) fn last_set(
    layer: &[u64],
    grid: &Grid,
    row: usize,
    from: usize,
    to: usize,
) -> Option<usize> {
    masked_words(layer, grid, row, from, to)
        .rev()
        .find_map(|(first, bits)| (bits != 0).then(|| first + 63 - bits.leading_zeros() as usize))
}

pub(super) fn build_template(
    arc: Arc,
    footprint: &Footprint,
    margins: &[f64],
    grid: &Grid,
    reach: f64,
) -> Template {
    let widest = arc.swept(footprint.widened(margins[margins.len() - 1]), reach);
    // Bounds of this arc's widest band, in grid cells.
    let (lo, hi) = bounds(widest.outlines(0.25).into_iter().flatten());
    let to_row =
        |x: f64| (((x - grid.x0) / grid.resolution).floor().max(0.0) as usize).min(grid.rows - 1);
    let to_column = |y: f64| {
        (((y - grid.y0) / grid.resolution).floor().max(0.0) as usize).min(grid.columns - 1)
    };
    let mut cells: Vec<Vec<(f32, usize, usize)>> = vec![Vec::new(); margins.len()];
    for row in to_row(lo.x)..=to_row(hi.x) {
        for column in to_column(lo.y)..=to_column(hi.y) {
            let p = grid.centre(row, column);
            if widest.first_contact(p).is_none() {
                continue;
            }
            for (band, &margin) in margins.iter().enumerate() {
                let swept = SweptFootprint {
                    arc,
                    footprint: footprint.widened(margin),
                    length_m: reach,
                };
                if let Some(s) = swept.first_contact(p) {
                    cells[band].push((s as f32, row, column));
                }
            }
        }
    }
    let mut body: Vec<(f32, [f32; 2])> = cells[0]
        .iter()
        .map(|&(s, row, column)| {
            let c = grid.centre(row, column);
            (s, [c.x as f32, c.y as f32])
        })
        .collect();
    body.sort_by(|a, b| a.0.total_cmp(&b.0));
    let body_runs = body
        .chunks(BODY_RUN)
        .scan(0, |end, run| {
            *end += run.len();
            let (lo, hi) = bounds(
                run.iter()
                    .map(|(_, [x, y])| Point2::new(f64::from(*x), f64::from(*y))),
            );
            Some((*end, [lo.x, lo.y, hi.x, hi.y]))
        })
        .collect();
    let bin = grid.resolution as f32;
    let bands = cells
        .into_iter()
        .map(|mut band| {
            band.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
            // Group by (distance bin, word), keeping the group's first distance.
            let mut entries: Vec<Entry> = Vec::new();
            let mut groups: HashMap<(i64, u32), usize> = HashMap::new();
            for (s, row, column) in band {
                let word = (row * grid.words_per_row + column / 64) as u32;
                let bit = 1u64 << (column % 64);
                let index = *groups
                    .entry(((s / bin).floor() as i64, word))
                    .or_insert_with(|| {
                        entries.push(Entry { s, word, mask: 0 });
                        entries.len() - 1
                    });
                entries[index].mask |= bit;
            }
            entries.sort_by(|a, b| a.s.total_cmp(&b.s));
            entries
        })
        .collect();
    Template {
        bands,
        body,
        body_runs,
    }
}

/// The lowest and highest x and y of `points`.
pub(super) fn bounds(points: impl Iterator<Item = Point2<f64>>) -> (Point2<f64>, Point2<f64>) {
    points.fold(
        (
            Point2::new(f64::INFINITY, f64::INFINITY),
            Point2::new(f64::NEG_INFINITY, f64::NEG_INFINITY),
        ),
        |(lo, hi), p| (lo.inf(&p), hi.sup(&p)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every cell of a grid of 0.1 m over [-1, 5] × [-2, 2] whose centre
    /// lies inside `outline`, by `cells_inside`.
    fn inside(outline: &[Point2<f64>]) -> Vec<(usize, usize)> {
        let (rows, columns) = (60, 40);
        let grid = Grid {
            x0: -1.0,
            y0: -2.0,
            resolution: 0.1,
            per_m: 10.0,
            rows,
            columns,
            words_per_row: 1,
        };
        let mut cells = Vec::new();
        cells_inside(&grid, outline, |row, from, to| {
            cells.extend((from..=to).map(|column| (row, column)));
            false
        });
        cells
    }

    /// A grid of 0.2 m over [-2, 18] × [-9.9, 9.9] (two words a row) and
    /// layers of it with about one cell in `one_in` set.
    fn layers(one_in: u64, count: usize) -> (Grid, Vec<Vec<u64>>) {
        let grid = Grid {
            x0: -2.0,
            y0: -9.9,
            resolution: 0.2,
            per_m: 5.0,
            rows: 100,
            columns: 99,
            words_per_row: 2,
        };
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut next = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let layers = (0..count)
            .map(|_| {
                let mut layer = vec![0u64; grid.rows * grid.words_per_row];
                for row in 0..grid.rows {
                    for column in 0..grid.columns {
                        if next() % one_in == 0 {
                            layer[row * 2 + column / 64] |= 1 << (column % 64);
                        }
                    }
                }
                layer
            })
            .collect();
        (grid, layers)
    }

    #[test]
    fn the_nearest_set_cell_is_the_nearest_of_all_set_cells() {
        let (grid, layers) = layers(400, 50);
        let mut empty = vec![0u64; grid.rows * grid.words_per_row];
        for layer in layers.iter().chain([&empty]) {
            let mut every = f64::INFINITY;
            for row in 0..grid.rows {
                for column in 0..grid.columns {
                    if layer[row * 2 + column / 64] & (1 << (column % 64)) != 0 {
                        let c = grid.centre(row, column);
                        every = every.min(c.x.hypot(c.y));
                    }
                }
            }
            assert_eq!(nearest_set(layer, &grid), every);
        }
        // One cell, in the last column: found from either side.
        empty[99 * 2 + 1] = 1 << (98 - 64);
        let c = grid.centre(99, 98);
        assert_eq!(nearest_set(&empty, &grid), c.x.hypot(c.y));
    }

    #[test]
    fn a_footprint_whose_box_holds_no_set_cell_has_none_under_it() {
        let (grid, layers) = layers(1500, 40);
        let body = Footprint::rectangle(-1.2, 4.1, 1.6).outline();
        let (mut skipped, mut held) = (0, 0);
        for (i, layer) in layers.iter().enumerate() {
            for step in 0..60 {
                let heading = (i * 60 + step) as f64 * 0.37;
                let rigid = Rigid {
                    cos: heading.cos(),
                    sin: heading.sin(),
                    x: -3.0 + 0.37 * step as f64,
                    y: -11.0 + 0.41 * step as f64,
                };
                let corners = body.map(|c| rigid.apply(c));
                let mut under = false;
                cells_inside(&grid, &corners, |row, from, to| {
                    under = first_set(layer, &grid, row, from, to).is_some();
                    under
                });
                if grid.may_hold(layer, &corners) {
                    held += usize::from(under);
                } else {
                    assert!(!under, "a set cell under a footprint whose box holds none");
                    skipped += 1;
                }
            }
        }
        // Both kinds of footprint were met.
        assert!(
            skipped > 100 && held > 100,
            "{skipped} skipped, {held} held"
        );
    }

    #[test]
    fn the_cover_of_a_box_holds_the_cells_of_its_points() {
        let (grid, _) = layers(1, 0);
        let (lo, hi) = (Point2::new(3.05, -0.31), Point2::new(4.93, 2.2));
        let cover = grid.cover(lo, hi).expect("on the grid");
        assert!(cover.whole);
        for i in 0..=20 {
            for j in 0..=20 {
                let p = lo
                    + (hi - lo).component_mul(&nalgebra::Vector2::new(
                        f64::from(i) / 20.0,
                        f64::from(j) / 20.0,
                    ));
                let (row, column) = grid.cell(p.x, p.y).expect("on the grid");
                assert!((cover.rows.0..=cover.rows.1).contains(&row));
                assert!((cover.columns.0..=cover.columns.1).contains(&column));
            }
        }
        // Over an edge: clipped, not whole; off the grid: none.
        let over = grid
            .cover(Point2::new(17.5, 0.0), Point2::new(19.0, 1.0))
            .expect("partly on");
        assert!(!over.whole && over.rows.1 == grid.rows - 1);
        assert!(
            grid.cover(Point2::new(18.5, 0.0), Point2::new(19.0, 1.0))
                .is_none()
        );
    }

    #[test]
    fn the_cells_inside_an_l_leave_out_its_notch() {
        use arcnav_vehicle::Footprint;
        let p = Point2::new;
        let ell = Footprint::polygon(&[
            p(-0.6, -1.1),
            p(2.0, -1.1),
            p(2.0, 0.0),
            p(4.0, 0.0),
            p(4.0, 1.1),
            p(-0.6, 1.1),
        ])
        .unwrap();
        let cells = inside(&ell.outline());
        // The cell centres (x, y) = (-1 + 0.1·(row + ½), -2 + 0.1·(column + ½)).
        let centre = |(row, column): (usize, usize)| {
            p(
                -1.0 + 0.1 * (row as f64 + 0.5),
                -2.0 + 0.1 * (column as f64 + 0.5),
            )
        };
        let expected: Vec<_> = (0..60)
            .flat_map(|row| (0..40).map(move |column| (row, column)))
            .filter(|&c| ell.contains(centre(c)))
            .collect();
        assert_eq!(cells, expected);
        // 26 rows of 22 cells, and 20 rows of 11 (the arm).
        assert_eq!(cells.len(), 26 * 22 + 20 * 11);
        // A rectangle: one run per row, as before.
        let box_ = Footprint::rectangle(-0.6, 4.0, 1.1);
        assert_eq!(inside(&box_.outline()).len(), 46 * 22);
    }
}
