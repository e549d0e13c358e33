//! The live arbiter: completeness, deadlines, order, watchdog.

use super::*;
use arcnav_arbiter::{ArbiterConfig, Votes};
use arcnav_vehicle::{ArcSet, ArcSetConfig, VehicleConfig};

fn votes(name: &str, utime: Utime, arcs: usize) -> BehaviourVotes {
    let mut v = Votes::new(arcs);
    for i in 0..arcs {
        v.set(i, 0.5);
    }
    BehaviourVotes {
        behaviour: name.into(),
        utime,
        votes: v,
    }
}

fn arbiter_stage(now: i64) -> (ArbiterNode, usize) {
    let arcs = ArcSet::new(&ArcSetConfig::default()).unwrap();
    let n = arcs.len();
    let arbiter = Arbiter::new(&ArbiterConfig::default(), arcs, &VehicleConfig::default());
    let expected = vec!["goal_seeking".into(), "obstacle_avoidance".into()];
    let node = ArbiterNode::new(
        arbiter,
        expected,
        &LiveConfig::default(),
        &PipelineConfig::default(),
        now,
    );
    (node, n)
}

/// The one command `f` decides, if any.
fn one(f: impl FnOnce(&mut Vec<Decided>)) -> Option<Decided> {
    let mut out = Vec::new();
    f(&mut out);
    assert!(out.len() <= 1, "{out:?}");
    out.pop()
}

#[test]
fn the_arbiter_decides_when_every_expected_behaviour_voted() {
    let t0 = 1_000_000_000;
    let (mut stage, n) = arbiter_stage(t0);
    stage.on_pose(5_000_000, t0);
    stage.on_perceived(4_900_000, t0 - 2_000);
    let first = one(|o| {
        stage
            .on_votes(&votes("goal_seeking", 5_000_000, n), &[], t0 + 100, o)
            .unwrap()
    });
    assert!(first.is_none());
    let decided = one(|o| {
        stage
            .on_votes(
                &votes("obstacle_avoidance", 5_000_000, n),
                &[(4_900_000, t0 - 2_000)],
                t0 + 200,
                o,
            )
            .unwrap()
    })
    .unwrap();
    assert_eq!(decided.why, Why::Complete);
    assert_eq!(decided.command.utime, 5_000_000);
    assert!(decided.command.speed_mps > 0.0);
    let latency = stage.arrival_to_command_ms.summary();
    assert_eq!(latency.count, 1);
    assert!((latency.max - 2.2).abs() < 1e-9);
    // Capture 100 ms before the pose that arrived at t0: 100.2 ms.
    assert!((stage.capture_to_command_ms.summary().max - 100.2).abs() < 1e-9);
}

#[test]
fn a_missing_behaviour_is_waited_for_until_the_deadline() {
    let t0 = 1_000_000_000;
    let (mut stage, n) = arbiter_stage(t0);
    stage.on_pose(5_000_000, t0);
    stage.on_perceived(5_000_000, t0);
    assert!(
        one(|o| stage
            .on_votes(&votes("obstacle_avoidance", 5_000_000, n), &[], t0, o)
            .unwrap())
        .is_none()
    );
    assert!(one(|o| stage.on_tick(t0 + 10_000, o)).is_none());
    let decided = one(|o| stage.on_tick(t0 + 50_000, o)).unwrap();
    assert_eq!(
        decided.why,
        Why::Deadline {
            missing: vec!["goal_seeking".into()]
        }
    );
    assert!(decided.command.speed_mps > 0.0);
    assert_eq!(stage.counts().deadline_decisions, 1);
}

