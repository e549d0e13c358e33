//! Ganesha (002 §5): the untraversable cells near the vehicle.
//!
//! - **Insertion**: each report carries the cells of one image, already in
//!   the world frame because perception placed them with the pose at capture
//!   time; a report that arrives 600 ms late therefore lands where the
//!   obstacle is, not where the vehicle has moved to. Cells are aggregated
//!   into world-aligned patches (0.40 m), each keeping first/last-seen time,
//!   confirmations, sensors, reasons and heights.
//! - **Consistency pruning**: a patch whose centre lies in the observed
//!   footprint of a newer image from a sensor that reported it, and which
//!   that image did not report again, takes a miss; after `misses_to_drop`
//!   misses it is dropped: 2 by default, where the paper drops it at the
//!   next image. A 10 Hz lidar at 10 m/s looks again 1 m on, where its rows
//!   land elsewhere on a hole's edge: a cell flagged in one frame and not
//!   the next is still a hole's edge. Shadows count as in the footprint, as in 002 §5
//!   (tried the other way, more drop-off cells stayed and the vehicle found
//!   its way round other trenches, not more of them). An image older than a
//!   patch's last confirmation counts no miss, so out-of-order reports never
//!   prune what newer images confirmed. Nor does an image whose sensor
//!   stood farther from the patch than `miss_range_factor` times the
//!   nearest distance any image reported it from: 002 §5 drops cells "not
//!   reported ... in the next overlapping images" because they follow
//!   quickly as the vehicle drives on, from nearer; a vehicle backing away
//!   from a ditch sees it again from farther, where its far wall no longer
//!   shows (`w·H/R`), and must not erase it. A suspected drop-off (graded,
//!   reason drop-off: a hole's edge seen from too far to show its depth),
//!   and a flagged one reported from within `drop_off_trust_factor` times
//!   `hole_range_m`, take a miss only from an image whose sensor stood
//!   within `hole_range_m` of them, where a hole would have been flagged
//!   for certain: far frames flag a ditch's edge in one frame and not the
//!   next (a vehicle turning round 10 m before a ditch it had flagged lost
//!   it that way, and the route sent it across). A drop-off flagged only
//!   from farther is missed like any cell: far rows flag rough ground as
//!   often as holes.
//! - **The loop** ([`LocalMap::update`]): with the current pose every patch is
//!   re-expressed in the vehicle frame and those outside the window dropped.
//! - **Seen ground**: the ground each image observed (its footprint, less
//!   the shadows beyond edges it could not see into) is marked per patch in
//!   the same scrolling grid, so unseen ground is never mistaken for free
//!   ground; ground around the first pose counts as seen (`assume_seen_m`).
//!   Ground that leaves the window is forgotten with its patches: seen
//!   ground whose cells were dropped would read as free when the vehicle
//!   comes back to it (backing out of a cul-de-sac past a bank's end).
//! - **Under the vehicle**: patches under the vehicle's body are cleared
//!   at every pose and insertion, counted and logged: the ground it stands
//!   on bears it, and a cell there would veto every arc.
//! - **Snapshots**: immutable, vehicle frame, behind an `Arc`.
//!
//! Patches live in a scrolling ring-buffer grid (a power-of-two square that
//! covers the window whatever the heading) holding indices into a dense list:
//! lookup by position is O(1), iteration touches only live patches, and
//! nothing is copied as the vehicle moves.

use arcnav_vehicle::numbers::floor_i64;
use std::sync::Arc;

use nalgebra::Point2;

use arcnav_perception::{ObstacleReport, Reasons, ShadowIndex};
use arcnav_vehicle::frames::yaw_of;
use arcnav_vehicle::time::seconds_between;
use arcnav_vehicle::{Footprint, Isometry, Pose, Utime, VehicleConfig};

use crate::config::{JumpPolicy, LocalMapConfig};
use crate::driven::DrivenGround;
use crate::elevation::{ElevationGrid, ElevationLayer};
use crate::raster::Coverage;

mod outcome;
mod patch;
mod seen;
mod snapshot;

pub use outcome::{
    InsertError, InsertOutcome, JumpReason, MAX_COORDINATE_M, MAX_SENSORS, MapStats, PoseUpdate,
};
pub use patch::Patch;
pub use seen::SeenGround;
pub use snapshot::{MapSnapshot, SeenFrame, SeenLine};

const EMPTY: u32 = u32::MAX;

