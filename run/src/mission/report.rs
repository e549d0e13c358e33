//! What a mission produced: its outcome, `report.json`'s statistics, the
//! driven track and the ground the local map held, for the summary and
//! the pictures.

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use arcnav_arbiter::RecoveryStats;
use arcnav_config::SpeedBound;
use arcnav_perception::Reasons;
use arcnav_pipeline::StageTimes;
use arcnav_sim::Collision;
use arcnav_vehicle::Utime;
use serde::Serialize;

/// How it ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Outcome {
    Completed,
    Collision,
    Timeout,
    Stuck,
    /// A required behaviour can no longer vote (an external program that
    /// ended): the vehicle would stand for good.
    BehaviourFailed,
    /// A waypoint no route reaches inside the operating area
    /// (`[mission] on_unreachable = "stop"`).
    Unreachable,
}

/// A waypoint no route reached, and why the route said so.
#[derive(Debug, Clone, Serialize)]
pub struct NoRouteReport {
    /// The waypoint, counted from 1, and where it is, m.
    pub waypoint: usize,
    pub position: [f64; 2],
    /// Mission time at which the planner first found no way, and at which
    /// it gave the waypoint up, s.
    pub no_way_since_s: f64,
    pub given_up_at_s: f64,
    /// Where the vehicle was then, m.
    pub vehicle_at: [f64; 2],
    /// Ground of the operating area in the planner's memory that images
    /// had shown, and all of it there, m².
    pub known_m2: f64,
    pub area_m2: f64,
    /// Impassable memory cells in the ring that closed it off.
    pub ring_cells: usize,
    /// Whether the mission went on to the next waypoint.
    pub skipped: bool,
}

/// Progress, reported about once per simulated second.
#[derive(Debug, Clone, Copy)]
pub struct MissionProgress {
    pub sim_time_s: f64,
    pub distance_m: f64,
    pub waypoint: usize,
    pub waypoints: usize,
    pub speed_mps: f64,
    pub time_limit_s: f64,
}

/// Mission statistics (`report.json`).
#[derive(Debug, Clone, Serialize)]
pub struct MissionReport {
    pub world: String,
    pub sensor: String,
    pub outcome: Outcome,
    /// True only when the mission completed with zero collisions.
    pub success: bool,
    pub waypoints_reached: usize,
    pub waypoints: usize,
    /// Waypoints given up as unreachable (`on_unreachable = "skip"`).
    pub waypoints_skipped: usize,
    /// The waypoints found unreachable, with the evidence.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub unreachable: Vec<NoRouteReport>,
    /// The operating area the vehicle kept to (`[mission] area`), world
    /// frame, m; absent when it had none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub area: Option<Vec<[f64; 2]>>,
    pub distance_m: f64,
    pub duration_s: f64,
    pub average_speed_mps: f64,
    pub max_speed_mps: f64,
    /// The cruise speed the arbiter drove at: the one asked for
    /// (`arbiter.cruise_speed_mps`), held to the hole speed cap, m/s.
    pub cruise_mps: f64,
    /// The cruise speed asked for, `arbiter.cruise_speed_mps`, m/s.
    pub cruise_asked_mps: f64,
    /// The hole speed cap (`[lookahead] hole_speed_cap`), when it applies, m/s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cruise_cap_mps: Option<f64>,
    pub images: u64,
    pub images_dropped: u64,
    /// The defect injected into the pipeline on purpose (`[pipeline]
    /// fault`) and what it did; absent when there is none.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fault: Option<FaultReport>,
    /// What the guard did (`[guard]`); absent when it is off.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub guard: Option<super::GuardReport>,
    /// Images sent in slices (`sim.slice_lines`): what perception did
    /// with them (slices, steps, lines lost). Absent for whole images.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub slices: Option<arcnav_pipeline::SliceCounts>,
    /// Images of different sensors judged together in one height map
    /// (`perception.fuse_within_s`); absent when it is 0.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fused: Option<arcnav_pipeline::FusionCounts>,
    /// Untraversable cells perception reported, summed over the images,
    /// per reason (a cell with two reasons counts in both).
    pub untraversable_cells: BTreeMap<&'static str, u64>,
    /// Graded cells (cost below 1) perception reported, summed over the images.
    pub graded_cells: u64,
    /// Of those, suspected drop-offs (`[perception.drop_off] suspect_cost`).
    pub suspected_drop_offs: u64,
    /// Near edges of holes the evidence over images
    /// (`[perception.evidence]`) suspected, summed over the images: cells
    /// reported as suspected drop-offs besides the evaluator's.
    pub evidence_suspected: u64,
    pub collisions: Vec<Collision>,
    /// Smallest gap between the footprint and a true hazard, m.
    pub closest_approach_m: Option<f64>,
    /// When (s from the start), where and to what that gap was: `arcnav
    /// render mission.lcm --at S` draws the decision of that moment.
    pub closest_approach: Option<NearMissReport>,
    /// Each hole and ditch the wheels do not bridge (ground truth), with
    /// the range from the sensor at which perception first flagged or
    /// suspected it (see [`super::first_seen`]).
    pub drops_first_seen: Vec<super::first_seen::DropFirstSeen>,
    pub stops: StopStats,
    /// What the ground did to the vehicle (ground truth): peak roll and
    /// pitch, vertical acceleration of the body.
    pub ride: arcnav_sim::RideReport,
    /// Backing up when blocked.
    pub recovery: RecoveryStats,
    /// Counters behaviours keep (the route planner's plans and re-plans),
    /// by behaviour.
    pub behaviour_counters: BTreeMap<String, BTreeMap<&'static str, u64>>,
    /// Behaviours that could no longer vote, by name, with why (an
    /// external program that exited, hung or wrote garbage).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub behaviour_faults: BTreeMap<String, String>,
    /// Mean |change of curvature| between consecutive commands, 1/m: how
    /// much the vehicle weaves.
    pub steering_activity: f64,
    pub map_resets: u64,
    /// What the local map did with the reports: patches made, confirmed,
    /// pruned by newer images, misses not counted because the image looked
    /// from too far (`miss_range_factor`), cleared under the vehicle.
    pub localmap: arcnav_localmap::MapStats,
    pub stage_times: StageTimes,
    /// Rendering range images (simulator, not pipeline), ms per image.
    pub render_ms_mean: f64,
    /// Images rendered ahead, while the pipeline worked on the one before
    /// (see `mission::ahead`), and those rendered ahead in vain (the vehicle
    /// was elsewhere when they were due) and rendered again.
    pub images_rendered_ahead: u64,
    pub images_rendered_again: u64,
    pub wall_time_s: f64,
    pub realtime_factor: f64,
    /// The speed this configuration allows (002 §7: sensor rate and
    /// resolution, latency, braking, turning radius; see
    /// [`crate::speed_bound`]), and the average speed as a fraction of it.
    pub speed_bound: SpeedBound,
    pub speed_fraction_of_bound: f64,
    /// Seconds driving, by the limit that set the speed (cruise, vehicle,
    /// a speed vote by its cause: free distance, verified distance,
    /// terrain, suspected drop-off; lateral, weak vote, reverse): what held
    /// the average down.
    pub speed_limited_by_s: BTreeMap<&'static str, f64>,
    /// How far the ground was verified along the arc driven forwards,
    /// over the decisions: the least and the median, m (none when no
    /// behaviour said).
    pub verified_distance_m: Option<VerifiedDistanceReport>,
    /// Stretches of image columns the hole evidence left unverified
    /// (reported as shadows: ground not seen), summed over the images.
    pub evidence_unverified: u64,
}

