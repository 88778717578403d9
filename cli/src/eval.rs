//! `kumi eval arm`: the shipped (or any) arm skill through the policy runtime, in the paper's
//! protocol.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use kumi_policies::goals::GoalDistribution;
use kumi_policies::skill::ArmSkill;
use kumi_runtime::{BackendChoice, RuntimeError, SkillPolicy, WholeBodyPolicy};
use kumi_train::arm_reach::ArmReachConfig;
use kumi_train::evaluate::evaluate;
use kumi_train::evaluate_body::{Episode, Protocol, TraceStep};
use kumi_train::whole_body::{PushConfig, WholeBodyConfig};

use crate::sim::load_model;

#[derive(Subcommand, Debug)]
pub enum EvalCommand {
    /// The low-level skill: final tool errors at the end of each 4 s goal (the paper's section IV-A).
    Arm(EvalArmArgs),
    /// A whole-body policy over the frozen skill: final tool errors, leg orientation,
    /// undesired contacts and falls over whole episodes (the paper's section V-C).
    WholeBody(EvalBodyArgs),
}

#[derive(Args, Debug)]
pub struct EvalBodyArgs {
    /// `minimal`, `dragon`, `tricycle`, or a path to a morphology file.
    pub morphology: String,
    /// Which policy: over the skill, or a baseline (picks the default policy and config).
    #[arg(long, value_enum, default_value_t)]
    pub variant: crate::train::Variant,
    /// The ONNX policy (default: the shipped one of the variant, e.g.
    /// policies/<robot>_whole_body/<robot>_whole_body.onnx or policies/<robot>_flat/<robot>_flat.onnx).
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// The training config the policy was trained with (task and action bounds; default:
    /// the one the shipped policy of the robot and variant finished its training with, e.g.
    /// train/configs/whole_body/tricycle_sixth.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The frozen skill (default: the shipped policies/arm_reach/arm_reach.onnx).
    #[arg(long)]
    pub skill: Option<PathBuf>,
    /// Episodes to evaluate.
    #[arg(long, default_value_t = 1000)]
    pub rollouts: usize,
    /// Seed of the episodes (start poses, targets).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Inference backend for the whole-body policy: auto, onnxruntime or tract.
    #[arg(long, default_value = "auto")]
    pub backend: BackendChoice,
    /// Physics engines to evaluate in, one report each (e.g. `rapier,mujoco`; default: the
    /// training engine).
    #[arg(long, value_delimiter = ',', value_parser = crate::engine::parse)]
    pub engine: Vec<kumi_worlds::Engine>,
    /// Print one JSON object (an array for several engines) instead of markdown.
    #[arg(long)]
    pub json: bool,
    /// Also write every episode to this CSV: its start, closest and final tool errors, yaw
    /// error, leg orientation, contact steps, length, whether it fell and whether its physics
    /// blew up (a column names the engine).
    #[arg(long)]
    pub episodes: Option<PathBuf>,
    /// Also write every control step of the first `--traced` episodes to this CSV: base pose,
    /// tool pose, target and errors, in the world frame; the base's tilt, horizontal speed and
    /// yaw rate, the turn governor's scale for them, the links on the ground and the action
    /// (a column names the engine).
    #[arg(long)]
    pub trace: Option<PathBuf>,
    /// How many episodes `--trace` and `--trace-plot` record.
    #[arg(long, default_value_t = 10)]
    pub traced: usize,
    /// Also draw the first `--traced` episodes as SVG in this directory (made if missing), per
    /// engine: `<engine>_paths.svg`, a top view of each episode's base path and its target, and
    /// `<engine>_tilt.svg`, the base's tilt over time against the tilt that ends an episode.
    /// Episodes that fell are black, with the time they fell (or their physics blew up) in the
    /// legend.
    #[arg(long)]
    pub trace_plot: Option<PathBuf>,
    /// Standard deviation of Gaussian noise added to every action value (policy units, before
    /// the terms clip and scale it), as training explores: how the policy fares off its mean.
    /// 0 runs the deterministic policy.
    #[arg(long, default_value_t = 0.0, value_parser = non_negative)]
    pub action_noise: f64,
    /// Shove the robot as `[push]` does in training: its horizontal velocity jumps by x and y
    /// each uniform in [-V, V] [m/s] every `--push-interval-s`: how the policy recovers. 0 (the
    /// default, with `--push-tip-rad-s` 0) evaluates the task without pushes, whatever the
    /// config's `[push]` says.
    #[arg(long, default_value_t = 0.0, value_parser = non_negative)]
    pub push_m_s: f64,
    /// With the pushes, the robot starts to tip about the world's x and y axes through its
    /// base at rates each uniform in [-W, W] [rad/s].
    #[arg(long, default_value_t = 0.0, value_parser = non_negative)]
    pub push_tip_rad_s: f64,
    /// The time between pushes [s], uniform in LO,HI.
    #[arg(long, value_delimiter = ',', default_values_t = [4.0, 8.0])]
    pub push_interval_s: Vec<f64>,
}

