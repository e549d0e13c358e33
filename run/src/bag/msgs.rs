//! The ROS messages a replay reads from a bag, decoded from their wire
//! bytes (ROS 2's CDR, by `cdr-encoding`; ROS 1's, by
//! `roslibrust_serde_rosmsg`) after their type has been checked against
//! the fields decoded here: a message whose schema says otherwise (ROS 2:
//! [`Schema::check`]) or whose type's md5sum is not ROS 1's
//! ([`Kind::ros1_md5sum`]) is never decoded.
//!
//! Every field is read (ROS 1's decoder holds a message to its length),
//! but only what a replay uses is kept.

use std::borrow::Cow;

use arcnav_vehicle::{Isometry, Utime};
use nalgebra::{Quaternion, Translation3, UnitQuaternion, Vector3};
use serde::Deserialize;

/// The message types a replay reads, by the short name of their ROS type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Kind {
    /// `sensor_msgs/PointCloud2`
    Cloud,
    /// `nav_msgs/Odometry`
    Odometry,
    /// `geometry_msgs/PoseStamped`
    PoseStamped,
    /// `geometry_msgs/PoseWithCovarianceStamped`
    PoseWithCovariance,
    /// `tf2_msgs/TFMessage`
    Transforms,
}

impl Kind {
    /// The kind of a ROS type name (`sensor_msgs/msg/PointCloud2` or
    /// `sensor_msgs/PointCloud2`), if a replay reads it.
    pub fn of(type_name: &str) -> Option<Self> {
        let (package, name) = type_name.split_once('/')?;
        let name = name.strip_prefix("msg/").unwrap_or(name);
        Some(match (package, name) {
            ("sensor_msgs", "PointCloud2") => Self::Cloud,
            ("nav_msgs", "Odometry") => Self::Odometry,
            ("geometry_msgs", "PoseStamped") => Self::PoseStamped,
            ("geometry_msgs", "PoseWithCovarianceStamped") => Self::PoseWithCovariance,
            ("tf2_msgs", "TFMessage") => Self::Transforms,
            _ => return None,
        })
    }

    /// Whether messages of this kind give the vehicle's pose.
    pub fn is_pose(self) -> bool {
        matches!(
            self,
            Self::Odometry | Self::PoseStamped | Self::PoseWithCovariance
        )
    }

    /// The md5sum ROS 1 gives the type (`rosmsg md5`): a bag's connection
    /// whose type has another is not decoded.
    pub fn ros1_md5sum(self) -> &'static str {
        match self {
            Self::Cloud => "1158d486dd51d683ce2f1be655c3c181",
            Self::Odometry => "cd5e73d190d741a2f92e81eda573aca7",
            Self::PoseStamped => "d3812c3cbc69362b77dc0b19b345f8f5",
            Self::PoseWithCovariance => "953b798c0f514ff060a53a3498ce6246",
            Self::Transforms => "94810edda583a504dfda3829e70d7eec",
        }
    }

    fn top(self) -> &'static str {
        match self {
            Self::Cloud => "PointCloud2",
            Self::Odometry => "Odometry",
            Self::PoseStamped => "PoseStamped",
            Self::PoseWithCovariance => "PoseWithCovarianceStamped",
            Self::Transforms => "TFMessage",
        }
    }
}

/// A message definition as a bag carries it (ROS 2's `ros2msg` text: the
/// type's fields, then each type it uses after a line of `=` and
/// `MSG: package/Type`).
pub struct Schema<'a>(pub &'a str);

/// Why a schema is not the one decoded here.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{type_name}'s field {} is {}, not {}", .at + 1, or_none(found.get(*at)), or_none(expected.get(*at)))]
pub struct SchemaMismatch {
    pub type_name: String,
    pub found: Vec<String>,
    pub expected: Vec<String>,
    /// The first field that differs (or is missing on either side).
    pub at: usize,
}

fn or_none(field: Option<&String>) -> String {
    field.map_or_else(|| "missing".to_owned(), |f| format!("`{f}`"))
}