/// Where the report's sensor stood (its ground position at capture), when
/// the report says so plausibly: on or within [`VIEWPOINT_SLACK_M`] of the
/// box around its footprint (a producer that leaves `shadow_origin` at 0
/// far from where it looked tells nothing).
fn viewpoint(report: &ObstacleReport) -> Option<Point2<f64>> {
    let o = report.shadows.origin;
    let vertices = &report.fov.vertices;
    if vertices.len() < 3 || !(o.x.is_finite() && o.y.is_finite()) {
        return None;
    }
    let (mut lo, mut hi) = (vertices[0], vertices[0]);
    for v in vertices {
        lo = Point2::new(lo.x.min(v.x), lo.y.min(v.y));
        hi = Point2::new(hi.x.max(v.x), hi.y.max(v.y));
    }
    let within =
        |v: f64, lo: f64, hi: f64| v >= lo - VIEWPOINT_SLACK_M && v <= hi + VIEWPOINT_SLACK_M;
    (within(o.x, lo.x, hi.x) && within(o.y, lo.y, hi.y)).then_some(o)
}

/// How far outside its footprint's box a report's sensor may stand, m (a
/// sensor looking ahead sees no ground right before the bumper).
const VIEWPOINT_SLACK_M: f64 = 10.0;

/// The local map.
#[derive(Debug)]
pub struct LocalMap {
    config: LocalMapConfig,
    max_speed_mps: f64,
    /// The vehicle's body, widened by half a patch: patches inside are cleared.
    body: Footprint,
    mask: i64,
    side: usize,
    slots: Vec<u32>,
    patches: Vec<Patch>,
    sensors: Vec<String>,
    pose: Option<Pose>,
    /// Reports captured before this time predate the last reset.
    epoch_start: Utime,
    stamp: u64,
    coverage: Coverage,
    /// Scratch: the shadows of the report being inserted.
    shadows: ShadowIndex,
    /// Per ring slot: the world patch whose ground some image observed
    /// (`UNSEEN` if none): a slot the window scrolled past holds another
    /// patch's index, so nothing needs clearing as the vehicle moves.
    seen: SeenSlots,
    /// Ground around the next accepted pose is to be marked seen.
    assume_seen_pending: bool,
    /// The static occupancy map, if one was given.
    statics: Option<std::sync::Arc<crate::StaticMap>>,
    /// Ground the vehicle has driven over: seen again when it comes back
    /// into the window.
    driven: DrivenGround,
    /// The steep ground of the last elevation snapshot (see
    /// [`LocalMap::snapshot`]).
    steep: std::sync::Mutex<SteepGround>,
    elevation: ElevationLayer,
    stats: MapStats,
}

const UNSEEN: (i64, i64) = (i64::MIN, i64::MIN);

/// The ring's seen slots, with the list of those that hold a patch: each
/// pose forgets the seen ground that left the window by walking the slots
/// that hold one rather than every slot (65 536 at the defaults): the
/// map's pose updates fell from 10.8 to 7.3 % of the CPU of a replay of
/// paper_loop's ERIM log, whose output log is byte for byte the same.
#[derive(Debug, Clone)]
struct SeenSlots {
    /// Per slot: the patch seen there, or `UNSEEN`.
    patch: Vec<(i64, i64)>,
    /// The slots that hold a patch, in no order.
    held: Vec<u32>,
    /// Per slot: its place in `held` (`NOT_HELD`: none).
    place: Vec<u32>,
}

const NOT_HELD: u32 = u32::MAX;

impl SeenSlots {
    fn new(slots: usize) -> Self {
        Self {
            patch: vec![UNSEEN; slots],
            held: Vec::new(),
            place: vec![NOT_HELD; slots],
        }
    }

    fn get(&self, slot: usize) -> (i64, i64) {
        self.patch[slot]
    }

    fn set(&mut self, slot: usize, patch: (i64, i64)) {
        self.patch[slot] = patch;
        if self.place[slot] == NOT_HELD {
            self.place[slot] = self.held.len() as u32;
            self.held.push(slot as u32);
        }
    }

    fn clear(&mut self) {
        for &slot in &self.held {
            self.patch[slot as usize] = UNSEEN;
            self.place[slot as usize] = NOT_HELD;
        }
        self.held.clear();
    }

    /// Forgets each held patch for which `gone(patch)` is true.
    fn forget(&mut self, mut gone: impl FnMut((i64, i64)) -> bool) {
        let mut k = 0;
        while k < self.held.len() {
            let slot = self.held[k] as usize;
            if gone(self.patch[slot]) {
                self.patch[slot] = UNSEEN;
                self.place[slot] = NOT_HELD;
                self.held.swap_remove(k);
                if let Some(&moved) = self.held.get(k) {
                    self.place[moved as usize] = k as u32;
                }
            } else {
                k += 1;
            }
        }
    }
}

