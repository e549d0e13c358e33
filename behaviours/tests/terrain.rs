//! Attitude, chassis clearance and roughness predicted along arcs from the
//! elevation layer (004 §IV), and what obstacle avoidance does with them.

use arcnav_arbiter::Votes;
use arcnav_behaviours::{
    Behaviour, Judgement, ObstacleAvoidance, ObstacleAvoidanceConfig, Setup, TerrainCheck,
    TerrainConfig, VoteContext,
};
use arcnav_localmap::{ElevationGrid, LocalMapConfig, MapSnapshot, SeenGround};
use arcnav_vehicle::frames::planar_isometry;
use arcnav_vehicle::{ArcSet, ArcSetConfig, Pose, VehicleConfig};

const CELL: f64 = 0.2;

/// An elevation square of 60 m around the origin, measured everywhere as
/// `height(x, y)` at each cell's centre with a 1 cm standard deviation.
fn grid(height: impl Fn(f64, f64) -> f64) -> ElevationGrid {
    let side = 300u32;
    let origin = (-150i64, -150i64);
    let mut cells = Vec::with_capacity((side * side) as usize);
    for j in 0..i64::from(side) {
        for i in 0..i64::from(side) {
            let (x, y) = (
                (origin.0 + i) as f64 * CELL + CELL / 2.0,
                (origin.1 + j) as f64 * CELL + CELL / 2.0,
            );
            cells.push([height(x, y) as f32, 1e-4]);
        }
    }
    ElevationGrid {
        cell_size_m: CELL,
        origin,
        side,
        cells,
    }
}

fn check() -> TerrainCheck {
    TerrainCheck::new(
        &TerrainConfig::default(),
        &VehicleConfig::default(),
        &[0.0],
        18.0,
    )
}

/// The stance of the vehicle with its rear axle's middle at (x, y), heading `yaw`.
fn stance_at(grid: &ElevationGrid, x: f64, y: f64, yaw: f64) -> arcnav_behaviours::Stance {
    check()
        .stance(grid, [x, y, yaw.cos(), yaw.sin()])
        .expect("every wheel on measured ground")
}

#[test]
fn on_a_twenty_degree_side_slope_the_predicted_roll_is_twenty_degrees() {
    let tan = 20f64.to_radians().tan();
    let slope = grid(|_, y| tan * y);
    for yaw in [0.0f64, 0.3, -0.2, std::f64::consts::PI] {
        // Heading along the contour lines of a slope that rises along +y
        // (rotated: the slope always rises across the vehicle).
        let rotated = grid(|x, y| tan * (-yaw.sin() * x + yaw.cos() * y));
        let stance = stance_at(&rotated, 1.0, -2.0, yaw);
        assert!(
            (stance.roll.to_degrees() - 20.0).abs() < 1.0,
            "heading {yaw}: roll {:.2}°",
            stance.roll.to_degrees()
        );
        assert!(stance.pitch.to_degrees() < 1.0, "{stance:?}");
        assert!(stance.twist < 0.05 && stance.belly < 0.2, "{stance:?}");
    }
    // Heading up the same slope, it is pitch.
    let stance = stance_at(&slope, 0.0, 0.0, std::f64::consts::FRAC_PI_2);
    assert!((stance.pitch.to_degrees() - 20.0).abs() < 1.0, "{stance:?}");
    assert!(stance.roll.to_degrees() < 1.0, "{stance:?}");
    assert!(matches!(check().judge(&stance), Judgement::Passable { severity } if severity > 0.0));
}

#[test]
fn a_thirty_centimetre_rock_under_one_wheel_rolls_the_vehicle_by_the_track() {
    let vehicle = VehicleConfig::default();
    // A rock 0.3 m tall, 0.3 m across, under the front left wheel
    // (x = wheelbase, y = track / 2) of a vehicle at the origin heading +x.
    let (wx, wy) = (vehicle.wheelbase_m, vehicle.track_m / 2.0);
    let rock = grid(|x, y| {
        if (x - wx).abs() < 0.15 && (y - wy).abs() < 0.15 {
            0.3
        } else {
            0.0
        }
    });
    let stance = stance_at(&rock, 0.0, 0.0, 0.0);
    let expected = (0.3 / vehicle.track_m).atan().to_degrees();
    assert!(
        (stance.roll.to_degrees() - expected).abs() < 1.0,
        "roll {:.2}°, expected {expected:.2}°",
        stance.roll.to_degrees()
    );
    let pitch = (0.3 / vehicle.wheelbase_m).atan().to_degrees();
    assert!(
        (stance.pitch.to_degrees() - pitch).abs() < 1.0,
        "{stance:?}"
    );
    assert!((stance.twist - 0.3).abs() < 0.01, "{stance:?}");
    // The same rock between the wheels, under the chassis: 0.3 m is below
    // the 0.4 m clearance, passable but costly (004 eq. 6: 1 - V_trav = 0.3 / 0.41).
    let under = grid(|x, y| {
        if (x - 1.65).abs() < 0.3 && y.abs() < 0.3 {
            0.3
        } else {
            0.0
        }
    });
    let stance = stance_at(&under, 0.0, 0.0, 0.0);
    assert!(stance.roll.to_degrees() < 0.5, "{stance:?}");
    assert!((stance.belly - 0.3 / 0.41).abs() < 0.02, "{stance:?}");
    // 0.5 m under the chassis strikes it.
    let tall = grid(|x, y| {
        if (x - 1.65).abs() < 0.3 && y.abs() < 0.3 {
            0.5
        } else {
            0.0
        }
    });
    let stance = stance_at(&tall, 0.0, 0.0, 0.0);
    assert_eq!(check().judge(&stance), Judgement::Forbidden, "{stance:?}");
}

