//! kumi's MuJoCo world: any assembled morphology on MuJoCo 3.17 (through `mujoco-rs`), behind
//! the same [`kumi_engine::SimWorld`] interface as the rapier world, with kumi's servo law.
//!
//! The model is generated from `kumi-model` ([`mjcf`]). Linking libmujoco needs the `mujoco`
//! feature and the PyPI wheel installed by `scripts/install-mujoco.sh`; without them
//! `kumi-worlds` answers [`SimError::Unavailable`], saying how to install it ([`unavailable`]).

pub mod geometry;
pub mod mjcf;
pub mod servo;
#[cfg(feature = "mujoco")]
mod world;

#[cfg(feature = "mujoco")]
pub use world::MujocoWorld;

use kumi_engine::{Engine, SimError};

/// How to get MuJoCo, for error messages.
pub const INSTALL_HINT: &str = "install it with `bash scripts/install-mujoco.sh` (MuJoCo 3.17.0 \
from PyPI) and build kumi with `--features mujoco`";

/// Whether this build can simulate on MuJoCo.
pub const AVAILABLE: bool = cfg!(feature = "mujoco");

/// The error of a build without MuJoCo.
pub fn unavailable() -> SimError {
    SimError::Unavailable {
        engine: Engine::Mujoco,
        reason: format!("this kumi was built without MuJoCo: {INSTALL_HINT}"),
    }
}
