//! The simulated robot: commands in, physics stepped at the control rate, state out.

use std::sync::Arc;

use kumi_engine::{
    Contact, Engine, LinkLoad, Load, RobotState, ServoBank, ServoState, SimConfig, SimError,
    SimWorld, Snapshot, GROUND,
};
use kumi_model::kinematics::KinematicTree;
use kumi_model::RobotModel;
use nalgebra::{Isometry3, Vector3};
use rapier3d::prelude::*;

use crate::convert::{to_na_isometry, to_na_vector, to_rapier_pose, to_rapier_vector};
use crate::spawn::{link_pose, place_body, root_multibody_mut, spawn, ArticulatedJoint, LinkBody};

/// Everything needed to restore rapier's physics exactly as it was.
#[derive(Clone)]
struct RapierState {
    /// The world it was taken from: the robot model (by identity: held, so that its address
    /// cannot be reused by another model while the snapshot lives) and the settings.
    model: Arc<RobotModel>,
    config: SimConfig,
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
    /// Whether the physics had blown up when it was taken.
    diverged: bool,
}

impl RapierState {
    fn capture(
        model: &Arc<RobotModel>,
        config: SimConfig,
        physics: &PhysicsWorld,
        servos: &[ServoState],
        time_s: f64,
        diverged: bool,
    ) -> Self {
        Self {
            model: Arc::clone(model),
            config,
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
            diverged,
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
    servos: ServoBank,
    multibody_roots: Vec<RigidBodyHandle>,
    collider_links: std::collections::HashMap<ColliderHandle, usize>,
    ground: ColliderHandle,
    base_link: usize,
    /// The physics as built, before the robot was placed: every reset starts from it, so a
    /// reset world and a freshly built one follow bit-identical trajectories.
    pristine: RapierState,
    time_s: f64,
    /// The state passed [`kumi_engine::blown_up`]'s bounds since the last reset.
    diverged: bool,
    /// The load [`SimWorld::set_link_load`] put on, applied anew at every physics step.
    link_load: Option<LinkLoad>,
}

impl World {
    /// Puts the load on its link's body for the next physics step: the force at the link
    /// frame's origin as the body stands now, applied at the body's centre of mass with its
    /// moment about it (rapier keeps user forces and torques, in the world frame, until they
    /// are reset).
    fn apply_link_load(&mut self) {
        if let Some(LinkLoad { link, load }) = self.link_load {
            let link = &self.links[link];
            let point = link_pose(&self.physics, link).translation.vector;
            let force_w = load.force_at(&point);
            let rb = &mut self.physics.bodies[link.body];
            let com = to_na_vector(rb.center_of_mass());
            let torque = (point - com).cross(&force_w);
            rb.reset_forces(false);
            rb.reset_torques(false);
            rb.add_force(to_rapier_vector(&force_w), true);
            rb.add_torque(to_rapier_vector(&torque), true);
        }
    }

    /// Takes the load off its body.
    fn clear_link_load(&mut self) {
        if let Some(load) = self.link_load.take() {
            let rb = &mut self.physics.bodies[self.links[load.link].body];
            rb.reset_forces(false);
            rb.reset_torques(false);
        }
    }

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

        let base_link = tree
            .link_index(&model.base_link)
            .expect("the base link is in the URDF");
        let servos = ServoBank::new(&model);
        let pristine = RapierState::capture(&model, config, &physics, servos.states(), 0.0, false);
        let mut world = Self {
            model,
            config,
            tree,
            physics,
            links: spawned.links,
            joints: spawned.joints,
            servos,
            multibody_roots: spawned.multibody_roots,
            collider_links: spawned.collider_links,
            ground: spawned.ground,
            base_link,
            pristine,
            time_s: 0.0,
            diverged: false,
            link_load: None,
        };
        let home = world.home_state();
        world.reset(&home);
        Ok(world)
    }

    /// Joint positions in the kinematic tree's order from positions in actuator order.
    fn tree_positions(&self, joint_positions: &[f64]) -> Vec<f64> {
        let mut q = vec![0.0; self.tree.joints().len()];
        for (joint, &value) in self.joints.iter().zip(joint_positions) {
            q[joint.tree_joint] = value;
        }
        q
    }

    fn restore_owned(&mut self, s: RapierState) {
        self.physics.islands = s.islands;
        self.physics.broad_phase = s.broad_phase;
        self.physics.narrow_phase = s.narrow_phase;
        self.physics.bodies = s.bodies;
        self.physics.colliders = s.colliders;
        self.physics.impulse_joints = s.impulse_joints;
        self.physics.multibody_joints = s.multibody_joints;
        self.physics.ccd_solver = s.ccd_solver;
        self.servos.restore(&s.servos);
        self.time_s = s.time_s;
        self.diverged = s.diverged;
    }
}

impl SimWorld for World {
    fn engine(&self) -> Engine {
        Engine::Rapier
    }

