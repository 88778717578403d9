//! The actuator law applied before every physics step: pure functions, so the same limits hold
//! in training, evaluation and the bridge. The rules for commands themselves (clamping, the
//! meaning of increments, the control rate) belong to the robot model
//! ([`kumi_model::commands`]), so that nodes on hardware use them without a simulator.

use kumi_model::commands::CommandRate;
use kumi_model::{Actuator, ActuatorMode};

/// The command a driven joint is following.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoState {
    /// The latest command: a position [rad] or a velocity [rad/s] target, already clamped.
    pub command: f64,
    /// For position servos, the set-point the PD law tracks now [rad]: it slews toward
    /// `command` at no more than the velocity limit. For velocity servos, the integrated
    /// wheel angle it holds [rad].
    pub setpoint: f64,
    /// Position servos: the commanded rate, what a wheel following this joint's steering rolls
    /// with ([`CommandRate`]). Unused by velocity servos.
    pub command_rate: CommandRate,
    /// The commanded rate [rad/s] during the current physics step (position servos).
    pub rate_now: f64,
}

impl ServoState {
    /// A servo at rest holding `q`: position servos commanded to `q`, velocity servos to stop.
    pub fn holding(mode: ActuatorMode, q: f64) -> Self {
        Self {
            command: match mode {
                ActuatorMode::Position => q,
                ActuatorMode::Velocity => 0.0,
            },
            setpoint: q,
            command_rate: CommandRate::default(),
            rate_now: 0.0,
        }
    }
}

/// Moves a position set-point toward the command by at most `velocity_limit * dt` [rad].
pub fn slew(setpoint: f64, command: f64, velocity_limit: f64, dt: f64) -> f64 {
    let max_step = velocity_limit * dt;
    setpoint + (command - setpoint).clamp(-max_step, max_step)
}

/// How far a velocity servo's set-point may lead its position [rad]: effort limit / stiffness,
/// the lead at which it pushes with its full effort (0 without a position gain).
pub fn max_lead(actuator: &Actuator) -> f64 {
    if actuator.stiffness > 0.0 {
        actuator.effort_limit / actuator.stiffness
    } else {
        0.0
    }
}

/// Integrates a velocity command [rad/s] into a wheel's position set-point [rad], keeping it
/// within `max_lead` [rad] of the measured position `q` (anti-windup: a blocked wheel pushes
/// with at most its effort limit, and does not lurch forward when freed).
pub fn integrate_velocity_setpoint(
    setpoint: f64,
    command: f64,
    q: f64,
    max_lead: f64,
    dt: f64,
) -> f64 {
    (setpoint + command * dt).clamp(q - max_lead, q + max_lead)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slew_is_rate_limited_and_lands_exactly() {
        // 1.5 rad/s over 1/120 s is 0.0125 rad per step.
        assert_eq!(slew(0.0, 1.0, 1.5, 1.0 / 120.0), 0.0125);
        assert_eq!(slew(0.0, -1.0, 1.5, 1.0 / 120.0), -0.0125);
        assert_eq!(slew(0.995, 1.0, 1.5, 1.0 / 120.0), 1.0);
    }

    #[test]
    fn velocity_setpoint_integrates_and_never_winds_up() {
        // 2 rad/s over 0.01 s advances 0.02 rad.
        assert!((integrate_velocity_setpoint(1.0, 2.0, 1.0, 0.5, 0.01) - 1.02).abs() < 1e-12);
        // A blocked wheel (q stuck at 0) leads by at most max_lead.
        let mut sp = 0.0;
        for _ in 0..1000 {
            sp = integrate_velocity_setpoint(sp, 5.0, 0.0, 0.45, 0.01);
        }
        assert_eq!(sp, 0.45);
    }
}
