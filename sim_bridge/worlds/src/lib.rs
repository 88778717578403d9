//! One place that turns an [`Engine`] choice into a world: everything that lets users pick the
//! engine (training, evaluation, benchmarks, the sim bridge) builds its worlds here.

use std::sync::Arc;

pub use kumi_engine::*;
use kumi_model::RobotModel;

/// Builds `model` on `engine` with `config`, at its home pose.
pub fn build(
    engine: Engine,
    model: Arc<RobotModel>,
    config: SimConfig,
) -> Result<Box<dyn SimWorld>, SimError> {
    Ok(match engine {
        Engine::Rapier => Box::new(kumi_sim::World::new(model, config)?),
        Engine::Mujoco => mujoco(model, config)?,
    })
}

#[cfg(feature = "mujoco")]
fn mujoco(model: Arc<RobotModel>, config: SimConfig) -> Result<Box<dyn SimWorld>, SimError> {
    Ok(Box::new(kumi_mujoco::MujocoWorld::new(model, config)?))
}

#[cfg(not(feature = "mujoco"))]
fn mujoco(_model: Arc<RobotModel>, _config: SimConfig) -> Result<Box<dyn SimWorld>, SimError> {
    Err(kumi_mujoco::unavailable())
}

/// Whether this build can simulate on `engine`.
pub fn available(engine: Engine) -> bool {
    match engine {
        Engine::Rapier => true,
        Engine::Mujoco => kumi_mujoco::AVAILABLE,
    }
}

/// The engines this build can simulate on, rapier first.
pub fn available_engines() -> Vec<Engine> {
    Engine::ALL.into_iter().filter(|&e| available(e)).collect()
}

/// Training's engine when none is named: MuJoCo where this build has it (about 10x faster),
/// rapier otherwise.
pub fn default_training_engine() -> Engine {
    if available(Engine::Mujoco) {
        Engine::Mujoco
    } else {
        Engine::Rapier
    }
}

/// The MuJoCo model (MJCF) that the MuJoCo engine builds for `model`; pure Rust, so it works
/// in builds without MuJoCo too.
pub fn mjcf(model: &RobotModel, config: &SimConfig) -> Result<String, SimError> {
    Ok(kumi_mujoco::mjcf::build(model, config)?.xml)
}

/// The MuJoCo install hint, for messages that mention the engine choice.
pub const MUJOCO_INSTALL_HINT: &str = kumi_mujoco::INSTALL_HINT;
