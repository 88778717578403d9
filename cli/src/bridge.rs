//! `kumi sim-bridge`: the simulated robot on ROS 2.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::{bail, Context, Result};
use clap::Args;
use kumi_sim_bridge::{BridgeConfig, Mode};

use crate::sim::load_model;

#[derive(Args, Debug)]
pub struct BridgeArgs {
    /// `minimal`, `dragon`, `tricycle`, `arm`, or a path to a morphology file.
    pub morphology: String,
    /// Robot name, the namespace of every topic (default: the morphology's name).
    #[arg(long)]
    pub robot: Option<String>,
    /// Advance one control step only when every commanded module has sent its command for the
    /// tick (or the lockstep timeout passes); publishes /clock; runs as fast as its consumers.
    #[arg(long)]
    pub lockstep: bool,
    /// Lockstep: step anyway after this long without every expected command [s]. Time stands
    /// still only before the first command: a controller that dies is stepped without, once
    /// per timeout (logged, and listed in /diagnostics as `lockstep_silent`), until its module
    /// holds.
    #[arg(long, default_value_t = 0.5)]
    pub lockstep_timeout: f64,
    /// Lockstep: the first step waits for a command from each of these modules, however long
    /// it takes (a launch names the modules whose nodes it started, so that a run never starts
    /// without a node that discovery has not found yet).
    #[arg(long, value_delimiter = ',', value_name = "MODULE,...")]
    pub wait_for: Vec<String>,
    /// Real-time mode: simulated seconds per wall-clock second.
    #[arg(long, default_value_t = 1.0)]
    pub realtime_factor: f64,
    /// A module whose commands stop for this long [s of sim time] holds its position.
    #[arg(long, default_value_t = 0.5)]
    pub stale_after: f64,
    /// Physics engine: rapier (default) or mujoco (with `--features mujoco`).
    #[arg(long, value_parser = crate::engine::parse)]
    pub engine: Option<kumi_worlds::Engine>,
}

pub fn run(args: BridgeArgs) -> Result<()> {
    let model = load_model(&args.morphology)?;
    if !args.lockstep && !args.wait_for.is_empty() {
        bail!("--wait-for applies to --lockstep only");
    }
    if !(args.lockstep_timeout.is_finite() && args.lockstep_timeout > 0.0) {
        bail!("--lockstep-timeout must be a positive number of seconds");
    }
    if !(args.stale_after.is_finite() && args.stale_after > 0.0) {
        bail!("--stale-after must be a positive number of seconds");
    }
    let config = BridgeConfig {
        engine: crate::engine::choose(args.engine, kumi_worlds::Engine::Rapier)?,
        robot: args.robot.unwrap_or_else(|| model.name.clone()),
        domain_id: kumi_ros::domain_id_from_env()?,
        model,
        mode: if args.lockstep {
            Mode::Lockstep {
                timeout: Duration::from_secs_f64(args.lockstep_timeout),
            }
        } else {
            Mode::RealTime {
                factor: args.realtime_factor,
            }
        },
        stale_after_s: args.stale_after,
        duplicate_check: Duration::from_millis(1500),
        first_step_waits_for: args.wait_for,
    };
    let shutdown = Arc::new(AtomicBool::new(false));
    let flag = shutdown.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    kumi_sim_bridge::run(config, shutdown)?;
    Ok(())
}
