//! Which links may touch each other: the same rule in every engine.
//!
//! rapier simulates a robot as one or more multibodies ([`Layout`]); links of one multibody
//! never collide with each other (a module's links overlap at their joints), links of
//! different multibodies do, except the two links a mount joins. MuJoCo reproduces this with
//! the groups computed here (and its own parent-child filter for the mount).

use kumi_model::{Layout, RobotModel};

/// Whether a mount joint becomes a fixed impulse joint between two multibodies (true) or a
/// joint inside one multibody (false) under `layout`. Only module mounts (`…/mount`) can be
/// impulse joints.
pub fn mount_is_impulse(model: &RobotModel, layout: Layout, joint: &urdf_rs::Joint) -> bool {
    if !joint.name.ends_with("/mount") {
        return false;
    }
    match layout {
        Layout::SingleMultibody => false,
        Layout::PerModule => true,
        Layout::PerLimb => {
            // A module with children starts its own multibody; leaves stay in their parent's.
            let child = joint.child.link.as_str();
            let Some(module) = model
                .modules
                .iter()
                .find(|m| m.links.iter().any(|l| l == child))
            else {
                return false;
            };
            model
                .modules
                .iter()
                .any(|c| c.parent.as_deref() == Some(module.name.as_str()))
        }
    }
}

/// The multibody group of every URDF link (in `model.urdf.links` order): links of one group
/// never collide with each other.
pub fn contact_groups(model: &RobotModel, layout: Layout) -> Vec<usize> {
    let links = &model.urdf.links;
    let index = |name: &str| links.iter().position(|l| l.name == name);
    let mut parent: Vec<usize> = (0..links.len()).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for joint in &model.urdf.joints {
        if mount_is_impulse(model, layout, joint) {
            continue;
        }
        if let (Some(a), Some(b)) = (index(&joint.parent.link), index(&joint.child.link)) {
            let (ra, rb) = (root(&mut parent, a), root(&mut parent, b));
            parent[ra.max(rb)] = ra.min(rb);
        }
    }
    // Number the groups densely, in order of first appearance.
    let mut ids: Vec<Option<usize>> = vec![None; links.len()];
    let mut next = 0;
    (0..links.len())
        .map(|i| {
            let r = root(&mut parent, i);
            *ids[r].get_or_insert_with(|| {
                next += 1;
                next - 1
            })
        })
        .collect()
}