/// World patches seen from the vehicle frame of one pose, the pose's
/// trigonometry done once for a loop over many patches.
#[derive(Debug, Clone, Copy)]
struct PatchFrame {
    tx: f64,
    ty: f64,
    sin: f64,
    cos: f64,
    patch_size_m: f64,
}

impl PatchFrame {
    fn new(pose: &Pose, patch_size_m: f64) -> Self {
        let t = pose.world_from_vehicle.translation.vector;
        let (sin, cos) = yaw_of(&pose.world_from_vehicle).sin_cos();
        Self {
            tx: t.x,
            ty: t.y,
            sin,
            cos,
            patch_size_m,
        }
    }

    /// The centre of world patch (i, j) in the vehicle frame.
    fn centre(&self, i: i64, j: i64) -> (f64, f64) {
        let s = self.patch_size_m;
        let (dx, dy) = (
            (i as f64 + 0.5) * s - self.tx,
            (j as f64 + 0.5) * s - self.ty,
        );
        (
            self.cos * dx + self.sin * dy,
            -self.sin * dx + self.cos * dy,
        )
    }
}

/// The steep ground of one elevation snapshot, and scratch to find it.
#[derive(Debug, Default)]
struct SteepGround {
    of: Option<Arc<ElevationGrid>>,
    patches: Arc<Vec<(i64, i64)>>,
    scratch: Vec<bool>,
    cells: Vec<(i64, i64)>,
}

impl LocalMap {
    /// An empty map for `vehicle`: its top speed bounds plausible motion
    /// between poses, and patches under its body are cleared. Call
    /// `config.validate()` first.
    pub fn new(config: &LocalMapConfig, vehicle: &VehicleConfig) -> Self {
        let radius = config.radius_m();
        let side = ((2.0 * radius / config.patch_size_m).ceil() as usize + 2).next_power_of_two();
        Self {
            config: config.clone(),
            max_speed_mps: vehicle.max_speed_mps,
            // Patches whose square overlaps the body's flanks: obstacle
            // avoidance grows the body by half a patch to each side, and
            // a cell there would touch every arc, forwards and backwards.
            body: vehicle.footprint().widened(config.patch_size_m / 2.0),
            mask: side as i64 - 1,
            side,
            slots: vec![EMPTY; side * side],
            patches: Vec::new(),
            sensors: Vec::new(),
            pose: None,
            epoch_start: Utime::MIN,
            stamp: 0,
            coverage: Coverage::default(),
            shadows: ShadowIndex::default(),
            seen: SeenSlots::new(side * side),
            assume_seen_pending: true,
            statics: None,
            driven: DrivenGround::new(vehicle, config.patch_size_m, config.driven_memory_m),
            steep: std::sync::Mutex::default(),
            elevation: ElevationLayer::new(&config.elevation, radius),
            stats: MapStats::default(),
        }
    }

    /// Merges a static occupancy map (001 §3.4): its patches are in the map
    /// whenever the window reaches them, never pruned by an image, and
    /// perception cells on them are not stored again.
    pub fn set_static_map(&mut self, statics: std::sync::Arc<crate::StaticMap>) {
        self.statics = (!statics.is_empty()).then_some(statics);
        self.add_static_patches();
    }

    fn is_static(&self, i: i64, j: i64) -> bool {
        self.statics.as_ref().is_some_and(|s| s.contains(i, j))
    }

    /// Adds the static map's patches that lie in the window and are not in
    /// the map yet (nor under the vehicle).
    fn add_static_patches(&mut self) {
        let (Some(statics), Some(pose), Some((i0, j0, side))) =
            (self.statics.clone(), self.pose, self.window_square())
        else {
            return;
        };
        let utime = pose.utime;
        for j in j0..j0 + i64::from(side) {
            for i in i0..i0 + i64::from(side) {
                if !statics.contains(i, j) {
                    continue;
                }
                let slot = self.slot_index(i, j);
                let existing = self.slots[slot];
                if existing != EMPTY {
                    let patch = &mut self.patches[existing as usize];
                    if (patch.i, patch.j) == (i, j) {
                        patch.reasons.insert(Reasons::STATIC_MAP);
                        patch.cost = 1.0;
                        continue;
                    }
                    self.remove(existing as usize);
                    self.stats.dropped_outside_window += 1;
                }
                let (cx, cy) = self.patch_centre(i, j);
                let Some((vx, vy)) = self.to_vehicle(cx, cy) else {
                    return;
                };
                if !self.config.in_window(vx, vy) {
                    continue;
                }
                let patch = Patch {
                    x: vx as f32,
                    y: vy as f32,
                    first_seen: utime,
                    last_seen: utime,
                    confirmations: 1,
                    reasons: Reasons::STATIC_MAP,
                    ..Patch::at(i, j)
                };
                if self.body.contains(Point2::new(vx, vy)) {
                    continue;
                }
                self.slots[slot] = self.patches.len() as u32;
                self.patches.push(patch);
                self.stats.static_patches_added += 1;
            }
        }
    }

