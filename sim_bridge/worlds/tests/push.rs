//! A push moves the whole robot at once as one rigid body, alike in every engine; a fixed base
//! does not move.

mod common;

use common::{engines, world};
use kumi_worlds::{Engine, RobotState, SimWorld};
use nalgebra::{Translation3, Vector3};

/// Every link's position [m], in URDF link order.
fn link_positions(w: &dyn SimWorld) -> Vec<Vector3<f64>> {
    w.body_poses()
        .into_iter()
        .map(|(_, pose)| pose.translation.vector)
        .collect()
}

/// Pushes `name`, held 2 m above the ground, by `dv` [m/s] and `dw` [rad/s] (world frame, about
/// its base origin), and checks the base's twist at once and every link's motion over the next
/// control step: in the air nothing but gravity (along z) and the servos holding the joints act
/// on it, so every link moves as one rigid body pushed so.
fn a_push_moves_every_link(engine: Engine, name: &str, dv: Vector3<f64>, dw: Vector3<f64>) {
    let mut w = world(engine, name);
    let home = w.home_state();
    w.reset(&RobotState {
        base_pose_w: Translation3::new(0.0, 0.0, 2.0) * home.base_pose_w,
        ..home
    });
    let origin = w.base_pose().translation.vector;
    let (v_before, w_before) = w.base_twist_w();
    let joints_before = w.joint_velocities();
    w.push(&dv, &dw);

    // The base's twist: its angular velocity by dw; its centre of mass's linear velocity by dv
    // plus dw x r, r the centre of mass from the base origin (within a metre of it): a change
    // square to dw (within rapier's f32).
    let (v_after, w_after) = w.base_twist_w();
    assert!(
        (w_after - w_before - dw).norm() < 1e-5,
        "{engine} {name}: the base's angular velocity changed by {:?}, pushed by {dw:?}",
        w_after - w_before
    );
    let lever = v_after - v_before - dv;
    assert!(
        lever.dot(&dw).abs() < 1e-5 && lever.norm() <= dw.norm() + 1e-5,
        "{engine} {name}: the base's velocity changed by {:?}, pushed by {dv:?} and {dw:?}",
        v_after - v_before
    );
    for (a, b) in joints_before.iter().zip(&w.joint_velocities()) {
        assert!(
            (a - b).abs() < 1e-4,
            "{engine} {name}: a push moved a joint"
        );
    }

    let before = link_positions(w.as_ref());
    w.step();
    let dt = 1.0 / w.config().control_hz;
    for ((link, _), (a, b)) in w
        .body_poses()
        .iter()
        .zip(before.iter().zip(link_positions(w.as_ref())))
    {
        let pushed = (dv + dw.cross(&(a - origin))).xy() * dt;
        let moved = (b - a).xy();
        assert!(
            (moved - pushed).norm() < 0.1 * pushed.norm() + 1e-3,
            "{engine} {name}: link {link} moved {moved:?} m across in one step, pushed {pushed:?} m"
        );
    }
}

#[test]
fn a_push_moves_every_link_of_every_robot() {
    let slide = Vector3::new(0.4, -0.3, 0.0);
    for engine in engines() {
        for name in ["minimal", "dragon", "tricycle"] {
            a_push_moves_every_link(engine, name, slide, Vector3::zeros());
        }
    }
}

#[test]
fn a_tip_turns_every_link_of_every_robot_about_the_base() {
    let tip = Vector3::new(0.8, 0.5, 0.0);
    for engine in engines() {
        for name in ["minimal", "dragon", "tricycle"] {
            a_push_moves_every_link(engine, name, Vector3::new(0.1, 0.0, 0.0), tip);
        }
    }
}

#[test]
fn a_pushed_robot_on_the_ground_slides_alike_in_every_engine() {
    // Tricycle, standing, pushed along x at 0.5 m/s: its base slides on, slowed by its braked
    // wheels, by much the same in every engine.
    let travel: Vec<(Engine, f64)> = engines()
        .into_iter()
        .map(|engine| {
            let mut w = world(engine, "tricycle");
            for _ in 0..15 {
                w.step();
            }
            let start = w.base_pose().translation.vector;
            w.push(&Vector3::new(0.5, 0.0, 0.0), &Vector3::zeros());
            for _ in 0..6 {
                w.step();
            }
            (engine, (w.base_pose().translation.vector - start).x)
        })
        .collect();
    for &(engine, x) in &travel {
        // Free flight for 0.2 s would be 0.1 m; standing still 0.
        assert!(x > 0.01 && x < 0.1, "{engine}: the base slid {x} m");
    }
    if let [(_, a), (_, b)] = travel[..] {
        assert!(
            (a - b).abs() < 0.5 * a.max(b),
            "engines disagree: {travel:?}"
        );
    }
}

#[test]
fn a_push_leaves_a_fixed_base_where_it_is() {
    for engine in engines() {
        let mut w = world(engine, "arm");
        let before = w.base_pose();
        w.push(&Vector3::new(0.4, -0.3, 0.0), &Vector3::new(0.8, 0.5, 0.0));
        for _ in 0..10 {
            w.step();
        }
        let moved = (w.base_pose().translation.vector - before.translation.vector).norm();
        assert!(moved < 1e-9, "{engine}: a fixed base moved {moved} m");
    }
}
