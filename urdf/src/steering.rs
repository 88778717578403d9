//! Wheels that follow their module's steering: when the joint a wheel module hangs from turns
//! it about the vertical (a leg's tip roll), each wheel rolls by the distance its contact is
//! carried sideways instead of being dragged across the ground (one velocity for both wheels
//! drags them). The rule is pure geometry at home, derived once from the model; the servo layer
//! of every engine adds `gain * steering rate` to each wheel's velocity command.

use nalgebra::Vector3;

use crate::assemble::RobotModel;
use crate::kinematics::{JointKind, KinematicTree, TreeJoint};

/// One wheel joint rolling with the joint its module hangs from.
#[derive(Debug, Clone, PartialEq)]
pub struct SteeringCoupling {
    /// The wheel's velocity joint (`wheel0/wheel_left`).
    pub wheel_joint: String,
    /// The position joint the wheel module hangs from (`leg0/joint7`).
    pub steering_joint: String,
    /// Wheel rate per steering rate [(rad/s) / (rad/s)], both about their own joint axes.
    pub gain: f64,
}

/// Gains below this are geometry that does not carry the wheel along its rolling direction (a
/// roll about the axle's own line, as Dragon's rear wheels hang): no coupling.
const MIN_GAIN: f64 = 1e-6;

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
    /// nearest actuated position joint above its module; wheels whose gain is below 1e-6, or
    /// whose link has no cylinder collider (no radius), get none.
    pub fn steering_couplings(&self) -> Vec<SteeringCoupling> {
        let Some((tree, poses)) = self.home_link_poses() else {
            return Vec::new();
        };
        let mut out = Vec::new();
        for m in self.modules.iter().filter(|m| m.follow_steering) {
            let Some(s) = self.steering_joint_above(&tree, &m.root_link) else {
                continue;
            };
            let frame = poses[s.parent_link] * s.origin;
            let axis = frame.rotation * s.axis.into_inner();
            let pivot = frame.translation.vector;
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
                        steering_joint: s.name.clone(),
                        gain,
                    });
                }
            }
        }
        out
    }

    /// The nearest actuated revolute position joint above `link` in `tree`, walking up from it.
    fn steering_joint_above<'t>(
        &self,
        tree: &'t KinematicTree,
        link: &str,
    ) -> Option<&'t TreeJoint> {
        let mut link = tree.link_index(link)?;
        loop {
            let j = tree.joints().iter().find(|j| j.child_link == link)?;
            let actuated = self
                .actuators()
                .any(|a| a.joint == j.name && a.mode == crate::ActuatorMode::Position);
            if j.kind == JointKind::Revolute && actuated {
                return Some(j);
            }
            link = j.parent_link;
        }
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
