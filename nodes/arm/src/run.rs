//! The ROS 2 shell of the arm-module node: subscriptions in, [`ArmController`] in the middle,
//! commands and the tool pose out.
//!
//! Timing is [`Schedule`]'s. Joint states older than `stale_after_s` (by their stamp in sim
//! time, by their arrival in wall time) make it hold.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use kumi_model::{Actuator, RobotModel};
use kumi_msgs::builtin_interfaces::Time;
use kumi_msgs::diagnostic_msgs::DiagnosticArray;
use kumi_msgs::geometry_msgs::PoseStamped;
use kumi_msgs::rosgraph_msgs::Clock;
use kumi_msgs::sensor_msgs::JointState;
use kumi_msgs::std_msgs::{Float64MultiArray, Header};
use kumi_policies::kinematics::ToolKinematics;
use kumi_policies::observation::{BASE_DIM, JOINTS};
use kumi_policies::skill::{ArmSkill, SkillError};
use kumi_ros::parameters::{ParameterValue, Settings};
use kumi_ros::{geometry, qos, topics, RateLimited, RosError, RosNode, StrictSubscription};
use kumi_runtime::{BackendChoice, RuntimeError, SkillPolicy};
use nalgebra::Isometry3;
use ros2_client::Publisher;
use tracing::{debug, info, warn};

use crate::controller::{ArmController, Hold};
use crate::goal::GoalRules;
use crate::joints;
use crate::report::Report;
use crate::schedule::{GoalSync, Schedule, SimClock, Sync};

/// What the node publishes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Output {
    /// `joint_increments` (`std_msgs/Float64MultiArray`), for the sim bridge.
    Increments,
    /// `joint_set` (`sensor_msgs/JointState`, absolute targets), for MoonBot's Motion Stack.
    JointSet,
}

/// Where the node's time comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ClockSource {
    /// Sim time once a `/<robot>/clock` message arrives, wall time until then.
    Auto,
    Sim,
    Wall,
}

#[derive(Debug, Clone)]
pub struct ArmNodeConfig {
    pub model: Arc<RobotModel>,
    /// The robot's namespace (`/<robot>/...`).
    pub robot: String,
    /// The arm module this node drives.
    pub module: String,
    pub policy: PathBuf,
    pub backend: BackendChoice,
    pub output: Output,
    pub domain_id: u16,
    pub clock: ClockSource,
    /// Joint states older than this [s] make the node hold.
    pub stale_after_s: f64,
    /// How long to listen for another node already commanding this module before starting.
    pub duplicate_check: Duration,
    /// In sim time, wait up to this long [s, wall] for the goal stamped with a joint state's
    /// stamp before acting on that joint state ([`GoalSync`]; 0: act on the latest goal at
    /// once). Set when a whole-body node sends the goals.
    pub goal_sync_s: f64,
    /// MoonBot hardware (Motion Stack): joint states from the limb's `joint_read` (published
    /// only on change: a still joint is not stale while the limb's publisher is alive), absolute
    /// targets on its `joint_set`, joint names as the profile maps them. Forces
    /// [`Output::JointSet`].
    pub hardware: Option<Arc<kumi_ros::motion_stack::MotionStackProfile>>,
    /// With goal sync: send nothing before the first goal (lockstep bring-up with a whole-body
    /// node: simulated time stands still until the robot has a target).
    pub wait_for_first_goal: bool,
}