#[test]
fn the_watchdog_stops_on_stale_poses_images_or_silence() {
    let t0 = 1_000_000_000;
    let (mut stage, n) = arbiter_stage(t0);
    // Nothing yet: stop, repeated at the command rate, not more often.
    let first = one(|o| stage.on_tick(t0, o)).unwrap();
    assert_eq!(first.why, Why::Watchdog(Hazard::NoPose));
    assert!(first.command.is_stop());
    assert!(one(|o| stage.on_tick(t0 + 50_000, o)).is_none());
    assert!(one(|o| stage.on_tick(t0 + 100_000, o)).is_some());
    // Fresh inputs and votes: driving.
    let t1 = t0 + 200_000;
    stage.on_pose(9_000_000, t1);
    stage.on_perceived(9_000_000, t1);
    for name in ["goal_seeking", "obstacle_avoidance"] {
        one(|o| {
            stage
                .on_votes(&votes(name, 9_000_000, n), &[], t1, o)
                .unwrap()
        });
    }
    assert!(one(|o| stage.on_tick(t1 + 100_000, o)).is_none());
    // Poses stop: the next decision is a stop, and so is every tick.
    let t2 = t1 + 600_000;
    for name in ["goal_seeking", "obstacle_avoidance"] {
        if let Some(d) = one(|o| {
            stage
                .on_votes(&votes(name, 9_100_000, n), &[], t2, o)
                .unwrap()
        }) {
            assert!(matches!(d.why, Why::Watchdog(Hazard::PoseStale { .. })));
            assert!(d.command.is_stop());
            // Stop at the sensor time of the cycle.
            assert_eq!(d.command.utime, 9_100_000);
        }
    }
    let tick = one(|o| stage.on_tick(t2 + 100_000, o)).unwrap();
    assert!(matches!(tick.why, Why::Watchdog(Hazard::PoseStale { .. })));
    // Extrapolated sensor clock.
    assert_eq!(tick.command.utime, 9_000_000 + 700_000);
    // Poses back but images stale.
    let t3 = t2 + 1_000_000;
    stage.on_pose(10_000_000, t3);
    let tick = one(|o| stage.on_tick(t3, o)).unwrap();
    assert!(matches!(
        tick.why,
        Why::Watchdog(Hazard::ImagesStale { .. })
    ));
    // Everything fresh but nobody votes: stop once vote_timeout_s passes.
    let t4 = t3 + 1_100_000;
    stage.on_pose(11_000_000, t4);
    stage.on_perceived(11_000_000, t4);
    let tick = one(|o| stage.on_tick(t4, o)).unwrap();
    assert!(matches!(
        tick.why,
        Why::Watchdog(Hazard::NoDecisions { .. })
    ));
    assert!(stage.counts().watchdog_stops >= 4);
    let last = stage.final_stop(t4 + 1);
    assert_eq!(last.why, Why::Final);
    assert!(last.command.is_stop());
}

#[test]
fn interleaved_cycles_are_each_decided_once_in_order_with_their_own_votes() {
    let t0 = 1_000_000_000;
    let (mut stage, n) = arbiter_stage(t0);
    stage.on_pose(5_000_000, t0);
    stage.on_perceived(5_000_000, t0);
    let mut out = Vec::new();
    // Obstacle avoidance runs a cycle ahead of goal seeking.
    stage
        .on_votes(
            &votes("obstacle_avoidance", 5_000_000, n),
            &[],
            t0,
            &mut out,
        )
        .unwrap();
    stage
        .on_votes(
            &votes("obstacle_avoidance", 5_100_000, n),
            &[],
            t0,
            &mut out,
        )
        .unwrap();
    assert!(out.is_empty(), "no cycle is complete yet");
    stage
        .on_votes(&votes("goal_seeking", 5_000_000, n), &[], t0, &mut out)
        .unwrap();
    stage
        .on_votes(&votes("goal_seeking", 5_100_000, n), &[], t0, &mut out)
        .unwrap();
    let decided: Vec<(Utime, &Why)> = out.iter().map(|d| (d.command.utime, &d.why)).collect();
    assert_eq!(
        decided,
        [(5_000_000, &Why::Complete), (5_100_000, &Why::Complete)]
    );
    // A newer complete cycle decides an older incomplete one first.
    out.clear();
    stage
        .on_votes(&votes("goal_seeking", 5_200_000, n), &[], t0, &mut out)
        .unwrap();
    stage
        .on_votes(&votes("goal_seeking", 5_300_000, n), &[], t0, &mut out)
        .unwrap();
    stage
        .on_votes(
            &votes("obstacle_avoidance", 5_300_000, n),
            &[],
            t0,
            &mut out,
        )
        .unwrap();
    let times: Vec<Utime> = out.iter().map(|d| d.command.utime).collect();
    assert_eq!(times, [5_200_000, 5_300_000]);
    assert!(matches!(&out[0].why, Why::Deadline { missing } if missing == &["obstacle_avoidance"]));
    // Votes for a cycle already decided are counted and dropped.
    out.clear();
    stage
        .on_votes(
            &votes("obstacle_avoidance", 5_200_000, n),
            &[],
            t0,
            &mut out,
        )
        .unwrap();
    assert!(out.is_empty());
    assert_eq!(stage.counts().late_votes, 1);
}

