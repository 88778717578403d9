//! `kumi robot`: what a user needs to know of a robot before training it. Its modules and
//! roles, its mass, each arm module's home tool pose and standing height, the sizes of its
//! whole-body policy, its tilt standing at home and whether it stands on the skill (the
//! `kumi sim --skill-on all` check), and which config values a robot kumi does not ship
//! needs.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Args;
use kumi_model::{RobotModel, Role};
use kumi_policies::kinematics::ToolKinematics;
use kumi_policies::observation::JOINTS;
use kumi_policies::skill::ArmSkill;
use kumi_worlds::Engine;
use serde::Serialize;

use crate::sim::{load_model, simulate, PhysicsArgs, SimArgs};
use crate::train::{body_config_for, TrainBodyConfig, Variant, DEFAULT_RECIPE_ROBOT};

/// How long the robot stands on the skill for the check [s] (as `kumi sim`'s default).
const STANDING_S: f64 = 10.0;
/// How long it settles on its servos at home before its tilt is read [s].
const SETTLE_S: f64 = 2.0;
/// Holding still on the skill: arm joints no faster than this after the first second [rad/s]
/// and the base no further than [`STILL_TRAVEL_M`] (the standing bounds of issue 67's settled
/// skill).
const STILL_JOINT_SPEED_RAD_S: f64 = 0.3;
const STILL_TRAVEL_M: f64 = 0.02;

#[derive(Args, Debug)]
pub struct RobotArgs {
    /// `minimal`, `dragon`, `tricycle`, or a morphology file.
    pub morphology: String,
    /// The whole-body config whose terms size the policy (default: the robot's shipped one,
    /// else Dragon's, the one to start a new robot's from).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The engine of the standing check: rapier (default) or mujoco (with `--features mujoco`).
    #[arg(long, value_parser = crate::engine::parse)]
    pub engine: Option<Engine>,
    /// Leave out the standing check on the skill (10 s of simulation).
    #[arg(long)]
    pub no_standing: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(Debug, Serialize)]
struct ModuleSummary {
    name: String,
    kind: String,
    role: String,
    /// The module it is mounted to (none: the base).
    parent: Option<String>,
    position_joints: usize,
    wheels: usize,
}

#[derive(Debug, Serialize)]
struct ArmSummary {
    module: String,
    role: String,
    /// The tool's position at the home angles in the module's base frame [m].
    home_tool_b_m: [f64; 3],
    /// The tool's height above the ground with the robot standing at home [m].
    standing_tool_height_m: f64,
}

#[derive(Debug, Serialize)]
struct Standing {
    engine: String,
    seconds: f64,
    /// The config's tilt limit [rad]: past it, training counts a fall.
    tilt_limit_rad: f64,
    /// The base stayed below the tilt limit.
    stands: bool,
    /// It also held still: arm joints at most 0.3 rad/s after the first second, the base within
    /// 0.02 m of where it started.
    still: bool,
    max_tilt_rad: f64,
    base_travel_xy_m: f64,
    arm_joint_speed_after_1s_max_rad_s: f64,
    arm_target_lead_after_1s_max_rad: f64,
    wheel_modules_off_ground_mean: f64,
}

#[derive(Debug, Serialize)]
struct RobotSummary {
    robot: String,
    mass_kg: f64,
    modules: Vec<ModuleSummary>,
    arms: Vec<ArmSummary>,
    /// The config the policy's sizes come from.
    config: String,
    observations: usize,
    actions: usize,
    /// The base's largest tilt settling 2 s on its servos at home [rad].
    tilt_at_home_rad: f64,
    standing: Option<Standing>,
    /// What a config for this robot should set, when it has none of its own.
    advice: Vec<String>,
}

pub fn run(args: RobotArgs) -> Result<()> {
    let model = load_model(&args.morphology)?;
    let summary = summarise(&model, &args)?;
    if args.json {
        println!("{}", serde_json::to_string(&summary)?);
    } else {
        print(&summary);
    }
    Ok(())
}

