//! Issue 10's process-level checks, each node the `kumi` binary in a process of its own:
//! nodes killed with SIGKILL (no DDS goodbye) and restarted while the others run, a flood of
//! goals and megabyte payloads, and the bridge and an arm node in two network namespaces
//! joined by a veth pair. A real rclpy peer sends the goals and watches.
//!
//! Recovery times are printed (`--nocapture`): from starting the replacement to the tool
//! within [`REACH_BOUND_M`] of the goal, including the start of the rclpy peer that checks it.

use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use kumi_tests::{
    distance, fresh_domain, number, numbers, peer, reach, reach_arm_goal, reach_arm_goal_in,
    watch_arm, KumiProcess, ARM_GOAL, ARM_GOAL_2, REACH_BOUND_M,
};

const KUMI: &str = env!("CARGO_BIN_EXE_kumi");
const START: Duration = Duration::from_secs(60);

#[derive(Clone, Copy, Debug, PartialEq)]
enum Timing {
    Lockstep,
    RealTime,
}

fn bridge(prefix: &[&str], domain: u16, timing: Timing) -> KumiProcess {
    let mut args = vec!["sim-bridge", "arm"];
    if timing == Timing::Lockstep {
        args.extend(["--lockstep", "--lockstep-timeout", "0.1"]);
    }
    let bridge = KumiProcess::spawn(KUMI, prefix, &args, domain);
    assert!(
        bridge.wait_for_log("sim bridge up", START),
        "{}",
        bridge.log()
    );
    bridge
}

fn arm_node(prefix: &[&str], domain: u16) -> KumiProcess {
    let node = KumiProcess::spawn(KUMI, prefix, &["arm", "arm"], domain);
    assert!(node.wait_for_log("arm node up", START), "{}", node.log());
    node
}

/// Sends [`ARM_GOAL_2`] after a restart (the arm stood at [`ARM_GOAL`], or at home in a new
/// simulator: either way beyond the bound, which is checked, so the tool must move);
/// returns the tool's error and the seconds since `since`.
fn reach_after(domain: u16, since: Instant) -> (f64, f64, serde_json::Value) {
    let bound = REACH_BOUND_M.to_string();
    let (error, out) = reach(&[], domain, &ARM_GOAL_2, 8.0, &["--within", &bound]);
    let from = distance(&numbers(&out["start_position"]), &ARM_GOAL_2);
    assert!(
        from > REACH_BOUND_M,
        "the tool already stood {from:.3} m from the goal: {out}"
    );
    (error, since.elapsed().as_secs_f64(), out)
}

#[test]
fn a_sigkilled_bridge_is_replaced_and_the_arm_node_resumes_on_its_own() {
    for timing in [Timing::Lockstep, Timing::RealTime] {
        let domain = fresh_domain();
        let first = bridge(&[], domain, timing);
        let mut node = arm_node(&[], domain);
        let (error, out) = reach_arm_goal(domain, 2.0, &[]);
        assert!(
            error < 0.5,
            "{timing:?}: the first bridge was not driven: {out}"
        );
        first.kill9();
        std::thread::sleep(Duration::from_secs(1));
        let restarted = Instant::now();
        let _second = bridge(&[], domain, timing);
        let (error, seconds, out) = reach_after(domain, restarted);
        eprintln!(
            "{timing:?}: bridge SIGKILLed and restarted: tool {error:.3} m from the goal {seconds:.1} s after the restart"
        );
        assert!(node.alive(), "{timing:?}: {}", node.log());
        assert!(
            error < REACH_BOUND_M,
            "{timing:?}: tool ended {error:.3} m away: {out}\n{}",
            node.log()
        );
    }
}

#[test]
fn a_sigkilled_arm_node_is_noticed_the_arm_holds_and_a_new_node_takes_over() {
    for timing in [Timing::Lockstep, Timing::RealTime] {
        let domain = fresh_domain();
        let mut bridge = bridge(&[], domain, timing);
        let node = arm_node(&[], domain);
        let (error, out) = reach_arm_goal(domain, 2.0, &[]);
        assert!(error < 0.5, "{timing:?}: the arm was not driven: {out}");
        node.kill9();
        let watched = watch_arm(domain, 4.0);
        assert!(
            number(&watched["stale_holds"]) >= 1.0,
            "{timing:?}: the bridge did not hold: {watched}"
        );
        assert!(
            number(&watched["max_speed"]) < 0.05,
            "{timing:?}: the arm still moves: {watched}"
        );
        let advanced = number(&watched["clock_end"]) - number(&watched["clock_start"]);
        assert!(
            advanced > 0.5,
            "{timing:?}: sim time stood still: {watched}"
        );
        let restarted = Instant::now();
        let _node = arm_node(&[], domain);
        let (error, seconds, out) = reach_after(domain, restarted);
        eprintln!(
            "{timing:?}: arm node SIGKILLed and restarted: tool {error:.3} m from the goal {seconds:.1} s after the restart"
        );
        assert!(bridge.alive(), "{}", bridge.log());
        assert!(
            error < REACH_BOUND_M,
            "{timing:?}: tool ended {error:.3} m away: {out}"
        );
    }
}

