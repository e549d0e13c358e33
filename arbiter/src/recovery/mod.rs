//! Backing up when the way forward is blocked.
//!
//! A reactive vehicle that only drives forwards stops for good in front of a
//! bush first seen inside its minimum distance, or at the end of a
//! cul-de-sac. When every forward arc stays forbidden or unacceptable (or
//! allowed only at a crawl) for `wait_s` with the vehicle standing, the
//! arbiter backs it up at `speed_mps` for `distance_m` along a backward arc
//! that the behaviours checking the ground behind (obstacle avoidance) say
//! is clear for that distance plus `margin_m`, then goes forward again. The
//! backward arc is the one that swings the nose towards the forward arc the
//! behaviours like best, ignoring vetoes: backing along curvature k turns
//! the heading by -k per metre, so the arc mirroring the preferred one. At
//! most `max_attempts` recoveries follow each other without `progress_m` of
//! forward driving in between; then the vehicle stops and says why.
//!
//! **Turning round.** When what the vehicle wants — the weighted mean vote
//! of the behaviours that judge no ground (give no clearance), e.g. the
//! route — is an extreme arc, or every arc's is below 0, its way lies
//! beyond the arcs, to the side or behind, as at the end of a cul-de-sac. Backing up
//! once and then driving on the fused vote swings the nose back and forth
//! (the forward arcs that obstacle avoidance likes best lead back in).
//! Instead the vehicle makes a K-point turn, as a driver would in a narrow
//! lane: backing legs along arcs curving away from that side and forward
//! legs along arcs curving towards it, both turning the heading the same
//! way, each the leg that turns it most (|k|·length) among those clear for
//! at least `min_distance_m` — forwards too, however close (obstacle
//! avoidance's `min_distance_m` veto is for driving at speed, not for a
//! leg at `speed_mps`); when the other way has no such leg, the same way
//! again. The wheels are turned standing before each leg. It
//! ends when the wish's favourite arc curves less than `turn_exit_fraction`
//! of the hardest towards that side and its vote is 0 or more (the way lies
//! ahead again, for a second: a route's path can swing for a cycle as it
//! re-plans; a wish for the other side's hardest arc, the way still
//! behind, does not end it), after `turn_max_legs` legs, or when no leg is
//! clear. When the way comes to lie well ahead on the other side (that
//! side's hardest arc wished for with a vote of 0.3 or more, for a second:
//! a route that found one end of a ditch shut goes round the other), the
//! turn goes that way, the short way to it. One turn counts as one
//! recovery; a turn left unfinished is taken up towards the same side by
//! the next one (until `progress_m` of driving).
//!
//! **Backing out the way it came.** When no manoeuvre can start (no
//! backward arc is clear) or a turn round ends with no leg clear (a lane
//! narrower than the turning circle and the vehicle's length allow to turn
//! in), the vehicle retraces its own path: the arbiter remembers the last
//! `retrace_max_m` of its motions (curvature and distance, from its
//! commands) and undoes them newest first — backing along what it drove
//! forwards, creeping forwards along what it backed — each checked against
//! the behaviours' clearances like any leg (the local map counts the ground
//! it drove over as seen: see `localmap.driven_memory_m`). Retracing
//! towards a turn ends where an arc curving towards the way is clear for
//! `retrace_room_m` ahead (room to turn); otherwise after `distance_m`, as a
//! backing-up would. One retrace counts as one recovery. The way back is
//! driven on the arc nearest the curvature pursued that has room, within
//! 0.05 1/m of it (a corner standing beside a bank refuses the arc that
//! swings it in); a run that cannot be driven to its end (a turn's leg was
//! driven as close as its clearance allowed, and pursuit ends a little
//! off it) is given up within a metre of its end for the next.
//!
//! **Nothing behind.** Where nothing behind is known (the mission's start,
//! or a trail followed back to where it began) and the arcs the vehicle
//! wants are held to a stop by ground not seen close along them (a sensor
//! looking ahead never saw beside the start), it turns towards them
//! forwards, as far as the ground is seen: the legs of a turn round
//! towards that side, which ends once the way lies ahead.
//!
//! The arbiter reads no pose: how far the vehicle has moved comes from its
//! own commands and the vehicle's acceleration limits, so every executor
//! fed the same votes decides the same. The behaviours re-check the ground
//! behind at every decision; backing ends at once if its arc is no longer
//! clear enough to stop on.

