//! The low-level policy's observation: Table I's joint angles, joint velocities, goal position
//! and goal orientation (the goal in the arm's base frame), then how far each joint's position
//! target leads its angle, then how far the tool is from the goal.
//!
//! The skill moves the servo targets by increments; the joints follow with a lag, and under
//! load they sag below their targets. Without the lead a policy at its goal cannot tell
//! whether its targets are ahead of the joints or behind them, so it cannot command "stay".
//! The tool's error is the forward kinematics of the measured angles
//! ([`crate::kinematics::ToolKinematics`]) set against the goal: without it the policy has to
//! learn the arm's kinematics to tell how far it still has to go.
//!
//! The joint step is the damped least-squares step toward the goal
//! ([`crate::kinematics::damped_step_rad`]): the tool's error mapped back to the joints, which a
//! network finds hard to learn to the last centimetre.
//!
//! Each format reads a prefix of one layout: `kumi-skill/arm-reach/1` the first 21 values
//! ([`BASE_DIM`], Table I's), `/2` the first 28 ([`LEAD_DIM`], with the lead), `/3` the first 34
//! ([`TOOL_DIM`], with the tool's error), `/4` all [`OBSERVATION_DIM`].

use nalgebra::{Isometry3, UnitQuaternion, Vector3};

use crate::kinematics::{damped_step_rad, tool_error_b};
use crate::rotation::canonical;

/// Joints of an arm module.
pub const JOINTS: usize = 7;
/// Length of the observation.
pub const OBSERVATION_DIM: usize = 41;
/// Length of Table I's part (joints, velocities, goal): what a skill of format
/// `kumi-skill/arm-reach/1` reads.
pub const BASE_DIM: usize = 21;
/// Length of Table I's part and the targets' lead: what a skill of format
/// `kumi-skill/arm-reach/2` reads.
pub const LEAD_DIM: usize = 28;
/// Length of the values up to the tool's error: what a skill of format
/// `kumi-skill/arm-reach/3` reads.
pub const TOOL_DIM: usize = 34;

/// Name of each observation entry, in order (written into the exported policy's metadata).
pub const OBSERVATION_NAMES: [&str; OBSERVATION_DIM] = [
    "q1",
    "q2",
    "q3",
    "q4",
    "q5",
    "q6",
    "q7", // joint angles [rad]
    "qd1",
    "qd2",
    "qd3",
    "qd4",
    "qd5",
    "qd6",
    "qd7", // joint velocities [rad/s]
    "goal_x",
    "goal_y",
    "goal_z", // goal position in the arm base frame [m]
    "goal_qw",
    "goal_qx",
    "goal_qy",
    "goal_qz", // goal orientation in the arm base frame, w >= 0
    "lead1",
    "lead2",
    "lead3",
    "lead4",
    "lead5",
    "lead6",
    "lead7", // position target less joint angle [rad]
    "tool_to_goal_x",
    "tool_to_goal_y",
    "tool_to_goal_z", // goal position less tool position, arm base frame [m]
    "tool_to_goal_rx",
    "tool_to_goal_ry",
    "tool_to_goal_rz", // tool to goal rotation, a rotation vector in the base frame [rad]
    "step1",
    "step2",
    "step3",
    "step4",
    "step5",
    "step6",
    "step7", // damped least-squares joint step toward the goal [rad]
];

/// A reaching goal for the tool frame, in the arm base frame (`_b`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Goal {
    /// Tool position [m].
    pub position_b: Vector3<f64>,
    /// Tool orientation.
    pub orientation_b: UnitQuaternion<f64>,
}

