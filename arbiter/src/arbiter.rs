//! DAMN command fusion (Rosenblatt; 002 §6): behaviours never steer, they
//! vote; the arbiter decides.
//!
//! Each decision: fresh votes (younger than the timeout) of behaviours with a
//! non-zero weight are summed with their weights and normalised by the total
//! weight, so the fused vote stays in [-1, 1]; optionally smoothed across
//! neighbouring arcs; an arc any of them vetoes can never win; the best arc
//! wins (ties go to the straighter arc; of arcs within `speed_tie_vote` of
//! the best, the one that may be driven fastest), optionally refined to the peak of a
//! parabola through its neighbours. The command is stop when a required
//! behaviour is stale, when nobody voted, when every arc is vetoed, or when the
//! best vote is below the acceptable minimum. Speed is the minimum of the
//! behaviours' speed votes, the cruise speed, the vehicle's top speed and the
//! lateral-acceleration limit of the arc, lowered when the winning vote is
//! weak.
//!
//! With [`Arbiter::set_explain`] on, every decision is kept as a [`Decision`]
//! (each behaviour's votes, weight and age, the fused votes, who vetoed what
//! because of which cell, the command or the stop reason); off, none of it
//! is copied.

use arcnav_vehicle::time::seconds_to_micros;
use arcnav_vehicle::{ArcSet, SteeringCommand, Utime, VehicleConfig};

use crate::config::ArbiterConfig;
use crate::recovery::{self, Behind, Recovery, RecoveryStats};
use crate::votes::{BehaviourVotes, SpeedCause, VetoCause, Votes};

/// Why the arbiter commanded stop.
#[derive(Debug, Clone, PartialEq)]
pub enum StopReason {
    /// No behaviour with a non-zero weight has fresh votes.
    NoVotes,
    /// A required behaviour has not voted within the timeout.
    RequiredStale {
        behaviour: String,
        age_us: Option<Utime>,
    },
    /// Every arc is vetoed: by whom, how many arcs, and for what.
    AllArcsForbidden { vetoes: Vec<Vetoer> },
    /// The best fused vote is below `min_acceptable_vote`.
    NoAcceptableArc { best_vote: f32 },
    /// Blocked again after `attempts` recoveries in a row.
    Stuck { attempts: u32, blocked: String },
}

impl std::fmt::Display for StopReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            StopReason::NoVotes => write!(f, "no behaviour has voted"),
            StopReason::RequiredStale {
                behaviour,
                age_us: Some(age),
            } => {
                write!(
                    f,
                    "required behaviour {behaviour} last voted {:.2} s ago",
                    *age as f64 * 1e-6
                )
            }
            StopReason::RequiredStale {
                behaviour,
                age_us: None,
            } => {
                write!(f, "required behaviour {behaviour} has never voted")
            }
            StopReason::AllArcsForbidden { vetoes } => {
                let who: Vec<String> = vetoes.iter().map(Vetoer::to_string).collect();
                write!(f, "every arc is forbidden ({})", who.join(", "))
            }
            StopReason::NoAcceptableArc { best_vote } => {
                write!(
                    f,
                    "the best arc's fused vote {best_vote:.2} is below the acceptable minimum"
                )
            }
            StopReason::Stuck { attempts, blocked } => {
                write!(
                    f,
                    "stuck: {blocked} after backing up {attempts} times without getting through"
                )
            }
        }
    }
}

/// A behaviour's part in a stop for vetoes.
#[derive(Debug, Clone, PartialEq)]
pub struct Vetoer {
    pub behaviour: String,
    /// Arcs it vetoed.
    pub arcs: usize,
    /// What is behind its veto of the arc nearest straight ahead, when it
    /// said: a cell, or the operating area's edge (vehicle frame of the
    /// cycle).
    pub cause: Option<VetoCause>,
}

impl std::fmt::Display for Vetoer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{} vetoed {}", self.behaviour, self.arcs)?;
        if let Some(cause) = self.cause {
            write!(f, ", for {cause}")?;
        }
        Ok(())
    }
}

/// Why the last command is what it is, in short: kept for every decision
/// (what `DECISION` carries on the wire); [`Decision`] is the full record.
#[derive(Debug, Clone, PartialEq)]
pub enum Reason {
    /// The fused votes' best arc.
    Drive,
    /// A recovery manoeuvre's command: backing up, a forward leg of a
    /// turn, standing to steer for the next leg, or turning round in
    /// place.
    Manoeuvre {
        backing: bool,
        standing: bool,
        in_place: bool,
    },
    /// Stop with arcs allowed: the best arc's speed limit is 0 (unseen
    /// ground, cells right ahead; `asked_by` empty), or the behaviours in
    /// `asked_by` asked to stop (a mission complete, a waypoint no route
    /// reaches).
    SpeedLimited { asked_by: Vec<String> },
    /// Stop, and why; with the behaviours that vetoed arcs in this
    /// decision, whatever the stop's cause (a stop for no acceptable arc
    /// among a few left by vetoes names them too).
    Stop {
        stop: StopReason,
        vetoers: Vec<Vetoer>,
    },
}

