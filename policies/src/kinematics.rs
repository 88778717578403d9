//! An arm module's forward kinematics: its tool pose in its own base frame from its joint
//! angles. Used by the arm node (to report its tool pose) and by training (working-pose goals).

use kumi_model::kinematics::{joint_motion, KinematicTree, TreeJoint};
use kumi_model::{ModuleInstance, RobotModel};
use nalgebra::{Isometry3, SMatrix, Vector3, Vector6};

use crate::observation::{Goal, JOINTS};
use crate::rotation::canonical;

/// How much a radian of orientation error weighs against a metre of position error in
/// [`damped_step_rad`] [m/rad]: about what the reward's fine terms trade (`a_of / a_pf`).
pub const STEP_ORIENTATION_WEIGHT_M_PER_RAD: f64 = 0.2;
/// The damping of [`damped_step_rad`] [m]: near a singular pose the step stays bounded.
pub const STEP_DAMPING_M: f64 = 0.05;
/// The longest step [`damped_step_rad`] returns [rad] (its norm over the joints): far from a
/// goal only its direction is given, so near one its values are not lost in the scale of far ones.
pub const STEP_MAX_RAD: f64 = 0.2;
/// The joint-angle difference of the numerical Jacobian [rad].
const JACOBIAN_STEP_RAD: f64 = 1e-6;

/// One joint on the way between two links: its fixed origin, its motion and which of the
/// module's joints drives it (none: a joint of another module, held at 0).
#[derive(Debug, Clone)]
struct ChainJoint {
    joint: TreeJoint,
    angle: Option<usize>,
}

/// The module's forward kinematics: tool pose in the module's base frame from its joints,
/// computed along the joints between the two links only.
#[derive(Debug, Clone)]
pub struct ToolKinematics {
    /// From the links' nearest common ancestor down to the base link, and down to the tool.
    to_base: Vec<ChainJoint>,
    to_tool: Vec<ChainJoint>,
}

impl ToolKinematics {
    /// For `module` of `model`; an error names what is missing.
    pub fn new(model: &RobotModel, module: &ModuleInstance) -> Result<Self, String> {
        let tree = KinematicTree::new(&model.urdf).map_err(|e| e.to_string())?;
        let link = |name: &str| {
            tree.link_index(name)
                .ok_or_else(|| format!("no link `{name}`"))
        };
        let base = link(&module.root_link)?;
        let tool = link(module.ee_link.as_deref().unwrap_or_default())?;
        let joints: Vec<String> = module.position_joints().map(|a| a.joint.clone()).collect();
        // Each link's joints up to the root, nearest first.
        let up = |mut link: usize| {
            let mut path = Vec::new();
            while let Some(j) = tree.joints().iter().position(|j| j.child_link == link) {
                path.push(j);
                link = tree.joints()[j].parent_link;
            }
            path
        };
        let (mut base_up, mut tool_up) = (up(base), up(tool));
        // Drop the joints the two paths share: what is left hangs from the common ancestor.
        while let (Some(a), Some(b)) = (base_up.last(), tool_up.last()) {
            if a != b {
                break;
            }
            base_up.pop();
            tool_up.pop();
        }
        let chain = |path: Vec<usize>| -> Vec<ChainJoint> {
            path.into_iter()
                .rev()
                .map(|j| {
                    let joint = tree.joints()[j].clone();
                    let angle = joints.iter().position(|name| *name == joint.name);
                    ChainJoint { joint, angle }
                })
                .collect()
        };
        Ok(Self {
            to_base: chain(base_up),
            to_tool: chain(tool_up),
        })
    }

    /// The tool pose [m] in the module's base frame for joint angles `q` [rad].
    pub fn tool_pose_b(&self, q: &[f64; JOINTS]) -> Isometry3<f64> {
        let along = |chain: &[ChainJoint]| {
            chain.iter().fold(Isometry3::identity(), |pose, c| {
                let angle = c.angle.map_or(0.0, |i| q[i]);
                pose * c.joint.origin * joint_motion(&c.joint, angle)
            })
        };
        if self.to_base.is_empty() {
            along(&self.to_tool)
        } else {
            along(&self.to_base).inverse() * along(&self.to_tool)
        }
    }
}

/// The tool's error to `goal` at pose `tool_b`, both in the arm base frame: the goal's position
/// less the tool's [m], and the rotation from the tool's orientation to the goal's as a rotation
/// vector [rad]. The observation's tool error and [`damped_step_rad`] both use it.
pub fn tool_error_b(goal: &Goal, tool_b: &Isometry3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    (
        goal.position_b - tool_b.translation.vector,
        canonical(&(goal.orientation_b * tool_b.rotation.inverse())).scaled_axis(),
    )
}

/// [`tool_error_b`] as one vector, the rotation weighed by [`STEP_ORIENTATION_WEIGHT_M_PER_RAD`].
fn weighted_error(goal: &Goal, tool_b: &Isometry3<f64>) -> Vector6<f64> {
    let (dp, rotation) = tool_error_b(goal, tool_b);
    let dr = rotation * STEP_ORIENTATION_WEIGHT_M_PER_RAD;
    Vector6::new(dp.x, dp.y, dp.z, dr.x, dr.y, dr.z)
}

