//! Backing up when the way forward is blocked: when it starts, which arc,
//! how far, how often, and when it must not.

use arcnav_arbiter::{Arbiter, ArbiterConfig, BehaviourVotes, StopReason, Votes};
use arcnav_vehicle::{
    ArcSet, ArcSetConfig, MotionLimits, MotionModel, PlanarState, SteeringCommand, VehicleConfig,
};

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
    // Then turns the wheels standing: the command acts after the 0.25 s
    // latency, the wheels turn at 0.15 1/m per second to within 0.02 1/m
    // of the arc's -0.072 1/m (0.35 s): 6 decisions; then backs up.
    assert_eq!(first, 21, "backs up after 1.5 s blocked and 0.6 s steering");
    for steer in &commands[15..first] {
        assert!(steer.is_stop(), "{steer:?}");
        assert_eq!(steer.arc_index, Some(38 - goal), "{steer:?}");
    }
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
    // The stop names who asked for it (live, its status lines say so).
    assert_eq!(a.reason().to_string(), "route asked to stop");
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

/// Obstacle avoidance forbidding every forward arc for driving at speed
/// (`vetoed`), with `ahead` metres of creeping room and 5 m behind on every
/// arc; the route wishing for `wish(arc)`.
fn cornered(
    utime: i64,
    vetoed: bool,
    ahead: f64,
    wish: impl Fn(usize) -> f32,
) -> [BehaviourVotes; 2] {
    let [mut avoid, mut route] = blocked(utime, |_| Some(5.0), 19);
    for arc in 0..39 {
        if !vetoed {
            avoid.votes = {
                let mut v = Votes::new(39);
                (0..39).for_each(|a| {
                    v.set(a, 1.0);
                    v.set_reverse_clearance(a, 5.0);
                });
                v
            };
        }
        avoid.votes.set_forward_clearance(arc, ahead);
        route.votes.set(arc, wish(arc));
    }
    [avoid, route]
}

/// The way lies behind and to the left: every arc leads away, the hard
/// left one least.
fn behind_left(arc: usize) -> f32 {
    -0.9 + 0.5 * arc as f32 / 38.0
}

#[test]
fn with_the_way_behind_it_turns_round_in_legs_that_all_turn_the_same_way() {
    let mut a = arbiter();
    let commands = drive(&mut a, 0, 40.0, |t| cornered(t, true, 3.0, behind_left));
    let moving: Vec<_> = commands.iter().filter(|c| !c.is_stop()).collect();
    assert!(!moving.is_empty());
    // Backing along right arcs and creeping forwards along left ones: the
    // heading rate k·v is positive (left) on every leg.
    for c in &moving {
        assert!(c.curvature * c.speed_mps > 0.0, "{c:?}");
        assert!(c.speed_mps.abs() <= 1.0, "{c:?}");
    }
    // Both kinds of leg, alternating, the hardest arcs (room is the same
    // on all of them).
    let legs: Vec<bool> = moving
        .windows(2)
        .filter(|w| w[0].is_reverse() != w[1].is_reverse())
        .map(|w| w[1].is_reverse())
        .collect();
    assert!(legs.len() >= 6, "{} changes of direction", legs.len());
    assert!(
        moving
            .iter()
            .all(|c| c.arc_index == Some(0) || c.arc_index == Some(38))
    );
    let stats = *a.recovery_stats();
    assert!(stats.turns >= 1, "{stats:?}");
    assert!(stats.turn_legs >= 7, "{stats:?}");
    // Forward legs stop 0.5 m (margin_m) short of the 3 m of room: 2.5 m;
    // backing legs go the 4 m distance.
    assert!(stats.turned_deg > 90.0, "{stats:?}");
    // No turn has more than turn_max_legs legs.
    let max = ArbiterConfig::default().recovery.turn_max_legs;
    assert!(stats.turn_legs <= u64::from(max) * stats.turns, "{stats:?}");
}

