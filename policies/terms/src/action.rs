//! Action terms: how the upper policy's action vector becomes commands for the modules.
//!
//! The action is laid out module by module in the morphology's order: an arm module takes a
//! goal for the frozen reaching skill (a manipulator 6 values: position and rotation; a leg 4:
//! position and roll about its tool's x axis), a wheel module one velocity for both wheels, a
//! passive body nothing. Every value is clipped to [-1, 1] (a non-finite one counts as 0) and
//! scaled: goals are bounded offsets around the module's home tool pose, in the module's base
//! frame (the frame the skill was trained in); a wheel's velocity is scaled by its limit, or by
//! the policy's wheel bound where that is lower. Where the policy sets a wheel acceleration,
//! the wheel commands follow the policy's through a [`WheelRamp`] (a rate limit whose state the
//! caller keeps, as it keeps the previous action). Where the policy sets a lateral
//! acceleration, a turn governor ([`turn_governor`]) first scales the wheel commands down
//! while the base turns faster than that at its speed.

use kumi_model::{ActuatorMode, ModuleInstance, RobotModel, Role};
use kumi_policies::kinematics::ToolKinematics;
use kumi_policies::observation::{Goal, JOINTS};
use nalgebra::{Isometry3, UnitQuaternion, Vector3};

/// How far goals may move from each arm module's home tool pose, and how fast the wheels may
/// turn (for an action of 1): `[action]` of a whole-body training config.
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct GoalBounds {
    /// Manipulator: largest position offset along each base-frame axis [m].
    pub manipulator_position_m: f64,
    /// Manipulator: largest component of the rotation vector [rad] that turns the home tool
    /// orientation (applied in the module's base frame).
    pub manipulator_rotation_rad: f64,
    /// Leg: largest position offset along each base-frame axis [m].
    pub leg_position_m: f64,
    /// Leg: largest roll [rad] about the tool's own x axis.
    pub leg_roll_rad: f64,
    /// Largest wheel velocity [rad/s] the policy may command (for an action of 1); absent or
    /// above a wheel module's own limit, that limit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wheel_velocity_rad_s: Option<f64>,
    /// Largest change of a wheel's commanded velocity [rad/s^2]: the command ramps toward the
    /// policy's at this rate ([`WheelRamp`]); absent, it follows the policy at once.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wheel_acceleration_rad_s2: Option<f64>,
    /// Largest lateral acceleration of a turn [m/s^2], the base's horizontal speed times its
    /// yaw rate: above it every wheel command is scaled down to meet it ([`turn_governor`]);
    /// absent, no governor.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lateral_acceleration_m_s2: Option<f64>,
}

impl GoalBounds {
    fn check(&self) -> Result<(), TermError> {
        let all = [
            ("manipulator_position_m", self.manipulator_position_m),
            ("manipulator_rotation_rad", self.manipulator_rotation_rad),
            ("leg_position_m", self.leg_position_m),
            ("leg_roll_rad", self.leg_roll_rad),
        ];
        match all.iter().find(|(_, v)| !(v.is_finite() && *v >= 0.0)) {
            Some((name, value)) => Err(TermError::Bound {
                name,
                value: *value,
            }),
            None => self.wheel().check(),
        }
    }

    /// The wheel terms' bounds.
    fn wheel(&self) -> WheelBounds {
        WheelBounds {
            velocity_rad_s: self.wheel_velocity_rad_s,
            acceleration_rad_s2: self.wheel_acceleration_rad_s2,
            lateral_acceleration_m_s2: self.lateral_acceleration_m_s2,
        }
    }
}

/// What bounds every wheel term of a policy (unset: the module's own limit, no ramp, no
/// governor).
#[derive(Debug, Clone, Copy)]
struct WheelBounds {
    velocity_rad_s: Option<f64>,
    acceleration_rad_s2: Option<f64>,
    lateral_acceleration_m_s2: Option<f64>,
}

impl WheelBounds {
    /// The wheel bounds, where set, must be positive.
    fn check(&self) -> Result<(), TermError> {
        let positive = |name, bound: Option<f64>| bound.map_or(Ok(()), |v| check_positive(name, v));
        positive("wheel_velocity_rad_s", self.velocity_rad_s)?;
        positive("wheel_acceleration_rad_s2", self.acceleration_rad_s2)?;
        positive("lateral_acceleration_m_s2", self.lateral_acceleration_m_s2)
    }
}

