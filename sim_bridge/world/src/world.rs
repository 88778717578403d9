//! The simulated robot: commands in, physics stepped at the control rate, state out.

use std::sync::Arc;

use kumi_model::kinematics::KinematicTree;
use kumi_model::{Actuator, ActuatorMode, RobotModel};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use rapier3d::prelude::*;

use crate::actuator::{clamp_command, integrate_velocity_setpoint, max_lead, slew, ServoState};
use crate::config::SimConfig;
use crate::convert::{to_na_isometry, to_na_vector, to_rapier_pose};
use crate::error::SimError;
use crate::spawn::{link_pose, place_body, spawn, ArticulatedJoint, LinkBody};

/// A joint configuration and base pose to place the robot at.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotState {
    /// Base link pose in the world [m, unit quaternion]. Ignored for fixed-base robots, whose
    /// base stays at the world origin.
    pub base_pose_w: Isometry3<f64>,
    /// One position per actuator [rad], in [`World::actuator_names`] order (wheel angles too).
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

/// The name contacts use for the ground.
pub const GROUND: &str = "ground";

/// Everything needed to restore the physics exactly as it was.
#[derive(Clone)]
pub struct Snapshot {
    islands: IslandManager,
    broad_phase: BroadPhaseBvh,
    narrow_phase: NarrowPhase,
    bodies: RigidBodySet,
    colliders: ColliderSet,
    impulse_joints: ImpulseJointSet,
    multibody_joints: MultibodyJointSet,
    ccd_solver: CCDSolver,
    servos: Vec<ServoState>,
    time_s: f64,
}

impl Snapshot {
    fn capture(physics: &PhysicsWorld, servos: &[ServoState], time_s: f64) -> Self {
        Self {
            islands: physics.islands.clone(),
            broad_phase: physics.broad_phase.clone(),
            narrow_phase: physics.narrow_phase.clone(),
            bodies: physics.bodies.clone(),
            colliders: physics.colliders.clone(),
            impulse_joints: physics.impulse_joints.clone(),
            multibody_joints: physics.multibody_joints.clone(),
            ccd_solver: physics.ccd_solver.clone(),
            servos: servos.to_vec(),
            time_s,
        }
    }
}

/// One robot in a rapier world with a ground plane and gravity along -z.
pub struct World {
    model: Arc<RobotModel>,
    config: SimConfig,
    tree: KinematicTree,
    physics: PhysicsWorld,
    links: Vec<LinkBody>,
    joints: Vec<ArticulatedJoint>,
    /// Every actuator, in the order of the per-joint vectors of this API.
    actuators: Vec<Actuator>,
    servos: Vec<ServoState>,
    /// First actuator index of each module, and one past the last.
    module_actuators: Vec<std::ops::Range<usize>>,
    multibody_roots: Vec<RigidBodyHandle>,
    collider_links: std::collections::HashMap<ColliderHandle, usize>,
    ground: ColliderHandle,
    base_link: usize,
    /// The physics as built, before the robot was placed: every reset starts from it, so a
    /// reset world and a freshly built one follow bit-identical trajectories.
    pristine: Snapshot,
    time_s: f64,
}

