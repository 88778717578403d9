//! The MuJoCo world: [`SimWorld`] on MuJoCo 3.17 through `mujoco-rs`.

use std::sync::Arc;

use kumi_engine::{
    Contact, Engine, LinkLoad, Load, RobotState, ServoBank, ServoState, SimConfig, SimError,
    SimWorld, Snapshot, GROUND,
};
use kumi_model::kinematics::KinematicTree;
use kumi_model::RobotModel;
use mujoco_rs::prelude::*;
use mujoco_rs::wrappers::MjtWarning;
use nalgebra::{Isometry3, Matrix3, Translation3, Vector3};

use crate::geometry::{lowest_z, GeomShape};
use crate::mjcf::{self, quat_wxyz, GROUND_GEOM};
use crate::servo::servo_command;

/// The warnings MuJoCo raises when it finds non-finite or huge positions, velocities or
/// accelerations and restarts the data from the model's initial state (`mj_checkPos`,
/// `mj_checkVel`, `mj_checkAcc` in MuJoCo's `engine_forward.c`).
const BLOW_UPS: [MjtWarning; 3] = [
    MjtWarning::mjWARN_BADQPOS,
    MjtWarning::mjWARN_BADQVEL,
    MjtWarning::mjWARN_BADQACC,
];

/// One actuated joint in MuJoCo's arrays.
#[derive(Debug, Clone, Copy)]
struct ServoJoint {
    qpos: usize,
    dof: usize,
    /// The joint's own (passive) damping [N m s/rad].
    joint_damping: f64,
}

/// MuJoCo's state plus kumi's servo state: everything a snapshot restores.
#[derive(Clone)]
struct MujocoState {
    /// The world it was taken from: the robot model (by identity: held, so that its address
    /// cannot be reused by another model while the snapshot lives) and the settings.
    model: Arc<RobotModel>,
    config: SimConfig,
    physics: Box<[f64]>,
    servos: Vec<ServoState>,
    time_s: f64,
    /// Whether the physics had blown up when it was taken.
    diverged: bool,
}

/// What MuJoCo restores: time, positions, velocities, warm start, applied forces.
const STATE_SPEC: u32 = MjtState::mjSTATE_INTEGRATION as u32;

/// One robot in a MuJoCo world with a ground plane and gravity along -z.
pub struct MujocoWorld {
    model: Arc<RobotModel>,
    config: SimConfig,
    tree: KinematicTree,
    data: MjData<Box<MjModel>>,
    /// Per URDF link (tree order): MuJoCo body id and the link frame in that body's frame.
    links: Vec<(usize, Isometry3<f64>)>,
    /// URDF link name of each MuJoCo body that is a link (None: world, or no link).
    body_links: Vec<Option<String>>,
    /// Robot geoms (all but the ground) and their shapes.
    geoms: Vec<(usize, GeomShape)>,
    ground_geom: usize,
    joints: Vec<ServoJoint>,
    servos: ServoBank,
    base_link: usize,
    time_s: f64,
    /// MuJoCo reported a blow-up (and reset itself), or a control step ended past
    /// [`kumi_engine::blown_up`]'s bounds, since the last reset.
    diverged: bool,
    /// The load [`SimWorld::set_link_load`] put on, applied anew at every physics step.
    link_load: Option<LinkLoad>,
}

fn rejected(model: &RobotModel, message: String) -> SimError {
    SimError::EngineRejected {
        engine: Engine::Mujoco,
        robot: model.name.clone(),
        message,
    }
}