    pub fn config(&self) -> &LocalMapConfig {
        &self.config
    }

    /// The elevation layer (004 §III).
    pub fn elevation(&self) -> &ElevationLayer {
        &self.elevation
    }

    pub fn stats(&self) -> &MapStats {
        &self.stats
    }

    pub fn len(&self) -> usize {
        self.patches.len()
    }

    pub fn is_empty(&self) -> bool {
        self.patches.is_empty()
    }

    /// The live patches, in no particular (but deterministic) order.
    pub fn patches(&self) -> &[Patch] {
        &self.patches
    }

    /// The pose of the last accepted update.
    pub fn pose(&self) -> Option<&Pose> {
        self.pose.as_ref()
    }

    /// Name of the sensor with index `index` in [`Patch::sensors`].
    pub fn sensor_name(&self, index: usize) -> Option<&str> {
        self.sensors.get(index).map(String::as_str)
    }

    /// Forgets every patch; reports captured before `utime` will be refused.
    pub fn reset(&mut self, utime: Utime) {
        self.patches.clear();
        self.slots.fill(EMPTY);
        self.seen.clear();
        self.driven.clear();
        self.elevation.clear();
        self.assume_seen_pending = true;
        self.epoch_start = utime;
        self.stats.resets += 1;
    }

    fn slot_index(&self, i: i64, j: i64) -> usize {
        ((j & self.mask) as usize) * self.side + (i & self.mask) as usize
    }

    fn sensor_index(&mut self, name: &str) -> Result<usize, InsertError> {
        if let Some(index) = self.sensors.iter().position(|s| s == name) {
            return Ok(index);
        }
        if self.sensors.len() == MAX_SENSORS {
            return Err(InsertError::TooManySensors {
                sensor: name.to_owned(),
            });
        }
        self.sensors.push(name.to_owned());
        Ok(self.sensors.len() - 1)
    }

    /// Vehicle-frame position of a world point under the current pose.
    fn to_vehicle(&self, x: f64, y: f64) -> Option<(f64, f64)> {
        let pose = self.pose.as_ref()?;
        let t = pose.world_from_vehicle.translation.vector;
        let (sin, cos) = yaw_of(&pose.world_from_vehicle).sin_cos();
        let (dx, dy) = (x - t.x, y - t.y);
        Some((cos * dx + sin * dy, -sin * dx + cos * dy))
    }

    fn patch_centre(&self, i: i64, j: i64) -> (f64, f64) {
        let s = self.config.patch_size_m;
        ((i as f64 + 0.5) * s, (j as f64 + 0.5) * s)
    }

    fn remove(&mut self, index: usize) {
        let patch = self.patches.swap_remove(index);
        let slot = self.slot_index(patch.i, patch.j);
        self.slots[slot] = EMPTY;
        if let Some(moved) = self.patches.get(index) {
            let slot = self.slot_index(moved.i, moved.j);
            self.slots[slot] = index as u32;
        }
    }

