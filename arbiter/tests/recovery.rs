//! Backing up when the way forward is blocked: when it starts, which arc,
//! how far, how often, and when it must not.

use arcnav_arbiter::{Arbiter, ArbiterConfig, BehaviourVotes, StopReason, Votes};
use arcnav_vehicle::{ArcSet, ArcSetConfig, SteeringCommand, VehicleConfig};

const SECOND: i64 = 1_000_000;
/// Decisions every 100 ms, as the live arbiter makes them.
const PERIOD: i64 = SECOND / 10;

fn arbiter() -> Arbiter {
    let config = ArbiterConfig::default();
    config.validate().unwrap();
    Arbiter::new(
        &config,
        ArcSet::new(&ArcSetConfig::default()).unwrap(),
        &VehicleConfig::default(),
    )
}

/// Obstacle avoidance forbidding every forward arc, with `clear(arc)`
/// metres behind each; goal seeking preferring arc `goal`.
fn blocked(utime: i64, clear: impl Fn(usize) -> Option<f64>, goal: usize) -> [BehaviourVotes; 2] {
    let mut avoid = Votes::new(39);
    let mut seek = Votes::new(39);
    for arc in 0..39 {
        avoid.veto(arc, None);
        if let Some(c) = clear(arc) {
            avoid.set_reverse_clearance(arc, c);
        }
        seek.set(arc, 1.0 - arc.abs_diff(goal) as f32 / 20.0);
    }
    [
        BehaviourVotes {
            behaviour: "obstacle_avoidance".into(),
            utime,
            votes: avoid,
        },
        BehaviourVotes {
            behaviour: "route".into(),
            utime,
            votes: seek,
        },
    ]
}

/// Decides every 100 ms from `from` for `seconds`, feeding `votes(t)`.
fn drive(
    arbiter: &mut Arbiter,
    from: i64,
    seconds: f64,
    votes: impl Fn(i64) -> [BehaviourVotes; 2],
) -> Vec<SteeringCommand> {
    let steps = (seconds * 10.0).round() as i64;
    (0..steps)
        .map(|k| {
            let t = from + k * PERIOD;
            for v in votes(t) {
                arbiter.on_votes(&v).unwrap();
            }
            arbiter.decide(t)
        })
        .collect()
}

#[test]
fn blocked_and_standing_it_backs_up_along_the_arc_that_swings_the_nose_towards_the_goal() {
    let mut a = arbiter();
    let goal = 30; // left of straight (19)
    let commands = drive(&mut a, 0, 7.0, |t| blocked(t, |_| Some(5.0), goal));
    // Stops for wait_s (1.5 s) first.
    assert!(commands[..15].iter().all(SteeringCommand::is_stop));
    let first = commands
        .iter()
        .position(SteeringCommand::is_reverse)
        .unwrap();
    assert_eq!(first, 15, "backs up after 1.5 s blocked");
    let back = commands[first];
    assert_eq!(back.speed_mps, -1.0);
    // Backing along a right arc turns the heading left, towards the goal:
    // the mirror of the goal's arc (38 - 30 = 8).
    assert_eq!(back.arc_index, Some(38 - goal), "{back:?}");
    assert!(back.curvature < 0.0);
    // 4 m at up to 1 m/s (1 s to reach it): about 4.5 s of backing, then
    // forward again (blocked: stop), and not backing before wait_s again.
    let backing = commands[first..]
        .iter()
        .take_while(|c| c.is_reverse())
        .count();
    assert!((43..=48).contains(&backing), "{backing} decisions backing");
    let stats = a.recovery_stats();
    assert_eq!(stats.recoveries, 1);
    // 4 m, and the braking after (0.17 m at 3 m/s²).
    assert!((3.9..=4.3).contains(&stats.backed_m), "{stats:?}");
    let after = first + backing;
    assert!(commands[after].is_stop());
}

