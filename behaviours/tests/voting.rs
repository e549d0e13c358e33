//! Hand-computed cases of 002 §6 for the two behaviours, the registry, and
//! the behaviours together with the arbiter.
//!
//! Distances "ahead" are measured from the front bumper (x = 4.0 m in the
//! vehicle frame), which is where the swept footprint first touches them.

use arcnav_arbiter::{Arbiter, ArbiterConfig, BehaviourVotes, StopReason, Votes};
use arcnav_behaviours::{
    Behaviour, GoalSeeking, GoalSeekingConfig, Mission, ObstacleAvoidance, ObstacleAvoidanceConfig,
    Overlay, Registry, RegistryError, Setup, VoteContext, Waypoint,
};
use arcnav_localmap::{LocalMap, LocalMapConfig, MapSnapshot};
use arcnav_perception::{FovPolygon, ObstacleCell, ObstacleReport, Reasons};
use arcnav_vehicle::frames::planar_isometry;
use arcnav_vehicle::{
    Arc, ArcSet, ArcSetConfig, DrivenPath, Pose, Steering, SteeringCommand, SteeringResponse,
    VehicleConfig,
};
use nalgebra::Point2;

static LOCALMAP: std::sync::LazyLock<arcnav_localmap::LocalMapConfig> =
    std::sync::LazyLock::new(arcnav_localmap::LocalMapConfig::default);

const FRONT: f64 = 4.0;

fn arcs() -> ArcSet {
    ArcSet::new(&ArcSetConfig::default()).unwrap()
}

fn setup<'a>(arcs: &'a ArcSet, vehicle: &'a VehicleConfig) -> Setup<'a> {
    Setup {
        arcs,
        vehicle,
        localmap: &LOCALMAP,
        statics: None,
        cruise_mps: 2.5,
        area: None,
        unreachable: Default::default(),
    }
}

/// A map with cells at the given vehicle-frame positions (vehicle at the origin heading east).
/// The map after one image that saw everything around the vehicle and
/// reported `cells`.
fn snapshot(cells: &[(f64, f64)]) -> MapSnapshot {
    snapshot_seeing(cells, 40.0)
}

/// ... that saw the ground within `reach` of the vehicle (a square).
fn snapshot_seeing(cells: &[(f64, f64)], reach: f64) -> MapSnapshot {
    snapshot_seeing_from(cells, -reach, reach)
}

/// ... that saw the ground from `near` to `reach` ahead of the vehicle
/// origin, within `reach` to each side.
fn snapshot_seeing_from(cells: &[(f64, f64)], near: f64, reach: f64) -> MapSnapshot {
    let cells = cells.iter().map(|&(x, y)| rock(x, y)).collect();
    snapshot_of(cells, near, reach)
}

/// A 0.6 m rock at (x, y).
fn rock(x: f64, y: f64) -> ObstacleCell {
    ObstacleCell {
        x,
        y,
        z_min: 0.0,
        z_max: 0.6,
        reasons: Reasons::HEIGHT_VARIATION,
        region: 0,
        cost: 1.0,
    }
}

/// The near edge of a drop-off across the way at `x`, from `-half_width`
/// to `half_width`: cells 0.2 m apart with the reason drop-off, of `cost`
/// (1: flagged; below 1: suspected).
fn drop_off_edge(x: f64, half_width: f64, cost: f32) -> Vec<ObstacleCell> {
    let cells = (2.0 * half_width / 0.2).round() as u32;
    (0..=cells)
        .map(|i| ObstacleCell {
            x,
            y: -half_width + 0.2 * f64::from(i),
            z_min: 0.0,
            z_max: 0.0,
            reasons: Reasons::DROP_OFF,
            region: 0,
            cost,
        })
        .collect()
}

/// The map after one image that saw the ground from `near` to `reach`
/// ahead of the vehicle origin, within `reach` to each side, and reported
/// `cells`.
fn snapshot_of(cells: Vec<ObstacleCell>, near: f64, reach: f64) -> MapSnapshot {
    snapshot_after(vec![(cells, [near, reach, reach])])
}

/// The map after images, each reporting its cells and seeing the ground
/// from `[near, far, half_width]`: `near` to `far` ahead of the vehicle
/// origin, within `half_width` to each side.
fn snapshot_after(images: Vec<(Vec<ObstacleCell>, [f64; 3])>) -> MapSnapshot {
    snapshot_after_rectangles(
        images
            .into_iter()
            .map(|(cells, [near, far, half])| (cells, [near, far, -half, half]))
            .collect(),
    )
}

/// ... each image seeing the rectangle [x0, x1] × [y0, y1].
fn snapshot_after_rectangles(images: Vec<(Vec<ObstacleCell>, [f64; 4])>) -> MapSnapshot {
    snapshot_at(&Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0)), images)
}

/// ... the vehicle at `pose` (cells and rectangles in the world frame).
fn snapshot_at(pose: &Pose, images: Vec<(Vec<ObstacleCell>, [f64; 4])>) -> MapSnapshot {
    snapshot_of_vehicle_at(&VehicleConfig::default(), pose, images)
}

/// ... the local map kept for `vehicle` (which clears its own ground).
fn snapshot_of_vehicle_at(
    vehicle: &VehicleConfig,
    pose: &Pose,
    images: Vec<(Vec<ObstacleCell>, [f64; 4])>,
) -> MapSnapshot {
    let mut map = LocalMap::new(
        &LocalMapConfig {
            assume_seen_m: 0.0,
            ..LocalMapConfig::default()
        },
        vehicle,
    );
    map.update(pose);
    for (cells, [near, far, left, right]) in images {
        let report = ObstacleReport {
            utime: 0,
            sensor: "test".into(),
            cell_size_m: 0.2,
            cells,
            regions: vec![],
            fov: FovPolygon::new(vec![
                Point2::new(near, left),
                Point2::new(far, left),
                Point2::new(far, right),
                Point2::new(near, right),
            ]),
            shadows: Default::default(),
            ..ObstacleReport::default()
        };
        map.insert(&report).unwrap();
    }
    (*map.snapshot()).clone()
}

fn avoidance_votes(cells: &[(f64, f64)]) -> Votes {
    avoidance_votes_on(&snapshot(cells), ObstacleAvoidanceConfig::default())
}

fn avoidance_votes_on(map: &MapSnapshot, config: ObstacleAvoidanceConfig) -> Votes {
    avoidance_votes_moving(map, config, 0.0)
}

/// ... with the vehicle driving straight ahead at `speed` m/s.
fn avoidance_votes_moving(map: &MapSnapshot, config: ObstacleAvoidanceConfig, speed: f64) -> Votes {
    let mut pose = Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0));
    pose.velocity.x = speed;
    avoidance_votes_at(map, config, &pose)
}

/// ... with the vehicle at `pose`.
fn avoidance_votes_at(map: &MapSnapshot, config: ObstacleAvoidanceConfig, pose: &Pose) -> Votes {
    let (arcs, vehicle) = (arcs(), VehicleConfig::default());
    let mut behaviour = ObstacleAvoidance::new(config, &setup(&arcs, &vehicle));
    let mission = Mission::default();
    let ctx = VoteContext::new(0, pose, map, &mission, &arcs);
    let mut votes = Votes::new(arcs.len());
    behaviour.vote(&ctx, &mut votes);
    votes
}

/// The highest speed obstacle avoidance accepts on any arc it allows.
fn best_speed(votes: &Votes) -> f64 {
    (0..votes.len())
        .filter(|&i| !votes.is_vetoed(i))
        .filter_map(|i| votes.arc_speed(i))
        .fold(0.0, f64::max)
}

#[test]
fn an_obstacle_5_m_ahead_forbids_straight_and_leaves_the_hard_turns_clear() {
    let votes = avoidance_votes(&[(FRONT + 5.0, 0.0)]);
    assert!(
        votes.is_vetoed(19),
        "straight collides 5 m ahead, closer than 6 m"
    );
    assert_eq!(votes.vote(19), Some(-1.0));
    let cause = votes.causes()[19].expect("the veto names its cell").at();
    assert!(
        (f64::from(cause[0]) - 9.0).abs() < 0.3 && f64::from(cause[1]).abs() < 0.3,
        "{cause:?}"
    );
    assert_eq!(votes.vote(0), Some(1.0), "hard right is clear");
    assert_eq!(votes.vote(38), Some(1.0), "hard left is clear");
    assert!(!votes.is_vetoed(0) && !votes.is_vetoed(38));
}

#[test]
fn an_obstacle_15_m_ahead_makes_straight_negative_but_not_forbidden() {
    let votes = avoidance_votes(&[(FRONT + 15.0, 0.0)]);
    let straight = votes.vote(19).unwrap();
    assert!(!votes.is_vetoed(19));
    // Contact after 15 m - 0.2 m (half a patch): -(1 - (14.8 - 6) / 12) = -0.27.
    assert!(
        (straight - (-0.267)).abs() < 0.03,
        "straight votes {straight}"
    );
    // Nearer obstacles give lower votes.
    let nearer = avoidance_votes(&[(FRONT + 10.0, 0.0)]).vote(19).unwrap();
    assert!(nearer < straight, "{nearer} < {straight}");
}

