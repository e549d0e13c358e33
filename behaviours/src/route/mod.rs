//! Route (`route`): finds the way around what the local map has shown, as
//! D* voting in DAMN did (Stentz & Hebert, 1995) and 004 re-plans a blocked
//! stretch of its global path.
//!
//! - **Memory**: a world-frame grid of `cell_m` cells over `size_m` square
//!   around the vehicle (re-centred, keeping what overlaps, when the
//!   vehicle has moved a quarter of it from the centre). Each cycle, every
//!   cell wholly inside the local map's window takes what the map says: an
//!   obstacle if a patch lies in it, free if its ground was seen and no
//!   patch does; cells outside the window keep what they were last shown.
//! - **Costs**: free ground 1, ground never seen `unseen_cost`, an obstacle
//!   impassable; ground next to an obstacle (within one cell) costs
//!   `1 + clearance_cost` times more, within two cells `1 + clearance_cost/4`
//!   times (the vehicle is wider than a cell: obstacle avoidance decides
//!   the last metre, the route keeps away from narrow gaps); seen ground
//!   as rough as stones or ruts costs up to `1 + rough_cost` (four levels
//!   from the elevation layer's second differences: see
//!   `Route::roughness_level`), so a smooth track beside rubble wins;
//!   ground with a suspected drop-off in it (a hole's edge seen from too
//!   far to show its depth) is rough ground too, or, with `suspect_cost`,
//!   costs that much, so that a short way round it is taken and a long one
//!   is not.
//! - **Unseen ground it was held short of**: when the vehicle starts to
//!   back up (the arbiter's recovery: held standing before the ground
//!   ahead), the cells never seen within `shut_unseen_m` of its front and
//!   within 60° of its heading are shut, planned round like an obstacle,
//!   until an image sees them. The shadow beyond a ledge stays unseen
//!   from wherever the vehicle can stand (a 2 m drop seen from 10 m shows
//!   its floor no steeper than a slope the vehicle may drive, so the edge
//!   is not flagged; the vehicle is held 2 m short of the shadow), and
//!   counted passable at `unseen_cost` the path would lead back to the
//!   same edge after every backing-up. From those cells the shutting
//!   spreads through unseen cells with seen ground on both sides (a
//!   shadow lies between the edge and the ground it falls to), within
//!   `shut_along_m` and well inside the local map's window (in view yet
//!   unseen), so that one backing-up closes the edge within sight, not the
//!   next metre of it. A cell seen at its centre but not wholly, between
//!   shut cells (within [`GAP_CELLS`] on both sides), is shut too: the
//!   gap it leaves in the band is narrower than the vehicle, and obstacle
//!   avoidance, which looks at the unseen part, holds the vehicle short of
//!   it after every backing-up. A shut cell opens again once all of it
//!   has been seen. A cell with shut ground right beside it on two
//!   opposite sides (or shut ground on one and an obstacle on the other)
//!   is impassable: a strip one cell wide seen through the shadow is no
//!   way for the vehicle. Shut cells that leave no way to the waypoint are
//!   opened again.
//! - **Planning**: D* Lite ([`dstar`]) from the current waypoint to the
//!   vehicle, repaired incrementally as cells change and as the vehicle
//!   moves; from scratch only for a new waypoint or a re-centred memory. A
//!   waypoint outside the memory is sought where the line to it leaves it.
//! - **Holding to a way**: near where the vehicle last stood (slower than
//!   0.1 m/s, as before backing up; within two lookaheads), the path
//!   followed is kept, all of it to the goal, while the vehicle is within
//!   2 m of it, it stays passable
//!   and following it from the vehicle costs at most `hold_fraction`
//!   more than the plan; else the plan's is followed from then on. Each
//!   image shows a little more, and the plan alone flips between ways of
//!   about the same cost (the two ends of a ditch across the way, each
//!   farther than it looked as more of the ditch is seen): a vehicle
//!   standing before it, turning to each in turn, goes neither way.
//!   Driving on, the route follows the plan.
//! - **Votes**: for the arcs that head for the point of the path
//!   `lookahead_m` from the vehicle (`lookahead_s` of driving at the cruise
//!   speed, if farther) or, with `sight_line`, for the farthest point of
//!   the path the vehicle sees in a straight line over ground no costlier
//!   than the path's own when that is farther (string pulling: the
//!   8-connected path's point a fixed distance ahead jumps sideways from
//!   cycle to cycle). Scored as goal seeking scores arcs
//!   towards a waypoint. With no path (the waypoint walled off) it says so
//!   once and votes towards the waypoint itself.

pub mod dstar;

use arcnav_arbiter::Votes;
use arcnav_localmap::{LocalMapConfig, MapSnapshot};
use arcnav_vehicle::SteeringResponse;
use arcnav_vehicle::Utime;
use arcnav_vehicle::config::ConfigError;
use arcnav_vehicle::frames::yaw_of;
use arcnav_vehicle::mission::{Area, OnUnreachable, WhenUnreachable};
use arcnav_vehicle::numbers::floor_i64;
use arcnav_vehicle::time::seconds_to_micros;

use crate::behaviour::Plugin;
use crate::behaviour::{
    Behaviour, NoRoute, Overlay, OverlayCells, OverlayLine, OverlayPoint, Progress, Setup,
    VoteContext,
};
use crate::goal_seeking::{WaypointTracker, lookahead, vote_towards};
use dstar::{DStarLite, PlannerStats};

mod cells;
pub mod config;

use cells::{
    AXES, DOUBTFUL, FREE, GAP_CELLS, Layout, NEIGHBOURS, OBSTACLE, ROUGH, ROUGH_LEVELS,
    SHADOW_CELLS, SHUT, SHUT_HALF_ANGLE_DEG, SHUT_IN_VIEW_M, SUSPECT, SUSPECTED_LEVEL, UNKNOWN,
    roughness_level, wholly_seen,
};
pub use config::RouteConfig;

/// The planned path is drawn this far along ([`Behaviour::overlay`]), m.
const OVERLAY_PATH_M: f64 = 60.0;

/// The path followed is held (`hold_fraction`) within this many
/// lookaheads of where the vehicle last stood (as it does before backing
/// up); farther on, driving, it follows the best plan.
const HOLD_AFTER_STANDING: f64 = 2.0;

/// The vehicle stands when slower than this, m/s.
const STANDING_MPS: f64 = 0.1;

