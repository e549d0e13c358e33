//! Issue 64: `arcnav replay` of ROS 2 bags (MCAP, CDR). The bags are
//! written by the reference writer (PyPI rosbags, installed by
//! scripts/test-tools; under CI these tests never skip) from a simulated
//! run's inputs (`tests/tools/lcm_to_bag.py`, which reads the run's LCM
//! log with the reference `lcm`): replayed, each gives the decisions of
//! the log it came from. Damaged bags end with exit status 3 and say what
//! was lost.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use arcnav_bus::Message as _;
use arcnav_bus::lcmtypes::steering_command_t;
use arcnav_bus::log::LogReader;
use arcnav_bus::messages::channels;
use arcnav_testkit::{LcmReference, workspace_root};

/// `arcnav ARGS…`: exit code, stdout, stderr.
fn arcnav(args: &[&str]) -> (i32, String, String) {
    let _slot = arcnav_testkit::cpu_slot();
    let out = Command::new(env!("CARGO_BIN_EXE_arcnav"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The run a bag is made from (`short_course` with a sensor), and a
/// directory of the test's own for what it writes.
struct Run {
    /// Holds `run/` (the log and its config.toml): made once for this
    /// build of the tests and shared by their processes, never written.
    shared: PathBuf,
    /// Removed when the test passes.
    work: arcnav_testkit::ScratchDir,
}

impl Run {
    fn log(&self) -> PathBuf {
        self.shared.join("run/mission.lcm")
    }

    fn config(&self) -> PathBuf {
        self.shared.join("run/config.toml")
    }

    /// A file of this test's own, `name`.
    fn out(&self, name: &str) -> PathBuf {
        self.work.join(name)
    }
}

/// `short_course` with `sensor` ("-sliced": its images streamed in slices
/// of 16 columns, as `sim_mission`'s streamed missions are), made once for
/// this build of the tests ([`arcnav_testkit::shared_file`]); the lidar's
/// runs end at 6 s (a timeout, exit status 1): its bags take its first
/// seconds only.
fn run(sensor: &str) -> Run {
    let shared = arcnav_testkit::shared_file(&format!("bag-run-{sensor}"), |dir| {
        std::fs::create_dir_all(dir).unwrap();
        let out = dir.join("run");
        let limit = dir.join("six-seconds.toml");
        let (sensor, sliced) = match sensor.strip_suffix("-sliced") {
            Some(sensor) => (
                sensor,
                "slice_lines = 16\n[pipeline]\nperception_latency_s = 0.02\n",
            ),
            None => (sensor, ""),
        };
        std::fs::write(&limit, format!("[sim]\ntime_limit_s = 6.0\n{sliced}")).unwrap();
        let mut args = vec![
            "sim",
            "--world",
            "short_course",
            "--sensor",
            sensor,
            "--out",
            out.to_str().unwrap(),
        ];
        if sensor != "erim" {
            args.extend(["--config", limit.to_str().unwrap()]);
        }
        let (code, stdout, stderr) = arcnav(&args);
        assert!(
            out.join("mission.lcm").is_file(),
            "{code}: {stdout}\n{stderr}"
        );
        assert_eq!(
            code,
            if sensor == "erim" { 0 } else { 1 },
            "{stdout}\n{stderr}"
        );
    });
    Run {
        shared,
        work: arcnav_testkit::scratch_dir(&format!("arcnav-bag-{sensor}")),
    }
}

/// A bag of `run`'s log written by rosbags (`lcm_to_bag.py ARGS`): the
/// path of its .mcap (or .bag), or `None` when the reference tools are
/// missing (a failure under CI).
fn make_bag(run: &Run, name: &str, args: &[&str]) -> Option<PathBuf> {
    let (reference, types) = LcmReference::with_arcnav_types()?;
    let out = run.out(name);
    let output = reference
        .python()
        .arg(workspace_root().join("tests/tools/lcm_to_bag.py"))
        .arg(run.log())
        .arg(&out)
        .args(args)
        .env("PYTHONPATH", types)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    if !output.status.success() && stderr.contains("No module named 'rosbags'") {
        arcnav_testkit::missing("the reference ROS bag writer (PyPI rosbags)");
        return None;
    }
    assert!(output.status.success(), "lcm_to_bag.py {args:?}: {stderr}");
    if out.is_file() {
        return Some(out);
    }
    let mcap = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().path())
        .find(|p| p.extension().is_some_and(|e| e == "mcap"))
        .expect("a ROS 2 bag holds a .mcap");
    Some(mcap)
}

/// `lcm_to_bag.py`'s arguments for a ROS 2 bag of organized clouds and
/// odometry over the log's first `seconds`, and `extra`.
fn organized<'a>(seconds: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec![
        "--format",
        "mcap",
        "--cloud",
        "organized",
        "--poses",
        "odometry",
        "--seconds",
        seconds,
    ];
    args.extend_from_slice(extra);
    args
}

