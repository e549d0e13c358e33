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
//! **Creeping forwards**: each arc's distance to its first collision or
//! unseen ground, however close, also goes out with the votes
//! ([`Votes::set_forward_clearance`]). `min_distance_m` vetoes arcs for
//! driving at speed; a turning manoeuvre's short legs at a crawl may still
//! take them as far as they are clear.

use std::collections::HashMap;

use arcnav_arbiter::Votes;
use arcnav_vehicle::config::{self, ConfigError};
use arcnav_vehicle::{Arc, Footprint, SweptFootprint};
use nalgebra::Point2;
use serde::{Deserialize, Serialize};

use crate::behaviour::{Behaviour, Setup, VoteContext};
use crate::registry::Plugin;
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
    /// What ground no image has seen is: slow (drive only as fast as the
    /// vehicle can stop within seen ground), obstacle, or free.
    pub unseen_ground: UnseenGround,
    /// Backward arcs are checked this far, m (0: no opinion on backing up,
    /// so the arbiter never backs up).
    pub reverse_reach_m: f64,
    /// Clearance kept to each side of the body when backing up, m.
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
            unseen_ground: UnseenGround::Slow,
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
}

/// The vehicle-frame grid the map is rasterised into.
#[derive(Debug, Clone)]
struct Grid {
    x0: f64,
    y0: f64,
    resolution: f64,
    rows: usize,
    columns: usize,
    words_per_row: usize,
}

