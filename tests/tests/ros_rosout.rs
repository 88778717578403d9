//! Issue 10, finding 10: kumi's nodes published nothing on `/rosout`. A stock rclpy node
//! hears the bridge's and the arm node's records there, each under its ROS logger name.

use std::time::Duration;

use kumi_arm_node::Output;
use kumi_sim_bridge::Mode;
use kumi_tests::{fresh_domain, peer, ArmNode, Bridge};
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;

#[test]
fn rclpy_hears_the_nodes_on_rosout() {
    // What the `kumi` binary installs: records go to /rosout through this layer.
    tracing_subscriber::registry()
        .with(tracing_subscriber::EnvFilter::new("info"))
        .with(kumi_ros::rosout::RosoutLayer)
        .init();
    let domain = fresh_domain();
    let _bridge = Bridge::start("arm", domain, Mode::RealTime { factor: 1.0 });
    let _node = ArmNode::start("arm", "arm", "arm", domain, Output::Increments);
    let out = peer(
        domain,
        &[
            "rosout",
            "--robot",
            "arm",
            "--arm",
            "arm",
            "--drive-seconds",
            "2",
            "--timeout",
            "20",
        ],
        Duration::from_secs(40),
    );
    let records = out["records"].as_array().unwrap();
    let from = |name: &str, level: u64, text: &str| {
        records.iter().any(|r| {
            r["name"] == name && r["level"] == level && r["msg"].as_str().unwrap().contains(text)
        })
    };
    assert!(from("arm.sim_bridge", 20, "sim bridge up"), "{out}");
    assert!(from("arm.arm.arm_node", 20, "arm node up"), "{out}");
    assert!(
        from("arm.arm.arm_node", 30, "goal rejected"),
        "the rejected goal's warning: {out}"
    );
}