/// The largest resident memory of `pids` [KiB] while `run` runs, sampled every 20 ms.
fn peak_rss<T>(processes: &[&KumiProcess], run: impl FnOnce() -> T) -> (T, Vec<u64>) {
    /// Stops the sampler however `run` ends (a panic included).
    struct Stop(Arc<AtomicBool>);
    impl Drop for Stop {
        fn drop(&mut self) {
            self.0.store(true, Ordering::Relaxed);
        }
    }
    let pids: Vec<u32> = processes.iter().map(|p| p.pid()).collect();
    let done = Arc::new(AtomicBool::new(false));
    let flag = done.clone();
    let sampler = std::thread::spawn(move || {
        let mut peak = vec![0; pids.len()];
        while !flag.load(Ordering::Relaxed) {
            for (k, pid) in pids.iter().enumerate() {
                peak[k] = peak[k].max(kumi_tests::rss_kib(*pid));
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        peak
    });
    let stop = Stop(done);
    let out = run();
    drop(stop);
    (out, sampler.join().unwrap())
}

/// Runs the rclpy peer's `flood` (2000 goals, then 1 MB payloads on every subscribed topic,
/// then [`ARM_GOAL`]) against robot `arm`.
fn flood(domain: u16) -> serde_json::Value {
    let goal: Vec<String> = ARM_GOAL.iter().map(|v| v.to_string()).collect();
    let goal = goal.join(",");
    let out = peer(
        domain,
        &[
            "flood",
            "--robot",
            "arm",
            "--arm",
            "arm",
            "--goal",
            &goal,
            "--count",
            "2000",
            "--drive-seconds",
            "5",
            "--timeout",
            "60",
        ],
        Duration::from_secs(120),
    );
    assert!(out.get("error").is_none(), "{out}");
    out
}

/// The flood's checks: the last goal won, and every kind of bad payload was counted.
fn check_flood(out: &serde_json::Value) {
    let error = distance(&numbers(&out["position"]), &ARM_GOAL);
    assert!(
        error < REACH_BOUND_M,
        "the last goal did not win: tool {error:.3} m away: {out}"
    );
    let diagnostics = &out["diagnostics"];
    let arm = &diagnostics["kumi arm node: arm/arm"];
    assert!(
        number(&arm["rejected_malformed"]) >= 3.0,
        "junk on goal_pose, joint_states and /clock: {out}"
    );
    assert!(
        number(&arm["goals_rejected"]) >= 1.0,
        "a 1 MB frame id: {out}"
    );
    assert!(
        number(&arm["joint_states_rejected"]) >= 1.0,
        "a 1 MB joint state naming joints many times: {out}"
    );
    assert_eq!(number(&arm["sim_restarts"]), 0.0, "{out}");
    let bridge = &diagnostics["kumi sim bridge: arm"];
    assert!(number(&bridge["rejected_malformed"]) >= 2.0, "{out}");
    assert!(number(&bridge["rejected_wrong_length"]) >= 1.0, "{out}");
    assert!(number(&bridge["rejected_duplicate_joint"]) >= 1.0, "{out}");
}

#[test]
fn a_flood_of_goals_and_megabyte_payloads_leaves_the_nodes_up_and_the_last_goal_wins() {
    let domain = fresh_domain();
    let mut bridge = bridge(&[], domain, Timing::RealTime);
    let mut node = arm_node(&[], domain);
    let (error, out) = reach_arm_goal(domain, 2.0, &[]);
    assert!(error < 0.5, "the arm was not driven: {out}");
    let mut rss = vec![[bridge.rss_kib(), node.rss_kib()]];
    for round in 1..=2 {
        let (out, peak) = peak_rss(&[&bridge, &node], || flood(domain));
        std::thread::sleep(Duration::from_secs(3));
        rss.push([bridge.rss_kib(), node.rss_kib()]);
        eprintln!(
            "flood {round}: 2000 goals in {:.2} s; resident memory [KiB] bridge {} -> peak {} -> {}, arm node {} -> peak {} -> {}",
            number(&out["goals_s"]),
            rss[round - 1][0],
            peak[0],
            rss[round][0],
            rss[round - 1][1],
            peak[1],
            rss[round][1]
        );
        assert!(bridge.alive(), "{}", bridge.log());
        assert!(node.alive(), "{}", node.log());
        check_flood(&out);
    }
    // Memory: the first flood leaves what the allocator and the DDS histories keep (bounded);
    // a second one must not add to it.
    for (k, name) in ["bridge", "arm node"].iter().enumerate() {
        assert!(
            rss[1][k] < rss[0][k] + 64 * 1024 && rss[2][k] < rss[1][k] + 8 * 1024,
            "{name}: resident memory [KiB] before the floods, after one, after two: {} {} {}",
            rss[0][k],
            rss[1][k],
            rss[2][k]
        );
    }
}

/// Two network namespaces joined by a veth pair, removed when dropped.
struct Namespaces {
    names: [String; 2],
}

fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| format!("`ip {}` did not run: {e}", args.join(" ")))?;
    if out.status.success() {
        Ok(())
    } else {
        Err(format!(
            "`ip {}` failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        ))
    }
}

impl Namespaces {
    /// Namespaces `<tag>a` and `<tag>b`, `10.213.<n>.1/24` and `.2/24` on the link, with the
    /// multicast route that DDS discovery needs; nothing else (no loopback route between them).
    fn create(tag: &str, subnet: u8) -> Result<Self, String> {
        let names = [format!("{tag}a"), format!("{tag}b")];
        let (a, b) = (&names[0], &names[1]);
        let ns = Self {
            names: names.clone(),
        };
        let (veth_a, veth_b) = (format!("{tag}va"), format!("{tag}vb"));
        // Left over by a run that was killed (its veth pair went with them).
        for name in &names {
            let _ = ip(&["netns", "del", name]);
        }
        ip(&["netns", "add", a])?;
        ip(&["netns", "add", b])?;
        ip(&[
            "link", "add", &veth_a, "netns", a, "type", "veth", "peer", "name", &veth_b, "netns", b,
        ])?;
        for (name, veth, host) in [(a, &veth_a, 1), (b, &veth_b, 2)] {
            let address = format!("10.213.{subnet}.{host}/24");
            ip(&["-n", name, "addr", "add", &address, "dev", veth])?;
            ip(&["-n", name, "link", "set", veth, "up"])?;
            ip(&["-n", name, "link", "set", "lo", "up"])?;
            ip(&["-n", name, "route", "add", "224.0.0.0/4", "dev", veth])?;
        }
        Ok(ns)
    }

    fn exec(&self, k: usize) -> [&str; 4] {
        ["ip", "netns", "exec", &self.names[k]]
    }
}

impl Drop for Namespaces {
    fn drop(&mut self) {
        for name in &self.names {
            let _ = ip(&["netns", "del", name]);
        }
    }
}

#[test]
fn the_bridge_and_an_arm_node_in_two_network_namespaces_talk_over_a_veth_link() {
    let tag = format!("k{}", std::process::id() % 100_000);
    let subnet = (std::process::id() % 250) as u8;
    let ns = Namespaces::create(&tag, subnet).unwrap_or_else(|e| {
        panic!("this machine does not allow the namespaces the test needs: {e}")
    });
    let domain = fresh_domain();
    let mut bridge = bridge(&ns.exec(0), domain, Timing::RealTime);
    let mut node = arm_node(&ns.exec(1), domain);
    // The peer sits beside the bridge: the goal crosses the link to the node, the node's
    // increments cross back to the bridge, and the tool pose comes back from the node.
    let (error, out) = reach_arm_goal_in(&ns.exec(0), domain, 6.0, &[]);
    eprintln!("across namespaces the tool ended {error:.3} m from the goal");
    assert!(
        bridge.alive() && node.alive(),
        "{}\n{}",
        bridge.log(),
        node.log()
    );
    assert!(
        error < REACH_BOUND_M,
        "tool ended {error:.3} m away: {out}\n{}\n{}",
        bridge.log(),
        node.log()
    );
}
