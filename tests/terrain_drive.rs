//! Slopes and rough ground at the vehicle's scale (018), driven end to end
//! with the ERIM at 2.5 m/s: the elevation layer, attitude along the arcs,
//! terrain speed and the route's roughness costs together.

use std::sync::Arc;

use arcnav::Config;
use arcnav::mission::{MissionOptions, MissionRun, Outcome, run_mission};
use arcnav_sim::World;
use arcnav_testkit::workspace_root;

fn drive(world: &str) -> MissionRun {
    let path = workspace_root().join("tests/worlds").join(world);
    let run = run(World::load(&path).unwrap());
    let r = &run.report;
    assert_eq!(
        r.outcome,
        Outcome::Completed,
        "{world}: {r:#?}",
        world = r.world
    );
    assert!(r.collisions.is_empty(), "{:#?}", r.collisions);
    run
}

/// The mission on `world` with the default configuration.
fn run(world: World) -> MissionRun {
    let _slot = arcnav_testkit::cpu_slot();
    run_mission(
        &Config::default().resolved().unwrap(),
        Arc::new(world),
        &MissionOptions::default(),
        &mut |_| {},
    )
    .unwrap()
}

/// Mean speed of the track points whose position satisfies `within`.
fn mean_speed(run: &MissionRun, within: impl Fn(f64, f64) -> bool) -> f64 {
    let speeds: Vec<f64> = run
        .track
        .iter()
        .filter(|p| within(p.x, p.y))
        .map(|p| p.speed_mps)
        .collect();
    assert!(speeds.len() > 10, "{} track points there", speeds.len());
    speeds.iter().sum::<f64>() / speeds.len() as f64
}

/// The hillside DEM scaled to side slopes of 14-24.5° along the whole
/// route: completed, and the true roll stayed below the vehicle's limit.
/// Without attitude prediction (per-cell slope as in 002) this world
/// stopped the vehicle for good.
#[test]
fn a_hillside_of_fourteen_to_twenty_four_degrees_is_driven_below_the_roll_limit() {
    let run = drive("hillside_steep.toml");
    let ride = run.report.ride;
    let limit = Config::default().vehicle.max_slope_deg;
    assert!(
        ride.peak_roll_deg < limit && ride.peak_pitch_deg < limit,
        "{ride:?}"
    );
    // It did drive on the slope, not around it: the roll it met is that
    // of a 14-24.5° hillside.
    assert!(ride.peak_roll_deg > 15.0, "{ride:?}");
}

/// 15 cm stones (below the 20 cm the vehicle steps over): slower on the
/// band of rubble across the route than on the smooth ground before it,
/// and along the strip of rubble it keeps to the smooth track beside it.
#[test]
fn rubble_is_crossed_slower_and_a_smooth_track_beside_it_is_taken() {
    let run = drive("rubble.toml");
    // The band: x 24-36 m. The approach: x 5-20 m.
    let on_rubble = mean_speed(&run, |x, y| (25.0..35.0).contains(&x) && y.abs() < 20.0);
    let before = mean_speed(&run, |x, y| (5.0..20.0).contains(&x) && y.abs() < 20.0);
    assert!(
        on_rubble < 0.8 * before,
        "{on_rubble:.2} m/s on the rubble, {before:.2} m/s before it"
    );
    // The strip covers y -6 to 3 from x 62 to 148 m; the track lies north
    // of it. Along its middle the vehicle's centre line keeps off it.
    let along: Vec<f64> = run
        .track
        .iter()
        .filter(|p| (85.0..140.0).contains(&p.x))
        .map(|p| p.y)
        .collect();
    let off = along.iter().filter(|&&y| y > 3.0).count();
    assert!(
        off * 10 >= along.len() * 8,
        "{off} of {} track points beside the strip: {along:?}",
        along.len()
    );
    // The ground truth felt it: the body bounced on the stones.
    assert!(
        run.report.ride.peak_vertical_accel_mps2 > 2.0,
        "{:?}",
        run.report.ride
    );
}

/// 018's "as before": the generated moderate worlds are all completed
/// without a collision with the terrain checks on (and per-cell slope off),
/// two at a time: seeds 0 to N-1, N from `ARCNAV_TEST_WORLDS` (6 when it is
/// not set; 018 drove 20, as `ARCNAV_TEST_WORLDS=20` does, or `arcnav sweep
/// --seeds 0..20`).
#[test]
fn generated_moderate_worlds_are_completed() {
    const VAR: &str = "ARCNAV_TEST_WORLDS";
    let worlds: u64 = std::env::var(VAR).map_or(6, |text| {
        text.trim()
            .parse()
            .unwrap_or_else(|_| panic!("{VAR}={text:?}: give how many worlds to drive"))
    });
    let next = std::sync::atomic::AtomicU64::new(0);
    let failures = std::sync::Mutex::new(Vec::new());
    std::thread::scope(|scope| {
        for _ in 0..2 {
            scope.spawn(|| {
                loop {
                    let seed = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    if seed >= worlds {
                        break;
                    }
                    let spec = arcnav_sim::generate(seed, arcnav_sim::Difficulty::Moderate);
                    let run = run(World::build(spec, "generated world", None).unwrap());
                    let r = &run.report;
                    if r.outcome != Outcome::Completed || !r.collisions.is_empty() {
                        failures.lock().unwrap().push(format!(
                            "seed {seed}: {:?}, collisions {:?}",
                            r.outcome, r.collisions
                        ));
                    }
                }
            });
        }
    });
    let failures = failures.into_inner().unwrap();
    assert!(failures.is_empty(), "{failures:#?}");
}
