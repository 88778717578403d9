//! kumi's rapier world: any assembled morphology on flat ground, driven at the control rate.
//!
//! One [`World`] is one robot, behind the engine-independent [`SimWorld`] interface of
//! `kumi-engine` (re-exported here). Arm joints are position servos (PD with effort limit and a
//! rate-limited set-point), wheels are velocity servos; see [`kumi_model::Actuator`] for where
//! every gain and limit comes from. rapier is the default engine of training, evaluation and
//! the sim bridge.

mod convert;
mod spawn;
mod world;

pub use kumi_engine::*;
pub use world::World;
