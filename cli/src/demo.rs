//! `kumi demo`: the whole system end to end. Launches a robot (sim bridge in lockstep, an arm
//! node per arm module, the whole-body node; each its own process) on a private ROS domain,
//! sends it targets one after another as a user would (`/<robot>/goal_pose`), and reports
//! each target's final tool error and time, with a top-down plot (SVG) and a CSV of the run.
//! Needs no ROS install and no native library (tract, rapier).

use std::collections::BTreeMap;
use std::f64::consts::PI;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use clap::Args;
use kumi_msgs::builtin_interfaces::Time;
use kumi_msgs::diagnostic_msgs::DiagnosticArray;
use kumi_msgs::geometry_msgs::PoseStamped;
use kumi_msgs::nav_msgs::Odometry;
use kumi_msgs::std_msgs::Header;
use kumi_recorder::{RecordedTopic, Recorder, RecordingThread};
use kumi_ros::services::TriggerClient;
use kumi_ros::{geometry, qos, topics, Publisher, RosNode};
use kumi_terms::observation::{target_errors, tool_yaw, Target};
use kumi_terms::termination::tilt;
use nalgebra::{Isometry3, UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::launch::{self, Launch, LaunchArgs};
use crate::plot;
use crate::sim::load_model;

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// `minimal`, `dragon`, `tricycle`, or a morphology file with a whole-body policy.
    pub morphology: String,
    /// How many targets, one after another.
    #[arg(long, default_value_t = 3)]
    pub targets: usize,
    /// Seed of the targets.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Simulated seconds per target (default: the policy's training episodes' length).
    #[arg(long)]
    pub seconds: Option<f64>,
    /// The base tilt [rad] past which the robot has tipped over (default: the one the policy
    /// was trained with, from its metadata).
    #[arg(long)]
    pub tilt_limit_rad: Option<f64>,
    /// Where the plot, the CSV and the nodes' log go (default: runs/demo-<robot>).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// The ROS domain (default: a private one from this process's id, 100-199).
    #[arg(long)]
    pub domain: Option<u16>,
    /// The whole-body policy (default: the shipped one).
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// The sim bridge's physics engine: rapier (default) or mujoco (built with `--features
    /// mujoco`).
    #[arg(long)]
    pub engine: Option<String>,
    /// One JSON object on stdout: {robot, targets: [{target: [x, y, z, yaw], position_error_m,
    /// yaw_error_rad, seconds, tipped_over_after_s}], skipped, inexact_ticks, plot, csv,
    /// recording: {file, topics: [{topic, type, messages}]} or null}.
    #[arg(long)]
    pub json: bool,
    /// Record every topic of the run to <out>/<robot>.mcap (`kumi record`; MCAP as rosbag2
    /// writes it, for Foxglove and `ros2 bag`), from before the first target to the end.
    #[arg(long)]
    pub record: bool,
}

/// Where targets are drawn: within `xy_m` of the robot's base along x and y, height in `z_m`.
struct TargetRange {
    xy_m: f64,
    z_m: [f64; 2],
}

/// The targets of a run, each relative to where the base stands when it is sent ([`place`]):
/// seeded, within the range the policy was trained on (training draws each episode's target
/// around a base that starts near the origin).
fn draw_targets(n: usize, seed: u64, range: &TargetRange) -> Vec<Target> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..n)
        .map(|_| Target {
            position_w: Vector3::new(
                rng.random_range(-range.xy_m..range.xy_m),
                rng.random_range(-range.xy_m..range.xy_m),
                rng.random_range(range.z_m[0]..range.z_m[1]),
            ),
            yaw: rng.random_range(-PI..PI),
        })
        .collect()
}

/// A drawn target placed around the base standing at `base_xy` [m]: a target drawn around the
/// start would be out of the trained range (and refused by the whole-body node) once the robot
/// has moved.
fn place(offset: &Target, base_xy: [f64; 2]) -> Target {
    Target {
        position_w: offset.position_w + Vector3::new(base_xy[0], base_xy[1], 0.0),
        yaw: offset.yaw,
    }
}

/// One sample of the run, as the CSV has it: one control tick.
struct Sample {
    t_s: f64,
    target: usize,
    /// Base x, y [m] and yaw [rad].
    base: [f64; 3],
    /// Base tilt [rad] at the same tick (`kumi_terms::termination::tilt`).
    tilt_rad: f64,
    tool: Isometry3<f64>,
}

/// A robot that tipped over: during which target, and how long after it was sent [s].
struct TippedOver {
    target: usize,
    after_s: f64,
}

/// What one target came to.
#[derive(serde::Serialize)]
struct Outcome {
    target: [f64; 4],
    position_error_m: f64,
    yaw_error_rad: f64,
    /// Simulated seconds until the tool first came within 0.1 m of the target (`null`: never).
    seconds: Option<f64>,
    /// Simulated seconds until the base tilted past the policy's limit (`null`: it did not).
    tipped_over_after_s: Option<f64>,
}