impl World {
    /// Builds the world and places the robot at its home configuration, standing on the ground
    /// at the origin (fixed-base robots: base at the origin).
    pub fn new(model: Arc<RobotModel>, config: SimConfig) -> Result<Self, SimError> {
        if !(config.control_hz > 0.0 && config.substeps > 0 && config.solver_iterations > 0) {
            return Err(SimError::BadConfig(format!(
                "control rate, substeps and solver iterations must be positive: {config:?}"
            )));
        }
        let tree = KinematicTree::new(&model.urdf).map_err(|source| SimError::Tree {
            robot: model.name.clone(),
            source,
        })?;
        let mut physics = PhysicsWorld::new();
        physics.gravity = Vector::new(0.0, 0.0, -9.81);
        physics.integration_parameters.dt = config.dt() as f32;
        physics.integration_parameters.num_solver_iterations = config.solver_iterations as usize;
        physics
            .integration_parameters
            .num_internal_stabilization_iterations = config.stabilization_iterations as usize;
        let spawned = spawn(&model, &tree, &config, &mut physics)?;

        let actuators: Vec<_> = model.actuators().cloned().collect();
        let mut module_actuators = Vec::with_capacity(model.modules.len());
        let mut start = 0;
        for m in &model.modules {
            module_actuators.push(start..start + m.actuators.len());
            start += m.actuators.len();
        }
        let base_link = tree
            .link_index(&model.base_link)
            .expect("the base link is in the URDF");
        let servos: Vec<ServoState> = actuators
            .iter()
            .map(|a| ServoState::holding(a.mode, 0.0))
            .collect();
        let pristine = Snapshot::capture(&physics, &servos, 0.0);
        let mut world = Self {
            actuators,
            model,
            config,
            tree,
            physics,
            links: spawned.links,
            joints: spawned.joints,
            servos,
            module_actuators,
            multibody_roots: spawned.multibody_roots,
            collider_links: spawned.collider_links,
            ground: spawned.ground,
            base_link,
            pristine,
            time_s: 0.0,
        };
        let home = world.home_state();
        world.reset(&home);
        Ok(world)
    }

    pub fn model(&self) -> &Arc<RobotModel> {
        &self.model
    }

    pub fn config(&self) -> &SimConfig {
        &self.config
    }

    /// Simulated time since the last reset [s].
    pub fn time(&self) -> f64 {
        self.time_s
    }

    /// Actuated joint names, in the order of every per-joint vector of this API.
    pub fn actuator_names(&self) -> Vec<&str> {
        self.model.actuators().map(|a| a.joint.as_str()).collect()
    }

    /// The actuator index range of a module.
    pub fn module_range(&self, module: &str) -> Result<std::ops::Range<usize>, SimError> {
        let i = self
            .model
            .modules
            .iter()
            .position(|m| m.name == module)
            .ok_or_else(|| SimError::UnknownModule(module.to_string()))?;
        Ok(self.module_actuators[i].clone())
    }

    /// The home configuration, standing on the ground at the world origin.
    pub fn home_state(&self) -> RobotState {
        let joint_positions: Vec<f64> = self
            .model
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
            .collect();
        self.standing_state(0.0, 0.0, 0.0, joint_positions)
    }

