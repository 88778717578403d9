//! Issue 10's findings on command state and restarts, over real DDS with a real rclpy peer:
//! the servo targets belong to the bridge alone (finding 1), a restarted bridge is followed
//! (finding 2), a dead arm node in lockstep is noticed and the robot holds (finding 6).
//!
//! The nodes run in threads of this process and stop cleanly; `cli/tests/ros_processes.rs`
//! kills them with SIGKILL (no DDS goodbye).

use std::time::{Duration, Instant};

use kumi_arm_node::Output;
use kumi_sim_bridge::Mode;
use kumi_tests::{
    fresh_domain, reach_arm_goal, watch_arm as watch, ArmNode, Bridge, REACH_BOUND_M,
};

const LOCKSTEP: Mode = Mode::Lockstep {
    timeout: Duration::from_millis(100),
};

fn f(v: &serde_json::Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

#[test]
fn a_joint_set_from_another_publisher_does_not_throw_the_arm_off_its_goals() {
    // Finding 1: one `joint_set` of joint2 from another publisher, and one increment of
    // 1e308 rad, used to leave the node's private copy of the targets wrong for good (misses
    // of 0.43-1.3 m). The bridge owns the targets now; the node sends the skill's increments.
    let domain = fresh_domain();
    let bridge = Bridge::start("arm", domain, LOCKSTEP);
    let node = ArmNode::start("arm", "arm", "arm", domain, Output::Increments);
    let (error, out) = reach_arm_goal(domain, 6.0, &["--disturb"]);
    assert!(node.alive() && bridge.alive(), "a node stopped: {out}");
    eprintln!("after the disturbance the tool ended {error:.3} m from the goal");
    assert!(error < REACH_BOUND_M, "tool ended {error:.3} m away: {out}");
}

#[test]
fn the_arm_node_follows_a_restarted_bridge() {
    // Finding 2: after the bridge restarts, sim time goes back to 0. The node used to wait for
    // the new time to pass the old one (forever in lockstep, where it is the node's commands
    // that make time pass).
    for mode in [LOCKSTEP, Mode::RealTime { factor: 1.0 }] {
        let domain = fresh_domain();
        let first = Bridge::start("arm", domain, mode);
        let node = ArmNode::start("arm", "arm", "arm", domain, Output::Increments);
        let (error, out) = reach_arm_goal(domain, 2.0, &[]);
        assert!(
            error < 0.5,
            "{mode:?}: the first bridge was not driven: {out}"
        );
        first.stop().unwrap();
        let restarted = Instant::now();
        let second = Bridge::start("arm", domain, mode);
        let (error, out) = reach_arm_goal(domain, 4.0, &[]);
        eprintln!(
            "{mode:?}: after the bridge restarted the tool ended {error:.3} m from the goal ({:.1} s of wall time)",
            restarted.elapsed().as_secs_f64()
        );
        assert!(node.alive() && second.alive(), "{mode:?}: a node stopped");
        assert!(
            error < REACH_BOUND_M,
            "{mode:?}: tool ended {error:.3} m away after the restart: {out}"
        );
        assert!(
            f(&out["start"]) < 30.0,
            "{mode:?}: the second bridge's time: {out}"
        );
    }
}

#[test]
fn a_dead_arm_node_in_lockstep_is_reported_and_the_robot_holds() {
    // Finding 6: the simulation froze (no /clock, a frozen non-zero velocity, no stale hold).
    let domain = fresh_domain();
    let bridge = Bridge::start("arm", domain, LOCKSTEP);
    let node = ArmNode::start("arm", "arm", "arm", domain, Output::Increments);
    let (_, out) = reach_arm_goal(domain, 0.5, &[]);
    assert!(out.get("error").is_none(), "{out}");
    drop(node);
    let watched = watch(domain, 6.0);
    assert!(bridge.alive());
    // Sim time goes on at one step per timeout (0.1 s): 6 s of wall time is ~2 s of sim time.
    let advanced = f(&watched["clock_end"]) - f(&watched["clock_start"]);
    assert!(advanced > 1.0, "sim time stood still: {watched}");
    assert_eq!(
        watched["lockstep_silent"],
        serde_json::json!(["arm"]),
        "{watched}"
    );
    assert!(f(&watched["lockstep_timeouts"]) >= 1.0, "{watched}");
    assert!(f(&watched["stale_holds"]) >= 1.0, "{watched}");
    assert!(
        f(&watched["max_speed"]) < 0.05,
        "the arm still moves: {watched}"
    );
    // A new node picks the loop up again.
    let _node = ArmNode::start("arm", "arm", "arm", domain, Output::Increments);
    let (error, out) = reach_arm_goal(domain, 4.0, &[]);
    assert!(error < REACH_BOUND_M, "tool ended {error:.3} m away: {out}");
}

#[test]
fn a_node_joining_a_running_simulation_does_not_take_its_joint_states_for_stale() {
    // Finding 8: a node that joined 3 s into a simulation warned "joint states are 3 s old;
    // holding": it stamped the first joint state in wall time, then compared it with /clock.
    let domain = fresh_domain();
    let _bridge = Bridge::start("arm", domain, Mode::RealTime { factor: 1.0 });
    std::thread::sleep(Duration::from_secs(3));
    let _node = ArmNode::start("arm", "arm", "arm", domain, Output::Increments);
    let watched = watch(domain, 4.0);
    let node = &watched["node"];
    assert!(
        !node["messages"].as_array().unwrap().is_empty(),
        "no diagnostics from the arm node: {watched}"
    );
    assert_eq!(node["stale_holds"], 0, "{watched}");
    assert!(
        node["messages"]
            .as_array()
            .unwrap()
            .iter()
            .all(|m| m == "holding: no goal yet"),
        "{watched}"
    );
}

#[test]
fn a_second_arm_node_for_the_same_module_is_refused() {
    // Finding 7: a second `kumi arm <module>` for the same module was not refused.
    let domain = fresh_domain();
    let _bridge = Bridge::start("arm", domain, Mode::RealTime { factor: 1.0 });
    let first = ArmNode::start("arm", "arm", "arm", domain, Output::Increments);
    std::thread::sleep(Duration::from_secs(2));
    let second = ArmNode::start("arm", "arm", "arm", domain, Output::Increments);
    let deadline = Instant::now() + Duration::from_secs(10);
    while second.alive() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    match second.stop() {
        Err(kumi_arm_node::ArmNodeError::Duplicate {
            robot,
            module,
            topic,
        }) => {
            assert_eq!((robot.as_str(), module.as_str()), ("arm", "arm"));
            assert_eq!(topic, "/arm/arm/joint_increments");
        }
        other => panic!("the second node was not refused: {other:?}"),
    }
    assert!(first.alive(), "refusing the second must not stop the first");
    // The first still drives the arm.
    let (error, out) = reach_arm_goal(domain, 4.0, &[]);
    assert!(error < REACH_BOUND_M, "tool ended {error:.3} m away: {out}");
    // A node for the same module of another robot name is not a duplicate.
    let other = ArmNode::start("arm", "arm_b", "arm", domain, Output::Increments);
    std::thread::sleep(Duration::from_secs(2));
    assert!(other.alive());
}
