//! One behaviour's votes over the arc set.

use arcnav_vehicle::Utime;

/// `value`, with negative values and NaN (no number of m/s or metres) as 0.
fn zero_or_more(value: f64) -> f64 {
    if value.is_nan() { 0.0 } else { value.max(0.0) }
}

/// A clearance nobody gave.
const NO_OPINION: f32 = -1.0;

/// `metres` as a stored clearance (negative or NaN: 0).
fn clearance_slot(slot: Option<&mut f32>, metres: f64) {
    if let Some(clear) = slot {
        *clear = zero_or_more(metres) as f32;
    }
}

/// A stored clearance, if one was given.
fn clearance_of(slots: &[f32], index: usize) -> Option<f64> {
    slots
        .get(index)
        .filter(|&&m| m >= 0.0)
        .map(|&m| f64::from(m))
}

/// Why a behaviour limits an arc's speed, where it says. Kept with the
/// votes in memory (every executor's arbiter reads it there); the votes'
/// message does not carry it, so votes read from the bus say nothing.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum SpeedCause {
    #[default]
    NotSaid,
    /// Stopping within the arc's free distance (to the first cell).
    FreeDistance,
    /// Stopping within the arc's verified distance (to the first ground
    /// not seen, or seen only where a hole may hide).
    VerifiedDistance,
    /// The terrain's severity along the arc.
    Terrain,
    /// Slowing for a suspected drop-off along the arc.
    SuspectedDropOff,
}

impl SpeedCause {
    /// How reports name it.
    pub fn name(self) -> &'static str {
        match self {
            Self::NotSaid => "speed vote",
            Self::FreeDistance => "free distance",
            Self::VerifiedDistance => "verified distance",
            Self::Terrain => "terrain",
            Self::SuspectedDropOff => "suspected drop-off",
        }
    }
}

/// What makes an arc forbidden, where a behaviour says.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VetoCause {
    /// A map cell, its centre in the vehicle frame of the cycle, m.
    Cell([f32; 2]),
    /// The operating area's edge: where the arc's swept footprint first
    /// leaves the area, vehicle frame of the cycle, m.
    AreaEdge([f32; 2]),
}

impl VetoCause {
    /// Where it is, vehicle frame, m.
    pub fn at(&self) -> [f32; 2] {
        match *self {
            Self::Cell(at) | Self::AreaEdge(at) => at,
        }
    }
}

impl std::fmt::Display for VetoCause {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Cell([x, y]) => write!(f, "the cell at ({x:.1}, {y:.1}) m"),
            Self::AreaEdge([x, y]) => write!(f, "the operating area's edge at ({x:.1}, {y:.1}) m"),
        }
    }
}

/// What a behaviour thinks of every arc: a vote in [-1, 1] per arc (index
/// order of the `ArcSet`), arcs it forbids outright (a veto: no weighted sum
/// can make such an arc win), the map cell that caused each veto, an
/// optional speed limit, and — for behaviours that check the ground — how
/// far the vehicle can drive along each arc, forwards and backing up, at a
/// crawl (the manoeuvres of [`crate::recovery`]). Buffers are sized
/// once for the arc set; behaviours fill them in place.
#[derive(Debug, Clone, PartialEq)]
pub struct Votes {
    values: Vec<f32>,
    vetoed: Vec<bool>,
    causes: Vec<Option<VetoCause>>,
    speed_mps: Option<f64>,
    /// Per arc: the highest speed accepted on it (∞: no limit), and why.
    arc_speeds: Vec<f32>,
    speed_causes: Vec<SpeedCause>,
    /// Per arc: how far along it the ground is verified, m (negative: not
    /// said). In memory only, as the speed causes.
    verified: Vec<f32>,
    /// Per arc: metres the vehicle may back up along it (negative: no opinion).
    reverse_clear: Vec<f32>,
    /// Per arc: metres the vehicle may creep forwards along it, however
    /// close that is (negative: no opinion).
    forward_clear: Vec<f32>,
}

impl Votes {
    /// Neutral votes (0, no veto, no speed) for `arcs` arcs.
    pub fn new(arcs: usize) -> Self {
        Self {
            values: vec![0.0; arcs],
            vetoed: vec![false; arcs],
            causes: vec![None; arcs],
            speed_mps: None,
            arc_speeds: vec![f32::INFINITY; arcs],
            speed_causes: vec![SpeedCause::NotSaid; arcs],
            verified: vec![NO_OPINION; arcs],
            reverse_clear: vec![NO_OPINION; arcs],
            forward_clear: vec![NO_OPINION; arcs],
        }
    }

