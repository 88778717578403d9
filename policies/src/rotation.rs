//! Orientation error by the quaternion log map.

use nalgebra::UnitQuaternion;

/// The angle [rad, 0..=pi] of the rotation from `reference` to `actual`: for a unit quaternion
/// q = (cos(theta/2), sin(theta/2) n), |log q| = theta/2, so this is 2 |log(reference^-1 actual)|.
/// Independent of the quaternions' signs (q and -q are the same rotation).
pub fn orientation_error(reference: &UnitQuaternion<f64>, actual: &UnitQuaternion<f64>) -> f64 {
    let relative = reference.inverse() * actual;
    // |w| handles the double cover; clamp guards rounding just above 1.
    2.0 * relative.w.abs().min(1.0).acos()
}

/// The quaternion with the same rotation and a non-negative scalar part: q and -q are the same
/// rotation, and a policy should see one of them only.
pub fn canonical(q: &UnitQuaternion<f64>) -> UnitQuaternion<f64> {
    if q.w < 0.0 {
        UnitQuaternion::new_unchecked(-q.into_inner())
    } else {
        *q
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;
    use std::f64::consts::{FRAC_PI_2, PI};

    #[test]
    fn hand_computed_angles() {
        let id = UnitQuaternion::identity();
        assert_eq!(orientation_error(&id, &id), 0.0);
        let quarter = UnitQuaternion::from_axis_angle(&Vector3::x_axis(), FRAC_PI_2);
        assert!((orientation_error(&id, &quarter) - FRAC_PI_2).abs() < 1e-12);
        // 0.3 about z then 0.5 more about z: 0.5 apart.
        let a = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.3);
        let b = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.8);
        assert!((orientation_error(&a, &b) - 0.5).abs() < 1e-12);
        // A half turn is pi, the largest error.
        let half = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), PI);
        assert!((orientation_error(&id, &half) - PI).abs() < 1e-9);
    }

    #[test]
    fn sign_of_the_quaternion_does_not_matter() {
        let a = UnitQuaternion::from_euler_angles(0.3, -0.7, 1.1);
        let b = UnitQuaternion::from_euler_angles(-0.2, 0.4, 0.9);
        let minus_b = UnitQuaternion::new_unchecked(-b.into_inner());
        assert!((orientation_error(&a, &b) - orientation_error(&a, &minus_b)).abs() < 1e-12);
        assert!(canonical(&minus_b).w >= 0.0);
        assert!(canonical(&minus_b).angle_to(&b) < 1e-12);
    }
}
