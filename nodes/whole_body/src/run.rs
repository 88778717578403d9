//! The ROS 2 shell of the whole-body node: the target, odometry and joint states in,
//! [`WholeBodyController`] in the middle, each arm module's goal and each wheel module's
//! velocity out.
//!
//! **Timing.** The node decides once per tick, on the tick's complete state ([`Tick`]), and
//! stamps every goal with that tick's stamp. Arm nodes started with a goal wait (`kumi arm
//! --goal-sync`) act on a tick's joint states only with the goal computed from the same tick,
//! so in lockstep the skill acts on the goal the upper policy chose from the same state, as in
//! training.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use kumi_model::commands::wheel_joint_velocities;
use kumi_model::RobotModel;
use kumi_msgs::builtin_interfaces::Time;
use kumi_msgs::diagnostic_msgs::DiagnosticArray;
use kumi_msgs::geometry_msgs::PoseStamped;
use kumi_msgs::nav_msgs::Odometry;
use kumi_msgs::sensor_msgs::JointState;
use kumi_msgs::std_msgs::{Float64, Header};
use kumi_ros::motion_stack::MotionStackProfile;
use kumi_ros::parameters::{ParameterValue, Settings};
use kumi_ros::{geometry, qos, topics, RateLimited, RosError, RosNode, StrictSubscription};
use kumi_runtime::{BackendChoice, ModelFile, RuntimeError, WholeBodyPolicy};
use kumi_terms::{ActionTerms, GoalBounds, ObservationOptions, Target};
use nalgebra::Vector3;
use ros2_client::Publisher;
use tracing::{debug, info, warn};

use crate::controller::{Decision, Hold, WholeBodyController};
use crate::report::Report;
use crate::steering::SteeringRates;
use crate::target;
use crate::tick::{BaseState, Due, ModuleState, Tick};

#[derive(Debug, Clone)]
pub struct WholeBodyNodeConfig {
    pub model: Arc<RobotModel>,
    /// The robot's namespace (`/<robot>/...`).
    pub robot: String,
    /// The whole-body policy (ONNX with its contract).
    pub policy: PathBuf,
    /// The skill the arm nodes run: the policy must have been trained over it.
    pub skill: PathBuf,
    pub backend: BackendChoice,
    pub domain_id: u16,
    /// Inputs older than this [s, wall] make the node hold.
    pub stale_after_s: f64,
    /// The sim bridge runs in lockstep (simulated time stands still until this node answers):
    /// wait for every module's joint states of a tick however long it takes, and never hold
    /// for inputs old only in wall time. Otherwise the node waits one control period for them
    /// and holds on inputs older than `stale_after_s`.
    pub lockstep: bool,
    /// Targets further than this [m] from the base (horizontally) are refused.
    pub max_target_distance_m: f64,
    /// How long to listen for another whole-body node of the same robot before starting.
    pub duplicate_check: Duration,
    /// Base tilt [rad] past which the node stops driving until a new target: the tilt that
    /// ended the policy's training episodes (none: it never stops).
    pub tilt_limit_rad: Option<f64>,
    /// MoonBot hardware (Motion Stack): each module's joint states from its limb's lazy
    /// `joint_read`, the base odometry from the profile's topic, wheel velocities as
    /// `sensor_msgs/JointState` velocities on each wheel limb's `joint_set`.
    pub hardware: Option<Arc<MotionStackProfile>>,
}

