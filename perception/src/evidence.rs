//! Hole evidence accumulated over images (issue 63): where ground returns
//! have landed, image after image, and where rays only ever passed over.
//!
//! One image suspects a hole's near edge only when its dip exceeds the
//! height error of a far return (`[perception.drop_off]`, see
//! `arcnav_config::speed_bound`):
//!
//! ```text
//! (w − u)·H/R > noise_m + Δ·R
//! ```
//!
//! where `u` is how far past the edge the next row would have met level
//! ground: the 64-beam lidar 2.4 m up is certain of it only within 11.4 m,
//! where rows lie close enough that some `u` is small. But a hole leaves
//! ground that *no* return ever reaches at ground height, whatever the
//! image, while the rows of a moving sensor sweep the ground around it
//! (each image lands them `v/f` farther on, and they draw closer together
//! as the vehicle nears): level ground is hit densely within a few metres
//! of travel, and a hole is not hit at all.
//!
//! This layer keeps, per world-aligned cell of `[perception.evidence]
//! cell_size_m` (0.1 m: a gap the wheels do not bridge spans several),
//! the highest return that landed in it (any image), and per tile of 4×4
//! cells how far the vehicle had travelled when a ray first passed over
//! it. A return of a column (the near edge), its next return a gap `g`
//! beyond (`g·|cos φ| > max_gap_m` along the heading) and the one beyond
//! that, is a suspected hole when
//!
//! ```text
//! v > noise_m + Δ·g        and        a run of settled cells along the gap,
//!                                      at least max_gap_m − cell long,
//!                                      holds no return at ground height
//! ```
//!
//! where `v`, the notch, is how far the far return lies below the ground
//! through the near edge and the return beyond it (a hole's far wall
//! under ground that goes on; a slope or a roll of the ground is no
//! notch), the ground beyond rising back at least `v/2` above the far
//! return. The notch is judged between returns of one column a gap apart,
//! so an error of the pose's attitude (what `Δ` allows for, by range)
//! moves them alike but for `Δ·g`; what the single image could not tell
//! (a row landing far past the edge shows almost no dip) the history
//! tells: no return has ever been seen in the gap. A hole `w` wide holds
//! at least `⌊w/cell⌋ − 1` whole cells, so one 0.8 m wide or more is
//! certain to leave the run. A cell is *settled* once the vehicle has
//! travelled `settle_m` since a ray first passed over its tile, so ground
//! newly in view, or watched from a standstill (the rows land where they
//! landed), is not taken for a hole because no row has yet landed in it.
//! The suspected cell is where the unseen run begins.
//!
//! Where returns are sparse, the ground beside a hole may still be unseen
//! and join it in the run: from 20 m, where a 10 cm cell of level ground
//! has about even odds of no return yet at 8 m/s, a 0.3 m rut may be
//! suspected; from 16 m it is not (the tests drive both).
//!
//! The same history says where the ground is *verified* (issue 63 item
//! 2): a gap of a column no longer than the wheels bridge hides no hole,
//! nor does one within `verified_within_m` of the sensor (where one image
//! is certain to suspect a hole, `speed_bound.suspect_range_m`), nor one
//! whose cells hold no run of `max_gap_m − cell` that no return of any
//! image reached at ground height (`min_depth_m + Δ·g` below the lower
//! end: a smaller step down is driven). The rest of each column, and all
//! of it beyond `reach_m`, is reported as shadow (ground not seen), so
//! that the local map sees only verified ground and obstacle avoidance's
//! speed governor stops short of the rest (`verify`, on where the cruise
//! speed needs it).
//!
//! Only what the vehicle drives into is kept: returns ahead of the
//! sensor, within `reach_m` of it and no wider than the region. The
//! window is robot-centric and scrolls: a ring of tiles indexed by world
//! tile modulo its side, each knowing which world tile it holds, so
//! ground left behind is forgotten when ground ahead takes its place.
//! Memory is fixed by `reach_m` and the cell size (1.7 MiB by default).

use arcnav_vehicle::Isometry;

#[cfg(test)]
use crate::config::DropOffConfig;
use crate::config::{EvidenceConfig, MAX_EVIDENCE_SIDE, PerceptionConfig};
use crate::evaluator::{ImageStats, ObstacleCell, ObstacleReport, Reasons, Region};
use crate::grid::{Projector, RowPoints, level_frames};
use crate::image::RangeImage;
use crate::shadow::{Shadow, Shadows};

/// Cells are kept in square tiles of this many a side: the cells of a
/// tile share a cache line (16 heights of 4 bytes), and a tile knows the
/// world tile it holds and when a ray first passed over it.
const TILE: usize = 4;
const TILE_CELLS: usize = TILE * TILE;

/// The side of the ring holding every cell within `reach` of the sensor,
/// tiles (at most [`MAX_EVIDENCE_SIDE`] cells: what validation allows).
fn ring_side(reach: f64, cell: f64) -> usize {
    let tiles = (2.0 * reach / (cell * TILE as f64)).ceil() + 2.0;
    (tiles.max(1.0) as usize).min(MAX_EVIDENCE_SIDE / TILE)
}

/// One tile of the ring.
#[derive(Debug, Clone, Copy)]
struct Tile {
    /// The world tile held.
    key: [i32; 2],
    /// The vehicle's travel when a ray first passed over it (NaN: none did).
    passed: f32,
}

const EMPTY: Tile = Tile {
    key: [i32::MIN; 2],
    passed: f32::NAN,
};

/// A tile's cells when it takes new ground: no return yet.
const NO_TOPS: [f32; TILE_CELLS] = [f32::NEG_INFINITY; TILE_CELLS];

