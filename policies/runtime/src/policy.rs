//! A loaded skill policy: checked against its module, run by one backend.

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;
use std::str::FromStr;

use kumi_policies::observation::{JOINTS, OBSERVATION_DIM};
use kumi_policies::skill::{ArmSkill, MetadataMismatch};
use kumi_terms::contract::ContractMismatch;

use crate::model_file::{ModelFile, TensorShape};
use crate::onnxruntime::{ort_library_from_env, OrtEngine};
use crate::tract::TractEngine;

/// One inference engine: `rows` observations in (row-major), the raw outputs out.
pub(crate) trait Infer: Send {
    fn infer(&mut self, input: &[f32], rows: usize) -> Result<Vec<f32>, String>;
}

/// The engine that runs a policy.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    /// ONNX Runtime (native, loaded from `ORT_DYLIB_PATH`).
    OnnxRuntime,
    /// tract (pure Rust).
    Tract,
}

impl fmt::Display for Backend {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::OnnxRuntime => "onnxruntime",
            Self::Tract => "tract",
        })
    }
}

/// Which backend to use.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum BackendChoice {
    /// ONNX Runtime when `ORT_DYLIB_PATH` is set (failing loudly if it cannot be loaded),
    /// tract otherwise.
    #[default]
    Auto,
    OnnxRuntime,
    Tract,
}

impl BackendChoice {
    /// The backend this choice means now (reads `ORT_DYLIB_PATH` for `Auto`).
    pub fn resolve(self) -> Backend {
        match self {
            Self::Auto if ort_library_from_env().is_some() => Backend::OnnxRuntime,
            Self::Auto | Self::Tract => Backend::Tract,
            Self::OnnxRuntime => Backend::OnnxRuntime,
        }
    }
}

impl FromStr for BackendChoice {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "auto" => Ok(Self::Auto),
            "onnxruntime" | "ort" => Ok(Self::OnnxRuntime),
            "tract" => Ok(Self::Tract),
            _ => Err(format!(
                "unknown backend `{s}`: expected auto, onnxruntime or tract"
            )),
        }
    }
}

#[derive(Debug, thiserror::Error)]
pub enum RuntimeError {
    // The causes are in the messages, not `#[source]`: `{:#}` would print them twice.
    #[error("{path}: {error}")]
    Read { path: String, error: std::io::Error },
    #[error("{path}: not an ONNX model: {message}")]
    Decode { path: String, message: String },
    #[error("{path}: does not fit module `{module}`: {mismatch}")]
    Metadata {
        path: String,
        module: String,
        mismatch: Box<MetadataMismatch>,
    },
    #[error("{path}: does not fit this robot and skill: {mismatch}")]
    Contract {
        path: String,
        mismatch: Box<ContractMismatch>,
    },
    #[error("{path}: {what} has shape {found}, the policy's contract needs {expected}")]
    Shape {
        path: String,
        what: &'static str,
        found: String,
        expected: String,
    },
    #[error("{path}: {backend} cannot load the model: {message}")]
    Load {
        path: String,
        backend: Backend,
        message: String,
    },
    #[error("{backend} inference failed: {message}")]
    Infer { backend: Backend, message: String },
    #[error("the policy returned {found} values, not {expected}")]
    OutputSize { found: usize, expected: usize },
    #[error("{found} input values are not whole rows of {width}")]
    InputSize { found: usize, width: usize },
}

fn describe(shape: &TensorShape) -> String {
    let dims: Vec<String> = shape
        .iter()
        .map(|d| d.map_or("batch".to_string(), |v| v.to_string()))
        .collect();
    format!("[{}]", dims.join(", "))
}

/// `[batch or 1, width]`.
fn fits(shape: &TensorShape, width: usize) -> bool {
    shape.len() == 2 && matches!(shape[0], None | Some(1)) && shape[1] == Some(width as i64)
}

