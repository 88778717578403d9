//! A loaded skill policy: checked against its module, run by one backend.

use std::collections::BTreeMap;
use std::fmt;
use std::path::Path;
use std::str::FromStr;

use kumi_policies::observation::{JOINTS, OBSERVATION_DIM};
use kumi_policies::skill::{ArmSkill, MetadataMismatch};

use crate::model_file::{ModelFile, TensorShape};
use crate::onnxruntime::{ort_library_from_env, OrtEngine};
use crate::tract::TractEngine;

/// One inference engine: an observation in, the raw policy output out.
pub(crate) trait Infer: Send {
    fn infer(&mut self, observation: &[f32]) -> Result<Vec<f32>, String>;
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
    #[error("{path}: {source}")]
    Read {
        path: String,
        source: std::io::Error,
    },
    #[error("{path}: not an ONNX model: {message}")]
    Decode { path: String, message: String },
    #[error("{path}: does not fit module `{module}`: {source}")]
    Metadata {
        path: String,
        module: String,
        source: Box<MetadataMismatch>,
    },
    #[error("{path}: {what} has shape {found}, the arm skill needs {expected}")]
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
    #[error("the policy returned {found} values, not {JOINTS}")]
    OutputSize { found: usize },
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

fn check_shapes(path: &str, file: &ModelFile) -> Result<(), RuntimeError> {
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
    one("the input", &file.inputs, OBSERVATION_DIM)?;
    one("the output", &file.outputs, JOINTS)
}

/// A low-level skill policy ready to drive one arm module.
pub struct SkillPolicy {
    backend: Backend,
    engine: Box<dyn Infer>,
    metadata: BTreeMap<String, String>,
}

impl fmt::Debug for SkillPolicy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SkillPolicy")
            .field("backend", &self.backend)
            .field("metadata", &self.metadata)
            .finish_non_exhaustive()
    }
}

impl SkillPolicy {
    /// Loads the ONNX policy at `path` to drive the module `skill` describes.
    pub fn load(
        path: &Path,
        skill: &ArmSkill,
        choice: BackendChoice,
    ) -> Result<Self, RuntimeError> {
        let label = path.display().to_string();
        let bytes = std::fs::read(path).map_err(|source| RuntimeError::Read {
            path: label.clone(),
            source,
        })?;
        Self::from_bytes(bytes, &label, skill, choice)
    }

    /// As [`Self::load`], from the file's bytes; `label` names it in errors.
    pub fn from_bytes(
        bytes: Vec<u8>,
        label: &str,
        skill: &ArmSkill,
        choice: BackendChoice,
    ) -> Result<Self, RuntimeError> {
        let file = ModelFile::decode(bytes).map_err(|message| RuntimeError::Decode {
            path: label.to_string(),
            message,
        })?;
        skill
            .check(&file.metadata)
            .map_err(|source| RuntimeError::Metadata {
                path: label.to_string(),
                module: skill.module.clone(),
                source: Box::new(source),
            })?;
        check_shapes(label, &file)?;
        let backend = choice.resolve();
        let engine: Box<dyn Infer> = match backend {
            Backend::OnnxRuntime => {
                OrtEngine::new(&file.bytes, OBSERVATION_DIM).map(|e| Box::new(e) as Box<dyn Infer>)
            }
            Backend::Tract => TractEngine::new(&file.bytes, OBSERVATION_DIM)
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
        })
    }

    /// The policy's action (7 values, to be clipped and scaled by
    /// [`ArmSkill::increments`]) for one observation.
    pub fn act(
        &mut self,
        observation: &[f32; OBSERVATION_DIM],
    ) -> Result<[f32; JOINTS], RuntimeError> {
        let out = self
            .engine
            .infer(observation)
            .map_err(|message| RuntimeError::Infer {
                backend: self.backend,
                message,
            })?;
        out.as_slice()
            .try_into()
            .map_err(|_| RuntimeError::OutputSize { found: out.len() })
    }

    pub fn backend(&self) -> Backend {
        self.backend
    }

    /// The file's `metadata_props`.
    pub fn metadata(&self) -> &BTreeMap<String, String> {
        &self.metadata
    }
}
