//! kumi's servo law on MuJoCo: the same PD servo as rapier's force-based motor, solved per
//! physics step.
//!
//! rapier 0.36 solves its motor implicitly: with stiffness k, damping c, set-point `sp`,
//! velocity target `v_t` and step h, the torque is `k (sp - q) + c v_t - (c + h k) v'`, where
//! `v'` is the velocity at the end of the step, clamped to the effort limit. On MuJoCo the
//! damping part `(c + h k)` is integrated implicitly by `implicitfast` as joint damping (exact
//! backward Euler against the full inertia and contacts), and the rest is applied as a joint
//! force. Whether the clamp is active is decided per step from the dof's own inertia (a
//! one-dof prediction of `v'`); a clamped servo applies its effort limit with no damping.

use kumi_engine::ServoTarget;
use kumi_model::Actuator;

/// What a servo applies during one physics step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ServoForce {
    /// Within the effort limit: apply `spring` [N m] and integrate the servo damping
    /// `c + h k` implicitly.
    Tracking { spring: f64 },
    /// At the effort limit: apply `effort` [N m] (signed), no servo damping.
    Saturated { effort: f64 },
}

/// The servo's force for one step of `dt` [s], at position `q` [rad] and velocity `v`
/// [rad/s], with `other` [N m] the other forces on the dof and `inertia` [kg m^2] its diagonal
/// entry of the joint-space inertia.
pub fn servo_force(
    a: &Actuator,
    target: ServoTarget,
    q: f64,
    v: f64,
    other: f64,
    inertia: f64,
    dt: f64,
) -> ServoForce {
    let spring = a.stiffness * (target.position - q) + a.damping * target.velocity;
    let damping = a.damping + dt * a.stiffness;
    // tau = spring - D v',  v' = v + dt (tau + other) / m  =>  solve for tau.
    let h_over_m = dt / inertia.max(f64::MIN_POSITIVE);
    let tau = (spring - damping * v - damping * h_over_m * other) / (1.0 + damping * h_over_m);
    if tau.abs() <= a.effort_limit {
        ServoForce::Tracking { spring }
    } else {
        ServoForce::Saturated {
            effort: a.effort_limit.copysign(tau),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kumi_model::ActuatorMode;

    fn joint() -> Actuator {
        Actuator {
            joint: "j".into(),
            mode: ActuatorMode::Position,
            stiffness: 30000.0,
            damping: 800.0,
            armature: 0.1,
            joint_damping: 0.0,
            joint_friction: 0.0,
            effort_limit: 136.0,
            velocity_limit: 1.5,
            lower: -2.0,
            upper: 2.0,
        }
    }

    fn at(position: f64) -> ServoTarget {
        ServoTarget {
            position,
            velocity: 0.0,
        }
    }

    #[test]
    fn a_small_error_is_tracked_with_the_spring_force() {
        // 1 mrad at 30000 N m/rad: 30 N m, well within 136.
        let f = servo_force(&joint(), at(0.001), 0.0, 0.0, 0.0, 1.0, 1.0 / 120.0);
        assert_eq!(f, ServoForce::Tracking { spring: 30.0 });
    }

    #[test]
    fn a_large_error_saturates_at_the_effort_limit_with_its_sign() {
        let f = servo_force(&joint(), at(-0.5), 0.0, 0.0, 0.0, 1.0, 1.0 / 120.0);
        assert_eq!(f, ServoForce::Saturated { effort: -136.0 });
    }

    #[test]
    fn the_implicit_prediction_matches_the_one_dof_backward_euler_step() {
        // One dof, inertia m, no clamp: tau = spring - D v', v' = v + h (tau + f) / m.
        let (a, h, m, v, f) = (joint(), 1.0 / 120.0, 2.0, 0.3, -50.0);
        let big = Actuator {
            effort_limit: 1e9,
            ..a.clone()
        };
        let spring = a.stiffness * 0.004;
        let d = a.damping + h * a.stiffness;
        let tau = (spring - d * v - d * h * f / m) / (1.0 + d * h / m);
        let v_new = v + h * (tau + f) / m;
        assert!((tau - (spring - d * v_new)).abs() < 1e-9);
        assert_eq!(
            servo_force(&big, at(0.004), 0.0, v, f, m, h),
            ServoForce::Tracking { spring }
        );
        // The same step with the real limit: |tau| exceeds 136 N m only if the prediction does.
        let limited = servo_force(&a, at(0.004), 0.0, v, f, m, h);
        assert_eq!(
            tau.abs() > 136.0,
            matches!(limited, ServoForce::Saturated { .. })
        );
    }
}
