//! An arm module's forward kinematics: its tool pose in its own base frame from its joint
//! angles. Used by the arm node (to report its tool pose) and by training (working-pose goals).

use kumi_model::kinematics::KinematicTree;
use kumi_model::{ModuleInstance, RobotModel};
use nalgebra::Isometry3;

use crate::observation::JOINTS;

/// The module's forward kinematics: tool pose in the module's base frame from its joints.
#[derive(Debug, Clone)]
pub struct ToolKinematics {
    tree: KinematicTree,
    joints: Vec<String>,
    base: usize,
    tool: usize,
}

impl ToolKinematics {
    /// For `module` of `model`; an error names what is missing.
    pub fn new(model: &RobotModel, module: &ModuleInstance) -> Result<Self, String> {
        let tree = KinematicTree::new(&model.urdf).map_err(|e| e.to_string())?;
        let link = |name: &str| {
            tree.link_index(name)
                .ok_or_else(|| format!("no link `{name}`"))
        };
        let base = link(&module.root_link)?;
        let tool = link(module.ee_link.as_deref().unwrap_or_default())?;
        Ok(Self {
            joints: module.position_joints().map(|a| a.joint.clone()).collect(),
            tree,
            base,
            tool,
        })
    }

    /// The tool pose [m] in the module's base frame for joint angles `q` [rad].
    pub fn tool_pose_b(&self, q: &[f64; JOINTS]) -> Isometry3<f64> {
        let named = self
            .joints
            .iter()
            .map(String::as_str)
            .zip(q.iter().copied());
        let poses = self
            .tree
            .forward(&Isometry3::identity(), &self.tree.positions(named));
        poses[self.base].inverse() * poses[self.tool]
    }
}
