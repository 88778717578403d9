//! `kumi arm`: the arm-module node, running the shared low-level skill for one arm module.

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::{Args, ValueEnum};
use kumi_arm_node::{ArmNodeConfig, ClockSource, Output};
use kumi_runtime::BackendChoice;

use crate::sim::load_model;

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum OutputArg {
    /// `joint_increments` (std_msgs/Float64MultiArray), for the sim bridge.
    Increments,
    /// `joint_set` (sensor_msgs/JointState, absolute targets), for MoonBot's Motion Stack.
    JointSet,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum ClockArg {
    /// Sim time once /clock is heard, wall time until then.
    Auto,
    Sim,
    Wall,
}

#[derive(Args, Debug)]
pub struct ArmArgs {
    /// The arm module to drive (`arm`, `leg1`, ...).
    pub module: String,
    /// Robot name, the namespace of every topic (`/<robot>/<module>/...`), as given to the
    /// sim bridge.
    #[arg(long, default_value = "arm")]
    pub robot: String,
    /// The robot's morphology: `minimal`, `dragon`, `tricycle`, `arm`, or a morphology file
    /// (default: the robot name).
    #[arg(long)]
    pub morphology: Option<String>,
    /// The ONNX skill policy (default: the shipped policies/arm_reach/arm_reach.onnx).
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// Inference backend: auto (ONNX Runtime when ORT_DYLIB_PATH is set, else tract),
    /// onnxruntime or tract.
    #[arg(long, default_value = "auto")]
    pub backend: BackendChoice,
    #[arg(long, value_enum, default_value_t = OutputArg::Increments)]
    pub output: OutputArg,
    #[arg(long, value_enum, default_value_t = ClockArg::Auto)]
    pub clock: ClockArg,
    /// Joint states older than this [s] make the node hold.
    #[arg(long, default_value_t = 0.2)]
    pub stale_after: f64,
    /// With a whole-body node sending the goals: wait up to this long [ms] for the goal computed
    /// from a tick's state before acting on that tick's joint states (sim time only), so the
    /// skill acts on the same tick's goal, as in training. 0: act on the latest goal at once.
    #[arg(long, default_value_t = 0.0)]
    pub goal_sync_ms: f64,
    /// With --goal-sync-ms: send no command before the first goal (in lockstep simulated time
    /// then stands still until the whole-body node has a target, so a run starts from the
    /// bridge's start state).
    #[arg(long)]
    pub wait_for_first_goal: bool,
    /// On MoonBot hardware: the Motion Stack profile (limb namespaces, joint names; see the
    /// README). Joint states come from the limb's `joint_read`, absolute targets go to its
    /// `joint_set`.
    #[arg(long, value_name = "PROFILE")]
    pub hardware: Option<PathBuf>,
}

pub fn run(args: ArmArgs) -> Result<()> {
    if !(args.stale_after.is_finite() && args.stale_after > 0.0) {
        bail!("--stale-after must be a positive number of seconds");
    }
    if !(args.goal_sync_ms.is_finite() && args.goal_sync_ms >= 0.0) {
        bail!("--goal-sync-ms must be a number of milliseconds >= 0");
    }
    let model = load_model(args.morphology.as_deref().unwrap_or(&args.robot))?;
    let hardware = match &args.hardware {
        Some(path) => Some(Arc::new(crate::launch::load_profile(&model, path)?)),
        None => None,
    };
    let config = ArmNodeConfig {
        robot: args.robot,
        module: args.module,
        policy: args.policy.unwrap_or_else(kumi_runtime::shipped_arm_policy),
        backend: args.backend,
        output: match args.output {
            OutputArg::Increments => Output::Increments,
            OutputArg::JointSet => Output::JointSet,
        },
        domain_id: kumi_ros::domain_id_from_env()?,
        clock: match args.clock {
            ClockArg::Auto => ClockSource::Auto,
            ClockArg::Sim => ClockSource::Sim,
            ClockArg::Wall => ClockSource::Wall,
        },
        stale_after_s: args.stale_after,
        duplicate_check: std::time::Duration::from_millis(1500),
        goal_sync_s: args.goal_sync_ms / 1000.0,
        wait_for_first_goal: args.wait_for_first_goal,
        hardware,
        model,
    };
    let shutdown = Arc::new(AtomicBool::new(false));
    let flag = shutdown.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    kumi_arm_node::run(config, shutdown)?;
    Ok(())
}