#[derive(Debug, thiserror::Error)]
pub enum WholeBodyNodeError {
    #[error("reading {path}: {error}")]
    Read { path: String, error: std::io::Error },
    #[error("{path}: {message}")]
    Policy { path: String, message: String },
    #[error(transparent)]
    Runtime(#[from] RuntimeError),
    #[error(transparent)]
    Ros(#[from] RosError),
    #[error("robot `{robot}`: {message}")]
    Robot { robot: String, message: String },
    #[error("another whole-body node already drives robot `{robot}` (it publishes {topic}); stop it first, or give this robot another name with --robot")]
    Duplicate { robot: String, topic: String },
}

/// Loads the policy and checks it against the robot and the skill: the goal bounds come from
/// the policy's own action description, and the whole contract must match.
pub fn prepare(config: &WholeBodyNodeConfig) -> Result<WholeBodyController, WholeBodyNodeError> {
    let read = |path: &PathBuf| {
        std::fs::read(path).map_err(|error| WholeBodyNodeError::Read {
            path: path.display().to_string(),
            error,
        })
    };
    let skill = read(&config.skill)?;
    let bytes = read(&config.policy)?;
    let label = config.policy.display().to_string();
    let policy_error = |message: String| WholeBodyNodeError::Policy {
        path: label.clone(),
        message,
    };
    let file = ModelFile::decode(bytes.clone())
        .map_err(|e| policy_error(format!("not an ONNX model: {e}")))?;
    let description = file
        .metadata
        .get(kumi_terms::contract::ACTION)
        .ok_or_else(|| {
            policy_error(format!(
                "metadata `{}` is missing: not a kumi whole-body policy",
                kumi_terms::contract::ACTION
            ))
        })?;
    let bounds =
        GoalBounds::from_description(description).map_err(|e| policy_error(e.to_string()))?;
    let robot_error = |message: String| WholeBodyNodeError::Robot {
        robot: config.model.name.clone(),
        message,
    };
    let terms = ActionTerms::new(&config.model, &bounds).map_err(|e| robot_error(e.to_string()))?;
    let options = file
        .metadata
        .get(kumi_policies::metadata::OBSERVATION)
        .map(|d| ObservationOptions::from_description(d))
        .unwrap_or_default();
    let expected = kumi_terms::contract::contract(
        &config.model,
        &terms,
        options,
        &skill,
        kumi_model::commands::CONTROL_HZ,
    );
    let mut policy = WholeBodyPolicy::from_bytes(bytes, &label, &expected, config.backend)?;
    info!(
        "whole-body policy {} ({} backend) over skill {}",
        label,
        policy.backend(),
        config.skill.display()
    );
    if let Some(trained) = file
        .metadata
        .get(kumi_terms::contract::TRAINED_MORPHOLOGY_FINGERPRINT)
    {
        info!(
            "the policy was re-stamped (`kumi policy restamp`): trained on `{}` with robot fingerprint {trained}, run on it as it is now",
            config.model.name
        );
    }
    let controller = WholeBodyController::new(
        &config.model,
        terms,
        Box::new(move |obs| policy.act(obs).map_err(|e| e.to_string())),
    )
    .map_err(robot_error)?
    .with_observation(options);
    Ok(match config.tilt_limit_rad {
        Some(limit_rad) => controller.with_tilt_limit(limit_rad),
        None => controller,
    })
}

/// Where a wheel module's velocity goes.
enum WheelOutput {
    /// The sim bridge's `wheel_velocity` (`std_msgs/Float64`, the module's velocity).
    Bridge(Publisher<Float64>),
    /// A Motion Stack limb's `joint_set`: each wheel joint's velocity by its name there.
    Limb {
        publisher: Publisher<JointState>,
        /// Its wheel joints: the model's name and the limb's.
        joints: Vec<(String, String)>,
    },
}

struct Io {
    target: StrictSubscription<PoseStamped>,
    odom: StrictSubscription<Odometry>,
    /// Per module: its joint states and the names to read them by.
    joint_states: Vec<(StrictSubscription<JointState>, String, Vec<String>)>,
    goals: Vec<(String, String, Publisher<PoseStamped>)>,
    wheels: Vec<(String, WheelOutput)>,
    /// On hardware, per module with joints that turn a following wheel module: its limb's
    /// `joint_set` (the arm node's commands).
    steering: Vec<SteeringInput>,
    tool_pose: Publisher<PoseStamped>,
    diagnostics: Publisher<DiagnosticArray>,
}

/// A limb's `joint_set` (the arm node's commands) and the joints read from it that turn a
/// following wheel module, by their model and limb names.
struct SteeringInput {
    commands: StrictSubscription<JointState>,
    joints: Vec<(String, String)>,
}

/// Messages taken per subscription per loop: a flood cannot keep the node from acting.
const MAX_TAKEN: usize = 1000;

fn open_io(
    node: &mut RosNode,
    config: &WholeBodyNodeConfig,
    controller: &WholeBodyController,
    steered: &SteeringRates,
) -> Result<Io, WholeBodyNodeError> {
    let robot = config.robot.as_str();
    let hardware = config.hardware.as_deref();
    let mut joint_states = Vec::new();
    for (index, module) in controller.modules().iter().enumerate() {
        let names: Vec<String> = controller
            .joint_names(index)
            .iter()
            .map(|j| match hardware {
                Some(p) => p.joint_name(module, unprefixed(module, j)),
                None => j.clone(),
            })
            .collect();
        let topic = match hardware {
            Some(p) => p.joint_read(module),
            None => topics::joint_states(robot, module),
        };
        joint_states.push((
            node.strict_subscription(&topic, qos::default())?,
            topic,
            names,
        ));
    }
    let mut goals = Vec::new();
    for arm in controller.terms().arms() {
        let root = &config
            .model
            .module(&arm.module)
            .expect("terms come from the model")
            .root_link;
        goals.push((
            arm.module.clone(),
            topics::frame(robot, root),
            node.publisher(&topics::goal_pose(robot, &arm.module), qos::default())?,
        ));
    }
    let mut wheels = Vec::new();
    for wheel in controller.terms().wheels() {
        let output = match hardware {
            Some(p) => WheelOutput::Limb {
                publisher: node.publisher(&p.joint_set(&wheel.module), qos::default())?,
                joints: config
                    .model
                    .module(&wheel.module)
                    .expect("terms come from the model")
                    .velocity_joints()
                    .map(|a| {
                        let bare = unprefixed(&wheel.module, &a.joint);
                        (a.joint.clone(), p.joint_name(&wheel.module, bare))
                    })
                    .collect(),
            },
            None => WheelOutput::Bridge(node.publisher(
                &topics::wheel_velocity(robot, &wheel.module),
                qos::default(),
            )?),
        };
        wheels.push((wheel.module.clone(), output));
    }
    let mut steering = Vec::new();
    if let Some(p) = hardware {
        for module in &config.model.modules {
            let joints: Vec<(String, String)> = steered
                .joints()
                .filter(|j| kumi_model::unprefixed(&module.name, j).is_some())
                .map(|j| {
                    (
                        j.to_string(),
                        p.joint_name(&module.name, unprefixed(&module.name, j)),
                    )
                })
                .collect();
            if !joints.is_empty() {
                let topic = p.joint_set(&module.name);
                steering.push(SteeringInput {
                    commands: node.strict_subscription(&topic, qos::default())?,
                    joints,
                });
            }
        }
    }
    let odom = match hardware {
        Some(p) => p.odometry.clone().ok_or_else(|| WholeBodyNodeError::Robot {
            robot: config.robot.clone(),
            message: "the hardware profile names no `odometry` topic; the whole-body node needs the base's".into(),
        })?,
        None => topics::odom(robot),
    };
    Ok(Io {
        target: node.strict_subscription(&topics::robot_goal_pose(robot), qos::default())?,
        odom: node.strict_subscription(&odom, qos::default())?,
        joint_states,
        goals,
        wheels,
        steering,
        tool_pose: node.publisher(&topics::tool_pose(robot), qos::default())?,
        diagnostics: node.publisher(topics::DIAGNOSTICS, qos::default())?,
    })
}

/// The base state of an odometry message: pose in its frame, twist (linear and angular)
/// turned from the child (base) frame into it. `None` when a value is not finite or the pose is
/// not one ([`geometry::isometry`]).
pub fn base_state(msg: &Odometry) -> Option<BaseState> {
    let pose_w = geometry::isometry(&msg.pose.pose).ok()?;
    let (v, w) = (msg.twist.twist.linear, msg.twist.twist.angular);
    let v_b = Vector3::new(v.x, v.y, v.z);
    let w_b = Vector3::new(w.x, w.y, w.z);
    if !v_b.iter().chain(w_b.iter()).all(|x| x.is_finite()) {
        return None;
    }
    Some(BaseState {
        pose_w,
        linear_velocity_w: pose_w.rotation * v_b,
        angular_velocity_w: pose_w.rotation * w_b,
    })
}

/// A joint's name without its module's prefix (`arm0/joint3` -> `joint3`), or as it is.
fn unprefixed<'a>(module: &str, joint: &'a str) -> &'a str {
    kumi_model::unprefixed(module, joint).unwrap_or(joint)
}