#[derive(serde::Serialize)]
struct Report {
    robot: String,
    targets: Vec<Outcome>,
    /// Targets not sent: the robot had tipped over and the world could not be reset.
    skipped: usize,
    /// Ticks that did not wait for every node (the nodes' `lockstep_timeouts`, `late_goals`
    /// and `unsynchronised_ticks`): 0 when the run repeats exactly.
    inexact_ticks: u64,
    plot: String,
    csv: String,
    recording: Option<Recording>,
}

/// A run's recording ([`DemoArgs::record`]).
#[derive(serde::Serialize)]
struct Recording {
    file: String,
    topics: Vec<RecordedTopic>,
}

/// Starts recording the run into `<out>/<robot>.mcap`, replacing an earlier run's.
fn start_recording(out: &std::path::Path, robot: &str, domain: u16) -> Result<RecordingThread> {
    let file = crate::record::file_in(out, robot);
    if file.exists() {
        std::fs::remove_file(&file).with_context(|| format!("removing {}", file.display()))?;
    }
    Ok(Recorder::create(robot, domain, &file)?.spawn())
}

/// Stops the recording and says what it holds.
fn finish_recording(recording: RecordingThread) -> Result<Recording> {
    let file = recording.path().to_path_buf();
    let topics = recording.stop()?;
    eprintln!("demo: {}", crate::record::summary(&file, &topics));
    Ok(Recording {
        file: file.display().to_string(),
        topics,
    })
}

/// A target as `/<robot>/goal_pose` takes it; stamped with the simulated time [s] it starts
/// at, or zero (at once).
fn target_msg(target: &Target, frame: &str, starts_at_s: Option<f64>) -> PoseStamped {
    let pose = Isometry3::from_parts(
        target.position_w.into(),
        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), target.yaw),
    );
    PoseStamped {
        header: Header {
            stamp: starts_at_s.map_or_else(Default::default, Time::from_seconds),
            frame_id: frame.to_string(),
        },
        pose: geometry::pose(&pose),
    }
}

pub fn run(args: DemoArgs) -> Result<()> {
    if args.targets == 0 || args.seconds.is_some_and(|s| !(s.is_finite() && s > 0.0)) {
        bail!("--targets and --seconds must be positive");
    }
    let model = load_model(&args.morphology)?;
    let robot = model.name.clone();
    let launch_args = LaunchArgs {
        morphology: args.morphology.clone(),
        robot: Some(robot.clone()),
        lockstep: true,
        engine: args.engine.clone(),
        without: Vec::new(),
        no_whole_body: false,
        policy: args.policy.clone(),
        tilt_limit_rad: args.tilt_limit_rad,
        skill: None,
        backend: Some("tract".into()),
        hardware: None,
        profile: None,
        record: None,
    };
    let policy = launch::check_policy(&model, &launch_args, None)?;
    let (range, tilt_limit_rad, seconds) = match crate::whole_body::trained_task(&policy, &robot)? {
        Some((task, from)) => {
            eprintln!(
                "demo: targets within {} m of the base at heights {}-{} m, {} s each, tipped over past {} rad ({from})",
                task.target_xy_m, task.target_z_m[0], task.target_z_m[1], task.episode_s, task.tilt_limit_rad
            );
            (
                TargetRange {
                    xy_m: task.target_xy_m,
                    z_m: task.target_z_m,
                },
                Some(task.tilt_limit_rad),
                task.episode_s,
            )
        }
        None => {
            eprintln!(
                "demo: {} carries no training task (exported by an older kumi) and kumi ships no config for `{robot}`: targets within 3 m at heights 0.9-1.5 m, 12 s each, and no tilt limit unless --tilt-limit-rad gives one",
                policy.display()
            );
            (
                TargetRange {
                    xy_m: 3.0,
                    z_m: [0.9, 1.5],
                },
                None,
                12.0,
            )
        }
    };
    let tilt_limit_rad = args.tilt_limit_rad.or(tilt_limit_rad);
    let seconds = args.seconds.unwrap_or(seconds);
    let targets = draw_targets(args.targets, args.seed, &range);
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("runs/demo-{robot}")));
    crate::output::ensure_dir(&out)?;
    let domain = args
        .domain
        .unwrap_or(100 + (std::process::id() % 100) as u16);
    let nodes = launch::plan(&model, &launch_args)?;
    eprintln!(
        "demo: `{robot}` on ROS domain {domain} (watch with ROS_DOMAIN_ID={domain} ros2 topic echo /{robot}/tool_pose); nodes log to {}",
        out.join("nodes.log").display()
    );
    let shutdown = Arc::new(AtomicBool::new(false));
    let flag = shutdown.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    let recording = match args.record {
        true => Some(start_recording(&out, &robot, domain)?),
        false => None,
    };
    let mut launched = Launch::start(&nodes, Some(domain), Some(&out.join("nodes.log")))?;
    let result = drive(
        &model,
        &robot,
        domain,
        &targets,
        seconds,
        tilt_limit_rad,
        &shutdown,
        &mut launched,
        recording.as_ref(),
    );
    // The recording ends with the run, before the nodes stop (they go on ticking until then).
    let recording = recording.map(finish_recording).transpose();
    launched.stop(Duration::from_secs(5));
    let recording = recording?;
    report(&robot, &result?, targets.len(), &out, args.json, recording)
}

