//! `kumi train arm`: trains the low-level reaching skill with PPO.

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use kumi_terms::action::{GoalBounds, JointBounds};
use kumi_terms::ObservationOptions;
use kumi_train::arm_reach::{
    ArmReach, ArmReachConfig, GoalConfig, SkillAction, SkillObservation, ToolLoad,
};
use kumi_train::body_reward::{BodyWeights, PenaltyWeights};
use kumi_train::env::Environment;
use kumi_train::noise::ObservationNoise;
use kumi_train::ppo::trainer::{IterationStats, PpoConfig, Trainer};
use kumi_train::randomize::RandomizeConfig;
use kumi_train::replay::ReplayConfig;
use kumi_train::reward::ReachWeights;
use kumi_train::whole_body::{
    ArmControl, CriticObservation, PushConfig, TaskConfig, WholeBody, WholeBodyConfig,
};

/// The training config file: PPO hyperparameters, the reward's weights and the goals.
#[derive(Debug, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct TrainArmConfig {
    pub ppo: PpoConfig,
    pub reward: ReachWeights,
    pub goals: GoalConfig,
    /// A load on the tool during some goals; none when absent. (Left out of the config's
    /// fingerprint when absent, as `[observation]`, so a config without them keeps its
    /// fingerprint and reproduces its skill bit for bit.)
    #[serde(default, skip_serializing_if = "ToolLoad::is_none")]
    pub load: ToolLoad,
    /// What the skill observes; Table I's 21 values when absent.
    #[serde(default, skip_serializing_if = "SkillObservation::is_table_i")]
    pub observation: SkillObservation,
    /// How the skill's action is formed; the network's output alone when absent.
    #[serde(default, skip_serializing_if = "SkillAction::is_plain")]
    pub action: SkillAction,
}

impl TrainArmConfig {
    /// The fingerprint a skill trained on this config carries (`kumi.config_hash`): of the
    /// values, not the text, so that comments and layout do not change what was trained.
    pub fn fingerprint(&self) -> Result<String> {
        Ok(kumi_policies::metadata::fingerprint(
            &serde_json::to_string(self)?,
        ))
    }
}

/// The config at `path`, or the shipped one.
pub fn read_config(path: Option<&std::path::Path>) -> Result<TrainArmConfig> {
    let text = match path {
        Some(path) => {
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?
        }
        None => SHIPPED_CONFIG.to_string(),
    };
    toml::from_str(&text).with_context(|| {
        format!(
            "parsing {}",
            path.map_or("the shipped config".into(), |p| p.display().to_string())
        )
    })
}

use crate::sim::load_model;

#[derive(Subcommand, Debug)]
pub enum TrainCommand {
    /// The low-level skill: one fixed-base arm reaching goals (the paper's section IV-A).
    Arm(TrainArmArgs),
    /// An upper-level policy over the frozen skill for one morphology (the paper's section IV-B).
    WholeBody(TrainBodyArgs),
}

/// What every training command takes.
#[derive(Args, Debug)]
pub struct RunArgs {
    /// Override the number of environment steps.
    #[arg(long)]
    pub steps: Option<u64>,
    /// Override the seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Physics engine (default: mujoco when this build has it, else rapier).
    #[arg(long, value_parser = crate::engine::parse)]
    pub engine: Option<kumi_worlds::Engine>,
    /// Threads for collection and update (default: every core). Results do not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Continue from a checkpoint directory (parameters, Adam's moments, observation
    /// statistics, step count).
    #[arg(long)]
    pub resume: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct TrainArmArgs {
    /// PPO hyperparameters (TOML; default: the shipped train/configs/arm_reach.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Where metrics (metrics.csv), checkpoints (checkpoint/) and the policy go.
    #[arg(long, default_value = "runs/arm_reach")]
    pub out: PathBuf,
    #[command(flatten)]
    pub run: RunArgs,
}

#[derive(Args, Debug)]
pub struct TrainBodyArgs {
    /// `minimal`, `dragon`, `tricycle`, or a path to a morphology file (one manipulator).
    pub morphology: String,
    /// Task, reward, action bounds and PPO settings (TOML; default for a shipped robot:
    /// train/configs/whole_body/<morphology>.toml; required for another).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// The frozen skill every arm module runs (default: the shipped policies/arm_reach/arm_reach.onnx).
    #[arg(long)]
    pub skill: Option<PathBuf>,
    /// The policy to train: over the skill, or a baseline (its default config is
    /// train/configs/{whole_body,flat,penalty}/<morphology>.toml).
    #[arg(long, value_enum, default_value_t)]
    pub variant: Variant,
    /// Where metrics, checkpoints and the policy go (default: runs/<policy name>, e.g.
    /// runs/minimal_whole_body or runs/minimal_flat).
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[command(flatten)]
    pub run: RunArgs,
}

/// Iterations between checkpoints.
const CHECKPOINT_EVERY: usize = 10;
/// Iterations between progress lines when stderr is not a terminal.
const LOG_EVERY: usize = 5;

const SHIPPED_CONFIG: &str = include_str!("../../train/configs/arm_reach.toml");

/// Which whole-body policy: the paper's hierarchical one over the frozen skill, or a
/// baseline of section V-C.
#[derive(clap::ValueEnum, Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Variant {
    /// Goals for the frozen skill per arm module, velocities per wheel module.
    #[default]
    Hierarchical,
    /// Every arm joint's position target directly (the paper's section V-C).
    Flat,
    /// Flat, with the leg-orientation reward and contact penalty (Eqs. 5, 6).
    Penalty,
}

impl Variant {
    /// The policy's name: `<robot>_whole_body`, `<robot>_flat` or `<robot>_penalty` (its folder
    /// in `policies/`, its run directory under `runs/`).
    pub fn policy_name(self, robot: &str) -> String {
        match self {
            Variant::Hierarchical => format!("{robot}_whole_body"),
            Variant::Flat => format!("{robot}_flat"),
            Variant::Penalty => format!("{robot}_penalty"),
        }
    }

    /// The shipped policy file of this variant for `robot`.
    pub fn shipped_policy(self, robot: &str) -> PathBuf {
        kumi_runtime::shipped_policy(&self.policy_name(robot))
    }

