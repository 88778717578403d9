//! The MoonBot hardware profile: how kumi's modules map onto Motion Stack's limbs.
//!
//! Motion Stack (the MoonBot driver stack) runs one ROS 2 namespace per limb, numbered
//! (`/leg1`, `/leg2`, ...), each with `joint_set` (`sensor_msgs/JointState` in: absolute
//! position targets by joint name, or velocities for wheels) and `joint_read`
//! (`sensor_msgs/JointState` out, published only when a joint changes). A small TOML file beside
//! the morphology names each module's limb, renames joints where Motion Stack calls them
//! otherwise, and names the base odometry topic:
//!
//! ```toml
//! odometry = "/odom"         # nav_msgs/Odometry of the base (the whole-body node reads it)
//! [limbs.arm0]
//! namespace = "/leg1"
//! [limbs.arm0.joints]        # kumi's joint name (unprefixed) = Motion Stack's; the rest keep theirs
//! joint1 = "leg1_joint1"
//! [limbs.wheel0]
//! namespace = "/leg11"
//! ```

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::Deserialize;

/// A robot's Motion Stack profile.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotionStackProfile {
    /// `nav_msgs/Odometry` of the base: pose in its odometry frame, twist in the base frame.
    #[serde(default)]
    pub odometry: Option<String>,
    /// Per kumi module: its limb.
    pub limbs: BTreeMap<String, Limb>,
}

/// One module's limb.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Limb {
    /// Motion Stack's namespace of the limb (`/leg1`).
    pub namespace: String,
    /// kumi's joint name (unprefixed: `joint3`, `wheel_left`) to Motion Stack's; joints not
    /// listed keep their name.
    #[serde(default)]
    pub joints: BTreeMap<String, String>,
}

fn valid_topic(name: &str) -> bool {
    name.starts_with('/')
        && name.len() > 1
        && !name.ends_with('/')
        && !name.contains("//")
        && name[1..].split('/').all(|part| {
            part.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
                && !part.starts_with(|c: char| c.is_ascii_digit())
        })
}

impl MotionStackProfile {
    /// Reads and checks a profile against the robot's modules: `(module, its joints
    /// unprefixed)` for every module with joints. Errors name the file and the problem.
    pub fn load(path: &Path, modules: &[(String, Vec<String>)]) -> Result<Self, String> {
        let label = path.display();
        let text = std::fs::read_to_string(path).map_err(|e| format!("{label}: {e}"))?;
        let profile: Self = toml::from_str(&text).map_err(|e| format!("{label}: {e}"))?;
        profile
            .check(modules)
            .map_err(|e| format!("{label}: {e}"))?;
        Ok(profile)
    }

    /// Every module with joints has a limb with a valid, distinct namespace; every renamed joint
    /// exists; no limb names a module the robot lacks.
    pub fn check(&self, modules: &[(String, Vec<String>)]) -> Result<(), String> {
        for name in self.limbs.keys() {
            if !modules.iter().any(|(m, _)| m == name) {
                return Err(format!(
                    "limb for `{name}`, a module this robot does not have"
                ));
            }
        }
        let mut namespaces = BTreeMap::new();
        for (module, joints) in modules {
            let limb = self
                .limbs
                .get(module)
                .ok_or_else(|| format!("module `{module}` has no limb (`[limbs.{module}]`)"))?;
            if !valid_topic(&limb.namespace) {
                return Err(format!(
                    "limb `{module}`: namespace `{}` is not a ROS namespace (`/leg1`)",
                    limb.namespace
                ));
            }
            if let Some(other) = namespaces.insert(limb.namespace.clone(), module) {
                return Err(format!(
                    "limbs `{other}` and `{module}` share namespace `{}`",
                    limb.namespace
                ));
            }
            for (joint, renamed) in &limb.joints {
                if !joints.contains(joint) {
                    return Err(format!(
                        "limb `{module}`: no joint `{joint}` to rename (its joints: {})",
                        joints.join(", ")
                    ));
                }
                if renamed.is_empty() {
                    return Err(format!(
                        "limb `{module}`: joint `{joint}` renamed to nothing"
                    ));
                }
            }
        }
        if let Some(odom) = &self.odometry {
            if !valid_topic(odom) {
                return Err(format!("odometry topic `{odom}` is not a ROS topic name"));
            }
        }
        Ok(())
    }

