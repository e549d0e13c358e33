//! Obstacle avoidance (002 §6): the vehicle footprint swept along each arc
//! against the map's cells.
//!
//! - a collision closer than `min_distance_m` along the arc: -1, a veto,
//!   recording the cell that causes it;
//! - no collision before `max_distance_m`: +1, minus a near-miss penalty that
//!   grows as the closest cell comes nearer to the swept footprint;
//! - a collision in between: a negative vote rising linearly from -1 at
//!   `min_distance_m` towards 0 at `max_distance_m`.
//!
//! Per-arc geometry is precomputed once: for the footprint and for
//! `near_miss_bands` widenings of it up to `near_miss_m`, the grid cells each
//! sweeps, grouped into 64-bit row masks sorted by the distance along the arc
//! at which the footprint first touches them (exact, from
//! [`arcnav_vehicle::SweptFootprint::first_contact`]). Each cycle the map's
//! cells are rasterised into a small bitmap and each arc walks its masks in
//! distance order: most arcs are decided by one pass over the widest band.
//! Map patches are squares, so the footprint is grown by half a patch.
//! Standing, a cell the raster puts under the footprint already (the
//! local map clears those whose centres are; grid rounding moves one just
//! beyond inside) stops only the arcs that take the footprint deeper over
//! it, not every arc (`UnderStart`).
//!
//! Graded ground (map patches of cost below 1: perception's graded cells,
//! e.g. 000's D̃ short of an obstacle) is no collision: a clear arc loses
//! `terrain.penalty` times the highest cost its footprint crosses, and its
//! speed falls as for the terrain's severity (see [`crate::terrain`]).
//!
//! Ground no image has seen is not free ground (000 §4.2 treats unknown
//! height as an obstacle). `unseen_ground` sets what it is:
//! - `slow` (default): each arc's speed is limited so that the vehicle can
//!   stop `stop_margin_m` short of the ground not seen along it (and of
//!   its free distance, as before): `v·t + v²/2a = room`. An arc whose
//!   unseen ground lies closer than the vehicle, braking as hard as it can
//!   from the speed it has, would stop in is forbidden: turning onto it, its
//!   limit would come too late;
//! - `obstacle`: unseen ground is an obstacle like a cell;
//! - `free`: it is ignored (the paper's behaviour).
//!
//! The ground under the vehicle up to its front axle counts as seen: it
//! stands there (the front overhang does not: it may hang over a ledge).
//!
//! **Backing up** (`reverse_reach_m` > 0): the same sweep, mirrored. Driven
//! backwards along curvature k, the vehicle covers the mirror image (x → -x)
//! of what a vehicle with its body mirrored covers driving forwards along
//! k, so the backward sweeps are forward templates of the mirrored body
//! (grown by `reverse_margin_m`) over a grid of the ground behind, read with
//! x negated. Each arc's clearance — how far the vehicle can back along it
//! before its body meets a cell or ground no image has seen — goes out with
//! the votes ([`Votes::set_reverse_clearance`]); the arbiter backs up only
//! along arcs clear for the distance it needs.
//!
//! **Creeping forwards**: each arc's distance to its first collision, cell
//! within the widest near-miss band inside `reverse_margin_m` (0.25 m) of
//! the body, or unseen ground, however close, also goes out with the votes
//! ([`Votes::set_forward_clearance`]). `min_distance_m` vetoes arcs for
//! driving at speed; a turning manoeuvre's short legs at a crawl may still
//! take them as far as they are clear, keeping beside the body about the
//! room backing up keeps (clear to the body itself, a retrace's forward run
//! brought a corner 0.2 m from a bank's side).

use std::collections::HashMap;

use arcnav_arbiter::Votes;
use arcnav_vehicle::config::{self, ConfigError};
use arcnav_vehicle::{Arc, ArcPose, DrivenPath, Footprint, SteeringResponse, SweptFootprint};
use nalgebra::Point2;
use serde::{Deserialize, Serialize};

use crate::behaviour::Plugin;
use crate::behaviour::{Behaviour, Setup, VoteContext};
use crate::terrain::{ArcTerrain, TerrainCheck, TerrainConfig};

/// Lives in `[behaviours.obstacle_avoidance]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ObstacleAvoidanceConfig {
    /// A collision closer than this along the arc forbids the arc, m.
    pub min_distance_m: f64,
    /// An arc clear this far along is a good arc, m.
    pub max_distance_m: f64,
    /// Cells closer than this to the swept footprint count as near misses, m.
    pub near_miss_m: f64,
    /// Vote lost by a clear arc whose footprint grazes a cell.
    pub near_miss_penalty: f64,
    /// Clearance bands between 0 and `near_miss_m` (the penalty's resolution).
    pub near_miss_bands: u32,
    /// Resolution of the collision grid, m.
    pub grid_resolution_m: f64,
    /// Vote a speed at which the vehicle can stop within the best arc's free
    /// distance (minus `stop_margin_m`), reacting after `reaction_s`.
    pub speed_vote: bool,
    pub stop_margin_m: f64,
    pub reaction_s: f64,
    /// Fraction of `vehicle.max_deceleration_mps2` the speed votes count
    /// on when stopping (the rest is margin for ground that brakes worse).
    pub braking_fraction: f64,
    /// What ground no image has seen is: slow (drive only as fast as the
    /// vehicle can stop within seen ground), obstacle, or free.
    pub unseen_ground: UnseenGround,
    /// How far the front is from a hole when the ray grazing its edge flags
    /// it, m: a suspected drop-off (graded ground with the reason
    /// drop-off) slows an arc only to the speed at which the vehicle stops
    /// within this of it (0: stop short of it; the pipeline sets it from
    /// the sensor, `speed_bound.hole_grazed_m` less the sensor's setback).
    pub hole_seen_within_m: f64,
    /// Backward arcs are checked this far, m (0: no opinion on backing up,
    /// so the arbiter never backs up).
    pub reverse_reach_m: f64,
    /// Clearance kept to each side of the body when backing up, m; creeping
    /// forwards in a manoeuvre, the widest near-miss band within it.
    pub reverse_margin_m: f64,
    /// Attitude, chassis clearance and roughness along the arcs, from the
    /// map's elevation layer (004 §IV).
    pub terrain: TerrainConfig,
}

/// What obstacle avoidance makes of ground no image has seen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum UnseenGround {
    /// Drive only as fast as the vehicle can stop within seen ground.
    Slow,
    /// Unseen ground is an obstacle (000 §4.2).
    Obstacle,
    /// Unseen ground is free (002's behaviour).
    Free,
}

