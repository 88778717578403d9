//! Wheels that follow their steering, on hardware: the simulator's servos roll the wheels of a
//! `follow_steering` module with the commanded rate of the joint above them
//! ([`kumi_model::RobotModel::steering_couplings`]); on Motion Stack the whole-body node sends
//! the wheels, so it applies the same rule from the steering joints' commands, which the arm
//! nodes send on their limbs' `joint_set`. Pure: the ROS shell in [`crate::run`] feeds it
//! commands and wall time.

use kumi_model::commands::{follow_steering, wheel_joint_velocities, CommandRate};
use kumi_model::{RobotModel, SteeringCoupling};

/// One steering joint: its latest command and commanded rate.
#[derive(Debug, Clone)]
struct Steering {
    /// The model's joint name (`leg0/joint7`).
    joint: String,
    velocity_limit: f64,
    /// The latest command [rad]; `None` before the first.
    command: Option<f64>,
    rate: CommandRate,
}

/// The commanded rates of every steering joint of a robot, and the wheel velocities that
/// follow them.
#[derive(Debug, Clone)]
pub struct SteeringRates {
    couplings: Vec<SteeringCoupling>,
    joints: Vec<Steering>,
    /// The wall time [s] up to which every rate has been told the time that passed.
    now_s: f64,
}

impl SteeringRates {
    /// The steering joints of `model` (none for a robot without `follow_steering`).
    pub fn new(model: &RobotModel) -> Self {
        let couplings = model.steering_couplings();
        let mut joints: Vec<Steering> = Vec::new();
        for c in &couplings {
            if joints.iter().any(|s| s.joint == c.steering_joint) {
                continue;
            }
            let velocity_limit = model
                .actuators()
                .find(|a| a.joint == c.steering_joint)
                .map_or(0.0, |a| a.velocity_limit);
            joints.push(Steering {
                joint: c.steering_joint.clone(),
                velocity_limit,
                command: None,
                rate: CommandRate::default(),
            });
        }
        Self {
            couplings,
            joints,
            now_s: 0.0,
        }
    }

    /// Whether any wheel follows a steering joint.
    pub fn is_empty(&self) -> bool {
        self.couplings.is_empty()
    }

    /// The steering joints (model names), each once.
    pub fn joints(&self) -> impl Iterator<Item = &str> {
        self.joints.iter().map(|s| s.joint.as_str())
    }

    /// Lets the time up to `now_s` [s] pass (a clock that goes back is taken as standing).
    fn advance(&mut self, now_s: f64) {
        let dt = now_s - self.now_s;
        if dt > 0.0 {
            for s in &mut self.joints {
                s.rate.elapse(dt);
            }
            self.now_s = now_s;
        }
    }

    /// A command `position` [rad] for steering joint `joint` at `now_s` [s]. A non-finite
    /// position or a joint that steers nothing is ignored (returns false).
    pub fn command(&mut self, joint: &str, position: f64, now_s: f64) -> bool {
        if !position.is_finite() {
            return false;
        }
        self.advance(now_s);
        let Some(s) = self.joints.iter_mut().find(|s| s.joint == joint) else {
            return false;
        };
        let previous = s.command.unwrap_or(position);
        s.rate.command(previous, position, s.velocity_limit);
        s.command = Some(position);
        true
    }

    /// The commanded rate [rad/s] of a steering joint at `now_s` [s] (0 for any other joint).
    pub fn rate(&mut self, joint: &str, now_s: f64) -> f64 {
        self.advance(now_s);
        self.rate_now(joint)
    }

    /// Each wheel joint's velocity [rad/s] for wheel module `module` driven at `v` [rad/s] at
    /// `now_s` [s]: [`wheel_joint_velocities`], then each following wheel's
    /// [`follow_steering`]. `None` as `wheel_joint_velocities` gives it.
    pub fn wheel_velocities(
        &mut self,
        model: &RobotModel,
        module: &str,
        v: f64,
        now_s: f64,
    ) -> Option<Vec<(String, f64)>> {
        let mut wheels = wheel_joint_velocities(model, module, v)?;
        self.advance(now_s);
        for (joint, velocity) in &mut wheels {
            let Some(c) = self.couplings.iter().find(|c| &c.wheel_joint == joint) else {
                continue;
            };
            let actuator = model.actuators().find(|a| &a.joint == joint)?;
            *velocity = follow_steering(
                actuator,
                *velocity,
                c.gain,
                self.rate_now(&c.steering_joint),
            );
        }
        Some(wheels)
    }

    /// The commanded rate [rad/s] of a steering joint at the time last advanced to.
    fn rate_now(&self, joint: &str) -> f64 {
        self.joints
            .iter()
            .find(|s| s.joint == joint)
            .map_or(0.0, |s| s.rate.rate())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kumi_model::{assemble, load_morphology, ModuleLibrary};

    fn model(name: &str) -> RobotModel {
        let library = ModuleLibrary::shipped();
        assemble(&load_morphology(name, &library).unwrap(), &library)
    }

    #[test]
    fn a_legs_roll_commands_turn_its_wheels_apart_for_one_period() {
        let model = model("tricycle");
        let mut rates = SteeringRates::new(&model);
        assert_eq!(
            rates.joints().collect::<Vec<_>>(),
            ["leg0/joint7", "leg1/joint7", "leg2/joint7"]
        );
        let straight = wheel_joint_velocities(&model, "wheel0", 1.0).unwrap();
        // The first command has nothing before it: the wheels roll straight.
        assert!(rates.command("leg0/joint7", 0.0, 0.0));
        assert_eq!(
            rates.wheel_velocities(&model, "wheel0", 1.0, 0.01),
            Some(straight.clone())
        );
        // 0.01 rad in 1/32 s: 0.32 rad/s of roll until 1/32 s after the command.
        assert!(rates.command("leg0/joint7", 0.01, 0.03125));
        let gain = 0.286 / 0.27;
        let following = rates.wheel_velocities(&model, "wheel0", 1.0, 0.05).unwrap();
        assert!((following[0].1 - (straight[0].1 + gain * 0.32)).abs() < 1e-9);
        assert!((following[1].1 - (straight[1].1 - gain * 0.32)).abs() < 1e-9);
        // Another leg's wheels do not follow leg0.
        assert_eq!(
            rates.wheel_velocities(&model, "wheel1", 1.0, 0.05),
            wheel_joint_velocities(&model, "wheel1", 1.0)
        );
        // The commands stop: a period after the last the wheels roll straight again.
        assert_eq!(
            rates.wheel_velocities(&model, "wheel0", 1.0, 0.07),
            Some(straight)
        );
    }

    #[test]
    fn bad_steering_commands_are_ignored_and_other_robots_follow_nothing() {
        let tricycle = model("tricycle");
        let mut rates = SteeringRates::new(&tricycle);
        assert!(!rates.command("leg0/joint7", f64::NAN, 0.0));
        assert!(!rates.command("leg0/joint3", 0.5, 0.0));
        assert!(!rates.command("no/joint", 0.5, 0.0));
        assert_eq!(rates.rate("leg0/joint7", 0.1), 0.0);
        for name in ["minimal", "dragon"] {
            assert!(SteeringRates::new(&model(name)).is_empty(), "{name}");
        }
    }
}
