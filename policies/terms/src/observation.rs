//! The whole-body observation (the paper's Table III): base linear velocity, projected
//! gravity, the tool-to-target position and yaw error, the wheels' angular velocities and the
//! previous action. Every slot is named with its size, unit and frame; values are rounded to
//! f32 here, once, for training and deployment alike.

use std::f64::consts::PI;

use kumi_model::kinematics::KinematicTree;
use kumi_model::{RobotModel, Role};
use nalgebra::{Isometry3, UnitQuaternion, Vector3};

/// One named part of the observation.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ObservationSlot {
    pub name: &'static str,
    pub size: usize,
    pub unit: &'static str,
    pub frame: &'static str,
}

/// The name of the optional base angular velocity slot ([`ObservationOptions`]).
pub const BASE_ANGULAR_VELOCITY: &str = "base_angular_velocity";

/// The name of the optional arm joint angle slot ([`ObservationOptions`]).
pub const ARM_JOINT_ANGLES: &str = "arm_joint_angles";

/// The optional slots' names, each a field of [`ObservationOptions`].
pub const OPTIONAL_SLOTS: [&str; 2] = [BASE_ANGULAR_VELOCITY, ARM_JOINT_ANGLES];

/// Slots a policy may observe beyond Table III (`[observation]` in a whole-body config; none
/// by default). A policy file names them in its observation description, so whoever runs it
/// reads them from there ([`ObservationOptions::from_description`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct ObservationOptions {
    /// The base's angular velocity [rad/s] in the base frame, after the previous action: how
    /// fast the base tips and turns, which projected gravity shows only as an angle.
    #[serde(default)]
    pub base_angular_velocity: bool,
    /// Every arm module's joint angles [rad] (module by module in the action terms' order,
    /// each in actuator order), after the base angular velocity: where the legs stand, which
    /// the previous action shows only as the goals they were sent.
    #[serde(default)]
    pub arm_joint_angles: bool,
}

impl ObservationOptions {
    /// True when no optional slot is on (Table III as it is).
    pub fn is_none(&self) -> bool {
        *self == Self::default()
    }

    /// The options a policy's observation description ([`describe`]) was built with.
    pub fn from_description(description: &str) -> Self {
        let has = |name: &str| {
            description
                .split(';')
                .any(|slot| slot.split(':').next() == Some(name))
        };
        Self {
            base_angular_velocity: has(BASE_ANGULAR_VELOCITY),
            arm_joint_angles: has(ARM_JOINT_ANGLES),
        }
    }
}

/// The slots, in order, for a robot with `wheels` wheel joints and `arm_joints` arm joints
/// (all arm modules together), an action of `action_size` and the optional slots `options`.
pub fn slots(
    wheels: usize,
    arm_joints: usize,
    action_size: usize,
    options: ObservationOptions,
) -> Vec<ObservationSlot> {
    let slot = |name, size, unit, frame| ObservationSlot {
        name,
        size,
        unit,
        frame,
    };
    let mut slots = vec![
        slot("base_linear_velocity", 3, "m/s", "base"),
        slot("projected_gravity", 3, "1", "base"),
        slot("tool_to_target", 3, "m", "base"),
        slot("target_yaw_error", 1, "rad", "world z"),
        slot("wheel_velocities", wheels, "rad/s", "joint"),
        slot("previous_action", action_size, "1", "policy"),
    ];
    if options.base_angular_velocity {
        slots.push(slot(BASE_ANGULAR_VELOCITY, 3, "rad/s", "base"));
    }
    if options.arm_joint_angles {
        slots.push(slot(ARM_JOINT_ANGLES, arm_joints, "rad", "joint"));
    }
    slots
}