/// Control ticks per second of simulated time: every stamp is a whole tick.
const TICKS_PER_S: f64 = kumi_model::commands::CONTROL_HZ;

fn tick_of(t_s: f64) -> i64 {
    (t_s * TICKS_PER_S).round() as i64
}

/// When each target of a run is placed, sent for, and judged, in control ticks: target `i`
/// drives the ticks `(start + i n, start + (i + 1) n]` and is placed around where the base
/// stands `lead` ticks before its first (the first target: where the robot stands at `start`).
/// Pure.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Schedule {
    /// The tick at which the first target arrives (simulated time stands still until then).
    start: i64,
    /// Ticks per target.
    n: i64,
    /// Ticks between a later target's placement and its start: time for it to arrive before it
    /// is due, on however loaded a machine.
    lead: i64,
}

impl Schedule {
    fn new(start: i64, seconds: f64) -> Self {
        let n = tick_of(seconds).max(2);
        Self {
            start,
            n,
            lead: (n / 2).min(TICKS_PER_S as i64),
        }
    }

    /// The tick whose state target `i`'s first action is decided on.
    fn begin(&self, i: usize) -> i64 {
        self.start + i as i64 * self.n
    }

    /// The tick of the base pose target `i` is placed around.
    fn placed_at(&self, i: usize) -> i64 {
        if i == 0 {
            self.start
        } else {
            self.begin(i) - self.lead
        }
    }

    /// Seconds from target `i`'s start to `tick`.
    fn after_s(&self, i: usize, tick: i64) -> f64 {
        (tick - self.begin(i)) as f64 / TICKS_PER_S
    }

    /// The target whose actions led to the state of `tick` (`None`: before the first).
    fn target_of(&self, tick: i64) -> Option<usize> {
        (tick > self.start).then(|| ((tick - self.start - 1) / self.n) as usize)
    }
}

/// A run as [`drive`] recorded it.
#[derive(Default)]
struct Driven {
    /// The targets as sent.
    placed: Vec<Target>,
    samples: Vec<Sample>,
    /// Each time the robot tipped over (the world was reset after it).
    tipped: Vec<TippedOver>,
    /// Ticks that did not wait for every node ([`Exactness`]).
    inexact_ticks: u64,
}

/// The demo's node: what it sends, what it watches.
struct Peer<'a> {
    publisher: Publisher<PoseStamped>,
    tool: kumi_ros::StrictSubscription<PoseStamped>,
    odom: kumi_ros::StrictSubscription<Odometry>,
    diagnostics: kumi_ros::StrictSubscription<DiagnosticArray>,
    reset: TriggerClient,
    exactness: Exactness,
    /// Target messages published so far.
    sent: u64,
    /// After a reset, until the first odometry and tool pose of the new world: the tick of the
    /// latest of the old world ([`from_new_world`]; the old world's may still be on their way).
    odom_before_reset: Option<i64>,
    tool_before_reset: Option<i64>,
    frame: String,
    robot: &'a str,
    shutdown: &'a AtomicBool,
    launched: &'a mut Launch,
    // Last: dropped after its publisher and subscriptions.
    node: RosNode,
}

/// One stretch of simulated time without a reset: the targets it drove, the samples, and
/// where it ended if the robot tipped over.
struct Segment {
    placed: Vec<Target>,
    samples: Vec<Sample>,
    /// The target (index into the run's) during which the base tilted past the limit, and the
    /// tick.
    tipped: Option<(usize, i64)>,
}

impl<'a> Peer<'a> {
    fn new(
        robot: &'a str,
        domain: u16,
        shutdown: &'a AtomicBool,
        launched: &'a mut Launch,
    ) -> Result<Self> {
        let mut node = RosNode::new(&format!("/{robot}"), "demo", domain)?;
        Ok(Self {
            publisher: node.publisher(&topics::robot_goal_pose(robot), qos::default())?,
            tool: node.strict_subscription(&topics::tool_pose(robot), qos::default())?,
            odom: node.strict_subscription(&topics::odom(robot), qos::default())?,
            diagnostics: node.strict_subscription(topics::DIAGNOSTICS, qos::default())?,
            reset: node.trigger_client(&topics::reset(robot))?,
            node,
            exactness: Exactness::default(),
            sent: 0,
            odom_before_reset: None,
            tool_before_reset: None,
            frame: topics::odom_frame(robot),
            robot,
            shutdown,
            launched,
        })
    }

