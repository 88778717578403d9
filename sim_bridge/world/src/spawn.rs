//! Turns an assembled [`RobotModel`] into rapier bodies, colliders and joints.

use std::collections::HashMap;
use std::path::Path;

use kumi_model::kinematics::KinematicTree;
use kumi_model::{ActuatorMode, RobotModel};
use nalgebra::Isometry3;
use rapier3d::prelude::*;
use rapier3d_urdf::{UrdfLoaderOptions, UrdfRobot};

use kumi_engine::{mount_is_impulse, SimConfig, SimError};

use crate::convert::{to_na_isometry, to_rapier_pose};

/// Where a URDF link lives in rapier: a rigid body, and the link frame in that body's frame
/// (not the identity for frame-only links such as `ee`, which the loader folds into a parent).
#[derive(Debug, Clone, Copy)]
pub(crate) struct LinkBody {
    pub body: RigidBodyHandle,
    pub offset: Isometry3<f64>,
}

/// The rapier side of one actuator.
#[derive(Debug, Clone, Copy)]
pub(crate) struct ArticulatedJoint {
    pub handle: MultibodyJointHandle,
    /// Index of this joint in the [`KinematicTree`].
    pub tree_joint: usize,
}

/// Everything [`spawn`] creates.
pub(crate) struct Spawned {
    pub links: Vec<LinkBody>,
    pub joints: Vec<ArticulatedJoint>,
    /// The root body of every multibody.
    pub multibody_roots: Vec<RigidBodyHandle>,
    pub collider_links: HashMap<ColliderHandle, usize>,
    pub ground: ColliderHandle,
}

/// Half-extents of the ground box [m]: large enough for a 3 m reaching task in any direction.
const GROUND_HALF_EXTENTS: [f32; 3] = [50.0, 50.0, 0.5];