/// Where a cell is: its world cell, its tile's world tile, the tile's slot
/// in the ring and the cell's index within the tile.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Spot {
    cell: [i32; 2],
    tile: [i32; 2],
    slot: usize,
    sub: usize,
}

/// A return of a column: horizontal distance from the sensor, level-frame
/// position and world z.
#[derive(Debug, Clone, Copy)]
struct Return {
    d: f32,
    x: f32,
    y: f32,
    z: f32,
}

/// What one image added to the evidence.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EvidenceStats {
    /// Near edges suspected (cells reported).
    pub suspected: u32,
    /// Gaps whose dip and rise made them candidates.
    pub candidates: u32,
    /// Stretches of columns left unverified (shadows reported).
    pub unverified: u32,
}

/// A stretch of a column no return has verified: from `near` to `far`
/// (horizontal distances from the sensor), in level-frame direction
/// (`dx`, `dy`).
#[derive(Debug, Clone, Copy)]
struct Stretch {
    col: u32,
    near: f32,
    far: f32,
    dx: f32,
    dy: f32,
}

/// The layer (see the module's documentation).
#[derive(Debug, Default)]
pub struct HoleEvidence {
    config: EvidenceConfig,
    /// Near edges are suspected (`[perception.drop_off] suspect_cost` > 0).
    suspect: bool,
    rule: Rule,
    /// `[perception.region]`, ahead, behind and to each side: near edges
    /// are judged only there (the local map keeps nothing beyond).
    region: [f32; 3],
    min_range: f32,
    max_range: f32,
    tiles: Vec<Tile>,
    /// Per tile, its cells' highest returns, world z (−∞: none).
    tops: Vec<[f32; TILE_CELLS]>,
    /// The ring's side, tiles.
    side: usize,
    /// Distance the vehicle has travelled, m, and where its origin was
    /// last.
    travelled: f64,
    last_origin: Option<[f64; 2]>,
    projector: Projector,
    points: RowPoints,
    /// Per column, the last two returns walking up from the lowest beam.
    near: Vec<Option<Return>>,
    far: Vec<Option<Return>>,
    /// This image's suspected near edges: world cell, world (x, y) and z
    /// (deduplicated by cell before reporting).
    found: Vec<([i32; 2], [f64; 2], f32)>,
    /// Cells along a gap, with their distance along it.
    keys: Vec<(Spot, f32)>,
    /// This image's returns kept (column, return), row after row.
    kept: Vec<(u32, Return)>,
    /// This image's unverified stretches, and per column the index of
    /// its last one (`u32::MAX`: none), to extend.
    stretches: Vec<Stretch>,
    open: Vec<u32>,
    /// The unverified stretches as shadows, world frame.
    shadows: Shadows,
    /// The image's columns looking ahead, in runs.
    columns: Vec<std::ops::Range<usize>>,
    order: Vec<usize>,
}

/// The drop-off rule's numbers the layer judges with.
#[derive(Debug, Default, Clone, Copy)]
struct Rule {
    max_gap: f32,
    min_depth: f32,
    noise: f32,
    depth_per_m: f32,
    cost: f32,
}

/// Where the image's level frame lies in the ring's world cells.
struct Placement {
    /// The sensor, in cells from the corner of world cell `base` (plus
    /// the ring's side in cells, so that every cell within reach has
    /// positive coordinates and truncating is flooring), and in the level
    /// frame; the level frame's heading.
    origin: [f32; 2],
    sensor: [f32; 2],
    base: [i64; 2],
    /// `base` modulo a tile's side, the world tile holding `base` modulo
    /// the ring's side (in tiles), and that side.
    base_in_tile: [usize; 2],
    base_tile: [i64; 2],
    base_slot: [usize; 2],
    side: usize,
    sin: f32,
    cos: f32,
    tz: f32,
    inverse: f32,
}

impl Placement {
    fn new(
        sensor_world: [f64; 2],
        sensor_level: [f32; 2],
        yaw: f64,
        tz: f64,
        cell: f64,
        side: usize,
    ) -> Self {
        let base = sensor_world.map(|v| (v / cell).floor() as i64);
        let cells = (side * TILE) as f64;
        let tile = TILE as i64;
        Self {
            origin: [
                ((sensor_world[0] - base[0] as f64 * cell) / cell + cells) as f32,
                ((sensor_world[1] - base[1] as f64 * cell) / cell + cells) as f32,
            ],
            sensor: sensor_level,
            base,
            base_in_tile: base.map(|b| b.rem_euclid(tile) as usize),
            base_tile: base.map(|b| b.div_euclid(tile)),
            base_slot: base.map(|b| b.div_euclid(tile).rem_euclid(side as i64) as usize),
            side,
            sin: yaw.sin() as f32,
            cos: yaw.cos() as f32,
            tz: tz as f32,
            inverse: (1.0 / cell) as f32,
        }
    }

    /// Level-frame (x, y) in cells from the corner of world cell `base`,
    /// plus the ring's side in cells.
    #[inline(always)]
    fn cells_from_base(&self, x: f32, y: f32) -> [f32; 2] {
        let (x, y) = (x - self.sensor[0], y - self.sensor[1]);
        [
            self.origin[0] + (self.cos * x - self.sin * y) * self.inverse,
            self.origin[1] + (self.sin * x + self.cos * y) * self.inverse,
        ]
    }