    pub fn len(&self) -> usize {
        self.values.len()
    }

    pub fn is_empty(&self) -> bool {
        self.values.is_empty()
    }

    /// Back to neutral, keeping the buffers.
    pub fn clear(&mut self) {
        self.values.fill(0.0);
        self.vetoed.fill(false);
        self.causes.fill(None);
        self.speed_mps = None;
        self.arc_speeds.fill(f32::INFINITY);
        self.speed_causes.fill(SpeedCause::NotSaid);
        self.verified.fill(NO_OPINION);
        self.reverse_clear.fill(NO_OPINION);
        self.forward_clear.fill(NO_OPINION);
    }

    /// Arc `index` back to neutral (a behaviour judging it afresh).
    pub fn reset(&mut self, index: usize) {
        if index < self.values.len() {
            self.values[index] = 0.0;
            self.vetoed[index] = false;
            self.causes[index] = None;
            self.arc_speeds[index] = f32::INFINITY;
            self.speed_causes[index] = SpeedCause::NotSaid;
            self.verified[index] = NO_OPINION;
            self.reverse_clear[index] = NO_OPINION;
            self.forward_clear[index] = NO_OPINION;
        }
    }

    /// Sets the vote of arc `index`, clamped to [-1, 1] (NaN counts as -1).
    pub fn set(&mut self, index: usize, vote: f32) {
        if let Some(v) = self.values.get_mut(index) {
            *v = if vote.is_nan() {
                -1.0
            } else {
                vote.clamp(-1.0, 1.0)
            };
        }
    }

    /// Forbids arc `index` (its vote becomes -1); `cell` is the vehicle-frame
    /// position of the map cell that makes it forbidden, if known.
    pub fn veto(&mut self, index: usize, cell: Option<[f32; 2]>) {
        self.veto_for(index, cell.map(VetoCause::Cell));
    }

    /// Forbids arc `index` (its vote becomes -1) for `cause`, if known.
    pub fn veto_for(&mut self, index: usize, cause: Option<VetoCause>) {
        if index < self.values.len() {
            self.values[index] = -1.0;
            self.vetoed[index] = true;
            self.causes[index] = cause;
        }
    }

    /// Votes the highest speed this behaviour accepts, m/s (negative: 0).
    pub fn vote_speed(&mut self, speed_mps: f64) {
        self.speed_mps = Some(zero_or_more(speed_mps));
    }

    /// The highest speed this behaviour accepts on arc `index`, m/s
    /// (negative or NaN: 0): applies when that arc is driven.
    pub fn limit_arc_speed(&mut self, index: usize, speed_mps: f64) {
        self.limit_arc_speed_for(index, speed_mps, SpeedCause::NotSaid);
    }

    /// [`Votes::limit_arc_speed`], saying why.
    pub fn limit_arc_speed_for(&mut self, index: usize, speed_mps: f64, cause: SpeedCause) {
        if let Some(limit) = self.arc_speeds.get_mut(index) {
            *limit = zero_or_more(speed_mps) as f32;
            self.speed_causes[index] = cause;
        }
    }

    /// Why arc `index`'s speed is limited, where said.
    pub fn arc_speed_cause(&self, index: usize) -> SpeedCause {
        self.speed_causes
            .get(index)
            .copied()
            .unwrap_or(SpeedCause::NotSaid)
    }

    /// How far along arc `index` the ground is verified, m (negative or
    /// NaN: 0).
    pub fn set_verified_distance(&mut self, index: usize, metres: f64) {
        clearance_slot(self.verified.get_mut(index), metres);
    }

    /// How far along arc `index` the ground is verified, if said.
    pub fn verified_distance(&self, index: usize) -> Option<f64> {
        clearance_of(&self.verified, index)
    }

    /// The speed limit on arc `index`, if this behaviour set one.
    pub fn arc_speed(&self, index: usize) -> Option<f64> {
        self.arc_speeds
            .get(index)
            .filter(|s| s.is_finite())
            .map(|&s| f64::from(s))
    }

    /// How far the vehicle may back up along arc `index` (its curvature,
    /// driven backwards), m (negative or NaN: 0). Behaviours that never set
    /// it have no opinion on backing up.
    pub fn set_reverse_clearance(&mut self, index: usize, metres: f64) {
        clearance_slot(self.reverse_clear.get_mut(index), metres);
    }