/// The verified distance over a run.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct VerifiedDistanceReport {
    pub min: f64,
    pub median: f64,
    /// Decisions counted.
    pub decisions: u64,
}

/// The moment of the closest approach.
#[derive(Debug, Clone, Serialize)]
pub struct NearMissReport {
    /// Seconds from the mission's start.
    pub at_s: f64,
    /// Vehicle origin, world frame, m.
    pub position: [f64; 2],
    pub hazard: String,
}

/// Stop commands during the mission.
#[derive(Debug, Clone, Default, Serialize)]
pub struct StopStats {
    pub stop_commands: u64,
    /// Runs of consecutive stop commands.
    pub episodes: u64,
    pub no_votes: u64,
    pub required_stale: u64,
    pub all_arcs_forbidden: u64,
    pub no_acceptable_arc: u64,
    /// Stops after recoveries were used up.
    pub stuck: u64,
    /// Seconds standing, by why.
    pub stopped_s: BTreeMap<&'static str, f64>,
}

/// A point of the driven path.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct TrackPoint {
    pub utime: Utime,
    pub x: f64,
    pub y: f64,
    pub speed_mps: f64,
    /// The speed governor set the speed commanded last.
    pub governed: bool,
}

/// Where a vehicle turned in place (a skid-steer vehicle's turn round).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TurnInPlaceMark {
    /// Where it began, world frame, m.
    pub x: f64,
    pub y: f64,
    /// The first command of the turn.
    pub utime: Utime,
    /// Heading turned, degrees, + left.
    pub turned_deg: f64,
}

/// Everything a mission produced.
#[derive(Debug, Clone)]
pub struct MissionRun {
    pub report: MissionReport,
    pub track: Vec<TrackPoint>,
    /// Where the vehicle turned in place.
    pub turns_in_place: Vec<TurnInPlaceMark>,
    /// Where images were taken.
    pub image_positions: Vec<[f64; 2]>,
    /// World patches that were ever in the local map (i, j), with the
    /// union of their reasons, and the patch size.
    /// ... and the highest cost they had (below 1: graded ground).
    pub obstacle_patches: BTreeMap<(i64, i64), (Reasons, f32)>,
    /// World patches whose ground some image observed during the mission.
    pub seen_patches: BTreeSet<(i64, i64)>,
    pub patch_size_m: f64,
    pub snapshots: Vec<PathBuf>,
    /// The waypoints no route reached, with the rings that closed them off.
    pub no_routes: Vec<arcnav_behaviours::NoRoute>,
}

/// A fault injected into the pipeline (`report.json`'s `fault`).
#[derive(Debug, Clone, Serialize)]
pub struct FaultReport {
    /// `[pipeline] fault`.
    pub fault: &'static str,
    /// It began this long after the first pose, s.
    pub after_s: f64,
    #[serde(flatten)]
    pub counts: arcnav_pipeline::FaultCounts,
}
