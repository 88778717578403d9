//! Wheels at constant velocity move the robot at omega * r.

mod common;

use common::{engines, world};
use kumi_model::Role;
use kumi_worlds::Engine;
use nalgebra::Vector3;

/// Wheel radius [m], from wheel.urdf (the tyre cylinder).
const WHEEL_RADIUS: f64 = 0.27;

fn drives_forward_at_omega_r(engine: Engine, name: &str) {
    let mut w = world(engine, name);
    let omega = 2.0; // [rad/s]
    let base_x = w.base_pose().rotation * Vector3::x();
    let model = w.model().clone();
    for m in model.modules_with_role(Role::Wheel) {
        // Positive drives the base along +x however the module is mounted (the world applies
        // `RobotModel::wheel_drive_sign`; Tricycle's wheel modules face backwards).
        w.set_wheel_velocity(&m.name, omega).unwrap();
    }
    // 2 s to get up to speed, then measure over 5 s.
    for _ in 0..60 {
        w.step();
    }
    let start = w.base_pose().translation.vector;
    for _ in 0..150 {
        w.step();
    }
    let travelled = (w.base_pose().translation.vector - start).dot(&base_x);
    let expected = omega * WHEEL_RADIUS * 5.0;
    let ratio = travelled / expected;
    assert!(
        (ratio - 1.0).abs() < 0.1,
        "{engine} {name}: travelled {travelled:.3} m in 5 s, expected {expected:.3} m (ratio {ratio:.3})"
    );
}

#[test]
fn minimal_drives_forward_at_omega_r() {
    for engine in engines() {
        drives_forward_at_omega_r(engine, "minimal");
    }
}

#[test]
fn dragon_drives_forward_at_omega_r() {
    for engine in engines() {
        drives_forward_at_omega_r(engine, "dragon");
    }
}

#[test]
fn tricycle_drives_forward_at_omega_r() {
    for engine in engines() {
        drives_forward_at_omega_r(engine, "tricycle");
    }
}

#[test]
fn wheel_velocity_is_clamped_and_nan_rejected() {
    for engine in engines() {
        wheel_commands_are_checked(engine);
    }
}

fn wheel_commands_are_checked(engine: Engine) {
    let mut w = world(engine, "dragon");
    w.set_wheel_velocity("front_wheel", 100.0).unwrap();
    let range = w.module_range("front_wheel").unwrap();
    assert_eq!(
        w.commands()[range.start],
        5.0,
        "wheel velocity limit is 5 rad/s"
    );
    let before = w.commands();
    assert!(w.set_wheel_velocity("front_wheel", f64::NAN).is_err());
    assert_eq!(w.commands(), before, "a rejected command changes nothing");
    assert!(w.set_wheel_velocity("no_such_module", 1.0).is_err());
    assert!(
        w.set_wheel_velocity("arm0", 1.0).is_err(),
        "arms have no wheels"
    );
    assert!(
        w.set_position_targets("arm0", &[0.0; 6]).is_err(),
        "7 values expected"
    );
}
