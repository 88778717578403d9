//! Forward kinematics over a URDF tree: pure functions on nalgebra isometries.
//!
//! Used by tests (where should the end effector be?), by the simulator to place a robot at a
//! joint configuration, and later by the nodes to report end-effector poses.

use nalgebra::{Isometry3, Unit, UnitQuaternion, Vector3};

use crate::pose;

/// The kind of motion a joint allows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum JointKind {
    /// Rotation about the axis [rad] (revolute and continuous joints).
    Revolute,
    /// Translation along the axis [m].
    Prismatic,
    /// No motion.
    Fixed,
}

/// One joint of the tree.
#[derive(Debug, Clone)]
pub struct TreeJoint {
    pub name: String,
    pub kind: JointKind,
    pub parent_link: usize,
    pub child_link: usize,
    /// Pose of the joint frame in the parent link's frame.
    pub origin: Isometry3<f64>,
    /// Joint axis in the joint frame.
    pub axis: Unit<Vector3<f64>>,
}

/// Errors in the URDF's tree structure.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TreeError {
    #[error("joint `{joint}` names unknown link `{link}`")]
    UnknownLink { joint: String, link: String },
    #[error("link `{link}` is the child of more than one joint")]
    TwoParents { link: String },
    #[error("the URDF must have exactly one root link; found {0:?}")]
    Roots(Vec<String>),
    #[error("joint `{joint}` has a zero-length axis")]
    ZeroAxis { joint: String },
    #[error("joint `{joint}` has unsupported type {kind}")]
    Unsupported { joint: String, kind: String },
}

/// A URDF's links and joints, joints ordered parents first.
#[derive(Debug, Clone)]
pub struct KinematicTree {
    links: Vec<String>,
    joints: Vec<TreeJoint>,
    root: usize,
}

impl KinematicTree {
    pub fn new(robot: &urdf_rs::Robot) -> Result<Self, TreeError> {
        let links: Vec<String> = robot.links.iter().map(|l| l.name.clone()).collect();
        let find = |joint: &str, name: &str| {
            links
                .iter()
                .position(|l| l == name)
                .ok_or_else(|| TreeError::UnknownLink {
                    joint: joint.to_string(),
                    link: name.to_string(),
                })
        };
        let mut unordered = Vec::with_capacity(robot.joints.len());
        let mut has_parent = vec![false; links.len()];
        for j in &robot.joints {
            let parent_link = find(&j.name, &j.parent.link)?;
            let child_link = find(&j.name, &j.child.link)?;
            if std::mem::replace(&mut has_parent[child_link], true) {
                return Err(TreeError::TwoParents {
                    link: links[child_link].clone(),
                });
            }
            let kind = match j.joint_type {
                urdf_rs::JointType::Revolute | urdf_rs::JointType::Continuous => {
                    JointKind::Revolute
                }
                urdf_rs::JointType::Prismatic => JointKind::Prismatic,
                urdf_rs::JointType::Fixed => JointKind::Fixed,
                ref other => {
                    return Err(TreeError::Unsupported {
                        joint: j.name.clone(),
                        kind: format!("{other:?}"),
                    })
                }
            };
            let axis = Vector3::from(j.axis.xyz.0);
            let axis = Unit::try_new(axis, 1e-9).ok_or_else(|| TreeError::ZeroAxis {
                joint: j.name.clone(),
            })?;
            unordered.push(TreeJoint {
                name: j.name.clone(),
                kind,
                parent_link,
                child_link,
                origin: pose::from_urdf(&j.origin),
                axis,
            });
        }
        let roots: Vec<usize> = (0..links.len()).filter(|&i| !has_parent[i]).collect();
        if roots.len() != 1 {
            return Err(TreeError::Roots(
                roots.iter().map(|&i| links[i].clone()).collect(),
            ));
        }
        let root = roots[0];
        // Order joints parents first (breadth-first from the root).
        let mut joints = Vec::with_capacity(unordered.len());
        let mut frontier = vec![root];
        while let Some(link) = frontier.pop() {
            let (children, rest): (Vec<_>, Vec<_>) = unordered
                .into_iter()
                .partition(|j: &TreeJoint| j.parent_link == link);
            unordered = rest;
            for j in children {
                frontier.push(j.child_link);
                joints.push(j);
            }
        }
        Ok(Self {
            links,
            joints,
            root,
        })
    }