use arcnav_vehicle::frames::wrap_angle;
use arcnav_vehicle::time::{micros_to_seconds, seconds_to_micros};
use arcnav_vehicle::{
    MotionLimits, MotionModel, PlanarState, SteeringCommand, Utime, VehicleConfig,
};

use crate::trail::{Pursuit, Trail};
use serde::Serialize;

mod behind;
mod config;

use behind::Leg;
pub(crate) use behind::{Behind, TurnArc};
pub use config::RecoveryConfig;

/// A leg starts moving once the steering is this near its curvature, 1/m
/// (0.13 s of the default steering rate).
const STEERED_WITHIN: f64 = 0.02;

/// Decisions further apart than this restart the motion estimate, µs: the
/// commands before have acted in full (latency, steering and speed ramps).
const SETTLED_US: Utime = 2_000_000;

/// Slower than this, the vehicle stands, m/s.
const STANDING_MPS: f64 = 0.05;

/// Retracing, a run that cannot be driven to its end is given up for the
/// next one when this little of it is left, m.
const RUN_SLACK_M: f64 = 1.0;

/// Retracing steers at most this far from the curvature pursuit asks for
/// to find an arc with room, 1/m (2.5 m of lateral offset over 10 m).
const RETRACE_STEER_SLACK: f64 = 0.05;

/// Retracing, an arc is taken for the way back when it has this much room
/// past the margin (or the rest of the run), m.
const RETRACE_ROOM_M: f64 = 0.5;

/// A turn in place starts only when clear for this much, radians (20°).
const SPIN_MIN_RAD: f64 = 0.35;

/// A turn in place stops this far before what it would meet, radians (5°).
const SPIN_MARGIN_RAD: f64 = 0.087;

/// A turn in place gives up after a whole turn, degrees.
const SPIN_MAX_DEG: f64 = 360.0;

/// A turn round ends once the way has lain ahead this long, s: a route's
/// path can swing for a cycle as it re-plans.
const WISH_HELD_S: f64 = 1.0;

/// What recoveries did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct RecoveryStats {
    /// Times the vehicle started backing up or turning round.
    pub recoveries: u64,
    /// Metres backed (estimated from the commands), m.
    pub backed_m: f64,
    /// Decisions that were blocked with no backward arc clear.
    pub no_way_back: u64,
    /// Decisions that stopped because recoveries were exhausted.
    pub exhausted: u64,
    /// Of the recoveries, K-point turns.
    pub turns: u64,
    /// Legs driven in those turns, backing and forward.
    pub turn_legs: u64,
    /// Heading turned by them (estimated from the commands), degrees.
    pub turned_deg: f64,
    /// Turns that went the other way when the way came to lie ahead on
    /// that side.
    pub turns_reversed: u64,
    /// Of the recoveries, retraces of the vehicle's own path.
    pub retraces: u64,
    /// Metres retraced (estimated from the commands), m.
    pub retraced_m: f64,
    /// Of the turns round, turns in place (a skid-steer vehicle's).
    pub turns_in_place: u64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    Forward,
    /// Backing up once, then forward again.
    Backing(Leg),
    /// A K-point turn towards `side` (+1 left, -1 right).
    Turning {
        side: f64,
        leg: Leg,
        legs: u32,
    },
    /// Turning in place towards `side` (a vehicle that can, where another
    /// makes a K-point turn).
    Spinning {
        side: f64,
    },
    /// Undoing the vehicle's own motions, newest first, for at most
    /// `budget_m`; towards a turn to `side`, until there is room to turn.
    Retracing {
        side: Option<f64>,
        done_m: f64,
        budget_m: f64,
    },
}

/// The recovery state machine (owned by the arbiter).
#[derive(Debug, Clone)]
pub(crate) struct Recovery {
    config: RecoveryConfig,
    /// The vehicle's acceleration limits, for the speed estimate.
    limits: MotionLimits,
    mode: Mode,
    blocked_since: Option<Utime>,
    attempts: u32,
    forward_since_recovery_m: f64,
    /// The vehicle as its commands move it (dead reckoning in a frame of
    /// its own, latency and limits included); begun at the first decision.
    model: Option<MotionModel>,
    /// Turning round: since when the way has lain ahead.
    wish_ahead_since: Option<Utime>,
    /// Since when the way has lain ahead on the other side of a turn.
    other_side_since: Option<Utime>,
    /// The side of a turn that ended with no leg clear, until the vehicle
    /// has made progress or a turn has finished.
    unfinished_turn: Option<f64>,
    /// Heading turned by the turn under way (and those it takes up again
    /// after they found no leg clear), degrees.
    turn_deg: f64,
    /// The last turn found no leg clear before `retrace_below_deg`: the
    /// next recovery retraces.
    cramped: bool,
    /// Turning round: since when no leg has been clear.
    stalled_since: Option<Utime>,
    /// The way the vehicle came, at most `retrace_max_m`.
    trail: Trail,
    pub stats: RecoveryStats,
}

