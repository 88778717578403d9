//! Per-morphology simulation settings: how a robot is articulated in rapier. They live in the
//! morphology file (`[physics]`), so training, evaluation and the sim bridge all simulate a
//! robot the same way.
//!
//! The step settings (physics steps and solver iterations per control step) are deliberately
//! not here: a servo's response depends on them (measured: joint2's sag under gravity is
//! 0.0112 rad at 4 solver substeps per control step, 0.0043 rad at 16), and the low-level skill
//! trained on one arm must meet the same servos in every morphology.

use serde::Deserialize;

use crate::error::{ModelError, Problem};

/// How the robot's joints are split between rapier's multibodies (reduced coordinates, exact
/// joints, cost growing with DoF squared) and fixed impulse joints (cheap, but they flex).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layout {
    /// The whole robot is one multibody: mounts are exact.
    SingleMultibody,
    /// Each limb is its own multibody: a module with children starts a new multibody, joined to
    /// its parent by a fixed impulse joint; leaf modules (a wheel module at a leg's tip, a lone
    /// manipulator) stay in their parent's multibody.
    PerLimb,
    /// Each module is its own multibody; every mount is a fixed impulse joint.
    PerModule,
}

impl Layout {
    pub const ALL: [Layout; 3] = [Layout::SingleMultibody, Layout::PerLimb, Layout::PerModule];

    pub fn as_str(self) -> &'static str {
        match self {
            Layout::SingleMultibody => "single-multibody",
            Layout::PerLimb => "per-limb",
            Layout::PerModule => "per-module",
        }
    }

    pub fn parse(s: &str) -> Option<Layout> {
        Layout::ALL.into_iter().find(|l| l.as_str() == s)
    }
}

/// The `[physics]` table of a morphology file; unset fields fall back to the simulator's
/// defaults.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PhysicsSettings {
    pub layout: Option<Layout>,
    /// Physics steps per control step in MuJoCo, where a robot needs a finer step there than
    /// the default (rapier keeps its own).
    pub mujoco_substeps: Option<u32>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawPhysics {
    layout: Option<String>,
    mujoco_substeps: Option<u32>,
}

impl RawPhysics {
    pub(crate) fn validate(self, file: &str) -> Result<PhysicsSettings, ModelError> {
        let layout = match self.layout {
            None => None,
            Some(name) => Some(Layout::parse(&name).ok_or_else(|| {
                let known: Vec<_> = Layout::ALL.iter().map(|l| l.as_str()).collect();
                ModelError::new(
                    file,
                    "physics.layout",
                    Problem::BadValue(format!(
                        "unknown layout `{name}` (known: {})",
                        known.join(", ")
                    )),
                )
            })?),
        };
        if self.mujoco_substeps == Some(0) {
            return Err(ModelError::new(
                file,
                "physics.mujoco_substeps",
                Problem::BadValue("must be at least 1".into()),
            ));
        }
        Ok(PhysicsSettings {
            layout,
            mujoco_substeps: self.mujoco_substeps,
        })
    }
}