fn summarise(model: &RobotModel, args: &RobotArgs) -> Result<RobotSummary> {
    let (config, label, own_config) = config_for(model, args)?;
    let terms = config.arms()?.terms(model)?;
    let control_hz = kumi_worlds::SimConfig::for_model(model).control_hz;
    let skill = std::fs::read(kumi_runtime::shipped_arm_policy()).context("reading the skill")?;
    let contract =
        kumi_terms::contract::contract(model, &terms, config.observation, &skill, control_hz);
    let size =
        |key: &str| -> Result<usize> { contract[key].parse().context("a size in the contract") };
    let arms = arm_summaries(model)?;
    let sim = |seconds: f64, skill_on: Vec<String>| {
        simulate(&SimArgs {
            morphology: args.morphology.clone(),
            seconds,
            wheel_velocity: 0.0,
            skill_on,
            skill: None,
            leg_roll: 0.0,
            max_lead_rad: None,
            json: true,
            physics: PhysicsArgs {
                engine: args.engine,
                ..PhysicsArgs::default()
            },
        })
    };
    let tilt_at_home_rad = sim(SETTLE_S, Vec::new())?.max_tilt_rad;
    let limit = config.task.tilt_limit_rad;
    let standing = if args.no_standing || arms.is_empty() {
        None
    } else {
        let r = sim(STANDING_S, vec!["all".into()])?;
        Some(Standing {
            engine: r.engine.clone(),
            seconds: STANDING_S,
            tilt_limit_rad: limit,
            stands: r.finite && r.max_tilt_rad < limit,
            still: r.finite
                && r.arm_joint_speed_after_1s_max_rad_s <= STILL_JOINT_SPEED_RAD_S
                && r.base_travel_xy_m <= STILL_TRAVEL_M,
            max_tilt_rad: r.max_tilt_rad,
            base_travel_xy_m: r.base_travel_xy_m,
            arm_joint_speed_after_1s_max_rad_s: r.arm_joint_speed_after_1s_max_rad_s,
            arm_target_lead_after_1s_max_rad: r.arm_target_lead_after_1s_max_rad,
            wheel_modules_off_ground_mean: r.wheel_modules_off_ground_mean,
        })
    };
    let advice = if own_config {
        Vec::new()
    } else {
        advice(&args.morphology, &config)
    };
    Ok(RobotSummary {
        robot: model.name.clone(),
        mass_kg: model.urdf.links.iter().map(|l| l.inertial.mass.value).sum(),
        modules: model
            .modules
            .iter()
            .map(|m| ModuleSummary {
                name: m.name.clone(),
                kind: m.kind.clone(),
                role: m.role.to_string(),
                parent: m.parent.clone(),
                position_joints: m.position_joints().count(),
                wheels: m.velocity_joints().count(),
            })
            .collect(),
        arms,
        config: label,
        observations: size(kumi_policies::metadata::OBSERVATION_DIM_KEY)?,
        actions: size(kumi_policies::metadata::ACTION_DIM_KEY)?,
        tilt_at_home_rad,
        standing,
        advice,
    })
}

/// The config that sizes the policy, where it came from, and whether it is the robot's own
/// (given, or shipped for it) rather than the default recipe.
fn config_for(model: &RobotModel, args: &RobotArgs) -> Result<(TrainBodyConfig, String, bool)> {
    let chosen = body_config_for(model, args.config.as_deref(), Variant::Hierarchical, false)?;
    Ok((chosen.config, chosen.label, !chosen.default_recipe))
}

/// The manipulator tool's height above the ground with the robot standing at home [m]
/// (`None`: the robot has no manipulator module).
pub fn manipulator_standing_height_m(model: &RobotModel) -> Result<Option<f64>> {
    Ok(arm_summaries(model)?
        .into_iter()
        .find(|a| a.role == Role::Manipulator.to_string())
        .map(|a| a.standing_tool_height_m))
}

