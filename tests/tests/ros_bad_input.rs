//! Bad input never crashes the bridge: each kind is sent by a real rclpy peer, and the test
//! checks that the node is alive, the robot holds a safe state, and `/diagnostics` reports it.

use std::time::Duration;

use kumi_sim_bridge::{BridgeError, Mode};
use kumi_tests::{fresh_domain, peer, Bridge};
use serde_json::Value;

const REALTIME: Mode = Mode::RealTime { factor: 1.0 };

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

fn counter(out: &Value, key: &str) -> u64 {
    out["diagnostics"][key]
        .as_str()
        .unwrap_or_else(|| panic!("no {key} in {}", out["diagnostics"]))
        .parse()
        .unwrap()
}

/// Runs one bad-input scenario on Dragon and returns the peer's report.
fn scenario(kind: &str) -> (Value, Bridge) {
    let domain = fresh_domain();
    let bridge = Bridge::start("dragon", domain, REALTIME);
    let out = peer(
        domain,
        &[
            "badinput",
            "--robot",
            "dragon",
            "--arm",
            "arm0",
            "--wheel",
            "front_wheel",
            "--kind",
            kind,
        ],
        Duration::from_secs(60),
    );
    assert!(out.get("error").is_none(), "{out}");
    assert!(bridge.alive(), "the bridge died on {kind}");
    assert!(
        out["alive_after"][kind].is_array(),
        "no joint states after {kind}: {out}"
    );
    (out, bridge)
}

/// The arm did not move from where it was before the bad command.
fn held(out: &Value, kind: &str) {
    for (before, after) in out["home"]
        .as_array()
        .unwrap()
        .iter()
        .zip(out["alive_after"][kind].as_array().unwrap())
    {
        assert!(
            (f(before) - f(after)).abs() < 0.01,
            "{kind}: arm moved from {} to {}",
            out["home"],
            out["alive_after"][kind]
        );
    }
}

#[test]
fn nan_and_infinite_values_are_rejected() {
    let (out, _bridge) = scenario("nan");
    held(&out, "nan");
    assert_eq!(
        counter(&out, "rejected_non_finite"),
        3,
        "2 increments + 1 wheel velocity"
    );
    assert_eq!(out["diagnostics"]["_level"], 1, "WARN while rejecting");
}

#[test]
fn wrong_array_lengths_are_rejected() {
    let (out, _bridge) = scenario("wrong_length");
    held(&out, "wrong_length");
    assert_eq!(
        counter(&out, "rejected_wrong_length"),
        3,
        "6 and 9 increments, 2 names for 1 position"
    );
}

#[test]
fn increments_beyond_one_control_step_are_rejected() {
    // Issue 10, finding 1: `[1e308] * 7` used to be applied (clamped silently to the limits).
    let (out, _bridge) = scenario("too_large");
    held(&out, "too_large");
    assert_eq!(counter(&out, "rejected_too_large"), 2, "1e308 and 0.3 rad");
}

#[test]
fn unknown_joint_names_are_rejected() {
    let (out, _bridge) = scenario("unknown_joint");
    held(&out, "unknown_joint");
    assert_eq!(counter(&out, "rejected_unknown_joint"), 1);
}

#[test]
fn targets_beyond_limits_are_clamped() {
    let (out, _bridge) = scenario("beyond_limits");
    let q1 = f(&out["alive_after"]["beyond_limits"][0]);
    assert!(
        (q1 - 2.8).abs() < 0.02,
        "joint1 should stop at its 2.8 rad limit, is at {q1}"
    );
    assert!(counter(&out, "clamped") >= 1);
    assert_eq!(
        counter(&out, "rejected_total"),
        0,
        "clamping is not a rejection"
    );
}

#[test]
fn commands_that_stop_arriving_make_the_module_hold() {
    let (out, _bridge) = scenario("stale");
    assert!(f(&out["speed_while_commanded"]) > 0.3, "{out}");
    assert!(
        f(&out["speed_after_silence"]) < 0.05,
        "still moving after commands stopped: {out}"
    );
    assert!(counter(&out, "stale_holds") >= 1);
}