    /// Where level-frame (x, y), within reach of the sensor, is.
    #[inline(always)]
    fn locate(&self, x: f32, y: f32) -> Spot {
        // In [0, 2·side·TILE): the reach is less than half the side.
        let [gx, gy] = self.cells_from_base(x, y);
        // Through i32: one conversion instruction (to usize, several).
        let (lx, ly) = (gx as i32 as usize, gy as i32 as usize);
        let side = self.side;
        let cells = (side * TILE) as i64;
        // From the corner of `base`'s tile: whole tiles and the rest.
        let (fx, fy) = (self.base_in_tile[0] + lx, self.base_in_tile[1] + ly);
        let (tx, ty) = (fx / TILE, fy / TILE);
        let wrap = |v: usize| {
            let v = if v >= side { v - side } else { v };
            let v = if v >= side { v - side } else { v };
            if v >= side { v - side } else { v }
        };
        Spot {
            cell: [
                (self.base[0] + lx as i64 - cells) as i32,
                (self.base[1] + ly as i64 - cells) as i32,
            ],
            tile: [
                (self.base_tile[0] + tx as i64 - side as i64) as i32,
                (self.base_tile[1] + ty as i64 - side as i64) as i32,
            ],
            slot: wrap(self.base_slot[1] + ty) * side + wrap(self.base_slot[0] + tx),
            sub: (fy % TILE) * TILE + fx % TILE,
        }
    }

    /// World (x, y) of level-frame (x, y).
    fn world(&self, x: f32, y: f32) -> [f64; 2] {
        let cell = 1.0 / f64::from(self.inverse);
        let cells = (self.side * TILE) as f64;
        let [gx, gy] = self.cells_from_base(x, y);
        [
            (self.base[0] as f64 + f64::from(gx) - cells) * cell,
            (self.base[1] as f64 + f64::from(gy) - cells) * cell,
        ]
    }
}

impl HoleEvidence {
    /// From `[perception]`; keeps nothing when `[perception.evidence]` or
    /// `[perception.drop_off]` is off, and suspects no hole when suspected
    /// drop-offs are not reported (`suspect_cost = 0`).
    pub fn new(perception: &PerceptionConfig) -> Self {
        let d = &perception.drop_off;
        let on = perception.evidence.enabled && d.enabled;
        let mut config = perception.evidence.clone();
        config.enabled = on;
        let side = if on {
            ring_side(config.reach_m, config.cell_size_m)
        } else {
            0
        };
        Self {
            suspect: on && d.suspect_cost > 0.0,
            rule: Rule {
                max_gap: d.max_gap_m as f32,
                min_depth: d.min_depth_m as f32,
                noise: d.noise_m as f32,
                depth_per_m: d.depth_per_m as f32,
                cost: d.suspect_cost as f32,
            },
            region: [
                perception.region.ahead_m as f32,
                perception.region.behind_m as f32,
                perception.region.half_width_m as f32,
            ],
            min_range: perception.min_range_m as f32,
            max_range: perception.max_range_m as f32,
            tiles: vec![EMPTY; side * side],
            tops: vec![NO_TOPS; side * side],
            side,
            config,
            ..Self::default()
        }
    }

    /// The ring's memory, bytes.
    pub fn memory_bytes(&self) -> usize {
        self.tiles.len() * std::mem::size_of::<Tile>()
            + self.tops.len() * std::mem::size_of::<[f32; TILE_CELLS]>()
    }

    /// Forgets everything (the pose jumped: what was seen is elsewhere).
    pub fn reset(&mut self) {
        self.tiles.fill(EMPTY);
        self.last_origin = None;
    }

    /// Adds `image`, captured at `world_from_vehicle`, to the evidence and
    /// appends the near edges it now suspects to `report` (graded cells
    /// with the reason drop-off, in a region of their own).
    pub fn observe(
        &mut self,
        image: &RangeImage,
        world_from_vehicle: &Isometry,
        report: &mut ObstacleReport,
    ) -> EvidenceStats {
        let mut stats = EvidenceStats::default();
        if !self.config.enabled || image.cols() == 0 {
            return stats;
        }
        let (world_from_level, level_from_sensor) = level_frames(image, world_from_vehicle);
        let sensor = (world_from_level * level_from_sensor).translation.vector;
        // The vehicle's travel (not a sensor's: images of two sensors
        // mounted apart alternate).
        let origin = world_from_vehicle.translation.vector;
        if let Some([x, y]) = self.last_origin {
            let moved = (origin.x - x).hypot(origin.y - y);
            // A jump of the pose puts what was seen elsewhere.
            if !moved.is_finite() || moved > 0.5 * self.config.reach_m {
                self.reset();
            } else {
                self.travelled += moved;
            }
        }
        self.last_origin = Some([origin.x, origin.y]);
        let t = world_from_level.translation.vector;
        let s = level_from_sensor.translation.vector;
        let sensor_level = [s.x as f32, s.y as f32, s.z as f32];
        // The ring is placed by the sensor: every cell within its reach.
        let place = Placement::new(
            [sensor.x, sensor.y],
            [sensor_level[0], sensor_level[1]],
            arcnav_vehicle::frames::yaw_of(&world_from_level),
            t.z,
            self.config.cell_size_m,
            self.side,
        );
        // Rows from the lowest beam up: on open ground, near to far.
        self.order.clear();
        self.order.extend(0..image.rows());
        let elevation = &image.beams.elevation;
        self.order
            .sort_by(|&a, &b| elevation[a].total_cmp(&elevation[b]));
        let cols = image.cols();
        for walk in [&mut self.near, &mut self.far] {
            walk.clear();
            walk.resize(cols, None);
        }
        self.found.clear();
        self.stretches.clear();
        self.open.clear();
        self.open.resize(cols, u32::MAX);
        let start = self.projector.prepare(image, &level_from_sensor);
        let kept = (self.min_range, self.max_range);
        let mut skipped = ImageStats::default();
        // First every return's height (other columns' returns verify the
        // ground in a column's gap), keeping the returns; then the walk,
        // row by row again.
        self.kept.clear();
        // Only the columns looking ahead (or about: a column's returns
        // spread a little either side of its heading).
        self.columns.clear();
        let mut run: Option<usize> = None;
        for (c, &forward) in self.projector.forward().iter().enumerate() {
            match (forward > -0.05, run) {
                (true, None) => run = Some(c),
                (false, Some(first)) => {
                    self.columns.push(first..c);
                    run = None;
                }
                _ => {}
            }
        }
        if let Some(first) = run {
            self.columns.push(first..cols);
        }
        let columns = std::mem::take(&mut self.columns);
        for position in 0..self.order.len() {
            let row = self.order[position];
            let line = &image.range[row * cols..(row + 1) * cols];
            for span in &columns {
                let mut points = std::mem::take(&mut self.points);
                self.projector.project_columns(
                    &start,
                    row,
                    (&line[span.clone()], span.start),
                    kept,
                    &mut points,
                    &mut skipped,
                );
                self.raise(&points, span.start, &place, sensor_level);
                self.points = points;
            }
        }
        self.columns = columns;
        // Row after row, as kept: each column's returns near to far.
        for i in 0..self.kept.len() {
            let (k, here) = self.kept[i];
            self.walk(k as usize, here, &place, sensor_level, &mut stats);
        }
        self.report(report, &mut stats);
        if self.config.verify {
            self.beyond_reach(sensor_level);
        }
        let ground = world_from_level * nalgebra::Point3::new(s.x, s.y, 0.0);
        self.emit_shadows(
            image,
            nalgebra::Point2::new(ground.x, ground.y),
            arcnav_vehicle::frames::yaw_of(&world_from_level),
        );
        stats.unverified = self.shadows.sectors.len() as u32;
        stats
    }

