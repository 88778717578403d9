//! The world interface: one robot on flat ground, driven at the control rate.

use std::any::Any;
use std::ops::Range;
use std::sync::Arc;

use kumi_model::kinematics::KinematicTree;
use kumi_model::{ActuatorMode, RobotModel};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use crate::config::SimConfig;
use crate::engine::Engine;
use crate::error::SimError;
use crate::servos::ServoBank;
use kumi_model::commands::apply_increments;

/// A load on a link ([`SimWorld::set_link_load`]): a constant force plus a spring pulling the
/// link frame's origin toward an anchor, as the ground holds a leg's tip or a hand holds a tool.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Load {
    /// The constant part [N], world frame.
    pub force_w: Vector3<f64>,
    /// Where the spring pulls [m], world frame.
    pub anchor_w: Vector3<f64>,
    /// The spring's stiffness [N/m]; 0 for no spring.
    pub stiffness_n_m: f64,
}

impl Load {
    /// No load.
    pub const NONE: Self = Self {
        force_w: Vector3::new(0.0, 0.0, 0.0),
        anchor_w: Vector3::new(0.0, 0.0, 0.0),
        stiffness_n_m: 0.0,
    };

    /// A constant force [N], world frame.
    pub fn constant(force_w: Vector3<f64>) -> Self {
        Self {
            force_w,
            ..Self::NONE
        }
    }

    /// The force [N] on the link when its frame's origin is at `point_w` [m].
    pub fn force_at(&self, point_w: &Vector3<f64>) -> Vector3<f64> {
        self.force_w + self.stiffness_n_m * (self.anchor_w - point_w)
    }
}

/// A load on one link of a world, as the engines keep it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LinkLoad {
    /// The link's index in the kinematic tree.
    pub link: usize,
    pub load: Load,
}

impl LinkLoad {
    /// The load [`SimWorld::set_link_load`] asks for in a world whose links are `tree`'s:
    /// `None` for no load, an error for an unknown link, a non-finite value or a negative
    /// stiffness.
    pub fn checked(
        tree: &KinematicTree,
        link: &str,
        load: &Load,
    ) -> Result<Option<Self>, SimError> {
        let index = tree
            .link_index(link)
            .ok_or_else(|| SimError::UnknownLink(link.to_string()))?;
        let finite = load
            .force_w
            .iter()
            .chain(load.anchor_w.iter())
            .all(|x| x.is_finite());
        if !(finite && load.stiffness_n_m.is_finite() && load.stiffness_n_m >= 0.0) {
            return Err(SimError::BadLoad {
                link: link.to_string(),
                load: format!("{load:?}"),
            });
        }
        let none = load.force_w == Vector3::zeros() && load.stiffness_n_m == 0.0;
        Ok((!none).then_some(Self {
            link: index,
            load: *load,
        }))
    }
}

/// A joint configuration and base pose to place the robot at.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotState {
    /// Base link pose in the world [m, unit quaternion]. Ignored for fixed-base robots, whose
    /// base stays at the world origin.
    pub base_pose_w: Isometry3<f64>,
    /// One position per actuator [rad], in [`SimWorld::actuator_names`] order (wheel angles too).
    pub joint_positions: Vec<f64>,
}

/// A contact between two parts of the scene.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct Contact {
    /// URDF link name, or `ground`.
    pub a: String,
    /// URDF link name, or `ground`.
    pub b: String,
}

impl Contact {
    /// The pair in canonical order (`a <= b`).
    pub fn new(a: String, b: String) -> Self {
        if a <= b {
            Self { a, b }
        } else {
            Self { a: b, b: a }
        }
    }
}

/// The name contacts use for the ground.
pub const GROUND: &str = "ground";

/// Everything an engine needs to restore a world exactly as it was; opaque outside the engine
/// that took it. Cheap to clone.
#[derive(Clone)]
pub struct Snapshot(Arc<dyn Any + Send + Sync>);

impl Snapshot {
    pub fn new<T: Any + Send + Sync>(state: T) -> Self {
        Self(Arc::new(state))
    }

    /// The engine's own state, or [`SimError::ForeignSnapshot`] if another engine took it.
    pub fn downcast<T: Any>(&self) -> Result<&T, SimError> {
        self.0.downcast_ref().ok_or(SimError::ForeignSnapshot)
    }
}

/// The home joint positions of `model`, one per actuator: each arm at its module's home pose,
/// wheels at zero.
pub fn home_joint_positions(model: &RobotModel) -> Vec<f64> {
    model
        .modules
        .iter()
        .flat_map(|m| {
            let mut home = m.home.iter().copied();
            m.actuators
                .iter()
                .map(move |a| match a.mode {
                    ActuatorMode::Position => home.next().unwrap_or(0.0),
                    ActuatorMode::Velocity => 0.0,
                })
                .collect::<Vec<_>>()
        })
        .collect()
}

