//! The arm skill's contract with the module it drives, derived once from the robot model and
//! the control rate: joint order and the action scale. (Joint ranges stay with the module's
//! actuators, which clamp increments everywhere through `kumi_model::commands::apply_increments`.) Training, evaluation and
//! the arm-module node all build one from the same model, and an exported policy carries it in
//! its metadata, so a policy trained for other joints, limits or rates is refused, not run.

use std::collections::BTreeMap;

use kumi_model::ModuleInstance;

use crate::metadata;
use crate::observation::{
    BASE_DIM, JOINTS, LEAD_DIM, OBSERVATION_DIM, OBSERVATION_NAMES, TOOL_DIM,
};

/// The bound [policy units] the skill's action values are clipped to before they are scaled
/// to joint increments ([`ArmSkill::increments`]).
pub const ACTION_LIMIT: f64 = 1.0;

/// How many of `action`'s values lie past +-[`ACTION_LIMIT`], where clipping makes them all
/// the largest increment. A skill whose mean actions mostly lie there acts as a relay: around a
/// goal it has reached it swings between its largest increments instead of settling
/// (`policies/arm_reach/README.md`). Non-finite values are not counted (they hold).
pub fn values_past_limit(action: &[f32]) -> usize {
    action
        .iter()
        .filter(|a| a.is_finite() && f64::from(a.abs()) > ACTION_LIMIT)
        .count()
}

/// The skill's view of one arm module.
#[derive(Debug, Clone, PartialEq)]
pub struct ArmSkill {
    /// The module's name in its robot (`arm`, `leg2`).
    pub module: String,
    /// Joint names in policy order, without the module prefix (`joint1` .. `joint7`).
    pub joints: Vec<String>,
    /// Largest increment per control step [rad] for each joint: the velocity limit [rad/s]
    /// divided by the control rate, so a saturated action asks for what the joint can do in
    /// one step.
    pub increment_scale: [f64; JOINTS],
    /// Control rate [Hz].
    pub control_hz: f64,
}

#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SkillError {
    #[error("module `{module}` is not an arm module: the arm skill drives {JOINTS} position joints and a tool frame, it has {positions} position joints, {velocities} velocity joints and {tool}")]
    NotAnArm {
        module: String,
        positions: usize,
        velocities: usize,
        tool: &'static str,
    },
    #[error("the control rate must be positive and finite, not {0} Hz")]
    ControlRate(f64),
}

/// How an exported policy's metadata differs from the module it is asked to drive.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MetadataMismatch {
    #[error("metadata `{key}` is missing: not a kumi skill policy, or exported by an older kumi")]
    Missing { key: &'static str },
    #[error("metadata `{key}` is `{found}`, but module `{module}` needs `{expected}`")]
    Differs {
        key: &'static str,
        module: String,
        found: String,
        expected: String,
    },
}

fn join<T: ToString>(values: &[T]) -> String {
    values
        .iter()
        .map(ToString::to_string)
        .collect::<Vec<_>>()
        .join(",")
}

impl ArmSkill {
    /// The skill for `module` of an assembled robot, stepped at `control_hz` [Hz].
    pub fn new(module: &ModuleInstance, control_hz: f64) -> Result<Self, SkillError> {
        if !(control_hz.is_finite() && control_hz > 0.0) {
            return Err(SkillError::ControlRate(control_hz));
        }
        let positions: Vec<_> = module.position_joints().collect();
        let velocities = module.velocity_joints().count();
        if positions.len() != JOINTS || velocities != 0 || module.ee_link.is_none() {
            return Err(SkillError::NotAnArm {
                module: module.name.clone(),
                positions: positions.len(),
                velocities,
                tool: if module.ee_link.is_some() {
                    "a tool frame"
                } else {
                    "no tool frame"
                },
            });
        }
        let prefix = format!("{}/", module.name);
        Ok(Self {
            module: module.name.clone(),
            joints: positions
                .iter()
                .map(|a| a.joint.trim_start_matches(prefix.as_str()).to_string())
                .collect(),
            increment_scale: std::array::from_fn(|i| positions[i].max_increment(control_hz)),
            control_hz,
        })
    }

    /// The joint increments [rad] for a policy output: each value clipped to
    /// [-[`ACTION_LIMIT`], [`ACTION_LIMIT`]] and scaled by its joint's [`Self::increment_scale`].
    /// A non-finite output becomes 0 (hold).
    pub fn increments(&self, action: &[f32; JOINTS]) -> [f64; JOINTS] {
        let mut out = [0.0; JOINTS];
        for ((o, a), scale) in out.iter_mut().zip(action).zip(&self.increment_scale) {
            let a = f64::from(*a);
            *o = if a.is_finite() {
                a.clamp(-ACTION_LIMIT, ACTION_LIMIT) * scale
            } else {
                0.0
            };
        }
        out
    }