impl std::fmt::Display for Reason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Reason::Drive => write!(f, "driving the best arc"),
            Reason::Manoeuvre { backing: true, .. } => write!(f, "recovery: backing up"),
            Reason::Manoeuvre { in_place: true, .. } => {
                write!(f, "recovery: turning round in place")
            }
            Reason::Manoeuvre { standing: true, .. } => {
                write!(f, "recovery: standing to steer for the next leg")
            }
            Reason::Manoeuvre { .. } => write!(f, "recovery: a forward leg of a turn"),
            Reason::SpeedLimited { asked_by } if asked_by.is_empty() => {
                write!(f, "arcs are allowed, but the best arc's speed limit is 0")
            }
            Reason::SpeedLimited { asked_by } => {
                write!(f, "{} asked to stop", asked_by.join(" and "))
            }
            Reason::Stop { stop, vetoers } => {
                stop.fmt(f)?;
                if !matches!(stop, StopReason::AllArcsForbidden { .. }) && !vetoers.is_empty() {
                    let who: Vec<String> = vetoers.iter().map(Vetoer::to_string).collect();
                    write!(f, " ({})", who.join("; "))?;
                }
                Ok(())
            }
        }
    }
}

/// A vote buffer of the wrong size.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{behaviour} voted over {got} arcs, the arbiter's arc set has {expected}")]
pub struct VoteSizeError {
    pub behaviour: String,
    pub got: usize,
    pub expected: usize,
}

/// One behaviour's part in a decision.
#[derive(Debug, Clone, PartialEq)]
pub struct InputExplanation {
    pub behaviour: String,
    pub weight: f64,
    /// Age of its latest votes at the decision, if it ever voted.
    pub age_us: Option<Utime>,
    /// Whether its votes took part (fresh and weighted).
    pub used: bool,
    pub votes: Option<Votes>,
}

/// The full record of one decision.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    pub utime: Utime,
    pub command: SteeringCommand,
    pub stop: Option<StopReason>,
    /// Fused (and smoothed) vote per arc; vetoed arcs hold -1.
    pub fused: Vec<f32>,
    /// Per arc, the behaviours that vetoed it with the cell that caused it.
    pub vetoes: Vec<Vec<(String, Option<VetoCause>)>>,
    pub inputs: Vec<InputExplanation>,
    /// The speed limits that applied, m/s: cruise, speed votes, lateral, weak vote.
    pub speed_limits: Vec<(String, f64)>,
}

impl Decision {
    /// True when the command is a manoeuvre's (backing up, turning round,
    /// or standing for one), not the fused vote's.
    pub fn is_manoeuvre(&self) -> bool {
        SpeedTime::manoeuvre(&self.speed_limits)
    }
}

/// Time spent standing, by why, µs: from each stop command to the next
/// decision.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct StopTime {
    pub no_votes_us: u64,
    pub required_stale_us: u64,
    pub all_arcs_forbidden_us: u64,
    pub no_acceptable_arc_us: u64,
    /// Arcs allowed, but every one's speed limit was 0 (ground unseen,
    /// cells right ahead).
    pub speed_limited_us: u64,
    /// A behaviour asked to stop (a mission complete).
    pub asked_us: u64,
    pub stuck_us: u64,
    /// Turning the wheels, standing, before a manoeuvre's leg.
    pub steering_us: u64,
}

impl StopTime {
    /// (why, seconds) for the non-zero ones.
    pub fn seconds(&self) -> Vec<(&'static str, f64)> {
        nonzero_seconds([
            ("no votes", self.no_votes_us),
            ("required behaviour stale", self.required_stale_us),
            ("all arcs forbidden", self.all_arcs_forbidden_us),
            ("no acceptable arc", self.no_acceptable_arc_us),
            ("speed limited to 0", self.speed_limited_us),
            ("asked to stop", self.asked_us),
            ("stuck", self.stuck_us),
            ("steering for a manoeuvre", self.steering_us),
        ])
    }
}