    /// How far the vehicle may back up along arc `index`, if this behaviour
    /// said.
    pub fn reverse_clearance(&self, index: usize) -> Option<f64> {
        clearance_of(&self.reverse_clear, index)
    }

    /// How far the vehicle may creep forwards along arc `index` before it
    /// meets what this behaviour forbids, m (negative or NaN: 0) — however
    /// close that is: an arc vetoed for driving at speed may still take a
    /// turning manoeuvre's short leg.
    pub fn set_forward_clearance(&mut self, index: usize, metres: f64) {
        clearance_slot(self.forward_clear.get_mut(index), metres);
    }

    /// How far the vehicle may creep forwards along arc `index`, if this
    /// behaviour said.
    pub fn forward_clearance(&self, index: usize) -> Option<f64> {
        clearance_of(&self.forward_clear, index)
    }

    /// Per arc: the forward clearance, negative where none was given.
    pub fn forward_clearances(&self) -> &[f32] {
        &self.forward_clear
    }

    /// Per arc: the backing-up clearance, negative where none was given.
    pub fn reverse_clearances(&self) -> &[f32] {
        &self.reverse_clear
    }

    /// Per arc: the speed limit, ∞ where none.
    pub fn arc_speeds(&self) -> &[f32] {
        &self.arc_speeds
    }

    pub fn values(&self) -> &[f32] {
        &self.values
    }

    pub fn vetoed(&self) -> &[bool] {
        &self.vetoed
    }

    pub fn causes(&self) -> &[Option<VetoCause>] {
        &self.causes
    }

    pub fn speed_mps(&self) -> Option<f64> {
        self.speed_mps
    }

    pub fn vote(&self, index: usize) -> Option<f32> {
        self.values.get(index).copied()
    }

    pub fn is_vetoed(&self, index: usize) -> bool {
        self.vetoed.get(index).copied().unwrap_or(false)
    }

    /// Copies `other` into these buffers (same arc count).
    pub fn copy_from(&mut self, other: &Votes) {
        self.values.clone_from(&other.values);
        self.vetoed.clone_from(&other.vetoed);
        self.causes.clone_from(&other.causes);
        self.speed_mps = other.speed_mps;
        self.arc_speeds.clone_from(&other.arc_speeds);
        self.speed_causes.clone_from(&other.speed_causes);
        self.verified.clone_from(&other.verified);
        self.reverse_clear.clone_from(&other.reverse_clear);
        self.forward_clear.clone_from(&other.forward_clear);
    }
}

/// Votes as the arbiter receives them: whose, and when they were cast.
#[derive(Debug, Clone, PartialEq)]
pub struct BehaviourVotes {
    pub behaviour: String,
    /// When the votes were cast.
    pub utime: Utime,
    pub votes: Votes,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn votes_are_clamped_and_vetoes_are_minus_one() {
        let mut v = Votes::new(5);
        v.set(0, 3.0);
        v.set(1, -7.0);
        v.set(2, f32::NAN);
        v.veto(3, Some([5.0, 0.0]));
        v.set(9, 1.0);
        assert_eq!(v.values(), [1.0, -1.0, -1.0, -1.0, 0.0]);
        assert_eq!(v.vetoed(), [false, false, false, true, false]);
        assert_eq!(v.causes()[3], Some(VetoCause::Cell([5.0, 0.0])));
        v.vote_speed(-2.0);
        assert_eq!(v.speed_mps(), Some(0.0));
        v.limit_arc_speed(1, 3.5);
        v.limit_arc_speed(2, f64::NAN);
        v.limit_arc_speed(7, 1.0);
        assert_eq!(
            (v.arc_speed(0), v.arc_speed(1), v.arc_speed(2)),
            (None, Some(3.5), Some(0.0))
        );
        v.set_reverse_clearance(0, 2.5);
        v.set_reverse_clearance(1, f64::NAN);
        assert_eq!(
            (
                v.reverse_clearance(0),
                v.reverse_clearance(1),
                v.reverse_clearance(2)
            ),
            (Some(2.5), Some(0.0), None)
        );
        v.set_forward_clearance(3, 1.25);
        v.set_forward_clearance(4, -3.0);
        assert_eq!(
            (
                v.forward_clearance(3),
                v.forward_clearance(4),
                v.forward_clearance(0)
            ),
            (Some(1.25), Some(0.0), None)
        );
        v.clear();
        assert_eq!(v, Votes::new(5));
    }
}