#[test]
fn a_near_miss_lowers_the_vote_of_the_arc_passing_beside_it() {
    // 1.8 m left of the centreline, 8 m ahead: 0.5 m from the grown footprint.
    let votes = avoidance_votes(&[(FRONT + 8.0, 1.8)]);
    let straight = votes.vote(19).unwrap();
    assert!(
        straight > 0.0 && straight < 1.0,
        "straight grazes it: {straight}"
    );
    assert_eq!(votes.vote(5), Some(1.0), "a right turn passes far from it");
    // Closer passes cost more.
    let closer = avoidance_votes(&[(FRONT + 8.0, 1.45)]).vote(19).unwrap();
    assert!(closer < straight, "{closer} < {straight}");
}

#[test]
fn an_empty_map_makes_every_arc_clear() {
    let votes = avoidance_votes(&[]);
    assert!(votes.values().iter().all(|&v| v == 1.0));
    assert!((0..votes.len()).all(|i| votes.arc_speed(i).unwrap() > 5.0));
}

#[test]
fn unseen_ground_slows_forbids_or_is_ignored_as_configured() {
    use arcnav_behaviours::UnseenGround;
    let straight = 19;
    // Only the ground within 8 m of the vehicle was seen (the body reaches
    // 4 m ahead): 4 m of seen ground ahead of the bumper.
    let map = snapshot_seeing(&[], 8.0);
    let config = |unseen_ground| ObstacleAvoidanceConfig {
        unseen_ground,
        ..ObstacleAvoidanceConfig::default()
    };
    let slow = avoidance_votes_on(&map, config(UnseenGround::Slow));
    let seen = avoidance_votes(&[]);
    // The speed governor (issue 63): v·t + v²/2a = 4 m (less half a
    // patch) less the 2 m stop margin, braking as hard as the vehicle can
    // (3 m/s²: a hole may hide there, or may not): about 2.1 m/s.
    let (a, t): (f64, f64) = (3.0, 0.75);
    let limit = -a * t + ((a * t).powi(2) + 2.0 * a * 2.0).sqrt();
    let v = slow.arc_speed(straight).unwrap();
    assert!(
        v <= limit && v > 0.7 * limit,
        "{v} m/s, stopping 2 m short of 4 m: {limit}"
    );
    assert_eq!(
        slow.arc_speed_cause(straight),
        arcnav_arbiter::SpeedCause::VerifiedDistance
    );
    let verified = slow.verified_distance(straight).unwrap();
    assert!((3.5..=4.2).contains(&verified), "verified {verified} m");
    assert!(seen.arc_speed(straight).unwrap() > 2.0 * v);
    assert!(seen.verified_distance(straight).unwrap() > 15.0);
    assert!(
        slow.values().iter().all(|&v| v == 1.0),
        "slow does not steer"
    );
    // As an obstacle, unseen ground 4 m ahead forbids every arc.
    let obstacle = avoidance_votes_on(&map, config(UnseenGround::Obstacle));
    assert!((0..obstacle.len()).all(|i| obstacle.is_vetoed(i)));
    // Free: as if it had been seen.
    let free = avoidance_votes_on(&map, config(UnseenGround::Free));
    assert_eq!(free, seen);
    // The braking counted on for what is known to be there
    // (`braking_fraction`) is not what the governor counts on.
    let braking = avoidance_votes_on(
        &map,
        ObstacleAvoidanceConfig {
            braking_fraction: 1.0,
            ..config(UnseenGround::Slow)
        },
    );
    assert_eq!(braking.arc_speed(straight), Some(v));
}

#[test]
fn a_suspected_drop_off_slows_an_arc_only_to_the_speed_that_stops_where_a_hole_would_show() {
    let straight = 19;
    // The near edge of a suspected hole across the way, `ahead` m beyond
    // the bumper; as a definite drop-off with `cost` 1.
    let edge = |ahead: f64, cost: f32| {
        snapshot_of(drop_off_edge(FRONT + ahead + 0.1, 1.5, cost), -40.0, 40.0)
    };
    let config = |hole_seen_within_m| ObstacleAvoidanceConfig {
        hole_seen_within_m,
        ..ObstacleAvoidanceConfig::default()
    };
    // A hole that may be there is stopped for braking as hard as the
    // vehicle can (3 m/s²), as ground not verified is (issue 63).
    let (a, t): (f64, f64) = (3.0, 0.75);
    let stopping = |room: f64| -a * t + ((a * t).powi(2) + 2.0 * a * room).sqrt();
    // (Within a map patch of the edge.)
    let near = |v: f64, expected: f64| (v - expected).abs() < 0.1;
    // 12 m ahead: stop 2 m short of it (5.8 m/s), the vote untouched.
    let far = avoidance_votes_on(&edge(12.0, 0.5), config(6.0));
    let v = far.arc_speed(straight).unwrap();
    assert!(near(v, stopping(10.0)), "{v} m/s, not {}", stopping(10.0));
    assert!(
        far.values().iter().all(|&v| v == 1.0),
        "a suspect does not steer"
    );
    // 1 m ahead: no slower than stopping within the 6 m where a hole
    // would have been flagged by now (it is not one, or it would be a cell).
    let close = avoidance_votes_on(&edge(1.0, 0.5), config(6.0));
    assert!(!close.is_vetoed(straight));
    let v = close.arc_speed(straight).unwrap();
    assert!(
        (v - stopping(4.0)).abs() < 1e-6,
        "{v} m/s, not {}",
        stopping(4.0)
    );
    // Where a hole shows unknown (0): stop short of it.
    let unknown = avoidance_votes_on(&edge(1.0, 0.5), config(0.0));
    assert_eq!(unknown.arc_speed(straight), Some(0.0));
    assert!((0..close.len()).all(|i| !close.is_vetoed(i)));
    // The same edge flagged for certain forbids the arc.
    let definite = avoidance_votes_on(&edge(1.0, 1.0), config(6.0));
    assert!(definite.is_vetoed(straight));
}

#[test]
fn unseen_ground_as_an_obstacle_stops_blocking_once_it_has_been_seen() {
    use arcnav_behaviours::UnseenGround;
    let (arcs, vehicle) = (arcs(), VehicleConfig::default());
    let config = ObstacleAvoidanceConfig {
        unseen_ground: UnseenGround::Obstacle,
        ..ObstacleAvoidanceConfig::default()
    };
    let mut behaviour = ObstacleAvoidance::new(config, &setup(&arcs, &vehicle));
    let pose = Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0));
    let mission = Mission::default();
    let mut vote = |map: &MapSnapshot| {
        let ctx = VoteContext::new(0, &pose, map, &mission, &arcs);
        let mut votes = Votes::new(arcs.len());
        behaviour.vote(&ctx, &mut votes);
        votes
    };
    // Seen only 8 m around: every arc forbidden; then all of it seen,
    // with no cell anywhere: none (the same behaviour, one cycle later).
    let blind = vote(&snapshot_seeing(&[], 8.0));
    assert!((0..blind.len()).all(|i| blind.is_vetoed(i)));
    let seen = vote(&snapshot(&[]));
    assert!(
        (0..seen.len()).all(|i| !seen.is_vetoed(i) && seen.values()[i] == 1.0),
        "{:?}",
        seen.values()
    );
}

/// Obstacle avoidance's vote for `arc` with the vehicle at `speed` m/s
/// driving curvature `curvature`, which its last command also asked for.
fn arc_vote_steering(map: &MapSnapshot, arc: usize, speed: f64, curvature: f64) -> (f32, bool) {
    let arcs = ArcSet::new(&ArcSetConfig {
        driven_paths: arcnav_vehicle::DrivenPaths::On,
        ..Default::default()
    })
    .unwrap();
    let vehicle = VehicleConfig::default();
    let mut behaviour =
        ObstacleAvoidance::new(ObstacleAvoidanceConfig::default(), &setup(&arcs, &vehicle));
    let mut pose = Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0));
    pose.velocity.x = speed;
    pose.yaw_rate = speed * curvature;
    let last = SteeringCommand {
        utime: 0,
        curvature,
        speed_mps: speed,
        arc_index: Some(arcs.nearest_index(curvature)),
        vote: 1.0,
        turn_rate_radps: 0.0,
    };
    let mission = Mission::default();
    let mut ctx = VoteContext::new(0, &pose, map, &mission, &arcs);
    ctx.last_command = Some(&last);
    let mut votes = Votes::new(arcs.len());
    behaviour.vote(&ctx, &mut votes);
    (votes.values()[arc], votes.is_vetoed(arc))
}

/// A point the arc's widest band (body, half a patch and the near-miss
/// margin) never touches, over which the body drives on the path the
/// vehicle takes when commanded onto the arc at `speed` from `curvature`:
/// the first such rear-axle position from `from_m` along the path.
fn driven_over_not_swept(k: f64, speed: f64, curvature: f64, from_m: f64) -> Point2<f64> {
    let vehicle = VehicleConfig::default();
    let body = vehicle.footprint();
    let steering = Steering {
        speed_mps: speed,
        curvature,
        commanded_curvature: curvature,
    };
    let path = DrivenPath::new(&steering, &SteeringResponse::of(&vehicle), k);
    let widest = Arc::new(k).swept(body.widened(0.2 + 1.0 + 0.3), 18.0);
    path.sample(16.0, 0.1)
        .into_iter()
        .filter(|(s, _)| *s >= from_m)
        .map(|(_, pose)| pose.position)
        .find(|&p| !widest.covers(p))
        .expect("the path leaves the arc's sweep")
}

