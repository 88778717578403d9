//! Target intake: the tool's target as a `geometry_msgs/PoseStamped` in `<robot>/odom`;
//! position and heading (the yaw of the pose's x axis) are used, as in training.

use kumi_msgs::geometry_msgs::PoseStamped;
use kumi_ros::geometry::PoseError;
use kumi_terms::observation::tool_yaw;
use kumi_terms::Target;

/// Why a target was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TargetRejection {
    #[error("target is not a pose: {0}")]
    NotAPose(#[from] PoseError),
    #[error("target is in frame `{found}`; this node takes targets in `{expected}` (or an empty frame id)")]
    UnknownFrame { found: String, expected: String },
    #[error("target is {distance_m:.2} m from the robot's base, more than the {limit_m:.1} m this node accepts")]
    TooFar { distance_m: f64, limit_m: f64 },
}

/// Reads a target; `odom_frame` is the frame it must be in (an empty frame id is taken as
/// it). Targets further than `max_distance_m` horizontally from `base_xy` (when known) are
/// refused: the policy never saw them.
pub fn accept(
    msg: &PoseStamped,
    odom_frame: &str,
    base_xy: Option<[f64; 2]>,
    max_distance_m: f64,
) -> Result<Target, TargetRejection> {
    let frame = &msg.header.frame_id;
    if !frame.is_empty() && frame != odom_frame {
        return Err(TargetRejection::UnknownFrame {
            found: frame.clone(),
            expected: odom_frame.to_string(),
        });
    }
    let pose = kumi_ros::geometry::isometry(&msg.pose)?;
    let p = pose.translation.vector;
    if let Some([x, y]) = base_xy {
        let distance_m = (p.x - x).hypot(p.y - y);
        if distance_m > max_distance_m {
            return Err(TargetRejection::TooFar {
                distance_m,
                limit_m: max_distance_m,
            });
        }
    }
    Ok(Target {
        position_w: p,
        yaw: tool_yaw(&pose.rotation),
    })
}

/// How far ahead [s] of the robot's clock a target's stamp may be for the target to wait for
/// that time. A stamp further ahead is another clock's (a wall-clock stamp sent to a
/// simulator): such a target, like one stamped zero or in the past, applies at once.
pub const SCHEDULE_HORIZON_S: f64 = 60.0;

/// When a target stamped `stamp_s` [s] takes effect, the robot's clock standing at `clock_s`
/// (the latest state's stamp; `None` before any): at its stamp when that is ahead of the
/// clock by at most [`SCHEDULE_HORIZON_S`] (`Some`), else at once (`None`). A run that stamps
/// each target with the time it should start is repeatable in lockstep, whenever the target
/// is sent.
pub fn starts_at(stamp_s: f64, clock_s: Option<f64>) -> Option<f64> {
    let clock_s = clock_s?;
    (stamp_s > clock_s && stamp_s <= clock_s + SCHEDULE_HORIZON_S).then_some(stamp_s)
}

/// Whether a state stamped `stamp_s` [s] is at or past a target's start `at_s` [s] (within a
/// microsecond: stamps are whole nanoseconds).
pub fn has_started(stamp_s: f64, at_s: f64) -> bool {
    stamp_s + 1e-6 >= at_s
}

#[cfg(test)]
mod tests {
    use super::*;
    use kumi_msgs::geometry_msgs::{Point, Pose, Quaternion};
    use kumi_msgs::std_msgs::Header;

    fn msg(frame: &str, x: f64, yaw: f64) -> PoseStamped {
        PoseStamped {
            header: Header {
                frame_id: frame.into(),
                ..Default::default()
            },
            pose: Pose {
                position: Point { x, y: 1.0, z: 1.2 },
                orientation: Quaternion {
                    x: 0.0,
                    y: 0.0,
                    z: (yaw / 2.0).sin(),
                    w: (yaw / 2.0).cos(),
                },
            },
        }
    }

    #[test]
    fn position_and_heading_are_read() {
        let t = accept(&msg("r/odom", 2.0, 0.7), "r/odom", None, 5.0).unwrap();
        assert_eq!(t.position_w.x, 2.0);
        assert!((t.yaw - 0.7).abs() < 1e-12);
        assert!(accept(&msg("", 2.0, -3.0), "r/odom", Some([0.0, 0.0]), 5.0).is_ok());
    }

    #[test]
    fn a_target_stamped_ahead_of_the_clock_waits_for_its_time() {
        assert_eq!(starts_at(4.0, Some(3.0)), Some(4.0));
        assert_eq!(starts_at(0.0, Some(3.0)), None, "stamped zero: at once");
        assert_eq!(starts_at(2.0, Some(3.0)), None, "in the past: at once");
        assert_eq!(starts_at(3.0, Some(3.0)), None, "now: at once");
        assert_eq!(starts_at(4.0, None), None, "no clock yet: at once");
        assert_eq!(
            starts_at(1.7e9, Some(3.0)),
            None,
            "a wall-clock stamp against sim time: at once"
        );
        assert!(has_started(4.0, 4.0) && has_started(4.0 - 1e-9, 4.0));
        assert!(!has_started(4.0 - 1.0 / 30.0, 4.0));
    }

    #[test]
    fn bad_targets_are_refused() {
        assert!(matches!(
            accept(&msg("world", 0.0, 0.0), "r/odom", None, 5.0),
            Err(TargetRejection::UnknownFrame { .. })
        ));
        assert_eq!(
            accept(&msg("", f64::NAN, 0.0), "r/odom", None, 5.0),
            Err(TargetRejection::NotAPose(PoseError::NonFinite))
        );
        // The arm node's rule: a quaternion far from unit length is not a rotation.
        let mut tiny = msg("", 0.0, 0.0);
        tiny.pose.orientation.w = 1e-9;
        assert_eq!(
            accept(&tiny, "r/odom", None, 5.0),
            Err(TargetRejection::NotAPose(PoseError::NotARotation(1e-9)))
        );
        assert!(matches!(
            accept(&msg("", 9.0, 0.0), "r/odom", Some([0.0, 0.0]), 5.0),
            Err(TargetRejection::TooFar { .. })
        ));
    }
}