impl EvalBodyArgs {
    /// The pushes `--push-*` ask for (none when both sizes are 0: `kumi report compare`
    /// evaluates without pushes and passes no interval).
    pub(crate) fn push(&self) -> Result<Option<PushConfig>> {
        if self.push_m_s == 0.0 && self.push_tip_rad_s == 0.0 {
            return Ok(None);
        }
        let [lo, hi] = self.push_interval_s[..] else {
            bail!("--push-interval-s takes two times, LO,HI [s]");
        };
        let push = PushConfig {
            interval_s: [lo, hi],
            velocity_m_s: self.push_m_s,
            tip_rad_s: self.push_tip_rad_s,
        };
        push.check().context("checking the --push-* options")?;
        Ok(Some(push))
    }

    /// Makes `--trace-plot`'s folder and checks `--episodes` and `--trace` before the
    /// evaluation, so that a bad path fails in a second instead of after the episodes.
    fn check_outputs(&self) -> Result<()> {
        if let Some(dir) = &self.trace_plot {
            crate::output::ensure_dir(dir)?;
        }
        if let Some(path) = &self.episodes {
            crate::output::check_file(path, "--episodes")?;
        }
        if let Some(path) = &self.trace {
            crate::output::check_file(path, "--trace")?;
        }
        Ok(())
    }

    /// How many episodes to trace: `--traced` where a trace or its plot is asked for, else none.
    fn traced_episodes(&self) -> usize {
        if self.trace.is_some() || self.trace_plot.is_some() {
            self.traced
        } else {
            0
        }
    }
}

/// A finite number of at least 0.
fn non_negative(text: &str) -> std::result::Result<f64, String> {
    match text.parse::<f64>() {
        Ok(v) if v.is_finite() && v >= 0.0 => Ok(v),
        _ => Err(format!("`{text}` is not a finite number of at least 0")),
    }
}

pub fn run(what: EvalCommand) -> Result<()> {
    match what {
        EvalCommand::Arm(args) => run_arm(args),
        EvalCommand::WholeBody(args) => run_whole_body(args),
    }
}

/// A path relative to the working directory when inside it, so reports do not carry a home
/// path.
fn shown(path: &std::path::Path) -> String {
    std::env::current_dir()
        .ok()
        .and_then(|cwd| path.strip_prefix(cwd).ok().map(|p| p.display().to_string()))
        .unwrap_or_else(|| path.display().to_string())
}

fn run_whole_body(args: EvalBodyArgs) -> Result<()> {
    let results = evaluate_whole_body(&args)?;
    if let Some(path) = &args.episodes {
        write_csv(path, &results.episodes_csv(), "episodes")?;
    }
    if let Some(path) = &args.trace {
        write_csv(path, &results.trace_csv(), "traces")?;
    }
    if let Some(dir) = &args.trace_plot {
        results.write_trace_plots(dir)?;
    }
    if args.json {
        match results.evaluations.as_slice() {
            [one] => println!("{}", serde_json::to_string(one)?),
            many => println!("{}", serde_json::to_string(many)?),
        }
    } else {
        print!("{}", results.markdown());
    }
    Ok(())
}

/// Writes `text` to `path` and says so.
fn write_csv(path: &std::path::Path, text: &str, what: &str) -> Result<()> {
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))?;
    eprintln!("{what} written to {}", path.display());
    Ok(())
}

