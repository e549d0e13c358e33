//! Wire compatibility with the reference LCM implementation (PyPI `lcm`,
//! pinned by scripts/test-tools): fingerprints, bytes both ways, event logs
//! with `lcm-logger`, `lcm.EventLog` and `lcm-logplayer`, and live UDP
//! multicast both ways. Live traffic runs only inside a network namespace
//! each test creates and deletes.

mod common;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use arcnav_bus::lcmtypes::{ALL_TYPES, range_image_t, steering_command_t};
use arcnav_bus::{AnyMessage, Lcm, LogReader, LogWriter, Message, schema};
use arcnav_testkit::{LcmReference, NetNs, temp_dir};
use common::{Rng, random_message, samples};
use serde_json::Value;
use sha2::{Digest, Sha256};

const URL: &str = "udpm://239.255.76.67:7667?ttl=0";
/// The reference receiver needs a large buffer for fragmented messages.
const PEER_URL: &str = "udpm://239.255.76.67:7667?ttl=0&recv_buf_size=4194304";

fn lcm_files() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("lcmtypes");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "lcm"))
        .collect();
    files.sort();
    files
}

fn sha256(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// The Python peer: `lcm-gen -p` classes of our `.lcm` files and `lcm_peer.py`.
struct Peer {
    reference: LcmReference,
    gendir: PathBuf,
}

impl Peer {
    fn new() -> Option<Self> {
        let reference = LcmReference::require()?;
        let gendir = temp_dir("lcmgen");
        reference.generate_python(&lcm_files(), &gendir);
        Some(Self { reference, gendir })
    }

    fn script() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/peer/lcm_peer.py")
    }

    fn args(&self, command: &str, rest: &[&str]) -> Vec<String> {
        let mut args = vec![
            Self::script().display().to_string(),
            command.to_owned(),
            self.gendir.display().to_string(),
        ];
        args.extend(rest.iter().map(|s| s.to_string()));
        args
    }

    fn run(&self, command: &str, rest: &[&str]) -> Vec<Value> {
        let out = self
            .reference
            .python()
            .args(self.args(command, rest))
            .output()
            .expect("run the peer");
        assert!(
            out.status.success(),
            "peer {command} failed: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        parse_lines(&String::from_utf8_lossy(&out.stdout))
    }

    /// Starts the peer inside `ns`, with stdout piped.
    fn spawn_in(&self, ns: &NetNs, command: &str, rest: &[&str]) -> Child {
        ns.command(self.reference.python_path())
            .env("PYTHONUNBUFFERED", "1")
            .args(self.args(command, rest))
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start the peer in the namespace")
    }
}

fn parse_lines(text: &str) -> Vec<Value> {
    text.lines()
        .filter(|l| l.starts_with('{'))
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("bad peer output {l:?}: {e}")))
        .collect()
}

/// Reads the peer's first line and checks it says it is ready.
fn wait_ready(child: &mut Child) -> BufReader<std::process::ChildStdout> {
    let mut stdout = BufReader::new(child.stdout.take().expect("piped stdout"));
    let mut line = String::new();
    stdout.read_line(&mut line).expect("read the peer");
    assert!(
        line.contains("\"ready\""),
        "peer did not get ready: {line:?}"
    );
    stdout
}

#[test]
fn fingerprints_equal_what_lcm_gen_generates() {
    let Some(peer) = Peer::new() else { return };
    let python: BTreeMap<String, u64> = peer
        .run("fingerprints", &[])
        .into_iter()
        .map(|v| {
            (
                v["type"].as_str().unwrap().to_owned(),
                v["fingerprint"].as_u64().unwrap(),
            )
        })
        .collect();
    let rust: BTreeMap<String, u64> = ALL_TYPES.iter().map(|(n, f)| (n.to_string(), *f)).collect();
    assert_eq!(rust, python);
    assert_eq!(rust.len(), 14);
}

