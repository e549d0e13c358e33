//! The ROS 2 message types arcnav reads from bags and writes to them, as
//! ROS 2 defines them: their fields (a bag's schema is checked against
//! them before a message is decoded, [`super::msgs::Schema`]) and the
//! definition text a bag carries for each (`ros2msg`, as rosbag2 writes
//! it: the type's fields, then each type it uses after a line of `=` and
//! `MSG: package/Type`).
//!
//! Field types are written without their package here; a definition's
//! text names each with its package, as any ROS 2 tool reads it.
//! `visualization_msgs/Marker` is Jazzy's (the texture and mesh-file
//! fields that Iron added); `ackermann_msgs` is the ROS 2 port of the
//! package (`ros-<distro>-ackermann-msgs`).

/// A message type: its package, name and fields (`type name`, constants
/// left out: a bag's schema may hold them, they are no part of the wire).
#[derive(Debug, Clone, Copy)]
pub struct Definition {
    pub package: &'static str,
    pub name: &'static str,
    pub fields: &'static [&'static str],
}

const fn def(
    package: &'static str,
    name: &'static str,
    fields: &'static [&'static str],
) -> Definition {
    Definition {
        package,
        name,
        fields,
    }
}

/// Every type read or written. Trailing fields that a replay does not
/// decode (an odometry's twist covariance) are listed all the same: a
/// schema must match whole.
pub const DEFINITIONS: &[Definition] = &[
    def(
        "builtin_interfaces",
        "Time",
        &["int32 sec", "uint32 nanosec"],
    ),
    def(
        "builtin_interfaces",
        "Duration",
        &["int32 sec", "uint32 nanosec"],
    ),
    def("std_msgs", "Header", &["Time stamp", "string frame_id"]),
    def(
        "std_msgs",
        "ColorRGBA",
        &["float32 r", "float32 g", "float32 b", "float32 a"],
    ),
    def(
        "sensor_msgs",
        "PointCloud2",
        &[
            "Header header",
            "uint32 height",
            "uint32 width",
            "PointField[] fields",
            "bool is_bigendian",
            "uint32 point_step",
            "uint32 row_step",
            "uint8[] data",
            "bool is_dense",
        ],
    ),
    def(
        "sensor_msgs",
        "PointField",
        &[
            "string name",
            "uint32 offset",
            "uint8 datatype",
            "uint32 count",
        ],
    ),
    def(
        "sensor_msgs",
        "CompressedImage",
        &["Header header", "string format", "uint8[] data"],
    ),
    def(
        "nav_msgs",
        "Odometry",
        &[
            "Header header",
            "string child_frame_id",
            "PoseWithCovariance pose",
            "TwistWithCovariance twist",
        ],
    ),
    def(
        "geometry_msgs",
        "PoseWithCovariance",
        &["Pose pose", "float64[36] covariance"],
    ),
    def(
        "geometry_msgs",
        "TwistWithCovariance",
        &["Twist twist", "float64[36] covariance"],
    ),
    def(
        "geometry_msgs",
        "Twist",
        &["Vector3 linear", "Vector3 angular"],
    ),
    def(
        "geometry_msgs",
        "Pose",
        &["Point position", "Quaternion orientation"],
    ),
    def(
        "geometry_msgs",
        "Point",
        &["float64 x", "float64 y", "float64 z"],
    ),
    def(
        "geometry_msgs",
        "Vector3",
        &["float64 x", "float64 y", "float64 z"],
    ),
    def(
        "geometry_msgs",
        "Quaternion",
        &["float64 x", "float64 y", "float64 z", "float64 w"],
    ),
    def(
        "geometry_msgs",
        "PoseStamped",
        &["Header header", "Pose pose"],
    ),
    def(
        "geometry_msgs",
        "PoseWithCovarianceStamped",
        &["Header header", "PoseWithCovariance pose"],
    ),
    def(
        "geometry_msgs",
        "TransformStamped",
        &[
            "Header header",
            "string child_frame_id",
            "Transform transform",
        ],
    ),
    def(
        "geometry_msgs",
        "Transform",
        &["Vector3 translation", "Quaternion rotation"],
    ),
    def("tf2_msgs", "TFMessage", &["TransformStamped[] transforms"]),
    def(
        "ackermann_msgs",
        "AckermannDriveStamped",
        &["Header header", "AckermannDrive drive"],
    ),
    def(
        "ackermann_msgs",
        "AckermannDrive",
        &[
            "float32 steering_angle",
            "float32 steering_angle_velocity",
            "float32 speed",
            "float32 acceleration",
            "float32 jerk",
        ],
    ),
    def("visualization_msgs", "MarkerArray", &["Marker[] markers"]),
    def(
        "visualization_msgs",
        "Marker",
        &[
            "Header header",
            "string ns",
            "int32 id",
            "int32 type",
            "int32 action",
            "Pose pose",
            "Vector3 scale",
            "ColorRGBA color",
            "Duration lifetime",
            "bool frame_locked",
            "Point[] points",
            "ColorRGBA[] colors",
            "string texture_resource",
            "CompressedImage texture",
            "UVCoordinate[] uv_coordinates",
            "string text",
            "string mesh_resource",
            "MeshFile mesh_file",
            "bool mesh_use_embedded_materials",
        ],
    ),
    def(
        "visualization_msgs",
        "UVCoordinate",
        &["float32 u", "float32 v"],
    ),
    def(
        "visualization_msgs",
        "MeshFile",
        &["string filename", "uint8[] data"],
    ),
];