#[test]
fn the_turn_ends_once_the_way_has_lain_ahead_for_a_second() {
    let ahead = |arc: usize| 1.0 - arc.abs_diff(19) as f32 / 20.0;
    // The way swings ahead for 0.5 s at 8 s (a route re-planning), then
    // for good at 12 s; from 12 s the ground ahead is clear too.
    let votes = |t: i64| {
        let swing = (8 * SECOND..8 * SECOND + SECOND / 2).contains(&t);
        if t >= 12 * SECOND {
            cornered(t, false, 18.0, ahead)
        } else if swing {
            cornered(t, true, 3.0, ahead)
        } else {
            cornered(t, true, 3.0, behind_left)
        }
    };
    let mut a = arbiter();
    let commands = drive(&mut a, 0, 16.0, votes);
    // Still turning after the swing (legs with the hardest arcs)...
    assert!(commands[85..120].iter().any(
        |c| c.arc_index == Some(0) && c.is_reverse() || c.arc_index == Some(38) && !c.is_stop()
    ));
    // ... and driving on the fused vote a second after the way lies ahead.
    let normal =
        |c: &SteeringCommand| !c.is_reverse() && c.arc_index.is_some_and(|i| i.abs_diff(19) <= 2);
    assert!(
        !commands[120..129].iter().any(normal),
        "not before a second"
    );
    assert!(
        commands[131..].iter().all(normal),
        "{:?}",
        &commands[129..135]
    );
    assert_eq!(a.recovery_stats().turns, 1);
    assert!(!a.is_backing_up());
}

/// The way lies ahead to the right: the hardest right arc is wished for,
/// and it leads towards the way (a vote of 0 or more).
fn ahead_right(arc: usize) -> f32 {
    0.4 - 0.8 * arc as f32 / 38.0
}

/// The way lies just beside on the right: the hardest right arc is wished
/// for, with a vote of 0.1 (below `AHEAD_VOTE`, 0.3).
fn beside_right(arc: usize) -> f32 {
    0.1 - 0.8 * arc as f32 / 38.0
}

/// The way lies behind and to the right: every arc leads away, the hard
/// right one least.
fn behind_right(arc: usize) -> f32 {
    -0.4 - 0.5 * arc as f32 / 38.0
}

/// Turning left for a way behind on the left, the way comes to lie ahead
/// on the right (a route that found the left end of a ditch shut and now
/// goes round the right one): a second later the legs turn the heading
/// right, the short way to it, not the 270° on. A way behind on the right
/// (every vote below 0) does not turn the turn: the heading swinging past
/// a way behind the vehicle moves it from side to side. Nor does a way
/// just beside on the right (where a plan swinging between the ends of a
/// ditch puts it for a few seconds).
#[test]
fn a_turn_goes_the_other_way_once_the_way_lies_ahead_on_that_side() {
    let rate = |c: &SteeringCommand| c.curvature * c.speed_mps;
    let after = |wish: fn(usize) -> f32| {
        let mut a = arbiter();
        let commands = drive(&mut a, 0, 14.0, |t| {
            if t >= 6 * SECOND {
                cornered(t, true, 3.0, wish)
            } else {
                cornered(t, true, 3.0, behind_left)
            }
        });
        let moving = |range: std::ops::Range<usize>| -> Vec<SteeringCommand> {
            commands[range]
                .iter()
                .filter(|c| !c.is_stop())
                .copied()
                .collect()
        };
        let (before, later) = (moving(0..60), moving(75..140));
        assert!(!before.is_empty() && !later.is_empty());
        assert!(before.iter().all(|c| rate(c) > 0.0), "{before:?}");
        (later, *a.recovery_stats())
    };
    let (later, stats) = after(ahead_right);
    assert!(later.iter().all(|c| rate(c) < 0.0), "{later:?}");
    assert_eq!((stats.turns, stats.turns_reversed), (1, 1), "{stats:?}");
    for wish in [behind_right, beside_right] {
        let (later, stats) = after(wish);
        assert!(later.iter().all(|c| rate(c) > 0.0), "{later:?}");
        assert_eq!((stats.turns, stats.turns_reversed), (1, 0), "{stats:?}");
    }
}

