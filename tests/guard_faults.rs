//! Issue 65: the guard stops a faulty pipeline short of what its sensor
//! plainly sees. Each of four defects (obstacle avoidance weighted 0, a
//! perception that reports nothing, a local map that drops every cell, a
//! map that stops changing: `[pipeline] fault`) drives at each of four
//! barriers ahead (a row of boulders, a row of trunks, a bank, a ditch) at
//! 2.5 and 4.5 m/s with the ERIM (the defaults; 40 m ahead) and, all but
//! the forgetful map (below), at 8 m/s
//! with the 64-beam lidar (60 m ahead: room to reach that speed at 1 m/s²;
//! the top speeds reached, 7.3-8.0 m/s, within 0.1 m/s of those at 70 m,
//! for a tenth less of the test's time; in every test run each barrier
//! once, the faults in turn, and every pair with
//! `ARCNAV_GUARD_GRID=whole`): with the
//! guard no run touches a hazard it could have stopped for; without it the
//! same runs collide.
//!
//! The barriers cross the whole world, so that no pipeline, faulty or not,
//! can find a way round and the only way not to hit one is to stop.

use std::sync::Arc;

use arcnav::Config;
use arcnav::mission::{MissionOptions, MissionReport, run_mission};
use arcnav_sim::World;

/// The barriers' line, m ahead of the start, at `speed`.
fn ahead_m(speed: f64) -> f64 {
    if speed > 5.0 { 60.0 } else { 40.0 }
}

/// A world with `kind` of barrier across it `ahead` m ahead, the
/// waypoint 30 m beyond.
fn barrier_world(kind: &str, ahead: f64) -> World {
    let mut text = format!(
        "name = \"guard_{kind}\"\n\
         description = \"a {kind} barrier across the world {ahead} m ahead\"\n\
         [terrain]\norigin_m = [-20.0, -60.0]\nsize_m = [140.0, 120.0]\nseed = 11\n\
         hills_amplitude_m = 0.05\nhills_wavelength_m = 120.0\n\
         roughness_amplitude_m = 0.01\nroughness_wavelength_m = 2.0\n\
         [start]\nposition_m = [0.0, 0.0]\nheading_deg = 0.0\n\
         [[waypoints]]\nposition_m = [{}, 0.0]\n",
        ahead + 30.0
    );
    // Rows: 1 m boulders 0.6 m apart, 8 m trunks 1 m apart (the vehicle is
    // 2 m wide).
    let row = |text: &mut String, table: &str, step: f64, radius: f64, height: f64| {
        let mut y = -59.0;
        while y <= 59.0 {
            text.push_str(&format!(
                "[[{table}]]\nposition_m = [{ahead}, {y:.1}]\nradius_m = {radius}\nheight_m = {height}\n"
            ));
            y += step;
        }
    };
    match kind {
        "boulders" => row(&mut text, "boulders", 1.8, 0.6, 1.0),
        "trees" => row(&mut text, "trees", 1.5, 0.25, 8.0),
        "bank" => text.push_str(&format!(
            "[[banks]]\nfrom_m = [{ahead}, -60.0]\nto_m = [{ahead}, 60.0]\n\
             height_m = 1.0\ntop_width_m = 1.5\nslope_deg = 70.0\n"
        )),
        "ditch" => text.push_str(&format!(
            "[[ditches]]\nfrom_m = [{ahead}, -60.0]\nto_m = [{ahead}, 60.0]\n\
             width_m = 1.5\ndepth_m = 1.0\n"
        )),
        _ => unreachable!("{kind}"),
    }
    World::from_toml(&text, &format!("the {kind} barrier"), None).unwrap()
}

/// The configuration of one run: the fault, the speed (8 m/s with the
/// lidar, its hole-speed cap off so that it drives that fast), the guard
/// on or off. A run ends 8 s after the vehicle stops gaining on its
/// waypoint.
fn config(fault: &str, speed: f64, guard: bool) -> Config {
    let fault = match fault {
        "no_avoidance" => {
            "[arbiter]\nrequired = []\n[arbiter.weights]\nobstacle_avoidance = 0.0\n".to_string()
        }
        fault => format!("[pipeline]\nfault = \"{fault}\"\nfault_after_s = 2.0\n"),
    };
    // The ERIM held to what one image shows of a hole in time (4.19 m/s
    // for 4.5 asked), as the matrix was drawn up: uncapped, the route
    // alone steered round the boulders at 4.5 m/s, and the fault had no
    // barrier to drive into.
    let sensor = if speed > 5.0 {
        "[sensor]\npreset = \"lidar64\"\n"
    } else {
        "[lookahead]\nhole_speed_cap = true\n"
    };
    let text = format!(
        "{fault}{sensor}[sim]\nstuck_after_s = 4.0\ntime_limit_s = 40.0\nthreads = 1\n\
         [guard]\nenabled = {guard}\n"
    );
    let mut config = Config::parse(&text, "the fault's configuration").unwrap();
    config.arbiter.cruise_speed_mps = speed;
    config
}

