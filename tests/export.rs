//! `arcnav export LOG --mcap OUT`, read back by the reference MCAP readers
//! (PyPI `mcap` with `mcap-protobuf-support` and Foxglove's protobuf
//! schemas): every channel of the log is there with as many messages, the
//! Foxglove schemas are the published ones, a point cloud decodes to the
//! image's returns, and log times never go back on any topic.

use std::collections::BTreeMap;
use std::process::Command;
use std::sync::Arc;

use arcnav::Config;
use arcnav::mission::{MissionOptions, run_mission};
use arcnav_bus::log::LogReader;
use arcnav_bus::messages::AnyMessage;
use arcnav_sim::World;
use arcnav_testkit::{LcmReference, temp_dir, workspace_root};

#[test]
fn an_exported_sim_run_reads_back_in_the_reference_mcap_reader() {
    let Some(reference) = LcmReference::require() else {
        return;
    };
    let dir = temp_dir("export");
    let log = dir.join("mission.lcm");
    let mut config = Config::default();
    config.sim.time_limit_s = 12.0;
    let world = Arc::new(World::embedded("short_course").unwrap().unwrap());
    let options = MissionOptions {
        log: Some(log.clone()),
        ..MissionOptions::default()
    };
    run_mission(&config.resolved().unwrap(), world, &options, &mut |_| {}).unwrap();

    // What the log holds: messages per channel, and the first image's returns.
    let mut channels: BTreeMap<String, u64> = BTreeMap::new();
    let mut first_returns = None;
    let mut reader = LogReader::open(&log).unwrap();
    while let Some(event) = reader.next_event().unwrap() {
        *channels.entry(event.channel.clone()).or_default() += 1;
        if first_returns.is_none()
            && let Ok(Some(AnyMessage::RangeImage(msg))) = AnyMessage::decode(&event.data)
        {
            let image = arcnav::wire::range_image_from_wire(msg).unwrap();
            first_returns = Some(arcnav::export::returns(&image));
        }
    }
    let first_returns = first_returns.expect("the log has images");
    assert!(first_returns > 1000, "{first_returns} returns");

    let mcap = dir.join("run.mcap");
    let out = Command::new(env!("CARGO_BIN_EXE_arcnav"))
        .args([
            "export",
            log.to_str().unwrap(),
            "--mcap",
            mcap.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // Refuses to write over its input.
    let refused = Command::new(env!("CARGO_BIN_EXE_arcnav"))
        .args([
            "export",
            log.to_str().unwrap(),
            "--mcap",
            log.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert_eq!(refused.status.code(), Some(1));
    assert!(
        !String::from_utf8_lossy(&out.stderr).contains("another arc set"),
        "the log's own arc set"
    );
    // Another arc set than the log's: its indices would mark the wrong
    // arcs; not drawn, and said (it had drawn them silently).
    let other = dir.join("arcs25.toml");
    std::fs::write(&other, "[arcs]\ncount = 25\n").unwrap();
    let other_mcap = dir.join("other.mcap");
    let mismatch = Command::new(env!("CARGO_BIN_EXE_arcnav"))
        .args(["export", log.to_str().unwrap(), "--mcap"])
        .args([
            other_mcap.to_str().unwrap(),
            "--config",
            other.to_str().unwrap(),
        ])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&mismatch.stderr);
    assert!(mismatch.status.success(), "{said}");
    assert!(
        said.contains("STEERING_COMMAND (/arcs)") && said.contains("another arc set"),
        "{said}"
    );
    assert!(
        said.contains("voted over 39 arcs, this arc set has 25"),
        "{said}"
    );

    let read = reference
        .python()
        .arg(workspace_root().join("tests/tools/read_mcap.py"))
        .arg(&mcap)
        .output()
        .unwrap();
    assert!(
        read.status.success(),
        "{}",
        String::from_utf8_lossy(&read.stderr)
    );
    let got: serde_json::Value = serde_json::from_slice(&read.stdout).unwrap();
    let topics = &got["topics"];

    // Every channel, as many messages; the published schemas; time forward.
    let expect = |topic: &str, count: u64, schema: &str| {
        let t = &topics[topic];
        assert_eq!(t["count"].as_u64(), Some(count), "{topic}: {t}");
        assert_eq!(t["schema"], schema, "{topic}");
        assert_eq!(t["increasing"], true, "{topic}: log times go back");
    };
    for (channel, &count) in &channels {
        match channel.as_str() {
            "POSE" => {
                expect("/pose", count, "foxglove.PoseInFrame");
                expect("/tf", count, "foxglove.FrameTransforms");
            }
            "STEERING_COMMAND" => {
                expect("/steering_command", count, "arcnav.SteeringCommand");
                expect("/arcs", count, "foxglove.SceneUpdate");
            }
            "DECISION" => expect("/decision", count, "arcnav.Decision"),
            "OBSTACLE_CELLS" | "WAYPOINTS" | "LOCAL_MAP" => {
                expect(
                    &arcnav::export::topic(channel),
                    count,
                    "foxglove.SceneUpdate",
                );
            }
            c if c.starts_with("RANGE_IMAGE") => {
                expect(&arcnav::export::topic(c), count, "foxglove.PointCloud");
            }
            c if c.starts_with("ARC_VOTES_") => {
                expect(&arcnav::export::topic(c), count, "arcnav.ArcVotes");
            }
            other => panic!("the log has a channel the test does not know: {other}"),
        }
    }
    assert!(channels.contains_key("RANGE_IMAGE_ERIM") && channels.contains_key("ARC_VOTES_ROUTE"));
    // A sim log holds no LOCAL_MAP: the map is rebuilt, one per decision
    // cycle (a command each), and it holds the cells seen.
    assert!(!channels.contains_key("LOCAL_MAP"));
    expect(
        "/local_map",
        channels["STEERING_COMMAND"],
        "foxglove.SceneUpdate",
    );
    assert!(
        got["most_local_map_patches"].as_u64().unwrap() > 10,
        "{got}"
    );

    // The first point cloud: every return of the first image, vehicle frame.
    let cloud = &got["cloud"];
    assert_eq!(
        cloud["points"].as_u64(),
        Some(first_returns as u64),
        "{cloud}"
    );
    assert_eq!(cloud["frame"], "vehicle");
    assert_eq!(cloud["fields"], serde_json::json!(["x", "y", "z", "range"]));
    // The arcs: one line per arc, in the vehicle frame.
    assert_eq!(
        got["arcs"]["lines"].as_u64(),
        Some(config.arcs.count as u64)
    );
    assert_eq!(got["arcs"]["frame"], "vehicle");
    // The command as a plottable series.
    assert!(
        got["command"]["speed_mps"].is_number(),
        "{}",
        got["command"]
    );
}
