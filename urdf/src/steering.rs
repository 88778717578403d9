//! Wheels that follow their module's steering: when the joint a wheel module hangs from turns
//! it about the vertical (a leg's tip roll), each wheel rolls by the distance its contact is
//! carried sideways instead of being dragged across the ground (one velocity for both wheels
//! drags them). Whatever else turns the module about that axis drags them alike: other joints
//! of the leg whose axes share its direction, and the base's own turning. So the rate followed
//! is the module's turn about the steering axis ([`crate::commands::steering_turn_rate`]): the
//! commanded rates of those joints, each by its share of the axis, plus the base's angular
//! velocity about it. The rule is pure geometry at home, derived once from the model; the servo
//! layer of every engine adds `gain * turn rate` to each wheel's velocity command.

use nalgebra::Vector3;

use crate::assemble::RobotModel;
use crate::kinematics::{JointKind, KinematicTree, TreeJoint};

/// One wheel joint rolling with its module's turns about the joint it hangs from.
#[derive(Debug, Clone, PartialEq)]
pub struct SteeringCoupling {
    /// The wheel's velocity joint (`wheel0/wheel_left`).
    pub wheel_joint: String,
    /// Wheel rate per turn rate of its module about the steering axis [(rad/s) / (rad/s)],
    /// both about their own axes.
    pub gain: f64,
    /// The steering joint's axis in the base frame at home (unit): the base's turning about
    /// it turns the wheel module as the joint does.
    pub axis_b: Vector3<f64>,
    /// Every actuated revolute position joint above the module that turns it about the
    /// steering axis, nearest first (the steering joint, share 1), with its share: its own axis
    /// dotted with the steering axis at home (shares below 1e-6 are left out). Tricycle's legs:
    /// `joint7` and `joint5`, both 1.
    pub turning_joints: Vec<(String, f64)>,
}

impl SteeringCoupling {
    /// The position joint the wheel module hangs from (`leg0/joint7`): the nearest of its
    /// turning joints.
    pub fn steering_joint(&self) -> &str {
        &self.turning_joints[0].0
    }
}

/// Gains below this are geometry that does not carry the wheel along its rolling direction (a
/// roll about the axle's own line, as Dragon's rear wheels hang): no coupling.
const MIN_GAIN: f64 = 1e-6;

/// Shares below this are joints whose axes lie across the steering axis (a leg's pitches and
/// the rolls along its length): they do not turn the module about it.
const MIN_SHARE: f64 = 1e-6;

/// The wheel rate [rad/s per rad/s of steering] that keeps a wheel rolling, not sliding, when a
/// joint turns it: the wheel centre `centre` moves at `axis x (centre - pivot)` per rad/s of the
/// steering joint (axis `axis` through `pivot`), and a wheel turning at 1 rad/s about its axle
/// `axle` rolls its centre `radius` metres per second along `axle x up`. All vectors in one frame
/// (the base at home); `up` is the ground normal; `radius` [m].
pub fn rolling_gain(
    axis: &Vector3<f64>,
    pivot: &Vector3<f64>,
    centre: &Vector3<f64>,
    axle: &Vector3<f64>,
    up: &Vector3<f64>,
    radius: f64,
) -> f64 {
    axis.cross(&(centre - pivot)).dot(&axle.cross(up)) / radius
}

