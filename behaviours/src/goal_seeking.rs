//! Goal seeking (002 §6): higher votes for arcs that steer the vehicle
//! toward the current waypoint; advances through the waypoint list.
//!
//! An arc's vote is the cosine of the angle between the vehicle's heading
//! after driving `lookahead_m` along the arc and the direction from there to
//! the waypoint: +1 for an arc that ends pointing at it, -1 pointing away,
//! varying smoothly across arcs. A waypoint is reached within its arrival
//! radius, or — so that an obstacle detour does not force a loop back — when
//! it is behind the vehicle and within `pass_radius_factor` radii. After the
//! last waypoint the mission is complete: votes are neutral and the speed
//! vote is 0.

use arcnav_arbiter::Votes;
use arcnav_vehicle::config::{self, ConfigError};
use arcnav_vehicle::frames::wrap_angle;
use arcnav_vehicle::mission::OnUnreachable;
use arcnav_vehicle::{DrivenPath, SteeringResponse};
use serde::{Deserialize, Serialize};

use crate::behaviour::Plugin;
use crate::behaviour::{Behaviour, Mission, Progress, Setup, VoteContext, Waypoint};

/// Lives in `[behaviours.goal_seeking]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GoalSeekingConfig {
    /// A waypoint is reached within this distance (unless the waypoint has its own), m.
    pub arrival_radius_m: f64,
    /// Arcs are judged by where they point after this distance, m ...
    pub lookahead_m: f64,
    /// ... or after this many seconds at the cruise speed, if farther, s
    /// (see [`lookahead`]).
    pub lookahead_s: f64,
    /// A waypoint behind the vehicle and within this many arrival radii is
    /// passed (0 = only the radius counts).
    pub pass_radius_factor: f64,
}

impl Default for GoalSeekingConfig {
    fn default() -> Self {
        Self {
            arrival_radius_m: 5.0,
            lookahead_m: 10.0,
            lookahead_s: 0.0,
            pass_radius_factor: 2.0,
        }
    }
}

/// Where a vehicle is in its list of waypoints: the one sought, advanced
/// past those reached (within their arrival radius, or behind the vehicle
/// within `pass_radius_factor` radii), restarted when the list changes.
/// Shared by the goal-directed behaviours.
#[derive(Debug, Clone)]
pub(crate) struct WaypointTracker {
    arrival_radius_m: f64,
    pass_radius_factor: f64,
    mission_version: Option<i64>,
    waypoints: usize,
    current: usize,
    skipped: usize,
    stopped: bool,
}

impl WaypointTracker {
    pub fn new(arrival_radius_m: f64, pass_radius_factor: f64) -> Self {
        Self {
            arrival_radius_m,
            pass_radius_factor,
            mission_version: None,
            waypoints: 0,
            current: 0,
            skipped: 0,
            stopped: false,
        }
    }

    /// The waypoint to seek from `ctx`'s pose (`None`: complete or nothing
    /// to do), and its index.
    pub fn seek<'m>(&mut self, ctx: &VoteContext<'m>) -> Option<(usize, &'m Waypoint)> {
        if self.mission_version != Some(ctx.mission.version) {
            self.mission_version = Some(ctx.mission.version);
            self.current = 0;
            self.skipped = 0;
            self.stopped = false;
        }
        if self.stopped {
            return None;
        }
        self.waypoints = ctx.mission.waypoints.len();
        let position = ctx.pose.position();
        self.advance(ctx.mission, position.x, position.y, ctx.pose.yaw());
        let mission: &'m Mission = ctx.mission;
        mission
            .waypoints
            .get(self.current)
            .map(|w| (self.current, w))
    }

    /// Moves past every waypoint already reached from (x, y) heading `yaw`.
    fn advance(&mut self, mission: &Mission, x: f64, y: f64, yaw: f64) {
        while let Some(w) = mission.waypoints.get(self.current) {
            let radius = w
                .radius_m
                .filter(|r| *r > 0.0)
                .unwrap_or(self.arrival_radius_m);
            let (dx, dy) = (w.x - x, w.y - y);
            let distance = dx.hypot(dy);
            let ahead = dx * yaw.cos() + dy * yaw.sin();
            let passed = ahead < 0.0 && distance < radius * self.pass_radius_factor;
            if distance <= radius || passed {
                self.current += 1;
            } else {
                break;
            }
        }
    }

    /// Gives up the waypoint being sought: [`OnUnreachable::Skip`] goes on
    /// to the next, [`OnUnreachable::Stop`] seeks none from now on (until
    /// the mission changes).
    pub fn give_up(&mut self, then: OnUnreachable) {
        match then {
            OnUnreachable::Skip => {
                self.current += 1;
                self.skipped += 1;
            }
            OnUnreachable::Stop => self.stopped = true,
        }
    }

    pub fn reset(&mut self) {
        self.current = 0;
        self.skipped = 0;
        self.stopped = false;
        self.mission_version = None;
    }

    pub fn progress(&self) -> Progress {
        Progress {
            current: self.current.min(self.waypoints),
            waypoints: self.waypoints,
            complete: self.waypoints > 0 && self.current >= self.waypoints,
            skipped: self.skipped,
            unreachable: self.stopped,
        }
    }
}

