//! Arm joints go where they are told: the tool frame settles where forward kinematics puts it.

mod common;

use common::{engines, world};
use kumi_model::kinematics::KinematicTree;
use kumi_worlds::Engine;
use nalgebra::Isometry3;

/// Steps one joint at a time on the fixed-base arm and checks that after 3 s the tool frame is
/// within 1 cm of its forward-kinematics position for the commanded configuration.
#[test]
fn a_joint_step_settles_within_1_cm_of_forward_kinematics() {
    for engine in engines() {
        joint_steps_settle(engine);
    }
}

fn joint_steps_settle(engine: Engine) {
    let mut w = world(engine, "arm");
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
        let home = w.home_state();
        w.reset(&home);
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
            "{engine}: joint{} -> {target} rad: tool {error:.4} m from forward kinematics",
            joint + 1
        );
    }
}

/// Targets beyond a joint's range are clamped to it, and the joint settles there.
#[test]
fn targets_are_clamped_to_joint_limits() {
    for engine in engines() {
        targets_clamp(engine);
    }
}

fn targets_clamp(engine: Engine) {
    let mut w = world(engine, "arm");
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
        "{engine}: settled at {q:?}"
    );
}

/// On every mobile robot, a step of each of the manipulator's joints lands the tool, in the
/// base frame, within 1 cm of forward kinematics of the commanded configuration (the other
/// modules at their measured joint angles).
#[test]
fn manipulator_steps_on_mobile_robots_land_within_1_cm_of_forward_kinematics() {
    for engine in engines() {
        for name in ["minimal", "dragon", "tricycle"] {
            for joint in 0..7 {
                let mut w = world(engine, name);
                let tree = KinematicTree::new(&w.model().urdf).unwrap();
                let range = w.module_range("arm0").unwrap();
                let mut q = w.commands()[range.clone()].to_vec();
                q[joint] += if joint % 2 == 0 { 0.6 } else { -0.4 };
                w.set_position_targets("arm0", &q).unwrap();
                for _ in 0..90 {
                    w.step();
                }
                let mut all = w.joint_positions();
                all[range.clone()].copy_from_slice(&q);
                let named = w.actuator_names().into_iter().zip(all);
                let expected = tree.forward(&Isometry3::identity(), &tree.positions(named))
                    [tree.link_index("arm0/ee").unwrap()];
                let actual = w.base_pose().inverse() * w.link_pose("arm0/ee").unwrap();
                let error = (actual.translation.vector - expected.translation.vector).norm();
                assert!(
                    error < 0.01,
                    "{engine} {name}: joint{} step: tool {error:.4} m from forward kinematics",
                    joint + 1
                );
            }
        }
    }
}