/// `arcnav replay BAG` with the run's configuration and the course's
/// waypoints, and `extra`; the recomputed log is `out`.
fn replay(run: &Run, bag: &Path, out: &Path, extra: &[&str]) -> (i32, String, String) {
    let config = run.config();
    let waypoints = workspace_root().join("sim/worlds/short_course.toml");
    let mut args = vec![
        "replay",
        bag.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    if !extra.contains(&"--goal-ahead") {
        args.extend(["--waypoints", waypoints.to_str().unwrap()]);
    }
    args.extend_from_slice(extra);
    arcnav(&args)
}

/// A log's steering commands by their cycle's time: (curvature, speed).
fn commands(log: &Path) -> BTreeMap<i64, (f64, f64)> {
    LogReader::open(log)
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.channel == channels::STEERING_COMMAND)
        .map(|e| {
            let c = steering_command_t::decode(&e.data).unwrap();
            (c.utime, (c.curvature, c.speed))
        })
        .collect()
}

/// Every cycle of `replayed` is a cycle of `recorded` with the same
/// command; `replayed` has at least `min` of them.
fn assert_same_decisions(tag: &str, recorded: &Path, replayed: &Path, min: usize) {
    let (a, b) = (commands(recorded), commands(replayed));
    assert!(b.len() >= min, "{tag}: {} decisions", b.len());
    let differing: Vec<_> = b
        .iter()
        .filter(|(t, (k, v))| {
            a.get(t)
                .is_none_or(|(k0, v0)| (k - k0).abs() > 1e-6 || (v - v0).abs() > 1e-6)
        })
        .take(5)
        .collect();
    assert!(
        differing.is_empty(),
        "{tag}: {} decisions, these differ from the log's own: {differing:?}",
        b.len()
    );
}

#[test]
fn bags_written_by_rosbags_replay_to_the_decisions_of_the_log_they_came_from() {
    let erim = run("erim");
    // Each cloud layout, each kind of pose.
    for (name, args) in [
        (
            "organized-odometry",
            &["--cloud", "organized", "--poses", "odometry"],
        ),
        ("rings-tf", &["--cloud", "rings", "--poses", "tf"]),
        ("xyz-pose", &["--cloud", "xyz", "--poses", "pose"]),
    ] {
        let mut all = vec!["--format", "mcap", "--seconds", "30"];
        all.extend_from_slice(args);
        let Some(bag) = make_bag(&erim, name, &all) else {
            return;
        };
        let out = erim.out(&format!("{name}.lcm"));
        let (code, stdout, stderr) = replay(&erim, &bag, &out, &[]);
        assert_eq!(code, 0, "{name}:\n{stdout}\n{stderr}");
        assert!(stdout.contains("problems      none"), "{name}:\n{stdout}");
        assert!(
            stdout.contains("mount         from /tf_static: base_link ← lidar"),
            "{name}:\n{stdout}"
        );
        // The course's first 30 s: a decision every 0.1 s.
        assert_same_decisions(name, &erim.log(), &out, 295);
    }
    // The 64-beam lidar's 64 × 2048 organized clouds, 4 s of them.
    let lidar = run("lidar64");
    let args = organized("4", &[]);
    let Some(bag) = make_bag(&lidar, "organized-odometry", &args) else {
        return;
    };
    let out = lidar.out("organized.lcm");
    let (code, stdout, stderr) = replay(&lidar, &bag, &out, &[]);
    assert_eq!(code, 0, "lidar64:\n{stdout}\n{stderr}");
    assert!(
        stdout.contains("clouds        41 organized from /points"),
        "{stdout}"
    );
    assert_same_decisions("lidar64", &lidar.log(), &out, 40);
}