/// The damped least-squares step of the joint angles [rad] from `q` toward `goal`: J^T (J J^T +
/// d^2 I)^-1 e, with e the weighted tool error, J its Jacobian (numerical, forward differences of
/// `tool_pose_b`, the module's forward kinematics) and d [`STEP_DAMPING_M`]; shortened to
/// [`STEP_MAX_RAD`] when longer. Zero at the goal. Joint limits are not considered.
pub fn damped_step_rad(
    tool_pose_b: &dyn Fn(&[f64; JOINTS]) -> Isometry3<f64>,
    q: &[f64; JOINTS],
    goal: &Goal,
) -> [f64; JOINTS] {
    let error = weighted_error(goal, &tool_pose_b(q));
    // The error falls as the tool moves toward the goal: the Jacobian of the pose is minus
    // that of the error.
    let mut jacobian = SMatrix::<f64, 6, JOINTS>::zeros();
    for j in 0..JOINTS {
        let mut moved = *q;
        moved[j] += JACOBIAN_STEP_RAD;
        let column = (error - weighted_error(goal, &tool_pose_b(&moved))) / JACOBIAN_STEP_RAD;
        jacobian.set_column(j, &column);
    }
    let damped = jacobian * jacobian.transpose()
        + SMatrix::<f64, 6, 6>::identity() * (STEP_DAMPING_M * STEP_DAMPING_M);
    let Some(inverse) = damped.try_inverse() else {
        return [0.0; JOINTS];
    };
    let step = jacobian.transpose() * (inverse * error);
    if !step.iter().all(|s| s.is_finite()) {
        return [0.0; JOINTS];
    }
    let scale = (STEP_MAX_RAD / step.norm()).min(1.0);
    std::array::from_fn(|j| step[j] * scale)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::UnitQuaternion;

    /// A stand-in arm: the tool at (q1, q2, q3), turned q4 about x; q5..q7 move nothing.
    fn stand_in(q: &[f64; JOINTS]) -> Isometry3<f64> {
        Isometry3::from_parts(
            Vector3::new(q[0], q[1], q[2]).into(),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), q[3]),
        )
    }

    fn goal(position: [f64; 3], roll_rad: f64) -> Goal {
        Goal {
            position_b: Vector3::from(position),
            orientation_b: UnitQuaternion::from_axis_angle(&Vector3::x_axis(), roll_rad),
        }
    }

    #[test]
    fn the_chain_gives_the_whole_trees_tool_pose_on_every_shipped_arm_module() {
        let library = kumi_model::ModuleLibrary::shipped();
        let mut checked = 0;
        let caterpillar = concat!(env!("CARGO_MANIFEST_DIR"), "/../examples/caterpillar.toml");
        let shipped = kumi_model::SHIPPED_MORPHOLOGIES.map(|(name, _)| name);
        for name in shipped.into_iter().chain([caterpillar]) {
            let model = kumi_model::assemble(
                &kumi_model::load_morphology(name, &library).unwrap(),
                &library,
            );
            let tree = KinematicTree::new(&model.urdf).unwrap();
            for module in model.modules.iter().filter(|m| m.ee_link.is_some()) {
                let joints: Vec<&str> =
                    module.position_joints().map(|a| a.joint.as_str()).collect();
                if joints.len() != JOINTS {
                    continue;
                }
                let fk = ToolKinematics::new(&model, module).unwrap();
                let q = [0.3, -0.7, 1.1, -1.9, 0.4, 1.2, -2.5];
                let poses = tree.forward(
                    &Isometry3::identity(),
                    &tree.positions(joints.iter().copied().zip(q)),
                );
                let link = |name: &str| tree.link_index(name).unwrap();
                let expected = poses[link(&module.root_link)].inverse()
                    * poses[link(module.ee_link.as_deref().unwrap())];
                let found = fk.tool_pose_b(&q);
                let moved = (found.translation.vector - expected.translation.vector).norm();
                let turned = found.rotation.angle_to(&expected.rotation);
                assert!(
                    moved < 1e-12 && turned < 1e-9,
                    "{name}/{}: {moved} m, {turned} rad",
                    module.name
                );
                checked += 1;
            }
        }
        assert!(checked >= 10, "{checked} arm modules checked");
    }

    #[test]
    fn the_step_near_a_goal_is_the_damped_inverse_of_the_error() {
        let step = damped_step_rad(&stand_in, &[0.0; JOINTS], &goal([0.01, -0.02, 0.03], 0.05));
        let d2 = STEP_DAMPING_M * STEP_DAMPING_M;
        let w = STEP_ORIENTATION_WEIGHT_M_PER_RAD;
        let expected = [
            0.01 / (1.0 + d2),
            -0.02 / (1.0 + d2),
            0.03 / (1.0 + d2),
            w * w * 0.05 / (w * w + d2),
            0.0,
            0.0,
            0.0,
        ];
        for (s, e) in step.iter().zip(expected) {
            assert!((s - e).abs() < 1e-6, "{step:?} against {expected:?}");
        }
    }

    #[test]
    fn the_step_is_zero_at_the_goal_and_shortened_far_from_it() {
        let q = [0.3, 0.1, 0.9, 0.4, 0.0, 0.0, 0.0];
        let at = damped_step_rad(&stand_in, &q, &goal([0.3, 0.1, 0.9], 0.4));
        assert!(at.iter().all(|s| s.abs() < 1e-9), "{at:?}");
        let far = damped_step_rad(&stand_in, &q, &goal([1.3, 0.1, 0.9], 0.4));
        let norm = far.iter().map(|s| s * s).sum::<f64>().sqrt();
        assert!((norm - STEP_MAX_RAD).abs() < 1e-12, "{far:?}");
        assert!(
            far[0] > 0.0 && far[1..].iter().all(|s| s.abs() < 1e-6),
            "{far:?}"
        );
    }
}
