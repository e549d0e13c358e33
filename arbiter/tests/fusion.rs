//! DAMN fusion: weights, vetoes, smoothing, staleness, speed, explanations.

use arcnav_arbiter::{
    Arbiter, ArbiterConfig, BehaviourVotes, Reason, StopReason, VetoCause, Vetoer, Votes,
};
use arcnav_vehicle::{ArcSet, ArcSetConfig, VehicleConfig};

const SECOND: i64 = 1_000_000;

fn arbiter(config: ArbiterConfig) -> Arbiter {
    config.validate().unwrap();
    Arbiter::new(
        &config,
        ArcSet::new(&ArcSetConfig::default()).unwrap(),
        &VehicleConfig::default(),
    )
}

/// No smoothing; goal seeking weighted 0.5, as 002 weighted it (the
/// shipped defaults give that weight to the route behaviour).
fn plain() -> ArbiterConfig {
    let mut config = ArbiterConfig {
        smoothing_sigma_arcs: 0.0,
        ..Default::default()
    };
    config.weights.insert("goal_seeking".into(), 0.5);
    config
}

fn votes(behaviour: &str, utime: i64, f: impl Fn(usize) -> f32) -> BehaviourVotes {
    let mut v = Votes::new(39);
    for i in 0..39 {
        v.set(i, f(i));
    }
    BehaviourVotes {
        behaviour: behaviour.into(),
        utime,
        votes: v,
    }
}

#[test]
fn the_weighted_sum_decides() {
    let mut a = arbiter(plain());
    // Obstacle avoidance (weight 1) likes the right (index 10), goal seeking
    // (weight 0.5) the left (index 30).
    a.on_votes(&votes("obstacle_avoidance", 0, |i| {
        if i == 10 { 1.0 } else { 0.2 }
    }))
    .unwrap();
    a.on_votes(&votes(
        "goal_seeking",
        0,
        |i| if i == 30 { 1.0 } else { 0.0 },
    ))
    .unwrap();
    let command = a.decide(0);
    assert_eq!(
        command.arc_index,
        Some(10),
        "1.0·1 + 0.5·0 beats 1.0·0.2 + 0.5·1"
    );
    assert!(
        (command.vote - 1.0 / 1.5).abs() < 1e-6,
        "normalised by the total weight"
    );
    // With goal seeking weighted 2, the left wins.
    let mut config = plain();
    config.weights.insert("goal_seeking".into(), 2.0);
    let mut a = arbiter(config);
    a.on_votes(&votes("obstacle_avoidance", 0, |i| {
        if i == 10 { 1.0 } else { 0.2 }
    }))
    .unwrap();
    a.on_votes(&votes(
        "goal_seeking",
        0,
        |i| if i == 30 { 1.0 } else { 0.0 },
    ))
    .unwrap();
    assert_eq!(a.decide(0).arc_index, Some(30));
}

#[test]
fn a_veto_beats_a_high_weighted_sum() {
    let mut config = plain();
    config.weights.insert("goal_seeking".into(), 10.0);
    let mut a = arbiter(config);
    let mut avoid = votes("obstacle_avoidance", 0, |_| 0.5);
    avoid.votes.veto(30, Some([5.0, 1.0]));
    a.on_votes(&avoid).unwrap();
    a.on_votes(&votes(
        "goal_seeking",
        0,
        |i| if i == 30 { 1.0 } else { -1.0 },
    ))
    .unwrap();
    a.set_explain(true);
    let command = a.decide(0);
    assert_ne!(command.arc_index, Some(30));
    let decision = a.decision().unwrap();
    assert_eq!(
        decision.vetoes[30],
        [(
            "obstacle_avoidance".to_owned(),
            Some(VetoCause::Cell([5.0, 1.0]))
        )]
    );
    assert_eq!(decision.fused[30], -1.0);
}

