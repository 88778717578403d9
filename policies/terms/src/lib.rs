//! The whole-body (upper-level) policy's interface (the paper's section IV-B, its Tables III and
//! V), defined once and used by training, evaluation and the whole-body node alike:
//!
//! - [`action`]: the action terms, derived from any morphology: a goal for the frozen skill per
//!   arm module (6 values for the manipulator, 4 for a leg), a velocity per wheel module;
//! - [`observation`]: the observation's named slots and its builder;
//! - [`contract`]: what an exported whole-body policy carries in its metadata, and the check
//!   that it fits the morphology and the skill in use;
//! - [`termination`]: when the robot has tipped over (training's episode end, the node's stop).
//!
//! Nothing here simulates or trains: a node that runs on hardware links this crate.

pub mod action;
pub mod contract;
pub mod observation;
pub mod termination;

pub use action::{
    ActionTerms, ArmGoalTerm, GoalBounds, JointBounds, JointTargetTerm, TermError, WheelRamp,
    WheelTerm,
};
pub use observation::{BodyState, ObservationOptions, ObservationSlot, Target, ToolChain};