#[test]
fn at_speed_an_arc_is_judged_along_the_path_the_vehicle_drives_onto_it() {
    let arcs = arcs();
    // Straight at 8 m/s, the hardest left: 2 m of latency, then 6.7 m
    // to steer full left: the turn comes late, wide of the arc.
    let left = arcs.len() - 1;
    let k = arcs.curvature(left).unwrap();
    let p = driven_over_not_swept(k, 8.0, 0.0, 8.0);
    let map = snapshot(&[(p.x, p.y)]);
    let (still, vetoed) = arc_vote_steering(&map, left, 0.0, 0.0);
    assert!(
        still > 0.99 && !vetoed,
        "standing, the arc is clear: {still}"
    );
    let (moving, vetoed) = arc_vote_steering(&map, left, 8.0, 0.0);
    assert!(
        vetoed || moving < 0.0,
        "at 8 m/s the path meets the cell at {p}: {moving}"
    );
    // Turning hard right at 6 m/s, straight ahead: the vehicle first goes
    // on turning right for the latency, then unwinds over 5 m.
    let straight = arcs.straight_index();
    let p = driven_over_not_swept(0.0, 6.0, -0.125, 4.0);
    assert!(p.y < -2.0, "{p}");
    let map = snapshot(&[(p.x, p.y)]);
    let (still, _) = arc_vote_steering(&map, straight, 0.0, -0.125);
    assert!(still > 0.99, "standing, straight is clear: {still}");
    let (moving, vetoed) = arc_vote_steering(&map, straight, 6.0, -0.125);
    assert!(vetoed || moving < 0.0, "turning right at 6 m/s: {moving}");
}

#[test]
fn an_arc_the_vehicle_can_no_longer_stop_on_before_unseen_ground_is_forbidden() {
    // 4 m of seen ground ahead of the bumper. At 5 m/s the vehicle needs
    // 5·0.75 + 5²/(2·3) = 7.9 m to stand, braking as hard as it can: a
    // speed limit on the arcs straight ahead would come too late.
    let map = snapshot_seeing(&[], 8.0);
    let config = ObstacleAvoidanceConfig::default;
    let fast = avoidance_votes_moving(&map, config(), 5.0);
    assert!(fast.is_vetoed(19), "straight");
    let cause = fast.causes()[19]
        .expect("the veto names the unseen ground")
        .at();
    assert!(
        (f64::from(cause[0]) - 8.0).abs() < 0.5,
        "the first unseen ground straight ahead: {cause:?}"
    );
    // At 1 m/s it stands within 0.9 m: every arc stays allowed, slowly.
    let slow = avoidance_votes_moving(&map, config(), 1.0);
    assert!((0..slow.len()).all(|i| !slow.is_vetoed(i)));
    assert!(slow.arc_speed(19).unwrap() < 2.0);
}

#[test]
fn ground_under_the_front_overhang_must_have_been_seen() {
    // Seen up to 3.6 m: under the wheels (to the front axle, 3.3 m) the
    // vehicle stands; the overhang to the bumper (4.0 m) may hang over a
    // ledge no image saw. Nothing may move it forward.
    let overhang = avoidance_votes_on(
        &snapshot_seeing(&[], 3.6),
        ObstacleAvoidanceConfig::default(),
    );
    assert_eq!(best_speed(&overhang), 0.0);
    // Ground under the wheels that no image saw (behind x = 3.2 m here)
    // does not hold the vehicle: it stands there.
    let wheels = avoidance_votes_on(
        &snapshot_seeing_from(&[], 3.2, 9.0),
        ObstacleAvoidanceConfig::default(),
    );
    assert!(best_speed(&wheels) > 1.0);
    let ahead = avoidance_votes_on(
        &snapshot_seeing(&[], 9.0),
        ObstacleAvoidanceConfig::default(),
    );
    assert!(best_speed(&ahead) > 1.0);
}

#[test]
fn backing_up_is_checked_against_the_cells_and_the_unseen_ground_behind() {
    let reach = ObstacleAvoidanceConfig::default().reverse_reach_m;
    let clearance = |votes: &Votes, arc: usize| votes.reverse_clearance(arc).unwrap();
    // Open seen ground: every backward arc is clear as far as it is checked.
    let open = avoidance_votes(&[]);
    assert!((0..39).all(|arc| clearance(&open, arc) == reach));
    // A rock 2 m behind the rear bumper (x = -0.6 m), 1.5 m left of the
    // centre line (its patch's centre 1.4 m; the body with half a patch
    // and the margin reaches 1.6 m): straight back meets it after ~2 m less
    // the half patch and grid rounding. Backing with the wheels turned
    // right swings the tail away from it: the body's flank meets it only
    // after ~3.5 m, as the nose swings out. Turned left, the tail stays on
    // it (the inner side of the turn moves least).
    let rock = avoidance_votes(&[(-2.6, 1.5)]);
    let straight = clearance(&rock, 19);
    assert!((1.4..=2.0).contains(&straight), "{straight} m");
    let all: Vec<f64> = (0..39).map(|arc| clearance(&rock, arc)).collect();
    assert!((3.0..reach).contains(&all[0]), "hard right: {all:?}");
    assert!(all[38] < straight + 0.5, "hard left: {all:?}");
    // Ground behind the vehicle no image has seen (only ahead of the rear
    // axle was seen): the body may not back onto it.
    let blind = avoidance_votes_on(
        &snapshot_seeing_from(&[], 0.0, 20.0),
        ObstacleAvoidanceConfig::default(),
    );
    assert!(
        (0..39).all(|arc| clearance(&blind, arc) < 0.5),
        "{:?}",
        blind.reverse_clearances()
    );
    // The forward votes do not change with what lies behind.
    assert_eq!(rock.values(), open.values());
    // reverse_reach_m = 0: no opinion on backing up.
    let off = avoidance_votes_on(
        &snapshot(&[]),
        ObstacleAvoidanceConfig {
            reverse_reach_m: 0.0,
            ..Default::default()
        },
    );
    assert!((0..39).all(|arc| off.reverse_clearance(arc).is_none()));
}

#[test]
fn creeping_forwards_is_clear_to_the_first_cell_or_unseen_ground_however_close() {
    let max = ObstacleAvoidanceConfig::default().max_distance_m;
    let clearance = |votes: &Votes, arc: usize| votes.forward_clearance(arc).unwrap();
    // Open seen ground: as far as arcs are judged.
    let open = avoidance_votes(&[]);
    assert!((0..39).all(|arc| clearance(&open, arc) == max));
    // A rock 2 m ahead of the bumper: straight is vetoed for driving (it is
    // within min_distance_m) but still clear to creep about 2 m, less half
    // a patch (no arc turns away from it in 2 m).
    let rock = avoidance_votes(&[(FRONT + 2.0, 0.0)]);
    assert!(rock.is_vetoed(19));
    let straight = clearance(&rock, 19);
    assert!((1.5..=2.1).contains(&straight), "{straight} m");
    // A rock 3 m ahead and 2.5 m left: the hard left arc meets it within
    // a few metres, the hard right one never does.
    let left = avoidance_votes(&[(FRONT + 3.0, 2.5)]);
    assert!(clearance(&left, 38) < 4.0, "{}", clearance(&left, 38));
    assert_eq!(clearance(&left, 0), max);
    // Ground seen only to 3 m ahead of the bumper: no further.
    let blind = avoidance_votes_on(
        &snapshot_seeing(&[], FRONT + 3.0),
        ObstacleAvoidanceConfig::default(),
    );
    let all: Vec<f64> = (0..39).map(|arc| clearance(&blind, arc)).collect();
    assert!(all.iter().all(|&c| c <= 3.1), "{all:?}");
    assert!(all[19] > 2.0, "{all:?}");
}

/// A manoeuvre's leg creeping forwards keeps `reverse_margin_m` (to the
/// near-miss band within it, 0.25 m) beside the body, as backing up does:
/// a turn's forward legs and a retrace's forward runs brought a corner
/// 0.2 m from a bank's side when they were clear to the body itself.
#[test]
fn creeping_forwards_keeps_the_reverse_margin_beside_the_body() {
    let clearance = |votes: &Votes| votes.forward_clearance(19).unwrap();
    let max = ObstacleAvoidanceConfig::default().max_distance_m;
    // A rock 3 m ahead of the bumper, 0.15 m beside the straight arc's
    // footprint (the body 1.1 m wide each side, and half a patch).
    let beside = [(FRONT + 3.0, 1.45)];
    let votes = avoidance_votes(&beside);
    assert!(!votes.is_vetoed(19) && votes.values()[19] > 0.0);
    let straight = clearance(&votes);
    assert!((2.5..=3.1).contains(&straight), "{straight} m");
    // Without the margin, the straight arc passes it.
    let no_margin = avoidance_votes_on(
        &snapshot(&beside),
        ObstacleAvoidanceConfig {
            reverse_margin_m: 0.0,
            ..Default::default()
        },
    );
    assert_eq!(clearance(&no_margin), max);
    // 0.4 m beside the footprint, outside the margin: clear.
    assert_eq!(clearance(&avoidance_votes(&[(FRONT + 3.0, 1.7)])), max);
}

