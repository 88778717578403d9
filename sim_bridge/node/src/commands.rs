//! Command intake: what arrives on each module's command topics, validated and turned into
//! servo commands. Pure: no ROS, no clock; the node passes in sim time.

use std::collections::BTreeMap;

use kumi_model::{Actuator, ActuatorMode, RobotModel};
use kumi_worlds::apply_increments;

/// Why a command was refused. Each kind is counted in `/diagnostics`.
#[derive(Debug, Clone, PartialEq)]
pub enum Rejection {
    NonFinite {
        module: String,
    },
    WrongLength {
        module: String,
        expected: usize,
        got: usize,
    },
    UnknownJoint {
        module: String,
        joint: String,
    },
    /// A joint named twice in one message (which value would win is not the sender's to leave
    /// to the receiver).
    DuplicateJoint {
        module: String,
        joint: String,
    },
    /// A command for a module that has no joints of that kind (increments to a wheel module).
    WrongModule {
        module: String,
        what: &'static str,
    },
    /// An increment larger than its joint can move in one control step.
    TooLarge {
        module: String,
        joint: String,
        increment_rad: f64,
        limit_rad: f64,
    },
}

impl Rejection {
    /// The counter this rejection increments.
    pub fn kind(&self) -> &'static str {
        match self {
            Rejection::NonFinite { .. } => "non_finite",
            Rejection::WrongLength { .. } => "wrong_length",
            Rejection::UnknownJoint { .. } => "unknown_joint",
            Rejection::DuplicateJoint { .. } => "duplicate_joint",
            Rejection::WrongModule { .. } => "wrong_module",
            Rejection::TooLarge { .. } => "too_large",
        }
    }
}

impl std::fmt::Display for Rejection {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Rejection::NonFinite { module } => write!(
                f,
                "{module}: rejected a command with NaN or infinite values"
            ),
            Rejection::WrongLength {
                module,
                expected,
                got,
            } => {
                write!(
                    f,
                    "{module}: rejected a command of {got} values, expected {expected}"
                )
            }
            Rejection::UnknownJoint { module, joint } => write!(
                f,
                "{module}: rejected a command for unknown joint `{joint}`"
            ),
            Rejection::DuplicateJoint { module, joint } => write!(
                f,
                "{module}: rejected a command that names joint `{joint}` twice"
            ),
            Rejection::WrongModule { module, what } => write!(
                f,
                "{module}: rejected a {what} command: this module has no such joints"
            ),
            Rejection::TooLarge {
                module,
                joint,
                increment_rad,
                limit_rad,
            } => write!(
                f,
                "{module}: rejected increments: {increment_rad:e} rad for `{joint}` is more than it moves in one control step ({limit_rad:.4} rad)"
            ),
        }
    }
}

/// One module's command state.
#[derive(Debug, Clone)]
struct ModuleState {
    /// Position joints' names (prefixed, `arm0/joint1`), in order.
    position_joints: Vec<String>,
    /// Their actuators (for ranges), in the same order.
    position_actuators: Vec<Actuator>,
    /// The largest increment [rad] each may take per control step.
    max_increments: Vec<f64>,
    has_wheels: bool,
    /// Position targets [rad] the module is following.
    targets: Vec<f64>,
    /// Wheel velocity [rad/s].
    wheel_velocity: f64,
    /// Sim time [s] of the last accepted command; `None` before any.
    last_command_s: Option<f64>,
    /// The module is holding because its commands stopped.
    holding: bool,
}

impl ModuleState {
    /// Records an accepted command at `now_s`: the module stops holding.
    fn accept(&mut self, now_s: f64) {
        self.last_command_s = Some(now_s);
        self.holding = false;
    }

    fn targets_update(&self, module: &str) -> Update {
        Update::PositionTargets {
            module: module.to_string(),
            targets: self.targets.clone(),
        }
    }
}

/// What each module is commanded to do, and the rules for changing it.
#[derive(Debug, Clone)]
pub struct Commands {
    modules: BTreeMap<String, ModuleState>,
    /// Commands older than this [s of sim time] make the module hold its position.
    stale_after_s: f64,
    /// Accepted increments that took a target past its joint's range (clamped there).
    clamped: u64,
}

/// A change for the simulator, produced by [`Commands`].
#[derive(Debug, Clone, PartialEq)]
pub enum Update {
    PositionTargets { module: String, targets: Vec<f64> },
    WheelVelocity { module: String, velocity: f64 },
}