/// ... and only while the vehicle is within this distance of it, m:
/// farther off, its point a lookahead on may lie behind the vehicle (held
/// to a path up to 8 m off, the ERIM wandered up `hillside_steep` after
/// a stop, 477 m for 255).
const HOLD_OFF_PATH_M: f64 = 2.0;

/// The memory covers the whole operating area, fixed over it, when the
/// area's bounding box fits in this many cells a side; a larger area is
/// remembered as any mission is, `size_m` around the vehicle.
const MAX_AREA_CELLS: usize = 1000;

/// What the route behaviour did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RouteStats {
    pub planner: PlannerStats,
    /// Times the memory was re-centred on the vehicle.
    pub recentres: u64,
    /// Cycles with no path to the waypoint.
    pub no_path_cycles: u64,
    /// Memory cells that changed state, in all.
    pub cell_changes: u64,
    /// Unseen cells shut when the vehicle started to back up, in all.
    pub shut_cells: u64,
    /// Shut cells opened again because they left no way, in all.
    pub reopened_cells: u64,
    /// Cycles the path being followed was kept though the plan found a
    /// cheaper one (within `hold_fraction`).
    pub held_cycles: u64,
    /// Times the path being followed was left for the plan's: it became
    /// impassable, or cost more than `hold_fraction` over the plan's.
    pub path_switches: u64,
}

/// The elevation grid and the memory's origin the route's roughness levels
/// were read for.
type RoughnessOf = (
    std::sync::Arc<arcnav_localmap::ElevationGrid>,
    Option<(i64, i64)>,
);

/// The route behaviour.
#[derive(Debug, Clone)]
pub struct Route {
    config: RouteConfig,
    tracker: WaypointTracker,
    /// The local map's window (cells wholly inside it follow the map).
    window: LocalMapConfig,
    /// Where the memory cells lie in the world.
    layout: Layout,
    /// The memory's origin when it is fixed over the operating area
    /// (never re-centred).
    fixed: Option<(i64, i64)>,
    state: Vec<u8>,
    costs: Vec<f32>,
    planner: DStarLite,
    /// The waypoint being planned to and its memory cell.
    goal: Option<(usize, usize)>,
    hits: Vec<u32>,
    /// Per cell: the stamp of the cycle an obstacle patch seen from within
    /// `confirm_within_m` (or from a distance not known) lay in it.
    near_hits: Vec<u32>,
    /// Per cell: the stamp of the cycle a graded patch lay in it, and the
    /// highest roughness level of those patches.
    graded: Vec<(u32, u8)>,
    /// Per cell: its roughness level from the elevation layer, and the
    /// `rough_epoch` it was read in. The level of a cell depends only on
    /// the layer's grid (one shared snapshot between images) and on where
    /// the cell lies, so it is read again only when either changed.
    rough: Vec<(u32, u8)>,
    rough_epoch: u32,
    /// The grid and the memory's origin the epoch stands for (the grid
    /// held, so that its address is never another's).
    rough_of: Option<RoughnessOf>,
    stamp: u32,
    changed: Vec<usize>,
    path: Vec<usize>,
    has_path: bool,
    /// The static occupancy map: its patches are obstacles in the memory
    /// wherever the memory reaches, seen or not.
    statics: Option<std::sync::Arc<arcnav_localmap::StaticMap>>,
    stats: RouteStats,
    /// How the vehicle answers a command: arcs are judged along the paths
    /// it drives.
    response: SteeringResponse,
    /// Arcs head for the path's point this far away, m.
    aim_m: f64,
    /// From the vehicle's origin to its front bumper, m.
    front_m: f64,
    /// The last command seen backed up.
    backing: bool,
    /// Scratch: the cells a shutting spreads from.
    flood: Vec<usize>,
    /// World point the last vote steered for, and whether it lay on a
    /// planned path (else the waypoint, with no path).
    aimed_at: Option<([f64; 2], bool)>,
    /// The path being followed, all the way to the goal cell (empty: none
    /// yet, or the goal or the memory moved).
    held: Vec<usize>,
    /// Index in `held` of its cell nearest the vehicle.
    held_at: usize,
    /// Where the vehicle last stood (slower than [`STANDING_MPS`]).
    stood_at: Option<[f64; 2]>,
    /// The operating area: the route plans inside it only.
    area: Option<Area>,
    /// Per memory cell: its centre lies beyond the area, or nearer its
    /// edge than half the vehicle's width (the vehicle on the path would
    /// stick out). Impassable, whatever images show.
    outside: Vec<bool>,
    /// Half the vehicle's width, m.
    half_width_m: f64,
    unreachable: WhenUnreachable,
    /// The waypoint (index) the planner has found no way to, searching all
    /// it knows, and since when (µs).
    no_way_since: Option<(usize, Utime)>,
    /// The waypoints given up as unreachable, with the evidence.
    no_routes: Vec<NoRoute>,
}

impl Route {
    pub fn new(config: RouteConfig, setup: &Setup<'_>) -> Self {
        let (side, fixed) = memory_over(&config, setup.area);
        let n = side * side;
        Self {
            tracker: WaypointTracker::new(config.arrival_radius_m, config.pass_radius_factor),
            window: setup.localmap.clone(),
            layout: Layout {
                side,
                origin: None,
                cell_m: config.cell_m,
            },
            fixed,
            state: vec![UNKNOWN; n],
            costs: vec![0.0; n],
            planner: DStarLite::new(side, 1.0),
            goal: None,
            hits: vec![0; n],
            near_hits: vec![0; n],
            graded: vec![(0, 0); n],
            rough: vec![(0, 0); n],
            rough_epoch: 0,
            rough_of: None,
            stamp: 0,
            changed: Vec::new(),
            path: Vec::new(),
            has_path: false,
            statics: setup.statics.cloned(),
            stats: RouteStats::default(),
            response: setup.steering_response(),
            aim_m: lookahead(config.lookahead_m, config.lookahead_s, setup.cruise_mps),
            front_m: setup.vehicle.footprint().x_max,
            backing: false,
            flood: Vec::new(),
            aimed_at: None,
            held: Vec::new(),
            held_at: 0,
            stood_at: None,
            area: setup.area.cloned(),
            outside: vec![false; n],
            half_width_m: setup.vehicle.footprint().half_width,
            unreachable: setup.unreachable,
            no_way_since: None,
            no_routes: Vec::new(),
            config,
        }
    }