/// The named durations (µs) that are not zero, in seconds.
fn nonzero_seconds<const N: usize>(named: [(&'static str, u64); N]) -> Vec<(&'static str, f64)> {
    named
        .into_iter()
        .filter(|(_, us)| *us > 0)
        .map(|(why, us)| (why, us as f64 * 1e-6))
        .collect()
}

/// Time spent driving, by the limit that set the speed, µs: from each
/// command to the next decision. Tells what holds a mission's average
/// down (002 §7's question: what limits the speed).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SpeedTime {
    /// `arbiter.cruise_speed_mps`.
    pub cruise_us: u64,
    /// `vehicle.max_speed_mps`.
    pub vehicle_us: u64,
    /// A behaviour's speed vote, by the cause it gave: stopping within the
    /// free distance (cells), within the verified distance (the speed
    /// governor), the terrain, a suspected drop-off; and votes that gave
    /// none.
    pub free_distance_us: u64,
    pub verified_distance_us: u64,
    pub terrain_us: u64,
    pub suspected_drop_off_us: u64,
    pub speed_vote_us: u64,
    /// Lateral acceleration on the arc driven.
    pub lateral_us: u64,
    /// The best vote was weak (below `slow_below_vote`).
    pub weak_vote_us: u64,
    /// Backing up.
    pub reverse_us: u64,
    /// A turning-round manoeuvre's forward legs.
    pub turning_us: u64,
}

impl SpeedTime {
    /// (limit, seconds) for the non-zero ones.
    pub fn seconds(&self) -> Vec<(&'static str, f64)> {
        nonzero_seconds([
            ("cruise", self.cruise_us),
            ("vehicle", self.vehicle_us),
            (SpeedCause::FreeDistance.name(), self.free_distance_us),
            (
                SpeedCause::VerifiedDistance.name(),
                self.verified_distance_us,
            ),
            (SpeedCause::Terrain.name(), self.terrain_us),
            (
                SpeedCause::SuspectedDropOff.name(),
                self.suspected_drop_off_us,
            ),
            (SpeedCause::NotSaid.name(), self.speed_vote_us),
            ("lateral", self.lateral_us),
            ("weak vote", self.weak_vote_us),
            ("reverse", self.reverse_us),
            ("turning", self.turning_us),
        ])
    }

    /// True when `limits` are a manoeuvre's (backing up, turning round).
    fn manoeuvre(limits: &[(String, f64)]) -> bool {
        matches!(limits, [(name, _)] if name == BACKING || name == TURNING)
    }

    /// Whether a behaviour's speed vote set `limits`' speed (not a limit of
    /// the arbiter's own, a weak vote or a manoeuvre).
    fn set_by_vote(limits: &[(String, f64)]) -> bool {
        !limits.iter().any(|(name, _)| name == "weak vote")
            && limits
                .iter()
                .min_by(|a, b| a.1.total_cmp(&b.1))
                .is_some_and(|(name, _)| !OWN_LIMITS.contains(&name.as_str()))
    }

    /// The counter of the limit that set `limits`' speed (the arbiter's
    /// list: cruise, vehicle, a speed vote, lateral, weak vote last), a
    /// speed vote's by its `cause`.
    fn binding(limits: &[(String, f64)], cause: SpeedCause) -> TimeCounter {
        let weak = limits.iter().any(|(name, _)| name == "weak vote");
        let lowest = limits
            .iter()
            .filter(|(name, _)| name != "weak vote")
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(name, _)| name.as_str());
        match (weak, lowest) {
            (true, _) => |t| &mut t.moving.weak_vote_us,
            (_, Some(BACKING)) => |t| &mut t.moving.reverse_us,
            (_, Some(TURNING)) => |t| &mut t.moving.turning_us,
            (_, Some("cruise")) => |t| &mut t.moving.cruise_us,
            (_, Some("vehicle")) => |t| &mut t.moving.vehicle_us,
            (_, Some("lateral")) => |t| &mut t.moving.lateral_us,
            _ => match cause {
                SpeedCause::FreeDistance => |t| &mut t.moving.free_distance_us,
                SpeedCause::VerifiedDistance => |t| &mut t.moving.verified_distance_us,
                SpeedCause::Terrain => |t| &mut t.moving.terrain_us,
                SpeedCause::SuspectedDropOff => |t| &mut t.moving.suspected_drop_off_us,
                SpeedCause::NotSaid => |t| &mut t.moving.speed_vote_us,
            },
        }
    }
}

/// The speed limit a manoeuvre's command carries: backing up, and a
/// turning-round's forward legs.
const BACKING: &str = "recovery";
const TURNING: &str = "turning";

/// The limits of the arbiter's own (besides the weak vote's).
const OWN_LIMITS: [&str; 5] = [BACKING, TURNING, "cruise", "vehicle", "lateral"];

/// Picks the [`ArbiterStats`] time counter a command feeds until the next
/// decision.
type TimeCounter = fn(&mut ArbiterStats) -> &mut u64;

/// Counts of decisions.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ArbiterStats {
    pub decisions: u64,
    pub stops_no_votes: u64,
    pub stops_required_stale: u64,
    pub stops_all_forbidden: u64,
    pub stops_no_acceptable: u64,
    /// Stops after recoveries were used up.
    pub stops_stuck: u64,
    /// Decisions that backed the vehicle up.
    pub reverse_commands: u64,
    pub rejected_votes: u64,
    pub stopped: StopTime,
    pub moving: SpeedTime,
    /// The verified distance of the arc driven, decision by decision.
    pub verified: VerifiedDistances,
}

/// The verified distance of the arcs driven forwards (where a behaviour
/// said it), one count per decision: in bins of [`Self::BIN_M`] to
/// [`Self::BINS`] of them (the last holds everything farther), and the
/// least to the centimetre.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct VerifiedDistances {
    pub counts: [u32; Self::BINS],
    pub min_cm: Option<u32>,
}

impl Default for VerifiedDistances {
    fn default() -> Self {
        Self {
            counts: [0; Self::BINS],
            min_cm: None,
        }
    }
}

