//! The arm node's control step, free of ROS: from the latest goal and joint state to the next
//! command. The observation is built by [`kumi_policies::observation::build`], the function the
//! training environment uses, and the action becomes increments by [`ArmSkill::increments`].
//!
//! **Who owns the servo targets.** Increments are applied to the targets by whoever holds them,
//! through [`kumi_model::commands::apply_increments`] (the one rule: add, then clamp to the joint range).
//! The node always keeps its own targets, starting from the measured joint angles and starting
//! over from them whenever it resumes after holding, because the skill observes how far they
//! lead the joints. It sends them as absolute targets (`joint_set`, the sim bridge's and Motion
//! Stack's form). A skill of the first format (Table I's observation, no targets) may instead
//! send bare increments to the sim bridge, which then holds the targets itself.
use kumi_model::commands::apply_increments;
use kumi_model::Actuator;
use kumi_policies::observation::{self, Goal, JOINTS, OBSERVATION_DIM};
use kumi_policies::skill::ArmSkill;
use nalgebra::Isometry3;

use crate::joints::Joints;

/// A policy: observation in, action (7 values in policy units) out.
pub type PolicyFn = Box<dyn FnMut(&[f32; OBSERVATION_DIM]) -> Result<[f32; JOINTS], String> + Send>;

/// The module's forward kinematics: the tool pose in its base frame from its joint angles
/// [rad] ([`kumi_policies::kinematics::ToolKinematics::tool_pose_b`] on a robot).
pub type ToolFn = Box<dyn Fn(&[f64; JOINTS]) -> Isometry3<f64> + Send>;

/// Why a step held the arm still instead of running the policy.
#[derive(Debug, Clone, PartialEq)]
pub enum Hold {
    /// No goal received yet.
    NoGoal,
    /// No joint state received yet: nothing is commanded at all.
    NoJointState,
    /// The latest joint state is older than the limit [s].
    Stale { age_s: f64 },
    /// The policy failed (its message); the arm holds.
    PolicyFailed(String),
}

/// What one step decided.
#[derive(Debug, Clone, PartialEq)]
pub struct Command {
    /// The skill's increments [rad] for this step (zero when holding), for the holder of the
    /// targets to apply with [`kumi_model::commands::apply_increments`].
    pub increments: [f64; JOINTS],
    /// Absolute joint targets [rad] when the node holds the targets itself (Motion Stack):
    /// the increments applied to the node's own targets. `None` until a joint state has been
    /// seen.
    pub targets: Option<[f64; JOINTS]>,
    /// Set when the step held.
    pub hold: Option<Hold>,
    /// The observation fed to the policy, when it ran.
    pub observation: Option<[f32; OBSERVATION_DIM]>,
}

/// One arm module's controller.
pub struct ArmController {
    skill: ArmSkill,
    actuators: Vec<Actuator>,
    tool_pose_b: ToolFn,
    /// The joints' limits [rad], (lower, upper), in the skill's joint order.
    limits_rad: [(f64, f64); JOINTS],
    policy: PolicyFn,
    stale_after_s: f64,
    goal: Option<Goal>,
    joints: Option<(Joints, f64)>,
    /// The node's own targets (used by Motion Stack output); cleared by every hold, so that
    /// they restart from the measured joint angles.
    targets: Option<[f64; JOINTS]>,
}

impl ArmController {
    /// A controller for the module `skill` describes, with its position `actuators` (for the
    /// joint limits; the skill's [`JOINTS`], in its order), its forward kinematics, a policy,
    /// and the joint-state age [s] beyond which it holds.
    pub fn new(
        skill: ArmSkill,
        actuators: Vec<Actuator>,
        tool_pose_b: ToolFn,
        policy: PolicyFn,
        stale_after_s: f64,
    ) -> Self {
        let limits_rad = std::array::from_fn(|j| (actuators[j].lower, actuators[j].upper));
        Self {
            skill,
            actuators,
            tool_pose_b,
            limits_rad,
            policy,
            stale_after_s,
            goal: None,
            joints: None,
            targets: None,
        }
    }

    pub fn skill(&self) -> &ArmSkill {
        &self.skill
    }

