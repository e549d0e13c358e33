//! `arcnav sim` end to end, as a user runs it.

use std::collections::BTreeMap;
use std::path::Path;

use arcnav_bus::log::LogReader;
use arcnav_bus::messages::{AnyMessage, TypedEvents};
use arcnav_testkit::ScratchDir;
use serde_json::Value;

fn arcnav(args: &[&str]) -> (i32, String, String) {
    arcnav_testkit::output_of(env!("CARGO_BIN_EXE_arcnav"), args)
}

/// The `report.json` a run wrote in `dir`.
fn read_report(dir: &Path) -> Value {
    let path = dir.join("report.json");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn out_dir(tag: &str) -> ScratchDir {
    arcnav_testkit::scratch_dir(&format!("arcnav-sim-{tag}"))
}

/// The mission `tag` completed with no collision (its summary printed
/// when not).
fn assert_completed_without_collision(tag: &str, report: &Value, stdout: &str) {
    assert_eq!(report["outcome"], "completed", "{tag}:\n{stdout}");
    assert_no_collision(tag, report, stdout);
}

/// The mission `tag` met nothing, whatever its outcome (its summary
/// printed when it did).
fn assert_no_collision(tag: &str, report: &Value, stdout: &str) {
    assert_eq!(
        report["collisions"].as_array().unwrap().len(),
        0,
        "{tag}:\n{stdout}"
    );
}

/// Runs `arcnav sim --out DIR ARGS…` for every (tag, args), as many at a
/// time as there are cores: each mission's report and standard output, in
/// the order of `runs`.
fn missions<'a, T: AsRef<str> + Sync>(
    prefix: &str,
    runs: &'a [(T, Vec<String>)],
) -> Vec<(&'a str, Value, String)> {
    missions_kept(prefix, runs)
        .into_iter()
        .map(|(tag, _, report, stdout)| (tag, report, stdout))
        .collect()
}

