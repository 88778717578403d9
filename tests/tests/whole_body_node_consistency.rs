//! The whole-body node feeds its policy what training fed it: for the same simulated state,
//! the observation the node builds from the messages the sim bridge publishes (odometry, each
//! module's joint states) equals the training environment's observation bit for bit, on every
//! shipped robot with a manipulator, step after step of an episode driven by varied actions.

use std::sync::{Arc, Mutex};

use kumi_model::{assemble, load_morphology, ModuleLibrary, RobotModel};
use kumi_msgs::builtin_interfaces::Time;
use kumi_sim_bridge::state;
use kumi_terms::{ActionTerms, GoalBounds, ObservationOptions};
use kumi_train::whole_body::WholeBody;
use kumi_whole_body_node::tick::{ModuleState, Snapshot};
use kumi_whole_body_node::WholeBodyController;
use kumi_worlds::Engine;

fn model(name: &str) -> Arc<RobotModel> {
    let library = ModuleLibrary::shipped();
    Arc::new(assemble(
        &load_morphology(name, &library).unwrap(),
        &library,
    ))
}

const BOUNDS: GoalBounds = GoalBounds {
    manipulator_position_m: 0.25,
    manipulator_rotation_rad: 0.5,
    leg_position_m: 0.1,
    leg_roll_rad: 0.5,
    wheel_velocity_rad_s: None,
    wheel_acceleration_rad_s2: None,
    lateral_acceleration_m_s2: None,
};

/// [`BOUNDS`] with the wheel commands ramped at 3 rad/s^2 (0.1 rad/s per control step).
const RAMPED: GoalBounds = GoalBounds {
    wheel_acceleration_rad_s2: Some(3.0),
    ..BOUNDS
};

/// [`BOUNDS`] with a turn governor low enough to act on almost every step that turns at all.
const GOVERNED: GoalBounds = GoalBounds {
    lateral_acceleration_m_s2: Some(0.01),
    ..BOUNDS
};

/// Table III's slots; with them the base's angular velocity; with both optional slots.
const PLAIN: ObservationOptions = ObservationOptions {
    base_angular_velocity: false,
    arm_joint_angles: false,
};
const SPINNING: ObservationOptions = ObservationOptions {
    base_angular_velocity: true,
    arm_joint_angles: false,
};
const BOTH: ObservationOptions = ObservationOptions {
    base_angular_velocity: true,
    arm_joint_angles: true,
};

fn env(
    model: Arc<RobotModel>,
    engine: Engine,
    bounds: GoalBounds,
    observation: ObservationOptions,
) -> WholeBody {
    let config = kumi_train::whole_body::WholeBodyConfig {
        observation,
        ..kumi_tests::whole_body_config(engine, 3.0, bounds)
    };
    let skill = std::fs::read(kumi_runtime::shipped_arm_policy()).unwrap();
    WholeBody::new(model, config, &skill, 3).unwrap()
}

/// The state as the node gathers it from the bridge's messages for one tick.
fn snapshot(
    world: &dyn kumi_worlds::SimWorld,
    controller: &WholeBodyController,
    robot: &str,
) -> Snapshot {
    let stamp = Time::from_seconds(1.0);
    let odom = state::odometry(world, robot, stamp);
    let base = kumi_whole_body_node::run::base_state(&odom).expect("finite odometry");
    let modules = controller
        .modules()
        .iter()
        .enumerate()
        .map(|(i, module)| {
            let msg = state::joint_state(world, module, stamp).expect("a module with joints");
            let (q, qd) =
                kumi_ros::joint_state::read_named(&msg, module, controller.joint_names(i)).unwrap();
            ModuleState { q, qd }
        })
        .collect();
    Snapshot {
        stamp,
        base,
        modules,
        synchronous: true,
    }
}

