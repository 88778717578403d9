//! Wheels that follow their steering, on hardware: the simulator's servos roll the wheels of a
//! `follow_steering` module with their module's turn about the vertical (the commanded rates of
//! the leg joints that turn it and the base's turning,
//! [`kumi_model::RobotModel::steering_couplings`]); on Motion Stack the whole-body node sends
//! the wheels, so it applies the same rule from those joints' commands, which the arm
//! nodes send on their limbs' `joint_set`, and from the base's turning, which odometry reports
//! ([`kumi_model::commands::steering_turn_rate`]). Pure: the ROS shell in [`crate::run`] feeds
//! it commands, odometry and wall time.

use kumi_model::commands::{
    follow_steering, steering_turn_rate, wheel_joint_velocities, CommandRate, MAX_COMMAND_GAP_S,
};
use kumi_model::{RobotModel, SteeringCoupling};
use nalgebra::Vector3;

/// One joint that turns a wheel module: its latest command and commanded rate.
#[derive(Debug, Clone)]
struct Steering {
    /// The model's joint name (`leg0/joint7`).
    joint: String,
    velocity_limit: f64,
    /// The latest command [rad]; `None` before the first.
    command: Option<f64>,
    rate: CommandRate,
}

/// The commanded rates of every joint that turns a following wheel module, and the wheel
/// velocities that follow them.
#[derive(Debug, Clone)]
pub struct SteeringRates {
    couplings: Vec<SteeringCoupling>,
    joints: Vec<Steering>,
    /// The wall time [s] up to which every rate has been told the time that passed.
    now_s: f64,
    /// The base's latest angular velocity [rad/s] in the base frame and when it came [s].
    base_turning: Option<(Vector3<f64>, f64)>,
}

impl SteeringRates {
    /// The joints that turn `model`'s following wheel modules (none for a robot without
    /// `follow_steering`).
    pub fn new(model: &RobotModel) -> Self {
        let couplings = model.steering_couplings();
        let mut joints: Vec<Steering> = Vec::new();
        for (joint, _) in couplings.iter().flat_map(|c| &c.turning_joints) {
            if joints.iter().any(|s| &s.joint == joint) {
                continue;
            }
            let velocity_limit = model
                .actuators()
                .find(|a| &a.joint == joint)
                .map_or(0.0, |a| a.velocity_limit);
            joints.push(Steering {
                joint: joint.clone(),
                velocity_limit,
                command: None,
                rate: CommandRate::default(),
            });
        }
        Self {
            couplings,
            joints,
            now_s: 0.0,
            base_turning: None,
        }
    }

    /// Whether any wheel follows a steering joint.
    pub fn is_empty(&self) -> bool {
        self.couplings.is_empty()
    }

    /// The joints that turn a following wheel module (model names), each once: Tricycle's
    /// legs' `joint7` and `joint5`.
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

    /// A command `position` [rad] for `joint`, one that turns a wheel module, at `now_s` [s].
    /// A non-finite position or a joint that turns none is ignored (returns false).
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

    /// The base's angular velocity `w_b` [rad/s] in the base frame (odometry's twist) at
    /// `now_s` [s]. It counts for [`MAX_COMMAND_GAP_S`]: odometry that stops turns no wheel.
    /// A non-finite value is ignored (returns false).
    pub fn base_turning(&mut self, w_b: Vector3<f64>, now_s: f64) -> bool {
        if !w_b.iter().all(|x| x.is_finite()) {
            return false;
        }
        self.base_turning = Some((w_b, now_s));
        true
    }

    /// The commanded rate [rad/s] of a joint that turns a wheel module at `now_s` [s] (0 for
    /// any other joint).
    pub fn rate(&mut self, joint: &str, now_s: f64) -> f64 {
        self.advance(now_s);
        self.rate_now(joint)
    }

    /// Each wheel joint's velocity [rad/s] for wheel module `module` driven at `v` [rad/s] at
    /// `now_s` [s]: [`wheel_joint_velocities`], then each following wheel's
    /// [`follow_steering`] of its module's turn (its leg's commanded rates and the base's
    /// turning). `None` as `wheel_joint_velocities` gives it.
    pub fn wheel_velocities(
        &mut self,
        model: &RobotModel,
        module: &str,
        v: f64,
        now_s: f64,
    ) -> Option<Vec<(String, f64)>> {
        let mut wheels = wheel_joint_velocities(model, module, v)?;
        self.advance(now_s);
        let base_w_b = match self.base_turning {
            Some((w_b, at_s)) if now_s - at_s <= MAX_COMMAND_GAP_S => w_b,
            _ => Vector3::zeros(),
        };
        for (joint, velocity) in &mut wheels {
            let Some(c) = self.couplings.iter().find(|c| &c.wheel_joint == joint) else {
                continue;
            };
            let actuator = model.actuators().find(|a| &a.joint == joint)?;
            let joint_turns = c
                .turning_joints
                .iter()
                .map(|(j, share)| (*share, self.rate_now(j)));
            let turn_rate = steering_turn_rate(joint_turns, &c.axis_b, &base_w_b);
            *velocity = follow_steering(actuator, *velocity, c.gain, turn_rate);
        }
        Some(wheels)
    }

    /// The commanded rate [rad/s] of a joint that turns a wheel module at the time last
    /// advanced to.
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
            [
                "leg0/joint7",
                "leg0/joint5",
                "leg1/joint7",
                "leg1/joint5",
                "leg2/joint7",
                "leg2/joint5"
            ]
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
    fn the_bases_turning_rolls_the_wheels_apart_while_odometry_is_fresh() {
        let model = model("tricycle");
        let mut rates = SteeringRates::new(&model);
        let straight = wheel_joint_velocities(&model, "wheel0", 1.0).unwrap();
        let coupling = &model.steering_couplings()[0];
        let turn = steering_turn_rate([], &coupling.axis_b, &Vector3::new(0.0, 0.0, 0.5));
        assert!(turn.abs() > 0.4, "the legs steer about the vertical");
        assert!(rates.base_turning(Vector3::new(0.0, 0.0, 0.5), 0.0));
        let turning = rates.wheel_velocities(&model, "wheel0", 1.0, 0.05).unwrap();
        assert!((turning[0].1 - (straight[0].1 + coupling.gain * turn)).abs() < 1e-9);
        assert!((turning[1].1 - (straight[1].1 - coupling.gain * turn)).abs() < 1e-9);
        // Odometry older than two periods turns nothing; a non-finite twist is ignored.
        assert!(!rates.base_turning(Vector3::new(0.0, f64::NAN, 0.5), 0.05));
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
