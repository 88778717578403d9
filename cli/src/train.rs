//! `kumi train arm`: trains the low-level reaching skill with PPO.

use std::io::Write;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use clap::{Args, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use kumi_train::arm_reach::{ArmReach, ArmReachConfig, GoalConfig};
use kumi_train::ppo::trainer::{IterationStats, PpoConfig, Trainer};
use kumi_train::reward::ReachWeights;

/// The training config file: PPO hyperparameters, the reward's weights and the goals.
#[derive(Debug, serde::Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct TrainArmConfig {
    pub ppo: PpoConfig,
    pub reward: ReachWeights,
    pub goals: GoalConfig,
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
    /// The low-level skill: one fixed-base arm reaching goals (SPEC section 4).
    Arm(TrainArmArgs),
}

#[derive(Args, Debug)]
pub struct TrainArmArgs {
    /// PPO hyperparameters (TOML; default: the shipped train/configs/arm_reach.toml).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Override the number of environment steps.
    #[arg(long)]
    pub steps: Option<u64>,
    /// Override the seed.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Where metrics (metrics.csv) and checkpoints (checkpoint/) go.
    #[arg(long, default_value = "runs/arm_reach")]
    pub out: PathBuf,
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

/// Iterations between checkpoints.
const CHECKPOINT_EVERY: usize = 10;
/// Iterations between progress lines when stderr is not a terminal.
const LOG_EVERY: usize = 5;

const SHIPPED_CONFIG: &str = include_str!("../../train/configs/arm_reach.toml");

const COLUMNS: [&str; 16] = [
    "iteration",
    "env_steps",
    "collect_steps_per_s",
    "update_samples_per_s",
    "mean_step_reward",
    "mean_episode_return",
    "final_position_error",
    "final_orientation_error",
    "policy_loss",
    "value_loss",
    "entropy",
    "approx_kl",
    "clip_fraction",
    "action_std",
    "learning_rate",
    "wall_s",
];

fn row(s: &IterationStats, wall_s: f64) -> String {
    let v = [
        s.iteration as f64,
        s.env_steps as f64,
        s.collect_steps_per_s,
        s.update_samples_per_s,
        s.mean_step_reward,
        s.mean_episode_return,
        s.final_position_error,
        s.final_orientation_error,
        s.policy_loss,
        s.value_loss,
        s.entropy,
        s.approx_kl,
        s.clip_fraction,
        s.action_std,
        s.learning_rate,
        wall_s,
    ];
    v.iter()
        .map(|x| x.to_string())
        .collect::<Vec<_>>()
        .join(",")
}

pub fn run(what: TrainCommand) -> Result<()> {
    let TrainCommand::Arm(args) = what;
    let file = read_config(args.config.as_deref())?;
    let goals = file.goals.resolve()?;
    let mut config = file.ppo;
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
    // What is trained, overrides included: its fingerprint goes into the policy's metadata.
    let trained = TrainArmConfig {
        ppo: config.clone(),
        reward: file.reward,
        goals: file.goals.clone(),
    };
    let model = load_model("arm")?;
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
    let envs = (0..config.num_envs)
        .map(|i| {
            ArmReach::new(
                model.clone(),
                ArmReachConfig {
                    engine,
                    weights: file.reward,
                    goals: goals.clone(),
                    ..ArmReachConfig::default()
                },
                config.seed.wrapping_mul(1000).wrapping_add(i as u64),
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let csv_path = args.out.join("metrics.csv");
    let mut csv = std::fs::File::create(&csv_path)
        .with_context(|| format!("creating {}", csv_path.display()))?;
    writeln!(csv, "{}", COLUMNS.join(","))?;

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
    let checkpoint = args.out.join("checkpoint");
    let start = Instant::now();
    eprintln!(
        "training the arm-reaching skill for {total} steps; metrics in {}",
        csv_path.display()
    );
    // A live bar on a terminal; on a pipe or file (CI, nohup) a line every few iterations.
    let bar = ProgressBar::new(total).with_style(
        ProgressStyle::with_template(
            "{bar:30} {pos}/{len} steps [{elapsed_precise} < {eta_precise}] {msg}",
        )
        .expect("a valid template"),
    );
    bar.set_position(trainer.env_steps);
    while trainer.env_steps < total {
        let s = trainer.iterate();
        let wall = start.elapsed().as_secs_f64();
        writeln!(csv, "{}", row(&s, wall))?;
        let status = format!(
            "{:.0} steps/s collect, {:.0} samples/s update | reward/step {:.3} | final error {:.3} m, {:.3} rad | std {:.3}",
            s.collect_steps_per_s,
            s.update_samples_per_s,
            s.mean_step_reward,
            s.final_position_error,
            s.final_orientation_error,
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

    // The deterministic actor, normalisation included, with the skill's metadata.
    let metadata = kumi_policies::skill::ArmSkill::new(
        &model.modules[0],
        kumi_worlds::SimConfig::for_model(&model).control_hz,
    )?
    .metadata(
        // Of the values, not the text: comments and layout do not change what was trained.
        &kumi_policies::metadata::fingerprint(&serde_json::to_string(&trained)?),
        trainer.env_steps,
    );
    let onnx = kumi_train::export::actor_model(
        &trainer.norm,
        &trainer.learner.net.actor.parameters(),
        &metadata,
    );
    let onnx_path = args.out.join("arm_reach.onnx");
    std::fs::write(&onnx_path, kumi_train::export::encode(&onnx))
        .with_context(|| format!("writing {}", onnx_path.display()))?;
    eprintln!("policy in {}", onnx_path.display());
    Ok(())
}
