//! The route behaviour over a 1 km mission: a vehicle drives 1 km (four
//! legs of 250 m) at 2.5 m/s through a field of boulders, with the decision
//! rate of the pipeline (10 Hz: 4 000 cycles) and a local map fed an image
//! of the boulders around it twice a second. Times each cycle's vote
//! (memory update from the map, incremental D* Lite re-plan, votes) and
//! prints the mean, the 99th percentile and the worst, with the memory the
//! route holds. Targets (017): ≤ 1 ms per cycle amortised; ≤ 16 MB.
//! Run with `cargo bench -p arcnav-behaviours --bench route`.

use std::time::Instant;

use arcnav_arbiter::Votes;
use arcnav_behaviours::{Behaviour, Mission, Route, RouteConfig, Setup, VoteContext, Waypoint};
use arcnav_localmap::{LocalMap, LocalMapConfig};
use arcnav_perception::{FovPolygon, ObstacleCell, ObstacleReport, Reasons};
use arcnav_vehicle::frames::planar_isometry;
use arcnav_vehicle::{ArcSet, ArcSetConfig, Pose, VehicleConfig};
use nalgebra::Point2;

/// A reproducible boulder field: centres on a jittered 12 m lattice.
fn boulders() -> Vec<(f64, f64)> {
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut out = Vec::new();
    for i in -30..=60 {
        for j in -30..=60 {
            out.push((
                i as f64 * 12.0 + 10.0 * next(),
                j as f64 * 12.0 + 10.0 * next(),
            ));
        }
    }
    out
}

fn main() {
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
    let mut route = Route::new(RouteConfig::default(), &setup);
    let mut map = LocalMap::new(&localmap, &vehicle);
    let corners = [
        (0.0, 0.0),
        (250.0, 0.0),
        (250.0, 250.0),
        (0.0, 250.0),
        (0.0, 0.0),
    ];
    let mission = Mission {
        version: 1,
        waypoints: corners[1..]
            .iter()
            .map(|&(x, y)| Waypoint {
                x,
                y,
                radius_m: None,
            })
            .collect(),
    };
    let field = boulders();
    let mut votes = Votes::new(arcs.len());
    let mut times = Vec::new();
    let (step, period_us) = (0.25, 100_000i64);
    let mut t = 0i64;
    for leg in corners.windows(2) {
        let ((x0, y0), (x1, y1)) = (leg[0], leg[1]);
        let length = f64::hypot(x1 - x0, y1 - y0);
        let yaw = (y1 - y0).atan2(x1 - x0);
        for k in 0..(length / step) as usize {
            let s = k as f64 * step;
            let (x, y) = (x0 + s * yaw.cos(), y0 + s * yaw.sin());
            t += period_us;
            let pose = Pose::at_rest(t, planar_isometry(x, y, yaw));
            map.update(&pose);
            if k % 5 == 0 {
                // An image: each boulder near the vehicle as a 3 x 3 of cells.
                let cells: Vec<ObstacleCell> = field
                    .iter()
                    .filter(|(bx, by)| (bx - x).hypot(by - y) < 30.0)
                    .flat_map(|&(bx, by)| {
                        (0..9).map(move |c| ObstacleCell {
                            x: bx + (c % 3) as f64 * 0.2,
                            y: by + (c / 3) as f64 * 0.2,
                            z_min: 0.0,
                            z_max: 0.8,
                            reasons: Reasons::HEIGHT_VARIATION,
                            region: 0,
                            cost: 1.0,
                        })
                    })
                    .collect();
                let fov = FovPolygon::new(
                    [(-6.0, -10.0), (20.0, -10.0), (20.0, 10.0), (-6.0, 10.0)]
                        .iter()
                        .map(|&(u, v)| {
                            Point2::new(
                                x + u * yaw.cos() - v * yaw.sin(),
                                y + u * yaw.sin() + v * yaw.cos(),
                            )
                        })
                        .collect(),
                );
                let report = ObstacleReport {
                    utime: t,
                    sensor: "bench".into(),
                    cell_size_m: 0.2,
                    cells,
                    regions: vec![],
                    fov,
                    shadows: Default::default(),
                    ..ObstacleReport::default()
                };
                map.insert(&report).expect("a valid report");
            }
            let snapshot = map.snapshot();
            let ctx = VoteContext::new(t, &pose, &snapshot, &mission, &arcs);
            votes.clear();
            let started = Instant::now();
            route.vote(&ctx, &mut votes);
            times.push(started.elapsed().as_secs_f64() * 1e3);
        }
    }
    let cycles = times.len();
    let mean = times.iter().sum::<f64>() / cycles as f64;
    times.sort_by(f64::total_cmp);
    let p99 = times[cycles * 99 / 100];
    let worst = times[cycles - 1];
    let stats = route.stats();
    println!("route over a 1 km mission: {cycles} cycles (10 Hz at 2.5 m/s)");
    println!(
        "  time per cycle   mean {mean:.3} ms  p99 {p99:.3} ms  worst {worst:.3} ms   (target: mean <= 1 ms)"
    );
    println!(
        "  memory           {:.2} MB for a {} m square of {} m cells   (target: <= 16 MB)",
        route.memory_bytes() as f64 / 1e6,
        RouteConfig::default().size_m,
        RouteConfig::default().cell_m
    );
    println!(
        "  planner          {} plans from scratch, {} incremental re-plans, {} expansions, {} re-centres, {} cycles without a path",
        stats.planner.plans,
        stats.planner.replans,
        stats.planner.expansions,
        stats.recentres,
        stats.no_path_cycles
    );
}
