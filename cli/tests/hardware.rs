//! Issue 12's MoonBot hardware profile against a fake Motion Stack limb written in rclpy
//! (`tests/ros/peer.py fakelimb`): `joint_set` in, `joint_read` out only when a joint moves
//! by its encoder's resolution. The arm node, given the profile, drives the limb to a goal on
//! wall time (no simulator, no `/clock`); a limb that is silent because its joints are still
//! does not make the node hold; a limb that is gone does.

use std::time::Duration;

use kumi_tests::{
    distance, fresh_domain, number, numbers, peer, KumiProcess, ARM_GOAL, REACH_BOUND_M,
};

const KUMI: &str = env!("CARGO_BIN_EXE_kumi");

/// The tests here run one at a time: each runs several rclpy processes beside kumi's nodes on
/// wall time, and two at once on a 2-core machine starve the fake limbs.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

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
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
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
                "32",
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
    let bound = REACH_BOUND_M.to_string();
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
            "15",
            "--within",
            &bound,
            "--timeout",
            "40",
        ],
        Duration::from_secs(60),
    );
    let error = distance(&numbers(&out["position"]), &ARM_GOAL);
    println!(
        "reached on the fake limb: {error:.3} m in {:.1} s",
        number(&out["wall_s"])
    );
    // The fake limb is an ideal servo, not the simulator's: the skill converges more slowly on
    // it (5-7 s here) than in simulation (1-2 s), to the bound of the simulated arm tests.
    assert!(error < REACH_BOUND_M, "{out}");

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

/// `peer` in a thread of its own (a fake device that runs while the test goes on).
fn device(domain: u16, args: Vec<&'static str>) -> std::thread::JoinHandle<serde_json::Value> {
    std::thread::spawn(move || peer(domain, &args, Duration::from_secs(90)))
}

#[test]
fn a_launch_on_hardware_drives_fake_motion_stack_limbs_from_a_target() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let domain = fresh_domain();
    let profile = std::env::temp_dir().join(format!("kumi-ms-minimal-{}.toml", std::process::id()));
    std::fs::write(
        &profile,
        "odometry = \"/odom\"\n[limbs.arm0]\nnamespace = \"/leg1\"\n[limbs.arm0.joints]\njoint1 = \"leg1_joint1\"\n[limbs.wheel0]\nnamespace = \"/leg10\"\n",
    )
    .unwrap();
    // Minimal's limbs, its arm at home, and a base whose odometry says it does not move.
    let arm = device(
        domain,
        vec![
            "fakelimb",
            "--frame",
            "/leg1",
            "--arms",
            "leg1_joint1,joint2,joint3,joint4,joint5,joint6,joint7",
            "--samples",
            "0,-0.3,0,1.5,0,0.3707963267948966,0",
            "--drive-seconds",
            "30",
        ],
    );
    let wheel = device(
        domain,
        vec![
            "fakelimb",
            "--frame",
            "/leg10",
            "--arms",
            "wheel_left,wheel_right",
            "--drive-seconds",
            "30",
        ],
    );
    let odom = device(
        domain,
        vec!["fakeodom", "--frame", "/odom", "--drive-seconds", "30"],
    );
    let path = profile.display().to_string();
    let launch = KumiProcess::spawn(
        KUMI,
        &[],
        &[
            "launch",
            "minimal",
            "--hardware",
            "motion-stack",
            "--profile",
            &path,
        ],
        domain,
    );
    assert!(
        launch.wait_for_log("whole-body node up", Duration::from_secs(60)),
        "{}",
        launch.log()
    );
    assert!(
        launch.log().contains("2 nodes"),
        "no sim bridge: {}",
        launch.log()
    );
    // The node takes targets in the odometry's frame once it has heard the odometry.
    assert!(
        launch.wait_for_log("odometry in frame `odom`", Duration::from_secs(30)),
        "{}",
        launch.log()
    );
    // A target within the arm's reach of the standing base, in the odometry's frame.
    let out = peer(
        domain,
        &[
            "target",
            "--wall",
            "--robot",
            "minimal",
            "--goal",
            "0.9,0.15,1.2,0.0",
            "--frame",
            "odom",
            "--drive-seconds",
            "6",
            "--timeout",
            "40",
        ],
        Duration::from_secs(60),
    );
    let d = &out["diagnostics"];
    let trajectory = out["trajectory"].as_array().expect("tool poses");
    let error_at = |row: &serde_json::Value| {
        let r: Vec<f64> = row.as_array().unwrap().iter().map(number).collect();
        distance(&r[1..4], &[0.9, 0.15, 1.2])
    };
    let (first, last) = (
        error_at(&trajectory[0]),
        error_at(trajectory.last().unwrap()),
    );
    let at = |row: &serde_json::Value| -> Vec<f64> {
        row.as_array().unwrap()[1..4].iter().map(number).collect()
    };
    let moved = distance(&at(&trajectory[0]), &at(trajectory.last().unwrap()));
    println!(
        "on fake hardware: tool {first:.3} m -> {last:.3} m from the target, moved {moved:.3} m; {d}"
    );
    assert_eq!(number(&d["targets_accepted"]), 1.0, "{d}");
    assert_eq!(
        number(&d["stale_holds"]),
        0.0,
        "lazy joint_read is not stale: {d}"
    );
    assert!(
        number(&d["unsynchronised_ticks"]) > 30.0,
        "hardware stamps: {d}"
    );
    // The fake base cannot move, so the policy cannot bring the tool to the target; the chain
    // target -> whole-body node -> goals -> arm node -> joint_set -> limb -> joint_read ->
    // tool pose must still move the tool.
    assert!(moved > 0.02, "the tool did not move: {out}");
    drop(launch);
    let (arm, wheel, _) = (
        arm.join().unwrap(),
        wheel.join().unwrap(),
        odom.join().unwrap(),
    );
    println!("arm limb {arm}\nwheel limb {wheel}");
    assert!(number(&arm["counts"]["joint_set"]) > 30.0, "{arm}");
    // Both wheels driven by the one rule: the module's velocity, the mount's sign, the limit.
    let v = &wheel["largest_velocity"];
    let (left, right) = (number(&v["wheel_left"]), number(&v["wheel_right"]));
    assert!(left.abs() > 0.01 && left == right, "{wheel}");
    // The launch stopped: the whole-body node stopped the wheels on its way out.
    let last = &wheel["last_velocity"];
    assert_eq!(
        (number(&last["wheel_left"]), number(&last["wheel_right"])),
        (0.0, 0.0),
        "{wheel}"
    );
    let _ = std::fs::remove_file(profile);
}
