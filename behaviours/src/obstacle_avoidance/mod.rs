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
//! height as an obstacle), and ground seen only between rows of returns
//! farther apart than the wheels bridge is not seen either: a hole may
//! hide there (perception reports such stretches, unless its hole
//! evidence has since verified them, as shadows; issue 63). How far an
//! arc's footprint runs over seen ground before it meets any is the
//! arc's *verified distance*. `unseen_ground` sets what the rest is:
//! - `slow` (default), the speed governor: each arc's speed is limited so
//!   that the vehicle can stop `stop_margin_m` short of the ground not
//!   seen along it, braking as hard as it can (`a` the vehicle's
//!   `max_deceleration_mps2`, not the `braking_fraction` of it kept for
//!   cells known to be there): `v·t + v²/2a = verified − stop_margin_m`
//!   (what `arcnav_config::speed_bound` reasons for one image). An arc
//!   whose unseen ground lies closer than the vehicle, braking as hard as
//!   it can from the speed it has, would stop in is forbidden: turning
//!   onto it, its limit would come too late;
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
//! **The operating area** (`[mission] area`): an arc along which the
//! body leaves the area meets its edge as it would a cell (a veto within
//! `min_distance_m`, cause the area's edge), and backing up is clear only
//! as far as the edge (`area::AreaEdge`).
//!
//! **Creeping forwards**: each arc's distance to its first collision, cell
//! within the widest near-miss band inside `reverse_margin_m` (0.25 m) of
//! the body, or unseen ground, however close, also goes out with the votes
//! ([`Votes::set_forward_clearance`]). `min_distance_m` vetoes arcs for
//! driving at speed; a turning manoeuvre's short legs at a crawl may still
//! take them as far as they are clear, keeping beside the body about the
//! room backing up keeps (clear to the body itself, a retrace's forward run
//! brought a corner 0.2 m from a bank's side).

use arcnav_arbiter::{SpeedCause, VetoCause, Votes};
use arcnav_vehicle::config::ConfigError;
use arcnav_vehicle::footprint::Outline;
use arcnav_vehicle::{Arc, ArcPose, DrivenPath, Footprint, SteeringResponse};
use nalgebra::Point2;

use crate::behaviour::{Behaviour, Plugin, Setup, VoteContext};
use crate::terrain::{ArcTerrain, TerrainCheck};

mod area;
mod backing;
pub mod config;
mod raster;
mod turning;
mod under_start;

use area::AreaEdge;
use backing::Reverse;
pub use config::{ObstacleAvoidanceConfig, UnseenGround};
use raster::{
    Raster, Rigid, Template, build_template, cells_inside, first_in, first_set, grid_around,
    nearest_set,
};
use turning::Turning;
use under_start::UnderStart;

