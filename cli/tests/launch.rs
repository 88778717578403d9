//! Issue 12: whole robots brought up by `kumi launch`, each node a process of its own, driven
//! by a real rclpy peer that sends the robot a target as a user would (`/<robot>/goal_pose`).
//!
//! - End to end: the launched Minimal reaches a target, refusing a NaN target and one in the
//!   wrong frame first.
//! - Consistency: in lockstep the ROS closed loop reproduces the in-process episode (the
//!   training environment stepped by the same policies from the same start and target) to
//!   the bit.
//! - Reconfiguration: a module left out of the launch joins by hand; a second robot runs
//!   beside the first on the same domain; a second node for a module, or a second whole-body
//!   node for a robot, is refused; a launch whose node dies stops and says which.

use std::time::Duration;

use kumi_runtime::{BackendChoice, WholeBodyPolicy};
use kumi_terms::{ActionTerms, GoalBounds};
use kumi_tests::{fresh_domain, number, peer, shipped_model, KumiProcess};
use kumi_train::whole_body::WholeBody;
use kumi_worlds::Engine;
use nalgebra::Vector3;

const KUMI: &str = env!("CARGO_BIN_EXE_kumi");
/// Whole robots are launched one test at a time: with two or three launches at once on CI's 2
/// cores (each a bridge, arm nodes and a whole-body node), a lockstep robot of the by-hand test
/// stalled after 15 ticks.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner())
}
const START: Duration = Duration::from_secs(60);
/// Minimal's target: 1.4 m from the start, in the trained range (|x|, |y| <= 3 m, z in
/// [0.9, 1.5] m), heading 0.5 rad.
const TARGET: [f64; 4] = [1.0, 0.5, 1.1, 0.5];
/// Tricycle's: the same, at a height in its trained range (z in [2.05, 2.45] m: its tool stands
/// on top of a 1.24 m hub).
const TRICYCLE_TARGET: [f64; 4] = [1.0, 0.5, 2.2, 0.5];
/// Simulated seconds the peer watches (the episodes of training last 12 s).
const DRIVE_S: f64 = 8.0;

fn launch(domain: u16, args: &[&str]) -> KumiProcess {
    let mut all = vec!["launch"];
    all.extend(args);
    let launch = KumiProcess::spawn(KUMI, &[], &all, domain);
    assert!(
        launch.wait_for_log("whole-body node up", START),
        "{}",
        launch.log()
    );
    launch
}

fn send_target(domain: u16, robot: &str, extra: &[&str]) -> serde_json::Value {
    send_target_for(domain, robot, DRIVE_S, extra)
}

/// The `/diagnostics` status name of the arm node of `robot`'s `module`, as it goes on the wire.
fn arm_status(robot: &str, module: &str) -> String {
    format!("kumi arm node: {robot}/{module}")
}

/// The [`arm_status`] names of `robot`'s `modules`, comma-separated (the peer's `--expect`: it
/// waits for a report from each after the drive).
fn arm_statuses(robot: &str, modules: &[&str]) -> String {
    modules
        .iter()
        .map(|m| arm_status(robot, m))
        .collect::<Vec<_>>()
        .join(",")
}

/// [`send_target`], watching `drive_s` simulated seconds.
fn send_target_for(domain: u16, robot: &str, drive_s: f64, extra: &[&str]) -> serde_json::Value {
    let target = if robot == "tricycle" {
        TRICYCLE_TARGET
    } else {
        TARGET
    };
    let goal = target.map(|v| v.to_string()).join(",");
    let drive = drive_s.to_string();
    let mut args = vec![
        "target",
        "--robot",
        robot,
        "--goal",
        &goal,
        "--drive-seconds",
        &drive,
        "--timeout",
        "90",
    ];
    args.extend(extra);
    let out = peer(domain, &args, Duration::from_secs(120));
    assert!(out.get("error").is_none(), "{out}");
    assert_eq!(
        out["missing_diagnostics"],
        serde_json::json!([]),
        "nodes whose /diagnostics report never came after the drive: {out}"
    );
    out
}

/// The in-process episode: the training environment in rapier (the bridge's engine) from the
/// bridge's start (home, at the origin), held still (zero increments, wheels stopped) for
/// `hold_ticks` as the nodes held it before the target, then stepped by the shipped policy
/// (tract, as the launched nodes were told) for `ticks`. The tool position after each step
/// (index `k - 1` after step `k`).
fn in_process_episode(hold_ticks: usize, ticks: usize) -> Vec<Vector3<f64>> {
    let model = shipped_model("minimal");
    let path = kumi_runtime::shipped_whole_body_policy("minimal");
    let file = kumi_runtime::ModelFile::decode(std::fs::read(&path).unwrap()).unwrap();
    let bounds =
        GoalBounds::from_description(&file.metadata[kumi_terms::contract::ACTION]).unwrap();
    // The optional observation slots, as the whole-body node reads them: from the file.
    let options = kumi_terms::ObservationOptions::from_description(
        &file.metadata[kumi_policies::metadata::OBSERVATION],
    );
    let skill = std::fs::read(kumi_runtime::shipped_arm_policy()).unwrap();
    let config = kumi_train::whole_body::WholeBodyConfig {
        observation: options,
        ..kumi_tests::whole_body_config(Engine::Rapier, 0.6, bounds)
    };
    let mut env = WholeBody::new(model.clone(), config, &skill, 0).unwrap();
    let terms = ActionTerms::new(&model, &bounds).unwrap();
    let expected = kumi_terms::contract::contract(
        &model,
        &terms,
        options,
        &skill,
        kumi_model::commands::CONTROL_HZ,
    );
    let mut policy = WholeBodyPolicy::load(&path, &expected, BackendChoice::Tract).unwrap();
    let home = env.world().home_state();
    env.world_mut().reset(&home);
    let mut tool = Vec::new();
    for _ in 0..hold_ticks {
        let world = env.world_mut();
        for arm in terms.arms() {
            world.apply_increments(&arm.module, &[0.0; 7]).unwrap();
        }
        for wheel in terms.wheels() {
            world.set_wheel_velocity(&wheel.module, 0.0).unwrap();
        }
        world.step();
        tool.push(env.observed_tool_pose_w().translation.vector);
    }
    let [x, y, z, yaw] = TARGET;
    env.set_target(kumi_terms::Target {
        position_w: Vector3::new(x, y, z),
        yaw,
    });
    for _ in 0..ticks {
        let action = policy.act(&env.observation()).unwrap();
        env.step(&action);
        tool.push(env.observed_tool_pose_w().translation.vector);
    }
    tool
}