#[test]
fn a_bag_replays_toward_a_goal_ahead_and_names_what_it_cannot_choose() {
    let erim = run("erim");
    let Some(bag) = make_bag(&erim, "goal", &organized("10", &[])) else {
        return;
    };
    let out = erim.out("goal.lcm");
    let (code, stdout, stderr) = replay(&erim, &bag, &out, &["--goal-ahead", "30"]);
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    assert!(stdout.contains("1 waypoint lists"), "{stdout}");
    assert!(commands(&out).len() >= 90, "{stdout}");
    // A topic that is not there, or not of the kind asked for.
    let (code, _, stderr) = replay(&erim, &bag, &out, &["--cloud", "/velodyne_points"]);
    assert_eq!(code, 1);
    assert!(
        stderr.contains(
            "the bag has no topic /velodyne_points; its topics: /odom (nav_msgs/msg/Odometry, "
        ),
        "{stderr}"
    );
    let (code, _, stderr) = replay(&erim, &bag, &out, &["--pose", "/points"]);
    assert_eq!(code, 1);
    assert!(
        stderr.contains("/points is a sensor_msgs/msg/PointCloud2, not a pose"),
        "{stderr}"
    );
}

/// ROS 1 bags written by rosbags (Noetic's types), their chunks stored
/// plain, bz2- and lz4-compressed, each kind of cloud and pose: the
/// decisions of the log they came from, as the MCAP bags give.
#[test]
fn ros_1_bags_replay_to_the_decisions_of_the_log_they_came_from() {
    let erim = run("erim");
    for (name, compression, cloud, poses) in [
        ("ros1-none.bag", "none", "organized", "odometry"),
        ("ros1-bz2.bag", "bz2", "rings", "tf"),
        ("ros1-lz4.bag", "lz4", "xyz", "pose"),
    ] {
        let args = [
            "--format",
            "ros1",
            "--compression",
            compression,
            "--cloud",
            cloud,
            "--poses",
            poses,
            "--seconds",
            "10",
        ];
        let Some(bag) = make_bag(&erim, name, &args) else {
            return;
        };
        let out = erim.out(&format!("{name}.lcm"));
        let (code, stdout, stderr) = replay(&erim, &bag, &out, &[]);
        assert_eq!(code, 0, "{name}:\n{stdout}\n{stderr}");
        assert!(stdout.contains("ROS 1 (bag)"), "{name}:\n{stdout}");
        assert!(stdout.contains("problems      none"), "{name}:\n{stdout}");
        assert!(
            stdout.contains("mount         from /tf_static: base_link ← lidar"),
            "{name}:\n{stdout}"
        );
        assert_same_decisions(name, &erim.log(), &out, 95);
        if compression != "lz4" {
            continue;
        }
        // Cut two thirds in (a copy interrupted): what the whole chunks
        // hold replays, the loss named, exit 3.
        let bytes = std::fs::read(&bag).unwrap();
        let cut = erim.out("ros1-cut.bag");
        std::fs::write(&cut, &bytes[..bytes.len() * 2 / 3]).unwrap();
        let (code, stdout, stderr) = replay(&erim, &cut, &out, &[]);
        assert_eq!(code, 3, "cut:\n{stdout}\n{stderr}");
        assert!(stdout.contains("the bag is damaged"), "cut:\n{stdout}");
        assert!(stdout.contains("cut short"), "cut:\n{stdout}");
        assert_same_decisions("cut", &erim.log(), &out, 30);
    }
}

/// Where each record of an MCAP file starts (after its magic), with its
/// opcode: opcode u8, length u64 LE, body.
fn records(bytes: &[u8]) -> Vec<(usize, u8)> {
    let mut at = 8;
    let mut found = Vec::new();
    while at + 9 <= bytes.len() {
        let op = bytes[at];
        let len = u64::from_le_bytes(bytes[at + 1..at + 9].try_into().unwrap()) as usize;
        found.push((at, op));
        if op == 0x02 {
            break; // the footer
        }
        at += 9 + len;
    }
    found
}

