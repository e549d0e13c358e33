//! Obstacle avoidance's vote (020 item 2): the 39 arcs judged on a local
//! map holding 600 cells scattered ahead (trunks and rocks of a forest)
//! and unseen ground beyond 30 m and behind, one core. Judged along the
//! arcs (`[arcs] driven_paths = false`; the default `"auto"` does so up to
//! 3 m/s of cruise) and along the paths the vehicle drives onto them
//! (`true`; `"auto"` above 3 m/s) with the vehicle straight at 0,
//! 2.5, 5 and 10 m/s, turning right at 5 m/s. Prints the median and the
//! 99th percentile over 300 votes. No target: the cost of the driven paths
//! shown against the arcs'.
//! Run with `cargo bench -p arcnav-behaviours --bench avoidance`.

use std::time::Instant;

use arcnav_arbiter::Votes;
use arcnav_behaviours::{
    Behaviour, Mission, ObstacleAvoidance, ObstacleAvoidanceConfig, Setup, VoteContext,
};
use arcnav_localmap::{LocalMap, LocalMapConfig, MapSnapshot};
use arcnav_perception::{FovPolygon, ObstacleCell, ObstacleReport, Reasons};
use arcnav_vehicle::frames::planar_isometry;
use arcnav_vehicle::{ArcSet, ArcSetConfig, Pose, SteeringCommand, VehicleConfig};
use nalgebra::Point2;

fn forest() -> MapSnapshot {
    let vehicle = VehicleConfig::default();
    let mut map = LocalMap::new(&LocalMapConfig::default(), &vehicle);
    map.update(&Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0)));
    // A fixed scatter: 600 cells from 3 m to 30 m ahead, ±15 m aside.
    let mut state = 12_345u64;
    let mut unit = || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let cells = (0..600)
        .map(|_| ObstacleCell {
            x: 3.0 + 27.0 * unit(),
            y: -15.0 + 30.0 * unit(),
            z_min: 0.0,
            z_max: 0.8,
            reasons: Reasons::HEIGHT_VARIATION,
            region: 0,
            cost: 1.0,
        })
        .collect();
    let report = ObstacleReport {
        utime: 0,
        sensor: "bench".into(),
        cell_size_m: 0.2,
        cells,
        fov: FovPolygon::new(vec![
            Point2::new(0.0, -30.0),
            Point2::new(30.0, -30.0),
            Point2::new(30.0, 30.0),
            Point2::new(0.0, 30.0),
        ]),
        ..ObstacleReport::default()
    };
    map.insert(&report).expect("the bench's report is valid");
    (*map.snapshot()).clone()
}

fn main() {
    let vehicle = VehicleConfig::default();
    let localmap = LocalMapConfig::default();
    let map = forest();
    let mission = Mission::default();
    println!(
        "{:<12} {:<22} {:>10} {:>10}",
        "judged", "vehicle", "median ms", "p99 ms"
    );
    for driven_paths in [false, true] {
        let arcs = ArcSet::new(&ArcSetConfig {
            driven_paths: driven_paths.into(),
            ..Default::default()
        })
        .expect("default arcs");
        let setup = Setup {
            arcs: &arcs,
            vehicle: &vehicle,
            localmap: &localmap,
            statics: None,
            cruise_mps: 2.5,
            area: None,
            unreachable: Default::default(),
        };
        let mut behaviour = ObstacleAvoidance::new(ObstacleAvoidanceConfig::default(), &setup);
        for (label, speed, curvature) in [
            ("standing", 0.0, 0.0),
            ("straight 2.5 m/s", 2.5, 0.0),
            ("straight 5 m/s", 5.0, 0.0),
            ("straight 10 m/s", 10.0, 0.0),
            ("turning right 5 m/s", 5.0, -0.1),
        ] {
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
            let mut ctx = VoteContext::new(0, &pose, &map, &mission, &arcs);
            ctx.last_command = Some(&last);
            let mut votes = Votes::new(arcs.len());
            let mut times = Vec::new();
            for n in 0..330 {
                votes.clear();
                let start = Instant::now();
                behaviour.vote(&ctx, &mut votes);
                if n >= 30 {
                    times.push(start.elapsed().as_secs_f64() * 1e3);
                }
            }
            times.sort_by(f64::total_cmp);
            println!(
                "{:<12} {:<22} {:>10.3} {:>10.3}",
                if driven_paths { "driven paths" } else { "arcs" },
                label,
                times[times.len() / 2],
                times[times.len() * 99 / 100],
            );
        }
    }
}