/// One robot in a physics engine: commands in, one control step at a time, state out.
///
/// Per-joint vectors are in actuator order ([`SimWorld::actuator_names`]). Arm joints are
/// position servos (PD with effort limit and a set-point slewed at the velocity limit), wheels
/// velocity servos; both engines run the law of [`ServoBank`]. Same seed and commands give
/// bit-identical trajectories within one engine.
pub trait SimWorld: Send {
    fn engine(&self) -> Engine;
    fn model(&self) -> &Arc<RobotModel>;
    fn config(&self) -> &SimConfig;
    fn servos(&self) -> &ServoBank;
    fn servos_mut(&mut self) -> &mut ServoBank;
    /// Simulated time since the last reset [s].
    fn time(&self) -> f64;

    /// The lowest point [m] of any robot collider with the robot placed at `base_pose_w` and
    /// `joint_positions` (one per actuator), computed without moving the robot.
    fn lowest_point(&self, base_pose_w: &Isometry3<f64>, joint_positions: &[f64]) -> f64;
    /// Places the robot at `state`, at rest, with every servo holding that configuration and
    /// every wheel braked; clears contacts and time. A reset world follows the same trajectory
    /// as a freshly built one.
    fn reset(&mut self, state: &RobotState);
    /// A copy of the full physics state.
    fn snapshot(&self) -> Snapshot;
    /// Restores a snapshot taken from this world: the trajectory from here on is bit-identical
    /// to the one that followed the snapshot.
    fn restore(&mut self, snapshot: &Snapshot) -> Result<(), SimError>;
    /// Advances one control step (`substeps` physics steps).
    fn step(&mut self);
    /// Shoves the robot as one rigid body: its base link's origin gains `delta_v_w` [m/s] and
    /// the whole robot the angular velocity `delta_w_w` [rad/s] about that origin (both in the
    /// world frame), every link at once, joint velocities unchanged (the push of legged_gym's and
    /// Isaac Lab's `push_by_setting_velocity`, done in place). The robot's servos and the ground
    /// take it from there. Fixed-base robots do not move.
    fn push(&mut self, delta_v_w: &Vector3<f64>, delta_w_w: &Vector3<f64>);
    /// Puts a load ([`Load`]) on `link`, applied at its frame's origin at every physics step
    /// from the next one until it is changed: what the rest of a robot or the ground puts on a
    /// module's tool, for training a skill under load. One link at a time (a new call replaces
    /// the previous load); [`Load::NONE`] or a reset removes it; snapshots do not carry it. A
    /// bad load is refused and the load stays as it was.
    fn set_link_load(&mut self, link: &str, load: &Load) -> Result<(), SimError>;

    /// Joint positions [rad], in actuator order.
    fn joint_positions(&self) -> Vec<f64>;
    /// Joint velocities [rad/s], in actuator order.
    fn joint_velocities(&self) -> Vec<f64>;
    /// The world pose of any URDF link (the `ee` tool frames included).
    fn link_pose(&self, link: &str) -> Result<Isometry3<f64>, SimError>;
    /// The base link's pose in the world.
    fn base_pose(&self) -> Isometry3<f64>;
    /// The base's linear [m/s] (of its centre of mass) and angular [rad/s] velocity, both in
    /// the world frame.
    fn base_twist_w(&self) -> (Vector3<f64>, Vector3<f64>);
    /// Every pair of touching links (or [`GROUND`]), sorted and deduplicated.
    fn contacts(&self) -> Vec<Contact>;
    /// The lowest point [m] of any robot collider now (negative: sunk into the ground).
    fn lowest_collider_z(&self) -> f64;
    /// For each mounted module, how far its root link has moved from where its mount puts it:
    /// `(module, translation error [m], rotation error [rad])`.
    fn mount_errors(&self) -> Vec<(String, f64, f64)>;
    /// The world pose of every URDF link frame, in URDF link order.
    fn body_poses(&self) -> Vec<(String, Isometry3<f64>)>;

    /// Whether the physics blew up since the last reset (a restored snapshot brings back its
    /// world's answer): after a control step ended in a state past [`crate::blown_up`]'s
    /// bounds, in either engine, or, in MuJoCo, after MuJoCo found non-finite or huge
    /// positions, velocities or accelerations and restarted itself from its initial state. A
    /// diverged world's state means nothing until the next reset.
    fn diverged(&self) -> bool;

    /// Whether the state now is past [`crate::blown_up`]'s bounds: what each engine checks
    /// after every control step to set [`SimWorld::diverged`].
    fn state_blown_up(&self) -> bool {
        let (linear, angular) = self.base_twist_w();
        crate::blown_up(
            &self.joint_velocities(),
            &self.base_pose().translation.vector,
            &linear,
            &angular,
        )
    }

