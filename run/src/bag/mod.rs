//! ROS bags (ROS 1's `.bag`; ROS 2's MCAP, CDR messages) as the input of
//! a replay: their point
//! clouds become range images, their odometry, poses or `/tf` chain the
//! vehicle's pose, their `/tf_static` the sensor's mount, all as the LCM
//! events an arcnav log holds, so that everything a replay does with a
//! log (the summary, `--out`, `--from`/`--to`, the counts) it does with a
//! bag.
//!
//! A bag is read twice: once to list its topics and take what the replay
//! needs before it starts (the static frames, the first pose, which topics
//! to use), then message by message in the file's order. The file is
//! mapped, not read into memory; one cloud is converted at a time.
//!
//! Nothing in a bag can crash the replay: a message whose schema is not
//! the one decoded here, one that does not decode, a cloud that cannot be
//! an image, damage that ends the file early: each is counted by topic and
//! reason ([`BagSummary::refused`], [`BagSummary::damaged`]).

pub mod cloud;
pub mod definitions;
pub mod frames;
pub mod msgs;
mod records;
mod ros1;

use std::collections::BTreeMap;
use std::io::Read as _;
use std::path::{Path, PathBuf};

use arcnav_bus::Message as _;
use arcnav_bus::lcmtypes::pose_t;
use arcnav_bus::log::{EventSource, LogEvent, LogStats};
use arcnav_bus::messages::channels;
use arcnav_perception::RangeImage;
use arcnav_perception::sensor::{MAX_IMAGE_BYTES, SensorModel};
use arcnav_vehicle::{Isometry, Pose, Utime};
use nalgebra::Vector3;
use serde::Serialize;

use cloud::{CloudCounts, Layout};
use frames::Frames;
use msgs::{Kind, Schema};
pub use records::MCAP_MAGIC;
use records::{ChannelInfo, RawMessage, Records};
pub use ros1::ROS1_MAGIC;
use ros1::Ros1Records;

/// What a file holds, by its first bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    Mcap,
    Ros1,
    /// Anything else: an LCM log, or not a log at all.
    Other,
}

/// The format of the file at `path`.
pub fn format_of(path: &Path) -> std::io::Result<Format> {
    let mut head = [0u8; 13];
    let mut file = std::fs::File::open(path)?;
    let mut n = 0;
    while n < head.len() {
        match file.read(&mut head[n..])? {
            0 => break,
            k => n += k,
        }
    }
    let head = &head[..n];
    Ok(if head.starts_with(MCAP_MAGIC) {
        Format::Mcap
    } else if head.starts_with(ROS1_MAGIC) {
        Format::Ros1
    } else {
        Format::Other
    })
}

/// Which of a bag's topics and frames to use (`arcnav replay --cloud`,
/// `--pose`, `--vehicle-frame`); each is found when there is one of its
/// kind.
#[derive(Debug, Clone, Default)]
pub struct BagOptions {
    pub cloud: Option<String>,
    /// A pose topic, or `/tf` for the chain of frames to the vehicle's.
    pub pose: Option<String>,
    pub vehicle_frame: Option<String>,
    /// Columns per slice when clouds carry per-point times (0: each cloud
    /// one image all the same).
    pub slice_lines: usize,
}

/// Columns per slice by default: an Ouster's packet.
pub const SLICE_LINES: usize = 16;