/// A scale that must be finite and above 0.
fn check_positive(name: &'static str, value: f64) -> Result<(), TermError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(TermError::NotPositive { name, value })
    }
}

impl GoalBounds {
    /// The bounds a policy was trained with, read back from its action description
    /// ([`ActionTerms::describe`], the `kumi.action` metadata): a deployed node takes them from
    /// the policy file, not from a training config. Bounds of a role the robot lacks are 0; the
    /// wheel bound is the largest wheel velocity described (none without wheels; for a policy
    /// trained without a bound, the wheels' own limit); the wheel acceleration and the turn
    /// governor's lateral acceleration are the ones every wheel entry names, by key after the
    /// velocity (none where none does; entries that differ, and unknown keys, are refused). The
    /// caller still checks the whole contract: terms built from these bounds must describe
    /// themselves exactly as the file does.
    pub fn from_description(description: &str) -> Result<Self, TermError> {
        let bad = |why: String| TermError::Description(why);
        let mut bounds = GoalBounds {
            manipulator_position_m: 0.0,
            manipulator_rotation_rad: 0.0,
            leg_position_m: 0.0,
            leg_roll_rad: 0.0,
            wheel_velocity_rad_s: None,
            wheel_acceleration_rad_s2: None,
            lateral_acceleration_m_s2: None,
        };
        let mut seen: Vec<(&str, f64, f64)> = Vec::new();
        // Every wheel entry's acceleration and governor (none, or one value for all: one bound
        // made them).
        let mut wheel_limits: Option<(Option<f64>, Option<f64>)> = None;
        for entry in description.split(';').filter(|e| !e.is_empty()) {
            let fields: Vec<&str> = entry.split(':').collect();
            let role = *fields
                .get(1)
                .ok_or_else(|| bad(format!("`{entry}` names no role")))?;
            if fields.get(3) == Some(&"joint_targets") {
                return Err(bad(format!(
                    "`{entry}`: a flat baseline policy (joint targets), not a policy over the skill"
                )));
            }
            let value = |i: usize, key: &str| -> Result<f64, TermError> {
                fields
                    .get(i)
                    .and_then(|f| f.strip_prefix(key))
                    .and_then(|v| v.strip_prefix('='))
                    .and_then(|v| v.parse::<f64>().ok())
                    .ok_or_else(|| bad(format!("`{entry}`: no number `{key}=` in field {i}")))
            };
            if role == "wheel" {
                let largest = |old: Option<f64>, new: f64| Some(old.map_or(new, |v| v.max(new)));
                let velocity = value(3, "velocity_rad_s")?;
                bounds.wheel_velocity_rad_s = largest(bounds.wheel_velocity_rad_s, velocity);
                let keyed = |key: &str| -> Result<Option<f64>, TermError> {
                    match fields[4..]
                        .iter()
                        .position(|f| f.split('=').next() == Some(key))
                    {
                        Some(i) => value(4 + i, key).map(Some),
                        None => Ok(None),
                    }
                };
                if let Some(unknown) = fields[4..].iter().find(|f| {
                    !matches!(
                        f.split('=').next(),
                        Some("acceleration_rad_s2" | "lateral_acceleration_m_s2")
                    )
                }) {
                    return Err(bad(format!("`{entry}`: unknown wheel bound `{unknown}`")));
                }
                let limits = (
                    keyed("acceleration_rad_s2")?,
                    keyed("lateral_acceleration_m_s2")?,
                );
                if wheel_limits.is_some_and(|l| l != limits) {
                    return Err(bad(format!(
                        "`{entry}`: wheel modules with different wheel bounds"
                    )));
                }
                wheel_limits = Some(limits);
                (
                    bounds.wheel_acceleration_rad_s2,
                    bounds.lateral_acceleration_m_s2,
                ) = limits;
                continue;
            }
            let position = value(3, "position_m")?;
            let rotation = match role {
                "manipulator" => value(4, "rotation_rad")?,
                "leg" => value(4, "roll_rad")?,
                other => return Err(bad(format!("`{entry}`: unknown role `{other}`"))),
            };
            if let Some((_, p, r)) = seen.iter().find(|(r, _, _)| *r == role) {
                if (*p, *r) != (position, rotation) {
                    return Err(bad(format!("two {role} modules with different bounds")));
                }
            }
            seen.push((role, position, rotation));
            if role == "manipulator" {
                bounds.manipulator_position_m = position;
                bounds.manipulator_rotation_rad = rotation;
            } else {
                bounds.leg_position_m = position;
                bounds.leg_roll_rad = rotation;
            }
        }
        bounds.check()?;
        Ok(bounds)
    }
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TermError {
    #[error("goal bound `{name}` must be finite and >= 0, not {value}")]
    Bound { name: &'static str, value: f64 },
    #[error("`{name}` must be finite and > 0, not {value}")]
    NotPositive { name: &'static str, value: f64 },
    #[error("module `{module}`: {message}")]
    Module { module: String, message: String },
    #[error("the action has {found} values, the morphology's terms take {expected}")]
    Size { expected: usize, found: usize },
    #[error("robot `{0}` has no arm or wheel module: nothing for a whole-body policy to command")]
    Empty(String),
    #[error("action description: {0}")]
    Description(String),
}

/// Clips to [-1, 1]; a non-finite value becomes 0 (hold the home goal, stop the wheel).
pub fn clip(a: f32) -> f64 {
    let a = f64::from(a);
    if a.is_finite() {
        a.clamp(-1.0, 1.0)
    } else {
        0.0
    }
}

/// An arm module's home joint angles [rad].
fn home_angles(module: &ModuleInstance) -> Result<[f64; JOINTS], TermError> {
    <[f64; JOINTS]>::try_from(module.home.as_slice()).map_err(|_| TermError::Module {
        module: module.name.clone(),
        message: format!(
            "{} home angles, an arm module has {JOINTS}",
            module.home.len()
        ),
    })
}

/// The frozen skill's goal for one arm module.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmGoalTerm {
    pub module: String,
    /// [`Role::Manipulator`] (6 values) or [`Role::Leg`] (4 values).
    pub role: Role,
    /// The tool pose at the module's home joint angles, in the module's base frame.
    pub home_tool_b: Isometry3<f64>,
    /// Position offset for an action of 1 [m].
    pub position_scale_m: f64,
    /// Rotation for an action of 1 [rad].
    pub rotation_scale_rad: f64,
}

impl ArmGoalTerm {
    /// The term for an arm module of `model`; its home tool pose by forward kinematics.
    pub fn new(
        model: &RobotModel,
        module: &ModuleInstance,
        bounds: &GoalBounds,
    ) -> Result<Self, TermError> {
        let fail = |message: String| TermError::Module {
            module: module.name.clone(),
            message,
        };
        let home = home_angles(module)?;
        let kinematics = ToolKinematics::new(model, module).map_err(fail)?;
        let (position_scale_m, rotation_scale_rad) = match module.role {
            Role::Manipulator => (
                bounds.manipulator_position_m,
                bounds.manipulator_rotation_rad,
            ),
            _ => (bounds.leg_position_m, bounds.leg_roll_rad),
        };
        Ok(Self {
            module: module.name.clone(),
            role: if module.role == Role::Manipulator {
                Role::Manipulator
            } else {
                Role::Leg
            },
            home_tool_b: kinematics.tool_pose_b(&home),
            position_scale_m,
            rotation_scale_rad,
        })
    }

    /// Action values this term takes: 6 for the manipulator, 4 for a leg.
    pub fn width(&self) -> usize {
        if self.role == Role::Manipulator {
            6
        } else {
            4
        }
    }

    /// Names of this term's action values, in order.
    pub fn value_names(&self) -> &'static [&'static str] {
        if self.role == Role::Manipulator {
            &["dx", "dy", "dz", "rx", "ry", "rz"]
        } else {
            &["dx", "dy", "dz", "roll"]
        }
    }

    /// The goal in the module's base frame for this term's `action` values (`width()` of
    /// them): home position plus the scaled offset; home orientation turned by the scaled
    /// rotation vector (manipulator, base frame) or rolled about the tool's x axis (leg).
    pub fn goal(&self, action: &[f32]) -> Goal {
        let a = |i: usize| clip(action[i]);
        let offset = Vector3::new(a(0), a(1), a(2)) * self.position_scale_m;
        let home = self.home_tool_b.rotation;
        let orientation_b = if self.role == Role::Manipulator {
            let r = Vector3::new(a(3), a(4), a(5)) * self.rotation_scale_rad;
            UnitQuaternion::from_scaled_axis(r) * home
        } else {
            home * UnitQuaternion::from_axis_angle(
                &Vector3::x_axis(),
                a(3) * self.rotation_scale_rad,
            )
        };
        Goal {
            position_b: self.home_tool_b.translation.vector + offset,
            orientation_b,
        }
    }
}

/// The flat baseline's arm term (the paper's section V-C): an arm module's seven joints commanded
/// directly, no skill between. Each action value moves its joint's absolute position target
/// from the home angle by up to `scale_rad`; the servos clamp to the joint range and slew as
/// they do for the skill's increments.
#[derive(Debug, Clone, PartialEq)]
pub struct JointTargetTerm {
    pub module: String,
    pub role: Role,
    /// The module's home joint angles [rad].
    pub home_rad: [f64; JOINTS],
    /// Offset from home for an action of 1 [rad].
    pub scale_rad: f64,
}

impl JointTargetTerm {
    /// The absolute joint position targets [rad] for this term's `JOINTS` action values.
    pub fn targets(&self, action: &[f32]) -> [f64; JOINTS] {
        std::array::from_fn(|j| self.home_rad[j] + clip(action[j]) * self.scale_rad)
    }
}

/// How far the flat baseline's joint targets may move from home (`[flat]` of a whole-body
/// training config).
#[derive(Debug, Clone, Copy, PartialEq, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct JointBounds {
    /// Largest offset of each arm joint's target from its home angle [rad].
    pub joint_scale_rad: f64,
    /// As [`GoalBounds::wheel_velocity_rad_s`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wheel_velocity_rad_s: Option<f64>,
    /// As [`GoalBounds::wheel_acceleration_rad_s2`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wheel_acceleration_rad_s2: Option<f64>,
    /// As [`GoalBounds::lateral_acceleration_m_s2`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lateral_acceleration_m_s2: Option<f64>,
}

