//! The ONNX Runtime backend: `ort` with the shared library loaded at run time. ONNX Runtime
//! allows one environment per process; it is created on first use from `ORT_DYLIB_PATH` and
//! shared by every policy after.

use std::path::PathBuf;
use std::sync::OnceLock;

use ort::environment::Environment;
use ort::session::builder::GraphOptimizationLevel;
use ort::session::Session;
use ort::value::TensorRef;

use crate::policy::Infer;

/// The environment variable naming the ONNX Runtime shared library (ort's convention).
pub const ORT_DYLIB_PATH: &str = "ORT_DYLIB_PATH";

/// The library named by `ORT_DYLIB_PATH`, if the variable is set and not empty.
pub fn ort_library_from_env() -> Option<PathBuf> {
    std::env::var_os(ORT_DYLIB_PATH)
        .filter(|v| !v.is_empty())
        .map(PathBuf::from)
}

static ENVIRONMENT: OnceLock<Result<(PathBuf, Environment), String>> = OnceLock::new();

/// The process's ONNX Runtime environment, loading the library from `ORT_DYLIB_PATH` the first
/// time. Every failure is a message that says what to do.
fn environment() -> Result<&'static Environment, String> {
    let loaded = ENVIRONMENT.get_or_init(|| {
        let path = ort_library_from_env().ok_or_else(|| {
            format!("{ORT_DYLIB_PATH} is not set: point it at libonnxruntime.so (the PyPI `onnxruntime` wheel ships it as onnxruntime/capi/libonnxruntime.so.<version>), or use the tract backend")
        })?;
        if !path.is_file() {
            return Err(format!(
                "{ORT_DYLIB_PATH}={}: no such file",
                path.display()
            ));
        }
        let env = ort::init_from(&path)
            .map_err(|e| format!("{ORT_DYLIB_PATH}={}: {e}", path.display()))?
            .with_name("kumi")
            .build()
            .map_err(|e| format!("ONNX Runtime from {}: {e}", path.display()))?;
        Ok((path, env))
    });
    loaded.as_ref().map(|(_, env)| env).map_err(Clone::clone)
}

pub(crate) struct OrtEngine {
    session: Session,
    input_dim: usize,
}

impl OrtEngine {
    pub(crate) fn new(bytes: &[u8], input_dim: usize) -> Result<Self, String> {
        let env = environment()?;
        // One thread: a batch-1 MLP gains nothing from more, and a node shares its cores.
        let build = || -> ort::Result<Session> {
            Session::builder(env)?
                .with_optimization_level(GraphOptimizationLevel::All)?
                .with_intra_threads(1)?
                .commit_from_memory(bytes)
        };
        let session = build().map_err(|e| e.to_string())?;
        Ok(Self { session, input_dim })
    }
}

impl Infer for OrtEngine {
    fn infer(&mut self, input: &[f32], rows: usize) -> Result<Vec<f32>, String> {
        let input = TensorRef::from_array_view(([rows, self.input_dim], input))
            .map_err(|e| e.to_string())?;
        let outputs = self
            .session
            .run(ort::inputs![input])
            .map_err(|e| e.to_string())?;
        let (_, values) = outputs[0]
            .try_extract_tensor::<f32>()
            .map_err(|e| e.to_string())?;
        Ok(values.to_vec())
    }
}
