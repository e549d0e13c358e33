//! `arcnav export LOG --bag OUT.mcap`: an LCM log as a ROS 2 bag (rosbag2's
//! MCAP storage: profile `ros2`, `ros2msg` schemas, CDR messages) of
//! standard messages only, so that RViz (through `ros2 bag play`),
//! Foxglove and every ROS 2 tool show it with no arcnav type, and `arcnav
//! replay` reads it back.
//!
//! | LCM channel | topic | type |
//! |---|---|---|
//! | POSE | `/odom`: pose in `odom`, velocity in `base_link` | `nav_msgs/msg/Odometry` |
//! | POSE | `/tf`: `odom` → `base_link` | `tf2_msgs/msg/TFMessage` |
//! | RANGE_IMAGE | `/points` (`/points_<sensor>` from `RANGE_IMAGE_<SENSOR>`): an organized cloud, a row per beam row, a column per column, x, y, z and range (float32) in the sensor's frame (its name), NaN where there is no return | `sensor_msgs/msg/PointCloud2` |
//! | (each sensor's mount) | `/tf_static`: `base_link` → sensor, every mount so far, when a sensor first appears (offered transient-local, as tf2's static broadcaster does) | `tf2_msgs/msg/TFMessage` |
//! | STEERING_COMMAND | `/cmd`: steering angle atan(wheelbase · curvature), signed speed | `ackermann_msgs/msg/AckermannDriveStamped` |
//! | STEERING_COMMAND | `/arcs`: a line strip per arc in `base_link`, coloured by the cycle's fused vote, the commanded one wider | `visualization_msgs/msg/MarkerArray` |
//! | OBSTACLE_CELLS | `/obstacle_cells`: a cube per cell at its highest point, in `odom`, obstacles red, graded ground purple | `visualization_msgs/msg/MarkerArray` |
//! | LOCAL_MAP (or rebuilt) | `/local_map`: a cube per patch at its highest point, in `odom` | `visualization_msgs/msg/MarkerArray` |
//! | WAYPOINTS | `/waypoints`: a sphere per waypoint, its arrival radius | `visualization_msgs/msg/MarkerArray` |
//!
//! Votes, decisions and the guard's verdicts have no standard message:
//! they are counted as skipped (`arcnav export --mcap` writes them). A
//! slice of a streamed log is a cloud of its columns (a replay of the bag
//! reads each cloud as an image).
//!
//! Messages are stamped (header) with the arcnav message's time and
//! logged at the log's event time. Every message is serialized by
//! `cdr-encoding` from the definitions of [`crate::bag::definitions`],
//! whose texts the bag carries as its schemas.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::Path;

use arcnav_bus::lcmtypes::{
    arc_votes_t, decision_t, guard_status_t, local_map_t, obstacle_cells_t, pose_t,
    steering_command_t, waypoints_t,
};
use arcnav_config::Resolved;
use arcnav_perception::RangeImage;
use arcnav_vehicle::Isometry;
use serde::Serialize;
use serde::ser::SerializeTuple as _;

use super::sink::{
    ExportError, ExportSummary, FusedArcs, PATCH_RGBA, Sink, WAYPOINT_RGBA, arc_polylines,
    cell_rgba, returns_of, vote_rgb,
};
use crate::bag::definitions;
use crate::output::Staged;

/// The world frame (REP 105's `odom`: fixed, continuous).
pub const WORLD_FRAME: &str = "odom";
/// The vehicle frame (REP 105's `base_link`: arcnav's vehicle frame).
pub const VEHICLE_FRAME: &str = "base_link";

#[derive(Serialize)]
struct Time {
    sec: i32,
    nanosec: u32,
}

impl Time {
    /// A µs time (0 before the epoch; the last second ROS's `int32`
    /// holds after 2038).
    fn of(utime: i64) -> Self {
        let utime = utime.max(0);
        Self {
            sec: i32::try_from(utime / 1_000_000).unwrap_or(i32::MAX),
            nanosec: u32::try_from(utime % 1_000_000 * 1000).unwrap_or(0),
        }
    }
}