#[test]
fn a_launched_minimal_reaches_a_target_from_rclpy_and_replays_the_in_process_episode() {
    let _one = one_at_a_time();
    let domain = fresh_domain();
    let launch = launch(domain, &["minimal", "--lockstep", "--backend", "tract"]);
    let out = send_target(domain, "minimal", &["--disturb"]);
    let d = &out["diagnostics"];
    let error = number(&out["position_error_m"]);
    println!(
        "minimal over ROS (lockstep): tool {error:.4} m and {:.3} rad from the target after {DRIVE_S} s of sim time, {:.1} s of wall time; diagnostics {d}",
        number(&out["yaw_error_rad"]),
        number(&out["wall_s"])
    );
    assert_eq!(
        number(&d["targets_rejected"]),
        2.0,
        "the NaN and wrong-frame targets: {d}"
    );
    assert_eq!(number(&d["unsynchronised_ticks"]), 0.0, "{d}");
    // The bound: Minimal's mean final error over 1000 rapier rollouts (policies/minimal_whole_body/README.md).
    assert!(error < 0.121, "{out}");

    // The same episode in process, from the tick the node first ran the policy on.
    let dt = 1.0 / kumi_model::commands::CONTROL_HZ;
    let since = number(&d["target_since_s"]);
    let first = (since / dt).round() as usize;
    let trajectory: Vec<(usize, Vector3<f64>)> = out["trajectory"]
        .as_array()
        .unwrap()
        .iter()
        .map(|row| {
            let row: Vec<f64> = row.as_array().unwrap().iter().map(number).collect();
            (
                (row[0] / dt).round() as usize,
                Vector3::new(row[1], row[2], row[3]),
            )
        })
        .filter(|(k, _)| *k > 0)
        .collect();
    let last = trajectory
        .iter()
        .map(|(k, _)| *k)
        .max()
        .expect("tool poses after the target");
    let replay = in_process_episode(first, last - first);
    let mut worst = 0.0_f64;
    for (k, p) in &trajectory {
        let d = (replay[k - 1] - p).norm();
        if d > 0.0 && worst == 0.0 {
            println!("first difference at tick {k}: {d:e} m");
        }
        worst = worst.max(d);
    }
    println!(
        "ROS vs in-process over {} ticks from tick {first}: largest tool distance {worst:e} m",
        trajectory.len()
    );
    assert!(
        trajectory.len() as f64 > 0.9 * (last - first) as f64,
        "ticks missing"
    );
    assert_eq!(worst, 0.0, "the ROS loop left the in-process episode");
    drop(launch);
}

/// The process ids of `pid`'s children.
fn children(pid: u32) -> Vec<u32> {
    std::fs::read_to_string(format!("/proc/{pid}/task/{pid}/children"))
        .unwrap_or_default()
        .split_whitespace()
        .filter_map(|p| p.parse().ok())
        .collect()
}

/// The command line of process `pid`.
fn cmdline(pid: u32) -> String {
    std::fs::read_to_string(format!("/proc/{pid}/cmdline"))
        .unwrap_or_default()
        .replace('\0', " ")
}

/// Runs `kumi args`, which must end on its own within `deadline`; its output.
fn kumi_once(domain: u16, args: &[&str], deadline: Duration) -> String {
    let mut p = KumiProcess::spawn(KUMI, &[], args, domain);
    let start = std::time::Instant::now();
    while p.alive() && start.elapsed() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(
        !p.alive(),
        "`kumi {}` still runs: {}",
        args.join(" "),
        p.log()
    );
    p.log()
}