/// The node's observations equal training's bit for bit, and so do its wheel commands and
/// those training sent the simulator (with `bounds`' ramp, if any). Under a turn governor the
/// node reads the base's yaw rate back from odometry (turned into the base frame and out
/// again), so its scale may differ from training's in the last bits: there the commands agree
/// within 1e-12 relative, and the governor must have acted. With the optional slots
/// `observation` the node reads the base's angular velocity from odometry.
fn check(name: &str, engine: Engine, bounds: GoalBounds, observation: ObservationOptions) {
    let model = model(name);
    let mut env = env(model.clone(), engine, bounds, observation);
    let seen: Arc<Mutex<Vec<f32>>> = Arc::default();
    let record = seen.clone();
    let size = env.terms().size();
    let mut k = 0u32;
    // A policy whose actions sweep the whole range (and past it, where clipping applies).
    let policy = Box::new(move |obs: &[f32]| {
        *record.lock().unwrap() = obs.to_vec();
        k += 1;
        Ok((0..size)
            .map(|i| (0.7 * (k as f32) + 1.3 * i as f32).sin() * 1.2)
            .collect())
    });
    let terms = ActionTerms::new(&model, &bounds).unwrap();
    let mut controller = WholeBodyController::new(&model, terms, policy)
        .unwrap()
        .with_observation(observation);
    let mut worst = (0.0_f32, String::new());
    let governed = bounds.lateral_acceleration_m_s2.is_some();
    let mut slowed = 0;
    for step in 0..40 {
        controller.set_target(env.target());
        let snap = snapshot(env.world(), &controller, name);
        let decision = controller.step(&snap);
        let node_obs = seen.lock().unwrap().clone();
        let env_obs = env.observation();
        assert_eq!(node_obs.len(), env_obs.len());
        for (i, (a, b)) in node_obs.iter().zip(&env_obs).enumerate() {
            let d = (a - b).abs();
            if d > worst.0 {
                worst = (d, format!("step {step}, value {i}: node {a}, training {b}"));
            }
        }
        let action = decision.action.expect("a target is set: the policy ran");
        let out = env.step(&action);
        assert!(!out.terminated || step > 0, "{name}: fell at once");
        let node_wheels: Vec<f64> = decision.wheel_velocities.iter().map(|w| w.1).collect();
        let wanted = env.terms().commands(&action).unwrap().wheel_velocities;
        slowed += usize::from(
            node_wheels
                .iter()
                .zip(&wanted)
                .any(|(v, w)| v.abs() < w.abs() * (1.0 - 1e-9)),
        );
        let commanded = wheel_commands(env.world());
        let per_module = commanded.len() / node_wheels.len();
        for (m, v) in node_wheels.iter().enumerate() {
            for c in &commanded[m * per_module..(m + 1) * per_module] {
                let tolerance = if governed { 1e-12 * v.abs() } else { 0.0 };
                assert!(
                    (c.abs() - v.abs()).abs() <= tolerance,
                    "{name} ({engine}) step {step}: wheel module {m}: node {v}, training {c}"
                );
            }
        }
    }
    if governed {
        assert!(slowed > 0, "{name} ({engine}): the governor never acted");
    }
    assert!(
        worst.0 == 0.0,
        "{name} ({engine}): the node's observation differs from training's by up to {} ({})",
        worst.0,
        worst.1
    );
}

/// Odometry whose linear or angular twist is not finite is refused (the node logs it and acts
/// on none of it): the turn governor reads the angular twist's yaw rate.
#[test]
fn odometry_with_a_twist_that_is_not_finite_is_refused() {
    let model = model("tricycle");
    let config = kumi_worlds::SimConfig::for_model(&model);
    let world = kumi_worlds::build(Engine::Rapier, model.clone(), config).unwrap();
    let odom = state::odometry(&*world, "tricycle", Time::from_seconds(1.0));
    let read = kumi_whole_body_node::run::base_state;
    assert!(read(&odom).is_some());
    for bad in [f64::NAN, f64::INFINITY] {
        let mut linear = odom.clone();
        linear.twist.twist.linear.y = bad;
        let mut angular = odom.clone();
        angular.twist.twist.angular.z = bad;
        assert!(read(&linear).is_none() && read(&angular).is_none(), "{bad}");
    }
}

/// The simulator's velocity commands [rad/s] of every wheel joint, in actuator order.
fn wheel_commands(world: &dyn kumi_worlds::SimWorld) -> Vec<f64> {
    let modes = world.servos().actuators().iter().map(|a| a.mode);
    modes
        .zip(world.commands())
        .filter(|(mode, _)| *mode == kumi_model::ActuatorMode::Velocity)
        .map(|(_, c)| c)
        .collect()
}