impl VerifiedDistances {
    pub const BIN_M: f64 = 0.5;
    pub const BINS: usize = 200;

    pub fn record(&mut self, metres: f64) {
        let bin = ((metres / Self::BIN_M) as usize).min(Self::BINS - 1);
        self.counts[bin] = self.counts[bin].saturating_add(1);
        let cm = (metres * 100.0).round().clamp(0.0, f64::from(u32::MAX)) as u32;
        self.min_cm = Some(self.min_cm.map_or(cm, |m| m.min(cm)));
    }

    /// Decisions counted.
    pub fn len(&self) -> u64 {
        self.counts.iter().map(|&c| u64::from(c)).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The least, m.
    pub fn min_m(&self) -> Option<f64> {
        self.min_cm.map(|cm| f64::from(cm) / 100.0)
    }

    /// The median, m: the middle of the bin holding it.
    pub fn median_m(&self) -> Option<f64> {
        let half = self.len().div_ceil(2);
        let mut seen = 0;
        self.counts.iter().enumerate().find_map(|(bin, &c)| {
            seen += u64::from(c);
            (c > 0 && seen >= half).then_some((bin as f64 + 0.5) * Self::BIN_M)
        })
    }
}

#[derive(Debug, Clone)]
struct Input {
    name: String,
    weight: f64,
    required: bool,
    latest: Option<(Utime, Votes)>,
}

/// The arbiter.
#[derive(Debug, Clone)]
pub struct Arbiter {
    config: ArbiterConfig,
    arcs: ArcSet,
    /// The speed driven when nothing asks for less, m/s.
    cruise_mps: f64,
    max_speed_mps: f64,
    timeout_us: Utime,
    inputs: Vec<Input>,
    fused: Vec<f32>,
    vetoed: Vec<bool>,
    smoothed: Vec<f32>,
    kernel: Vec<f32>,
    explain: bool,
    decision: Option<Decision>,
    reason: Reason,
    stats: ArbiterStats,
    recovery: Recovery,
    /// Per arc: the fused vote before vetoes (which way the behaviours
    /// would like to go).
    preference: Vec<f32>,
    /// Per arc: the least backing-up clearance of the fresh votes.
    clearance: Vec<Option<f64>>,
    /// Per arc: the least forward (creeping) clearance of the fresh votes.
    forward: Vec<Option<f64>>,
    /// Per arc: the weighted mean vote of the fresh behaviours that give no
    /// clearance (see [`crate::recovery`]).
    wish: Vec<f32>,
    /// The last command's time and the counter it feeds.
    last_command: Option<(Utime, TimeCounter)>,
    /// The last command's speed was the speed governor's.
    governed: bool,
}

impl Arbiter {
    /// An arbiter over `arcs` for `vehicle`. Call `config.validate()` first.
    pub fn new(config: &ArbiterConfig, arcs: ArcSet, vehicle: &VehicleConfig) -> Self {
        let n = arcs.len();
        let sigma = config.smoothing_sigma_arcs;
        let kernel = if sigma > 0.0 {
            let half = (3.0 * sigma).ceil() as i64;
            (-half..=half)
                .map(|d| (-(d as f64).powi(2) / (2.0 * sigma * sigma)).exp() as f32)
                .collect()
        } else {
            vec![1.0]
        };
        let mut arbiter = Self {
            config: config.clone(),
            arcs,
            cruise_mps: config.cruise_speed_mps,
            max_speed_mps: vehicle.max_speed_mps,
            timeout_us: seconds_to_micros(config.vote_timeout_s),
            inputs: Vec::new(),
            fused: vec![0.0; n],
            vetoed: vec![false; n],
            smoothed: vec![0.0; n],
            kernel,
            explain: false,
            decision: None,
            reason: Reason::Stop {
                stop: StopReason::NoVotes,
                vetoers: Vec::new(),
            },
            stats: ArbiterStats::default(),
            recovery: Recovery::new(&config.recovery, vehicle),
            preference: vec![0.0; n],
            clearance: vec![None; n],
            forward: vec![None; n],
            wish: vec![0.0; n],
            last_command: None,
            governed: false,
        };
        for name in &config.required {
            arbiter.input_index(name);
        }
        arbiter
    }

    pub fn arcs(&self) -> &ArcSet {
        &self.arcs
    }

    pub fn config(&self) -> &ArbiterConfig {
        &self.config
    }

    /// This arbiter driving at `mps` when nothing asks for less, in place of
    /// the `cruise_speed_mps` asked for (what a cap on it allows).
    pub fn cruising_at(mut self, mps: f64) -> Self {
        self.cruise_mps = mps;
        self
    }

    /// The speed driven when nothing asks for less, m/s.
    pub fn cruise_mps(&self) -> f64 {
        self.cruise_mps
    }

    pub fn stats(&self) -> &ArbiterStats {
        &self.stats
    }

    /// What backing up did.
    pub fn recovery_stats(&self) -> &RecoveryStats {
        &self.recovery.stats
    }