#[derive(Debug, thiserror::Error)]
pub enum ArmNodeError {
    #[error("robot `{robot}` has no module `{module}` (its modules: {known})")]
    UnknownModule {
        robot: String,
        module: String,
        known: String,
    },
    #[error(transparent)]
    Skill(#[from] SkillError),
    #[error(transparent)]
    Policy(#[from] RuntimeError),
    #[error(transparent)]
    Ros(#[from] RosError),
    #[error("kinematics: {0}")]
    Kinematics(String),
    #[error("another node already commands module `{module}` of robot `{robot}` (its commands arrive on {topic}); stop it first, or give this robot another name with --robot")]
    Duplicate {
        robot: String,
        module: String,
        topic: String,
    },
}

/// Everything a node needs that is not ROS: checked before any ROS entity is created, so a bad
/// module, policy or model fails fast with its own message.
pub struct Prepared {
    pub controller: ArmController,
    /// The skill observes how far its targets lead the joints, so the node must hold them
    /// ([`Output::JointSet`]).
    pub reads_targets: bool,
    pub rules: GoalRules,
    kinematics: ToolKinematics,
    base_frame: String,
    control_hz: f64,
}

impl Prepared {
    pub fn new(config: &ArmNodeConfig) -> Result<Self, ArmNodeError> {
        let model = &config.model;
        let module = model
            .module(&config.module)
            .ok_or_else(|| ArmNodeError::UnknownModule {
                robot: model.name.clone(),
                module: config.module.clone(),
                known: model
                    .modules
                    .iter()
                    .map(|m| m.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            })?;
        let control_hz = kumi_model::commands::CONTROL_HZ;
        let skill = ArmSkill::new(module, control_hz)?;
        let mut policy = SkillPolicy::load(&config.policy, &skill, config.backend)?;
        let reads_targets = policy.observation_dim() > BASE_DIM;
        info!(
            "{}: policy {} ({} backend)",
            config.module,
            config.policy.display(),
            policy.backend()
        );
        let kinematics = ToolKinematics::new(model, module).map_err(ArmNodeError::Kinematics)?;
        let reach = crate::goal::reach_m(&kinematics);
        let actuators: Vec<Actuator> = module.position_joints().cloned().collect();
        Ok(Self {
            controller: ArmController::new(
                skill,
                actuators,
                {
                    let kinematics = kinematics.clone();
                    Box::new(move |q| kinematics.tool_pose_b(q))
                },
                Box::new(move |obs| policy.act(obs).map_err(|e| e.to_string())),
                config.stale_after_s,
            ),
            reads_targets,
            rules: GoalRules {
                // The module's base frame as `/tf` names it (empty: the same, by convention).
                frames: vec![topics::frame(&config.robot, &module.root_link)],
                reach,
            },
            base_frame: topics::frame(&config.robot, &module.root_link),
            kinematics,
            control_hz,
        })
    }

    /// The tool pose [m] in the module's base frame for joint angles `q` [rad].
    pub fn tool_pose_b(&self, q: &[f64; JOINTS]) -> Isometry3<f64> {
        self.kinematics.tool_pose_b(q)
    }
}

struct Io {
    goal: StrictSubscription<PoseStamped>,
    joint_states: StrictSubscription<JointState>,
    clock: StrictSubscription<Clock>,
    increments: Option<Publisher<Float64MultiArray>>,
    joint_set: Option<Publisher<JointState>>,
    ee_pose: Publisher<PoseStamped>,
    diagnostics: Publisher<DiagnosticArray>,
}

/// The writers of the messages waiting on `sub` (the messages are dropped).
/// Messages taken per subscription per loop: a flood cannot keep the node from acting.
const MAX_TAKEN: usize = 1000;

/// The node's settings, as its read-only ROS parameters
/// (`ros2 param list /<robot>/<module>/arm_node`).
fn settings(config: &ArmNodeConfig, output: Output) -> Settings {
    use ParameterValue::{Boolean, Double, String as Text};
    let mut s = Settings::new();
    s.insert("robot".into(), Text(config.robot.clone()));
    s.insert("module".into(), Text(config.module.clone()));
    s.insert("morphology".into(), Text(config.model.name.clone()));
    let fingerprint = kumi_policies::metadata::fingerprint_bytes;
    kumi_ros::parameters::file(&mut s, "policy", &config.policy, fingerprint);
    s.insert(
        "backend".into(),
        Text(format!("{:?}", config.backend).to_lowercase()),
    );
    s.insert("output".into(), Text(format!("{output:?}").to_lowercase()));
    s.insert(
        "clock".into(),
        Text(format!("{:?}", config.clock).to_lowercase()),
    );
    s.insert("stale_after_s".into(), Double(config.stale_after_s));
    s.insert("goal_sync_s".into(), Double(config.goal_sync_s));
    s.insert(
        "wait_for_first_goal".into(),
        Boolean(config.wait_for_first_goal),
    );
    s.insert("hardware".into(), Boolean(config.hardware.is_some()));
    s
}

/// Publishes the node's diagnostics once a second.
fn publish_report(
    io: &Io,
    report_at: &mut Instant,
    report: &Report,
    robot: &str,
    module: &str,
    now: f64,
) {
    if report_at.elapsed() >= Duration::from_secs(1) {
        *report_at = Instant::now();
        let _ = io.diagnostics.publish(DiagnosticArray {
            header: Header {
                stamp: Time::from_seconds(now),
                frame_id: String::new(),
            },
            status: vec![report.status(robot, module)],
        });
    }
}

/// Runs the node until `shutdown` is set.
pub fn run(config: ArmNodeConfig, shutdown: Arc<AtomicBool>) -> Result<(), ArmNodeError> {
    let mut prepared = Prepared::new(&config)?;
    let (robot, module) = (config.robot.as_str(), config.module.as_str());
    let mut node = RosNode::new(&format!("/{robot}/{module}"), "arm_node", config.domain_id)?;
    let _rosout = kumi_ros::rosout::attach(
        &mut node,
        &kumi_ros::rosout::logger_name(&format!("/{robot}/{module}"), "arm_node"),
    )?;
    let hardware = config.hardware.as_deref();
    let output = if hardware.is_some() || prepared.reads_targets {
        Output::JointSet
    } else {
        config.output
    };
    if output != config.output {
        info!(
            "{module}: sending absolute targets on joint_set: the node holds the targets its skill observes"
        );
    }
    let output_topic = match (hardware, output) {
        (Some(profile), _) => profile.joint_set(module),
        (None, Output::Increments) => topics::joint_increments(robot, module),
        (None, Output::JointSet) => topics::joint_set(robot, module),
    };
    let joint_states_topic = match hardware {
        Some(profile) => profile.joint_read(module),
        None => topics::joint_states(robot, module),
    };
    // The skill's joints as the joint states and targets name them.
    let joint_names: Vec<String> = prepared
        .controller
        .skill()
        .joints
        .iter()
        .map(|j| hardware.map_or_else(|| j.clone(), |p| p.joint_name(module, j)))
        .collect();
    let duplicate = || ArmNodeError::Duplicate {
        robot: robot.to_string(),
        module: module.to_string(),
        topic: output_topic.clone(),
    };
    let io = Io {
        goal: node.strict_subscription(&topics::goal_pose(robot, module), qos::default())?,
        joint_states: node.strict_subscription(&joint_states_topic, qos::default())?,
        clock: node.strict_subscription(&topics::robot_clock(robot), qos::default())?,
        increments: match output {
            Output::Increments => Some(node.publisher(&output_topic, qos::default())?),
            Output::JointSet => None,
        },
        joint_set: match output {
            Output::JointSet => Some(node.publisher(&output_topic, qos::default())?),
            Output::Increments => None,
        },
        ee_pose: node.publisher(&topics::ee_pose(robot, module), qos::default())?,
        diagnostics: node.publisher(topics::DIAGNOSTICS, qos::default())?,
    };
    let own = match (&io.increments, &io.joint_set) {
        (Some(p), _) => p.gid(),
        (_, Some(p)) => p.gid(),
        _ => unreachable!("one output publisher exists"),
    };
    // Another node commanding this module now: refuse to be the second. (One that DDS still
    // lists but that sends nothing, such as a node killed with SIGKILL, is no reason to.)
    let others = match output {
        Output::Increments => {
            node.others_publish::<Float64MultiArray>(&output_topic, own, config.duplicate_check)?
        }
        Output::JointSet => {
            node.others_publish::<JointState>(&output_topic, own, config.duplicate_check)?
        }
    };
    if others {
        return Err(duplicate());
    }
    // The writers on the output already known (those of killed nodes among them): only a
    // writer that appears later is another sender of this module's commands.
    let mut known_writers = node.remote_writers(&output_topic);
    let mut writers_at = Instant::now();
    let parameters = node.parameter_services(settings(&config, output))?;
    info!(
        "arm node up: /{robot}/{module}, joint states from {joint_states_topic}, output {output:?} on {output_topic}, clock {:?}, domain {}",
        config.clock,
        node.domain_id()
    );

    let start = Instant::now();
    let mut schedule = Schedule::new(prepared.control_hz);
    let mut clock = SimClock::default();
    let mut log = RateLimited::new(Duration::from_secs(1));
    let mut hold_log = RateLimited::new(Duration::from_secs(2));
    let mut goal_log = RateLimited::new(Duration::from_secs(1));
    let mut latest_stamp = Time::default();
    let mut goal_sync = GoalSync::new(config.goal_sync_s);
    let mut goal_stamp: Option<f64> = None;
    // Ticks in a row acted on without their goal: warned once per run of them.
    let mut late_in_row: u64 = 0;
    let mut report = Report::default();
    let mut report_at = Instant::now();
    let mut liveliness_at = Instant::now();

    while !shutdown.load(Ordering::Relaxed) {
        parameters.poll();
        // Someone who started commanding this module later (a second arm node refuses to
        // start when it hears this one; `ros2 topic pub` does not), as discovery finds them.
        if writers_at.elapsed() >= Duration::from_secs(1) {
            writers_at = Instant::now();
            for writer in node.remote_writers(&output_topic) {
                if known_writers.insert(writer) {
                    warn!("{module}: another publisher also sends this module's commands on {output_topic}");
                }
            }
        }
        for taken in (0..MAX_TAKEN).map_while(|_| io.clock.take()) {
            let c = match taken {
                Ok((c, _)) => c,
                Err(why) => {
                    report.malformed += 1;
                    if log.check(Instant::now()).is_some() {
                        warn!("{module}: refused a malformed clock message: {why}");
                    }
                    continue;
                }
            };
            if config.clock == ClockSource::Wall {
                continue;
            }
            let t = c.clock.seconds();
            if let Some(before) = clock.clock(t) {
                // A new simulator: what was measured in the old one's time means nothing now.
                info!("{module}: sim time went back from {before:.3} s to {t:.3} s (a restarted simulator); starting over from its next joint state");
                report.sim_restarts += 1;
                schedule.forget();
                prepared.controller.forget_state();
                // A goal stamped on the old clock is not the new world's: the next goal is
                // (with --wait-for-first-goal the node waits for it, as at start-up).
                if goal_stamp.is_some_and(|g| g > t) {
                    goal_stamp = None;
                }
            }
        }
        let sim = match config.clock {
            ClockSource::Sim => true,
            ClockSource::Wall => false,
            ClockSource::Auto => clock.now_s().is_some(),
        };
        if schedule.use_sim_time(sim) {
            // A joint state stamped in the other time base would look ages old (or new).
            prepared.controller.forget_state();
            if sim {
                info!("{module}: using sim time from /{robot}/clock");
            }
        }
        let wall_now = start.elapsed().as_secs_f64();

        for _ in 0..MAX_TAKEN {
            match io.goal.take() {
                Some(Ok((msg, _))) => match prepared.rules.accept(&msg) {
                    Ok(goal) => {
                        report.goals_accepted += 1;
                        let p = goal.position_b;
                        match goal_log.check(Instant::now()) {
                            Some(0) => info!(
                                "{module}: new goal at ({:.3}, {:.3}, {:.3}) m",
                                p.x, p.y, p.z
                            ),
                            Some(n) => info!(
                                "{module}: new goal at ({:.3}, {:.3}, {:.3}) m ({n} more in the last second)",
                                p.x, p.y, p.z
                            ),
                            None => debug!(
                                "{module}: new goal at ({:.3}, {:.3}, {:.3}) m",
                                p.x, p.y, p.z
                            ),
                        }
                        goal_stamp = Some(msg.header.stamp.seconds());
                        prepared.controller.set_goal(goal);
                    }
                    Err(why) => {
                        report.goals_rejected += 1;
                        if let Some(n) = log.check(Instant::now()) {
                            warn!("{module}: goal rejected: {why} ({n} more suppressed)");
                        }
                    }
                },
                None => break,
                Some(Err(why)) => {
                    report.malformed += 1;
                    if log.check(Instant::now()).is_some() {
                        warn!("{module}: refused a malformed goal: {why}");
                    }
                }
            }
        }
        for _ in 0..MAX_TAKEN {
            match io.joint_states.take() {
                Some(Ok((msg, _))) => match joints::read(&msg, module, &joint_names) {
                    Ok(j) => {
                        let t = if sim {
                            msg.header.stamp.seconds()
                        } else {
                            wall_now
                        };
                        if sim {
                            clock.stamp(t);
                        }
                        schedule.joint_state(t);
                        latest_stamp = msg.header.stamp;
                        prepared.controller.set_joints(j, t);
                    }
                    Err(why) => {
                        report.joint_states_rejected += 1;
                        if let Some(n) = log.check(Instant::now()) {
                            warn!("{module}: joint state rejected: {why} ({n} more suppressed)");
                        }
                    }
                },
                None => break,
                Some(Err(why)) => {
                    report.malformed += 1;
                    if log.check(Instant::now()).is_some() {
                        warn!("{module}: refused a malformed joint state: {why}");
                    }
                }
            }
        }
        // After the joint states: in sim time, their stamps may have moved the clock on.
        let now = if sim {
            clock.now_s().unwrap_or(0.0)
        } else {
            wall_now
        };

        // Motion Stack publishes `joint_read` only on change: while the limb's publisher is
        // alive, its last joint state still holds (a still joint is not a stale one).
        if hardware.is_some() && !sim && liveliness_at.elapsed() >= Duration::from_millis(100) {
            liveliness_at = Instant::now();
            if node.remote_publishers(&joint_states_topic) > 0 {
                if let Some((j, _)) = prepared.controller.joints().copied() {
                    prepared.controller.set_joints(j, wall_now);
                }
            }
        }
        let measured_at = prepared.controller.joints().map(|(_, t)| *t);
        if config.wait_for_first_goal && goal_stamp.is_none() {
            // Nothing is commanded before the first goal.
            publish_report(&io, &mut report_at, &report, robot, module, now);
            std::thread::sleep(Duration::from_micros(200));
            continue;
        }
        if config.goal_sync_s > 0.0 && sim && schedule.fresh() {
            if let Some(t) = measured_at {
                match goal_sync.check(t, goal_stamp, wall_now) {
                    Sync::Wait => {
                        publish_report(&io, &mut report_at, &report, robot, module, now);
                        std::thread::sleep(Duration::from_micros(100));
                        continue;
                    }
                    Sync::Late => {
                        report.late_goals += 1;
                        late_in_row += 1;
                        if late_in_row == 1 {
                            warn!("{module}: no goal for the tick at {t:.3} s within {:.3} s; acting on the previous one until goals come again (each such tick counts in late_goals on /diagnostics)", config.goal_sync_s);
                        }
                    }
                    Sync::Ready => {
                        if late_in_row > 0 {
                            info!("{module}: goals are back after {late_in_row} ticks without one");
                            late_in_row = 0;
                        }
                    }
                }
            }
        }
        if schedule.due(now, measured_at) {
            let cmd = prepared.controller.step(now);
            report.step(cmd.hold.as_ref());
            let warning = match &cmd.hold {
                Some(Hold::Stale { age_s }) => {
                    Some(format!("joint states are {age_s:.2} s old; holding"))
                }
                Some(Hold::PolicyFailed(e)) => Some(format!("policy failed ({e}); holding")),
                Some(h) => {
                    debug!("{module}: holding: {h:?}");
                    None
                }
                None => None,
            };
            if let Some(w) = warning {
                if hold_log.check(Instant::now()).is_some() {
                    warn!("{module}: {w}");
                }
            }
            if let Some(targets) = cmd.targets {
                if let Some(p) = &io.increments {
                    let _ = p.publish(Float64MultiArray::vector("joints", cmd.increments.to_vec()));
                }
                if let Some(p) = &io.joint_set {
                    let _ = p.publish(JointState {
                        header: Header {
                            stamp: Time::from_seconds(now),
                            frame_id: String::new(),
                        },
                        name: joint_names.clone(),
                        position: targets.to_vec(),
                        velocity: Vec::new(),
                        effort: Vec::new(),
                    });
                }
            }
            if let Some((j, _)) = prepared.controller.joints() {
                let pose = prepared.tool_pose_b(&j.q);
                let _ = io.ee_pose.publish(PoseStamped {
                    header: Header {
                        stamp: latest_stamp,
                        frame_id: prepared.base_frame.clone(),
                    },
                    pose: geometry::pose(&pose),
                });
            }
        }
        publish_report(&io, &mut report_at, &report, robot, module, now);
        std::thread::sleep(Duration::from_micros(200));
    }
    info!("arm node /{robot}/{module} stopping");
    Ok(())
}