    /// The stretches of this image's columns that no return has verified
    /// (see [`HoleEvidence::verify`]), as shadows.
    pub fn unverified(&self) -> &Shadows {
        &self.shadows
    }

    /// Whether level-frame (x, y) is kept: ahead of the sensor at
    /// level-frame `sensor` (what the vehicle drives into), within reach
    /// of it and no wider than the region.
    #[inline(always)]
    fn inside(&self, x: f32, y: f32, sensor: [f32; 3]) -> bool {
        let reach = self.config.reach_m as f32;
        let (dx, dy) = (x - sensor[0], y - sensor[1]);
        dx >= 0.0 && dx * dx + dy * dy <= reach * reach && y.abs() <= self.region[2]
    }

    /// Nothing beyond reach is verified: each column's stretch from its
    /// last return in the region on to the farthest range is unverified
    /// (its gaps there are longer than the wheels bridge anyway).
    fn beyond_reach(&mut self, sensor: [f32; 3]) {
        for k in 0..self.far.len() {
            let Some(last) = self.far[k].filter(|&r| self.in_region(r)) else {
                continue;
            };
            let (dx, dy) = (last.x - sensor[0], last.y - sensor[1]);
            self.stretch(k, last.d, self.max_range.max(last.d), (dx, dy));
        }
    }

    /// Whether `r` lies in `[perception.region]`.
    fn in_region(&self, r: Return) -> bool {
        let [ahead, behind, half] = self.region;
        r.x <= ahead && r.x >= -behind && r.y.abs() <= half
    }

    /// The tile of `spot`, emptied first if it held other ground.
    #[inline(always)]
    fn hold(&mut self, spot: Spot) -> &mut Tile {
        let tile = &mut self.tiles[spot.slot];
        if tile.key != spot.tile {
            *tile = Tile {
                key: spot.tile,
                ..EMPTY
            };
            self.tops[spot.slot] = NO_TOPS;
        }
        tile
    }

    /// Raises each cell to the highest return of the row in it (`points`,
    /// its column 0 the image's `first`), keeping the returns for the
    /// walk.
    fn raise(&mut self, points: &RowPoints, first: usize, place: &Placement, sensor: [f32; 3]) {
        for k in 0..points.x.len() {
            let (x, y) = (points.x[k], points.y[k]);
            if !points.used[k] || !self.inside(x, y, sensor) {
                continue;
            }
            let spot = place.locate(x, y);
            let z = points.z[k] + place.tz;
            self.hold(spot);
            let top = &mut self.tops[spot.slot][spot.sub];
            *top = top.max(z);
            let d = ((x - sensor[0]).powi(2) + (y - sensor[1]).powi(2)).sqrt();
            self.kept.push(((first + k) as u32, Return { d, x, y, z }));
        }
    }

    /// One return's step of its column's walk (`here`, column `k`): marks
    /// the tiles its gap to the column's previous return passes over, and
    /// judges the gap before that one now that the ground beyond it is
    /// known.
    fn walk(
        &mut self,
        k: usize,
        here: Return,
        place: &Placement,
        sensor: [f32; 3],
        stats: &mut EvidenceStats,
    ) {
        let Some(far) = self.far[k] else {
            self.far[k] = Some(here);
            return;
        };
        if here.d <= far.d {
            // Nearer than the last return (a wall's face): not a gap.
            return;
        }
        self.pass_over(far, here, place);
        if self.config.verify && self.in_region(far) {
            self.verify(k, far, here, place);
        }
        if let Some(near) = self.near[k]
            && self.suspect
            && self.in_region(near)
        {
            stats.candidates += u32::from(self.judge(near, far, here, place, sensor));
        }
        self.near[k] = Some(far);
        self.far[k] = Some(here);
    }

