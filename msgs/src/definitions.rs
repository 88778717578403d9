//! The interface definitions (`.msg` text) of every message kumi speaks, so that a recording
//! can carry its own schemas: an MCAP file written by `kumi record` opens in Foxglove or with
//! `mcap-ros2-support` on a machine without ROS.
//!
//! Each definition lists the fields of the standard interface (ROS 2 Kilted/Jazzy) in order,
//! with its constants, without comments or default values; message-typed fields name their
//! type in full (`geometry_msgs/Point`). [`schema`] appends every type a definition uses, as
//! rosbag2 does for its `ros2msg` schemas (MCAP's well-known `ros2msg` encoding): a line of 80
//! `=`, `MSG: package/Name`, its definition.

/// `(package/Name, definition)` of every message type kumi publishes or subscribes to, and of
/// the types they are made of.
const DEFINITIONS: &[(&str, &str)] = &[
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec"),
    (
        "std_msgs/Header",
        "builtin_interfaces/Time stamp\nstring frame_id",
    ),
    ("std_msgs/Float64", "float64 data"),
    ("std_msgs/Bool", "bool data"),
    ("std_msgs/String", "string data"),
    (
        "std_msgs/MultiArrayDimension",
        "string label\nuint32 size\nuint32 stride",
    ),
    (
        "std_msgs/MultiArrayLayout",
        "std_msgs/MultiArrayDimension[] dim\nuint32 data_offset",
    ),
    (
        "std_msgs/Float64MultiArray",
        "std_msgs/MultiArrayLayout layout\nfloat64[] data",
    ),
    ("geometry_msgs/Vector3", "float64 x\nfloat64 y\nfloat64 z"),
    ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z"),
    (
        "geometry_msgs/Quaternion",
        "float64 x\nfloat64 y\nfloat64 z\nfloat64 w",
    ),
    (
        "geometry_msgs/Pose",
        "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation",
    ),
    (
        "geometry_msgs/PoseStamped",
        "std_msgs/Header header\ngeometry_msgs/Pose pose",
    ),
    (
        "geometry_msgs/Twist",
        "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular",
    ),
    (
        "geometry_msgs/Transform",
        "geometry_msgs/Vector3 translation\ngeometry_msgs/Quaternion rotation",
    ),
    (
        "geometry_msgs/TransformStamped",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/Transform transform",
    ),
    (
        "geometry_msgs/PoseWithCovariance",
        "geometry_msgs/Pose pose\nfloat64[36] covariance",
    ),
    (
        "geometry_msgs/TwistWithCovariance",
        "geometry_msgs/Twist twist\nfloat64[36] covariance",
    ),
    (
        "sensor_msgs/JointState",
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort",
    ),
    (
        "sensor_msgs/Imu",
        "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\nfloat64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\nfloat64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\nfloat64[9] linear_acceleration_covariance",
    ),
    (
        "nav_msgs/Odometry",
        "std_msgs/Header header\nstring child_frame_id\ngeometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist",
    ),
    (
        "tf2_msgs/TFMessage",
        "geometry_msgs/TransformStamped[] transforms",
    ),
    ("diagnostic_msgs/KeyValue", "string key\nstring value"),
    (
        "diagnostic_msgs/DiagnosticStatus",
        "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\nbyte level\nstring name\nstring message\nstring hardware_id\ndiagnostic_msgs/KeyValue[] values",
    ),
    (
        "diagnostic_msgs/DiagnosticArray",
        "std_msgs/Header header\ndiagnostic_msgs/DiagnosticStatus[] status",
    ),
    ("rosgraph_msgs/Clock", "builtin_interfaces/Time clock"),
    (
        "rcl_interfaces/Log",
        "uint8 DEBUG=10\nuint8 INFO=20\nuint8 WARN=30\nuint8 ERROR=40\nuint8 FATAL=50\nbuiltin_interfaces/Time stamp\nuint8 level\nstring name\nstring msg\nstring file\nstring function\nuint32 line",
    ),
];

/// The line between two definitions of a `ros2msg` schema.
const SEPARATOR: &str =
    "================================================================================";

/// The definition of `package/Name` (or `package/msg/Name`) alone, without the types it uses.
pub fn definition(type_name: &str) -> Option<&'static str> {
    let short = short_name(type_name);
    DEFINITIONS
        .iter()
        .find(|(name, _)| *name == short)
        .map(|(_, text)| *text)
}

/// `package/Name` of `package/msg/Name` (unchanged when already short).
fn short_name(type_name: &str) -> String {
    match type_name.split('/').collect::<Vec<_>>().as_slice() {
        [package, "msg", name] => format!("{package}/{name}"),
        _ => type_name.to_string(),
    }
}