    fn model(&self) -> &Arc<RobotModel> {
        &self.model
    }

    fn config(&self) -> &SimConfig {
        &self.config
    }

    fn servos(&self) -> &ServoBank {
        &self.servos
    }

    fn servos_mut(&mut self) -> &mut ServoBank {
        &mut self.servos
    }

    fn time(&self) -> f64 {
        self.time_s
    }

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

    /// Runs in place, without rebuilding: restores the physics as built, then places the bodies.
    fn reset(&mut self, state: &RobotState) {
        assert_eq!(
            state.joint_positions.len(),
            self.joints.len(),
            "one joint position per actuator"
        );
        self.restore_owned(self.pristine.clone());
        self.link_load = None;
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
            let mb = root_multibody_mut(&mut self.physics.multibody_joints, *root);
            mb.forward_kinematics(&self.physics.bodies, true);
            mb.update_rigid_bodies(&mut self.physics.bodies, true);
            mb.generalized_velocity_mut().fill(0.0);
        }
        // Arms hold the configuration; wheels start braked, holding their angle.
        self.servos.hold(&state.joint_positions);
        self.time_s = 0.0;
    }

    fn snapshot(&self) -> Snapshot {
        Snapshot::new(RapierState::capture(
            &self.model,
            self.config,
            &self.physics,
            self.servos.states(),
            self.time_s,
            self.diverged,
        ))
    }

    fn restore(&mut self, snapshot: &Snapshot) -> Result<(), SimError> {
        let state = snapshot.downcast::<RapierState>()?.clone();
        if !Arc::ptr_eq(&state.model, &self.model) || state.config != self.config {
            return Err(SimError::ForeignSnapshot);
        }
        self.restore_owned(state);
        Ok(())
    }

    /// Advances one control step (`substeps` physics steps), or stops where the state blew up
    /// ([`SimWorld::diverged`]): the physics then stands still until the next reset or restore.
    fn step(&mut self) {
        let dt = self.config.dt();
        for _ in 0..self.config.substeps {
            // A blown-up state soon holds non-finite values, on which rapier's joint motors
            // panic: a world that blew up is not stepped again until a reset or restore.
            self.diverged = self.diverged || self.state_blown_up();
            if self.diverged {
                break;
            }
            let (_, w_w) = self.base_twist_w();
            let w_b = self.base_pose().rotation.inverse() * w_w;
            self.servos.set_base_angular_velocity(w_b);
            for (i, joint) in self.joints.iter().enumerate() {
                let (mb, link_id) = self
                    .physics
                    .multibody_joints
                    .get_mut_internal(joint.handle)
                    .expect("actuated joints are multibody joints");
                let joint = &mut mb.link_mut(link_id).expect("link exists").joint;
                let target = self.servos.advance(i, f64::from(joint.coords()[3]), dt);
                let a = &self.servos.actuators()[i];
                // rapier's force-based motor: implicit PD toward (set-point, velocity target),
                // clamped to the effort limit (set at spawn).
                joint.data.set_motor(
                    JointAxis::AngX,
                    target.position as f32,
                    target.velocity as f32,
                    a.stiffness as f32,
                    a.damping as f32,
                );
            }
            self.apply_link_load();
            self.physics.step();
        }
        self.time_s += 1.0 / self.config.control_hz;
        self.diverged = self.diverged || self.state_blown_up();
    }

    fn diverged(&self) -> bool {
        self.diverged
    }

