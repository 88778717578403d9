//! The ROS 2 messages kumi speaks, as plain serde structs.
//!
//! Each struct mirrors the standard interface definition of ROS 2 Kilted/Jazzy field for field,
//! in the same order (CDR, the wire format, is positional), and names its ROS type through
//! [`RosMessage`]. No middleware dependency: the ROS layer (`kumi-ros`) turns the type name
//! into a topic type.

pub mod builtin_interfaces;
pub mod cdr;
pub mod definitions;
pub mod diagnostic_msgs;
mod fixed_array;
pub mod geometry_msgs;
pub mod nav_msgs;
pub mod rcl_interfaces;
pub mod rosgraph_msgs;
pub mod sensor_msgs;
pub mod std_msgs;
pub mod tf2_msgs;

/// A message type with its ROS 2 name: `PACKAGE/msg/NAME`.
pub trait RosMessage:
    serde::Serialize + serde::de::DeserializeOwned + Clone + Send + 'static
{
    /// The interface package, such as `sensor_msgs`.
    const PACKAGE: &'static str;
    /// The message name, such as `JointState`.
    const NAME: &'static str;
}

/// Implements [`RosMessage`] for a type.
macro_rules! ros_message {
    ($ty:ty, $package:literal, $name:literal) => {
        impl $crate::RosMessage for $ty {
            const PACKAGE: &'static str = $package;
            const NAME: &'static str = $name;
        }
    };
}
pub(crate) use ros_message;
