//! The contract an exported whole-body policy carries in its ONNX `metadata_props`, and the
//! check that it fits the morphology and the skill it is asked to run with. A mismatch names
//! the key and both values.

use std::collections::BTreeMap;

use kumi_model::RobotModel;
use kumi_policies::metadata;

use crate::action::ActionTerms;
use crate::observation::{self, ObservationOptions};

/// Format tag of a whole-body policy.
pub const WHOLE_BODY_FORMAT: &str = "kumi-policy/whole-body/1";

pub const MORPHOLOGY: &str = "kumi.morphology";
/// Fingerprint of the assembled robot (URDF, module roles and home angles, steering couplings).
pub const MORPHOLOGY_FINGERPRINT: &str = "kumi.morphology_fingerprint";
/// The robot fingerprint a policy was trained on, kept when `kumi policy restamp` moves it to a
/// changed robot without retraining (absent from files that were not re-stamped).
pub const TRAINED_MORPHOLOGY_FINGERPRINT: &str = "kumi.trained_morphology_fingerprint";
/// Fingerprint of the frozen skill's ONNX file the policy was trained over ([`NO_SKILL`] for
/// the flat baseline).
pub const SKILL_FINGERPRINT: &str = "kumi.skill_fingerprint";
/// The skill fingerprint of a policy that drives its joints without the skill.
pub const NO_SKILL: &str = "none";
/// The action terms ([`ActionTerms::describe`]).
pub const ACTION: &str = "kumi.action";

/// The keys a policy must match, in the order they are checked (the first mismatch is the
/// root cause: a foreign file fails on its format, another robot on its morphology).
pub const CONTRACT_KEYS: [&str; 9] = [
    metadata::FORMAT,
    MORPHOLOGY,
    MORPHOLOGY_FINGERPRINT,
    SKILL_FINGERPRINT,
    metadata::OBSERVATION_DIM_KEY,
    metadata::ACTION_DIM_KEY,
    metadata::OBSERVATION,
    ACTION,
    metadata::CONTROL_HZ,
];

/// The keys a training config decides (its observation slots and its action terms' bounds):
/// a policy that differs on one of them from the config it is checked against may have been
/// trained with another config of the same robot.
pub const CONFIG_KEYS: [&str; 4] = [
    metadata::OBSERVATION_DIM_KEY,
    metadata::ACTION_DIM_KEY,
    metadata::OBSERVATION,
    ACTION,
];

/// A policy that does not fit.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ContractMismatch {
    #[error(
        "metadata `{key}` is missing: not a kumi whole-body policy, or exported by an older kumi"
    )]
    Missing { key: &'static str },
    #[error("metadata `{key}` is `{found}`, but this robot and skill need `{expected}`")]
    Differs {
        key: &'static str,
        found: String,
        expected: String,
    },
}

impl ContractMismatch {
    /// The key that does not fit.
    pub fn key(&self) -> &'static str {
        match self {
            Self::Missing { key } | Self::Differs { key, .. } => key,
        }
    }

    /// Whether the key is one a training config decides ([`CONFIG_KEYS`]).
    pub fn from_config(&self) -> bool {
        CONFIG_KEYS.contains(&self.key())
    }
}

/// A robot's fingerprint: its URDF, each module's name, role and home angles, and its wheels'
/// steering couplings with their axes and turning joints (none for robots without
/// `follow_steering`, whose fingerprints are what they were before couplings existed).
pub fn morphology_fingerprint(model: &RobotModel) -> String {
    let mut text = model.urdf_xml();
    for m in &model.modules {
        text.push_str(&format!("\n{}:{}:{:?}", m.name, m.role, m.home));
    }
    for c in model.steering_couplings() {
        // The axis and the joints that turn the module too: a following wheel turns with each
        // of them and with the base about that axis.
        let a = c.axis_b;
        text.push_str(&format!(
            "\nsteer:{}<-{}:{:.9}:turn[{:.6},{:.6},{:.6}]",
            c.wheel_joint,
            c.steering_joint(),
            c.gain,
            a.x,
            a.y,
            a.z
        ));
        for (joint, share) in &c.turning_joints {
            text.push_str(&format!(":{joint}*{share:.6}"));
        }
    }
    metadata::fingerprint(&text)
}