#[test]
fn a_second_bridge_with_the_same_robot_name_is_refused() {
    let domain = fresh_domain();
    let first = Bridge::start("arm", domain, REALTIME);
    std::thread::sleep(Duration::from_secs(1));
    let second = Bridge::start("arm", domain, REALTIME);
    match second.stop() {
        Err(BridgeError::Duplicate {
            robot, domain: d, ..
        }) => assert_eq!((robot.as_str(), d), ("arm", domain)),
        other => panic!("the second bridge was not refused: {other:?}"),
    }
    assert!(
        first.alive(),
        "refusing the second must not disturb the first"
    );
    // Another name on the same domain is fine.
    let third = Bridge::start_named("arm", "arm_b", domain, REALTIME);
    std::thread::sleep(Duration::from_secs(1));
    assert!(third.alive());
    third.stop().unwrap();
    first.stop().unwrap();
}

#[test]
fn a_bad_robot_name_or_rate_is_a_clear_error() {
    let bad = Bridge::start_named("arm", "no spaces", fresh_domain(), REALTIME);
    assert!(
        matches!(bad.stop(), Err(BridgeError::BadConfig(msg)) if msg.contains("valid ROS name"))
    );
    let bad = Bridge::start("arm", fresh_domain(), Mode::RealTime { factor: f64::NAN });
    assert!(
        matches!(bad.stop(), Err(BridgeError::BadConfig(msg)) if msg.contains("realtime-factor"))
    );
}

#[test]
fn malformed_wire_data_is_refused_whole_and_counted() {
    // Issue 10, finding 3: a goal whose frame_id length was 0 was accepted with every later
    // field shifted (the arm drove to a goal nobody sent); a string without its NUL, a
    // JointState missing its last byte and a zero-length label were accepted too.
    let domain = fresh_domain();
    let bridge = Bridge::start("arm", domain, REALTIME);
    let node = kumi_tests::ArmNode::start(
        "arm",
        "arm",
        "arm",
        domain,
        kumi_arm_node::Output::Increments,
    );
    let out = peer(
        domain,
        &[
            "malformed",
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
    assert!(bridge.alive() && node.alive());
    let arm = &out["diagnostics"]["kumi arm node: arm/arm"];
    let sim = &out["diagnostics"]["kumi sim bridge: arm"];
    let n = |v: &Value, key: &str| -> u64 {
        v[key]
            .as_str()
            .unwrap_or_else(|| panic!("no {key}: {out}"))
            .parse()
            .unwrap()
    };
    assert_eq!(
        n(arm, "goals_accepted"),
        0,
        "a broken goal was acted on: {out}"
    );
    assert_eq!(n(arm, "rejected_malformed"), 6, "{out}");
    assert_eq!(n(sim, "rejected_malformed"), 6, "{out}");
    for (b, a) in out["before"]
        .as_array()
        .unwrap()
        .iter()
        .zip(out["after"].as_array().unwrap())
    {
        assert!((f(b) - f(a)).abs() < 0.01, "the arm moved: {out}");
    }
}

/// Issue 10, finding 4: a 0-byte sample is never acknowledged by RustDDS 0.15.1's reliable
/// reader, so later samples of the same writer wait until it has sent 10 more (its keep-last
/// history). The cause is upstream (`rtps/reader.rs`, `Reader::handle_data_msg`: a payload
/// shorter than its 4-byte encapsulation header fails `SerializedPayload::from_bytes`, the
/// failure is logged at debug level and the sequence number is never marked received, so the
/// reader NACKs it until the writer's heartbeat moves past it). kumi cannot work around it
/// without patching RustDDS; this test is the reproduction, and passes once it is fixed.
#[test]
#[ignore = "RustDDS 0.15.1 does not acknowledge a 0-byte sample (issue 10, finding 4): run with --ignored to check an upgrade"]
fn a_zero_byte_sample_does_not_stall_the_topic() {
    let domain = fresh_domain();
    let _node = kumi_tests::ArmNode::start(
        "arm",
        "arm",
        "arm",
        domain,
        kumi_arm_node::Output::Increments,
    );
    let out = peer(
        domain,
        &[
            "zerobyte",
            "--robot",
            "arm",
            "--arm",
            "arm",
            "--drive-seconds",
            "10",
            "--timeout",
            "20",
        ],
        Duration::from_secs(40),
    );
    assert!(
        out["accepted_after_s"].as_f64().is_some_and(|s| s < 2.0),
        "the goal after a 0-byte sample was held back: {out}"
    );
}