impl Default for ObstacleAvoidanceConfig {
    fn default() -> Self {
        Self {
            min_distance_m: 6.0,
            max_distance_m: 18.0,
            near_miss_m: 1.0,
            near_miss_penalty: 0.5,
            near_miss_bands: 4,
            grid_resolution_m: 0.2,
            speed_vote: true,
            stop_margin_m: 2.0,
            reaction_s: 0.75,
            braking_fraction: 0.5,
            unseen_ground: UnseenGround::Slow,
            hole_seen_within_m: 0.0,
            reverse_reach_m: 5.0,
            reverse_margin_m: 0.3,
            terrain: TerrainConfig::default(),
        }
    }
}

/// One group of grid cells of an arc's swept band.
#[derive(Debug, Clone, Copy)]
struct Entry {
    /// Distance along the arc at which the footprint first touches the group.
    s: f32,
    /// Word of the bitmap.
    word: u32,
    mask: u64,
}

/// The swept bands of one arc, each a list of entries in distance order.
#[derive(Debug, Clone)]
struct Template {
    bands: Vec<Vec<Entry>>,
    /// The body's band (band 0) cell by cell: the distance at which the
    /// footprint first touches the cell, and its centre, by distance.
    body: Vec<(f32, [f32; 2])>,
}

/// The vehicle-frame grid the map is rasterised into.
#[derive(Debug, Clone)]
struct Grid {
    x0: f64,
    y0: f64,
    resolution: f64,
    /// 1 / resolution.
    per_m: f64,
    rows: usize,
    columns: usize,
    words_per_row: usize,
}

impl Grid {
    fn cell(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let (fx, fy) = ((x - self.x0) * self.per_m, (y - self.y0) * self.per_m);
        (fx >= 0.0 && fy >= 0.0 && fx < self.rows as f64 && fy < self.columns as f64)
            .then_some((fx as usize, fy as usize))
    }

    /// The first cell of `bitmap` that `entry` holds (it must hold one).
    fn first_cell(&self, entry: &Entry, bitmap: &[u64]) -> (usize, usize) {
        let hits = bitmap[entry.word as usize] & entry.mask;
        let row = entry.word as usize / self.words_per_row;
        let column =
            (entry.word as usize % self.words_per_row) * 64 + hits.trailing_zeros() as usize;
        (row, column)
    }

    /// The bitmap word holding cell `cell` (`row · columns + column`).
    fn word_of(&self, cell: u32) -> usize {
        let (row, column) = (cell as usize / self.columns, cell as usize % self.columns);
        row * self.words_per_row + column / 64
    }

