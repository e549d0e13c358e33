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
//! The arbiter reads no pose: how far the vehicle has moved comes from its
//! own commands and the vehicle's acceleration limits, so every executor
//! fed the same votes decides the same. The behaviours re-check the ground
//! behind at every decision; backing ends at once if its arc is no longer
//! clear enough to stop on.

use arcnav_vehicle::config::{self, ConfigError};
use arcnav_vehicle::motion::speed_ramp;
use arcnav_vehicle::time::{micros_to_seconds, seconds_to_micros};
use arcnav_vehicle::{MotionLimits, SteeringCommand, Utime, VehicleConfig};
use serde::{Deserialize, Serialize};

/// Lives in `[arbiter.recovery]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RecoveryConfig {
    /// Back up when blocked (false: stop and wait, as 002's vehicle did).
    pub enabled: bool,
    /// Blocked this long with the vehicle standing before backing up, s.
    pub wait_s: f64,
    /// Backing-up speed, m/s.
    pub speed_mps: f64,
    /// Distance backed per recovery, m.
    pub distance_m: f64,
    /// A backward arc must be clear this much further than the distance, m.
    pub margin_m: f64,
    /// Back up only along an arc clear for at least this much (when none is
    /// clear for `distance_m`), m.
    pub min_distance_m: f64,
    /// Recoveries in a row without `progress_m` of forward driving between
    /// them; then the vehicle stops.
    pub max_attempts: u32,
    /// Forward driving that shows a recovery worked, m.
    pub progress_m: f64,
    /// Commands slower than this count as standing (blocked when the arcs'
    /// limits force it), m/s.
    pub creep_mps: f64,
}

impl Default for RecoveryConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            wait_s: 1.5,
            speed_mps: 1.0,
            distance_m: 4.0,
            margin_m: 0.5,
            min_distance_m: 1.0,
            max_attempts: 8,
            progress_m: 8.0,
            creep_mps: 0.1,
        }
    }
}

impl RecoveryConfig {
    /// Keys relative to `[arbiter.recovery]`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        config::in_range("wait_s", self.wait_s, 0.0, 60.0)?;
        config::in_range("speed_mps", self.speed_mps, 0.05, 5.0)?;
        config::in_range("distance_m", self.distance_m, 0.1, 50.0)?;
        config::in_range("min_distance_m", self.min_distance_m, 0.0, self.distance_m)?;
        config::non_negative("margin_m", self.margin_m)?;
        config::non_negative("progress_m", self.progress_m)?;
        config::in_range("creep_mps", self.creep_mps, 0.0, 1.0)?;
        if self.max_attempts > 1000 {
            return Err(ConfigError::new(
                "max_attempts",
                format!("is {}, at most 1000", self.max_attempts),
            ));
        }
        Ok(())
    }
}

/// What recoveries did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct RecoveryStats {
    /// Times the vehicle started backing up.
    pub recoveries: u64,
    /// Metres backed (estimated from the commands), m.
    pub backed_m: f64,
    /// Decisions that were blocked with no backward arc clear.
    pub no_way_back: u64,
    /// Decisions that stopped because recoveries were exhausted.
    pub exhausted: u64,
}