    pub fn links(&self) -> &[String] {
        &self.links
    }

    /// Joints, parents first.
    pub fn joints(&self) -> &[TreeJoint] {
        &self.joints
    }

    pub fn root(&self) -> usize {
        self.root
    }

    pub fn link_index(&self, name: &str) -> Option<usize> {
        self.links.iter().position(|l| l == name)
    }

    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// The pose of each link (indexed like [`Self::links`]) given the root's pose and a
    /// position for each joint (indexed like [`Self::joints`]; ignored for fixed joints).
    pub fn forward(&self, root_pose: &Isometry3<f64>, q: &[f64]) -> Vec<Isometry3<f64>> {
        assert_eq!(q.len(), self.joints.len(), "one position per joint");
        let mut poses = vec![Isometry3::identity(); self.links.len()];
        poses[self.root] = *root_pose;
        for (j, &qj) in self.joints.iter().zip(q) {
            poses[j.child_link] = poses[j.parent_link] * j.origin * joint_motion(j, qj);
        }
        poses
    }

    /// Joint positions (indexed like [`Self::joints`]) from `(name, value)` pairs; others are 0.
    pub fn positions<'a>(&self, named: impl IntoIterator<Item = (&'a str, f64)>) -> Vec<f64> {
        let mut q = vec![0.0; self.joints.len()];
        for (name, value) in named {
            if let Some(i) = self.joint_index(name) {
                q[i] = value;
            }
        }
        q
    }
}

/// The transform a joint adds at position `q`.
pub fn joint_motion(joint: &TreeJoint, q: f64) -> Isometry3<f64> {
    match joint.kind {
        JointKind::Revolute => Isometry3::from_parts(
            Default::default(),
            UnitQuaternion::from_axis_angle(&joint.axis, q),
        ),
        JointKind::Prismatic => {
            Isometry3::translation(joint.axis.x * q, joint.axis.y * q, joint.axis.z * q)
        }
        JointKind::Fixed => Isometry3::identity(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::FRAC_PI_2;

    const TWO_LINK: &str = r#"<robot name="t">
      <link name="a"/><link name="b"/><link name="c"/>
      <joint name="j1" type="revolute"><parent link="a"/><child link="b"/>
        <origin xyz="0 0 1" rpy="0 0 0"/><axis xyz="0 1 0"/>
        <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
      <joint name="j2" type="fixed"><parent link="b"/><child link="c"/>
        <origin xyz="0 0 0.5" rpy="0 0 0"/></joint>
    </robot>"#;

    #[test]
    fn hand_computed_two_link_chain() {
        let robot = urdf_rs::read_from_string(TWO_LINK).unwrap();
        let tree = KinematicTree::new(&robot).unwrap();
        // Rotating j1 by +pi/2 about y turns the 0.5 m offset along z into +x.
        let q = tree.positions([("j1", FRAC_PI_2)]);
        let poses = tree.forward(&Isometry3::identity(), &q);
        let c = poses[tree.link_index("c").unwrap()].translation.vector;
        assert!((c - Vector3::new(0.5, 0.0, 1.0)).norm() < 1e-12, "{c}");
    }

    #[test]
    fn rejects_two_roots() {
        let robot = urdf_rs::read_from_string(
            r#"<robot name="t"><link name="a"/><link name="b"/></robot>"#,
        )
        .unwrap();
        assert!(matches!(
            KinematicTree::new(&robot),
            Err(TreeError::Roots(_))
        ));
    }
}