/// What recovery makes of a decision.
pub(crate) enum Outcome {
    /// Forward decision stands.
    Keep,
    /// Drive a manoeuvre's leg with this command (backing up when its
    /// speed is negative).
    Drive(SteeringCommand),
    /// Blocked and recoveries are used up.
    Exhausted { attempts: u32 },
}

impl Recovery {
    pub fn new(config: &RecoveryConfig, vehicle: &VehicleConfig) -> Self {
        Self {
            config: config.clone(),
            limits: MotionLimits::from_vehicle(vehicle),
            mode: Mode::Forward,
            blocked_since: None,
            attempts: 0,
            forward_since_recovery_m: 0.0,
            model: None,
            wish_ahead_since: None,
            other_side_since: None,
            unfinished_turn: None,
            turn_deg: 0.0,
            cramped: false,
            stalled_since: None,
            trail: Trail::new(config.retrace_max_m),
            stats: RecoveryStats::default(),
        }
    }

    /// True while a manoeuvre (backing up, turning round) drives.
    pub fn is_backing(&self) -> bool {
        !matches!(self.mode, Mode::Forward)
    }

    /// The vehicle's speed and curvature as its commands make them.
    fn speed_and_curvature(&self) -> (f64, f64) {
        self.model
            .as_ref()
            .map_or((0.0, 0.0), |m| (m.state().speed_mps, m.state().curvature))
    }

    /// Moves the motion estimate to `now` under the commands sent.
    fn advance(&mut self, now: Utime) {
        let limits = self.limits;
        let model = self
            .model
            .get_or_insert_with(|| MotionModel::new(limits, PlanarState::default(), now));
        if now > model.utime().saturating_add(SETTLED_US) {
            // A gap between decisions (cycles skipped, a clock that jumped
            // ahead): the commands have long acted, but where the vehicle
            // went is not known. The estimate starts afresh at `now`, with
            // the speed and curvature they left, and no way back.
            let settled = model.advance_to(model.utime() + SETTLED_US);
            *model = MotionModel::new(
                limits,
                PlanarState {
                    speed_mps: settled.speed_mps,
                    curvature: settled.curvature,
                    ..PlanarState::default()
                },
                now,
            );
            self.trail = Trail::new(self.config.retrace_max_m);
        }
        let (before, odometer_before) = (*model.state(), model.odometer_m());
        let after = model.advance_to(now);
        let odometer = model.odometer_m();
        let distance = odometer - odometer_before;
        if distance < 0.0 {
            self.stats.backed_m -= distance;
        }
        if let Mode::Retracing { done_m, .. } = &mut self.mode {
            *done_m += distance.abs();
            self.stats.retraced_m += distance.abs();
            return;
        }
        self.trail
            .record(&before, odometer_before, &after, odometer);
        if matches!(self.mode, Mode::Turning { .. } | Mode::Spinning { .. }) {
            let turned = wrap_angle(after.yaw - before.yaw).to_degrees().abs();
            self.stats.turned_deg += turned;
            self.turn_deg += turned;
        }
        let leg = match &mut self.mode {
            Mode::Forward => {
                if distance > 0.0 {
                    self.forward_since_recovery_m += distance;
                    if self.forward_since_recovery_m >= self.config.progress_m {
                        self.attempts = 0;
                        self.unfinished_turn = None;
                        self.cramped = false;
                    }
                }
                return;
            }
            Mode::Backing(leg) => leg,
            Mode::Turning { leg, .. } => leg,
            Mode::Spinning { .. } | Mode::Retracing { .. } => return,
        };
        if (distance < 0.0) == leg.reverse {
            leg.done_m += distance.abs();
        }
    }

    /// Records the command sent at `now` (it acts after the vehicle's
    /// latency).
    pub fn sent(&mut self, _now: Utime, command: &SteeringCommand) {
        if let Some(model) = &mut self.model {
            model.command(*command);
        }
    }

