//! The sim bridge node: kumi's rapier world on ROS 2, standing in for MoonBot hardware.
//!
//! Per module it publishes joint states and takes joint increments, absolute joint targets
//! (`joint_set`, Motion Stack's form) or wheel velocities; for the robot it publishes odometry,
//! IMU, `/tf`, the URDF (latched) and `/clock`. See the README's topic table.
//!
//! The node is a thin shell: command validation ([`commands`]), lockstep gating ([`lockstep`])
//! and message building ([`state`]) are pure and tested on their own; [`run`] moves messages.

pub mod commands;
pub mod lockstep;
mod run;
pub mod state;

pub use run::{run, BridgeConfig, BridgeError, Mode};