    pub fn stats(&self) -> RouteStats {
        RouteStats {
            planner: self.planner.stats,
            ..self.stats
        }
    }

    /// True when the last plan found a path to the waypoint.
    pub fn has_path(&self) -> bool {
        self.has_path
    }

    /// Bytes the memory and the planner hold.
    pub fn memory_bytes(&self) -> usize {
        let n = self.layout.side * self.layout.side;
        // state, outside, costs, hits, near hits, graded; the planner's g,
        // rhs, queued key, marks.
        n * (1 + 1 + 4 + 4 + 4 + std::mem::size_of::<(u32, u8)>())
            + n * (4 + 4 + 12 + 4)
            + (self.path.capacity() + self.flood.capacity() + self.held.capacity()) * 8
    }

    /// Whether world point `p` lies at least `margin` inside the local
    /// map's window around a vehicle at `vehicle` whose yaw has sine and
    /// cosine `(sin, cos)`.
    fn in_window(
        &self,
        vehicle: [f64; 2],
        (sin, cos): (f64, f64),
        p: [f64; 2],
        margin: f64,
    ) -> bool {
        let (dx, dy) = (p[0] - vehicle[0], p[1] - vehicle[1]);
        let (vx, vy) = (cos * dx + sin * dy, -sin * dx + cos * dy);
        let w = &self.window;
        vx >= -w.behind_m + margin
            && vx <= w.ahead_m - margin
            && vy.abs() <= w.half_width_m - margin
    }

    /// Centres the memory on (x, y) when the vehicle has left the middle
    /// half of it (keeping the cells that overlap); true when it moved.
    fn recentre(&mut self, x: f64, y: f64) -> bool {
        let cell = self.config.cell_m;
        let half = (self.layout.side / 2) as i64;
        let wanted = self
            .fixed
            .unwrap_or((floor_i64(x / cell) - half, floor_i64(y / cell) - half));
        if let Some((i0, j0)) = self.layout.origin {
            let quarter = (self.layout.side / 4) as i64;
            if (wanted.0 - i0).abs() < quarter && (wanted.1 - j0).abs() < quarter {
                return false;
            }
            let mut state = vec![UNKNOWN; self.state.len()];
            let side = self.layout.side as i64;
            for (c, slot) in state.iter_mut().enumerate() {
                let (i, j) = (
                    (c as i64 % side) + wanted.0 - i0,
                    (c as i64 / side) + wanted.1 - j0,
                );
                if (0..side).contains(&i) && (0..side).contains(&j) {
                    *slot = self.state[(j * side + i) as usize];
                }
            }
            self.state = state;
            self.stats.recentres += 1;
        }
        self.layout.origin = Some(wanted);
        self.mark_outside();
        self.mark_statics();
        for c in 0..self.costs.len() {
            self.costs[c] = self.cost_of(c);
        }
        true
    }

    /// Marks the memory cells the vehicle may not plan through for the
    /// operating area ([`Route::outside`]).
    fn mark_outside(&mut self) {
        let Some(area) = &self.area else {
            return;
        };
        for (c, outside) in self.outside.iter_mut().enumerate() {
            *outside = !area.holds(self.layout.centre(c), self.half_width_m);
        }
    }

    /// Whether cell `c` is impassable whatever its cost around it: an
    /// obstacle, shut, or outside the area.
    fn blocked(&self, c: usize) -> bool {
        self.outside[c] || matches!(self.state[c], OBSTACLE | SHUT)
    }

    /// Marks every memory cell a static-map patch touches an obstacle (the
    /// map's patches are smaller than the memory's cells).
    fn mark_statics(&mut self) {
        let Some(statics) = self.statics.clone() else {
            return;
        };
        let patch = self.window.patch_size_m;
        let cell = self.config.cell_m;
        for c in 0..self.state.len() {
            let [x, y] = self.layout.centre(c);
            let (lo_i, hi_i) = (
                floor_i64((x - cell / 2.0) / patch),
                ((x + cell / 2.0) / patch).ceil() as i64 - 1,
            );
            let (lo_j, hi_j) = (
                floor_i64((y - cell / 2.0) / patch),
                ((y + cell / 2.0) / patch).ceil() as i64 - 1,
            );
            let occupied = (lo_j..=hi_j).any(|j| (lo_i..=hi_i).any(|i| statics.contains(i, j)));
            if occupied {
                self.state[c] = OBSTACLE;
            }
        }
    }

    /// The cost of crossing cell `c` (see the module docs).
    fn cost_of(&self, c: usize) -> f32 {
        if self.outside[c] {
            return f32::INFINITY;
        }
        let base = match self.state[c] {
            OBSTACLE | SHUT => return f32::INFINITY,
            DOUBTFUL => self.config.doubtful_cost as f32,
            FREE => 1.0,
            UNKNOWN => self.config.unseen_cost as f32,
            SUSPECT => self.config.suspect_cost as f32,
            rough => {
                let level = f64::from(rough - ROUGH + 1) / f64::from(ROUGH_LEVELS);
                (1.0 + self.config.rough_cost * level) as f32
            }
        };
        let (x, y) = self.layout.column_row(c);
        // A cell between shut ground on both sides (or shut ground and an
        // obstacle): a gap in a ledge's shut band one cell wide, through
        // which an image happened to see. Obstacle avoidance holds the
        // vehicle short of the unseen ground on either side of it.
        let beside = |dx: i64, dy: i64| self.layout.index(x + dx, y + dy).map(|n| self.state[n]);
        if AXES.into_iter().any(|(dx, dy)| {
            matches!(
                (beside(dx, dy), beside(-dx, -dy)),
                (Some(SHUT), Some(SHUT | OBSTACLE)) | (Some(OBSTACLE), Some(SHUT))
            )
        }) {
            return f32::INFINITY;
        }
        let mut nearest = 3;
        for dy in -2..=2i64 {
            for dx in -2..=2i64 {
                if self
                    .layout
                    .index(x + dx, y + dy)
                    .is_some_and(|n| self.blocked(n))
                {
                    nearest = nearest.min(dx.abs().max(dy.abs()));
                }
            }
        }
        let factor = match nearest {
            1 => 1.0 + self.config.clearance_cost,
            2 => 1.0 + self.config.clearance_cost / 4.0,
            _ => 1.0,
        };
        base * factor as f32
    }

