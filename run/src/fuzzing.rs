//! The bodies of the fuzz targets: each takes arbitrary bytes as a file,
//! datagram or message would bring them, and must return without panicking,
//! hanging or allocating from an unchecked size. `fuzz/` runs them under
//! libFuzzer (`cargo +nightly fuzz run NAME`); `tests/fuzz_corpus.rs` runs
//! them over the committed corpora on stable, so the suite catches a
//! regression without a fuzzer. See DEVELOPERS.md.

use std::net::{Ipv4Addr, SocketAddr};
use std::path::Path;
use std::time::{Duration, Instant};

use arcnav_bus::codec::Message;
use arcnav_bus::lcmtypes::{
    decision_t, local_map_t, obstacle_cells_t, pose_t, range_image_t, range_slice_t,
    steering_command_t, waypoints_t,
};
use arcnav_bus::log::{InTimeOrder, LogReader, ReorderWindow};
use arcnav_bus::messages::{AnyMessage, TypedEvents};
use arcnav_bus::transport::udpm::Reassembler;
use arcnav_sim::World;
use arcnav_sim::heightmap::HeightGrid;
use arcnav_vehicle::VehicleConfig;

use arcnav_config::Resolved;

/// A fuzz target: arbitrary bytes in, nothing out.
pub type Target = fn(&[u8]);

/// Every target, by the name `cargo fuzz` and the corpus directory use.
pub const TARGETS: &[(&str, Target)] = &[
    ("lcm_messages", lcm_messages),
    ("event_log", event_log),
    ("udpm_fragments", udpm_fragments),
    ("configuration", configuration),
    ("world", world),
    ("height_file", height_file),
    ("waypoints", waypoints),
    ("occupancy_map", occupancy_map),
    ("key_file", key_file),
    ("range_slices", range_slices),
    ("ros2_bag", ros2_bag),
    ("ros1_bag", ros1_bag),
    ("cdr_messages", cdr_messages),
];

/// A ROS 2 bag (MCAP): its topics chosen (as found, and as the seeds name
/// them), every message converted as a replay converts them (clouds on the
/// ERIM's grid), every event read.
pub fn ros2_bag(data: &[u8]) {
    bag("fuzz.mcap", data);
}

/// A ROS 1 bag, as [`ros2_bag`] reads an MCAP one.
pub fn ros1_bag(data: &[u8]) {
    bag("fuzz.bag", data);
}

fn bag(name: &str, data: &[u8]) {
    use arcnav_bus::log::EventSource as _;
    let bag = crate::bag::Bag::from_bytes(name, data.to_vec());
    let sensor = arcnav_perception::SensorModel::erim();
    let choices = [
        (None, None),
        (Some("/points"), Some("/odom")),
        (Some("/velodyne_points"), Some("/tf")),
    ];
    for (cloud, pose) in choices {
        let options = crate::bag::BagOptions {
            cloud: cloud.map(str::to_owned),
            pose: pose.map(str::to_owned),
            vehicle_frame: None,
            slice_lines: crate::bag::SLICE_LINES,
        };
        let Ok(plan) = bag.plan(&options, &sensor) else {
            continue;
        };
        let Ok(mut events) = bag.events(&plan) else {
            continue;
        };
        let mut n = 0u64;
        while let Ok(Some(event)) = events.next_event() {
            assert!(!event.data.is_empty());
            n += 1;
        }
        let summary = events.summary();
        assert_eq!(summary.poses + summary.clouds.values().sum::<u64>(), n);
    }
}

/// CDR bytes as each message type a replay reads; a cloud that decodes,
/// as an image on a small grid.
pub fn cdr_messages(data: &[u8]) {
    use crate::bag::msgs;
    if let Ok(cloud) = msgs::from_cdr::<msgs::PointCloud2>(data) {
        let grid = arcnav_perception::BeamTable::uniform(16, 64, 0.3, -0.3, 3.0, -3.0);
        if let Ok(image) = crate::bag::cloud::to_image(&cloud, &grid, 1 << 20) {
            assert_eq!(image.range.len(), image.beams.rows() * image.beams.cols());
        }
    }
    let _ = msgs::from_cdr::<msgs::Odometry>(data).map(|o| o.pose.pose.isometry());
    let _ = msgs::from_cdr::<msgs::PoseStamped>(data).map(|p| p.pose.isometry());
    let _ = msgs::from_cdr::<msgs::PoseWithCovarianceStamped>(data);
    if let Ok(tf) = msgs::from_cdr::<msgs::TfMessage>(data) {
        let mut frames = crate::bag::frames::Frames::default();
        for t in &tf.transforms {
            if let Ok(iso) = msgs::isometry(t.transform.translation, t.transform.rotation) {
                frames.set(&t.header.frame_id, &t.child_frame_id, iso);
            }
        }
        for t in &tf.transforms {
            let _ = frames.to_top(&t.child_frame_id);
        }
    }
}