#[test]
fn forward_legs_need_creeping_room_and_turning_round_can_be_switched_off() {
    // 1.2 m of room ahead is less than min_distance_m (1 m) + margin_m
    // (0.5 m): the turn is backing legs only, each followed by a stop
    // (not retracing them: that is the next tests').
    let mut config = ArbiterConfig::default();
    config.recovery.retrace = false;
    let mut a = Arbiter::new(
        &config,
        ArcSet::new(&ArcSetConfig::default()).unwrap(),
        &VehicleConfig::default(),
    );
    let commands = drive(&mut a, 0, 30.0, |t| cornered(t, true, 1.2, behind_left));
    assert!(commands.iter().any(SteeringCommand::is_reverse));
    assert!(
        commands.iter().all(|c| c.is_stop() || c.is_reverse()),
        "no forward leg"
    );
    // turn_round = false: backing up once per recovery, as before.
    let mut config = ArbiterConfig::default();
    config.recovery.turn_round = false;
    config.validate().unwrap();
    let mut a = Arbiter::new(
        &config,
        ArcSet::new(&ArcSetConfig::default()).unwrap(),
        &VehicleConfig::default(),
    );
    let commands = drive(&mut a, 0, 20.0, |t| cornered(t, true, 3.0, behind_left));
    assert!(commands.iter().any(SteeringCommand::is_reverse));
    assert!(commands.iter().all(|c| c.is_stop() || c.is_reverse()));
    assert_eq!(a.recovery_stats().turns, 0);
}

// ---------------------------------------------------------------------------
// Backing out the way the vehicle came.

/// Obstacle avoidance with every arc open (18 m ahead, 5 m behind), and a
/// route favouring arc `goal`.
fn open(utime: i64, goal: usize) -> [BehaviourVotes; 2] {
    let [mut avoid, mut route] = blocked(utime, |_| Some(5.0), goal);
    avoid.votes = Votes::new(39);
    for arc in 0..39 {
        avoid.votes.set(arc, 1.0);
        avoid.votes.set_reverse_clearance(arc, 5.0);
        avoid.votes.set_forward_clearance(arc, 18.0);
        route.votes.set(arc, 1.0 - arc.abs_diff(goal) as f32 / 20.0);
    }
    [avoid, route]
}

/// A lane too narrow to turn in, the way behind and to the left: every
/// forward arc forbidden, 0.4 m of creeping room ahead (no forward leg),
/// 1.2 m behind every arc (less than a backing leg needs, min_distance_m
/// plus margin_m), except that from `room_from` on the left arcs are
/// clear 12 m ahead (the lane's mouth).
fn lane(utime: i64, room_from: i64) -> [BehaviourVotes; 2] {
    let [mut avoid, route] = cornered(utime, true, 0.4, behind_left);
    for arc in 0..39 {
        avoid.votes.set_reverse_clearance(arc, 1.2);
        if utime >= room_from && arc > 19 {
            avoid.votes.set_forward_clearance(arc, 12.0);
        }
    }
    [avoid, route]
}

/// Where `commands`, decided every 100 ms from 0, take the vehicle: its
/// state after each decision's interval, as the simulator drives it.
fn driven(commands: &[SteeringCommand]) -> Vec<PlanarState> {
    let limits = MotionLimits::from_vehicle(&VehicleConfig::default());
    let mut model = MotionModel::new(limits, PlanarState::default(), 0);
    commands
        .iter()
        .enumerate()
        .map(|(k, command)| {
            model.command(*command);
            model.advance_to((k as i64 + 1) * PERIOD)
        })
        .collect()
}

#[test]
fn in_a_lane_too_narrow_to_turn_in_it_backs_out_the_way_it_came_and_turns_where_there_is_room() {
    let mut a = arbiter();
    let room_from = 20 * SECOND;
    let commands = drive(&mut a, 0, 26.0, |t| {
        if t < 8 * SECOND {
            open(t, 19)
        } else {
            lane(t, room_from)
        }
    });
    let states = driven(&commands);
    let deepest = states[79].x;
    assert!(deepest > 12.0, "drove {deepest} m into the lane");
    // Blocked, no turn can start and no backing leg fits: it backs along
    // the way it came (straight), at a crawl.
    let backing: Vec<_> = commands[80..200].iter().filter(|c| !c.is_stop()).collect();
    assert!(backing.len() > 50, "{} commands backing", backing.len());
    for c in &backing {
        assert!(c.is_reverse() && c.speed_mps >= -1.0, "{c:?}");
        assert_eq!(c.arc_index, Some(19), "{c:?}");
    }
    let stats = *a.recovery_stats();
    assert_eq!(stats.retraces, 1, "{stats:?}");
    // On the line it came by, well back from where it stopped.
    let at_room = states[199];
    assert!(
        at_room.y.abs() < 0.05 && at_room.yaw.abs() < 0.01,
        "{at_room:?}"
    );
    assert!(deepest - at_room.x > 6.0, "{at_room:?}");
    assert!(
        (stats.retraced_m - (states[99].x - at_room.x)).abs() < 0.5,
        "{stats:?} {:?} {at_room:?}",
        states[99]
    );
    // Where the left arcs have room, the turn starts at once, forwards
    // and to the left.
    let next = commands[200..]
        .iter()
        .find(|c| !c.is_stop())
        .expect("drives on");
    assert!(!next.is_reverse() && next.curvature > 0.1, "{next:?}");
    assert_eq!(a.recovery_stats().turns, 1);
    assert_eq!(a.recovery_stats().recoveries, 1, "one recovery");
}