#[test]
fn it_backs_up_only_where_the_ground_behind_is_clear() {
    // Only arcs 0..=5 are clear for 4 m (not quite the 4 m and the margin:
    // they back up as far as they can).
    let mut a = arbiter();
    let commands = drive(&mut a, 0, 3.0, |t| {
        blocked(t, |arc| Some(if arc <= 5 { 4.0 } else { 1.0 }), 19)
    });
    let back = commands.iter().find(|c| c.is_reverse()).unwrap();
    assert!(back.arc_index.unwrap() <= 5, "{back:?}");
    // Nothing clear behind (a wall 0.8 m behind the bumper): it stays
    // stopped and counts the decisions with no way back.
    let mut a = arbiter();
    let commands = drive(&mut a, 0, 4.0, |t| blocked(t, |_| Some(0.8), 19));
    assert!(commands.iter().all(SteeringCommand::is_stop));
    assert!(a.recovery_stats().no_way_back > 0);
    assert_eq!(a.recovery_stats().recoveries, 0);
    // No behaviour checks the ground behind: never backs up.
    let mut a = arbiter();
    let commands = drive(&mut a, 0, 4.0, |t| blocked(t, |_| None, 19));
    assert!(commands.iter().all(SteeringCommand::is_stop));
}

#[test]
fn backing_up_stops_when_the_ground_behind_closes() {
    let mut a = arbiter();
    // Clear for 5 m until 2.5 s, then a cell 0.6 m behind every arc.
    let commands = drive(&mut a, 0, 5.0, |t| {
        blocked(t, |_| Some(if t < 2_500_000 { 5.0 } else { 0.6 }), 19)
    });
    assert!(commands[15].is_reverse());
    assert!(commands[25..].iter().all(SteeringCommand::is_stop));
}

#[test]
fn recoveries_are_bounded_then_the_stop_says_why() {
    let mut a = arbiter();
    a.set_explain(true);
    let max = ArbiterConfig::default().recovery.max_attempts;
    let commands = drive(&mut a, 0, 90.0, |t| blocked(t, |_| Some(5.0), 19));
    assert_eq!(a.recovery_stats().recoveries, u64::from(max));
    assert!(commands.last().unwrap().is_stop());
    let stop = a.decision().unwrap().stop.clone().unwrap();
    assert!(
        matches!(stop, StopReason::Stuck { attempts, .. } if attempts == max),
        "{stop:?}"
    );
    assert!(
        stop.to_string().contains("every arc is forbidden"),
        "{stop}"
    );
    assert!(a.stats().stops_stuck > 0);
}

#[test]
fn no_backing_up_when_a_behaviour_asks_to_stop_or_votes_are_missing() {
    // Mission complete: goal seeking votes speed 0 and obstacle avoidance
    // limits every arc to 0 (say, unseen ground ahead): a stop, not a block.
    let mut a = arbiter();
    let commands = drive(&mut a, 0, 4.0, |t| {
        let [mut avoid, mut seek] = blocked(t, |_| Some(5.0), 19);
        avoid.votes = Votes::new(39);
        for arc in 0..39 {
            avoid.votes.set(arc, 1.0);
            avoid.votes.limit_arc_speed(arc, 0.0);
            avoid.votes.set_reverse_clearance(arc, 5.0);
        }
        seek.votes.vote_speed(0.0);
        [avoid, seek]
    });
    assert!(commands.iter().all(SteeringCommand::is_stop));
    // The same speed limits without the stop request: blocked, so it backs up.
    let mut a = arbiter();
    let commands = drive(&mut a, 0, 4.0, |t| {
        let [mut avoid, seek] = blocked(t, |_| Some(5.0), 19);
        avoid.votes = Votes::new(39);
        for arc in 0..39 {
            avoid.votes.set(arc, 1.0);
            avoid.votes.limit_arc_speed(arc, 0.0);
            avoid.votes.set_reverse_clearance(arc, 5.0);
        }
        [avoid, seek]
    });
    assert!(commands.iter().any(SteeringCommand::is_reverse));
    // The required behaviour falls silent while backing: stop at once.
    let mut a = arbiter();
    let commands = drive(&mut a, 0, 4.0, |t| {
        let votes = blocked(t, |_| Some(5.0), 19);
        if t < 2 * SECOND {
            votes
        } else {
            // Stale: stamped 2 s ago.
            blocked(t - 2 * SECOND, |_| Some(5.0), 19)
        }
    });
    // Its last votes (1.9 s) go stale after the 1 s timeout.
    assert!(commands[15].is_reverse());
    assert!(commands[29].is_reverse());
    assert!(commands[30..].iter().all(SteeringCommand::is_stop));
    assert!(!a.is_backing_up());
}