/// A whole-body policy's evaluations, one per engine, with what a report says about them.
pub struct BodyEvaluations {
    pub evaluations: Vec<kumi_train::evaluate_body::BodyEvaluation>,
    /// The report's header: policy, steps, protocol, backend.
    pub header: String,
    /// Environment steps the policy was trained for (from its metadata; `?` if absent).
    pub steps: String,
    /// The policy's control rate [Hz]: one traced step each.
    pub control_hz: f64,
    /// The base tilt [rad] past which an episode ends (a fall).
    pub tilt_limit_rad: f64,
}

impl BodyEvaluations {
    /// Every episode of every engine, one CSV row each.
    pub fn episodes_csv(&self) -> String {
        let mut text = format!("engine,{}\n", Episode::CSV_HEADER);
        for result in &self.evaluations {
            for (k, e) in result.episodes.iter().enumerate() {
                text.push_str(&format!("{},{}\n", result.engine, e.csv_row(k)));
            }
        }
        text
    }

    /// Every step of the traced episodes of every engine, one CSV row each.
    pub fn trace_csv(&self) -> String {
        let names = self
            .evaluations
            .first()
            .map_or(&[][..], |r| &r.action_names[..]);
        let mut text = format!("engine,{}\n", TraceStep::csv_header(names));
        for result in &self.evaluations {
            for (k, e) in result.episodes.iter().enumerate() {
                for (step, s) in e.trace.iter().enumerate() {
                    let row = s.csv_row(k, step, &e.target, names.len());
                    text.push_str(&format!("{},{row}\n", result.engine));
                }
            }
        }
        text
    }

    /// Draws each engine's traced episodes into `dir` (`--trace-plot`).
    fn write_trace_plots(&self, dir: &std::path::Path) -> Result<()> {
        crate::output::ensure_dir(dir)?;
        for result in &self.evaluations {
            let title = format!("{} on {}", result.robot, result.engine);
            let plots = crate::trace_plot::trace_plots(
                &title,
                &result.episodes,
                self.control_hz,
                self.tilt_limit_rad,
            );
            for (name, svg) in [("paths", plots.paths_svg), ("tilt", plots.tilt_svg)] {
                let path = dir.join(format!("{}_{name}.svg", result.engine));
                std::fs::write(&path, svg)
                    .with_context(|| format!("writing {}", path.display()))?;
                eprintln!("trace plot written to {}", path.display());
            }
        }
        Ok(())
    }

    pub fn markdown(&self) -> String {
        let mut text = self.header.clone();
        for result in &self.evaluations {
            text.push('\n');
            text.push_str(&result.markdown());
        }
        text
    }
}

/// Why the policy at `path` did not load, with a hint only where the config can be the cause:
/// a contract mismatch on a key the config decides (its observation or action terms). A file
/// that is not a policy, another robot's or skill's policy, or a backend that fails to load (no
/// ONNX Runtime library, say) is named as what it is.
fn policy_load_error(
    e: RuntimeError,
    args: &EvalBodyArgs,
    path: &std::path::Path,
    robot: &str,
) -> anyhow::Error {
    let from_config =
        matches!(&e, RuntimeError::Contract { mismatch, .. } if mismatch.from_config());
    let e = anyhow::Error::new(e);
    match (&args.config, from_config) {
        (_, false) => e.context("loading the policy"), // the error names the file
        (Some(config), true) => e.context(format!(
            "checking {} against {}",
            path.display(),
            config.display()
        )),
        (None, true) => e.context(format!(
            "checking {} against the shipped {} config for {robot}: a policy trained with another config needs it passed with --config",
            path.display(),
            args.variant,
        )),
    }
}