/// A bag that cannot be replayed at all.
#[derive(Debug, thiserror::Error)]
pub enum BagError {
    #[error("cannot read the bag {path}: {source}")]
    Open {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path} is not a readable bag (ROS 1, or ROS 2's MCAP): {reason}")]
    Unreadable { path: PathBuf, reason: String },
    #[error("{0}")]
    Choice(String),
}

/// One topic of a bag, and what the replay made of it.
#[derive(Debug, Clone, Serialize)]
pub struct TopicSummary {
    pub topic: String,
    pub type_name: String,
    pub messages: u64,
    /// `cloud`, `pose`, `frames`: what the replay used it for.
    pub used_as: Option<&'static str>,
    /// Why not, when it was not used.
    pub skipped_because: Option<String>,
}

/// What a replay read from a bag.
#[derive(Debug, Clone, Serialize)]
pub struct BagSummary {
    pub format: &'static str,
    pub topics: Vec<TopicSummary>,
    pub cloud_topic: String,
    /// The pose topic, or `/tf (odom → base_link)`.
    pub poses_from: String,
    pub vehicle_frame: String,
    /// Where the sensor's mount came from.
    pub mount_from: String,
    /// Clouds made range images, by layout.
    pub clouds: BTreeMap<String, u64>,
    /// Of those, streamed as slices of columns at their per-point times:
    /// the time field's name, the columns per slice and the slices made.
    pub streamed: Option<(String, usize)>,
    pub slices: u64,
    /// Their points.
    pub points: CloudCounts,
    pub poses: u64,
    /// Messages of the topics used that could not be, by topic and reason.
    pub refused: BTreeMap<String, u64>,
    /// Damage that ended the bag before its end, if any.
    pub damaged: Option<String>,
}

impl BagSummary {
    /// Messages lost: refused, or the bag ended by damage.
    pub fn lost_input(&self) -> bool {
        !self.refused.is_empty() || self.damaged.is_some()
    }
}

/// A bag, mapped (or, for the fuzz targets, in memory).
pub struct Bag {
    path: PathBuf,
    bytes: Bytes,
}

enum Bytes {
    Mapped(memmap2::Mmap),
    Owned(Vec<u8>),
}

impl std::ops::Deref for Bytes {
    type Target = [u8];

    fn deref(&self) -> &[u8] {
        match self {
            Self::Mapped(map) => map,
            Self::Owned(bytes) => bytes,
        }
    }
}

impl Bag {
    /// Opens a bag: ROS 1's or MCAP, told by its first bytes.
    pub fn open(path: &Path) -> Result<Self, BagError> {
        let open = |source| BagError::Open {
            path: path.to_owned(),
            source,
        };
        let file = std::fs::File::open(path).map_err(open)?;
        // SAFETY: the map is only read; a file changed under a replay gives
        // wrong bytes (decoded with every check), not undefined behaviour
        // of ours, short of the file being truncated meanwhile.
        let map = unsafe { memmap2::Mmap::map(&file) }.map_err(open)?;
        Ok(Self {
            path: path.to_owned(),
            bytes: Bytes::Mapped(map),
        })
    }

    /// A bag of `bytes` (the file's), named `name` in messages.
    pub fn from_bytes(name: &str, bytes: Vec<u8>) -> Self {
        Self {
            path: PathBuf::from(name),
            bytes: Bytes::Owned(bytes),
        }
    }

    fn messages(&self) -> Result<Messages<'_>, BagError> {
        if self.bytes.starts_with(MCAP_MAGIC) {
            Ok(Messages::Mcap(Box::new(Records::new(&self.bytes))))
        } else if self.bytes.starts_with(ROS1_MAGIC) {
            Ok(Messages::Ros1(Ros1Records::new(&self.bytes)))
        } else {
            Err(BagError::Unreadable {
                path: self.path.clone(),
                reason: "it starts with neither `#ROSBAG V2.0` nor MCAP's magic bytes".into(),
            })
        }
    }

    /// What the summary calls the bag's format.
    fn format(&self) -> &'static str {
        if self.bytes.starts_with(ROS1_MAGIC) {
            "ROS 1 (bag)"
        } else {
            "MCAP"
        }
    }

    pub fn len(&self) -> u64 {
        self.bytes.len() as u64
    }

    pub fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// Reads the bag once: its topics, the static frames, the first
    /// pose; chooses the topics to use.
    pub fn plan(&self, options: &BagOptions, sensor: &SensorModel) -> Result<Plan, BagError> {
        let mut topics: BTreeMap<String, Topic> = BTreeMap::new();
        let mut statics = Frames::default();
        let mut damaged = None;
        for message in self.messages()? {
            let message = match message {
                Ok(m) => m,
                Err(e) => {
                    damaged = Some(e);
                    break;
                }
            };
            let channel = &message.channel;
            let topic = topics
                .entry(channel.topic.clone())
                .or_insert_with(|| Topic::of(channel));
            topic.messages += 1;
            let Ok(kind) = topic.readable() else { continue };
            match kind {
                Kind::Transforms if channel.topic == "/tf_static" => {
                    if let Ok(tf) = message.decode::<msgs::TfMessage>() {
                        set_frames(&mut statics, &tf);
                    }
                }
                Kind::Cloud if topic.frame.is_none() => {
                    if let Ok(c) = message.decode::<msgs::PointCloud2>() {
                        topic.timed = cloud::time_field(&c.fields).is_some();
                        topic.frame = Some(c.header.frame_id);
                    }
                }
                Kind::Odometry if topic.frame.is_none() => {
                    if let Ok(o) = message.decode::<msgs::Odometry>() {
                        topic.frame = Some(o.child_frame_id);
                    }
                }
                _ => {}
            }
            if kind == Kind::Transforms
                && channel.topic == "/tf"
                && let Ok(tf) = message.decode::<msgs::TfMessage>()
            {
                set_frames(&mut topic.frames, &tf);
            }
        }
        Plan::choose(self.format(), topics, statics, damaged, options, sensor)
    }

    /// The bag's messages as a replay's events, as `plan` chose them.
    pub fn events<'a>(&'a self, plan: &'a Plan) -> Result<BagEvents<'a>, BagError> {
        Ok(BagEvents {
            messages: self.messages()?,
            plan,
            summary: plan.summary.clone(),
            dynamic: plan.statics.clone(),
            previous: None,
            stats: LogStats::default(),
            ended: false,
            held: std::collections::BinaryHeap::new(),
            released_before: Utime::MIN,
            newest: Utime::MIN,
            sequence: 0,
        })
    }
}