impl JointBounds {
    fn check(&self) -> Result<(), TermError> {
        check_positive("joint_scale_rad", self.joint_scale_rad)?;
        self.wheel().check()
    }

    fn wheel(&self) -> WheelBounds {
        WheelBounds {
            velocity_rad_s: self.wheel_velocity_rad_s,
            acceleration_rad_s2: self.wheel_acceleration_rad_s2,
            lateral_acceleration_m_s2: self.lateral_acceleration_m_s2,
        }
    }
}

/// One velocity for both wheels of a wheel module.
#[derive(Debug, Clone, PartialEq)]
pub struct WheelTerm {
    pub module: String,
    /// Wheel velocity for an action of 1 [rad/s]: the wheels' velocity limit, or the policy's
    /// wheel bound where that is lower.
    pub scale_rad_s: f64,
    /// Wheels of the module (velocity joints).
    pub wheels: usize,
    /// Largest change of the commanded velocity [rad/s^2] ([`WheelRamp`]); none: no ramp.
    pub acceleration_rad_s2: Option<f64>,
    /// The turn governor's lateral acceleration [m/s^2] ([`turn_governor`]); none: no governor.
    pub lateral_acceleration_m_s2: Option<f64>,
}

impl WheelTerm {
    /// The wheel velocity [rad/s] for one action value.
    pub fn velocity(&self, action: f32) -> f64 {
        clip(action) * self.scale_rad_s
    }
}