    /// Every node up: the whole-body node's and each arm node's outputs are discovered, and a
    /// `recording` records them, this node's targets, the odometry and every module's joint
    /// states.
    fn wait_for_nodes(
        &mut self,
        model: &kumi_model::RobotModel,
        recording: Option<&RecordingThread>,
    ) -> Result<()> {
        let mut outputs = vec![topics::tool_pose(self.robot)];
        for m in model.modules.iter().filter(|m| m.ee_link.is_some()) {
            outputs.push(topics::joint_increments(self.robot, &m.name));
        }
        let mut recorded = outputs.clone();
        recorded.push(topics::robot_goal_pose(self.robot));
        recorded.push(topics::odom(self.robot));
        for m in model.modules.iter().filter(|m| !m.actuators.is_empty()) {
            recorded.push(topics::joint_states(self.robot, &m.name));
        }
        let recording_ready = || {
            recording.is_none_or(|r| {
                let have = r.topics();
                !r.failed() && recorded.iter().all(|t| have.iter().any(|h| &h.topic == t))
            })
        };
        let deadline = Instant::now() + Duration::from_secs(120);
        while outputs.iter().any(|t| self.node.remote_publishers(t) == 0) || !recording_ready() {
            if let Some((name, status)) = self.launched.exited() {
                bail!("node `{name}` exited ({status}) during start-up; see the nodes' log");
            }
            if Instant::now() > deadline || self.shutdown.load(Ordering::Relaxed) {
                bail!("the nodes did not come up within 120 s; see the nodes' log");
            }
            std::thread::sleep(Duration::from_millis(50));
        }
        std::thread::sleep(Duration::from_secs(1));
        Ok(())
    }

    fn check(&mut self) -> Result<()> {
        if self.shutdown.load(Ordering::Relaxed) {
            bail!("interrupted");
        }
        if let Some((name, status)) = self.launched.exited() {
            bail!("node `{name}` exited ({status}); see the nodes' log");
        }
        Ok(())
    }

    fn publish(&mut self, target: &Target, starts_at_s: Option<f64>) {
        let _ = self
            .publisher
            .publish(target_msg(target, &self.frame, starts_at_s));
        self.sent += 1;
    }

    /// Drives `targets` (the run's from index `first` on) from the tick the robot's time stands
    /// at, each placed around the base as [`Schedule`] says; the first is `preplaced` when the
    /// robot already has it. Ends after the last target's ticks, or when the base tilts past
    /// `tilt_limit_rad`.
    fn segment(
        &mut self,
        targets: &[Target],
        first: usize,
        seconds: f64,
        tilt_limit_rad: Option<f64>,
        preplaced: Option<Target>,
        odometry: BTreeMap<i64, BaseSample>,
    ) -> Result<Segment> {
        let mut odometry = odometry;
        // After a reset the new world's time began at its first odometry (the robot has its
        // target and moves at once); before the first target time stands still.
        let start = match preplaced {
            Some(_) => odometry.keys().next().copied(),
            None => {
                self.read(&mut odometry);
                odometry.keys().last().copied()
            }
        };
        let schedule = Schedule::new(start.unwrap_or(0), seconds);
        let end = schedule.begin(targets.len());
        // The tool pose of each tick; odometry is paired with it at the end (the two topics
        // arrive in either order).
        let mut tool_poses: BTreeMap<i64, Isometry3<f64>> = BTreeMap::new();
        let mut placed: Vec<Target> = preplaced.into_iter().collect();
        let mut sent_at = None::<Instant>;
        let mut tipped_at: Option<i64> = None;
        let mut last_sample_at = Instant::now();
        let mut late = std::collections::BTreeSet::new();
        loop {
            self.check()?;
            self.read(&mut odometry);
            if let (None, Some(limit)) = (tipped_at, tilt_limit_rad) {
                tipped_at = odometry
                    .range(schedule.start + 1..=end)
                    .find(|(_, b)| b.tilt_rad > limit)
                    .map(|(k, _)| *k);
            }
            // The next target, once the base pose it is placed around is known.
            let next = placed.len();
            if next < targets.len() && tipped_at.is_none() {
                if let Some(base) = odometry.range(schedule.placed_at(next)..).next() {
                    let xy = [base.1.xy_yaw[0], base.1.xy_yaw[1]];
                    placed.push(place(&targets[next], xy));
                    sent_at = None;
                }
            }
            // The latest target is sent until its ticks begin (a target sent before the
            // whole-body node's subscription is matched would be lost); repeating it changes
            // nothing. The first applies at once, a later one at its stamp.
            let latest = tool_poses.keys().last().copied().unwrap_or(schedule.start);
            if let Some(target) = placed.last().copied() {
                let i = placed.len() - 1;
                let started = schedule.target_of(latest).is_some_and(|t| t >= i);
                if !started && sent_at.is_none_or(|s| s.elapsed() > Duration::from_millis(500)) {
                    let stamp = (i > 0).then(|| schedule.begin(i) as f64 / TICKS_PER_S);
                    self.publish(&target, stamp);
                    sent_at = Some(Instant::now());
                }
            }
            while let Some((tick, pose)) = self.take_tool() {
                let Some(i) = schedule.target_of(tick).filter(|_| tick <= end) else {
                    continue;
                };
                if i >= placed.len() {
                    if late.insert(i) {
                        eprintln!(
                            "target {}: not sent before its time (this process fell behind); it starts late, and this run will not repeat exactly",
                            first + i + 1
                        );
                    }
                    continue;
                }
                tool_poses.insert(tick, pose);
                last_sample_at = Instant::now();
                if tick == schedule.begin(i + 1) {
                    print_outcome(first + i, &placed[i], &pose, schedule.after_s(i, tick));
                }
            }
            let last = tipped_at.unwrap_or(end);
            if tool_poses.range(last..).next().is_some() {
                break;
            }
            if last_sample_at.elapsed() > Duration::from_secs(60) {
                bail!(
                    "no tool pose from the whole-body node for 60 s (target {}); see the nodes' log",
                    first + placed.len()
                );
            }
            std::thread::sleep(Duration::from_millis(1));
        }
        // Every sample's odometry (sent before the tool pose of its tick, but maybe not here).
        let last = tipped_at.unwrap_or(end);
        let waited = Instant::now();
        while odometry.range(last..).next().is_none() && waited.elapsed() < Duration::from_secs(5) {
            std::thread::sleep(Duration::from_millis(1));
            self.read(&mut odometry);
        }
        let samples = tool_poses
            .range(..=last)
            .filter_map(|(&tick, pose)| {
                let i = schedule.target_of(tick)?;
                let base = odometry
                    .range(..=tick)
                    .next_back()
                    .map_or_else(BaseSample::default, |(_, b)| *b);
                Some(Sample {
                    t_s: tick as f64 / TICKS_PER_S,
                    target: first + i,
                    base: base.xy_yaw,
                    tilt_rad: base.tilt_rad,
                    tool: *pose,
                })
            })
            .collect();
        let tipped = tipped_at.and_then(|tick| {
            let i = schedule.target_of(tick)?;
            placed.truncate(i + 1);
            Some((first + i, tick))
        });
        Ok(Segment {
            placed,
            samples,
            tipped,
        })
    }

