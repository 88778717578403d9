//! `sensor_msgs`.

use serde::{Deserialize, Serialize};

use crate::geometry_msgs::{Quaternion, Vector3};
use crate::ros_message;
use crate::std_msgs::Header;

/// `sensor_msgs/JointState`: positions [rad], velocities [rad/s], efforts [N m] by joint name.
/// Any of the three arrays may be empty.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointState {
    pub header: Header,
    pub name: Vec<String>,
    pub position: Vec<f64>,
    pub velocity: Vec<f64>,
    pub effort: Vec<f64>,
}
ros_message!(JointState, "sensor_msgs", "JointState");

/// `sensor_msgs/Imu`: orientation, angular velocity [rad/s] and linear acceleration [m/s^2],
/// the vectors in `header.frame_id`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Imu {
    pub header: Header,
    pub orientation: Quaternion,
    #[serde(with = "crate::fixed_array")]
    pub orientation_covariance: [f64; 9],
    pub angular_velocity: Vector3,
    #[serde(with = "crate::fixed_array")]
    pub angular_velocity_covariance: [f64; 9],
    pub linear_acceleration: Vector3,
    #[serde(with = "crate::fixed_array")]
    pub linear_acceleration_covariance: [f64; 9],
}
ros_message!(Imu, "sensor_msgs", "Imu");
