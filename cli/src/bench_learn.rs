//! `kumi bench learn`: the learner's throughput. The PPO update (samples per second, epochs
//! counted once, through the trainer's own update) for the skill's network and a
//! whole-body-sized one, and the collection rate of the arm-reach environment (environment steps
//! per second, policy inference included), each on one thread and on all of them.

use std::time::Instant;

use anyhow::{bail, Result};
use clap::Args;
use kumi_train::arm_reach::{ArmReach, ArmReachConfig};
use kumi_train::ppo::trainer::{Batch, Learner, PpoConfig, Trainer};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use crate::sim::load_model;

#[derive(Args, Debug)]
pub struct BenchLearnArgs {
    /// Timed repetitions per figure (the median is reported).
    #[arg(long, default_value_t = 5)]
    pub rounds: usize,
    /// Environments for the collection figure.
    #[arg(long, default_value_t = 16)]
    pub envs: usize,
    /// Thread counts to measure (default: 1 and every core).
    #[arg(long, value_delimiter = ',')]
    pub threads: Vec<usize>,
    /// Only the update, or only the collection.
    #[arg(long, value_parser = ["update", "collect"])]
    pub only: Option<String>,
    /// Physics engine of the collection figure (default: the training default).
    #[arg(long, value_parser = crate::engine::parse)]
    pub engine: Option<kumi_worlds::Engine>,
    /// Print one JSON array of records instead of a table.
    #[arg(long)]
    pub json: bool,
}

/// One measured figure.
#[derive(Debug, Serialize)]
pub struct Record {
    /// "update" or "collect".
    pub what: &'static str,
    /// Layer sizes, `obs-hidden..-act`.
    pub net: String,
    pub threads: usize,
    /// Environments (collection) or rollout samples / `rollout_steps` (update).
    pub envs: usize,
    /// Samples per second (update, epochs counted once) or environment steps per second.
    pub per_s: f64,
}

/// The networks measured: the skill's (the paper's Table II) and a whole-body-sized one.
const NETS: [(usize, usize, [usize; 2]); 2] = [(21, 7, [256, 128]), (64, 24, [512, 256])];

fn net_name(obs: usize, act: usize, hidden: &[usize]) -> String {
    let mut parts = vec![obs.to_string()];
    parts.extend(hidden.iter().map(|h| h.to_string()));
    parts.push(act.to_string());
    parts.join("-")
}

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

/// A synthetic rollout of the shipped config's size (what the anchor measures).
fn synthetic_batch(rows: usize, obs: usize, act: usize, rng: &mut ChaCha8Rng) -> Batch {
    let mut r = |n: usize| (0..n).map(|_| rng.random_range(-1.0_f32..1.0)).collect();
    Batch {
        observations: r(rows * obs),
        actions: r(rows * act),
        old_log_prob: r(rows),
        advantages: r(rows),
        returns: r(rows),
    }
}

fn bench_update(net: (usize, usize, [usize; 2]), rounds: usize) -> Result<(usize, f64)> {
    let (obs, act, hidden) = net;
    let config = PpoConfig {
        hidden: hidden.to_vec(),
        ..PpoConfig::default()
    };
    let rows = config.num_envs * config.rollout_steps;
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let batch = synthetic_batch(rows, obs, act, &mut rng);
    let mut learner = Learner::new(config.clone(), obs, act, &mut rng)?;
    learner.update(&batch, 0); // warm-up
    let times = (0..rounds)
        .map(|_| {
            let start = Instant::now();
            learner.update(&batch, 0);
            start.elapsed().as_secs_f64()
        })
        .collect();
    Ok((config.num_envs, rows as f64 / median(times)))
}

fn bench_collect(envs: usize, engine: kumi_worlds::Engine, rounds: usize) -> Result<f64> {
    let model = load_model("arm")?;
    let config = PpoConfig {
        num_envs: envs,
        rollout_steps: 64,
        ..PpoConfig::default()
    };
    let envs = (0..envs)
        .map(|i| {
            ArmReach::new(
                model.clone(),
                ArmReachConfig {
                    engine,
                    ..ArmReachConfig::default()
                },
                i as u64,
            )
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut trainer = Trainer::new(config, envs)?;
    trainer.collect_rate(); // warm-up
    Ok(median(
        (0..rounds).map(|_| trainer.collect_rate()).collect(),
    ))
}

fn in_pool<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> Result<T> {
    Ok(rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()?
        .install(f))
}

pub fn run(args: BenchLearnArgs) -> Result<()> {
    if args.rounds == 0 || args.envs == 0 {
        bail!("--rounds and --envs must be positive");
    }
    let threads = if args.threads.is_empty() {
        let all = std::thread::available_parallelism().map_or(1, |n| n.get());
        if all > 1 {
            vec![1, all]
        } else {
            vec![1]
        }
    } else {
        args.threads.clone()
    };
    if threads.contains(&0) {
        bail!("--threads must be positive");
    }
    let engine = crate::engine::choose(args.engine, kumi_worlds::default_training_engine())?;
    let mut records = Vec::new();
    if args.only.as_deref() != Some("collect") {
        for net in NETS {
            for &t in &threads {
                tracing::info!("update, {}, {t} threads", net_name(net.0, net.1, &net.2));
                let (envs, per_s) = in_pool(t, || bench_update(net, args.rounds))??;
                records.push(Record {
                    what: "update",
                    net: net_name(net.0, net.1, &net.2),
                    threads: t,
                    envs,
                    per_s,
                });
            }
        }
    }
    if args.only.as_deref() != Some("update") {
        for &t in &threads {
            tracing::info!(
                "collect, {} environments on {engine}, {t} threads",
                args.envs
            );
            let per_s = in_pool(t, || bench_collect(args.envs, engine, args.rounds))??;
            let (obs, act, hidden) = NETS[0];
            records.push(Record {
                what: "collect",
                net: net_name(obs, act, &hidden),
                threads: t,
                envs: args.envs,
                per_s,
            });
        }
    }
    if args.json {
        println!("{}", serde_json::to_string(&records)?);
        return Ok(());
    }
    println!("| what | net | threads | envs | per second |");
    println!("|---|---|---|---|---|");
    for r in &records {
        println!(
            "| {} | {} | {} | {} | {:.0} |",
            r.what, r.net, r.threads, r.envs, r.per_s
        );
    }
    Ok(())
}
