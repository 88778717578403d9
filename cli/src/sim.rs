//! `kumi sim`: simulate a morphology and report stability, motion and contacts.

use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use kumi_model::{assemble, load_morphology, ModuleInstance, ModuleLibrary, RobotModel, Role};
use kumi_policies::kinematics::ToolKinematics;
use kumi_policies::observation::{self, Goal, JOINTS};
use kumi_policies::rotation::orientation_error;
use kumi_policies::skill::ArmSkill;

use kumi_runtime::{BackendChoice, SkillPolicy};
use kumi_terms::{ArmGoalTerm, GoalBounds};
use kumi_worlds::{Engine, Layout, SimConfig, SimWorld};
use serde::Serialize;

/// Loads and assembles a morphology by shipped name or file path.
pub fn load_model(morphology: &str) -> Result<Arc<RobotModel>> {
    let library = ModuleLibrary::shipped();
    let morphology = load_morphology(morphology, &library)?;
    Ok(Arc::new(assemble(&morphology, &library)))
}

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum LayoutArg {
    SingleMultibody,
    PerLimb,
    PerModule,
}

impl From<LayoutArg> for Layout {
    fn from(l: LayoutArg) -> Self {
        match l {
            LayoutArg::SingleMultibody => Layout::SingleMultibody,
            LayoutArg::PerLimb => Layout::PerLimb,
            LayoutArg::PerModule => Layout::PerModule,
        }
    }
}

/// Physics overrides shared by `sim` and `bench`; unset, a robot is simulated with
/// [`SimConfig::for_model`] (the defaults and its morphology's `[physics]` table).
#[derive(Args, Clone, Debug, Default)]
pub struct PhysicsArgs {
    /// Physics engine: rapier (default) or mujoco (with `--features mujoco`).
    #[arg(long, value_parser = crate::engine::parse)]
    pub engine: Option<Engine>,
    /// Articulation layout (default: the morphology's).
    #[arg(long, value_enum)]
    pub layout: Option<LayoutArg>,
    /// Physics steps per control step (rapier).
    #[arg(long)]
    pub substeps: Option<u32>,
    /// Physics steps per control step in MuJoCo (default: 4, or the morphology's).
    #[arg(long)]
    pub mujoco_substeps: Option<u32>,
    /// Solver iterations per physics step.
    #[arg(long)]
    pub iterations: Option<u32>,
    /// Velocity-only stabilisation passes per physics step.
    #[arg(long)]
    pub stabilization: Option<u32>,
}

impl PhysicsArgs {
    pub fn config(&self, model: &RobotModel) -> SimConfig {
        let mut c = SimConfig::for_model(model);
        if let Some(l) = self.layout {
            c.layout = l.into();
        }
        if let Some(s) = self.substeps {
            c.substeps = s;
        }
        if let Some(s) = self.mujoco_substeps {
            c.mujoco_substeps = s;
        }
        if let Some(i) = self.iterations {
            c.solver_iterations = i;
        }
        if let Some(s) = self.stabilization {
            c.stabilization_iterations = s;
        }
        c
    }
}

#[derive(Args, Debug)]
pub struct SimArgs {
    /// `minimal`, `dragon`, `tricycle`, `arm`, or a path to a morphology file.
    pub morphology: String,
    /// Simulated duration [s].
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Velocity for every wheel module [rad/s], signed so that each drives the base along +x.
    #[arg(long, default_value_t = 0.0)]
    pub wheel_velocity: f64,
    /// Arm modules that run the frozen skill toward their home tool pose, as the upper level's
    /// neutral goal would ask (comma-separated, or `all`); the others hold their home angles on
    /// their servos. Does the robot stand on the skill?
    #[arg(long, value_delimiter = ',')]
    pub skill_on: Vec<String>,
    /// The skill for `--skill-on` (default: the shipped policies/arm_reach/arm_reach.onnx).
    #[arg(long)]
    pub skill: Option<std::path::PathBuf>,
    /// Legs on the skill are asked to roll their tools by this angle [rad] about the tool's own
    /// x axis, by the whole-body leg term's rule (the roll that steers a wheel module at a leg's
    /// tip). The report says how far each module's tool ends from its goal.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub leg_roll: f64,
    /// Keep each skill-driven joint's position target within this of its angle [rad]
    /// (`kumi_model::commands::bound_lead`): what a bound on targets wound up against a load
    /// would do. Nothing else applies it yet; a skill trained in free space never leads its
    /// joints by more than about 0.05 rad.
    #[arg(long)]
    pub max_lead_rad: Option<f64>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub physics: PhysicsArgs,
}