/// Evaluates the policy `args` names in each of its engines.
pub fn evaluate_whole_body(args: &EvalBodyArgs) -> Result<BodyEvaluations> {
    anyhow::ensure!(args.rollouts > 0, "--rollouts must be positive");
    anyhow::ensure!(
        args.trace_plot.is_none() || args.traced > 0,
        "--trace-plot needs at least one traced episode (--traced)"
    );
    let push = args.push()?;
    args.check_outputs()?;
    let model = load_model(&args.morphology)?;
    let file =
        crate::train::body_config_for(&model, args.config.as_deref(), args.variant, true)?.config;
    let path =
        args.variant
            .require_policy(&model.name, &args.morphology, args.policy.as_deref(), None)?;
    let skill_path = args
        .skill
        .clone()
        .unwrap_or_else(kumi_runtime::shipped_arm_policy);
    let skill = std::fs::read(&skill_path)
        .with_context(|| format!("reading the skill {}", skill_path.display()))?;
    let terms = file.arms()?.terms(&model)?;
    let control_hz = kumi_worlds::SimConfig::for_model(&model).control_hz;
    let expected =
        kumi_terms::contract::contract(&model, &terms, file.observation, &skill, control_hz);
    let probe = WholeBodyPolicy::load(&path, &expected, args.backend)
        .map_err(|e| policy_load_error(e, args, &path, &model.name))?;
    let backend = probe.backend();
    let steps = probe
        .metadata()
        .get(kumi_policies::metadata::ENV_STEPS)
        .cloned()
        .unwrap_or_else(|| "?".into());
    // A policy moved to a changed robot without retraining (`kumi policy restamp`) says so.
    let restamped = probe
        .metadata()
        .get(kumi_terms::contract::TRAINED_MORPHOLOGY_FINGERPRINT)
        .map(|trained| {
            format!(
                "\n- re-stamped (`kumi policy restamp`): trained on `{}` with robot fingerprint {trained}, evaluated on it as it is now ({})",
                model.name,
                kumi_terms::contract::morphology_fingerprint(&model)
            )
        })
        .unwrap_or_default();
    drop(probe);
    let engines = if args.engine.is_empty() {
        vec![crate::engine::choose(
            None,
            kumi_worlds::default_training_engine(),
        )?]
    } else {
        args.engine.clone()
    };
    let mut results = Vec::new();
    for &engine in &engines {
        crate::engine::choose(Some(engine), engine)?;
        eprintln!(
            "evaluating {} ({backend} backend, {engine} engine) over {} episodes",
            path.display(),
            args.rollouts
        );
        let start = Instant::now();
        let config = WholeBodyConfig {
            push,
            replay: None,    // training's: evaluation starts every episode afresh
            randomize: None, // training's: evaluation runs the robot's own physics
            critic: Default::default(), // training's: what only the critic sees
            observation_noise: Default::default(), // training's
            ..file.environment(engine)?
        };
        let result = kumi_train::evaluate_body::evaluate_body(
            model.clone(),
            config,
            &skill,
            Protocol {
                rollouts: args.rollouts,
                seed: args.seed,
                traced: args.traced_episodes(),
                action_noise: args.action_noise,
            },
            || {
                let mut policy = WholeBodyPolicy::load(&path, &expected, args.backend)
                    .map_err(|e| e.to_string())?;
                Ok(move |obs: &[f32]| policy.act(obs).map_err(|e| e.to_string()))
            },
        )
        .context("evaluation failed")?;
        eprintln!("done in {:.1} s", start.elapsed().as_secs_f64());
        results.push(result);
    }
    let header = format!(
        "# {} {} whole-body policy: evaluation\n\n- policy: `{}` (trained for {steps} environment steps){}{restamped}\n- protocol: {} episodes of {} s from a random start pose (x, y within +-{} m, any heading) to a random target (x, y within +-{} m, z in [{}, {}] m, any yaw); errors at the episode's end, over episodes that did not fall; episode seed {}\n- inference: {backend} backend\n",
        model.name,
        args.variant,
        shown(&path),
        if terms.uses_skill() {
            format!(", skill `{}`", shown(&skill_path))
        } else {
            String::new()
        },
        args.rollouts,
        file.task.episode_s,
        file.task.initial_xy_m,
        file.task.target_xy_m,
        file.task.target_z_m[0],
        file.task.target_z_m[1],
        args.seed,
    );
    let header = match push {
        Some(p) => format!(
            "{header}- pushes: every {}-{} s the robot's horizontal velocity jumps by x and y each uniform in +-{} m/s, and its angular velocity about the world's x and y axes by +-{} rad/s\n",
            p.interval_s[0], p.interval_s[1], p.velocity_m_s, p.tip_rad_s
        ),
        None => header,
    };
    Ok(BodyEvaluations {
        evaluations: results,
        header,
        steps,
        control_hz,
        tilt_limit_rad: file.task.tilt_limit_rad,
    })
}