/// The message types a definition's fields have (`package/Name`), in order, each once.
fn field_types(definition: &str) -> Vec<&str> {
    let mut types = Vec::new();
    for line in definition.lines() {
        let Some(ty) = line.split_whitespace().next() else {
            continue;
        };
        let base = ty.split('[').next().unwrap_or(ty);
        if base.contains('/') && !types.contains(&base) {
            types.push(base);
        }
    }
    types
}

/// The `ros2msg` schema of `package/Name` or `package/msg/Name`: its definition, then every
/// message type it uses, directly or through another, each once in the order first met.
/// `None` for a type kumi does not know.
pub fn schema(type_name: &str) -> Option<String> {
    let mut text = definition(type_name)?.to_string();
    let mut done = vec![short_name(type_name)];
    let mut pending: Vec<String> = field_types(&text)
        .into_iter()
        .rev()
        .map(str::to_string)
        .collect();
    while let Some(next) = pending.pop() {
        if done.contains(&next) {
            continue;
        }
        let body = definition(&next)?;
        text.push_str(&format!("\n{SEPARATOR}\nMSG: {next}\n{body}"));
        pending.extend(field_types(body).into_iter().rev().map(str::to_string));
        done.push(next);
    }
    Some(text)
}

/// The ROS name (`package/msg/Name`) of a DDS type name as ROS 2 middlewares announce it
/// (`package::msg::dds_::Name_`); `None` for a type name of another form.
pub fn ros_type_of_dds(dds_type: &str) -> Option<String> {
    let parts: Vec<&str> = dds_type.split("::").collect();
    match parts.as_slice() {
        [package, kind, "dds_", name] if !package.is_empty() => {
            let name = name.strip_suffix('_').filter(|n| !n.is_empty())?;
            Some(format!("{package}/{kind}/{name}"))
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::RosMessage;

    fn full_name<M: RosMessage>() -> String {
        format!("{}/msg/{}", M::PACKAGE, M::NAME)
    }

    #[test]
    fn every_message_kumi_speaks_has_a_schema() {
        use crate::*;
        let names = [
            full_name::<sensor_msgs::JointState>(),
            full_name::<sensor_msgs::Imu>(),
            full_name::<nav_msgs::Odometry>(),
            full_name::<tf2_msgs::TFMessage>(),
            full_name::<geometry_msgs::PoseStamped>(),
            full_name::<std_msgs::Float64>(),
            full_name::<std_msgs::Float64MultiArray>(),
            full_name::<std_msgs::StringMsg>(),
            full_name::<std_msgs::Bool>(),
            full_name::<diagnostic_msgs::DiagnosticArray>(),
            full_name::<rosgraph_msgs::Clock>(),
            full_name::<rcl_interfaces::Log>(),
        ];
        for name in names {
            assert!(schema(&name).is_some(), "{name}");
        }
    }

    #[test]
    fn every_type_a_definition_uses_is_defined_and_primitive_types_are_ros_ones() {
        const PRIMITIVES: [&str; 15] = [
            "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
            "int32", "uint32", "int64", "uint64", "string", "wstring",
        ];
        for (name, text) in DEFINITIONS {
            for line in text.lines() {
                let ty = line.split_whitespace().next().unwrap();
                let base = ty.split('[').next().unwrap();
                assert!(
                    PRIMITIVES.contains(&base) || definition(base).is_some(),
                    "{name}: `{line}`"
                );
            }
        }
    }

    #[test]
    fn a_schema_appends_each_type_it_uses_once_depth_first() {
        let odometry = schema("nav_msgs/msg/Odometry").unwrap();
        let sections: Vec<&str> = odometry
            .lines()
            .filter_map(|l| l.strip_prefix("MSG: "))
            .collect();
        assert_eq!(
            sections,
            [
                "std_msgs/Header",
                "builtin_interfaces/Time",
                "geometry_msgs/PoseWithCovariance",
                "geometry_msgs/Pose",
                "geometry_msgs/Point",
                "geometry_msgs/Quaternion",
                "geometry_msgs/TwistWithCovariance",
                "geometry_msgs/Twist",
                "geometry_msgs/Vector3",
            ]
        );
        assert!(odometry.starts_with("std_msgs/Header header\nstring child_frame_id\n"));
        assert_eq!(odometry.matches(SEPARATOR).count(), sections.len());
        assert_eq!(schema("std_msgs/String").unwrap(), "string data");
        assert_eq!(schema("std_msgs/msg/Nope"), None);
    }

    #[test]
    fn dds_type_names_map_to_ros_names() {
        assert_eq!(
            ros_type_of_dds("sensor_msgs::msg::dds_::JointState_").as_deref(),
            Some("sensor_msgs/msg/JointState")
        );
        assert_eq!(ros_type_of_dds("sensor_msgs/msg/JointState"), None);
        assert_eq!(ros_type_of_dds("a::msg::dds_::_"), None);
        assert_eq!(ros_type_of_dds("::msg::dds_::X_"), None);
    }
}