    /// Actuated joint names, in the order of every per-joint vector of this API.
    fn actuator_names(&self) -> Vec<&str> {
        self.servos()
            .actuators()
            .iter()
            .map(|a| a.joint.as_str())
            .collect()
    }

    /// The actuator index range of a module.
    fn module_range(&self, module: &str) -> Result<Range<usize>, SimError> {
        self.servos().module_range(module)
    }

    /// A configuration with the base at (`x`, `y`) [m] and heading `yaw` [rad], lifted so that
    /// the lowest collider just touches the ground (fixed-base robots: base at the origin).
    fn standing_state(&self, x: f64, y: f64, yaw: f64, joint_positions: Vec<f64>) -> RobotState {
        let level = Isometry3::from_parts(
            Translation3::new(x, y, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
        );
        let lift = if self.model().fixed_base {
            0.0
        } else {
            -self.lowest_point(&level, &joint_positions)
        };
        RobotState {
            base_pose_w: Translation3::new(0.0, 0.0, lift) * level,
            joint_positions,
        }
    }

    /// The home configuration, standing on the ground at the world origin.
    fn home_state(&self) -> RobotState {
        self.standing_state(0.0, 0.0, 0.0, home_joint_positions(self.model()))
    }

    /// Commands position targets [rad] for a module's position joints (an arm's 7 joints, in
    /// order). Targets are clamped to the joint ranges; the servo set-point slews toward them
    /// at the joint velocity limit. A non-finite value rejects the whole command.
    fn set_position_targets(&mut self, module: &str, targets: &[f64]) -> Result<(), SimError> {
        self.servos_mut()
            .set(module, ActuatorMode::Position, targets)
    }

    /// Moves a module's position targets by `increments` [rad] through the one increment rule
    /// ([`apply_increments`]): each target clamped to its joint's range.
    fn apply_increments(&mut self, module: &str, increments: &[f64]) -> Result<(), SimError> {
        if let Some(&value) = increments.iter().find(|d| !d.is_finite()) {
            return Err(SimError::NonFinite {
                module: module.to_string(),
                value,
            });
        }
        let range = self.module_range(module)?;
        let servos = self.servos();
        let joints: Vec<_> = servos.actuators()[range.clone()]
            .iter()
            .filter(|a| a.mode == ActuatorMode::Position)
            .collect();
        let targets: Vec<f64> = range
            .filter(|&i| servos.actuators()[i].mode == ActuatorMode::Position)
            .map(|i| servos.states()[i].command)
            .collect();
        let moved = apply_increments(&targets, increments, &joints).ok_or_else(|| {
            SimError::LengthMismatch {
                module: module.to_string(),
                expected: targets.len(),
                got: increments.len(),
            }
        })?;
        self.set_position_targets(module, &moved)
    }

    /// Commands one wheel velocity [rad/s] for both wheels of a wheel module, clamped to the
    /// velocity limit. Positive drives the base along its +x axis with every module at home,
    /// however the module is mounted ([`kumi_model::RobotModel::wheel_drive_sign`]); the joint
    /// commands carry that sign.
    fn set_wheel_velocity(&mut self, module: &str, velocity: f64) -> Result<(), SimError> {
        let n = self.servos().velocity_joints(module)?;
        let sign = self.servos().drive_sign(module)?;
        self.servos_mut()
            .set(module, ActuatorMode::Velocity, &vec![sign * velocity; n])
    }

    /// The current commands, in actuator order: position targets [rad] or velocities [rad/s].
    fn commands(&self) -> Vec<f64> {
        self.servos().commands()
    }

    /// Tilt of the base [rad]: the angle between its z axis and the world's.
    fn base_tilt(&self) -> f64 {
        let z = self.base_pose().rotation * Vector3::z();
        z.z.clamp(-1.0, 1.0).acos()
    }

    /// Links that touch the ground now, sorted, each once: [`Self::contacts`] is sorted and
    /// deduplicated by pair, and a pair's links are in order, so the links named before
    /// [`GROUND`] come first, in order, then those named after it.
    fn ground_contacts(&self) -> Vec<String> {
        self.contacts()
            .into_iter()
            .filter_map(|c| match (c.a.as_str(), c.b.as_str()) {
                (GROUND, other) | (other, GROUND) => Some(other.to_string()),
                _ => None,
            })
            .collect()
    }

    /// The wheel modules (modules with velocity joints) none of whose links touches the ground
    /// now. Ground links are named `module/link` ([`Self::ground_contacts`]).
    fn wheel_modules_off_ground(&self) -> usize {
        let down = self.ground_contacts();
        self.model()
            .modules
            .iter()
            .filter(|m| m.velocity_joints().next().is_some())
            .filter(|m| {
                !down
                    .iter()
                    .any(|l| kumi_model::unprefixed(&m.name, l).is_some())
            })
            .count()
    }
}