    /// Where `kumi train whole-body` writes this variant's policy for `robot` by default:
    /// `runs/<name>/<name>.onnx`.
    pub fn trained_policy(self, robot: &str) -> PathBuf {
        let name = self.policy_name(robot);
        PathBuf::from("runs")
            .join(&name)
            .join(format!("{name}.onnx"))
    }

    /// The policy a command uses when none is named: the shipped one, or, for a robot kumi does
    /// not ship, the one `kumi train whole-body` wrote ([`Self::trained_policy`]).
    pub fn default_policy(self, robot: &str) -> PathBuf {
        let shipped = self.shipped_policy(robot);
        let trained = self.trained_policy(robot);
        if !shipped.exists() && trained.exists() {
            trained
        } else {
            shipped
        }
    }

    /// The policy a command runs (`named`, else [`Self::default_policy`]), or an error that
    /// says where it looked and how to get one; `otherwise` is what else the command can do
    /// without one (a launch: `--no-whole-body`).
    pub fn require_policy(
        self,
        robot: &str,
        morphology: &str,
        named: Option<&std::path::Path>,
        otherwise: Option<&str>,
    ) -> Result<PathBuf> {
        let policy = named.map_or_else(|| self.default_policy(robot), PathBuf::from);
        if policy.exists() {
            return Ok(policy);
        }
        let or = otherwise.map_or(String::new(), |o| format!(", or {o}"));
        if named.is_some() {
            bail!("no policy file at {}{or}", policy.display());
        }
        let variant = match self {
            Variant::Hierarchical => String::new(),
            other => format!(" --variant {other}"),
        };
        bail!(
            "no {self} policy for `{robot}`: none is shipped ({shipped}) and training has not written {trained}. Train one with `kumi train whole-body {morphology}{variant}` (the robot's config, or the default recipe when it has none; it writes {trained}, which this command then finds) or pass --policy FILE{or}",
            shipped = self.shipped_policy(robot).display(),
            trained = self.trained_policy(robot).display(),
        )
    }

    fn config_dir(self) -> &'static str {
        match self {
            Variant::Hierarchical => "whole_body",
            Variant::Flat => "flat",
            Variant::Penalty => "penalty",
        }
    }
}

impl std::fmt::Display for Variant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Variant::Hierarchical => "hierarchical",
            Variant::Flat => "flat",
            Variant::Penalty => "penalty",
        })
    }
}

/// The shipped whole-body configs, by robot name and variant.
pub const SHIPPED_BODY_CONFIGS: [(&str, Variant, &str); 7] = [
    (
        "minimal",
        Variant::Hierarchical,
        include_str!("../../train/configs/whole_body/minimal.toml"),
    ),
    (
        "dragon",
        Variant::Hierarchical,
        include_str!("../../train/configs/whole_body/dragon.toml"),
    ),
    (
        "tricycle",
        Variant::Hierarchical,
        include_str!("../../train/configs/whole_body/tricycle.toml"),
    ),
    (
        "minimal",
        Variant::Flat,
        include_str!("../../train/configs/flat/minimal.toml"),
    ),
    (
        "dragon",
        Variant::Flat,
        include_str!("../../train/configs/flat/dragon.toml"),
    ),
    (
        "tricycle",
        Variant::Flat,
        include_str!("../../train/configs/flat/tricycle.toml"),
    ),
    (
        "tricycle",
        Variant::Penalty,
        include_str!("../../train/configs/penalty/tricycle.toml"),
    ),
];

/// The whole-body training config file: `[action]` (goal bounds, over the skill) or `[flat]`
/// (joint targets), and for the penalty baseline `[penalty]`.
#[derive(Debug, Clone, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct TrainBodyConfig {
    pub ppo: PpoConfig,
    pub task: TaskConfig,
    pub reward: BodyWeights,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub action: Option<GoalBounds>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub flat: Option<JointBounds>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub penalty: Option<PenaltyWeights>,
    /// Optional observation slots (none when the section is absent; left out of the config's
    /// hash then, so that policies trained before the section existed keep theirs).
    #[serde(default, skip_serializing_if = "ObservationOptions::is_none")]
    pub observation: ObservationOptions,
    /// Random shoves in training (none when the section is absent, and out of the hash then).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub push: Option<PushConfig>,
    /// Episodes replayed from before earlier ones tipped, in training (none when the section
    /// is absent, and out of the hash then).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub replay: Option<ReplayConfig>,
    /// Each training environment's own ground friction and contact (none when the section is
    /// absent, and out of the hash then).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub randomize: Option<RandomizeConfig>,
    /// What only the critic sees in training (none when the section is absent, and out of the
    /// hash then).
    #[serde(default, skip_serializing_if = "CriticObservation::is_none")]
    pub critic: CriticObservation,
    /// Noise on the policy's observation in training, per slot (none when the section is
    /// absent or all zero, and out of the hash then).
    #[serde(default, skip_serializing_if = "ObservationNoise::is_none")]
    pub observation_noise: ObservationNoise,
}

impl TrainBodyConfig {
    /// How the policy drives the arms: exactly one of `[action]` and `[flat]`.
    pub fn arms(&self) -> Result<ArmControl> {
        match (self.action, self.flat) {
            (Some(bounds), None) => Ok(ArmControl::Skill(bounds)),
            (None, Some(bounds)) => Ok(ArmControl::Joints(bounds)),
            (Some(_), Some(_)) => bail!("the config has both [action] (goals for the skill) and [flat] (joint targets): keep one"),
            (None, None) => bail!("the config has neither [action] (goals for the skill) nor [flat] (joint targets)"),
        }
    }

    /// The environment's settings in `engine`.
    pub fn environment(&self, engine: kumi_worlds::Engine) -> Result<WholeBodyConfig> {
        Ok(WholeBodyConfig {
            engine,
            task: self.task,
            weights: self.reward,
            penalty: self.penalty.unwrap_or_default(),
            arms: self.arms()?,
            observation: self.observation,
            push: self.push,
            replay: self.replay,
            randomize: self.randomize,
            critic: self.critic,
            observation_noise: self.observation_noise.clone(),
        })
    }

    /// The goal bounds over the skill (an error for a flat config).
    pub fn goal_bounds(&self) -> Result<GoalBounds> {
        match self.arms()? {
            ArmControl::Skill(bounds) => Ok(bounds),
            ArmControl::Joints(_) => {
                bail!("a flat baseline config has no goal bounds for the skill")
            }
        }
    }
}

