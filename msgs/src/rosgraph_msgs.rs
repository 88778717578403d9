//! `rosgraph_msgs`.

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;
use crate::ros_message;

/// `rosgraph_msgs/Clock`: simulated time, published on `/clock`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Clock {
    pub clock: Time,
}
ros_message!(Clock, "rosgraph_msgs", "Clock");
