//! `kumi whole-body`: the whole-body node, running a robot's upper-level policy.

use crate::train::Variant;
use kumi_terms::contract::TrainedTask;
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
    /// The sim bridge runs in lockstep: simulated time stands still until this node has
    /// answered, so it waits for every module's joint states of a tick however long that takes
    /// and never holds for inputs that are old only in wall time (`kumi launch --lockstep`
    /// gives it).
    #[arg(long)]
    pub lockstep: bool,
    /// Targets further than this [m] from the base (horizontally) are refused: the policies are
    /// trained on targets within 3 m of the origin, the robot starting within 0.5 m of it.
    #[arg(long, default_value_t = 4.5)]
    pub max_target_distance: f64,
    /// Base tilt [rad] past which the node stops driving (wheels stop, arms keep their goals)
    /// until a new target: the policy never saw a robot tilted further, its training episodes
    /// ended there. Default: the limit the policy was trained with (its metadata; for a policy
    /// exported without it, the shipped config's `tilt_limit_rad`).
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
    if args.lockstep && args.hardware.is_some() {
        bail!("--lockstep is for the sim bridge; on hardware time does not stand still");
    }
    if !(args.max_target_distance.is_finite() && args.max_target_distance > 0.0) {
        bail!("--max-target-distance must be a positive number of metres");
    }
    let model = load_model(args.morphology.as_deref().unwrap_or(&args.robot))?;
    let policy = args
        .policy
        .clone()
        .unwrap_or_else(|| Variant::Hierarchical.default_policy(&model.name));
    let trained = trained_task(&policy, &model.name)?;
    let tilt_limit_rad = tilt_limit(args.tilt_limit_rad, trained.as_ref().map(|(t, _)| *t))?;
    if let (None, Some((task, from))) = (args.tilt_limit_rad, trained) {
        tracing::info!(
            "tilt limit {} rad: the policy's training limit ({from}); --tilt-limit-rad for another",
            task.tilt_limit_rad
        );
    }
    let hardware = match &args.hardware {
        Some(path) => Some(Arc::new(crate::launch::load_profile(&model, path)?)),
        None => None,
    };
    let config = WholeBodyNodeConfig {
        policy,
        skill: args.skill.unwrap_or_else(kumi_runtime::shipped_arm_policy),
        robot: args.robot,
        backend: args.backend,
        domain_id: kumi_ros::domain_id_from_env()?,
        stale_after_s: args.stale_after,
        lockstep: args.lockstep,
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
fn tilt_limit(given: Option<f64>, trained: Option<TrainedTask>) -> Result<Option<f64>> {
    match given {
        Some(limit) if !(limit.is_finite() && limit > 0.0 && limit <= std::f64::consts::PI) => {
            bail!("--tilt-limit-rad must be an angle in (0, pi], not {limit}")
        }
        Some(limit) => Ok(Some(limit)),
        None => Ok(trained.map(|t| t.tilt_limit_rad)),
    }
}

/// What the policy at `path` was trained on, and where that was read: its metadata, or for a
/// policy exported without it, the shipped config of `robot` (`None`: neither).
pub fn trained_task(path: &std::path::Path, robot: &str) -> Result<Option<(TrainedTask, String)>> {
    let from_file = match std::fs::read(path) {
        Ok(bytes) => {
            let file = kumi_runtime::ModelFile::decode(bytes)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?;
            TrainedTask::from_metadata(&file.metadata)
                .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))?
        }
        // The node reports a missing policy with its own message.
        Err(_) => None,
    };
    if let Some(task) = from_file {
        return Ok(Some((task, format!("the metadata of {}", path.display()))));
    }
    Ok(
        crate::train::read_shipped_policy_config(None, robot, Variant::Hierarchical)
            .ok()
            .map(|c| {
                (
                    c.task.trained_task(),
                    format!("the shipped config of `{robot}`"),
                )
            }),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tilt_limit_is_the_training_one_unless_given() {
        let trained = |robot: &str| {
            let policy = Variant::Hierarchical.shipped_policy(robot);
            trained_task(&policy, robot).unwrap().map(|(t, _)| t)
        };
        assert_eq!(tilt_limit(None, trained("minimal")).unwrap(), Some(0.6));
        assert_eq!(tilt_limit(None, trained("dragon")).unwrap(), Some(1.0));
        assert_eq!(tilt_limit(None, trained("tricycle")).unwrap(), Some(0.785));
        assert_eq!(trained("my_robot"), None);
        assert_eq!(tilt_limit(None, None).unwrap(), None);
        assert_eq!(
            tilt_limit(Some(0.5), trained("tricycle")).unwrap(),
            Some(0.5)
        );
        for bad in [0.0, -1.0, f64::NAN, 4.0] {
            let err = tilt_limit(Some(bad), None).unwrap_err();
            assert!(err.to_string().contains("--tilt-limit-rad"), "{err}");
        }
    }
}