impl Commands {
    /// Every module starts holding `home` (positions per module, in model order); increments
    /// are bounded by what each joint moves in one step at `control_hz` [Hz].
    pub fn new(
        model: &RobotModel,
        initial_positions: &BTreeMap<String, Vec<f64>>,
        stale_after_s: f64,
        control_hz: f64,
    ) -> Self {
        let modules = model
            .modules
            .iter()
            .map(|m| {
                let position_joints: Vec<String> =
                    m.position_joints().map(|a| a.joint.clone()).collect();
                let targets = initial_positions
                    .get(&m.name)
                    .cloned()
                    .unwrap_or_else(|| vec![0.0; position_joints.len()]);
                (
                    m.name.clone(),
                    ModuleState {
                        has_wheels: m.actuators.iter().any(|a| a.mode == ActuatorMode::Velocity),
                        position_actuators: m.position_joints().cloned().collect(),
                        max_increments: m
                            .position_joints()
                            .map(|a| a.max_increment(control_hz))
                            .collect(),
                        position_joints,
                        targets,
                        wheel_velocity: 0.0,
                        last_command_s: None,
                        holding: true,
                    },
                )
            })
            .collect();
        Self {
            modules,
            stale_after_s,
            clamped: 0,
        }
    }

    /// How many accepted increments were clamped at a joint limit so far.
    pub fn clamped(&self) -> u64 {
        self.clamped
    }

    fn module(&mut self, module: &str, what: &'static str) -> Result<&mut ModuleState, Rejection> {
        self.modules
            .get_mut(module)
            .ok_or_else(|| Rejection::WrongModule {
                module: module.to_string(),
                what,
            })
    }

    /// Joint increments [rad], one per position joint in order: targets move by that much.
    pub fn increments(
        &mut self,
        module: &str,
        increments: &[f64],
        now_s: f64,
    ) -> Result<Update, Rejection> {
        let state = self.module(module, "joint increments")?;
        if state.position_joints.is_empty() {
            return Err(Rejection::WrongModule {
                module: module.to_string(),
                what: "joint increments",
            });
        }
        if increments.len() != state.targets.len() {
            return Err(Rejection::WrongLength {
                module: module.to_string(),
                expected: state.targets.len(),
                got: increments.len(),
            });
        }
        if increments.iter().any(|x| !x.is_finite()) {
            return Err(Rejection::NonFinite {
                module: module.to_string(),
            });
        }
        // A tolerance of 1e-9 rad: a saturated skill action asks for exactly the limit.
        if let Some(i) =
            (0..increments.len()).find(|&i| increments[i].abs() > state.max_increments[i] + 1e-9)
        {
            return Err(Rejection::TooLarge {
                module: module.to_string(),
                joint: state.position_joints[i].clone(),
                increment_rad: increments[i],
                limit_rad: state.max_increments[i],
            });
        }
        let actuators: Vec<&Actuator> = state.position_actuators.iter().collect();
        let next = apply_increments(&state.targets, increments, &actuators)
            .expect("lengths and values were checked above");
        let clamped = next
            .iter()
            .zip(&state.targets)
            .zip(increments)
            .any(|((n, t), d)| *n != t + d);
        state.targets = next;
        state.accept(now_s);
        let update = state.targets_update(module);
        self.clamped += u64::from(clamped);
        Ok(update)
    }

    /// Absolute targets [rad] by joint name (`joint3` or `arm0/joint3`); joints not named keep
    /// their targets. The whole message is refused if any name is unknown or any value is bad.
    pub fn joint_set(
        &mut self,
        module: &str,
        names: &[String],
        positions: &[f64],
        now_s: f64,
    ) -> Result<Update, Rejection> {
        let state = self.module(module, "joint set")?;
        if state.position_joints.is_empty() {
            return Err(Rejection::WrongModule {
                module: module.to_string(),
                what: "joint set",
            });
        }
        if names.len() != positions.len() || names.is_empty() {
            return Err(Rejection::WrongLength {
                module: module.to_string(),
                expected: names.len(),
                got: positions.len(),
            });
        }
        if positions.iter().any(|x| !x.is_finite()) {
            return Err(Rejection::NonFinite {
                module: module.to_string(),
            });
        }
        let prefix = format!("{module}/");
        let mut indices = Vec::with_capacity(names.len());
        for name in names {
            let full = if name.starts_with(&prefix) {
                name.clone()
            } else {
                format!("{prefix}{name}")
            };
            let i = state
                .position_joints
                .iter()
                .position(|j| *j == full)
                .ok_or_else(|| Rejection::UnknownJoint {
                    module: module.to_string(),
                    joint: name.clone(),
                })?;
            if indices.contains(&i) {
                return Err(Rejection::DuplicateJoint {
                    module: module.to_string(),
                    joint: name.clone(),
                });
            }
            indices.push(i);
        }
        for (i, q) in indices.into_iter().zip(positions) {
            state.targets[i] = *q;
        }
        state.accept(now_s);
        Ok(state.targets_update(module))
    }