/// Publishes a decision: wheel velocities first ([`publish_wheels`]), then the goals stamped
/// with the tick.
fn publish(
    io: &Io,
    model: &RobotModel,
    decision: &Decision,
    stamp: Time,
    odom_frame: &str,
    following: Option<(&mut SteeringRates, f64)>,
) {
    publish_wheels(io, model, &decision.wheel_velocities, stamp, following);
    publish_goals(io, decision, stamp, odom_frame);
}

/// Sends each wheel module its velocity [rad/s] (`(module, v)`, in the order of `io.wheels`).
/// On hardware, wheels that follow their steering add their module's turn at `following`'s
/// time [s] (`None`: they do not, as when the node stops them on its way out).
fn publish_wheels(
    io: &Io,
    model: &RobotModel,
    wheel_velocities: &[(String, f64)],
    stamp: Time,
    mut following: Option<(&mut SteeringRates, f64)>,
) {
    for ((module, output), (_, v)) in io.wheels.iter().zip(wheel_velocities) {
        match output {
            WheelOutput::Bridge(publisher) => {
                let _ = publisher.publish(Float64 { data: *v });
            }
            WheelOutput::Limb { publisher, joints } => {
                // The one wheel rule (sign by mounting, clamp; following the steering as the
                // simulator's servos do), then each joint by its name.
                let velocities = match following.as_mut() {
                    Some((rates, now_s)) => rates.wheel_velocities(model, module, *v, *now_s),
                    None => wheel_joint_velocities(model, module, *v),
                };
                let Some(velocities) = velocities else {
                    continue;
                };
                let _ = publisher.publish(JointState {
                    header: Header {
                        stamp,
                        frame_id: String::new(),
                    },
                    name: joints.iter().map(|(_, limb)| limb.clone()).collect(),
                    position: Vec::new(),
                    velocity: joints
                        .iter()
                        .map(|(joint, _)| {
                            velocities
                                .iter()
                                .find(|(j, _)| j == joint)
                                .map_or(0.0, |(_, v)| *v)
                        })
                        .collect(),
                    effort: Vec::new(),
                });
            }
        }
    }
}

