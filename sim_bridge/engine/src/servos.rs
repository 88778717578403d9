//! The servo commands of one robot: what every engine keeps between control steps, so that
//! commands are validated, clamped and slewed by one piece of code whatever the engine.

use std::ops::Range;

use kumi_model::{Actuator, ActuatorMode, RobotModel};

use crate::actuator::{integrate_velocity_setpoint, max_lead, slew, ServoState};
use crate::error::SimError;
use kumi_model::commands::clamp_command;

/// Every actuator of a robot with its servo state, in the model's actuator order.
#[derive(Debug, Clone, PartialEq)]
pub struct ServoBank {
    actuators: Vec<Actuator>,
    states: Vec<ServoState>,
    /// Each module's name and actuator index range.
    modules: Vec<(String, Range<usize>)>,
    /// Each module's [`RobotModel::wheel_drive_sign`], in the order of `modules`.
    drive_signs: Vec<f64>,
}

/// What the PD law of one servo tracks during one physics step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServoTarget {
    /// Position set-point [rad].
    pub position: f64,
    /// Velocity target [rad/s]: 0 for position servos, the command for velocity servos.
    pub velocity: f64,
}

impl ServoBank {
    /// Every servo of `model`, holding zero.
    pub fn new(model: &RobotModel) -> Self {
        let actuators: Vec<Actuator> = model.actuators().cloned().collect();
        let mut modules = Vec::with_capacity(model.modules.len());
        let mut start = 0;
        for m in &model.modules {
            modules.push((m.name.clone(), start..start + m.actuators.len()));
            start += m.actuators.len();
        }
        let states = actuators
            .iter()
            .map(|a| ServoState::holding(a.mode, 0.0))
            .collect();
        Self {
            actuators,
            states,
            modules,
            drive_signs: model
                .modules
                .iter()
                .map(|m| model.wheel_drive_sign(&m.name))
                .collect(),
        }
    }

    /// The sign a module's wheel velocity is multiplied by so that positive drives the base
    /// along +x at home ([`RobotModel::wheel_drive_sign`]).
    pub fn drive_sign(&self, module: &str) -> Result<f64, SimError> {
        self.modules
            .iter()
            .position(|(name, _)| name == module)
            .map(|i| self.drive_signs[i])
            .ok_or_else(|| SimError::UnknownModule(module.to_string()))
    }

    /// Every actuator, in the order of every per-joint vector of [`crate::SimWorld`].
    pub fn actuators(&self) -> &[Actuator] {
        &self.actuators
    }

    pub fn states(&self) -> &[ServoState] {
        &self.states
    }

    /// The actuator index range of a module.
    pub fn module_range(&self, module: &str) -> Result<Range<usize>, SimError> {
        self.modules
            .iter()
            .find(|(name, _)| name == module)
            .map(|(_, range)| range.clone())
            .ok_or_else(|| SimError::UnknownModule(module.to_string()))
    }

    /// Every servo holds `joint_positions` (one per actuator): position servos commanded
    /// there, velocity servos to stop, braked at that angle.
    pub fn hold(&mut self, joint_positions: &[f64]) {
        assert_eq!(
            joint_positions.len(),
            self.actuators.len(),
            "one joint position per actuator"
        );
        for ((state, a), &q) in self
            .states
            .iter_mut()
            .zip(&self.actuators)
            .zip(joint_positions)
        {
            *state = ServoState::holding(a.mode, q);
        }
    }

    /// Replaces every servo state (restoring a snapshot).
    pub fn restore(&mut self, states: &[ServoState]) {
        self.states.copy_from_slice(states);
    }

    /// Sets the commands of a module's joints of one mode, each clamped to its limits. A wrong
    /// count, module or mode, or any non-finite value, rejects the whole command.
    pub fn set(
        &mut self,
        module: &str,
        mode: ActuatorMode,
        values: &[f64],
    ) -> Result<(), SimError> {
        let indices: Vec<usize> = self
            .module_range(module)?
            .filter(|&i| self.actuators[i].mode == mode)
            .collect();
        if indices.is_empty() {
            return Err(SimError::WrongModuleKind {
                module: module.to_string(),
                what: match mode {
                    ActuatorMode::Position => "position",
                    ActuatorMode::Velocity => "velocity",
                },
            });
        }
        if indices.len() != values.len() {
            return Err(SimError::LengthMismatch {
                module: module.to_string(),
                expected: indices.len(),
                got: values.len(),
            });
        }
        let clamped = indices
            .iter()
            .zip(values)
            .map(|(&i, &v)| {
                clamp_command(&self.actuators[i], v).ok_or_else(|| SimError::NonFinite {
                    module: module.to_string(),
                    value: v,
                })
            })
            .collect::<Result<Vec<f64>, SimError>>()?;
        for (&i, v) in indices.iter().zip(clamped) {
            self.states[i].command = v;
        }
        Ok(())
    }

    /// The number of velocity (wheel) joints of a module.
    pub fn velocity_joints(&self, module: &str) -> Result<usize, SimError> {
        Ok(self.actuators[self.module_range(module)?]
            .iter()
            .filter(|a| a.mode == ActuatorMode::Velocity)
            .count())
    }

    /// The current commands, in actuator order: position targets [rad] or velocities [rad/s].
    pub fn commands(&self) -> Vec<f64> {
        self.states.iter().map(|s| s.command).collect()
    }

    /// Advances servo `i`'s set-point by one physics step of `dt` [s], given its measured
    /// position `q` [rad], and returns what its PD law tracks during that step. Position
    /// set-points slew toward the command at the velocity limit; wheel set-points integrate the
    /// velocity command without winding up.
    pub fn advance(&mut self, i: usize, q: f64, dt: f64) -> ServoTarget {
        let a = &self.actuators[i];
        let s = &mut self.states[i];
        match a.mode {
            ActuatorMode::Position => {
                s.setpoint = slew(s.setpoint, s.command, a.velocity_limit, dt);
                ServoTarget {
                    position: s.setpoint,
                    velocity: 0.0,
                }
            }
            ActuatorMode::Velocity => {
                s.setpoint = integrate_velocity_setpoint(s.setpoint, s.command, q, max_lead(a), dt);
                ServoTarget {
                    position: s.setpoint,
                    velocity: s.command,
                }
            }
        }
    }
}