/// The flat baseline's slots (the paper's section V-C): the upper-level `slots` followed by every arm
/// module's low-level state, `arm_joints` joint angles and as many velocities (none: the
/// slots unchanged).
pub fn with_arm_state(mut slots: Vec<ObservationSlot>, arm_joints: usize) -> Vec<ObservationSlot> {
    if arm_joints > 0 {
        slots.push(ObservationSlot {
            name: "arm_joint_positions",
            size: arm_joints,
            unit: "rad",
            frame: "joint",
        });
        slots.push(ObservationSlot {
            name: "arm_joint_velocities",
            size: arm_joints,
            unit: "rad/s",
            frame: "joint",
        });
    }
    slots
}

/// Appends the arm modules' joint angles [rad] and velocities [rad/s] to an observation, in
/// the slots of [`with_arm_state`].
pub fn push_arm_state(obs: &mut Vec<f32>, positions: &[f64], velocities: &[f64]) {
    obs.extend(positions.iter().map(|v| *v as f32));
    obs.extend(velocities.iter().map(|v| *v as f32));
}

/// Total length of an observation with these slots.
pub fn size(slots: &[ObservationSlot]) -> usize {
    slots.iter().map(|s| s.size).sum()
}

/// The slots in one line, for a policy's metadata: `name:size:unit:frame` joined by `;`.
pub fn describe(slots: &[ObservationSlot]) -> String {
    slots
        .iter()
        .map(|s| format!("{}:{}:{}:{}", s.name, s.size, s.unit, s.frame))
        .collect::<Vec<_>>()
        .join(";")
}

/// Where the manipulator's tool should go: a position and a heading in the world (odometry)
/// frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// [m], world frame.
    pub position_w: Vector3<f64>,
    /// Heading of the tool's x axis about the world z axis [rad].
    pub yaw: f64,
}

/// An angle wrapped into [-pi, pi).
pub fn wrap_angle(a: f64) -> f64 {
    (a + PI).rem_euclid(2.0 * PI) - PI
}

/// The heading [rad] of a tool frame: the angle of its x axis, projected on the world's
/// horizontal plane, about the world z axis.
pub fn tool_yaw(rotation_w: &UnitQuaternion<f64>) -> f64 {
    let x = rotation_w * Vector3::x();
    x.y.atan2(x.x)
}

/// The target's yaw minus the tool's, wrapped into [-pi, pi).
pub fn yaw_error(tool_w: &Isometry3<f64>, target: &Target) -> f64 {
    wrap_angle(target.yaw - tool_yaw(&tool_w.rotation))
}

/// The task's errors: tool position error [m] and absolute yaw error [rad].
pub fn target_errors(tool_w: &Isometry3<f64>, target: &Target) -> (f64, f64) {
    (
        (target.position_w - tool_w.translation.vector).norm(),
        yaw_error(tool_w, target).abs(),
    )
}

/// The manipulator's tool pose as a robot can measure it: forward kinematics of its joint
/// angles from the base pose. Training and the whole-body node both observe it this way (a
/// simulator's own link pose can differ by its joint constraints' error: micrometres in
/// rapier).
#[derive(Debug, Clone)]
pub struct ToolChain {
    tree: KinematicTree,
    tool_link: usize,
}

impl ToolChain {
    /// The chain to `model`'s manipulator's tool.
    pub fn new(model: &RobotModel) -> Result<Self, String> {
        let tree = KinematicTree::new(&model.urdf).map_err(|e| e.to_string())?;
        let manipulator = model
            .modules_with_role(Role::Manipulator)
            .next()
            .ok_or_else(|| format!("robot `{}` has no manipulator", model.name))?;
        let tool = manipulator
            .ee_link
            .as_ref()
            .ok_or_else(|| format!("manipulator `{}` has no tool link", manipulator.name))?;
        let tool_link = tree
            .link_index(tool)
            .ok_or_else(|| format!("tool link `{tool}` is not in the URDF"))?;
        Ok(Self { tree, tool_link })
    }

    /// The tool pose in the base pose's frame, for joint positions by URDF joint name (joints
    /// not named are at 0).
    pub fn tool_pose_w<'a>(
        &self,
        base_pose_w: &Isometry3<f64>,
        joints: impl IntoIterator<Item = (&'a str, f64)>,
    ) -> Isometry3<f64> {
        let q = self.tree.positions(joints);
        self.tree.forward(base_pose_w, &q)[self.tool_link]
    }
}

