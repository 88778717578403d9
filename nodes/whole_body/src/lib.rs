//! The whole-body node: one per robot, running its upper-level policy over
//! the arm nodes' frozen skill.
//!
//! - [`target`]: validating the `geometry_msgs/PoseStamped` target (frame, finiteness,
//!   quaternion) into a [`kumi_terms::Target`].
//! - [`tick`]: gathering one control tick's state (odometry and every module's joint states,
//!   matched by stamp) from messages that arrive one by one.
//! - [`controller`]: the pure control step: the observation by
//!   [`kumi_terms::observation::build`] (the function training uses), the policy, and the
//!   commands by [`kumi_terms::ActionTerms::commands`]; or a hold and why.
//! - [`report`]: what it reports on `/diagnostics`.
//! - [`steering`]: on hardware, wheels that follow their legs' steering commands, as the
//!   simulator's servos roll them.
//! - [`run`]: the ROS 2 shell around them.

pub mod controller;
pub mod report;
pub mod run;
pub mod steering;
pub mod target;
pub mod tick;

pub use controller::{Decision, Hold, WholeBodyController};
pub use run::{run, WholeBodyNodeConfig, WholeBodyNodeError};