/// Sends each arm module's goal and the tool pose of a decision, stamped with its tick.
fn publish_goals(io: &Io, decision: &Decision, stamp: Time, odom_frame: &str) {
    if let Some(goals) = &decision.goals {
        for ((_, frame, publisher), (_, goal)) in io.goals.iter().zip(goals) {
            let pose = nalgebra::Isometry3::from_parts(goal.position_b.into(), goal.orientation_b);
            let _ = publisher.publish(PoseStamped {
                header: Header {
                    stamp,
                    frame_id: frame.clone(),
                },
                pose: geometry::pose(&pose),
            });
        }
    }
    if let Some(tool) = &decision.tool_pose_w {
        let _ = io.tool_pose.publish(PoseStamped {
            header: Header {
                stamp,
                frame_id: odom_frame.to_string(),
            },
            pose: geometry::pose(tool),
        });
    }
}

/// Refuses to start when another whole-body node already publishes this robot's tool pose.
fn refuse_duplicates(
    node: &RosNode,
    config: &WholeBodyNodeConfig,
    own: ros2_client::Gid,
) -> Result<(), WholeBodyNodeError> {
    let topic = topics::tool_pose(&config.robot);
    if node.others_publish::<PoseStamped>(&topic, own, config.duplicate_check)? {
        return Err(WholeBodyNodeError::Duplicate {
            robot: config.robot.clone(),
            topic,
        });
    }
    Ok(())
}

