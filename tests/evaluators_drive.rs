//! Missions with each terrain evaluator and with two sensors, as a user
//! runs them (`arcnav sim --evaluator`, `[[sensors]]`).

use std::path::PathBuf;
use std::process::Command;

use arcnav_bus::log::LogReader;
use serde_json::Value;

fn out_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("arcnav-eval-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// Runs `arcnav sim` with `args` into a fresh directory; the report and
/// the directory (for the log), and what it printed.
fn sim(tag: &str, args: &[&str]) -> (Value, PathBuf, String) {
    let out = out_dir(tag);
    let output = Command::new(env!("CARGO_BIN_EXE_arcnav"))
        .arg("sim")
        .args(["--out", out.to_str().unwrap()])
        .args(args)
        .output()
        .expect("the arcnav binary runs");
    let printed = format!(
        "{}\n{}",
        String::from_utf8_lossy(&output.stdout),
        String::from_utf8_lossy(&output.stderr)
    );
    let report = std::fs::read_to_string(out.join("report.json"))
        .unwrap_or_else(|e| panic!("{tag}: no report ({e}):\n{printed}"));
    (serde_json::from_str(&report).unwrap(), out, printed)
}

fn assert_completed(tag: &str, report: &Value, printed: &str) {
    assert_eq!(report["outcome"], "completed", "{tag}:\n{printed}");
    assert_eq!(
        report["collisions"].as_array().map(Vec::len),
        Some(0),
        "{tag}:\n{printed}"
    );
}

#[test]
fn each_evaluator_completes_the_papers_loop_and_the_short_course() {
    let runs = [
        ("paper_loop", "height_diff", "height difference"),
        ("paper_loop", "pca", "not flat"),
        ("short_course", "height_diff", "height difference"),
        ("short_course", "pca", "not flat"),
    ];
    let results: Vec<_> = std::thread::scope(|scope| {
        let handles: Vec<_> = runs
            .iter()
            .map(|(world, evaluator, _)| {
                scope.spawn(move || {
                    let tag = format!("{world}-{evaluator}");
                    let (report, out, printed) = sim(
                        &tag,
                        &["--world", world, "--evaluator", evaluator, "--no-images"],
                    );
                    let _ = std::fs::remove_dir_all(out);
                    (tag, report, printed)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    for ((tag, report, printed), (_, evaluator, reason)) in results.iter().zip(&runs) {
        assert_completed(tag, report, printed);
        assert!(
            printed.contains(&format!("and the {evaluator} evaluator")),
            "{tag}: {printed}"
        );
        // The evaluator's own judgement found obstacles (not only drop-offs).
        let found = report["untraversable_cells"][*reason].as_u64().unwrap_or(0);
        assert!(found > 100, "{tag}: {found} cells for {reason}:\n{printed}");
        for other in ["height variation", "discontinuity"] {
            assert_eq!(
                report["untraversable_cells"][other], 0,
                "{tag}: the cell classifier ran"
            );
        }
    }
}

#[test]
fn a_vehicle_with_a_front_lidar_and_a_rear_depth_camera_completes_the_short_course() {
    let out = out_dir("two-sensors-config");
    std::fs::create_dir_all(&out).unwrap();
    let config = out.join("two.toml");
    std::fs::write(
        &config,
        "[[sensors]]\npreset = \"lidar64\"\nrate_hz = 5.0\n\n\
         [[sensors]]\npreset = \"depth_camera\"\nid = \"rear\"\nrate_hz = 10.0\n\
         mount_position_m = [-0.6, 0.0, 2.0]\nmount_rpy_deg = [0.0, 25.0, 180.0]\n",
    )
    .unwrap();
    let (report, run, printed) = sim(
        "two-sensors",
        &[
            "--world",
            "short_course",
            "--config",
            config.to_str().unwrap(),
        ],
    );
    assert_completed("two sensors", &report, &printed);
    assert_eq!(report["sensor"], "lidar64+rear", "{printed}");
    // Both sensors' images are in the log, each on its own channel, at
    // its own rate.
    let mut counts = std::collections::BTreeMap::<String, u64>::new();
    for event in LogReader::open(run.join("mission.lcm")).unwrap() {
        let event = event.unwrap();
        if event.channel.starts_with("RANGE_IMAGE") {
            *counts.entry(event.channel.clone()).or_default() += 1;
        }
    }
    let (lidar, rear) = (counts["RANGE_IMAGE_LIDAR64"], counts["RANGE_IMAGE_REAR"]);
    assert!(lidar > 100 && rear > 100, "{counts:?}");
    assert!((rear as f64 / lidar as f64 - 2.0).abs() < 0.1, "{counts:?}");
    assert_eq!(report["images"].as_u64(), Some(lidar + rear));
    // The rear camera looks behind: the bound is the front lidar's (its
    // reach set by the map window, not by the camera's 10 m).
    assert_eq!(
        report["speed_bound"]["range_limited_by"], "map window",
        "{printed}"
    );
    let _ = std::fs::remove_dir_all(&run);
    let _ = std::fs::remove_dir_all(&out);
}
