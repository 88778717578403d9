//! Lockstep mode: a closed loop over ROS with a real rclpy controller is reproducible.

use std::time::Duration;

use kumi_sim_bridge::Mode;
use kumi_tests::{fresh_domain, peer, Bridge};
use serde_json::Value;

fn run(seed: &str) -> Value {
    let domain = fresh_domain();
    let bridge = Bridge::start(
        "arm",
        domain,
        Mode::Lockstep {
            timeout: Duration::from_secs(2),
        },
    );
    let out = peer(
        domain,
        &[
            "lockstep",
            "--robot",
            "arm",
            "--arm",
            "arm",
            "--steps",
            "90",
            "--seed",
            seed,
            "--timeout",
            "40",
        ],
        Duration::from_secs(60),
    );
    bridge.stop().unwrap();
    assert!(out.get("error").is_none(), "{out}");
    out
}

#[test]
fn the_same_command_sequence_gives_the_same_trajectory_twice() {
    let a = run("0.5");
    let b = run("0.5");
    let ta = a["trajectory"].as_array().unwrap();
    assert_eq!(ta.len(), 90);
    // Ticks are consecutive control steps: 1/30 s apart, starting at 0.
    for (k, tick) in ta.iter().enumerate() {
        let t = tick["t"].as_f64().unwrap();
        assert!((t - k as f64 / 30.0).abs() < 1e-6, "tick {k} at {t}");
    }
    assert_eq!(
        a["trajectory"], b["trajectory"],
        "two lockstep runs diverged"
    );
    // The controller really moved the arm.
    let q_first = ta[0]["q"][0].as_f64().unwrap();
    let q_last = ta[89]["q"][0].as_f64().unwrap();
    assert!(
        (q_last - q_first).abs() > 0.05,
        "joint1 barely moved: {q_first} -> {q_last}"
    );
    let c = run("1.5");
    assert_ne!(
        a["trajectory"], c["trajectory"],
        "a different command sequence must differ"
    );
}