fn set_frames(frames: &mut Frames, tf: &msgs::TfMessage) {
    for t in &tf.transforms {
        match msgs::isometry(t.transform.translation, t.transform.rotation) {
            Ok(iso) => frames.set(&t.header.frame_id, &t.child_frame_id, iso),
            Err(_) => frames.refused += 1,
        }
    }
}

/// A topic as the first reading found it.
struct Topic {
    type_name: String,
    kind: Option<Kind>,
    /// Why its schema cannot be read, if it cannot.
    unreadable: Option<String>,
    messages: u64,
    /// A cloud's frame, an odometry's child frame (from its first message).
    frame: Option<String>,
    /// A cloud whose first message has a per-point time field.
    timed: bool,
    /// `/tf`'s frames, all of them, for choosing the vehicle's chain.
    frames: Frames,
}

impl Topic {
    fn of(channel: &ChannelInfo) -> Self {
        let schema = channel.schema.as_deref();
        let type_name = schema.map_or_else(String::new, |s| s.name.clone());
        let kind = Kind::of(&type_name);
        let unreadable = match (kind, schema) {
            (None, _) => Some("not a type the replay reads".to_string()),
            (Some(kind), Some(s)) if channel.message_encoding == "ros1" => {
                let ros1 = kind.ros1_md5sum();
                match s.md5sum.as_deref() {
                    Some(md5) if md5 == ros1 => None,
                    Some(md5) => Some(format!(
                        "its type's md5sum {md5} is not ROS 1's {type_name} ({ros1})"
                    )),
                    // An MCAP file's ROS 1 messages (converted from a bag):
                    // their definition, field by field.
                    None if s.encoding == "ros1msg" => {
                        let text = String::from_utf8_lossy(&s.data);
                        Schema(&text)
                            .check_ros1(kind)
                            .err()
                            .map(|e| format!("its schema differs from ROS 1's: {e}"))
                    }
                    None => Some(format!("schema encoding {:?}, not ros1msg", s.encoding)),
                }
            }
            (Some(_), _) if channel.message_encoding != "cdr" => Some(format!(
                "message encoding {:?}, not CDR",
                channel.message_encoding
            )),
            (Some(_), Some(s)) if s.encoding != "ros2msg" => {
                Some(format!("schema encoding {:?}, not ros2msg", s.encoding))
            }
            (Some(kind), Some(s)) => {
                let text = String::from_utf8_lossy(&s.data);
                Schema(&text)
                    .check(kind)
                    .err()
                    .map(|e| format!("its schema differs from ROS 2's: {e}"))
            }
            (Some(_), None) => Some("no schema".to_string()),
        };
        Self {
            type_name,
            kind,
            unreadable,
            messages: 0,
            frame: None,
            timed: false,
            frames: Frames::default(),
        }
    }

    fn readable(&self) -> Result<Kind, ()> {
        match (self.kind, &self.unreadable) {
            (Some(kind), None) => Ok(kind),
            _ => Err(()),
        }
    }
}

