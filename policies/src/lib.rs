//! The low-level reaching skill's interface, defined once and used by the training environment
//! and the arm-module node alike, so that what a policy saw in training is exactly what it is fed
//! in deployment (the paper's section IV-A and Table I).
//!
//! - [`observation`]: the 21-value observation and its builder.
//! - [`skill`]: the skill's contract with an arm module (joint order, limits, action scale)
//!   and from the policy's 7 outputs to joint increments [rad].
//! - [`metadata`]: the keys an exported policy carries.
//! - [`goal`]: goal sampling in the arm base frame, and per-step goal noise.
//! - [`rotation`]: the orientation error (the quaternion log map).
//! - [`settle`]: how calmly the skill holds and reaches a goal (hold smoothness, settle time,
//!   joint speeds), as evaluation and the standing check report it.

pub mod goal;
pub mod goals;
pub mod kinematics;
pub mod metadata;
pub mod observation;
pub mod rotation;
pub mod settle;
pub mod skill;