/// What a whole-body policy for `model`, its `terms`, its optional observation slots
/// `options`, the skill file `skill_onnx` (its bytes; unused by flat terms) and `control_hz`
/// must carry.
pub fn contract(
    model: &RobotModel,
    terms: &ActionTerms,
    options: ObservationOptions,
    skill_onnx: &[u8],
    control_hz: f64,
) -> BTreeMap<String, String> {
    let wheels = terms.wheels().map(|w| w.wheels).sum();
    let joints = kumi_policies::observation::JOINTS;
    let flat_joints = terms.joint_terms().count() * joints;
    let arm_joints = terms.arms().count() * joints + flat_joints;
    let upper = observation::slots(wheels, arm_joints, terms.size(), options);
    let slots = observation::with_arm_state(upper, flat_joints);
    let skill = if terms.uses_skill() {
        metadata::fingerprint_bytes(skill_onnx)
    } else {
        NO_SKILL.to_string()
    };
    [
        (metadata::FORMAT, WHOLE_BODY_FORMAT.to_string()),
        (MORPHOLOGY, model.name.clone()),
        (MORPHOLOGY_FINGERPRINT, morphology_fingerprint(model)),
        (SKILL_FINGERPRINT, skill),
        (
            metadata::OBSERVATION_DIM_KEY,
            observation::size(&slots).to_string(),
        ),
        (metadata::ACTION_DIM_KEY, terms.size().to_string()),
        (metadata::OBSERVATION, observation::describe(&slots)),
        (ACTION, terms.describe()),
        (metadata::CONTROL_HZ, control_hz.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

/// Checks a policy's metadata against the contract `expected` ([`contract`]).
pub fn check(
    expected: &BTreeMap<String, String>,
    found: &BTreeMap<String, String>,
) -> Result<(), ContractMismatch> {
    for key in CONTRACT_KEYS {
        let want = expected.get(key).map(String::as_str).unwrap_or_default();
        match found.get(key) {
            None => return Err(ContractMismatch::Missing { key }),
            Some(v) if v != want => {
                return Err(ContractMismatch::Differs {
                    key,
                    found: v.clone(),
                    expected: want.to_string(),
                })
            }
            Some(_) => {}
        }
    }
    Ok(())
}

/// The base tilt [rad] at which the policy's training episodes ended (a fall).
pub const TILT_LIMIT: &str = "kumi.tilt_limit_rad";
/// Its training targets: x and y within this distance [m] of the base's start.
pub const TARGET_XY: &str = "kumi.target_xy_m";
/// Its training targets' heights [m], `low,high`.
pub const TARGET_Z: &str = "kumi.target_z_m";
/// Its training episodes' length [s].
pub const EPISODE: &str = "kumi.episode_s";

/// What a whole-body policy's training episodes were, carried in its metadata so that
/// deployment (the whole-body node, `kumi launch`, `kumi demo`) knows it without the training
/// config: when the robot has tipped over, where targets may be drawn, how long one takes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrainedTask {
    pub tilt_limit_rad: f64,
    pub target_xy_m: f64,
    pub target_z_m: [f64; 2],
    pub episode_s: f64,
}

impl TrainedTask {
    /// The metadata entries.
    pub fn metadata(&self) -> [(String, String); 4] {
        let [lo, hi] = self.target_z_m;
        [
            (TILT_LIMIT, self.tilt_limit_rad.to_string()),
            (TARGET_XY, self.target_xy_m.to_string()),
            (TARGET_Z, format!("{lo},{hi}")),
            (EPISODE, self.episode_s.to_string()),
        ]
        .map(|(k, v)| (k.to_string(), v))
    }

    /// Reads the entries: `None` for a policy exported without them (an older kumi), an error
    /// naming the key for one that is missing among the others or not a number.
    pub fn from_metadata(found: &BTreeMap<String, String>) -> Result<Option<Self>, String> {
        let keys = [TILT_LIMIT, TARGET_XY, TARGET_Z, EPISODE];
        if keys.iter().all(|k| !found.contains_key(*k)) {
            return Ok(None);
        }
        let number = |key: &str, text: &str| -> Result<f64, String> {
            text.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| format!("metadata `{key}` is `{text}`, not a number"))
        };
        let value = |key: &'static str| -> Result<&String, String> {
            found
                .get(key)
                .ok_or_else(|| format!("metadata `{key}` is missing beside the task's other keys"))
        };
        let z = value(TARGET_Z)?;
        let Some((lo, hi)) = z.split_once(',') else {
            return Err(format!("metadata `{TARGET_Z}` is `{z}`, not `low,high`"));
        };
        Ok(Some(Self {
            tilt_limit_rad: number(TILT_LIMIT, value(TILT_LIMIT)?)?,
            target_xy_m: number(TARGET_XY, value(TARGET_XY)?)?,
            target_z_m: [number(TARGET_Z, lo)?, number(TARGET_Z, hi)?],
            episode_s: number(EPISODE, value(EPISODE)?)?,
        }))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_trained_task_goes_into_the_metadata_and_back() {
        let task = TrainedTask {
            tilt_limit_rad: 0.785,
            target_xy_m: 3.0,
            target_z_m: [2.05, 2.45],
            episode_s: 12.0,
        };
        let mut m: BTreeMap<String, String> = task.metadata().into_iter().collect();
        assert_eq!(m[TARGET_Z], "2.05,2.45");
        assert_eq!(TrainedTask::from_metadata(&m), Ok(Some(task)));
        assert_eq!(TrainedTask::from_metadata(&BTreeMap::new()), Ok(None));
        m.insert(TILT_LIMIT.into(), "steep".into());
        let err = TrainedTask::from_metadata(&m).unwrap_err();
        assert!(err.contains(TILT_LIMIT) && err.contains("steep"), "{err}");
        m.remove(TILT_LIMIT);
        let err = TrainedTask::from_metadata(&m).unwrap_err();
        assert!(err.contains(TILT_LIMIT) && err.contains("missing"), "{err}");
    }
}