/// Where the vehicle's pose comes from.
#[derive(Debug, Clone, PartialEq, Eq)]
enum PoseSource {
    Topic(String, Kind),
    /// `/tf`: the chain from the vehicle's frame to its top.
    Tf,
}

/// What a replay of a bag uses, chosen before it starts.
pub struct Plan {
    /// The topics used whose messages cannot be read, and why.
    unreadable: BTreeMap<String, String>,
    cloud_topic: String,
    poses: PoseSource,
    vehicle_frame: String,
    statics: Frames,
    /// The configured sensor, with the mount the bag gives it.
    sensor: SensorModel,
    channel: &'static str,
    /// Columns per slice of the clouds (0: none; only a cloud topic whose
    /// first message has per-point times is streamed).
    slice_lines: usize,
    summary: BagSummary,
}

impl Plan {
    fn choose(
        format: &'static str,
        topics: BTreeMap<String, Topic>,
        statics: Frames,
        damaged: Option<String>,
        options: &BagOptions,
        sensor: &SensorModel,
    ) -> Result<Self, BagError> {
        let listing = || {
            topics
                .iter()
                .map(|(name, t)| format!("{name} ({}, {} messages)", t.type_name, t.messages))
                .collect::<Vec<_>>()
                .join(", ")
        };
        // Topics of a kind by their type's name: one whose schema cannot be
        // read is still the one chosen (its messages are then counted as
        // lost, never misread).
        let of_kind = |want: &dyn Fn(Kind) -> bool| -> Vec<&String> {
            topics
                .iter()
                .filter(|(_, t)| t.kind.is_some_and(want))
                .map(|(name, _)| name)
                .collect()
        };
        let named =
            |given: &str, what: &str, want: &dyn Fn(Kind) -> bool| -> Result<String, BagError> {
                match topics.get(given) {
                    None => Err(BagError::Choice(format!(
                        "the bag has no topic {given}; its topics: {}",
                        listing()
                    ))),
                    Some(t) if t.kind.is_some_and(want) => Ok(given.to_owned()),
                    Some(t) => Err(BagError::Choice(format!(
                        "{given} is a {}, not {what}",
                        t.type_name
                    ))),
                }
            };
        // The one topic of a kind; none; or an error naming the several.
        let only =
            |found: Vec<&String>, what: &str, flag: &str| -> Result<Option<String>, BagError> {
                match found.as_slice() {
                    [one] => Ok(Some((*one).clone())),
                    [] => Ok(None),
                    several => Err(BagError::Choice(format!(
                        "the bag holds {} {what} topics ({}): choose one with {flag}",
                        several.len(),
                        several
                            .iter()
                            .map(|s| s.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))),
                }
            };
        let is_cloud = |k: Kind| k == Kind::Cloud;
        let cloud_topic = match &options.cloud {
            Some(given) => named(given, "a sensor_msgs/PointCloud2", &is_cloud)?,
            None => only(of_kind(&is_cloud), "point-cloud", "--cloud")?.ok_or_else(|| {
                BagError::Choice(format!(
                    "the bag holds no point cloud (sensor_msgs/PointCloud2); its topics: {}",
                    listing()
                ))
            })?,
        };
        let has_tf = topics
            .get("/tf")
            .is_some_and(|t| t.readable() == Ok(Kind::Transforms));
        let pose_topic = |topic: String| {
            let kind = topics[&topic].kind.unwrap_or(Kind::PoseStamped);
            PoseSource::Topic(topic, kind)
        };
        let poses = match options.pose.as_deref() {
            Some("/tf") if has_tf => PoseSource::Tf,
            Some(given) => pose_topic(named(
                given,
                "a pose (nav_msgs/Odometry, geometry_msgs/PoseStamped or PoseWithCovarianceStamped) or /tf",
                &Kind::is_pose,
            )?),
            None => match only(of_kind(&Kind::is_pose), "pose", "--pose (or --pose /tf)")? {
                Some(topic) => pose_topic(topic),
                None if has_tf => PoseSource::Tf,
                None => {
                    return Err(BagError::Choice(format!(
                        "the bag holds no pose (nav_msgs/Odometry, geometry_msgs/PoseStamped, \
                         PoseWithCovarianceStamped) nor /tf; its topics: {}",
                        listing()
                    )));
                }
            },
        };
        let vehicle_frame = options
            .vehicle_frame
            .clone()
            .or_else(|| match &poses {
                PoseSource::Topic(t, Kind::Odometry) => {
                    topics[t].frame.clone().filter(|f| !f.is_empty())
                }
                _ => None,
            })
            .unwrap_or_else(|| "base_link".to_owned());
        let cloud_frame = topics[&cloud_topic].frame.clone().unwrap_or_default();
        // The mount: the static frames first, then /tf's (a mount sent on
        // /tf, as some drivers do).
        let tf_frames = topics.get("/tf").map(|t| &t.frames);
        let found = statics
            .between(&vehicle_frame, &cloud_frame)
            .map(|m| (m, format!("/tf_static: {vehicle_frame} ← {cloud_frame}")))
            .or_else(|| {
                tf_frames
                    .and_then(|f| f.between(&vehicle_frame, &cloud_frame))
                    .map(|m| (m, format!("/tf: {vehicle_frame} ← {cloud_frame}")))
            });
        let mut sensor = sensor.clone();
        let mount_from = match &found {
            Some((mount, from)) => {
                sensor.vehicle_from_sensor = *mount;
                from.clone()
            }
            None => format!(
                "[sensor] mount (the bag has no transform {vehicle_frame} ← {cloud_frame:?})"
            ),
        };
        if poses == PoseSource::Tf
            && !tf_frames.is_some_and(|f| {
                f.to_top(&vehicle_frame)
                    .is_some_and(|(top, _)| top != vehicle_frame)
            })
        {
            return Err(BagError::Choice(format!(
                "/tf has no frame above {vehicle_frame}: name the vehicle's frame with --vehicle-frame"
            )));
        }
        let poses_from = match &poses {
            PoseSource::Topic(t, _) => format!("{t} ({})", topics[t].type_name),
            PoseSource::Tf => {
                let top = tf_frames
                    .and_then(|f| f.to_top(&vehicle_frame))
                    .map_or_else(String::new, |(top, _)| top);
                format!("/tf ({top} → {vehicle_frame})")
            }
        };
        let used = |name: &str| -> Option<&'static str> {
            if name == cloud_topic {
                Some("cloud")
            } else if matches!(&poses, PoseSource::Topic(t, _) if t == name)
                || (poses == PoseSource::Tf && name == "/tf")
            {
                Some("pose")
            } else if name == "/tf_static" && found.is_some() {
                Some("frames")
            } else {
                None
            }
        };
        let summary = BagSummary {
            format,
            topics: topics
                .iter()
                .map(|(name, t)| {
                    let used_as = used(name);
                    TopicSummary {
                        topic: name.clone(),
                        type_name: t.type_name.clone(),
                        messages: t.messages,
                        used_as,
                        skipped_because: match (used_as, &t.unreadable) {
                            (Some(_), Some(why)) => Some(why.clone()),
                            (Some(_), None) => None,
                            (None, Some(why)) => Some(why.clone()),
                            (None, None) => Some("not chosen".to_string()),
                        },
                    }
                })
                .collect(),
            cloud_topic: cloud_topic.clone(),
            poses_from,
            vehicle_frame: vehicle_frame.clone(),
            mount_from,
            clouds: BTreeMap::new(),
            streamed: None,
            slices: 0,
            points: CloudCounts::default(),
            poses: 0,
            refused: BTreeMap::new(),
            damaged,
        };
        let unreadable = topics
            .iter()
            .filter(|(name, _)| used(name).is_some())
            .filter_map(|(name, t)| Some((name.clone(), t.unreadable.clone()?)))
            .collect();
        let slice_lines = if topics[&cloud_topic].timed {
            options.slice_lines
        } else {
            0
        };
        Ok(Self {
            unreadable,
            cloud_topic,
            poses,
            vehicle_frame,
            statics,
            channel: channels::RANGE_IMAGE,
            sensor,
            slice_lines,
            summary,
        })
    }

