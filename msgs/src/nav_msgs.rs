//! `nav_msgs`.

use serde::{Deserialize, Serialize};

use crate::geometry_msgs::{PoseWithCovariance, TwistWithCovariance};
use crate::ros_message;
use crate::std_msgs::Header;

/// `nav_msgs/Odometry`: pose in `header.frame_id`, twist in `child_frame_id`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}
ros_message!(Odometry, "nav_msgs", "Odometry");