/// One module's term.
#[derive(Debug, Clone, PartialEq)]
pub enum Term {
    Arm(ArmGoalTerm),
    Joints(JointTargetTerm),
    Wheel(WheelTerm),
}

impl Term {
    pub fn module(&self) -> &str {
        match self {
            Term::Arm(t) => &t.module,
            Term::Joints(t) => &t.module,
            Term::Wheel(t) => &t.module,
        }
    }

    pub fn width(&self) -> usize {
        match self {
            Term::Arm(t) => t.width(),
            Term::Joints(_) => JOINTS,
            Term::Wheel(_) => 1,
        }
    }
}

/// What one action commands: a goal per arm module (or, for the flat baseline, joint targets
/// per arm module) and a velocity per wheel module, each in the order of
/// [`ActionTerms::arms`], [`ActionTerms::joint_terms`] and [`ActionTerms::wheels`].
#[derive(Debug, Clone, PartialEq)]
pub struct Commands {
    pub goals: Vec<Goal>,
    /// Absolute joint position targets [rad] (flat baseline only).
    pub joint_targets: Vec<[f64; JOINTS]>,
    pub wheel_velocities: Vec<f64>,
}

/// Every module's term, in the morphology's module order.
#[derive(Debug, Clone, PartialEq)]
pub struct ActionTerms {
    pub terms: Vec<Term>,
}

