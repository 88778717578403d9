//! The bridge's event loop.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use kumi_model::kinematics::KinematicTree;
use kumi_model::{ActuatorMode, RobotModel};
use kumi_msgs::builtin_interfaces::Time;
use kumi_msgs::diagnostic_msgs::{DiagnosticArray, DiagnosticStatus, KeyValue};
use kumi_msgs::rosgraph_msgs::Clock;
use kumi_msgs::sensor_msgs::JointState;
use kumi_msgs::std_msgs::{Float64, Float64MultiArray, Header, StringMsg};
use kumi_ros::parameters::{ParameterValue, Settings};
use kumi_ros::services::TriggerResponse;
use kumi_ros::{qos, topics, RateLimited, RosError, RosNode, StrictSubscription};
use kumi_worlds::{Engine, SimConfig, SimError, SimWorld};
use nalgebra::Vector3;
use ros2_client::Publisher;
use tracing::{error, info, warn};

use crate::commands::{Commands, Rejection, Update};
use crate::lockstep::Lockstep;
use crate::state;

/// How the bridge paces the simulation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mode {
    /// Physics paced to the wall clock, `factor` times real time.
    RealTime { factor: f64 },
    /// One control step when every commanded module has sent its command for the tick, or when
    /// `timeout` passes without them; as fast as the consumers allow. Before the first command
    /// simulated time stands still and the current state is republished every `timeout`, so a
    /// run always starts from the same state; after it, a controller that goes silent is
    /// logged, counted on `/diagnostics` and stepped without, so that it holds once its
    /// commands go stale ([`Lockstep`]).
    Lockstep { timeout: Duration },
}

/// Everything the bridge needs to run.
#[derive(Debug, Clone)]
pub struct BridgeConfig {
    pub model: Arc<RobotModel>,
    /// The physics engine (rapier by default).
    pub engine: Engine,
    /// The robot name: the namespace of every topic.
    pub robot: String,
    /// ROS domain id.
    pub domain_id: u16,
    pub mode: Mode,
    /// Commands older than this [s of sim time] make a module hold its position (wheels stop).
    pub stale_after_s: f64,
    /// How long to listen for another bridge of the same robot before starting.
    pub duplicate_check: Duration,
    /// Lockstep: modules whose first command the first step waits for, however long it takes
    /// (besides those whose command topics have a publisher when commands begin).
    pub first_step_waits_for: Vec<String>,
}