/// LCM message decoding: by fingerprint, and as each type whatever the
/// fingerprint says; what decodes converts to arcnav's types or is refused.
pub fn lcm_messages(data: &[u8]) {
    if let Ok(Some(message)) = AnyMessage::decode(data) {
        let _ = message.on_its_channel("POSE");
        match message {
            AnyMessage::Pose(m) => drop(arcnav_vehicle::Pose::try_from(&m)),
            AnyMessage::RangeImage(m) => drop(arcnav_wire::range_image_from_wire(m)),
            AnyMessage::RangeSlice(m) => drop(arcnav_wire::range_slice_from_wire(m)),
            AnyMessage::ObstacleCells(m) => drop(arcnav_wire::obstacles_from_wire(m)),
            AnyMessage::Waypoints(m) => drop(arcnav_wire::mission_from_wire(&m)),
            AnyMessage::LocalMap(m) => drop(arcnav_wire::map_from_wire(&m)),
            AnyMessage::SteeringCommand(m) => {
                let _ = arcnav_vehicle::SteeringCommand::from(&m);
            }
            AnyMessage::DriveCommand(m) => {
                let _ = arcnav_vehicle::SteeringCommand::from(&m);
            }
            AnyMessage::ArcVotes(_) => {}
            AnyMessage::Decision(m) => drop(arcnav_wire::decision_from_wire(&m)),
            AnyMessage::GuardStatus(m) => drop(arcnav_wire::guard_status_from_wire(&m)),
        }
    }
    let _ = pose_t::decode(data);
    let _ = range_image_t::decode(data);
    let _ = range_slice_t::decode(data);
    let _ = steering_command_t::decode(data);
    let _ = arcnav_bus::messages::decode_votes(data);
    let _ = decision_t::decode(data);
    let _ = arcnav_bus::lcmtypes::guard_status_t::decode(data);
    let _ = obstacle_cells_t::decode(data);
    let _ = waypoints_t::decode(data);
    let _ = local_map_t::decode(data);
}

/// The event-log reader, in file order and in time order (a small window,
/// so restarts and stragglers are exercised), decoding what it reads.
pub fn event_log(data: &[u8]) {
    let reader = LogReader::new(data);
    let window = ReorderWindow {
        horizon_us: 1_000_000,
        max_bytes: 1 << 16,
        max_events: 64,
    };
    let mut events = TypedEvents::new(InTimeOrder::new(reader, window));
    for event in events.by_ref() {
        if event.is_err() {
            break;
        }
    }
    let mut plain = LogReader::new(data);
    while let Ok(Some(_)) = plain.next_event() {}
    let stats = plain.stats();
    assert!(stats.skipped_bytes + stats.truncated_tail_bytes <= data.len() as u64);
}

/// UDP multicast reassembly: `data` is a series of datagrams, each a
/// 2-byte big-endian length and its bytes, from two senders, 10 ms apart.
pub fn udpm_fragments(data: &[u8]) {
    let mut reassembler = Reassembler::default();
    let start = Instant::now();
    let senders = [
        SocketAddr::from((Ipv4Addr::LOCALHOST, 7667)),
        SocketAddr::from((Ipv4Addr::LOCALHOST, 7668)),
    ];
    let mut rest = data;
    let mut k = 0u64;
    while let [a, b, tail @ ..] = rest {
        let len = usize::from(u16::from_be_bytes([*a, *b])).min(tail.len());
        let (datagram, next) = tail.split_at(len);
        let now = start + Duration::from_millis(10 * k);
        if let Some((_, message)) =
            reassembler.on_datagram(senders[(k % 2) as usize], datagram, now)
        {
            assert!(message.len() <= arcnav_bus::transport::udpm::MAX_MESSAGE_SIZE);
        }
        rest = next;
        k += 1;
    }
}

/// The configuration file: parsed and checked, and what it sizes (the
/// perception grid, the local map's ring, the arc set) built.
pub fn configuration(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data)
        && let Ok(config) =
            Resolved::from_toml(text, "fuzz.toml", &arcnav_behaviours::Registry::builtin())
    {
        let _ = config.perception_node();
        let _ = config.decision_cycle::<()>(arcnav_pipeline::Delivery::held(&config.pipeline));
        let _ = config.arbiter();
    }
}

/// World files (without height files, which are their own target).
pub fn world(data: &[u8]) {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if text.contains("heightmap") {
        return;
    }
    if let Ok(world) = World::from_toml(text, "fuzz.toml", None) {
        let _ = world.validate_for(&VehicleConfig::default(), "fuzz.toml");
        let _ = world.height(world.start.0[0], world.start.0[1]);
    }
}