fn check_shapes(
    path: &str,
    file: &ModelFile,
    input_dim: usize,
    output_dim: usize,
) -> Result<(), RuntimeError> {
    let one = |what: &'static str, list: &[(String, TensorShape)], width: usize| {
        let found = match list {
            [(_, shape)] if fits(shape, width) => return Ok(()),
            [(_, shape)] => describe(shape),
            _ => format!("{} tensors", list.len()),
        };
        Err(RuntimeError::Shape {
            path: path.to_string(),
            what,
            found,
            expected: format!("one tensor [batch, {width}]"),
        })
    };
    one("the input", &file.inputs, input_dim)?;
    one("the output", &file.outputs, output_dim)
}

/// A checked ONNX network on one backend: rows of `input_dim` values in, rows of
/// `output_dim` out.
pub struct Network {
    backend: Backend,
    engine: Box<dyn Infer>,
    metadata: BTreeMap<String, String>,
    input_dim: usize,
    output_dim: usize,
}

impl fmt::Debug for Network {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Network")
            .field("backend", &self.backend)
            .field("metadata", &self.metadata)
            .finish_non_exhaustive()
    }
}

fn read(path: &Path) -> Result<Vec<u8>, RuntimeError> {
    std::fs::read(path).map_err(|error| RuntimeError::Read {
        path: path.display().to_string(),
        error,
    })
}

fn decode(bytes: Vec<u8>, label: &str) -> Result<ModelFile, RuntimeError> {
    ModelFile::decode(bytes).map_err(|message| RuntimeError::Decode {
        path: label.to_string(),
        message,
    })
}

impl Network {
    /// The network of a decoded file whose metadata has been checked: its shapes must be
    /// `[batch, input_dim]` and `[batch, output_dim]`.
    fn new(
        file: ModelFile,
        label: &str,
        choice: BackendChoice,
        input_dim: usize,
        output_dim: usize,
    ) -> Result<Self, RuntimeError> {
        check_shapes(label, &file, input_dim, output_dim)?;
        let backend = choice.resolve();
        let engine: Box<dyn Infer> = match backend {
            Backend::OnnxRuntime => {
                OrtEngine::new(&file.bytes, input_dim).map(|e| Box::new(e) as Box<dyn Infer>)
            }
            Backend::Tract => TractEngine::new(&file.bytes, input_dim)
                .map(|e| Box::new(e) as Box<dyn Infer>)
                .map_err(|e| e.to_string()),
        }
        .map_err(|message| RuntimeError::Load {
            path: label.to_string(),
            backend,
            message,
        })?;
        Ok(Self {
            backend,
            engine,
            metadata: file.metadata,
            input_dim,
            output_dim,
        })
    }

    /// The outputs for whole rows of inputs, row-major.
    pub fn run(&mut self, input: &[f32]) -> Result<Vec<f32>, RuntimeError> {
        if input.is_empty() || !input.len().is_multiple_of(self.input_dim) {
            return Err(RuntimeError::InputSize {
                found: input.len(),
                width: self.input_dim,
            });
        }
        let rows = input.len() / self.input_dim;
        let out = self
            .engine
            .infer(input, rows)
            .map_err(|message| RuntimeError::Infer {
                backend: self.backend,
                message,
            })?;
        if out.len() != rows * self.output_dim {
            return Err(RuntimeError::OutputSize {
                found: out.len(),
                expected: rows * self.output_dim,
            });
        }
        Ok(out)
    }

    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// The file's `metadata_props`.
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }
}

/// A low-level skill policy ready to drive one arm module.
#[derive(Debug)]
pub struct SkillPolicy {
    net: Network,
    /// How many leading observation values the network reads ([`ArmSkill::check`]).
    observation_dim: usize,
}

impl SkillPolicy {
    /// Loads the ONNX policy at `path` to drive the module `skill` describes.
    pub fn load(
        path: &Path,
        skill: &ArmSkill,
        choice: BackendChoice,
    ) -> Result<Self, RuntimeError> {
        Self::from_bytes(read(path)?, &path.display().to_string(), skill, choice)
    }

