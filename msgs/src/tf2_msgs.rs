//! `tf2_msgs`.

use serde::{Deserialize, Serialize};

use crate::geometry_msgs::TransformStamped;
use crate::ros_message;

/// `tf2_msgs/TFMessage`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TFMessage {
    pub transforms: Vec<TransformStamped>,
}
ros_message!(TFMessage, "tf2_msgs", "TFMessage");