#[test]
fn the_way_back_follows_the_curve_it_came_by_to_where_the_trail_begins() {
    // 6 s straight, 6 s along arc 30 (curving left), then a lane with no
    // room anywhere: the vehicle backs out along all it remembers.
    let mut a = arbiter();
    let commands = drive(&mut a, 0, 70.0, |t| match t {
        t if t < 6 * SECOND => open(t, 19),
        t if t < 12 * SECOND => open(t, 30),
        t => lane(t, i64::MAX),
    });
    let states = driven(&commands);
    let blocked_at = states[125];
    assert!(
        blocked_at.yaw > 0.5,
        "turned left on the way in: {blocked_at:?}"
    );
    let first_back = commands[120..]
        .iter()
        .find(|c| c.is_reverse())
        .expect("backs up");
    // (The stop straightened the wheels as it slowed: the path's last
    // metre curves less than the arc.)
    assert!(
        first_back.curvature > 0.03,
        "backs along the curve first: {first_back:?}"
    );
    let last_back = commands
        .iter()
        .rposition(SteeringCommand::is_reverse)
        .unwrap();
    assert!(
        commands[last_back].curvature.abs() < 0.01,
        "ends along the straight: {:?}",
        commands[last_back]
    );
    // Back where it started, facing the way it set off.
    let end = states.last().unwrap();
    assert!(end.x.hypot(end.y) < 0.6, "{end:?}");
    assert!(end.yaw.abs() < 3f64.to_radians(), "{end:?}");
    assert!(
        commands[last_back + 10..]
            .iter()
            .all(SteeringCommand::is_stop)
    );
    let stats = *a.recovery_stats();
    assert!(stats.retraces >= 1 && stats.retraced_m > 20.0, "{stats:?}");
}

#[test]
fn a_decision_far_in_the_future_restarts_the_estimate_and_forgets_the_way_back() {
    // Driving, then a decision stamped near the end of time (a corrupt
    // log): no overflow, no integration over the gap; where the vehicle
    // went meanwhile is unknown, so only what it drove since (braking from
    // cruise: about 1.5 m) can be retraced, not the 16 m before.
    let mut a = arbiter();
    drive(&mut a, 0, 8.0, |t| open(t, 19));
    let late = i64::MAX - 10 * SECOND;
    drive(&mut a, late, 6.0, |t| lane(t, i64::MAX));
    let stats = *a.recovery_stats();
    assert!(stats.retraced_m < 2.0, "{stats:?}");
}

/// Decides every 100 ms from 0 for `seconds`, with the votes made by
/// `votes(t, state)` from where the commands so far have taken the vehicle
/// (as the simulator drives it); the commands and the states they lead to.
fn drive_seen(
    arbiter: &mut Arbiter,
    seconds: f64,
    mut votes: impl FnMut(i64, &PlanarState) -> [BehaviourVotes; 2],
) -> (Vec<SteeringCommand>, Vec<PlanarState>) {
    let limits = MotionLimits::from_vehicle(&VehicleConfig::default());
    let mut model = MotionModel::new(limits, PlanarState::default(), 0);
    let steps = (seconds * 10.0).round() as i64;
    (0..steps)
        .map(|k| {
            let t = k * PERIOD;
            for v in votes(t, model.state()) {
                arbiter.on_votes(&v).unwrap();
            }
            let command = arbiter.decide(t);
            model.command(command);
            (command, model.advance_to(t + PERIOD))
        })
        .unzip()
}