    /// Takes the cells of one image and prunes what that image should have
    /// seen again and did not.
    pub fn insert(&mut self, report: &ObstacleReport) -> Result<InsertOutcome, InsertError> {
        if report.utime < self.epoch_start {
            self.stats.reports_refused += 1;
            return Err(InsertError::BeforeReset {
                utime: report.utime,
                reset: self.epoch_start,
            });
        }
        if let Some(bad) = report
            .cells
            .iter()
            .find(|c| !(c.x.is_finite() && c.y.is_finite()))
        {
            self.stats.reports_refused += 1;
            return Err(InsertError::BadCell { x: bad.x, y: bad.y });
        }
        if let Some(bad) = report
            .fov
            .vertices
            .iter()
            .find(|v| !(v.x.abs() <= MAX_COORDINATE_M && v.y.abs() <= MAX_COORDINATE_M))
        {
            self.stats.reports_refused += 1;
            return Err(InsertError::BadFootprint { x: bad.x, y: bad.y });
        }
        let sensor = self.sensor_index(&report.sensor).inspect_err(|_| {
            self.stats.reports_refused += 1;
        })?;
        let sensor_bit = 1u32 << sensor;
        self.elevation
            .insert(&report.heights, report.heights_cell_m);
        self.stamp += 1;
        let stamp = self.stamp;
        let mut outcome = InsertOutcome::default();
        let s = self.config.patch_size_m;
        let viewpoint = viewpoint(report);
        if viewpoint.is_none() {
            self.stats.reports_without_viewpoint += 1;
        }
        // How far the image's sensor stood from a cell (infinite: not known).
        let distance =
            |x: f64, y: f64| viewpoint.map_or(f32::INFINITY, |o| ((x - o.x).hypot(y - o.y)) as f32);
        for cell in &report.cells {
            let (i, j) = (floor_i64(cell.x / s), floor_i64(cell.y / s));
            if self.is_static(i, j) {
                self.stats.already_in_static_map += 1;
                continue;
            }
            let slot = self.slot_index(i, j);
            let existing = self.slots[slot];
            if existing != EMPTY {
                let patch = &mut self.patches[existing as usize];
                if (patch.i, patch.j) == (i, j) {
                    if patch.stamp != stamp {
                        patch.stamp = stamp;
                        patch.confirmations += 1;
                        patch.misses = 0;
                        outcome.confirmed_patches += 1;
                    }
                    patch.first_seen = patch.first_seen.min(report.utime);
                    patch.last_seen = patch.last_seen.max(report.utime);
                    patch.reasons.insert(cell.reasons);
                    patch.sensors |= sensor_bit;
                    patch.z_min = patch.z_min.min(cell.z_min);
                    patch.z_max = patch.z_max.max(cell.z_max);
                    patch.cost = patch.cost.max(cell.cost);
                    patch.nearest_m = patch.nearest_m.min(distance(cell.x, cell.y));
                    continue;
                }
                // The ring wrapped onto a patch far outside the window.
                self.remove(existing as usize);
                self.stats.dropped_outside_window += 1;
            }
            let (cx, cy) = self.patch_centre(i, j);
            let (vx, vy) = match self.to_vehicle(cx, cy) {
                Some((vx, vy)) if !self.config.in_window(vx, vy) => {
                    outcome.outside_window += 1;
                    continue;
                }
                Some(v) => v,
                // No pose yet: placed at the first update.
                None => (0.0, 0.0),
            };
            let patch = Patch {
                i,
                j,
                x: vx as f32,
                y: vy as f32,
                first_seen: report.utime,
                last_seen: report.utime,
                confirmations: 1,
                misses: 0,
                reasons: cell.reasons,
                sensors: sensor_bit,
                z_min: cell.z_min,
                z_max: cell.z_max,
                cost: cell.cost,
                nearest_m: distance(cell.x, cell.y),
                stamp,
            };
            self.slots[slot] = self.patches.len() as u32;
            self.patches.push(patch);
            outcome.new_patches += 1;
        }
        outcome.pruned = self.prune(report, viewpoint, sensor_bit, stamp);
        if self.pose.is_some() {
            // Cells placed under the vehicle (captured before it drove there).
            self.clear_under_vehicle();
        }
        self.stats.reports += 1;
        self.stats.new_patches += u64::from(outcome.new_patches);
        self.stats.confirmations += u64::from(outcome.confirmed_patches);
        self.stats.pruned_inconsistent += u64::from(outcome.pruned);
        Ok(outcome)
    }

    /// The square of world patches that covers the window around the
    /// current pose (`None` before the first pose): first (i, j) and side.
    fn window_square(&self) -> Option<(i64, i64, u32)> {
        let pose = self.pose.as_ref()?;
        let t = pose.world_from_vehicle.translation.vector;
        let s = self.config.patch_size_m;
        let reach = (self.config.radius_m() / s).ceil() as i64 + 1;
        let (i, j) = (floor_i64(t.x / s), floor_i64(t.y / s));
        Some((i - reach, j - reach, (2 * reach + 1) as u32))
    }

    fn mark_seen(&mut self, i: i64, j: i64) {
        let slot = self.slot_index(i, j);
        self.seen.set(slot, (i, j));
    }

