//! The arm-module node: one per arm module, running the shared low-level skill.
//!
//! - [`goal`]: validating a `geometry_msgs/PoseStamped` goal (frame, finiteness, quaternion,
//!   workspace).
//! - [`joints`]: reading the module's `sensor_msgs/JointState` in the skill's joint order.
//! - [`controller`]: the pure control step: hold, or observation -> policy -> increments
//!   (the holder of the servo targets applies them). It builds the observation with the same function training
//!   uses ([`kumi_policies::observation::build`]).
//! - [`schedule`]: when the node acts (sim time or wall time), and sim time that restarts.
//! - [`report`]: what it reports on `/diagnostics`.
//! - [`run`]: the ROS 2 shell around them.

pub mod controller;
pub mod goal;
pub mod joints;
pub mod report;
pub mod run;
pub mod schedule;

pub use controller::{ArmController, Command, Hold};
pub use run::{run, ArmNodeConfig, ArmNodeError, ClockSource, Output};
