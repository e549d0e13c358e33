//! External behaviours in lock-step (`[behaviours.external.NAME]`): a
//! program of its own that `arcnav sim`, `sweep` and `replay` start and talk
//! to over its standard input and output. The Python side is
//! `examples/python/heading_hold.py` on the helper
//! `examples/python/arcnav_behaviour.py`, with the reference `lcm` package's
//! `lcm-gen` types (installed by scripts/test-tools; under CI these tests
//! never skip).

use std::path::{Path, PathBuf};
use std::process::Command;

use arcnav_bus::lcmtypes::pose_t;
use arcnav_bus::log::LogReader;
use arcnav_bus::messages::channels;
use arcnav_testkit::{LcmReference, ScratchDir, workspace_root};
use serde_json::Value;

/// The reference LCM and arcnav's types generated for Python.
fn python() -> Option<&'static (LcmReference, PathBuf)> {
    LcmReference::with_arcnav_types()
}

/// `arcnav ARGS…` with the Python types importable; exit code, stdout, stderr.
fn arcnav(types: &Path, args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_arcnav"))
        .args(args)
        .env("PYTHONPATH", types)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A configuration file in `dir` with one external behaviour `name` running
/// `command` at weight 1, and `extra` TOML.
fn config_with(dir: &Path, file: &str, name: &str, command: &[&str], extra: &str) -> PathBuf {
    let path = dir.join(file);
    let command: Vec<String> = command.iter().map(|c| format!("{c:?}")).collect();
    std::fs::write(
        &path,
        format!(
            "{extra}\n[behaviours.external.{name}]\ncommand = [{}]\n[arbiter.weights]\n{name} = 1.0\n",
            command.join(", ")
        ),
    )
    .unwrap();
    path
}

fn heading_hold(reference: &LcmReference, heading_deg: f64) -> Vec<String> {
    vec![
        reference.python_path().display().to_string(),
        workspace_root()
            .join("examples/python/heading_hold.py")
            .display()
            .to_string(),
        "--heading-deg".into(),
        heading_deg.to_string(),
    ]
}

/// `arcnav sim` on open_field with `config`, into `out`.
fn sim_open_field(types: &Path, config: &Path, out: &Path) -> (i32, String, String) {
    arcnav(
        types,
        &[
            "sim",
            "--world",
            "open_field",
            "--config",
            config.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ],
    )
}

fn report(dir: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("report.json")).unwrap()).unwrap()
}

/// The vehicle's mean heading (rad) over the poses of `log` from `from_s`
/// seconds after its first.
fn mean_heading(log: &Path, from_s: f64) -> f64 {
    let mut reader = LogReader::open(log).unwrap();
    let (mut s, mut c, mut first) = (0.0, 0.0, None);
    while let Some(event) = reader.next_event().unwrap() {
        if event.channel != channels::POSE {
            continue;
        }
        let first = *first.get_or_insert(event.timestamp);
        if ((event.timestamp - first) as f64) < from_s * 1e6 {
            continue;
        }
        use arcnav_bus::Message;
        let pose = pose_t::decode(&event.data).unwrap();
        let yaw = arcnav_vehicle::Pose::try_from(&pose).unwrap().yaw();
        s += yaw.sin();
        c += yaw.cos();
    }
    s.atan2(c)
}

const SHORT: &str = "[sim]\ntime_limit_s = 30.0\n";

/// The Done-when of issue 66: `arcnav sim` with the Python heading-hold
/// behaviour (weight 1, heading 90°) on open_field turns the vehicle to
/// 90° (its route heads elsewhere without it), and runs twice to the same log.
#[test]
fn a_python_behaviour_steers_a_simulated_mission_and_the_run_reproduces() {
    let Some((reference, types)) = python() else {
        return;
    };
    let dir = arcnav_testkit::scratch_dir("external-sim");
    let command = heading_hold(reference, 90.0);
    let command: Vec<&str> = command.iter().map(String::as_str).collect();
    let with = config_with(&dir, "with.toml", "heading_hold", &command, SHORT);
    let without = dir.join("without.toml");
    std::fs::write(&without, SHORT).unwrap();
    let mut logs = Vec::new();
    for (run, config) in [("a", &with), ("b", &with), ("base", &without)] {
        let out = dir.join(run);
        let (code, stdout, stderr) = sim_open_field(types, config, &out);
        // A 30 s mission ends at its time limit (exit 1) or off the map.
        assert!(code == 0 || code == 1, "{run}: {code}\n{stdout}\n{stderr}");
        logs.push((out.join("mission.lcm"), stdout, report(&out)));
    }
    let (log, stdout, r) = &logs[0];
    let counters = &r["behaviour_counters"]["heading_hold"];
    assert!(counters["voted"].as_u64().unwrap() >= 100, "{stdout}");
    assert_eq!(counters["abstained"], 0, "{stdout}");
    assert!(r.get("behaviour_faults").is_none(), "{stdout}");
    assert!(stdout.contains("heading_hold  abstained 0"), "{stdout}");
    let held = mean_heading(log, 10.0).to_degrees();
    let base = mean_heading(&logs[2].0, 10.0).to_degrees();
    eprintln!("mean heading after 10 s: {held:.1}° with heading_hold, {base:.1}° without");
    assert!((held - 90.0).abs() < 15.0, "{held:.1}°\n{stdout}");
    assert!(
        (base - 90.0).abs() > 30.0,
        "without it the route heads {base:.1}° too"
    );
    assert!(
        std::fs::read(log).unwrap() == std::fs::read(&logs[1].0).unwrap(),
        "two runs with the same deterministic behaviour wrote different logs"
    );
}