    /// Sets `path` to the cells the vehicle follows next (as many as the
    /// lookahead needs, after its own): near where the vehicle last stood
    /// ([`HOLD_AFTER_STANDING`]), those of the path being
    /// followed while the vehicle is on it ([`HOLD_OFF_PATH_M`]) and it
    /// costs no more than `hold_fraction` over the best plan (from the
    /// vehicle `here`, in cell `start`), else the plan's, which becomes
    /// the path followed. A plan alone flips between ways of about the
    /// same cost as each image shows a little more: the two ends of a
    /// ditch across the way, each farther than it looked as more of the
    /// ditch is seen, or a detour and a crossing of suspected ground; the
    /// vehicle, turning to each in turn, went neither way (`ditch_across`
    /// at 5.3 m/s: 78 s of turning on the spot, stuck). A driver keeps to
    /// the side chosen until the other is clearly better, or this one is
    /// shut, as bug algorithms keep to a wall. Driving on, a better line
    /// is taken at once: held to it everywhere, the ERIM wandered up
    /// `hillside_steep` round cells that came and went (477 m for 255).
    fn hold_or_switch(&mut self, start: usize, here: [f64; 2]) {
        let steps = (2.0 * self.aim_m / self.config.cell_m).ceil() as usize + 2;
        let best = self.planner.cost_to_goal(start);
        let limit = best * (1.0 + self.config.hold_fraction as f32);
        let near_stand = self.stood_at.is_some_and(|at| {
            (at[0] - here[0]).hypot(at[1] - here[1]) <= HOLD_AFTER_STANDING * self.aim_m
        });
        let held = near_stand.then(|| self.held_cost(start, steps)).flatten();
        match held {
            Some((at, cost)) if cost <= limit => {
                self.held_at = at;
                if cost > best * (1.0 + 1e-4) {
                    self.stats.held_cycles += 1;
                }
            }
            _ => {
                if near_stand && !self.held.is_empty() {
                    self.stats.path_switches += 1;
                    tracing::debug!(
                        held = held.map_or(f32::INFINITY, |(_, cost)| cost),
                        plan = best,
                        "route: the path followed left for the plan's"
                    );
                }
                self.planner
                    .path(&self.costs, self.state.len(), &mut self.path);
                self.held.clear();
                self.held.push(start);
                self.held.extend_from_slice(&self.path);
                self.held_at = 0;
            }
        }
        let next = (self.held_at + 1).min(self.held.len());
        self.path.clear();
        self.path
            .extend(self.held[next..].iter().take(steps).copied());
    }

    /// Where the vehicle in cell `start` is on the path being followed
    /// (the index of its nearest cell near where it was last cycle,
    /// `steps` on at most) and what following it to the goal costs from
    /// there: the octile distance to that cell at free ground's cost, then
    /// the path's edges at today's costs. None when there is no such path,
    /// the vehicle is farther from it than [`HOLD_OFF_PATH_M`], or it is
    /// no longer passable.
    fn held_cost(&self, start: usize, steps: usize) -> Option<(usize, f32)> {
        if self.config.hold_fraction <= 0.0 || self.held.is_empty() {
            return None;
        }
        let back = (self.aim_m / self.config.cell_m).ceil() as usize;
        let window = self.held_at.saturating_sub(back)..(self.held_at + steps).min(self.held.len());
        let (at, off) = window
            .map(|k| (k, self.planner.octile(start, self.held[k])))
            .min_by(|a, b| a.1.total_cmp(&b.1).then(b.0.cmp(&a.0)))?;
        if f64::from(off) * self.config.cell_m > HOLD_OFF_PATH_M {
            return None;
        }
        let cost = off + self.planner.path_cost(&self.costs, &self.held[at..]);
        cost.is_finite().then_some((at, cost))
    }

    /// The farthest point of the planned path that the vehicle at `here`
    /// sees along a straight line crossing no cell costlier than the path
    /// itself up to that point, every nearer path point in sight too
    /// (string pulling, as any-angle planners smooth a grid path). On an
    /// 8-connected grid many paths cost the same — diagonal steps first or
    /// straight ones first — and the one the planner returns changes from
    /// cycle to cycle, so the path's point a fixed distance ahead jumps
    /// sideways by metres; the straight line over the same open ground does
    /// not. Only ground the path itself would cross is crossed: where the
    /// path bends round an obstacle's margin the sight line stops there.
    fn farthest_in_sight(&self, here: [f64; 2]) -> Option<[f64; 2]> {
        let step = 0.25 * self.config.cell_m;
        let mut limit = self
            .layout
            .cell_at(here[0], here[1])
            .map_or(1.0, |c| self.costs[c]);
        let mut sighted = None;
        for &cell in &self.path {
            limit = limit.max(self.costs[cell]);
            if !limit.is_finite() {
                break;
            }
            let point = self.layout.centre(cell);
            let (dx, dy) = (point[0] - here[0], point[1] - here[1]);
            let samples = (dx.hypot(dy) / step).ceil().max(1.0) as usize;
            let clear = (1..samples).all(|k| {
                let f = k as f64 / samples as f64;
                self.layout
                    .cell_at(here[0] + f * dx, here[1] + f * dy)
                    .is_some_and(|c| self.costs[c] <= limit * (1.0 + 1e-6))
            });
            if !clear {
                break;
            }
            sighted = Some(point);
        }
        sighted
    }

    /// Sets cell `c`'s state; re-costs the cells around it that change.
    fn set_state(&mut self, c: usize, state: u8) {
        if self.state[c] == state {
            return;
        }
        self.state[c] = state;
        self.stats.cell_changes += 1;
        let (x, y) = self.layout.column_row(c);
        for dy in -2..=2i64 {
            for dx in -2..=2i64 {
                if let Some(n) = self.layout.index(x + dx, y + dy) {
                    let cost = self.cost_of(n);
                    if cost != self.costs[n] {
                        self.costs[n] = cost;
                        self.changed.push(n);
                    }
                }
            }
        }
    }

