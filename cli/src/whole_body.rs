//! `kumi whole-body`: the whole-body node, running a robot's upper-level policy.

use crate::train::Variant;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{bail, Context, Result};
use clap::Args;
use kumi_runtime::BackendChoice;
use kumi_whole_body_node::WholeBodyNodeConfig;

use crate::sim::load_model;

#[derive(Args, Debug)]
pub struct WholeBodyArgs {
    /// Robot name, the namespace of every topic (`/<robot>/...`), as given to the sim bridge.
    #[arg(long)]
    pub robot: String,
    /// The robot's morphology: `minimal`, `dragon`, `tricycle`, or a morphology file
    /// (default: the robot name).
    #[arg(long)]
    pub morphology: Option<String>,
    /// The whole-body ONNX policy (default: the shipped policies/<morphology>_whole_body/<morphology>_whole_body.onnx).
    #[arg(long)]
    pub policy: Option<PathBuf>,
    /// The skill the arm nodes run (default: the shipped policies/arm_reach/arm_reach.onnx); the policy
    /// must have been trained over it.
    #[arg(long)]
    pub skill: Option<PathBuf>,
    /// Inference backend: auto (ONNX Runtime when ORT_DYLIB_PATH is set, else tract),
    /// onnxruntime or tract.
    #[arg(long, default_value = "auto")]
    pub backend: BackendChoice,
    /// Inputs older than this [s] make the node hold (wheels stop, arms keep their goals).
    #[arg(long, default_value_t = 0.5)]
    pub stale_after: f64,
    /// Targets further than this [m] from the base (horizontally) are refused: the policies are
    /// trained on targets within 3 m of the origin, the robot starting within 0.5 m of it.
    #[arg(long, default_value_t = 4.5)]
    pub max_target_distance: f64,
    /// Base tilt [rad] past which the node stops driving (wheels stop, arms keep their goals)
    /// until a new target: the policy never saw a robot tilted further, its training episodes
    /// ended there. Default: the shipped robot's training limit
    /// (`tilt_limit_rad` in train/configs/whole_body/<morphology>.toml); none for another
    /// morphology unless given.
    #[arg(long, value_name = "RAD")]
    pub tilt_limit_rad: Option<f64>,
    /// On MoonBot hardware: the Motion Stack profile (limb namespaces, joint names, the
    /// odometry topic; see the README). Joint states come from each limb's `joint_read`, wheel
    /// velocities go to each wheel limb's `joint_set`.
    #[arg(long, value_name = "PROFILE")]
    pub hardware: Option<PathBuf>,
}

pub fn run(args: WholeBodyArgs) -> Result<()> {
    if !(args.stale_after.is_finite() && args.stale_after > 0.0) {
        bail!("--stale-after must be a positive number of seconds");
    }
    if !(args.max_target_distance.is_finite() && args.max_target_distance > 0.0) {
        bail!("--max-target-distance must be a positive number of metres");
    }
    let model = load_model(args.morphology.as_deref().unwrap_or(&args.robot))?;
    let tilt_limit_rad = tilt_limit(args.tilt_limit_rad, &model.name)?;
    if let (None, Some(limit)) = (args.tilt_limit_rad, tilt_limit_rad) {
        tracing::info!(
            "tilt limit {limit} rad: the shipped `{}` policy's training limit (train/configs/whole_body/{}.toml); --tilt-limit-rad for another",
            model.name,
            model.name
        );
    }
    let hardware = match &args.hardware {
        Some(path) => Some(Arc::new(crate::launch::load_profile(&model, path)?)),
        None => None,
    };
    let config = WholeBodyNodeConfig {
        policy: args
            .policy
            .unwrap_or_else(|| Variant::Hierarchical.default_policy(&model.name)),
        skill: args.skill.unwrap_or_else(kumi_runtime::shipped_arm_policy),
        robot: args.robot,
        backend: args.backend,
        domain_id: kumi_ros::domain_id_from_env()?,
        stale_after_s: args.stale_after,
        max_target_distance_m: args.max_target_distance,
        tilt_limit_rad,
        duplicate_check: std::time::Duration::from_millis(1500),
        hardware,
        model,
    };
    let shutdown = Arc::new(AtomicBool::new(false));
    let flag = shutdown.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    kumi_whole_body_node::run(config, shutdown)?;
    Ok(())
}

/// The tilt limit [rad]: as given, else the one the shipped robot's policy was trained with.
fn tilt_limit(given: Option<f64>, morphology: &str) -> Result<Option<f64>> {
    match given {
        Some(limit) if !(limit.is_finite() && limit > 0.0 && limit <= std::f64::consts::PI) => {
            bail!("--tilt-limit-rad must be an angle in (0, pi], not {limit}")
        }
        Some(limit) => Ok(Some(limit)),
        None => Ok(crate::train::read_body_config(
            None,
            morphology,
            crate::train::Variant::Hierarchical,
        )
        .ok()
        .map(|c| c.task.tilt_limit_rad)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tilt_limit_is_the_training_one_unless_given() {
        assert_eq!(tilt_limit(None, "minimal").unwrap(), Some(0.6));
        assert_eq!(tilt_limit(None, "dragon").unwrap(), Some(1.0));
        assert_eq!(tilt_limit(None, "tricycle").unwrap(), Some(0.785));
        assert_eq!(tilt_limit(None, "my_robot").unwrap(), None);
        assert_eq!(tilt_limit(Some(0.5), "tricycle").unwrap(), Some(0.5));
        for bad in [0.0, -1.0, f64::NAN, 4.0] {
            let err = tilt_limit(Some(bad), "tricycle").unwrap_err();
            assert!(err.to_string().contains("--tilt-limit-rad"), "{err}");
        }
    }
}