#[test]
fn backing_out_passes_a_leg_it_cannot_undo_to_the_end_and_an_arc_it_cannot_take() {
    // In 8 s straight, then blocked with the way ahead: one plain backing
    // up of 4 m. From 16 s the way lies behind and to the left, no turn
    // leg fits (1.2 m behind, 0.4 m ahead on the left arcs), and the only
    // way out is back along the trail. Undoing the backing leg forwards
    // meets a wall 0.3 m short of where it began (as a leg driven to the
    // limit of its room does): it stops about 0.7 m short of the leg's
    // start and carries on from there.
    // Backing along the straight way in, the straight arc itself is
    // blocked 0.4 m behind (a corner beside a bank); its neighbours are
    // not.
    let mut a = arbiter();
    let mut deepest = f64::MIN;
    let (commands, states) = drive_seen(&mut a, 60.0, |t, state| {
        deepest = deepest.max(state.x);
        if t < 8 * SECOND {
            return open(t, 19);
        }
        if t < 16 * SECOND {
            return blocked(t, |_| Some(5.0), 19);
        }
        let wall = (deepest - 0.3 - state.x).max(0.0);
        let [mut avoid, route] = cornered(t, true, 0.4, behind_left);
        for arc in 0..39 {
            let forward = if arc <= 19 { wall } else { 0.4 };
            avoid.votes.set_forward_clearance(arc, forward);
            avoid
                .votes
                .set_reverse_clearance(arc, if arc == 19 { 0.4 } else { 1.2 });
        }
        [avoid, route]
    });
    let turned_back = states[159].x;
    assert!(
        deepest - turned_back > 3.5,
        "backed up once by 16 s: {deepest} -> {turned_back}"
    );
    // Creeps forwards towards the leg's start, then backs out along the
    // way in on the arcs beside the straight one.
    let after: Vec<_> = commands[160..].iter().filter(|c| !c.is_stop()).collect();
    let first_back = after
        .iter()
        .position(|c| c.is_reverse())
        .unwrap_or_else(|| panic!("backs out: {:?}", a.recovery_stats()));
    assert!(first_back > 10, "creeps forwards first");
    assert!(after[..first_back].iter().all(|c| c.speed_mps > 0.0));
    for c in &after[first_back..] {
        assert!(c.is_reverse(), "{c:?}");
        assert_ne!(c.arc_index, Some(19), "{c:?}");
        assert!(c.curvature.abs() < 0.06, "{c:?}");
    }
    let end = states.last().unwrap();
    assert!(
        end.x < deepest - 12.0,
        "backed out to {end:?} from {deepest}"
    );
    assert!(end.y.abs() < 0.5, "kept to the way in: {end:?}");
    let stats = *a.recovery_stats();
    assert_eq!(stats.retraces, 1, "{stats:?}");
}

#[test]
fn where_nothing_behind_is_known_it_turns_towards_the_way_forwards_as_far_as_the_ground_is_seen() {
    // The mission's start: nothing behind has been seen (no backing
    // clearance, no trail), the way lies to the right (arc 8, not the
    // hardest), and every arc is held to 0 m/s by ground not seen close
    // along it; the right arcs up to straight have 6 m of creeping room.
    let votes = |t: i64| {
        let [mut avoid, mut route] = blocked(t, |_| None, 8);
        avoid.votes = Votes::new(39);
        for arc in 0..39 {
            avoid.votes.set(arc, 1.0);
            avoid.votes.limit_arc_speed(arc, 0.0);
            avoid
                .votes
                .set_forward_clearance(arc, if (5..=19).contains(&arc) { 6.0 } else { 0.5 });
            route.votes.set(arc, 1.0 - arc.abs_diff(8) as f32 / 20.0);
        }
        [avoid, route]
    };
    let mut a = arbiter();
    let commands = drive(&mut a, 0, 12.0, votes);
    // Stands for wait_s, then creeps forwards along a right arc with room.
    assert!(commands[..15].iter().all(SteeringCommand::is_stop));
    let first = commands
        .iter()
        .find(|c| !c.is_stop())
        .unwrap_or_else(|| panic!("stays: {:?}", a.recovery_stats()));
    assert!(first.speed_mps > 0.0 && first.speed_mps <= 1.0, "{first:?}");
    assert!(first.curvature < 0.0, "towards the way, right: {first:?}");
    assert!((5..=19).contains(&first.arc_index.unwrap()), "{first:?}");
    assert_eq!(a.recovery_stats().turns, 1, "{:?}", a.recovery_stats());
}