#[test]
fn a_weight_of_zero_skips_a_behaviour_and_its_vetoes() {
    let mut config = plain();
    config.weights.insert("goal_seeking".into(), 0.0);
    let mut a = arbiter(config);
    a.on_votes(&votes("obstacle_avoidance", 0, |i| {
        if i == 5 { 1.0 } else { 0.0 }
    }))
    .unwrap();
    let mut goal = votes("goal_seeking", 0, |_| 1.0);
    goal.votes.veto(5, None);
    a.on_votes(&goal).unwrap();
    assert_eq!(a.decide(0).arc_index, Some(5));
}

#[test]
fn stale_votes_are_ignored_and_a_stale_required_behaviour_stops_the_vehicle() {
    let mut a = arbiter(plain());
    a.set_explain(true);
    a.on_votes(&votes("obstacle_avoidance", 0, |_| 1.0))
        .unwrap();
    a.on_votes(&votes(
        "goal_seeking",
        0,
        |i| if i == 30 { 1.0 } else { 0.0 },
    ))
    .unwrap();
    a.on_votes(&votes("goal_seeking", SECOND / 2, |i| {
        if i == 8 { 1.0 } else { 0.0 }
    }))
    .unwrap();
    // An older vote arriving late does not replace the newer one.
    a.on_votes(&votes("goal_seeking", SECOND / 4, |i| {
        if i == 30 { 1.0 } else { 0.0 }
    }))
    .unwrap();
    assert_eq!(a.decide(SECOND / 2).arc_index, Some(8));
    // 1.2 s after obstacle avoidance last voted (timeout 1 s): stop.
    let command = a.decide(SECOND + SECOND / 5);
    assert!(command.is_stop());
    assert_eq!(command.speed_mps, 0.0);
    assert_eq!(
        a.decision().unwrap().stop,
        Some(StopReason::RequiredStale {
            behaviour: "obstacle_avoidance".into(),
            age_us: Some(1_200_000)
        })
    );
    // A required behaviour that never voted stops it too.
    let mut a = arbiter(plain());
    a.on_votes(&votes("goal_seeking", 0, |_| 1.0)).unwrap();
    assert!(a.decide(0).is_stop());
    assert_eq!(a.stats().stops_required_stale, 1);
}

#[test]
fn all_arcs_forbidden_means_stop_with_speed_zero_and_says_who() {
    let mut a = arbiter(plain());
    a.set_explain(true);
    let mut avoid = votes("obstacle_avoidance", 0, |_| 1.0);
    for i in 0..39 {
        avoid.votes.veto(i, Some([3.0, 0.0]));
    }
    a.on_votes(&avoid).unwrap();
    let command = a.decide(0);
    assert!(command.is_stop());
    assert_eq!((command.speed_mps, command.arc_index), (0.0, None));
    assert_eq!(
        a.decision().unwrap().stop,
        Some(StopReason::AllArcsForbidden {
            vetoes: vec![Vetoer {
                behaviour: "obstacle_avoidance".into(),
                arcs: 39,
                cause: Some(VetoCause::Cell([3.0, 0.0])),
            }]
        })
    );
    assert_eq!(
        a.decision().unwrap().stop.as_ref().unwrap().to_string(),
        "every arc is forbidden (obstacle_avoidance vetoed 39, for the cell at (3.0, 0.0) m)"
    );
    // Kept whether explaining or not, as DECISION carries it.
    let Reason::Stop { stop, vetoers } = a.reason() else {
        panic!("{:?}", a.reason());
    };
    assert_eq!(Some(stop), a.decision().unwrap().stop.as_ref());
    assert_eq!(vetoers.len(), 1);
    assert_eq!(vetoers[0].cause, Some(VetoCause::Cell([3.0, 0.0])));
}

#[test]
fn no_acceptable_arc_means_stop() {
    let mut a = arbiter(plain());
    a.on_votes(&votes("obstacle_avoidance", 0, |_| -0.8))
        .unwrap();
    assert!(a.decide(0).is_stop());
    assert_eq!(a.stats().stops_no_acceptable, 1);
}