/// One arm module driven by the frozen skill toward a fixed goal in its base frame.
struct SkillDriver {
    module: String,
    joints: std::ops::Range<usize>,
    actuators: Vec<kumi_model::Actuator>,
    max_lead_rad: Option<f64>,
    skill: ArmSkill,
    policy: SkillPolicy,
    kinematics: ToolKinematics,
    goal: Goal,
}

/// How far a skill-driven module's tool ended from its goal.
#[derive(Serialize)]
struct Tracking {
    module: String,
    /// Distance from the tool to its goal position [m].
    position_error_m: f64,
    /// Angle between the tool's orientation and its goal's [rad], the skill's own measure.
    orientation_error_rad: f64,
    /// The module's joint angles at the end [rad].
    joints_rad: [f64; JOINTS],
}

impl SkillDriver {
    /// Every arm module named in `names` (`all`: every arm module), each with its home tool
    /// pose as its goal, a leg's rolled by `leg_roll_rad` about its tool's x axis.
    fn for_modules(
        model: &RobotModel,
        world: &dyn SimWorld,
        names: &[String],
        skill_path: &std::path::Path,
        control_hz: f64,
        leg_roll_rad: f64,
        max_lead_rad: Option<f64>,
    ) -> Result<Vec<Self>> {
        let all = names.iter().any(|n| n == "all");
        let bytes = std::fs::read(skill_path)
            .with_context(|| format!("reading the skill {}", skill_path.display()))?;
        let mut drivers = Vec::new();
        for name in names.iter().filter(|n| *n != "all") {
            if model.module(name).is_none() {
                bail!("--skill-on: {} has no module `{name}`", model.name);
            }
        }
        for m in model.modules.iter().filter(|m| {
            m.ee_link.is_some()
                && m.velocity_joints().next().is_none()
                && (all || names.contains(&m.name))
        }) {
            let skill = ArmSkill::new(m, control_hz)?;
            let policy = SkillPolicy::from_bytes(
                bytes.clone(),
                &skill_path.display().to_string(),
                &skill,
                BackendChoice::Tract,
            )?;
            drivers.push(Self {
                module: m.name.clone(),
                joints: world.module_range(&m.name)?,
                actuators: m.position_joints().cloned().collect(),
                max_lead_rad,
                skill,
                policy,
                kinematics: ToolKinematics::new(model, m).map_err(anyhow::Error::msg)?,
                goal: goal_for(model, m, leg_roll_rad)?,
            });
        }
        for name in names.iter().filter(|n| *n != "all") {
            if !drivers.iter().any(|d| &d.module == name) {
                bail!(
                    "--skill-on: `{name}` is not an arm module of {}",
                    model.name
                );
            }
        }
        Ok(drivers)
    }

    /// Observes the module, runs the skill and applies its increments (the arm node's rule).
    fn act(&mut self, world: &mut dyn SimWorld) -> Result<()> {
        let (q, qd, targets) = (
            world.joint_positions(),
            world.joint_velocities(),
            world.commands(),
        );
        let fk = |q: &[f64; JOINTS]| self.kinematics.tool_pose_b(q);
        let observation = observation::build(
            &self.at(&q),
            &self.at(&qd),
            &self.at(&targets),
            &self.goal,
            &fk,
            self.kinematics.limits_rad(),
        );
        let action = self.policy.act(&observation)?;
        let increments = self.skill.increments(&action);
        match self.max_lead_rad {
            None => world.apply_increments(&self.module, &increments)?,
            Some(bound) => {
                let actuators: Vec<&kumi_model::Actuator> = self.actuators.iter().collect();
                let next = kumi_model::commands::apply_increments(
                    &self.at(&targets),
                    &increments,
                    &actuators,
                )
                .context("the skill's increments")?;
                let next = kumi_model::commands::bound_lead(&next, &q, bound);
                world.set_position_targets(&self.module, &next)?;
            }
        }
        Ok(())
    }

