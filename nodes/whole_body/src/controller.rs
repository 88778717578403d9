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
//!
//! **Tipping over.** When the base tilts past the limit the policy was trained with (its
//! episodes ended there: [`kumi_terms::termination`]), the policy has never seen the state
//! and its commands mean nothing. The controller holds from then on, upright again or not,
//! until a new target arrives: an operator decides when to go on.

use kumi_model::RobotModel;
use kumi_policies::observation::Goal;
use kumi_terms::observation::{self, BodyState, ObservationOptions};
use kumi_terms::termination;
use kumi_terms::{ActionTerms, Target, ToolChain, WheelRamp};
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
    /// The base tilted past the limit; held until a new target.
    #[error("tipped over: the base tilted {tilt_rad:.3} rad, past the policy's {limit_rad:.3} rad; send a different target to go on")]
    TippedOver { tilt_rad: f64, limit_rad: f64 },
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
    /// This step found the base tipped over (the hold for it begins).
    pub tipped_over_now: bool,
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
    /// Indices in [`Self::modules`] of the arm modules, in training's order (the terms' arm
    /// terms, then their flat joint terms).
    arm_modules: Vec<usize>,
    policy: PolicyFn,
    target: Option<Target>,
    previous_action: Vec<f32>,
    /// The wheel commands' rate limit, as in training.
    wheel_ramp: WheelRamp,
    last_goals: Option<Vec<(String, Goal)>>,
    /// Tilt [rad] past which the controller stops (none: it never does).
    tilt_limit_rad: Option<f64>,
    /// The tilt [rad] the base tipped over at, while holding for it.
    tipped_rad: Option<f64>,
    /// The optional observation slots the policy was trained with.
    observation: ObservationOptions,
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
        let arm_names = terms.arms().map(|a| &a.module);
        let arm_modules = arm_names
            .chain(terms.joint_terms().map(|j| &j.module))
            .map(|name| {
                modules
                    .iter()
                    .position(|m| m == name)
                    .expect("the terms name their modules")
            })
            .collect();
        Ok(Self {
            previous_action: vec![0.0; terms.size()],
            wheel_ramp: WheelRamp::new(&terms, kumi_model::commands::CONTROL_HZ),
            terms,
            tool,
            joints,
            modules,
            wheel_joints,
            arm_modules,
            policy,
            target: None,
            last_goals: None,
            tilt_limit_rad: None,
            tipped_rad: None,
            observation: ObservationOptions::default(),
        })
    }

    /// Builds the observation with the optional slots `options` (those the policy's
    /// observation description names: [`ObservationOptions::from_description`]).
    pub fn with_observation(mut self, options: ObservationOptions) -> Self {
        self.observation = options;
        self
    }

    /// Stops driving when the base tilts past `limit_rad` (the tilt that ended the policy's
    /// training episodes), until a new target.
    pub fn with_tilt_limit(mut self, limit_rad: f64) -> Self {
        self.tilt_limit_rad = Some(limit_rad);
        self
    }

    pub fn tilt_limit_rad(&self) -> Option<f64> {
        self.tilt_limit_rad
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

    /// A new target; it also ends a hold for having tipped over.
    pub fn set_target(&mut self, target: Target) {
        self.target = Some(target);
        self.rearm();
    }

    /// Ends a hold for having tipped over (a new target, a restarted simulator).
    pub fn rearm(&mut self) {
        self.tipped_rad = None;
    }

    /// A restarted simulator (its time went back): a new episode on the same target, as
    /// training's reset starts one (no hold, the previous action zero, the wheels at rest).
    pub fn start_over(&mut self) {
        self.rearm();
        self.previous_action.iter_mut().for_each(|a| *a = 0.0);
        self.wheel_ramp.stop();
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
        if let Some(limit_rad) = self.tilt_limit_rad {
            let rotation = &state.base.pose_w.rotation;
            let now = self.tipped_rad.is_none() && termination::fallen(rotation, limit_rad);
            if now {
                self.tipped_rad = Some(termination::tilt(rotation));
            }
            if let Some(tilt_rad) = self.tipped_rad {
                let why = Hold::TippedOver {
                    tilt_rad,
                    limit_rad,
                };
                let mut decision = self.hold(why, Some(tool_pose_w));
                decision.tipped_over_now = now;
                return decision;
            }
        }
        let wheels: Vec<f64> = self
            .wheel_joints
            .iter()
            .map(|&(m, j)| state.modules[m].qd[j])
            .collect();
        let arm_angles: Vec<f64> = if self.observation.arm_joint_angles {
            let arms = self.arm_modules.iter();
            arms.flat_map(|&m| state.modules[m].q.iter().copied())
                .collect()
        } else {
            Vec::new()
        };
        let body = BodyState {
            base_pose_w: state.base.pose_w,
            base_linear_velocity_w: state.base.linear_velocity_w,
            base_angular_velocity_w: state.base.angular_velocity_w,
            tool_pose_w,
            target,
            wheel_velocities: &wheels,
            arm_joint_angles: &arm_angles,
            previous_action: &self.previous_action,
        };
        let obs = observation::build(&body, self.observation);
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
        let mut wheel_velocities = commands.wheel_velocities;
        let base = &state.base;
        self.terms.govern(
            &mut wheel_velocities,
            &base.linear_velocity_w,
            &base.angular_velocity_w,
        );
        Decision {
            goals: Some(goals),
            wheel_velocities: self
                .terms
                .wheels()
                .map(|w| w.module.clone())
                .zip(self.wheel_ramp.follow(&wheel_velocities))
                .collect(),
            hold: None,
            tool_pose_w: Some(tool_pose_w),
            observation: Some(obs),
            action: Some(action),
            tipped_over_now: false,
        }
    }

    /// Holds: wheels stop (at once: a ramp's rate limit does not slow a hold), arms keep their
    /// last goals, the previous action starts over. Before the first target nothing is
    /// commanded at all: the bridge holds what it was never told to move, and in lockstep
    /// simulated time stands still until there is a target.
    pub fn hold(&mut self, why: Hold, tool_pose_w: Option<Isometry3<f64>>) -> Decision {
        self.previous_action.iter_mut().for_each(|a| *a = 0.0);
        self.wheel_ramp.stop();
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
            tipped_over_now: false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tick::{BaseState, ModuleState};
    use kumi_model::{assemble, load_morphology, ModuleLibrary};
    use kumi_msgs::builtin_interfaces::Time;
    use kumi_terms::GoalBounds;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    /// Tricycle's controller over a policy that always answers zeros.
    fn tricycle() -> WholeBodyController {
        tricycle_with(None, 0.0)
    }

    /// Tricycle's controller, its wheels ramped at `acceleration_rad_s2`, over a policy that
    /// always answers `answer` for every value.
    fn tricycle_with(acceleration_rad_s2: Option<f64>, answer: f32) -> WholeBodyController {
        tricycle_bounded(
            GoalBounds {
                wheel_acceleration_rad_s2: acceleration_rad_s2,
                ..BOUNDS
            },
            answer,
        )
    }

    /// Tricycle's shipped goal bounds without its turn governor (0.07 m/s^2 in the shipped policy:
    /// train/configs/whole_body/tricycle_sixth.toml), no ramp.
    const BOUNDS: GoalBounds = GoalBounds {
        manipulator_position_m: 0.25,
        manipulator_rotation_rad: 0.5,
        leg_position_m: 0.05,
        leg_roll_rad: 1.5,
        wheel_velocity_rad_s: None,
        wheel_acceleration_rad_s2: None,
        lateral_acceleration_m_s2: None,
    };

    /// Tricycle's controller with `bounds`, over a policy that always answers `answer`.
    fn tricycle_bounded(bounds: GoalBounds, answer: f32) -> WholeBodyController {
        let library = ModuleLibrary::shipped();
        let model = assemble(&load_morphology("tricycle", &library).unwrap(), &library);
        let terms = ActionTerms::new(&model, &bounds).unwrap();
        let size = terms.size();
        let policy: PolicyFn = Box::new(move |_| Ok(vec![answer; size]));
        WholeBodyController::new(&model, terms, policy).unwrap()
    }

    /// Every module at zero joint angles, the base tilted `tilt_rad` about its x axis.
    fn state(controller: &WholeBodyController, tilt_rad: f64) -> Snapshot {
        let modules = (0..controller.modules().len())
            .map(|m| {
                let n = controller.joint_names(m).len();
                ModuleState {
                    q: vec![0.0; n],
                    qd: vec![0.0; n],
                }
            })
            .collect();
        Snapshot {
            stamp: Time::default(),
            base: BaseState {
                pose_w: Isometry3::from_parts(
                    Translation3::new(0.0, 0.0, 1.2),
                    UnitQuaternion::from_axis_angle(&Vector3::x_axis(), tilt_rad),
                ),
                linear_velocity_w: Vector3::zeros(),
                angular_velocity_w: Vector3::zeros(),
            },
            modules,
            synchronous: true,
        }
    }

    fn target(x: f64) -> Target {
        Target {
            position_w: Vector3::new(x, 0.0, 2.2),
            yaw: 0.0,
        }
    }

    #[test]
    fn tipped_over_it_holds_until_a_new_target_even_upright_again() {
        let mut c = tricycle().with_tilt_limit(0.785);
        c.set_target(target(1.0));
        assert!(c.step(&state(&c, 0.7)).action.is_some(), "within the limit");
        let tipped = c.step(&state(&c, 0.9));
        assert!(tipped.tipped_over_now);
        match tipped.hold {
            Some(Hold::TippedOver {
                tilt_rad,
                limit_rad,
            }) => assert!((tilt_rad - 0.9).abs() < 1e-9 && limit_rad == 0.785),
            ref other => panic!("{other:?}"),
        }
        assert!(tipped.action.is_none());
        // Wheels stop; the arms keep the goals they were last sent.
        assert!(tipped.wheel_velocities.iter().all(|(_, v)| *v == 0.0));
        assert_eq!(tipped.wheel_velocities.len(), 3);
        assert!(tipped.goals.is_some());
        // Upright again: still holding, at the tilt it tipped over at, once tipped.
        let still = c.step(&state(&c, 0.0));
        assert_eq!(still.hold, tipped.hold);
        assert!(!still.tipped_over_now);
        // A restarted simulator re-arms it, as a new target does.
        c.rearm();
        assert!(c.step(&state(&c, 0.0)).action.is_some());
        assert!(c.step(&state(&c, 1.0)).tipped_over_now);
        c.set_target(target(2.0));
        assert!(
            c.step(&state(&c, 0.0)).action.is_some(),
            "a new target re-arms it"
        );
        // Without a limit nothing stops it.
        let mut free = tricycle();
        free.set_target(target(1.0));
        assert!(free.step(&state(&free, 1.5)).action.is_some());
        assert_eq!(free.tilt_limit_rad(), None);
    }

    #[test]
    fn ramped_wheels_speed_up_at_the_policys_acceleration_and_stop_at_once_on_a_hold() {
        // 3 rad/s^2 at 30 Hz: 0.1 rad/s more per control step toward full speed, as in training.
        let mut c = tricycle_with(Some(3.0), 1.0).with_tilt_limit(0.785);
        c.set_target(target(1.0));
        let speeds =
            |d: &Decision| -> Vec<f64> { d.wheel_velocities.iter().map(|w| w.1).collect() };
        for step in 1..=3 {
            let d = c.step(&state(&c, 0.0));
            let want = 0.1 * step as f64;
            assert!(speeds(&d).iter().all(|v| (v - want).abs() < 1e-9), "{d:?}");
        }
        // A hold stops the wheels at once; after it the ramp starts again from 0.
        let held = c.step(&state(&c, 1.0));
        assert!(speeds(&held).iter().all(|v| *v == 0.0));
        c.set_target(target(2.0));
        let again = c.step(&state(&c, 0.0));
        assert!(
            speeds(&again).iter().all(|v| (v - 0.1).abs() < 1e-9),
            "{again:?}"
        );
        // Unramped, the policy's velocity is commanded at once.
        let mut free = tricycle_with(None, 1.0);
        free.set_target(target(1.0));
        let d = free.step(&state(&free, 0.0));
        assert!(speeds(&d).iter().all(|v| *v == 5.0), "{d:?}");
    }

    #[test]
    fn a_turn_governor_scales_the_wheels_by_the_odometrys_speed_and_yaw_rate() {
        // 0.5 m/s at 0.4 rad/s is 0.2 m/s^2; the governor allows 0.1: half speed.
        let governed = GoalBounds {
            lateral_acceleration_m_s2: Some(0.1),
            ..BOUNDS
        };
        let mut c = tricycle_bounded(governed, 1.0);
        c.set_target(target(1.0));
        let moving = |c: &WholeBodyController, v: [f64; 2], w_z: f64| {
            let mut s = state(c, 0.0);
            s.base.linear_velocity_w = Vector3::new(v[0], v[1], 0.0);
            s.base.angular_velocity_w = Vector3::new(0.0, 0.0, w_z);
            s
        };
        let speeds =
            |d: &Decision| -> Vec<f64> { d.wheel_velocities.iter().map(|w| w.1).collect() };
        let d = c.step(&moving(&c, [0.3, -0.4], -0.4));
        assert!(speeds(&d).iter().all(|v| (v - 2.5).abs() < 1e-9), "{d:?}");
        // Turning in place, or driving straight, is not governed.
        let d = c.step(&moving(&c, [0.0, 0.0], 2.0));
        assert!(speeds(&d).iter().all(|v| *v == 5.0), "{d:?}");
        let d = c.step(&moving(&c, [1.0, 0.0], 0.0));
        assert!(speeds(&d).iter().all(|v| *v == 5.0), "{d:?}");
    }

    #[test]
    fn the_optional_angular_velocity_slot_comes_last_in_the_base_frame() {
        let mut plain = tricycle();
        let spinning = ObservationOptions {
            base_angular_velocity: true,
            ..Default::default()
        };
        let mut with = tricycle().with_observation(spinning);
        plain.set_target(target(1.0));
        with.set_target(target(1.0));
        // The base rolled 0.3 rad about its x axis, turning about world z at 1 rad/s: in the
        // base frame that is (0, sin 0.3, cos 0.3) rad/s.
        let mut s = state(&with, 0.3);
        s.base.angular_velocity_w = Vector3::new(0.0, 0.0, 1.0);
        let a = plain.step(&s).observation.unwrap();
        let b = with.step(&s).observation.unwrap();
        assert_eq!(b.len(), a.len() + 3);
        assert_eq!(b[..a.len()], a[..]);
        let expected = [0.0, 0.3_f64.sin() as f32, 0.3_f64.cos() as f32];
        for (o, e) in b[a.len()..].iter().zip(expected) {
            assert!((o - e).abs() < 1e-6, "{b:?}");
        }
    }

    #[test]
    fn the_optional_joint_angle_slot_holds_every_arm_modules_angles_in_training_order() {
        let angles = ObservationOptions {
            arm_joint_angles: true,
            ..Default::default()
        };
        let mut plain = tricycle();
        let mut with = tricycle().with_observation(angles);
        plain.set_target(target(1.0));
        with.set_target(target(1.0));
        // Each joint's angle names its module and joint: module m, joint j at m + j / 10.
        let mut s = state(&with, 0.0);
        for (m, module) in s.modules.iter_mut().enumerate() {
            for (j, q) in module.q.iter_mut().enumerate() {
                *q = m as f64 + j as f64 / 10.0;
            }
        }
        let a = plain.step(&s).observation.unwrap();
        let b = with.step(&s).observation.unwrap();
        assert_eq!(b[..a.len()], a[..]);
        let terms = with.terms();
        let expected: Vec<f32> = terms
            .arms()
            .flat_map(|arm| {
                let m = with
                    .modules()
                    .iter()
                    .position(|n| *n == arm.module)
                    .unwrap();
                s.modules[m].q.iter().map(|q| *q as f32)
            })
            .collect();
        assert_eq!(expected.len(), 4 * 7, "Tricycle has four arm modules");
        assert_eq!(b[a.len()..], expected[..]);
    }
}