pub(crate) fn spawn(
    model: &RobotModel,
    tree: &KinematicTree,
    config: &SimConfig,
    physics: &mut PhysicsWorld,
) -> Result<Spawned, SimError> {
    let options = UrdfLoaderOptions {
        make_roots_fixed: model.fixed_base,
        // Mass properties come from the URDF inertials; colliders carry no mass.
        collider_blueprint: ColliderBuilder::default().density(0.0),
        // Sleeping would freeze a robot holding still; it must always respond to commands.
        rigid_body_blueprint: RigidBodyBuilder::dynamic().can_sleep(false),
        enable_joint_collisions: false,
        ..Default::default()
    };
    let robot = UrdfRobot::from_robot(&model.urdf, options, Path::new(""));

    let mut links: Vec<Option<LinkBody>> = vec![None; tree.links().len()];
    let mut loader_bodies = Vec::with_capacity(robot.links.len());
    let mut collider_links = HashMap::new();
    for urdf_link in robot.links {
        let link_index = urdf_link.urdf_link_index;
        let link_name = &model.urdf.links[link_index].name;
        let body = physics.bodies.insert(urdf_link.body);
        let collision_names = &model.urdf.links[link_index].collision;
        for (k, c) in urdf_link.colliders.into_iter().enumerate() {
            let name = collision_names.get(k).and_then(|c| c.name.as_deref());
            let friction = name
                .and_then(|n| model.friction_of(n))
                .unwrap_or(config.default_friction);
            let mut collider = c.collider;
            collider.set_friction(friction as f32);
            collider.set_friction_combine_rule(CoefficientCombineRule::Min);
            let handle = physics
                .colliders
                .insert_with_parent(collider, body, &mut physics.bodies);
            collider_links.insert(handle, link_index);
        }
        let tree_index = tree
            .link_index(link_name)
            .expect("the tree is built from the same URDF");
        links[tree_index] = Some(LinkBody {
            body,
            offset: Isometry3::identity(),
        });
        loader_bodies.push(body);
    }

    let mut joint_handles: HashMap<String, MultibodyJointHandle> = HashMap::new();
    for joint in robot.joints {
        let name = &model.urdf.joints[joint.urdf_joint_index].name;
        let (b1, b2) = (loader_bodies[joint.link1], loader_bodies[joint.link2]);
        let impulse = mount_is_impulse(
            model,
            config.layout,
            &model.urdf.joints[joint.urdf_joint_index],
        );
        if impulse {
            let mut data = joint.joint;
            data.set_contacts_enabled(false);
            physics.impulse_joints.insert(b1, b2, data, false);
        } else if let Some(handle) = physics.multibody_joints.insert(b1, b2, joint.joint, false) {
            joint_handles.insert(name.clone(), handle);
        }
    }

    // Frame-only links folded away by the loader hang off their parent's body.
    for j in tree.joints() {
        if links[j.child_link].is_none() {
            let parent = links[j.parent_link].expect("joints are ordered parents first");
            links[j.child_link] = Some(LinkBody {
                body: parent.body,
                offset: parent.offset * j.origin,
            });
        }
    }
    let links: Vec<LinkBody> = links
        .into_iter()
        .map(|l| l.expect("every link is a body or hangs off one"))
        .collect();

    // Actuators: force-based motors (gains in N m/rad), effort-limited; per-DoF damping and
    // armature from the model (rapier ignores the URDF's <dynamics>).
    let mut joints = Vec::new();
    for actuator in model.actuators() {
        let handle = *joint_handles.get(&actuator.joint).ok_or_else(|| {
            SimError::ActuatorNotArticulated {
                robot: model.name.clone(),
                joint: actuator.joint.clone(),
            }
        })?;
        let (multibody, link_id) = physics
            .multibody_joints
            .get_mut(handle)
            .expect("handle was just created");
        let assembly_id = multibody.link(link_id).expect("link exists").assembly_id();
        multibody.damping_mut()[assembly_id] = actuator.joint_damping as f32;
        multibody.armature_mut()[assembly_id] = actuator.armature as f32;
        multibody.frictions_mut()[assembly_id] = actuator.joint_friction as f32;
        let data = &mut multibody.link_mut(link_id).expect("link exists").joint.data;
        data.set_motor_model(JointAxis::AngX, MotorModel::ForceBased);
        data.set_motor_max_force(JointAxis::AngX, actuator.effort_limit as f32);
        match actuator.mode {
            ActuatorMode::Position => data.set_motor_position(
                JointAxis::AngX,
                0.0,
                actuator.stiffness as f32,
                actuator.damping as f32,
            ),
            ActuatorMode::Velocity => {
                data.set_motor_velocity(JointAxis::AngX, 0.0, actuator.damping as f32)
            }
        };
        let tree_joint = tree
            .joint_index(&actuator.joint)
            .expect("the tree is built from the same URDF");
        joints.push(ArticulatedJoint { handle, tree_joint });
    }

    let mut multibody_roots = Vec::new();
    for mb in physics.multibody_joints.multibodies() {
        let root = mb.root().rigid_body_handle();
        multibody_roots.push(root);
    }
    // Zero the floating bases' damping (rapier defaults every DoF to 0.1) and disable
    // contacts inside a multibody: a module's own links overlap at their joints.
    for root in &multibody_roots {
        let mb = root_multibody_mut(&mut physics.multibody_joints, *root);
        mb.set_self_contacts_enabled(false);
        let root_dofs = mb.root().joint().ndofs();
        for d in 0..root_dofs {
            mb.damping_mut()[d] = 0.0;
        }
    }

    let ground_body = physics
        .bodies
        .insert(RigidBodyBuilder::fixed().translation(Vector::new(
            0.0,
            0.0,
            -GROUND_HALF_EXTENTS[2],
        )));
    let ground = physics.colliders.insert_with_parent(
        ColliderBuilder::cuboid(
            GROUND_HALF_EXTENTS[0],
            GROUND_HALF_EXTENTS[1],
            GROUND_HALF_EXTENTS[2],
        )
        .friction(config.ground_friction as f32)
        .friction_combine_rule(CoefficientCombineRule::Min),
        ground_body,
        &mut physics.bodies,
    );

    Ok(Spawned {
        links,
        joints,
        multibody_roots,
        collider_links,
        ground,
    })
}

/// The multibody whose root link is the body `root` (one of [`Spawned::multibody_roots`]).
pub(crate) fn root_multibody_mut(
    multibody_joints: &mut MultibodyJointSet,
    root: RigidBodyHandle,
) -> &mut Multibody {
    let link_id = *multibody_joints
        .rigid_body_link(root)
        .expect("root of a multibody");
    multibody_joints
        .get_multibody_mut(link_id.multibody)
        .expect("multibody exists")
}

/// The pose of a link in the world [m, unit quaternion], from its body's pose.
pub(crate) fn link_pose(physics: &PhysicsWorld, link: &LinkBody) -> Isometry3<f64> {
    to_na_isometry(physics.bodies[link.body].position()) * link.offset
}

/// Places a body at a pose and stops it.
pub(crate) fn place_body(physics: &mut PhysicsWorld, body: RigidBodyHandle, pose: &Isometry3<f64>) {
    let rb = &mut physics.bodies[body];
    rb.set_position(to_rapier_pose(pose), false);
    rb.set_linvel(Vector::ZERO, false);
    rb.set_angvel(Vector::ZERO, false);
}
