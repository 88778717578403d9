//! When the robot has tipped over: the episode's end in training (Table V's thresholds) and
//! the whole-body node's cue to stop driving. One rule for both.

use nalgebra::{UnitQuaternion, Vector3};

/// The base's tilt [rad]: the angle between its z axis and the world's.
pub fn tilt(base_rotation_w: &UnitQuaternion<f64>) -> f64 {
    let z = base_rotation_w * Vector3::z();
    z.z.clamp(-1.0, 1.0).acos()
}

/// Whether the base tilts past `limit_rad` (Table V: Minimal 0.6, Dragon 1.0, Tricycle 0.785).
pub fn fallen(base_rotation_w: &UnitQuaternion<f64>, limit_rad: f64) -> bool {
    tilt(base_rotation_w) > limit_rad
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tilt_is_the_angle_of_the_base_z_axis_from_the_vertical() {
        let level = UnitQuaternion::identity();
        assert_eq!(tilt(&level), 0.0);
        let tipped = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.7);
        assert!((tilt(&tipped) - 0.7).abs() < 1e-12);
        assert!(fallen(&tipped, 0.6)); // Minimal's threshold
        assert!(!fallen(&tipped, 0.785)); // Tricycle's
                                          // Yaw alone is no tilt; upside down is pi.
        let turned = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 3.0);
        assert!(tilt(&turned) < 1e-12);
        let upside_down = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), std::f64::consts::PI);
        assert!((tilt(&upside_down) - std::f64::consts::PI).abs() < 1e-6);
    }
}