#[test]
fn the_same_inputs_give_the_same_decision() {
    let run = || {
        let mut a = arbiter(ArbiterConfig::default());
        a.on_votes(&votes("obstacle_avoidance", 0, |i| {
            ((i * 7919) % 13) as f32 / 13.0
        }))
        .unwrap();
        a.on_votes(&votes("goal_seeking", 0, |i| {
            1.0 - (i as f32 - 25.0).abs() / 25.0
        }))
        .unwrap();
        a.decide(1000)
    };
    assert_eq!(run(), run());
}

#[test]
fn ties_go_to_the_straighter_arc() {
    let mut a = arbiter(plain());
    a.on_votes(&votes("obstacle_avoidance", 0, |i| {
        if i == 12 || i == 24 { 1.0 } else { 0.0 }
    }))
    .unwrap();
    assert_eq!(
        a.decide(0).arc_index,
        Some(24),
        "24 is 5 arcs from straight, 12 is 7"
    );
}

/// Of arcs whose fused votes are within `speed_tie_vote` of the best, the
/// one that may be driven fastest wins: at 10 m/s a vote a hundredth
/// higher on an arc the lateral limit holds to 4.9 m/s does not beat the
/// straighter arc allowed 8.7 m/s (at 1.5 m/s²). At 2.5 m/s every arc
/// allows cruise and the best vote wins; nor does a faster arc win from
/// outside the margin, nor one whose speed vote is lower.
#[test]
fn near_ties_go_to_the_arc_that_may_be_driven_fastest() {
    let arcs = ArcSet::new(&ArcSetConfig::default()).unwrap();
    let decide = |cruise: f64, margin: f64, hard: f32, straighter: f32, limit: Option<f64>| {
        let mut a = arbiter(ArbiterConfig {
            cruise_speed_mps: cruise,
            speed_tie_vote: margin,
            ..plain()
        });
        let mut avoid = votes("obstacle_avoidance", 0, |i| match i {
            7 => hard,
            16 => straighter,
            _ => 0.0,
        });
        if let Some(limit) = limit {
            avoid.votes.limit_arc_speed(16, limit);
        }
        a.on_votes(&avoid).unwrap();
        a.decide(0)
    };
    // Arc 7 (k = 0.079 1/m: 4.4 m/s) votes 0.99, arc 16 (0.020: 8.7 m/s) 0.98.
    let lateral = |i: usize| (1.5 / arcs.curvatures()[i].abs()).sqrt();
    assert!(lateral(7) < 5.0 && lateral(16) > 8.0);
    let command = decide(10.0, 0.02, 0.99, 0.98, None);
    assert_eq!(command.arc_index, Some(16));
    assert!((command.speed_mps - lateral(16)).abs() < 1e-9);
    // The margin off: the best vote wins, and with it the lower speed.
    let command = decide(10.0, 0.0, 0.99, 0.98, None);
    assert_eq!(command.arc_index, Some(7));
    assert!((command.speed_mps - lateral(7)).abs() < 1e-9);
    // Outside the margin the faster arc loses.
    assert_eq!(decide(10.0, 0.02, 0.99, 0.95, None).arc_index, Some(7));
    // At the paper's speed both allow cruise: the best vote wins.
    assert_eq!(decide(2.5, 0.02, 0.99, 0.98, None).arc_index, Some(7));
    // A behaviour's speed limit on the straighter arc counts too.
    assert_eq!(decide(10.0, 0.02, 0.99, 0.98, Some(3.0)).arc_index, Some(7));
}

#[test]
fn smoothing_keeps_the_vehicle_away_from_a_forbidden_neighbour() {
    // Arcs 20 and 23 vote equally; arc 21 is forbidden. Smoothed, the choice
    // moves to the side away from the forbidden arc.
    let mut a = arbiter(ArbiterConfig {
        smoothing_sigma_arcs: 1.0,
        ..Default::default()
    });
    let mut avoid = votes("obstacle_avoidance", 0, |i| {
        if i == 20 || i == 23 { 1.0 } else { 0.6 }
    });
    avoid.votes.veto(21, None);
    a.on_votes(&avoid).unwrap();
    let chosen = a.decide(0).arc_index.unwrap();
    assert!((23..=24).contains(&chosen), "chose arc {chosen}");
}