struct Run {
    fault: &'static str,
    world: &'static str,
    speed: f64,
    guarded: MissionReport,
    unguarded: MissionReport,
}

fn mission(world: &World, config: &Config) -> MissionReport {
    let options = MissionOptions {
        beside_others: true,
        ..MissionOptions::default()
    };
    let _slot = arcnav_testkit::cpu_slot();
    run_mission(
        &config.resolved().unwrap(),
        Arc::new(world.clone()),
        &options,
        &mut |_| {},
    )
    .unwrap()
    .report
}

fn line(run: &Run) -> String {
    let r = &run.guarded;
    let guard = r.guard.as_ref().unwrap();
    let first = guard.first.first().map_or("-".to_string(), |e| {
        format!("{} at x {:.1}: {}", e.verdict, e.x, e.reason)
    });
    let hit = |r: &MissionReport| {
        r.collisions
            .first()
            .map_or("no collision".to_string(), |c| {
                format!("{} at x {:.1}", c.cause, c.position[0])
            })
    };
    format!(
        "{:<16} {:<9} {:>4.1} m/s | guard: {} stops, {} slows, max {:.1} m/s, {}; first {} | without: {}",
        run.fault,
        run.world,
        run.speed,
        guard.stops,
        guard.slows,
        r.max_speed_mps,
        hit(r),
        first,
        hit(&run.unguarded),
    )
}

/// The lidar's runs at 8 m/s of every test run: each barrier once, the
/// faults in turn, the ditch with the blind perception (its hole shows
/// late: the run of the grid that asks most of the guard). Each lidar run
/// costs about ten times an ERIM one; the other eight of the grid run with
/// `ARCNAV_GUARD_GRID=whole` (DEVELOPERS.md): after changing the guard.
const LIDAR_IN_EVERY_RUN: [(&str, &str); 4] = [
    ("no_avoidance", "boulders"),
    ("stale_map", "trees"),
    ("blind_perception", "bank"),
    ("blind_perception", "ditch"),
];

/// Whether to drive the whole grid (`ARCNAV_GUARD_GRID=whole`).
fn whole_grid() -> bool {
    std::env::var("ARCNAV_GUARD_GRID").is_ok_and(|v| v == "whole")
}

