//! kumi's servo law on MuJoCo: the same PD servo as rapier's force-based motor, solved per
//! physics step.
//!
//! rapier 0.36 solves its motor implicitly: with stiffness k, damping c, set-point `sp`,
//! velocity target `v_t` and step h, the torque is `k (sp - q) + c v_t - (c + h k) v'`, where
//! `v'` is the velocity at the end of the step, clamped to the effort limit. On MuJoCo the
//! damping part `D = c + h k` is integrated implicitly by `implicitfast` as joint damping (exact
//! backward Euler against the full inertia and contacts), and the spring part
//! `k (sp - q) + c v_t` is applied as a joint force. Where the servo's torque at the step's
//! starting velocity, `spring - D v`, exceeds the effort limit, spring and damping are both
//! scaled down by the same factor, so the torque is the limit and the damping stays implicit.
//!
//! Two other laws fail near the limit. Switching the damping off whenever a one-dof
//! prediction of `v'` put the servo over its limit chattered on closed chains, where that
//! prediction cannot see contacts (Tricycle's loaded legs at 5-30 rad/s). Keeping the whole
//! damping implicit and clamping the spring to `D v +- effort` put an explicit `D v` on the
//! joint, which on a light distal joint (`h D` far above its inertia) shook the manipulator at
//! 10 rad/s once it saturated. The scaled law has neither a switch nor an explicit velocity term.

use kumi_engine::ServoTarget;
use kumi_model::Actuator;

/// What a servo applies during one physics step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoCommand {
    /// Joint force [N m], applied explicitly.
    pub spring: f64,
    /// Servo damping [N m s/rad], integrated implicitly (on top of the joint's own).
    pub damping: f64,
}

/// The servo's command for one physics step of `dt` [s], at position `q` [rad] and velocity
/// `v` [rad/s]: `k (sp - q) + c v_t` and `c + dt k`, both scaled by
/// `min(1, effort / |spring - D v|)`.
pub fn servo_command(a: &Actuator, target: ServoTarget, q: f64, v: f64, dt: f64) -> ServoCommand {
    let spring = a.stiffness * (target.position - q) + a.damping * target.velocity;
    let damping = a.damping + dt * a.stiffness;
    let torque = (spring - damping * v).abs();
    let scale = if torque > a.effort_limit {
        a.effort_limit / torque
    } else {
        1.0
    };
    ServoCommand {
        spring: scale * spring,
        damping: scale * damping,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kumi_model::ActuatorMode;

    const DT: f64 = 1.0 / 120.0;
    /// `c + DT k` for [`joint`]: 800 + 30000 / 120.
    const D: f64 = 1050.0;

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
    fn within_the_limit_the_servo_is_the_whole_pd() {
        // 1 mrad at 30000 N m/rad: 30 N m; at 0.02 rad/s the damping takes 21 N m more.
        let c = servo_command(&joint(), at(0.001), 0.0, -0.02, DT);
        assert_eq!(c.spring, 30.0);
        assert!((c.damping - D).abs() < 1e-9);
    }

    #[test]
    fn past_the_limit_spring_and_damping_scale_so_the_torque_is_the_limit() {
        // At rest, 0.5 rad short: 15000 N m asked, 136 given, with the damping scaled alike.
        let c = servo_command(&joint(), at(-0.5), 0.0, 0.0, DT);
        assert!((c.spring + 136.0).abs() < 1e-9, "{c:?}");
        assert!((c.damping - D * 136.0 / 15000.0).abs() < 1e-9, "{c:?}");
        // Sagging at 0.1 rad/s against a 3 mrad error: 90 + 105 = 195 N m asked.
        let v = -0.1;
        let c = servo_command(&joint(), at(0.003), 0.0, v, DT);
        let torque = c.spring - c.damping * v;
        assert!((torque - 136.0).abs() < 1e-9, "{c:?}");
        assert!(
            c.damping > 0.0,
            "the damping never leaves, nor turns negative"
        );
    }
}
