//! The rules for commands to driven joints, everywhere a command is made or applied (training,
//! evaluation, the sim bridge, the arm node on hardware): what a command may be, what an
//! increment means, and the control rate. The simulator's servo law (set-points, slewing) lives
//! in `kumi-engine`; nothing here needs a physics engine.

use nalgebra::Vector3;

use crate::{Actuator, ActuatorMode};

/// The control rate of every kumi robot [Hz]: one control step each 1/30 s (the paper's 30 Hz).
/// Policies act once per control step; an increment is a change per control step.
pub const CONTROL_HZ: f64 = 30.0;

/// The rate [rad/s] a new position command asks for: its change from the previous command over
/// the time since that one [s], clamped to the joint's velocity limit (the set-point moves no
/// faster). `None` when no time has passed (two commands in one instant).
pub fn command_rate(
    previous: f64,
    command: f64,
    elapsed_s: f64,
    velocity_limit: f64,
) -> Option<f64> {
    (elapsed_s > 0.0)
        .then(|| ((command - previous) / elapsed_s).clamp(-velocity_limit, velocity_limit))
}

/// The commanded rate of a position joint as its commands come (what a wheel that follows the
/// joint's steering rolls with, [`crate::RobotModel::steering_couplings`]): each command's
/// [`command_rate`] over the time since the one before, held for that long, so a joint whose
/// commands stop has no rate one period later. Time passes by [`Self::elapse`]: physics steps in
/// the simulator's servos, wall time in the whole-body node on hardware.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CommandRate {
    /// The latest command's rate [rad/s].
    rate: f64,
    /// How long it holds [s]: the time since the command before it.
    window_s: f64,
    /// Time since the latest command [s].
    since_s: f64,
}

/// The longest gap between two commands [s] whose change is spread over it (two control
/// periods): after a longer one (a node that held, restarted or was away) the next command is
/// taken as a first, so a stale change never rolls the wheels for the length of the gap.
pub const MAX_COMMAND_GAP_S: f64 = 2.0 / CONTROL_HZ;

impl CommandRate {
    /// A new command `command` after `previous` [rad], for a joint of `velocity_limit` [rad/s].
    /// The first command (no time since the last reset), one after more than
    /// [`MAX_COMMAND_GAP_S`] and a second in the same instant set no rate; a non-finite value
    /// changes nothing.
    pub fn command(&mut self, previous: f64, command: f64, velocity_limit: f64) {
        if !(previous.is_finite() && command.is_finite()) {
            return;
        }
        if self.since_s > MAX_COMMAND_GAP_S {
            *self = Self::default();
        } else if let Some(rate) = command_rate(previous, command, self.since_s, velocity_limit) {
            self.rate = rate;
            self.window_s = self.since_s;
        }
        self.since_s = 0.0;
    }

    /// `dt_s` [s] pass.
    pub fn elapse(&mut self, dt_s: f64) {
        self.since_s += dt_s;
    }

    /// The rate now [rad/s]: the latest command's while its window lasts, else 0.
    pub fn rate(&self) -> f64 {
        if self.since_s < self.window_s {
            self.rate
        } else {
            0.0
        }
    }
}

/// How fast a wheel module turns about its steering joint's axis [rad/s]: the commanded rates
/// of the joints that turn it (`joint_turns`: each joint's share of the axis and its commanded
/// rate [rad/s], [`CommandRate`]; [`crate::SteeringCoupling::turning_joints`]) plus the base's
/// angular velocity about that axis, `axis_b . base_angular_velocity_b` (the axis,
/// [`crate::SteeringCoupling::axis_b`], and the velocity [rad/s], both in the base frame). A
/// turning base carries its wheel modules round with it: wheels that only roll straight would
/// scrub against the turn.
pub fn steering_turn_rate(
    joint_turns: impl IntoIterator<Item = (f64, f64)>,
    axis_b: &Vector3<f64>,
    base_angular_velocity_b: &Vector3<f64>,
) -> f64 {
    let joints: f64 = joint_turns
        .into_iter()
        .map(|(share, rate)| share * rate)
        .sum();
    let (a, w) = (axis_b, base_angular_velocity_b);
    joints + (a.x * w.x + a.y * w.y + a.z * w.z)
}

/// A wheel's velocity [rad/s] when it follows its module's steering: its command [rad/s] plus
/// `gain` times the module's turn rate [rad/s] ([`steering_turn_rate`]), within its velocity
/// limit. The simulator's servos apply it each physics step, the whole-body node on hardware
/// each time it sends the wheels.
pub fn follow_steering(actuator: &Actuator, command: f64, gain: f64, turn_rate: f64) -> f64 {
    actuator.clamp_velocity(command + gain * turn_rate)
}

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

