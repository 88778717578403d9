//! The world interface of kumi: what training, evaluation and the sim bridge need from a physics
//! engine, written once, and the rules every engine shares.
//!
//! A [`SimWorld`] is one robot on flat ground, driven at the control rate. Two engines implement
//! it: rapier (`kumi-sim`, the default everywhere) and MuJoCo (`kumi-mujoco`, for training
//! speed). What must not differ between them lives here: the servo law and its limits
//! ([`actuator`], [`ServoBank`]), the settings ([`SimConfig`]), the state types, which links may
//! touch ([`contact_groups`]) and the errors.

mod actuator;
mod config;
mod divergence;
mod engine;
mod error;
mod groups;
mod servos;
mod world;

pub use actuator::{integrate_velocity_setpoint, max_lead, slew, ServoState};
pub use config::SimConfig;
pub use divergence::{blown_up, BLOWN_UP_RATE_RAD_S, BLOWN_UP_SPEED_M_S};
pub use engine::Engine;
pub use error::SimError;
pub use groups::{contact_groups, mount_is_impulse};
pub use kumi_model::commands::{apply_increments, clamp_command, CONTROL_HZ};
pub use kumi_model::Layout;
pub use servos::{ServoBank, ServoTarget};
pub use world::{
    home_joint_positions, Contact, LinkLoad, Load, RobotState, SimWorld, Snapshot, GROUND,
};