/// What the observation is built from.
#[derive(Debug, Clone, Copy)]
pub struct BodyState<'a> {
    /// The base link's pose in the world.
    pub base_pose_w: Isometry3<f64>,
    /// The base's linear velocity [m/s] in the world frame.
    pub base_linear_velocity_w: Vector3<f64>,
    /// The base's angular velocity [rad/s] in the world frame (observed only with
    /// [`ObservationOptions::base_angular_velocity`]).
    pub base_angular_velocity_w: Vector3<f64>,
    /// The manipulator's tool pose in the world.
    pub tool_pose_w: Isometry3<f64>,
    pub target: Target,
    /// Every wheel's angular velocity [rad/s], wheel modules in morphology order, each
    /// module's wheels in actuator order.
    pub wheel_velocities: &'a [f64],
    /// Every arm module's joint angles [rad], as [`ObservationOptions::arm_joint_angles`]
    /// orders them (observed only with that option).
    pub arm_joint_angles: &'a [f64],
    /// The action of the previous control step (zeros after a reset), as the policy output it
    /// (unclipped).
    pub previous_action: &'a [f32],
}

/// Builds the observation, slot by slot as [`slots`] lists them for `options`.
pub fn build(state: &BodyState, options: ObservationOptions) -> Vec<f32> {
    let to_base = state.base_pose_w.rotation.inverse();
    let velocity_b = to_base * state.base_linear_velocity_w;
    let gravity_b = to_base * -Vector3::z();
    let to_target_b = to_base * (state.target.position_w - state.tool_pose_w.translation.vector);
    let mut obs =
        Vec::with_capacity(13 + state.wheel_velocities.len() + state.previous_action.len());
    obs.extend(velocity_b.iter().map(|v| *v as f32));
    obs.extend(gravity_b.iter().map(|v| *v as f32));
    obs.extend(to_target_b.iter().map(|v| *v as f32));
    obs.push(yaw_error(&state.tool_pose_w, &state.target) as f32);
    obs.extend(state.wheel_velocities.iter().map(|v| *v as f32));
    obs.extend_from_slice(state.previous_action);
    if options.base_angular_velocity {
        let angular_b = to_base * state.base_angular_velocity_w;
        obs.extend(angular_b.iter().map(|v| *v as f32));
    }
    if options.arm_joint_angles {
        obs.extend(state.arm_joint_angles.iter().map(|v| *v as f32));
    }
    obs
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Translation3;

    #[test]
    fn angles_wrap_into_minus_pi_to_pi() {
        assert!((wrap_angle(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
        assert!((wrap_angle(-3.0 * PI / 2.0) - PI / 2.0).abs() < 1e-12);
        assert_eq!(wrap_angle(0.25), 0.25);
        assert!((wrap_angle(PI) + PI).abs() < 1e-12);
    }

    #[test]
    fn observation_by_hand() {
        // Base turned 90 degrees about z, moving along world +x at 1 m/s: in the base frame
        // that is -y. The tool sits 1 m above the base origin facing world +y (yaw pi/2); the
        // target is 2 m along world +x at yaw 0.
        let yaw90 = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), PI / 2.0);
        let base = Isometry3::from_parts(Translation3::new(0.0, 0.0, 0.5), yaw90);
        let tool = Isometry3::from_parts(Translation3::new(0.0, 0.0, 1.5), yaw90);
        let target = Target {
            position_w: Vector3::new(2.0, 0.0, 1.5),
            yaw: 0.0,
        };
        let state = BodyState {
            base_pose_w: base,
            base_linear_velocity_w: Vector3::new(1.0, 0.0, 0.0),
            base_angular_velocity_w: Vector3::new(0.5, 0.0, 2.0),
            tool_pose_w: tool,
            target,
            wheel_velocities: &[3.0, -3.0],
            arm_joint_angles: &[0.25, -0.5, 1.0],
            previous_action: &[0.5, -1.5],
        };
        let obs = build(&state, ObservationOptions::default());
        let expected = [
            0.0,
            -1.0,
            0.0, // velocity in the base frame
            0.0,
            0.0,
            -1.0, // gravity
            0.0,
            -2.0,
            0.0,              // target 2 m along world x is along base -y
            -PI as f32 / 2.0, // turn right by 90 degrees
            3.0,
            -3.0,
            0.5,
            -1.5,
        ];
        assert_eq!(obs.len(), expected.len());
        for (o, e) in obs.iter().zip(expected) {
            assert!((o - e).abs() < 1e-6, "{obs:?}");
        }
        assert_eq!(
            size(&slots(2, 3, 2, ObservationOptions::default())),
            obs.len()
        );
        let (distance, yaw) = target_errors(&tool, &target);
        assert!((distance - 2.0).abs() < 1e-12 && (yaw - PI / 2.0).abs() < 1e-12);

        // The same state, observing the base's angular velocity: the base's x axis is world
        // y and its y axis world -x, so world (0.5, 0, 2) rad/s is base (0, -0.5, 2).
        let with = ObservationOptions {
            base_angular_velocity: true,
            ..Default::default()
        };
        let obs_w = build(&state, with);
        assert_eq!(
            obs_w[..obs.len()],
            obs[..],
            "the Table III slots come first, unchanged"
        );
        let angular = &obs_w[obs.len()..];
        assert_eq!(angular.len(), 3);
        for (o, e) in angular.iter().zip([0.0, -0.5, 2.0]) {
            assert!((o - e).abs() < 1e-6, "{angular:?}");
        }
        assert_eq!(size(&slots(2, 3, 2, with)), obs_w.len());

        // And the arm joint angles after it, as they were given (f32).
        let both = ObservationOptions {
            base_angular_velocity: true,
            arm_joint_angles: true,
        };
        let obs_b = build(&state, both);
        assert_eq!(obs_b[..obs_w.len()], obs_w[..]);
        assert_eq!(obs_b[obs_w.len()..], [0.25, -0.5, 1.0]);
        assert_eq!(size(&slots(2, 3, 2, both)), obs_b.len());
        let angles_only = ObservationOptions {
            arm_joint_angles: true,
            ..Default::default()
        };
        let obs_a = build(&state, angles_only);
        assert_eq!(obs_a[..obs.len()], obs[..]);
        assert_eq!(obs_a[obs.len()..], [0.25, -0.5, 1.0]);
    }

    #[test]
    fn options_read_back_from_the_description() {
        let with = ObservationOptions {
            base_angular_velocity: true,
            ..Default::default()
        };
        let angles = ObservationOptions {
            arm_joint_angles: true,
            ..Default::default()
        };
        let both = ObservationOptions {
            base_angular_velocity: true,
            arm_joint_angles: true,
        };
        for options in [ObservationOptions::default(), with, angles, both] {
            let text = describe(&slots(6, 28, 18, options));
            assert_eq!(
                ObservationOptions::from_description(&text),
                options,
                "{text}"
            );
        }
        assert!(!with.is_none() && ObservationOptions::default().is_none());
        let near_miss = "base_angular_velocity_x:3:rad/s:base;arm_joint_positions:28:rad:joint";
        assert!(ObservationOptions::from_description(near_miss).is_none());
    }

    #[test]
    fn slots_describe_themselves() {
        let text = describe(&slots(6, 28, 18, ObservationOptions::default()));
        assert!(
            text.starts_with("base_linear_velocity:3:m/s:base;"),
            "{text}"
        );
        assert!(text.ends_with("wheel_velocities:6:rad/s:joint;previous_action:18:1:policy"));
        assert_eq!(
            size(&slots(6, 28, 18, ObservationOptions::default())),
            10 + 6 + 18
        );
    }
}