#[derive(Serialize)]
struct Header<'a> {
    stamp: Time,
    frame_id: &'a str,
}

impl<'a> Header<'a> {
    fn new(utime: i64, frame_id: &'a str) -> Self {
        Self {
            stamp: Time::of(utime),
            frame_id,
        }
    }
}

#[derive(Serialize, Clone, Copy)]
struct Xyz {
    x: f64,
    y: f64,
    z: f64,
}

impl Xyz {
    fn of([x, y, z]: [f64; 3]) -> Self {
        Self { x, y, z }
    }
}

#[derive(Serialize, Clone, Copy)]
struct Quaternion {
    x: f64,
    y: f64,
    z: f64,
    w: f64,
}

impl Quaternion {
    /// From arcnav's (w, x, y, z).
    fn of([w, x, y, z]: [f64; 4]) -> Self {
        Self { x, y, z, w }
    }

    const IDENTITY: Self = Self {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        w: 1.0,
    };
}

#[derive(Serialize, Clone, Copy)]
struct Pose {
    position: Xyz,
    orientation: Quaternion,
}

#[derive(Serialize)]
struct Transform {
    translation: Xyz,
    rotation: Quaternion,
}

#[derive(Serialize)]
struct TransformStamped<'a> {
    header: Header<'a>,
    child_frame_id: &'a str,
    transform: Transform,
}

#[derive(Serialize)]
struct TfMessage<'a> {
    transforms: Vec<TransformStamped<'a>>,
}

/// A 6 × 6 covariance (a fixed array: no length on the wire), unknown: 0.
struct Covariance;

impl Serialize for Covariance {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        let mut tuple = serializer.serialize_tuple(36)?;
        for _ in 0..36 {
            tuple.serialize_element(&0.0f64)?;
        }
        tuple.end()
    }
}

#[derive(Serialize)]
struct PoseWithCovariance {
    pose: Pose,
    covariance: Covariance,
}

#[derive(Serialize)]
struct Twist {
    linear: Xyz,
    angular: Xyz,
}

#[derive(Serialize)]
struct TwistWithCovariance {
    twist: Twist,
    covariance: Covariance,
}

#[derive(Serialize)]
struct Odometry<'a> {
    header: Header<'a>,
    child_frame_id: &'a str,
    pose: PoseWithCovariance,
    twist: TwistWithCovariance,
}

#[derive(Serialize)]
struct PointField<'a> {
    name: &'a str,
    offset: u32,
    datatype: u8,
    count: u32,
}

#[derive(Serialize)]
struct PointCloud2<'a> {
    header: Header<'a>,
    height: u32,
    width: u32,
    fields: Vec<PointField<'a>>,
    is_bigendian: bool,
    point_step: u32,
    row_step: u32,
    #[serde(with = "serde_bytes")]
    data: &'a [u8],
    is_dense: bool,
}

#[derive(Serialize)]
struct AckermannDrive {
    steering_angle: f32,
    steering_angle_velocity: f32,
    speed: f32,
    acceleration: f32,
    jerk: f32,
}

#[derive(Serialize)]
struct AckermannDriveStamped<'a> {
    header: Header<'a>,
    drive: AckermannDrive,
}

#[derive(Serialize, Clone, Copy)]
struct ColorRgba {
    r: f32,
    g: f32,
    b: f32,
    a: f32,
}

impl ColorRgba {
    fn of([r, g, b, a]: [f64; 4]) -> Self {
        Self {
            r: r as f32,
            g: g as f32,
            b: b as f32,
            a: a as f32,
        }
    }
}

#[derive(Serialize)]
struct CompressedImage<'a> {
    header: Header<'a>,
    format: &'a str,
    #[serde(with = "serde_bytes")]
    data: &'a [u8],
}