    /// True while the arbiter is backing the vehicle up.
    pub fn is_backing_up(&self) -> bool {
        self.recovery.is_backing()
    }

    /// Keeps a [`Decision`] record of every decision (costs copies).
    pub fn set_explain(&mut self, explain: bool) {
        self.explain = explain;
        if !explain {
            self.decision = None;
        }
    }

    /// The record of the last decision, when explaining.
    pub fn decision(&self) -> Option<&Decision> {
        self.decision.as_ref()
    }

    /// Why the last command is what it is (kept whether explaining or not).
    pub fn reason(&self) -> &Reason {
        &self.reason
    }

    fn input_index(&mut self, name: &str) -> usize {
        if let Some(i) = self.inputs.iter().position(|input| input.name == name) {
            return i;
        }
        self.inputs.push(Input {
            name: name.to_owned(),
            weight: self.config.weight(name),
            required: self.config.required.iter().any(|r| r == name),
            latest: None,
        });
        self.inputs.len() - 1
    }

    /// Takes a behaviour's votes (the newest per behaviour is kept; older
    /// votes arriving late do not replace newer ones).
    pub fn on_votes(&mut self, votes: &BehaviourVotes) -> Result<(), VoteSizeError> {
        if votes.votes.len() != self.arcs.len() {
            self.stats.rejected_votes += 1;
            return Err(VoteSizeError {
                behaviour: votes.behaviour.clone(),
                got: votes.votes.len(),
                expected: self.arcs.len(),
            });
        }
        let i = self.input_index(&votes.behaviour);
        match &mut self.inputs[i].latest {
            Some((utime, _)) if *utime > votes.utime => {}
            Some((utime, latest)) => {
                *utime = votes.utime;
                latest.copy_from(&votes.votes);
            }
            slot @ None => *slot = Some((votes.utime, votes.votes.clone())),
        }
        Ok(())
    }

    fn fresh(&self, input: &Input, now: Utime) -> bool {
        input
            .latest
            .as_ref()
            .is_some_and(|(utime, _)| now - *utime <= self.timeout_us)
    }

    /// The inputs whose votes take part in a decision at `now` (weighted
    /// and fresh), with those votes.
    fn used(&self, now: Utime) -> impl Iterator<Item = (&Input, &Votes)> + '_ {
        self.inputs
            .iter()
            .filter(move |input| input.weight > 0.0 && self.fresh(input, now))
            .filter_map(|input| input.latest.as_ref().map(|(_, votes)| (input, votes)))
    }

    /// Whether the speed governor set the last command's speed (a
    /// behaviour's speed vote stopping within the verified distance).
    pub fn governed(&self) -> bool {
        self.governed
    }