/// `arcnav sweep` over two worlds starts the program for each mission.
#[test]
fn a_sweep_runs_the_python_behaviour_in_every_mission() {
    let Some((reference, types)) = python() else {
        return;
    };
    let dir = arcnav_testkit::scratch_dir("external-sweep");
    let command = heading_hold(reference, 45.0);
    let command: Vec<&str> = command.iter().map(String::as_str).collect();
    let config = config_with(
        &dir,
        "c.toml",
        "heading_hold",
        &command,
        "[sim]\ntime_limit_s = 15.0\n",
    );
    let out = dir.join("sweep");
    let (code, stdout, stderr) = arcnav(
        types,
        &[
            "sweep",
            "--world",
            "open_field",
            "--world",
            "short_course",
            "--config",
            config.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--jobs",
            "2",
        ],
    );
    assert!(code == 0 || code == 1, "{code}\n{stdout}\n{stderr}");
    let rows = std::fs::read_to_string(out.join("rows.jsonl")).unwrap();
    let rows: Vec<Value> = rows
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(rows.len(), 2, "{stdout}\n{stderr}");
    for row in &rows {
        assert!(
            row["external_votes"].as_u64().is_some_and(|v| v > 50),
            "{row}\n{stderr}"
        );
        assert_eq!(row["behaviour_faults"], "", "{row}");
    }
    let table = std::fs::read_to_string(out.join("table.csv")).unwrap();
    assert!(
        table
            .lines()
            .next()
            .unwrap()
            .contains(",external_votes,behaviour_faults,"),
        "{table}"
    );
}

/// `arcnav replay` of a log recorded without it, with it configured:
/// decisions compared, and the differences moved by it.
#[test]
fn a_replay_with_the_python_behaviour_names_it_as_what_changed_the_decisions() {
    let Some((reference, types)) = python() else {
        return;
    };
    let dir = arcnav_testkit::scratch_dir("external-replay");
    let plain = dir.join("plain.toml");
    std::fs::write(&plain, "[sim]\ntime_limit_s = 20.0\n").unwrap();
    let recorded = dir.join("recorded");
    let (code, stdout, stderr) = sim_open_field(types, &plain, &recorded);
    assert!(code == 0 || code == 1, "{stdout}\n{stderr}");
    let command = heading_hold(reference, 120.0);
    let command: Vec<&str> = command.iter().map(String::as_str).collect();
    let with = config_with(&dir, "with.toml", "heading_hold", &command, "");
    let (code, stdout, stderr) = arcnav(
        types,
        &[
            "replay",
            recorded.join("mission.lcm").to_str().unwrap(),
            "--config",
            with.to_str().unwrap(),
        ],
    );
    assert!(code == 0 || code == 1, "{code}\n{stdout}\n{stderr}");
    assert!(stdout.contains("heading_hold  voted "), "{stdout}");
    let moved = stdout
        .lines()
        .find(|l| l.contains("differences moved by:"))
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(
        moved
            .trim()
            .starts_with("differences moved by: heading_hold "),
        "{stdout}"
    );
}

/// One mission with a misbehaving program (tests/external/misbehaving.py
/// MODE): its report, summary and how long it took.
fn misbehaving(mode: &str, extra: &str) -> (i32, Value, String, std::time::Duration) {
    let (reference, types) = python().expect("checked by the caller");
    let dir = arcnav_testkit::scratch_dir(&format!("external-{mode}"));
    let script = workspace_root().join("tests/external/misbehaving.py");
    let python = reference.python_path().display().to_string();
    let config = config_with(
        &dir,
        "c.toml",
        "bad",
        &[&python, script.to_str().unwrap(), mode],
        &format!("[sim]\ntime_limit_s = 10.0\n{extra}"),
    );
    let toml = std::fs::read_to_string(&config).unwrap();
    std::fs::write(
        &config,
        toml.replace(
            "[arbiter.weights]",
            "timeout_s = 0.5\nstart_timeout_s = 20.0\n[arbiter.weights]",
        ),
    )
    .unwrap();
    let out = dir.join("out");
    let started = std::time::Instant::now();
    let (code, stdout, stderr) = sim_open_field(types, &config, &out);
    let took = started.elapsed();
    let _keep: &ScratchDir = &dir;
    (code, report(&out), format!("{stdout}\n{stderr}"), took)
}

