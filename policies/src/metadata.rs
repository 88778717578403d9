//! The metadata an exported skill carries in its ONNX `metadata_props`: the contract between the
//! exporter (training) and the runtime (the arm-module node), defined once. A runtime compares
//! these with the module it is asked to drive and refuses a mismatch.

use crate::action::INCREMENT_SCALE;
use crate::observation::{JOINTS, OBSERVATION_DIM, OBSERVATION_NAMES};

/// Format tag of the low-level arm-reaching skill.
pub const ARM_REACH_FORMAT: &str = "kumi-skill/arm-reach/1";

pub const FORMAT: &str = "kumi.format";
pub const OBSERVATION: &str = "kumi.observation";
pub const OBSERVATION_DIM_KEY: &str = "kumi.observation_dim";
pub const ACTION_DIM_KEY: &str = "kumi.action_dim";
pub const JOINT_NAMES: &str = "kumi.joints";
pub const ACTION_SCALE: &str = "kumi.action_scale";
pub const ACTION_CLIP: &str = "kumi.action_clip";
pub const GOAL_FRAME: &str = "kumi.goal_frame";
pub const CONTROL_HZ: &str = "kumi.control_hz";
pub const CONFIG_HASH: &str = "kumi.config_hash";
pub const ENV_STEPS: &str = "kumi.env_steps";

/// The arm skill's metadata. `joints` are the module's joint names in order (unprefixed),
/// `config_hash` identifies the training config, `env_steps` how long it trained.
pub fn arm_reach(
    joints: &[&str],
    control_hz: f64,
    config_hash: &str,
    env_steps: u64,
) -> Vec<(String, String)> {
    assert_eq!(joints.len(), JOINTS, "an arm module has {JOINTS} joints");
    [
        (FORMAT, ARM_REACH_FORMAT.to_string()),
        (OBSERVATION, OBSERVATION_NAMES.join(",")),
        (OBSERVATION_DIM_KEY, OBSERVATION_DIM.to_string()),
        (ACTION_DIM_KEY, JOINTS.to_string()),
        (JOINT_NAMES, joints.join(",")),
        (ACTION_SCALE, INCREMENT_SCALE.to_string()),
        (ACTION_CLIP, "1".to_string()),
        (
            GOAL_FRAME,
            "arm base frame: origin at the mount face, z along the arm; goal quaternion (w, x, y, z) with w >= 0 for the tool frame, whose x axis points out of the arm".to_string(),
        ),
        (CONTROL_HZ, control_hz.to_string()),
        (CONFIG_HASH, config_hash.to_string()),
        (ENV_STEPS, env_steps.to_string()),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

/// FNV-1a (64 bit) of a text, as 16 hex digits: a stable fingerprint of a training config.
pub fn fingerprint(text: &str) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    format!("{h:016x}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fingerprint_is_fnv1a() {
        // Published FNV-1a 64 test vectors.
        assert_eq!(fingerprint(""), "cbf29ce484222325");
        assert_eq!(fingerprint("a"), "af63dc4c8601ec8c");
    }

    #[test]
    fn arm_metadata_names_the_layout() {
        let joints = [
            "joint1", "joint2", "joint3", "joint4", "joint5", "joint6", "joint7",
        ];
        let m = arm_reach(&joints, 30.0, "abc", 480000);
        let get = |k: &str| m.iter().find(|(key, _)| key == k).map(|(_, v)| v.as_str());
        assert_eq!(get(FORMAT), Some(ARM_REACH_FORMAT));
        assert_eq!(get(OBSERVATION_DIM_KEY), Some("21"));
        assert_eq!(get(ACTION_SCALE), Some("0.05"));
        assert!(get(OBSERVATION).unwrap().starts_with("q1,q2,"));
        assert_eq!(
            get(JOINT_NAMES),
            Some("joint1,joint2,joint3,joint4,joint5,joint6,joint7")
        );
    }
}
