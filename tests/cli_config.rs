//! `arcnav config` as a user runs it.

use std::path::PathBuf;
use std::process::Command;

fn arcnav(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_arcnav"))
        .args(args)
        .output()
        .expect("the arcnav binary runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn temp_file(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("arcnav-cli-config-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn config_prints_defaults_merged_with_the_file() {
    let file = temp_file("narrow.toml", "[vehicle]\nwidth_m = 1.8\n");
    let (code, stdout, _) = arcnav(&["config", file.to_str().unwrap()]);
    assert_eq!(code, 0);
    let printed: arcnav::Config = toml::from_str(&stdout).expect("output is TOML");
    assert_eq!(printed.vehicle.width_m, 1.8);
    assert_eq!(
        printed.vehicle.length_m, 4.6,
        "other keys keep their defaults"
    );
}

#[test]
fn config_check_accepts_the_shipped_defaults() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/config/default.toml");
    let (code, stdout, _) = arcnav(&["config", "--check", path]);
    assert_eq!(code, 0);
    assert!(stdout.ends_with(": valid\n"), "{stdout}");
}

#[test]
fn config_check_names_the_bad_key_and_fails() {
    let file = temp_file("bad.toml", "[arcs]\ncount = 40\n");
    let (code, stdout, stderr) = arcnav(&["config", "--check", file.to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(stdout.is_empty());
    assert!(
        stderr.contains("`arcs.count`: is 40, must be an odd number"),
        "{stderr}"
    );
}

#[test]
fn config_check_without_a_file_is_a_usage_error() {
    let (code, _, stderr) = arcnav(&["config", "--check"]);
    assert_eq!(code, 2);
    assert!(stderr.contains("<FILE>"), "{stderr}");
}