    fn centre(&self, row: usize, column: usize) -> Point2<f64> {
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
struct Raster {
    grid: Grid,
    /// 1 for the ground ahead, -1 for the mirrored ground behind.
    mirror: f64,
    bitmap: Vec<u64>,
    /// Cells whose ground no image has seen (same layout as `bitmap`).
    unseen: Vec<u64>,
    /// Cells the vehicle stands on: never unseen.
    standing: Vec<u64>,
    /// Map patch index per grid cell that holds one (u32::MAX otherwise).
    causes: Vec<u32>,
    set_cells: Vec<u32>,
    /// Cells holding graded ground (patches of cost below 1), same layout
    /// as `bitmap`, and the highest cost per grid cell.
    graded: Vec<u64>,
    graded_cost: Vec<f32>,
    graded_cells: Vec<u32>,
    /// Cells holding a suspected drop-off (graded patches with the reason
    /// drop-off), same layout as `bitmap`, and which they are.
    suspect: Vec<u64>,
    suspect_cells: Vec<u32>,
    /// Cells and unseen ground together, when unseen ground is an
    /// obstacle (`unseen_blocks`).
    blocked: Vec<u64>,
    unseen_blocks: bool,
}

impl Raster {
    /// A raster over `grid`; `standing(p)` tells the vehicle-frame points
    /// the vehicle stands on.
    fn new(grid: Grid, mirror: f64, standing: impl Fn(Point2<f64>) -> bool) -> Self {
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
            mirror,
            grid,
        }
    }

    /// Rasterises the map's cells (clearing the last cycle's).
    fn rasterise(&mut self, ctx: &VoteContext<'_>) {
        let mirror = self.mirror;
        self.rasterise_with(ctx, 0..ctx.map.patches.len(), |x, y| (mirror * x, y));
    }

    /// Rasterises the map's patches of index `patches` placed by `to_grid`
    /// (vehicle frame to this raster's frame), clearing the last ones.
    fn rasterise_with(
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
    fn rasterise_unseen(&mut self, ctx: &VoteContext<'_>) {
        let seen = ctx.map.seen_lookup();
        let grid = &self.grid;
        for row in 0..grid.rows {
            let words = &mut self.unseen[row * grid.words_per_row..][..grid.words_per_row];
            words.fill(0);
            for column in 0..grid.columns {
                let p = grid.centre(row, column);
                if !seen(self.mirror * p.x, p.y) {
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
    fn cause(&self, entry: &Entry, layer: &[u64], ctx: &VoteContext<'_>) -> Option<[f32; 2]> {
        let (row, column) = self.grid.first_cell(entry, layer);
        self.cause_at(row, column, ctx)
    }

    /// The map patch behind grid cell (row, column), vehicle frame.
    fn cause_at(&self, row: usize, column: usize, ctx: &VoteContext<'_>) -> Option<[f32; 2]> {
        let patch = self.causes.get(row * self.grid.columns + column)?;
        let patch = ctx.map.patches.get(*patch as usize)?;
        Some([patch.x, patch.y])
    }

    /// Whether the ground at `p` (this raster's frame) is unseen, if `p`
    /// lies on the grid.
    fn unseen_at(&self, p: Point2<f64>) -> Option<bool> {
        let (row, column) = self.grid.cell(p.x, p.y)?;
        Some(self.unseen[row * self.grid.words_per_row + column / 64] & (1 << (column % 64)) != 0)
    }

    /// What collisions are tested against: the map's cells, and unseen
    /// ground when it is an obstacle (see [`Raster::block`]).
    fn blocked(&self) -> &[u64] {
        if self.unseen_blocks {
            &self.blocked
        } else {
            &self.bitmap
        }
    }

    /// Makes unseen ground block (`obstacle`) or not.
    fn block(&mut self, policy: UnseenGround) {
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
    fn unseen_over(&mut self, band: &[Entry], reach: f32, unseen: impl Fn(Point2<f64>) -> bool) {
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
    fn graded_crossed(&self, band: &[Entry], reach: f32, near: f32) -> (f32, f32) {
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

/// Cells under the footprint where the vehicle stands (s = 0). The local
/// map clears patches whose centres lie under the body grown by half a
/// patch; rasterised to this behaviour's grid, a patch just beyond that
/// can land in a grid cell inside the footprint, where every arc's sweep
/// meets it at once: all arcs vetoed, forwards and backing, though the
/// patch only touches the body's flank (`short_ditch_09`, a ditch's edge
/// beside the rear overhang after a turn round: stuck for 90 s). Such a
/// cell stops an arc only if driving it takes the footprint deeper over
/// the cell; an arc that slides past it or turns away is free of it.
#[derive(Debug, Clone, Default)]
struct UnderStart {
    /// The cells: bitmap word, bit, centre (the raster's frame).
    cells: Vec<(usize, u64, Point2<f64>)>,
    /// Scratch: an arc's blocked layer with the cells it leaves cleared.
    blocked: Vec<u64>,
}

impl UnderStart {
    /// Finds the cells of `raster` under `footprint` (not those on unseen
    /// ground too: clearing one would clear the unseen ground's block).
    fn find(&mut self, raster: &Raster, footprint: &Footprint) {
        self.cells.clear();
        let grid = &raster.grid;
        cells_inside(grid, &footprint.corners(), |row, from, to| {
            for column in from..=to {
                let word = row * grid.words_per_row + column / 64;
                let bit = 1u64 << (column % 64);
                if raster.bitmap[word] & bit != 0 && raster.unseen[word] & bit == 0 {
                    self.cells.push((word, bit, grid.centre(row, column)));
                }
            }
            false
        });
    }

    /// `blocked` as arc `arc` meets it: the cells under the start that
    /// driving the arc does not take `footprint` deeper over cleared;
    /// `None` when there are none (use `blocked` itself).
    fn for_arc(
        &mut self,
        blocked: &[u64],
        arc: Arc,
        footprint: &Footprint,
        step: f64,
    ) -> Option<&[u64]> {
        if self.cells.is_empty() {
            return None;
        }
        self.blocked.clear();
        self.blocked.extend_from_slice(blocked);
        for &(word, bit, centre) in &self.cells {
            if !deepens(arc, footprint, centre, step) {
                self.blocked[word] &= !bit;
            }
        }
        Some(&self.blocked)
    }
}

/// Whether driving `arc` takes `footprint` deeper over the point `p` (the
/// arc's start frame, inside the footprint there) within the footprint's
/// own length and width: the point's depth inside the rectangle, sampled
/// every `step` along the arc, grows.
fn deepens(arc: Arc, footprint: &Footprint, p: Point2<f64>, step: f64) -> bool {
    let depth = |q: Point2<f64>| {
        (footprint.x_max - q.x)
            .min(q.x - footprint.x_min)
            .min(footprint.half_width - q.y.abs())
    };
    let start = depth(p);
    let length = (footprint.x_max - footprint.x_min).hypot(2.0 * footprint.half_width) + step;
    let steps = (length / step).ceil() as usize;
    (1..=steps).any(|i| {
        let q = Rigid::of(&arc.pose_at(i as f64 * step)).invert(p);
        depth(q) > start + 1e-6
    })
}

/// The backward sweeps: one band per arc over a mirrored raster.
#[derive(Debug, Clone)]
struct Reverse {
    raster: Raster,
    /// Per arc: the body's band, and the band grown by the margin.
    bands: Vec<[Vec<Entry>; 2]>,
    /// Scratch: cells and unseen ground together.
    blocked: Vec<u64>,
    /// Per arc: the terrain's verdict backing up along it.
    verdicts: Vec<ArcTerrain>,
    /// The mirrored body the bands sweep.
    footprint: Footprint,
    /// Cells under it where the vehicle stands.
    under_start: UnderStart,
}

/// The grid covering every outline of `footprint` swept `reach` along
/// every arc.
fn grid_around(arcs: &arcnav_vehicle::ArcSet, footprint: Footprint, reach: f64, r: f64) -> Grid {
    let (mut lo, mut hi) = (
        Point2::new(f64::MAX, f64::MAX),
        Point2::new(f64::MIN, f64::MIN),
    );
    for arc in arcs.iter() {
        for outline in arc.swept(footprint, reach).outlines(0.25) {
            for corner in outline {
                lo = lo.inf(&corner);
                hi = hi.sup(&corner);
            }
        }
    }
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

/// The obstacle-avoidance behaviour.
#[derive(Debug, Clone)]
pub struct ObstacleAvoidance {
    config: ObstacleAvoidanceConfig,
    ahead: Raster,
    templates: Vec<Template>,
    /// Margin of band b (0 for the footprint itself).
    margins: Vec<f64>,
    /// The widest band within `reverse_margin_m`: the clearance a
    /// manoeuvre's leg keeps creeping forwards, as backing up keeps
    /// `reverse_margin_m`.
    crawl_band: usize,
    /// Deceleration the speed limits assume (half the vehicle's best), m/s².
    deceleration: f64,
    /// The vehicle's best deceleration, m/s².
    max_deceleration: f64,
    reverse: Option<Reverse>,
    /// Per arc: first collision distance (∞ if none within max), for speed.
    free: Vec<f64>,
    /// Per arc: where the crawl band first meets a cell (∞ if none).
    crawl_free: Vec<f64>,
    /// Per arc: where its footprint first meets unseen ground (distance,
    /// vehicle-frame point), when `unseen_ground` is `slow` (as an
    /// obstacle it is a collision in `free`).
    unseen_at: Vec<Option<(f64, [f32; 2])>>,
    /// Per arc: how far along it its footprint first meets a suspected
    /// drop-off.
    suspect_at: Vec<Option<f64>>,
    terrain: TerrainCheck,
    /// Per arc: this cycle's verdict on the ground.
    verdicts: Vec<ArcTerrain>,
    cruise_mps: f64,
    /// The body grown by half a patch ahead and to the sides (band 0).
    footprint: Footprint,
    /// The ground the wheels stand on, vehicle frame: never unseen.
    standing: Footprint,
    /// How the vehicle answers a command, and per arc this cycle's path
    /// its command would put it on.
    response: SteeringResponse,
    paths: Vec<DrivenPath>,
    /// Scratch: the map in the frame where a path settles on its arc, and
    /// the poses of the path before it does.
    shifted: Raster,
    lead_poses: Vec<(f64, ArcPose)>,
    /// Cells under the footprint where the vehicle stands.
    under_start: UnderStart,
    /// Scratch: the map patches a path's arc may reach this cycle.
    near: Vec<u32>,
    /// This cycle: distance from the rear axle to the nearest cell of each
    /// [`Layer`] of the vehicle-frame raster, m (∞ when it has none).
    nearest: [f64; 4],
}

/// The layers of a raster a path's lead is checked against.
#[derive(Debug, Clone, Copy)]
enum Layer {
    Blocked,
    Unseen,
    Graded,
    Suspect,
}

/// What one part of a path meets: its distances are along the path.
#[derive(Debug, Clone, Copy, Default)]
struct Met {
    /// The first cell (or unseen ground, when it is an obstacle) the
    /// footprint meets, and the map patch behind it (vehicle frame).
    collision: Option<(f64, Option<[f32; 2]>)>,
    /// The narrowest near-miss band that meets a cell.
    grazed: Option<usize>,
    /// The first cell the crawl band meets.
    crawled: Option<f64>,
    /// The first ground no image has seen (`slow`), and where (vehicle frame).
    unseen: Option<(f64, [f32; 2])>,
    /// The highest graded cost crossed, and within the speed horizon.
    graded: (f32, f32),
    /// The first suspected drop-off the footprint meets.
    suspect: Option<f64>,
}

/// The smaller of two values either part of a path may have met.
fn least<T: PartialOrd>(a: Option<T>, b: Option<T>) -> Option<T> {
    match (a, b) {
        (Some(a), Some(b)) => Some(if b < a { b } else { a }),
        (a, b) => a.or(b),
    }
}

/// The nearer of two things met (the first on a tie).
fn nearer<T>(a: Option<(f64, T)>, b: Option<(f64, T)>) -> Option<(f64, T)> {
    match (a, b) {
        (Some(a), Some(b)) => Some(if b.0 < a.0 { b } else { a }),
        (a, b) => a.or(b),
    }
}

impl Met {
    /// What the whole path meets, this part or `other`.
    fn and(self, other: Met) -> Met {
        Met {
            collision: nearer(self.collision, other.collision),
            grazed: least(self.grazed, other.grazed),
            crawled: least(self.crawled, other.crawled),
            unseen: nearer(self.unseen, other.unseen),
            graded: (
                self.graded.0.max(other.graded.0),
                self.graded.1.max(other.graded.1),
            ),
            suspect: least(self.suspect, other.suspect),
        }
    }
}

impl ObstacleAvoidance {
    /// Precomputes the swept bands of every arc.
    pub fn new(config: ObstacleAvoidanceConfig, setup: &Setup<'_>) -> Self {
        let half_patch = setup.localmap.patch_size_m / 2.0;
        let body = setup.vehicle.footprint();
        // The body grown by half a patch ahead and to the sides (the local
        // map clears patches overlapping its flanks), not behind: driving
        // forwards, what lies behind the rear bumper stays behind.
        let footprint = Footprint {
            x_min: body.x_min,
            x_max: body.x_max + half_patch,
            half_width: body.half_width + half_patch,
        };
        let bands = config.near_miss_bands as usize;
        let margins: Vec<f64> = (0..=bands)
            .map(|b| config.near_miss_m * b as f64 / bands.max(1) as f64)
            .collect();
        let crawl_band = margins
            .iter()
            .rposition(|&m| m <= config.reverse_margin_m + 1e-9)
            .unwrap_or(0);
        let reach = config.max_distance_m;
        let r = config.grid_resolution_m;
        let grid = grid_around(setup.arcs, footprint.widened(config.near_miss_m), reach, r);
        let templates = setup
            .arcs
            .iter()
            .map(|arc| build_template(arc, &footprint, &margins, &grid, reach))
            .collect();
        // The ground the wheels stand on: from the rear bumper to the
        // front axle, as wide as the footprint swept (the body and half a
        // patch). Not the front overhang: crept forward onto ground no
        // image has seen (a ledge in a lidar's blind zone), it must still
        // stop the vehicle.
        let wheels = footprint.x_min..=setup.vehicle.wheelbase_m.min(body.x_max);
        let ahead = Raster::new(grid, 1.0, |p| {
            wheels.contains(&p.x) && p.y.abs() <= footprint.half_width
        });
        let reverse = (config.reverse_reach_m > 0.0).then(|| {
            // The body mirrored (x -> -x), grown behind and to the sides:
            // backing up, what lies ahead of the front bumper stays there.
            let mirrored = Footprint {
                x_min: -body.x_max,
                x_max: -(body.x_min - half_patch),
                half_width: footprint.half_width,
            };
            let margin = config.reverse_margin_m;
            let grid = grid_around(
                setup.arcs,
                mirrored.widened(margin),
                config.reverse_reach_m,
                r,
            );
            let bands = setup
                .arcs
                .iter()
                .map(|arc| {
                    let template = build_template(
                        arc,
                        &mirrored,
                        &[0.0, margin],
                        &grid,
                        config.reverse_reach_m,
                    );
                    let mut bands = template.bands.into_iter();
                    [
                        bands.next().unwrap_or_default(),
                        bands.next().unwrap_or_default(),
                    ]
                })
                .collect();
            // Backing up, the whole body stands on seen ground (the
            // overhang over ground it drove across).
            let standing = Footprint {
                x_min: body.x_min - half_patch,
                ..footprint
            };
            let raster = Raster::new(grid, -1.0, |p| standing.contains(p));
            Reverse {
                blocked: vec![0; raster.bitmap.len()],
                raster,
                verdicts: vec![ArcTerrain::default(); setup.arcs.len()],
                bands,
                footprint: mirrored,
                under_start: UnderStart::default(),
            }
        });
        let mut terrain = TerrainCheck::new(
            &config.terrain,
            setup.vehicle,
            setup.arcs.curvatures(),
            config.max_distance_m,
        );
        if reverse.is_some() {
            terrain = terrain.with_reverse(setup.arcs.curvatures(), config.reverse_reach_m);
        }
        let shifted = Raster::new(ahead.grid.clone(), 1.0, |_| false);
        Self {
            terrain,
            footprint,
            standing: Footprint {
                x_min: footprint.x_min,
                x_max: setup.vehicle.wheelbase_m.min(body.x_max),
                half_width: footprint.half_width,
            },
            response: setup.steering_response(),
            paths: setup
                .arcs
                .curvatures()
                .iter()
                .map(|&k| DrivenPath::arc(k))
                .collect(),
            shifted,
            lead_poses: Vec::new(),
            under_start: UnderStart::default(),
            near: Vec::new(),
            nearest: [f64::INFINITY; 4],
            verdicts: vec![ArcTerrain::default(); setup.arcs.len()],
            cruise_mps: setup.cruise_mps,
            deceleration: setup.vehicle.max_deceleration_mps2 * config.braking_fraction,
            max_deceleration: setup.vehicle.max_deceleration_mps2,
            free: vec![f64::INFINITY; setup.arcs.len()],
            crawl_free: vec![f64::INFINITY; setup.arcs.len()],
            unseen_at: vec![None; setup.arcs.len()],
            suspect_at: vec![None; setup.arcs.len()],
            config,
            ahead,
            templates,
            crawl_band,
            margins,
            reverse,
        }
    }

    /// What arc `arc`'s path meets: before it settles on its arc, its
    /// footprints sampled every grid cell on the map as it is; after, the
    /// arc's precomputed sweep over the map placed where the path settles.
    fn meet(&mut self, arc: usize, ctx: &VoteContext<'_>, horizon: f64) -> Met {
        let path = self.paths[arc];
        let reach = self.config.max_distance_m;
        let lead = path.settled_at().min(reach);
        let policy = self.config.unseen_ground;
        let mut met = Met::default();
        if lead > 0.0 {
            path.sample_into(lead, self.ahead.grid.resolution, &mut self.lead_poses);
            met = self.meet_lead(ctx, horizon);
        }
        let rest = reach - lead;
        if rest <= 0.0 {
            return met;
        }
        let settled = path.settled_pose();
        let rigid = Rigid::of(&settled);
        let to_vehicle = |c| rigid.apply(c);
        let template = &self.templates[arc];
        let widest = self.margins.len() - 1;
        // Taken at once (standing, or arcs judged as arcs), the arc starts
        // where the vehicle is: the vehicle-frame raster serves.
        let at_once = path.is_arc();
        let raster = if at_once {
            &self.ahead
        } else {
            // The map in the frame where the path settles on its arc.
            let near = self.near.iter().map(|&i| i as usize);
            self.shifted.rasterise_with(ctx, near, |x, y| {
                let p = rigid.invert(Point2::new(x, y));
                (p.x, p.y)
            });
            if policy == UnseenGround::Obstacle {
                // Unseen ground is an obstacle, in every near-miss band:
                // read off the vehicle-frame layer (it comes in areas, not
                // single cells), or the map's own beyond that layer.
                let (ahead, standing) = (&self.ahead, self.standing);
                let seen = ctx.map.seen_lookup();
                self.shifted
                    .unseen_over(&template.bands[widest], rest as f32, |c| {
                        let q = to_vehicle(c);
                        ahead
                            .unseen_at(q)
                            .unwrap_or_else(|| !seen(q.x, q.y) && !standing.contains(q))
                    });
            }
            self.shifted.block(policy);
            &self.shifted
        };
        let rest = rest as f32;
        // Standing, the arc starts where the vehicle is: the cells under
        // its footprint there count only if the arc drives deeper over
        // them ([`UnderStart`]).
        let blocked = if at_once {
            let step = raster.grid.resolution;
            self.under_start
                .for_arc(
                    raster.blocked(),
                    Arc::new(ctx.arcs.curvature(arc).unwrap_or(0.0)),
                    &self.footprint,
                    step,
                )
                .unwrap_or(raster.blocked())
        } else {
            raster.blocked()
        };
        let mut part = Met::default();
        if first_in(blocked, &template.bands[widest], rest).is_some() {
            part.collision = first_in(blocked, &template.bands[0], rest)
                .map(|hit| (f64::from(hit.s) + lead, raster.cause(hit, blocked, ctx)));
            part.grazed =
                (1..=widest).find(|&b| first_in(blocked, &template.bands[b], rest).is_some());
            part.crawled = first_in(blocked, &template.bands[self.crawl_band], rest)
                .map(|hit| f64::from(hit.s) + lead);
        }
        part.graded = raster.graded_crossed(&template.bands[0], rest, (horizon - lead) as f32);
        if !raster.suspect_cells.is_empty() {
            part.suspect = first_in(&raster.suspect, &template.bands[0], rest)
                .map(|hit| f64::from(hit.s) + lead);
        }
        if policy == UnseenGround::Slow {
            part.unseen = if at_once {
                first_in(&raster.unseen, &template.bands[0], rest).map(|hit| {
                    let (row, column) = raster.grid.first_cell(hit, &raster.unseen);
                    let c = raster.grid.centre(row, column);
                    (f64::from(hit.s), [c.x as f32, c.y as f32])
                })
            } else {
                // Cell by cell along the body's band, nearest first.
                let seen = ctx.map.seen_lookup();
                template
                    .body
                    .iter()
                    .take_while(|(s, _)| *s <= rest)
                    .find_map(|&(s, [x, y])| {
                        let q = to_vehicle(Point2::new(f64::from(x), f64::from(y)));
                        let unseen = self
                            .ahead
                            .unseen_at(q)
                            .unwrap_or_else(|| !seen(q.x, q.y) && !self.standing.contains(q));
                        unseen.then_some((f64::from(s) + lead, [q.x as f32, q.y as f32]))
                    })
            };
        }
        met.and(part)
    }

    /// What the path meets before it settles on its arc (`lead_poses`):
    /// the footprint at each pose on the map as it is.
    fn meet_lead(&self, ctx: &VoteContext<'_>, horizon: f64) -> Met {
        let raster = &self.ahead;
        let grid = &raster.grid;
        let widest = self.margins.len() - 1;
        let corners = |pose: &ArcPose, band: usize| {
            let rigid = Rigid::of(pose);
            self.footprint
                .widened(self.margins[band])
                .corners()
                .map(|c| rigid.apply(c))
        };
        // The first cell of `layer` under the footprint of `band` at `pose`.
        let under = |pose: &ArcPose, band: usize, layer: &[u64]| {
            let mut found = None;
            cells_inside(grid, &corners(pose, band), |row, from, to| {
                found = first_set(layer, grid, row, from, to).map(|column| (row, column));
                found.is_some()
            });
            found
        };
        let poses = &self.lead_poses;
        let blocked = raster.blocked();
        let mut met = Met::default();
        // How far from the rear axle the footprints of this lead reach: a
        // layer with nothing that near has nothing to meet.
        let lead = poses.last().map_or(0.0, |(s, _)| *s);
        let body = self.footprint.widened(self.margins[widest]);
        let within = lead + body.x_max.max(-body.x_min).hypot(body.half_width) + grid.resolution;
        let near = |layer: Layer| self.nearest[layer as usize] <= within;
        if near(Layer::Blocked)
            && let Some(from) = poses
                .iter()
                .position(|(_, p)| under(p, widest, blocked).is_some())
        {
            met.collision = poses[from..].iter().find_map(|(s, p)| {
                under(p, 0, blocked).map(|(row, column)| (*s, raster.cause_at(row, column, ctx)))
            });
            met.grazed = (1..=widest).find(|&b| {
                poses[from..]
                    .iter()
                    .any(|(_, p)| under(p, b, blocked).is_some())
            });
            met.crawled = poses[from..]
                .iter()
                .find(|(_, p)| under(p, self.crawl_band, blocked).is_some())
                .map(|(s, _)| *s);
        }
        if self.config.unseen_ground == UnseenGround::Slow && near(Layer::Unseen) {
            met.unseen = poses.iter().find_map(|(s, p)| {
                under(p, 0, &raster.unseen).map(|(row, column)| {
                    let c = grid.centre(row, column);
                    (*s, [c.x as f32, c.y as f32])
                })
            });
        }
        if !raster.suspect_cells.is_empty() && near(Layer::Suspect) {
            met.suspect = poses
                .iter()
                .find(|(_, p)| under(p, 0, &raster.suspect).is_some())
                .map(|(s, _)| *s);
        }
        if !raster.graded_cells.is_empty() && near(Layer::Graded) {
            for (s, p) in poses {
                cells_inside(grid, &corners(p, 0), |row, from, to| {
                    for column in from..=to {
                        if raster.graded[row * grid.words_per_row + column / 64]
                            & (1 << (column % 64))
                            != 0
                        {
                            let cost = raster.graded_cost[row * grid.columns + column];
                            met.graded.0 = met.graded.0.max(cost);
                            if *s <= horizon {
                                met.graded.1 = met.graded.1.max(cost);
                            }
                        }
                    }
                    false
                });
            }
        }
        met
    }

    /// Each arc's clearance backing up: cells, unseen ground and ground the
    /// vehicle cannot stand on (its attitude or chassis) stop it.
    fn vote_reverse(&mut self, ctx: &VoteContext<'_>, votes: &mut Votes) {
        let Some(reverse) = &mut self.reverse else {
            return;
        };
        let reach = self.config.reverse_reach_m;
        self.terrain.judge_reverse_arcs(
            &ctx.map.elevation,
            &ctx.map.world_from_vehicle,
            &mut reverse.verdicts,
        );
        reverse.raster.rasterise(ctx);
        reverse.raster.rasterise_unseen(ctx);
        for ((blocked, cell), unseen) in reverse
            .blocked
            .iter_mut()
            .zip(&reverse.raster.bitmap)
            .zip(&reverse.raster.unseen)
        {
            *blocked = cell | unseen;
        }
        reverse
            .under_start
            .find(&reverse.raster, &reverse.footprint);
        let step = reverse.raster.grid.resolution;
        for (arc, [body, margin]) in reverse.bands.iter().enumerate().take(votes.len()) {
            // The body may not meet a cell or unseen ground; the margin
            // beside it may not close on a cell. Cells already inside the
            // margin where the vehicle stands (s = 0: a trunk beside the
            // flank) are left to the body's band; cells inside the body's
            // band there, to the arc's direction ([`UnderStart`]; mirrored,
            // the backward sweep is the forward arc's).
            let curvature = ctx.arcs.curvature(arc).unwrap_or(0.0);
            let blocked = reverse
                .under_start
                .for_arc(
                    &reverse.blocked,
                    Arc::new(curvature),
                    &reverse.footprint,
                    step,
                )
                .unwrap_or(&reverse.blocked);
            let body_hit = first_in(blocked, body, reach as f32).map(|hit| hit.s);
            let moving = margin.partition_point(|e| e.s <= 0.0);
            let margin_hit =
                first_in(&reverse.raster.bitmap, &margin[moving..], reach as f32).map(|hit| hit.s);
            let ground = reverse.verdicts[arc].forbidden.map(|(s, _)| s);
            let clear = body_hit
                .into_iter()
                .chain(margin_hit)
                .map(f64::from)
                .chain(ground)
                .fold(reach, f64::min);
            votes.set_reverse_clearance(arc, clear);
        }
    }
}

/// The first entry of `band` within `reach` that holds a cell of `bitmap`.
fn first_in<'t>(bitmap: &[u64], band: &'t [Entry], reach: f32) -> Option<&'t Entry> {
    band.iter()
        .take_while(|e| e.s <= reach)
        .find(|e| bitmap[e.word as usize] & e.mask != 0)
}

/// Visits, row by row, the cells of `grid` whose centres lie inside the
/// convex quadrilateral `corners` (grid frame) as runs `(row, first
/// column, last column)`; stops when `visit` returns true, and says
/// whether it did.
fn cells_inside(
    grid: &Grid,
    corners: &[Point2<f64>; 4],
    mut visit: impl FnMut(usize, usize, usize) -> bool,
) -> bool {
    let r = grid.resolution;
    let (lo_x, hi_x) = corners
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
    let edges: [(Point2<f64>, Point2<f64>, Option<f64>); 4] = std::array::from_fn(|i| {
        let (a, b) = (corners[i], corners[(i + 1) % 4]);
        (a, b, (a.x != b.x).then(|| (b.y - a.y) / (b.x - a.x)))
    });
    for row in first as usize..=last {
        let x = grid.x0 + (row as f64 + 0.5) * r;
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for &(a, b, slope) in &edges {
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
        let from = ceil((lo - grid.y0) / r - 0.5).max(0.0);
        let to = floor((hi - grid.y0) / r - 0.5);
        if from.is_nan() || to.is_nan() || from > to || from >= grid.columns as f64 {
            continue;
        }
        if visit(row, from as usize, (to as usize).min(grid.columns - 1)) {
            return true;
        }
    }
    false
}

/// `x.floor()` without the library call the baseline x86-64 target makes
/// of it (no SSE4.1); NaN stays NaN, and beyond ±2⁵³ x is whole already.
fn floor(x: f64) -> f64 {
    if x.is_nan() || x.abs() >= 9.0e15 {
        return x;
    }
    let t = x as i64 as f64;
    if t > x { t - 1.0 } else { t }
}

/// `x.ceil()`, as [`floor`].
fn ceil(x: f64) -> f64 {
    -floor(-x)
}

/// A pose's rotation and translation, its sine and cosine taken once.
#[derive(Debug, Clone, Copy)]
struct Rigid {
    cos: f64,
    sin: f64,
    x: f64,
    y: f64,
}

impl Rigid {
    fn of(pose: &ArcPose) -> Self {
        let (sin, cos) = pose.heading.sin_cos();
        Self {
            cos,
            sin,
            x: pose.position.x,
            y: pose.position.y,
        }
    }

    /// `p`, given in the pose's frame, in the frame the pose is given in.
    fn apply(&self, p: Point2<f64>) -> Point2<f64> {
        Point2::new(
            self.x + self.cos * p.x - self.sin * p.y,
            self.y + self.sin * p.x + self.cos * p.y,
        )
    }

    /// `p`, given in the frame the pose is given in, in the pose's frame.
    fn invert(&self, p: Point2<f64>) -> Point2<f64> {
        let (dx, dy) = (p.x - self.x, p.y - self.y);
        Point2::new(
            self.cos * dx + self.sin * dy,
            -self.sin * dx + self.cos * dy,
        )
    }
}

/// Distance from the origin to the nearest cell centre set in `layer`, m.
fn nearest_set(layer: &[u64], grid: &Grid) -> f64 {
    let mut nearest = f64::INFINITY;
    for (word, &bits) in layer.iter().enumerate() {
        let mut bits = bits;
        let row = word / grid.words_per_row;
        let base = (word % grid.words_per_row) * 64;
        while bits != 0 {
            let column = base + bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let c = grid.centre(row, column);
            nearest = nearest.min(c.x.hypot(c.y));
        }
    }
    nearest
}

/// The first column in `from..=to` of `row` set in `layer`.
fn first_set(layer: &[u64], grid: &Grid, row: usize, from: usize, to: usize) -> Option<usize> {
    let base = row * grid.words_per_row;
    for word in from / 64..=to / 64 {
        let low = if word == from / 64 { from % 64 } else { 0 };
        let high = if word == to / 64 { to % 64 } else { 63 };
        let mask = (u64::MAX << low) & (u64::MAX >> (63 - high));
        let hits = layer[base + word] & mask;
        if hits != 0 {
            return Some(word * 64 + hits.trailing_zeros() as usize);
        }
    }
    None
}

fn build_template(
    arc: Arc,
    footprint: &Footprint,
    margins: &[f64],
    grid: &Grid,
    reach: f64,
) -> Template {
    let widest = arc.swept(footprint.widened(margins[margins.len() - 1]), reach);
    // Bounds of this arc's widest band, in grid cells.
    let (mut lo, mut hi) = (
        Point2::new(f64::MAX, f64::MAX),
        Point2::new(f64::MIN, f64::MIN),
    );
    for outline in widest.outlines(0.25) {
        for corner in outline {
            lo = lo.inf(&corner);
            hi = hi.sup(&corner);
        }
    }
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
    Template { bands, body }
}

impl Behaviour for ObstacleAvoidance {
    fn name(&self) -> &str {
        Self::NAME
    }

    fn vote(&mut self, ctx: &VoteContext<'_>, votes: &mut Votes) {
        self.vote_reverse(ctx, votes);
        self.ahead.rasterise(ctx);
        let policy = self.config.unseen_ground;
        if policy != UnseenGround::Free {
            self.ahead.rasterise_unseen(ctx);
        }
        self.ahead.block(policy);
        let (min, max) = (self.config.min_distance_m, self.config.max_distance_m);
        // The ground ahead at the vehicle's scale: the speed horizon is
        // where the vehicle gets to while it reacts and brakes from cruise.
        let cruise = self.cruise_mps;
        let horizon = cruise * self.config.reaction_s
            + cruise * cruise / (2.0 * self.deceleration)
            + self.terrain.config().step_m;
        // The path each arc's command would put the vehicle on.
        let steering = ctx.steering();
        let arcs = self.templates.len().min(votes.len()).min(ctx.arcs.len());
        for (path, &k) in self.paths.iter_mut().zip(ctx.arcs.curvatures()) {
            *path = DrivenPath::new(&steering, &self.response, k);
        }
        // Cells under the footprint count per arc only for arcs taken at
        // once (`meet`): driving, none are looked for.
        if self.paths[..arcs].iter().any(DrivenPath::is_arc) {
            self.under_start.find(&self.ahead, &self.footprint);
        } else {
            self.under_start.cells.clear();
        }
        if self.paths[..arcs].iter().all(DrivenPath::is_arc) {
            // Every arc taken at once (standing, or arcs judged as arcs):
            // the arcs' own precomputed poses.
            self.terrain.judge_arcs(
                &ctx.map.elevation,
                &ctx.map.world_from_vehicle,
                horizon,
                &mut self.verdicts,
            );
        } else {
            // The patches any path may reach: within its length and the
            // widest band's reach from the rear axle.
            let body = self.footprint.widened(self.config.near_miss_m);
            let within = max + body.x_max.max(-body.x_min).hypot(body.half_width);
            self.near.clear();
            self.near.extend(
                ctx.map
                    .patches
                    .iter()
                    .enumerate()
                    .filter(|(_, p)| f64::from(p.x).hypot(f64::from(p.y)) <= within)
                    .map(|(i, _)| i as u32),
            );
            self.nearest = [
                self.ahead.blocked(),
                &self.ahead.unseen,
                &self.ahead.graded,
                &self.ahead.suspect,
            ]
            .map(|layer| nearest_set(layer, &self.ahead.grid));
            self.terrain.judge_paths(
                &ctx.map.elevation,
                &ctx.map.world_from_vehicle,
                horizon,
                &self.paths[..arcs],
                &mut self.verdicts,
            );
        }
        let terrain_penalty = self.config.terrain.penalty;
        for arc in 0..arcs {
            let met = self.meet(arc, ctx, horizon);
            let verdict = self.verdicts[arc];
            self.free[arc] = f64::INFINITY;
            self.crawl_free[arc] = met.crawled.unwrap_or(f64::INFINITY);
            self.unseen_at[arc] = met.unseen;
            self.suspect_at[arc] = met.suspect;
            // The first collision with a cell, or with ground the vehicle
            // cannot stand on (its attitude or chassis), whichever is nearer.
            let collision = match (met.collision, verdict.forbidden) {
                (Some((d, cause)), Some((g, _))) if d <= g => Some((d, cause)),
                (_, Some((g, at))) => Some((g, Some(at))),
                (cell, None) => cell,
            };
            if let Some((distance, cause)) = collision {
                self.free[arc] = distance;
                if distance < min {
                    votes.veto(arc, cause);
                } else {
                    votes.set(arc, -(1.0 - (distance - min) / (max - min)) as f32);
                }
                continue;
            }
            // Clear of collisions: the narrowest band that grazes a cell,
            // and how hard the ground along the path is.
            let penalty = match met.grazed {
                Some(band) => {
                    let clearance = self.margins[band - 1];
                    self.config.near_miss_penalty * (1.0 - clearance / self.config.near_miss_m)
                }
                None => 0.0,
            };
            // Graded ground the footprint crosses (perception's graded
            // cells, e.g. 000's D̃) counts like the terrain's severity.
            let (crossed, near) = met.graded;
            self.verdicts[arc].near_severity =
                self.verdicts[arc].near_severity.max(f64::from(near));
            let severity = verdict.severity.max(f64::from(crossed));
            votes.set(arc, (1.0 - penalty - terrain_penalty * severity) as f32);
        }
        // How far each arc is clear at a crawl: to the first collision,
        // cell within the crawl band or unseen ground, however close (a
        // turning manoeuvre's leg).
        for arc in 0..arcs {
            let unseen = self.unseen_at[arc].map_or(f64::INFINITY, |(s, _)| s);
            let clear = self.free[arc].min(self.crawl_free[arc]).min(unseen);
            votes.set_forward_clearance(arc, clear.min(max));
        }
        if !self.config.speed_vote {
            return;
        }
        // Per arc, the speed at which the vehicle stops in time on it:
        // v·t + v²/2a = room, solved for v.
        let (a, t) = (self.deceleration, self.config.reaction_s);
        let stopping_speed =
            |room: f64| -a * t + ((a * t).powi(2) + 2.0 * a * room.max(0.0)).sqrt();
        // How far the vehicle runs before it stands, braking as hard as it
        // can from its speed now.
        let speed = ctx.pose.velocity.norm();
        let braking = speed * t + speed * speed / (2.0 * self.max_deceleration);
        // A suspected drop-off is flagged for certain, if it is a hole, once
        // the front is `hole_seen_within_m` from it: an arc towards one is
        // driven no faster than the vehicle stops short of it, and never
        // slower than it stops within that distance (by then a hole would
        // be a cell, and an edge still suspected is none).
        let margin = self.config.stop_margin_m;
        let hole_speed = stopping_speed(self.config.hole_seen_within_m - margin);
        for arc in 0..arcs {
            if votes.is_vetoed(arc) {
                continue;
            }
            let mut room = self.free[arc].min(max) - self.config.stop_margin_m;
            if let Some((distance, at)) = self.unseen_at[arc] {
                // Stop `stop_margin_m` before the first unseen ground the
                // footprint meets (its patch may begin past the edge);
                // an arc the vehicle can no longer stop on before it, at
                // the speed it has, is forbidden: its speed limit would
                // come too late.
                if distance < braking {
                    votes.veto(arc, Some(at));
                    continue;
                }
                room = room.min(distance - self.config.stop_margin_m);
            }
            // Terrain speed: from cruise at severity 0 down to
            // min_speed_fraction of it at severity 1 over the ground reached
            // before the vehicle could slow down.
            // (No limit on easy ground: cruise is the arbiter's to set.)
            let floor = self.config.terrain.min_speed_fraction;
            let severity = self.verdicts[arc].near_severity;
            let terrain = if severity > 0.0 {
                cruise * (1.0 - (1.0 - floor) * severity)
            } else {
                f64::INFINITY
            };
            let suspect = self.suspect_at[arc].map_or(f64::INFINITY, |distance| {
                stopping_speed(distance - margin).max(hole_speed)
            });
            votes.limit_arc_speed(arc, stopping_speed(room).min(terrain).min(suspect));
        }
    }
}

impl Plugin for ObstacleAvoidance {
    const NAME: &'static str = "obstacle_avoidance";
    type Config = ObstacleAvoidanceConfig;

    fn validate(c: &Self::Config, setup: &Setup<'_>) -> Result<(), ConfigError> {
        config::positive("min_distance_m", c.min_distance_m)?;
        config::positive("max_distance_m", c.max_distance_m)?;
        if c.max_distance_m <= c.min_distance_m {
            return Err(ConfigError::new(
                "max_distance_m",
                format!(
                    "is {} m, must exceed min_distance_m ({} m)",
                    c.max_distance_m, c.min_distance_m
                ),
            ));
        }
        if c.max_distance_m > 100.0 {
            return Err(ConfigError::new(
                "max_distance_m",
                format!("is {} m, at most 100 m", c.max_distance_m),
            ));
        }
        // The footprint is widened by it over the grid of every arc: 1e300
        // had hung the first vote.
        config::in_range("near_miss_m", c.near_miss_m, 0.01, 10.0)?;
        config::in_range("near_miss_penalty", c.near_miss_penalty, 0.0, 2.0)?;
        if !(1..=16).contains(&c.near_miss_bands) {
            return Err(ConfigError::new(
                "near_miss_bands",
                format!("is {}, must be 1 to 16", c.near_miss_bands),
            ));
        }
        config::in_range("grid_resolution_m", c.grid_resolution_m, 0.05, 1.0)?;
        config::non_negative("stop_margin_m", c.stop_margin_m)?;
        config::non_negative("reaction_s", c.reaction_s)?;
        config::in_range("braking_fraction", c.braking_fraction, 0.1, 1.0)?;
        config::in_range("reverse_reach_m", c.reverse_reach_m, 0.0, 20.0)?;
        config::in_range("reverse_margin_m", c.reverse_margin_m, 0.0, 2.0)?;
        c.terrain
            .validate(setup.vehicle)
            .map_err(|e| e.within("terrain"))
    }

    fn build(config: Self::Config, setup: &Setup<'_>) -> Self {
        Self::new(config, setup)
    }
}