/// How far ahead a goal-directed behaviour aims: `lookahead_m`, or
/// `lookahead_s` of driving at the cruise speed if that is farther,
/// `L = max(L_min, v_c·t_L)` — regulated pure pursuit scales its lookahead
/// with speed for the same reason (Macenski et al., 2023). Aimed a fixed
/// distance ahead, a fast vehicle turns as hard for a metre off its path
/// as a slow one: a 1 m offset 8 m ahead asks for curvature
/// `2·1/8² = 0.031 1/m`, which allows only √(1.5/0.031) = 7 m/s at 1.5 m/s²
/// of lateral acceleration, and it weaves; 20 m ahead the same offset asks
/// for 0.005 1/m. The cruise speed, not the speed of the moment: a
/// lookahead that shrinks as the vehicle slows for a turn makes the next
/// turn sharper still.
pub(crate) fn lookahead(lookahead_m: f64, lookahead_s: f64, cruise_mps: f64) -> f64 {
    lookahead_m.max(lookahead_s * cruise_mps)
}

/// Votes for the arcs that head for world point `target`: each arc's vote
/// is the cosine of the angle between the vehicle's heading after
/// `lookahead_m` along the path its command would put it on ([`DrivenPath`]:
/// the latency and the steering's rate first, the arc after; or the
/// distance to the target, if nearer) and the direction from there to the
/// target. A turn in place is judged by where it points after a quarter
/// turn.
pub(crate) fn vote_towards(
    ctx: &VoteContext<'_>,
    response: &SteeringResponse,
    target: [f64; 2],
    lookahead_m: f64,
    votes: &mut Votes,
) {
    let position = ctx.pose.position();
    // The target in the vehicle frame.
    let (dx, dy) = (target[0] - position.x, target[1] - position.y);
    let (sin, cos) = ctx.pose.yaw().sin_cos();
    let (gx, gy) = (cos * dx + sin * dy, -sin * dx + cos * dy);
    let lookahead = lookahead_m.min(gx.hypot(gy));
    let steering = ctx.steering();
    for (index, &k) in ctx.arcs.curvatures().iter().enumerate() {
        if k.is_infinite() {
            let heading = std::f64::consts::FRAC_PI_2.copysign(k);
            votes.set(index, wrap_angle(gy.atan2(gx) - heading).cos() as f32);
            continue;
        }
        let end = DrivenPath::new(&steering, response, k).pose_at(lookahead);
        let bearing = (gy - end.position.y).atan2(gx - end.position.x);
        votes.set(index, wrap_angle(bearing - end.heading).cos() as f32);
    }
}

/// The goal-seeking behaviour.
#[derive(Debug, Clone)]
pub struct GoalSeeking {
    config: GoalSeekingConfig,
    tracker: WaypointTracker,
    response: SteeringResponse,
    /// Arcs are judged by where they point this far along, m.
    aim_m: f64,
}

impl GoalSeeking {
    /// Goal seeking for a vehicle that takes each arc at once (arcs
    /// judged as arcs); [`GoalSeeking::with_response`] judges the paths a
    /// real vehicle drives (the registry's, with `[arcs] driven_paths`).
    pub fn new(config: GoalSeekingConfig) -> Self {
        Self {
            tracker: WaypointTracker::new(config.arrival_radius_m, config.pass_radius_factor),
            aim_m: config.lookahead_m,
            config,
            response: SteeringResponse::immediate(),
        }
    }

    /// Judges each arc along the path the vehicle drives when commanded
    /// onto it, answering commands as `response` says.
    #[must_use]
    pub fn with_response(mut self, response: SteeringResponse) -> Self {
        self.response = response;
        self
    }

    /// Aims `lookahead_s` of driving at `cruise_mps` ahead when that is
    /// farther than `lookahead_m` ([`lookahead`]; the registry's does).
    #[must_use]
    pub fn with_cruise(mut self, cruise_mps: f64) -> Self {
        self.aim_m = lookahead(self.config.lookahead_m, self.config.lookahead_s, cruise_mps);
        self
    }
}

impl Behaviour for GoalSeeking {
    fn name(&self) -> &str {
        Self::NAME
    }

    fn vote(&mut self, ctx: &VoteContext<'_>, votes: &mut Votes) {
        let Some((_, goal)) = self.tracker.seek(ctx) else {
            // Complete (or nothing to do): no opinion on steering, and stop.
            votes.vote_speed(0.0);
            return;
        };
        vote_towards(ctx, &self.response, [goal.x, goal.y], self.aim_m, votes);
    }

    fn reset(&mut self) {
        self.tracker.reset();
    }

    fn progress(&self) -> Option<Progress> {
        Some(self.tracker.progress())
    }
}

impl Plugin for GoalSeeking {
    const NAME: &'static str = "goal_seeking";
    type Config = GoalSeekingConfig;

    fn validate(c: &Self::Config, _setup: &Setup<'_>) -> Result<(), ConfigError> {
        config::positive("arrival_radius_m", c.arrival_radius_m)?;
        config::positive("lookahead_m", c.lookahead_m)?;
        config::in_range("lookahead_s", c.lookahead_s, 0.0, 10.0)?;
        config::non_negative("pass_radius_factor", c.pass_radius_factor)?;
        Ok(())
    }

    fn build(config: Self::Config, setup: &Setup<'_>) -> Self {
        Self::new(config)
            .with_response(setup.steering_response())
            .with_cruise(setup.cruise_mps)
    }
}