    /// Takes the odometry (none from the world before a reset) and the nodes' reports waiting.
    fn read(&mut self, odometry: &mut BTreeMap<i64, BaseSample>) {
        self.exactness.read(&self.diagnostics, self.robot);
        while let Some(msg) = self.odom.take() {
            let Ok((m, _)) = msg else { continue };
            let Ok(pose) = geometry::isometry(&m.pose.pose) else {
                continue;
            };
            let tick = tick_of(m.header.stamp.seconds());
            if !from_new_world(&mut self.odom_before_reset, tick) {
                continue;
            }
            let p = pose.translation.vector;
            odometry.insert(
                tick,
                BaseSample {
                    xy_yaw: [p.x, p.y, tool_yaw(&pose.rotation)],
                    tilt_rad: tilt(&pose.rotation),
                },
            );
        }
    }

    /// The next tool pose waiting, by tick (none from the world before a reset).
    fn take_tool(&mut self) -> Option<(i64, Isometry3<f64>)> {
        loop {
            let msg = self.tool.take()?;
            let Ok((m, _)) = msg else { continue };
            let Ok(pose) = geometry::isometry(&m.pose) else {
                continue;
            };
            let tick = tick_of(m.header.stamp.seconds());
            if from_new_world(&mut self.tool_before_reset, tick) {
                return Some((tick, pose));
            }
        }
    }

    /// After the robot tipped over at `tipped_tick`: gives the whole-body node `next` (placed
    /// around the start, where the reset puts the robot), waits until it has taken it, resets
    /// the world (`/<robot>/reset`) and waits for the world's time to go back. Returns the
    /// odometry since the reset; an error when the bridge cannot be reset.
    fn reset_with(&mut self, next: &Target, tipped_tick: i64) -> Result<BTreeMap<i64, BaseSample>> {
        // The node takes the next target before the reset, so that it drives to it from the
        // reset's first tick and not to the target it fell on.
        self.publish(next, None);
        let deadline = Instant::now() + Duration::from_secs(20);
        while self.exactness.targets_accepted < self.sent {
            self.check()?;
            if Instant::now() > deadline {
                bail!("the whole-body node did not report the next target within 20 s");
            }
            self.exactness.read(&self.diagnostics, self.robot);
            std::thread::sleep(Duration::from_millis(5));
        }
        let service = topics::reset(self.robot);
        let answer = self
            .node
            .trigger(&self.reset, &service, Duration::from_secs(20))
            .map_err(anyhow::Error::msg)?;
        if !answer.success {
            bail!("{service}: {}", answer.message);
        }
        eprintln!("demo: {service}: {}", answer.message);
        // Whatever the old world sent after the tip is dropped: its odometry and its tool
        // poses until time went back.
        self.odom_before_reset = Some(tipped_tick);
        self.tool_before_reset = Some(tipped_tick);
        let mut odometry = BTreeMap::new();
        let deadline = Instant::now() + Duration::from_secs(20);
        while odometry.is_empty() {
            self.check()?;
            if Instant::now() > deadline {
                bail!("no odometry from the reset world within 20 s");
            }
            self.read(&mut odometry);
            std::thread::sleep(Duration::from_millis(1));
        }
        Ok(odometry)
    }
}