#[test]
fn peak_interpolation_steers_between_arcs() {
    let arcs = ArcSet::new(&ArcSetConfig::default()).unwrap();
    let mut a = arbiter(ArbiterConfig {
        interpolate_peak: true,
        ..plain()
    });
    // A peak halfway between arcs 25 and 26: votes symmetric about 25.5.
    a.on_votes(&votes("obstacle_avoidance", 0, |i| {
        1.0 - 0.1 * (i as f32 - 25.4).abs()
    }))
    .unwrap();
    let command = a.decide(0);
    assert_eq!(command.arc_index, Some(25));
    let (k25, k26) = (arcs.curvatures()[25], arcs.curvatures()[26]);
    assert!(
        command.curvature > k25 && command.curvature < k26,
        "{} in ({k25}, {k26})",
        command.curvature
    );
}

#[test]
fn speed_is_the_minimum_of_the_limits_and_drops_with_a_weak_vote() {
    let mut a = arbiter(plain());
    let mut avoid = votes("obstacle_avoidance", 0, |i| if i == 19 { 1.0 } else { 0.0 });
    avoid.votes.vote_speed(1.8);
    a.on_votes(&avoid).unwrap();
    let command = a.decide(0);
    assert_eq!(
        command.speed_mps, 1.8,
        "the behaviour's 1.8 m/s is below the 2.5 m/s cruise speed"
    );
    // A hard turn: v ≤ sqrt(1.5 m/s² · 8 m) = 3.46, above cruise; cruise holds.
    let mut a = arbiter(plain());
    a.on_votes(&votes("obstacle_avoidance", 0, |i| {
        if i == 0 { 1.0 } else { 0.0 }
    }))
    .unwrap();
    assert_eq!(a.decide(0).speed_mps, 2.5);
    // A weak winner (fused 0.0, halfway from -0.5 to 0.5): half speed.
    let mut a = arbiter(plain());
    a.on_votes(&votes("obstacle_avoidance", 0, |i| {
        if i == 19 { 0.0 } else { -0.4 }
    }))
    .unwrap();
    let command = a.decide(0);
    assert!(
        (command.speed_mps - 1.25).abs() < 1e-9,
        "{}",
        command.speed_mps
    );
}

/// Each command's time, to the next decision, goes to the limit that set
/// its speed: what a mission report says held the average down.
#[test]
fn time_driving_is_counted_by_the_limit_that_set_the_speed() {
    let mut config = plain();
    config.cruise_speed_mps = 8.0;
    let mut a = arbiter(config);
    let tenth = SECOND / 10;
    // Straight and clear: cruise, for 0.3 s.
    for n in 0..3 {
        a.on_votes(&votes("obstacle_avoidance", n * tenth, |i| {
            if i == 19 { 1.0 } else { 0.0 }
        }))
        .unwrap();
        assert_eq!(a.decide(n * tenth).speed_mps, 8.0);
    }
    // A hard turn: sqrt(1.5 · 8) = 3.46 m/s, for 0.2 s.
    for n in 3..5 {
        a.on_votes(&votes("obstacle_avoidance", n * tenth, |i| {
            if i == 0 { 1.0 } else { 0.0 }
        }))
        .unwrap();
        assert!((a.decide(n * tenth).speed_mps - 12f64.sqrt()).abs() < 1e-9);
    }
    // Straight, but the behaviour asks for 2 m/s: a speed vote, for 0.1 s.
    let mut slow = votes("obstacle_avoidance", 5 * tenth, |i| {
        if i == 19 { 1.0 } else { 0.0 }
    });
    slow.votes.vote_speed(2.0);
    a.on_votes(&slow).unwrap();
    a.decide(5 * tenth);
    a.decide(6 * tenth);
    let moving = a.stats().moving;
    assert_eq!(moving.cruise_us, 3 * tenth as u64);
    assert_eq!(moving.lateral_us, 2 * tenth as u64);
    assert_eq!(moving.speed_vote_us, tenth as u64);
    let names: Vec<&str> = moving.seconds().iter().map(|(name, _)| *name).collect();
    assert_eq!(
        names,
        ["cruise", "speed vote", "lateral"],
        "only those that held"
    );
}