    /// This module's values of a whole-robot joint vector.
    fn at(&self, v: &[f64]) -> [f64; JOINTS] {
        std::array::from_fn(|j| v[self.joints.start + j])
    }

    /// Where the tool is now against its goal.
    fn tracking(&self, world: &dyn SimWorld) -> Tracking {
        let q = self.at(&world.joint_positions());
        let tool = self.kinematics.tool_pose_b(&q);
        Tracking {
            module: self.module.clone(),
            position_error_m: (tool.translation.vector - self.goal.position_b).norm(),
            orientation_error_rad: orientation_error(&self.goal.orientation_b, &tool.rotation),
            joints_rad: q,
        }
    }
}

/// The goal of an arm module on the skill in `kumi sim`: its home tool pose, a leg's rolled by
/// `leg_roll_rad` through the whole-body leg term (so the rule is the one training uses).
fn goal_for(model: &RobotModel, module: &ModuleInstance, leg_roll_rad: f64) -> Result<Goal> {
    let bounds = GoalBounds {
        manipulator_position_m: 0.0,
        manipulator_rotation_rad: 0.0,
        leg_position_m: 0.0,
        leg_roll_rad: leg_roll_rad.abs(),
        wheel_velocity_rad_s: None,
        wheel_acceleration_rad_s2: None,
        lateral_acceleration_m_s2: None,
    };
    let term = ArmGoalTerm::new(model, module, &bounds)?;
    let mut action = vec![0.0_f32; term.width()];
    if term.role == Role::Leg {
        action[3] = leg_roll_rad.signum() as f32;
    }
    Ok(term.goal(&action))
}

#[derive(Serialize)]
pub struct SimReport {
    pub morphology: String,
    pub engine: String,
    config: String,
    seconds: f64,
    control_hz: f64,
    /// Arm modules that ran the frozen skill toward their home tool pose.
    skill_on: Vec<String>,
    /// Roll asked of the legs on the skill [rad].
    leg_roll_rad: f64,
    /// The bound on the targets' lead (`--max-lead-rad`; `null`: none).
    max_lead_rad: Option<f64>,
    /// Each skill-driven module's tool against its goal at the end.
    skill_tracking: Vec<Tracking>,
    control_steps: u64,
    wall_s: f64,
    realtime_factor: f64,
    base_start_m: [f64; 3],
    base_end_m: [f64; 3],
    pub base_travel_xy_m: f64,
    pub max_tilt_rad: f64,
    lowest_point_m: f64,
    max_mount_error_m: f64,
    max_mount_error_rad: f64,
    max_joint_speed_rad_s: f64,
    /// The arm joints' speeds after the first second (the start's transient): their mean and
    /// largest absolute value over every arm joint and control step [rad/s]
    /// (`kumi_policies::settle::SpeedTally`; NaN for a run no longer than a second).
    arm_joint_speed_after_1s_mean_rad_s: f64,
    pub arm_joint_speed_after_1s_max_rad_s: f64,
    /// How far the arm joints' position targets lead their angles after the first second:
    /// mean and largest absolute value [rad]. A servo reaches its effort limit a few mrad
    /// from its target at rest, so a larger lead at rest is a command wound up against a load
    /// it cannot move.
    arm_target_lead_after_1s_mean_rad: f64,
    pub arm_target_lead_after_1s_max_rad: f64,
    pub finite: bool,
    ground_contacts_at_end: Vec<String>,
    /// Wheel modules with no wheel on the ground, mean over the control steps (0 without
    /// wheel modules).
    pub wheel_modules_off_ground_mean: f64,
    /// Share of the control steps on which every wheel module touched the ground.
    all_wheel_modules_down_share: f64,
}

