//! The arm-module node over real ROS 2 with a real rclpy peer: it reaches a goal through the
//! sim bridge in lockstep, holds it as calmly as the skill does in process, and it rejects bad
//! input without losing its state.

use std::time::Duration;

use kumi_arm_node::Output;
use kumi_policies::kinematics::ToolKinematics;
use kumi_policies::observation::{self, Goal, JOINTS};
use kumi_policies::settle::{HoldCounts, HOLD_WINDOW_S};
use kumi_policies::skill::ArmSkill;
use kumi_runtime::{BackendChoice, SkillPolicy};
use kumi_sim_bridge::Mode;
use kumi_tests::{fresh_domain, peer, reach_arm_goal, ArmNode, Bridge, REACH_BOUND_M};
use kumi_worlds::{Engine, SimConfig};
use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde_json::Value;

/// How far the hold measures over ROS may lie from those in process (shares of the largest
/// increment, and of the steps).
const HOLD_SHARE_TOLERANCE: f64 = 0.05;

#[test]
fn an_rclpy_goal_is_reached_within_the_skills_accuracy_in_4_s_of_sim_time() {
    reach(Output::Increments);
}

#[test]
fn with_motion_stack_output_the_goal_is_reached_too() {
    reach(Output::JointSet);
}

fn reach(output: Output) {
    let domain = fresh_domain();
    let bridge = Bridge::start(
        "arm",
        domain,
        Mode::Lockstep {
            timeout: Duration::from_secs(2),
        },
    );
    let node = ArmNode::start("arm", "arm", "arm", domain, output);
    let (error, out) = reach_arm_goal(domain, 4.0, &[]);
    assert!(node.alive() && bridge.alive(), "a node stopped: {out}");
    drop(node);
    bridge.stop().unwrap();
    let sim_s = out["end"].as_f64().unwrap() - out["start"].as_f64().unwrap();
    // 120 steps of 1/30 s sum to 3.9999999999999996 in floating point.
    assert!((3.999..4.5).contains(&sim_s), "ran {sim_s} s of sim time");
    eprintln!("{output:?}: tool ended {error:.4} m from the goal after {sim_s:.2} s of sim time");
    assert!(
        error < REACH_BOUND_M,
        "tool ended {error:.3} m from the goal: {out}"
    );
    // The frame as `/tf` names it: robot `arm`, module `arm`, link `base`.
    assert_eq!(out["frame"], "arm/arm/base", "{out}");
}

fn max_abs(out: &Value, phase: &str) -> f64 {
    out[phase]["max_abs"]
        .as_f64()
        .unwrap_or_else(|| panic!("phase {phase} saw no increments: {out}"))
}

#[test]
fn bad_input_is_rejected_and_the_node_holds_without_losing_its_goal() {
    let domain = fresh_domain();
    let node = ArmNode::start("arm", "arm", "arm", domain, Output::Increments);
    let out = peer(
        domain,
        &[
            "armnode",
            "--robot",
            "arm",
            "--arm",
            "arm",
            "--timeout",
            "30",
        ],
        Duration::from_secs(60),
    );
    assert!(out.get("error").is_none(), "{out}");
    assert!(node.alive(), "the node stopped: {out}");
    // Holding is exact: zero increments, still published at the control rate.
    assert_eq!(max_abs(&out, "no_goal"), 0.0, "{out}");
    assert!(out["no_goal"]["messages"].as_u64().unwrap() >= 15, "{out}");
    for bad in ["nan", "zero_quaternion", "unknown_frame", "out_of_reach"] {
        assert_eq!(
            max_abs(&out, &format!("bad_{bad}")),
            0.0,
            "{bad} goal was acted on: {out}"
        );
    }
    // A near-unit quaternion is normalised and the goal pursued; a NaN goal after it is
    // rejected and the good goal kept.
    assert!(max_abs(&out, "good_goal") > 0.0, "{out}");
    assert!(max_abs(&out, "nan_after_good") > 0.0, "{out}");
    // Joint states without joint7 are refused, so the last good one goes stale: hold.
    assert_eq!(max_abs(&out, "missing_joint"), 0.0, "{out}");
    assert!(max_abs(&out, "recovered") > 0.0, "{out}");
    // No joint states at all: stale after 0.2 s, hold.
    assert_eq!(max_abs(&out, "stale"), 0.0, "{out}");
}