#[derive(Args, Debug)]
pub struct EvalArmArgs {
    /// The ONNX policy (default: the shipped policies/arm_reach/arm_reach.onnx).
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// Goals to evaluate.
    #[arg(long, default_value_t = 1000)]
    pub rollouts: usize,
    /// Seed of the episodes (initial joints, goals, goal noise).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Inference backend: auto (ONNX Runtime when ORT_DYLIB_PATH is set, else tract),
    /// onnxruntime or tract.
    #[arg(long, default_value = "auto")]
    pub backend: BackendChoice,
    /// Physics engines to evaluate in, one report each (e.g. `rapier,mujoco`; default rapier).
    #[arg(long, value_delimiter = ',', value_parser = crate::engine::parse)]
    pub engine: Vec<kumi_worlds::Engine>,
    /// Goal distributions, one report each: `paper` (the paper's box, section IV-A) and
    /// `working` (tool poses around the home configurations of every arm module of the
    /// robots named in the training config's `[goals]`).
    #[arg(long, value_delimiter = ',', default_value = "paper", value_parser = ["paper", "working"])]
    pub goals: Vec<String>,
    /// The training config whose `[goals]` define the working poses (default: the shipped one).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Standard deviation [m] of the noise on the goal position the skill observes, drawn
    /// afresh every step (training's by default; 0 for a still goal).
    #[arg(long, default_value_t = ArmReachConfig::default().goal_noise.position_std)]
    pub goal_noise_m: f64,
    /// Standard deviation [rad] of the noise on the goal orientation the skill observes, drawn
    /// afresh every step (training's by default; 0 for a still goal).
    #[arg(long, default_value_t = ArmReachConfig::default().goal_noise.orientation_std)]
    pub goal_noise_rad: f64,
    /// Print one JSON object instead of a markdown table (an array for several engines or
    /// goal sets).
    #[arg(long)]
    pub json: bool,
}

fn run_arm(args: EvalArmArgs) -> Result<()> {
    anyhow::ensure!(args.rollouts > 0, "--rollouts must be positive");
    for (flag, std) in [
        ("--goal-noise-m", args.goal_noise_m),
        ("--goal-noise-rad", args.goal_noise_rad),
    ] {
        anyhow::ensure!(
            std.is_finite() && std >= 0.0,
            "{flag} must be a standard deviation >= 0; got {std}"
        );
    }
    let goal_noise = kumi_policies::goal::GoalNoise {
        position_std: args.goal_noise_m,
        orientation_std: args.goal_noise_rad,
    };
    let path = args.policy.unwrap_or_else(kumi_runtime::shipped_arm_policy);
    let model = load_model("arm")?;
    let skill = ArmSkill::new(
        &model.modules[0],
        kumi_worlds::SimConfig::for_model(&model).control_hz,
    )?;
    // Load once here so that a bad file fails before any work, with its own message.
    let probe = SkillPolicy::load(&path, &skill, args.backend)?;
    let backend = probe.backend();
    let meta = |key: &str| {
        probe
            .metadata()
            .get(key)
            .cloned()
            .unwrap_or_else(|| "?".into())
    };
    let shown = shown(&path);
    let training_noise = ArmReachConfig::default().goal_noise;
    let provenance = format!(
        "- policy: `{}` (trained for {} environment steps, config fingerprint {})\n- protocol: {} goals, each held 4 s (120 steps at {} Hz) in 12 s episodes from random initial joints, goal noise {} m and {} rad (training's: {} m, {} rad); error at the end of each goal; episode seed {}\n- inference: {backend} backend\n",
        shown,
        meta(kumi_policies::metadata::ENV_STEPS),
        meta(kumi_policies::metadata::CONFIG_HASH),
        args.rollouts,
        skill.control_hz,
        args.goal_noise_m,
        args.goal_noise_rad,
        training_noise.position_std,
        training_noise.orientation_std,
        args.seed,
    );
    drop(probe);
    let engines = if args.engine.is_empty() {
        vec![kumi_worlds::Engine::Rapier]
    } else {
        args.engine.clone()
    };
    for &engine in &engines {
        crate::engine::choose(Some(engine), engine)?;
    }
    let goal_config = crate::train::read_config(args.config.as_deref())?.goals;
    let working = goal_config.resolve()?.working_only();
    let mut results = Vec::new();
    for (engine, goals) in engines
        .iter()
        .flat_map(|e| args.goals.iter().map(move |g| (*e, g)))
    {
        eprintln!(
            "evaluating {} ({backend} backend, {engine} engine) over {} {goals} goals",
            path.display(),
            args.rollouts
        );
        let start = Instant::now();
        let result = evaluate(
            model.clone(),
            ArmReachConfig {
                engine,
                goals: if goals == "working" {
                    working.clone()
                } else {
                    GoalDistribution::paper()
                },
                goal_noise,
                ..ArmReachConfig::default()
            },
            args.rollouts,
            args.seed,
            || {
                let mut policy =
                    SkillPolicy::load(&path, &skill, args.backend).map_err(|e| e.to_string())?;
                Ok(move |obs: &_| policy.act(obs).map_err(|e| e.to_string()))
            },
        )
        .context("evaluation failed")?;
        eprintln!("done in {:.1} s", start.elapsed().as_secs_f64());
        results.push(result);
    }
    if args.json {
        // One object for one engine (the documented shape), an array for several.
        match results.as_slice() {
            [one] => println!("{}", serde_json::to_string(one)?),
            many => println!("{}", serde_json::to_string(many)?),
        }
    } else {
        print!("# Arm-reach skill: evaluation\n\n{provenance}");
        if args.goals.iter().any(|g| g == "working") {
            print!("\n{}", working_table(&goal_config, &model)?);
        }
        for result in &results {
            print!("\n{}", result.markdown());
        }
        if let ([a, b], [_]) = (results.as_slice(), args.goals.as_slice()) {
            println!(
                "\nBetween the engines ({} minus {}): mean position error {:+.4} m, mean orientation error {:+.4} rad.",
                b.engine,
                a.engine,
                b.position_error_m.mean - a.position_error_m.mean,
                b.orientation_error_rad.mean - a.orientation_error_rad.mean
            );
        }
    }
    Ok(())
}