pub fn run(args: SimArgs) -> Result<()> {
    let report = simulate(&args)?;
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print_report(&report);
    }
    Ok(())
}

/// Simulates what `args` asks and measures it.
pub fn simulate(args: &SimArgs) -> Result<SimReport> {
    if !(args.seconds.is_finite() && args.seconds > 0.0) {
        bail!(
            "--seconds must be a positive number of seconds, got {}",
            args.seconds
        );
    }
    if !(args.leg_roll.is_finite() && args.leg_roll.abs() <= std::f64::consts::PI) {
        bail!(
            "--leg-roll must be an angle in [-pi, pi] rad, got {}",
            args.leg_roll
        );
    }
    if args
        .max_lead_rad
        .is_some_and(|b| !(b.is_finite() && b > 0.0))
    {
        bail!("--max-lead-rad must be a positive angle [rad]");
    }
    let model = load_model(&args.morphology)?;
    let config = args.physics.config(&model);
    let engine = crate::engine::choose(args.physics.engine, Engine::Rapier)?;
    let mut world =
        crate::engine::world(engine, model.clone(), config).context("building the world")?;
    // Positive drives the base along +x, however each module is mounted (the world's rule).
    for m in model
        .modules
        .iter()
        .filter(|m| m.velocity_joints().next().is_some())
    {
        world.set_wheel_velocity(&m.name, args.wheel_velocity)?;
    }
    let skill_path = args
        .skill
        .clone()
        .unwrap_or_else(kumi_runtime::shipped_arm_policy);
    let mut drivers = if args.skill_on.is_empty() {
        Vec::new()
    } else {
        SkillDriver::for_modules(
            &model,
            world.as_ref(),
            &args.skill_on,
            &skill_path,
            config.control_hz,
            args.leg_roll,
            args.max_lead_rad,
        )?
    };
    let start = world.base_pose().translation.vector;
    let steps = (args.seconds * config.control_hz).round() as u64;
    let (mut max_tilt, mut lowest, mut mount_m, mut mount_rad, mut max_speed) =
        (0.0_f64, f64::INFINITY, 0.0_f64, 0.0_f64, 0.0_f64);
    let mut finite = true;
    let (mut off_ground, mut all_down) = (0_usize, 0_u64);
    let arm_joint: Vec<bool> = model
        .actuators()
        .map(|a| a.mode == kumi_model::ActuatorMode::Position)
        .collect();
    let speed_after_step =
        (kumi_policies::settle::SPEED_AFTER_S * config.control_hz).round() as u64;
    let mut arm_speeds = kumi_policies::settle::SpeedTally::default();
    let mut arm_leads = kumi_policies::settle::SpeedTally::default();
    let wall = Instant::now();
    for step in 0..steps {
        for driver in drivers.iter_mut() {
            driver.act(world.as_mut())?;
        }
        world.step();
        max_tilt = max_tilt.max(world.base_tilt());
        lowest = lowest.min(world.lowest_collider_z());
        for (_, m, r) in world.mount_errors() {
            mount_m = mount_m.max(m);
            mount_rad = mount_rad.max(r);
        }
        let v = world.joint_velocities();
        finite &= v.iter().all(|x| x.is_finite())
            && world
                .base_pose()
                .translation
                .vector
                .iter()
                .all(|x| x.is_finite());
        max_speed = v.iter().fold(max_speed, |a, x| a.max(x.abs()));
        if step >= speed_after_step {
            let arm = |values: Vec<f64>| {
                values
                    .into_iter()
                    .zip(&arm_joint)
                    .filter(|(_, arm)| **arm)
                    .map(|(x, _)| x)
            };
            arm_speeds.add(arm(v.clone()));
            let q = world.joint_positions();
            arm_leads.add(arm(world.commands()).zip(arm(q)).map(|(t, q)| t - q));
        }
        let off = world.wheel_modules_off_ground();
        off_ground += off;
        all_down += u64::from(off == 0);
    }
    let wall_s = wall.elapsed().as_secs_f64();
    let end = world.base_pose().translation.vector;
    let (arm_speeds, arm_leads) = (arm_speeds.stats(), arm_leads.stats());
    let report = SimReport {
        morphology: model.name.clone(),
        engine: engine.to_string(),
        config: config.label_for(engine),
        seconds: args.seconds,
        control_hz: config.control_hz,
        skill_on: drivers.iter().map(|d| d.module.clone()).collect(),
        leg_roll_rad: args.leg_roll,
        max_lead_rad: args.max_lead_rad,
        skill_tracking: drivers.iter().map(|d| d.tracking(world.as_ref())).collect(),
        control_steps: steps,
        wall_s,
        realtime_factor: args.seconds / wall_s,
        base_start_m: start.into(),
        base_end_m: end.into(),
        base_travel_xy_m: (end - start).xy().norm(),
        max_tilt_rad: max_tilt,
        lowest_point_m: lowest,
        max_mount_error_m: mount_m,
        max_mount_error_rad: mount_rad,
        max_joint_speed_rad_s: max_speed,
        arm_joint_speed_after_1s_mean_rad_s: arm_speeds.mean,
        arm_joint_speed_after_1s_max_rad_s: arm_speeds.max,
        arm_target_lead_after_1s_mean_rad: arm_leads.mean,
        arm_target_lead_after_1s_max_rad: arm_leads.max,
        finite,
        ground_contacts_at_end: world.ground_contacts(),
        wheel_modules_off_ground_mean: off_ground as f64 / steps.max(1) as f64,
        all_wheel_modules_down_share: all_down as f64 / steps.max(1) as f64,
    };
    Ok(report)
}