#[test]
fn a_damaged_bag_ends_in_a_clear_message_and_exit_3_with_counts() {
    let erim = run("erim");
    let Some(bag) = make_bag(&erim, "damage", &organized("20", &["--rewrite"])) else {
        return;
    };
    let bytes = std::fs::read(&bag).unwrap();
    let chunks: Vec<usize> = records(&bytes)
        .into_iter()
        .filter(|&(_, op)| op == 0x06)
        .map(|(at, _)| at)
        .collect();
    assert!(chunks.len() >= 3, "{} chunks", chunks.len());
    let out = erim.out("damage.lcm");
    let damaged = erim.out("damaged.mcap");
    let check = |what: &str, bytes: &[u8], says: &str| {
        std::fs::write(&damaged, bytes).unwrap();
        let (code, stdout, stderr) = replay(&erim, &damaged, &out, &[]);
        assert_eq!(code, 3, "{what}:\n{stdout}\n{stderr}");
        assert!(stdout.contains(says), "{what}: not {says:?}:\n{stdout}");
        // What came before the damage was replayed.
        assert!(!commands(&out).is_empty(), "{what}:\n{stdout}");
    };
    // Cut in the middle of its third chunk.
    check("truncated", &bytes[..chunks[2] + 100], "the bag is damaged");
    // A byte of the third chunk's records changed (written by the
    // reference writer with CRCs): its CRC no longer holds.
    let mut flipped = bytes.clone();
    flipped[chunks[2] + 200] ^= 0x40;
    check("a chunk's CRC", &flipped, "the bag is damaged");
    // A record declaring 2 GB, put before the third chunk.
    let mut huge = bytes[..chunks[2]].to_vec();
    huge.push(0x05);
    huge.extend_from_slice(&(2u64 << 30).to_le_bytes());
    huge.extend_from_slice(&[0u8; 64]);
    huge.extend_from_slice(&bytes[chunks[2]..]);
    check("a 2 GB record", &huge, "the bag is damaged");
    // The cloud topic's schema is not ROS 2's: every cloud counted, none
    // misread.
    let Some(renamed) = make_bag(
        &erim,
        "renamed",
        &organized("3", &["--cloud-schema-renamed"]),
    ) else {
        return;
    };
    let (code, stdout, stderr) = replay(&erim, &renamed, &out, &[]);
    assert_eq!(code, 3, "{stdout}\n{stderr}");
    assert!(
        stdout.contains(
            "7 message(s) of /points: its schema differs from ROS 2's: PointCloud2's field 7 is \
             `uint32 row_stride`, not `uint32 row_step`"
        ),
        "{stdout}"
    );
    assert!(
        stdout.contains("inputs        151 poses, 0 range images"),
        "{stdout}"
    );
}