    /// Takes what the local map shows into the memory.
    fn integrate(&mut self, map: &MapSnapshot) {
        self.stamp = self.stamp.wrapping_add(1);
        if self.stamp == 0 {
            self.hits.fill(0);
            self.near_hits.fill(0);
            self.graded.fill((0, 0));
            self.stamp = 1;
        }
        let same_grid = self.rough_of.as_ref().is_some_and(|(grid, origin)| {
            std::sync::Arc::ptr_eq(grid, &map.elevation) && *origin == self.layout.origin
        });
        if !same_grid {
            self.rough_epoch = self.rough_epoch.wrapping_add(1);
            if self.rough_epoch == 0 {
                self.rough.fill((0, 0));
                self.rough_epoch = 1;
            }
            self.rough_of = Some((map.elevation.clone(), self.layout.origin));
        }
        let s = map.patch_size_m;
        for patch in &map.patches {
            let (x, y) = ((patch.i as f64 + 0.5) * s, (patch.j as f64 + 0.5) * s);
            if let Some(c) = self.layout.cell_at(x, y) {
                if patch.is_obstacle() {
                    self.hits[c] = self.stamp;
                    // Seen from near, or from a distance not known (a map
                    // off the wire): certain.
                    let near = f64::from(patch.nearest_m);
                    if !near.is_finite() || near <= self.config.confirm_within_m {
                        self.near_hits[c] = self.stamp;
                    }
                } else {
                    // Graded ground: rough, as costly as its cost says; a
                    // suspected drop-off costs `suspect_cost` when set (see
                    // config/default.toml for what it does to which
                    // vehicle). Planned round like a flagged cell (infinite
                    // cost), no way would be left through a ditch suspected
                    // end to end.
                    let level = if patch.is_suspected_drop_off() && self.config.suspect_cost > 0.0 {
                        SUSPECTED_LEVEL
                    } else {
                        (f64::from(patch.cost) * f64::from(ROUGH_LEVELS)).round() as u8
                    };
                    let graded = &mut self.graded[c];
                    *graded = if graded.0 == self.stamp {
                        (self.stamp, graded.1.max(level))
                    } else {
                        (self.stamp, level)
                    };
                }
            }
        }
        let t = map.world_from_vehicle.translation.vector;
        let yaw = yaw_of(&map.world_from_vehicle).sin_cos();
        let cell = self.config.cell_m;
        // A cell follows the map only when wholly inside its window.
        let margin = self.layout.whole_cell_margin();
        let reach = self.window.radius_m();
        let (lo_x, hi_x) = (
            ((t.x - reach) / cell).floor(),
            ((t.x + reach) / cell).ceil(),
        );
        let (lo_y, hi_y) = (
            ((t.y - reach) / cell).floor(),
            ((t.y + reach) / cell).ceil(),
        );
        for j in lo_y as i64..=hi_y as i64 {
            for i in lo_x as i64..=hi_x as i64 {
                let (x, y) = ((i as f64 + 0.5) * cell, (j as f64 + 0.5) * cell);
                let Some(c) = self.layout.cell_at(x, y) else {
                    continue;
                };
                let hit = self.hits[c] == self.stamp;
                if self.in_window([t.x, t.y], yaw, [x, y], margin) {
                    // A shut cell opens again once all of it was seen:
                    // the ground that held the vehicle may be a corner of
                    // a cell whose centre was seen (see `shut_unseen_ahead`).
                    let seen = if self.state[c] == SHUT {
                        wholly_seen(map, x, y, cell)
                    } else {
                        map.seen.contains(floor_i64(x / s), floor_i64(y / s))
                    };
                    if hit {
                        let near = self.near_hits[c] == self.stamp;
                        let state = if near || self.state[c] == OBSTACLE {
                            OBSTACLE
                        } else {
                            DOUBTFUL
                        };
                        self.set_state(c, state);
                    } else if seen {
                        let graded = self.graded[c];
                        let graded = if graded.0 == self.stamp { graded.1 } else { 0 };
                        let state = if graded == SUSPECTED_LEVEL {
                            SUSPECT
                        } else {
                            let rough = &mut self.rough[c];
                            if rough.0 != self.rough_epoch {
                                *rough =
                                    (self.rough_epoch, roughness_level(&self.config, map, x, y));
                            }
                            match rough.1.max(graded) {
                                0 => FREE,
                                level => ROUGH + level - 1,
                            }
                        };
                        self.set_state(c, state);
                    }
                } else if hit {
                    self.set_state(c, OBSTACLE);
                }
            }
        }
    }

    /// Shuts the cells no image has seen within `shut_unseen_m` of the
    /// front of a vehicle at `position` heading `yaw` and within
    /// [`SHUT_HALF_ANGLE_DEG`] of its heading (seen from the front), and
    /// from them the unseen cells between seen ground
    /// ([`Route::between_seen`]) within `shut_along_m` of the front and
    /// [`SHUT_IN_VIEW_M`] inside the window: the shadow of a ledge runs
    /// along its edge, and shut only where the vehicle was held, the path
    /// would lead it to the next metres of the same edge, one backing-up
    /// at a time.
    fn shut_unseen_ahead(&mut self, map: &MapSnapshot, position: [f64; 2], yaw: f64) {
        let reach = self.config.shut_unseen_m;
        if reach <= 0.0 {
            return;
        }
        let margin = self.layout.whole_cell_margin();
        let (sin, cos) = yaw.sin_cos();
        let front = [
            position[0] + self.front_m * cos,
            position[1] + self.front_m * sin,
        ];
        let cell = self.config.cell_m;
        let min_cos = SHUT_HALF_ANGLE_DEG.to_radians().cos();
        let before = self.stats.shut_cells;
        let mut frontier = std::mem::take(&mut self.flood);
        frontier.clear();
        let mut partly_seen = Vec::new();
        let (lo_i, hi_i) = (
            floor_i64((front[0] - reach) / cell),
            ((front[0] + reach) / cell).ceil() as i64,
        );
        let (lo_j, hi_j) = (
            floor_i64((front[1] - reach) / cell),
            ((front[1] + reach) / cell).ceil() as i64,
        );
        for j in lo_j..=hi_j {
            for i in lo_i..=hi_i {
                let (x, y) = ((i as f64 + 0.5) * cell, (j as f64 + 0.5) * cell);
                let (dx, dy) = (x - front[0], y - front[1]);
                let distance = dx.hypot(dy);
                if distance > reach || dx * cos + dy * sin < distance * min_cos {
                    continue;
                }
                let Some(c) = self.layout.cell_at(x, y) else {
                    continue;
                };
                if self.state[c] == UNKNOWN {
                    self.shut(c);
                    frontier.push(c);
                } else if matches!(self.state[c], FREE | ROUGH..SUSPECT)
                    && self.in_window(position, (sin, cos), [x, y], margin)
                    && !wholly_seen(map, x, y, cell)
                {
                    partly_seen.push(c);
                }
            }
        }
        // Through the shadow, within `shut_along_m`.
        let along = self.config.shut_along_m.max(reach);
        while let Some(c) = frontier.pop() {
            let (x, y) = self.layout.column_row(c);
            for (dx, dy) in NEIGHBOURS {
                let Some(n) = self.layout.index(x + dx, y + dy) else {
                    continue;
                };
                let [cx, cy] = self.layout.centre(n);
                if self.state[n] == UNKNOWN
                    && self.in_window(position, (sin, cos), [cx, cy], SHUT_IN_VIEW_M)
                    && (cx - front[0]).hypot(cy - front[1]) <= along
                    && self.between_seen(n)
                {
                    self.shut(n);
                    frontier.push(n);
                }
            }
        }
        self.flood = frontier;
        // Gaps in the shut band: cells seen at their centre but not wholly
        // (obstacle avoidance holds the vehicle short of their unseen
        // part), between shut cells, are shut too, again and again as each
        // shut one narrows the gaps beside it, until none is left between.
        loop {
            let before = partly_seen.len();
            partly_seen.retain(|&c| {
                let gap = self.between(c, GAP_CELLS, |state| matches!(state, OBSTACLE | SHUT));
                if gap {
                    self.shut(c);
                }
                !gap
            });
            if partly_seen.len() == before {
                break;
            }
        }
        tracing::debug!(
            cells = self.stats.shut_cells - before,
            x = position[0],
            y = position[1],
            "route: backing up; unseen ground ahead shut until seen"
        );
    }

