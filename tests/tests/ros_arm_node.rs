//! The arm-module node over real ROS 2 with a real rclpy peer: it reaches a goal through the
//! sim bridge in lockstep, and it rejects bad input without losing its state.

use std::time::Duration;

use kumi_arm_node::Output;
use kumi_sim_bridge::Mode;
use kumi_tests::{fresh_domain, peer, reach_arm_goal, ArmNode, Bridge, REACH_BOUND_M};
use serde_json::Value;

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