    /// As [`Self::load`], from the file's bytes; `label` names it in errors.
    pub fn from_bytes(
        bytes: Vec<u8>,
        label: &str,
        skill: &ArmSkill,
        choice: BackendChoice,
    ) -> Result<Self, RuntimeError> {
        let file = decode(bytes, label)?;
        let observation_dim =
            skill
                .check(&file.metadata)
                .map_err(|mismatch| RuntimeError::Metadata {
                    path: label.to_string(),
                    module: skill.module.clone(),
                    mismatch: Box::new(mismatch),
                })?;
        Ok(Self {
            net: Network::new(file, label, choice, observation_dim, JOINTS)?,
            observation_dim,
        })
    }

    /// How many leading values of the observation the policy reads: all of them, or Table
    /// I's 21 for a skill exported before the targets' lead was observed.
    pub fn observation_dim(&self) -> usize {
        self.observation_dim
    }

    /// The policy's action (7 values, to be clipped and scaled by
    /// [`ArmSkill::increments`]) for one observation.
    pub fn act(
        &mut self,
        observation: &[f32; OBSERVATION_DIM],
    ) -> Result<[f32; JOINTS], RuntimeError> {
        let out = self.net.run(&observation[..self.observation_dim])?;
        Ok(std::array::from_fn(|j| out[j]))
    }

    /// The actions for several observations at once (several arm modules or environments),
    /// in one inference.
    pub fn act_batch(
        &mut self,
        observations: &[[f32; OBSERVATION_DIM]],
    ) -> Result<Vec<[f32; JOINTS]>, RuntimeError> {
        let out = if self.observation_dim == OBSERVATION_DIM {
            self.net.run(observations.as_flattened())?
        } else {
            let read: Vec<f32> = observations
                .iter()
                .flat_map(|o| &o[..self.observation_dim])
                .copied()
                .collect();
            self.net.run(&read)?
        };
        Ok(out
            .chunks_exact(JOINTS)
            .map(|row| std::array::from_fn(|j| row[j]))
            .collect())
    }

    pub fn backend(&self) -> Backend {
        self.net.backend()
    }

    /// The file's `metadata_props`.
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        self.net.metadata()
    }
}

/// A whole-body (upper-level) policy, checked against the contract of the robot and skill it
/// will run with ([`kumi_terms::contract::contract`]).
#[derive(Debug)]
pub struct WholeBodyPolicy {
    net: Network,
}

impl WholeBodyPolicy {
    /// Loads the ONNX policy at `path`; its metadata must match `expected` key by key.
    pub fn load(
        path: &Path,
        expected: &BTreeMap<String, String>,
        choice: BackendChoice,
    ) -> Result<Self, RuntimeError> {
        Self::from_bytes(read(path)?, &path.display().to_string(), expected, choice)
    }

    /// As [`Self::load`], from the file's bytes; `label` names it in errors.
    pub fn from_bytes(
        bytes: Vec<u8>,
        label: &str,
        expected: &BTreeMap<String, String>,
        choice: BackendChoice,
    ) -> Result<Self, RuntimeError> {
        let file = decode(bytes, label)?;
        kumi_terms::contract::check(expected, &file.metadata).map_err(|mismatch| {
            RuntimeError::Contract {
                path: label.to_string(),
                mismatch: Box::new(mismatch),
            }
        })?;
        let dim = |key: &str| {
            expected
                .get(key)
                .and_then(|v| v.parse::<usize>().ok())
                .unwrap_or(0)
        };
        let (input, output) = (
            dim(kumi_policies::metadata::OBSERVATION_DIM_KEY),
            dim(kumi_policies::metadata::ACTION_DIM_KEY),
        );
        Ok(Self {
            net: Network::new(file, label, choice, input, output)?,
        })
    }

    /// The actions for rows of observations (one row per robot), row-major.
    pub fn act(&mut self, observations: &[f32]) -> Result<Vec<f32>, RuntimeError> {
        self.net.run(observations)
    }

    pub fn backend(&self) -> Backend {
        self.net.backend()
    }

    pub fn metadata(&self) -> &BTreeMap<String, String> {
        self.net.metadata()
    }
}
