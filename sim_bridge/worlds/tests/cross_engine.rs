//! The two engines simulate the same robot: same kinematics and masses, and the same command
//! sequence gives tool trajectories that agree.
#![cfg(feature = "mujoco")]

mod common;

use common::{model, world, Rng};
use kumi_model::kinematics::KinematicTree;
use kumi_worlds::Engine;
use nalgebra::Isometry3;

const ROBOTS: [&str; 4] = ["arm", "minimal", "dragon", "tricycle"];

/// Placed at random configurations (without stepping), every link of every robot is where
/// kumi's forward kinematics of the URDF puts it, in both engines.
#[test]
fn both_engines_place_every_link_at_its_forward_kinematics() {
    for name in ROBOTS {
        let model = model(name);
        let tree = KinematicTree::new(&model.urdf).unwrap();
        let mut rng = Rng::new(5);
        for engine in [Engine::Rapier, Engine::Mujoco] {
            let mut w = world(engine, name);
            for _ in 0..20 {
                let q: Vec<f64> = w
                    .servos()
                    .actuators()
                    .iter()
                    .map(|a| rng.uniform(a.lower.max(-3.0), a.upper.min(3.0)))
                    .collect();
                let state = w.standing_state(rng.uniform(-1.0, 1.0), 0.0, 0.5, q.clone());
                w.reset(&state);
                let named = w.actuator_names().into_iter().zip(q.iter().copied());
                let base = if model.fixed_base {
                    Isometry3::identity()
                } else {
                    state.base_pose_w
                };
                let expected = tree.forward(&base, &tree.positions(named));
                for (i, (link, pose)) in w.body_poses().iter().enumerate() {
                    let error = (pose.translation.vector - expected[i].translation.vector).norm();
                    let angle = (pose.rotation.inverse() * expected[i].rotation).angle();
                    // rapier stores poses in f32.
                    assert!(
                        error < 1e-5 && angle < 1e-5,
                        "{engine} {name}: {link} is {error} m / {angle} rad from FK"
                    );
                }
            }
        }
    }
}

/// The arm's tool, in the base frame, over 2 s after a step of one joint from home.
fn step_response(
    engine: Engine,
    name: &str,
    module: &str,
    joint: usize,
    delta: f64,
) -> Vec<Isometry3<f64>> {
    let mut w = world(engine, name);
    let range = w.module_range(module).unwrap();
    let mut q: Vec<f64> = w.commands()[range].to_vec();
    q[joint] += delta;
    w.set_position_targets(module, &q).unwrap();
    let ee = w.model().module(module).unwrap().ee_link.clone().unwrap();
    (0..60)
        .map(|_| {
            w.step();
            w.base_pose().inverse() * w.link_pose(&ee).unwrap()
        })
        .collect()
}

/// Joint steps of every arm joint agree between the engines within 2 cm (fixed arm) or 3 cm
/// (mobile robots) at the tool, in the base frame, at every control step over 2 s, and within
/// 1 cm once settled; one saturated case within 7 cm. Why 2 cm: the servo law is the same,
/// but rapier's motor is softer and less damped (peak joint speeds 1.5–1.9x MuJoCo's while
/// settling; gravity sag 0.0034 against 0.0024 rad at joint2), which is a few millimetres at
/// the tool of a 1.5 m arm, more during the transient.
#[test]
fn joint_steps_agree_between_engines() {
    let cases = [
        ("arm", "arm"),
        ("minimal", "arm0"),
        ("dragon", "arm0"),
        ("tricycle", "arm0"),
    ];
    for (name, module) in cases {
        for joint in 0..7 {
            let delta = if joint % 2 == 0 { 0.8 } else { -0.5 };
            let a = step_response(Engine::Rapier, name, module, joint, delta);
            let b = step_response(Engine::Mujoco, name, module, joint, delta);
            let gaps: Vec<f64> = a
                .iter()
                .zip(&b)
                .map(|(x, y)| (x.translation.vector - y.translation.vector).norm())
                .collect();
            let worst = gaps.iter().copied().fold(0.0, f64::max);
            let last = *gaps.last().unwrap();
            println!(
                "{name} {module} joint{}: worst {:.1} mm, settled {:.1} mm",
                joint + 1,
                worst * 1e3,
                last * 1e3
            );
            // The fixed arm's joint2 step tips the upright arm past what its 136 N m servo holds:
            // it falls, saturated, until the slewed set-point catches it, and the engines'
            // clamped motors part there: rapier's gives exactly the limit, MuJoCo's scaled servo
            // the limit plus a little damping against the fall (measured 65.4 mm at the worst
            // step, 2.8 mm settled; 49 mm under a law that switched the damping off at the limit,
            // which chattered on legs: sim_bridge/mujoco/src/servo.rs). On the mobile robots the
            // base rocks on its contacts during the transient too (measured worst 14.0 mm,
            // Dragon's joint2; 25.8 mm under the switching law): 3 cm there.
            let bound = match (name, joint) {
                ("arm", 1) => 0.07,
                ("arm", _) => 0.02,
                _ => 0.03,
            };
            assert!(
                worst < bound,
                "{name} joint{}: tools {worst} m apart",
                joint + 1
            );
            assert!(
                last < 0.01,
                "{name} joint{}: settled {last} m apart",
                joint + 1
            );
        }
    }
}

/// Driving straight for 3 s moves the base the same distance in both engines (within 5 %).
#[test]
fn driving_agrees_between_engines() {
    for name in ["minimal", "dragon", "tricycle"] {
        let travel = |engine| {
            let mut w = world(engine, name);
            let model = w.model().clone();
            let start = w.base_pose();
            for m in model.modules_with_role(kumi_model::Role::Wheel) {
                let forward = (start.inverse() * w.link_pose(&m.root_link).unwrap()).rotation
                    * nalgebra::Vector3::x();
                w.set_wheel_velocity(&m.name, 2.0 * forward.x.signum())
                    .unwrap();
            }
            for _ in 0..90 {
                w.step();
            }
            (start.inverse() * w.base_pose()).translation.vector
        };
        let (a, b) = (travel(Engine::Rapier), travel(Engine::Mujoco));
        println!("{name}: rapier {a:?}, mujoco {b:?}");
        assert!((a.x - b.x).abs() < 0.05 * a.x.abs(), "{name}: {a} vs {b}");
    }
}
