//! Authenticated messages checked by another implementation: the Python
//! verifier in `examples/verify_command.py` (hmac and hashlib from the
//! standard library) accepts the commands arcnav signs and refuses a
//! tampered one, a replay and an unauthenticated one.

use std::os::unix::fs::PermissionsExt;
use std::process::Command;

use arcnav_bus::Message;
use arcnav_bus::auth::{GroupKey, Signer};
use arcnav_bus::lcmtypes::steering_command_t;
use arcnav_bus::log::LogWriter;

const T: i64 = 1_700_000_000_000_000;

fn command(k: i32) -> Vec<u8> {
    steering_command_t {
        utime: T + i64::from(k) * 100_000,
        curvature: 0.0125 * f64::from(k),
        speed: 2.5,
        arc_index: 19 + k,
        vote: 0.75,
    }
    .encode()
    .unwrap()
}

#[test]
fn the_python_verifier_accepts_arcnavs_commands_and_refuses_a_tampered_one() {
    let dir = arcnav_testkit::scratch_dir("arcnav-auth-python");
    let key_hex: String = (0..32u8).map(|i| format!("{:02x}", 0x3f ^ i)).collect();
    let key_path = dir.join("group.key");
    std::fs::write(&key_path, format!("{key_hex}\n")).unwrap();
    std::fs::set_permissions(&key_path, std::fs::Permissions::from_mode(0o600)).unwrap();
    let key = GroupKey::from_file(&key_path).unwrap();
    let mut signer = Signer::new(key);
    let log_path = dir.join("commands.lcm");
    let mut log = LogWriter::create(&log_path).unwrap();
    let mut signed = Vec::new();
    for k in 0..3 {
        let now = T + i64::from(k) * 100_000;
        let sent = signer.sign("STEERING_COMMAND", &command(k), now as u64);
        log.write_event(now, "STEERING_COMMAND", &sent).unwrap();
        signed.push(sent);
    }
    // Tampered: speed raised (a byte of the message flipped, trailer kept).
    let mut tampered = signed[2].clone();
    tampered[8 + 8 + 8] ^= 0x40;
    log.write_event(T + 300_000, "STEERING_COMMAND", &tampered)
        .unwrap();
    // A replay of the first command, and one without a trailer.
    log.write_event(T + 400_000, "STEERING_COMMAND", &signed[0])
        .unwrap();
    log.write_event(T + 500_000, "STEERING_COMMAND", &command(4))
        .unwrap();
    drop(log);
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/verify_command.py");
    let out = Command::new("python3")
        .arg(script)
        .arg(&key_path)
        .arg(&log_path)
        .output()
        .expect("python3 runs (scripts/test-tools installs it)");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(
        lines.len(),
        7,
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        lines[0].ends_with("accepted: curvature +0.0000 1/m, speed 2.50 m/s, arc 19"),
        "{}",
        lines[0]
    );
    assert!(
        lines[2].ends_with("accepted: curvature +0.0250 1/m, speed 2.50 m/s, arc 21"),
        "{}",
        lines[2]
    );
    assert!(lines[3].ends_with("refused: bad tag"), "{}", lines[3]);
    assert!(lines[4].ends_with("refused: replayed"), "{}", lines[4]);
    assert!(
        lines[5].ends_with("refused: unauthenticated"),
        "{}",
        lines[5]
    );
    assert_eq!(lines[6], "3 accepted, 3 refused");
    assert_eq!(out.status.code(), Some(1), "a refusal is a failure");
    // A key file others can read is refused, naming the file.
    std::fs::set_permissions(&key_path, std::fs::Permissions::from_mode(0o644)).unwrap();
    let out = Command::new("python3")
        .arg(script)
        .arg(&key_path)
        .arg(&log_path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("group.key") && stderr.contains("chmod 600"),
        "{stderr}"
    );
}