    /// Marks the tiles between `a` and `b` passed over (when no ray had),
    /// a point every half tile.
    fn pass_over(&mut self, a: Return, b: Return, place: &Placement) {
        // Only a gap longer than the wheels bridge can hold a hole's run.
        if b.d - a.d <= self.rule.max_gap {
            return;
        }
        let travelled = self.travelled as f32;
        let step = 0.5 * TILE as f32 * self.config.cell_size_m as f32;
        let (steps, points) = along(a, b, step);
        for (_, x, y) in points.take(steps) {
            let tile = self.hold(place.locate(x, y));
            if tile.passed.is_nan() {
                tile.passed = travelled;
            }
        }
    }

    /// Whether the gap from `a` to `b`, returns of column `k` one after the
    /// other, is verified ground: within `verified_within_m` of the sensor
    /// (where one image is certain to suspect a hole), no longer than the
    /// wheels bridge, or
    /// within reach with no run of cells along it, `max_gap_m − cell` or
    /// longer, that no return (of any image) reached at ground height (no
    /// deeper than `δ = min_depth_m + Δ·g` below the lower end, for a gap
    /// `g`: a smaller step down is driven). A stretch that is not is kept
    /// as unverified, joined to the column's last one when they meet.
    fn verify(&mut self, k: usize, a: Return, b: Return, place: &Placement) {
        let rule = self.rule;
        let gap = b.d - a.d;
        // One image shows a hole there (`verified_within_m`).
        if gap <= rule.max_gap || b.d <= self.config.verified_within_m as f32 {
            return;
        }
        let cell = self.config.cell_size_m as f32;
        let verified = {
            let ground = a.z.min(b.z) - (rule.min_depth + rule.depth_per_m * gap);
            let mut keys = std::mem::take(&mut self.keys);
            cells_between(a, b, place, 0.5 * cell, &mut keys);
            let (mut start, mut longest) = (None, 0.0f32);
            for &(spot, at) in &keys {
                let tile = &self.tiles[spot.slot];
                if tile.key != spot.tile || self.tops[spot.slot][spot.sub] < ground {
                    let first = *start.get_or_insert(at);
                    longest = longest.max(at - first + cell);
                } else {
                    start = None;
                }
            }
            self.keys = keys;
            longest < rule.max_gap - cell
        };
        if !verified {
            self.stretch(k, a.d, b.d, (b.x - a.x, b.y - a.y));
        }
    }

    /// Keeps column `k`'s stretch from `near` to `far` (m from the sensor,
    /// in level-frame direction `(dx, dy)`) as unverified, joined to the
    /// column's last one when they meet.
    fn stretch(&mut self, k: usize, near: f32, far: f32, (dx, dy): (f32, f32)) {
        let open = self.open[k];
        if let Some(last) = self.stretches.get_mut(open as usize)
            && last.far == near
        {
            last.far = far;
            return;
        }
        self.open[k] = self.stretches.len() as u32;
        self.stretches.push(Stretch {
            col: k as u32,
            near,
            far,
            dx,
            dy,
        });
    }

    /// This image's unverified stretches as shadows seen from `origin`
    /// (the sensor's ground position, world frame), the level frame
    /// turned `yaw` from the world's: each as wide as its column (half
    /// way to the farther neighbour, a hair more, as the evaluators'
    /// shadows).
    fn emit_shadows(&mut self, image: &RangeImage, origin: nalgebra::Point2<f64>, yaw: f64) {
        self.shadows.clear();
        self.shadows.origin = origin;
        let azimuth = &image.beams.azimuth;
        let spacing = |c: usize| {
            [c.checked_sub(1), (c + 1 < azimuth.len()).then_some(c + 1)]
                .into_iter()
                .flatten()
                .map(|n| {
                    arcnav_vehicle::frames::wrap_angle(f64::from(azimuth[n] - azimuth[c])).abs()
                })
                .fold(0.0f64, f64::max)
        };
        for s in &self.stretches {
            let direction = f64::from(s.dy).atan2(f64::from(s.dx)) + yaw;
            self.shadows.sectors.push(Shadow {
                azimuth: arcnav_vehicle::frames::wrap_angle(direction) as f32,
                half_width: ((0.51 * spacing(s.col as usize)) as f32).min(Shadow::MAX_HALF_WIDTH),
                near: s.near,
                far: s.far,
            });
        }
    }

    /// Whether the gap from `near` to `far` (returns of one column, `beyond`
    /// the next beyond `far`) dips and rises back as a hole's would; if so,
    /// and the evidence holds no return at ground height along a run of
    /// it the wheels may not bridge, `near` is suspected.
    fn judge(
        &mut self,
        near: Return,
        far: Return,
        beyond: Return,
        place: &Placement,
        sensor: [f32; 3],
    ) -> bool {
        let rule = self.rule;
        let gap = far.d - near.d;
        // The notch: how far `far` lies below the ground through `near`
        // and `beyond` (a hole's far wall under ground that goes on; the
        // ground's own slope, rolling or not, is no notch).
        let span = (beyond.d - near.d).max(gap);
        let surface = near.z + (beyond.z - near.z) * gap / span;
        let dip = surface - far.z;
        let tolerance = rule.noise + rule.depth_per_m * gap;
        if !(gap > rule.max_gap
            && dip > tolerance
            && beyond.z - far.z > 0.5 * dip
            && sensor[2] + place.tz > near.z)
        {
            return false;
        }
        let (dx, dy) = (far.x - sensor[0], far.y - sensor[1]);
        let along = dx.abs() / dx.hypot(dy).max(f32::MIN_POSITIVE);
        if gap * along <= rule.max_gap {
            return false;
        }
        let cell = self.config.cell_size_m as f32;
        let (travelled, settle) = (self.travelled as f32, self.config.settle_m as f32);
        let ground = near.z - tolerance;
        let mut keys = std::mem::take(&mut self.keys);
        cells_between(near, far, place, 0.5 * cell, &mut keys);
        // The longest run of settled cells with no return at ground height:
        // (its start, metres from `near`, and length).
        let (mut start, mut longest) = (None, (0.0f32, 0.0f32));
        for &(spot, at) in &keys {
            let tile = &self.tiles[spot.slot];
            let unseen = tile.key == spot.tile
                && self.tops[spot.slot][spot.sub] < ground
                && travelled - tile.passed >= settle;
            if unseen {
                let first = *start.get_or_insert(at);
                if at - first + cell > longest.1 {
                    longest = (first, at - first + cell);
                }
            } else {
                start = None;
            }
        }
        self.keys = keys;
        // A hole of `w` holds at least ⌊w/cell⌋ − 1 whole cells: one at
        // least max_gap_m + cell/3 wide (0.8 m) is certain to leave this
        // run; one the wheels bridge leaves it only with a cell or more of
        // ground unseen beside it.
        if longest.1 * along >= rule.max_gap - cell {
            // Reported where the unseen run begins: the ground before it
            // was seen, whatever row last landed on it.
            let t = longest.0
                / (far.x - near.x)
                    .hypot(far.y - near.y)
                    .max(f32::MIN_POSITIVE);
            let (x, y) = (near.x + (far.x - near.x) * t, near.y + (far.y - near.y) * t);
            self.found
                .push((place.locate(x, y).cell, place.world(x, y), near.z));
        }
        true
    }