#[test]
fn votes_of_an_unconfigured_behaviour_or_from_the_future_change_nothing() {
    let t0 = 1_000_000_000;
    let (mut stage, n) = arbiter_stage(t0);
    stage.on_pose(5_000_000, t0);
    stage.on_perceived(5_000_000, t0);
    let mut out = Vec::new();
    // A stray publisher vetoing every arc, and obstacle avoidance
    // stamped a minute ahead.
    let mut stray = votes("anything", 5_000_000, n);
    for i in 0..n {
        stray.votes.veto(i, None);
    }
    stage.on_votes(&stray, &[], t0, &mut out).unwrap();
    stage
        .on_votes(
            &votes("obstacle_avoidance", 65_000_000, n),
            &[],
            t0,
            &mut out,
        )
        .unwrap();
    assert_eq!(stage.counts().ignored_votes, 1);
    assert_eq!(stage.counts().future_votes, 1);
    // The real cycle is decided, driving, and later cycles still are.
    for t in [5_000_000, 5_100_000] {
        stage.on_pose(t, t0);
        for name in ["goal_seeking", "obstacle_avoidance"] {
            stage
                .on_votes(&votes(name, t, n), &[], t0, &mut out)
                .unwrap();
        }
    }
    let decided: Vec<(Utime, bool)> = out
        .iter()
        .map(|d| (d.command.utime, d.command.is_stop()))
        .collect();
    assert_eq!(decided, [(5_000_000, false), (5_100_000, false)]);
}

#[test]
fn reproducing_lockstep_a_cycle_waits_for_its_votes_up_to_the_vote_timeout() {
    let t0 = 1_000_000_000;
    let arcs = ArcSet::new(&ArcSetConfig::default()).unwrap();
    let n = arcs.len();
    let arbiter = Arbiter::new(&ArbiterConfig::default(), arcs, &VehicleConfig::default());
    let live = LiveConfig {
        reproduce_lockstep: true,
        ..LiveConfig::default()
    };
    let expected = vec!["goal_seeking".into(), "obstacle_avoidance".into()];
    let mut stage = ArbiterNode::new(arbiter, expected, &live, &PipelineConfig::default(), t0);
    stage.on_pose(5_000_000, t0);
    stage.on_perceived(5_000_000, t0);
    let mut out = Vec::new();
    stage
        .on_votes(&votes("goal_seeking", 5_000_000, n), &[], t0, &mut out)
        .unwrap();
    stage.on_tick(t0 + 500_000, &mut out);
    assert!(out.is_empty(), "0.5 s late votes still complete the cycle");
    stage
        .on_votes(
            &votes("obstacle_avoidance", 5_000_000, n),
            &[],
            t0 + 500_000,
            &mut out,
        )
        .unwrap();
    assert_eq!(out.len(), 1);
    assert_eq!(out[0].why, Why::Complete);
}

/// When poses stop, commands keep coming at the command rate on the wall
/// clock: the last decision held until the poses are stale, then the
/// watchdog's stop. Nothing had been published for 0.58 s.
#[test]
fn a_late_decision_is_covered_by_the_last_command_until_the_inputs_are_stale() {
    let t0 = 1_000_000_000;
    let (mut stage, n) = arbiter_stage(t0);
    stage.on_pose(9_000_000, t0);
    stage.on_perceived(9_000_000, t0);
    let mut decided = None;
    for name in ["goal_seeking", "obstacle_avoidance"] {
        if let Some(d) = one(|o| {
            stage
                .on_votes(&votes(name, 9_000_000, n), &[], t0, o)
                .unwrap()
        }) {
            decided = Some(d);
        }
    }
    let decided = decided.expect("decided once every behaviour voted");
    assert!(!decided.command.is_stop());
    // Poses stop. Ticks every 10 ms: every command period (100 ms) on the
    // wall clock something is published, the first 150 ms after the last
    // decision (a decision may be late by half a period).
    let mut published = Vec::new();
    let mut times = vec![t0];
    for k in 1..=100 {
        let now = t0 + k * 10_000;
        let before = published.len();
        stage.on_tick(now, &mut published);
        if published.len() > before {
            times.push(now);
        }
    }
    let gaps: Vec<i64> = times.windows(2).map(|w| w[1] - w[0]).collect();
    assert_eq!(gaps[0], 150_000, "{gaps:?}");
    assert!(gaps[1..].iter().all(|&g| g <= 100_000), "{gaps:?}");
    let held: Vec<_> = published.iter().filter(|d| d.why == Why::Held).collect();
    assert!(!held.is_empty());
    for d in &held {
        assert_eq!(d.command.curvature, decided.command.curvature);
        assert!(d.command.utime > decided.command.utime, "restamped");
    }
    // Past the pose timeout (0.5 s): stops, and no held command after one.
    let first_stop = published
        .iter()
        .position(|d| matches!(d.why, Why::Watchdog(Hazard::PoseStale { .. })))
        .expect("a stop once the poses are stale");
    assert!(published[first_stop..].iter().all(|d| d.command.is_stop()));
    assert_eq!(stage.counts().held as usize, held.len());
    // Poses and images back, but no new decision: the old command is not
    // held again (only a decision moves the vehicle after a stop).
    let t1 = t0 + 1_100_000;
    stage.on_pose(10_100_000, t1);
    stage.on_perceived(10_100_000, t1);
    let mut after = Vec::new();
    stage.on_tick(t1 + 200_000, &mut after);
    assert!(after.iter().all(|d| d.why != Why::Held), "{after:?}");
}