impl Schema<'_> {
    /// Checks the top-level type's fields, and those of every type the
    /// text defines, against their ROS 2 definitions
    /// ([`super::definitions`]).
    pub fn check(&self, kind: Kind) -> Result<(), SchemaMismatch> {
        self.check_in(kind, Encoding::Cdr)
    }

    /// [`check`](Self::check) for a definition of ROS 1's (`ros1msg`, as
    /// an MCAP file converted from a ROS 1 bag carries it): its header has
    /// a sequence number and a `time` of its own; every other type is
    /// ROS 2's.
    pub fn check_ros1(&self, kind: Kind) -> Result<(), SchemaMismatch> {
        self.check_in(kind, Encoding::Ros1)
    }

    fn check_in(&self, kind: Kind, encoding: Encoding) -> Result<(), SchemaMismatch> {
        const ROS1_HEADER: (&str, &[&str]) =
            ("Header", &["uint32 seq", "time stamp", "string frame_id"]);
        let mut sections = vec![(kind.top().to_string(), Vec::new())];
        for line in self.0.lines() {
            let line = line.split('#').next().unwrap_or("").trim();
            if line.is_empty() {
                continue;
            }
            if line.starts_with("===") {
                continue;
            }
            if let Some(type_name) = line.strip_prefix("MSG:") {
                sections.push((short(type_name.trim()).to_string(), Vec::new()));
                continue;
            }
            let mut words = line.split_whitespace();
            let (Some(field_type), Some(name)) = (words.next(), words.next()) else {
                continue;
            };
            // A constant (`uint8 INT8 = 1`, `uint8 INT8=1`) is no field.
            if name.contains('=') || words.next().is_some_and(|w| w.starts_with('=')) {
                continue;
            }
            if let Some((_, fields)) = sections.last_mut() {
                fields.push(format!("{} {name}", short(field_type)));
            }
        }
        for (type_name, found) in &sections {
            let expected = match encoding {
                Encoding::Ros1 if type_name == ROS1_HEADER.0 => Some(ROS1_HEADER),
                _ => super::definitions::named(type_name).map(|d| (d.name, d.fields)),
            };
            let Some((_, expected)) = expected else {
                continue;
            };
            if found
                .iter()
                .map(String::as_str)
                .ne(expected.iter().copied())
            {
                let at = found
                    .iter()
                    .zip(expected.iter())
                    .position(|(f, e)| f != e)
                    .unwrap_or(found.len().min(expected.len()));
                return Err(SchemaMismatch {
                    type_name: type_name.clone(),
                    found: found.clone(),
                    expected: expected.iter().map(|s| s.to_string()).collect(),
                    at,
                });
            }
        }
        Ok(())
    }
}

/// A type without its package (`std_msgs/Header`, `std_msgs/msg/Header`:
/// `Header`); an array keeps its brackets.
fn short(type_name: &str) -> &str {
    type_name.rsplit('/').next().unwrap_or(type_name)
}

/// A message that did not decode.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    #[error("{0} bytes: too short for the CDR encapsulation header")]
    Short(usize),
    #[error("CDR representation {0:#06x} is not plain CDR (0x0000 or 0x0001)")]
    Representation(u16),
    #[error("{0}")]
    Cdr(String),
    #[error("{0}")]
    Ros1(String),
    #[error("a stamp {0} s after 1970: past what a ROS 2 time holds (2038)")]
    Stamp(u32),
}

/// How a message's bytes are encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Encoding {
    /// ROS 2: CDR with its encapsulation header.
    Cdr,
    /// ROS 1: little-endian, unpadded, lengths before strings and arrays.
    Ros1,
}

/// A message type decoded here, from either encoding.
pub trait Message<'a>: Sized + Deserialize<'a> {
    /// From ROS 1's bytes: its own type with ROS 1's header, made this one.
    fn from_ros1(data: &'a [u8]) -> Result<Self, DecodeError>;

    fn decode(encoding: Encoding, data: &'a [u8]) -> Result<Self, DecodeError> {
        match encoding {
            Encoding::Cdr => from_cdr(data),
            Encoding::Ros1 => Self::from_ros1(data),
        }
    }
}

/// Decodes ROS 1's bytes of a message (a bag's message data: no length
/// before it). Every length inside is checked against the message's own
/// before anything is allocated for it.
fn from_ros1<T: serde::de::DeserializeOwned>(data: &[u8]) -> Result<T, DecodeError> {
    let length = u32::try_from(data.len())
        .map_err(|_| DecodeError::Ros1(format!("{} bytes: past 4 GiB", data.len())))?;
    roslibrust_serde_rosmsg::from_slice_known_length(data, length)
        .map_err(|e| DecodeError::Ros1(e.to_string()))
}

/// ROS 1's time: unsigned seconds.
#[derive(Debug, Clone, Copy, Deserialize)]
struct Ros1Time {
    secs: u32,
    nsecs: u32,
}

/// ROS 1's header: a sequence number first.
#[derive(Debug, Clone, Deserialize)]
pub struct Ros1Header {
    _seq: u32,
    stamp: Ros1Time,
    frame_id: String,
}

impl TryFrom<Ros1Header> for Header {
    type Error = DecodeError;