impl Grid {
    fn cell(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let (fx, fy) = (
            (x - self.x0) / self.resolution,
            (y - self.y0) / self.resolution,
        );
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
            mirror,
            grid,
        }
    }

    /// Rasterises the map's cells (clearing the last cycle's).
    fn rasterise(&mut self, ctx: &VoteContext<'_>) {
        for &cell in &self.set_cells {
            let (row, column) = (
                cell as usize / self.grid.columns,
                cell as usize % self.grid.columns,
            );
            self.bitmap[row * self.grid.words_per_row + column / 64] = 0;
            self.causes[cell as usize] = u32::MAX;
        }
        self.set_cells.clear();
        for &cell in &self.graded_cells {
            let (row, column) = (
                cell as usize / self.grid.columns,
                cell as usize % self.grid.columns,
            );
            self.graded[row * self.grid.words_per_row + column / 64] = 0;
            self.graded_cost[cell as usize] = 0.0;
        }
        self.graded_cells.clear();
        for (index, patch) in ctx.map.patches.iter().enumerate() {
            let (x, y) = (self.mirror * f64::from(patch.x), f64::from(patch.y));
            let Some((row, column)) = self.grid.cell(x, y) else {
                continue;
            };
            let cell = row * self.grid.columns + column;
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

    /// The map cell behind a hit entry, vehicle frame.
    fn cause(&self, entry: &Entry, ctx: &VoteContext<'_>) -> Option<[f32; 2]> {
        let (row, column) = self.grid.first_cell(entry, &self.bitmap);
        let patch = self.causes.get(row * self.grid.columns + column)?;
        let patch = ctx.map.patches.get(*patch as usize)?;
        Some([patch.x, patch.y])
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
    /// Deceleration the speed limits assume (half the vehicle's best), m/s².
    deceleration: f64,
    /// The vehicle's best deceleration, m/s².
    max_deceleration: f64,
    reverse: Option<Reverse>,
    /// Per arc: first collision distance (∞ if none within max), for speed.
    free: Vec<f64>,
    /// Per arc: where its footprint first meets unseen ground, when
    /// `unseen_ground` is `slow` (as an obstacle it is a collision in `free`).
    unseen_at: Vec<Option<Entry>>,
    terrain: TerrainCheck,
    /// Per arc: this cycle's verdict on the ground.
    verdicts: Vec<ArcTerrain>,
    cruise_mps: f64,
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
        Self {
            terrain,
            verdicts: vec![ArcTerrain::default(); setup.arcs.len()],
            cruise_mps: setup.cruise_mps,
            deceleration: setup.vehicle.max_deceleration_mps2 * 0.5,
            max_deceleration: setup.vehicle.max_deceleration_mps2,
            free: vec![f64::INFINITY; setup.arcs.len()],
            unseen_at: vec![None; setup.arcs.len()],
            config,
            ahead,
            templates,
            margins,
            reverse,
        }
    }

    /// The first entry of `band` that holds a map cell within `reach`.
    fn first_hit<'t>(&self, band: &'t [Entry], reach: f32) -> Option<&'t Entry> {
        first_in(&self.ahead.bitmap, band, reach)
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
        for (arc, [body, margin]) in reverse.bands.iter().enumerate().take(votes.len()) {
            // The body may not meet a cell or unseen ground; the margin
            // beside it may not close on a cell. Cells already inside the
            // margin where the vehicle stands (s = 0: a trunk beside the
            // flank) are left to the body's band.
            let body_hit = first_in(&reverse.blocked, body, reach as f32).map(|hit| hit.s);
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
    Template { bands }
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
            if policy == UnseenGround::Obstacle {
                let ahead = &mut self.ahead;
                for (cell, unseen) in ahead.bitmap.iter_mut().zip(&ahead.unseen) {
                    *cell |= unseen;
                }
            }
        }
        let (min, max) = (self.config.min_distance_m, self.config.max_distance_m);
        let reach = max as f32;
        let widest = self.margins.len() - 1;
        // The ground ahead at the vehicle's scale: the speed horizon is
        // where the vehicle gets to while it reacts and brakes from cruise.
        let cruise = self.cruise_mps;
        let horizon = cruise * self.config.reaction_s
            + cruise * cruise / (2.0 * self.deceleration)
            + self.terrain.config().step_m;
        self.terrain.judge_arcs(
            &ctx.map.elevation,
            &ctx.map.world_from_vehicle,
            horizon,
            &mut self.verdicts,
        );
        let terrain_penalty = self.config.terrain.penalty;
        for arc in 0..self.templates.len().min(votes.len()) {
            let template = &self.templates[arc];
            let verdict = self.verdicts[arc];
            self.free[arc] = f64::INFINITY;
            // The bands are nested: when the widest touches no cell, no
            // band does (most arcs are decided by this one pass).
            let grazed = self.first_hit(&template.bands[widest], reach).is_some();
            // The first collision with a cell, or with ground the vehicle
            // cannot stand on (its attitude or chassis), whichever is nearer.
            let cell = grazed
                .then(|| self.first_hit(&template.bands[0], reach))
                .flatten()
                .map(|hit| (f64::from(hit.s), hit));
            let ground = verdict.forbidden;
            let collision = match (cell, ground) {
                (Some((d, hit)), Some((g, _))) if d <= g => Some((d, self.ahead.cause(hit, ctx))),
                (_, Some((g, at))) => Some((g, Some(at))),
                (Some((d, hit)), None) => Some((d, self.ahead.cause(hit, ctx))),
                (None, None) => None,
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
            // and how hard the ground along the arc is.
            let narrowest = grazed
                .then(|| {
                    (1..=widest).find(|&b| self.first_hit(&template.bands[b], reach).is_some())
                })
                .flatten();
            let penalty = match narrowest {
                Some(band) => {
                    let clearance = self.margins[band - 1];
                    self.config.near_miss_penalty * (1.0 - clearance / self.config.near_miss_m)
                }
                None => 0.0,
            };
            // Graded ground the footprint crosses (perception's graded
            // cells, e.g. 000's D̃) counts like the terrain's severity.
            let (crossed, near) =
                self.ahead
                    .graded_crossed(&template.bands[0], reach, horizon as f32);
            self.verdicts[arc].near_severity =
                self.verdicts[arc].near_severity.max(f64::from(near));
            let severity = verdict.severity.max(f64::from(crossed));
            votes.set(arc, (1.0 - penalty - terrain_penalty * severity) as f32);
        }
        // How far each arc is clear at a crawl: to the first collision or
        // unseen ground, however close (a turning manoeuvre's leg).
        for arc in 0..self.templates.len().min(votes.len()) {
            self.unseen_at[arc] = (policy == UnseenGround::Slow)
                .then(|| first_in(&self.ahead.unseen, &self.templates[arc].bands[0], reach))
                .flatten()
                .copied();
            let unseen = self.unseen_at[arc].map_or(f64::INFINITY, |hit| f64::from(hit.s));
            votes.set_forward_clearance(arc, self.free[arc].min(unseen).min(max));
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
        for arc in 0..self.templates.len().min(votes.len()) {
            if votes.is_vetoed(arc) {
                continue;
            }
            let mut room = self.free[arc].min(max) - self.config.stop_margin_m;
            if let Some(unseen) = &self.unseen_at[arc] {
                // Stop `stop_margin_m` before the first unseen ground the
                // footprint meets (its patch may begin past the edge);
                // an arc the vehicle can no longer stop on before it, at
                // the speed it has, is forbidden: its speed limit would
                // come too late.
                let distance = f64::from(unseen.s);
                if distance < braking {
                    let grid = &self.ahead.grid;
                    let (row, column) = grid.first_cell(unseen, &self.ahead.unseen);
                    let p = grid.centre(row, column);
                    votes.veto(arc, Some([p.x as f32, p.y as f32]));
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
            votes.limit_arc_speed(arc, stopping_speed(room).min(terrain));
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
        config::positive("near_miss_m", c.near_miss_m)?;
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
