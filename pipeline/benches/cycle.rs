//! One full cycle: obstacle avoidance and goal seeking vote, the arbiter
//! decides, over a map of 2 000 cells. Targets: ≤ 20 µs with 39 arcs,
//! ≤ 0.3 ms with 1 000 arcs (1 001 here: the count is odd so that straight is
//! one of the arcs). Run with `cargo bench -p arcnav-pipeline`.
//! The behaviours vote through [`BehaviourSet`], as in every executor.

use arcnav_arbiter::{Arbiter, ArbiterConfig};
use arcnav_behaviours::{Behaviour, Mission, Registry, Setup, Waypoint};
use arcnav_localmap::{LocalMap, LocalMapConfig, MapSnapshot};
use arcnav_perception::{FovPolygon, ObstacleCell, ObstacleReport, Reasons};
use arcnav_pipeline::BehaviourSet;
use arcnav_vehicle::frames::planar_isometry;
use arcnav_vehicle::{ArcSet, ArcSetConfig, Pose, VehicleConfig};
use divan::{Bencher, black_box};

static LOCALMAP: std::sync::LazyLock<arcnav_localmap::LocalMapConfig> =
    std::sync::LazyLock::new(arcnav_localmap::LocalMapConfig::default);

fn main() {
    divan::main();
}

/// 2 000 distinct patches scattered over the window (deterministic).
fn map() -> MapSnapshot {
    let mut local = LocalMap::new(&LocalMapConfig::default(), &VehicleConfig::default());
    local.update(&Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0)));
    let mut cells = Vec::new();
    let mut k: u64 = 1;
    while local.len() < 2_000 {
        cells.clear();
        for _ in 0..64 {
            k = k
                .wrapping_mul(6_364_136_223_846_793_005)
                .wrapping_add(1_442_695_040_888_963_407);
            let x = -5.9 + (k >> 40) as f64 / (1u64 << 24) as f64 * 25.8;
            let y = -9.9 + ((k >> 16) & 0xff_ffff) as f64 / (1u64 << 24) as f64 * 19.8;
            cells.push(ObstacleCell {
                x,
                y,
                z_min: 0.0,
                z_max: 0.5,
                reasons: Reasons::HEIGHT_VARIATION,
                region: 0,
                cost: 1.0,
            });
        }
        let report = ObstacleReport {
            utime: 0,
            sensor: "bench".into(),
            cell_size_m: 0.2,
            cells: cells.clone(),
            regions: vec![],
            fov: FovPolygon::default(),
            shadows: Default::default(),
            ..ObstacleReport::default()
        };
        local.insert(&report).expect("valid cells");
    }
    (*local.snapshot()).clone()
}

fn bench_cycle(bencher: Bencher, arc_count: usize) {
    let arcs = ArcSet::new(&ArcSetConfig {
        count: arc_count,
        min_radius_m: 8.0,
        ..Default::default()
    })
    .expect("valid arcs");
    let vehicle = VehicleConfig::default();
    let setup = Setup {
        arcs: &arcs,
        vehicle: &vehicle,
        localmap: &LOCALMAP,
        statics: None,
        cruise_mps: 2.5,
        area: None,
        unreachable: Default::default(),
    };
    let registry = Registry::builtin();
    let built = std::time::Instant::now();
    let behaviours: Vec<Box<dyn Behaviour>> = ["obstacle_avoidance", "goal_seeking"]
        .iter()
        .map(|name| {
            registry
                .build(name, &toml::Table::new(), &setup)
                .expect("builtin")
        })
        .collect();
    println!(
        "{arc_count} arcs: behaviours built in {:.1} ms (once, at start-up)",
        built.elapsed().as_secs_f64() * 1e3
    );
    let mut arbiter = Arbiter::new(&ArbiterConfig::default(), arcs.clone(), &vehicle);
    let mut behaviours = BehaviourSet::new(behaviours, arcs);
    let map = map();
    let pose = Pose::at_rest(0, planar_isometry(0.0, 0.0, 0.0));
    behaviours.on_waypoints(Mission {
        version: 1,
        waypoints: vec![Waypoint {
            x: 200.0,
            y: 40.0,
            radius_m: None,
        }],
    });
    bencher.bench_local(|| {
        for votes in behaviours.vote(0, &pose, black_box(&map)) {
            let _ = arbiter.on_votes(votes);
        }
        arbiter.decide(0)
    });
}

#[divan::bench]
fn cycle_39_arcs(bencher: Bencher) {
    bench_cycle(bencher, 39);
}

#[divan::bench]
fn cycle_1001_arcs(bencher: Bencher) {
    bench_cycle(bencher, 1001);
}