/// Prints a report as a table.
fn print_report(report: &SimReport) {
    let (start, end) = (report.base_start_m, report.base_end_m);
    println!(
        "{} for {} s simulated ({} control steps at {} Hz, {} physics {})",
        report.morphology,
        report.seconds,
        report.control_steps,
        report.control_hz,
        report.engine,
        report.config
    );
    if !report.skill_on.is_empty() {
        println!(
            "  on the skill        {} (toward their home tool poses, legs rolled {} rad)",
            report.skill_on.join(", "),
            report.leg_roll_rad
        );
        for t in &report.skill_tracking {
            println!(
                "    {:<8} tool {:.4} m, {:.3} rad from its goal; joints {:.2?} rad",
                t.module, t.position_error_m, t.orientation_error_rad, t.joints_rad
            );
        }
    }
    println!(
        "  wall time           {:.2} s ({:.1}x real time)",
        report.wall_s, report.realtime_factor
    );
    println!(
        "  base start -> end   [{:.3}, {:.3}, {:.3}] -> [{:.3}, {:.3}, {:.3}] m",
        start[0], start[1], start[2], end[0], end[1], end[2]
    );
    println!("  base travel (xy)    {:.4} m", report.base_travel_xy_m);
    println!(
        "  max base tilt       {:.4} rad ({:.2} deg)",
        report.max_tilt_rad,
        report.max_tilt_rad.to_degrees()
    );
    println!(
        "  lowest point        {:.4} m (negative: below the ground)",
        report.lowest_point_m
    );
    println!(
        "  max mount error     {:.5} m, {:.3} deg",
        report.max_mount_error_m,
        report.max_mount_error_rad.to_degrees()
    );
    println!(
        "  max joint speed     {:.3} rad/s",
        report.max_joint_speed_rad_s
    );
    println!(
        "  arm joints after 1 s {:.3} rad/s mean, {:.3} rad/s max",
        report.arm_joint_speed_after_1s_mean_rad_s, report.arm_joint_speed_after_1s_max_rad_s
    );
    println!(
        "  targets' lead after 1 s {:.4} rad mean, {:.4} rad max",
        report.arm_target_lead_after_1s_mean_rad, report.arm_target_lead_after_1s_max_rad
    );
    println!("  all values finite   {}", report.finite);
    println!(
        "  touching the ground {}",
        report.ground_contacts_at_end.join(", ")
    );
    println!(
        "  wheel modules off   {:.3} per control step; all down on {:.1} % of the steps",
        report.wheel_modules_off_ground_mean,
        100.0 * report.all_wheel_modules_down_share
    );
}
