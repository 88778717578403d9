//! Harness for kumi's end-to-end tests: an in-process sim bridge on a private ROS domain, and
//! real rclpy peers (`tests/ros/peer.py`) run as separate processes with hard deadlines.
//!
//! rclpy comes from PyPI (ROS 2 Kilted) in a virtual environment: `.ci/run` creates it at
//! `target/rosvenv`; `KUMI_ROS_PYTHON` may point at another interpreter. The tests never skip
//! when it is missing: they fail and say how to install it.

use std::io::Read;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU16, Ordering};
use std::sync::Arc;
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use kumi_model::{assemble, load_morphology, ModuleLibrary, RobotModel};
use kumi_sim_bridge::{BridgeConfig, BridgeError, Mode};

/// The workspace root.
pub fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A shipped morphology (`arm`, `minimal`, `dragon`, `tricycle`), assembled.
pub fn shipped_model(morphology: &str) -> Arc<RobotModel> {
    let library = ModuleLibrary::shipped();
    Arc::new(assemble(
        &load_morphology(morphology, &library).unwrap(),
        &library,
    ))
}

/// The Python interpreter that has rclpy.
pub fn python() -> PathBuf {
    let path = std::env::var_os("KUMI_ROS_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace().join("target/rosvenv/bin/python"));
    assert!(
        path.exists(),
        "no Python with rclpy at {}: run `bash .ci/run`, or create it with \
         `python3 -m venv target/rosvenv && target/rosvenv/bin/pip install ros-rclpy \
         ros-rmw-fastrtps-cpp ros-std-msgs ros-geometry-msgs ros-sensor-msgs ros-nav-msgs \
         ros-rosgraph-msgs ros-diagnostic-msgs ros-std-srvs mcap mcap-ros2-support` (or set \
         KUMI_ROS_PYTHON)",
        path.display()
    );
    path
}

/// A ROS domain id no other test of this run uses: tests run in parallel without crosstalk.
/// Different test processes start from different offsets.
pub fn fresh_domain() -> u16 {
    static NEXT: AtomicU16 = AtomicU16::new(0);
    let base = 20 + (std::process::id() % 8) as u16 * 20;
    base + NEXT.fetch_add(1, Ordering::Relaxed) % 20
}

/// A sim bridge running in a thread; stopped when dropped.
pub struct Bridge {
    pub robot: String,
    pub domain: u16,
    shutdown: Arc<AtomicBool>,
    handle: Option<JoinHandle<Result<(), BridgeError>>>,
}

impl Bridge {
    /// Starts a bridge for a shipped morphology on `domain`, and waits until it has started.
    pub fn start(morphology: &str, domain: u16, mode: Mode) -> Self {
        Self::start_named(morphology, morphology, domain, mode)
    }

    pub fn start_named(morphology: &str, robot: &str, domain: u16, mode: Mode) -> Self {
        let model = shipped_model(morphology);
        let config = BridgeConfig {
            model,
            engine: kumi_worlds::Engine::Rapier,
            robot: robot.to_string(),
            domain_id: domain,
            mode,
            stale_after_s: 0.5,
            duplicate_check: Duration::from_millis(500),
            first_step_waits_for: Vec::new(),
        };
        let shutdown = Arc::new(AtomicBool::new(false));
        let flag = shutdown.clone();
        let handle = std::thread::spawn(move || kumi_sim_bridge::run(config, flag));
        Self {
            robot: robot.to_string(),
            domain,
            shutdown,
            handle: Some(handle),
        }
    }

    /// Whether the bridge is still running.
    pub fn alive(&self) -> bool {
        self.handle.as_ref().is_some_and(|h| !h.is_finished())
    }

    /// Stops the bridge and returns how it ended.
    pub fn stop(mut self) -> Result<(), BridgeError> {
        self.shutdown.store(true, Ordering::Relaxed);
        self.handle
            .take()
            .expect("not yet joined")
            .join()
            .expect("bridge thread panicked")
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        self.shutdown.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// `program` as a command, run under `prefix` (`ip netns exec NS`) when there is one.
fn command_under(prefix: &[&str], program: &std::ffi::OsStr) -> Command {
    match prefix.split_first() {
        Some((first, rest)) => {
            let mut c = Command::new(first);
            c.args(rest).arg(program);
            c
        }
        None => Command::new(program),
    }
}

/// Runs `tests/ros/peer.py <args>` on `domain` and returns its JSON result; kills it after
/// `deadline`.
pub fn peer(domain: u16, args: &[&str], deadline: Duration) -> serde_json::Value {
    peer_in(&[], domain, args, deadline)
}

/// [`peer`] run under a command prefix (`ip netns exec NS`), or none.
pub fn peer_in(
    prefix: &[&str],
    domain: u16,
    args: &[&str],
    deadline: Duration,
) -> serde_json::Value {
    let mut child = command_under(prefix, python().as_os_str())
        .arg(workspace().join("tests/ros/peer.py"))
        .args(args)
        .env("ROS_DOMAIN_ID", domain.to_string())
        .env("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start the rclpy peer");
    // Both pipes are drained as the peer runs, so that a chatty peer never blocks on a full pipe.
    let stdout = drain(child.stdout.take().unwrap());
    let stderr = drain(child.stderr.take().unwrap());
    let start = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().unwrap() {
            break Some(status);
        }
        if start.elapsed() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            break None;
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let stdout = stdout.join().unwrap_or_default();
    let stderr = stderr.join().unwrap_or_default();
    let said = |what: &str| {
        format!(
            "rclpy peer `{}` {what}; its stderr:\n{}",
            args.join(" "),
            tail(&stderr, 4000)
        )
    };
    let result = || {
        let last = stdout.lines().last().unwrap_or_default();
        serde_json::from_str(last)
            .unwrap_or_else(|e| panic!("peer printed no JSON ({e}):\n{stdout}\n{stderr}"))
    };
    match status {
        Some(status) if status.success() => result(),
        // The peer's work is done and its result printed: only rclpy's teardown hung after it.
        _ if stderr.contains(&format!("] {PEER_RESULT_OUT}\n")) => {
            let how = status.map_or(format!("ran past its {deadline:?} deadline"), |s| {
                s.to_string()
            });
            println!(
                "warning: {}",
                said(&format!(
                    "hung in rclpy's shutdown after its result ({how}); the result stands"
                ))
            );
            result()
        }
        Some(status) => panic!("{}", said(&format!("failed: {status}"))),
        None => panic!("{}", said(&format!("ran past its {deadline:?} deadline"))),
    }
}

/// An MCAP recording as `tests/ros/mcap_read.py` reads it with the `mcap` and
/// `mcap-ros2-support` packages: its header, and per topic its schema, encodings, message
/// counts (from the summary and by reading), whether every message decodes to the same values
/// with rclpy's type support, its definition against the installed `.msg`, and its stamps.
pub fn read_mcap(path: &std::path::Path) -> serde_json::Value {
    let out = Command::new(python())
        .arg(workspace().join("tests/ros/mcap_read.py"))
        .arg(path)
        .output()
        .expect("run mcap_read.py");
    assert!(
        out.status.success(),
        "mcap_read.py {} failed: {}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("mcap_read.py prints JSON")
}

/// What `tests/ros/peer.py` says on stderr (`RESULT_OUT`) once its result is printed and flushed.
const PEER_RESULT_OUT: &str = "result out";

/// Reads `pipe` to its end on a thread of its own; the text, lossily decoded.
fn drain(mut pipe: impl Read + Send + 'static) -> JoinHandle<String> {
    std::thread::spawn(move || {
        let mut bytes = Vec::new();
        let _ = pipe.read_to_end(&mut bytes);
        String::from_utf8_lossy(&bytes).into_owned()
    })
}

/// The ONNX Runtime shared library from the PyPI `onnxruntime` wheel in `target/rosvenv`
/// (installed by `.ci/run`), or `ORT_DYLIB_PATH` when set. Fails, never skips, when missing.
pub fn onnxruntime_library() -> PathBuf {
    if let Some(p) = std::env::var_os("ORT_DYLIB_PATH").filter(|p| !p.is_empty()) {
        return PathBuf::from(p);
    }
    let lib = workspace().join("target/rosvenv/lib");
    let found = std::fs::read_dir(&lib).ok().and_then(|pythons| {
        pythons.flatten().find_map(|python| {
            let capi = python.path().join("site-packages/onnxruntime/capi");
            std::fs::read_dir(capi).ok()?.flatten().find_map(|f| {
                let name = f.file_name().to_string_lossy().into_owned();
                name.starts_with("libonnxruntime.so.").then(|| f.path())
            })
        })
    });
    found.unwrap_or_else(|| {
        panic!(
            "no libonnxruntime.so.* under {}/python3*/site-packages/onnxruntime/capi: run \
             `bash .ci/run`, or `target/rosvenv/bin/pip install onnxruntime` (or set ORT_DYLIB_PATH)",
            lib.display()
        )
    })
}

/// An arm-module node running in a thread; stopped when dropped.
pub struct ArmNode {
    shutdown: Arc<AtomicBool>,
    handle: Option<JoinHandle<Result<(), kumi_arm_node::ArmNodeError>>>,
}

impl ArmNode {
    /// Starts the node for `module` of the shipped `morphology`, named `robot`, on `domain`,
    /// with the shipped policy (tract backend).
    pub fn start(
        morphology: &str,
        robot: &str,
        module: &str,
        domain: u16,
        output: kumi_arm_node::Output,
    ) -> Self {
        let model = shipped_model(morphology);
        let config = kumi_arm_node::ArmNodeConfig {
            model,
            robot: robot.to_string(),
            module: module.to_string(),
            policy: kumi_runtime::shipped_arm_policy(),
            backend: kumi_runtime::BackendChoice::Tract,
            output,
            domain_id: domain,
            clock: kumi_arm_node::ClockSource::Auto,
            stale_after_s: 0.2,
            duplicate_check: Duration::from_millis(1500),
            goal_sync_s: 0.0,
            wait_for_first_goal: false,
            hardware: None,
        };
        let shutdown = Arc::new(AtomicBool::new(false));
        let flag = shutdown.clone();
        let handle = std::thread::spawn(move || kumi_arm_node::run(config, flag));
        Self {
            shutdown,
            handle: Some(handle),
        }
    }

    /// Whether the node is still running.
    pub fn alive(&self) -> bool {
        self.handle.as_ref().is_some_and(|h| !h.is_finished())
    }

    /// Stops the node and returns how it ended.
    pub fn stop(mut self) -> Result<(), kumi_arm_node::ArmNodeError> {
        self.shutdown.store(true, Ordering::Relaxed);
        self.handle
            .take()
            .expect("not yet joined")
            .join()
            .expect("arm node thread panicked")
    }
}

impl Drop for ArmNode {
    fn drop(&mut self) {
        self.shutdown.store(true, Ordering::Relaxed);
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

/// A goal inside the skill's training distribution (the paper's section IV-A: position box, pitch within
/// pi/3, yaw 0) for the single-arm robot: x, y, z [m], then the quaternion w, x, y, z (roll
/// 0.5 rad about the tool's x axis).
pub const ARM_GOAL: [f64; 7] = [0.35, 0.1, 1.0, 0.968_912_4, 0.247_403_96, 0.0, 0.0];

/// A second goal in the same distribution, 0.3 m from [`ARM_GOAL`]: a test that must see the
/// arm move after a restart sends it this one.
pub const ARM_GOAL_2: [f64; 7] = [0.3, -0.15, 0.85, 0.968_912_4, 0.247_403_96, 0.0, 0.0];

/// How close the tool must end [m]: the shipped skill's accuracy over ROS, not better than the
/// skill itself. Over 1000 goals of the paper's box in rapier its final position error has mean
/// 0.10 m and p90 0.17 m (`policies/arm_reach/README.md`); over ROS it ends 0.10 m from
/// [`ARM_GOAL`]. (The skill before working starts ended within 5 cm there.)
pub const REACH_BOUND_M: f64 = 0.15;

/// Sends [`ARM_GOAL`] to the arm node of robot `arm` (module `arm`) through the rclpy peer and
/// waits `drive_s` of sim time; returns the tool's final distance to the goal [m] and the
/// peer's report. `extra` adds peer options (`--disturb`).
pub fn reach_arm_goal(domain: u16, drive_s: f64, extra: &[&str]) -> (f64, serde_json::Value) {
    reach_arm_goal_in(&[], domain, drive_s, extra)
}

/// [`reach_arm_goal`] with the peer run under a command prefix (see [`peer_in`]).
pub fn reach_arm_goal_in(
    prefix: &[&str],
    domain: u16,
    drive_s: f64,
    extra: &[&str],
) -> (f64, serde_json::Value) {
    reach(prefix, domain, &ARM_GOAL, drive_s, extra)
}

/// The distance [m] between the first three values of `a` and of `b`.
pub fn distance(a: &[f64], b: &[f64]) -> f64 {
    (0..3).map(|k| (a[k] - b[k]).powi(2)).sum::<f64>().sqrt()
}

/// A whole-body environment's settings for tests that only need a robot, an engine, goal
/// bounds and a tilt limit: Table IV's terms with the shipped configs' weights, 12 s episodes,
/// the training ranges of start and target.
pub fn whole_body_config(
    engine: kumi_worlds::Engine,
    tilt_limit_rad: f64,
    bounds: kumi_terms::GoalBounds,
) -> kumi_train::whole_body::WholeBodyConfig {
    kumi_train::whole_body::WholeBodyConfig {
        engine,
        task: kumi_train::whole_body::TaskConfig {
            episode_s: 12.0,
            tilt_limit_rad,
            target_xy_m: 3.0,
            target_z_m: [0.9, 1.5],
            initial_xy_m: 0.5,
        },
        weights: kumi_train::body_reward::BodyWeights {
            w_p1: 1.0,
            w_p2: 1.0,
            w_o: 0.1,
            w_v: 1e-4,
            w_a: 0.005,
            alive: 0.2,
            fall: 0.0,
            tilt: 0.0,
            turn: 0.0,
            rock: 0.0,
            airborne: 0.0,
        },
        penalty: Default::default(),
        arms: kumi_train::whole_body::ArmControl::Skill(bounds),
        observation: Default::default(),
        push: None,
        replay: None,
        randomize: None,
        critic: Default::default(),
        observation_noise: Default::default(),
    }
}

/// A JSON number, or a string holding one (`/diagnostics` values are strings).
pub fn number(v: &serde_json::Value) -> f64 {
    v.as_f64()
        .or_else(|| v.as_str().and_then(|s| s.parse().ok()))
        .unwrap_or_else(|| panic!("not a number: {v}"))
}

/// The numbers of a JSON array.
pub fn numbers(v: &serde_json::Value) -> Vec<f64> {
    v.as_array()
        .unwrap_or_else(|| panic!("not an array: {v}"))
        .iter()
        .map(|x| x.as_f64().unwrap_or_else(|| panic!("not a number: {x}")))
        .collect()
}

/// Sends `goal` (x, y, z, qw, qx, qy, qz in the arm's base frame) to the arm node of robot
/// `arm` through the rclpy peer (under `prefix`) and waits `drive_s` of sim time; returns the
/// tool's final distance to the goal [m] and the peer's report.
pub fn reach(
    prefix: &[&str],
    domain: u16,
    goal: &[f64; 7],
    drive_s: f64,
    extra: &[&str],
) -> (f64, serde_json::Value) {
    let goal_text: Vec<String> = goal.iter().map(|v| v.to_string()).collect();
    let goal_text = goal_text.join(",");
    let drive = drive_s.to_string();
    let mut args = vec![
        "reach",
        "--robot",
        "arm",
        "--arm",
        "arm",
        "--goal",
        &goal_text,
        "--drive-seconds",
        &drive,
        "--timeout",
        "60",
    ];
    args.extend_from_slice(extra);
    let out = peer_in(prefix, domain, &args, Duration::from_secs(90));
    assert!(out.get("error").is_none(), "{out}");
    (distance(&numbers(&out["position"]), goal), out)
}

/// What the rclpy peer saw of robot `arm` (module `arm`) over `seconds` of wall time: its
/// `watch` report (sim time, the bridge's stale holds, lockstep timeouts and silent modules, the
/// arm node's diagnostics, the arm's joint speeds at the end).
pub fn watch_arm(domain: u16, seconds: f64) -> serde_json::Value {
    let seconds = seconds.to_string();
    peer(
        domain,
        &[
            "watch",
            "--robot",
            "arm",
            "--arm",
            "arm",
            "--drive-seconds",
            &seconds,
            "--timeout",
            "20",
        ],
        Duration::from_secs(40),
    )
}

/// The resident memory of process `pid` [KiB] (`VmRSS` in /proc), or 0 when it has gone.
pub fn rss_kib(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(0)
}

/// A kumi node run as a process of its own (the `kumi` binary of the calling crate), so that a
/// test can kill it with SIGKILL: no DDS goodbye, no clean shutdown. Its stdout and stderr go to
/// a log file; it is killed when dropped.
pub struct KumiProcess {
    child: std::process::Child,
    label: String,
    log: PathBuf,
}

impl KumiProcess {
    /// Starts `exe args` on `domain` (under `prefix`, for example `ip netns exec NS`), with the
    /// ONNX Runtime library of [`onnxruntime_library`].
    pub fn spawn(exe: &str, prefix: &[&str], args: &[&str], domain: u16) -> Self {
        Self::spawn_with(exe, prefix, args, domain, None)
    }

    /// [`Self::spawn`] in the working directory `dir` (where `runs/` is written and read).
    pub fn spawn_in(dir: &std::path::Path, exe: &str, args: &[&str], domain: u16) -> Self {
        Self::spawn_with(exe, &[], args, domain, Some(dir))
    }

    fn spawn_with(
        exe: &str,
        prefix: &[&str],
        args: &[&str],
        domain: u16,
        dir: Option<&std::path::Path>,
    ) -> Self {
        static SERIAL: AtomicU16 = AtomicU16::new(0);
        let label = args.join(" ");
        let log = std::env::temp_dir().join(format!(
            "kumi-test-{}-{}.log",
            std::process::id(),
            SERIAL.fetch_add(1, Ordering::Relaxed)
        ));
        let file = std::fs::File::create(&log).expect("create the log file");
        let mut command = command_under(prefix, exe.as_ref());
        if let Some(dir) = dir {
            command.current_dir(dir);
        }
        let child = command
            .args(args)
            .env("ROS_DOMAIN_ID", domain.to_string())
            .env("ORT_DYLIB_PATH", onnxruntime_library())
            .env_remove("RUST_LOG")
            .stdout(file.try_clone().expect("log file"))
            .stderr(file)
            .spawn()
            .unwrap_or_else(|e| panic!("start `{label}`: {e}"));
        Self { child, label, log }
    }

    /// The process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Whether it still runs.
    pub fn alive(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    /// Kills it with SIGKILL and reaps it.
    pub fn kill9(mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }

    /// Its resident memory [KiB], or 0 when it has gone.
    pub fn rss_kib(&self) -> u64 {
        rss_kib(self.pid())
    }

    /// Everything it printed so far.
    pub fn log(&self) -> String {
        format!(
            "== {}\n{}",
            self.label,
            std::fs::read_to_string(&self.log).unwrap_or_default()
        )
    }

    /// Waits up to `timeout` for a line of its log that contains `text`.
    pub fn wait_for_log(&self, text: &str, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        while Instant::now() < deadline {
            if std::fs::read_to_string(&self.log)
                .unwrap_or_default()
                .contains(text)
            {
                return true;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        false
    }
}

impl Drop for KumiProcess {
    /// Kills the process. When the test is failing, its log's tail goes to stderr and the file
    /// is kept (its path printed), so that a failure on CI says what the nodes saw.
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        if std::thread::panicking() {
            let log = self.log();
            eprintln!("{} (log kept at {})", tail(&log, 6000), self.log.display());
        } else {
            let _ = std::fs::remove_file(&self.log);
        }
    }
}

/// The last `max_bytes` of `text` (from a line start where possible).
fn tail(text: &str, max_bytes: usize) -> &str {
    if text.len() <= max_bytes {
        return text;
    }
    let mut start = text.len() - max_bytes;
    while !text.is_char_boundary(start) {
        start += 1;
    }
    match text[start..].find('\n') {
        Some(i) => &text[start + i + 1..],
        None => &text[start..],
    }
}