#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error(transparent)]
    Sim(#[from] SimError),
    #[error(transparent)]
    Ros(#[from] RosError),
    #[error("another sim bridge already runs robot `{robot}` on ROS domain {domain} (it publishes {topic}); give this one another name with --robot")]
    Duplicate {
        robot: String,
        domain: u16,
        topic: String,
    },
    #[error("invalid configuration: {0}")]
    BadConfig(String),
}

/// Subscriptions of one module.
struct ModuleInputs {
    name: String,
    increments: Option<StrictSubscription<Float64MultiArray>>,
    joint_set: Option<StrictSubscription<JointState>>,
    wheel_velocity: Option<StrictSubscription<Float64>>,
}

/// An incoming message, taken off its subscription.
enum Incoming {
    Increments(Float64MultiArray),
    JointSet(JointState),
    WheelVelocity(f64),
}

/// Rejection and clamp counters, reported on `/diagnostics`.
#[derive(Default)]
struct Counters {
    by_kind: BTreeMap<&'static str, u64>,
    /// Targets set absolutely that the simulator clamped to a joint's range.
    clamped: u64,
    /// Increments that took a target past its range ([`Commands::clamped`]).
    increments_clamped: u64,
    stale_holds: u64,
    /// Lockstep steps that ran on the timeout.
    lockstep_timeouts: u64,
    /// Modules a lockstep step waited for in vain that have not spoken since.
    lockstep_silent: BTreeSet<String>,
    /// Real time: steps that began more than one control period after their tick.
    late_steps: u64,
    /// Real time: the latest any step began after its tick [s].
    max_step_late_s: f64,
    /// The sim time [s] of the step after which the physics blew up ([`SimWorld::diverged`]).
    diverged_at_s: Option<f64>,
    /// Times the world was reset (`/<robot>/reset`).
    resets: u64,
}

/// The ROS side of the bridge: publishers, subscriptions.
struct Io {
    joint_states: Vec<(String, Publisher<JointState>)>,
    joint_targets: Vec<(String, Publisher<JointState>)>,
    odom: Publisher<kumi_msgs::nav_msgs::Odometry>,
    imu: Publisher<kumi_msgs::sensor_msgs::Imu>,
    tf: Publisher<kumi_msgs::tf2_msgs::TFMessage>,
    clock: Publisher<Clock>,
    robot_clock: Publisher<Clock>,
    diagnostics: Publisher<DiagnosticArray>,
    inputs: Vec<ModuleInputs>,
    // Kept alive: the description and the fixed transforms are latched.
    _description: Publisher<StringMsg>,
    _tf_static: Publisher<kumi_msgs::tf2_msgs::TFMessage>,
}

fn check_config(config: &BridgeConfig) -> Result<(), BridgeError> {
    if let Mode::RealTime { factor } = config.mode {
        if !(factor.is_finite() && factor > 0.0) {
            return Err(BridgeError::BadConfig(format!(
                "--realtime-factor must be positive, got {factor}"
            )));
        }
    }
    if config.robot.is_empty()
        || !config
            .robot
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_')
        || config.robot.starts_with(|c: char| c.is_ascii_digit())
    {
        return Err(BridgeError::BadConfig(format!(
            "robot name `{}` must be a valid ROS name: letters, digits and `_`, not starting with a digit",
            config.robot
        )));
    }
    for module in &config.first_step_waits_for {
        if config.model.module(module).is_none() {
            return Err(BridgeError::BadConfig(format!(
                "--wait-for {module}: robot `{}` has no module `{module}` (its modules: {})",
                config.model.name,
                config
                    .model
                    .modules
                    .iter()
                    .map(|m| m.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )));
        }
    }
    Ok(())
}

/// Refuses to start when another bridge already publishes this robot's description.
fn refuse_duplicates(node: &RosNode, config: &BridgeConfig) -> Result<(), BridgeError> {
    let topic = topics::robot_description(&config.robot);
    let deadline = Instant::now() + config.duplicate_check;
    while Instant::now() < deadline {
        if node.remote_publishers(&topic) > 0 {
            return Err(BridgeError::Duplicate {
                robot: config.robot.clone(),
                domain: node.domain_id(),
                topic,
            });
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok(())
}

fn open_io(
    node: &mut RosNode,
    config: &BridgeConfig,
    tree: &KinematicTree,
) -> Result<Io, BridgeError> {
    let robot = &config.robot;
    let mut joint_states = Vec::new();
    let mut joint_targets = Vec::new();
    let mut inputs = Vec::new();
    for m in &config.model.modules {
        if m.actuators.is_empty() {
            continue;
        }
        joint_states.push((
            m.name.clone(),
            node.publisher(&topics::joint_states(robot, &m.name), qos::default())?,
        ));
        let has_position = m.actuators.iter().any(|a| a.mode == ActuatorMode::Position);
        let has_wheels = m.actuators.iter().any(|a| a.mode == ActuatorMode::Velocity);
        if has_position {
            joint_targets.push((
                m.name.clone(),
                node.publisher(&topics::joint_targets(robot, &m.name), qos::default())?,
            ));
        }
        inputs.push(ModuleInputs {
            name: m.name.clone(),
            increments: if has_position {
                Some(node.strict_subscription(
                    &topics::joint_increments(robot, &m.name),
                    qos::default(),
                )?)
            } else {
                None
            },
            joint_set: if has_position {
                Some(node.strict_subscription(&topics::joint_set(robot, &m.name), qos::default())?)
            } else {
                None
            },
            wheel_velocity: if has_wheels {
                Some(
                    node.strict_subscription(
                        &topics::wheel_velocity(robot, &m.name),
                        qos::default(),
                    )?,
                )
            } else {
                None
            },
        });
    }
    let description =
        node.publisher::<StringMsg>(&topics::robot_description(robot), qos::latched())?;
    // Latched: published once, kept for late joiners.
    if let Err(e) = description.publish(StringMsg {
        data: config.model.urdf_xml(),
    }) {
        warn!("could not publish the robot description: {e:?}");
    }
    let tf_static = node.publisher(topics::TF_STATIC, qos::latched())?;
    if let Err(e) = tf_static.publish(state::static_transforms(tree, robot)) {
        warn!("could not publish the fixed transforms: {e:?}");
    }
    Ok(Io {
        joint_states,
        joint_targets,
        odom: node.publisher(&topics::odom(robot), qos::default())?,
        imu: node.publisher(&topics::imu(robot), qos::default())?,
        tf: node.publisher(topics::TF, qos::default())?,
        clock: node.publisher(topics::CLOCK, qos::default())?,
        robot_clock: node.publisher(&topics::robot_clock(robot), qos::default())?,
        diagnostics: node.publisher(topics::DIAGNOSTICS, qos::default())?,
        inputs,
        _description: description,
        _tf_static: tf_static,
    })
}

/// Messages taken per subscription per loop: a flood cannot keep the bridge from stepping.
const MAX_TAKEN: usize = 1000;

/// Takes the waiting messages of one subscription, oldest first; what does not decode exactly
/// is counted in `malformed` and logged (rate-limited) with the reason.
fn take_all<M: kumi_msgs::RosMessage>(
    sub: &StrictSubscription<M>,
    topic: &str,
    malformed: &mut u64,
    log: &mut RateLimited,
    out: &mut Vec<Incoming>,
    wrap: fn(M) -> Incoming,
) {
    for _ in 0..MAX_TAKEN {
        match sub.take() {
            None => break,
            Some(Ok((m, _))) => out.push(wrap(m)),
            Some(Err(why)) => {
                *malformed += 1;
                if let Some(n) = log.check(Instant::now()) {
                    warn!("{topic}: refused a malformed message: {why} ({n} more suppressed)");
                }
            }
        }
    }
}

/// Takes every waiting message of one module, oldest first.
fn drain(inputs: &ModuleInputs, malformed: &mut u64, log: &mut RateLimited) -> Vec<Incoming> {
    let mut out = Vec::new();
    let m = &inputs.name;
    if let Some(sub) = &inputs.increments {
        take_all(
            sub,
            &format!("{m}/joint_increments"),
            malformed,
            log,
            &mut out,
            Incoming::Increments,
        );
    }
    if let Some(sub) = &inputs.joint_set {
        take_all(
            sub,
            &format!("{m}/joint_set"),
            malformed,
            log,
            &mut out,
            Incoming::JointSet,
        );
    }
    if let Some(sub) = &inputs.wheel_velocity {
        take_all(
            sub,
            &format!("{m}/wheel_velocity"),
            malformed,
            log,
            &mut out,
            |x| Incoming::WheelVelocity(x.data),
        );
    }
    out
}

/// Applies a validated update to the world; returns whether any value was clamped.
fn apply(
    world: &mut dyn SimWorld,
    commands: &mut Commands,
    update: &Update,
) -> Result<bool, SimError> {
    match update {
        Update::PositionTargets { module, targets } => {
            world.set_position_targets(module, targets)?;
            let range = world.module_range(module)?;
            let applied: Vec<f64> = world.commands()[range].to_vec();
            let clamped = applied != *targets;
            commands.set_applied_targets(module, &applied);
            Ok(clamped)
        }
        Update::WheelVelocity { module, velocity } => {
            world.set_wheel_velocity(module, *velocity)?;
            let range = world.module_range(module)?;
            // The joint command carries the module's drive sign: compare magnitudes.
            Ok(world.commands()[range.start].abs() != velocity.abs())
        }
    }
}

/// Per module, `values` (indexed like the world's actuators) of its position joints.
fn per_module(
    world: &dyn SimWorld,
    model: &RobotModel,
    values: &[f64],
) -> BTreeMap<String, Vec<f64>> {
    model
        .modules
        .iter()
        .filter_map(|m| {
            let range = world.module_range(&m.name).ok()?;
            let positions: Vec<f64> = range
                .zip(&m.actuators)
                .filter(|(_, a)| a.mode == ActuatorMode::Position)
                .map(|(i, _)| values[i])
                .collect();
            Some((m.name.clone(), positions))
        })
        .collect()
}

/// Each module's measured joint angles (where a module that goes stale holds).
fn module_positions(world: &dyn SimWorld, model: &RobotModel) -> BTreeMap<String, Vec<f64>> {
    per_module(world, model, &world.joint_positions())
}

/// Each module's servo set-points: what the first increments are added to, as in training
/// (at the start state, the home angles exactly, where the measured angles may differ in the
/// last bits).
fn module_targets(world: &dyn SimWorld, model: &RobotModel) -> BTreeMap<String, Vec<f64>> {
    per_module(world, model, &world.commands())
}

/// Modules whose command topics have a publisher other than this node now.
fn commanded_modules(node: &RosNode, robot: &str, io: &Io) -> Vec<String> {
    io.inputs
        .iter()
        .filter(|m| {
            [
                m.increments
                    .as_ref()
                    .map(|_| topics::joint_increments(robot, &m.name)),
                m.joint_set
                    .as_ref()
                    .map(|_| topics::joint_set(robot, &m.name)),
                m.wheel_velocity
                    .as_ref()
                    .map(|_| topics::wheel_velocity(robot, &m.name)),
            ]
            .into_iter()
            .flatten()
            .any(|topic| node.remote_publishers(&topic) > 0)
        })
        .map(|m| m.name.clone())
        .collect()
}

/// Runs the bridge until `shutdown` is set.
pub fn run(config: BridgeConfig, shutdown: Arc<AtomicBool>) -> Result<(), BridgeError> {
    check_config(&config)?;
    let model = config.model.clone();
    let mut world = kumi_worlds::build(config.engine, model.clone(), SimConfig::for_model(&model))?;
    let tree =
        KinematicTree::new(&model.urdf).map_err(|e| BridgeError::BadConfig(e.to_string()))?;
    let control_dt = 1.0 / world.config().control_hz;

    // No ros2-client spinner: the node needs none to be seen in the ROS graph, and its
    // spinner would subscribe to /clock with the wrong type (builtin_interfaces/Time).
    let mut node = RosNode::new(
        &format!("/{}", config.robot),
        "sim_bridge",
        config.domain_id,
    )?;

    let rosout = kumi_ros::rosout::attach(
        &mut node,
        &kumi_ros::rosout::logger_name(&format!("/{}", config.robot), "sim_bridge"),
    )?;
    refuse_duplicates(&node, &config)?;
    let io = open_io(&mut node, &config, &tree)?;
    let parameters = node.parameter_services(settings(&config, world.as_ref()))?;
    let reset = node.trigger_server(&topics::reset(&config.robot))?;
    // A reset under way: since when, the sim time it left [s], the request to answer.
    let mut resetting = None;
    info!(
        robot = %config.robot,
        domain = node.domain_id(),
        mode = ?config.mode,
        "sim bridge up: {} modules, {} physics {}",
        model.modules.len(),
        config.engine,
        world.config().label_for(config.engine)
    );

    let (mut commands, mut lockstep) = fresh_start(world.as_ref(), &config);
    let mut waiting_log = RateLimited::new(Duration::from_secs(5));
    let mut counters = Counters::default();
    let mut malformed = 0_u64;
    let mut reject_log = RateLimited::new(Duration::from_secs(1));
    let mut malformed_log = RateLimited::new(Duration::from_secs(1));
    let mut steps: u64 = 0;
    let mut last_linvel = world.base_twist_w().0;
    let mut accel_w = Vector3::zeros();
    let start = Instant::now();
    let mut last_step_at = Instant::now();
    let mut next_tick = Instant::now();
    let mut diag_at = Instant::now() + Duration::from_secs(1);
    let mut diag_window = (Instant::now(), 0_u64);
    let mut discovered_at = Instant::now() - Duration::from_secs(1);

    let publish_state = |world: &dyn SimWorld, steps: u64, accel_w: &Vector3<f64>| {
        let stamp = Time::from_seconds(sim_time_s(steps, control_dt));
        let robot = &config.robot;
        for (module, publisher) in &io.joint_states {
            if let Some(js) = state::joint_state(world, module, stamp) {
                let _ = publisher.publish(js);
            }
        }
        for (module, publisher) in &io.joint_targets {
            if let Some(targets) = state::joint_targets(world, module, stamp) {
                let _ = publisher.publish(targets);
            }
        }
        let _ = io.odom.publish(state::odometry(world, robot, stamp));
        let _ = io.imu.publish(state::imu(world, robot, accel_w, stamp));
        let _ = io.tf.publish(state::transforms(world, &tree, robot, stamp));
        let _ = io.clock.publish(Clock { clock: stamp });
        let _ = io.robot_clock.publish(Clock { clock: stamp });
    };
    publish_state(world.as_ref(), steps, &accel_w);

    while !shutdown.load(Ordering::Relaxed) {
        parameters.poll();
        // A reset: the robot back at its start pose, sim time back to zero (the nodes start
        // over when they see time go back), lockstep waiting for the first commands again.
        // The commands the nodes sent for the old world that are still on their way are
        // dropped for RESET_GRACE before the new world's first state goes out.
        while let Ok(Some((id, _))) = reset.receive_request() {
            let at_s = sim_time_s(steps, control_dt);
            match kumi_worlds::build(config.engine, model.clone(), SimConfig::for_model(&model)) {
                Ok(fresh) => {
                    world = fresh;
                    (commands, lockstep) = fresh_start(world.as_ref(), &config);
                    steps = 0;
                    last_linvel = world.base_twist_w().0;
                    accel_w = Vector3::zeros();
                    counters.diverged_at_s = None;
                    counters.lockstep_silent.clear();
                    counters.resets += 1;
                    resetting = Some((Instant::now(), at_s, id));
                }
                Err(e) => {
                    error!("reset refused: the world could not be built again: {e}");
                    let answer = TriggerResponse {
                        success: false,
                        message: format!("the world could not be built again: {e}"),
                    };
                    let _ = reset.send_response(id, answer);
                }
            }
        }
        if let Some((since, at_s, id)) = resetting {
            for inputs in &io.inputs {
                drain(inputs, &mut malformed, &mut malformed_log);
            }
            if since.elapsed() < RESET_GRACE {
                std::thread::sleep(Duration::from_millis(1));
                continue;
            }
            resetting = None;
            diag_window = (Instant::now(), 0);
            (last_step_at, next_tick) = (Instant::now(), Instant::now());
            publish_state(world.as_ref(), steps, &accel_w);
            let message = format!("reset after {at_s:.3} s of sim time: the robot is back at its start pose, sim time at 0");
            info!("{message}");
            let _ = reset.send_response(
                id,
                TriggerResponse {
                    success: true,
                    message,
                },
            );
        }
        let now_s = sim_time_s(steps, control_dt);
        // Commands.
        for inputs in &io.inputs {
            for message in drain(inputs, &mut malformed, &mut malformed_log) {
                let result = match message {
                    Incoming::Increments(m) => commands.increments(&inputs.name, &m.data, now_s),
                    Incoming::JointSet(m) => {
                        commands.joint_set(&inputs.name, &m.name, &m.position, now_s)
                    }
                    Incoming::WheelVelocity(v) => commands.wheel_velocity(&inputs.name, v, now_s),
                };
                match result {
                    Ok(update) => {
                        tracing::debug!("step {steps}: {update:?}");
                        counters.clamped +=
                            u64::from(apply(world.as_mut(), &mut commands, &update)?);
                        lockstep.received(&inputs.name);
                        counters.lockstep_silent.remove(&inputs.name);
                    }
                    Err(rejection) => {
                        *counters.by_kind.entry(rejection.kind()).or_default() += 1;
                        log_rejection(&mut reject_log, &rejection);
                    }
                }
            }
        }

        // Before the first step in lockstep: wait for every node that commands a module.
        if matches!(config.mode, Mode::Lockstep { .. })
            && steps == 0
            && discovered_at.elapsed() >= Duration::from_millis(50)
        {
            discovered_at = Instant::now();
            lockstep.expect_first(commanded_modules(&node, &config.robot, &io));
        }
        // Step when it is time.
        let due = match config.mode {
            Mode::RealTime { .. } => Instant::now() >= next_tick,
            Mode::Lockstep { timeout } => {
                let timed_out = last_step_at.elapsed() >= timeout;
                if timed_out && !lockstep.may_time_out() {
                    publish_state(world.as_ref(), steps, &accel_w);
                    last_step_at = Instant::now();
                    if lockstep.active() && waiting_log.check(Instant::now()).is_some() {
                        warn!(
                            "lockstep: the first step waits for the first command from {}",
                            lockstep.missing().join(", ")
                        );
                    }
                }
                lockstep.ready() || (timed_out && lockstep.may_time_out())
            }
        };
        if due {
            if let Mode::RealTime { factor } = config.mode {
                let late_s = Instant::now()
                    .saturating_duration_since(next_tick)
                    .as_secs_f64();
                counters.max_step_late_s = counters.max_step_late_s.max(late_s);
                // One control period of wall time.
                if late_s > control_dt / factor {
                    counters.late_steps += 1;
                }
            }
            if let Mode::Lockstep { timeout } = config.mode {
                let silent = lockstep.missing();
                if !lockstep.ready() {
                    counters.lockstep_timeouts += 1;
                    if !silent.is_empty() {
                        warn!(
                            "lockstep: no command from {} within {timeout:?}; stepping without (they hold after {} s of sim time)",
                            silent.join(", "),
                            config.stale_after_s
                        );
                    }
                }
                counters.lockstep_silent.extend(silent);
            }
            for update in commands.expire(now_s, &module_positions(world.as_ref(), &model)) {
                counters.stale_holds += 1;
                warn!(
                    "{}: commands stopped for {} s of sim time; holding position",
                    module_of(&update),
                    config.stale_after_s
                );
                apply(world.as_mut(), &mut commands, &update)?;
            }
            world.step();
            steps += 1;
            if world.diverged() && counters.diverged_at_s.is_none() {
                let at_s = sim_time_s(steps, control_dt);
                error!("the physics blew up at {at_s:.3} s of sim time: the simulated robot means nothing until a reset (/{}/reset) or a restart of the bridge", config.robot);
                counters.diverged_at_s = Some(at_s);
            }
            let linvel = world.base_twist_w().0;
            accel_w = (linvel - last_linvel) / control_dt;
            last_linvel = linvel;
            lockstep.stepped();
            last_step_at = Instant::now();
            publish_state(world.as_ref(), steps, &accel_w);
            if let Mode::RealTime { factor } = config.mode {
                next_tick += Duration::from_secs_f64(control_dt / factor);
                // Fell far behind (a stall): resynchronise rather than sprint to catch up.
                if Instant::now() > next_tick + Duration::from_secs(1) {
                    next_tick = Instant::now();
                }
            }
        }

        if Instant::now() >= diag_at {
            let (since, steps_then) = diag_window;
            let rtf = (steps - steps_then) as f64 * control_dt / since.elapsed().as_secs_f64();
            counters.increments_clamped = commands.clamped();
            let _ = io.diagnostics.publish(diagnostics(
                &config, steps, control_dt, rtf, &counters, malformed, start,
            ));
            diag_window = (Instant::now(), steps);
            diag_at += Duration::from_secs(1);
        }

        // Wait: real time sleeps to the next tick; lockstep polls for commands.
        match config.mode {
            Mode::RealTime { .. } => {
                let wait = next_tick
                    .saturating_duration_since(Instant::now())
                    .min(diag_at.saturating_duration_since(Instant::now()));
                std::thread::sleep(wait.min(Duration::from_millis(50)));
            }
            Mode::Lockstep { .. } => std::thread::sleep(Duration::from_micros(100)),
        }
    }
    info!("sim bridge stopping after {steps} control steps");
    drop(io);
    drop(rosout);
    drop(node);
    Ok(())
}

/// The bridge's settings, as its read-only ROS parameters (`ros2 param list
/// /<robot>/sim_bridge`).
fn settings(config: &BridgeConfig, world: &dyn SimWorld) -> Settings {
    use ParameterValue::{Double, String as Text, StringArray};
    let mut s = Settings::new();
    s.insert("robot".into(), Text(config.robot.clone()));
    s.insert("morphology".into(), Text(config.model.name.clone()));
    s.insert("engine".into(), Text(config.engine.to_string()));
    s.insert(
        "physics".into(),
        Text(world.config().label_for(config.engine)),
    );
    s.insert("control_hz".into(), Double(world.config().control_hz));
    s.insert("stale_after_s".into(), Double(config.stale_after_s));
    match config.mode {
        Mode::RealTime { factor } => {
            s.insert("mode".into(), Text("real_time".into()));
            s.insert("realtime_factor".into(), Double(factor));
        }
        Mode::Lockstep { timeout } => {
            s.insert("mode".into(), Text("lockstep".into()));
            s.insert("lockstep_timeout_s".into(), Double(timeout.as_secs_f64()));
            s.insert(
                "wait_for".into(),
                StringArray(config.first_step_waits_for.clone()),
            );
        }
    }
    s
}

fn module_of(update: &Update) -> &str {
    match update {
        Update::PositionTargets { module, .. } | Update::WheelVelocity { module, .. } => module,
    }
}

/// The commands and the lockstep gate of a world at its start (the bridge's, and after each
/// reset): every module holding where it stands, nothing received, the first step waiting for
/// the modules the config names.
fn fresh_start(world: &dyn SimWorld, config: &BridgeConfig) -> (Commands, Lockstep) {
    let model = &config.model;
    let commands = Commands::new(
        model,
        &module_targets(world, model),
        config.stale_after_s,
        world.config().control_hz,
    );
    let mut lockstep = Lockstep::default();
    lockstep.require_first(config.first_step_waits_for.iter().cloned());
    (commands, lockstep)
}

/// How long after a reset the bridge drops the commands still on their way for the old world
/// before it publishes the new world's first state (the nodes answer a state within
/// milliseconds; their answers to the old world's last one must not drive the new).
const RESET_GRACE: Duration = Duration::from_millis(300);

/// The bridge's sim time [s] after `steps` control steps of `control_dt` [s]: the clock it
/// publishes, the stamp of every message and what it reports.
fn sim_time_s(steps: u64, control_dt: f64) -> f64 {
    steps as f64 * control_dt
}

fn log_rejection(limiter: &mut RateLimited, rejection: &Rejection) {
    if let Some(suppressed) = limiter.check(Instant::now()) {
        if suppressed > 0 {
            warn!("{rejection} ({suppressed} more rejections in the last second)");
        } else {
            warn!("{rejection}");
        }
    }
}

fn diagnostics(
    config: &BridgeConfig,
    steps: u64,
    control_dt: f64,
    rtf: f64,
    counters: &Counters,
    malformed: u64,
    start: Instant,
) -> DiagnosticArray {
    let rejected: u64 = counters.by_kind.values().sum::<u64>() + malformed;
    let mut values = vec![
        KeyValue {
            key: "mode".into(),
            value: match config.mode {
                Mode::RealTime { factor } => format!("realtime x{factor}"),
                Mode::Lockstep { .. } => "lockstep".into(),
            },
        },
        KeyValue {
            key: "control_steps".into(),
            value: steps.to_string(),
        },
        KeyValue {
            key: "sim_time_s".into(),
            value: format!("{:.3}", sim_time_s(steps, control_dt)),
        },
        KeyValue {
            key: "wall_time_s".into(),
            value: format!("{:.3}", start.elapsed().as_secs_f64()),
        },
        KeyValue {
            key: "realtime_factor".into(),
            value: format!("{rtf:.3}"),
        },
        KeyValue {
            key: "rejected_total".into(),
            value: rejected.to_string(),
        },
        KeyValue {
            key: "rejected_malformed".into(),
            value: malformed.to_string(),
        },
        KeyValue {
            key: "clamped".into(),
            value: (counters.clamped + counters.increments_clamped).to_string(),
        },
        KeyValue {
            key: "stale_holds".into(),
            value: counters.stale_holds.to_string(),
        },
        KeyValue {
            key: "lockstep_timeouts".into(),
            value: counters.lockstep_timeouts.to_string(),
        },
        KeyValue {
            key: "late_steps".into(),
            value: counters.late_steps.to_string(),
        },
        KeyValue {
            key: "max_step_late_ms".into(),
            value: format!("{:.1}", counters.max_step_late_s * 1e3),
        },
        KeyValue {
            key: "lockstep_silent".into(),
            value: counters
                .lockstep_silent
                .iter()
                .cloned()
                .collect::<Vec<_>>()
                .join(","),
        },
        KeyValue {
            key: "physics_diverged_at_s".into(),
            value: counters
                .diverged_at_s
                .map(|t| format!("{t:.3}"))
                .unwrap_or_default(),
        },
        KeyValue {
            key: "resets".into(),
            value: counters.resets.to_string(),
        },
    ];
    for kind in [
        "non_finite",
        "wrong_length",
        "unknown_joint",
        "duplicate_joint",
        "wrong_module",
        "too_large",
    ] {
        values.push(KeyValue {
            key: format!("rejected_{kind}"),
            value: counters.by_kind.get(kind).copied().unwrap_or(0).to_string(),
        });
    }
    let level = if counters.diverged_at_s.is_some() {
        DiagnosticStatus::ERROR
    } else if rejected > 0 {
        DiagnosticStatus::WARN
    } else {
        DiagnosticStatus::OK
    };
    DiagnosticArray {
        header: Header {
            stamp: Time::from_seconds(sim_time_s(steps, control_dt)),
            frame_id: String::new(),
        },
        status: vec![DiagnosticStatus {
            level,
            name: format!("kumi sim bridge: {}", config.robot),
            message: if let Some(t) = counters.diverged_at_s {
                format!("the physics blew up at {t:.3} s: reset the world (/{}/reset) or restart the bridge", config.robot)
            } else if rejected > 0 {
                format!("{rejected} commands rejected")
            } else {
                "ok".into()
            },
            hardware_id: config.robot.clone(),
            values,
        }],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use kumi_model::{assemble, load_morphology, ModuleLibrary};

    fn config() -> BridgeConfig {
        let library = ModuleLibrary::shipped();
        let morphology = load_morphology("minimal", &library).unwrap();
        BridgeConfig {
            model: Arc::new(assemble(&morphology, &library)),
            engine: Engine::Rapier,
            robot: "minimal".into(),
            domain_id: 0,
            mode: Mode::RealTime { factor: 1.0 },
            stale_after_s: 0.5,
            duplicate_check: Duration::ZERO,
            first_step_waits_for: Vec::new(),
        }
    }

    #[test]
    fn the_first_step_waits_only_for_modules_of_the_robot() {
        let mut c = config();
        c.first_step_waits_for = vec!["arm0".into(), "leg7".into()];
        let err = check_config(&c).unwrap_err().to_string();
        assert!(
            err.contains("no module `leg7`") && err.contains("its modules: "),
            "{err}"
        );
        c.first_step_waits_for.pop();
        assert!(check_config(&c).is_ok());
    }

    fn status(counters: &Counters, malformed: u64) -> DiagnosticStatus {
        diagnostics(
            &config(),
            90,
            1.0 / 30.0,
            1.0,
            counters,
            malformed,
            Instant::now(),
        )
        .status
        .remove(0)
    }

    fn value<'a>(status: &'a DiagnosticStatus, key: &str) -> &'a str {
        let found = status.values.iter().find(|v| v.key == key);
        &found.unwrap_or_else(|| panic!("no {key}")).value
    }

    #[test]
    fn a_blow_up_is_an_error_above_any_rejection() {
        let mut counters = Counters::default();
        assert_eq!(status(&counters, 0).level, DiagnosticStatus::OK);
        assert_eq!(value(&status(&counters, 0), "physics_diverged_at_s"), "");
        assert_eq!(status(&counters, 2).level, DiagnosticStatus::WARN);
        counters.diverged_at_s = Some(2.5);
        let lost = status(&counters, 2);
        assert_eq!(lost.level, DiagnosticStatus::ERROR);
        assert_eq!(value(&lost, "physics_diverged_at_s"), "2.500");
        assert!(
            lost.message.contains("blew up at 2.500 s"),
            "{}",
            lost.message
        );
    }
}
