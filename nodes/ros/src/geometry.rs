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

/// The isometry of a pose message, if its quaternion can be normalised (non-zero, finite). A
/// quaternion within 1e-9 of unit length is taken as it is.
pub fn isometry(pose: &Pose) -> Option<Isometry3<f64>> {
    let p = pose.position;
    let o = pose.orientation;
    let values = [p.x, p.y, p.z, o.x, o.y, o.z, o.w];
    if values.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let q = nalgebra::Quaternion::new(o.w, o.x, o.y, o.z);
    let norm = q.norm();
    if norm < 1e-9 {
        return None;
    }
    // A quaternion that is a unit one to within rounding is kept bit for bit: what a node
    // publishes, another reads back unchanged.
    let unit = if (norm - 1.0).abs() <= 1e-9 {
        q
    } else {
        q / norm
    };
    Some(Isometry3::from_parts(
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
        assert!(isometry(&zero).is_none());
        let mut nan = pose(&iso);
        nan.position.x = f64::NAN;
        assert!(isometry(&nan).is_none());
    }
}
