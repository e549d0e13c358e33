//! The behaviour trait, what a behaviour sees, and the trait that lets the
//! registry build one from its configuration.

use arcnav_arbiter::Votes;
use arcnav_localmap::{LocalMapConfig, MapSnapshot};
use arcnav_vehicle::mission::{Area, WhenUnreachable};
use arcnav_vehicle::{
    ArcSet, ConfigError, Pose, Steering, SteeringCommand, SteeringResponse, Utime, VehicleConfig,
};
use serde::Serialize;
use serde::de::DeserializeOwned;

/// A point to reach, world frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Waypoint {
    pub x: f64,
    pub y: f64,
    /// Arrival radius, m; `None` uses the goal-seeking default.
    pub radius_m: Option<f64>,
}

/// The waypoints to reach, in order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Mission {
    /// Changes whenever the list changes (the `utime` of its message).
    pub version: Utime,
    pub waypoints: Vec<Waypoint>,
}

/// Everything a behaviour may look at when it votes.
#[derive(Debug, Clone, Copy)]
pub struct VoteContext<'a> {
    /// Time of the vote.
    pub utime: Utime,
    /// The vehicle now.
    pub pose: &'a Pose,
    /// The local map in the vehicle frame of `pose`.
    pub map: &'a MapSnapshot,
    pub mission: &'a Mission,
    /// The arcs to vote over; votes are in this set's index order.
    pub arcs: &'a ArcSet,
    /// The last command the arbiter sent, if any.
    pub last_command: Option<&'a SteeringCommand>,
}

impl<'a> VoteContext<'a> {
    /// What a behaviour sees at `utime` with no command sent yet (executors
    /// build it in `arcnav_pipeline::BehaviourSet`, tests here).
    pub fn new(
        utime: Utime,
        pose: &'a Pose,
        map: &'a MapSnapshot,
        mission: &'a Mission,
        arcs: &'a ArcSet,
    ) -> Self {
        Self {
            utime,
            pose,
            map,
            mission,
            arcs,
            last_command: None,
        }
    }
}

impl VoteContext<'_> {
    /// How the vehicle steers as this vote is taken: its speed forwards
    /// (0 backing up), the curvature it drives (yaw rate over speed when
    /// it moves faster than 0.5 m/s; the last command's otherwise) and
    /// the command on its way, which it steers towards until a new one
    /// takes effect. With [`DrivenPath`](arcnav_vehicle::DrivenPath), the
    /// path each arc's command would really put the vehicle on.
    pub fn steering(&self) -> Steering {
        Steering::of(self.pose, self.last_command.map(|c| c.curvature))
    }
}

/// What a behaviour is built with, besides its own TOML table.
#[derive(Debug, Clone, Copy)]
pub struct Setup<'a> {
    pub arcs: &'a ArcSet,
    pub vehicle: &'a VehicleConfig,
    /// The local map: its window, and its patches' side (a patch is a
    /// square, its position its centre).
    pub localmap: &'a LocalMapConfig,
    /// The static occupancy map of the area, if one was given
    /// (`[localmap.occupancy]`): known before any image shows it.
    pub statics: Option<&'a std::sync::Arc<arcnav_localmap::StaticMap>>,
    /// The speed the arbiter drives at when nothing asks for less, m/s
    /// (`arbiter.cruise_speed_mps`): speed limits given as a fraction of it
    /// (terrain speed) use it.
    pub cruise_mps: f64,
    /// The operating area (`[mission] area`), if the vehicle has one: the
    /// route plans inside it, obstacle avoidance vetoes arcs that leave it.
    pub area: Option<&'a Area>,
    /// When a waypoint no route reaches is given up on, and what follows.
    pub unreachable: WhenUnreachable,
}

impl Setup<'_> {
    /// How the vehicle answers a command, as behaviours judge arcs: its
    /// latency and steering rate when `[arcs] driven_paths` is on (each
    /// arc judged along the [`DrivenPath`](arcnav_vehicle::DrivenPath) the
    /// vehicle drives onto it), taking each arc at once otherwise.
    pub fn steering_response(&self) -> SteeringResponse {
        if self.arcs.driven_paths() {
            SteeringResponse::of(self.vehicle)
        } else {
            SteeringResponse::immediate()
        }
    }
}

/// How far a mission has come.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Progress {
    /// Index of the waypoint being sought (== `waypoints` when complete).
    pub current: usize,
    pub waypoints: usize,
    pub complete: bool,
    /// Waypoints given up as unreachable (`on_unreachable = "skip"`).
    pub skipped: usize,
    /// The waypoint being sought has no route and the mission stops there
    /// (`on_unreachable = "stop"`): the behaviour votes to stand.
    pub unreachable: bool,
}