    /// Replaces the goal (already validated).
    pub fn set_goal(&mut self, goal: Goal) {
        self.goal = Some(goal);
    }

    pub fn goal(&self) -> Option<&Goal> {
        self.goal.as_ref()
    }

    /// Records a joint state measured at `t_s` [s].
    pub fn set_joints(&mut self, joints: Joints, t_s: f64) {
        self.joints = Some((joints, t_s));
    }

    /// Forgets the joint state and the node's targets (the time base changed, or the
    /// simulator restarted): the next step holds until a new joint state arrives. The goal is
    /// kept.
    pub fn forget_state(&mut self) {
        self.joints = None;
        self.targets = None;
    }

    /// The latest joint state and when it was measured [s].
    pub fn joints(&self) -> Option<&(Joints, f64)> {
        self.joints.as_ref()
    }

    /// The observation the policy would see now, if there is a goal and a joint state. The
    /// targets are the node's own, or the measured angles before the first step and after a
    /// hold (where the next step starts them, as training's reset does).
    pub fn observation(&self) -> Option<[f32; OBSERVATION_DIM]> {
        let (j, _) = self.joints.as_ref()?;
        let targets = self.targets.unwrap_or(j.q);
        Some(observation::build(
            &j.q,
            &j.qd,
            &targets,
            self.goal.as_ref()?,
            &*self.tool_pose_b,
            &self.limits_rad,
        ))
    }

    /// A hold: zero increments; the node's targets (Motion Stack) stay where they are for
    /// this command and restart from the measured angles when the policy runs again.
    fn hold(&mut self, why: Hold) -> Command {
        let targets = self.targets.take().or(self.joints.map(|(j, _)| j.q));
        Command {
            increments: [0.0; JOINTS],
            targets,
            hold: Some(why),
            observation: None,
        }
    }

