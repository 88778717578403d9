//! `kumi bench sim`: simulation speed (control steps per second, single world and parallel
//! worlds), world build time and reset time; optionally the standing-stability figures of the
//! same configuration, so that a faster configuration is never reported without its cost.

use std::sync::Arc;
use std::time::Instant;

use anyhow::{bail, Result};
use clap::{Args, Subcommand};
use kumi_model::{ActuatorMode, RobotModel};
use kumi_worlds::{Engine, SimConfig, SimWorld};
use rayon::prelude::*;
use serde::Serialize;

use crate::sim::{load_model, PhysicsArgs};

#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Simulation speed: control steps per second, build and reset time.
    Sim(BenchSimArgs),
    /// Learner speed: PPO update samples per second and collection steps per second.
    Learn(crate::bench_learn::BenchLearnArgs),
}

#[derive(Args, Debug)]
pub struct BenchSimArgs {
    /// Morphologies to measure (shipped names or files).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "arm,minimal,dragon,tricycle"
    )]
    pub models: Vec<String>,
    /// Simulated seconds per speed measurement.
    #[arg(long, default_value_t = 20.0)]
    pub seconds: f64,
    /// Worlds stepped in parallel, one per thread, for the parallel figure (0: one per core).
    #[arg(long, default_value_t = 0)]
    pub worlds: usize,
    /// Also stand each robot 60 s at home with wheels braked and report drift, tilt and mount error.
    #[arg(long)]
    pub stability: bool,
    /// Print one JSON array of records instead of a table.
    #[arg(long)]
    pub json: bool,
    /// Engines to measure, interleaved model by model (e.g. `rapier,mujoco`; default: the
    /// engine of --engine, or rapier).
    #[arg(long, value_delimiter = ',', value_parser = crate::engine::parse)]
    pub engines: Vec<Engine>,
    #[command(flatten)]
    pub physics: PhysicsArgs,
}

#[derive(Serialize)]
struct Record {
    model: String,
    engine: String,
    config: String,
    threads: usize,
    worlds: usize,
    control_steps_per_s: f64,
    build_ms: f64,
    reset_us: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    stability: Option<Stability>,
}

#[derive(Serialize, Clone, Copy)]
struct Stability {
    drift_m: f64,
    max_tilt_deg: f64,
    max_mount_error_deg: f64,
    lowest_point_m: f64,
}

/// A deterministic, representative load: every arm joint tracks a slow sine around home
/// (0.2 rad, 0.5 Hz), every wheel module turns at 1 rad/s.
fn drive(world: &mut dyn SimWorld, home: &[f64], step: u64) {
    let model = world.model().clone();
    let t = step as f64 / world.config().control_hz;
    let offset = 0.2 * (std::f64::consts::PI * t).sin();
    let mut index = 0;
    for m in &model.modules {
        let range = index..index + m.actuators.len();
        index = range.end;
        if m.actuators.iter().any(|a| a.mode == ActuatorMode::Velocity) {
            world
                .set_wheel_velocity(&m.name, 1.0)
                .expect("wheel module");
        } else if !m.actuators.is_empty() {
            let targets: Vec<f64> = home[range].iter().map(|q| q + offset).collect();
            world
                .set_position_targets(&m.name, &targets)
                .expect("arm module");
        }
    }
}

fn steps_per_second(
    engine: Engine,
    model: &Arc<RobotModel>,
    config: SimConfig,
    steps: u64,
) -> Result<f64> {
    let mut world = crate::engine::world(engine, model.clone(), config)?;
    let home = world.home_state().joint_positions;
    let start = Instant::now();
    for k in 0..steps {
        drive(world.as_mut(), &home, k);
        world.step();
    }
    Ok(steps as f64 / start.elapsed().as_secs_f64())
}

fn median(mut xs: Vec<f64>) -> f64 {
    xs.sort_by(f64::total_cmp);
    xs[xs.len() / 2]
}

