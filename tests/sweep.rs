//! `arcnav sweep` as a user runs it: the table, the summary, the picture,
//! reproducibility, interruption and resumption, and bad input refused
//! before any run.

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use arcnav_testkit::temp_dir;

/// Two short worlds × two cruise speeds, each run at most 25 simulated s.
const PLAN: [&str; 10] = [
    "--world",
    "short_course",
    "--seeds",
    "3..4",
    "--difficulty",
    "easy",
    "--set",
    "arbiter.cruise_speed_mps=2.5,4",
    "--set",
    "sim.time_limit_s=25",
];

fn sweep(args: &[&str], out: &Path) -> Command {
    let mut command = Command::new(env!("CARGO_BIN_EXE_arcnav"));
    command
        .arg("sweep")
        .args(args)
        .arg("--out")
        .arg(out)
        .stdin(Stdio::null());
    command
}

fn run(args: &[&str], out: &Path) -> Output {
    let _slot = arcnav_testkit::cpu_slot();
    sweep(args, out).output().unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// table.csv without its wall-time column (what the machine's load sets).
fn table_without_wall_time(out: &Path) -> String {
    let csv = std::fs::read_to_string(out.join("table.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let wall = header.iter().position(|h| *h == "wall_time_s").unwrap();
    csv.lines()
        .map(|line| {
            let mut fields: Vec<&str> = line.split(',').collect();
            fields.remove(wall);
            fields.join(",")
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn json(path: PathBuf) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn a_sweep_writes_a_reproducible_table_a_consistent_summary_and_a_picture() {
    let out = temp_dir("sweep-a");
    let first = run(&PLAN, &out);
    assert_eq!(first.status.code(), Some(0), "{}", text(&first.stderr));

    // One row per world × setting, in plan order, with the right settings.
    let rows = json(out.join("table.json"));
    let rows = rows.as_array().unwrap();
    let got: Vec<(String, String, String)> = rows
        .iter()
        .map(|r| {
            (
                r["world"].as_str().unwrap().to_owned(),
                r["values"][0].as_str().unwrap().to_owned(),
                r["values"][1].as_str().unwrap().to_owned(),
            )
        })
        .collect();
    let want = |w: &str, v: &str| (w.to_owned(), v.to_owned(), "25.0".to_owned());
    assert_eq!(
        got,
        [
            want("short_course", "2.5"),
            want("short_course", "4.0"),
            want("seed 3 (easy)", "2.5"),
            want("seed 3 (easy)", "4.0"),
        ]
    );
    for r in rows {
        assert!(r["duration_s"].as_f64().unwrap() <= 25.0 + 1e-9, "{r}");
        assert!(r["distance_m"].as_f64().unwrap() > 10.0, "it drove: {r}");
    }
    // At 4 m/s the short course's first 25 s pass its ditch: the row says
    // how far ahead a hole or ditch was first reported.
    let first = rows[1]["drops_first_seen_min_m"].as_f64();
    assert!(
        first.is_some_and(|m| (5.0..40.0).contains(&m)),
        "{}",
        rows[1]
    );
    let csv = std::fs::read_to_string(out.join("table.csv")).unwrap();
    assert_eq!(csv.lines().count(), 5, "{csv}");
    assert!(
        csv.starts_with("run,world,arbiter.cruise_speed_mps,sim.time_limit_s,outcome,"),
        "{csv}"
    );

    // The summary is the rows', setting by setting.
    let summary = json(out.join("summary.json"));
    let summary = summary.as_array().unwrap();
    assert_eq!(summary.len(), 2);
    for s in summary {
        let of: Vec<&serde_json::Value> = rows
            .iter()
            .filter(|r| r["setting"] == s["setting"])
            .collect();
        assert_eq!(s["runs"].as_u64().unwrap(), of.len() as u64);
        let successes = of.iter().filter(|r| r["success"] == true).count();
        assert_eq!(s["successes"].as_u64().unwrap(), successes as u64);
        let speed = of
            .iter()
            .map(|r| r["average_speed_mps"].as_f64().unwrap())
            .sum::<f64>()
            / of.len() as f64;
        assert!((s["mean_speed_mps"].as_f64().unwrap() - speed).abs() < 1e-9);
        let worst = of
            .iter()
            .filter_map(|r| r["closest_approach_m"].as_f64())
            .fold(f64::INFINITY, f64::min);
        assert_eq!(s["worst_closest_approach_m"].as_f64().unwrap(), worst);
    }
    // A faster cruise drives faster on average.
    assert!(summary[1]["mean_speed_mps"].as_f64() > summary[0]["mean_speed_mps"].as_f64());

    // The picture decodes.
    let png = tiny_skia::Pixmap::load_png(out.join("sweep.png")).unwrap();
    assert!(png.width() >= 500 && png.height() >= 400);

    // The same command, elsewhere: the same table.
    let again = temp_dir("sweep-b");
    let second = run(&PLAN, &again);
    assert_eq!(second.status.code(), Some(0), "{}", text(&second.stderr));
    assert_eq!(
        table_without_wall_time(&out),
        table_without_wall_time(&again)
    );

    // A finished sweep is not overwritten by another.
    let refused = run(&PLAN, &out);
    assert_eq!(refused.status.code(), Some(1));
    assert!(text(&refused.stderr).contains("--resume carries it on"));
}

/// `--shard K/N` × 3 as three processes at once, merged: the table of one
/// unsharded sweep of the same plan (wall time aside); a shard missing,
/// given twice, of another plan, or merged over a sweep: refused.
#[test]
fn three_shards_merged_give_the_table_of_one_sweep_and_mixed_plans_are_refused() {
    let root = temp_dir("sweep-shards");
    let whole = root.join("whole");
    let shards: Vec<PathBuf> = (1..=3).map(|k| root.join(format!("shard{k}"))).collect();
    let mut running = vec![sweep(&PLAN, &whole).stderr(Stdio::piped()).spawn().unwrap()];
    for (k, dir) in shards.iter().enumerate() {
        let shard = format!("{}/3", k + 1);
        let mut args = PLAN.to_vec();
        args.extend(["--shard", &shard, "--jobs", "1"]);
        running.push(sweep(&args, dir).stderr(Stdio::piped()).spawn().unwrap());
    }
    for child in running {
        let out = child.wait_with_output().unwrap();
        assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    }
    // Each shard ran its own runs only: 0 and 3, 1, 2 of the four.
    let runs = |dir: &Path| -> Vec<u64> {
        json(dir.join("table.json"))
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["run"].as_u64().unwrap())
            .collect()
    };
    assert_eq!(runs(&shards[0]), [0, 3]);
    assert_eq!(runs(&shards[1]), [1]);
    assert_eq!(runs(&shards[2]), [2]);

    let merge = |dirs: &[&Path], out: &Path| {
        let mut command = Command::new(env!("CARGO_BIN_EXE_arcnav"));
        command
            .args(["sweep", "merge"])
            .args(dirs)
            .arg("--out")
            .arg(out);
        command.output().unwrap()
    };
    let merged = root.join("merged");
    let all: Vec<&Path> = shards.iter().map(PathBuf::as_path).collect();
    let out = merge(&[all[2], all[0], all[1]], &merged);
    assert_eq!(out.status.code(), Some(0), "{}", text(&out.stderr));
    assert_eq!(
        table_without_wall_time(&merged),
        table_without_wall_time(&whole)
    );
    for file in ["summary.csv", "sweep.json"] {
        let read = |dir: &Path| std::fs::read_to_string(dir.join(file)).unwrap();
        assert_eq!(read(&merged), read(&whole), "{file}");
    }
    assert_eq!(runs(&merged), [0, 1, 2, 3]);
    // The merged directory is a whole sweep: resumed, it has nothing to do.
    let resumed = run(&[&PLAN[..], &["--resume"]].concat(), &merged);
    assert_eq!(resumed.status.code(), Some(0), "{}", text(&resumed.stderr));
    assert!(
        text(&resumed.stderr).contains("(4 already done)"),
        "{}",
        text(&resumed.stderr)
    );

    let refused = |dirs: &[&Path], out: &Path, says: &str| {
        let out = merge(dirs, out);
        let stderr = text(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(stderr.contains(says), "{says}: {stderr}");
    };
    refused(&all[..2], &root.join("m1"), "no directory holds shard 3/3");
    refused(
        &[all[0], all[1], all[1]],
        &root.join("m2"),
        "shard 2/3 is given twice",
    );
    refused(
        &[all[0], &whole],
        &root.join("m3"),
        "is of a plan in 3 shards",
    );
    refused(&all, &whole, "already holds a sweep");
    refused(&all, all[0], "it is one of the shards given");
    // A shard of another plan (its worlds' digests differ).
    let other = root.join("other");
    std::fs::create_dir_all(&other).unwrap();
    std::fs::copy(shards[2].join("rows.jsonl"), other.join("rows.jsonl")).unwrap();
    let mut plan = json(shards[2].join("sweep.json"));
    plan["world_digests"][0] = "0".repeat(64).into();
    std::fs::write(other.join("sweep.json"), plan.to_string()).unwrap();
    refused(
        &[all[0], all[1], &other],
        &root.join("m4"),
        "holds another sweep than",
    );
    // Resuming a shard as another shard: another sweep.
    let wrong = run(
        &[&PLAN[..], &["--resume", "--shard", "2/3"]].concat(),
        &shards[0],
    );
    assert_eq!(wrong.status.code(), Some(1), "{}", text(&wrong.stderr));
    assert!(
        text(&wrong.stderr).contains("shard 1/3, not 2/3"),
        "{}",
        text(&wrong.stderr)
    );
    // A bad shard is refused before any run.
    let bad = run(
        &[&PLAN[..], &["--shard", "4/3"]].concat(),
        &root.join("bad"),
    );
    assert_eq!(bad.status.code(), Some(2), "{}", text(&bad.stderr));
    assert!(
        text(&bad.stderr).contains("expected K/N"),
        "{}",
        text(&bad.stderr)
    );
}

#[test]
fn an_interrupted_sweep_resumed_gives_the_table_of_an_uninterrupted_one() {
    let whole = temp_dir("sweep-whole");
    let done = run(&PLAN, &whole);
    assert_eq!(done.status.code(), Some(0), "{}", text(&done.stderr));

    // One run at a time; interrupted once the first row is on disk.
    let out = temp_dir("sweep-cut");
    let args: Vec<&str> = PLAN.iter().copied().chain(["--jobs", "1"]).collect();
    let child = sweep(&args, &out)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let rows = out.join("rows.jsonl");
    let deadline = Instant::now() + Duration::from_secs(120);
    while std::fs::read_to_string(&rows).map_or(0, |t| t.lines().count()) < 1 {
        assert!(Instant::now() < deadline, "no row after 120 s");
        std::thread::sleep(Duration::from_millis(20));
    }
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let cut = child.wait_with_output().unwrap();
    let stderr = text(&cut.stderr);
    assert_eq!(cut.status.code(), Some(130), "{stderr}");
    assert!(stderr.contains("--resume carries on"), "{stderr}");
    let kept = std::fs::read_to_string(&rows).unwrap().lines().count();
    assert!((1..4).contains(&kept), "{kept} rows kept");
    // The partial tables hold what was done.
    let partial = std::fs::read_to_string(out.join("table.csv")).unwrap();
    assert_eq!(partial.lines().count(), 1 + kept);

    let resumed = run(&[&args[..], &["--resume"]].concat(), &out);
    let stderr = text(&resumed.stderr);
    assert_eq!(resumed.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains(&format!("({kept} already done)")),
        "{stderr}"
    );
    assert_eq!(
        table_without_wall_time(&out),
        table_without_wall_time(&whole)
    );

    // Resuming with other settings is refused.
    let other: Vec<&str> = PLAN
        .iter()
        .map(|a| {
            if *a == "arbiter.cruise_speed_mps=2.5,4" {
                "arbiter.cruise_speed_mps=3"
            } else {
                a
            }
        })
        .chain(["--resume"])
        .collect();
    let refused = run(&other, &out);
    assert_eq!(refused.status.code(), Some(1));
    assert!(text(&refused.stderr).contains("holds another sweep"));
}

/// `--resume` carries on this plan's runs only: a row edited to another
/// world or value is not tabulated but run again, and a world file
/// changed since the sweep started makes it another sweep (both had been
/// mixed in under one label).
#[test]
fn a_resumed_sweep_takes_only_rows_of_its_own_plan_and_worlds() {
    let dir = temp_dir("sweep-own");
    let world = dir.join("ditch.toml");
    let source = arcnav_testkit::workspace_root().join("tests/worlds/short_ditch.toml");
    std::fs::write(&world, std::fs::read_to_string(source).unwrap()).unwrap();
    let out = dir.join("out");
    let plan = [
        "--world",
        world.to_str().unwrap(),
        "--set",
        "arbiter.cruise_speed_mps=2.5",
        "--set",
        "sim.time_limit_s=4",
    ];
    let first = run(&plan, &out);
    assert_eq!(first.status.code(), Some(0), "{}", text(&first.stderr));
    let table = table_without_wall_time(&out);
    // A row edited to another value.
    let rows = out.join("rows.jsonl");
    let edited = std::fs::read_to_string(&rows)
        .unwrap()
        .replace("\"2.5\"", "\"9\"");
    std::fs::write(&rows, edited).unwrap();
    let resumed = run(&[&plan[..], &["--resume"]].concat(), &out);
    let stderr = text(&resumed.stderr);
    assert_eq!(resumed.status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("1 rows of") && stderr.contains("not runs of this plan"),
        "{stderr}"
    );
    assert_eq!(table_without_wall_time(&out), table);
    // The world changed: another sweep.
    let changed = std::fs::read_to_string(&world)
        .unwrap()
        .replace("seed = 31", "seed = 32");
    std::fs::write(&world, changed).unwrap();
    let refused = run(&[&plan[..], &["--resume"]].concat(), &out);
    let stderr = text(&refused.stderr);
    assert_eq!(refused.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("changed since it started"), "{stderr}");
}

#[test]
fn bad_settings_and_worlds_are_refused_before_any_run_by_name() {
    let grid_dir = temp_dir("sweep-grid");
    let empty_grid = grid_dir.join("empty.toml");
    std::fs::write(&empty_grid, "\"arbiter.cruise_speed_mps\" = []\n").unwrap();
    let no_keys = grid_dir.join("none.toml");
    std::fs::write(&no_keys, "# nothing\n").unwrap();
    let broken_world = grid_dir.join("broken.toml");
    std::fs::write(&broken_world, "name = \"broken\"\n[terrain\n").unwrap();
    let (empty, none, broken) = (
        empty_grid.to_str().unwrap(),
        no_keys.to_str().unwrap(),
        broken_world.to_str().unwrap(),
    );
    let cases: [(&[&str], &str); 10] = [
        (
            &["--world", "short_course", "--set", "arbiter.cruise_speed=3"],
            "`arbiter.cruise_speed`: no such key",
        ),
        (
            &[
                "--world",
                "short_course",
                "--set",
                "arbiter.cruise_speed_mps=fast",
            ],
            "`arbiter.cruise_speed_mps` = fast",
        ),
        (
            &[
                "--world",
                "short_course",
                "--set",
                "arbiter.cruise_speed_mps=4,true",
            ],
            "is boolean, the key takes float",
        ),
        (
            &["--world", "short_course", "--grid", empty],
            "`arbiter.cruise_speed_mps` is swept over no values",
        ),
        (
            &["--world", "short_course", "--grid", none],
            "lists no keys",
        ),
        (&["--world", broken], "broken.toml"),
        (
            &["--world", "no_such_world"],
            "no embedded world named \"no_such_world\"",
        ),
        (&["--set", "arbiter.cruise_speed_mps=3"], "no worlds"),
        (
            &["--world", "short_course", "--jobs", "0"],
            "--jobs 0: at least one run",
        ),
        // It had started 9 500 threads for one run after 50 s, and did
        // not stop for SIGTERM.
        (
            &["--world", "short_course", "--jobs", "100000"],
            "--jobs 100000: at most 1024 runs at a time",
        ),
    ];
    for (args, expect) in cases {
        let out = temp_dir("sweep-bad");
        std::fs::remove_dir(&out).unwrap();
        let refused = run(args, &out);
        let stderr = text(&refused.stderr);
        assert_eq!(refused.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(stderr.contains(expect), "{args:?}: {stderr}");
        assert!(!out.exists(), "{args:?}: a run started");
    }
}