    fn shut(&mut self, c: usize) {
        self.set_state(c, SHUT);
        self.stats.shut_cells += 1;
    }

    /// Whether cell `c` lies between seen ground (or obstacles): seen
    /// cells within [`SHADOW_CELLS`] on both sides of it along a row, a
    /// column or a diagonal. A shadow beyond an edge has the near ground on
    /// one side and the ground it falls to on the other; ground that was
    /// never in view (round the end of a ledge) has seen ground on one side.
    fn between_seen(&self, c: usize) -> bool {
        self.between(c, SHADOW_CELLS, |state| !matches!(state, UNKNOWN | SHUT))
    }

    /// Whether cell `c` has cells whose state is `wanted` within `cells`
    /// on both sides of it along a row, a column or a diagonal.
    fn between(&self, c: usize, cells: i64, wanted: impl Fn(u8) -> bool) -> bool {
        let (x, y) = self.layout.column_row(c);
        let towards = |dx: i64, dy: i64| {
            (1..=cells).any(|k| {
                self.layout
                    .index(x + k * dx, y + k * dy)
                    .is_some_and(|n| wanted(self.state[n]))
            })
        };
        AXES.into_iter()
            .any(|(dx, dy)| towards(dx, dy) && towards(-dx, -dy))
    }

    /// Opens every shut cell again (unseen ground at `unseen_cost`): when
    /// they leave no way to the waypoint, the way may lie through them.
    fn reopen(&mut self) {
        let mut opened = 0;
        for c in 0..self.state.len() {
            if self.state[c] == SHUT {
                self.set_state(c, UNKNOWN);
                opened += 1;
            }
        }
        self.stats.reopened_cells += opened;
        tracing::debug!(
            cells = opened,
            "route: no way round the shut ground; opened again"
        );
    }

    /// Plans within the budget: whether a path was found, and whether the
    /// search ran to its end (a failure is then the answer, not the budget).
    fn plan(&mut self) -> (bool, bool) {
        let expanded = self.planner.stats.expansions;
        let found = self.planner.plan(&self.costs, self.config.max_expansions);
        let searched = self.planner.stats.expansions - expanded < self.config.max_expansions;
        (found, searched)
    }

    /// Gives up waypoint `index` at `position` (its memory cell `goal`) as
    /// unreachable, keeping the evidence: how much of the area the memory
    /// knows, and the ring of impassable cells round `closed`, the ground
    /// [`Route::closed_off`] found closed off.
    fn give_up(
        &mut self,
        (index, position, goal): (usize, [f64; 2], usize),
        since: Utime,
        now: Utime,
        vehicle_at: [f64; 2],
        closed: &[usize],
    ) {
        let cell_area = self.config.cell_m * self.config.cell_m;
        let inside = (0..self.state.len()).filter(|&c| !self.outside[c]);
        let (known, all) = inside.fold((0usize, 0usize), |(k, a), c| {
            (
                k + usize::from(!matches!(self.state[c], UNKNOWN | SHUT)),
                a + 1,
            )
        });
        let ring = self.ring_round(closed, goal);
        let skipped = self.unreachable.then == OnUnreachable::Skip;
        let within = if self.area.is_some() {
            "inside the operating area"
        } else {
            "through the ground around it"
        };
        tracing::warn!(
            waypoint = index,
            x = position[0],
            y = position[1],
            known_m2 = known as f64 * cell_area,
            ring_cells = ring.len(),
            skipped,
            "route: no route to the waypoint {within}"
        );
        self.no_routes.push(NoRoute {
            waypoint: index,
            position,
            since,
            decided: now,
            vehicle_at,
            known_m2: known as f64 * cell_area,
            area_m2: all as f64 * cell_area,
            ring,
            cell_m: self.config.cell_m,
            skipped,
        });
        self.tracker.give_up(self.unreachable.then);
        self.no_way_since = None;
        self.goal = None;
    }

    /// Of the vehicle's cell `start` and the goal's `goal`, the ground
    /// passable from the one with less of it, when that ground is closed
    /// off inside the memory: `None` when both reach the memory's edge
    /// where the area (or the world, with none) goes on beyond it — what
    /// lies there the planner cannot know, and no ring is proven.
    fn closed_off(&self, start: usize, goal: usize) -> Option<Vec<usize>> {
        let side = self.layout.side as i64;
        // A memory fixed over the whole area has no edge the area goes on
        // beyond.
        let open_edge = |cells: &[usize]| {
            self.fixed.is_none()
                && cells.iter().any(|&c| {
                    let (x, y) = self.layout.column_row(c);
                    x == 0 || y == 0 || x == side - 1 || y == side - 1
                })
        };
        let around_goal = self.passable_around(goal);
        let around_start = self.passable_around(start);
        let (small, large) = if around_goal.len() <= around_start.len() {
            (around_goal, around_start)
        } else {
            (around_start, around_goal)
        };
        if !open_edge(&small) {
            Some(small)
        } else if !open_edge(&large) {
            Some(large)
        } else {
            None
        }
    }

