//! Conversions between rapier's f32 glam types and kumi's f64 nalgebra types.

use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};
use rapier3d::math::{Pose, Rotation, Vector};

pub fn to_na_vector(v: Vector) -> Vector3<f64> {
    Vector3::new(f64::from(v.x), f64::from(v.y), f64::from(v.z))
}

pub fn to_rapier_vector(v: &Vector3<f64>) -> Vector {
    Vector::new(v.x as f32, v.y as f32, v.z as f32)
}

pub fn to_na_isometry(p: &Pose) -> Isometry3<f64> {
    let q = p.rotation;
    Isometry3::from_parts(
        Translation3::from(to_na_vector(p.translation)),
        UnitQuaternion::new_normalize(Quaternion::new(
            f64::from(q.w),
            f64::from(q.x),
            f64::from(q.y),
            f64::from(q.z),
        )),
    )
}

pub fn to_rapier_pose(iso: &Isometry3<f64>) -> Pose {
    let q = iso.rotation.quaternion();
    let rotation = Rotation::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32).normalize();
    Pose::from_parts(to_rapier_vector(&iso.translation.vector), rotation)
}
