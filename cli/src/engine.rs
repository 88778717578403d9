//! `--engine`: which physics engine a command simulates with.

use std::sync::Arc;

use anyhow::{bail, Result};
use kumi_model::RobotModel;
use kumi_worlds::{Engine, SimConfig, SimWorld};

/// Parses an engine name for clap.
pub fn parse(s: &str) -> Result<Engine, String> {
    s.parse()
}

/// The engine to use: the one asked for, which must be in this build, or `default`.
pub fn choose(asked: Option<Engine>, default: Engine) -> Result<Engine> {
    let engine = asked.unwrap_or(default);
    if !kumi_worlds::available(engine) {
        bail!(
            "the {engine} engine is not in this build: {}",
            kumi_worlds::MUJOCO_INSTALL_HINT
        );
    }
    Ok(engine)
}

/// Builds a world on `engine`.
pub fn world(
    engine: Engine,
    model: Arc<RobotModel>,
    config: SimConfig,
) -> Result<Box<dyn SimWorld>> {
    Ok(kumi_worlds::build(engine, model, config)?)
}
