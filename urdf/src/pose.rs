//! Conversions between URDF origins (`xyz`, `rpy`) and nalgebra isometries.
//!
//! URDF's `rpy` is fixed-axis roll, pitch, yaw: R = Rz(yaw) Ry(pitch) Rx(roll), which is what
//! [`UnitQuaternion::from_euler_angles`] builds.

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// The isometry of a URDF origin: translation [m] and fixed-axis roll, pitch, yaw [rad].
pub fn isometry(xyz: [f64; 3], rpy: [f64; 3]) -> Isometry3<f64> {
    Isometry3::from_parts(
        Translation3::new(xyz[0], xyz[1], xyz[2]),
        UnitQuaternion::from_euler_angles(rpy[0], rpy[1], rpy[2]),
    )
}

/// The isometry of a parsed URDF `<origin>`.
pub fn from_urdf(origin: &urdf_rs::Pose) -> Isometry3<f64> {
    isometry(origin.xyz.0, origin.rpy.0)
}

/// Fixed-axis roll, pitch, yaw [rad] of a rotation, robust at gimbal lock (pitch = +/-pi/2),
/// where it sets yaw to 0 and puts the whole turn about the vertical into roll.
///
/// With R = Rz(y) Ry(p) Rx(r): r20 = -sin p, (r21, r22) = cos p (sin r, cos r),
/// (r10, r00) = cos p (sin y, cos y); at cos p = 0 with y = 0, (r12, r11) = (-sin r, cos r).
pub fn rpy(rotation: &UnitQuaternion<f64>) -> [f64; 3] {
    let m = rotation.to_rotation_matrix();
    let m = m.matrix();
    let cos_p = m[(2, 1)].hypot(m[(2, 2)]);
    let pitch = (-m[(2, 0)]).atan2(cos_p);
    if cos_p < 1e-9 {
        [(-m[(1, 2)]).atan2(m[(1, 1)]), pitch, 0.0]
    } else {
        [
            m[(2, 1)].atan2(m[(2, 2)]),
            pitch,
            m[(1, 0)].atan2(m[(0, 0)]),
        ]
    }
}

/// The URDF `<origin>` of an isometry.
pub fn to_urdf(iso: &Isometry3<f64>) -> urdf_rs::Pose {
    let [r, p, y] = rpy(&iso.rotation);
    let t = iso.translation.vector;
    urdf_rs::Pose {
        xyz: urdf_rs::Vec3([clean(t.x), clean(t.y), clean(t.z)]),
        rpy: urdf_rs::Vec3([clean(r), clean(p), clean(y)]),
    }
}

/// Rounds away floating-point dust (|x| < 1e-12) so that written URDFs read cleanly.
fn clean(x: f64) -> f64 {
    if x.abs() < 1e-12 {
        0.0
    } else {
        x
    }
}

/// A rotation of `angle` [rad] about the z axis.
pub fn rot_z(angle: f64) -> Isometry3<f64> {
    Isometry3::rotation(Vector3::z() * angle)
}

/// A rotation of `angle` [rad] about the x axis.
pub fn rot_x(angle: f64) -> Isometry3<f64> {
    Isometry3::rotation(Vector3::x() * angle)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn rpy_is_fixed_axis_roll_pitch_yaw() {
        // pitch of -pi/2 turns +x into +z (the arm's tool frame at its tip).
        let iso = isometry([0.0; 3], [0.0, -FRAC_PI_2, 0.0]);
        let x = iso.rotation * Vector3::x();
        assert!((x - Vector3::z()).norm() < 1e-12, "{x}");
        // yaw of pi/2 turns +x into +y.
        let iso = isometry([0.0; 3], [0.0, 0.0, FRAC_PI_2]);
        assert!((iso.rotation * Vector3::x() - Vector3::y()).norm() < 1e-12);
    }

    #[test]
    fn urdf_round_trip() {
        let iso = isometry([0.1, -0.2, 0.3], [0.3, -0.4, 2.5]);
        let back = from_urdf(&to_urdf(&iso));
        assert!((iso.translation.vector - back.translation.vector).norm() < 1e-12);
        assert!(iso.rotation.angle_to(&back.rotation) < 1e-12);
    }

    /// Regression: legs are mounted at pitch = +/-pi/2, where roll and yaw are degenerate and
    /// a naive extraction read them from rounding noise (a 15 degree error on Tricycle's leg1).
    #[test]
    fn urdf_round_trip_at_gimbal_lock() {
        for pitch in [FRAC_PI_2, -FRAC_PI_2] {
            for yaw in [0.0, 2.0943951023931957, -2.0943951023931957, 0.7] {
                let composed = isometry([0.0; 3], [0.0, pitch, yaw]) * rot_x(std::f64::consts::PI);
                let back = from_urdf(&to_urdf(&composed));
                let err = composed.rotation.angle_to(&back.rotation);
                assert!(err < 1e-9, "pitch {pitch} yaw {yaw}: error {err} rad");
            }
        }
    }
}