/// Issue 68: a skid-steer vehicle's arc set ends in turns in place (index
/// 0 right, 40 left). Cornered with the way behind and to the left, it
/// turns round in place to the left: never as a forward choice (for the
/// `wait_s` a block is waited out it stops, though the turn's fused vote
/// is the best), then on the left turn at the vehicle's yaw rate, no legs.
/// Where obstacle avoidance finds the turn clear for less than 20°, the
/// K-point turn of an Ackermann vehicle, on the driving arcs.
#[test]
fn a_vehicle_that_turns_in_place_turns_round_in_place_where_the_turn_is_clear() {
    let vehicle = VehicleConfig::warthog();
    let arcs = ArcSet::new(&ArcSetConfig {
        turn_in_place: true,
        ..ArcSetConfig::default()
    })
    .unwrap();
    let config = ArbiterConfig::default();
    // The driving arcs 1..=39 as `cornered` has them; the turns in place
    // clear for `turn_clear` radians, obstacle avoidance's best.
    let votes = |t: i64, turn_clear: f64| {
        let inner = cornered(t, true, 3.0, behind_left);
        inner.map(|b| {
            let mut v = Votes::new(41);
            for arc in 0..39 {
                let (value, vetoed) = (b.votes.values()[arc], b.votes.vetoed()[arc]);
                v.set(arc + 1, value);
                if vetoed {
                    v.veto(arc + 1, None);
                }
                if let Some(c) = b.votes.forward_clearance(arc) {
                    v.set_forward_clearance(arc + 1, c);
                }
                if let Some(c) = b.votes.reverse_clearance(arc) {
                    v.set_reverse_clearance(arc + 1, c);
                }
            }
            for turn in [0, 40] {
                if b.behaviour == "obstacle_avoidance" {
                    v.set(turn, 1.0);
                    v.set_forward_clearance(turn, turn_clear);
                    v.set_reverse_clearance(turn, 0.0);
                } else {
                    v.set(turn, if turn == 40 { 0.5 } else { -0.5 });
                }
            }
            BehaviourVotes { votes: v, ..b }
        })
    };
    let mut a = Arbiter::new(&config, arcs.clone(), &vehicle);
    let commands = drive(&mut a, 0, 6.0, |t| votes(t, std::f64::consts::PI));
    let wait = (config.recovery.wait_s * 10.0) as usize;
    assert!(
        commands[..wait].iter().all(SteeringCommand::is_stop),
        "{:?}",
        &commands[..wait]
    );
    let turning: Vec<_> = commands.iter().filter(|c| c.is_turn_in_place()).collect();
    assert!(turning.len() > 20, "{commands:?}");
    for c in &turning {
        assert_eq!(c.arc_index, Some(40));
        assert!(
            (c.turn_rate_radps - 60f64.to_radians()).abs() < 1e-9,
            "{c:?}"
        );
        assert_eq!((c.speed_mps, c.curvature), (0.0, f64::INFINITY));
    }
    let stats = *a.recovery_stats();
    assert_eq!((stats.turns_in_place, stats.turn_legs), (1, 0), "{stats:?}");
    // Over 4 s of turning at 60°/s, less the start: round and on.
    assert!(stats.turned_deg > 180.0, "{stats:?}");
    // Hemmed in: the K-point turn, on the driving arcs.
    let mut a = Arbiter::new(&config, arcs, &vehicle);
    let commands = drive(&mut a, 0, 20.0, |t| votes(t, 0.2));
    assert!(!commands.iter().any(SteeringCommand::is_turn_in_place));
    let stats = *a.recovery_stats();
    assert!(
        stats.turns_in_place == 0 && stats.turn_legs >= 2,
        "{stats:?}"
    );
    assert!(
        commands
            .iter()
            .filter(|c| !c.is_stop())
            .all(|c| c.arc_index == Some(1) || c.arc_index == Some(39))
    );
}