fn votes_on(elevation: ElevationGrid) -> Votes {
    oa_votes(elevation, Vec::new())
}

/// Obstacle avoidance's votes from the origin heading +x, at rest, on a
/// map that saw everything and holds `patches` and `elevation`.
fn oa_votes(elevation: ElevationGrid, patches: Vec<arcnav_localmap::Patch>) -> Votes {
    let arcs = ArcSet::new(&ArcSetConfig::default()).unwrap();
    let vehicle = VehicleConfig::default();
    let localmap = LocalMapConfig::default();
    let setup = Setup {
        arcs: &arcs,
        vehicle: &vehicle,
        localmap: &localmap,
        statics: None,
        cruise_mps: 2.5,
        area: None,
        unreachable: Default::default(),
    };
    let mut oa = ObstacleAvoidance::new(ObstacleAvoidanceConfig::default(), &setup);
    let pose = Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0));
    let mut seen = SeenGround::new(-100, -100, 200);
    for j in -100..100 {
        for i in -100..100 {
            seen.insert(i, j);
        }
    }
    let map = MapSnapshot {
        utime: 0,
        world_from_vehicle: pose.world_from_vehicle,
        patch_size_m: 0.4,
        patches,
        seen,
        elevation: std::sync::Arc::new(elevation),
    };
    let mission = Default::default();
    let ctx = VoteContext::new(0, &pose, &map, &mission, &arcs);
    let mut votes = Votes::new(arcs.len());
    oa.vote(&ctx, &mut votes);
    votes
}

#[test]
fn a_thirty_degree_side_slope_forbids_the_arcs_that_cross_it() {
    // Flat ground, and from 8 m to the left on, a slope of 30° rising
    // further left: arcs turning left climb onto it across their path.
    let tan = 30f64.to_radians().tan();
    let votes = votes_on(grid(|_, y| if y > 3.0 { tan * (y - 3.0) } else { 0.0 }));
    let arcs = ArcSet::new(&ArcSetConfig::default()).unwrap();
    let straight = arcs.straight_index();
    assert!(votes.vote(straight).unwrap() > 0.9, "{:?}", votes.values());
    let hardest_left = arcs.len() - 1;
    assert!(
        arcs.curvature(hardest_left).unwrap() > 0.1,
        "the last arc turns left hardest"
    );
    // It climbs past 25° of roll some 8 m along: a collision there, beyond
    // min_distance_m, so a negative vote (002 §6) rather than a veto.
    assert!(
        votes.vote(hardest_left).unwrap() < -0.5,
        "{:?}",
        votes.values()
    );
    // The same slope starting 1.5 m to the left: forbidden outright.
    let near = votes_on(grid(|_, y| if y > 1.5 { tan * (y - 1.5) } else { 0.0 }));
    assert!(near.is_vetoed(hardest_left), "{:?}", near.values());
    // Right turns stay on the flat.
    assert!(
        !votes.is_vetoed(0) && votes.vote(0).unwrap() > 0.5,
        "{:?}",
        votes.values()
    );
    // On a 20° slope everywhere nothing is forbidden, but every arc loses
    // vote and speed: 20° is within caution of the 25° limit.
    let tan = 20f64.to_radians().tan();
    let votes = votes_on(grid(|_, y| tan * y));
    assert!(votes.vetoed().iter().all(|v| !v), "{:?}", votes.vetoed());
    // Severity (20 - (25 - 8)) / 8 = 0.375: the vote 1 - 0.5 · 0.375, the
    // speed 2.5 · (1 - 0.6 · 0.375) m/s.
    let straight_vote = votes.vote(straight).unwrap();
    assert!((straight_vote - 0.8125).abs() < 0.03, "{straight_vote}");
    let speed = votes.arc_speed(straight).unwrap();
    assert!((speed - 1.94).abs() < 0.1, "{speed} m/s on a 20° slope");
    // Flat ground: full vote and cruise.
    let votes = votes_on(grid(|_, _| 0.0));
    assert_eq!(votes.vote(straight), Some(1.0));
    assert!(votes.arc_speed(straight).unwrap() >= 2.5 - 1e-9);
}