/// The last stage of each shipped policy that trained in stages with other action terms than
/// its first (the first stage is the robot's entry in [`SHIPPED_BODY_CONFIGS`], the default to
/// train from): Tricycle's fourth stage tightened the turn governor, and its fifth and sixth
/// keep it.
const SHIPPED_LAST_STAGES: [(&str, Variant, &str); 1] = [(
    "tricycle",
    Variant::Hierarchical,
    include_str!("../../train/configs/whole_body/tricycle_sixth.toml"),
)];

/// The whole-body config at `path`, or the one shipped for `robot` and `variant` (the first
/// stage: what `kumi train` starts from).
pub fn read_body_config(
    path: Option<&std::path::Path>,
    robot: &str,
    variant: Variant,
) -> Result<TrainBodyConfig> {
    read_config_from(path, robot, variant, SHIPPED_BODY_CONFIGS.iter())
}

/// The whole-body config at `path`, or the one the shipped policy of `robot` and `variant`
/// finished its training with (its last stage): what `kumi eval` and `kumi report compare`
/// check the shipped policy against.
pub fn read_shipped_policy_config(
    path: Option<&std::path::Path>,
    robot: &str,
    variant: Variant,
) -> Result<TrainBodyConfig> {
    let last_first = SHIPPED_LAST_STAGES.iter().chain(&SHIPPED_BODY_CONFIGS);
    read_config_from(path, robot, variant, last_first)
}

/// The shipped robot whose recipe trains a robot kumi ships no config for: Dragon, a
/// manipulator on a wheel module and a leg carrying another, the nearest to what the shipped
/// modules assemble into.
pub const DEFAULT_RECIPE_ROBOT: &str = "dragon";

/// The default recipe's target heights [m] for a robot whose manipulator tool stands
/// `standing_m` [m] above the ground at home: the recipe robot's own range `recipe_z_m`, moved
/// by how much higher or lower that tool stands than the recipe robot's (`recipe_standing_m`),
/// to the centimetre. For the recipe robot itself, its own range. Pure.
pub fn target_heights_m(recipe_z_m: [f64; 2], recipe_standing_m: f64, standing_m: f64) -> [f64; 2] {
    let shift_m = ((standing_m - recipe_standing_m) * 100.0).round() / 100.0;
    [recipe_z_m[0] + shift_m, recipe_z_m[1] + shift_m]
}

/// The whole-body config for `model` and `variant`, and where it came from: `path`; else the
/// one shipped for the robot (with `last_stage`, the one its shipped policy finished with);
/// else the default recipe ([`DEFAULT_RECIPE_ROBOT`]'s), its targets moved with this robot's
/// manipulator tool ([`target_heights_m`]). Training, evaluation and `kumi robot` take it
/// from here, so a robot kumi does not ship needs no config of its own.
pub fn body_config_for(
    model: &kumi_model::RobotModel,
    path: Option<&std::path::Path>,
    variant: Variant,
    last_stage: bool,
) -> Result<ChosenConfig> {
    let robot = model.name.as_str();
    let shipped = SHIPPED_BODY_CONFIGS
        .iter()
        .any(|(name, v, _)| *name == robot && *v == variant);
    if path.is_some() || shipped {
        let label = path.map_or_else(
            || format!("train/configs/{}/{robot}.toml", variant.config_dir()),
            |p| p.display().to_string(),
        );
        let config = if last_stage {
            read_shipped_policy_config(path, robot, variant)?
        } else {
            read_body_config(path, robot, variant)?
        };
        return Ok(ChosenConfig {
            config,
            label,
            default_recipe: false,
        });
    }
    let mut config = read_body_config(None, DEFAULT_RECIPE_ROBOT, variant).with_context(|| {
        format!("`{robot}` has no {variant} config of its own: pass --config FILE")
    })?;
    let standing = |m: &kumi_model::RobotModel| {
        crate::robot::manipulator_standing_height_m(m)?.with_context(|| {
            format!(
                "`{}` has no manipulator module, whose tool the whole-body task steers",
                m.name
            )
        })
    };
    let standing_m = standing(model)?;
    let recipe_standing_m = standing(&*crate::sim::load_model(DEFAULT_RECIPE_ROBOT)?)?;
    config.task.target_z_m =
        target_heights_m(config.task.target_z_m, recipe_standing_m, standing_m);
    let [lo, hi] = config.task.target_z_m;
    let label = format!(
        "the default recipe (train/configs/{}/{DEFAULT_RECIPE_ROBOT}.toml), its targets at {lo:.2}-{hi:.2} m: {DEFAULT_RECIPE_ROBOT}'s, moved with the manipulator tool's standing height ({standing_m:.3} m; {DEFAULT_RECIPE_ROBOT}'s {recipe_standing_m:.3} m)",
        variant.config_dir()
    );
    Ok(ChosenConfig {
        config,
        label,
        default_recipe: true,
    })
}

/// A whole-body config as [`body_config_for`] chose it.
pub struct ChosenConfig {
    pub config: TrainBodyConfig,
    /// Where it came from, for a person.
    pub label: String,
    /// It is the default recipe, the robot having no config of its own.
    pub default_recipe: bool,
}

/// The config at `path`, else the first entry for `robot` and `variant` in `shipped`.
fn read_config_from<'a>(
    path: Option<&std::path::Path>,
    robot: &str,
    variant: Variant,
    mut shipped: impl Iterator<Item = &'a (&'a str, Variant, &'a str)>,
) -> Result<TrainBodyConfig> {
    let (text, label) = match path {
        Some(path) => (
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?,
            path.display().to_string(),
        ),
        None => match shipped.find(|(name, v, _)| *name == robot && *v == variant) {
            Some((_, _, text)) => (text.to_string(), format!("the shipped {variant} config for {robot}")),
            None => bail!(
                "no shipped {variant} whole-body config for robot `{robot}`: pass --config FILE (start from train/configs/{}/dragon.toml, as examples/caterpillar_whole_body.toml does, and set [task] target_z_m around your robot's tool heights)",
                variant.config_dir()
            ),
        },
    };
    let config: TrainBodyConfig =
        toml::from_str(&text).with_context(|| format!("parsing {label}"))?;
    config.arms().with_context(|| format!("in {label}"))?;
    Ok(config)
}