/// Sends the targets one by one, each placed around where the base stands then, and records
/// the run; returns the targets as sent. In lockstep the run is repeatable: a later target is
/// stamped with the simulated time it starts at (the whole-body node waits for it) and placed
/// around the base as it stood a fixed time before, and every sample pairs the tool pose and
/// the odometry of the same tick. A robot that tilts past `tilt_limit_rad` has tipped over
/// (the whole-body node stops driving it): the world is reset (`/<robot>/reset`) and the
/// remaining targets go on from the start pose.
#[allow(clippy::too_many_arguments)]
fn drive(
    model: &kumi_model::RobotModel,
    robot: &str,
    domain: u16,
    targets: &[Target],
    seconds: f64,
    tilt_limit_rad: Option<f64>,
    shutdown: &AtomicBool,
    launched: &mut Launch,
    recording: Option<&RecordingThread>,
) -> Result<Driven> {
    let mut peer = Peer::new(robot, domain, shutdown, launched)?;
    peer.wait_for_nodes(model, recording)?;
    let mut run = Driven::default();
    let (mut first, mut preplaced, mut odometry) = (0, None, BTreeMap::new());
    // Where the robot starts, and where a reset puts it.
    let mut start_xy = None;
    // Simulated time before the current segment [s] (a reset sets the robot's back to zero).
    let mut offset_s = 0.0;
    loop {
        let mut segment = peer.segment(
            &targets[first..],
            first,
            seconds,
            tilt_limit_rad,
            preplaced.take(),
            std::mem::take(&mut odometry),
        )?;
        let start = *start_xy.get_or_insert_with(|| {
            segment
                .samples
                .first()
                .map_or([0.0, 0.0], |s| [s.base[0], s.base[1]])
        });
        for s in &mut segment.samples {
            s.t_s += offset_s;
        }
        offset_s = segment.samples.last().map_or(offset_s, |s| s.t_s);
        run.placed.extend(segment.placed);
        run.samples.extend(segment.samples);
        let Some((i, tick)) = segment.tipped else {
            break;
        };
        let target_start_s = run
            .samples
            .iter()
            .find(|s| s.target == i)
            .map_or(0.0, |s| s.t_s - 1.0 / TICKS_PER_S);
        let after_s = offset_s - target_start_s;
        let last = run.samples.last().expect("a tipped segment has samples");
        print_outcome(i, &run.placed[i], &last.tool, after_s);
        eprintln!(
            "target {}: the robot tipped over after {after_s:.1} s (tilt {:.3} rad, past the policy's {:.3}); the whole-body node stopped driving it",
            i + 1,
            last.tilt_rad,
            tilt_limit_rad.unwrap_or(f64::NAN),
        );
        run.tipped.push(TippedOver { target: i, after_s });
        first = i + 1;
        let Some(next) = targets.get(first) else {
            break;
        };
        let next = place(next, start);
        match peer.reset_with(&next, tick) {
            Ok(after_reset) => {
                odometry = after_reset;
                preplaced = Some(next);
            }
            Err(e) => {
                eprintln!(
                    "demo: the world could not be reset ({e}); {} more target(s) are not sent",
                    targets.len() - first
                );
                break;
            }
        }
    }
    // Every node's counters once more (each node reports once a second).
    let waited = Instant::now();
    while waited.elapsed() < Duration::from_millis(1200) {
        std::thread::sleep(Duration::from_millis(5));
        peer.exactness.read(&peer.diagnostics, robot);
    }
    peer.exactness.tell();
    run.inexact_ticks = peer.exactness.total();
    Ok(run)
}

/// Whether a message stamped `tick` is from the world after a reset, `before` holding the
/// latest tick of the world before it (`None`: no reset pending). One topic's messages arrive
/// in order, so the first one whose time went back, and every one after it, is the new
/// world's. Pure.
fn from_new_world(before: &mut Option<i64>, tick: i64) -> bool {
    match *before {
        Some(old) if tick >= old => {
            *before = Some(tick);
            false
        }
        Some(_) => {
            *before = None;
            true
        }
        None => true,
    }
}

/// What a run did that breaks its exact repetition, from the nodes' `/diagnostics` counters:
/// steps the bridge ran without a node's command (`lockstep_timeouts`), ticks an arm node acted
/// without its goal (`late_goals`), and ticks the whole-body node acted without every module's
/// state (`unsynchronised_ticks`). All zero: the seeded run repeats exactly.
#[derive(Debug, Default)]
struct Exactness {
    /// Per node (status name): its latest value of each counter.
    counters: BTreeMap<String, BTreeMap<&'static str, u64>>,
    /// The whole-body node's `targets_accepted`, as last reported.
    targets_accepted: u64,
}