    /// Marks the ground within `assume_seen_m` of the current pose seen.
    fn assume_seen_around_pose(&mut self) {
        let Some(pose) = self.pose else {
            return;
        };
        let (s, r) = (self.config.patch_size_m, self.config.assume_seen_m);
        let t = pose.world_from_vehicle.translation.vector;
        let (lo_i, hi_i) = (floor_i64((t.x - r) / s), floor_i64((t.x + r) / s));
        let (lo_j, hi_j) = (floor_i64((t.y - r) / s), floor_i64((t.y + r) / s));
        for j in lo_j..=hi_j {
            for i in lo_i..=hi_i {
                let (cx, cy) = self.patch_centre(i, j);
                if (cx - t.x).hypot(cy - t.y) <= r {
                    self.mark_seen(i, j);
                }
            }
        }
    }

    /// Marks the report's observed footprint seen within the window, and
    /// prepares the footprint's coverage of the rows of the window and of
    /// the patches (for pruning). False when the footprint is empty.
    fn observe(&mut self, report: &ObstacleReport) -> bool {
        if report.fov.is_empty() {
            return false;
        }
        let square = self.window_square();
        // Only these rows are rasterised: a footprint reaching far beyond
        // the window costs no more than one inside it.
        let rows = self
            .patches
            .iter()
            .map(|p| (p.j, p.j))
            .chain(square.map(|(_, j0, side)| (j0, j0 + i64::from(side) - 1)))
            .reduce(|(lo, hi), (a, b)| (lo.min(a), hi.max(b)));
        let Some(rows) = rows else {
            return false;
        };
        self.coverage
            .rasterise(&report.fov, self.config.patch_size_m, rows);
        if let Some((i0, _, side)) = square {
            self.shadows.build(&report.shadows);
            let coverage = std::mem::take(&mut self.coverage);
            coverage.for_each_covered((i0, i0 + i64::from(side) - 1), |i, j| {
                // Ground in the footprint but out of sight was not seen.
                if !self.in_shadow(i, j) {
                    self.mark_seen(i, j);
                }
            });
            self.coverage = coverage;
        }
        true
    }

    /// Whether the centre of patch (`i`, `j`) lies in a shadow of the
    /// report being inserted.
    fn in_shadow(&self, i: i64, j: i64) -> bool {
        let (x, y) = self.patch_centre(i, j);
        self.shadows.contains(x, y)
    }

    fn prune(
        &mut self,
        report: &ObstacleReport,
        viewpoint: Option<Point2<f64>>,
        sensor_bit: u32,
        stamp: u64,
    ) -> u32 {
        if !self.observe(report) {
            return 0;
        }
        let (factor, hole_range, trust) = (
            self.config.miss_range_factor,
            self.config.hole_range_m,
            self.config.drop_off_trust_factor,
        );
        let s = self.config.patch_size_m;
        let mut pruned = 0;
        let mut index = 0;
        while index < self.patches.len() {
            let patch = &mut self.patches[index];
            // Seen from farther than it could be seen from, it is not
            // missed; nor is a drop-off (suspected, or flagged from near
            // where a hole is certain to show) seen from beyond there.
            let near_enough = || match viewpoint {
                Some(o) => {
                    let (x, y) = ((patch.i as f64 + 0.5) * s, (patch.j as f64 + 0.5) * s);
                    let distance = (x - o.x).hypot(y - o.y);
                    let afar = factor > 0.0
                        && patch.nearest_m.is_finite()
                        && distance > factor * f64::from(patch.nearest_m);
                    let unsure = hole_range > 0.0
                        && patch.reasons.contains(Reasons::DROP_OFF)
                        && (patch.is_suspected_drop_off()
                            || (trust > 0.0 && f64::from(patch.nearest_m) <= trust * hole_range))
                        && distance > hole_range;
                    !(afar || unsure)
                }
                None => true,
            };
            let judged = patch.stamp != stamp
                && !patch.reasons.contains(Reasons::STATIC_MAP)
                && patch.last_seen < report.utime
                && (self.config.cross_sensor_pruning || patch.sensors & sensor_bit != 0)
                && self.coverage.covers(patch.i, patch.j);
            if judged && !near_enough() {
                self.stats.seen_from_afar += 1;
            } else if judged {
                patch.misses += 1;
                if patch.misses >= self.config.misses_to_drop {
                    self.remove(index);
                    pruned += 1;
                    continue;
                }
            }
            index += 1;
        }
        pruned
    }