/// The shipped skill driving robot `arm` (module `arm`) to [`kumi_tests::ARM_GOAL`] in process
/// for `steps` control steps from its home pose, in rapier (the bridge's engine): its actions.
fn in_process_actions(steps: usize) -> Vec<[f32; JOINTS]> {
    let model = kumi_tests::shipped_model("arm");
    let config = SimConfig::for_model(&model);
    let module = &model.modules[0];
    let skill = ArmSkill::new(module, config.control_hz).unwrap();
    let path = kumi_runtime::shipped_arm_policy();
    let mut policy = SkillPolicy::load(&path, &skill, BackendChoice::Tract).unwrap();
    let fk = ToolKinematics::new(&model, module).unwrap();
    let mut world = kumi_worlds::build(Engine::Rapier, model.clone(), config).unwrap();
    let [x, y, z, qw, qx, qy, qz] = kumi_tests::ARM_GOAL;
    let goal = Goal {
        position_b: Vector3::new(x, y, z),
        orientation_b: UnitQuaternion::from_quaternion(Quaternion::new(qw, qx, qy, qz)),
    };
    let mut actions = Vec::with_capacity(steps);
    for _ in 0..steps {
        let at = |v: Vec<f64>| -> [f64; JOINTS] { std::array::from_fn(|j| v[j]) };
        let obs = observation::build(
            &at(world.joint_positions()),
            &at(world.joint_velocities()),
            &at(world.commands()),
            &goal,
            &|q| fk.tool_pose_b(q),
            fk.limits_rad(),
        );
        let action = policy.act(&obs).unwrap();
        world
            .apply_increments(&module.name, &skill.increments(&action))
            .unwrap();
        world.step();
        actions.push(action);
    }
    actions
}

#[test]
fn the_arm_node_holds_over_ros_as_calmly_as_the_skill_in_process() {
    // Hold smoothness (kumi_policies::settle) of the increments the arm node sends through the
    // lockstep bridge over the last second of a 4 s goal, against the same skill's on the same
    // arm, goal and engine in process: the node adds nothing of its own to the hold.
    let domain = fresh_domain();
    let bridge = Bridge::start(
        "arm",
        domain,
        Mode::Lockstep {
            timeout: Duration::from_secs(2),
        },
    );
    let node = ArmNode::start("arm", "arm", "arm", domain, Output::Increments);
    let (_, out) = reach_arm_goal(domain, 4.0, &["--record"]);
    assert!(node.alive() && bridge.alive(), "a node stopped: {out}");
    drop(node);
    bridge.stop().unwrap();
    let model = kumi_tests::shipped_model("arm");
    let control_hz = SimConfig::for_model(&model).control_hz;
    let skill = ArmSkill::new(&model.modules[0], control_hz).unwrap();
    // Increments back to the clipped actions they came from.
    let sent: Vec<[f32; JOINTS]> = out["increments"]
        .as_array()
        .unwrap_or_else(|| panic!("no increments reported: {out}"))
        .iter()
        .map(|row| {
            let row = kumi_tests::numbers(row);
            std::array::from_fn(|j| (row[j] / skill.increment_scale[j]) as f32)
        })
        .collect();
    let steps = (4.0 * control_hz).round() as usize;
    let window = (HOLD_WINDOW_S * control_hz).round() as usize;
    assert!(
        sent.len() + 5 >= steps,
        "{} increments in 4 s of sim time",
        sent.len()
    );
    let over_ros = HoldCounts::of(&sent[sent.len() - window..]);
    let in_process = HoldCounts::of(&in_process_actions(steps)[steps - window..]);
    let (ros_share, own_share) = (
        over_ros.mean_increment_share(),
        in_process.mean_increment_share(),
    );
    let (ros_reversals, own_reversals) = (over_ros.reversal_share(), in_process.reversal_share());
    eprintln!(
        "hold over the last {HOLD_WINDOW_S} s: mean increment {ros_share:.3} of the largest over ROS, \
         {own_share:.3} in process; reversals {ros_reversals:.3} and {own_reversals:.3}"
    );
    assert!(
        (ros_share - own_share).abs() <= HOLD_SHARE_TOLERANCE,
        "mean increment share {ros_share:.3} over ROS against {own_share:.3} in process"
    );
    assert!(
        (ros_reversals - own_reversals).abs() <= HOLD_SHARE_TOLERANCE,
        "reversal share {ros_reversals:.3} over ROS against {own_reversals:.3} in process"
    );
}
