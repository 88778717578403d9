//! `rcl_interfaces`.

use serde::{Deserialize, Serialize};

use crate::builtin_interfaces::Time;
use crate::ros_message;

/// `rcl_interfaces/Log`: one log record, as ROS 2 nodes publish them on `/rosout`.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Log {
    pub stamp: Time,
    /// One of the `Log::*` levels.
    pub level: u8,
    /// The logger: the node's name with dots (`arm.arm.arm_node`).
    pub name: String,
    pub msg: String,
    pub file: String,
    pub function: String,
    pub line: u32,
}
ros_message!(Log, "rcl_interfaces", "Log");

impl Log {
    pub const DEBUG: u8 = 10;
    pub const INFO: u8 = 20;
    pub const WARN: u8 = 30;
    pub const ERROR: u8 = 40;
    pub const FATAL: u8 = 50;
}
