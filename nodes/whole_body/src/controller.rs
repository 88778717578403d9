//! The whole-body node's control step, free of ROS: from the target and one tick's state to
//! the arm modules' goals and the wheel modules' velocities. The observation is built by
//! [`kumi_terms::observation::build`] and the action becomes commands by
//! [`ActionTerms::commands`], the functions training uses; the tool pose comes from forward
//! kinematics of the measured joint angles from the measured base pose.
//!
//! **Holding.** Without a target, on stale state or when the policy fails, the wheels stop and
//! the arms keep the goals they were last sent (none before the first target: the arm nodes
//! hold their joints). The previous action starts over from zeros after a hold, as after a
//! reset in training.

use kumi_model::RobotModel;
use kumi_policies::observation::Goal;
use kumi_terms::observation::{self, BodyState};
use kumi_terms::{ActionTerms, Target, ToolChain};
use nalgebra::Isometry3;

use crate::tick::Snapshot;

/// A policy: observation in, action out.
pub type PolicyFn = Box<dyn FnMut(&[f32]) -> Result<Vec<f32>, String> + Send>;

/// Why a step held.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Hold {
    /// No target received yet.
    #[error("no target yet")]
    NoTarget,
    /// An input has not been heard from yet.
    #[error("no {input} yet")]
    Waiting { input: String },
    /// An input is too old.
    #[error("{input} are {age_s:.2} s old")]
    Stale { input: String, age_s: f64 },
    /// The policy failed (its message).
    #[error("policy failed: {0}")]
    PolicyFailed(String),
}

/// What one step decided.
#[derive(Debug, Clone, PartialEq)]
pub struct Decision {
    /// Each arm module's goal in its base frame (the latest ones while holding; `None` before
    /// the first target).
    pub goals: Option<Vec<(String, Goal)>>,
    /// Each wheel module's wheel velocity [rad/s] (0 while holding; none before the first
    /// target).
    pub wheel_velocities: Vec<(String, f64)>,
    pub hold: Option<Hold>,
    /// The manipulator's tool pose in `<robot>/odom`, when the step had state.
    pub tool_pose_w: Option<Isometry3<f64>>,
    /// The observation and the action, when the policy ran.
    pub observation: Option<Vec<f32>>,
    pub action: Option<Vec<f32>>,
}

/// One robot's upper-level controller.
pub struct WholeBodyController {
    terms: ActionTerms,
    tool: ToolChain,
    /// Per module of [`Self::modules`]: its joints' names (as in the URDF).
    joints: Vec<Vec<String>>,
    modules: Vec<String>,
    /// (module index, joint index) of every wheel joint, in training's order.
    wheel_joints: Vec<(usize, usize)>,
    policy: PolicyFn,
    target: Option<Target>,
    previous_action: Vec<f32>,
    last_goals: Option<Vec<(String, Goal)>>,
}

impl WholeBodyController {
    /// The controller for `model` with its `terms`, running `policy`.
    pub fn new(model: &RobotModel, terms: ActionTerms, policy: PolicyFn) -> Result<Self, String> {
        let tool = ToolChain::new(model)?;
        let modules: Vec<String> = terms.terms.iter().map(|t| t.module().to_string()).collect();
        let mut joints = Vec::new();
        let mut wheel_joints = Vec::new();
        for (m, name) in modules.iter().enumerate() {
            let module = model.module(name).expect("terms come from the model");
            joints.push(module.actuators.iter().map(|a| a.joint.clone()).collect());
            if terms.wheels().any(|w| &w.module == name) {
                for (j, a) in module.actuators.iter().enumerate() {
                    if a.mode == kumi_model::ActuatorMode::Velocity {
                        wheel_joints.push((m, j));
                    }
                }
            }
        }
        Ok(Self {
            previous_action: vec![0.0; terms.size()],
            terms,
            tool,
            joints,
            modules,
            wheel_joints,
            policy,
            target: None,
            last_goals: None,
        })
    }

    /// The modules whose joint states a tick needs, in [`Snapshot::modules`] order.
    pub fn modules(&self) -> &[String] {
        &self.modules
    }

    /// Each module's joint names, in the order of [`crate::tick::ModuleState`].
    pub fn joint_names(&self, module: usize) -> &[String] {
        &self.joints[module]
    }

    pub fn terms(&self) -> &ActionTerms {
        &self.terms
    }

    pub fn target(&self) -> Option<Target> {
        self.target
    }

    pub fn set_target(&mut self, target: Target) {
        self.target = Some(target);
    }

    /// The manipulator's tool pose in the odometry frame for a tick's state.
    pub fn tool_pose_w(&self, state: &Snapshot) -> Isometry3<f64> {
        let named = self
            .joints
            .iter()
            .zip(&state.modules)
            .flat_map(|(names, m)| names.iter().map(String::as_str).zip(m.q.iter().copied()));
        self.tool.tool_pose_w(&state.base.pose_w, named)
    }

    /// One control step on a tick's state.
    pub fn step(&mut self, state: &Snapshot) -> Decision {
        let tool_pose_w = self.tool_pose_w(state);
        let Some(target) = self.target else {
            return self.hold(Hold::NoTarget, Some(tool_pose_w));
        };
        let wheels: Vec<f64> = self
            .wheel_joints
            .iter()
            .map(|&(m, j)| state.modules[m].qd[j])
            .collect();
        let obs = observation::build(&BodyState {
            base_pose_w: state.base.pose_w,
            base_linear_velocity_w: state.base.linear_velocity_w,
            tool_pose_w,
            target,
            wheel_velocities: &wheels,
            previous_action: &self.previous_action,
        });
        let action = match (self.policy)(&obs) {
            Ok(a) if a.len() == self.terms.size() => a,
            Ok(a) => {
                let why = format!(
                    "{} action values, the terms take {}",
                    a.len(),
                    self.terms.size()
                );
                return self.hold(Hold::PolicyFailed(why), Some(tool_pose_w));
            }
            Err(why) => return self.hold(Hold::PolicyFailed(why), Some(tool_pose_w)),
        };
        let commands = self
            .terms
            .commands(&action)
            .expect("the action's size was checked");
        let goals: Vec<(String, Goal)> = self
            .terms
            .arms()
            .map(|a| a.module.clone())
            .zip(commands.goals)
            .collect();
        self.last_goals = Some(goals.clone());
        self.previous_action.copy_from_slice(&action);
        Decision {
            goals: Some(goals),
            wheel_velocities: self
                .terms
                .wheels()
                .map(|w| w.module.clone())
                .zip(commands.wheel_velocities)
                .collect(),
            hold: None,
            tool_pose_w: Some(tool_pose_w),
            observation: Some(obs),
            action: Some(action),
        }
    }

    /// Holds: wheels stop, arms keep their last goals, the previous action starts over. Before
    /// the first target nothing is commanded at all: the bridge holds what it was never told
    /// to move, and in lockstep simulated time stands still until there is a target.
    pub fn hold(&mut self, why: Hold, tool_pose_w: Option<Isometry3<f64>>) -> Decision {
        self.previous_action.iter_mut().for_each(|a| *a = 0.0);
        let commanded = self.last_goals.is_some();
        Decision {
            goals: self.last_goals.clone(),
            wheel_velocities: match commanded {
                true => self
                    .terms
                    .wheels()
                    .map(|w| (w.module.clone(), 0.0))
                    .collect(),
                false => Vec::new(),
            },
            hold: Some(why),
            tool_pose_w,
            observation: None,
            action: None,
        }
    }
}