#[test]
fn the_golden_table_matches_lcm_gen_too() {
    let Some(reference) = LcmReference::require() else {
        return;
    };
    let source = "package rtest;\n\
        struct header_t { int64_t utime; int32_t seq; string frame_id; }\n\
        struct simple_t { int64_t utime; }\n\
        struct steering_cmd_t { int64_t utime; float steering_angle; float speed; boolean enabled; }\n\
        struct range_image_t { const int32_t MAX_WIDTH = 2048; header_t header; int32_t width; int32_t height; int32_t num_ranges;\n\
          float ranges[num_ranges]; int16_t intensity[height][width]; double pose[4][4]; byte flags[3]; }\n\
        struct pair_t { header_t a; header_t b; simple_t c[2]; }\n\
        struct node_t { int32_t n; node_t children[n]; }\n";
    let dir = temp_dir("golden");
    let file = dir.join("rtest.lcm");
    std::fs::write(&file, source).unwrap();
    reference.generate_python(std::slice::from_ref(&file), &dir);
    let ours = schema::fingerprints(&schema::parse(source).unwrap()).unwrap();
    let out = reference
        .python()
        .current_dir(&dir)
        .args(["-c", "import rtest\nfor n in ['header_t','simple_t','steering_cmd_t','range_image_t','pair_t','node_t']: print(n, getattr(rtest, n)._get_hash_recursive([]))"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let (name, value) = line.split_once(' ').unwrap();
        assert_eq!(
            ours[&format!("rtest.{name}")],
            value.parse::<u64>().unwrap(),
            "{name}"
        );
    }
}

#[test]
fn python_and_rust_produce_identical_bytes_for_the_same_values() {
    let Some(peer) = Peer::new() else { return };
    let dir = temp_dir("py-make");
    peer.run("make", &[dir.to_str().unwrap()]);
    for (name, message) in samples() {
        let python = std::fs::read(dir.join(format!("{name}.bin"))).unwrap();
        let rust = message.encode().unwrap();
        assert_eq!(
            rust, python,
            "{name}: Rust and lcm-gen Python encode differently"
        );
        // Rust decodes Python's bytes to the same values.
        let decoded = AnyMessage::decode(&python).unwrap().unwrap();
        assert_eq!(decoded.encode().unwrap(), python, "{name}");
    }
}

#[test]
fn python_decodes_what_rust_encodes() {
    let Some(peer) = Peer::new() else { return };
    let input = temp_dir("rust-encoded");
    let output = temp_dir("py-reencoded");
    let mut originals = BTreeMap::new();
    for (i, (name, message)) in samples().into_iter().enumerate() {
        originals.insert(format!("s{i}-{name}.bin"), message.encode().unwrap());
    }
    let mut rng = Rng::new(0x5eed);
    for i in 0..210 {
        let (name, message) = random_message(&mut rng, i);
        originals.insert(format!("r{i:03}-{name}.bin"), message.encode().unwrap());
    }
    for (file, bytes) in &originals {
        std::fs::write(input.join(file), bytes).unwrap();
    }
    let report = peer.run(
        "reencode",
        &[input.to_str().unwrap(), output.to_str().unwrap()],
    );
    assert_eq!(report.len(), originals.len());
    for (file, bytes) in &originals {
        let back = std::fs::read(output.join(file)).unwrap();
        assert_eq!(&back, bytes, "{file}: Python re-encoded different bytes");
    }
    // And the values Python saw are the ones Rust meant.
    let values: BTreeMap<&str, &Value> = report
        .iter()
        .map(|r| (r["file"].as_str().unwrap(), &r["values"]))
        .collect();
    let cells = values["s4-obstacle_cells_t.bin"];
    assert_eq!(cells["sensor"], "erim-\u{3c0}");
    assert_eq!(cells["cells"][2]["reasons"], 4);
    assert_eq!(cells["fov"][1], serde_json::json!([10.0, -5.0]));
    let votes = values["s3-arc_votes_t.bin"];
    assert_eq!(votes["vetoed"][5], true);
    assert_eq!(votes["vetoed"][6], false);
    assert_eq!(values["s0-pose_t.bin"]["position"][1], -2.25);
    assert_eq!(values["s1-range_image_t.bin"]["range"][0][7], "nan");
}

/// Runs `f` with a Rust `Lcm` inside `ns`.
fn with_lcm<T: Send>(ns: &NetNs, f: impl FnOnce(&mut Lcm) -> T + Send) -> T {
    ns.run(|| {
        let mut lcm = Lcm::new(URL).expect("udpm inside the test namespace");
        f(&mut lcm)
    })
}

#[test]
fn a_log_recorded_by_lcm_logger_reads_in_rust() {
    let Some(peer) = Peer::new() else { return };
    let Some(ns) = NetNs::require("logger") else {
        return;
    };
    let dir = temp_dir("logger");
    let log = dir.join("reference.log");
    let mut logger = ns
        .command(peer.reference.tool_path("lcm-logger"))
        .args([
            "-f",
            &format!("--lcm-url={PEER_URL}"),
            "--flush-interval=10",
        ])
        .arg(&log)
        .stdout(Stdio::null())
        .spawn()
        .expect("start lcm-logger");
    let expected: Vec<(String, Vec<u8>)> = samples()
        .into_iter()
        .map(|(name, m)| (name.to_uppercase(), m.encode().unwrap()))
        .collect();
    with_lcm(&ns, |lcm| {
        // Knock until the logger has recorded something: then it listens.
        let deadline = Instant::now() + Duration::from_secs(20);
        while std::fs::metadata(&log).map_or(0, |m| m.len()) == 0 {
            assert!(
                Instant::now() < deadline,
                "lcm-logger never started recording"
            );
            lcm.publish("KNOCK", b"knock").unwrap();
            std::thread::sleep(Duration::from_millis(50));
        }
        for (channel, bytes) in &expected {
            lcm.publish(channel, bytes).unwrap();
            std::thread::sleep(Duration::from_millis(20));
        }
    });
    std::thread::sleep(Duration::from_millis(300));
    interrupt(&logger);
    logger.wait().expect("lcm-logger exits on SIGINT");
    let mut reader = LogReader::open(&log).unwrap();
    let events: Vec<_> = reader
        .by_ref()
        .map(Result::unwrap)
        .filter(|e| e.channel != "KNOCK")
        .collect();
    let got: Vec<(String, Vec<u8>)> = events
        .iter()
        .map(|e| (e.channel.clone(), e.data.clone()))
        .collect();
    assert_eq!(got, expected);
    for event in &events {
        assert!(AnyMessage::decode(&event.data).unwrap().is_some());
    }
    assert!(!reader.stats().lost_anything());
}

/// Sends SIGINT, the way to stop `lcm-logger` cleanly.
fn interrupt(child: &Child) {
    let status = Command::new("kill")
        .args(["-INT", &child.id().to_string()])
        .status();
    assert!(
        status.is_ok_and(|s| s.success()),
        "could not interrupt process {}",
        child.id()
    );
}

fn write_rust_log(path: &Path) -> Vec<(i64, String, Vec<u8>)> {
    let mut writer = LogWriter::create(path).unwrap();
    let mut events = Vec::new();
    for (i, (name, message)) in samples().into_iter().enumerate() {
        let channel = name.to_uppercase();
        let bytes = message.encode().unwrap();
        let timestamp = 1_700_000_000_000_000 + i as i64 * 10_000;
        writer.write_event(timestamp, &channel, &bytes).unwrap();
        events.push((timestamp, channel, bytes));
    }
    let image = common::range_image(128, 2048, "lidar128");
    let bytes = image.encode().unwrap();
    writer
        .write_event(1_700_000_000_100_000, "RANGE_IMAGE_LIDAR", &bytes)
        .unwrap();
    events.push((1_700_000_000_100_000, "RANGE_IMAGE_LIDAR".into(), bytes));
    events
}

#[test]
fn a_rust_log_reads_in_python_event_log() {
    let Some(peer) = Peer::new() else { return };
    let log = temp_dir("rust-log").join("rust.log");
    let events = write_rust_log(&log);
    let read = peer.run("readlog", &[log.to_str().unwrap()]);
    assert_eq!(read.len(), events.len());
    for (i, (value, (timestamp, channel, bytes))) in read.iter().zip(&events).enumerate() {
        assert_eq!(value["eventnum"], i as u64);
        assert_eq!(value["timestamp"], *timestamp);
        assert_eq!(value["channel"], channel.as_str());
        assert_eq!(value["sha256"], sha256(bytes));
    }
}

#[test]
fn a_rust_log_plays_with_lcm_logplayer() {
    let Some(peer) = Peer::new() else { return };
    let Some(ns) = NetNs::require("logplayer") else {
        return;
    };
    let log = temp_dir("rust-log-play").join("rust.log");
    let events = write_rust_log(&log);
    let received = with_lcm(&ns, |lcm| {
        lcm.subscribe_regex(".*").unwrap();
        let mut player = ns
            .command(peer.reference.tool_path("lcm-logplayer"))
            .args(["-s", "10", &format!("--lcm-url={URL}")])
            .arg(&log)
            .stdout(Stdio::null())
            .spawn()
            .expect("start lcm-logplayer");
        let mut received = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(30);
        while received.len() < events.len() && Instant::now() < deadline {
            if let Some(m) = lcm.recv_timeout(Duration::from_millis(200)).unwrap() {
                received.push((m.channel, m.data));
            }
        }
        let _ = player.wait();
        received
    });
    let expected: Vec<(String, Vec<u8>)> = events.into_iter().map(|(_, c, b)| (c, b)).collect();
    assert_eq!(received, expected);
}

#[test]
fn live_rust_publishes_what_python_receives_intact() {
    let Some(peer) = Peer::new() else { return };
    let Some(ns) = NetNs::require("rust-to-py") else {
        return;
    };
    let image = common::range_image(128, 2048, "lidar128");
    let image_bytes = image.encode().unwrap();
    assert!(
        image_bytes.len() > 1 << 20,
        "a 128x2048 image needs many datagrams"
    );
    let commands: Vec<steering_command_t> = (0..5)
        .map(|i| steering_command_t {
            utime: 1_700_000_000_000_000 + i,
            curvature: 0.01 * i as f64,
            speed: 2.0,
            arc_index: i as i32,
            vote: 0.5,
        })
        .collect();
    let mut child = peer.spawn_in(&ns, "subscribe", &[PEER_URL, "6", "20"]);
    let stdout = wait_ready(&mut child);
    with_lcm(&ns, |lcm| {
        lcm.publish("RANGE_IMAGE_LIDAR", &image_bytes).unwrap();
        for command in &commands {
            lcm.publish_message("STEERING_COMMAND", command).unwrap();
        }
    });
    let lines: Vec<Value> = stdout
        .lines()
        .map_while(Result::ok)
        .flat_map(|l| parse_lines(&l))
        .collect();
    assert!(child.wait().unwrap().success());
    assert_eq!(lines.len(), 6, "python received {lines:?}");
    let image_line = lines
        .iter()
        .find(|l| l["channel"] == "RANGE_IMAGE_LIDAR")
        .expect("the image arrived");
    assert_eq!(image_line["sha256"], sha256(&image_bytes));
    assert_eq!(
        (image_line["rows"].as_u64(), image_line["cols"].as_u64()),
        (Some(128), Some(2048))
    );
    assert_eq!(
        image_line["range_1000"].as_f64().unwrap() as f32,
        image.range[1000]
    );
    let arcs: Vec<i64> = lines
        .iter()
        .filter(|l| l["channel"] == "STEERING_COMMAND")
        .map(|l| l["arc_index"].as_i64().unwrap())
        .collect();
    assert_eq!(arcs, [0, 1, 2, 3, 4]);
}

#[test]
fn live_rust_receives_what_python_publishes() {
    let Some(peer) = Peer::new() else { return };
    let Some(ns) = NetNs::require("py-to-rust") else {
        return;
    };
    let received = with_lcm(&ns, |lcm| {
        lcm.subscribe("POSE");
        lcm.subscribe("STEERING_COMMAND");
        lcm.subscribe_regex("RANGE_IMAGE_.*").unwrap();
        let status = peer
            .spawn_in(&ns, "publish", &[URL])
            .wait()
            .expect("python publisher ran");
        assert!(status.success());
        let mut received = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(10);
        while received.len() < 3 && Instant::now() < deadline {
            if let Some(m) = lcm.recv_timeout(Duration::from_millis(100)).unwrap() {
                received.push(m);
            }
        }
        received
    });
    let channels: Vec<&str> = received.iter().map(|m| m.channel.as_str()).collect();
    assert_eq!(channels, ["POSE", "STEERING_COMMAND", "RANGE_IMAGE_LIDAR"]);
    let expected = samples();
    assert_eq!(received[0].data, expected[0].1.encode().unwrap());
    let image = range_image_t::decode(&received[2].data).unwrap();
    let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
    assert_eq!(
        bits(&image.range),
        bits(&common::range_image(128, 2048, "lidar128").range)
    );
}