/// Real frames (tests/bags/README.md): an Ouster OS-1-128 standing in a
/// street, three organized clouds of 128 × 1024. Replayed with the
/// 128-beam lidar's configuration, every frame is evaluated and a
/// decision made every cycle; the parked cars and walls along both sides
/// of the street (7-12 m to either side) are obstacle cells, the road
/// ahead (5-15 m) is clear but for one return 2 m above it in the first
/// frame only.
#[test]
fn real_ouster_frames_replay_with_the_street_s_sides_as_obstacles_and_its_road_clear() {
    use arcnav_bus::lcmtypes::obstacle_cells_t;
    let dir = arcnav_testkit::temp_dir("bag-ouster");
    let config = dir.join("lidar128.toml");
    std::fs::write(&config, "[sensor]\npreset = \"lidar128\"\n").unwrap();
    let out = dir.join("ouster.lcm");
    let bag = workspace_root().join("tests/bags/ouster-os1-128.mcap");
    let (code, stdout, stderr) = arcnav(&[
        "replay",
        bag.to_str().unwrap(),
        "--config",
        config.to_str().unwrap(),
        "--goal-ahead",
        "20",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    assert!(
        stdout.contains("clouds        3 organized from /os_cloud"),
        "{stdout}"
    );
    assert!(stdout.contains("3 range images"), "{stdout}");
    assert!(
        stdout.contains("mount         from /tf_static: base_link ← os_sensor"),
        "{stdout}"
    );
    // Poses over 1.2 s: a decision every 0.1 s.
    assert!(commands(&out).len() >= 12, "{stdout}");
    let mut cells = std::collections::BTreeSet::new();
    let mut reports = 0;
    for event in LogReader::open(&out).unwrap().map(|e| e.unwrap()) {
        if event.channel == channels::OBSTACLE_CELLS {
            reports += 1;
            let report =
                arcnav_wire::obstacles_from_wire(obstacle_cells_t::decode(&event.data).unwrap())
                    .unwrap();
            for cell in &report.cells {
                cells.insert((
                    (cell.x * 10.0).round() as i64,
                    (cell.y * 10.0).round() as i64,
                ));
            }
        }
    }
    assert_eq!(reports, 3, "one report per frame");
    let count = |x: (f64, f64), y: (f64, f64)| {
        cells
            .iter()
            .filter(|&&(cx, cy)| {
                let (cx, cy) = (cx as f64 / 10.0, cy as f64 / 10.0);
                cx > x.0 && cx < x.1 && cy > y.0 && cy < y.1
            })
            .count()
    };
    let (left, right) = (
        count((-20.0, 20.0), (7.0, 12.0)),
        count((-20.0, 20.0), (-12.0, -7.0)),
    );
    let road = count((5.0, 15.0), (-3.0, 3.0));
    assert!(
        left >= 300 && right >= 300,
        "the street's sides: {left} cells left, {right} right"
    );
    assert!(road <= 2, "{road} cells on the road 5-15 m ahead");
}

/// Issue 64's round trip: `arcnav export LOG --bag OUT.mcap` writes a ROS 2
/// bag of standard messages only, which the reference readers (PyPI mcap
/// and rosbags, each type built from the definition the bag carries) read
/// whole, and which `arcnav replay` plays to the decisions of the log it
/// came from.
#[test]
fn a_run_exported_as_a_ros_2_bag_is_read_by_ros_tools_and_replays_to_its_own_decisions() {
    let erim = run("erim");
    let log = erim.log();
    let bag = erim.out("exported.mcap");
    let (code, stdout, stderr) = arcnav(&[
        "export",
        log.to_str().unwrap(),
        "--bag",
        bag.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    // Every event used or counted: the votes and decisions have no
    // standard message, and say so.
    assert!(
        stderr.contains("on DECISION: no standard ROS 2 message"),
        "{stderr}"
    );

    // What the log holds, to compare with.
    let (mut poses, mut images, mut first_returns) = (0, 0, None);
    for event in LogReader::open(&log).unwrap() {
        let event = event.unwrap();
        poses += usize::from(event.channel == channels::POSE);
        if event.channel.starts_with(channels::RANGE_IMAGE) {
            images += 1;
            if first_returns.is_none()
                && let Ok(Some(arcnav_bus::messages::AnyMessage::RangeImage(msg))) =
                    arcnav_bus::messages::AnyMessage::decode(&event.data)
            {
                let image = arcnav_wire::range_image_from_wire(msg).unwrap();
                first_returns = Some(arcnav::export::returns(&image));
            }
        }
    }
    let recorded = commands(&log);

    let Some((reference, _)) = LcmReference::with_arcnav_types() else {
        return;
    };
    let output = reference
        .python()
        .arg(workspace_root().join("tests/tools/read_ros2_bag.py"))
        .arg(&bag)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&output.stderr);
    if !output.status.success() && stderr.contains("No module named 'rosbags'") {
        arcnav_testkit::missing("the reference ROS bag reader (PyPI rosbags)");
        return;
    }
    assert!(output.status.success(), "read_ros2_bag.py: {stderr}");
    let read: serde_json::Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(read["profile"], "ros2");
    let topics = read["topics"].as_object().unwrap();
    for (topic, ty, count) in [
        ("/odom", "nav_msgs/msg/Odometry", poses),
        ("/tf", "tf2_msgs/msg/TFMessage", poses),
        ("/tf_static", "tf2_msgs/msg/TFMessage", 1),
        ("/points_erim", "sensor_msgs/msg/PointCloud2", images),
        (
            "/cmd",
            "ackermann_msgs/msg/AckermannDriveStamped",
            recorded.len(),
        ),
        (
            "/arcs",
            "visualization_msgs/msg/MarkerArray",
            recorded.len(),
        ),
        (
            "/obstacle_cells",
            "visualization_msgs/msg/MarkerArray",
            images,
        ),
        ("/waypoints", "visualization_msgs/msg/MarkerArray", 1),
    ] {
        let t = &topics[topic];
        assert_eq!(t["type"], ty, "{topic}");
        assert_eq!(t["count"], count, "{topic}");
        assert_eq!(t["schema_encoding"], "ros2msg", "{topic}");
        assert_eq!(t["encoding"], "cdr", "{topic}");
        assert_eq!(t["increasing"], true, "{topic}");
    }
    // The local map rebuilt each decision cycle (the log holds none).
    assert_eq!(topics["/local_map"]["count"], recorded.len());
    // The frames a ROS user expects (REP 105), the mount latched.
    assert_eq!(
        read["frames"]["/odom"],
        serde_json::json!(["odom", "base_link"])
    );
    assert_eq!(
        read["frames"]["/tf"],
        serde_json::json!([["odom", "base_link"]])
    );
    assert_eq!(
        read["frames"]["/tf_static"],
        serde_json::json!([["base_link", "erim"]])
    );
    assert!(
        topics["/tf_static"]["qos"]
            .as_str()
            .unwrap()
            .contains("durability: 1"),
        "{}",
        topics["/tf_static"]["qos"]
    );
    // The ERIM's 64 × 256 image, organized, its returns (range = distance
    // from the sensor, checked point by point by the reader) and no more.
    let cloud = &read["clouds"][0];
    assert_eq!(cloud["frame"], "erim");
    assert_eq!(
        (cloud["height"].as_u64(), cloud["width"].as_u64()),
        (Some(64), Some(256))
    );
    assert_eq!(
        cloud["fields"],
        serde_json::json!([["x", 0, 7], ["y", 4, 7], ["z", 8, 7], ["range", 12, 7]])
    );
    assert_eq!(cloud["returns"].as_u64(), first_returns.map(|n| n as u64));
    // Commands: the steering angle of the curvature over the HMMWV's
    // wheelbase, the speed, each at its cycle's time.
    let wheelbase = arcnav::Config::default().vehicle.wheelbase_m;
    let commands = read["commands"].as_array().unwrap();
    assert_eq!(commands.len(), 50);
    for c in commands {
        let (curvature, speed) = recorded[&c["utime"].as_i64().unwrap()];
        let angle = c["steering_angle"].as_f64().unwrap();
        assert!(((wheelbase * curvature).atan() - angle).abs() < 1e-6, "{c}");
        assert!((speed - c["speed"].as_f64().unwrap()).abs() < 1e-6, "{c}");
    }
    let markers = &read["markers"];
    assert_eq!(markers["/arcs"]["types"], serde_json::json!([4]));
    assert_eq!(markers["/arcs"]["frames"], serde_json::json!(["base_link"]));
    assert_eq!(markers["/arcs"]["most_points"], 25);
    assert_eq!(markers["/local_map"]["types"], serde_json::json!([6]));
    assert!(markers["/local_map"]["most_points"].as_u64().unwrap() > 50);
    assert_eq!(
        markers["/obstacle_cells"]["frames"],
        serde_json::json!(["odom"])
    );
    assert_eq!(markers["/waypoints"]["types"], serde_json::json!([2]));

    // Replayed, the bag gives the log's own decisions, every one of them.
    let out = erim.out("exported.lcm");
    let (code, stdout, stderr) = replay(&erim, &bag, &out, &[]);
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    assert!(stdout.contains("problems      none"), "{stdout}");
    assert!(
        stdout.contains("mount         from /tf_static: base_link ← erim"),
        "{stdout}"
    );
    assert!(
        stdout.contains("/cmd (ackermann_msgs/msg/AckermannDriveStamped"),
        "{stdout}"
    );
    assert_same_decisions("exported", &log, &out, recorded.len());
}

/// A streamed run's slices gathered into organized clouds with Ouster's
/// per-point time field `t` (as an Ouster driver publishes a frame): the
/// replay streams each cloud to perception again as slices of 16 columns
/// at their times, among the poses as the sensor sent them, and gives the
/// streamed log's own decisions; `--slice-lines 0` makes each cloud one
/// image.
#[test]
fn clouds_with_per_point_times_replay_as_the_slices_they_were_streamed_in() {
    let sliced = run("lidar64-sliced");
    let args = [
        "--format",
        "mcap",
        "--cloud",
        "organized-timed",
        "--poses",
        "odometry",
        "--seconds",
        "3",
    ];
    let Some(bag) = make_bag(&sliced, "timed", &args) else {
        return;
    };
    let out = sliced.out("timed.lcm");
    let (code, stdout, stderr) = replay(&sliced, &bag, &out, &[]);
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    assert!(stdout.contains("problems      none"), "{stdout}");
    assert!(
        stdout.contains("slices of 16 columns, each at its points' times (field t)"),
        "{stdout}"
    );
    let log = sliced.log();
    // Each 64 × 2048 cloud 128 slices, and nothing else to perception.
    let clouds: usize = stdout
        .split("clouds        ")
        .nth(1)
        .and_then(|rest| rest.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("{stdout}"));
    assert!(clouds >= 25, "{stdout}");
    assert!(
        stdout.contains(&format!("from 0 images and {} slices", clouds * 128)),
        "{stdout}"
    );
    assert_same_decisions("timed", &log, &out, 28);
    // `--slice-lines 0`: each cloud one image at its stamp.
    let whole = sliced.out("whole.lcm");
    let (code, stdout, _) = replay(&sliced, &bag, &whole, &["--slice-lines", "0"]);
    assert_eq!(code, 0, "{stdout}");
    assert!(
        stdout.contains(&format!("from {clouds} images and 0 slices")),
        "{stdout}"
    );
}