#[test]
fn being_boxed_in_slows_the_speed_vote() {
    // A wall 7 m ahead alone is avoided by turning: no reason to slow down.
    let ahead: Vec<(f64, f64)> = (-25..=25).map(|k| (FRONT + 7.0, k as f64 * 0.4)).collect();
    let open = best_speed(&avoidance_votes(&[]));
    assert_eq!(best_speed(&avoidance_votes(&ahead)), open);
    // With walls 5 m to each side as well, every arc ends within ~8 m.
    let mut boxed = ahead;
    boxed.extend((5..=27).flat_map(|k| [(k as f64 * 0.4, 5.0), (k as f64 * 0.4, -5.0)]));
    let slowed = best_speed(&avoidance_votes(&boxed));
    assert!(
        slowed < 0.7 * open,
        "{slowed} m/s boxed in, {open} m/s in the open"
    );
}

fn goal_votes(goal: (f64, f64)) -> Votes {
    goal_votes_moving(goal, GoalSeeking::new(GoalSeekingConfig::default()), 0.0)
}

/// ... by `behaviour`, the vehicle driving straight at `speed` m/s.
fn goal_votes_moving(goal: (f64, f64), mut behaviour: GoalSeeking, speed: f64) -> Votes {
    let arcs = arcs();
    let map = MapSnapshot::default();
    let mut pose = Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0));
    pose.velocity.x = speed;
    let mission = Mission {
        version: 1,
        waypoints: vec![Waypoint {
            x: goal.0,
            y: goal.1,
            radius_m: None,
        }],
    };
    let ctx = VoteContext::new(0, &pose, &map, &mission, &arcs);
    let mut votes = Votes::new(arcs.len());
    behaviour.vote(&ctx, &mut votes);
    votes
}

#[test]
fn at_speed_goal_seeking_asks_for_more_turn_to_head_for_the_goal_in_time() {
    // The goal 45° to the left, 14 m off. Standing, the arc that heads
    // for it after the lookahead; at 8 m/s the turn comes late (2 m of
    // latency, then the steering's rate), so it takes a harder one.
    let vehicle = VehicleConfig::default();
    let goal = (10.0, 10.0);
    let best = |votes: &Votes| best_arc(votes);
    let still = best(&goal_votes_moving(
        goal,
        GoalSeeking::new(GoalSeekingConfig::default())
            .with_response(SteeringResponse::of(&vehicle)),
        0.0,
    ));
    let moving = best(&goal_votes_moving(
        goal,
        GoalSeeking::new(GoalSeekingConfig::default())
            .with_response(SteeringResponse::of(&vehicle)),
        8.0,
    ));
    assert!(still > 19 && still < 38, "standing: arc {still}");
    assert!(moving > still, "at 8 m/s arc {moving}, standing {still}");
    // A vehicle that takes arcs at once asks for the same at any speed.
    let ideal = best(&goal_votes_moving(
        goal,
        GoalSeeking::new(GoalSeekingConfig::default()),
        8.0,
    ));
    assert_eq!(ideal, still);
}

#[test]
fn a_goal_to_the_left_prefers_left_arcs_and_votes_vary_smoothly() {
    let votes = goal_votes((5.0, 40.0));
    let v = votes.values();
    assert!(
        v[38] > v[19] && v[19] > v[0],
        "left {} > straight {} > right {}",
        v[38],
        v[19],
        v[0]
    );
    for pair in v.windows(2) {
        assert!(
            pair[1] >= pair[0],
            "votes rise steadily towards the left: {v:?}"
        );
        assert!(
            (pair[1] - pair[0]).abs() < 0.15,
            "no jump between neighbouring arcs"
        );
    }
    // Straight ahead: straight is best.
    let ahead = goal_votes((100.0, 0.0));
    let best = (0..39)
        .max_by(|&a, &b| ahead.values()[a].total_cmp(&ahead.values()[b]))
        .unwrap();
    assert_eq!(best, 19);
}

#[test]
fn goal_seeking_advances_through_the_waypoints_and_reports_the_mission_complete() {
    let arcs = arcs();
    let mut behaviour = GoalSeeking::new(GoalSeekingConfig::default());
    let map = MapSnapshot::default();
    let mission = Mission {
        version: 7,
        waypoints: vec![
            Waypoint {
                x: 20.0,
                y: 0.0,
                radius_m: None,
            },
            Waypoint {
                x: 40.0,
                y: 0.0,
                radius_m: Some(1.0),
            },
        ],
    };
    let mut vote_at = |x: f64| {
        let pose = Pose::at_rest(0, planar_isometry(x, 0.0, 0.0));
        let ctx = VoteContext::new(0, &pose, &map, &mission, &arcs);
        let mut votes = Votes::new(arcs.len());
        behaviour.vote(&ctx, &mut votes);
        (behaviour.progress().unwrap(), votes)
    };
    assert_eq!(vote_at(0.0).0.current, 0);
    assert_eq!(
        vote_at(16.0).0.current,
        1,
        "within 5 m of the first waypoint"
    );
    let (progress, votes) = vote_at(38.5);
    assert_eq!(progress.current, 1, "the second waypoint asks for 1 m");
    assert!(votes.speed_mps().is_none());
    let (progress, votes) = vote_at(39.5);
    assert!(progress.complete);
    assert_eq!(votes.speed_mps(), Some(0.0), "mission complete: stop");
    assert!(votes.values().iter().all(|&v| v == 0.0));
}

#[test]
fn a_waypoint_passed_during_a_detour_counts_as_reached() {
    let arcs = arcs();
    let mut behaviour = GoalSeeking::new(GoalSeekingConfig::default());
    let map = MapSnapshot::default();
    let mission = Mission {
        version: 1,
        waypoints: vec![
            Waypoint {
                x: 20.0,
                y: 0.0,
                radius_m: None,
            },
            Waypoint {
                x: 60.0,
                y: 0.0,
                radius_m: None,
            },
        ],
    };
    // 7 m to the side of it, already 2 m past: 7.3 m away, under 2 × 5 m.
    let pose = Pose::at_rest(0, planar_isometry(22.0, 7.0, 0.0));
    let ctx = VoteContext::new(0, &pose, &map, &mission, &arcs);
    let mut votes = Votes::new(arcs.len());
    behaviour.vote(&ctx, &mut votes);
    assert_eq!(behaviour.progress().unwrap().current, 1);
}

#[test]
fn the_registry_builds_by_name_and_lists_the_known_ones_for_an_unknown_name() {
    let (arcs, vehicle) = (arcs(), VehicleConfig::default());
    let registry = Registry::builtin();
    assert_eq!(
        registry.names(),
        ["goal_seeking", "obstacle_avoidance", "route"]
    );
    let table: toml::Table = toml::from_str("lookahead_m = 12.0").unwrap();
    let behaviour = registry
        .build("goal_seeking", &table, &setup(&arcs, &vehicle))
        .unwrap();
    assert_eq!(behaviour.name(), "goal_seeking");
    let err = registry
        .build(
            "wall_follower",
            &toml::Table::new(),
            &setup(&arcs, &vehicle),
        )
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        "unknown behaviour \"wall_follower\" (known: goal_seeking, obstacle_avoidance, route)"
    );
    let bad: toml::Table = toml::from_str("lookahed_m = 12.0").unwrap();
    let RegistryError::Config(err) = registry
        .build("goal_seeking", &bad, &setup(&arcs, &vehicle))
        .unwrap_err()
    else {
        panic!("a config error expected")
    };
    assert_eq!(err.key, "lookahed_m");
    let contradictory: toml::Table = toml::from_str("min_distance_m = 20.0").unwrap();
    let RegistryError::Config(err) = registry
        .build(
            "obstacle_avoidance",
            &contradictory,
            &setup(&arcs, &vehicle),
        )
        .unwrap_err()
    else {
        panic!("a config error expected")
    };
    assert_eq!(err.key, "max_distance_m");
    let prepared = registry
        .prepare("goal_seeking", &table, &setup(&arcs, &vehicle))
        .unwrap();
    let full = prepared.table();
    assert_eq!(
        prepared.build(&setup(&arcs, &vehicle)).name(),
        "goal_seeking"
    );
    assert_eq!(full["lookahead_m"].as_float(), Some(12.0));
    assert_eq!(
        full["arrival_radius_m"].as_float(),
        Some(5.0),
        "defaults filled in"
    );
}