impl ActionTerms {
    /// The terms of every arm and wheel module of `model`: a goal for the frozen skill per
    /// arm module.
    pub fn new(model: &RobotModel, bounds: &GoalBounds) -> Result<Self, TermError> {
        bounds.check()?;
        Self::build(model, bounds.wheel(), |module| {
            Ok(Term::Arm(ArmGoalTerm::new(model, module, bounds)?))
        })
    }

    /// The flat baseline's terms (the paper's section V-C): every arm joint's position target directly,
    /// a velocity per wheel module.
    pub fn flat(model: &RobotModel, bounds: &JointBounds) -> Result<Self, TermError> {
        bounds.check()?;
        let scale = bounds.joint_scale_rad;
        Self::build(model, bounds.wheel(), |module| {
            Ok(Term::Joints(JointTargetTerm {
                module: module.name.clone(),
                role: module.role,
                home_rad: home_angles(module)?,
                scale_rad: scale,
            }))
        })
    }

    /// Every module's term: `arm` makes an arm module's, a wheel module gets a wheel term
    /// scaled by its wheels' velocity limit, or by the wheel bound where that is lower, and
    /// ramped at the wheel acceleration where one is set.
    fn build(
        model: &RobotModel,
        wheel: WheelBounds,
        arm: impl Fn(&ModuleInstance) -> Result<Term, TermError>,
    ) -> Result<Self, TermError> {
        let mut terms = Vec::new();
        for module in &model.modules {
            let positions = module.position_joints().count();
            let wheels = module.velocity_joints().count();
            if positions == JOINTS && wheels == 0 && module.ee_link.is_some() {
                terms.push(arm(module)?);
            } else if wheels > 0 && positions == 0 {
                let limit = module
                    .actuators
                    .iter()
                    .filter(|a| a.mode == ActuatorMode::Velocity)
                    .map(|a| a.velocity_limit)
                    .fold(wheel.velocity_rad_s.unwrap_or(f64::INFINITY), f64::min);
                terms.push(Term::Wheel(WheelTerm {
                    module: module.name.clone(),
                    scale_rad_s: limit,
                    wheels,
                    acceleration_rad_s2: wheel.acceleration_rad_s2,
                    lateral_acceleration_m_s2: wheel.lateral_acceleration_m_s2,
                }));
            } else if positions + wheels > 0 {
                return Err(TermError::Module {
                    module: module.name.clone(),
                    message: format!("{positions} position and {wheels} velocity joints: neither an arm module ({JOINTS} position joints and a tool) nor a wheel module"),
                });
            }
        }
        if terms.is_empty() {
            return Err(TermError::Empty(model.name.clone()));
        }
        Ok(Self { terms })
    }

    /// Length of the action vector.
    pub fn size(&self) -> usize {
        self.terms.iter().map(Term::width).sum()
    }

    pub fn arms(&self) -> impl Iterator<Item = &ArmGoalTerm> {
        self.terms.iter().filter_map(|t| match t {
            Term::Arm(a) => Some(a),
            _ => None,
        })
    }

    /// The flat baseline's joint-target terms (none for a policy over the skill).
    pub fn joint_terms(&self) -> impl Iterator<Item = &JointTargetTerm> {
        self.terms.iter().filter_map(|t| match t {
            Term::Joints(j) => Some(j),
            _ => None,
        })
    }

    pub fn wheels(&self) -> impl Iterator<Item = &WheelTerm> {
        self.terms.iter().filter_map(|t| match t {
            Term::Wheel(w) => Some(w),
            _ => None,
        })
    }

    /// Whether these terms drive arm modules through the frozen skill (false: the flat
    /// baseline, or a robot with wheels only).
    pub fn uses_skill(&self) -> bool {
        self.arms().next().is_some()
    }