impl MujocoWorld {
    /// Builds the world and places the robot at its home configuration, standing on the ground
    /// at the origin (fixed-base robots: base at the origin).
    pub fn new(model: Arc<RobotModel>, config: SimConfig) -> Result<Self, SimError> {
        if !(config.control_hz > 0.0 && config.mujoco_substeps > 0) {
            return Err(SimError::BadConfig(format!(
                "control rate and substeps must be positive: {config:?}"
            )));
        }
        let tree = KinematicTree::new(&model.urdf).map_err(|source| SimError::Tree {
            robot: model.name.clone(),
            source,
        })?;
        let spec = mjcf::build(&model, &config)?;
        let mj =
            MjModel::from_xml_string(&spec.xml).map_err(|e| rejected(&model, e.to_string()))?;
        let body_id = |name: &str| {
            mj.name_to_id(MjtObjBase::mjOBJ_BODY, name)
                .ok_or_else(|| rejected(&model, format!("no body `{name}` in the compiled model")))
        };
        let links = spec
            .links
            .iter()
            .map(|l| Ok((body_id(&l.body)?, l.offset)))
            .collect::<Result<Vec<_>, SimError>>()?;
        let mut body_links = vec![None; mj.nbody() as usize];
        for (i, name) in tree.links().iter().enumerate() {
            if links[i].1 == Isometry3::identity() && spec.links[i].body == *name {
                body_links[links[i].0] = Some(name.clone());
            }
        }
        let ground_geom = mj
            .name_to_id(MjtObjBase::mjOBJ_GEOM, GROUND_GEOM)
            .ok_or_else(|| rejected(&model, "no ground geom".into()))?;
        let geoms = (0..mj.ngeom() as usize)
            .filter(|&g| g != ground_geom)
            .map(|g| Ok((g, GeomShape::of(&mj, g).map_err(|e| rejected(&model, e))?)))
            .collect::<Result<Vec<_>, SimError>>()?;
        let servos = ServoBank::new(&model);
        let joints = servos
            .actuators()
            .iter()
            .map(|a| {
                let j = mj
                    .name_to_id(MjtObjBase::mjOBJ_JOINT, &a.joint)
                    .ok_or_else(|| rejected(&model, format!("no joint `{}`", a.joint)))?;
                let dof = mj.jnt_dofadr()[j] as usize;
                Ok(ServoJoint {
                    qpos: mj.jnt_qposadr()[j] as usize,
                    dof,
                    joint_damping: a.joint_damping,
                })
            })
            .collect::<Result<Vec<_>, SimError>>()?;
        let base_link = tree.root();
        let mut world = Self {
            data: MjData::new(Box::new(mj)),
            model,
            config,
            tree,
            links,
            body_links,
            geoms,
            ground_geom,
            joints,
            servos,
            base_link,
            time_s: 0.0,
            diverged: false,
            link_load: None,
        };
        let home = world.home_state();
        world.reset(&home);
        Ok(world)
    }

    fn body_pose(&self, body: usize) -> Isometry3<f64> {
        let p = self.data.xpos()[body];
        Isometry3::from_parts(
            Translation3::new(p[0], p[1], p[2]),
            quat_wxyz(&self.data.xquat()[body]),
        )
    }

    /// Sets each dof's damping to its own plus the servo's at rest (a reset's starting point;
    /// every physics step sets it again).
    fn set_damping(&mut self) {
        let dt = self.config.mujoco_dt();
        // SAFETY: only the per-dof damping values change; the model's layout does not.
        let damping = unsafe { self.data.model_mut() }.dof_damping_mut();
        for (i, j) in self.joints.iter().enumerate() {
            let a = &self.servos.actuators()[i];
            damping[j.dof] = j.joint_damping + a.damping + dt * a.stiffness;
        }
    }

    /// One physics step: kumi's servo law on the step's starting state (each servo's spring as
    /// a joint force, its damping as the dof's, which MuJoCo integrates implicitly), then
    /// MuJoCo's step.
    fn physics_step(&mut self) {
        let dt = self.config.mujoco_dt();
        if !self.model.fixed_base {
            // The free joint's angular velocity is in the base's own frame.
            let w = &self.data.qvel()[3..6];
            self.servos
                .set_base_angular_velocity(Vector3::new(w[0], w[1], w[2]));
        }
        for i in 0..self.joints.len() {
            let j = self.joints[i];
            let q = self.data.qpos()[j.qpos];
            let v = self.data.qvel()[j.dof];
            let target = self.servos.advance(i, q, dt);
            let command = servo_command(&self.servos.actuators()[i], target, q, v, dt);
            self.data.qfrc_applied_mut()[j.dof] = command.spring;
            // SAFETY: only a damping value changes; the model's layout does not.
            unsafe { self.data.model_mut() }.dof_damping_mut()[j.dof] =
                j.joint_damping + command.damping;
        }
        self.apply_link_load();
        self.data.step();
        // MuJoCo counts bad positions, velocities and accelerations (each after restarting
        // from its initial state).
        if BLOW_UPS
            .iter()
            .any(|&w| self.data.warning()[w as usize].number > 0)
        {
            self.diverged = true;
        }
    }

    /// Puts the load on its link's body for the next physics step: the force at the link
    /// frame's origin, applied as MuJoCo applies a body's `xfrc_applied`, at its centre of mass
    /// with its moment about it. A spring reads the link's pose now (MuJoCo's poses after a
    /// step are those before its integration).
    fn apply_link_load(&mut self) {
        if let Some(LinkLoad { link, load }) = self.link_load {
            if load.stiffness_n_m > 0.0 {
                self.data.kinematics();
                self.data.com_pos();
            }
            let (body, offset) = self.links[link];
            let point = (self.body_pose(body) * offset).translation.vector;
            let com = Vector3::from(self.data.xipos()[body]);
            let f = load.force_at(&point);
            let torque = (point - com).cross(&f);
            self.data.xfrc_applied_mut()[body] = [f.x, f.y, f.z, torque.x, torque.y, torque.z];
        }
    }