#[test]
fn the_node_observation_equals_training_bit_for_bit_rapier() {
    for name in ["minimal", "dragon", "tricycle"] {
        check(name, Engine::Rapier, BOUNDS, PLAIN);
        check(name, Engine::Rapier, RAMPED, PLAIN);
        check(name, Engine::Rapier, GOVERNED, PLAIN);
        check(name, Engine::Rapier, BOUNDS, SPINNING);
        check(name, Engine::Rapier, BOUNDS, BOTH);
    }
}

#[cfg(feature = "mujoco")]
#[test]
fn the_node_observation_equals_training_bit_for_bit_mujoco() {
    for name in ["minimal", "dragon", "tricycle"] {
        check(name, Engine::Mujoco, BOUNDS, PLAIN);
        check(name, Engine::Mujoco, RAMPED, PLAIN);
        check(name, Engine::Mujoco, GOVERNED, PLAIN);
        check(name, Engine::Mujoco, BOUNDS, SPINNING);
        check(name, Engine::Mujoco, BOUNDS, BOTH);
    }
}

/// The wheel rule the node uses on hardware commands what the simulator's servos are commanded
/// for the same module velocity (sign by mounting, clamp to the limit), on every wheel module.
#[test]
fn wheel_joint_velocities_match_what_the_simulator_commands() {
    for name in ["minimal", "dragon", "tricycle"] {
        let model = model(name);
        let mut world = kumi_worlds::build(
            Engine::Rapier,
            model.clone(),
            kumi_worlds::SimConfig::for_model(&model),
        )
        .unwrap();
        let names: Vec<String> = world
            .actuator_names()
            .iter()
            .map(|s| s.to_string())
            .collect();
        for m in model
            .modules
            .iter()
            .filter(|m| m.velocity_joints().count() > 0)
        {
            for v in [3.0, -1.5, 1e3] {
                world.set_wheel_velocity(&m.name, v).unwrap();
                let commands = world.commands();
                let rule =
                    kumi_model::commands::wheel_joint_velocities(&model, &m.name, v).unwrap();
                for (joint, value) in rule {
                    let i = names.iter().position(|n| *n == joint).unwrap();
                    assert_eq!(commands[i], value, "{name}/{joint} at {v}");
                }
            }
        }
        assert!(kumi_model::commands::wheel_joint_velocities(&model, "nope", 1.0).is_none());
    }
}

#[test]
fn every_goal_a_shipped_whole_body_policy_can_send_is_accepted_by_its_arm_node() {
    // The arm node refuses goals beyond its reach; the whole-body terms send goals anywhere in
    // the box of their bounds around each module's home tool pose. Every corner of every box
    // (position offsets and rotations at their bounds) must pass, or a module silently loses
    // its goals (Dragon's leg did: its home tool is at its full reach).
    use kumi_arm_node::goal::{reach_m, GoalRules};
    use kumi_msgs::geometry_msgs::PoseStamped;
    use kumi_msgs::std_msgs::Header;
    let mut checked = 0;
    for name in ["minimal", "dragon", "tricycle"] {
        let robot = model(name);
        let text = std::fs::read_to_string(
            kumi_tests::workspace().join(format!("train/configs/whole_body/{name}.toml")),
        )
        .unwrap();
        #[derive(serde::Deserialize)]
        struct Config {
            action: GoalBounds,
        }
        let config: Config = toml::from_str(&text).unwrap();
        let terms = ActionTerms::new(&robot, &config.action).unwrap();
        for term in terms.arms() {
            let module = robot.module(&term.module).unwrap();
            let kinematics =
                kumi_policies::kinematics::ToolKinematics::new(&robot, module).unwrap();
            let rules = GoalRules {
                frames: Vec::new(),
                reach: reach_m(&kinematics),
            };
            for corner in 0..(1 << term.width()) {
                let action: Vec<f32> = (0..term.width())
                    .map(|i| if corner >> i & 1 == 1 { 1.0 } else { -1.0 })
                    .collect();
                let goal = term.goal(&action);
                let pose =
                    nalgebra::Isometry3::from_parts(goal.position_b.into(), goal.orientation_b);
                let msg = PoseStamped {
                    header: Header::default(),
                    pose: kumi_ros::geometry::pose(&pose),
                };
                rules
                    .accept(&msg)
                    .unwrap_or_else(|e| panic!("{name}/{}: corner {action:?}: {e}", term.module));
                checked += 1;
            }
        }
    }
    // Minimal 64, Dragon 64 + 16, Tricycle 64 + 3 x 16.
    assert_eq!(checked, 64 + 80 + 112);
}