    /// A wheel velocity [rad/s] for both wheels of a wheel module.
    pub fn wheel_velocity(
        &mut self,
        module: &str,
        velocity: f64,
        now_s: f64,
    ) -> Result<Update, Rejection> {
        let state = self.module(module, "wheel velocity")?;
        if !state.has_wheels {
            return Err(Rejection::WrongModule {
                module: module.to_string(),
                what: "wheel velocity",
            });
        }
        if !velocity.is_finite() {
            return Err(Rejection::NonFinite {
                module: module.to_string(),
            });
        }
        state.wheel_velocity = velocity;
        state.accept(now_s);
        Ok(Update::WheelVelocity {
            module: module.to_string(),
            velocity,
        })
    }

    /// Records the targets the simulator actually applied (after clamping to joint limits), so
    /// that increments build on reachable targets.
    pub fn set_applied_targets(&mut self, module: &str, targets: &[f64]) {
        if let Some(state) = self.modules.get_mut(module) {
            state.targets = targets.to_vec();
        }
    }

    /// Modules whose commands stopped `stale_after_s` ago start holding: position targets go
    /// to where the joints are now, wheels stop. Returns the updates, once per module.
    pub fn expire(&mut self, now_s: f64, positions: &BTreeMap<String, Vec<f64>>) -> Vec<Update> {
        let mut updates = Vec::new();
        for (name, state) in &mut self.modules {
            let Some(last) = state.last_command_s else {
                continue;
            };
            if state.holding || now_s - last < self.stale_after_s {
                continue;
            }
            state.holding = true;
            if !state.position_joints.is_empty() {
                if let Some(q) = positions.get(name) {
                    state.targets = q.clone();
                }
                updates.push(state.targets_update(name));
            }
            if state.has_wheels {
                state.wheel_velocity = 0.0;
                updates.push(Update::WheelVelocity {
                    module: name.clone(),
                    velocity: 0.0,
                });
            }
        }
        updates
    }