/// Targets kept within `max_lead_rad` of the measured angles `q` [rad]: a bound on how far a
/// command may wind up ahead of a joint that cannot follow (a leg whose tip the ground holds).
/// Free motion never meets it when the bound is above what a joint at its velocity limit
/// needs (damping / stiffness x speed). Lengths must match.
pub fn bound_lead(targets: &[f64], q: &[f64], max_lead_rad: f64) -> Vec<f64> {
    debug_assert_eq!(targets.len(), q.len());
    targets
        .iter()
        .zip(q)
        .map(|(t, q)| t.clamp(q - max_lead_rad, q + max_lead_rad))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bounded_lead_keeps_targets_near_the_joints() {
        let q = [0.0, 1.0, -1.0];
        assert_eq!(bound_lead(&[0.1, 1.5, -1.05], &q, 0.2), [0.1, 1.2, -1.05]);
        assert_eq!(bound_lead(&[-0.5, 1.0, -2.0], &q, 0.2), [-0.2, 1.0, -1.2]);
    }

    #[test]
    fn a_commanded_rate_holds_for_the_period_it_was_spread_over() {
        let mut r = CommandRate::default();
        // The first command has nothing before it.
        r.command(0.0, 0.0, 1.5);
        assert_eq!(r.rate(), 0.0);
        // 0.01 rad in 1/30 s (four steps of 1/120 s): 0.3 rad/s for four steps, then none.
        let dt = 1.0 / 120.0;
        (0..4).for_each(|_| r.elapse(dt));
        r.command(0.0, 0.01, 1.5);
        for step in 0..4 {
            assert!((r.rate() - 0.3).abs() < 1e-12, "{step}");
            r.elapse(dt);
        }
        assert_eq!(r.rate(), 0.0);
        // A command in the same instant as the last keeps the rate it had.
        r.command(0.01, 0.02, 1.5);
        (0..4).for_each(|_| r.elapse(dt));
        r.command(0.02, 0.02, 1.5);
        r.command(0.02, 0.5, 1.5);
        assert_eq!(
            r.rate(),
            0.0,
            "no change over the last period, none for the jump in no time"
        );
        // After a gap of more than two periods the next command is a first: no rate.
        (0..12).for_each(|_| r.elapse(dt));
        r.command(0.5, 0.9, 1.5);
        assert_eq!(r.rate(), 0.0, "a change after a gap is not spread over it");
        // Non-finite commands change nothing.
        (0..4).for_each(|_| r.elapse(dt));
        r.command(0.9, f64::NAN, 1.5);
        r.command(0.9, 0.91, 1.5);
        assert!((r.rate() - 0.3).abs() < 1e-12);
    }

    #[test]
    fn a_command_rate_is_the_change_over_the_time_since_the_last_command() {
        // 0.01 rad over 1/30 s is 0.3 rad/s.
        assert!((command_rate(0.5, 0.51, 1.0 / 30.0, 1.5).unwrap() - 0.3).abs() < 1e-12);
        // A jump of 1 rad in 1/30 s is limited to 1.5 rad/s.
        assert_eq!(command_rate(0.0, -1.0, 1.0 / 30.0, 1.5), Some(-1.5));
        assert_eq!(command_rate(0.0, 1.0, 0.0, 1.5), None);
    }

    #[test]
    fn a_module_turns_with_its_joints_and_with_the_base_about_the_steering_axis() {
        // A steering axis pointing down (Tricycle's leg tips): the base turning left at 0.5
        // rad/s turns the module by -0.5 rad/s about it; with 0.2 rad/s of steering, -0.3.
        let down = Vector3::new(0.0, 0.0, -1.0);
        let left = Vector3::new(0.0, 0.0, 0.5);
        assert_eq!(steering_turn_rate([(1.0, 0.2)], &down, &left), 0.2 - 0.5);
        // A second joint along the axis adds its rate; one at half the share, half of it.
        assert_eq!(
            steering_turn_rate([(1.0, 0.2), (1.0, 0.1), (0.5, 0.2)], &down, &left),
            0.2 + 0.1 + 0.1 - 0.5
        );
        // Rolling and pitching about axes across the steering axis turn it not at all.
        assert_eq!(
            steering_turn_rate([(1.0, 0.2)], &down, &Vector3::new(0.3, -0.4, 0.0)),
            0.2
        );
        // A tilted axis takes the base's turn about its own line.
        let tilted = Vector3::new(0.6, 0.0, 0.8);
        let turn = steering_turn_rate([], &tilted, &Vector3::new(1.0, 0.0, 1.0));
        assert!((turn - 1.4).abs() < 1e-12);
    }

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