    /// The decision at `now`: `blocked` says whether the forward decision
    /// leaves the vehicle standing for want of an arc; `safe` is false when
    /// it stopped for a reason no manoeuvre may override (votes missing).
    pub fn step(&mut self, now: Utime, blocked: bool, safe: bool, behind: &Behind<'_>) -> Outcome {
        self.advance(now);
        if !self.config.enabled {
            return Outcome::Keep;
        }
        if !safe {
            self.mode = Mode::Forward;
            return Outcome::Keep;
        }
        match self.mode {
            Mode::Forward => self.when_forward(now, blocked, behind),
            Mode::Backing(leg) => {
                if let Some(command) = self.drive(now, &leg, behind) {
                    return Outcome::Drive(command);
                }
                tracing::info!(
                    t_s = micros_to_seconds(now),
                    backed_m = leg.done_m,
                    "backing up ends"
                );
                self.end(now, blocked)
            }
            Mode::Turning { side, leg, legs } => {
                let since = self
                    .wish_ahead(side, behind)
                    .then(|| self.wish_ahead_since.unwrap_or(now));
                self.wish_ahead_since = since;
                if since.is_some_and(|since| now - since >= seconds_to_micros(WISH_HELD_S)) {
                    tracing::info!(t_s = micros_to_seconds(now), legs, "turned round");
                    self.unfinished_turn = None;
                    return self.end(now, blocked);
                }
                // The way lies ahead on the other side (a route that found
                // this side shut and goes round the other end), for a
                // second: turn that way, the shorter way to it. A way
                // behind (every vote below 0, as at the end of a
                // cul-de-sac) does not turn the turn: it passes from side
                // to side as the heading swings past it.
                let other = behind
                    .wished()
                    .is_some_and(|wish| wish.ahead_on_the_other_side(side));
                let other_since = other.then(|| self.other_side_since.unwrap_or(now));
                self.other_side_since = other_since;
                if other_since.is_some_and(|since| now - since >= seconds_to_micros(WISH_HELD_S))
                    && legs < self.config.turn_max_legs
                    && let Some(next) = self
                        .choose_leg(-side, false, behind)
                        .or_else(|| self.choose_leg(-side, true, behind))
                {
                    tracing::info!(
                        t_s = micros_to_seconds(now),
                        legs,
                        side = -side,
                        "turning round: the way lies ahead on the other side, turning that way"
                    );
                    self.stats.turns_reversed += 1;
                    self.other_side_since = None;
                    self.start_turn_leg(-side, next, legs + 1);
                    return self.step(now, blocked, safe, behind);
                }
                if let Some(command) = self.drive(now, &leg, behind) {
                    return Outcome::Drive(command);
                }
                // The next leg goes the other way and turns the same way;
                // with no room that way, the same way again (on an arc with
                // room: it turns the heading on, if less).
                let next = (legs < self.config.turn_max_legs)
                    .then(|| {
                        self.choose_leg(side, !leg.reverse, behind)
                            .or_else(|| self.choose_leg(side, leg.reverse, behind))
                    })
                    .flatten();
                let Some(next) = next else {
                    // Standing still a moment may free a leg (the vehicle
                    // rolls on as it stops; new images come in): the turn
                    // waits `wait_s` for one before it ends.
                    let stalled = *self.stalled_since.get_or_insert(now);
                    if legs < self.config.turn_max_legs
                        && now - stalled < seconds_to_micros(self.config.wait_s)
                    {
                        return Outcome::Drive(self.hold(now, &leg, behind));
                    }
                    tracing::info!(
                        t_s = micros_to_seconds(now),
                        legs,
                        "turning round ends: no leg clear or legs used up"
                    );
                    self.unfinished_turn = Some(side);
                    self.cramped = self.turn_deg < self.config.retrace_below_deg;
                    return self.end(now, blocked);
                };
                self.stalled_since = None;
                self.start_turn_leg(side, next, legs + 1);
                self.step(now, blocked, safe, behind)
            }
            Mode::Spinning { side } => self.spin(now, side, blocked, behind),
            Mode::Retracing {
                side,
                done_m,
                budget_m,
            } => {
                let roomy = side.is_some_and(|side| {
                    done_m >= self.min_leg_m() && self.room_to_turn(side, behind)
                });
                let command = (!roomy && done_m < budget_m)
                    .then(|| self.retrace_command(now, budget_m - done_m, behind))
                    .flatten();
                if let Some(command) = command {
                    return Outcome::Drive(command);
                }
                tracing::info!(
                    t_s = micros_to_seconds(now),
                    retraced_m = done_m,
                    room_to_turn = roomy,
                    trail_m = self.trail.length_m(),
                    "retracing ends"
                );
                if let Some(model) = &self.model {
                    self.trail.resume_from(model.odometer_m());
                }
                // With room to turn, the turn starts at once, forwards (on
                // the fused vote, the arcs leading back in win again).
                let turn = side
                    .filter(|_| roomy)
                    .and_then(|side| Some((side, self.choose_leg(side, false, behind)?)));
                if let Some((side, leg)) = turn {
                    self.start_turn(now, side, leg, "room to turn");
                    return self.step(now, blocked, safe, behind);
                }
                self.end(now, blocked)
            }
        }
    }

