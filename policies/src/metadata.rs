//! The keys an exported skill carries in its ONNX `metadata_props`: the contract between the
//! exporter (training) and the runtime (evaluation, the arm-module node), defined once. The
//! values come from [`crate::skill::ArmSkill::metadata`]; [`crate::skill::ArmSkill::check`]
//! compares them with the module a policy is asked to drive.

/// Format tag of the low-level arm-reaching skill that reads the whole observation, the joint
/// step toward the goal included ([`crate::observation::OBSERVATION_DIM`] values).
pub const ARM_REACH_FORMAT: &str = "kumi-skill/arm-reach/4";
/// Format tag of a skill that reads the values up to the tool's error, the observation's
/// leading [`crate::observation::TOOL_DIM`].
pub const ARM_REACH_FORMAT_TOOL: &str = "kumi-skill/arm-reach/3";
/// Format tag of a skill that reads Table I's values and the targets' lead, the observation's
/// leading [`crate::observation::LEAD_DIM`].
pub const ARM_REACH_FORMAT_LEAD: &str = "kumi-skill/arm-reach/2";
/// Format tag of a skill that reads Table I's values only, the observation's leading
/// [`crate::observation::BASE_DIM`].
pub const ARM_REACH_FORMAT_BASE: &str = "kumi-skill/arm-reach/1";

pub const FORMAT: &str = "kumi.format";
pub const OBSERVATION: &str = "kumi.observation";
pub const OBSERVATION_DIM_KEY: &str = "kumi.observation_dim";
pub const ACTION_DIM_KEY: &str = "kumi.action_dim";
pub const JOINT_NAMES: &str = "kumi.joints";
/// Per-joint increment per control step [rad] for an action of 1, comma-separated.
pub const ACTION_SCALE: &str = "kumi.action_scale";
pub const ACTION_CLIP: &str = "kumi.action_clip";
pub const GOAL_FRAME: &str = "kumi.goal_frame";
pub const CONTROL_HZ: &str = "kumi.control_hz";
pub const CONFIG_HASH: &str = "kumi.config_hash";
pub const ENV_STEPS: &str = "kumi.env_steps";

/// The keys a policy must match to drive a module, in the order they are checked.
pub const CONTRACT_KEYS: [&str; 8] = [
    FORMAT,
    OBSERVATION_DIM_KEY,
    ACTION_DIM_KEY,
    OBSERVATION,
    JOINT_NAMES,
    ACTION_SCALE,
    ACTION_CLIP,
    CONTROL_HZ,
];

/// What the goal frame is, for people reading a policy file.
pub const GOAL_FRAME_TEXT: &str = "arm base frame: origin at the mount face, z along the arm; goal quaternion (w, x, y, z) with w >= 0 for the tool frame, whose x axis points out of the arm";

/// FNV-1a (64 bit) of a text, as 16 hex digits: a stable fingerprint of a training config.
pub fn fingerprint(text: &str) -> String {
    fingerprint_bytes(text.as_bytes())
}

/// FNV-1a (64 bit) of bytes (a policy file), as 16 hex digits.
pub fn fingerprint_bytes(bytes: &[u8]) -> String {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
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
}