    /// Fuses the fresh votes into a command at time `now`; backs the
    /// vehicle up when the way forward stays blocked (see
    /// [`crate::recovery`]).
    pub fn decide(&mut self, now: Utime) -> SteeringCommand {
        self.stats.decisions += 1;
        self.governed = false;
        let mut outcome = self.fuse(now);
        let creep = self.config.recovery.creep_mps;
        if let Some((since, counter)) = self.last_command.take() {
            *counter(&mut self.stats) += u64::try_from(now - since).unwrap_or(0);
        }
        let stop_asked = self
            .used(now)
            .any(|(_, votes)| votes.speed_mps().is_some_and(|s| s <= creep));
        let (blocked, safe) = match &outcome {
            // Standing although arcs are allowed: their speed limits
            // (unseen ground, cells right ahead) hold it, unless some
            // behaviour asks to stop (a mission complete).
            Ok((command, _)) => (command.speed_mps < creep && !stop_asked, true),
            Err(StopReason::AllArcsForbidden { .. } | StopReason::NoAcceptableArc { .. }) => {
                (true, true)
            }
            Err(_) => (false, false),
        };
        let wished = self.gather_clearance(now);
        // Manoeuvres drive the driving arcs; the turns in place at the
        // ends of the set (if any) are read apart, their clearance an angle.
        let driving = self.arcs.driving();
        let turns = self.arcs.turns_in_place().then(|| {
            [0, self.arcs.len() - 1].map(|arc| recovery::TurnArc {
                arc,
                clear: self.forward[arc],
                vote: self.preference[arc],
            })
        });
        let behind = Behind {
            clearance: &self.clearance[driving.clone()],
            forward: &self.forward[driving.clone()],
            preference: &self.preference[driving.clone()],
            wish: wished.then_some(&self.wish[driving.clone()]),
            curvatures: &self.arcs.curvatures()[driving.clone()],
            offset: driving.start,
            turns,
        };
        match self.recovery.step(now, blocked, safe, &behind) {
            recovery::Outcome::Keep => {}
            recovery::Outcome::Drive(command) => {
                let label = if command.is_reverse() {
                    self.stats.reverse_commands += 1;
                    BACKING
                } else {
                    TURNING
                };
                outcome = Ok((command, vec![(label.to_owned(), command.speed_mps.abs())]));
            }
            recovery::Outcome::Exhausted { attempts } => {
                let blocked = match &outcome {
                    Err(reason) => reason.to_string(),
                    Ok(_) => "every allowed arc's speed limit is 0".to_owned(),
                };
                outcome = Err(StopReason::Stuck { attempts, blocked });
            }
        }
        let command = match &outcome {
            Ok((command, _)) => *command,
            Err(reason) => {
                match reason {
                    StopReason::NoVotes => self.stats.stops_no_votes += 1,
                    StopReason::RequiredStale { .. } => self.stats.stops_required_stale += 1,
                    StopReason::AllArcsForbidden { .. } => self.stats.stops_all_forbidden += 1,
                    StopReason::NoAcceptableArc { .. } => self.stats.stops_no_acceptable += 1,
                    StopReason::Stuck { .. } => self.stats.stops_stuck += 1,
                }
                SteeringCommand::stop(now)
            }
        };
        let counter: TimeCounter = match &outcome {
            Err(StopReason::NoVotes) => |t| &mut t.stopped.no_votes_us,
            Err(StopReason::RequiredStale { .. }) => |t| &mut t.stopped.required_stale_us,
            Err(StopReason::AllArcsForbidden { .. }) => |t| &mut t.stopped.all_arcs_forbidden_us,
            Err(StopReason::NoAcceptableArc { .. }) => |t| &mut t.stopped.no_acceptable_arc_us,
            Err(StopReason::Stuck { .. }) => |t| &mut t.stopped.stuck_us,
            Ok((_, limits)) if command.is_stop() && SpeedTime::manoeuvre(limits) => {
                |t| &mut t.stopped.steering_us
            }
            Ok(_) if command.is_stop() && stop_asked => |t| &mut t.stopped.asked_us,
            Ok(_) if command.is_stop() => |t| &mut t.stopped.speed_limited_us,
            Ok((command, limits)) => {
                let arc = command.arc_index;
                if let Some(verified) = arc
                    .filter(|_| !SpeedTime::manoeuvre(limits))
                    .and_then(|arc| self.verified_on(arc, now))
                {
                    self.stats.verified.record(verified);
                }
                let cause = arc.map_or(SpeedCause::NotSaid, |arc| self.speed_cause(arc, now));
                self.governed =
                    cause == SpeedCause::VerifiedDistance && SpeedTime::set_by_vote(limits);
                SpeedTime::binding(limits, cause)
            }
        };
        self.last_command = Some((now, counter));
        self.recovery.sent(now, &command);
        self.reason = match &outcome {
            Err(StopReason::AllArcsForbidden { vetoes }) => Reason::Stop {
                stop: StopReason::AllArcsForbidden {
                    vetoes: vetoes.clone(),
                },
                vetoers: vetoes.clone(),
            },
            Err(stop) => Reason::Stop {
                stop: stop.clone(),
                vetoers: self.vetoers(now),
            },
            Ok((_, limits)) if SpeedTime::manoeuvre(limits) => Reason::Manoeuvre {
                backing: command.is_reverse(),
                standing: command.is_stop(),
                in_place: command.is_turn_in_place(),
            },
            Ok(_) if command.is_stop() => Reason::SpeedLimited {
                asked_by: if stop_asked {
                    self.used(now)
                        .filter(|(_, votes)| votes.speed_mps().is_some_and(|s| s <= creep))
                        .map(|(input, _)| input.name.clone())
                        .collect()
                } else {
                    Vec::new()
                },
            },
            Ok(_) => Reason::Drive,
        };
        if self.explain {
            let (stop, limits) = match outcome {
                Ok((_, limits)) => (None, limits),
                Err(reason) => (Some(reason), Vec::new()),
            };
            self.decision = Some(self.explanation(now, command, stop, limits));
        }
        command
    }

    /// The behaviours whose fresh votes veto arcs at `now`: how many, and
    /// the cell behind the veto of the arc nearest straight ahead.
    fn vetoers(&self, now: Utime) -> Vec<Vetoer> {
        let straight = self.arcs.straight_index();
        self.used(now)
            .filter_map(|(input, votes)| {
                let count = votes.vetoed().iter().filter(|&&v| v).count();
                let nearest_straight = (0..votes.len())
                    .filter(|&i| votes.is_vetoed(i))
                    .min_by_key(|&i| i.abs_diff(straight))?;
                Some(Vetoer {
                    behaviour: input.name.clone(),
                    arcs: count,
                    cause: votes.causes()[nearest_straight],
                })
            })
            .collect()
    }