/// Builds the observation: `q` [rad] and `qd` [rad/s] in the module's joint order, the goal in
/// the arm base frame, the joints' position targets [rad] (what the servos are commanded
/// to, which the skill's increments move), and the module's forward kinematics
/// (`tool_pose_b`: the tool pose in the arm base frame from joint angles) and joint limits
/// (`limits_rad`, (lower, upper) per joint), which give the tool's error and the joint step
/// ([`damped_step_rad`]). The goal quaternion is written with a non-negative
/// scalar part. Values are rounded to f32 here, once, for both training and deployment.
pub fn build(
    q: &[f64; JOINTS],
    qd: &[f64; JOINTS],
    targets: &[f64; JOINTS],
    goal: &Goal,
    tool_pose_b: &dyn Fn(&[f64; JOINTS]) -> Isometry3<f64>,
    limits_rad: &[(f64, f64); JOINTS],
) -> [f32; OBSERVATION_DIM] {
    let mut obs = [0.0_f32; OBSERVATION_DIM];
    for i in 0..JOINTS {
        obs[i] = q[i] as f32;
        obs[JOINTS + i] = qd[i] as f32;
        obs[BASE_DIM + i] = (targets[i] - q[i]) as f32;
    }
    let p = goal.position_b;
    obs[14] = p.x as f32;
    obs[15] = p.y as f32;
    obs[16] = p.z as f32;
    let o = canonical(&goal.orientation_b);
    obs[17] = o.w as f32;
    obs[18] = o.i as f32;
    obs[19] = o.j as f32;
    obs[20] = o.k as f32;
    let (to_goal_b, rotation_b) = tool_error_b(goal, &tool_pose_b(q));
    for i in 0..3 {
        obs[LEAD_DIM + i] = to_goal_b[i] as f32;
        obs[LEAD_DIM + 3 + i] = rotation_b[i] as f32;
    }
    for (j, step) in damped_step_rad(tool_pose_b, limits_rad, q, goal)
        .iter()
        .enumerate()
    {
        obs[TOOL_DIM + j] = *step as f32;
    }
    obs
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_joints_velocities_position_quaternion_lead_tool_error() {
        let q = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7];
        let qd = [-1.0, -2.0, -3.0, -4.0, -5.0, -6.0, -7.0];
        // A goal whose quaternion comes in with w < 0: the observation flips it.
        let r = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.5);
        let goal = Goal {
            position_b: Vector3::new(0.25, -0.125, 1.0),
            orientation_b: UnitQuaternion::new_unchecked(-r.into_inner()),
        };
        let targets = [0.1, 0.25, 0.3, 0.4, 0.5, 0.6, 0.5];
        // The tool 0.1 m short in x and turned 0.2 rad about z: 0.3 rad short of the goal.
        let tool_b = Isometry3::from_parts(
            Vector3::new(0.15, -0.125, 1.0).into(),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.2),
        );
        let obs = build(
            &q,
            &qd,
            &targets,
            &goal,
            &|_| tool_b,
            &[(-3.0, 3.0); JOINTS],
        );
        assert_eq!(&obs[..7], &[0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7]);
        assert_eq!(&obs[7..14], &[-1.0, -2.0, -3.0, -4.0, -5.0, -6.0, -7.0]);
        assert_eq!(&obs[14..17], &[0.25, -0.125, 1.0]);
        // cos(0.25), 0, 0, sin(0.25)
        assert_eq!(obs[17], 0.25_f64.cos() as f32);
        assert_eq!(&obs[18..20], &[0.0, 0.0]);
        assert_eq!(obs[20], 0.25_f64.sin() as f32);
        assert_eq!(OBSERVATION_NAMES[14], "goal_x");
        let lead: Vec<f32> = (0..JOINTS).map(|i| (targets[i] - q[i]) as f32).collect();
        assert_eq!(&obs[BASE_DIM..LEAD_DIM], lead.as_slice());
        assert_eq!(obs[BASE_DIM], 0.0);
        assert_eq!(OBSERVATION_NAMES[BASE_DIM], "lead1");
        assert_eq!(OBSERVATION_NAMES[LEAD_DIM], "tool_to_goal_x");
        let close = |a: &[f32], b: &[f32]| a.iter().zip(b).all(|(a, b)| (a - b).abs() < 1e-6);
        assert!(
            close(&obs[LEAD_DIM..LEAD_DIM + 3], &[0.1, 0.0, 0.0]),
            "{obs:?}"
        );
        assert!(
            close(&obs[LEAD_DIM + 3..TOOL_DIM], &[0.0, 0.0, 0.3]),
            "{obs:?}"
        );
        assert_eq!(OBSERVATION_NAMES[TOOL_DIM], "step1");
        // A tool the joints do not move has no step.
        assert_eq!(&obs[TOOL_DIM..], &[0.0; JOINTS]);
    }

    #[test]
    fn a_tool_at_its_goal_has_no_error_whichever_sign_the_quaternions_take() {
        let r = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 2.5);
        let goal = Goal {
            position_b: Vector3::new(0.3, 0.2, 0.9),
            orientation_b: UnitQuaternion::new_unchecked(-r.into_inner()),
        };
        let tool_b = Isometry3::from_parts(Vector3::new(0.3, 0.2, 0.9).into(), r);
        let obs = build(
            &[0.0; JOINTS],
            &[0.0; JOINTS],
            &[0.0; JOINTS],
            &goal,
            &|_| tool_b,
            &[(-3.0, 3.0); JOINTS],
        );
        assert!(obs[LEAD_DIM..].iter().all(|v| v.abs() < 1e-6), "{obs:?}");
    }
}
