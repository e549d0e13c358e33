//! The configured behaviours voting on one cycle (002 §6).

use arcnav_arbiter::{BehaviourVotes, Votes};
use arcnav_behaviours::{Behaviour, Mission, Overlay, Progress, VoteContext};
use arcnav_localmap::MapSnapshot;
use arcnav_vehicle::{ArcSet, Pose, SteeringCommand, Utime};

/// Behaviours voting over one arc set: snapshot + pose + mission → one vote
/// set each. Every executor, benchmark and test that makes behaviours vote
/// uses this type; it owns the vote buffers (allocated once) and what the
/// behaviours see besides the map: the mission and the last command.
pub struct BehaviourSet {
    behaviours: Vec<Box<dyn Behaviour>>,
    votes: Vec<BehaviourVotes>,
    mission: Mission,
    arcs: ArcSet,
    last_command: Option<SteeringCommand>,
    /// Map resets seen so far (see [`BehaviourSet::on_cycle`]).
    resets: u64,
}

impl BehaviourSet {
    pub fn new(behaviours: Vec<Box<dyn Behaviour>>, arcs: ArcSet) -> Self {
        let votes = behaviours
            .iter()
            .map(|b| BehaviourVotes {
                behaviour: b.name().to_owned(),
                utime: 0,
                votes: Votes::new(arcs.len()),
            })
            .collect();
        Self {
            behaviours,
            votes,
            mission: Mission::default(),
            arcs,
            last_command: None,
            resets: 0,
        }
    }

    /// The behaviours' names, in voting order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.behaviours.iter().map(|b| b.name())
    }

    pub fn arcs(&self) -> &ArcSet {
        &self.arcs
    }

    pub fn on_waypoints(&mut self, mission: Mission) {
        self.mission = mission;
    }

    pub fn mission(&self) -> &Mission {
        &self.mission
    }

    /// Every behaviour votes at `now` on `map` (in the vehicle frame of
    /// `pose`). After a map reset (`resets` changed since the last call)
    /// each first forgets what it carried between cycles.
    pub fn on_cycle(
        &mut self,
        resets: u64,
        now: Utime,
        pose: &Pose,
        map: &MapSnapshot,
    ) -> &[BehaviourVotes] {
        if resets != self.resets {
            self.resets = resets;
            self.reset();
        }
        self.vote(now, pose, map)
    }

    /// Every behaviour votes at `now` on `map`: the votes cast, in voting
    /// order (a behaviour that [abstained](Behaviour::abstained) is left out).
    pub fn vote(&mut self, now: Utime, pose: &Pose, map: &MapSnapshot) -> &[BehaviourVotes] {
        let ctx = VoteContext {
            utime: now,
            pose,
            map,
            mission: &self.mission,
            arcs: &self.arcs,
            last_command: self.last_command.as_ref(),
        };
        // The votes cast fill the buffers from the front: with nobody
        // abstaining each behaviour keeps its own buffer (and its name).
        let mut cast = 0;
        for behaviour in &mut self.behaviours {
            let out = &mut self.votes[cast];
            out.votes.clear();
            out.utime = now;
            behaviour.vote(&ctx, &mut out.votes);
            if behaviour.abstained() {
                continue;
            }
            if out.behaviour != behaviour.name() {
                out.behaviour.clear();
                out.behaviour.push_str(behaviour.name());
            }
            cast += 1;
        }
        &self.votes[..cast]
    }

    /// Behaviours that can no longer vote, by name, with why.
    pub fn faults(&self) -> Vec<(&str, &str)> {
        self.behaviours
            .iter()
            .filter_map(|b| b.fault().map(|why| (b.name(), why)))
            .collect()
    }

    /// Adds a behaviour, voting after those already in the set (an
    /// external program's, which executors start themselves).
    pub fn push(&mut self, behaviour: Box<dyn Behaviour>) {
        self.votes.push(BehaviourVotes {
            behaviour: behaviour.name().to_owned(),
            utime: 0,
            votes: Votes::new(self.arcs.len()),
        });
        self.behaviours.push(behaviour);
    }

    /// What each behaviour's last vote rested on, by name, in the vehicle
    /// frame of `pose` (the pose of that vote): those that show nothing
    /// left out. For pictures ([`Behaviour::overlay`]).
    pub fn overlays(&self, pose: &Pose) -> Vec<(String, Overlay)> {
        self.behaviours
            .iter()
            .map(|b| (b.name().to_owned(), b.overlay(pose)))
            .filter(|(_, o)| !o.is_empty())
            .collect()
    }

    /// The command the arbiter sent: every behaviour is debriefed, and the
    /// next vote sees it as the last command.
    pub fn on_command(&mut self, command: &SteeringCommand) {
        for behaviour in &mut self.behaviours {
            behaviour.debrief(command);
        }
        self.last_command = Some(*command);
    }

    /// The last command the arbiter sent.
    pub fn last_command(&self) -> Option<&SteeringCommand> {
        self.last_command.as_ref()
    }

    /// Forgets state carried between cycles (map reset, new mission).
    pub fn reset(&mut self) {
        for behaviour in &mut self.behaviours {
            behaviour.reset();
        }
    }

    /// Each behaviour's counters (those that keep any), by behaviour name.
    pub fn counters(&self) -> Vec<(String, Vec<(&'static str, u64)>)> {
        self.behaviours
            .iter()
            .map(|b| (b.name().to_owned(), b.counters()))
            .filter(|(_, counters)| !counters.is_empty())
            .collect()
    }

    /// How many waypoints the behaviours found no route to (live status
    /// lines and `--stats`: `unreachable_waypoints`).
    pub fn unreachable(&self) -> usize {
        self.behaviours.iter().map(|b| b.no_routes().len()).sum()
    }

    /// The waypoints the behaviours found no route to, with the evidence.
    pub fn no_routes(&self) -> Vec<arcnav_behaviours::NoRoute> {
        self.behaviours
            .iter()
            .flat_map(|b| b.no_routes().iter().cloned())
            .collect()
    }

    /// The mission's progress: of the behaviours that follow waypoints,
    /// the one that has come furthest (ended, or the most waypoints
    /// behind it). Goal seeking follows them weighted 0 too, and cannot
    /// tell that the route gave one up.
    pub fn progress(&self) -> Option<Progress> {
        self.behaviours
            .iter()
            .filter_map(|b| b.progress())
            .max_by_key(|p| (p.complete || p.unreachable, p.current))
    }
}