/// Both behaviours vote, the arbiter decides.
fn decide(
    cells: &[(f64, f64)],
    goal: (f64, f64),
) -> (arcnav_vehicle::SteeringCommand, Option<StopReason>) {
    let (arcs, vehicle) = (arcs(), VehicleConfig::default());
    let registry = Registry::builtin();
    let s = setup(&arcs, &vehicle);
    let mut behaviours: Vec<Box<dyn Behaviour>> = ["obstacle_avoidance", "goal_seeking"]
        .iter()
        .map(|name| registry.build(name, &toml::Table::new(), &s).unwrap())
        .collect();
    let mut arbiter = Arbiter::new(&ArbiterConfig::default(), arcs.clone(), &vehicle);
    arbiter.set_explain(true);
    let map = snapshot(cells);
    let pose = Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0));
    let mission = Mission {
        version: 1,
        waypoints: vec![Waypoint {
            x: goal.0,
            y: goal.1,
            radius_m: None,
        }],
    };
    let ctx = VoteContext::new(0, &pose, &map, &mission, &arcs);
    for behaviour in &mut behaviours {
        let mut votes = Votes::new(arcs.len());
        behaviour.vote(&ctx, &mut votes);
        arbiter
            .on_votes(&BehaviourVotes {
                behaviour: behaviour.name().into(),
                utime: 0,
                votes,
            })
            .unwrap();
    }
    let command = arbiter.decide(0);
    (command, arbiter.decision().unwrap().stop.clone())
}

#[test]
fn with_a_rock_ahead_and_the_goal_ahead_the_vehicle_steers_around_it() {
    let rock: Vec<(f64, f64)> = (-2..=2)
        .flat_map(|i| (-2..=2).map(move |j| (FRONT + 8.0 + i as f64 * 0.4, j as f64 * 0.4)))
        .collect();
    let (command, stop) = decide(&rock, (100.0, 0.0));
    assert_eq!(stop, None);
    let arc = command.arc_index.unwrap();
    assert_ne!(arc, 19, "not into the rock");
    assert!(command.speed_mps > 0.0);
    let (free, _) = decide(&[], (100.0, 0.0));
    assert_eq!(
        free.arc_index,
        Some(19),
        "with nothing in the way, straight to the goal"
    );
}

#[test]
fn a_wall_across_every_arc_stops_the_vehicle() {
    let wall: Vec<(f64, f64)> = (-25..=25).map(|k| (FRONT + 1.5, k as f64 * 0.4)).collect();
    let (command, stop) = decide(&wall, (100.0, 0.0));
    assert!(command.is_stop());
    assert_eq!(command.speed_mps, 0.0);
    assert!(
        matches!(stop, Some(StopReason::AllArcsForbidden { .. })),
        "{stop:?}"
    );
}

#[test]
fn the_same_inputs_give_the_same_decision() {
    let rock = [(FRONT + 6.0, 0.4), (FRONT + 6.4, 0.8), (FRONT + 9.0, -2.0)];
    assert_eq!(decide(&rock, (50.0, 20.0)), decide(&rock, (50.0, 20.0)));
}

/// The route's votes at the origin heading east, for a waypoint at
/// (`goal`, 0), with `statics` known, on an empty map.
fn route_votes(goal: f64, statics: Option<&std::sync::Arc<arcnav_localmap::StaticMap>>) -> Votes {
    route_votes_to([goal, 0.0], statics, &Default::default())
}

/// ... for a waypoint at `goal`, with `[behaviours.route]` set by `table`.
fn route_votes_to(
    goal: [f64; 2],
    statics: Option<&std::sync::Arc<arcnav_localmap::StaticMap>>,
    table: &toml::Table,
) -> Votes {
    route_votes_on(None, goal, statics, table)
}

/// ... on `map` (an empty map seen 20 m round if none).
fn route_votes_on(
    map: Option<&MapSnapshot>,
    goal: [f64; 2],
    statics: Option<&std::sync::Arc<arcnav_localmap::StaticMap>>,
    table: &toml::Table,
) -> Votes {
    let arcs = arcs();
    let vehicle = VehicleConfig::default();
    let setup = Setup {
        statics,
        ..setup(&arcs, &vehicle)
    };
    let mut behaviour = Registry::builtin().build("route", table, &setup).unwrap();
    let map = map.cloned().unwrap_or_else(|| snapshot_seeing(&[], 20.0));
    let pose = Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0));
    let mission = mission_to(goal);
    let ctx = VoteContext::new(0, &pose, &map, &mission, &arcs);
    let mut votes = Votes::new(arcs.len());
    behaviour.vote(&ctx, &mut votes);
    votes
}

/// A mission of one waypoint at `goal`.
fn mission_to(goal: [f64; 2]) -> Mission {
    Mission {
        version: 1,
        waypoints: vec![Waypoint {
            x: goal[0],
            y: goal[1],
            radius_m: None,
        }],
    }
}

/// The arc with the highest vote (0 hardest right, 19 straight, 38 hardest left).
fn best_arc(votes: &Votes) -> usize {
    let vote = |i: usize| votes.vote(i).unwrap_or(f32::NEG_INFINITY);
    (0..votes.len())
        .max_by(|&a, &b| vote(a).total_cmp(&vote(b)))
        .unwrap()
}

#[test]
fn the_route_plans_around_a_wall_the_static_map_knows_before_any_image_shows_it() {
    // A wall 100 m long across the way 25 m ahead, beyond the 20 m window,
    // open to the left only (y from -60 to +40): every way round starts
    // more than 45° to the left.
    let grid = arcnav_localmap::OccupancyGrid {
        resolution_m: 0.5,
        origin: planar_isometry(25.0, -60.0, 0.0),
        cols: 2,
        rows: 200,
        occupied: vec![true; 400],
    };
    let statics = std::sync::Arc::new(arcnav_localmap::StaticMap::from_grid(&grid, 0.4).unwrap());
    let without = best_arc(&route_votes(80.0, None));
    let with = best_arc(&route_votes(80.0, Some(&statics)));
    assert!(
        without.abs_diff(19) <= 2,
        "no map: about straight, not {without}"
    );
    assert!(
        with >= 30,
        "the way round is well to the left: best arc {with}"
    );
}

/// A suspected drop-off (graded, reason drop-off: a hole's edge seen from
/// too far to show its depth) across the way: with `suspect_cost = 30`
/// the route plans round it when the way round is short, as round a
/// flagged ditch, and not across its suspected stretch. Counted as rough
/// ground (the default), crossing it costs less than a few metres of
/// detour: a vehicle stopped at a ditch whose ends were only suspected is
/// sent across them.
#[test]
fn with_a_suspect_cost_the_route_plans_round_a_suspected_drop_off_when_the_way_round_is_short() {
    // 8 m of suspected edge across the way 12 m ahead.
    let best = |cost: f32, table: &str| {
        let map = snapshot_of(drop_off_edge(12.0, 4.0, cost), -40.0, 40.0);
        best_arc(&route_votes_on(
            Some(&map),
            [60.0, 0.0],
            None,
            &toml::from_str(table).unwrap(),
        ))
    };
    let suspected = best(0.5, "suspect_cost = 30.0");
    let flagged = best(1.0, "");
    let as_rough = best(0.5, "");
    assert!(
        as_rough.abs_diff(19) <= 2,
        "as rough ground it is crossed: about straight, not {as_rough}"
    );
    assert!(
        flagged.abs_diff(19) >= 6,
        "a flagged ditch is planned round: {flagged}"
    );
    // Cheaper than free ground it would break the planner's heuristic.
    let arcs = arcs();
    let vehicle = VehicleConfig::default();
    let cheap: toml::Table = toml::from_str("suspect_cost = 0.5").unwrap();
    let Err(refused) = Registry::builtin().build("route", &cheap, &setup(&arcs, &vehicle)) else {
        panic!("suspect_cost 0.5 is refused");
    };
    let refused = refused.to_string();
    assert!(refused.contains("suspect_cost"), "{refused}");
    assert!(
        suspected.abs_diff(19) >= 6,
        "so is a suspected one with a suspect cost, when the way round is short: {suspected}"
    );
}

/// Over open ground the route heads where the waypoint lies, whatever its
/// bearing: as the bearing turns from 0° to 40° in 1° steps, its best arc
/// turns left steadily, never back, never by more than two arcs a step.
/// The planner's 8-connected path to a waypoint 60 m away at 10° goes
/// diagonally for some cells and straight for the others, in an order
/// that changes from cycle to cycle; its point 8 m along lay anywhere
/// from 0° to 45°, and at 10 m/s the votes flipped between arcs eight
/// apart. With `sight_line` the route aims along the straight line over
/// the same ground (without it this fails at once: arc 21 at 0°).
#[test]
fn with_a_sight_line_the_route_turns_steadily_with_the_bearing_of_the_waypoint() {
    let table: toml::Table = toml::from_str("sight_line = true").unwrap();
    let mut previous = None;
    for degrees in 0..=40 {
        let bearing = f64::from(degrees).to_radians();
        let best = best_arc(&route_votes_to(
            [60.0 * bearing.cos(), 60.0 * bearing.sin()],
            None,
            &table,
        ));
        if let Some(before) = previous {
            assert!(
                best >= before && best - before <= 2,
                "at {degrees}°: best arc {best}, at {}°: {before}",
                degrees - 1
            );
        } else {
            // The memory's 1 m cells put the waypoint's centre 0.5 m left.
            assert!(best.abs_diff(19) <= 1, "about straight at 0°, not {best}");
        }
        previous = Some(best);
    }
    assert!(previous.is_some_and(|best| best >= 30), "{previous:?}");
}