    /// The bag's first pose of the vehicle, read again (for `--goal-ahead`).
    pub fn first_pose(&self, bag: &Bag) -> Result<Option<Pose>, BagError> {
        let mut events = bag.events(self)?;
        while let Some(event) = events.next_event().ok().flatten() {
            if event.channel == channels::POSE {
                let msg = pose_t::decode(&event.data).ok();
                return Ok(msg.and_then(|m| Pose::try_from(&m).ok()));
            }
        }
        Ok(None)
    }
}

/// A bag's messages in file order, by its format.
enum Messages<'a> {
    Mcap(Box<Records<'a>>),
    Ros1(Ros1Records<'a>),
}

impl Messages<'_> {
    fn position(&self) -> u64 {
        match self {
            Self::Mcap(r) => Records::position(r),
            Self::Ros1(r) => r.position(),
        }
    }
}

impl Iterator for Messages<'_> {
    type Item = Result<RawMessage, String>;

    fn next(&mut self) -> Option<Self::Item> {
        match self {
            Self::Mcap(r) => r.next(),
            Self::Ros1(r) => r.next(),
        }
    }
}

impl RawMessage {
    /// The message decoded as `T`, by its channel's encoding.
    fn decode<'a, T: msgs::Message<'a>>(&'a self) -> Result<T, msgs::DecodeError> {
        let encoding = if self.channel.message_encoding == "ros1" {
            msgs::Encoding::Ros1
        } else {
            msgs::Encoding::Cdr
        };
        T::decode(encoding, &self.data)
    }
}