/// A program that crashes, hangs or writes garbage ends with a clear count
/// and its name and reason in the summary, and the mission goes on without
/// it; votes over the wrong arcs, from the future or undecodable are
/// refused and counted each cycle, the program kept.
#[test]
fn crashing_hanging_and_garbage_writing_behaviours_are_counted_and_the_mission_goes_on() {
    if python().is_none() {
        return;
    }
    for (mode, reason, counter) in [
        (
            "crash",
            "closed its standard output; it exited (exit status: 3)",
            None,
        ),
        ("hang", "gave no votes within 0.5 s", Some("timeouts")),
        (
            "garbage",
            "wrote something that is not a framed message",
            None,
        ),
    ] {
        let (_, r, out, took) = misbehaving(mode, "");
        let counters = &r["behaviour_counters"]["bad"];
        assert_eq!(counters["voted"], 3, "{mode}: {out}");
        assert_eq!(counters["ended"], 1, "{mode}: {out}");
        if let Some(counter) = counter {
            assert_eq!(counters[counter], 1, "{mode}: {out}");
        }
        let cycles = counters["voted"].as_u64().unwrap() + counters["abstained"].as_u64().unwrap();
        assert!(cycles >= 90, "{mode}: the mission stopped with it: {out}");
        let fault = r["behaviour_faults"]["bad"].as_str().unwrap_or_default();
        assert!(fault.contains(reason), "{mode}: {fault}\n{out}");
        assert!(
            fault.contains("now going wrong"),
            "{mode}: its last words: {fault}"
        );
        assert!(
            out.contains("bad           ENDED: external behaviour bad"),
            "{out}"
        );
        assert_eq!(r["outcome"], "timeout", "{mode}: {out}");
        assert!(took.as_secs() < 60, "{mode} took {took:?}");
    }
    for (mode, counter) in [
        ("wrong_arcs", "refused_invalid"),
        ("future", "refused_from_the_future"),
        ("undecodable", "refused_undecodable"),
    ] {
        let (_, r, out, _) = misbehaving(mode, "");
        let counters = &r["behaviour_counters"]["bad"];
        assert_eq!(counters["ended"], 0, "{mode}: {out}");
        assert_eq!(counters["voted"], 3, "{mode}: {out}");
        let refused = counters[counter].as_u64().unwrap();
        assert_eq!(
            refused,
            counters["abstained"].as_u64().unwrap(),
            "{mode}: {out}"
        );
        assert!(refused >= 90, "{mode}: {out}");
    }
}

/// A required program that ends ends the mission at once: the vehicle
/// could never move again.
#[test]
fn a_required_behaviour_that_crashes_ends_the_mission() {
    if python().is_none() {
        return;
    }
    let (code, r, out, took) = misbehaving("crash", "[arbiter]\nrequired = [\"bad\"]\n");
    assert_eq!(code, 1, "{out}");
    assert_eq!(r["outcome"], "behaviour_failed", "{out}");
    assert!(r["duration_s"].as_f64().unwrap() < 2.0, "{out}");
    assert!(out.contains("FAILED: a required behaviour ended"), "{out}");
    assert!(took.as_secs() < 60);
}

/// No command, or a program that cannot start: refused before the run,
/// with what to do.
#[test]
fn an_external_behaviour_without_a_runnable_command_is_refused_up_front() {
    let dir = arcnav_testkit::scratch_dir("external-refused");
    for (toml, expect) in [
        (
            "[behaviours.external.mine]\n[arbiter.weights]\nmine = 1.0\n",
            "behaviours.external.mine has no `command`",
        ),
        (
            "[behaviours.external.mine]\ncommand = [\"/nonexistent/mine\"]\n",
            "cannot start behaviours.external.mine (/nonexistent/mine)",
        ),
    ] {
        let config = dir.join("c.toml");
        std::fs::write(&config, toml).unwrap();
        let (code, stdout, stderr) = sim_open_field(&dir, &config, &dir.join("out"));
        assert_ne!(code, 0, "{stdout}");
        assert!(stderr.contains(expect), "{stderr}");
    }
}
