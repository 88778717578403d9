//! Arm joints go where they are told: the tool frame settles where forward kinematics puts it.

mod common;

use common::world;
use kumi_model::kinematics::KinematicTree;
use nalgebra::Isometry3;

/// Steps one joint at a time on the fixed-base arm and checks that after 3 s the tool frame is
/// within 1 cm of its forward-kinematics position for the commanded configuration.
#[test]
fn a_joint_step_settles_within_1_cm_of_forward_kinematics() {
    let mut w = world("arm");
    let tree = KinematicTree::new(&w.model().urdf).unwrap();
    let names: Vec<String> = w.actuator_names().iter().map(|s| s.to_string()).collect();
    // One step per joint, each loading it against gravity where it can (pitch joints).
    let steps = [
        (0, 1.0),
        (1, 0.6),
        (2, -1.0),
        (3, 1.2),
        (4, 0.8),
        (5, -0.9),
        (6, 1.5),
    ];
    for (joint, target) in steps {
        w.reset(&w.home_state());
        let mut q = vec![0.0; 7];
        q[joint] = target;
        w.set_position_targets("arm", &q).unwrap();
        for _ in 0..90 {
            w.step();
        }
        let expected = tree.forward(
            &Isometry3::identity(),
            &tree.positions(names.iter().map(String::as_str).zip(q.iter().copied())),
        )[tree.link_index("arm/ee").unwrap()];
        let actual = w.link_pose("arm/ee").unwrap();
        let error = (actual.translation.vector - expected.translation.vector).norm();
        assert!(
            error < 0.01,
            "joint{} -> {target} rad: tool {error:.4} m from forward kinematics",
            joint + 1
        );
    }
}

/// Targets beyond a joint's range are clamped to it, and the joint settles there.
#[test]
fn targets_are_clamped_to_joint_limits() {
    let mut w = world("arm");
    w.set_position_targets("arm", &[5.0, 0.0, 0.0, 0.0, 0.0, 0.0, -5.0])
        .unwrap();
    assert_eq!(w.commands()[0], 2.8, "joint1's upper limit is 2.8 rad");
    assert_eq!(w.commands()[6], -2.8, "joint7's lower limit is -2.8 rad");
    // 2.8 rad at the 1.5 rad/s velocity limit takes 1.9 s.
    for _ in 0..90 {
        w.step();
    }
    let q = w.joint_positions();
    assert!(
        (q[0] - 2.8).abs() < 0.01 && (q[6] + 2.8).abs() < 0.01,
        "settled at {q:?}"
    );
}