#[test]
fn the_guard_stops_each_faulty_pipeline_before_each_barrier_at_each_speed() {
    const FAULTS: [&str; 4] = [
        "no_avoidance",
        "blind_perception",
        "forgetful_map",
        "stale_map",
    ];
    const WORLDS: [&str; 4] = ["boulders", "trees", "bank", "ditch"];
    const SPEEDS: [f64; 3] = [2.5, 4.5, 8.0];
    let worlds: Vec<(&str, f64, World)> = WORLDS
        .iter()
        .flat_map(|&k| [40.0, 60.0].map(|ahead| (k, ahead, barrier_world(k, ahead))))
        .collect();
    // A map that drops every cell leaves the pipeline what a blind
    // perception does, an empty map, and the guard sees for itself: their
    // lidar runs at 8 m/s were the same to the decimetre and the tenth of
    // a m/s (2026-12-07), for 18 s of CPU each. The map's fault is driven
    // with the ERIM.
    let cases: Vec<(&'static str, &'static str, f64)> = FAULTS
        .iter()
        .flat_map(|&f| {
            WORLDS
                .iter()
                .flat_map(move |&w| SPEEDS.iter().map(move |&s| (f, w, s)))
        })
        .filter(|&(f, _, s)| !(f == "forgetful_map" && s > 5.0))
        .filter(|&(f, w, s)| s < 5.0 || whole_grid() || LIDAR_IN_EVERY_RUN.contains(&(f, w)))
        .collect();
    let threads = std::thread::available_parallelism().map_or(2, |n| n.get().min(4));
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut runs: Vec<Run> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..threads)
            .map(|_| {
                scope.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(&(fault, world, speed)) = cases.get(i) else {
                            return done;
                        };
                        let map = &worlds
                            .iter()
                            .find(|(k, ahead, _)| *k == world && *ahead == ahead_m(speed))
                            .unwrap()
                            .2;
                        done.push((
                            i,
                            Run {
                                fault,
                                world,
                                speed,
                                guarded: mission(map, &config(fault, speed, true)),
                                unguarded: mission(map, &config(fault, speed, false)),
                            },
                        ));
                    }
                })
            })
            .collect();
        let mut all: Vec<(usize, Run)> = handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect();
        all.sort_by_key(|(i, _)| *i);
        all.into_iter().map(|(_, run)| run).collect()
    });
    let table: String = runs.iter().map(|r| line(r) + "\n").collect();
    eprintln!("{table}");
    let braking = arcnav_guard::zones::Braking::of(&Config::default().vehicle, 0.0);
    for run in runs.drain(..) {
        let what = line(&run);
        let guard = run.guarded.guard.as_ref().unwrap();
        // The fault was in force.
        assert_eq!(
            run.guarded.fault.as_ref().map(|f| f.fault),
            (run.fault != "no_avoidance").then_some(run.fault),
            "{what}"
        );
        // Where the pipeline would have hit the barrier, the guard acted.
        let hit = |r: &MissionReport| {
            r.collisions
                .iter()
                .any(|c| c.position[0] > ahead_m(run.speed) - 6.0)
        };
        if hit(&run.unguarded) {
            assert!(guard.interventions() > 0, "{what}\n\n{table}");
        }
        // A trunk hides the ground behind it, and a pipeline whose map
        // holds no cell still knows the ground it has not seen: it may stop
        // short of it (the lookahead) guard or not. Everywhere else the
        // fault drives the vehicle into the barrier without the guard.
        let may_stop_itself =
            run.world == "trees" && matches!(run.fault, "blind_perception" | "forgetful_map");
        if !may_stop_itself {
            assert!(hit(&run.unguarded), "{what}\n\n{table}");
        }
        // A ditch 1.5 m wide shows the lidar 2.4 m up a far wall deep
        // enough to be a hole only within about 8-12 m (w·H/R): from 7-8 m/s
        // the vehicle needs more than that to stop (v·latency + v²/2a).
        // There the guard stops it as soon as the hole shows and the
        // vehicle reaches the ditch slowed; asserted: the first stop came
        // inside the stopping distance from the top speed.
        if run.world == "ditch" && run.speed > 5.0 {
            let first = guard.first.first().expect("the guard acted");
            assert_eq!(first.verdict, "stop", "{what}");
            let along: f64 = first.reason.split(' ').nth(1).unwrap().parse().unwrap();
            assert!(
                along < braking.stopping_m(run.guarded.max_speed_mps),
                "{what}: the hole showed {along} m along the path"
            );
            continue;
        }
        assert!(run.guarded.collisions.is_empty(), "{what}\n\n{table}");
    }
}

/// A trench 3 m wide and 2 m deep (`drop_offs`) in front of a blind
/// pipeline: the guard stops the vehicle short of it and keeps it there.
/// The hole shows as returns on the trench's floor, each image a little
/// farther in; held only where they fell, the nearer ones were seen to be
/// ground and forgotten, and the vehicle crept 0.1-0.3 m at a time until
/// its wheels went over the edge. The near edge is held as the hole.
#[test]
fn a_blind_pipeline_is_held_short_of_a_wide_trench_however_long_it_stands() {
    let world = World::embedded("drop_offs").unwrap().unwrap();
    let run = |guard: bool| {
        let mut config = config("blind_perception", 2.5, guard);
        config.pipeline.fault_after_s = 0.0;
        config.sim.stuck_after_s = 20.0;
        config.sim.time_limit_s = 60.0;
        mission(&world, &config)
    };
    let guarded = run(true);
    let guard = guarded.guard.as_ref().unwrap();
    assert!(
        guarded.collisions.is_empty(),
        "{:?}\n{:?}",
        guarded.collisions,
        guard.first
    );
    assert!(guard.stops > 0, "{guard:?}");
    assert_eq!(guard.by_reason.get("hole"), Some(&guard.stops), "{guard:?}");
    // It stood before the trench (its near edge at x = 28.5 m) until the
    // mission gave up (20 s without getting nearer its waypoint).
    assert_eq!(guarded.outcome, arcnav::mission::Outcome::Stuck);
    assert!(guard.stopped_s > 15.0, "{guard:?}");
    let unguarded = run(false);
    assert!(
        unguarded
            .collisions
            .iter()
            .any(|c| c.cause.starts_with("ditch")),
        "{:?}",
        unguarded.collisions
    );
}