    /// The memory cells passable ground joins to cell `from` (8-connected;
    /// none when `from` itself is impassable).
    fn passable_around(&self, from: usize) -> Vec<usize> {
        let mut seen = vec![false; self.state.len()];
        let mut cells = Vec::new();
        if !self.costs[from].is_finite() {
            return cells;
        }
        seen[from] = true;
        cells.push(from);
        let mut next = 0;
        while let Some(&c) = cells.get(next) {
            next += 1;
            let (x, y) = self.layout.column_row(c);
            for (dx, dy) in NEIGHBOURS {
                if let Some(n) = self.layout.index(x + dx, y + dy)
                    && !seen[n]
                    && self.costs[n].is_finite()
                {
                    seen[n] = true;
                    cells.push(n);
                }
            }
        }
        cells
    }

    /// The centres of the impassable cells bordering `region` (or cell
    /// `lone` alone, when the region is empty: the waypoint's own cell is
    /// impassable).
    fn ring_round(&self, region: &[usize], lone: usize) -> Vec<[f64; 2]> {
        if region.is_empty() {
            return vec![self.layout.centre(lone)];
        }
        let mut ring = std::collections::BTreeSet::new();
        for &c in region {
            let (x, y) = self.layout.column_row(c);
            for (dx, dy) in NEIGHBOURS {
                if let Some(n) = self.layout.index(x + dx, y + dy)
                    && !self.costs[n].is_finite()
                {
                    ring.insert(n);
                }
            }
        }
        ring.into_iter().map(|c| self.layout.centre(c)).collect()
    }

    /// The memory cell to plan to for waypoint (x, y): its own, or where
    /// the line from the vehicle to it leaves the memory.
    fn goal_cell(&self, from: [f64; 2], to: [f64; 2]) -> Option<usize> {
        if let Some(c) = self.layout.cell_at(to[0], to[1]) {
            return Some(c);
        }
        let (i0, j0) = self.layout.origin?;
        let cell = self.config.cell_m;
        // The memory shrunk by a cell, in world metres.
        let lo = [(i0 as f64 + 1.0) * cell, (j0 as f64 + 1.0) * cell];
        let hi = [
            (i0 as f64 + self.layout.side as f64 - 1.0) * cell,
            (j0 as f64 + self.layout.side as f64 - 1.0) * cell,
        ];
        let d = [to[0] - from[0], to[1] - from[1]];
        let mut t = 1.0f64;
        for axis in 0..2 {
            if d[axis] > 0.0 {
                t = t.min((hi[axis] - from[axis]) / d[axis]);
            } else if d[axis] < 0.0 {
                t = t.min((lo[axis] - from[axis]) / d[axis]);
            }
        }
        self.layout.cell_at(from[0] + t * d[0], from[1] + t * d[1])
    }
}

impl Behaviour for Route {
    fn name(&self) -> &str {
        Self::NAME
    }

    fn vote(&mut self, ctx: &VoteContext<'_>, votes: &mut Votes) {
        self.aimed_at = None;
        let Some((index, waypoint)) = self.tracker.seek(ctx) else {
            votes.vote_speed(0.0);
            return;
        };
        let reach = self.aim_m;
        let target = [waypoint.x, waypoint.y];
        let position = ctx.pose.position();
        let here = [position.x, position.y];
        let moved = self.recentre(here[0], here[1]);
        self.changed.clear();
        self.integrate(ctx.map);
        let backing = ctx.last_command.is_some_and(|c| c.speed_mps < 0.0);
        // From the pose, not the last command: every executor votes on the
        // same poses, while when a command reaches the behaviours depends
        // on the executor (backing up starts from standing).
        if ctx.pose.velocity.norm() < STANDING_MPS {
            self.stood_at = Some(here);
        }
        if backing && !self.backing {
            self.shut_unseen_ahead(ctx.map, here, ctx.pose.yaw());
        }
        self.backing = backing;
        let (Some(start), Some(goal)) = (
            self.layout.cell_at(here[0], here[1]),
            match self.goal {
                Some((i, c)) if i == index && !moved => Some(c),
                _ => self.goal_cell(here, target),
            },
        ) else {
            self.aimed_at = Some((target, false));
            vote_towards(ctx, &self.response, target, reach, votes);
            return;
        };
        if moved || self.goal != Some((index, goal)) {
            self.goal = Some((index, goal));
            self.planner.reset(start, goal);
            self.held.clear();
        } else {
            self.planner.move_start(start);
            self.planner.cells_changed(&self.costs, &self.changed);
        }
        let (mut found, mut searched) = self.plan();
        // No path within the budget's reach (not cut short by it) while
        // shut cells stand: the way may lie through them.
        if !found && searched && self.state.contains(&SHUT) {
            self.changed.clear();
            self.reopen();
            self.planner.cells_changed(&self.costs, &self.changed);
            (found, searched) = self.plan();
        }
        if !found {
            self.stats.no_path_cycles += 1;
            if self.has_path || self.stats.no_path_cycles == 1 {
                tracing::warn!(
                    waypoint = index,
                    "route: no path to the waypoint through what the map has shown"
                );
            }
            self.has_path = false;
            self.held.clear();
            // Searched to the end: every way runs through ground known to
            // be impassable or out of the area. Lasting, that is the
            // answer; the vehicle gives the waypoint up.
            // (Whether a ring closes it off is asked once that has lasted:
            // the flood over the memory is not for every cycle.)
            if searched {
                let since = match self.no_way_since {
                    Some((i, since)) if i == index => since,
                    _ => ctx.utime,
                };
                self.no_way_since = Some((index, since));
                if ctx.utime - since >= seconds_to_micros(self.unreachable.after_s) {
                    if let Some(closed) = self.closed_off(start, goal) {
                        self.give_up((index, target, goal), since, ctx.utime, here, &closed);
                        if self.unreachable.then == OnUnreachable::Stop {
                            votes.vote_speed(0.0);
                            return;
                        }
                    } else {
                        // No ring inside the memory: the way may lie
                        // beyond it. Asked again as long after.
                        self.no_way_since = Some((index, ctx.utime));
                    }
                }
            }
            self.aimed_at = Some((target, false));
            vote_towards(ctx, &self.response, target, reach, votes);
            return;
        }
        self.no_way_since = None;
        self.has_path = true;
        self.hold_or_switch(start, here);
        // The point of the path `reach` from the vehicle.
        let carrot = if self
            .goal
            .is_some_and(|(_, c)| self.layout.cell_at(target[0], target[1]) == Some(c))
            && (target[0] - here[0]).hypot(target[1] - here[1]) <= reach
        {
            target
        } else if let Some(sighted) = self
            .config
            .sight_line
            .then(|| self.farthest_in_sight(here))
            .flatten()
            .filter(|p| (p[0] - here[0]).hypot(p[1] - here[1]) >= reach)
        {
            sighted
        } else {
            self.path
                .iter()
                .map(|&c| self.layout.centre(c))
                .find(|p| (p[0] - here[0]).hypot(p[1] - here[1]) >= reach)
                .or_else(|| self.path.last().map(|&c| self.layout.centre(c)))
                .unwrap_or(target)
        };
        self.aimed_at = Some((carrot, true));
        tracing::trace!(
            x = here[0],
            y = here[1],
            yaw_deg = ctx.pose.yaw().to_degrees(),
            aim_x = carrot[0],
            aim_y = carrot[1],
            "route: steering for the path's point"
        );
        vote_towards(ctx, &self.response, carrot, reach, votes);
    }