    /// Per arc, the least clearance, backing up and creeping forwards, the
    /// fresh votes give; and the weighted mean vote of the fresh behaviours
    /// that give none (false when there are none).
    fn gather_clearance(&mut self, now: Utime) -> bool {
        let (mut clearance, mut forward, mut wish) = (
            std::mem::take(&mut self.clearance),
            std::mem::take(&mut self.forward),
            std::mem::take(&mut self.wish),
        );
        clearance.fill(None);
        forward.fill(None);
        wish.fill(0.0);
        let least = |slot: &mut Option<f64>, c: Option<f64>| {
            if let Some(c) = c {
                *slot = Some(slot.map_or(c, |s| s.min(c)));
            }
        };
        let mut weight = 0.0;
        for (input, votes) in self.used(now) {
            let mut judges_ground = false;
            for arc in 0..clearance.len() {
                let (back, ahead) = (votes.reverse_clearance(arc), votes.forward_clearance(arc));
                judges_ground |= back.is_some() || ahead.is_some();
                least(&mut clearance[arc], back);
                least(&mut forward[arc], ahead);
            }
            if !judges_ground {
                weight += input.weight;
                for (w, &v) in wish.iter_mut().zip(votes.values()) {
                    *w += input.weight as f32 * v;
                }
            }
        }
        if weight > 0.0 {
            wish.iter_mut().for_each(|w| *w /= weight as f32);
        }
        (self.clearance, self.forward, self.wish) = (clearance, forward, wish);
        weight > 0.0
    }

    #[allow(clippy::type_complexity)]
    fn fuse(&mut self, now: Utime) -> Result<(SteeringCommand, Vec<(String, f64)>), StopReason> {
        self.smoothed.fill(0.0);
        for input in &self.inputs {
            if input.required && input.weight > 0.0 && !self.fresh(input, now) {
                return Err(StopReason::RequiredStale {
                    behaviour: input.name.clone(),
                    age_us: input.latest.as_ref().map(|(t, _)| now - t),
                });
            }
        }
        self.fused.fill(0.0);
        self.vetoed.fill(false);
        let mut total_weight = 0.0;
        for input in &self.inputs {
            if input.weight <= 0.0 || !self.fresh(input, now) {
                continue;
            }
            let Some((_, votes)) = &input.latest else {
                continue;
            };
            total_weight += input.weight;
            let w = input.weight as f32;
            for ((fused, vetoed), (&vote, &veto)) in self
                .fused
                .iter_mut()
                .zip(self.vetoed.iter_mut())
                .zip(votes.values().iter().zip(votes.vetoed()))
            {
                *fused += w * vote;
                *vetoed |= veto;
            }
        }
        if total_weight <= 0.0 {
            return Err(StopReason::NoVotes);
        }
        let scale = (1.0 / total_weight) as f32;
        for ((fused, preference), &vetoed) in self
            .fused
            .iter_mut()
            .zip(self.preference.iter_mut())
            .zip(&self.vetoed)
        {
            *preference = *fused * scale;
            *fused = if vetoed { -1.0 } else { *fused * scale };
        }
        self.smooth();
        let straight = self.arcs.straight_index();
        let by_vote = |a: usize, b: usize| {
            self.smoothed[a]
                .total_cmp(&self.smoothed[b])
                // Ties: the straighter arc wins.
                .then(b.abs_diff(straight).cmp(&a.abs_diff(straight)))
        };
        // Turns in place are the recovery's to take, never a forward choice.
        let driving = self.arcs.driving();
        let best = driving
            .clone()
            .filter(|&i| !self.vetoed[i])
            .max_by(|&a, &b| by_vote(a, b));
        // Near-ties: the arc that may be driven fastest.
        let margin = self.config.speed_tie_vote as f32;
        let best = best.map(|best| {
            if margin <= 0.0 {
                return best;
            }
            let floor = self.smoothed[best] - margin;
            driving
                .clone()
                .filter(|&i| !self.vetoed[i] && self.smoothed[i] >= floor)
                .map(|i| (i, self.speed_on(i, self.arcs.curvatures()[i], now).0))
                .max_by(|&(a, va), &(b, vb)| va.total_cmp(&vb).then(by_vote(a, b)))
                .map_or(best, |(i, _)| i)
        });
        let Some(best) = best else {
            return Err(StopReason::AllArcsForbidden {
                vetoes: self.vetoers(now),
            });
        };
        let best_vote = self.smoothed[best];
        if f64::from(best_vote) < self.config.min_acceptable_vote {
            return Err(StopReason::NoAcceptableArc { best_vote });
        }
        let curvature = self.peak_curvature(best);
        let (base, mut limits) = self.speed_on(best, curvature, now);
        let slow = self.config.slow_below_vote;
        let floor = self.config.min_acceptable_vote;
        let factor = if f64::from(best_vote) >= slow {
            1.0
        } else {
            ((f64::from(best_vote) - floor) / (slow - floor)).max(self.config.min_speed_fraction)
        };
        if factor < 1.0 {
            limits.push(("weak vote".to_owned(), base * factor));
        }
        Ok((
            SteeringCommand {
                utime: now,
                curvature,
                speed_mps: base * factor,
                arc_index: Some(best),
                vote: best_vote,
                turn_rate_radps: 0.0,
            },
            limits,
        ))
    }

