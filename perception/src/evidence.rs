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
//! the highest return that landed in it (any image) and how far the
//! sensor had travelled when a ray first passed over it. A near edge of a
//! column, its next return a gap `g` beyond (`g·|cos φ| > max_gap_m` along
//! the heading) and lower by `v`, the ground rising back beyond, is a
//! suspected hole when
//!
//! ```text
//! v > noise_m + Δ·g        and        a run of settled cells along the gap,
//!                                      at least max_gap_m − 2·cell long,
//!                                      holds no return at ground height
//! ```
//!
//! The dip is judged between two returns of one column a gap apart, so an
//! error of the pose's attitude (what `Δ` allows for, by range) moves them
//! alike but for `Δ·g`; what the single image could not tell (a row
//! landing far past the edge shows almost no dip) the history tells: no
//! return has ever been seen in the gap. A cell is *settled* once the
//! sensor has travelled `settle_m` since a ray first passed over it, so
//! ground newly in view, or watched from a standstill (the rows land
//! where they landed), is not taken for a hole because no row has yet
//! landed in it.
//!
//! The window is robot-centric and scrolls: a ring of cells indexed by
//! world cell modulo its side, each cell knowing which world cell it
//! holds, so a cell of ground left behind is forgotten when ground ahead
//! takes its place. Memory is fixed by `reach_m` and the cell size.

use arcnav_vehicle::Isometry;
use arcnav_vehicle::config::{self, ConfigError};
use serde::{Deserialize, Serialize};

use crate::config::{DropOffConfig, PerceptionConfig};
use crate::evaluator::{ImageStats, ObstacleCell, ObstacleReport, Reasons, Region};
use crate::grid::{Projector, RowPoints, level_frames};
use crate::image::RangeImage;

/// Lives in `[perception.evidence]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EvidenceConfig {
    /// Accumulate returns over images and suspect the holes they show
    /// (reported as `[perception.drop_off]` suspected drop-offs, at
    /// `suspect_cost`).
    pub enabled: bool,
    /// World-aligned cell of the layer, m: a gap the wheels do not
    /// bridge must span several.
    pub cell_size_m: f64,
    /// How far the sensor travels, after a ray first passed over a cell,
    /// before the absence of a return there counts, m.
    pub settle_m: f64,
    /// Returns within this horizontal distance of the sensor are kept,
    /// m: beyond the region ahead, so that the ground there has settled
    /// by the time the vehicle nears it.
    pub reach_m: f64,
}

impl Default for EvidenceConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            cell_size_m: 0.1,
            settle_m: 3.0,
            reach_m: 30.0,
        }
    }
}

/// The most cells on a side of the layer's ring.
const MAX_SIDE: usize = 4096;

impl EvidenceConfig {
    /// Checks the keys (relative to `[perception.evidence]`), with the
    /// drop-off rule's gap it must resolve.
    pub(crate) fn validate(&self, drop_off: &DropOffConfig) -> Result<(), ConfigError> {
        config::in_range("cell_size_m", self.cell_size_m, 0.02, 1.0)?;
        config::in_range("settle_m", self.settle_m, 0.0, 100.0)?;
        config::in_range("reach_m", self.reach_m, 1.0, 500.0)?;
        if self.enabled && 3.0 * self.cell_size_m > drop_off.max_gap_m {
            return Err(ConfigError::new(
                "cell_size_m",
                format!(
                    "is {} m; a gap of drop_off.max_gap_m ({} m) must span at least three \
                     cells: use cells of at most {:.3} m",
                    self.cell_size_m,
                    drop_off.max_gap_m,
                    drop_off.max_gap_m / 3.0
                ),
            ));
        }
        if self.enabled && ring_side(self.reach_m, self.cell_size_m) > MAX_SIDE {
            return Err(ConfigError::new(
                "cell_size_m",
                format!(
                    "{} m cells out to reach_m ({} m) need a ring of more than {MAX_SIDE} \
                     cells a side: use larger cells or a shorter reach",
                    self.cell_size_m, self.reach_m
                ),
            ));
        }
        Ok(())
    }
}

/// The side of the ring holding every cell within `reach` of the sensor,
/// cells.
fn ring_side(reach: f64, cell: f64) -> usize {
    let cells = (2.0 * reach / cell).ceil() + 4.0;
    if cells > MAX_SIDE as f64 {
        return usize::MAX;
    }
    cells as usize
}