    /// A configuration with the base at (`x`, `y`) [m] and heading `yaw` [rad], lifted so that
    /// the lowest collider just touches the ground.
    pub fn standing_state(
        &self,
        x: f64,
        y: f64,
        yaw: f64,
        joint_positions: Vec<f64>,
    ) -> RobotState {
        let level = Isometry3::from_parts(
            Translation3::new(x, y, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), yaw),
        );
        let lowest = self.lowest_point(&level, &joint_positions);
        let lift = if self.model.fixed_base { 0.0 } else { -lowest };
        RobotState {
            base_pose_w: Translation3::new(0.0, 0.0, lift) * level,
            joint_positions,
        }
    }

    /// The lowest point [m] of any robot collider with the robot placed at `base_pose_w`.
    fn lowest_point(&self, base_pose_w: &Isometry3<f64>, joint_positions: &[f64]) -> f64 {
        let poses = self
            .tree
            .forward(base_pose_w, &self.tree_positions(joint_positions));
        let mut lowest = f64::INFINITY;
        for (&handle, &link_index) in &self.collider_links {
            let collider = &self.physics.colliders[handle];
            let link_name = &self.model.urdf.links[link_index].name;
            let tree_index = self.tree.link_index(link_name).expect("same URDF");
            let local = collider
                .position_wrt_parent()
                .copied()
                .unwrap_or(Pose::IDENTITY);
            let pose = to_rapier_pose(&poses[tree_index]) * local;
            let aabb = collider.shape().compute_aabb(&pose);
            lowest = lowest.min(f64::from(aabb.mins.z));
        }
        lowest
    }

    /// Joint positions in the kinematic tree's order from positions in actuator order.
    fn tree_positions(&self, joint_positions: &[f64]) -> Vec<f64> {
        let mut q = vec![0.0; self.tree.joints().len()];
        for (joint, &value) in self.joints.iter().zip(joint_positions) {
            q[joint.tree_joint] = value;
        }
        q
    }

    /// Places the robot at `state`, at rest, with every servo holding that configuration and
    /// every wheel commanded to stop; clears contacts and time. Runs in place, without
    /// rebuilding: it restores the physics as built, then places the bodies.
    pub fn reset(&mut self, state: &RobotState) {
        assert_eq!(
            state.joint_positions.len(),
            self.joints.len(),
            "one joint position per actuator"
        );
        self.restore_owned(self.pristine.clone());
        let base = if self.model.fixed_base {
            Isometry3::identity()
        } else {
            state.base_pose_w
        };
        let poses = self
            .tree
            .forward(&base, &self.tree_positions(&state.joint_positions));
        for (link, pose) in self.links.iter().zip(&poses) {
            if link.offset == Isometry3::identity() {
                place_body(&mut self.physics, link.body, pose);
            }
        }
        for (joint, &q) in self.joints.iter().zip(&state.joint_positions) {
            let (mb, link_id) = self
                .physics
                .multibody_joints
                .get_mut(joint.handle)
                .expect("actuated joints are multibody joints");
            let link = mb.link_mut(link_id).expect("link exists");
            let current = link.joint.coords()[3];
            link.joint.apply_displacement(&[q as f32 - current]);
        }
        for root in &self.multibody_roots {
            let id = *self
                .physics
                .multibody_joints
                .rigid_body_link(*root)
                .expect("multibody root");
            let mb = self
                .physics
                .multibody_joints
                .get_multibody_mut(id.multibody)
                .expect("multibody exists");
            mb.forward_kinematics(&self.physics.bodies, true);
            mb.update_rigid_bodies(&mut self.physics.bodies, true);
            mb.generalized_velocity_mut().fill(0.0);
        }
        // Arms hold the configuration; wheels start braked, holding their angle.
        for (i, servo) in self.servos.iter_mut().enumerate() {
            *servo = ServoState::holding(self.actuators[i].mode, state.joint_positions[i]);
        }
        self.time_s = 0.0;
    }

    /// A copy of the full physics state.
    pub fn snapshot(&self) -> Snapshot {
        Snapshot::capture(&self.physics, &self.servos, self.time_s)
    }

    /// Restores a snapshot taken from this world: the trajectory from here on is bit-identical
    /// to the one that followed the snapshot.
    pub fn restore(&mut self, snapshot: &Snapshot) {
        self.restore_owned(snapshot.clone());
    }

    fn restore_owned(&mut self, s: Snapshot) {
        self.physics.islands = s.islands;
        self.physics.broad_phase = s.broad_phase;
        self.physics.narrow_phase = s.narrow_phase;
        self.physics.bodies = s.bodies;
        self.physics.colliders = s.colliders;
        self.physics.impulse_joints = s.impulse_joints;
        self.physics.multibody_joints = s.multibody_joints;
        self.physics.ccd_solver = s.ccd_solver;
        self.servos = s.servos;
        self.time_s = s.time_s;
    }

    /// Commands position targets [rad] for a module's position joints (an arm's 7 joints, in
    /// order). Targets are clamped to the joint ranges; the servo set-point slews toward them
    /// at the joint velocity limit. A non-finite value rejects the whole command.
    pub fn set_position_targets(&mut self, module: &str, targets: &[f64]) -> Result<(), SimError> {
        self.set_module_commands(module, ActuatorMode::Position, targets)
    }

    /// Commands one wheel velocity [rad/s] for both wheels of a wheel module, clamped to the
    /// velocity limit.
    pub fn set_wheel_velocity(&mut self, module: &str, velocity: f64) -> Result<(), SimError> {
        let range = self.module_range(module)?;
        let n = self.actuators[range]
            .iter()
            .filter(|a| a.mode == ActuatorMode::Velocity)
            .count();
        self.set_module_commands(module, ActuatorMode::Velocity, &vec![velocity; n])
    }

    fn set_module_commands(
        &mut self,
        module: &str,
        mode: ActuatorMode,
        values: &[f64],
    ) -> Result<(), SimError> {
        let range = self.module_range(module)?;
        let indices: Vec<usize> = range.filter(|&i| self.actuators[i].mode == mode).collect();
        if indices.is_empty() {
            return Err(SimError::WrongModuleKind {
                module: module.to_string(),
                what: match mode {
                    ActuatorMode::Position => "position",
                    ActuatorMode::Velocity => "velocity",
                },
            });
        }
        if indices.len() != values.len() {
            return Err(SimError::LengthMismatch {
                module: module.to_string(),
                expected: indices.len(),
                got: values.len(),
            });
        }
        let mut clamped = Vec::with_capacity(values.len());
        for (&i, &v) in indices.iter().zip(values) {
            clamped.push(clamp_command(&self.actuators[i], v).ok_or_else(|| {
                SimError::NonFinite {
                    module: module.to_string(),
                    value: v,
                }
            })?);
        }
        for (&i, v) in indices.iter().zip(clamped) {
            self.servos[i].command = v;
        }
        Ok(())
    }

    /// The current commands, in actuator order: position targets [rad] or velocities [rad/s].
    pub fn commands(&self) -> Vec<f64> {
        self.servos.iter().map(|s| s.command).collect()
    }

    /// Advances one control step (`substeps` physics steps).
    pub fn step(&mut self) {
        let dt = self.config.dt();
        for _ in 0..self.config.substeps {
            for (i, joint) in self.joints.iter().enumerate() {
                let servo = &mut self.servos[i];
                let actuator = &self.actuators[i];
                let (stiffness, damping) = (actuator.stiffness as f32, actuator.damping as f32);
                let (mb, link_id) = self
                    .physics
                    .multibody_joints
                    .get_mut_internal(joint.handle)
                    .expect("actuated joints are multibody joints");
                let joint = &mut mb.link_mut(link_id).expect("link exists").joint;
                match actuator.mode {
                    ActuatorMode::Position => {
                        servo.setpoint =
                            slew(servo.setpoint, servo.command, actuator.velocity_limit, dt);
                        joint.data.set_motor_position(
                            JointAxis::AngX,
                            servo.setpoint as f32,
                            stiffness,
                            damping,
                        );
                    }
                    ActuatorMode::Velocity => {
                        let q = f64::from(joint.coords()[3]);
                        servo.setpoint = integrate_velocity_setpoint(
                            servo.setpoint,
                            servo.command,
                            q,
                            max_lead(actuator),
                            dt,
                        );
                        joint.data.set_motor(
                            JointAxis::AngX,
                            servo.setpoint as f32,
                            servo.command as f32,
                            stiffness,
                            damping,
                        );
                    }
                }
            }
            self.physics.step();
        }
        self.time_s += 1.0 / self.config.control_hz;
    }

    /// Joint positions [rad], in actuator order.
    pub fn joint_positions(&self) -> Vec<f64> {
        self.joints
            .iter()
            .map(|j| {
                let (mb, id) = self.physics.multibody_joints.get(j.handle).expect("exists");
                f64::from(mb.link(id).expect("exists").joint().coords()[3])
            })
            .collect()
    }

    /// Joint velocities [rad/s], in actuator order.
    pub fn joint_velocities(&self) -> Vec<f64> {
        self.joints
            .iter()
            .map(|j| {
                let (mb, id) = self.physics.multibody_joints.get(j.handle).expect("exists");
                f64::from(mb.joint_velocity(mb.link(id).expect("exists"))[0])
            })
            .collect()
    }

    /// Tilt of the base [rad]: the angle between its z axis and the world's.
    pub fn base_tilt(&self) -> f64 {
        let z = self.base_pose().rotation * Vector3::z();
        z.z.clamp(-1.0, 1.0).acos()
    }

    /// The world pose of any URDF link (the `ee` tool frames included).
    pub fn link_pose(&self, link: &str) -> Result<Isometry3<f64>, SimError> {
        let index = self
            .tree
            .link_index(link)
            .ok_or_else(|| SimError::UnknownLink(link.to_string()))?;
        Ok(link_pose(&self.physics, &self.links[index]))
    }

    /// The base link's pose in the world.
    pub fn base_pose(&self) -> Isometry3<f64> {
        link_pose(&self.physics, &self.links[self.base_link])
    }

    /// The base's linear [m/s] and angular [rad/s] velocity, both in the world frame
    /// (linear velocity of the base body's centre of mass).
    pub fn base_twist_w(&self) -> (Vector3<f64>, Vector3<f64>) {
        let rb = &self.physics.bodies[self.links[self.base_link].body];
        (to_na_vector(rb.linvel()), to_na_vector(rb.angvel()))
    }

    /// Every pair of touching colliders, by link name (or [`GROUND`]), sorted and deduplicated.
    pub fn contacts(&self) -> Vec<Contact> {
        let name = |c: ColliderHandle| -> String {
            if c == self.ground {
                GROUND.to_string()
            } else {
                self.collider_links
                    .get(&c)
                    .map(|&i| self.model.urdf.links[i].name.clone())
                    .unwrap_or_else(|| "unknown".to_string())
            }
        };
        let mut contacts: Vec<Contact> = self
            .physics
            .narrow_phase
            .contact_pairs()
            .filter(|p| p.has_any_active_contact())
            .map(|p| {
                let (a, b) = (name(p.collider1), name(p.collider2));
                if a <= b {
                    Contact { a, b }
                } else {
                    Contact { a: b, b: a }
                }
            })
            .collect();
        contacts.sort();
        contacts.dedup();
        contacts
    }

    /// Links that touch the ground now.
    pub fn ground_contacts(&self) -> Vec<String> {
        self.contacts()
            .into_iter()
            .filter_map(|c| match (c.a.as_str(), c.b.as_str()) {
                (GROUND, other) | (other, GROUND) => Some(other.to_string()),
                _ => None,
            })
            .collect()
    }

    /// The lowest point [m] of any robot collider now (negative: sunk into the ground).
    pub fn lowest_collider_z(&self) -> f64 {
        self.collider_links
            .keys()
            .map(|&h| {
                let c = &self.physics.colliders[h];
                f64::from(c.shape().compute_aabb(c.position()).mins.z)
            })
            .fold(f64::INFINITY, f64::min)
    }

    /// For each mounted module, how far its root link has moved from where its mount puts it:
    /// `(module, translation error [m], rotation error [rad])`. Exactly zero for mounts inside
    /// a multibody; impulse-joint mounts flex a little.
    pub fn mount_errors(&self) -> Vec<(String, f64, f64)> {
        self.model
            .modules
            .iter()
            .filter_map(|m| {
                let joint = self.tree.joint_index(m.mount_joint.as_deref()?)?;
                let j = &self.tree.joints()[joint];
                let parent = link_pose(&self.physics, &self.links[j.parent_link]);
                let child = link_pose(&self.physics, &self.links[j.child_link]);
                let error = (parent * j.origin).inverse() * child;
                Some((
                    m.name.clone(),
                    error.translation.vector.norm(),
                    error.rotation.angle(),
                ))
            })
            .collect()
    }

    /// The world pose of every rigid body's link frame, for rendering or debugging.
    pub fn body_poses(&self) -> Vec<(String, Isometry3<f64>)> {
        self.tree
            .links()
            .iter()
            .zip(&self.links)
            .map(|(name, link)| {
                (
                    name.clone(),
                    to_na_isometry(self.physics.bodies[link.body].position()) * link.offset,
                )
            })
            .collect()
    }
}
