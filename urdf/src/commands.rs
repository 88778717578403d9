//! The rules for commands to driven joints, everywhere a command is made or applied (training,
//! evaluation, the sim bridge, the arm node on hardware): what a command may be, what an
//! increment means, and the control rate. The simulator's servo law (set-points, slewing) lives
//! in `kumi-engine`; nothing here needs a physics engine.

use crate::{Actuator, ActuatorMode};

/// The control rate of every kumi robot [Hz]: one control step each 1/30 s (the paper's 30 Hz).
/// Policies act once per control step; an increment is a change per control step.
pub const CONTROL_HZ: f64 = 30.0;

/// Clamps a raw command to the actuator's limits; `None` for a non-finite command.
pub fn clamp_command(actuator: &Actuator, command: f64) -> Option<f64> {
    if !command.is_finite() {
        return None;
    }
    Some(match actuator.mode {
        ActuatorMode::Position => actuator.clamp_position(command),
        ActuatorMode::Velocity => actuator.clamp_velocity(command),
    })
}

/// Each wheel joint's velocity command [rad/s] (`(joint, value)`, in actuator order) for a
/// wheel module's velocity `v` [rad/s]: positive drives the base along its +x axis with the
/// robot at home, however the module is mounted ([`crate::RobotModel::wheel_drive_sign`]),
/// each clamped to its joint's limit. What the simulator's servos are commanded; what the
/// whole-body node sends a wheel limb on hardware. `None` for a non-finite `v` or a module
/// without wheels.
pub fn wheel_joint_velocities(
    model: &crate::RobotModel,
    module: &str,
    v: f64,
) -> Option<Vec<(String, f64)>> {
    let m = model.module(module)?;
    let sign = model.wheel_drive_sign(module);
    let wheels: Vec<(String, f64)> = m
        .velocity_joints()
        .map(|a| Some((a.joint.clone(), clamp_command(a, sign * v)?)))
        .collect::<Option<_>>()?;
    (!wheels.is_empty()).then_some(wheels)
}

/// The meaning of joint increments, everywhere (training, the bridge, the arm node): each
/// target moves by its increment [rad] and is clamped to its joint's range. `None` if any
/// increment is non-finite or the lengths differ.
pub fn apply_increments(
    targets: &[f64],
    increments: &[f64],
    actuators: &[&Actuator],
) -> Option<Vec<f64>> {
    if targets.len() != increments.len()
        || targets.len() != actuators.len()
        || increments.iter().any(|d| !d.is_finite())
    {
        return None;
    }
    Some(
        targets
            .iter()
            .zip(increments)
            .zip(actuators)
            .map(|((t, d), a)| a.clamp_position(t + d))
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn arm_joint() -> Actuator {
        Actuator {
            joint: "j".into(),
            mode: ActuatorMode::Position,
            stiffness: 800.0,
            damping: 60.0,
            armature: 0.1,
            joint_damping: 2.0,
            joint_friction: 0.0,
            effort_limit: 136.0,
            velocity_limit: 1.5,
            lower: -2.0,
            upper: 2.0,
        }
    }

    #[test]
    fn increments_move_targets_and_clamp_to_the_range() {
        let a = arm_joint(); // range [-2, 2]
        let joints = [&a, &a, &a];
        assert_eq!(
            apply_increments(&[0.0, 1.9, -1.0], &[0.1, 0.3, -0.5], &joints),
            Some(vec![0.1, 2.0, -1.5])
        );
        assert_eq!(
            apply_increments(&[0.0; 3], &[0.1, f64::NAN, 0.0], &joints),
            None
        );
        assert_eq!(apply_increments(&[0.0; 3], &[0.1; 2], &joints), None);
    }

    #[test]
    fn commands_are_clamped_and_non_finite_rejected() {
        let a = arm_joint();
        assert_eq!(clamp_command(&a, 3.0), Some(2.0));
        assert_eq!(clamp_command(&a, -3.0), Some(-2.0));
        assert_eq!(clamp_command(&a, f64::NAN), None);
        assert_eq!(clamp_command(&a, f64::INFINITY), None);
        let wheel = Actuator {
            mode: ActuatorMode::Velocity,
            velocity_limit: 5.0,
            lower: f64::NEG_INFINITY,
            upper: f64::INFINITY,
            ..a
        };
        assert_eq!(clamp_command(&wheel, 9.0), Some(5.0));
    }
}