    /// One control step at time `now_s` [s].
    pub fn step(&mut self, now_s: f64) -> Command {
        let Some((joints, t)) = self.joints else {
            return self.hold(Hold::NoJointState);
        };
        let age_s = now_s - t;
        if age_s > self.stale_after_s {
            return self.hold(Hold::Stale { age_s });
        }
        let Some(obs) = self.observation() else {
            return self.hold(Hold::NoGoal);
        };
        let action = match (self.policy)(&obs) {
            Ok(a) => a,
            Err(e) => return self.hold(Hold::PolicyFailed(e)),
        };
        // The node's targets start where the arm is, as in training (reset sets them to the
        // joint angles).
        let targets = self.targets.unwrap_or(joints.q);
        let increments = self.skill.increments(&action);
        let actuators: Vec<&Actuator> = self.actuators.iter().collect();
        let next = apply_increments(&targets, &increments, &actuators)
            .expect("the skill's increments are finite and sized for the module");
        self.targets = Some(std::array::from_fn(|i| next[i]));
        Command {
            increments,
            targets: self.targets,
            hold: None,
            observation: Some(obs),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kumi_model::{ActuatorMode, ModuleInstance, Role};
    use nalgebra::{UnitQuaternion, Vector3};

    fn module() -> ModuleInstance {
        ModuleInstance {
            name: "arm".into(),
            kind: "arm".into(),
            role: Role::Manipulator,
            parent: None,
            mount_joint: None,
            root_link: "arm/base".into(),
            links: vec![],
            ee_link: Some("arm/ee".into()),
            actuators: (1..=JOINTS)
                .map(|i| Actuator {
                    joint: format!("arm/joint{i}"),
                    mode: ActuatorMode::Position,
                    stiffness: 1.0,
                    damping: 1.0,
                    armature: 0.0,
                    joint_damping: 0.0,
                    joint_friction: 0.0,
                    effort_limit: 1.0,
                    velocity_limit: 1.5,
                    lower: -1.0,
                    upper: 1.0,
                })
                .collect(),
            home: vec![0.0; JOINTS],
            follow_steering: false,
        }
    }

    fn controller(policy: PolicyFn) -> ArmController {
        let m = module();
        ArmController::new(
            ArmSkill::new(&m, 30.0).unwrap(),
            m.actuators.clone(),
            Box::new(tool_pose_b),
            policy,
            0.2,
        )
    }

    /// A stand-in for forward kinematics: the tool 1 m up, moved along x by joint1's angle.
    fn tool_pose_b(q: &[f64; JOINTS]) -> Isometry3<f64> {
        Isometry3::translation(q[0], 0.0, 1.0)
    }

    fn goal() -> Goal {
        Goal {
            position_b: Vector3::new(0.3, 0.0, 1.0),
            orientation_b: UnitQuaternion::identity(),
        }
    }

    fn joints(q0: f64) -> Joints {
        Joints {
            q: [q0; JOINTS],
            qd: [0.0; JOINTS],
        }
    }

    #[test]
    fn holds_without_joint_state_or_goal() {
        let mut c = controller(Box::new(|_| Ok([1.0; JOINTS])));
        assert_eq!(c.step(0.0).hold, Some(Hold::NoJointState));
        assert_eq!(c.step(0.0).targets, None);
        c.set_joints(joints(0.25), 0.0);
        let cmd = c.step(0.0);
        assert_eq!(cmd.hold, Some(Hold::NoGoal));
        assert_eq!(
            (cmd.increments, cmd.targets),
            ([0.0; JOINTS], Some([0.25; JOINTS]))
        );
    }

    #[test]
    fn sends_the_skills_increments_and_clamps_only_its_own_targets() {
        let mut c = controller(Box::new(|_| Ok([1.0, -1.0, -0.5, 0.0, 0.0, 0.0, 0.0])));
        c.set_goal(goal());
        c.set_joints(joints(0.98), 0.0);
        let cmd = c.step(0.0);
        assert!(cmd.hold.is_none());
        // The increments are the skill's (velocity limit / rate = 0.05 rad per unit): the
        // holder of the targets clamps them, the node does not second-guess where they are.
        assert_eq!(cmd.increments[..3], [0.05, -0.05, -0.025]);
        // Its own targets (Motion Stack) go through the one rule: joint1 stops at 1.0.
        let targets = cmd.targets.unwrap();
        assert_eq!(targets[0], 1.0);
        assert!((targets[1] - 0.93).abs() < 1e-12);
        // The observation is the shared builder's.
        assert_eq!(
            cmd.observation,
            Some(observation::build(
                &[0.98; 7],
                &[0.0; 7],
                &[0.98; 7],
                &goal(),
                &tool_pose_b,
                &[(-1.0, 1.0); JOINTS],
            ))
        );
        // Targets accumulate while the policy runs ...
        let next = c.step(0.0).targets.unwrap();
        assert!((next[1] - 0.88).abs() < 1e-12);
    }

    #[test]
    fn targets_restart_from_the_measured_angles_after_a_hold() {
        let mut c = controller(Box::new(|_| Ok([-1.0; JOINTS])));
        c.set_goal(goal());
        c.set_joints(joints(0.5), 0.0);
        c.step(0.0);
        assert!((c.step(0.0).targets.unwrap()[0] - 0.4).abs() < 1e-12);
        // Stale: hold, and forget the node's targets.
        assert!(matches!(c.step(1.0).hold, Some(Hold::Stale { .. })));
        c.set_joints(joints(0.2), 1.0);
        assert!((c.step(1.0).targets.unwrap()[0] - 0.15).abs() < 1e-12);
        // A restarted simulator: the state is forgotten, nothing is commanded until a new
        // joint state arrives; the goal is kept.
        c.forget_state();
        assert_eq!(c.step(0.0).hold, Some(Hold::NoJointState));
        assert!(c.goal().is_some());
    }

    #[test]
    fn stale_joint_states_and_policy_failures_hold() {
        let mut c = controller(Box::new(|_| Err("boom".into())));
        c.set_goal(goal());
        c.set_joints(joints(0.0), 1.0);
        assert_eq!(c.step(1.1).hold, Some(Hold::PolicyFailed("boom".into())));
        let stale = c.step(1.5);
        assert!(matches!(stale.hold, Some(Hold::Stale { age_s }) if (age_s - 0.5).abs() < 1e-12));
        assert_eq!(stale.increments, [0.0; JOINTS]);
        assert_eq!(stale.targets, Some([0.0; JOINTS]));
    }
}