/// Takes the arm nodes' commands on the steering legs' `joint_set` (hardware) into `steering`;
/// whether any joint that turns a wheel module got a command. A non-finite position is counted
/// as a rejected joint state and logged.
fn take_steering_commands(
    io: &Io,
    steering: &mut SteeringRates,
    now_s: f64,
    report: &mut Report,
    log: &mut RateLimited,
) -> bool {
    let mut any = false;
    for input in &io.steering {
        for _ in 0..MAX_TAKEN {
            match input.commands.take() {
                None => break,
                Some(Ok((msg, _))) => {
                    for (joint, limb_name) in &input.joints {
                        let position = msg
                            .name
                            .iter()
                            .position(|n| n == limb_name)
                            .and_then(|k| msg.position.get(k));
                        let Some(&q) = position else { continue };
                        if steering.command(joint, q, now_s) {
                            any = true;
                        } else {
                            report.joint_states_rejected += 1;
                            if let Some(n) = log.check(Instant::now()) {
                                warn!(
                                    "{joint}: steering command {q} rejected ({n} more suppressed)"
                                );
                            }
                        }
                    }
                }
                Some(Err(why)) => {
                    report.malformed += 1;
                    if log.check(Instant::now()).is_some() {
                        warn!("refused a malformed steering command: {why}");
                    }
                }
            }
        }
    }
    any
}

/// Makes `t` the target (a publisher repeating the current target changes nothing); whether
/// it changed.
fn start_target(controller: &mut WholeBodyController, report: &mut Report, t: Target) -> bool {
    if controller.target() == Some(t) {
        return false;
    }
    let p = t.position_w;
    info!(
        "new target: ({:.2}, {:.2}, {:.2}) m, yaw {:.2} rad",
        p.x, p.y, p.z, t.yaw
    );
    controller.set_target(t);
    report.target_since_s = None;
    true
}

/// The node's settings, as its read-only ROS parameters (`ros2 param list /<robot>/whole_body`).
fn settings(config: &WholeBodyNodeConfig, controller: &WholeBodyController) -> Settings {
    use ParameterValue::{Boolean, Double, String as Text};
    let mut s = Settings::new();
    s.insert("robot".into(), Text(config.robot.clone()));
    s.insert("morphology".into(), Text(config.model.name.clone()));
    let fingerprint = kumi_policies::metadata::fingerprint_bytes;
    kumi_ros::parameters::file(&mut s, "policy", &config.policy, fingerprint);
    kumi_ros::parameters::file(&mut s, "skill", &config.skill, fingerprint);
    s.insert(
        "backend".into(),
        Text(format!("{:?}", config.backend).to_lowercase()),
    );
    s.insert("stale_after_s".into(), Double(config.stale_after_s));
    s.insert(
        "max_target_distance_m".into(),
        Double(config.max_target_distance_m),
    );
    if let Some(limit) = controller.tilt_limit_rad() {
        s.insert("tilt_limit_rad".into(), Double(limit));
    }
    s.insert("lockstep".into(), Boolean(config.lockstep));
    s.insert("hardware".into(), Boolean(config.hardware.is_some()));
    s
}