/// One cell of the ring.
#[derive(Debug, Clone, Copy)]
struct Cell {
    /// The world cell held.
    key: [i32; 2],
    /// Highest return that landed in it, world z (−∞: none).
    top: f32,
    /// The sensor's travel when a ray first passed over it (NaN: none did).
    passed: f32,
}

const EMPTY: Cell = Cell {
    key: [i32::MIN; 2],
    top: f32::NEG_INFINITY,
    passed: f32::NAN,
};

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
}

/// The layer (see the module's documentation).
#[derive(Debug, Default)]
pub struct HoleEvidence {
    config: EvidenceConfig,
    rule: Rule,
    /// `[perception.region]`, ahead, behind and to each side: near edges
    /// are judged only there (the local map keeps nothing beyond).
    region: [f32; 3],
    min_range: f32,
    max_range: f32,
    cells: Vec<Cell>,
    side: usize,
    /// Distance the sensor has travelled, m, and where it was last.
    travelled: f64,
    last_sensor: Option<[f64; 2]>,
    projector: Projector,
    points: RowPoints,
    /// Per column, the last two returns walking up from the lowest beam.
    near: Vec<Option<Return>>,
    far: Vec<Option<Return>>,
    /// This image's suspected near edges: world cell, world (x, y) and z
    /// (deduplicated by cell before reporting).
    found: Vec<([i32; 2], [f64; 2], f32)>,
    /// Cells along a gap, with their distance along it.
    keys: Vec<([i32; 2], usize, f32)>,
    order: Vec<usize>,
}

/// The drop-off rule's numbers the layer judges with.
#[derive(Debug, Default, Clone, Copy)]
struct Rule {
    max_gap: f32,
    noise: f32,
    depth_per_m: f32,
    cost: f32,
}

/// Where the image's level frame lies in the ring's world cells.
struct Placement {
    /// The sensor, in cells from the corner of world cell `base` (plus the
    /// ring's side, so that every cell within reach has positive
    /// coordinates and truncating is flooring), and in the level frame;
    /// the level frame's heading.
    origin: [f32; 2],
    sensor: [f32; 2],
    base: [i64; 2],
    /// `base` modulo the ring's side.
    base_slot: [usize; 2],
    side: usize,
    sin: f32,
    cos: f32,
    tz: f32,
    inverse: f32,
}

impl Placement {
    /// The world cell holding level-frame (x, y), within reach of the
    /// sensor, and its slot in the ring.
    #[inline(always)]
    fn locate(&self, x: f32, y: f32) -> ([i32; 2], usize) {
        // In [0, 2·side): the reach is less than half the side.
        let (x, y) = (x - self.sensor[0], y - self.sensor[1]);
        let lx = (self.origin[0] + (self.cos * x - self.sin * y) * self.inverse) as usize;
        let ly = (self.origin[1] + (self.sin * x + self.cos * y) * self.inverse) as usize;
        let side = self.side;
        let key = [
            (self.base[0] + lx as i64 - side as i64) as i32,
            (self.base[1] + ly as i64 - side as i64) as i32,
        ];
        let wrap = |v: usize| {
            let v = if v >= side { v - side } else { v };
            if v >= side { v - side } else { v }
        };
        let slot = wrap(self.base_slot[1] + ly) * side + wrap(self.base_slot[0] + lx);
        (key, slot)
    }

    /// World (x, y) of level-frame (x, y).
    fn world(&self, x: f32, y: f32) -> [f64; 2] {
        let cell = 1.0 / f64::from(self.inverse);
        let side = self.side as f64;
        let (x, y) = (x - self.sensor[0], y - self.sensor[1]);
        let gx = f64::from(self.origin[0] + (self.cos * x - self.sin * y) * self.inverse);
        let gy = f64::from(self.origin[1] + (self.sin * x + self.cos * y) * self.inverse);
        [
            (self.base[0] as f64 + gx - side) * cell,
            (self.base[1] as f64 + gy - side) * cell,
        ]
    }
}