#[test]
fn modules_join_by_hand_robots_share_a_domain_duplicates_are_refused_and_a_dead_node_stops_its_launch(
) {
    let _one = one_at_a_time();
    let domain = fresh_domain();
    // `first` without its arm node; the node started by hand joins.
    let first = launch(
        domain,
        &[
            "minimal",
            "--robot",
            "first",
            "--lockstep",
            "--without",
            "arm0",
        ],
    );
    assert!(
        !first.log().contains("kumi arm arm0"),
        "arm0 was left out: {}",
        first.log()
    );
    let by_hand = KumiProcess::spawn(
        KUMI,
        &[],
        &[
            "arm",
            "arm0",
            "--robot",
            "first",
            "--morphology",
            "minimal",
            "--goal-sync-ms",
            "2500",
            "--wait-for-first-goal",
        ],
        domain,
    );
    assert!(
        by_hand.wait_for_log("arm node up", START),
        "{}",
        by_hand.log()
    );
    // `second`, a whole robot of its own on the same domain.
    let second = launch(domain, &["minimal", "--robot", "second", "--lockstep"]);
    let mut last = serde_json::Value::Null;
    let expect = arm_statuses("first", &["arm0"]);
    for robot in ["first", "second"] {
        let out = send_target(domain, robot, &["--expect", &expect]);
        let error = number(&out["position_error_m"]);
        println!("{robot}: tool {error:.4} m from the target");
        assert!(error < 0.121, "{robot}: {out}");
        last = out;
    }
    // Each simulator's time is its robot's own (`/<robot>/clock`): while `second` ran, `first`'s
    // arm nodes never took its time for a restart of theirs.
    let arm = &last["all_diagnostics"]["kumi arm node: first/arm0"];
    assert_eq!(number(&arm["sim_restarts"]), 0.0, "first/arm0: {arm}");

    // A second node for first's arm0, and a second whole-body node for first: refused.
    let log = kumi_once(
        domain,
        &["arm", "arm0", "--robot", "first", "--morphology", "minimal"],
        Duration::from_secs(30),
    );
    assert!(
        log.contains("another node already commands module `arm0` of robot `first`"),
        "{log}"
    );
    let log = kumi_once(
        domain,
        &["whole-body", "--robot", "first", "--morphology", "minimal"],
        Duration::from_secs(30),
    );
    assert!(
        log.contains("another whole-body node already drives robot `first`"),
        "{log}"
    );

    // second's whole-body node dies: its launch stops every node and says which died.
    let mut second = second;
    let nodes = children(second.pid());
    assert_eq!(nodes.len(), 3, "bridge, arm0, whole_body: {nodes:?}");
    let whole_body = *nodes
        .iter()
        .find(|&&p| cmdline(p).contains("whole-body"))
        .expect("a whole-body child");
    std::process::Command::new("kill")
        .args(["-9", &whole_body.to_string()])
        .status()
        .unwrap();
    let start = std::time::Instant::now();
    while second.alive() && start.elapsed() < Duration::from_secs(20) {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(
        !second.alive(),
        "the launch went on without its whole-body node"
    );
    assert!(
        second.log().contains("node `whole_body` exited"),
        "{}",
        second.log()
    );
    for p in nodes {
        assert!(
            !std::path::Path::new(&format!("/proc/{p}")).exists()
                || std::fs::read_to_string(format!("/proc/{p}/stat"))
                    .is_ok_and(|s| s.contains(") Z ")),
            "node {p} ({}) outlived its launch",
            cmdline(p)
        );
    }
    drop(first);
    drop(by_hand);
}

/// The launches on MuJoCo, built with `--features mujoco` (as `.ci/run` builds the tests).
#[cfg(feature = "mujoco")]
mod on_mujoco {
    use super::*;
    use kumi_tests::numbers;

    /// Launches `robot` in lockstep on MuJoCo (its training engine), sends the target and watches a
    /// whole 12 s training episode. Asserts that no tick went unsynchronised and that every goal the
    /// policy sent reached each of `arm_modules`, none refused. The peer's output, the tool's final
    /// error [m], and the launch, which stops when dropped.
    fn reach_on_mujoco(robot: &str, arm_modules: &[&str]) -> (serde_json::Value, f64, KumiProcess) {
        let domain = fresh_domain();
        let launch = launch(
            domain,
            &[
                robot,
                "--lockstep",
                "--engine",
                "mujoco",
                "--backend",
                "tract",
            ],
        );
        let expect = arm_statuses(robot, arm_modules);
        let out = send_target_for(domain, robot, 12.0, &["--expect", &expect]);
        let error = number(&out["position_error_m"]);
        let d = &out["diagnostics"];
        println!(
            "{robot} over ROS (lockstep, MuJoCo): tool {error:.4} m and {:.3} rad from the target after 12 s of sim time, {:.1} s of wall time; diagnostics {d}",
            number(&out["yaw_error_rad"]),
            number(&out["wall_s"])
        );
        assert_eq!(number(&d["unsynchronised_ticks"]), 0.0, "{d}");
        for module in arm_modules {
            let arm = &out["all_diagnostics"][arm_status(robot, module)];
            assert_eq!(number(&arm["goals_rejected"]), 0.0, "{module}: {arm}");
            assert!(number(&arm["goals_accepted"]) > 300.0, "{module}: {arm}");
        }
        (out, error, launch)
    }

    /// Dragon runs on MuJoCo: its policy was trained there and does not carry over to rapier
    /// (policies/dragon_whole_body/README.md).
    #[test]
    fn a_launched_dragon_reaches_a_target_from_rclpy_on_mujoco() {
        let _one = one_at_a_time();
        // Dragon turns by steering its rear wheel module. Both arm modules get every goal (the leg's
        // home tool is at its full reach: a tighter reach check once refused all of its goals).
        let (out, error, _launch) = reach_on_mujoco("dragon", &["arm0", "leg0"]);
        // The bound: the 90th percentile of Dragon's final error over 1000 MuJoCo rollouts
        // (0.42 m, policies/dragon_whole_body/README.md). The episode is not the same on every run: the
        // robot settles on its wheels while it waits, and the target lands on whichever tick the
        // peer gets to (0.06, 0.09 and 0.13 m measured). A robot whose goals went astray ends
        // metres away.
        assert!(error < 0.42, "{out}");
    }

    /// The 99th percentile of Tricycle's closest approach [m] to its target over the MuJoCo
    /// rollouts that started within 1.5 m of it, as this target does (0.1552 m over 180 of 1000,
    /// median 0.0315 m, p90 0.0703 m; policies/tricycle_whole_body/README.md). One run is one draw of
    /// that spread, so the bound is its far tail, not its p90: a robot whose goals went astray,
    /// or that fell on the way, comes nowhere near a target 1.1 m off. The closest approach, not
    /// the final error: Tricycle comes close and then wanders near the target (an earlier
    /// policy's final errors were 0.40-0.72 m in eight runs here, its closest approaches
    /// 0.05-0.09 m), so its final error depends on the instant the episode ends.
    const TRICYCLE_CLOSEST_P99: f64 = 0.1552;

    #[test]
    fn a_launched_tricycle_reaches_a_target_from_rclpy_on_mujoco() {
        let _one = one_at_a_time();
        // Four arm nodes, each fed every goal the policy sent: the manipulator and three legs.
        let (out, error, _launch) = reach_on_mujoco("tricycle", &["arm0", "leg0", "leg1", "leg2"]);
        // The peer's trajectory rows are [t, x, y, z, yaw] of the tool.
        let closest = out["trajectory"]
            .as_array()
            .unwrap()
            .iter()
            .map(|row| {
                let row = numbers(row);
                (0..3)
                    .map(|k| (row[k + 1] - TRICYCLE_TARGET[k]).powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .fold(f64::INFINITY, f64::min);
        println!(
            "tricycle: closest approach {closest:.4} m, final {error:.4} m, tipped over {}",
            out["diagnostics"]["tipped_over"]
        );
        // A robot whose goals went astray never comes near; one that fell on the way neither. A
        // fall after coming close is not asserted against: the policy's falls are measured by
        // `kumi eval whole-body`, not here.
        assert!(closest < TRICYCLE_CLOSEST_P99, "{out}");
    }
}

#[test]
fn a_launched_minimal_reaches_a_target_in_real_time() {
    let _one = one_at_a_time();
    let domain = fresh_domain();
    let launch = launch(domain, &["minimal"]);
    let expect = format!(
        "{},kumi sim bridge: minimal",
        arm_statuses("minimal", &["arm0"])
    );
    let out = send_target(domain, "minimal", &["--expect", &expect]);
    let error = number(&out["position_error_m"]);
    let all = &out["all_diagnostics"];
    let arm = &all["kumi arm node: minimal/arm0"];
    let bridge = &all["kumi sim bridge: minimal"];
    println!(
        "minimal in real time: tool {error:.4} m from the target after {DRIVE_S} s; arm late_goals {}, bridge late_steps {} (max {} ms late), whole-body {}",
        arm["late_goals"], bridge["late_steps"], bridge["max_step_late_ms"], out["diagnostics"]
    );
    // Real time is not reproducible to the bit: the bound is the policy's evaluated mean
    // (0.121 m in rapier) with a margin for a tick acted on late.
    assert!(error < 0.15, "{out}");
    assert_eq!(
        number(&out["diagnostics"]["unsynchronised_ticks"]),
        0.0,
        "{out}"
    );
    drop(launch);
}

#[test]
fn the_demo_runs_end_to_end_with_its_plot_csv_and_json() {
    let _one = one_at_a_time();
    let (report, csv, svg) = demo(&["minimal", "--targets", "2"]);
    println!("demo: {report}");
    assert_eq!(report["robot"], "minimal");
    let targets = report["targets"].as_array().unwrap();
    assert_eq!(targets.len(), 2);
    for t in targets {
        assert_eq!(t["target"].as_array().unwrap().len(), 4);
        let e = number(&t["position_error_m"]);
        assert!(
            e.is_finite() && e < 0.321,
            "beyond Minimal's p90 in rapier: {t}"
        );
        assert!(number(&t["yaw_error_rad"]).is_finite());
        assert!(t["tipped_over_after_s"].is_null(), "{t}");
    }
    assert_eq!(report["skipped"], 0);
    assert!(
        svg.contains("<polyline") && svg.matches("<circle").count() == 2,
        "{svg}"
    );
    assert_eq!(
        csv.lines().count(),
        1 + 2 * 360,
        "two 12 s targets at 30 Hz"
    );
    assert!(
        csv.starts_with("t_s,target,") && csv.lines().next().unwrap().contains(",base_tilt_rad,")
    );
}

/// Runs `kumi demo` with `args` to its end; its JSON report, its CSV and its plot.
fn demo(args: &[&str]) -> (serde_json::Value, String, String) {
    let (report, dir) = demo_kept(args);
    let csv = std::fs::read_to_string(report["csv"].as_str().unwrap()).unwrap();
    let svg = std::fs::read_to_string(report["plot"].as_str().unwrap()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    (report, csv, svg)
}

/// Runs `kumi demo` with `args` to its end; its JSON report and its output folder (the
/// caller removes it).
fn demo_kept(args: &[&str]) -> (serde_json::Value, std::path::PathBuf) {
    let domain = fresh_domain();
    let dir = std::env::temp_dir().join(format!("kumi-demo-{}-{domain}", std::process::id()));
    let (d, out) = (domain.to_string(), dir.display().to_string());
    let mut all = vec!["demo", "--domain", &d, "--out", &out, "--json"];
    all.extend(args);
    let mut demo = KumiProcess::spawn(KUMI, &[], &all, domain);
    let start = std::time::Instant::now();
    while demo.alive() && start.elapsed() < Duration::from_secs(240) {
        std::thread::sleep(Duration::from_millis(100));
    }
    let log = demo.log();
    let line = log
        .lines()
        .find(|l| l.starts_with("{\"robot\""))
        .unwrap_or_else(|| panic!("no JSON line: {log}"));
    (serde_json::from_str(line).unwrap(), dir)
}

/// Every channel of a recording read back: rosbag2's encodings, its summary's count equal to
/// the messages read, each message decoded from the file's own schema to the values rclpy's
/// type support gives (tf2_msgs, not on PyPI, only the former), each schema's definition that
/// of the installed interface. Returns the channels by topic.
fn check_recording(recording: &serde_json::Value) -> serde_json::Map<String, serde_json::Value> {
    assert_eq!(recording["profile"], "ros2");
    assert_eq!(recording["log_time_in_order"], true);
    let channels = recording["channels"].as_object().unwrap().clone();
    for (topic, c) in &channels {
        assert_eq!(c["schema_encoding"], "ros2msg", "{topic}: {c}");
        assert_eq!(c["message_encoding"], "cdr", "{topic}: {c}");
        assert_eq!(c["summary_count"], c["count"], "{topic}: {c}");
        assert_eq!(c["mismatches"], serde_json::json!([]), "{topic}: {c}");
        let tf = c["type"] == "tf2_msgs/msg/TFMessage";
        assert_eq!(c["checked_natively"], !tf, "{topic}: {c}");
        if !tf {
            assert_eq!(c["definition_matches"], true, "{topic}: {c}");
        }
    }
    channels
}

/// Issue 69, item 8: `kumi demo --record` writes every topic of the run to an MCAP file that
/// the `mcap` Python package opens; its channels, schemas and counts are what the nodes and the
/// demo published.
#[test]
fn a_recording_of_the_demo_holds_every_topic_as_it_was_published() {
    let _one = one_at_a_time();
    let (report, dir) = demo_kept(&["minimal", "--targets", "2", "--seconds", "2", "--record"]);
    let file = std::path::PathBuf::from(report["recording"]["file"].as_str().unwrap());
    assert_eq!(file, dir.join("minimal.mcap"));
    let recording = kumi_tests::read_mcap(&file);
    let csv = std::fs::read_to_string(report["csv"].as_str().unwrap()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let channels = check_recording(&recording);
    let expected = [
        ("/minimal/arm0/joint_states", "sensor_msgs/msg/JointState"),
        ("/minimal/wheel0/joint_states", "sensor_msgs/msg/JointState"),
        ("/minimal/arm0/joint_targets", "sensor_msgs/msg/JointState"),
        (
            "/minimal/arm0/joint_increments",
            "std_msgs/msg/Float64MultiArray",
        ),
        ("/minimal/arm0/goal_pose", "geometry_msgs/msg/PoseStamped"),
        ("/minimal/arm0/ee_pose", "geometry_msgs/msg/PoseStamped"),
        ("/minimal/wheel0/wheel_velocity", "std_msgs/msg/Float64"),
        ("/minimal/odom", "nav_msgs/msg/Odometry"),
        ("/minimal/imu", "sensor_msgs/msg/Imu"),
        ("/minimal/goal_pose", "geometry_msgs/msg/PoseStamped"),
        ("/minimal/tool_pose", "geometry_msgs/msg/PoseStamped"),
        ("/minimal/robot_description", "std_msgs/msg/String"),
        ("/minimal/clock", "rosgraph_msgs/msg/Clock"),
        ("/clock", "rosgraph_msgs/msg/Clock"),
        ("/tf", "tf2_msgs/msg/TFMessage"),
        ("/tf_static", "tf2_msgs/msg/TFMessage"),
        ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
        ("/rosout", "rcl_interfaces/msg/Log"),
    ];
    for (topic, ty) in expected {
        let c = channels
            .get(topic)
            .unwrap_or_else(|| panic!("{topic} not recorded: {recording}"));
        assert_eq!(c["type"], ty, "{topic}");
    }
    assert_eq!(channels.len(), expected.len(), "{recording}");
    // What the demo says it recorded is what the file holds.
    for t in report["recording"]["topics"].as_array().unwrap() {
        let topic = t["topic"].as_str().unwrap();
        assert_eq!(t["messages"], channels[topic]["count"], "{topic}");
    }
    // Latched topics once each; the demo's two targets.
    assert_eq!(channels["/minimal/robot_description"]["count"], 1);
    assert_eq!(channels["/tf_static"]["count"], 1);
    let frames = channels["/tf_static"]["frames"].as_array().unwrap();
    assert!(frames.contains(&"minimal/arm0/ee".into()), "{frames:?}");
    // (The demo sends a target again until its ticks begin: on a loaded machine, twice.)
    let goals: std::collections::BTreeSet<u64> = channels["/minimal/goal_pose"]["stamps_ns"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_u64().unwrap())
        .collect();
    assert_eq!(
        goals,
        [0, 2_000_000_000].into(),
        "the first at once, the second at 2 s"
    );
    // Every tick of the run, as the demo's CSV has it, has its tool pose, odometry and
    // joint states in the recording.
    let tick = |ns: u64| (ns as f64 * 1e-9 * 30.0).round() as i64;
    let ticks_of = |topic: &str| -> std::collections::BTreeSet<i64> {
        channels[topic]["stamps_ns"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| tick(s.as_u64().unwrap()))
            .collect()
    };
    let run: Vec<i64> = csv
        .lines()
        .skip(1)
        .map(|l| (l.split(',').next().unwrap().parse::<f64>().unwrap() * 30.0).round() as i64)
        .collect();
    assert_eq!(run.len(), 120, "two 2 s targets at 30 Hz");
    for topic in [
        "/minimal/tool_pose",
        "/minimal/odom",
        "/minimal/arm0/joint_states",
        "/minimal/wheel0/joint_states",
        "/minimal/arm0/goal_pose",
    ] {
        let recorded = ticks_of(topic);
        let missing: Vec<&i64> = run.iter().filter(|t| !recorded.contains(t)).collect();
        assert!(
            missing.is_empty(),
            "{topic}: ticks {missing:?} not recorded"
        );
    }
}

/// `kumi launch --record DIR`: the recorder starts with the nodes, and a Ctrl-C of the launch
/// leaves a finished file (its summary written); a second launch does not overwrite it.
#[test]
fn a_launch_with_record_leaves_a_finished_recording_after_ctrl_c() {
    let _one = one_at_a_time();
    let domain = fresh_domain();
    let dir = std::env::temp_dir().join(format!("kumi-record-{}-{domain}", std::process::id()));
    let out = dir.display().to_string();
    let mut launched = launch(domain, &["minimal", "--record", &out]);
    // Real time: a few seconds of joint states at 30 Hz.
    std::thread::sleep(Duration::from_secs(3));
    let stopped = std::process::Command::new("kill")
        .args(["-INT", &launched.pid().to_string()])
        .status()
        .unwrap();
    assert!(stopped.success());
    let start = std::time::Instant::now();
    while launched.alive() && start.elapsed() < Duration::from_secs(30) {
        std::thread::sleep(Duration::from_millis(50));
    }
    let log = launched.log();
    assert!(log.contains("[recorder] recorded "), "{log}");
    let recording = kumi_tests::read_mcap(&dir.join("minimal.mcap"));
    let channels = check_recording(&recording);
    assert_eq!(channels["/minimal/robot_description"]["count"], 1);
    assert_eq!(channels["/tf_static"]["count"], 1);
    let states = channels["/minimal/arm0/joint_states"]["count"]
        .as_u64()
        .unwrap();
    assert!(states >= 30, "{states} joint states in 3 s at 30 Hz");
    assert!(
        channels.contains_key("/minimal/arm0/goal_pose"),
        "{recording}"
    );
    let again = kumi_once(domain, &["launch", "minimal", "--record", &out], START);
    assert!(again.contains("already exists"), "{again}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_seeded_lockstep_demo_with_several_arm_nodes_repeats_its_csv_exactly() {
    let _one = one_at_a_time();
    // Dragon: two arm nodes and the whole-body node driving two wheel modules, each its own
    // process; three targets, each later one sent while the one before runs and stamped with
    // its start. With this seed the shipped policy tips Dragon over on rapier during the
    // second: the demo resets the world (/dragon/reset) and drives the third from the start.
    let args = ["dragon", "--targets", "3", "--seconds", "4", "--seed", "3"];
    let (first, csv, _) = demo(&args);
    let (second, again, _) = demo(&args);
    println!("demo: {first}");
    assert_eq!(first["skipped"], 0, "every target driven: {first}");
    assert_eq!(first["inexact_ticks"], 0, "{first}");
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    for (k, row) in rows.iter().enumerate() {
        let t: f64 = row.split(',').next().unwrap().parse().unwrap();
        assert!(
            (t - (k + 1) as f64 / 30.0).abs() < 1e-3,
            "row {k} at {t} s: one per tick"
        );
    }
    let target_of = |row: &str| row.split(',').nth(1).unwrap().to_string();
    assert_eq!(target_of(rows[119]), "1");
    assert_eq!(
        target_of(rows[120]),
        "2",
        "the second target drives from tick 121"
    );
    assert_eq!(target_of(rows.last().unwrap()), "3");
    for key in ["targets", "skipped"] {
        assert_eq!(
            first[key], second[key],
            "two runs of the same seeded demo: {key}"
        );
    }
    assert!(
        csv == again,
        "two runs of the same seeded demo wrote different CSVs"
    );
}

#[test]
fn the_whole_body_node_holds_through_a_dead_bridge_and_resumes_with_its_replacement() {
    let _one = one_at_a_time();
    // Each node by hand, in real time, as on separate hosts.
    let domain = fresh_domain();
    let start_bridge = || {
        let b = KumiProcess::spawn(KUMI, &[], &["sim-bridge", "minimal"], domain);
        assert!(b.wait_for_log("sim bridge up", START), "{}", b.log());
        b
    };
    let bridge = start_bridge();
    let arm = KumiProcess::spawn(
        KUMI,
        &[],
        &["arm", "arm0", "--robot", "minimal", "--goal-sync-ms", "10"],
        domain,
    );
    let whole_body = KumiProcess::spawn(KUMI, &[], &["whole-body", "--robot", "minimal"], domain);
    assert!(
        whole_body.wait_for_log("whole-body node up", START),
        "{}",
        whole_body.log()
    );
    let first = send_target(domain, "minimal", &[]);
    assert!(number(&first["position_error_m"]) < 0.15, "{first}");

    bridge.kill9();
    assert!(
        whole_body.wait_for_log("holding", Duration::from_secs(10)),
        "no hold without odometry: {}",
        whole_body.log()
    );
    let _replacement = start_bridge();
    // The new simulator starts over at home; the node still has its target and drives to it.
    let second = send_target(domain, "minimal", &[]);
    let d = &second["diagnostics"];
    println!("after the bridge's restart: {d}");
    assert!(number(&second["position_error_m"]) < 0.15, "{second}");
    assert!(number(&d["stale_holds"]) >= 1.0, "{d}");
    assert!(number(&d["sim_restarts"]) >= 1.0, "{d}");
    drop(arm);
}

/// A morphology kumi does not ship, written here: Dragon with its manipulator on the rear wheel
/// module instead of the front one.
const TUG: &str = r#"
name = "tug"
description = "Dragon with its manipulator on the rear wheel module"

[[module]]
name = "front_wheel"
kind = "wheel"
role = "wheel"

[[module]]
name = "leg0"
kind = "arm"
role = "leg"
mount = { parent = "front_wheel", connector = "back", spin = 1.5707963267948966 }
home = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]

[[module]]
name = "rear_wheel"
kind = "wheel"
role = "wheel"
mount = { parent = "leg0", connector = "tip", child_connector = "front", spin = 1.5707963267948966 }

[[module]]
name = "arm0"
kind = "arm"
role = "manipulator"
mount = { parent = "rear_wheel", connector = "top" }
home = [0.0, -0.3, 0.0, 1.5, 0.0, 0.3707963267948966, 0.0]
"#;

/// Runs `kumi args` in `dir` to its end (at most `deadline`); its output, and its JSON line
/// when it printed one.
fn kumi_in(
    dir: &std::path::Path,
    args: &[&str],
    deadline: Duration,
) -> (String, Option<serde_json::Value>) {
    let mut p = KumiProcess::spawn_in(dir, KUMI, args, fresh_domain());
    let start = std::time::Instant::now();
    while p.alive() && start.elapsed() < deadline {
        std::thread::sleep(Duration::from_millis(100));
    }
    assert!(
        !p.alive(),
        "`kumi {}` ran past {deadline:?}",
        args.join(" ")
    );
    let log = p.log();
    let json = log
        .lines()
        .find(|l| l.starts_with('{'))
        .map(|l| serde_json::from_str(l).unwrap());
    (log, json)
}

#[test]
fn a_robot_kumi_does_not_ship_goes_from_its_file_to_a_deployed_hierarchy_with_no_config() {
    let _one = one_at_a_time();
    let dir = std::env::temp_dir().join(format!("kumi-tug-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("tug.toml"), TUG).unwrap();
    let minute = Duration::from_secs(60);

    // What the robot is, and that it needs no config.
    let (log, robot) = kumi_in(&dir, &["robot", "tug.toml", "--json"], minute);
    let robot = robot.unwrap_or_else(|| panic!("no JSON: {log}"));
    assert_eq!(robot["robot"], "tug");
    assert_eq!(robot["modules"].as_array().unwrap().len(), 4);
    assert_eq!(robot["arms"].as_array().unwrap().len(), 2);
    assert_eq!(
        (robot["observations"].as_u64(), robot["actions"].as_u64()),
        (Some(26), Some(12))
    );
    assert!(robot["standing"]["stands"].as_bool().unwrap(), "{robot}");
    let config = robot["config"].as_str().unwrap();
    assert!(config.starts_with("the default recipe"), "{config}");

    // A short training on the default recipe, found by every command after it.
    let (log, _) = kumi_in(
        &dir,
        &["train", "whole-body", "tug.toml", "--steps", "8192"],
        5 * minute,
    );
    let policy = dir.join("runs/tug_whole_body/tug_whole_body.onnx");
    assert!(policy.exists(), "no policy: {log}");
    assert!(log.contains("config: the default recipe"), "{log}");

    let (log, eval) = kumi_in(
        &dir,
        &[
            "eval",
            "whole-body",
            "tug.toml",
            "--rollouts",
            "4",
            "--json",
        ],
        5 * minute,
    );
    let eval = eval.unwrap_or_else(|| panic!("no JSON: {log}"));
    assert_eq!(
        (eval["robot"].as_str(), eval["rollouts"].as_u64()),
        (Some("tug"), Some(4))
    );
    assert!(
        number(&eval["position_error_m"]["mean"]).is_finite(),
        "{eval}"
    );

    // The demo reads the task it was trained on from the policy: targets in its range.
    let (log, demo) = kumi_in(
        &dir,
        &[
            "demo",
            "tug.toml",
            "--targets",
            "2",
            "--seconds",
            "2",
            "--json",
        ],
        4 * minute,
    );
    let demo = demo.unwrap_or_else(|| panic!("no JSON: {log}"));
    assert!(
        log.contains("(the metadata of runs/tug_whole_body/tug_whole_body.onnx)"),
        "{log}"
    );
    let [lo, hi] = [0.89, 1.49];
    assert!(
        config.contains(&format!("targets at {lo:.2}-{hi:.2} m")),
        "{config}"
    );
    let targets = demo["targets"].as_array().unwrap();
    assert_eq!(
        targets.len() + demo["skipped"].as_u64().unwrap() as usize,
        2,
        "{demo}"
    );
    for t in targets {
        let z = number(&t["target"][2]);
        assert!(
            (lo..=hi).contains(&z),
            "target height {z} outside the trained {lo}-{hi} m"
        );
        assert!(number(&t["position_error_m"]).is_finite(), "{t}");
    }

    // The launch: every node up, the whole-body node on the trained policy and its tilt limit.
    let launch = KumiProcess::spawn_in(&dir, KUMI, &["launch", "tug.toml"], fresh_domain());
    assert!(
        launch.wait_for_log("whole-body node up", START),
        "{}",
        launch.log()
    );
    let log = launch.log();
    for node in ["sim_bridge", "leg0", "arm0", "whole_body"] {
        assert!(log.contains(&format!("[{node}]")), "no {node}: {log}");
    }
    assert!(
        log.contains("tilt limit 1 rad: the policy's training limit (the metadata of runs/tug_whole_body/tug_whole_body.onnx)"),
        "{log}"
    );
    drop(launch);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 69, item 3: `ros2 param list` and `ros2 param get` on every node, as rclpy's parameter
/// services client does them; settings are read-only.
#[test]
fn ros2_param_list_and_get_answer_every_nodes_settings_read_only() {
    let _one = one_at_a_time();
    let domain = fresh_domain();
    let _launch = launch(domain, &["minimal", "--lockstep"]);
    let params = |node: &str| {
        let out = peer(
            domain,
            &["params", "--kind", node, "--timeout", "20"],
            Duration::from_secs(90),
        );
        assert!(out.get("error").is_none(), "{node}: {out}");
        println!("{node}: {out}");
        let set = &out["set"][0];
        assert_eq!(set["successful"], false, "{node}: {out}");
        assert!(
            set["reason"].as_str().unwrap().contains("read-only"),
            "{out}"
        );
        assert!(
            out["read_only"]
                .as_array()
                .unwrap()
                .iter()
                .all(|r| r == true),
            "{out}"
        );
        out["values"].clone()
    };
    let bridge = params("/minimal/sim_bridge");
    assert_eq!(bridge["robot"], "minimal");
    assert_eq!(bridge["mode"], "lockstep");
    assert_eq!(bridge["lockstep_timeout_s"], 5.0);
    assert_eq!(bridge["wait_for"], serde_json::json!(["arm0", "wheel0"]));
    let arm = params("/minimal/arm0/arm_node");
    assert_eq!(arm["module"], "arm0");
    assert_eq!(arm["goal_sync_s"], 2.5);
    assert!(
        arm["policy.file"]
            .as_str()
            .unwrap()
            .ends_with("arm_reach.onnx"),
        "{arm}"
    );
    let skill = std::fs::read(arm["policy.file"].as_str().unwrap()).unwrap();
    assert_eq!(
        arm["policy.fingerprint"],
        kumi_policies::metadata::fingerprint_bytes(&skill)
    );
    let whole_body = params("/minimal/whole_body");
    assert_eq!(whole_body["lockstep"], true);
    assert_eq!(whole_body["tilt_limit_rad"], 0.6);
    assert_eq!(whole_body["skill.fingerprint"], arm["policy.fingerprint"]);
}

/// Issue 69, item 4: a robot is put back at its start by the sim bridge's reset
/// (`std_srvs/srv/Trigger` on `/<robot>/reset`, called from rclpy as `ros2 service call` does);
/// the nodes start over and the whole-body node drives to its target again.
#[test]
fn a_reset_puts_the_robot_back_at_its_start_and_the_nodes_start_over() {
    let _one = one_at_a_time();
    let domain = fresh_domain();
    let _launch = launch(domain, &["minimal", "--lockstep"]);
    let first = send_target(domain, "minimal", &[]);
    assert!(number(&first["position_error_m"]) < 0.15, "{first}");
    let out = peer(
        domain,
        &[
            "reset",
            "--robot",
            "minimal",
            "--drive-seconds",
            "4",
            "--timeout",
            "30",
        ],
        Duration::from_secs(90),
    );
    println!("reset: {out}");
    assert!(out.get("error").is_none(), "{out}");
    assert_eq!(out["success"], true, "{out}");
    let (before, after, later) = (&out["before"], &out["after"], &out["later"]);
    assert!(number(&before["t"]) >= DRIVE_S, "{out}");
    assert!(number(&after["t"]) < 0.1, "sim time starts over: {out}");
    let xy = |p: &serde_json::Value| [number(&p["xyz"][0]), number(&p["xyz"][1])];
    let [x0, y0] = xy(after);
    assert!(x0.hypot(y0) < 0.02, "back at the start pose: {out}");
    let [x1, y1] = xy(before);
    assert!(x1.hypot(y1) > 0.3, "it had driven away: {out}");
    // The whole-body node kept its target and drives to it again.
    let [x2, y2] = xy(later);
    assert!(x2.hypot(y2) > 0.3, "it drives again after the reset: {out}");
}

/// Issue 69, item 2 (the part kumi can fix): the check that a node is the only one publishing
/// its output leaves no reader behind, so no node lists itself as a subscriber of its own
/// output in the ROS graph (as `ros2 topic info -v` shows it, from rclpy's graph).
#[test]
fn no_node_subscribes_to_its_own_output_in_the_ros_graph() {
    let _one = one_at_a_time();
    let domain = fresh_domain();
    let _launch = launch(domain, &["minimal", "--lockstep"]);
    let graph = |topic: &str| {
        let out = peer(
            domain,
            &["graph", "--kind", topic, "--linger", "3"],
            Duration::from_secs(60),
        );
        println!("{topic}: {out}");
        let names = |key: &str| -> Vec<String> {
            out[key]
                .as_array()
                .unwrap()
                .iter()
                .map(|v| v.as_str().unwrap().to_string())
                .collect()
        };
        (names("publishers"), names("subscribers"))
    };
    let (publishers, subscribers) = graph("/minimal/tool_pose");
    assert_eq!(publishers, vec!["/minimal/whole_body".to_string()]);
    assert!(subscribers.is_empty(), "{subscribers:?}");
    let (publishers, subscribers) = graph("/minimal/arm0/joint_increments");
    assert_eq!(publishers, vec!["/minimal/arm0/arm_node".to_string()]);
    assert!(
        !subscribers.iter().any(|s| s.contains("arm_node")),
        "{subscribers:?}"
    );
    assert!(subscribers.contains(&"/minimal/sim_bridge".to_string()));
}

/// Issue 69, item 1: what `ros2 topic pub --once --keep-alive 3.5` does (the README's command:
/// a new participant each time, one sample, alive 3.5 s) delivers every target. (`--once`
/// alone, alive 0.1 s, loses them: RustDDS drops a sample from a writer it has not matched
/// yet, and the writer is gone before it repairs; docs/ros.md, known limits.)
#[test]
fn ros2_topic_pub_once_with_the_readmes_keep_alive_delivers_every_target() {
    let _one = one_at_a_time();
    let domain = fresh_domain();
    let _launch = launch(domain, &["minimal", "--lockstep"]);
    let out = peer(
        domain,
        &[
            "once",
            "--robot",
            "minimal",
            "--goal",
            "1.0,0.5,1.1,0.5",
            "--count",
            "5",
            "--within",
            "3.5",
            "--timeout",
            "20",
        ],
        Duration::from_secs(120),
    );
    println!("--once --keep-alive 3.5: {out}");
    assert!(out.get("error").is_none(), "{out}");
    assert_eq!(out["unmatched"], 0, "{out}");
    assert_eq!(out["arrived"], 5, "{out}");
}
