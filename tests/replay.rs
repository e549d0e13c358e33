//! `arcnav replay` and `arcnav render`: reproduction, determinism,
//! comparison, and damaged input.

use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};

use arcnav::Config;
use arcnav::mission::{MissionOptions, run_mission};
use arcnav::replay::{ReplayOptions, ReplayResult, compare, replay};
use arcnav_bus::log::{LogReader, LogWriter};
use arcnav_perception::SensorPreset;
use arcnav_sim::World;
use serde_json::Value;

/// The directory of files the tests of `tag` write: under the target
/// directory, the same each run (so runs replace what the last one wrote
/// rather than leave a gigabyte of logs in the system's temporary
/// directory each time).
fn dir(tag: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("replay-{tag}"));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `path` replayed with the default configuration and behaviours.
fn replay_with_defaults(path: &Path) -> ReplayResult {
    replay(
        path,
        &Config::default().resolved().unwrap(),
        &ReplayOptions::default(),
        &mut |_| {},
    )
    .unwrap()
}

/// A log of the short course, made once for this build of the tests
/// (shared by their processes: [`arcnav_testkit::shared_file`]).
fn sim_log() -> &'static Path {
    static LOG: OnceLock<PathBuf> = OnceLock::new();
    LOG.get_or_init(|| {
        arcnav_testkit::shared_file("short_course.lcm", |path| {
            let world = Arc::new(World::embedded("short_course").unwrap().unwrap());
            let options = MissionOptions {
                log: Some(path.to_owned()),
                ..MissionOptions::default()
            };
            let run = run_mission(
                &Config::default().resolved().unwrap(),
                world,
                &options,
                &mut |_| {},
            )
            .unwrap();
            assert!(run.report.success);
        })
    })
}

fn arcnav(args: &[&str]) -> (i32, String, String) {
    arcnav_testkit::output_of(env!("CARGO_BIN_EXE_arcnav"), args)
}

/// Rewrites a log, keeping the events `keep` accepts.
fn filtered(source: &Path, target: &Path, keep: impl Fn(&str, i64) -> bool) {
    let mut writer = LogWriter::create(target).unwrap();
    for event in LogReader::open(source).unwrap() {
        let event = event.unwrap();
        if keep(&event.channel, event.timestamp) {
            writer
                .write_event(event.timestamp, &event.channel, &event.data)
                .unwrap();
        }
    }
}

#[test]
fn replaying_a_sim_log_reproduces_the_sims_own_commands_exactly() {
    let result = replay_with_defaults(sim_log());
    assert!(result.recorded.len() > 500);
    let same = |name: &str| Config::default().arbiter.weight(name);
    let comparison = compare(
        ("recorded", "replayed"),
        &result.recorded,
        &result.cycles,
        (&same, &same),
        0,
    );
    assert_eq!(comparison.compared, result.recorded.len());
    assert_eq!(
        comparison.agreement_percent,
        Some(100.0),
        "{:?}",
        comparison.first_divergence
    );
    assert!(
        !result.problems.lost_input(),
        "{:?}",
        result.problems.lines()
    );
}