    /// The command that follows the trail back (see [`crate::trail`]), for
    /// at most `budget_m` more, on the arc nearest the curvature pursued.
    fn retrace_command(
        &mut self,
        now: Utime,
        budget_m: f64,
        behind: &Behind<'_>,
    ) -> Option<SteeringCommand> {
        let state = *self.model.as_ref()?.state();
        loop {
            let pursuit = self.trail.pursue(&state)?;
            let arc = self.retrace_arc(&pursuit, behind);
            let leg = Leg::along(arc, behind, pursuit.reverse, pursuit.run_m.min(budget_m));
            if let Some(command) = self.drive(now, &leg, behind) {
                return Some(command);
            }
            if state.speed_mps.abs() >= STANDING_MPS {
                // Too fast to stop in the room left: stop, then creep on.
                return Some(self.hold(now, &leg, behind));
            }
            // A leg of a turn round was driven as close to what stood in
            // the way as the clearance allowed: driving it back ends a
            // little short of where it began. Near enough, the next run
            // (the other way) starts from here.
            if pursuit.run_m > RUN_SLACK_M || !self.trail.skip_run() {
                tracing::debug!(
                    run_m = pursuit.run_m,
                    reverse = pursuit.reverse,
                    curvature = pursuit.curvature,
                    clear_m = behind.clear(arc, pursuit.reverse),
                    "retracing: no room along the way back"
                );
                return None;
            }
        }
    }

    /// The arc to follow the trail back on: the one nearest the curvature
    /// pursued that has room to go on (`RETRACE_ROOM_M` past the margin),
    /// within `RETRACE_STEER_SLACK` of it; else the nearest. Standing with
    /// a corner beside a bank, a curvature that swings it in is refused
    /// and a straighter one taken: pursuit steers back onto the trail a
    /// metre later.
    fn retrace_arc(&self, pursuit: &Pursuit, behind: &Behind<'_>) -> usize {
        let nearest = nearest_arc(behind.curvatures, pursuit.curvature);
        let needed = self.config.margin_m + RETRACE_ROOM_M.min(pursuit.run_m);
        (0..behind.curvatures.len())
            .filter(|&arc| {
                (behind.curvatures[arc] - pursuit.curvature).abs() <= RETRACE_STEER_SLACK
                    && behind
                        .clear(arc, pursuit.reverse)
                        .is_some_and(|c| c >= needed)
            })
            .min_by(|&a, &b| {
                let off = |arc: usize| (behind.curvatures[arc] - pursuit.curvature).abs();
                off(a).total_cmp(&off(b))
            })
            .unwrap_or(nearest)
    }

    /// Standing with the wheels at `leg`'s curvature.
    fn hold(&self, now: Utime, leg: &Leg, behind: &Behind<'_>) -> SteeringCommand {
        SteeringCommand {
            utime: now,
            curvature: leg.curvature,
            speed_mps: 0.0,
            arc_index: Some(leg.arc + behind.offset),
            vote: behind.preference.get(leg.arc).copied().unwrap_or(0.0),
            turn_rate_radps: 0.0,
        }
    }

    /// True when an arc curving towards `side`, at least half as hard as
    /// the hardest, is clear `retrace_room_m` ahead.
    fn room_to_turn(&self, side: f64, behind: &Behind<'_>) -> bool {
        let hardest = behind.curvatures.iter().fold(0.0f64, |m, k| m.max(k.abs()));
        (0..behind.curvatures.len()).any(|arc| {
            behind.curvatures[arc] * side >= 0.5 * hardest
                && behind
                    .clear(arc, false)
                    .is_some_and(|c| c - self.config.margin_m >= self.config.retrace_room_m)
        })
    }

