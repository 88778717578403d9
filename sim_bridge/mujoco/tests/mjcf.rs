//! The generated MuJoCo model: built for every shipped robot from kumi-model alone, and a clear
//! error for what MuJoCo's builder cannot express. Pure Rust: runs without libmujoco.

use std::sync::Arc;

use kumi_engine::{SimConfig, SimError};
use kumi_model::{assemble, load_morphology, ModuleLibrary, RobotModel, SHIPPED_MORPHOLOGIES};
use kumi_mujoco::mjcf;

fn model(name: &str) -> RobotModel {
    let library = ModuleLibrary::shipped();
    assemble(&load_morphology(name, &library).unwrap(), &library)
}

#[test]
fn every_shipped_robot_has_a_model_with_its_masses_joints_and_frictions() {
    for (name, _) in SHIPPED_MORPHOLOGIES {
        let m = model(name);
        let config = SimConfig::for_model(&m);
        let out = mjcf::build(&m, &config).unwrap();
        assert_eq!(out.links.len(), m.urdf.links.len(), "{name}");
        // One hinge per moving URDF joint, with the model's armature for actuated ones.
        let hinges = out.xml.matches("type=\"hinge\"").count();
        let moving = m
            .urdf
            .joints
            .iter()
            .filter(|j| j.joint_type != urdf_rs::JointType::Fixed)
            .count();
        assert_eq!(hinges, moving, "{name}");
        for a in m.actuators() {
            let line = out
                .xml
                .lines()
                .find(|l| l.contains(&format!("<joint name=\"{}\"", a.joint)))
                .unwrap();
            assert!(
                line.contains(&format!("armature=\"{}\"", a.armature)),
                "{line}"
            );
            assert!(
                line.contains(&format!("damping=\"{}\"", a.joint_damping)),
                "{line}"
            );
        }
        // Every mass of the URDF, once.
        let urdf_mass: f64 = m.urdf.links.iter().map(|l| l.inertial.mass.value).sum();
        let mjcf_mass: f64 = out
            .xml
            .split("mass=\"")
            .skip(1)
            .map(|s| s[..s.find('"').unwrap()].parse::<f64>().unwrap())
            .sum();
        assert!(
            (urdf_mass - mjcf_mass).abs() < 1e-9,
            "{name}: {urdf_mass} vs {mjcf_mass}"
        );
        assert_eq!(out.xml.contains("<freejoint"), !m.fixed_base, "{name}");
    }
}

#[test]
fn the_tyres_take_their_friction_and_the_smaller_friction_wins() {
    let m = model("dragon");
    let out = mjcf::build(&m, &SimConfig::for_model(&m)).unwrap();
    let tyre = m.friction_of("front_wheel/tyre").unwrap();
    let line = out
        .xml
        .lines()
        .find(|l| l.contains("type=\"cylinder\" size=\"0.27"))
        .unwrap();
    assert!(line.contains(&format!("friction=\"{tyre} 0 0\"")), "{line}");
    // Lower friction has higher priority: arm links (0.8) outrank tyres and ground (1.0).
    let arm = out
        .xml
        .lines()
        .find(|l| l.contains("friction=\"0.8 0 0\""))
        .unwrap();
    assert!(
        arm.contains("priority=\"1\"") && line.contains("priority=\"0\""),
        "{arm}\n{line}"
    );
}

#[test]
fn a_mesh_collision_is_refused_naming_the_module_and_the_reason() {
    let mut m = model("tricycle");
    let link = m
        .urdf
        .links
        .iter_mut()
        .find(|l| l.name == "leg1/link3")
        .unwrap();
    link.collision[0].geometry = urdf_rs::Geometry::Mesh {
        filename: "leg.stl".into(),
        scale: None,
    };
    let err = mjcf::build(&m, &SimConfig::for_model(&m)).unwrap_err();
    assert!(
        matches!(err, SimError::Unsupported { ref module, .. } if module == "leg1"),
        "{err}"
    );
    let text = err.to_string();
    assert!(
        text.contains("leg1") && text.contains("Mesh") && text.contains("mujoco"),
        "{text}"
    );
}

#[test]
fn a_prismatic_joint_is_refused_naming_the_module() {
    let mut m = model("arm");
    let j = m
        .urdf
        .joints
        .iter_mut()
        .find(|j| j.name == "arm/joint3")
        .unwrap();
    j.joint_type = urdf_rs::JointType::Prismatic;
    let err = mjcf::build(&Arc::new(m.clone()), &SimConfig::for_model(&m)).unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("module `arm`") && text.contains("prismatic"),
        "{text}"
    );
}