    fn limb(&self, module: &str) -> &Limb {
        &self.limbs[module]
    }

    /// `<namespace>/joint_read` of a module's limb (a checked profile has every module).
    pub fn joint_read(&self, module: &str) -> String {
        format!("{}/joint_read", self.limb(module).namespace)
    }

    /// `<namespace>/joint_set` of a module's limb.
    pub fn joint_set(&self, module: &str) -> String {
        format!("{}/joint_set", self.limb(module).namespace)
    }

    /// Motion Stack's name of one of a module's joints (`joint` unprefixed).
    pub fn joint_name(&self, module: &str, joint: &str) -> String {
        self.limb(module)
            .joints
            .get(joint)
            .cloned()
            .unwrap_or_else(|| joint.to_string())
    }
}

/// Where a morphology's profile lives by default: beside the morphology file
/// (`tricycle.toml` -> `tricycle.motion_stack.toml`), for a shipped morphology in
/// `urdf/morphologies/`.
pub fn default_path(morphology: &str, shipped_dir: &Path) -> PathBuf {
    let path = Path::new(morphology);
    if path.extension().is_some_and(|e| e == "toml") {
        path.with_extension("motion_stack.toml")
    } else {
        shipped_dir.join(format!("{morphology}.motion_stack.toml"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn modules() -> Vec<(String, Vec<String>)> {
        vec![
            (
                "arm0".into(),
                (1..=7).map(|i| format!("joint{i}")).collect(),
            ),
            (
                "wheel0".into(),
                vec!["wheel_left".into(), "wheel_right".into()],
            ),
        ]
    }

    fn parse(text: &str) -> Result<MotionStackProfile, String> {
        let p: MotionStackProfile = toml::from_str(text).map_err(|e| e.to_string())?;
        p.check(&modules())?;
        Ok(p)
    }

    #[test]
    fn topics_and_joint_names_come_from_the_profile() {
        let p = parse(
            "odometry = \"/odom\"\n[limbs.arm0]\nnamespace = \"/leg1\"\n[limbs.arm0.joints]\njoint1 = \"j1\"\n[limbs.wheel0]\nnamespace = \"/leg11\"\n",
        )
        .unwrap();
        assert_eq!(p.joint_read("arm0"), "/leg1/joint_read");
        assert_eq!(p.joint_set("wheel0"), "/leg11/joint_set");
        assert_eq!(p.joint_name("arm0", "joint1"), "j1");
        assert_eq!(p.joint_name("arm0", "joint2"), "joint2");
        assert_eq!(
            default_path("tricycle", Path::new("/m")),
            PathBuf::from("/m/tricycle.motion_stack.toml")
        );
        assert_eq!(
            default_path("robots/cat.toml", Path::new("/m")),
            PathBuf::from("robots/cat.motion_stack.toml")
        );
    }

    #[test]
    fn a_profile_that_does_not_fit_the_robot_is_refused_with_the_reason() {
        let cases = [
            ("[limbs.arm0]\nnamespace = \"/leg1\"\n", "module `wheel0` has no limb"),
            ("[limbs.arm0]\nnamespace = \"/leg1\"\n[limbs.wheel0]\nnamespace = \"/leg1\"\n", "share namespace"),
            ("[limbs.arm0]\nnamespace = \"leg1\"\n[limbs.wheel0]\nnamespace = \"/leg2\"\n", "not a ROS namespace"),
            ("[limbs.arm0]\nnamespace = \"/leg1\"\n[limbs.arm0.joints]\njoint9 = \"x\"\n[limbs.wheel0]\nnamespace = \"/leg2\"\n", "no joint `joint9`"),
            ("[limbs.arm0]\nnamespace = \"/leg1\"\n[limbs.wheel0]\nnamespace = \"/leg2\"\n[limbs.tail]\nnamespace = \"/leg3\"\n", "does not have"),
            ("odometry = \"odom\"\n[limbs.arm0]\nnamespace = \"/leg1\"\n[limbs.wheel0]\nnamespace = \"/leg2\"\n", "odometry topic"),
            ("[limbs.arm0]\nnamespace = \"/leg1\"\nspeed = 3\n", "unknown field"),
        ];
        for (text, why) in cases {
            let err = parse(text).unwrap_err();
            assert!(err.contains(why), "{text}: {err}");
        }
    }
}
