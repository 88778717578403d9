//! An arm module's forward kinematics: its tool pose in its own base frame from its joint
//! angles. Used by the arm node (to report its tool pose) and by training (working-pose goals).

use kumi_model::kinematics::{joint_motion, KinematicTree, TreeJoint};
use kumi_model::{ModuleInstance, RobotModel};
use nalgebra::{Isometry3, SMatrix, SVector, Vector3, Vector6};

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
/// How near its limit [rad] a joint starts to drop out of [`damped_step_rad`] when the step would
/// move it toward that limit: its share falls from whole at this distance to none at the limit.
/// Two of the skill's largest increments (0.05 rad each).
pub const STEP_LIMIT_MARGIN_RAD: f64 = 0.1;
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
    /// The module's joint limits [rad], (lower, upper) per joint.
    limits_rad: [(f64, f64); JOINTS],
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
        let limits: Vec<(f64, f64)> = module
            .position_joints()
            .map(|a| (a.lower, a.upper))
            .collect();
        let limits_rad = <[(f64, f64); JOINTS]>::try_from(limits)
            .map_err(|l| format!("{} position joints, not {JOINTS}", l.len()))?;
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
            limits_rad,
        })
    }

    /// The module's joint limits [rad], (lower, upper) per joint.
    pub fn limits_rad(&self) -> &[(f64, f64); JOINTS] {
        &self.limits_rad
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

/// The damped least-squares step of the joint angles [rad] from `q` toward `goal`, within the
/// joint limits `limits_rad` ((lower, upper) per joint): J^T (J J^T + d^2 I)^-1 e, with e the
/// weighted tool error, J its Jacobian (numerical, forward differences of `tool_pose_b`, the
/// module's forward kinematics) and d [`STEP_DAMPING_M`]; shortened to [`STEP_MAX_RAD`] when
/// longer. Zero at the goal.
///
/// A joint that the step would move toward a limit less than [`STEP_LIMIT_MARGIN_RAD`] away
/// gives up its share in proportion (its Jacobian column and its step weighed by its room over
/// the margin), and the other joints take up the motion: at a limit the step points where the
/// arm can still go, instead of into the limit.
pub fn damped_step_rad(
    tool_pose_b: &dyn Fn(&[f64; JOINTS]) -> Isometry3<f64>,
    limits_rad: &[(f64, f64); JOINTS],
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
    let Some(free) = damped_solve(&jacobian, &error, &[1.0; JOINTS]) else {
        return [0.0; JOINTS];
    };
    let Some(step) = damped_solve(&jacobian, &error, &limit_weights(limits_rad, q, &free)) else {
        return [0.0; JOINTS];
    };
    let scale = (STEP_MAX_RAD / step.norm()).min(1.0);
    std::array::from_fn(|j| step[j] * scale)
}

/// Each joint's share of a step: its room [rad] toward the limit the `free` step moves it to,
/// over [`STEP_LIMIT_MARGIN_RAD`], within [0, 1].
fn limit_weights(
    limits_rad: &[(f64, f64); JOINTS],
    q: &[f64; JOINTS],
    free: &SVector<f64, JOINTS>,
) -> [f64; JOINTS] {
    std::array::from_fn(|j| {
        let (lower, upper) = limits_rad[j];
        let room = if free[j] > 0.0 {
            upper - q[j]
        } else {
            q[j] - lower
        };
        (room / STEP_LIMIT_MARGIN_RAD).clamp(0.0, 1.0)
    })
}

/// The damped least-squares solution W (J W)^T ((J W)(J W)^T + d^2 I)^-1 e with W the joints'
/// `weights` on the diagonal; `None` when it is not finite.
fn damped_solve(
    jacobian: &SMatrix<f64, 6, JOINTS>,
    error: &Vector6<f64>,
    weights: &[f64; JOINTS],
) -> Option<SVector<f64, JOINTS>> {
    let w = SMatrix::<f64, JOINTS, JOINTS>::from_diagonal(&SVector::from(*weights));
    let weighted = jacobian * w;
    let damped = weighted * weighted.transpose()
        + SMatrix::<f64, 6, 6>::identity() * (STEP_DAMPING_M * STEP_DAMPING_M);
    let step = w * weighted.transpose() * (damped.try_inverse()? * error);
    step.iter().all(|s| s.is_finite()).then_some(step)
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

    /// Limits no test reaches.
    const FREE: [(f64, f64); JOINTS] = [(-10.0, 10.0); JOINTS];

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
        let step = damped_step_rad(
            &stand_in,
            &FREE,
            &[0.0; JOINTS],
            &goal([0.01, -0.02, 0.03], 0.05),
        );
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
        let at = damped_step_rad(&stand_in, &FREE, &q, &goal([0.3, 0.1, 0.9], 0.4));
        assert!(at.iter().all(|s| s.abs() < 1e-9), "{at:?}");
        let far = damped_step_rad(&stand_in, &FREE, &q, &goal([1.3, 0.1, 0.9], 0.4));
        let norm = far.iter().map(|s| s * s).sum::<f64>().sqrt();
        assert!((norm - STEP_MAX_RAD).abs() < 1e-12, "{far:?}");
        assert!(
            far[0] > 0.0 && far[1..].iter().all(|s| s.abs() < 1e-6),
            "{far:?}"
        );
    }

    #[test]
    fn a_joint_at_its_limit_leaves_the_step_to_the_others() {
        // Two joints move the tool along x, one alone along y.
        let redundant = |q: &[f64; JOINTS]| Isometry3::translation(q[0] + q[1], q[2], 0.0);
        let toward = goal([0.05, 0.0, 0.0], 0.0);
        let mut limits = FREE;
        limits[0] = (-1.0, 0.0);
        let free = damped_step_rad(&redundant, &FREE, &[0.0; JOINTS], &toward);
        assert!(
            (free[0] - free[1]).abs() < 1e-9 && free[0] > 0.02,
            "{free:?}"
        );
        // Joint 1 at its upper limit: the whole x motion goes to joint 2.
        let held = damped_step_rad(&redundant, &limits, &[0.0; JOINTS], &toward);
        assert!(held[0].abs() < 1e-12, "{held:?}");
        assert!((held[1] - 0.05).abs() < 2e-3, "{held:?}");
        // Half the margin from the limit: half a share.
        let q = [-STEP_LIMIT_MARGIN_RAD / 2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
        let near = damped_step_rad(&redundant, &limits, &q, &goal([0.0, 0.0, 0.0], 0.0));
        assert!(near[0] > 0.0 && near[0] < near[1], "{near:?}");
        // Away from the limit it moves freely.
        let away = damped_step_rad(
            &redundant,
            &limits,
            &[0.0; JOINTS],
            &goal([-0.05, 0.0, 0.0], 0.0),
        );
        assert!(
            (away[0] - away[1]).abs() < 1e-9 && away[0] < -0.02,
            "{away:?}"
        );
    }
}