    /// Appends this image's suspected near edges to `report`, one cell each.
    fn report(&mut self, report: &mut ObstacleReport, stats: &mut EvidenceStats) {
        if self.found.is_empty() {
            return;
        }
        self.found.sort_unstable_by_key(|f| f.0);
        self.found.dedup_by_key(|f| f.0);
        let region = report.regions.len() as u32;
        for &(_, [x, y], z) in &self.found {
            report.cells.push(ObstacleCell {
                x,
                y,
                z_min: z,
                z_max: z,
                reasons: Reasons::DROP_OFF,
                region,
                cost: self.rule.cost,
            });
        }
        stats.suspected = self.found.len() as u32;
        report.regions.push(Region {
            cells: stats.suspected,
            reasons: Reasons::NONE,
        });
    }
}

/// The world cells strictly between returns `a` and `b` (level frame),
/// sampled every `step` metres, each with its slot and its distance from
/// `a`, into `out`; the cells of `a` and `b` themselves are left out.
fn cells_between(a: Return, b: Return, place: &Placement, step: f32, out: &mut Vec<(Spot, f32)>) {
    out.clear();
    let (ka, kb) = (place.locate(a.x, a.y).cell, place.locate(b.x, b.y).cell);
    let mut previous = ka;
    let (steps, points) = along(a, b, step);
    for (s, x, y) in points.take(steps.saturating_sub(1)) {
        let spot = place.locate(x, y);
        if spot.cell == previous || spot.cell == ka || spot.cell == kb {
            continue;
        }
        previous = spot.cell;
        out.push((spot, s as f32 * step));
    }
}