    /// The metadata an exported policy of this skill carries, reading the leading
    /// `observation_dim` observation values ([`OBSERVATION_DIM`]; [`TOOL_DIM`], format
    /// `kumi-skill/arm-reach/3`; [`LEAD_DIM`], format `kumi-skill/arm-reach/2`; or [`BASE_DIM`]
    /// for Table I's observation, format `kumi-skill/arm-reach/1`). `config_hash` identifies the training
    /// config, `env_steps` how long it trained.
    pub fn metadata(
        &self,
        observation_dim: usize,
        config_hash: &str,
        env_steps: u64,
    ) -> BTreeMap<String, String> {
        let mut m = self.contract(observation_dim);
        m.insert(metadata::CONFIG_HASH.into(), config_hash.into());
        m.insert(metadata::ENV_STEPS.into(), env_steps.to_string());
        m.insert(
            metadata::GOAL_FRAME.into(),
            metadata::GOAL_FRAME_TEXT.into(),
        );
        m
    }

    /// The entries a policy reading the leading `observation_dim` observation values must
    /// match to drive this module.
    fn contract(&self, observation_dim: usize) -> BTreeMap<String, String> {
        let format = match observation_dim {
            BASE_DIM => metadata::ARM_REACH_FORMAT_BASE,
            LEAD_DIM => metadata::ARM_REACH_FORMAT_LEAD,
            TOOL_DIM => metadata::ARM_REACH_FORMAT_TOOL,
            _ => metadata::ARM_REACH_FORMAT,
        };
        [
            (metadata::FORMAT, format.to_string()),
            (
                metadata::OBSERVATION,
                OBSERVATION_NAMES[..observation_dim].join(","),
            ),
            (metadata::OBSERVATION_DIM_KEY, observation_dim.to_string()),
            (metadata::ACTION_DIM_KEY, JOINTS.to_string()),
            (metadata::JOINT_NAMES, self.joints.join(",")),
            (metadata::ACTION_SCALE, join(&self.increment_scale)),
            (metadata::ACTION_CLIP, ACTION_LIMIT.to_string()),
            (metadata::CONTROL_HZ, self.control_hz.to_string()),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect()
    }

    /// Checks a policy's metadata against this module: format, observation layout, sizes,
    /// joint names and order, action scale and clip, and control rate must all agree. Returns
    /// how many leading observation values the policy reads: [`OBSERVATION_DIM`], [`TOOL_DIM`]
    /// for a skill of format `kumi-skill/arm-reach/3`, [`LEAD_DIM`] for `/2` or [`BASE_DIM`]
    /// for `/1`.
    pub fn check(&self, found: &BTreeMap<String, String>) -> Result<usize, MetadataMismatch> {
        // Keys are checked in a fixed order so that the first error names the root cause
        // (a foreign file fails on its format, not on some later key).
        let observation_dim = match found.get(metadata::FORMAT).map(String::as_str) {
            Some(metadata::ARM_REACH_FORMAT_BASE) => BASE_DIM,
            Some(metadata::ARM_REACH_FORMAT_LEAD) => LEAD_DIM,
            Some(metadata::ARM_REACH_FORMAT_TOOL) => TOOL_DIM,
            _ => OBSERVATION_DIM,
        };
        let contract = self.contract(observation_dim);
        for key in metadata::CONTRACT_KEYS {
            let expected = &contract[key];
            match found.get(key) {
                None => return Err(MetadataMismatch::Missing { key }),
                Some(v) if v != expected => {
                    return Err(MetadataMismatch::Differs {
                        key,
                        module: self.module.clone(),
                        found: v.clone(),
                        expected: expected.clone(),
                    })
                }
                Some(_) => {}
            }
        }
        Ok(observation_dim)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kumi_model::{Actuator, ActuatorMode, Role};

    fn arm(velocity_limit: f64) -> ModuleInstance {
        let actuators = (1..=JOINTS)
            .map(|i| Actuator {
                joint: format!("leg1/joint{i}"),
                mode: ActuatorMode::Position,
                stiffness: 1.0,
                damping: 1.0,
                armature: 0.0,
                joint_damping: 0.0,
                joint_friction: 0.0,
                effort_limit: 10.0,
                velocity_limit,
                lower: -2.0,
                upper: 2.0,
            })
            .collect();
        ModuleInstance {
            name: "leg1".into(),
            kind: "arm".into(),
            role: Role::Leg,
            parent: None,
            mount_joint: None,
            root_link: "leg1/base".into(),
            links: vec![],
            ee_link: Some("leg1/ee".into()),
            actuators,
            home: vec![0.0; JOINTS],
            follow_steering: false,
        }
    }

    #[test]
    fn scale_is_velocity_limit_over_control_rate() {
        let skill = ArmSkill::new(&arm(1.5), 30.0).unwrap();
        assert_eq!(skill.joints[0], "joint1");
        assert!((skill.increment_scale[3] - 0.05).abs() < 1e-15);
        let inc = skill.increments(&[0.5, -0.5, 2.0, -3.0, 0.0, f32::NAN, f32::INFINITY]);
        assert_eq!(inc, [0.025, -0.025, 0.05, -0.05, 0.0, 0.0, 0.0]);
    }

    #[test]
    fn values_past_the_limit_are_counted_by_hand() {
        assert_eq!(values_past_limit(&[0.5, -0.5, 1.0, -1.0, 0.0]), 0);
        assert_eq!(
            values_past_limit(&[1.01, -3.0, 0.99, f32::NAN, f32::INFINITY]),
            2
        );
        assert_eq!(values_past_limit(&[]), 0);
    }

    #[test]
    fn a_policy_for_this_module_passes_its_own_check() {
        let skill = ArmSkill::new(&arm(1.5), 30.0).unwrap();
        let m = skill.metadata(OBSERVATION_DIM, "abc", 10);
        assert_eq!(
            m[metadata::ACTION_SCALE],
            "0.05,0.05,0.05,0.05,0.05,0.05,0.05"
        );
        assert_eq!(m[metadata::OBSERVATION_DIM_KEY], "41");
        assert_eq!(skill.check(&m), Ok(OBSERVATION_DIM));
        let tool = skill.metadata(TOOL_DIM, "abc", 10);
        assert_eq!(tool[metadata::FORMAT], metadata::ARM_REACH_FORMAT_TOOL);
        assert_eq!(skill.check(&tool), Ok(TOOL_DIM));
        let lead = skill.metadata(LEAD_DIM, "abc", 10);
        assert_eq!(lead[metadata::FORMAT], metadata::ARM_REACH_FORMAT_LEAD);
        assert_eq!(skill.check(&lead), Ok(LEAD_DIM));
    }

    #[test]
    fn a_skill_of_the_first_format_reads_the_leading_21_values() {
        let skill = ArmSkill::new(&arm(1.5), 30.0).unwrap();
        let mut m = skill.metadata(OBSERVATION_DIM, "abc", 10);
        m.insert(
            metadata::FORMAT.into(),
            metadata::ARM_REACH_FORMAT_BASE.into(),
        );
        m.insert(metadata::OBSERVATION_DIM_KEY.into(), "21".into());
        m.insert(
            metadata::OBSERVATION.into(),
            OBSERVATION_NAMES[..BASE_DIM].join(","),
        );
        assert_eq!(skill.check(&m), Ok(BASE_DIM));
        // The first format with the lead's names is not that layout.
        m.insert(metadata::OBSERVATION_DIM_KEY.into(), "28".into());
        let err = skill.check(&m).unwrap_err().to_string();
        assert!(err.contains("kumi.observation_dim"), "{err}");
    }

    #[test]
    fn mismatches_name_the_key_and_both_values() {
        let skill = ArmSkill::new(&arm(1.5), 30.0).unwrap();
        let trained = skill.metadata(OBSERVATION_DIM, "abc", 10);
        // Another control rate changes the scale and the rate: the scale is reported first.
        let other = ArmSkill::new(&arm(1.5), 60.0).unwrap();
        let err = other.check(&trained).unwrap_err().to_string();
        assert!(
            err.contains("kumi.action_scale") && err.contains("0.025"),
            "{err}"
        );
        // A missing key and a foreign format.
        let mut m = trained.clone();
        m.remove(metadata::JOINT_NAMES);
        assert_eq!(
            skill.check(&m),
            Err(MetadataMismatch::Missing {
                key: metadata::JOINT_NAMES
            })
        );
        let mut m = trained;
        m.insert(metadata::FORMAT.into(), "something-else".into());
        assert!(skill
            .check(&m)
            .unwrap_err()
            .to_string()
            .contains("`something-else`"));
    }

    #[test]
    fn wheels_are_not_arms() {
        let mut m = arm(1.5);
        m.actuators[6].mode = ActuatorMode::Velocity;
        let err = ArmSkill::new(&m, 30.0).unwrap_err().to_string();
        assert!(err.contains("6 position joints, 1 velocity"), "{err}");
        assert!(ArmSkill::new(&arm(1.5), 0.0).is_err());
    }
}