/// The most bytes of a range image a cloud may become.
const MAX_PIXELS: u64 = (MAX_IMAGE_BYTES / 4) as u64;

/// A bag's messages as LCM events: POSE (`pose_t`) and RANGE_IMAGE
/// (`range_image_t`), stamped with the bag's log times.
pub struct BagEvents<'a> {
    messages: Messages<'a>,
    plan: &'a Plan,
    summary: BagSummary,
    /// `/tf_static` and `/tf` as read so far.
    dynamic: Frames,
    /// The previous pose, for a velocity where the message has none.
    previous: Option<Pose>,
    stats: LogStats,
    ended: bool,
    /// Streaming, the events made but not yet given, by time (see
    /// [`Held`]); given once nothing still to come can precede them.
    held: std::collections::BinaryHeap<std::cmp::Reverse<Held>>,
    /// Held events before this time may go: the latest streamed cloud's
    /// stamp (every slice still to come is later), or the newest time
    /// read less [`HOLD_S`].
    released_before: Utime,
    newest: Utime,
    sequence: u64,
}

/// An event held for its time: the slices of a cloud are taken over its
/// frame, and the poses read before the cloud go among them, as a sensor
/// streaming its slices would have sent them (a slice before a pose of
/// the same time, as `arcnav sim` logs them).
#[derive(Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Held {
    utime: Utime,
    /// 0 a slice, 1 anything else.
    rank: u8,
    sequence: u64,
    channel: String,
    data: Vec<u8>,
}

/// How far behind the newest time read an event is held at most, s:
/// beyond a frame's period and a driver's delay in sending it.
const HOLD_S: f64 = 2.0;

