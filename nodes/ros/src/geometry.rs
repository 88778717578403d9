//! Conversions between nalgebra and `geometry_msgs`.

use kumi_msgs::geometry_msgs::{Point, Pose, Quaternion, Transform, Vector3};
use nalgebra::{Isometry3, Translation3, UnitQuaternion};

pub fn vector3(v: &nalgebra::Vector3<f64>) -> Vector3 {
    Vector3 {
        x: v.x,
        y: v.y,
        z: v.z,
    }
}

pub fn quaternion(q: &UnitQuaternion<f64>) -> Quaternion {
    Quaternion {
        x: q.i,
        y: q.j,
        z: q.k,
        w: q.w,
    }
}

pub fn pose(iso: &Isometry3<f64>) -> Pose {
    let t = iso.translation.vector;
    Pose {
        position: Point {
            x: t.x,
            y: t.y,
            z: t.z,
        },
        orientation: quaternion(&iso.rotation),
    }
}

pub fn transform(iso: &Isometry3<f64>) -> Transform {
    Transform {
        translation: vector3(&iso.translation.vector),
        rotation: quaternion(&iso.rotation),
    }
}

/// How far a pose's quaternion norm may be from 1 and still be normalised rather than refused:
/// the one rule for every pose kumi reads (goals, targets, odometry).
pub const QUATERNION_NORM_TOLERANCE: f64 = 0.1;

/// Why a pose message is not a pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PoseError {
    #[error("a non-finite value")]
    NonFinite,
    #[error("its quaternion has norm {0:.3}, not within {QUATERNION_NORM_TOLERANCE} of 1: not a rotation")]
    NotARotation(f64),
}

/// The isometry of a pose message: every value finite, and a quaternion whose norm is within
/// [`QUATERNION_NORM_TOLERANCE`] of 1, normalised. A quaternion within 1e-9 of unit length is
/// taken as it is, so that what a node publishes another reads back bit for bit.
pub fn isometry(pose: &Pose) -> Result<Isometry3<f64>, PoseError> {
    let p = pose.position;
    let o = pose.orientation;
    let values = [p.x, p.y, p.z, o.x, o.y, o.z, o.w];
    if values.iter().any(|v| !v.is_finite()) {
        return Err(PoseError::NonFinite);
    }
    let q = nalgebra::Quaternion::new(o.w, o.x, o.y, o.z);
    let norm = q.norm();
    let unit = if (norm - 1.0).abs() <= 1e-9 {
        q
    } else if (norm - 1.0).abs() <= QUATERNION_NORM_TOLERANCE {
        q / norm
    } else {
        return Err(PoseError::NotARotation(norm));
    };
    Ok(Isometry3::from_parts(
        Translation3::new(p.x, p.y, p.z),
        UnitQuaternion::new_unchecked(unit),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_round_trip_and_rejections() {
        let iso = Isometry3::new(
            nalgebra::Vector3::new(1.0, -2.0, 0.5),
            nalgebra::Vector3::new(0.1, 0.2, -0.3),
        );
        let back = isometry(&pose(&iso)).unwrap();
        assert!((back.translation.vector - iso.translation.vector).norm() < 1e-12);
        assert!(back.rotation.angle_to(&iso.rotation) < 1e-12);
        let mut zero = pose(&iso);
        zero.orientation = Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 0.0,
        };
        assert_eq!(isometry(&zero), Err(PoseError::NotARotation(0.0)));
        let mut nan = pose(&iso);
        nan.position.x = f64::NAN;
        assert_eq!(isometry(&nan), Err(PoseError::NonFinite));
    }

    #[test]
    fn one_rule_for_a_quaternion_near_unit_length() {
        let with_w = |w: f64| Pose {
            orientation: Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w,
            },
            ..Default::default()
        };
        // Within 0.1 of unit length: normalised; a unit one (to within 1e-9) is kept bit for bit.
        for w in [0.91, 1.0, 1.09] {
            let r = isometry(&with_w(w)).unwrap().rotation;
            assert_eq!(r.w, 1.0, "norm {w}");
        }
        let kept = isometry(&with_w(1.0 + 1e-12)).unwrap().rotation;
        assert_eq!(kept.w, 1.0 + 1e-12);
        // Beyond it, however close to a rotation its direction is, refused with the norm.
        for w in [1e-9, 0.5, 0.89, 1.11, 2.0] {
            assert_eq!(isometry(&with_w(w)), Err(PoseError::NotARotation(w)));
        }
    }
}