/// Where each arm module of the training config's robots holds its tool at home, against the
/// paper's goal box: the centres of the working-pose goals.
fn working_table(
    goals: &kumi_train::arm_reach::GoalConfig,
    arm: &kumi_model::RobotModel,
) -> Result<String> {
    let fk = kumi_policies::kinematics::ToolKinematics::new(arm, &arm.modules[0])
        .map_err(anyhow::Error::msg)?;
    let paper = kumi_policies::goal::GoalRange::default();
    let mut out = format!(
        "Working goals: the tool pose at joint angles within +-{} rad of one arm module's home (`[goals]` of the training config). Home tool poses in each module's base frame:\n\n| module | position [m] | roll, pitch, yaw [rad] | in the paper's box |\n|---|---|---|---|\n",
        goals.spread_rad
    );
    for (name, home) in goals.working_configurations()? {
        let pose = fk.tool_pose_b(&home);
        let p = pose.translation.vector;
        let (roll, pitch, yaw) = pose.rotation.euler_angles();
        let inside = (0..3).all(|i| p[i] >= paper.position_min[i] && p[i] <= paper.position_max[i])
            && pitch >= paper.pitch.0
            && pitch <= paper.pitch.1
            && yaw.abs() < 1e-6;
        out += &format!(
            "| {name} | ({:.3}, {:.3}, {:.3}) | ({roll:.2}, {pitch:.2}, {yaw:.2}) | {} |\n",
            p.x,
            p.y,
            p.z,
            if inside { "yes" } else { "no" }
        );
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        args: EvalBodyArgs,
    }

    fn traced(flags: &[&str]) -> usize {
        let argv = ["kumi", "minimal"].iter().chain(flags);
        Cli::try_parse_from(argv).unwrap().args.traced_episodes()
    }

    #[test]
    fn episodes_are_traced_for_a_trace_or_its_plot_only() {
        assert_eq!(traced(&[]), 0);
        assert_eq!(traced(&["--traced", "3"]), 0);
        assert_eq!(traced(&["--trace", "t.csv"]), 10);
        assert_eq!(traced(&["--trace-plot", "plots", "--traced", "3"]), 3);
    }
}