    /// Adds the push to the free root of every multibody (each module's tree, mounts being
    /// impulse joints between them), and to every body's own velocity so that reads agree
    /// before the next step. A free root's linear velocity is taken as its centre of mass's, as
    /// rapier reports a body's `linvel`; rapier's free-joint integration moves the root's
    /// origin with it, which may differ by `dw x (com - origin)` of the root link alone (a few
    /// centimetres' lever): `tests/push.rs` checks the shove link by link within 10 %.
    fn push(&mut self, delta_v_w: &Vector3<f64>, delta_w_w: &Vector3<f64>) {
        if self.model.fixed_base {
            return;
        }
        let origin = self.base_pose().translation.vector;
        // The change of a point's velocity [m/s] where the robot turns about the base origin.
        let at = |point: Vector3<f64>| delta_v_w + delta_w_w.cross(&(point - origin));
        let dw = to_rapier_vector(delta_w_w);
        for root in &self.multibody_roots {
            let com = to_na_vector(self.physics.bodies[*root].center_of_mass());
            let dv = to_rapier_vector(&at(com));
            let mb = root_multibody_mut(&mut self.physics.multibody_joints, *root);
            if mb.root().joint().ndofs() == 6 {
                let mut v = mb.generalized_velocity_mut();
                for k in 0..3 {
                    v[k] += dv[k];
                    v[k + 3] += dw[k];
                }
            }
        }
        let bodies: std::collections::HashSet<_> = self.links.iter().map(|l| l.body).collect();
        for handle in bodies {
            let rb = &mut self.physics.bodies[handle];
            if rb.is_dynamic() {
                let dv = to_rapier_vector(&at(to_na_vector(rb.center_of_mass())));
                let (v, w) = (rb.linvel() + dv, rb.angvel() + dw);
                rb.set_linvel(v, true);
                rb.set_angvel(w, true);
            }
        }
    }

    fn set_link_load(&mut self, link: &str, load: &Load) -> Result<(), SimError> {
        let load = LinkLoad::checked(&self.tree, link, load)?;
        self.clear_link_load();
        self.link_load = load;
        Ok(())
    }

    /// Joint positions [rad], in actuator order.
    fn joint_positions(&self) -> Vec<f64> {
        self.joints
            .iter()
            .map(|j| {
                let (mb, id) = self.physics.multibody_joints.get(j.handle).expect("exists");
                f64::from(mb.link(id).expect("exists").joint().coords()[3])
            })
            .collect()
    }

    /// Joint velocities [rad/s], in actuator order.
    fn joint_velocities(&self) -> Vec<f64> {
        self.joints
            .iter()
            .map(|j| {
                let (mb, id) = self.physics.multibody_joints.get(j.handle).expect("exists");
                f64::from(mb.joint_velocity(mb.link(id).expect("exists"))[0])
            })
            .collect()
    }

    /// The world pose of any URDF link (the `ee` tool frames included).
    fn link_pose(&self, link: &str) -> Result<Isometry3<f64>, SimError> {
        let index = self
            .tree
            .link_index(link)
            .ok_or_else(|| SimError::UnknownLink(link.to_string()))?;
        Ok(link_pose(&self.physics, &self.links[index]))
    }

    /// The base link's pose in the world.
    fn base_pose(&self) -> Isometry3<f64> {
        link_pose(&self.physics, &self.links[self.base_link])
    }

    /// The base's linear [m/s] and angular [rad/s] velocity, both in the world frame
    /// (linear velocity of the base body's centre of mass).
    fn base_twist_w(&self) -> (Vector3<f64>, Vector3<f64>) {
        let rb = &self.physics.bodies[self.links[self.base_link].body];
        (to_na_vector(rb.linvel()), to_na_vector(rb.angvel()))
    }

    /// Every pair of touching colliders, by link name (or [`GROUND`]), sorted and deduplicated.
    fn contacts(&self) -> Vec<Contact> {
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
            .map(|p| Contact::new(name(p.collider1), name(p.collider2)))
            .collect();
        contacts.sort();
        contacts.dedup();
        contacts
    }

    /// The lowest point [m] of any robot collider now (negative: sunk into the ground).
    fn lowest_collider_z(&self) -> f64 {
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
    fn mount_errors(&self) -> Vec<(String, f64, f64)> {
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
    fn body_poses(&self) -> Vec<(String, Isometry3<f64>)> {
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