#[derive(Serialize)]
struct UvCoordinate {
    u: f32,
    v: f32,
}

#[derive(Serialize)]
struct MeshFile<'a> {
    filename: &'a str,
    #[serde(with = "serde_bytes")]
    data: &'a [u8],
}

/// `visualization_msgs/Marker` (Jazzy's): the fields a marker of cubes,
/// spheres or lines uses; texture and mesh empty.
#[derive(Serialize)]
struct Marker<'a> {
    header: Header<'a>,
    ns: &'a str,
    id: i32,
    #[serde(rename = "type")]
    kind: i32,
    action: i32,
    pose: Pose,
    scale: Xyz,
    color: ColorRgba,
    lifetime: Time,
    frame_locked: bool,
    points: Vec<Xyz>,
    colors: Vec<ColorRgba>,
    texture_resource: &'a str,
    texture: CompressedImage<'a>,
    uv_coordinates: Vec<UvCoordinate>,
    text: &'a str,
    mesh_resource: &'a str,
    mesh_file: MeshFile<'a>,
    mesh_use_embedded_materials: bool,
}

/// Marker types and the one action used.
const SPHERE: i32 = 2;
const LINE_STRIP: i32 = 4;
const CUBE_LIST: i32 = 6;
const ADD: i32 = 0;

impl<'a> Marker<'a> {
    /// A marker `ns`/`id` of `kind` in `frame` at `utime`, at the frame's
    /// origin, forever (until replaced by the next of its `ns` and `id`).
    fn new(utime: i64, frame: &'a str, ns: &'a str, id: i32, kind: i32) -> Self {
        Self {
            header: Header::new(utime, frame),
            ns,
            id,
            kind,
            action: ADD,
            pose: Pose {
                position: Xyz::of([0.0; 3]),
                orientation: Quaternion::IDENTITY,
            },
            scale: Xyz::of([1.0; 3]),
            color: ColorRgba::of([1.0; 4]),
            lifetime: Time { sec: 0, nanosec: 0 },
            frame_locked: false,
            points: Vec::new(),
            colors: Vec::new(),
            texture_resource: "",
            texture: CompressedImage {
                header: Header::new(utime, frame),
                format: "",
                data: &[],
            },
            uv_coordinates: Vec::new(),
            text: "",
            mesh_resource: "",
            mesh_file: MeshFile {
                filename: "",
                data: &[],
            },
            mesh_use_embedded_materials: false,
        }
    }
}

#[derive(Serialize)]
struct MarkerArray<'a> {
    markers: Vec<Marker<'a>>,
}

/// The ROS 2 type of each message written, by the name of its definition.
const TYPES: &[(&str, &str)] = &[
    ("Odometry", "nav_msgs/msg/Odometry"),
    ("TFMessage", "tf2_msgs/msg/TFMessage"),
    ("PointCloud2", "sensor_msgs/msg/PointCloud2"),
    (
        "AckermannDriveStamped",
        "ackermann_msgs/msg/AckermannDriveStamped",
    ),
    ("MarkerArray", "visualization_msgs/msg/MarkerArray"),
];

/// `/tf_static`'s offered QoS as rosbag2 records it (keep last 1,
/// reliable, transient local, no deadline, lifespan or lease): played
/// back, a late subscriber still gets the mounts.
const STATIC_QOS: &str = "- history: 1\n  depth: 1\n  reliability: 1\n  durability: 1\n  \
deadline:\n    sec: 2147483647\n    nsec: 4294967295\n  lifespan:\n    sec: 2147483647\n    \
nsec: 4294967295\n  liveliness: 1\n  liveliness_lease_duration:\n    sec: 2147483647\n    \
nsec: 4294967295\n  avoid_ros_namespace_conventions: false";