    /// Takes the load off its body.
    fn clear_link_load(&mut self) {
        if let Some(load) = self.link_load.take() {
            self.data.xfrc_applied_mut()[self.links[load.link].0] = [0.0; 6];
        }
    }

    /// Joint positions in the kinematic tree's order from positions in actuator order.
    fn tree_positions(&self, joint_positions: &[f64]) -> Vec<f64> {
        let mut q = vec![0.0; self.tree.joints().len()];
        for (a, &value) in self.servos.actuators().iter().zip(joint_positions) {
            q[self.tree.joint_index(&a.joint).expect("same URDF")] = value;
        }
        q
    }
}

impl SimWorld for MujocoWorld {
    fn engine(&self) -> Engine {
        Engine::Mujoco
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
        let mj = self.data.model();
        let mut lowest = f64::INFINITY;
        for &(g, shape) in &self.geoms {
            let body = mj.geom_bodyid()[g] as usize;
            let Some(link) = self.body_links[body].as_deref() else {
                continue;
            };
            let link_pose = poses[self.tree.link_index(link).expect("same URDF")];
            let p = mj.geom_pos()[g];
            let local = Isometry3::from_parts(
                Translation3::new(p[0], p[1], p[2]),
                quat_wxyz(&mj.geom_quat()[g]),
            );
            let pose = link_pose * local;
            lowest = lowest.min(lowest_z(
                shape,
                &pose.translation.vector,
                pose.rotation.to_rotation_matrix().matrix(),
            ));
        }
        lowest
    }

    fn reset(&mut self, state: &RobotState) {
        assert_eq!(
            state.joint_positions.len(),
            self.joints.len(),
            "one joint position per actuator"
        );
        self.data.reset();
        self.link_load = None;
        if !self.model.fixed_base {
            let t = state.base_pose_w.translation.vector;
            let q = state.base_pose_w.rotation.quaternion();
            self.data.qpos_mut()[..7].copy_from_slice(&[t.x, t.y, t.z, q.w, q.i, q.j, q.k]);
        }
        for (j, &q) in self.joints.iter().zip(&state.joint_positions) {
            self.data.qpos_mut()[j.qpos] = q;
        }
        self.servos.hold(&state.joint_positions);
        self.set_damping();
        self.data.forward();
        self.time_s = 0.0;
        self.diverged = false;
    }

    fn snapshot(&self) -> Snapshot {
        Snapshot::new(MujocoState {
            model: Arc::clone(&self.model),
            config: self.config,
            physics: self.data.state(STATE_SPEC),
            servos: self.servos.states().to_vec(),
            time_s: self.time_s,
            diverged: self.diverged,
        })
    }

    fn restore(&mut self, snapshot: &Snapshot) -> Result<(), SimError> {
        let s = snapshot.downcast::<MujocoState>()?;
        if !Arc::ptr_eq(&s.model, &self.model)
            || s.config != self.config
            || s.physics.len() != self.data.model().state_size(STATE_SPEC)
        {
            return Err(SimError::ForeignSnapshot);
        }
        self.data
            .set_state(&s.physics, STATE_SPEC)
            .map_err(|_| SimError::ForeignSnapshot)?;
        self.servos.restore(&s.servos);
        self.time_s = s.time_s;
        // MuJoCo's state leaves its warning counts alone: without this, a world that blew up
        // after the snapshot would call the restored, sound state diverged on its next step.
        for w in BLOW_UPS {
            self.data.warning_mut()[w as usize].number = 0;
        }
        self.diverged = s.diverged;
        self.set_damping();
        self.data.forward();
        Ok(())
    }

    fn step(&mut self) {
        for _ in 0..self.config.mujoco_substeps {
            self.physics_step();
        }
        // mj_step2 leaves link poses at the positions before its integration: bring them to the
        // new positions, so that poses agree with joint positions (contacts stay those the
        // last physics step solved). The next mj_step1 recomputes them anyway: the trajectory
        // is the same.
        self.data.kinematics();
        self.data.com_pos();
        self.time_s += 1.0 / self.config.control_hz;
        self.diverged = self.diverged || self.state_blown_up();
    }