/// The segment from `a` to `b` (level frame) in `step`s: how many whole
/// steps it holds, and the points one step, two steps, … from `a`, each
/// with its count of steps. Both ends lie within reach: the count is
/// bounded by its diameter.
fn along(a: Return, b: Return, step: f32) -> (usize, impl Iterator<Item = (usize, f32, f32)>) {
    let length = ((b.x - a.x).powi(2) + (b.y - a.y).powi(2)).sqrt();
    let (dx, dy) = ((b.x - a.x) / length * step, (b.y - a.y) / length * step);
    let points = (1..).map(move |s| (s, a.x + dx * s as f32, a.y + dy * s as f32));
    ((length / step) as usize, points)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::HeightFunction;
    use crate::sensor::SensorModel;
    use arcnav_vehicle::frames::isometry_from_xyz_rpy;

    /// The 64-beam lidar's rows (2° to −24.9°, 2.4 m up) and column
    /// spacing, over the 22.5° ahead only and out to 32 m: what a ditch
    /// ahead is seen with, for a fraction of the rendering.
    fn lidar_ahead() -> SensorModel {
        let mut c = SensorModel::lidar64().to_custom();
        c.cols = 128;
        c.azimuth_left_deg = 11.25;
        c.azimuth_right_deg = -11.25;
        c.max_range_m = 32.0;
        SensorModel::from_custom(&c)
    }

    /// Gently rolling ground (heights to ±12 cm, 2 cm ripples), with a
    /// ditch `width` m wide and 1 m deep across the way from x = `at`.
    fn ground(at: f64, width: f64) -> impl Fn(f64, f64) -> f64 + Sync {
        move |x: f64, y: f64| {
            if (at..at + width).contains(&x) {
                -1.0
            } else {
                0.12 * (0.09 * x).sin() * (0.13 * y).cos() + 0.02 * (2.1 * x + 1.3 * y).sin()
            }
        }
    }

    /// Drives `sensor` along the x axis, a frame every `step` m from
    /// `from` to `to` (vehicle origin), over `scene`, into `evidence`:
    /// for each frame, the sensor's x and the cells reported.
    fn drive(
        evidence: &mut HoleEvidence,
        sensor: &SensorModel,
        scene: &(impl Fn(f64, f64) -> f64 + Sync),
        span: (f64, f64, f64),
    ) -> Vec<(f64, Vec<ObstacleCell>)> {
        drive_seeing(evidence, sensor, scene, span)
            .into_iter()
            .map(|(x, cells, _)| (x, cells))
            .collect()
    }

    /// [`drive`], with each frame's unverified stretches as well.
    fn drive_seeing(
        evidence: &mut HoleEvidence,
        sensor: &SensorModel,
        scene: &(impl Fn(f64, f64) -> f64 + Sync),
        (from, to, step): (f64, f64, f64),
    ) -> Vec<(f64, Vec<ObstacleCell>, Shadows)> {
        // Marched in 20 cm steps, each crossing refined by bisection: the
        // narrowest feature here is 30 cm.
        let rays = HeightFunction::with_step(scene, 0.2);
        let mount = sensor.vehicle_from_sensor.translation.vector.x;
        let frames = ((to - from) / step).round() as usize + 1;
        (0..frames)
            .map(|k| {
                let x = from + step * k as f64;
                let pose = isometry_from_xyz_rpy([x, 0.0, scene(x, 0.0)], 0.0, 0.0, 0.0);
                let image = sensor.render(k as i64 * 100_000, &pose, &rays);
                let mut report = ObstacleReport::default();
                evidence.observe(&image, &pose, &mut report);
                (x + mount, report.cells, evidence.unverified().clone())
            })
            .collect()
    }

    /// The range from the sensor at which a cell near the ditch's near
    /// edge (`at`) was first reported, and every cell reported elsewhere.
    fn first_and_elsewhere(
        frames: &[(f64, Vec<ObstacleCell>)],
        at: f64,
    ) -> (Option<f64>, Vec<(f64, f64)>) {
        let mut first = None;
        let mut elsewhere = Vec::new();
        for (sensor, cells) in frames {
            for c in cells {
                // The unseen run begins at the last ground seen before the
                // edge: from afar, and to the side, up to half a metre in.
                if c.x >= at - 0.6 && c.x <= at + 0.4 {
                    first = first.or(Some(at - sensor));
                } else {
                    elsewhere.push((c.x, c.y));
                }
            }
        }
        (first, elsewhere)
    }

    #[test]
    fn a_ditch_one_image_cannot_show_is_suspected_from_16_m_at_8_m_per_s() {
        // One image is certain to suspect a 0.8 m ditch only within 11.4 m
        // (`speed_bound`'s suspect_range_m for this lidar); issue 63 asks
        // for 16 m at 8 m/s. Frames every 0.8 m (8 m/s at 10 Hz), from
        // 45 m short of the ditch.
        let at = 60.0;
        let scene = ground(at, 0.8);
        let sensor = lidar_ahead();
        let mut evidence = HoleEvidence::new(&PerceptionConfig::default());
        let frames = drive(&mut evidence, &sensor, &scene, (15.0, at - 12.0, 0.8));
        let (first, elsewhere) = first_and_elsewhere(&frames, at);
        let first = first.expect("the ditch was never suspected");
        assert!(first >= 16.0, "first suspected {first:.1} m away");
        assert!(elsewhere.is_empty(), "suspected elsewhere: {elsewhere:?}");
        // And every frame from there on keeps it suspected until close.
        let after: Vec<_> = frames
            .iter()
            .filter(|(s, _)| at - s < first && at - s > 12.0)
            .map(|(_, cells)| cells.iter().any(|c| (c.x - at).abs() <= 0.4))
            .collect();
        assert!(after.iter().all(|&a| a), "{after:?}");
    }

    #[test]
    fn level_ground_is_never_suspected_nor_a_rut_the_wheels_roll_over_from_near() {
        // A rut 0.3 m wide and 1 m deep (the wheels bridge 0.77 m), at 8
        // and at 5.5 m/s (the rows land in other places): its far wall is a
        // notch each image. From 20 m, where a 10 cm cell of level ground
        // has even odds of no return yet, the ground before it may join it
        // in a run of unseen ground as long as a hole the wheels do not
        // bridge leaves (0.67 m); from nearer the ground around it has
        // been seen.
        for step in [0.8, 0.5] {
            let at = 50.0;
            let scene = ground(at, 0.3);
            let mut evidence = HoleEvidence::new(&PerceptionConfig::default());
            let frames = drive(
                &mut evidence,
                &lidar_ahead(),
                &scene,
                (10.0, at - 4.0, step),
            );
            let reported: Vec<_> = frames
                .iter()
                .flat_map(|(sensor, cells)| cells.iter().map(move |c| (at - sensor, c.x, c.y)))
                .collect();
            let elsewhere: Vec<_> = reported.iter().filter(|r| r.1 < at - 1.5).collect();
            assert!(elsewhere.is_empty(), "{step} m a frame: {elsewhere:?}");
            let near: Vec<_> = reported.iter().filter(|r| r.0 < 16.0).collect();
            assert!(near.is_empty(), "{step} m a frame: {near:?}");
        }
    }

    /// Issue 63 item 2: ground is verified where returns at ground height
    /// have covered it so densely that no gap the wheels do not bridge
    /// can hide in it; the rest of each image's columns is reported as
    /// shadow (not seen).
    #[test]
    fn ground_swept_by_returns_is_verified_and_a_ditch_never_is() {
        let at = 60.0;
        let scene = ground(at, 0.8);
        // Judged out to 40 m ahead, as the region reaches at speed.
        let mut config = PerceptionConfig::default();
        config.region.ahead_m = 40.0;
        config.max_range_m = 40.0;
        let mut evidence = HoleEvidence::new(&config);
        // 8 m/s at 10 Hz, from 45 m short of the ditch to 8 m short.
        let frames = drive_seeing(&mut evidence, &lidar_ahead(), &scene, (15.0, at - 8.0, 0.8));
        let mut index = crate::ShadowIndex::default();
        // How far straight ahead the ground is verified, frame by frame:
        // to the nearest unverified point along the line (10 cm steps).
        let verified: Vec<(f64, f64)> = frames
            .iter()
            .map(|(sensor, _, shadows)| {
                index.build(shadows);
                let first = (1..400)
                    .map(|k| sensor + 0.1 * f64::from(k))
                    .find(|&x| index.contains(x, 0.0))
                    .map_or(f64::INFINITY, |x| x - sensor);
                (*sensor, first)
            })
            .collect();
        // One image alone: its rows lie farther apart than 0.77 m on the
        // ground beyond about 15.7 m (R²·δθ/H), and no history fills them.
        let (_, alone) = verified[0];
        assert!((12.0..17.0).contains(&alone), "first image: {alone:.1} m");
        // Swept by the rows of the frames before (8 of them, 5.6 m of
        // travel), level ground is verified farther: to at least 18 m (to
        // the last return, 32 m, on much of the way) short of the ditch.
        for &(sensor, ahead) in &verified[8..] {
            let to_ditch = at - sensor;
            // (Short of the ditch: from its edge's last return, a row's
            // spacing before it, under a metre within 18 m.)
            assert!(
                ahead >= 18.0_f64.min(to_ditch - 1.5),
                "{ahead:.1} m verified from {sensor:.1} m ({to_ditch:.1} m to the ditch)"
            );
            // ... and never across the ditch, once returns reach well past
            // it (beyond the last return, 32 m, the ground is no image's).
            assert!(
                to_ditch > 26.0 || ahead <= to_ditch + 0.5,
                "verified past the ditch from {sensor:.1} m"
            );
        }
        // Without the history, the same frames verify no farther than one
        // image does.
        let mut forgetful = HoleEvidence::new(&config);
        let mut nearest = f64::INFINITY;
        for k in 0..5 {
            forgetful.reset();
            let x = 10.0 + 0.8 * f64::from(k);
            let (sensor, _, shadows) =
                drive_seeing(&mut forgetful, &lidar_ahead(), &scene, (x, x, 0.0)).remove(0);
            index.build(&shadows);
            let first = (1..400)
                .map(|k| sensor + 0.1 * f64::from(k))
                .find(|&x| index.contains(x, 0.0))
                .map_or(f64::INFINITY, |x| x - sensor);
            nearest = nearest.min(first);
        }
        assert!(nearest < 17.0, "one image verified to {nearest:.1} m");
    }

    #[test]
    fn a_standing_sensor_suspects_nothing_the_single_image_would_not() {
        // From a standstill the rows land where they landed: the gaps
        // between them never fill, and never settle either.
        let at = 40.0;
        let scene = ground(at, 0.8);
        let mut evidence = HoleEvidence::new(&PerceptionConfig::default());
        let x = at - 19.0;
        let frames = drive(&mut evidence, &lidar_ahead(), &scene, (x, x, 0.0));
        assert_eq!(frames.len(), 1);
        let again = drive(
            &mut evidence,
            &lidar_ahead(),
            &scene,
            (x, x + 0.0001, 0.0001),
        );
        // A second lidar mounted 3 m further back, its images between the
        // first's: the vehicle stands, whichever sensor sees.
        let mut behind = lidar_ahead().to_custom();
        behind.mount_position_m[0] -= 3.0;
        let behind = SensorModel::from_custom(&behind);
        let mut others = Vec::new();
        for _ in 0..4 {
            others.extend(drive(&mut evidence, &behind, &scene, (x, x, 0.0)));
            others.extend(drive(&mut evidence, &lidar_ahead(), &scene, (x, x, 0.0)));
        }
        let reported: Vec<_> = frames
            .iter()
            .chain(&again)
            .chain(&others)
            .flat_map(|(_, c)| c)
            .collect();
        assert!(reported.is_empty(), "{reported:?}");
    }

    #[test]
    fn a_pose_jump_forgets_and_the_ring_holds_only_what_is_in_reach() {
        let at = 60.0;
        let scene = ground(at, 0.8);
        let sensor = lidar_ahead();
        let mut evidence = HoleEvidence::new(&PerceptionConfig::default());
        let bytes = evidence.memory_bytes();
        drive(&mut evidence, &sensor, &scene, (8.0, 20.0, 0.8));
        // Jumped 22 m on: nothing seen before counts (the ditch, now 17 m
        // ahead, has not settled).
        let jumped = drive(&mut evidence, &sensor, &scene, (at - 18.2, at - 18.2, 0.0));
        assert!(jumped[0].1.is_empty(), "{:?}", jumped[0].1);
        assert_eq!(evidence.memory_bytes(), bytes, "the ring does not grow");
        // 0.1 m cells out to 30 m: 152 tiles a side, 76 bytes each.
        assert_eq!(bytes, 152 * 152 * 76);
    }

    #[test]
    fn cells_too_coarse_for_the_gap_or_a_ring_too_large_are_refused() {
        let drop_off = DropOffConfig::default();
        let coarse = EvidenceConfig {
            cell_size_m: 0.3,
            ..EvidenceConfig::default()
        };
        let e = coarse.validate(&drop_off).unwrap_err();
        assert_eq!(e.key, "cell_size_m");
        assert!(e.reason.contains("three cells"), "{e}");
        let far = EvidenceConfig {
            cell_size_m: 0.05,
            reach_m: 400.0,
            ..EvidenceConfig::default()
        };
        let e = far.validate(&drop_off).unwrap_err();
        assert!(e.reason.contains("ring"), "{e}");
        assert!(EvidenceConfig::default().validate(&drop_off).is_ok());
        // Off, any cell size is accepted (nothing is built).
        let off = EvidenceConfig {
            enabled: false,
            ..coarse
        };
        assert!(off.validate(&drop_off).is_ok());
    }
}
