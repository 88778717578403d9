//! The servo commands of one robot: what every engine keeps between control steps, so that
//! commands are validated, clamped and slewed by one piece of code whatever the engine.

use std::ops::Range;

use kumi_model::{Actuator, ActuatorMode, RobotModel};

use crate::actuator::{integrate_velocity_setpoint, max_lead, slew, ServoState};
use crate::error::SimError;
use kumi_model::commands::{clamp_command, follow_steering, steering_turn_rate};
use nalgebra::Vector3;

/// Every actuator of a robot with its servo state, in the model's actuator order.
#[derive(Debug, Clone, PartialEq)]
pub struct ServoBank {
    actuators: Vec<Actuator>,
    states: Vec<ServoState>,
    /// Each module's name and actuator index range.
    modules: Vec<(String, Range<usize>)>,
    /// Each module's [`RobotModel::wheel_drive_sign`], in the order of `modules`.
    drive_signs: Vec<f64>,
    /// Per actuator: the steering a wheel follows ([`RobotModel::steering_couplings`]); `None`
    /// for every other joint.
    steering: Vec<Option<Following>>,
    /// The base's angular velocity [rad/s] in the base frame, as the engine last set it
    /// ([`ServoBank::set_base_angular_velocity`]).
    base_angular_velocity_b: Vector3<f64>,
}

