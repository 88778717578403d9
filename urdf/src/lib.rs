//! The kumi robot model: module descriptions, morphology files, and the assembler that turns a
//! morphology into one complete URDF with prefixed, unique names (`arm0/joint1`, ...).
//!
//! This crate is the single source of truth for every physical parameter: geometry, masses and
//! joint limits come from the module URDFs in `urdf/modules/`, actuator gains, connectors and
//! contact materials from the module TOML files beside them. Training, evaluation, the sim
//! bridge and the nodes all read the model through [`RobotModel`].

mod assemble;
mod catalog;
pub mod commands;
mod error;
pub mod kinematics;
mod module;
mod morphology;
mod physics;
pub mod pose;
mod steering;

pub use assemble::{assemble, unprefixed, ModuleInstance, RobotModel};
pub use catalog::{load_morphology, shipped_morphologies, ModuleLibrary, SHIPPED_MORPHOLOGIES};
pub use error::{ModelError, Problem};
pub use module::{Actuator, ActuatorMode, Connector, ContactMaterial, Module};
pub use morphology::{Morphology, MorphologyModule, Mount, Role};
pub use physics::{Layout, PhysicsSettings};
pub use steering::{rolling_gain, SteeringCoupling};