impl HoleEvidence {
    /// From `[perception]`; judges nothing when `[perception.evidence]` or
    /// `[perception.drop_off]` is off, or suspected drop-offs are not
    /// reported (`suspect_cost = 0`).
    pub fn new(perception: &PerceptionConfig) -> Self {
        let d = &perception.drop_off;
        let on = perception.evidence.enabled && d.enabled && d.suspect_cost > 0.0;
        let mut config = perception.evidence.clone();
        config.enabled = on;
        let side = if on {
            ring_side(config.reach_m, config.cell_size_m)
        } else {
            0
        };
        Self {
            rule: Rule {
                max_gap: d.max_gap_m as f32,
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
            cells: vec![EMPTY; side * side],
            side,
            config,
            ..Self::default()
        }
    }

    /// The ring's memory, bytes.
    pub fn memory_bytes(&self) -> usize {
        self.cells.len() * std::mem::size_of::<Cell>()
    }

    /// Whether the layer judges anything.
    pub fn enabled(&self) -> bool {
        self.config.enabled
    }

    /// Forgets everything (the pose jumped: what was seen is elsewhere).
    pub fn reset(&mut self) {
        self.cells.fill(EMPTY);
        self.last_sensor = None;
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
        if let Some([x, y]) = self.last_sensor {
            let moved = (sensor.x - x).hypot(sensor.y - y);
            // A jump of the pose puts what was seen elsewhere.
            if !moved.is_finite() || moved > 0.5 * self.config.reach_m {
                self.reset();
            } else {
                self.travelled += moved;
            }
        }
        self.last_sensor = Some([sensor.x, sensor.y]);
        let t = world_from_level.translation.vector;
        let cell = self.config.cell_size_m;
        // The ring is placed by the sensor: every cell within its reach.
        let base = [
            (sensor.x / cell).floor() as i64,
            (sensor.y / cell).floor() as i64,
        ];
        let yaw = arcnav_vehicle::frames::yaw_of(&world_from_level);
        let side = self.side;
        let s = level_from_sensor.translation.vector;
        let sensor_level = [s.x as f32, s.y as f32, s.z as f32];
        let place = Placement {
            origin: [
                ((sensor.x - base[0] as f64 * cell) / cell + side as f64) as f32,
                ((sensor.y - base[1] as f64 * cell) / cell + side as f64) as f32,
            ],
            sensor: [sensor_level[0], sensor_level[1]],
            base,
            base_slot: base.map(|b| b.rem_euclid(side as i64) as usize),
            side,
            sin: yaw.sin() as f32,
            cos: yaw.cos() as f32,
            tz: t.z as f32,
            inverse: (1.0 / cell) as f32,
        };
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
        let start = self.projector.prepare(image, &level_from_sensor);
        let kept = (self.min_range, self.max_range);
        let mut skipped = ImageStats::default();
        // First every return's height (other columns' returns verify the
        // ground in a column's gap), then the walk, row by row again.
        for pass in 0..2 {
            for position in 0..self.order.len() {
                let row = self.order[position];
                let line = &image.range[row * cols..(row + 1) * cols];
                let mut points = std::mem::take(&mut self.points);
                self.projector
                    .project_row(&start, row, line, kept, &mut points, &mut skipped);
                if pass == 0 {
                    self.raise(&points, &place, sensor_level);
                } else {
                    self.walk(&points, &place, sensor_level, &mut stats);
                }
                self.points = points;
            }
        }
        self.report(report, &mut stats);
        stats
    }

    /// Whether level-frame (x, y) lies ahead of the sensor at level-frame
    /// `sensor` (not behind it: what the vehicle drives into), within
    /// reach.
    #[inline(always)]
    fn inside(&self, x: f32, y: f32, sensor: [f32; 3]) -> bool {
        let reach = self.config.reach_m as f32;
        let (dx, dy) = (x - sensor[0], y - sensor[1]);
        dx >= 0.0 && dx * dx + dy * dy <= reach * reach
    }

    /// Whether `r` lies in `[perception.region]`.
    fn in_region(&self, r: Return) -> bool {
        let [ahead, behind, half] = self.region;
        r.x <= ahead && r.x >= -behind && r.y.abs() <= half
    }

    /// Raises each cell to the highest return of the row in it.
    fn raise(&mut self, points: &RowPoints, place: &Placement, sensor: [f32; 3]) {
        for k in 0..points.x.len() {
            let (x, y) = (points.x[k], points.y[k]);
            if !points.used[k] || !self.inside(x, y, sensor) {
                continue;
            }
            let (key, slot) = place.locate(x, y);
            let z = points.z[k] + place.tz;
            let c = &mut self.cells[slot];
            if c.key != key {
                *c = Cell { key, ..EMPTY };
            }
            c.top = c.top.max(z);
        }
    }

    /// One row's step of every column's walk: marks the cells its gap to
    /// the column's previous return passes over, and judges the gap
    /// before that one now that the ground beyond it is known.
    fn walk(
        &mut self,
        points: &RowPoints,
        place: &Placement,
        sensor: [f32; 3],
        stats: &mut EvidenceStats,
    ) {
        for k in 0..points.x.len() {
            let (x, y) = (points.x[k], points.y[k]);
            if !points.used[k] || !self.inside(x, y, sensor) {
                continue;
            }
            let here = Return {
                // Within reach: no overflow for `hypot` to guard against.
                d: ((x - sensor[0]).powi(2) + (y - sensor[1]).powi(2)).sqrt(),
                x,
                y,
                z: points.z[k] + place.tz,
            };
            let Some(far) = self.far[k] else {
                self.far[k] = Some(here);
                continue;
            };
            if here.d <= far.d {
                // Nearer than the last return (a wall's face): not a gap.
                continue;
            }
            self.pass_over(far, here, place);
            if let Some(near) = self.near[k]
                && self.in_region(near)
            {
                stats.candidates += u32::from(self.judge(near, far, here, place, sensor));
            }
            self.near[k] = Some(far);
            self.far[k] = Some(here);
        }
    }

    /// Marks the cells between `a` and `b` passed over (when no ray had).
    fn pass_over(&mut self, a: Return, b: Return, place: &Placement) {
        // Only a gap longer than the wheels bridge can hold a hole's run.
        if b.d - a.d <= self.rule.max_gap {
            return;
        }
        let travelled = self.travelled as f32;
        let mut keys = std::mem::take(&mut self.keys);
        cells_between(a, b, place, self.config.cell_size_m as f32, &mut keys);
        for &(key, slot, _) in &keys {
            let c = &mut self.cells[slot];
            if c.key != key {
                *c = Cell { key, ..EMPTY };
            }
            if c.passed.is_nan() {
                c.passed = travelled;
            }
        }
        self.keys = keys;
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
        let (dx, dy) = (far.x - sensor[0], far.y - sensor[1]);
        let along = dx.abs() / dx.hypot(dy).max(f32::MIN_POSITIVE);
        let dip = near.z - far.z;
        let tolerance = rule.noise + rule.depth_per_m * gap;
        let candidate = gap * along > rule.max_gap
            && dip > tolerance
            && sensor[2] + place.tz > near.z
            && beyond.z - far.z > 0.5 * dip;
        if !candidate {
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
        for &(key, slot, at) in &keys {
            let c = &self.cells[slot];
            let unseen = c.key == key && c.top < ground && travelled - c.passed >= settle;
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
        if longest.1 * along >= rule.max_gap - 2.0 * cell {
            // Reported where the unseen run begins: the ground before it
            // was seen, whatever row last landed on it.
            let t = longest.0
                / (far.x - near.x)
                    .hypot(far.y - near.y)
                    .max(f32::MIN_POSITIVE);
            let (x, y) = (near.x + (far.x - near.x) * t, near.y + (far.y - near.y) * t);
            self.found
                .push((place.locate(x, y).0, place.world(x, y), near.z));
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
fn cells_between(
    a: Return,
    b: Return,
    place: &Placement,
    step: f32,
    out: &mut Vec<([i32; 2], usize, f32)>,
) {
    out.clear();
    let length = ((b.x - a.x).powi(2) + (b.y - a.y).powi(2)).sqrt();
    // Both ends lie within reach: the count is bounded by its diameter.
    let steps = (length / step) as usize;
    let (ka, kb) = (place.locate(a.x, a.y).0, place.locate(b.x, b.y).0);
    let mut previous = ka;
    let (dx, dy) = ((b.x - a.x) / length * step, (b.y - a.y) / length * step);
    for s in 1..steps {
        let (key, slot) = place.locate(a.x + dx * s as f32, a.y + dy * s as f32);
        if key == previous || key == ka || key == kb {
            continue;
        }
        previous = key;
        out.push((key, slot, s as f32 * step));
    }
}