const INEXACT_COUNTERS: [&str; 3] = ["lockstep_timeouts", "late_goals", "unsynchronised_ticks"];

impl Exactness {
    fn read(&mut self, sub: &kumi_ros::StrictSubscription<DiagnosticArray>, robot: &str) {
        while let Some(msg) = sub.take() {
            let Ok((array, _)) = msg else { continue };
            for status in array.status {
                let id = &status.hardware_id;
                if id != robot && !id.starts_with(&format!("{robot}/")) {
                    continue;
                }
                if id == robot && status.name.starts_with("kumi whole-body node") {
                    if let Some(kv) = status.values.iter().find(|kv| kv.key == "targets_accepted") {
                        self.targets_accepted = kv.value.parse().unwrap_or(0);
                    }
                }
                let mine = self.counters.entry(status.name.clone()).or_default();
                for kv in &status.values {
                    if let Some(key) = INEXACT_COUNTERS.iter().find(|k| **k == kv.key) {
                        mine.insert(key, kv.value.parse().unwrap_or(0));
                    }
                }
            }
        }
    }

    fn total(&self) -> u64 {
        self.counters.values().flat_map(|c| c.values()).sum()
    }

    fn tell(&self) {
        if self.total() == 0 {
            return;
        }
        for (node, counters) in &self.counters {
            for (key, n) in counters.iter().filter(|(_, n)| **n > 0) {
                eprintln!("demo: {node}: {key} {n}");
            }
        }
        eprintln!("demo: some ticks did not wait for every node (above; a message came later than the lockstep timeouts allow, on a loaded machine): this run will not repeat exactly");
    }
}

fn print_outcome(i: usize, target: &Target, tool: &Isometry3<f64>, after_s: f64) {
    let (p, y) = target_errors(tool, target);
    eprintln!(
        "target {}: ({:.2}, {:.2}, {:.2}) m, yaw {:.2} rad -> tool {p:.3} m and {y:.2} rad away after {after_s:.1} s",
        i + 1,
        target.position_w.x,
        target.position_w.y,
        target.position_w.z,
        target.yaw,
    );
}

/// The base as one odometry message has it: x, y [m] and yaw [rad] in `<robot>/odom`, and its
/// tilt [rad].
#[derive(Debug, Clone, Copy, Default)]
struct BaseSample {
    xy_yaw: [f64; 3],
    tilt_rad: f64,
}