/// A ROS 2 bag being written: its channels as their topics first appear,
/// each sensor's mount, the wheelbase the steering angle needs.
pub struct Ros2Bag {
    writer: mcap::Writer<BufWriter<std::fs::File>>,
    staged: Staged,
    out: String,
    /// Schema ids by definition name; channel ids and next sequence by topic.
    schemas: BTreeMap<&'static str, u16>,
    channels: BTreeMap<String, (u16, u32)>,
    /// Each sensor's frame and mount, in order of appearance.
    mounts: Vec<(String, Isometry)>,
    wheelbase_m: f64,
    /// The first error writing, said at the end.
    failed: Option<String>,
}

impl Ros2Bag {
    /// Starts a bag for `out`, written beside it and put in its place by
    /// [`finish`](Self::finish) (any file there stays as it was until then).
    pub fn create(out: &Path, config: &Resolved) -> Result<Self, ExportError> {
        let write_error = |reason: String| ExportError::Write {
            path: out.display().to_string(),
            reason,
        };
        let (staged, file) = Staged::create(out).map_err(|e| write_error(e.to_string()))?;
        let options = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("arcnav ", env!("CARGO_PKG_VERSION")));
        let writer = options
            .create(BufWriter::new(file))
            .map_err(|e| write_error(e.to_string()))?;
        Ok(Self {
            writer,
            staged,
            out: out.display().to_string(),
            schemas: BTreeMap::new(),
            channels: BTreeMap::new(),
            mounts: Vec::new(),
            wheelbase_m: config.vehicle.wheelbase_m,
            failed: None,
        })
    }

    /// Closes the bag and puts it in place; an error met while writing
    /// any message fails it (nothing is put in place).
    pub fn finish(mut self) -> Result<(), ExportError> {
        let write_error = |reason: String| ExportError::Write {
            path: self.out.clone(),
            reason,
        };
        if let Some(reason) = self.failed.take() {
            return Err(write_error(reason));
        }
        self.writer
            .finish()
            .map_err(|e| write_error(e.to_string()))?;
        let file = self
            .writer
            .into_inner()
            .into_inner()
            .map_err(|e| write_error(e.error().to_string()))?;
        self.staged
            .commit(file)
            .map_err(|e| write_error(e.to_string()))
    }

    /// Writes `msg` (of the definition `name`) on `topic` at `time`,
    /// counted in `summary`; a failure is kept for [`finish`](Self::finish).
    fn write(
        &mut self,
        topic: &str,
        name: &'static str,
        msg: &impl Serialize,
        time: u64,
        summary: &mut ExportSummary,
    ) {
        if self.failed.is_some() {
            return;
        }
        match self.try_write(topic, name, msg, time) {
            Ok(()) => summary.wrote(topic),
            Err(e) => self.failed = Some(format!("{topic}: {e}")),
        }
    }

    fn try_write(
        &mut self,
        topic: &str,
        name: &'static str,
        msg: &impl Serialize,
        time: u64,
    ) -> Result<(), String> {
        let (channel_id, sequence) = match self.channels.get_mut(topic) {
            Some((id, sequence)) => {
                *sequence += 1;
                (*id, *sequence)
            }
            None => {
                let id = self.channel(topic, name)?;
                self.channels.insert(topic.to_owned(), (id, 0));
                (id, 0)
            }
        };
        // CDR, little-endian, after its encapsulation header.
        let mut data = vec![0x00, 0x01, 0x00, 0x00];
        cdr_encoding::to_writer::<_, byteorder::LittleEndian, _>(&mut data, msg)
            .map_err(|e| e.to_string())?;
        self.writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id,
                    sequence,
                    log_time: time,
                    publish_time: time,
                },
                &data,
            )
            .map_err(|e| e.to_string())
    }

    /// A channel for `topic` of the definition `name`, with its schema.
    fn channel(&mut self, topic: &str, name: &'static str) -> Result<u16, String> {
        let schema = match self.schemas.get(name) {
            Some(&id) => id,
            None => {
                let ros_type = TYPES
                    .iter()
                    .find(|(n, _)| *n == name)
                    .map(|(_, t)| *t)
                    .ok_or_else(|| format!("no ROS 2 type for {name}"))?;
                let text =
                    definitions::ros2msg(name).ok_or_else(|| format!("no definition of {name}"))?;
                let id = self
                    .writer
                    .add_schema(ros_type, "ros2msg", text.as_bytes())
                    .map_err(|e| e.to_string())?;
                self.schemas.insert(name, id);
                id
            }
        };
        let mut metadata = BTreeMap::new();
        if topic == "/tf_static" {
            metadata.insert("offered_qos_profiles".to_owned(), STATIC_QOS.to_owned());
        }
        self.writer
            .add_channel(schema, topic, "cdr", &metadata)
            .map_err(|e| e.to_string())
    }

    /// `/tf_static` with every mount so far, when `frame`'s is new or moved.
    fn mount(&mut self, frame: &str, image: &RangeImage, time: u64, summary: &mut ExportSummary) {
        let mount = image.vehicle_from_sensor;
        match self.mounts.iter_mut().find(|(f, _)| f == frame) {
            Some((_, known)) if *known == mount => return,
            Some((_, known)) => *known = mount,
            None => self.mounts.push((frame.to_owned(), mount)),
        }
        let mounts = self.mounts.clone();
        let transforms = mounts
            .iter()
            .map(|(child, m)| {
                let q = m.rotation.quaternion();
                TransformStamped {
                    header: Header::new(image.utime, VEHICLE_FRAME),
                    child_frame_id: child,
                    transform: Transform {
                        translation: Xyz::of(m.translation.vector.into()),
                        rotation: Quaternion {
                            x: q.i,
                            y: q.j,
                            z: q.k,
                            w: q.w,
                        },
                    },
                }
            })
            .collect();
        let msg = TfMessage { transforms };
        self.write("/tf_static", "TFMessage", &msg, time, summary);
    }
}