    /// The loop of 002 §5 (Figure 8): takes the current pose, re-expresses
    /// every patch in the vehicle frame and drops those outside the window.
    /// A pose that jumps, or comes from the past, resets the map or is
    /// rejected, as configured, with the reason logged.
    pub fn update(&mut self, pose: &Pose) -> PoseUpdate {
        if let Some(previous) = &self.pose {
            let reason = if pose.utime < previous.utime {
                Some(JumpReason::TimeBackwards {
                    from: previous.utime,
                    to: pose.utime,
                })
            } else {
                let moved = (pose.world_from_vehicle.translation.vector
                    - previous.world_from_vehicle.translation.vector)
                    .xy()
                    .norm();
                let allowed = self.config.max_pose_jump_m
                    + self.max_speed_mps * seconds_between(previous.utime, pose.utime);
                (moved > allowed || !moved.is_finite()).then_some(JumpReason::Jump {
                    distance_m: moved,
                    allowed_m: allowed,
                })
            };
            if let Some(reason) = reason {
                match self.config.on_pose_jump {
                    JumpPolicy::Reset => {
                        tracing::warn!(%reason, patches = self.patches.len(), "local map reset");
                        self.reset(pose.utime);
                        self.pose = Some(*pose);
                        let t = pose.world_from_vehicle.translation.vector;
                        self.elevation.recentre(t.x, t.y);
                        self.assume_seen_pending = false;
                        self.assume_seen_around_pose();
                        self.add_static_patches();
                        return PoseUpdate::Reset(reason);
                    }
                    JumpPolicy::Reject => {
                        tracing::warn!(%reason, "pose rejected by the local map");
                        self.stats.rejected_poses += 1;
                        return PoseUpdate::Rejected(reason);
                    }
                }
            }
        }
        self.pose = Some(*pose);
        let t = pose.world_from_vehicle.translation.vector;
        self.elevation.recentre(t.x, t.y);
        if self.assume_seen_pending {
            self.assume_seen_pending = false;
            self.assume_seen_around_pose();
        }
        let frame = PatchFrame::new(pose, self.config.patch_size_m);
        let mut index = 0;
        while index < self.patches.len() {
            let patch = &mut self.patches[index];
            let (vx, vy) = frame.centre(patch.i, patch.j);
            if !self.config.in_window(vx, vy) {
                self.remove(index);
                self.stats.dropped_outside_window += 1;
                continue;
            }
            patch.x = vx as f32;
            patch.y = vy as f32;
            let patch = *patch;
            if self.under_vehicle(&patch) {
                self.remove(index);
                continue;
            }
            index += 1;
        }
        self.forget_seen_outside_window();
        self.driven.drive(pose);
        self.see_driven_ground();
        self.add_static_patches();
        PoseUpdate::Accepted
    }

    /// Marks the driven ground inside the window seen: it bore the vehicle
    /// (see [`crate::driven`]), though the window may have forgotten it.
    fn see_driven_ground(&mut self) {
        let Some(pose) = self.pose else {
            return;
        };
        let frame = PatchFrame::new(&pose, self.config.patch_size_m);
        for (i, j) in self.driven.iter() {
            let (x, y) = frame.centre(i, j);
            if self.config.in_window(x, y) {
                let slot = self.slot_index(i, j);
                self.seen.set(slot, (i, j));
            }
        }
    }

    /// Forgets the seen ground that has left the window, as its patches
    /// were dropped: what the map no longer holds, it has not seen.
    fn forget_seen_outside_window(&mut self) {
        let Some(pose) = self.pose else {
            return;
        };
        let frame = PatchFrame::new(&pose, self.config.patch_size_m);
        let config = &self.config;
        self.seen.forget(|(i, j)| {
            let (x, y) = frame.centre(i, j);
            !config.in_window(x, y)
        });
    }

    /// Removes every patch under the vehicle (see [`Self::under_vehicle`]).
    fn clear_under_vehicle(&mut self) {
        let mut index = 0;
        while index < self.patches.len() {
            let patch = self.patches[index];
            if self.under_vehicle(&patch) {
                self.remove(index);
                continue;
            }
            index += 1;
        }
    }

