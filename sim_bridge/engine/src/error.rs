//! Errors of the simulated worlds, whatever the engine.

use kumi_model::kinematics::TreeError;

#[derive(Debug, thiserror::Error)]
pub enum SimError {
    #[error("robot `{robot}`: {source}")]
    Tree { robot: String, source: TreeError },
    #[error(
        "robot `{robot}`: actuated joint `{joint}` is not a multibody joint in the rapier model"
    )]
    ActuatorNotArticulated { robot: String, joint: String },
    #[error("no module named `{0}`")]
    UnknownModule(String),
    #[error("no link named `{0}`")]
    UnknownLink(String),
    #[error("module `{module}` expects {expected} values, got {got}")]
    LengthMismatch {
        module: String,
        expected: usize,
        got: usize,
    },
    #[error("link `{link}`: a load needs finite values and a stiffness >= 0, not {load}")]
    BadLoad { link: String, load: String },
    #[error("module `{module}`: non-finite command {value}")]
    NonFinite { module: String, value: f64 },
    #[error("module `{module}` has no {what} joints")]
    WrongModuleKind { module: String, what: &'static str },
    #[error("invalid configuration: {0}")]
    BadConfig(String),
    #[error("robot `{robot}`, module `{module}`: the {engine} engine cannot express it: {reason}")]
    Unsupported {
        engine: crate::Engine,
        robot: String,
        module: String,
        reason: String,
    },
    #[error("the {engine} engine is not available: {reason}")]
    Unavailable {
        engine: crate::Engine,
        reason: String,
    },
    #[error("the {engine} engine rejected robot `{robot}`: {message}")]
    EngineRejected {
        engine: crate::Engine,
        robot: String,
        message: String,
    },
    #[error("this snapshot was taken from a world of another engine or robot")]
    ForeignSnapshot,
}