    /// Why the lowest speed a behaviour accepts on arc `arc` is what it
    /// is, where that behaviour said.
    fn speed_cause(&self, arc: usize, now: Utime) -> SpeedCause {
        self.used(now)
            .filter_map(|(_, votes)| {
                let on_arc = votes
                    .arc_speed(arc)
                    .map(|s| (s, votes.arc_speed_cause(arc)));
                let any = votes.speed_mps().map(|s| (s, SpeedCause::NotSaid));
                [on_arc, any]
                    .into_iter()
                    .flatten()
                    .reduce(|a, b| if b.0 < a.0 { b } else { a })
            })
            .reduce(|a, b| if b.0 < a.0 { b } else { a })
            .map_or(SpeedCause::NotSaid, |(_, cause)| cause)
    }

    /// How far along arc `arc` the ground is verified, by the behaviours
    /// that said (the least).
    fn verified_on(&self, arc: usize, now: Utime) -> Option<f64> {
        self.used(now)
            .filter_map(|(_, votes)| votes.verified_distance(arc))
            .reduce(f64::min)
    }

    /// The speed arc `arc` may be driven at, steering `curvature`, and the
    /// limits that set it: the cruise speed, the vehicle's top speed, the
    /// lowest speed a behaviour accepts (on that arc or on any) and the
    /// lateral-acceleration limit `v = √(a_lat/|k|)`.
    fn speed_on(&self, arc: usize, curvature: f64, now: Utime) -> (f64, Vec<(String, f64)>) {
        let mut speed_vote: Option<(String, f64)> = None;
        for (input, votes) in self.used(now) {
            let speeds = votes.speed_mps().into_iter().chain(votes.arc_speed(arc));
            if let Some(speed) = speeds.reduce(f64::min)
                && speed_vote.as_ref().is_none_or(|(_, s)| speed < *s)
            {
                speed_vote = Some((input.name.clone(), speed));
            }
        }
        let mut limits = vec![
            ("cruise".to_owned(), self.cruise_mps),
            ("vehicle".to_owned(), self.max_speed_mps),
        ];
        if let Some((behaviour, speed)) = speed_vote {
            limits.push((behaviour, speed));
        }
        if curvature != 0.0 {
            limits.push((
                "lateral".to_owned(),
                (self.config.max_lateral_accel_mps2 / curvature.abs()).sqrt(),
            ));
        }
        let base = limits.iter().map(|(_, s)| *s).fold(f64::INFINITY, f64::min);
        (base, limits)
    }

    /// Gaussian smoothing of the fused votes across the driving arcs
    /// (vetoed arcs count as -1); a turn in place keeps its own.
    fn smooth(&mut self) {
        let driving = self.arcs.driving();
        let (start, n) = (driving.start as i64, driving.end as i64);
        let half = (self.kernel.len() / 2) as i64;
        for i in 0..self.fused.len() as i64 {
            if !(start..n).contains(&i) {
                self.smoothed[i as usize] = self.fused[i as usize];
                continue;
            }
            let (mut sum, mut weight) = (0.0f32, 0.0f32);
            for (k, &w) in self.kernel.iter().enumerate() {
                let j = i + k as i64 - half;
                if (start..n).contains(&j) {
                    sum += w * self.fused[j as usize];
                    weight += w;
                }
            }
            self.smoothed[i as usize] = sum / weight;
        }
    }

    /// The winning arc's curvature, moved to the peak of the parabola through
    /// it and its neighbours when that is enabled and they are not vetoed.
    fn peak_curvature(&self, best: usize) -> f64 {
        let k = self.arcs.curvatures()[best];
        let driving = self.arcs.driving();
        if !self.config.interpolate_peak || best == driving.start || best + 1 >= driving.end {
            return k;
        }
        if self.vetoed[best - 1] || self.vetoed[best + 1] {
            return k;
        }
        let (a, b, c) = (
            f64::from(self.smoothed[best - 1]),
            f64::from(self.smoothed[best]),
            f64::from(self.smoothed[best + 1]),
        );
        let denominator = a - 2.0 * b + c;
        if denominator >= 0.0 {
            return k;
        }
        let offset = (0.5 * (a - c) / denominator).clamp(-0.5, 0.5);
        k + offset * self.arcs.spacing()
    }

    fn explanation(
        &self,
        now: Utime,
        command: SteeringCommand,
        stop: Option<StopReason>,
        speed_limits: Vec<(String, f64)>,
    ) -> Decision {
        let mut vetoes = vec![Vec::new(); self.arcs.len()];
        let mut inputs = Vec::with_capacity(self.inputs.len());
        for input in &self.inputs {
            let used = input.weight > 0.0 && self.fresh(input, now);
            if let (true, Some((_, votes))) = (used, &input.latest) {
                for (arc, cause) in votes.vetoed().iter().zip(votes.causes()).enumerate() {
                    if *cause.0 {
                        vetoes[arc].push((input.name.clone(), *cause.1));
                    }
                }
            }
            inputs.push(InputExplanation {
                behaviour: input.name.clone(),
                weight: input.weight,
                age_us: input.latest.as_ref().map(|(t, _)| now - t),
                used,
                votes: input.latest.as_ref().map(|(_, v)| v.clone()),
            });
        }
        Decision {
            utime: now,
            command,
            stop,
            fused: self.smoothed.clone(),
            vetoes,
            inputs,
            speed_limits,
        }
    }
}