    /// Starts retracing (a recovery), towards a turn to `side` if given;
    /// false when there is no trail to retrace.
    fn start_retrace(&mut self, now: Utime, side: Option<f64>, behind: &Behind<'_>) -> bool {
        if !self.config.retrace || self.trail.length_m() < self.min_leg_m() {
            return false;
        }
        // Only when the way back is open now: a retrace that cannot move
        // would spend a recovery on nothing.
        let Some(state) = self.model.as_ref().map(|m| *m.state()) else {
            return false;
        };
        let mut trail = self.trail.clone();
        let open = trail.pursue(&state).is_some_and(|p| {
            let arc = self.retrace_arc(&p, behind);
            let leg = Leg::along(arc, behind, p.reverse, p.run_m);
            self.drive(now, &leg, behind).is_some()
        });
        if !open {
            return false;
        }
        self.begin();
        self.cramped = false;
        self.stats.retraces += 1;
        let budget_m = if side.is_some() {
            self.config.retrace_max_m
        } else {
            self.config.distance_m
        };
        tracing::info!(
            t_s = micros_to_seconds(now),
            attempt = self.attempts,
            trail_m = self.trail.length_m(),
            side,
            "blocked: retracing the way the vehicle came"
        );
        self.mode = Mode::Retracing {
            side,
            done_m: 0.0,
            budget_m,
        };
        true
    }

    /// Driving forwards: blocked long enough, standing, starts a manoeuvre.
    fn when_forward(&mut self, now: Utime, blocked: bool, behind: &Behind<'_>) -> Outcome {
        if !blocked {
            self.blocked_since = None;
            return Outcome::Keep;
        }
        let since = *self.blocked_since.get_or_insert(now);
        let standing = self.speed_and_curvature().0.abs() < STANDING_MPS;
        if now - since < seconds_to_micros(self.config.wait_s) || !standing {
            return Outcome::Keep;
        }
        if self.attempts >= self.config.max_attempts {
            self.stats.exhausted += 1;
            return Outcome::Exhausted {
                attempts: self.attempts,
            };
        }
        // A turn left unfinished (no leg clear) carries on towards the same
        // side: starting the other way undoes it.
        let side = behind
            .wished()
            .filter(|_| self.config.turn_round)
            .and_then(|wish| wish.beyond_the_arcs())
            .map(|side| self.unfinished_turn.unwrap_or(side));
        // A turn that could not turn far here: back out the way the vehicle
        // came first, to where there is room.
        if self.cramped && self.start_retrace(now, side.or(self.unfinished_turn), behind) {
            return self.step(now, blocked, true, behind);
        }
        // A vehicle that turns in place turns round so, where that turn is
        // clear.
        if let Some(side) = side.filter(|&side| self.can_spin(side, behind)) {
            self.begin();
            self.stats.turns += 1;
            self.stats.turns_in_place += 1;
            self.turn_deg = 0.0;
            tracing::info!(
                t_s = micros_to_seconds(now),
                attempt = self.attempts,
                side,
                "blocked, the way behind: turning round in place"
            );
            self.mode = Mode::Spinning { side };
            return self.step(now, blocked, true, behind);
        }
        // Turning round starts with the leg that has room: backing first.
        let turn = side.and_then(|side| {
            [true, false]
                .into_iter()
                .find_map(|reverse| self.choose_leg(side, reverse, behind))
                .map(|leg| (side, leg))
        });
        if let Some((side, leg)) = turn {
            self.begin();
            // A turn taken up again after finding no leg clear counts what
            // the one before it turned.
            let turned = self.unfinished_turn.map(|_| self.turn_deg);
            self.start_turn(now, side, leg, "blocked, the way behind");
            self.turn_deg = turned.unwrap_or(0.0);
        } else if side.is_some() && self.start_retrace(now, side, behind) {
            // The way is behind and no turn can start here: backing out the
            // way the vehicle came leads where it can (backing up once and
            // driving on would lead back in).
        } else if let Some((arc, goal_m)) = self.choose(behind) {
            self.begin();
            let leg = Leg::along(arc, behind, true, goal_m);
            tracing::info!(
                t_s = micros_to_seconds(now),
                attempt = self.attempts,
                ?leg,
                "blocked: backing up"
            );
            self.mode = Mode::Backing(leg);
        } else if !self.start_retrace(now, side, behind) {
            // Nothing behind is known (where the mission began, or a trail
            // followed back to its start) and the arcs the vehicle wants
            // lead into ground not seen yet: a turn towards them, forwards
            // as far as the ground is seen, shows more of it.
            let lean = behind
                .wished()
                .filter(|wish| self.config.turn_round && wish.turn != 0.0)
                .map(|wish| wish.turn.signum());
            let Some((side, leg)) =
                lean.and_then(|side| Some((side, self.choose_leg(side, false, behind)?)))
            else {
                self.stats.no_way_back += 1;
                return Outcome::Keep;
            };
            self.begin();
            self.start_turn(
                now,
                side,
                leg,
                "blocked, no way back: towards the way, forwards",
            );
        }
        self.step(now, blocked, true, behind)
    }

