//! `arcnav config` as a user runs it.

use std::path::PathBuf;
use std::process::Command;

fn arcnav(args: &[&str]) -> (i32, String, String) {
    arcnav_testkit::output_of(env!("CARGO_BIN_EXE_arcnav"), args)
}

/// `arcnav config --check` of a file holding `text` fails (exit 1) with a
/// message containing `expect`.
fn assert_check_refuses(text: &str, expect: &str) {
    let (_dir, file) = temp_file("bad.toml", text);
    let (code, _, stderr) = arcnav(&["config", "--check", file.to_str().unwrap()]);
    assert_eq!(code, 1, "{text}: {stderr}");
    assert!(stderr.contains(expect), "{text}: {stderr}");
}

/// `text` written to `name` in a directory removed when the guard drops.
fn temp_file(name: &str, text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::Builder::new()
        .prefix("arcnav-cli-config-")
        .tempdir()
        .unwrap();
    let path = dir.path().join(name);
    std::fs::write(&path, text).unwrap();
    (dir, path)
}

#[test]
fn config_prints_defaults_merged_with_the_file() {
    let (_dir, file) = temp_file("narrow.toml", "[vehicle]\nwidth_m = 2.0\n");
    let (code, stdout, _) = arcnav(&["config", file.to_str().unwrap()]);
    assert_eq!(code, 0);
    let printed: arcnav::Config = toml::from_str(&stdout).expect("output is TOML");
    assert_eq!(printed.vehicle.width_m, 2.0);
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
    let (_dir, file) = temp_file("bad.toml", "[arcs]\ncount = 40\n");
    let (code, stdout, stderr) = arcnav(&["config", "--check", file.to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(stdout.is_empty());
    assert!(
        stderr.contains("`arcs.count`: is 40, must be an odd number"),
        "{stderr}"
    );
}

/// `[mission]` (issue 62): the operating area is "world", "none" or a
/// simple polygon; anything else, a crossing or degenerate polygon, or an
/// unknown `on_unreachable`, is refused naming the key and the reason.
#[test]
fn the_operating_area_and_unreachable_keys_are_checked() {
    let (_dir, good) = temp_file(
        "area.toml",
        "[mission]\narea = [[0, 0], [100, 0], [100, 50], [0, 50]]\non_unreachable = \"skip\"\n",
    );
    let (code, stdout, stderr) = arcnav(&["config", "--check", good.to_str().unwrap()]);
    assert_eq!(code, 0, "{stdout}{stderr}");
    for (text, expect) in [
        (
            "[mission]\narea = \"map\"\n",
            "`mission.area`: is \"map\": give \"world\", \"none\" or",
        ),
        (
            "[mission]\narea = [[0, 0], [10, 10], [10, 0], [0, 10]]\n",
            "`mission.area`: edges 0 and 2 cross",
        ),
        (
            "[mission]\narea = [[0, 0], [10, 0]]\n",
            "`mission.area`: has 2 vertices, a polygon needs at least 3",
        ),
        (
            "[mission]\nunreachable_after_s = -1\n",
            "`mission.unreachable_after_s`",
        ),
        ("[mission]\non_unreachable = \"wait\"\n", "on_unreachable"),
    ] {
        assert_check_refuses(text, expect);
    }
}

/// `[vehicle] footprint`: a circle and a polygon are accepted; each key
/// of a shape is refused with its reason when it is missing, malformed,
/// or given with another shape.
#[test]
fn the_footprint_keys_are_checked() {
    for good in [
        "[vehicle]\nfootprint = \"circle\"\nradius_m = 1.5\ncentre_m = [1.5, 0.0]\nwheelbase_m = 2.0\n",
        "[vehicle]\nfootprint = \"polygon\"\nvertices_m = [[-0.6, -1.1], [2.0, -1.1], [2.0, 0.0], \
         [4.0, 0.0], [4.0, 1.1], [-0.6, 1.1]]\n",
    ] {
        let (dir, file) = temp_file("shape.toml", good);
        let (code, stdout, stderr) = arcnav(&["config", "--check", file.to_str().unwrap()]);
        assert_eq!(code, 0, "{good}: {stdout}{stderr}");
        // What `arcnav config` prints (as a run's config.toml is written)
        // reads back: no rectangle's keys beside the outline.
        let (code, printed, stderr) = arcnav(&["config", file.to_str().unwrap()]);
        assert_eq!(code, 0, "{stderr}");
        assert!(!printed.contains("length_m"), "{printed}");
        let again = dir.path().join("printed.toml");
        std::fs::write(&again, &printed).unwrap();
        let (code, stdout, stderr) = arcnav(&["config", "--check", again.to_str().unwrap()]);
        assert_eq!(code, 0, "{printed}: {stdout}{stderr}");
    }
    for (text, expect) in [
        (
            "[vehicle]\nfootprint = \"oval\"\n",
            "unknown variant `oval`, expected one of `rectangle`, `circle`, `polygon`",
        ),
        (
            "[vehicle]\nfootprint = \"circle\"\n",
            "`vehicle.radius_m`: is needed with footprint = \"circle\"",
        ),
        (
            "[vehicle]\nfootprint = \"circle\"\nradius_m = -1.0\n",
            "`vehicle.radius_m`: is -1, must be a finite number > 0",
        ),
        (
            "[vehicle]\nfootprint = \"circle\"\nradius_m = 1e300\n",
            "`vehicle.radius_m`: puts a point of the body",
        ),
        (
            "[vehicle]\nfootprint = \"circle\"\nradius_m = 1.5\nwidth_m = 3.0\nwheelbase_m = 1.0\n",
            "`vehicle.width_m`: is a rectangle's, and footprint is \"circle\"",
        ),
        (
            "[vehicle]\nradius_m = 1.5\n",
            "`vehicle.radius_m`: is read only with footprint = \"circle\" (footprint is \"rectangle\")",
        ),
        (
            "[vehicle]\nfootprint = \"polygon\"\n",
            "`vehicle.vertices_m`: is needed with footprint = \"polygon\"",
        ),
        (
            "[vehicle]\nfootprint = \"polygon\"\nvertices_m = [[0, -1], [4, 1], [4, -1], [0, 1]]\n",
            "`vehicle.vertices_m`: edges 0 and 2 cross",
        ),
        (
            "[vehicle]\nfootprint = \"polygon\"\nvertices_m = [[0, -1], [4, -1]]\n",
            "`vehicle.vertices_m`: has 2 vertices",
        ),
        (
            "[vehicle]\nfootprint = \"polygon\"\nvertices_m = [[1, -1], [4, -1], [4, 1], [1, 1]]\n",
            "`vehicle.vertices_m`: puts the body from x = 1 m to 4 m: the rear axle (x = 0) must lie under it",
        ),
    ] {
        assert_check_refuses(text, expect);
    }
}

/// Issue 68: the skid-steer keys. The preset is valid and its printed
/// configuration reads back; each key's errors name it.
#[test]
fn the_kinematics_keys_are_checked() {
    let preset = format!("{}/config/skid_steer.toml", env!("CARGO_MANIFEST_DIR"));
    let (code, printed, stderr) = arcnav(&["config", &preset]);
    assert_eq!(code, 0, "{stderr}");
    assert!(
        printed.contains("kinematics = \"skid_steer\"") && printed.contains("turn_in_place = true"),
        "{printed}"
    );
    let (dir, again) = temp_file("printed.toml", &printed);
    let (code, stdout, stderr) = arcnav(&["config", "--check", again.to_str().unwrap()]);
    assert_eq!(code, 0, "{printed}: {stdout}{stderr}");
    drop(dir);
    for (text, expect) in [
        (
            "[vehicle]\nkinematics = \"tracked\"\n",
            "unknown variant `tracked`, expected `ackermann` or `skid_steer`",
        ),
        (
            "[vehicle]\nkinematics = \"skid_steer\"\n",
            "`vehicle.max_yaw_rate_dps`: is needed with kinematics = \"skid_steer\"",
        ),
        (
            "[vehicle]\nkinematics = \"skid_steer\"\nmax_yaw_rate_dps = 0.0\n",
            "`vehicle.max_yaw_rate_dps`: is 0",
        ),
        (
            "[vehicle]\nmax_yaw_rate_dps = 60.0\n",
            "`vehicle.max_yaw_rate_dps`: is read only with kinematics = \"skid_steer\"",
        ),
        (
            "[arcs]\nturn_in_place = true\n",
            "`arcs.turn_in_place`: needs a vehicle that turns in place",
        ),
        ("[arcs]\nturn_in_place = \"yes\"\n", "`arcs.turn_in_place`"),
    ] {
        assert_check_refuses(text, expect);
    }
}

/// Values that aborted or hung `arcnav sim` (found by setting every number
/// of config/default.toml to ±1e300 in turn), refused by their key.
#[test]
fn values_that_aborted_or_hung_a_run_are_refused_by_key() {
    for (text, expect) in [
        // Aborted: no memory for 100 000 threads' stacks.
        (
            "[sim]\nthreads = 100000\n",
            "`sim.threads`: is 100000, must be 0 (all cores) to 1024",
        ),
        // Poses 1e300 m out: the elevation layer's indices overflowed.
        ("[sim]\npose_noise_m = 1e300\n", "`sim.pose_noise_m`"),
        ("[sim]\ndrift_per_m = 1e300\n", "`sim.drift_per_m`"),
        // Hung the first vote: the footprint widened by 1e300 m.
        (
            "[behaviours.obstacle_avoidance]\nnear_miss_m = 1e300\n",
            "`behaviours.obstacle_avoidance.near_miss_m`",
        ),
    ] {
        assert_check_refuses(text, expect);
    }
}

/// An occupancy map whose cells are huge against the local map's patches
/// (`resolution: 100000`, one pixel) had aborted `config --check`: "memory
/// allocation of 4294967296 bytes failed", exit 134.
#[test]
fn an_occupancy_map_too_large_for_the_patches_is_refused_by_key() {
    let (dir, file) = temp_file("huge.toml", "[localmap.occupancy]\nfile = \"huge.yaml\"\n");
    let folder = file.parent().unwrap();
    std::fs::write(folder.join("one.pgm"), b"P5\n1 1\n255\n\0").unwrap();
    std::fs::write(
        folder.join("huge.yaml"),
        "image: one.pgm\nresolution: 100000\norigin: [0, 0, 0]\n",
    )
    .unwrap();
    let (code, _, stderr) = arcnav(&["config", "--check", file.to_str().unwrap()]);
    assert_eq!(code, 1, "{stderr}");
    assert!(
        stderr.contains("localmap.occupancy.file") && stderr.contains("is its resolution right?"),
        "{stderr}"
    );
    drop(dir);
}

#[test]
fn config_check_without_a_file_is_a_usage_error() {
    let (code, _, stderr) = arcnav(&["config", "--check"]);
    assert_eq!(code, 2);
    assert!(stderr.contains("<FILE>"), "{stderr}");
}

/// A configuration naming `key` as its group key, in its own directory
/// (removed when the guard drops).
fn keyed_config(
    tag: &str,
    key: Option<(&str, u32)>,
    extra: &str,
) -> (tempfile::TempDir, PathBuf, PathBuf) {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::Builder::new()
        .prefix(&format!("arcnav-cli-key-{tag}-"))
        .tempdir()
        .unwrap();
    let key_path = dir.path().join("group.key");
    if let Some((text, mode)) = key {
        std::fs::write(&key_path, text).unwrap();
        std::fs::set_permissions(&key_path, std::fs::Permissions::from_mode(mode)).unwrap();
    }
    let config = dir.path().join("vehicle.toml");
    std::fs::write(
        &config,
        format!("[bus.auth]\nkey_file = \"group.key\"\n{extra}"),
    )
    .unwrap();
    (dir, config, key_path)
}

const GOOD_KEY: &str = "00112233445566778899aabbccddeeff00112233445566778899aabbccddeeff\n";

/// A key that cannot be used stops every live command at start, before it
/// opens the bus, with a message naming the file and what to do.
#[test]
fn live_commands_refuse_a_key_they_cannot_use_and_name_the_file() {
    let cases = [
        ("missing", None, "cannot read it"),
        ("world", Some((GOOD_KEY, 0o644)), "readable by everyone"),
        ("group", Some((GOOD_KEY, 0o640)), "readable by its group"),
        ("short", Some(("0011223344556677\n", 0o600)), "8-byte key"),
        ("not-hex", Some(("arcnav\n", 0o600)), "not a hex digit"),
        ("empty", Some(("", 0o600)), "0-byte key"),
        (
            "odd",
            Some(("0011223\n", 0o600)),
            "odd number of hex digits",
        ),
        (
            "zero",
            Some((&"00".repeat(32), 0o600)),
            "repeated: not a secret",
        ),
    ];
    for (tag, key, expect) in cases {
        let (_dir, config, key_path) = keyed_config(tag, key, "");
        let config = config.to_str().unwrap();
        // `config --check` says so too (it had said "valid").
        let (code, stdout, stderr) = arcnav(&["config", "--check", config]);
        assert_eq!(code, 1, "{tag}: {stdout}");
        assert!(
            stderr.contains(expect) && stderr.contains("bus.auth.key_file"),
            "{tag}: {stderr}"
        );
        for command in [
            &["run"][..],
            &["node", "arbiter"],
            &["node", "behaviour", "obstacle_avoidance"],
            &["vehicle"],
        ] {
            let args: Vec<&str> = command
                .iter()
                .copied()
                .chain(["--lcm", "memq://", "--config", config, "--duration", "0.1"])
                .collect();
            let (code, _, stderr) = arcnav(&args);
            assert_eq!(code, 1, "{args:?}: {stderr}");
            assert!(
                stderr.contains(expect) && stderr.contains(&key_path.display().to_string()),
                "{tag}, {args:?}: {stderr}"
            );
        }
    }
}

/// `--json` is written at exit: onto the configuration or the key file it
/// had replaced them. Refused at start, by name; elsewhere it is written.
#[test]
fn live_figures_never_replace_the_configuration_or_the_key() {
    let (dir, config, key_path) = keyed_config("json", Some((GOOD_KEY, 0o600)), "");
    let before = std::fs::read_to_string(&config).unwrap();
    let json = dir.path().join("figures.json");
    // `command` on the bus for 0.1 s, its figures written to `out`.
    let live = |command: &[&str], out: &std::path::Path| {
        let args: Vec<&str> = command
            .iter()
            .copied()
            .chain(["--lcm", "memq://", "--config", config.to_str().unwrap()])
            .chain(["--duration", "0.1", "--json", out.to_str().unwrap()])
            .collect();
        let (code, _, stderr) = arcnav(&args);
        (code, format!("{args:?}"), stderr)
    };
    for (out, expect) in [
        (&config, "it is the configuration"),
        (&key_path, "it is the bus key file"),
    ] {
        for command in [&["run"][..], &["node", "arbiter"]] {
            let (code, args, stderr) = live(command, out);
            assert_eq!(code, 1, "{args}: {stderr}");
            assert!(stderr.contains(expect), "{args}: {stderr}");
        }
    }
    assert_eq!(std::fs::read_to_string(&config).unwrap(), before);
    assert_eq!(std::fs::read_to_string(&key_path).unwrap(), GOOD_KEY);
    let (code, args, stderr) = live(&["run"], &json);
    assert_eq!(code, 0, "{args}: {stderr}");
    let figures: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert!(figures.is_object(), "{figures}");
}

/// The vehicle bridge refuses set-ups that would let unverified commands
/// through, and says how to fix them.
#[test]
fn the_vehicle_bridge_refuses_to_follow_unsigned_commands_or_itself() {
    let (_dir, config, _) = keyed_config(
        "uncovered",
        Some((GOOD_KEY, 0o600)),
        "channels = [\"ARC_VOTES_.*\"]\n",
    );
    let config = config.to_str().unwrap();
    let (code, _, stderr) = arcnav(&["vehicle", "--lcm", "memq://", "--config", config]);
    assert_eq!(code, 1, "{stderr}");
    assert!(
        stderr.contains("do not include STEERING_COMMAND"),
        "{stderr}"
    );
    let (code, _, stderr) = arcnav(&[
        "vehicle",
        "--lcm",
        "memq://",
        "--forward",
        "memq://",
        "--duration",
        "0.1",
    ]);
    assert_eq!(code, 1, "{stderr}");
    assert!(stderr.contains("no controller hears"), "{stderr}");
    let (code, _, stderr) = arcnav(&["vehicle", "--lcm", "memq://", "--rate", "0"]);
    assert_eq!(code, 1, "{stderr}");
    assert!(stderr.contains("--rate 0"), "{stderr}");
    // Slower than twice per timeout: the stop would come late (1e-9 Hz and
    // 0.5 Hz against a 0.3 s timeout had been taken).
    for rate in ["1e-9", "0.5", "6"] {
        let args = [
            "vehicle",
            "--lcm",
            "memq://",
            "--timeout",
            "0.3",
            "--rate",
            rate,
        ];
        let (code, _, stderr) = arcnav(&args);
        assert_eq!(code, 1, "{rate}: {stderr}");
        assert!(
            stderr.contains("hand over at least 6.7 Hz"),
            "{rate}: {stderr}"
        );
    }
    let args = [
        "vehicle",
        "--lcm",
        "memq://",
        "--timeout",
        "0.3",
        "--rate",
        "7",
    ];
    let (code, _, stderr) = arcnav(&[&args[..], &["--duration", "0.1"]].concat());
    assert_eq!(code, 0, "{stderr}");
    // A stop timeout that never comes (1e300 s had been taken).
    for timeout in ["1e300", "61", "0"] {
        let (code, _, stderr) = arcnav(&[
            "vehicle",
            "--lcm",
            "memq://",
            "--timeout",
            timeout,
            "--duration",
            "0.1",
        ]);
        assert_eq!(code, 1, "{timeout}: {stderr}");
        assert!(
            stderr.contains("must be more than 0 and at most 60 s"),
            "{timeout}: {stderr}"
        );
    }
}

/// The bus the bridge hears, spelt another way, is still that bus: the
/// bridge had followed its own forwards and never stopped the vehicle.
/// Inside a network namespace of its own (udpm sockets).
#[test]
fn the_vehicle_bridge_refuses_to_forward_onto_its_own_bus_however_spelt() {
    let Some(ns) = arcnav_testkit::NetNs::require("forward-spelt") else {
        return;
    };
    for forward in [
        "udpm://",
        "udpm://239.255.76.67:7667",
        "udpm://239.255.76.67:7667?ttl=1",
    ] {
        let out = ns
            .command(env!("CARGO_BIN_EXE_arcnav"))
            .args(["vehicle", "--lcm", "udpm://239.255.76.67:7667?ttl=0"])
            .args(["--forward", forward, "--duration", "0.1"])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{forward}: {stderr}");
        assert!(
            stderr.contains("is the bus the commands come from"),
            "{forward}: {stderr}"
        );
    }
}

/// With authentication off the bridge still runs (off is the default), says
/// it follows anyone, and hands over stops until a command comes, then a
/// final stop.
#[test]
fn the_vehicle_bridge_without_commands_executes_stops() {
    let (code, stdout, stderr) = arcnav(&[
        "vehicle",
        "--lcm",
        "memq://",
        "--print",
        "--rate",
        "50",
        "--duration",
        "0.3",
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stderr.contains("authentication is off"), "{stderr}");
    let ticks: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert!(ticks.len() >= 10, "{stdout}");
    let (last, before) = ticks.split_last().unwrap();
    assert!(
        before
            .iter()
            .all(|t| t["state"] == "no_command_yet" && t["speed_mps"] == 0.0)
    );
    assert_eq!(last["state"], "shutting_down");
}

/// A reader that leaves before `arcnav config` or `arcnav evaluators` has
/// printed (`arcnav config | head`) ends it as it ends any Unix filter: by
/// SIGPIPE, with nothing on standard error (it panicked with "failed
/// printing to stdout: Broken pipe" before).
#[test]
fn printing_into_a_pipe_whose_reader_has_left_ends_quietly() {
    use std::os::unix::process::ExitStatusExt;
    for command in ["config", "evaluators"] {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        let out = Command::new(env!("CARGO_BIN_EXE_arcnav"))
            .arg(command)
            .stdout(writer)
            .output()
            .expect("the arcnav binary runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(
            out.status.signal(),
            Some(libc::SIGPIPE),
            "{command}: {:?}\n{stderr}",
            out.status
        );
        assert!(stderr.is_empty(), "{command}: {stderr}");
    }
}