/// `lookahead_s`: goal seeking and the route aim that many seconds of
/// cruise ahead when that is farther than `lookahead_m`. At 10 m/s with
/// 2 s they vote as if `lookahead_m` were 20; at 2.5 m/s (5 m) the 8 or
/// 10 m hold. Goal seeking's votes for a waypoint 40 m ahead and 6 m to
/// the left show which distance was used.
#[test]
fn lookahead_s_aims_seconds_of_cruise_ahead_when_that_is_farther() {
    let arcs = arcs();
    let vehicle = VehicleConfig::default();
    let map = snapshot_seeing(&[], 20.0);
    let pose = Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0));
    let mission = Mission {
        version: 1,
        waypoints: vec![Waypoint {
            x: 40.0,
            y: 6.0,
            radius_m: None,
        }],
    };
    let votes = |name: &str, table: &str, cruise: f64| {
        let setup = Setup {
            cruise_mps: cruise,
            area: None,
            unreachable: Default::default(),
            ..setup(&arcs, &vehicle)
        };
        let mut behaviour = Registry::builtin()
            .build(name, &toml::from_str(table).unwrap(), &setup)
            .unwrap();
        let ctx = VoteContext::new(0, &pose, &map, &mission, &arcs);
        let mut votes = Votes::new(arcs.len());
        behaviour.vote(&ctx, &mut votes);
        votes.values().to_vec()
    };
    for (name, metres) in [("goal_seeking", 10.0), ("route", 8.0)] {
        let by_seconds = votes(name, "lookahead_s = 2.0", 10.0);
        let by_metres = votes(name, "lookahead_m = 20.0", 10.0);
        assert_eq!(by_seconds, by_metres, "{name}: 2 s at 10 m/s is 20 m");
        let slow = votes(name, "lookahead_s = 2.0", 2.5);
        let fixed = votes(name, &format!("lookahead_m = {metres}"), 2.5);
        assert_eq!(slow, fixed, "{name}: 5 m at 2.5 m/s is under {metres} m");
        assert_ne!(by_seconds, fixed, "{name}: the distance matters here");
    }
}

/// The map after images that saw the ground within 20 m round the vehicle
/// except a strip across the way from `near` to `far` ahead of its origin,
/// 40 m long: the shadow beyond a ledge, with the floor seen beyond it.
fn snapshot_with_shadow(near: f64, far: f64) -> MapSnapshot {
    snapshot_after(vec![
        (vec![], [-20.0, near, 20.0]),
        (vec![], [far, 20.0, 20.0]),
    ])
}

/// The route's best arc, its counters and its overlay, after one vote on
/// `map` per entry of `commands` (the last command sent before each), for
/// a waypoint at `goal` (vehicle standing at the origin heading east).
fn route_after(
    maps: &[&MapSnapshot],
    commands: &[Option<f64>],
    goal: [f64; 2],
    table: &str,
) -> (usize, Vec<(&'static str, u64)>, Overlay) {
    route_after_at(maps, commands, goal, table, 0.0)
}

/// ... the vehicle driving east at `speed` m/s.
fn route_after_at(
    maps: &[&MapSnapshot],
    commands: &[Option<f64>],
    goal: [f64; 2],
    table: &str,
    speed: f64,
) -> (usize, Vec<(&'static str, u64)>, Overlay) {
    let arcs = arcs();
    let vehicle = VehicleConfig::default();
    let setup = setup(&arcs, &vehicle);
    let table: toml::Table = toml::from_str(table).unwrap();
    let mut behaviour = Registry::builtin().build("route", &table, &setup).unwrap();
    let pose = Pose {
        velocity: nalgebra::Vector3::new(speed, 0.0, 0.0),
        ..Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0))
    };
    let mission = mission_to(goal);
    let mut best = 0;
    for (map, speed) in maps.iter().zip(commands) {
        let command = speed.map(|speed_mps| SteeringCommand {
            speed_mps,
            ..SteeringCommand::stop(0)
        });
        let ctx = VoteContext {
            last_command: command.as_ref(),
            ..VoteContext::new(0, &pose, map, &mission, &arcs)
        };
        let mut votes = Votes::new(arcs.len());
        behaviour.vote(&ctx, &mut votes);
        best = best_arc(&votes);
    }
    (best, behaviour.counters(), behaviour.overlay(&pose))
}

/// The route's planned path as its overlay draws it.
fn planned_path(overlay: &Overlay) -> Vec<[f64; 2]> {
    overlay
        .lines
        .iter()
        .find(|l| l.label.contains("path"))
        .expect("the path drawn")
        .points
        .clone()
}

