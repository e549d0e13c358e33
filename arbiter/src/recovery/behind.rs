//! What the arbiter knows of the ground and the behaviours' wishes at one
//! decision, and the legs of a manoeuvre chosen from it.

/// A turn round goes the other way when the way lies ahead on that side
/// with at least this vote for that side's hardest arc. The vote is the
/// cosine of the angle between the heading that arc leaves and the way;
/// with the hardest arc turning the heading about 57° over the 8 m
/// lookahead, 0.3 (73°) puts the way within about 130° of the heading on
/// that side (a vote of 0: within 147°). A way just beside (a vote near 0,
/// where a route's plan swinging between the two ends of a ditch puts it
/// for a few seconds) does not reverse the turn: reversed for it, the turn
/// went on the long way when the plan swung back (`ledge_north`, the ERIM
/// at the default speed, noise seed 3: stuck after turning 342°).
pub(super) const AHEAD_VOTE: f32 = 0.3;

/// What the arbiter knows of the ground and the behaviours' wishes at one
/// decision.
pub(crate) struct Behind<'a> {
    /// Per arc: the least backing-up clearance any fresh behaviour gave
    /// (`None`: nobody had an opinion).
    pub clearance: &'a [Option<f64>],
    /// Per arc: the least forward (creeping) clearance any fresh behaviour
    /// gave.
    pub forward: &'a [Option<f64>],
    /// Per arc: the fused vote before vetoes.
    pub preference: &'a [f32],
    /// Per arc: the weighted mean vote of the fresh behaviours that judge
    /// no ground (give no clearance): where the vehicle wants to go (`None`:
    /// no such behaviour voted).
    pub wish: Option<&'a [f32]>,
    /// The driving arcs' curvatures (these slices' arcs).
    pub curvatures: &'a [f64],
    /// Index in the arc set of these slices' first arc (the arcs before
    /// it turn in place).
    pub offset: usize,
    /// The turns in place, right and left.
    pub turns: Option<[TurnArc; 2]>,
}

/// A turn in place as the arbiter knows it at one decision.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct TurnArc {
    /// Its index in the arc set.
    pub arc: usize,
    /// The angle the behaviours judging ground found it clear, radians.
    pub clear: Option<f64>,
    /// Its fused vote.
    pub vote: f32,
}

impl Behind<'_> {
    /// The turn in place towards `side` (+1 left, -1 right), if the arc
    /// set has turns in place.
    pub(super) fn turn(&self, side: f64) -> Option<TurnArc> {
        let [right, left] = self.turns?;
        Some(if side > 0.0 { left } else { right })
    }

    /// The clearance along `arc` driven forwards or backing up.
    pub(super) fn clear(&self, arc: usize, reverse: bool) -> Option<f64> {
        let side = if reverse {
            self.clearance
        } else {
            self.forward
        };
        side.get(arc).copied().flatten()
    }

    /// What the vehicle wants: the wished-for arc's curvature as a
    /// fraction of the hardest arc's (-1 hard right .. 1 hard left; ties go
    /// to the straighter arc), and its wish vote.
    pub(super) fn wished(&self) -> Option<Wish> {
        let wish = self.wish?;
        let n = wish.len().min(self.curvatures.len());
        let straight = n / 2;
        let best = (0..n).max_by(|&a, &b| {
            wish[a]
                .total_cmp(&wish[b])
                .then(b.abs_diff(straight).cmp(&a.abs_diff(straight)))
                .then(b.cmp(&a))
        })?;
        let hardest = self.curvatures.iter().fold(0.0f64, |m, k| m.max(k.abs()));
        let left: f32 = wish[straight + 1..n].iter().sum();
        let right: f32 = wish[..straight].iter().sum();
        (hardest > 0.0).then(|| Wish {
            turn: self.curvatures[best] / hardest,
            vote: wish[best],
            better_side: if left >= right { 1.0 } else { -1.0 },
        })
    }
}

/// Where the behaviours that judge no ground want the vehicle to go.
#[derive(Debug, Clone, Copy)]
pub(super) struct Wish {
    /// The wished-for arc's curvature over the hardest arc's.
    pub(super) turn: f64,
    /// Its vote: below 0 every arc leads away (the way lies behind).
    pub(super) vote: f32,
    /// +1 when the left arcs are liked better than the right ones, else -1.
    pub(super) better_side: f64,
}

impl Wish {
    /// The side to turn round towards, when the way lies beyond the arcs:
    /// the hardest arc is wished for, or every arc leads away.
    pub(super) fn beyond_the_arcs(&self) -> Option<f64> {
        if self.turn.abs() >= 1.0 - 1e-9 {
            Some(self.turn.signum())
        } else if self.vote < 0.0 {
            Some(self.better_side)
        } else {
            None
        }
    }

    /// Whether the way lies ahead on the side `-side` (opposite the
    /// turn's): that side's hardest arc is wished for, with a vote of at
    /// least [`AHEAD_VOTE`].
    pub(super) fn ahead_on_the_other_side(&self, side: f64) -> bool {
        self.turn * side <= -1.0 + 1e-9 && self.vote >= AHEAD_VOTE
    }
}

/// One leg of a manoeuvre along an arc at a crawl.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Leg {
    pub(super) arc: usize,
    pub(super) curvature: f64,
    pub(super) reverse: bool,
    /// Distance to drive, m.
    pub(super) goal_m: f64,
    pub(super) done_m: f64,
}

impl Leg {
    /// A leg of `goal_m` along `arc`, backing up when `reverse`.
    pub(super) fn along(arc: usize, behind: &Behind<'_>, reverse: bool, goal_m: f64) -> Self {
        Self {
            arc,
            curvature: behind.curvatures[arc],
            reverse,
            goal_m,
            done_m: 0.0,
        }
    }
}