/// Graded ground (a patch of cost below 1, e.g. 000's D̃ short of an
/// obstacle) is no collision: the arc crossing it loses penalty × cost of
/// its vote and slows; the same patch at cost 1 is an obstacle.
#[test]
fn graded_ground_lowers_an_arc_and_its_speed_but_does_not_block_it() {
    let straight = ArcSet::new(&ArcSetConfig::default())
        .unwrap()
        .straight_index();
    // A patch 2 m ahead of the front bumper (x = 4 m), on the straight arc.
    let votes_with = |cost: f32| {
        let mut patch = arcnav_localmap::Patch::at(15, 0);
        (patch.x, patch.y, patch.cost) = (6.2, 0.2, cost);
        oa_votes(ElevationGrid::default(), vec![patch])
    };
    let graded = votes_with(0.8);
    assert!(!graded.is_vetoed(straight));
    let vote = graded.vote(straight).unwrap();
    assert!((vote - (1.0 - 0.5 * 0.8)).abs() < 1e-5, "{vote}");
    let speed = graded.arc_speed(straight).unwrap();
    assert!(
        (speed - 2.5 * (1.0 - 0.6 * 0.8)).abs() < 0.05,
        "{speed} m/s over graded ground 2 m ahead"
    );
    // The same patch as an obstacle forbids the straight arc outright.
    assert!(votes_with(1.0).is_vetoed(straight));
}

/// Backing up is judged like driving forwards: the poses backing along each
/// arc (the forward ones mirrored) must keep the vehicle within its
/// attitude limits. A 30° bank rising behind the vehicle (from 1 m behind
/// the rear axle) stops every backward arc on it; flat ground behind leaves
/// each clear to `reverse_reach_m`; the stance the vehicle has now never
/// forbids backing (backing is how it gets off such ground).
#[test]
fn backing_onto_a_bank_steeper_than_the_attitude_limits_is_not_clear() {
    let reach = ObstacleAvoidanceConfig::default().reverse_reach_m;
    let flat = votes_on(grid(|_, _| 0.0));
    let arcs = ArcSet::new(&ArcSetConfig::default()).unwrap();
    for arc in 0..arcs.len() {
        assert_eq!(flat.reverse_clearance(arc), Some(reach), "arc {arc}");
    }
    let tan = 30f64.to_radians().tan();
    let bank = votes_on(grid(|x, _| if x < -1.0 { tan * (-1.0 - x) } else { 0.0 }));
    let straight = arcs.straight_index();
    let clear = bank.reverse_clearance(straight).unwrap();
    // The rear wheels reach the bank's foot after 1 m; with the front
    // wheels on the flat, the pitch tan 30° (s - 1)/3.3 passes 25° at
    // s = 3.7 m: poses every 0.5 m find it at 4 m.
    assert!((3.0..=4.0).contains(&clear), "{clear} m");
    for arc in 0..arcs.len() {
        assert!(bank.reverse_clearance(arc).unwrap() < reach, "arc {arc}");
    }
    // Standing on a 30° side slope (beyond the limits), backing along it
    // is not refused for the stance it has now: only its ground's roll
    // along the way, the same 30°, stops it one step on.
    let side = votes_on(grid(|_, y| tan * y));
    let clear = side.reverse_clearance(straight).unwrap();
    assert!(clear > 0.0, "{clear} m");
    // Forwards, the same stance forbids every arc outright.
    assert!((0..arcs.len()).all(|arc| side.is_vetoed(arc)));
}

/// 020 item 2: the ground is judged along the path the vehicle drives
/// when commanded onto an arc, not along the arc.
#[test]
fn at_speed_the_ground_is_judged_where_the_vehicle_will_drive() {
    use arcnav_vehicle::{Arc, DrivenPath, Steering, SteeringResponse};
    let vehicle = VehicleConfig::default();
    let k = 0.125;
    let steering = Steering {
        speed_mps: 8.0,
        ..Default::default()
    };
    let path = DrivenPath::new(&steering, &SteeringResponse::of(&vehicle), k);
    // A 1 m block 2 m across under the path's rear axle 11 m on, which
    // the arc's body and its margin never touch.
    let on_path = path.pose_at(11.0).position;
    let swept = Arc::new(k).swept(vehicle.footprint().widened(1.5), 18.0);
    assert!(!swept.covers(on_path), "{on_path}");
    let block = grid(|x, y| {
        if (x - on_path.x).abs() < 1.0 && (y - on_path.y).abs() < 1.0 {
            1.0
        } else {
            0.0
        }
    });
    let mut check = TerrainCheck::new(&TerrainConfig::default(), &vehicle, &[k], 18.0);
    let pose = planar_isometry(0.0, 0.0, 0.0);
    let mut verdict = [arcnav_behaviours::ArcTerrain::default()];
    check.judge_arcs(&block, &pose, 6.0, &mut verdict);
    assert_eq!(verdict[0].forbidden, None, "the arc passes inside it");
    check.judge_paths(&block, &pose, 6.0, &[path], &mut verdict);
    let (s, _) = verdict[0].forbidden.expect("the path climbs it");
    assert!((6.0..11.5).contains(&s), "forbidden at {s} m");
    // Taken at once, the same arc is the arc.
    check.judge_paths(&block, &pose, 6.0, &[DrivenPath::arc(k)], &mut verdict);
    assert_eq!(verdict[0].forbidden, None);
}