    fn try_from(h: Ros1Header) -> Result<Self, DecodeError> {
        Ok(Header {
            stamp: Time {
                sec: i32::try_from(h.stamp.secs).map_err(|_| DecodeError::Stamp(h.stamp.secs))?,
                nanosec: h.stamp.nsecs,
            },
            frame_id: h.frame_id,
        })
    }
}

/// ROS 1's cloud: its bytes read whole (not byte by byte).
#[derive(Debug, Clone, Deserialize)]
struct Ros1Cloud {
    header: Ros1Header,
    height: u32,
    width: u32,
    fields: Vec<PointField>,
    is_bigendian: bool,
    point_step: u32,
    row_step: u32,
    data: serde_bytes::ByteBuf,
    is_dense: bool,
}

impl<'a> Message<'a> for PointCloud2<'a> {
    fn from_ros1(data: &'a [u8]) -> Result<Self, DecodeError> {
        let c: Ros1Cloud = from_ros1(data)?;
        Ok(PointCloud2 {
            header: c.header.try_into()?,
            height: c.height,
            width: c.width,
            fields: c.fields,
            is_bigendian: c.is_bigendian,
            point_step: c.point_step,
            row_step: c.row_step,
            data: Cow::Owned(c.data.into_vec()),
            is_dense: c.is_dense,
        })
    }
}

impl Message<'_> for Odometry {
    fn from_ros1(data: &[u8]) -> Result<Self, DecodeError> {
        let o: Odometry<Ros1Header> = from_ros1(data)?;
        Ok(Odometry {
            header: o.header.try_into()?,
            child_frame_id: o.child_frame_id,
            pose: o.pose,
            twist: o.twist,
        })
    }
}

impl Message<'_> for PoseStamped {
    fn from_ros1(data: &[u8]) -> Result<Self, DecodeError> {
        let p: PoseStamped<Ros1Header> = from_ros1(data)?;
        Ok(PoseStamped {
            header: p.header.try_into()?,
            pose: p.pose,
        })
    }
}

impl Message<'_> for PoseWithCovarianceStamped {
    fn from_ros1(data: &[u8]) -> Result<Self, DecodeError> {
        let p: PoseWithCovarianceStamped<Ros1Header> = from_ros1(data)?;
        Ok(PoseWithCovarianceStamped {
            header: p.header.try_into()?,
            pose: p.pose,
        })
    }
}

impl Message<'_> for TfMessage {
    fn from_ros1(data: &[u8]) -> Result<Self, DecodeError> {
        let tf: TfMessage<Ros1Header> = from_ros1(data)?;
        let transforms = tf
            .transforms
            .into_iter()
            .map(|t| {
                Ok(TransformStamped {
                    header: t.header.try_into()?,
                    child_frame_id: t.child_frame_id,
                    transform: t.transform,
                })
            })
            .collect::<Result<_, DecodeError>>()?;
        Ok(TfMessage { transforms })
    }
}

/// Decodes a CDR-encoded message (its 4-byte encapsulation header first:
/// big- or little-endian plain CDR).
pub fn from_cdr<'a, T: Deserialize<'a>>(data: &'a [u8]) -> Result<T, DecodeError> {
    let (head, body) = data
        .split_at_checked(4)
        .ok_or(DecodeError::Short(data.len()))?;
    let representation = u16::from_be_bytes([head[0], head[1]]);
    let decoded = match representation {
        0x0000 => cdr_encoding::from_bytes::<T, byteorder::BigEndian>(body),
        0x0001 => cdr_encoding::from_bytes::<T, byteorder::LittleEndian>(body),
        other => return Err(DecodeError::Representation(other)),
    };
    decoded
        .map(|(value, _)| value)
        .map_err(|e| DecodeError::Cdr(e.to_string()))
}

#[derive(Debug, Clone, Copy, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// Microseconds since the epoch (rounded down).
    pub fn utime(self) -> Utime {
        i64::from(self.sec) * 1_000_000 + i64::from(self.nanosec / 1000)
    }
}