/// A sensor's frame: its name, lower-cased, characters ROS names do not
/// take as `_` (`sensor` when it has none).
fn frame_of(sensor: &str) -> String {
    let frame: String = sensor
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() {
                c.to_ascii_lowercase()
            } else {
                '_'
            }
        })
        .collect();
    if frame.is_empty() || frame.starts_with(|c: char| c.is_ascii_digit()) {
        format!("sensor{frame}")
    } else {
        frame
    }
}

/// The cloud topic of a range-image channel: `/points`, or
/// `/points_<sensor>` for `RANGE_IMAGE_<SENSOR>`.
fn cloud_topic(channel: &str) -> String {
    let suffix = channel
        .strip_prefix(arcnav_bus::messages::channels::RANGE_IMAGE)
        .unwrap_or(channel)
        .trim_start_matches('_');
    if suffix.is_empty() {
        "/points".to_owned()
    } else {
        format!("/points_{}", frame_of(suffix))
    }
}

/// An organized cloud of `image`: x, y, z and range (float32, little-endian)
/// per pixel in the sensor frame, NaN where there is no return.
fn organized(image: &RangeImage, data: &mut Vec<u8>) -> Option<(u32, u32)> {
    const STEP: usize = 16;
    let (rows, cols) = (image.rows(), image.cols());
    data.clear();
    data.resize(rows * cols * STEP, 0);
    for pixel in data.chunks_exact_mut(4) {
        pixel.copy_from_slice(&f32::NAN.to_le_bytes());
    }
    for (row, col, r, [x, y, z]) in returns_of(image) {
        let at = (row * cols + col) * STEP;
        for (k, v) in [x as f32, y as f32, z as f32, r].into_iter().enumerate() {
            data[at + 4 * k..at + 4 * k + 4].copy_from_slice(&v.to_le_bytes());
        }
    }
    Some((u32::try_from(rows).ok()?, u32::try_from(cols).ok()?))
}