    /// The planned path (as far as [`OVERLAY_PATH_M`]), the point the vote
    /// steered for, and the memory's obstacles and shut ground.
    fn overlay(&self, pose: &arcnav_vehicle::Pose) -> Overlay {
        let mut overlay = Overlay::default();
        if self.layout.origin.is_none() {
            return overlay;
        }
        let p = pose.position();
        let yaw = pose.yaw();
        let (sin, cos) = yaw.sin_cos();
        let local = |[x, y]: [f64; 2]| {
            let (dx, dy) = (x - p.x, y - p.y);
            [cos * dx + sin * dy, -sin * dx + cos * dy]
        };
        if self.has_path {
            let cells = (OVERLAY_PATH_M / self.config.cell_m).ceil() as usize;
            let from = self.planner.start();
            let followed = self.held.iter().skip(self.held_at).take(cells);
            overlay.lines.push(OverlayLine {
                label: "route: planned path".to_owned(),
                points: std::iter::once(from)
                    .chain(followed.copied().filter(|&c| c != from))
                    .map(|c| local(self.layout.centre(c)))
                    .collect(),
            });
        }
        if let Some((at, on_path)) = self.aimed_at {
            overlay.points.push(OverlayPoint {
                label: if on_path {
                    "route: steering for (on the path)"
                } else {
                    "route: steering for the waypoint (no path)"
                }
                .to_owned(),
                at: local(at),
            });
        }
        for (state, label) in [
            (OBSTACLE, "route: obstacles remembered"),
            (DOUBTFUL, "route: obstacles seen only from afar (doubtful)"),
            (SHUT, "route: shut (unseen, backed away from)"),
        ] {
            let centres: Vec<[f64; 2]> = (0..self.state.len())
                .filter(|&c| self.state[c] == state)
                .map(|c| local(self.layout.centre(c)))
                .collect();
            if !centres.is_empty() {
                overlay.cells.push(OverlayCells {
                    label: label.to_owned(),
                    size_m: self.config.cell_m,
                    yaw: -yaw,
                    centres,
                });
            }
        }
        overlay
    }

    fn reset(&mut self) {
        self.aimed_at = None;
        self.no_way_since = None;
        self.held.clear();
        self.stood_at = None;
        self.tracker.reset();
        self.layout.origin = None;
        self.goal = None;
        self.state.fill(UNKNOWN);
        self.has_path = false;
        self.backing = false;
    }

    fn progress(&self) -> Option<Progress> {
        Some(self.tracker.progress())
    }

    fn no_routes(&self) -> &[NoRoute] {
        &self.no_routes
    }

    fn counters(&self) -> Vec<(&'static str, u64)> {
        let planner = &self.planner.stats;
        vec![
            ("plans", planner.plans),
            ("replans", planner.replans),
            ("expansions", planner.expansions),
            ("recentres", self.stats.recentres),
            ("no_path_cycles", self.stats.no_path_cycles),
            ("unreachable", self.no_routes.len() as u64),
            ("shut_cells", self.stats.shut_cells),
            ("reopened_cells", self.stats.reopened_cells),
            ("held_cycles", self.stats.held_cycles),
            ("path_switches", self.stats.path_switches),
        ]
    }
}

impl Plugin for Route {
    const NAME: &'static str = "route";
    type Config = RouteConfig;

    fn validate(c: &Self::Config, _setup: &Setup<'_>) -> Result<(), ConfigError> {
        c.validate()
    }

    fn build(config: Self::Config, setup: &Setup<'_>) -> Self {
        Self::new(config, setup)
    }
}

/// The memory's side in cells, and its fixed origin when it covers the
/// operating area: with an area whose bounding box (and a cell beyond it)
/// fits in [`MAX_AREA_CELLS`] a side, the memory lies over all of it for
/// the whole mission, so that a way round a barrier is never cut off by
/// the memory's edge; else `size_m` around the vehicle, re-centred.
fn memory_over(config: &RouteConfig, area: Option<&Area>) -> (usize, Option<(i64, i64)>) {
    let side = (config.size_m / config.cell_m).round() as usize;
    let Some(area) = area else {
        return (side, None);
    };
    let cell = config.cell_m;
    let (lo, hi) = area.bounds();
    let (i0, j0) = (floor_i64(lo[0] / cell) - 1, floor_i64(lo[1] / cell) - 1);
    let (i1, j1) = (floor_i64(hi[0] / cell) + 1, floor_i64(hi[1] / cell) + 1);
    let needed = usize::try_from((i1 - i0).max(j1 - j0) + 1).unwrap_or(usize::MAX);
    if needed > MAX_AREA_CELLS {
        return (side, None);
    }
    (needed.max(side.min(MAX_AREA_CELLS)), Some((i0, j0)))
}