/// The steering one wheel follows.
#[derive(Debug, Clone, PartialEq)]
struct Following {
    /// The joints that turn its module: actuator index and share of the steering axis
    /// ([`kumi_model::SteeringCoupling::turning_joints`]).
    joints: Vec<(usize, f64)>,
    /// Wheel rate per turn rate of its module [(rad/s) / (rad/s)].
    gain: f64,
    /// The steering axis in the base frame at home.
    axis_b: Vector3<f64>,
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
        let index = |joint: &str| actuators.iter().position(|a| a.joint == joint);
        let mut steering = vec![None; actuators.len()];
        for c in model.steering_couplings() {
            let Some(wheel) = index(&c.wheel_joint) else {
                continue;
            };
            let joints: Vec<(usize, f64)> = c
                .turning_joints
                .iter()
                .filter_map(|(joint, share)| Some((index(joint)?, *share)))
                .collect();
            // Parents come first, so the turning joints advance before their wheels in each
            // physics step and they read this step's rates.
            assert!(
                joints.iter().all(|&(j, _)| j < wheel),
                "turning joints precede their wheels"
            );
            steering[wheel] = Some(Following {
                joints,
                gain: c.gain,
                axis_b: c.axis_b,
            });
        }
        Self {
            steering,
            base_angular_velocity_b: Vector3::zeros(),
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
    /// there, velocity servos to stop, braked at that angle. The base's angular velocity is
    /// forgotten until the engine sets it again.
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
        self.base_angular_velocity_b = Vector3::zeros();
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
            let s = &mut self.states[i];
            if mode == ActuatorMode::Position {
                let limit = self.actuators[i].velocity_limit;
                s.command_rate.command(s.command, v, limit);
            }
            s.command = v;
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

    /// The base's angular velocity [rad/s] in the base frame, which following wheels add to
    /// their steering ([`ServoBank::advance`]): the engines set it before each physics step
    /// (zero for a fixed base). A non-finite value (a state that blew up) counts as zero.
    pub fn set_base_angular_velocity(&mut self, w_b: Vector3<f64>) {
        self.base_angular_velocity_b = if w_b.iter().all(|x| x.is_finite()) {
            w_b
        } else {
            Vector3::zeros()
        };
    }

    /// Advances servo `i`'s set-point by one physics step of `dt` [s], given its measured
    /// position `q` [rad], and returns what its PD law tracks during that step. Position
    /// set-points slew toward the command at the velocity limit; wheel set-points integrate the
    /// velocity command without winding up. A wheel that follows its module's steering adds
    /// `gain` times its module's turn rate, within its velocity limit: the commanded rates of
    /// the joints that turn it (advanced earlier in the same physics step) plus the base's
    /// turning about the steering axis ([`steering_turn_rate`]).
    pub fn advance(&mut self, i: usize, q: f64, dt: f64) -> ServoTarget {
        let following = self.steering[i].as_ref().map(|f| {
            let joint_turns = f
                .joints
                .iter()
                .map(|&(j, share)| (share, self.states[j].rate_now));
            let turn_rate =
                steering_turn_rate(joint_turns, &f.axis_b, &self.base_angular_velocity_b);
            (f.gain, turn_rate)
        });
        let a = &self.actuators[i];
        let s = &mut self.states[i];
        match a.mode {
            ActuatorMode::Position => {
                s.rate_now = s.command_rate.rate();
                s.command_rate.elapse(dt);
                s.setpoint = slew(s.setpoint, s.command, a.velocity_limit, dt);
                ServoTarget {
                    position: s.setpoint,
                    velocity: 0.0,
                }
            }
            ActuatorMode::Velocity => {
                let velocity = following.map_or(s.command, |(gain, turn_rate)| {
                    follow_steering(a, s.command, gain, turn_rate)
                });
                s.setpoint = integrate_velocity_setpoint(s.setpoint, velocity, q, max_lead(a), dt);
                ServoTarget {
                    position: s.setpoint,
                    velocity,
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::home_joint_positions;
    use kumi_model::{assemble, load_morphology, ModuleLibrary};

    fn model(name: &str) -> RobotModel {
        let library = ModuleLibrary::shipped();
        assemble(&load_morphology(name, &library).unwrap(), &library)
    }

    /// The shipped robot `name`, a servo bank for it and its home joint positions, every
    /// servo holding them.
    fn holding(name: &str) -> (RobotModel, ServoBank, Vec<f64>) {
        let model = model(name);
        let mut bank = ServoBank::new(&model);
        let q = home_joint_positions(&model);
        bank.hold(&q);
        (model, bank, q)
    }

    /// The actuator index of `joint` in `bank`.
    fn actuator(bank: &ServoBank, joint: &str) -> usize {
        bank.actuators()
            .iter()
            .position(|a| a.joint == joint)
            .unwrap()
    }

    /// Advances every servo one physics step of `dt` [s] at the joint positions `q`, in
    /// actuator order as the engines do; returns each servo's target.
    fn physics_step(bank: &mut ServoBank, q: &[f64], dt: f64) -> Vec<ServoTarget> {
        (0..q.len()).map(|i| bank.advance(i, q[i], dt)).collect()
    }

    #[test]
    fn a_wheel_follows_its_steering_commands_rate_for_one_command_period() {
        let (_, mut bank, q) = holding("tricycle");
        let (roll, left, right) = (
            actuator(&bank, "leg0/joint7"),
            actuator(&bank, "wheel0/wheel_left"),
            actuator(&bank, "wheel0/wheel_right"),
        );
        let gain = 0.286 / 0.27;
        let sign = bank.drive_sign("wheel0").unwrap();
        // 30 Hz commands, 4 physics steps each.
        let dt = 1.0 / 120.0;
        let command = |bank: &mut ServoBank, roll_rad: f64| {
            let mut targets = q[bank.module_range("leg0").unwrap()].to_vec();
            targets[6] = roll_rad;
            bank.set("leg0", ActuatorMode::Position, &targets).unwrap();
            bank.set("wheel0", ActuatorMode::Velocity, &[sign * 1.0, sign * 1.0])
                .unwrap();
        };
        // The first command after holding has no previous period: the wheels roll straight.
        command(&mut bank, q[roll]);
        for _ in 0..4 {
            let t = physics_step(&mut bank, &q, dt);
            assert_eq!((t[left].velocity, t[right].velocity), (sign, sign));
        }
        // 0.01 rad more after 1/30 s: 0.3 rad/s of roll, for 1/30 s.
        command(&mut bank, q[roll] + 0.01);
        for step in 0..4 {
            let t = physics_step(&mut bank, &q, dt);
            assert!(
                (t[left].velocity - (sign + gain * 0.3)).abs() < 1e-9,
                "{step}"
            );
            assert!(
                (t[right].velocity - (sign - gain * 0.3)).abs() < 1e-9,
                "{step}"
            );
        }
        // No new command: the following stops one period later; the drive command holds.
        let t = physics_step(&mut bank, &q, dt);
        assert_eq!((t[left].velocity, t[right].velocity), (sign, sign));
        // Other wheel modules do not follow leg0.
        assert_eq!(t[actuator(&bank, "wheel1/wheel_left")].velocity, 0.0);
    }

    #[test]
    fn a_wheel_follows_every_turn_of_its_module_about_the_steering_axis() {
        let (model, mut bank, q) = holding("tricycle");
        let (roll, joint5, left, right) = (
            actuator(&bank, "leg0/joint7"),
            actuator(&bank, "leg0/joint5"),
            actuator(&bank, "wheel0/wheel_left"),
            actuator(&bank, "wheel0/wheel_right"),
        );
        // Tricycle's leg tips steer about the vertical, pointing down at home.
        let coupling = &model.steering_couplings()[0];
        assert_eq!(coupling.wheel_joint, "wheel0/wheel_left");
        assert!((coupling.axis_b - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-9);
        let gain = coupling.gain;
        let dt = 1.0 / 120.0;
        let command = |bank: &mut ServoBank, roll_rad: f64| {
            let mut targets = q[bank.module_range("leg0").unwrap()].to_vec();
            targets[6] = roll_rad;
            bank.set("leg0", ActuatorMode::Position, &targets).unwrap();
        };
        // The base turning left at 0.5 rad/s (its z up) turns the module by -0.5 rad/s about
        // the steering axis: the wheels roll apart though the leg holds still.
        bank.set_base_angular_velocity(Vector3::new(0.0, 0.0, 0.5));
        command(&mut bank, q[roll]);
        for _ in 0..4 {
            let t = physics_step(&mut bank, &q, dt);
            assert!((t[left].velocity + gain * 0.5).abs() < 1e-12);
            assert!((t[right].velocity - gain * 0.5).abs() < 1e-12);
        }
        // A leg steering against the turn (+0.5 rad/s about its downward axis) keeps its
        // module's heading in the world: the wheels roll straight.
        command(&mut bank, q[roll] + 0.5 / 30.0);
        for _ in 0..4 {
            let t = physics_step(&mut bank, &q, dt);
            assert!(t[left].velocity.abs() < 1e-9 && t[right].velocity.abs() < 1e-9);
        }
        // Rolling and pitching do not turn the modules about their vertical axes.
        bank.set_base_angular_velocity(Vector3::new(0.7, -0.4, 0.0));
        let t = physics_step(&mut bank, &q, dt);
        assert!(t[left].velocity.abs() < 1e-12 && t[right].velocity.abs() < 1e-12);
        // The leg's joint5 turns about the vertical too: 0.01 rad of it in 1/30 s, with joint7
        // held, rolls the wheels apart as 0.3 rad/s of steering would.
        let mut targets = q[bank.module_range("leg0").unwrap()].to_vec();
        targets[6] = q[roll] + 0.5 / 30.0;
        bank.set("leg0", ActuatorMode::Position, &targets).unwrap();
        (0..4).for_each(|_| drop(physics_step(&mut bank, &q, dt)));
        targets[4] = q[joint5] + 0.01;
        bank.set("leg0", ActuatorMode::Position, &targets).unwrap();
        let t = physics_step(&mut bank, &q, dt);
        assert!((t[left].velocity - gain * 0.3).abs() < 1e-9);
        assert!((t[right].velocity + gain * 0.3).abs() < 1e-9);
    }

    #[test]
    fn a_following_wheel_stays_within_its_velocity_limit() {
        let (_, mut bank, q) = holding("tricycle");
        let left = actuator(&bank, "wheel0/wheel_left");
        let limit = bank.actuators()[left].velocity_limit;
        let sign = bank.drive_sign("wheel0").unwrap();
        bank.set(
            "wheel0",
            ActuatorMode::Velocity,
            &[sign * 10.0, sign * 10.0],
        )
        .unwrap();
        physics_step(&mut bank, &q, 0.01);
        // A full-speed roll (its velocity limit) on top of a full-speed drive.
        let mut targets = q[bank.module_range("leg0").unwrap()].to_vec();
        targets[6] += 1.0;
        bank.set("leg0", ActuatorMode::Position, &targets).unwrap();
        let t = physics_step(&mut bank, &q, 0.01);
        // One wheel is driven past its limit and held there; the other slows by the roll.
        let (l, r) = (t[left].velocity, t[left + 1].velocity);
        assert!(l.abs() <= limit && r.abs() <= limit, "{l} {r}");
        assert!(l.abs() == limit || r.abs() == limit, "{l} {r}");
        assert!((l.abs() - r.abs()).abs() > 1.0, "{l} {r}");
    }

    #[test]
    fn wheels_of_robots_without_follow_steering_take_their_command_alone() {
        for name in ["minimal", "dragon"] {
            let (model, mut bank, q) = holding(name);
            physics_step(&mut bank, &q, 0.01);
            for m in model.modules.iter().filter(|m| m.kind == "arm") {
                let mut targets = q[bank.module_range(&m.name).unwrap()].to_vec();
                targets.iter_mut().for_each(|t| *t += 0.01);
                bank.set(&m.name, ActuatorMode::Position, &targets).unwrap();
            }
            let t = physics_step(&mut bank, &q, 0.01);
            let mut wheels = 0;
            for (a, target) in bank.actuators().iter().zip(&t) {
                if a.mode == ActuatorMode::Velocity {
                    assert_eq!(target.velocity, 0.0, "{name} {}", a.joint);
                    wheels += 1;
                }
            }
            assert!(wheels >= 2, "{name} has wheels");
        }
    }
}