    /// True (counted and logged with its reasons) when `patch`'s centre, in
    /// the vehicle frame, lies under the vehicle's body or its square
    /// overlaps the body's flanks: the vehicle stands there, so that ground
    /// bears it, whatever an image made of it (a slope cell flagged from
    /// afar, a cell placed late, the foot of a boulder it brushes past).
    /// Such patches are removed.
    fn under_vehicle(&mut self, patch: &Patch) -> bool {
        let centre = Point2::new(f64::from(patch.x), f64::from(patch.y));
        if !self.body.contains(centre) {
            return false;
        }
        tracing::debug!(
            i = patch.i,
            j = patch.j,
            reasons = %patch.reasons.names(),
            confirmations = patch.confirmations,
            "cell under the vehicle cleared"
        );
        self.stats.cleared_under_vehicle += 1;
        true
    }

    /// The map as it stands, in the vehicle frame of the last update: its
    /// patches, and the ground its elevation layer finds steeper than
    /// `elevation.steep_deg` as obstacle patches of their own (reason
    /// `steep`; a patch already held gets the reason and becomes an
    /// obstacle), within the window and not under the vehicle. Perception
    /// judges each image alone and marks a bank's side only in places; the
    /// fused layer sees all of it, for every behaviour (obstacle avoidance
    /// driving and backing, the route's memory).
    pub fn snapshot(&self) -> Arc<MapSnapshot> {
        let elevation = self.elevation.snapshot();
        let mut patches = self.patches.clone();
        if let Some(pose) = self.pose {
            let steep = self.steep_patches(&elevation);
            self.add_steep(&steep, &pose, &elevation, &mut patches);
        }
        Arc::new(MapSnapshot {
            utime: self.pose.map_or(0, |p| p.utime),
            world_from_vehicle: self
                .pose
                .map_or_else(Isometry::identity, |p| p.world_from_vehicle),
            patch_size_m: self.config.patch_size_m,
            patches,
            seen: self.seen_ground(),
            elevation,
        })
    }

    /// The world patches holding steep cells of `elevation`, found once per
    /// elevation snapshot.
    fn steep_patches(&self, elevation: &Arc<ElevationGrid>) -> Arc<Vec<(i64, i64)>> {
        let mut steep = self.steep.lock().unwrap_or_else(|e| e.into_inner());
        if !steep
            .of
            .as_ref()
            .is_some_and(|of| Arc::ptr_eq(of, elevation))
        {
            let SteepGround { scratch, cells, .. } = &mut *steep;
            elevation.steep_cells(self.config.elevation.steep_deg, scratch, cells);
            let (c, s) = (elevation.cell_size_m, self.config.patch_size_m);
            let mut found: Vec<(i64, i64)> = cells
                .iter()
                .map(|&(i, j)| {
                    let centre = |k: i64| floor_i64((k as f64 + 0.5) * c / s);
                    (centre(i), centre(j))
                })
                .collect();
            found.sort_unstable();
            found.dedup();
            steep.patches = Arc::new(found);
            steep.of = Some(Arc::clone(elevation));
        }
        Arc::clone(&steep.patches)
    }

    /// Adds the `steep` world patches to `patches` (vehicle frame at `pose`).
    fn add_steep(
        &self,
        steep: &[(i64, i64)],
        pose: &Pose,
        elevation: &ElevationGrid,
        patches: &mut Vec<Patch>,
    ) {
        let frame = PatchFrame::new(pose, self.config.patch_size_m);
        for &(i, j) in steep {
            let index = self.slots[self.slot_index(i, j)];
            if let Some(held) = patches
                .get_mut(index as usize)
                .filter(|p| (p.i, p.j) == (i, j))
            {
                held.reasons.insert(Reasons::STEEP);
                held.cost = 1.0;
                continue;
            }
            let (x, y) = frame.centre(i, j);
            if !self.config.in_window(x, y) || self.body.contains(Point2::new(x, y)) {
                continue;
            }
            let (cx, cy) = self.patch_centre(i, j);
            let z = elevation.at(cx, cy).map_or(0.0, |[mean, _]| mean);
            patches.push(Patch {
                x: x as f32,
                y: y as f32,
                first_seen: pose.utime,
                last_seen: pose.utime,
                reasons: Reasons::STEEP,
                z_min: z,
                z_max: z,
                ..Patch::at(i, j)
            });
        }
    }

    /// The seen ground of the square around the window.
    pub fn seen_ground(&self) -> SeenGround {
        let Some((i0, j0, side)) = self.window_square() else {
            return SeenGround::default();
        };
        let mut seen = SeenGround::new(i0, j0, side);
        for j in j0..j0 + i64::from(side) {
            for i in i0..i0 + i64::from(side) {
                if self.seen.get(self.slot_index(i, j)) == (i, j) {
                    seen.insert(i, j);
                }
            }
        }
        seen
    }
}