/// A waypoint no route reached, and the evidence: the planner searched all
/// of the operating area it knows and every way to the waypoint ran
/// through ground known to be impassable (or beyond the area's edge).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct NoRoute {
    /// Index of the waypoint (from 0) and where it is, world frame, m.
    pub waypoint: usize,
    pub position: [f64; 2],
    /// When the planner first found no way, and when that had lasted
    /// `unreachable_after_s` (the decision), µs.
    pub since: Utime,
    pub decided: Utime,
    /// Where the vehicle was when the planner last found no way, m.
    pub vehicle_at: [f64; 2],
    /// Ground of the operating area within the planner's memory that
    /// images have shown, and all of it there, m².
    pub known_m2: f64,
    pub area_m2: f64,
    /// Centres of the impassable cells that close the waypoint off (or the
    /// vehicle in), world frame, m: the ring the planner could not cross.
    pub ring: Vec<[f64; 2]>,
    /// Side of those cells, m.
    pub cell_m: f64,
    /// Whether the mission went on to the next waypoint.
    pub skipped: bool,
}

/// A voting behaviour (002 §6, DAMN).
///
/// Behaviours never steer: every cycle each fills one vote per arc in
/// [-1, 1] (and may veto arcs or vote a speed limit); the arbiter weights and
/// fuses them. A behaviour is added with one file implementing this trait and
/// [`crate::Plugin`], one line in the [`crate::Registry`] and one table in the
/// configuration.
pub trait Behaviour: Send {
    /// The name its votes are weighted and published under
    /// (`ARC_VOTES_<NAME>`), as in its configuration table.
    fn name(&self) -> &str;

    /// Fills `votes` for `ctx.arcs`. Called every cycle with `votes` reset
    /// to neutral (0, no veto, no speed). The hot method: allocate nothing.
    fn vote(&mut self, ctx: &VoteContext<'_>, votes: &mut Votes);

    /// Whether its last [`vote`](Self::vote) cast no votes: a behaviour
    /// in another process that did not answer in time, say. Its votes of
    /// that cycle are then not counted anywhere, and the arbiter ages its
    /// earlier ones as if it had not voted (002 §6: DAMN fuses the votes it
    /// has).
    fn abstained(&self) -> bool {
        false
    }

    /// Why it can no longer vote at all, if it cannot (an external
    /// program that exited, hung or wrote garbage): it abstains from then on.
    fn fault(&self) -> Option<&str> {
        None
    }

    /// Forgets everything carried between cycles. Called when a mission
    /// starts over or the local map was reset.
    fn reset(&mut self) {}

    /// Called after each decision with the command the arbiter sent.
    fn debrief(&mut self, _command: &SteeringCommand) {}

    /// Progress through the mission, for behaviours that follow one.
    fn progress(&self) -> Option<Progress> {
        None
    }

    /// The waypoints this behaviour found no route to, with the evidence.
    fn no_routes(&self) -> &[NoRoute] {
        &[]
    }

    /// Counts worth reporting (a planner's re-plans, say), by name, for
    /// mission reports and `--stats`.
    fn counters(&self) -> Vec<(&'static str, u64)> {
        Vec::new()
    }

    /// What its last vote rested on that the votes alone do not show (a
    /// planner's path, the point it steered for, ground it set apart), in
    /// the vehicle frame of `pose`: drawn on `arcnav render`'s and the
    /// simulator's snapshot pictures. Asked only for those, never in the
    /// loop that drives.
    fn overlay(&self, _pose: &Pose) -> Overlay {
        Overlay::default()
    }
}

/// What a behaviour shows of its reasoning on a picture of a decision
/// ([`Behaviour::overlay`]): lines, points and cells in the vehicle frame
/// (x forward, y left, m), each kind under a label for the legend.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Overlay {
    pub lines: Vec<OverlayLine>,
    pub points: Vec<OverlayPoint>,
    pub cells: Vec<OverlayCells>,
}

impl Overlay {
    pub fn is_empty(&self) -> bool {
        self.lines.is_empty() && self.points.is_empty() && self.cells.is_empty()
    }
}

/// A polyline (a planned path, say).
#[derive(Debug, Clone, PartialEq)]
pub struct OverlayLine {
    pub label: String,
    pub points: Vec<[f64; 2]>,
}

/// One point (what the behaviour steered for, say).
#[derive(Debug, Clone, PartialEq)]
pub struct OverlayPoint {
    pub label: String,
    pub at: [f64; 2],
}

/// Square cells of one size, by centre (a planner's memory of some kind of
/// ground, say). Their sides run along the world's axes, at `yaw` (rad)
/// from the vehicle's.
#[derive(Debug, Clone, PartialEq)]
pub struct OverlayCells {
    pub label: String,
    pub size_m: f64,
    pub yaw: f64,
    pub centres: Vec<[f64; 2]>,
}

impl std::fmt::Debug for dyn Behaviour {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Behaviour({})", self.name())
    }
}

/// A behaviour the registry can build from configuration.
pub trait Plugin: Behaviour + Sized + 'static {
    /// Its name in the configuration (`[behaviours.NAME]`).
    const NAME: &'static str;
    /// Its configuration, with the documented defaults in `Default`.
    type Config: Serialize + DeserializeOwned + Default + Clone + Send + Sync + 'static;

    /// Checks the configuration (keys relative to its table).
    fn validate(_config: &Self::Config, _setup: &Setup<'_>) -> Result<(), ConfigError> {
        Ok(())
    }

    /// Builds the behaviour from its (validated) configuration.
    fn build(config: Self::Config, setup: &Setup<'_>) -> Self;
}
