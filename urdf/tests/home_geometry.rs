//! The shipped morphologies' home poses are geometrically sound: wheels level on one plane,
//! axles where the drive direction needs them, names unique.

use std::collections::HashSet;

use kumi_model::kinematics::KinematicTree;
use kumi_model::{
    assemble, load_morphology, shipped_morphologies, ModuleLibrary, RobotModel, Role,
};
use nalgebra::{Isometry3, Vector3};

fn model(name: &str) -> RobotModel {
    let library = ModuleLibrary::shipped();
    let morphology = load_morphology(name, &library).unwrap();
    assemble(&morphology, &library)
}

/// Link poses at home, base at the identity.
fn home_poses(model: &RobotModel) -> (KinematicTree, Vec<Isometry3<f64>>) {
    let tree = KinematicTree::new(&model.urdf).unwrap();
    let named = model.modules.iter().flat_map(|m| {
        m.position_joints()
            .zip(&m.home)
            .map(|(a, q)| (a.joint.as_str(), *q))
    });
    let q = tree.positions(named);
    let poses = tree.forward(&Isometry3::identity(), &q);
    (tree, poses)
}

/// (centre [m], axle direction) of each wheel module, in the base frame at home.
fn wheel_axles(model: &RobotModel) -> Vec<(Vector3<f64>, Vector3<f64>)> {
    let (tree, poses) = home_poses(model);
    model
        .modules_with_role(Role::Wheel)
        .map(|m| {
            let body = poses[tree.link_index(&m.root_link).unwrap()];
            (body.translation.vector, body.rotation * Vector3::y())
        })
        .collect()
}

#[test]
fn every_shipped_morphology_has_unique_names() {
    for name in shipped_morphologies() {
        let m = model(name);
        // URDF keeps link and joint names in separate namespaces.
        let mut links = HashSet::new();
        for l in &m.urdf.links {
            assert!(
                links.insert(l.name.clone()),
                "{name}: duplicate link {}",
                l.name
            );
        }
        let mut joints = HashSet::new();
        for j in &m.urdf.joints {
            assert!(
                joints.insert(j.name.clone()),
                "{name}: duplicate joint {}",
                j.name
            );
        }
        KinematicTree::new(&m.urdf).unwrap();
    }
}

#[test]
fn module_counts_match_the_paper() {
    // Paper, section IV-B: Minimal 1 arm + 1 wheel, Dragon 2 + 2, Tricycle 4 + 3.
    for (name, arms, wheels) in [("minimal", 1, 1), ("dragon", 2, 2), ("tricycle", 4, 3)] {
        let m = model(name);
        let count = |kind: &str| m.modules.iter().filter(|x| x.kind == kind).count();
        assert_eq!((count("arm"), count("wheel")), (arms, wheels), "{name}");
        assert_eq!(m.modules_with_role(Role::Manipulator).count(), 1, "{name}");
    }
}

#[test]
fn wheels_stand_level_at_home() {
    for name in ["dragon", "tricycle"] {
        let axles = wheel_axles(&model(name));
        let z0 = axles[0].0.z;
        for (centre, axle) in &axles {
            assert!(
                (centre.z - z0).abs() < 0.01,
                "{name}: axle heights {axles:?}"
            );
            assert!(axle.z.abs() < 1e-6, "{name}: axle not horizontal: {axle}");
        }
    }
}

#[test]
fn wheel_axles_are_parallel_so_the_robot_drives_along_base_x() {
    for name in ["minimal", "dragon", "tricycle"] {
        for (_, axle) in wheel_axles(&model(name)) {
            assert!(
                axle.y.abs() > 1.0 - 1e-6,
                "{name}: axle {axle} not along base y: {:?}",
                wheel_axles(&model(name))
            );
        }
    }
}

#[test]
fn the_fixed_arm_tool_points_up_at_zero_and_its_x_axis_is_the_arm_axis() {
    let m = model("arm");
    let (tree, poses) = home_poses(&m);
    let ee = poses[tree.link_index("arm/ee").unwrap()];
    let x = ee.rotation * Vector3::x();
    assert!((x - Vector3::z()).norm() < 1e-9, "tool x axis {x}");
    // Joint offsets along z sum to 1.359 m, plus the 0.1 m tool.
    assert!(
        (ee.translation.vector.z - 1.459).abs() < 1e-3,
        "{}",
        ee.translation.vector
    );
}

#[test]
fn tricycles_wheels_follow_their_legs_turns_about_the_vertical_and_the_others_have_no_couplings() {
    let tricycle = model("tricycle");
    let couplings = tricycle.steering_couplings();
    assert_eq!(couplings.len(), 6, "{couplings:?}");
    for c in &couplings {
        let leg = c.wheel_joint.replace("wheel", "leg");
        let leg = leg.split('/').next().unwrap();
        assert_eq!(c.steering_joint(), format!("{leg}/joint7"), "{c:?}");
        // Half the track (0.286 m) over the tyre radius (0.27 m), the left wheel forward when
        // the roll is positive: the tip roll's axis points down the leg's last link.
        let expected = if c.wheel_joint.ends_with("wheel_left") {
            0.286 / 0.27
        } else {
            -0.286 / 0.27
        };
        assert!((c.gain - expected).abs() < 1e-9, "{c:?}");
        // The tip roll and joint5 turn the wheel module about the vertical; the pitches and
        // the rolls about the leg's length (joints 1 and 3) do not.
        let turning: Vec<&str> = c.turning_joints.iter().map(|(j, _)| j.as_str()).collect();
        assert_eq!(
            turning,
            [format!("{leg}/joint7"), format!("{leg}/joint5")],
            "{c:?}"
        );
        assert!(c
            .turning_joints
            .iter()
            .all(|(_, share)| (share - 1.0).abs() < 1e-9));
        assert!((c.axis_b - nalgebra::Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-9);
    }
    for other in ["minimal", "dragon"] {
        assert!(model(other).steering_couplings().is_empty(), "{other}");
    }
}