/// What the arbiter knows of the ground behind and the behaviours' wishes
/// at one decision.
pub(crate) struct Behind<'a> {
    /// Per arc: the least backing-up clearance any fresh behaviour gave
    /// (`None`: nobody had an opinion).
    pub clearance: &'a [Option<f64>],
    /// Per arc: the fused vote before vetoes.
    pub preference: &'a [f32],
    pub curvatures: &'a [f64],
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Mode {
    Forward,
    Backing {
        arc: usize,
        /// Distance to back up, m.
        goal_m: f64,
        backed_m: f64,
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
    /// The vehicle's speed as the commands so far make it, m/s.
    speed_estimate: f64,
    last: Option<(Utime, f64)>,
    pub stats: RecoveryStats,
}

/// What recovery makes of a decision.
pub(crate) enum Outcome {
    /// Forward decision stands.
    Keep,
    /// Back up with this command.
    Back(SteeringCommand),
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
            speed_estimate: 0.0,
            last: None,
            stats: RecoveryStats::default(),
        }
    }

    /// True while backing up.
    pub fn is_backing(&self) -> bool {
        matches!(self.mode, Mode::Backing { .. })
    }

    /// Moves the speed estimate to `now` under the last command.
    fn advance(&mut self, now: Utime) {
        let Some((since, target)) = self.last else {
            return;
        };
        self.last = Some((now, target));
        let dt = micros_to_seconds(now - since).max(0.0);
        let (v1, mean) = speed_ramp(self.speed_estimate, target, &self.limits, dt);
        let distance = mean * dt;
        self.speed_estimate = v1;
        if distance > 0.0 {
            self.forward_since_recovery_m += distance;
            if self.forward_since_recovery_m >= self.config.progress_m {
                self.attempts = 0;
            }
        } else {
            self.stats.backed_m -= distance;
            if let Mode::Backing { backed_m, .. } = &mut self.mode {
                *backed_m -= distance;
            }
        }
    }

    /// Records the command sent at `now`.
    pub fn sent(&mut self, now: Utime, command: &SteeringCommand) {
        let speed = if command.is_stop() {
            0.0
        } else {
            command.speed_mps
        };
        self.last = Some((now, speed));
    }

    /// The decision at `now`: `blocked` says whether the forward decision
    /// leaves the vehicle standing for want of an arc; `safe` is false when
    /// it stopped for a reason no backing up may override (votes missing).
    pub fn step(&mut self, now: Utime, blocked: bool, safe: bool, behind: &Behind<'_>) -> Outcome {
        self.advance(now);
        if !self.config.enabled {
            return Outcome::Keep;
        }
        if !safe {
            self.end_backing();
            return Outcome::Keep;
        }
        if let Mode::Backing {
            arc,
            goal_m,
            backed_m,
        } = self.mode
        {
            let remaining = goal_m - backed_m;
            let clear = behind.clearance.get(arc).copied().flatten().unwrap_or(0.0);
            // Room to stand before what is behind, at the speed it has.
            let v = self.speed_estimate.abs();
            let braking = v * v / (2.0 * self.limits.max_deceleration_mps2);
            if remaining > 0.0 && clear - self.config.margin_m > braking {
                let room = (clear - self.config.margin_m).min(remaining + braking);
                let speed = self
                    .config
                    .speed_mps
                    .min((2.0 * self.limits.max_deceleration_mps2 * room.max(0.0)).sqrt());
                return Outcome::Back(SteeringCommand {
                    utime: now,
                    curvature: behind.curvatures[arc],
                    speed_mps: -speed,
                    arc_index: Some(arc),
                    vote: behind.preference.get(arc).copied().unwrap_or(0.0),
                });
            }
            tracing::info!(backed_m, remaining, clear, "backing up ends");
            self.end_backing();
            // Give the way forward a fresh look before backing again.
            self.blocked_since = blocked.then_some(now);
            return Outcome::Keep;
        }
        if !blocked {
            self.blocked_since = None;
            return Outcome::Keep;
        }
        let since = *self.blocked_since.get_or_insert(now);
        let standing = self.speed_estimate.abs() < 0.05;
        if now - since < seconds_to_micros(self.config.wait_s) || !standing {
            return Outcome::Keep;
        }
        if self.attempts >= self.config.max_attempts {
            self.stats.exhausted += 1;
            return Outcome::Exhausted {
                attempts: self.attempts,
            };
        }
        let Some((arc, goal_m)) = self.choose(behind) else {
            self.stats.no_way_back += 1;
            return Outcome::Keep;
        };
        self.attempts += 1;
        self.stats.recoveries += 1;
        self.forward_since_recovery_m = 0.0;
        tracing::info!(
            attempt = self.attempts,
            curvature = behind.curvatures[arc],
            distance_m = goal_m,
            "blocked: backing up"
        );
        self.mode = Mode::Backing {
            arc,
            goal_m,
            backed_m: 0.0,
        };
        self.step(now, blocked, safe, behind)
    }

    fn end_backing(&mut self) {
        self.mode = Mode::Forward;
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
                r >= self.config.min_distance_m.max(0.1)
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
