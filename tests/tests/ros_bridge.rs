//! The sim bridge against real rclpy (ROS 2 Kilted from PyPI) as an independent peer.

use std::time::{Duration, Instant};

use kumi_msgs::tf2_msgs::TFMessage;
use kumi_ros::{qos, RosNode};
use kumi_sim_bridge::Mode;
use kumi_tests::{fresh_domain, peer, Bridge};
use serde_json::Value;

const REALTIME: Mode = Mode::RealTime { factor: 1.0 };
const DEADLINE: Duration = Duration::from_secs(60);

fn f(v: &Value) -> f64 {
    v.as_f64().unwrap_or_else(|| panic!("not a number: {v}"))
}

/// rclpy receives every topic with the right type, names, sizes, frames and plausible values,
/// and sees the bridge in its node list.
#[test]
fn rclpy_receives_every_topic() {
    let domain = fresh_domain();
    let bridge = Bridge::start("dragon", domain, REALTIME);
    let out = peer(
        domain,
        &[
            "observe",
            "--robot",
            "dragon",
            "--arms",
            "arm0,leg0",
            "--wheels",
            "front_wheel,rear_wheel",
            "--timeout",
            "20",
        ],
        DEADLINE,
    );
    for (topic, got) in out["received"].as_object().unwrap() {
        assert_eq!(got, true, "rclpy received nothing on {topic}");
    }
    let nodes: Vec<&str> = out["nodes"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap())
        .collect();
    assert!(
        nodes.contains(&"/dragon/sim_bridge"),
        "node list: {nodes:?}"
    );

    let types = &out["topic_types"];
    for (topic, ty) in [
        ("/dragon/arm0/joint_states", "sensor_msgs/msg/JointState"),
        (
            "/dragon/arm0/joint_increments",
            "std_msgs/msg/Float64MultiArray",
        ),
        ("/dragon/arm0/joint_set", "sensor_msgs/msg/JointState"),
        ("/dragon/rear_wheel/wheel_velocity", "std_msgs/msg/Float64"),
        ("/dragon/odom", "nav_msgs/msg/Odometry"),
        ("/dragon/imu", "sensor_msgs/msg/Imu"),
        ("/dragon/robot_description", "std_msgs/msg/String"),
        ("/tf", "tf2_msgs/msg/TFMessage"),
        ("/clock", "rosgraph_msgs/msg/Clock"),
        ("/dragon/clock", "rosgraph_msgs/msg/Clock"),
        ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
    ] {
        assert_eq!(types[topic], serde_json::json!([ty]), "{topic}");
    }

    let arm = &out["joint_states"]["arm0"];
    let names: Vec<String> = (1..=7).map(|i| format!("arm0/joint{i}")).collect();
    assert_eq!(arm["name"], serde_json::json!(names));
    assert_eq!(arm["position"].as_array().unwrap().len(), 7);
    assert_eq!(arm["velocity"].as_array().unwrap().len(), 7);
    // At home: joint4 is bent 1.5 rad.
    assert!((f(&arm["position"][3]) - 1.5).abs() < 0.05, "{arm}");
    let wheel = &out["joint_states"]["rear_wheel"];
    assert_eq!(
        wheel["name"],
        serde_json::json!(["rear_wheel/wheel_left", "rear_wheel/wheel_right"])
    );

    let odom = &out["odom"];
    assert_eq!(odom["frame"], "dragon/odom");
    assert_eq!(odom["child"], "dragon/front_wheel/body");
    assert_eq!(odom["covariance_len"], 36);
    assert!(
        (f(&odom["position"][2]) - 0.27).abs() < 0.02,
        "base at axle height: {odom}"
    );
    assert!((f(&odom["quat_norm"]) - 1.0).abs() < 1e-6);
    // A standing IMU feels +9.81 m/s^2 along its z axis.
    assert_eq!(out["imu"]["frame"], "dragon/front_wheel/body");
    assert!(
        (f(&out["imu"]["accel"][2]) - 9.81).abs() < 0.5,
        "{}",
        out["imu"]
    );
    assert!(f(&out["clock_s"]) > 0.0);
    assert!(out["description_chars"].as_u64().unwrap() > 10_000);
    assert!(out["description_head"]
        .as_str()
        .unwrap()
        .contains("<robot name=\"dragon\">"));
    assert_eq!(out["diagnostics_name"], "kumi sim bridge: dragon");

    // /tf's content, read by a Rust peer (tf2_msgs has no PyPI package for rclpy).
    let mut node = RosNode::new("/", "tf_reader", domain).unwrap();
    let sub = node
        .subscription::<TFMessage>("/tf", qos::default())
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    let tf = loop {
        if let Ok(Some((msg, _))) = sub.take() {
            break msg;
        }
        assert!(Instant::now() < deadline, "no /tf received");
        std::thread::sleep(Duration::from_millis(20));
    };
    // Base in odom, then one transform per moving joint (2 arms x 7 + 2 wheel modules x 2);
    // the fixed ones (2 tool frames, 3 mounts) once on /tf_static (issue 10, finding 10).
    assert_eq!(tf.transforms.len(), 1 + 2 * 7 + 2 * 2);
    assert_eq!(tf.transforms[0].header.frame_id, "dragon/odom");
    assert!(tf
        .transforms
        .iter()
        .all(|t| t.child_frame_id.starts_with("dragon/")));
    assert!(tf
        .transforms
        .iter()
        .any(|t| t.child_frame_id == "dragon/arm0/link7"));
    // A late subscriber still gets the fixed transforms (latched).
    let tf_static = node
        .subscription::<TFMessage>("/tf_static", qos::latched())
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    let fixed = loop {
        if let Ok(Some((msg, _))) = tf_static.take() {
            break msg;
        }
        assert!(Instant::now() < deadline, "no /tf_static received");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert_eq!(fixed.transforms.len(), 2 + 3);
    assert!(fixed
        .transforms
        .iter()
        .any(|t| t.child_frame_id == "dragon/arm0/ee" && t.header.frame_id == "dragon/arm0/link7"));
    assert!(bridge.alive());
}

/// rclpy publishers with default QoS drive the robot: increments move the joints by the
/// commanded amounts, wheel velocities move the base.
#[test]
fn rclpy_publishers_drive_the_robot() {
    let domain = fresh_domain();
    let _bridge = Bridge::start("dragon", domain, REALTIME);
    let out = peer(
        domain,
        &[
            "drive",
            "--robot",
            "dragon",
            "--arm",
            "arm0",
            "--wheel",
            "front_wheel",
            "--joint",
            "0",
            "--increment",
            "0.05",
            "--count",
            "4",
            "--wheel-velocity",
            "2.0",
            "--drive-seconds",
            "3",
        ],
        DEADLINE,
    );
    assert!(out.get("error").is_none(), "{out}");
    let moved = f(&out["q1"][0]) - f(&out["q0"][0]);
    assert!(
        (moved - 0.2).abs() < 0.01,
        "joint1 moved {moved} rad for four 0.05 rad increments"
    );
    for j in 1..7 {
        let d = f(&out["q1"][j]) - f(&out["q0"][j]);
        assert!(
            d.abs() < 0.01,
            "joint{} moved {d} rad without being commanded",
            j + 1
        );
    }
    // Both wheel modules are driven by the front one only here: 2 rad/s x 0.27 m for ~3 s
    // pushes the base well over half a metre.
    let base = f(&out["base_moved_m"]);
    assert!(base > 0.5, "base moved only {base} m");
}

/// A subscriber that starts late still receives the robot description (transient local).
#[test]
fn a_late_subscriber_receives_the_robot_description() {
    let domain = fresh_domain();
    let _bridge = Bridge::start("arm", domain, REALTIME);
    std::thread::sleep(Duration::from_secs(3));
    let out = peer(
        domain,
        &["late", "--robot", "arm", "--timeout", "15"],
        DEADLINE,
    );
    assert!(out["description_chars"].as_u64().unwrap() > 3000, "{out}");
    assert!(out["starts_with"].as_str().unwrap().starts_with("<?xml"));
}

/// Issue 10, finding 9: +2 rad/s on all three of Tricycle's wheel modules drove the base
/// backwards (-0.53 m/s along its x axis). Positive drives along +x on every robot.
#[test]
fn a_positive_wheel_velocity_drives_every_robot_forward() {
    for (robot, arm, wheels) in [
        ("tricycle", "arm0", "wheel0,wheel1,wheel2"),
        ("dragon", "arm0", "front_wheel,rear_wheel"),
    ] {
        let domain = fresh_domain();
        let _bridge = Bridge::start(robot, domain, REALTIME);
        let out = peer(
            domain,
            &[
                "drive",
                "--robot",
                robot,
                "--arm",
                arm,
                "--wheels",
                wheels,
                "--increment",
                "0",
                "--wheel-velocity",
                "2.0",
                "--drive-seconds",
                "2",
            ],
            DEADLINE,
        );
        assert!(out.get("error").is_none(), "{robot}: {out}");
        let forward = f(&out["base_forward_m"]);
        eprintln!("{robot}: {forward:.3} m along the base x axis in 2 s at +2 rad/s");
        assert!(
            forward > 0.3,
            "{robot} drove {forward:.3} m along +x: {out}"
        );
    }
}