    /// Whether the vehicle turns in place and its turn towards `side` is
    /// clear for at least [`SPIN_MIN_RAD`].
    fn can_spin(&self, side: f64, behind: &Behind<'_>) -> bool {
        self.limits.max_turn_rate > 0.0
            && behind
                .turn(side)
                .and_then(|turn| turn.clear)
                .is_some_and(|clear| clear >= SPIN_MIN_RAD)
    }

    /// Turning in place: on while the way lies behind and the turn is
    /// clear for more than the vehicle turns while it stops turning.
    fn spin(&mut self, now: Utime, side: f64, blocked: bool, behind: &Behind<'_>) -> Outcome {
        if self.wish_ahead(side, behind) {
            tracing::info!(
                t_s = micros_to_seconds(now),
                turned_deg = self.turn_deg,
                "turned round in place"
            );
            self.unfinished_turn = None;
            return self.end(now, blocked);
        }
        let rate = self.model.as_ref().map_or(0.0, |m| m.turn_rate().abs());
        // Turned while the command to stop acts and the rate ramps down,
        // and a margin.
        let stopping = rate * self.limits.turn_stop_s() + SPIN_MARGIN_RAD;
        let turn = behind.turn(side);
        let clear = turn.and_then(|turn| turn.clear).unwrap_or(0.0);
        let Some(turn) = turn.filter(|_| clear > stopping && self.turn_deg < SPIN_MAX_DEG) else {
            tracing::info!(
                t_s = micros_to_seconds(now),
                turned_deg = self.turn_deg,
                clear_rad = clear,
                "turning in place ends: not clear, or turned a whole turn"
            );
            self.unfinished_turn = Some(side);
            return self.end(now, blocked);
        };
        Outcome::Drive(SteeringCommand::turn_in_place(
            now,
            side * self.limits.max_turn_rate,
            turn.arc,
            turn.vote,
        ))
    }

    /// Starts a turn round towards `side` with `leg` (one more turn; the
    /// heading turned counts from 0), saying `why` in the log.
    fn start_turn(&mut self, now: Utime, side: f64, leg: Leg, why: &str) {
        self.stats.turns += 1;
        self.turn_deg = 0.0;
        tracing::info!(
            t_s = micros_to_seconds(now),
            attempt = self.attempts,
            side,
            why,
            "turning round"
        );
        self.start_turn_leg(side, leg, 1);
    }

    /// Counts a recovery starting.
    fn begin(&mut self) {
        self.attempts += 1;
        self.stats.recoveries += 1;
        self.forward_since_recovery_m = 0.0;
    }

    fn start_turn_leg(&mut self, side: f64, leg: Leg, legs: u32) {
        self.stats.turn_legs += 1;
        if legs == 1 {
            self.wish_ahead_since = None;
            self.other_side_since = None;
            self.stalled_since = None;
        }
        tracing::info!(
            leg = legs,
            reverse = leg.reverse,
            curvature = leg.curvature,
            distance_m = leg.goal_m,
            "turning round: next leg"
        );
        self.mode = Mode::Turning { side, leg, legs };
    }

    /// Back to driving on the fused vote; a block gets a fresh look first.
    fn end(&mut self, now: Utime, blocked: bool) -> Outcome {
        self.mode = Mode::Forward;
        self.blocked_since = blocked.then_some(now);
        Outcome::Keep
    }

    /// True when the way lies ahead again for a turn towards `side`: the
    /// wished-for arc curves less than `turn_exit_fraction` of the hardest
    /// towards it and leads towards the way (a vote of 0 or more). A wish
    /// for the other side's hardest arc does not end the turn: the way is
    /// still behind, and turning on gets there as well (switching sides is
    /// what swings the nose to and fro).
    fn wish_ahead(&self, side: f64, behind: &Behind<'_>) -> bool {
        behind.wished().is_none_or(|wish| {
            let towards = wish.turn * side;
            towards < self.config.turn_exit_fraction && towards > -1.0 + 1e-9 && wish.vote >= 0.0
        })
    }