impl Sink for Ros2Bag {
    fn pose(&mut self, msg: &pose_t, time: u64, summary: &mut ExportSummary) {
        let pose = Pose {
            position: Xyz::of(msg.position),
            orientation: Quaternion::of(msg.orientation),
        };
        // The velocity in the vehicle frame: the world's rotated back.
        let [w, x, y, z] = msg.orientation;
        let to_vehicle =
            nalgebra::UnitQuaternion::from_quaternion(nalgebra::Quaternion::new(w, x, y, z))
                .inverse();
        let v = to_vehicle * nalgebra::Vector3::from(msg.velocity);
        let odometry = Odometry {
            header: Header::new(msg.utime, WORLD_FRAME),
            child_frame_id: VEHICLE_FRAME,
            pose: PoseWithCovariance {
                pose,
                covariance: Covariance,
            },
            twist: TwistWithCovariance {
                twist: Twist {
                    linear: Xyz::of(v.into()),
                    angular: Xyz::of([0.0, 0.0, msg.yaw_rate]),
                },
                covariance: Covariance,
            },
        };
        self.write("/odom", "Odometry", &odometry, time, summary);
        let tf = TfMessage {
            transforms: vec![TransformStamped {
                header: Header::new(msg.utime, WORLD_FRAME),
                child_frame_id: VEHICLE_FRAME,
                transform: Transform {
                    translation: pose.position,
                    rotation: pose.orientation,
                },
            }],
        };
        self.write("/tf", "TFMessage", &tf, time, summary);
    }

    fn image(&mut self, channel: &str, image: &RangeImage, time: u64, summary: &mut ExportSummary) {
        let frame = frame_of(&image.sensor);
        self.mount(&frame, image, time, summary);
        let mut data = Vec::new();
        let Some((height, width)) = organized(image, &mut data) else {
            summary.skip(channel, "an image too large for a PointCloud2");
            return;
        };
        let field = |name, offset| PointField {
            name,
            offset,
            datatype: 7, // FLOAT32
            count: 1,
        };
        let cloud = PointCloud2 {
            header: Header::new(image.utime, &frame),
            height,
            width,
            fields: vec![
                field("x", 0),
                field("y", 4),
                field("z", 8),
                field("range", 12),
            ],
            is_bigendian: false,
            point_step: 16,
            row_step: 16 * width,
            data: &data,
            is_dense: false,
        };
        self.write(&cloud_topic(channel), "PointCloud2", &cloud, time, summary);
    }

    fn obstacle_cells(&mut self, msg: &obstacle_cells_t, time: u64, summary: &mut ExportSummary) {
        let ns = format!("obstacle_cells/{}", msg.sensor);
        let mut marker = Marker::new(msg.utime, WORLD_FRAME, &ns, 0, CUBE_LIST);
        let size = f64::from(msg.cell_size);
        marker.scale = Xyz::of([size, size, 0.1]);
        (marker.points, marker.colors) = msg
            .cells
            .iter()
            .map(|c| {
                let top = Xyz::of([c.x, c.y, f64::from(c.z_max) - 0.05]);
                (top, ColorRgba::of(cell_rgba(c.cost)))
            })
            .unzip();
        let markers = MarkerArray {
            markers: vec![marker],
        };
        self.write("/obstacle_cells", "MarkerArray", &markers, time, summary);
    }

    fn local_map(&mut self, map: &local_map_t, time: u64, summary: &mut ExportSummary) {
        let mut marker = Marker::new(map.utime, WORLD_FRAME, "local_map", 0, CUBE_LIST);
        let size = f64::from(map.patch_size);
        marker.scale = Xyz::of([size, size, 0.1]);
        marker.color = ColorRgba::of(PATCH_RGBA);
        marker.points = map
            .patches
            .iter()
            .map(|p| Xyz::of([p.world_x, p.world_y, f64::from(p.z_max) - 0.05]))
            .collect();
        let markers = MarkerArray {
            markers: vec![marker],
        };
        self.write("/local_map", "MarkerArray", &markers, time, summary);
    }