impl BagEvents<'_> {
    /// What was read, used and refused so far.
    pub fn summary(&self) -> &BagSummary {
        &self.summary
    }

    fn refuse(&mut self, topic: &str, why: impl std::fmt::Display) {
        *self
            .summary
            .refused
            .entry(format!("{topic}: {why}"))
            .or_default() += 1;
    }

    /// The LCM events a bag message makes: none, one, or a streamed
    /// cloud's slices; each with its time (µs) and rank (0 a slice).
    fn convert(&mut self, message: &RawMessage) -> Vec<(Utime, u8, String, Vec<u8>)> {
        let mut out = Vec::new();
        if let Some((utime, channel, data)) = self.convert_one(message, &mut out) {
            out.push((utime, 1, channel, data));
        }
        out
    }

    /// The LCM event a bag message makes, if any; a streamed cloud's
    /// slices go to `slices`.
    fn convert_one(
        &mut self,
        message: &RawMessage,
        slices: &mut Vec<(Utime, u8, String, Vec<u8>)>,
    ) -> Option<(Utime, String, Vec<u8>)> {
        let topic = message.channel.topic.as_str();
        let plan = self.plan;
        if let Some(why) = plan.unreadable.get(topic) {
            self.refuse(topic, why);
            return None;
        }
        if topic == plan.cloud_topic {
            let cloud = match message.decode::<msgs::PointCloud2>() {
                Ok(c) => c,
                Err(e) => {
                    self.refuse(topic, e);
                    return None;
                }
            };
            let image = match cloud::to_image(&cloud, &plan.sensor.beams, MAX_PIXELS) {
                Ok(i) => i,
                Err(e) => {
                    self.refuse(topic, e);
                    return None;
                }
            };
            let layout = match image.layout {
                Layout::Organized => "organized",
                Layout::Rings => "rings",
                Layout::SensorGrid => "sensor grid",
            };
            *self.summary.clouds.entry(layout.to_owned()).or_default() += 1;
            self.summary.points.add(&image.counts);
            let stamp = cloud.header.stamp.utime();
            let range_image = RangeImage {
                utime: stamp,
                sensor: plan.sensor.id.clone(),
                vehicle_from_sensor: plan.sensor.vehicle_from_sensor,
                beams: image.beams,
                range: image.range,
            };
            if let Some((field, line_utimes)) = image.line_utimes.filter(|_| plan.slice_lines > 0) {
                self.summary.streamed = Some((field, plan.slice_lines));
                self.released_before = self.released_before.max(stamp);
                for slice in column_slices(&range_image, &line_utimes, plan.slice_lines) {
                    match arcnav_wire::range_slice_to_wire(&slice).encode() {
                        Ok(bytes) => {
                            self.summary.slices += 1;
                            slices.push((slice.utime, 0, plan.channel.to_owned(), bytes));
                        }
                        Err(e) => self.refuse(topic, e),
                    }
                }
                return None;
            }
            let wire = arcnav_wire::range_image_to_wire(&range_image);
            return match wire.encode() {
                Ok(bytes) => Some((stamp, plan.channel.to_owned(), bytes)),
                Err(e) => {
                    self.refuse(topic, e);
                    None
                }
            };
        }
        let pose = match &plan.poses {
            PoseSource::Topic(t, kind) if t == topic => self.pose_of(*kind, message),
            PoseSource::Tf if topic == "/tf" || topic == "/tf_static" => {
                let tf = match message.decode::<msgs::TfMessage>() {
                    Ok(tf) => tf,
                    Err(e) => {
                        self.refuse(topic, e);
                        return None;
                    }
                };
                set_frames(&mut self.dynamic, &tf);
                let moved = tf
                    .transforms
                    .iter()
                    .filter(|t| {
                        self.dynamic
                            .on_chain(&plan.vehicle_frame, &t.child_frame_id)
                    })
                    .map(|t| t.header.stamp.utime())
                    .max();
                let at = moved?;
                let (_, top_from_vehicle) = self.dynamic.to_top(&plan.vehicle_frame)?;
                Ok(self.moving(at, top_from_vehicle, None))
            }
            _ => return None,
        };
        match pose {
            Ok(pose) => {
                self.summary.poses += 1;
                self.previous = Some(pose);
                pose_t::from(&pose)
                    .encode()
                    .ok()
                    .map(|bytes| (pose.utime, channels::POSE.to_owned(), bytes))
            }
            Err(why) => {
                self.refuse(topic, why);
                None
            }
        }
    }

    /// A pose message as the vehicle's pose.
    fn pose_of(&self, kind: Kind, message: &RawMessage) -> Result<Pose, String> {
        let (stamp, pose, twist) = match kind {
            Kind::Odometry => {
                let o = message
                    .decode::<msgs::Odometry>()
                    .map_err(|e| e.to_string())?;
                (o.header.stamp, o.pose.pose, Some(o.twist.twist))
            }
            Kind::PoseWithCovariance => {
                let p = message
                    .decode::<msgs::PoseWithCovarianceStamped>()
                    .map_err(|e| e.to_string())?;
                (p.header.stamp, p.pose.pose, None)
            }
            _ => {
                let p = message
                    .decode::<msgs::PoseStamped>()
                    .map_err(|e| e.to_string())?;
                (p.header.stamp, p.pose, None)
            }
        };
        let world_from_vehicle = pose.isometry().map_err(|e| e.to_string())?;
        Ok(self.moving(stamp.utime(), world_from_vehicle, twist))
    }

    /// The pose at `utime`, its velocity from the twist (in the vehicle's
    /// frame, REP 105) or, without one, from the previous pose.
    fn moving(
        &self,
        utime: Utime,
        world_from_vehicle: Isometry,
        twist: Option<msgs::Twist>,
    ) -> Pose {
        let (velocity, yaw_rate) = match (twist, &self.previous) {
            (Some(t), _) => (world_from_vehicle.rotation * t.linear.vector(), t.angular.z),
            (None, Some(p)) if utime > p.utime => {
                let dt = (utime - p.utime) as f64 * 1e-6;
                let dp =
                    world_from_vehicle.translation.vector - p.world_from_vehicle.translation.vector;
                let yaw = |iso: &Isometry| iso.rotation.euler_angles().2;
                let dyaw = (yaw(&world_from_vehicle) - yaw(&p.world_from_vehicle)
                    + std::f64::consts::PI)
                    .rem_euclid(std::f64::consts::TAU)
                    - std::f64::consts::PI;
                (dp / dt, dyaw / dt)
            }
            _ => (Vector3::zeros(), 0.0),
        };
        Pose {
            utime,
            world_from_vehicle,
            velocity,
            yaw_rate,
        }
    }
}