    /// The command that drives `leg` on, while it has distance to go and
    /// room to stop before what its clearance shows; `None` when it ends.
    /// The wheels are turned to the leg's curvature standing first: the
    /// sweep that was checked is the arc's, not the steering's transition.
    fn drive(&self, now: Utime, leg: &Leg, behind: &Behind<'_>) -> Option<SteeringCommand> {
        let remaining = leg.goal_m - leg.done_m;
        let clear = behind.clear(leg.arc, leg.reverse).unwrap_or(0.0);
        // Room to stand before what is in the way, at the speed it has: the
        // command's latency, then braking.
        let (a, latency) = (
            self.limits.max_deceleration_mps2,
            micros_to_seconds(self.limits.latency_us),
        );
        let (speed, curvature) = self.speed_and_curvature();
        let v = speed.abs();
        let stopping = v * latency + v * v / (2.0 * a);
        if remaining <= 0.0 || clear - self.config.margin_m <= stopping {
            return None;
        }
        let steering = (curvature - leg.curvature).abs() > STEERED_WITHIN;
        let room = (clear - self.config.margin_m).min(remaining + stopping);
        // v·t + v²/2a = room, solved for v.
        let stopping_speed = -a * latency + ((a * latency).powi(2) + 2.0 * a * room).sqrt();
        let speed = if steering {
            0.0
        } else {
            self.config.speed_mps.min(stopping_speed)
        };
        Some(SteeringCommand {
            utime: now,
            curvature: leg.curvature,
            speed_mps: if leg.reverse { -speed } else { speed },
            arc_index: Some(leg.arc + behind.offset),
            vote: behind.preference.get(leg.arc).copied().unwrap_or(0.0),
            turn_rate_radps: 0.0,
        })
    }

    /// The least room a leg needs, m.
    fn min_leg_m(&self) -> f64 {
        self.config.min_distance_m.max(0.1)
    }

    /// A K-point turn's next leg towards `side`: driven backwards along an
    /// arc curving away from it, or forwards along one curving towards it,
    /// the one that turns the heading most (|k|·length) among those clear
    /// for at least `min_distance_m`.
    fn choose_leg(&self, side: f64, reverse: bool, behind: &Behind<'_>) -> Option<Leg> {
        let turning = if reverse { -side } else { side };
        let margin = self.config.margin_m;
        (0..behind.curvatures.len())
            .filter(|&arc| behind.curvatures[arc] * turning > 0.0)
            .filter_map(|arc| {
                let room = behind.clear(arc, reverse)? - margin;
                (room >= self.min_leg_m()).then(|| (arc, room.min(self.config.distance_m)))
            })
            .max_by(|&(a, ra), &(b, rb)| {
                let turn = |arc: usize, r: f64| behind.curvatures[arc].abs() * r;
                turn(a, ra).total_cmp(&turn(b, rb)).then(ra.total_cmp(&rb))
            })
            .map(|(arc, goal_m)| Leg::along(arc, behind, reverse, goal_m))
    }

    /// The backward arc to take and how far: clear for the distance (or
    /// the longest one clear for at least the minimum), swinging the nose
    /// towards the preferred forward arc.
    fn choose(&self, behind: &Behind<'_>) -> Option<(usize, f64)> {
        let n = behind.curvatures.len();
        let margin = self.config.margin_m;
        let room = |arc: usize| behind.clearance[arc].map(|c| c - margin);
        let full = self.config.distance_m;
        let any_full = (0..n).any(|arc| room(arc).is_some_and(|r| r >= full));
        let candidates = (0..n).filter_map(|arc| {
            let r = room(arc)?;
            let ok = if any_full {
                r >= full
            } else {
                r >= self.min_leg_m()
            };
            ok.then_some((arc, r.min(full)))
        });
        let straight = n / 2;
        candidates.max_by(|&(a, ra), &(b, rb)| {
            // Backing along arc a swings the nose as driving forwards along
            // its mirror n-1-a would: the better that arc, the better.
            let (pa, pb) = (behind.preference[n - 1 - a], behind.preference[n - 1 - b]);
            pa.total_cmp(&pb)
                .then(ra.total_cmp(&rb))
                .then(b.abs_diff(straight).cmp(&a.abs_diff(straight)))
                .then(b.cmp(&a))
        })
    }
}

/// The arc whose curvature is nearest `curvature` (0 for an empty set).
fn nearest_arc(curvatures: &[f64], curvature: f64) -> usize {
    (0..curvatures.len())
        .min_by(|&a, &b| {
            let off = |arc: usize| (curvatures[arc] - curvature).abs();
            off(a).total_cmp(&off(b))
        })
        .unwrap_or(0)
}