/// Each arm module's home tool pose, and its tool's height with the robot standing at home.
fn arm_summaries(model: &RobotModel) -> Result<Vec<ArmSummary>> {
    let sim = kumi_worlds::SimConfig::for_model(model);
    let world = kumi_worlds::build(Engine::Rapier, std::sync::Arc::new(model.clone()), sim)
        .context("building the robot standing at home")?;
    model
        .modules
        .iter()
        .filter(|m| ArmSkill::new(m, sim.control_hz).is_ok())
        .map(|m| {
            let home: [f64; JOINTS] =
                std::array::from_fn(|j| m.home.get(j).copied().unwrap_or(0.0));
            let tool_b = ToolKinematics::new(model, m)
                .map_err(anyhow::Error::msg)?
                .tool_pose_b(&home)
                .translation
                .vector;
            let ee = m.ee_link.as_deref().unwrap_or_default();
            Ok(ArmSummary {
                module: m.name.clone(),
                role: m.role.to_string(),
                home_tool_b_m: tool_b.into(),
                standing_tool_height_m: world.link_pose(ee)?.translation.z,
            })
        })
        .collect()
}

/// What to know about training a robot on the default recipe, and what a config of its own
/// would set instead.
fn advice(morphology: &str, config: &TrainBodyConfig) -> Vec<String> {
    let [lo, hi] = config.task.target_z_m;
    vec![
        format!(
            "no config needed: `kumi train whole-body {morphology}` trains on the default recipe (train/configs/whole_body/{DEFAULT_RECIPE_ROBOT}.toml), its targets at {lo:.2}-{hi:.2} m ({DEFAULT_RECIPE_ROBOT}'s, moved with the manipulator's standing tool height)"
        ),
        format!(
            "a config of its own (--config FILE, every key in docs/config-reference.md) would set [task] tilt_limit_rad, the tilt this robot should not pass (the recipe's: {} rad), and target_z_m where its targets should be",
            config.task.tilt_limit_rad
        ),
    ]
}

fn print(s: &RobotSummary) {
    println!(
        "{}: {} modules, {:.1} kg",
        s.robot,
        s.modules.len(),
        s.mass_kg
    );
    for m in &s.modules {
        println!(
            "  {:<11} {:<6} {:<12} on {:<11} {} joints, {} wheels",
            m.name,
            m.kind,
            m.role,
            m.parent.as_deref().unwrap_or("the base"),
            m.position_joints,
            m.wheels
        );
    }
    for a in &s.arms {
        let p = a.home_tool_b_m;
        println!(
            "  {:<11} home tool at ({:.3}, {:.3}, {:.3}) m in its base frame, {:.3} m above the ground standing",
            a.module, p[0], p[1], p[2], a.standing_tool_height_m
        );
    }
    println!(
        "  whole-body policy: {} observations, {} actions ({})",
        s.observations, s.actions, s.config
    );
    println!(
        "  tilt at home       {:.3} rad after {SETTLE_S} s on its servos",
        s.tilt_at_home_rad
    );
    if let Some(st) = &s.standing {
        println!(
            "  on the skill       {} for {} s ({}): tilt {:.3} rad (limit {}), base travel {:.3} m, arm joints up to {:.2} rad/s after 1 s, targets up to {:.3} rad ahead, {:.2} wheel modules off the ground per step",
            match (st.stands, st.still) {
                (true, true) => "stands still",
                (true, false) => "stands, but does not hold still,",
                (false, _) => "TIPS OVER",
            },
            st.seconds,
            st.engine,
            st.max_tilt_rad,
            st.tilt_limit_rad,
            st.base_travel_xy_m,
            st.arm_joint_speed_after_1s_max_rad_s,
            st.arm_target_lead_after_1s_max_rad,
            st.wheel_modules_off_ground_mean
        );
    }
    for a in &s.advice {
        println!("  config: {a}");
    }
}
