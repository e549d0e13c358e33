//! Authentication in the transport: what a key holder publishes arrives as
//! sent; forged, unsigned and replayed messages on authenticated channels
//! never arrive and are counted. In-process (`memq://`): no network.

use std::time::Duration;

use arcnav_bus::auth::{AuthPolicy, Freshness, GroupKey, Signer, TRAILER_LEN};
use arcnav_bus::transport::{Lcm, wall_clock_utime};

fn policy(key: u8) -> AuthPolicy {
    let channels = ["STEERING_COMMAND".to_owned(), "ARC_VOTES_.*".to_owned()];
    AuthPolicy::new(
        GroupKey::new(&[key; 32]).unwrap(),
        Freshness::default(),
        &channels,
    )
    .unwrap()
}

fn drain(lcm: &mut Lcm) -> Vec<(String, Vec<u8>)> {
    let mut out = Vec::new();
    while let Some(m) = lcm.recv_timeout(Duration::from_millis(20)).unwrap() {
        out.push((m.channel, m.data));
    }
    out
}

#[test]
fn only_fresh_messages_signed_with_the_group_key_arrive() {
    let lcm = Lcm::new("memq://").unwrap();
    // Taken before authentication is on: publishes as an outsider would.
    let outsider = lcm.publisher();
    let mut lcm = lcm.authenticate(policy(7));
    lcm.subscribe("STEERING_COMMAND");
    lcm.subscribe_regex("ARC_VOTES_.*").unwrap();
    lcm.subscribe("POSE");

    // Signed by this instance: arrives without its trailer.
    lcm.publish("STEERING_COMMAND", b"steer left").unwrap();
    lcm.publish("ARC_VOTES_ROUTE", b"votes").unwrap();
    // POSE is not an authenticated channel: open.
    outsider.publish("POSE", b"pose").unwrap();
    // Unsigned, signed with another key, and a replay of a signed message.
    outsider.publish("STEERING_COMMAND", b"forged").unwrap();
    let now = u64::try_from(wall_clock_utime()).unwrap();
    let mut other = Signer::new(GroupKey::new(&[9; 32]).unwrap());
    let wrong_key = other.sign("ARC_VOTES_OBSTACLE_AVOIDANCE", b"veto all", now);
    outsider
        .publish("ARC_VOTES_OBSTACLE_AVOIDANCE", &wrong_key)
        .unwrap();
    let mut holder = policy(7).signer();
    let captured = holder.sign("STEERING_COMMAND", b"captured", now);
    outsider.publish("STEERING_COMMAND", &captured).unwrap();
    outsider.publish("STEERING_COMMAND", &captured).unwrap();
    // A vote signed for another channel, replayed as a command.
    let vote = holder.sign("ARC_VOTES_ROUTE", b"as a command", now + 1);
    outsider.publish("STEERING_COMMAND", &vote).unwrap();
    // Stale: two seconds old.
    let stale = policy(7)
        .signer()
        .sign("STEERING_COMMAND", b"stale", now - 2_000_000);
    outsider.publish("STEERING_COMMAND", &stale).unwrap();

    let got = drain(&mut lcm);
    let names: Vec<(&str, &[u8])> = got
        .iter()
        .map(|(c, d)| (c.as_str(), d.as_slice()))
        .collect();
    assert_eq!(
        names,
        [
            ("STEERING_COMMAND", &b"steer left"[..]),
            ("ARC_VOTES_ROUTE", b"votes"),
            ("POSE", b"pose"),
            ("STEERING_COMMAND", b"captured"),
        ]
    );
    let stats = lcm.auth_stats().unwrap();
    let command = stats.channels["STEERING_COMMAND"];
    // unauthenticated, bad tag, expired, from the future, replayed
    assert_eq!(command.refused, [1, 1, 1, 0, 1]);
    assert_eq!(command.accepted, 2);
    assert_eq!(
        stats.channels["ARC_VOTES_OBSTACLE_AVOIDANCE"].refused,
        [0, 1, 0, 0, 0]
    );
    assert_eq!(stats.refused_total(), 5);
    assert!(!stats.channels.contains_key("POSE"), "POSE is not checked");
    let lines = stats.refusal_lines().join("\n");
    assert!(lines.contains("STEERING_COMMAND: 4 refused"), "{lines}");
}

#[test]
fn the_trailer_is_what_a_signed_message_adds() {
    let mut signer = policy(7).signer();
    let signed = signer.sign("STEERING_COMMAND", b"abc", 1);
    assert_eq!(signed.len(), 3 + TRAILER_LEN);
    assert_eq!(&signed[..3], b"abc");
}