    fn waypoints(&mut self, msg: &waypoints_t, time: u64, summary: &mut ExportSummary) {
        let markers = msg
            .position
            .iter()
            .zip(&msg.radius)
            .zip(0..)
            .map(|((p, &r), id)| {
                let mut marker = Marker::new(msg.utime, WORLD_FRAME, "waypoints", id, SPHERE);
                let d = 2.0 * f64::from(r).max(1.0);
                marker.pose.position = Xyz::of([p[0], p[1], 0.0]);
                marker.scale = Xyz::of([d, d, 0.5]);
                marker.color = ColorRgba::of(WAYPOINT_RGBA);
                marker
            })
            .collect();
        let markers = MarkerArray { markers };
        self.write("/waypoints", "MarkerArray", &markers, time, summary);
    }

    fn votes(&mut self, channel: &str, _: &arc_votes_t, _: u64, summary: &mut ExportSummary) {
        summary.skip(channel, NO_STANDARD_MESSAGE);
    }

    fn decision(&mut self, _: &decision_t, _: u64, summary: &mut ExportSummary) {
        summary.skip(
            arcnav_bus::messages::channels::DECISION,
            NO_STANDARD_MESSAGE,
        );
    }

    fn guard(&mut self, _: &guard_status_t, _: u64, summary: &mut ExportSummary) {
        summary.skip(
            arcnav_bus::messages::channels::GUARD_STATUS,
            NO_STANDARD_MESSAGE,
        );
    }

    fn command(
        &mut self,
        msg: &steering_command_t,
        arcs: Option<FusedArcs<'_>>,
        time: u64,
        summary: &mut ExportSummary,
    ) {
        let drive = AckermannDriveStamped {
            header: Header::new(msg.utime, VEHICLE_FRAME),
            drive: AckermannDrive {
                steering_angle: (self.wheelbase_m * msg.curvature).atan() as f32,
                steering_angle_velocity: 0.0,
                speed: msg.speed as f32,
                acceleration: 0.0,
                jerk: 0.0,
            },
        };
        self.write("/cmd", "AckermannDriveStamped", &drive, time, summary);
        let Some(FusedArcs { arcs, fused }) = arcs else {
            return;
        };
        let chosen = usize::try_from(msg.arc_index).ok();
        let markers = arc_polylines(arcs)
            .into_iter()
            .zip(0..)
            .map(|(line, id)| {
                let mut marker = Marker::new(msg.utime, VEHICLE_FRAME, "arcs", id, LINE_STRIP);
                let i = usize::try_from(id).unwrap_or(usize::MAX);
                let width = if Some(i) == chosen { 0.12 } else { 0.04 };
                marker.scale = Xyz::of([width, 0.0, 0.0]);
                marker.color = ColorRgba::of(fused.get(i).map_or([0.6, 0.6, 0.6, 0.6], |&v| {
                    let [r, g, b] = vote_rgb(v);
                    [r, g, b, 1.0]
                }));
                marker.points = line.into_iter().map(Xyz::of).collect();
                marker
            })
            .collect();
        let markers = MarkerArray { markers };
        self.write("/arcs", "MarkerArray", &markers, time, summary);
    }
}