fn counter(counters: &[(&'static str, u64)], name: &str) -> u64 {
    counters
        .iter()
        .find(|(n, _)| *n == name)
        .map(|&(_, v)| v)
        .unwrap_or_else(|| panic!("no counter {name}: {counters:?}"))
}

/// Where the route's path passes the line x = `x`: the side (+1 left,
/// -1 right) of its point nearest that line.
fn side_at(path: &[[f64; 2]], x: f64) -> f64 {
    let nearest = path
        .iter()
        .min_by(|a, b| (a[0] - x).abs().total_cmp(&(b[0] - x).abs()))
        .expect("a path");
    nearest[1].signum()
}

/// A wall across the way, 16 m long, 10 m ahead: the ways round its two
/// ends cost about the same. Made a little longer at the end the path
/// goes round (1.2 m, a few per cent more), the plan alone goes round the
/// other end, and again the first as the next image shows a little more
/// of the other: a vehicle standing before it, turning to each way in
/// turn, goes neither (`ditch_across` at 5.3 m/s: turned on the spot until
/// stuck). Near where the vehicle last stood (as before backing up), the
/// route holds to the path it follows while it costs at most
/// `hold_fraction` more than the plan's; a way made much costlier (a wall along that side too, the
/// way round it through ground never seen) is left. Driving on, never
/// held up, it follows the plan: a better line is taken at once (held to
/// it, a vehicle wandered up `hillside_steep` round cells that came and
/// went, 477 m for 255).
#[test]
fn standing_the_route_holds_to_the_way_it_chose_until_the_other_is_clearly_better() {
    // Every cell certain, however far it was seen from: this is about
    // holding a way, not about doubtful obstacles.
    const CERTAIN: &str = "confirm_within_m = 100.0";
    let wall = |right: f64, left: f64| -> Vec<(f64, f64)> {
        let n = ((left - right) / 0.4).round() as i32;
        (0..=n)
            .map(|k| (10.0, right + 0.4 * f64::from(k)))
            .collect()
    };
    let goal = [60.0, 0.0];
    let standing = Some(0.0);
    let forward = Some(1.0);
    let first = snapshot_seeing(&wall(-8.0, 8.0), 20.0);
    let (_, _, overlay) = route_after(&[&first], &[standing], goal, CERTAIN);
    let side = side_at(&planned_path(&overlay), 10.0);
    // The end the path goes round, 1.2 m farther out.
    let longer = if side > 0.0 {
        wall(-8.0, 9.2)
    } else {
        wall(-9.2, 8.0)
    };
    let longer = snapshot_seeing(&longer, 20.0);
    let both = [&first, &longer];
    let (_, counters, overlay) = route_after(&both, &[standing, standing], goal, CERTAIN);
    assert_eq!(
        side_at(&planned_path(&overlay), 10.0),
        side,
        "held to its side: {:?}",
        planned_path(&overlay)
    );
    assert!(counter(&counters, "held_cycles") >= 1, "{counters:?}");
    assert_eq!(counter(&counters, "path_switches"), 0, "{counters:?}");
    for (speed, table) in [
        (0.0, "hold_fraction = 0.0\nconfirm_within_m = 100.0"),
        (2.0, CERTAIN),
    ] {
        let (_, counters, overlay) = route_after_at(&both, &[forward, forward], goal, table, speed);
        assert_eq!(
            side_at(&planned_path(&overlay), 10.0),
            -side,
            "at {speed} m/s {table}: the plan alone flips to the other end: {:?}",
            planned_path(&overlay)
        );
        assert_eq!(counter(&counters, "held_cycles"), 0, "{counters:?}");
    }
    // That side walled along too, from the wall to the window's far edge:
    // the way round it lies through 10 m of ground never seen.
    let mut walled: Vec<(f64, f64)> = if side > 0.0 {
        wall(-8.0, 10.0)
    } else {
        wall(-10.0, 8.0)
    };
    walled.extend((0..=25).map(|k| (10.0 + 0.4 * f64::from(k), 9.6 * side)));
    let walled = snapshot_seeing(&walled, 20.0);
    let (_, counters, overlay) = route_after(
        &[&first, &longer, &walled],
        &[standing, standing, standing],
        goal,
        CERTAIN,
    );
    assert_eq!(
        side_at(&planned_path(&overlay), 10.0),
        -side,
        "left for the other end: {:?}",
        planned_path(&overlay)
    );
    assert_eq!(counter(&counters, "path_switches"), 1, "{counters:?}");
}

/// A vehicle held short of ground no image shows (the shadow beyond a
/// ledge, 3 m deep, 40 m long, 3 m beyond its front) backs up. Counted
/// passable at `unseen_cost`, the shadow kept the route's path across it,
/// and the vehicle came back to the same edge after every backing-up
/// (`tests/worlds/ledge.toml`: stuck). From the first backward command the
/// unseen ground ahead, and the shadow along the edge within sight, are
/// shut: the route turns away to go round. Once an image sees that ground
/// it is open again; with `shut_unseen_m = 0` nothing is shut.
#[test]
fn the_route_shuts_unseen_ground_the_vehicle_backed_away_from_until_it_is_seen() {
    let shadow = snapshot_with_shadow(FRONT + 3.0, FRONT + 6.0);
    let seen = snapshot_with_shadow(FRONT + 3.0, FRONT + 3.0);
    let goal = [60.0, 0.0];
    let forward = Some(1.0);
    let back = Some(-1.0);
    let (before, _, _) = route_after(&[&shadow], &[forward], goal, "");
    assert!(
        before.abs_diff(19) <= 2,
        "unseen ground is crossed: about straight, not {before}"
    );
    let (after, counters, overlay) = route_after(&[&shadow, &shadow], &[forward, back], goal, "");
    assert!(
        after.abs_diff(19) >= 6,
        "backed away from it, the route goes round: {after}"
    );
    // Shut within sight: the strip, 3 cells deep, where it lies 2 m inside
    // the window (±10 m to the sides): about 3 × 17 cells.
    let shut = counter(&counters, "shut_cells");
    assert!((30..=80).contains(&shut), "{shut} cells shut");
    // The overlay shows the shut cells, in the strip, and the path round
    // them, from the vehicle to the waypoint, with the point steered for
    // on it.
    let shut_cells = overlay
        .cells
        .iter()
        .find(|c| c.label.contains("shut"))
        .expect("shut cells drawn");
    assert_eq!(shut_cells.centres.len() as u64, shut);
    assert!(
        shut_cells
            .centres
            .iter()
            .all(|&[x, _]| (FRONT + 2.5..=FRONT + 6.5).contains(&x)),
        "{:?}",
        shut_cells.centres
    );
    let path = &planned_path(&overlay);
    let (first, last) = (path[0], path[path.len() - 1]);
    assert!(
        first[0].hypot(first[1]) < 1.0,
        "from the vehicle: {first:?}"
    );
    // Drawn for 60 m: most of the way to the waypoint, 60 m off.
    assert!(
        (last[0] - goal[0]).hypot(last[1] - goal[1]) < 12.0,
        "towards the waypoint: {last:?}"
    );
    let in_strip = |&[x, y]: &[f64; 2]| (FRONT + 3.0..=FRONT + 6.0).contains(&x) && y.abs() < 8.0;
    assert!(!path.iter().any(in_strip), "round the strip: {path:?}");
    let aim = overlay.points[0].at;
    assert!(
        path.iter()
            .any(|p| (p[0] - aim[0]).hypot(p[1] - aim[1]) < 0.5),
        "steering for a point on the path: {aim:?}"
    );
    // The plan's (the path followed keeps to the way round while it costs
    // at most `hold_fraction` more: 22 % here).
    let (reseen, _, _) = route_after(
        &[&shadow, &shadow, &seen],
        &[forward, back, forward],
        goal,
        "hold_fraction = 0.0",
    );
    assert!(
        reseen.abs_diff(19) <= 2,
        "seen, the ground is open again: about straight, not {reseen}"
    );
    let (never, counters, _) = route_after(
        &[&shadow, &shadow],
        &[forward, back],
        goal,
        "shut_unseen_m = 0.0",
    );
    assert!(
        never.abs_diff(19) <= 2,
        "nothing shut: straight, not {never}"
    );
    assert_eq!(counter(&counters, "shut_cells"), 0);
}

/// A shadow 2.6 m deep across the way with a gap 1.3 m wide seen through
/// it, straight ahead: too narrow for the vehicle, so obstacle avoidance
/// holds it short of the unseen ground beside the gap. The route's 1 m
/// cells astride the gap are seen at their centres, not wholly; before,
/// they counted as free, backing up shut the shadow round them and the
/// path kept going through the gap (`tests/worlds/ledge.toml` with the
/// ERIM: back to the same gap five times, stuck). They are shut with the
/// shadow, and stay shut while part of them is unseen; a gap the vehicle
/// fits through stays open.
#[test]
fn a_gap_seen_only_in_part_is_shut_with_the_shadow_round_it() {
    let (near, far) = (FRONT + 3.2, FRONT + 5.8);
    let gap = 0.65;
    let shadow = snapshot_after(vec![
        (vec![], [-20.0, near, 20.0]),
        (vec![], [far, 20.0, 20.0]),
        (vec![], [near, far, gap]),
    ]);
    let goal = [60.0, 0.0];
    let (forward, back) = (Some(1.0), Some(-1.0));
    let (before, _, overlay) = route_after(&[&shadow], &[forward], goal, "");
    assert!(
        before.abs_diff(19) <= 2,
        "through the gap before backing up: about straight, not {before}"
    );
    let path = planned_path;
    let in_shadow = |&[x, y]: &[f64; 2]| (near..=far).contains(&x) && y.abs() < 8.0;
    assert!(path(&overlay).iter().any(in_shadow), "the gap is taken");
    let (after, counters, overlay) = route_after(
        &[&shadow, &shadow, &shadow],
        &[forward, back, back],
        goal,
        "",
    );
    assert!(
        !path(&overlay).iter().any(in_shadow),
        "round the shadow, gap and all: {:?}",
        path(&overlay)
    );
    assert!(
        after.abs_diff(19) >= 6,
        "backed away from it, the route goes round: {after}"
    );
    let shut = overlay
        .cells
        .iter()
        .find(|c| c.label.contains("shut"))
        .expect("shut cells drawn");
    assert!(
        shut.centres
            .iter()
            .any(|&[x, y]| (near..=far).contains(&x) && y.abs() < 1.0),
        "the cells astride the gap are shut: {:?}",
        shut.centres
    );
    assert_eq!(shut.centres.len() as u64, counter(&counters, "shut_cells"));
    // A gap 5.3 m wide, its edges seen in part as well: only what lies
    // between shut cells is shut, and the way through stays open.
    let wide = snapshot_after(vec![
        (vec![], [-20.0, near, 20.0]),
        (vec![], [far, 20.0, 20.0]),
        (vec![], [near, far, 2.65]),
    ]);
    let (_, _, overlay) = route_after(&[&wide, &wide, &wide], &[forward, back, back], goal, "");
    assert!(
        path(&overlay).iter().any(in_shadow),
        "through the wide gap: {:?}",
        path(&overlay)
    );
}

/// A strip one route cell wide seen right through the shut shadow (an
/// image saw through a low spot of the edge): no way for a vehicle wider
/// than a cell, which obstacle avoidance holds short of the unseen ground
/// on either side. Before, the path went through it after every
/// backing-up (a ledge 18 m off the way, the ERIM with `sim.seed` 2:
/// back to the same strip ten times, stuck).
#[test]
fn a_strip_one_cell_wide_seen_through_the_shut_shadow_is_no_way() {
    let (near, far) = (FRONT + 3.2, FRONT + 5.8);
    let shadow = snapshot_after_rectangles(vec![
        (vec![], [-20.0, near, -20.0, 20.0]),
        (vec![], [far, 20.0, -20.0, 20.0]),
        // Every patch of the cells from y = 0 to 1 m and none of the ones
        // beside them (0.4 m patches).
        (vec![], [near, far, -0.05, 1.05]),
    ]);
    let goal = [60.0, 0.0];
    let (forward, back) = (Some(1.0), Some(-1.0));
    let (_, _, overlay) = route_after(
        &[&shadow, &shadow, &shadow],
        &[forward, back, back],
        goal,
        "",
    );
    let path = &planned_path(&overlay);
    let in_shadow = |&[x, y]: &[f64; 2]| (near..=far).contains(&x) && y.abs() < 8.0;
    assert!(!path.iter().any(in_shadow), "round the shadow: {path:?}");
    let shut = &overlay
        .cells
        .iter()
        .find(|c| c.label.contains("shut"))
        .expect("shut cells drawn")
        .centres;
    let strip = |&&[x, y]: &&[f64; 2]| (near..=far).contains(&x) && (0.0..1.0).contains(&y);
    assert!(
        !shut.iter().any(|c| strip(&c)),
        "the strip itself is seen, not shut: {shut:?}"
    );
}

/// Shut ground that leaves no way to the waypoint (here the waypoint lies
/// in it) is opened again: the way may lie through it.
#[test]
fn shut_ground_that_leaves_no_way_is_opened_again() {
    let shadow = snapshot_with_shadow(FRONT + 3.0, FRONT + 6.0);
    let goal = [FRONT + 4.5, 0.0];
    let (best, counters, _) = route_after(&[&shadow, &shadow], &[Some(1.0), Some(-1.0)], goal, "");
    assert!(counter(&counters, "shut_cells") > 0);
    assert_eq!(
        counter(&counters, "reopened_cells"),
        counter(&counters, "shut_cells")
    );
    assert!(
        best.abs_diff(19) <= 2,
        "straight for the waypoint, not {best}"
    );
}

/// The vehicle standing 8 cm right of the patch lattice, a cell in the
/// patch beside its right flank just behind the rear axle: the local map
/// keeps it (its centre, 1.32 m right of the centre line, lies outside the
/// body grown by half a patch, 1.30 m), but rasterised to obstacle
/// avoidance's 0.2 m grid it lands inside the footprint, where every arc's
/// sweep met it at once: all 39 arcs were vetoed, though driving straight
/// on or turning right takes the flank along or away from it
/// (`short_ditch_09` at `--speed 10`, a ditch's edge beside the rear
/// overhang: stuck for 90 s). Turning left swings the tail right, over it.
#[test]
fn a_cell_touching_the_flank_where_the_vehicle_stands_stops_only_the_arcs_that_drive_over_it() {
    let pose = Pose::at_rest(0, planar_isometry(0.0, -0.08, 0.0));
    let snapshot = snapshot_at(
        &pose,
        vec![(vec![rock(-0.2, -1.4)], [-40.0, 40.0, -40.0, 40.0])],
    );
    let kept: Vec<(f32, f32)> = snapshot.patches.iter().map(|p| (p.x, p.y)).collect();
    assert_eq!(kept.len(), 1, "{kept:?}");
    assert!((kept[0].1 + 1.32).abs() < 1e-3, "{kept:?}");
    let votes = avoidance_votes_at(&snapshot, ObstacleAvoidanceConfig::default(), &pose);
    let vetoed: Vec<usize> = (0..39).filter(|&arc| votes.is_vetoed(arc)).collect();
    assert_eq!(vetoed, (20..39).collect::<Vec<_>>(), "left arcs only");
    assert!(
        votes.values()[..20].iter().all(|&v| v > 0.0),
        "{:?}",
        votes.values()
    );
}

/// 004 checks the robot's own shape. On the hardest left arc (radius 8 m,
/// centre 8 m left of the rear axle) a body sweeps the ring between its
/// nearest and farthest points from the centre: a body whose front right
/// corner is cut away (an L) or rounded (a circle) sweeps a narrower ring
/// than the rectangle that bounds it, and passes between a rock inside
/// the ring and one outside it that the rectangle strikes. A rock inside
/// the shape's own ring stops the shape too.
#[test]
fn a_circle_and_an_l_pass_between_rocks_their_bounding_rectangle_strikes() {
    use arcnav_vehicle::model::FootprintShape;
    let hardest_left = 38;
    // Rocks on the centres of map patches (0.2 m), 30-50° round the turn,
    // by their distance from the turning centre (0, 8): 6.24 m, inside
    // every body's ring; 9.93 m, outside the L's and the circle's, inside
    // their rectangles'.
    let (inner, outer) = ((4.1, 3.3), (6.5, 0.5));
    let votes_for = |vehicle: &VehicleConfig, rocks: &[(f64, f64)]| {
        let cells: Vec<_> = rocks.iter().map(|&(x, y)| rock(x, y)).collect();
        let pose = Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0));
        let mut map = LocalMap::new(
            &LocalMapConfig {
                assume_seen_m: 0.0,
                ..LocalMapConfig::default()
            },
            vehicle,
        );
        map.update(&pose);
        let report = ObstacleReport {
            sensor: "test".into(),
            cell_size_m: 0.2,
            cells,
            fov: FovPolygon::new(vec![
                Point2::new(-40.0, 40.0),
                Point2::new(40.0, 40.0),
                Point2::new(40.0, -40.0),
                Point2::new(-40.0, -40.0),
            ]),
            ..ObstacleReport::default()
        };
        map.insert(&report).unwrap();
        let arcs = arcs();
        let mut behaviour =
            ObstacleAvoidance::new(ObstacleAvoidanceConfig::default(), &setup(&arcs, vehicle));
        let mission = Mission::default();
        let snapshot = map.snapshot();
        let ctx = VoteContext::new(0, &pose, &snapshot, &mission, &arcs);
        let mut votes = Votes::new(arcs.len());
        behaviour.vote(&ctx, &mut votes);
        votes
    };
    // The bounding rectangle of a shape, as a vehicle.
    let bounding = |shaped: &VehicleConfig| {
        let f = shaped.footprint();
        VehicleConfig {
            footprint: FootprintShape::Rectangle,
            radius_m: None,
            centre_m: None,
            vertices_m: None,
            length_m: f.x_max - f.x_min,
            width_m: 2.0 * f.half_width,
            rear_overhang_m: -f.x_min,
            ..shaped.clone()
        }
    };
    // The HMMWV's rectangle with its front right quarter cut away from
    // 2 m ahead of the rear axle: its right side sweeps out to
    // hypot(2, 9.1) = 9.32 m from the centre, the rectangle's to
    // hypot(4, 9.1) = 9.94 m (each grown by half a patch).
    let ell = VehicleConfig {
        footprint: FootprintShape::Polygon,
        vertices_m: Some(vec![
            [-0.6, -1.1],
            [2.0, -1.1],
            [2.0, 0.0],
            [4.0, 0.0],
            [4.0, 1.1],
            [-0.6, 1.1],
        ]),
        ..VehicleConfig::default()
    };
    // A round body 3 m across just ahead of the rear axle: out to
    // hypot(1.5, 8) + 1.5 = 9.64 m; its bounding square to
    // hypot(3, 9.5) = 9.96 m.
    let round = VehicleConfig {
        footprint: FootprintShape::Circle,
        radius_m: Some(1.5),
        centre_m: Some([1.5, 0.0]),
        wheelbase_m: 2.0,
        ..VehicleConfig::default()
    };
    // Inside each shape's own ring: 9.08 m from the centre (the L), 9.36 m
    // (the circle).
    for (name, shaped, inside) in [
        ("the L", ell, (5.9, 1.1)),
        ("the circle", round, (6.1, 0.9)),
    ] {
        let between = [inner, outer];
        shaped.validate().unwrap();
        let shape = votes_for(&shaped, &between);
        let rectangle = votes_for(&bounding(&shaped), &between);
        assert!(
            !shape.is_vetoed(hardest_left) && shape.vote(hardest_left).unwrap() > -0.5,
            "{name} passes between the rocks: {:?}",
            shape.vote(hardest_left)
        );
        assert!(
            rectangle.is_vetoed(hardest_left),
            "its bounding rectangle strikes the outer rock: {:?}",
            rectangle.vote(hardest_left)
        );
        let struck = votes_for(&shaped, &[inner, inside]);
        assert!(
            struck.is_vetoed(hardest_left),
            "{name} strikes a rock inside its own ring: {:?}",
            struck.vote(hardest_left)
        );
    }
}