/// Height files: the first byte picks `.npy` (even) or `.asc` (odd).
pub fn height_file(data: &[u8]) {
    let Some((first, bytes)) = data.split_first() else {
        return;
    };
    let name = if first % 2 == 0 { "h.npy" } else { "h.asc" };
    if let Ok(grid) = HeightGrid::parse(Path::new(name), bytes.to_vec(), Some(0.5), None) {
        let b = grid.bounds();
        assert!(b.iter().all(|v| v.is_finite()));
    }
}

/// `--waypoints` files.
pub fn waypoints(data: &[u8]) {
    if let Ok(text) = std::str::from_utf8(data)
        && let Ok(mission) = crate::replay::parse_waypoints(text)
    {
        assert!(
            mission
                .waypoints
                .iter()
                .all(|w| w.x.is_finite() && w.y.is_finite())
        );
    }
}

/// Static occupancy maps: the first byte picks a `.npy` array (even) or a
/// map_server YAML (odd), whose image is the bytes after the YAML's first
/// NUL. What parses is gathered onto 0.4 m patches.
pub fn occupancy_map(data: &[u8]) {
    use arcnav_config::occupancy::{parse_npy, parse_yaml};
    let Some((first, bytes)) = data.split_first() else {
        return;
    };
    let config = arcnav_localmap::OccupancyConfig::default();
    let grid = if first % 2 == 0 {
        parse_npy(Path::new("fuzz.npy"), bytes, &config)
    } else {
        let (yaml, image) = match bytes.iter().position(|&b| b == 0) {
            Some(i) => (&bytes[..i], &bytes[i + 1..]),
            None => (bytes, &[][..]),
        };
        parse_yaml(Path::new("fuzz.yaml"), yaml, |_| Ok(image.to_vec()))
    };
    if let Ok(grid) = grid {
        assert_eq!(grid.occupied.len(), grid.rows * grid.cols);
        let _ = arcnav_localmap::StaticMap::from_grid(&grid, 0.4);
    }
}

/// `[bus.auth]` key files' text.
pub fn key_file(data: &[u8]) {
    if let Ok(key) = arcnav_bus::auth::GroupKey::parse(data) {
        // A key that parses signs.
        let mut signer = arcnav_bus::auth::Signer::new(key);
        let signed = signer.sign("STEERING_COMMAND", data, 1);
        assert!(signed.len() > data.len());
    }
}

/// An evaluator that checks each image and reports no cell: the
/// `range_slices` target fuzzes the assembly of frames, not an evaluator
/// (each has its own tests), and a real one judged its mostly empty frames
/// at 58 inputs a second.
struct Checking;

impl arcnav_perception::TerrainEvaluator for Checking {
    fn name(&self) -> &'static str {
        "checking"
    }

    fn evaluate_with(
        &mut self,
        image: &arcnav_perception::RangeImage,
        _world_from_vehicle: &arcnav_vehicle::Isometry,
        report: &mut arcnav_perception::ObstacleReport,
        _runner: &dyn arcnav_perception::Runner,
    ) -> Result<arcnav_perception::ImageStats, arcnav_perception::PerceptionError> {
        image.validate()?;
        *report = arcnav_perception::ObstacleReport {
            utime: image.utime,
            sensor: image.sensor.clone(),
            cell_size_m: 0.2,
            ..arcnav_perception::ObstacleReport::default()
        };
        Ok(arcnav_perception::ImageStats::default())
    }
}

/// Streamed range slices: `data` is a series of `range_slice_t` messages,
/// each a 2-byte big-endian length and its bytes, fed to one frame
/// assembler as perception feeds them (the default support), then the
/// input ends.
pub fn range_slices(data: &[u8]) {
    use arcnav_perception::{
        FrameStream, InOrder, PerceptionConfig, StreamingConfig, TerrainEvaluator,
    };
    let perception = PerceptionConfig::default();
    let mut evaluator = Checking;
    let mut stream = FrameStream::new(StreamingConfig::default(), evaluator.support(), &perception);
    let pose = arcnav_vehicle::Isometry::identity();
    let poses = |_: arcnav_vehicle::Utime| Some(pose);
    let mut rest = data;
    while let [a, b, tail @ ..] = rest {
        let len = usize::from(u16::from_be_bytes([*a, *b])).min(tail.len());
        let (bytes, next) = tail.split_at(len);
        rest = next;
        let Ok(msg) = range_slice_t::decode(bytes) else {
            continue;
        };
        if let Ok(slice) = arcnav_wire::range_slice_from_wire(msg) {
            let _ = stream.on_slice(&slice, &poses, &mut evaluator, &InOrder, &mut |_| {});
        }
    }
    let _ = stream.flush(&poses, &mut evaluator, &InOrder, &mut |_| {});
    let c = stream.counts;
    assert!(c.slices <= data.len() as u64);
}