/// Writes the CSV and the plot; prints the table (or the JSON object).
fn report(
    robot: &str,
    run: &Driven,
    drawn: usize,
    out: &std::path::Path,
    json: bool,
    recording: Option<Recording>,
) -> Result<()> {
    let (targets, samples, tipped) = (&run.placed, &run.samples, &run.tipped);
    let csv_path = out.join("run.csv");
    let mut csv = String::from(
        "t_s,target,target_x_m,target_y_m,target_z_m,target_yaw_rad,base_x_m,base_y_m,base_yaw_rad,base_tilt_rad,tool_x_m,tool_y_m,tool_z_m,tool_yaw_rad,position_error_m,yaw_error_rad\n",
    );
    let mut outcomes = Vec::new();
    for (i, target) in targets.iter().enumerate() {
        let mine: Vec<&Sample> = samples.iter().filter(|s| s.target == i).collect();
        // The target's start: one tick before its first sample.
        let start = mine.first().map_or(0.0, |s| s.t_s - 1.0 / TICKS_PER_S);
        let mut reached = None;
        for s in &mine {
            let (p, y) = target_errors(&s.tool, target);
            if p < 0.1 && reached.is_none() {
                reached = Some(s.t_s - start);
            }
            let t = s.tool.translation.vector;
            csv.push_str(&format!(
                "{:.4},{},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4},{:.4}\n",
                s.t_s,
                i + 1,
                target.position_w.x,
                target.position_w.y,
                target.position_w.z,
                target.yaw,
                s.base[0],
                s.base[1],
                s.base[2],
                s.tilt_rad,
                t.x,
                t.y,
                t.z,
                tool_yaw(&s.tool.rotation),
                p,
                y
            ));
        }
        let (p, y) = mine
            .last()
            .map_or((f64::NAN, f64::NAN), |s| target_errors(&s.tool, target));
        outcomes.push(Outcome {
            target: [
                target.position_w.x,
                target.position_w.y,
                target.position_w.z,
                target.yaw,
            ],
            position_error_m: p,
            yaw_error_rad: y,
            seconds: reached,
            tipped_over_after_s: tipped.iter().find(|t| t.target == i).map(|t| t.after_s),
        });
    }
    std::fs::write(&csv_path, csv).with_context(|| format!("writing {}", csv_path.display()))?;
    let svg_path = out.join("run.svg");
    let svg = plot::top_down(
        &format!("kumi demo: {robot}, top view"),
        &[
            plot::Path {
                label: "base".into(),
                colour: plot::GREY,
                points: samples.iter().map(|s| [s.base[0], s.base[1]]).collect(),
            },
            plot::Path {
                label: "tool".into(),
                colour: plot::SERIES[0],
                points: samples
                    .iter()
                    .map(|s| [s.tool.translation.x, s.tool.translation.y])
                    .collect(),
            },
        ],
        &targets
            .iter()
            .enumerate()
            .map(|(i, t)| plot::Mark {
                label: format!("{}", i + 1),
                xy: [t.position_w.x, t.position_w.y],
                yaw: t.yaw,
            })
            .collect::<Vec<_>>(),
    );
    std::fs::write(&svg_path, svg).with_context(|| format!("writing {}", svg_path.display()))?;
    let report = Report {
        robot: robot.to_string(),
        targets: outcomes,
        skipped: drawn - targets.len(),
        inexact_ticks: run.inexact_ticks,
        plot: svg_path.display().to_string(),
        csv: csv_path.display().to_string(),
        recording,
    };
    if json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        println!("| target | x, y, z [m] | yaw [rad] | final position error [m] | final yaw error [rad] | within 0.1 m after [s] | tipped over after [s] |");
        println!("|---|---|---|---|---|---|---|");
        for (i, o) in report.targets.iter().enumerate() {
            println!(
                "| {} | {:.2}, {:.2}, {:.2} | {:.2} | {:.3} | {:.2} | {} | {} |",
                i + 1,
                o.target[0],
                o.target[1],
                o.target[2],
                o.target[3],
                o.position_error_m,
                o.yaw_error_rad,
                o.seconds.map_or("never".into(), |s| format!("{s:.1}")),
                o.tipped_over_after_s
                    .map_or("-".into(), |s| format!("{s:.1}"))
            );
        }
        if report.skipped > 0 {
            println!(
                "{} target(s) not sent: the robot had tipped over and the world could not be reset",
                report.skipped
            );
        }
        println!("plot: {}\ncsv: {}", report.plot, report.csv);
        if let Some(r) = &report.recording {
            println!("recording: {}", r.file);
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn targets_are_seeded_and_inside_the_trained_range() {
        let range = TargetRange {
            xy_m: 3.0,
            z_m: [0.9, 1.5],
        };
        let a = draw_targets(20, 4, &range);
        assert_eq!(a.len(), 20);
        assert!(a.iter().all(|t| t.position_w.x.abs() <= 3.0
            && t.position_w.y.abs() <= 3.0
            && (0.9..1.5).contains(&t.position_w.z)
            && t.yaw.abs() <= PI));
        let b = draw_targets(20, 4, &range);
        assert_eq!(a[7].position_w, b[7].position_w);
        assert_ne!(draw_targets(1, 5, &range)[0].position_w, a[0].position_w);
    }

    #[test]
    fn each_target_has_its_ticks_and_is_placed_before_them() {
        let s = Schedule::new(0, 12.0);
        assert_eq!((s.n, s.lead), (360, 30));
        assert_eq!((s.begin(0), s.begin(1), s.begin(3)), (0, 360, 1080));
        assert_eq!((s.placed_at(0), s.placed_at(1)), (0, 330));
        // The state at tick 0 is the start, before the first target's first action; the state
        // at a target's first tick is the previous target's last.
        assert_eq!(s.target_of(0), None);
        assert_eq!(s.target_of(1), Some(0));
        assert_eq!(s.target_of(360), Some(0));
        assert_eq!(s.target_of(361), Some(1));
        let short = Schedule::new(5, 0.01);
        assert_eq!((short.n, short.lead), (2, 1), "at least two ticks a target");
        assert_eq!(short.target_of(7), Some(0));
    }

    #[test]
    fn after_a_reset_only_messages_from_after_time_went_back_count() {
        let mut before = Some(57);
        assert!(!from_new_world(&mut before, 57));
        assert!(
            !from_new_world(&mut before, 300),
            "the old world ran on after the tip"
        );
        assert!(from_new_world(&mut before, 0), "time went back");
        assert!(
            from_new_world(&mut before, 400),
            "and the new world's time runs on"
        );
        assert_eq!(before, None);
    }

    #[test]
    fn each_target_is_placed_around_where_the_base_stands() {
        let offset = Target {
            position_w: Vector3::new(2.5, -3.0, 1.2),
            yaw: 0.4,
        };
        let t = place(&offset, [4.0, 1.0]);
        assert_eq!(t.position_w, Vector3::new(6.5, -2.0, 1.2));
        assert_eq!(t.yaw, 0.4);
        // However far the robot has gone, the target is as far from it as training's are
        // from a base starting at the origin: within the whole-body node's 4.5 m.
        let range = TargetRange {
            xy_m: 3.0,
            z_m: [0.9, 1.5],
        };
        for offset in draw_targets(200, 11, &range) {
            let t = place(&offset, [-7.0, 5.0]);
            let d = (t.position_w.x + 7.0).hypot(t.position_w.y - 5.0);
            assert!(d <= 3.0 * 2f64.sqrt() && d < 4.5, "{d}");
        }
    }
}
