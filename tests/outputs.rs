//! No output of a command replaces what the command reads — the files a
//! configuration or a world names included — nor anything but a regular
//! file it writes whole: an export with nothing to export keeps the old
//! file, a link is written through and kept.

use std::path::{Path, PathBuf};

use arcnav_testkit::temp_dir;

fn arcnav(args: &[&str]) -> (i32, String, String) {
    arcnav_testkit::output_of(env!("CARGO_BIN_EXE_arcnav"), args)
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Runs `args`, expecting it refused for writing onto `what`, and `file`
/// unchanged.
fn refused(args: &[&str], what: &str, file: &Path) {
    let before = std::fs::read(file).unwrap();
    let (code, stdout, stderr) = arcnav(args);
    assert_eq!(code, 1, "{args:?}: {stdout}{stderr}");
    assert!(
        stderr.contains("refusing to write") && stderr.contains(&format!("it is {what}")),
        "{args:?}: {stderr}"
    );
    assert_eq!(std::fs::read(file).unwrap(), before, "{args:?} changed it");
}

/// A world on a height file, and a configuration naming an occupancy map
/// (a map_server YAML and its image).
fn inputs(dir: &Path) -> (PathBuf, PathBuf, PathBuf, PathBuf, PathBuf) {
    let root = arcnav_testkit::workspace_root().join("tests/worlds");
    let world = dir.join("hillside.toml");
    let heights = dir.join("hillside.asc");
    std::fs::copy(root.join("hillside.toml"), &world).unwrap();
    std::fs::copy(root.join("hillside.asc"), &heights).unwrap();
    let mut pgm = b"P5\n4 4\n255\n".to_vec();
    pgm.extend_from_slice(&[255; 16]);
    let image = dir.join("map.pgm");
    std::fs::write(&image, &pgm).unwrap();
    let yaml = dir.join("map.yaml");
    std::fs::write(
        &yaml,
        "image: map.pgm\nresolution: 0.5\norigin: [500.0, 500.0, 0.0]\n",
    )
    .unwrap();
    let config = dir.join("run.toml");
    std::fs::write(&config, "[localmap.occupancy]\nfile = \"map.yaml\"\n").unwrap();
    (world, heights, config, yaml, image)
}

#[test]
fn no_output_of_sim_is_a_file_the_world_or_the_configuration_names() {
    let dir = temp_dir("outputs-names");
    let (world, heights, config, yaml, image) = inputs(&dir);
    let out = dir.join("run");
    let base = [
        "sim",
        "--world",
        s(&world),
        "--config",
        s(&config),
        "--out",
        s(&out),
    ];
    for (flag, file, what) in [
        ("--mcap", &heights, "the world's height file"),
        ("--save-world", &world, "the world file"),
        ("--mcap", &config, "the configuration"),
        ("--save-world", &yaml, "the occupancy map"),
        ("--mcap", &image, "the occupancy map's image"),
    ] {
        let mut args = base.to_vec();
        args.extend([flag, s(file)]);
        refused(&args, what, file);
    }
    assert!(!out.exists(), "a refused run made its output directory");
}

#[test]
fn an_export_of_a_log_with_nothing_in_it_keeps_the_old_file() {
    let dir = temp_dir("outputs-empty");
    let log = dir.join("empty.lcm");
    std::fs::write(&log, b"").unwrap();
    let mcap = dir.join("kept.mcap");
    std::fs::write(&mcap, b"an earlier export").unwrap();
    let (code, _, stderr) = arcnav(&["export", s(&log), "--mcap", s(&mcap)]);
    assert_eq!(code, 1, "{stderr}");
    assert!(stderr.contains("no LCM event could be read"), "{stderr}");
    assert_eq!(std::fs::read(&mcap).unwrap(), b"an earlier export");
    let left = std::fs::read_dir(&dir).unwrap().count();
    assert_eq!(left, 2, "a temporary was left");
}
