//! Two runs' decisions side by side: agreement, the first divergence, the
//! largest curvature difference, and which behaviour moved each change.

use std::collections::BTreeMap;

use arcnav_arbiter::BehaviourVotes;
use arcnav_vehicle::{SteeringCommand, Utime};
use serde::Serialize;

/// One decision of a replay (or of the log it replays): the command and
/// the votes it was fused from.
#[derive(Debug, Clone, PartialEq)]
pub struct Cycle {
    pub command: SteeringCommand,
    pub votes: Vec<BehaviourVotes>,
}

/// Decisions by the run of the log they belong to (0, and one more each
/// time the log starts over: logs concatenated) and their cycle's time.
/// Keyed by time alone, a second run's decisions had replaced the first's.
pub type Decisions = BTreeMap<(u32, Utime), Cycle>;

/// A behaviour's weight by name, for attributing changes.
pub type WeightOf<'a> = &'a dyn Fn(&str) -> f64;

/// A decision that differs between two runs.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Difference {
    /// Seconds from the log's start.
    pub time_s: f64,
    pub utime: Utime,
    pub a: Decided,
    pub b: Decided,
    /// The behaviour whose (weighted) votes moved the choice from a's arc to b's most.
    pub moved_by: Option<String>,
}

/// One side of a difference.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Decided {
    pub arc: Option<usize>,
    pub curvature: f64,
    pub speed_mps: f64,
}

impl From<&SteeringCommand> for Decided {
    fn from(c: &SteeringCommand) -> Self {
        Self {
            arc: c.arc_index,
            curvature: c.curvature,
            speed_mps: c.speed_mps,
        }
    }
}

/// How two runs of a log compare.
#[derive(Debug, Clone, Serialize)]
pub struct Comparison {
    pub a: String,
    pub b: String,
    /// Decisions at the same times in both runs.
    pub compared: usize,
    pub agreeing: usize,
    /// `None` when no decision could be compared: never "100 %" of nothing.
    pub agreement_percent: Option<f64>,
    pub largest_curvature_difference: Option<Difference>,
    pub first_divergence: Option<Difference>,
    pub differences: Vec<Difference>,
}

/// Compares decisions of `a` and `b` at the times both made one.
/// `weights_a`/`weights_b` give each behaviour's weight, to attribute changes.
pub fn compare(
    labels: (&str, &str),
    a: &Decisions,
    b: &Decisions,
    weights: (WeightOf<'_>, WeightOf<'_>),
    origin: Utime,
) -> Comparison {
    let mut differences = Vec::new();
    let mut compared = 0;
    for (t, ca) in a {
        let Some(cb) = b.get(t) else { continue };
        compared += 1;
        // A turn in place's curvature is ±∞ (equal, not near).
        let (ka, kb) = (ca.command.curvature, cb.command.curvature);
        let same = ca.command.arc_index == cb.command.arc_index
            && (ca.command.speed_mps - cb.command.speed_mps).abs() < 1e-6
            && (ka == kb || (ka - kb).abs() < 1e-9)
            && (ca.command.turn_rate_radps - cb.command.turn_rate_radps).abs() < 1e-9;
        if same {
            continue;
        }
        differences.push(Difference {
            time_s: (t.1 - origin) as f64 * 1e-6,
            utime: t.1,
            a: Decided::from(&ca.command),
            b: Decided::from(&cb.command),
            moved_by: attribute(ca, cb, weights),
        });
    }
    let largest = differences
        .iter()
        .max_by(|x, y| {
            let apart = |d: &Difference| {
                if d.a.curvature == d.b.curvature {
                    0.0
                } else {
                    (d.a.curvature - d.b.curvature).abs()
                }
            };
            apart(x).total_cmp(&apart(y))
        })
        .cloned();
    Comparison {
        a: labels.0.to_owned(),
        b: labels.1.to_owned(),
        compared,
        agreeing: compared - differences.len(),
        agreement_percent: (compared > 0)
            .then(|| 100.0 * (compared - differences.len()) as f64 / compared as f64),
        largest_curvature_difference: largest,
        first_divergence: differences.first().cloned(),
        differences,
    }
}

/// Which behaviour's weighted votes moved the choice from a's arc to b's
/// most: for each behaviour, how much more it favours b's arc over a's in
/// run b than in run a.
fn attribute(a: &Cycle, b: &Cycle, weights: (WeightOf<'_>, WeightOf<'_>)) -> Option<String> {
    let (arc_a, arc_b) = (a.command.arc_index?, b.command.arc_index?);
    let preference = |cycle: &Cycle, name: &str, weight: f64| -> f64 {
        cycle
            .votes
            .iter()
            .find(|v| v.behaviour == name)
            .map_or(0.0, |v| {
                weight
                    * f64::from(
                        v.votes.vote(arc_b).unwrap_or(0.0) - v.votes.vote(arc_a).unwrap_or(0.0),
                    )
            })
    };
    let mut names: Vec<&str> = a
        .votes
        .iter()
        .chain(&b.votes)
        .map(|v| v.behaviour.as_str())
        .collect();
    names.sort_unstable();
    names.dedup();
    names
        .into_iter()
        .map(|name| {
            (
                name,
                preference(b, name, (weights.1)(name)) - preference(a, name, (weights.0)(name)),
            )
        })
        .filter(|(_, shift)| *shift > 1e-9)
        .max_by(|x, y| x.1.total_cmp(&y.1))
        .map(|(name, _)| name.to_owned())
}