impl BagEvents<'_> {
    /// The next held event whose time has come (any, once the bag ended).
    fn release(&mut self) -> Option<LogEvent> {
        let before = self
            .released_before
            .max(self.newest.saturating_sub((HOLD_S * 1e6) as Utime));
        let std::cmp::Reverse(next) = self.held.peek()?;
        if !self.ended && next.utime >= before {
            return None;
        }
        let std::cmp::Reverse(held) = self.held.pop()?;
        Some(self.event(held.utime, held.channel, held.data))
    }

    fn event(&mut self, utime: Utime, channel: String, data: Vec<u8>) -> LogEvent {
        self.stats.events += 1;
        LogEvent {
            event_number: self.stats.events as i64,
            timestamp: utime,
            channel,
            data,
        }
    }
}

/// An image as slices of `lines` columns, each column acquired at its
/// time in `line_utimes`, each slice complete at its last.
fn column_slices<'a>(
    image: &'a RangeImage,
    line_utimes: &'a [Utime],
    lines: usize,
) -> impl Iterator<Item = arcnav_perception::RangeSlice> + 'a {
    let (rows, cols) = (image.rows(), image.cols());
    (0..cols).step_by(lines.max(1)).map(move |first| {
        let end = (first + lines.max(1)).min(cols);
        let times = line_utimes[first..end].to_vec();
        arcnav_perception::RangeSlice {
            utime: times.iter().copied().max().unwrap_or(image.utime),
            frame_utime: image.utime,
            sensor: image.sensor.clone(),
            vehicle_from_sensor: image.vehicle_from_sensor,
            frame_rows: rows,
            frame_cols: cols,
            axis: arcnav_perception::stream::SliceAxis::Columns,
            first,
            beams: arcnav_perception::BeamTable {
                elevation: image.beams.elevation.clone(),
                azimuth: image.beams.azimuth[first..end].to_vec(),
            },
            line_utimes: times,
            range: (0..rows)
                .flat_map(|r| {
                    image.range[r * cols + first..r * cols + end]
                        .iter()
                        .copied()
                })
                .collect(),
        }
    })
}

impl EventSource for BagEvents<'_> {
    fn next_event(&mut self) -> std::io::Result<Option<LogEvent>> {
        loop {
            if let Some(event) = self.release() {
                return Ok(Some(event));
            }
            if self.ended {
                return Ok(None);
            }
            let message = match self.messages.next() {
                None => {
                    self.ended = true;
                    continue;
                }
                Some(Err(e)) => {
                    // Counted, and the bag ends here: its summary says so.
                    self.summary.damaged = Some(e);
                    self.stats.corrupt_events += 1;
                    self.ended = true;
                    continue;
                }
                Some(Ok(m)) => m,
            };
            let log_time = i64::try_from(message.log_time / 1000).unwrap_or(i64::MAX);
            let made = self.convert(&message);
            if self.plan.slice_lines == 0 {
                // Nothing streamed: each event as the bag has it, at its
                // log time.
                if let Some((_, _, channel, data)) = made.into_iter().next() {
                    return Ok(Some(self.event(log_time, channel, data)));
                }
                continue;
            }
            for (utime, rank, channel, data) in made {
                self.newest = self.newest.max(utime);
                self.sequence += 1;
                self.held.push(std::cmp::Reverse(Held {
                    utime,
                    rank,
                    sequence: self.sequence,
                    channel,
                    data,
                }));
            }
        }
    }

    fn stats(&self) -> &LogStats {
        &self.stats
    }

    fn position(&self) -> u64 {
        self.messages.position()
    }
}