fn stability(engine: Engine, model: &Arc<RobotModel>, config: SimConfig) -> Result<Stability> {
    let mut world = crate::engine::world(engine, model.clone(), config)?;
    let start = world.base_pose().translation.vector;
    let (mut tilt_max, mut mount_max, mut lowest) = (0.0_f64, 0.0_f64, f64::INFINITY);
    for _ in 0..(60.0 * config.control_hz) as u64 {
        world.step();
        tilt_max = tilt_max.max(world.base_tilt());
        lowest = lowest.min(world.lowest_collider_z());
        for (_, _, r) in world.mount_errors() {
            mount_max = mount_max.max(r);
        }
    }
    // Horizontal creep: settling a few millimetres onto the servos is not drift.
    let drift = (world.base_pose().translation.vector - start).xy().norm();
    Ok(Stability {
        drift_m: drift,
        max_tilt_deg: tilt_max.to_degrees(),
        max_mount_error_deg: mount_max.to_degrees(),
        lowest_point_m: lowest,
    })
}

fn bench_model(
    engine: Engine,
    name: &str,
    args: &BenchSimArgs,
    worlds: usize,
) -> Result<Vec<Record>> {
    let model = load_model(name)?;
    let config = args.physics.config(&model);
    let steps = (args.seconds * config.control_hz).round().max(1.0) as u64;

    let build_ms = median(
        (0..7)
            .map(|_| {
                let t = Instant::now();
                let w = crate::engine::world(engine, model.clone(), config).map(|_| ());
                w.map(|_| t.elapsed().as_secs_f64() * 1e3)
            })
            .collect::<Result<Vec<_>, _>>()?,
    );
    let mut world = crate::engine::world(engine, model.clone(), config)?;
    let home = world.home_state();
    for _ in 0..30 {
        world.step();
    }
    let reset_us = median(
        (0..51)
            .map(|_| {
                let t = Instant::now();
                world.reset(&home);
                t.elapsed().as_secs_f64() * 1e6
            })
            .collect(),
    );
    let single = steps_per_second(engine, &model, config, steps)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(worlds)
        .build()?;
    let start = Instant::now();
    pool.install(|| {
        (0..worlds)
            .into_par_iter()
            .map(|_| steps_per_second(engine, &model, config, steps).map(|_| ()))
            .collect::<Result<Vec<_>>>()
    })?;
    let parallel = (steps * worlds as u64) as f64 / start.elapsed().as_secs_f64();
    let stability = if args.stability {
        Some(stability(engine, &model, config)?)
    } else {
        None
    };
    let record = |threads, worlds, rate| Record {
        model: model.name.clone(),
        engine: engine.to_string(),
        config: config.label_for(engine),
        threads,
        worlds,
        control_steps_per_s: rate,
        build_ms,
        reset_us,
        stability,
    };
    Ok(vec![record(1, 1, single), record(worlds, worlds, parallel)])
}

pub fn run(what: BenchCommand) -> Result<()> {
    let args = match what {
        BenchCommand::Sim(args) => args,
        BenchCommand::Learn(args) => return crate::bench_learn::run(args),
    };
    if !(args.seconds.is_finite() && args.seconds > 0.0) {
        bail!("--seconds must be positive, got {}", args.seconds);
    }
    let worlds = if args.worlds == 0 {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    } else {
        args.worlds
    };
    let engines = if args.engines.is_empty() {
        vec![args.physics.engine.unwrap_or(Engine::Rapier)]
    } else {
        args.engines.clone()
    };
    for &engine in &engines {
        crate::engine::choose(Some(engine), Engine::Rapier)?;
    }
    let mut records = Vec::new();
    for name in &args.models {
        for &engine in &engines {
            tracing::info!("benchmarking {name} on {engine}");
            records.extend(bench_model(engine, name, &args, worlds)?);
        }
    }
    if args.json {
        println!("{}", serde_json::to_string(&records)?);
        return Ok(());
    }
    println!("| model | engine | config | threads | worlds | control steps/s | build [ms] | reset [us] | 60 s xy drift [m] | max tilt [deg] | max mount error [deg] |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|");
    for r in &records {
        let (drift, tilt, mount) = match r.stability {
            Some(s) => (
                format!("{:.4}", s.drift_m),
                format!("{:.3}", s.max_tilt_deg),
                format!("{:.3}", s.max_mount_error_deg),
            ),
            None => ("-".into(), "-".into(), "-".into()),
        };
        println!(
            "| {} | {} | {} | {} | {} | {:.0} | {:.2} | {:.1} | {} | {} | {} |",
            r.model,
            r.engine,
            r.config,
            r.threads,
            r.worlds,
            r.control_steps_per_s,
            r.build_ms,
            r.reset_us,
            drift,
            tilt,
            mount
        );
    }
    Ok(())
}