    /// The commands for one action vector of [`Self::size`] values.
    pub fn commands(&self, action: &[f32]) -> Result<Commands, TermError> {
        if action.len() != self.size() {
            return Err(TermError::Size {
                expected: self.size(),
                found: action.len(),
            });
        }
        let mut commands = Commands {
            goals: Vec::new(),
            joint_targets: Vec::new(),
            wheel_velocities: Vec::new(),
        };
        let mut at = 0;
        for term in &self.terms {
            let values = &action[at..at + term.width()];
            match term {
                Term::Arm(t) => commands.goals.push(t.goal(values)),
                Term::Joints(t) => commands.joint_targets.push(t.targets(values)),
                Term::Wheel(t) => commands.wheel_velocities.push(t.velocity(values[0])),
            }
            at += term.width();
        }
        Ok(commands)
    }

    /// Every action value's name (`arm0/dx`, `leg1/roll`, `wheel0/velocity`), in order.
    pub fn names(&self) -> Vec<String> {
        let mut names = Vec::new();
        for term in &self.terms {
            match term {
                Term::Arm(t) => {
                    names.extend(t.value_names().iter().map(|v| format!("{}/{v}", t.module)))
                }
                Term::Joints(t) => {
                    names.extend((1..=JOINTS).map(|j| format!("{}/joint{j}", t.module)))
                }
                Term::Wheel(t) => names.push(format!("{}/velocity", t.module)),
            }
        }
        names
    }

    /// The terms in one line, for a policy's metadata: per module its name, role, width and
    /// scales (`arm0:manipulator:6:position_m=0.25:rotation_rad=0.5;wheel0:wheel:1:velocity_rad_s=8`;
    /// a ramped wheel adds `:acceleration_rad_s2=4`).
    pub fn describe(&self) -> String {
        self.terms
            .iter()
            .map(|term| match term {
                Term::Arm(t) => format!(
                    "{}:{}:{}:position_m={}:{}={}",
                    t.module,
                    t.role,
                    t.width(),
                    t.position_scale_m,
                    if t.role == Role::Manipulator {
                        "rotation_rad"
                    } else {
                        "roll_rad"
                    },
                    t.rotation_scale_rad
                ),
                Term::Joints(t) => format!(
                    "{}:{}:{}:joint_targets:scale_rad={}",
                    t.module, t.role, JOINTS, t.scale_rad
                ),
                Term::Wheel(t) => {
                    let ramp = t
                        .acceleration_rad_s2
                        .map_or(String::new(), |a| format!(":acceleration_rad_s2={a}"));
                    let governor = t
                        .lateral_acceleration_m_s2
                        .map_or(String::new(), |a| format!(":lateral_acceleration_m_s2={a}"));
                    format!(
                        "{}:wheel:1:velocity_rad_s={}{ramp}{governor}",
                        t.module, t.scale_rad_s
                    )
                }
            })
            .collect::<Vec<_>>()
            .join(";")
    }
}

/// The lateral (centripetal) acceleration [m/s^2] of a base that drives along its heading at
/// `speed_xy_m_s` [m/s] while it turns at `yaw_rate_rad_s` [rad/s]: `|v_xy| |w_z|`. The turn
/// governor bounds it; training's turn penalty squares it.
pub fn turn_lateral_acceleration(speed_xy_m_s: f64, yaw_rate_rad_s: f64) -> f64 {
    speed_xy_m_s.abs() * yaw_rate_rad_s.abs()
}

/// The base's horizontal speed [m/s] and yaw rate [rad/s] (`|v_xy|`, `w_z`) from its linear
/// and angular velocity in a world frame with z up (the simulator's world, odometry's
/// `<robot>/odom`): what the turn governor and training's turn penalty read.
pub fn planar_twist(
    linear_velocity_w: &Vector3<f64>,
    angular_velocity_w: &Vector3<f64>,
) -> (f64, f64) {
    (linear_velocity_w.xy().norm(), angular_velocity_w.z)
}

/// The turn governor's scale for the wheel commands, in [0, 1]: 1 while the base's lateral
/// acceleration in a turn, `|v_xy| |w_z|` (its horizontal speed [m/s] times its yaw rate
/// [rad/s], no sideslip), is within `limit_m_s2`, else `limit / (|v_xy| |w_z|)`. Without a
/// limit 1; a non-finite speed or yaw rate gives 0 (stop the wheels). Training, evaluation and
/// the whole-body node scale every wheel module's command by it before the ramp.
pub fn turn_governor(limit_m_s2: Option<f64>, speed_xy_m_s: f64, yaw_rate_rad_s: f64) -> f64 {
    let Some(limit) = limit_m_s2 else {
        return 1.0;
    };
    let lateral = turn_lateral_acceleration(speed_xy_m_s, yaw_rate_rad_s);
    if !lateral.is_finite() {
        0.0
    } else if lateral > limit {
        limit / lateral
    } else {
        1.0
    }
}