#[derive(Debug, Clone, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

#[derive(Debug, Clone, Deserialize)]
pub struct PointField {
    pub name: String,
    pub offset: u32,
    pub datatype: u8,
    pub count: u32,
}

#[derive(Debug, Clone, Deserialize)]
pub struct PointCloud2<'a> {
    pub header: Header,
    pub height: u32,
    pub width: u32,
    pub fields: Vec<PointField>,
    pub is_bigendian: bool,
    pub point_step: u32,
    pub row_step: u32,
    #[serde(borrow, with = "serde_bytes")]
    pub data: Cow<'a, [u8]>,
    pub is_dense: bool,
}

#[derive(Debug, Clone, Copy, Deserialize)]
pub struct Xyz {
    pub x: f64,
    pub y: f64,
    pub z: f64,
}

#[derive(Debug, Clone, Copy, Deserialize)]
pub struct Xyzw {
    pub x: f64,
    pub y: f64,
    pub z: f64,
    pub w: f64,
}

#[derive(Debug, Clone, Copy, Deserialize)]
pub struct RosPose {
    pub position: Xyz,
    pub orientation: Xyzw,
}

/// 36 numbers (a 6 × 6 covariance), read past.
type Covariance = [[f64; 6]; 6];

#[derive(Debug, Clone, Copy, Deserialize)]
pub struct PoseWithCovariance {
    pub pose: RosPose,
    _covariance: Covariance,
}

#[derive(Debug, Clone, Copy, Deserialize)]
pub struct Twist {
    pub linear: Xyz,
    pub angular: Xyz,
}

#[derive(Debug, Clone, Copy, Deserialize)]
pub struct TwistWithCovariance {
    pub twist: Twist,
    _covariance: Covariance,
}

#[derive(Debug, Clone, Deserialize)]
pub struct Odometry<H = Header> {
    pub header: H,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}

#[derive(Debug, Clone, Deserialize)]
pub struct PoseStamped<H = Header> {
    pub header: H,
    pub pose: RosPose,
}

#[derive(Debug, Clone, Deserialize)]
pub struct PoseWithCovarianceStamped<H = Header> {
    pub header: H,
    pub pose: PoseWithCovariance,
}

#[derive(Debug, Clone, Copy, Deserialize)]
pub struct Transform {
    pub translation: Xyz,
    pub rotation: Xyzw,
}

#[derive(Debug, Clone, Deserialize)]
pub struct TransformStamped<H = Header> {
    pub header: H,
    pub child_frame_id: String,
    pub transform: Transform,
}

#[derive(Debug, Clone, Deserialize)]
pub struct TfMessage<H = Header> {
    pub transforms: Vec<TransformStamped<H>>,
}

/// A rigid transform that is not one (a position not finite, a rotation
/// not a finite, non-zero quaternion).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("not a rigid transform: a position or rotation that is not finite, or a zero rotation")]
pub struct NotRigid;

/// `parent ← child` from a translation and a rotation (normalised; ROS
/// quaternions are x, y, z, w).
pub fn isometry(translation: Xyz, rotation: Xyzw) -> Result<Isometry, NotRigid> {
    let Xyzw { x, y, z, w } = rotation;
    let q = Quaternion::new(w, x, y, z);
    let finite = [translation.x, translation.y, translation.z, w, x, y, z]
        .iter()
        .all(|v| v.is_finite());
    if !finite || q.norm() < 1e-9 {
        return Err(NotRigid);
    }
    Ok(Isometry::from_parts(
        Translation3::new(translation.x, translation.y, translation.z),
        UnitQuaternion::from_quaternion(q),
    ))
}

impl RosPose {
    pub fn isometry(&self) -> Result<Isometry, NotRigid> {
        isometry(self.position, self.orientation)
    }
}