/// The obstacle-avoidance behaviour.
#[derive(Debug, Clone)]
pub struct ObstacleAvoidance {
    config: ObstacleAvoidanceConfig,
    ahead: Raster,
    templates: Vec<Template>,
    /// Margin of band b (0 for the footprint itself).
    margins: Vec<f64>,
    /// The footprint widened by each band's margin, its outline (the lead
    /// of a path places them at each of its poses, every cycle).
    band_outlines: Vec<Outline>,
    /// How far from the rear axle the widest band's footprint reaches (its
    /// bounding box's corner), m.
    widest_reach: f64,
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
    /// The same poses, their sines and cosines taken.
    lead: Vec<(f64, Rigid)>,
    /// Cells under the footprint where the vehicle stands.
    under_start: UnderStart,
    /// Scratch: the map patches a path's arc may reach this cycle.
    near: Vec<u32>,
    /// This cycle: distance from the rear axle to the nearest cell of each
    /// [`Layer`] of the vehicle-frame raster, m (∞ when it has none).
    nearest: [f64; 4],
    /// The operating area's edge, when the mission has an area.
    area: Option<AreaEdge>,
    /// Per arc: where its body first leaves the area (distance along,
    /// vehicle-frame point).
    area_exit: Vec<Option<(f64, [f32; 2])>>,
    /// The turns in place' sweeps, when the arc set has them.
    turning: Option<Turning>,
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
        let footprint = body.grown(half_patch, 0.0, half_patch);
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
        let wheels = footprint.clipped(footprint.x_min, setup.vehicle.wheelbase_m.min(body.x_max));
        let ahead = Raster::new(grid, 1.0, |p| wheels.contains(p));
        let reverse = (config.reverse_reach_m > 0.0).then(|| {
            // The body mirrored (x -> -x), grown behind and to the sides:
            // backing up, what lies ahead of the front bumper stays there.
            let mirrored = body.grown(0.0, half_patch, half_patch).mirrored();
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
            let standing = body.grown(half_patch, half_patch, half_patch);
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
            standing: wheels,
            response: setup.steering_response(),
            paths: setup
                .arcs
                .curvatures()
                .iter()
                .map(|&k| DrivenPath::arc(k))
                .collect(),
            shifted,
            lead_poses: Vec::new(),
            lead: Vec::new(),
            under_start: UnderStart::default(),
            near: Vec::new(),
            nearest: [f64::INFINITY; 4],
            area: setup.area.map(|a| AreaEdge::new(a.clone(), &body)),
            area_exit: vec![None; setup.arcs.len()],
            turning: setup
                .arcs
                .turns_in_place()
                .then(|| Turning::new(setup.vehicle, half_patch, config.reverse_margin_m)),
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
            band_outlines: margins
                .iter()
                .map(|&m| footprint.widened(m).outline())
                .collect(),
            widest_reach: {
                let body = footprint.widened(margins[margins.len() - 1]);
                body.x_max.max(-body.x_min).hypot(body.half_width)
            },
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
            self.lead.clear();
            self.lead
                .extend(self.lead_poses.iter().map(|(s, p)| (*s, Rigid::of(p))));
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
                let (ahead, standing) = (&self.ahead, &self.standing);
                let seen = ctx.map.seen_lookup();
                self.shifted
                    .unseen_over(&template.bands[widest], rest as f32, |c| {
                        ahead.unseen_or_beyond(to_vehicle(c), &seen, standing)
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
                self.first_unseen_on_body(template, rest, to_vehicle, ctx.map.seen_lookup())
                    .map(|(s, q)| (f64::from(s) + lead, [q.x as f32, q.y as f32]))
            };
        }
        met.and(part)
    }

    /// The first ground no image has seen along the body's band of
    /// `template` within `rest`, the band placed by `to_vehicle` (from the
    /// frame where a path settles on its arc): its distance along the band
    /// and where it lies (vehicle frame). Cell by cell, nearest first, a
    /// run of cells at a time: a run whose box lies on the vehicle-frame
    /// grid over no unseen cell has none.
    fn first_unseen_on_body(
        &self,
        template: &Template,
        rest: f32,
        to_vehicle: impl Fn(Point2<f64>) -> Point2<f64>,
        seen: impl Fn(f64, f64) -> bool,
    ) -> Option<(f32, Point2<f64>)> {
        let ahead = &self.ahead;
        let mut start = 0;
        for &(end, [x0, y0, x1, y1]) in &template.body_runs {
            if template.body.get(start).is_none_or(|(s, _)| *s > rest) {
                return None;
            }
            let (lo, hi) = raster::bounds(
                [(x0, y0), (x1, y0), (x0, y1), (x1, y1)]
                    .into_iter()
                    .map(|(x, y)| to_vehicle(Point2::new(x, y))),
            );
            let clear = ahead
                .grid
                .cover(lo, hi)
                .is_some_and(|cover| cover.whole && !ahead.grid.any_set(&ahead.unseen, &cover));
            if !clear {
                let found = template.body[start..end]
                    .iter()
                    .take_while(|(s, _)| *s <= rest)
                    .find_map(|&(s, [x, y])| {
                        let q = to_vehicle(Point2::new(f64::from(x), f64::from(y)));
                        ahead
                            .unseen_or_beyond(q, &seen, &self.standing)
                            .then_some((s, q))
                    });
                if found.is_some() {
                    return found;
                }
            }
            start = end;
        }
        None
    }

    /// What the path meets before it settles on its arc (`lead_poses`):
    /// the footprint at each pose on the map as it is.
    fn meet_lead(&self, ctx: &VoteContext<'_>, horizon: f64) -> Met {
        let raster = &self.ahead;
        let grid = &raster.grid;
        let widest = self.margins.len() - 1;
        let corners = |pose: &Rigid, band: usize| self.band_outlines[band].map(|c| pose.apply(c));
        // The first cell of `layer` under the footprint of `band` at `pose`.
        let under = |pose: &Rigid, band: usize, layer: &[u64]| {
            let corners = corners(pose, band);
            if !grid.may_hold(layer, &corners) {
                return None;
            }
            let mut found = None;
            cells_inside(grid, &corners, |row, from, to| {
                found = first_set(layer, grid, row, from, to).map(|column| (row, column));
                found.is_some()
            });
            found
        };
        let poses = &self.lead;
        let blocked = raster.blocked();
        let mut met = Met::default();
        // How far from the rear axle the footprints of this lead reach: a
        // layer with nothing that near has nothing to meet.
        let lead = poses.last().map_or(0.0, |(s, _)| *s);
        let within = lead + self.widest_reach + grid.resolution;
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
                let corners = corners(p, 0);
                if !grid.may_hold(&raster.graded, &corners) {
                    continue;
                }
                cells_inside(grid, &corners, |row, from, to| {
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

    /// The cells under the footprint and the ground each of the first
    /// `arcs` paths crosses within `horizon`: arcs taken at once by their
    /// precomputed poses, driven paths by theirs.
    fn judge_ground(&mut self, ctx: &VoteContext<'_>, horizon: f64, arcs: usize) {
        let max = self.config.max_distance_m;
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
    }

    /// Each arc's vote from what its sweep meets and the ground it crosses:
    /// vetoed or graded by the nearest collision, else by how close it
    /// passes and how hard the ground is.
    fn vote_arcs(&mut self, ctx: &VoteContext<'_>, horizon: f64, arcs: usize, votes: &mut Votes) {
        let (min, max) = (self.config.min_distance_m, self.config.max_distance_m);
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
            }
            .map(|(d, cell)| (d, cell.map(VetoCause::Cell)));
            // ... or the operating area's edge, if nearer still.
            let edge = self.area_exit[arc].map(|(d, at)| (d, Some(VetoCause::AreaEdge(at))));
            if let Some((distance, cause)) = nearer(collision, edge) {
                self.free[arc] = distance;
                if distance < min {
                    votes.veto_for(arc, cause);
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
    }

    /// Each arc's speed limit: the vehicle stops in time before what it
    /// meets, slows on hard ground and before suspected drop-offs.
    fn vote_speeds(&self, ctx: &VoteContext<'_>, arcs: usize, votes: &mut Votes) {
        let cruise = self.cruise_mps;
        let max = self.config.max_distance_m;
        // Per arc, the speed at which the vehicle stops in time on it:
        // v·t + v²/2a = room, solved for v.
        let t = self.config.reaction_s;
        let stopping_at =
            |a: f64, t: f64, room: f64| -a * t + ((a * t).powi(2) + 2.0 * a * room.max(0.0)).sqrt();
        let stopping_speed = |room: f64| stopping_at(self.deceleration, t, room);
        // How far the vehicle runs before it stands, braking as hard as it
        // can from its speed now.
        let speed = ctx.pose.velocity.norm();
        let braking = speed * t + speed * speed / (2.0 * self.max_deceleration);
        // A suspected drop-off is flagged for certain, if it is a hole, once
        // the front is `hole_seen_within_m` from it: an arc towards one is
        // driven no faster than the vehicle stops short of it, and never
        // slower than it stops within that distance (by then a hole would
        // be a cell, and an edge still suspected is none). A hole that may
        // be there, as unverified ground: braking as hard as it can.
        let margin = self.config.stop_margin_m;
        // (0, never derived from a pipeline: `reaction_s`.)
        let governor_t = match self.config.governor_reaction_s {
            0.0 => t,
            given => given,
        };
        let possible_hole = |room: f64| stopping_at(self.max_deceleration, governor_t, room);
        let hole_speed = possible_hole(self.config.hole_seen_within_m - margin);
        for arc in 0..arcs {
            if votes.is_vetoed(arc) {
                continue;
            }
            let room = self.free[arc].min(max) - self.config.stop_margin_m;
            // The governor: stop `stop_margin_m` before the first unseen
            // ground the footprint meets (its patch may begin past the
            // edge), braking as hard as the vehicle can (a hole may hide
            // there, or may not: `braking_fraction` is the margin kept for
            // what is known to be there). An arc the vehicle can no longer
            // stop on before it, at the speed it has, is forbidden: its
            // speed limit would come too late.
            let verified = match self.unseen_at[arc] {
                Some((distance, at)) if distance < braking => {
                    votes.veto(arc, Some(at));
                    continue;
                }
                Some((distance, _)) => {
                    votes.set_verified_distance(arc, distance);
                    possible_hole(distance - margin)
                }
                None => {
                    votes.set_verified_distance(arc, max);
                    f64::INFINITY
                }
            };
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
                possible_hole(distance - margin).max(hole_speed)
            });
            let (speed, cause) = [
                (stopping_speed(room), SpeedCause::FreeDistance),
                (verified, SpeedCause::VerifiedDistance),
                (terrain, SpeedCause::Terrain),
                (suspect, SpeedCause::SuspectedDropOff),
            ]
            .into_iter()
            .fold((f64::INFINITY, SpeedCause::NotSaid), |best, c| {
                if c.0 < best.0 { c } else { best }
            });
            votes.limit_arc_speed_for(arc, speed, cause);
        }
    }

    /// Each arc's clearance backing up ([`Reverse::vote`]), no farther
    /// than the operating area's edge.
    fn vote_reverse(&mut self, ctx: &VoteContext<'_>, votes: &mut Votes) {
        let reach = self.config.reverse_reach_m;
        if let Some(reverse) = &mut self.reverse {
            reverse.vote(&mut self.terrain, reach, ctx, votes);
            if let Some(area) = self
                .area
                .as_mut()
                .filter(|a| !a.far_inside(ctx.pose, reach))
            {
                for (arc, &k) in ctx.arcs.curvatures().iter().enumerate().take(votes.len()) {
                    if let (Some(edge), Some(clear)) = (
                        area.backing(ctx.pose, k, reach),
                        votes.reverse_clearance(arc),
                    ) {
                        votes.set_reverse_clearance(arc, clear.min(edge));
                    }
                }
            }
        }
    }
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
        let max = self.config.max_distance_m;
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
        self.judge_ground(ctx, horizon, arcs);
        if let Some(area) = &mut self.area {
            area.forward(
                ctx.pose,
                &self.paths[..arcs],
                max,
                &mut self.area_exit[..arcs],
            );
        }
        self.vote_arcs(ctx, horizon, arcs, votes);
        // How far each arc is clear at a crawl: to the first collision,
        // cell within the crawl band or unseen ground, however close (a
        // turning manoeuvre's leg).
        for arc in 0..arcs {
            let unseen = self.unseen_at[arc].map_or(f64::INFINITY, |(s, _)| s);
            let clear = self.free[arc].min(self.crawl_free[arc]).min(unseen);
            votes.set_forward_clearance(arc, clear.min(max));
        }
        if self.config.speed_vote {
            self.vote_speeds(ctx, arcs, votes);
        }
        if let Some(turning) = &self.turning {
            turning.vote(ctx, votes);
        }
    }
}

impl Plugin for ObstacleAvoidance {
    const NAME: &'static str = "obstacle_avoidance";
    type Config = ObstacleAvoidanceConfig;

    fn validate(c: &Self::Config, setup: &Setup<'_>) -> Result<(), ConfigError> {
        c.validate(setup)
    }

    fn build(config: Self::Config, setup: &Setup<'_>) -> Self {
        Self::new(config, setup)
    }
}
