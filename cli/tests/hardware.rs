//! Issue 12's MoonBot hardware profile against a fake Motion Stack limb written in rclpy
//! (`tests/ros/peer.py fakelimb`): `joint_set` in, `joint_read` out only when a joint moves
//! by its encoder's resolution. The arm node, given the profile, drives the limb to a goal on
//! wall time (no simulator, no `/clock`); a limb that is silent because its joints are still
//! does not make the node hold; a limb that is gone does.

use std::time::Duration;

use kumi_tests::{distance, fresh_domain, numbers, peer, KumiProcess, ARM_GOAL};

const KUMI: &str = env!("CARGO_BIN_EXE_kumi");

fn number(v: &serde_json::Value) -> f64 {
    v.as_f64()
        .or_else(|| v.as_str().and_then(|s| s.parse().ok()))
        .unwrap_or_else(|| panic!("not a number: {v}"))
}

/// The arm node's latest diagnostics after listening `seconds`.
fn arm_diagnostics(domain: u16, seconds: f64) -> serde_json::Value {
    let s = seconds.to_string();
    let all = peer(
        domain,
        &["diagnostics", "--drive-seconds", &s],
        Duration::from_secs(60),
    );
    all["kumi arm node: arm/arm"].clone()
}

#[test]
fn an_arm_node_drives_a_fake_motion_stack_limb_and_tells_a_quiet_limb_from_a_dead_one() {
    let domain = fresh_domain();
    let profile = std::env::temp_dir().join(format!("kumi-ms-{}.toml", std::process::id()));
    // Motion Stack calls the first joint otherwise: the profile maps it.
    std::fs::write(
        &profile,
        "[limbs.arm]\nnamespace = \"/leg7\"\n[limbs.arm.joints]\njoint1 = \"leg7_joint1\"\n",
    )
    .unwrap();
    let limb = std::thread::spawn(move || {
        peer(
            domain,
            &[
                "fakelimb",
                "--frame",
                "/leg7",
                "--arms",
                "leg7_joint1,joint2,joint3,joint4,joint5,joint6,joint7",
                "--drive-seconds",
                "22",
            ],
            Duration::from_secs(60),
        )
    });
    let path = profile.display().to_string();
    let node = KumiProcess::spawn(KUMI, &[], &["arm", "arm", "--hardware", &path], domain);
    assert!(
        node.wait_for_log("arm node up", Duration::from_secs(60)),
        "{}",
        node.log()
    );
    assert!(node.log().contains("/leg7/joint_read") && node.log().contains("/leg7/joint_set"));

    // Still and silent: the limb published once at its start; no hold for staleness.
    let quiet = arm_diagnostics(domain, 3.0);
    println!("quiet limb: {quiet}");
    assert_eq!(number(&quiet["stale_holds"]), 0.0, "{quiet}");
    assert_eq!(quiet["message"], "holding: no goal yet", "{quiet}");

    // A goal: reached on wall time.
    let goal = ARM_GOAL.map(|v| v.to_string()).join(",");
    let out = peer(
        domain,
        &[
            "reach",
            "--wall",
            "--robot",
            "arm",
            "--arm",
            "arm",
            "--goal",
            &goal,
            "--drive-seconds",
            "8",
            "--within",
            "0.1",
            "--timeout",
            "30",
        ],
        Duration::from_secs(60),
    );
    let error = distance(&numbers(&out["position"]), &ARM_GOAL);
    println!(
        "reached on the fake limb: {error:.3} m in {:.1} s",
        number(&out["wall_s"])
    );
    assert!(error < 0.1, "{out}");

    // The limb leaves: the node holds.
    let limb = limb.join().unwrap();
    println!("fake limb: {limb}");
    assert!(number(&limb["counts"]["joint_set"]) > 30.0, "{limb}");
    assert!(number(&limb["longest_quiet_s"]) > 2.5, "{limb}");
    let gone = arm_diagnostics(domain, 3.0);
    println!("limb gone: {gone}");
    assert!(number(&gone["stale_holds"]) >= 1.0, "{gone}");
    assert!(
        gone["message"]
            .as_str()
            .is_some_and(|m| m.contains("joint states are")),
        "{gone}"
    );
    let _ = std::fs::remove_file(profile);
    drop(node);
}