impl Xyz {
    pub fn vector(self) -> Vector3<f64> {
        Vector3::new(self.x, self.y, self.z)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const CLOUD: &str = "std_msgs/Header header\nuint32 height\nuint32 width\n\
        PointField[] fields\nbool    is_bigendian # comment\nuint32  point_step\nuint32  row_step\n\
        uint8[] data\nbool is_dense\n\
        ================================================================================\n\
        MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n\
        ================================================================================\n\
        MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n\
        ================================================================================\n\
        MSG: sensor_msgs/PointField\nuint8 INT8    = 1\nuint8 FLOAT32 = 7\n\
        string name\nuint32 offset\nuint8  datatype\nuint32 count\n";

    #[test]
    fn a_schema_as_ros_2_writes_it_matches_and_one_field_otherwise_does_not() {
        assert_eq!(Schema(CLOUD).check(Kind::Cloud), Ok(()));
        let renamed = CLOUD.replace("row_step", "row_stride");
        let err = Schema(&renamed).check(Kind::Cloud).unwrap_err();
        assert_eq!(err.type_name, "PointCloud2");
        assert_eq!(
            err.to_string(),
            "PointCloud2's field 7 is `uint32 row_stride`, not `uint32 row_step`"
        );
        let retyped = CLOUD.replace("uint32 offset", "uint16 offset");
        assert_eq!(
            Schema(&retyped).check(Kind::Cloud).unwrap_err().type_name,
            "PointField"
        );
        // ROS 2's defaults after a field's name are no part of its type.
        let quaternion = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n";
        let pose = format!(
            "std_msgs/Header header\nPose pose\n====\nMSG: geometry_msgs/Pose\nPoint position\n\
             Quaternion orientation\n====\nMSG: geometry_msgs/Quaternion\n{quaternion}"
        );
        assert_eq!(Schema(&pose).check(Kind::PoseStamped), Ok(()));
    }

    #[test]
    fn a_ros_1_definition_is_checked_with_ros_1_s_header() {
        let pose = "std_msgs/Header header\ngeometry_msgs/Pose pose\n====\nMSG: std_msgs/Header\n\
            uint32 seq\ntime stamp\nstring frame_id\n====\nMSG: geometry_msgs/Pose\n\
            geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n";
        assert_eq!(Schema(pose).check_ros1(Kind::PoseStamped), Ok(()));
        // ROS 2's header is not ROS 1's, nor the other way round.
        assert_eq!(
            Schema(pose).check(Kind::PoseStamped).unwrap_err().type_name,
            "Header"
        );
        let ros2 = pose.replace("uint32 seq\ntime stamp", "builtin_interfaces/Time stamp");
        assert_eq!(
            Schema(&ros2)
                .check_ros1(Kind::PoseStamped)
                .unwrap_err()
                .type_name,
            "Header"
        );
    }

    #[test]
    fn type_names_of_ros_1_and_2_name_the_same_kind() {
        assert_eq!(Kind::of("sensor_msgs/msg/PointCloud2"), Some(Kind::Cloud));
        assert_eq!(Kind::of("sensor_msgs/PointCloud2"), Some(Kind::Cloud));
        assert_eq!(Kind::of("nav_msgs/msg/Odometry"), Some(Kind::Odometry));
        assert_eq!(Kind::of("sensor_msgs/msg/Image"), None);
        assert_eq!(Kind::of("PointCloud2"), None);
    }

    #[test]
    fn cdr_of_either_byte_order_decodes_and_damage_is_an_error() {
        // A Time, little-endian: sec 7, nanosec 5000.
        let le = [0u8, 1, 0, 0, 7, 0, 0, 0, 0x88, 0x13, 0, 0];
        let t: Time = from_cdr(&le).unwrap();
        assert_eq!((t.sec, t.nanosec, t.utime()), (7, 5000, 7_000_005));
        let be = [0u8, 0, 0, 0, 0, 0, 0, 7, 0, 0, 0x13, 0x88];
        let t: Time = from_cdr(&be).unwrap();
        assert_eq!((t.sec, t.nanosec), (7, 5000));
        assert!(matches!(
            from_cdr::<Time>(&le[..2]),
            Err(DecodeError::Short(2))
        ));
        assert!(matches!(
            from_cdr::<Time>(&[0, 2, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8]),
            Err(DecodeError::Representation(2))
        ));
        assert!(matches!(
            from_cdr::<Time>(&le[..9]),
            Err(DecodeError::Cdr(_))
        ));
        // A string whose length claims 4 GB: an error, nothing allocated.
        let mut header = vec![0u8, 1, 0, 0, 7, 0, 0, 0, 0, 0, 0, 0];
        header.extend_from_slice(&u32::MAX.to_le_bytes());
        assert!(matches!(
            from_cdr::<Header>(&header),
            Err(DecodeError::Cdr(_))
        ));
    }
}
