//! kumi's rapier world: any assembled morphology on flat ground, driven at the control rate.
//!
//! One [`World`] is one robot. Arm joints are position servos (PD with effort limit and a
//! rate-limited set-point), wheels are velocity servos; see [`kumi_model::Actuator`] for where
//! every gain and limit comes from. Training, evaluation and the sim bridge all use this crate.

mod actuator;
mod config;
mod convert;
mod error;
mod spawn;
mod world;

pub use actuator::{
    apply_increments, clamp_command, integrate_velocity_setpoint, slew, ServoState,
};
pub use config::SimConfig;
pub use error::SimError;
pub use kumi_model::Layout;
pub use world::{Contact, RobotState, Snapshot, World, GROUND};