/// Issue 68, skid-steer: obstacle avoidance sweeps the body through each
/// turn in place about the middle of the wheelbase (the arcs of curvature
/// ±∞ at the ends of the set), grown by half a 0.4 m patch and the
/// manoeuvres' 0.3 m: from the turn centre ±1.26 m along, ±1.19 m across.
/// A rock whose patch centre lies 1.43 m from the centre, 24.8° right,
/// just off that box's front edge (which meets the patch's circle at
/// ±28.4°): turning left brings it in after 3.6°, a veto; turning right,
/// after 53.2°, the clearance given (in radians). Open ground all round:
/// both clear for half a turn, voted +1. Neither is ever backed along.
#[test]
fn a_turn_in_place_is_vetoed_towards_a_rock_its_corner_swings_into() {
    let vehicle = VehicleConfig::warthog();
    let arcs = ArcSet::new(&ArcSetConfig {
        turn_in_place: true,
        ..ArcSetConfig::default()
    })
    .unwrap();
    let (right, left) = (0, arcs.len() - 1);
    let votes_with = |cells: &[(f64, f64)]| {
        let pose = Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0));
        let cells = cells.iter().map(|&(x, y)| rock(x, y)).collect();
        let map =
            snapshot_of_vehicle_at(&vehicle, &pose, vec![(cells, [-40.0, 40.0, -40.0, 40.0])]);
        let mut behaviour =
            ObstacleAvoidance::new(ObstacleAvoidanceConfig::default(), &setup(&arcs, &vehicle));
        let mission = Mission::default();
        let ctx = VoteContext::new(0, &pose, &map, &mission, &arcs);
        let mut votes = Votes::new(arcs.len());
        behaviour.vote(&ctx, &mut votes);
        votes
    };
    let open = votes_with(&[]);
    for arc in [right, left] {
        assert!(!open.is_vetoed(arc), "{arc}");
        assert_eq!(open.vote(arc), Some(1.0));
        assert!((open.forward_clearance(arc).unwrap() - std::f64::consts::PI).abs() < 1e-6);
        assert_eq!(open.reverse_clearance(arc), Some(0.0));
    }
    // The turn centre is 0.5 m ahead of the origin; the rock's patch
    // centre (1.8, -0.6), (1.3, -0.6) from it.
    let votes = votes_with(&[(1.7, -0.5)]);
    assert!(votes.is_vetoed(left), "{:?}", votes.forward_clearance(left));
    let clear = votes.forward_clearance(right).unwrap().to_degrees();
    assert!(
        !votes.is_vetoed(right) && (clear - 53.2).abs() < 0.2,
        "{clear}°"
    );
}