#[test]
fn the_same_log_and_configuration_give_byte_identical_output_logs() {
    let out = dir("determinism");
    let (a, b) = (out.join("a.lcm"), out.join("b.lcm"));
    for target in [&a, &b] {
        let (code, stdout, stderr) = arcnav(&[
            "replay",
            sim_log().to_str().unwrap(),
            "--out",
            target.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "{stdout}{stderr}");
        assert!(stdout.contains("(100.00%)"), "{stdout}");
    }
    let (la, lb) = (std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    assert!(la.len() > 1_000_000);
    assert!(la == lb, "two replays of the same log differ");
    // The output holds the inputs and the recomputed outputs.
    let channels: std::collections::BTreeSet<String> = LogReader::open(&a)
        .unwrap()
        .map(|e| e.unwrap().channel)
        .collect();
    for channel in [
        "POSE",
        "RANGE_IMAGE_ERIM",
        "WAYPOINTS",
        "OBSTACLE_CELLS",
        "ARC_VOTES_OBSTACLE_AVOIDANCE",
        "ARC_VOTES_GOAL_SEEKING",
        "STEERING_COMMAND",
        "DECISION",
    ] {
        assert!(
            channels.contains(channel),
            "{channel} missing from {channels:?}"
        );
    }
}

#[test]
fn a_one_weight_change_produces_a_comparison_naming_the_behaviour() {
    let out = dir("compare");
    let (a, b, json) = (
        out.join("a.toml"),
        out.join("b.toml"),
        out.join("comparison.json"),
    );
    std::fs::write(&a, "[arbiter.weights]\ngoal_seeking = 0.5\n").unwrap();
    std::fs::write(&b, "[arbiter.weights]\ngoal_seeking = 2.0\n").unwrap();
    let (code, stdout, stderr) = arcnav(&[
        "replay",
        sim_log().to_str().unwrap(),
        "--compare-config",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "--json",
        json.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stdout}{stderr}");
    assert!(stdout.contains("first divergence at"), "{stdout}");
    assert!(stdout.contains("moved by goal_seeking"), "{stdout}");
    let report: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    let comparison = &report["comparisons"][0];
    assert!(comparison["agreement_percent"].as_f64().unwrap() < 100.0);
    let differences = comparison["differences"].as_array().unwrap();
    let by_goal = differences
        .iter()
        .filter(|d| d["moved_by"] == "goal_seeking")
        .count();
    assert!(
        by_goal * 2 > differences.len(),
        "{by_goal} of {} differences attributed to goal_seeking",
        differences.len()
    );
    assert!(
        comparison["largest_curvature_difference"]["time_s"]
            .as_f64()
            .is_some()
    );
}

#[test]
fn a_log_truncated_mid_event_replays_and_reports_the_loss() {
    let out = dir("truncated");
    let bytes = std::fs::read(sim_log()).unwrap();
    let cut = out.join("cut.lcm");
    std::fs::write(&cut, &bytes[..bytes.len() - 3000]).unwrap();
    let (code, stdout, _) = arcnav(&["replay", cut.to_str().unwrap()]);
    assert_eq!(code, 3, "input was lost: {stdout}");
    assert!(stdout.contains("log ends mid-event"), "{stdout}");
    assert!(
        stdout.contains("decisions"),
        "the rest was replayed: {stdout}"
    );
}

#[test]
fn a_corrupted_region_is_skipped_and_the_replay_goes_on() {
    let out = dir("corrupt");
    let mut bytes = std::fs::read(sim_log()).unwrap();
    // Longer than any event (a range image is 64 KB), so headers are hit.
    let middle = bytes.len() / 2;
    for b in &mut bytes[middle..middle + 200_000] {
        *b = 0x5a;
    }
    let damaged = out.join("damaged.lcm");
    std::fs::write(&damaged, &bytes).unwrap();
    let result = replay_with_defaults(&damaged);
    assert!(
        result.problems.log.skipped_bytes > 100_000,
        "{:?}",
        result.problems.log
    );
    let whole = replay_with_defaults(sim_log());
    let last = |r: &arcnav::replay::ReplayResult| *r.cycles.keys().last().unwrap();
    assert_eq!(
        last(&result),
        last(&whole),
        "decisions continue after the damage to the end"
    );
    assert!(result.problems.lost_input());
    let (code, stdout, _) = arcnav(&["replay", damaged.to_str().unwrap()]);
    assert_eq!(code, 3);
    assert!(stdout.contains("bytes of damaged log skipped"), "{stdout}");
}

#[test]
fn images_in_a_hole_of_the_pose_stream_are_skipped_with_a_counted_reason() {
    let out = dir("pose-gap");
    let first = LogReader::open(sim_log())
        .unwrap()
        .next()
        .unwrap()
        .unwrap()
        .timestamp;
    let holed = out.join("holed.lcm");
    let (from, to) = (first + 20_000_000, first + 23_000_000);
    filtered(sim_log(), &holed, |channel, t| {
        !(channel == "POSE" && (from..to).contains(&t))
    });
    let result = replay_with_defaults(&holed);
    assert!(
        (5..=7).contains(&result.problems.images_without_pose),
        "the 6 images of the 3 s hole: {}",
        result.problems.images_without_pose
    );
    let (code, stdout, _) = arcnav(&["replay", holed.to_str().unwrap()]);
    assert_eq!(code, 3);
    assert!(
        stdout.contains("image(s) skipped: no pose around the capture time"),
        "{stdout}"
    );
}

#[test]
fn foreign_channels_are_skipped_and_listed_without_counting_as_loss() {
    let out = dir("foreign");
    let mixed = out.join("mixed.lcm");
    let mut writer = LogWriter::create(&mixed).unwrap();
    writer
        .write_event(0, "LCM_SELF_TEST", b"lcm self test")
        .unwrap();
    for (k, event) in LogReader::open(sim_log()).unwrap().enumerate() {
        let event = event.unwrap();
        writer
            .write_event(event.timestamp, &event.channel, &event.data)
            .unwrap();
        if k % 100 == 0 {
            writer
                .write_event(
                    event.timestamp,
                    "CAMERA_JPEG",
                    b"\xff\xd8 not an arcnav type",
                )
                .unwrap();
        }
    }
    drop(writer);
    let result = replay_with_defaults(&mixed);
    assert_eq!(result.problems.unknown_channels["LCM_SELF_TEST"], 1);
    assert!(result.problems.unknown_channels["CAMERA_JPEG"] > 10);
    assert!(!result.problems.lost_input());
    let (code, stdout, _) = arcnav(&["replay", mixed.to_str().unwrap()]);
    assert_eq!(code, 0, "{stdout}");
    assert!(
        stdout.contains("message(s) of an unknown type on CAMERA_JPEG (skipped)"),
        "{stdout}"
    );
}

#[test]
fn out_of_order_images_are_handled() {
    let out = dir("order");
    // Swap every other pair of RANGE_IMAGE events: the older one arrives late.
    let events: Vec<_> = LogReader::open(sim_log())
        .unwrap()
        .map(Result::unwrap)
        .collect();
    let images: Vec<usize> = events
        .iter()
        .enumerate()
        .filter(|(_, e)| e.channel == "RANGE_IMAGE_ERIM")
        .map(|(i, _)| i)
        .collect();
    let mut order: Vec<usize> = (0..events.len()).collect();
    for pair in images.chunks_exact(2).step_by(2) {
        order.swap(pair[0], pair[1]);
    }
    let shuffled = out.join("shuffled.lcm");
    let mut writer = LogWriter::create(&shuffled).unwrap();
    // Logged when they arrived: the log stays in time order, the images'
    // capture times do not.
    for (at, i) in order.into_iter().enumerate() {
        writer
            .write_event(events[at].timestamp, &events[i].channel, &events[i].data)
            .unwrap();
    }
    drop(writer);
    let result = replay_with_defaults(&shuffled);
    assert!(
        result.problems.images_out_of_order > 10,
        "{:?}",
        result.problems.images_out_of_order
    );
    assert!(result.cycles.len() > 500, "the replay went on");
}

#[test]
fn render_draws_a_decision_and_refuses_a_time_past_the_log() {
    let out = dir("render");
    let png = out.join("decision.png");
    let (code, stdout, stderr) = arcnav(&[
        "render",
        sim_log().to_str().unwrap(),
        "--at",
        "12.5",
        "--out",
        png.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stdout}{stderr}");
    assert!(stdout.contains("decision at 12.50 s"), "{stdout}");
    assert_eq!(&std::fs::read(&png).unwrap()[1..4], b"PNG");
    let (code, _, stderr) = arcnav(&["render", sim_log().to_str().unwrap(), "--at", "9999"]);
    assert_eq!(code, 1);
    assert!(
        stderr.contains("no decision at or after 9999 s"),
        "{stderr}"
    );
}

/// A log without range images (`arcnav sim --no-images`) is drawn from
/// its recorded cells, and says so: recomputed, its map would be empty and
/// every arc vetoed, a picture of nothing that happened.
#[test]
fn render_draws_a_log_without_images_from_its_recorded_cells() {
    let out = dir("render-no-images");
    let log = out.join("no-images.lcm");
    filtered(sim_log(), &log, |channel, _| {
        !channel.starts_with("RANGE_IMAGE")
    });
    let draw = |log: &Path, png: &str, extra: &[&str]| {
        let png = out.join(png);
        let mut args = vec![
            "render",
            log.to_str().unwrap(),
            "--at",
            "12.5",
            "--out",
            png.to_str().unwrap(),
        ];
        args.extend(extra);
        let (code, stdout, stderr) = arcnav(&args);
        assert_eq!(code, 0, "{stdout}{stderr}");
        (std::fs::read(&png).unwrap(), stderr)
    };
    let (auto, stderr) = draw(&log, "auto.png", &[]);
    assert!(
        stderr.contains("holds no range image") && stderr.contains("recorded OBSTACLE_CELLS"),
        "{stderr}"
    );
    assert!(!stderr.contains("nothing was perceived"), "{stderr}");
    let (asked, stderr) = draw(&log, "asked.png", &["--recorded-cells"]);
    assert!(!stderr.contains("holds no range image"), "{stderr}");
    assert!(auto == asked, "the same picture as --recorded-cells draws");
    // And the same as the log with its images drawn from its cells: the
    // map the vehicle drove on, not an empty one.
    let (with_images, _) = draw(sim_log(), "with-images.png", &["--recorded-cells"]);
    assert!(auto == with_images);
}

/// The decision a picture is drawn of comes with what the behaviours'
/// votes rested on: the route's planned path from the vehicle on, and the
/// point it steered for.
#[test]
fn the_kept_decision_carries_the_routes_path() {
    let result = replay(
        sim_log(),
        &Config::default().resolved().unwrap(),
        &ReplayOptions {
            stop_at_s: Some(12.5),
            ..ReplayOptions::default()
        },
        &mut |_| {},
    )
    .unwrap();
    let kept = result.kept.expect("a decision at 12.5 s");
    let route = &kept
        .overlays
        .iter()
        .find(|(name, _)| name == "route")
        .expect("the route shows its reasoning")
        .1;
    let path = &route.lines[0].points;
    assert!(path.len() > 10, "{path:?}");
    assert!(
        path[0][0].hypot(path[0][1]) < 1.0,
        "from the vehicle: {:?}",
        path[0]
    );
    assert_eq!(route.points.len(), 1, "the point steered for");
    // Only the behaviours that show something.
    assert!(
        kept.overlays.iter().all(|(_, o)| !o.is_empty()),
        "{:?}",
        kept.overlays
    );
}

#[test]
fn waypoints_can_come_from_a_file() {
    let out = dir("waypoints");
    let no_waypoints = out.join("no-waypoints.lcm");
    filtered(sim_log(), &no_waypoints, |channel, _| {
        channel != "WAYPOINTS"
    });
    let file = out.join("w.toml");
    std::fs::write(&file, "[[waypoints]]\nposition_m = [55.0, 4.0]\n[[waypoints]]\nposition_m = [105.0, -4.0]\n[[waypoints]]\nposition_m = [150.0, 0.0]\n").unwrap();
    let (code, stdout, stderr) = arcnav(&[
        "replay",
        no_waypoints.to_str().unwrap(),
        "--waypoints",
        file.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stdout}{stderr}");
    assert!(
        stdout.contains("(100.00%)"),
        "the same waypoints give the same decisions: {stdout}"
    );
}

/// Rewrites a log with each event's log time and position changed by `f`
/// (its log time, channel) → (new log time, sort key).
fn rewritten(source: &Path, target: &Path, f: impl Fn(i64, &str) -> (i64, i64)) {
    let mut events: Vec<(i64, i64, String, Vec<u8>)> = LogReader::open(source)
        .unwrap()
        .map(|e| {
            let e = e.unwrap();
            let (t, key) = f(e.timestamp, &e.channel);
            (key, t, e.channel, e.data)
        })
        .collect();
    events.sort_by_key(|e| e.0);
    let mut writer = LogWriter::create(target).unwrap();
    for (_, t, channel, data) in events {
        writer.write_event(t, &channel, &data).unwrap();
    }
}

#[test]
fn a_log_not_in_time_order_is_replayed_in_time_order_and_says_so() {
    // Every range image logged 0.1 s after capture, and written after
    // every pose of its 20 s (a program that logs its channels in batches).
    let sorted = dir("order").join("sorted.lcm");
    let batched = dir("order").join("batched.lcm");
    let late = |t: i64, c: &str| {
        if c.starts_with("RANGE_IMAGE") {
            t + 100_000
        } else {
            t
        }
    };
    rewritten(sim_log(), &sorted, |t, c| (late(t, c), late(t, c)));
    let in_batches = |seconds: i64| {
        move |t: i64, c: &str| {
            let images = i64::from(c.starts_with("RANGE_IMAGE"));
            let block = t / (seconds * 1_000_000);
            (late(t, c), (block * 2 + images) << 40 | t)
        }
    };
    rewritten(sim_log(), &batched, in_batches(20));
    let (a, b) = (
        replay_with_defaults(&sorted),
        replay_with_defaults(&batched),
    );
    assert!(b.problems.reordered > 0);
    assert!(
        b.problems
            .lines()
            .iter()
            .any(|l| l.contains("fed in time order")),
        "{:?}",
        b.problems.lines()
    );
    // The short course lasts less than the reader's 30 s window: every
    // image is fed in time, and every decision is the sorted log's.
    assert_eq!(b.problems.fed_late, 0);
    assert!(!b.problems.lost_input());
    assert_eq!(a.inputs.images, b.inputs.images);
    let commands = |r: &ReplayResult| r.cycles.values().map(|c| c.command).collect::<Vec<_>>();
    assert_eq!(commands(&a), commands(&b));
}

#[test]
fn decisions_stamped_by_a_logger_are_compared_by_their_cycle_time() {
    // lcm-logger stamps each event when it receives it: a few ms after the
    // message's own time.
    let logged = dir("logger").join("logged.lcm");
    rewritten(sim_log(), &logged, |t, _| (t + 3_000, t));
    let result = replay_with_defaults(&logged);
    let comparison = compare(
        ("recorded", "replayed"),
        &result.recorded,
        &result.cycles,
        (&|_: &str| 1.0, &|_: &str| 1.0),
        0,
    );
    assert!(
        comparison.compared > 100,
        "{} compared",
        comparison.compared
    );
    assert_eq!(comparison.compared, result.recorded.len());
    assert_eq!(comparison.agreement_percent, Some(100.0));
    // Nothing in common is said so, not "100 %".
    let nothing = compare(
        ("recorded", "replayed"),
        &result.recorded,
        &Default::default(),
        (&|_: &str| 1.0, &|_: &str| 1.0),
        0,
    );
    assert_eq!(nothing.agreement_percent, None);
}

/// The reported live defect's log (`../shared/repro/live_no_images.lcm`,
/// written by the reference Python LCM): every pose is in the file before
/// every image, so played as written the images arrive 10 s late. Read in
/// time order, each image is evaluated when it was logged.
#[test]
fn the_reported_log_with_every_image_after_every_pose_is_replayed_in_time_order() {
    let path = arcnav_testkit::workspace_root().join("../shared/repro/live_no_images.lcm");
    if !path.exists() {
        arcnav_testkit::missing(&format!("{} (the shared repro log)", path.display()));
        return;
    }
    let result = replay_with_defaults(&path);
    assert_eq!(result.inputs.images, 20);
    assert_eq!(result.problems.reordered, 20);
    assert!(result.problems.max_reorder_lag_s > 9.0);
    assert_eq!(result.problems.fed_late, 0);
    assert!(
        !result.problems.lost_input(),
        "{:?}",
        result.problems.lines()
    );
}

/// A copy of the short course's log under `name`, to be damaged or overwritten.
fn copy_of_log(tag: &str, name: &str) -> PathBuf {
    let path = dir(tag).join(name);
    std::fs::copy(sim_log(), &path).unwrap();
    path
}

#[test]
fn an_output_that_is_the_input_log_is_refused_and_the_log_stays_whole() {
    let log = copy_of_log("overwrite", "mission.lcm");
    let before = std::fs::read(&log).unwrap();
    let link = dir("overwrite").join("link.lcm");
    let _ = std::fs::remove_file(&link);
    std::os::unix::fs::symlink(&log, &link).unwrap();
    let l = log.to_str().unwrap();
    for args in [
        vec!["replay", l, "--out", l],
        vec!["replay", l, "--json", l],
        vec!["replay", l, "--out", link.to_str().unwrap()],
        vec!["render", l, "--at", "5", "--out", l],
    ] {
        let (code, stdout, stderr) = arcnav(&args);
        assert_eq!(code, 1, "{args:?}: {stdout}");
        assert!(stderr.contains("refusing to write"), "{args:?}: {stderr}");
        assert!(stderr.contains("it is the log"), "{args:?}: {stderr}");
        assert!(
            std::fs::read(&log).unwrap() == before,
            "{args:?} changed the log"
        );
    }
    // The same file for two outputs.
    let json = dir("overwrite").join("both");
    let j = json.to_str().unwrap();
    let (code, _, stderr) = arcnav(&["replay", l, "--out", j, "--json", j]);
    assert_eq!(code, 1, "{stderr}");
}

#[test]
fn a_sim_log_is_replayed_with_the_configuration_beside_it_and_says_which() {
    // `arcnav sim` writes config.toml beside mission.lcm; replayed with the
    // defaults instead, a run made with another evaluator had agreed on
    // 0.07 % of its decisions.
    let log = copy_of_log("beside", "mission.lcm");
    let beside = dir("beside").join("config.toml");
    let json = dir("beside").join("replay.json");
    let replayed = |config: &str| {
        std::fs::write(&beside, config).unwrap();
        let (code, stdout, stderr) = arcnav(&[
            "replay",
            log.to_str().unwrap(),
            "--json",
            json.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "{stdout}{stderr}");
        assert!(
            stderr.contains("the configuration the run was made with"),
            "{stderr}"
        );
        let report: Value = serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        assert_eq!(report["configurations"][0], beside.to_str().unwrap());
        report["comparisons"][0]["agreement_percent"]
            .as_f64()
            .unwrap()
    };
    // The log was made with the defaults.
    assert_eq!(replayed("# the defaults\n"), 100.0);
    assert!(replayed("[arbiter.weights]\ngoal_seeking = 2.0\n") < 100.0);
    // --config wins over the file beside the log.
    let (code, stdout, stderr) = arcnav(&[
        "replay",
        log.to_str().unwrap(),
        "--config",
        dir("beside").join("none.toml").to_str().unwrap(),
    ]);
    assert_eq!(code, 1, "{stdout}");
    assert!(stderr.contains("none.toml"), "{stderr}");
    std::fs::remove_file(&beside).unwrap();
}

#[test]
fn a_window_past_the_logs_end_says_so_and_not_that_the_log_has_no_commands() {
    let (code, stdout, stderr) = arcnav(&["replay", sim_log().to_str().unwrap(), "--from", "1000"]);
    assert_eq!(code, 3, "{stdout}{stderr}");
    assert!(
        stdout.contains("no decision between --from and --to"),
        "{stdout}"
    );
    assert!(
        stdout.contains("no STEERING_COMMAND between --from and --to")
            && !stdout.contains("the log holds no STEERING_COMMAND"),
        "{stdout}"
    );
}

/// `--from S` decides from S as the whole replay does there: the log
/// before S brings the map, the progress along the waypoints and each
/// behaviour's memory to S (skipped, the vehicle had steered back to the
/// first waypoint behind it: 0 of 319 decisions agreed).
#[test]
fn a_replay_from_a_time_decides_there_as_the_whole_replay_does() {
    let whole = replay_with_defaults(sim_log());
    let from = replay(
        sim_log(),
        &Config::default().resolved().unwrap(),
        &ReplayOptions {
            from_s: Some(8.0),
            ..ReplayOptions::default()
        },
        &mut |_| {},
    )
    .unwrap();
    let origin = whole.span.unwrap().0;
    let after = |r: &ReplayResult| -> Vec<_> {
        r.cycles
            .iter()
            .filter(|((_, t), _)| *t >= origin + 8_200_000)
            .map(|(k, c)| (*k, c.command))
            .collect()
    };
    assert!(after(&whole).len() > 50);
    assert!(
        after(&from) == after(&whole),
        "decided otherwise after --from"
    );
    assert!(from.cycles.keys().all(|(_, t)| *t >= origin + 7_900_000));
    assert!(from.problems.before_window > 0);
    assert!(!from.problems.lost_input(), "{:?}", from.problems.lines());
}

#[test]
fn a_finished_replay_replaces_the_old_output_and_leaves_no_temporary() {
    // (A run that fails keeps the old file: see arcnav::output's tests.)
    let log = copy_of_log("staged", "mission.lcm");
    let out = dir("staged").join("out.lcm");
    std::fs::write(&out, b"old").unwrap();
    let (code, stdout, stderr) = arcnav(&[
        "replay",
        log.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stdout}{stderr}");
    assert!(std::fs::metadata(&out).unwrap().len() > 1000);
    let left: Vec<_> = std::fs::read_dir(dir("staged"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".partial"))
        .collect();
    assert!(left.is_empty(), "{left:?}");
}

#[test]
fn absurd_numbers_on_the_command_line_are_refused_with_the_flag_named() {
    let l = sim_log().to_str().unwrap();
    for (args, says) in [
        (vec!["replay", l, "--speed", "1e-30"], "--speed 0.00000"),
        (vec!["replay", l, "--speed", "inf"], "--speed inf"),
        (vec!["replay", l, "--from", "NaN"], "--from NaN"),
        (
            vec!["replay", l, "--from", "30", "--to", "10"],
            "the range is empty",
        ),
        (vec!["render", l, "--at", "NaN"], "--at NaN"),
        (vec!["render", l, "--at", "inf"], "--at inf"),
        (vec!["render", l, "--at", "1e13"], "--at 10000000000000"),
        (
            vec!["sim", "--snapshot-every", "inf"],
            "--snapshot-every inf",
        ),
        (
            vec!["sim", "--world", "short_course", "--snapshot-every", "0.01"],
            "shorter than one decision cycle",
        ),
    ] {
        let (code, stdout, stderr) = arcnav(&args);
        assert_eq!(code, 1, "{args:?}: {stdout}");
        assert!(stderr.contains(says), "{args:?}: {stderr}");
    }
    // An endless configuration file: refused, its cause said once.
    let (code, _, stderr) = arcnav(&["config", "--check", "/dev/zero"]);
    assert_eq!(code, 1);
    assert_eq!(stderr.matches("larger than 16 MiB").count(), 1, "{stderr}");
    // A waypoint that is not a number.
    let waypoints = dir("nan-waypoint").join("w.toml");
    std::fs::write(&waypoints, "[[waypoints]]\nposition_m = [nan, 4.0]\n").unwrap();
    let (code, _, stderr) = arcnav(&["replay", l, "--waypoints", waypoints.to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(
        stderr.contains("waypoint 1: position_m [NaN, 4.0] is not finite"),
        "{stderr}"
    );
    // A file of random bytes: nothing could be read, and it says so.
    let noise = dir("noise").join("noise.lcm");
    let bytes: Vec<u8> = (0..100_000u32)
        .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8)
        .collect();
    std::fs::write(&noise, bytes).unwrap();
    let (code, _, stderr) = arcnav(&["render", noise.to_str().unwrap(), "--at", "1"]);
    assert_eq!(code, 1);
    assert!(stderr.contains("no LCM event could be read"), "{stderr}");
}

#[test]
fn a_log_replayed_twice_in_a_row_is_two_runs_and_says_so() {
    let twice = dir("twice").join("twice.lcm");
    let once = std::fs::read(sim_log()).unwrap();
    std::fs::write(&twice, [once.as_slice(), once.as_slice()].concat()).unwrap();
    let (a, b) = (
        replay_with_defaults(sim_log()),
        replay_with_defaults(&twice),
    );
    // Every decision of both runs, each run's under its own number (keyed
    // by time alone, the second run's had replaced the first's: one run's
    // decisions "replayed as consecutive runs"). The pipeline carries on
    // over the restart as a live one would (the map reset, the cycle clock
    // restarted), so the first run is decided as the log alone.
    assert_eq!(b.inputs.poses, 2 * a.inputs.poses);
    assert_eq!(b.problems.log_restarts, 1);
    assert_eq!(b.problems.clock_restarts, 1);
    assert_eq!(b.problems.fed_late, 0);
    assert_eq!(b.recorded.len(), 2 * a.recorded.len());
    let of_run = |run: u32| b.cycles.keys().filter(|(r, _)| *r == run).count();
    assert_eq!(of_run(0), a.cycles.len());
    assert!(
        of_run(1) + 2 >= a.cycles.len(),
        "{} of {}",
        of_run(1),
        a.cycles.len()
    );
    let first = |r: &ReplayResult, run: u32| -> Vec<_> {
        r.cycles
            .iter()
            .filter(|((k, _), _)| *k == run)
            .map(|((_, t), c)| (*t, c.command))
            .collect()
    };
    assert!(
        first(&b, 0) == first(&a, 0),
        "run 0 decided otherwise than the log alone"
    );
    let lines = b.problems.lines().join("\n");
    assert!(lines.contains("the log starts over 1 time(s)"), "{lines}");
    assert!(
        lines.contains("the pose clock went backwards 1 time(s)"),
        "{lines}"
    );
}

/// A POSE whose fingerprint is damaged is input that could not be used:
/// counted as lost (it had been skipped as "an unknown type", exit 0).
#[test]
fn a_pose_with_a_damaged_fingerprint_is_lost_input() {
    let damaged = dir("fingerprint").join("damaged.lcm");
    let mut writer = LogWriter::create(&damaged).unwrap();
    let mut done = false;
    for e in LogReader::open(sim_log()).unwrap().map(Result::unwrap) {
        let mut data = e.data.clone();
        if !done && e.channel == "POSE" && e.event_number > 100 {
            data[0] ^= 0x5a;
            done = true;
        }
        writer.write_event(e.timestamp, &e.channel, &data).unwrap();
    }
    drop(writer);
    let result = replay_with_defaults(&damaged);
    assert_eq!(result.problems.undecodable.get("POSE"), Some(&1));
    assert!(result.problems.unknown_channels.is_empty());
    assert!(result.problems.lost_input());
}

#[test]
fn poses_at_either_end_of_time_are_refused_and_counted_and_nothing_hangs() {
    use arcnav_bus::codec::Message as _;
    use arcnav_bus::lcmtypes::{pose_t, waypoints_t};
    // Poses stamped i64::MAX and i64::MIN in the middle of the log, and the
    // waypoints again, stamped i64::MAX. The one near i64::MIN had
    // restarted the cycle clock there; the next pose's gap saturated and
    // ~10^10 cycles were caught up one by one (a hang, memory growing).
    let events: Vec<_> = LogReader::open(sim_log())
        .unwrap()
        .map(Result::unwrap)
        .collect();
    let middle = events.len() / 2;
    let (at, data) = events
        .iter()
        .skip(middle)
        .find(|e| e.channel == "POSE")
        .map(|e| (e.timestamp, e.data.clone()))
        .unwrap();
    let pose = pose_t::decode(&data).unwrap();
    let mut waypoints = events
        .iter()
        .find(|e| e.channel == "WAYPOINTS")
        .map(|e| waypoints_t::decode(&e.data).unwrap())
        .unwrap();
    waypoints.utime = i64::MAX;
    let jumped = dir("end-of-time").join("jumped.lcm");
    let mut writer = LogWriter::create(&jumped).unwrap();
    for (k, e) in events.iter().enumerate() {
        writer
            .write_event(e.timestamp, &e.channel, &e.data)
            .unwrap();
        if k == middle {
            for utime in [i64::MAX, i64::MIN] {
                let absurd = pose_t { utime, ..pose };
                writer.write_message(at, "POSE", &absurd).unwrap();
            }
        }
        if k == middle / 2 {
            writer
                .write_message(e.timestamp, "WAYPOINTS", &waypoints)
                .unwrap();
        }
    }
    drop(writer);
    // Counted, not timed: a hang never reaches a wall-clock bound.
    let (a, b) = (
        replay_with_defaults(sim_log()),
        replay_with_defaults(&jumped),
    );
    assert_eq!(b.problems.invalid_poses, 2);
    assert_eq!(b.problems.skipped_cycles, a.problems.skipped_cycles);
    assert_eq!(b.problems.clock_restarts, a.problems.clock_restarts);
    assert!(
        b.cycles.len().abs_diff(a.cycles.len()) <= 3,
        "{} vs {} decisions",
        b.cycles.len(),
        a.cycles.len()
    );
    assert!(b.problems.lost_input());
}

#[test]
fn a_log_without_images_replayed_without_its_cells_says_nothing_was_perceived() {
    let cells_only = dir("cells-only").join("cells.lcm");
    filtered(sim_log(), &cells_only, |channel, _| {
        !channel.starts_with("RANGE_IMAGE")
    });
    let (code, stdout, _) = arcnav(&["replay", cells_only.to_str().unwrap()]);
    assert_eq!(code, 3, "{stdout}");
    assert!(
        stdout.contains("no range image: nothing was perceived"),
        "{stdout}"
    );
    let (code, stdout, _) = arcnav(&["replay", cells_only.to_str().unwrap(), "--recorded-cells"]);
    assert_eq!(code, 0, "{stdout}");
    // `arcnav render` draws such a log from its cells by itself:
    // render_draws_a_log_without_images_from_its_recorded_cells.
}

#[test]
fn messages_on_other_programs_channels_are_listed_and_never_taken_as_inputs() {
    use arcnav_bus::codec::Message as _;
    use arcnav_bus::lcmtypes::{pose_t, steering_command_t};
    // A second pose stream 50 m off, and a teleoperation stream that steers
    // hard left, beside the log's own.
    // Its own directory: `foreign_channels_are_skipped_…` writes its own
    // mixed.lcm, and the two may run at once (a run with four tests at a
    // time replayed one's log half written over by the other).
    let mixed = dir("other-programs").join("mixed.lcm");
    let mut writer = LogWriter::create(&mixed).unwrap();
    for e in LogReader::open(sim_log()).unwrap().map(Result::unwrap) {
        writer
            .write_event(e.timestamp, &e.channel, &e.data)
            .unwrap();
        if e.channel == "POSE" {
            let mut gps = pose_t::decode(&e.data).unwrap();
            gps.position[0] += 50.0;
            writer
                .write_message(e.timestamp, "POSE_GPS_RAW", &gps)
                .unwrap();
        }
        if e.channel == "STEERING_COMMAND" {
            let mut teleop = steering_command_t::decode(&e.data).unwrap();
            teleop.curvature = 0.125;
            teleop.arc_index = 38;
            writer
                .write_message(e.timestamp, "STEERING_COMMAND_TELEOP", &teleop)
                .unwrap();
        }
    }
    drop(writer);
    let (a, b) = (
        replay_with_defaults(sim_log()),
        replay_with_defaults(&mixed),
    );
    assert_eq!(b.problems.map_resets, 0);
    assert_eq!(b.inputs.poses, a.inputs.poses);
    assert_eq!(b.recorded.len(), a.recorded.len());
    let commands = |r: &ReplayResult| r.cycles.values().map(|c| c.command).collect::<Vec<_>>();
    assert_eq!(commands(&a), commands(&b));
    let recorded = |r: &ReplayResult| r.recorded.values().map(|c| c.command).collect::<Vec<_>>();
    assert_eq!(recorded(&a), recorded(&b));
    assert_eq!(b.problems.foreign.len(), 2, "{:?}", b.problems.foreign);
    assert!(!b.problems.lost_input());
    let lines = b.problems.lines().join("\n");
    assert!(
        lines.contains("on POSE_GPS_RAW, not an arcnav channel"),
        "{lines}"
    );
}

#[test]
fn an_empty_log_or_one_without_poses_is_never_a_success() {
    let empty = dir("empty").join("empty.lcm");
    std::fs::write(&empty, b"").unwrap();
    let (code, stdout, _) = arcnav(&["replay", empty.to_str().unwrap()]);
    assert_eq!(code, 3, "{stdout}");
    assert!(stdout.contains("no LCM event could be read"), "{stdout}");
    assert!(!stdout.contains("every input was used"), "{stdout}");
    let no_poses = dir("empty").join("no-poses.lcm");
    filtered(sim_log(), &no_poses, |channel, _| channel != "POSE");
    let (code, stdout, _) = arcnav(&["replay", no_poses.to_str().unwrap()]);
    assert_eq!(code, 3, "{stdout}");
    assert!(stdout.contains("the log holds no POSE"), "{stdout}");
    assert!(!stdout.contains("100.00"), "{stdout}");
    // The images are all counted: unplaced ones are said.
    let result = replay_with_defaults(&no_poses);
    assert!(result.problems.images_unplaced + result.problems.images_without_pose > 0);
    // A window past the log's end: its poses lie outside, it holds them.
    let (code, stdout, _) = arcnav(&["replay", sim_log().to_str().unwrap(), "--from", "1e6"]);
    assert_eq!(code, 3, "{stdout}");
    assert!(
        stdout.contains("no decision between --from and --to: all"),
        "{stdout}"
    );
    assert!(!stdout.contains("the log holds no POSE"), "{stdout}");
}

#[test]
fn a_paced_replay_does_not_wait_out_a_jump_in_log_time() {
    // The first 5 s of the log, then one pose logged a year later.
    let jumped = dir("pace").join("jumped.lcm");
    let mut writer = LogWriter::create(&jumped).unwrap();
    let mut first = None;
    for e in LogReader::open(sim_log()).unwrap().map(Result::unwrap) {
        let t0 = *first.get_or_insert(e.timestamp);
        if e.timestamp - t0 > 5_000_000 {
            if e.channel == "POSE" {
                writer
                    .write_event(t0 + 365 * 86_400_000_000, "POSE", &e.data)
                    .unwrap();
                break;
            }
            continue;
        }
        writer
            .write_event(e.timestamp, &e.channel, &e.data)
            .unwrap();
    }
    drop(writer);
    let started = std::time::Instant::now();
    let (code, stdout, stderr) = arcnav(&["replay", jumped.to_str().unwrap(), "--speed", "100"]);
    assert!(
        started.elapsed().as_secs() < 20,
        "took {:?}",
        started.elapsed()
    );
    assert!(code == 0 || code == 3, "{stdout}{stderr}");
}

#[test]
fn a_replay_from_the_middle_keeps_the_mission_sent_before_it() {
    let options = ReplayOptions {
        from_s: Some(10.0),
        ..ReplayOptions::default()
    };
    let result = replay(
        sim_log(),
        &Config::default().resolved().unwrap(),
        &options,
        &mut |_| {},
    )
    .unwrap();
    assert_eq!(result.inputs.waypoints, 1, "the waypoints sent at 0 s");
    let comparison = compare(
        ("recorded", "replayed"),
        &result.recorded,
        &result.cycles,
        (&|_: &str| 1.0, &|_: &str| 1.0),
        0,
    );
    let percent = comparison.agreement_percent.unwrap();
    eprintln!(
        "from 10 s: {} compared, {percent:.1}% agree",
        comparison.compared
    );
    // The map and the route's memory start empty at 10 s, so decisions
    // near obstacles differ (90 % agree with route, 95 % with goal
    // seeking alone); without the mission nearly none did (1 in 313).
    assert!(percent > 85.0, "{percent:.1}% agree");
}

#[test]
fn reports_from_more_sensors_than_the_map_tracks_are_counted_and_said() {
    use arcnav_bus::codec::Message as _;
    use arcnav_bus::lcmtypes::obstacle_cells_t;
    // The recorded cells, each image from another of 40 sensors (the map
    // tracks 32).
    let many = dir("sensors").join("many.lcm");
    let mut writer = LogWriter::create(&many).unwrap();
    let mut k = 0;
    for e in LogReader::open(sim_log()).unwrap().map(Result::unwrap) {
        if e.channel == "OBSTACLE_CELLS" {
            let mut cells = obstacle_cells_t::decode(&e.data).unwrap();
            cells.sensor = format!("sensor{}", k % 40);
            k += 1;
            writer
                .write_message(e.timestamp, &e.channel, &cells)
                .unwrap();
        } else {
            writer
                .write_event(e.timestamp, &e.channel, &e.data)
                .unwrap();
        }
    }
    drop(writer);
    let (code, stdout, _) = arcnav(&["replay", many.to_str().unwrap(), "--recorded-cells"]);
    assert_eq!(code, 3, "{stdout}");
    assert!(
        stdout.contains("obstacle report(s) refused by the local map"),
        "{stdout}"
    );
}

#[test]
fn a_flipped_bit_in_one_events_log_time_does_not_end_the_replay_early() {
    // One pose 2^40 µs (12.7 days) late in the log's time, 2 s in.
    let flipped = dir("flipped").join("flipped.lcm");
    let mut writer = LogWriter::create(&flipped).unwrap();
    let mut first = None;
    let mut done = false;
    for e in LogReader::open(sim_log()).unwrap().map(Result::unwrap) {
        let t0 = *first.get_or_insert(e.timestamp);
        let t = if !done && e.channel == "POSE" && e.timestamp - t0 > 2_000_000 {
            done = true;
            e.timestamp + (1 << 40)
        } else {
            e.timestamp
        };
        writer.write_event(t, &e.channel, &e.data).unwrap();
    }
    drop(writer);
    let to = |path: &Path| {
        let options = ReplayOptions {
            to_s: Some(8.0),
            ..ReplayOptions::default()
        };
        replay(
            path,
            &Config::default().resolved().unwrap(),
            &options,
            &mut |_| {},
        )
        .unwrap()
        .cycles
        .len()
    };
    let (a, b) = (to(sim_log()), to(&flipped));
    assert!(a > 70, "{a} decisions in 8 s");
    assert!(
        b.abs_diff(a) <= 1,
        "{b} decisions with the flipped bit, {a} without"
    );
}

/// A log of `seconds` of the short course with `sensor` streaming each
/// image in slices of `lines` lines (002 §7's integrated mode).
fn streamed_log(tag: &str, sensor: SensorPreset, lines: usize, seconds: f64) -> (PathBuf, Config) {
    let path = dir(tag).join("streamed.lcm");
    let mut config = Config::default();
    config.sensor.preset = sensor;
    config.sim.slice_lines = lines;
    config.sim.time_limit_s = seconds;
    config.pipeline.perception_latency_s = arcnav_pipeline::Latency::Seconds(0.02);
    let world = Arc::new(World::embedded("short_course").unwrap().unwrap());
    let options = MissionOptions {
        log: Some(path.clone()),
        ..MissionOptions::default()
    };
    run_mission(&config.resolved().unwrap(), world, &options, &mut |_| {}).unwrap();
    (path, config)
}

/// 020 item 3: a log of range-image slices (a lidar's blocks of columns,
/// the ERIM's blocks of rows) replays to the simulator's own commands, every
/// slice used.
#[test]
fn a_log_of_streamed_slices_replays_to_the_sims_own_commands() {
    for (tag, sensor, lines) in [
        ("slices-lidar", SensorPreset::Lidar64, 16),
        ("slices-erim", SensorPreset::Erim, 4),
    ] {
        let (log, config) = streamed_log(tag, sensor, lines, 12.0);
        let result = replay(
            &log,
            &config.resolved().unwrap(),
            &ReplayOptions::default(),
            &mut |_| {},
        )
        .unwrap();
        assert_eq!(result.inputs.images, 0, "{tag}");
        let frames = 12.0
            * if sensor == SensorPreset::Erim {
                2.0
            } else {
                10.0
            };
        let per_frame = match sensor {
            SensorPreset::Erim => 64 / lines,
            _ => 2048 / lines,
        };
        assert!(
            result.inputs.slices as f64 >= (frames - 1.0) * per_frame as f64,
            "{tag}: {} slices",
            result.inputs.slices
        );
        let same = |name: &str| config.arbiter.weight(name);
        let comparison = compare(
            ("recorded", "replayed"),
            &result.recorded,
            &result.cycles,
            (&same, &same),
            0,
        );
        assert!(comparison.compared > 100, "{tag}");
        assert_eq!(
            comparison.agreement_percent,
            Some(100.0),
            "{tag}: {:?}",
            comparison.first_divergence
        );
        assert!(
            !result.problems.lost_input(),
            "{tag}: {:?}",
            result.problems.lines()
        );
    }
}

/// Slices missing from a log (a lost packet) are lines of an image lost:
/// counted and said, the replay goes on.
#[test]
fn slices_missing_from_a_log_are_counted_as_lost_lines() {
    let (log, config) = streamed_log("slices-lost", SensorPreset::Lidar64, 16, 3.0);
    let holed = dir("slices-lost").join("holed.lcm");
    let mut seen = 0;
    let mut writer = LogWriter::create(&holed).unwrap();
    for event in LogReader::open(&log).unwrap() {
        let event = event.unwrap();
        if event.channel.starts_with("RANGE_IMAGE") {
            seen += 1;
            // Every 50th slice lost.
            if seen % 50 == 0 {
                continue;
            }
        }
        writer
            .write_event(event.timestamp, &event.channel, &event.data)
            .unwrap();
    }
    drop(writer);
    let result = replay(
        &holed,
        &config.resolved().unwrap(),
        &ReplayOptions::default(),
        &mut |_| {},
    )
    .unwrap();
    // Every dropped slice but perhaps the log's last is a gap before the
    // next slice of its frame.
    let dropped = (seen / 50) as u64;
    let lost = result.problems.lost_slice_lines;
    assert!(
        lost == dropped * 16 || lost == (dropped - 1) * 16,
        "{lost} lines lost, {dropped} slices dropped"
    );
    assert!(result.problems.lost_input());
    assert!(
        result
            .problems
            .lines()
            .iter()
            .any(|l| l.contains("line(s) of streamed range images never arrived")),
        "{:?}",
        result.problems.lines()
    );
}

/// Logs written before veto causes and DECISION (arc_votes_t of the older
/// fingerprint, no DECISION) still replay: their votes are read (vetoes
/// without a cause) and every decision agrees.
#[test]
fn logs_written_before_veto_causes_still_replay() {
    use arcnav_bus::Message;
    use arcnav_bus::lcmtypes::{arc_votes_t, arc_votes_v1_t};
    let old = dir("old-votes").join("old.lcm");
    let mut writer = LogWriter::create(&old).unwrap();
    let mut rewritten_votes = 0;
    for event in LogReader::open(sim_log()).unwrap() {
        let e = event.unwrap();
        let data = if e.channel == "DECISION" {
            continue;
        } else if e.channel.starts_with("ARC_VOTES_") {
            let v = arc_votes_t::decode(&e.data).unwrap();
            rewritten_votes += 1;
            arc_votes_v1_t {
                utime: v.utime,
                behaviour: v.behaviour,
                num_arcs: v.num_arcs,
                curvature: v.curvature,
                votes: v.votes,
                vetoed: v.vetoed,
                has_speed_vote: v.has_speed_vote,
                speed_vote: v.speed_vote,
                arc_speed: v.arc_speed,
                reverse_clear: v.reverse_clear,
                forward_clear: v.forward_clear,
            }
            .encode()
            .unwrap()
        } else {
            e.data
        };
        writer.write_event(e.timestamp, &e.channel, &data).unwrap();
    }
    drop(writer);
    assert!(rewritten_votes > 1000);
    let result = replay_with_defaults(&old);
    assert!(result.recorded_reasons.is_empty());
    assert!(
        result.recorded.values().all(|c| c.votes.len() == 3),
        "the old votes are read"
    );
    let same = |name: &str| Config::default().arbiter.weight(name);
    let comparison = compare(
        ("recorded", "replayed"),
        &result.recorded,
        &result.cycles,
        (&same, &same),
        0,
    );
    assert_eq!(comparison.agreement_percent, Some(100.0));
    assert!(
        !result.problems.lost_input(),
        "{:?}",
        result.problems.lines()
    );
    assert!(
        result.problems.lines().is_empty(),
        "{:?}",
        result.problems.lines()
    );
}

/// `render --at S` counts from the first pose on the messages' clock: a
/// log that lcm-logger stamped with the wall clock of the recording (here
/// 11 days after the messages' own times) is drawn at the same decision,
/// and what its DECISION says is what deciding again gives.
#[test]
fn render_counts_from_the_first_pose_whatever_clock_stamped_the_log() {
    let logged = dir("render-logger").join("logged.lcm");
    rewritten(sim_log(), &logged, |t, _| (t + 950_400_000_000, t));
    let mut said = Vec::new();
    for log in [sim_log(), logged.as_path()] {
        let png = logged.with_extension(format!("{}.png", said.len()));
        let (code, stdout, stderr) = arcnav(&[
            "render",
            log.to_str().unwrap(),
            "--at",
            "12.5",
            "--out",
            png.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "{stdout}{stderr}");
        assert!(stdout.contains("decision at 12.50 s"), "{stdout}");
        let line = |prefix: &str| {
            stdout
                .lines()
                .find_map(|l| l.strip_prefix(prefix))
                .unwrap_or_else(|| panic!("no {prefix:?} in {stdout}"))
                .trim()
                .to_owned()
        };
        assert_eq!(line("as logged"), line("redone"), "{stdout}");
        said.push(line("as logged"));
    }
    assert_eq!(said[0], said[1]);
}