    fn push(&mut self, delta_v_w: &Vector3<f64>, delta_w_w: &Vector3<f64>) {
        if self.model.fixed_base {
            return;
        }
        // The free joint's velocities: its origin's linear velocity in the world frame, then its
        // angular velocity in its own frame; every body of the one tree hanging off it follows.
        let body = self.links[self.base_link].0;
        let delta_w_b = quat_wxyz(&self.data.xquat()[body]).inverse() * delta_w_w;
        let delta = delta_v_w.iter().chain(delta_w_b.iter());
        for (v, d) in self.data.qvel_mut()[..6].iter_mut().zip(delta) {
            *v += d;
        }
    }

    fn set_link_load(&mut self, link: &str, load: &Load) -> Result<(), SimError> {
        let load = LinkLoad::checked(&self.tree, link, load)?;
        self.clear_link_load();
        self.link_load = load;
        Ok(())
    }

    fn joint_positions(&self) -> Vec<f64> {
        self.joints
            .iter()
            .map(|j| self.data.qpos()[j.qpos])
            .collect()
    }

    fn joint_velocities(&self) -> Vec<f64> {
        self.joints
            .iter()
            .map(|j| self.data.qvel()[j.dof])
            .collect()
    }

    fn link_pose(&self, link: &str) -> Result<Isometry3<f64>, SimError> {
        let i = self
            .tree
            .link_index(link)
            .ok_or_else(|| SimError::UnknownLink(link.to_string()))?;
        let (body, offset) = self.links[i];
        Ok(self.body_pose(body) * offset)
    }

    fn base_pose(&self) -> Isometry3<f64> {
        let (body, offset) = self.links[self.base_link];
        self.body_pose(body) * offset
    }

    fn base_twist_w(&self) -> (Vector3<f64>, Vector3<f64>) {
        if self.model.fixed_base {
            return (Vector3::zeros(), Vector3::zeros());
        }
        // Free joint: linear velocity of the body origin in the world frame, angular velocity
        // in the body frame.
        let v = self.data.qvel();
        let body = self.links[self.base_link].0;
        let rotation = quat_wxyz(&self.data.xquat()[body]);
        let angular_w = rotation * Vector3::new(v[3], v[4], v[5]);
        let (com, origin) = (self.data.xipos()[body], self.data.xpos()[body]);
        let r = Vector3::new(com[0] - origin[0], com[1] - origin[1], com[2] - origin[2]);
        let linear_w = Vector3::new(v[0], v[1], v[2]) + angular_w.cross(&r);
        (linear_w, angular_w)
    }

    fn contacts(&self) -> Vec<Contact> {
        let mj = self.data.model();
        let name = |g: i32| -> String {
            let g = g as usize;
            if g == self.ground_geom {
                GROUND.to_string()
            } else {
                self.body_links[mj.geom_bodyid()[g] as usize]
                    .clone()
                    .unwrap_or_else(|| "unknown".to_string())
            }
        };
        let mut contacts: Vec<Contact> = self
            .data
            .contact()
            .iter()
            .filter(|c| c.dist <= 0.0)
            .map(|c| Contact::new(name(c.geom1), name(c.geom2)))
            .collect();
        contacts.sort();
        contacts.dedup();
        contacts
    }

    fn lowest_collider_z(&self) -> f64 {
        self.geoms
            .iter()
            .map(|&(g, shape)| {
                let p = self.data.geom_xpos()[g];
                let m = self.data.geom_xmat()[g];
                lowest_z(
                    shape,
                    &Vector3::new(p[0], p[1], p[2]),
                    &Matrix3::from_row_slice(&m),
                )
            })
            .fold(f64::INFINITY, f64::min)
    }

    fn mount_errors(&self) -> Vec<(String, f64, f64)> {
        self.model
            .modules
            .iter()
            .filter_map(|m| {
                let joint = self.tree.joint_index(m.mount_joint.as_deref()?)?;
                let j = &self.tree.joints()[joint];
                let parent = self.link_pose(&self.tree.links()[j.parent_link]).ok()?;
                let child = self.link_pose(&self.tree.links()[j.child_link]).ok()?;
                let error = (parent * j.origin).inverse() * child;
                Some((
                    m.name.clone(),
                    error.translation.vector.norm(),
                    error.rotation.angle(),
                ))
            })
            .collect()
    }

    fn diverged(&self) -> bool {
        self.diverged
    }

    fn body_poses(&self) -> Vec<(String, Isometry3<f64>)> {
        self.tree
            .links()
            .iter()
            .zip(&self.links)
            .map(|(name, &(body, offset))| (name.clone(), self.body_pose(body) * offset))
            .collect()
    }
}