impl RobotModel {
    /// The steering couplings of every wheel module whose morphology entry sets
    /// `follow_steering`, at home, in actuator order of the wheels. A wheel is coupled to the
    /// nearest actuated position joint above its module (its gain and axis) and turns with
    /// every such joint whose axis shares that one's direction; wheels whose gain is below
    /// 1e-6, or whose link has no cylinder collider (no radius), get none.
    pub fn steering_couplings(&self) -> Vec<SteeringCoupling> {
        let Some((tree, poses)) = self.home_link_poses() else {
            return Vec::new();
        };
        let mut out = Vec::new();
        for m in self.modules.iter().filter(|m| m.follow_steering) {
            let above = self.position_joints_above(&tree, &m.root_link);
            let Some(s) = above.first() else {
                continue;
            };
            let frame = poses[s.parent_link] * s.origin;
            let axis = frame.rotation * s.axis.into_inner();
            let pivot = frame.translation.vector;
            let turning_joints: Vec<(String, f64)> = above
                .iter()
                .map(|j| {
                    let axis_j = (poses[j.parent_link] * j.origin).rotation * j.axis.into_inner();
                    (j.name.clone(), axis_j.dot(&axis))
                })
                .filter(|(_, share)| share.abs() >= MIN_SHARE)
                .collect();
            for wheel in m.velocity_joints() {
                let Some(w) = tree.joint_index(&wheel.joint).map(|i| &tree.joints()[i]) else {
                    continue;
                };
                let Some(radius) = self.wheel_radius(&tree.links()[w.child_link]) else {
                    continue;
                };
                let wheel_frame = poses[w.parent_link] * w.origin;
                let gain = rolling_gain(
                    &axis,
                    &pivot,
                    &wheel_frame.translation.vector,
                    &(wheel_frame.rotation * w.axis.into_inner()),
                    &Vector3::z(),
                    radius,
                );
                if gain.abs() >= MIN_GAIN {
                    out.push(SteeringCoupling {
                        wheel_joint: wheel.joint.clone(),
                        gain,
                        axis_b: axis,
                        turning_joints: turning_joints.clone(),
                    });
                }
            }
        }
        out
    }

    /// The actuated revolute position joints above `link` in `tree`, walking up from it:
    /// nearest first.
    fn position_joints_above<'t>(&self, tree: &'t KinematicTree, link: &str) -> Vec<&'t TreeJoint> {
        let mut out = Vec::new();
        let Some(mut link) = tree.link_index(link) else {
            return out;
        };
        while let Some(j) = tree.joints().iter().find(|j| j.child_link == link) {
            let actuated = self
                .actuators()
                .any(|a| a.joint == j.name && a.mode == crate::ActuatorMode::Position);
            if j.kind == JointKind::Revolute && actuated {
                out.push(j);
            }
            link = j.parent_link;
        }
        out
    }

    /// The largest cylinder collider radius [m] of a link: its tyre.
    fn wheel_radius(&self, link: &str) -> Option<f64> {
        self.urdf
            .links
            .iter()
            .find(|l| l.name == link)?
            .collision
            .iter()
            .filter_map(|c| match c.geometry {
                urdf_rs::Geometry::Cylinder { radius, .. } => Some(radius),
                _ => None,
            })
            .reduce(f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_wheel_beside_a_vertical_pivot_rolls_by_its_offset_over_its_radius() {
        // Pivot at the origin turning about +z; the wheel 0.3 m along +y with its axle along y,
        // radius 0.25 m. Turning at 1 rad/s carries the centre along -x at 0.3 m/s; a wheel
        // turning positively about +y rolls along y x z = +x: the wheel must turn at
        // -0.3 / 0.25 = -1.2 rad/s.
        let g = rolling_gain(
            &Vector3::z(),
            &Vector3::zeros(),
            &Vector3::new(0.0, 0.3, 0.0),
            &Vector3::y(),
            &Vector3::z(),
            0.25,
        );
        assert!((g + 1.2).abs() < 1e-12, "{g}");
        // The wheel on the other side turns the other way.
        let g = rolling_gain(
            &Vector3::z(),
            &Vector3::zeros(),
            &Vector3::new(0.0, -0.3, 0.0),
            &Vector3::y(),
            &Vector3::z(),
            0.25,
        );
        assert!((g - 1.2).abs() < 1e-12, "{g}");
    }

    #[test]
    fn a_roll_about_a_horizontal_line_through_the_axle_needs_no_rolling() {
        // Dragon's rear wheels: the pivot axis along x, the wheels beside it along y. The
        // centres move vertically, not along the rolling direction.
        let g = rolling_gain(
            &Vector3::x(),
            &Vector3::zeros(),
            &Vector3::new(-0.15, 0.286, 0.0),
            &Vector3::y(),
            &Vector3::z(),
            0.27,
        );
        assert!(g.abs() < 1e-12, "{g}");
    }
}