/// Runs the node until `shutdown` is set.
pub fn run(
    config: WholeBodyNodeConfig,
    shutdown: Arc<AtomicBool>,
) -> Result<(), WholeBodyNodeError> {
    let mut controller = prepare(&config)?;
    let robot = config.robot.as_str();
    let namespace = format!("/{robot}");
    let mut node = RosNode::new(&namespace, "whole_body", config.domain_id)?;
    let _rosout = kumi_ros::rosout::attach(
        &mut node,
        &kumi_ros::rosout::logger_name(&namespace, "whole_body"),
    )?;
    let mut steering = SteeringRates::new(&config.model);
    let io = open_io(&mut node, &config, &controller, &steering)?;
    refuse_duplicates(&node, &config, io.tool_pose.gid())?;
    let parameters = node.parameter_services(settings(&config, &controller))?;
    // Targets and the tool pose are in the odometry's frame: `<robot>/odom` from the sim
    // bridge, whatever the odometry says on hardware.
    let mut odom_frame = topics::odom_frame(robot);
    info!(
        "whole-body node up: /{robot}, {} arm and {} wheel modules, domain {}; send targets to {}",
        io.goals.len(),
        io.wheels.len(),
        node.domain_id(),
        topics::robot_goal_pose(robot)
    );
    if config.hardware.is_some() && !steering.is_empty() {
        info!(
            "wheels follow their steering (`follow_steering`): reading {} on the limbs' joint_set",
            steering.joints().collect::<Vec<_>>().join(", ")
        );
    }
    match controller.tilt_limit_rad() {
        Some(limit) => {
            info!("stops driving if the base tilts past {limit:.3} rad, until a new target")
        }
        None => warn!(
            "no tilt limit: the node drives on even if the robot tips over (--tilt-limit-rad)"
        ),
    }

    let start = Instant::now();
    let period_s = 1.0 / kumi_model::commands::CONTROL_HZ;
    let (sync_wait_s, stale_after_s) = if config.lockstep {
        (f64::INFINITY, f64::INFINITY)
    } else {
        (period_s, config.stale_after_s)
    };
    let mut tick = Tick::new(controller.modules().to_vec());
    let mut report = Report::default();
    let mut report_at = Instant::now();
    let mut log = RateLimited::new(Duration::from_secs(1));
    let mut hold_log = RateLimited::new(Duration::from_secs(2));
    let mut progress_log = RateLimited::new(Duration::from_secs(2));
    let mut sync_log = RateLimited::new(Duration::from_secs(5));
    let mut last_odom_stamp: Option<Time> = None;
    let mut last_stale_hold_s = f64::NEG_INFINITY;
    let mut base_xy: Option<[f64; 2]> = None;
    let mut liveliness_at = Instant::now();
    // The last decided wheel velocities and their tick, sent again when a steering leg's
    // command changes its wheels' following (hardware).
    let mut last_wheels: Option<(Vec<(String, f64)>, Time)> = None;
    // A target stamped ahead of the robot's clock, and the time [s] it starts at.
    let mut pending: Option<(Target, f64)> = None;

    while !shutdown.load(Ordering::Relaxed) {
        let now_s = start.elapsed().as_secs_f64();
        for _ in 0..MAX_TAKEN {
            match io.target.take() {
                None => break,
                Some(Ok((msg, _))) => {
                    match target::accept(&msg, &odom_frame, base_xy, config.max_target_distance_m) {
                        Ok(t) => {
                            report.targets_accepted += 1;
                            let clock_s = last_odom_stamp.map(|s| s.seconds());
                            match target::starts_at(msg.header.stamp.seconds(), clock_s) {
                                Some(at_s) => {
                                    if pending != Some((t, at_s)) {
                                        info!("target for {at_s:.3} s of the robot's clock (stamped ahead): waits for that time");
                                    }
                                    pending = Some((t, at_s));
                                }
                                None => {
                                    pending = None;
                                    if start_target(&mut controller, &mut report, t) {
                                        tick.decide_again();
                                    }
                                }
                            }
                        }
                        Err(why) => {
                            report.targets_rejected += 1;
                            if let Some(n) = log.check(Instant::now()) {
                                warn!("target rejected: {why} ({n} more suppressed)");
                            }
                        }
                    }
                }
                Some(Err(why)) => {
                    report.malformed += 1;
                    if log.check(Instant::now()).is_some() {
                        warn!("refused a malformed target: {why}");
                    }
                }
            }
        }
        for _ in 0..MAX_TAKEN {
            match io.odom.take() {
                None => break,
                Some(Ok((msg, _))) => match base_state(&msg) {
                    Some(base) => {
                        if config.hardware.is_some()
                            && !msg.header.frame_id.is_empty()
                            && msg.header.frame_id != odom_frame
                        {
                            odom_frame.clone_from(&msg.header.frame_id);
                            info!("odometry in frame `{odom_frame}`: targets are taken in it");
                        }
                        let stamp = msg.header.stamp;
                        if last_odom_stamp.is_some_and(|before| stamp < before) {
                            info!("odometry time went back (a restarted simulator); starting over");
                            report.sim_restarts += 1;
                            controller.start_over();
                            report.target_since_s = None;
                            tick.forget();
                        }
                        last_odom_stamp = Some(stamp);
                        base_xy = Some([base.pose_w.translation.x, base.pose_w.translation.y]);
                        // Wheels that follow their steering also follow the base's turning.
                        let w_b = msg.twist.twist.angular;
                        steering.base_turning(Vector3::new(w_b.x, w_b.y, w_b.z), now_s);
                        tick.base(stamp, base, now_s);
                    }
                    None => {
                        report.odometry_rejected += 1;
                        if log.check(Instant::now()).is_some() {
                            warn!("odometry rejected: a non-finite value or a quaternion that is not a rotation");
                        }
                    }
                },
                Some(Err(why)) => {
                    report.malformed += 1;
                    if log.check(Instant::now()).is_some() {
                        warn!("refused a malformed odometry message: {why}");
                    }
                }
            }
        }
        for (index, (sub, _, names)) in io.joint_states.iter().enumerate() {
            let module = &controller.modules()[index];
            for _ in 0..MAX_TAKEN {
                match sub.take() {
                    None => break,
                    Some(Ok((msg, _))) => {
                        match kumi_ros::joint_state::read_named(&msg, module, names) {
                            Ok((q, qd)) => {
                                tick.joints(index, msg.header.stamp, ModuleState { q, qd }, now_s)
                            }
                            Err(why) => {
                                report.joint_states_rejected += 1;
                                if let Some(n) = log.check(Instant::now()) {
                                    warn!("{module}: joint state rejected: {why} ({n} more suppressed)");
                                }
                            }
                        }
                    }
                    Some(Err(why)) => {
                        report.malformed += 1;
                        if log.check(Instant::now()).is_some() {
                            warn!("{module}: refused a malformed joint state: {why}");
                        }
                    }
                }
            }
        }

        if take_steering_commands(&io, &mut steering, now_s, &mut report, &mut log) {
            // A leg's new command changes its wheels' following now, not at the next decision.
            if let Some((wheels, stamp)) = &last_wheels {
                publish_wheels(
                    &io,
                    &config.model,
                    wheels,
                    *stamp,
                    Some((&mut steering, now_s)),
                );
            }
        }

        // Motion Stack publishes `joint_read` only on change: while a limb's publisher is alive
        // its last joint state still holds.
        if config.hardware.is_some() && liveliness_at.elapsed() >= Duration::from_millis(100) {
            liveliness_at = Instant::now();
            for (index, (_, topic, _)) in io.joint_states.iter().enumerate() {
                if node.remote_publishers(topic) > 0 {
                    tick.refresh(index, now_s);
                }
            }
        }
        // How long ago the tick's odometry arrived, for the decision latency.
        let odometry_age_s = tick.base_age_s(now_s).unwrap_or(0.0);
        let decided_at = Instant::now();
        let decision = match tick.due(now_s, sync_wait_s, stale_after_s) {
            Due::Wait => {
                // No odometry for too long (or none yet): hold, once per control period.
                let age_s = tick.base_age_s(now_s);
                let overdue = age_s.is_none_or(|a| a >= stale_after_s);
                (overdue && now_s - last_stale_hold_s >= period_s).then(|| {
                    last_stale_hold_s = now_s;
                    let input = "odometry messages".to_string();
                    let why = match age_s {
                        Some(age_s) => Hold::Stale { input, age_s },
                        None => Hold::Waiting { input },
                    };
                    (
                        controller.hold(why, None),
                        last_odom_stamp.unwrap_or_default(),
                    )
                })
            }
            Due::Stale { input, age_s } => {
                let why = if age_s.is_finite() {
                    Hold::Stale { input, age_s }
                } else {
                    Hold::Waiting { input }
                };
                Some((
                    controller.hold(why, None),
                    last_odom_stamp.unwrap_or_default(),
                ))
            }
            Due::Act(snapshot) => {
                if snapshot.synchronous {
                    report.synchronous_ticks += 1;
                } else {
                    report.unsynchronised_ticks += 1;
                    if sync_log.check(Instant::now()).is_some() {
                        warn!(
                            "acting on the tick at {:.3} s without every module's joint states of that tick (waited {:.0} ms; counted in unsynchronised_ticks on /diagnostics)",
                            snapshot.stamp.seconds(),
                            sync_wait_s * 1000.0
                        );
                    }
                }
                if let Some((t, at_s)) = pending {
                    if target::has_started(snapshot.stamp.seconds(), at_s) {
                        pending = None;
                        start_target(&mut controller, &mut report, t);
                    }
                }
                Some((controller.step(&snapshot), snapshot.stamp))
            }
        };
        if let Some((decision, stamp)) = decision {
            report.step(decision.hold.as_ref());
            if let (true, Some(h)) = (decision.tipped_over_now, &decision.hold) {
                report.tipped_over += 1;
                warn!("stopped: {h}");
            }
            if decision.action.is_some() && report.target_since_s.is_none() {
                report.target_since_s = Some(stamp.seconds());
            }
            if let Some(h @ (Hold::Stale { .. } | Hold::PolicyFailed(_))) = &decision.hold {
                // Before the first target nothing is commanded, and in lockstep simulated time
                // stands still until one comes: old odometry then is no news.
                if controller.target().is_none() {
                    debug!("holding before the first target: {h}");
                } else if hold_log.check(Instant::now()).is_some() {
                    warn!("holding: {h}");
                }
            }
            if let (Some(target), Some(tool)) = (controller.target(), &decision.tool_pose_w) {
                let (p, y) = kumi_terms::observation::target_errors(tool, &target);
                report.errors = Some((p, y));
                if decision.hold.is_none() && progress_log.check(Instant::now()).is_some() {
                    info!("tool {p:.3} m and {y:.2} rad from the target");
                }
            }
            let now_s = start.elapsed().as_secs_f64();
            publish(
                &io,
                &config.model,
                &decision,
                stamp,
                &odom_frame,
                Some((&mut steering, now_s)),
            );
            if !io.steering.is_empty() {
                last_wheels = Some((decision.wheel_velocities.clone(), stamp));
            }
            if decision.action.is_some() {
                report.latency(odometry_age_s + decided_at.elapsed().as_secs_f64());
            }
        }
        parameters.poll();
        if report_at.elapsed() >= Duration::from_secs(1) {
            report_at = Instant::now();
            let _ = io.diagnostics.publish(DiagnosticArray {
                header: Header {
                    stamp: last_odom_stamp.unwrap_or_default(),
                    frame_id: String::new(),
                },
                status: vec![report.status(robot)],
            });
        }
        std::thread::sleep(Duration::from_micros(200));
    }
    // On the way out the wheels stop (arms keep their goals): a wheel limb on hardware keeps
    // its last velocity otherwise.
    let stop = controller.hold(
        Hold::Waiting {
            input: "a running whole-body node".into(),
        },
        None,
    );
    publish(
        &io,
        &config.model,
        &stop,
        last_odom_stamp.unwrap_or_default(),
        &odom_frame,
        None,
    );
    info!("whole-body node /{robot} stopping (wheels stopped)");
    Ok(())
}
