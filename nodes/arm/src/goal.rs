//! Goal intake: a `geometry_msgs/PoseStamped` in the module's base frame, checked before it can
//! reach the policy.

use kumi_msgs::geometry_msgs::PoseStamped;
use kumi_policies::observation::Goal;
use kumi_ros::geometry::PoseError;

/// Goals further than the arm's reach plus this margin [m] are refused. It covers every goal
/// a shipped whole-body policy can send: Dragon's leg stands straight up, its home tool at its
/// full reach (1.46 m), and its goals may lie up to 0.17 m further (0.1 m along each axis); a
/// margin of 0.1 m refused them all and left the leg without goals (`tests/tests/
/// whole_body_node_consistency.rs` checks every shipped robot's furthest goals).
pub const WORKSPACE_MARGIN: f64 = 0.3;

/// An arm's reach [m]: the distance from its base to its tool with every joint at zero
/// (stretched out).
pub fn reach_m(kinematics: &kumi_policies::kinematics::ToolKinematics) -> f64 {
    kinematics
        .tool_pose_b(&[0.0; kumi_policies::observation::JOINTS])
        .translation
        .vector
        .norm()
}

/// Why a goal was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GoalRejection {
    #[error("goal is not a pose: {0}")]
    NotAPose(#[from] PoseError),
    #[error(
        "goal is in frame `{found}`; this node takes goals in `{expected}` (or an empty frame id)"
    )]
    UnknownFrame { found: String, expected: String },
    #[error("goal is {distance:.2} m from the arm base, beyond its reach of {reach:.2} m")]
    OutOfReach { distance: f64, reach: f64 },
}

/// What a goal must satisfy for one module.
#[derive(Debug, Clone, PartialEq)]
pub struct GoalRules {
    /// Frame ids accepted as the module's base frame (besides the empty one).
    pub frames: Vec<String>,
    /// The arm's reach from its base [m].
    pub reach: f64,
}

impl GoalRules {
    /// Checks and converts a goal message: a pose by the one rule for every pose
    /// ([`kumi_ros::geometry::isometry`]), in the module's base frame, within reach.
    pub fn accept(&self, msg: &PoseStamped) -> Result<Goal, GoalRejection> {
        let frame = &msg.header.frame_id;
        if !frame.is_empty() && !self.frames.iter().any(|f| f == frame) {
            return Err(GoalRejection::UnknownFrame {
                found: frame.clone(),
                expected: self.frames.first().cloned().unwrap_or_default(),
            });
        }
        let pose = kumi_ros::geometry::isometry(&msg.pose)?;
        let position = pose.translation.vector;
        let distance = position.norm();
        if distance > self.reach + WORKSPACE_MARGIN {
            return Err(GoalRejection::OutOfReach {
                distance,
                reach: self.reach,
            });
        }
        Ok(Goal {
            position_b: position,
            orientation_b: pose.rotation,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kumi_msgs::geometry_msgs::{Point, Pose, Quaternion as Q};
    use kumi_msgs::std_msgs::Header;

    fn rules() -> GoalRules {
        GoalRules {
            frames: vec!["arm/base".into(), "robot/arm/base".into()],
            reach: 1.4,
        }
    }

    fn msg(frame: &str, p: [f64; 3], q: [f64; 4]) -> PoseStamped {
        PoseStamped {
            header: Header {
                frame_id: frame.into(),
                ..Default::default()
            },
            pose: Pose {
                position: Point {
                    x: p[0],
                    y: p[1],
                    z: p[2],
                },
                orientation: Q {
                    w: q[0],
                    x: q[1],
                    y: q[2],
                    z: q[3],
                },
            },
        }
    }

    #[test]
    fn accepts_good_goals_in_known_frames() {
        let g = rules()
            .accept(&msg("", [0.3, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0]))
            .unwrap();
        assert_eq!(g.position_b, nalgebra::Vector3::new(0.3, 0.0, 1.0));
        assert!(rules()
            .accept(&msg(
                "robot/arm/base",
                [0.3, 0.0, 1.0],
                [0.0, 1.0, 0.0, 0.0]
            ))
            .is_ok());
    }

    #[test]
    fn normalises_near_unit_quaternions() {
        let g = rules()
            .accept(&msg("", [0.3, 0.0, 1.0], [1.05, 0.0, 0.0, 0.0]))
            .unwrap();
        assert!((g.orientation_b.into_inner().norm() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn refuses_bad_goals_with_a_reason() {
        let r = rules();
        assert_eq!(
            r.accept(&msg("", [f64::NAN, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0])),
            Err(GoalRejection::NotAPose(PoseError::NonFinite))
        );
        assert_eq!(
            r.accept(&msg("", [0.3, 0.0, 1.0], [0.0, 0.0, 0.0, 0.0])),
            Err(GoalRejection::NotAPose(PoseError::NotARotation(0.0)))
        );
        assert!(matches!(
            r.accept(&msg("map", [0.3, 0.0, 1.0], [1.0, 0.0, 0.0, 0.0])),
            Err(GoalRejection::UnknownFrame { .. })
        ));
        let far = r
            .accept(&msg("", [3.0, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]))
            .unwrap_err();
        assert_eq!(
            far.to_string(),
            "goal is 3.00 m from the arm base, beyond its reach of 1.40 m"
        );
    }
}