impl ActionTerms {
    /// The turn governor's limit [m/s^2] of these terms (one for every wheel module; none
    /// without wheels or a governor).
    pub fn lateral_acceleration_m_s2(&self) -> Option<f64> {
        self.wheels().find_map(|w| w.lateral_acceleration_m_s2)
    }

    /// The turn governor's scale, in [0, 1], for the base's linear [m/s] and angular [rad/s]
    /// velocity in a world frame with z up ([`planar_twist`], [`turn_governor`] with these
    /// terms' limit): what [`ActionTerms::govern`] multiplies the wheel commands by.
    pub fn governor_scale(
        &self,
        linear_velocity_w: &Vector3<f64>,
        angular_velocity_w: &Vector3<f64>,
    ) -> f64 {
        let (speed_xy_m_s, yaw_rate_rad_s) = planar_twist(linear_velocity_w, angular_velocity_w);
        turn_governor(
            self.lateral_acceleration_m_s2(),
            speed_xy_m_s,
            yaw_rate_rad_s,
        )
    }

    /// Scales `wheel_velocities` [rad/s] (as [`Commands::wheel_velocities`]) by
    /// [`ActionTerms::governor_scale`] for the base's linear and angular velocity.
    pub fn govern(
        &self,
        wheel_velocities: &mut [f64],
        linear_velocity_w: &Vector3<f64>,
        angular_velocity_w: &Vector3<f64>,
    ) {
        let scale = self.governor_scale(linear_velocity_w, angular_velocity_w);
        wheel_velocities.iter_mut().for_each(|v| *v *= scale);
    }
}

/// The wheel commands' rate limit: each wheel module's commanded velocity moves toward the
/// policy's by at most its term's acceleration times the control period per step. Training,
/// evaluation and the whole-body node keep one each, so a policy drives its wheels as it
/// learnt to. Wheels without an acceleration follow the policy at once.
#[derive(Debug, Clone, PartialEq)]
pub struct WheelRamp {
    /// Per wheel module: the largest change per control step [rad/s] (none: no ramp).
    max_step_rad_s: Vec<Option<f64>>,
    /// Per wheel module: the velocity commanded last [rad/s].
    commanded_rad_s: Vec<f64>,
}

impl WheelRamp {
    /// The ramp for `terms`' wheel modules at `control_hz`, starting from stopped wheels.
    pub fn new(terms: &ActionTerms, control_hz: f64) -> Self {
        let max_step_rad_s: Vec<Option<f64>> = terms
            .wheels()
            .map(|w| w.acceleration_rad_s2.map(|a| a / control_hz))
            .collect();
        Self {
            commanded_rad_s: vec![0.0; max_step_rad_s.len()],
            max_step_rad_s,
        }
    }

    /// The velocities [rad/s] to command now for the policy's `wanted_rad_s` (one per wheel
    /// module, in the order of [`ActionTerms::wheels`]), remembered for the next step.
    pub fn follow(&mut self, wanted_rad_s: &[f64]) -> Vec<f64> {
        for ((now, wanted), step) in self
            .commanded_rad_s
            .iter_mut()
            .zip(wanted_rad_s)
            .zip(&self.max_step_rad_s)
        {
            *now = ramp(*now, *wanted, *step);
        }
        self.commanded_rad_s.clone()
    }

    /// The wheels were stopped (a new episode, a hold): the ramp starts again from 0.
    pub fn stop(&mut self) {
        self.commanded_rad_s.iter_mut().for_each(|v| *v = 0.0);
    }
}

/// One step of a rate limit: `wanted`, or as close to it as `max_step` from `now` allows (no
/// limit: exactly `wanted`).
pub fn ramp(now: f64, wanted: f64, max_step: Option<f64>) -> f64 {
    match max_step {
        Some(step) if (wanted - now).abs() > step => now + step.copysign(wanted - now),
        _ => wanted,
    }
}