const NO_STANDARD_MESSAGE: &str =
    "no standard ROS 2 message holds it (arcnav export --mcap writes it as JSON)";

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sensors_are_frames_and_topics_ros_accepts() {
        assert_eq!(frame_of("erim"), "erim");
        assert_eq!(frame_of("Rear Depth-1"), "rear_depth_1");
        assert_eq!(frame_of("64beam"), "sensor64beam");
        assert_eq!(frame_of(""), "sensor");
        assert_eq!(cloud_topic("RANGE_IMAGE"), "/points");
        assert_eq!(cloud_topic("RANGE_IMAGE_REAR"), "/points_rear");
    }

    /// Two sensors: a cloud topic and a frame each, both mounts latched
    /// on /tf_static (again only when a mount is new); the replay's reader
    /// finds either sensor's mount from the bag.
    #[test]
    fn each_sensor_is_a_cloud_topic_in_its_own_frame_with_its_mount_latched() {
        use arcnav_perception::{BeamTable, SensorModel};
        let dir = arcnav_testkit::temp_dir("export-two-sensors");
        let out = dir.join("two.mcap");
        let mut bag = Ros2Bag::create(&out, &Resolved::default()).unwrap();
        let mut summary = ExportSummary::default();
        let image = |sensor: &str, x: f64| RangeImage {
            utime: 1_000_000,
            sensor: sensor.into(),
            vehicle_from_sensor: arcnav_vehicle::frames::isometry_from_xyz_rpy(
                [x, 0.0, 1.5],
                0.0,
                0.0,
                0.0,
            ),
            beams: BeamTable::uniform(4, 8, 0.1, -0.3, 1.0, -1.0),
            range: vec![10.0; 32],
        };
        let pose = pose_t {
            utime: 1_000_000,
            position: [0.0; 3],
            orientation: [1.0, 0.0, 0.0, 0.0],
            velocity: [0.0; 3],
            yaw_rate: 0.0,
        };
        bag.pose(&pose, 1_000, &mut summary);
        bag.image(
            "RANGE_IMAGE_FRONT",
            &image("front", 1.0),
            2_000,
            &mut summary,
        );
        bag.image(
            "RANGE_IMAGE_REAR",
            &image("rear", -1.0),
            3_000,
            &mut summary,
        );
        bag.image(
            "RANGE_IMAGE_FRONT",
            &image("front", 1.0),
            4_000,
            &mut summary,
        );
        bag.finish().unwrap();
        assert_eq!(summary.topics["/points_front"], 2);
        assert_eq!(summary.topics["/points_rear"], 1);
        assert_eq!(summary.topics["/tf_static"], 2);

        let read = crate::bag::Bag::open(&out).unwrap();
        for (topic, frame) in [("/points_front", "front"), ("/points_rear", "rear")] {
            let options = crate::bag::BagOptions {
                cloud: Some(topic.into()),
                ..Default::default()
            };
            let plan = read.plan(&options, &SensorModel::erim()).unwrap();
            let events = read.events(&plan).unwrap();
            assert_eq!(
                events.summary().mount_from,
                format!("/tf_static: base_link ← {frame}")
            );
        }
        // Without --cloud, the two are named.
        let err = read
            .plan(&Default::default(), &SensorModel::erim())
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("/points_front, /points_rear"), "{err}");
        let _ = std::fs::remove_dir_all(dir);
    }

    #[test]
    fn stamps_hold_what_ros_time_holds() {
        let t = Time::of(1_767_225_600_123_456);
        assert_eq!((t.sec, t.nanosec), (1_767_225_600, 123_456_000));
        let before = Time::of(-5);
        assert_eq!((before.sec, before.nanosec), (0, 0));
        // Past 2038 (int32 seconds): the last second it holds.
        assert_eq!(Time::of(i64::MAX).sec, i32::MAX);
    }

    #[test]
    fn a_message_is_cdr_after_its_encapsulation_header() {
        let msg = Header::new(2_500_000, "odom");
        let mut data = vec![0x00, 0x01, 0x00, 0x00];
        cdr_encoding::to_writer::<_, byteorder::LittleEndian, _>(&mut data, &msg).unwrap();
        // sec 2, nanosec 5e8, then the string: length with its NUL, bytes.
        let mut expected = vec![0, 1, 0, 0, 2, 0, 0, 0];
        expected.extend(500_000_000u32.to_le_bytes());
        expected.extend(5u32.to_le_bytes());
        expected.extend(b"odom\0");
        assert_eq!(data, expected);
    }
}