/// The definition of a type named without its package.
pub fn named(name: &str) -> Option<&'static Definition> {
    DEFINITIONS.iter().find(|d| d.name == name)
}

/// A field's type without its array brackets (`Point[]`, `float64[36]`:
/// `Point`, `float64`).
fn element(field_type: &str) -> &str {
    field_type.split('[').next().unwrap_or(field_type)
}

/// The `ros2msg` text of `name` (a type of [`DEFINITIONS`], without its
/// package): its fields, then every type they use, each once, in the
/// order first used; every type named with its package. `None` for a type
/// not defined here.
pub fn ros2msg(name: &str) -> Option<String> {
    let top = named(name)?;
    let mut order = vec![top];
    let mut next = 0;
    while let Some(definition) = order.get(next) {
        let used: Vec<&'static Definition> = definition
            .fields
            .iter()
            .filter_map(|f| named(element(f.split_whitespace().next().unwrap_or(""))))
            .collect();
        for d in used {
            if !order.iter().any(|o| o.name == d.name) {
                order.push(d);
            }
        }
        next += 1;
    }
    let mut text = String::new();
    for (i, definition) in order.iter().enumerate() {
        if i > 0 {
            text.push_str(&"=".repeat(80));
            text.push_str(&format!(
                "\nMSG: {}/{}\n",
                definition.package, definition.name
            ));
        }
        for field in definition.fields {
            let (field_type, field_name) = field.split_once(' ').unwrap_or((field, ""));
            let base = element(field_type);
            match named(base) {
                Some(d) => text.push_str(&format!("{}/{field_type} {field_name}\n", d.package)),
                None => text.push_str(&format!("{field_type} {field_name}\n")),
            }
        }
    }
    Some(text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_type_a_definition_uses_is_a_primitive_or_defined_here() {
        const PRIMITIVES: &[&str] = &[
            "bool", "byte", "char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
            "uint64", "float32", "float64", "string",
        ];
        for d in DEFINITIONS {
            for field in d.fields {
                let t = element(field.split_whitespace().next().unwrap());
                assert!(
                    PRIMITIVES.contains(&t) || named(t).is_some(),
                    "{}/{}: {field}",
                    d.package,
                    d.name
                );
            }
        }
    }

    #[test]
    fn a_definition_names_its_types_with_their_package_each_once() {
        let text = ros2msg("Odometry").unwrap();
        assert!(text.starts_with("std_msgs/Header header\nstring child_frame_id\n"));
        assert!(text.contains("geometry_msgs/PoseWithCovariance pose\n"));
        assert!(text.contains("\nMSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n"));
        // Vector3 is used by Twist alone, Point by Pose: each defined once.
        assert_eq!(text.matches("MSG: geometry_msgs/Vector3\n").count(), 1);
        assert_eq!(text.matches("MSG: ").count(), 9, "{text}");
        let marker = ros2msg("MarkerArray").unwrap();
        assert!(marker.starts_with("visualization_msgs/Marker[] markers\n"));
        assert!(marker.contains("geometry_msgs/Point[] points\n"));
        assert!(ros2msg("Unknown").is_none());
    }
}