    /// Whether a module is holding (no command yet, or its commands went stale).
    pub fn is_holding(&self, module: &str) -> bool {
        self.modules.get(module).is_none_or(|s| s.holding)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kumi_model::{assemble, load_morphology, ModuleLibrary};

    fn dragon() -> RobotModel {
        let library = ModuleLibrary::shipped();
        assemble(&load_morphology("dragon", &library).unwrap(), &library)
    }

    fn commands() -> Commands {
        Commands::new(&dragon(), &BTreeMap::new(), 0.5, 30.0)
    }

    #[test]
    fn increments_accumulate_on_the_targets() {
        let mut c = commands();
        c.increments("arm0", &[0.05; 7], 0.0).unwrap();
        let u = c
            .increments("arm0", &[0.03, 0.0, 0.0, 0.0, 0.0, 0.0, -0.05], 0.1)
            .unwrap();
        assert_eq!(
            u,
            Update::PositionTargets {
                module: "arm0".into(),
                targets: vec![0.08, 0.05, 0.05, 0.05, 0.05, 0.05, 0.0]
            }
        );
        assert_eq!(c.clamped(), 0);
    }

    #[test]
    fn increments_beyond_one_control_step_are_rejected_and_limits_counted() {
        // Issue 10, finding 1: `[1e308] * 7` was applied, clamped to the limits, uncounted.
        let mut c = commands();
        let err = c.increments("arm0", &[1e308; 7], 0.0).unwrap_err();
        assert_eq!(err.kind(), "too_large");
        assert!(err.to_string().contains("arm0/joint1"), "{err}");
        // 1.5 rad/s at 30 Hz: 0.05 rad per step, exactly the skill's saturated action.
        assert_eq!(
            c.increments("arm0", &[0.0, 0.0501, 0.0, 0.0, 0.0, 0.0, 0.0], 0.0)
                .unwrap_err()
                .kind(),
            "too_large"
        );
        assert!(c.is_holding("arm0"), "nothing was accepted");
        c.increments("arm0", &[-0.05; 7], 0.0).unwrap();
        assert_eq!(c.clamped(), 0);
        // joint2's range is [-2, 2]: from a target at 1.98 an increment of 0.05 clamps.
        let targets = [("arm0".to_string(), vec![1.98; 7])].into();
        let mut c = Commands::new(&dragon(), &targets, 0.5, 30.0);
        let u = c.increments("arm0", &[0.05; 7], 0.0).unwrap();
        let Update::PositionTargets { targets, .. } = u else {
            panic!("{u:?}")
        };
        assert_eq!(targets[1], 2.0);
        assert_eq!(c.clamped(), 1, "one message, counted once");
    }

    #[test]
    fn bad_increments_are_rejected_and_change_nothing() {
        let mut c = commands();
        assert_eq!(
            c.increments("arm0", &[0.1; 6], 0.0).unwrap_err().kind(),
            "wrong_length"
        );
        assert_eq!(
            c.increments("arm0", &[f64::NAN; 7], 0.0)
                .unwrap_err()
                .kind(),
            "non_finite"
        );
        assert_eq!(
            c.increments("front_wheel", &[0.0; 7], 0.0)
                .unwrap_err()
                .kind(),
            "wrong_module"
        );
        assert_eq!(
            c.increments("nobody", &[0.0; 7], 0.0).unwrap_err().kind(),
            "wrong_module"
        );
        assert!(
            c.is_holding("arm0"),
            "rejected commands do not count as commands"
        );
        let u = c.increments("arm0", &[0.0; 7], 0.0).unwrap();
        assert_eq!(
            u,
            Update::PositionTargets {
                module: "arm0".into(),
                targets: vec![0.0; 7]
            }
        );
    }

    #[test]
    fn joint_set_by_short_or_full_name() {
        let mut c = commands();
        let u = c
            .joint_set(
                "leg0",
                &["joint2".into(), "leg0/joint7".into()],
                &[0.3, -0.2],
                0.0,
            )
            .unwrap();
        assert_eq!(
            u,
            Update::PositionTargets {
                module: "leg0".into(),
                targets: vec![0.0, 0.3, 0.0, 0.0, 0.0, 0.0, -0.2]
            }
        );
        assert_eq!(
            c.joint_set(
                "leg0",
                &["joint2".into(), "leg0/joint2".into()],
                &[0.3, -0.2],
                0.0
            )
            .unwrap_err(),
            Rejection::DuplicateJoint {
                module: "leg0".into(),
                joint: "leg0/joint2".into()
            }
        );
        let err = c
            .joint_set("leg0", &["joint9".into()], &[0.1], 0.0)
            .unwrap_err();
        assert_eq!(
            err,
            Rejection::UnknownJoint {
                module: "leg0".into(),
                joint: "joint9".into()
            }
        );
        assert_eq!(
            c.joint_set("leg0", &["joint1".into()], &[], 0.0)
                .unwrap_err()
                .kind(),
            "wrong_length"
        );
        assert_eq!(
            c.joint_set("leg0", &["joint1".into()], &[f64::INFINITY], 0.0)
                .unwrap_err()
                .kind(),
            "non_finite"
        );
        assert_eq!(
            c.joint_set("leg0", &["arm0/joint1".into()], &[0.1], 0.0)
                .unwrap_err()
                .kind(),
            "unknown_joint"
        );
    }

    #[test]
    fn wheel_velocity_only_for_wheel_modules() {
        let mut c = commands();
        assert_eq!(
            c.wheel_velocity("rear_wheel", 2.0, 0.0).unwrap(),
            Update::WheelVelocity {
                module: "rear_wheel".into(),
                velocity: 2.0
            }
        );
        assert_eq!(
            c.wheel_velocity("arm0", 2.0, 0.0).unwrap_err().kind(),
            "wrong_module"
        );
        assert_eq!(
            c.wheel_velocity("rear_wheel", f64::NAN, 0.0)
                .unwrap_err()
                .kind(),
            "non_finite"
        );
    }

    #[test]
    fn stale_commands_hold_position_once() {
        let mut c = commands();
        c.increments("arm0", &[0.05; 7], 1.0).unwrap();
        c.wheel_velocity("front_wheel", 3.0, 1.0).unwrap();
        let measured: BTreeMap<String, Vec<f64>> = [("arm0".to_string(), vec![0.2; 7])].into();
        assert!(
            c.expire(1.4, &measured).is_empty(),
            "0.4 s is not stale yet"
        );
        let updates = c.expire(1.5, &measured);
        assert_eq!(
            updates,
            vec![
                Update::PositionTargets {
                    module: "arm0".into(),
                    targets: vec![0.2; 7]
                },
                Update::WheelVelocity {
                    module: "front_wheel".into(),
                    velocity: 0.0
                },
            ]
        );
        assert!(c.is_holding("arm0") && c.is_holding("front_wheel"));
        assert!(
            c.expire(3.0, &measured).is_empty(),
            "a holding module is not expired again"
        );
        // New increments build on the held position.
        let u = c.increments("arm0", &[0.05; 7], 3.1).unwrap();
        assert_eq!(
            u,
            Update::PositionTargets {
                module: "arm0".into(),
                targets: vec![0.25; 7]
            }
        );
    }
}