/// Issue 63: a speed vote's time is counted by the cause its behaviour
/// gave for the arc driven (the governor's verified distance apart from
/// the rest), the verified distance of the arc driven is kept decision by
/// decision, and the arbiter says when the governor set the speed.
#[test]
fn time_held_by_a_speed_vote_is_counted_by_its_cause_with_the_verified_distance() {
    use arcnav_arbiter::SpeedCause;
    let mut config = plain();
    config.cruise_speed_mps = 8.0;
    let mut a = arbiter(config);
    let tenth = SECOND / 10;
    let straight = |n: i64, speed: f64, cause: SpeedCause, verified: f64| {
        let mut v = votes("obstacle_avoidance", n * tenth, |i| {
            if i == 19 { 1.0 } else { 0.0 }
        });
        for arc in 0..v.votes.len() {
            v.votes.limit_arc_speed_for(arc, speed, cause);
            v.votes.set_verified_distance(arc, verified);
        }
        v
    };
    // Ground verified 14 m ahead: the governor holds it to 6 m/s, 0.3 s.
    for n in 0..3 {
        a.on_votes(&straight(
            n,
            6.0,
            SpeedCause::VerifiedDistance,
            14.0 + n as f64,
        ))
        .unwrap();
        assert_eq!(a.decide(n * tenth).speed_mps, 6.0);
        assert!(a.governed());
    }
    // A cell 9 m ahead: the free distance, 0.2 s.
    for n in 3..5 {
        a.on_votes(&straight(n, 4.0, SpeedCause::FreeDistance, 30.0))
            .unwrap();
        assert_eq!(a.decide(n * tenth).speed_mps, 4.0);
        assert!(!a.governed());
    }
    // Verified far enough for the cruise: the cruise sets it, 0.1 s.
    a.on_votes(&straight(5, 12.0, SpeedCause::VerifiedDistance, 40.0))
        .unwrap();
    assert_eq!(a.decide(5 * tenth).speed_mps, 8.0);
    assert!(!a.governed(), "the cruise set the speed");
    a.decide(6 * tenth);
    let stats = a.stats();
    assert_eq!(stats.moving.verified_distance_us, 3 * tenth as u64);
    assert_eq!(stats.moving.free_distance_us, 2 * tenth as u64);
    assert_eq!(stats.moving.cruise_us, tenth as u64);
    assert_eq!(stats.moving.speed_vote_us, 0);
    let names: Vec<&str> = stats.moving.seconds().iter().map(|(n, _)| *n).collect();
    assert_eq!(names, ["cruise", "free distance", "verified distance"]);
    // Seven decisions drove the straight arc: 14, 15, 16, 30, 30, 40, 40 m.
    let verified = stats.verified;
    assert_eq!(verified.len(), 7);
    assert_eq!(verified.min_m(), Some(14.0));
    assert_eq!(verified.median_m(), Some(30.25));
}

#[test]
fn votes_for_another_arc_set_are_refused() {
    let mut a = arbiter(plain());
    let wrong = BehaviourVotes {
        behaviour: "x".into(),
        utime: 0,
        votes: Votes::new(41),
    };
    let err = a.on_votes(&wrong).unwrap_err();
    assert_eq!(
        err.to_string(),
        "x voted over 41 arcs, the arbiter's arc set has 39"
    );
}

#[test]
fn explaining_costs_nothing_when_off() {
    let mut a = arbiter(plain());
    a.on_votes(&votes("obstacle_avoidance", 0, |_| 1.0))
        .unwrap();
    a.decide(0);
    assert!(a.decision().is_none());
    a.set_explain(true);
    a.decide(0);
    let d = a.decision().unwrap();
    assert_eq!(d.inputs.len(), 1);
    assert_eq!(d.inputs[0].behaviour, "obstacle_avoidance");
    assert_eq!(d.fused.len(), 39);
}