/// [`missions`], each with the directory it wrote (removed when dropped).
fn missions_kept<'a, T: AsRef<str> + Sync>(
    prefix: &str,
    runs: &'a [(T, Vec<String>)],
) -> Vec<(&'a str, ScratchDir, Value, String)> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let workers = std::thread::available_parallelism().map_or(2, |n| n.get());
    type Done<'a> = (usize, (&'a str, ScratchDir, Value, String));
    let mut done: Vec<Done<'a>> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..workers.min(runs.len()))
            .map(|_| {
                scope.spawn(|| {
                    let mut mine = Vec::new();
                    loop {
                        let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some((tag, args)) = runs.get(k) else {
                            return mine;
                        };
                        let tag = tag.as_ref();
                        let out = out_dir(&format!("{prefix}-{tag}"));
                        let mut all = vec!["sim", "--out", out.to_str().unwrap()];
                        all.extend(args.iter().map(String::as_str));
                        let (_, stdout, stderr) = arcnav(&all);
                        let report = std::fs::read_to_string(out.join("report.json"))
                            .unwrap_or_else(|e| {
                                panic!("{tag}: no report ({e}):\n{stdout}\n{stderr}")
                            });
                        let report = serde_json::from_str(&report).unwrap();
                        mine.push((k, (tag, out, report, stdout)));
                    }
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect()
    });
    done.sort_by_key(|(k, _)| *k);
    done.into_iter().map(|(_, run)| run).collect()
}

/// The range-noise seeds (`sim.seed`) a mission test asks its question
/// over where the answer hangs on the noise (one seed's outcome may be its
/// realisation's luck): seeds 1 to N, N from `ARCNAV_TEST_NOISE_SEEDS`, 1
/// when it is not set. Every assertion runs with seed 1 in every test run;
/// the figures these tests quote were measured over seeds 1-6, and a change
/// to what drives is checked over them before it lands
/// (`ARCNAV_TEST_NOISE_SEEDS=6 cargo test --release --test sim_mission`,
/// about six times as long; DEVELOPERS.md). One by default since
/// 2026-12-02 (two, six, then four before), to keep the whole suite near
/// ten minutes on two cores.
fn noise_seeds() -> std::ops::RangeInclusive<u64> {
    const VAR: &str = "ARCNAV_TEST_NOISE_SEEDS";
    match std::env::var(VAR) {
        Err(_) => 1..=1,
        Ok(text) => match text.trim().parse::<u64>() {
            Ok(n @ 1..=64) => 1..=n,
            _ => panic!("{VAR}={text:?}: give how many noise seeds to ask over, 1 to 64"),
        },
    }
}

/// Each (tag, sensor, TOML merged over the defaults) with each of
/// [`noise_seeds`], `args` added: the missions' reports, grouped by run in
/// the order given, seeds in order within each, tagged `TAG-seedN`.
fn over_noise_seeds(
    prefix: &str,
    runs: &[(&str, &str, &str)],
    args: &[&str],
) -> Vec<Vec<(String, Value, String)>> {
    let configs = out_dir(&format!("{prefix}-configs"));
    let dir: &Path = &configs;
    let seeds = noise_seeds();
    let all: Vec<_> = runs
        .iter()
        .flat_map(|&run| seeds.clone().map(move |seed| seeded(dir, run, args, seed)))
        .collect();
    let reports: Vec<(String, Value, String)> = missions(prefix, &all)
        .into_iter()
        .map(|(tag, report, stdout)| (tag.to_owned(), report, stdout))
        .collect();
    reports.chunks(seeds.count()).map(<[_]>::to_vec).collect()
}

/// The mission (tag, sensor, TOML merged over the defaults) with noise
/// seed `seed` and `args` added, its configuration written in `configs`:
/// tagged `TAG-seedN`, with the arguments of `arcnav sim`.
fn seeded(
    configs: &Path,
    (tag, sensor, toml): (&str, &str, &str),
    args: &[&str],
    seed: u64,
) -> (String, Vec<String>) {
    let path = configs.join(format!("{tag}-seed{seed}.toml"));
    std::fs::write(&path, format!("{toml}\n[sim]\nseed = {seed}\n")).unwrap();
    let mut run: Vec<String> = ["--sensor", sensor, "--config", path.to_str().unwrap()]
        .map(String::from)
        .to_vec();
    run.extend(args.iter().map(|a| a.to_string()));
    (format!("{tag}-seed{seed}"), run)
}

/// Held to the hole speed cap (`speed_bound.suspect_bound_mps`), and the
/// world's one ditch first flagged or suspected at least as far off as one
/// image is certain to (`suspect_range_m`, less a frame's travel): the
/// report and the summary say how far (issue 63's measure).
/// The run drove faster than one image shows a hole in time (the old
/// cap), the governor holding its speed where the ground was not verified,
/// and the ditch was reported no nearer than one image would.
fn assert_governed_and_the_ditch_reported_in_time(tag: &str, report: &Value, stdout: &str) {
    let bound = &report["speed_bound"];
    let cap = bound["suspect_bound_mps"].as_f64().unwrap();
    let max = report["max_speed_mps"].as_f64().unwrap();
    assert!(max > cap + 0.5, "{tag}: {max} m/s, not above {cap}");
    let governed = report["speed_limited_by_s"]["verified distance"]
        .as_f64()
        .unwrap_or(0.0);
    assert!(governed > 1.0, "{tag}: governed {governed} s:\n{stdout}");
    assert!(
        report["verified_distance_m"]["median"].as_f64().unwrap() > 10.0,
        "{tag}: {}",
        report["verified_distance_m"]
    );
    let range = bound["suspect_range_m"].as_f64().unwrap();
    let drops = report["drops_first_seen"].as_array().unwrap();
    assert_eq!(drops.len(), 1, "{tag}: {drops:?}");
    let first = drops[0]["first_range_m"].as_f64().unwrap();
    assert!(first >= range - 1.0, "{tag}: first reported {first} m away");
    assert!(
        stdout.contains("drop hazards  1 hole or ditch the wheels do not bridge: first"),
        "{tag}:\n{stdout}"
    );
}

fn run_short_course(tag: &str) -> ScratchDir {
    let out = out_dir(tag);
    let (code, stdout, stderr) = arcnav(&[
        "sim",
        "--world",
        "short_course",
        "--out",
        out.to_str().unwrap(),
        "--snapshot-every",
        "20",
    ]);
    assert_eq!(code, 0, "the short course completes:\n{stdout}\n{stderr}");
    assert!(
        stdout.contains("mission       completed on short_course"),
        "{stdout}"
    );
    out
}

#[test]
fn a_short_mission_completes_and_its_report_log_and_pictures_are_sound() {
    let out = run_short_course("e2e");
    let report: Value = read_report(&out);
    assert_eq!(report["outcome"], "completed");
    assert_eq!(report["success"], true);
    assert_eq!(report["waypoints_reached"], 3);
    assert_eq!(report["collisions"].as_array().unwrap().len(), 0);
    let distance = report["distance_m"].as_f64().unwrap();
    assert!(
        (140.0..200.0).contains(&distance),
        "{distance} m for a 150 m course"
    );
    let duration = report["duration_s"].as_f64().unwrap();
    assert!(report["average_speed_mps"].as_f64().unwrap() > 2.0);
    // The closest approach says when, where and to what, within the run.
    let near = &report["closest_approach"];
    let at = near["at_s"].as_f64().unwrap();
    assert!((0.0..=duration).contains(&at), "{near}");
    assert!(
        near["hazard"].as_str().is_some_and(|h| !h.is_empty()),
        "{near}"
    );
    assert!(report["closest_approach_m"].as_f64().unwrap() >= 0.0);
    // And the speed the configuration allows, with the share achieved.
    let bound = report["speed_bound"]["bound_mps"].as_f64().unwrap();
    let fraction = report["speed_fraction_of_bound"].as_f64().unwrap();
    assert!(
        (fraction * bound - report["average_speed_mps"].as_f64().unwrap()).abs() < 1e-9,
        "{fraction} of {bound}"
    );
    // Holes the wheels do not bridge are seen nearer than steps: the
    // ERIM flags one for certain only within ~6.3 m, so the paper's 2-3
    // m/s.
    let holes = &report["speed_bound"];
    let hole_range = holes["hole_certain_m"].as_f64().unwrap();
    let hole_bound = holes["hole_bound_mps"].as_f64().unwrap();
    assert!(
        hole_range < holes["detection_range_m"].as_f64().unwrap() && hole_bound < bound,
        "{holes}"
    );
    assert!(
        report["stage_times"]["perception"]["count"]
            .as_u64()
            .unwrap()
            > 50
    );

    // Every message of the log decodes; every channel is there at its rate.
    let mut events = TypedEvents::new(LogReader::open(out.join("mission.lcm")).unwrap());
    let mut times: BTreeMap<String, Vec<i64>> = BTreeMap::new();
    for event in events.by_ref() {
        let event = event.unwrap();
        times
            .entry(event.channel.clone())
            .or_default()
            .push(event.timestamp);
        if let AnyMessage::SteeringCommand(c) = &event.message {
            // Backing up (negative speed) only ever at the recovery speed.
            assert!(c.speed >= -1.0 && c.curvature.abs() <= 0.125 + 1e-9);
        }
    }
    assert!(!events.log_stats().lost_anything());
    assert!(events.stats().unknown.is_empty() && events.stats().undecodable.is_empty());
    let channels: Vec<&str> = times.keys().map(String::as_str).collect();
    assert_eq!(
        channels,
        [
            "ARC_VOTES_GOAL_SEEKING",
            "ARC_VOTES_OBSTACLE_AVOIDANCE",
            "ARC_VOTES_ROUTE",
            "DECISION",
            "OBSTACLE_CELLS",
            "POSE",
            "RANGE_IMAGE_ERIM",
            "STEERING_COMMAND",
            "WAYPOINTS"
        ]
    );
    // Every command says why (DECISION, at the same times).
    assert_eq!(times["DECISION"], times["STEERING_COMMAND"]);
    let rate = |channel: &str| {
        let t = &times[channel];
        let gaps: Vec<i64> = t.windows(2).map(|w| w[1] - w[0]).collect();
        (
            t.len(),
            gaps.iter().copied().min().unwrap(),
            gaps.iter().copied().max().unwrap(),
        )
    };
    let (commands, min_gap, max_gap) = rate("STEERING_COMMAND");
    assert_eq!(
        (min_gap, max_gap),
        (100_000, 100_000),
        "commands every 100 ms (10 Hz)"
    );
    assert!(
        (commands as f64 - duration * 10.0).abs() <= 2.0,
        "{commands} commands in {duration} s"
    );
    assert_eq!(rate("POSE").1, 20_000, "poses at 50 Hz");
    assert_eq!(rate("RANGE_IMAGE_ERIM").1, 500_000, "images at 2 Hz");
    assert_eq!(
        times["OBSTACLE_CELLS"].len(),
        times["RANGE_IMAGE_ERIM"].len(),
        "one report per image"
    );

    // Pictures.
    let png = std::fs::read(out.join("map.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    let snapshots = std::fs::read_dir(out.join("snapshots")).unwrap().count();
    assert!(
        snapshots >= 3,
        "{snapshots} snapshots over ~60 s at one per 20 s"
    );
}

/// The missions whose logs are held to committed digests: every decision
/// of the pipeline, the simulator's motion and every image, byte for byte.
/// (tag, `arcnav sim` arguments); `tests/golden/logs.sha256` holds the
/// digest of each one's `mission.lcm`.
const GOLDEN: &[(&str, &[&str])] = &[
    (
        "paper_loop-erim",
        &["--world", "paper_loop", "--sensor", "erim"],
    ),
    // The lidar's missions: at 8 m/s, faster than one image shows a hole
    // in time (the ground verified over images, the speed governor), and
    // at 5 m/s, slower. (Not round the paper's loop: 33 s of CPU, a
    // twentieth of the suite's, for what the ones below hold already.)
    (
        "short_course-erim",
        &["--world", "short_course", "--sensor", "erim"],
    ),
    (
        "short_course-lidar64-8",
        &[
            "--world",
            "short_course",
            "--sensor",
            "lidar64",
            "--speed",
            "8",
        ],
    ),
    (
        "seed8-hard-erim",
        &["--seed", "8", "--difficulty", "hard", "--sensor", "erim"],
    ),
    (
        "seed8-hard-lidar64-5",
        &[
            "--seed",
            "8",
            "--difficulty",
            "hard",
            "--sensor",
            "lidar64",
            "--speed",
            "5",
            "--config",
            FIRST_45_S,
        ],
    ),
];

/// The generated worlds' lidar missions run their first 45 s (of about
/// 90): as many decisions as a whole ERIM mission holds, at half the CPU.
const FIRST_45_S: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/golden/first_45_s.toml");

/// The same missions write the same logs as when the digests were taken
/// (before the configuration and executors were redesigned): a change that
/// moves code changes no decision. A change that means to drive otherwise
/// takes new digests with `ARCNAV_UPDATE_DIGESTS=1` and says why in its
/// commit. Each mission runs once per test run, so this also holds that
/// the same mission writes the same log whenever it runs.
#[test]
fn the_missions_write_the_logs_their_committed_digests_hold() {
    use sha2::Digest as _;
    let file = arcnav_testkit::workspace_root().join("tests/golden/logs.sha256");
    let runs: Vec<(&str, Vec<String>)> = GOLDEN
        .iter()
        .map(|(tag, args)| (*tag, args.iter().map(|a| a.to_string()).collect()))
        .collect();
    // Two at a time, each taking the next mission when it is done.
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut digests: Vec<(usize, (String, String))> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..2)
            .map(|_| {
                scope.spawn(|| {
                    std::iter::from_fn(|| {
                        let index = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        runs.get(index).map(|run| (index, run))
                    })
                    .map(|(index, (tag, args))| {
                        (index, {
                            let out = out_dir(&format!("golden-{tag}"));
                            let mut all = vec!["sim", "--out", out.to_str().unwrap()];
                            all.extend(args.iter().map(String::as_str));
                            let (code, stdout, stderr) = arcnav(&all);
                            // Hashed as it is read: a lidar's log holds
                            // every image (hundreds of megabytes).
                            let mut hasher = sha2::Sha256::new();
                            let bytes = std::fs::File::open(out.join("mission.lcm"))
                                .and_then(|mut log| std::io::copy(&mut log, &mut hasher))
                                .unwrap_or_else(|e| {
                                    panic!("{tag}: no log (exit {code}, {e}):\n{stdout}\n{stderr}")
                                });
                            assert!(bytes > 100_000, "{tag}: {bytes} bytes");
                            // With no fault, the guard beside the pipeline
                            // never has to act (issue 65).
                            let report = read_report(&out);
                            assert_eq!(
                                report["guard"]["stops"]
                                    .as_u64()
                                    .zip(report["guard"]["slows"].as_u64()),
                                Some((0, 0)),
                                "{tag}: the guard intervened: {}",
                                report["guard"]
                            );
                            let digest = hasher.finalize();
                            let hex: String = digest.iter().map(|b| format!("{b:02x}")).collect();
                            (tag.to_string(), hex)
                        })
                    })
                    .collect::<Vec<_>>()
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap())
            .collect()
    });
    digests.sort_by_key(|(index, _)| *index);
    let digests: Vec<(String, String)> = digests.into_iter().map(|(_, d)| d).collect();
    let now: String = digests
        .iter()
        .map(|(tag, hex)| format!("{hex}  {tag}\n"))
        .collect();
    if std::env::var_os("ARCNAV_UPDATE_DIGESTS").is_some() {
        std::fs::create_dir_all(file.parent().unwrap()).unwrap();
        std::fs::write(&file, &now).unwrap();
        return;
    }
    let committed =
        std::fs::read_to_string(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    let differing: Vec<&str> = now
        .lines()
        .filter(|line| !committed.lines().any(|c| c == *line))
        .collect();
    assert!(
        differing.is_empty() && committed.lines().count() == GOLDEN.len(),
        "logs differ from {}:\n{}\n(a change meant to drive otherwise takes new digests \
         with ARCNAV_UPDATE_DIGESTS=1)",
        file.display(),
        differing.join("\n")
    );
}

/// A lidar's images rendered beside the pipeline (`sim.render_ahead`) make
/// the mission that renders each image when due, byte for byte: every image
/// but the first was rendered ahead, none had to be rendered again, and the
/// logs are the same. 8 s of short_course with the 64-beam lidar (the
/// vehicle under way, turning and meeting the course's first cells).
#[test]
fn images_rendered_beside_the_pipeline_make_the_same_mission() {
    let run = |tag: &str, ahead: bool| {
        let out = out_dir(tag);
        let config = out.join("ahead.toml");
        std::fs::write(
            &config,
            format!("[sim]\ntime_limit_s = 8.0\nrender_ahead = {ahead}\n"),
        )
        .unwrap();
        let (_, stdout, stderr) = arcnav(&[
            "sim",
            "--world",
            "short_course",
            "--sensor",
            "lidar64",
            "--config",
            config.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ]);
        let report: Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap())
                .unwrap_or_else(|e| panic!("{tag}: {e}\n{stdout}\n{stderr}"));
        assert_eq!(report["outcome"], "timeout", "{tag}: {stdout}");
        let log = std::fs::read(out.join("mission.lcm")).unwrap();
        (report, log, stdout, out)
    };
    let (ahead, ahead_log, stdout, _a) = run("ahead-on", true);
    let (when_due, when_due_log, _, _b) = run("ahead-off", false);
    let images = ahead["images"].as_u64().unwrap();
    assert!(images >= 80, "{ahead}");
    assert_eq!(ahead["images_rendered_ahead"], images - 1);
    assert_eq!(ahead["images_rendered_again"], 0);
    assert!(
        stdout.contains(&format!(
            "({} of {images} rendered ahead, beside the pipeline; 0 rendered twice)",
            images - 1
        )),
        "{stdout}"
    );
    assert_eq!(when_due["images_rendered_ahead"], 0);
    assert_eq!(when_due["images"], images);
    assert!(ahead_log.len() > 5_000_000, "{} bytes", ahead_log.len());
    assert!(
        ahead_log == when_due_log,
        "rendering ahead changed the mission's log"
    );
}

#[test]
fn list_shows_the_embedded_worlds() {
    let (code, stdout, _) = arcnav(&["sim", "--list"]);
    assert_eq!(code, 0);
    for name in ["paper_loop", "short_course", "open_field"] {
        assert!(stdout.contains(name), "{stdout}");
    }
}

#[test]
fn bad_worlds_fail_with_a_message_naming_the_problem() {
    let (code, _, stderr) = arcnav(&["sim", "--world", "atlantis"]);
    assert_eq!(code, 1);
    assert!(
        stderr.contains("no embedded world named \"atlantis\""),
        "{stderr}"
    );
    assert!(
        stderr.contains("paper_loop"),
        "the known ones are listed: {stderr}"
    );

    let (code, _, stderr) = arcnav(&["sim", "--world", "/nonexistent/world.toml"]);
    assert_eq!(code, 1);
    assert!(
        stderr.contains("cannot read world file /nonexistent/world.toml"),
        "{stderr}"
    );

    let dir = out_dir("bad-world");
    let file = dir.join("w.toml");
    std::fs::write(
        &file,
        "name = \"w\"\n[start]\nposition_m = [0.0, 0.0]\n[[waypoints]]\nposition_m = [30.0, 0.0]\n[[trees]]\nposition_m = [30.0, 0.2]\nradius_m = 0.3\nheight_m = 5.0\n",
    )
    .unwrap();
    let (code, _, stderr) = arcnav(&[
        "sim",
        "--world",
        file.to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 1);
    assert!(
        stderr.contains("waypoint 1 at (30.0, 0.0) lies inside tree #0"),
        "{stderr}"
    );
    assert!(
        !Path::new(&dir.join("mission.lcm")).exists(),
        "nothing is run"
    );
}

/// Refused before the mission runs, what the run reads left as it was:
/// `--save-world` onto the world file given had rewritten it without its
/// comments, and onto any file of the run's (`map.png`) had been
/// overwritten by it; a run's `config.toml` given back as `--config` was
/// rewritten by the run.
#[test]
fn a_mission_never_writes_over_the_world_or_configuration_it_reads() {
    let dir = out_dir("inputs-kept");
    let world = dir.join("my_world.toml");
    let text = std::fs::read_to_string(format!(
        "{}/tests/worlds/forest.toml",
        env!("CARGO_MANIFEST_DIR")
    ))
    .unwrap();
    std::fs::write(&world, &text).unwrap();
    let config = dir.join("config.toml");
    let config_text = "# mine\n[sim]\nseed = 2\n";
    std::fs::write(&config, config_text).unwrap();
    let (w, c, d) = (
        world.to_str().unwrap(),
        config.to_str().unwrap(),
        dir.to_str().unwrap(),
    );
    let map = dir.join("map.png");
    for (args, expect) in [
        (
            vec!["--world", w, "--save-world", w],
            "it is the world".to_owned(),
        ),
        (
            vec!["--config", c, "--out", d],
            "it is the configuration".to_owned(),
        ),
        (
            vec![
                "--world",
                "short_course",
                "--out",
                d,
                "--save-world",
                map.to_str().unwrap(),
            ],
            format!("the run writes {} already", map.display()),
        ),
    ] {
        let mut all = vec!["sim", "--no-images"];
        all.extend(args.iter().copied());
        let (code, stdout, stderr) = arcnav(&all);
        assert_eq!(code, 1, "{args:?}: {stdout}{stderr}");
        assert!(stderr.contains(&expect), "{args:?}: {stderr}");
        assert!(!stdout.contains("mission "), "{args:?}: it ran:\n{stdout}");
    }
    assert_eq!(std::fs::read_to_string(&world).unwrap(), text);
    assert_eq!(std::fs::read_to_string(&config).unwrap(), config_text);
    assert!(!map.exists());
}

#[test]
fn a_generated_world_can_be_saved_and_run_again() {
    let dir = out_dir("generated");
    let file = dir.join("seed7.toml");
    // The first 40 s of each run (the worlds themselves are compared whole).
    let limit = dir.join("limit.toml");
    std::fs::write(&limit, "[sim]\ntime_limit_s = 40.0\n").unwrap();
    let (code, stdout, stderr) = arcnav(&[
        "sim",
        "--seed",
        "7",
        "--difficulty",
        "easy",
        "--save-world",
        file.to_str().unwrap(),
        "--config",
        limit.to_str().unwrap(),
        "--out",
        dir.to_str().unwrap(),
        "--no-images",
    ]);
    assert!(stdout.contains("world saved to"), "{stdout}{stderr}");
    let first: Value = read_report(&dir);
    assert_eq!(
        code == 0,
        first["success"] == true,
        "exit status 0 exactly when the mission succeeds"
    );
    let again = dir.join("again");
    let resaved = dir.join("again.toml");
    let (_, _, stderr) = arcnav(&[
        "sim",
        "--world",
        file.to_str().unwrap(),
        "--save-world",
        resaved.to_str().unwrap(),
        "--config",
        limit.to_str().unwrap(),
        "--out",
        again.to_str().unwrap(),
        "--no-images",
    ]);
    let second: Value =
        serde_json::from_str(&std::fs::read_to_string(again.join("report.json")).unwrap())
            .unwrap_or_else(|_| panic!("{stderr}"));
    // The saved world read back saves as the same file: the whole world,
    // not only the part the first 40 s drive through.
    assert_eq!(
        std::fs::read_to_string(&file).unwrap(),
        std::fs::read_to_string(&resaved).unwrap(),
        "the saved world is the generated one"
    );
    assert!(first["distance_m"].as_f64().unwrap() > 50.0, "{first}");
    assert_eq!(
        first["distance_m"], second["distance_m"],
        "and drives the same"
    );
}

/// A trench, a pit and oblique ditches (`drop_offs`): the sensors see them
/// only as missing ground. With drop-offs, seen ground and the speed it
/// allows, the vehicle gets round every one, with the ERIM at 2.5 and 4 m/s
/// (the 64-beam lidar at 10 m/s:
/// `at_speed_arcs_judged_along_driven_paths_keep_clear_of_ditches_and_boulders`);
/// with perception judging only cells with points (as before), the ERIM
/// drives into the trench.
#[test]
fn the_drop_offs_world_completes_without_falling_into_anything() {
    for (tag, args) in [
        ("drop-erim", &["--sensor", "erim"][..]),
        ("drop-erim-4", &["--sensor", "erim", "--speed", "4"][..]),
    ] {
        let out = out_dir(tag);
        // The report is all this reads: no images in the log.
        let mut all = vec![
            "sim",
            "--world",
            "drop_offs",
            "--no-images",
            "--out",
            out.to_str().unwrap(),
        ];
        all.extend_from_slice(args);
        let (code, stdout, stderr) = arcnav(&all);
        assert_eq!(code, 0, "{tag}:\n{stdout}\n{stderr}");
        let report: Value = read_report(&out);
        assert_eq!(report["outcome"], "completed", "{tag}");
        assert_eq!(report["collisions"].as_array().unwrap().len(), 0, "{tag}");
        assert!(
            report["untraversable_cells"]["drop-off"].as_u64().unwrap() > 100,
            "{tag}: the trench's and ditches' near edges are drop-offs: {}",
            report["untraversable_cells"]
        );
    }
    // 002's system (no drop-off detection, unseen ground free, goal
    // seeking): the trench.
    let out = out_dir("drop-off-disabled");
    let config = out.join("drop-off-disabled.toml");
    std::fs::write(
        &config,
        "[perception.drop_off]\nenabled = false\n[behaviours.obstacle_avoidance]\nunseen_ground = \"free\"\n\
         [arbiter.weights]\nroute = 0.0\ngoal_seeking = 0.5\n",
    )
    .unwrap();
    let (code, stdout, _) = arcnav(&[
        "sim",
        "--world",
        "drop_offs",
        "--config",
        config.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_ne!(code, 0, "{stdout}");
    assert!(stdout.contains("ditch 2.00 m deep"), "{stdout}");
    let _ = std::fs::remove_file(&config);
}

/// Trenches too wide to see into (`tests/worlds/`): from afar the near edge
/// looks like the crest of a gentle slope and is flagged only about 5 m
/// away, so the ground beyond it must count as unseen (a shadow) and the
/// vehicle must already be slow enough to stop before it. Before shadows
/// (the whole footprint counted as seen), the ERIM at 4 m/s and both lidars
/// drove into these. Each completes without a collision; so does the
/// ledge, whose shadow the 64-beam lidar never sees into, with the lidar
/// at 8 m/s asked (see
/// `held_short_of_a_ledge_s_shadow_the_vehicle_goes_round_the_ledge`: the
/// route shuts the unseen ground the vehicle backed away from).
#[test]
fn trenches_too_wide_to_see_into_are_driven_round_never_into() {
    let world = |name: &str| format!("{}/tests/worlds/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    for (tag, name, args) in [
        (
            "wide-erim-4",
            "wide_trench",
            &["--sensor", "erim", "--speed", "4"][..],
        ),
        (
            "oblique-lidar128-6",
            "oblique_trench",
            &["--sensor", "lidar128", "--speed", "6"][..],
        ),
    ] {
        let out = out_dir(tag);
        let world = world(name);
        let mut all = vec![
            "sim",
            "--world",
            &world,
            "--no-images",
            "--out",
            out.to_str().unwrap(),
        ];
        all.extend_from_slice(args);
        let (_, stdout, stderr) = arcnav(&all);
        let report: Value = serde_json::from_str(
            &std::fs::read_to_string(out.join("report.json"))
                .unwrap_or_else(|e| panic!("{tag}: no report ({e}):\n{stdout}\n{stderr}")),
        )
        .unwrap();
        assert_completed_without_collision(tag, &report, &stdout);
    }
}

/// 017's four situations: a forest, a hillside from a DEM, a cul-de-sac
/// with the waypoint behind it, and generated moderate world 4 (boxed in
/// after a U-turn). Each used to end stopped for good; with the route
/// behaviour, footprint clearing and backing up each completes at 2.5 m/s
/// with the ERIM and no collision. In the cul-de-sac the way out needs
/// both: the route turns the vehicle round, backing up makes room.
#[test]
fn forest_hillside_cul_de_sac_and_boxed_in_worlds_complete() {
    let world = |name: &str| format!("{}/tests/worlds/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    let runs: Vec<(&str, Vec<String>)> = vec![
        ("cul_de_sac", vec!["--world".into(), world("cul_de_sac")]),
        ("forest", vec!["--world".into(), world("forest")]),
        ("hillside", vec!["--world".into(), world("hillside")]),
        ("seed4", vec!["--seed".into(), "4".into()]),
    ];
    let reports = missions("stuck", &runs);
    for (tag, report, stdout) in &reports {
        assert_completed_without_collision(tag, report, stdout);
        assert!(
            report["behaviour_counters"]["route"]["plans"]
                .as_u64()
                .unwrap()
                >= 1
        );
    }
    let cul_de_sac = &reports[0].1;
    assert!(
        cul_de_sac["recovery"]["recoveries"].as_u64().unwrap() >= 1,
        "the U is left by backing up: {cul_de_sac}"
    );
    assert!(cul_de_sac["recovery"]["backed_m"].as_f64().unwrap() > 2.0);
    assert!(
        cul_de_sac["behaviour_counters"]["route"]["replans"]
            .as_u64()
            .unwrap()
            > 10
    );
}

/// 017, the class beyond the U: cul-de-sacs narrower than the
/// vehicle's turning circle (7.7 m of floor against 16 m), and the 24 m one
/// with the 64-beam lidar, whose route swings the vehicle to and fro when
/// it only backs up once. Each is left by turning round in a K-point turn:
/// completed, no collision, at least 90° turned in legs.
#[test]
fn narrow_cul_de_sacs_are_left_by_turning_round() {
    let world = |name: &str| format!("{}/tests/worlds/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    let run = |tag, name, sensor: &str| {
        let args = ["--world", &world(name), "--sensor", sensor, "--no-images"];
        (tag, args.map(String::from).to_vec())
    };
    let runs = [
        run("narrow-erim", "cul_de_sac_narrow", "erim"),
        run("narrow-lidar64", "cul_de_sac_narrow", "lidar64"),
        run("wide-lidar64", "cul_de_sac", "lidar64"),
    ];
    let reports = missions("turn", &runs);
    for (tag, report, stdout) in &reports {
        assert_completed_without_collision(tag, report, stdout);
        let recovery = &report["recovery"];
        assert!(
            recovery["turns"].as_u64().unwrap() >= 1,
            "{tag}: {recovery}"
        );
        assert!(
            recovery["turn_legs"].as_u64().unwrap() >= 2,
            "{tag}: {recovery}"
        );
        assert!(
            recovery["turned_deg"].as_f64().unwrap() >= 90.0,
            "{tag}: {recovery}"
        );
    }
}

/// 004's own shape (issue 68): an L-shaped body (the HMMWV's rectangle
/// with its front right quarter cut away; the 64-beam lidar at 5 m/s)
/// and a round one (the ERIM, the defaults) drive the narrow cul-de-sac
/// out, turning round in legs forwards and backing (the outline
/// mirrored), with the ground truth and every sweep on the shape. The L
/// was stuck there while near-miss bands grew a polygon at its front and
/// rear too (every leg of its turn kept half a metre more from the end).
#[test]
fn bodies_of_their_own_shape_turn_round_in_a_narrow_cul_de_sac() {
    let dir = arcnav_testkit::temp_dir("shapes");
    let shape = |name: &str, text: &str| {
        let file = dir.join(format!("{name}.toml"));
        std::fs::write(&file, text).unwrap();
        let world = format!(
            "{}/tests/worlds/cul_de_sac_narrow.toml",
            env!("CARGO_MANIFEST_DIR")
        );
        let args = [
            "--world",
            &world,
            "--config",
            file.to_str().unwrap(),
            "--no-images",
        ];
        (name.to_string(), args.map(String::from).to_vec())
    };
    let runs = [
        shape(
            "ell",
            "[vehicle]\nfootprint = \"polygon\"\n\
             vertices_m = [[-0.6, -1.1], [2.0, -1.1], [2.0, 0.0], [4.0, 0.0], [4.0, 1.1], [-0.6, 1.1]]\n\
             [sensor]\npreset = \"lidar64\"\n[arbiter]\ncruise_speed_mps = 5.0\n",
        ),
        shape(
            "round",
            "[vehicle]\nfootprint = \"circle\"\nradius_m = 1.5\ncentre_m = [1.5, 0.0]\nwheelbase_m = 2.0\n",
        ),
    ];
    for (tag, report, stdout) in &missions("shape", &runs) {
        assert_completed_without_collision(tag, report, stdout);
        let recovery = &report["recovery"];
        assert!(
            recovery["turns"].as_u64().unwrap() >= 1,
            "{tag}: {recovery}"
        );
    }
}

/// Issue 68: the skid-steer preset (`config/skid_steer.toml`, a
/// Warthog-class vehicle on the HMMWV's arcs) drives paper_loop,
/// short_course and the cul-de-sacs without a collision, and turns round
/// in place where the HMMWV makes a K-point turn (the narrow cul-de-sac:
/// `narrow_cul_de_sacs_are_left_by_turning_round`): in no legs, its
/// commands `drive_command_t` with the yaw rate, and in its log the
/// heading swings through more than 90° while the point it turns about
/// moves less than 0.3 m.
#[test]
fn the_skid_steer_preset_turns_round_in_place_where_the_hmmwv_makes_a_k_point_turn() {
    let root = env!("CARGO_MANIFEST_DIR");
    let preset = format!("{root}/config/skid_steer.toml");
    // The longest first: two at a time, the dead ends beside it.
    let worlds = [
        ("paper_loop", "paper_loop".to_owned()),
        (
            "cul_de_sac_narrow",
            format!("{root}/tests/worlds/cul_de_sac_narrow.toml"),
        ),
        (
            "lane_dead_end",
            format!("{root}/tests/worlds/lane_dead_end.toml"),
        ),
        ("cul_de_sac", format!("{root}/tests/worlds/cul_de_sac.toml")),
        ("short_course", "short_course".to_owned()),
    ];
    let runs: Vec<(&str, Vec<String>)> = worlds
        .iter()
        .map(|(tag, world)| {
            let mut args = vec!["--world", world, "--config", &preset];
            // One log keeps its images, to be replayed.
            if *tag != "cul_de_sac_narrow" {
                args.push("--no-images");
            }
            (*tag, args.into_iter().map(String::from).collect())
        })
        .collect();
    let runs = missions_kept("skid", &runs);
    for (tag, out, report, stdout) in &runs {
        assert_completed_without_collision(tag, report, stdout);
        if !tag.contains("cul_de_sac") && *tag != "lane_dead_end" {
            continue;
        }
        let recovery = &report["recovery"];
        assert!(
            recovery["turns_in_place"].as_u64().unwrap() >= 1
                && recovery["turn_legs"].as_u64().unwrap() == 0,
            "{tag}: {recovery}"
        );
        // From the log: the commands, and the heading swung standing.
        let (mut turning, mut poses) = (0, Vec::new());
        for event in TypedEvents::new(LogReader::open(out.join("mission.lcm")).unwrap()) {
            match event.unwrap().message {
                AnyMessage::SteeringCommand(_) => panic!("{tag}: a steering_command_t"),
                AnyMessage::DriveCommand(c) if c.curvature.is_infinite() => {
                    assert!(
                        c.speed == 0.0 && c.yaw_rate * c.curvature > 0.0,
                        "{tag}: {c:?}"
                    );
                    turning += 1;
                }
                AnyMessage::Pose(p) => {
                    let pose = arcnav_vehicle::Pose::try_from(&p).unwrap();
                    let (x, y, yaw) = (pose.position().x, pose.position().y, pose.yaw());
                    // The turn centre, half the 1 m wheelbase ahead.
                    poses.push((x + 0.5 * yaw.cos(), y + 0.5 * yaw.sin(), yaw));
                }
                _ => {}
            }
        }
        assert!(turning > 5, "{tag}: {turning} turns in place commanded");
        let mut swung: f64 = 0.0;
        for i in 0..poses.len() {
            let (mut turned, mut j) = (0.0f64, i + 1);
            while j < poses.len() && (poses[j].0 - poses[i].0).hypot(poses[j].1 - poses[i].1) < 0.3
            {
                turned += arcnav_vehicle::frames::wrap_angle(poses[j].2 - poses[j - 1].2);
                swung = swung.max(turned.abs());
                j += 1;
            }
        }
        assert!(
            swung.to_degrees() > 90.0,
            "{tag}: the heading swung at most {:.0}° standing",
            swung.to_degrees()
        );
        // The log replays to its own decisions, turns in place included.
        if *tag == "cul_de_sac_narrow" {
            let (log, config) = (out.join("mission.lcm"), out.join("config.toml"));
            let (code, stdout, stderr) = arcnav(&[
                "replay",
                log.to_str().unwrap(),
                "--config",
                config.to_str().unwrap(),
            ]);
            assert_eq!(code, 0, "{stderr}");
            assert!(stdout.contains("agree (100.00%)"), "{stdout}");
        }
    }
}

/// A ditch square across the way that a sensor flags only from near (the
/// 64-beam lidar: within about 8 m), its near end beyond the map's side.
/// The vehicle stops at it and turns round; the images it takes backing
/// away see the ditch from farther than it can be flagged from. Counted as
/// misses (002 §5 as written), they erased it, the route planned through
/// it, and the vehicle came back, turned round again and was stuck after
/// 130 s. With `localmap.miss_range_factor` those images count no miss:
/// both sensors complete at 2.5 m/s without a collision with every noise
/// seed (the defaults; as 002 §5 has it, a factor of 0, one miss to drop a
/// cell, no suspected drop-offs and no flagged ones kept
/// (`drop_off_trust_factor = 0`), it is stuck with some: drop-offs kept
/// until seen from within the hole range, suspected or flagged from near,
/// also see it through). Whether the vehicle happens to catch the ditch
/// again hangs on the noise, so both are asked over several seeds (as 002:
/// stuck with 2 of the 6, 2026-11-28). Since the route holds to one end
/// near a stop and a turn round goes the short way to the way ahead
/// (2026-11-29), the vehicle with 002's map gets round too (seeds 5, 6, 1
/// completed, with `hold_fraction = 0` as well): the control now checks
/// only that such a map counts every miss.
#[test]
fn a_ditch_seen_only_from_near_is_not_forgotten_when_the_vehicle_backs_away() {
    let world = format!(
        "{}/tests/worlds/ditch_across.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    // 002 §5's map, and no suspected drop-offs (which only images from
    // within the hole range may drop).
    let as_002 = "[localmap]\nmiss_range_factor = 0\nmisses_to_drop = 1\n\
                  drop_off_trust_factor = 0\n\
                  [perception.drop_off]\nsuspect_cost = 0\n";
    let args = ["--world", &world, "--no-images"];
    let runs = over_noise_seeds(
        "ditch",
        &[("lidar64", "lidar64", ""), ("erim", "erim", "")],
        &args,
    );
    for (tag, report, stdout) in runs.iter().flatten() {
        assert_completed_without_collision(tag, report, stdout);
        assert!(stdout.contains("misses not counted"), "{tag}:\n{stdout}");
    }
    for (tag, report, _) in &runs[0] {
        let lidar = &report["localmap"];
        assert!(
            lidar["seen_from_afar"].as_u64().unwrap() > 0,
            "{tag}: {lidar}"
        );
    }
    // Every overlapping image counting a miss (seed 5 was stuck so,
    // 2026-11-28): the first 45 s, up to the ditch and along it (with the
    // defaults, images from afar had left 16 486 misses uncounted by then).
    let configs = out_dir("ditch-as-002-configs");
    let config = configs.join("as-002.toml");
    std::fs::write(
        &config,
        format!("{as_002}[sim]\nseed = 5\ntime_limit_s = 45.0\n"),
    )
    .unwrap();
    let mut run = vec!["--sensor", "lidar64", "--config", config.to_str().unwrap()];
    run.extend(args);
    let run = [(
        "lidar64-as-002-seed5",
        run.into_iter().map(String::from).collect(),
    )];
    for (tag, report, stdout) in &missions("ditch", &run) {
        assert_eq!(report["localmap"]["seen_from_afar"], 0, "{tag}");
        assert!(
            report["localmap"]["reports"].as_u64().unwrap() > 400,
            "{tag}"
        );
        assert_no_collision(tag, report, stdout);
    }
}

/// A ditch square across the way whose ends lie out of sight, at 4.5 m/s
/// with the 64-beam lidar: it stops 8-10 m short of the ditch, where the
/// ditch is flagged in one frame and not in the next, and turns towards
/// the nearer end. Its images from 9-12 m, which did not happen to catch
/// the far wall, erased the flags; the route then planned across the
/// stretch they had left, wished for the other side's hardest arc, and
/// the K-turn went on for 12 legs, 380°, until stuck. A drop-off flagged
/// from within twice the hole range is now kept until an image from
/// within the hole range misses it (`localmap.drop_off_trust_factor`):
/// the vehicle completes with every noise seed, turning once and driving
/// round the end with all but one (as before: stuck with 1 of the 6;
/// which images catch the far wall hangs on the noise). With seed 3 it
/// comes back to the ditch after its first turn, loses the ditch's cells
/// from the map while turning in place, turns for 12 legs and then once
/// more before going round (2026-11-28): not fixed, hence "all but one".
///
/// Since 2026-11-29 a drop-off is suspected wherever the gap to the return
/// beyond may hide a hole wider than the wheels bridge (not only where the
/// ray alone ran that far below the edge): the ditch's edge straight ahead
/// is suspected in most frames, not in patches, and kept. Without the
/// trust factor (`drop_off_trust_factor = 0`), which had got stuck with
/// seed 1, the vehicle now completes with every seed too (measured, six
/// seeds, one recovery each); that control is no longer asserted.
#[test]
fn a_vehicle_turning_before_a_ditch_keeps_it_and_drives_round_its_end() {
    let world = format!(
        "{}/tests/worlds/ditch_ends_out_of_sight.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let args = ["--world", &world, "--speed", "4.5", "--no-images"];
    let runs = over_noise_seeds("ditch-ends", &[("now", "lidar64", "")], &args);
    for (tag, report, stdout) in &runs[0] {
        assert_completed_without_collision(tag, report, stdout);
    }
    let turned_once: Vec<&str> = runs[0]
        .iter()
        .filter(|(_, report, _)| report["recovery"]["turns"].as_u64().unwrap() <= 1)
        .map(|(tag, _, _)| tag.as_str())
        .collect();
    assert!(
        turned_once.len() + 1 >= runs[0].len(),
        "one turn towards the near end only with {turned_once:?}"
    );
}

/// `tests/worlds/ledge.toml` with the 64-beam lidar at `--speed 8` (held
/// to 5.28 m/s by the hole speed cap; at the default speed it goes round
/// the same way, 163 s of mission against 81 s, and is no longer driven
/// in every test run): a 2 m drop across the way, open 25 m to one side.
/// From afar the floor beyond the edge looks like a slope the vehicle may
/// drive; from within
/// 5 m, where it would show as a drop, the edge lies in the lidar's blind
/// zone. So the edge is never flagged: the shadow beyond it stays unseen,
/// and the vehicle is held 2 m short of it. Counted passable at
/// `unseen_cost`, the shadow kept the route's path across it, and the
/// vehicle backed up and came back to the same edge until stuck (with
/// `shut_unseen_m = 0`, stuck after 100 s, 2026-12-07; no longer driven in
/// every test run). Shutting the unseen ground it backed away from, and
/// the shadow along the edge, the route leads it round.
#[test]
fn held_short_of_a_ledge_s_shadow_the_vehicle_goes_round_the_ledge() {
    let world = format!("{}/tests/worlds/ledge.toml", env!("CARGO_MANIFEST_DIR"));
    let args = [
        "--world",
        &world,
        "--sensor",
        "lidar64",
        "--speed",
        "8",
        "--no-images",
    ];
    let runs = [("lidar64-8", args.map(String::from).to_vec())];
    let (tag, report, stdout) = &missions("ledge-shut", &runs)[0];
    assert_completed_without_collision(tag, report, stdout);
    assert!(
        report["behaviour_counters"]["route"]["shut_cells"]
            .as_u64()
            .unwrap()
            > 0,
        "{tag}: unseen ground was shut:\n{stdout}"
    );
}

/// The same ledge with the ERIM, over the noise seeds, and the ledge open
/// to the other side (`ledge_north`): the route shut the shadow along the
/// edge but left gaps in the band. Where its 1 m cells were seen at their
/// centres and not wholly (ledge, seed 1; with the noise drawn by
/// Box-Muller, seeds 4-6), or an image saw a strip one cell wide right
/// through the shadow (ledge_north, seed 2), the path went through the
/// gap; obstacle avoidance, looking at the unseen ground beside it, held
/// the vehicle short of it, and it backed away and came back until stuck.
/// Partly seen cells between shut ones are shut too, and a cell between
/// shut ones is impassable: every seed goes round.
#[test]
fn the_erim_goes_round_a_ledge_through_no_gap_in_its_shut_shadow() {
    let world = |name: &str| format!("{}/tests/worlds/{name}.toml", env!("CARGO_MANIFEST_DIR"));
    for name in ["ledge", "ledge_north"] {
        let runs = over_noise_seeds(
            &format!("{name}-erim"),
            &[("erim", "erim", "")],
            &["--world", &world(name), "--no-images"],
        );
        for (tag, report, stdout) in &runs[0] {
            assert_completed_without_collision(tag, report, stdout);
        }
    }
}

/// 020 at speed: a 0.9 m ditch square across the way. The 64-beam lidar
/// 2.4 m up flags it only within 8.4 m (the grazing ray's range, 3.95
/// m/s); from 15-20 m its rays dip 0.1-0.2 m into it, less than δ, and it
/// is a *suspected* drop-off: the vehicle slows for it to the speed at
/// which it stops once the ditch shows, then goes round, with every noise
/// seed. Without the suspicion (`suspect_cost = 0`) it learns of the ditch
/// 5-7 m short of it, and drives in (with each of the 6 seeds at 8 m/s,
/// measured; one is run here at 10, 9.05 m/s at most).
///
/// At `--speed 10`. Suspected only 15-19 m ahead, the ditch cannot stop a
/// vehicle at 9.5 m/s (0.75 s and 3 m/s² take 22 m): one noise seed of 6
/// drove in, and the others got round only because the route's swings had
/// slowed them first (2026-11-28). The cruise speed is now held to the
/// speed that stops within the range at which such a ditch is first
/// suspected (`[lookahead] hole_speed_cap`, 6.9 m/s then): each of seeds
/// 1-6 went round, 0.92-1.45 m from the ditch, at 6.5 m/s at most. Since
/// 2026-11-29 the range counts the rows' spacing against the dip (11.4 m,
/// 5.28 m/s; `at_speed_a_short_ditch_is_suspected_in_time_to_stop`).
/// Since issue 63 the cap is off: the speed governor lets the vehicle
/// drive faster than it wherever the ground ahead is verified over images
/// and slows it where it is not; with neither the suspicion nor the
/// verification it drives in.
#[test]
fn at_speed_a_ditch_suspected_from_afar_slows_the_vehicle_in_time() {
    let world = format!(
        "{}/tests/worlds/ditch_across.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let args = ["--world", &world, "--speed", "10", "--no-images"];
    let suspected = over_noise_seeds("suspect", &[("suspected", "lidar64", "")], &args);
    for (tag, report, stdout) in suspected.iter().flatten() {
        assert_completed_without_collision(tag, report, stdout);
        assert!(
            report["suspected_drop_offs"].as_u64().unwrap() > 0,
            "{tag}:\n{stdout}"
        );
        assert_governed_and_the_ditch_reported_in_time(tag, report, stdout);
    }
    // Neither suspected nor left unverified, the ditch is driven into.
    let configs = out_dir("suspect-unsuspected-config");
    let config = configs.join("config.toml");
    std::fs::write(
        &config,
        "[perception.drop_off]\nsuspect_cost = 0\n[perception.evidence]\nverify = false\n",
    )
    .unwrap();
    let mut unsuspected = vec!["--sensor", "lidar64", "--config", config.to_str().unwrap()];
    unsuspected.extend(args);
    let runs = [(
        "unsuspected",
        unsuspected.into_iter().map(String::from).collect(),
    )];
    for (tag, report, stdout) in &missions("suspect", &runs) {
        assert_eq!(report["outcome"], "collision", "{tag}:\n{stdout}");
        assert_eq!(report["suspected_drop_offs"], 0, "{tag}");
    }
}

/// 020 at speed, `ditch_across` with noise seed 5: held to 5.28 m/s, the
/// vehicle stopped 10 m short of the ditch, whose near end lies 12 m off
/// the line, out of sight. As each image showed a little more of the
/// ditch, the route's plan flipped between its two ends and crossings of
/// ground only suspected, at 10-20 % more or less; turning on the spot
/// towards each in turn (one turn round of 12 legs, 344°), the vehicle
/// went neither way and was stuck after 107 s. Near where it stood, the
/// route now holds to the path it follows while that costs at most
/// `hold_fraction` more than the plan: one short turn (2 legs, 50°) and
/// round the near end. With `hold_fraction = 0` the turn went the other
/// way when the way came to lie ahead there (468° in 16 legs); since the
/// route plans inside an operating area with obstacles seen only from
/// afar doubtful (issue 62), the plan no longer flips here and the vehicle
/// gets round without the hold too (64° in 3 legs, 2026-12-06), so that
/// run shows nothing the held one does not and is no longer driven: the
/// held run completes without a collision, holding and turning less than
/// 90°.
#[test]
fn at_speed_the_route_holds_to_one_end_of_a_ditch_across_the_way() {
    let world = format!(
        "{}/tests/worlds/ditch_across.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let args = ["--world", &world, "--speed", "10", "--no-images"];
    let configs = out_dir("hold-configs");
    let runs = [seeded(&configs, ("held", "lidar64", ""), &args, 5)];
    let done = missions("hold", &runs);
    let (tag, report, stdout) = &done[0];
    assert_completed_without_collision(tag, report, stdout);
    let route = &report["behaviour_counters"]["route"];
    assert!(route["held_cycles"].as_u64().unwrap() > 0, "{tag}: {route}");
    let turned = report["recovery"]["turned_deg"].as_f64().unwrap();
    assert!(turned < 90.0, "{tag}:\n{stdout}");
}

/// 020 at speed: a ditch too short to be seen from afar, square across
/// the route (`short_ditch`, 3 m long, 0.8 m wide). The 64-beam lidar
/// suspects it for certain only within 11.4 m: the row that lands first
/// past its near edge may land up to a row's spacing in and show only the
/// rest of the ditch's far wall, so the dip and the rows' spacing add up
/// (`(Δ + δθ)·R² + noise_m·R = w·H`). Taking the smaller of the two
/// instead (15.9 m, a cap of 6.89 m/s), the vehicle drove in at
/// `--speed 10` with noise seeds 2, 3 and 6 of 6; held to 5.28 m/s it
/// stops or goes round with every seed (2026-11-29: 0.09-0.40 m from the
/// ditch as it passes its end slowly). Without the cap it drove in (seeds
/// 1, 3, 4 and 5 of 6) until the hole evidence over images
/// (`[perception.evidence]`, issue 63): the rows of a moving sensor never
/// land in the ditch while they sweep the ground around it, and it is
/// suspected from 16 m and more, where one image cannot show it; uncapped
/// at 10 m/s the vehicle now stops or goes round.
#[test]
fn at_speed_a_short_ditch_is_suspected_in_time_to_stop() {
    let world = format!(
        "{}/tests/worlds/short_ditch.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let args = ["--world", &world, "--speed", "10", "--no-images"];
    // Held to the cap, ditch_across's test shows the cap at work
    // (`at_speed_a_ditch_suspected_from_afar_slows_the_vehicle_in_time`).
    let runs = over_noise_seeds(
        "short-ditch",
        &[(
            "uncapped",
            "lidar64",
            "[lookahead]\nhole_speed_cap = false\n",
        )],
        &args,
    );
    for (tag, report, stdout) in &runs[0] {
        assert_completed_without_collision(tag, report, stdout);
        // One image is certain to suspect it only within 11.4 m.
        let range = report["speed_bound"]["suspect_range_m"].as_f64().unwrap();
        assert!((11.0..12.0).contains(&range), "{tag}: {range} m");
        let drops = report["drops_first_seen"].as_array().unwrap();
        let first = drops[0]["first_range_m"].as_f64().unwrap();
        assert!(first >= 16.0, "{tag}: first reported {first} m away");
        assert!(report["evidence_suspected"].as_u64().unwrap() > 0, "{tag}");
    }
}

/// 017, narrower still: a dead-end lane with 5.7 m of floor, where no
/// K-point turn gets the vehicle round. It backs out the way it came (at
/// least 20 m of the 30 m lane, both sensors), turns once out, and
/// completes without a collision, keeping at least 0.3 m off the banks'
/// sides, with every noise seed. The ERIM's K-turns before backing out
/// brought a corner 0.20-0.30 m from a side with 3 of the 6 seeds while a
/// leg creeping forwards kept no room beside the body; it now keeps the
/// near-miss band within `reverse_margin_m`, as backing up keeps that
/// margin (0.57-0.63 m, 2026-11-28).
#[test]
fn a_dead_end_lane_too_narrow_to_turn_in_is_left_backing_out_the_way_it_came() {
    let world = format!(
        "{}/tests/worlds/lane_dead_end.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let runs = over_noise_seeds(
        "lane",
        &[("erim", "erim", ""), ("lidar64", "lidar64", "")],
        &["--world", &world, "--no-images"],
    );
    for (tag, report, stdout) in runs.iter().flatten() {
        assert_completed_without_collision(tag, report, stdout);
        let recovery = &report["recovery"];
        assert!(
            recovery["retraces"].as_u64().unwrap() >= 1
                && recovery["retraced_m"].as_f64().unwrap() >= 20.0,
            "{tag}: {recovery}"
        );
        let closest = report["closest_approach_m"].as_f64().unwrap();
        assert!(closest >= 0.3, "{tag}: {closest} m from a bank's side");
    }
}

/// 020 item 2: at speed, arcs judged along the paths the vehicle drives
/// onto them (`[arcs] driven_paths`), the 64-beam lidar looking as far as
/// the speed needs. Judged along the arcs, the vehicle drove into the 1 m
/// ditch of `drop_offs` at 10 m/s cruise and into a 0.6 m boulder of
/// `short_course` at 9 m/s (measured, one collision each; 0.12 m from a
/// boulder at 8 m/s): a hard turn judged clear begins, at these speeds,
/// 2.3-2.5 m of latency and up to 8 m of steering later than its arc. Along
/// the driven paths both complete with every noise seed, keeping at least
/// half a metre from every hazard (2026-11-28: 1.62-2.08 m on drop_offs,
/// 0.74-1.24 m on short_course, where one seed had given 1.50 m).
#[test]
fn at_speed_arcs_judged_along_driven_paths_keep_clear_of_ditches_and_boulders() {
    // At the speed asked for: the hole speed cap would hold it to 5.3 m/s.
    let driven =
        "[arcs]\ndriven_paths = true\n[lookahead]\nfrom_speed = true\nhole_speed_cap = false\n";
    let at = |world: &str, speed: &str| {
        over_noise_seeds(
            &format!("driven-{world}"),
            &[("lidar64", "lidar64", driven)],
            &["--world", world, "--speed", speed, "--no-images"],
        )
    };
    for (world, reports) in [
        ("drop_offs", at("drop_offs", "10")),
        ("short_course", at("short_course", "9")),
    ] {
        for (tag, report, stdout) in reports.iter().flatten() {
            assert_completed_without_collision(tag, report, stdout);
            let closest = report["closest_approach_m"].as_f64().unwrap();
            assert!(
                closest >= 0.5,
                "{world} {tag}: {closest} m from a hazard:\n{stdout}"
            );
        }
    }
}

/// 020 item 1: a faster vehicle looks farther. With the 18 m of arc and
/// the 20 m window of 002 §5, obstacle avoidance's stopping-distance vote
/// caps every sensor at 5.9 m/s; with the lookahead from speed
/// (`lookahead.from_speed`, on by default since 020) the 64-beam lidar at 10 m/s
/// cruise drives faster than that, still without a collision, and the
/// report says what set the speed. Faster than one image shows a hole in
/// time, the speed governor slows where the ground is not verified (said
/// before the run); with `hole_speed_cap` asked for, the cruise speed is
/// held to the speed that stops where one image first suspects a ditch
/// (5.61 m/s).
#[test]
fn a_faster_vehicle_looks_farther_and_drives_faster_than_the_20_m_window_allows() {
    let run = |tag: &str, config: &str| -> Value {
        let out = out_dir(tag);
        let file = out.with_extension("toml");
        std::fs::write(&file, config).unwrap();
        let args = [
            "sim",
            "--config",
            file.to_str().unwrap(),
            "--world",
            "short_course",
            "--sensor",
            "lidar64",
            "--speed",
            "10",
            "--no-images",
            "--out",
            out.to_str().unwrap(),
        ];
        let (code, stdout, stderr) = arcnav(&args);
        assert_eq!(
            code, 0,
            "{tag}: completes without a collision:\n{stdout}\n{stderr}"
        );
        assert!(
            stdout.contains("holes the wheels do not bridge are flagged for certain within 6.9 m"),
            "{stdout}"
        );
        assert!(
            stdout.contains("and first suspected within 11.4 m"),
            "{stdout}"
        );
        // 10 m/s is beyond what one image shows of a ditch in time: the
        // governor slows where the ground is not verified, or, with the
        // cap asked for, the cruise is held to it; said before the run.
        let held = config.contains("hole_speed_cap = true");
        assert_eq!(
            stderr.contains("the speed governor slows wherever the ground ahead is not verified"),
            !held,
            "{stderr}"
        );
        assert_eq!(stderr.contains("note: cruise held to "), held, "{stderr}");
        assert_eq!(
            stdout.contains("held from 10.00 by [lookahead] hole_speed_cap"),
            held,
            "{stdout}"
        );
        let report: Value = read_report(&out);
        let _ = std::fs::remove_file(&file);
        report
    };
    let uncapped = "";
    let fixed = run(
        "window-fixed",
        &format!("[lookahead]\nfrom_speed = false\n{uncapped}"),
    );
    let max = |r: &Value| r["max_speed_mps"].as_f64().unwrap();
    assert!(
        max(&fixed) <= 5.95,
        "the 18 m arcs cap the speed vote at 5.9 m/s: {}",
        max(&fixed)
    );
    let looking = run(
        "window-from-speed",
        &format!("[lookahead]\nfrom_speed = true\n{uncapped}"),
    );
    // Looking as far along the arcs as 10 m/s needs, not 18 m: 7.25 m/s at
    // most, 4.69 on average against 5.41 and 3.37 (2026-11-29).
    assert!(
        max(&looking) > 6.2,
        "looking farther along the arcs lets it go faster: {}",
        max(&looking)
    );
    assert!(
        looking["average_speed_mps"].as_f64().unwrap()
            > fixed["average_speed_mps"].as_f64().unwrap(),
        "and faster on average"
    );
    // Asked for (`[lookahead] hole_speed_cap`), no faster than the speed
    // from which it stops short of a ditch first suspected: said before
    // the run and in the report.
    let looking = run(
        "window-held",
        "[lookahead]\nfrom_speed = true\nhole_speed_cap = true\n",
    );
    let cap = looking["speed_bound"]["suspect_bound_mps"]
        .as_f64()
        .unwrap();
    assert_eq!(looking["cruise_mps"].as_f64(), Some(cap));
    assert_eq!(looking["cruise_asked_mps"].as_f64(), Some(10.0));
    assert_eq!(looking["cruise_cap_mps"].as_f64(), Some(cap));
    assert!(max(&looking) <= cap + 0.05, "{} > {cap}", max(&looking));
    // Every second driven is put down to the limit that set the speed.
    let limited: f64 = looking["speed_limited_by_s"]
        .as_object()
        .unwrap()
        .values()
        .map(|s| s.as_f64().unwrap())
        .sum();
    let duration = looking["duration_s"].as_f64().unwrap();
    let stopped: f64 = looking["stops"]["stopped_s"]
        .as_object()
        .unwrap()
        .values()
        .map(|s| s.as_f64().unwrap())
        .sum();
    assert!(
        (limited + stopped - duration).abs() < 0.5,
        "{limited} s limited + {stopped} s stopped vs {duration} s"
    );
}

/// 020 item 3: with `[sim] slice_lines` each range image is sent in
/// slices as the sensor acquires them (a lidar's blocks of columns, the
/// ERIM's blocks of rows, each rendered where the vehicle is) and
/// perception judges each as it arrives; with the 20 ms of processing that
/// leaves (no frame's acquisition to wait for) missions complete at speed.
#[test]
fn missions_complete_with_images_streamed_in_slices() {
    let configs = out_dir("sliced-config");
    let config = configs.join("sliced.toml");
    std::fs::write(
        &config,
        "[pipeline]\nperception_latency_s = 0.02\n[sim]\nslice_lines = 16\n",
    )
    .unwrap();
    let erim = configs.join("sliced-erim.toml");
    std::fs::write(
        &erim,
        "[pipeline]\nperception_latency_s = 0.05\n[sim]\nslice_lines = 4\n",
    )
    .unwrap();
    let run = |tag, config: &Path, sensor: &str, speed: &str| {
        let args = [
            "--config",
            config.to_str().unwrap(),
            "--world",
            "short_course",
            "--sensor",
            sensor,
            "--speed",
            speed,
            "--no-images",
        ];
        (tag, args.map(String::from).to_vec())
    };
    let runs = [
        // Below the speeds from which the governor verifies ground over
        // images (5.6 and 4.2 m/s): slicing is what is driven here.
        run("lidar64-5.5", &config, "lidar64", "5.5"),
        run("erim-4", &erim, "erim", "4"),
    ];
    for (tag, report, stdout) in &missions("sliced", &runs) {
        assert_completed_without_collision(tag, report, stdout);
        let closest = report["closest_approach_m"].as_f64().unwrap();
        assert!(
            closest >= 0.3,
            "{tag}: {closest} m from a hazard:\n{stdout}"
        );
        let slices = &report["slices"];
        assert!(
            slices["received"].as_u64().unwrap() > 1000,
            "{tag}: {slices}"
        );
        assert_eq!(slices["stream"]["lost_lines"], 0, "{tag}: {slices}");
        assert!(
            slices["stream"]["steps"].as_u64().unwrap() > 100,
            "{tag}: judged in parts as slices came: {slices}"
        );
        assert!(stdout.contains("streamed      "), "{tag}:\n{stdout}");
    }
}

/// Issue 65: the guard is a second path beside the pipeline. With obstacle
/// avoidance out of the vote (the fault: its weight 0, not required), the
/// route alone drives into a tree on `forest`; the guard stops the vehicle
/// short of it and says why, and without the guard the same mission
/// collides.
#[test]
fn the_guard_stops_a_faulty_pipeline_short_of_the_tree_it_would_hit() {
    let world = arcnav_testkit::workspace_root().join("tests/worlds/forest.toml");
    let fault = "[arbiter]\nrequired = []\n[arbiter.weights]\nobstacle_avoidance = 0.0\n\
                 [sim]\nstuck_after_s = 20.0\n";
    let run = |tag: &str, extra: &str| {
        let out = out_dir(tag);
        let config = out.join("fault.toml");
        std::fs::write(&config, format!("{fault}{extra}")).unwrap();
        let (code, stdout, stderr) = arcnav(&[
            "sim",
            "--world",
            world.to_str().unwrap(),
            "--config",
            config.to_str().unwrap(),
            "--no-images",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert_ne!(
            code, 0,
            "{tag}: a faulty pipeline cannot complete:\n{stdout}"
        );
        (read_report(&out), stdout, stderr)
    };
    let (guarded, unguarded) = std::thread::scope(|scope| {
        let guarded = scope.spawn(|| run("guard-on", ""));
        let unguarded = scope.spawn(|| run("guard-off", "[guard]\nenabled = false\n"));
        (guarded.join().unwrap(), unguarded.join().unwrap())
    });
    let (report, stdout, stderr) = guarded;
    assert_no_collision("guard-on", &report, &stdout);
    let guard = &report["guard"];
    assert!(
        guard["stops"].as_u64().unwrap() >= 1,
        "{guard}\n{stdout}{stderr}"
    );
    assert!(
        guard["by_reason"]["obstacle"].as_u64().unwrap() >= 1,
        "{guard}"
    );
    let first = &guard["first"][0];
    assert_eq!(first["verdict"], "stop", "{guard}");
    assert!(
        first["reason"].as_str().unwrap().starts_with("obstacle"),
        "{guard}"
    );
    assert!(
        stdout.contains("guard "),
        "the summary says what the guard did:\n{stdout}"
    );
    let (report, stdout, _) = unguarded;
    assert_eq!(report["outcome"], "collision", "guard-off:\n{stdout}");
    assert!(
        report.get("guard").is_none_or(Value::is_null),
        "{}",
        report["guard"]
    );
}

/// Issue 62. A barrier across the whole map with one crossing out of sight
/// (60 m left of the line): the vehicle meets it, searches one way, turns
/// back where that side ends at the operating area's edge (the map less
/// `mission.area_margin_m`) and crosses where the crossing is — completed,
/// no collision (leaving the area is one). A waypoint on an island closed
/// by a trench ends the mission `unreachable` (exit status 4) within 300 s
/// of the start, its report naming the waypoint and the ring; with
/// `on_unreachable = "skip"` the mission goes on and reaches the next.
/// Without the area the vehicle left the map; without the unreachable
/// model it circled the island until the time limit.
#[test]
fn a_barrier_is_searched_inside_the_area_and_a_closed_island_is_unreachable() {
    let world = |name: &str| {
        format!(
            "{}/tests/worlds/barriers/{name}.toml",
            env!("CARGO_MANIFEST_DIR")
        )
    };
    let configs = out_dir("barriers-config");
    let skip = configs.join("skip.toml");
    std::fs::write(&skip, "[mission]\non_unreachable = \"skip\"\n").unwrap();
    let runs: Vec<(&str, Vec<String>)> = vec![
        ("trench", vec!["--world".into(), world("trench_left_far")]),
        ("island", vec!["--world".into(), world("ring_trench")]),
        (
            "skip",
            vec![
                "--world".into(),
                world("ring_skip"),
                "--config".into(),
                skip.to_str().unwrap().into(),
            ],
        ),
    ];
    let reports = missions("barriers", &runs);
    let (tag, trench, stdout) = &reports[0];
    assert_completed_without_collision(tag, trench, stdout);
    let area = trench["area"]
        .as_array()
        .expect("the world's area is reported");
    assert_eq!(area.len(), 4, "the map less its margin: {area:?}");
    assert!(
        trench["distance_m"].as_f64().unwrap() > 200.0,
        "the crossing lay out of sight, off the first side searched: {stdout}"
    );

    let (tag, island, stdout) = &reports[1];
    assert_eq!(island["outcome"], "unreachable", "{tag}:\n{stdout}");
    assert_no_collision(tag, island, stdout);
    let given_up = &island["unreachable"][0];
    assert_eq!(given_up["waypoint"], 1, "{given_up}");
    assert!(given_up["ring_cells"].as_u64().unwrap() > 20, "{given_up}");
    assert!(
        given_up["given_up_at_s"].as_f64().unwrap() <= 300.0,
        "{given_up}"
    );
    assert!(stdout.contains("unreachable   waypoint 1"), "{stdout}");

    let (tag, skipped, stdout) = &reports[2];
    assert_completed_without_collision(tag, skipped, stdout);
    assert_eq!(skipped["waypoints_skipped"], 1, "{stdout}");
    assert_eq!(skipped["waypoints_reached"], 1, "{stdout}");
    assert_eq!(skipped["unreachable"][0]["skipped"], true, "{stdout}");

    // The exit status tells an unreachable waypoint from a failure.
    let out = out_dir("barriers-exit");
    let (code, _, _) = arcnav(&[
        "sim",
        "--world",
        &world("ring_boulders"),
        "--no-images",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 4, "unreachable exits 4");
}