/// The generic columns of metrics.csv; the environment's own metrics follow, then `wall_s`.
const COLUMNS: [&str; 14] = [
    "iteration",
    "env_steps",
    "collect_steps_per_s",
    "update_samples_per_s",
    "mean_step_reward",
    "mean_episode_return",
    "policy_loss",
    "value_loss",
    "entropy",
    "approx_kl",
    "clip_fraction",
    "action_std",
    "learning_rate",
    "episodes",
];

fn header(metrics: &[&str]) -> String {
    let mut all: Vec<&str> = COLUMNS.to_vec();
    all.extend_from_slice(metrics);
    all.push("wall_s");
    all.join(",")
}

fn row(s: &IterationStats, wall_s: f64) -> String {
    let mut v = vec![
        s.iteration as f64,
        s.env_steps as f64,
        s.collect_steps_per_s,
        s.update_samples_per_s,
        s.mean_step_reward,
        s.mean_episode_return,
        s.policy_loss,
        s.value_loss,
        s.entropy,
        s.approx_kl,
        s.clip_fraction,
        s.action_std,
        s.learning_rate,
        s.episodes as f64,
    ];
    v.extend(s.metrics.iter().map(|(_, x)| *x));
    v.push(wall_s);
    v.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(",")
}

/// Applies the shared overrides to a config and sets up the thread pool.
fn prepare(config: &mut PpoConfig, args: &RunArgs) -> Result<()> {
    if let Some(s) = args.steps {
        config.total_steps = s;
    }
    if let Some(s) = args.seed {
        config.seed = s;
    }
    config
        .check()
        .map_err(|e| anyhow::anyhow!("invalid [ppo] config: {e}"))?;
    if let Some(threads) = args.threads {
        if threads == 0 {
            bail!("--threads must be positive");
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build_global()
            .context("setting the number of threads")?;
    }
    eprintln!(
        "{} threads (a seeded run gives the same bits on any number)",
        rayon::current_num_threads()
    );
    Ok(())
}

/// The engine to train on, said aloud.
fn training_engine(args: &RunArgs) -> Result<kumi_worlds::Engine> {
    let engine = crate::engine::choose(args.engine, kumi_worlds::default_training_engine())?;
    eprintln!(
        "training on the {engine} engine{}",
        if args.engine.is_none() && engine == kumi_worlds::Engine::Rapier {
            format!(
                " (MuJoCo, about 10x faster, is not in this build: {})",
                kumi_worlds::MUJOCO_INSTALL_HINT
            )
        } else {
            String::new()
        }
    );
    Ok(engine)
}

/// `metrics.csv` for writing, its `header` written. A resumed run goes on with the file of the
/// run it resumes when it is there, without the rows past the checkpoint (a run that died after
/// its last checkpoint wrote them, and will write them again), unless that file has other
/// columns (an error); a new run starts it afresh.
fn open_metrics(
    path: &std::path::Path,
    resumed: bool,
    iteration: usize,
    header: &str,
) -> Result<std::fs::File> {
    let kept = if resumed && path.exists() {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        let mut lines = text.lines();
        let columns = lines.next().unwrap_or(header);
        if columns != header {
            bail!(
                "{} has the columns of another run ({columns}), and this run writes ({header}): resume into another --out",
                path.display()
            );
        }
        let mut kept = vec![header];
        kept.extend(lines.filter(|l| {
            l.split(',')
                .next()
                .and_then(|i| i.parse::<usize>().ok())
                .is_some_and(|i| i <= iteration)
        }));
        kept.join("\n") + "\n"
    } else {
        format!("{header}\n")
    };
    std::fs::write(path, kept).with_context(|| format!("writing {}", path.display()))?;
    std::fs::OpenOptions::new()
        .append(true)
        .open(path)
        .with_context(|| format!("opening {}", path.display()))
}

/// What an exported policy carries besides the network: its metadata (the step count is added
/// at the end) and a prior, a matrix from observation to action added to the network's output
/// ([`kumi_train::export::actor_model`]), which the environments add in training.
struct PolicyFile {
    metadata: std::collections::BTreeMap<String, String>,
    prior: Option<Vec<f32>>,
}

/// The one training runner: PPO over `envs` until `config.total_steps`, with metrics.csv,
/// progress (a bar on a terminal, a line every few iterations otherwise), checkpoints and
/// resume; then the deterministic actor exported to `out/<name>.onnx` as `policy` says.
fn train<E: Environment>(
    what: &str,
    config: PpoConfig,
    envs: Vec<E>,
    args: &RunArgs,
    out: &std::path::Path,
    policy: PolicyFile,
    name: &str,
) -> Result<PathBuf> {
    let PolicyFile {
        mut metadata,
        prior,
    } = policy;
    let metric_names = envs.first().map(|e| e.metric_names()).unwrap_or(&[]);
    crate::output::ensure_dir(out)?;
    let total = config.total_steps;
    let mut trainer = Trainer::new(config, envs)?;
    if let Some(dir) = &args.resume {
        trainer.load_checkpoint(dir)?;
        eprintln!(
            "resumed from {} at {} steps",
            dir.display(),
            trainer.env_steps
        );
    }
    let csv_path = out.join("metrics.csv");
    let mut csv = open_metrics(
        &csv_path,
        args.resume.is_some(),
        trainer.iteration,
        &header(metric_names),
    )?;
    let checkpoint = out.join("checkpoint");
    let start = Instant::now();
    eprintln!(
        "training {what} for {total} steps; metrics in {}",
        csv_path.display()
    );
    let bar = ProgressBar::new(total).with_style(
        ProgressStyle::with_template(
            "{bar:30} {pos}/{len} steps [{elapsed_precise} < {eta_precise}] {msg}",
        )
        .expect("a valid template"),
    );
    bar.set_position(trainer.env_steps);
    // Ctrl-C ends the run after the current iteration, with a checkpoint and the policy.
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let flag = stop.clone();
    let _ = ctrlc::set_handler(move || flag.store(true, std::sync::atomic::Ordering::Relaxed));
    while trainer.env_steps < total {
        if stop.load(std::sync::atomic::Ordering::Relaxed) {
            bar.suspend(|| {
                eprintln!(
                    "stopped by Ctrl-C at {} of {total} steps: saving the checkpoint and the policy",
                    trainer.env_steps
                )
            });
            break;
        }
        let s = trainer.iterate();
        let wall = start.elapsed().as_secs_f64();
        writeln!(csv, "{}", row(&s, wall))?;
        let figures: Vec<String> = s.metrics.iter().map(|(n, v)| figure(n, *v)).collect();
        let status = format!(
            "{:.0} steps/s collect, {:.0} samples/s update | reward/step {:.3} | {} | std {:.3}",
            s.collect_steps_per_s,
            s.update_samples_per_s,
            s.mean_step_reward,
            figures.join(", "),
            s.action_std,
        );
        bar.set_position(s.env_steps.min(total));
        if bar.is_hidden() {
            if s.iteration.is_multiple_of(LOG_EVERY) || s.env_steps >= total {
                eprintln!(
                    "[{:>5.1}%] steps {:>8}/{total} | {status} | {wall:.0} s",
                    100.0 * s.env_steps as f64 / total as f64,
                    s.env_steps,
                );
            }
        } else {
            bar.set_message(status);
        }
        if s.iteration.is_multiple_of(CHECKPOINT_EVERY) {
            trainer.save_checkpoint(&checkpoint)?;
        }
    }
    bar.finish();
    trainer.save_checkpoint(&checkpoint)?;
    eprintln!("checkpoint in {}", checkpoint.display());

    metadata.insert(
        kumi_policies::metadata::ENV_STEPS.into(),
        trainer.env_steps.to_string(),
    );
    let onnx = kumi_train::export::actor_model(
        &trainer.actor_norm(),
        &trainer.learner.net.actor.parameters(),
        prior.as_deref(),
        &metadata,
    );
    let onnx_path = out.join(format!("{name}.onnx"));
    std::fs::write(&onnx_path, kumi_train::export::encode(&onnx))
        .with_context(|| format!("writing {}", onnx_path.display()))?;
    eprintln!(
        "policy in {} ({:.0} s)",
        onnx_path.display(),
        start.elapsed().as_secs_f64()
    );
    Ok(onnx_path)
}

pub fn run(what: TrainCommand) -> Result<()> {
    match what {
        TrainCommand::Arm(args) => train_arm(args),
        TrainCommand::WholeBody(args) => train_whole_body(args),
    }
}

fn train_arm(args: TrainArmArgs) -> Result<()> {
    let file = read_config(args.config.as_deref())?;
    let goals = file.goals.resolve()?;
    let mut config = file.ppo;
    prepare(&mut config, &args.run)?;
    // What is trained, overrides included: its fingerprint goes into the policy's metadata.
    let trained = TrainArmConfig {
        ppo: config.clone(),
        reward: file.reward,
        goals: file.goals.clone(),
        load: file.load,
        observation: file.observation,
        action: file.action,
    };
    let model = load_model("arm")?;
    let engine = training_engine(&args.run)?;
    let envs = (0..config.num_envs)
        .map(|i| {
            ArmReach::new(
                model.clone(),
                ArmReachConfig {
                    engine,
                    weights: file.reward,
                    goals: goals.clone(),
                    load: file.load,
                    observation: file.observation,
                    action: file.action,
                    ..ArmReachConfig::default()
                },
                config.seed.wrapping_mul(1000).wrapping_add(i as u64),
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    // The deterministic actor, normalisation and step follower included, with the skill's
    // metadata.
    let skill = kumi_policies::skill::ArmSkill::new(
        &model.modules[0],
        kumi_worlds::SimConfig::for_model(&model).control_hz,
    )?;
    let prior = (!file.action.is_plain())
        .then(|| kumi_train::arm_reach::step_prior(file.action.step_prior_gain, &skill));
    let mut metadata = skill.metadata(
        envs[0].config().observation_dim(),
        &trained.fingerprint()?,
        0,
    );
    metadata.remove(kumi_policies::metadata::ENV_STEPS);
    train(
        "the arm-reaching skill",
        config,
        envs,
        &args.run,
        &args.out,
        PolicyFile { metadata, prior },
        "arm_reach",
    )?;
    Ok(())
}

fn train_whole_body(args: TrainBodyArgs) -> Result<()> {
    let model = load_model(&args.morphology)?;
    let chosen = body_config_for(&model, args.config.as_deref(), args.variant, false)?;
    eprintln!("config: {}", chosen.label);
    let file = chosen.config;
    let mut config = file.ppo.clone();
    prepare(&mut config, &args.run)?;
    let trained = TrainBodyConfig {
        ppo: config.clone(),
        ..file.clone()
    };
    let skill_path = args
        .skill
        .clone()
        .unwrap_or_else(kumi_runtime::shipped_arm_policy);
    let skill = std::fs::read(&skill_path)
        .with_context(|| format!("reading the skill {}", skill_path.display()))?;
    let engine = training_engine(&args.run)?;
    let body = file.environment(engine)?;
    let envs = (0..config.num_envs)
        .map(|i| {
            WholeBody::new(
                model.clone(),
                body.clone(),
                &skill,
                config.seed.wrapping_mul(1000).wrapping_add(i as u64),
            )
        })
        .collect::<Result<Vec<_>, _>>()
        .with_context(|| format!("building the whole-body environment for `{}`", model.name))?;
    let control_hz = kumi_worlds::SimConfig::for_model(&model).control_hz;
    let mut metadata = kumi_terms::contract::contract(
        &model,
        envs[0].terms(),
        file.observation,
        &skill,
        control_hz,
    );
    metadata.insert(
        kumi_policies::metadata::CONFIG_HASH.into(),
        kumi_policies::metadata::fingerprint(&serde_json::to_string(&trained)?),
    );
    // What deployment reads instead of the training config: the tilt limit, the targets, the
    // episode length.
    metadata.extend(trained.task.trained_task().metadata());
    eprintln!(
        "{} ({}): {} observations, {} actions ({}); {}",
        model.name,
        args.variant,
        envs[0].observation_dim(),
        envs[0].terms().size(),
        envs[0].terms().describe(),
        if envs[0].terms().uses_skill() {
            format!("skill {}", skill_path.display())
        } else {
            "no skill: arm joints commanded directly".into()
        }
    );
    if envs[0].critic_extras_dim() > 0 {
        eprintln!(
            "the critic also sees {} values ([critic]: {}); the policy file takes the {} observations",
            envs[0].critic_extras_dim(),
            serde_json::to_string(&file.critic)?,
            envs[0].observation_dim(),
        );
    }
    if !file.observation_noise.is_none() {
        eprintln!(
            "training noises the observation ([observation_noise], standard deviations in each slot's unit: {}); evaluation and the policy file do not",
            serde_json::to_string(&file.observation_noise)?,
        );
    }
    let name = args.variant.policy_name(&model.name);
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("runs").join(&name));
    train(
        &format!("the whole-body policy of `{}`", model.name),
        config,
        envs,
        &args.run,
        &out,
        PolicyFile {
            metadata,
            prior: None,
        },
        &name,
    )?;
    Ok(())
}

/// One figure of the progress line: a metric no episode gave this iteration (NaN: none
/// ended) is a dash.
fn figure(name: &str, value: f64) -> String {
    if value.is_finite() {
        format!("{name} {value:.3}")
    } else {
        format!("{name} -")
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_metric_no_episode_gave_prints_as_a_dash() {
        assert_eq!(
            super::figure("termination_rate", 0.25),
            "termination_rate 0.250"
        );
        assert_eq!(
            super::figure("termination_rate", f64::NAN),
            "termination_rate -"
        );
    }

    #[test]
    fn the_shipped_skill_config_keeps_the_shipped_skills_fingerprint() {
        // Keys added since (a load, the targets' lead, the lead penalty) are left out of the
        // fingerprint when absent: `kumi train arm` still reproduces the shipped file.
        let model = crate::sim::load_model("arm").unwrap();
        let skill = kumi_policies::skill::ArmSkill::new(&model.modules[0], 30.0).unwrap();
        let shipped = kumi_runtime::SkillPolicy::load(
            &kumi_runtime::shipped_arm_policy(),
            &skill,
            kumi_runtime::BackendChoice::Tract,
        )
        .unwrap();
        let config = read_config(None).unwrap();
        assert_eq!(
            config.fingerprint().unwrap(),
            shipped.metadata()[kumi_policies::metadata::CONFIG_HASH]
        );
        assert_eq!(
            shipped.observation_dim(),
            kumi_policies::observation::BASE_DIM
        );
    }

    use super::*;

    #[test]
    fn the_default_recipe_moves_its_targets_with_the_tool_and_is_dragons_own_on_dragon() {
        assert_eq!(target_heights_m([0.9, 1.5], 1.343, 1.343), [0.9, 1.5]);
        let moved = target_heights_m([0.9, 1.5], 1.343, 0.851);
        assert!(
            (moved[0] - 0.41).abs() < 1e-9 && (moved[1] - 1.01).abs() < 1e-9,
            "{moved:?}"
        );
        let dragon = crate::sim::load_model("dragon").unwrap();
        let chosen = body_config_for(&dragon, None, Variant::Hierarchical, false).unwrap();
        assert!(!chosen.default_recipe);
        // A robot kumi does not ship.
        let text = std::fs::read_to_string(
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples/caterpillar.toml"),
        )
        .unwrap();
        let dir = std::env::temp_dir().join(format!("kumi-recipe-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("caterpillar.toml");
        std::fs::write(&file, text).unwrap();
        let caterpillar = crate::sim::load_model(file.to_str().unwrap()).unwrap();
        let chosen = body_config_for(&caterpillar, None, Variant::Hierarchical, false).unwrap();
        assert!(chosen.default_recipe, "{}", chosen.label);
        let [lo, hi] = chosen.config.task.target_z_m;
        assert!(
            (hi - lo - 0.6).abs() < 1e-9 && (0.8..1.1).contains(&lo),
            "{lo}-{hi}"
        );
        assert!(
            chosen.label.contains("the default recipe"),
            "{}",
            chosen.label
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn every_shipped_whole_body_config_parses_as_its_variant() {
        for (robot, variant, _) in SHIPPED_BODY_CONFIGS {
            let config = read_body_config(None, robot, variant).unwrap();
            let arms = config.arms().unwrap();
            match variant {
                Variant::Hierarchical => assert!(matches!(arms, ArmControl::Skill(_))),
                _ => assert!(matches!(arms, ArmControl::Joints(_)), "{robot} {variant}"),
            }
            assert_eq!(config.penalty.is_some(), variant == Variant::Penalty);
        }
        let err = read_body_config(None, "dragon", Variant::Penalty).unwrap_err();
        assert!(err.to_string().contains("no shipped penalty"), "{err}");
    }

    /// The bounds on the wheels a config's policy may command: velocity [rad/s],
    /// acceleration [rad/s^2] and the turn governor's lateral acceleration [m/s^2].
    fn wheel_bound(config: &TrainBodyConfig) -> (Option<f64>, Option<f64>, Option<f64>) {
        match config.arms().unwrap() {
            ArmControl::Skill(b) => (
                b.wheel_velocity_rad_s,
                b.wheel_acceleration_rad_s2,
                b.lateral_acceleration_m_s2,
            ),
            ArmControl::Joints(b) => (
                b.wheel_velocity_rad_s,
                b.wheel_acceleration_rad_s2,
                b.lateral_acceleration_m_s2,
            ),
        }
    }

    #[test]
    fn a_robots_variants_share_task_and_reward_and_its_targets_are_within_reach() {
        // The baselines are compared with the hierarchical policy on the same task, reward
        // (Table IV's terms; the penalty baseline adds its own on top) and wheel bounds; and the
        // target heights must lie around the manipulator's tool standing at home, where its
        // goal box (+-manipulator_position_m) can bring it. Tricycle's tool stands 0.9 m higher
        // than Minimal's; its first configs kept Minimal's heights, and no hierarchical policy
        // could come within 0.75 m of a target.
        for robot in ["minimal", "dragon", "tricycle"] {
            let hierarchical = read_body_config(None, robot, Variant::Hierarchical).unwrap();
            for (other, variant, _) in SHIPPED_BODY_CONFIGS {
                if other == robot && variant != Variant::Hierarchical {
                    let config = read_body_config(None, robot, variant).unwrap();
                    assert_eq!(config.task, hierarchical.task, "{robot} {variant}");
                    assert_eq!(config.reward, hierarchical.reward, "{robot} {variant}");
                    assert_eq!(
                        wheel_bound(&config),
                        wheel_bound(&hierarchical),
                        "{robot} {variant}: the wheels' velocity, acceleration and turn bounds"
                    );
                }
            }
            let ArmControl::Skill(bounds) = hierarchical.arms().unwrap() else {
                panic!("{robot}: the hierarchical config drives the skill")
            };
            let home_z = standing_tool_height_m(robot);
            let [lo, hi] = hierarchical.task.target_z_m;
            let middle = 0.5 * (lo + hi);
            assert!(
                (middle - home_z).abs() < bounds.manipulator_position_m,
                "{robot}: targets at z in [{lo}, {hi}] m, the tool at home at {home_z:.2} m"
            );
        }
    }

    #[test]
    fn tricycles_later_stage_configs_change_only_the_steps_noise_and_governor() {
        // The shipped policy is tricycle.toml resumed with tricycle_settle.toml, then with
        // tricycle_third.toml, tricycle_fourth.toml, tricycle_fifth.toml and
        // tricycle_sixth.toml: the task and reward it trained on must stay the first stage's,
        // its action bounds too but for the fourth stage's tighter turn governor (which the
        // fifth and sixth keep), and each stage must go on where the one before it stopped.
        let first = read_body_config(None, "tricycle", Variant::Hierarchical).unwrap();
        let stage = |name: &str| {
            let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../train/configs/whole_body")
                .join(name);
            read_body_config(Some(&path), "tricycle", Variant::Hierarchical).unwrap()
        };
        let second = stage("tricycle_settle.toml");
        let third = stage("tricycle_third.toml");
        let fourth = stage("tricycle_fourth.toml");
        let fifth = stage("tricycle_fifth.toml");
        let sixth = stage("tricycle_sixth.toml");
        let stages = [&first, &second, &third, &fourth, &fifth, &sixth];
        for pair in stages.windows(2) {
            let (before, after) = (pair[0], pair[1]);
            assert_eq!(after.task, first.task);
            assert_eq!(after.reward, first.reward);
            assert_eq!(after.penalty, first.penalty);
            assert_eq!(after.observation, first.observation);
            assert_stage_follows(&before.ppo, &after.ppo);
        }
        assert_eq!(second.action, first.action);
        assert_eq!(third.action, first.action);
        assert_eq!(fifth.action, fourth.action);
        assert_eq!(sixth.action, fourth.action);
        let (first_bounds, fourth_bounds) = (first.action.unwrap(), fourth.action.unwrap());
        assert_eq!(fourth_bounds.lateral_acceleration_m_s2, Some(0.07));
        assert_eq!(
            GoalBounds {
                lateral_acceleration_m_s2: first_bounds.lateral_acceleration_m_s2,
                ..fourth_bounds
            },
            first_bounds
        );
        // What eval checks the shipped policy against by default is its last stage; training
        // starts from the first.
        let shipped = read_shipped_policy_config(None, "tricycle", Variant::Hierarchical).unwrap();
        assert_eq!(shipped.action, sixth.action);
        assert_eq!(shipped.ppo, sixth.ppo);
        for (robot, variant, _) in SHIPPED_BODY_CONFIGS {
            if (robot, variant) != ("tricycle", Variant::Hierarchical) {
                let (a, b) = (
                    read_shipped_policy_config(None, robot, variant).unwrap(),
                    read_body_config(None, robot, variant).unwrap(),
                );
                assert_eq!((a.ppo, a.action, a.flat), (b.ppo, b.action, b.flat));
            }
        }
    }

    /// `after` resumes a run of `before`: more steps, its noise cap starting where `before`'s
    /// ended and not rising from there, every other PPO setting the same.
    fn assert_stage_follows(before: &PpoConfig, after: &PpoConfig) {
        assert!(after.total_steps > before.total_steps);
        let start = after.total_steps as f64 * after.anneal_after;
        assert!(
            (start - before.total_steps as f64).abs() < 4096.0,
            "{start}"
        );
        let ended = before
            .log_std_cap(before.total_steps)
            .unwrap_or(before.initial_log_std);
        let cap = after.log_std_cap(before.total_steps).unwrap();
        assert!((cap - ended).abs() < 1e-3, "{cap} against {ended}");
        assert!(after.final_log_std.unwrap() <= ended);
        assert_eq!(
            PpoConfig {
                total_steps: before.total_steps,
                anneal_after: before.anneal_after,
                initial_log_std: before.initial_log_std,
                final_log_std: before.final_log_std,
                ..after.clone()
            },
            *before
        );
    }

    /// The manipulator tool's height [m] with the robot standing at home.
    fn standing_tool_height_m(robot: &str) -> f64 {
        let model = load_model(robot).unwrap();
        let sim = kumi_worlds::SimConfig::for_model(&model);
        let mut world =
            kumi_worlds::build(kumi_worlds::Engine::Rapier, model.clone(), sim).unwrap();
        let state = world.standing_state(0.0, 0.0, 0.0, kumi_worlds::home_joint_positions(&model));
        world.reset(&state);
        let manipulator = model
            .modules_with_role(kumi_model::Role::Manipulator)
            .next()
            .unwrap();
        let tool = manipulator.ee_link.as_ref().unwrap();
        world.link_pose(tool).unwrap().translation.z
    }

    #[test]
    fn the_observation_section_is_optional_checked_and_out_of_the_hash_when_absent() {
        let (_, _, text) = SHIPPED_BODY_CONFIGS[2];
        let plain: TrainBodyConfig = toml::from_str(text).unwrap();
        assert!(plain.observation.is_none());
        // Absent, it is not serialised: the config hash of policies trained before the section
        // existed stays theirs.
        assert!(!serde_json::to_string(&plain)
            .unwrap()
            .contains("observation"));
        let with = format!("{text}\n[observation]\nbase_angular_velocity = true\n");
        let spinning: TrainBodyConfig = toml::from_str(&with).unwrap();
        assert!(spinning.observation.base_angular_velocity);
        let env = spinning.environment(kumi_worlds::Engine::Rapier).unwrap();
        assert!(env.observation.base_angular_velocity);
        assert!(!env.observation.arm_joint_angles);
        let angles = format!("{text}\n[observation]\narm_joint_angles = true\n");
        let angles: TrainBodyConfig = toml::from_str(&angles).unwrap();
        assert!(angles.observation.arm_joint_angles && !angles.observation.base_angular_velocity);
        let typo = format!("{text}\n[observation]\nbase_angular_velocty = true\n");
        let err = toml::from_str::<TrainBodyConfig>(&typo)
            .unwrap_err()
            .to_string();
        assert!(err.contains("base_angular_velocty"), "{err}");
    }

    #[test]
    fn the_training_only_sections_are_optional_out_of_the_hash_when_absent_and_off_in_eval() {
        // [push], [replay], [critic], [observation_noise] and [ppo]'s critic_learning_rate change
        // training, not the policy: absent, none is serialised, so every shipped policy keeps its
        // config hash.
        for (_, _, text) in SHIPPED_BODY_CONFIGS.iter().chain(&SHIPPED_LAST_STAGES) {
            let plain: TrainBodyConfig = toml::from_str(text).unwrap();
            assert!(plain.push.is_none() && plain.replay.is_none());
            assert!(plain.ppo.critic_learning_rate.is_none() && plain.critic.is_none());
            assert!(plain.observation_noise.is_none());
            let json = serde_json::to_string(&plain).unwrap();
            let keys = [
                "push",
                "replay",
                "critic_learning_rate",
                "\"critic\"",
                "observation_noise",
            ];
            for key in keys {
                assert!(!json.contains(key), "{key} in {json}");
            }
        }
        let (_, _, text) = SHIPPED_BODY_CONFIGS[2];
        let with = format!(
            "{}\n[push]\ninterval_s = [3.0, 6.0]\nvelocity_m_s = 0.5\ntip_rad_s = 1.0\n\n[replay]\ntilt_rad = 0.3\nbefore_s = 1.5\nprobability = 0.15\ncapacity = 16\n",
            text.replacen("\n[ppo]", "\n[ppo]\ncritic_learning_rate = 3e-4\n#", 1)
        );
        let config: TrainBodyConfig = toml::from_str(&with).unwrap();
        assert_eq!(config.ppo.critic_learning_rate, Some(3e-4));
        assert!(config.critic.is_none());
        let privileged = format!("{with}\n[critic]\nbase_height = true\narm_joint_state = true\n");
        let privileged: TrainBodyConfig = toml::from_str(&privileged).unwrap();
        let critic = privileged
            .environment(kumi_worlds::Engine::Rapier)
            .unwrap()
            .critic;
        assert!(critic.base_height && critic.arm_joint_state && !critic.base_angular_velocity);
        // Set, it is part of the config (and its hash); misspelt, it is refused by name.
        assert!(serde_json::to_string(&privileged)
            .unwrap()
            .contains("\"critic\":{\"base_angular_velocity\":false,\"base_height\":true"));
        let typo = format!("{with}\n[critic]\nbase_heigth = true\n");
        let err = toml::from_str::<TrainBodyConfig>(&typo)
            .unwrap_err()
            .to_string();
        assert!(err.contains("base_heigth"), "{err}");
        // Set, it is in the hash; a slot at 0 is a slot left out, there as everywhere.
        let noised = format!(
            "{with}\n[observation_noise]\nprojected_gravity = 0.02\nbase_linear_velocity = 0.0\n"
        );
        let noised: TrainBodyConfig = toml::from_str(&noised).unwrap();
        let env = noised.environment(kumi_worlds::Engine::Rapier).unwrap();
        assert_eq!(env.observation_noise.0["projected_gravity"], 0.02);
        assert!(serde_json::to_string(&noised)
            .unwrap()
            .contains("\"observation_noise\":{\"projected_gravity\":0.02}"));
        let zero = format!("{with}\n[observation_noise]\nprojected_gravity = 0.0\n");
        let zero: TrainBodyConfig = toml::from_str(&zero).unwrap();
        assert!(!serde_json::to_string(&zero)
            .unwrap()
            .contains("observation_noise"));
        let env = config.environment(kumi_worlds::Engine::Rapier).unwrap();
        assert_eq!(env.push.unwrap().tip_rad_s, 1.0);
        assert_eq!(env.replay.unwrap().capacity, 16);
        let typo = with.replace("tip_rad_s", "tip_rads");
        let err = toml::from_str::<TrainBodyConfig>(&typo)
            .unwrap_err()
            .to_string();
        assert!(err.contains("tip_rads"), "{err}");
    }

    #[test]
    fn a_resumed_run_refuses_a_metrics_file_of_other_columns() {
        let dir = std::env::temp_dir().join(format!("kumi-metrics-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("metrics.csv");
        std::fs::write(&path, "iteration,a\n1,0.5\n2,0.6\n3,0.7\n").unwrap();
        // The same columns: the rows up to the checkpoint's iteration stay.
        drop(open_metrics(&path, true, 2, "iteration,a").unwrap());
        assert_eq!(
            std::fs::read_to_string(&path).unwrap(),
            "iteration,a\n1,0.5\n2,0.6\n"
        );
        let err = open_metrics(&path, true, 2, "iteration,a,b")
            .unwrap_err()
            .to_string();
        assert!(err.contains("another --out"), "{err}");
        // A new run starts the file afresh with its own columns.
        drop(open_metrics(&path, false, 0, "iteration,a,b").unwrap());
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "iteration,a,b\n");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_config_with_both_or_neither_arm_control_is_refused() {
        let (_, _, flat) = SHIPPED_BODY_CONFIGS[3];
        let both = format!("{flat}\n[action]\nmanipulator_position_m = 0.25\nmanipulator_rotation_rad = 0.5\nleg_position_m = 0.1\nleg_roll_rad = 0.5\n");
        let config: TrainBodyConfig = toml::from_str(&both).unwrap();
        assert!(config.arms().unwrap_err().to_string().contains("both"));
        let neither = flat
            .replace("[flat]", "[unused]")
            .replace("joint_scale_rad = 0.5", "");
        let neither = &neither[..neither.find("[unused]").unwrap()];
        let config: TrainBodyConfig = toml::from_str(neither).unwrap();
        assert!(config.arms().unwrap_err().to_string().contains("neither"));
    }
}
