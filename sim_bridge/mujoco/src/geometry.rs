//! Collision shapes of the MuJoCo model and their lowest points, for standing a robot on the
//! ground and for the sink check.

use nalgebra::{Matrix3, Vector3};

/// A robot collision geom: the shapes kumi's URDFs use.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum GeomShape {
    /// Half extents [m].
    Box([f64; 3]),
    /// Radius and half length along local z [m].
    Cylinder {
        radius: f64,
        half_length: f64,
    },
    Sphere {
        radius: f64,
    },
}

/// The lowest world z [m] of a shape at `position` with rotation matrix `r` (local to world).
pub fn lowest_z(shape: GeomShape, position: &Vector3<f64>, r: &Matrix3<f64>) -> f64 {
    // Row 2 of r: the world z component of each local axis.
    let z = [r[(2, 0)], r[(2, 1)], r[(2, 2)]];
    let reach = match shape {
        GeomShape::Box(h) => h[0] * z[0].abs() + h[1] * z[1].abs() + h[2] * z[2].abs(),
        GeomShape::Cylinder {
            radius,
            half_length,
        } => half_length * z[2].abs() + radius * (1.0 - z[2] * z[2]).max(0.0).sqrt(),
        GeomShape::Sphere { radius } => radius,
    };
    position.z - reach
}

#[cfg(feature = "mujoco")]
impl GeomShape {
    /// The shape of geom `g` of a compiled model.
    pub fn of(model: &mujoco_rs::prelude::MjModel, g: usize) -> Result<Self, String> {
        use mujoco_rs::prelude::MjtGeomBase;
        let s = model.geom_size()[g];
        Ok(match model.geom_type()[g] {
            MjtGeomBase::mjGEOM_BOX => GeomShape::Box(s),
            MjtGeomBase::mjGEOM_CYLINDER => GeomShape::Cylinder {
                radius: s[0],
                half_length: s[1],
            },
            MjtGeomBase::mjGEOM_SPHERE => GeomShape::Sphere { radius: s[0] },
            other => return Err(format!("geom {g} has unsupported type {other:?}")),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    #[test]
    fn lowest_points_of_upright_and_tilted_shapes() {
        let up = Matrix3::identity();
        let at = Vector3::new(0.0, 0.0, 1.0);
        assert_eq!(lowest_z(GeomShape::Box([0.1, 0.2, 0.3]), &at, &up), 0.7);
        let cyl = GeomShape::Cylinder {
            radius: 0.27,
            half_length: 0.1,
        };
        assert!((lowest_z(cyl, &at, &up) - 0.9).abs() < 1e-12);
        // A wheel: cylinder axis horizontal, touches at its radius.
        let side = *Rotation3::from_euler_angles(std::f64::consts::FRAC_PI_2, 0.0, 0.0).matrix();
        assert!((lowest_z(cyl, &at, &side) - 0.73).abs() < 1e-12);
        assert_eq!(
            lowest_z(GeomShape::Sphere { radius: 0.05 }, &at, &side),
            0.95
        );
    }
}
